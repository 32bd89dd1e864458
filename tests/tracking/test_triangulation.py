"""Triangulation: exactness, noise behaviour, the seed's two-camera formulas, degenerate input."""

import numpy as np
from hypothesis import given, settings, strategies as st

from calibration import Camera
from tracking.triangulation import (
    pair_frame,
    ray_to_cylinder,
    seed_cylinder_stereo,
    seed_parallel_stereo,
    triangulate,
    triangulate_one,
)


def ring_rig(n=4, radius=2.2, height=1.6, size=(640, 480), f=560.0):
    cams = []
    for k in range(n):
        az = np.radians(35 + 360.0 * k / n)
        eye = (radius * np.sin(az), height, -radius * np.cos(az))
        cams.append(Camera.look_at(f"cam{k + 1}", size, f, eye, (0, 0.9, 0)))
    return cams


def normalized(cams, p):
    return np.stack([c.undistort_points(c.project(p)) for c in cams], axis=1)  # (N, C, 2)


def test_exact_points_are_recovered():
    cams = ring_rig()
    rng = np.random.default_rng(0)
    p = rng.normal([0, 0.9, 0], 0.3, size=(50, 3))
    ext = np.stack([c.extrinsic for c in cams])
    out = triangulate(ext, normalized(cams, p))
    assert np.abs(out - p).max() < 1e-9


def test_fewer_than_two_views_gives_nan():
    cams = ring_rig()
    p = np.array([[0.1, 1.0, 0.0]])
    xn = normalized(cams, p)
    seen = np.array([[True, False, False, False]])
    out = triangulate(np.stack([c.extrinsic for c in cams]), xn, seen)
    assert np.isnan(out).all()


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    sigma_px=st.floats(0.05, 1.0),
    n_views=st.integers(2, 4),
)
def test_error_under_noise_is_bounded_and_shrinks_with_views(seed, sigma_px, n_views):
    """Pixel noise of sigma gives a 3D error of the order sigma * depth / f, never a blow-up."""
    cams = ring_rig()[:n_views]
    rng = np.random.default_rng(seed)
    p = rng.normal([0, 0.9, 0], 0.25, size=(200, 3))
    uv = np.stack([c.project(p) for c in cams], axis=1) + rng.normal(0, sigma_px, (200, n_views, 2))
    xn = np.stack([c.undistort_points(uv[:, k]) for k, c in enumerate(cams)], axis=1)
    out = triangulate(np.stack([c.extrinsic for c in cams]), xn)
    rms = np.sqrt(np.mean(np.sum((out - p) ** 2, axis=1)))
    # depth ~2.3 m, f = 560 px: one pixel ~ 4 mm at the patient; the geometry costs < x3
    assert rms < 3.0 * sigma_px * 2.3 / 560 * 1.8


def test_seed_parallel_formula_matches_least_squares():
    """Seed equation 2 on a rectified pair equals N-view linear least squares on the same pair."""
    baseline = 0.5
    K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
    # camera 1 at x=-l/2, camera 2 at x=+l/2, both looking along +z (world = pair frame here)
    cam1 = Camera("c1", (640, 480), K, np.zeros(4), np.zeros(3), np.array([baseline / 2, 0, 0]))
    cam2 = Camera("c2", (640, 480), K, np.zeros(4), np.zeros(3), np.array([-baseline / 2, 0, 0]))
    p = np.array([0.13, -0.2, 2.1])
    (u1, v1), (u2, _) = cam1.project(p[None])[0] - K[:2, 2], cam2.project(p[None])[0] - K[:2, 2]
    seed = seed_parallel_stereo(u1, v1, u2, 600.0, baseline)
    lsq = triangulate_one(np.stack([cam1.extrinsic, cam2.extrinsic]), normalized([cam1, cam2], p[None])[0])
    assert np.allclose(seed, p, atol=1e-9)
    assert np.allclose(seed, lsq, atol=1e-9)


def test_seed_cylinder_formula_matches_least_squares_for_facing_cameras():
    """Seed equation 3: cameras facing each other across the patient (no common image plane)."""
    front = Camera.look_at("front", (640, 480), 560, (0.3, 1.5, -2.2), (0, 0.9, 0))
    back = Camera.look_at("back", (640, 480), 560, (-0.3, 1.6, 2.2), (0, 0.9, 0))
    rng = np.random.default_rng(3)
    for p in rng.normal([0, 0.9, 0], 0.25, size=(10, 3)):
        uv1, uv2 = front.project(p[None]), back.project(p[None])
        R, origin = pair_frame(front.centre_m, back.centre_m)
        baseline = np.linalg.norm(back.centre_m - front.centre_m)
        u1, th1 = ray_to_cylinder(front.back_project(uv1)[1][0], R, 560.0)
        u2, _ = ray_to_cylinder(back.back_project(uv2)[1][0], R, 560.0)
        seed_pair = seed_cylinder_stereo(u1, th1, u2, 560.0, baseline)
        seed_world = R.T @ seed_pair + origin
        lsq = triangulate_one(np.stack([front.extrinsic, back.extrinsic]), normalized([front, back], p[None])[0])
        assert np.allclose(seed_world, p, atol=1e-8)
        assert np.allclose(seed_world, lsq, atol=1e-8)


def test_distortion_is_removed_before_triangulating():
    cams = [
        Camera(c.name, c.size_px, c.K, [-0.25, 0.08, 0.001, -0.0005, 0.0], c.rvec, c.t_m)
        for c in ring_rig(3)
    ]
    p = np.array([[0.35, 1.25, -0.1], [-0.3, 0.5, 0.2]])
    out = triangulate(np.stack([c.extrinsic for c in cams]), normalized(cams, p))
    assert np.abs(out - p).max() < 1e-7
