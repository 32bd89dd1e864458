"""The per-frame tracker: one object, ``step(images) -> TrackerSample``, for every driver.

docs/METHOD.md sections 5.2-5.4, online (no look-ahead); each stage lives in
:mod:`tracking.pipeline` (docs/ARCHITECTURE.md, "A frame set's way through the tracker"):

1. **Identification** on the reference pose: full-frame measurement, then names
   (:mod:`tracking.pipeline.naming`).
2. **Tracking**: each marker's next position is predicted from its history
   (:mod:`~tracking.pipeline.prediction`); the colour table runs only inside search windows around
   the prediction's image in every camera (:mod:`~tracking.pipeline.windows`); the views that fit
   are triangulated (:mod:`~tracking.pipeline.views`) and the candidate consistent with the
   prediction and the segments is taken (:mod:`~tracking.pipeline.consistency`); images off the
   set's instant are brought to it (:mod:`~tracking.pipeline.timing`).
3. **Hidden markers**: a marker without a consistent candidate is estimated from its own and
   its neighbours' motion (:mod:`tracking.hidden`), or reported lost.
4. **Re-acquisition**: lost markers are searched in the full frame every few frames
   (:mod:`~tracking.pipeline.reacquire`); if most markers are lost for long, the tracker
   identifies again (also on request).

Pure computation on arrays: no files, processes or GL.
"""

from __future__ import annotations

import enum
import logging
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from calibration.camera import Camera
from calibration.errors import RehabError
from tracking import window_kernel
from tracking.colour.table import ColourTable
from tracking.hidden import Estimator, estimator_config
from tracking.labelling.checks import SelfChecks
from tracking.markerset import MarkerSet
from tracking.full_frame import FrameMeasurer, StageTimes
from tracking.pipeline.arcs import ArcRegions
from tracking.pipeline.consistency import accept, learn_lengths
from tracking.pipeline.naming import Naming
from tracking.pipeline.params import TrackerParams
from tracking.pipeline.prediction import predict
from tracking.pipeline.reacquire import centroids_used, reacquire, search_now
from tracking.pipeline.selfcheck import checked_angles, self_check
from tracking.pipeline.state import FrameState, MarkerMemory, Setup
from tracking.pipeline.timing import correct_to_set_instant, frame_skew
from tracking.pipeline.update import estimate_hidden, remember
from tracking.pipeline.views import choose_views, full_views_as_rays
from tracking.pipeline.windows import ImageSizes, LumaLabels, window_observations
from tracking.reconstruction import CameraObservations, Points3D, RigGeometry
from tracking.marker_status import MarkerStatus

log = logging.getLogger(__name__)

__all__ = ["STEP_STAGES", "Tracker", "TrackerParams", "TrackerSample", "TrackingState", "centroids_used"]


class TrackingState(enum.IntEnum):
    """What the tracker is doing."""

    WAITING = 0  # not identified yet: waiting for the reference pose
    TRACKING = 1


@dataclass(frozen=True, slots=True)
class TrackerSample:
    """The tracker's output for one frame set.

    Attributes:
        frame_index: frame number.
        time_s: time stamp of the frame set.
        state: WAITING (no names yet) or TRACKING.
        positions_m: (M, 3) float64 marker positions, world metres; NaN where lost.
        status: (M,) uint8 :class:`MarkerStatus` per marker.
        angles_deg: joint angles (docs/JOINT_ANGLES.md), NaN where undefined, and forearm
            supination NaN while an estimated elbow or wrist marker's axis is a guess
            (:attr:`tracking.hidden.Estimator.axis_guessed`).
        message: a one-line explanation while WAITING (e.g. which reference-pose rule fails); while
            TRACKING, what the self-checks found ("" when nothing).
        n_points: unlabelled points measured in full-frame mode this frame (0 in window mode).
        windows_px: (M, C, 3) float64 search window of each marker in each camera this frame:
            predicted image position (u, v) and half size, pixels (the pixels within the half size
            of the rounded position were searched); NaN where the marker had no window in that
            camera; None when no windows were searched (waiting for identification).
        uv_px: (M, C, 2) float64 centroid from which each marker's position was triangulated in
            each camera this frame (the window's, or the full frame's for the frame set that
            identifies the markers and a marker found again); NaN where none (not measured, view
            not used); None while waiting for identification.
        suspect: (M,) bool markers whose names the self-checks doubt this frame (the angles that
            need them are NaN); None while WAITING.
    """

    frame_index: int
    time_s: float
    state: TrackingState
    positions_m: np.ndarray
    status: np.ndarray
    angles_deg: dict[str, float]
    message: str = ""
    n_points: int = 0
    windows_px: np.ndarray | None = None
    uv_px: np.ndarray | None = None
    suspect: np.ndarray | None = None


