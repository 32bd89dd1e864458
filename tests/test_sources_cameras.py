"""CameraSource: reader threads, grouping by time stamp, dropped / out-of-step / stopped cameras.

The cameras are fake devices (``VideoCapture``'s ``read``/``isOpened``/``release``) that deliver
frame ``k`` at ``t0 + phase + k / fps`` with every pixel set to ``k % 256``, so a frame set's
images tell which frame of each camera it holds; and OpenCV reading video files.
"""

import logging
import time

import numpy as np
import pytest

from calibration.errors import CalibrationError
from tracking.io.recording import RecordingWriter
from tracking.sources.base import SourceError
from tracking.sources.cameras import CameraSource, PacedCapture, is_file_device, open_capture

from fake_cameras import SIZE, FakeDevice, cameras, factory_of


def make_source(devs, fps, **kw):
    return CameraSource(cameras(len(devs)), [str(k) for k in range(len(devs))], fps,
                        capture_factory=factory_of(devs), **kw)


def frame_values(fs):
    return [int(img[0, 0, 0]) if not m else None for img, m in zip(fs.images, fs.missing)]


def test_frames_of_the_same_instant_are_grouped():
    fps = 20.0
    t0 = time.perf_counter() + 0.05
    devs = [FakeDevice(t0, fps, phase_s=p) for p in (0.0, 0.004, 0.009)]
    with make_source(devs, fps) as src:
        sets = [src.read() for _ in range(15)]
        assert src.warnings() == () or all("dropped" in w for w in src.warnings())
    complete = [fs for fs in sets if not fs.missing.any()]
    assert len(complete) >= 12
    same = [len(set(frame_values(fs))) == 1 for fs in complete]  # every camera's frame of the same instant
    # (host time stamps: a reader thread not scheduled for half a period on the loaded test
    # machine stamps its frame late, rarely)
    assert np.mean(same) >= 0.85
    for fs in complete:
        assert np.abs(fs.stamps_s - fs.time_s).max() <= 0.5 / fps + 1e-9  # within half a period of the set's instant
        assert all(img.shape == (SIZE[1], SIZE[0], 3) for img in fs.images)
    assert np.all(np.diff([fs.time_s for fs in sets]) > 0)
    assert [fs.index for fs in sets] == list(range(15))


@pytest.mark.parametrize("mode", ["hang", "fail"])
def test_a_camera_that_stops_is_missing_and_warned_about(mode, caplog):
    fps = 20.0
    t0 = time.perf_counter() + 0.05
    devs = [FakeDevice(t0, fps), FakeDevice(t0, fps, stop_after=5, mode=mode), FakeDevice(t0, fps)]
    caplog.set_level(logging.WARNING, logger="tracking.sources.cameras")
    with make_source(devs, fps, stall_s=0.3) as src:
        sets = [src.read() for _ in range(20)]
        warnings = src.warnings()
    late = sets[-5:]
    for fs in late:
        assert fs.missing.tolist() == [False, True, False]
        assert not fs.images[1].any()  # black image for the missing camera
        assert np.isnan(fs.stamps_s[1])
        a, _, c = frame_values(fs)
        assert a == c
    stopped = [w for w in warnings if "stopped" in w]
    assert len(stopped) == 1 and "cam2" in stopped[0] and "tracking goes on with cam1, cam3" in stopped[0]
    assert "\n" not in stopped[0]
    from tracking.sources.cameras import is_pace_warning

    assert not is_pace_warning(stopped[0])   # a stopped camera fails a headless run
    logged = [r.getMessage() for r in caplog.records if "stopped" in r.getMessage()]
    assert len(logged) == 1  # logged once when it appears, not per frame set
    assert src.missing[1] >= 5 and src.missing[0] == 0


def test_a_camera_that_comes_back_is_used_again():
    fps = 20.0
    t0 = time.perf_counter() + 0.05
    devs = [FakeDevice(t0, fps), FakeDevice(t0, fps, skip=range(4, 16))]  # silent for 0.6 s
    with make_source(devs, fps, stall_s=0.25) as src:
        sets = [src.read() for _ in range(24)]
        assert not any("stopped" in w for w in src.warnings())
    assert any(fs.missing[1] for fs in sets[4:16])
    assert not sets[-1].missing.any() and len(set(frame_values(sets[-1]))) == 1


def test_a_slow_reader_counts_dropped_frames():
    fps = 25.0
    t0 = time.perf_counter() + 0.05
    devs = [FakeDevice(t0, fps), FakeDevice(t0, fps)]
    with make_source(devs, fps) as src:
        for _ in range(6):
            src.read()
            time.sleep(2.5 / fps)  # the tracker is slower than the cameras
        warnings = src.warnings()
    assert src.dropped[0] >= 5 and src.dropped[1] >= 5
    assert any(w.startswith("camera cam1 dropped") for w in warnings)
    # a busy machine's dropped frames are a pace warning: they do not fail a headless run
    from tracking.sources.cameras import is_pace_warning

    assert all(is_pace_warning(w) for w in warnings if " dropped " in w)


