"""The 2D layer: rounded panels, dots, text and images drawn over the 3D view with OpenGL.

Coordinates are window pixels, origin at the top-left corner, x right, y down (as pygame and
OpenCV count them). Colours are sRGB ``(r, g, b)`` or ``(r, g, b, a)`` in 0..255.

llvmpipe (the CPU rasteriser this must run on) pays per draw call, and Python pays per call
into moderngl, so every shape and every string of a frame goes into ONE instanced draw:

- rectangles, rounded panels, outlines and circles are a signed-distance shape per instance;
- text is rendered by pygame.font once per (string, size) into a shared white atlas texture
  (:class:`TextAtlas`, shelf-packed, started afresh when full) and drawn as tinted atlas quads
  by the same shader (:func:`surface_to_texture` is the pygame -> GL bridge for other surfaces);
- images (camera frames) go into textures reused frame after frame (:meth:`Canvas.image`);
  they end the batch and are drawn on their own;
- large opaque single-colour areas are :meth:`Canvas.fill` (a plain one-colour quad without
  blending: the cheapest pixels llvmpipe paints after a clear);
- small white masks (a ripple, an icon) share the text atlas (:meth:`Canvas.sprite`).

Drawing order is call order. The GL commands of a frame are issued at :meth:`Canvas.end`, after
the strings new in this frame were written into the atlas: llvmpipe rasterizes later, so writing
a texture that a queued draw already samples makes it finish the whole frame drawn so far first
(a stall of ~7 ms, measured on the games' changing readouts).
"""

from __future__ import annotations

import functools
import struct

import moderngl
import numpy as np
import pygame

Colour = tuple[int, int, int] | tuple[int, int, int, int]

_BATCH_VS = """
#version 330
uniform vec2 u_screen;
in vec2 in_corner;              // 0..1 unit quad
in vec4 in_rect;                // x, y, w, h in pixels
in vec4 in_fill;                // shape fill or text colour
in vec4 in_edge;
in vec2 in_shape;               // corner radius, border width (pixels); radius < 0: text
in vec4 in_uv;                  // text: atlas u0, v0, u1, v1
out vec2 v_px;
out vec2 v_uv;
flat out vec4 v_rect;
flat out vec4 v_fill;
flat out vec4 v_edge;
flat out vec2 v_shape;
void main() {
    // shapes get one pixel of margin so that the anti-aliased edge is not cut
    float margin = in_shape.x < 0.0 ? 0.0 : 1.0;
    vec2 px = in_rect.xy - margin + in_corner * (in_rect.zw + 2.0 * margin);
    v_px = px;
    v_uv = mix(in_uv.xy, in_uv.zw, in_corner);
    v_rect = in_rect; v_fill = in_fill; v_edge = in_edge; v_shape = in_shape;
    gl_Position = vec4(px.x / u_screen.x * 2.0 - 1.0, 1.0 - px.y / u_screen.y * 2.0, 0.0, 1.0);
}
"""

