"""Stillness (the hold of the reference pose): flickering points do not stop it, moving ones do."""

import numpy as np

from tracking.labelling.still import Stillness

FPS = 30.0


def _points(rng, n=14):
    return rng.uniform(-0.5, 0.5, (n, 3)) + np.array([0.0, 1.2, 2.5])


def test_points_that_flicker_in_and_out_complete_the_hold():
    """As on webcam images: 5-10 of 14 points made, a different subset every frame set, 1.5 mm of
    jitter; the old frame-to-frame comparison never completed the hold on such a sequence."""
    rng = np.random.default_rng(3)
    truth, colour = _points(rng), np.arange(14) % 4
    still = Stillness(FPS, hold_s=0.2)
    done = []
    for _ in range(20):
        seen = rng.random(14) < 0.55
        p = truth[seen] + rng.normal(0.0, 0.0015, (seen.sum(), 3))
        done.append(still.update(p, colour[seen]))
    assert max(done) == 1.0
    assert done.index(1.0) <= still.frames_needed + 4


def test_a_moving_arm_never_completes_the_hold():
    """Half of the points (an arm) moving 15 mm per frame set (0.45 m/s), all points seen, no noise."""
    rng = np.random.default_rng(4)
    truth, colour = _points(rng), np.arange(14) % 4
    still = Stillness(FPS, hold_s=0.2)
    for k in range(30):
        p = truth.copy()
        p[7:, 1] += 0.015 * k
        assert still.update(p, colour) == 0.0


def test_slow_drift_within_the_step_counts_as_still_and_a_jump_restarts_it():
    rng = np.random.default_rng(5)
    truth, colour = _points(rng), np.zeros(14, int)
    still = Stillness(FPS, hold_s=0.2)
    for k in range(8):
        done = still.update(truth + [0.002 * k, 0.0, 0.0], colour)
    assert done == 1.0
    assert still.update(truth + [0.1, 0.0, 0.0], colour) == 0.0
    assert still.update(np.zeros((0, 3)), np.zeros(0, int)) == 0.0
