"""Identification (labelling) of the markers on the first frame, from the marker set's rules.

docs/METHOD.md 5.2: the patient starts in a reference pose in which the markers keep known orderings
along the axes of the patient's frame (the left arm left of the sternum, the elbow above the
wrist, the thumb-side wrist marker in front of the little-finger-side one, ...). The seed sorts
the 14 points by hand-written steps; here the orderings are data (``identification:`` in the
marker-set YAML, :class:`tracking.markerset.OrderRule`), so any marker set can state its own.

The search
    Every rule is a set of pairwise constraints on two markers: an ordering
    ``sign * (c_b - c_a) >= min_margin`` on one patient-frame coordinate, or a distance range
    ``lo <= |p_b - p_a| <= hi`` (markers on one bone; these keep a wrong pose, or points all of
    one colour, from being "explained" by swapping markers between body parts). Markers are the
    variables; a marker's domain is the points of its colour. A depth-first search assigns the marker with the fewest candidates left
    (colour classes of one point first), and after each assignment removes from every
    constrained neighbour's domain the points that would break a constraint with it (forward
    checking on bitsets). It is a branch and bound on the worst margin: after each complete
    assignment the bar rises to its worst margin, so the result is the assignment whose worst
    rule margin is largest. Points of one colour for all 14 markers (the seed's setup) take
    ~5 ms (4 colours ~3 ms).

Explaining a failure
    When no assignment satisfies the rules, the same search with the bar lowered below zero finds
    the one that breaks them least (largest worst margin), keeping the distance rules hard where
    possible (they hold in any pose, so the near-assignment then differs from the reference pose
    only by the pose); the worst-broken rule's message is what the therapist is told. This takes
    up to ~150 ms with one colour (a few ms with four). With one colour a pose that mirrors a
    valid one (palms turned back: the two wrist markers swap places) cannot be told from it.

The patient's frame
    +Y is up (calibration fixes it). The patient may sit turned about the vertical: the first
    guess of their right (+x) is the principal axis of the points' horizontal spread (the
    reference pose is wide left-right and shallow front-back), signed towards world +X and
    limited to ``max_turn_deg``. After a search the frame is re-estimated from the identified
    ``left_right_pairs`` (shoulders and hips) and the search repeated in that frame until it
    settles. If the first guess finds nothing, the world frame itself (facing -Z) is tried. A
    patient turned beyond ``max_turn_deg`` (the rules hold in their own frame) is told to turn
    the chair. Coordinates are relative to the points' centroid: nothing depends on the origin.

Unseen markers
    In some camera layouts a marker of the reference pose is seen by one camera only (the inner
    elbow marker, half hidden by the trunk) and gets no 3D point. Each unseen marker then gets a
    stand-in point that satisfies every rule: the search names the seen points, and the names
    are given when no other naming comes near satisfying the rules (the tracker's re-acquisition
    finds the unseen marker later, by the rules' distances to its named neighbours). A wrong pose
    often hides markers too: the stand-ins let the explanation name the broken rule anyway.

Markers on rays
    A stand-in checks nothing, so with more than three unseen the names are not given (wrong
    poses fitted). But a marker seen by one camera is not unknown: it lies on the ray through
    its blob, at a distance its blob's size bounds (:func:`single_view_rays`). Such a ray is a
    candidate point of the search, sampled along its range; a naming puts its markers on rays
    at the samples that keep the rules best, so the rules check them too, and the search stays
    as small as with points (one candidate per ray). Two rays of one colour from two cameras
    that meet are one ball whose second view is partly hidden, or two balls: both readings are
    searched and must agree.

For the tracker: :func:`try_identify` returns None while the names are not certain (too many
markers unseen, a stray point: wait for the next frame) and raises :class:`IdentificationError`
when the pose breaks the rules.
"""

from __future__ import annotations

import colorsys
import logging
import math
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from calibration.camera import Camera
from calibration.errors import RehabError
from tracking.errors import ContentError
from tracking.markerset import IdentificationRules, MarkerSet, OrderRule
from tracking.reconstruction import CameraObservations, Points3D

log = logging.getLogger(__name__)

# the principal axis of the horizontal spread is trusted when the spread is this much wider than deep
_MIN_SPREAD_RATIO = 1.5
_REFINE_TOL_DEG = 1.0
_MAX_REFINE = 3
# every rule holds (up to rounding)
_SATISFIED = -1e-12
# relaxed bars for explaining a failure: the best near-assignment is looked for above each in turn
_RELAXED_BARS_M = (-0.02, -0.05, -0.1, -0.15, -0.2, -0.3, -0.5, -math.inf)
# a marker seen by one camera lies on the ray through its blob, between these multiples of the
# distance that the blob's size gives: a whole (round) blob gives it within a few per cent, a
# partly hidden ball looks smaller, so farther (measured 0.98-1.03 times it for blobs of roundness
# 0.88 or more, 0.68-0.92 below, in the sweep's layouts)
_RAY_NEAR_WHOLE, _RAY_FAR_WHOLE, _RAY_NEAR, _RAY_FAR = 0.92, 1.08, 0.55, 1.08
_ROUND = 0.9
# points along a ray are tried this far apart, within this margin around the seen points
_RAY_STEP_M = 0.015
_RAY_BOX_M = 0.4
# markers on rays that share a rule are placed together up to this many sample combinations
_MAX_JOINT = 200_000


class IdentificationError(RehabError):
    """The markers cannot be identified: a marker is missing or the pose breaks a rule."""


