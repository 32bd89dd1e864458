"""The tracker process end to end on the simulated patient: samples, restarts, errors, cleanup.

Each LiveTracker spawns real processes that render and track 320x240 images, so the file keeps
to two trackers (one healthy, shared by the tests in order; one with a faulty source).
"""

import multiprocessing
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from tracking.live import LiveTracker, PatientInput, SourceConfig
from tracking.live.client import BLOCK_PREFIX, remove_stale_blocks
from tracking.live.protocol import LiveError
from tracking.live.ring import ProcessState
from tracking.sources.sim import SimulatedSource
from tracking.marker_status import MarkerStatus
from tracking.tracker import TrackingState

SIZE = (320, 240)
#: How long a test waits for a killed process's replacement to publish (2 s on an idle machine;
#: CI machines run loaded).
RESUME_LIMIT_S = 10.0


def _my_blocks() -> list[str]:
    return sorted(p.name for p in Path("/dev/shm").glob(f"{BLOCK_PREFIX}{os.getpid()}_*"))


def _wait(predicate, timeout_s: float, poll_s: float = 0.01):
    deadline = time.perf_counter() + timeout_s
    while time.perf_counter() < deadline:
        got = predicate()
        if got:
            return got
        time.sleep(poll_s)
    return predicate()


@pytest.fixture(scope="module")
def live():
    # Every frame set tracked whatever the load (sim_clock="frames"): with the wall clock on a busy
    # machine (load average ~25) the tracker dropped frame sets of the hand's move and had not
    # found the lost wrist marker MRW1 again a second after the hand stopped (docs/LIVE.md).
    tracker = LiveTracker(SourceConfig(size=SIZE, fps=15.0, motion=None, sim_clock="frames"), ring_size=64)
    tracker.start(wait=False)  # as a game does: it keeps drawing while the process starts
    yield tracker
    tracker.close()


def _collect(live: LiveTracker, seconds: float) -> list:
    out = []
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        live.status()
        out.extend(live.poll())
        time.sleep(0.02)
    return out


def test_samples_arrive_identified_and_close_to_the_truth(live):
    assert len(live.cameras) == 4 and live.markerset.n_markers == 14
    assert "right_elbow_flexion" in live.angle_names
    assert _wait(lambda: live.status() and live.ready, 60.0, 0.05), live.status()
    samples = _collect(live, 2.0)
    assert len(samples) >= 5
    numbers = [s.number for s in samples]
    assert numbers == list(range(numbers[0], numbers[0] + len(numbers)))  # no gaps
    frames = [s.frame_index for s in samples]
    assert frames == sorted(frames)
    last = samples[-1]
    assert last.state == TrackingState.TRACKING
    measured = last.status == MarkerStatus.MEASURED
    assert measured.sum() >= 12
    err = np.linalg.norm(last.positions_m[measured] - last.truth_m[measured], axis=1)
    assert err.max() < 0.010
    assert np.isfinite(last.angle("right_elbow_flexion"))
    assert last.t_frame_ready_s <= last.t_published_s <= time.perf_counter()
    assert last.windows_px.shape == (14, 4, 3) and last.uv_px.shape == (14, 4, 2)
    assert last.stamps_s.shape == (4,) and np.isfinite(last.stamps_s).all()  # each image's instant
    images = live.latest_images()
    assert len(images) == 4 and images[0].shape == (240, 320, 3) and images[0].dtype == np.uint8
    assert images[0].std() > 5  # a rendered scene, not a blank
    status = live.status()
    assert status.alive and status.last_error == "" and status.restarts == 0
    assert status.source_fps > 0 and status.tracker_ms > 0


def test_the_interactive_hand_is_measured_where_it_goes(live):
    live.poll()
    right_w1, right_w2 = live.markerset.index("MRW1"), live.markerset.index("MRW2")
    start = live.latest().positions_m[right_w1].copy()
    target = (0.30, 1.05, -0.30)
    live.set_patient_input(PatientInput(side="right", hand_target_m=target, forearm_rotation_deg=0.0))

    def arrived():  # the wrist centre lies midway between the styloid markers
        s = live.latest()
        wrist = (s.truth_m[right_w1] + s.truth_m[right_w2]) / 2
        return np.linalg.norm(wrist - np.array(target)) < 0.01 and s

    got = _wait(arrived, 15.0, 0.05)
    assert got, "the simulated hand did not reach the target"
    # a second later (the tracker may have lost a hidden wrist marker on the way: re-acquired)
    sample = _wait(lambda: (s := live.latest()).frame_index > got.frame_index + 15 and s, 10.0)
    assert sample, "no samples after the hand arrived"
    assert sample.status[right_w1] == MarkerStatus.MEASURED
    assert np.linalg.norm(sample.positions_m[right_w1] - sample.truth_m[right_w1]) < 0.010
    assert np.linalg.norm(sample.positions_m[right_w1] - start) > 0.2  # it moved, and was followed
    live.set_patient_input(PatientInput())  # the arm stays where it is


