"""Live output of the tracker process: Lab Streaming Layer and OSC (with VMC bones).

The tracker loop hands each frame set to :meth:`StreamSender.offer`, which copies a few small
arrays into a bounded queue and returns (a full queue drops the frame set and counts it: the
tracker never waits for a network). A thread sends from the queue:

- **LSL** (``pylsl``; docs/STREAMING.md): three outlets, time-stamped with the instant the frame
  set was ready (``FrameSet.t_ready_s``; on Linux ``time.perf_counter`` and LSL's clock are both
  CLOCK_MONOTONIC, elsewhere the offset is measured once):

  - ``<name> markers``, type ``Mocap``: 3 x M float32 channels ``MB_X, MB_Y, MB_Z, ...`` in
    millimetres, world frame, NaN where lost; the description follows the XDF motion-capture
    meta-data (``channels/channel`` with ``label``, ``marker``, ``type`` PositionX/Y/Z, ``unit``
    millimeters; ``setup/markers/marker``; ``acquisition``) and names the marker set;
  - ``<name> angles``, type ``Angles``: the joint angles in degrees (docs/JOINT_ANGLES.md), NaN
    where undefined;
  - ``<name> status``, type ``Status``: int16 channels ``state`` (0 waiting for the reference pose,
    1 tracking) and one per marker (0 lost, 1 measured, 2 estimated).

  Source ids are fixed (``<name>-markers`` ...), so an inlet resumes by itself when the tracker
  process is restarted.
- **OSC** (``python-osc``, UDP) to HOST:PORT, one bundle per frame set: ``/rehab/frame index
  time_s state``, ``/rehab/marker name x y z status`` (metres, world frame) per marker,
  ``/rehab/angle name degrees`` per angle; and the **VMC** messages (Virtual Motion Capture
  protocol) of the skeleton driven by the angles (:mod:`tracking.io.bvh`): ``/VMC/Ext/Root/Pos``,
  ``/VMC/Ext/Bone/Pos`` for Hips, Spine, Neck, Head, Right/LeftUpperArm, LowerArm and Hand (local
  position and rotation, Unity's left-handed axes, rotations relative to a T-pose as VRM avatars
  rest), ``/VMC/Ext/OK 1`` and ``/VMC/Ext/T``.
"""

from __future__ import annotations

import functools
import logging
import math
import os
import queue
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration.errors import RehabError
from tracking.angles import ANGLE_COLUMNS

log = logging.getLogger(__name__)

#: VMC's usual port (avatar tools listen there).
VMC_PORT = 39539


class StreamError(RehabError):
    """A streaming option cannot work (a bad OSC target, pylsl or python-osc missing)."""


@dataclass(frozen=True, slots=True)
class StreamConfig:
    """What the tracker process streams; all off by default.

    Attributes:
        lsl: publish the LSL marker, angle and status streams.
        osc: (host, port) to send OSC and VMC messages to; None: no OSC.
        name: the streams' name prefix.
        queue_size: frame sets waiting for the sender at most (more are dropped).
    """

    lsl: bool = False
    osc: tuple[str, int] | None = None
    name: str = "rehab-mocap"
    queue_size: int = 8

    @property
    def enabled(self) -> bool:
        return self.lsl or self.osc is not None

    def check(self) -> None:
        """:class:`StreamError` (one line) if the libraries or the target are missing."""
        if self.lsl:
            try:
                # lazy: checks that pylsl and its native liblsl load
                import pylsl  # noqa: F401
            except (ImportError, RuntimeError) as exc:
                raise StreamError(f"--lsl needs pylsl with its liblsl ({exc}); install rehab-mocap's dependencies") from None
        if self.osc is not None:
            try:
                # lazy: checks that python-osc is installed
                import pythonosc  # noqa: F401
            except ImportError:
                raise StreamError("--osc needs python-osc; install rehab-mocap's dependencies") from None

            try:
                socket.getaddrinfo(self.osc[0], self.osc[1], type=socket.SOCK_DGRAM)
            except (socket.gaierror, UnicodeError):
                raise StreamError(f"--osc {self.osc[0]}:{self.osc[1]}: unknown host {self.osc[0]!r}; give an IP "
                                  "address or a name this machine resolves") from None


