"""The markers without a point placed on the rays of blobs that a single camera sees.

A marker without a point, of a colour with rays (:func:`tracking.labelling.rays.single_view_rays`),
lies on one of them, within the range its blob's size gives. The labellings found with those
markers unseen (their score a lower bound) are placed on the rays best first, each at the ray
samples that score best (:meth:`RayPlacement.place`), until no other labelling can come within
the margin of the best. A ray that no marker explains puts a labelling beyond reach.
"""

from __future__ import annotations

import logging
import math
from itertools import permutations, product

import numpy as np

from tracking.labelling.body_score import BodyScore
from tracking.labelling.parts import MAX_NEAR, bound
from tracking.labelling.rays import sample_ray

log = logging.getLogger(__name__)

# at most this many assignments of markers to rays per labelling; two markers' samples are placed
# jointly up to this many pairs, more by this many sweeps
_MAX_ASSIGN = 48
_MAX_JOINT = 1500
# with a coarser grid of sample pairs, every sample around this many best is tried
_REFINE = 3
_SWEEPS = 2


def ray_samples(pts: np.ndarray, short: np.ndarray, rays, radius_m: float
                ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The candidate places of the balls seen by one camera: each ray of a colour short of
    points sampled over the range its blob's size gives (:func:`tracking.labelling.rays.sample_ray`).

    Returns:
        (each kept ray's (S, 3) samples, (R,) each kept ray's colour, (R, 3) its direction).
    """

    out, colours, dirs = [], [], []
    if rays is not None and len(pts):
        for k in range(len(rays)):
            c = int(rays.colour[k])
            if 0 <= c < len(short) and short[c] > 0:
                p = sample_ray(rays, k, pts, radius_m)
                if len(p):
                    out.append(p)
                    colours.append(c)
                    dirs.append(rays.direction[k])
    return out, np.array(colours, np.int64), np.array(dirs, np.float64).reshape(-1, 3)


class RayPlacement:
    """The rays of one search, in its patient frame, and the placing of markers on them.

    Args:
        body: the body model's terms and costs.
        colour: (M,) palette index of each marker.
        reach, min_margin: as :class:`tracking.labelling.parts.PartSearch`'s.
        radius_m: the balls' radius.
        on: each ray's (S, 3) samples in the patient frame.
        lines: (R, 3) each ray's origin, (R, 3) its direction, (R,) its colour, (R,) whether a
            point explains it (passes within a ball's diameter of it).
        free: (n colours,) markers of a colour that may be unseen (neither a point nor a ray).
    """

    def __init__(self, body: BodyScore, colour: np.ndarray, reach: float, min_margin: float, radius_m: float,
                 on: list[np.ndarray], lines: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                 free: np.ndarray):
        self.body, self.colour, self.reach, self.min_margin, self.radius_m = body, colour, reach, min_margin, radius_m
        self.on, self.lines, self.free = on, lines, free

    @classmethod
    def in_frame(cls, body: BodyScore, colour: np.ndarray, reach: float, min_margin: float, radius_m: float,
                 q_points: np.ndarray, col: np.ndarray, centre: np.ndarray, axes: np.ndarray,
                 samples: list[np.ndarray], ray_dir: np.ndarray, ray_col: np.ndarray, free: np.ndarray
                 ) -> "RayPlacement":
        """The rays' ``samples`` (world) and directions in the patient frame of ``centre`` and
        ``axes``, and which of them the points ``q_points`` (patient frame, colours ``col``) explain."""
        on = [(s - centre) @ axes for s in samples]
        origin, direction = np.array([o[0] for o in on]), ray_dir @ axes
        rel = q_points[:, None, :] - origin[None]
        off = np.linalg.norm(rel - np.einsum("pri,ri->pr", rel, direction)[..., None] * direction[None], axis=-1)
        by_point = ((off < 2.0 * radius_m) & (col[:, None] == ray_col[None])).any(axis=0)
        return cls(body, colour, reach, min_margin, radius_m, on, (origin, direction, ray_col, by_point), free)

    def _bound(self, out: list[tuple[float, np.ndarray, np.ndarray]]) -> float:
        return bound([o[:2] for o in out], self.reach, self.min_margin)

    def place_all(self, q: np.ndarray, bounds: list[tuple[float, np.ndarray]], kind: np.ndarray, cut: float
                  ) -> list:
        """The labellings of ``bounds`` (lower bounds, best first) with their markers without a
        point placed on rays (:meth:`place`), within a margin of the best: (score, rows, (M, 3)
        positions), best first. A labelling that no placement keeps within reach is dropped.
        ``cut``: the search looked at no labelling scoring more (without rays); when the margin
        of the best reaches past it, labellings not looked at could be near: none (not confident)."""
        out: list[tuple[float, np.ndarray, np.ndarray]] = []
        for lb, rows in bounds:
            if lb > self._bound(out):
                break
            placed = self.place(q[rows], np.flatnonzero(kind[rows] != 0), lb)
            if placed is None or placed[0] > self._bound(out):
                continue
            out.append((placed[0], rows, placed[1]))
            out.sort(key=lambda o: o[0])
            b = self._bound(out)
            out = [o for o in out if o[0] <= b]
            if len(out) > MAX_NEAR:
                return []
        if out and self._bound(out) > cut + 1e-9:
            log.debug("the labellings without rays were cut at %.1f: not confident", cut)
            return []
        return out

    def place(self, p: np.ndarray, without: np.ndarray, lower: float) -> tuple[float, np.ndarray] | None:
        """The best score of one labelling ((M, 3) patient-frame positions, NaN at the markers
        ``without`` a point) with each of those markers on its own ray of its colour (or unseen,
        at most ``free`` of a colour), at the ray's sample that scores best: every assignment of
        markers to rays, the samples of two markers jointly, of more by turns (two sweeps from
        each one's best alone; two markers' pairs beyond ``_MAX_JOINT`` on a coarser grid first,
        then every pair around the best few). Returns (score, positions) or None. With more than
        ``_MAX_ASSIGN`` assignments: ``lower`` (its score without them) and the positions
        without them, so that it counts as near as it might be."""

        on, ray_col = self.on, self.lines[2]
        by_colour: dict[int, list[int]] = {}
        for m in without.tolist():
            by_colour.setdefault(int(self.colour[m]), []).append(m)
        per_colour = []
        for c, ms in by_colour.items():
            rays_c = np.flatnonzero(ray_col == c).tolist() + [-1] * int(self.free[c])
            per_colour.append([(ms, pick) for pick in dict.fromkeys(permutations(rays_c, len(ms)))])
        best: tuple[float, np.ndarray] | None = None
        n_done = 0
        # the assignments of at most two markers on rays: every sample (pair) in one batch, every
        # ``stride``-th where the pairs are too many, then every sample around the best few
        grids, where, many = [], [], []
        for combo in product(*per_colour):
            n_done += 1
            if n_done > _MAX_ASSIGN:
                return lower, p
            placed = [(m, r) for ms, pick in combo for m, r in zip(ms, pick) if r >= 0]
            if len(placed) > 2:
                many.append(placed)
                continue
            size = math.prod(len(on[r]) for _, r in placed)
            stride = max(1, math.ceil(math.sqrt(size / _MAX_JOINT))) if len(placed) == 2 else 1
            idx = [np.arange(0, len(on[r]), stride) for _, r in placed]
            grids.append(self._grid(p, placed, on, idx))
            where.append((placed, stride, idx))
        # more than two markers on rays: by turns, every assignment of the same markers in one batch
        for score, pos in self._best_samples_many(p, many):
            if best is None or score < best[0]:
                best = (score, pos)
        if grids:
            best = self._best_on_grids(p, grids, where, [(m, -1) for m in without.tolist()], best)
        return best

    def _best_on_grids(self, p: np.ndarray, grids: list[np.ndarray], where: list, everyone: list[tuple[int, int]],
                       best: tuple[float, np.ndarray] | None) -> tuple[float, np.ndarray]:
        """The best of ``best`` and the assignments of at most two markers on rays: ``grids`` each
        assignment's (N, M, 3) positions at every ``stride``-th sample (``where``: its (markers,
        rays), stride and samples), then around the best few of a coarser grid every sample."""
        on = self.on
        lens = [len(g) for g in grids]
        sc = np.concatenate([self.objective(g, everyone) for g in grids])
        starts = np.cumsum([0] + lens)
        for k in np.argsort(sc)[:_REFINE].tolist():
            g = int(np.searchsorted(starts, k, side="right") - 1)
            if best is None or sc[k] < best[0]:
                best = (float(sc[k]), grids[g][k - starts[g]])
            placed, stride, idx = where[g]
            if stride == 1:
                continue
            # (row k - start of the grid) -> the sample of each marker, then every sample near
            at = np.unravel_index(k - starts[g], [len(i) for i in idx])
            near = [np.arange(max(int(i[j]) - stride + 1, 0), min(int(i[j]) + stride, len(on[r])))
                    for i, j, (_, r) in zip(idx, at, placed)]
            fine = self._grid(p, placed, on, near)
            fs = self.objective(fine, everyone)
            j = int(np.argmin(fs))
            if fs[j] < best[0]:
                best = (float(fs[j]), fine[j])
        return best

    @staticmethod
    def _grid(p: np.ndarray, placed: list[tuple[int, int]], on: list[np.ndarray], idx: list[np.ndarray]
              ) -> np.ndarray:
        """(N, M, 3) positions ``p`` with each marker placed at every combination of the samples
        ``idx`` of its ray."""
        size = math.prod(len(i) for i in idx)
        batch = np.repeat(p[None], size, axis=0)
        if placed:
            grid = np.meshgrid(*idx, indexing="ij")
            for (m, r), g in zip(placed, grid):
                batch[:, m] = on[r][g.ravel()]
        return batch

    def objective(self, p: np.ndarray, placed: list[tuple[int, int]]) -> np.ndarray:
        """(N,) the scores of a batch of positions ((N, M, 3)) with markers ``placed`` on rays,
        plus ``reach`` for every ray that neither a point nor a marker on a ray explains (passes
        within a ball's diameter of): a blob is a ball of its colour, and a labelling that leaves
        one without a marker does not explain what the cameras see (the two rays of one ball seen
        whole by one camera and partly hidden by another meet at the ball: one marker explains
        both). Stray blobs (clutter) leave every labelling beyond reach: nothing is named."""
        score = self.body.scores(p)
        origin, direction, colour, by_point = self.lines
        if not len(colour):
            return score
        explained = np.repeat(by_point[None], len(p), axis=0)
        for m, _ in placed:  # (a marker left unseen, NaN, explains nothing)
            rel = p[:, m, None, :] - origin[None]                       # (N, R, 3)
            along = np.einsum("nri,ri->nr", rel, direction)
            off = np.linalg.norm(rel - along[..., None] * direction[None], axis=-1)
            explained |= (off < 2.0 * self.radius_m) & (colour[None] == self.colour[m])
        return score + self.reach * (~explained).sum(axis=1)

    def _best_samples_many(self, p: np.ndarray, many: list[list[tuple[int, int]]]
                           ) -> list[tuple[float, np.ndarray]]:
        """The markers of each assignment in ``many`` (more than two markers on rays each, in their
        order) at their rays' best samples: each alone (the others without a point), then by
        turns (``_SWEEPS``): (score, positions) each. The assignments that place the same markers
        go through their turns together, each turn one scoring batch for all of them (the scores
        of a batch's rows are independent of each other), instead of one batch per assignment
        and turn (thousands of small batches for four to six markers on rays, seconds per frame
        set)."""
        on = self.on
        out: list[tuple[float, np.ndarray] | None] = [None] * len(many)
        groups: dict[tuple[int, ...], list[int]] = {}
        for i, placed in enumerate(many):
            groups.setdefault(tuple(m for m, _ in placed), []).append(i)
        for markers, items in groups.items():
            placed0 = many[items[0]]
            pos = np.repeat(p[None], len(items), axis=0)            # (A, M, 3) each assignment's
            rays = np.array([[r for _, r in many[i]] for i in items])   # (A, k)

            def turn(j: int) -> np.ndarray:
                """Marker j of every assignment at its best sample, the others where they are;
                (A,) the scores."""
                m = markers[j]
                lens = [len(on[r]) for r in rays[:, j]]
                batch = np.repeat(pos, lens, axis=0)
                batch[:, m] = np.concatenate([on[r] for r in rays[:, j]])
                sc = self.objective(batch, placed0)
                starts = np.concatenate([[0], np.cumsum(lens)[:-1]])
                k = np.array([s0 + int(np.argmin(sc[s0:s0 + n])) for s0, n in zip(starts, lens)])
                pos[:] = batch[k]
                return sc[k]

            for j in range(len(markers)):
                turn(j)
            score = self.objective(pos, placed0)
            for _ in range(_SWEEPS):
                for j in range(len(markers)):
                    score = turn(j)
            for a, i in enumerate(items):
                out[i] = (float(score[a]), pos[a].copy())
        return out
