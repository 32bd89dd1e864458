"""Offline drivers: track a recording folder frame by frame and write result files."""

from __future__ import annotations

import contextlib
import csv
import logging
from pathlib import Path
from typing import Sequence

import numpy as np
from tqdm import tqdm

from calibration.atomic import written_via_temp
from tracking import exports
from tracking.angles import ANGLE_COLUMNS
from tracking.clock_sync import fit_clocks, skew_evidence
from tracking.colour.adapt import ColourAdapter, calibration_colours, read_colours, table_from_colours
from tracking.colour.table import ColourTable
from tracking.markerset import MarkerSet
from tracking.full_frame import FrameMeasurer
from tracking.errors import RecordingError
from tracking.exports import TrackedRecording
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker, TrackingState
from tracking.sources.recording import RecordingSource

log = logging.getLogger(__name__)


def track_recording(
    folder: Path,
    *,
    calibration: Path | None = None,
    markerset: str | None = None,
    marker_colours: Sequence[str] | None = None,
    points_csv: Path | None = None,
    colours: Path | None = None,
    adapt_colours: bool = False,
    progress: bool = False,
    sync: str = "auto",
    **outputs: Path | None,
) -> str:
    """Track a recording frame by frame and write what was asked. Returns a summary line.

    ``points_csv`` gets the unlabelled full-frame points; ``outputs`` (an export format's name ->
    its file, :func:`write_results`: ``trc``, ``status_csv``, ``angles_csv``, ``c3d``, ``mot``
    (OpenSim joint angles), ``bvh`` (the avatar's skeleton), ``detections`` (2D centroids per
    camera), ...) the labelled markers from the tracker (the online algorithm, no look-ahead).
    ``colours`` is a learned colour file (``rehab colour learn``) used instead of the nominal
    table; without it, the colours learnt into the calibration file (``rehab calibrate colour``)
    are used when it holds them; ``adapt_colours`` lets the tracker's table follow the lighting
    (docs/COLOUR.md).
    """
    if _asked_files(outputs):   # (an unknown format fails here, before the work)
        return _track_labelled(folder, calibration=calibration, markerset=markerset, marker_colours=marker_colours,
                               colours=colours, adapt_colours=adapt_colours, progress=progress, sync=sync, **outputs)
    with RecordingSource(folder, calibration, markerset=markerset, marker_colours=marker_colours, sync="none") as rec:
        ms = rec.markerset
        table = _colour_table(ms, learnt_colours(rec.calibration_path, ms, colours))
        measurer = FrameMeasurer(rec.cameras, table, ms.radius_m,
                                 markers_per_colour=np.bincount(ms.colour_index, minlength=table.n_colours))
        n_points = n_frames = 0
        with contextlib.ExitStack() as temp:
            out = None
            if points_csv:
                Path(points_csv).parent.mkdir(parents=True, exist_ok=True)
                out = open(temp.enter_context(written_via_temp(points_csv)), "w", newline="", encoding="utf-8")
                temp.callback(out.close)   # closed before the rename (or the removal) of the temporary file
            writer = csv.writer(out) if out else None
            if writer:
                writer.writerow(["frame", "time", "x_mm", "y_mm", "z_mm", "n_cameras", "reproj_px"])
            frames = tqdm(iter(rec.read, None), total=rec.n_frames, unit="frame", desc="tracking",
                          disable=not progress)
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
    per = measurer.times.per_frame_ms()
    timing = ", ".join(f"{k} {v:.1f} ms" for k, v in per.items())
    return f"{n_frames} frame sets, {n_points / max(n_frames, 1):.1f} points per frame ({timing})"


def learnt_colours(calibration: Path, ms: MarkerSet, colours: Path | None = None):
    """The learnt colours to track with: ``colours`` (a colour file) if given, else those saved in
    the calibration file, else None (the nominal table). Returns (models, label_hs) or None."""
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
    return table_from_colours(*learnt)


def _track_labelled(folder, *, calibration, markerset, marker_colours, colours=None, adapt_colours=False,
                    progress=False, sync="auto", **outputs) -> str:
    run = track_frames_of(folder, calibration=calibration, markerset=markerset, marker_colours=marker_colours,
                          colours=colours, adapt_colours=adapt_colours, progress=progress, sync=sync)
    write_results(run, **outputs)
    st = run.status
    share = {s.name.lower(): float(np.mean(st == s)) for s in MarkerStatus}
    return (
        f"{len(run.frames)} frame sets: {100 * share['measured']:.1f} % of marker positions measured, "
        f"{100 * share['estimated']:.1f} % estimated, {100 * share['lost']:.1f} % lost"
        + (f"\n{run.timing}" if run.timing else "")
    )


#: how much of a recording without time stamps ``--sync auto`` studies for the cameras' clocks
SYNC_STUDY_S = 30.0


def estimated_skews(folder, n_frames: int | None, fps: float, **tracking) -> tuple[np.ndarray | None, str]:
    """The cameras' image instants estimated from the markers' motion (:mod:`tracking.clock_sync`)
    over the first ``SYNC_STUDY_S`` seconds: tracked as synchronized, estimated, tracked again with
    the estimate and estimated once more. Returns ((F, C) skews for the whole recording, or None
    when every camera is within 1 ms of the first, and a line saying what was found)."""
    study = int(round(SYNC_STUDY_S * fps))
    skews = None
    est = None
    # the recording's warnings (a camera that ends early) once, in the real pass
    reading = [logging.getLogger(name) for name in ("tracking.io.recording", "tracking.sources.recording")]
    levels = [r.level for r in reading]
    for r in reading:
        r.setLevel(logging.ERROR)
    try:
        for _ in range(2):
            try:
                run = track_frames_of(folder, sync="none", _skews=skews, _max_frames=study, **tracking)
            except RecordingError:  # (not named in the first seconds: the real pass says why)
                return None, f"clock offsets not estimated: the markers were not named in the first {SYNC_STUDY_S:g} s"
            pos = np.where((run.status == MarkerStatus.MEASURED)[..., None], run.positions_mm / 1000.0, np.nan)
            est = fit_clocks(skew_evidence(run.cameras, run.times_s, pos, run.uv_px), 1.0 / fps)
            skews = est.skews(np.arange(n_frames or len(run.times_s)) / fps)
    finally:
        for r, level in zip(reading, levels):
            r.setLevel(level)
    names = [c.name for c in run.cameras]
    line = est.line(names)
    if np.abs(skews).max() < 0.001:  # (a camera not estimated keeps the first camera's instants)
        return None, line + "; cameras taken as synchronized"
    return skews, line + "; applied"


