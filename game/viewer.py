"""The interim ``rehab play``: the simulated patient, measured live, shown in a pygame window.

Until the game proper exists, ``rehab play`` shows the measurement working with one command: the
studio renders the patient from its virtual cameras, the full-frame measurement
(:class:`tracking.measure.FrameMeasurer`) finds the marker centroids and triangulates them, and
the window shows, every frame,

- the camera images in a grid, each detected centroid circled and each measured 3D point
  reprojected as a cross, in the marker's colour;
- front and side orthographic views of the measured points, the true markers as faint rings;
- a status panel: motion and time, frame sets per second of simulation and measurement, points
  measured of the markers worn, and the keys.

Three parts, kept apart so that tests drive each directly:

- computing: :class:`LiveSimulation` (render + measure one frame -> :class:`LiveFrame`),
  :class:`Playhead` (which frame is due), :class:`RateMeter`;
- drawing: :func:`draw_live_view` (data + a pygame Surface -> pixels; no computing beyond screen
  coordinates);
- the loop: :func:`run_viewer` (events -> actions, pacing with an injected clock, screenshot).

The window is a plain software surface; the studio renders through its own offscreen EGL context.
"""

from __future__ import annotations

import enum
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Sequence

import cv2
import numpy as np
import pygame

from calibration.camera import Camera
from calibration.errors import RehabError
from game.display import close_window, open_window
from tracking.blobs import Blobs
from tracking.colour_table import ColourTable
from tracking.measure import FrameMeasurer, observations_from_blobs
from tracking.reconstruction import Points3D, reconstruct
from tracking.sim.body import BodyModel
from tracking.sim.motions import Motion, available_motions, load_motion
from tracking.sim.studio import SimulationSettings, Studio, studio_from_settings

log = logging.getLogger(__name__)

WINDOW_SIZE = (1280, 720)
#: A measured point farther than this from every true marker is a ghost (as in tracking.evaluate).
MATCH_M = 0.020
#: Margin around the motion's marker extent in the 3D views.
VIEW_MARGIN_M = 0.08
#: Smallest side of the 3D views' box, so that a motion in one plane still gets a readable view.
VIEW_MIN_SIZE_M = 0.6
#: How often the paused loop looks for keys.
PAUSED_POLL_S = 0.05

Clock = Callable[[], float]


# ============================================================================ computing
@dataclass(frozen=True, slots=True)
class PlayOptions:
    """What ``rehab play`` was asked for.

    Attributes:
        motion: built-in motion name or motion file to start with.
        rig: camera layout name or file.
        size_px: camera image (width, height).
        fps: camera frame rate; the motion advances 1/fps per frame set.
        headless: render offscreen (SDL dummy driver), one frame set per step, no pacing.
        seconds: stop after this much simulated time (None: run until quit).
        screenshot: PNG written from the last frame shown.
        noise_sigma: sensor noise of the simulated cameras, 8-bit units.
        seed: seed of the sensor noise.
    """

    motion: str = "right_external_rotation"
    rig: str = "ring4"
    size_px: tuple[int, int] = (320, 240)
    fps: float = 15.0
    headless: bool = False
    seconds: float | None = None
    screenshot: Path | None = None
    noise_sigma: float = 1.5
    seed: int = 0


def frame_count(seconds: float, fps: float) -> int:
    """Frame sets in ``seconds`` of simulated time at ``fps`` (at least one)."""
    return max(1, int(round(seconds * fps)))


@dataclass(frozen=True, slots=True)
class LiveFrame:
    """One frame set, measured, with the simulator's truth.

    Attributes:
        index: frame number since the motion (re)started.
        motion: motion name.
        time_s: time within the motion (it loops).
        duration_s: the motion's length.
        images: per camera, (H, W, 3) uint8 BGR.
        blobs: per camera, the marker centroids found.
        points: the measured 3D points (world metres).
        truth_m: (M, 3) true marker centres, world metres, in marker-set order.
        error_m: (P,) distance of each measured point to the nearest true marker.
        extent_m: (2, 3) low and high corner of the box the 3D views show (the motion's reach).
        render_s: wall seconds the simulation took.
        measure_s: wall seconds the measurement took.
    """

    index: int
    motion: str
    time_s: float
    duration_s: float
    images: tuple[np.ndarray, ...]
    blobs: tuple[Blobs, ...]
    points: Points3D
    truth_m: np.ndarray
    error_m: np.ndarray
    extent_m: np.ndarray
    render_s: float
    measure_s: float

    @property
    def n_matched(self) -> int:
        """Points within :data:`MATCH_M` of a true marker."""
        return int((self.error_m <= MATCH_M).sum())

    @property
    def rms_error_mm(self) -> float:
        """RMS distance of the matched points to their true markers, mm (NaN if none)."""
        ok = self.error_m[self.error_m <= MATCH_M]
        return float(np.sqrt(np.mean(ok**2)) * 1000.0) if len(ok) else math.nan


