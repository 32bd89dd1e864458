"""Simulated calibration material with ground truth: board images and a wand sequence.

Boards are ray-cast on the CPU through the exact camera model (:meth:`Camera.undistort_points`
for every sub-pixel sample, so lens distortion is exact) and anti-aliased by supersampling; they
are drawn over the studio's room as the GL renderer images it with no one in it. A board is
always drawn in front of the room (nothing occludes it), which holds for a board held in the
capture volume; for the board lying on the seat it means that the chair's backrest does not hide
it from the cameras behind the chair, as it would in a real room.

The wand (two marker balls on a thin dark stick) is rendered by the studio renderer itself, as
the patient's markers are, so the wand's centroids come from the same blob detector as tracking.

What is made (:func:`write_calibration_material`)::

    OUT/
      truth_calibration.toml        the rig's true cameras (world frame of docs/INTERFACES.md)
      material.yaml                 board, seat-board origin, wand length and colours
      intrinsics/cam1/000.png ...   the board close to each camera, in many places and tilts
      intrinsics_charuco/cam1/...   on request: a ChArUco board likewise, some views partly out of the picture
      extrinsics_charuco/cam1/...   on request: a larger ChArUco board seen by neighbouring cameras, and on the seat
      extrinsics/cam1/000.png ...   the board seen by neighbouring cameras at once (same name = same instant)
      extrinsics/cam1/seat.png ...  the board lying on the seat: sets the world frame
      wand/cam1.avi ... meta.yaml   the wand waved through the volume (lossless FFV1)
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

import cv2
import numpy as np
from tqdm import tqdm
import yaml

from calibration.board import Checkerboard
from calibration.camera import Camera, rotation_from_rvec
from calibration.files import save_calibration_toml
from tracking.errors import RecordingError
from tracking.sim.renderer import StudioRenderer
from tracking.sim.scene import SceneFrame

log = logging.getLogger(__name__)

WHITE_LEVEL = 215.0
BLACK_LEVEL = 28.0
BACK_LEVEL = 120.0  # the back of the board
MARGIN_SQUARES = 0.8  # white margin around the printed squares
SEAT_TOP_M = 0.45
DEFAULT_BOARD = Checkerboard(9, 6, 0.06)
WAND_LENGTH_M = 0.5
WAND_BALL_RADIUS_M = 0.02
WAND_STICK_RADIUS_M = 0.003  # a thin carbon rod
WAND_COLOURS_RGB255 = ((255, 214, 0), (225, 0, 210))  # yellow, magenta (marker palette colours)


@dataclass(frozen=True, slots=True)
class BoardPose:
    """Where a board is: board frame -> world, ``x_world = R @ x_board + t``.

    Attributes:
        R: (3, 3) float64 rotation.
        t_m: (3,) float64 position of corner 0, world metres.
    """

    R: np.ndarray
    t_m: np.ndarray


def seat_board_pose(board: Checkerboard) -> BoardPose:
    """The board lying face up on the seat, x along the patient's right (+X), centred on the seat.

    Face up means its z (into the face) points down, so its y runs backwards (+Z).
    """
    R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # columns: x->+X, y->+Z, z->-Y
    w = (board.cols - 1) * board.square_m
    h = (board.rows - 1) * board.square_m
    return BoardPose(R, np.array([-w / 2.0, SEAT_TOP_M + 0.003, -h / 2.0]))


class BoardRaycaster:
    """Draws a board into images of one camera by ray casting (cached sub-pixel rays).

    Args:
        camera: the camera (intrinsics, distortion and pose).
        board: the board: a :class:`Checkerboard` or a :class:`calibration.charuco.CharucoBoard`
            (anything with ``cols``, ``rows``, ``square_m``, ``object_points()`` and ``is_black()``).
        supersample: sub-samples per pixel along each axis.
    """

    def __init__(self, camera: Camera, board, supersample: int = 3):
        self.camera = camera
        self.board = board
        self.s = int(supersample)
        w, h = camera.size_px
        offs = (np.arange(self.s) + 0.5) / self.s - 0.5
        u = (np.arange(w)[:, None] + offs[None, :]).ravel()
        v = (np.arange(h)[:, None] + offs[None, :]).ravel()
        uu, vv = np.meshgrid(u, v)  # (h*s, w*s)
        xn = camera.undistort_points(np.stack([uu.ravel(), vv.ravel()], axis=1))
        rays = np.hstack([xn, np.ones((xn.shape[0], 1))]).astype(np.float32)  # camera frame
        self._rays = rays.reshape(h * self.s, w * self.s, 3)

    def draw(self, background_bgr: np.ndarray, pose: BoardPose, *, light: float = 1.0) -> np.ndarray:
        """The background with the board drawn over it (no noise). Returns a new (H, W, 3) uint8 image."""
        cam, board, s = self.camera, self.board, self.s
        w, h = cam.size_px
        R_cb = cam.R @ pose.R  # board -> camera
        t_cb = cam.R @ pose.t_m + cam.t_m
        Hm = np.column_stack([R_cb[:, 0], R_cb[:, 1], t_cb])  # board plane (x, y, 1) -> camera ray
        x0, y0, x1, y1 = self._pixel_box(pose)
        if x1 <= x0 or y1 <= y0:
            return background_bgr.copy()
        rays = self._rays[y0 * s : y1 * s, x0 * s : x1 * s].reshape(-1, 3)
        w, h = x1 - x0, y1 - y0
        # Board coordinates in squares (float32 is plenty: 1e-7 of a square), (x, y, 1) / depth.
        q = rays @ (np.linalg.inv(Hm).T / np.array([board.square_m, board.square_m, 1.0])).astype(np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = q[:, 0] / q[:, 2]
            y = q[:, 1] / q[:, 2]
        # The printed squares span -1..cols along x and -1..rows along y, then the white margin.
        lo = -1.0 - MARGIN_SQUARES
        on = (q[:, 2] > 0) & (x >= lo) & (x <= board.cols + MARGIN_SQUARES) & (y >= lo) & (y <= board.rows + MARGIN_SQUARES)
        front = float(R_cb[:, 2] @ t_cb) > 0.0  # the camera is on the printed side
        if front:
            black = board.is_black(x * board.square_m, y * board.square_m)
            level = np.where(black, np.float32(BLACK_LEVEL * light), np.float32(WHITE_LEVEL * light))
        else:
            level = np.full(q.shape[0], np.float32(BACK_LEVEL * light))
        level = np.where(on, level, np.float32(0.0)).reshape(h, s, w, s)
        n_on = on.reshape(h, s, w, s).sum(axis=(1, 3))
        board_sum = level.sum(axis=(1, 3), dtype=np.float64)
        bg = background_bgr[y0:y1, x0:x1].astype(np.float64)
        out = background_bgr.copy()
        patch = (board_sum[..., None] + (s * s - n_on)[..., None] * bg) / (s * s)
        out[y0:y1, x0:x1] = np.clip(np.rint(patch), 0, 255).astype(np.uint8)
        return out

    def _pixel_box(self, pose: BoardPose) -> tuple[int, int, int, int]:
        """Pixel bounds (x0, y0, x1, y1), end exclusive, of the board with its margin in the image."""
        cam, board = self.camera, self.board
        lo, sq = -1.0 - MARGIN_SQUARES, board.square_m
        hx, hy = board.cols + MARGIN_SQUARES, board.rows + MARGIN_SQUARES
        t = np.linspace(0.0, 1.0, 25)[:, None]
        corners = np.array([[lo, lo], [hx, lo], [hx, hy], [lo, hy], [lo, lo]]) * sq
        edge = np.vstack([a + t * (b - a) for a, b in zip(corners[:-1], corners[1:])])
        uv = cam.project(np.hstack([edge, np.zeros((len(edge), 1))]) @ pose.R.T + pose.t_m)
        w, h = cam.size_px
        if not np.all(np.isfinite(uv)):  # partly behind the camera: cast every ray
            return 0, 0, w, h
        x0, y0 = np.floor(uv.min(axis=0)).astype(int) - 2
        x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + 3
        return max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)

    def corners_px(self, pose: BoardPose) -> np.ndarray:
        """(N, 2) true pixel positions of the board's inner corners."""
        return self.camera.project(self.board.object_points() @ pose.R.T + pose.t_m)


