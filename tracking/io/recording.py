"""Recording folders (docs/INTERFACES.md): reading them frame by frame, and writing them.

```
recording/
  calibration.toml          cameras, in order
  cam1.avi cam2.avi ...     one video per camera (any codec OpenCV reads), or
  cam1/ cam2/ ...           one folder of numbered images per camera (000000.png, ...)
  truth.trc                 simulator only: ground-truth marker positions
  truth_angles.csv          simulator only: ground-truth joint angles
  meta.yaml                 frame rate, marker set, marker colours, how it was made
```
"""

from __future__ import annotations

import csv
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Sequence

import cv2
import numpy as np
import yaml

from calibration.camera import Camera
from calibration.errors import CalibrationError, utf8_text
from calibration.files import check_camera_count, check_frame_sizes, load_calibration, save_calibration_toml
from tracking.errors import RecordingError

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
VIDEO_SUFFIXES = (".avi", ".mp4", ".mkv", ".mov")


@dataclass(frozen=True, slots=True)
class FrameSet:
    """Synchronized images of all cameras at one instant.

    Attributes:
        index: frame number from 0.
        time_s: time stamp in seconds from the start of the recording.
        images: one (H, W, 3) uint8 BGR image per camera, in calibration order.
    """

    index: int
    time_s: float
    images: tuple[np.ndarray, ...]


@dataclass(frozen=True, slots=True)
class RecordingMeta:
    """The parsed meta.yaml (unknown keys are kept in ``extra``)."""

    fps: float
    markerset: str = "upper_limb_seated"
    marker_colours: tuple[tuple[int, int, int], ...] | None = None
    n_frames: int | None = None
    extra: dict = field(default_factory=dict)


def read_meta(folder: Path) -> RecordingMeta:
    """Read and check a recording's meta.yaml (every value is checked here, once)."""
    path = folder / "meta.yaml"
    if not path.is_file():
        raise RecordingError(f"{path} not found: a recording folder needs meta.yaml with at least 'fps: 30'")
    try:
        data = yaml.safe_load(utf8_text(path, path.read_bytes(), RecordingError)) or {}
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read ({exc.strerror})") from None
    except RecursionError:
        raise RecordingError(f"{path}: nested too deeply; fix the file") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        raise RecordingError(f"{path}:{where}: invalid YAML ({getattr(exc, 'problem', None) or 'syntax'}); fix the "
                             f"file") from None
    if not isinstance(data, dict):
        raise RecordingError(f"{path}: expected keys such as 'fps: 30'")
    fps = data.get("fps")
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not 0 < fps <= 10_000:
        raise RecordingError(f"{path}: 'fps' must be a positive number of frames per second (got {fps!r})")
    n_frames = data.get("n_frames")
    if n_frames is not None and (isinstance(n_frames, bool) or not isinstance(n_frames, int) or n_frames < 0):
        raise RecordingError(f"{path}: 'n_frames' must be a whole number of frames (got {n_frames!r})")
    markerset = data.get("markerset", "upper_limb_seated")
    if not isinstance(markerset, str) or not markerset.strip():
        raise RecordingError(f"{path}: 'markerset' must be a marker set name such as upper_limb_seated")
    known = {"fps", "markerset", "marker_colours", "n_frames"}
    return RecordingMeta(
        fps=float(fps),
        markerset=markerset,
        marker_colours=_meta_colours(path, data.get("marker_colours")),
        n_frames=n_frames,
        extra={k: v for k, v in data.items() if k not in known},
    )


def _meta_colours(path: Path, colours) -> tuple[tuple[int, int, int], ...] | None:
    """meta.yaml's ``marker_colours``: a list of [R, G, B] of whole numbers 0-255 (or none)."""
    if colours is None or colours == []:
        return None
    ok = isinstance(colours, list) and all(
        isinstance(c, list) and len(c) == 3 and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 255
                                                    for v in c) for c in colours)
    if not ok:
        raise RecordingError(f"{path}: 'marker_colours' must be a list of [R, G, B] colours of whole numbers "
                             f"0-255, one per marker")
    return tuple(tuple(c) for c in colours)


