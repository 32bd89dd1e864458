"""The tracker process: owns the frame source and the tracker, publishes every sample.

:func:`tracker_main` is the process's picklable entry (multiprocessing ``spawn``). It attaches to
the shared memory the game created (:mod:`tracking.live.ring`), opens the source, reports
``("ready", ...)`` or ``("failed", line)`` on the control pipe and runs :class:`TrackerLoop`:

- the source is paced in real time at its frame rate (the game sees 30 frame sets/s), its time
  stamps are ``frame_index / fps``. A source tied to the clock (``paced_by_clock``: the simulated
  patient) behaves like a camera: frame set k is due at ``start + k / fps`` of the wall clock, and
  when the loop is late it grabs the frame set due now and drops the ones it missed, so the
  patient's motion keeps the clock's pace on a busy machine instead of playing in slow motion. A
  recording plays every frame set; when the loop falls behind it runs as fast as it can instead of
  bursting to catch up (:class:`Pacer`);
- each frame set is grabbed, tracked (:meth:`tracking.tracker.Tracker.step`) and published into
  the ring and the latest slot, then its images into the image block;
- an exception while grabbing or tracking a frame set is logged and published as the header's
  error line; the loop goes on with the next frame set;
- every loop turn writes the heartbeat and reads the control pipe (small frozen commands of
  :mod:`tracking.live.protocol`);
- the process dies with the game: ``PR_SET_PDEATHSIG`` on Linux, and a check of the parent's pid.

Before reporting ready it renders and tracks one frame set and forgets it (first-frame costs
such as shader compilation would otherwise stall the first heartbeats). A *standby* process
(``ProcessArgs.standby``) gets as far as that, reports ``("standby", pid)`` and waits for
:class:`~tracking.live.protocol.Activate`: the game keeps one so that replacing a dead process
takes a frame or two instead of a process start.

:meth:`TrackerLoop.step` is the per-frame work; tests call it directly, without a process.
"""

from __future__ import annotations

import ctypes
import logging
import math
import os
import signal
import sys
import time
from dataclasses import dataclass
from multiprocessing import shared_memory
from typing import Callable

import numpy as np

from calibration.errors import RehabError
from tracking.colour.adapt import ColourAdapter, table_from_colours
from tracking.colour.table import ColourTable
from tracking.live.protocol import (Activate, LiveError, Pause, PatientInput, Reidentify, Resume, SetColours, SetMotion, SetPatientInput,
                                    SourceConfig, Stop)
from tracking.live.ring import ImageLayout, ImageSlot, ProcessState, RingLayout, RingWriter, encode_line
from tracking.live.source import angle_names_for, learnt_colours_for, open_source
from tracking.live.stream import StreamFrame, StreamSender
from tracking.sources.base import FrameRequest, FrameSource, warnings_and_end
from tracking.sources.cameras import is_pace_warning

log = logging.getLogger(__name__)

#: Smoothing of the reported frame rate and step time (weight of the newest frame).
RATE_SMOOTHING = 0.1
#: Longest wait between two loop turns (heartbeat and commands stay responsive).
MAX_IDLE_S = 0.05
#: How often the loop checks that the game still runs.
PARENT_CHECK_S = 0.5
#: The same error is logged in full once, then every this many times.
LOG_EVERY = 100


@dataclass(frozen=True, slots=True)
class ProcessArgs:
    """Everything the tracker process needs (pickled by ``spawn``).

    Attributes:
        config: the source.
        sample_block, image_block: names of the shared-memory blocks the game created.
        ring: layout of the sample block.
        images: layout of the image block.
        parent_pid: the game's process id (the tracker exits when it is gone).
        patient_input: the interactive patient's input to start with.
        paused: start paused.
        standby: get ready (source, tracker), then wait for :class:`Activate` before publishing:
            a warm spare that takes over within a frame or two when the running process dies.
        notify: write end of a pipe (a ``multiprocessing`` Connection used only for its file
            descriptor) that gets one byte per published sample, so a reader can block until the
            next sample instead of polling; None: no notification.
        stream: a :class:`tracking.live.stream.StreamConfig`: LSL and OSC output of every sample
            from a sender thread of this process (None or all off: no streaming).
        die_with_parent: ask Linux to kill this process when the thread that spawned it ends
            (``PR_SET_PDEATHSIG`` follows the spawning *thread*, so the game sets it only when
            spawning from its main thread; the parent-pid check and the pipe's end-of-file cover
            the other cases within half a second).
    """

    config: SourceConfig
    sample_block: str
    image_block: str
    ring: RingLayout
    images: ImageLayout
    parent_pid: int
    patient_input: PatientInput = PatientInput()
    paused: bool = False
    standby: bool = False
    die_with_parent: bool = True
    notify: object = None
    stream: object = None


