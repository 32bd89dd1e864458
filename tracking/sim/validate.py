"""Measurement accuracy on the simulated patient, motion by motion (``rehab validate``).

Each motion is rendered in memory (no video encoding) and measured by the same
:class:`tracking.measure.FrameMeasurer` that ``rehab track`` uses; the points are compared with
the simulator's truth by :func:`tracking.evaluate.evaluate_points`.
"""

from __future__ import annotations

from dataclasses import replace
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
