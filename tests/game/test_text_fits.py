"""Text fits, at 1280x720 and at a larger window: every line the scenes write in a frame lies
inside the window, no two lines overlap, and no dot of a dial or gauge lies on a line. Checked on
the screens where text collided: the live view with a long motion title, the ROM test with a long
title beside the patient ID, the progress review's list (long test names beside both sides'
values) and its games chart, and the key game's dial with the forearm turned past its end."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from game.app import App, BaseScene, Services, Settings
from game.db import Database
from game.exergames.session import GameLog
from game.exergames.visit import store_log
from game.exergames.spec import load_game
from game.rom.session import RomResult, RomState
from game.rom.spec import load_rom_test
from game.scenes.game_play import GameScene
from game.scenes.live import LiveScene
from game.scenes.progress import ProgressScene
from game.scenes.rom_test import RomTestScene, RomVisit
from tracking.sim.body import ArmPose, reference_pose
from tracking.sim.motions import available_motions

from test_scene_rom import MotionLink, db_path  # noqa: F401 - db_path: the fixture (P001, no results)
from test_scenes_live import BodyLink, Clock

SIZES = [(1280, 720), (1600, 1000)]


class Recorder:
    """Wraps a canvas's ``text`` and ``circle`` for one frame: what was written where."""

    def __init__(self, canvas) -> None:
        self.canvas = canvas
        self.texts: list[tuple[str, tuple[float, float, float, float]]] = []
        self.circles: list[tuple[float, float, float]] = []
        self._text, self._circle = canvas.text, canvas.circle

    def __enter__(self):
        def text(t, pos, size, colour, **kw):
            rect = self._text(t, pos, size, colour, **kw)
            if t.strip():
                self.texts.append((t, rect))
            return rect

        def circle(centre, radius, fill, **kw):
            self.circles.append((float(centre[0]), float(centre[1]), float(radius)))
            return self._circle(centre, radius, fill, **kw)

        self.canvas.text, self.canvas.circle = text, circle
        return self

    def __exit__(self, *exc) -> None:
        del self.canvas.text, self.canvas.circle


def _overlap(a, b) -> float:
    """Area of the intersection of two (x, y, w, h) rectangles."""
    w = min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0])
    h = min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1])
    return max(w, 0.0) * max(h, 0.0)


def assert_text_fits(rec: Recorder, size_px) -> None:
    w, h = size_px
    for text, (x, y, tw, th) in rec.texts:
        assert x >= -1 and y >= -1 and x + tw <= w + 1 and y + th <= h + 1, (text, (x, y, tw, th))
    for i, (ta, a) in enumerate(rec.texts):
        for tb, b in rec.texts[i + 1:]:
            # a line's box includes its leading: touching lines share a few pixels, words do not
            assert _overlap(a, b) <= 0.15 * min(a[2] * a[3], b[2] * b[3]), (ta, a, tb, b)
    for cx, cy, r in rec.circles:
        for text, (x, y, tw, th) in rec.texts:
            box = (x + 2, y + 0.2 * th, tw - 4, 0.6 * th)          # the glyphs, not the leading
            assert _overlap((cx - r, cy - r, 2 * r, 2 * r), box) <= 0.1 * (2 * r) ** 2, (text, (cx, cy, r))


def frame_texts(app: App) -> Recorder:
    with Recorder(app.canvas) as rec:
        app.frame()
    return rec


@pytest.fixture
def clinic(tmp_path):
    """A patient with every ROM test on both sides over three sessions, and three games played
    (one by the automatic demo)."""
    db_path = tmp_path / "clinic.sqlite3"
    tests = ("shoulder_flexion", "shoulder_abduction", "elbow_flexion", "shoulder_external_rotation",
             "shoulder_internal_rotation", "forearm_supination", "forearm_pronation", "shoulder_extension",
             "shoulder_horizontal_flexion", "shoulder_horizontal_extension")
    with Database(db_path) as db:
        db.add_patient("P001")
        for k in range(3):
            session = db.start_session("P001", "rom", source="test")
            for i, test in enumerate(tests):
                for side in ("right", "left"):
                    value = 100.0 + 5 * i + 10 * k + (5 if side == "left" else 0)
                    db.add_rom_result(session, RomResult(
                        test=test, title=test, side=side, angle=f"{side}_{test}", direction=1, mode="active",
                        position="p", position_words="Seated.", standard="jarm", reference_deg=None,
                        max_deg=value, start_deg=3.0, range_deg=value - 3.0, max_time_s=1.0, started_s=0.0,
                        ended_s=5.0, compensations=(), estimated_markers=(), n_samples=100))
            db.end_session(session)
    for game, reached in (("reach", 12), ("rotation", 7), ("turn_key", 9)):
        # the key game played by the demo: its bars hatched, "played by the demo" in the legend
        store_log(db_path, "P001", GameLog(game, "right", reached=reached, missed=3, started_s=0.0, ended_s=60.0,
                                           active_s=55.0, demo_s=55.0 if game == "turn_key" else 0.0,
                                           level_start=0.3, level_end=0.4), source="test")
    return db_path