def one_line(where: str, frame_index: int, exc: BaseException) -> str:
    """A readable one-line error: what failed, at which frame, the exception's class and text."""
    text = " ".join(str(exc).split()) or "(no message)"
    return f"{where} error at frame {frame_index}: {type(exc).__name__}: {text}"


class Pacer:
    """When the loop's next frame set is due and, for a source tied to the clock, which one.

    Args:
        fps: the source's frame rate.
        now_s: the clock now (frame set ``index`` is due at once).
        index: the next frame set's number.
        drops: the source is tied to the clock (a camera, the simulated patient): frame set
            ``index + k`` is due ``k / fps`` after ``now_s`` whatever happens, and a late loop skips
            to the one due now. False: every frame set is grabbed, one period after the last one
            (after a stall the pace starts afresh: no burst of catch-up frames).
    """

    def __init__(self, fps: float, now_s: float, index: int, *, drops: bool) -> None:
        self.period_s = 1.0 / float(fps)
        self.drops = drops
        self.restart(now_s, index)

    def restart(self, now_s: float, index: int) -> None:
        """Frame set ``index`` is due now (the start, the end of a pause)."""
        self._t0_s, self._index0, self._next_due_s = now_s, index, now_s

    def wait_s(self, now_s: float, index: int) -> float:
        """Seconds until frame set ``index`` is due (zero or less: due now)."""
        if self.drops:
            return self._t0_s + (index - self._index0) * self.period_s - now_s
        return self._next_due_s - now_s

    def to_grab(self, now_s: float, index: int) -> int:
        """The frame set to grab now that ``index`` is due: the latest one due for a source tied
        to the clock (those in between are dropped), else ``index``."""
        if not self.drops:
            return index
        return max(index, self._index0 + int((now_s - self._t0_s) / self.period_s + 1e-9))

    def grabbed(self, now_s: float) -> None:
        """A frame set was grabbed and tracked (``now_s``: the clock after it)."""
        if not self.drops:
            self._next_due_s += self.period_s
            if now_s - self._next_due_s > self.period_s:  # fell behind: go on from now
                self._next_due_s = now_s


