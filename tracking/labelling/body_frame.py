"""The patient's frame: their right, up and backwards in world coordinates, and its yaw.

+Y is up (calibration fixes it). The patient may sit turned about the vertical: the first guess
of their right (+x) is the principal axis of the points' horizontal spread (the reference pose is
wide left-right and shallow front-back), signed towards world +X; once markers are named, the
frame follows their left-right pairs (shoulders, hips). Shared by the rules' search and the fit.
"""

from __future__ import annotations

import math

import numpy as np

# the principal axis of the horizontal spread is trusted when the spread is this much wider than deep
_MIN_SPREAD_RATIO = 1.5


def patient_axes(yaw_rad: float) -> np.ndarray:
    """(3, 3) columns: the patient's right, up and backwards in world coordinates."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def yaw_from_points(p_world_m: np.ndarray) -> float:
    """First guess of the patient's yaw (radians): the principal axis of the horizontal spread.

    The sign is the one closer to world +X (the patient roughly faces -Z); an isotropic spread
    (no clear left-right axis) gives 0.
    """
    h = p_world_m[:, [0, 2]] - p_world_m[:, [0, 2]].mean(axis=0)
    evals, evecs = np.linalg.eigh(h.T @ h)
    if evals[1] < _MIN_SPREAD_RATIO * max(evals[0], 1e-12):
        return 0.0
    ex, ez = evecs[:, 1]
    if ex < 0:
        ex, ez = -ex, -ez
    return math.atan2(-ez, ex)


def yaw_from_pairs(p_world_m: np.ndarray, pairs: np.ndarray, default: float = 0.0) -> float:
    """Yaw (radians) from the mean horizontal left -> right direction of (left, right) points.

    Pairs with a stand-in (NaN) point are left out; ``default`` when none is left.
    """
    d = p_world_m[pairs[:, 1]] - p_world_m[pairs[:, 0]]
    d = d[np.isfinite(d).all(axis=1)][:, [0, 2]]
    if len(d) == 0:
        return default
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    vx, vz = d.sum(axis=0)
    return math.atan2(-vz, vx)