@dataclass(frozen=True, slots=True)
class RigInfo:
    """What the drawing needs to know about the rig and the marker set, fixed for a session.

    Attributes:
        cameras: the calibrated cameras, in image order.
        palette_rgb: (K, 3) uint8 sRGB marker colours; ``Points3D.colour`` and ``Blobs.colour``
            index it.
        marker_colour: (M,) palette index of each marker (colours of the true-marker rings).
        links: pairs of marker indices joined by a faint line in the 3D views (a stick figure of
            the truth, so that the points read as a body).
    """

    cameras: tuple[Camera, ...]
    palette_rgb: np.ndarray
    marker_colour: np.ndarray
    links: tuple[tuple[int, int], ...]


#: Stick-figure lines between markers of ``upper_limb_seated``; pairs naming a marker that a
#: marker set lacks are skipped.
STICK_FIGURE = (
    ("MRS", "MB"), ("MB", "MLS"), ("MB", "MP"),
    ("MRS", "MRE1"), ("MRS", "MRE2"), ("MRE1", "MRE2"), ("MRE1", "MRW1"), ("MRE2", "MRW2"), ("MRW1", "MRW2"),
    ("MLS", "MLE1"), ("MLS", "MLE2"), ("MLE1", "MLE2"), ("MLE1", "MLW1"), ("MLE2", "MLW2"), ("MLW1", "MLW2"),
    ("MP", "MRH"), ("MP", "MLH"), ("MRH", "MLH"),
)


def stick_figure_links(names: Sequence[str]) -> tuple[tuple[int, int], ...]:
    """Index pairs of :data:`STICK_FIGURE` for a marker set's names."""
    index = {n: i for i, n in enumerate(names)}
    return tuple((index[a], index[b]) for a, b in STICK_FIGURE if a in index and b in index)


def motion_extent_m(body: BodyModel, motion: Motion, samples_per_s: float = 4.0) -> np.ndarray:
    """(2, 3) box around every true marker over the whole motion, plus :data:`VIEW_MARGIN_M`,
    each side at least :data:`VIEW_MIN_SIZE_M`."""
    markers = np.concatenate([body.markers_m(motion.pose_at(t)) for t in motion.times(samples_per_s)])
    lo, hi = markers.min(axis=0) - VIEW_MARGIN_M, markers.max(axis=0) + VIEW_MARGIN_M
    grow = np.maximum(VIEW_MIN_SIZE_M - (hi - lo), 0.0) / 2.0
    return np.stack([lo - grow, hi + grow])


def nearest_distance_m(points_m: np.ndarray, truth_m: np.ndarray) -> np.ndarray:
    """(P,) distance from each of the (P, 3) points to the nearest of the (M, 3) markers."""
    if len(points_m) == 0:
        return np.zeros(0)
    return np.linalg.norm(points_m[:, None, :] - truth_m[None, :, :], axis=-1).min(axis=1)


