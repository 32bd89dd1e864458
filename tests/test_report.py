"""The HTML progress report: embedded PNG plots, the table, the CSV beside it, sessions in order."""

from __future__ import annotations

import base64
import csv
import re

import cv2
import numpy as np
import pytest

from game.db import Database, DatabaseError
from game.report import rom_plot_png, session_order, write_report
from game.rom.session import RomResult


def rom_result(test="shoulder_flexion", value=120.0, comp=(), est=()) -> RomResult:
    return RomResult(test=test, title=test, side="right", angle=f"right_{test}", direction=1, mode="active",
                     position="seated_arm_at_side", position_words="Seated.", standard="jarm", reference_deg=180.0,
                     max_deg=value, start_deg=-10.0, range_deg=value + 10.0, max_time_s=3.0, started_s=1.0,
                     ended_s=6.0, compensations=comp, estimated_markers=est, n_samples=150)


@pytest.fixture()
def db(tmp_path):
    db = Database(tmp_path / "db.sqlite3")
    db.add_patient("P001")
    db.add_patient("P002")
    # sessions inserted out of date order: the report must sort them by date
    for day, value in (("2026-03-01", 130.0), ("2026-01-01", 100.0), ("2026-02-01", 117.4)):
        s = db.start_session("P001", "rom", started_utc=f"{day}T09:00:00Z")
        comp = ("the trunk leaned 10 degrees back",) if value == 117.4 else ()
        db.add_rom_result(s, rom_result(value=value, comp=comp), recorded_utc=f"{day}T09:05:00Z")
        db.add_rom_result(s, rom_result(test="shoulder_external_rotation", value=value / 3, est=("MRE2",)),
                          recorded_utc=f"{day}T09:06:00Z")
        g = db.start_session("P001", "exercise", started_utc=f"{day}T10:00:00Z")
        db.add_exercise_result(g, "reach", int(value / 10), 300.0, recorded_utc=f"{day}T10:05:00Z")
    yield db
    db.close()


def _pngs(html: str) -> list[np.ndarray]:
    out = []
    for b64 in re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html):
        img = cv2.imdecode(np.frombuffer(base64.b64decode(b64), np.uint8), cv2.IMREAD_COLOR)
        assert img is not None and img.shape[0] > 100
        out.append(img)
    return out


