"""The frame-source interface: one synchronized frame set per :meth:`FrameSource.read`.

A camera whose image is missing from a frame set (it stopped delivering, or its frame was out of
step with the others) gets a black image of its calibrated size: the tracker finds no marker in
it and goes on with the other cameras' views, and ``missing`` says which cameras had none.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np

from calibration.camera import Camera
from calibration.errors import RehabError


class SourceError(RehabError):
    """A frame source cannot be opened or read (a missing camera, a video that ends early, ...)."""


@dataclass(frozen=True, slots=True)
class SourceFrameSet:
    """One synchronized frame set from a source.

    Attributes:
        index: frame-set number from 0.
        time_s: time stamp of the set, seconds from the source's start.
        images: one (H, W, 3) uint8 BGR image per camera, calibration order; black where missing.
        stamps_s: (C,) float64 time stamp of each camera's image, seconds from the source's start;
            NaN where missing.
        missing: (C,) bool, the camera delivered no image for this set.
        truth_m: (M, 3) float64 true marker centres, world metres (simulated sources), else None.
    """

    index: int
    time_s: float
    images: tuple[np.ndarray, ...]
    stamps_s: np.ndarray
    missing: np.ndarray
    truth_m: np.ndarray | None = None


class FrameSource(Protocol):
    """What the tracker (live or offline) and ``rehab record`` need from a source.

    Attributes:
        cameras: the calibrated cameras, in the order of the images.
        fps: nominal frame rate, frame sets per second.
    """

    cameras: tuple[Camera, ...]
    fps: float

    def open(self) -> None:
        """Open the devices or files (idempotent; :meth:`read` opens a source not yet open).

        Raises:
            SourceError: a device or file cannot be opened (one line that names it).
        """

    def read(self) -> SourceFrameSet | None:
        """The next frame set, or None when the source has ended (see :meth:`end_reason`)."""

    def warnings(self) -> tuple[str, ...]:
        """Current problems, one line each (dropped frames, a stopped camera...); () if none."""

    def end_reason(self) -> str:
        """Why :meth:`read` returned None ("" while it has not)."""

    def close(self) -> None:
        """Release devices, files and threads (idempotent)."""


def black_image(camera: Camera) -> np.ndarray:
    """(H, W, 3) uint8 zeros of ``camera``'s calibrated size: the image of a missing view."""
    w, h = camera.size_px
    return np.zeros((int(h), int(w), 3), np.uint8)


def camera_names(cameras: Sequence[Camera], mask: np.ndarray) -> str:
    """``"cam1, cam3"``: the names of the cameras where ``mask`` (C,) bool is true."""
    return ", ".join(c.name for c, m in zip(cameras, mask) if m)
