"""The 2D layer: rounded panels, dots, text and images drawn over the 3D view with OpenGL.

Coordinates are window pixels, origin at the top-left corner, x right, y down (as pygame and
OpenCV count them). Colours are sRGB ``(r, g, b)`` or ``(r, g, b, a)`` in 0..255.

llvmpipe (the CPU rasteriser this must run on) pays per draw call and per pixel shaded, so:

- rectangles, rounded panels, outlines and circles are one signed-distance shader, queued and
  drawn as one instanced call per run of consecutive shapes;
- text is rendered by pygame.font once per (string, size) into a white texture kept in a small
  LRU cache and tinted when drawn (:func:`surface_to_texture` is the one pygame -> GL bridge);
- images (camera frames) go into textures reused frame after frame (:meth:`Canvas.image`).

Drawing order is call order: a shape queued before a text is drawn before it.
"""

from __future__ import annotations

import struct
from collections import OrderedDict
from dataclasses import dataclass

import moderngl
import numpy as np
import pygame

Colour = tuple[int, int, int] | tuple[int, int, int, int]

_RECT_VS = """
#version 330
uniform vec2 u_screen;
in vec2 in_corner;              // 0..1 unit quad
in vec4 in_rect;                // x, y, w, h in pixels
in vec4 in_fill;
in vec4 in_edge;
in vec2 in_shape;               // corner radius, border width (pixels)
out vec2 v_px;
flat out vec4 v_rect;
flat out vec4 v_fill;
flat out vec4 v_edge;
flat out vec2 v_shape;
void main() {
    // one pixel of margin so that the anti-aliased edge is not cut
    vec2 px = in_rect.xy - 1.0 + in_corner * (in_rect.zw + 2.0);
    v_px = px; v_rect = in_rect; v_fill = in_fill; v_edge = in_edge; v_shape = in_shape;
    gl_Position = vec4(px.x / u_screen.x * 2.0 - 1.0, 1.0 - px.y / u_screen.y * 2.0, 0.0, 1.0);
}
"""

_RECT_FS = """
#version 330
in vec2 v_px;
flat in vec4 v_rect;
flat in vec4 v_fill;
flat in vec4 v_edge;
flat in vec2 v_shape;
out vec4 f_colour;
void main() {
    vec2 half_size = 0.5 * v_rect.zw;
    float r = min(v_shape.x, min(half_size.x, half_size.y));
    vec2 q = abs(v_px - (v_rect.xy + half_size)) - half_size + r;
    float d = length(max(q, 0.0)) + min(max(q.x, q.y), 0.0) - r;   // signed distance to the outline
    float cover = clamp(0.5 - d, 0.0, 1.0);
    vec4 colour = v_fill;
    if (v_shape.y > 0.0) {
        float inside = clamp(0.5 - (d + v_shape.y), 0.0, 1.0);
        colour = mix(v_edge, v_fill, inside);
    }
    f_colour = vec4(colour.rgb, colour.a * cover);
    if (f_colour.a <= 0.0) discard;
}
"""

_QUAD_VS = """
#version 330
uniform vec2 u_screen;
uniform vec4 u_rect;            // x, y, w, h in pixels
uniform vec4 u_uv;              // u0, v0, u1, v1 (v0 = top row of the image)
in vec2 in_corner;
out vec2 v_uv;
void main() {
    vec2 px = u_rect.xy + in_corner * u_rect.zw;
    v_uv = mix(u_uv.xy, u_uv.zw, in_corner);
    gl_Position = vec4(px.x / u_screen.x * 2.0 - 1.0, 1.0 - px.y / u_screen.y * 2.0, 0.0, 1.0);
}
"""

_QUAD_FS = """
#version 330
uniform sampler2D u_texture;
uniform vec4 u_tint;
in vec2 v_uv;
out vec4 f_colour;
void main() {
    f_colour = texture(u_texture, v_uv) * u_tint;
}
"""

_FLOATS_PER_SHAPE = 14
_ANCHORS = ("topleft", "midtop", "topright", "midleft", "center", "midright", "bottomleft", "midbottom",
            "bottomright")


def _rgba(colour: Colour) -> tuple[float, float, float, float]:
    if len(colour) == 3:
        return colour[0] / 255.0, colour[1] / 255.0, colour[2] / 255.0, 1.0
    return colour[0] / 255.0, colour[1] / 255.0, colour[2] / 255.0, colour[3] / 255.0


def surface_to_texture(ctx: moderngl.Context, surface: pygame.Surface) -> moderngl.Texture:
    """A pygame Surface as an RGBA texture whose first row is the surface's top row.

    The one bridge from pygame to GL: the quad shader samples v = 0 at the top of the quad, so
    neither side flips anything.
    """
    data = pygame.image.tobytes(surface, "RGBA")
    tex = ctx.texture(surface.get_size(), 4, data)
    # Text is drawn at whole pixels, one texel per pixel: nearest sampling is exact and cheaper.
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    tex.repeat_x = tex.repeat_y = False
    return tex


