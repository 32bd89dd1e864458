"""Prediction: each marker's position in this frame set from its history, and how uncertain it is."""

from __future__ import annotations

import numpy as np

from tracking.pipeline.params import TrackerParams
from tracking.pipeline.state import FrameState, MarkerMemory


def predict(frame: FrameState, memory: MarkerMemory, p: TrackerParams) -> None:
    """Fill ``frame.pred`` (constant velocity), ``frame.sigma`` (grows with the frame sets without a
    measurement, up to ``max_sigma_frames``, and with the speed) and ``frame.known``."""
    known = np.isfinite(memory.positions).all(axis=1)
    frame.known = known
    frame.pred = np.where(known[:, None], memory.positions + memory.velocity, np.nan)
    speed = np.linalg.norm(memory.velocity, axis=1)
    frame.sigma = (p.base_sigma_m + p.accel_sigma_m * np.minimum(memory.frames_unmeasured, p.max_sigma_frames)
                   + p.speed_sigma * speed)
