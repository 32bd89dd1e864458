"""The soak command's measurements: processes below the game, their memory, the verdict."""

import os
import subprocess
import sys
import time

import pytest

from game.soak import ProcInfo, Sample, SoakResult, descendants, read_proc, report, rss_kb

pytestmark = pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="reads /proc (Linux)")


def test_descendants_and_their_memory_are_read_from_proc():
    parent = subprocess.Popen([sys.executable, "-c",
                               "import subprocess, sys, time; "
                               "c = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(30)']); "
                               "print(c.pid, flush=True); time.sleep(30)"], stdout=subprocess.PIPE, text=True)
    try:
        child = int(parent.stdout.readline())
        found = {p.pid: p for p in descendants(parent.pid)}
        assert child in found and found[child].ppid == parent.pid
        # the child has just been started: its interpreter maps its memory within a moment (right
        # after the exec its resident set can read a few kB on a busy machine)
        deadline = time.monotonic() + 10.0
        while rss_kb(child) <= 1000 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert rss_kb(child) > 1000 and rss_kb(parent.pid) > 1000
        assert read_proc(child).start_ticks == found[child].start_ticks
    finally:
        parent.kill()
        parent.wait()
        os.kill(child, 9)
    time.sleep(0.2)
    assert read_proc(child) is None or read_proc(child).start_ticks != found[child].start_ticks


def _result(game_mb, child_mb, left=(), blocks_left=()):
    samples = [Sample(10.0 * i, int(g * 1024), {} if c is None else {1: int(c * 1024), 2: 1024})
               for i, (g, c) in enumerate(zip(game_mb, child_mb))]
    seen = {1: ProcInfo(1, 0, 1, "python"), 2: ProcInfo(2, 0, 1, "python")}
    return SoakResult(10.0 * len(samples), 0, samples, 20.0, seen, list(left), {"rehab_live_1_a_samples"},
                      set(blocks_left), "rehab play: 100 frames in 60 s")


def test_growth_counts_from_the_warm_up_to_the_last_sample_with_every_process_up():
    # start-up (no children yet), up at 10 s, warm-up 20 s, then +3 MB, then the shutdown (children gone)
    r = _result([5, 150, 180, 190, 191, 192, 193, 120], [None, 300, 600, 600, 600, 600, 600, None])
    lines, ok = report(r, 10.0)
    assert ok, lines
    text = "\n".join(lines)
    assert "growth after the warm-up: +3.0 MB" in text
    assert "0 left behind" in text and "the session: 100 frames in 60 s" in text
    grown = _result([5, 150, 180, 190, 195, 200, 205, 120], [None, 300, 600, 600, 600, 600, 600, None])
    assert not report(grown, 10.0)[1]                                    # +15 MB: failed
    left = _result([5, 150, 180, 190, 191, 192, 193, 120], [None, 300, 600, 600, 600, 600, 600, None],
                   left=[ProcInfo(2, 0, 1, "python")], blocks_left={"rehab_live_1_a_samples"})
    lines, ok = report(left, 10.0)
    assert not ok and any("1 left behind (2 python)" in line for line in lines)
    assert any("rehab_live_1_a_samples" in line for line in lines)
