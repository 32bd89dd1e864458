"""Identification of the markers on the reference pose from the marker set's ordering rules.

docs/METHOD.md 5.2: the patient starts in a reference pose in which the markers keep known orderings
along the axes of the patient's frame (the left arm left of the sternum, the elbow above the
wrist, the thumb-side wrist marker in front of the little-finger-side one, ...). The seed sorts
the 14 points by hand-written steps; here the orderings are data (``identification:`` in the
marker-set YAML, :class:`tracking.markerset.OrderRule`), so any marker set can state its own.

:class:`Identifier` compiles the rules (:mod:`.constraints`), searches the naming with the largest
worst margin in the patient's frame (:mod:`.search`, :mod:`.body_frame`), names the seen points
when some markers are unseen or on single-camera rays (:mod:`.ray_naming`, :mod:`.rays`), and
says in one line why not (:mod:`.explain`). For the tracker: :func:`try_identify` returns None
while the names are not certain (wait for the next frame) and raises
:class:`IdentificationError` when the pose breaks the rules. The labelling's fit
(:mod:`.fit`) names the markers where the marker set's YAML gives the body model's roles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from calibration.errors import RehabError
from tracking.errors import ContentError
from tracking.labelling.body_frame import yaw_from_pairs, yaw_from_points
from tracking.labelling.constraints import Constraints
from tracking.labelling.explain import Explainer
from tracking.labelling.ray_naming import RayNaming
from tracking.labelling.rays import Rays
from tracking.labelling.search import Found, RuleSearch
from tracking.labelling.words import palette_words
from tracking.markerset import IdentificationRules, MarkerSet
from tracking.reconstruction import Points3D


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
        self.max_unseen = max_unseen
        self.max_explained_unseen = max_explained_unseen
        self.colour = np.asarray(markerset.colour_index, dtype=np.int64)
        self.words = palette_words(markerset.palette)
        self.constraints = Constraints(markerset, rules, len(self.words))
        self.search = RuleSearch(self.constraints, tuple(markerset.names), max_nodes)
        self.explainer = Explainer(markerset, self.words, self.search)
        self.ray_naming = RayNaming(markerset, self.search, max_unseen)

    @property
    def max_nodes(self) -> int:
        """Search-node budget per search."""
        return self.search.max_nodes

    def count_problem(self, colour: np.ndarray) -> str | None:
        """One line on the point counts per colour that do not fit the marker set, or None."""
        return self.explainer.count_problem(colour)

    def distance_fit_m(self, marker: int, p_cand_m: np.ndarray, positions_m: np.ndarray, known: np.ndarray
                       ) -> np.ndarray:
        """How well each candidate fits the distance rules of ``marker`` to the known markers
        (:meth:`tracking.labelling.constraints.Constraints.distance_fit_m`)."""
        return self.constraints.distance_fit_m(marker, p_cand_m, positions_m, known)

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
        are placed on their rays instead (:meth:`RayNaming.name`): the rules then check them
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
        on_rays = (lambda: self._on_rays(p_world_m[keep], col_seen, keep, deficit, rays)
                   if rays is not None and len(rays) else None)
        if n_unseen > self.max_explained_unseen:
            return on_rays()
        stand_in = np.repeat(np.arange(n_col), deficit)
        pts = np.vstack([p_world_m[keep], np.full((n_unseen, 3), np.nan)])
        col = np.concatenate([col, stand_in])
        found = self._best(pts, col)  # raises when the seen points break the rules
        if n_unseen > self.max_unseen or found.nodes > self.search.max_nodes or not self.search.certain(pts, col, found, len(keep)):
            return on_rays()
        return self._result(found, np.append(keep, np.full(n_unseen, -1)))

    def _on_rays(self, p_seen_m: np.ndarray, col_seen: np.ndarray, keep: np.ndarray, deficit: np.ndarray,
                  rays: Rays) -> Identification | None:
        """The names with the unseen markers on single-camera rays (:meth:`RayNaming.name`), or None."""
        named = self.ray_naming.name(p_seen_m, col_seen, deficit, rays)
        if named is None:
            return None
        found, point_of_row = named
        return self._result(found, np.append(keep, point_of_row))

    @staticmethod
    def _checked(p_world_m: np.ndarray, colour: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p_world_m = np.asarray(p_world_m, dtype=np.float64)
        colour = np.asarray(colour, dtype=np.int64)
        if p_world_m.ndim != 2 or p_world_m.shape[1] != 3 or colour.shape != (p_world_m.shape[0],):
            raise ValueError(f"expected points (P, 3) and colours (P,), got {p_world_m.shape} and {colour.shape}")
        return p_world_m, colour

    def _best(self, pts: np.ndarray, col: np.ndarray) -> Found:
        """The naming that satisfies the rules with the largest worst margin, in the patient's frame.

        Raises:
            IdentificationError: no naming satisfies the rules, or the patient is turned too far.
        """
        limit = math.radians(self.rules.max_turn_deg)
        seen = yaw_from_points(pts[np.isfinite(pts).all(axis=1)])
        guess = float(np.clip(seen, -limit, limit))
        found = None
        for yaw in dict.fromkeys((guess, 0.0)):
            found = self.search.settle(pts, col, yaw)
            if found is not None:
                break
        if found is None:
            if abs(seen) > limit:  # the spread says turned too far: do the rules hold in that frame?
                turned = self.search.settle(pts, col, seen)
                if turned is not None:
                    raise IdentificationError(self.explainer.turned(yaw_from_pairs(pts, turned.index[self.constraints.lr_pairs], seen)))
            raise IdentificationError(self.explainer.explain(pts, col, guess))
        turn = yaw_from_pairs(pts, found.index[self.constraints.lr_pairs], found.yaw)
        if abs(turn) > limit:
            raise IdentificationError(self.explainer.turned(turn))
        return found

    def _result(self, found: Found, point_of_row: np.ndarray) -> Identification:
        """The public result; ``point_of_row`` maps the searched rows to the caller's points (-1: none)."""
        margins = self.constraints.rule_margins(found.slack_m)
        index = np.asarray(point_of_row, dtype=np.int64)[found.index]
        return Identification(index, float(margins.min()), margins, math.degrees(found.yaw))



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
