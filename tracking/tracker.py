"""The per-frame tracker: one object, ``step(images) -> TrackerSample``, for every driver.

METHOD.md sections 5.2-5.4, online (no look-ahead):

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
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from calibration.camera import Camera
from calibration.errors import RehabError
from tracking.angles import joint_angles
from tracking.blobs import find_blobs
from tracking.colour_table import ColourTable
from tracking.markerset import MarkerSet
from tracking.measure import FrameMeasurer, StageTimes, blob_gates
from tracking.reconstruction import Points3D, RigGeometry
from tracking.status import MarkerStatus
from tracking.triangulation import reprojection_errors_px, triangulate

log = logging.getLogger(__name__)


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
        angles_deg: joint angles (spec/JOINT_ANGLES.md), NaN where undefined.
        message: a one-line explanation while WAITING (e.g. which reference-pose rule fails).
        n_points: unlabelled points measured in full-frame mode this frame (0 in window mode).
    """

    frame_index: int
    time_s: float
    state: TrackingState
    positions_m: np.ndarray
    status: np.ndarray
    angles_deg: dict[str, float]
    message: str = ""
    n_points: int = 0


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
        reidentify_after: identify again when more than half the markers are lost this many frames.
        max_reproj_px: largest RMS reprojection error of a candidate.
        max_reproj_px_two_view: the same for a candidate seen by two cameras only (which must also
            show a ball of the right size in both).
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
    reidentify_after: int = 30
    max_reproj_px: float = 2.5
    max_reproj_px_two_view: float = 1.2


#: Stages of :meth:`Tracker.step` reported by ``rehab bench``.
STEP_STAGES = (
    "windows (colour table + centroids)",
    "candidates + triangulation",
    "hidden markers",
    "full-frame re-acquisition",
    "joint angles",
)


def _depth_rows(geo: RigGeometry, p: np.ndarray) -> np.ndarray:
    """(M, 3) points -> (M, C) depth in each camera (NaN rows stay NaN)."""
    return np.einsum("cj,mj->mc", geo.extrinsics[:, 2, :3], p) + geo.extrinsics[None, :, 2, 3]


