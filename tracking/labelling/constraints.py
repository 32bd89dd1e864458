"""The marker set's identification rules compiled into pairwise constraints, and their slacks.

Every rule is a set of pairwise constraints on two markers: an ordering
``sign * (c_b - c_a) >= min_margin`` on one patient-frame coordinate, or a distance range
``lo <= |p_b - p_a| <= hi`` (markers on one bone; these keep a wrong pose, or points all of one
colour, from being "explained" by swapping markers between body parts). A constraint's slack is
by how much it holds (metres, negative: broken); an unseen marker's stand-in point (NaN) satisfies
every constraint.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from tracking.markerset import IdentificationRules, MarkerSet, OrderRule


@dataclass(frozen=True, slots=True)
class RayRows:
    """Rays as points of a search: the searched points from ``first`` on (NaN rows) are rays,
    ray k sampled at ``samples[k]``; in the extended points (the rows before ``first``, then every
    sample) ray k's samples are the rows ``starts[first + k]`` on."""

    first: int
    samples: tuple[np.ndarray, ...]
    starts: np.ndarray
    key: bytes

    @staticmethod
    def of(first: int, samples: Sequence[np.ndarray]) -> "RayRows":
        counts = [len(p) for p in samples]
        starts = np.concatenate([np.arange(first), first + np.cumsum([0] + counts[:-1])]).astype(np.int64)
        return RayRows(first, tuple(samples), starts, b"".join(p.tobytes() for p in samples))

    def rows(self, point: int) -> np.ndarray:
        """Rows of the extended points of the ray that is searched point ``point``."""
        k = point - self.first
        return self.starts[point] + np.arange(len(self.samples[k]))


@dataclass(frozen=True, slots=True)
class Blocks:
    """Pair slacks over many points, kept only where a pair's markers' colours are.

    Attributes:
        block: per marker pair (i, j), (points of i's colour, points of j's colour) worst slack.
        loc: (E,) position of each point among the points of its colour.
    """

    block: list[np.ndarray]
    loc: np.ndarray

    def get(self, pair: int, p, q) -> np.ndarray:
        """Slack of ``pair`` with its first marker at point(s) ``p``, its second at ``q``."""
        return self.block[pair][self.loc[p], self.loc[q]]



