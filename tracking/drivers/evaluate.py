"""Accuracy of measured 3D points against the simulator's ground truth.

Definitions used in the docs and acceptance figures:

- a marker is *seen* by a camera when at least ``seen_fraction`` (75 %) of its ball's disc is
  visible there (the simulator's per-camera visibility). A ball hidden by more than a quarter
  gives a blob whose centroid is shifted by a large fraction of its radius; such views are used
  when other cameras confirm them, but a point is not owed from them. Nor is it owed from a
  camera in which the ball's disc touches that of another ball of the same colour: one merged
  blob is a view of neither;
- a measured point *matches* the nearest true marker if it is within ``match_m`` (20 mm);
  a point matching no marker is a *ghost*;
- *completeness*: the fraction of (frame, marker) pairs seen by two or more cameras that have a
  matching point;
- *RMSE*: over all matched points, the 3D distance to the true ball centre.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np


@dataclass(frozen=True, slots=True)
class PointAccuracy:
    frames: int
    markers_seen2: int
    markers_found: int
    rmse_mm: float
    p95_mm: float
    max_mm: float
    ghost_points: int
    ghost_frames: int

    @property
    def completeness(self) -> float:
        return self.markers_found / max(self.markers_seen2, 1)

    @property
    def ghost_frame_fraction(self) -> float:
        return self.ghost_frames / max(self.frames, 1)

    def summary(self) -> str:
        return (
            f"{self.frames} frames: {100 * self.completeness:.2f} % of markers seen by >= 2 cameras measured "
            f"({self.markers_found}/{self.markers_seen2}), RMSE {self.rmse_mm:.2f} mm "
            f"(p95 {self.p95_mm:.2f}, max {self.max_mm:.1f}), ghosts in {100 * self.ghost_frame_fraction:.2f} % "
            f"of frames ({self.ghost_points} points)"
        )


def evaluate_points(
    points_m: Sequence[np.ndarray],
    truth_m: np.ndarray,
    visible_fraction: np.ndarray,
    merged: np.ndarray | None = None,
    *,
    seen_fraction: float = 0.75,
    match_m: float = 0.020,
) -> PointAccuracy:
    """Compare unlabelled points with the true markers frame by frame.

    Args:
        points_m: per frame, (P, 3) measured points in world metres.
        truth_m: (T, M, 3) true marker centres.
        visible_fraction: (T, C, M) visible fraction of each marker in each camera.
        merged: (T, C, M) bool, marker merged with a same-coloured one in that camera (optional).
    """
    errs: list[float] = []
    seen2 = found = ghosts = ghost_frames = 0
    for t, pts in enumerate(points_m):
        true = truth_m[t]
        views = visible_fraction[t] >= seen_fraction
        if merged is not None:
            views &= ~merged[t]
        seen = views.sum(axis=0) >= 2
        seen2 += int(seen.sum())
        if len(pts) == 0:
            continue
        d = np.linalg.norm(pts[:, None, :] - true[None, :, :], axis=-1)  # (P, M)
        nearest = d.min(axis=1)
        g = int((nearest > match_m).sum())
        ghosts += g
        ghost_frames += int(g > 0)
        ok = nearest <= match_m
        errs.extend(nearest[ok].tolist())
        covered = (d <= match_m).any(axis=0)
        found += int((covered & seen).sum())
    e = np.asarray(errs) * 1000.0
    return PointAccuracy(
        frames=len(points_m),
        markers_seen2=seen2,
        markers_found=found,
        rmse_mm=float(np.sqrt(np.mean(e**2))) if e.size else float("nan"),
        p95_mm=float(np.percentile(e, 95)) if e.size else float("nan"),
        max_mm=float(e.max()) if e.size else float("nan"),
        ghost_points=ghosts,
        ghost_frames=ghost_frames,
    )
