"""The search for the labelling that best explains the points, with its confidence.

A labelling gives each marker one point of its own colour, or none ("unseen": at most the
colour's shortfall of points). The score of a labelling is the sum of the body model's costs
(:mod:`.prior`); the search finds every labelling whose score is within ``reach`` =
``max_score + min_margin`` and keeps the two best. It builds the labelling in parts, each
part's candidates scored at once (numpy) and those beyond ``reach`` dropped, because every cost
is >= 0 and a part's cost is a lower bound of the whole:

1. per arm, the elbow's marker pairs, then the shoulder with them, then the wrist's pairs;
2. the trunk's four markers;
3. trunk x right arm x left arm, in order of score, with the costs that link them, stopping as
   soon as a partial sum passes ``reach``.

The patient's frame (+y up, their right +x) comes from the horizontal spread of the points
(:func:`tracking.identify.yaw_from_points`), then from the best labelling's shoulders and hips;
the search is repeated in that frame when it turned more than a degree.

The labelling is *confident* when the best scores at most ``max_score`` and the second best at
least ``min_margin`` more. With one colour for all markers a wrong pair of elbow or wrist markers
turns the upper arm or the thumb by about 180 degrees: it scores in the hundreds, a margin the
right labelling keeps under every variation of the population (docs/TRACKING.md).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from tracking.labelling import prior as bm
from tracking.labelling.roles import ArmRoles, BodyRoles

log = logging.getLogger(__name__)

# at most this many labellings within a margin of the best are weighed (more: not confident)
_MAX_NEAR = 64
# a labelling within this many degrees of yaw of the frame it was scored in is not scored again
_YAW_SETTLED_DEG = 1.0
_MAX_REFINE = 2


@dataclass(frozen=True, slots=True)
class Labelling:
    """The result of :meth:`Labeller.label`.

    Attributes:
        index: (M,) int64 point of each marker (marker-set order), -1 where unseen or where the
            labellings within the margin of the best disagree (it joins when seen); None when no
            labelling is within reach.
        score: the best labelling's score (0: every range of the body model kept).
        margin: every labelling that names a labelled marker otherwise scores at least this much
            more than the best (the search looks no further than ``min_margin``).
        confident: score <= max_score and margin >= min_margin.
        yaw_deg: the patient frame's yaw (as :class:`tracking.identify.Identification`).
        worst: (term, marker side or "", value) of the best labelling's largest cost, or None.
        terms: term name (with the side, e.g. "right humeral_rotation") -> value, of the best.
        ambiguous: markers that the labellings within the margin of the best name differently.
    """

    index: np.ndarray | None
    score: float
    margin: float
    confident: bool
    yaw_deg: float
    worst: tuple[str, float] | None = None
    terms: dict[str, float] = field(default_factory=dict)
    ambiguous: tuple[int, ...] = ()


@dataclass(slots=True)
class _Part:
    """Candidates of one part: (N, k) point rows of its markers, (N,) score, (N, F) lengths
    compared with the other side's (:data:`.prior.SYMMETRIC`; arms only)."""

    rows: np.ndarray
    score: np.ndarray
    lengths: np.ndarray | None = None

    def keep(self, ok: np.ndarray) -> "_Part":
        return _Part(self.rows[ok], self.score[ok], None if self.lengths is None else self.lengths[ok])

    def sorted(self) -> "_Part":
        return self.keep(np.argsort(self.score, kind="stable"))


#: what the patient does about a term out of its range
_ADVICE = {
    "abduction": "hold the {side} arm 5-40 degrees away from the body",
    "arm_flexion": "let the {side} arm hang at the side, neither forward nor back",
    "humeral_rotation": "let the {side} arm hang relaxed with the elbow crease forward or slightly inward",
    "elbow_flexion": "straighten the {side} elbow",
    "forearm_down": "let the {side} forearm hang down",
    "thumb": "turn the {side} hand so that the thumb points forward",
    "trunk_lean": "sit upright",
    "hips_tilt": "sit level on the chair",
    "hips_turn": "turn the chair to face the front",
}


class _TooMany(Exception):
    """Too many labellings within a margin of the best."""


