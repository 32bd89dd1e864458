"""The calibration screen's rig steps: every camera's images at once, and the pictures they show.

- :class:`SimRigFeed`: the simulated helper holding the board where neighbouring cameras both see
  it, one place after the other, waving the wand through the volume (rendered by the studio
  renderer, as the patient's markers are), or laying the board face up on the seat (when the
  screen asks for the floor board); :class:`CameraRigFeed`: real cameras read one after the other
  (the board is held still, so the images need no hardware synchronisation; a moving wand does,
  so it is not offered with them).
- :func:`link_diagram`: the cameras around a circle, a line for each pair that shared board views
  or wand frames (teal when linked, amber while too few); :func:`draw_wand`: the balls found.
- :func:`floor_board_picture`: how to lay the board on the seat, seen from above.
"""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from calibration.camera import Camera, rotation_from_rvec, rvec_from_rotation
from calibration.guided import MIN_SHARED_VIEWS

_TEAL = (190, 200, 94)  # BGR of theme.ACCENT
_AMBER = (92, 190, 242)  # BGR of theme.ATTENTION
_TEXT = (245, 240, 236)
_DIM = (190, 174, 163)
_BACK = (43, 33, 27)


def board_pose_between(a, b, f: float):
    """Board pose a fraction ``f`` of the way from ``a`` to ``b`` (position linear, rotation geodesic)."""
    from tracking.sim.calibration_material import BoardPose  # lazy: the simulator only for the demo calibration

    rel = rvec_from_rotation(b.R @ a.R.T)
    return BoardPose(rotation_from_rvec(f * rel) @ a.R, (1 - f) * a.t_m + f * b.t_m)


class SimRigFeed:
    """A simulated helper with the board, seen by every camera of the simulated studio.

    The board holds still at each place of
    :func:`tracking.sim.calibration_material.extrinsics_poses` (``per_pair`` places for each pair
    of neighbouring cameras) for ``hold`` frames, then is carried to the next in ``move`` frames;
    after :meth:`lay_on_seat` it lies face up on the seat, centred, its first corner at the
    patient's front left.

    Args:
        cameras: the true cameras.
        backgrounds: the empty room as each sees it.
        board: the board.
        ctx: the application's moderngl context to render the wand with when the feed is read on
            the drawing thread (the screen rebinds its own framebuffer every frame); None: a
            standalone context, made on the thread that first reads a wand frame.
    """

    #: cameras that take their pictures at the same instant: the wand may move between pictures
    synchronised = True

    def __init__(self, cameras: Sequence[Camera], backgrounds: Sequence[np.ndarray], board, *, per_pair: int = 3,
                 hold: int = 4, move: int = 3, seed: int = 0, noise_sigma: float = 1.5, wand_fps: float = 10.0,
                 ctx=None) -> None:
        # lazy: the simulator only for the demo calibration (tests/test_layout.py)
        from tracking.sim.calibration_material import BoardRaycaster, extrinsics_poses, seat_board_pose

        self.names = [c.name for c in cameras]
        self.truth = list(cameras)
        self.board = board
        self._rng = np.random.default_rng(seed)
        self._casters = [BoardRaycaster(c, board, supersample=2) for c in cameras]
        self._backgrounds = list(backgrounds)
        self._noise = float(noise_sigma)
        poses = extrinsics_poses(cameras, board, per_pair, np.random.default_rng(seed + 1))
        self._path = []
        for i, pose in enumerate(poses):
            nxt = poses[(i + 1) % len(poses)]
            self._path += [pose] * hold + [board_pose_between(pose, nxt, (k + 1) / (move + 1)) for k in range(move)]
        self._seat = seat_board_pose(board)
        centre = board.object_points().mean(axis=0)
        self.seat_board_centre_m = self._seat.R @ centre + self._seat.t_m  # where the helper lays it
        self.mode = "board"   # "board" held up, "seat" lying on the seat, "wand" waved
        self._k = 0
        self._last = None
        self._clean: list[np.ndarray] = []
        self._seed = seed
        self._wand_fps = float(wand_fps)
        self._wand = None
        self._w = 0
        self._renderer = None
        self._ctx = ctx

    @classmethod
    def from_feeds(cls, feeds, board, **kwargs) -> "SimRigFeed":
        """From the screen's per-camera simulated feeds (their true cameras and rooms)."""
        return cls([f.truth for f in feeds], [f._background for f in feeds], board, **kwargs)

    @property
    def on_seat(self) -> bool:
        return self.mode == "seat"

    def lay_on_seat(self) -> None:
        self.mode = "seat"

    def hold_up(self) -> None:
        self.mode = "board"

    def wave_wand(self) -> None:
        """The helper waves the wand (yellow and magenta balls 500 mm apart) through the volume;
        each call goes on along the same path, so later frames are new places."""
        self.mode = "wand"

    def _wand_frames(self) -> list[np.ndarray]:
        # lazy: the simulator only for the demo calibration (tests/test_layout.py)
        from tracking.sim.calibration_material import wand_path, wand_scene
        # lazy: the simulator only for the demo calibration (tests/test_layout.py)
        from tracking.sim.renderer import StudioRenderer

        if self._renderer is None:   # the given context, or a standalone one made on the thread that reads the feed
            self._renderer = StudioRenderer(self.truth, ctx=self._ctx)
            self._wand = wand_path(int(120 * self._wand_fps), self._wand_fps, seed=self._seed)
        balls = self._wand[self._w % len(self._wand)]
        self._w += 1
        return list(self._renderer.render(wand_scene(balls), noise_sigma=self._noise, seed=self._seed * 1_000_003 + self._w,
                                          with_visibility=False).images)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.release()
            self._renderer = None

    def next_frames(self) -> list[np.ndarray]:
        # lazy: the simulator only for the demo calibration (tests/test_layout.py)
        from tracking.sim.calibration_material import add_noise, board_light

        if self.mode == "wand":
            return self._wand_frames()
        pose = self._seat if self.on_seat else self._path[self._k % len(self._path)]
        self._k += 1
        if pose is not self._last:
            self._last = pose
            self._clean = [c.draw(bg, pose, light=board_light(pose)) for c, bg in zip(self._casters, self._backgrounds)]
        return [add_noise(img, self._noise, self._rng) for img in self._clean]


