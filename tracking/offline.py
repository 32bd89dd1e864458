"""Offline drivers: track a recording folder frame by frame and write result files."""

from __future__ import annotations

import csv
import logging
from pathlib import Path
from typing import Sequence

import numpy as np
from tqdm import tqdm

from tracking.colour_table import ColourTable
from tracking.markerset import MarkerSet, load_markerset, parse_rgb
from tracking.measure import FrameMeasurer
from tracking.recording import Recording

log = logging.getLogger(__name__)


def markerset_for(recording: Recording, markerset: str | None, marker_colours: Sequence[str] | None) -> MarkerSet:
    """The marker set of a recording: --markerset or meta.yaml's; colours: --marker-color, else meta.yaml's."""
    ms = load_markerset(markerset or recording.meta.markerset)
    if marker_colours:
        return ms.with_colours([parse_rgb(c) for c in marker_colours])
    if recording.meta.marker_colours and len(recording.meta.marker_colours) == ms.n_markers:
        return ms.with_colours(list(recording.meta.marker_colours))
    return ms


def track_recording(
    folder: Path,
    *,
    calibration: Path | None = None,
    markerset: str | None = None,
    marker_colours: Sequence[str] | None = None,
    points_csv: Path | None = None,
    progress: bool = False,
) -> str:
    """Measure every frame set of a recording; write the unlabelled points. Returns a summary line."""
    with Recording(folder, calibration) as rec:
        ms = markerset_for(rec, markerset, marker_colours)
        table = ColourTable.build(ms.palette)
        measurer = FrameMeasurer(rec.cameras, table, ms.radius_m)
        n_points = n_frames = 0
        out = open(points_csv, "w", newline="", encoding="utf-8") if points_csv else None
        try:
            writer = csv.writer(out) if out else None
            if writer:
                writer.writerow(["frame", "time", "x_mm", "y_mm", "z_mm", "n_cameras", "reproj_px"])
            frames = tqdm(rec, total=rec.n_frames, unit="frame", desc="tracking", disable=not progress)
            for fs in frames:
                pts = measurer.measure(fs.images)
                n_frames += 1
                n_points += len(pts)
                if writer:
                    p_mm = pts.p_world_m * 1000.0
                    for k in range(len(pts)):
                        writer.writerow([
                            fs.index, f"{fs.time_s:.4f}",
                            f"{p_mm[k, 0]:.2f}", f"{p_mm[k, 1]:.2f}", f"{p_mm[k, 2]:.2f}",
                            int(pts.n_cameras[k]), f"{pts.reproj_px[k]:.3f}",
                        ])
        finally:
            if out:
                out.close()
    per = measurer.times.per_frame_ms()
    timing = ", ".join(f"{k} {v:.1f} ms" for k, v in per.items())
    return f"{n_frames} frame sets, {n_points / max(n_frames, 1):.1f} points per frame ({timing})"
