"""The game's side of the live tracker: start it without freezing the window, read it each frame.

:class:`tracking.live.LiveTracker` spawns the tracker process and blocks until it is ready (a few
seconds: the process imports the tracker, opens the cameras or builds the simulated studio).
:class:`LiveLink` runs that start on a helper thread so that the window keeps drawing "Starting
the tracker...", and afterwards touches the tracker from the main thread only, once per frame in
:meth:`LiveLink.tick`: new samples, the process's health (``LiveTracker.status`` notices a dead
process and restarts it without blocking), and a :class:`LinkState` the scenes show.

Commands (patient input, motion, re-identification) sent before the tracker is ready are kept
and sent when it is.
"""

from __future__ import annotations

import enum
import logging
import math
import threading
import time
from typing import Callable

from calibration.errors import RehabError

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
            ``lambda: LiveTracker(SourceConfig(...))``; tests pass other objects with the same
            methods.
        start_timeout_s: how long the first start may take.
    """

    def __init__(self, make_tracker: Callable[[], object], *, start_timeout_s: float = 60.0) -> None:
        self._make_tracker = make_tracker
        self._start_timeout_s = start_timeout_s
        self.tracker = None
        self.state = LinkState.CLOSED
        self.error = ""
        self.status = None
        self.latest = None
        self.new_samples: list = []
        self.samples_received = 0
        self._thread: threading.Thread | None = None
        self._started = threading.Event()
        self._closing = threading.Event()
        self._start_error: str | None = None
        self._pending: dict[str, tuple] = {}

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        """Begin starting the tracker in the background (returns at once)."""
        if self.state is not LinkState.CLOSED:
            return
        self.state = LinkState.STARTING
        self.tracker = self._make_tracker()
        self._thread = threading.Thread(target=self._start_tracker, name="rehab-tracker-start", daemon=True)
        self._thread.start()

    def _start_tracker(self) -> None:
        try:
            self.tracker.start(self._start_timeout_s)
        except RehabError as exc:
            self._start_error = str(exc)
        except Exception as exc:  # reported on the screen and in the log, never lost in the thread
            log.exception("the tracker did not start")
            self._start_error = f"the tracker did not start: {exc}"
        finally:
            self._started.set()
        # The tracker process dies with the thread that spawned it (Linux PR_SET_PDEATHSIG
        # follows the thread, not the process): this thread lives until the link closes.
        self._closing.wait()

    def wait_ready(self, timeout_s: float, *, first_sample: bool = True) -> bool:
        """Block until the tracker runs (and, with ``first_sample``, has published a sample).

        For headless runs and tests; the window never blocks. Returns whether it got there.
        """
        deadline = time.perf_counter() + timeout_s
        if self._thread is not None:
            self._started.wait(timeout_s)
        while True:
            self.tick()
            done = self.state is LinkState.RUNNING and (self.latest is not None or not first_sample)
            if done or self.state in (LinkState.FAILED, LinkState.CLOSED) or time.perf_counter() >= deadline:
                return done
            time.sleep(0.02)

    def close(self) -> None:
        """Stop the tracker process (idempotent)."""
        if self.state is LinkState.CLOSED:
            return
        if self._thread is not None:
            self._started.wait(self._start_timeout_s)
        if self.tracker is not None:
            self.tracker.close()
        self._closing.set()
        if self._thread is not None:
            self._thread.join(1.0)
        self.state = LinkState.CLOSED

    # ------------------------------------------------------------------ per frame
    def tick(self) -> None:
        """Read new samples and the process's health (call once per frame, main thread)."""
        self.new_samples = []
        if self.state is LinkState.STARTING:
            if not self._started.is_set():
                return
            if self._start_error is not None:
                self.state, self.error = LinkState.FAILED, self._start_error
                log.error("%s", self.error)
                return
            self.state = LinkState.RUNNING
            for method, args in self._pending.values():
                getattr(self.tracker, method)(*args)
            self._pending.clear()
        if self.state not in (LinkState.RUNNING, LinkState.RESTARTING):
            return
        self.status = self.tracker.status()
        self.new_samples = self.tracker.poll()
        if self.new_samples:
            self.latest = self.new_samples[-1]
            self.samples_received += len(self.new_samples)
        self.state = LinkState.RUNNING if self.status.alive else LinkState.RESTARTING
        self.error = self.status.last_error

    # ------------------------------------------------------------------ facts
    @property
    def ready(self) -> bool:
        """The tracker started once (cameras, marker set and angle names are known)."""
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
    def source_fps(self) -> float:
        return self.status.source_fps if self.status is not None else math.nan

    def latest_images(self):
        return self.tracker.latest_images() if self.ready else None

    def summary(self) -> str:
        """One line for the home screen."""
        if self.state is LinkState.STARTING:
            return "Starting the tracker..."
        if self.state is LinkState.FAILED:
            return f"The tracker is not running: {self.error}"
        if self.state is LinkState.RESTARTING:
            return "The tracker stopped; restarting..."
        if self.state is LinkState.RUNNING:
            kind = getattr(getattr(self.tracker, "source", None), "kind", "sim")
            what = "Simulated patient" if kind == "sim" else "Cameras"
            return f"{what}: tracker running, {self.source_fps:.0f} frame sets/s"
        return ""

    # ------------------------------------------------------------------ commands
    def _command(self, method: str, *args) -> None:
        if self.ready:
            getattr(self.tracker, method)(*args)
        elif self.state is LinkState.STARTING:
            self._pending[method] = args  # the newest of each kind is what counts

    def set_patient_input(self, value) -> None:
        self._command("set_patient_input", value)

    def set_motion(self, name: str | None) -> None:
        self._command("set_motion", name)

    def reidentify(self) -> None:
        self._command("reidentify")
