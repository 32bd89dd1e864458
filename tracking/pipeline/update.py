"""The end of a tracked frame set: the hidden-marker estimate of the markers not measured, then each
marker's memory for the next frame set.

The estimator is :class:`tracking.hidden.Estimator`, passed in (only ``tracking/tracker.py`` imports
:mod:`tracking.hidden`, so that its home can move with one line)."""

from __future__ import annotations

import numpy as np

from tracking.pipeline.consistency import learn_lengths
from tracking.pipeline.params import TrackerParams
from tracking.pipeline.state import FrameState, MarkerMemory, Setup
from tracking.pipeline.timing import remember_views
from tracking.marker_status import MarkerStatus


def estimate_hidden(setup: Setup, p: TrackerParams, frame: FrameState, estimator, new_pos: np.ndarray,
                    measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) positions and (M,) statuses from the hidden-marker estimator, given the markers
    measured this frame set."""
    if not measured.all():  # (the estimator reads the markers' noise only for its estimates)
        # each marker's position noise: a share of a pixel's size at its distance (nearest camera)
        footprint = np.fmin.reduce(frame.pred_depth / setup.stack.focal_px, axis=1)
        estimator.marker_sigma_m = np.where(np.isfinite(footprint), p.marker_sigma_px * footprint,
                                            estimator.marker_sigma_m)
    est_pos, status = estimator.update(np.where(measured[:, None], new_pos, np.nan), measured)
    return est_pos, np.asarray(status, dtype=np.uint8)


def remember(setup: Setup, p: TrackerParams, frame: FrameState, memory: MarkerMemory, est_pos: np.ndarray,
             status: np.ndarray, measured: np.ndarray, found: np.ndarray) -> bool:
    """Update ``memory`` with this frame set's positions; True when most markers have been lost for
    ``reidentify_after`` frame sets (identify again)."""
    prev = memory.positions
    memory.positions = est_pos
    memory.status = status
    has = np.isfinite(est_pos).all(axis=1) & np.isfinite(prev).all(axis=1)
    # a marker found again far from its estimate: the jump is the estimate's error, not motion
    memory.velocity = np.where((has & ~found)[:, None], est_pos - prev, 0.0)
    remember_views(frame, memory, measured)
    memory.frames_unmeasured = np.where(measured, 0, memory.frames_unmeasured + 1)
    memory.last_seen[measured] = est_pos[measured]
    learn_lengths(setup, p, memory, measured)
    lost = memory.status == MarkerStatus.LOST
    memory.lost_streak = memory.lost_streak + 1 if lost.sum() > len(lost) // 2 else 0
    return memory.lost_streak >= p.reidentify_after