class Tracker:
    """Labels and tracks the markers of one marker set seen by calibrated cameras.

    Args:
        cameras: calibrated cameras, in the order of the images passed to :meth:`step`.
        markerset: the markers worn by the patient (names, colours, segments, rules).
        table: the colour lookup table (default: built from the marker set's colours).
        params: tracking knobs.
        fps: frame rate of the source (for time stamps when none are given).
    """

    def __init__(self, cameras: Sequence[Camera], markerset: MarkerSet, *, table: ColourTable | None = None,
                 params: TrackerParams = TrackerParams(), fps: float = 30.0):
        from tracking.hidden import Estimator, estimator_config
        from tracking.identify import Identifier

        self.cameras = tuple(cameras)
        self.markerset = markerset
        self.params = params
        self.fps = float(fps)
        self.table = table or ColourTable.build(markerset.palette)
        self.measurer = FrameMeasurer(self.cameras, self.table, markerset.radius_m)
        self.geometry: RigGeometry = self.measurer.geometry
        self.gates = [blob_gates(c, markerset.radius_m) for c in self.cameras]
        self.colour = markerset.colour_index
        self._estimator_factory = lambda: Estimator(**estimator_config(markerset), fps=self.fps)
        self.identifier = Identifier(markerset)
        self.times = StageTimes(STEP_STAGES)
        m = markerset.n_markers
        # pairs of markers whose distance is (nearly) constant: markers of one segment, and the
        # near-rigid pairs across a joint that the marker set names (hidden_markers.limits)
        seg = np.array(markerset.segments)
        self._same_segment = (seg[:, None] == seg[None, :]) & ~np.eye(m, dtype=bool)
        for i, j in estimator_config(markerset)["length_pairs"]:
            self._same_segment[i, j] = self._same_segment[j, i] = True
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget everything; the next frames identify the markers again."""
        m = self.markerset.n_markers
        self.state = TrackingState.WAITING
        self.positions = np.full((m, 3), np.nan)
        self.velocity = np.zeros((m, 3))
        self.status = np.full(m, MarkerStatus.LOST, dtype=np.uint8)
        self.frames_unmeasured = np.zeros(m, dtype=np.int64)
        self.seg_length = np.full((m, m), np.nan)  # learned distances on segments
        self._last_seen = np.full((m, 3), np.nan)  # last measured position of each marker
        self.estimator = self._estimator_factory()
        self.frame_count = 0
        self._lost_streak = 0

    def reidentify(self) -> None:
        """Identify the markers again from the next frame (the patient takes the reference pose)."""
        self.reset()

    # ------------------------------------------------------------------ the step
    def step(self, images: Sequence[np.ndarray], time_s: float | None = None) -> TrackerSample:
        """Process one synchronized frame set (one BGR image per camera, calibration order)."""
        if len(images) != len(self.cameras):
            raise RehabError(f"the tracker has {len(self.cameras)} cameras but got {len(images)} images")
        index = self.frame_count
        self.frame_count += 1
        t = index / self.fps if time_s is None else float(time_s)
        message = ""
        n_points = 0
        if self.state == TrackingState.WAITING:
            t0 = time.perf_counter()
            points = self.measurer.measure(images)
            n_points = len(points)
            message = self._try_identify(points)
            self.times.add("full-frame re-acquisition", time.perf_counter() - t0)
        else:
            n_points = self._track(images)
        t0 = time.perf_counter()
        angles = joint_angles(self.positions, self.markerset.names) if self.state == TrackingState.TRACKING else {}
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
        )

    # ------------------------------------------------------------------ identification
    def _try_identify(self, points: Points3D) -> str:
        from tracking.identify import IdentificationError, try_identify

        try:
            ident = try_identify(points, self.identifier)
        except IdentificationError as exc:
            return str(exc)
        if ident is None:
            return self.identifier.count_problem(np.asarray(points.colour)) or "waiting for the reference pose"
        idx = np.asarray(ident.index)
        ok = idx >= 0
        self.positions[:] = np.nan
        self.positions[ok] = points.p_world_m[idx[ok]]
        self.status[:] = np.where(ok, MarkerStatus.MEASURED, MarkerStatus.LOST)
        self.velocity[:] = 0.0
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
        lost_now = ~measured & (self.status == MarkerStatus.LOST)
        if lost_now.any() and self.frame_count % self.params.reacquire_every == 0:
            t3 = time.perf_counter()
            points = self.measurer.measure(images)
            n_points = len(points)
            self._reacquire(points, new_pos, measured)
            self.times.add("full-frame re-acquisition", time.perf_counter() - t3)

        t4 = time.perf_counter()
        est_pos, status = self.estimator.update(np.where(measured[:, None], new_pos, np.nan), measured)
        self.times.add("hidden markers", time.perf_counter() - t4)

        prev = self.positions
        self.positions = est_pos
        self.status = np.asarray(status, dtype=np.uint8)
        has = np.isfinite(est_pos).all(axis=1) & np.isfinite(prev).all(axis=1)
        self.velocity = np.where(has[:, None], est_pos - prev, 0.0)
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
        from the mask's moments, computed for all of a camera's windows at once (one gather of the
        windows' pixels, one table look-up, array reductions). A window whose mask is too large or
        not round holds several balls (or clutter): then its regions are separated and the one
        nearest to the prediction is taken.

        Returns:
            uv (M, C, 2) float64 centroids (NaN where none), radius (M, C) equivalent radius in px.
        """
        m_count = self.markerset.n_markers
        n_cams = len(self.cameras)
        uv_out = np.full((m_count, n_cams, 2), np.nan)
        rad_out = np.full((m_count, n_cams), np.nan)
        self._pred_uv = np.full((m_count, n_cams, 2), np.nan)  # predictions in each image (for Q)
        # markers measured last frame share small windows (vectorized); the others (coming back
        # from hiding: larger uncertainty) get windows of their own size
        recent = known & (self.frames_unmeasured == 0)
        groups = [np.flatnonzero(recent)] + [np.array([m]) for m in np.flatnonzero(known & ~recent)]
        for group in groups:
            if group.size:
                self._windows(images, pred, sigma, group, uv_out, rad_out)
        return uv_out, rad_out

    def _windows(self, images, pred, sigma, idx, uv_out, rad_out) -> None:
        """Fill uv_out/rad_out for markers ``idx``, whose windows share one size per camera."""
        p = self.params
        lut = self.table.lut
        target = (self.colour[idx] + 1).astype(np.uint8)
        for c, (cam, img) in enumerate(zip(self.cameras, images)):
            uv = cam.project(pred[idx])
            self._pred_uv[idx, c] = uv
            depth = cam.world_to_camera(pred[idx])[:, 2]
            f = (cam.K[0, 0] + cam.K[1, 1]) / 2.0
            safe_depth = np.maximum(depth, 1e-3)
            r_px = f * self.markerset.radius_m / safe_depth
            half = np.minimum(r_px * 1.2 + 2.0 + p.window_sigmas * f * sigma[idx] / safe_depth, p.max_window_px)
            h_img, w_img = img.shape[:2]
            valid = np.isfinite(uv).all(axis=1) & (depth > 0)
            valid &= (uv[:, 0] > -half) & (uv[:, 0] < w_img + half) & (uv[:, 1] > -half) & (uv[:, 1] < h_img + half)
            if not valid.any():
                continue
            # one window size for the camera: the largest needed (hidden markers' larger windows
            # are rare and short-lived)
            hw = int(np.ceil(half[valid].max()))
            size = 2 * hw + 1
            cx = np.round(np.where(valid, uv[:, 0], 0)).astype(np.int64)
            cy = np.round(np.where(valid, uv[:, 1], 0)).astype(np.int64)
            offs = np.arange(-hw, hw + 1)
            xs = cx[:, None] + offs[None, :]  # (K, S)
            ys = cy[:, None] + offs[None, :]
            # each marker keeps to its own window inside the shared size (a fast marker's large
            # window must not make the others swallow their same-coloured neighbours)
            own = np.abs(offs)[None, :] <= half[:, None]  # (K, S)
            inside = (((xs >= 0) & (xs < w_img)) & own)[:, None, :] & (((ys >= 0) & (ys < h_img)) & own)[:, :, None]
            flat = ys.clip(0, h_img - 1)[:, :, None] * w_img + xs.clip(0, w_img - 1)[:, None, :]
            img_c = np.ascontiguousarray(img)
            words = np.ndarray((h_img * w_img - 1,), dtype="<u4", buffer=img_c, strides=(3,))
            pix = np.take(words, flat, mode="clip")  # the image's last pixel reads its neighbour
            np.bitwise_and(pix, 0xFFFFFF, out=pix)
            labels = np.take(lut, pix)
            mask = (labels == target[:, None, None]) & inside & valid[:, None, None]
            col = mask.sum(axis=1, dtype=np.float64)  # (K, S) counts per column
            row = mask.sum(axis=2, dtype=np.float64)  # (K, S) counts per row
            m00 = col.sum(axis=1)
            ok = m00 >= self.gates[c].min_area_px
            with np.errstate(divide="ignore", invalid="ignore"):
                mx = (col * offs).sum(axis=1) / m00
                my = (row * offs).sum(axis=1) / m00
                mu20 = (col * offs**2).sum(axis=1) / m00 - mx**2
                mu02 = (row * offs**2).sum(axis=1) / m00 - my**2
                mu11 = np.einsum("kij,i,j->k", mask, offs.astype(np.float64), offs.astype(np.float64)) / m00 - mx * my
                spread = np.sqrt(((mu20 - mu02) / 2.0) ** 2 + mu11**2)
                lam1 = (mu20 + mu02) / 2.0 + spread
                lam2 = (mu20 + mu02) / 2.0 - spread
                roundness = np.sqrt(np.clip(lam2, 0, None) / lam1)
            # a sliver (under 40 % of the ball's area) is a ball mostly hidden in this camera: no view
            ok &= m00 >= 0.4 * np.pi * r_px**2
            simple = ok & (m00 <= 1.6 * np.pi * r_px**2) & (roundness >= 0.6)
            uv_out[idx[simple], c, 0] = cx[simple] + mx[simple]
            uv_out[idx[simple], c, 1] = cy[simple] + my[simple]
            rad_out[idx[simple], c] = np.sqrt(m00[simple] / np.pi)
            gate = self.gates[c]
            for k in np.flatnonzero(ok & ~simple):  # several regions in the window: separate them
                m = idx[k]
                x0, y0 = max(0, cx[k] - hw), max(0, cy[k] - hw)
                x1, y1 = min(w_img, cx[k] + hw + 1), min(h_img, cy[k] + hw + 1)
                win_labels = self.table.classify_window(img, x0, y0, x1, y1)
                blobs = find_blobs(win_labels, self.table.n_colours, min_area_px=gate.min_area_px,
                                   max_area_px=gate.max_area_px, min_roundness=gate.min_roundness,
                                   offset_px=(x0, y0))
                sel = np.flatnonzero(blobs.colour == self.colour[m])
                if sel.size:
                    j = sel[np.argmin(np.linalg.norm(blobs.uv_px[sel] - uv[k], axis=1))]
                    uv_out[m, c] = blobs.uv_px[j]
                    rad_out[m, c] = blobs.radius_px[j]

    def _choose(self, obs, pred, sigma, known):
        """Triangulate every marker from its window centroids; keep geometrically consistent ones."""
        uv, rad = obs
        geo = self.geometry
        m_count, n_cams = uv.shape[:2]
        xn = np.full_like(uv, np.nan)
        for c, cam in enumerate(self.cameras):
            ok = np.isfinite(uv[:, c, 0])
            if ok.any():
                xn[ok, c] = cam.undistort_points(uv[ok, c])
        seen = np.isfinite(xn[..., 0]) & known[:, None]
        # a partly hidden ball (blob much smaller than the ball at the predicted depth) has a
        # shifted centroid: leave it out while two full views remain
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = rad / (geo.focal_px[None, :] * self.markerset.radius_m / _depth_rows(geo, np.nan_to_num(pred)))
        partial = seen & (ratio < 0.8)
        keep_full = (seen & ~partial).sum(axis=1) >= 2
        seen &= ~(partial & keep_full[:, None])
        pts = np.full((m_count, 3), np.nan)
        for _ in range(n_cams):
            pts = triangulate(geo.extrinsics, xn, seen)
            err = reprojection_errors_px(geo.extrinsics, geo.focal_px, pts, xn, seen)
            worst = np.argmax(np.where(seen, err, -1.0), axis=1)
            worst_err = err[np.arange(m_count), worst]
            drop = (worst_err > self.params.max_reproj_px) & (seen.sum(axis=1) >= 3)
            if not drop.any():
                break
            seen[np.flatnonzero(drop), worst[drop]] = False
        n_seen = seen.sum(axis=1)
        sq = np.where(seen, err, 0.0) ** 2
        rms = np.sqrt(sq.sum(axis=1) / np.maximum(n_seen, 1))
        # two views always meet in some point: a two-camera candidate must fit tightly and show a
        # ball of the right size in both views (as in tracking.reconstruction)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio_now = rad / (geo.focal_px[None, :] * self.markerset.radius_m / _depth_rows(geo, pts))
        size_fit = np.all(~seen | ((ratio_now > 0.65) & (ratio_now < 1.35)), axis=1)
        two_ok = (rms <= self.params.max_reproj_px_two_view) & size_fit
        with np.errstate(invalid="ignore"):
            measured = (n_seen >= 2) & (rms <= self.params.max_reproj_px) & ((n_seen >= 3) | two_ok)
            measured &= np.linalg.norm(pts - pred, axis=1) <= self.params.gate_sigmas * sigma + 0.01
        # Q of the chosen candidate, for the one-ball-one-marker rule
        q_cam = 1.0 / (1.0 + np.linalg.norm(uv - self._pred_uv, axis=-1))
        q_best = np.where(measured, np.prod(np.where(seen, q_cam, 1.0), axis=1), 0.0)
        new_pos = np.where(measured[:, None], pts, np.nan)
        # one ball, one marker: a marker measured last frame keeps its ball, then the larger Q
        was_measured = self.status == MarkerStatus.MEASURED
        d = np.linalg.norm(new_pos[:, None, :] - new_pos[None, :, :], axis=-1)
        clash = measured[:, None] & measured[None, :] & (d < self.params.same_ball_m)
        np.fill_diagonal(clash, False)
        if clash.any():
            rank = np.lexsort((-q_best, ~was_measured))
            for a in rank:
                if measured[a]:
                    measured &= ~clash[a]
        measured &= self._segments_consistent(new_pos, measured)
        new_pos[~measured] = np.nan
        return new_pos, measured

    def _segments_consistent(self, pos: np.ndarray, measured: np.ndarray) -> np.ndarray:
        """False for a marker whose distance to a segment neighbour broke its learned length.

        Neighbours measured this frame count; so do neighbours known only from last frame's
        estimate, against a newly found marker (with twice the tolerance), so that a marker
        coming back from hiding cannot take a ball that is not where its segment says.
        """
        tol = self.params.segment_tol_m
        d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=-1)
        dev = np.abs(d - self.seg_length)
        check = self._same_segment & measured[:, None] & measured[None, :] & np.isfinite(self.seg_length)
        bad_pair = check & (dev > tol)
        returning = measured & (self.status != MarkerStatus.MEASURED)
        known_prev = np.isfinite(self.positions).all(axis=1) & ~measured
        if returning.any() and known_prev.any():
            d_prev = np.linalg.norm(pos[:, None, :] - self.positions[None, :, :], axis=-1)
            chk = self._same_segment & returning[:, None] & known_prev[None, :] & np.isfinite(self.seg_length)
            bad_prev = (chk & (np.abs(d_prev - self.seg_length) > 2 * tol)).any(axis=1)
            measured = measured & ~bad_prev
        ok = measured.copy()
        # drop the marker involved in most broken pairs, one at a time
        while bad_pair.any():
            worst = int(np.argmax(bad_pair.sum(axis=1)))
            ok[worst] = False
            bad_pair[worst, :] = bad_pair[:, worst] = False
        return ok

    def _learn_lengths(self, measured: np.ndarray) -> None:
        pos = self.positions
        d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=-1)
        pair = self._same_segment & measured[:, None] & measured[None, :]
        first = pair & ~np.isfinite(self.seg_length)
        self.seg_length[first] = d[first]
        upd = pair & ~first
        self.seg_length[upd] = 0.95 * self.seg_length[upd] + 0.05 * d[upd]

    def _reacquire(self, points: Points3D, new_pos: np.ndarray, measured: np.ndarray) -> None:
        """Give lost markers the unexplained full-frame points that fit their segment lengths."""
        if len(points) == 0:
            return
        taken = np.zeros(len(points), dtype=bool)
        for m in np.flatnonzero(measured):
            d = np.linalg.norm(points.p_world_m - new_pos[m], axis=1)
            taken |= d < 0.02
        last = self._last_seen
        for m in np.flatnonzero(~measured & (self.status == MarkerStatus.LOST)):
            cands = np.flatnonzero(~taken & (points.colour == self.colour[m]))
            nb = np.flatnonzero(self._same_segment[m] & measured & np.isfinite(self.seg_length[m]))
            best, best_dev = -1, np.inf
            for i in cands:
                if nb.size:  # a measured neighbour on the segment: the learned lengths decide
                    dev = np.abs(np.linalg.norm(new_pos[nb] - points.p_world_m[i], axis=1) - self.seg_length[m, nb]).max()
                    if dev < self.params.segment_tol_m and dev < best_dev:
                        best, best_dev = i, dev
                elif np.isfinite(last[m]).all():  # otherwise: near where it was last seen
                    dev = float(np.linalg.norm(points.p_world_m[i] - last[m]))
                    if dev < self.params.reacquire_radius_m and dev < best_dev:
                        best, best_dev = i, dev
            if best >= 0:
                new_pos[m] = points.p_world_m[best]
                measured[m] = True
                taken[best] = True