_BATCH_FS = """
#version 330
uniform sampler2D u_atlas;
in vec2 v_px;
in vec2 v_uv;
flat in vec4 v_rect;
flat in vec4 v_fill;
flat in vec4 v_edge;
flat in vec2 v_shape;
out vec4 f_colour;
void main() {
    if (v_shape.x < 0.0) {
        f_colour = vec4(v_fill.rgb, v_fill.a * texture(u_atlas, v_uv).a);
    } else {
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
    }
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

_FILL_VS = """
#version 330
uniform vec2 u_screen;
in vec2 in_corner;
in vec4 in_rect;                // x, y, w, h in pixels
in vec4 in_colour;
flat out vec4 v_colour;
void main() {
    vec2 px = in_rect.xy + in_corner * in_rect.zw;
    v_colour = in_colour;
    gl_Position = vec4(px.x / u_screen.x * 2.0 - 1.0, 1.0 - px.y / u_screen.y * 2.0, 0.0, 1.0);
}
"""

_FILL_FS = """
#version 330
flat in vec4 v_colour;
out vec4 f_colour;
void main() {
    f_colour = v_colour;
}
"""

_FLOATS = 18                     # per instance: rect 4, fill 4, edge 4, shape 2, uv 4
_FILL_FLOATS = 8                 # per fill: rect 4, colour 4
_NO_UV = (0.0, 0.0, 0.0, 0.0)
_NO_EDGE = (0.0, 0.0, 0.0, 0.0)
_ANCHORS = ("topleft", "midtop", "topright", "midleft", "center", "midright", "bottomleft", "midbottom",
            "bottomright")


@functools.lru_cache(maxsize=256)
def _rgba(colour: Colour) -> tuple[float, float, float, float]:
    """sRGB 0..255 -> 0..1 RGBA (a UI uses a handful of colours: cached)."""
    if len(colour) == 3:
        return colour[0] / 255.0, colour[1] / 255.0, colour[2] / 255.0, 1.0
    return colour[0] / 255.0, colour[1] / 255.0, colour[2] / 255.0, colour[3] / 255.0


def surface_to_texture(ctx: moderngl.Context, surface: pygame.Surface) -> moderngl.Texture:
    """A pygame Surface as an RGBA texture whose first row is the surface's top row.

    The bridge from pygame to GL: the quad shaders sample v = 0 at the top of the quad, so
    neither side flips anything.
    """
    data = pygame.image.tobytes(surface, "RGBA")
    tex = ctx.texture(surface.get_size(), 4, data)
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = False
    return tex


class TextAtlas:
    """Strings rendered by pygame.font into one white texture, packed in shelves.

    When the atlas is full it starts afresh (the strings in use come back on their next draw),
    which bounds memory without bookkeeping; changing readouts (angles, rates) fill it slowly.
    New entries are written into the texture by :meth:`upload` (the canvas calls it before it
    draws), not at once.

    Args:
        ctx: the GL context owning the texture.
        size_px: atlas (width, height).
    """

    def __init__(self, ctx: moderngl.Context, size_px: tuple[int, int] = (2048, 1024)) -> None:
        self.size_px = size_px
        self.texture = ctx.texture(size_px, 4)
        # Text is drawn at whole pixels, one texel per pixel: nearest sampling is exact and cheaper.
        self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._fonts: dict[int, pygame.font.Font] = {}
        self._entries: dict[tuple[str, int], tuple[tuple[float, float, float, float], tuple[int, int]]] = {}
        self._sizes: dict[tuple[str, int], tuple[int, int]] = {}
        self._uploads: list[tuple[bytes, tuple[int, int, int, int]]] = []
        self.resets = 0
        self._reset_shelves()

    def _reset_shelves(self) -> None:
        self._entries.clear()
        self._x = self._y = self._shelf_h = 0

    def upload(self) -> None:
        """Write the entries added since the last call into the texture."""
        for data, viewport in self._uploads:
            self.texture.write(data, viewport=viewport)
        self._uploads.clear()

    def font(self, size: int) -> pygame.font.Font:
        """pygame's bundled font (nothing is read from the system) at ``size`` pixels."""
        if size not in self._fonts:
            self._fonts[size] = pygame.font.Font(None, size)
        return self._fonts[size]

    def measure(self, text: str, size: int) -> tuple[int, int]:
        """(width, height) in pixels that ``text`` takes at ``size``."""
        key = (text, size)
        got = self._sizes.get(key)
        if got is None:
            got = self._sizes[key] = self.font(size).size(text)
            if len(self._sizes) > 4096:
                self._sizes.clear()
        return got

    def get(self, text: str, size: int, before_reset) -> tuple[tuple[float, float, float, float], tuple[int, int]]:
        """Atlas uv rectangle and pixel size of ``text``; ``before_reset()`` runs if the atlas must
        start afresh (the caller draws what it queued with the old contents first)."""
        key = (text, size)
        hit = self._entries.get(key)
        if hit is not None:
            return hit
        return self._add(key, self.font(size).render(text, True, (255, 255, 255)), before_reset)

    def get_surface(self, key, surface: pygame.Surface,
                    before_reset) -> tuple[tuple[float, float, float, float], tuple[int, int]]:
        """As :meth:`get` for a mask drawn by the caller: ``surface``'s alpha (white RGB) under ``key``
        (any hashable other than a (str, int) pair)."""
        hit = self._entries.get(key)
        if hit is not None:
            return hit
        return self._add(key, surface, before_reset)

    def _add(self, key, surface: pygame.Surface,
             before_reset) -> tuple[tuple[float, float, float, float], tuple[int, int]]:
        aw, ah = self.size_px
        if surface.get_width() > aw or surface.get_height() > ah:
            surface = surface.subsurface((0, 0, min(surface.get_width(), aw), min(surface.get_height(), ah)))
        w, h = surface.get_size()
        if self._x + w > aw:
            self._x, self._y, self._shelf_h = 0, self._y + self._shelf_h + 1, 0
        if self._y + h > ah:
            before_reset()
            self._reset_shelves()
            self.resets += 1
        x, y = self._x, self._y
        self._uploads.append((pygame.image.tobytes(surface, "RGBA"), (x, y, w, h)))
        self._x += w + 1
        self._shelf_h = max(self._shelf_h, h)
        entry = ((x / aw, y / ah, (x + w) / aw, (y + h) / ah), (w, h))
        self._entries[key] = entry
        return entry

    def release(self) -> None:
        self.texture.release()