class LiveSimulation:
    """The simulated patient playing a motion in a loop, rendered and measured frame by frame.

    It computes only; :func:`draw_live_view` draws what it returns.

    Args:
        studio: the simulated studio (owns its EGL context; closed by :meth:`close`).
        motion: the first motion, already loaded for the studio's body.
        playlist: motion names or files that Right arrow cycles through; ``motion`` is the first.
        fps: camera frame rate.
        noise_sigma: sensor noise, 8-bit units.
        seed: sensor noise seed.
        clock: wall clock in seconds, to time the stages.
    """

    def __init__(self, studio: Studio, motion: Motion, playlist: Sequence[str], *, fps: float,
                 noise_sigma: float = 1.5, seed: int = 0, clock: Clock = time.perf_counter) -> None:
        self.studio = studio
        self.fps = float(fps)
        self.noise_sigma = float(noise_sigma)
        self.seed = int(seed)
        self._clock = clock
        self._playlist = tuple(playlist)
        self._position = 0
        self._motions: dict[str, Motion] = {self._playlist[0]: motion}
        self._extents: dict[str, np.ndarray] = {}
        ms = studio.markerset
        self.measurer = FrameMeasurer(studio.cameras, ColourTable.build(ms.palette), ms.radius_m)
        self.rig = RigInfo(studio.cameras, ms.palette, ms.colour_index, stick_figure_links(ms.names))

    @classmethod
    def create(cls, options: PlayOptions, clock: Clock = time.perf_counter) -> "LiveSimulation":
        """Build the studio, the first motion and the playlist that :class:`PlayOptions` describes."""
        settings = SimulationSettings(motion=options.motion, rig=options.rig, size_px=options.size_px,
                                      fps=options.fps, noise_sigma=options.noise_sigma, seed=options.seed)
        studio, motion = studio_from_settings(settings)
        names = available_motions()
        if options.motion in names:
            k = names.index(options.motion)
            playlist = names[k:] + names[:k]
        else:
            playlist = [options.motion, *names]
        return cls(studio, motion, playlist, fps=options.fps, noise_sigma=options.noise_sigma,
                   seed=options.seed, clock=clock)

    @property
    def motion(self) -> Motion:
        name = self._playlist[self._position]
        if name not in self._motions:
            self._motions[name] = load_motion(name, self.studio.body.dims)
        return self._motions[name]

    @property
    def motion_name(self) -> str:
        """The current playlist entry (known before the motion is loaded)."""
        return Path(self._playlist[self._position]).stem

    def next_motion(self) -> None:
        """Switch to the next motion of the playlist (it starts from frame 0)."""
        self._position = (self._position + 1) % len(self._playlist)

    def _extent(self, motion: Motion) -> np.ndarray:
        if motion.name not in self._extents:
            self._extents[motion.name] = motion_extent_m(self.studio.body, motion)
        return self._extents[motion.name]

    def measure(self, images: Sequence[np.ndarray]) -> tuple[list[Blobs], Points3D]:
        """Centroids in every image and the 3D points triangulated from them.

        The same steps as :meth:`FrameMeasurer.measure`, keeping the centroids for display.
        """
        blobs = self.measurer.blobs(images)
        m = self.measurer
        points = reconstruct(m.geometry, [observations_from_blobs(b) for b in blobs], m.params)
        return blobs, points

    def frame(self, index: int) -> LiveFrame:
        """Render and measure frame ``index`` of the current motion (looping; deterministic)."""
        motion = self.motion
        extent = self._extent(motion)
        t = (index / self.fps) % motion.duration_s if motion.duration_s > 0 else 0.0
        t0 = self._clock()
        sim = self.studio.render(motion.pose_at(t), index, t, noise_sigma=self.noise_sigma,
                                 seed=self.seed * 1_000_003 + index, with_visibility=False)
        t1 = self._clock()
        images = tuple(sim.frames.images)
        blobs, points = self.measure(images)
        t2 = self._clock()
        return LiveFrame(
            index=index, motion=motion.name, time_s=t, duration_s=motion.duration_s,
            images=images, blobs=tuple(blobs), points=points, truth_m=sim.markers_m,
            error_m=nearest_distance_m(points.p_world_m, sim.markers_m), extent_m=extent,
            render_s=t1 - t0, measure_s=t2 - t1,
        )

    def close(self) -> None:
        self.studio.close()

    def __enter__(self) -> "LiveSimulation":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Playhead:
    """Which frame set is due.

    Stepped (headless): every :meth:`advance` moves one frame, whatever the wall time.
    Real time (the window): frames are due every 1/fps seconds of the clock; when the loop falls
    behind, :meth:`advance` skips to the newest due frame, as a tracker that always takes the
    camera's latest frame, so the patient moves at true speed.

    Args:
        fps: frame rate.
        clock: wall clock in seconds.
        realtime: follow the clock (True) or step (False).
    """

    def __init__(self, fps: float, clock: Clock, *, realtime: bool) -> None:
        self.fps = float(fps)
        self.realtime = realtime
        self._clock = clock
        self.index = 0
        self._origin_s = clock()
        self._paused_at_s: float | None = None

    def restart(self) -> None:
        self.index = 0
        self._origin_s = self._clock()
        if self._paused_at_s is not None:
            self._paused_at_s = self._origin_s

    @property
    def paused(self) -> bool:
        return self._paused_at_s is not None

    def set_paused(self, paused: bool) -> None:
        if paused and self._paused_at_s is None:
            self._paused_at_s = self._clock()
        elif not paused and self._paused_at_s is not None:
            self._origin_s += self._clock() - self._paused_at_s
            self._paused_at_s = None

    def advance(self) -> int:
        """Move to the next due frame; returns how many frames were skipped."""
        nxt = self.index + 1
        if self.realtime:
            due = int(math.floor((self._clock() - self._origin_s) * self.fps))
            skipped = max(0, due - nxt)
            self.index = max(nxt, due)
            return skipped
        self.index = nxt
        return 0

    def wait_s(self) -> float:
        """Wall seconds until the current frame is due (0 when stepping, late or paused)."""
        if not self.realtime or self.paused:
            return 0.0
        return max(0.0, self._origin_s + self.index / self.fps - self._clock())


class RateMeter:
    """Smoothed duration of a repeated step, read as steps per second."""

    def __init__(self, smoothing: float = 0.1) -> None:
        self.smoothing = smoothing
        self.mean_s: float | None = None
        self.total_s = 0.0
        self.count = 0

    def add(self, dt_s: float) -> None:
        self.total_s += dt_s
        self.count += 1
        self.mean_s = dt_s if self.mean_s is None else self.mean_s + self.smoothing * (dt_s - self.mean_s)

    @property
    def per_second(self) -> float:
        return 1.0 / self.mean_s if self.mean_s else math.nan

    @property
    def average_ms(self) -> float:
        return 1000.0 * self.total_s / self.count if self.count else math.nan


