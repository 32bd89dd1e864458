"""Where frames are drawn: a pygame window with an OpenGL 3.3 core context, or an offscreen
framebuffer on a headless EGL context. Scenes draw into a :class:`Screen` and never know which.

SDL, asked for a window on a machine without a display, may fail late, pick a driver that shows
nothing, or (with some drivers) grab the console; so the environment is checked first, with a
pure function (:func:`has_display`), and only then is pygame's display touched.

Headless, pygame still runs (SDL's dummy video driver) so that fonts and the event queue work the
same, but the OpenGL context is a standalone EGL one rendering into a framebuffer object.
"""

from __future__ import annotations

import ctypes
import functools
import logging
import os
import sys
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator, Mapping

import cv2
import moderngl
import numpy as np
import pygame

from calibration.errors import RehabError

log = logging.getLogger(__name__)

NO_DISPLAY_MESSAGE = (
    "no display found; run 'rehab play --headless --seconds 5 --screenshot play.png' to render offscreen"
)

#: SDL video drivers that open no visible window.
OFFSCREEN_DRIVERS = frozenset({"dummy", "offscreen"})


class NoDisplayError(RehabError):
    """There is no screen to open a window on."""

    def __init__(self, detail: str = "") -> None:
        super().__init__(NO_DISPLAY_MESSAGE if not detail else f"{NO_DISPLAY_MESSAGE} ({detail})")


class GraphicsUnavailable(RehabError):
    """No OpenGL 3.3 context could be created."""


