"""Measurement accuracy on the simulated patient, motion by motion (``rehab validate``).

Each motion is rendered in memory (no video encoding) and measured by the same
:class:`tracking.full_frame.FrameMeasurer` that ``rehab track`` uses; the points are compared with
the simulator's truth by :func:`tracking.drivers.evaluate.evaluate_points`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import numpy as np
from tqdm import tqdm

from tracking.angles import joint_angles
from tracking.colour.table import ColourTable
from tracking.drivers.evaluate import PointAccuracy, evaluate_points
from tracking.full_frame import FrameMeasurer
from tracking.io.recording import Recording
from tracking.io.trc import read_trc
from tracking.marker_status import MarkerStatus
from tracking.markerset import load_markerset
from tracking.sim.motions import available_motions
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.tracker import Tracker, TrackingState


def validate_motion(settings: SimulationSettings, *, progress: bool = False) -> PointAccuracy:
    """Render one motion and measure it; accuracy against the truth ("seen" at 75 %)."""
    return validate_motion_both(settings, progress=progress)[0]


def validate_motion_both(settings: SimulationSettings, *, progress: bool = False) -> tuple[PointAccuracy, PointAccuracy]:
    """Like :func:`validate_motion`, with "seen" at 75 % and at 90 % of the ball visible."""
    studio, motion = studio_from_settings(settings)
    with studio:
        ms = studio.markerset
        measurer = FrameMeasurer(studio.cameras, ColourTable.build(ms.palette), ms.radius_m)
        points, truth, vis, merged = [], [], [], []
        frames = studio.play(motion, settings.fps, seconds=settings.seconds, noise_sigma=settings.noise_sigma,
                             brightness_drop=settings.brightness_drop, colour_cast=settings.colour_cast,
                             seed=settings.seed)
        total = studio.n_frames(motion, settings.fps, settings.seconds)
        for sf in tqdm(frames, total=total, unit="frame", desc=settings.motion, leave=False, disable=not progress):
            points.append(measurer.measure(sf.frames.images).p_world_m)
            truth.append(sf.markers_m)
            vis.append(sf.visible_fraction)
            merged.append(sf.merged)
    args = (points, np.stack(truth), np.stack(vis), np.stack(merged))
    return evaluate_points(*args), evaluate_points(*args, seen_fraction=0.9)


def validate(base: SimulationSettings, motions: Sequence[str] | None = None, *, progress: bool = False
             ) -> Iterator[tuple[str, PointAccuracy, PointAccuracy]]:
    """Validate several motions (default: every built-in one).

    Yields (motion, accuracy with "seen" at 75 % of the ball visible, the same at 90 %).
    """
    for name in motions or available_motions():
        yield (name, *validate_motion_both(replace(base, motion=name), progress=progress))


def combine(results: Sequence[PointAccuracy]) -> PointAccuracy:
    """Pool several motions' figures (RMSE pooled by matched-point count; p95 is the worst motion's)."""
    found = sum(r.markers_found for r in results)
    sq = sum((r.rmse_mm**2) * r.markers_found for r in results if np.isfinite(r.rmse_mm))
    return PointAccuracy(
        frames=sum(r.frames for r in results),
        markers_seen2=sum(r.markers_seen2 for r in results),
        markers_found=found,
        rmse_mm=float(np.sqrt(sq / max(found, 1))),
        p95_mm=max((r.p95_mm for r in results), default=float("nan")),
        max_mm=max((r.max_mm for r in results), default=float("nan")),
        ghost_points=sum(r.ghost_points for r in results),
        ghost_frames=sum(r.ghost_frames for r in results),
    )


@dataclass(frozen=True, slots=True)
class AngleAccuracy:
    """One joint angle over a tracked motion, against the truth.

    Attributes:
        rmse_deg: RMSE over the frames where the angle has a tracked and a true value, i.e. where
            all its markers are measured or estimated (NaN: no such frame).
        frames: frames with a true value (the angle is defined for the true pose).
        estimated: share of those frames in which the angle was reported with at least one of its
            markers estimated.
        lost: share of those frames without a reported value (one of its markers lost).
        rmse_estimated_deg: RMSE over the frames with an estimated marker (NaN: none).
        rmse_measured_deg: RMSE over the frames with all its markers measured (the floor that
            measurement noise sets; NaN: none).
        ill_conditioned: frames left out of the RMSEs above because the angle is ill-conditioned
            in the true pose there: 1 mm of error in one of its markers can move it by more than
            :data:`ILL_CONDITIONED_DEG_PER_MM` (a planar angle of a segment nearly along the
            plane's normal: shoulder flexion with the arm straight out to the side).
        rmse_all_deg: RMSE over all the frames of ``rmse_deg`` and the ill-conditioned ones.
    """

    rmse_deg: float
    frames: int
    estimated: float
    lost: float
    rmse_estimated_deg: float
    rmse_measured_deg: float = float("nan")
    ill_conditioned: int = 0
    rmse_all_deg: float = float("nan")


@dataclass(frozen=True, slots=True)
class TrackingAccuracy:
    """The tracker on one simulated motion, against the truth.

    Attributes:
        frames: frame sets processed; identified_at: first frame with names (-1: never).
        swaps: (frame, marker) cases where a marker was measured on another marker's ball.
        measured, estimated, lost: shares of marker positions by status after identification.
        measured_rmse_mm, estimated_mean_mm: position errors by status.
        angle_rmse_deg: per angle, RMSE over frames where both tracked and true angles exist
            (all the angle's markers measured or estimated).
        angles: per angle, the RMSE with the shares of frames estimated and lost.
    """

    frames: int
    identified_at: int
    swaps: int
    measured: float
    estimated: float
    lost: float
    measured_rmse_mm: float
    estimated_mean_mm: float
    angle_rmse_deg: dict[str, float]
    angles: dict[str, AngleAccuracy] = field(default_factory=dict)

    def worst_angle(self) -> tuple[str, float]:
        """(name, RMSE) of the angle with the largest RMSE (("-", NaN) without angles)."""
        return max(self.angle_rmse_deg.items(), key=lambda kv: kv[1], default=("-", float("nan")))

    def summary(self) -> str:
        worst = self.worst_angle()
        text = (
            f"{self.frames} frames, identified at frame {self.identified_at}, {self.swaps} swaps; "
            f"measured {100 * self.measured:.1f} % (RMSE {self.measured_rmse_mm:.2f} mm), estimated "
            f"{100 * self.estimated:.1f} % (mean error {self.estimated_mean_mm:.1f} mm), lost {100 * self.lost:.1f} %; "
            f"worst angle RMSE {worst[1]:.2f} deg ({worst[0]})"
        )
        if worst[0] in self.angles:
            a = self.angles[worst[0]]
            text += (f", its frames estimated {100 * a.estimated:.1f} % / lost {100 * a.lost:.1f} %, "
                     f"RMSE {a.rmse_measured_deg:.2f} deg where all its markers are measured")
        ill = {name: a for name, a in self.angles.items() if a.ill_conditioned}
        if ill:
            text += "; left out as ill-conditioned (> {:g} deg per mm): ".format(ILL_CONDITIONED_DEG_PER_MM) + ", ".join(
                f"{name} {a.ill_conditioned} frame{'s' if a.ill_conditioned > 1 else ''} (RMSE with them {a.rmse_all_deg:.2f})"
                for name, a in ill.items())
        return text


ILL_CONDITIONED_DEG_PER_MM = 5.0
"""An angle that 1 mm of error in one marker (along any axis) can move by more than this is
ill-conditioned in that frame. Well-conditioned angles move 0.1-0.3 degrees per mm (shoulder and
elbow, 250-350 mm segments) to ~1.5 (forearm supination, markers 50-60 mm apart); shoulder flexion
passes 5 degrees per mm where the upper arm is within ~2 degrees of the trunk's left-right axis."""


def angle_sensitivity(truth_m: np.ndarray, names: Sequence[str], uses: dict[str, np.ndarray],
                      step_m: float = 0.001) -> dict[str, np.ndarray]:
    """Per angle, (T,) the largest change (degrees) of its true value when one of its markers
    moves by ``step_m`` along one world axis: how much marker error the angle amplifies in each
    frame (NaN where the angle is undefined)."""
    base = joint_angles(truth_m, names)
    sens = {name: np.where(np.isfinite(v), 0.0, np.nan) for name, v in base.items()}
    for m in np.flatnonzero(np.any(list(uses.values()), axis=0)):
        for axis in range(3):
            moved = truth_m.copy()
            moved[:, m, axis] += step_m
            for name, values in joint_angles(moved, names).items():
                if uses[name][m]:
                    d = np.abs((values - base[name] + 180.0) % 360.0 - 180.0)
                    sens[name] = np.fmax(sens[name], np.where(np.isfinite(base[name]), np.nan_to_num(d, nan=np.inf), np.nan))
    return sens


def angle_markers(truth_m: np.ndarray, names: Sequence[str]) -> dict[str, np.ndarray]:
    """Which markers each joint angle reads: angle -> (M,) bool.

    Found on the true poses: an angle reads marker m if hiding m (NaN) makes it undefined in a
    frame where it is defined. Shape of ``truth_m``: (T, M, 3) world metres.
    """
    base = joint_angles(truth_m, names)
    uses = {name: np.zeros(len(names), dtype=bool) for name in base}
    for m in range(len(names)):
        hidden = truth_m.copy()
        hidden[:, m] = np.nan
        for name, values in joint_angles(hidden, names).items():
            uses[name][m] = bool(np.any(np.isfinite(base[name]) & ~np.isfinite(values)))
    return uses


def score_tracking(positions_m: np.ndarray, status: np.ndarray, truth_m: np.ndarray, names: Sequence[str], *,
                   frames: int, identified_at: int, swaps: int,
                   angles_deg: dict[str, np.ndarray] | None = None) -> TrackingAccuracy:
    """Compare a tracked motion with the truth.

    Args:
        positions_m: (T, M, 3) tracked positions after identification, NaN where LOST.
        status: (T, M) uint8 :class:`~tracking.marker_status.MarkerStatus`.
        truth_m: (T, M, 3) true marker centres.
        names: the M marker names.
        frames, identified_at, swaps: passed through to the result.
        angles_deg: the tracker's reported angles, name -> (T,) (NaN where it reported none, e.g.
            a withheld supination); None: computed from the positions.
    """

    pos = np.where((status != MarkerStatus.LOST)[..., None], positions_m, np.nan)
    err = np.linalg.norm(pos - truth_m, axis=-1) * 1000.0
    meas, est = status == MarkerStatus.MEASURED, status == MarkerStatus.ESTIMATED
    true_angles = joint_angles(truth_m, names)
    tracked_angles = joint_angles(pos, names) if angles_deg is None else angles_deg
    uses = angle_markers(truth_m, names)
    sensitivity = angle_sensitivity(truth_m, names, uses)
    rmse, angles = {}, {}
    for name, values in tracked_angles.items():
        defined = np.isfinite(true_angles[name])
        reported = np.isfinite(values) & defined
        ill = reported & ~(sensitivity[name] <= ILL_CONDITIONED_DEG_PER_MM)
        ok = reported & ~ill
        with_est = ok & est[:, uses[name]].any(axis=1)
        all_meas = ok & meas[:, uses[name]].all(axis=1)
        diff = (values - true_angles[name] + 180.0) % 360.0 - 180.0
        n = int(defined.sum())
        a_rmse = float(np.sqrt(np.mean(diff[ok] ** 2))) if ok.any() else float("nan")
        if ok.any():
            rmse[name] = a_rmse
        angles[name] = AngleAccuracy(
            rmse_deg=a_rmse,
            frames=n,
            estimated=float(with_est.sum() / n) if n else 0.0,
            lost=float((defined & ~np.isfinite(values)).sum() / n) if n else 0.0,
            rmse_estimated_deg=float(np.sqrt(np.mean(diff[with_est] ** 2))) if with_est.any() else float("nan"),
            rmse_measured_deg=float(np.sqrt(np.mean(diff[all_meas] ** 2))) if all_meas.any() else float("nan"),
            ill_conditioned=int(ill.sum()),
            rmse_all_deg=float(np.sqrt(np.mean(diff[reported] ** 2))) if reported.any() else float("nan"),
        )
    return TrackingAccuracy(
        frames=frames,
        identified_at=identified_at,
        swaps=swaps,
        measured=float(meas.mean()),
        estimated=float(est.mean()),
        lost=float((status == MarkerStatus.LOST).mean()),
        measured_rmse_mm=float(np.sqrt(np.mean(err[meas] ** 2))) if meas.any() else float("nan"),
        estimated_mean_mm=float(err[est].mean()) if est.any() else float("nan"),
        angle_rmse_deg=rmse,
        angles=angles,
    )


@dataclass(frozen=True, slots=True, eq=False)
class TrackedRun:
    """The tracker's output over one motion, frame by frame, with the truth.

    Attributes:
        names: the M marker names.
        positions_m: (T, M, 3) tracked positions after identification (NaN where lost).
        status: (T, M) uint8 marker status.
        truth_m: (T, M, 3) true marker centres of the same frames.
        frames: all frame sets processed (identification included).
        identified_at: first frame with names (-1: never).
        swaps: (frame, marker) cases where a marker was measured on another marker's ball.
        angles_deg: the tracker's reported angles of the same frames, name -> (T,); None: computed
            from the positions when scored.
    """

    names: tuple[str, ...]
    positions_m: np.ndarray
    status: np.ndarray
    truth_m: np.ndarray
    frames: int
    identified_at: int
    swaps: int
    angles_deg: dict[str, np.ndarray] | None = None

    def score(self) -> TrackingAccuracy:
        if not len(self.positions_m):
            return TrackingAccuracy(self.frames, -1, 0, 0.0, 0.0, 1.0, float("nan"), float("nan"), {})
        return score_tracking(self.positions_m, self.status, self.truth_m, self.names, frames=self.frames,
                              identified_at=self.identified_at, swaps=self.swaps, angles_deg=self.angles_deg)


def track_frames(tracker, frames: Iterable[tuple[Sequence[np.ndarray], float, np.ndarray]]) -> TrackedRun:
    """Run ``tracker`` over (images, time_s, true (M, 3) marker centres) frame sets."""

    positions, status, truth, angles = [], [], [], []
    identified_at, swaps, total = -1, 0, 0
    for images, time_s, truth_m in frames:
        total += 1
        s = tracker.step(images, time_s)
        if s.state != TrackingState.TRACKING:
            continue
        if identified_at < 0:
            identified_at = s.frame_index
        d = np.linalg.norm(s.positions_m[:, None, :] - truth_m[None, :, :], axis=-1)
        # an identity swap: a marker measured on another marker's ball (an estimate that drifts
        # near another ball is an estimation error, counted in estimated_mean_mm)
        meas_now = s.status == MarkerStatus.MEASURED
        own = np.diag(d)
        swaps += int(np.sum(meas_now & (own > 0.02) & (d.min(axis=1) < 0.02) & (d.argmin(axis=1) != np.arange(len(own)))))
        positions.append(np.where((s.status != MarkerStatus.LOST)[:, None], s.positions_m, np.nan))
        status.append(s.status)
        truth.append(truth_m)
        angles.append(s.angles_deg)
    m = len(tracker.markerset.names)
    stack = (lambda rows, shape: np.stack(rows) if rows else np.zeros(shape))
    reported = {name: np.array([a.get(name, np.nan) for a in angles]) for name in angles[0]} if angles else None
    return TrackedRun(tuple(tracker.markerset.names), stack(positions, (0, m, 3)), stack(status, (0, m)).astype(np.uint8),
                      stack(truth, (0, m, 3)), total, identified_at, swaps, reported)


def validate_tracking(settings: SimulationSettings, *, progress: bool = False) -> TrackingAccuracy:
    """Render one motion and run the tracker on it, frame by frame, as ``rehab track`` does."""
    return track_simulated(settings, progress=progress).score()


def track_simulated(settings: SimulationSettings, *, progress: bool = False) -> TrackedRun:
    """Render one motion and run the tracker on it; the frame-by-frame output with the truth."""
    studio, motion = studio_from_settings(settings)
    with studio:
        tracker = Tracker(studio.cameras, studio.markerset, fps=settings.fps)
        frames = studio.play(motion, settings.fps, seconds=settings.seconds, noise_sigma=settings.noise_sigma,
                             brightness_drop=settings.brightness_drop, colour_cast=settings.colour_cast,
                             seed=settings.seed, with_visibility=False)
        total = studio.n_frames(motion, settings.fps, settings.seconds)
        bar = tqdm(frames, total=total, unit="frame", desc=settings.motion, leave=False, disable=not progress)
        return track_frames(tracker, ((sf.frames.images, sf.frames.time_s, sf.markers_m) for sf in bar))


def track_recording_with_truth(folder: Path, *, progress: bool = False) -> TrackedRun:
    """Run the tracker on a simulated recording folder (``rehab simulate``) against its truth.trc.

    Tracking a cached recording gives the same figures as :func:`validate_tracking` on the same
    settings (the videos are lossless) without rendering again.
    """

    folder = Path(folder)
    truth = read_trc(folder / "truth.trc")
    with Recording(folder) as rec:
        ms = load_markerset(rec.meta.markerset)
        tracker = Tracker(rec.cameras, ms, fps=rec.fps)
        index = [truth.names.index(n) for n in ms.names]
        truth_m = truth.positions_mm[:, index] / 1000.0
        bar = tqdm(rec, total=rec.n_frames, unit="frame", desc=folder.name, leave=False, disable=not progress)
        return track_frames(tracker, ((fs.images, fs.time_s, truth_m[fs.index]) for fs in bar))
