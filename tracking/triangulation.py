"""Triangulation of 3D points from several calibrated cameras.

Pure numpy. Observations are *ideal normalized* image coordinates (distortion removed, divided by
the focal length: ``x = X_cam / Z_cam``), so every camera enters with the 3x4 extrinsic matrix
``[R | t]`` (world -> camera) and the least-squares system is well conditioned.

The general method is linear least squares (DLT) over all cameras that see the point, with one
reweighting by the projective depth so that each camera's residual approximates its image-plane
error (the plain DLT weights far cameras less). The seed paper's two-camera formulas (METHOD.md
section 5.1, equations 2 and 3) are implemented as a documented reference in
:func:`seed_parallel_stereo` and :func:`seed_cylinder_stereo`; for noise-free observations they give
the same point as :func:`triangulate` (tests show it).
"""

from __future__ import annotations

import numpy as np


def triangulate(extrinsics: np.ndarray, xn: np.ndarray, seen: np.ndarray | None = None) -> np.ndarray:
    """Triangulate many points at once from normalized observations.

    Args:
        extrinsics: (C, 3, 4) float64 ``[R | t]`` world -> camera of each camera.
        xn: (N, C, 2) float64 ideal normalized coordinates of point n in camera c (NaN if unseen).
        seen: (N, C) bool; defaults to ``isfinite(xn).all(-1)``.
    Returns:
        (N, 3) float64 points in world metres; NaN where fewer than 2 cameras see the point.
    """
    extrinsics = np.asarray(extrinsics, dtype=np.float64)
    xn = np.asarray(xn, dtype=np.float64)
    if xn.ndim == 2:
        xn = xn[None]
    n_pts, n_cams, _ = xn.shape
    if seen is None:
        seen = np.isfinite(xn).all(axis=-1)
    seen = np.asarray(seen, dtype=bool).reshape(n_pts, n_cams)
    out = np.full((n_pts, 3), np.nan)
    ok = seen.sum(axis=1) >= 2
    if not ok.any():
        return out
    if not ok.all():
        xn, seen = xn[ok], seen[ok]
    x = np.where(seen[..., None], xn, 0.0)  # (n, C, 2)
    w = seen.astype(np.float64)  # (n, C)
    # rows x * P3 - P1 and y * P3 - P2 of every camera: (n, C, 2, 4)
    rows = x[..., None] * extrinsics[None, :, 2:3, :] - extrinsics[None, :, 0:2, :]
    n = x.shape[0]
    for first in (True, False):
        A = (rows * w[..., None, None]).reshape(n, 2 * n_cams, 4)
        # normal equations of A[:, :, :3] X = -A[:, :, 3] (inhomogeneous form: the same minimiser
        # as the SVD for points not at infinity), all from one Gram matrix A^T A
        G = np.matmul(A.transpose(0, 2, 1), A)
        X = np.linalg.solve(G[:, :3, :3], -G[:, :3, 3:])[..., 0]
        if first:
            # reweight by 1 / depth so each row measures an image-plane (normalized) error
            depth = X @ extrinsics[:, 2, :3].T + extrinsics[:, 2, 3]
            w = np.where(seen, 1.0 / np.maximum(np.abs(depth), 1e-6), 0.0)
            w /= w.max(axis=1, keepdims=True)
    out[ok] = X
    return out


def triangulate_one(extrinsics: np.ndarray, xn: np.ndarray) -> np.ndarray:
    """One point: extrinsics (C, 3, 4), xn (C, 2) -> (3,) world metres (NaN if < 2 views)."""
    return triangulate(extrinsics, np.asarray(xn, dtype=np.float64)[None])[0]


