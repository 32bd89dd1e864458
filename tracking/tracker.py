"""The per-frame tracker: one object, ``step(images) -> TrackerSample``, for every driver.

docs/METHOD.md sections 5.2-5.4, online (no look-ahead):

1. **Identification** on the reference pose: full-frame measurement, then names from the
   marker set's rules (:mod:`tracking.identify`).
2. **Tracking**: each marker's next position is predicted from its history; the prediction is
   projected into every camera and the colour table runs only inside a search window sized from
   the prediction's uncertainty; the blobs of the marker's colour in the windows give candidate
   3D points, and the candidate with the largest marker confidence Q (equation 4) that is also
   geometrically consistent (distance to the prediction, segment lengths to the other measured
   markers) is taken.
3. **Hidden markers**: a marker without a consistent candidate is estimated from its own and
   its neighbours' motion (:mod:`tracking.hidden`), or reported lost.
4. **Re-acquisition**: lost markers are searched in the full frame every few frames; if most
   markers are lost for long, the tracker identifies again (also on request).

Pure computation on arrays: no files, processes or GL.
"""

from __future__ import annotations

import enum
import logging
import math
import time
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from calibration.camera import Camera, CameraStack
from calibration.errors import RehabError
from tracking.angles import AXIS_ANGLES, joint_angles
from tracking.blobs import ARC_EDGE_SHRINK_PX, PIXEL_MOMENT, arc_centres, axis_ratio, find_blobs
from tracking.colour_table import ColourTable
from tracking.markerset import MarkerSet
from tracking.measure import FrameMeasurer, StageTimes, blob_gates
from tracking.reconstruction import CameraObservations, Points3D, RigGeometry
from tracking.status import MarkerStatus
from tracking import window_kernel
from tracking.triangulation import Triangulator

log = logging.getLogger(__name__)


_MEASURED = np.uint8(MarkerStatus.MEASURED)


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


@dataclass(frozen=True, slots=True)
class TrackerParams:
    """Knobs of the tracker.

    Attributes:
        base_sigma_m: position uncertainty of a prediction for a marker measured last frame.
        accel_sigma_m: added uncertainty per frame without a measurement (unmodelled motion).
        max_sigma_frames: the uncertainty stops growing after this many frames (the hidden-marker
            estimate, not the extrapolation, is the prediction then).
        speed_sigma: added uncertainty as a fraction of the marker's displacement per frame (a fast
            swing changes velocity more between frames than a slow one).
        window_sigmas: search-window half size in prediction standard deviations (plus the ball).
        max_window_px: cap on the window half size.
        gate_sigmas: a candidate farther than this many sigmas from the prediction is rejected.
        same_ball_m: two markers whose candidates are nearer than this hold the same ball: only one
            keeps it.
        segment_tol_m: largest change of a learned distance to a neighbour on the same segment.
        reacquire_every: full-frame search for lost markers every this many frames.
        reacquire_radius_m: a lost marker with no measured neighbour on its segment takes a free
            point of its colour this near to where it was last seen.
        stale_after: an estimated marker unmeasured for this many frames is searched for in the
            full frame too (its estimate may have drifted off its ball, e.g. after the cameras
            were blocked while the arm moved: its windows then miss it for good), every
            ``reacquire_stale_every`` frames.
        reidentify_after: identify again when more than half the markers are lost this many frames.
        identify_hold_s: the markers are named only once the patient has held still this long
            (:class:`tracking.labelling.still.Stillness`; 0.2 s in ``rehab validate
            --population``); 0 (the default for now): on any frame set, moving or not.
        max_reproj_px: largest RMS reprojection error of a candidate.
        max_reproj_px_two_view: the same for a candidate seen by two cameras only (which must also
            show a ball of the right size in both).
        max_loo_px: of three or more views, the worst is dropped when the point triangulated
            from the others misses it by more than this (a wrong ball in one view).
        view_choice_margin_m: of three or more views, the worst is dropped unless another view's
            removal leaves a fitting point this much nearer the prediction (then that view goes).
        partial_ratio, oversize_ratio: a view whose blob radius is below / above these fractions
            of the ball's projected radius is left out while two other views remain (a partly
            hidden ball: centroid shifted by ~1 px at 0.8-0.9; a blob holding another ball of the
            colour: 0.8 of those above 1.1 were > 2 px off in the simulated motions); a
            two-view candidate needs both views at most ``oversize_ratio``.
        marker_sigma_px: position noise of a measured marker, in pixels of the camera nearest to it
            (its pixel's size there), for the hidden-marker estimator's weights
            (:attr:`~tracking.hidden.Estimator.marker_sigma_m`).
        view_sigma_px: centroid uncertainty of a single full view of a marker that is not
            measured; such views go to the hidden-marker estimator as rays
            (:meth:`~tracking.hidden.Estimator.observe_views`).
        arc_fit_ratio, arc_fit_roundness: a window region whose equivalent radius is below
            ``arc_fit_ratio`` times the ball's (projected radius less ``ARC_EDGE_SHRINK_PX``), or
            whose roundness is below ``arc_fit_roundness``, is taken for a partly hidden ball: its
            centre is fitted to the visible arc of its outline (:func:`~tracking.blobs.arc_centres`)
            instead of its centroid. In the simulated motions at 640x480 this takes 99.8 % of the
            views of balls 10-50 % hidden and 0.2 % of the whole ones (at 320x240 a third of the
            whole ones too: balls of 2.5-3.5 px are seldom round); all 0 turn it off.
        arc_fit_all_below_px: every region (not larger than the whole ball) of a ball whose
            radius (less ``ARC_EDGE_SHRINK_PX``) is below this is fitted: on balls of a few pixels
            neither size nor roundness tells a partly hidden ball, and the fit leaves a whole
            ball's centre where its centroid is (0.168 px RMS either way on the 5661 whole views
            of trunk_lean_compensation at 320x240).
        arc_subpixel: fit those arcs a second time on edges placed by the pixels' coverage
            (``colours`` of :func:`~tracking.blobs.arc_centres`): a binary region reaches into a
            dark background and stops short of a bright one, which moved the centres of partly
            hidden balls 0.2-0.4 px (docs/TRACKING.md, "Partly hidden balls: edges placed by
            coverage"). False: the binary fit alone.
    """

    base_sigma_m: float = 0.008
    accel_sigma_m: float = 0.006
    max_sigma_frames: int = 5
    speed_sigma: float = 0.35
    window_sigmas: float = 2.5
    max_window_px: float = 80.0
    gate_sigmas: float = 3.0
    same_ball_m: float = 0.025
    segment_tol_m: float = 0.03
    reacquire_every: int = 3
    reacquire_radius_m: float = 0.08
    stale_after: int = 3
    reacquire_stale_every: int = 6
    reidentify_after: int = 30
    identify_hold_s: float = 0.0
    max_reproj_px: float = 2.5
    max_reproj_px_two_view: float = 1.2
    max_loo_px: float = 3.0
    partial_ratio: float = 0.88
    view_choice_margin_m: float = 0.02
    oversize_ratio: float = 1.1
    view_sigma_px: float = 0.5
    marker_sigma_px: float = 0.25
    arc_fit_ratio: float = 0.95
    arc_fit_roundness: float = 0.9
    arc_fit_all_below_px: float = 4.0
    arc_subpixel: bool = True

    def full_view(self, ratio: np.ndarray) -> np.ndarray:
        """Views whose blob radius over the ball's projected radius (``ratio``) shows the whole
        ball: neither partly hidden nor holding more than the ball (False for NaN)."""
        return (ratio >= self.partial_ratio) & (ratio <= self.oversize_ratio)


_ONES2 = np.ones(2)  # row sums of (N, 2) and (N, 3) arrays as matrix products
_ONES3 = np.ones(3)