#: Stages of :meth:`Tracker.step` reported by ``rehab bench``.
STEP_STAGES = (
    "windows (colour table + centroids)",
    "candidates + triangulation",
    "hidden markers",
    "full-frame re-acquisition",
    "joint angles",
)


class Tracker:
    """Labels and tracks the markers of one marker set seen by calibrated cameras.

    Args:
        cameras: calibrated cameras, in the order of the images passed to :meth:`step`.
        markerset: the markers worn by the patient (names, colours, segments, rules).
        table: the colour lookup table (default: built from the marker set's colours).
        params: tracking knobs.
        fps: frame rate of the source (for time stamps when none are given).
        compiled: where numba is installed and imports, run the search windows, the crowded
            windows (:mod:`tracking.window_kernel`), the triangulation
            (:class:`~tracking.triangulation.Triangulator`) and the arc fits' iterations
            (:func:`~tracking.blobs.arc_centres`) as compiled loops; False: the numpy paths (the
            same results to ~1e-12 m, 25-40 % slower per frame set).
    """

    def __init__(self, cameras: Sequence[Camera], markerset: MarkerSet, *, table: ColourTable | None = None,
                 params: TrackerParams = TrackerParams(), fps: float = 30.0, compiled: bool = True):
        self.cameras = tuple(cameras)
        self.markerset = markerset
        self.params = params
        self.fps = float(fps)
        self.table = table or ColourTable.build(markerset.palette)
        self.measurer = FrameMeasurer(self.cameras, self.table, markerset.radius_m, markers_per_colour=np.bincount(
            markerset.colour_index, minlength=self.table.n_colours))
        self.geometry: RigGeometry = self.measurer.geometry
        # the hot loops compiled where numba is installed and imports (see ``compiled``)
        self.compiled = bool(compiled) and window_kernel.usable([])  # (imports numba once)
        self.setup = Setup.of(self.cameras, markerset, self.geometry, self.compiled,
                              estimator_config(markerset)["length_pairs"])
        self.gates = self.setup.gates
        self.colour = markerset.colour_index
        # (a new configuration for each estimator: nothing of one run's can reach the next)
        self._estimator_factory = lambda: Estimator(**estimator_config(markerset), fps=self.fps)
        self.naming = Naming(self.cameras, markerset, params, self.fps)
        self.identifier = self.naming.identifier
        self.labeller = self.naming.labeller
        self.checks = SelfChecks(self.naming.roles) if self.naming.roles is not None else None
        self.times = StageTimes(STEP_STAGES)
        self._sizes = ImageSizes()
        self._luma = LumaLabels()
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget everything; the next frames identify the markers again."""
        self.state = TrackingState.WAITING
        self.memory = MarkerMemory.empty(self.markerset.n_markers, len(self.cameras))
        self.estimator = self._estimator_factory()
        self.frame_count = 0
        self.naming.reset()

    positions = property(lambda self: self.memory.positions, doc="(M, 3) the markers' last positions.")
    status = property(lambda self: self.memory.status, doc="(M,) the markers' last :class:`MarkerStatus`.")
    velocity = property(lambda self: self.memory.velocity, doc="(M, 3) displacement per frame set.")
    frames_unmeasured = property(lambda self: self.memory.frames_unmeasured, doc="(M,) frame sets unmeasured.")
    seg_length = property(lambda self: self.memory.seg_length, doc="(M, M) learned segment lengths.")

    @property
    def hold_frames(self) -> int:
        """Still frame sets after the first that the patient holds before the markers are named."""
        return self.naming.hold_frames

    def compile_loops(self, images: Sequence[np.ndarray]) -> None:
        """Compile (or load from numba's disk cache) every compiled loop for these images' types
        now, on a few pixels, instead of at the first frame set that needs each: a first
        compilation takes seconds, which the tracker process must spend before it reports ready,
        not between heartbeats. Nothing to do without numba."""
        if not (self.compiled and window_kernel.usable(images)):
            return
        n = len(images)
        boxes = np.zeros((n, 4), dtype=np.int64)
        boxes[:, 2:] = 2
        label = self.setup.label
        window_kernel.window_moments(images, self.table.lut, np.arange(n), boxes, label[np.zeros(n, int)],
                                     self.table.bits)
        window_kernel.crowded_window(images[0], self.table.lut, self.table.bits, (0, 0, 2, 2), int(label[0]),
                                     np.zeros(2), self.gates[0])
        if self.params.window_luma:
            window_kernel.fill_labels(images, self.table.lut, np.arange(n), boxes, self.table.bits,
                                      self._luma.of(images))
        seen = np.zeros((1, n), dtype=bool)
        seen[0, :2] = True
        self.setup.triangulate(np.zeros((1, n, 2)), seen)
        region = np.zeros(3, dtype=np.int64)
        arcs = ArcRegions()
        arcs.add_many(region, np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.zeros((1, 2)), np.zeros((1, 2)),
                      np.array([1.0]), np.zeros((1, 2)), np.full((1, 2), 4.0), np.zeros((1, 2)), np.zeros(1, int),
                      np.zeros(1, int), np.ones(1))
        arcs.fit(compiled=True, images=images if self.params.arc_subpixel else None)

    def reidentify(self) -> None:
        """Identify the markers again from the next frame (the patient takes the reference pose)."""
        self.reset()

    def set_colour_table(self, table: ColourTable) -> None:
        """Use ``table`` from the next frame on, in the windows and the full-frame search (e.g.
        learned colours, docs/COLOUR.md)."""
        self.table = table
        self.measurer.table = table

    # ------------------------------------------------------------------ the step
    def step(self, images: Sequence[np.ndarray], time_s: float | None = None,
             stamps_s: np.ndarray | None = None) -> TrackerSample:
        """Process one frame set (one BGR image per camera, calibration order) of instant ``time_s``.

        ``stamps_s``: (C,) the instant of each image (its first row's under a rolling shutter), on
        the clock of ``time_s``; NaN where unknown. Cameras that do not image at the set's instant
        (free-running clocks, rolling shutters: ``Camera.rolling_shutter_s``) have their window
        centroids brought to the set's instant before triangulation, with the motion that the
        tracker predicts for each marker (its velocity from the last frame sets). None: every image
        taken at ``time_s``.
        """
        if len(images) != len(self.cameras):
            raise RehabError(f"the tracker has {len(self.cameras)} cameras but got {len(images)} images")
        index = self.frame_count
        self.frame_count += 1
        t = index / self.fps if time_s is None else float(time_s)
        frame = FrameState(index, t, frame_skew(self.setup, t, stamps_s))
        message = ""
        if self.state == TrackingState.WAITING:
            t0 = time.perf_counter()
            points, views = self.measurer.measure_views(images)
            frame.n_points = len(points)
            message = self._identify(frame, points, views)
            self.times.add("full-frame re-acquisition", time.perf_counter() - t0)
        else:
            self._track(frame, images)
        t0 = time.perf_counter()
        angles = {}
        suspect = None
        if self.state == TrackingState.TRACKING:
            suspect, message = self_check(self.checks, self.memory, self.estimator, self.markerset.names,
                                          self.params, self.frame_count - 1)
            # angles that need a suspect marker are withheld (NaN), the reason in the message
            angles = checked_angles(self.memory.positions, suspect, self.estimator.axis_guessed, self.markerset.names,
                                    self.markerset.roles)
        self.times.add("joint angles", time.perf_counter() - t0)
        self.times.frames += 1
        return TrackerSample(frame_index=index, time_s=t, state=self.state, positions_m=self.memory.positions.copy(),
                             status=self.memory.status.copy(), angles_deg={k: float(v) for k, v in angles.items()},
                             message=message, n_points=frame.n_points, windows_px=frame.windows_px,
                             uv_px=frame.used_uv, suspect=suspect)

    def _identify(self, frame: FrameState, points: Points3D, views: Sequence[CameraObservations]) -> str:
        """Name the markers from the full frame's points; start tracking when named."""
        idx, message = self.naming.name(points, views)
        if idx is None:
            return message
        # marker k at point idx[k] (-1: not seen yet, found later); ``views`` are the centroids the
        # points were triangulated from
        ok = idx >= 0
        frame.used_uv = centroids_used(points, views, idx)
        mem = self.memory
        mem.positions[:] = np.nan
        mem.positions[ok] = points.p_world_m[idx[ok]]
        mem.status[:] = np.where(ok, MarkerStatus.MEASURED, MarkerStatus.LOST)
        mem.velocity[:] = 0.0
        mem.seen_pos[:] = np.nan
        mem.seen_velocity[:] = 0.0
        mem.frames_unmeasured[:] = np.where(ok, 0, 1)
        learn_lengths(self.setup, self.params, mem, ok)
        mem.last_seen[ok] = mem.positions[ok]
        self.estimator.update(mem.positions.copy(), ok)
        self.state = TrackingState.TRACKING
        log.info("markers identified at frame %d", self.frame_count - 1)
        return ""

    def _track(self, frame: FrameState, images: Sequence[np.ndarray]) -> None:
        """One tracked frame set through the stages (docs/ARCHITECTURE.md)."""
        setup, p, mem = self.setup, self.params, self.memory
        predict(frame, mem, p)
        t0 = time.perf_counter()
        uv, rad = window_observations(setup, p, self.table, frame, mem, self.fps, self._sizes, images, self._luma)
        t1 = time.perf_counter()
        choice = choose_views(setup, p, frame, uv, rad)
        new_pos, measured = accept(setup, p, frame, mem, choice, uv, rad)
        if frame.skew_s is not None:
            correct_to_set_instant(setup, frame, mem, self.fps, uv, choice.xn, choice.xn_seen, choice.seen, measured,
                                   new_pos)
        frame.used_uv = np.where((choice.seen & measured[:, None])[..., None], uv, np.nan)
        rays = full_views_as_rays(setup, p, choice.xn, choice.seen & ~measured[:, None] & p.full_view(choice.ratio_pred))
        if rays is not None:  # (the estimator forgets the views of the last frame by itself)
            self.estimator.observe_views(*rays)
        t2 = time.perf_counter()
        self.times.add("windows (colour table + centroids)", t1 - t0)
        self.times.add("candidates + triangulation", t2 - t1)
        found = np.zeros_like(measured)
        search = search_now(p, mem, measured, self.frame_count)
        if search.any():
            t3 = time.perf_counter()
            points, views = self.measurer.measure_views(images)
            frame.n_points = len(points)
            taken = reacquire(setup, p, mem, self.identifier, points, new_pos, measured, search)
            found = taken >= 0
            if found.any():  # the views of the found markers: those of the full-frame points they took
                frame.used_uv = np.where(found[:, None, None], centroids_used(points, views, taken), frame.used_uv)
            self.times.add("full-frame re-acquisition", time.perf_counter() - t3)
        t4 = time.perf_counter()
        est_pos, status = estimate_hidden(setup, p, frame, self.estimator, new_pos, measured)
        self.times.add("hidden markers", time.perf_counter() - t4)
        if remember(setup, p, frame, mem, est_pos, status, measured, found):
            log.warning("most markers lost for %d frames: identifying again", mem.lost_streak)
            self.reset()