@dataclass(frozen=True, slots=True)
class Status:
    """The loop's state for the status panel.

    Attributes:
        paused: playback is paused.
        simulation_fps: frame sets per second the simulator renders (from its time per frame).
        measurement_fps: frame sets per second the measurement handles (from its time per frame).
        shown_fps: frames per second the window actually shows.
        camera_fps: the cameras' frame rate.
    """

    paused: bool = False
    simulation_fps: float = math.nan
    measurement_fps: float = math.nan
    shown_fps: float = math.nan
    camera_fps: float = 15.0


class Action(enum.Enum):
    QUIT = "quit"
    TOGGLE_PAUSE = "pause"
    NEXT_MOTION = "next motion"
    RESTART = "restart"


KEYMAP = {
    pygame.K_SPACE: Action.TOGGLE_PAUSE,
    pygame.K_RIGHT: Action.NEXT_MOTION,
    pygame.K_r: Action.RESTART,
    pygame.K_ESCAPE: Action.QUIT,
    pygame.K_q: Action.QUIT,
}


def actions_from_events(events: Iterable[pygame.event.Event]) -> list[Action]:
    """Raw pygame events -> viewer actions, through :data:`KEYMAP`."""
    out = []
    for ev in events:
        if ev.type == pygame.QUIT:
            out.append(Action.QUIT)
        elif ev.type == pygame.KEYDOWN and ev.key in KEYMAP:
            out.append(KEYMAP[ev.key])
    return out


# ============================================================================ drawing
BACKGROUND = (24, 26, 30)
PANEL = (36, 39, 45)
PANEL_EDGE = (62, 67, 76)
GRID = (50, 54, 61)
TEXT = (235, 237, 240)
TEXT_DIM = (160, 166, 175)
OUTLINE = (0, 0, 0)
ACCENT = (255, 196, 60)
MARGIN = 12
GAP = 8


@dataclass(frozen=True, slots=True)
class Fonts:
    """The viewer's fonts (pygame's built-in font, so nothing is loaded from disk)."""

    title: pygame.font.Font
    large: pygame.font.Font
    medium: pygame.font.Font
    small: pygame.font.Font

    @classmethod
    def load(cls) -> "Fonts":
        """Needs ``pygame.font.init()`` (done by :func:`game.display.open_window`)."""
        return cls(pygame.font.Font(None, 40), pygame.font.Font(None, 34), pygame.font.Font(None, 28),
                   pygame.font.Font(None, 22))


@dataclass(frozen=True, slots=True)
class CameraTile:
    """Where one camera's image sits in the window.

    Attributes:
        rect: the image's screen rectangle.
        image_px: the image's (width, height).
    """

    rect: pygame.Rect
    image_px: tuple[int, int]

    @property
    def scale(self) -> float:
        """Screen pixels per image pixel (horizontally; vertically it differs by under a pixel)."""
        return self.rect.w / self.image_px[0]

    def to_screen(self, uv_px: np.ndarray) -> np.ndarray:
        """(N, 2) image pixel coordinates (OpenCV centres) -> (N, 2) float screen coordinates."""
        uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
        scale = np.array(self.rect.size, dtype=np.float64) / self.image_px
        return np.array(self.rect.topleft, dtype=np.float64) + (uv + 0.5) * scale - 0.5


@dataclass(frozen=True, slots=True)
class Layout:
    """Screen regions of the live view.

    Attributes:
        tiles: one per camera, in camera order.
        help: the key help bar under the camera grid.
        status: the status panel (top of the right column).
        views: the 3D views' region (middle of the right column).
        legend: what the symbols mean (bottom of the right column).
    """

    tiles: tuple[CameraTile, ...]
    help: pygame.Rect
    status: pygame.Rect
    views: pygame.Rect
    legend: pygame.Rect

    @classmethod
    def for_window(cls, window_px: tuple[int, int], image_px: tuple[int, int], n_cameras: int) -> "Layout":
        """Camera grid on the left two thirds, status and 3D views on the right."""
        w, h = window_px
        left_w = round(w * 2 / 3)
        help_h = 52
        grid = pygame.Rect(MARGIN, MARGIN, left_w - 2 * MARGIN, h - 2 * MARGIN - help_h - GAP)
        cols = max(1, math.ceil(math.sqrt(n_cameras)))
        rows = max(1, math.ceil(n_cameras / cols))
        cell_w = (grid.w - GAP * (cols - 1)) / cols
        cell_h = (grid.h - GAP * (rows - 1)) / rows
        # One scale for both axes: the tile width is a multiple of the image's aspect step.
        step = image_px[0] // math.gcd(*image_px)
        scale = min(cell_w / image_px[0], cell_h / image_px[1])
        tw = int(image_px[0] * scale) // step * step
        if tw == 0:  # an aspect ratio in large numbers: the axes' scales differ by under a pixel
            tw = int(image_px[0] * scale)
        th = round(tw * image_px[1] / image_px[0])
        tiles = []
        for c in range(n_cameras):
            r, k = divmod(c, cols)
            x = grid.x + k * (cell_w + GAP) + (cell_w - tw) / 2
            y = grid.y + r * (cell_h + GAP) + (cell_h - th) / 2
            tiles.append(CameraTile(pygame.Rect(round(x), round(y), tw, th), tuple(image_px)))
        help_rect = pygame.Rect(MARGIN, grid.bottom + GAP, grid.w, help_h)
        right_x = left_w
        status = pygame.Rect(right_x, MARGIN, w - right_x - MARGIN, 292)
        legend = pygame.Rect(right_x, help_rect.y, status.w, help_h)
        views = pygame.Rect(right_x, status.bottom + GAP, status.w, legend.y - status.bottom - 2 * GAP)
        return cls(tuple(tiles), help_rect, status, views, legend)