def add_noise(image: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Sensor noise: Gaussian, ``sigma`` in 8-bit units, on a (H, W, 3) uint8 image (a new one)."""
    if sigma <= 0:
        return image
    noisy = image.astype(np.float64) + rng.normal(0.0, sigma, image.shape)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def board_light(pose: BoardPose) -> float:
    """Diffuse brightness of the board: ambient plus a ceiling light above and in front."""
    normal = -pose.R[:, 2]  # out of the printed face
    light = np.array([0.25, 0.65, -0.72])
    light /= np.linalg.norm(light)
    return 0.7 + 0.3 * abs(float(normal @ light))


def _fully_visible(cam: Camera, board: Checkerboard, pose: BoardPose, margin_px: float) -> bool:
    """All inner corners and the outer squares project inside the image, on the printed side."""
    sq = board.square_m
    outline = np.array([[-sq, -sq, 0], [board.cols * sq, -sq, 0], [-sq, board.rows * sq, 0], [board.cols * sq, board.rows * sq, 0]])
    pts = np.vstack([board.object_points(), outline]) @ pose.R.T + pose.t_m
    uv = cam.project(pts)
    w, h = cam.size_px
    R_cb = cam.R @ pose.R
    t_cb = cam.R @ pose.t_m + cam.t_m
    if not float(R_cb[:, 2] @ t_cb) > 0.0:
        return False
    return bool(np.all(np.isfinite(uv)) and uv[:, 0].min() > margin_px and uv[:, 1].min() > margin_px
                and uv[:, 0].max() < w - 1 - margin_px and uv[:, 1].max() < h - 1 - margin_px)


def _rotation(axis_angle: np.ndarray) -> np.ndarray:
    return rotation_from_rvec(np.asarray(axis_angle, float))


def visible_corner_share(cam: Camera, board, pose: BoardPose, margin_px: float = 3.0) -> float:
    """Share 0..1 of the board's inner corners that project inside the image (0 from behind)."""
    R_cb = cam.R @ pose.R
    t_cb = cam.R @ pose.t_m + cam.t_m
    if not float(R_cb[:, 2] @ t_cb) > 0.0:
        return 0.0
    uv = cam.project(board.object_points() @ pose.R.T + pose.t_m)
    w, h = cam.size_px
    with np.errstate(invalid="ignore"):
        inside = (uv[:, 0] > margin_px) & (uv[:, 1] > margin_px) & (uv[:, 0] < w - 1 - margin_px) & (uv[:, 1] < h - 1 - margin_px)
    return float(inside.mean())


def partial_poses(cam: Camera, board, n: int, rng: np.random.Generator, *, share=(0.3, 0.75)) -> list[BoardPose]:
    """``n`` board poses close to one camera, each partly out of the picture over an edge or corner.

    Between ``share[0]`` and ``share[1]`` of the inner corners are in view: a ChArUco board still
    gives those corners; a checkerboard would be lost.
    """
    w, h = cam.size_px
    bw, bh = (board.cols - 1) * board.square_m, (board.rows - 1) * board.square_m
    f = cam.K[0, 0]
    places = [(-1, -1), (1, 1), (1, -1), (-1, 1), (-1, 0), (1, 0), (0, -1), (0, 1)]
    poses: list[BoardPose] = []
    attempts = 0
    while len(poses) < n:
        attempts += 1
        if attempts > 200 * max(n, 1):
            raise RecordingError(f"{cam.name}: cannot place the board partly in view {n} times")
        g = np.asarray(places[len(poses) % len(places)], float)
        width_frac = rng.uniform(0.45, 0.7)
        fx, fy = 0.5 + g * rng.uniform(0.4, 0.55, 2)  # the board's centre near the edge of the picture
        depth = f * bw / (width_frac * w)
        xn = cam.undistort_points(np.array([[fx * w, fy * h]]))[0]
        centre_cam = np.array([xn[0], xn[1], 1.0]) * depth
        R_cb = _rotation([*rng.uniform(-0.5, 0.5, 2), 0.0]) @ _rotation([0.0, 0.0, rng.uniform(-0.35, 0.35)])
        t_cb = centre_cam - R_cb @ np.array([bw / 2, bh / 2, 0.0])
        pose = BoardPose(cam.R.T @ R_cb, cam.R.T @ (t_cb - cam.t_m))
        if share[0] <= visible_corner_share(cam, board, pose) <= share[1]:
            poses.append(pose)
    return poses


def intrinsics_poses(cam: Camera, board: Checkerboard, n: int, rng: np.random.Generator) -> list[BoardPose]:
    """``n`` board poses close to one camera, spread over the image, tilted up to ~35 degrees."""
    w, h = cam.size_px
    bw, bh = (board.cols - 1) * board.square_m, (board.rows - 1) * board.square_m
    f = cam.K[0, 0]
    # Image positions: the corners and edges of the picture first (where lens distortion shows),
    # then random ones; the board is pushed as far out as its size allows.
    grid = [(-1, -1), (1, 1), (1, -1), (-1, 1), (0, 0), (0, -1), (0, 1), (-1, 0), (1, 0)]
    poses: list[BoardPose] = []
    attempts = 0
    while len(poses) < n:
        attempts += 1
        if attempts > 200 * n:
            raise RecordingError(f"{cam.name}: cannot place the board fully in view {n} times; use a smaller board")
        k = len(poses)
        g = np.asarray(grid[k % len(grid)] if k < 2 * len(grid) else rng.uniform(-1, 1, 2), float)
        width_frac = rng.uniform(0.35, 0.6)  # board width as a share of the image width
        half = np.array([width_frac / 2, width_frac * (bh / bw) * (w / h) / 2])
        reach = np.maximum(0.5 - half - 0.03, 0.0) * rng.uniform(0.6, 1.0)
        fx, fy = 0.5 + g * reach
        depth = f * bw / (width_frac * w)
        xn = cam.undistort_points(np.array([[fx * w, fy * h]]))[0]
        centre_cam = np.array([xn[0], xn[1], 1.0]) * depth
        tilt = rng.uniform(-0.6, 0.6, 2)
        roll = rng.uniform(-0.35, 0.35)
        R_cb = _rotation([tilt[0], tilt[1], 0.0]) @ _rotation([0.0, 0.0, roll])
        t_cb = centre_cam - R_cb @ np.array([bw / 2, bh / 2, 0.0])
        pose = BoardPose(cam.R.T @ R_cb, cam.R.T @ (t_cb - cam.t_m))
        if _fully_visible(cam, board, pose, margin_px=3.0):
            poses.append(pose)
    return poses


def shared_poses(cams: Sequence[Camera], board: Checkerboard, n: int, rng: np.random.Generator,
                 centre_m=(0.0, 1.0, 0.0), spread_m=(0.25, 0.25, 0.25)) -> list[BoardPose]:
    """``n`` board poses in the capture volume, facing between two cameras, fully seen by both."""
    a, b = cams
    bw, bh = (board.cols - 1) * board.square_m, (board.rows - 1) * board.square_m
    poses: list[BoardPose] = []
    attempts = 0
    while len(poses) < n and attempts < 300 * n:
        attempts += 1
        centre = np.asarray(centre_m) + rng.uniform(-1, 1, 3) * np.asarray(spread_m)
        to_a = a.centre_m - centre
        to_b = b.centre_m - centre
        facing = to_a / np.linalg.norm(to_a) + to_b / np.linalg.norm(to_b)
        if np.linalg.norm(facing) < 1e-6:
            break
        z = -facing / np.linalg.norm(facing)  # board z points away from the cameras
        z = _rotation(rng.uniform(-0.2, 0.2, 3)) @ z
        x = np.cross(np.array([0.0, 1.0, 0.0]), z)  # board rows horizontal-ish
        x /= np.linalg.norm(x)
        x = _rotation(z * rng.uniform(-0.3, 0.3)) @ x
        y = np.cross(z, x)
        R = np.column_stack([x, y, z])
        pose = BoardPose(R, centre - R @ np.array([bw / 2, bh / 2, 0.0]))
        if _fully_visible(a, board, pose, 3.0) and _fully_visible(b, board, pose, 3.0):
            poses.append(pose)
    return poses


def neighbour_pairs(cams: Sequence[Camera], target_m=(0.0, 1.0, 0.0)) -> list[tuple[int, int]]:
    """Pairs of cameras next to each other around the target (by azimuth), closing the ring."""
    az = [np.arctan2(c.centre_m[0] - target_m[0], -(c.centre_m[2] - target_m[2])) for c in cams]
    order = [int(i) for i in np.argsort(az)]
    if len(order) == 2:
        return [(order[0], order[1])]
    return [(order[k], order[(k + 1) % len(order)]) for k in range(len(order))]


def room_backgrounds(cams: Sequence[Camera]) -> list[np.ndarray]:
    """The empty room as each camera sees it (GL renderer, no noise)."""
    with StudioRenderer(cams) as renderer:
        return list(renderer.render(SceneFrame.empty(), with_visibility=False).images)


def render_intrinsics_images(cam: Camera, background: np.ndarray, board, n: int, *, seed: int = 0,
                             noise_sigma: float = 1.5, n_partial: int = 0) -> tuple[list[np.ndarray], list[BoardPose]]:
    """``n`` images of the whole board close to one camera, then ``n_partial`` images of the board
    partly out of the picture (:func:`partial_poses`), and the board poses.

    ``board`` is a :class:`Checkerboard` or a :class:`calibration.charuco.CharucoBoard`.
    """
    rng = np.random.default_rng(seed)
    caster = BoardRaycaster(cam, board)
    poses = intrinsics_poses(cam, board, n, rng)
    if n_partial:
        poses += partial_poses(cam, board, n_partial, rng)
    images = [add_noise(caster.draw(background, p, light=board_light(p)), noise_sigma, rng) for p in poses]
    return images, poses


def render_views(cams: Sequence[Camera], backgrounds: Sequence[np.ndarray], board: Checkerboard,
                 poses: Sequence[BoardPose], *, seed: int = 0, noise_sigma: float = 1.5) -> list[list[np.ndarray]]:
    """Each board pose imaged by every camera: ``images[view][camera]``."""
    rng = np.random.default_rng(seed)
    casters = [BoardRaycaster(c, board) for c in cams]
    return [[add_noise(cs.draw(bg, p, light=board_light(p)), noise_sigma, rng) for cs, bg in zip(casters, backgrounds)]
            for p in poses]


def extrinsics_poses(cams: Sequence[Camera], board: Checkerboard, per_pair: int, rng: np.random.Generator) -> list[BoardPose]:
    """Board poses for the extrinsics: ``per_pair`` shared views for each neighbouring pair."""
    poses = []
    for i, j in neighbour_pairs(cams):
        got = shared_poses((cams[i], cams[j]), board, per_pair, rng)
        if len(got) < per_pair:
            log.warning("only %d board poses fully seen by both %s and %s", len(got), cams[i].name, cams[j].name)
        poses += got
    return poses


# ----------------------------------------------------------------------------- wand
def wand_path(n_frames: int, fps: float, *, seed: int = 0, length_m: float = WAND_LENGTH_M,
              centre_m=(0.0, 1.0, 0.0), half_size_m=(0.45, 0.45, 0.4)) -> np.ndarray:
    """(T, 2, 3) ball centres of a wand waved smoothly through a box around the patient's place."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / fps
    freq = rng.uniform(0.08, 0.25, (2, 3, 3))  # Hz: position / direction, axis, harmonic
    phase = rng.uniform(0, 2 * np.pi, (2, 3, 3))
    amp = np.array([0.6, 0.3, 0.15])
    wave = (amp[None, None, :, None] * np.sin(2 * np.pi * freq[..., None] * t + phase[..., None])).sum(axis=2)  # (2, 3, T)
    centre = np.asarray(centre_m)[:, None] + np.asarray(half_size_m)[:, None] * wave[0] / amp.sum()
    direction = wave[1] + np.array([[0.3], [0.2], [0.0]])
    direction /= np.linalg.norm(direction, axis=0, keepdims=True)
    half = 0.5 * length_m * direction
    return np.stack([(centre - half).T, (centre + half).T], axis=1)


def wand_scene(balls_m: np.ndarray, radius_m: float = WAND_BALL_RADIUS_M,
               colours_rgb255=WAND_COLOURS_RGB255) -> SceneFrame:
    """The wand at one instant: two marker balls (indices 0, 1) joined by a thin dark stick."""
    a, b = balls_m
    d = (b - a) / np.linalg.norm(b - a)
    p0, p1 = a + d * 0.9 * radius_m, b - d * 0.9 * radius_m  # the stick ends inside the balls
    return SceneFrame(
        sphere_centre_m=np.asarray(balls_m, float),
        sphere_radius_m=np.full(2, radius_m),
        sphere_rgb=np.asarray(colours_rgb255, np.float32) / 255.0,
        sphere_marker_index=np.array([0, 1], np.int32),
        capsule_p0_m=p0[None], capsule_p1_m=p1[None],
        capsule_r0_m=np.array([WAND_STICK_RADIUS_M]), capsule_r1_m=np.array([WAND_STICK_RADIUS_M]),
        capsule_rgb=np.array([[0.12, 0.12, 0.12]], np.float32),
        ellipsoid_centre_m=np.zeros((0, 3)), ellipsoid_axes_m=np.zeros((0, 3, 3)), ellipsoid_rgb=np.zeros((0, 3), np.float32),
    )


def render_wand(cams: Sequence[Camera], balls_m: np.ndarray, *, noise_sigma: float = 1.5, seed: int = 0,
                colours_rgb255=WAND_COLOURS_RGB255) -> Iterator[tuple[np.ndarray, ...]]:
    """Images of every camera, frame by frame, of the wand at ``balls_m`` (T, 2, 3)."""
    with StudioRenderer(cams) as renderer:
        for k, balls in enumerate(balls_m):
            yield renderer.render(wand_scene(balls, colours_rgb255=colours_rgb255), noise_sigma=noise_sigma,
                                  seed=seed * 1_000_003 + k, with_visibility=False).images


# ----------------------------------------------------------------------------- all of it
def write_calibration_material(out_dir: Path, cams: Sequence[Camera], *, board: Checkerboard = DEFAULT_BOARD,
                               n_intrinsics: int = 15, per_pair: int = 4, wand_seconds: float = 20.0,
                               wand_fps: float = 15.0, noise_sigma: float = 1.5, seed: int = 0,
                               charuco=None, charuco_extrinsics=None, n_partial: int = 5, progress: bool = False) -> str:
    """Write board images, a wand sequence and the truth (module docstring). Returns a summary line.

    With ``charuco`` (a :class:`calibration.charuco.CharucoBoard`), also ``intrinsics_charuco/``:
    ``n_intrinsics`` images of the whole ChArUco board per camera and ``n_partial`` with the board
    partly out of the picture. With ``charuco_extrinsics`` (a ChArUco board large enough to be
    seen from the cameras' distance), also ``extrinsics_charuco/``: its shared views and the seat.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    save_calibration_toml(out_dir / "truth_calibration.toml", cams)
    backgrounds = room_backgrounds(cams)
    rng = np.random.default_rng(seed)
    n_images = 0
    for k, (cam, bg) in enumerate(tqdm(list(zip(cams, backgrounds)), desc="intrinsics images", disable=not progress)):
        folder = out_dir / "intrinsics" / cam.name
        folder.mkdir(parents=True, exist_ok=True)
        images, _ = render_intrinsics_images(cam, bg, board, n_intrinsics, seed=seed * 101 + k, noise_sigma=noise_sigma)
        for i, img in enumerate(images):
            cv2.imwrite(str(folder / f"{i:03d}.png"), img)
        n_images += len(images)
        if charuco is not None:
            folder = out_dir / "intrinsics_charuco" / cam.name
            folder.mkdir(parents=True, exist_ok=True)
            images, _ = render_intrinsics_images(cam, bg, charuco, n_intrinsics, seed=seed * 101 + k + 50,
                                                 noise_sigma=noise_sigma, n_partial=n_partial)
            for i, img in enumerate(images):
                cv2.imwrite(str(folder / f"{i:03d}.png"), img)
            n_images += len(images)
    n, seat = _write_shared_views(out_dir / "extrinsics", cams, backgrounds, board, per_pair, rng, seed=seed + 7,
                                  noise_sigma=noise_sigma)
    n_images += n
    if charuco_extrinsics is not None:
        n_images += _write_shared_views(out_dir / "extrinsics_charuco", cams, backgrounds, charuco_extrinsics, per_pair,
                                        np.random.default_rng(seed + 11), seed=seed + 13, noise_sigma=noise_sigma)[0]
    n_wand = int(round(wand_seconds * wand_fps))
    balls = wand_path(n_wand, wand_fps, seed=seed)
    write_wand_sequence(out_dir / "wand", cams, balls, wand_fps, noise_sigma=noise_sigma, seed=seed, progress=progress)
    material = {
        "board": {"pattern": f"{board.cols}x{board.rows}", "square_mm": board.square_m * 1000.0},
        "seat_board": {"image": "extrinsics/<camera>/seat.png", "origin_m": [float(v) for v in seat.t_m],
                       "x_axis": "+X (patient's right)"},
        "wand": {"folder": "wand", "length_mm": WAND_LENGTH_M * 1000.0, "colours": [list(c) for c in WAND_COLOURS_RGB255]},
        "noise_sigma": noise_sigma,
        "seed": seed,
    }
    if charuco is not None:
        material["charuco"] = {"squares": f"{charuco.squares_x}x{charuco.squares_y}", "square_mm": charuco.square_m * 1000.0,
                               "marker_mm": charuco.marker_m * 1000.0, "dictionary": charuco.dictionary,
                               "images": "intrinsics_charuco/<camera>/", "partial_views": n_partial}
    if charuco_extrinsics is not None:
        b = charuco_extrinsics
        material["charuco_extrinsics"] = {
            "squares": f"{b.squares_x}x{b.squares_y}", "square_mm": b.square_m * 1000.0, "marker_mm": b.marker_m * 1000.0,
            "dictionary": b.dictionary, "images": "extrinsics_charuco/<camera>/",
            "seat_origin_m": [float(v) for v in seat_board_pose(b).t_m]}
    (out_dir / "material.yaml").write_text(yaml.safe_dump(material, sort_keys=False), encoding="utf-8")
    return (f"wrote {n_images} board images and a {n_wand}-frame wand sequence from {len(cams)} cameras "
            f"to {out_dir} (truth in truth_calibration.toml)")


def _write_shared_views(folder: Path, cams: Sequence[Camera], backgrounds, board, per_pair: int,
                        rng: np.random.Generator, *, seed: int, noise_sigma: float) -> tuple[int, BoardPose]:
    """The extrinsics views and the seat board as ``folder/<camera>/000.png ... seat.png``.
    Returns the number of images and the seat board's pose."""
    poses = extrinsics_poses(cams, board, per_pair, rng)
    seat = seat_board_pose(board)
    views = render_views(cams, backgrounds, board, [*poses, seat], seed=seed, noise_sigma=noise_sigma)
    for c, cam in enumerate(cams):
        (folder / cam.name).mkdir(parents=True, exist_ok=True)
        for v, per_cam in enumerate(views):
            name = "seat" if v == len(poses) else f"{v:03d}"
            cv2.imwrite(str(folder / cam.name / f"{name}.png"), per_cam[c])
    return len(views) * len(cams), seat


def write_wand_sequence(folder: Path, cams: Sequence[Camera], balls_m: np.ndarray, fps: float, *,
                        noise_sigma: float = 1.5, seed: int = 0, progress: bool = False,
                        colours_rgb255=WAND_COLOURS_RGB255) -> None:
    """A wand recording: one lossless FFV1 video per camera, meta.yaml, truth_wand.csv (mm)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fourcc = cv2.VideoWriter_fourcc(*"FFV1")
    writers = [cv2.VideoWriter(str(folder / f"{c.name}.avi"), fourcc, fps, tuple(c.size_px)) for c in cams]
    try:
        if not all(w.isOpened() for w in writers):
            raise RecordingError(f"{folder}: cannot write FFV1 videos here")
        for images in tqdm(render_wand(cams, balls_m, noise_sigma=noise_sigma, seed=seed, colours_rgb255=colours_rgb255),
                           total=len(balls_m),
                           desc="wand", unit="frame", disable=not progress):
            for w, img in zip(writers, images):
                w.write(img)
    finally:
        for w in writers:
            w.release()
    meta = {"fps": float(fps), "n_frames": int(len(balls_m)), "source": "simulator: calibration wand",
            "wand_length_mm": WAND_LENGTH_M * 1000.0, "wand_colours": [list(c) for c in colours_rgb255]}
    (folder / "meta.yaml").write_text(yaml.safe_dump(meta, sort_keys=False), encoding="utf-8")
    np.savetxt(folder / "truth_wand.csv", balls_m.reshape(len(balls_m), 6) * 1000.0, delimiter=",", fmt="%.3f",
               header="ball0_x_mm,ball0_y_mm,ball0_z_mm,ball1_x_mm,ball1_y_mm,ball1_z_mm", comments="")
