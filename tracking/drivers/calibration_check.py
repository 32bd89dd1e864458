"""How much a calibration changes tracking: the same recording tracked with two calibrations."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from calibration.camera import Camera
from tracking.markerset import load_markerset
from tracking.io.recording import Recording
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker


def track_positions(folder: str | Path, cameras: Sequence[Camera]) -> tuple[np.ndarray, np.ndarray]:
    """Track a recording with the given cameras.

    Returns:
        positions_m: (T, M, 3) world metres, NaN unless measured (triangulated) in that frame.
        status: (T, M) MarkerStatus values.
    """
    with Recording(folder) as rec:
        ms = load_markerset(rec.meta.markerset)
        if rec.meta.marker_colours and len(rec.meta.marker_colours) == ms.n_markers:
            ms = ms.with_colours(list(rec.meta.marker_colours))
        tracker = Tracker(tuple(cameras), ms, fps=rec.fps)
        pos, status = [], []
        for fs in rec:
            sample = tracker.step(fs.images, fs.time_s)
            measured = sample.status == MarkerStatus.MEASURED
            pos.append(np.where(measured[:, None], sample.positions_m, np.nan))
            status.append(sample.status)
    return np.stack(pos), np.stack(status)


def tracking_difference_mm(folder: str | Path, cameras: Sequence[Camera], reference: Sequence[Camera]) -> tuple[float, int]:
    """RMS distance (mm) between the markers measured with ``cameras`` and with ``reference``.

    Only marker positions measured in the same frame with both calibrations count.
    Returns (rmse_mm, number of positions compared).
    """
    a, _ = track_positions(folder, cameras)
    b, _ = track_positions(folder, reference)
    both = np.all(np.isfinite(a), axis=2) & np.all(np.isfinite(b), axis=2)
    d = np.linalg.norm(a[both] - b[both], axis=1) * 1000.0
    return (float(np.sqrt(np.mean(d**2))) if d.size else float("nan")), int(d.size)
