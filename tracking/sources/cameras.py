"""Live cameras through OpenCV: one reader thread per camera, frame sets grouped by time stamp.

Each camera's thread reads its device as fast as it delivers, stamps every frame with the host
clock the moment ``read()`` returns, and keeps the last few frames. :meth:`CameraSource.read`
waits until every camera that still delivers has a new frame, takes as the set's time the newest
instant all of them have reached (the earliest of their newest stamps), and gives each camera its
frame nearest to that instant:

- a frame more than half a frame period from it is *out of step* (a camera lagging or running at
  another rate): it is left out of the set, and a warning says so;
- frames a camera delivered but the set skipped (the tracker is slower than the cameras), and
  gaps between a camera's own time stamps longer than 1.5 periods (the camera or its driver
  dropped them), count as *dropped* frames, with a warning;
- a camera that delivers nothing for ``stall_s`` (unplugged, crashed driver, end of a video
  file) is *stopped*: its image is missing (black) from every set until it comes back, and a
  warning names it and the cameras tracking goes on with.

Warnings are current conditions, one line each (:meth:`CameraSource.warnings`), and each new
condition is logged once.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections import deque
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import cv2
import numpy as np

from calibration.camera import Camera
from calibration.files import check_camera_count, load_calibration
from tracking.markerset import MarkerSet, load_markerset
from tracking.sources.base import FrameSet, InOrderSource, SourceError, black_image, camera_names, one_size

log = logging.getLogger(__name__)

#: Frames each reader keeps (the set picks the one nearest its time).
KEEP_FRAMES = 4
#: Warnings about dropped or out-of-step frames hold this long after the last occurrence.
WARN_WINDOW_S = 2.0
#: Consecutive failed reads after which a device counts as ended (a video file at its end,
#: an unplugged camera whose driver reports failure instead of blocking).
FAILED_READS_TO_END = 25


#: OpenCV's log level for errors only (its LogLevel enum: SILENT 0, FATAL 1, ERROR 2, WARNING 3).
_OPENCV_LOG_ERROR = 2


@contextmanager
def _opencv_errors_only():
    """OpenCV logs only errors inside the block (``cv2.utils.logging`` from OpenCV 5,
    ``cv2.setLogLevel`` before it)."""
    api = getattr(cv2.utils, "logging", None) or cv2
    level = api.getLogLevel()
    api.setLogLevel(_OPENCV_LOG_ERROR)
    try:
        yield
    finally:
        api.setLogLevel(level)


def is_file_device(device: str) -> bool:
    """A video file or image sequence (``cam1.avi``, ``cam1/%06d.png``), not a device index or URL."""
    return not device.isdigit() and "://" not in device



#: How the pace warnings begin (frames dropped or left out while every camera delivers): the
#: machine or the cameras could not keep up, a weaker measurement but not a failed one. Matched
#: at the start, since a published warning line may be cut at its end.
_PACE = re.compile(r"camera .+? (dropped \d+ frames|is out of step with the others)")


def is_pace_warning(line: str) -> bool:
    """``line`` (one warning of :meth:`CameraSource.warnings`, perhaps cut short) says only that
    frames were dropped or left out of step, not that a camera stopped."""
    return _PACE.match(line) is not None

class PacedCapture:
    """A capture that delivers at most ``fps`` frames per second, as a camera does.

    OpenCV reads a video file or an image sequence as fast as it decodes: given as a camera, it
    would run through the file in a fraction of its length (and on a loaded machine the cameras
    would end before the tracker started). Behind by more than a frame (a slow reader), it catches
    up one frame at a time rather than in a burst.
    """

    def __init__(self, capture, fps: float, *, clock=time.perf_counter, sleep=time.sleep) -> None:
        self.capture = capture
        self.period_s = 1.0 / float(fps)
        self._clock, self._sleep = clock, sleep
        self._due_s: float | None = None

    def read(self):
        now = self._clock()
        if self._due_s is not None and self._due_s > now:
            self._sleep(self._due_s - now)
            now = self._due_s
        self._due_s = max(self._due_s if self._due_s is not None else now, now - self.period_s) + self.period_s
        return self.capture.read()

    def __getattr__(self, name):  # isOpened, set, get, release: the capture's own
        return getattr(self.capture, name)


def open_capture(device: str, size_px: tuple[int, int] | None, fps: float | None):
    """An OpenCV ``VideoCapture`` for a device index (``"0"``), a URL or a video file path (or an
    image sequence, ``cam1/%06d.png``); a file is delivered at ``fps``, as a camera would.

    The size and frame rate are requests; the driver may ignore them (the first frame's size is
    checked against the calibration).
    """
    # OpenCV prints its own warnings when a device is absent; the caller reports it in one line
    with _opencv_errors_only():
        cap = cv2.VideoCapture(int(device) if device.isdigit() else device)
    if cap.isOpened():
        if size_px is not None:
            cap.set(cv2.CAP_PROP_FRAME_WIDTH, float(size_px[0]))
            cap.set(cv2.CAP_PROP_FRAME_HEIGHT, float(size_px[1]))
        if fps is not None:
            cap.set(cv2.CAP_PROP_FPS, float(fps))
            if is_file_device(device):
                return PacedCapture(cap, fps)
    return cap


def calibrated_cameras(config) -> tuple[Camera, ...]:
    """The calibration of a live source configuration, one camera per device (one-line error)."""
    cameras = tuple(load_calibration(config.calibration))
    check_camera_count(cameras, len(config.devices), "the source", kind="camera devices",
                       calibration_name=str(config.calibration))
    return cameras


def geometry(config) -> tuple[tuple[Camera, ...], MarkerSet]:
    """The calibrated cameras and the marker set of a live source configuration (no device opened)."""
    config.check()
    return calibrated_cameras(config), load_markerset(config.markerset)


def calibration_file(config) -> Path | None:
    """The cameras' calibration file."""
    return Path(config.calibration) if config.calibration else None


