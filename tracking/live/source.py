"""Frame sources of the tracker process: where the synchronized camera images come from.

A source delivers one frame set per call of :meth:`FrameSource.grab`. The simulated patient
(:class:`SimSource`) renders it with the studio of :mod:`tracking.sim.studio`: a scripted motion
played in a loop, or the interactive patient of :mod:`tracking.sim.interactive` driven by the
game's ``PatientInput``. It hands the tracker only the images; the true marker centres travel
beside them for tests and benchmarks.

Recordings and live cameras (:mod:`tracking.sources`) come through :class:`DeviceSource`, which
adapts a :class:`tracking.sources.FrameSource` to this interface: their frame sets carry their own
time stamps and the source's current warnings (a stopped camera, dropped frames), and a source
that ended delivers None.
"""

from __future__ import annotations

import importlib
import logging
import math
import time
from dataclasses import dataclass, replace
from typing import Protocol, Sequence

import numpy as np

from calibration.camera import Camera
from tracking.angles import supported_angles
from tracking.markerset import MarkerSet, load_markerset
from tracking.live.protocol import LiveError, PatientInput, Reidentify, SetMotion, SetPatientInput, SourceConfig

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class SourceFrame:
    """One synchronized frame set.

    Attributes:
        images: one (H, W, 3) uint8 BGR image per camera, calibration order.
        truth_m: (M, 3) float64 true marker centres (world metres), or None (real cameras).
        t_ready_s: ``time.perf_counter()`` when the images were complete.
        source_ms: time the source took to deliver them.
        time_s: the source's own time stamp of the set (NaN: the loop's ``frame_index / fps``).
        warnings: the source's current problems, one line each.
        stamps_s: (C,) each image's own instant on the clock of ``time_s`` (NaN unknown), or None:
            all taken at ``time_s`` (the tracker brings the views to the set's instant).
    """

    images: Sequence[np.ndarray]
    truth_m: np.ndarray | None
    t_ready_s: float
    source_ms: float
    time_s: float = math.nan
    warnings: tuple[str, ...] = ()
    stamps_s: np.ndarray | None = None


class FrameSource(Protocol):
    """What the tracker process needs from a source."""

    cameras: tuple[Camera, ...]
    markerset: MarkerSet

    def grab(self, frame_index: int, time_s: float, identified: bool) -> SourceFrame | None:
        """The frame set of ``frame_index`` at source time ``time_s``; ``identified`` tells a
        simulated patient whether the tracker has identified the markers (a patient waiting to be
        identified holds the reference pose). None: the source has ended (a recording)."""

    def handle(self, command: object) -> None:
        """Apply a source command (``SetMotion``, ``SetPatientInput``, ``Reidentify``)."""

    def close(self) -> None:
        """Release devices and GL resources."""


def source_geometry(config: SourceConfig) -> tuple[tuple[Camera, ...], MarkerSet]:
    """Cameras and marker set of a source, without opening it (content, calibration and
    meta.yaml files only).

    The game sizes the shared memory from them before the tracker process starts.
    """
    from tracking.sim.rigs import load_rig

    config.check()
    if config.kind == "recording":
        from tracking.sources.recording import RecordingSource

        with RecordingSource(config.path, config.calibration) as rec:
            return rec.cameras, rec.markerset()
    if config.kind == "cameras":
        return _calibrated_cameras(config), load_markerset(config.markerset)
    return tuple(load_rig(config.rig, tuple(config.size))), load_markerset(config.markerset)


def calibration_file_for(config: SourceConfig):
    """The calibration file of a camera or recording source (a Path), None for a simulated one."""
    from pathlib import Path

    if config.kind == "cameras" and config.calibration:
        return Path(config.calibration)
    if config.kind == "recording" and config.path:
        return Path(config.calibration) if config.calibration else Path(config.path) / "calibration.toml"
    return None


def learnt_colours_for(config: SourceConfig, markerset: MarkerSet):
    """The marker colours learnt into the source's calibration file (``rehab calibrate colour``):
    (models, label_hs), or None (none saved, or a simulated source: the nominal table)."""
    from tracking.colour.adapt import calibration_colours

    path = calibration_file_for(config)
    return None if path is None else calibration_colours(path, markerset)


