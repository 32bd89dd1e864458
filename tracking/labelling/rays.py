"""Markers seen by one camera only: the ray through the blob, and the range along it the blob's size gives.

A ball seen by one camera gets no 3D point, but it is not unknown: it lies on the ray through its
blob, at a distance that its blob's size bounds. The rules' search and the fit both place such
markers on their rays (sampled every ``RAY_STEP_M``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from calibration.camera import Camera
from tracking.reconstruction import CameraObservations, Points3D

# a marker seen by one camera lies on the ray through its blob, between these multiples of the
# distance that the blob's size gives: a whole (round) blob gives it within a few per cent, a
# partly hidden ball looks smaller, so farther (measured 0.98-1.03 times it for blobs of roundness
# 0.88 or more, 0.68-0.92 below, in the sweep's layouts)
RAY_NEAR_WHOLE, RAY_FAR_WHOLE, RAY_NEAR, RAY_FAR = 0.92, 1.08, 0.55, 1.08
ROUND_BLOB = 0.9
# points along a ray are tried this far apart, within this margin around the seen points
RAY_STEP_M = 0.015
RAY_BOX_M = 0.4


@dataclass(frozen=True, slots=True)
class Rays:
    """Blobs that no 3D point uses: a marker seen by one camera only lies on the ray through its blob.

    Attributes:
        origin_m: (R, 3) float64 optical centre of the blob's camera, world metres.
        direction: (R, 3) float64 unit direction of the ray through the blob's centroid, world.
        colour: (R,) int64 palette index of the blob.
        range_m: (R, 2) float64 nearest and farthest distance of the ball's centre along the ray.
        whole: (R,) bool the blob is round (the ball not partly hidden); None: not known (taken as not).
    """

    origin_m: np.ndarray
    direction: np.ndarray
    colour: np.ndarray
    range_m: np.ndarray
    whole: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.colour.shape[0])


def single_view_rays(cameras: Sequence[Camera], observations: Sequence[CameraObservations], points: Points3D,
                     radius_m: float) -> Rays:
    """The rays of the blobs that no 3D point uses (markers seen by one camera only).

    A blob whose ray passes within a ball radius of a point of its colour is taken for that
    point's view (a partly hidden view the triangulation left out) and gives no ray. The range
    along the ray comes from the blob's size (``r_px = f R / distance``), widened towards the
    camera for a blob that is not round (a partly hidden ball: smaller, so it looks farther).

    Args:
        cameras: the calibrated cameras, in the order of ``observations``.
        observations: one frame's centroids of each camera.
        points: the 3D points measured from them (``obs_index`` says which centroids they use).
        radius_m: the marker balls' radius.
    """
    origin, direction, colour, rng, whole = [], [], [], [], []
    for c, (cam, obs) in enumerate(zip(cameras, observations)):
        free = np.ones(len(obs.colour), bool)
        used = points.obs_index[:, c] if len(points) else np.zeros(0, np.int64)
        free[used[used >= 0]] = False
        free &= np.isfinite(obs.radius_px) & (obs.radius_px > 0)
        k = np.flatnonzero(free)
        if not len(k):
            continue
        centre, d = cam.back_project(obs.uv_px[k])
        rel = points.p_world_m - centre
        along = rel @ d.T  # (P, N)
        off = np.linalg.norm(rel[:, None, :] - along[..., None] * d[None], axis=-1)
        same = (points.colour[:, None] == obs.colour[k][None, :]) & (off < radius_m) & (along > 0)
        keep = ~same.any(axis=0)
        focal = 0.5 * (cam.K[0, 0] + cam.K[1, 1])
        # the blob's size gives the depth along the optical axis; the ray is longer off-axis
        dist = focal * radius_m / obs.radius_px[k] / np.maximum(d @ cam.R[2], 1e-3)
        origin.append(np.broadcast_to(centre, (int(keep.sum()), 3)))
        direction.append(d[keep])
        colour.append(np.asarray(obs.colour)[k][keep])
        round_ = obs.roundness[k] >= ROUND_BLOB if obs.roundness is not None else np.zeros(len(k), bool)
        near = np.where(round_, RAY_NEAR_WHOLE, RAY_NEAR)
        far = np.where(round_, RAY_FAR_WHOLE, RAY_FAR)
        rng.append(np.stack([near[keep] * dist[keep], far[keep] * dist[keep]], axis=1))
        whole.append(round_[keep])
    if not colour:
        return Rays(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0, bool))
    return Rays(np.concatenate(origin).astype(np.float64), np.concatenate(direction), np.concatenate(colour).astype(np.int64),
                np.concatenate(rng), np.concatenate(whole))


def sample_ray(rays: Rays, r: int, p_seen_m: np.ndarray, radius_m: float) -> np.ndarray:
    """(S, 3) the places of ray ``r``'s ball to try: every ``RAY_STEP_M`` over its range, within
    ``RAY_BOX_M`` of the seen points' box and not inside a seen ball (two balls do not overlap)."""
    lo, hi = p_seen_m.min(axis=0) - RAY_BOX_M, p_seen_m.max(axis=0) + RAY_BOX_M
    near, far = rays.range_m[r]
    t = np.arange(near, far + 0.5 * RAY_STEP_M, RAY_STEP_M)
    p = rays.origin_m[r] + t[:, None] * rays.direction[r]
    ok = ((p >= lo) & (p <= hi)).all(axis=1)
    ok &= np.linalg.norm(p[:, None, :] - p_seen_m[None], axis=-1).min(axis=1) > 2.0 * radius_m - RAY_STEP_M
    return p[ok]