def resolve(config):
    """``config`` with the calibrated image size, and no motion."""
    config.check()
    return replace(config, size=one_size(calibrated_cameras(config)), motion=None)


def from_config(config) -> "CameraSource":
    """The live cameras of a source configuration, for the live tracker's loop."""
    # a read never blocks the loop longer than half a second (its heartbeat is watched)
    return CameraSource(calibrated_cameras(config), config.devices, config.fps,
                        stall_s=min(max(5.0 / config.fps, 0.25), 0.5), markerset=load_markerset(config.markerset))


@dataclass(slots=True)
class _Frame:
    seq: int
    stamp: float
    image: np.ndarray


class _Reader:
    """One camera's reader thread and its latest frames (guarded by the source's condition)."""

    def __init__(self, name: str, device: str, capture, cond: threading.Condition, clock: Callable[[], float],
                 period_s: float) -> None:
        self.name = name
        self.device = device
        self.capture = capture
        self.cond = cond
        self.clock = clock
        self.period_s = period_s
        self.frames: deque[_Frame] = deque(maxlen=KEEP_FRAMES)
        self.seq = -1  # newest frame's number
        self.ended = ""  # why the device stopped for good ("" while it runs)
        self.gap_drops: deque[tuple[float, int]] = deque()  # (stamp, frames) missing between stamps
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, name=f"camera-{name}", daemon=True)

    def _run(self) -> None:
        failures = 0
        while not self.stop.is_set():
            try:
                ok, image = self.capture.read()
            except Exception as exc:  # a driver error ends this camera, not the source
                self._end(f"the driver failed: {type(exc).__name__}: {exc}")
                return
            stamp = self.clock()
            if not ok or image is None:
                failures += 1
                if failures >= FAILED_READS_TO_END:
                    self._end("the device reports no more frames")
                    return
                self.stop.wait(min(self.period_s, 0.01))
                continue
            failures = 0
            with self.cond:
                if self.frames:
                    missed = int(round((stamp - self.frames[-1].stamp) / self.period_s)) - 1
                    if missed > 0 and stamp - self.frames[-1].stamp > 1.5 * self.period_s:
                        self.gap_drops.append((stamp, missed))
                self.seq += 1
                self.frames.append(_Frame(self.seq, stamp, image))
                self.cond.notify_all()

    def _end(self, reason: str) -> None:
        with self.cond:
            self.ended = reason
            self.cond.notify_all()

    def newest_stamp(self) -> float:
        return self.frames[-1].stamp if self.frames else -np.inf