def _calibrated_cameras(config: SourceConfig) -> tuple[Camera, ...]:
    from calibration.files import check_camera_count, load_calibration

    cameras = tuple(load_calibration(config.calibration))
    check_camera_count(cameras, len(config.devices), "the source", kind="camera devices",
                       calibration_name=str(config.calibration))
    return cameras


def resolve_config(config: SourceConfig) -> SourceConfig:
    """``config`` with the image size (and, for a recording, the frame rate) its source decides.

    Raises:
        LiveError: the cameras' image sizes differ (the live image block holds one size).
        RehabError: the recording or the calibration cannot be read (one line).
    """
    config.check()
    if config.kind not in ("recording", "cameras"):
        return config
    cameras, _ = source_geometry(config)
    sizes = sorted({tuple(c.size_px) for c in cameras})
    if len(sizes) != 1:
        raise LiveError(f"the cameras have different image sizes {sizes}: the live tracker needs one size; "
                        "set the cameras to one size and recalibrate")
    fps = config.fps
    if config.kind == "recording":
        from tracking.io.recording import read_meta
        from pathlib import Path

        fps = read_meta(Path(config.path)).fps
    return replace(config, size=sizes[0], fps=fps, motion=None)


def angle_names_for(markerset: MarkerSet) -> tuple[str, ...]:
    """The joint angles the tracker reports for a marker set: those its roles' markers give."""
    return supported_angles(markerset.roles)


def open_source(config: SourceConfig) -> FrameSource:
    """The source that ``config`` names (``"sim"``, ``"recording"``, ``"cameras"``, or a
    ``"module:function"`` factory)."""
    if config.kind == "sim":
        return SimSource(config)
    if config.kind == "recording":
        from tracking.sources.recording import RecordingSource

        rec = RecordingSource(config.path, config.calibration)
        return DeviceSource(rec, rec.markerset())
    if config.kind == "cameras":
        from tracking.sources.cameras import CameraSource

        # a read never blocks the loop longer than half a second (its heartbeat is watched)
        cams = CameraSource(_calibrated_cameras(config), config.devices, config.fps,
                            stall_s=min(max(5.0 / config.fps, 0.25), 0.5))
        return DeviceSource(cams, load_markerset(config.markerset))
    module_name, _, attr = config.kind.partition(":")
    try:
        factory = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise LiveError(f"source kind {config.kind!r}: cannot import it ({exc}); give 'sim' or module:function") from None
    return factory(config)


