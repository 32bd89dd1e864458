"""`rehab bench`'s per-frame figures: alternating passes, each tracking pass against the
full-frame pass before it, and the best pass named (speed is reported, not asserted)."""

import re

from tracking.drivers.bench import run_benchmarks


def test_bench_reports_each_pass_and_the_best():
    lines = list(run_benchmarks(n_frames=12, passes=2))
    text = "\n".join(lines)
    full = re.search(r"full-frame measurement.*passes ([\d.]+) ([\d.]+) ms\)", text)
    track = re.search(r"steady-state tracking, 4x640x480: +([\d.]+) ms.*passes ([\d.]+)x ([\d.]+)x\)", text)
    passes = re.search(r"passes: ([\d.]+) ([\d.]+) ms; best pass ([\d.]+) ms \((\d+) frame sets/s", text)
    assert full and track and passes, text
    t1, t2, best = float(passes[1]), float(passes[2]), float(passes[3])
    assert best == min(t1, t2) and min(t1, t2) <= float(track[1]) <= max(t1, t2)
    # each ratio is that pass's full-frame time over its tracking time (2 decimals printed)
    for k in (1, 2):
        ratio = float(full[k]) / float(passes[k])
        assert abs(float(track[k + 1]) - ratio) <= 0.051 + 0.01 * ratio
    assert sum("speed target" in line for line in lines) == 3
    worst = re.search(r"worst frame set of each pass: ([\d.]+) ([\d.]+) ms", text)
    assert worst and float(worst[1]) >= t1 and float(worst[2]) >= t2  # the slowest is not below the median
    webcam = re.search(r"webcam images .*full-frame measurement median ([\d.]+) ms, worst ([\d.]+) ms", text)
    assert webcam and float(webcam[2]) >= float(webcam[1]), text