class CameraRigFeed:
    """Real cameras (the screen's per-camera feeds), read one after the other."""

    seat_board_centre_m = None
    synchronised = False

    def __init__(self, feeds) -> None:
        self.feeds = list(feeds)
        self.names = [f.name for f in self.feeds]
        self.truth = None

    def lay_on_seat(self) -> None:
        pass

    def hold_up(self) -> None:
        pass

    def wave_wand(self) -> None:
        pass

    def close(self) -> None:
        pass

    def next_frames(self) -> list[np.ndarray]:
        return [f.next_frame() for f in self.feeds]


def draw_wand(image: np.ndarray, uv_px: np.ndarray) -> np.ndarray:
    """A camera's image with the wand balls found drawn over it: (2, 2) pixels, NaN where not seen."""
    out = image.copy()
    r = max(6, round(image.shape[1] / 60))
    pts = [tuple(int(v) for v in np.rint(p)) for p in uv_px if np.all(np.isfinite(p))]
    if len(pts) == 2:
        cv2.line(out, pts[0], pts[1], _TEAL, max(1, r // 4), cv2.LINE_AA)
    for p in pts:
        cv2.circle(out, p, r, _TEAL if len(pts) == 2 else _AMBER, max(1, r // 3), cv2.LINE_AA)
    return out


def link_diagram(names: Sequence[str], counts: np.ndarray, size_px: tuple[int, int] = (360, 300),
                 need: int = MIN_SHARED_VIEWS) -> np.ndarray:
    """(H, W, 3) BGR picture: the cameras around a circle, the views (or wand frames) each pair
    shared on its line, teal from ``need``."""
    w, h = size_px
    img = np.full((h, w, 3), _BACK, np.uint8)
    n = len(names)
    centre = np.array([w / 2, h / 2])
    r = 0.36 * min(w, h)
    ang = -np.pi / 2 + 2 * np.pi * np.arange(n) / max(n, 1)
    pos = centre + r * np.column_stack([np.cos(ang), np.sin(ang)])
    for i in range(n):
        for j in range(i + 1, n):
            k = int(counts[i, j])
            if k == 0:
                continue
            colour = _TEAL if k >= need else _AMBER
            a, b = tuple(np.rint(pos[i]).astype(int)), tuple(np.rint(pos[j]).astype(int))
            cv2.line(img, a, b, colour, 4 if k >= need else 2, cv2.LINE_AA)
            mid = np.rint((pos[i] + pos[j]) / 2).astype(int)
            cv2.putText(img, str(k), (int(mid[0]) - 6, int(mid[1]) - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.6, colour, 2, cv2.LINE_AA)
    for p, name in zip(pos, names):
        q = tuple(np.rint(p).astype(int))
        cv2.circle(img, q, 24, (59, 46, 38), -1, cv2.LINE_AA)
        cv2.circle(img, q, 24, _DIM, 2, cv2.LINE_AA)
        (tw, th), _ = cv2.getTextSize(name, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
        cv2.putText(img, name, (q[0] - tw // 2, q[1] + th // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.5, _TEXT, 1, cv2.LINE_AA)
    return img


def floor_board_picture(board, size_px: tuple[int, int] = (360, 300)) -> np.ndarray:
    """(H, W, 3) BGR picture, seen from above: the seat, the board on it with its black corner
    square at the patient's front left, the patient's facing direction."""
    w, h = size_px
    img = np.full((h, w, 3), _BACK, np.uint8)
    seat = (int(0.18 * w), int(0.2 * h), int(0.82 * w), int(0.8 * h))
    cv2.rectangle(img, seat[:2], seat[2:], (90, 80, 70), -1)
    cv2.putText(img, "seat, seen from above", (seat[0], seat[1] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, _DIM, 1, cv2.LINE_AA)
    sq_x, sq_y = board.cols + 1, board.rows + 1  # squares of the printed pattern
    cell = min((seat[2] - seat[0]) * 0.8 / sq_x, (seat[3] - seat[1]) * 0.8 / sq_y)
    x0 = (w - cell * sq_x) / 2
    y0 = (seat[1] + seat[3]) / 2 - cell * sq_y / 2
    # Seen from above with the patient's front at the bottom of the picture, the patient's right
    # (+X, the board's x) is on the picture's left and the back (+Z, the board's y) at its top; the
    # square beyond corner 0 (black) is at the patient's front left: the picture's bottom right.
    for ii in range(sq_x):
        for jj in range(sq_y):
            left = x0 + (sq_x - 1 - ii) * cell
            top = y0 + (sq_y - 1 - jj) * cell
            black = (ii + jj) % 2 == 0
            cv2.rectangle(img, (int(left), int(top)), (int(left + cell), int(top + cell)),
                          (25, 25, 25) if black else (225, 225, 225), -1)
    corner = (int(x0 + (sq_x - 1) * cell), int(y0 + (sq_y - 1) * cell))
    cv2.circle(img, corner, 6, _TEAL, -1, cv2.LINE_AA)
    cv2.putText(img, "first corner", (corner[0] - 60, corner[1] + 30), cv2.FONT_HERSHEY_SIMPLEX, 0.45, _TEAL, 1, cv2.LINE_AA)
    cv2.arrowedLine(img, (w // 2, int(0.84 * h)), (w // 2, int(0.97 * h)), _AMBER, 3, cv2.LINE_AA, tipLength=0.35)
    cv2.putText(img, "patient faces this way", (w // 2 + 12, int(0.93 * h)), cv2.FONT_HERSHEY_SIMPLEX, 0.45, _AMBER, 1, cv2.LINE_AA)
    cv2.putText(img, "right", (6, h // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.42, _DIM, 1, cv2.LINE_AA)
    cv2.putText(img, "left", (w - 36, h // 2), cv2.FONT_HERSHEY_SIMPLEX, 0.42, _DIM, 1, cv2.LINE_AA)
    cv2.putText(img, "(the patient's)", (6, h // 2 + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.38, _DIM, 1, cv2.LINE_AA)
    return img
