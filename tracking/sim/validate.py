"""Measurement accuracy on the simulated patient, motion by motion (``rehab validate``).

Each motion is rendered in memory (no video encoding) and measured by the same
:class:`tracking.measure.FrameMeasurer` that ``rehab track`` uses; the points are compared with
the simulator's truth by :func:`tracking.evaluate.evaluate_points`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Iterator, Sequence

import numpy as np
from tqdm import tqdm

from tracking.colour_table import ColourTable
from tracking.evaluate import PointAccuracy, evaluate_points
from tracking.measure import FrameMeasurer
from tracking.sim.motions import available_motions
from tracking.sim.studio import SimulationSettings, studio_from_settings


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
class TrackingAccuracy:
    """The tracker on one simulated motion, against the truth.

    Attributes:
        frames: frame sets processed; identified_at: first frame with names (-1: never).
        swaps: (frame, marker) cases where a marker was measured on another marker's ball.
        measured, estimated, lost: shares of marker positions by status after identification.
        measured_rmse_mm, estimated_mean_mm: position errors by status.
        angle_rmse_deg: per angle, RMSE over frames where both tracked and true angles exist.
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

    def summary(self) -> str:
        worst = max(self.angle_rmse_deg.items(), key=lambda kv: kv[1], default=("-", float("nan")))
        return (
            f"{self.frames} frames, identified at frame {self.identified_at}, {self.swaps} swaps; "
            f"measured {100 * self.measured:.1f} % (RMSE {self.measured_rmse_mm:.2f} mm), estimated "
            f"{100 * self.estimated:.1f} % (mean error {self.estimated_mean_mm:.1f} mm), lost {100 * self.lost:.1f} %; "
            f"worst angle RMSE {worst[1]:.2f} deg ({worst[0]})"
        )


def validate_tracking(settings: SimulationSettings, *, progress: bool = False) -> TrackingAccuracy:
    """Render one motion and run the tracker on it, frame by frame, as ``rehab track`` does."""
    from tracking.angles import joint_angles
    from tracking.status import MarkerStatus
    from tracking.tracker import Tracker, TrackingState

    studio, motion = studio_from_settings(settings)
    with studio:
        ms = studio.markerset
        tracker = Tracker(studio.cameras, ms, fps=settings.fps)
        positions, status, truth = [], [], []
        identified_at, swaps = -1, 0
        frames = studio.play(motion, settings.fps, seconds=settings.seconds, noise_sigma=settings.noise_sigma,
                             brightness_drop=settings.brightness_drop, colour_cast=settings.colour_cast,
                             seed=settings.seed, with_visibility=False)
        total = studio.n_frames(motion, settings.fps, settings.seconds)
        for sf in tqdm(frames, total=total, unit="frame", desc=settings.motion, leave=False, disable=not progress):
            s = tracker.step(sf.frames.images, sf.frames.time_s)
            if s.state != TrackingState.TRACKING:
                continue
            if identified_at < 0:
                identified_at = s.frame_index
            d = np.linalg.norm(s.positions_m[:, None, :] - sf.markers_m[None, :, :], axis=-1)
            has = s.status != MarkerStatus.LOST
            # an identity swap: a marker measured on another marker's ball (an estimate that
            # drifts near another ball is an estimation error, counted in estimated_mean_mm)
            meas_now = s.status == MarkerStatus.MEASURED
            own = np.diag(d)
            swaps += int(np.sum(meas_now & (own > 0.02) & (d.min(axis=1) < 0.02) & (d.argmin(axis=1) != np.arange(len(own)))))
            positions.append(np.where(has[:, None], s.positions_m, np.nan))
            status.append(s.status)
            truth.append(sf.markers_m)
    if not positions:
        return TrackingAccuracy(total, -1, 0, 0.0, 0.0, 1.0, float("nan"), float("nan"), {})
    pos, st, tru = np.stack(positions), np.stack(status), np.stack(truth)
    err = np.linalg.norm(pos - tru, axis=-1) * 1000.0
    meas, est = st == MarkerStatus.MEASURED, st == MarkerStatus.ESTIMATED
    tracked_angles, true_angles = joint_angles(pos, ms.names), joint_angles(tru, ms.names)
    rmse = {}
    for name, values in tracked_angles.items():
        ok = np.isfinite(values) & np.isfinite(true_angles[name])
        if ok.any():
            diff = (values[ok] - true_angles[name][ok] + 180.0) % 360.0 - 180.0
            rmse[name] = float(np.sqrt(np.mean(diff**2)))
    return TrackingAccuracy(
        frames=total,
        identified_at=identified_at,
        swaps=swaps,
        measured=float(meas.mean()),
        estimated=float(est.mean()),
        lost=float((st == MarkerStatus.LOST).mean()),
        measured_rmse_mm=float(np.sqrt(np.mean(err[meas] ** 2))) if meas.any() else float("nan"),
        estimated_mean_mm=float(err[est].mean()) if est.any() else float("nan"),
        angle_rmse_deg=rmse,
    )
