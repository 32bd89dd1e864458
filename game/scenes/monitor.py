"""The camera check: every camera's latest image with what the tracker made of it.

For a therapist setting up (or a reviewer checking the simulated studio): the images in a grid,
each drawn by :func:`game.gfx.camera_overlay.overlay_cameras` with the pixels the colour table takes for
marker colours painted in those colours over the dimmed picture, each marker's search window
and name at the centroid used, the markers a camera does not see, and the tracking state. The
overlays are redrawn when a new sample arrives (30 times a second), not every display frame.
C or Esc goes back.

The colour table (a 2^24-entry lookup, about half a second to build) is built on a helper thread
when the scene opens; until it is ready the images are shown without the painted colours.

Manual colour pick (the fallback of colour calibration, :mod:`tracking.colour.pick`): Left and
Right choose a marker colour, a click on a ball of that colour in a camera image teaches it
(learnt from the clicked ball's pixels); the table is rebuilt on a helper thread, the images are
painted with it and the tracker tracks with it from then on. Enter saves the taught colours into
the source's calibration file (cameras or a recording; the simulated studio has none).

Under each image, the camera's clock as its image stamps show it over the last 10 s
(:func:`tracking.clock_sync.stamp_timing`): its offset and drift against the first camera and its
jitter, and in words when its timing is too irregular for the tracker to correct.
"""

from __future__ import annotations

import logging
import math
import threading
from collections import deque

import numpy as np

from calibration.errors import RehabError
from game.app import BaseScene, Frame
from game.gfx import theme
from game.input import Action, InputEvent, Pointer, PointerKind, Press
from game.live_link import LiveLink
from game.gfx.camera_overlay import overlay_cameras
from tracking.clock_sync import IRREGULAR_ADVICE, StampTiming, stamp_timing
from tracking.colour.adapt import nominal_models, save_colours_to_calibration
from tracking.colour.pick import ColourPickError, ManualColours
from tracking.colour.table import ColourTable
from tracking.live.source import calibration_file_for, learnt_colours_for
from tracking.markerset import load_markerset

log = logging.getLogger(__name__)

Rect = tuple[float, float, float, float]

#: The camera clocks are measured over this many recent samples (10 s at 30 frames/s) ...
STAMP_HISTORY = 300
#: ... and measured again after this many new ones.
STAMP_EVERY = 15


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


def screen_to_image(xy_px, rect: Rect, image_px: tuple[int, int]) -> np.ndarray:
    """The inverse of :func:`image_to_screen` for one (2,) screen point."""
    x, y, w, h = rect
    return (np.asarray(xy_px, dtype=np.float64) - (x, y)) * (image_px[0] / w, image_px[1] / h) - 0.5


def colour_name(rgb) -> str:
    """A word for a marker colour by its hue (for the teaching line)."""
    r, g, b = (int(v) for v in rgb)
    mx, mn = max(r, g, b), min(r, g, b)
    if mx - mn < 40:
        return "grey"
    if mx == r:
        hue = (60.0 * (g - b) / (mx - mn)) % 360.0
    elif mx == g:
        hue = 60.0 * (b - r) / (mx - mn) + 120.0
    else:
        hue = 60.0 * (r - g) / (mx - mn) + 240.0
    names = ((15, "red"), (40, "orange"), (70, "yellow"), (160, "green"), (200, "cyan"), (260, "blue"),
             (330, "magenta"), (360, "red"))
    return next(name for limit, name in names if hue < limit)


