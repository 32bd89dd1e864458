"""Identification: the markers named on the reference pose, once the patient holds it still, by the
labelling's fit (:mod:`tracking.labelling`), or by the marker set's rules alone
(:mod:`tracking.labelling.rules`) where its YAML does not name the body model's landmarks."""

from __future__ import annotations

import logging
from typing import Sequence

import numpy as np

from calibration.camera import Camera
from tracking.labelling import BodyRoles, Labeller
from tracking.labelling.rays import single_view_rays
from tracking.labelling.rules import IdentificationError, Identifier, try_identify
from tracking.labelling.still import Snapshot, Stillness
from tracking.markerset import MarkerSet
from tracking.pipeline.params import TrackerParams
from tracking.reconstruction import CameraObservations, Points3D

log = logging.getLogger(__name__)

WAITING = "waiting for the reference pose"


class Naming:
    """Names the full frame's points, or says why not yet.

    Args:
        cameras: the calibrated cameras (for the single-camera rays).
        markerset: the markers worn.
        params: ``identify_hold_s`` (the hold) and ``rejudge_every``.
        fps: frame rate (the hold's frame sets).
    """

    def __init__(self, cameras: Sequence[Camera], markerset: MarkerSet, params: TrackerParams, fps: float):
        self.cameras = tuple(cameras)
        self.markerset = markerset
        self.rejudge_every = params.rejudge_every
        self.colour = markerset.colour_index
        self.identifier = Identifier(markerset)
        roles = BodyRoles.of(markerset)
        self.roles = roles
        self.labeller = Labeller.for_markerset(markerset) if roles is not None else None
        self.stillness = Stillness(fps, params.identify_hold_s) if params.identify_hold_s > 0 else None
        self.snapshot = Snapshot()
        self.last_message = ""

    def reset(self) -> None:
        """Forget the hold and the points judged."""
        if self.stillness is not None:
            self.stillness.reset()
        self.snapshot.reset()

    @property
    def hold_frames(self) -> int:
        """Still frame sets after the first that the patient holds before the markers are named."""
        return self.stillness.frames_needed if self.stillness is not None and self.labeller is not None else 0

    def name(self, points: Points3D, views: Sequence[CameraObservations]) -> tuple[np.ndarray | None, str]:
        """(M,) the point of each marker (-1: not seen yet) and "", or None and why not; while no
        labelling is confident the message says why, in the marker set's rules' words where a rule
        fails."""
        if self.labeller is not None:
            held = self.stillness.update(points.p_world_m, points.colour) if self.stillness is not None else 1.0
            if held < 1.0:
                return None, f"hold the reference pose still ({100 * held:.0f} %)"
            if self.stillness is not None and \
                    (self.stillness.count - self.stillness.frames_needed) % self.rejudge_every != 0:
                return None, self.last_message  # (still and not confident: judged again every few frame sets)
        rays = single_view_rays(self.cameras, views, points, self.markerset.radius_m)
        if self.labeller is not None and self.snapshot.same(points.p_world_m, points.colour, rays.colour):
            return None, self.last_message  # (judged on these points already, not confident)
        if self.labeller is None or not self.labeller.takes(points.colour, rays):
            return self._by_rules(points, rays)
        lab = self.labeller.label(points.p_world_m, points.colour, rays)
        if lab.confident:
            log.info("labelled with score %.1f, margin %.1f", lab.score, lab.margin)
            return np.asarray(lab.index), ""
        self.last_message = self._not_confident(points, lab, rays)
        return None, self.last_message

    def _by_rules(self, points: Points3D, rays) -> tuple[np.ndarray | None, str]:
        """More markers without a point (or without a ray) than the fit takes: the rules with the
        single-camera rays name them, and the body model must find the names within its ranges;
        not with one colour for all markers (there the rules' search with many stand-ins takes
        seconds and is what named elbow pairs exchanged), nor with more markers without a point
        than the fit ever places (its search on rays took 5-15 s per frame set with 12 of 14
        markers seen by one camera or none, and could not name them with any confidence): the
        counts are reported."""
        if self.labeller is not None and (len(self.identifier.words) == 1
                                          or self._without_point(points).sum() > self.labeller.max_on_rays):
            self.last_message = self.identifier.count_problem(np.asarray(points.colour)) or WAITING
            return None, self.last_message
        try:
            ident = try_identify(points, self.identifier, rays)
        except IdentificationError as exc:
            self.last_message = str(exc)
            return None, self.last_message
        if ident is not None and (self.labeller is None or self.labeller.score_of(
                points.p_world_m, ident.index, ident.yaw_deg) <= self.labeller.max_score):
            return np.asarray(ident.index), ""
        self.last_message = self.identifier.count_problem(np.asarray(points.colour)) or WAITING
        return None, self.last_message

    def _not_confident(self, points: Points3D, lab, rays) -> str:
        """Why no labelling is confident: the point counts, else the marker set's rule that fails
        (the seed's ordering rules, in their plain words), else the fit's own words. The rules'
        explanation is not looked for with one colour and more than ``max_unseen`` markers without
        a point (its search with stand-ins takes seconds): the counts, or the fit's words."""
        colour = np.asarray(points.colour)[np.isfinite(points.p_world_m).all(axis=1)]
        short = self._without_point(points)
        if np.any(short < 0):
            return self.identifier.count_problem(colour) or WAITING
        if short.sum() > self.labeller.max_unseen and len(self.identifier.words) == 1:
            if lab.index is None:
                return self.identifier.count_problem(colour) or self.labeller.advice(lab, self.markerset.names)
            return self.labeller.advice(lab, self.markerset.names)
        try:
            self.identifier.identify_with_unseen(points.p_world_m, points.colour, rays)
        except IdentificationError as exc:
            return str(exc)
        return self.labeller.advice(lab, self.markerset.names)

    def _without_point(self, points: Points3D) -> np.ndarray:
        """(colours,) markers of each colour without a point (negative: more points than markers)."""
        colour = np.asarray(points.colour)[np.isfinite(points.p_world_m).all(axis=1)]
        n_col = len(self.identifier.words)
        return np.bincount(self.colour, minlength=n_col) - np.bincount(colour[(colour >= 0) & (colour < n_col)],
                                                                        minlength=n_col)