def has_display(environ: Mapping[str, str], platform: str) -> bool:
    """Whether a visible window can be expected, judged from the environment alone.

    Args:
        environ: the process environment (``os.environ``).
        platform: ``sys.platform``.

    On Linux and the BSDs a window needs an X11 or Wayland server (``DISPLAY`` or
    ``WAYLAND_DISPLAY``), or an explicit on-screen SDL driver such as ``kmsdrm``. Windows and macOS
    always have a desktop when a user runs the command.
    """
    driver = environ.get("SDL_VIDEODRIVER", "").strip().lower()
    if driver:
        return driver not in OFFSCREEN_DRIVERS
    if platform.startswith(("win", "darwin")):
        return True
    return bool(environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY"))


@functools.cache
def _gl_flush_function() -> Callable[[], None]:
    """glFlush of the current context (libglvnd dispatches it for GLX windows and EGL alike);
    a no-op where no GL library exposes it (moderngl has no flush of its own)."""
    for name in ("libOpenGL.so.0", "libGL.so.1", "opengl32", "/System/Library/Frameworks/OpenGL.framework/OpenGL"):
        try:
            return getattr(ctypes.CDLL(name), "glFlush")
        except (OSError, AttributeError):
            continue
    log.debug("no glFlush found: frames are rasterized when presented")
    return lambda: None


def _gl_flush() -> None:
    _gl_flush_function()()


_UPSCALE_VS = """
#version 330
out vec2 v_uv;
void main() {
    v_uv = vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1));
    gl_Position = vec4(v_uv * 2.0 - 1.0, 0.0, 1.0);
}
"""

_UPSCALE_FS = """
#version 330
uniform sampler2D u_texture;
in vec2 v_uv;
out vec4 f_colour;
void main() {
    f_colour = texture(u_texture, v_uv);
}
"""


class _ScaledTarget:
    """An offscreen colour texture and depth buffer of a reduced-scale 3D view's size, upscaled
    (linear) into the window. RGB: the window's alpha stays 1 whatever the view blended."""

    def __init__(self, ctx: moderngl.Context, size_px: tuple[int, int]) -> None:
        self.size_px = size_px
        self.colour = ctx.texture(size_px, 3)
        self.colour.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.colour.repeat_x = self.colour.repeat_y = False   # the edges' texels, not the far side's
        self.depth = ctx.depth_renderbuffer(size_px)
        self.fbo = ctx.framebuffer(color_attachments=[self.colour], depth_attachment=self.depth)
        self.prog = ctx.program(vertex_shader=_UPSCALE_VS, fragment_shader=_UPSCALE_FS)
        self.vao = ctx.vertex_array(self.prog, [])

    def release(self) -> None:
        for obj in (self.vao, self.prog, self.fbo, self.depth, self.colour):
            obj.release()


class Screen:
    """An OpenGL context and the framebuffer a frame is drawn into.

    Use :func:`open_screen`. Per frame: :meth:`begin` (binds the target, clears), draw with
    :attr:`ctx`, then :meth:`present`. :meth:`read_rgb` / :meth:`save_png` read back what was
    drawn (before :meth:`present` in a window, whose back buffer is undefined after the swap).

    Attributes:
        ctx: the moderngl context (OpenGL 3.3 core or newer).
        size_px: (width, height) of the drawing area in pixels.
        headless: True when drawing offscreen (no window).
    """

    def __init__(self, ctx: moderngl.Context, target: moderngl.Framebuffer, size_px: tuple[int, int], *,
                 headless: bool, owned: tuple = ()) -> None:
        self.ctx = ctx
        self.target = target
        self.size_px = (int(size_px[0]), int(size_px[1]))
        self.headless = headless
        self._owned = owned
        self._closed = False
        self._clear_rgb = (0.0, 0.0, 0.0)
        self._scaled: _ScaledTarget | None = None

    @property
    def aspect(self) -> float:
        return self.size_px[0] / self.size_px[1]

    def begin(self, clear_rgb: tuple[float, float, float] | None, *, depth: bool = True) -> None:
        """Bind the frame's target and clear it (colour and depth).

        Args:
            clear_rgb: the clear colour, 0..1; None: bind only (the frame repaints every pixel).
            depth: clear the depth too; False when the frame resets the depth where it needs it
                (a 3D view's background drawn at the far plane): the depth clear of the whole
                1280x720 target is about half the clear's cost on llvmpipe (~0.7 ms CPU).

        The clear is of the whole target: llvmpipe clears a whole surface cheaply, tile by tile,
        whereas a scissored clear is drawn like a quad and makes the next texture upload of the
        frame (a new string in the text atlas) wait until everything queued is rasterized.
        """
        self.target.use()
        self.ctx.viewport = (0, 0, *self.size_px)
        if clear_rgb is not None:
            self._clear_rgb = tuple(float(c) for c in clear_rgb)
            if depth:
                self.target.clear(*clear_rgb, 1.0, depth=1.0)
            else:   # glClear honours the depth mask: the colour alone
                self.target.depth_mask = False
                self.target.clear(*clear_rgb, 1.0)
                self.target.depth_mask = True

    @contextmanager
    def view_3d(self, viewport, scale: float = 1.0) -> Iterator[tuple[int, int, int, int]]:
        """Draw a 3D view into ``viewport`` (a :class:`game.gfx.view3d.Viewport`, window pixels)
        at ``scale`` of its pixels along each axis; yields the GL viewport the drawing is in.

        At 1.0 the view is drawn straight into the frame's target. Below, it is drawn into an
        offscreen framebuffer (cleared to the frame's clear colour and the far depth), then
        stretched with linear filtering over ``viewport``: the rasterizer's work falls with the
        square of the scale, while whatever is drawn after (the 2D text) stays at full resolution.
        """
        x, y, w, h = viewport.gl(self.size_px[1])
        full = (0, 0, *self.size_px)
        if scale >= 1.0 or w <= 0 or h <= 0:
            self.ctx.viewport = (x, y, w, h)
            try:
                yield (x, y, w, h)
            finally:
                self.ctx.viewport = full
            return
        sw, sh = min(max(1, round(w * scale)), w), min(max(1, round(h * scale)), h)
        if self._scaled is None or self._scaled.size_px != (sw, sh):   # a new size only when the scale steps
            if self._scaled is not None:
                self._scaled.release()
            self._scaled = _ScaledTarget(self.ctx, (sw, sh))
        st = self._scaled
        st.fbo.use()
        self.ctx.viewport = (0, 0, sw, sh)
        st.fbo.clear(*self._clear_rgb, 1.0, depth=1.0)
        try:
            yield (0, 0, sw, sh)
        finally:
            self.target.use()
            self.ctx.viewport = (x, y, w, h)
            self.ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
            st.colour.use(0)
            st.prog["u_texture"].value = 0
            st.vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
            self.ctx.viewport = full

    def flush(self) -> None:
        """Hand the commands issued so far to the rasterizer without waiting for them (glFlush):
        Mesa llvmpipe then rasterizes on its own threads while this thread goes on."""
        _gl_flush()

    def present(self) -> None:
        """Show the frame (swap the window's buffers; offscreen, make sure the GPU finished)."""
        if self.headless:
            self.ctx.finish()
        else:
            pygame.display.flip()

    def read_rgb(self) -> np.ndarray:
        """(H, W, 3) uint8 RGB of the frame drawn so far, row 0 at the top."""
        data = self.target.read(viewport=(0, 0, *self.size_px), components=3, alignment=1)
        w, h = self.size_px
        return np.frombuffer(data, np.uint8).reshape(h, w, 3)[::-1].copy()

    def save_png(self, path: Path) -> Path:
        """Write the frame drawn so far as a PNG.

        Raises:
            RehabError: the file cannot be written.
        """
        path = Path(path)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            ok = cv2.imwrite(str(path), cv2.cvtColor(self.read_rgb(), cv2.COLOR_RGB2BGR))
        except (OSError, cv2.error) as exc:
            raise RehabError(f"cannot write the screenshot {path}: {exc}; choose a writable .png path") from None
        if not ok:
            raise RehabError(f"cannot write the screenshot {path}: choose a writable path ending in .png")
        return path

    def close(self) -> None:
        """Release GL objects and shut pygame's display down (safe to call twice)."""
        if self._closed:
            return
        self._closed = True
        if self._scaled is not None:
            self._scaled.release()
        for obj in self._owned:
            obj.release()
        if self.headless:
            self.ctx.release()
        pygame.quit()

    def __enter__(self) -> "Screen":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _set_gl_attributes() -> None:
    """Ask SDL for a forward-compatible OpenGL 3.3 core profile context with a depth buffer."""
    attrs = (
        (pygame.GL_CONTEXT_MAJOR_VERSION, 3),
        (pygame.GL_CONTEXT_MINOR_VERSION, 3),
        (pygame.GL_CONTEXT_PROFILE_MASK, pygame.GL_CONTEXT_PROFILE_CORE),
        (pygame.GL_CONTEXT_FLAGS, pygame.GL_CONTEXT_FORWARD_COMPATIBLE_FLAG),
        (pygame.GL_DEPTH_SIZE, 24),
        (pygame.GL_DOUBLEBUFFER, 1),
    )
    for attr, value in attrs:
        pygame.display.gl_set_attribute(attr, value)


def open_screen(size_px: tuple[int, int], title: str, *, headless: bool, vsync: bool = True) -> Screen:
    """Initialise pygame and an OpenGL context: a window, or an offscreen framebuffer.

    Args:
        size_px: (width, height) of the window or framebuffer.
        title: window caption.
        headless: draw offscreen (EGL context, SDL dummy driver for events and fonts).
        vsync: in a window, ask for buffer swaps in step with the display.

    Raises:
        NoDisplayError: not headless and there is no display, or SDL cannot open the window.
        GraphicsUnavailable: no OpenGL 3.3 context.
    """
    # SDL may otherwise present surfaces through a GL renderer of its own whose context, made
    # current at every flip, displaces another context of this thread. Read when video starts.
    os.environ["SDL_FRAMEBUFFER_ACCELERATION"] = "0"
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    if headless:
        os.environ["SDL_VIDEODRIVER"] = "dummy"
    elif not has_display(os.environ, sys.platform):
        raise NoDisplayError()
    pygame.display.init()
    pygame.font.init()
    if headless:
        return _open_offscreen(size_px)
    _set_gl_attributes()
    try:
        with warnings.catch_warnings():
            # pygame warns when the driver ignores the vsync request (Xvfb, some VMs): harmless,
            # the frame-rate cap of the loop still paces the frames.
            warnings.simplefilter("ignore")
            pygame.display.set_mode(size_px, pygame.OPENGL | pygame.DOUBLEBUF, vsync=int(vsync))
    except pygame.error as exc:
        if vsync:  # some drivers refuse vsync; a window without it is still a window
            try:
                pygame.display.set_mode(size_px, pygame.OPENGL | pygame.DOUBLEBUF)
            except pygame.error:
                pass
            else:
                exc = None
        if exc is not None:
            pygame.quit()
            raise NoDisplayError(str(exc).splitlines()[0] if str(exc) else "") from None
    pygame.display.set_caption(title)
    try:
        ctx = moderngl.create_context(require=330)
    except Exception as exc:  # moderngl raises plain Exceptions
        pygame.quit()
        raise GraphicsUnavailable(f"OpenGL 3.3 is unavailable in the window ({exc}); update the graphics "
                                  "driver, or run with --headless") from None
    width, height = pygame.display.get_window_size()
    log.info("window %dx%d, %s", width, height, ctx.info.get("GL_RENDERER", "?"))
    return Screen(ctx, ctx.screen, (width, height), headless=False)


def _open_offscreen(size_px: tuple[int, int]) -> Screen:
    errors = []
    for kwargs in ({"backend": "egl"}, {}):
        try:
            ctx = moderngl.create_standalone_context(require=330, **kwargs)
            break
        except Exception as exc:  # glcontext raises plain Exceptions of several types
            errors.append(f"{kwargs.get('backend', 'default')}: {exc}")
    else:
        pygame.quit()
        reasons = "; ".join(errors).replace("\n", " ")
        raise GraphicsUnavailable(f"OpenGL offscreen rendering is unavailable ({reasons}): install Mesa EGL "
                                  "(apt-get install libegl1 libgl1-mesa-dri)")
    colour = ctx.renderbuffer(size_px, components=4)
    depth = ctx.depth_renderbuffer(size_px)
    fbo = ctx.framebuffer(color_attachments=[colour], depth_attachment=depth)
    return Screen(ctx, fbo, size_px, headless=True, owned=(fbo, colour, depth))
