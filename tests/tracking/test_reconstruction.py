"""Cross-camera matching and triangulation of unlabelled centroids."""

import numpy as np

from calibration import Camera
from tracking.reconstruction import CameraObservations, RigGeometry, reconstruct

COLOURS = np.array([0, 0, 1, 2, 1, 1, 2, 2, 1, 1, 2, 2, 0, 0])


def ring_rig(n=4):
    cams = []
    for k in range(n):
        az = np.radians(35 + 360.0 * k / n)
        cams.append(Camera.look_at(f"cam{k + 1}", (640, 480), 560, (2.2 * np.sin(az), 1.6, -2.2 * np.cos(az)), (0, 0.9, 0)))
    return cams


def observe(cams, p, colours, rng, sigma=0.15, drop=None):
    obs = []
    for c_idx, c in enumerate(cams):
        uv = c.project(p) + rng.normal(0, sigma, (len(p), 2))
        r = c.K[0, 0] * 0.02 / c.world_to_camera(p)[:, 2]
        keep = np.ones(len(p), bool) if drop is None else ~drop[:, c_idx]
        obs.append(CameraObservations(uv[keep], colours[keep], r[keep]))
    return obs


def match(points, p_true, tol=0.02):
    d = np.linalg.norm(points.p_world_m[:, None] - p_true[None], axis=-1)
    return d.min(axis=1), d.min(axis=0)


def test_all_markers_found_without_ghosts():
    cams = ring_rig()
    geo = RigGeometry.from_cameras(cams)
    rng = np.random.default_rng(0)
    ghosts = found = 0
    errs = []
    for _ in range(50):
        p = rng.normal([0, 0.9, 0], [0.3, 0.25, 0.15], size=(14, 3))
        pts = reconstruct(geo, observe(cams, p, COLOURS, rng))
        to_truth, from_truth = match(pts, p)
        ghosts += int((to_truth > 0.02).sum())
        found += int((from_truth < 0.02).sum())
        errs += list(to_truth[to_truth < 0.02])
    assert ghosts == 0
    assert found == 50 * 14
    assert np.sqrt(np.mean(np.square(errs))) < 0.0015


def test_two_camera_points_are_kept_when_unambiguous():
    cams = ring_rig()
    geo = RigGeometry.from_cameras(cams)
    rng = np.random.default_rng(1)
    p = np.array([[0.2, 1.0, -0.1], [-0.25, 0.7, 0.05]])
    drop = np.array([[False, True, True, False], [True, False, False, True]])  # each seen by 2
    pts = reconstruct(geo, observe(cams, p, np.array([0, 0]), rng, drop=drop))
    to_truth, from_truth = match(pts, p)
    assert (from_truth < 0.01).all() and (to_truth < 0.01).all()
    assert set(pts.n_cameras.tolist()) == {2}


def test_shifted_centroid_in_one_view_is_dropped():
    """A partly hidden ball gives a shifted centroid in one camera; the others outvote it."""
    cams = ring_rig()
    geo = RigGeometry.from_cameras(cams)
    p = np.array([[0.1, 1.0, 0.0]])
    obs = []
    for k, c in enumerate(cams):
        uv = c.project(p) + (np.array([[6.0, 0.0]]) if k == 2 else 0.0)
        obs.append(CameraObservations(uv, np.array([0]), np.array([c.K[0, 0] * 0.02 / c.world_to_camera(p)[0, 2]])))
    pts = reconstruct(geo, obs)
    assert len(pts) == 1
    assert pts.n_cameras[0] == 3 and pts.obs_index[0, 2] == -1
    assert np.linalg.norm(pts.p_world_m[0] - p[0]) < 1e-6


def test_blob_size_rejects_wrong_depth_pairings():
    """Observed radii that do not fit the triangulated depth make the point implausible."""
    cams = ring_rig(2)
    geo = RigGeometry.from_cameras(cams)
    p = np.array([[0.0, 0.9, 0.0]])
    obs = [CameraObservations(c.project(p), np.array([0]), np.array([30.0])) for c in cams]  # far too big
    assert len(reconstruct(geo, obs)) == 0


def test_empty_and_single_camera_inputs():
    cams = ring_rig()
    geo = RigGeometry.from_cameras(cams)
    assert len(reconstruct(geo, [CameraObservations.empty() for _ in cams])) == 0
    p = np.array([[0.0, 0.9, 0.0]])
    obs = [CameraObservations.empty() for _ in cams]
    obs[0] = CameraObservations(cams[0].project(p), np.array([0]), np.array([5.0]))
    assert len(reconstruct(geo, obs)) == 0
