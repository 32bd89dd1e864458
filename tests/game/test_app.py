"""The loop (fixed steps and interpolation alpha under a fake clock), input mapping, the scene
stack, and headless frames with pixels checked. SDL dummy driver, EGL (llvmpipe)."""

from __future__ import annotations

import itertools

import numpy as np
import pygame
import pytest

from game.app import App, BaseScene, FixedStep, Frame, Settings
from game.gfx import theme
from game.gfx.screen import has_display
from game.input import Action, InputMapper, Pointer, PointerKind, Press


class FakeClock:
    """A clock the test moves by hand; ``sleep`` moves it too."""

    def __init__(self, now_s: float = 50.0) -> None:
        self.now_s = now_s

    def __call__(self) -> float:
        return self.now_s

    def sleep(self, dt_s: float) -> None:
        self.now_s += dt_s


@pytest.fixture
def screen(open_headless):
    return open_headless((320, 180))


# ---------------------------------------------------------------------------- fixed step
def test_fixed_step_counts_updates_and_keeps_the_leftover_as_alpha():
    step = FixedStep(1 / 120, 0.25, now_s=10.0)
    assert step.advance(10.0 + 0.05) == 6
    assert step.alpha == pytest.approx(0.0, abs=1e-6)
    assert step.advance(10.05 + 1 / 240) == 0
    assert step.alpha == pytest.approx(0.5)
    assert step.advance(10.05 + 1 / 240 + 1 / 240) == 1
    assert step.alpha == pytest.approx(0.0, abs=1e-6)
    assert step.total_steps == 7


def test_fixed_step_drops_a_stall_beyond_the_cap():
    step = FixedStep(0.01, 0.25, now_s=0.0)
    assert step.advance(5.0) == 25
    assert step.advance(5.0) == 0
    assert step.advance(4.0) == 0  # a clock going backwards never makes negative time


class Recorder(BaseScene):
    """Records what the app asks of it."""

    def __init__(self, colour=(255, 0, 0)) -> None:
        self.colour = colour
        self.updates = 0
        self.alphas: list[float] = []
        self.events: list = []
        self.entered = self.exited = 0

    def enter(self, app):
        super().enter(app)
        self.entered += 1

    def exit(self):
        self.exited += 1

    def handle(self, event):
        self.events.append(event)

    def update(self, dt_s):
        assert dt_s == pytest.approx(1 / 120)
        self.updates += 1

    def render_2d(self, frame: Frame):
        self.alphas.append(frame.alpha)
        w, h = frame.size_px
        frame.canvas.rect((0, 0, w / 2, h), self.colour)


def test_app_runs_two_updates_per_60_hz_frame_and_interpolates(screen):
    clock = FakeClock()
    # each frame takes 1/60 s of work on the fake clock (a 0.5-step offset shows in alpha)
    scene = Recorder()
    app = App(screen, Settings(update_hz=120, max_fps=0, show_fps=False), clock=clock, sleep=clock.sleep,
              events=lambda: [])
    app.push(scene)
    clock.now_s += 1 / 240
    for _ in range(10):
        app.frame()
        clock.now_s += 1 / 60
    assert scene.updates == 18  # 1/240 + 9/60 s elapsed before the 10th frame: 18.5 steps
    assert scene.alphas == pytest.approx([0.5] * 10)


def test_run_paces_frames_to_max_fps_and_stops_after_seconds(screen):
    clock = FakeClock()
    app = App(screen, Settings(max_fps=30, show_fps=False), clock=clock, sleep=clock.sleep, events=lambda: [])
    app.push(Recorder())
    summary = app.run(seconds=1.0)
    assert summary.frames == pytest.approx(30, abs=1)
    assert summary.updates == pytest.approx(120, abs=4)


def test_run_holds_max_fps_on_average_when_sleeps_wake_late_and_some_frames_are_slow(screen):
    """Frames are paced to deadlines: a late wake-up or a frame longer than the period is made up by
    the next wait (paced from each frame's start, the rate fell to ~53 of 60 here)."""
    clock = FakeClock()
    late = itertools.cycle((0.004, 0.0, 0.002))

    def sleep(dt_s: float) -> None:
        clock.now_s += dt_s + next(late)

    class Working(Recorder):
        drawn = 0

        def render_2d(self, frame: Frame):
            super().render_2d(frame)
            Working.drawn += 1
            clock.now_s += 0.020 if Working.drawn % 7 == 0 else 0.008   # now and then slower than 1/60 s

    # the deadlines alone (one frame in 7 skipping a refresh would halve the rate: test_pacing.py)
    app = App(screen, Settings(max_fps=60, show_fps=False, adaptive_pace=False), clock=clock, sleep=sleep,
              events=lambda: [])
    app.push(Working())
    summary = app.run(seconds=2.0)
    assert summary.frames == pytest.approx(120, abs=2)


