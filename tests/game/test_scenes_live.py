"""The live mirror on synthetic samples (the simulator's exact markers, no tracker process):
keys and pointer -> the interactive patient's input, the mirror (the patient's right on the
screen's right, in pixels), angle readouts, the tracker's states, the camera grid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from game.app import App, BaseScene, Services, Settings
from game.gfx import theme
from game.gfx.view3d import project_px
from game.input import Action, Pointer, PointerKind, Press
from game.live_link import LinkState, LiveLink
from game.avatar.live import LiveAvatar
from game.scenes.live import ARM_ROWS, ControlLimits, LiveScene, PatientControl, format_angle, live_layout, truth_error_mm
from game.scenes.monitor import MonitorScene, grid_rects, image_to_screen
from tracking.angles import ANGLE_COLUMNS, joint_angles
from tracking.live import LiveSample
from tracking.live.source import angle_names_for
from tracking.markerset import load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose, reference_pose

SIZE = (640, 360)


class BodyLink:
    """Stands in for :class:`game.live_link.LiveLink`: samples of the simulated body's exact
    markers for the poses the test sets, and a record of the commands sent."""

    problem = LiveLink.problem  # the real words for the link's state

    def __init__(self, clock, markerset: str = "upper_limb_seated") -> None:
        self.markerset = load_markerset(markerset)
        self.body = BodyModel(BodyDimensions.from_percentile(50, "male"), self.markerset)
        self.angle_names = angle_names_for(self.markerset)
        self.cameras = ()
        self.clock = clock
        self.state = LinkState.RUNNING
        self.error = ""
        self.warning = ""
        self.latest = None
        self.new_samples: list = []
        self.sent: list = []
        self.motions: list = []
        self.reidentified = 0
        self._queue: list = []
        self._n = 0

    def feed(self, pose, *, state: int = 1, message: str = "", status=None) -> LiveSample:
        truth = self.body.markers_m(pose)
        m = len(truth)
        status = np.ones(m, np.uint8) if status is None else np.asarray(status, np.uint8)
        p = np.where((status == 0)[:, None], np.nan, truth)   # lost markers have no position
        angles = joint_angles(p, self.markerset.names, roles=self.markerset.roles)
        sample = LiveSample(
            frame_index=self._n, time_s=self._n / 30, t_frame_ready_s=self.clock() - 0.001 * (10 - self._n % 10),
            t_published_s=self.clock(), state=state, positions_m=p,
            status=status,
            angles_deg=np.array([angles[n] for n in self.angle_names], dtype=np.float64), message=message,
            windows_px=np.full((m, 1, 3), np.nan), uv_px=np.full((m, 1, 2), np.nan), truth_m=truth,
            number=self._n, angle_names=self.angle_names)
        self._n += 1
        self._queue.append(sample)
        return sample

    def tick(self) -> None:
        self.new_samples, self._queue = self._queue, []
        if self.new_samples:
            self.latest = self.new_samples[-1]

    def summary(self) -> str:
        return "test link"

    def latest_images(self):
        return None

    def set_patient_input(self, value) -> None:
        self.sent.append(value)

    def set_motion(self, name) -> None:
        self.motions.append(name)

    def reidentify(self) -> None:
        self.reidentified += 1


class Clock:
    def __init__(self) -> None:
        self.now_s = 1000.0

    def __call__(self) -> float:
        return self.now_s


@pytest.fixture
def screen(open_headless):
    return open_headless(SIZE)


def make_app(screen, *, motion=None, avatar=True, markerset="upper_limb_seated"):
    clock = Clock()
    link = BodyLink(clock, markerset)
    app = App(screen, Settings(show_fps=False, max_fps=0), clock=clock, sleep=lambda s: None,
              services=Services(link), events=lambda: [])
    app.push(BaseScene())
    scene = LiveScene(link, motions=[None, "shoulder_flexion", "reach"], motion=motion,
                      open_monitor=lambda: MonitorScene(link),
                      make_avatar=(lambda ctx, names, roles: LiveAvatar(ctx, names, roles=roles)) if avatar else None)
    app.push(scene)
    return app, scene, link, clock


def run_frames(app, clock, n=3, dt=1 / 60):
    for _ in range(n):
        app.frame()
        clock.now_s += dt


# ---------------------------------------------------------------------------- patient control
def test_held_keys_turn_the_forearm_and_lean_the_trunk_back_to_upright():
    c = PatientControl(ControlLimits(forearm_speed_deg_s=90, lean_speed_deg_s=30))
    c.held = {Action.ROTATE_OUT, Action.UP}
    for _ in range(60):
        c.update(1 / 120)
    assert c.forearm_deg == pytest.approx(45.0)
    assert c.forward_lean_deg == pytest.approx(15.0)
    c.held = {Action.LEFT}
    for _ in range(120):
        c.update(1 / 120)
    assert c.forearm_deg == pytest.approx(45.0)            # stays where it was turned
    assert c.forward_lean_deg == pytest.approx(0.0)        # back upright
    assert c.lateral_lean_deg == pytest.approx(-25.0)      # left arrow: the patient's left, at the limit
    c.held = {Action.ROTATE_IN}
    for _ in range(600):
        c.update(1 / 120)
    assert c.forearm_deg == pytest.approx(-85.0)
    c.switch_arm()
    assert c.side == "left" and c.hand_target_m is None and c.forearm_deg == 0.0
    c.wheel(100)
    assert c.depth_m == pytest.approx(0.55)


def test_pointer_moves_the_hand_like_a_mirror(screen):
    app, scene, link, clock = make_app(screen)
    link.feed(reference_pose())
    run_frames(app, clock)
    view = live_layout(SIZE).view
    shoulder = link.body.markers_m(reference_pose())[link.markerset.names.index("MRS")]

    def aim(fx, fy):
        app.dispatch(Pointer(PointerKind.MOVE, (view.x + fx * view.w) / SIZE[0], (view.y + fy * view.h) / SIZE[1]))
        return np.array(scene.control.hand_target_m)

    right, left, up = aim(0.8, 0.5), aim(0.2, 0.5), aim(0.5, 0.1)
    assert right[0] > shoulder[0] + 0.2 > left[0]          # screen right = the patient's right (+X)
    assert up[1] > shoulder[1] + 0.2                        # screen up = world up
    assert right[2] == pytest.approx(shoulder[2] - scene.control.depth_m)
    # the target lies under the pointer
    xy = project_px(right[None], scene.proj_m @ scene.view_m, view)[0]
    assert xy == pytest.approx([view.x + 0.8 * view.w, view.y + 0.5 * view.h], abs=0.5)
    # the wheel moves the hand's plane forward (and re-aims at the pointer)
    app.dispatch(Pointer(PointerKind.WHEEL, (view.x + 0.5 * view.w) / SIZE[0], (view.y + 0.1 * view.h) / SIZE[1],
                         wheel=2))
    assert scene.control.depth_m == pytest.approx(0.35)
    run_frames(app, clock, 2)
    assert link.sent[-1].side == "right"
    target = np.array(link.sent[-1].hand_target_m)
    assert target[2] == pytest.approx(shoulder[2] - 0.35)
    assert target[1] > shoulder[1] + 0.2
    # keys reach the patient input; Tab switches the arm
    app.dispatch(Press(Action.ROTATE_OUT))
    run_frames(app, clock, 30, dt=1 / 60)
    app.dispatch(Press(Action.ROTATE_OUT, down=False))
    app.dispatch(Press(Action.SWITCH_ARM))
    run_frames(app, clock, 2)
    assert any(v.forearm_rotation_deg > 20 and v.side == "right" for v in link.sent)
    assert link.sent[-1].side == "left"


def test_motions_reidentify_camera_check_and_back(screen):
    app, scene, link, clock = make_app(screen, avatar=False)
    assert link.motions == [None]                 # entering sets mouse control
    app.dispatch(Press(Action.NEXT_MOTION))
    app.dispatch(Press(Action.NEXT_MOTION))
    assert scene.motion == "reach" and link.motions[-2:] == ["shoulder_flexion", "reach"]
    n_sent = len(link.sent)
    app.dispatch(Pointer(PointerKind.MOVE, 0.3, 0.5))
    run_frames(app, clock, 2)
    assert len(link.sent) == n_sent                # a scripted motion ignores the mouse
    app.dispatch(Press(Action.NEXT_MOTION))
    assert scene.motion is None
    app.dispatch(Press(Action.REIDENTIFY))
    assert link.reidentified == 1
    app.dispatch(Press(Action.MONITOR))
    assert isinstance(app.scene, MonitorScene)
    run_frames(app, clock, 2)                       # no images yet: draws the waiting line
    quiet = app.screen.read_rgb().astype(np.int32)
    link.warning = "camera cam2 stopped: tracking goes on with cam1, cam3, cam4"
    run_frames(app, clock, 1)                       # the warning is written top right, in the title band
    changed = np.abs(app.screen.read_rgb().astype(np.int32) - quiet).sum(axis=2) > 60
    h, w = changed.shape
    assert changed[: h // 10, w // 2:].sum() > 100 and changed[h // 10:].sum() == 0
    link.warning = ""
    app.dispatch(Press(Action.BACK))
    assert app.scene is scene
    app.dispatch(Press(Action.BACK))
    assert app.scene is not scene and app.running


def _render(app, clock, link, pose, n=4):
    for _ in range(n):
        link.feed(pose)
        app.frame()
        clock.now_s += 1 / 30
    return app.screen.read_rgb().astype(np.int32)


def test_the_avatar_is_a_mirror_image_in_pixels(screen):
    app, scene, link, clock = make_app(screen, motion="shoulder_flexion")
    rest = reference_pose()
    raised = rest.with_arm("right", ArmPose.clinical(abduction_deg=90.0))
    a = _render(app, clock, link, rest)
    b = _render(app, clock, link, raised)
    view = live_layout(SIZE).view
    changed = np.abs(a - b).sum(axis=2) > 60
    ys, xs = np.nonzero(changed[:, : int(view.w)])
    assert len(xs) > 400                                    # the arm moved on the screen
    centre = project_px(link.body.markers_m(rest)[[link.markerset.names.index("MB")]],
                        scene.proj_m @ scene.view_m, view)[0][0]
    assert np.mean(xs > centre) > 0.9                       # and it is on the screen's right


def test_a_one_arm_marker_set_drives_the_avatar_and_the_readouts_through_its_roles(screen):
    """right_arm_seated (other names, no left arm): the avatar is built from it and raises its
    right arm on the screen's right, the right arm's angles read, the left arm's are withheld,
    and the hand is aimed from the right shoulder marker found by its role."""
    app, scene, link, clock = make_app(screen, motion="shoulder_flexion", markerset="right_arm_seated")
    assert link.angle_names == tuple(c for c in ANGLE_COLUMNS if not c.startswith("left_"))
    rest = reference_pose()
    raised = rest.with_arm("right", ArmPose.clinical(abduction_deg=90.0))
    a = _render(app, clock, link, rest)
    assert scene.feed.avatar is not None
    assert scene.feed.avatar.skeleton.update(link.latest.positions_m, link.latest.status).segment_state(
        "left_forearm").name == "LOST"
    b = _render(app, clock, link, raised)
    view = live_layout(SIZE).view
    ys, xs = np.nonzero((np.abs(a - b).sum(axis=2) > 60)[:, : int(view.w)])
    centre = project_px(link.body.markers_m(rest)[[link.markerset.names.index("STRN")]],
                        scene.proj_m @ scene.view_m, view)[0][0]
    assert len(xs) > 400 and np.mean(xs > centre) > 0.9
    full = load_markerset("upper_limb_seated")
    want = joint_angles(BodyModel(link.body.dims, full).markers_m(raised), full.names, near_singular="withhold")
    assert scene._angle(link.latest, "right_shoulder_abduction") == pytest.approx(float(want["right_shoulder_abduction"]))
    assert 60.0 < scene._angle(link.latest, "right_shoulder_abduction") < 100.0  # (skin markers: ~80)
    assert math.isnan(scene._angle(link.latest, "left_shoulder_abduction"))
    np.testing.assert_array_equal(scene._shoulder_m(), link.latest.positions_m[link.markerset.names.index("RSHO")])
    # the panel lists what the marker set gives: no rows for the left arm, which it has no markers for
    assert [name for name, _, _ in scene._rows(False)] == [f"right_{suffix}" for suffix, _, _ in ARM_ROWS]


def test_banners_say_what_the_tracker_is_doing(screen):
    app, scene, link, clock = make_app(screen, avatar=False)
    assert scene.banner(None)[0].startswith("Waiting for the first images")
    link.feed(reference_pose(), state=0, message="Stand in the reference pose: arms slightly away from the body")
    run_frames(app, clock, 1)
    assert scene.banner(link.latest)[0].startswith("Stand in the reference pose")
    link.feed(reference_pose())
    run_frames(app, clock, 1)
    assert scene.banner(link.latest) is None
    link.warning = "camera cam2 (device '1') stopped (no frame for 1.0 s): tracking goes on with cam1, cam3, cam4"
    assert scene.banner(link.latest)[0].startswith("Camera cam2 (device '1') stopped")
    link.warning = ""
    clock.now_s += 2.0                                       # no sample for 2 s
    assert "No new images" in scene.banner(link.latest)[0]
    link.state = LinkState.RESTARTING
    text, colour = scene.banner(link.latest)
    assert text == "The tracker stopped: restarting..."
    link.error = "the tracker process was killed (SIGKILL); restarted"
    assert scene.banner(link.latest)[0] == ("The tracker stopped: restarting... (the tracker process was killed "
                                            "(SIGKILL); restarted)")
    link.error = ""
    link.state = LinkState.STARTING
    assert scene.banner(None)[0] == "Starting the tracker..."
    link.state, link.error = LinkState.FAILED, "no camera"
    assert scene.banner(None)[0] == "The tracker is not running: no camera"
    # the banner is drawn: its text makes bright pixels in the top band of the view
    link.state = LinkState.RESTARTING
    app.frame()
    rgb = app.screen.read_rgb()
    top = rgb[15:60, 20: int(live_layout(SIZE).view.w) - 20]
    assert (top.max(axis=2) > 200).sum() > 100


def test_angles_are_hidden_while_the_tracker_restarts(screen, monkeypatch):
    """A restart (the tracker and its standby killed together) takes seconds: the last sample's
    angles are not shown as the patient's, the panel says they are paused, the banner why."""
    from game.gfx.canvas import Canvas
    from game.scenes.live import PAUSED_LINE

    drawn: list[str] = []
    text = Canvas.text

    def record(self, words, *args, **kwargs):
        drawn.append(words)
        return text(self, words, *args, **kwargs)

    banner = Canvas.banner

    def record_banner(self, words, *args, **kwargs):
        drawn.append(words)
        return banner(self, words, *args, **kwargs)

    monkeypatch.setattr(Canvas, "text", record)
    monkeypatch.setattr(Canvas, "banner", record_banner)
    app, scene, link, clock = make_app(screen, avatar=False)
    pose = reference_pose()
    link.feed(pose)
    run_frames(app, clock, 2)
    degrees = [t for t in drawn if t.endswith("\N{DEGREE SIGN}")]
    assert degrees and PAUSED_LINE not in drawn                # live: the angles are shown
    drawn.clear()
    link.state, link.error = LinkState.RESTARTING, "the tracker process was killed (SIGKILL); restarted"
    run_frames(app, clock, 2)
    assert PAUSED_LINE in drawn
    assert not [t for t in drawn if t.endswith("\N{DEGREE SIGN}")]   # no stale angle shown as live
    assert any("killed (SIGKILL)" in t for t in drawn)       # the banner says what happened
    drawn.clear()
    link.state, link.error = LinkState.RUNNING, ""
    clock.now_s += 2.0                                         # running again but no new sample yet: still paused
    run_frames(app, clock, 1)
    assert PAUSED_LINE in drawn and not [t for t in drawn if t.endswith("\N{DEGREE SIGN}")]
    drawn.clear()
    link.feed(pose)
    run_frames(app, clock, 2)
    assert PAUSED_LINE not in drawn and [t for t in drawn if t.endswith("\N{DEGREE SIGN}")]


