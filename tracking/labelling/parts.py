"""The labellings within reach, built in parts: each arm, the trunk, then the three joined.

Every cost of the body model (:mod:`.prior`) is >= 0, so a part's cost is a lower bound of the
whole labelling's: each part's candidates are scored at once (numpy) and those beyond ``reach``
dropped before the parts are joined:

1. per arm, the elbow's marker pairs, then the shoulder with them, then the wrist's pairs;
2. the trunk's four markers;
3. trunk x right arm x left arm, in order of score, with the costs that link them (each arm to
   the trunk, the shoulders' breadth, the arms' symmetry and proportions), stopping as soon as
   a partial sum passes the bound.

A candidate's rows index the search's balls (:meth:`tracking.labelling.fit.Labeller.label`): the
points, then as many unseen rows (NaN) of a colour as it is short of points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracking.labelling import prior as bm
from tracking.labelling.body_score import BodyScore
from tracking.labelling.roles import ArmRoles

#: at most this many labellings within a margin of the best are weighed (more: not confident)
MAX_NEAR = 64


@dataclass(slots=True)
class Part:
    """Candidates of one part: (N, k) point rows of its markers, (N,) score, (N, F) lengths
    compared with the other side's (:data:`.prior.SYMMETRIC`; arms only)."""

    rows: np.ndarray
    score: np.ndarray
    lengths: np.ndarray | None = None

    def keep(self, ok: np.ndarray) -> "Part":
        return Part(self.rows[ok], self.score[ok], None if self.lengths is None else self.lengths[ok])

    def sorted(self) -> "Part":
        return self.keep(np.argsort(self.score, kind="stable"))


class TooMany(Exception):
    """Too many labellings within a margin of the best."""


def pairs(a: np.ndarray, b: np.ndarray, ball: np.ndarray) -> np.ndarray:
    """(N, 2) rows (p, q), p from ``a``, q from ``b``, of two different balls."""
    p, q = np.meshgrid(a, b, indexing="ij")
    p, q = p.ravel(), q.ravel()
    ok = ball[p] != ball[q]
    return np.stack([p[ok], q[ok]], axis=1)


def distinct(rows: np.ndarray, ball: np.ndarray) -> np.ndarray:
    """(N,) no ball used twice in a row."""
    b = ball[rows]
    n = rows.shape[1]
    ok = np.ones(len(rows), bool)
    for i in range(n):
        for j in range(i + 1, n):
            ok &= b[:, i] != b[:, j]
    return ok


def key(rows: np.ndarray, ball: np.ndarray, kind: np.ndarray) -> np.ndarray:
    """What a labelling says: each marker's ball (a point or a ray; -1 unseen, whichever row)."""
    return np.where(kind[rows] == 2, -1, ball[rows])


def bound(best: list[tuple[float, np.ndarray]], reach: float, min_margin: float) -> float:
    """Labellings scoring above this matter no more: beyond reach, or a margin past the best."""
    return min(reach, best[0][0] + min_margin) if best else reach


class Nearest:
    """The whole labellings found so far, best first, each once (:func:`key`: unseen rows are
    alike): those within a margin of the best, or with ``cap`` the ``cap`` best within reach."""

    def __init__(self, reach: float, min_margin: float, ball: np.ndarray, kind: np.ndarray, cap: int):
        self.reach, self.min_margin, self.ball, self.kind, self.cap = reach, min_margin, ball, kind, cap
        self.best: list[tuple[float, np.ndarray]] = []
        self.seen_keys: dict[bytes, float] = {}
        self.bound = self._bound_of()

    def _bound_of(self) -> float:
        if self.cap:
            return self.reach if len(self.best) < self.cap else self.best[-1][0]
        return bound(self.best, self.reach, self.min_margin)

    def add(self, s: np.floating, rows: np.ndarray) -> None:
        """One labelling (score, (M,) rows); raises :class:`TooMany` past :data:`MAX_NEAR` (no cap)."""
        ball, kind = self.ball, self.kind
        k = key(rows, ball, kind).tobytes()
        if k in self.seen_keys:
            if self.seen_keys[k] <= s:
                return
            self.best = [b for b in self.best if key(b[1], ball, kind).tobytes() != k]
        self.seen_keys[k] = float(s)
        self.best.append((float(s), rows))
        self.best.sort(key=lambda b: b[0])
        if self.cap and len(self.best) > self.cap:
            self.best.pop()
        self.bound = self._bound_of()
        while self.best and self.best[-1][0] > self.bound:
            self.best.pop()
        if not self.cap and len(self.best) > MAX_NEAR:
            raise TooMany