@pytest.mark.parametrize("size", SIZES)
def test_progress_review(open_headless, clinic, size):
    app = App(open_headless(size), Settings(show_fps=False), clock=lambda: 0.0, events=lambda: [])
    app.push(BaseScene())
    app.push(ProgressScene(clinic, "P001"))
    try:
        rec = frame_texts(app)
        assert_text_fits(rec, size)
        # every test is listed, and both sides' values beside it
        assert sum(t.startswith("R ") and " L " in t for t, _ in rec.texts) == 10
    finally:
        app.close()


@pytest.mark.parametrize("size", SIZES)
def test_rom_test_long_title_beside_the_patient(open_headless, db_path, size):
    link = MotionLink()
    app = App(open_headless(size), Settings(show_fps=False, max_fps=0), clock=lambda: 0.0, sleep=lambda s: None,
              services=Services(link), events=lambda: [])
    app.push(BaseScene())
    scene = RomTestScene(link, RomVisit(db_path, "P001"), load_rom_test("shoulder_external_rotation"), "right")
    app.push(scene)
    try:
        link.queue(3)
        rec = frame_texts(app)
        assert_text_fits(rec, size)
        assert any("Patient P001" in t for t, _ in rec.texts)
        assert any(t.startswith("Shoulder external rotation") for t, _ in rec.texts)
        # the result: the raw maximum, the range moved and the start it is counted from
        link.set_motion("right_external_rotation")
        for _ in range(600):
            if scene.state == RomState.DONE:
                break
            link.queue(4)
            app.frame()
        assert scene.state == RomState.DONE
        rec = frame_texts(app)
        assert_text_fits(rec, size)
        r = scene.session.result
        assert f"moved {r.range_deg:.0f}\N{DEGREE SIGN} from the start" in [t for t, _ in rec.texts]
        assert any(t.startswith("(the start position read") for t, _ in rec.texts)
    finally:
        app.close()


@pytest.mark.parametrize("size", SIZES)
def test_live_view_every_motion_title(open_headless, size):
    clock = Clock()
    link = BodyLink(clock)
    app = App(open_headless(size), Settings(show_fps=False, max_fps=0), clock=clock, sleep=lambda s: None,
              services=Services(link), events=lambda: [])
    app.push(BaseScene())
    scene = LiveScene(link, motions=[None, "elbow_flexion_supination"], motion="elbow_flexion_supination",
                      open_monitor=lambda: None, make_avatar=None)
    app.push(scene)
    try:
        for motion in (*available_motions(), "a_motion_file_of_the_clinic_with_a_long_descriptive_name"):
            scene.motion = motion          # every title the panel may show
            link.feed(reference_pose())
            rec = frame_texts(app)
            assert_text_fits(rec, size)
    finally:
        app.close()


@pytest.mark.parametrize("size", SIZES)
def test_key_game_dial_with_the_forearm_turned_past_its_end(open_headless, db_path, size):
    """The forearm turned 88 degrees (the dial ends at 52): the needle stays on the dial, above
    the instructions."""
    clock = Clock()
    link = BodyLink(clock)
    link.motion_names = []
    app = App(open_headless(size), Settings(show_fps=False, max_fps=0), clock=clock, sleep=lambda s: None,
              services=Services(link), events=lambda: [])
    app.push(BaseScene())
    scene = GameScene(link, load_game("turn_key"), "right", db_path, "P001", mute=True)
    app.push(scene)
    try:
        pose = reference_pose()
        pose = pose.with_arm("right", ArmPose.clinical(elbow_flexion_deg=90.0, forearm_supination_deg=88.0))
        link.feed(pose)
        rec = frame_texts(app)
        assert scene.session.value_now() > 80.0
        assert_text_fits(rec, size)
    finally:
        app.close()


