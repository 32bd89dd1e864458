"""The camera check: every camera's latest image with what the tracker made of it.

For a therapist setting up (or a reviewer checking the simulated studio): the images in a grid,
each marker's centroid used this frame circled in the marker's colour, its search window drawn
as a thin square, and per camera how many markers it sees. C or Esc goes back.
"""

from __future__ import annotations

import math

import numpy as np

from game.app import BaseScene, Frame
from game.gfx import theme
from game.input import Action, InputEvent, Press
from game.live_link import LiveLink

Rect = tuple[float, float, float, float]


def grid_rects(area: Rect, n: int, image_aspect: float, gap: float) -> list[Rect]:
    """``n`` rectangles of ``image_aspect`` (w / h) tiling ``area`` as large as they fit."""
    ax, ay, aw, ah = area
    best = None
    for cols in range(1, n + 1):
        rows = math.ceil(n / cols)
        w = min((aw - (cols - 1) * gap) / cols, (ah - (rows - 1) * gap) / rows * image_aspect)
        if best is None or w > best[0]:
            best = (w, cols, rows)
    w, cols, rows = best
    h = w / image_aspect
    x0 = ax + (aw - (cols * w + (cols - 1) * gap)) / 2
    y0 = ay + (ah - (rows * h + (rows - 1) * gap)) / 2
    return [(x0 + (k % cols) * (w + gap), y0 + (k // cols) * (h + gap), w, h) for k in range(n)]


def image_to_screen(uv_px: np.ndarray, rect: Rect, image_px: tuple[int, int]) -> np.ndarray:
    """(N, 2) image pixel coordinates (OpenCV: pixel centres at integers) -> screen pixels."""
    x, y, w, h = rect
    scale = np.array([w / image_px[0], h / image_px[1]])
    return np.array([x, y]) + (np.asarray(uv_px, dtype=np.float64) + 0.5) * scale


class MonitorScene(BaseScene):
    """The camera grid.

    Args:
        link: the live tracker link.
    """

    def __init__(self, link: LiveLink) -> None:
        self.link = link

    def handle(self, event: InputEvent) -> None:
        if isinstance(event, Press) and event.down and event.action in (Action.BACK, Action.MONITOR):
            self.app.pop()

    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        s = min(w / 1280.0, h / 720.0)
        c.text("Camera check", (theme.MARGIN * s, 18 * s), round(theme.MEDIUM * s), theme.TEXT)
        c.text("Circles: markers found this frame   Squares: where the tracker looks   Esc: back",
               (w / 2, h - 8 * s), round(theme.SMALL * 0.85 * s), theme.TEXT_FAINT, anchor="midbottom")
        images = self.link.latest_images()
        if not images:
            c.text(self.link.summary() or "Waiting for the cameras...", (w / 2, h / 2), round(theme.BODY * s),
                   theme.ATTENTION, anchor="center")
            return
        ih, iw = images[0].shape[:2]
        area = (theme.MARGIN * s, 66 * s, w - 2 * theme.MARGIN * s, h - 100 * s)
        rects = grid_rects(area, len(images), iw / ih, 12 * s)
        sample = self.link.latest
        markerset = self.link.markerset
        cameras = self.link.cameras
        for j, (img, rect) in enumerate(zip(images, rects)):
            c.image(f"camera{j}", img, rect)
            if sample is not None and markerset is not None:
                self._overlay(c, sample, markerset, j, rect, (iw, ih), s)
            name = cameras[j].name if j < len(cameras) else f"camera {j + 1}"
            label = name
            if sample is not None and np.isfinite(sample.uv_px).any():  # a source that reports centroids
                label = f"{name}: {int(np.isfinite(sample.uv_px[:, j, 0]).sum())} markers"
            tw, th = c.measure(label, round(theme.SMALL * s))
            c.rect((rect[0] + 8 * s, rect[1] + 8 * s, tw + 20 * s, th + 10 * s), theme.OVERLAY, radius=8 * s)
            c.text(label, (rect[0] + 18 * s, rect[1] + 13 * s), round(theme.SMALL * s), theme.TEXT)

    @staticmethod
    def _overlay(c, sample, markerset, j: int, rect: Rect, image_px: tuple[int, int], s: float) -> None:
        scale = rect[2] / image_px[0]
        palette = np.asarray(markerset.palette)
        colours = [tuple(int(v) for v in palette[k]) for k in markerset.colour_index]
        windows = sample.windows_px[:, j]
        ok = np.isfinite(windows).all(axis=1)
        centres = image_to_screen(windows[:, :2], rect, image_px)
        for m in np.flatnonzero(ok):
            half = windows[m, 2] * scale
            x, y = centres[m]
            c.rect((x - half, y - half, 2 * half, 2 * half), (0, 0, 0, 0), border=1.5 * s,
                   border_colour=(*colours[m], 170))
        uv = sample.uv_px[:, j]
        ok = np.isfinite(uv).all(axis=1)
        xy = image_to_screen(uv, rect, image_px)
        radius = 7.0 * s
        for m in np.flatnonzero(ok):
            c.circle(tuple(xy[m]), radius + 1.5 * s, (0, 0, 0, 0), border=4 * s, border_colour=(15, 18, 24, 200))
            c.circle(tuple(xy[m]), radius, (0, 0, 0, 0), border=2.5 * s, border_colour=colours[m])
