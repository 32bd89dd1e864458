"""The calibration scene: each camera's lens and focal length from a checkerboard, with live feedback.

A helper moves a printed checkerboard in front of one camera at a time. The scene shows that
camera's image with the corners found drawn over it (green; a red line when the board is not
found), a coverage map (the cells of the picture where captured views had corners, tinted), the
number of views captured and how many are needed, and a hint in plain words saying where to
move the board next (the empty regions, :mod:`calibration.intrinsics`).

Keys (the shared key map, :mod:`game.input`): Space or Enter captures the current view (only
when the board is found), A switches auto-capture on or off (a view is captured when the board
is found and has moved since the last capture, and the camera is calibrated again after each new
view once there are enough), C calibrates the camera and shows the result
(RMS reprojection error, focal length, and for the simulated feed the error against the true
focal length), Tab goes to the next camera, S saves the calibrated cameras (two or more) as a
TOML file, Esc goes back. The buttons at the bottom do the same with the mouse.

Images come from a :class:`BoardFeed`: :class:`SimBoardFeed` is the simulated one (a board moved
by a simulated helper in front of one camera of the simulated studio, with the true camera known),
:class:`CameraBoardFeed` a real camera (or a video file) through OpenCV (:func:`camera_feeds`).
The board may be a checkerboard or a ChArUco board (whose corners are found, and drawn, even when
part of it is out of the picture).

After the lenses (:mod:`calibration.guided`): where the cameras stand, from the board held where
two cameras see it or (W) from the wand waved through the volume (cameras that take their
pictures at the same instant only), the world frame from the board on the seat, and the report
in millimetres, which goes on measuring the wand waved again with the finished calibration.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, Sequence

import cv2
import numpy as np

from calibration.board import Checkerboard, Detection, detect_board
from calibration.camera import Camera
from calibration.errors import RehabError
from calibration.files import load_calibration, save_calibration_toml, write_lens_information
from calibration.intrinsics import (COVERAGE_GRID, IntrinsicsResult, calibrate_intrinsics, coverage_of,
                                    steady_lens_information)
from calibration.guided import (GOOD_LENGTH_MM, MIN_WAND_FRAMES, RigViews, WAND_FRAMES, WandViews,
                                quality_report, solve_rig, solve_rig_wand, wand_check)
from calibration.view_selection import coverage_hint
from game.app import BaseScene, Frame
from game.db import default_db_path
from game.gfx import theme
from game.input import Action, InputEvent, Pointer, PointerKind, Press
from game.scenes.calibrate_rig import (CameraRigFeed, SimRigFeed, board_pose_between, draw_wand, floor_board_picture,
                                      link_diagram)
from tracking.colour.table import ColourTable
from tracking.sources.base import SourceError
from tracking.sources.cameras import open_capture

log = logging.getLogger(__name__)

Rect = tuple[float, float, float, float]

#: Views to capture before calibrating (OpenCV needs 4; 8 spread views give a steady focal length).
NEED_VIEWS = 8
#: Auto-capture: the corners must have moved this share of the image diagonal (mean) since the last capture.
AUTO_MIN_MOVE = 0.08
#: How often the feed gives a new image and the board is looked for, per second.
FEED_RATE_HZ = 10.0


class BoardFeed(Protocol):
    """One camera's images for calibration.

    Attributes:
        name: the camera's name (as in the calibration file).
        size_px: (width, height) of its images.
        truth: the true camera when known (a simulation), else None.
    """

    name: str
    size_px: tuple[int, int]
    truth: Camera | None

    def next_frame(self) -> np.ndarray:
        """The next (H, W, 3) BGR uint8 image."""
        ...


class SimBoardFeed:
    """A simulated helper moving the board in front of one simulated camera.

    The board holds still at each pose of :func:`tracking.sim.calibration_material.intrinsics_poses`
    for ``hold`` frames, then is carried to the next one in ``move`` frames; every third move
    first swings half of the board out of the picture (the "board not found" case).

    Args:
        camera: the true camera.
        background: (H, W, 3) BGR image of the room seen by it.
        board: the board.
        n_poses: poses before the round repeats.
        hold, move: frames per still pose and per move.
        seed: random seed (poses and noise).
        noise_sigma: image noise, grey levels.
    """

    def __init__(self, camera: Camera, background: np.ndarray, board: Checkerboard, *, n_poses: int = 12,
                 hold: int = 6, move: int = 4, seed: int = 0, noise_sigma: float = 1.5) -> None:
        # lazy: the simulator only for the demo calibration (tests/test_layout.py)
        from tracking.sim.calibration_material import BoardRaycaster, intrinsics_poses

        self.name = camera.name
        self.size_px = camera.size_px
        self.truth = camera
        self.board = board
        self._rng = np.random.default_rng(seed)
        self._caster = BoardRaycaster(camera, board, supersample=2)
        self._background = background
        self._noise = float(noise_sigma)
        self._path = self._make_path(intrinsics_poses(camera, board, n_poses, self._rng), hold, move)
        self._k = 0
        self._last_pose = None
        self._clean = background

    def _make_path(self, poses, hold: int, move: int) -> list:
        # lazy: the simulator only for the demo calibration (tests/test_layout.py)
        from tracking.sim.calibration_material import BoardPose

        path = []
        bw = (self.board.cols + 1) * self.board.square_m
        for i, pose in enumerate(poses):
            path += [pose] * hold
            nxt = poses[(i + 1) % len(poses)]
            if i % 3 == 2:  # swing out sideways (along the board's own x) first: half of it leaves the picture
                out = BoardPose(pose.R, pose.t_m + pose.R[:, 0] * 0.6 * bw)
                path += [out] * max(move, 2)
                pose = out
            path += [board_pose_between(pose, nxt, (k + 1) / (move + 1)) for k in range(move)]
        return path

    def next_frame(self) -> np.ndarray:
        # lazy: the simulator only for the demo calibration (tests/test_layout.py)
        from tracking.sim.calibration_material import add_noise, board_light

        pose = self._path[self._k % len(self._path)]
        self._k += 1
        if pose is not self._last_pose:   # the board held still: the clean image is drawn once
            self._last_pose = pose
            self._clean = self._caster.draw(self._background, pose, light=board_light(pose))
        return add_noise(self._clean, self._noise, self._rng)

    def true_corners_px(self) -> np.ndarray:
        """(N, 2) true pixel positions of the inner corners in the last image (may lie outside it)."""
        return self._caster.corners_px(self._last_pose)


def sim_feeds(rig: str = "ring4", size_px: tuple[int, int] = (640, 480), board: Checkerboard | None = None,
              *, seed: int = 0, ctx=None, **kwargs) -> list[SimBoardFeed]:
    """One simulated feed per camera of a built-in rig (with the demo lens distortion), over the
    empty studio room rendered once by GL.

    Args:
        ctx: the application's moderngl context to render the room with (its framebuffer and
            state are changed: the screen rebinds its own every frame); None: a standalone one.
        kwargs: passed to :class:`SimBoardFeed`.
    """
    # lazy: the simulator only for the demo calibration (tests/test_layout.py)
    from tracking.sim.calibration_material import DEFAULT_BOARD
    # lazy: the simulator only for the demo calibration (tests/test_layout.py)
    from tracking.sim.renderer import DEMO_LENS, StudioRenderer
    from tracking.sim.rigs import load_rig  # lazy: the simulator only for the demo calibration (tests/test_layout.py)
    # lazy: the simulator only for the demo calibration (tests/test_layout.py)
    from tracking.sim.scene import SceneFrame

    board = board or DEFAULT_BOARD
    cams = [Camera(c.name, c.size_px, c.K, DEMO_LENS, c.rvec, c.t_m) for c in load_rig(rig, size_px)]
    with StudioRenderer(cams, ctx=ctx) as renderer:
        backgrounds = list(renderer.render(SceneFrame.empty(), with_visibility=False).images)
    return [SimBoardFeed(c, bg, board, seed=seed + i, **kwargs) for i, (c, bg) in enumerate(zip(cams, backgrounds))]


class CameraBoardFeed:
    """A real camera's images for calibration, from an OpenCV capture.

    The first frame is read at once: it gives the image size, and a camera that delivers none
    is refused here rather than on the screen.

    Args:
        name: the camera's name (``cam1``, ...).
        capture: an opened capture with ``cv2.VideoCapture``'s ``read()`` and ``release()``.
        max_failed_reads: consecutive failed reads after which :meth:`next_frame` raises.
    Raises:
        SourceError: the capture delivers no first frame.
    """

    def __init__(self, name: str, capture, *, max_failed_reads: int = 25) -> None:
        self.name = name
        self.truth = None
        self._capture = capture
        self._max_failed = int(max_failed_reads)
        for _ in range(self._max_failed):
            ok, image = capture.read()
            if ok and image is not None:
                break
        else:
            capture.release()
            raise SourceError(f"{name}: the camera delivered no image: check that it is plugged in and not used elsewhere")
        self._last = self._colour(image)
        self.size_px = (self._last.shape[1], self._last.shape[0])
        self._given_first = False

    @staticmethod
    def _colour(image: np.ndarray) -> np.ndarray:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image

    def next_frame(self) -> np.ndarray:
        """The camera's next image (the first one read at opening comes first).

        Raises:
            SourceError: the camera stopped delivering (``max_failed_reads`` reads in a row failed).
        """
        if not self._given_first:
            self._given_first = True
            return self._last
        for _ in range(self._max_failed):
            ok, image = self._capture.read()
            if ok and image is not None:
                image = self._colour(image)
                if (image.shape[1], image.shape[0]) != self.size_px:
                    raise SourceError(f"{self.name}: the image size changed from {self.size_px[0]}x{self.size_px[1]} "
                                      f"to {image.shape[1]}x{image.shape[0]}: keep one camera setting")
                self._last = image
                return image
        raise SourceError(f"{self.name}: the camera stopped delivering images")

    def close(self) -> None:
        self._capture.release()


def camera_feeds(devices: Sequence[str], *, size_px: tuple[int, int] | None = None) -> list[CameraBoardFeed]:
    """One :class:`CameraBoardFeed` per device (index like ``"0"``, URL or video file), named cam1, cam2, ...

    Raises:
        SourceError: a device cannot be opened or delivers nothing (the ones opened are released).
    """

    feeds: list[CameraBoardFeed] = []
    try:
        for k, device in enumerate(devices):
            cap = open_capture(str(device), size_px, None)
            if not cap.isOpened():
                cap.release()
                raise SourceError(f"camera {device}: cannot be opened (check the index, URL or path)")
            feeds.append(CameraBoardFeed(f"cam{k + 1}", cap))
    except BaseException:
        for feed in feeds:
            feed.close()
        raise
    return feeds


def lenses_for_feeds(path: Path, feeds: Sequence[BoardFeed]) -> list[Camera]:
    """The lens data of the calibration file ``path`` for each feed, by camera name, at the feed's
    image size (scaled when only the resolution differs, refused when the shape does).

    Raises:
        RehabError: a feed's camera is not in the file, or its pictures have another shape.
    """
    cameras = load_calibration(path)
    source = str(path)
    by_name = {c.name: c for c in cameras}
    out = []
    for feed in feeds:
        cam = by_name.get(feed.name)
        if cam is None:
            raise RehabError(f"{source}: no lens data for {feed.name} (it has {', '.join(by_name) or 'no camera'}); "
                             "calibrate its lens first or give the file of these cameras")
        (w, h), (fw, fh) = cam.size_px, feed.size_px
        if abs(w * fh - h * fw) > max(w, h):   # another aspect ratio: another field of view, not another resolution
            raise RehabError(f"{source}: {feed.name}'s lens data are for {w}x{h} pictures, the camera gives {fw}x{fh}: "
                             "calibrate its lens again at this size")
        out.append(cam if (w, h) == (fw, fh) else cam.with_size((fw, fh)))
    return out


def default_calibration_path() -> Path:
    """``calibration.toml`` in the user's data directory (beside the database)."""
    return default_db_path().parent / "calibration.toml"


