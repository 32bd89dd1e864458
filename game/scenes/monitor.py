"""The camera check: every camera's latest image with what the tracker made of it.

For a therapist setting up (or a reviewer checking the simulated studio): the images in a grid,
each drawn by :func:`game.monitor.overlay_cameras` with the pixels the colour table takes for
marker colours painted in those colours over the dimmed picture, each marker's search window
and name at the centroid used, the markers a camera does not see, and the tracking state. The
overlays are redrawn when a new sample arrives (30 times a second), not every display frame.
C or Esc goes back.

The colour table (a 2^24-entry lookup, about half a second to build) is built on a helper thread
when the scene opens; until it is ready the images are shown without the painted colours.
"""

from __future__ import annotations

import logging
import math
import threading

import numpy as np

from game.app import BaseScene, Frame
from game.gfx import theme
from game.input import Action, InputEvent, Press
from game.live_link import LiveLink
from game.monitor import overlay_cameras

log = logging.getLogger(__name__)

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
        paint_colours: paint the colour table's marker pixels (builds the table once).
    """

    def __init__(self, link: LiveLink, *, paint_colours: bool = True) -> None:
        self.link = link
        self.paint_colours = paint_colours
        self.colour_table = None
        self.overlays: list[np.ndarray] = []
        self._shown = None          # (sample number, table ready) the overlays were made for
        self._builder: threading.Thread | None = None

    def enter(self, app) -> None:
        super().enter(app)
        if self.paint_colours and self.colour_table is None and self._builder is None:
            self._builder = threading.Thread(target=self._build_table, name="rehab-colour-table", daemon=True)
            self._builder.start()

    def _build_table(self) -> None:
        from tracking.colour_table import ColourTable

        markerset = self.link.markerset
        if markerset is None:
            from tracking.markerset import load_markerset

            markerset = load_markerset(getattr(getattr(self.link.tracker, "source", None), "markerset",
                                               "upper_limb_seated"))
        self.colour_table = ColourTable.build(markerset.palette)

    def handle(self, event: InputEvent) -> None:
        if isinstance(event, Press) and event.down and event.action in (Action.BACK, Action.MONITOR):
            self.app.pop()

    def _refresh(self) -> None:
        """Redraw the overlays when a new sample (or the colour table) arrived."""
        sample, markerset = self.link.latest, self.link.markerset
        key = (None if sample is None else sample.number, self.colour_table is not None)
        if key == self._shown:
            return
        images = self.link.latest_images()
        if not images:
            return
        self._shown = key
        if sample is None or markerset is None:
            self.overlays = list(images)
            return
        marker_rgb = np.asarray(markerset.palette)[markerset.colour_index]
        cameras = self.link.cameras
        # A sample without any centroid comes from a tracker that does not report them (yet):
        # no "not seen here" list built from that.
        reported = bool(np.isfinite(sample.uv_px).any())
        self.overlays = overlay_cameras(
            images, markerset.names, marker_rgb, windows_px=sample.windows_px if reported else None,
            uv_px=sample.uv_px if reported else None,
            status=sample.status, state=sample.state, message=sample.message,
            camera_names=[cam.name for cam in cameras] if len(cameras) == len(images) else None,
            colour_table=self.colour_table)

    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        s = min(w / 1280.0, h / 720.0)
        c.text("Camera check", (theme.MARGIN * s, 18 * s), round(theme.MEDIUM * s), theme.TEXT)
        warning = getattr(self.link, "warning", "")
        if warning:  # a camera that stopped or fell out of step: say which, beside the title
            c.text(warning[:1].upper() + warning[1:], (w - theme.MARGIN * s, 26 * s), round(theme.SMALL * s),
                   theme.ATTENTION, anchor="topright")
        legend = "Marker colours painted where the colour table finds them   Squares: where the tracker looks   Esc: back"
        c.text(legend, (w / 2, h - 8 * s), round(theme.SMALL * 0.85 * s), theme.TEXT_FAINT, anchor="midbottom")
        self._refresh()
        if not self.overlays:
            c.text(self.link.summary() or "Waiting for the cameras...", (w / 2, h / 2), round(theme.BODY * s),
                   theme.ATTENTION, anchor="center")
            return
        ih, iw = self.overlays[0].shape[:2]
        area = (theme.MARGIN * s, 66 * s, w - 2 * theme.MARGIN * s, h - 100 * s)
        for j, (img, rect) in enumerate(zip(self.overlays, grid_rects(area, len(self.overlays), iw / ih, 12 * s))):
            c.image(f"camera{j}", img, rect)
