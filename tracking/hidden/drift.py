"""Near-rigid pairs: distances learned while both markers are measured, checked on estimates.

An estimate whose distance to a measured partner of a near-rigid pair (``length_pairs``) leaves
the range learned while both were measured, widened by ``tolerance_m``, has left what the body
allows and is dropped to LOST.
"""

from __future__ import annotations

import numpy as np


class PairRanges:
    """Learned distance range of each pair (``pairs``: (P, 2) marker indices)."""

    def __init__(self, pairs: np.ndarray, tolerance_m: float) -> None:
        self.pairs = pairs
        self.tolerance_m = float(tolerance_m)
        self.reset()

    def reset(self) -> None:
        self.lo = np.full(len(self.pairs), np.inf)
        self.hi = np.full(len(self.pairs), -np.inf)

    def learn(self, p: np.ndarray, ok: np.ndarray) -> None:
        if len(self.pairs):
            both = ok[self.pairs].all(axis=1)
            if both.any():
                q = p[self.pairs]
                d = np.sqrt(((q[:, 0] - q[:, 1]) ** 2).sum(axis=1))
                self.lo = np.where(both, np.fmin(self.lo, d), self.lo)
                self.hi = np.where(both, np.fmax(self.hi, d), self.hi)

    def outside(self, p: np.ndarray, hidden: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """Indices of the estimated markers (``hidden``) whose distance to a measured partner
        leaves its range (+ tolerance); both markers of such a pair are listed."""
        if not len(self.pairs):
            return np.zeros(0, dtype=np.intp)
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        check = ((hidden[i] & ok[j]) | (hidden[j] & ok[i])) & (self.hi >= self.lo)
        if not check.any():
            return np.zeros(0, dtype=np.intp)
        d = np.linalg.norm(p[i[check]] - p[j[check]], axis=1)
        out = (d < self.lo[check] - self.tolerance_m) | (d > self.hi[check] + self.tolerance_m)
        return np.r_[i[check][out], j[check][out]]
