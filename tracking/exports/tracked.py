"""What the tracker made of a recording, as the export formats are given it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True, eq=False)  # arrays: no elementwise __eq__
class TrackedRecording:
    """What the tracker made of a recording, frame by frame (T frame sets, M markers, C cameras).

    Attributes:
        names: the M marker names; markerset: the marker set's name.
        cameras: the C cameras.
        frames: (T,) recording frame indices (0 = first image); times_s: (T,) seconds.
        rate_hz: the recording's frame rate.
        positions_mm: (T, M, 3) world millimetres, NaN where lost.
        status: (T, M) :class:`~tracking.marker_status.MarkerStatus` codes.
        angles_deg: angle name -> (T,) degrees (the tracker's, NaN where undefined).
        uv_px: (T, M, C, 2) centroids each position was triangulated from, NaN where unused.
        identified: (T,) bool, the frame sets where the tracker identified the markers (the first
            TRACKING frame set after WAITING).
        subject: meta.yaml's ``subject`` (a pseudonymous ID), or None.
        timing: one line on the images' instants used (time stamps, rolling shutter), or "".
    """

    names: tuple[str, ...]
    markerset: str
    cameras: tuple
    frames: np.ndarray
    times_s: np.ndarray
    rate_hz: float
    positions_mm: np.ndarray
    status: np.ndarray
    angles_deg: dict[str, np.ndarray]
    uv_px: np.ndarray
    identified: np.ndarray
    subject: str | None = None
    timing: str = ""
