"""Recent frames as a ring: the rigid fits' reference configurations.

A rigid fit carries a hidden marker with its segment from the most recent frame in which the
marker and at least three of the current supports were measured, so the shape adapts to the
person and to slow changes.
"""

from __future__ import annotations

import numpy as np


class ReferenceHistory:
    """The last ``length`` frames' positions and measured flags, and the chosen references."""

    def __init__(self, length: int, n_markers: int) -> None:
        self.pos = np.full((length, n_markers, 3), np.nan)
        self.ok = np.zeros((length, n_markers), dtype=bool)
        self.frame = np.full(length, -1, dtype=np.int64)
        self._cache: dict[tuple[int, bytes], int] = {}  # (marker, supports) -> reference slot

    def store(self, frame: int, p: np.ndarray, ok: np.ndarray) -> None:
        """Keep frame ``frame`` (its slot's old frame is forgotten)."""
        slot = frame % len(self.frame)
        if self._cache and (ok.any() or any(v == slot for v in self._cache.values())):
            self._cache = {key: v for key, v in self._cache.items() if not ok[key[0]] and v != slot}
        self.pos[slot] = p
        self.ok[slot] = ok
        self.frame[slot] = frame

    def reference(self, k: int, cand: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The most recent stored frame in which marker k and at least three of the candidate
        supports ``cand`` (indices) were measured (else the one with most of them), as
        (positions (M, 3), measured (M,))."""
        key = (k, cand.tobytes())
        slot = self._cache.get(key)
        if slot is not None:
            return self.pos[slot], self.ok[slot]
        has = self.ok[:, k] & (self.frame >= 0)
        if not has.any() or not len(cand):
            return None
        count = np.where(has, self.ok[:, cand].sum(axis=1), -1)
        need = min(3, int(count.max()))
        if need < 1:
            return None
        slots = np.flatnonzero(count >= need)
        slot = int(slots[np.argmax(self.frame[slots])])
        # valid while k stays hidden (a newer reference needs k measured) and the slot is kept
        self._cache[key] = slot
        return self.pos[slot], self.ok[slot]