class Canvas:
    """Immediate-mode 2D drawing in window pixels over whatever the frame already holds.

    Args:
        ctx: the GL context.
        size_px: (width, height) of the drawing area.
        atlas_px: size of the text atlas.
    """

    def __init__(self, ctx: moderngl.Context, size_px: tuple[int, int], *,
                 atlas_px: tuple[int, int] = (2048, 1024)) -> None:
        self.ctx = ctx
        self.size_px = (int(size_px[0]), int(size_px[1]))
        self.atlas = TextAtlas(ctx, atlas_px)
        corners = np.array([0, 0, 1, 0, 0, 1, 1, 1], dtype="f4")
        self._corners = ctx.buffer(corners.tobytes())
        self._batch_prog = ctx.program(vertex_shader=_BATCH_VS, fragment_shader=_BATCH_FS)
        self._quad_prog = ctx.program(vertex_shader=_QUAD_VS, fragment_shader=_QUAD_FS)
        self._batch = _InstanceStream(ctx, self._batch_prog, self._corners, _FLOATS, 512, "4f 4f 4f 2f 4f/i",
                                      ("in_rect", "in_fill", "in_edge", "in_shape", "in_uv"))
        self._quad_vao = ctx.vertex_array(self._quad_prog, [(self._corners, "2f", "in_corner")])
        self._fill_prog = ctx.program(vertex_shader=_FILL_VS, fragment_shader=_FILL_FS)
        self._fills = _InstanceStream(ctx, self._fill_prog, self._corners, _FILL_FLOATS, 16, "4f 4f/i",
                                      ("in_rect", "in_colour"))
        self._pending: list[float] = []
        # the frame's draws, issued by end(): ("batch", float32 rows) | ("quad", texture, rect, uv, tint)
        # | ("fills", [rect and colour floats of consecutive fills]) | ("clip", GL scissor box or None)
        self._ops: list[tuple] = []
        self._clip = None
        self._images: dict[str, moderngl.Texture] = {}

    # ------------------------------------------------------------------ frame
    def begin(self) -> None:
        """Prepare GL state for 2D drawing (call after the 3D pass)."""
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        screen = struct.pack("2f", *self.size_px)
        self._batch_prog["u_screen"].write(screen)
        self._quad_prog["u_screen"].write(screen)
        self._fill_prog["u_screen"].write(screen)

    def flush(self) -> None:
        """End the current batch of shapes and text (what is queued after it is drawn over it)."""
        if self._pending:
            self._ops.append(("batch", np.asarray(self._pending, dtype="f4")))
            self._pending.clear()

    def draw_queued(self) -> None:
        """Issue the GL commands of everything queued, in order (new atlas entries written first)."""
        self.flush()
        self.atlas.upload()
        ctx = self.ctx
        for op in self._ops:
            kind = op[0]
            if kind == "batch":
                self._draw_batch(op[1])
            elif kind == "quad":
                _, texture, rect, uv, tint = op
                prog = self._quad_prog
                prog["u_rect"].write(struct.pack("4f", *rect))
                prog["u_uv"].write(struct.pack("4f", *uv))
                prog["u_tint"].write(struct.pack("4f", *_rgba(tint)))
                texture.use(0)
                self._quad_vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
            elif kind == "fills":
                self._draw_fills(op[1])
            else:  # clip
                ctx.scissor = op[1]
        self._ops.clear()

    def _draw_batch(self, rows: np.ndarray) -> None:
        self.atlas.texture.use(0)
        self._batch.draw(rows)

    def _draw_fills(self, values: list[float]) -> None:
        self.ctx.disable(moderngl.BLEND)    # opaque: blending would read every pixel back
        self._fills.draw(np.asarray(values, dtype="f4"))
        self.ctx.enable(moderngl.BLEND)

    def end(self) -> None:
        """Draw what is queued and leave blending off (and no clip) for the next 3D pass."""
        if self._clip is not None:
            self.clip(None)
        self.draw_queued()
        self.ctx.disable(moderngl.BLEND)

    def clip(self, rect: tuple[float, float, float, float] | None) -> None:
        """Draw only inside ``rect`` (x, y, w, h window pixels) from now on; None: everywhere."""
        self.flush()
        box = None
        if rect is not None:
            x, y, w, h = (round(v) for v in rect)
            box = (x, self.size_px[1] - (y + h), w, h)   # GL's scissor counts from the bottom
        self._clip = box
        self._ops.append(("clip", box))

    # ------------------------------------------------------------------ shapes
    def rect(self, rect: tuple[float, float, float, float], fill: Colour, *, radius: float = 0.0,
             border: float = 0.0, border_colour: Colour = (0, 0, 0, 0)) -> None:
        """A rectangle ``(x, y, w, h)``, optionally with rounded corners and a border inside it."""
        x, y, w, h = rect
        self._pending.extend((x, y, w, h, *_rgba(fill), *_rgba(border_colour), max(radius, 0.0), border, *_NO_UV))

    def circle(self, centre: tuple[float, float], radius: float, fill: Colour, *, border: float = 0.0,
               border_colour: Colour = (0, 0, 0, 0)) -> None:
        """A disc (a fully rounded square)."""
        cx, cy = centre
        self.rect((cx - radius, cy - radius, 2 * radius, 2 * radius), fill, radius=radius, border=border,
                  border_colour=border_colour)

    def fill(self, rect: tuple[float, float, float, float], colour: Colour) -> None:
        """An opaque rectangle of one colour (alpha ignored): for large areas, the cheapest to paint.
        Consecutive fills are one draw."""
        self.flush()
        if not self._ops or self._ops[-1][0] != "fills":
            self._ops.append(("fills", []))
        self._ops[-1][1].extend((*(float(v) for v in rect), *_rgba((*colour[:3], 255))))

    def sprite(self, key, surface: pygame.Surface, pos: tuple[float, float], colour: Colour) -> None:
        """The alpha of ``surface`` (a white mask made once by the caller, kept in the text atlas under
        ``key``) tinted with ``colour``, its top-left corner at ``pos`` (whole pixels)."""
        uv, (w, h) = self.atlas.get_surface(key, surface, self.draw_queued)
        self._pending.extend((round(pos[0]), round(pos[1]), w, h, *_rgba(colour), *_NO_EDGE, -1.0, 0.0, *uv))

    # ------------------------------------------------------------------ text
    def measure(self, text: str, size: int) -> tuple[int, int]:
        """(width, height) of ``text`` at font ``size`` pixels."""
        return self.atlas.measure(text, size)

    def text(self, text: str, pos: tuple[float, float], size: int, colour: Colour, *,
             anchor: str = "topleft") -> tuple[float, float, float, float]:
        """Draw one line of text; ``anchor`` is a pygame Rect point name placed at ``pos``.

        Returns:
            The ``(x, y, w, h)`` the text covers.
        """
        if not text:
            return pos[0], pos[1], 0.0, 0.0
        uv, (w, h) = self.atlas.get(text, size, self.draw_queued)
        x, y = _anchored(pos, (w, h), anchor)
        # Whole pixels keep the glyphs crisp (one texel per pixel).
        x, y = round(x), round(y)
        self._pending.extend((x, y, w, h, *_rgba(colour), *_NO_EDGE, -1.0, 0.0, *uv))
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

    def fit(self, text: str, size: int, width: float, *, min_size: int | None = None) -> tuple[str, int]:
        """``text`` and the largest text size up to ``size`` at which it is no wider than ``width``
        (down to ``min_size``, by default 70 % of ``size``); still too wide there, the text is cut
        at a word (or a letter) and ends with an ellipsis. For titles and names of any length in a
        fixed place (a long motion title, a test's name beside its value)."""
        lo = max(1, round(size * 0.7) if min_size is None else int(min_size))
        size = int(size)
        while size > lo and self.measure(text, size)[0] > width:
            size -= 1
        if self.measure(text, size)[0] <= width:
            return text, size
        ellipsis = "\N{HORIZONTAL ELLIPSIS}"
        words = text.split(" ")
        while len(words) > 1 and self.measure(" ".join(words) + ellipsis, size)[0] > width:
            words.pop()
        cut = " ".join(words).rstrip(" ,;:(")
        while cut and self.measure(cut + ellipsis, size)[0] > width:
            cut = cut[:-1]
        return cut.rstrip(" ,;:(") + ellipsis, size

    # ------------------------------------------------------------------ images
    def banner(self, text: str, pos: tuple[float, float], width: float, size: int, fill: Colour, border: Colour,
               text_colour: Colour, *, scale: float = 1.0, max_lines: int = 3) -> float:
        """A rounded box at ``pos`` (top-left), ``width`` wide, holding ``text`` wrapped to at most
        ``max_lines`` lines, outlined in ``border``; sizes scale with ``scale``. Returns its height."""
        x, y = pos
        lines = self.wrap(text, size, width - 40 * scale)[:max_lines]
        line_h = self.measure("Ag", size)[1] + 6 * scale
        h = len(lines) * line_h + 28 * scale
        self.rect((x, y, width, h), fill, radius=14 * scale, border=3 * scale, border_colour=border)
        for k, line in enumerate(lines):
            self.text(line, (x + 20 * scale, y + 14 * scale + k * line_h), size, text_colour)
        return h

    def image(self, key: str, image: np.ndarray, rect: tuple[float, float, float, float], *,
              bgr: bool = True, tint: Colour = (255, 255, 255)) -> None:
        """Draw an (H, W, 3) uint8 image (OpenCV BGR unless ``bgr`` is False) stretched to ``rect``.

        The texture named ``key`` is reused while the image size stays the same.
        """
        h, w = image.shape[:2]
        self.draw_queued()   # a draw of this texture queued earlier must not see the new image
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
        self._ops.append(("quad", texture, tuple(rect), tuple(uv), tint))

    def release(self) -> None:
        self.atlas.release()
        for tex in self._images.values():
            tex.release()
        self._images.clear()
        for obj in (self._batch, self._quad_vao, self._fills, self._corners, self._batch_prog, self._quad_prog,
                    self._fill_prog):
            obj.release()