class TrackerLoop:
    """Grabs, tracks and publishes frame sets.

    Args:
        source: the frame source.
        writer: the sample block's writer.
        images: the image block (None: images are not published).
        fps: the source's frame rate (time stamps are ``frame_index / fps``).
        tracker: the tracker (default: one for the source's cameras and marker set).
        clock: ``time.perf_counter`` (injected in tests).
        notify_fd: non-blocking pipe end that gets one byte per published sample (or None).
        adapter: a :class:`tracking.colour.adapt.ColourAdapter` whose table the tracker reads; it
            learns from every tracked frame set (None: the colour table stays fixed).
        streamer: a :class:`tracking.live.stream.StreamSender` offered every tracked frame set
            (it queues or drops, never blocks); None: no streaming.
    """

    def __init__(self, source: FrameSource, writer: RingWriter, images: ImageSlot | None, *, fps: float,
                 tracker=None, clock: Callable[[], float] = time.perf_counter, notify_fd: int | None = None,
                 adapter=None, streamer=None) -> None:
        # lazy: the tracker only in the tracker process (the game imports this module)
        from tracking.tracker import Tracker

        self.source = source
        self.writer = writer
        self.images = images
        self.fps = float(fps)
        self.tracker = tracker or Tracker(source.cameras, source.markerset, fps=self.fps)
        self.angle_names = angle_names_for(source.markerset)
        self.clock = clock
        self.notify_fd = notify_fd
        self.adapter = adapter
        self.streamer = streamer
        self.paused = False
        self.dropped_frames = 0  # frame sets of a source tied to the clock skipped because the loop was late
        self._fps_ema = math.nan
        self._step_ema = math.nan
        self._last_ready = math.nan
        self._error_counts: dict[str, int] = {}
        self._warning = ""
        self._raw_warnings: tuple[str, ...] = ()
        last = writer.latest_frame_index()
        self.frame_index = 0 if last is None else last + 1
        m, c = source.markerset.n_markers, len(source.cameras)
        self._nan_windows = np.full((m, c, 3), np.nan)
        self._nan_uv = np.full((m, c, 2), np.nan)
        self._nan_truth = np.full((m, 3), np.nan)
        self._shapes = [(cam.size_px[1], cam.size_px[0], 3) for cam in source.cameras]

    # ------------------------------------------------------------------ commands
    def handle(self, command: object) -> bool:
        """Apply one command; False when it asks the loop to stop."""
        if isinstance(command, Stop):
            return False
        if isinstance(command, Pause):
            self.paused = True
        elif isinstance(command, Resume):
            self.paused = False
        elif isinstance(command, Reidentify):
            self.tracker.reidentify()
            self.source.handle(command)
        elif isinstance(command, (SetMotion, SetPatientInput)):
            try:
                self.source.handle(command)
            except Exception as exc:  # a bad motion name must not stop the tracker
                self._report("source", exc)
                return True
            if isinstance(command, SetMotion):  # the new motion starts from the reference pose
                self.tracker.reidentify()
        elif isinstance(command, SetColours):
            try:
                self.set_colours(command.models, command.label_hs)
            except Exception as exc:  # bad colours must not stop the tracker: it keeps its table
                self._report("colours", exc)
        else:
            log.warning("unknown command %r ignored", command)
        return True

    def set_colours(self, models, label_hs) -> None:
        """Track with these colours from the next frame set (an adapter, if any, starts from them)."""
        models = list(models)
        label_hs = np.asarray(label_hs, np.uint8).reshape(256, 256)
        if len(models) != self.source.markerset.palette.shape[0] or int(label_hs.max()) > len(models):
            raise LiveError(f"{len(models)} colours given for a marker set of {self.source.markerset.palette.shape[0]}")
        if self.adapter is not None:
            self.adapter = ColourAdapter(self.source.cameras, self.source.markerset, start=(models, label_hs),
                                         every=self.adapter.every)
            self.tracker.set_colour_table(self.adapter.table)
        else:
            self.tracker.set_colour_table(table_from_colours(models, label_hs))
        log.info("tracking with taught colours")

    # ------------------------------------------------------------------ the step
    def step(self) -> bool:
        """Grab, track and publish one frame set; False if it failed (the error is published)."""
        # lazy: the tracker only in the tracker process (the game imports this module)
        from tracking.tracker import TrackingState

        index = self.frame_index
        time_s = index / self.fps
        try:
            frame = self.source.read(FrameRequest(index, time_s, self.tracker.state == TrackingState.TRACKING))
            if frame is None:  # the source ended (a recording): nothing more to track
                self._warn(warnings_and_end(self.source))
                return False
            self._check_images(frame.images)
        except Exception as exc:
            self.frame_index += 1
            self._report("source", exc, index)
            return False
        self.frame_index += 1
        self._warn(self.source.warnings())
        if math.isfinite(frame.time_s):
            time_s = frame.time_s
        t0 = self.clock()
        self.writer.header["heartbeat_s"] = t0
        try:
            sample = self.tracker.step(frame.images, time_s, frame.stamps_s)
        except Exception as exc:
            self._report("tracker", exc, index)
            return False
        if self.adapter is not None:
            try:  # learning from this frame set's markers; a failure must not stop the tracking
                self.adapter.observe(frame.images, sample.positions_m, sample.status)
            except Exception as exc:
                self._report("colour adaptation", exc, index)
        step_ms = (self.clock() - t0) * 1000.0
        self._publish(index, time_s, frame, sample, step_ms)
        if self.streamer is not None:
            self._stream(index, time_s, frame, sample)
        if self.images is not None:
            self.images.write(frame.images, index)
        self._rates(frame.t_ready_s, step_ms)
        return True

    def _warn(self, warnings) -> None:
        """Publish the source's current warnings when they change (compared as given, so the
        frames without a change cost one tuple comparison)."""
        warnings = tuple(warnings)
        if warnings == self._raw_warnings:
            return
        self._raw_warnings = warnings

        # failures first: the published line has a length limit, and what it cuts must be the
        # pace warnings (frames dropped on a busy machine), never a stopped camera
        line = "; ".join(sorted(warnings, key=is_pace_warning))
        if line != self._warning:
            self._warning = line
            self.writer.set_warning(line)

    def _check_images(self, images) -> None:
        """The source delivers what the cameras are calibrated for (the tracker trusts it)."""
        if len(images) != len(self._shapes):
            raise LiveError(f"the source delivered {len(images)} images for {len(self._shapes)} cameras")
        for cam, img, shape in zip(self.source.cameras, images, self._shapes):
            if img.shape != shape or img.dtype != np.uint8:
                h, w = img.shape[:2]
                raise LiveError(f"camera {cam.name} delivered {w}x{h} {img.dtype} images but is calibrated for "
                                f"{shape[1]}x{shape[0]} uint8 BGR: recalibrate or set the camera size")

    def _publish(self, index: int, time_s: float, frame, sample, step_ms: float) -> None:
        rec = self.writer.scratch
        rec["frame_index"] = index
        rec["time_s"] = time_s
        rec["t_frame_ready_s"] = frame.t_ready_s
        rec["step_ms"] = step_ms
        rec["source_ms"] = frame.source_ms
        rec["state"] = int(sample.state)
        rec["positions_m"] = sample.positions_m
        rec["status"] = sample.status
        angles = sample.angles_deg
        rec["angles_deg"] = [angles.get(n, math.nan) for n in self.angle_names]
        windows = getattr(sample, "windows_px", None)
        rec["windows_px"] = self._nan_windows if windows is None else windows
        uv = getattr(sample, "uv_px", None)
        rec["uv_px"] = self._nan_uv if uv is None else uv
        rec["truth_m"] = self._nan_truth if frame.truth_m is None else frame.truth_m
        rec["stamps_s"] = time_s if frame.stamps_s is None else frame.stamps_s  # (None: taken at the set's instant)
        rec["message"] = encode_line(sample.message)
        rec["t_published_s"] = self.clock()
        self.writer.publish()
        if self.notify_fd is not None:
            try:
                os.write(self.notify_fd, b"\1")
            except (BlockingIOError, BrokenPipeError):
                pass  # the reader is far behind (the pipe is full) or gone: the ring has the sample

    def _stream(self, index: int, time_s: float, frame, sample) -> None:
        angles = sample.angles_deg
        self.streamer.offer(StreamFrame(
            frame_index=index, time_s=time_s, t_ready_s=frame.t_ready_s, state=int(sample.state),
            positions_m=np.array(sample.positions_m, dtype=np.float64), status=np.array(sample.status),
            angles_deg=np.array([angles.get(n, math.nan) for n in self.angle_names], dtype=np.float64)))

    def _rates(self, t_ready_s: float, step_ms: float) -> None:
        h = self.writer.header
        a = RATE_SMOOTHING
        if math.isfinite(self._last_ready) and t_ready_s > self._last_ready:
            dt = t_ready_s - self._last_ready
            self._fps_ema = dt if math.isnan(self._fps_ema) else (1 - a) * self._fps_ema + a * dt
            h["source_fps"] = 1.0 / self._fps_ema
        self._last_ready = t_ready_s
        self._step_ema = step_ms if math.isnan(self._step_ema) else (1 - a) * self._step_ema + a * step_ms
        h["step_ms"] = self._step_ema

    def _report(self, where: str, exc: BaseException, index: int | None = None) -> None:
        line = one_line(where, self.frame_index - 1 if index is None else index, exc)
        self.writer.set_error(line)
        key = f"{where}:{type(exc).__name__}"  # not the text: it may name the frame
        n = self._error_counts.get(key, 0)
        self._error_counts[key] = n + 1
        if n % LOG_EVERY == 0:
            log.error("%s (%d times)", line, n + 1, exc_info=n == 0)

    # ------------------------------------------------------------------ the loop
    def run(self, conn, parent_pid: int | None = None) -> None:
        """Pace, step and obey commands until :class:`Stop`, a closed pipe, or the parent's death."""
        h = self.writer.header
        pacer = Pacer(self.fps, self.clock(), self.frame_index, drops=bool(getattr(self.source, "paced_by_clock", False)))
        next_parent_check = self.clock() + PARENT_CHECK_S
        try:
            while True:
                now = self.clock()
                h["heartbeat_s"] = now
                h["state"] = ProcessState.PAUSED if self.paused else ProcessState.RUNNING
                while conn.poll():
                    if not self.handle(conn.recv()):
                        return
                if parent_pid is not None and now >= next_parent_check:
                    next_parent_check = now + PARENT_CHECK_S
                    if os.getppid() != parent_pid:
                        log.warning("the game (pid %d) is gone: the tracker process exits", parent_pid)
                        return
                if self.paused:
                    conn.poll(MAX_IDLE_S)
                    pacer.restart(self.clock(), self.frame_index)
                    continue
                wait_s = pacer.wait_s(now, self.frame_index)
                if wait_s > 0:
                    conn.poll(min(wait_s, MAX_IDLE_S))
                    continue
                index = pacer.to_grab(now, self.frame_index)
                self.dropped_frames += index - self.frame_index
                self.frame_index = index
                self.step()
                pacer.grabbed(self.clock())
        except (EOFError, BrokenPipeError, ConnectionResetError):
            log.warning("the control pipe closed: the tracker process exits")
        finally:
            h["state"] = ProcessState.STOPPED


