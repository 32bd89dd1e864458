"""What a marker position in a frame rests on: measured, estimated or lost."""

from __future__ import annotations

from enum import IntEnum


class MarkerStatus(IntEnum):
    """Per-frame, per-marker status; stored as ``uint8`` arrays of shape (T, M) or (M,).

    LOST: no position (the position is NaN).
    MEASURED: triangulated from the images of this frame.
    ESTIMATED: hidden in this frame; the position is an estimate (e.g. from neighbour motion).
    """

    LOST = 0
    MEASURED = 1
    ESTIMATED = 2

    @property
    def label(self) -> str:
        """The word used in files (status CSV): ``lost``, ``measured``, ``estimated``."""
        return self.name.lower()

    @classmethod
    def from_label(cls, label: str) -> "MarkerStatus":
        """``'measured'`` -> :attr:`MEASURED`; a ValueError lists the allowed words."""
        try:
            return cls[label.strip().upper()]
        except KeyError:
            allowed = ", ".join(s.label for s in cls)
            raise ValueError(f"status {label!r} is not one of {allowed}") from None