def _text(surface: pygame.Surface, font: pygame.font.Font, text: str, pos: tuple[int, int],
          colour=TEXT, anchor: str = "topleft") -> pygame.Rect:
    img = font.render(text, True, colour)
    rect = img.get_rect(**{anchor: pos})
    surface.blit(img, rect)
    return rect


def _faint(rgb: Sequence[int], amount: float = 0.5) -> tuple[int, int, int]:
    """``rgb`` blended ``amount`` of the way towards the panel colour."""
    return tuple(int(round(c + (p - c) * amount)) for c, p in zip(rgb, PANEL))  # type: ignore[return-value]


def _colour(palette_rgb: np.ndarray, k: int) -> tuple[int, int, int]:
    return tuple(int(v) for v in palette_rgb[k])  # type: ignore[return-value]


def draw_cross(surface: pygame.Surface, centres: Sequence[tuple[int, int]], colours: Sequence[tuple[int, int, int]],
               arm_px: int = 6) -> None:
    """Crosses with a black outline; all outlines first, so no outline covers another cross."""
    for x, y in centres:
        pygame.draw.line(surface, OUTLINE, (x - arm_px - 1, y), (x + arm_px + 1, y), 5)
        pygame.draw.line(surface, OUTLINE, (x, y - arm_px - 1), (x, y + arm_px + 1), 5)
    for (x, y), rgb in zip(centres, colours):
        pygame.draw.line(surface, rgb, (x - arm_px, y), (x + arm_px, y), 3)
        pygame.draw.line(surface, rgb, (x, y - arm_px), (x, y + arm_px), 3)


def blit_bgr(surface: pygame.Surface, image_bgr: np.ndarray, rect: pygame.Rect) -> None:
    """Draw a (H, W, 3) uint8 BGR image scaled into ``rect``."""
    h, w = image_bgr.shape[:2]
    # Area averaging costs 3 ms per 640x480 image; bilinear is as clean down to half size.
    interp = cv2.INTER_AREA if 2 * rect.w < w else cv2.INTER_LINEAR
    scaled = np.ascontiguousarray(cv2.resize(image_bgr, rect.size, interpolation=interp))
    surface.blit(pygame.image.frombuffer(scaled, rect.size, "BGR"), rect.topleft)


def draw_camera_tile(surface: pygame.Surface, tile: CameraTile, camera: Camera, image_bgr: np.ndarray,
                     blobs: Blobs, points: Points3D, palette_rgb: np.ndarray, font: pygame.font.Font) -> None:
    """One camera: its image, its centroids circled, the 3D points reprojected as crosses."""
    blit_bgr(surface, image_bgr, tile.rect)
    clip = surface.get_clip()
    surface.set_clip(tile.rect)
    for (x, y), r_px, k in zip(tile.to_screen(blobs.uv_px), blobs.radius_px, blobs.colour):
        r = int(round(max(r_px * tile.scale + 5, 7)))
        centre = (int(round(x)), int(round(y)))
        pygame.draw.circle(surface, OUTLINE, centre, r + 1, 4)
        pygame.draw.circle(surface, _colour(palette_rgb, int(k)), centre, r, 2)
    if len(points):
        uv = camera.project(points.p_world_m)
        ok = np.isfinite(uv).all(axis=1)
        xy = tile.to_screen(uv[ok])
        centres = [(int(round(x)), int(round(y))) for x, y in xy]
        draw_cross(surface, centres, [_colour(palette_rgb, int(k)) for k in points.colour[ok]])
    caption = f"{camera.name}   {len(blobs)} markers seen"
    img = font.render(caption, True, TEXT)
    back = pygame.Surface((img.get_width() + 12, img.get_height() + 6), pygame.SRCALPHA)
    back.fill((0, 0, 0, 150))
    surface.blit(back, tile.rect.topleft)
    surface.blit(img, (tile.rect.x + 6, tile.rect.y + 3))
    surface.set_clip(clip)
    pygame.draw.rect(surface, PANEL_EDGE, tile.rect.inflate(2, 2), 1)


