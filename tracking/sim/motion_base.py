"""What every motion of the simulated patient is (:class:`Motion`), the reference pose's shortest
hold and the easing between keys: shared by the scripted motions (:mod:`tracking.sim.motions`) and
the replays of real captures (:mod:`tracking.sim.capture_replay`)."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from tracking.errors import MotionError
from tracking.sim.body import Pose

#: Identification needs the reference pose held at least this long at the start of every motion.
MIN_REFERENCE_HOLD_S = 1.0


def ease(tau: np.ndarray | float, kind: str = "minimum_jerk") -> np.ndarray | float:
    """Blend weight 0..1 for a progress ``tau`` in 0..1 (clipped).

    ``minimum_jerk``: 10t^3 - 15t^4 + 6t^5 (zero velocity and acceleration at both ends, the
    profile of smooth human point-to-point movements); ``cosine``: (1 - cos(pi t)) / 2;
    ``linear``: t.
    """
    t = np.clip(tau, 0.0, 1.0)
    if kind == "minimum_jerk":
        return t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)
    if kind == "cosine":
        return 0.5 - 0.5 * np.cos(np.pi * t)
    return t


class Motion(ABC):
    """A pose for every instant of ``[0, duration_s]``; before 0 and after the end it holds."""

    name: str
    duration_s: float

    @abstractmethod
    def pose_at(self, t_s: float) -> Pose:
        """The pose at ``t_s`` seconds from the start (clamped to the motion's span)."""

    def times(self, fps: float) -> np.ndarray:
        """(T,) sample times in seconds at ``fps`` frames per second over the whole motion."""
        if fps <= 0:
            raise MotionError(f"frame rate {fps:g} must be positive")
        return np.arange(int(math.floor(self.duration_s * fps + 1e-9)) + 1) / fps
