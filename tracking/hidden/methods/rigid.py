"""Rigid segment: the segment's other markers carry the hidden one (weighted Kabsch).

The reference configuration is the most recent frame in which the hidden marker and at least
three of the current supports were measured (:mod:`tracking.hidden.history`). Markers estimated
earlier in the same frame support with a small weight; two supports (or three nearly on a line)
leave the rotation about their line free, and a weak pseudo-point at the marker's prediction
picks it.
"""

from __future__ import annotations

import math

import numpy as np

from tracking.hidden.codes import Method
from tracking.hidden.frame import FrameInputs
from tracking.hidden.geometry import kabsch, spread_m
from tracking.hidden.registry import HiddenMethod, register


def rigid_estimate(
    ref_m: np.ndarray,
    cur_m: np.ndarray,
    target_ref_m: np.ndarray,
    *,
    weights: np.ndarray | None = None,
    prior_m: np.ndarray | None = None,
    prior_weight: float = 0.1,
    min_spread_m: float = 0.015,
    residual: list[float] | None = None,
) -> np.ndarray | None:
    """Carry a segment's hidden marker with the rigid motion of its other markers.

    Args:
        ref_m: (K, 3) reference positions of the support markers (a frame in which the hidden
            marker was measured too).
        cur_m: (K, 3) their positions now.
        target_ref_m: (3,) the hidden marker's position in the reference frame.
        weights: (K,) support weights (default 1; estimated supports weigh less).
        prior_m: (3,) predicted position of the hidden marker, used as a weak extra point when
            the support alone leaves a rotation free (K = 2 or collinear points).
        prior_weight: that point's weight.
        min_spread_m: support points closer than this (RMS) to a line are collinear.
        residual: a one-element list that receives the supports' RMS misfit (m).

    Returns:
        (3,) the estimate, or None when the fit is ill-posed (K < 2, or free rotation and no prior).
    """
    k = len(ref_m)
    if k < 2:
        return None
    if k < 3 or spread_m(ref_m) < min_spread_m:
        if prior_m is None or not np.all(np.isfinite(prior_m)):
            return None
        # the prior lives in the current frame; its reference is the target's reference position
        ref_m = np.vstack([ref_m, target_ref_m])
        cur_m = np.vstack([cur_m, prior_m])
        w = np.ones(k + 1) if weights is None else np.r_[weights, 0.0]
        w[-1] = prior_weight
    else:
        w = weights
    r, t = kabsch(ref_m, cur_m, w)
    est = r @ target_ref_m + t
    if residual is not None:  # RMS misfit of the supports: how far the segment is from rigid
        d = ref_m @ r.T + t - cur_m
        residual[0] = math.sqrt(float((d * d).sum()) / len(d))
    return est


def rigid_fit(frame: FrameInputs, k: int, residual: list[float] | None = None) -> np.ndarray | None:
    """Rigid estimate of marker k from the first of its segments that gives one (supports: the
    markers with a position now, ``frame.weight`` > 0)."""
    state, weight, p = frame.state, frame.weight, frame.p
    for s in state.layout.segments_of[k]:
        seg = state.layout.segments[s]
        cand = seg[(weight[seg] > 0) & (seg != k)]
        ref = state.history.reference(k, cand)
        if ref is None:
            continue
        ref_pos, ref_ok = ref
        sup = cand[ref_ok[cand]]
        est = rigid_estimate(ref_pos[sup], p[sup], ref_pos[k], weights=weight[sup], prior_m=frame.prior[k],
                             prior_weight=state.params.prior_weight, min_spread_m=state.params.min_spread_m,
                             residual=residual)
        if est is not None:
            return est
    return None


@register
class Rigid(HiddenMethod):
    """Kabsch on the marker's rigid groups (``rigid_groups``), in the order given."""

    name = "rigid"
    code = Method.RIGID
    fallback = "neighbours"
    rank = 2
    max_hidden_s = 5.0

    def estimate(self, frame: FrameInputs, k: int) -> np.ndarray | None:
        return rigid_fit(frame, k)
