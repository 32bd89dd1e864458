"""The tracker process's restarts: a starved process is not taken as hung; the tracker and its
standby killed together are replaced, retried for as long as it takes, and the game says so."""

import os
import signal
import subprocess
import sys
import time

import pytest

from tests.test_live_process import _wait
from tracking.live.client import process_activity_s, process_cpu_s

pytestmark = pytest.mark.skipif(not os.path.exists("/proc/self/schedstat"), reason="needs Linux scheduler statistics")

_BUSY = "import os, sys; os.sched_setaffinity(0, {int(sys.argv[1])})\nwhile True: pass"


def test_a_process_starved_of_cpu_is_active_a_stopped_one_is_not():
    """Three busy loops on one CPU: each runs a third of the time and waits the rest; its CPU time
    alone grows at a third of the clock (it looked hung to a loaded machine's game), its CPU time
    plus its wait for a CPU at the clock's rate. A stopped process does neither."""
    cpu = sorted(os.sched_getaffinity(0))[0]
    procs = [subprocess.Popen([sys.executable, "-c", _BUSY, str(cpu)]) for _ in range(3)]
    try:
        time.sleep(0.5)
        pid = procs[0].pid
        a0, c0, t0 = process_activity_s(pid), process_cpu_s(pid), time.perf_counter()
        time.sleep(2.0)
        a1, c1, t1 = process_activity_s(pid), process_cpu_s(pid), time.perf_counter()
        assert (c1 - c0) < 0.7 * (t1 - t0)   # starved: far from a whole CPU
        assert (a1 - a0) > 0.8 * (t1 - t0)   # but running or waiting to run all along
        os.kill(pid, signal.SIGSTOP)
        time.sleep(0.2)
        s0 = process_activity_s(pid)
        time.sleep(1.0)
        assert process_activity_s(pid) - s0 < 0.05
    finally:
        for p in procs:
            p.kill()
            p.wait()


SIZE = (320, 240)

def test_the_tracker_and_its_standby_killed_together_are_replaced():
    """The out-of-memory killer's case: no standby to take over, a new process starts at once."""
    from tracking.live import LiveTracker, SourceConfig

    with LiveTracker(SourceConfig(size=SIZE, fps=15.0, motion="reference"), ring_size=32) as live:
        assert _wait(lambda: live.status() and live.standby_ready, 120.0), "no standby process"
        live.poll()
        old, spare = live.pid, live._spare.pid
        t0 = time.perf_counter()
        os.kill(old, signal.SIGKILL)
        os.kill(spare, signal.SIGKILL)
        resumed = _wait(lambda: live.status() and [s for s in live.poll() if s.t_frame_ready_s > t0], 120.0)
        assert resumed, live.status()
        print(f"the tracker and its standby killed: a new sample after {resumed[0].t_published_s - t0:.2f} s")
        status = live.status()
        assert status.alive and live.pid not in (old, spare)
        assert "killed (SIGKILL)" in status.last_error
    # killed processes are reaped without blocking the game (join 0, then later; close() waits for
    # them): none is left once the tracker is closed
    assert not os.path.exists(f"/proc/{old}") and not os.path.exists(f"/proc/{spare}")


def failing_source(config):
    """The simulated patient, in a tracker process that cannot start the first few times
    (counted in the file named by REHAB_TEST_STARTS; a ``kind="module:function"`` source)."""
    from calibration.errors import RehabError
    from tracking.sources.sim import SimulatedSource

    path = os.environ["REHAB_TEST_STARTS"]
    with open(path, "a+") as f:
        f.write("x")
        f.seek(0)
        n = len(f.read())
    if n <= 6:
        raise RehabError(f"injected start failure {n}")
    return SimulatedSource(config)


def test_a_process_that_cannot_start_is_tried_again_for_as_long_as_it_takes(tmp_path, monkeypatch):
    """It gave up for good after 4 failed starts; now it keeps trying, with a growing wait."""
    from tracking.live import LiveTracker, SourceConfig, client

    monkeypatch.setattr(client, "RETRY_AFTER_S", 0.05)
    monkeypatch.setattr(client, "RETRY_MAX_S", 0.2)
    monkeypatch.setenv("REHAB_TEST_STARTS", str(tmp_path / "starts"))
    config = SourceConfig(kind=f"{__name__}:failing_source", size=SIZE, fps=15.0, motion="reference")
    live = LiveTracker(config, ring_size=16, warm_standby=False)
    live.start(wait=False)
    try:
        assert _wait(lambda: live.status() and live.gave_up, 120.0), live.status()
        assert "injected start failure" in live.status().last_error
        assert _wait(lambda: live.status() and live.ready and live.poll(), 180.0, 0.05), live.status()
        assert len((tmp_path / "starts").read_text()) == 7
    finally:
        live.close()


def test_a_start_slowed_by_a_busy_machine_is_not_taken_as_hung_a_stopped_one_is():
    """Past the start timeout, a starting process that still runs or waits for a CPU (three busy
    loops on one CPU) is left to finish its start (a busy machine gave it a share of a core and it
    was killed as "stopped answering while starting", to start again from nothing); a stopped one
    is hung a second later; past SLOW_START_S any start is."""
    from tracking.live.client import SLOW_START_S, START_TIMEOUT_S, _Child

    cpu = sorted(os.sched_getaffinity(0))[0]
    procs = [subprocess.Popen([sys.executable, "-c", _BUSY, str(cpu)]) for _ in range(3)]
    try:
        children = []
        for p in procs[:2]:
            child = object.__new__(_Child)   # the start's bookkeeping only, on a busy process
            child.proc = p
            child.started_at = child.progress_at = time.perf_counter() - START_TIMEOUT_S - 5.0
            child._cpu_seen_s, child._cpu_grew_at = float("nan"), child.started_at
            children.append(child)
        busy, stopped = children
        os.kill(stopped.proc.pid, signal.SIGSTOP)
        time.sleep(0.2)
        assert not busy.start_hung(time.perf_counter()) and not stopped.start_hung(time.perf_counter())
        for _ in range(15):   # the game looks every frame; here every 0.1 s for 1.5 s
            time.sleep(0.1)
            now = time.perf_counter()
            assert not busy.start_hung(now)
        assert stopped.start_hung(time.perf_counter())
        busy.progress_at = time.perf_counter() - 10.0   # a progress message: a new start timeout
        assert not busy.start_hung(time.perf_counter())
        busy.progress_at = time.perf_counter() - SLOW_START_S - 1.0
        assert busy.start_hung(time.perf_counter())
    finally:
        for p in procs:
            p.kill()
            p.wait()
