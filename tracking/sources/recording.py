"""A recording folder (docs/INTERFACES.md) as a frame source, and what it says about itself: its
marker set (meta.yaml) and its images' instants (timestamps.csv)."""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path
from typing import Sequence

import numpy as np

from calibration.camera import Camera
from tracking.errors import RecordingError
from tracking.markerset import MarkerSet, load_markerset, parse_rgb
from tracking.io.recording import Recording, read_meta, read_timestamps
from tracking.sources.base import FrameSet, InOrderSource, SourceError, one_size

log = logging.getLogger(__name__)

#: The words of a recording's normal end (all cameras to the end meta.yaml gives): no problem.
NORMAL_END = "ended after"


def is_normal_end(line: str) -> bool:
    """``line`` (a source's warning line) says only that a recording ended normally."""
    return line.startswith("the recording ") and f" {NORMAL_END} " in line and "; " not in line


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



SYNC_MODES = ("auto", "stamps", "none")


def check_skews(path: Path, times: np.ndarray, skew: np.ndarray, fps: float, names=None) -> None:
    """Stamps the tracker can use: frame-set instants that increase, and every image within one
    frame period of its set's instant. A set joins each camera's image nearest its instant, so an
    image stamped further away belongs to another set (or the stamps are wrong): bringing it to
    this set's instant would extrapolate the motion over the gap. One-line :class:`RecordingError`."""
    fix = "fix it, or track with --sync none (the cameras taken as synchronized)"
    back = np.flatnonzero(np.diff(times) <= 0)
    if back.size:
        raise RecordingError(f"{path} line {int(back[0]) + 3}: the frame sets' times must increase: {fix}")
    far = np.abs(np.nan_to_num(skew)) > 1.0 / fps
    if far.any():
        f, c = (int(v) for v in np.argwhere(far)[0])
        name = names[c] if names is not None else f"camera {c + 1}"
        raise RecordingError(f"{path} line {f + 2}: {name}'s image is {1000 * skew[f, c]:+.1f} ms from its "
                             f"frame set's instant, more than one frame period ({1000 / fps:.1f} ms): {fix}")


def image_skews(rec: Recording, sync: str = "auto") -> tuple[np.ndarray | None, str]:
    """Each image's instant minus its frame set's, from the recording's ``timestamps.csv``.

    ``sync``: "auto" and "stamps" use the file ("stamps" requires it), "none" takes the cameras as
    synchronized. Returns (F, C) seconds (NaN unknown) or None, and one line saying what is used."""
    if sync not in SYNC_MODES:
        raise RecordingError(f"--sync {sync!r}: give one of {', '.join(SYNC_MODES)}")
    rolling = [c.name for c in rec.cameras if c.rolling_shutter_s > 0]
    shutter = (f"rolling shutter of {', '.join(rolling)} from the calibration ("
               f"{1000 * max(c.rolling_shutter_s for c in rec.cameras):g} ms readout)") if rolling else ""
    read = None if sync == "none" else read_timestamps(rec.folder, [c.name for c in rec.cameras])
    if read is None:
        if sync == "stamps":
            raise RecordingError(f"{rec.folder}: no timestamps.csv for --sync stamps: give a recording from "
                                 f"'rehab record', or --sync none")
        what = "cameras taken as synchronized (--sync none)" if sync == "none" else ""
        return None, "; ".join(x for x in (what, shutter) if x)
    times, stamps = read
    skew = stamps - times[:, None]
    check_skews(rec.folder / "timestamps.csv", times, skew, rec.fps, [c.name for c in rec.cameras])
    worst = float(np.nanmax(np.abs(skew))) if np.isfinite(skew).any() else 0.0
    line = f"image time stamps from timestamps.csv (up to {1000 * worst:.1f} ms from their frame sets' instants)"
    if len(times) < (rec.n_frames or 0):
        line += f"; only {len(times)} of {rec.n_frames} frame sets stamped"
    return skew, "; ".join(x for x in (line, shutter) if x)


def geometry(config) -> tuple[tuple[Camera, ...], MarkerSet]:
    """A recording's cameras and marker set (its calibration and meta.yaml) without reading images."""
    config.check()
    with RecordingSource(config.path, config.calibration) as rec:
        return rec.cameras, rec.markerset


def calibration_file(config) -> Path | None:
    """The recording's calibration (``calibration`` given, else the folder's calibration.toml)."""
    if not config.path:
        return None
    return Path(config.calibration) if config.calibration else Path(config.path) / "calibration.toml"


def resolve(config):
    """``config`` with the recording's image size and frame rate (meta.yaml), and no motion."""
    cameras, _ = geometry(config)
    return replace(config, size=one_size(cameras), fps=read_meta(Path(config.path)).fps, motion=None)


def from_config(config) -> "RecordingSource":
    """The recording of a live source configuration (played once; a camera that ends early is a warning)."""
    return RecordingSource(config.path, config.calibration)


