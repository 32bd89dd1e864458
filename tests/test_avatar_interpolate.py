"""Smooth avatar poses at the display rate: slerp, lerp, the interpolator's timing and no overshoot."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from game.avatar.interpolate import PoseInterpolator, lerp_pose, slerp_frames
from game.avatar.skeleton import JOINTS, SEGMENTS, Proportions, SkeletonPose
from tracking.geometry.rotations import axis_angle_matrix, slerp_rotation
from tracking.marker_status import MarkerStatus


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def pose_at(value: float, angle_rad: float = 0.0, state: int = MarkerStatus.MEASURED) -> SkeletonPose:
    """A pose whose joints all sit at ``value`` and whose frames turn by ``angle_rad`` about z."""
    r = axis_angle_matrix(np.array([0.0, 0.0, 1.0]), angle_rad)
    return SkeletonPose(
        joints_m=np.full((len(JOINTS), 3), float(value)),
        frames=np.repeat(r[None], len(SEGMENTS), axis=0),
        state=np.full(len(SEGMENTS), state, np.uint8),
        proportions=Proportions.default(),
    )


def test_slerp_matches_the_geodesic_and_its_ends():
    rng = np.random.default_rng(3)
    for _ in range(20):
        r0, r1 = random_rotation(rng), random_rotation(rng)
        w = rng.uniform()
        np.testing.assert_allclose(slerp_frames(r0, r1, 0.0), r0, atol=1e-9)
        np.testing.assert_allclose(slerp_frames(r0, r1, 1.0), r1, atol=1e-9)
        np.testing.assert_allclose(slerp_frames(r0, r1, w), slerp_rotation(r0, r1, w), atol=1e-7)


def test_slerp_of_identical_rotations_and_batches():
    rng = np.random.default_rng(4)
    rs = np.stack([random_rotation(rng) for _ in range(5)])
    np.testing.assert_allclose(slerp_frames(rs, rs, 0.3), rs, atol=1e-9)
    assert slerp_frames(rs, rs[::-1], 0.5).shape == (5, 3, 3)


def test_lerp_pose_moves_joints_linearly_and_turns_frames_halfway():
    a, b = pose_at(0.0, 0.0), pose_at(1.0, 1.0)
    mid = lerp_pose(a, b, 0.25)
    np.testing.assert_allclose(mid.joints_m, 0.25)
    np.testing.assert_allclose(mid.frames[0], axis_angle_matrix(np.array([0.0, 0.0, 1.0]), 0.25), atol=1e-12)


def test_state_switches_at_the_midpoint():
    a, b = pose_at(0.0), pose_at(1.0, state=MarkerStatus.LOST)
    assert (lerp_pose(a, b, 0.49).state == MarkerStatus.MEASURED).all()
    assert (lerp_pose(a, b, 0.51).state == MarkerStatus.LOST).all()


def test_display_at_60_hz_follows_a_30_hz_ramp_one_interval_late():
    interp = PoseInterpolator()
    dt = 1.0 / 30.0
    for k in range(10):
        interp.push(k * dt, pose_at(k * dt))  # joints move 1 m/s
    assert interp.delay_s == pytest.approx(dt)
    for t in np.arange(4 * dt, 9 * dt, 1.0 / 60.0):
        shown = interp.sample(t)
        assert shown.joints_m[0, 0] == pytest.approx(t - dt, abs=1e-9)


def test_late_samples_hold_the_newest_pose_and_early_times_the_oldest():
    interp = PoseInterpolator()
    assert interp.sample(1.0) is None
    interp.push(0.0, pose_at(0.0))
    interp.push(0.1, pose_at(1.0))
    assert interp.sample(5.0).joints_m[0, 0] == 1.0  # no extrapolation
    assert interp.sample(-5.0).joints_m[0, 0] == 0.0


def test_old_or_repeated_time_stamps_are_ignored():
    interp = PoseInterpolator()
    interp.push(1.0, pose_at(1.0))
    interp.push(1.0, pose_at(5.0))
    interp.push(0.5, pose_at(7.0))
    assert len(interp) == 1 and interp.sample(2.0).joints_m[0, 0] == 1.0


@settings(max_examples=40, deadline=None)
@given(
    values=st.lists(st.floats(-2.0, 2.0), min_size=2, max_size=10),
    gaps=st.lists(st.floats(0.02, 0.08), min_size=9, max_size=9),
    display=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20),
)
def test_never_overshoots_the_two_samples_around_it(values, gaps, display):
    interp = PoseInterpolator(capacity=16)
    times = np.concatenate([[0.0], np.cumsum(gaps)])[: len(values)]
    for t, v in zip(times, values):
        interp.push(float(t), pose_at(v, angle_rad=0.5 * v))  # turns < 180 deg apart
    for d in display:
        t = float(d) * (times[-1] + 0.1)
        shown = interp.sample(t)
        x = shown.joints_m[0, 0]
        lag = t - interp.delay_s
        k = int(np.searchsorted(times, lag))
        lo_i, hi_i = max(k - 1, 0), min(k, len(values) - 1)
        lo, hi = sorted((values[lo_i], values[hi_i]))
        assert lo - 1e-9 <= x <= hi + 1e-9
        angle = np.arctan2(shown.frames[0][1, 0], shown.frames[0][0, 0])
        assert 0.5 * lo - 1e-6 <= angle <= 0.5 * hi + 1e-6


def test_capacity_must_hold_two_samples():
    with pytest.raises(ValueError):
        PoseInterpolator(capacity=1)


def test_look_fader_fades_a_real_change_and_smooths_flicker():
    from game.avatar.interpolate import LookFader

    n = len(SEGMENTS)
    fader = LookFader(n, tau_s=0.15)
    measured = np.full(n, MarkerStatus.MEASURED, np.uint8)
    estimated = np.full(n, MarkerStatus.ESTIMATED, np.uint8)
    assert (fader.update(measured, 0.0) == 0).all()
    # A real change: visible within a few tenths of a second, complete after half a second.
    assert 0.0 < fader.update(estimated, 0.05)[0, 0] < 0.5
    assert fader.update(estimated, 0.6)[0, 0] > 0.95
    # A marker flickering every sample (30 Hz) at display frames (60 Hz): no blinking.
    fader.reset()
    levels = []
    for k in range(120):
        t = k / 60.0
        state = estimated if int(t * 30) % 2 else measured
        levels.append(fader.update(state, t)[0, 0])
    tail = np.array(levels[60:])
    assert np.ptp(tail) < 0.25
    with pytest.raises(ValueError):
        fader.update(np.zeros(n + 1, np.uint8), 1.0)
