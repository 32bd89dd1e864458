"""The tracker process's restarts: a starved process is not taken as hung; the tracker and its
standby killed together are replaced, retried for as long as it takes, and the game says so."""

import os
import signal
import subprocess
import sys
import time

import pytest

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