@dataclass(frozen=True, slots=True)
class Identification:
    """Which point is which marker.

    Attributes:
        index: (M,) int64 index into the points for each marker of the marker set (marker-set
            order), -1 for an unseen marker (only from :meth:`Identifier.identify_with_unseen`;
            :func:`identify` needs every marker).
        margin_m: the worst rule margin: min over rules of (separation - the rule's min margin),
            metres; >= 0 when every rule holds.
        rule_margins_m: (R,) float64 margin of each rule of ``markerset.identification.rules``.
        yaw_deg: the patient frame the rules were checked in: the patient's right is
            (cos, 0, -sin)(yaw) in world coordinates, i.e. the frame is turned about +Y by the
            right-hand rule from facing -Z (positive: the patient turned towards their left).
    """

    index: np.ndarray
    margin_m: float
    rule_margins_m: np.ndarray
    yaw_deg: float


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
        round_ = obs.roundness[k] >= _ROUND if obs.roundness is not None else np.zeros(len(k), bool)
        near = np.where(round_, _RAY_NEAR_WHOLE, _RAY_NEAR)
        far = np.where(round_, _RAY_FAR_WHOLE, _RAY_FAR)
        rng.append(np.stack([near[keep] * dist[keep], far[keep] * dist[keep]], axis=1))
        whole.append(round_[keep])
    if not colour:
        return Rays(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0, bool))
    return Rays(np.concatenate(origin).astype(np.float64), np.concatenate(direction), np.concatenate(colour).astype(np.int64),
                np.concatenate(rng), np.concatenate(whole))


def sample_ray(rays: Rays, r: int, p_seen_m: np.ndarray, radius_m: float) -> np.ndarray:
    """(S, 3) the places of ray ``r``'s ball to try: every ``_RAY_STEP_M`` over its range, within
    ``_RAY_BOX_M`` of the seen points' box and not inside a seen ball (two balls do not overlap)."""
    lo, hi = p_seen_m.min(axis=0) - _RAY_BOX_M, p_seen_m.max(axis=0) + _RAY_BOX_M
    near, far = rays.range_m[r]
    t = np.arange(near, far + 0.5 * _RAY_STEP_M, _RAY_STEP_M)
    p = rays.origin_m[r] + t[:, None] * rays.direction[r]
    ok = ((p >= lo) & (p <= hi)).all(axis=1)
    ok &= np.linalg.norm(p[:, None, :] - p_seen_m[None], axis=-1).min(axis=1) > 2.0 * radius_m - _RAY_STEP_M
    return p[ok]


def colour_word(rgb: Iterable[int]) -> str:
    """A plain colour name for an sRGB colour (0-255), by hue: 'yellow', 'cyan', ..."""
    r, g, b = (float(c) / 255.0 for c in rgb)
    h, s, v = colorsys.rgb_to_hsv(r, g, b)
    if v < 0.2:
        return "black"
    if s < 0.25:
        return "white" if v > 0.8 else "grey"
    hue = h * 360.0
    for limit, word in ((15, "red"), (40, "orange"), (70, "yellow"), (165, "green"), (200, "cyan"),
                        (255, "blue"), (290, "purple"), (345, "magenta")):
        if hue < limit:
            return word
    return "red"


def palette_words(palette: np.ndarray) -> list[str]:
    """Colour names of a (K, 3) palette, with the RGB added where two colours share a name."""
    words = [colour_word(c) for c in palette]
    return [w if words.count(w) == 1 else f"{w} ({','.join(str(int(v)) for v in c)})" for w, c in zip(words, palette)]


def patient_axes(yaw_rad: float) -> np.ndarray:
    """(3, 3) columns: the patient's right, up and backwards in world coordinates."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def yaw_from_points(p_world_m: np.ndarray) -> float:
    """First guess of the patient's yaw (radians): the principal axis of the horizontal spread.

    The sign is the one closer to world +X (the patient roughly faces -Z); an isotropic spread
    (no clear left-right axis) gives 0.
    """
    h = p_world_m[:, [0, 2]] - p_world_m[:, [0, 2]].mean(axis=0)
    evals, evecs = np.linalg.eigh(h.T @ h)
    if evals[1] < _MIN_SPREAD_RATIO * max(evals[0], 1e-12):
        return 0.0
    ex, ez = evecs[:, 1]
    if ex < 0:
        ex, ez = -ex, -ez
    return math.atan2(-ez, ex)


def _bitsets(ok: np.ndarray) -> list[list[int]]:
    """(..., P) bool -> nested lists of ints with bit q set where ``ok[..., q]``."""
    n = ok.shape[-1]
    if n <= 62:
        return (ok.astype(np.int64) @ (np.int64(1) << np.arange(n, dtype=np.int64))).tolist()
    packed = np.packbits(ok, axis=-1, bitorder="little")
    return [[int.from_bytes(row.tobytes(), "little") for row in m] for m in packed]


def _yaw_from_pairs(p_world_m: np.ndarray, pairs: np.ndarray, default: float = 0.0) -> float:
    """Yaw (radians) from the mean horizontal left -> right direction of (left, right) points.

    Pairs with a stand-in (NaN) point are left out; ``default`` when none is left.
    """
    d = p_world_m[pairs[:, 1]] - p_world_m[pairs[:, 0]]
    d = d[np.isfinite(d).all(axis=1)][:, [0, 2]]
    if len(d) == 0:
        return default
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    vx, vz = d.sum(axis=0)
    return math.atan2(-vz, vx)


@dataclass(frozen=True, slots=True)
class _Pools:
    """Groups of points of which a naming may take at most so many (for :func:`_branch_and_bound`).

    Attributes:
        mask: per pool, the bitset of its points.
        size: per pool, how many of its points may be taken.
        of_point: point -> the pools it belongs to.
    """

    mask: tuple[int, ...]
    size: tuple[int, ...]
    of_point: dict[int, tuple[int, ...]]

    @staticmethod
    def of(groups: Iterable[tuple[np.ndarray, int]]) -> "_Pools":
        """From (point indices, how many may be taken) per pool."""
        mask, size, of_point = [], [], {}
        for k, (rows, n) in enumerate(groups):
            mask.append(sum(1 << int(q) for q in rows))
            size.append(int(n))
            for q in rows:
                of_point[int(q)] = of_point.get(int(q), ()) + (k,)
        return _Pools(tuple(mask), tuple(size), of_point)


@dataclass(frozen=True, slots=True)
class _RayRows:
    """Rays as points of a search: the searched points from ``first`` on (NaN rows) are rays,
    ray k sampled at ``samples[k]``; in the extended points (the rows before ``first``, then every
    sample) ray k's samples are the rows ``starts[first + k]`` on."""

    first: int
    samples: tuple[np.ndarray, ...]
    starts: np.ndarray
    key: bytes

    @staticmethod
    def of(first: int, samples: Sequence[np.ndarray]) -> "_RayRows":
        counts = [len(p) for p in samples]
        starts = np.concatenate([np.arange(first), first + np.cumsum([0] + counts[:-1])]).astype(np.int64)
        return _RayRows(first, tuple(samples), starts, b"".join(p.tobytes() for p in samples))

    def rows(self, point: int) -> np.ndarray:
        """Rows of the extended points of the ray that is searched point ``point``."""
        k = point - self.first
        return self.starts[point] + np.arange(len(self.samples[k]))


