"""An arm chain that coasts: a moving arm behind the other one or the trunk for a frame or two.

While fewer than two of an arm's epicondyle and styloid markers are measured, the hinge and the
forearm have nothing to turn about and the rigid and neighbour fallbacks would leave the markers
where they were; each hidden chain marker (except an epicondyle marker whose hinge partner is
measured: the hinge places it) keeps its last velocity while the extrapolation's uncertainty
``0.5 a t^2`` stays within ``max_extrapolation_m`` (a: ``limb_accel_m_s2`` plus the marker's own
acceleration over its last two steps, so a swinging arm does not coast; t from the last frame with
two chain markers measured). docs/HIDDEN_MARKERS.md has the measurements.
"""

from __future__ import annotations

import math

import numpy as np

from tracking.hidden.layout import Layout
from tracking.hidden.params import EstimatorParams


def coasting(layout: Layout, params: EstimatorParams, ok: np.ndarray, chain_coast: np.ndarray,
             positions: np.ndarray, velocity: np.ndarray, velocity_before: np.ndarray) -> dict[int, np.ndarray]:
    """Marker -> estimate of the chain markers that coast this frame.

    Args:
        ok: (M,) measured now; chain_coast: (A,) frames in a row each chain coasted before.
        positions, velocity, velocity_before: (M, 3) the last output, its step and the step before.
    """
    out: dict[int, np.ndarray] = {}
    if not len(layout.chain):
        return out
    fps = float(params.fps)
    counts = ok[layout.chain].sum(axis=1)
    for r in np.flatnonzero(counts < 2).tolist():
        t = (int(chain_coast[r]) + 1) / fps
        for k in layout.chain[r].tolist():
            if ok[k]:
                continue
            hinge = layout.hinges.get(k)
            if hinge is not None and ok[hinge.partner]:
                continue
            v, base = velocity[k], positions[k]
            # the acceleration the marker just had counts with the unknown one: a swinging
            # arm (the walk: ~12 m/s^2 at the wrist) does not coast
            accel = float(np.linalg.norm(v - velocity_before[k])) * fps * fps
            if not (np.all(np.isfinite(base)) and math.isfinite(accel)):
                continue
            if 0.5 * (float(params.limb_accel_m_s2) + accel) * t * t <= float(params.max_extrapolation_m):
                out[k] = base + v
    return out
