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
from tracking.errors import RecordingError
from tracking.recording import Recording

log = logging.getLogger(__name__)


def markerset_for(recording: Recording, markerset: str | None, marker_colours: Sequence[str] | None) -> MarkerSet:
    """The marker set of a recording: --markerset or meta.yaml's; colours: --marker-color, else meta.yaml's."""
    ms = load_markerset(markerset or recording.meta.markerset)
    if marker_colours:
        return ms.with_colours([parse_rgb(c) for c in marker_colours])
    if recording.meta.marker_colours:
        if len(recording.meta.marker_colours) != ms.n_markers:
            raise RecordingError(f"{recording.folder / 'meta.yaml'} gives {len(recording.meta.marker_colours)} "
                                 f"marker_colours but the marker set {ms.name} has {ms.n_markers} markers: give one "
                                 f"per marker ({', '.join(ms.names)}) or none")
        return ms.with_colours(list(recording.meta.marker_colours))
    return ms


def track_recording(
    folder: Path,
    *,
    calibration: Path | None = None,
    markerset: str | None = None,
    marker_colours: Sequence[str] | None = None,
    points_csv: Path | None = None,
    trc: Path | None = None,
    status_csv: Path | None = None,
    angles_csv: Path | None = None,
    c3d: Path | None = None,
    colours: Path | None = None,
    adapt_colours: bool = False,
    progress: bool = False,
) -> str:
    """Track a recording frame by frame and write what was asked. Returns a summary line.

    ``points_csv`` gets the unlabelled full-frame points; ``trc``, ``status_csv``, ``angles_csv``
    and ``c3d`` the labelled markers from the tracker (the online algorithm, no look-ahead).
    ``colours`` is a learned colour file (``rehab colour learn``) used instead of the nominal
    table; without it, the colours learnt into the calibration file (``rehab calibrate colour``)
    are used when it holds them; ``adapt_colours`` lets the tracker's table follow the lighting
    (docs/COLOUR.md).
    """
    if trc or status_csv or angles_csv or c3d:
        return _track_labelled(folder, calibration=calibration, markerset=markerset, marker_colours=marker_colours,
                               points_csv=points_csv, trc=trc, status_csv=status_csv, angles_csv=angles_csv,
                               c3d=c3d, colours=colours, adapt_colours=adapt_colours, progress=progress)
    with Recording(folder, calibration) as rec:
        ms = markerset_for(rec, markerset, marker_colours)
        table = _colour_table(ms, learnt_colours(rec.calibration_path, ms, colours))
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


def learnt_colours(calibration: Path, ms: MarkerSet, colours: Path | None = None):
    """The learnt colours to track with: ``colours`` (a colour file) if given, else those saved in
    the calibration file, else None (the nominal table). Returns (models, label_hs) or None."""
    from tracking.colour_adapt import calibration_colours, read_colours

    if colours is not None:
        return read_colours(colours, ms)
    found = calibration_colours(calibration, ms)
    if found is not None:
        log.info("using the marker colours learnt into %s", calibration)
    return found


def _colour_table(ms: MarkerSet, learnt) -> ColourTable:
    """The nominal table, or the table of ``learnt`` (models, label_hs) colours."""
    if learnt is None:
        return ColourTable.build(ms.palette)
    from tracking.colour_adapt import table_from_colours

    return table_from_colours(*learnt)


def _track_labelled(folder, *, calibration, markerset, marker_colours, points_csv, trc, status_csv, angles_csv,
                    c3d, colours=None, adapt_colours=False, progress=False) -> str:
    from tracking.angles import ANGLE_COLUMNS
    from tracking.c3d_io import write_c3d
    from tracking.status import MarkerStatus
    from tracking.tables import write_angles_csv, write_status_csv
    from tracking.tracker import Tracker, TrackingState
    from tracking.trc import write_trc

    with Recording(folder, calibration) as rec:
        ms = markerset_for(rec, markerset, marker_colours)
        adapter = None
        learnt = learnt_colours(rec.calibration_path, ms, colours)
        if adapt_colours:
            from tracking.colour_adapt import ColourAdapter

            adapter = ColourAdapter(rec.cameras, ms, start=learnt)
            tracker = Tracker(rec.cameras, ms, table=adapter.table, fps=rec.fps)
        else:
            tracker = Tracker(rec.cameras, ms, table=_colour_table(ms, learnt), fps=rec.fps)
        positions, status, frames, times, angles = [], [], [], [], []
        waiting_message = ""
        frame_iter = tqdm(rec, total=rec.n_frames, unit="frame", desc="tracking", disable=not progress)
        for fs in frame_iter:
            sample = tracker.step(fs.images, fs.time_s)
            if sample.state == TrackingState.WAITING:
                waiting_message = sample.message
            elif adapter is not None:
                adapter.observe(fs.images, sample.positions_m, sample.status)
            positions.append(np.where(sample.status[:, None] == MarkerStatus.LOST, np.nan, sample.positions_m))
            status.append(sample.status)
            angles.append(sample.angles_deg)
            frames.append(fs.index)
            times.append(fs.time_s)
    if not frames:
        raise RecordingError(f"{folder}: the recording has no frames")
    pos_mm = np.stack(positions) * 1000.0
    st = np.stack(status)
    frames_a, times_a = np.asarray(frames), np.asarray(times)
    if not (st != MarkerStatus.LOST).any():
        raise RecordingError(
            f"{folder}: the markers were never identified ({waiting_message or 'no reference pose'}); "
            "the recording must start with the patient in the reference pose"
        )
    for path in (trc, status_csv, angles_csv, c3d):
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
    if trc:
        write_trc(trc, ms.names, pos_mm, rec.fps, frame_numbers=frames_a, times_s=times_a)
    if status_csv:
        write_status_csv(status_csv, frames_a, times_a, ms.names, pos_mm, st)
    if angles_csv:
        # the tracker's angles: those of the positions (as `rehab angles` on the TRC gives), but
        # without a supination whose elbow axis is a guess
        write_angles_csv(angles_csv, frames_a, times_a,
                         {c: np.array([a.get(c, np.nan) for a in angles]) for c in ANGLE_COLUMNS})
    if c3d:
        write_c3d(c3d, ms.names, pos_mm, rec.fps)
    share = {s.name.lower(): float(np.mean(st == s)) for s in MarkerStatus}
    return (
        f"{len(frames)} frame sets: {100 * share['measured']:.1f} % of marker positions measured, "
        f"{100 * share['estimated']:.1f} % estimated, {100 * share['lost']:.1f} % lost"
    )