def track_frames_of(folder, *, calibration=None, markerset=None, marker_colours=None, colours=None,
                    adapt_colours=False, progress=False, sync="auto", _skews=None, _max_frames=None
                    ) -> TrackedRecording:
    """Run the tracker over a recording folder; :class:`RecordingError` (one line) if it never
    identified the markers. ``sync``: the images' instants
    (:func:`tracking.sources.recording.image_skews`; "auto" without timestamps.csv estimates them,
    :func:`estimated_skews`)."""
    with RecordingSource(folder, calibration, markerset=markerset, marker_colours=marker_colours, sync=sync) as rec:
        ms = rec.markerset
        if _skews is not None:
            rec.use_skews(_skews, "")
        elif sync == "auto" and rec.skews is None and _max_frames is None:
            skews, found = estimated_skews(folder, rec.n_frames, rec.fps, calibration=calibration, markerset=markerset,
                                           marker_colours=marker_colours, colours=colours)
            rec.use_skews(skews, "; ".join(x for x in (found, rec.timing) if x))
        adapter = None
        learnt = learnt_colours(rec.calibration_path, ms, colours)
        if adapt_colours:
            adapter = ColourAdapter(rec.cameras, ms, start=learnt)
            tracker = Tracker(rec.cameras, ms, table=adapter.table, fps=rec.fps)
        else:
            tracker = Tracker(rec.cameras, ms, table=_colour_table(ms, learnt), fps=rec.fps)
        no_uv = np.full((ms.n_markers, len(rec.cameras), 2), np.nan)
        positions, status, frames, times, angles, uv, identified = [], [], [], [], [], [], []
        waiting_message = ""
        was_tracking = False
        frame_iter = tqdm(iter(rec.read, None), total=rec.n_frames, unit="frame", desc="tracking",
                          disable=not progress)
        for fs in frame_iter:
            if _max_frames is not None and fs.index >= _max_frames:
                break
            sample = tracker.step(fs.images, fs.time_s, fs.stamps_s)
            tracking = sample.state == TrackingState.TRACKING
            if not tracking:
                waiting_message = sample.message
            elif adapter is not None:
                adapter.observe(fs.images, sample.positions_m, sample.status)
            identified.append(tracking and not was_tracking)
            was_tracking = tracking
            positions.append(np.where(sample.status[:, None] == MarkerStatus.LOST, np.nan, sample.positions_m))
            status.append(sample.status)
            angles.append(sample.angles_deg)
            uv.append(no_uv if sample.uv_px is None else sample.uv_px)
            frames.append(fs.index)
            times.append(fs.time_s)
        cameras = tuple(rec.cameras)
        subject = rec.meta.extra.get("subject")
        rate = rec.fps
        timing = rec.timing
    if not frames:
        raise RecordingError(f"{folder}: the recording has no frames")
    st = np.stack(status)
    if not (st != MarkerStatus.LOST).any():
        raise RecordingError(
            f"{folder}: the markers were never identified ({waiting_message or 'no reference pose'}); "
            "the recording must start with the patient in the reference pose"
        )
    return TrackedRecording(
        names=tuple(ms.names), markerset=ms.name, cameras=cameras, frames=np.asarray(frames),
        times_s=np.asarray(times, dtype=np.float64), rate_hz=float(rate), positions_mm=np.stack(positions) * 1000.0,
        status=st, angles_deg={c: np.array([a.get(c, np.nan) for a in angles]) for c in ANGLE_COLUMNS},
        uv_px=np.stack(uv), identified=np.asarray(identified), subject=None if subject is None else str(subject),
        timing=timing,
    )


def write_results(run: TrackedRecording, **paths: str | Path | None) -> None:
    """Write the asked result files of a tracked recording (docs/FILES.md).

    ``paths``: an export format's name (:mod:`tracking.exports`: ``trc``, ``status_csv``,
    ``angles_csv``, ``c3d``, ``mot``, ``bvh``, ``detections``, ...) -> its file (None: not asked),
    written in the formats' order.
    """
    asked = _asked_files(paths)
    for _, path in asked:
        path.parent.mkdir(parents=True, exist_ok=True)
    # each file through a temporary file beside it, renamed when whole: a kill or a failure
    # half-way never leaves half a file under the asked name
    for fmt, path in asked:
        with written_via_temp(path) as tmp:
            fmt.write(run, tmp, asked=path)


def _asked_files(paths) -> list[tuple[exports.ExportFormat, Path]]:
    """(format, file) of each asked file in the formats' order; a TypeError, as for any unknown
    keyword, when ``paths`` names a format that is not registered."""
    unknown = sorted(set(paths) - set(exports.names()))
    if unknown:
        raise TypeError(f"unexpected keyword argument {unknown[0]!r}: export formats are {', '.join(exports.names())}")
    return [(fmt, Path(paths[fmt.name])) for fmt in exports.formats() if paths.get(fmt.name)]