@pytest.mark.parametrize("size", SIZES)
def test_game_menu_limits(open_headless, db_path, size):
    """The game menu with its limits in words (the game's own, or set for this patient)."""
    from game.exergames.limits import LIMIT_KEYS
    from game.input import Action, Press
    from game.scenes.game_menu import ChooseGameScene

    app = App(open_headless(size), Settings(show_fps=False), clock=lambda: 0.0, events=lambda: [])
    app.push(BaseScene())
    menu = ChooseGameScene("P001", lambda spec, pid, **kw: BaseScene(), db_path=db_path)
    app.push(menu)
    try:
        for name in [g.name for g in menu.games]:
            menu.selected = [g.name for g in menu.games].index(name)
            menu.handle(Press(Action.SELECT))                 # its column: Play and the limits
            rec = frame_texts(app)
            assert_text_fits(rec, size)
            assert sum("the game's own" in t for t, _ in rec.texts) == len(LIMIT_KEYS)
            menu.handle(Press(Action.BACK))
    finally:
        app.close()


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("interactive", [True, False])
def test_live_view_explains_why_the_rest_pose_reads_below_zero(open_headless, size, interactive):
    """Issue 25: the patient at rest read -11 degrees of shoulder flexion and trunk forward lean
    with nothing to say why (the sternum markers' slope, tests/test_rest_pose_angles.py)."""
    from game.scenes.live import REST_NOTE

    clock = Clock()
    link = BodyLink(clock)
    app = App(open_headless(size), Settings(show_fps=False, max_fps=0), clock=clock, sleep=lambda s: None,
              services=Services(link), events=lambda: [])
    app.push(BaseScene())
    app.push(LiveScene(link, motions=[None, "reference"], motion=None if interactive else "reference",
                       open_monitor=lambda: None, make_avatar=None))
    try:
        link.feed(reference_pose())
        rec = frame_texts(app)
        assert_text_fits(rec, size)
        texts = [t for t, _ in rec.texts]
        assert "-11\N{DEGREE SIGN}" in texts      # the reading it explains
        words = REST_NOTE.format(example=" (-11\N{DEGREE SIGN} on the simulated patient)").split()
        drawn = " ".join(texts).split()
        start = drawn.index("(upright,") - 2
        assert drawn[start:start + len(words)] == words  # every word of it, in order
    finally:
        app.close()


@pytest.mark.parametrize("size", SIZES)
def test_rom_test_list_titles_stay_inside_their_rows(open_headless, db_path, size):
    """Issue 25's walk-through: "Shoulder external rotation (arm at the side)" ran past its row's
    highlight at 1280x720."""
    from game.scenes.rom_test import ChooseTestScene

    app = App(open_headless(size), Settings(show_fps=False), clock=lambda: 0.0, events=lambda: [])
    app.push(BaseScene())
    choice = ChooseTestScene(RomVisit(db_path, "P001"), lambda *a: BaseScene())
    app.push(choice)
    try:
        for selected in range(len(choice.tests)):
            choice.selected = selected
            rec = frame_texts(app)
            assert_text_fits(rec, size)
            rows = choice._layout()[1]
            for test, (rx, ry, rw, rh) in zip(choice.tests, rows):
                drawn = [(t, r) for t, r in rec.texts if rx < r[0] < rx + rw and r[1] >= ry - 1 and r[1] + r[3] <= ry + rh + 1]
                assert drawn, test.title
                for t, (x, y, tw, th) in drawn:
                    assert x + tw <= rx + rw - 8, (t, x + tw, rx + rw)
    finally:
        app.close()


class _PlayedGame(BaseScene):
    """A game scene as the menu sees it once it has ended: stored (an id) or not (the reason)."""

    def __init__(self, stored_uid, store_error="", reached=3, missed=1) -> None:
        super().__init__()
        self.stored_uid, self.store_error = stored_uid, store_error
        self.session = SimpleNamespace(log=SimpleNamespace(reached=reached, missed=missed))


@pytest.mark.parametrize("size", SIZES)
def test_game_menu_says_the_last_game_was_saved_or_why_not(open_headless, db_path, size):
    """Back from a game (Esc: end and save), the menu says in a line that the session is stored,
    with its count, or why it is not; nothing before a game or for one that never started."""
    from game.scenes.game_menu import ChooseGameScene

    app = App(open_headless(size), Settings(show_fps=False), clock=lambda: 0.0, events=lambda: [])
    app.push(BaseScene())
    outcomes = iter([_PlayedGame("uid-1"), _PlayedGame(None, "the database is read-only"), _PlayedGame(None)])
    menu = ChooseGameScene("P001", lambda spec, pid, **kw: next(outcomes), db_path=db_path)
    app.push(menu)
    try:
        assert not any(t.startswith("Saved") for t, _ in frame_texts(app).texts)
        title = menu.game.title
        expected = [f"Saved: {title}, 3 collected, 1 missed", f"{title}: not saved (the database is read-only)", None]
        for want in expected:
            menu.start()
            app.pop()                                         # the game ends (Esc)
            rec = frame_texts(app)
            assert_text_fits(rec, size)
            lines = [t for t, _ in rec.texts if t.startswith("Saved") or "not saved" in t]
            assert lines == ([want] if want else [])
    finally:
        app.close()