def _die_with_parent(parent_pid: int, pdeathsig: bool) -> None:
    """Ask Linux to kill this process when the game dies; exit now if it already has."""
    if pdeathsig and sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            PR_SET_PDEATHSIG = 1
            libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError) as exc:  # the parent-pid check still applies
            log.debug("prctl(PR_SET_PDEATHSIG) unavailable: %s", exc)
    if os.getppid() != parent_pid:
        os._exit(0)


def _wait_for_activation(conn, parent_pid: int) -> Activate | None:
    """A standby process waits here until the game activates it (None: stop instead)."""
    try:
        while True:
            if conn.poll(PARENT_CHECK_S):
                command = conn.recv()
                if isinstance(command, Activate):
                    return command
                if isinstance(command, Stop):
                    return None
            elif os.getppid() != parent_pid:
                return None
    except (EOFError, OSError):
        return None


def tracker_main(args: ProcessArgs, conn) -> None:
    """Entry of the tracker process (see the module docstring)."""
    _die_with_parent(args.parent_pid, args.die_with_parent)
    # Mesa llvmpipe (the simulated cameras' renderer) rasterizes in this thread rather than on
    # threads of its own: its 4 small images fit the frame period on one core, and its extra
    # threads would only compete with the game's renderer for the machine's cores (~4 % less
    # CPU per frame set, measured). Set before the first GL context; an explicit value wins.
    os.environ.setdefault("LP_NUM_THREADS", "0")
    # Ctrl-C in the terminal reaches the whole process group: the game decides when we stop.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # The game created the blocks and unlinks them; attaching registers them again with the
    # resource tracker that spawn shares with the game, which is harmless (a set of names).
    sample_shm = shared_memory.SharedMemory(args.sample_block)
    image_shm = shared_memory.SharedMemory(args.image_block)
    writer = images = source = streamer = None
    try:
        writer = RingWriter(sample_shm.buf, args.ring)
        h = writer.header
        if not args.standby:  # a standby leaves the header to the running process
            h["pid"] = os.getpid()
            h["state"] = ProcessState.STARTING
            h["heartbeat_s"] = time.perf_counter()
        images = ImageSlot(image_shm.buf, args.images)
        try:
            source = open_source(args.config)
            _check_geometry(source, args)
            tracker, adapter = make_tracker(args.config, source)
            _warm_up(source, tracker, progress=lambda what: conn.send(("progress", what)))
        except Exception as exc:
            line = " ".join(str(exc).split()) or type(exc).__name__
            # A user's error (a missing camera, a bad file) reaches the game, which says it once; a
            # bug is logged here with its traceback.
            user_error = _is_user_error(exc)
            log.log(logging.INFO if user_error else logging.ERROR, "the tracker process cannot start: %s", line,
                    exc_info=not user_error)
            if not args.standby:
                writer.set_error(f"cannot start: {line}")
                h["state"] = ProcessState.FAILED
            conn.send(("failed", line))
            return
        motion, patient_input, paused = args.config.motion, args.patient_input, args.paused
        if args.standby:
            conn.send(("standby", os.getpid()))
            go = _wait_for_activation(conn, args.parent_pid)
            if go is None:
                return
            h["pid"] = os.getpid()
            h["heartbeat_s"] = time.perf_counter()
            patient_input, paused = go.patient_input, go.paused
            motion = go.motion
        notify_fd = None
        if args.notify is not None:
            notify_fd = args.notify.fileno()
            os.set_blocking(notify_fd, False)
        streamer = _open_streamer(args, source, writer)
        loop = TrackerLoop(source, writer, images, fps=args.config.fps, tracker=tracker, notify_fd=notify_fd,
                           adapter=adapter, streamer=streamer)
        if motion != args.config.motion:
            loop.handle(SetMotion(motion))
        loop.handle(SetPatientInput(patient_input))
        loop.paused = paused
        conn.send(("ready", os.getpid()))
        loop.run(conn, args.parent_pid)
    except (EOFError, BrokenPipeError, ConnectionResetError):
        log.warning("the control pipe closed: the tracker process exits")
    finally:
        if streamer is not None:
            streamer.close()
        if source is not None:
            source.close()
        for part in (writer, images):
            if part is not None:
                part.release()
        sample_shm.close()
        image_shm.close()