def _view_rects(region: pygame.Rect, extent_m: np.ndarray, title_h: int) -> tuple[pygame.Rect, pygame.Rect, float]:
    """Front and side view rectangles side by side at one scale (pixels per metre)."""
    size = extent_m[1] - extent_m[0]
    width_front, height, width_side = float(size[0]), float(size[1]), float(size[2])
    scale = min((region.w - GAP) / (width_front + width_side), (region.h - title_h - 28) / height)
    fw, sw, vh = round(width_front * scale), round(width_side * scale), round(height * scale)
    x0 = region.x + (region.w - GAP - fw - sw) // 2
    y0 = region.y + title_h + (region.h - title_h - 28 - vh) // 2
    front = pygame.Rect(x0, y0, fw, vh)
    side = pygame.Rect(front.right + GAP, y0, sw, vh)
    return front, side, scale


def _project_view(p_m: np.ndarray, rect: pygame.Rect, lo_m: np.ndarray, scale: float, axis: int,
                  flip: bool) -> np.ndarray:
    """World points -> screen: horizontal from world ``axis`` (mirrored if ``flip``), vertical from Y."""
    h = p_m[:, axis] - lo_m[axis]
    if flip:
        h = (rect.w / scale) - h
    x = rect.x + h * scale
    y = rect.bottom - (p_m[:, 1] - lo_m[1]) * scale
    return np.stack([x, y], axis=1)


def draw_3d_views(surface: pygame.Surface, region: pygame.Rect, frame: LiveFrame, rig: RigInfo,
                  fonts: Fonts) -> None:
    """Front view (seen by someone facing the patient) and side view (from the patient's right).

    Measured points are filled dots; the true markers are faint rings joined by faint lines.
    """
    title_h = 30
    lo = frame.extent_m[0]
    front, side, scale = _view_rects(region, frame.extent_m, title_h)
    # Facing the patient (who faces -Z), the patient's right (+X) is on the viewer's left; from the
    # patient's right side the patient faces to the screen's right (-Z).
    views = ((front, 0, True, "Front", ("R", "L")), (side, 2, True, "Side", ("back", "front")))
    for rect, axis, flip, title, (left_label, right_label) in views:
        pygame.draw.rect(surface, PANEL, rect)
        step_px = 0.1 * scale
        for k in range(1, int(rect.w / step_px) + 1):
            x = rect.x + k * step_px
            pygame.draw.line(surface, GRID, (x, rect.y), (x, rect.bottom - 1))
        for k in range(1, int(rect.h / step_px) + 1):
            y = rect.bottom - k * step_px
            pygame.draw.line(surface, GRID, (rect.x, y), (rect.right - 1, y))
        pygame.draw.rect(surface, PANEL_EDGE, rect, 1)
        _text(surface, fonts.medium, title, (rect.centerx, rect.y - 4), anchor="midbottom")
        _text(surface, fonts.small, left_label, (rect.x + 5, rect.y + 5), TEXT_DIM)
        _text(surface, fonts.small, right_label, (rect.right - 5, rect.y + 5), TEXT_DIM, anchor="topright")
        clip = surface.get_clip()
        surface.set_clip(rect)
        truth = _project_view(frame.truth_m, rect, lo, scale, axis, flip)
        for a, b in rig.links:
            pygame.draw.line(surface, (88, 93, 102), truth[a], truth[b], 2)
        for (x, y), k in zip(truth, rig.marker_colour):
            pygame.draw.circle(surface, _faint(_colour(rig.palette_rgb, int(k)), 0.45), (x, y), 9, 2)
        if len(frame.points):
            pts = _project_view(frame.points.p_world_m, rect, lo, scale, axis, flip)
            for (x, y), k in zip(pts, frame.points.colour):
                pygame.draw.circle(surface, OUTLINE, (x, y), 6)
                pygame.draw.circle(surface, _colour(rig.palette_rgb, int(k)), (x, y), 5)
        surface.set_clip(clip)
    bar = round(0.1 * scale)
    y = front.bottom + 14
    pygame.draw.line(surface, TEXT_DIM, (front.x, y), (front.x + bar, y), 3)
    _text(surface, fonts.small, "10 cm (one grid square)", (front.x + bar + 8, y), TEXT_DIM, anchor="midleft")


def _humanize(name: str) -> str:
    text = name.replace("_", " ").strip()
    return text[:1].upper() + text[1:]


def _fps_text(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value:.0f}" if value >= 10 else f"{value:.1f}"


