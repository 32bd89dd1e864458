"""Dynamic resolution of the 3D views: the controller on made-up frame times (down under load,
back up after, no flicker), and headless frames drawn at a reduced scale (the 3D view fills its
rectangle, upscaled; the 2D text is the same pixels as at full resolution)."""

from __future__ import annotations

import moderngl
import numpy as np
import pytest

from game.app import App, BaseScene, Frame, Settings
from game.gfx.render_scale import RenderScaler, ScaleLimits
from game.gfx.view3d import Viewport

BUDGET_S = 1 / 60


def frame_time_s(scale: float, base_s: float, pixels_s: float, rng: np.random.Generator, jitter: float) -> float:
    """A frame's time: a part that does not depend on the pixels, and rasterizing ~ scale^2;
    ``jitter`` is the relative spread of a frame's time on a busy machine."""
    return (base_s + pixels_s * scale ** 2) * float(rng.lognormal(0.0, jitter))


def drive(scaler: RenderScaler, phases, seed: int, jitter: float = 0.15) -> list[float]:
    """Scales after each frame over ``phases`` of (frames, base_s, pixels_s)."""
    rng = np.random.default_rng(seed)
    scales = []
    for n, base_s, pixels_s in phases:
        for _ in range(n):
            scales.append(scaler.observe(frame_time_s(scaler.scale, base_s, pixels_s, rng, jitter)))
    return scales


def reversals(scales: list[float]) -> int:
    """How often the scale changed direction (down then up, or up then down)."""
    steps = [np.sign(b - a) for a, b in zip(scales, scales[1:]) if b != a]
    return sum(1 for a, b in zip(steps, steps[1:]) if a != b)


IDLE = (4e-3, 7e-3)       # 11 ms at full scale: 0.66 of the budget, inside the dead band
BUSY = (5e-3, 22e-3)      # 27 ms at full scale; ~11-13 ms near scale 0.6
QUIET = (2e-3, 5e-3)      # 7 ms: room to raise


@pytest.mark.parametrize("seed", range(6))
def test_the_scale_goes_down_under_load_and_back_up_after_without_flicker(seed):
    scaler = RenderScaler(BUDGET_S)
    scales = drive(scaler, [(300, *IDLE), (600, *BUSY), (900, *QUIET)], seed)
    idle, busy, quiet = scales[:300], scales[300:900], scales[900:]
    assert set(idle) == {1.0}                         # inside the band: left alone
    assert min(busy[:30]) < 1.0                       # lowered within half a second of the load
    settled = busy[200:]
    assert 0.5 <= min(settled) and max(settled) <= 0.8
    assert len(set(settled)) <= 2                     # at most one step of wavering, once settled
    assert reversals(busy) <= 1
    assert quiet[-1] == 1.0                           # back to full resolution once the load is gone
    assert quiet[:44] == [quiet[0]] * 44              # raised slowly: not before raise_after (45) frames
    assert reversals(scales) <= 2                     # down, (maybe one waver), up


def test_a_load_beyond_reach_stops_at_the_smallest_scale():
    scaler = RenderScaler(BUDGET_S, limits=ScaleLimits(min_scale=0.5))
    scales = drive(scaler, [(300, 30e-3, 30e-3)], seed=1)
    assert scales[-1] == 0.5 and min(scales) == 0.5


def test_a_fixed_scale_never_moves_and_bad_values_are_refused():
    scaler = RenderScaler(BUDGET_S, fixed=1.0)
    assert set(drive(scaler, [(200, 40e-3, 40e-3)], seed=0)) == {1.0}
    assert not scaler.dynamic
    with pytest.raises(ValueError):
        RenderScaler(BUDGET_S, fixed=0.0)
    with pytest.raises(ValueError):
        ScaleLimits(raise_at=0.95, lower_at=0.9)
    with pytest.raises(ValueError):
        Settings(render_scale=1.5)