def parse_osc_target(text: str) -> tuple[str, int]:
    """``"HOST:PORT"`` or ``"PORT"`` (host 127.0.0.1) -> (host, port); one-line :class:`StreamError`."""
    host, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 1 <= number <= 65535:
        raise StreamError(f"--osc {text!r}: give HOST:PORT or PORT, e.g. 127.0.0.1:{VMC_PORT}")
    return host.strip("[]") or "127.0.0.1", number


@dataclass(frozen=True, slots=True)
class StreamFrame:
    """One frame set as streamed (copies, owned by the sender)."""

    frame_index: int
    time_s: float
    t_ready_s: float
    state: int
    positions_m: np.ndarray
    status: np.ndarray
    angles_deg: np.ndarray


class StreamSender:
    """Sends frame sets to LSL and OSC from a thread of its own (module docstring).

    Args:
        config: what to stream.
        names: the M marker names; markerset: the marker set's name.
        angle_names: the angles' names, in the order of ``StreamFrame.angles_deg``.
        fps: the nominal frame rate.
    """

    def __init__(self, config: StreamConfig, names, markerset: str, angle_names, fps: float) -> None:
        self.config = config
        self.dropped = 0
        self.sent = 0
        self.errors = 0
        self._queue: queue.Queue = queue.Queue(maxsize=max(1, config.queue_size))
        self._outputs = []
        if config.lsl:
            self._outputs.append(LslOutput(config.name, tuple(names), markerset, tuple(angle_names), fps))
        if config.osc is not None:
            self._outputs.append(OscOutput(config.osc, tuple(names), tuple(angle_names)))
        self._thread = threading.Thread(target=self._run, name="rehab-stream", daemon=True)
        self._thread.start()

    def offer(self, frame: StreamFrame) -> bool:
        """Queue a frame set for sending; False (and counted) if the queue is full. Never blocks."""
        try:
            self._queue.put_nowait(frame)
            return True
        except queue.Full:
            self.dropped += 1
            if self.dropped % 100 == 1:
                log.warning("streaming falls behind: %d frame sets dropped so far", self.dropped)
            return False

    def close(self, timeout_s: float = 1.0) -> None:
        """Send what is queued (within ``timeout_s``), then stop the thread and close the outputs."""
        deadline = time.monotonic() + timeout_s
        while self._thread.is_alive():
            try:
                self._queue.put(None, timeout=0.05)
                break
            except queue.Full:
                if time.monotonic() > deadline:
                    break
        self._thread.join(max(0.0, deadline - time.monotonic()))
        for output in self._outputs:
            output.close()

    def _run(self) -> None:
        while True:
            frame = self._queue.get()
            if frame is None:
                return
            for output in self._outputs:
                try:
                    output.send(frame)
                except Exception as exc:  # a network error must not stop the sender
                    self.errors += 1
                    if self.errors % 100 == 1:
                        log.warning("streaming (%s) failed %d times, last: %s", type(output).__name__, self.errors, exc)
            self.sent += 1


# ------------------------------------------------------------------------------------ LSL


def quiet_lsl() -> None:
    """liblsl logs INFO lines to stderr; keep warnings only, unless the user configured LSL
    (a config file LSL would read, whose KnownPeers or SessionID must stay in force)."""
    import pylsl  # lazy: pylsl loads its native liblsl: only when LSL output is on

    user_files = [os.environ.get("LSLAPICFG", ""), "lsl_api.cfg", str(Path.home() / "lsl_api" / "lsl_api.cfg"),
                  "/etc/lsl_api/lsl_api.cfg"]
    if not any(p and Path(p).is_file() for p in user_files):
        try:
            pylsl.set_config_content("[log]\nlevel = -2\n")
        except (NotImplementedError, AttributeError):
            pass