class SimSource:
    """The simulated patient rendered by the studio's virtual cameras.

    Like a camera, it is tied to the clock (``paced_by_clock``, ``config.sim_clock == "wall"``):
    the loop asks for the frame set due now, whose time stamp is its wall-clock time since the
    start, and frame sets the loop was too late for are never rendered. A scripted motion and the
    interactive patient thus move at the clock's pace however busy the machine is (with fewer
    frame sets per second). With ``sim_clock="frames"`` every frame set is rendered, the time
    being the frame count (measurements independent of the machine's load).

    Args:
        config: rig, size, frame rate, body, marker set, motion (None: interactive), noise.
    """

    def __init__(self, config: SourceConfig) -> None:
        from tracking.sim.body import BodyDimensions
        from tracking.sim.interactive import InteractivePatient
        from tracking.sim.studio import Studio

        self.config = config
        self.paced_by_clock = config.sim_clock == "wall"
        cameras, markerset = source_geometry(config)
        percentile, sex = config.body_percentile_sex()
        dims = BodyDimensions.from_percentile(percentile, sex)
        self.studio = Studio(cameras, markerset, dims)
        self.cameras = self.studio.cameras
        self.markerset = markerset
        self.patient = InteractivePatient(self.studio.body)
        self.patient_input = PatientInput()
        self.motion = None
        self._motion_start_s = 0.0
        self._last_time_s = 0.0
        self._restart_motion = True
        if config.motion is not None:
            self.set_motion(config.motion)

    def set_motion(self, name: str | None) -> None:
        """Play ``name`` from its start (None: the interactive patient). Raises on unknown names."""
        from tracking.sim.motions import load_motion

        self.motion = None if name is None else load_motion(name, self.studio.body.dims)
        self._restart_motion = True
        self.patient.take_reference_pose()

    def handle(self, command: object) -> None:
        if isinstance(command, SetMotion):
            self.set_motion(command.name)
        elif isinstance(command, SetPatientInput):
            self.patient_input = command.value
        elif isinstance(command, Reidentify):
            # the patient is asked to take the reference pose: a motion starts again from it
            self._restart_motion = True
            self.patient.take_reference_pose()

    def pose_at(self, time_s: float, identified: bool):
        """The body pose of the frame at source time ``time_s``."""
        dt = time_s - self._last_time_s
        self._last_time_s = time_s
        if self.motion is not None:
            if self._restart_motion:
                self._motion_start_s = time_s
                self._restart_motion = False
            duration = self.motion.duration_s
            t = (time_s - self._motion_start_s) % duration if duration > 0 else 0.0
            return self.motion.pose_at(t)
        if not identified:
            return self.patient.take_reference_pose()
        return self.patient.step(self.patient_input, min(max(dt, 0.0), 0.2))

    def grab(self, frame_index: int, time_s: float, identified: bool) -> SourceFrame:
        t0 = time.perf_counter()
        pose = self.pose_at(time_s, identified)
        cfg = self.config
        sim = self.studio.render(pose, frame_index, time_s, noise_sigma=cfg.noise_sigma,
                                 seed=cfg.seed * 1_000_003 + frame_index, with_visibility=False)
        t1 = time.perf_counter()
        return SourceFrame(sim.frames.images, sim.markers_m, t1, (t1 - t0) * 1000.0)

    def close(self) -> None:
        self.studio.close()



class DeviceSource:
    """A :class:`tracking.sources.FrameSource` (a recording, live cameras) as a tracker-process source.

    Frame sets come in the source's order with its time stamps. The loop asks for frame sets by
    number: asking again for the last one returns it again (the warm-up frame set is the first
    one tracked), and a number beyond the next one skips the frame sets in between (a replacement
    process continues a recording where the dead one was). When the source ends, :meth:`grab`
    returns None and the end is one of :meth:`warnings`.

    Args:
        source: the frame source (opened here).
        markerset: the markers the tracker looks for.
    """

    def __init__(self, source, markerset: MarkerSet) -> None:
        self.source = source
        self.cameras = tuple(source.cameras)
        self.markerset = markerset
        self.fps = source.fps
        source.open()
        self._next = 0  # number of the next frame set the source will deliver
        self._last: tuple[int, SourceFrame] | None = None
        self._ended = ""

    def grab(self, frame_index: int, time_s: float, identified: bool) -> SourceFrame | None:
        if self._last is not None and self._last[0] == frame_index:
            return self._last[1]
        if self._ended:
            return None
        t0 = time.perf_counter()
        if frame_index > self._next and hasattr(self.source, "skip"):
            self._next += self.source.skip(frame_index - self._next)
        fs = self.source.read()
        t1 = time.perf_counter()
        if fs is None:
            self._ended = self.source.end_reason() or "the source ended"
            log.warning("%s", self._ended)
            return None
        self._next += 1
        frame = SourceFrame(fs.images, fs.truth_m, t1, (t1 - t0) * 1000.0, fs.time_s, self.warnings(), fs.stamps_s)
        self._last = (frame_index, frame)
        return frame

    def warnings(self) -> tuple[str, ...]:
        """The source's current problems, one line each; once it ended, why, after what it said
        before (e.g. a camera that ended before the others)."""
        said = tuple(w for w in self.source.warnings() if w != self._ended)
        return (*said, self._ended) if self._ended else said

    def handle(self, command: object) -> None:
        if isinstance(command, SetMotion) and command.name is not None:
            raise LiveError(f"motion {command.name!r}: this source measures a recording or cameras, it plays no motions")

    def close(self) -> None:
        self.source.close()
