"""Re-acquisition: markers lost (or estimated for long) take the unexplained full-frame points of
their colour that fit them (docs/METHOD.md 5.4)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from tracking.labelling.rules import Identifier
from tracking.pipeline.params import TrackerParams
from tracking.pipeline.state import MarkerMemory, Setup
from tracking.reconstruction import CameraObservations, Points3D
from tracking.marker_status import MarkerStatus


def search_now(p: TrackerParams, memory: MarkerMemory, measured: np.ndarray, frame_count: int) -> np.ndarray:
    """(M,) the markers searched in the full frame this frame set: the lost ones every
    ``reacquire_every`` frame sets, those estimated for ``stale_after`` frame sets or more every
    ``reacquire_stale_every``."""
    search = ~measured & (memory.status == MarkerStatus.LOST) & (frame_count % p.reacquire_every == 0)
    if frame_count % p.reacquire_stale_every == 0:
        search |= ~measured & (memory.status == MarkerStatus.ESTIMATED) & (memory.frames_unmeasured >= p.stale_after)
    return search


def reacquire(setup: Setup, p: TrackerParams, memory: MarkerMemory, identifier: Identifier, points: Points3D,
              new_pos: np.ndarray, measured: np.ndarray, search: np.ndarray) -> np.ndarray:
    """Give the markers of ``search`` (lost, or estimated for long) the unexplained full-frame
    points of their colour that fit them.

    A point fits when its distances to the measured markers of the segment (and the near-rigid
    pairs) are the learned ones; with no such neighbour, when it satisfies the marker set's
    distance rules to the measured markers (``Identifier.distance_fit_m``) and is the only
    free point of the colour that does; a lost marker with neither also takes the nearest
    point within ``reacquire_radius_m`` of where it was last seen (still within the rules).
    An estimated marker is only taken on the learned lengths or a unique rule fit (its
    windows already searched near its estimate).

    Returns:
        (M,) int, the point each marker found took, -1 for the others (``new_pos`` and
        ``measured`` are updated in place).
    """
    took = np.full(len(measured), -1)
    if len(points) == 0:
        return took
    p_m = points.p_world_m
    taken = np.zeros(len(points), dtype=bool)
    for m in np.flatnonzero(measured):
        taken |= np.linalg.norm(p_m - new_pos[m], axis=1) < p.taken_radius_m
    last = memory.last_seen
    tol = p.segment_tol_m
    for m in np.flatnonzero(search & ~measured):
        cands = np.flatnonzero(~taken & (points.colour == setup.colour[m]))
        if cands.size == 0:
            continue
        best = -1
        nb = np.flatnonzero(setup.same_segment[m] & measured & np.isfinite(memory.seg_length[m]))
        if nb.size:  # a measured neighbour on the segment: the learned lengths decide
            dev = np.abs(np.linalg.norm(new_pos[nb][None] - p_m[cands][:, None], axis=-1)
                         - memory.seg_length[m, nb][None]).max(axis=1)
            if dev.min() < tol:
                best = int(cands[np.argmin(dev)])
        else:
            fit = identifier.distance_fit_m(m, p_m[cands], new_pos, measured)
            ruled = np.isfinite(fit)  # a rule links the marker to a measured one
            within = ~ruled | (fit >= 0.0)
            if memory.status[m] == MarkerStatus.LOST and np.isfinite(last[m]).all():
                dev = np.where(within, np.linalg.norm(p_m[cands] - last[m], axis=1), np.inf)
                if dev.min() < p.reacquire_radius_m:
                    best = int(cands[np.argmin(dev)])
            fits = cands[ruled & within]
            if best < 0 and len(fits) == 1:
                best = int(fits[0])
        if best >= 0:
            new_pos[m], measured[m], taken[best], took[m] = p_m[best], True, True, best
    return took


def centroids_used(points: Points3D, views: Sequence[CameraObservations], index: np.ndarray) -> np.ndarray:
    """(M, C, 2) the centroids full-frame point ``index[m]`` was triangulated from in each camera
    (``Points3D.obs_index``); NaN where the point used no centroid of that camera or ``index[m]``
    is -1."""
    idx = np.asarray(index, dtype=np.int64)
    out = np.full((len(idx), len(views), 2), np.nan)
    for m in np.flatnonzero(idx >= 0).tolist():
        for c, j in enumerate(points.obs_index[idx[m]].tolist()):
            if j >= 0:
                out[m, c] = views[c].uv_px[j]
    return out