class PartSearch:
    """The parts' candidates within reach and their join.

    Args:
        body: the body model's terms and costs.
        n_markers: markers of the marker set.
        reach: a labelling scoring more does not count (``max_score + min_margin``).
        min_margin: the margin past the best within which labellings are kept.
    """

    def __init__(self, body: BodyScore, n_markers: int, reach: float, min_margin: float):
        self.body, self.n_markers, self.reach, self.min_margin = body, n_markers, reach, min_margin

    def arm(self, q: np.ndarray, cand: list[np.ndarray], arm: ArmRoles, ball: np.ndarray) -> Part:
        """Candidates (shoulder, E1, E2, W1, W2) of one arm within reach."""
        pr, tab, reach = self.body.prior, self.body.table, self.reach
        s_i, e1_i, e2_i, w1_i, w2_i = arm.markers
        elbow = pairs(cand[e1_i], cand[e2_i], ball)
        width = bm.cost(bm.norm(q[elbow[:, 0]] - q[elbow[:, 1]]), *tab["elbow_width"])
        elbow, width = elbow[width <= reach], width[width <= reach]
        # shoulder x elbow pairs
        si = np.repeat(cand[s_i], len(elbow))
        ei = np.tile(elbow, (len(cand[s_i]), 1))
        w0 = np.tile(width, len(cand[s_i]))
        rows = np.column_stack([si, ei])
        ok = distinct(rows, ball)
        rows, w0 = rows[ok], w0[ok]
        vals = bm.upper_arm_terms(pr, arm.sign, q[rows[:, 0]], q[rows[:, 1]], q[rows[:, 2]])
        vals.pop("elbow_width")
        upper = Part(rows, w0 + bm.total(vals, tab))
        upper = upper.keep(upper.score <= reach)
        wrist = pairs(cand[w1_i], cand[w2_i], ball)
        ww = bm.cost(bm.norm(q[wrist[:, 0]] - q[wrist[:, 1]]), *tab["wrist_width"])
        wrist, ww = wrist[ww <= reach], ww[ww <= reach]
        if not len(upper.rows) or not len(wrist):
            return Part(np.zeros((0, 5), np.int64), np.zeros(0))
        a = np.repeat(np.arange(len(upper.rows)), len(wrist))
        b = np.tile(np.arange(len(wrist)), len(upper.rows))
        pre = upper.score[a] + ww[b]
        a, b, pre = a[pre <= reach], b[pre <= reach], pre[pre <= reach]
        rows = np.column_stack([upper.rows[a], wrist[b]])
        ok = distinct(rows, ball)
        rows, pre = rows[ok], pre[ok]
        vals = bm.forearm_terms(pr, arm.sign, *(q[rows[:, k]] for k in range(5)))
        vals.pop("wrist_width")
        part = Part(rows, pre + bm.total(vals, tab))
        part = part.keep(part.score <= reach)
        s, e1, e2, w1, w2 = (q[part.rows[:, k]] for k in range(5))
        e, w = bm.mid(e1, e2), bm.mid(w1, w2)
        part.lengths = np.stack([bm.norm(e - s), bm.norm(w - e), bm.norm(e1 - e2), bm.norm(w1 - w2), bm.norm(w - s)],
                                axis=1)
        return part.sorted()

    def trunk(self, q: np.ndarray, cand: list[np.ndarray], ball: np.ndarray) -> Part:
        """Candidates (upper, lower, left hip, right hip) within reach."""
        r = self.body.roles
        ul = pairs(cand[r.upper], cand[r.lower], ball)
        hips = pairs(cand[r.left_hip], cand[r.right_hip], ball)
        a = np.repeat(np.arange(len(ul)), len(hips))
        b = np.tile(np.arange(len(hips)), len(ul))
        rows = np.column_stack([ul[a], hips[b]])
        rows = rows[distinct(rows, ball)]
        vals = bm.trunk_terms(self.body.prior, *(q[rows[:, k]] for k in range(4)))
        part = Part(rows, bm.total(vals, self.body.table))
        return part.keep(part.score <= self.reach).sorted()

    def combine(self, q: np.ndarray, trunk: Part, arms: list[Part], ball: np.ndarray, kind: np.ndarray,
                n_points: int, cap: int = 0) -> tuple[list[tuple[float, np.ndarray]], float]:
        """The whole labellings within a margin of the best (score, (M,) rows), best first, each
        labelling once (:func:`key`: unseen rows are alike), every point used. With ``cap``: the
        ``cap`` best within reach instead (their scores are lower bounds, placed later on rays).

        Returns:
            (the labellings, the score above which none was looked at)."""
        r = self.body.roles
        right, left = arms
        if not len(trunk.rows) or not len(right.rows) or not len(left.rows):
            return [], self.reach
        bits = lambda rows: np.left_shift(np.int64(1), ball[rows]).sum(axis=1)  # noqa: E731  (balls differ)
        n_pts = lambda rows: (kind[rows] == 0).sum(axis=1)  # noqa: E731
        tb, rb, lb = bits(trunk.rows), bits(right.rows), bits(left.rows)
        tn, rn, ln = n_pts(trunk.rows), n_pts(right.rows), n_pts(left.rows)
        rt, ra, rx = self._links(q, trunk, right, r.arms[0], tb, tn, rb, rn, ln, n_points)
        lt, la, lx = self._links(q, trunk, left, r.arms[1], tb, tn, lb, ln, rn, n_points)
        # join on the trunk candidate
        found = Nearest(self.reach, self.min_margin, ball, kind, cap)
        lsort = np.argsort(lt, kind="stable")
        lt, la, lx = lt[lsort], la[lsort], lx[lsort]
        starts = np.searchsorted(lt, np.arange(len(trunk.rows) + 1))
        for k in np.argsort(trunk.score[rt] + right.score[ra] + rx, kind="stable"):
            t, a, x = int(rt[k]), int(ra[k]), float(rx[k])
            base = trunk.score[t] + right.score[a] + x
            if base > found.bound:
                break
            js = np.arange(starts[t], starts[t + 1])
            if not len(js):
                continue
            tot = base + left.score[la[js]] + lx[js]
            ok = (tot <= found.bound) & ((lb[la[js]] & (tb[t] | rb[a])) == 0) & (tn[t] + rn[a] + ln[la[js]] == n_points)
            js, tot = js[ok], tot[ok]
            if not len(js):
                continue
            tot = self._with_both_arms(tot, q, right, left, a, la[js])
            for j, s in zip(js[tot <= found.bound], tot[tot <= found.bound]):
                rows = np.empty(self.n_markers, np.int64)
                rows[list(r.trunk)] = trunk.rows[t]
                rows[list(r.arms[0].markers)] = right.rows[a]
                rows[list(r.arms[1].markers)] = left.rows[la[j]]
                found.add(s, rows)
        return found.best, found.bound

    def _links(self, q: np.ndarray, trunk: Part, part: Part, arm: ArmRoles, tb: np.ndarray, tn: np.ndarray,
               pb: np.ndarray, pn: np.ndarray, other: np.ndarray, n_points: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The costs linking an arm to the trunk: every trunk x arm pair within reach, at once, as
        (trunk candidates, arm candidates, their linking costs). ``tb``, ``pb``: the balls each
        trunk and arm candidate uses (bits); ``tn``, ``pn``, ``other``: the points each trunk,
        arm and other arm's candidate uses."""
        ti = np.repeat(np.arange(len(trunk.rows)), len(part.rows))
        ai = np.tile(np.arange(len(part.rows)), len(trunk.rows))
        pre = trunk.score[ti] + part.score[ai]
        # within reach, no ball used twice, and the other arm can still use the points left
        sel = (pre <= self.reach) & ((tb[ti] & pb[ai]) == 0) & (tn[ti] + pn[ai] + other.max() >= n_points)
        ti, ai, pre = ti[sel], ai[sel], pre[sel]
        limbs = np.stack([q[part.rows[ai, k]] for k in (1, 2, 3, 4)], axis=1)
        vals = bm.coupling_terms(self.body.prior, arm.sign, q[trunk.rows[ti, 0]], q[trunk.rows[ti, 1]],
                                 q[trunk.rows[ti, 3 if arm.sign > 0 else 2]], q[part.rows[ai, 0]], limbs)
        extra = bm.total(vals, self.body.table)
        sel = pre + extra <= self.reach
        return ti[sel], ai[sel], extra[sel]

    def _with_both_arms(self, tot: np.ndarray, q: np.ndarray, right: Part, left: Part, a: int, lefts: np.ndarray
                        ) -> np.ndarray:
        """``tot`` of the right arm candidate ``a`` with each of the left arm candidates ``lefts``
        plus the costs of both arms together: the shoulders' breadth, the arms' symmetry and their
        proportions to the shoulders."""
        tab = self.body.table
        shoulders = bm.norm(q[right.rows[a, 0]] - q[left.rows[lefts, 0]])
        tot = tot + bm.cost(shoulders, *tab["shoulders"])
        n_sym = len(bm.SYMMETRIC)
        diff = np.abs(right.lengths[a][None, :n_sym] - left.lengths[lefts, :n_sym])
        tot = tot + bm.cost(diff, *tab["symmetry"]).sum(axis=1)
        for name, c in bm.PROPORTIONS.items():
            tot = tot + bm.cost(right.lengths[a, c] / shoulders, *tab[name])
            tot = tot + bm.cost(left.lengths[lefts, c] / shoulders, *tab[name])
        return tot
