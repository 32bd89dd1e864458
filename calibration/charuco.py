"""ChArUco calibration boards: a checkerboard with ArUco markers in its white squares.

Each marker names the corners around it, so a board that is only partly in the picture (or
partly hidden) still gives the corners it shows, each with its id; a plain checkerboard must be
seen whole. This lets views reach into the corners of the picture, where lens distortion is
strongest and a whole board rarely fits.

The board frame is the :class:`calibration.board.Checkerboard`'s: corner 0 (the first inner
corner, OpenCV's ChArUco corner id 0) is the origin, x runs along a row of ``cols = squares_x - 1``
inner corners, y down the columns, z into the printed face; corner ids count row by row (x
fastest), so ``object_points()[ids]`` are the positions of detected corners. OpenCV's own board
frame has its origin at the outer corner of the first square; the two differ by one square in
x and y. The square beyond corner 0 is black (OpenCV's layout), as on the project's checkerboards.

Detection uses OpenCV's ``cv2.aruco.CharucoDetector`` with its default of two markers per
corner: a chessboard corner is interpolated only when the markers on both sides of it are found
(with one allowed, corners of small, tilted boards came out 1.5-2.5 px off and the rig 5-8 mm off
on the simulator, docs/CALIBRATION.md), and markers missed at first are looked for again where
the board's layout puts them (``tryRefineMarkers``), which finds the board lying on the seat.
On simulated boards the corners come out 0.12-0.13 px RMS from the truth close to a camera and
0.13-0.18 px from 2 m (a checkerboard's: ~0.06-0.1 px): the markers in the white squares pull the
sub-pixel refinement a little.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from calibration.board import Detection, grid_points, usable_gray
from calibration.errors import CalibrationError

log = logging.getLogger(__name__)

#: OpenCV before 5 interpolates ChArUco corners less exactly: on the simulated boards 0.66 px RMS
#: from the true corners with OpenCV 4.8-4.10 against 0.14-0.28 px with OpenCV 5 (docs/CALIBRATION.md).
PRECISE_CHARUCO_OPENCV = 5

MIN_CORNERS = 6  # fewer corners in one view constrain a camera too weakly (and may be collinear)
TEXTURE_PX_PER_SQUARE = 120  # marker bit edges placed to 1/120 of a square in the simulator's drawing


@dataclass(frozen=True, slots=True)
class CharucoBoard:
    """A ChArUco board.

    Attributes:
        squares_x: squares along a row (>= 3).
        squares_y: squares along a column (>= 3).
        square_m: side of one square in metres.
        marker_m: side of one ArUco marker in metres (smaller than the square).
        dictionary: OpenCV predefined dictionary name, e.g. ``"DICT_4X4_50"``; it must hold at
            least one marker per white square.
    """

    squares_x: int
    squares_y: int
    square_m: float
    marker_m: float
    dictionary: str = "DICT_4X4_50"

    def __post_init__(self) -> None:
        if self.squares_x < 3 or self.squares_y < 3:
            raise CalibrationError(f"ChArUco board {self.squares_x}x{self.squares_y}: give at least 3x3 squares, e.g. 10x7")
        if not (np.isfinite(self.square_m) and 0.001 <= self.square_m <= 1.0):
            raise CalibrationError(f"ChArUco square {self.square_m * 1000:g} mm: give the printed square size in mm (1..1000)")
        if not (np.isfinite(self.marker_m) and 0.2 * self.square_m <= self.marker_m < self.square_m):
            raise CalibrationError(
                f"ChArUco marker {self.marker_m * 1000:g} mm with {self.square_m * 1000:g} mm squares: the marker must be "
                "smaller than the square (typically 0.7-0.8 of it); measure the printed black marker's side"
            )
        names = [n for n in dir(cv2.aruco) if n.startswith("DICT_")]
        if self.dictionary not in names:
            raise CalibrationError(f"ChArUco dictionary {self.dictionary!r} unknown: use one of OpenCV's, e.g. DICT_4X4_50, DICT_5X5_100")
        n_markers = (self.squares_x * self.squares_y) // 2
        size = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary)).bytesList.shape[0]
        if size < n_markers:
            raise CalibrationError(f"ChArUco board {self.squares_x}x{self.squares_y} needs {n_markers} markers but "
                                   f"{self.dictionary} has {size}: use a larger dictionary")

    @classmethod
    def parse(cls, squares: str, square_mm: float, marker_mm: float | None = None,
              dictionary: str = "DICT_4X4_50") -> "CharucoBoard":
        """From ``"10x7"`` (squares, not inner corners), the square and marker sides in millimetres.

        The marker side defaults to 0.75 of the square (OpenCV's usual proportion).
        """
        try:
            sx, sy = (int(v) for v in squares.lower().split("x"))
        except ValueError:
            raise CalibrationError(f"ChArUco squares {squares!r}: give the squares as COLSxROWS, e.g. 10x7") from None
        marker = 0.75 * float(square_mm) if marker_mm is None else float(marker_mm)
        return cls(sx, sy, float(square_mm) / 1000.0, marker / 1000.0, dictionary.upper())

    @property
    def cols(self) -> int:
        """Inner corners along a row."""
        return self.squares_x - 1

    @property
    def rows(self) -> int:
        """Inner corners along a column."""
        return self.squares_y - 1

    @property
    def n_corners(self) -> int:
        return self.cols * self.rows

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the printed squares in metres (without a margin)."""
        return (self.squares_x * self.square_m, self.squares_y * self.square_m)

    def object_points(self) -> np.ndarray:
        """(N, 3) float64 corner positions in the board frame, metres, in corner-id order."""
        return grid_points(self.rows, self.cols, self.square_m)

    def is_black(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Whether board-frame points (metres) lie on black print (False on the white margin).

        The chessboard squares are exact (their corners are what calibration measures); the
        marker bits come from OpenCV's drawing of the board, sampled at
        ``TEXTURE_PX_PER_SQUARE`` pixels per square.
        """
        x_m = np.asarray(x_m, np.float64)
        y_m = np.asarray(y_m, np.float64)
        i = np.floor(x_m / self.square_m)
        j = np.floor(y_m / self.square_m)
        inside = (i >= -1) & (i <= self.cols - 1) & (j >= -1) & (j <= self.rows - 1)
        square_black = (i + j) % 2 == 0
        tex = _texture(self)
        s = TEXTURE_PX_PER_SQUARE / self.square_m
        with np.errstate(invalid="ignore"):
            u = np.clip(np.floor((x_m + self.square_m) * s), 0, tex.shape[1] - 1)
            v = np.clip(np.floor((y_m + self.square_m) * s), 0, tex.shape[0] - 1)
        u = np.nan_to_num(u).astype(np.intp)
        v = np.nan_to_num(v).astype(np.intp)
        return inside & (square_black | tex[v, u])

    def cv_board(self) -> "cv2.aruco.CharucoBoard":
        """OpenCV's board object (cached)."""
        return _cv_board(self.squares_x, self.squares_y, self.square_m, self.marker_m, self.dictionary)

    def image(self, px_per_square: int = 100, margin_px: int = 0) -> np.ndarray:
        """(H, W) uint8 image of the board for printing (black 0, white 255)."""
        w = self.squares_x * px_per_square + 2 * margin_px
        h = self.squares_y * px_per_square + 2 * margin_px
        return self.cv_board().generateImage((w, h), marginSize=margin_px, borderBits=1)

    def detect(self, image: np.ndarray) -> tuple[Detection | None, str]:
        """The corners of this board in ``image`` (:func:`detect_charuco`; what
        :func:`calibration.board.detect_board` calls for a ChArUco board)."""
        return detect_charuco(image, self)


@lru_cache(maxsize=8)
def _cv_board(sx: int, sy: int, square_m: float, marker_m: float, dictionary: str):
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    return cv2.aruco.CharucoBoard((sx, sy), square_m, marker_m, d)


@lru_cache(maxsize=8)
def _texture(board: CharucoBoard) -> np.ndarray:
    """(H, W) bool: black print of the whole board at TEXTURE_PX_PER_SQUARE pixels per square."""
    return board.image(TEXTURE_PX_PER_SQUARE) < 128


def opencv_major() -> int:
    """The installed OpenCV's major version."""
    return int(cv2.__version__.split(".", 1)[0])


@lru_cache(maxsize=8)
def _detector(board: CharucoBoard) -> "cv2.aruco.CharucoDetector":
    if opencv_major() < PRECISE_CHARUCO_OPENCV:
        log.warning("OpenCV %s places ChArUco corners about 0.6 px off (OpenCV %d: about 0.2 px): for a precise "
                    "calibration install opencv-python-headless>=%d.0 (the README's lock file has it) or use a "
                    "checkerboard", cv2.__version__, PRECISE_CHARUCO_OPENCV, PRECISE_CHARUCO_OPENCV)
    params = cv2.aruco.CharucoParameters()
    params.minMarkers = 2  # OpenCV's default: a corner needs both neighbouring markers (1 lets in corners 1-3 px off)
    params.tryRefineMarkers = True  # look again for markers the board's layout predicts (small, oblique boards)
    det_params = cv2.aruco.DetectorParameters()
    det_params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE  # the ChArUco corners are refined, not the markers
    return cv2.aruco.CharucoDetector(board.cv_board(), params, det_params)


def detect_charuco(image: np.ndarray, board: CharucoBoard) -> tuple[Detection | None, str]:
    """Find the board's corners in an image; a board partly out of view gives the corners it shows.

    Args:
        image: (H, W) grey or (H, W, 3) BGR uint8 image.
        board: the board to look for.
    Returns:
        (detection, "") with ``ids`` (M,) sorted corner ids and ``uv_px`` (M, 2) float64 their
        (distorted) pixel positions, or (None, reason) with a reason a person can act on.
    """
    gray, reason = usable_gray(image)
    if gray is None:
        return None, reason
    corners, ids, _, marker_ids = _detector(board).detectBoard(gray)
    if marker_ids is None or len(marker_ids) == 0:
        return None, f"no {board.dictionary} markers found: check the board settings (--squares, --dictionary) and focus"
    n = 0 if ids is None else len(ids)
    if n < MIN_CORNERS:
        return None, f"only {n} ChArUco corners found (need {MIN_CORNERS}): show more of the board"
    ids = ids.reshape(-1).astype(np.intp)
    uv = corners.reshape(-1, 2).astype(np.float64)
    if board.cv_board().checkCharucoCornersCollinear(ids.reshape(-1, 1).astype(np.int32)):
        return None, "the ChArUco corners found lie on one line: show more rows of the board"
    order = np.argsort(ids)
    return Detection(uv[order], (gray.shape[1], gray.shape[0]), ids[order]), ""