def frame_rate_from_files(folder: Path) -> float | None:
    """The frame rate of a recording folder without meta.yaml: its first video's own (the
    container's), else the median interval between the modification times of a camera folder's
    images (cameras that save frame by frame), or None when neither gives 1-1000 frames/s."""
    for p in sorted(folder.iterdir()):
        if p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES:
            cap = cv2.VideoCapture(str(p))
            fps = float(cap.get(cv2.CAP_PROP_FPS)) if cap.isOpened() else 0.0
            cap.release()
            if 1.0 <= fps <= 1000.0:
                return fps
    for p in sorted(folder.iterdir()):
        if p.is_dir():
            times = np.sort([f.stat().st_mtime for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES])
            if times.size >= 3:
                dt = float(np.median(np.diff(times)))
                if 1e-3 <= dt <= 1.0:
                    return 1.0 / dt
    return None


class _VideoReader:
    def __init__(self, path: Path):
        self.path = path
        self.cap = cv2.VideoCapture(str(path))
        if not self.cap.isOpened():
            raise RecordingError(f"{path}: OpenCV cannot open this video; re-encode it (e.g. MJPG or FFV1 AVI)")
        self.size = (int(self.cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self.cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        n = int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.n_frames = n if n > 0 else None

    def read(self) -> np.ndarray | None:
        ok, frame = self.cap.read()
        return frame if ok else None

    def close(self) -> None:
        self.cap.release()


class _ImageFolderReader:
    def __init__(self, path: Path):
        self.path = path
        self.files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not self.files:
            raise RecordingError(f"{path}: no images (.png/.jpg) in this camera folder")
        first = self._load(self.files[0])
        self.size = (first.shape[1], first.shape[0])
        self.n_frames = len(self.files)
        self._next = 0

    def _load(self, file: Path) -> np.ndarray:
        img = cv2.imread(str(file), cv2.IMREAD_COLOR)
        if img is None:
            raise RecordingError(f"{file}: unreadable image; replace or delete it")
        return img

    def read(self) -> np.ndarray | None:
        if self._next >= len(self.files):
            return None
        file = self.files[self._next]
        img = self._load(file)
        self._next += 1
        if (img.shape[1], img.shape[0]) != self.size:
            raise RecordingError(f"{file}: {img.shape[1]}x{img.shape[0]} pixels but the other images of "
                                 f"{self.path.name} are {self.size[0]}x{self.size[1]}: replace or delete it")
        return img

    def close(self) -> None:
        pass


def _camera_source(folder: Path, name: str):
    for suffix in VIDEO_SUFFIXES:
        if (folder / f"{name}{suffix}").is_file():
            return _VideoReader(folder / f"{name}{suffix}")
    if (folder / name).is_dir():
        return _ImageFolderReader(folder / name)
    return None


class Recording:
    """A recording folder opened for reading. Iterate it for :class:`FrameSet` objects.

    The calibration decides how many cameras there are and their names; each camera's images come
    from ``<name>.avi`` (or .mp4/.mkv/.mov) or a folder ``<name>/`` of numbered images. A frame
    size that differs from the calibration, or a camera without images, is an error. If one camera
    ends before the others, reading stops there with a warning (nothing read so far is lost).
    """

    def __init__(self, folder: str | Path, calibration: str | Path | None = None, *, meta_optional: bool = False):
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise RecordingError(f"{self.folder}: no such recording folder")
        if meta_optional and not (self.folder / "meta.yaml").is_file():  # e.g. a wand, whose solver needs no time
            fps = frame_rate_from_files(self.folder)
            if fps is None:
                raise RecordingError(f"{self.folder}: no meta.yaml and no frame rate in its videos or image times: "
                                     "add meta.yaml with 'fps: 30'")
            self.meta = RecordingMeta(fps=fps)
        else:
            self.meta = read_meta(self.folder)
        calib_path = Path(calibration) if calibration else self.folder / "calibration.toml"
        self.calibration_path = calib_path
        self.cameras: tuple[Camera, ...] = tuple(load_calibration(calib_path))
        found = sorted(
            p.stem if p.is_file() else p.name
            for p in self.folder.iterdir()
            if (p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES) or (p.is_dir() and p.name.startswith("cam"))
        )
        readers = [_camera_source(self.folder, c.name) for c in self.cameras]
        n_sources = sum(r is not None for r in readers)
        used = {r.path.stem if r.path.is_file() else r.path.name for r in readers if r is not None}
        unused = [name for name in found if name not in used]
        if n_sources == len(self.cameras) and unused:
            for r in readers:
                r.close()
            # a calibration of 3 cameras with a recording of 4 would silently drop a quarter of the views
            raise RecordingError(
                f"{calib_path.name} has {len(self.cameras)} cameras ({', '.join(c.name for c in self.cameras)}) but "
                f"the recording {self.folder} also has {', '.join(unused)}: give the calibration of all "
                f"{len(found)} cameras with --calibration FILE, or move the extra videos out of the folder")
        if n_sources != len(self.cameras):
            for r in readers:
                if r is not None:
                    r.close()
            missing = [c.name for c, r in zip(self.cameras, readers) if r is None]
            check_camera_count(self.cameras, len(found), f"the recording {self.folder}")
            raise RecordingError(
                f"{self.folder}: no video or image folder for {', '.join(missing)} "
                f"(found {', '.join(found) or 'none'}); name them after the cameras in the calibration"
            )
        self._readers = readers
        try:
            check_frame_sizes(self.cameras, [r.size for r in readers], [r.path.name for r in readers])
        except CalibrationError:
            self.close()
            raise
        counts = [r.n_frames for r in readers if r.n_frames is not None]
        self.n_frames = max(counts) if counts else self.meta.n_frames
        self._ended: set[int] = set()   # cameras whose video or folder ended while others go on
        if counts and max(counts) != min(counts):
            log.info("cameras have different frame counts %s; the longest are tracked to their end", counts)

    @property
    def fps(self) -> float:
        return self.meta.fps

    @property
    def file_names(self) -> tuple[str, ...]:
        """The video or image-folder name of each camera, calibration order (``"cam2.avi"``)."""
        return tuple(r.path.name for r in self._readers)

    def read_images(self) -> list[np.ndarray | None]:
        """The next image of every camera, calibration order; None where its video or folder ended."""
        return [r.read() for r in self._readers]

    def go_on_without_ended(self, images: list[np.ndarray | None], index: int) -> tuple[list[np.ndarray], str]:
        """``images`` (from :meth:`read_images`) with a black image for each camera whose video or
        folder has ended while others go on, so that tracking goes on with the others; and the
        line saying so when a camera has just ended ("" otherwise). Raises nothing: call it only
        when some camera still delivers."""
        ended_now = [k for k, img in enumerate(images) if img is None and k not in self._ended]
        self._ended.update(ended_now)
        line = ""
        if ended_now:
            left = [r.path.name for k, r in enumerate(self._readers) if k not in self._ended]
            line = (f"{', '.join(self._readers[k].path.name for k in ended_now)} ended at frame {index} while the "
                    f"other cameras go on: tracking goes on with {', '.join(left)}")
        out = [img if img is not None else np.zeros((r.size[1], r.size[0], 3), np.uint8)
               for r, img in zip(self._readers, images)]
        return out, line

    @property
    def ended_cameras(self) -> tuple[str, ...]:
        """The video or folder names of the cameras that ended before the others."""
        return tuple(self._readers[k].path.name for k in sorted(self._ended))

    def __iter__(self) -> Iterator[FrameSet]:
        """Every frame set; a camera that ends before the others gives black images from then on
        (said once, as a warning), the recording ends with its longest camera."""
        index = 0
        while True:
            images = self.read_images()
            if all(img is None for img in images):
                return
            if any(img is None for img in images):
                images, line = self.go_on_without_ended(images, index)
                if line:
                    log.warning("%s", line)
            yield FrameSet(index, index / self.meta.fps, tuple(images))
            index += 1

    def close(self) -> None:
        for r in self._readers:
            r.close()

    def __enter__(self) -> "Recording":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class RecordingWriter:
    """Writes a recording folder: calibration, one lossless video (or image folder) per camera, meta.

    Args:
        folder: output folder (created).
        cameras: the cameras, in order; their names name the files.
        fps: frame rate.
        images: write numbered PNG folders instead of FFV1 AVI videos.
    """

    def __init__(self, folder: str | Path, cameras: Sequence[Camera], fps: float, *, images: bool = False):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.cameras = tuple(cameras)
        self.fps = float(fps)
        self.images = images
        self.n_frames = 0
        save_calibration_toml(self.folder / "calibration.toml", self.cameras)
        self._writers = []
        if not images:
            fourcc = cv2.VideoWriter_fourcc(*"FFV1")
            for cam in self.cameras:
                w = cv2.VideoWriter(str(self.folder / f"{cam.name}.avi"), fourcc, self.fps, tuple(cam.size_px))
                if not w.isOpened():
                    raise RecordingError(
                        f"cannot write {cam.name}.avi with the FFV1 codec here; use image folders instead (--images)"
                    )
                self._writers.append(w)
        else:
            for cam in self.cameras:
                (self.folder / cam.name).mkdir(exist_ok=True)

    def write(self, images: Sequence[np.ndarray]) -> None:
        """Append one frame set: one (H, W, 3) uint8 BGR image per camera."""
        for k, (cam, img) in enumerate(zip(self.cameras, images)):
            if self.images:
                cv2.imwrite(str(self.folder / cam.name / f"{self.n_frames:06d}.png"), img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
            else:
                self._writers[k].write(img)
        self.n_frames += 1

    def write_meta(self, markerset: str, marker_colours: np.ndarray, **extra) -> None:
        meta = {
            "fps": self.fps,
            "n_frames": self.n_frames,
            "markerset": markerset,
            "marker_colours": [list(map(int, c)) for c in np.asarray(marker_colours)],
            **extra,
        }
        (self.folder / "meta.yaml").write_text(yaml.safe_dump(meta, sort_keys=False), encoding="utf-8")

    def close(self) -> None:
        for w in self._writers:
            w.release()
        self._writers = []


TIMESTAMPS_FILE = "timestamps.csv"


def write_timestamps(path: Path, camera_names: Sequence[str], times_s: np.ndarray, stamps_s: np.ndarray) -> None:
    """``frame,time,<cam1>,<cam2>...``: each frame set's instant and each camera's image instant,
    seconds (the format ``rehab record`` writes; NaN is written empty: a missing image)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        table = csv.writer(fh)
        table.writerow(["frame", "time", *camera_names])
        for k, (t, row) in enumerate(zip(times_s, stamps_s)):
            table.writerow([k, f"{t:.6f}", *("" if not np.isfinite(v) else f"{v:.6f}" for v in row)])


def read_timestamps(folder: Path, camera_names: Sequence[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """A recording's ``timestamps.csv``: (F,) frame-set instants and (F, C) image instants of the
    cameras ``camera_names`` (NaN where empty), seconds; None without the file. A file that does
    not fit (other cameras, text for numbers, frames out of order) is a one-line
    :class:`RecordingError`."""
    path = Path(folder) / TIMESTAMPS_FILE
    if not path.is_file():
        return None
    try:
        rows = list(csv.reader(utf8_text(path, path.read_bytes(), RecordingError).splitlines()))
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read ({exc.strerror})") from None
    fix = "fix it or move it out of the folder (then the cameras are taken as synchronized)"
    if not rows or rows[0][:2] != ["frame", "time"]:
        raise RecordingError(f"{path}: the first line must be frame,time,<camera names>: {fix}")
    header = rows[0][2:]
    missing = [n for n in camera_names if n not in header]
    if missing:
        raise RecordingError(f"{path} has no column for {', '.join(missing)}: {fix}")
    cols = [2 + header.index(n) for n in camera_names]
    times, stamps = [], []
    for line, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        try:
            if int(row[0]) != len(times) or len(row) != len(header) + 2:
                raise ValueError
            t = float(row[1])
            s = [float(row[c]) if row[c].strip() else np.nan for c in cols]
        except ValueError:
            raise RecordingError(f"{path} line {line}: expected frame {len(times)}, its time and one time per "
                                 f"camera in seconds: {fix}") from None
        if not np.isfinite(t) or np.isinf(s).any():
            raise RecordingError(f"{path} line {line}: times must be finite numbers of seconds: {fix}")
        times.append(t)
        stamps.append(s)
    return np.asarray(times, dtype=np.float64), np.asarray(stamps, dtype=np.float64).reshape(-1, len(camera_names))