def test_marker_counts_and_estimated_markers_are_drawn(screen):
    app, scene, link, clock = make_app(screen, avatar=False)
    status = np.ones(14, np.uint8)
    status[[6, 7]] = 2
    status[12] = 0
    link.feed(reference_pose(), status=status)
    run_frames(app, clock, 2)
    rgb = app.screen.read_rgb().astype(int)
    xy = project_px(link.latest.positions_m, scene.proj_m @ scene.view_m, live_layout(SIZE).view)
    amber, teal = np.array([242, 190, 92]), np.array([94, 200, 190])

    def near(colour, x, y, r=7):
        patch = rgb[int(y) - r:int(y) + r + 1, int(x) - r:int(x) + r + 1].reshape(-1, 3)
        return (np.abs(patch - colour).max(axis=1) < 50).sum()

    assert near(amber, *xy[6]) > 5 and near(teal, *xy[0]) > 5
    lost = project_px(link.latest.truth_m[[12]], scene.proj_m @ scene.view_m, live_layout(SIZE).view)[0]
    assert near(teal, *lost, r=2) == 0 and near(amber, *lost, r=2) == 0


def test_a_planar_angle_near_its_singular_pose_reads_continued_not_wrapped(screen):
    """The left arm raised high and out, the trunk leaning 24 degrees forward: relative to the
    trunk the arm points up, out and a little back. The spec's wrapped flexion (the sample's) is
    about -140; the live view shows it continued past 180, and withholds flexion of an arm
    pointing sideways (where every value occurs within a few degrees), as `rehab play` showed
    "-138" before."""
    app, scene, link, clock = make_app(screen)
    up_out = np.array([np.sin(np.radians(160.0)), -np.cos(np.radians(160.0)), 0.0])
    arm = ArmPose.from_direction(np.array([up_out[0], up_out[1], 0.45]) / np.linalg.norm([up_out[0], up_out[1], 0.45]))
    sample = link.feed(Pose(trunk_forward_lean_deg=24.0, left=arm))
    run_frames(app, clock)
    wrapped = float(sample.angles_deg[link.angle_names.index("left_shoulder_flexion")])
    shown = scene._angle(link.latest, "left_shoulder_flexion")
    assert wrapped < -90.0 and 180.0 < shown <= 225.0 and shown == pytest.approx(wrapped + 360.0)
    sideways = link.feed(Pose(right=ArmPose.from_direction(np.array([1.0, 0.0, 0.0]))))
    run_frames(app, clock)
    assert np.isfinite(sideways.angles_deg[link.angle_names.index("right_shoulder_flexion")])
    assert math.isnan(scene._angle(link.latest, "right_shoulder_flexion"))
    assert 60.0 < scene._angle(link.latest, "right_shoulder_abduction") < 100.0  # (skin markers: ~80)