def _pairs(a: np.ndarray, b: np.ndarray, unseen: int) -> np.ndarray:
    """(N, 2) rows (p, q), p from ``a``, q from ``b``, p != q unless both are the unseen row."""
    p, q = np.meshgrid(a, b, indexing="ij")
    p, q = p.ravel(), q.ravel()
    ok = (p != q) | (p == unseen)
    return np.stack([p[ok], q[ok]], axis=1)


def _distinct(rows: np.ndarray, unseen: int) -> np.ndarray:
    """(N,) no point used twice in a row (the unseen row may repeat)."""
    n = rows.shape[1]
    ok = np.ones(len(rows), bool)
    for i in range(n):
        for j in range(i + 1, n):
            ok &= (rows[:, i] != rows[:, j]) | (rows[:, i] == unseen)
    return ok


class Labeller:
    """Labels the points of a reference pose by the body model's fit.

    Args:
        roles: which marker is which landmark (:meth:`BodyRoles.of`).
        colour: (M,) palette index of each marker.
        prior: the body model's ranges.
        max_score: a labelling scoring more does not explain the points (a pose outside the
            tolerances, a marker far off its landmark).
        min_margin: the second best must score this much more.
        max_turn_deg: the patient's frame is looked for within this yaw.
        max_unseen: at most this many markers without a point.
    """

    def __init__(self, roles: BodyRoles, colour: np.ndarray, prior: bm.BodyPrior = bm.BodyPrior(), *,
                 max_score: float = 9.0, min_margin: float = 16.0, max_turn_deg: float = 30.0, max_unseen: int = 2):
        self.roles = roles
        self.colour = np.asarray(colour, dtype=np.int64)
        self.prior = prior
        self.table = bm.ranges(prior)
        self.max_score = float(max_score)
        self.min_margin = float(min_margin)
        self.reach = self.max_score + self.min_margin
        self.max_turn_deg = float(max_turn_deg)
        self.max_unseen = int(max_unseen)

    @classmethod
    def for_markerset(cls, markerset, **kw) -> "Labeller":
        """The labeller of a marker set (its roles, colours, ball size and allowed turn).

        Raises:
            ContentError: the marker set's YAML does not name the body model's landmarks.
        """
        from dataclasses import replace

        from tracking.errors import ContentError

        roles = BodyRoles.of(markerset)
        if roles is None:
            raise ContentError(
                f"marker set {markerset.name}: its hidden_markers section does not name the trunk, elbows and "
                "wrists the labelling's body model needs (trunk, elbows, forearms)")
        prior = replace(kw.pop("prior", bm.BodyPrior()), ball_offset_m=markerset.radius_m + markerset.soft_tissue_m)
        if markerset.identification is not None:
            kw.setdefault("max_turn_deg", markerset.identification.max_turn_deg)
        return cls(roles, markerset.colour_index, prior, **kw)

    # ------------------------------------------------------------------ public
    def label(self, p_world_m: np.ndarray, colour: np.ndarray) -> Labelling:
        """The best labelling of the finite points and its confidence.

        Args:
            p_world_m: (P, 3) float64 points, world metres (rows with NaN are left out).
            colour: (P,) palette index of each point.
        """
        from tracking.identify import yaw_from_points

        p_world_m = np.asarray(p_world_m, dtype=np.float64).reshape(-1, 3)
        colour = np.asarray(colour, dtype=np.int64).reshape(-1)
        keep = np.flatnonzero(np.isfinite(p_world_m).all(axis=1))
        pts, col = p_world_m[keep], colour[keep]
        n_col = int(self.colour.max()) + 1
        have = np.bincount(col[(col >= 0) & (col < n_col)], minlength=n_col)
        want = np.bincount(self.colour, minlength=n_col)
        short = want - have
        if np.any(short < 0) or np.any((col < 0) | (col >= n_col)) or short.sum() > self.max_unseen or len(pts) < 3:
            return Labelling(None, math.inf, 0.0, False, 0.0)
        limit = self.max_turn_deg
        yaw = float(np.clip(math.degrees(yaw_from_points(pts)), -limit, limit))
        result = None
        for _ in range(_MAX_REFINE + 1):
            with np.errstate(invalid="ignore", divide="ignore"):  # unseen markers: NaN terms cost 0
                result = self._label_in(pts, col, short, yaw)
            if result.index is None:
                break
            new = self._yaw_of(pts, result.index)
            if new is None or abs(new - yaw) < _YAW_SETTLED_DEG or abs(new) > limit:
                break
            yaw = new
        if result.index is not None:
            result = Labelling(np.where(result.index >= 0, keep[np.maximum(result.index, 0)], -1), result.score,
                               result.margin, result.confident, result.yaw_deg, result.worst, result.terms,
                               result.ambiguous)
        return result

    def terms_of(self, p_pat_m: np.ndarray) -> dict[str, float]:
        """Every term's value for labelled marker positions in the patient's frame ((M, 3), NaN unseen)."""
        r = self.roles
        out: dict[str, float] = {}
        t = bm.trunk_terms(self.prior, *(p_pat_m[k] for k in r.trunk))
        out.update({k: float(v) for k, v in t.items()})
        for arm in r.arms:
            s, e1, e2, w1, w2 = (p_pat_m[k] for k in arm.markers)
            vals = {**bm.upper_arm_terms(self.prior, arm.sign, s, e1, e2),
                    **bm.forearm_terms(self.prior, arm.sign, s, e1, e2, w1, w2),
                    **bm.coupling_terms(self.prior, arm.sign, p_pat_m[r.upper], p_pat_m[r.lower],
                                        p_pat_m[r.right_hip if arm.sign > 0 else r.left_hip], s,
                                        np.stack([e1, e2, w1, w2]))}
            out.update({f"{arm.side} {k}": float(v) for k, v in vals.items()})
        a, b = (p_pat_m[arm.shoulder] for arm in r.arms)
        out["shoulders"] = float(bm.norm(a - b))
        for name in bm.SYMMETRIC:
            out[f"symmetry {name}"] = abs(out[f"right {name}"] - out[f"left {name}"])
        for side in ("right", "left"):
            out[f"{side} upper_arm_ratio"] = out[f"{side} upper_arm"] / out["shoulders"]
            out[f"{side} reach_ratio"] = out[f"{side} reach"] / out["shoulders"]
        return out

    def score_of(self, p_world_m: np.ndarray, index: np.ndarray, yaw_deg: float = 0.0) -> float:
        """The body model's score of a given labelling (index -1: unseen) in the frame of ``yaw_deg``."""
        from tracking.identify import patient_axes

        index = np.asarray(index)
        p = np.where((index >= 0)[:, None], np.asarray(p_world_m, dtype=np.float64)[np.maximum(index, 0)], np.nan)
        q = (p - np.nanmean(p, axis=0)) @ patient_axes(math.radians(yaw_deg))
        with np.errstate(invalid="ignore", divide="ignore"):
            terms = self.terms_of(q)
            return float(sum(self.cost_of(k, v) for k, v in terms.items() if np.isfinite(v)))

    def advice(self, lab: Labelling, names: tuple[str, ...]) -> str:
        """One line for the therapist on a labelling that is not confident (the fit's own words;
        the marker set's ordering rules say it in theirs first, see the tracker)."""
        if lab.index is None:
            return "the markers do not fit the reference pose"
        if lab.ambiguous and lab.score <= self.max_score:
            which = ", ".join(names[m] for m in lab.ambiguous)
            return (f"the markers {which} fit the reference pose in more than one way: hold the arms a little "
                    "further from the body, elbows nearly straight, thumbs forward, and hold still")
        if lab.worst is not None:
            name, value = lab.worst
            side, _, term = name.rpartition(" ")
            rng, _ = self.table["symmetry" if side == "symmetry" else term]
            text = _ADVICE.get(term, "")
            unit = "degrees" if term.endswith(("rotation", "abduction", "flexion", "axis", "thumb", "lean", "tilt",
                                              "turn", "down")) else "mm"
            shown = value if unit == "degrees" else 1000 * value
            lo, hi = (rng if unit == "degrees" else (1000 * rng[0], 1000 * rng[1]))
            where = f"{side} " if side and side != "symmetry" else ""
            return (f"the {where}{term.replace('_', ' ')} is {shown:.0f} {unit} (expected {lo:.0f} to {hi:.0f})"
                    + (f": {text.format(side=side or 'either')}" if text else ""))
        return "the markers do not fit the reference pose"

    def cost_of(self, name: str, value: float) -> float:
        """The cost of a value of :meth:`terms_of`."""
        key = "symmetry" if name.startswith("symmetry") else name.split(" ")[-1]
        rng, scale = self.table[key]
        return float(bm.cost(np.float64(value), rng, scale))

    # ------------------------------------------------------------------ search
    def _yaw_of(self, pts: np.ndarray, index: np.ndarray) -> float | None:
        """Yaw (degrees) of the mean left -> right direction of the labelled shoulders and hips."""
        r = self.roles
        d = []
        for left, right in ((r.arms[1].shoulder, r.arms[0].shoulder), (r.left_hip, r.right_hip)):
            if index[left] >= 0 and index[right] >= 0:
                v = pts[index[right]] - pts[index[left]]
                v = v[[0, 2]] / max(float(np.hypot(v[0], v[2])), 1e-9)
                d.append(v)
        if not d:
            return None
        vx, vz = np.sum(d, axis=0)
        return math.degrees(math.atan2(-vz, vx))

    def _label_in(self, pts: np.ndarray, col: np.ndarray, short: np.ndarray, yaw_deg: float) -> Labelling:
        from tracking.identify import patient_axes

        q = (pts - pts.mean(axis=0)) @ patient_axes(math.radians(yaw_deg))
        unseen = len(q)
        q = np.vstack([q, np.full((1, 3), np.nan)])
        seen = [np.flatnonzero(col == c).astype(np.int64) for c in self.colour]
        arm_parts: dict[tuple[int, frozenset], _Part] = {}
        trunk_parts: dict[frozenset, _Part] = {}
        best: list[tuple[float, np.ndarray]] = []
        for missing in self._unseen_cases(short):
            cand = [np.array([unseen], np.int64) if m in missing else seen[m] for m in range(len(self.colour))]
            arms = []
            for k, arm in enumerate(self.roles.arms):
                key = (k, missing & frozenset(arm.markers))
                if key not in arm_parts:
                    arm_parts[key] = self._arm(q, cand, arm, unseen)
                arms.append(arm_parts[key])
            key = missing & frozenset(self.roles.trunk)
            if key not in trunk_parts:
                trunk_parts[key] = self._trunk(q, cand, unseen)
            try:
                best = self._combine(q, trunk_parts[key], arms, unseen, best)
            except _TooMany:
                log.debug("more than %d labellings within a margin of the best: not confident", _MAX_NEAR)
                return Labelling(None, best[0][0], 0.0, False, yaw_deg)
        if not best:
            return Labelling(None, math.inf, 0.0, False, yaw_deg)
        # the markers every labelling within the margin names alike (the others: -1)
        s0 = best[0][0]
        rows = np.array([b[1] for b in best])
        agree = (rows == rows[:1]).all(axis=0)
        index = np.where(agree & (rows[0] != unseen), rows[0], -1)
        # every labelling that names a labelled marker otherwise scores above the bound
        margin = self._bound(best) - s0
        terms = self.terms_of(q[rows[0]])
        costs = {k: self.cost_of(k, v) for k, v in terms.items()}
        name = max(costs, key=costs.get)
        worst = (name, terms[name]) if costs[name] > 0 else None
        # every seen point must be named alike by all of them: a point two labellings name
        # differently is not certain, and would be left to a re-acquisition that knows less
        confident = bool(s0 <= self.max_score and margin >= self.min_margin - 1e-9
                         and np.sum(index < 0) == int(short.sum()))
        return Labelling(index, float(s0), float(margin), confident, yaw_deg, worst, terms,
                         tuple(np.flatnonzero(~agree).tolist()))

    def _arm(self, q: np.ndarray, cand: list[np.ndarray], arm: ArmRoles, unseen: int) -> _Part:
        """Candidates (shoulder, E1, E2, W1, W2) of one arm within reach."""
        pr, tab, reach = self.prior, self.table, self.reach
        s_i, e1_i, e2_i, w1_i, w2_i = arm.markers
        elbow = _pairs(cand[e1_i], cand[e2_i], unseen)
        width = bm.cost(bm.norm(q[elbow[:, 0]] - q[elbow[:, 1]]), *tab["elbow_width"])
        elbow, width = elbow[width <= reach], width[width <= reach]
        # shoulder x elbow pairs
        si = np.repeat(cand[s_i], len(elbow))
        ei = np.tile(elbow, (len(cand[s_i]), 1))
        w0 = np.tile(width, len(cand[s_i]))
        rows = np.column_stack([si, ei])
        ok = _distinct(rows, unseen)
        rows, w0 = rows[ok], w0[ok]
        vals = bm.upper_arm_terms(pr, arm.sign, q[rows[:, 0]], q[rows[:, 1]], q[rows[:, 2]])
        vals.pop("elbow_width")
        upper = _Part(rows, w0 + bm.total(vals, tab))
        upper = upper.keep(upper.score <= reach)
        wrist = _pairs(cand[w1_i], cand[w2_i], unseen)
        ww = bm.cost(bm.norm(q[wrist[:, 0]] - q[wrist[:, 1]]), *tab["wrist_width"])
        wrist, ww = wrist[ww <= reach], ww[ww <= reach]
        if not len(upper.rows) or not len(wrist):
            return _Part(np.zeros((0, 5), np.int64), np.zeros(0))
        a = np.repeat(np.arange(len(upper.rows)), len(wrist))
        b = np.tile(np.arange(len(wrist)), len(upper.rows))
        pre = upper.score[a] + ww[b]
        a, b, pre = a[pre <= reach], b[pre <= reach], pre[pre <= reach]
        rows = np.column_stack([upper.rows[a], wrist[b]])
        ok = _distinct(rows, unseen)
        rows, pre = rows[ok], pre[ok]
        vals = bm.forearm_terms(pr, arm.sign, *(q[rows[:, k]] for k in range(5)))
        vals.pop("wrist_width")
        part = _Part(rows, pre + bm.total(vals, tab))
        part = part.keep(part.score <= reach)
        s, e1, e2, w1, w2 = (q[part.rows[:, k]] for k in range(5))
        e, w = bm.mid(e1, e2), bm.mid(w1, w2)
        part.lengths = np.stack([bm.norm(e - s), bm.norm(w - e), bm.norm(e1 - e2), bm.norm(w1 - w2), bm.norm(w - s)],
                                axis=1)
        return part.sorted()

    def _trunk(self, q: np.ndarray, cand: list[np.ndarray], unseen: int) -> _Part:
        """Candidates (upper, lower, left hip, right hip) within reach."""
        r = self.roles
        ul = _pairs(cand[r.upper], cand[r.lower], unseen)
        hips = _pairs(cand[r.left_hip], cand[r.right_hip], unseen)
        a = np.repeat(np.arange(len(ul)), len(hips))
        b = np.tile(np.arange(len(hips)), len(ul))
        rows = np.column_stack([ul[a], hips[b]])
        rows = rows[_distinct(rows, unseen)]
        vals = bm.trunk_terms(self.prior, *(q[rows[:, k]] for k in range(4)))
        part = _Part(rows, bm.total(vals, self.table))
        return part.keep(part.score <= self.reach).sorted()

    def _unseen_cases(self, short: np.ndarray) -> list[frozenset]:
        """Every set of markers that may be the unseen ones: per colour, its shortfall of them."""
        from itertools import combinations, product

        per_colour = [list(combinations(np.flatnonzero(self.colour == c).tolist(), int(n)))
                      for c, n in enumerate(short) if n > 0]
        return [frozenset(m for group in pick for m in group) for pick in product(*per_colour)]

    def _combine(self, q: np.ndarray, trunk: _Part, arms: list[_Part], unseen: int,
                 best: list[tuple[float, np.ndarray]]) -> list[tuple[float, np.ndarray]]:
        """The two best whole labellings within reach, ``best`` (score, (M,) rows) so far included."""
        r, reach, tab = self.roles, self.reach, self.table
        right, left = arms
        if not len(trunk.rows) or not len(right.rows) or not len(left.rows):
            return best
        n_m = len(self.colour)
        bits = lambda rows: np.where(rows == unseen, 0, np.left_shift(1, np.minimum(rows, 62))).sum(axis=1)  # noqa: E731
        tb, rb, lb = bits(trunk.rows), bits(right.rows), bits(left.rows)
        # costs linking an arm to the trunk: every trunk x arm pair within reach, at once
        link = []
        for part, arm in ((right, r.arms[0]), (left, r.arms[1])):
            ti = np.repeat(np.arange(len(trunk.rows)), len(part.rows))
            ai = np.tile(np.arange(len(part.rows)), len(trunk.rows))
            pre = trunk.score[ti] + part.score[ai]
            sel = pre <= reach
            ti, ai, pre = ti[sel], ai[sel], pre[sel]
            sel = (tb[ti] & (rb if arm is r.arms[0] else lb)[ai]) == 0
            ti, ai, pre = ti[sel], ai[sel], pre[sel]
            limbs = np.stack([q[part.rows[ai, k]] for k in (1, 2, 3, 4)], axis=1)
            vals = bm.coupling_terms(self.prior, arm.sign, q[trunk.rows[ti, 0]], q[trunk.rows[ti, 1]],
                                     q[trunk.rows[ti, 3 if arm.sign > 0 else 2]], q[part.rows[ai, 0]], limbs)
            extra = bm.total(vals, tab)
            sel = pre + extra <= reach
            link.append((ti[sel], ai[sel], extra[sel]))
        # join on the trunk candidate
        best = list(best)
        bound = self._bound(best)
        (rt, ra, rx), (lt, la, lx) = link
        lsort = np.argsort(lt, kind="stable")
        lt, la, lx = lt[lsort], la[lsort], lx[lsort]
        starts = np.searchsorted(lt, np.arange(len(trunk.rows) + 1))
        for k in np.argsort(trunk.score[rt] + right.score[ra] + rx, kind="stable"):
            t, a, x = int(rt[k]), int(ra[k]), float(rx[k])
            base = trunk.score[t] + right.score[a] + x
            if base > bound:
                break
            js = np.arange(starts[t], starts[t + 1])
            if not len(js):
                continue
            tot = base + left.score[la[js]] + lx[js]
            js, tot = js[tot <= bound], tot[tot <= bound]
            js, tot = js[(lb[la[js]] & (tb[t] | rb[a])) == 0], tot[(lb[la[js]] & (tb[t] | rb[a])) == 0]
            if not len(js):
                continue
            shoulders = bm.norm(q[right.rows[a, 0]] - q[left.rows[la[js], 0]])
            tot = tot + bm.cost(shoulders, *tab["shoulders"])
            n_sym = len(bm.SYMMETRIC)
            diff = np.abs(right.lengths[a][None, :n_sym] - left.lengths[la[js], :n_sym])
            tot = tot + bm.cost(diff, *tab["symmetry"]).sum(axis=1)
            for name, col in bm.PROPORTIONS.items():
                tot = tot + bm.cost(right.lengths[a, col] / shoulders, *tab[name])
                tot = tot + bm.cost(left.lengths[la[js], col] / shoulders, *tab[name])
            for j, s in zip(js[tot <= bound], tot[tot <= bound]):
                rows = np.empty(n_m, np.int64)
                rows[list(r.trunk)] = trunk.rows[t]
                rows[list(r.arms[0].markers)] = right.rows[a]
                rows[list(r.arms[1].markers)] = left.rows[la[j]]
                best.append((float(s), rows))
                best.sort(key=lambda b: b[0])
                bound = self._bound(best)
                while best and best[-1][0] > bound:
                    best.pop()
                if len(best) > _MAX_NEAR:
                    raise _TooMany
        return best

    def _bound(self, best: list[tuple[float, np.ndarray]]) -> float:
        """Labellings scoring above this matter no more: beyond reach, or a margin past the best."""
        return min(self.reach, best[0][0] + self.min_margin) if best else self.reach
