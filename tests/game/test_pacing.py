"""The frame pacer's controller (game.pacing) on made-up frame intervals: a steady machine keeps
the full rate, a busy one gets the half rate within a second and keeps it without flickering,
and the full rate comes back once the machine is free again."""

import numpy as np
import pytest

from game.pacing import FramePacer, PaceLimits

FULL_S = 1.0 / 60.0


def _intervals(pacer: FramePacer, rng: np.random.Generator, miss_rate: float) -> float:
    """One frame's interval at the pacer's current period: a skipped refresh with probability
    ``miss_rate`` (a busy machine) at the full rate; the half rate's longer period absorbs it."""
    jitter = rng.uniform(-0.002, 0.002)
    if not pacer.halved and rng.random() < miss_rate:
        return 2 * FULL_S + rng.uniform(0.0, 0.03)
    return pacer.period_s + jitter


@pytest.mark.parametrize("seed", range(6))
def test_a_steady_machine_keeps_the_full_rate(seed):
    rng = np.random.default_rng(seed)
    pacer = FramePacer(60.0)
    for _ in range(3000):   # 50 s; a skipped refresh now and then (1 in 20) is no reason to halve
        pacer.observe(_intervals(pacer, rng, 0.05))
    assert not pacer.halved and pacer.changes == 0
    assert pacer.period_s == pytest.approx(FULL_S)


@pytest.mark.parametrize("miss_rate", [0.25, 0.33, 0.5])
@pytest.mark.parametrize("seed", range(6))
def test_a_busy_machine_gets_the_half_rate_and_the_full_rate_comes_back_after(seed, miss_rate):
    rng = np.random.default_rng(seed)
    pacer = FramePacer(60.0)
    for _ in range(120):
        pacer.observe(_intervals(pacer, rng, 0.0))
    for _ in range(60):   # a burst of a second: a third of the frames skip, then none
        pacer.observe(_intervals(pacer, rng, 0.33))
    for _ in range(300):
        pacer.observe(_intervals(pacer, rng, 0.0))
    assert not pacer.halved
    # busy: a quarter to a half of the frames skip a refresh
    for i in range(300):
        pacer.observe(_intervals(pacer, rng, miss_rate))
        if pacer.halved:
            break
    assert pacer.halved and i < 240, "halved within four seconds of the load"
    assert pacer.period_s == pytest.approx(2 * FULL_S)
    # 60 s of the same load: the full rate is tried now and then, each failed try waits twice as
    # long before the next, so the rate stays half nearly all the time
    halved, changes_before = 0, pacer.changes
    for _ in range(1800):
        pacer.observe(_intervals(pacer, rng, miss_rate))
        halved += pacer.halved
    assert halved / 1800 > 0.9
    assert pacer.changes - changes_before <= 10
    # the machine is free again: back to the full rate within the longest wait, and it stays
    for i in range(PaceLimits().max_rise_after + 200):
        pacer.observe(_intervals(pacer, rng, 0.0))
        if not pacer.halved:
            break
    assert not pacer.halved
    changes = pacer.changes
    for _ in range(600):
        pacer.observe(_intervals(pacer, rng, 0.0))
    assert not pacer.halved and pacer.changes == changes


def test_a_return_that_holds_resets_the_wait():
    pacer = FramePacer(60.0, limits=PaceLimits(window=10, drop_misses=2, rise_after=5, max_rise_after=40, hold=20, probe=10, probe_misses=2))
    slow, quick = 3 * FULL_S, FULL_S
    pacer.observe(slow), pacer.observe(slow)
    assert pacer.halved
    for _ in range(5):
        pacer.observe(2 * FULL_S)
    assert not pacer.halved                      # tried after rise_after frames
    pacer.observe(slow), pacer.observe(slow)     # failed at once: the next wait is doubled
    assert pacer.halved
    for n in range(1, 11):
        pacer.observe(2 * FULL_S)
        if not pacer.halved:
            break
    assert n == 10
    for _ in range(21):                          # held for `hold` frames: the wait is back to 5
        pacer.observe(quick)
    pacer.observe(slow), pacer.observe(slow)
    assert pacer.halved
    for n in range(1, 11):
        pacer.observe(2 * FULL_S)
        if not pacer.halved:
            break
    assert n == 5


def test_without_adaptation_the_rate_stays_full():
    pacer = FramePacer(60.0, adaptive=False)
    for _ in range(200):
        pacer.observe(0.1)
    assert not pacer.halved and pacer.period_s == pytest.approx(FULL_S)


def test_bad_limits_are_refused():
    with pytest.raises(ValueError):
        PaceLimits(drop_misses=0)
    with pytest.raises(ValueError):
        PaceLimits(miss_at=0.9)
    with pytest.raises(ValueError):
        PaceLimits(hold=10)
    with pytest.raises(ValueError):
        FramePacer(0.0)


@pytest.mark.parametrize("flag, adaptive", [((), True), (("--fixed-rate",), False)])
def test_rehab_play_halves_on_a_busy_machine_unless_told_to_keep_the_rate(monkeypatch, capsys, flag, adaptive):
    import game.play
    from game.app import RunSummary
    from game.cli import main

    seen = []
    monkeypatch.setattr(game.play, "run_play", lambda options: seen.append(options) or RunSummary(1, 1, 1.0, 1.0))
    assert main(["play", "--headless", "--seconds", "1", *flag]) == 0
    assert seen[0].settings.adaptive_pace is adaptive
