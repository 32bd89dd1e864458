"""Elbow hinge: a hidden epicondyle marker on the elbow's flexion axis (docs/HIDDEN_MARKERS.md).

With n the unit axis from the visible epicondyle marker and d their learned distance, the elbow
centre is ``partner + d/2 n``; n is perpendicular to the humerus (learned shoulder pivot -> elbow
centre) and to the forearm (elbow centre -> wrist centre), both linear in n. Where the two
conditions do not fix n the rigid forearm-elbow fit (or the previous axis) fills in, dropped past
``max_hinge_sigma_deg`` of extrapolated turn; of two mirror images the one on the side the elbow
bends is kept; a single camera view moves the estimate across its ray.
"""

from __future__ import annotations

import math

import numpy as np

from tracking.hidden.codes import DROP, Method
from tracking.hidden.frame import FrameInputs
from tracking.hidden.geometry import cross3, hinge_axis, unit
from tracking.hidden.methods.rigid import rigid_fit
from tracking.hidden.registry import HiddenMethod, register


@register
class HingeEstimator(HiddenMethod):
    """Epicondyle markers (``elbows:`` entries), falling back to the rigid fit."""

    name = "hinge"
    code = Method.HINGE
    fallback = "rigid"
    rank = 3
    max_hidden_s = 20.0

    def check(self, marker: int, layout) -> None:
        if marker not in layout.hinges:
            raise ValueError(f"marker {marker} uses the hinge estimator but has no hinge")

    def estimate(self, frame: FrameInputs, k: int) -> np.ndarray | None:
        est = self._axis_estimate(frame, k)
        views = frame.state.views
        if est is None or est is DROP or not np.all(np.isfinite(est)) or k not in views.by_marker:
            return est
        est, viewed = views.refine(k, est)
        if viewed:
            frame.state.elbows.viewed_now.add(k)
        return est

    def _axis_estimate(self, frame: FrameInputs, k: int) -> np.ndarray | None:
        state, p, ok = frame.state, frame.p, frame.ok
        h = state.layout.hinges[k]
        r = state.layout.h_row[k]
        elbows = state.elbows
        length = elbows.length[r]
        if not (ok[h.partner] and ok[h.shoulder]) or not np.isfinite(length):
            return None
        # prediction: the rigid forearm-elbow fit (exact while the forearm does not turn), else
        # the axis of the previous frame
        prev_axis = frame.base[k] - frame.base[h.partner]
        prev_axis = unit(prev_axis) if np.all(np.isfinite(prev_axis)) else None
        rigid = rigid_fit(frame, k)
        if rigid is not None:
            axis_pred = unit(rigid - p[h.partner])
        elif prev_axis is not None:
            axis_pred = prev_axis
        else:
            return None
        # the axis is perpendicular to the humerus (pivot -> elbow centre) and to the forearm
        # (elbow centre -> wrist centre); with the centre = partner + length/2 n both are linear in n
        pivot = state.pivots.pivot_m(h.shoulder, p[h.shoulder], p[h.partner])
        rows = [p[h.partner] - pivot]
        values = [-0.5 * length]
        wa, wb = h.wrists
        if ok[wa] and ok[wb]:
            rows.append(0.5 * (p[wa] + p[wb]) - p[h.partner])
            values.append(elbows.fore[r])
        side = prev_axis
        if len(rows) == 2 and abs(elbows.sense[r]) > state.params.bend_sense_min:
            # of the two mirror images the one on the side the elbow bends (anatomy), rather than
            # the previous axis' (which may itself be an extrapolation, or unknown after LOST)
            side = math.copysign(1.0, elbows.sense[r]) * unit(cross3(rows[0], rows[1]))
        n = self._solve(frame, k, r, np.array(rows), np.array(values), axis_pred, side)
        return n if n is DROP else p[h.partner] + length * n

    @staticmethod
    def _solve(frame: FrameInputs, k: int, r: int, rows: np.ndarray, values: np.ndarray,
               axis_pred: np.ndarray, side: np.ndarray | None) -> np.ndarray:
        """The unit axis of hinge row r from its conditions, or DROP where its extrapolated turn
        is too uncertain."""
        state = frame.state
        prm = state.params
        fixed, sv = [0], []
        n = hinge_axis(rows, values, axis_pred, min_singular=prm.min_singular, axis_prev=side, fixed=fixed,
                       singular=sv)
        if fixed[0] < 2 and len(sv) == 2 and sv[1] >= prm.weak_singular:
            # elbow nearly straight, wrists measured: the second condition pins the axis' turn
            # about the arm only weakly (its error follows the learned pivot's), the prediction
            # (the previous axis, or the rigid fit that turns with the forearm) drifts with the
            # forearm's turn: two estimates with independent errors of similar size, averaged.
            # Not extrapolated, so not dropped; supination still withheld (axis_guessed)
            n = unit(n + hinge_axis(rows, values, axis_pred, min_singular=prm.weak_singular, axis_prev=side))
            state.elbows.weak_now.add(r)
        elif fixed[0] < 2:  # the axis' turn about the arm is extrapolated (elbow straight, wrists hidden)
            free = state.elbows.free[r] + 1
            arm = state.layout.arm_of_elbow.get(k)
            arms = state.arms
            speed = (abs(float(arms.velocity[arm][1])) * arms.fps
                     if arm is not None and np.isfinite(arms.velocity[arm][1]) else 0.0)
            t = free / arms.fps
            if 0.5 * arms.accel_rad_s2 * t * t + prm.speed_share * speed * t > math.radians(prm.max_hinge_sigma_deg):
                return DROP
            state.elbows.free_now.add(r)
        return n