@dataclass(frozen=True, slots=True)
class _Blocks:
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


@dataclass(frozen=True, slots=True)
class _Found:
    index: np.ndarray
    slack_m: np.ndarray  # (K,) per constraint
    yaw: float
    nodes: int


class Identifier:
    """The rules of a marker set compiled into pairwise constraints, ready for many frames.

    Args:
        markerset: the marker set; its ``identification`` rules are used unless ``rules`` is given.
        rules: other rules (e.g. for a different reference pose).
        max_nodes: search-node budget per search (a safety bound for the live tracker; a search
            under the rules' bar needs a few hundred).
        max_unseen: :meth:`identify_with_unseen` names the markers with at most this many unseen.
        max_explained_unseen: with up to this many unseen, a pose that breaks the rules is still
            explained (a wrong pose often hides markers); with more, the point counts are reported.
    """

    def __init__(self, markerset: MarkerSet, rules: IdentificationRules | None = None, *, max_nodes: int = 200_000,
                 max_unseen: int = 3, max_explained_unseen: int = 4):
        rules = rules if rules is not None else markerset.identification
        if rules is None:
            raise ContentError(
                f"marker set {markerset.name} has no identification rules: add an 'identification:' section to its YAML"
            )
        self.markerset = markerset
        self.rules = rules
        self.max_nodes = max_nodes
        self.max_unseen = max_unseen
        self.max_explained_unseen = max_explained_unseen
        self._last_slack: tuple[object, np.ndarray | None] = (None, None)  # (frame key, pair slacks)
        self.colour = np.asarray(markerset.colour_index, dtype=np.int64)
        self.words = palette_words(markerset.palette)
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
        self._by_pair = np.argsort(self.c_pair, kind="stable")
        self._pair_starts = np.searchsorted(self.c_pair[self._by_pair], np.arange(len(self.pairs)))
        self._inexact = False  # a search placed markers on rays without trying every combination
        self.lr_pairs = np.array([(idx[l], idx[r]) for l, r in rules.left_right_pairs], np.int64)
        self.neighbours: list[list[tuple[int, int, bool]]] = [[] for _ in markerset.names]
        for k, (i, j) in enumerate(self.pairs):
            self.neighbours[i].append((int(j), k, True))
            self.neighbours[j].append((int(i), k, False))

    # ------------------------------------------------------------------------------ checks

    def count_problem(self, colour: np.ndarray) -> str | None:
        """One line on the point counts per colour that do not fit the marker set, or None."""
        n_col = len(self.words)
        have = np.bincount(colour[(colour >= 0) & (colour < n_col)], minlength=n_col)
        want = np.bincount(self.colour, minlength=n_col)
        problems = []
        for k in np.flatnonzero(have != want):
            names = [n for n, c in zip(self.markerset.names, self.colour) if c == k]
            if have[k] < want[k]:
                missing = want[k] - have[k]
                which = "the hidden one" if missing == 1 else f"the {missing} hidden ones"
                problems.append(
                    f"{have[k]} of the {want[k]} {self.words[k]} markers are seen: {which} must be seen by two "
                    f"cameras (check that {self._where(names)} are not covered and the patient is in the reference pose)"
                )
            else:
                problems.append(
                    f"{have[k]} {self.words[k]} points are seen but there are {want[k]} {self.words[k]} markers "
                    f"({', '.join(names)}): remove or cover other {self.words[k]} objects in the cameras' view"
                )
        stray = int(np.sum((colour < 0) | (colour >= n_col)))
        if stray:
            problems.append(f"{stray} points have a colour that is not in the marker set's palette")
        return "; ".join(problems) if problems else None

    def _where(self, names: list[str]) -> str:
        ms = self.markerset
        segs = list(dict.fromkeys(ms.segments[ms.index(n)].replace("_", " ") for n in names))
        listed = ", ".join(names)
        if len(segs) > 3:
            return f"the markers ({listed})"
        return f"the {' and '.join(segs)} markers ({listed})"

    # ------------------------------------------------------------------------------ search

    def _slack(self, p_m: np.ndarray, c_pat: np.ndarray, pa: np.ndarray, pb: np.ndarray,
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

    def _pair_blocks(self, p_m: np.ndarray, c_pat: np.ndarray, colour: np.ndarray) -> _Blocks:
        """Worst slack of each marker pair's constraints over the points of the pair's colours only.

        For many points (rays sampled finely) where :meth:`_pair_slack` would be large: pair k's
        block holds [i at p, j at q] for p among the points of marker i's colour, q of j's. The
        distances and coordinate differences are computed once per pair of colours.
        """
        members = [np.flatnonzero(colour == c) for c in range(len(self.words))]
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
            end = self._pair_starts[k + 1] if k + 1 < len(self.pairs) else len(self._by_pair)
            for kk in self._by_pair[self._pair_starts[k]:end]:
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
        return _Blocks(blocks, loc)

    def _pair_slack(self, p_m: np.ndarray, c_pat: np.ndarray, hard_distances: bool) -> np.ndarray:
        """(pairs, P, P) worst slack of each marker pair's constraints, [i at p, j at q]."""
        n = c_pat.shape[0]
        pts = np.arange(n)
        # d[k, p, q]: constraint k with its marker a at point p and b at point q
        d = self._slack(p_m, c_pat, pts[:, None, None], pts[None, :, None], hard_distances).transpose(2, 0, 1)
        d = np.where(self.c_flip[:, None, None], d.transpose(0, 2, 1), d)
        return np.minimum.reduceat(d[self._by_pair], self._pair_starts, axis=0)

    def _search(self, p_world_m: np.ndarray, colour: np.ndarray, yaw: float, bars_m: Iterable[float],
                hard_distances: bool = False, exclude: tuple[int, int] | None = None,
                pools: _Pools | None = None, rays: _RayRows | None = None) -> _Found | None:
        """The assignment with the largest worst slack, in the frame of ``yaw``.

        ``bars_m`` are lower and lower bars on the worst slack: the search stops at the first
        bar above which an assignment exists, so a good bar keeps the tree small. Rows of NaN are
        stand-ins for unseen markers (they satisfy every constraint), or with ``rays`` the rays
        from ``rays.first`` on. ``exclude`` = (marker, point) forbids that one naming. ``pools``:
        see :func:`_branch_and_bound`.

        A ray is one point of the search whose pair slacks are the best over its samples (a bound);
        a complete naming places its markers on rays at the samples that make its worst slack
        largest (:meth:`_place_on_rays`), so the result is exact on the samples.
        """
        if rays is not None and hard_distances:
            raise ValueError("rays are searched with soft distances only")
        centre = np.nanmean(p_world_m, axis=0)
        axes = patient_axes(yaw)
        c_pat = (p_world_m - centre) @ axes
        key = (p_world_m.tobytes(), yaw, hard_distances, None if rays is None else rays.key)
        if self._last_slack[0] != key:  # the uniqueness checks search the same frame many times
            if rays is None:
                self._last_slack = (key, (self._pair_slack(p_world_m, c_pat, hard_distances), None))
            else:
                ext_p = np.vstack([p_world_m[:rays.first], *rays.samples])
                ext_pat = (ext_p - centre) @ axes
                ext_col = np.concatenate([colour[:rays.first]]
                                         + [np.full(len(p), colour[rays.first + k]) for k, p in enumerate(rays.samples)])
                blocks = self._pair_blocks(ext_p, ext_pat, ext_col)
                self._last_slack = (key, (self._compact(blocks, colour, ext_col, rays), (ext_p, ext_pat, blocks)))
        slack, ext = self._last_slack[1]
        domains = [0] * len(self.colour)
        for m, c in enumerate(self.colour):
            for q in np.flatnonzero(colour == c):
                domains[m] |= 1 << int(q)
        if exclude is not None:
            domains[exclude[0]] &= ~(1 << exclude[1])

        def slack_of(index: np.ndarray, hard: bool = hard_distances) -> np.ndarray:
            if ext is None or not np.any(index >= rays.first):
                return self._slack(p_world_m, c_pat, index[self.c_a], index[self.c_b], hard)
            ext_index = self._place_on_rays(index, rays, ext[2])
            return self._slack(ext[0], ext[1], ext_index[self.c_a], ext_index[self.c_b], hard)

        nodes = 0
        for bar in bars_m:
            best, nodes_used = _branch_and_bound(slack, domains, self.neighbours, bar, slack_of, self.max_nodes,
                                                 pools)
            nodes += nodes_used
            if nodes_used > self.max_nodes:
                log.warning("identification search stopped after %d nodes; the result may not be the best", nodes_used)
            if best is not None:
                return _Found(best, slack_of(best, False), yaw, nodes)
        return None

    def _compact(self, blocks: _Blocks, colour: np.ndarray, ext_col: np.ndarray, rays: _RayRows) -> np.ndarray:
        """(pairs, P, P) pair slacks of the searched points: a ray's the best over its samples."""
        n = len(colour)
        out = np.full((len(self.pairs), n, n), -np.inf)
        # the extended points of one colour are ordered by the searched point they belong to
        owner = np.concatenate([np.arange(rays.first)]
                               + [np.full(len(p), rays.first + k) for k, p in enumerate(rays.samples)])
        rows, starts = [], []
        for c in range(len(self.words)):
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

    def _place_on_rays(self, index: np.ndarray, rays: _RayRows, s_ext: _Blocks) -> np.ndarray:
        """Each marker named to a ray at the sample that makes the naming's worst slack largest.

        The markers on rays that share a constraint are placed together (every combination of
        their samples: up to ``_MAX_JOINT``; beyond, each alone and the search is marked inexact).

        Args:
            index: (M,) a complete naming; rows from ``rays.first`` on are rays.
            rays: the rays' samples (rows of the extended points after ``rays.first``).
            s_ext: pair slacks over the extended points (seen, stand-ins, samples).

        Returns:
            (M,) the naming in rows of the extended points.
        """
        ext_index = index.copy()
        on_ray = np.flatnonzero(index >= rays.first)
        rows = {int(m): rays.rows(int(index[m])) for m in on_ray}
        unary = {m: np.full(len(r), np.inf) for m, r in rows.items()}
        links: list[tuple[int, int, np.ndarray]] = []
        for m, r in rows.items():
            for j, k, forward in self.neighbours[m]:
                if j in rows:
                    if m < j:
                        mat = s_ext.get(k, r[:, None], rows[j][None, :])
                        links.append((m, j, mat if forward else mat.T))
                else:
                    q = int(index[j])
                    unary[m] = np.minimum(unary[m], s_ext.get(k, r, q) if forward else s_ext.get(k, q, r))
        group = {m: m for m in rows}  # union-find over the links: markers placed together

        def root(m: int) -> int:
            while group[m] != m:
                m = group[m]
            return m

        for a, b, _ in links:
            group[root(a)] = root(b)
        for g in {root(m) for m in rows}:
            members = [m for m in rows if root(m) == g]
            sizes = [len(rows[m]) for m in members]
            if math.prod(sizes) > _MAX_JOINT:
                self._inexact = True
                for m in members:
                    ext_index[m] = rows[m][int(np.argmax(unary[m]))]
                continue
            axis = {m: a for a, m in enumerate(members)}
            total = np.full(sizes, np.inf)
            for m in members:
                shape = [1] * len(members)
                shape[axis[m]] = sizes[axis[m]]
                total = np.minimum(total, unary[m].reshape(shape))
            for a, b, mat in links:
                if a in axis:
                    if axis[a] > axis[b]:
                        a, b, mat = b, a, mat.T
                    shape = [1] * len(members)
                    shape[axis[a]], shape[axis[b]] = mat.shape
                    total = np.minimum(total, mat.reshape(shape))
            best = np.unravel_index(int(np.argmax(total)), total.shape)
            for m in members:
                ext_index[m] = rows[m][best[axis[m]]]
        return ext_index

    def _rule_margins(self, slack: np.ndarray) -> np.ndarray:
        out = np.full(len(self.rules.rules), np.inf)
        np.minimum.at(out, self.c_rule, slack)
        return out

    # ------------------------------------------------------------------------------ public

    def identify(self, p_world_m: np.ndarray, colour: np.ndarray) -> Identification:
        """Label the points of one frame; see :func:`identify`."""
        p_world_m, colour = self._checked(p_world_m, colour)
        finite = np.isfinite(p_world_m).all(axis=1)
        problem = self.count_problem(colour[finite])
        if problem is not None:
            raise IdentificationError(problem)
        keep = np.flatnonzero(finite)
        found = self._best(p_world_m[keep], colour[keep])
        return self._result(found, keep)

    def identify_with_unseen(self, p_world_m: np.ndarray, colour: np.ndarray, rays: Rays | None = None
                             ) -> Identification | None:
        """Label a frame in which some markers have no point (hidden, or seen by one camera only).

        Each unseen marker gets a stand-in point that satisfies every rule, so the search names
        the seen points and says which markers are unseen. The names are given only when they
        are certain: at most ``max_unseen`` markers unseen, every rule kept by twice its margin
        (a rule with an unseen marker checks nothing, so the others must hold clearly), and for
        every named point no other naming comes within half a rule margin of satisfying the rules
        (a missing point can make two namings fit, e.g. an elbow marker and a wrist marker of one
        colour on one side).

        When that is not possible and ``rays`` are given, the unseen markers seen by one camera
        are placed on their rays instead (:meth:`_identify_on_rays`): the rules then check them
        too, so more may be unseen.

        Args:
            p_world_m: (P, 3) float64 unlabelled points, world metres (rows with NaN are ignored).
            colour: (P,) int palette index of each point.
            rays: the blobs no point uses (:func:`single_view_rays`), or None.

        Returns:
            The identification, ``index`` -1 for the unseen markers; None while it is not
            certain, or when some colour has more points than markers (wait for the next frame).

        Raises:
            IdentificationError: no naming of the seen points satisfies the rules (the pose is
                wrong: the message says which rule, in plain words), or the patient sits turned
                too far.
        """
        p_world_m, colour = self._checked(p_world_m, colour)
        finite = np.isfinite(p_world_m).all(axis=1)
        keep = np.flatnonzero(finite)
        n_col = len(self.words)
        col = colour[keep]
        if np.any((col < 0) | (col >= n_col)):
            return None
        deficit = np.bincount(self.colour, minlength=n_col) - np.bincount(col, minlength=n_col)
        if np.any(deficit < 0):
            return None
        n_unseen = int(deficit.sum())
        if n_unseen == 0:
            return self._result(self._best(p_world_m[keep], col), keep)
        col_seen = col
        on_rays = (lambda: self._identify_on_rays(p_world_m[keep], col_seen, keep, deficit, rays)
                   if rays is not None and len(rays) else None)
        if n_unseen > self.max_explained_unseen:
            return on_rays()
        stand_in = np.repeat(np.arange(n_col), deficit)
        pts = np.vstack([p_world_m[keep], np.full((n_unseen, 3), np.nan)])
        col = np.concatenate([col, stand_in])
        found = self._best(pts, col)  # raises when the seen points break the rules
        if n_unseen > self.max_unseen or found.nodes > self.max_nodes or not self._certain(pts, col, found, len(keep)):
            return on_rays()
        return self._result(found, np.append(keep, np.full(n_unseen, -1)))

    def _certain(self, pts: np.ndarray, col: np.ndarray, found: _Found, n_seen: int, pools: _Pools | None = None,
                 rays: _RayRows | None = None) -> bool:
        """Whether the names of the seen points (rows below ``n_seen``) of ``found`` are beyond doubt.

        Every rule must hold by twice its margin: a rule with an unseen marker checks nothing, so
        the others must hold clearly (a wrong pose, hands on the thighs with the inner wrist
        markers hidden, kept every rule within 4 mm with the elbow and wrist markers swapped).
        And no naming that gives a seen point another name may come within half a margin of
        satisfying the rules (with ``rays``, within half a margin and a sampling step).
        """
        if self._rule_margins(found.slack_m).min() < self.min_order_margin_m:
            return False
        bar = -0.5 * self.min_order_margin_m
        if rays is not None:
            # a naming is scored at its best samples, up to half a step from the best place on
            # each of two rays: another naming may fit better than its samples say
            bar -= _RAY_STEP_M
        for m, q in enumerate(found.index):
            if q < n_seen and self._search(pts, col, found.yaw, [bar], exclude=(m, int(q)), pools=pools,
                                           rays=rays) is not None:
                log.debug("identification with unseen markers is ambiguous for %s", self.markerset.names[m])
                return False
        return True

    def _identify_on_rays(self, p_seen_m: np.ndarray, col_seen: np.ndarray, keep: np.ndarray, deficit: np.ndarray,
                          rays: Rays) -> Identification | None:
        """Name the seen points with the unseen markers placed on the rays of single-camera blobs.

        Each ray of an unseen colour is sampled every ``_RAY_STEP_M`` over its range, near the
        seen points and not inside a seen ball; a ray is one candidate point of the search (a
        blob is one marker), placed at its best sample (:meth:`_search`). A marker of a colour
        with fewer rays than unseen markers may still take a stand-in point that satisfies every
        rule, at most ``max_unseen`` of them. The names of the seen points are given under the
        same conditions as with stand-ins only (:meth:`_certain`); the markers on rays are left
        for the tracker's re-acquisition (``index`` -1), like the unseen ones.

        Two rays that may be two views of one ball (:meth:`_merge_views`) may also be two balls
        whose rays cross: both readings are searched, and the names are given only when one
        reading is certain and every reading that fits the rules at all names the seen points
        the same.

        Returns:
            The identification or None (nothing fits, or not beyond doubt: wait; no point seen
            by two cameras: nothing to place the rays near, as when one camera is left).
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
        merged = self._merge_views(samples, ray_col, np.array(ray_origin), np.array(ray_whole))
        if len(merged[0]) < len(samples):
            readings.append(merged)
        named: list[tuple[_Found, bool, np.ndarray]] = []
        for candidates, colours in readings:
            attempt = self._search_on_rays(p_seen_m, col_seen, deficit, candidates, colours)
            if attempt is not None:
                named.append(attempt)
        n_seen = len(p_seen_m)
        sure = [a for a in named if a[1]]
        if not sure or any(not np.array_equal(_seen_names(a[0], n_seen), _seen_names(sure[0][0], n_seen))
                           for a in named):
            return None
        found, _, point_of_row = sure[0]
        return self._result(found, np.append(keep, point_of_row))

    def _search_on_rays(self, p_seen_m: np.ndarray, col_seen: np.ndarray, deficit: np.ndarray,
                        samples: list[np.ndarray], ray_col: np.ndarray) -> tuple[_Found, bool, np.ndarray] | None:
        """One reading of the rays (:meth:`_identify_on_rays`): the best naming, whether it is
        certain, and the rows after the seen points (-1 each); None when no naming fits."""
        n_seen = len(p_seen_m)
        stand_in = np.repeat(np.arange(len(deficit)),
                             np.maximum(deficit - np.bincount(ray_col, minlength=len(deficit)), 0))
        if len(stand_in) > self.max_unseen:
            log.debug("%d markers are neither seen nor on a ray", len(stand_in))
            return None
        first = n_seen + len(stand_in)
        on_rays = _RayRows.of(first, samples)
        pts = np.vstack([p_seen_m, np.full((len(stand_in) + len(samples), 3), np.nan)])
        col = np.concatenate([col_seen, stand_in, ray_col]).astype(np.int64)
        # the stand-ins and rays of a colour name at most its unseen markers: every seen point is named
        unseen_rows = np.arange(n_seen, len(pts))
        pools = _Pools.of((unseen_rows[col[unseen_rows] == c], int(deficit[c])) for c in np.flatnonzero(deficit > 0))
        limit = math.radians(self.rules.max_turn_deg)
        guess = float(np.clip(yaw_from_points(p_seen_m), -limit, limit))
        self._inexact = False
        found = None
        for yaw in dict.fromkeys((guess, 0.0)):
            found = self._settle(pts, col, yaw, pools, on_rays)
            if found is not None:
                break
        if found is None:
            log.debug("no naming with markers on rays keeps the rules")
            return None
        certain = (found.nodes <= self.max_nodes
                   and abs(_yaw_from_pairs(pts, found.index[self.lr_pairs], found.yaw)) <= limit
                   and self._certain(pts, col, found, n_seen, pools, on_rays) and not self._inexact)
        log.debug("%s with %d markers on single-camera rays, %d unseen (worst margin %.0f mm)",
                  "named" if certain else "not certain", int(np.sum(found.index >= first)), len(stand_in),
                  1000 * self._rule_margins(found.slack_m).min())
        return found, certain, np.full(len(pts) - n_seen, -1)

    def _merge_views(self, samples: list[np.ndarray], ray_col: np.ndarray, origin_m: np.ndarray, whole: np.ndarray
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

    @staticmethod
    def _checked(p_world_m: np.ndarray, colour: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p_world_m = np.asarray(p_world_m, dtype=np.float64)
        colour = np.asarray(colour, dtype=np.int64)
        if p_world_m.ndim != 2 or p_world_m.shape[1] != 3 or colour.shape != (p_world_m.shape[0],):
            raise ValueError(f"expected points (P, 3) and colours (P,), got {p_world_m.shape} and {colour.shape}")
        return p_world_m, colour

    def _best(self, pts: np.ndarray, col: np.ndarray) -> _Found:
        """The naming that satisfies the rules with the largest worst margin, in the patient's frame.

        Raises:
            IdentificationError: no naming satisfies the rules, or the patient is turned too far.
        """
        limit = math.radians(self.rules.max_turn_deg)
        seen = yaw_from_points(pts[np.isfinite(pts).all(axis=1)])
        guess = float(np.clip(seen, -limit, limit))
        found = None
        for yaw in dict.fromkeys((guess, 0.0)):
            found = self._settle(pts, col, yaw)
            if found is not None:
                break
        if found is None:
            if abs(seen) > limit:  # the spread says turned too far: do the rules hold in that frame?
                turned = self._settle(pts, col, seen)
                if turned is not None:
                    raise IdentificationError(self._turned(_yaw_from_pairs(pts, turned.index[self.lr_pairs], seen)))
            raise IdentificationError(self._explain(pts, col, guess))
        turn = _yaw_from_pairs(pts, found.index[self.lr_pairs], found.yaw)
        if abs(turn) > limit:
            raise IdentificationError(self._turned(turn))
        return found

    def _result(self, found: _Found, point_of_row: np.ndarray) -> Identification:
        """The public result; ``point_of_row`` maps the searched rows to the caller's points (-1: none)."""
        margins = self._rule_margins(found.slack_m)
        index = np.asarray(point_of_row, dtype=np.int64)[found.index]
        return Identification(index, float(margins.min()), margins, math.degrees(found.yaw))

    def _settle(self, pts: np.ndarray, colour: np.ndarray, yaw: float, pools: _Pools | None = None,
                rays: _RayRows | None = None) -> _Found | None:
        """Search in the frame of ``yaw``, then in the frame of the identified left-right pairs."""
        found = self._search(pts, colour, yaw, [_SATISFIED], pools=pools, rays=rays)
        for _ in range(_MAX_REFINE):
            if found is None:
                break
            new_yaw = _yaw_from_pairs(pts, found.index[self.lr_pairs], found.yaw)
            if abs(math.degrees(new_yaw - found.yaw)) < _REFINE_TOL_DEG:
                break
            again = self._search(pts, colour, new_yaw, [_SATISFIED], pools=pools, rays=rays)
            if again is None:
                break
            found = again
        return found

    def _turned(self, yaw: float) -> str:
        deg = math.degrees(yaw)
        return (f"the patient sits turned {abs(deg):.0f} degrees to the {'left' if deg > 0 else 'right'} "
                f"(at most {self.rules.max_turn_deg:g} allowed): turn the chair to face the front")

    def _explain(self, pts: np.ndarray, colour: np.ndarray, yaw: float) -> str:
        """One line: the worst-broken rule of the assignment that breaks the rules least.

        The distances between markers on one body part hold in any pose, so the assignment is
        first looked for among those that keep every distance rule: then only orderings fail and
        their message says how the pose differs. Only if no assignment keeps the distances (a
        marker misplaced, or a stray point taken for one) are all rules relaxed together. As in
        :meth:`identify`, the frame follows the near-assignment's own left-right pairs (a wrong
        pose can mislead the first guess from the spread of the points).
        """
        limit = math.radians(self.rules.max_turn_deg)
        near = None
        for _ in range(_MAX_REFINE):
            for hard in (True, False):
                near = self._search(pts, colour, yaw, _RELAXED_BARS_M, hard_distances=hard)
                if near is not None:
                    break
            if near is None:  # only with a spent node budget
                return f"the markers cannot be identified: {self.rules.reference_pose}"
            turn = _yaw_from_pairs(pts, near.index[self.lr_pairs], yaw)
            if abs(turn) > limit:
                # a patient turned too far, or a wrong pose that mislabels a pair: the rules hold
                # in the turned frame only in the first case
                turned = self._settle(pts, colour, turn)
                if turned is not None:
                    return self._turned(_yaw_from_pairs(pts, turned.index[self.lr_pairs], turn))
                break
            if abs(math.degrees(turn - yaw)) < _REFINE_TOL_DEG:
                break
            yaw = turn
        margins = self._rule_margins(near.slack_m)
        broken = np.flatnonzero(margins < 0)
        worst = int(np.argmin(margins))
        rule = self.rules.rules[worst]
        more = f"{len(broken)} rules fail, worst " if len(broken) > 1 else "rule "
        return f"{rule.message} ({more}'{rule.text}' by {-margins[worst] * 1000:.0f} mm)"


def identify(p_world_m: np.ndarray, colour: np.ndarray, markerset: MarkerSet) -> Identification:
    """Which point is which marker, in the reference pose of the marker set's rules.

    Args:
        p_world_m: (P, 3) float64 unlabelled points, world metres (rows with NaN are ignored).
        colour: (P,) int palette index of each point (``markerset.palette``).
        markerset: the marker set with its ``identification`` rules.

    Returns:
        The assignment that satisfies every rule with the largest worst margin.

    Raises:
        IdentificationError: the points of some colour are not as many as its markers, or no
            assignment satisfies the rules (the message says which rule fails, in plain words).
    """
    return Identifier(markerset).identify(p_world_m, colour)


def try_identify(points: Points3D, identifier: Identifier, rays: Rays | None = None) -> Identification | None:
    """For the tracker, once per frame until it succeeds.

    With every marker seen, the names of :meth:`Identifier.identify`. With a few unseen (a marker
    seen by one camera only in the reference pose), the names of the seen ones when the rules
    still decide them beyond doubt (:meth:`Identifier.identify_with_unseen`; index -1 for the
    unseen, which the tracker's re-acquisition finds later; ``rays`` of the blobs seen by one camera
    only, :func:`single_view_rays`, let more be unseen). Returns None while that is not
    possible (too many unseen, a stray point, an ambiguous naming: wait for the next frame);
    raises :class:`IdentificationError` when the pose breaks the rules (tell the therapist).
    """
    return identifier.identify_with_unseen(points.p_world_m, points.colour, rays)


def identify_over_frames(frames: Iterable[Points3D], markerset: MarkerSet, max_frames: int = 30
                         ) -> tuple[int, Identification]:
    """Identify on the first of the first ``max_frames`` frames that :func:`try_identify` names.

    Returns:
        (frame number counted from 0, identification; index -1 for markers unseen in that frame).

    Raises:
        IdentificationError: no frame is named (the message of the last frame's counts), or a
            frame breaks the rules.
    """
    identifier = Identifier(markerset)
    last = "no frames"
    for n, points in enumerate(frames):
        if n >= max_frames:
            break
        result = try_identify(points, identifier)
        if result is not None:
            return n, result
        finite = np.isfinite(points.p_world_m).all(axis=1)
        last = identifier.count_problem(np.asarray(points.colour)[finite]) or last
    raise IdentificationError(f"no frame of the first {max_frames} shows every marker: {last}")


def _seen_names(found: _Found, n_seen: int) -> np.ndarray:
    """(M,) the point each marker is named to, -1 where it is not one of the first ``n_seen``."""
    return np.where(found.index < n_seen, found.index, -1)


def _branch_and_bound(slack: np.ndarray, domains: list[int], neighbours: list[list[tuple[int, int, bool]]],
                      bar_m: float, slack_of, max_nodes: int, pools: _Pools | None = None
                      ) -> tuple[np.ndarray | None, int]:
    """Depth-first search for the assignment with the largest worst slack above ``bar_m``.

    Args:
        slack: (pairs, P, P) worst slack of each constrained marker pair, [first at p, second at q].
        domains: per marker, a bitset of the points it may take (its colour).
        neighbours: per marker, (other marker, pair, marker is the pair's first) of its pairs.
        bar_m: only assignments whose every pair slack exceeds this are considered.
        slack_of: (M,) assignment -> (K,) slack of every constraint.
        max_nodes: node budget; the best so far is returned when it is spent.
        pools: groups of points of which at most so many may be taken (the points sampled along
            one ray: one; the points that are not seen of one colour: its unseen markers).

    Returns:
        (the best assignment or None, nodes visited).
    """
    masks: list[tuple[list[int], list[int]]] = []

    def set_bar(bar: float) -> None:
        ok = slack > bar
        masks[:] = list(zip(_bitsets(ok), _bitsets(ok.transpose(0, 2, 1))))

    state = {"bar": bar_m, "best": None, "nodes": 0}
    set_bar(bar_m)

    pool_of = pools.of_point if pools is not None else {}

    def descend(dom: list[int], free: list[int], left: tuple[int, ...]) -> bool:
        """False stops the search (budget spent, or nothing left to improve); ``left``: what each
        pool may still give."""
        if not free:
            index = np.array([d.bit_length() - 1 for d in dom], np.int64)
            s = slack_of(index)
            worst = float(s.min()) if s.size else math.inf
            if worst > state["bar"]:
                state["best"], state["bar"] = index, worst
                if math.isinf(worst):
                    return False
                set_bar(worst)  # from now on only better assignments pass the forward checks
            return True
        v = min(free, key=lambda u: dom[u].bit_count())  # fewest candidates first
        rest = [u for u in free if u != v]
        d = dom[v]
        while d:
            low = d & -d
            d ^= low
            state["nodes"] += 1
            if state["nodes"] > max_nodes:
                return False
            q = low.bit_length() - 1
            new = dom.copy()
            new[v] = low
            used, now = low, left
            if q in pool_of:
                now = list(left)
                for k in pool_of[q]:
                    now[k] -= 1
                    if now[k] == 0:
                        used |= pools.mask[k]
                now = tuple(now)
            used = ~used
            for u in rest:
                new[u] &= used
            for u, k, forward in neighbours[v]:
                new[u] &= masks[k][0 if forward else 1][q]
            # assigned neighbours too: after the bar rose, an earlier pair may no longer pass
            if not all(new):
                continue
            if not descend(new, rest, now):
                return False
        return True

    descend(domains, list(range(len(domains))), tuple(pools.size) if pools is not None else ())
    return state["best"], state["nodes"]