class Constraints:
    """The pairwise constraints of a marker set's rules, ready for many frames.

    Args:
        markerset: the marker set (names, colours).
        rules: its identification rules.
        n_colours: the palette's size.
    """

    def __init__(self, markerset: MarkerSet, rules: IdentificationRules, n_colours: int):
        self.rules = rules
        self.n_colours = n_colours
        self.colour = np.asarray(markerset.colour_index, dtype=np.int64)
        idx = {n: i for i, n in enumerate(markerset.names)}
        # one row per pairwise constraint: markers a, b; rule; ordering (axis, sign, margin) or
        # distance range (lo, hi)
        rows = []
        for r_i, r in enumerate(rules.rules):
            links = zip(r.groups[:-1], r.groups[1:]) if isinstance(r, OrderRule) else [r.groups]
            for lo_group, hi_group in links:
                for na in lo_group:
                    for nb in hi_group:
                        if isinstance(r, OrderRule):
                            rows.append((idx[na], idx[nb], r_i, False, r.axis, r.sign, r.min_margin_m, 0.0, 0.0))
                        else:
                            rows.append((idx[na], idx[nb], r_i, True, 0, 1, 0.0, r.min_m, r.max_m))
        cols = list(zip(*rows))
        self.c_a, self.c_b, self.c_rule = (np.array(c, np.int64) for c in cols[:3])
        self.c_dist = np.array(cols[3], bool)
        self.c_axis = np.array(cols[4], np.int64)
        self.c_sign, self.c_margin, self.c_lo, self.c_hi = (np.array(c, np.float64) for c in cols[5:])
        orders = self.c_margin[~self.c_dist]
        self.min_order_margin_m = float(orders.min()) if orders.size else 0.0
        # unordered marker pairs (i < j) with at least one constraint, and which constraints
        lo_hi = np.sort(np.stack([self.c_a, self.c_b], axis=1), axis=1)
        self.pairs, self.c_pair = np.unique(lo_hi, axis=0, return_inverse=True)
        self.c_pair = self.c_pair.reshape(-1)
        self.c_flip = self.c_a > self.c_b  # constraint written as (j, i) of its pair (i, j)
        self.by_pair = np.argsort(self.c_pair, kind="stable")
        self.pair_starts = np.searchsorted(self.c_pair[self.by_pair], np.arange(len(self.pairs)))
        self.lr_pairs = np.array([(idx[l], idx[r]) for l, r in rules.left_right_pairs], np.int64)
        self.neighbours: list[list[tuple[int, int, bool]]] = [[] for _ in markerset.names]
        for k, (i, j) in enumerate(self.pairs):
            self.neighbours[i].append((int(j), k, True))
            self.neighbours[j].append((int(i), k, False))

    def slack(self, p_m: np.ndarray, c_pat: np.ndarray, pa: np.ndarray, pb: np.ndarray,
              hard_distances: bool = False, ks: slice | np.ndarray = slice(None)) -> np.ndarray:
        """Slack of every constraint k with marker a at point ``pa[..., k]``, b at ``pb[..., k]``.

        With ``hard_distances`` a distance constraint is +inf when it holds and -inf when not, so
        that a bound on the worst slack bounds the orderings only. ``ks``: only these constraints
        (the last axis of ``pa`` and ``pb``).
        """
        ax = self.c_axis[ks]
        order = self.c_sign[ks] * (c_pat[pb, ax] - c_pat[pa, ax]) - self.c_margin[ks]
        d = np.linalg.norm(p_m[pb] - p_m[pa], axis=-1)
        dist = np.minimum(d - self.c_lo[ks], self.c_hi[ks] - d)
        # an unseen marker's stand-in point (NaN) satisfies every constraint
        order = np.where(np.isnan(order), np.inf, order)
        dist = np.where(np.isnan(dist), np.inf, dist)
        if hard_distances:
            dist = np.where(dist >= 0, np.inf, -np.inf)
        return np.where(self.c_dist[ks], dist, order)

    def pair_blocks(self, p_m: np.ndarray, c_pat: np.ndarray, colour: np.ndarray) -> Blocks:
        """Worst slack of each marker pair's constraints over the points of the pair's colours only.

        For many points (rays sampled finely) where :meth:`pair_slack` would be large: pair k's
        block holds [i at p, j at q] for p among the points of marker i's colour, q of j's. The
        distances and coordinate differences are computed once per pair of colours.
        """
        members = [np.flatnonzero(colour == c) for c in range(self.n_colours)]
        loc = np.zeros(len(colour), np.int64)
        for rows in members:
            loc[rows] = np.arange(len(rows))
        shared: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        blocks = []
        for k, (i, j) in enumerate(self.pairs):
            ci, cj = int(self.colour[i]), int(self.colour[j])
            if (ci, cj) not in shared:
                r, c = members[ci], members[cj]
                diff = c_pat[c][None, :, :] - c_pat[r][:, None, :]  # (R, C, 3) j minus i
                dist = np.linalg.norm(p_m[c][None, :, :] - p_m[r][:, None, :], axis=-1)
                shared[ci, cj] = (diff, dist)
            diff, dist = shared[ci, cj]
            block = np.full(diff.shape[:2], np.inf)
            end = self.pair_starts[k + 1] if k + 1 < len(self.pairs) else len(self.by_pair)
            for kk in self.by_pair[self.pair_starts[k]:end]:
                if self.c_dist[kk]:
                    sl = np.minimum(dist - self.c_lo[kk], self.c_hi[kk] - dist)
                else:
                    # a constraint written (j, i) orders i after j: the difference changes sign
                    sign = -self.c_sign[kk] if self.c_flip[kk] else self.c_sign[kk]
                    sl = sign * diff[..., self.c_axis[kk]] - self.c_margin[kk]
                # an unseen marker's stand-in point (NaN) satisfies every constraint (np.fmin
                # ignores NaN)
                np.fmin(block, sl, out=block)
            blocks.append(block)
        return Blocks(blocks, loc)

    def pair_slack(self, p_m: np.ndarray, c_pat: np.ndarray, hard_distances: bool) -> np.ndarray:
        """(pairs, P, P) worst slack of each marker pair's constraints, [i at p, j at q]."""
        n = c_pat.shape[0]
        pts = np.arange(n)
        # d[k, p, q]: constraint k with its marker a at point p and b at point q
        d = self.slack(p_m, c_pat, pts[:, None, None], pts[None, :, None], hard_distances).transpose(2, 0, 1)
        d = np.where(self.c_flip[:, None, None], d.transpose(0, 2, 1), d)
        return np.minimum.reduceat(d[self.by_pair], self.pair_starts, axis=0)

    def compact(self, blocks: Blocks, colour: np.ndarray, ext_col: np.ndarray, rays: RayRows) -> np.ndarray:
        """(pairs, P, P) pair slacks of the searched points: a ray's the best over its samples."""
        n = len(colour)
        out = np.full((len(self.pairs), n, n), -np.inf)
        # the extended points of one colour are ordered by the searched point they belong to
        owner = np.concatenate([np.arange(rays.first)]
                               + [np.full(len(p), rays.first + k) for k, p in enumerate(rays.samples)])
        rows, starts = [], []
        for c in range(self.n_colours):
            ext_rows = np.flatnonzero(ext_col == c)
            first = np.flatnonzero(np.diff(np.concatenate([[-1], owner[ext_rows]])) != 0)
            rows.append(owner[ext_rows][first])
            starts.append(first)
        for k, (i, j) in enumerate(self.pairs):
            ci, cj = self.colour[i], self.colour[j]
            if not len(rows[ci]) or not len(rows[cj]):
                continue
            b = np.maximum.reduceat(np.maximum.reduceat(blocks.block[k], starts[ci], axis=0), starts[cj], axis=1)
            out[k][np.ix_(rows[ci], rows[cj])] = b
        return out

    def rule_margins(self, slack: np.ndarray) -> np.ndarray:
        out = np.full(len(self.rules.rules), np.inf)
        np.minimum.at(out, self.c_rule, slack)
        return out

    def distance_fit_m(self, marker: int, p_cand_m: np.ndarray, positions_m: np.ndarray, known: np.ndarray
                       ) -> np.ndarray:
        """How well each candidate point fits the distance rules of ``marker`` to the known markers.

        The distance rules (markers on one bone) hold in any pose, so they place a marker that
        was unseen at identification once it shows up (the tracker's re-acquisition).

        Args:
            marker: marker index (marker-set order).
            p_cand_m: (N, 3) float64 candidate points, world metres.
            positions_m: (M, 3) float64 marker positions, world metres.
            known: (M,) bool, markers whose position is trusted (measured this frame).

        Returns:
            (N,) float64 worst slack of the rules (metres, >= 0: every rule holds); +inf for all
            when no distance rule links ``marker`` to a known marker.
        """
        known = np.asarray(known, dtype=bool)
        rows = self.c_dist & (((self.c_a == marker) & known[self.c_b]) | ((self.c_b == marker) & known[self.c_a]))
        p_cand_m = np.asarray(p_cand_m, dtype=np.float64).reshape(-1, 3)
        if not rows.any():
            return np.full(len(p_cand_m), np.inf)
        other = np.where(self.c_a[rows] == marker, self.c_b[rows], self.c_a[rows])
        d = np.linalg.norm(p_cand_m[:, None, :] - positions_m[other][None, :, :], axis=-1)
        return np.minimum(d - self.c_lo[rows], self.c_hi[rows] - d).min(axis=1)

