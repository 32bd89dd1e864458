"""A recording folder (docs/INTERFACES.md) as a frame source."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from tracking.markerset import MarkerSet
from tracking.io.recording import Recording
from tracking.sources.base import SourceError, SourceFrameSet

log = logging.getLogger(__name__)

#: The words of a recording's normal end (all cameras to the end meta.yaml gives): no problem.
NORMAL_END = "ended after"


def is_normal_end(line: str) -> bool:
    """``line`` (a source's warning line) says only that a recording ended normally."""
    return line.startswith("the recording ") and f" {NORMAL_END} " in line and "; " not in line


class RecordingSource:
    """Reads a recording folder frame set by frame set (videos or numbered image folders).

    The recording is checked when the source is made (calibration, one video or image folder per
    camera, frame sizes, meta.yaml). A camera whose video ends before the others gives black
    images from then on: tracking goes on with the other cameras, and :meth:`warnings` says which
    camera ended where. The source ends with its longest camera (:meth:`read` returns None,
    :meth:`end_reason` says why); ended before meta.yaml's ``n_frames``, it is cut short (a
    warning). With ``strict`` a short camera or a cut-short recording raises :class:`SourceError`
    instead (offline tools, where a recording that is cut short is an error the user must see).

    Args:
        folder: the recording folder.
        calibration: calibration file (default: ``folder/calibration.toml``).
        strict: raise when a camera ends before the others (or all before meta.yaml's ``n_frames``).
    """

    def __init__(self, folder: str | Path, calibration: str | Path | None = None, *, strict: bool = False) -> None:
        self.folder = Path(folder)
        self._calibration = calibration
        self.strict = strict
        self._rec: Recording | None = Recording(self.folder, calibration)
        self.cameras = self._rec.cameras
        self.fps = self._rec.fps
        self.meta = self._rec.meta
        self.n_frames = self._rec.n_frames
        from tracking.drivers.offline import image_skews

        # each image's instant from timestamps.csv when the recording has one, as rehab track
        self._skews, self.timing = image_skews(self._rec)
        self._index = 0
        self._end = ""
        self._short_camera = ""   # the line saying which camera ended before the others

    def markerset(self, name: str | None = None) -> MarkerSet:
        """The recording's marker set (meta.yaml's, or ``name``) with meta.yaml's marker colours."""
        from tracking.drivers.offline import markerset_for

        return markerset_for(self._rec, name, None)

    def open(self) -> None:
        if self._rec is None:
            raise SourceError(f"{self.folder}: the recording source was closed; make a new one")

    def read(self) -> SourceFrameSet | None:
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
        if self._skews is not None and self._index < len(self._skews):
            stamps += np.nan_to_num(self._skews[self._index])
        fs = SourceFrameSet(self._index, t, tuple(images), stamps, np.zeros(len(images), bool))
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
        while done < n and self.read() is not None:
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