class _InstanceStream:
    """Per-instance rows of one instanced quad program: a dynamic buffer (doubled when a draw needs
    more rows) and its vertex array over the shared unit-square corners."""

    def __init__(self, ctx: moderngl.Context, prog: moderngl.Program, corners: moderngl.Buffer, floats: int,
                 capacity: int, layout: str, names: tuple[str, ...]) -> None:
        self.ctx, self._prog, self._corners = ctx, prog, corners
        self._floats, self._layout, self._names = floats, layout, names
        self.capacity = capacity
        self.buffer = ctx.buffer(reserve=capacity * floats * 4, dynamic=True)
        self.vao = self._make_vao()

    def _make_vao(self) -> moderngl.VertexArray:
        return self.ctx.vertex_array(self._prog, [(self._corners, "2f", "in_corner"),
                                                  (self.buffer, self._layout, *self._names)])

    def draw(self, rows: np.ndarray) -> None:
        """Draw one quad per row of ``rows`` (float32, ``floats`` values per row, flat)."""
        n = len(rows) // self._floats
        if n > self.capacity:
            while self.capacity < n:
                self.capacity *= 2
            self.buffer.orphan(self.capacity * self._floats * 4)
            self.vao.release()
            self.vao = self._make_vao()
        # (a vertex buffer is read when the draw is issued: rewriting it for the next draw costs no wait)
        self.buffer.write(rows.tobytes())
        self.vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=n)

    def release(self) -> None:
        self.vao.release()
        self.buffer.release()


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
