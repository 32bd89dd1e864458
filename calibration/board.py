"""Checkerboard calibration targets: the board model and corner detection in images.

A :class:`Checkerboard` has ``cols x rows`` inner corners (OpenCV's ``patternSize``) spaced by
``square_m``. Its frame: corner 0 is the origin, x runs along a row of ``cols`` corners, y along a
column of ``rows`` corners, z = x cross y points INTO the printed face (away from a camera that
sees the pattern), so a board lying face up has z pointing down.

Corner order is made canonical, so that every camera labels the same physical corner 0 even when
the views are far apart:

- handedness: the printed face is seen from the front, where the x and y directions of the
  corner grid keep their orientation in the image (x cross y > 0 with image y down); a detection
  that comes out mirrored is flipped row by row;
- the remaining half-turn ambiguity is settled by colour: the outer square diagonally beyond
  corner 0 is black, the one beyond the last corner white. This needs one even and one odd count
  of inner corners (e.g. 9 x 6), which is why boards with both counts even or both odd are refused.

Pure image processing: images in, corner arrays and reasons out; reading files is
:func:`read_gray`, kept separate so that callers report unreadable files per image.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from calibration.errors import CalibrationError


def grid_points(rows: int, cols: int, spacing_m: float) -> np.ndarray:
    """(rows * cols, 3) float64 points of a planar grid in its own frame (z = 0), row by row with
    x fastest: a board's inner corners in corner-id order."""
    j, i = np.mgrid[0:rows, 0:cols]
    pts = np.zeros((rows * cols, 3))
    pts[:, 0] = i.ravel() * spacing_m
    pts[:, 1] = j.ravel() * spacing_m
    return pts


@dataclass(frozen=True, slots=True)
class Checkerboard:
    """A planar checkerboard.

    Attributes:
        cols: inner corners along a row (OpenCV pattern width), >= 3.
        rows: inner corners along a column (OpenCV pattern height), >= 3; ``cols + rows`` odd.
        square_m: side of one square in metres.
    """

    cols: int
    rows: int
    square_m: float

    def __post_init__(self) -> None:
        if self.cols < 3 or self.rows < 3:
            raise CalibrationError(f"board {self.cols}x{self.rows}: give at least 3x3 inner corners, e.g. 9x6")
        if (self.cols + self.rows) % 2 == 0:
            raise CalibrationError(
                f"board {self.cols}x{self.rows}: one count of inner corners must be even and the other odd "
                "(e.g. 9x6), or the board's two ends look alike and cameras may number the corners differently"
            )
        if not (np.isfinite(self.square_m) and 0.001 <= self.square_m <= 1.0):
            raise CalibrationError(f"board square {self.square_m * 1000:g} mm: give the printed square size in mm (1..1000)")

    @classmethod
    def parse(cls, pattern: str, square_mm: float) -> "Checkerboard":
        """From ``"9x6"`` (inner corners) and the square side in millimetres."""
        try:
            cols, rows = (int(v) for v in pattern.lower().split("x"))
        except ValueError:
            raise CalibrationError(f"board {pattern!r}: give the inner corners as COLSxROWS, e.g. 9x6") from None
        return cls(cols, rows, float(square_mm) / 1000.0)

    @property
    def n_corners(self) -> int:
        return self.cols * self.rows

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the printed squares in metres (without a margin)."""
        return ((self.cols + 1) * self.square_m, (self.rows + 1) * self.square_m)

    def object_points(self) -> np.ndarray:
        """(N, 3) float64 corner positions in the board frame, metres, row by row (x fastest)."""
        return grid_points(self.rows, self.cols, self.square_m)

    def is_black(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Whether board-frame points (metres) lie on a black square (False on the white margin).

        Square (i, j) spans corners i..i+1 along x and j..j+1 along y (i from -1 to cols - 1); it is
        black when i + j is even, so the square beyond corner 0, (-1, -1), is black.
        """
        i = np.floor(np.asarray(x_m) / self.square_m)
        j = np.floor(np.asarray(y_m) / self.square_m)
        inside = (i >= -1) & (i <= self.cols - 1) & (j >= -1) & (j <= self.rows - 1)
        return inside & ((i + j) % 2 == 0)


@dataclass(frozen=True, slots=True)
class Detection:
    """The corners of one board found in one image.

    Attributes:
        uv_px: (N, 2) float64 corner positions in (distorted) pixels, canonical board order.
        size_px: (width, height) of the image.
        ids: None when every corner of the board was found (``uv_px`` holds them all, in order);
            else (N,) intp the corner ids (indices into the board's ``object_points()``) of the
            corners found, sorted: a ChArUco board seen in part.
    """

    uv_px: np.ndarray
    size_px: tuple[int, int]
    ids: np.ndarray | None = None

    def object_points(self, board) -> np.ndarray:
        """(N, 3) float64 board-frame positions (metres) of this detection's corners."""
        pts = board.object_points()
        return pts if self.ids is None else pts[self.ids]


def read_gray(path: str | Path) -> tuple[np.ndarray | None, str]:
    """Read an image file as 8-bit grey. Returns (image, "") or (None, reason)."""
    path = Path(path)
    if not path.is_file():
        return None, "no such file"
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        return None, "not an image OpenCV can read"
    return image, ""


