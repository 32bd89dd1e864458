"""The game's side of the live tracker: start it without freezing the window, read it each frame.

:class:`tracking.live.LiveTracker` starts its process without waiting (``start(wait=False)``):
the window keeps drawing "Starting the tracker..." while the process imports the tracker and
builds its source. Afterwards :class:`LiveLink` touches the tracker once per frame, in
:meth:`LiveLink.tick`: new samples, and the process's health (``LiveTracker.status`` notices a
dead or hung process and hands over to a warm standby or restarts it, without blocking), turned
into a :class:`LinkState` the scenes show.

Commands (patient input, motion, re-identification) sent before the tracker runs are kept and
sent when it does (the newest of each kind).
"""

from __future__ import annotations

import enum
import logging
import math
import time
from typing import Callable

from calibration.errors import RehabError
from tracking.sources.cameras import is_pace_warning
from tracking.sources.recording import is_normal_end

log = logging.getLogger(__name__)


class LinkState(enum.Enum):
    STARTING = "starting"
    RUNNING = "running"
    RESTARTING = "restarting"
    FAILED = "failed"
    CLOSED = "closed"


class LiveLink:
    """Owns a live tracker for the application.

    Args:
        make_tracker: builds the (not yet started) tracker, e.g.
            ``lambda: LiveTracker(SourceConfig(...))``.
        start_timeout_s: how long the process may take to become ready before the link gives up.
        clock: seconds, monotonic (for the start timeout).
    """

    def __init__(self, make_tracker: Callable[[], object], *, start_timeout_s: float = 60.0,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self._make_tracker = make_tracker
        self._start_timeout_s = start_timeout_s
        self._clock = clock
        self.tracker = None
        self.state = LinkState.CLOSED
        self.error = ""
        self.status = None
        self.latest = None
        self.new_samples: list = []
        self.samples_received = 0
        self._started_s = math.nan
        self._pending: dict[str, tuple] = {}

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        """Create the tracker and spawn its process (returns at once; :meth:`tick` follows it)."""
        if self.state is not LinkState.CLOSED:
            return
        self.tracker = self._make_tracker()
        self._started_s = self._clock()
        try:
            self.tracker.start(self._start_timeout_s, wait=False)
        except RehabError as exc:
            # Shown by the scenes (and by the command line when headless): logged once, quietly.
            self.state, self.error = LinkState.FAILED, str(exc)
            log.info("the tracker cannot start: %s", self.error)
            return
        self.state = LinkState.STARTING

    def wait_ready(self, timeout_s: float, *, first_sample: bool = True) -> bool:
        """Block until the tracker runs (and, with ``first_sample``, has published a sample).

        For headless runs and tests; the window never blocks. Returns whether it got there.
        """
        deadline = time.perf_counter() + timeout_s
        while True:
            self.tick()
            done = self.state is LinkState.RUNNING and (self.latest is not None or not first_sample)
            if done or self.state in (LinkState.FAILED, LinkState.CLOSED) or time.perf_counter() >= deadline:
                return done
            time.sleep(0.02)

    def close(self) -> None:
        """Stop the tracker's processes (idempotent)."""
        if self.tracker is not None:
            self.tracker.close()
        self.state = LinkState.CLOSED

    # ------------------------------------------------------------------ per frame
    def tick(self) -> None:
        """Read new samples and the process's health (call once per frame)."""
        self.new_samples = []
        if self.state in (LinkState.CLOSED, LinkState.FAILED):
            return
        self.status = self.tracker.status()
        self.error = self.status.last_error
        if self.state is LinkState.STARTING:
            if not self.tracker.ready:
                if getattr(self.tracker, "gave_up", False):  # a missing camera: no use waiting longer
                    self.state = LinkState.FAILED
                    log.info("the tracker cannot start: %s", self.error)
                elif self._clock() - self._started_s > self._start_timeout_s:
                    self.state = LinkState.FAILED
                    self.error = (f"the tracker did not start within {self._start_timeout_s:g} s"
                                  + (f": {self.error}" if self.error else ""))
                    # shown by the scenes (and by the command line when headless): logged quietly
                    log.info("%s", self.error)
                return
            self.state = LinkState.RUNNING
            for method, args in self._pending.items():
                getattr(self.tracker, method)(*args)
            self._pending.clear()
        self.new_samples = self.tracker.poll()
        if self.new_samples:
            self.latest = self.new_samples[-1]
            self.samples_received += len(self.new_samples)
        self.state = LinkState.RUNNING if self.status.alive else LinkState.RESTARTING

    # ------------------------------------------------------------------ facts
    @property
    def ready(self) -> bool:
        """The tracker ran once (cameras, marker set and angle names are known)."""
        return self.state in (LinkState.RUNNING, LinkState.RESTARTING)

    @property
    def markerset(self):
        return self.tracker.markerset if self.ready else None

    @property
    def angle_names(self) -> tuple[str, ...]:
        return self.tracker.angle_names if self.ready else ()

    @property
    def cameras(self) -> tuple:
        return self.tracker.cameras if self.ready else ()

    @property
    def warning(self) -> str:
        """The source's warning line (e.g. a camera that stopped delivering frames), "" if none."""
        return getattr(self.status, "warning", "") if self.status is not None and self.ready else ""

    @property
    def source_fps(self) -> float:
        return self.status.source_fps if self.status is not None else math.nan

    def latest_images(self):
        return self.tracker.latest_images() if self.ready else None

    def problem(self) -> tuple[str, bool] | None:
        """What keeps samples from flowing, in words, and whether it is a failure (not a wait);
        None while the tracker runs."""
        if self.state is LinkState.STARTING:
            return "Starting the tracker...", False
        if self.state is LinkState.FAILED:
            return f"The tracker is not running: {self.error}", True
        if self.state is LinkState.RESTARTING:
            # what happened (killed, no heartbeat, cannot start: ...) so the therapist knows why
            return "The tracker stopped: restarting..." + (f" ({self.error})" if self.error else ""), False
        if self.state is LinkState.CLOSED:
            return "The tracker is off", True
        return None

    def run_problem(self) -> str:
        """At the end of a run: what kept the measurement from being whole, in one line ("" if
        nothing): the tracker not running, its errors, the source's warning (a camera that ended
        or stopped, a recording cut short; a recording played to its end, and frames dropped or out
        of step on a busy machine, are no failure)."""
        problem = self.problem()
        if problem is not None and self.state is not LinkState.CLOSED:
            return problem[0]
        status = self.status
        if status is not None and getattr(status, "errors", 0):
            return f"the tracker reported {status.errors} error(s), the last: {status.last_error}"

        # frames dropped on a busy machine weaken the measurement but do not fail the run
        kept = [w for w in self.warning.split("; ") if w and not is_pace_warning(w)] if self.warning else []
        line = "; ".join(kept)
        return "" if is_normal_end(line) else line

    def summary(self) -> str:
        """One line for the home screen."""
        if self.state is LinkState.RUNNING:
            kind = getattr(getattr(self.tracker, "source", None), "kind", "sim")
            what = "Simulated patient" if kind == "sim" else "Cameras"
            line = f"{what}: tracker running, {self.source_fps:.0f} frame sets/s"
            return f"{line}; {self.warning}" if self.warning else line
        problem = self.problem()
        return problem[0] if problem and self.state is not LinkState.CLOSED else ""

    # ------------------------------------------------------------------ commands
    def _command(self, method: str, *args) -> None:
        if self.ready:
            getattr(self.tracker, method)(*args)
        elif self.state is LinkState.STARTING:
            self._pending[method] = args

    def set_patient_input(self, value) -> None:
        self._command("set_patient_input", value)

    def set_motion(self, name: str | None) -> None:
        self._command("set_motion", name)

    def reidentify(self) -> None:
        self._command("reidentify")

    def set_colours(self, models, label_hs) -> None:
        """Track with taught marker colours (see :meth:`tracking.live.LiveTracker.set_colours`)."""
        self._command("set_colours", models, label_hs)
