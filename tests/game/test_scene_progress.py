"""The progress review scene on a database of a few results: the plot drawn with the normal band
(its colour in the plot's pixels, at the normal value's height) and the 5-degree grid, the tests
listed and chosen with the keys, the games' plot or "No games yet", and one line for an unknown
patient."""

from __future__ import annotations

import numpy as np
import pytest

from game.app import App, BaseScene, Settings
from game.db import Database
from game.input import Action, Press
from game.rom.session import RomResult
from game.scenes.progress import BAND_COLOUR, ProgressScene, rom_plot_rgb

SIZE = (1280, 720)


def result(test: str, value: float, *, side: str = "right", angle: str = "shoulder_flexion", ref: float | None = 180.0,
           compensation: tuple[str, ...] = (), estimated: tuple[str, ...] = ()) -> RomResult:
    return RomResult(test=test, title=test, side=side, angle=f"{side}_{angle}", direction=1, mode="active",
                     position="seated_arm_at_side", position_words="seated", standard="jarm", reference_deg=ref,
                     max_deg=value, start_deg=-10.0, range_deg=value + 10.0, max_time_s=3.0, started_s=1.0,
                     ended_s=7.0, compensations=compensation, estimated_markers=estimated, n_samples=90)


def fill(path, *, games: bool) -> None:
    with Database(path) as db:
        db.add_patient("P001")
        for day, (flex, elbow) in enumerate(((121.3, 118.0), (133.9, 126.2), (146.2, 131.0)), start=1):
            sid = db.start_session("P001", "rom", started_utc=f"2026-11-{day:02d}T09:00:00Z")
            db.add_rom_result(sid, result("shoulder_flexion", flex, compensation=("the trunk leaned",) if day == 2 else ()))
            db.add_rom_result(sid, result("shoulder_flexion", flex - 8, side="left"))
            db.add_rom_result(sid, result("elbow_flexion", elbow, angle="elbow_flexion", ref=145.0,
                                          estimated=("MRE2",) if day == 3 else ()))
            if games:
                gid = db.start_session("P001", "exercise", started_utc=f"2026-11-{day:02d}T10:00:00Z")
                db.add_exercise_result(gid, "reach", repetitions=10 + 5 * day, duration_s=240.0 + 30 * day)


@pytest.fixture
def screen(open_headless):
    return open_headless(SIZE)


def band_rgb() -> np.ndarray:
    return np.array([int(BAND_COLOUR[i:i + 2], 16) for i in (1, 3, 5)])


def test_plot_has_the_normal_band_at_the_normal_value(tmp_path):
    path = tmp_path / "db.sqlite3"
    fill(path, games=False)
    with Database(path) as db:
        rows = [r for r in db.rom_results("P001") if r.test == "shoulder_flexion"]
    from game.report import session_order

    rgb = rom_plot_rgb("Shoulder flexion", rows, session_order(rows), 180.0, "jarm", (800, 400)).astype(int)
    assert rgb.shape == (400, 800, 3)
    # the band: the teal drawn at 30 % over the dark background, a horizontal stripe across the axes
    background = np.array([27, 33, 43])
    expected = background + 0.3 * (band_rgb() - background)
    band = np.abs(rgb - expected).sum(axis=2) < 12
    rows_with_band = np.flatnonzero(band.sum(axis=1) > 300)
    assert len(rows_with_band) >= 8
    # no band when the standard's value is for another position
    plain = rom_plot_rgb("x", rows, session_order(rows), None, "aaos", (800, 400)).astype(int)
    assert (np.abs(plain - expected).sum(axis=2) < 12).sum() < 50


def open_progress(screen, tmp_path):
    """The progress review of P001 (three sessions of two tests, and games) over a base scene."""
    path = tmp_path / "db.sqlite3"
    fill(path, games=True)
    app = App(screen, Settings(show_fps=False, max_fps=0), clock=lambda: 0.0, events=lambda: [])
    app.push(BaseScene())
    scene = ProgressScene(path, "P001", standard="jarm")
    app.push(scene)
    return app, scene