def test_format_angle():
    assert format_angle(87.4) == "87\N{DEGREE SIGN}"
    assert format_angle(-0.4) == "0\N{DEGREE SIGN}"
    assert format_angle(math.nan) == "-"


def test_truth_error_counts_measured_markers_only():
    truth = np.zeros((3, 3))
    measured = truth + [[0.003, 0, 0], [0, 0.004, 0], [0.5, 0, 0]]
    assert truth_error_mm(measured, truth, np.array([1, 1, 2])) == pytest.approx(math.sqrt((9 + 16) / 2))
    assert math.isnan(truth_error_mm(measured, np.full((3, 3), np.nan), np.array([1, 1, 1])))


def test_grid_and_image_coordinates():
    rects = grid_rects((0, 0, 1000, 500), 4, 4 / 3, 10)
    assert len(rects) == 4 and rects[0][2] / rects[0][3] == pytest.approx(4 / 3)
    assert rects[1][0] > rects[0][0] and rects[2][1] > rects[0][1]
    xy = image_to_screen(np.array([[-0.5, -0.5], [319.5, 239.5]]), (10, 20, 640, 480), (320, 240))
    assert xy == pytest.approx(np.array([[10, 20], [650, 500]]))


def test_camera_check_draws_the_overlays_of_each_camera(screen):
    app, scene, link, clock = make_app(screen, avatar=False)
    images = [np.full((240, 320, 3), (40 * k, 80, 160), np.uint8) for k in range(4)]
    link.latest_images = lambda: images
    sample = link.feed(reference_pose())
    uv = np.full((14, 4, 2), np.nan)
    uv[0, 1] = (100.0, 60.0)                       # MB's centroid in camera 2
    win = np.full((14, 4, 3), np.nan)
    win[0, 1] = (100.0, 60.0, 20.0)
    link._queue[-1] = type(sample)(**{**{f: getattr(sample, f) for f in sample.__dataclass_fields__},
                                      "uv_px": uv, "windows_px": win})
    app.dispatch(Press(Action.MONITOR))
    monitor = app.scene
    assert isinstance(monitor, MonitorScene)
    monitor._builder.join(30)                      # the colour table, built off the main thread
    run_frames(app, clock, 2)
    assert monitor.colour_table is not None and len(monitor.overlays) == 4
    rgb = app.screen.read_rgb().astype(int)
    w, h = SIZE
    s = min(w / 1280, h / 720)
    rects = grid_rects((28 * s, 66 * s, w - 56 * s, h - 100 * s), 4, 320 / 240, 12 * s)
    x, y, rw, rh = rects[3]
    # camera 4's image (BGR (120, 80, 160), no marker colour in it): dimmed by the overlay, as RGB
    assert np.abs(rgb[int(y + rh * 0.6), int(x + rw * 0.6)] - np.array([160, 80, 120]) * 0.55).max() <= 3
    # camera 2 shows MB's search window in MB's colour around the centroid
    yellow = np.array(link.markerset.palette[link.markerset.colour_index[0]], dtype=int)
    cx, cy = image_to_screen(uv[0, 1][None], rects[1], (320, 240))[0]
    half = 20 * rects[1][2] / 320
    edge = rgb[int(cy - half) - 2:int(cy - half) + 3, int(cx - half / 2):int(cx + half / 2)].reshape(-1, 3)
    assert (np.abs(edge - yellow).max(axis=1) < 80).sum() >= 3
    app.dispatch(Press(Action.BACK))
    assert app.scene is scene