def test_the_run_reports_its_frame_intervals_and_where_the_longest_went(screen):
    """One frame of 60 spends 250 ms in the scene's prepare: the summary's longest interval is it,
    named by its stage, and the 99th percentile sees it too."""
    clock = FakeClock()

    class Stalling(BaseScene):
        n = 0

        def prepare(self, frame: Frame):
            Stalling.n += 1
            clock.now_s += 0.25 if Stalling.n == 30 else 0.005

    app = App(screen, Settings(max_fps=0, show_fps=False), clock=clock, sleep=clock.sleep, events=lambda: [])
    app.push(Stalling())
    summary = app.run(frames=60)
    assert summary.interval_max_ms == pytest.approx(250.0, abs=1.0)
    assert summary.slowest.startswith("prepare 250")
    assert summary.interval_p99_ms == pytest.approx(250.0, abs=1.0)   # 1 of 59 intervals: above the 98th
    assert summary.interval_p50_ms == pytest.approx(5.0, abs=0.5)      # the usual frame
    assert "median 5 ms, p99 250 ms, longest 250 ms (prepare 250)" in summary.line()


def test_scene_stack_push_pop_replace_and_quit(screen):
    clock = FakeClock()
    app = App(screen, Settings(), clock=clock, events=lambda: [])
    a, b, c = Recorder(), Recorder(), Recorder()
    app.push(a)
    app.push(b)
    assert app.scene is b and a.exited == 0
    app.replace(c)
    assert app.scene is c and b.exited == 1
    app.dispatch(Press(Action.SELECT))
    assert c.events == [Press(Action.SELECT)] and a.events == []
    app.pop()
    assert app.scene is a and app.running
    app.pop()
    assert not app.running
    app2 = App(screen, Settings(), clock=clock, events=lambda: [])
    app2.push(Recorder())
    app2.dispatch(Press(Action.QUIT))
    assert not app2.running


def test_headless_frame_pixels_and_screenshot(screen, tmp_path):
    clock = FakeClock()
    app = App(screen, Settings(show_fps=True), clock=clock, sleep=clock.sleep, events=lambda: [])
    app.push(Recorder(colour=(200, 40, 30)))
    out = tmp_path / "shot.png"
    summary = app.run(frames=3, screenshot=out)
    assert summary.frames == 3 and summary.screenshot == out
    rgb = screen.read_rgb()
    assert rgb.shape == (180, 320, 3)
    assert tuple(rgb[90, 40]) == (200, 40, 30)                    # the scene's left half
    assert tuple(rgb[170, 300]) == theme.BACKGROUND               # cleared right half
    corner = rgb[8:40, 200:318].reshape(-1, 3)                     # the frame-rate overlay's text
    assert (corner.max(axis=1) > 120).sum() > 30
    import cv2

    saved = cv2.imread(str(out))[:, :, ::-1]
    assert np.array_equal(saved, rgb)