def draw_status(surface: pygame.Surface, rect: pygame.Rect, frame: LiveFrame, status: Status,
                n_markers: int, fonts: Fonts) -> None:
    """Motion and time, points measured, rates."""
    pygame.draw.rect(surface, PANEL, rect, border_radius=8)
    x, y = rect.x + 16, rect.y + 12
    _text(surface, fonts.small, "SIMULATED PATIENT, MEASURED LIVE", (x, y), TEXT_DIM)
    y += 24
    _text(surface, fonts.title, _humanize(frame.motion), (x, y))
    if status.paused:
        _text(surface, fonts.medium, "PAUSED", (rect.right - 16, rect.y + 10), ACCENT, anchor="topright")
    y += 40
    # Time within the motion, as a bar.
    bar = pygame.Rect(x, y + 6, rect.w - 32 - 130, 12)
    pygame.draw.rect(surface, GRID, bar, border_radius=6)
    done = bar.copy()
    done.w = max(6, round(bar.w * (frame.time_s / frame.duration_s if frame.duration_s > 0 else 0.0)))
    pygame.draw.rect(surface, ACCENT, done, border_radius=6)
    _text(surface, fonts.medium, f"{frame.time_s:4.1f} / {frame.duration_s:.1f} s", (rect.right - 16, y),
          anchor="topright")
    y += 36
    matched = frame.n_matched
    _text(surface, fonts.large, f"{matched} of {n_markers} markers measured", (x, y))
    y += 34
    err = frame.rms_error_mm
    detail = f"error vs truth {err:.1f} mm RMS" if math.isfinite(err) else "no point near a true marker"
    strays = len(frame.points) - matched
    if strays:
        detail += f", {strays} stray point{'s' if strays > 1 else ''}"
    _text(surface, fonts.medium, detail, (x, y), TEXT_DIM)
    y += 34
    rows = (("Cameras", f"{status.camera_fps:g} frame sets/s"),
            ("Simulation", f"{_fps_text(status.simulation_fps)} frame sets/s"),
            ("Measurement", f"{_fps_text(status.measurement_fps)} frame sets/s"),
            ("Shown", f"{_fps_text(status.shown_fps)} frames/s"))
    for label, value in rows:
        _text(surface, fonts.medium, label, (x, y))
        _text(surface, fonts.medium, value, (rect.right - 16, y), anchor="topright")
        y += 26


def draw_help(surface: pygame.Surface, rect: pygame.Rect, fonts: Fonts) -> None:
    """The keys."""
    pygame.draw.rect(surface, PANEL, rect, border_radius=8)
    keys = (("Space", "pause"), ("Right arrow", "next motion"), ("R", "restart"), ("Esc or Q", "quit"))
    labels = [(fonts.medium.render(k, True, ACCENT), fonts.medium.render(w, True, TEXT)) for k, w in keys]
    widths = [a.get_width() + 8 + b.get_width() for a, b in labels]
    spacing = (rect.w - 32 - sum(widths)) / (len(keys) - 1)
    x = rect.x + 16.0
    for (key_img, what_img), width in zip(labels, widths):
        surface.blit(key_img, key_img.get_rect(midleft=(round(x), rect.centery)))
        surface.blit(what_img, what_img.get_rect(midleft=(round(x) + key_img.get_width() + 8, rect.centery)))
        x += width + spacing


def draw_legend(surface: pygame.Surface, rect: pygame.Rect, fonts: Fonts) -> None:
    """What the circles, crosses, dots and rings mean."""
    pygame.draw.rect(surface, PANEL, rect, border_radius=8)
    x0, x1 = rect.x + 22, rect.x + rect.w // 2 - 10
    y0, y1 = rect.y + rect.h // 4 + 2, rect.y + 3 * rect.h // 4 - 2
    pygame.draw.circle(surface, OUTLINE, (x0, y0), 9, 4)
    pygame.draw.circle(surface, TEXT, (x0, y0), 8, 2)
    _text(surface, fonts.small, "marker found", (x0 + 16, y0), TEXT_DIM, anchor="midleft")
    draw_cross(surface, [(x1, y0)], [TEXT])
    _text(surface, fonts.small, "3D point, reprojected", (x1 + 16, y0), TEXT_DIM, anchor="midleft")
    pygame.draw.circle(surface, OUTLINE, (x0, y1), 6)
    pygame.draw.circle(surface, TEXT, (x0, y1), 5)
    _text(surface, fonts.small, "measured 3D point", (x0 + 16, y1), TEXT_DIM, anchor="midleft")
    pygame.draw.circle(surface, _faint(TEXT, 0.45), (x1, y1), 9, 2)
    _text(surface, fonts.small, "true marker", (x1 + 16, y1), TEXT_DIM, anchor="midleft")


def draw_live_view(surface: pygame.Surface, frame: LiveFrame, rig: RigInfo, status: Status, fonts: Fonts,
                   layout: Layout | None = None) -> Layout:
    """Draw one frame of the live view onto ``surface`` (any size; laid out for 1280x720).

    Args:
        surface: where to draw (the window, or any Surface in tests).
        frame: images, centroids, points and truth of one frame set.
        rig: cameras and colours.
        status: rates and pause state.
        fonts: :meth:`Fonts.load`.
        layout: screen regions (computed from the surface when None).

    Returns:
        The layout used (tests map image pixels to screen pixels with it).
    """
    if layout is None:
        h, w = frame.images[0].shape[:2]
        layout = Layout.for_window(surface.get_size(), (w, h), len(rig.cameras))
    surface.fill(BACKGROUND)
    for tile, cam, img, blobs in zip(layout.tiles, rig.cameras, frame.images, frame.blobs):
        draw_camera_tile(surface, tile, cam, img, blobs, frame.points, rig.palette_rgb, fonts.small)
    draw_help(surface, layout.help, fonts)
    draw_status(surface, layout.status, frame, status, len(rig.marker_colour), fonts)
    draw_3d_views(surface, layout.views, frame, rig, fonts)
    draw_legend(surface, layout.legend, fonts)
    return layout


