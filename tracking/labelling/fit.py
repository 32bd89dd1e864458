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

Markers without a point that a single camera sees lie on the rays of its blobs
(:func:`tracking.labelling.rays.single_view_rays`): the labellings found with them unseen (a lower
bound of their score) are then placed on the rays, best first (:meth:`Labeller._on_rays`), and a
ray that no marker explains puts a labelling beyond reach.

The patient's frame (+y up, their right +x) comes from the horizontal spread of the points
(:func:`tracking.labelling.body_frame.yaw_from_points`), then from the best labelling's shoulders and hips;
the search is repeated in that frame when it turned more than a degree.

The labelling is *confident* when the best scores at most ``max_score`` and the second best at
least ``min_margin`` more. With one colour for all markers a wrong pair of elbow or wrist markers
turns the upper arm or the thumb by about 180 degrees: it scores in the hundreds, a margin the
right labelling keeps under every variation of the population (docs/TRACKING.md).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from itertools import permutations, product

import numpy as np

from tracking.errors import ContentError
from tracking.labelling import prior as bm
from tracking.labelling.body_frame import patient_axes, yaw_from_points
from tracking.labelling.rays import sample_ray
from tracking.labelling.roles import ArmRoles, BodyRoles

log = logging.getLogger(__name__)

# at most this many labellings within a margin of the best are weighed (more: not confident)
_MAX_NEAR = 64
# at most this many balls (points and unseen rows) in one search (a bit each)
_MAX_BALLS = 62
# with rays: at most this many labellings (best first, by their score without the markers on
# rays) are placed on the rays; at most this many assignments of markers to rays each; two
# markers' samples are placed jointly up to this many pairs, more by this many sweeps
_MAX_BOUNDS = 128
_MAX_WAYS = 400
_MAX_ASSIGN = 48
_MAX_JOINT = 1500
# with a coarser grid of sample pairs, every sample around this many best is tried
_REFINE = 3
_SWEEPS = 2
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
        yaw_deg: the patient frame's yaw (as :class:`tracking.labelling.rules.Identification`).
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


def _pairs(a: np.ndarray, b: np.ndarray, ball: np.ndarray) -> np.ndarray:
    """(N, 2) rows (p, q), p from ``a``, q from ``b``, of two different balls."""
    p, q = np.meshgrid(a, b, indexing="ij")
    p, q = p.ravel(), q.ravel()
    ok = ball[p] != ball[q]
    return np.stack([p[ok], q[ok]], axis=1)


def _distinct(rows: np.ndarray, ball: np.ndarray) -> np.ndarray:
    """(N,) no ball used twice in a row."""
    b = ball[rows]
    n = rows.shape[1]
    ok = np.ones(len(rows), bool)
    for i in range(n):
        for j in range(i + 1, n):
            ok &= b[:, i] != b[:, j]
    return ok


def _key(rows: np.ndarray, ball: np.ndarray, kind: np.ndarray) -> np.ndarray:
    """What a labelling says: each marker's ball (a point or a ray; -1 unseen, whichever row)."""
    return np.where(kind[rows] == 2, -1, ball[rows])


