"""The game's handle on the tracker process: :class:`LiveTracker`.

It creates the shared memory (so that it can release it whatever happens to the process),
spawns the tracker process (:func:`tracking.live.process.tracker_main`), sends it commands and
reads its samples. :meth:`LiveTracker.status`, called by the game every frame, notices a process
that died or hangs (heartbeat older than ``STALE_HEARTBEAT_S`` while it neither uses CPU time nor
waits for a CPU: a process that a loaded machine merely slows down or starves is not replaced; a
start likewise, see ``SLOW_START_S``) and replaces it without
waiting: a warm standby process (source and tracker already built) takes over, or a new
process starts; the game keeps drawing, the samples resume when the new process is ready. The
shared memory stays, so sample numbers and frame indices continue.

Cleanup: :meth:`LiveTracker.close` (also at interpreter exit) stops the process (killing it if it
does not stop in time) and unlinks the shared memory. Blocks are named
``rehab_live_<game pid>_<random>_<part>``, so that a later game can unlink what a crashed game
left behind (:func:`remove_stale_blocks`).
"""

from __future__ import annotations

import atexit
import logging
import math
import multiprocessing
import os
import secrets
import select
import signal
import threading
import time
from dataclasses import replace
from multiprocessing import shared_memory
from pathlib import Path

import numpy as np

from tracking.live.process import ProcessArgs, tracker_main
from tracking.live.protocol import (Activate, LiveError, LiveSample, LiveStatus, PatientInput, Pause, Reidentify, Resume,
                                    SetColours, SetMotion, SetPatientInput, SourceConfig, Stop)
from tracking.live.ring import ImageLayout, ImageSlot, ProcessState, RingLayout, RingReader, RingWriter, decode_line
from tracking.live.source import angle_names_for, resolve_config, source_geometry

log = logging.getLogger(__name__)

#: Prefix of every shared-memory block of the live tracker.
BLOCK_PREFIX = "rehab_live_"
#: A running process whose heartbeat is older than this, and which has neither used CPU time nor
#: waited for a CPU for as long, is taken as hung and restarted.
STALE_HEARTBEAT_S = 1.0
#: A process whose heartbeat is older than this is taken as hung even if it uses CPU time (a loop
#: that never returns to the heartbeat); a loaded machine slows a loop turn by a second or two,
#: not by this much.
SLOW_HEARTBEAT_S = 10.0
#: A starting process has this long to report ready (imports, GL context, rig), or, after it
#: reports the progress of a long stage (the first compilation of the tracker's loops), this long
#: again from then.
START_TIMEOUT_S = 30.0
#: A starting process that keeps working (using CPU time or waiting for a CPU) past
#: ``START_TIMEOUT_S`` is given this long from its spawn or its last progress message before it is
#: taken as hung: a start takes ~5 s of a core, and a machine whose cores other work takes may
#: give the process a tenth of one (a start killed as hung then starts again from nothing).
SLOW_START_S = 300.0
#: Time a process gets to stop on request before it is killed.
STOP_TIMEOUT_S = 2.0
#: How long :meth:`LiveTracker.close` waits for killed processes to be gone, so that none outlives
#: the tracker (a killed process dies within milliseconds on an idle machine; a loaded one may
#: take a second or more to schedule it).
REAP_TIMEOUT_S = 10.0
#: A process that reports it cannot start this many times more in a row makes :attr:`LiveTracker.gave_up`
#: true (a game still starting may then say why); it is tried again all the same (the cause may pass).
MAX_START_RETRIES = 3
#: A new standby process is started this long after the running one became ready, so that its
#: start-up does not compete with a process that is just taking over.
STANDBY_DELAY_S = 2.0
#: After a restart whose process could not start, wait this long before trying again; each
#: further failure in a row doubles the wait, up to RETRY_MAX_S.
RETRY_AFTER_S = 2.0
RETRY_MAX_S = 30.0
_SHM_DIR = Path("/dev/shm")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def remove_stale_blocks() -> list[str]:
    """Unlink the shared-memory blocks of live trackers whose game process is gone.

    Returns the names removed. Only Linux lists its blocks (``/dev/shm``); elsewhere this does
    nothing.
    """
    removed = []
    if not _SHM_DIR.is_dir():
        return removed
    for path in _SHM_DIR.glob(f"{BLOCK_PREFIX}*"):
        try:
            pid = int(path.name[len(BLOCK_PREFIX):].split("_", 1)[0])
        except ValueError:
            continue
        if pid != os.getpid() and not _pid_alive(pid):
            try:
                path.unlink()
                removed.append(path.name)
            except OSError as exc:
                log.warning("cannot remove the stale shared-memory block %s: %s", path, exc)
    if removed:
        log.info("removed %d shared-memory blocks left by a crashed game: %s", len(removed), ", ".join(removed))
    return removed