def to_gray(image: np.ndarray) -> np.ndarray:
    """(H, W) or (H, W, 3) BGR uint8 -> (H, W) uint8."""
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image


def usable_gray(image: np.ndarray) -> tuple[np.ndarray | None, str]:
    """The 8-bit grey image to look for a board in, or (None, why it cannot hold one)."""
    gray = to_gray(np.asarray(image))
    if gray.dtype != np.uint8 or gray.ndim != 2 or min(gray.shape) < 16:
        return None, f"not an 8-bit image of at least 16x16 pixels (got {gray.dtype} {gray.shape})"
    contrast = float(np.percentile(gray, 99) - np.percentile(gray, 1))
    if contrast < 20:
        return None, f"almost uniform image (contrast {contrast:.0f} of 255): check the exposure and the lens cap"
    return gray, ""


def detect_board(image: np.ndarray, board) -> tuple[Detection | None, str]:
    """Find the board's inner corners in an image, in canonical order.

    Args:
        image: (H, W) grey or (H, W, 3) BGR uint8 image.
        board: the board to look for: a :class:`Checkerboard` (found whole or not at all) or a
            :class:`calibration.charuco.CharucoBoard` (the corners in view, with their ids).
    Returns:
        (detection, "") or (None, reason) with a reason a person can act on.
    """
    if not isinstance(board, Checkerboard):
        return board.detect(image)  # a ChArUco board (calibration.charuco imports this module)
    gray, reason = usable_gray(image)
    if gray is None:
        return None, reason
    corners = _find_corners(gray, board)
    if corners is None:
        return None, f"no {board.cols}x{board.rows} board found: the whole board must be in view, sharp and not too small"
    uv = corners.reshape(board.rows, board.cols, 2).astype(np.float64)
    # Handedness: with the printed face towards the camera, x cross y > 0 in image coordinates.
    dx = uv[0, -1] - uv[0, 0]
    dy = uv[-1, 0] - uv[0, 0]
    if dx[0] * dy[1] - dx[1] * dy[0] < 0:
        uv = uv[:, ::-1]
    # Half turn: the outer square beyond corner 0 is black, the one beyond the last corner white.
    if _outer_square_level(gray, uv, first=True) > _outer_square_level(gray, uv, first=False):
        uv = uv[::-1, ::-1]
    return Detection(uv.reshape(-1, 2).copy(), (gray.shape[1], gray.shape[0])), ""


def _find_corners(gray: np.ndarray, board: Checkerboard) -> np.ndarray | None:
    """(N, 1, 2) float32 corners in OpenCV order, or None.

    The classic detector with sub-pixel refinement first (fast, ~0.06-0.1 px on sharp images);
    the sector-based detector (``findChessboardCornersSB``, slower, more tolerant of blur and
    strong perspective) when it fails. The classic one starts with OpenCV's quick look for a
    board (``CALIB_CB_FAST_CHECK``): without it, an image it cannot read costs its whole search
    (0.12 s per image with OpenCV 4.8) before the sector-based detector runs anyway.
    """
    pattern = (board.cols, board.rows)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    found, corners = cv2.findChessboardCorners(gray, pattern, flags=flags)
    if found and corners is not None and len(corners) == board.n_corners:
        grid = corners.reshape(board.rows, board.cols, 2)
        spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(), np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
        # The search window stays inside the four squares around a corner.
        half = int(np.clip(0.4 * spacing, 2, 11))
        crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
        return cv2.cornerSubPix(gray, corners, (half, half), (-1, -1), crit)
    found, corners = cv2.findChessboardCornersSB(gray, pattern, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if found and corners is not None and len(corners) == board.n_corners:
        return corners
    return None


def _outer_square_level(gray: np.ndarray, uv: np.ndarray, first: bool) -> float:
    """Mean grey level near the centre of the outer square diagonally beyond corner 0 (or the last)."""
    if first:
        corner, inner = uv[0, 0], uv[1, 1]
    else:
        corner, inner = uv[-1, -1], uv[-2, -2]
    centre = corner + 0.5 * (corner - inner)
    r = max(1, int(0.15 * np.linalg.norm(corner - inner)))
    h, w = gray.shape
    x, y = int(round(centre[0])), int(round(centre[1]))
    patch = gray[max(0, y - r) : min(h, y + r + 1), max(0, x - r) : min(w, x + r + 1)]
    return float(patch.mean()) if patch.size else 128.0


def detect_in_files(paths, board) -> tuple[dict[str, Detection], dict[str, str]]:
    """Detect the board in image files.

    Returns:
        detections: file name (as given) -> Detection, for the images where the board was found.
        skipped: file name -> reason, for unreadable images and images without the board.
    """
    detections: dict[str, Detection] = {}
    skipped: dict[str, str] = {}
    for p in paths:
        gray, reason = read_gray(p)
        if gray is not None:
            det, reason = detect_board(gray, board)
            if det is not None:
                detections[str(p)] = det
                continue
        skipped[str(p)] = reason
    return detections, skipped