@dataclass(frozen=True, slots=True)
class Text:
    """A rendered string: its texture and size in pixels."""

    texture: moderngl.Texture
    size_px: tuple[int, int]


class TextCache:
    """Strings rendered by pygame.font into white textures, least recently used dropped first.

    Args:
        ctx: the GL context owning the textures.
        capacity: strings kept; changing readouts (angles, rates) churn through a few per frame.
    """

    def __init__(self, ctx: moderngl.Context, capacity: int = 384) -> None:
        self._ctx = ctx
        self._capacity = capacity
        self._fonts: dict[int, pygame.font.Font] = {}
        self._cache: OrderedDict[tuple[str, int], Text] = OrderedDict()

    def font(self, size: int) -> pygame.font.Font:
        """pygame's bundled font (nothing is read from the system) at ``size`` pixels."""
        if size not in self._fonts:
            self._fonts[size] = pygame.font.Font(None, size)
        return self._fonts[size]

    def measure(self, text: str, size: int) -> tuple[int, int]:
        """(width, height) in pixels that ``text`` takes at ``size``."""
        key = (text, size)
        if key in self._cache:
            return self._cache[key].size_px
        return self.font(size).size(text)

    def get(self, text: str, size: int) -> Text:
        key = (text, size)
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        surface = self.font(size).render(text, True, (255, 255, 255))
        entry = Text(surface_to_texture(self._ctx, surface), surface.get_size())
        self._cache[key] = entry
        while len(self._cache) > self._capacity:
            _, old = self._cache.popitem(last=False)
            old.texture.release()
        return entry

    def release(self) -> None:
        for entry in self._cache.values():
            entry.texture.release()
        self._cache.clear()


