"""Markers taken off and put on again: a placement error that moves with the body part.

Every time a therapist puts the markers on, each ball lands a little off its landmark. Here that
error is drawn once per donning (one seed) as a shift along the skin of up to
:data:`MAX_PLACEMENT_M` in a random direction, and kept in the frame of the body part that
carries the marker (trunk, upper arm, forearm), so that it turns with the arm through the whole
motion, as a ball stuck to the skin does. The population draws of :mod:`tracking.sim.population`
shift markers by the same amount but fixed in the world, which only holds for one pose.

:class:`RedonnedBody` wraps a :class:`tracking.sim.body.BodyModel` (its ``markers_m`` and
``scene``); :func:`redon` puts one on a :class:`tracking.sim.studio.Studio`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tracking.markerset import MarkerSet
from tracking.sim.body import BodyModel, Pose

#: the largest shift of a ball along the skin at one donning (metres), as in the population draws
MAX_PLACEMENT_M = 0.015

#: the smallest gap between two balls' surfaces at a donning (as the population draws)
MIN_GAP_M = 0.005

_ARM_SEGMENTS = {"upper_arm": ("gh", "elbow"), "forearm": ("elbow", "wrist")}


def _min_gap_m(p: np.ndarray) -> float:
    """The smallest distance between two of the (M, 3) centres."""
    gap = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(len(p)) * 1e9
    return float(gap.min())


def _segment_of(markerset: MarkerSet, k: int) -> tuple[str, str]:
    """(side or "", part) of marker ``k``: part is ``upper_arm``, ``forearm`` or ``trunk``."""
    segment = markerset.segments[k]
    for side in ("right", "left"):
        for part in _ARM_SEGMENTS:
            if segment == f"{side}_{part}":
                return side, part
    return "", "trunk"   # trunk, shoulders (acromion on the girdle), pelvis: carried by the trunk


class RedonnedBody:
    """A body model whose markers sit where one donning put them.

    Args:
        body: the patient's body model.
        seed: the donning (each seed puts every marker on again).
        max_m: the largest shift along the skin.

    The shift of each marker is ``a * t1 + b * t2`` with ``t1``, ``t2`` the skin's tangent
    directions at its landmark: ``t1`` the carrying part's long axis (or, where that is nearly
    along the skin normal, its forward axis) made perpendicular to the normal, ``t2 = n x t1``.
    ``(a, b)`` is drawn once: a uniform direction and a length uniform in ``[0, max_m]``; a
    placement where two balls would overlap (closer than :data:`MIN_GAP_M` in the neutral pose)
    is drawn again.
    Everything else is delegated to ``body``.
    """

    def __init__(self, body: BodyModel, seed: int, max_m: float = MAX_PLACEMENT_M) -> None:
        self._body = body
        ms = body.markerset
        self._parts = [_segment_of(ms, k) for k in range(ms.n_markers)]
        self._use_forward = np.zeros(ms.n_markers, dtype=bool)
        # the axis is chosen once, in the neutral pose, so that it never switches during a motion
        _, normal = body.landmarks_m(Pose())
        axes = self._long_axes(Pose())
        self._use_forward = np.abs(np.sum(axes * normal, axis=1)) > 0.8
        rng = np.random.default_rng([seed, 0x5EDD0])
        for _ in range(100):   # balls cannot overlap: such a placement is drawn again (as in the population)
            angle = rng.uniform(0.0, 2.0 * np.pi, ms.n_markers)
            length = rng.uniform(0.0, max_m, ms.n_markers)
            self.shift_ab_m = np.stack([length * np.cos(angle), length * np.sin(angle)], axis=1)
            if _min_gap_m(self.markers_m(Pose())) > 2.0 * ms.radius_m + MIN_GAP_M:
                break
        else:
            raise RuntimeError(f"no placement without overlapping balls in 100 draws of seed {seed}")

    def __getattr__(self, name: str):
        return getattr(self._body, name)

    def _long_axes(self, pose: Pose) -> np.ndarray:
        """(M, 3) unit axis of each marker's carrying part (trunk: up, or forward where up is
        nearly the skin normal, e.g. on the acromion)."""
        rt = self._body.trunk_rotation(pose)
        centres = {side: self._body.joint_centres_m(pose, side) for side in ("right", "left")}
        out = np.empty((len(self._parts), 3))
        for k, (side, part) in enumerate(self._parts):
            if part == "trunk":
                axis = rt[:, 2] if self._use_forward[k] else rt[:, 1]
            else:
                a, b = _ARM_SEGMENTS[part]
                axis = centres[side][b] - centres[side][a]   # across the skin normal there by construction
            out[k] = axis / np.linalg.norm(axis)
        return out

    def offsets_m(self, pose: Pose) -> np.ndarray:
        """(M, 3) each marker's shift off its landmark in ``pose``, world metres."""
        _, n = self._body.landmarks_m(pose)
        axis = self._long_axes(pose)
        t1 = axis - np.sum(axis * n, axis=1, keepdims=True) * n
        t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
        t2 = np.cross(n, t1)
        return self.shift_ab_m[:, :1] * t1 + self.shift_ab_m[:, 1:] * t2

    def markers_m(self, pose: Pose) -> np.ndarray:
        """(M, 3) marker centres of this donning, world metres."""
        return self._body.markers_m(pose) + self.offsets_m(pose)

    def scene(self, pose: Pose):
        """The body's render primitives with the marker balls of this donning."""
        scene = self._body.scene(pose)
        index = scene.sphere_marker_index
        centres = np.array(scene.sphere_centre_m, dtype=np.float64, copy=True)
        is_marker = index >= 0
        centres[is_marker] += self.offsets_m(pose)[index[is_marker]]
        return dataclasses.replace(scene, sphere_centre_m=centres)


def redon(studio, seed: int, max_m: float = MAX_PLACEMENT_M) -> RedonnedBody:
    """Put the markers of ``studio``'s patient on again (donning ``seed``); returns the new body."""
    base = studio.body._body if isinstance(studio.body, RedonnedBody) else studio.body
    studio.body = RedonnedBody(base, seed, max_m)
    return studio.body