#: Stages of :meth:`Tracker.step` reported by ``rehab bench``.
STEP_STAGES = (
    "windows (colour table + centroids)",
    "candidates + triangulation",
    "hidden markers",
    "full-frame re-acquisition",
    "joint angles",
)


class _ArcRegions:
    """Window regions of partly hidden balls gathered for one :func:`~tracking.blobs.arc_centres`
    call (one vectorized fit for all of a frame's), each with its own pixel origin."""

    def __init__(self) -> None:
        self.count = 0
        self._parts: list[tuple[np.ndarray, ...]] = []

    def add_many(self, region: np.ndarray, x: np.ndarray, y: np.ndarray, start_px: np.ndarray, prior_px: np.ndarray,
                 radius_px: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray, origin_px: np.ndarray,
                 marker: np.ndarray, camera: np.ndarray, prior_sigma_px: np.ndarray) -> None:
        """K regions: (P,) region index 0..K-1, pixel x, y relative to each region's (K, 2) origin
        (full-image pixels); (K, 2) centroids and predicted centres, (K,) radii, (K, 2) searched
        boxes (inclusive), all relative to the origin; (K,) marker and camera of each, and the
        prediction's uncertainty (px)."""
        self._parts.append((region + self.count, np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64),
                            start_px, prior_px, radius_px, np.asarray(box_lo, dtype=np.float64),
                            np.asarray(box_hi, dtype=np.float64), np.asarray(origin_px, dtype=np.float64),
                            marker, camera, np.asarray(prior_sigma_px, dtype=np.float64)))
        self.count += len(radius_px)

    def add_region(self, mask: np.ndarray, centroid_px: np.ndarray, prior_px: np.ndarray, origin_px: tuple[int, int],
                   radius_px: float, marker: int, camera: int, prior_sigma_px: float) -> None:
        """The 8-connected region of ``mask`` (a whole searched window at ``origin_px``) nearest
        the (full-image) ``centroid_px``; ``prior_px`` the (full-image) predicted centre, uncertain
        by ``prior_sigma_px``."""
        origin = np.array(origin_px, dtype=np.float64)
        local = centroid_px - origin
        _, regions = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
        ys, xs = np.nonzero(mask)
        nearest = np.argmin((xs - local[0]) ** 2 + (ys - local[1]) ** 2)
        ys, xs = np.nonzero(regions == regions[ys[nearest], xs[nearest]])
        self.add_pixels(xs, ys, centroid_px, prior_px, origin_px, mask.shape[::-1], radius_px, marker, camera,
                        prior_sigma_px)

    def add_pixels(self, xs: np.ndarray, ys: np.ndarray, centroid_px: np.ndarray, prior_px: np.ndarray,
                   origin_px: tuple[int, int], size_px: tuple[int, int], radius_px: float, marker: int, camera: int,
                   prior_sigma_px: float) -> None:
        """One region given by its pixels (window coordinates, raster order) in a searched window
        of ``size_px`` (width, height) at ``origin_px``; the rest as :meth:`add_region`."""
        origin = np.array(origin_px, dtype=np.float64)
        w, h = size_px
        self.add_many(np.zeros(len(xs), dtype=np.int64), xs, ys, (np.asarray(centroid_px) - origin)[None, :],
                      (np.asarray(prior_px) - origin)[None, :], np.array([radius_px]),
                      np.zeros((1, 2)), np.array([[w - 1.0, h - 1.0]]), origin[None, :], np.array([marker]),
                      np.array([camera]), np.array([prior_sigma_px]))

    def fit(self, compiled: bool = False, images: Sequence[np.ndarray] | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(K,) markers, (K,) cameras and (K, 2) fitted centres in full-image pixels (``compiled``:
        see :func:`~tracking.blobs.arc_centres`; ``images``: the frame set's images, for the
        sub-pixel fit on the pixels' coverage, ``colours`` there)."""
        if len(self._parts) == 1:
            cols = self._parts[0]
        else:
            cols = [np.concatenate(parts) for parts in zip(*self._parts)]
        region, x, y, start, prior, radius, lo, hi, origin, marker, camera, prior_sigma = cols
        colours = None if images is None else (images, camera, origin)
        return marker, camera, origin + arc_centres(region, x, y, start, radius, lo, hi, prior_px=prior,
                                                    prior_sigma_px=prior_sigma, compiled=compiled,
                                                    colours=colours)


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
        from tracking.hidden import Estimator, estimator_config
        from tracking.identify import Identifier
        from tracking.labelling import BodyRoles, Labeller
        from tracking.labelling.checks import SelfChecks
        from tracking.labelling.still import Snapshot, Stillness

        self.cameras = tuple(cameras)
        self.markerset = markerset
        self.params = params
        self.fps = float(fps)
        self.table = table or ColourTable.build(markerset.palette)
        self.measurer = FrameMeasurer(self.cameras, self.table, markerset.radius_m, markers_per_colour=np.bincount(
            markerset.colour_index, minlength=self.table.n_colours))
        self.geometry: RigGeometry = self.measurer.geometry
        self.gates = [blob_gates(c, markerset.radius_m) for c in self.cameras]
        self._stack = CameraStack(self.cameras)
        # the hot loops compiled where numba is installed and imports (see ``compiled``)
        self.compiled = bool(compiled) and window_kernel.usable([])  # (imports numba once)
        self._triangulate = Triangulator(self.geometry.extrinsics, compiled=self.compiled)
        self._ones_cams = np.ones(len(self.cameras))
        self._cam_centres = np.array([c.centre_m for c in self.cameras])
        self._min_area_px = np.array([g.min_area_px for g in self.gates])
        self.colour = markerset.colour_index
        self._label = (self.colour + 1).astype(np.uint8)  # each marker's label in the colour table
        self._estimator_factory = lambda: Estimator(**estimator_config(markerset), fps=self.fps)
        self.identifier = Identifier(markerset)
        roles = BodyRoles.of(markerset)
        self.labeller = Labeller.for_markerset(markerset) if roles is not None else None
        self.checks = SelfChecks(roles) if roles is not None else None
        self._stillness = Stillness(self.fps, params.identify_hold_s) if params.identify_hold_s > 0 else None
        self._snapshot = Snapshot()
        self._last_message = ""
        self.times = StageTimes(STEP_STAGES)
        m = markerset.n_markers
        # pairs of markers whose distance is (nearly) constant: markers of one segment, and the
        # near-rigid pairs across a joint that the marker set names (hidden_markers.limits)
        seg = np.array(markerset.segments)
        self._same_segment = (seg[:, None] == seg[None, :]) & ~np.eye(m, dtype=bool)
        for i, j in estimator_config(markerset)["length_pairs"]:
            self._same_segment[i, j] = self._same_segment[j, i] = True
        # pairs of markers of one colour: their windows can hold the same ball
        self._colour_pairs = np.argwhere(np.triu(self.colour[:, None] == self.colour[None, :], 1))
        self._colour_pairs_ij = tuple(np.ascontiguousarray(self._colour_pairs.T))
        # rolling shutter: seconds per pixel row of each camera (0: global shutter)
        self._row_s = np.array([c.rolling_shutter_s / c.size_px[1] for c in self.cameras])
        self._rolling = bool(self._row_s.any())
        self._skew_s: np.ndarray | None = None  # (C,) this frame set: each image's instant - the set's
        self._moving_cam: np.ndarray | None = None  # (M, C, 3) the markers' camera-frame velocity, m/s
        self._image_shapes: list[tuple[int, ...]] = []
        self._image_size = np.zeros((0, 2), dtype=np.int64)
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget everything; the next frames identify the markers again."""
        m = self.markerset.n_markers
        self.state = TrackingState.WAITING
        self.positions = np.full((m, 3), np.nan)
        self.velocity = np.zeros((m, 3))
        # images off the frame set's instant: each marker's views as seen in the last two frame sets
        # (normalized x, y and the view's instant of the last, then of the one before; NaN where not
        # used) and the velocity per frame set that brings this set's views to its instant, from
        # each view's image motion since then (free of its own correction, which fed back into the
        # corrected positions' velocity and oscillated under a rolling shutter)
        self._seen_pos = np.full((m, len(self.cameras), 6), np.nan)
        self._seen_velocity = np.zeros((m, 3))
        self.status = np.full(m, MarkerStatus.LOST, dtype=np.uint8)
        self.frames_unmeasured = np.zeros(m, dtype=np.int64)
        self.seg_length = np.full((m, m), np.nan)  # learned distances on segments
        self._last_seen = np.full((m, 3), np.nan)  # last measured position of each marker
        self.estimator = self._estimator_factory()
        self.frame_count = 0
        self._lost_streak = 0
        self._exchanged_streak = 0
        if getattr(self, "_stillness", None) is not None:
            self._stillness.reset()
        if getattr(self, "_snapshot", None) is not None:
            self._snapshot.reset()

    @property
    def hold_frames(self) -> int:
        """Still frame sets after the first that the patient holds before the markers are named."""
        return self._stillness.frames_needed if self._stillness is not None and self.labeller is not None else 0

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
        window_kernel.window_moments(images, self.table.lut, np.arange(n), boxes, self._label[np.zeros(n, int)],
                                     self.table.bits)
        window_kernel.crowded_window(images[0], self.table.lut, self.table.bits, (0, 0, 2, 2), int(self._label[0]),
                                     np.zeros(2), self.gates[0])
        seen = np.zeros((1, n), dtype=bool)
        seen[0, :2] = True
        self._triangulate(np.zeros((1, n, 2)), seen)
        region = np.zeros(3, dtype=np.int64)
        arcs = _ArcRegions()
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
        self._set_time_s = t
        self._skew_s = None
        if stamps_s is not None:
            skew = np.nan_to_num(np.asarray(stamps_s, dtype=np.float64).reshape(-1) - t)  # (unknown: 0)
            if skew.size != len(self.cameras):
                raise RehabError(f"the tracker has {len(self.cameras)} cameras but got {skew.size} time stamps")
            if skew.any():
                self._skew_s = skew
        if self._skew_s is None and self._rolling:
            self._skew_s = np.zeros(len(self.cameras))
        message = ""
        n_points = 0
        self._windows_px = self._used_uv = None
        if self.state == TrackingState.WAITING:
            t0 = time.perf_counter()
            points, views = self.measurer.measure_views(images)
            n_points = len(points)
            message = self._try_identify(points, views)
            self.times.add("full-frame re-acquisition", time.perf_counter() - t0)
        else:
            n_points = self._track(images)
        t0 = time.perf_counter()
        angles = {}
        suspect = None
        if self.state == TrackingState.TRACKING:
            suspect, message = self._self_check()
            # angles that need a suspect marker are withheld (NaN), the reason in the message
            angles = joint_angles(np.where(suspect[:, None], np.nan, self.positions), self.markerset.names)
            for k in np.flatnonzero(self.estimator.axis_guessed).tolist():
                # an elbow or wrist axis that no measurement pins: no supination rather than a guess
                name = AXIS_ANGLES.get(self.markerset.names[k])
                if name in angles:
                    angles[name] = math.nan
        self.times.add("joint angles", time.perf_counter() - t0)
        self.times.frames += 1
        return TrackerSample(
            frame_index=index,
            time_s=t,
            state=self.state,
            positions_m=self.positions.copy(),
            status=self.status.copy(),
            angles_deg={k: float(v) for k, v in angles.items()},
            message=message,
            n_points=n_points,
            windows_px=self._windows_px,
            uv_px=self._used_uv,
            suspect=suspect,
        )

    # ------------------------------------------------------------------ self-checks
    def _self_check(self) -> tuple[np.ndarray, str]:
        """The labelling's per-frame checks (:mod:`tracking.labelling.checks`): a pair of markers
        found exchanged two frame sets running is named back; until then, and where the checks
        cannot tell which pair, the markers are suspect. Returns (suspect (M,), reason or "")."""
        m = self.markerset.n_markers
        if self.checks is None:
            return np.zeros(m, bool), ""
        res = self.checks.check(self.positions, self.markerset.names)
        suspect = res.suspect.copy()
        if not res.relabel:
            self._exchanged_streak = 0
            return suspect, res.reason
        self._exchanged_streak += 1
        if self._exchanged_streak < 2:
            for i, j in res.relabel:
                suspect[[i, j]] = True
            return suspect, res.reason.replace("named back", "suspect, angles that need them withheld")
        for i, j in res.relabel:
            self._exchange(i, j)
        self._exchanged_streak = 0
        log.warning("self-check at frame %d: %s", self.frame_count - 1, res.reason)
        return suspect, res.reason

    def _exchange(self, i: int, j: int) -> None:
        """Exchange the names of markers i and j (everything the tracker holds about them); the
        hidden-marker estimator starts afresh from the measured markers."""
        for a in (self.positions, self.velocity, self.status, self.frames_unmeasured, self._last_seen,
                  self._seen_pos, self._seen_velocity):
            a[[i, j]] = a[[j, i]]
        self.seg_length[[i, j]] = self.seg_length[[j, i]]
        self.seg_length[:, [i, j]] = self.seg_length[:, [j, i]]
        measured = self.status == MarkerStatus.MEASURED
        self.estimator.reset()
        self.estimator.update(np.where(measured[:, None], self.positions, np.nan), measured)

    # ------------------------------------------------------------------ identification
    def _try_identify(self, points: Points3D, views: Sequence[CameraObservations]) -> str:
        """Name the markers once the patient holds the reference pose still, by the labelling's fit
        (:mod:`tracking.labelling`); while no labelling is confident the message says why, in the
        marker set's rules' words where a rule fails. A marker set whose YAML does not name the
        body model's landmarks is named by its rules alone (:mod:`tracking.identify`)."""
        from tracking.identify import IdentificationError, single_view_rays, try_identify

        if self.labeller is not None:
            held = self._stillness.update(points.p_world_m, points.colour) if self._stillness is not None else 1.0
            if held < 1.0:
                return f"hold the reference pose still ({100 * held:.0f} %)"
            if self._stillness is not None and (self._stillness.count - self._stillness.frames_needed) % 3 != 0:
                return self._last_message  # (still and not confident: judged again every third frame set)
        rays = single_view_rays(self.cameras, views, points, self.markerset.radius_m)
        if self.labeller is not None and self._snapshot.same(points.p_world_m, points.colour, rays.colour):
            return self._last_message  # (judged on these points already, not confident)
        if self.labeller is None or not self.labeller.takes(points.colour, rays):
            # more markers without a point (or without a ray) than the fit takes: the rules with
            # the single-camera rays name them, and the body model must find the names within its
            # ranges; not with one colour for all markers (there the rules' search with many
            # stand-ins takes seconds and is what named elbow pairs exchanged): the counts are reported
            # nor with more markers without a point than the fit ever places (its search on rays
            # took 5-15 s per frame set with 12 of 14 markers seen by one camera or none, and
            # could not name them with any confidence): the counts are reported
            if self.labeller is not None and (len(self.identifier.words) == 1
                                              or self._without_point(points).sum() > self.labeller.max_on_rays):
                self._last_message = self.identifier.count_problem(np.asarray(points.colour)) or \
                    "waiting for the reference pose"
                return self._last_message
            try:
                ident = try_identify(points, self.identifier, rays)
            except IdentificationError as exc:
                self._last_message = str(exc)
                return self._last_message
            if ident is not None and (self.labeller is None or self.labeller.score_of(
                    points.p_world_m, ident.index, ident.yaw_deg) <= self.labeller.max_score):
                return self._start_tracking(points, np.asarray(ident.index), views)
            self._last_message = (self.identifier.count_problem(np.asarray(points.colour))
                                  or "waiting for the reference pose")
            return self._last_message
        lab = self.labeller.label(points.p_world_m, points.colour, rays)
        if lab.confident:
            log.info("labelled with score %.1f, margin %.1f", lab.score, lab.margin)
            return self._start_tracking(points, np.asarray(lab.index), views)
        self._last_message = self._not_confident(points, views, lab, rays)
        return self._last_message

    def _not_confident(self, points: Points3D, views: Sequence[CameraObservations], lab, rays) -> str:
        """Why no labelling is confident: the point counts, else the marker set's rule that fails
        (the seed's ordering rules, in their plain words), else the fit's own words. The rules'
        explanation is not looked for with one colour and more than ``max_unseen`` markers without
        a point (its search with stand-ins takes seconds): the counts, or the fit's words."""
        from tracking.identify import IdentificationError

        colour = np.asarray(points.colour)[np.isfinite(points.p_world_m).all(axis=1)]
        short = self._without_point(points)
        if np.any(short < 0):
            return self.identifier.count_problem(colour) or "waiting for the reference pose"
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

    def _start_tracking(self, points: Points3D, idx: np.ndarray, views: Sequence[CameraObservations]) -> str:
        """Start tracking with marker k at point ``idx[k]`` (-1: not seen yet, found later);
        ``views`` are the centroids the points were triangulated from."""
        ok = idx >= 0
        self._used_uv = centroids_used(points, views, idx)
        self.positions[:] = np.nan
        self.positions[ok] = points.p_world_m[idx[ok]]
        self.status[:] = np.where(ok, MarkerStatus.MEASURED, MarkerStatus.LOST)
        self.velocity[:] = 0.0
        self._seen_pos[:] = np.nan
        self._seen_velocity[:] = 0.0
        self.frames_unmeasured[:] = np.where(ok, 0, 1)
        self._learn_lengths(ok)
        self._last_seen[ok] = self.positions[ok]
        self.estimator.update(self.positions.copy(), ok)
        self.state = TrackingState.TRACKING
        log.info("markers identified at frame %d", self.frame_count - 1)
        return ""

    # ------------------------------------------------------------------ tracking
    def _track(self, images: Sequence[np.ndarray]) -> int:
        p = self.params
        known = np.isfinite(self.positions).all(axis=1)
        pred = np.where(known[:, None], self.positions + self.velocity, np.nan)
        speed = np.linalg.norm(self.velocity, axis=1)
        sigma = (p.base_sigma_m + p.accel_sigma_m * np.minimum(self.frames_unmeasured, p.max_sigma_frames)
                 + p.speed_sigma * speed)

        t0 = time.perf_counter()
        cand = self._window_observations(images, pred, sigma, known)
        t1 = time.perf_counter()
        new_pos, measured = self._choose(cand, pred, sigma, known)
        t2 = time.perf_counter()
        self.times.add("windows (colour table + centroids)", t1 - t0)
        self.times.add("candidates + triangulation", t2 - t1)

        n_points = 0
        search = ~measured & (self.status == MarkerStatus.LOST) & (self.frame_count % p.reacquire_every == 0)
        if self.frame_count % p.reacquire_stale_every == 0:
            search |= ~measured & (self.status == MarkerStatus.ESTIMATED) & (self.frames_unmeasured >= p.stale_after)
        found = np.zeros_like(measured)
        if search.any():
            t3 = time.perf_counter()
            points, views = self.measurer.measure_views(images)
            n_points = len(points)
            taken = self._reacquire(points, new_pos, measured, search)
            found = taken >= 0
            if found.any():  # the views of the found markers: those of the full-frame points they took
                self._used_uv = np.where(found[:, None, None], centroids_used(points, views, taken), self._used_uv)
            self.times.add("full-frame re-acquisition", time.perf_counter() - t3)

        t4 = time.perf_counter()
        if not measured.all():  # (the estimator reads the markers' noise only for its estimates)
            # each marker's position noise: a share of a pixel's size at its distance (nearest camera)
            footprint = np.fmin.reduce(self._pred_depth / self._stack.focal_px, axis=1)
            self.estimator.marker_sigma_m = np.where(np.isfinite(footprint), p.marker_sigma_px * footprint,
                                                     self.estimator.marker_sigma_m)
        est_pos, status = self.estimator.update(np.where(measured[:, None], new_pos, np.nan), measured)
        self.times.add("hidden markers", time.perf_counter() - t4)

        prev = self.positions
        self.positions = est_pos
        self.status = np.asarray(status, dtype=np.uint8)
        has = np.isfinite(est_pos).all(axis=1) & np.isfinite(prev).all(axis=1)
        # a marker found again far from its estimate: the jump is the estimate's error, not motion
        self.velocity = np.where((has & ~found)[:, None], est_pos - prev, 0.0)
        if self._skew_s is not None:
            self._seen_velocity = np.where((measured & np.isfinite(self._seen_now).all(axis=1))[:, None],
                                           self._seen_now, self.velocity)
            self._seen_pos = np.concatenate([np.where(measured[:, None, None], self._seen_views, np.nan),
                                             self._seen_pos[..., :3]], axis=2)
        else:
            self._seen_pos[:] = np.nan
        self.frames_unmeasured = np.where(measured, 0, self.frames_unmeasured + 1)
        self._last_seen[measured] = est_pos[measured]
        self._learn_lengths(measured)

        lost = self.status == MarkerStatus.LOST
        self._lost_streak = self._lost_streak + 1 if lost.sum() > len(lost) // 2 else 0
        if self._lost_streak >= self.params.reidentify_after:
            log.warning("most markers lost for %d frames: identifying again", self._lost_streak)
            self.reset()
        return n_points

    def _window_observations(self, images, pred, sigma, known):
        """Each marker's centroid in each camera, from the colour table inside its search window.

        Q (equation 4) is a product of one factor per camera, 1 / (1 + |G_j C_j|), so the candidate
        of largest Q takes in every camera the centroid nearest to the predicted image position.
        The window's pixels of the marker's colour usually form that one ball: its centroid comes
        from the mask's moments. Every marker is projected into every camera at once, and the
        windows of all markers in all cameras are gathered into one array for one table look-up
        (:meth:`ColourTable.classify_windows`); the moments are sums over the few marker-coloured
        pixels. A window whose mask is too large or not round holds several balls (or clutter):
        then its regions are separated and the one nearest to the prediction is taken.

        Returns:
            uv (M, C, 2) float64 centroids (NaN where none), radius (M, C) equivalent radius in px.
        """
        p = self.params
        m_count = self.markerset.n_markers
        n_cams = len(self.cameras)
        uv_out = np.empty((m_count, n_cams, 2))
        uv_out.fill(np.nan)
        rad_out = np.empty((m_count, n_cams))
        rad_out.fill(np.nan)
        if self._skew_s is None:
            uv, depth = self._stack.project(pred)  # predictions in each image (also for Q); NaN if unknown
        else:  # where each camera sees the marker: at its image's instant (and its row's)
            uv, depth = self._stack.project_camera_points(self._at_image_instants(pred))
        self._pred_uv, self._pred_depth = uv, depth
        focal = self._stack.focal_px
        safe_depth = np.maximum(depth, 1e-3)
        r_px = focal * self.markerset.radius_m / safe_depth
        sigma_px = focal * sigma[:, None] / safe_depth
        half = np.minimum(r_px * 1.2 + 2.0 + p.window_sigmas * sigma_px, p.max_window_px)
        shapes = [img.shape for img in images]
        if shapes != self._image_shapes:
            self._image_shapes = shapes
            self._image_size = np.array([s[1::-1] for s in shapes], dtype=np.int64)  # (C, 2) width, height
        size = self._image_size
        # in front of the camera (project() gives NaN behind it) and the window overlaps the image
        # (comparisons with NaN are False, without a warning)
        windows = np.empty((m_count, n_cams, 3))
        windows[..., :2] = uv
        windows[..., 2] = half
        valid = ((uv > -windows[..., 2:]) & (uv < size + windows[..., 2:])).all(axis=2) & known[:, None]
        windows[~valid] = np.nan
        self._windows_px = windows
        if valid.any():
            self._windows(images, valid, uv, half, r_px, sigma_px, known, size, uv_out, rad_out)
            self._one_ball_one_marker(uv, sigma_px, r_px, uv_out, rad_out)
        return uv_out, rad_out

    def _at_image_instants(self, pred: np.ndarray) -> np.ndarray:
        """(M, C, 3) camera-frame positions of the markers predicted at each camera's image
        instant: ``pred`` (the frame set's instant) moved by the marker's velocity for the image's
        skew, plus, under a rolling shutter, the time to the predicted row. Keeps the prediction
        and the velocity in camera frames for :meth:`_to_set_instant`."""
        cam = self._stack.world_to_cameras(pred)
        # velocity in m/s (the tracker's velocity is the displacement per frame set)
        self._moving_cam = self._stack.rotate_to_cameras(self._seen_velocity * self.fps)
        self._pred_cam = cam
        dt = np.broadcast_to(self._skew_s, cam.shape[:2])
        moved = cam + self._moving_cam * dt[..., None]
        if self._rolling:
            rows = self._stack.project_camera_points(moved)[0][..., 1]
            dt = self._skew_s + self._row_s * np.nan_to_num(rows)
            moved = cam + self._moving_cam * dt[..., None]
        return moved

    def _to_set_instant(self, xn: np.ndarray, uv: np.ndarray, moving: np.ndarray | None = None,
                        cam: np.ndarray | None = None) -> np.ndarray:
        """(M, C, 2) normalized centroids seen at each image's instant (``uv`` their pixel rows)
        -> where each marker's motion puts them at the frame set's instant. ``moving``: (M, C, 3)
        the markers' camera-frame velocities (m/s), ``cam`` their camera-frame positions (default:
        the prediction's, :meth:`_at_image_instants`)."""
        dt = self._skew_s + self._row_s * uv[..., 1]  # NaN where no centroid
        cam = self._pred_cam if cam is None else cam
        then = cam + (self._moving_cam if moving is None else moving) * dt[..., None]
        with np.errstate(invalid="ignore"):  # (NaN for unknown markers: not seen)
            return xn + cam[..., :2] / cam[..., 2:] - then[..., :2] / then[..., 2:]

    def _image_velocity(self, now: np.ndarray, before: np.ndarray) -> np.ndarray:
        """(M, 3) each marker's velocity (m/s, NaN where fewer than two cameras saw it in both frame
        sets) from its views' image motion: ``now`` and ``before`` (M, C, 3) the views as seen
        (normalized x, y, instant). Each camera's displacement ``dx_c`` over its own interval
        ``dt_c`` is ``J_c v dt_c`` (``J_c`` the projection's derivative at the prediction), solved
        for ``v`` by least squares over the cameras that saw the marker twice: a view that joins or
        leaves the set, or two cameras' instants far apart, do not move the point as a point
        triangulated from changing views did (that made single frame sets 10-16 mm off), and a
        camera whose phase wrapped (an interval of a few milliseconds) weighs by its interval."""
        dt = now[..., 2] - before[..., 2]  # (M, C), NaN unless seen in both
        dx = now[..., :2] - before[..., :2]
        ok = np.isfinite(dt) & np.isfinite(dx).all(axis=2) & (dt > 0)
        v = np.full((len(now), 3), np.nan)
        rows = np.flatnonzero(ok.sum(axis=1) >= 2)
        if rows.size == 0:
            return v
        cam = self._pred_cam[rows]  # (K, C, 3)
        with np.errstate(invalid="ignore", divide="ignore"):
            x = cam[..., :2] / cam[..., 2:]
            rot = self._stack.rotation  # (C, 3, 3) world -> camera
            jac = (rot[None, :, :2, :] - x[..., :, None] * rot[None, :, 2:3, :]) / cam[..., 2, None, None]
        a = (np.nan_to_num(jac) * np.where(ok[rows], dt[rows], 0.0)[..., None, None]).reshape(rows.size, -1, 3)
        b = np.where(ok[rows][..., None], dx[rows], 0.0).reshape(rows.size, -1, 1)  # (K, 2C, 1)
        at = a.transpose(0, 2, 1)
        normal = at @ a  # (K, 3, 3)
        # (two cameras seeing the marker along nearly one line leave a direction unknown)
        scale = np.trace(normal, axis1=1, axis2=2)
        good = np.linalg.det(normal) > 1e-9 * scale**3
        v[rows[good]] = np.linalg.solve(normal[good], (at @ b)[good])[..., 0]
        return v

    def _one_ball_one_marker(self, uv, sigma_px, r_px, uv_out, rad_out) -> None:
        """A ball that the windows of two markers of its colour both found (the same blob in one
        camera, e.g. a hidden wrist marker behind the elbow marker of its colour on one line of
        sight) is a view of the marker whose prediction makes it likelier only; the other loses
        that view. Likelier: the smaller ``d^2 / sigma^2 + 4 ln sigma`` (minus twice the log of a
        2D normal density; d the distance from the prediction, sigma its uncertainty, pixels), so
        a marker estimated for a while, whose wide uncertainty puts any ball near its prediction,
        does not take the ball of a marker measured last frame that is a little farther from its
        sharp prediction."""
        i, j = self._colour_pairs_ij
        d = uv_out[i] - uv_out[j]  # (P, C, 2), NaN where either has none (no warning: no inf)
        shared = (d * d).sum(axis=2) < 0.25 * np.minimum(r_px[i], r_px[j]) ** 2
        if not shared.any():
            return
        pair, cam = np.nonzero(shared)
        ab = np.stack((i[pair], j[pair]))  # (2, S) the two markers of each shared view
        s = sigma_px[ab, cam]
        score = ((uv_out[ab, cam] - uv[ab, cam]) ** 2).sum(axis=2) / (s * s) + 4.0 * np.log(s)
        a, b = ab
        loser = np.where(score[0] <= score[1], b, a)
        uv_out[loser, cam] = np.nan
        rad_out[loser, cam] = np.nan

    def _window_moments_numpy(self, images, mi, ci, lo, hi):
        """:func:`tracking.window_kernel.window_moments` in numpy (where numba is missing or an
        image is not C-contiguous): count (K,), sums (5, K), col, row (n,) of each window's pixels
        of its marker's colour."""
        labels, starts = self.table.classify_windows(images, ci, np.concatenate([lo, hi], axis=1))
        # the marker's own colour among the (few) marker-coloured pixels of each window; the
        # pixels come window after window, so each window's share is one run of them, found by
        # K binary searches (runs and repeats: no per-pixel window look-up)
        hit = np.flatnonzero(labels != 0)  # (a bool array has numpy's fast nonzero)
        bounds = np.searchsorted(hit, starts)
        own = labels[hit] == np.repeat(self._label[mi], np.diff(bounds))
        hit = hit[own]
        n = hit.size
        run = np.concatenate(([0], np.cumsum(own)))[bounds]  # each window's first own pixel, and n
        count = np.diff(run)
        run = run[:-1]
        # pixel -> column and row in its window, in float64 (exact for these small integers; a
        # float division is cheaper than an integer one)
        local = (hit - np.repeat(starts[:-1], count)).astype(np.float64)
        width = np.repeat((hi[:, 0] - lo[:, 0]).astype(np.float64), count)
        cr = np.empty((5, n + 1))  # per pixel: column, row, their squares and product; one 0 column
        cr[:, n] = 0.0
        col, row = cr[0, :n], cr[1, :n]
        np.floor(local / width, out=row)
        np.subtract(local, row * width, out=col)
        np.multiply(cr[:2, :n], cr[:2, :n], out=cr[2:4, :n])
        np.multiply(col, row, out=cr[4, :n])
        # the five sums of every window as one reduction over the runs (the zero column ends the
        # last; an empty run gives the next run's first element: set to 0), then taken about the
        # window's centre pixel (offset ``first`` from the window's first pixel): sums of
        # integers, exact in float64 whatever the order
        sums = np.add.reduceat(cr, run, axis=1)
        sums[:, count == 0] = 0.0
        return count, sums, col, row

    def _windows(self, images, valid, uv, half, r_px, sigma_px, known, size, uv_out, rad_out) -> None:
        """Fill uv_out/rad_out from the windows of the ``valid`` (M, C) markers and cameras.

        A window holds the pixels within ``half`` (rounded down) of the rounded prediction, cut at
        the image border; the moments are taken about that pixel centre.
        """
        at = np.flatnonzero(valid)  # (K,) flat (marker, camera) index of each window
        mi, ci = np.divmod(at, valid.shape[1])
        centre = np.round(uv.reshape(-1, 2)[at]).astype(np.int64)  # (K, 2) window centre pixel x, y
        ext = half.reshape(-1)[at].astype(np.int64)[:, None]  # half size rounded down (it is positive)
        size_k = size[ci]
        lo = np.minimum(np.maximum(centre - ext, 0), size_k)  # (K, 2) x0, y0
        hi = np.maximum(np.minimum(centre + ext + 1, size_k), lo)  # (K, 2) x1, y1 (exclusive)
        k_count = mi.size
        compiled = self.compiled and window_kernel.usable(images)
        if compiled:
            # one compiled pass over the windows' pixels (tracking.window_kernel): the same
            # counts, sums and pixel coordinates as the numpy path below, to the bit
            count, sums, col, row = window_kernel.window_moments(
                images, self.table.lut, ci, np.concatenate([lo, hi], axis=1), self._label[mi], self.table.bits)
        else:
            count, sums, col, row = self._window_moments_numpy(images, mi, ci, lo, hi)
        sc, sr, scc, srr, scr = sums
        first = (lo - centre).astype(np.float64).T  # (2, K) offsets of each window's first pixel
        fx, fy = first
        m00 = count.astype(np.float64)
        sxy = sums[:2] + m00 * first
        sx, sy = sxy
        with np.errstate(divide="ignore", invalid="ignore"):
            mxy = sxy / m00  # (2, K) centroid about the centre pixel
            mx, my = mxy
            mu20 = (scc + fx * (sc + sx)) / m00 - mx**2
            mu02 = (srr + fy * (sr + sy)) / m00 - my**2
            mu11 = (scr + fy * sc + fx * sy) / m00 - mx * my
            roundness = axis_ratio(mu20, mu02, mu11)
            round_px = axis_ratio(mu20, mu02, mu11, PIXEL_MOMENT)  # roundness as tracking.blobs measures it
        mxy = mxy.T
        r_k = r_px.reshape(-1)[at]
        ball_area = np.pi * r_k**2
        # a sliver (under 40 % of the ball's area) is a ball mostly hidden in this camera: no view
        ok = (m00 >= self._min_area_px[ci]) & (m00 >= 0.4 * ball_area)
        simple = ok & (m00 <= 1.6 * ball_area) & (roundness >= 0.6)
        radius = np.sqrt(m00 / np.pi)
        at_simple = at[simple]
        uv_out.reshape(-1, 2)[at_simple] = centre[simple] + mxy[simple]
        rad_out.reshape(-1)[at_simple] = radius[simple]
        # a partly hidden ball: its region's centroid lies towards the visible part; its centre
        # comes from the visible arc instead (only these few windows pay for it), all in one call
        # with those of the crowded windows below
        edge_r = r_k - ARC_EDGE_SHRINK_PX
        params = self.params
        # (a region larger than the whole ball is no partly hidden ball: two balls of the colour
        # touching, whose outline fits neither)
        part = simple & (m00 <= np.pi * edge_r**2) & ((m00 < np.pi * (params.arc_fit_ratio * edge_r) ** 2)
                                                     | (round_px < params.arc_fit_roundness)
                                                     | (edge_r < params.arc_fit_all_below_px))
        # a view well below the ball's size is left out anyway while two full views remain (_choose)
        ratio = radius / r_k
        full = simple & params.full_view(ratio)
        part &= ~((ratio < params.partial_ratio) & (np.bincount(mi[full], minlength=valid.shape[0])[mi] >= 2))
        arcs = _ArcRegions()
        if part.any():
            win = np.repeat(np.arange(k_count), count)
            sel = part[win]
            ws = win[sel]
            arcs.add_many((np.cumsum(part) - 1)[ws], col[sel] + fx[ws], row[sel] + fy[ws], mxy[part],
                          uv.reshape(-1, 2)[at[part]] - centre[part], edge_r[part], first.T[part],
                          (hi - 1 - centre)[part], centre[part], mi[part], ci[part], sigma_px.reshape(-1)[at[part]])
        crowded = np.flatnonzero(ok & ~simple)
        # several regions in the window: separate them, in a window of the size that the markers
        # measured last frame share in this camera (the largest of theirs), or of the marker's own
        recent = known & (self.frames_unmeasured == 0)
        for k in crowded.tolist():
            m, c = int(mi[k]), int(ci[k])
            hw = int(np.ceil(half[recent & valid[:, c], c].max() if recent[m] else half[m, c]))
            img, gate = images[c], self.gates[c]
            (cx, cy), (w_img, h_img) = centre[k].tolist(), size_k[k].tolist()
            x0k, y0k = max(0, cx - hw), max(0, cy - hw)
            x1k, y1k = min(w_img, cx + hw + 1), min(h_img, cy + hw + 1)
            if compiled:  # the same regions, gates and choice in one compiled pass
                found, uv_j, area, round_j, xs, ys = window_kernel.crowded_window(
                    img, self.table.lut, self.table.bits, (x0k, y0k, x1k, y1k), int(self._label[m]), uv[m, c], gate)
                if found:
                    radius_j = math.sqrt(area / math.pi)
                    uv_out[m, c] = uv_j
                    rad_out[m, c] = radius_j
                    if radius_j <= edge_r[k] and (radius_j < params.arc_fit_ratio * edge_r[k]
                                                  or round_j < params.arc_fit_roundness):
                        arcs.add_pixels(xs, ys, np.array(uv_j), uv[m, c], (x0k, y0k), (x1k - x0k, y1k - y0k), edge_r[k],
                                        m, c, float(sigma_px[m, c]))
                continue
            win_labels = self.table.classify_window(img, x0k, y0k, x1k, y1k)
            blobs = find_blobs(win_labels, self.table.n_colours, min_area_px=gate.min_area_px,
                               max_area_px=gate.max_area_px, min_roundness=gate.min_roundness,
                               offset_px=(x0k, y0k), colours=(int(self.colour[m]),))
            if len(blobs):
                j = np.argmin(np.linalg.norm(blobs.uv_px - uv[m, c], axis=1))
                uv_out[m, c] = blobs.uv_px[j]
                rad_out[m, c] = blobs.radius_px[j]
                if blobs.radius_px[j] <= edge_r[k] and (blobs.radius_px[j] < params.arc_fit_ratio * edge_r[k]
                                                        or blobs.roundness[j] < params.arc_fit_roundness):
                    # e.g. half a ball (roundness ~0.5), or a ball beside another of its colour
                    arcs.add_region(win_labels == self._label[m], blobs.uv_px[j], uv[m, c], (x0k, y0k), edge_r[k], m, c,
                                    float(sigma_px[m, c]))
        if arcs.count:
            m_idx, c_idx, uv_fit = arcs.fit(self.compiled, images if params.arc_subpixel else None)
            uv_out[m_idx, c_idx] = uv_fit

    def _choose(self, obs, pred, sigma, known):
        """Triangulate every marker from its window centroids; keep geometrically consistent ones."""
        uv, rad = obs
        params = self.params
        stack = self._stack
        m_count, n_cams = uv.shape[:2]
        xn = stack.undistort_points(uv)
        xn_seen = xn
        if self._skew_s is not None:
            xn = self._to_set_instant(xn, uv)
        seen = np.isfinite(xn[..., 0]) & known[:, None]
        ball_px = stack.focal_px * self.markerset.radius_m  # ball radius in pixels at 1 m
        # a partly hidden ball (blob much smaller than the ball at the predicted depth) has a
        # shifted centroid, and a blob larger than the ball holds more than the ball (another ball
        # of the colour touching it): leave them out while two full views remain
        # (no errstate in this method: NaN where a marker or view is missing compares False
        # without a warning, and a depth of exactly 0 does not occur)
        ratio_pred = rad / (ball_px / self._pred_depth)
        partial = seen & ~params.full_view(ratio_pred) & ~np.isnan(ratio_pred)
        keep_full = (seen & ~partial).sum(axis=1) >= 2
        left_out = partial & keep_full[:, None]
        seen &= ~left_out
        triangulate = self._triangulate
        pts = triangulate(xn, seen)
        err, depth = self._reprojection(pts, xn)
        # a partly hidden view is shifted by less than the ball's radius: one that the point
        # misses by more says that a full view holds another ball of the colour (two views always
        # meet near some point): triangulate from all views and let the worst go below
        r_px = ball_px / self._pred_depth
        recheck = (left_out & (err > np.maximum(r_px, params.max_reproj_px))).any(axis=1)
        if recheck.any():
            redo = np.flatnonzero(recheck)
            seen[redo] |= left_out[redo]
            pts[redo] = triangulate(xn[redo], seen[redo])
            err[redo], depth[redo] = self._reprojection(pts[redo], xn[redo])
        rows = np.arange(m_count)
        changed = np.ones(m_count, dtype=bool)  # views changed since the leave-one-out check
        for _ in range(n_cams):  # drop the worst view while it misses and three or more remain
            worst = np.argmax(np.where(seen, err, -1.0), axis=1)
            many = seen.sum(axis=1) >= 3
            drop = (err[rows, worst] > params.max_reproj_px) & many
            # a wrong ball in one of three views pulls the point towards itself and hides its own
            # miss; the point from the other views shows it (leave-one-out)
            probe = np.flatnonzero(many & ~drop & changed)
            if probe.size:
                others = seen[probe].copy()
                others[np.arange(probe.size), worst[probe]] = False
                p_loo = triangulate(xn[probe], others)
                e_loo, _ = self._reprojection(p_loo, xn[probe])
                drop[probe] = e_loo[np.arange(probe.size), worst[probe]] > params.max_loo_px
            if not drop.any():
                break
            redo = np.flatnonzero(drop)
            changed = drop
            for m in redo.tolist():
                worst[m] = self._view_to_drop(m, seen[m], xn[m], pred[m], int(worst[m]))
            seen[redo, worst[drop]] = False
            pts[redo] = triangulate(xn[redo], seen[redo])  # the other points do not change
            err[redo], depth[redo] = self._reprojection(pts[redo], xn[redo])
        n_seen = seen.sum(axis=1)
        rms = np.sqrt(np.where(seen, err, 0.0) ** 2 @ self._ones_cams / np.maximum(n_seen, 1))
        # two views always meet in some point: a two-camera candidate must fit tightly and show a
        # ball of the right size in both views (as in tracking.reconstruction)
        ratio_now = rad / (ball_px / depth)
        size_fit = ~(seen & ~((ratio_now > 0.65) & (ratio_now <= params.oversize_ratio))).any(axis=1)
        measured = (n_seen >= 2) & (rms <= params.max_reproj_px)
        measured &= (n_seen >= 3) | ((rms <= params.max_reproj_px_two_view) & size_fit)
        off = pts - pred
        off_m = np.sqrt((off * off) @ _ONES3)  # distance to the prediction
        measured &= off_m <= params.gate_sigmas * sigma + 0.01
        new_pos = np.where(measured[:, None], pts, np.nan)
        # one ball, one marker: a marker measured last frame keeps its ball, then the larger Q
        diff = new_pos[:, None, :] - new_pos[None, :, :]
        dist = np.sqrt((diff * diff) @ _ONES3)  # (M, M), NaN unless both measured
        clash = dist < params.same_ball_m
        np.fill_diagonal(clash, False)
        if clash.any():
            # Q (equation 4) of the chosen candidate
            duv = uv - self._pred_uv
            q_cam = 1.0 / (1.0 + np.sqrt((duv * duv) @ _ONES2))
            q_best = np.where(measured, np.prod(np.where(seen, q_cam, 1.0), axis=1), 0.0)
            was_measured = self.status == _MEASURED
            for a in np.lexsort((-q_best, ~was_measured)):
                if measured[a]:
                    measured &= ~clash[a]
        surprise = off_m / sigma  # distance to the prediction in sigmas
        measured &= self._segments_consistent(dist, new_pos, measured, np.nan_to_num(surprise))
        new_pos[~measured] = np.nan
        if self._skew_s is not None:
            # the views as seen, with their instants: their image motion since the last frame set is
            # the markers' velocity over the last period (not the prediction's, a period older: it
            # lagged a fast swing's acceleration), which brings the views to the set's instant once more
            use = seen & measured[:, None]
            at = self._set_time_s + self._skew_s + self._row_s * uv[..., 1]
            self._seen_views = np.concatenate([np.where(use[..., None], xn_seen, np.nan), at[..., None]], axis=2)
            # over the last period and the last two: twice the one minus the other is the velocity at
            # the views' instants for a steady acceleration (the last period's alone lagged by half
            # a period: a swing's acceleration times 16 ms, ~0.1 m/s)
            last = self._image_velocity(self._seen_views, self._seen_pos[..., :3])
            two = self._image_velocity(self._seen_views, self._seen_pos[..., 3:])
            self._seen_now = np.where(np.isfinite(two), 2.0 * last - two, last) / self.fps
            if measured.any():
                velocity = np.where(np.isfinite(self._seen_now), self._seen_now, self._seen_velocity)
                moving = self._stack.rotate_to_cameras(velocity * self.fps)
                redo = np.flatnonzero(measured)
                xn_redo = self._to_set_instant(xn_seen[redo], uv[redo], moving[redo], self._pred_cam[redo])
                new_pos[redo] = triangulate(xn_redo, use[redo])
                xn[redo] = xn_redo
        self._used_uv = np.where((seen & measured[:, None])[..., None], uv, np.nan)
        full = seen & ~measured[:, None] & params.full_view(ratio_pred)
        self._offer_views(xn, full)
        return new_pos, measured

    def _offer_views(self, xn: np.ndarray, views: np.ndarray) -> None:
        """Pass the full-sized views of unmeasured markers to the hidden-marker estimator as rays
        (camera centre, unit direction, angular uncertainty), for this frame's update.

        Args:
            xn: (M, C, 2) normalized observations; views: (M, C) bool, the views to pass.
        """
        if not views.any():  # the estimator forgets the views of the last frame by itself
            return
        m_idx, c_idx = np.nonzero(views)
        rot = self.geometry.extrinsics[c_idx, :, :3]  # world -> camera
        ray = np.concatenate([xn[m_idx, c_idx], np.ones((m_idx.size, 1))], axis=1)
        d = np.einsum("kji,kj->ki", rot, ray)  # R^T [x, y, 1]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        self.estimator.observe_views(m_idx, self._cam_centres[c_idx], d,
                                     self.params.view_sigma_px / self._stack.focal_px[c_idx])

    def _view_to_drop(self, m: int, seen: np.ndarray, xn: np.ndarray, pred: np.ndarray, worst: int) -> int:
        """Which of marker m's (3 or more) views to drop: the worst, unless another view's removal
        leaves a point that fits the other views (RMS within ``max_reproj_px``) more than
        ``view_choice_margin_m`` nearer the prediction: then the one that leaves it nearest. Two
        partly hidden views, one of them another ball, can each fit a full view within a pixel;
        the prediction tells them apart.

        Args:
            seen: (C,) the views used; xn: (C, 2) normalized observations; pred: (3,) prediction.
        """
        views = np.flatnonzero(seen)
        keep = np.repeat(seen[None, :], views.size, axis=0)
        keep[np.arange(views.size), views] = False
        obs = np.repeat(xn[None], views.size, axis=0)
        pts = self._triangulate(obs, keep)
        err, _ = self._reprojection(pts, obs)
        rms = np.sqrt((np.where(keep, err, 0.0) ** 2).sum(axis=1) / keep.sum(axis=1))
        fits = rms <= self.params.max_reproj_px
        if not fits.any():
            return worst
        dist = np.linalg.norm(pts - pred, axis=1)
        near = np.where(fits, dist, np.inf)
        i_worst = int(np.flatnonzero(views == worst)[0])
        # the worst view goes unless that leaves the point clearly farther from the prediction
        if not fits[i_worst] or dist[i_worst] > near.min() + self.params.view_choice_margin_m:
            return int(views[np.argmin(near)])
        return worst

    def _reprojection(self, pts: np.ndarray, xn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) points, (N, C, 2) normalized observations -> (N, C) errors in pixels, (N, C) depths."""
        cam = self._stack.world_to_cameras(pts)
        depth = cam[..., 2]
        d = cam[..., :2] / depth[..., None] - xn  # (NaN for NaN points; no depth is exactly 0)
        return np.sqrt((d * d).sum(axis=2)) * self._stack.focal_px, depth

    def _segments_consistent(self, dist: np.ndarray, pos: np.ndarray, measured: np.ndarray,
                             surprise: np.ndarray) -> np.ndarray:
        """False for a marker whose distance to a segment neighbour broke its learned length.

        Neighbours measured this frame count; so do neighbours known only from last frame's
        estimate, against a newly found marker (with twice the tolerance), so that a marker
        coming back from hiding cannot take a ball that is not where its segment says.

        Args:
            dist: (M, M) distances between the markers' candidate positions ``pos`` (NaN where
                either has none).
            pos: (M, 3) candidate positions; measured: (M,) bool.
            surprise: (M,) each candidate's distance to its prediction in prediction sigmas.
        """
        tol = self.params.segment_tol_m
        broken = np.abs(dist - self.seg_length) > tol  # (False for NaN, without a warning)
        bad_pair = self._same_segment & measured[:, None] & measured[None, :] & broken
        returning = measured & (self.status != _MEASURED)
        if returning.any():
            known_prev = np.isfinite(self.positions).all(axis=1) & ~measured
            if known_prev.any():
                diff = pos[:, None, :] - self.positions[None, :, :]
                d_prev = np.sqrt((diff * diff) @ _ONES3)
                chk = self._same_segment & returning[:, None] & known_prev[None, :]
                bad_prev = (chk & (np.abs(d_prev - self.seg_length) > 2 * tol)).any(axis=1)
                measured = measured & ~bad_prev
        ok = measured.copy()
        # drop the marker involved in most broken pairs, one at a time; of markers in as many, a
        # returning one (not measured last frame) first: the one measured last frame still sits
        # on its ball far more often than a marker found again after hiding; then the candidate
        # farther from its prediction (a wrong ball in one view moves the point away from it)
        returning_now = self.status != _MEASURED
        while bad_pair.any():
            count = bad_pair.sum(axis=1)
            worst = max(np.flatnonzero(count == count.max()).tolist(),
                        key=lambda i: (bool(returning_now[i]), float(surprise[i])))
            ok[worst] = False
            bad_pair[worst, :] = bad_pair[:, worst] = False
        return ok

    def _learn_lengths(self, measured: np.ndarray) -> None:
        pos = self.positions
        diff = pos[:, None, :] - pos[None, :, :]
        d = np.sqrt((diff * diff) @ _ONES3)
        pair = self._same_segment & measured[:, None] & measured[None, :]
        old = self.seg_length  # NaN until first learned
        self.seg_length = np.where(pair, np.where(np.isnan(old), d, 0.95 * old + 0.05 * d), old)

    def _reacquire(self, points: Points3D, new_pos: np.ndarray, measured: np.ndarray, search: np.ndarray) -> np.ndarray:
        """Give the markers of ``search`` (lost, or estimated for long) the unexplained full-frame
        points of their colour that fit them.

        A point fits when its distances to the measured markers of the segment (and the near-rigid
        pairs) are the learned ones; with no such neighbour, when it satisfies the marker set's
        distance rules to the measured markers (``Identifier.distance_fit_m``) and is the only
        free point of the colour that does; a lost marker with neither also takes the nearest
        point within ``reacquire_radius_m`` of where it was last seen (still within the rules).
        An estimated marker is only taken on the learned lengths or a unique rule fit (its
        windows already searched near its estimate).

        Returns:
            (M,) int, the point each marker found took, -1 for the others (``new_pos`` and
            ``measured`` are updated in place).
        """
        took = np.full(len(measured), -1)
        if len(points) == 0:
            return took
        p_m = points.p_world_m
        taken = np.zeros(len(points), dtype=bool)
        for m in np.flatnonzero(measured):
            taken |= np.linalg.norm(p_m - new_pos[m], axis=1) < 0.02
        last = self._last_seen
        tol = self.params.segment_tol_m
        for m in np.flatnonzero(search & ~measured):
            cands = np.flatnonzero(~taken & (points.colour == self.colour[m]))
            if cands.size == 0:
                continue
            best = -1
            nb = np.flatnonzero(self._same_segment[m] & measured & np.isfinite(self.seg_length[m]))
            if nb.size:  # a measured neighbour on the segment: the learned lengths decide
                dev = np.abs(np.linalg.norm(new_pos[nb][None] - p_m[cands][:, None], axis=-1)
                             - self.seg_length[m, nb][None]).max(axis=1)
                if dev.min() < tol:
                    best = int(cands[np.argmin(dev)])
            else:
                fit = self.identifier.distance_fit_m(m, p_m[cands], new_pos, measured)
                ruled = np.isfinite(fit)  # a rule links the marker to a measured one
                within = ~ruled | (fit >= 0.0)
                if self.status[m] == MarkerStatus.LOST and np.isfinite(last[m]).all():
                    dev = np.where(within, np.linalg.norm(p_m[cands] - last[m], axis=1), np.inf)
                    if dev.min() < self.params.reacquire_radius_m:
                        best = int(cands[np.argmin(dev)])
                fits = cands[ruled & within]
                if best < 0 and len(fits) == 1:
                    best = int(fits[0])
            if best >= 0:
                new_pos[m], measured[m], taken[best], took[m] = p_m[best], True, True, best
        return took


def centroids_used(points: Points3D, views: Sequence[CameraObservations], index: np.ndarray) -> np.ndarray:
    """(M, C, 2) the centroids full-frame point ``index[m]`` was triangulated from in each camera
    (``Points3D.obs_index``); NaN where the point used no centroid of that camera or ``index[m]``
    is -1."""
    idx = np.asarray(index, dtype=np.int64)
    out = np.full((len(idx), len(views), 2), np.nan)
    for m in np.flatnonzero(idx >= 0).tolist():
        for c, j in enumerate(points.obs_index[idx[m]].tolist()):
            if j >= 0:
                out[m, c] = views[c].uv_px[j]
    return out

