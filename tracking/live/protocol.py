"""What the game and the tracker process say to each other: configuration, commands, samples.

Small frozen dataclasses only (they cross the process boundary by pickling through the control
pipe, or are rebuilt from shared-memory records on the game's side).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from tracking.sources import source_kinds
# the source commands are the sources' own; the game sends them through the control pipe
from tracking.sources.commands import LiveError, PatientInput, Reidentify, SetMotion, SetPatientInput


#: Clocks of the simulated patient (:attr:`SourceConfig.sim_clock`).
SIM_CLOCKS = ("wall", "frames")


@dataclass(frozen=True, slots=True)
class SourceConfig:
    """What the tracker process measures.

    Attributes:
        kind: a registered source kind (:mod:`tracking.sources`): ``"sim"``: the simulated
            patient rendered by virtual cameras; ``"recording"``: a recording folder (``path``)
            played once in real time; ``"cameras"``: live cameras (``devices`` and
            ``calibration``). A ``"module:function"`` path names a factory
            ``function(config) -> FrameSource`` to import in the tracker process (how tests
            inject a faulty source).
        rig: camera layout (content/rigs name or file) of the simulated patient.
        size: camera image (width, height), pixels; a recording's or a calibration's size
            replaces it (:func:`tracking.live.source.resolve_config`).
        fps: camera frame rate; the process delivers frame sets at this rate in real time (a
            recording's meta.yaml replaces it).
        motion: a scripted motion (content/motions name or file) played in a loop; None: the
            interactive patient (:class:`PatientInput`).
        body: simulated body, ``p<percentile>_<sex>`` (e.g. ``p50_male``, ``p5_female``).
        markerset: marker set name or file.
        seed: sensor-noise seed.
        noise_sigma: sensor noise of the simulated cameras, 8-bit units.
        path: the recording folder (kind ``"recording"``).
        devices: OpenCV device indices (``"0"``), URLs or video files, one per calibrated camera,
            calibration order (kind ``"cameras"``).
        calibration: calibration file (kind ``"cameras"``; for ``"recording"`` it replaces
            the folder's calibration.toml). Marker colours learnt into it (``rehab calibrate
            colour``) replace the nominal colour table.
        adapt_colours: the colour table follows lighting drift, learning from the pixels of the
            tracked markers (:class:`tracking.colour.adapt.ColourAdapter`, docs/COLOUR.md); False:
            the table stays as it starts.
        sim_clock: the simulated patient's clock. ``"wall"``: like a camera, its frame sets are
            tied to the wall clock and those the tracker is too late for are dropped (the motion
            keeps its real speed on a busy machine, with fewer frame sets); ``"frames"``: every
            frame set is rendered and its time is its number over ``fps`` (the motion slows down
            when the machine is busy, every frame set as on an idle machine: for measurements
            that must not depend on the load).
    """

    kind: str = "sim"
    rig: str = "ring4"
    size: tuple[int, int] = (320, 240)
    fps: float = 30.0
    motion: str | None = None
    body: str = "p50_male"
    markerset: str = "upper_limb_seated"
    seed: int = 0
    noise_sigma: float = 1.5
    path: str | None = None
    devices: tuple[str, ...] = ()
    calibration: str | None = None
    adapt_colours: bool = False
    sim_clock: str = "wall"

    def body_percentile_sex(self) -> tuple[float, str]:
        """``"p50_male"`` -> (50.0, "male"); :class:`LiveError` if malformed."""
        match = re.fullmatch(r"p(\d+(?:\.\d+)?)_(female|male)", self.body)
        if not match:
            raise LiveError(f"body {self.body!r}: write p<percentile>_<sex>, e.g. p50_male or p5_female")
        return float(match.group(1)), match.group(2)

    def check(self) -> None:
        """Raise :class:`LiveError` on values that cannot work (checked once, in the game)."""
        w, h = self.size
        if not (16 <= w <= 4096 and 16 <= h <= 4096):
            raise LiveError(f"source size {w}x{h}: give a camera image size between 16x16 and 4096x4096")
        if not (1.0 <= self.fps <= 240.0):
            raise LiveError(f"source fps {self.fps:g}: give a frame rate between 1 and 240")
        if self.sim_clock not in SIM_CLOCKS:
            raise LiveError(f"sim_clock {self.sim_clock!r}: give one of {', '.join(SIM_CLOCKS)}")
        if self.kind not in source_kinds() and ":" not in self.kind:
            raise LiveError(f"source kind {self.kind!r}: give one of {', '.join(source_kinds())} or module:function")
        if self.kind == "recording" and not self.path:
            raise LiveError("source kind 'recording' needs path: the recording folder")
        if self.kind == "cameras" and not (self.devices and self.calibration):
            raise LiveError("source kind 'cameras' needs devices (e.g. ('0', '1')) and calibration: the calibration file")
        self.body_percentile_sex()


@dataclass(frozen=True, slots=True)
class LiveSample:
    """One frame set as the tracker process published it.

    Attributes:
        frame_index: the source's frame number (continues across process restarts).
        time_s: source time stamp.
        t_frame_ready_s: ``time.perf_counter()`` in the tracker process when the frame set was
            ready (CLOCK_MONOTONIC: comparable across processes on one machine).
        t_published_s: ``time.perf_counter()`` when the sample was written to shared memory.
        state: ``tracking.tracker.TrackingState`` (0 WAITING, 1 TRACKING).
        positions_m: (M, 3) float64 world metres, NaN where lost.
        status: (M,) uint8 ``tracking.marker_status.MarkerStatus``.
        angles_deg: (A,) float64 in :attr:`angle_names` order, NaN where undefined.
        message: one line (why WAITING, or a tracker error).
        windows_px: (M, C, 3) float64 (u, v, half size) of the search windows, NaN where none.
        uv_px: (M, C, 2) float64 centroid used per marker per camera, NaN where none.
        truth_m: (M, 3) float64 the simulator's true marker centres (NaN for real cameras);
            for tests and benchmarks, never fed to the tracker.
        step_ms: the tracker's step time for this frame set.
        source_ms: time the source took to deliver it (rendering, for the simulator).
        number: sample number in the shared ring (0, 1, ...; continues across restarts).
        angle_names: the names of :attr:`angles_deg`.
        stamps_s: (C,) float64 the instant of each camera's image, source seconds (NaN where a
            camera gave none); None from a tracker that does not report them.
    """

    frame_index: int
    time_s: float
    t_frame_ready_s: float
    t_published_s: float
    state: int
    positions_m: np.ndarray
    status: np.ndarray
    angles_deg: np.ndarray
    message: str
    windows_px: np.ndarray
    uv_px: np.ndarray
    truth_m: np.ndarray
    step_ms: float = math.nan
    source_ms: float = math.nan
    number: int = -1
    angle_names: tuple[str, ...] = field(default=(), repr=False)
    stamps_s: np.ndarray | None = field(default=None, repr=False)

    def angle(self, name: str) -> float:
        """The angle called ``name`` in degrees (NaN where undefined); KeyError if unknown."""
        try:
            k = self.angle_names.index(name)
        except ValueError:
            raise KeyError(f"no angle {name!r}: the angles are {', '.join(self.angle_names)}") from None
        return float(self.angles_deg[k])


@dataclass(frozen=True, slots=True)
class LiveStatus:
    """Health of the tracker process, as the game sees it.

    Attributes:
        alive: the process runs and its heartbeat is fresh.
        heartbeat_age_s: seconds since the process's last loop turn.
        restarts: times the process was restarted after dying or hanging.
        last_error: one readable line, "" if none (a tracker error, or why the process died).
        source_fps: frame sets per second delivered recently.
        tracker_ms: mean tracker step time recently, milliseconds.
        dropped: samples the game missed because it fell more than the ring behind.
        errors: frame sets whose processing raised (each is logged; the last is ``last_error``).
        state: ``tracking.live.ring.ProcessState`` of the process (STARTING while restarting).
        samples: samples published so far.
        warning: the source's current problems as one line ("" if none): a camera that stopped
            (tracking goes on with the others), dropped or out-of-step frames, a recording that
            ended or is cut short.
    """

    alive: bool
    heartbeat_age_s: float
    restarts: int
    last_error: str
    source_fps: float
    tracker_ms: float
    dropped: int
    errors: int = 0
    state: int = 0
    samples: int = 0
    warning: str = ""


# ============================================================================ commands
@dataclass(frozen=True, slots=True)
class Stop:
    """Leave the loop and exit."""


@dataclass(frozen=True, slots=True)
class SetColours:
    """Track with these marker colours from now on (taught in the camera monitor).

    Attributes:
        models: one :class:`tracking.colour.learn.ColourModel` per marker colour.
        label_hs: (256, 256) uint8 (hue byte, saturation byte) labels (:mod:`tracking.colour.learn`).
    """

    models: tuple
    label_hs: np.ndarray


@dataclass(frozen=True, slots=True)
class Pause:
    """Freeze the source (no new frame sets; the heartbeat goes on)."""


@dataclass(frozen=True, slots=True)
class Resume:
    """Continue after :class:`Pause`."""


@dataclass(frozen=True, slots=True)
class Activate:
    """Take over (to a standby process): start publishing with this motion, input and pause state."""

    motion: str | None
    patient_input: PatientInput
    paused: bool


Command = Stop | Reidentify | SetMotion | SetPatientInput | Pause | Resume | Activate
