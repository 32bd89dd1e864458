"""Saving a frame source as a recording folder (docs/INTERFACES.md), for offline re-tracking."""

from __future__ import annotations

import csv
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from tracking.errors import RecordingError
from tracking.markerset import MarkerSet
from tracking.io.recording import RecordingWriter
from tracking.sources.base import FrameSource
from tracking.io.trc import write_trc

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class RecordSummary:
    """What :func:`record` wrote.

    Attributes:
        folder: the recording folder.
        n_frames: frame sets written.
        missing: (C,) int64 frame sets in which each camera's image was missing (written black).
        stopped_early: why recording stopped before ``n_frames`` ("" if it did not).
    """

    folder: Path
    n_frames: int
    camera_names: tuple[str, ...]
    size_px: tuple[int, int]
    fps: float
    missing: np.ndarray
    stopped_early: str = ""

    def line(self) -> str:
        w, h = self.size_px
        text = (f"wrote {self.n_frames} frame sets from {len(self.camera_names)} cameras ({w}x{h}, "
                f"{self.fps:g} fps) to {self.folder}")
        gaps = [f"{name} in {n}" for name, n in zip(self.camera_names, self.missing) if n]
        if gaps:
            text += f"; images missing (written black): {', '.join(gaps)} frame sets"
        if self.stopped_early:
            text += f"; stopped early: {self.stopped_early}"
        return text


def check_new_folder(folder: Path) -> None:
    """Raise :class:`RecordingError` unless ``folder`` is new or empty (never overwrite a recording)."""
    if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise RecordingError(f"{folder} exists and is not empty: give a new folder (a recording is never overwritten)")


def record(source: FrameSource, folder: str | Path, n_frames: int, markerset: MarkerSet, *, images: bool = False,
           progress: bool = False, meta: dict | None = None) -> RecordSummary:
    """Write ``n_frames`` frame sets of ``source`` (fewer if it ends or on Ctrl-C) as a recording folder.

    Besides the files of docs/INTERFACES.md (calibration.toml, one video or image folder per
    camera, meta.yaml) it writes ``timestamps.csv`` (``frame,time,<cam1>,<cam2>...``: each
    camera's time stamp in seconds, empty where its image was missing) and, for a simulated
    source, ``truth.trc``. A missing image is written black, so every camera keeps the same
    frame numbering.

    Args:
        source: the frame source (opened here, not closed).
        folder: a new or empty folder.
        n_frames: frame sets to write.
        markerset: the marker set worn (its name and colours go to meta.yaml).
        images: numbered PNG folders instead of lossless FFV1 videos.
        progress: show a progress bar.
        meta: more meta.yaml entries (how the recording was made).
    """
    folder = Path(folder)
    check_new_folder(folder)
    source.open()
    cams = source.cameras
    writer = RecordingWriter(folder, cams, source.fps, images=images)
    missing = np.zeros(len(cams), np.int64)
    truth, stopped = [], ""
    with open(folder / "timestamps.csv", "w", newline="", encoding="utf-8") as fh:
        table = csv.writer(fh)
        table.writerow(["frame", "time", *(c.name for c in cams)])
        bar = tqdm(total=n_frames, unit="frame", desc="recording", disable=not progress)
        try:
            while writer.n_frames < n_frames:
                fs = source.read()
                if fs is None:
                    stopped = source.end_reason() or "the source ended"
                    break
                k = writer.n_frames
                writer.write(fs.images)
                missing += fs.missing
                table.writerow([k, f"{fs.time_s:.6f}", *("" if m else f"{t:.6f}" for t, m in zip(fs.stamps_s, fs.missing))])
                if fs.truth_m is not None:
                    truth.append(fs.truth_m)
                bar.update()
        except KeyboardInterrupt:
            stopped = "interrupted (Ctrl-C)"
        finally:
            bar.close()
            writer.close()
    writer.write_meta(markerset.name, markerset.rgb, cameras=[c.name for c in cams],
                      missing_images={c.name: int(n) for c, n in zip(cams, missing)}, **(meta or {}))
    if truth and len(truth) == writer.n_frames:
        write_trc(folder / "truth.trc", markerset.names, np.stack(truth) * 1000.0, source.fps)
    if stopped:
        log.warning("recording stopped after %d frame sets: %s", writer.n_frames, stopped)
    if writer.n_frames == 0:
        raise RecordingError(f"no frame set was recorded to {folder}: {stopped or 'the source delivered none'}")
    w, h = cams[0].size_px
    return RecordSummary(folder, writer.n_frames, tuple(c.name for c in cams), (int(w), int(h)), source.fps,
                         missing, stopped)
