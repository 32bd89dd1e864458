"""A recording folder (spec/INTERFACES.md) as a frame source."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from tracking.markerset import MarkerSet
from tracking.recording import Recording
from tracking.sources.base import SourceError, SourceFrameSet

log = logging.getLogger(__name__)


class RecordingSource:
    """Reads a recording folder frame set by frame set (videos or numbered image folders).

    The recording is checked when the source is made (calibration, one video or image folder per
    camera, frame sizes, meta.yaml). A camera whose video ends before the others ends the source:
    :meth:`read` returns None and :meth:`end_reason` names the file and the frame; with
    ``strict`` it raises :class:`SourceError` instead (offline tools, where a recording that is
    cut short is an error the user must see).

    Args:
        folder: the recording folder.
        calibration: calibration file (default: ``folder/calibration.toml``).
        strict: raise when a camera ends before the others (or before meta.yaml's ``n_frames``).
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
        from tracking.offline import image_skews

        # each image's instant from timestamps.csv when the recording has one, as rehab track
        self._skews, self.timing = image_skews(self._rec)
        self._index = 0
        self._end = ""

    def markerset(self, name: str | None = None) -> MarkerSet:
        """The recording's marker set (meta.yaml's, or ``name``) with meta.yaml's marker colours."""
        from tracking.offline import markerset_for

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
        if ended.any():
            if ended.all() and not self._short():  # the normal end
                self._end = f"the recording {self.folder} ended after {self._index} frame sets"
                log.info("%s", self._end)
                return None
            self._end = self._ending(ended)
            log.warning("%s", self._end)
            if self.strict:
                raise SourceError(self._end)
            return None
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
        if ended.all():
            return (f"{', '.join(names)} ended at frame {self._index} but meta.yaml says {self.meta.n_frames} "
                    f"frames: the recording in {self.folder} is cut short; record it again or fix n_frames")
        return (f"{', '.join(names)} ended at frame {self._index} while the other cameras go on: "
                f"the recording in {self.folder} is cut short; record it again or trim the other videos")

    def skip(self, n: int) -> int:
        """Drop the next ``n`` frame sets (a restarted live process resumes where it was); returns
        how many were skipped before the end."""
        done = 0
        while done < n and self.read() is not None:
            done += 1
        return done

    def warnings(self) -> tuple[str, ...]:
        return (self._end,) if self._end and "cut short" in self._end else ()  # a normal end is no problem

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

