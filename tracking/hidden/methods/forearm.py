"""Forearm: a hidden styloid marker from its arm's flexion and supination, or the wrist circle.

Where the arm's angles are tracked (:mod:`tracking.hidden.arms`) the styloid comes from their fit
to the measured one; otherwise from the rigid forearm-elbow fit while that fits (misfit within
``max_rigid_residual_m``), and when the forearm has turned, the mirror of the measured styloid
through the wrist centre on its learned circle about the flexion axis.
"""

from __future__ import annotations

import numpy as np

from tracking.hidden.codes import Method
from tracking.hidden.forearm_model import wrist_centre
from tracking.hidden.frame import FrameInputs
from tracking.hidden.methods.rigid import rigid_fit
from tracking.hidden.registry import HiddenMethod, register


@register
class ForearmEstimator(HiddenMethod):
    """Styloid markers (``forearms:`` entries), falling back to the rigid fit."""

    name = "forearm"
    code = Method.FOREARM
    fallback = "rigid"
    rank = 4
    max_hidden_s = 20.0

    def check(self, marker: int, layout) -> None:
        if marker not in layout.forearms:
            raise ValueError(f"marker {marker} uses the forearm estimator but has no forearm")

    def estimate(self, frame: FrameInputs, k: int) -> np.ndarray | None:
        state, p, ok, weight = frame.state, frame.p, frame.ok, frame.weight
        if k in state.layout.arm_of:
            est = state.arms.estimate(k, p, ok, weight)
            if est is not None:
                return est
        f = state.layout.forearms[k]
        r = state.layout.f_row[k]
        ea, eb = f.elbow
        resid = [0.0]
        rigid = rigid_fit(frame, k, resid)
        if rigid is not None and resid[0] <= state.params.max_rigid_residual_m:
            return rigid
        # the forearm turned (or no rigid fit): the other styloid, measured, on the wrist circle
        along, radius = state.elbows.fore_along[r], state.elbows.fore_radius[r]
        if not (ok[f.partner] and weight[ea] > 0 and weight[eb] > 0) or not np.isfinite(radius):
            return rigid
        pred = rigid if rigid is not None else frame.prior[k]
        centre = wrist_centre(p[f.partner], p[ea], p[eb], along, radius, 0.5 * (pred + p[f.partner]))
        return 2.0 * centre - p[f.partner]