def _ray_samples(pts: np.ndarray, short: np.ndarray, rays, radius_m: float
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
        max_unseen: at most this many markers without a point and without a ray (seen by no
            camera, or more of a colour than its rays).
        max_on_rays: at most this many markers without a point (on rays or unseen).
        radius_m: the balls' radius (two balls do not overlap).
    """

    def __init__(self, roles: BodyRoles, colour: np.ndarray, prior: bm.BodyPrior = bm.BodyPrior(), *,
                 max_score: float = 9.0, min_margin: float = 16.0, max_turn_deg: float = 30.0, max_unseen: int = 2,
                 max_on_rays: int = 6, radius_m: float = 0.0125):
        self.roles = roles
        self.colour = np.asarray(colour, dtype=np.int64)
        self.prior = prior
        self.table = bm.ranges(prior)
        self.max_score = float(max_score)
        self.min_margin = float(min_margin)
        self.reach = self.max_score + self.min_margin
        self.max_turn_deg = float(max_turn_deg)
        self.max_unseen = int(max_unseen)
        self.max_on_rays = int(max_on_rays)
        self.radius_m = float(radius_m)

    @classmethod
    def for_markerset(cls, markerset, **kw) -> "Labeller":
        """The labeller of a marker set (its roles, colours, ball size and allowed turn).

        Raises:
            ContentError: the marker set's YAML does not name the body model's landmarks.
        """


        roles = BodyRoles.of(markerset)
        if roles is None:
            raise ContentError(
                f"marker set {markerset.name}: its hidden_markers section does not name the trunk, elbows and "
                "wrists the labelling's body model needs (trunk, elbows, forearms)")
        prior = replace(kw.pop("prior", bm.BodyPrior()), ball_offset_m=markerset.radius_m + markerset.soft_tissue_m)
        if markerset.identification is not None:
            kw.setdefault("max_turn_deg", markerset.identification.max_turn_deg)
        kw.setdefault("radius_m", markerset.radius_m)
        return cls(roles, markerset.colour_index, prior, **kw)

    # ------------------------------------------------------------------ public
    def takes(self, colour: np.ndarray, rays=None) -> bool:
        """Whether :meth:`label` searches these points at all: no colour with more points than
        markers, at most ``max_on_rays`` markers without a point, of them at most ``max_unseen``
        without a ray of their colour (:func:`tracking.labelling.rays.single_view_rays`) either, and at
        most ``_MAX_WAYS`` ways to choose which markers of a colour are the ones without a point
        (one colour: at most 3 of 14; the search's cost grows with them)."""
        short = self._short(np.asarray(colour, dtype=np.int64).reshape(-1))
        if short is None:
            return False
        n_rays = self._ray_counts(rays)
        want = np.bincount(self.colour, minlength=len(short))
        ways = math.prod(math.comb(int(w), int(k)) for w, k in zip(want, short))
        return bool(short.sum() <= self.max_on_rays and np.maximum(short - n_rays, 0).sum() <= self.max_unseen
                    and ways <= _MAX_WAYS)

    def label(self, p_world_m: np.ndarray, colour: np.ndarray, rays=None) -> Labelling:
        """The best labelling of the finite points and its confidence.

        Args:
            p_world_m: (P, 3) float64 points, world metres (rows with NaN are left out).
            colour: (P,) palette index of each point.
            rays: the blobs no point uses (:class:`tracking.labelling.rays.Rays`), or None: a marker
                without a point of a colour with rays lies on one of them, within the range its
                blob's size gives (the rest of them are unseen, at most ``max_unseen``).
        """

        p_world_m = np.asarray(p_world_m, dtype=np.float64).reshape(-1, 3)
        colour = np.asarray(colour, dtype=np.int64).reshape(-1)
        keep = np.flatnonzero(np.isfinite(p_world_m).all(axis=1))
        pts, col = p_world_m[keep], colour[keep]
        short = self._short(col)
        if short is None or len(pts) < 3 or not self.takes(col, rays):
            return Labelling(None, math.inf, 0.0, False, 0.0)
        samples, ray_col, ray_dir = _ray_samples(pts, short, rays, self.radius_m)
        free = np.maximum(short - np.bincount(ray_col, minlength=len(short)), 0)
        if free.sum() > self.max_unseen or len(pts) + short.sum() > _MAX_BALLS:
            return Labelling(None, math.inf, 0.0, False, 0.0)
        limit = self.max_turn_deg
        yaw = float(np.clip(math.degrees(yaw_from_points(pts)), -limit, limit))
        result = None
        for _ in range(_MAX_REFINE + 1):
            with np.errstate(invalid="ignore", divide="ignore"):  # unseen markers: NaN terms cost 0
                result = self._label_in(pts, col, samples, ray_col, ray_dir, free, yaw)
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

    def _short(self, col: np.ndarray) -> np.ndarray | None:
        """(n colours,) markers short of a point, per colour; None when a colour has too many
        points or a point has no colour of the marker set."""
        n_col = int(self.colour.max()) + 1
        if np.any((col < 0) | (col >= n_col)):
            return None
        short = np.bincount(self.colour, minlength=n_col) - np.bincount(col, minlength=n_col)
        return None if np.any(short < 0) else short

    def _ray_counts(self, rays) -> np.ndarray:
        n_col = int(self.colour.max()) + 1
        if rays is None or not len(rays):
            return np.zeros(n_col, np.int64)
        c = np.asarray(rays.colour, dtype=np.int64)
        return np.bincount(c[(c >= 0) & (c < n_col)], minlength=n_col)

    def terms_of(self, p_pat_m: np.ndarray) -> dict[str, float]:
        """Every term's value for labelled marker positions in the patient's frame ((M, 3), NaN unseen)."""
        return {k: float(v[0]) for k, v in self._terms(np.asarray(p_pat_m, dtype=np.float64)[None]).items()}

    def _terms(self, p: np.ndarray) -> dict[str, np.ndarray]:
        """:meth:`terms_of` of a batch of labellings' positions ((N, M, 3)): name -> (N,) values."""
        r = self.roles
        out: dict[str, np.ndarray] = dict(bm.trunk_terms(self.prior, *(p[:, k] for k in r.trunk)))
        for arm in r.arms:
            s, e1, e2, w1, w2 = (p[:, k] for k in arm.markers)
            vals = {**bm.upper_arm_terms(self.prior, arm.sign, s, e1, e2),
                    **bm.forearm_terms(self.prior, arm.sign, s, e1, e2, w1, w2),
                    **bm.coupling_terms(self.prior, arm.sign, p[:, r.upper], p[:, r.lower],
                                        p[:, r.right_hip if arm.sign > 0 else r.left_hip], s,
                                        np.stack([e1, e2, w1, w2], axis=1))}
            out.update({f"{arm.side} {k}": v for k, v in vals.items()})
        a, b = (p[:, arm.shoulder] for arm in r.arms)
        out["shoulders"] = bm.norm(a - b)
        for name in bm.SYMMETRIC:
            out[f"symmetry {name}"] = np.abs(out[f"right {name}"] - out[f"left {name}"])
        for side in ("right", "left"):
            out[f"{side} upper_arm_ratio"] = out[f"{side} upper_arm"] / out["shoulders"]
            out[f"{side} reach_ratio"] = out[f"{side} reach"] / out["shoulders"]
        return out

    def _scores(self, p: np.ndarray) -> np.ndarray:
        """(N,) the scores of a batch of labellings' positions ((N, M, 3), patient frame)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            total = np.zeros(len(p))
            for k, v in self._terms(p).items():
                key = "symmetry" if k.startswith("symmetry") else k.split(" ")[-1]
                total = total + bm.cost(v, *self.table[key])
            return total

    def score_of(self, p_world_m: np.ndarray, index: np.ndarray, yaw_deg: float = 0.0) -> float:
        """The body model's score of a given labelling (index -1: unseen) in the frame of ``yaw_deg``."""

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

    def _label_in(self, pts: np.ndarray, col: np.ndarray, samples: list[np.ndarray], ray_col: np.ndarray,
                  ray_dir: np.ndarray, free: np.ndarray, yaw_deg: float) -> Labelling:
        """One search in the frame of ``yaw_deg``. The candidates of a marker are the rows of its
        colour: the points and, per colour, as many unseen rows (NaN) as it is short of points.
        Every row is one ball: no labelling uses a ball twice, and every point is used (so the
        markers without a point are exactly the colours' shortfall). Without rays that is the
        search. With rays, the markers without a point are then put on the rays
        (:meth:`_place`), labelling by labelling in the order of their score without them (its
        terms that need them cost nothing: a lower bound), until no other can come within the
        margin of the best."""

        axes = patient_axes(math.radians(yaw_deg))
        centre = pts.mean(axis=0)
        n_p = len(pts)
        short = self._short(col)  # (without rays: ``free``)
        slot_col = np.repeat(np.arange(len(short)), short)
        q = np.vstack([(pts - centre) @ axes, np.full((len(slot_col), 3), np.nan)])
        row_col = np.concatenate([col, slot_col]).astype(np.int64)
        ball = np.arange(len(q))
        kind = np.concatenate([np.zeros(n_p, np.int8), np.full(len(slot_col), 2, np.int8)])
        cand = [np.flatnonzero(row_col == c).astype(np.int64) for c in self.colour]
        arms = [self._arm(q, cand, arm, ball) for arm in self.roles.arms]
        trunk = self._trunk(q, cand, ball)
        try:
            best, cut = self._combine(q, trunk, arms, ball, kind, n_p, cap=_MAX_BOUNDS if len(ray_col) else 0)
        except _TooMany:
            log.debug("more than %d labellings within a margin of the best: not confident", _MAX_NEAR)
            return Labelling(None, math.inf, 0.0, False, yaw_deg)
        if len(ray_col) and best:
            on = [(s - centre) @ axes for s in samples]
            origin, direction = np.array([o[0] for o in on]), ray_dir @ axes
            qp = q[:n_p]
            rel = qp[:, None, :] - origin[None]
            off = np.linalg.norm(rel - np.einsum("pri,ri->pr", rel, direction)[..., None] * direction[None], axis=-1)
            by_point = ((off < 2.0 * self.radius_m) & (col[:, None] == ray_col[None])).any(axis=0)
            self._lines = (origin, direction, ray_col, by_point)
            best = self._on_rays(q, best, kind, on, ray_col, free, cut)
        else:
            best = [(sc, rows, q[rows]) for sc, rows in best]
        if not best:
            return Labelling(None, math.inf, 0.0, False, yaw_deg)
        # the markers every labelling within the margin names alike (the others: -1); a marker on
        # a ray or unseen is not named (it joins when two cameras see it)
        s0, rows0, p0 = best[0]
        keys = np.array([np.where(kind[b[1]] == 2, -1, b[1]) for b in best])
        agree = (keys == keys[:1]).all(axis=0)
        index = np.where(agree & (kind[rows0] == 0), rows0, -1)
        # every labelling that names a labelled marker otherwise scores above the bound
        margin = self._bound([b[:2] for b in best]) - s0
        terms = self.terms_of(p0)
        costs = {k: self.cost_of(k, v) for k, v in terms.items()}
        name = max(costs, key=costs.get)
        worst = (name, terms[name]) if costs[name] > 0 else None
        # every seen point must be named alike by all of them: a point two labellings name
        # differently is not certain, and would be left to a re-acquisition that knows less
        confident = bool(s0 <= self.max_score and margin >= self.min_margin - 1e-9 and np.sum(index >= 0) == n_p)
        return Labelling(index, float(s0), float(margin), confident, yaw_deg, worst, terms,
                         tuple(np.flatnonzero(~agree).tolist()))

    def _on_rays(self, q: np.ndarray, bounds: list[tuple[float, np.ndarray]], kind: np.ndarray,
                 on: list[np.ndarray], ray_col: np.ndarray, free: np.ndarray, cut: float) -> list:
        """The labellings of ``bounds`` (lower bounds, best first) with their markers without a
        point placed on rays (:meth:`_place`), within a margin of the best: (score, rows, (M, 3)
        positions), best first. A labelling that no placement keeps within reach is dropped.
        ``cut``: the search looked at no labelling scoring more (without rays); when the margin
        of the best reaches past it, labellings not looked at could be near: none (not confident)."""
        out: list[tuple[float, np.ndarray, np.ndarray]] = []
        for lb, rows in bounds:
            if lb > self._bound([o[:2] for o in out]):
                break
            placed = self._place(q[rows], np.flatnonzero(kind[rows] != 0), on, ray_col, free, lb)
            if placed is None or placed[0] > self._bound([o[:2] for o in out]):
                continue
            out.append((placed[0], rows, placed[1]))
            out.sort(key=lambda o: o[0])
            bound = self._bound([o[:2] for o in out])
            out = [o for o in out if o[0] <= bound]
            if len(out) > _MAX_NEAR:
                return []
        if out and self._bound([o[:2] for o in out]) > cut + 1e-9:
            log.debug("the labellings without rays were cut at %.1f: not confident", cut)
            return []
        return out

    def _place(self, p: np.ndarray, without: np.ndarray, on: list[np.ndarray], ray_col: np.ndarray,
               free: np.ndarray, lower: float) -> tuple[float, np.ndarray] | None:
        """The best score of one labelling ((M, 3) patient-frame positions, NaN at the markers
        ``without`` a point) with each of those markers on its own ray of its colour (or unseen,
        at most ``free`` of a colour), at the ray's sample that scores best: every assignment of
        markers to rays, the samples of two markers jointly, of more by turns (two sweeps from
        each one's best alone; two markers' pairs beyond ``_MAX_JOINT`` on a coarser grid first,
        then every pair around the best few). Returns (score, positions) or None. With more than
        ``_MAX_ASSIGN`` assignments: ``lower`` (its score without them) and the positions
        without them, so that it counts as near as it might be."""

        by_colour: dict[int, list[int]] = {}
        for m in without.tolist():
            by_colour.setdefault(int(self.colour[m]), []).append(m)
        per_colour = []
        for c, ms in by_colour.items():
            rays_c = np.flatnonzero(ray_col == c).tolist() + [-1] * int(free[c])
            per_colour.append([(ms, pick) for pick in dict.fromkeys(permutations(rays_c, len(ms)))])
        best: tuple[float, np.ndarray] | None = None
        n_done = 0
        # the assignments of at most two markers on rays: every sample (pair) in one batch, every
        # ``stride``-th where the pairs are too many, then every sample around the best few
        grids, where, many = [], [], []
        everyone = [(m, -1) for m in without.tolist()]
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
        for score, pos in self._best_samples_many(p, many, on):
            if best is None or score < best[0]:
                best = (score, pos)
        if grids:
            lens = [len(g) for g in grids]
            sc = np.concatenate([self._objective(g, everyone) for g in grids])
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
                fs = self._objective(fine, everyone)
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

    def _objective(self, p: np.ndarray, placed: list[tuple[int, int]]) -> np.ndarray:
        """(N,) the scores of a batch of positions ((N, M, 3)) with markers ``placed`` on rays,
        plus ``reach`` for every ray that neither a point nor a marker on a ray explains (passes
        within a ball's diameter of): a blob is a ball of its colour, and a labelling that leaves
        one without a marker does not explain what the cameras see (the two rays of one ball seen
        whole by one camera and partly hidden by another meet at the ball: one marker explains
        both). Stray blobs (clutter) leave every labelling beyond reach: nothing is named."""
        score = self._scores(p)
        origin, direction, colour, by_point = self._lines
        if not len(colour):
            return score
        explained = np.repeat(by_point[None], len(p), axis=0)
        for m, _ in placed:  # (a marker left unseen, NaN, explains nothing)
            rel = p[:, m, None, :] - origin[None]                       # (N, R, 3)
            along = np.einsum("nri,ri->nr", rel, direction)
            off = np.linalg.norm(rel - along[..., None] * direction[None], axis=-1)
            explained |= (off < 2.0 * self.radius_m) & (colour[None] == self.colour[m])
        return score + self.reach * (~explained).sum(axis=1)

    def _best_samples_many(self, p: np.ndarray, many: list[list[tuple[int, int]]], on: list[np.ndarray]
                           ) -> list[tuple[float, np.ndarray]]:
        """The markers of each assignment in ``many`` (more than two markers on rays each, in their
        order) at their rays' best samples: each alone (the others without a point), then by
        turns (``_SWEEPS``): (score, positions) each. The assignments that place the same markers
        go through their turns together, each turn one scoring batch for all of them (the scores
        of a batch's rows are independent of each other), instead of one batch per assignment
        and turn (thousands of small batches for four to six markers on rays, seconds per frame
        set)."""
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
                sc = self._objective(batch, placed0)
                starts = np.concatenate([[0], np.cumsum(lens)[:-1]])
                k = np.array([s0 + int(np.argmin(sc[s0:s0 + n])) for s0, n in zip(starts, lens)])
                pos[:] = batch[k]
                return sc[k]

            for j in range(len(markers)):
                turn(j)
            score = self._objective(pos, placed0)
            for _ in range(_SWEEPS):
                for j in range(len(markers)):
                    score = turn(j)
            for a, i in enumerate(items):
                out[i] = (float(score[a]), pos[a].copy())
        return out

    def _arm(self, q: np.ndarray, cand: list[np.ndarray], arm: ArmRoles, ball: np.ndarray) -> _Part:
        """Candidates (shoulder, E1, E2, W1, W2) of one arm within reach."""
        pr, tab, reach = self.prior, self.table, self.reach
        s_i, e1_i, e2_i, w1_i, w2_i = arm.markers
        elbow = _pairs(cand[e1_i], cand[e2_i], ball)
        width = bm.cost(bm.norm(q[elbow[:, 0]] - q[elbow[:, 1]]), *tab["elbow_width"])
        elbow, width = elbow[width <= reach], width[width <= reach]
        # shoulder x elbow pairs
        si = np.repeat(cand[s_i], len(elbow))
        ei = np.tile(elbow, (len(cand[s_i]), 1))
        w0 = np.tile(width, len(cand[s_i]))
        rows = np.column_stack([si, ei])
        ok = _distinct(rows, ball)
        rows, w0 = rows[ok], w0[ok]
        vals = bm.upper_arm_terms(pr, arm.sign, q[rows[:, 0]], q[rows[:, 1]], q[rows[:, 2]])
        vals.pop("elbow_width")
        upper = _Part(rows, w0 + bm.total(vals, tab))
        upper = upper.keep(upper.score <= reach)
        wrist = _pairs(cand[w1_i], cand[w2_i], ball)
        ww = bm.cost(bm.norm(q[wrist[:, 0]] - q[wrist[:, 1]]), *tab["wrist_width"])
        wrist, ww = wrist[ww <= reach], ww[ww <= reach]
        if not len(upper.rows) or not len(wrist):
            return _Part(np.zeros((0, 5), np.int64), np.zeros(0))
        a = np.repeat(np.arange(len(upper.rows)), len(wrist))
        b = np.tile(np.arange(len(wrist)), len(upper.rows))
        pre = upper.score[a] + ww[b]
        a, b, pre = a[pre <= reach], b[pre <= reach], pre[pre <= reach]
        rows = np.column_stack([upper.rows[a], wrist[b]])
        ok = _distinct(rows, ball)
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

    def _trunk(self, q: np.ndarray, cand: list[np.ndarray], ball: np.ndarray) -> _Part:
        """Candidates (upper, lower, left hip, right hip) within reach."""
        r = self.roles
        ul = _pairs(cand[r.upper], cand[r.lower], ball)
        hips = _pairs(cand[r.left_hip], cand[r.right_hip], ball)
        a = np.repeat(np.arange(len(ul)), len(hips))
        b = np.tile(np.arange(len(hips)), len(ul))
        rows = np.column_stack([ul[a], hips[b]])
        rows = rows[_distinct(rows, ball)]
        vals = bm.trunk_terms(self.prior, *(q[rows[:, k]] for k in range(4)))
        part = _Part(rows, bm.total(vals, self.table))
        return part.keep(part.score <= self.reach).sorted()

    def _combine(self, q: np.ndarray, trunk: _Part, arms: list[_Part], ball: np.ndarray, kind: np.ndarray,
                 n_points: int, cap: int = 0) -> tuple[list[tuple[float, np.ndarray]], float]:
        """The whole labellings within a margin of the best (score, (M,) rows), best first, each
        labelling once (:func:`_key`: unseen rows are alike), every point used. With ``cap``: the
        ``cap`` best within reach instead (their scores are lower bounds, placed later on rays).

        Returns:
            (the labellings, the score above which none was looked at)."""
        r, reach, tab = self.roles, self.reach, self.table
        right, left = arms
        if not len(trunk.rows) or not len(right.rows) or not len(left.rows):
            return [], reach
        n_m = len(self.colour)
        bits = lambda rows: np.left_shift(np.int64(1), ball[rows]).sum(axis=1)  # noqa: E731  (balls differ)
        n_pts = lambda rows: (kind[rows] == 0).sum(axis=1)  # noqa: E731
        tb, rb, lb = bits(trunk.rows), bits(right.rows), bits(left.rows)
        tn, rn, ln = n_pts(trunk.rows), n_pts(right.rows), n_pts(left.rows)
        # costs linking an arm to the trunk: every trunk x arm pair within reach, at once
        link = []
        for part, arm, pb, pn, other in ((right, r.arms[0], rb, rn, ln), (left, r.arms[1], lb, ln, rn)):
            ti = np.repeat(np.arange(len(trunk.rows)), len(part.rows))
            ai = np.tile(np.arange(len(part.rows)), len(trunk.rows))
            pre = trunk.score[ti] + part.score[ai]
            # within reach, no ball used twice, and the other arm can still use the points left
            sel = (pre <= reach) & ((tb[ti] & pb[ai]) == 0) & (tn[ti] + pn[ai] + other.max() >= n_points)
            ti, ai, pre = ti[sel], ai[sel], pre[sel]
            limbs = np.stack([q[part.rows[ai, k]] for k in (1, 2, 3, 4)], axis=1)
            vals = bm.coupling_terms(self.prior, arm.sign, q[trunk.rows[ti, 0]], q[trunk.rows[ti, 1]],
                                     q[trunk.rows[ti, 3 if arm.sign > 0 else 2]], q[part.rows[ai, 0]], limbs)
            extra = bm.total(vals, tab)
            sel = pre + extra <= reach
            link.append((ti[sel], ai[sel], extra[sel]))
        # join on the trunk candidate
        best: list[tuple[float, np.ndarray]] = []
        seen_keys: dict[bytes, float] = {}
        bound_of = (lambda b: reach if len(b) < cap else b[-1][0]) if cap else self._bound  # noqa: E731
        bound = bound_of(best)
        (rt, ra, rx), (lt, la, lx) = link
        lsort = np.argsort(lt, kind="stable")
        lt, la, lx = lt[lsort], la[lsort], lx[lsort]
        starts = np.searchsorted(lt, np.arange(len(trunk.rows) + 1))
        n_sym = len(bm.SYMMETRIC)
        for k in np.argsort(trunk.score[rt] + right.score[ra] + rx, kind="stable"):
            t, a, x = int(rt[k]), int(ra[k]), float(rx[k])
            base = trunk.score[t] + right.score[a] + x
            if base > bound:
                break
            js = np.arange(starts[t], starts[t + 1])
            if not len(js):
                continue
            tot = base + left.score[la[js]] + lx[js]
            ok = (tot <= bound) & ((lb[la[js]] & (tb[t] | rb[a])) == 0) & (tn[t] + rn[a] + ln[la[js]] == n_points)
            js, tot = js[ok], tot[ok]
            if not len(js):
                continue
            shoulders = bm.norm(q[right.rows[a, 0]] - q[left.rows[la[js], 0]])
            tot = tot + bm.cost(shoulders, *tab["shoulders"])
            diff = np.abs(right.lengths[a][None, :n_sym] - left.lengths[la[js], :n_sym])
            tot = tot + bm.cost(diff, *tab["symmetry"]).sum(axis=1)
            for name, c in bm.PROPORTIONS.items():
                tot = tot + bm.cost(right.lengths[a, c] / shoulders, *tab[name])
                tot = tot + bm.cost(left.lengths[la[js], c] / shoulders, *tab[name])
            for j, s in zip(js[tot <= bound], tot[tot <= bound]):
                rows = np.empty(n_m, np.int64)
                rows[list(r.trunk)] = trunk.rows[t]
                rows[list(r.arms[0].markers)] = right.rows[a]
                rows[list(r.arms[1].markers)] = left.rows[la[j]]
                key = _key(rows, ball, kind).tobytes()
                if key in seen_keys:
                    if seen_keys[key] <= s:
                        continue
                    best = [b for b in best if _key(b[1], ball, kind).tobytes() != key]
                seen_keys[key] = float(s)
                best.append((float(s), rows))
                best.sort(key=lambda b: b[0])
                if cap and len(best) > cap:
                    best.pop()
                bound = bound_of(best)
                while best and best[-1][0] > bound:
                    best.pop()
                if not cap and len(best) > _MAX_NEAR:
                    raise _TooMany
        return best, bound

    def _bound(self, best: list[tuple[float, np.ndarray]]) -> float:
        """Labellings scoring above this matter no more: beyond reach, or a margin past the best."""
        return min(self.reach, best[0][0] + self.min_margin) if best else self.reach
