"""View choice: each marker triangulated from its window centroids, leaving out the views that do
not show its whole ball while two full ones remain, and dropping the view that misses while three
or more remain (a wrong ball in one view); the full views of unmeasured markers go to the
hidden-marker estimator as rays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracking.pipeline.params import TrackerParams
from tracking.pipeline.state import FrameState, Setup
from tracking.pipeline.timing import to_set_instant


@dataclass(frozen=True, slots=True)
class ViewChoice:
    """Each marker's triangulation from its chosen views: ``xn`` (M, C, 2) normalized observations
    (at the set's instant), ``xn_seen`` as seen, ``seen`` (M, C) the views used, ``pts`` (M, 3),
    ``err``/``depth`` (M, C) reprojection error (px) and depth, ``ratio_pred`` (M, C) blob radius over
    the ball's at the predicted depth, ``ball_px`` (C,) the ball's radius in pixels at 1 m."""

    xn: np.ndarray
    xn_seen: np.ndarray
    seen: np.ndarray
    pts: np.ndarray
    err: np.ndarray
    depth: np.ndarray
    ratio_pred: np.ndarray
    ball_px: np.ndarray


def reprojection(setup: Setup, pts: np.ndarray, xn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) points, (N, C, 2) normalized observations -> (N, C) errors in pixels, (N, C) depths."""
    cam = setup.stack.world_to_cameras(pts)
    depth = cam[..., 2]
    d = cam[..., :2] / depth[..., None] - xn  # (NaN for NaN points; no depth is exactly 0)
    return np.sqrt((d * d).sum(axis=2)) * setup.stack.focal_px, depth


def choose_views(setup: Setup, p: TrackerParams, frame: FrameState, uv: np.ndarray, rad: np.ndarray) -> ViewChoice:
    """Triangulate every marker from its window centroids ``uv`` (blob radii ``rad``) with the views
    that fit."""
    stack = setup.stack
    xn = stack.undistort_points(uv)
    xn_seen = xn
    if frame.skew_s is not None:
        xn = to_set_instant(setup, frame, xn, uv)
    seen = np.isfinite(xn[..., 0]) & frame.known[:, None]
    ball_px = stack.focal_px * setup.radius_m  # ball radius in pixels at 1 m
    # a partly hidden ball (blob much smaller than the ball at the predicted depth) has a
    # shifted centroid, and a blob larger than the ball holds more than the ball (another ball
    # of the colour touching it): leave them out while two full views remain
    # (no errstate here: NaN where a marker or view is missing compares False without a
    # warning, and a depth of exactly 0 does not occur)
    ratio_pred = rad / (ball_px / frame.pred_depth)
    partial = seen & ~p.full_view(ratio_pred) & ~np.isnan(ratio_pred)
    keep_full = (seen & ~partial).sum(axis=1) >= 2
    left_out = partial & keep_full[:, None]
    seen &= ~left_out
    pts = setup.triangulate(xn, seen)
    err, depth = reprojection(setup, pts, xn)
    # a partly hidden view is shifted by less than the ball's radius: one that the point
    # misses by more says that a full view holds another ball of the colour (two views always
    # meet near some point): triangulate from all views and let the worst go below
    r_px = ball_px / frame.pred_depth
    recheck = (left_out & (err > np.maximum(r_px, p.max_reproj_px))).any(axis=1)
    if recheck.any():
        redo = np.flatnonzero(recheck)
        seen[redo] |= left_out[redo]
        pts[redo] = setup.triangulate(xn[redo], seen[redo])
        err[redo], depth[redo] = reprojection(setup, pts[redo], xn[redo])
    drop_missing_views(setup, p, frame.pred, xn, seen, pts, err, depth)
    return ViewChoice(xn, xn_seen, seen, pts, err, depth, ratio_pred, ball_px)


def drop_missing_views(setup: Setup, p: TrackerParams, pred: np.ndarray, xn: np.ndarray, seen: np.ndarray,
                       pts: np.ndarray, err: np.ndarray, depth: np.ndarray) -> None:
    """Drop the worst view while it misses and three or more remain (``seen``, ``pts``, ``err`` and
    ``depth`` updated in place)."""
    m_count, n_cams = seen.shape
    rows = np.arange(m_count)
    changed = np.ones(m_count, dtype=bool)  # views changed since the leave-one-out check
    for _ in range(n_cams):
        worst = np.argmax(np.where(seen, err, -1.0), axis=1)
        many = seen.sum(axis=1) >= 3
        drop = (err[rows, worst] > p.max_reproj_px) & many
        # a wrong ball in one of three views pulls the point towards itself and hides its own
        # miss; the point from the other views shows it (leave-one-out)
        probe = np.flatnonzero(many & ~drop & changed)
        if probe.size:
            others = seen[probe].copy()
            others[np.arange(probe.size), worst[probe]] = False
            p_loo = setup.triangulate(xn[probe], others)
            e_loo, _ = reprojection(setup, p_loo, xn[probe])
            drop[probe] = e_loo[np.arange(probe.size), worst[probe]] > p.max_loo_px
        if not drop.any():
            break
        redo = np.flatnonzero(drop)
        changed = drop
        for m in redo.tolist():
            worst[m] = view_to_drop(setup, p, seen[m], xn[m], pred[m], int(worst[m]))
        seen[redo, worst[drop]] = False
        pts[redo] = setup.triangulate(xn[redo], seen[redo])  # the other points do not change
        err[redo], depth[redo] = reprojection(setup, pts[redo], xn[redo])


def view_to_drop(setup: Setup, p: TrackerParams, seen: np.ndarray, xn: np.ndarray, pred: np.ndarray,
                 worst: int) -> int:
    """Which of a marker's (3 or more) views to drop: the worst, unless another view's removal
    leaves a point that fits the other views (RMS within ``max_reproj_px``) more than
    ``view_choice_margin_m`` nearer the prediction: then the one that leaves it nearest. Two
    partly hidden views, one of them another ball, can each fit a full view within a pixel;
    the prediction tells them apart.

    Args:
        seen: (C,) the views used; xn: (C, 2) normalized observations; pred: (3,) prediction.
    """
    views = np.flatnonzero(seen)
    keep = np.repeat(seen[None, :], views.size, axis=0)
    keep[np.arange(views.size), views] = False
    obs = np.repeat(xn[None], views.size, axis=0)
    pts = setup.triangulate(obs, keep)
    err, _ = reprojection(setup, pts, obs)
    rms = np.sqrt((np.where(keep, err, 0.0) ** 2).sum(axis=1) / keep.sum(axis=1))
    fits = rms <= p.max_reproj_px
    if not fits.any():
        return worst
    dist = np.linalg.norm(pts - pred, axis=1)
    near = np.where(fits, dist, np.inf)
    i_worst = int(np.flatnonzero(views == worst)[0])
    # the worst view goes unless that leaves the point clearly farther from the prediction
    if not fits[i_worst] or dist[i_worst] > near.min() + p.view_choice_margin_m:
        return int(views[np.argmin(near)])
    return worst


def full_views_as_rays(setup: Setup, p: TrackerParams, xn: np.ndarray,
                       views: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The views ``views`` (M, C) of unmeasured markers as rays for the hidden-marker estimator:
    marker index, camera centre, unit direction, angular uncertainty; None when there are none.

    Args:
        xn: (M, C, 2) normalized observations; views: (M, C) bool, the views to pass.
    """
    if not views.any():
        return None
    m_idx, c_idx = np.nonzero(views)
    rot = setup.geometry.extrinsics[c_idx, :, :3]  # world -> camera
    ray = np.concatenate([xn[m_idx, c_idx], np.ones((m_idx.size, 1))], axis=1)
    d = np.einsum("kji,kj->ki", rot, ray)  # R^T [x, y, 1]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return m_idx, setup.cam_centres[c_idx], d, p.view_sigma_px / setup.stack.focal_px[c_idx]