def test_wait_pause_and_resume(live):
    live.poll()
    t0 = time.perf_counter()
    assert live.wait(5.0)
    assert time.perf_counter() - t0 < 5.0 and live.poll()
    live.pause()
    assert _wait(lambda: live.status().state == ProcessState.PAUSED, 5.0)
    live.poll()
    assert not live.wait(0.5)  # nothing new while paused
    assert live.status().alive  # the heartbeat goes on
    live.resume()
    assert live.wait(5.0) and live.poll()


def test_a_killed_process_is_replaced_within_2_s_without_blocking(live):
    assert _wait(lambda: live.status() and live.standby_ready, 60.0, 0.1), "no standby process"
    live.poll()
    old = live.pid
    os.kill(old, signal.SIGKILL)
    t0 = time.perf_counter()
    worst_call = 0.0
    saw_dead = False
    resumed = []
    # the goal is a new sample within 2 s on an idle machine (the standby takes over in a frame
    # or two); a loaded machine delays the standby's first frame by seconds: the test asserts the
    # replacement and that the game never waits for it, not the idle machine's figure
    while time.perf_counter() - t0 < RESUME_LIMIT_S and not resumed:
        c0 = time.perf_counter()
        status = live.status()
        new = live.poll()
        worst_call = max(worst_call, time.perf_counter() - c0)
        saw_dead |= not status.alive
        resumed = [s for s in new if s.t_frame_ready_s > t0]
        time.sleep(0.01)
    assert saw_dead
    assert resumed, f"no new sample within {RESUME_LIMIT_S:g} s: {live.status()}"
    print(f"a killed tracker process: a new sample after {resumed[0].t_frame_ready_s - t0:.2f} s")
    # status()/poll() never wait for a process (a wait is a join of 1 s or a start of seconds; a
    # loaded machine's scheduler alone may hold a call for a tenth of a second or two)
    assert worst_call < 0.5, worst_call
    status = live.status()
    assert status.alive and status.restarts == 1 and live.pid != old
    assert "killed (SIGKILL)" in status.last_error
    # reaped by the game's own status calls, never waiting for it (a loaded machine may take a moment
    # to tear a killed process down)
    assert _wait(lambda: live.status() and not os.path.exists(f"/proc/{old}"), 10.0, 0.05), "not reaped"


@pytest.mark.realtime
def test_a_hung_process_is_replaced(live):
    assert _wait(lambda: live.status() and live.standby_ready, 60.0, 0.1), "no standby process"
    old = live.pid
    os.kill(old, signal.SIGSTOP)
    t0 = time.perf_counter()
    try:
        assert _wait(lambda: live.status().restarts == 2 and live.pid != old, 5.0)
    finally:
        if os.path.exists(f"/proc/{old}"):
            os.kill(old, signal.SIGKILL)
    detected_s = time.perf_counter() - t0
    assert 0.9 < detected_s < 3.0
    assert "no heartbeat" in live.status().last_error
    assert _wait(lambda: live.status().alive and [s for s in live.poll() if s.t_frame_ready_s > t0],
                 RESUME_LIMIT_S)


def test_close_leaves_no_process_and_no_shared_memory(live):
    assert _my_blocks()
    pids = [p.pid for p in multiprocessing.active_children()]
    assert pids
    live.close()
    live.close()  # idempotent
    assert multiprocessing.active_children() == []
    for pid in pids:
        assert not os.path.exists(f"/proc/{pid}")
    assert _my_blocks() == []
    assert not live.status().alive


def faulty_source(config):
    """The simulated patient, in a tracker process whose tracker fails on every 7th frame set.

    Runs in the spawned tracker process only (a ``kind="module:function"`` source factory), so
    patching the class there touches nothing in the test process.
    """
    from tracking.tracker import Tracker

    step = Tracker.step

    def failing_step(self, images, time_s=None, stamps_s=None):
        if self.frame_count % 7 == 3:
            self.frame_count += 1
            raise ValueError("injected tracker failure\n(second line)")
        return step(self, images, time_s, stamps_s)

    Tracker.step = failing_step
    return SimulatedSource(config)


