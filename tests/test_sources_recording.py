"""RecordingSource, and the live tracker on recordings and on cameras of which one stops.

One small simulated recording (4 cameras, 320x240, 15 frame sets/s) serves every test.
"""

import os
import shutil
import subprocess
import sys
import time
from multiprocessing import shared_memory

import numpy as np
import pytest

from tracking.live import LiveTracker, SourceConfig
from tracking.live.process import TrackerLoop
from tracking.live.ring import RingLayout, RingReader, RingWriter
from tracking.live.source import angle_names_for, resolve_config
from tracking.io.recording import Recording
from tracking.sim.studio import SimulationSettings, simulate_recording
from tracking.sources.base import FrameRequest, SourceError, warnings_and_end
from tracking.sources.cameras import CameraSource
from tracking.sources.recording import RecordingSource
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker, TrackingState
from tracking.io.trc import read_trc

FPS = 15.0


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rec") / "rec"
    simulate_recording(folder, SimulationSettings(motion="shoulder_flexion", size_px=(320, 240), fps=FPS,
                                                  seconds=3.0, images=True))
    return folder


def offline_positions(folder):
    """Positions the tracker gives frame by frame on the recording (what ``rehab track`` does)."""
    with RecordingSource(folder) as src:
        tracker = Tracker(src.cameras, src.markerset, fps=src.fps)
        out = []
        while (fs := src.read()) is not None:
            out.append(tracker.step(fs.images, fs.time_s))
    return out


def test_recording_source_reads_every_frame_set_in_order(recording):
    with Recording(recording) as rec:
        expected = [fs.images for fs in rec]
    with RecordingSource(recording) as src:
        assert src.fps == FPS and len(src.cameras) == 4
        sets = []
        while (fs := src.read()) is not None:
            sets.append(fs)
        assert "ended after 46 frame sets" in src.end_reason() and src.warnings() == ()
    assert len(sets) == len(expected) == 46
    for k, fs in enumerate(sets):
        assert fs.index == k and fs.time_s == pytest.approx(k / FPS)
        assert not fs.missing.any() and np.allclose(fs.stamps_s, k / FPS)
        assert all(np.array_equal(a, b) for a, b in zip(fs.images, expected[k]))


