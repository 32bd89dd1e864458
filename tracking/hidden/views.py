"""Single camera views of hidden markers as rays, used by the next update only.

A camera that alone sees a hidden marker says the marker lies on a ray (camera centre, unit
direction) up to the view's angular uncertainty. A ray counts where it passes within
``view_gate_m`` of the estimator's prediction (farther: another ball of the colour).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from tracking.hidden.params import EstimatorParams

#: One view: camera centre (world metres), unit direction, angular uncertainty (rad).
View = tuple[list[float], list[float], float]


class ViewRays:
    """The views of the coming frame, per marker."""

    def __init__(self, params: EstimatorParams) -> None:
        self.gate_m = float(params.view_gate_m)
        self.estimate_sigma_m = float(params.view_estimate_sigma_m)
        self.by_marker: dict[int, list[View]] = {}

    def observe(self, markers: np.ndarray, origins_m: np.ndarray, directions: np.ndarray,
                sigma_rad: np.ndarray) -> None:
        """Replace the views (see :meth:`tracking.hidden.Estimator.observe_views`)."""
        views: dict[int, list[View]] = {}
        for k, o, d, sr in zip(np.asarray(markers).tolist(), np.asarray(origins_m).tolist(),
                               np.asarray(directions).tolist(), np.asarray(sigma_rad).tolist()):
            views.setdefault(int(k), []).append((o, d, float(sr)))
        self.by_marker = views

    def clear(self) -> None:
        self.by_marker = {}

    def nearest(self, markers: tuple[int, int], ok: np.ndarray,
                predict: Callable[[], tuple[np.ndarray, np.ndarray]]) -> list[tuple[int, list, list, float]]:
        """Of the views of the hidden ones of two markers (slots 0 and 1), per marker the one whose
        ray passes nearest its prediction (``predict()``: the two predicted positions), within the
        gate, as (slot, origin, direction, sigma_rad)."""
        if not self.by_marker:
            return []
        out = []
        pts = None
        for slot, w in enumerate(markers):
            if ok[w] or w not in self.by_marker:
                continue
            if pts is None:
                pts = predict()
            q = pts[slot].tolist()
            # of several views within the gate only the nearest: the tracker passes a marker's
            # full-sized single views when they made no consistent point, so two or more hold
            # at most one of the marker (the walk: a second ball 41 mm off moved MRW1 19 mm)
            nearest = None
            for o, d, sigma_rad in self.by_marker[w]:
                v = [q[i] - o[i] for i in range(3)]
                s = v[0] * d[0] + v[1] * d[1] + v[2] * d[2]
                off2 = sum((v[i] - s * d[i]) ** 2 for i in range(3))
                if off2 <= self.gate_m ** 2 and (nearest is None or off2 < nearest[0]):
                    nearest = (off2, (slot, o, d, sigma_rad))
            if nearest is not None:
                out.append(nearest[1])
        return out

    def refine(self, k: int, est: np.ndarray) -> tuple[np.ndarray, bool]:
        """An estimate of marker k moved across its views (rays within the gate): per ray, the
        offset across the ray shrinks by the view's weight (``sigma_rad`` times the distance)
        against the estimate's (``view_estimate_sigma_m``); the depth along the ray stays.
        Returns the estimate and whether a view was used."""
        q = est.tolist()
        used = False
        for o, d, sigma_rad in self.by_marker[k]:
            v = [q[i] - o[i] for i in range(3)]
            s = v[0] * d[0] + v[1] * d[1] + v[2] * d[2]
            off = [v[i] - s * d[i] for i in range(3)]
            if s <= 0 or sum(x * x for x in off) > self.gate_m ** 2:
                continue
            sr2 = (sigma_rad * s) ** 2
            gain = self.estimate_sigma_m ** 2 / (self.estimate_sigma_m ** 2 + sr2)
            q = [q[i] - gain * off[i] for i in range(3)]
            used = True
        return np.array(q), used
