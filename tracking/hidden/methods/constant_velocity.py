"""Equation 5, constant velocity: ``P(n) = P(n-1) + dP(n-1)`` (docs/HIDDEN_MARKERS.md)."""

from __future__ import annotations

import numpy as np

from tracking.hidden.codes import Method
from tracking.hidden.frame import FrameInputs
from tracking.hidden.registry import HiddenMethod, register


def constant_velocity(p_prev_m: np.ndarray, v_prev_m: np.ndarray) -> np.ndarray:
    """Equation 5: ``P(n) = P(n-1) + dP(n-1)``.

    Args:
        p_prev_m: (M, 3) positions in frame n-1, world metres.
        v_prev_m: (M, 3) displacements from frame n-2 to n-1 (NaN counts as 0).

    Returns:
        (M, 3) predicted positions in frame n.
    """
    return p_prev_m + np.nan_to_num(v_prev_m)


@register
class ConstantVelocity(HiddenMethod):
    """The marker keeps its last step (short gaps of a marker whose neighbours say nothing)."""

    name = "constant_velocity"
    code = Method.CONSTANT_VELOCITY
    fallback = None
    rank = 0
    max_hidden_s = 0.5

    def estimate(self, frame: FrameInputs, k: int) -> np.ndarray:
        return constant_velocity(frame.base[k], frame.velocity[k])
