"""``rehab play`` end to end with the tracker process on the simulated patient: the headless
command and its screenshot (the avatar's pixels where the body is), the tracker process killed
mid-run (the window keeps drawing, says so, recovers), no process left behind, and the one-line
answers without a display or with a bad motion."""

from __future__ import annotations

import multiprocessing
import os
import signal
import time

import cv2
import numpy as np
import pytest

from game.app import Settings
from game.cli import main
from game.gfx.screen import GraphicsUnavailable, open_screen
from game.live_link import LinkState, LiveLink
from game.play import PlayOptions, build_app
from game.input import Pointer, PointerKind
from game.scenes.live import LiveScene, live_layout

pytestmark = pytest.mark.timeout(240)


@pytest.fixture
def headless(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    try:
        open_screen((32, 32), "probe", headless=True).close()
    except GraphicsUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))


def _gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    # a zombie still answers kill(0): look at its state
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def test_headless_play_saves_the_avatar(headless, tmp_path, capsys):
    out = tmp_path / "play.png"
    rc = main(["play", "--headless", "--seconds", "3", "--screenshot", str(out), "--motion", "shoulder_abduction"])
    assert rc == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("rehab play:") and "frames" in line and str(out) in line
    bgr = cv2.imread(str(out))
    assert bgr.shape == (720, 1280, 3)
    rgb = bgr[:, :, ::-1].astype(int)
    view = live_layout((1280, 720)).view
    body = rgb[150:600, int(view.w * 0.3):int(view.w * 0.7)]
    # the avatar's shirt (blue) and skin fill the middle of the mirror view
    shirt = (body[..., 2] > body[..., 0] + 50) & (body[..., 2] > 110)
    skin = (body[..., 0] > 170) & (body[..., 0] > body[..., 2] + 40)
    assert shirt.sum() > 3000 and skin.sum() > 300
    # the panel's title (the motion) is drawn in light text on the dark right side
    title = rgb[30:90, int(view.w) + 20:int(view.w) + 420]
    assert (title.min(axis=2) > 200).sum() > 500
    assert multiprocessing.active_children() == []


@pytest.mark.realtime
def test_the_mouse_moves_the_hand_and_killing_the_tracker_keeps_the_window_drawing(headless, tmp_path):
    from tracking.live import LiveTracker, SourceConfig

    # the interactive simulated patient, every frame set tracked whatever the load (docs/LIVE.md)
    source = SourceConfig(motion=None, fps=30.0, sim_clock="frames")
    link = LiveLink(lambda: LiveTracker(source))
    screen = open_screen((640, 360), "test", headless=True)
    app = None
    pids = []
    try:
        link.start()
        assert link.wait_ready(120), link.error
        options = PlayOptions(settings=Settings(window_px=(640, 360), max_fps=30), scene="live", motion=None)
        app = build_app(screen, options, link)
        scene = app.scene
        assert isinstance(scene, LiveScene) and scene.interactive
        app.run(seconds=1.0)
        assert link.state is LinkState.RUNNING and scene.banner(link.latest) is None
        # The mouse up and to the right of the view: the patient's right hand goes there (mirror).
        wrist = link.markerset.names.index("MRW1")
        before = link.latest.positions_m[wrist].copy()
        view = live_layout((640, 360)).view
        app.dispatch(Pointer(PointerKind.MOVE, (view.x + 0.8 * view.w) / 640, (view.y + 0.25 * view.h) / 360))
        target = np.array(scene.control.hand_target_m)
        assert target[0] > before[0] + 0.2 and target[1] > before[1] + 0.4
        deadline = time.perf_counter() + 30
        moved = np.zeros(3)
        while time.perf_counter() < deadline and not (moved[0] > 0.1 and moved[1] > 0.2):
            app.run(seconds=0.5)
            now = link.latest.positions_m[wrist]
            if np.isfinite(now).all():
                moved = now - before
        assert moved[0] > 0.1 and moved[1] > 0.2, f"the right wrist moved by {moved}"
        # the tracker keeps a warm standby process to take over; kill once it is prepared
        deadline = time.perf_counter() + 60
        while not getattr(link.tracker, "standby_ready", True) and time.perf_counter() < deadline:
            app.run(seconds=0.2)
        pids.append(link.tracker.pid)
        received = link.samples_received
        os.kill(pids[0], signal.SIGKILL)
        killed_s = time.perf_counter()
        frame_times, banners = [], set()
        recovered_s = None
        while time.perf_counter() - killed_s < 90:
            app.frame()
            frame_times.append(time.perf_counter())
            got = scene.banner(link.latest)
            if got is not None:
                banners.add(got[0])
            new_pid = link.tracker.pid
            if new_pid is not None and new_pid not in pids:
                pids.append(new_pid)
            if link.state is LinkState.RUNNING and link.new_samples and link.tracker.pid != pids[0]:
                recovered_s = time.perf_counter() - killed_s
                break
            time.sleep(1 / 60)
        assert recovered_s is not None, f"samples did not resume; banners seen: {banners}"
        # 2 s is the goal on an idle machine (a frame or two); a loaded one delays the standby's
        # first frame by seconds: the test asserts the handover and its banner, not the figure
        print(f"a killed tracker process: samples resumed after {recovered_s:.2f} s")
        assert recovered_s < 10.0, f"samples resumed only after {recovered_s:.2f} s"
        if recovered_s > 0.2:  # a handover slower than a few frames is shown while it happens
            assert any(b.startswith("The tracker stopped: restarting...") for b in banners)
        assert link.samples_received > received
        gaps = np.diff([killed_s, *frame_times])
        # the window never froze while the process was replaced (generous for a loaded machine)
        assert gaps.max() < 1.0, f"longest frame gap {gaps.max():.2f} s"
        print(f"tracker killed: restarting shown, samples again after {recovered_s:.2f} s, "
              f"longest frame gap {gaps.max() * 1000:.0f} ms")
        app.run(seconds=0.3)
    finally:
        if app is not None:
            app.close()
        link.close()
        screen.close()
    assert len(pids) >= 2
    deadline = time.perf_counter() + 5
    while not all(_gone(p) for p in pids) and time.perf_counter() < deadline:
        time.sleep(0.05)
    assert all(_gone(p) for p in pids)
    assert multiprocessing.active_children() == []


