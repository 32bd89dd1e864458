"""The application: a scene stack driven by a fixed-timestep loop with interpolated rendering.

One :class:`App` owns the screen, the 2D canvas, the input mapper and the scenes; nothing here is
global. The clock is a callable handed in (tests pass a fake one), settings are a frozen
:class:`Settings` passed down, and whatever the scenes share (the tracker link; later scores) is
an explicit :class:`Services` object.

Per frame (:meth:`App.frame`): pygame events -> :class:`game.input.InputMapper` -> the top
scene's :meth:`Scene.handle`; then :class:`FixedStep` says how many fixed updates of
``1 / update_hz`` seconds fit in the time elapsed (the frame time is capped, so a stall never
triggers a burst of catch-up steps); each calls :meth:`Scene.update`; finally the scene draws
with ``alpha``, the fraction of an update step elapsed since the last one, so that motion is
drawn between the last two updates rather than jumping at update rate.

The frame is pipelined for a software rasterizer (Mesa llvmpipe rasterizes on threads of its own
once commands are flushed): the scene's CPU-only work of frame k (:meth:`Scene.prepare`: tracker
samples, skeleton, interpolation, solids) runs while llvmpipe still rasterizes frame k-1; then
frame k-1 is presented (the swap waits for it), frame k's drawing commands are issued and flushed,
and the loop goes on. A frame is shown one frame period later than when drawn serially; the
machine's cores work on the Python side and the pixels at the same time.

:meth:`App.run` paces frames to deadlines one period apart: ``1 / max_fps``, doubled while a busy
machine keeps frames late (:class:`game.pacing.FramePacer`): an even half rate rather than an
uneven full one.
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Protocol

import pygame

from game.gfx.canvas import Canvas
from game.gfx.render_scale import RenderScaler
from game.gfx.screen import Screen
from game.gfx import theme
from game.input import Action, InputEvent, InputMapper, Press
from game.pacing import FramePacer

log = logging.getLogger(__name__)

Clock = Callable[[], float]


@dataclass(frozen=True, slots=True)
class Settings:
    """How the application runs (passed down; never a module global).

    Attributes:
        window_px: window or offscreen framebuffer (width, height).
        update_hz: fixed update rate of the game logic.
        max_fps: frames drawn per second at most (0: as many as possible); the window's vsync
            may cap lower.
        max_frame_s: longest frame time the logic catches up on (a stall is not replayed).
        show_fps: draw the frame rate in the corner.
        title: window caption.
        render_scale: a fixed scale (0 < s <= 1) of the 3D views' pixels along each axis; None:
            dynamic, lowered down to half when frames take longer than the frame budget
            (:mod:`game.gfx.render_scale`; on llvmpipe the upscale costs more than it saves).
        adaptive_pace: halve the frame rate while frames keep missing ``max_fps`` (a busy
            machine), trying the full rate again now and then (:mod:`game.pacing`).
    """

    window_px: tuple[int, int] = (1280, 720)
    update_hz: float = 120.0
    max_fps: float = 60.0
    max_frame_s: float = 0.25
    show_fps: bool = True
    title: str = "rehab: motion capture for rehabilitation"
    render_scale: float | None = 1.0
    adaptive_pace: bool = True

    def __post_init__(self) -> None:
        if self.update_hz <= 0 or self.max_fps < 0 or self.max_frame_s <= 0:
            raise ValueError("Settings: update_hz and max_frame_s must be positive, max_fps >= 0")
        if self.render_scale is not None and not 0.0 < self.render_scale <= 1.0:
            raise ValueError("Settings: render_scale is in (0, 1] or None")


class FixedStep:
    """Fixed-timestep accounting: how many updates a frame runs, and the leftover fraction.

    Args:
        step_s: the update period.
        max_frame_s: elapsed time beyond this per frame is dropped.
        now_s: the clock's current reading.
    """

    def __init__(self, step_s: float, max_frame_s: float, now_s: float) -> None:
        self.step_s = float(step_s)
        self.max_frame_s = float(max_frame_s)
        self._last_s = float(now_s)
        self._accumulated_s = 0.0
        self.total_steps = 0

    def advance(self, now_s: float) -> int:
        """Account for the time since the last call; returns the updates to run now."""
        frame_s = min(max(now_s - self._last_s, 0.0), self.max_frame_s)
        self._last_s = now_s
        self._accumulated_s += frame_s
        steps = int(self._accumulated_s / self.step_s + 1e-9)
        self._accumulated_s = max(self._accumulated_s - steps * self.step_s, 0.0)
        self.total_steps += steps
        return steps

    @property
    def alpha(self) -> float:
        """Fraction (0..1) of an update step elapsed since the last update."""
        return min(self._accumulated_s / self.step_s, 1.0)


class RateMeter:
    """Frames per second over a sliding window of recent frame intervals."""

    def __init__(self, window: int = 60) -> None:
        self._intervals: deque[float] = deque(maxlen=window)
        self._work: deque[float] = deque(maxlen=window)

    def add(self, interval_s: float, work_s: float) -> None:
        self._intervals.append(interval_s)
        self._work.append(work_s)

    @property
    def fps(self) -> float:
        """Frames shown per second."""
        total = sum(self._intervals)
        return len(self._intervals) / total if total > 0 else math.nan

    @property
    def work_ms(self) -> float:
        """Mean time spent making a frame (events, updates, drawing; not the pacing sleep)."""
        return 1000.0 * sum(self._work) / len(self._work) if self._work else math.nan


@dataclass(frozen=True, slots=True)
class Frame:
    """What a scene draws with.

    Attributes:
        screen: the GL context and target (3D passes use ``screen.ctx``).
        canvas: the 2D layer (between ``canvas.begin()`` and ``canvas.end()``, done by the app).
        alpha: fraction of an update step since the last update, for interpolation.
        size_px: (width, height) of the frame.
        render_scale: share of the pixels (along each axis) 3D views render; pass it to
            :meth:`Screen.view_3d`.
    """

    screen: Screen
    canvas: Canvas
    alpha: float
    size_px: tuple[int, int]
    render_scale: float = 1.0


class Scene(Protocol):
    """What the app calls on the scene at the top of its stack (see :class:`BaseScene`)."""

    def enter(self, app: "App") -> None: ...
    def exit(self) -> None: ...
    def handle(self, event: InputEvent) -> None: ...
    def update(self, dt_s: float) -> None: ...
    def prepare(self, frame: Frame) -> None: ...
    def render_3d(self, frame: Frame) -> None: ...
    def render_2d(self, frame: Frame) -> None: ...


class BaseScene:
    """A scene that does nothing; subclasses override what they need.

    ``self.app`` is set by :meth:`enter`. ``render_3d`` draws into the cleared frame before the
    2D layer; ``render_2d`` draws with ``frame.canvas``.
    """

    app: "App"
    #: Clear colour of the frame, 0..1 linear-ish RGB.
    background = theme.BACKGROUND_GL
    #: The frame's depth is cleared with its colour; False: the scene resets the depth itself
    #: where it draws in 3D (e.g. with a background at the far plane), and the clear spares it.
    clear_depth = True

    def enter(self, app: "App") -> None:
        self.app = app

    def exit(self) -> None:
        pass

    def handle(self, event: InputEvent) -> None:
        pass

    def update(self, dt_s: float) -> None:
        pass

    def prepare(self, frame: "Frame") -> None:
        """CPU-only work of this frame's drawing (no GL calls): runs while the previous frame is
        still being rasterized. ``render_3d`` / ``render_2d`` then issue the GL commands."""

    def render_3d(self, frame: Frame) -> None:
        pass

    def render_2d(self, frame: Frame) -> None:
        pass


class Services:
    """What scenes share beyond the screen: the live tracker link (None when not running).

    Owned by whoever built the app (closed by them, not by the app).
    """

    def __init__(self, tracker=None) -> None:
        self.tracker = tracker

    def tick(self) -> None:
        """Once per frame: let the tracker link notice a dead process, restart it, read samples."""
        if self.tracker is not None:
            self.tracker.tick()


@dataclass(frozen=True, slots=True)
class RunSummary:
    """What :meth:`App.run` did.

    Attributes:
        frames: frames drawn.
        updates: fixed updates run.
        wall_s: wall time of the run.
        work_ms: mean time to make a frame (without the pacing sleep): 1000 / work_ms is the
            frame rate the machine could sustain uncapped.
        cpu_ms: CPU time of this process per frame, all threads (llvmpipe rasterizes on
            threads of its own): what a frame costs on a machine shared with other work.
        screenshot: the PNG written, if any.
        interval_p50_ms, interval_p99_ms, interval_max_ms: the median, the 99th percentile and the
            longest time between the ends of two frames (a stall the patient sees).
        slowest: where the longest frame spent its time (stage: ms, ...).
        scale_mean, scale_min: the 3D views' render scale over the frames (1.0: full resolution).
        problem: what went wrong with the measurement during the run, in one line ("" if
            nothing): the source ended early or warned, the tracker failed (set by ``run_play``).
        half_rate_share: share of the frames paced at half ``max_fps`` (:mod:`game.pacing`).
    """

    frames: int
    updates: int
    wall_s: float
    work_ms: float
    cpu_ms: float = math.nan
    screenshot: Path | None = None
    interval_p99_ms: float = math.nan
    interval_max_ms: float = math.nan
    slowest: str = ""
    interval_p50_ms: float = math.nan
    scale_mean: float = 1.0
    scale_min: float = 1.0
    problem: str = ""
    half_rate_share: float = 0.0

    @property
    def fps(self) -> float:
        return self.frames / self.wall_s if self.wall_s > 0 else math.nan

    def line(self) -> str:
        shot = f"; screenshot {self.screenshot}" if self.screenshot else ""
        capable = 1000.0 / self.work_ms if self.work_ms > 0 else math.nan
        stalls = ""
        if math.isfinite(self.interval_max_ms):
            stalls = (f"; frame interval median {self.interval_p50_ms:.0f} ms, p99 {self.interval_p99_ms:.0f} ms, "
                      f"longest {self.interval_max_ms:.0f} ms"
                      + (f" ({self.slowest})" if self.slowest else ""))
        if self.scale_min < 1.0:
            stalls += f"; 3D at {self.scale_mean:.2f} of full resolution on average, {self.scale_min:.2f} at least"
        if self.half_rate_share > 0:
            stalls += f"; {100 * self.half_rate_share:.0f} % of the frames paced at half the rate (a busy machine)"
        return (f"{self.frames} frames in {self.wall_s:.1f} s ({self.fps:.1f} frames/s shown; "
                f"{self.work_ms:.1f} ms of work per frame = {capable:.0f} frames/s possible; "
                f"{self.cpu_ms:.1f} ms CPU per frame{stalls}){shot}")


class App:
    """The scene stack and the loop.

    Args:
        screen: where frames go (:func:`game.gfx.screen.open_screen`).
        settings: how to run.
        clock: seconds, monotonic (``time.perf_counter`` in the program, a fake in tests).
        sleep: waits that many seconds (frame pacing).
        services: what the scenes share.
        events: returns the pygame events since the last call.
    """

    def __init__(self, screen: Screen, settings: Settings = Settings(), *, clock: Clock = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep, services: Services | None = None,
                 events: Callable[[], Iterable[pygame.event.Event]] = pygame.event.get) -> None:
        self.screen = screen
        self.settings = settings
        self.clock = clock
        self._sleep = sleep
        self._events = events
        self.services = services or Services()
        self.canvas = Canvas(screen.ctx, screen.size_px)
        self.input = InputMapper(screen.size_px)
        self.stack: list[BaseScene] = []
        self.running = True
        self.show_fps = settings.show_fps
        self.rate = RateMeter()
        # the frame budget: the capped rate's period (uncapped: 60 frames/s)
        self.scaler = RenderScaler(1.0 / (settings.max_fps or 60.0), fixed=settings.render_scale)
        # the pacing's period: 1 / max_fps, or twice that while frames miss it (None: uncapped)
        self.pacer = FramePacer(settings.max_fps, adaptive=settings.adaptive_pace) if settings.max_fps > 0 else None
        self.frames = 0
        self._step = FixedStep(1.0 / settings.update_hz, settings.max_frame_s, clock())
        self._last_frame_s = clock()
        self._work_total_s = 0.0
        self._pending = False  # a frame drawn and flushed but not presented yet
        self._loading = ""     # words shown while a scene is being opened (:meth:`open`)
        self.intervals: deque[float] = deque(maxlen=100_000)   # frame-to-frame times of the run, seconds
        self.scales: deque[float] = deque(maxlen=100_000)      # the render scale of each frame
        self._slowest: tuple = (0.0, (), 0.0)   # the longest interval, its stages, the wait before it
        self._timed_from = 0                     # frames before this one are not searched for the slowest
        self._halved_frames = 0                  # frames paced at the half rate (:class:`FramePacer`)

    # ------------------------------------------------------------------ scenes
    @property
    def scene(self) -> BaseScene | None:
        return self.stack[-1] if self.stack else None

    def push(self, scene: BaseScene) -> None:
        """Put ``scene`` on top; the one below stays as it is, to come back to."""
        self.stack.append(scene)
        scene.enter(self)

    def pop(self) -> None:
        """Leave the top scene; with none left the app stops."""
        if self.stack:
            self.stack.pop().exit()
        if not self.stack:
            self.running = False

    def replace(self, scene: BaseScene) -> None:
        """Swap the top scene for ``scene``."""
        if self.stack:
            self.stack.pop().exit()
        self.push(scene)

    def quit(self) -> None:
        self.running = False

    def busy(self, words: str, work: Callable[[], object]):
        """Run ``work()`` (seconds of it: a scene to build, a report to write) with ``words`` shown
        over the current scene meanwhile; returns what it returns."""
        self.present()
        if self.scene is not None:
            self._loading = words
            try:
                self.render(self.scene)
            finally:
                self._loading = ""
            self.screen.flush()
            self.screen.present()
        return work()

    def open(self, make: Callable[[], "BaseScene"], words: str = "Opening...", *, replace: bool = False) -> None:
        """Push the scene ``make()`` builds (``replace``: in place of the top scene), showing
        ``words`` over the current scene while it is built: a scene may take seconds to open (a
        database read, plots, cameras), and a screen that sits unchanged looks broken."""
        scene = self.busy(words, make)
        if replace:
            self.replace(scene)
        else:
            self.push(scene)

    # ------------------------------------------------------------------ input
    def dispatch(self, event: InputEvent) -> None:
        """Route one input event: quitting and the frame-rate overlay are the app's, the rest the scene's."""
        if isinstance(event, Press) and event.down and event.action is Action.QUIT:
            self.quit()
        elif isinstance(event, Press) and event.down and event.action is Action.TOGGLE_FPS:
            self.show_fps = not self.show_fps
        elif self.scene is not None:
            self.scene.handle(event)

    # ------------------------------------------------------------------ loop
    def frame(self, screenshot: Path | None = None) -> bool:
        """One frame: events, fixed updates, preparing, presenting the previous frame, drawing
        this one (``screenshot``: saving it) and flushing it to the rasterizer.

        Returns:
            Whether a frame was drawn (not when the events quit the app or left no scene).
        """
        start_s = self.clock()
        stages = [start_s]
        for event in self.input.map(self._events()):
            self.dispatch(event)
            if not self.running:
                return False
        stages.append(self.clock())
        self.services.tick()
        stages.append(self.clock())
        scene = self.scene
        if scene is None:
            self.running = False
            return False
        steps = self._step.advance(stages[-1])
        dt_s = self._step.step_s
        for _ in range(steps):
            scene.update(dt_s)
        stages.append(self.clock())
        frame = self._frame()
        scene.prepare(frame)  # while the previous frame is rasterized
        stages.append(self.clock())
        self.present()
        stages.append(self.clock())
        self.render(scene, frame)
        if screenshot is not None:
            # A window's back buffer is undefined after the swap: read it before presenting.
            self.screen.save_png(screenshot)
        self.screen.flush()
        self._pending = True
        end_s = self.clock()
        stages.append(end_s)
        interval_s = end_s - self._last_frame_s
        self.intervals.append(interval_s)
        self.scales.append(frame.render_scale)
        if interval_s > self._slowest[0] and self.frames > self._timed_from:
            self._slowest = (interval_s, tuple(b - a for a, b in zip(stages, stages[1:])), start_s - self._last_frame_s)
        self.rate.add(end_s - self._last_frame_s, end_s - start_s)
        # the time to make the frame, waiting for the last one's pixels included (not the pacing sleep)
        self.scaler.observe(end_s - start_s)
        if self.pacer is not None:
            self.pacer.observe(interval_s)
        self._work_total_s += end_s - start_s
        self._last_frame_s = end_s
        self.frames += 1
        return True

    def present(self) -> None:
        """Show the frame drawn last, if not shown yet (waits until it is rasterized)."""
        if self._pending:
            self._pending = False
            self.screen.present()

    def render(self, scene: BaseScene, frame: Frame | None = None) -> None:
        """Draw ``scene`` (3D pass, then the 2D layer and the overlay) into the screen's target."""
        if frame is None:
            frame = self._frame()
            scene.prepare(frame)
        # A whole-target clear is a fast tile clear on llvmpipe: cheaper than painting the part a
        # 3D pass leaves as a large 2D shape (tried: ~1.5-3 ms more per 1280x720 frame).
        self.screen.begin(scene.background, depth=scene.clear_depth)
        scene.render_3d(frame)
        self.canvas.begin()
        scene.render_2d(frame)
        if self._loading:
            self._draw_loading(self._loading)
        if self.show_fps:
            self._draw_fps()
        self.canvas.end()

    def _frame(self) -> Frame:
        return Frame(self.screen, self.canvas, self._step.alpha, self.screen.size_px, self.scaler.scale)

    def _draw_loading(self, words: str) -> None:
        w, h = self.screen.size_px
        s = min(w / 1280.0, h / 720.0)
        self.canvas.rect((0, 0, w, h), (0, 0, 0, 110))
        size = round(theme.MEDIUM * s)
        tw, th = self.canvas.measure(words, size)
        box = (w / 2 - tw / 2 - 40 * s, h / 2 - th / 2 - 26 * s, tw + 80 * s, th + 52 * s)
        self.canvas.rect(box, theme.PANEL, radius=theme.RADIUS * s, border=3 * s, border_colour=theme.ACCENT)
        self.canvas.text(words, (w / 2, h / 2), size, theme.TEXT, anchor="center")

    def _draw_fps(self) -> None:
        fps = self.rate.fps
        text = f"{fps:.0f} frames/s" if math.isfinite(fps) else "- frames/s"
        w, _ = self.screen.size_px
        size = theme.SMALL
        tw, th = self.canvas.measure(text, size)
        self.canvas.rect((w - tw - 28, 10, tw + 18, th + 10), theme.OVERLAY, radius=8)
        self.canvas.text(text, (w - 19, 15), size, theme.TEXT_DIM, anchor="topright")

    def run(self, *, seconds: float | None = None, frames: int | None = None,
            screenshot: Path | None = None) -> RunSummary:
        """Run frames until quit (or ``seconds`` of clock time or ``frames`` frames).

        Args:
            seconds: stop after this much clock time.
            frames: stop after this many frames.
            screenshot: save the last frame drawn there (PNG).
        """
        start_s = self.clock()
        start_cpu_s = time.process_time()
        first_frame = self.frames
        self._slowest, self._timed_from = (0.0, (), 0.0), self.frames + 1   # the run's first frame: its start-up
        work_before_s = self._work_total_s
        halved_before = self._halved_frames
        # Frames are paced to deadlines one period apart, not to a period after each frame's start:
        # a sleep that overshoots or a slow frame is made up by the next wait, so the rate holds
        # max_fps on average (paced from each start, 60 became 55-57 frames/s on a busy machine).
        deadline_s = start_s
        saved = None
        while self.running:
            frame_start_s = self.clock()
            elapsed_s = frame_start_s - start_s
            done = self.frames - first_frame
            if (seconds is not None and elapsed_s >= seconds - 1e-9) or (frames is not None and done >= frames):
                break
            # The last frame of the run is the one saved (read before the window swaps buffers).
            period_s = self.pacer.period_s if self.pacer is not None else 0.0
            last = (frames is not None and done + 1 >= frames) or (
                seconds is not None and elapsed_s + max(period_s, 1e-3) >= seconds - 1e-9)
            if screenshot is not None and last:
                if self.frame(screenshot=screenshot):
                    saved = screenshot
                break
            self.frame()
            if self.pacer is not None:
                period_s = self.pacer.period_s
                self._halved_frames += self.pacer.halved
                deadline_s += period_s
                now_s = self.clock()
                if now_s < deadline_s:
                    self._sleep(deadline_s - now_s)
                elif now_s - deadline_s > period_s:   # far behind (a stall): start afresh, no burst
                    deadline_s = now_s
        if screenshot is not None and saved is None:  # quit early: save what the scene shows now
            if self.scene is not None:
                self.present()
                self.render(self.scene)
            self.screen.save_png(screenshot)
        self.present()  # the last frame drawn: shown, and its rasterizing counted in the run's time
        n = self.frames - first_frame
        wall_s = self.clock() - start_s
        work_ms = 1000.0 * (self._work_total_s - work_before_s) / n if n else math.nan
        cpu_ms = 1000.0 * (time.process_time() - start_cpu_s) / n if n else math.nan
        intervals = list(self.intervals)[-n:][1:] if n > 1 else []   # the first counts the start-up
        ordered = sorted(intervals)
        p50, p99 = (1000.0 * float(ordered[min(len(ordered) - 1, int(q * len(ordered)))]) if ordered else math.nan
                    for q in (0.5, 0.99))
        worst = 1000.0 * max(intervals) if intervals else math.nan
        _, parts, wait = self._slowest
        names = ("events", "tracker link", "updates", "prepare", "present", "draw")
        slowest = ", ".join(f"{k} {1000 * v:.0f}" for k, v in (("before", wait), *zip(names, parts)) if v > 0.002)
        scales = list(self.scales)[-n:] if n else [1.0]
        return RunSummary(n, self._step.total_steps, wall_s, work_ms, cpu_ms, screenshot, p99, worst, slowest, p50,
                          sum(scales) / len(scales), min(scales),
                          half_rate_share=(self._halved_frames - halved_before) / n if n else 0.0)

    def close(self) -> None:
        """Exit every scene and release the canvas (the screen and services belong to the caller)."""
        while self.stack:
            self.stack.pop().exit()
        self.canvas.release()