def draw_message(surface: pygame.Surface, text: str, fonts: Fonts) -> None:
    """A single centred message (while the studio starts)."""
    surface.fill(BACKGROUND)
    _text(surface, fonts.large, text, surface.get_rect().center, anchor="center")


# ============================================================================ the loop
@dataclass(frozen=True, slots=True)
class PlaySummary:
    """What a run did: frames shown, points per frame, speed."""

    frames: int
    mean_points: float
    n_markers: int
    wall_s: float
    render_ms: float
    measure_ms: float
    draw_ms: float
    screenshot: Path | None

    @property
    def frames_per_s(self) -> float:
        return self.frames / self.wall_s if self.wall_s > 0 else math.nan

    def line(self) -> str:
        shot = f"; screenshot {self.screenshot}" if self.screenshot else ""
        return (
            f"played {self.frames} frame sets, {self.mean_points:.1f} points per frame for {self.n_markers} markers, "
            f"{self.frames_per_s:.1f} frame sets/s measured and drawn (per frame: simulation {self.render_ms:.0f} ms, "
            f"measurement {self.measure_ms:.0f} ms, drawing {self.draw_ms:.0f} ms){shot}"
        )


def save_screenshot(surface: pygame.Surface, path: Path) -> None:
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        pygame.image.save(surface, str(path))
    except (OSError, pygame.error) as exc:
        raise RehabError(f"cannot write the screenshot {path}: {exc}; choose a writable .png path") from None


def run_viewer(options: PlayOptions, *, clock: Clock = time.perf_counter,
               sleep: Callable[[float], None] = time.sleep) -> PlaySummary:
    """Open the window (or the offscreen surface) and run the live view until quit or ``seconds``.

    Raises:
        game.display.NoDisplayError: no display and not headless.
        RehabError: unknown motion or rig, unwritable screenshot.
    """
    surface = open_window(WINDOW_SIZE, "rehab play: the simulated patient, measured live", headless=options.headless)
    try:
        fonts = Fonts.load()
        if not options.headless:
            draw_message(surface, "Starting the simulated studio...", fonts)
            pygame.display.flip()
        with LiveSimulation.create(options, clock) as sim:
            summary = _loop(surface, fonts, sim, options, clock, sleep)
        if options.screenshot is not None:
            save_screenshot(surface, options.screenshot)
        return summary
    finally:
        close_window()


def _loop(surface: pygame.Surface, fonts: Fonts, sim: LiveSimulation, options: PlayOptions, clock: Clock,
          sleep: Callable[[float], None]) -> PlaySummary:
    playhead = Playhead(options.fps, clock, realtime=not options.headless)
    limit = frame_count(options.seconds, options.fps) if options.seconds is not None else None
    render, measure, draw, period = RateMeter(), RateMeter(), RateMeter(), RateMeter()
    layout = None
    frame: LiveFrame | None = None
    shown = points = 0
    running = True
    start_s = last_s = clock()
    while True:
        for action in actions_from_events(pygame.event.get()):
            if action is Action.QUIT:
                running = False
            elif action is Action.TOGGLE_PAUSE:
                playhead.set_paused(not playhead.paused)
            elif action is Action.NEXT_MOTION:
                sim.next_motion()
                # A captured motion takes a moment to solve for the body; say so meanwhile.
                draw_message(surface, f"Loading {_humanize(sim.motion_name)}...", fonts)
                pygame.display.flip()
                playhead.restart()
                frame = None
            elif action is Action.RESTART:
                playhead.restart()
                frame = None
        if not running:
            break
        if frame is None or not playhead.paused:
            frame = sim.frame(playhead.index)
            render.add(frame.render_s)
            measure.add(frame.measure_s)
            shown += 1
            points += len(frame.points)
        t0 = clock()
        status = Status(playhead.paused, render.per_second, measure.per_second, period.per_second, options.fps)
        layout = draw_live_view(surface, frame, sim.rig, status, fonts, layout)
        pygame.display.flip()
        t1 = clock()
        draw.add(t1 - t0)
        if not playhead.paused:
            period.add(t1 - last_s)
        last_s = t1
        if playhead.paused:
            sleep(PAUSED_POLL_S)
            continue
        if limit is not None and playhead.index + 1 >= limit:
            break
        skipped = playhead.advance()
        if skipped:
            log.debug("skipped %d frames to keep up", skipped)
        sleep(playhead.wait_s())
    wall_s = clock() - start_s
    return PlaySummary(shown, points / max(shown, 1), len(sim.rig.marker_colour), wall_s, render.average_ms,
                       measure.average_ms, draw.average_ms, options.screenshot)