def test_a_camera_that_ends_early_is_said_once_and_the_others_go_on(recording, tmp_path):
    """It stopped all tracking at the shortest camera; now the other cameras are tracked to their
    end (one line says which camera ended where); strict readers still refuse the recording."""
    cut = tmp_path / "cut"
    shutil.copytree(recording, cut)
    for f in sorted((cut / "cam3").iterdir())[20:]:
        f.unlink()
    with RecordingSource(cut, strict=True) as src:
        with pytest.raises(SourceError, match=r"^cam3 ended at frame 20 while the other cameras go on: .* cut short"):
            while src.read() is not None:
                pass
    with RecordingSource(cut) as src:  # live: a warning, and the other cameras to the end
        sets = list(iter(src.read, None))
        assert len(sets) == 46 and len(src.warnings()) == 1
        assert src.warnings()[0] == ("cam3 ended at frame 20 while the other cameras go on: tracking goes on with "
                                     "cam1, cam2, cam4")
        assert not sets[30].images[2].any() and sets[30].images[0].any()   # cam3 black, the others not
    # rehab track says it once and tracks every frame set, with three cameras after frame 20
    run = subprocess.run([sys.executable, "-m", "game", "track", str(cut), "--out", str(tmp_path / "m.trc")],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    warned = [line for line in run.stderr.splitlines() if "cam3 ended at frame 20" in line]
    assert len(warned) == 1 and "rehab: WARNING: cam3 ended" in warned[0] and "Traceback" not in run.stderr
    trc = read_trc(tmp_path / "m.trc")
    assert trc.n_frames == 46
    assert np.isfinite(trc.positions_mm[30:]).all(axis=2).mean() > 0.8   # still measured on three cameras


def test_live_tracking_of_a_recording_matches_offline_tracking(recording):
    offline = offline_positions(recording)
    config = SourceConfig(kind="recording", path=str(recording))
    resolved = resolve_config(config)
    assert resolved.size == (320, 240) and resolved.fps == FPS
    with LiveTracker(config, auto_restart=False, warm_standby=False) as live:
        deadline = time.perf_counter() + 60.0
        samples = []
        while time.perf_counter() < deadline:
            samples += live.poll()
            status = live.status()
            if "ended after" in status.warning:
                break
            time.sleep(0.05)
        samples += live.poll()
        assert "the recording" in status.warning and "ended after 46 frame sets" in status.warning
        assert status.last_error == ""
    assert [s.frame_index for s in samples] == list(range(46))
    assert [s.time_s for s in samples] == pytest.approx([k / FPS for k in range(46)])
    assert sum(s.state == TrackingState.TRACKING for s in samples) >= 40
    for s, o in zip(samples, offline):
        assert s.state == o.state
        assert np.array_equal(s.status, o.status)
        np.testing.assert_array_equal(s.positions_m, o.positions_m)  # the same algorithm, bit for bit


class ReplayDevice:
    """A camera replaying one camera's images of a recording at ``fps`` (frame k due at t0 + k/fps);
    after ``stop_after`` frames it reports failure, as an unplugged USB camera does."""

    def __init__(self, images, t0, fps, stop_after=None):
        self.images, self.t0, self.fps, self.stop_after, self.k = images, t0, fps, stop_after, 0

    def isOpened(self):
        return True

    def read(self):
        if self.stop_after is not None and self.k >= self.stop_after or self.k >= len(self.images):
            time.sleep(0.002)
            return False, None
        delay = self.t0 + self.k / self.fps - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        self.k += 1
        return True, self.images[self.k - 1]

    def release(self):
        pass


@pytest.mark.realtime
def test_tracking_goes_on_with_the_other_cameras_when_one_stops(recording):
    with Recording(recording) as rec:
        cams = rec.cameras
        per_camera = list(zip(*[fs.images for fs in rec]))
    frame_of = {id(img): k for images in per_camera for k, img in enumerate(images)}
    truth_m = read_trc(recording / "truth.trc").positions_mm / 1000.0
    t0 = time.perf_counter() + 0.1
    slow = 7.5  # half the recording's rate: the tracker keeps pace on a loaded machine
    devices = [ReplayDevice(images, t0, slow, stop_after=12 if c == 1 else None) for c, images in enumerate(per_camera)]
    with RecordingSource(recording) as rs:
        markerset = rs.markerset
    source = CameraSource(cams, ["0", "1", "2", "3"], slow, stall_s=0.5,
                          capture_factory=lambda dev, size, fps: devices[int(dev)], markerset=markerset)
    ring = RingLayout(markerset.n_markers, 4, len(angle_names_for(markerset)), 64)
    shm = shared_memory.SharedMemory(create=True, size=ring.nbytes)
    writer, reader = RingWriter(shm.buf, ring, initialize=True), RingReader(shm.buf, ring)
    try:
        loop = TrackerLoop(source, writer, None, fps=slow)
        # which recorded frame each camera's image of a tracked frame set is: the frame set the
        # loop itself read (on a loaded machine the cameras move on between two reads)
        read, tracked = source.read, {}
        source.read = lambda request: tracked.setdefault(request.index, read(request))
        for _ in range(40):
            index = loop.frame_index
            loop.step()
            if tracked.get(index) is None:
                break
            tracked[index] = [frame_of.get(id(img), -1) for img in tracked[index].images]
            if min(k for k in tracked[index] if k >= 0) >= 40:
                break
        samples = reader.read_new()
        warning = reader.warning_line()
    finally:
        source.close()
        writer.release()
        reader.release()
        shm.close()
        shm.unlink()
    assert "camera cam2 (device '1') stopped" in warning and "tracking goes on with cam1, cam3, cam4" in warning
    seen = [(s, tracked[int(s["frame_index"])]) for s in samples]
    after = [(s, k) for s, k in seen if k[1] == -1 and k[0] >= 0 and len({k[0], k[2], k[3]}) == 1]
    assert len(after) >= 10  # frame sets after the stop, from the three other cameras
    for s, k in after:
        assert int(s["state"]) == TrackingState.TRACKING
        ok = s["status"] != MarkerStatus.LOST
        assert ok.mean() >= 0.85
        err = np.linalg.norm(s["positions_m"][ok] - truth_m[k[0]][ok], axis=1)
        assert np.median(err) < 0.005 and err.max() < 0.03


def replayed_cameras_one_stops(config):
    """Source factory (``kind="module:function"``, run in the tracker process): the recording at
    ``config.path`` replayed by four fake cameras at ``config.fps``; cam2 stops after 10 frames."""
    with Recording(config.path) as rec:
        cams = rec.cameras
        per_camera = list(zip(*[fs.images for fs in rec]))
    t0 = time.perf_counter() + 0.5
    devices = [ReplayDevice(images, t0, config.fps, stop_after=10 if c == 1 else None)
               for c, images in enumerate(per_camera)]
    with RecordingSource(config.path) as rs:
        markerset = rs.markerset
    source = CameraSource(cams, ["0", "1", "2", "3"], config.fps, stall_s=0.4,
                          capture_factory=lambda dev, size, fps: devices[int(dev)], markerset=markerset)
    source.open()
    return source


def test_the_game_sees_a_stopped_camera_as_a_status_warning_and_tracking_goes_on(recording):
    config = SourceConfig(kind=f"{__name__}:replayed_cameras_one_stops", path=str(recording), size=(320, 240),
                          fps=7.5)
    with LiveTracker(config, auto_restart=False, warm_standby=False) as live:
        deadline = time.perf_counter() + 60.0
        samples, status = [], live.status()
        while time.perf_counter() < deadline and "stopped" not in status.warning:
            samples += live.poll()
            status = live.status()
            time.sleep(0.05)
        assert "camera cam2 (device '1') stopped" in status.warning
        assert "tracking goes on with cam1, cam3, cam4" in status.warning
        before = len(samples)
        while time.perf_counter() < deadline and len(samples) < before + 5:
            samples += live.poll()
            time.sleep(0.05)
        assert live.status().alive and live.status().last_error == ""
    late = samples[before:]
    assert len(late) >= 5
    for s in late:  # tracked from the three other cameras
        assert s.state == TrackingState.TRACKING
        assert (s.status != MarkerStatus.LOST).mean() >= 0.85


def test_the_cameras_kind_opens_devices_through_opencv_in_the_process(recording, tmp_path):
    """OpenCV opens an image sequence ("cam1/%06d.png") like a camera: it delivers every frame at
    once and then ends, which the game sees as stopped cameras; no standby opens the devices twice."""
    # the recording's images six times over (links): the four sequences are read at once, so on a
    # loaded machine a short one could end before its frames met the other cameras' in a set
    for k in range(1, 5):
        frames = sorted((recording / f"cam{k}").glob("*.png"))
        (tmp_path / f"cam{k}").mkdir()
        for i in range(6 * len(frames)):
            (tmp_path / f"cam{k}" / f"{i:06d}.png").symlink_to(frames[i % len(frames)])
    devices = tuple(str(tmp_path / f"cam{k}" / "%06d.png") for k in range(1, 5))
    config = SourceConfig(kind="cameras", devices=devices, calibration=str(recording / "calibration.toml"), fps=15.0,
                          size=(64, 48))
    assert resolve_config(config).size == (320, 240)  # the calibration's
    with LiveTracker(config) as live:
        deadline = time.perf_counter() + 30.0
        status = live.status()
        # a camera counts as stopped after 0.3 s without a frame, before its device says it ended
        # (a loaded machine: "cam1, cam2, cam3: no frame for 0.3 s; cam4: ..."): wait for the ends
        ended = "every camera stopped: cam1, cam2, cam3, cam4: the device reports no more frames"
        while time.perf_counter() < deadline and status.warning != ended:
            time.sleep(0.05)
            status = live.status()
        assert status.warning == ended
        assert status.last_error == "" and status.samples >= 1
        time.sleep(2.5)  # past the delay after which a standby would start
        live.status()
        assert not live.standby_ready and live._spare is None
    with pytest.raises(Exception, match="calibration.toml has 4 cameras but the source has 2 camera devices"):
        LiveTracker(SourceConfig(kind="cameras", devices=devices[:2], calibration=str(recording / "calibration.toml"))).start()


def test_device_source_repeats_the_warm_up_set_and_skips_ahead_after_a_restart(recording):
    from tracking.live.protocol import LiveError, PatientInput, SetMotion, SetPatientInput

    with Recording(recording) as rec:
        expected = [fs.images for fs in rec]
    source = RecordingSource(recording)
    try:
        first = source.read(FrameRequest(0, 0.0, False))
        assert source.read(FrameRequest(0, 0.0, True)) is first  # the loop tracks the warm-up frame set first
        later = source.read(FrameRequest(30, 0.0, True))  # a replacement process continues at frame 30
        assert later.time_s == pytest.approx(30 / FPS)
        assert all(np.array_equal(a, b) for a, b in zip(later.images, expected[30]))
        source.handle(SetPatientInput(PatientInput()))  # ignored: no simulated patient here
        with pytest.raises(LiveError, match="plays no motions"):
            source.handle(SetMotion("reach"))
        assert source.read(FrameRequest(50, 0.0, True)) is None
        assert warnings_and_end(source) == (f"the recording {recording} ended after 46 frame sets",)
    finally:
        source.close()


def test_a_headless_run_whose_source_ends_early_exits_non_zero_with_one_line(recording, tmp_path):
    """It ended with exit 0 and only a log line: nobody watches a headless run's window."""
    cut = tmp_path / "cut"
    shutil.copytree(recording, cut)
    for f in sorted((cut / "cam3").iterdir())[20:]:
        f.unlink()
    env = dict(os.environ, SDL_VIDEODRIVER="dummy", SDL_AUDIODRIVER="dummy")
    run = subprocess.run([sys.executable, "-m", "game", "play", "--headless", "--recording", str(cut), "--seconds", "4"],
                         capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 1, (run.stdout, run.stderr)
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith("rehab: error:") and "cam3 ended at frame 20" in last, last
    assert "Traceback" not in run.stderr
    whole = subprocess.run([sys.executable, "-m", "game", "play", "--headless", "--recording", str(recording),
                            "--seconds", "2"], capture_output=True, text=True, timeout=300, env=env)
    assert whole.returncode == 0, whole.stderr
