"""The camera monitor: each camera's image with what the tracker sees drawn over it.

This is how a therapist checks the setup: every camera's picture, the pixels the colour table
labels as marker colours (painted in the palette colour over a dimmed image), the search window
of each tracked marker (a square in the marker's colour), each marker's name at the centroid the
tracker used, the markers this camera does not see, and the tracking state.

Drawing is pure numpy + OpenCV on BGR images (:func:`overlay_camera`, :func:`overlay_cameras`,
:func:`tile_images`), so tests check pixels; :class:`MonitorTexture` is the small moderngl
bridge that shows such an image in a viewport of the game window.

Sub-pixel positions are drawn with OpenCV's fixed-point ``shift`` (4 fractional bits) rather
than rounded to whole pixels.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import cv2
import moderngl
import numpy as np

from tracking.marker_status import MarkerStatus

if TYPE_CHECKING:
    from tracking.colour.table import ColourTable

_SHIFT = 4  # fractional bits of OpenCV's fixed-point coordinates
_SCALE = 1 << _SHIFT
_FONT = cv2.FONT_HERSHEY_SIMPLEX
STATE_WORDS = {0: "WAITING", 1: "TRACKING"}


def _fixed(x: float) -> int:
    return int(round(x * _SCALE))


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float, bgr: tuple[int, int, int]) -> None:
    """Text with a dark outline, readable on any background.

    The outline is the text's own strokes grown by a pixel. (Drawn as the same text with thicker
    strokes it was wider: OpenCV's Hershey letters advance by their stroke width, so the dark copy
    drifted right letter by letter and its last letters showed after the text, "MRW2 W2".)
    """
    thick = max(1, int(round(scale * 2)))
    (tw, th), base = cv2.getTextSize(text, _FONT, scale, thick)
    h, w = img.shape[:2]
    pad = thick + 2
    x0, y0 = max(org[0] - pad, 0), max(org[1] - th - pad, 0)
    x1, y1 = min(org[0] + tw + pad, w), min(org[1] + base + pad, h)
    if x1 <= x0 or y1 <= y0:
        return
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    cv2.putText(mask, text, (org[0] - x0, org[1] - y0), _FONT, scale, 255, thick, cv2.LINE_AA)
    outline = cv2.dilate(mask, np.ones((3, 3), np.uint8))
    roi = img[y0:y1, x0:x1]
    roi[:] = (roi * (1.0 - outline[..., None] / 255.0)).astype(np.uint8)
    cv2.putText(img, text, org, _FONT, scale, bgr, thick, cv2.LINE_AA)


def paint_labels(image_bgr: np.ndarray, labels: np.ndarray, palette_rgb: np.ndarray, *, dim: float = 0.55) -> np.ndarray:
    """The image dimmed by ``dim`` with every labelled pixel painted in its palette colour.

    Args:
        image_bgr: (H, W, 3) uint8.
        labels: (H, W) uint8 colour-table labels: 0 background, k + 1 palette colour k.
        palette_rgb: (K, 3) uint8 sRGB palette.
    Returns:
        (H, W, 3) uint8 new image.
    """
    if labels.shape != image_bgr.shape[:2]:
        raise ValueError(f"labels {labels.shape} do not match the image {image_bgr.shape[:2]}")
    lut = np.zeros((256, 3), np.uint8)
    pal = np.asarray(palette_rgb, np.uint8)[:, ::-1]
    lut[1 : 1 + len(pal)] = pal
    out = (image_bgr.astype(np.float32) * dim).astype(np.uint8)
    mask = labels > 0
    out[mask] = lut[labels[mask]]
    return out


def overlay_camera(
    image_bgr: np.ndarray,
    names: Sequence[str],
    marker_rgb: np.ndarray,
    *,
    windows_px: np.ndarray | None = None,
    uv_px: np.ndarray | None = None,
    status: np.ndarray | None = None,
    labels: np.ndarray | None = None,
    palette_rgb: np.ndarray | None = None,
    title: str = "",
    footer: str = "",
) -> np.ndarray:
    """One camera's image with the tracker's view drawn over it.

    Args:
        image_bgr: (H, W, 3) uint8 camera image (not modified).
        names: the M marker names.
        marker_rgb: (M, 3) uint8 sRGB colour of each marker.
        windows_px: (M, 3) float64 search windows in this camera: centre u, v and half size in
            pixels; NaN rows have none.
        uv_px: (M, 2) float64 centroid of each marker in this camera, NaN where not seen.
        status: (M,) uint8 :class:`MarkerStatus` of each marker (3D); estimated markers are
            labelled with a trailing ``*``.
        labels, palette_rgb: colour-table labels of the image and the palette, to paint the
            colour regions (both or neither).
        title: first line at the top (camera name and such).
        footer: a line at the bottom (e.g. which markers this camera does not see).

    Returns:
        (H, W, 3) uint8 new image.
    """
    img = np.ascontiguousarray(image_bgr)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image_bgr must be (H, W, 3) uint8, got {img.shape} {img.dtype}")
    m = len(names)
    out = paint_labels(img, labels, palette_rgb) if labels is not None and palette_rgb is not None else img.copy()
    h, w = out.shape[:2]
    scale = max(0.35, w / 900.0)
    bgr = [tuple(int(c) for c in rgb[::-1]) for rgb in np.asarray(marker_rgb, np.uint8).reshape(m, 3)]
    if windows_px is not None:
        win = np.asarray(windows_px, np.float64).reshape(m, 3)
        for k in np.flatnonzero(np.isfinite(win).all(axis=1)):
            u, v, half = win[k]
            cv2.rectangle(out, (_fixed(u - half), _fixed(v - half)), (_fixed(u + half), _fixed(v + half)),
                          bgr[k], 1, cv2.LINE_AA, _SHIFT)
    if uv_px is not None:
        uv = np.asarray(uv_px, np.float64).reshape(m, 2)
        st = np.full(m, MarkerStatus.MEASURED, np.uint8) if status is None else np.asarray(status)
        for k in np.flatnonzero(np.isfinite(uv).all(axis=1)):
            u, v = uv[k]
            cv2.circle(out, (_fixed(u), _fixed(v)), 3 * _SCALE, (255, 255, 255), 1, cv2.LINE_AA, _SHIFT)
            label = names[k] + ("*" if st[k] == MarkerStatus.ESTIMATED else "")
            _text(out, label, (int(u + 6), int(v - 4)), 0.8 * scale, bgr[k])
    line_h = int(30 * scale)
    if title:
        _text(out, title, (6, line_h), scale, (255, 255, 255))
    if footer:
        _text(out, footer, (6, h - int(10 * scale)), 0.8 * scale, (180, 220, 255))
    return out


def overlay_cameras(
    images_bgr: Sequence[np.ndarray],
    names: Sequence[str],
    marker_rgb: np.ndarray,
    *,
    windows_px: np.ndarray | None = None,
    uv_px: np.ndarray | None = None,
    status: np.ndarray | None = None,
    state: int | None = None,
    message: str = "",
    camera_names: Sequence[str] | None = None,
    colour_table: ColourTable | None = None,
) -> list[np.ndarray]:
    """Every camera's overlay from one tracker sample (the fields of ``LiveSample``).

    Args:
        images_bgr: C images (H, W, 3) uint8, in camera order.
        names, marker_rgb: the marker set's names and colours (M, 3) uint8.
        windows_px: (M, C, 3) float64 search windows, NaN where none.
        uv_px: (M, C, 2) float64 centroids, NaN where none.
        status: (M,) uint8 :class:`MarkerStatus`.
        state: tracking state (0 WAITING, 1 TRACKING), shown in every title with ``message``.
        camera_names: C names for the titles (default cam1, cam2, ...).
        colour_table: a :class:`tracking.colour.table.ColourTable`; when given, its labels of
            each image are painted (costs ~1 ms per 640x480 image).

    Returns:
        C overlaid images. Redraw them when a new sample arrives (15-30 Hz), not every display
        frame: four 320x240 cameras cost a few milliseconds.
    """
    c = len(images_bgr)
    m = len(names)
    for label, arr, k in (("windows_px", windows_px, 3), ("uv_px", uv_px, 2)):
        if arr is not None and np.shape(arr) != (m, c, k):
            raise ValueError(f"{label} must be ({m}, {c}, {k}) for {m} markers and {c} images, got {np.shape(arr)}")
    cams = list(camera_names) if camera_names is not None else [f"cam{j + 1}" for j in range(c)]
    st = None if status is None else np.asarray(status)
    lost = [names[k] for k in range(m) if st is not None and st[k] == MarkerStatus.LOST]
    head = ""
    if state is not None:
        head = STATE_WORDS.get(int(state), str(state))
        if lost:
            head += f"  lost: {', '.join(lost)}"
        if message:
            head += f"  {message}"
    out = []
    for j, img in enumerate(images_bgr):
        win_j = None if windows_px is None else np.asarray(windows_px)[:, j, :]
        uv_j = None if uv_px is None else np.asarray(uv_px)[:, j, :]
        unseen = [] if uv_j is None else [names[k] for k in range(m) if not np.isfinite(uv_j[k]).all()]
        labels = colour_table.classify(img) if colour_table is not None else None
        palette = colour_table.palette_rgb if colour_table is not None else None
        title = f"{cams[j]}  {head}".rstrip()
        footer = f"not seen here: {', '.join(unseen)}" if unseen else ""
        out.append(overlay_camera(img, names, marker_rgb, windows_px=win_j, uv_px=uv_j, status=st,
                                  labels=labels, palette_rgb=palette, title=title, footer=footer))
    return out


def grid_shape(n: int, aspect: float = 16 / 9, tile_aspect: float = 4 / 3) -> tuple[int, int]:
    """(rows, columns) for ``n`` tiles of ``tile_aspect`` filling an area of ``aspect`` best."""
    best, best_size = (1, max(n, 1)), -1.0
    for cols in range(1, max(n, 1) + 1):
        rows = math.ceil(n / cols)
        size = min(aspect / (cols * tile_aspect), 1.0 / rows)  # tile height in area heights
        if size > best_size + 1e-12:
            best, best_size = (rows, cols), size
    return best


def tile_images(images_bgr: Sequence[np.ndarray], columns: int | None = None, *, gap_px: int = 4,
                background: tuple[int, int, int] = (40, 40, 40)) -> np.ndarray:
    """The images side by side in a grid (each resized to the first one's size)."""
    if not images_bgr:
        raise ValueError("tile_images needs at least one image")
    h, w = images_bgr[0].shape[:2]
    n = len(images_bgr)
    cols = columns or grid_shape(n, tile_aspect=w / h)[1]
    rows = math.ceil(n / cols)
    out = np.empty((rows * h + (rows - 1) * gap_px, cols * w + (cols - 1) * gap_px, 3), np.uint8)
    out[:] = background
    for k, img in enumerate(images_bgr):
        if img.shape[:2] != (h, w):
            img = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
        r, c = divmod(k, cols)
        out[r * (h + gap_px) : r * (h + gap_px) + h, c * (w + gap_px) : c * (w + gap_px) + w] = img
    return out


_VERTEX_QUAD = """
#version 330
out vec2 v_uv;
void main() {
    vec2 p = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1));
    v_uv = vec2(p.x, 1.0 - p.y);  // image row 0 is the top
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

_FRAGMENT_QUAD = """
#version 330
uniform sampler2D u_image;
in vec2 v_uv;
out vec4 f_colour;
void main() {
    f_colour = vec4(texture(u_image, v_uv).bgr, 1.0);  // the texture holds BGR bytes
}
"""


class MonitorTexture:
    """A BGR image as a moderngl texture, drawn into a viewport of the bound framebuffer.

    Call :meth:`upload` when the image changes (the texture is reallocated only when its size
    does) and :meth:`draw` every frame.
    """

    def __init__(self, ctx: moderngl.Context) -> None:
        self._ctx = ctx
        self._prog = ctx.program(vertex_shader=_VERTEX_QUAD, fragment_shader=_FRAGMENT_QUAD)
        self._vao = ctx.vertex_array(self._prog, [])
        self._tex: moderngl.Texture | None = None

    @property
    def size(self) -> tuple[int, int] | None:
        """(width, height) of the uploaded image, None before the first upload."""
        return None if self._tex is None else self._tex.size

    def upload(self, image_bgr: np.ndarray) -> None:
        """image_bgr: (H, W, 3) uint8."""
        img = np.ascontiguousarray(image_bgr, dtype=np.uint8)
        h, w = img.shape[:2]
        if self._tex is None or self._tex.size != (w, h):
            if self._tex is not None:
                self._tex.release()
            self._tex = self._ctx.texture((w, h), 3, alignment=1)
            self._tex.filter = moderngl.LINEAR, moderngl.LINEAR
        self._tex.write(img.tobytes(), alignment=1)

    def draw(self, viewport: tuple[int, int, int, int] | None = None) -> None:
        """Draw the image stretched over ``viewport`` (x, y, width, height in window pixels,
        y from the bottom as in OpenGL), by default the current one."""
        if self._tex is None:
            return
        old = self._ctx.viewport
        if viewport is not None:
            self._ctx.viewport = viewport
        self._ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND | moderngl.CULL_FACE)
        self._tex.use(0)
        self._vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        self._ctx.viewport = old

    def release(self) -> None:
        for obj in (self._tex, self._vao, self._prog):
            if obj is not None:
                obj.release()
        self._tex = None
