"""The trunk frame and the shoulder pivots learned in it (shared by the hinge and the forearm).

The shoulder pivot (glenohumeral centre) is the acromion marker plus an offset in the trunk frame,
learned online by least squares from the hinge's condition that the elbow axis is perpendicular
to the humerus, with forgetting. The acromion rides on the scapula, which turns upward with the
arm's elevation (the scapulohumeral rhythm): the offset is learned at the scapula's rest and
turned with it. docs/HIDDEN_MARKERS.md ("Elbow hinge") has the derivation and its measurements.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from tracking.hidden.geometry import solve3, trunk_rotation, turn_z
from tracking.hidden.layout import Layout
from tracking.hidden.params import EstimatorParams


class ShoulderPivots:
    """The last trunk rotation and each shoulder's pivot offset (normal equations per shoulder)."""

    def __init__(self, layout: Layout, params: EstimatorParams) -> None:
        self.trunk = layout.trunk
        self.shoulder_slot = layout.shoulder_slot
        self.prior_m = np.asarray(params.pivot_prior_m, dtype=np.float64)
        self.forget = math.exp(-1.0 / (float(params.fps) * params.pivot_memory_s))
        self.rhythm = float(params.scapular_rhythm)
        self.rhythm_deg = (float(params.rhythm_deg[0]), float(params.rhythm_deg[1]))
        self.reset()

    def reset(self) -> None:
        n = len(self.shoulder_slot)
        self._a = np.zeros((n, 3, 3))
        self._b = np.zeros((n, 3))
        self._rest_cache: dict[int, np.ndarray] = {}  # shoulder slot -> solved offset, until _a, _b change
        self._side = np.ones(n)  # +1 right, -1 left (trunk x)
        self._trunk_rot: np.ndarray | None = None

    def learn_trunk(self, p: np.ndarray, ok: np.ndarray) -> None:
        if self.trunk is not None and ok[self.trunk].all():
            try:
                self._trunk_rot = trunk_rotation(*p[self.trunk])
            except ValueError:  # degenerate this frame: keep the last good frame
                pass

    @property
    def trunk_rot(self) -> np.ndarray:
        """(3, 3) trunk -> world rotation of the last frame with the trunk markers measured."""
        return np.eye(3) if self._trunk_rot is None else self._trunk_rot

    def add_equation(self, k: int, n: list[float], shoulder: list[float], centre: list[float],
                     upper: list[float] | None) -> None:
        """One frame's condition for shoulder slot k: the unit elbow axis ``n`` perpendicular to
        the humerus, ``n . (centre - G) = 0`` with ``G = shoulder + R g``, i.e.
        ``(R^T n) . g = n . (centre - shoulder)`` (``upper``: the upper trunk marker, if measured,
        tells the side)."""
        rhs = sum(n[i] * (centre[i] - shoulder[i]) for i in range(3))
        rt = self.trunk_rot.tolist()
        a_t = [n[0] * rt[0][j] + n[1] * rt[1][j] + n[2] * rt[2][j] for j in range(3)]
        if self.rhythm > 0:  # the equation for the offset at the scapula's rest
            if upper is not None:
                lateral = sum((shoulder[i] - upper[i]) * rt[i][0] for i in range(3))
                self._side[k] = 1.0 if lateral >= 0 else -1.0
            a_t = turn_z(a_t, -self.scapula_angle(k, shoulder, centre))
        self._a[k] = self.forget * self._a[k] + np.array([[a_t[i] * a_t[j] for j in range(3)] for i in range(3)])
        self._b[k] = self.forget * self._b[k] + np.array([rhs * a_t[i] for i in range(3)])
        self._rest_cache.pop(k, None)

    def rest_offset(self, k: int) -> np.ndarray:
        # solved once per change of the normal equations (several callers per frame, ~20 us each)
        g = self._rest_cache.get(k)
        if g is None:
            g = np.array(solve3(self._a[k] + np.eye(3), self._b[k] + self.prior_m))
            g.flags.writeable = False
            self._rest_cache[k] = g
        return g

    def scapula_angle(self, k: int, shoulder: Sequence[float], elbow: Sequence[float]) -> float:
        """Angle (rad, about the trunk's z) of the scapula's upward rotation for the humerus
        elevation (shoulder slot k, the shoulder marker and the elbow centre now, world
        3-sequences): ``scapular_rhythm`` degrees per degree of elevation within ``rhythm_deg``.
        In plain floats: it runs for every arm in every frame."""
        rt = self.trunk_rot.tolist()
        g = self.rest_offset(k).tolist()
        d = [elbow[i] - shoulder[i] for i in range(3)]
        u = [rt[0][j] * d[0] + rt[1][j] * d[1] + rt[2][j] * d[2] - g[j] for j in range(3)]
        lu = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
        if not lu > 1e-9:
            return 0.0
        elevation = math.degrees(math.acos(max(-1.0, min(1.0, -u[1] / lu))))
        lo, hi = self.rhythm_deg
        return math.radians(self.rhythm * (min(max(elevation, lo), hi) - lo)) * float(self._side[k])

    def offset_f(self, k: int, shoulder: Sequence[float], elbow: Sequence[float]) -> list[float]:
        """The pivot offset of shoulder slot k (trunk frame) turned with the scapula for the
        humerus elevation (:meth:`scapula_angle`), in plain floats."""
        g = self.rest_offset(k).tolist()
        if self.rhythm <= 0:
            return g
        return turn_z(g, self.scapula_angle(k, shoulder, elbow))

    def pivot_offset(self, shoulder: int, elbow_m: np.ndarray | None = None,
                     shoulder_m: np.ndarray | None = None) -> np.ndarray:
        """(3,) learned shoulder pivot minus the shoulder marker ``shoulder`` (marker index),
        trunk frame; turned with the scapula when the elbow centre and the shoulder marker's
        position are given."""
        k = self.shoulder_slot[shoulder]
        if elbow_m is None or shoulder_m is None or self.rhythm <= 0:
            return self.rest_offset(k)
        return np.array(self.offset_f(k, shoulder_m.tolist(), elbow_m.tolist()))

    def pivot_m(self, shoulder: int, shoulder_m: np.ndarray, elbow_m: np.ndarray) -> np.ndarray:
        """(3,) the shoulder pivot in the world for the shoulder marker and elbow centre now."""
        return shoulder_m + self.trunk_rot @ self.pivot_offset(shoulder, elbow_m, shoulder_m)