def test_progress_scene_draws_the_plot_and_the_games(screen, tmp_path):
    app, scene = open_progress(screen, tmp_path)
    assert scene.tests == ["elbow_flexion", "shoulder_flexion"]   # first session, then name
    app.frame()
    rgb = screen.read_rgb().astype(int)
    _, _, plot, games = scene._layout()
    x, y, w, h = (round(v) for v in plot)
    background = np.array([27, 33, 43])
    expected = background + 0.3 * (band_rgb() - background)
    in_plot = rgb[y:y + h, x:x + w]
    assert ((np.abs(in_plot - expected).sum(axis=2) < 14).sum(axis=1) > 200).sum() >= 5    # the band
    # the right side's line (amber) is drawn
    amber = np.abs(in_plot - np.array([242, 190, 92])).sum(axis=2) < 40
    assert amber.sum() > 300
    # the games' bars in the lower part
    gx, gy, gw, gh = (round(v) for v in games)
    lower = rgb[gy:gy + gh, gx:gx + gw]
    assert (np.abs(lower - band_rgb()).sum(axis=2) < 30).sum() > 500
    screen.save_png(tmp_path / "progress.png")
    first_plot = scene.plot_rgb
    app.dispatch(Press(Action.DOWN))
    app.frame()
    assert scene.selected == 1 and scene.plot_rgb is not first_plot
    app.dispatch(Press(Action.BACK))
    assert not isinstance(app.scene, ProgressScene)
    app.close()


def test_no_games_yet_and_unknown_patient(screen, tmp_path):
    path = tmp_path / "db.sqlite3"
    fill(path, games=False)
    app = App(screen, Settings(show_fps=False, max_fps=0), clock=lambda: 0.0, events=lambda: [])
    app.push(BaseScene())
    scene = ProgressScene(path, "P001")
    app.push(scene)
    app.frame()
    assert scene.games == [] and "games" not in scene._textures
    unknown = ProgressScene(path, "P404")
    app.push(unknown)
    app.frame()
    assert "no patient 'P404'" in unknown.error
    app.close()


def test_games_show_for_a_patient_without_rom_results(screen, tmp_path):
    path = tmp_path / "db.sqlite3"
    with Database(path) as db:
        db.add_patient("P002")
        gid = db.start_session("P002", "exercise", started_utc="2026-11-03T10:00:00Z")
        db.add_exercise_result(gid, "reach", repetitions=12, duration_s=300.0)
    app = App(screen, Settings(show_fps=False, max_fps=0), clock=lambda: 0.0, events=lambda: [])
    app.push(BaseScene())
    scene = ProgressScene(path, "P002")
    app.push(scene)
    app.frame()
    assert scene.tests == [] and "games" in scene._textures
    _, _, _, games = scene._layout()
    gx, gy, gw, gh = (round(v) for v in games)
    lower = screen.read_rgb().astype(int)[gy:gy + gh, gx:gx + gw]
    assert (np.abs(lower - band_rgb()).sum(axis=2) < 30).sum() > 200   # the games' bars
    app.close()