class CameraSource(InOrderSource):
    """Live cameras read by OpenCV (or any object with ``VideoCapture``'s ``read``/``release``).

    Args:
        cameras: the calibration, one camera per device, same order.
        devices: device indices (``"0"``), URLs or video file paths, one per camera.
        fps: the cameras' frame rate (requested from the driver; sets the grouping tolerance).
        capture_factory: ``factory(device, size_px, fps) -> capture`` (default
            :func:`open_capture`; tests inject fake devices).
        stall_s: a camera silent this long counts as stopped (default: 5 periods, at least 0.25 s).
        open_timeout_s: how long :meth:`open` waits for every camera's first frame.
        clock: host clock for the time stamps (``time.perf_counter``).
        markerset: the markers the tracker looks for (None: the images only, ``rehab record``).
    """

    def __init__(self, cameras: Sequence[Camera], devices: Sequence[str], fps: float, *,
                 capture_factory: Callable = open_capture, stall_s: float | None = None,
                 open_timeout_s: float = 5.0, clock: Callable[[], float] = time.perf_counter,
                 markerset: MarkerSet | None = None) -> None:
        super().__init__()
        self.cameras = tuple(cameras)
        self.markerset = markerset
        self.devices = tuple(str(d) for d in devices)
        if len(self.devices) != len(self.cameras):
            raise SourceError(f"{len(self.devices)} camera devices ({', '.join(self.devices) or 'none'}) for "
                              f"{len(self.cameras)} calibrated cameras: give one device per camera, calibration order")
        if not fps > 0:
            raise SourceError(f"camera frame rate {fps}: give a positive number of frames per second")
        self.fps = float(fps)
        self.period_s = 1.0 / self.fps
        self.stall_s = max(5 * self.period_s, 0.25) if stall_s is None else float(stall_s)
        self.open_timeout_s = float(open_timeout_s)
        self.capture_factory = capture_factory
        self.clock = clock
        self.cond = threading.Condition()
        self._readers: list[_Reader] = []
        self._used = np.full(len(self.cameras), -1, np.int64)
        self._index = 0
        self._t0 = 0.0
        c = len(self.cameras)
        self.dropped = np.zeros(c, np.int64)  # frames delivered or lost but not in any set
        self.out_of_step = np.zeros(c, np.int64)  # frames left out for being out of step
        self.missing = np.zeros(c, np.int64)  # sets without this camera's image
        self._drop_events: list[deque] = [deque() for _ in range(c)]  # (time, frames)
        self._skew_events: list[deque] = [deque() for _ in range(c)]  # (time, skew_s)
        self._logged: set[str] = set()
        self._closed = False

    # ------------------------------------------------------------------ life cycle
    def open(self) -> None:
        """Open every device, start the reader threads, wait for each camera's first frame.

        Raises:
            SourceError: a device cannot be opened or delivers nothing in ``open_timeout_s``.
            CalibrationError: a camera delivers images of another size than its calibration.
        """
        if self._readers:
            return
        if self._closed:
            raise SourceError("the camera source was closed; make a new one")
        try:
            for cam, dev in zip(self.cameras, self.devices):
                cap = self.capture_factory(dev, tuple(cam.size_px), self.fps)
                if cap is None or not cap.isOpened():
                    raise SourceError(f"camera {cam.name} (device {dev!r}): cannot open it; check that it is "
                                      "plugged in and the device number or URL (ls /dev/video*)")
                self._readers.append(_Reader(cam.name, dev, cap, self.cond, self.clock, self.period_s))
            for r in self._readers:
                r.thread.start()
            self._wait_first_frames()
        except BaseException:
            self.close()
            raise
        self._t0 = min(r.frames[0].stamp for r in self._readers)

    def _wait_first_frames(self) -> None:
        deadline = self.clock() + self.open_timeout_s
        with self.cond:
            while True:
                silent = [r for r in self._readers if not r.frames]
                for r in silent:
                    if r.ended:
                        raise SourceError(f"camera {r.name} (device {r.device!r}) delivered no image: {r.ended}")
                left = deadline - self.clock()
                if not silent:
                    break
                if left <= 0:
                    names = ", ".join(f"{r.name} (device {r.device!r})" for r in silent)
                    raise SourceError(f"no image from {names} within {self.open_timeout_s:g} s: check the camera "
                                      "and that no other program uses it")
                self.cond.wait(min(left, 0.05))
            for cam, r in zip(self.cameras, self._readers):
                h, w = r.frames[0].image.shape[:2]
                cam.check_image_size((w, h), f"camera {cam.name} (device {r.device!r})")

    def close(self) -> None:
        """Stop the threads and release the devices (idempotent)."""
        self._closed = True
        readers, self._readers = self._readers, []
        for r in readers:
            r.stop.set()
        for r in readers:  # most readers leave read() within a frame period
            if r.thread.is_alive():
                r.thread.join(timeout=max(2 * self.period_s, 0.1))
        for r in readers:  # releasing also unblocks a read() stuck in the driver
            try:
                r.capture.release()
            except Exception as exc:  # releasing must not hide the reason we are closing
                log.warning("camera %s: release failed: %s", r.name, exc)
        for r in readers:
            if r.thread.is_alive():
                r.thread.join(timeout=1.0)
                if r.thread.is_alive():  # a daemon thread: it cannot keep the program alive
                    log.warning("camera %s (device %r) does not return from read()", r.name, r.device)

    def __enter__(self) -> "CameraSource":
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ frame sets
    def _stopped(self, r: _Reader, now: float) -> bool:
        return bool(r.ended) or now - r.newest_stamp() > self.stall_s

    def read_next(self) -> FrameSet | None:
        """The next frame set (it waits for the cameras' next frames); None when every camera ended
        for good (its driver reports failure; a silent camera may come back)."""
        self.open()
        n = len(self.cameras)
        with self.cond:
            deadline = self.clock() + self.stall_s
            while True:
                now = self.clock()
                waiting = [k for k, r in enumerate(self._readers)
                           if r.seq <= self._used[k] and not self._stopped(r, now)]
                if not waiting or now >= deadline:
                    break
                self.cond.wait(min(deadline - now, 0.05))
            if all(r.ended for r in self._readers):  # frames left in the buffers are stale now
                return None
            now = self.clock()
            fresh = [k for k, r in enumerate(self._readers) if r.seq > self._used[k] and not self._stopped(r, now)]
            chosen: dict[int, _Frame] = {}
            if fresh:
                new = {k: [f for f in self._readers[k].frames if f.seq > self._used[k]] for k in fresh}
                t_ref = self._set_time(new)
                for k in fresh:
                    best = min(new[k], key=lambda f: abs(f.stamp - t_ref))
                    skipped = best.seq - self._used[k] - 1 if self._used[k] >= 0 else 0
                    if abs(best.stamp - t_ref) > 0.5 * self.period_s:
                        self.out_of_step[k] += 1
                        self._skew_events[k].append((now, best.stamp - t_ref))  # its frames wait for the next set
                        continue
                    chosen[k] = best
                    self._used[k] = best.seq
                    if skipped > 0:
                        self._drop(k, now, skipped)
                for k, r in enumerate(self._readers):
                    while r.gap_drops:
                        _, missed = r.gap_drops.popleft()
                        self._drop(k, now, missed)
            else:
                t_ref = now
        images, stamps, missing = [], np.full(n, np.nan), np.ones(n, bool)
        for k, cam in enumerate(self.cameras):
            f = chosen.get(k)
            if f is None:
                images.append(black_image(cam))
                self.missing[k] += 1
            else:
                images.append(f.image)
                stamps[k] = f.stamp - self._t0
                missing[k] = False
        fs = FrameSet(self._index, t_ref - self._t0, tuple(images), stamps, missing)
        self._index += 1
        self._log_new_warnings()
        return fs

    def _set_time(self, new: dict[int, list[_Frame]]) -> float:
        """The instant of the set: the new frame's stamp that the most cameras have a frame within
        half a period of (the latest such stamp on a tie), no later than a period after the
        earliest camera's newest frame (a later instant would leave out cameras that simply have
        not delivered it yet)."""
        half = 0.5 * self.period_s
        limit = min(frames[-1].stamp for frames in new.values()) + self.period_s
        stamps = np.array(sorted({f.stamp for frames in new.values() for f in frames if f.stamp <= limit}))
        count = np.zeros(len(stamps), np.int64)
        for frames in new.values():
            s = np.array([f.stamp for f in frames])
            count += (np.abs(stamps[:, None] - s[None, :]) <= half).any(axis=1)
        best = np.flatnonzero(count == count.max())[-1]
        return float(stamps[best])

    def _drop(self, k: int, now: float, frames: int) -> None:
        self.dropped[k] += frames
        self._drop_events[k].append((now, frames))

    # ------------------------------------------------------------------ warnings
    def warnings(self) -> tuple[str, ...]:
        """Current problems, one line each: stopped cameras, dropped and out-of-step frames."""
        return tuple(line for _, line in self._conditions())

    def _conditions(self) -> list[tuple[str, str]]:
        """(key, line) of each current problem; the key names the camera and the kind."""
        now = self.clock()
        out = []
        readers = self._readers
        stopped = np.array([self._stopped(r, now) for r in readers], bool)
        if readers and stopped.all():
            out.append(("all/stopped", "every camera stopped: " + self._stop_reasons(now)))
        for k, r in enumerate(readers):
            if stopped[k] and not stopped.all():
                why = r.ended or f"no frame for {now - r.newest_stamp():.1f} s"
                rest = camera_names(self.cameras, ~stopped)
                tail = f"tracking goes on with {rest}" if rest else "no camera delivers frames"
                out.append((f"{r.name}/stopped", f"camera {r.name} (device {r.device!r}) stopped ({why}): {tail}"))
        for k, cam in enumerate(self.cameras):
            drops = self._recent(self._drop_events[k], now)
            if drops:
                n = sum(v for _, v in drops)
                out.append((f"{cam.name}/dropped",
                            f"camera {cam.name} dropped {n} frames in the last {WARN_WINDOW_S:g} s "
                            f"(the cameras or the tracker cannot keep {self.fps:g} frame sets/s)"))
            skews = self._recent(self._skew_events[k], now)
            if skews:
                worst = max(abs(v) for _, v in skews) * 1000.0
                out.append((f"{cam.name}/out_of_step",
                            f"camera {cam.name} is out of step with the others by up to {worst:.0f} ms (more than "
                            f"half a frame period): {len(skews)} of its frames left out in the last {WARN_WINDOW_S:g} s"))
        return out

    @staticmethod
    def _recent(events: deque, now: float) -> list:
        while events and now - events[0][0] > WARN_WINDOW_S:
            events.popleft()
        return list(events)

    def _log_new_warnings(self) -> None:
        """Log each problem once when it appears (it shows in :meth:`warnings` while it lasts)."""
        current = self._conditions()
        for key, line in current:
            if key not in self._logged:
                log.warning("%s", line)
        self._logged = {key for key, _ in current}

    def _stop_reasons(self, now: float) -> str:
        """``"cam1, cam2: the device reports no more frames; cam3: no frame for 0.6 s"``."""
        by_reason: dict[str, list[str]] = {}
        for r in self._readers:
            why = r.ended or f"no frame for {now - r.newest_stamp():.1f} s"
            by_reason.setdefault(why, []).append(r.name)
        return "; ".join(f"{', '.join(names)}: {why}" for why, names in by_reason.items())

    def end_reason(self) -> str:
        if self._readers and all(r.ended for r in self._readers):
            return "every camera stopped: " + self._stop_reasons(self.clock())
        return ""
