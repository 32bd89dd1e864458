"""Consistency checks: a triangulated candidate is taken when it fits its views, lies near its
prediction, holds a ball no other marker holds and keeps its learned distances to the markers of
its segment (docs/METHOD.md 5.3)."""

from __future__ import annotations

import numpy as np

from tracking.pipeline.params import TrackerParams
from tracking.pipeline.state import MEASURED, ONES2, ONES3, FrameState, MarkerMemory, Setup
from tracking.pipeline.views import ViewChoice


def accept(setup: Setup, p: TrackerParams, frame: FrameState, memory: MarkerMemory, choice: ViewChoice,
           uv: np.ndarray, rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) the positions taken (NaN where none) and (M,) which markers are measured."""
    seen, err, depth, pts = choice.seen, choice.err, choice.depth, choice.pts
    n_seen = seen.sum(axis=1)
    rms = np.sqrt(np.where(seen, err, 0.0) ** 2 @ setup.ones_cams / np.maximum(n_seen, 1))
    # two views always meet in some point: a two-camera candidate must fit tightly and show a
    # ball of the right size in both views (as in tracking.reconstruction)
    ratio_now = rad / (choice.ball_px / depth)
    size_fit = ~(seen & ~((ratio_now > p.two_view_min_ratio) & (ratio_now <= p.oversize_ratio))).any(axis=1)
    measured = (n_seen >= 2) & (rms <= p.max_reproj_px)
    measured &= (n_seen >= 3) | ((rms <= p.max_reproj_px_two_view) & size_fit)
    off = pts - frame.pred
    off_m = np.sqrt((off * off) @ ONES3)  # distance to the prediction
    measured &= off_m <= p.gate_sigmas * frame.sigma + p.gate_slack_m
    new_pos = np.where(measured[:, None], pts, np.nan)
    # one ball, one marker: a marker measured last frame keeps its ball, then the larger Q
    diff = new_pos[:, None, :] - new_pos[None, :, :]
    dist = np.sqrt((diff * diff) @ ONES3)  # (M, M), NaN unless both measured
    clash = dist < p.same_ball_m
    np.fill_diagonal(clash, False)
    if clash.any():
        # Q (equation 4) of the chosen candidate
        duv = uv - frame.pred_uv
        q_cam = 1.0 / (1.0 + np.sqrt((duv * duv) @ ONES2))
        q_best = np.where(measured, np.prod(np.where(seen, q_cam, 1.0), axis=1), 0.0)
        was_measured = memory.status == MEASURED
        for a in np.lexsort((-q_best, ~was_measured)):
            if measured[a]:
                measured &= ~clash[a]
    surprise = off_m / frame.sigma  # distance to the prediction in sigmas
    measured &= segments_consistent(setup, p, memory, dist, new_pos, measured, np.nan_to_num(surprise))
    new_pos[~measured] = np.nan
    return new_pos, measured


def segments_consistent(setup: Setup, p: TrackerParams, memory: MarkerMemory, dist: np.ndarray, pos: np.ndarray,
                        measured: np.ndarray, surprise: np.ndarray) -> np.ndarray:
    """False for a marker whose distance to a segment neighbour broke its learned length.

    Neighbours measured this frame count; so do neighbours known only from last frame's
    estimate, against a newly found marker (with ``returning_tol_factor`` times the tolerance),
    so that a marker coming back from hiding cannot take a ball that is not where its segment says.

    Args:
        dist: (M, M) distances between the markers' candidate positions ``pos`` (NaN where
            either has none).
        pos: (M, 3) candidate positions; measured: (M,) bool.
        surprise: (M,) each candidate's distance to its prediction in prediction sigmas.
    """
    tol = p.segment_tol_m
    same_segment, seg_length = setup.same_segment, memory.seg_length
    broken = np.abs(dist - seg_length) > tol  # (False for NaN, without a warning)
    bad_pair = same_segment & measured[:, None] & measured[None, :] & broken
    returning = measured & (memory.status != MEASURED)
    if returning.any():
        known_prev = np.isfinite(memory.positions).all(axis=1) & ~measured
        if known_prev.any():
            diff = pos[:, None, :] - memory.positions[None, :, :]
            d_prev = np.sqrt((diff * diff) @ ONES3)
            chk = same_segment & returning[:, None] & known_prev[None, :]
            bad_prev = (chk & (np.abs(d_prev - seg_length) > p.returning_tol_factor * tol)).any(axis=1)
            measured = measured & ~bad_prev
    ok = measured.copy()
    # drop the marker involved in most broken pairs, one at a time; of markers in as many, a
    # returning one (not measured last frame) first: the one measured last frame still sits
    # on its ball far more often than a marker found again after hiding; then the candidate
    # farther from its prediction (a wrong ball in one view moves the point away from it)
    returning_now = memory.status != MEASURED
    while bad_pair.any():
        count = bad_pair.sum(axis=1)
        worst = max(np.flatnonzero(count == count.max()).tolist(),
                    key=lambda i: (bool(returning_now[i]), float(surprise[i])))
        ok[worst] = False
        bad_pair[worst, :] = bad_pair[:, worst] = False
    return ok


def learn_lengths(setup: Setup, p: TrackerParams, memory: MarkerMemory, measured: np.ndarray) -> None:
    """Move the learned segment lengths of the pairs measured this frame set towards their distance
    (the first measurement sets them)."""
    pos = memory.positions
    diff = pos[:, None, :] - pos[None, :, :]
    d = np.sqrt((diff * diff) @ ONES3)
    pair = setup.same_segment & measured[:, None] & measured[None, :]
    old = memory.seg_length  # NaN until first learned
    rate = p.length_learning_rate
    memory.seg_length = np.where(pair, np.where(np.isnan(old), d, (1.0 - rate) * old + rate * d), old)
