"""The ROM test scenes driven through actions on samples of the simulated body's exact markers
(scripted motions posed frame by frame, no tracker process): the patient picker adds the next
pseudonymous ID, the test list, the stored result (raw value, labels, flags) after Accept,
nothing stored after Discard or Repeat, compensation flagged and Repeat offered, the demo motion
sent to the tracker. The same scene on the real tracker process is tests/game/test_scene_rom_live.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from game.app import App, BaseScene, Services, Settings
from game.db import Database
from game.input import Action, Pointer, PointerKind, Press
from game.live_link import LinkState, LiveLink
from game.rom.session import RomState
from game.rom.spec import load_rom_test
from game.scenes.patients import NEW_PATIENT, PatientsScene, next_patient_id
from game.scenes.rom_test import RomTestScene, RomVisit, ChooseTestScene, previous_line, reference_line
from tracking.angles import ANGLE_COLUMNS, joint_angles
from tracking.live import LiveSample
from tracking.markerset import load_markerset
from tracking.sim.body import BodyDimensions, BodyModel, reference_pose
from tracking.sim.motions import load_motion

SIZE = (640, 360)
FPS = 15.0


class MotionLink:
    """Stands in for :class:`game.live_link.LiveLink`: a scripted motion of the simulated body,
    its exact markers as samples (``feed_until``), and a record of the motions asked for."""

    problem = LiveLink.problem  # the real words for the link's state

    def __init__(self) -> None:
        self.markerset = load_markerset("upper_limb_seated")
        self.dims = BodyDimensions.from_percentile(50, "male")
        self.body = BodyModel(self.dims, self.markerset)
        self.angle_names = tuple(ANGLE_COLUMNS)
        self.state = LinkState.RUNNING
        self.error = ""
        self.latest = None
        self.new_samples: list = []
        self.motions: list = []
        self.motion = None
        self._queue: list = []
        self.n = 0
        self.motion_t0 = 0
        self.estimated: set[str] = set()   # markers published as estimated (hidden) in every sample

    def set_motion(self, name) -> None:
        self.motions.append(name)
        self.motion = None if name is None else load_motion(name, self.dims)
        self.motion_t0 = self.n

    def reidentify(self) -> None:
        pass

    def queue(self, n_frames: int) -> list[LiveSample]:
        """``n_frames`` more samples of the motion playing (in a loop, as the tracker process plays it)."""
        out = []
        for _ in range(n_frames):
            t = (self.n - self.motion_t0) / FPS
            pose = reference_pose() if self.motion is None else self.motion.pose_at(t % self.motion.duration_s)
            truth = self.body.markers_m(pose)
            angles = joint_angles(truth, self.markerset.names)
            m = len(truth)
            sample = LiveSample(
                frame_index=self.n, time_s=self.n / FPS, t_frame_ready_s=self.n / FPS, t_published_s=self.n / FPS,
                state=1, positions_m=truth,
                status=np.array([2 if n in self.estimated else 1 for n in self.markerset.names], np.uint8),
                angles_deg=np.array([angles[a] for a in self.angle_names]), message="",
                windows_px=np.full((m, 1, 3), np.nan), uv_px=np.full((m, 1, 2), np.nan), truth_m=truth,
                number=self.n, angle_names=self.angle_names)
            self.n += 1
            out.append(sample)
        self._queue += out
        return out

    def tick(self) -> None:
        self.new_samples, self._queue = self._queue, []
        if self.new_samples:
            self.latest = self.new_samples[-1]

    def summary(self) -> str:
        return "test link"


@pytest.fixture
def screen(open_headless):
    return open_headless(SIZE)


@pytest.fixture
def db_path(tmp_path):
    path = tmp_path / "clinic.sqlite3"
    with Database(path) as db:
        db.add_patient("P001")
    return path


def make_app(screen, link):
    app = App(screen, Settings(show_fps=False, max_fps=0), clock=lambda: 0.0, sleep=lambda s: None,
              services=Services(link), events=lambda: [])
    app.push(BaseScene())
    return app


def run_test(app, link, scene, *, frames_per_tick: int = 4, limit_s: float = 40.0):
    """Frames until the attempt is done; returns the samples fed."""
    fed = []
    while scene.state != RomState.DONE and len(fed) < limit_s * FPS:
        fed += link.queue(frames_per_tick)
        app.frame()
    return fed


def true_max(test, side, samples, result) -> float:
    """Maximum of the test value from the exact markers over the recording."""
    names = load_markerset("upper_limb_seated").names
    values = [test.direction * joint_angles(s.truth_m, names)[test.angle_name(side)]
              for s in samples if result.started_s - 1e-9 <= s.time_s <= result.ended_s + 1e-9]
    return float(np.nanmax(values))


# ---------------------------------------------------------------------------- patients
def test_next_patient_id_follows_the_highest_number():
    assert next_patient_id([]) == "P001"
    assert next_patient_id(["P001", "P009", "X7", "P010b"]) == "P010"
    assert next_patient_id(["P1234"]) == "P1235"


def test_patient_picker_lists_ids_adds_a_new_one_and_opens_the_next_scene(screen, db_path):
    app = make_app(screen, MotionLink())
    opened = []

    class Next(BaseScene):
        def __init__(self, pid):
            opened.append(pid)

    picker = PatientsScene(db_path, Next, title="ROM test: choose the patient")
    app.push(picker)
    assert picker.entries == [NEW_PATIENT, "P001"]
    assert picker.selected == 1                            # the patient, not "New patient": Enter adds none
    app.dispatch(Press(Action.SELECT))
    assert opened == ["P001"] and isinstance(app.scene, Next)
    with Database(db_path) as db:
        assert [p.id for p in db.patients()] == ["P001"]
    # new patient: the next ID is added to the database and chosen (mouse click on the first row)
    picker = PatientsScene(db_path, Next, title="again")
    app.push(picker)
    x, y, w, h = picker._rects()[0]
    app.dispatch(Pointer(PointerKind.PRESS, (x + w / 2) / SIZE[0], (y + h / 2) / SIZE[1], button=1))
    assert opened[-1] == "P002"
    with Database(db_path) as db:
        assert [p.id for p in db.patients()] == ["P001", "P002"]
    # the progress picker offers no new patient
    assert PatientsScene(db_path, Next, title="x", allow_new=False).entries == []  # not entered yet: nothing read
    progress_picker = PatientsScene(db_path, Next, title="x", allow_new=False)
    app.push(progress_picker)
    assert progress_picker.entries == ["P001", "P002"]


def test_test_list_shows_the_sides_tests_and_opens_one(screen, db_path):
    link = MotionLink()
    app = make_app(screen, link)
    opened = []
    visit = RomVisit(db_path, "P001")

    def open_test(v, test, side):
        opened.append((test.name, side))
        return BaseScene()

    choice = ChooseTestScene(visit, open_test)
    app.push(choice)
    right = [t.name for t in choice.tests]
    assert "shoulder_flexion" in right and len(right) == 10
    app.dispatch(Press(Action.RIGHT))                       # the other side
    assert choice.side == "left"
    assert all("left" in t.sides for t in choice.tests)
    idx = [t.name for t in choice.tests].index("shoulder_flexion")
    choice.selected = idx
    app.frame()
    app.dispatch(Press(Action.SELECT))
    assert opened == [("shoulder_flexion", "left")]
    assert reference_line(load_rom_test("shoulder_external_rotation"), "aaos").startswith("AAOS 90 was measured")
    assert reference_line(load_rom_test("shoulder_flexion"), "jarm") == "JARM normal 180\N{DEGREE SIGN} (seated arm at side)"


# ---------------------------------------------------------------------------- the test
def test_accept_stores_the_raw_maximum_with_its_labels(screen, db_path):
    link = MotionLink()
    app = make_app(screen, link)
    test = load_rom_test("shoulder_flexion")
    visit = RomVisit(db_path, "P001", "jarm")
    scene = RomTestScene(link, visit, test, "right", demo=True)
    app.push(scene)
    assert link.motions == ["shoulder_flexion"]             # the demo plays the test's motion
    fed = run_test(app, link, scene)
    assert scene.state == RomState.DONE
    result = scene.session.result
    truth = true_max(test, "right", fed, result)
    assert abs(result.max_deg - truth) < 3.0
    assert not result.compensated and not result.estimated
    assert [b.key for b in scene.buttons()] == ["accept", "repeat", "discard"] and scene.selected == 0
    app.frame()
    app.dispatch(Press(Action.SELECT))                      # Accept
    assert scene.state == RomState.ACCEPTED
    visit.close()
    with Database(db_path) as db:
        rows = db.rom_results("P001")
        sessions = db.sessions("P001")
    assert len(rows) == 1
    row = rows[0]
    assert row.value_deg == pytest.approx(result.max_deg)   # stored raw
    assert row.value_deg != result.rounded_deg
    assert (row.test, row.side, row.mode, row.standard, row.reference_deg) == (
        "shoulder_flexion", "right", "active", "jarm", 180.0)
    assert row.position == "seated_arm_at_side" and row.compensation == "" and row.estimated_markers == ""
    assert len(sessions) == 1 and sessions[0].ended_utc and sessions[0].source == "sim:shoulder_flexion"
    # the stored result is listed as a previous result, rounded to 5
    assert [previous_line(r) for r in scene.previous] == [previous_line(row)]
    assert f"{round(result.max_deg / 5) * 5}\N{DEGREE SIGN}" in previous_line(row)


def test_discard_and_repeat_store_nothing(screen, db_path):
    link = MotionLink()
    app = make_app(screen, link)
    visit = RomVisit(db_path, "P001")
    choice = ChooseTestScene(visit, lambda v, t, s: RomTestScene(link, v, t, s, demo=True))
    app.push(choice)
    choice.selected = [t.name for t in choice.tests].index("elbow_flexion")
    app.dispatch(Press(Action.SELECT))
    scene = app.scene
    assert isinstance(scene, RomTestScene) and scene.test.name == "elbow_flexion"
    run_test(app, link, scene)
    assert scene.state == RomState.DONE
    app.dispatch(Press(Action.RIGHT))
    app.dispatch(Press(Action.SELECT))                      # Repeat: a new attempt
    assert scene.state in (RomState.WAITING_TRACKER, RomState.CHECKING_START, RomState.RECORDING)
    run_test(app, link, scene)
    assert scene.state == RomState.DONE
    scene.press("discard")                                  # Discard: back to the list
    assert app.scene is choice
    app.dispatch(Press(Action.BACK))
    with Database(db_path) as db:
        assert db.rom_results("P001") == [] and db.sessions("P001") == []


def test_compensation_is_flagged_and_repeat_offered_first(screen, db_path):
    link = MotionLink()
    app = make_app(screen, link)
    test = load_rom_test("shoulder_flexion")
    scene = RomTestScene(link, RomVisit(db_path, "P001"), test, "right")
    app.push(scene)
    assert link.motions == [None]                           # no demo: the patient moves themselves
    link.set_motion("trunk_lean_compensation")              # a clean repetition, then one with trunk lean
    run_test(app, link, scene)
    first = scene.session.result
    assert not first.compensated
    scene.press("repeat")
    run_test(app, link, scene)
    second = scene.session.result
    assert second.compensated and any("trunk leaned" in c for c in second.compensations)
    assert scene.selected == 1                              # Repeat is chosen
    assert scene.status_line()[0].startswith("Compensation seen")
    app.frame()
    # the therapist may still accept it: it is stored flagged
    scene.press("accept")
    with Database(db_path) as db:
        (row,) = db.rom_results("P001")
    assert "trunk leaned" in row.compensation


def test_demo_button_toggles_the_motion_and_restarts_the_attempt(screen, db_path):
    link = MotionLink()
    app = make_app(screen, link)
    scene = RomTestScene(link, RomVisit(db_path, "P001"), load_rom_test("shoulder_abduction"), "right")
    app.push(scene)
    link.queue(2)
    app.frame()
    keys = [b.key for b in scene.buttons()]
    assert keys == ["demo", "restart", "back"]
    app.dispatch(Press(Action.NEXT_MOTION))
    assert scene.demo and link.motions[-1] == "shoulder_abduction"
    assert scene.buttons()[0].label == "Stop the demo"
    scene.press("demo")
    assert not scene.demo and link.motions[-1] is None
    app.dispatch(Press(Action.BACK))
    assert not isinstance(app.scene, RomTestScene)


def test_the_scene_draws_the_readout_and_buttons(screen, db_path):
    link = MotionLink()
    app = make_app(screen, link)
    scene = RomTestScene(link, RomVisit(db_path, "P001"), load_rom_test("shoulder_flexion"), "right", demo=True)
    app.push(scene)
    run_test(app, link, scene)
    app.frame()
    rgb = screen.read_rgb().astype(int)
    x0, right, bottom = scene._panel()
    s = scene.scale
    # the big number (light text) in the readout area
    readout = rgb[round(120 * s):round(260 * s), round(x0):round(x0 + 250 * s)]
    assert (readout.min(axis=2) > 200).sum() > 400
    # the selected button (Accept) has the teal edge
    def teal(rect):
        bx, by, bw, bh = rect
        part = rgb[round(by):round(by + bh), round(bx):round(bx + bw)]
        return int((np.abs(part - np.array((94, 200, 190))).sum(axis=2) < 60).sum())

    accept, repeat, _ = scene._button_rects(3)
    assert teal(accept) > 100 and teal(repeat) < 10
    assert math.isfinite(scene.session.result.max_deg)


def test_a_maximum_on_estimated_markers_is_marked_and_stored_so(screen, db_path):
    link = MotionLink()
    link.estimated = {"MRE2"}                               # the medial elbow marker hidden by the trunk
    app = make_app(screen, link)
    scene = RomTestScene(link, RomVisit(db_path, "P001"), load_rom_test("shoulder_extension"), "right", demo=True)
    app.push(scene)
    run_test(app, link, scene)
    result = scene.session.result
    assert result.estimated_markers == ("MRE2",)
    app.frame()
    rgb = screen.read_rgb().astype(int)
    x0, right, _ = scene._panel()
    s = scene.scale
    line = rgb[round(270 * s):round(310 * s), round(x0):round(right)]   # the amber "relied on estimated" line
    assert (np.abs(line - np.array((242, 190, 92))).sum(axis=2) < 60).sum() > 50
    scene.press("accept")
    with Database(db_path) as db:
        (row,) = db.rom_results("P001")
    assert row.estimated_markers == "MRE2" and row.test == "shoulder_extension"
    assert "estimated markers" in previous_line(row)


@pytest.mark.parametrize("size", [(1280, 720), (1600, 1000)])
def test_the_start_message_names_each_angle_with_its_value_and_range(open_headless, db_path, size):
    """Shoulder external rotation with the arm hanging: the message says which angles are off, with
    their values and ranges, in full (it once lost the first angle's name and value where it was
    split at the first parenthesis) and fits the panel at the window's size."""
    screen = open_headless(size)
    link = MotionLink()
    app = make_app(screen, link)
    scene = RomTestScene(link, RomVisit(db_path, "P001"), load_rom_test("shoulder_external_rotation"), "right")
    app.push(scene)
    link.set_motion(None)                                   # the reference pose: the elbow straight
    for _ in range(4):
        link.queue(2)
        app.frame()
    assert scene.state == RomState.CHECKING_START
    elbow = joint_angles(link.latest.truth_m, link.markerset.names)["right_elbow_flexion"]
    text, _ = scene.status_line()
    assert text == (f"Get into the start position: elbow flexion {elbow:.0f} (needs 65 to 115); "
                    "shoulder external rotation not measured")
    x, right, _ = scene._panel()
    lines, text_size, _ = scene.status_lines(app.canvas, right - x)
    assert " ".join(lines) == text                         # nothing cut off
    assert all(app.canvas.measure(line, text_size)[0] <= right - x for line in lines)
