"""Triangulation of 3D points from several calibrated cameras.

Pure numpy. Observations are *ideal normalized* image coordinates (distortion removed, divided by
the focal length: ``x = X_cam / Z_cam``), so every camera enters with the 3x4 extrinsic matrix
``[R | t]`` (world -> camera) and the least-squares system is well conditioned.

The general method is linear least squares (DLT) over all cameras that see the point, with one
reweighting by the projective depth so that each camera's residual approximates its image-plane
error (the plain DLT weights far cameras less). The seed paper's two-camera formulas (docs/METHOD.md
section 5.1, equations 2 and 3) are implemented as a documented reference in
:func:`seed_parallel_stereo` and :func:`seed_cylinder_stereo`; for noise-free observations they give
the same point as :func:`triangulate` (tests show it).
"""

from __future__ import annotations

import math

import numpy as np

from tracking.jit import INSTALLED, compile_loop


def triangulate(extrinsics: np.ndarray, xn: np.ndarray, seen: np.ndarray | None = None) -> np.ndarray:
    """Triangulate many points at once from normalized observations.

    Args:
        extrinsics: (C, 3, 4) float64 ``[R | t]`` world -> camera of each camera.
        xn: (N, C, 2) float64 ideal normalized coordinates of point n in camera c (NaN if unseen).
        seen: (N, C) bool; defaults to ``isfinite(xn).all(-1)``.
    Returns:
        (N, 3) float64 points in world metres; NaN where fewer than 2 cameras see the point.
    """
    return Triangulator(extrinsics)(xn, seen)