def test_play_command_opens_the_progress_scene_and_refuses_an_unknown_patient(screen, tmp_path, capsys):
    import cv2

    from game.cli import main

    path = tmp_path / "db.sqlite3"
    fill(path, games=False)
    assert main(["play", "--headless", "--scene", "progress", "--db", str(path)]) == 1
    assert main(["play", "--headless", "--scene", "rom", "--patient", "P404", "--db", str(path)]) == 1
    assert main(["play", "--headless", "--scene", "rom", "--patient", "P001", "--test", "no_such_test",
                 "--db", str(path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3
    assert "give --patient ID" in err[0] and "no patient 'P404'" in err[1] and "no_such_test" in err[2]
    out = tmp_path / "progress.png"
    assert main(["play", "--headless", "--scene", "progress", "--patient", "P001", "--db", str(path),
                 "--seconds", "0.5", "--screenshot", str(out), "--window", "1280x720"]) == 0
    rgb = cv2.imread(str(out))[:, :, ::-1].astype(int)
    background = np.array([27, 33, 43])
    expected = background + 0.3 * (band_rgb() - background)
    assert ((np.abs(rgb - expected).sum(axis=2) < 14).sum(axis=1) > 200).sum() >= 5   # the normal band


def test_the_export_button_writes_the_report_beside_the_database(screen, tmp_path):
    """A click on Export report writes the HTML report and its CSV into reports/ beside the
    database, readable by the user only, and the screen says where (the review once pointed to
    the command line)."""
    import os
    import stat

    from game.input import Pointer, PointerKind

    path = tmp_path / "db.sqlite3"
    fill(path, games=True)
    app = App(screen, Settings(show_fps=False), clock=lambda: 0.0, events=lambda: [])
    app.push(BaseScene())
    scene = ProgressScene(path, "P001")
    app.push(scene)
    try:
        app.frame()
        x, y, w, h = scene.export_rect()
        app.dispatch(Pointer(PointerKind.PRESS, (x + w / 2) / SIZE[0], (y + h / 2) / SIZE[1], button=1))
        (html,) = (tmp_path / "reports").glob("P001_*.html")
        (csv_file,) = (tmp_path / "reports").glob("P001_*.csv")
        assert "Shoulder flexion" in html.read_text(encoding="utf-8") and csv_file.stat().st_size > 100
        for f in (html, csv_file):
            assert stat.S_IMODE(os.stat(f).st_mode) == 0o600
        assert stat.S_IMODE(os.stat(tmp_path / "reports").st_mode) == 0o700
        assert scene.notice[0] == f"Exported: {html} (and the CSV beside it)"
        app.dispatch(Press(Action.SELECT))                     # Enter exports too (the same file again)
        assert scene.notice[0].startswith("Exported:")
        app.frame()
    finally:
        app.close()


def test_moving_through_the_list_draws_each_plot_once(screen, tmp_path, monkeypatch):
    """Issue 25 (stalls): every change of the selected test, even the pointer passing over the
    list, redrew the test's plot and the unchanged games' plot with matplotlib in the frame (a
    second or more on a busy machine). Each is drawn once; a test seen before comes from memory."""
    import game.scenes.progress as progress

    drawn = []
    for name in ("rom_plot_rgb", "games_plot_rgb"):
        real = getattr(progress, name)
        monkeypatch.setattr(progress, name, lambda *a, _real=real, _name=name, **k: drawn.append(_name) or _real(*a, **k))
    app, scene = open_progress(screen, tmp_path)
    app.frame()
    first = screen.read_rgb()
    for action in (Action.DOWN, Action.UP, Action.DOWN, Action.UP):
        app.dispatch(Press(action))
        app.frame()
    assert sorted(drawn) == ["games_plot_rgb", "rom_plot_rgb", "rom_plot_rgb"]
    assert scene.selected == 0 and np.array_equal(screen.read_rgb(), first)   # the same picture again
    app.close()


def test_the_change_since_the_last_session_is_called_real_only_beyond_the_sdc(screen, tmp_path):
    """Under the plot, per side, the latest change in words: +8 degrees within a smallest
    detectable change of 9 is "not a real change yet" (dim), +12 is "a real improvement" (accent)."""
    from game.gfx import theme
    from game.scenes.progress import TestInfo

    path = tmp_path / "db.sqlite3"
    with Database(path) as db:
        db.add_patient("P001")
        for day, (right, left) in enumerate(((120.0, 110.0), (128.0, 122.0)), start=1):
            sid = db.start_session("P001", "rom", started_utc=f"2026-11-{day:02d}T09:00:00Z")
            db.add_rom_result(sid, result("shoulder_flexion", right))
            db.add_rom_result(sid, result("shoulder_flexion", left, side="left"))
    app = App(screen, Settings(show_fps=False, max_fps=0), clock=lambda: 0.0, events=lambda: [])
    app.push(BaseScene())
    scene = ProgressScene(path, "P001")
    app.push(scene)
    try:
        scene.infos["shoulder_flexion"] = TestInfo("Shoulder flexion", 180.0, 9.0)
        lines = scene.change_lines("shoulder_flexion")
        assert lines == [
            ("Right, #1 to #2: +8 degrees: within the measurement's smallest detectable change of 9 degrees "
             "\u2014 not a real change yet", False),
            ("Left, #1 to #2: +12 degrees: beyond the smallest detectable change of 9 degrees \u2014 a real "
             "improvement", True)]
        app.frame()
        rgb = screen.read_rgb().astype(int)
        _, _, plot, games = scene._layout()
        x, w = round(plot[0]), round(plot[2])
        top = round(plot[1] + plot[3])
        first = rgb[top:top + round(30), x:x + w]            # the right side's line: dim
        second = rgb[top + 30:round(games[1]), x:x + w]      # the left side's line: the accent colour
        near = lambda img, colour: (np.abs(img - np.array(colour)).sum(axis=2) < 40).sum()  # noqa: E731
        assert near(first, theme.TEXT_DIM) > 150 and near(first, theme.ACCENT) < 20
        assert near(second, theme.ACCENT) > 150
        screen.save_png(tmp_path / "changes.png")
        # without a measured SDC the change is not judged
        scene.infos["shoulder_flexion"] = TestInfo("Shoulder flexion", 180.0, None)
        assert scene.change_lines("shoulder_flexion")[0] == (
            "Right, #1 to #2: +8 degrees (no smallest detectable change measured for this test: not judged)",
            None)
    finally:
        app.close()
