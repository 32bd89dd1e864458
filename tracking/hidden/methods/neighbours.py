"""Equation 6, neighbour motion: the marker moves with its weighted neighbours (docs/HIDDEN_MARKERS.md).

``P_m(n) = P_m(n-1) + dP_m(n-1) + (1 / sum_i S_mi) sum_i S_mi dP_i(n)`` over the neighbours i
measured in frames n-1 and n; without the ``dP_m(n-1)`` term by default (with the estimate fed
back the paper's formula adds the neighbours' motion every frame and runs away).
"""

from __future__ import annotations

import numpy as np

from tracking.hidden.codes import Method
from tracking.hidden.frame import FrameInputs
from tracking.hidden.registry import HiddenMethod, register


def neighbour_motion(
    p_prev_m: np.ndarray,
    v_prev_m: np.ndarray,
    d_now_m: np.ndarray,
    d_ok: np.ndarray,
    weights: np.ndarray,
    *,
    own_velocity: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Equation 6 for every marker at once.

    Args:
        p_prev_m: (M, 3) positions in frame n-1, world metres.
        v_prev_m: (M, 3) each marker's own displacement n-2 -> n-1 (NaN counts as 0).
        d_now_m: (M, 3) each marker's displacement n-1 -> n (rows with ``d_ok`` False ignored).
        d_ok: (M,) bool, the displacement is known (measured in both frames).
        weights: (M, M) ``S[m, i]``, weight of neighbour i for marker m (0: not a neighbour).
        own_velocity: add the marker's own ``dP_m(n-1)`` (the paper's formula) or not.

    Returns:
        positions: (M, 3) estimates for frame n.
        ok: (M,) bool, at least one weighted neighbour moved known (else the row is NaN).
    """
    w = weights * d_ok[None, :]
    total = w.sum(axis=1)
    ok = total > 0
    d = np.where(d_ok[:, None], d_now_m, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_d = (w @ d) / total[:, None]
    out = p_prev_m + mean_d
    if own_velocity:
        out = out + np.nan_to_num(v_prev_m)
    out[~ok] = np.nan
    return out, ok


@register
class Neighbours(HiddenMethod):
    """Equation 6 (computed for every marker once per frame); None where no neighbour's motion
    is known (then the marker's own decaying velocity)."""

    name = "neighbours"
    code = Method.NEIGHBOURS
    fallback = None
    rank = 1
    max_hidden_s = 2.0

    def estimate(self, frame: FrameInputs, k: int) -> np.ndarray | None:
        return frame.eq6[k] if frame.eq6_ok[k] else None