class LslOutput:
    """The three LSL outlets (module docstring)."""

    def __init__(self, name: str, names: tuple[str, ...], markerset: str, angle_names: tuple[str, ...], fps: float):
        import pylsl  # lazy: pylsl loads its native liblsl: only when LSL output is on

        quiet_lsl()
        self._pylsl = pylsl
        self._offset_s = pylsl.local_clock() - time.perf_counter()
        markers = pylsl.StreamInfo(f"{name} markers", "Mocap", 3 * len(names), fps, "float32", f"{name}-markers")
        desc = markers.desc()
        desc.append_child_value("marker_set", markerset)
        desc.append_child_value("frame", "world: right-handed, +Y up, the patient faces -Z, right is +X")
        acquisition = desc.append_child("acquisition")
        acquisition.append_child_value("manufacturer", "rehab-mocap")
        acquisition.append_child_value("model", "colour-marker multi-camera tracker")
        channels = desc.append_child("channels")
        for marker in names:
            for axis in "XYZ":
                channel = channels.append_child("channel")
                channel.append_child_value("label", f"{marker}_{axis}")
                channel.append_child_value("marker", marker)
                channel.append_child_value("type", f"Position{axis}")
                channel.append_child_value("unit", "millimeters")
        setup = desc.append_child("setup").append_child("markers")
        for marker in names:
            setup.append_child("marker").append_child_value("label", marker)
        angles = pylsl.StreamInfo(f"{name} angles", "Angles", len(angle_names), fps, "float32", f"{name}-angles")
        channels = angles.desc().append_child("channels")
        for angle in angle_names:
            channel = channels.append_child("channel")
            channel.append_child_value("label", angle)
            channel.append_child_value("unit", "degrees")
        angles.desc().append_child_value("definition", "docs/JOINT_ANGLES.md of rehab-mocap; NaN where undefined")
        status = pylsl.StreamInfo(f"{name} status", "Status", 1 + len(names), fps, "int16", f"{name}-status")
        channels = status.desc().append_child("channels")
        for label in ("state", *names):
            channels.append_child("channel").append_child_value("label", label)
        status.desc().append_child_value("codes", "state: 0 waiting for the reference pose, 1 tracking; "
                                                  "markers: 0 lost, 1 measured, 2 estimated")
        self.markers = pylsl.StreamOutlet(markers)
        self.angles = pylsl.StreamOutlet(angles)
        self.status = pylsl.StreamOutlet(status)
        self._status_row = np.zeros(1 + len(names), dtype=np.int16)

    def send(self, frame: StreamFrame) -> None:
        stamp = frame.t_ready_s + self._offset_s
        self.markers.push_sample((frame.positions_m * 1000.0).astype(np.float32).ravel(), stamp)
        self.angles.push_sample(frame.angles_deg.astype(np.float32), stamp)
        row = self._status_row
        row[0] = frame.state
        row[1:] = frame.status
        self.status.push_sample(row, stamp)

    def close(self) -> None:
        self.markers = self.angles = self.status = None  # outlets close when released


# ------------------------------------------------------------------------------------ OSC

#: The skeleton's joints (tracking/io/bvh.py) -> Unity's humanoid bone names (VMC).
VMC_BONES = {"Hips": "Hips", "Spine": "Spine", "Neck": "Neck", "Head": "Head",
             "RightArm": "RightUpperArm", "RightForeArm": "RightLowerArm", "RightHand": "RightHand",
             "LeftArm": "LeftUpperArm", "LeftForeArm": "LeftLowerArm", "LeftHand": "LeftHand"}


@functools.lru_cache(maxsize=1)
def _rest_to_t_pose() -> dict[str, np.ndarray]:
    """Per joint, the rotation C taking its T-pose rest direction to the skeleton's (arms hanging)."""
    from scipy.spatial.transform import Rotation  # lazy: scipy.spatial.transform (0.3 s to import) only for VMC output

    eye = np.eye(3)
    arm = {"Right": Rotation.from_euler("z", -90, degrees=True).as_matrix(),  # +X (T-pose) -> -Y (hanging)
           "Left": Rotation.from_euler("z", 90, degrees=True).as_matrix()}
    out = {name: eye for name in VMC_BONES}
    for side in ("Right", "Left"):
        for joint in ("Arm", "ForeArm", "Hand"):
            out[f"{side}{joint}"] = arm[side]
    return out