class RecordingSource(InOrderSource):
    """Reads a recording folder frame set by frame set (videos or numbered image folders).

    The recording is checked when the source is made (calibration, one video or image folder per
    camera, frame sizes, meta.yaml, marker set). A camera whose video ends before the others
    gives black images from then on: tracking goes on with the other cameras, and
    :meth:`warnings` says which camera ended where. The source ends with its longest camera
    (:meth:`read` returns None, :meth:`end_reason` says why); ended before meta.yaml's
    ``n_frames``, it is cut short (a warning). With ``strict`` a short camera or a cut-short
    recording raises :class:`SourceError` instead (offline tools, where a recording that is cut
    short is an error the user must see).

    Each image's time stamp is its frame set's instant plus its skew from ``timestamps.csv``
    (:func:`image_skews`; :meth:`use_skews` replaces them, e.g. with estimated clock offsets).

    Args:
        folder: the recording folder.
        calibration: calibration file (default: ``folder/calibration.toml``).
        markerset: marker set name or file (default: meta.yaml's); marker_colours: its colours
            (default: meta.yaml's), see :func:`markerset_for`.
        sync: how the images' instants are found (:data:`SYNC_MODES`).
        strict: raise when a camera ends before the others (or all before meta.yaml's ``n_frames``).
    """

    def __init__(self, folder: str | Path, calibration: str | Path | None = None, *, markerset: str | None = None,
                 marker_colours: Sequence[str] | None = None, sync: str = "auto", strict: bool = False) -> None:
        super().__init__()
        self.folder = Path(folder)
        self.strict = strict
        self._rec: Recording | None = Recording(self.folder, calibration)
        try:
            self.markerset = markerset_for(self._rec, markerset, marker_colours)
            self.skews, self.timing = image_skews(self._rec, sync)
        except Exception:
            self.close()
            raise
        self.cameras = self._rec.cameras
        self.calibration_path = self._rec.calibration_path
        self.fps = self._rec.fps
        self.meta = self._rec.meta
        self.n_frames = self._rec.n_frames
        self._index = 0
        self._end = ""
        self._short_camera = ""   # the line saying which camera ended before the others

    def use_skews(self, skews: np.ndarray | None, timing: str) -> None:
        """Stamp the images with ``skews`` ((F, C) seconds from their sets' instants, NaN unknown;
        None: synchronized) from now on, ``timing`` saying where they come from."""
        self.skews, self.timing = skews, timing

    def open(self) -> None:
        if self._rec is None:
            raise SourceError(f"{self.folder}: the recording source was closed; make a new one")

    def read_next(self) -> FrameSet | None:
        self.open()
        if self._end:
            return None
        images = self._rec.read_images()
        ended = np.array([img is None for img in images])
        if ended.all():
            if not self._short():  # the normal end
                self._end = f"the recording {self.folder} {NORMAL_END} {self._index} frame sets"
                log.info("%s", self._end)
                return None
            self._end = self._ending(ended)
            log.warning("%s", self._end)
            if self.strict:
                raise SourceError(self._end)
            return None
        if ended.any():   # one camera ended before the others: tracking goes on with them, said once
            images, line = self._rec.go_on_without_ended(images, self._index)
            if line:
                if self.strict:
                    raise SourceError(f"{line}: the recording in {self.folder} is cut short; record it again or "
                                      "trim the other videos")
                self._short_camera = line
                log.warning("%s", line)
        t = self._index / self.fps
        stamps = np.full(len(images), t)
        if self.skews is not None and self._index < len(self.skews):
            stamps += np.nan_to_num(self.skews[self._index])
        fs = FrameSet(self._index, t, tuple(images), stamps, np.zeros(len(images), bool))
        self._index += 1
        return fs

    def _short(self) -> bool:
        expected = self.meta.n_frames
        return expected is not None and self._index < expected

    def _ending(self, ended: np.ndarray) -> str:
        names = [n for n, e in zip(self._rec.file_names, ended) if e]
        return (f"{', '.join(names)} ended at frame {self._index} but meta.yaml says {self.meta.n_frames} "
                f"frames: the recording in {self.folder} is cut short; record it again or fix n_frames")

    def skip(self, n: int) -> int:
        """Drop the next ``n`` frame sets (a restarted live process resumes where it was); returns
        how many were skipped before the end."""
        done = 0
        while done < n and self.read_next() is not None:
            done += 1
        return done

    def warnings(self) -> tuple[str, ...]:
        """A camera that ended before the others, a recording cut short (a normal end is no problem)."""
        out = (self._short_camera,) if self._short_camera else ()
        return out + ((self._end,) if self._end and "cut short" in self._end else ())

    def end_reason(self) -> str:
        return self._end

    def close(self) -> None:
        if self._rec is not None:
            self._rec.close()
            self._rec = None

    def __enter__(self) -> "RecordingSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