def _exit_reason(exitcode: int | None) -> str:
    if exitcode is None:
        return "stopped answering (no heartbeat)"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"was killed ({name})"
    return f"exited with code {exitcode}"


def process_cpu_s(pid: int) -> float:
    """CPU seconds (user + system, all threads) a process has used so far; NaN if unknown (not Linux)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def process_activity_s(pid: int) -> float:
    """Seconds a process has run (all threads) or waited for a CPU (its main thread, runnable but
    not scheduled) so far; NaN if unknown. A process whose figure does not grow is blocked or
    stopped; one that a loaded machine starves of CPU keeps waiting to run, and is not hung."""
    cpu_s = process_cpu_s(pid)
    try:
        with open(f"/proc/{pid}/schedstat") as f:
            wait_s = int(f.read().split()[1]) * 1e-9
    except (OSError, IndexError, ValueError):
        wait_s = 0.0   # no scheduler statistics (a kernel without them): CPU time alone
    return cpu_s + wait_s


_PF_EXITING = 0x4  # the kernel's task flag of a process that is ending (/proc/PID/stat, field 9)


def process_exiting(pid: int) -> bool:
    """The process is ending (killed, or returned from main) but not yet gone: a killed process
    with hundreds of megabytes and a GL context takes a noticeable time to be torn down. False
    where unknown (not Linux)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return False
    return fields[0] in ("Z", "X") or bool(int(fields[6]) & _PF_EXITING)


def _ending_reason(pid: int) -> str:
    """Why an ending process ends, as far as /proc tells: a pending SIGKILL, else "is ending"."""
    try:
        with open(f"/proc/{pid}/status") as f:
            pending = [int(line.split()[1], 16) for line in f if line.startswith(("SigPnd:", "ShdPnd:"))]
    except (OSError, ValueError, IndexError):
        pending = []
    return "was killed (SIGKILL)" if any(p & (1 << 8) for p in pending) else "is ending"


def _check_motion(name: str | None) -> None:
    """Raise :class:`LiveError` unless ``name`` is None, a built-in motion or an existing file."""
    if name is None:
        return
    # lazy: the simulator only when the simulated patient is the source (tests/test_layout.py)
    from tracking.sim.motions import available_motions

    if name not in available_motions() and not Path(name).is_file():
        raise LiveError(f"unknown motion {name!r}: choose one of {available_motions()} or give a motion file")