def test_a_tracker_exception_reaches_the_game_as_a_status_line():
    config = SourceConfig(kind=f"{__name__}:faulty_source", size=SIZE, fps=15.0, motion="reference")
    with LiveTracker(config, auto_restart=False, warm_standby=False) as live:
        status = _wait(lambda: (s := live.status()).errors >= 2 and s, 30.0, 0.05)
        assert status, "no error reported"
        assert status.last_error.startswith("tracker error at frame ")
        assert status.last_error.endswith(": ValueError: injected tracker failure (second line)")
        assert status.alive
        before = live.status().samples
        assert _wait(lambda: live.status().samples > before + 3, 10.0, 0.05)  # it keeps running
        samples = live.poll()
        assert samples and samples[-1].state == TrackingState.TRACKING
        assert live.status().restarts == 0

        # another source replaces the process and the blocks; a bad one leaves them alone
        first = live.pid
        with pytest.raises(LiveError, match="source size"):
            live.set_source(SourceConfig(size=(8, 8)))
        assert live.pid == first
        live.set_source(SourceConfig(rig="front4", size=(160, 120), fps=15.0, motion="reference"), wait=True)
        assert live.pid != first and not os.path.exists(f"/proc/{first}")
        assert live.cameras[0].size_px == (160, 120) and len(_my_blocks()) == 2
        assert _wait(lambda: live.poll(), 10.0, 0.05)
        assert live.latest_images()[0].shape == (120, 160, 3)
        assert live.status().errors == 0 and live.status().last_error == ""


def test_a_source_that_cannot_start_is_one_line(tmp_path):
    with pytest.raises(LiveError, match="unknown motion 'no_such_motion'"):
        LiveTracker(SourceConfig(size=SIZE, motion="no_such_motion")).start()
    with pytest.raises(LiveError, match="p<percentile>_<sex>"):
        LiveTracker(SourceConfig(body="tall")).start()
    bad = tmp_path / "bad.yaml"
    bad.write_text("kind: scripted\nkeyframes: 3\n")
    with pytest.raises(LiveError, match=r"cannot start: .*bad.yaml") as info:
        LiveTracker(SourceConfig(size=SIZE, motion=str(bad)), warm_standby=False).start()
    assert "\n" not in str(info.value)
    # without waiting: the reason shows in the status line
    live = LiveTracker(SourceConfig(size=SIZE, motion=str(bad)), auto_restart=False, warm_standby=False)
    live.start(wait=False)
    try:
        status = _wait(lambda: "cannot start" in (s := live.status()).last_error and s, 30.0, 0.05)
        assert status and not status.alive and "bad.yaml" in status.last_error
    finally:
        live.close()
    assert multiprocessing.active_children() == []
    assert _my_blocks() == []


def test_stale_blocks_of_a_dead_game_are_removed():
    from multiprocessing import shared_memory

    dead_pid = 2**22 + 12345  # above the default pid_max: no such process
    shm = shared_memory.SharedMemory(f"{BLOCK_PREFIX}{dead_pid}_abcd_samples", create=True, size=64)
    shm.close()
    from multiprocessing import resource_tracker

    resource_tracker.unregister(shm._name, "shared_memory")  # we play the crashed game: it never unlinks
    assert f"{BLOCK_PREFIX}{dead_pid}_abcd_samples" in remove_stale_blocks()
    assert not Path(f"/dev/shm/{BLOCK_PREFIX}{dead_pid}_abcd_samples").exists()



def test_a_start_that_reports_progress_gets_a_new_start_timeout():
    """A first start compiles the tracker's loops (seconds without numba's disk cache): the
    process says so, and the game counts its start timeout from then, not from the spawn."""
    from tracking.live.client import _Child

    child = object.__new__(_Child)  # its pipe only, no process
    child.conn, other = multiprocessing.Pipe()
    child.proc = type("P", (), {"pid": 1})()
    child.started_at = child.progress_at = time.perf_counter() - 25.0
    child.ready, child.failed = False, ""
    other.send(("progress", "compiling the tracker's loops"))
    child.receive()
    assert time.perf_counter() - child.progress_at < 1.0
    assert not child.ready and not child.failed


def test_a_replacement_killed_again_and_again_before_it_is_ready_is_started_again(monkeypatch):
    """It gave up for good after the 4th kill; now it retries with a growing wait until one runs."""
    from tracking.live import client

    monkeypatch.setattr(client, "RETRY_AFTER_S", 0.05)
    monkeypatch.setattr(client, "RETRY_MAX_S", 0.4, raising=False)
    tracker = LiveTracker(SourceConfig(size=SIZE, fps=15.0, motion=None), ring_size=16, warm_standby=False)
    tracker.start(wait=False)
    try:
        killed = []
        while len(killed) < 6:
            pid = _wait(lambda: tracker.status() and not tracker.ready and tracker.pid, 10.0)
            assert pid and pid not in killed, f"no new start after {len(killed)} kills: {tracker.status()}"
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)
            assert _wait(lambda: tracker.status() and tracker.pid != pid, 10.0)
            assert not tracker.gave_up
        assert "killed (SIGKILL) while starting" in tracker.status().last_error
        assert _wait(lambda: tracker.status() and tracker.ready, 60.0, 0.05), tracker.status()
        assert _wait(lambda: tracker.status() and tracker.poll(), 10.0, 0.05)   # samples flow again
    finally:
        tracker.close()