class Canvas:
    """Immediate-mode 2D drawing in window pixels over whatever the frame already holds.

    Args:
        ctx: the GL context.
        size_px: (width, height) of the drawing area.
    """

    def __init__(self, ctx: moderngl.Context, size_px: tuple[int, int]) -> None:
        self.ctx = ctx
        self.size_px = (int(size_px[0]), int(size_px[1]))
        self.texts = TextCache(ctx)
        corners = np.array([0, 0, 1, 0, 0, 1, 1, 1], dtype="f4")
        self._corners = ctx.buffer(corners.tobytes())
        self._rect_prog = ctx.program(vertex_shader=_RECT_VS, fragment_shader=_RECT_FS)
        self._quad_prog = ctx.program(vertex_shader=_QUAD_VS, fragment_shader=_QUAD_FS)
        self._capacity = 256
        self._shapes = ctx.buffer(reserve=self._capacity * _FLOATS_PER_SHAPE * 4, dynamic=True)
        self._rect_vao = self._make_rect_vao()
        self._quad_vao = ctx.vertex_array(self._quad_prog, [(self._corners, "2f", "in_corner")])
        self._pending: list[float] = []
        self._images: dict[str, moderngl.Texture] = {}

    def _make_rect_vao(self) -> moderngl.VertexArray:
        return self.ctx.vertex_array(self._rect_prog, [
            (self._corners, "2f", "in_corner"),
            (self._shapes, "4f 4f 4f 2f/i", "in_rect", "in_fill", "in_edge", "in_shape"),
        ])

    # ------------------------------------------------------------------ frame
    def begin(self) -> None:
        """Prepare GL state for 2D drawing (call after the 3D pass)."""
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        screen = struct.pack("2f", *self.size_px)
        self._rect_prog["u_screen"].write(screen)
        self._quad_prog["u_screen"].write(screen)

    def flush(self) -> None:
        """Draw the queued shapes."""
        if not self._pending:
            return
        n = len(self._pending) // _FLOATS_PER_SHAPE
        if n > self._capacity:
            while self._capacity < n:
                self._capacity *= 2
            self._shapes.orphan(self._capacity * _FLOATS_PER_SHAPE * 4)
            self._rect_vao.release()
            self._rect_vao = self._make_rect_vao()
        self._shapes.write(np.asarray(self._pending, dtype="f4").tobytes())
        self._rect_vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=n)
        self._pending.clear()

    def end(self) -> None:
        """Draw what is queued and leave blending off for the next 3D pass."""
        self.flush()
        self.ctx.disable(moderngl.BLEND)

    # ------------------------------------------------------------------ shapes
    def rect(self, rect: tuple[float, float, float, float], fill: Colour, *, radius: float = 0.0,
             border: float = 0.0, border_colour: Colour = (0, 0, 0, 0)) -> None:
        """A rectangle ``(x, y, w, h)``, optionally with rounded corners and a border inside it."""
        x, y, w, h = rect
        self._pending.extend((x, y, w, h, *_rgba(fill), *_rgba(border_colour), radius, border))

    def circle(self, centre: tuple[float, float], radius: float, fill: Colour, *, border: float = 0.0,
               border_colour: Colour = (0, 0, 0, 0)) -> None:
        """A disc (a fully rounded square)."""
        cx, cy = centre
        self.rect((cx - radius, cy - radius, 2 * radius, 2 * radius), fill, radius=radius, border=border,
                  border_colour=border_colour)

    # ------------------------------------------------------------------ text
    def measure(self, text: str, size: int) -> tuple[int, int]:
        """(width, height) of ``text`` at font ``size`` pixels."""
        return self.texts.measure(text, size)

    def text(self, text: str, pos: tuple[float, float], size: int, colour: Colour, *,
             anchor: str = "topleft") -> tuple[float, float, float, float]:
        """Draw one line of text; ``anchor`` is a pygame Rect point name placed at ``pos``.

        Returns:
            The ``(x, y, w, h)`` the text covers.
        """
        if not text:
            return pos[0], pos[1], 0.0, 0.0
        entry = self.texts.get(text, size)
        w, h = entry.size_px
        x, y = _anchored(pos, (w, h), anchor)
        # Whole pixels keep the glyphs crisp (no resampling between texels).
        x, y = round(x), round(y)
        self._quad(entry.texture, (x, y, w, h), (0.0, 0.0, 1.0, 1.0), colour)
        return x, y, w, h

    def wrap(self, text: str, size: int, width: float) -> list[str]:
        """``text`` broken at spaces into lines no wider than ``width`` (a long word stays whole)."""
        lines: list[str] = []
        for paragraph in text.split("\n"):
            line = ""
            for word in paragraph.split(" "):
                trial = f"{line} {word}" if line else word
                if line and self.measure(trial, size)[0] > width:
                    lines.append(line)
                    line = word
                else:
                    line = trial
            lines.append(line)
        return lines

    # ------------------------------------------------------------------ images
    def image(self, key: str, image: np.ndarray, rect: tuple[float, float, float, float], *,
              bgr: bool = True, tint: Colour = (255, 255, 255)) -> None:
        """Draw an (H, W, 3) uint8 image (OpenCV BGR unless ``bgr`` is False) stretched to ``rect``.

        The texture named ``key`` is reused while the image size stays the same.
        """
        h, w = image.shape[:2]
        tex = self._images.get(key)
        if tex is None or tex.size != (w, h):
            if tex is not None:
                tex.release()
            tex = self.ctx.texture((w, h), 3, alignment=1)
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = False
            self._images[key] = tex
        tex.swizzle = "BGR1" if bgr else "RGB1"
        tex.write(np.ascontiguousarray(image, dtype=np.uint8).tobytes())
        self._quad(tex, rect, (0.0, 0.0, 1.0, 1.0), tint)

    def texture(self, texture: moderngl.Texture, rect: tuple[float, float, float, float], *,
                uv: tuple[float, float, float, float] = (0.0, 0.0, 1.0, 1.0), tint: Colour = (255, 255, 255)) -> None:
        """Draw a texture whose v = 0 row is the top (pass ``uv=(0, 1, 1, 0)`` for GL's bottom-up ones)."""
        self._quad(texture, rect, uv, tint)

    def _quad(self, texture: moderngl.Texture, rect, uv, tint: Colour) -> None:
        self.flush()
        prog = self._quad_prog
        prog["u_rect"].write(struct.pack("4f", *rect))
        prog["u_uv"].write(struct.pack("4f", *uv))
        prog["u_tint"].write(struct.pack("4f", *_rgba(tint)))
        texture.use(0)
        self._quad_vao.render(moderngl.TRIANGLE_STRIP, vertices=4)

    def release(self) -> None:
        self.texts.release()
        for tex in self._images.values():
            tex.release()
        self._images.clear()
        for obj in (self._rect_vao, self._quad_vao, self._shapes, self._corners, self._rect_prog, self._quad_prog):
            obj.release()


def _anchored(pos: tuple[float, float], size: tuple[float, float], anchor: str) -> tuple[float, float]:
    """Top-left corner of a box of ``size`` whose ``anchor`` point is at ``pos``."""
    if anchor not in _ANCHORS:
        raise ValueError(f"anchor {anchor!r} is not one of {', '.join(_ANCHORS)}")
    x, y = pos
    w, h = size
    if anchor.endswith("right"):
        x -= w
    elif anchor in ("midtop", "center", "midbottom"):
        x -= w / 2
    if anchor.startswith("bottom") or anchor == "midbottom":
        y -= h
    elif anchor in ("midleft", "center", "midright"):
        y -= h / 2
    return x, y
