"""Offline drivers: track a recording folder frame by frame and write result files."""

from __future__ import annotations

import contextlib
import csv
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
from tqdm import tqdm

from calibration.atomic import written_via_temp
from tracking.angles import ANGLE_COLUMNS
# the file writers through their modules (a test replaces one to fail half-way through a file)
import tracking.io.bvh as bvh_format
import tracking.io.c3d as c3d_format
import tracking.io.detections as detections_format
import tracking.io.opensim_mot as mot_format
import tracking.io.csv_tables as tables_format
import tracking.io.trc as trc_format
from tracking.clock_sync import fit_clocks, skew_evidence
from tracking.colour.adapt import ColourAdapter, calibration_colours, read_colours, table_from_colours
from tracking.colour.table import ColourTable
from tracking.markerset import MarkerSet
from tracking.full_frame import FrameMeasurer
from tracking.errors import RecordingError
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
    trc: Path | None = None,
    status_csv: Path | None = None,
    angles_csv: Path | None = None,
    c3d: Path | None = None,
    mot: Path | None = None,
    bvh: Path | None = None,
    detections: Path | None = None,
    colours: Path | None = None,
    adapt_colours: bool = False,
    progress: bool = False,
    sync: str = "auto",
) -> str:
    """Track a recording frame by frame and write what was asked. Returns a summary line.

    ``points_csv`` gets the unlabelled full-frame points; ``trc``, ``status_csv``, ``angles_csv``,
    ``c3d``, ``mot`` (OpenSim joint angles), ``bvh`` (the avatar's skeleton) and ``detections``
    (2D centroids per camera) the labelled markers from the tracker (the online algorithm, no
    look-ahead).
    ``colours`` is a learned colour file (``rehab colour learn``) used instead of the nominal
    table; without it, the colours learnt into the calibration file (``rehab calibrate colour``)
    are used when it holds them; ``adapt_colours`` lets the tracker's table follow the lighting
    (docs/COLOUR.md).
    """
    if trc or status_csv or angles_csv or c3d or mot or bvh or detections:
        return _track_labelled(folder, calibration=calibration, markerset=markerset, marker_colours=marker_colours,
                               points_csv=points_csv, trc=trc, status_csv=status_csv, angles_csv=angles_csv,
                               c3d=c3d, mot=mot, bvh=bvh, detections=detections, colours=colours,
                               adapt_colours=adapt_colours, progress=progress, sync=sync)
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


@dataclass(frozen=True, slots=True, eq=False)  # arrays: no elementwise __eq__
class TrackedRecording:
    """What the tracker made of a recording, frame by frame (T frame sets, M markers, C cameras).

    Attributes:
        names: the M marker names; markerset: the marker set's name.
        cameras: the C cameras.
        frames: (T,) recording frame indices (0 = first image); times_s: (T,) seconds.
        rate_hz: the recording's frame rate.
        positions_mm: (T, M, 3) world millimetres, NaN where lost.
        status: (T, M) :class:`~tracking.marker_status.MarkerStatus` codes.
        angles_deg: angle name -> (T,) degrees (the tracker's, NaN where undefined).
        uv_px: (T, M, C, 2) centroids each position was triangulated from, NaN where unused.
        identified: (T,) bool, the frame sets where the tracker identified the markers (the first
            TRACKING frame set after WAITING).
        subject: meta.yaml's ``subject`` (a pseudonymous ID), or None.
        timing: one line on the images' instants used (time stamps, rolling shutter), or "".
    """

    names: tuple[str, ...]
    markerset: str
    cameras: tuple
    frames: np.ndarray
    times_s: np.ndarray
    rate_hz: float
    positions_mm: np.ndarray
    status: np.ndarray
    angles_deg: dict[str, np.ndarray]
    uv_px: np.ndarray
    identified: np.ndarray
    subject: str | None = None
    timing: str = ""


def _track_labelled(folder, *, calibration, markerset, marker_colours, points_csv, trc, status_csv, angles_csv,
                    c3d, mot=None, bvh=None, detections=None, colours=None, adapt_colours=False,
                    progress=False, sync="auto") -> str:
    run = track_frames_of(folder, calibration=calibration, markerset=markerset, marker_colours=marker_colours,
                          colours=colours, adapt_colours=adapt_colours, progress=progress, sync=sync)
    write_results(run, trc=trc, status_csv=status_csv, angles_csv=angles_csv, c3d=c3d, mot=mot, bvh=bvh,
                  detections=detections)
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


def write_results(run: TrackedRecording, *, trc=None, status_csv=None, angles_csv=None, c3d=None, mot=None,
                  bvh=None, detections=None) -> None:
    """Write the asked result files of a tracked recording (docs/FILES.md)."""
    for path in (trc, status_csv, angles_csv, c3d, mot, bvh, detections):
        if path:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
    # each file through a temporary file beside it, renamed when whole: a kill or a failure
    # half-way never leaves half a file under the asked name
    if trc:
        with written_via_temp(trc) as tmp:
            # Frame# from 1 as OpenSim numbers frames: the first image (index 0) is frame 1
            trc_format.write_trc(tmp, run.names, run.positions_mm, run.rate_hz, frame_numbers=run.frames + 1,
                                 times_s=run.times_s)
    if status_csv:
        with written_via_temp(status_csv) as tmp:
            tables_format.write_status_csv(tmp, run.frames, run.times_s, run.names, run.positions_mm, run.status)
    if angles_csv:
        # the tracker's angles: those of the positions (as `rehab angles` on the TRC gives), but
        # without a supination whose elbow axis is a guess
        with written_via_temp(angles_csv) as tmp:
            tables_format.write_angles_csv(tmp, run.frames, run.times_s, run.angles_deg)
    if c3d:
        with written_via_temp(c3d) as tmp:
            _write_c3d(tmp, run)
    if mot:
        with written_via_temp(mot) as tmp:
            mot_format.write_mot(tmp, run.times_s, run.angles_deg, name=Path(mot).stem)
    if bvh:
        # segment lengths from the measured positions only (an estimate must not teach them)
        measured_mm = np.where((run.status == MarkerStatus.MEASURED)[..., None], run.positions_mm, np.nan)
        with written_via_temp(bvh) as tmp:
            skeleton = bvh_format.BvhSkeleton.from_markers(run.names, measured_mm)
            bvh_format.write_bvh(tmp, run.times_s, run.angles_deg, run.rate_hz, skeleton)
    if detections:
        with written_via_temp(detections) as tmp:
            detections_format.write_detections_csv(tmp, run.frames, run.times_s, [c.name for c in run.cameras],
                                                   run.names, run.uv_px)


def _write_c3d(path, run: TrackedRecording) -> None:
    residuals = detections_format.reprojection_residuals_mm(run.cameras, run.positions_mm / 1000.0, run.uv_px)
    events = [c3d_format.C3dEvent("Identified", float(t - run.times_s[0]), "General",
                                  "markers identified in the reference pose; tracking starts")
              for t in run.times_s[run.identified]]
    c3d_format.write_c3d(path, run.names, run.positions_mm, run.rate_hz, residuals=residuals, status=run.status,
                         camera_masks=detections_format.seen_by(run.uv_px), angles_deg=run.angles_deg,
                         subject=run.subject, markerset=run.markerset, events=events)