def _open_streamer(args: ProcessArgs, source: FrameSource, writer: RingWriter):
    """The stream sender that ``args.stream`` asks for, or None. A failure to open the streams
    (a missing library, a bad address) becomes the error line; tracking goes on without them."""
    if args.stream is None or not args.stream.enabled:
        return None

    ms = source.markerset
    try:
        return StreamSender(args.stream, ms.names, ms.name, angle_names_for(ms), args.config.fps)
    except Exception as exc:
        line = one_line("streaming", 0, exc)
        log.error("%s; tracking goes on without streaming", line)
        writer.set_error(line)
        return None


def make_tracker(config: SourceConfig, source: FrameSource):
    """The tracker for a source, and its colour adapter (None unless ``config.adapt_colours``).

    The colour table: the colours learnt into the source's calibration file when it holds them
    (``rehab calibrate colour``), else the marker set's nominal table; with ``adapt_colours`` it
    is the adapter's table, starting from the same colours.
    """
    from tracking.tracker import Tracker  # lazy: the tracker only in the tracker process (the game imports this module)

    learnt = learnt_colours_for(config, source.markerset)
    if learnt is not None:
        log.info("tracking with the marker colours learnt into the calibration")
    adapter = None
    if config.adapt_colours:
        # learning once a second: a drift over a few seconds is followed (every 2 s lost markers on a 4-s
        # ramp, tests/test_live_colours.py) for ~0.8 ms per frame set at 30 fps (docs/COLOUR.md)
        adapter = ColourAdapter(source.cameras, source.markerset, start=learnt, every=max(1, round(config.fps)))
        table = adapter.table
    elif learnt is not None:
        table = table_from_colours(*learnt)
    else:
        table = ColourTable.build(source.markerset.palette)
    return Tracker(source.cameras, source.markerset, table=table, fps=config.fps), adapter