class Triangulator:
    """:func:`triangulate` for one rig, with the per-camera constants prepared once (the
    per-frame tracker calls it a few times per frame set on ~14 points, where the count of numpy
    calls, not the work, is the cost).

    Method: linear least squares (DLT) over the cameras that see a point, solved through the
    normal equations of its inhomogeneous form, then once more with each camera's rows weighted
    by 1 / projective depth (so that its residual approximates the image-plane error). Camera c
    adds the rows ``x P3 - P1`` and ``y P3 - P2`` (``P = [R | t]``, weight w), i.e. to the 4x4
    Gram matrix ``A^T A``: ``w^2 ((x^2 + y^2) P3 P3^T - x (P3 P1^T + P1 P3^T) - y (P3 P2^T + P2 P3^T)
    + P1 P1^T + P2 P2^T)``: a fixed (4C, 16) basis times 4 numbers per point and camera, one
    matrix product for all points.
    """

    def __init__(self, extrinsics: np.ndarray, compiled: bool = False):
        ext = np.asarray(extrinsics, dtype=np.float64)
        if ext.ndim != 3 or ext.shape[1:] != (3, 4):
            raise ValueError(f"extrinsics must be (C, 3, 4), got {ext.shape}")
        self.n_cams = ext.shape[0]
        p1, p2, p3 = ext[:, 0, :, None], ext[:, 1, :, None], ext[:, 2, :, None]  # (C, 4, 1)

        def outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return a @ b.transpose(0, 2, 1)

        def sym(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return outer(a, b) + outer(b, a)

        basis = np.stack([outer(p3, p3), -sym(p3, p1), -sym(p3, p2), outer(p1, p1) + outer(p2, p2)], axis=1)
        self._basis = np.ascontiguousarray(basis.reshape(4 * self.n_cams, 16))
        self._depth_rot = np.ascontiguousarray(ext[:, 2, :3].T)  # (3, C)
        self._depth_t = np.ascontiguousarray(ext[:, 2, 3])
        # compiled (numba): the same two solves per point in one loop, no numpy call per step;
        # equal to the numpy path to ~1e-12 m (its 3x3 solves by cofactors, not LAPACK's LU)
        self._loop = compile_loop(_triangulate_loop) if compiled and INSTALLED else None
        self.compiled = self._loop is not None

    def __call__(self, xn: np.ndarray, seen: np.ndarray | None = None) -> np.ndarray:
        """(N, C, 2) normalized observations, (N, C) bool seen -> (N, 3) points (as :func:`triangulate`)."""
        xn = np.asarray(xn, dtype=np.float64)
        if xn.ndim == 2:
            xn = xn[None]
        n_pts, n_cams, _ = xn.shape
        if n_cams != self.n_cams:
            raise ValueError(f"{n_cams} cameras' observations for a rig of {self.n_cams}")
        if seen is None:
            seen = np.isfinite(xn).all(axis=-1)
        seen = np.asarray(seen, dtype=bool).reshape(n_pts, n_cams)
        if self._loop is not None:
            out = np.empty((n_pts, 3))
            self._loop(np.ascontiguousarray(xn), np.ascontiguousarray(seen), self._basis, self._depth_rot, self._depth_t, out)
            return out
        ok = np.count_nonzero(seen, axis=1) >= 2
        all_ok = bool(ok.all())
        if not all_ok:
            out = np.empty((n_pts, 3))
            out.fill(np.nan)
            if not ok.any():
                return out
            xn, seen = xn[ok], seen[ok]
        n = xn.shape[0]
        # per point and camera: x^2 + y^2, x, y, 1 (all 0 where unseen), the basis' coefficients
        feat = np.empty((n, n_cams, 4))
        x = np.where(seen[..., None], xn, 0.0)
        feat[..., 1:3] = x
        feat[..., 0] = (x * x).sum(axis=2)
        feat[..., 3] = seen
        gram = feat.reshape(n, 4 * n_cams) @ self._basis  # (n, 16) A^T A, unweighted
        X = _solve_normal(gram)
        # reweight by 1 / depth so each row measures an image-plane (normalized) error
        depth = X @ self._depth_rot + self._depth_t
        w = np.where(seen, 1.0 / np.maximum(np.abs(depth), 1e-6), 0.0)
        w /= w.max(axis=1, keepdims=True)
        feat *= (w * w)[..., None]
        X = _solve_normal(feat.reshape(n, 4 * n_cams) @ self._basis)
        if all_ok:
            return X
        out[ok] = X
        return out


def _triangulate_loop(xn, seen, basis, depth_rot, depth_t, out):
    """:meth:`Triangulator.__call__` as one loop over the points (compiled by numba; plain
    Python runs it too): per point the Gram matrix from the basis, the 3x3 solve, the depth
    weights, the Gram matrix and the solve again."""
    n_pts, n_cams = seen.shape
    feat = np.zeros((n_cams, 4))
    gram = np.zeros(16)
    for i in range(n_pts):
        count = 0
        for c in range(n_cams):
            if seen[i, c]:
                count += 1
        if count < 2:
            out[i, 0] = out[i, 1] = out[i, 2] = math.nan
            continue
        for c in range(n_cams):
            if seen[i, c]:
                x, y = xn[i, c, 0], xn[i, c, 1]
                feat[c, 0], feat[c, 1], feat[c, 2], feat[c, 3] = x * x + y * y, x, y, 1.0
            else:
                feat[c, 0] = feat[c, 1] = feat[c, 2] = feat[c, 3] = 0.0
        for rep in range(2):
            for j in range(16):
                gram[j] = 0.0
            for c in range(n_cams):
                if seen[i, c]:
                    for k in range(4):
                        f = feat[c, k]
                        for j in range(16):
                            gram[j] += f * basis[4 * c + k, j]
            # G[:3, :3] X = -G[:3, 3] by cofactors (G symmetric positive definite)
            a, b, cc = gram[0], gram[1], gram[2]
            d, e, f = gram[5], gram[6], gram[10]
            r0, r1, r2 = -gram[3], -gram[7], -gram[11]
            c00, c01, c02 = d * f - e * e, cc * e - b * f, b * e - cc * d
            det = a * c00 + b * c01 + cc * c02
            c11, c12, c22 = a * f - cc * cc, b * cc - a * e, a * d - b * b
            x0 = (c00 * r0 + c01 * r1 + c02 * r2) / det
            x1 = (c01 * r0 + c11 * r1 + c12 * r2) / det
            x2 = (c02 * r0 + c12 * r1 + c22 * r2) / det
            if rep == 0:  # reweight each camera's rows by 1 / projective depth (the largest 1)
                w_max = 0.0
                for c in range(n_cams):
                    if seen[i, c]:
                        depth = x0 * depth_rot[0, c] + x1 * depth_rot[1, c] + x2 * depth_rot[2, c] + depth_t[c]
                        w = 1.0 / max(abs(depth), 1e-6)
                        feat[c, 0] *= w * w  # (scaled by 1 / w_max^2 below)
                        feat[c, 1] *= w * w
                        feat[c, 2] *= w * w
                        feat[c, 3] *= w * w
                        w_max = max(w_max, w)
                scale = 1.0 / (w_max * w_max)
                for c in range(n_cams):
                    for k in range(4):
                        feat[c, k] *= scale
        out[i, 0], out[i, 1], out[i, 2] = x0, x1, x2


def _solve_normal(gram: np.ndarray) -> np.ndarray:
    """(n, 16) flattened 4x4 Gram matrices -> (n, 3) solutions of G[:3, :3] X = -G[:3, 3]."""
    g = gram.reshape(-1, 4, 4)
    return np.linalg.solve(g[:, :3, :3], -g[:, :3, 3:])[..., 0]


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