class _Child:
    """One tracker process and its end of the control pipe."""

    def __init__(self, ctx, args: ProcessArgs) -> None:
        self.conn, child_conn = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=tracker_main, args=(args, child_conn), name="rehab-tracker", daemon=True)
        self.proc.start()
        child_conn.close()
        self.standby = args.standby
        self.started_at = time.perf_counter()
        self.progress_at = self.started_at  # last sign of a start going on (its start, a progress message)
        self.ready = False  # reported ready (a standby: prepared and waiting)
        self.failed = ""  # why it could not start
        self.released = False  # joined and closed: the process is gone
        self.activated = False  # a standby told to take over (its start was done before)
        self._cpu_seen_s = math.nan  # its CPU time at the last look, and when that last grew
        self._cpu_grew_at = self.started_at

    @property
    def pid(self) -> int:
        return self.proc.pid

    def idle_for_s(self, now: float) -> float:
        """Seconds since this process last used CPU time or waited for a CPU (:func:`process_activity_s`),
        as far as these calls saw (call it often); infinite where the system does not tell (the
        heartbeat then decides alone)."""
        cpu_s = process_activity_s(self.proc.pid)
        if math.isnan(cpu_s):
            return math.inf
        if cpu_s != self._cpu_seen_s:
            self._cpu_seen_s, self._cpu_grew_at = cpu_s, now
        return now - self._cpu_grew_at

    def start_hung(self, now: float) -> bool:
        """A start that is not going on: no progress for ``START_TIMEOUT_S`` and for
        ``STALE_HEARTBEAT_S`` neither CPU time used nor a wait for a CPU (stopped, or blocked in a
        driver), or no progress for ``SLOW_START_S`` whatever it does."""
        since_s = now - self.progress_at
        if since_s <= START_TIMEOUT_S:
            return False
        return since_s > SLOW_START_S or self.idle_for_s(now) > STALE_HEARTBEAT_S

    def receive(self) -> None:
        """Read its messages: ("ready" | "standby", pid), ("progress", what) or ("failed", line)."""
        try:
            while self.conn.poll():
                kind, value = self.conn.recv()
                if kind in ("ready", "standby"):
                    self.ready = True
                    log.info("tracker process %d %s in %.2f s", value, "ready" if kind == "ready" else "standing by",
                             time.perf_counter() - self.started_at)
                elif kind == "progress":  # a long stage of the start (not hung): a new START_TIMEOUT_S
                    self.progress_at = time.perf_counter()
                    log.info("tracker process %d: %s", self.pid, value)
                elif kind == "failed":
                    self.failed = str(value)
        except (EOFError, OSError):
            pass  # it is gone: is_alive() says so

    def send(self, command) -> bool:
        try:
            self.conn.send(command)
            return True
        except (OSError, ValueError):
            return False

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> bool:
        """Ask it to stop, then terminate, then kill; join it. ``timeout_s`` 0: kill at once (a hung
        process; the game must not wait for it). True once the process is gone; False if it was
        killed but not yet reaped (stuck in the kernel, or a loaded machine has not scheduled its
        death yet): :meth:`reap` it later."""
        if self.released:
            return True
        proc = self.proc
        if proc.is_alive() and timeout_s > 0:
            self.send(Stop())
            proc.join(timeout_s)
            if proc.is_alive():
                proc.terminate()
                proc.join(0.5)
        if proc.is_alive():
            proc.kill()
            # a killed process is gone within milliseconds, unless stuck in the kernel (a driver)
            # or the machine is loaded: then it is reaped later rather than freezing the game
            proc.join(1.0 if timeout_s > 0 else 0.0)
        self.conn.close()
        return self.reap()

    def reap(self, timeout_s: float = 0.0) -> bool:
        """Wait up to ``timeout_s`` for a stopped process to be gone; True once it is (and its
        handle is released)."""
        if self.released:
            return True
        self.proc.join(timeout_s)
        if self.proc.exitcode is None:
            if self.proc.is_alive():
                self.proc.kill()  # again: harmless for a process already dying
            return False
        self.proc.close()
        self.released = True
        return True


