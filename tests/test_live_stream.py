"""Streaming from the tracker process: an LSL inlet and an OSC server on this machine receive the
markers, angles, status and VMC bones; the sender drops instead of blocking."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from tracking.angles import ANGLE_COLUMNS
from tracking.live import LiveTracker, SourceConfig
from tracking.live.stream import (StreamConfig, StreamError, StreamFrame, StreamSender, parse_osc_target,
                                  vmc_bones)

pylsl = pytest.importorskip("pylsl")
pytest.importorskip("pythonosc")
from pythonosc.dispatcher import Dispatcher  # noqa: E402
from pythonosc.osc_server import ThreadingOSCUDPServer  # noqa: E402

# rates and "no waiting" are checked against the wall clock: with no other test beside them
pytestmark = pytest.mark.realtime

NAMES = ("MB", "MP", "MRS")


class OscCollector:
    """A python-osc server on a free local port that keeps every message it receives."""

    def __init__(self) -> None:
        self.messages: list[tuple] = []
        self._lock = threading.Lock()
        dispatcher = Dispatcher()
        dispatcher.set_default_handler(self._keep)
        self.server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
        self.port = self.server.server_address[1]
        self._thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self._thread.start()

    def _keep(self, address: str, *args) -> None:
        with self._lock:
            self.messages.append((address, *args))

    def of(self, address: str) -> list[tuple]:
        with self._lock:
            return [m for m in self.messages if m[0] == address]

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def frame(i: int, n_angles: int = len(ANGLE_COLUMNS)) -> StreamFrame:
    p = np.arange(len(NAMES) * 3, dtype=float).reshape(-1, 3) / 10.0 + i
    return StreamFrame(frame_index=i, time_s=i / 30.0, t_ready_s=time.perf_counter(), state=1, positions_m=p,
                       status=np.array([1, 2, 0], np.uint8), angles_deg=np.full(n_angles, 10.0 + i))


def pull_all(inlet) -> tuple[list, list]:
    """Every sample the inlet holds (one pull_chunk may return part of them)."""
    samples, stamps = [], []
    while True:
        chunk, times = inlet.pull_chunk(timeout=0.0, max_samples=4096)
        if not chunk:
            return samples, stamps
        samples.extend(chunk)
        stamps.extend(times)


def wait_for(predicate, timeout_s: float = 5.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not predicate():
        time.sleep(0.01)
    return predicate()


def test_osc_messages_reach_a_python_osc_server():
    server = OscCollector()
    sender = StreamSender(StreamConfig(osc=("127.0.0.1", server.port)), NAMES, "test", ANGLE_COLUMNS, 30.0)
    try:
        for i in range(3):
            assert sender.offer(frame(i))
        assert wait_for(lambda: len(server.of("/VMC/Ext/T")) == 3)
    finally:
        sender.close()
        server.close()
    assert [m[1:] for m in server.of("/rehab/frame")] == [(i, pytest.approx(i / 30.0), 1) for i in range(3)]
    markers = server.of("/rehab/marker")
    assert [m[1] for m in markers[:3]] == list(NAMES) and markers[1][2:] == pytest.approx((0.3, 0.4, 0.5, 2))
    angles = server.of("/rehab/angle")
    assert len(angles) == 3 * len(ANGLE_COLUMNS) and angles[0][1:] == ("left_shoulder_flexion", pytest.approx(10.0))
    bones = {m[1] for m in server.of("/VMC/Ext/Bone/Pos")}
    assert {"Hips", "Spine", "Head", "RightUpperArm", "RightLowerArm", "LeftHand"} <= bones
    assert all(len(m) == 9 for m in server.of("/VMC/Ext/Bone/Pos"))  # name, position xyz, quaternion xyzw
    assert server.of("/VMC/Ext/OK")[0][1:] == (1,)


def test_vmc_rotations_are_relative_to_a_t_pose():
    """Arms straight out sideways (abduction 90, elbows straight) is the VRM rest pose: identity."""
    angles = dict.fromkeys(ANGLE_COLUMNS, 0.0)
    for side in ("left", "right"):
        angles.update({f"{side}_shoulder_abduction": 90.0, f"{side}_shoulder_elevation": 90.0,
                       f"{side}_shoulder_horizontal_flexion": 0.0, f"{side}_shoulder_flexion": 0.0})
    bones = vmc_bones(angles)
    for bone in ("RightUpperArm", "RightLowerArm", "LeftUpperArm", "LeftLowerArm", "Spine", "Head"):
        np.testing.assert_allclose(np.abs(bones[bone][1]), [0, 0, 0, 1], atol=1e-9, err_msg=bone)
    # the right forearm hangs off the upper arm towards the avatar's right (+X in Unity too)
    assert bones["RightLowerArm"][0][0] > 0.2 and bones["LeftLowerArm"][0][0] < -0.2
    # arms hanging: the upper arm turned 90 degrees down about the forward axis
    hanging = vmc_bones(dict.fromkeys(ANGLE_COLUMNS, 0.0))
    assert abs(abs(hanging["RightUpperArm"][1][2]) - math.sin(math.pi / 4)) < 1e-9


def test_a_slow_network_drops_frame_sets_instead_of_blocking():
    class Slow:
        def send(self, _frame):
            time.sleep(0.2)

        def close(self):
            pass

    sender = StreamSender(StreamConfig(queue_size=2), NAMES, "test", ANGLE_COLUMNS, 30.0)
    sender._outputs.append(Slow())
    t0 = time.perf_counter()
    accepted = [sender.offer(frame(i)) for i in range(50)]
    elapsed = time.perf_counter() - t0
    sender.close(timeout_s=0.1)
    assert elapsed < 0.05  # 50 offers while the sender sleeps: none waited
    assert sum(accepted) <= 3 and sender.dropped == 50 - sum(accepted)


@pytest.mark.parametrize("text, expected", [("9000", ("127.0.0.1", 9000)), ("10.0.0.2:39539", ("10.0.0.2", 39539)),
                                            ("[::1]:9000", ("::1", 9000))])
def test_osc_targets(text, expected):
    assert parse_osc_target(text) == expected


@pytest.mark.parametrize("text", ["host", "host:0", "host:70000", ":x"])
def test_bad_osc_targets_are_one_line(text):
    with pytest.raises(StreamError) as info:
        parse_osc_target(text)
    assert "HOST:PORT" in str(info.value) and "\n" not in str(info.value)


def test_the_tracker_process_streams_to_an_lsl_inlet_and_an_osc_server():
    """A real tracker process on the simulated patient; the inlet resolves the streams after the start."""
    server = OscCollector()
    fps = 15.0
    stream = StreamConfig(lsl=True, osc=("127.0.0.1", server.port), name="rehab-test-stream")
    with LiveTracker(SourceConfig(size=(320, 240), fps=fps, motion="shoulder_flexion"), ring_size=64,
                     warm_standby=False, stream=stream) as live:
        found = pylsl.resolve_byprop("source_id", "rehab-test-stream-markers", timeout=10.0)
        assert len(found) == 1
        info = found[0]
        inlet = pylsl.StreamInlet(info)
        full = inlet.info(timeout=5.0)
        assert full.channel_count() == 3 * 14 and full.nominal_srate() == fps and full.type() == "Mocap"
        channels = full.desc().child("channels")
        first = channels.child("channel")
        assert first.child_value("label") == "MB_X" and first.child_value("unit") == "millimeters"
        assert first.child_value("marker") == "MB" and first.child_value("type") == "PositionX"
        assert full.desc().child_value("marker_set") == "upper_limb_seated"
        angles_info = pylsl.resolve_byprop("source_id", "rehab-test-stream-angles", timeout=5.0)[0]
        angle_inlet = pylsl.StreamInlet(angles_info)
        status_inlet = pylsl.StreamInlet(pylsl.resolve_byprop("source_id", "rehab-test-stream-status", timeout=5.0)[0])
        inlet.open_stream(timeout=5.0)
        angle_inlet.open_stream(timeout=5.0)
        status_inlet.open_stream(timeout=5.0)
        records = []
        end = time.monotonic() + 3.0
        while time.monotonic() < end:  # as a game reads: the shared memory gets every sample too
            records.extend(live.poll_records())
            time.sleep(0.05)
        samples, stamps = pull_all(inlet)
        angle_samples, angle_stamps = pull_all(angle_inlet)
        status_samples, status_stamps = pull_all(status_inlet)
        records.extend(live.poll_records())
        for each in (inlet, angle_inlet, status_inlet):
            each.close_stream()
        del inlet, angle_inlet, status_inlet
        status = live.status()
    server_messages = len(server.of("/rehab/frame"))
    bones = server.of("/VMC/Ext/Bone/Pos")
    server.close()
    assert status.last_error == "", status.last_error
    # about 3 s of frame sets at the tracker's rate (loaded machine: at least a third of it)
    assert len(samples) >= fps and len(angle_samples) >= fps and len(status_samples) >= fps
    steps = np.diff(stamps)
    assert 0.9 / fps <= np.median(steps) <= 3.0 / fps  # the frame rate, or less on a loaded machine
    # time stamps: each sample's is the instant its frame set was ready (the ring's t_frame_ready_s),
    # and it carries that frame set's positions
    ready = np.array([float(r["t_frame_ready_s"]) for r in records])
    ring_mm = np.array([np.asarray(r["positions_m"]) * 1000.0 for r in records])
    checked = 0
    for sample, stamp in zip(samples, stamps):
        k = int(np.argmin(np.abs(ready - stamp)))
        if abs(ready[k] - stamp) < 1e-3:
            np.testing.assert_allclose(np.array(sample).reshape(-1, 3), ring_mm[k], atol=0.01, equal_nan=True)
            checked += 1
    assert checked >= len(samples) // 2  # the rest fell out of the 64-sample ring before it was read
    data = np.array(samples)
    status_at = dict(zip(status_stamps, status_samples))
    tracking = np.array([status_at.get(t, [0])[0] == 1 for t in stamps])
    assert tracking.any()
    measured = np.isfinite(data[tracking]).all(axis=1)
    assert measured.any()
    # positions in millimetres: the sternum marker about 1-1.5 m above the floor
    assert 900 < np.nanmedian(data[tracking, 1]) < 1600
    k = ANGLE_COLUMNS.index("right_elbow_flexion")
    assert np.isfinite(np.array(angle_samples)[:, k]).any()
    assert server_messages >= fps and len(bones) >= 10 * fps
    assert len(records) > 0  # the game's shared memory still gets every sample


def test_rehab_stream_and_rehab_play_send_osc(capsys):
    from game.cli import main

    server = OscCollector()
    try:
        assert main(["stream", "--osc", f"127.0.0.1:{server.port}", "--seconds", "4", "--fps", "15"]) == 0
        out = capsys.readouterr().out
        assert "streaming OSC to 127.0.0.1" in out and "frame sets streamed" in out
        streamed = len(server.of("/rehab/frame"))
        assert streamed >= 10
        assert main(["play", "--headless", "--seconds", "3", "--osc", f"127.0.0.1:{server.port}"]) == 0
        assert wait_for(lambda: len(server.of("/rehab/frame")) >= streamed + 10)
        names = {m[1] for m in server.of("/rehab/marker")}
        assert {"MB", "MRW2"} <= names
    finally:
        server.close()


@pytest.mark.parametrize("argv, needle", [
    (["stream"], "nothing to stream: give --lsl and/or --osc"),
    (["stream", "--osc", "localhost"], "give HOST:PORT or PORT"),
    (["play", "--headless", "--osc", "x:99999"], "give HOST:PORT or PORT"),
    (["stream", "--lsl", "--stream-name", " "], "--stream-name"),
    (["stream", "--osc", "no-such-host.invalid:9000"], "unknown host 'no-such-host.invalid'"),
])
def test_stream_options_are_one_line_errors(capsys, argv, needle):
    from game.cli import main

    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and needle in err


def test_rehab_stream_of_a_recording_stops_at_its_end(tmp_path, capsys):
    from game.cli import main
    from tracking.io.recording import RecordingWriter
    from tracking.sim.body import reference_pose
    from tracking.sim.studio import SimulationSettings, studio_from_settings

    studio, _ = studio_from_settings(SimulationSettings(motion="reference", size_px=(320, 240)))
    with studio:
        writer = RecordingWriter(tmp_path / "rec", studio.cameras, 15.0)
        for i in range(12):
            writer.write(studio.render(reference_pose(), i, i / 15.0, noise_sigma=1.5).frames.images)
        writer.close()
        writer.write_meta(studio.markerset.name, studio.markerset.rgb)
    server = OscCollector()
    try:
        t0 = time.monotonic()
        assert main(["stream", "--osc", str(server.port), "--recording", str(tmp_path / "rec"), "--seconds", "60"]) == 0
        assert time.monotonic() - t0 < 30  # ended with the recording, not at --seconds
        out = capsys.readouterr().out
        assert "frame sets streamed" in out
        frames = [m[1] for m in server.of("/rehab/frame")]
        # every frame set once, in order (a loaded machine may skip some to keep real time)
        assert frames == sorted(set(frames)) and frames[-1] <= 11 and len(frames) >= 6
    finally:
        server.close()


def test_an_lsl_inlet_started_after_rehab_stream_receives_at_the_trackers_rate():
    """The acceptance check: `rehab stream --lsl` in its own process, an inlet here started after it."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, SDL_VIDEODRIVER="dummy", SDL_AUDIODRIVER="dummy")
    proc = subprocess.Popen([sys.executable, "-m", "game.cli", "stream", "--lsl", "--stream-name", "rehab-cli-test",
                             "--fps", "15", "--seconds", "25"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        found = pylsl.resolve_byprop("source_id", "rehab-cli-test-markers", timeout=20.0)
        assert found, "no marker stream: " + (proc.stderr.read() if proc.poll() is not None else "still running")
        markers = pylsl.StreamInlet(found[0])
        angles = pylsl.StreamInlet(pylsl.resolve_byprop("source_id", "rehab-cli-test-angles", timeout=5.0)[0])
        labels = []
        channel = markers.info(timeout=5.0).desc().child("channels").child("channel")
        while not channel.empty():
            labels.append(channel.child_value("label"))
            channel = channel.next_sibling()
        angle_channel = angles.info(timeout=5.0).desc().child("channels").child("channel")
        markers.open_stream(timeout=5.0)
        angles.open_stream(timeout=5.0)
        t0 = pylsl.local_clock()
        time.sleep(4.0)
        m, m_stamps = pull_all(markers)
        a, _ = pull_all(angles)
        elapsed = pylsl.local_clock() - t0
        markers.close_stream()
        angles.close_stream()
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    assert labels[:3] == ["MB_X", "MB_Y", "MB_Z"] and len(labels) == 42
    assert angle_channel.child_value("label") == "left_shoulder_flexion"
    rate = len(m) / elapsed
    assert 5.0 <= rate <= 16.5, rate  # 15 frame sets/s asked; a loaded machine keeps less
    assert abs(len(a) - len(m)) <= 3
    assert 0.9 / 15.0 <= np.median(np.diff(m_stamps)) <= 3.0 / 15.0
