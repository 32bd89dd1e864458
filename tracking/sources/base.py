"""The frame-source interface: cameras, recordings and the simulated patient behind one protocol.

A source delivers one synchronized :class:`FrameSet` per :meth:`FrameSource.read`. A reader
that keeps its own clock (the live tracker's loop) passes a :class:`FrameRequest`: which frame
set it wants, at what time, and whether the tracker has named the markers; ``rehab record``,
``rehab track`` and the benchmarks read the frame sets in the source's own order.

A camera whose image is missing from a frame set (it stopped delivering, or its frame was out of
step with the others) gets a black image of its calibrated size: the tracker finds no marker in
it and goes on with the other cameras' views, and ``missing`` says which cameras had none.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Protocol, Sequence

import numpy as np

from calibration.camera import Camera
from calibration.errors import RehabError
from tracking.markerset import MarkerSet
from tracking.sources.commands import LiveError, SetMotion


class SourceError(RehabError):
    """A frame source cannot be opened or read (a missing camera, a video that ends early, ...)."""


@dataclass(frozen=True, slots=True)
class FrameSet:
    """One synchronized frame set from a source.

    Attributes:
        index: frame-set number from 0.
        time_s: time stamp of the set, seconds from the source's start.
        images: one (H, W, 3) uint8 BGR image per camera, calibration order; black where missing.
        stamps_s: (C,) float64 time stamp of each camera's image, seconds from the source's start;
            NaN where unknown or missing.
        missing: (C,) bool, the camera delivered no image for this set.
        truth_m: (M, 3) float64 true marker centres, world metres (simulated sources), else None.
        t_ready_s: ``time.perf_counter()`` when the images were complete.
        source_ms: time the source took to deliver them, milliseconds.
    """

    index: int
    time_s: float
    images: tuple[np.ndarray, ...]
    stamps_s: np.ndarray
    missing: np.ndarray
    truth_m: np.ndarray | None = None
    t_ready_s: float = math.nan
    source_ms: float = math.nan


@dataclass(frozen=True, slots=True)
class FrameRequest:
    """What a reader with its own clock asks for (the live tracker's loop).

    Attributes:
        index: the frame set's number; the same number again gives the same set, a number beyond
            the next skips the sets between (where the source can: a recording).
        time_s: the loop's time of the set, seconds (a simulated patient is rendered at it).
        identified: the tracker has named the markers (a simulated patient waiting to be named
            holds the reference pose).
    """

    index: int
    time_s: float
    identified: bool = True


class FrameSource(Protocol):
    """What the tracker (live or offline), ``rehab record`` and the benchmarks need from a source.

    Attributes:
        cameras: the calibrated cameras, in the order of the images.
        markerset: the markers the tracker looks for.
        fps: nominal frame rate, frame sets per second.
    """

    cameras: tuple[Camera, ...]
    markerset: MarkerSet
    fps: float

    def open(self) -> None:
        """Open the devices or files (idempotent; :meth:`read` opens a source not yet open).

        Raises:
            SourceError: a device or file cannot be opened (one line that names it).
        """

    def read(self, request: FrameRequest | None = None) -> FrameSet | None:
        """The next frame set (or the one ``request`` asks for), or None when the source has
        ended (see :meth:`end_reason`)."""

    def warnings(self) -> tuple[str, ...]:
        """Current problems, one line each (dropped frames, a stopped camera...); () if none."""

    def end_reason(self) -> str:
        """Why :meth:`read` returned None ("" while it has not)."""

    def handle(self, command: object) -> None:
        """Apply a live command meant for the source (the simulated patient's motion and input,
        a new identification); a source without motions refuses ``SetMotion`` in one line."""

    def close(self) -> None:
        """Release devices, files, threads and GL resources (idempotent)."""


def warnings_and_end(source: FrameSource) -> tuple[str, ...]:
    """The source's problems and, once it ended, why (last): what the live tracker publishes
    when a source stops."""
    end = source.end_reason()
    said = tuple(w for w in source.warnings() if w != end)
    return (*said, end) if end else said


class InOrderSource:
    """The :class:`FrameRequest` rules for a source that delivers its frame sets in its own order
    (a recording, live cameras); a subclass gives :meth:`read_next` (and :meth:`skip` if it can).

    Asking again for the last set returns it again (the live loop tracks its warm-up frame set
    first); a number beyond the next skips the sets in between where the source can (a process
    that replaces a dead one continues a recording where the dead one was).
    """

    def __init__(self) -> None:
        self._next_index = 0  # number of the next frame set the source will deliver
        self._last: FrameSet | None = None

    def read_next(self) -> FrameSet | None:
        """The source's next frame set, or None when it has ended."""
        raise NotImplementedError

    def skip(self, n: int) -> int:
        """Drop the next ``n`` frame sets; returns how many were dropped (none: a live source)."""
        return 0

    def read(self, request: FrameRequest | None = None) -> FrameSet | None:
        if request is not None and self._last is not None and self._last.index == request.index:
            return self._last
        t0 = time.perf_counter()
        if request is not None and request.index > self._next_index:
            self._next_index += self.skip(request.index - self._next_index)
        fs = self.read_next()
        t1 = time.perf_counter()
        if fs is None:
            return None
        self._next_index += 1
        if request is not None:  # numbered as the reader asked (a camera has no numbers of its own)
            fs = replace(fs, index=request.index)
        self._last = fs = replace(fs, t_ready_s=t1, source_ms=(t1 - t0) * 1000.0)
        return fs

    def handle(self, command: object) -> None:
        """Nothing to do for a new identification or patient input; a motion is refused."""
        if isinstance(command, SetMotion) and command.name is not None:
            raise LiveError(f"motion {command.name!r}: this source measures a recording or cameras, it plays no "
                              "motions")


def one_size(cameras: Sequence[Camera]) -> tuple[int, int]:
    """The image size all ``cameras`` share (the live image block holds one size); one-line
    :class:`LiveError` if they differ."""
    sizes = sorted({tuple(c.size_px) for c in cameras})
    if len(sizes) != 1:
        raise LiveError(f"the cameras have different image sizes {sizes}: the live tracker needs one size; "
                        "set the cameras to one size and recalibrate")
    return sizes[0]


def black_image(camera: Camera) -> np.ndarray:
    """(H, W, 3) uint8 zeros of ``camera``'s calibrated size: the image of a missing view."""
    w, h = camera.size_px
    return np.zeros((int(h), int(w), 3), np.uint8)


def camera_names(cameras: Sequence[Camera], mask: np.ndarray) -> str:
    """``"cam1, cam3"``: the names of the cameras where ``mask`` (C,) bool is true."""
    return ", ".join(c.name for c, m in zip(cameras, mask) if m)