class LiveTracker:
    """The tracker process as the game sees it (a context manager).

    Args:
        source: what to measure.
        ring_size: samples kept in the ring (how far the game may fall behind without losing any).
        auto_restart: :meth:`status` restarts a process that died or hangs.
        warm_standby: keep a second process prepared (source and tracker built, not publishing),
            so that a restart takes a frame or two instead of a process start (about 1.5 s on an
            idle machine, several seconds on a loaded one). Costs the memory of a second process
            and its start-up CPU shortly after :meth:`start`. Never for live cameras (a device
            opens in one process at a time).
        stream: a :class:`tracking.live.stream.StreamConfig`: the tracker process streams every
            sample over LSL and/or OSC (a standby opens its streams when it takes over).

    After :meth:`start`: ``cameras``, ``markerset`` and ``angle_names`` describe the samples.
    """

    def __init__(self, source: SourceConfig = SourceConfig(), *, ring_size: int = 256, auto_restart: bool = True,
                 warm_standby: bool = True, stream=None) -> None:
        self.source = source
        self.stream = stream
        self.ring_size = int(ring_size)
        self.auto_restart = auto_restart
        self.warm_standby = warm_standby and auto_restart
        self.cameras: tuple = ()
        self.markerset = None
        self.angle_names: tuple[str, ...] = ()
        self.restarts = 0
        self._ctx = multiprocessing.get_context("spawn")
        self._child: _Child | None = None
        self._spare: _Child | None = None
        self._stopping: list[_Child] = []  # killed, not yet reaped
        self._retry_at = 0.0
        self._spare_due: float | None = None
        self._failed_starts = 0   # starts the process itself reported impossible (counted to give up)
        self._lost_starts = 0   # starts whose process died before it was ready (killed: never give up)
        self._shm: list[shared_memory.SharedMemory] = []
        self._reader: RingReader | None = None
        self._images: ImageSlot | None = None
        self._args: ProcessArgs | None = None
        self._notify_r = None  # read end of the "new sample" pipe
        self._motion = source.motion
        self._input = PatientInput()
        self._paused = False
        self._colours: SetColours | None = None
        self._last_error = ""  # the newest of: why a process ended, the process's error line
        self._errors_seen = 0
        self._closed = True

    # ------------------------------------------------------------------ life cycle
    def start(self, timeout_s: float = START_TIMEOUT_S, *, wait: bool = True) -> None:
        """Create the shared memory, spawn the process and (``wait``) wait until it is ready.

        ``cameras``, ``markerset`` and ``angle_names`` are set before the process starts, so a
        game may call ``start(wait=False)`` and keep drawing: :attr:`ready` turns True (and
        ``status().state`` RUNNING) when the first samples can come, and a process that cannot
        start shows in ``status().last_error``.

        Raises:
            LiveError: the source cannot be opened (the message says why) or the process did not
                become ready within ``timeout_s``.
        """
        if not self._closed:
            return
        remove_stale_blocks()
        _check_motion(self._motion)
        self.source = resolve_config(self.source)
        cameras, markerset = source_geometry(self.source)
        self.cameras, self.markerset = cameras, markerset
        self.angle_names = angle_names_for(markerset)
        ring = RingLayout(markerset.n_markers, len(cameras), len(self.angle_names), self.ring_size)
        images = ImageLayout(len(cameras), tuple(self.source.size))
        stem = f"{BLOCK_PREFIX}{os.getpid()}_{secrets.token_hex(4)}"
        self._errors_seen = self._failed_starts = self._lost_starts = 0
        self._last_error = ""
        self._spare_due = None
        self._closed = False
        atexit.register(self.close)
        try:
            sample_shm = shared_memory.SharedMemory(f"{stem}_samples", create=True, size=ring.nbytes)
            self._shm.append(sample_shm)
            image_shm = shared_memory.SharedMemory(f"{stem}_images", create=True, size=images.nbytes)
            self._shm.append(image_shm)
            RingWriter(sample_shm.buf, ring, initialize=True).release()
            ImageSlot(image_shm.buf, images, initialize=True).release()
            self._reader = RingReader(sample_shm.buf, ring)
            self._images = ImageSlot(image_shm.buf, images)
            self._notify_r, notify_w = self._ctx.Pipe(duplex=False)
            os.set_blocking(self._notify_r.fileno(), False)
            self._args = ProcessArgs(self.source, sample_shm.name, image_shm.name, ring, images, os.getpid(),
                                     notify=notify_w, stream=self.stream)
            self._child = self._spawn(standby=False)
            if wait:
                self._wait_ready(timeout_s)
                if self._standby_allowed():
                    self._spare = self._spawn(standby=True)
        except BaseException:
            self.close()
            raise

    def _spawn(self, *, standby: bool) -> _Child:
        args = replace(self._args, config=replace(self.source, motion=self._motion), patient_input=self._input,
                       paused=self._paused, standby=standby,
                       die_with_parent=threading.current_thread() is threading.main_thread())
        if not standby:
            self._reader.header["state"] = ProcessState.STARTING
        child = _Child(self._ctx, args)
        log.info("tracker process %d started%s", child.pid, " (standby)" if standby else "")
        return child

    def _wait_ready(self, timeout_s: float) -> None:
        child = self._child
        deadline = time.perf_counter() + timeout_s
        while not child.ready:
            left = deadline - time.perf_counter()
            if left <= 0:
                raise LiveError(f"the tracker process did not start within {timeout_s:g} s: the machine may be "
                                "overloaded; try a smaller camera size")
            child.conn.poll(min(left, 0.1))
            child.receive()
            if child.failed:
                raise LiveError(f"the tracker process cannot start: {child.failed}")
            if not child.ready and not child.proc.is_alive():
                raise LiveError(f"the tracker process {_exit_reason(child.proc.exitcode)} while starting; "
                                "see the log above")

    def close(self) -> None:
        """Stop the process (killing it if it does not stop in time), release the shared memory.

        Idempotent; also runs at interpreter exit.
        """
        if self._closed:
            return
        self._closed = True
        atexit.unregister(self.close)
        try:
            if self._spare is not None:
                self._drop(self._spare)  # it publishes nothing: no need to wait for it
            if self._child is not None:
                self._drop(self._child, STOP_TIMEOUT_S)
        finally:
            self._child = self._spare = None
            self._reap_stopped(REAP_TIMEOUT_S)
            for part in (self._reader, self._images):
                if part is not None:
                    part.release()
            self._reader = self._images = None
            if self._args is not None and self._args.notify is not None:
                self._args.notify.close()
            if self._notify_r is not None:
                self._notify_r.close()
            self._args = self._notify_r = None
            for shm in self._shm:
                shm.close()
                try:
                    shm.unlink()
                except FileNotFoundError:
                    pass
            self._shm = []

    def __enter__(self) -> "LiveTracker":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ health
    def _heartbeat_age_s(self) -> float:
        hb = float(self._reader.header["heartbeat_s"])
        return time.perf_counter() - hb if hb > 0 else math.inf

    def _check(self) -> None:
        """Notice a dead or hung process; restart it when ``auto_restart``."""
        now = time.perf_counter()
        self._reap_stopped(0.0)
        self._tend_spare(now)
        child = self._child
        if child is None:  # an earlier start failed: try again later, with a growing wait, for as long as it takes
            if self.auto_restart and now >= self._retry_at:
                self._restart("")
            return
        if not child.ready:
            child.receive()
            if child.failed:
                self._last_error = f"the tracker process cannot start: {child.failed}"
                self._drop(child)
                self._child = None
                self._failed_starts += 1
                self._retry_at = now + self._backoff_s()
                return
            if child.ready:
                self._failed_starts = self._lost_starts = 0
        ending = child.proc.is_alive() and process_exiting(child.pid)   # a dying process is dead already
        alive = child.proc.is_alive() and not ending
        if alive and child.ready:
            if not self._hung(child, now):
                return
        elif alive and not child.start_hung(now):
            return  # still starting (slowly on a busy machine)
        if ending:
            child.proc.join(0.05)   # usually gone by then: its exit code says why
        if ending and child.proc.exitcode is None:
            why = _ending_reason(child.pid)
        else:
            why = _exit_reason(None if alive else child.proc.exitcode)
        reason = f"the tracker process {why}"
        if not child.ready:
            reason += " while starting"
        log.error("%s", reason)
        self._last_error = reason
        self._drop(child)
        self._child = None
        if not child.ready and child.activated:
            # a standby that died before it could take over (killed together with the running one,
            # as the out-of-memory killer does): a new process at once, no wait
            if self.auto_restart:
                self._restart("")
        elif not child.ready:
            # it died or hung before it ran (killed, out of memory): retry later with a growing wait,
            # for as long as it takes
            self._lost_starts += 1
            self._retry_at = now + self._backoff_s()
        elif self.auto_restart:
            self._restart(reason)

    def _backoff_s(self) -> float:
        """The wait before the next start: doubles with each failed or lost start in a row."""
        n = self._failed_starts + self._lost_starts
        return min(RETRY_MAX_S, RETRY_AFTER_S * 2.0 ** max(0, n - 1))

    def _hung(self, child: _Child, now: float) -> bool:
        """A ready process stopped beating: no heartbeat for ``STALE_HEARTBEAT_S`` and for as long
        neither CPU time used nor a wait for a CPU (stopped, or blocked), or no heartbeat for
        ``SLOW_HEARTBEAT_S``."""
        idle_s = child.idle_for_s(now)
        if int(self._reader.header["state"]) not in (ProcessState.RUNNING, ProcessState.PAUSED):
            return False
        age_s = self._heartbeat_age_s()
        return age_s > SLOW_HEARTBEAT_S or (age_s > STALE_HEARTBEAT_S and idle_s > STALE_HEARTBEAT_S)

    def _drop(self, child: _Child, timeout_s: float = 0.0) -> None:
        """Stop a process (``timeout_s`` 0: kill it without waiting, a hung or unneeded one); one
        not gone yet is reaped later."""
        if not child.stop(timeout_s):
            self._stopping.append(child)

    def _reap_stopped(self, timeout_s: float) -> None:
        """Join the killed processes, waiting up to ``timeout_s`` in all for them to be gone."""
        deadline = time.perf_counter() + timeout_s
        left = []
        for child in self._stopping:
            if not child.reap(max(0.0, deadline - time.perf_counter())):
                left.append(child)
        self._stopping = left
        if left and timeout_s > 0:
            log.warning("tracker processes %s did not end within %g s after being killed",
                        ", ".join(str(c.proc.pid) for c in left), timeout_s)

    def _tend_spare(self, now: float) -> None:
        """Keep one standby process (spawned once the running one is ready)."""
        spare = self._spare
        if spare is not None:
            spare.receive()
            if spare.failed or not spare.proc.is_alive() or process_exiting(spare.pid):
                log.warning("the standby tracker process %d ended: %s", spare.pid,
                            spare.failed or (_exit_reason(spare.proc.exitcode) if spare.proc.exitcode is not None
                                             else _ending_reason(spare.pid)))
                self._drop(spare)
                self._spare = None
        elif self._standby_allowed() and self._child is not None and self._child.ready:
            if self._spare_due is None:
                self._spare_due = now + STANDBY_DELAY_S
            elif now >= self._spare_due:
                self._spare_due = None
                self._spare = self._spawn(standby=True)

    def _standby_allowed(self) -> bool:
        """A standby would open the cameras a second time, which a camera device refuses."""
        return self.warm_standby and self.source.kind != "cameras"

    def _restart(self, reason: str) -> None:
        self.restarts += 1
        if reason:
            self._last_error = f"{reason}; restarted"
        spare, self._spare = self._spare, None
        if spare is not None and spare.proc.is_alive() and not process_exiting(spare.pid) and spare.send(Activate(self._motion, self._input, self._paused)):
            self._reader.header["state"] = ProcessState.STARTING
            spare.ready = False  # until it reports ready as the running process
            spare.standby = False
            spare.activated = True
            spare.started_at = spare.progress_at = time.perf_counter()
            self._child = spare
            log.info("standby tracker process %d takes over", spare.pid)
        else:
            if spare is not None:  # dying (killed together with the running one): reap it too
                self._drop(spare)
            self._child = self._spawn(standby=False)
        if self._colours is not None:  # taught colours outlive the process (read after it is ready)
            self._child.send(self._colours)

    @property
    def gave_up(self) -> bool:
        """Every start failed (the first and ``MAX_START_RETRIES`` more): the reason is
        ``status().last_error``. The tracker still tries again (every ``RETRY_MAX_S`` at most);
        a game that never had samples may stop waiting and say why."""
        return self._child is None and self._failed_starts > MAX_START_RETRIES

    @property
    def ready(self) -> bool:
        """The running process reported ready (samples flow)."""
        if self._child is not None and not self._child.ready:
            self._child.receive()
        return self._child is not None and self._child.ready

    @property
    def standby_ready(self) -> bool:
        """A standby process is prepared to take over."""
        if self._spare is not None:
            self._spare.receive()
        return self._spare is not None and self._spare.ready

    def status(self) -> LiveStatus:
        """The process's health; restarts a dead or hung process when ``auto_restart``."""
        if self._closed or self._reader is None:
            return LiveStatus(False, math.inf, self.restarts, self._last_error or "not started", math.nan, math.nan, 0)
        self._check()
        h = self._reader.header
        age = self._heartbeat_age_s()
        child = self._child
        # _check replaced (or, without auto_restart, dropped) a hung process: what is left is not hung
        alive = child is not None and child.ready and child.proc.is_alive()
        errors = int(h["errors"])
        if errors > self._errors_seen:
            self._errors_seen = errors
            self._last_error = self._reader.error_line()
        return LiveStatus(
            alive=alive,
            heartbeat_age_s=age,
            restarts=self.restarts,
            last_error=self._last_error,
            source_fps=float(h["source_fps"]) if alive else 0.0,
            tracker_ms=float(h["step_ms"]),
            dropped=self._reader.dropped,
            errors=errors,
            state=int(h["state"]) if child is not None else int(ProcessState.STOPPED),
            samples=int(h["written"]),
            warning=self._reader.warning_line(),
        )

    @property
    def pid(self) -> int | None:
        """The running tracker process's id (None when none runs)."""
        return None if self._child is None else self._child.pid

    # ------------------------------------------------------------------ samples
    def _sample(self, rec: np.ndarray) -> LiveSample:
        return LiveSample(
            frame_index=int(rec["frame_index"]),
            time_s=float(rec["time_s"]),
            t_frame_ready_s=float(rec["t_frame_ready_s"]),
            t_published_s=float(rec["t_published_s"]),
            state=int(rec["state"]),
            positions_m=rec["positions_m"],
            status=rec["status"],
            angles_deg=rec["angles_deg"],
            message=decode_line(rec["message"]),
            windows_px=rec["windows_px"],
            uv_px=rec["uv_px"],
            truth_m=rec["truth_m"],
            step_ms=float(rec["step_ms"]),
            source_ms=float(rec["source_ms"]),
            number=int(rec["number"]),
            angle_names=self.angle_names,
            stamps_s=rec["stamps_s"],
        )

    def poll(self) -> list[LiveSample]:
        """Every sample published since the last poll, oldest first (gaps only if ``dropped``)."""
        if self._reader is None:
            return []
        return [self._sample(rec) for rec in self._reader.read_new()]

    def poll_records(self) -> list[np.ndarray]:
        """Like :meth:`poll`, as raw shared-memory records (copies): cheaper for tight loops."""
        return [] if self._reader is None else self._reader.read_new()

    def wait(self, timeout_s: float) -> bool:
        """Block until a sample newer than the last :meth:`poll` is published, or ``timeout_s``
        passes; True if there is one. For a thread that records every sample (a ROM test) or a
        benchmark; a game loop simply polls once per frame."""
        if self._reader is None:
            return False
        deadline = time.perf_counter() + timeout_s
        fd = self._notify_r.fileno()
        while self._reader.written() <= self._reader.next_number:
            left = deadline - time.perf_counter()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                return self._reader.written() > self._reader.next_number
            try:
                while os.read(fd, 65536):
                    pass
            except BlockingIOError:
                pass
        return True

    def latest(self) -> LiveSample | None:
        """The newest sample (None before the first)."""
        rec = None if self._reader is None else self._reader.latest()
        return None if rec is None else self._sample(rec)

    def latest_images(self) -> list[np.ndarray] | None:
        """BGR images of the latest frame set, one per camera (None before the first)."""
        got = None if self._images is None else self._images.read()
        return None if got is None else got[1]

    # ------------------------------------------------------------------ commands
    def _send(self, command) -> None:
        # while restarting the command may be lost: the new process gets the state it sets
        # (motion, patient input, pause) when it starts or takes over
        if self._child is not None and not self._child.send(command):
            log.warning("the tracker process did not take %r (it is restarting)", command)

    def reidentify(self) -> None:
        """Identify the markers again (the simulated patient takes the reference pose)."""
        self._send(Reidentify())

    def set_motion(self, name: str | None) -> None:
        """Play a scripted motion in a loop from its start, or None for the interactive patient.

        Raises:
            LiveError: ``name`` is neither a built-in motion nor an existing motion file.
        """
        _check_motion(name)
        self._motion = name
        self._send(SetMotion(name))

    def set_source(self, source: SourceConfig, *, wait: bool = False) -> None:
        """Measure another source (rig, image size, body, kind...).

        The shared-memory layout depends on the cameras and the marker set, so the process and
        the blocks are replaced: samples start again from number 0, and ``cameras``, ``markerset``
        and ``angle_names`` change. A motion or patient input change needs only :meth:`set_motion`
        or :meth:`set_patient_input`.

        Raises:
            LiveError: as :meth:`start` (the configuration is checked before the running process
                is stopped, so a bad one leaves it running).
        """
        source.check()
        _check_motion(source.motion)
        source = resolve_config(source)
        source_geometry(source)
        self.close()
        self.source = source
        self._motion = source.motion
        self.start(wait=wait)

    def set_patient_input(self, value: PatientInput) -> None:
        """Drive the interactive patient (used when no scripted motion plays)."""
        self._input = value
        self._send(SetPatientInput(value))

    def set_colours(self, models, label_hs) -> None:
        """Track with these marker colours (models, (256, 256) uint8 labels; :mod:`tracking.colour.pick`)."""
        self._colours = SetColours(tuple(models), np.asarray(label_hs, np.uint8))
        self._send(self._colours)

    def pause(self) -> None:
        self._paused = True
        self._send(Pause())

    def resume(self) -> None:
        self._paused = False
        self._send(Resume())
