"""What the elbow hinges and the wrist circles learn while an arm's markers are all measured.

Per hinge: the epicondyle markers' distance, the axis' offset towards the wrist centre, the side
the elbow bends (the sign of ``n . (humerus x forearm)``) and, per frame, whether the hinge's
conditions pinned the axis' turn; per forearm: the wrist centre's circle about the elbow axis.
Each measured frame also gives the shoulder pivot one equation (:mod:`tracking.hidden.pivots`).
"""

from __future__ import annotations

import math

import numpy as np

from tracking.hidden.layout import Layout
from tracking.hidden.params import EstimatorParams
from tracking.hidden.pivots import ShoulderPivots


class ElbowState:
    """Learned hinge and wrist-circle constants, and this frame's hinge verdicts."""

    def __init__(self, layout: Layout, params: EstimatorParams) -> None:
        self.layout = layout
        self.rate = params.rate(params.shape_memory_s)
        self.bend_min_sine = float(params.bend_min_sine)
        self.reset()

    def reset(self) -> None:
        h, f = len(self.layout.h_idx), len(self.layout.f_idx)
        self.length = np.full(h, np.nan)  # epicondyle markers' distance
        self.fore = np.full(h, np.nan)    # n . (wrist centre - partner)
        self.free = np.zeros(h, dtype=np.int64)  # frames in a row with the axis extrapolated
        self.sense = np.zeros(h)  # sign of n . (humerus x forearm), learned (0: unknown)
        self.free_now: set[int] = set()   # rows whose axis' turn was extrapolated this frame
        self.weak_now: set[int] = set()   # rows whose axis' turn rests on a weak condition
        self.viewed_now: set[int] = set()  # markers whose estimate a single camera view moved
        self.fore_along = np.full(f, np.nan)   # wrist centre along the flexion axis
        self.fore_radius = np.full(f, np.nan)  # and its distance from it

    def end_frame(self) -> None:
        """Count the frames each hinge's axis has been extrapolated; forget this frame's verdicts."""
        if len(self.layout.h_idx):
            self.free = np.array([self.free[r] + 1 if r in self.free_now else 0
                                  for r in range(len(self.layout.h_idx))], dtype=np.int64)
            self.free_now = set()
            self.weak_now = set()
        self.viewed_now = set()

    def learn(self, pl: list, okl: list, pivots: ShoulderPivots) -> None:
        """Learn from a frame (``pl``, ``okl``: positions and measured flags as lists: a few
        3-vectors per arm, where plain floats are several times faster than numpy)."""
        rate = self.rate
        for r, (w, wp, ea, eb) in enumerate(self.layout.f_idx.tolist()):
            if not (okl[w] and okl[wp] and okl[ea] and okl[eb]):
                continue
            v = [0.5 * (pl[w][i] + pl[wp][i] - pl[ea][i] - pl[eb][i]) for i in range(3)]  # elbow -> wrist centre
            e = [pl[eb][i] - pl[ea][i] for i in range(3)]
            le = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
            if le < 1e-6:  # coincident elbow markers: nothing to learn from this frame
                continue
            along = (v[0] * e[0] + v[1] * e[1] + v[2] * e[2]) / le
            radius = math.sqrt(max(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - along * along, 0.0))
            old_a, old_r = self.fore_along[r], self.fore_radius[r]
            first = not math.isfinite(old_r)
            self.fore_along[r] = along if first else old_a + rate * (along - old_a)
            self.fore_radius[r] = radius if first else old_r + rate * (radius - old_r)
        trunk = self.layout.trunk
        for r, (mk, pa, sh, wa, wb) in enumerate(self.layout.h_idx.tolist()):
            if not (okl[mk] and okl[pa] and okl[sh] and okl[wa] and okl[wb]):
                continue
            n = self._learn_hinge(r, pl, mk, pa, sh, wa, wb)
            # the other marker's hinge gives the same pivot equation (n reversed)
            if n is None or mk < pa:
                continue
            centre = [0.5 * (pl[mk][i] + pl[pa][i]) for i in range(3)]
            upper = pl[trunk[0]] if trunk is not None and okl[trunk[0]] else None
            pivots.add_equation(self.layout.h_shoulder_slot[r], n, pl[sh], centre, upper)

    def _learn_hinge(self, r: int, pl: list, mk: int, pa: int, sh: int, wa: int, wb: int) -> list[float] | None:
        """Hinge r's length, wrist offset and bending side from a measured frame; its unit axis."""
        rate = self.rate
        e = [pl[mk][i] - pl[pa][i] for i in range(3)]
        length = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        if length < 1e-6:
            return None
        n = [c / length for c in e]
        fore = sum(n[i] * (0.5 * (pl[wa][i] + pl[wb][i]) - pl[pa][i]) for i in range(3))  # n . (wrist centre - partner)
        old_l, old_f = self.length[r], self.fore[r]
        first = not math.isfinite(old_l)
        self.length[r] = length if first else old_l + rate * (length - old_l)
        self.fore[r] = fore if first else old_f + rate * (fore - old_f)
        # which way the axis runs relative to humerus x forearm (the elbow bends one way only):
        # learned where the elbow is clearly flexed (sine of the angle > bend_min_sine)
        hum = [0.5 * (pl[mk][i] + pl[pa][i]) - pl[sh][i] for i in range(3)]
        fa = [0.5 * (pl[wa][i] + pl[wb][i] - pl[mk][i] - pl[pa][i]) for i in range(3)]
        hx = [hum[1] * fa[2] - hum[2] * fa[1], hum[2] * fa[0] - hum[0] * fa[2], hum[0] * fa[1] - hum[1] * fa[0]]
        sense = n[0] * hx[0] + n[1] * hx[1] + n[2] * hx[2]
        if abs(sense) > self.bend_min_sine * math.sqrt(sum(x * x for x in hum) * sum(x * x for x in fa)):
            self.sense[r] += rate * (math.copysign(1.0, sense) - self.sense[r])
        return n