def project_normalized(extrinsics: np.ndarray, p_world_m: np.ndarray) -> np.ndarray:
    """(C, 3, 4) extrinsics, (N, 3) points -> (N, C, 2) ideal normalized coordinates."""
    p = np.asarray(p_world_m, dtype=np.float64).reshape(-1, 3)
    cam = np.einsum("cij,nj->nci", extrinsics[:, :, :3], p) + extrinsics[None, :, :, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        return cam[..., :2] / cam[..., 2:3]


def reprojection_errors_px(
    extrinsics: np.ndarray, focal_px: np.ndarray, p_world_m: np.ndarray, xn: np.ndarray, seen: np.ndarray
) -> np.ndarray:
    """Per-observation image distance in (approximate) pixels.

    Args:
        extrinsics: (C, 3, 4); focal_px: (C,) mean focal length of each camera in pixels;
        p_world_m: (N, 3); xn: (N, C, 2) observed normalized coordinates; seen: (N, C) bool.
    Returns:
        (N, C) float64 distances in pixels, NaN where not seen.
    """
    pred = project_normalized(extrinsics, p_world_m)
    d = np.linalg.norm(pred - xn, axis=-1) * np.asarray(focal_px)[None, :]
    return np.where(seen, d, np.nan)


# --------------------------------------------------------------------------- the seed's formulas
def seed_parallel_stereo(u1: float, v1: float, u2: float, f: float, baseline: float) -> np.ndarray:
    """Seed equation 2: two cameras with parallel image planes (a rectified pair).

    Camera 1 sits at x = -l/2 and camera 2 at x = +l/2 on the pair's x axis, both looking along
    +z with image coordinates (u, v) measured from the principal point in pixels (focal length f):
    ``(x, y, z) = ((u1 + u2) / 2 * D, v1 * D, f * D)`` with ``D = l / (u1 - u2)``.

    Returns:
        (3,) point in the pair's frame (origin at the middle of the baseline), units of ``baseline``.
    """
    D = baseline / (u1 - u2)
    return np.array([(u1 + u2) / 2.0 * D, v1 * D, f * D])


def seed_cylinder_stereo(u1: float, theta1: float, u2: float, f: float, baseline: float) -> np.ndarray:
    """Seed equation 3: both images projected on a virtual cylinder around the baseline.

    For cameras that face each other no common image plane exists; the paper maps each camera's
    rays onto a cylinder of radius f whose axis is the line through the two optical centres
    (camera 1 at x = -l/2, camera 2 at x = +l/2). A ray reaches the cylinder at axial coordinate u
    and angle theta about the axis; both cameras share theta for one point (the epipolar plane):
    ``(x, y, z) = ((u1 + u2) / 2 * D, f cos(theta1) * D, f sin(theta1) * D)``, ``D = l / (u1 - u2)``.
    """
    D = baseline / (u1 - u2)
    return np.array([(u1 + u2) / 2.0 * D, f * np.cos(theta1) * D, f * np.sin(theta1) * D])


def pair_frame(centre1_m: np.ndarray, centre2_m: np.ndarray, up_hint=(0.0, 1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Frame of a camera pair for the seed formulas: origin at the baseline middle, x from 1 to 2.

    Returns:
        pair_from_world: (3, 3) rotation whose rows are the pair's x, y, z axes in world coordinates.
        origin_m: (3,) baseline middle in world metres.
    """
    x = np.asarray(centre2_m, float) - np.asarray(centre1_m, float)
    x /= np.linalg.norm(x)
    up = np.asarray(up_hint, float)
    y = up - x * np.dot(up, x)
    if np.linalg.norm(y) < 1e-9:
        y = np.cross(x, [1.0, 0.0, 0.0])
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    return np.stack([x, y, z]), (np.asarray(centre1_m, float) + np.asarray(centre2_m, float)) / 2.0


def ray_to_cylinder(dir_world: np.ndarray, pair_from_world: np.ndarray, f: float) -> tuple[float, float]:
    """A camera ray (world direction) -> the seed's cylinder coordinates (u, theta) for its pair."""
    d = pair_from_world @ np.asarray(dir_world, float)
    rho = np.hypot(d[1], d[2])
    return f * d[0] / rho, float(np.arctan2(d[2], d[1]))