def test_camera_check_shows_each_cameras_clock_and_warns_of_an_irregular_one(screen, tmp_path):
    """The samples' image stamps: camera 2 runs 12 ms after camera 1 and 0.1 % slow, camera 3's
    stamps scatter by 5 ms (a busy USB bus), camera 4 runs 8 ms before camera 1."""
    import dataclasses

    app, scene, link, clock = make_app(screen, avatar=False)
    images = [np.full((240, 320, 3), (40 * k, 80, 160), np.uint8) for k in range(4)]
    link.latest_images = lambda: images
    rng = np.random.default_rng(3)
    period = 1 / 30
    app.dispatch(Press(Action.MONITOR))
    monitor = app.scene
    for k in range(90):
        sample = link.feed(reference_pose())
        stamps = np.array([k * period, 0.012 + k * period * 1.001, k * period + rng.normal(0, 0.005),
                           -0.008 + k * period])
        link._queue[-1] = dataclasses.replace(sample, stamps_s=stamps)
        if k % 30 == 29:
            run_frames(app, clock, 1)
    lines = monitor.timing.lines(["camera 1", "camera 2", "camera 3", "camera 4"])
    assert lines[0] == "camera 1: the reference clock, jitter 0.0 ms"
    assert lines[1].startswith("camera 2: +15.0 ms from camera 1, drift -0.100 %")  # 12 ms + 89 x 0.033 ms
    assert lines[2].startswith("camera 3: timing too irregular to correct (jitter ")
    assert 4.0 < float(lines[2].split("(jitter ")[1].split(" ms)")[0]) < 6.5  # 5 ms drawn, 90 stamps
    assert lines[3].startswith("camera 4: -8.0 ms from camera 1, drift +0.000 %")
    monitor._builder.join(30)
    run_frames(app, clock, 2)
    app.screen.save_png(tmp_path / "timing.png")
    rgb = app.screen.read_rgb().astype(int)
    w, h = SIZE
    s = min(w / 1280, h / 720)
    rects = grid_rects((28 * s, 66 * s, w - 56 * s, h - 100 * s), 4, 320 / 240, 12 * s)
    amber = np.array(theme.ATTENTION)

    def amber_pixels(rect):
        x, y, rw, rh = (int(v) for v in rect)
        band = rgb[y + rh - 24:y + rh, x:x + rw].reshape(-1, 3)
        return int((np.abs(band - amber).max(axis=1) < 40).sum())

    # the warning is written in amber under camera 3 only
    assert amber_pixels(rects[2]) > 20
    assert amber_pixels(rects[0]) == amber_pixels(rects[1]) == amber_pixels(rects[3]) == 0