def test_report_has_plots_table_and_csv(db, tmp_path):
    html_path, csv_path = write_report(db, "P001", tmp_path / "out" / "report.html")
    html = html_path.read_text(encoding="utf-8")
    assert csv_path == tmp_path / "out" / "report.csv"
    assert len(_pngs(html)) == 3  # two ROM tests and the games
    assert "patient P001" in html and "Active ROM" in html and "JARM" in html
    assert "the trunk leaned 10 degrees back" in html and "MRE2" in html
    # table rows in session order, rounded to 5 with the raw value beside it
    order = [m for m in re.findall(r"<td>(2026-\d\d-\d\d) 09:00:00</td><td>shoulder flexion", html)]
    assert order == ["2026-01-01", "2026-02-01", "2026-03-01"]
    assert "<b>115</b></td><td class=\"num\">117.4</td>" in html
    with open(csv_path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and rows[0]["value_deg"] == "100.0" and rows[0]["mode"] == "active"
    assert {r["standard"] for r in rows} == {"jarm"} and rows[2]["rounded_deg"] == "115"


def test_sessions_are_numbered_by_date(db):
    order = session_order(db.rom_results("P001"))
    dates = sorted((n, r.session_started_utc) for r in db.rom_results("P001") for u, n in order.items() if u == r.session_uid)
    assert [d for _, d in dates] == sorted(d for _, d in dates)


def test_progress_plot_shows_the_normal_band_and_the_points(db):
    rows = [r for r in db.rom_results("P001") if r.test == "shoulder_flexion"]
    order = session_order(rows)
    img = cv2.imdecode(np.frombuffer(base64.b64decode(rom_plot_png("Shoulder flexion", rows, order, 180.0, "jarm")),
                                     np.uint8), cv2.IMREAD_COLOR)
    b, g, r = (img[..., k].astype(int) for k in range(3))
    band = (g > 200) & (r > 190) & (r < 225) & (b > 190) & (b < 225) & (g - r > 12)  # pale green, alpha 0.18
    blue = (b > 150) & (r < 80) & (g > 90) & (g < 150)  # the right side's line and markers
    assert band.sum() > 2000 and blue.sum() > 200
    # the band is above the points (normal 180, band to 162; the points reach 130)
    assert np.median(np.nonzero(band)[0]) < np.median(np.nonzero(blue)[0])
    # the points climb from session 1 to 3: blue pixels' height falls (image y) from left to right
    ys, xs = np.nonzero(blue)
    left, right = ys[xs < np.percentile(xs, 20)], ys[xs > np.percentile(xs, 80)]
    assert left.mean() > right.mean()


def test_a_patient_without_results_gets_a_report_and_an_unknown_one_an_error(db, tmp_path):
    html_path, _ = write_report(db, "P002", tmp_path / "p2.html")
    assert "No ROM results yet" in html_path.read_text(encoding="utf-8")
    with pytest.raises(DatabaseError, match="no patient 'P404'"):
        write_report(db, "P404", tmp_path / "x.html")


def test_games_say_who_played_and_scores_in_whole_percent(db, tmp_path):
    """A game the demo played part of says so (the table, the hatched part of the bars); the share
    of targets collected reads 22 %, not 0.222222."""
    import json

    g = db.start_session("P001", "exercise", started_utc="2026-03-02T10:00:00Z")
    details = {"active_s": 90.0, "demo_s": 30.0,
               "targets": [{"reached": True, "demo": k < 1} for k in range(2)] + [{"reached": False, "demo": False}] * 7}
    db.add_exercise_result(g, "turn_key", 2, 92.0, 2 / 9, json.dumps(details), recorded_utc="2026-03-02T10:02:00Z")
    html = write_report(db, "P001", tmp_path / "r.html")[0].read_text(encoding="utf-8")
    assert "<th>played by</th>" in html and "patient + demo (30 s)" in html and "2 (1 by the demo)" in html
    assert "22 %" in html and "0.2222" not in html
    assert html.count('<tr class="demo">') == 1


@pytest.mark.parametrize("repetitions", [0, 3])
def test_game_charts_start_at_zero_in_whole_repetitions(repetitions):
    """Issue 25: a game with no target collected drew its repetitions from -0.05 to 0.05."""
    from matplotlib.figure import Figure

    from game.db.database import ExerciseRow
    from game.report import plot_games

    row = ExerciseRow("e1", "s1", "P001", "2026-03-02T10:00:00Z", "rotation", repetitions, 27.0, 0.0, "{}",
                      "2026-03-02T10:01:00Z")
    fig = Figure()
    reps, minutes = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    plot_games(reps, minutes, [row], {"s1": 1}, ("#5ec8be",), "#a3aebe", "#333333")
    assert reps.get_ylim()[0] == 0.0 and reps.get_ylim()[1] >= max(repetitions, 1)
    assert minutes.get_ylim()[0] == 0.0 and minutes.get_ylim()[1] >= 27.0 / 60.0
    ticks = [t for t in reps.get_yticks() if reps.get_ylim()[0] <= t <= reps.get_ylim()[1]]
    assert ticks and all(t >= 0 and float(t).is_integer() for t in ticks)


def test_changes_between_sessions_are_called_real_only_beyond_the_sdc(tmp_path, monkeypatch):
    """The report says per side whether the latest change is beyond the test's smallest detectable
    change, and the table marks every change from the previous session the same way."""
    import game.report as report

    real_info = report._test_info
    monkeypatch.setattr(report, "_test_info", lambda test, standard: report._TestInfo(
        real_info(test, standard).title, 180.0, "Seated.", 9.0))
    with Database(tmp_path / "db.sqlite3") as db:
        db.add_patient("P001")
        for day, value in (("2026-01-01", 100.0), ("2026-02-01", 108.0), ("2026-03-01", 120.4)):
            s = db.start_session("P001", "rom", started_utc=f"{day}T09:00:00Z")
            db.add_rom_result(s, rom_result(value=value), recorded_utc=f"{day}T09:05:00Z")
        html_path, _ = write_report(db, "P001", tmp_path / "r.html")
    text = html_path.read_text(encoding="utf-8")
    assert "Smallest detectable change of this test: 9 degrees" in text
    # the latest change, in the summary under the test's title
    assert ('<li class="real">Right, #2 to #3: +12 degrees: beyond the smallest detectable change of 9 degrees '
            '\u2014 a real improvement</li>') in text
    # every change in the table: +8 is within the SDC, +12 beyond it
    cells = re.findall(r"<td>([^<]*(?:detectable change)[^<]*)</td>", text)
    assert cells == ["+8 degrees: within the measurement&#x27;s smallest detectable change of 9 degrees \u2014 "
                     "not a real change yet",
                     "+12 degrees: beyond the smallest detectable change of 9 degrees \u2014 a real improvement"]


def test_a_test_without_a_measured_sdc_says_changes_are_not_judged(tmp_path, monkeypatch):
    import game.report as report

    monkeypatch.setattr(report, "_test_info", lambda test, standard: report._TestInfo("Flexion", None, "", None))
    with Database(tmp_path / "db.sqlite3") as db:
        db.add_patient("P001")
        for day, value in (("2026-01-01", 100.0), ("2026-02-01", 96.0)):
            s = db.start_session("P001", "rom", started_utc=f"{day}T09:00:00Z")
            db.add_rom_result(s, rom_result(value=value), recorded_utc=f"{day}T09:05:00Z")
        text = write_report(db, "P001", tmp_path / "r.html")[0].read_text(encoding="utf-8")
    assert "No smallest detectable change has been measured for this test" in text
    assert "Right, #1 to #2: -4 degrees (no smallest detectable change measured for this test: not judged)" in text