def _warm_up(source: FrameSource, tracker, progress=lambda what: None) -> None:
    """Render and track one frame set before reporting ready, then forget it.

    The first frame set pays one-off costs (shader compilation, first-touch allocations, the
    full-frame identification, the tracker's compiled loops) that would otherwise stall the first
    heartbeats. ``progress`` is told before a long stage (the game then gives the start another
    ``START_TIMEOUT_S``).
    """
    frame = source.read(FrameRequest(0, 0.0, False))
    if frame is None:
        reason = "; ".join(warnings_and_end(source)) or "it ended at once"
        raise LiveError(f"the source delivered no frame set: {reason}")
    tracker.step(frame.images, 0.0)
    compile_loops = getattr(tracker, "compile_loops", None)  # (a test's stand-in tracker may lack it)
    if compile_loops is not None:
        # numba's first compilation: seconds without its disk cache (10 s on a busy machine), so
        # the game is told that the start goes on, lest it take the process for hung
        progress("compiling the tracker's loops")
        compile_loops(frame.images)
    tracker.reset()
    source.handle(Reidentify())  # a motion starts again from its reference pose


def _is_user_error(exc: BaseException) -> bool:
    return isinstance(exc, RehabError)


def _check_geometry(source: FrameSource, args: ProcessArgs) -> None:
    m, c = source.markerset.n_markers, len(source.cameras)
    if (m, c) != (args.ring.n_markers, args.ring.n_cameras):
        raise LiveError(f"the source has {m} markers and {c} cameras but the game expected "
                        f"{args.ring.n_markers} and {args.ring.n_cameras}")
    sizes = {tuple(cam.size_px) for cam in source.cameras}
    if sizes != {tuple(args.images.size_px)}:
        raise LiveError(f"the source's cameras deliver {sorted(sizes)} but the game expected {args.images.size_px}")
