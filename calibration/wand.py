"""Wand calibration: camera poses from two markers at a known distance waved through the volume.

Pure math on arrays: the ball centroids in every camera and frame come in (from the blob detector,
see :mod:`tracking.drivers.wand_capture`), the intrinsics are known.

Steps (:func:`calibrate_wand`):

1. The camera pair that saw both balls together most often: essential matrix (RANSAC) and its
   pose (``recoverPose``), the balls triangulated, the scale set so that the median wand length is
   the true one.
2. Every other camera by PnP (RANSAC) on the balls triangulated so far, most shared balls first;
   after each camera the balls are triangulated again from all posed cameras.
3. Bundle adjustment (``scipy.optimize.least_squares``, sparse Jacobian, soft-L1 loss) over all
   camera poses but the first and every ball position, with one residual per frame tying the two
   balls to the wand length (1 mm of length error weighs as 1 px of reprojection error), which
   fixes the scale.
4. Report: per-camera RMS reprojection error, and the wand length error of every frame with the
   balls triangulated again from the final cameras (linear triangulation, no length constraint),
   so the figure is an honest measure of the rig's metric accuracy.

The result's frame is the first camera of the best pair's (Y not up); set the world frame with
:func:`calibration.extrinsics.world_from_floor_board` from a board lying on the floor or seat.

Balls of one colour (:func:`match_same_colour_balls`): which blob is which ball is arbitrary in
each camera and frame; the cameras are made to agree by the rig's own epipolar geometry, found
from all four possible pairings of two cameras' blobs at once (RANSAC: the right pairings are
half of them), camera after camera against those already matched. A frame whose two pairings
fit about equally (the wand in an epipolar plane) is left out for that camera.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from calibration.camera import Camera, rotation_from_rvec, rvec_from_rotation
from calibration.errors import CalibrationError

log = logging.getLogger(__name__)

MIN_PAIR_FRAMES = 15
LENGTH_WEIGHT_PX_PER_MM = 1.0


@dataclass(frozen=True, slots=True)
class WandResult:
    """A rig calibrated with the wand.

    Attributes:
        cameras: the cameras with extrinsics (frame of the reference camera ``cameras[ref]``).
        reference: index of the camera whose frame the result is in.
        rms_px: (C,) RMS reprojection error of each camera over the balls, pixels.
        length_error_mm: (F,) measured minus true wand length in every frame where both balls were
            triangulated, mm.
        n_frames: frames used in the bundle adjustment.
        warnings: one-line warnings.
    """

    cameras: tuple[Camera, ...]
    reference: int
    rms_px: np.ndarray
    length_error_mm: np.ndarray
    n_frames: int
    warnings: tuple[str, ...]

    @property
    def length_rmse_mm(self) -> float:
        return float(np.sqrt(np.mean(self.length_error_mm**2))) if self.length_error_mm.size else float("nan")


def triangulate(cams_R: Sequence[np.ndarray], cams_t: Sequence[np.ndarray], xn: np.ndarray) -> np.ndarray:
    """Linear (DLT) triangulation in normalized coordinates.

    Args:
        cams_R, cams_t: C rotations (3, 3) and translations (3,), frame -> camera.
        xn: (C, P, 2) undistorted normalized coordinates, NaN where a camera did not see a point.
    Returns:
        (P, 3) points; NaN where fewer than two cameras saw the point.
    """
    C, P = xn.shape[:2]
    Ps = np.stack([np.hstack([R, t[:, None]]) for R, t in zip(cams_R, cams_t)])  # (C, 3, 4)
    seen = np.all(np.isfinite(xn), axis=2)  # (C, P)
    rows = np.zeros((P, 2 * C, 4))
    x = np.nan_to_num(xn)
    rows[:, 0::2] = (x[:, :, 0:1] * Ps[:, None, 2] - Ps[:, None, 0]).transpose(1, 0, 2)
    rows[:, 1::2] = (x[:, :, 1:2] * Ps[:, None, 2] - Ps[:, None, 1]).transpose(1, 0, 2)
    w = np.repeat(seen.T, 2, axis=1).astype(float)  # (P, 2C): drop unseen rows
    rows *= w[:, :, None]
    _, _, Vt = np.linalg.svd(rows)
    X = Vt[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        pts = X[:, :3] / X[:, 3:4]
    pts[seen.sum(axis=0) < 2] = np.nan
    return pts


def _undistort(cameras: Sequence[Camera], uv_px: np.ndarray) -> np.ndarray:
    """(C, T, 2, 2) pixels -> (C, T*2, 2) normalized coordinates (NaN kept)."""
    C = len(cameras)
    out = np.full((C, uv_px.shape[1] * 2, 2), np.nan)
    for c, cam in enumerate(cameras):
        uv = uv_px[c].reshape(-1, 2)
        ok = np.all(np.isfinite(uv), axis=1)
        if ok.any():
            out[c, ok] = cam.undistort_points(uv[ok])
    return out


def calibrate_wand(cameras: Sequence[Camera], uv_px: np.ndarray, length_m: float) -> WandResult:
    """Calibrate the cameras' poses from wand ball centroids.

    Args:
        cameras: C >= 2 cameras with calibrated intrinsics (extrinsics ignored).
        uv_px: (C, T, 2, 2) float64 distorted pixel centroids of ball 0 and ball 1 in every
            camera and frame; NaN where a ball was not seen (or not seen unambiguously).
        length_m: the distance between the two ball centres, metres.
    Raises:
        CalibrationError: too few frames shared by any two cameras, or a camera that sees too
            few triangulated balls to be placed.
    """
    C = len(cameras)
    uv_px = np.asarray(uv_px, dtype=np.float64)
    if C < 2 or uv_px.shape[0] != C or uv_px.shape[2:] != (2, 2):
        raise CalibrationError(f"wand centroids must have shape (cameras, frames, 2, 2) for {C} >= 2 cameras, got {uv_px.shape}")
    if not 0.05 <= length_m <= 5.0:
        raise CalibrationError(f"wand length {length_m * 1000:g} mm: give the distance between the ball centres in mm")
    T = uv_px.shape[1]
    xn = _undistort(cameras, uv_px)  # (C, 2T, 2)
    both = np.all(np.isfinite(uv_px), axis=(2, 3))  # (C, T) both balls seen
    counts = both.astype(int) @ both.T.astype(int)
    np.fill_diagonal(counts, 0)
    i, j = np.unravel_index(int(np.argmax(counts)), counts.shape)
    if counts[i, j] < MIN_PAIR_FRAMES:
        raise CalibrationError(
            f"no two cameras saw both wand balls in {MIN_PAIR_FRAMES} frames (best {counts[i, j]}): "
            "wave the wand longer through the middle of the volume, where the cameras overlap"
        )
    R = [None] * C
    t = [None] * C
    R[i], t[i] = np.eye(3), np.zeros(3)
    R[j], t[j] = _pair_pose(xn[i], xn[j], both[i] & both[j], cameras, (i, j), length_m)
    posed = [i, j]
    while len(posed) < C:
        pts = triangulate([R[c] for c in posed], [t[c] for c in posed], xn[posed])
        best, best_n = None, 0
        for c in range(C):
            if c in posed:
                continue
            n = int(np.sum(np.isfinite(pts[:, 0]) & np.all(np.isfinite(xn[c]), axis=1)))
            if n > best_n:
                best, best_n = c, n
        if best is None or best_n < 12:
            missing = [cameras[c].name for c in range(C) if c not in posed]
            raise CalibrationError(
                f"{', '.join(missing)} saw too few wand balls that other cameras also saw: "
                "wave the wand where those cameras overlap with the others"
            )
        R[best], t[best] = _pnp(pts, xn[best], cameras[best])
        posed.append(best)
    order = [i] + [c for c in range(C) if c != i]  # the reference camera first
    result_R, result_t, pts, rms = _bundle_adjust(cameras, order, R, t, uv_px, xn, length_m)
    out = tuple(Camera.from_rotation(cam.name, cam.size_px, cam.K, cam.dist, r, tt, fisheye=cam.fisheye)
                for cam, r, tt in zip(cameras, result_R, result_t))
    re = triangulate(result_R, result_t, xn).reshape(T, 2, 3)
    lengths = np.linalg.norm(re[:, 1] - re[:, 0], axis=1)
    err_mm = (lengths[np.isfinite(lengths)] - length_m) * 1000.0
    warnings = []
    for c in range(C):
        if rms[c] > 1.0:
            warnings.append(f"{cameras[c].name}: the wand balls fit to {rms[c]:.2f} px only: check its intrinsics and for other objects of the balls' colours")
    rmse = float(np.sqrt(np.mean(err_mm**2))) if err_mm.size else float("nan")
    if rmse > 2.0:
        warnings.append(f"the wand length varies by {rmse:.1f} mm RMS: check the intrinsics and the wand length")
    for w in warnings:  # returned for the caller to show; logged for the record
        log.info(w)
    n_frames = int(np.sum(np.all(np.isfinite(pts.reshape(T, 2, 3)), axis=(1, 2))))
    return WandResult(out, i, rms, err_mm, n_frames, tuple(warnings))


SAME_COLOUR_FIT_PX = 2.0  # a pairing of blobs fits the epipolar geometry within this distance
SAME_COLOUR_MISFIT_PX = 6.0  # and the other pairing must miss it by this much for the frame to count


def match_same_colour_balls(cameras: Sequence[Camera], uv_px: np.ndarray) -> tuple[np.ndarray, int]:
    """Make the ball order of a same-coloured wand agree between cameras.

    Args:
        cameras: C cameras with intrinsics.
        uv_px: (C, T, 2, 2) blob centroids, the two balls in arbitrary order in each camera and
            frame, NaN where a camera did not see exactly two balls.
    Returns:
        (C, T, 2, 2) the centroids with each camera's pair of blobs swapped where needed, NaN
        where the order could not be decided; and the number of camera-frames left out so.
    """
    C, T = uv_px.shape[:2]
    uv = np.array(uv_px, dtype=np.float64)
    xn = _undistort(cameras, uv).reshape(C, T, 2, 2)
    both = np.all(np.isfinite(uv), axis=(2, 3))
    counts = both.astype(int) @ both.T.astype(int)
    np.fill_diagonal(counts, 0)
    done = [int(np.argmax(counts.sum(axis=1)))]
    dropped = 0
    while len(done) < C:
        rest = [c for c in range(C) if c not in done]
        c = max(rest, key=lambda k: sum(counts[k, d] for d in done))
        fit_straight = np.zeros(T)
        fit_crossed = np.zeros(T)
        votes = np.zeros(T, int)
        for d in done:
            shared = both[c] & both[d]
            if shared.sum() < MIN_PAIR_FRAMES:
                continue
            d_s, d_x = _pairing_distances_px(xn[d], xn[c], shared, cameras[c].K[0, 0])
            if d_s is None:
                continue
            ok = np.isfinite(d_s)
            fit_straight[ok] += d_s[ok]
            fit_crossed[ok] += d_x[ok]
            votes[ok] += 1
        seen = both[c]
        with np.errstate(invalid="ignore", divide="ignore"):
            s_mean, x_mean = fit_straight / votes, fit_crossed / votes
        straight = (votes > 0) & (s_mean < SAME_COLOUR_FIT_PX) & (x_mean > SAME_COLOUR_MISFIT_PX)
        crossed = (votes > 0) & (x_mean < SAME_COLOUR_FIT_PX) & (s_mean > SAME_COLOUR_MISFIT_PX)
        uv[c, crossed] = uv[c, crossed][:, ::-1]
        xn[c, crossed] = xn[c, crossed][:, ::-1]
        undecided = seen & ~straight & ~crossed
        uv[c, undecided] = np.nan
        dropped += int(undecided.sum())
        both[c] = straight | crossed
        counts[c] = both.astype(int) @ both[c].astype(int)
        counts[:, c] = counts[c]
        counts[c, c] = 0
        done.append(c)
    return uv, dropped


def _pairing_distances_px(xa: np.ndarray, xb: np.ndarray, frames: np.ndarray, f_px: float):
    """Per frame, the larger epipolar distance (px in camera b) of the straight pairing (a0-b0,
    a1-b1) and of the crossed one (a0-b1, a1-b0), with the essential matrix found from both
    pairings of the ``frames`` by RANSAC. (None, None) when no geometry is found."""
    idx = np.flatnonzero(frames)
    pa = np.concatenate([xa[idx, 0], xa[idx, 1], xa[idx, 0], xa[idx, 1]])
    pb = np.concatenate([xb[idx, 0], xb[idx, 1], xb[idx, 1], xb[idx, 0]])
    E, _ = cv2.findEssentialMat(pa, pb, np.eye(3), method=cv2.RANSAC, prob=0.99999, threshold=1.0 / f_px, maxIters=5000)
    if E is None or E.shape != (3, 3):
        return None, None
    T = xa.shape[0]

    def dist(a, b):
        ha = np.column_stack([a, np.ones(len(a))])
        hb = np.column_stack([b, np.ones(len(b))])
        lines = ha @ E.T  # epipolar lines in b
        return np.abs(np.sum(lines * hb, axis=1)) / np.hypot(lines[:, 0], lines[:, 1]) * f_px

    d_s = np.full(T, np.nan)
    d_x = np.full(T, np.nan)
    d_s[idx] = np.maximum(dist(xa[idx, 0], xb[idx, 0]), dist(xa[idx, 1], xb[idx, 1]))
    d_x[idx] = np.maximum(dist(xa[idx, 0], xb[idx, 1]), dist(xa[idx, 1], xb[idx, 0]))
    return d_s, d_x


def _pair_pose(xa: np.ndarray, xb: np.ndarray, frames: np.ndarray, cameras, pair, length_m: float):
    """T_b_a of the best pair from the essential matrix, scaled by the wand length."""
    sel = np.repeat(frames, 2)  # both balls of each shared frame
    pa, pb = xa[sel], xb[sel]
    f = np.mean([cameras[pair[0]].K[0, 0], cameras[pair[1]].K[0, 0]])
    E, inliers = cv2.findEssentialMat(pa, pb, np.eye(3), method=cv2.RANSAC, prob=0.9999, threshold=1.5 / f)
    if E is None or E.shape != (3, 3):
        raise CalibrationError("the wand views of the best camera pair give no consistent geometry: check the centroids")
    _, R, t, _ = cv2.recoverPose(E, pa, pb, np.eye(3), mask=inliers.copy())
    t = t.ravel()
    pts = triangulate([np.eye(3), R], [np.zeros(3), t], np.stack([pa, pb])).reshape(-1, 2, 3)
    lengths = np.linalg.norm(pts[:, 1] - pts[:, 0], axis=1)
    scale = length_m / np.nanmedian(lengths)
    return R, t * scale


def _pnp(pts: np.ndarray, xn: np.ndarray, camera: Camera):
    ok = np.isfinite(pts[:, 0]) & np.all(np.isfinite(xn), axis=1)
    f = camera.K[0, 0]
    good, rvec, tvec, inliers = cv2.solvePnPRansac(pts[ok], xn[ok], np.eye(3), None, reprojectionError=2.0 / f,
                                                   iterationsCount=500, flags=cv2.SOLVEPNP_EPNP)
    if not good or inliers is None or len(inliers) < 6:
        raise CalibrationError(f"{camera.name}: cannot be placed from the wand balls it saw: wave the wand where it overlaps with the others")
    idx = inliers.ravel()
    rvec, tvec = cv2.solvePnPRefineLM(pts[ok][idx], xn[ok][idx], np.eye(3), None, rvec, tvec)
    return rotation_from_rvec(rvec.ravel()), tvec.ravel()


def _bundle_adjust(cameras, order, R, t, uv_px, xn, length_m):
    """Joint refinement; returns rotations, translations (reference camera = identity), points, per-camera RMS."""
    C = len(cameras)
    T = uv_px.shape[1]
    ref = order[0]
    # Re-express in the reference camera's frame (it already is: R[ref] = I, t[ref] = 0).
    pts = triangulate(R, t, xn)  # (2T, 3)
    use = np.isfinite(pts[:, 0])
    point_ids = np.flatnonzero(use)
    index_of = -np.ones(2 * T, int)
    index_of[point_ids] = np.arange(len(point_ids))
    others = order[1:]
    cam_slot = {c: k for k, c in enumerate(others)}
    obs_c, obs_p, obs_uv = [], [], []
    uv_flat = uv_px.reshape(C, 2 * T, 2)
    for c in range(C):
        seen = np.flatnonzero(use & np.all(np.isfinite(uv_flat[c]), axis=1))
        obs_c.append(np.full(len(seen), c))
        obs_p.append(index_of[seen])
        obs_uv.append(uv_flat[c, seen])
    obs_c, obs_p, obs_uv = np.concatenate(obs_c), np.concatenate(obs_p), np.concatenate(obs_uv)
    frames = np.flatnonzero(use[0::2] & use[1::2])
    la, lb = index_of[2 * frames], index_of[2 * frames + 1]
    n_cam = 6 * len(others)
    n_obs = len(obs_c)

    def unpack(x):
        Rs, ts = [None] * C, [None] * C
        Rs[ref], ts[ref] = np.eye(3), np.zeros(3)
        for c, k in cam_slot.items():
            Rs[c] = rotation_from_rvec(x[6 * k : 6 * k + 3])
            ts[c] = x[6 * k + 3 : 6 * k + 6]
        return Rs, ts, x[n_cam:].reshape(-1, 3)

    def residuals(x):
        Rs, ts, P = unpack(x)
        res = np.empty((n_obs, 2))
        for c in range(C):
            m = obs_c == c
            p_cam = P[obs_p[m]] @ Rs[c].T + ts[c]
            res[m] = cameras[c].distort_normalized(p_cam[:, :2] / p_cam[:, 2:3]) - obs_uv[m]
        length = (np.linalg.norm(P[lb] - P[la], axis=1) - length_m) * 1000.0 * LENGTH_WEIGHT_PX_PER_MM
        return np.concatenate([res.ravel(), length])

    sparsity = lil_matrix((2 * n_obs + len(frames), n_cam + 3 * len(point_ids)), dtype=int)
    rows = np.arange(n_obs)
    for d in range(2):
        for k in range(3):
            sparsity[2 * rows + d, n_cam + 3 * obs_p + k] = 1
        for c, slot in cam_slot.items():
            r = 2 * rows[obs_c == c] + d
            for k in range(6):
                sparsity[r, 6 * slot + k] = 1
    lr = 2 * n_obs + np.arange(len(frames))
    for k in range(3):
        sparsity[lr, n_cam + 3 * la + k] = 1
        sparsity[lr, n_cam + 3 * lb + k] = 1
    x0 = np.concatenate([np.concatenate([rvec_from_rotation(R[c]), t[c]]) for c in others] + [pts[point_ids].ravel()])
    sol = least_squares(residuals, x0, jac_sparsity=sparsity.tocsr(), loss="soft_l1", f_scale=1.0, x_scale="jac",
                        method="trf", xtol=1e-8, ftol=1e-8, gtol=1e-8, max_nfev=100)
    Rs, ts, P = unpack(sol.x)
    res = sol.fun[: 2 * n_obs].reshape(n_obs, 2)
    rms = np.array([np.sqrt(np.mean(np.sum(res[obs_c == c] ** 2, axis=1))) if np.any(obs_c == c) else np.nan for c in range(C)])
    all_pts = np.full((2 * T, 3), np.nan)
    all_pts[point_ids] = P
    return Rs, ts, all_pts, rms
