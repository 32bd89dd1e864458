"""The labelling's per-frame self-checks on the tracked markers (:mod:`tracking.labelling.checks`)
and the joint angles they allow. ``estimator``: the tracker's :class:`tracking.hidden.Estimator`
(passed in: only ``tracking/tracker.py`` imports :mod:`tracking.hidden`)."""

from __future__ import annotations

import logging
import math
from typing import Mapping, Sequence

import numpy as np

from tracking.angles import axis_angles, joint_angles
from tracking.labelling.checks import SelfChecks
from tracking.pipeline.params import TrackerParams
from tracking.pipeline.state import MarkerMemory
from tracking.marker_status import MarkerStatus

log = logging.getLogger(__name__)


def self_check(checks: SelfChecks | None, memory: MarkerMemory, estimator, names: Sequence[str], p: TrackerParams,
               frame_index: int) -> tuple[np.ndarray, str]:
    """A pair of markers found exchanged ``exchange_after`` frame sets running is named back; until
    then, and where the checks cannot tell which pair, the markers are suspect. Returns (suspect
    (M,), reason or "")."""
    m = len(names)
    if checks is None:
        return np.zeros(m, bool), ""
    res = checks.check(memory.positions, names)
    suspect = res.suspect.copy()
    if not res.relabel:
        memory.exchanged_streak = 0
        return suspect, res.reason
    memory.exchanged_streak += 1
    if memory.exchanged_streak < p.exchange_after:
        for i, j in res.relabel:
            suspect[[i, j]] = True
        return suspect, res.reason.replace("named back", "suspect, angles that need them withheld")
    for i, j in res.relabel:
        exchange(memory, estimator, i, j)
    memory.exchanged_streak = 0
    log.warning("self-check at frame %d: %s", frame_index, res.reason)
    return suspect, res.reason


def exchange(memory: MarkerMemory, estimator, i: int, j: int) -> None:
    """Exchange the names of markers i and j (everything the tracker holds about them); the
    hidden-marker estimator starts afresh from the measured markers."""
    for a in (memory.positions, memory.velocity, memory.status, memory.frames_unmeasured, memory.last_seen,
              memory.seen_pos, memory.seen_velocity):
        a[[i, j]] = a[[j, i]]
    memory.seg_length[[i, j]] = memory.seg_length[[j, i]]
    memory.seg_length[:, [i, j]] = memory.seg_length[:, [j, i]]
    measured = memory.status == MarkerStatus.MEASURED
    estimator.reset()
    estimator.update(np.where(measured[:, None], memory.positions, np.nan), measured)


def checked_angles(positions: np.ndarray, suspect: np.ndarray, axis_guessed: np.ndarray,
                   names: Sequence[str], roles: Mapping[str, str] | None = None) -> dict[str, float]:
    """The joint angles, NaN where they need a suspect marker, and no supination where an elbow or
    wrist axis that no measurement pins is a guess."""
    angles = joint_angles(np.where(suspect[:, None], np.nan, positions), names, roles=roles)
    axes = axis_angles() if roles is None else axis_angles(roles)
    for k in np.flatnonzero(axis_guessed).tolist():
        name = axes.get(names[k])
        if name in angles:
            angles[name] = math.nan
    return angles