def test_a_driver_gap_counts_as_dropped_frames():
    fps = 25.0
    t0 = time.perf_counter() + 0.05
    devs = [FakeDevice(t0, fps), FakeDevice(t0, fps, skip=(6, 7, 8))]  # its driver never delivers 6-8
    with make_source(devs, fps) as src:
        for _ in range(14):
            src.read()
        warnings = src.warnings()
    assert src.dropped[1] >= 3
    assert any(w.startswith("camera cam2 dropped") for w in warnings)


def test_a_camera_out_of_step_is_left_out_and_warned_about():
    t0 = time.perf_counter() + 0.05
    devs = [FakeDevice(t0, 20.0), FakeDevice(t0, 20.0), FakeDevice(t0, 13.0)]  # cam3 runs slower
    with make_source(devs, 20.0, stall_s=1.0) as src:
        sets = [src.read() for _ in range(30)]
        warnings = src.warnings()
    # cam3 is out of step again and again; the others only when a reader thread is not scheduled
    # for a while on a loaded machine (it stamps its frame late), rarely
    assert src.out_of_step[2] >= 3 and src.out_of_step[2] > 2 * src.out_of_step[:2].max()
    assert any("cam3 is out of step" in w for w in warnings)
    from tracking.sources.cameras import is_pace_warning

    assert all(is_pace_warning(w) for w in warnings if "out of step" in w)
    for fs in sets:  # whatever is in a set lies within half a period of the set's instant
        s = fs.stamps_s[~fs.missing]
        assert np.abs(s - fs.time_s).max() <= 0.5 / 20.0 + 1e-9


def test_open_errors_are_one_line():
    t0 = time.perf_counter()
    src = make_source([FakeDevice(t0, 20.0), FakeDevice(t0, 20.0, opened=False)], 20.0)
    with pytest.raises(SourceError, match=r"camera cam2 \(device '1'\): cannot open it"):
        src.open()
    src = make_source([FakeDevice(t0, 20.0), FakeDevice(t0, 20.0, size=(64, 48))], 20.0)
    with pytest.raises(CalibrationError, match="calibration of cam2 is for 32x24 but camera cam2 .* delivers 64x48"):
        src.open()
    src = make_source([FakeDevice(t0, 20.0), FakeDevice(t0, 20.0, stop_after=0)], 20.0, open_timeout_s=0.3)
    with pytest.raises(SourceError, match=r"no image from cam2 \(device '1'\) within 0.3 s"):
        src.open()
    with pytest.raises(SourceError, match="2 camera devices .* for 3 calibrated cameras"):
        CameraSource(cameras(3), ["0", "1"], 20.0)


def test_a_file_given_as_a_camera_is_delivered_at_the_camera_rate():
    """OpenCV reads a file as fast as it decodes; as a camera it must come at the asked rate, and a
    reader that fell behind catches up one frame at a time, not in a burst."""
    clock = [0.0]
    slept = []

    def sleep(s):
        slept.append(s)
        clock[0] += s

    class Frames:
        def read(self):
            return True, None

    cap = PacedCapture(Frames(), 20.0, clock=lambda: clock[0], sleep=sleep)
    reads = []
    for _ in range(5):
        cap.read()
        reads.append(clock[0])
    np.testing.assert_allclose(np.diff(reads), 0.05)
    clock[0] += 1.0  # the reader was held up for a second: one frame at once to catch up, then paced
    after = []
    for _ in range(4):
        cap.read()
        after.append(clock[0] - 1.2)
    np.testing.assert_allclose(after, [0.0, 0.0, 0.05, 0.1], atol=1e-12)
    assert is_file_device("cam1.avi") and is_file_device("rec/cam1/%06d.png")
    assert not is_file_device("0") and not is_file_device("rtsp://10.0.0.2/stream")


def test_opencv_reads_video_files_as_cameras(tmp_path):
    cams = cameras(2)
    writer = RecordingWriter(tmp_path, cams, 20.0)
    for k in range(12):
        writer.write([np.full((SIZE[1], SIZE[0], 3), 10 * k + c, np.uint8) for c in range(2)])
    writer.close()
    files = [str(tmp_path / f"{c.name}.avi") for c in cams]
    src = CameraSource(cams, files, 20.0, stall_s=0.3,
                       capture_factory=open_capture)
    sets = []
    with src:
        while (fs := src.read()) is not None:
            sets.append(fs)
        assert "every camera stopped" in src.end_reason()
    complete = [fs for fs in sets if not fs.missing.any()]
    assert len(complete) >= 8
    for fs in complete:
        a, b = (int(img[0, 0, 0]) for img in fs.images)
        assert b - a == 1 and a % 10 == 0  # frame k of both files (FFV1 is lossless)



def test_pace_warnings_are_told_from_failures_even_when_the_published_line_is_cut():
    """A headless run fails on a stopped camera, not on frames dropped by a busy machine; the
    tracker process publishes its warnings in one line of limited length, failures first."""
    from tracking.sources.cameras import is_pace_warning

    assert is_pace_warning("camera cam3 dropped 23 frames in")     # cut at the line's limit
    assert is_pace_warning("camera cam1 is out of step with the others by up to 24 ms (more than")
    assert not is_pace_warning("camera cam2 (device 'cam2.avi') stopped (the device reports no more "
                               "frames): tracking goes on with cam1")
    assert not is_pace_warning("every camera stopped: cam1, cam2: no frame for 0.3 s")
    assert not is_pace_warning("cam2.avi ended at frame 40 while the other cameras go on")