# ---------------------------------------------------------------------------- pixels
RED, BLUE = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
_STRIPES_FS = """
#version 330
out vec4 f_colour;
void main() { f_colour = (int(gl_FragCoord.x) % 2 == 0) ? vec4(1.0, 0.0, 0.0, 1.0) : vec4(0.0, 0.0, 1.0, 1.0); }
"""
_QUAD_VS = """
#version 330
void main() { gl_Position = vec4(float(gl_VertexID & 1) * 2.0 - 1.0, float(gl_VertexID >> 1) * 2.0 - 1.0, 0.5, 1.0); }
"""


class Striped(BaseScene):
    """A 3D view on the left half: one-pixel red and blue columns of its render target, depth
    tested; a line of text on the right half."""

    background = (0.1, 0.1, 0.1)

    def __init__(self) -> None:
        self.gl_viewports = []

    def enter(self, app):
        super().enter(app)
        self.prog = app.screen.ctx.program(vertex_shader=_QUAD_VS, fragment_shader=_STRIPES_FS)
        self.vao = app.screen.ctx.vertex_array(self.prog, [])

    def exit(self):
        self.vao.release()
        self.prog.release()

    def render_3d(self, frame: Frame):
        w, h = frame.size_px
        with frame.screen.view_3d(Viewport(0, 0, w // 2, h), frame.render_scale) as gl_viewport:
            self.gl_viewports.append(gl_viewport)
            frame.screen.ctx.enable(moderngl.DEPTH_TEST)
            self.vao.render(moderngl.TRIANGLE_STRIP, vertices=4)

    def render_2d(self, frame: Frame):
        w, h = frame.size_px
        frame.canvas.text("Shoulder flexion 92", (w // 2 + 10, 20), 22, (230, 230, 230))


def draw(open_headless, scale: float) -> tuple[np.ndarray, Striped]:
    screen = open_headless((320, 120))
    app = App(screen, Settings(render_scale=scale, show_fps=False), events=lambda: [])
    scene = Striped()
    app.push(scene)
    app.frame()
    rgb = screen.read_rgb()
    app.close()
    return rgb.astype(int), scene


def test_a_3d_view_at_half_scale_fills_its_rectangle_upscaled_and_the_text_stays_sharp(open_headless):
    full, scene_full = draw(open_headless, 1.0)
    half, scene_half = draw(open_headless, 0.5)
    assert scene_full.gl_viewports == [(0, 0, 160, 120)]
    assert scene_half.gl_viewports == [(0, 0, 80, 60)]         # half the pixels along each axis
    view_full, view_half = full[:, :160], half[:, :160]
    # full scale: exact one-pixel columns of the window
    assert (view_full[:, 0::2] == (255, 0, 0)).all() and (view_full[:, 1::2] == (0, 0, 255)).all()
    # half scale: the whole rectangle is the view's (red + blue, nothing of the background), and the
    # columns are blends of the smaller image's (linear upscaling), not the window's own
    assert (view_half[..., 1] == 0).all()
    assert np.abs(view_half[..., 0] + view_half[..., 2] - 255).max() <= 2
    assert not (view_half[:, 0::2] == (255, 0, 0)).all()
    assert ((view_half[..., 0] > 40) & (view_half[..., 0] < 215)).mean() > 0.5
    # the 2D layer: text drawn, and the very same pixels as at full scale
    text_full, text_half = full[:, 160:], half[:, 160:]
    assert (text_full.sum(axis=2) > 400).sum() > 50
    assert (text_full == text_half).all()


def test_the_play_command_takes_auto_or_a_scale_and_defaults_to_full_resolution(capsys):
    from game.cli import build_parser

    parse = build_parser().parse_args
    assert parse(["play"]).render_scale == 1.0
    assert parse(["play", "--render-scale", "auto"]).render_scale is None
    assert parse(["play", "--render-scale", "0.5"]).render_scale == 0.5
    for bad in ("2", "0.1", "nan", "half"):
        with pytest.raises(SystemExit):
            parse(["play", "--render-scale", bad])
        assert "--render-scale" in capsys.readouterr().err