@dataclass
class CameraProgress:
    """What was captured and computed for one camera."""

    views: list[Detection]
    result: IntrinsicsResult | None = None


def draw_feedback(image: np.ndarray, detection: Detection | None, views: Sequence[Detection],
                  board, *, grid: bool = True) -> np.ndarray:
    """The camera image with the coverage cells tinted and the corners found drawn (a new image)."""
    out = image.copy()
    h, w = out.shape[:2]
    gx, gy = COVERAGE_GRID
    if views:
        _, hit = coverage_of(views, (w, h))
        tint = np.zeros_like(out)
        for j, i in zip(*np.nonzero(hit)):
            x0, x1 = round(i * w / gx), round((i + 1) * w / gx)
            y0, y1 = round(j * h / gy), round((j + 1) * h / gy)
            tint[y0:y1, x0:x1] = (190, 200, 94)  # teal (BGR of theme.ACCENT)
        covered = tint.any(axis=2)
        out[covered] = (0.72 * out[covered] + 0.28 * tint[covered]).astype(np.uint8)
    for i in range(1, gx if grid else 0):
        cv2.line(out, (round(i * w / gx), 0), (round(i * w / gx), h - 1), (80, 80, 80), 1)
    for j in range(1, gy if grid else 0):
        cv2.line(out, (0, round(j * h / gy)), (w - 1, round(j * h / gy)), (80, 80, 80), 1)
    if detection is not None:
        thick = max(1, round(w / 320))
        ids = np.arange(board.n_corners) if detection.ids is None else detection.ids
        for r in range(board.rows):  # the rows of corners found, as lines (a partial ChArUco view: its pieces)
            in_row = (ids // board.cols) == r
            if in_row.sum() >= 2:
                cv2.polylines(out, [np.rint(detection.uv_px[in_row]).astype(np.int32)], False, (120, 220, 90), thick,
                              cv2.LINE_AA)
        for p in detection.uv_px:
            cv2.circle(out, (round(p[0]), round(p[1])), 2 * thick + 1, (90, 230, 80), -1, cv2.LINE_AA)
    return out


BUTTONS = (("Capture", "Space"), ("Auto", "A"), ("Calibrate", "C"), ("Next camera", "Tab"), ("Save lens", "S"),
           ("Next step", "D"), ("Back", "Esc"))
STAGE_BUTTONS = {
    "lens": BUTTONS,
    "positions": (("Capture", "Space"), ("Auto", "A"), ("Use the wand", "W"), ("Next step", "D"), ("Back", "Esc")),
    "wand": (("Use the board", "W"), ("Next step", "D"), ("Back", "Esc")),
    "floor": (("Capture", "Space"), ("Auto", "A"), ("Redo positions", "Tab"), ("Back", "Esc")),
    "report": (("Redo positions", "Tab"), ("Back", "Esc")),
}
STAGE_TITLES = {"lens": "Step 1 of 4, lenses", "positions": "Step 2 of 4, where the cameras stand",
                "wand": "Step 2 of 4, where the cameras stand (wand)",
                "floor": "Step 3 of 4, the floor", "report": "Step 4 of 4, how well it measures"}
_KEYS = {Action.SELECT: "Space", Action.LEFT: "A", Action.MONITOR: "C", Action.SWITCH_ARM: "Tab", Action.DOWN: "S",
         Action.RIGHT: "D", Action.BACK: "Esc", Action.UP: "W"}
#: A board counts as held still when no corner moved more than this between two images, pixels.
STILL_PX = 2.0
#: Where the floor board's centre lies when the screen cannot know better: centred over the origin on a 45 cm seat.
SEAT_BOARD_CENTRE_M = (0.0, 0.45, 0.0)
#: The wand of the screen: ball distance (centres) and colours, as the simulated helper's and docs/CALIBRATION.md's.
WAND_LENGTH_M = 0.5
WAND_BALL_RADIUS_M = 0.02
WAND_COLOURS_RGB255 = ((255, 214, 0), (225, 0, 210))
#: Wand frames the report measures at most.
MAX_CHECK_FRAMES = 200


class CalibrateScene(BaseScene):
    """Intrinsic calibration of each camera with live feedback.

    Args:
        feeds: one :class:`BoardFeed` per camera.
        board: the board being shown (a Checkerboard or a CharucoBoard).
        out_path: where S saves (None: :func:`default_calibration_path`).
        auto: start with auto-capture on.
        need_views: views to capture before calibrating.
        threaded: read the feed and look for the board on a helper thread (the window stays
            smooth); False: in :meth:`update`, one image per ``1 / FEED_RATE_HZ`` of updates (tests).
        lenses: lens data calibrated earlier, one camera per feed (their lens step is done).
        wand_length_m, wand_colours_rgb255: the wand of step 2 and of the report.
    """

    def __init__(self, feeds: Sequence[BoardFeed], board, *, out_path: Path | None = None,
                 auto: bool = False, need_views: int = NEED_VIEWS, threaded: bool = True, rig_feed=None,
                 board_centre_m=SEAT_BOARD_CENTRE_M, lenses: Sequence[Camera] | None = None,
                 wand_length_m: float = WAND_LENGTH_M, wand_colours_rgb255=WAND_COLOURS_RGB255) -> None:
        if not feeds:
            raise RehabError("no camera to calibrate: connect a camera or use the simulated studio")
        self.feeds = list(feeds)
        self.board = board
        self.out_path = out_path
        self.auto = auto
        self.need_views = int(need_views)
        self.index = 0
        self.progress = [CameraProgress([]) for _ in self.feeds]
        self.image: np.ndarray | None = None
        self.detection: Detection | None = None
        self.reason = ""
        self.message = ""
        self.message_colour = theme.TEXT_DIM
        self.overlay: np.ndarray | None = None
        self._since = 1.0 / FEED_RATE_HZ   # the first update reads a frame
        self._buttons: list[Rect] = []
        self.saved_path: Path | None = None
        self.image_rect: Rect | None = None   # where the camera image was last drawn, screen pixels
        self.threaded = threaded
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._latest = None
        self._failed = ""
        # the rig steps (positions, floor, report): calibration/guided.py
        self.stage = "lens"
        self.rig_feed = rig_feed
        self.board_centre_m = tuple(float(v) for v in board_centre_m)
        self.rig_views = None
        self.rig_images: list[np.ndarray] | None = None
        self.rig_detections: list[Detection | None] = []
        self._previous: list[Detection | None] = []
        self.rig_still = False
        self.rig_result = None
        self.report = None
        self.lens_path: Path | None = None
        # the wand (step 2 instead of the board, and the report's measure)
        self.method = "board"
        self.wand_length_m = float(wand_length_m)
        self.wand_colours = np.asarray(wand_colours_rgb255, np.uint8).reshape(2, 3)
        self.wand_views = None
        self.wand_uv: np.ndarray | None = None
        self.check_frames: list[np.ndarray] = []
        self._table = None
        self._report_views: dict = {}
        for k, cam in enumerate(lenses or ()):   # lens data calibrated earlier (intrinsics.toml)
            if k < len(self.progress):
                self.progress[k].result = IntrinsicsResult(cam, float("nan"), np.zeros(0), float("nan"), ())

    # ----------------------------------------------------------------- state
    @property
    def feed(self) -> BoardFeed:
        return self.feeds[self.index]

    @property
    def current(self) -> CameraProgress:
        return self.progress[self.index]

    def _say(self, text: str, colour=theme.TEXT_DIM) -> None:
        self.message, self.message_colour = text, colour

    def _grab(self, index: int) -> tuple:
        stage = self.stage
        if stage in ("positions", "floor"):   # every camera at once
            images = self.rig_feed.next_frames()
            return stage, images, [detect_board(img, self.board)[0] for img in images]
        if stage in ("wand", "report"):
            if stage == "report" and (not self.wand_ready() or len(self.check_frames) >= MAX_CHECK_FRAMES):
                return ("report",)
            images = self.rig_feed.next_frames()
            return stage, images, self._find_wand(images)
        
        image = self.feeds[index].next_frame()
        detection, reason = detect_board(image, self.board)
        return index, image, detection, reason

    def lens_hint(self) -> str:
        """The lens step's next instruction, in plain words: how to keep a board that is found,
        then where to move it (:func:`coverage_hint`)."""
        if not self.current.views and self.detection is not None and not self.auto:
            return "Press Space to capture this view, or A to capture as you move the board"
        return coverage_hint(self.current.views, self.feed.size_px)

    def next_frame(self) -> None:
        """Read the feed's next image and look for the board in it (on this thread)."""
        self._show(*self._grab(self.index))

    def _worker(self) -> None:
        """The feed read and the board looked for off the drawing thread, ``FEED_RATE_HZ`` times a second."""
        period = 1.0 / FEED_RATE_HZ
        while not self._stop.is_set():
            t0 = time.perf_counter()
            try:
                got = self._grab(self.index)
            except Exception as exc:   # a feed that fails: said on the screen, the thread ends
                log.exception("calibration feed failed")
                self._failed = f"The camera stopped: {exc}"
                return
            with self._lock:
                self._latest = got
            self._stop.wait(max(0.0, period - (time.perf_counter() - t0)))

    def _show(self, *got) -> None:
        if isinstance(got[0], str):
            if got[0] == self.stage and got[0] in ("wand", "report") and len(got) == 3:
                self._show_wand(*got[1:])
            elif got[0] == self.stage and got[0] in ("positions", "floor"):
                self._show_rig(*got[1:])
            return
        index, image, detection, reason = got
        if index != self.index or self.stage != "lens":   # grabbed just before a switch
            return
        self.image, self.detection, self.reason = image, detection, reason
        if self.auto and self.detection is not None and self._moved_enough():
            self.capture()
            if len(self.current.views) >= self.need_views:
                self.calibrate()   # auto: the result follows every new view once there are enough
        self.overlay = None

    def _moved_enough(self) -> bool:
        views = self.current.views
        if not views:
            return True
        w, h = self.feed.size_px
        move = float(np.mean(np.linalg.norm(self.detection.uv_px - views[-1].uv_px, axis=1)))
        return move > AUTO_MIN_MOVE * float(np.hypot(w, h))

    def capture(self) -> bool:
        """Keep the current view if the board is found in it. Returns whether it was kept."""
        if self.detection is None:
            self._say("Board not found: show the whole board to capture", theme.FAILURE)
            return False
        self.current.views.append(self.detection)
        self.current.result = None
        self._say(f"View {len(self.current.views)} captured", theme.ACCENT)
        self.overlay = None
        return True

    def calibrate(self) -> IntrinsicsResult | None:
        """Calibrate the current camera from its captured views (shown large)."""
        views = self.current.views
        if len(views) < self.need_views:
            self._say(f"Capture {self.need_views - len(views)} more views first", theme.ATTENTION)
            return None
        try:
            self.current.result = calibrate_intrinsics(self.feed.name, views, self.board)
        except RehabError as exc:
            self._say(str(exc), theme.FAILURE)
            return None
        self._say(f"{self.feed.name} calibrated", theme.ACCENT)
        return self.current.result

    def lens_data_path(self) -> Path:
        """Where the lens data go: ``intrinsics.toml`` beside the calibration file, never the
        calibration file itself (tracking with cameras all at the origin would be silently wrong)."""
        return Path(self.out_path or default_calibration_path()).with_name("intrinsics.toml")

    def save(self) -> Path | None:
        """Write the lens data of every calibrated camera (2 or more) to :meth:`lens_data_path`;
        returns the path written. The positions and the floor follow (Next step)."""
        done = [p.result for p in self.progress if p.result is not None]
        if len(done) < 2:
            self._say(f"Calibrate at least 2 cameras before saving ({len(done)} done; Tab: next camera)",
                      theme.ATTENTION)
            return None
        path = self.lens_data_path()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            rms = [r.rms_px for r in done if np.isfinite(r.rms_px)]   # lens data given (``lenses``) have none
            save_calibration_toml(path, [r.camera for r in done], error=float(np.mean(rms)) if rms else 0.0)
            write_lens_information(path, {r.camera.name: r.information for r in done if r.information is not None},
                                   views={r.camera.name: len(r.per_view_rms_px) for r in done if r.information is not None})
        except (RehabError, OSError) as exc:
            self._say(f"Not saved: {exc}", theme.FAILURE)
            return None
        self.lens_path = path
        todo = [f.name for f, p in zip(self.feeds, self.progress) if p.result is None]
        more = f" ({', '.join(todo)} still to do: Tab)" if todo else ""
        self._say(f"Saved the lens data of {len(done)} cameras{more} to {path}. Still missing: where the cameras "
                  "stand and the floor: Next step (D)", theme.ACCENT)
        return path

    def next_camera(self) -> None:
        self.index = (self.index + 1) % len(self.feeds)
        self._since = 1.0 / FEED_RATE_HZ
        self._say(f"Now {self.feed.name}")
        self.image = None
        self.detection = None

    # ----------------------------------------------------------------- scene
    @property
    def buttons(self) -> tuple[tuple[str, str], ...]:
        return STAGE_BUTTONS[self.stage]

    def handle(self, event: InputEvent) -> None:
        if isinstance(event, Press) and event.down:
            key = _KEYS.get(event.action)
            for label, k in self.buttons:
                if k == key:
                    self.do(label)
                    break
        elif isinstance(event, Pointer) and event.kind == PointerKind.PRESS and event.button == 1 and self._buttons:
            w, h = self.app.screen.size_px
            for (label, _), (x, y, bw, bh) in zip(self.buttons, self._buttons):
                if x <= event.x * w < x + bw and y <= event.y * h < y + bh:
                    self.do(label)

    def do(self, what: str) -> None:
        """Run a button's action by its label."""
        if what == "Capture":
            {"lens": self.capture, "positions": self.capture_view, "floor": self.capture_floor}[self.stage]()
        elif what == "Auto":
            self.auto = not self.auto
            self._say(f"Auto-capture {'on' if self.auto else 'off'}")
        elif what == "Calibrate":
            self.calibrate()
        elif what == "Next camera":
            self.next_camera()
        elif what == "Save lens":
            self.save()
        elif what == "Next step":
            self.next_step()
        elif what == "Redo positions":
            self.to_positions(keep=False)
        elif what == "Use the wand":
            self.to_wand()
        elif what == "Use the board":
            self.to_positions(keep=True)
        elif what == "Back":
            self.app.pop()

    # ----------------------------------------------------------------- the rig steps
    def next_step(self) -> None:
        """Lenses -> positions (every camera needs its lens data) -> floor (every camera linked)."""
        if self.stage == "lens":
            todo = [f.name for f, p in zip(self.feeds, self.progress) if p.result is None]
            if todo:
                self._say(f"Calibrate the lens of {', '.join(todo)} first (Tab: next camera)", theme.ATTENTION)
                return
            if self.save() is not None:
                self.to_positions(keep=False)
        elif self.stage in ("positions", "wand"):
            views = self.rig_views if self.stage == "positions" else self.wand_views
            if not (views.linked() if self.stage == "positions" else views.ready()):
                self._say(views.advice(), theme.ATTENTION)
                return
            self.method = "board" if self.stage == "positions" else "wand"
            self.stage = "floor"
            self.rig_feed.lay_on_seat()
            self._previous = []
            self._say("Lay the board face up on the seat as in the picture", theme.TEXT)

    def to_positions(self, *, keep: bool) -> None:
        if self.rig_feed is None:
            sim = all(isinstance(f, SimBoardFeed) for f in self.feeds)
            ctx = None if self.threaded or self.app is None else self.app.screen.ctx   # GL on the thread that reads
            self.rig_feed = SimRigFeed.from_feeds(self.feeds, self.board, ctx=ctx) if sim else CameraRigFeed(self.feeds)
        if not keep or self.rig_views is None:
            self.rig_views = RigViews([f.name for f in self.feeds])
        self.rig_feed.hold_up()
        self.stage = "positions"
        self.rig_images, self.rig_detections, self._previous = None, [], []
        self.rig_result = self.report = None
        self.wand_views, self.check_frames = None, []
        self._since = 1.0 / FEED_RATE_HZ

    def wand_ready(self) -> bool:
        """Whether the cameras take their pictures at the same instant (a moving wand needs it)."""
        return bool(getattr(self.rig_feed, "synchronised", False))

    def to_wand(self) -> None:
        """Step 2 with the wand instead of the board (cameras taking pictures at the same instant only)."""
        if not self.wand_ready():
            self._say("The wand needs cameras that take their pictures at the same instant; these are read one "
                      "after the other: use the board", theme.ATTENTION)
            return
        self.wand_views = WandViews([f.name for f in self.feeds])
        self.rig_feed.wave_wand()
        self.stage = "wand"
        self.rig_images, self.wand_uv = None, None
        self._say("Wave the wand slowly through the whole volume, turning it in all directions", theme.TEXT)

    def _find_wand(self, images: list[np.ndarray]) -> np.ndarray:
        """(C, 2, 2) the two balls' centroids in every camera's image, NaN where not seen once exactly."""
        # lazy: the blob finder (scipy, 0.2 s) only at the wand step; keeps the game's start-up short
        from tracking.drivers.wand_capture import wand_centroids_in_images

        if self._table is None:
            self._table = ColourTable.build(self.wand_colours)
        cams = [p.result.camera for p in self.progress]
        return wand_centroids_in_images(images, cams, self._table, WAND_BALL_RADIUS_M)

    def _show_wand(self, images: list[np.ndarray], uv: np.ndarray) -> None:
        """A wand frame: kept for the solve (step 2) or measured by the finished calibration (report)."""
        self.rig_images, self.wand_uv = images, uv
        if self.stage == "wand":
            if self.wand_views.add(uv):
                self._say(self.wand_views.advice(), theme.ACCENT if self.wand_views.ready() else theme.TEXT)
            return
        if int(np.all(np.isfinite(uv), axis=(1, 2)).sum()) >= 2:
            self.check_frames.append(uv)
            if len(self.check_frames) % 5 == 0 or len(self.check_frames) == MAX_CHECK_FRAMES:
                self._update_report()

    def _update_report(self) -> None:
        res = self.rig_result
        check = None
        if self.wand_ready():
            uv = np.stack(self.check_frames, axis=1) if self.check_frames else np.full((len(self.feeds), 0, 2, 2), np.nan)
            check = wand_check(res.cameras, uv, self.wand_length_m)
        self.report = quality_report(res.cameras, self.board, self._report_views, res.rms_px, wand=check,
                                     wand_length_m=self.wand_length_m)

    def _show_rig(self, images: list[np.ndarray], detections: list[Detection | None]) -> None:
        prev = self._previous
        moved = [float(np.max(np.linalg.norm(d.uv_px - p.uv_px, axis=1)))
                 for d, p in zip(detections, prev) if d is not None and p is not None and d.uv_px.shape == p.uv_px.shape]
        found = sum(d is not None for d in detections)
        self.rig_still = bool(prev) and found > 0 and len(moved) == found and max(moved) < STILL_PX
        self._previous = detections
        self.rig_images, self.rig_detections = images, detections
        if self.auto and self.rig_still:
            if self.stage == "positions" and found >= 2 and self._new_view():
                self.capture_view()
            elif self.stage == "floor":
                self.capture_floor()

    def _new_view(self) -> bool:
        if not self.rig_views.views:
            return True
        last = list(self.rig_views.views.values())[-1]
        if [d is None for d in last] != [d is None for d in self.rig_detections]:
            return True
        w, h = self.feeds[0].size_px
        return any(float(np.mean(np.linalg.norm(d.uv_px - p.uv_px, axis=1))) > AUTO_MIN_MOVE * float(np.hypot(w, h))
                   for d, p in zip(self.rig_detections, last) if d is not None and d.uv_px.shape == p.uv_px.shape)

    def capture_view(self) -> bool:
        """Keep the board view of the cameras that see it now (two or more)."""
        if self.rig_images is None or self.rig_views.add(self.rig_detections) is None:
            self._say("The board must be seen by two cameras or more to link them", theme.FAILURE)
            return False
        seen = [n for n, d in zip(self.rig_views.names, self.rig_detections) if d is not None]
        self._say(f"View {len(self.rig_views.views)}: {', '.join(seen)}. {self.rig_views.advice()}", theme.ACCENT)
        return True

    def floor_origin_m(self) -> tuple[float, float, float]:
        """The floor board's first corner in the world, its centre where the helper lays it."""
        # lazy: calibration.extrinsics (scipy.optimize) only once the rig is solved; keeps the game's start-up short
        from calibration.extrinsics import floor_board_centre_m

        known = getattr(self.rig_feed, "seat_board_centre_m", None)
        target = np.asarray(self.board_centre_m if known is None else known, float)
        return tuple(float(v) for v in target - floor_board_centre_m(self.board))

    def steady_lens_information(self) -> list:
        """The information matrices of the lenses calibrated here from 10 views or more (the board
        path refines them with the positions, as ``rehab calibrate extrinsics`` does); None for the
        others and for lens data given from a file."""
        results = [p.result for p in self.progress]
        return steady_lens_information([r.information for r in results], [len(r.per_view_rms_px) for r in results])

    def capture_floor(self) -> bool:
        """Solve the rig with the board on the seat, report its quality and save the calibration."""

        if self.rig_images is None or not any(d is not None for d in self.rig_detections):
            self._say("No camera sees the board on the seat yet", theme.FAILURE)
            return False
        cams = [p.result.camera for p in self.progress]
        try:
            if self.method == "wand":
                res = solve_rig_wand(cams, self.wand_views, self.wand_length_m, self.board, self.rig_detections,
                                     origin_m=self.floor_origin_m())
                self._report_views = {"floor": list(self.rig_detections)}
            else:
                res = solve_rig(cams, self.board, self.rig_views, self.rig_detections, origin_m=self.floor_origin_m(),
                                lens_information=self.steady_lens_information())
                self._report_views = {**self.rig_views.views, "floor": list(self.rig_detections)}
        except RehabError as exc:
            self.auto = False   # a wrong floor board is said once, not at every frame
            self._say(f"{exc}", theme.FAILURE)
            return False
        self.rig_result = res
        self.check_frames = []
        self._update_report()
        if self.wand_ready():   # the report measures the wand waved again with the finished calibration
            self.rig_feed.wave_wand()
        path = Path(self.out_path or default_calibration_path())
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            save_calibration_toml(path, res.cameras, adjusted=False, error=float(np.nanmax(res.rms_px)))
        except (RehabError, OSError) as exc:
            self._say(f"Not saved: {exc}", theme.FAILURE)
            return False
        self.saved_path = path
        self.stage = "report"
        self._say(f"Saved the calibration of {len(cams)} cameras to {path}", theme.ACCENT)
        return True

    def enter(self, app) -> None:
        super().enter(app)
        if self.stage == "lens" and self.rig_feed is None and all(p.result is not None for p in self.progress):
            self.next_step()   # every lens known (lens data given): straight to where the cameras stand
        if self.threaded and self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._worker, name="rehab-calibration-feed", daemon=True)
            self._thread.start()

    def exit(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for feed in [*self.feeds, self.rig_feed]:  # real cameras are released for the tracker to open
            close = getattr(feed, "close", None)
            if close is not None:
                close()

    def update(self, dt_s: float) -> None:
        if self._failed:
            self._say(self._failed, theme.FAILURE)
        if self.threaded:
            with self._lock:
                got, self._latest = self._latest, None
            if got is not None:
                self._show(*got)
            return
        self._since += dt_s
        if self._since >= 1.0 / FEED_RATE_HZ:
            self._since = 0.0
            self.next_frame()

    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        s = min(w / 1280.0, h / 720.0)
        if self.stage != "lens":
            title = STAGE_TITLES[self.stage]
            c.text(f"Calibrate cameras: {title}", (theme.MARGIN * s, 18 * s), round(theme.MEDIUM * s), theme.TEXT)
            {"positions": self._render_positions, "wand": self._render_wand, "floor": self._render_floor,
             "report": self._render_report}[self.stage](c, w, h, s)
            self._draw_buttons(c, w, h, s)
            return
        m = theme.MARGIN * s
        c.text(f"Calibrate cameras: {STAGE_TITLES['lens']}, {self.feed.name} ({self.index + 1} of {len(self.feeds)})",
               (m, 18 * s), round(theme.MEDIUM * s), theme.TEXT)
        if self.image is None:
            c.text("Waiting for the camera...", (w / 2, h / 2), round(theme.BODY * s), theme.ATTENTION, anchor="center")
            return
        if self.overlay is None:
            self.overlay = draw_feedback(self.image, self.detection, self.current.views, self.board)
        iw, ih = self.feed.size_px
        area_h = h - 170 * s
        img_w = min(0.6 * w, area_h * iw / ih)
        rect = (m, 72 * s, img_w, img_w * ih / iw)
        self.image_rect = rect
        c.image("calibrate-camera", self.overlay, rect)
        x = m + img_w + 28 * s
        y = 76 * s
        if self.detection is not None:
            c.text("Board found", (x, y), round(theme.BODY * s), theme.ACCENT)
        else:
            c.text("Board not found: show the whole board", (x, y), round(theme.BODY * s), theme.FAILURE)
        y += 48 * s
        n = len(self.current.views)
        c.text(f"{n} views captured", (x, y), round(theme.LARGE * s), theme.TEXT)
        y += 62 * s
        c.text(f"need at least {self.need_views}" + ("   auto-capture on" if self.auto else ""), (x, y),
               round(theme.SMALL * s), theme.ACCENT if n >= self.need_views else theme.TEXT_DIM)
        y += 40 * s
        col_w = w - x - m
        hint = self.lens_hint()
        for line in c.wrap(hint, round(theme.BODY * s), col_w)[:2]:
            c.text(line, (x, y), round(theme.BODY * s), theme.ACCENT if hint.startswith("Good") else theme.ATTENTION)
            y += 38 * s
        y += 10 * s
        result = self.current.result
        if result is not None:
            y = self._draw_result(c, result, x, y, s, col_w)
        for line in c.wrap(self.message, round(theme.SMALL * s), col_w)[:2]:
            c.text(line, (x, y), round(theme.SMALL * s), self.message_colour)
            y += 30 * s
        self._draw_buttons(c, w, h, s)

    def _draw_result(self, c, result: IntrinsicsResult, x: float, y: float, s: float, col_w: float) -> float:
        cam = result.camera
        f = float(np.mean(np.diag(cam.K)[:2]))
        good = result.rms_px < 0.5
        c.text(f"RMS error {result.rms_px:.2f} px", (x, y), round(theme.MEDIUM * s), theme.ACCENT if good else theme.ATTENTION)
        y += 46 * s
        c.text(f"Focal length {f:.1f} px", (x, y), round(theme.MEDIUM * s), theme.TEXT)
        y += 46 * s
        truth = self.feed.truth
        if truth is not None:
            f_true = float(np.mean(np.diag(truth.K)[:2]))
            c.text(f"{100 * (f - f_true) / f_true:+.2f} % from the true {f_true:.1f} px", (x, y),
                   round(theme.SMALL * s), theme.TEXT_DIM)
            y += 32 * s
        for warning in result.warnings[:2]:
            text = warning.split(": ", 1)[-1]
            for line in c.wrap(text, round(theme.SMALL * 0.85 * s), col_w)[:2]:
                c.text(line, (x, y), round(theme.SMALL * 0.85 * s), theme.ATTENTION)
                y += 26 * s
        return y + 8 * s

    # ----------------------------------------------------------------- drawing the rig steps
    def _thumbnails(self, c, s: float, area: Rect) -> None:
        """Every camera's image, the board found drawn over it, in a grid filling ``area``."""
        x0, y0, aw, ah = area
        if self.rig_images is None:
            c.text("Waiting for the cameras...", (x0 + aw / 2, y0 + ah / 2), round(theme.BODY * s), theme.ATTENTION,
                   anchor="center")
            return
        n = len(self.rig_images)
        cols = 1 if n == 1 else 2
        rows = -(-n // cols)
        iw, ih = self.feeds[0].size_px
        cell_w = min(aw / cols, (ah / rows - 26 * s) * iw / ih)
        cell_h = cell_w * ih / iw
        wand = self.stage in ("wand", "report") and self.wand_uv is not None and len(self.wand_uv) == n
        for k, img in enumerate(self.rig_images):
            x = x0 + (k % cols) * (cell_w + 8 * s)
            y = y0 + (k // cols) * (cell_h + 30 * s)
            if wand:
                balls = int(np.all(np.isfinite(self.wand_uv[k]), axis=1).sum())
                picture, found = draw_wand(img, self.wand_uv[k]), balls == 2
                label = f"{self.feeds[k].name}: " + ("both balls" if found else f"{balls} of 2 balls")
            else:
                det = self.rig_detections[k] if k < len(self.rig_detections) else None
                picture, found = draw_feedback(img, det, [], self.board, grid=False), det is not None
                label = f"{self.feeds[k].name}: " + ("board found" if found else "no board")
            c.image(f"calibrate-rig-{k}", picture, (x, y, cell_w, cell_h))
            c.text(label, (x, y + cell_h + 2 * s), round(theme.SMALL * 0.9 * s), theme.ACCENT if found else theme.TEXT_DIM)

    def _side_text(self, c, lines, x: float, y: float, s: float, col_w: float, size=theme.BODY, colour=theme.TEXT) -> float:
        for text in lines:
            for line in c.wrap(text, round(size * s), col_w):
                c.text(line, (x, y), round(size * s), colour)
                y += (size + 8) * s
        return y

    def _rig_layout(self, c, w: float, h: float, s: float, instruction: str, colour) -> tuple[float, float, float]:
        """The cameras' pictures on the left, the instruction at the top right; returns (x, y, width) below it."""
        m = theme.MARGIN * s
        left_w = 0.58 * w
        self._thumbnails(c, s, (m, 70 * s, left_w, h - 170 * s))
        x = m + left_w + 24 * s
        col_w = w - x - m
        return x, self._side_text(c, [instruction], x, 72 * s, s, col_w, theme.SMALL, colour), col_w

    def _render_positions(self, c, w: float, h: float, s: float) -> None:
        x, y, col_w = self._rig_layout(c, w, h, s, "Hold the board still where two or more cameras see all of it; go round the "
                                "cameras so that every neighbouring pair shares 3 views.", theme.TEXT_DIM)
        side = min(col_w, 0.36 * h)
        c.image("calibrate-links", link_diagram(self.rig_views.names, self.rig_views.pair_counts()),
                (x, y + 4 * s, side * 1.2, side))
        y += side + 14 * s
        n = len(self.rig_views.views)
        c.text(f"{n} view{'' if n == 1 else 's'}" + ("   auto-capture on" if self.auto else ""), (x, y), round(theme.BODY * s),
               theme.TEXT)
        y += 40 * s
        linked = self.rig_views.linked()
        y = self._side_text(c, [self.rig_views.advice()], x, y, s, col_w, theme.SMALL, theme.ACCENT if linked else theme.ATTENTION)
        self._side_text(c, [self.message], x, y + 6 * s, s, col_w, theme.SMALL * 0.9, self.message_colour)

    def _render_wand(self, c, w: float, h: float, s: float) -> None:

        views = self.wand_views
        x, y, col_w = self._rig_layout(c, w, h, s, f"Wave the wand ({1000 * self.wand_length_m:.0f} mm) slowly through the "
                                       "volume where the patient will sit, turning it; frames seen by two cameras are kept.",
                                       theme.TEXT_DIM)
        side = min(col_w, 0.36 * h)
        c.image("calibrate-links", link_diagram(views.names, views.pair_counts(), need=MIN_WAND_FRAMES),
                (x, y + 4 * s, side * 1.2, side))
        y += side + 14 * s
        c.text(f"{len(views.frames)} of {WAND_FRAMES} frames", (x, y), round(theme.BODY * s), theme.TEXT)
        y += 40 * s
        self._side_text(c, [views.advice()], x, y, s, col_w, theme.SMALL, theme.ACCENT if views.ready() else theme.ATTENTION)

    def _render_floor(self, c, w: float, h: float, s: float) -> None:
        x, y, col_w = self._rig_layout(c, w, h, s, "Lay the board face up on the seat, its rows across the patient, "
                                       "the black corner square at the patient's front left.", theme.TEXT)
        side = min(col_w / 1.2, 0.42 * h)
        c.image("calibrate-floor", floor_board_picture(self.board), (x, y + 4 * s, side * 1.2, side))
        y += side + 16 * s
        state = "Hold on..." if not self.rig_still else "Board still: capturing" if self.auto else "Board still: Capture (Space)"
        c.text(state, (x, y), round(theme.SMALL * s), theme.ACCENT if self.rig_still else theme.TEXT_DIM)
        self._side_text(c, [self.message], x, y + 36 * s, s, col_w, theme.SMALL * 0.9, self.message_colour)

    def _render_report(self, c, w: float, h: float, s: float) -> None:
        m = theme.MARGIN * s
        rep, res = self.report, self.rig_result
        colour = {"good": theme.ACCENT, "usable": theme.ATTENTION, "redo": theme.FAILURE}[rep.verdict]
        lines = rep.lines()
        n_cams = len(res.cameras)
        figures = lines[1:len(lines) - n_cams - len(rep.advice)]
        c.text(lines[0], (m, 76 * s), round(theme.LARGE * s), colour)
        y = 140 * s
        y = self._side_text(c, figures, m, y, s, w - 2 * m, theme.BODY * 0.9, theme.TEXT)
        y += 6 * s
        truth = getattr(self.rig_feed, "truth", None)
        pos = ang = None
        if truth is not None:
            # lazy: calibration.extrinsics (scipy.optimize) only once the rig is solved; keeps the game's start-up short
            from calibration.extrinsics import rig_errors

            pos, ang = rig_errors(res.cameras, truth)
        what = "wand balls" if self.method == "wand" else "board corners"
        wand_px = None if rep.wand is None else rep.wand.rms_px
        for k, cam in enumerate(res.cameras):
            at = ", ".join(f"{v:.2f}" for v in cam.centre_m)
            fit = f"{what} {rep.rms_px[k]:.2f} px"
            if wand_px is not None and self.method != "wand" and np.isfinite(wand_px[k]):
                fit += f", wand {wand_px[k]:.2f} px"
            drifts = rep.wand is not None and np.isfinite(rep.wand.edge_drift_px[k])
            if drifts:   # the lens near the picture's edge, as far as the balls went
                fit += f", lens near the edge {rep.wand.edge_drift_px[k]:+.2f} px"
            extra = "" if pos is None else f"  (simulated: {pos[k]:.1f} mm, {ang[k]:.2f} deg off)"
            worst = np.nanmax([rep.rms_px[k], -1.0 if wand_px is None else wand_px[k]])
            off = drifts and rep.wand.drift_found(k) and rep.wand.edge_drift_mm(k) >= GOOD_LENGTH_MM
            c.text(f"{cam.name}: {fit}, at ({at}) m{extra}", (m, y), round(theme.SMALL * 0.9 * s),
                   theme.TEXT if worst < 0.5 and not off else theme.ATTENTION)
            y += 30 * s
        y += 8 * s
        y = self._side_text(c, list(rep.advice), m, y, s, w - 2 * m, theme.SMALL * 0.9, theme.ATTENTION)
        self._side_text(c, [self.message], m, y + 6 * s, s, w - 2 * m, theme.SMALL * 0.9, self.message_colour)

    def _draw_buttons(self, c, w: float, h: float, s: float) -> None:
        n = len(self.buttons)
        gap = 14 * s
        bw = (w - 2 * theme.MARGIN * s - (n - 1) * gap) / n
        bh = 64 * s
        y = h - bh - 18 * s
        self._buttons = [(theme.MARGIN * s + i * (bw + gap), y, bw, bh) for i in range(n)]
        for (label, key), rect in zip(self.buttons, self._buttons):
            on = label == "Auto" and self.auto
            c.rect(rect, theme.ACCENT_DARK if on else theme.PANEL, radius=12 * s, border=2 * s, border_colour=theme.PANEL_EDGE)
            c.text(f"{label} ({key})", (rect[0] + rect[2] / 2, rect[1] + rect[3] / 2), round(theme.SMALL * s),
                   theme.TEXT, anchor="center")