def test_pointer_and_keys_are_mapped_once(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    mapper = InputMapper((800, 400))
    E = pygame.event.Event
    events = [
        E(pygame.KEYDOWN, key=pygame.K_TAB),
        E(pygame.KEYDOWN, key=pygame.K_q),
        E(pygame.KEYDOWN, key=pygame.K_q),          # auto-repeat: dropped
        E(pygame.KEYDOWN, key=pygame.K_F12),        # not mapped
        E(pygame.MOUSEMOTION, pos=(200, 100), rel=(0, 0), buttons=(0, 0, 0)),
        E(pygame.MOUSEBUTTONDOWN, pos=(400, 300), button=1),
        E(pygame.MOUSEWHEEL, x=0, y=-1),
        E(pygame.KEYUP, key=pygame.K_q),
        E(pygame.QUIT),
    ]
    out = mapper.map(events)
    assert out == [
        Press(Action.SWITCH_ARM),
        Press(Action.ROTATE_IN),
        Pointer(PointerKind.MOVE, 0.25, 0.25),
        Pointer(PointerKind.PRESS, 0.5, 0.75, button=1),
        Pointer(PointerKind.WHEEL, 0.5, 0.75, wheel=-1.0),
        Press(Action.ROTATE_IN, down=False),
        Press(Action.QUIT),
    ]
    assert mapper.held == {Action.SWITCH_ARM}
    out = mapper.map([E(pygame.WINDOWFOCUSLOST)])
    assert out == [Press(Action.SWITCH_ARM, down=False)] and not mapper.held


@pytest.mark.parametrize(
    "environ, platform, expected",
    [
        ({}, "linux", False),
        ({"DISPLAY": ":0"}, "linux", True),
        ({"WAYLAND_DISPLAY": "wayland-0"}, "linux", True),
        ({"DISPLAY": ":0", "SDL_VIDEODRIVER": "dummy"}, "linux", False),
        ({"SDL_VIDEODRIVER": "kmsdrm"}, "linux", True),
        ({}, "win32", True),
        ({}, "darwin", True),
    ],
)
def test_has_display(environ, platform, expected):
    assert has_display(environ, platform) is expected


def test_text_atlas_starts_afresh_when_full_without_losing_queued_text(screen):
    from game.gfx.canvas import Canvas

    canvas = Canvas(screen.ctx, screen.size_px, atlas_px=(256, 48))
    screen.begin((0.0, 0.0, 0.0))
    canvas.begin()
    boxes = []
    for k in range(24):   # far more strings than the atlas holds at once
        x, y = 8 + (k % 4) * 78, 8 + (k // 4) * 28
        boxes.append(canvas.text(f"n{k:02d}", (x, y), 24, (255, 255, 255)))
    canvas.end()
    assert canvas.atlas.resets >= 1
    rgb = screen.read_rgb()
    for x, y, w, h in boxes:
        patch = rgb[int(y):int(y + h), int(x):int(x + w)]
        assert (patch.max(axis=2) > 128).sum() > 20, (x, y)
    # the same string drawn again uses the atlas entry (no new reset)
    resets = canvas.atlas.resets
    canvas.begin()
    canvas.text("n23", (8, 8), 24, (255, 255, 255))
    canvas.end()
    assert canvas.atlas.resets == resets
    canvas.release()


def test_canvas_fill_sprite_and_clip_draw_in_call_order(screen):
    import pygame

    from game.gfx.canvas import Canvas

    canvas = Canvas(screen.ctx, screen.size_px)
    mask = pygame.Surface((20, 10), pygame.SRCALPHA)
    mask.fill((255, 255, 255, 255))
    screen.begin((0.0, 0.0, 0.0))
    canvas.begin()
    canvas.rect((0, 0, 100, 100), (255, 0, 0))               # under the fill: covered by it
    canvas.fill((10, 10, 80, 60), (0, 0, 200, 90))            # opaque whatever the alpha
    canvas.sprite("block", mask, (20, 20), (0, 255, 0))       # the mask tinted, over the fill
    canvas.clip((150, 0, 40, 40))
    canvas.circle((150, 20), 30, (255, 255, 0))               # only its part inside the clip
    canvas.clip(None)
    canvas.end()
    rgb = screen.read_rgb().astype(int)
    assert (rgb[50, 60] == (0, 0, 200)).all()                 # the fill, opaque
    assert (rgb[5, 5] == (255, 0, 0)).all()                   # the rect outside the fill
    assert (rgb[25, 30] == (0, 255, 0)).all()                 # the sprite
    assert (rgb[20, 160] == (255, 255, 0)).all()              # the circle inside the clip
    assert (rgb[20, 135] == (0, 0, 0)).all()                  # ... and not left of it
    canvas.release()


def test_canvas_writes_new_strings_into_the_atlas_before_any_draw_of_the_frame(screen, monkeypatch):
    """llvmpipe rasterizes later: a texture written after a draw that samples it was issued makes
    the driver finish that draw first (a stall), so the frame's new strings go in before its draws."""
    from game.gfx.canvas import Canvas

    canvas = Canvas(screen.ctx, screen.size_px)
    events = []
    write, draw = canvas.atlas.texture.write, canvas._draw_batch
    monkeypatch.setattr(canvas.atlas.texture, "write", lambda *a, **k: (events.append("write"), write(*a, **k)))
    monkeypatch.setattr(canvas, "_draw_batch", lambda rows: (events.append("draw"), draw(rows)))
    screen.begin((0.0, 0.0, 0.0))
    canvas.begin()
    canvas.text("first", (10, 10), 24, (255, 255, 255))
    canvas.fill((0, 60, 50, 50), (0, 0, 255))                 # ends a batch
    canvas.text("second", (10, 120), 24, (255, 255, 255))    # a new string after it
    canvas.end()
    assert events == ["write", "write", "draw", "draw"]
    rgb = screen.read_rgb()
    assert (rgb[10:40, 10:60].max(axis=2) > 128).sum() > 20 and (rgb[120:150, 10:70].max(axis=2) > 128).sum() > 20
    canvas.release()


def test_consecutive_fills_are_one_draw_and_keep_the_call_order(screen, monkeypatch):
    """The river's bands: consecutive fills go out as one instanced draw; a shape between two
    runs of fills stays between them."""
    from game.gfx.canvas import Canvas

    canvas = Canvas(screen.ctx, screen.size_px)
    draws = []
    render = canvas._fills.vao.render
    monkeypatch.setattr(canvas._fills.vao, "render", lambda *a, **k: (draws.append(k.get("instances")), render(*a, **k)))
    screen.begin((0.0, 0.0, 0.0))
    canvas.begin()
    for k, colour in enumerate(((200, 0, 0), (0, 200, 0), (0, 0, 200))):
        canvas.fill((20 * k, 0, 20, 100), colour)            # three bands side by side
    canvas.circle((30, 50), 10, (255, 255, 255))              # over the first two bands
    canvas.fill((25, 45, 10, 10), (90, 90, 90, 20))            # over the circle, opaque
    canvas.end()
    assert draws == [3, 1]
    rgb = screen.read_rgb().astype(int)
    assert (rgb[80, 10] == (200, 0, 0)).all() and (rgb[80, 30] == (0, 200, 0)).all()
    assert (rgb[80, 50] == (0, 0, 200)).all()
    assert (rgb[50, 24] == (255, 255, 255)).all()             # the circle over the bands
    assert (rgb[50, 30] == (90, 90, 90)).all()                # the last fill over the circle
    canvas.release()


def test_a_frame_clear_without_depth_keeps_the_depth(screen):
    """``begin(depth=False)`` clears the colour only (a scene that resets the depth itself, e.g.
    the games' gradient at the far plane, spares the clear the depth)."""
    import moderngl

    ctx = screen.ctx
    prog = ctx.program(
        vertex_shader="#version 330\nuniform float z;\nvoid main() {\n"
                      "  vec2 p = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1));\n"
                      "  gl_Position = vec4(p * 2.0 - 1.0, z, 1.0);\n}\n",
        fragment_shader="#version 330\nout vec4 f;\nvoid main() { f = vec4(1.0, 1.0, 1.0, 1.0); }\n")
    quad = ctx.vertex_array(prog, [])

    def draw_at(z: float) -> None:
        prog["z"].value = z
        quad.render(moderngl.TRIANGLE_STRIP, vertices=4)

    ctx.enable(moderngl.DEPTH_TEST)
    screen.begin((0.0, 0.0, 0.0))
    draw_at(-0.5)                                             # the near depth written
    screen.begin((0.2, 0.0, 0.0), depth=False)
    assert tuple(screen.read_rgb()[90, 160]) == (51, 0, 0)    # the colour cleared
    draw_at(0.5)                                              # behind the kept depth: hidden
    assert tuple(screen.read_rgb()[90, 160]) == (51, 0, 0)
    screen.begin((0.2, 0.0, 0.0))                             # the whole clear
    draw_at(0.5)
    assert tuple(screen.read_rgb()[90, 160]) == (255, 255, 255)
    ctx.disable(moderngl.DEPTH_TEST)
    quad.release()
    prog.release()


def test_frames_that_keep_missing_the_rate_are_paced_at_half_of_it(screen):
    """Frames that take 20-28 ms against 60 frames/s (a busy machine) are paced at 30 frames/s,
    an even rate, and the run's summary says so; with the adaptation off they come as they can."""
    results = {}
    for adaptive in (True, False):
        clock = FakeClock()
        costs = itertools.cycle((0.020, 0.028, 0.024))

        class Slow(Recorder):
            def render_2d(self, frame: Frame):
                super().render_2d(frame)
                clock.now_s += next(costs)

        app = App(screen, Settings(max_fps=60, show_fps=False, adaptive_pace=adaptive), clock=clock,
                  sleep=clock.sleep, events=lambda: [])
        app.push(Slow())
        results[adaptive] = app.run(seconds=30.0)
    halved, free = results[True], results[False]
    # halved after ~3 s; the full rate tried after 5, 10 and 20 s at half, halved again within 1 s
    assert halved.half_rate_share > 0.75 and "paced at half the rate" in halved.line()
    assert halved.fps == pytest.approx(30.0, abs=3.0)
    assert free.half_rate_share == 0.0 and free.fps > 38.0