def vmc_bones(angles: dict[str, float], skeleton=None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Unity humanoid bone -> (local position (3,) metres, local rotation quaternion x, y, z, w),
    in Unity's axes (left-handed: x right, y up, z forward of the avatar), rotations relative to a
    T-pose (identity: the VRM rest pose)."""
    from scipy.spatial.transform import Rotation  # lazy: scipy.spatial.transform (0.3 s to import) only for VMC output

    # lazy: tracking.io.bvh loads scipy.spatial.transform: only for VMC output
    from tracking.io.bvh import JOINTS, BvhSkeleton, joint_offsets_m, local_rotations

    sk = skeleton or BvhSkeleton()
    local = {k: v[0] for k, v in local_rotations({k: np.array([v], np.float64) for k, v in angles.items()}).items()}
    offsets = joint_offsets_m(sk)
    rest = _rest_to_t_pose()
    flip = np.diag([1.0, 1.0, -1.0])  # ours (faces -Z, right-handed) -> Unity (faces +Z, left-handed)
    positions, rotations = [], []
    for joint, parent in JOINTS:
        c_parent = rest[parent] if parent else np.eye(3)
        normalised = c_parent.T @ local[joint] @ rest[joint]  # relative to the T-pose frames
        positions.append(flip @ (c_parent.T @ offsets[joint]))
        rotations.append(flip @ normalised @ flip)
    quats = Rotation.from_matrix(np.stack(rotations)).as_quat()  # one call for all bones
    return {VMC_BONES[joint]: (p, q) for (joint, _), p, q in zip(JOINTS, positions, quats)}


def _osc_message(address: str, *args) -> bytes:
    """One OSC message's bytes (python-osc's encoders: its builder also parses back each message it
    builds, which tripled the sender's time per frame set)."""
    from pythonosc.parsing import osc_types  # lazy: python-osc only when OSC output is on

    tags, body = [","], []
    for a in args:
        if isinstance(a, str):
            tags.append("s")
            body.append(osc_types.write_string(a))
        elif isinstance(a, int):
            tags.append("i")
            body.append(osc_types.write_int(a))
        else:
            tags.append("f")
            body.append(osc_types.write_float(a))
    return osc_types.write_string(address) + osc_types.write_string("".join(tags)) + b"".join(body)


class _OscBundle:
    """An OSC bundle to be sent at once (what ``UDPClient.send`` needs: its ``dgram``)."""

    def __init__(self, messages: list[bytes]) -> None:
        from pythonosc.parsing import osc_types  # lazy: python-osc only when OSC output is on

        parts = [osc_types.write_string("#bundle"), osc_types.write_date(osc_types.IMMEDIATELY)]
        for m in messages:
            parts.append(osc_types.write_int(len(m)))
            parts.append(m)
        self.dgram = b"".join(parts)


class OscOutput:
    """OSC bundles to one UDP target (module docstring)."""

    def __init__(self, target: tuple[str, int], names: tuple[str, ...], angle_names: tuple[str, ...]):
        from pythonosc.udp_client import SimpleUDPClient  # lazy: python-osc only when OSC output is on

        self.client = SimpleUDPClient(*target)
        self.names = names
        self.angle_names = angle_names
        self._held: dict[str, float] = {}
        vmc_bones(dict.fromkeys(ANGLE_COLUMNS, 0.0))  # first-call imports now, not while frame sets queue up

    def send(self, frame: StreamFrame) -> None:
        messages = [_osc_message("/rehab/frame", int(frame.frame_index), float(frame.time_s), int(frame.state))]
        for name, p, s in zip(self.names, frame.positions_m.tolist(), frame.status.tolist()):
            messages.append(_osc_message("/rehab/marker", name, p[0], p[1], p[2], int(s)))
        angles = dict(zip(self.angle_names, frame.angles_deg.tolist()))
        for name, value in angles.items():
            messages.append(_osc_message("/rehab/angle", name, value))
        self.client.send(_OscBundle(messages))
        self._send_vmc(angles, frame.time_s)

    def _send_vmc(self, angles: dict[str, float], time_s: float) -> None:
        for name in ANGLE_COLUMNS:  # the skeleton holds an undefined angle (tracking/io/bvh.py)
            value = angles.get(name, math.nan)
            if math.isfinite(value) or name not in self._held:
                self._held[name] = value if math.isfinite(value) else 0.0
        messages = [_osc_message("/VMC/Ext/OK", 1), _osc_message("/VMC/Ext/T", float(time_s)),
                    _osc_message("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)]
        for bone, (p, q) in vmc_bones(self._held).items():
            messages.append(_osc_message("/VMC/Ext/Bone/Pos", bone, *p.tolist(), *q.tolist()))
        self.client.send(_OscBundle(messages))

    def close(self) -> None:
        try:
            self.client._sock.close()
        except (AttributeError, OSError):
            pass