class MonitorScene(BaseScene):
    """The camera grid.

    Args:
        link: the live tracker link.
        paint_colours: paint the colour table's marker pixels (builds the table once).
        threaded: rebuild the table after a colour pick on a helper thread (False: at once, tests).
    """

    def __init__(self, link: LiveLink, *, paint_colours: bool = True, threaded: bool = True) -> None:
        self.link = link
        self.paint_colours = paint_colours
        self.threaded = threaded
        self.colour_table = None
        self.overlays: list[np.ndarray] = []
        self._shown = None          # (sample number, table) the overlays were made for
        self._builder: threading.Thread | None = None
        self.teach_colour = 0       # palette index a click teaches
        self.manual = None          # tracking.colour.pick.ManualColours, made at the first pick
        self.message = ""
        self.message_colour = theme.TEXT_DIM
        self.images: list[np.ndarray] = []   # the raw images the overlays show (a click is learnt from them)
        self.rects: list[Rect] = []          # where each camera image was drawn, screen pixels
        self._teacher: threading.Thread | None = None
        self._stamps: deque = deque(maxlen=STAMP_HISTORY)  # recent samples' (C,) image stamps
        self._stamped = -1          # number of the last sample whose stamps were taken
        self._since = 0             # samples taken since the clocks were last measured
        self.timing: StampTiming | None = None

    def enter(self, app) -> None:
        super().enter(app)
        if self.paint_colours and self.colour_table is None and self._builder is None:
            self._builder = threading.Thread(target=self._build_table, name="rehab-colour-table", daemon=True)
            self._builder.start()

    def _build_table(self) -> None:
        markerset = self.link.markerset
        if markerset is None:
            markerset = load_markerset(getattr(getattr(self.link.tracker, "source", None), "markerset",
                                               "upper_limb_seated"))
        self.colour_table = ColourTable.build(markerset.palette)

    def handle(self, event: InputEvent) -> None:
        if isinstance(event, Press) and event.down:
            if event.action in (Action.BACK, Action.MONITOR):
                self.app.pop()
            elif event.action in (Action.LEFT, Action.RIGHT) and self.link.markerset is not None:
                n = self.link.markerset.palette.shape[0]
                self.teach_colour = (self.teach_colour + (1 if event.action is Action.RIGHT else -1)) % n
            elif event.action is Action.SELECT:
                self.save_colours()
        elif isinstance(event, Pointer) and event.kind == PointerKind.PRESS and event.button == 1:
            w, h = self.app.screen.size_px
            xy = (event.x * w, event.y * h)
            for j, (x, y, rw, rh) in enumerate(self.rects):
                if x <= xy[0] < x + rw and y <= xy[1] < y + rh and j < len(self.images):
                    ih, iw = self.images[j].shape[:2]
                    self.teach(j, screen_to_image(xy, self.rects[j], (iw, ih)))
                    return

    # ----------------------------------------------------------------- colour pick
    def _say(self, text: str, colour=theme.TEXT_DIM) -> None:
        self.message, self.message_colour = text, colour

    def teach(self, camera: int, uv_px) -> bool:
        """Learn the selected colour from the ball at ``uv_px`` in camera ``camera``'s image shown."""
        markerset = self.link.markerset
        if markerset is None or camera >= len(self.images):
            return False
        if self._teacher is not None and self._teacher.is_alive():
            self._say("Still rebuilding the colour table...", theme.ATTENTION)
            return False
        if self.manual is None:
            self.manual = ManualColours(self._start_models(markerset))
        name = colour_name(markerset.palette[self.teach_colour])
        try:
            blob = self.manual.teach(self.teach_colour, self.images[camera], uv_px, table=self.colour_table)
        except ColourPickError as exc:
            self._say(str(exc)[:1].upper() + str(exc)[1:], theme.FAILURE)
            return False
        self._say(f"Learnt {name} from {len(blob.pixels_bgr)} pixels (hue {blob.hue_deg:.0f} deg): rebuilding the table",
                  theme.ACCENT)
        if self.threaded:
            self._teacher = threading.Thread(target=self._rebuild, name="rehab-colour-pick", daemon=True)
            self._teacher.start()
        else:
            self._rebuild()
        return True

    def _start_models(self, markerset):
        """The colours to teach from: those learnt into the calibration file if any, else the nominal ones."""

        config = getattr(getattr(self.link, "tracker", None), "source", None)
        try:
            learnt = learnt_colours_for(config, markerset) if config is not None else None
        except RehabError as exc:
            log.warning("the calibration's learnt colours are ignored: %s", exc)
            learnt = None
        return list(learnt[0]) if learnt is not None else nominal_models(markerset.palette)

    def _rebuild(self) -> None:
        table = self.manual.table()
        models, label_hs = list(self.manual.models), self.manual.label_hs()
        self.colour_table = table
        self._shown = None
        self.link.set_colours(models, label_hs)

    def save_colours(self) -> bool:
        """Write the taught colours into the source's calibration file ([metadata.marker_colours])."""

        if self.manual is None or not self.manual.picks.any():
            self._say("Nothing taught yet: click a ball in a camera image first", theme.ATTENTION)
            return False
        config = getattr(getattr(self.link, "tracker", None), "source", None)
        path = calibration_file_for(config) if config is not None else None
        if path is None:
            self._say("The simulated studio has no calibration file: the colours are used until the game closes",
                      theme.ATTENTION)
            return False
        try:
            save_colours_to_calibration(path, self.link.markerset, self.manual.models, self.manual.label_hs())
        except (RehabError, OSError) as exc:
            self._say(f"Not saved: {exc}", theme.FAILURE)
            return False
        self._say(f"Colours saved in {path}", theme.ACCENT)
        return True

    def _take_stamps(self) -> None:
        """Keep the new samples' image stamps; measure the camera clocks now and then."""
        for sample in getattr(self.link, "new_samples", ()) or ():
            stamps = sample.stamps_s
            if sample.number <= self._stamped or stamps is None:
                continue
            if self._stamps and len(self._stamps[-1]) != len(stamps):
                self._stamps.clear()  # (another source: other cameras)
            self._stamped = sample.number
            self._stamps.append(np.asarray(stamps, dtype=np.float64))
            self._since += 1
        if self._since >= STAMP_EVERY or (self.timing is None and self._since):
            self.timing = stamp_timing(np.array(self._stamps))
            self._since = 0

    def _refresh(self) -> None:
        """Redraw the overlays when a new sample (or the colour table) arrived."""
        sample, markerset = self.link.latest, self.link.markerset
        key = (None if sample is None else sample.number, id(self.colour_table))
        if key == self._shown:
            return
        images = self.link.latest_images()
        if not images:
            return
        self._shown = key
        self.images = list(images)
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
        markerset = self.link.markerset
        if markerset is not None:
            rgb = markerset.palette[self.teach_colour % markerset.palette.shape[0]]
            names = [n for n, k in zip(markerset.names, markerset.colour_index) if k == self.teach_colour % markerset.palette.shape[0]]
            line = f"Teach a colour: Left/Right choose, click a ball   {colour_name(rgb)} ({', '.join(names[:3])})   Enter: save"
            box = c.text(line, (theme.MARGIN * s, 44 * s), round(theme.SMALL * 0.85 * s), theme.TEXT_DIM)
            c.rect((box[0] + box[2] + 8 * s, 44 * s, 18 * s, 16 * s), tuple(int(v) for v in rgb) + (255,), radius=4 * s)
            if self.message:
                c.text(self.message, (w - theme.MARGIN * s, 44 * s), round(theme.SMALL * 0.85 * s), self.message_colour,
                       anchor="topright")
        self._refresh()
        if not self.overlays:
            c.text(self.link.summary() or "Waiting for the cameras...", (w / 2, h / 2), round(theme.BODY * s),
                   theme.ATTENTION, anchor="center")
            return
        ih, iw = self.overlays[0].shape[:2]
        area = (theme.MARGIN * s, 66 * s, w - 2 * theme.MARGIN * s, h - 100 * s)
        self.rects = grid_rects(area, len(self.overlays), iw / ih, 12 * s)
        for j, (img, rect) in enumerate(zip(self.overlays, self.rects)):
            c.image(f"camera{j}", img, rect)
        self._take_stamps()
        if self.timing is not None and len(self.timing.jitter_s) == len(self.rects):
            cameras = self.link.cameras
            names = [cam.name for cam in cameras] if len(cameras) == len(self.rects) else \
                [f"camera {k + 1}" for k in range(len(self.rects))]
            size = round(theme.SMALL * 0.75 * s)
            for j, (line, rect) in enumerate(zip(self.timing.lines(names), self.rects)):
                irregular = bool(self.timing.irregular[j])
                rows = [line, IRREGULAR_ADVICE] if irregular else [line]
                colour = theme.ATTENTION if irregular else theme.TEXT_DIM
                x, y, rw, rh = rect
                tall = len(rows) * (size + 4 * s) + 4 * s
                c.rect((x, y + rh - tall, rw, tall), theme.OVERLAY)
                for k, row in enumerate(rows):
                    c.text(row, (x + 6 * s, y + rh - tall + 4 * s + k * (size + 4 * s)), size, colour)
