"""The simulated patient as a frame source: a scripted motion or the interactive patient, rendered
by the studio's virtual cameras (software GL), with the true marker centres beside the images."""

from __future__ import annotations

import time

import numpy as np

from calibration.camera import Camera
from tracking.markerset import MarkerSet, load_markerset
from tracking.sim.body import BodyDimensions
from tracking.sim.interactive import InteractivePatient
from tracking.sim.motions import load_motion
from tracking.sim.rigs import load_rig
from tracking.sources.base import FrameRequest, FrameSet
from tracking.sources.commands import PatientInput, Reidentify, SetMotion, SetPatientInput


def geometry(config) -> tuple[tuple[Camera, ...], MarkerSet]:
    """The rig's cameras at ``config.size`` and the marker set (content files only)."""
    config.check()
    return tuple(load_rig(config.rig, tuple(config.size))), load_markerset(config.markerset)


def from_config(config) -> "SimulatedSource":
    """The live tracker's simulated patient: its motion in a loop, or the interactive patient."""
    return SimulatedSource(config)


class SimulatedSource:
    """The simulated patient rendered by the studio's virtual cameras.

    Read with a :class:`FrameRequest` (the live tracker's loop), it is tied to the reader's clock
    like a camera (``paced_by_clock``, ``config.sim_clock == "wall"``): the loop asks for the
    frame set due now, rendered at its wall-clock time since the start, and frame sets the loop
    was too late for are never rendered; a scripted motion and the interactive patient thus move
    at the clock's pace however busy the machine is. With ``sim_clock="frames"``, and read
    without a request (``rehab record``, the benchmarks), every frame set is rendered, its time
    being its number over ``fps``.

    Args:
        config: a :class:`tracking.live.protocol.SourceConfig`: rig, size, frame rate, body,
            marker set, motion (None: interactive), noise, seed, clock.
        seconds: None: the motion plays in a loop (live); a number: it plays once, for at most
            that long, and the source ends (a recording of it).
        start_s: the motion's time of the first frame set.
    """

    def __init__(self, config, *, seconds: float | None = None, start_s: float = 0.0) -> None:
        # the studio (OpenGL) only where a simulated source is made: the game reads the rig's
        # geometry through this module without loading it
        # lazy: the simulator only when the simulated patient is the source (tests/test_layout.py)
        from tracking.sim.studio import Studio

        self.config = config
        self.paced_by_clock = config.sim_clock == "wall"
        cameras, markerset = geometry(config)
        percentile, sex = config.body_percentile_sex()
        self.studio = Studio(cameras, markerset, BodyDimensions.from_percentile(percentile, sex))
        self.cameras = self.studio.cameras
        self.markerset = markerset
        self.fps = float(config.fps)
        self.seconds = seconds
        self.start_s = float(start_s)
        self.patient = InteractivePatient(self.studio.body)
        self.patient_input = PatientInput()
        self.motion = None
        self.n_frames: int | None = None  # frame sets of a motion played once
        self._motion_start_s = 0.0
        self._last_time_s = 0.0
        self._restart_motion = True
        self._next_index = 0
        self._ended = ""
        if config.motion is not None:
            self.set_motion(config.motion)

    def set_motion(self, name: str | None) -> None:
        """Play ``name`` from its start (None: the interactive patient). Raises on unknown names."""
        self.motion = None if name is None else load_motion(name, self.studio.body.dims)
        self._restart_motion = True
        self.patient.take_reference_pose()
        if self.seconds is not None and self.motion is not None:
            self.n_frames = self.studio.n_frames(self.motion, self.fps, self.seconds)

    def open(self) -> None:
        """Nothing to open (the studio renders from its construction)."""

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
                self._motion_start_s = time_s - self.start_s
                self._restart_motion = False
            duration = self.motion.duration_s
            t = (time_s - self._motion_start_s) % duration if duration > 0 else 0.0
            return self.motion.pose_at(t)
        if not identified:
            return self.patient.take_reference_pose()
        return self.patient.step(self.patient_input, min(max(dt, 0.0), 0.2))

    def read(self, request: FrameRequest | None = None) -> FrameSet | None:
        if request is None:
            if self.n_frames is not None and self._next_index >= self.n_frames:
                self._ended = f"the motion {self.config.motion!r} ended"
                return None
            request = FrameRequest(self._next_index, self._next_index / self.fps)
        self._next_index = request.index + 1
        t0 = time.perf_counter()
        pose = self.pose_at(request.time_s, request.identified)
        cfg = self.config
        sim = self.studio.render(pose, request.index, request.time_s, noise_sigma=cfg.noise_sigma,
                                 seed=cfg.seed * 1_000_003 + request.index, with_visibility=False)
        t1 = time.perf_counter()
        c = len(self.cameras)
        return FrameSet(request.index, request.time_s, tuple(sim.frames.images), np.full(c, request.time_s),
                        np.zeros(c, bool), sim.markers_m, t1, (t1 - t0) * 1000.0)

    def warnings(self) -> tuple[str, ...]:
        return ()

    def end_reason(self) -> str:
        return self._ended

    def close(self) -> None:
        self.studio.close()

    def __enter__(self) -> "SimulatedSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
