"""Choosing board views from a moving camera feed for intrinsic calibration.

A person moves the board in front of a camera; the feed gives tens of frames a second, most of
them near-copies of the last or blurred by the motion. :class:`ViewSelector` keeps a frame's
board detection only when

- the board is held still (its corners moved less than ``still_px`` since the previous frame),
  so that the view is sharp; and
- the view is new: its corners reach grid cells of the image that no kept view reached, or the
  board stands in a distinct pose (its corners lie, on average, at least ``min_move`` of the image
  diagonal away from where they were in every kept view: moved, turned, tilted or nearer).

It says when the collection is good enough: at least ``min_views`` views covering at least
``target_coverage`` of the image (:func:`calibration.intrinsics.coverage_of`), or ``max_views``
views whatever the coverage. Pure logic: detections in, decisions out (no camera, no clock).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from calibration.board import Detection
from calibration.errors import CalibrationError
from calibration.intrinsics import COVERAGE_WARN, MIN_VIEWS, coverage_of, empty_regions


@dataclass(frozen=True, slots=True)
class SelectorProgress:
    """Where a collection stands.

    Attributes:
        n_views: views kept.
        coverage: share 0..1 of the image grid cells that kept views reached.
        done: enough views with enough coverage (or the maximum reached).
        hint: where to move the board next, in plain words.
    """

    n_views: int
    coverage: float
    done: bool
    hint: str


def coverage_hint(views: Sequence[Detection], size_px: tuple[int, int]) -> str:
    """Where to move the board next, in plain words."""
    if not views:
        return "Hold the whole board in front of the camera"
    fraction, hit = coverage_of(views, size_px)
    empty = empty_regions(hit)
    if empty:
        first = empty.split(", ")[0]
        where = "the centre" if first == "centre" else f"the {first} {'edge' if first in ('top', 'bottom', 'left', 'right') else 'corner'}"
        return f"Move the board into {where} of the picture"
    if fraction < COVERAGE_WARN:
        return "Move the board closer to the edges of the picture"
    return "Good coverage: tilt the board a little differently for each view"


def _common_shift_px(a: Detection, b: Detection) -> float | None:
    """Mean distance (pixels) between the corners two detections share; None if they share fewer than 4."""
    if a.ids is None and b.ids is None:
        return float(np.mean(np.linalg.norm(a.uv_px - b.uv_px, axis=1))) if len(a.uv_px) == len(b.uv_px) else None
    ids_a = np.arange(len(a.uv_px)) if a.ids is None else a.ids
    ids_b = np.arange(len(b.uv_px)) if b.ids is None else b.ids
    common, ia, ib = np.intersect1d(ids_a, ids_b, assume_unique=True, return_indices=True)
    if len(common) < 4:
        return None
    return float(np.mean(np.linalg.norm(a.uv_px[ia] - b.uv_px[ib], axis=1)))


class ViewSelector:
    """Keeps the distinct, still board views of one camera's feed (module docstring).

    Args:
        size_px: (width, height) of the camera's images.
        min_views: views needed at least (>= 4, OpenCV's minimum).
        target_coverage: image share 0..1 the kept views must reach.
        max_views: stop after this many views whatever the coverage.
        min_move: a new pose moves the corners by this share of the image diagonal from every kept view.
        still_px: the board counts as held still when its corners moved less than this (mean,
            pixels) since the previous frame; None: no stillness check (still images).
    """

    def __init__(self, size_px: tuple[int, int], *, min_views: int = 12, target_coverage: float = 0.85,
                 max_views: int = 30, min_move: float = 0.08, still_px: float | None = 2.0) -> None:
        if min_views < MIN_VIEWS or max_views < min_views:
            raise CalibrationError(f"views wanted {min_views}..{max_views}: give at least {MIN_VIEWS} and a maximum above the minimum")
        if not 0.0 < target_coverage <= 1.0:
            raise CalibrationError(f"target coverage {target_coverage}: give a share between 0 and 1, e.g. 0.85")
        self.size_px = (int(size_px[0]), int(size_px[1]))
        self.min_views = int(min_views)
        self.target_coverage = float(target_coverage)
        self.max_views = int(max_views)
        self.min_move_px = float(min_move) * float(np.hypot(*self.size_px))
        self.still_px = still_px
        self.views: list[Detection] = []
        self._previous: Detection | None = None

    def offer(self, detection: Detection | None) -> bool:
        """Consider one frame's detection (None: no board in that frame). Returns whether it was kept."""
        previous, self._previous = self._previous, detection
        if detection is None or self.progress().done:
            return False
        if detection.size_px != self.size_px:
            raise CalibrationError(f"a {detection.size_px[0]}x{detection.size_px[1]} image from a "
                                   f"{self.size_px[0]}x{self.size_px[1]} camera: keep one camera setting")
        if self.still_px is not None:
            if previous is None:
                return False
            shift = _common_shift_px(detection, previous)
            if shift is None or shift > self.still_px:
                return False
        if not self._is_new(detection):
            return False
        self.views.append(detection)
        return True

    def _is_new(self, detection: Detection) -> bool:
        if not self.views:
            return True
        _, hit_before = coverage_of(self.views, self.size_px)
        _, hit_with = coverage_of([detection], self.size_px)
        if np.any(hit_with & ~hit_before):
            return True
        for view in self.views:
            shift = _common_shift_px(detection, view)
            if shift is not None and shift < self.min_move_px:
                return False
        return True

    def progress(self) -> SelectorProgress:
        coverage = coverage_of(self.views, self.size_px)[0] if self.views else 0.0
        n = len(self.views)
        done = n >= self.max_views or (n >= self.min_views and coverage >= self.target_coverage)
        return SelectorProgress(n, coverage, done, coverage_hint(self.views, self.size_px))