def test_without_a_display_play_says_so_in_one_line(monkeypatch, capsys):
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setattr("sys.platform", "linux")
    assert main(["play"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no display" in err[0] and "--headless" in err[0]


def test_bad_motion_is_one_line(capsys):
    assert main(["play", "--headless", "--motion", "no_such_motion"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown motion 'no_such_motion'" in err[0] and "shoulder_flexion" in err[0]


def test_a_tracker_that_cannot_start_is_one_line(headless, capsys):
    assert main(["play", "--headless", "--rig", "no_such_rig", "--seconds", "1"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown rig 'no_such_rig'" in err[0] and "ring4" in err[0]
    assert multiprocessing.active_children() == []


@pytest.fixture(scope="module")
def short_recording(tmp_path_factory):
    from tracking.sim.studio import SimulationSettings, simulate_recording

    folder = tmp_path_factory.mktemp("rec") / "rec"
    simulate_recording(folder, SimulationSettings(motion="shoulder_abduction", size_px=(320, 240), fps=15.0,
                                                  seconds=4.0))
    return folder


def test_play_tracks_a_recording_and_cameras_instead_of_the_simulated_patient(headless, short_recording, tmp_path, capsys):
    out = tmp_path / "rec.png"
    rc = main(["play", "--headless", "--seconds", "2", "--screenshot", str(out), "--recording", str(short_recording)])
    assert rc == 0
    rgb = cv2.imread(str(out))[:, :, ::-1].astype(int)
    view = live_layout((1280, 720)).view
    body = rgb[150:600, int(view.w * 0.3):int(view.w * 0.7)]
    assert ((body[..., 2] > body[..., 0] + 50) & (body[..., 2] > 110)).sum() > 3000  # the avatar's shirt
    # the video files as four "cameras" with the recording's calibration (the camera path of the
    # tracker process: reader threads, frames grouped by time)
    videos = ",".join(str(short_recording / f"cam{k}.avi") for k in range(1, 5))
    capsys.readouterr()
    rc = main(["play", "--headless", "--seconds", "2", "--devices", videos,
               "--calibration", str(short_recording / "calibration.toml")])
    if rc != 0:
        # the 4-s videos play from when the process opens them: a start of seconds on a loaded
        # machine leaves less than the run's 2 s, and a headless run whose source ended says so
        err = capsys.readouterr().err.strip().splitlines()
        assert rc == 1 and err[-1].startswith("rehab: error:") and "stopped" in err[-1], err
    assert multiprocessing.active_children() == []


@pytest.mark.parametrize("args, words", [
    (["--devices", "0"], "--devices needs --calibration"),
    (["--recording", "no/such/folder"], "recording folder no/such/folder not found"),
    (["--calibration", "no/such.toml", "--devices", "0"], "calibration file no/such.toml not found"),
    (["--recording", ".", "--motion", "reach"], "--motion plays on the simulated patient"),
])
def test_bad_source_options_are_one_line(args, words, capsys):
    assert main(["play", "--headless", *args]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0]


def test_a_missing_camera_is_one_line_without_waiting_for_the_start_timeout(headless, short_recording, capsys):
    t0 = time.perf_counter()
    rc = main(["play", "--headless", "--seconds", "1", "--devices", "97,98,99,96",
               "--calibration", str(short_recording / "calibration.toml")])
    assert rc == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "camera cam1 (device '97'): cannot open it" in err[0]
    assert time.perf_counter() - t0 < 45.0  # the start retries, not the 60 s start timeout
    assert multiprocessing.active_children() == []
