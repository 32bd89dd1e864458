"""Naming the seen points with the markers seen by one camera placed on their rays.

A stand-in point checks nothing, so with more than a few markers unseen the names are not given
(wrong poses fitted). A marker seen by one camera lies on the ray through its blob
(:mod:`tracking.labelling.rays`): such a ray is a candidate point of the search, sampled along
its range; a naming puts its markers on rays at the samples that keep the rules best, so the rules
check them too. Two rays of one colour from two cameras that meet are one ball whose second view
is partly hidden, or two balls: both readings are searched and must agree.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from tracking.labelling.body_frame import yaw_from_pairs, yaw_from_points
from tracking.labelling.constraints import RayRows
from tracking.labelling.rays import Rays, sample_ray
from tracking.labelling.search import Found, Pools, RuleSearch, seen_names
from tracking.markerset import MarkerSet

log = logging.getLogger(__name__)


class RayNaming:
    """The rules' naming with unseen markers on single-camera rays.

    Args:
        markerset: the marker set (its balls' radius).
        search: the rules' search.
        max_unseen: at most this many markers neither seen nor on a ray.
    """

    def __init__(self, markerset: MarkerSet, search: RuleSearch, max_unseen: int):
        self.markerset = markerset
        self.search = search
        self.rules = search.constraints.rules
        self.max_unseen = max_unseen

    def name(self, p_seen_m: np.ndarray, col_seen: np.ndarray, deficit: np.ndarray, rays: Rays
             ) -> tuple[Found, np.ndarray] | None:
        """Name the seen points with the unseen markers placed on the rays of single-camera blobs.

        Each ray of an unseen colour is sampled every ``RAY_STEP_M`` over its range, near the
        seen points and not inside a seen ball; a ray is one candidate point of the search (a
        blob is one marker), placed at its best sample (:meth:`RuleSearch.search`). A marker of a colour
        with fewer rays than unseen markers may still take a stand-in point that satisfies every
        rule, at most ``max_unseen`` of them. The names of the seen points are given under the
        same conditions as with stand-ins only (:meth:`RuleSearch.certain`); the markers on rays are left
        for the tracker's re-acquisition (``index`` -1), like the unseen ones.

        Two rays that may be two views of one ball (:meth:`merge_views`) may also be two balls
        whose rays cross: both readings are searched, and the names are given only when one
        reading is certain and every reading that fits the rules at all names the seen points
        the same.

        Returns:
            (the naming, the searched rows after the seen points: -1 each), or None (nothing fits,
            or not beyond doubt: wait; no point seen by two cameras: nothing to place the rays
            near, as when one camera is left).
        """
        if len(p_seen_m) == 0:
            return None
        samples, ray_col, ray_origin, ray_whole = [], [], [], []
        for r in range(len(rays)):
            c = int(rays.colour[r])
            if not 0 <= c < len(deficit) or deficit[c] <= 0:
                continue
            p = sample_ray(rays, r, p_seen_m, self.markerset.radius_m)
            if len(p):
                samples.append(p)
                ray_col.append(c)
                ray_origin.append(rays.origin_m[r])
                ray_whole.append(bool(rays.whole[r]) if rays.whole is not None else False)
        if not samples:
            log.debug("no ray of an unseen colour passes near the seen points")
            return None
        ray_col = np.array(ray_col, np.int64)
        readings = [(samples, ray_col)]
        merged = self.merge_views(samples, ray_col, np.array(ray_origin), np.array(ray_whole))
        if len(merged[0]) < len(samples):
            readings.append(merged)
        named: list[tuple[Found, bool, np.ndarray]] = []
        for candidates, colours in readings:
            attempt = self.search_on_rays(p_seen_m, col_seen, deficit, candidates, colours)
            if attempt is not None:
                named.append(attempt)
        n_seen = len(p_seen_m)
        sure = [a for a in named if a[1]]
        if not sure or any(not np.array_equal(seen_names(a[0], n_seen), seen_names(sure[0][0], n_seen))
                           for a in named):
            return None
        found, _, point_of_row = sure[0]
        return found, point_of_row

    def search_on_rays(self, p_seen_m: np.ndarray, col_seen: np.ndarray, deficit: np.ndarray,
                        samples: list[np.ndarray], ray_col: np.ndarray) -> tuple[Found, bool, np.ndarray] | None:
        """One reading of the rays (:meth:`name`): the best naming, whether it is
        certain, and the rows after the seen points (-1 each); None when no naming fits."""
        n_seen = len(p_seen_m)
        stand_in = np.repeat(np.arange(len(deficit)),
                             np.maximum(deficit - np.bincount(ray_col, minlength=len(deficit)), 0))
        if len(stand_in) > self.max_unseen:
            log.debug("%d markers are neither seen nor on a ray", len(stand_in))
            return None
        first = n_seen + len(stand_in)
        on_rays = RayRows.of(first, samples)
        pts = np.vstack([p_seen_m, np.full((len(stand_in) + len(samples), 3), np.nan)])
        col = np.concatenate([col_seen, stand_in, ray_col]).astype(np.int64)
        # the stand-ins and rays of a colour name at most its unseen markers: every seen point is named
        unseen_rows = np.arange(n_seen, len(pts))
        pools = Pools.of((unseen_rows[col[unseen_rows] == c], int(deficit[c])) for c in np.flatnonzero(deficit > 0))
        limit = math.radians(self.rules.max_turn_deg)
        guess = float(np.clip(yaw_from_points(p_seen_m), -limit, limit))
        self.search.inexact = False
        found = None
        for yaw in dict.fromkeys((guess, 0.0)):
            found = self.search.settle(pts, col, yaw, pools, on_rays)
            if found is not None:
                break
        if found is None:
            log.debug("no naming with markers on rays keeps the rules")
            return None
        certain = (found.nodes <= self.search.max_nodes
                   and abs(yaw_from_pairs(pts, found.index[self.search.constraints.lr_pairs], found.yaw)) <= limit
                   and self.search.certain(pts, col, found, n_seen, pools, on_rays) and not self.search.inexact)
        log.debug("%s with %d markers on single-camera rays, %d unseen (worst margin %.0f mm)",
                  "named" if certain else "not certain", int(np.sum(found.index >= first)), len(stand_in),
                  1000 * self.search.constraints.rule_margins(found.slack_m).min())
        return found, certain, np.full(len(pts) - n_seen, -1)

    def merge_views(self, samples: list[np.ndarray], ray_col: np.ndarray, origin_m: np.ndarray, whole: np.ndarray
                     ) -> tuple[list[np.ndarray], np.ndarray]:
        """Two rays of one colour from two cameras, one of a partly hidden ball, that pass within a
        ball's diameter of each other become one.

        Two cameras that see a ball whose second view is partly hidden give two rays (a point
        needs two whole views): the ball is where they meet, so the pair is one candidate, its
        samples those of either ray near the other. Pairs are taken closest first. Two whole
        views of one ball make a point already, so two rays of whole blobs are two balls.

        Returns:
            (the candidates' samples, their colours).
        """
        reach = 2.0 * self.markerset.radius_m
        near: list[tuple[float, int, int]] = []
        for a in range(len(samples)):
            for b in range(a + 1, len(samples)):
                if (ray_col[a] == ray_col[b] and not (whole[a] and whole[b])
                        and not np.allclose(origin_m[a], origin_m[b])):
                    gap = float(np.linalg.norm(samples[a][:, None, :] - samples[b][None, :, :], axis=-1).min())
                    if gap < reach:
                        near.append((gap, a, b))
        merged: dict[int, np.ndarray] = {}
        gone: set[int] = set()
        for _, a, b in sorted(near):
            if a in gone or b in gone:
                continue
            d = np.linalg.norm(samples[a][:, None, :] - samples[b][None, :, :], axis=-1)
            merged[a] = np.vstack([samples[a][d.min(axis=1) < reach], samples[b][d.min(axis=0) < reach]])
            gone.update((a, b))
        keep = [k for k in range(len(samples)) if k not in gone or k in merged]
        return [merged.get(k, samples[k]) for k in keep], ray_col[keep]

