"""The search for the labelling that best explains the points, with its confidence.

A labelling gives each marker one point of its own colour, or none ("unseen": at most the
colour's shortfall of points). The score of a labelling is the sum of the body model's costs
(:mod:`.prior`, summed by :mod:`.body_score`); the search finds every labelling whose score is
within ``reach`` = ``max_score + min_margin`` and keeps the two best. It builds the labelling in
parts (:mod:`.parts`: each arm, the trunk, then the three joined), each part's candidates scored
at once (numpy) and those beyond ``reach`` dropped, because every cost is >= 0 and a part's cost
is a lower bound of the whole.

Markers without a point that a single camera sees lie on the rays of its blobs
(:func:`tracking.labelling.rays.single_view_rays`): the labellings found with them unseen (a lower
bound of their score) are then placed on the rays, best first (:mod:`.on_rays`), and a ray that no
marker explains puts a labelling beyond reach.

The patient's frame (+y up, their right +x) comes from the horizontal spread of the points
(:func:`tracking.labelling.body_frame.yaw_from_points`), then from the best labelling's shoulders and hips;
the search is repeated in that frame when it turned more than a degree.

The labelling is *confident* when the best scores at most ``max_score`` and the second best at
least ``min_margin`` more. With one colour for all markers a wrong pair of elbow or wrist markers
turns the upper arm or the thumb by about 180 degrees: it scores in the hundreds, a margin the
right labelling keeps under every variation of the population (docs/TRACKING.md). When it is not,
:mod:`.advice` says why in one line.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np

from tracking.errors import ContentError
from tracking.labelling import prior as bm
from tracking.labelling.advice import advice
from tracking.labelling.body_frame import patient_axes, yaw_from_points
from tracking.labelling.body_score import BodyScore
from tracking.labelling.on_rays import RayPlacement, ray_samples
from tracking.labelling.parts import MAX_NEAR, PartSearch, TooMany, bound
from tracking.labelling.roles import BodyRoles

log = logging.getLogger(__name__)

# at most this many balls (points and unseen rows) in one search (a bit each)
_MAX_BALLS = 62
# at most this many ways to choose which markers of a colour are the ones without a point
_MAX_WAYS = 400
# with rays: at most this many labellings (best first, by their score without the markers on
# rays) are placed on the rays
_MAX_BOUNDS = 128
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
        self.body = BodyScore(roles, prior)
        self.table = self.body.table
        self.max_score = float(max_score)
        self.min_margin = float(min_margin)
        self.reach = self.max_score + self.min_margin
        self.max_turn_deg = float(max_turn_deg)
        self.max_unseen = int(max_unseen)
        self.max_on_rays = int(max_on_rays)
        self.radius_m = float(radius_m)
        self.parts = PartSearch(self.body, len(self.colour), self.reach, self.min_margin)

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
        samples, ray_col, ray_dir = ray_samples(pts, short, rays, self.radius_m)
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
        return self.body.terms_of(p_pat_m)

    def score_of(self, p_world_m: np.ndarray, index: np.ndarray, yaw_deg: float = 0.0) -> float:
        """The body model's score of a given labelling (index -1: unseen) in the frame of ``yaw_deg``."""
        return self.body.score_of(p_world_m, index, yaw_deg)

    def cost_of(self, name: str, value: float) -> float:
        """The cost of a value of :meth:`terms_of`."""
        return self.body.cost_of(name, value)

    def advice(self, lab: Labelling, names: tuple[str, ...]) -> str:
        """One line for the therapist on a labelling that is not confident (the fit's own words;
        the marker set's ordering rules say it in theirs first, see the tracker)."""
        return advice(lab, names, self.table, self.max_score)

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
        (:meth:`RayPlacement.place`), labelling by labelling in the order of their score without
        them (its terms that need them cost nothing: a lower bound), until no other can come
        within the margin of the best."""

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
        arms = [self.parts.arm(q, cand, arm, ball) for arm in self.roles.arms]
        trunk = self.parts.trunk(q, cand, ball)
        try:
            best, cut = self.parts.combine(q, trunk, arms, ball, kind, n_p, cap=_MAX_BOUNDS if len(ray_col) else 0)
        except TooMany:
            log.debug("more than %d labellings within a margin of the best: not confident", MAX_NEAR)
            return Labelling(None, math.inf, 0.0, False, yaw_deg)
        if len(ray_col) and best:
            placement = RayPlacement.in_frame(self.body, self.colour, self.reach, self.min_margin, self.radius_m,
                                              q[:n_p], col, centre, axes, samples, ray_dir, ray_col, free)
            best = placement.place_all(q, best, kind, cut)
        else:
            best = [(sc, rows, q[rows]) for sc, rows in best]
        if not best:
            return Labelling(None, math.inf, 0.0, False, yaw_deg)
        return self._confidence(best, kind, n_p, yaw_deg)

    def _confidence(self, best: list[tuple[float, np.ndarray, np.ndarray]], kind: np.ndarray, n_p: int,
                    yaw_deg: float) -> Labelling:
        """The labelling of ``best`` (the labellings within a margin of the best: (score, rows,
        (M, 3) positions), best first) with its margin, its worst term and its confidence."""
        # the markers every labelling within the margin names alike (the others: -1); a marker on
        # a ray or unseen is not named (it joins when two cameras see it)
        s0, rows0, p0 = best[0]
        keys = np.array([np.where(kind[b[1]] == 2, -1, b[1]) for b in best])
        agree = (keys == keys[:1]).all(axis=0)
        index = np.where(agree & (kind[rows0] == 0), rows0, -1)
        # every labelling that names a labelled marker otherwise scores above the bound
        margin = bound([b[:2] for b in best], self.reach, self.min_margin) - s0
        terms = self.terms_of(p0)
        costs = {k: self.cost_of(k, v) for k, v in terms.items()}
        name = max(costs, key=costs.get)
        worst = (name, terms[name]) if costs[name] > 0 else None
        # every seen point must be named alike by all of them: a point two labellings name
        # differently is not certain, and would be left to a re-acquisition that knows less
        confident = bool(s0 <= self.max_score and margin >= self.min_margin - 1e-9 and np.sum(index >= 0) == n_p)
        return Labelling(index, float(s0), float(margin), confident, yaw_deg, worst, terms,
                         tuple(np.flatnonzero(~agree).tolist()))
