"""Cameras' clock offsets and drifts from the markers' motion (tracking.clock_sync, --sync auto)."""

import dataclasses

import numpy as np
import pytest

from tracking.clock_sync import ClockEstimate, SkewEvidence, fit_clocks, skew_evidence, stamp_timing
from tracking.sim.renderer import typical_studio_cameras

FPS = 30.0


def moving_points(t):
    """(T, 14, 3) points circling at 0.3-1 m/s in front of the typical studio's cameras at the
    instants ``t`` (T,) or (T, 14)."""
    k = np.arange(14)
    t = t[:, None] if t.ndim == 1 else t
    phase = 2 * np.pi * (0.5 + 0.1 * k)[None, :] * t + k[None, :]
    r = 0.1 + 0.01 * k[None, :]
    return np.stack([0.2 * np.sin(k)[None, :] + r * np.cos(phase), 0.9 + 0.02 * k[None, :] + r * np.sin(phase),
                     0.1 * np.cos(k)[None, :] + 0.05 * np.sin(phase / 2)], axis=-1)


@pytest.mark.parametrize("rolling_s", [0.0, 0.025])
def test_offsets_and_drifts_are_recovered_from_the_motion(rolling_s):
    cams = [dataclasses.replace(c, rolling_shutter_s=rolling_s) for c in typical_studio_cameras((320, 240))]
    truth = ClockEstimate(np.array([0.0, 0.4, -0.45, 0.2]) / FPS, np.array([0.0, 0.001, -0.001, 0.0005]),
                          np.zeros(4), 1.0 / FPS)
    t = np.arange(240) / FPS
    skew = truth.skews(t)  # (wraps: camera 2 crosses half a period)
    assert np.abs(np.diff(skew[:, 1])).max() > 0.9 / FPS
    uv = np.full((len(t), 14, 4, 2), np.nan)
    rng = np.random.default_rng(1)
    for c, cam in enumerate(cams):
        row = np.zeros((len(t), 14))
        for _ in range(3):  # each point at the instant of its own row
            uv[:, :, c] = cam.project(moving_points(t[:, None] + skew[:, c, None] + rolling_s * row).reshape(-1, 3)
                                      ).reshape(len(t), 14, 2)
            row = uv[:, :, c, 1] / cam.size_px[1]
    uv += rng.normal(0.0, 0.1, uv.shape)  # centroid noise
    # the tracked positions: at the first camera's instants, off by a millimetre
    tracked = moving_points(t) + rng.normal(0.0, 0.001, (len(t), 14, 3))
    est = fit_clocks(skew_evidence(cams, t, tracked, uv), 1.0 / FPS)
    assert est.offset_s == pytest.approx(truth.offset_s, abs=0.0005)
    assert est.rate == pytest.approx(truth.rate, abs=0.0002)
    # within a millisecond modulo the period: near a wrap (the phase near half a period) the
    # estimate switches phase up to (offset error / drift) earlier or later than the camera did
    d = np.abs(est.skews(t) - skew)
    d = np.minimum(d, 1.0 / FPS - d)
    assert d.max() < 0.001 and (np.abs(est.skews(t) - skew) > 0.001).mean() < 0.03


def test_still_markers_tell_nothing():
    cams = typical_studio_cameras((320, 240))
    t = np.arange(90) / FPS
    still = np.repeat(moving_points(np.zeros(1)), len(t), axis=0)
    uv = np.stack([cam.project(still.reshape(-1, 3)).reshape(len(t), 14, 2) for cam in cams], axis=2)
    est = fit_clocks(skew_evidence(cams, t, still, uv), 1.0 / FPS)
    assert np.isinf(est.sigma_s[1:]).all() and (est.offset_s == 0).all()
    assert "not estimated (its views of the markers hardly moved)" in est.line(["cam1", "cam2", "cam3", "cam4"])


def test_an_uncertain_estimate_is_not_used():
    """Views whose image motion over a skew is below the centroids' noise (a slow motion's): the
    skew's standard error from the cost's curvature exceeds half a millisecond, the camera keeps
    the first camera's instants and the line says so; the same views with less noise are used."""
    rng = np.random.default_rng(4)
    n = 300
    t = np.sort(rng.uniform(0.0, 10.0, n))
    g = rng.normal(0.0, 20.0, (n, 2))  # image velocity of camera 2's views, px/s
    a = np.zeros((n, 2, 2))
    a[:, 1, 1] = (g * g).sum(axis=1)
    for noise_px, used in ((1.0, False), (0.02, True)):
        r = g * 0.010 + rng.normal(0.0, noise_px, (n, 2))  # residuals of a 10 ms skew
        b = np.zeros((n, 2))
        b[:, 1] = (g * r).sum(axis=1)
        ev = SkewEvidence(t, a, b, (r * r).sum(axis=1), np.full(n, 2.0))
        est = fit_clocks(ev, 1.0 / FPS)
        if used:
            assert est.offset_s[1] == pytest.approx(0.010, abs=3e-4) and 0 < est.sigma_s[1] < 5e-4
        else:
            assert est.offset_s[1] == 0.0 and est.rate[1] == 0.0 and est.sigma_s[1] < -5e-4
            assert "cam2 uncertain (+-" in est.line(["cam1", "cam2"]) and "too little motion), not used" in est.line(
                ["cam1", "cam2"])


def test_stamp_timing_offsets_drifts_and_jitter():
    """The live camera check's figures from the images' stamps: a camera that skips images or
    gives one twice is still counted right; a jittery one is named irregular."""
    period = 1.0 / FPS
    k = np.arange(300)
    rng = np.random.default_rng(2)
    stamps = np.stack([k * period, 0.012 + k * period * 1.001, k * period + rng.normal(0, 0.004, k.size),
                       -0.008 + k * period * 0.9995], axis=1)
    stamps[100, 1] = stamps[99, 1]  # one image twice
    stamps[200, 3] = np.nan  # one missing
    tm = stamp_timing(stamps)
    assert tm.period_s == pytest.approx(period, rel=1e-3)
    assert tm.offset_s[1] == pytest.approx((0.012 + 299 * period * 0.001 + period / 2) % period - period / 2, abs=1e-6)
    assert tm.drift[1:] == pytest.approx([1 / 1.001 - 1, 0.0, 1 / 0.9995 - 1], abs=2e-4)
    assert tm.jitter_s[[0, 1, 3]] == pytest.approx(0.0, abs=1e-9) and 0.003 < tm.jitter_s[2] < 0.005
    assert tm.irregular.tolist() == [False, False, True, False]
    assert stamp_timing(stamps[:10]).lines(["a", "b", "c", "d"])[1] == "b: timing being measured"
