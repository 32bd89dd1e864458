"""Intrinsic calibration of one camera from checkerboard or ChArUco corners (OpenCV ``calibrateCamera``).

The result is a :class:`calibration.camera.Camera` with identity extrinsics, the RMS
reprojection error over all corners and per image, and the share of the image that the corners
covered: corners only in the middle leave the lens distortion near the edges unconstrained, so a
poor coverage gives a warning that says where to move the board.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from calibration.board import Detection
from calibration.camera import Camera
from calibration.errors import CalibrationError

log = logging.getLogger(__name__)

MIN_VIEWS = 4
STEADY_VIEWS = 10  # fewer usable images get a warning, and their lens data are not refined by default
COVERAGE_GRID = (8, 6)  # cells across, down
COVERAGE_WARN = 0.7


@dataclass(frozen=True, slots=True)
class IntrinsicsResult:
    """One camera's intrinsic calibration.

    Attributes:
        camera: intrinsics (extrinsics identity).
        rms_px: RMS reprojection error over all corners, pixels.
        per_view_rms_px: (V,) RMS per used view, same order as the detections given.
        coverage: fraction 0..1 of the cells of an 8 x 6 grid over the image that hold a corner.
        warnings: one-line warnings (poor coverage, few views, a view with a large error).
        information: (P, P) information matrix (inverse covariance) of the lens parameters
            fx, fy, cx, cy and the distortion coefficients, in the order of ``camera.dist``
            (:func:`lens_information`); None when not computed. A later step that refines the
            lens (the rig's bundle adjustment) uses it as the weight of this step's estimate.
    """

    camera: Camera
    rms_px: float
    per_view_rms_px: np.ndarray
    coverage: float
    warnings: tuple[str, ...]
    information: np.ndarray | None = None


def coverage_of(detections: Sequence[Detection], size_px: tuple[int, int], grid: tuple[int, int] = COVERAGE_GRID) -> tuple[float, np.ndarray]:
    """Share of the image's grid cells that hold at least one corner.

    Returns:
        fraction: 0..1.
        hit: (rows, cols) bool, the cells with a corner.
    """
    gx, gy = grid
    w, h = size_px
    hit = np.zeros((gy, gx), bool)
    for det in detections:
        cx = np.clip((det.uv_px[:, 0] + 0.5) * gx / w, 0, gx - 1).astype(int)
        cy = np.clip((det.uv_px[:, 1] + 0.5) * gy / h, 0, gy - 1).astype(int)
        hit[cy, cx] = True
    return float(hit.mean()), hit


def empty_regions(hit: np.ndarray) -> str:
    """Which image regions (corners, edges, centre in a 3 x 3 split) hold no corner, in words."""
    gy, gx = hit.shape
    names = (("top-left", "top", "top-right"), ("left", "centre", "right"), ("bottom-left", "bottom", "bottom-right"))
    ys = np.array_split(np.arange(gy), 3)
    xs = np.array_split(np.arange(gx), 3)
    empty = [names[i][j] for i in range(3) for j in range(3) if not hit[np.ix_(ys[i], xs[j])].any()]
    return ", ".join(empty)


def coverage_warning(name: str, coverage: float, hit: np.ndarray) -> str:
    """The warning for corners covering too little of the picture, naming the empty regions."""
    empty = empty_regions(hit)
    where = f" (none in the {empty})" if empty else " (gaps in every part of it)"
    return (f"{name}: corners cover only {100 * coverage:.0f} % of the image{where}: "
            "add images with the board near the edges and corners of the picture")


def calibrate_intrinsics(
    name: str,
    detections: Sequence[Detection],
    board,
    *,
    fix_k3: bool = True,
    view_names: Sequence[str] | None = None,
) -> IntrinsicsResult:
    """Calibrate one camera from board detections in its images.

    Args:
        name: the camera's name.
        detections: corners of the board in >= 4 images of this camera, all of one size (a
            ChArUco detection may hold only part of the board's corners).
        board: the board (:class:`Checkerboard` or :class:`calibration.charuco.CharucoBoard`).
        fix_k3: keep k3 at 0 (the 4-coefficient model k1, k2, p1, p2; enough for the usual
            lenses and safer with few views); False also fits k3.
        view_names: a name per detection (e.g. its file name) for the warnings.
    Raises:
        CalibrationError: too few views or images of different sizes.
    """
    if len(detections) < MIN_VIEWS:
        raise CalibrationError(
            f"{name}: the board was found in {len(detections)} images; take at least {MIN_VIEWS} "
            "(15-25 is better) with the board in different places and tilts"
        )
    sizes = {d.size_px for d in detections}
    if len(sizes) != 1:
        raise CalibrationError(f"{name}: the images have different sizes {sorted(sizes)}: use one camera setting")
    size = sizes.pop()
    object_points = [d.object_points(board).astype(np.float32) for d in detections]
    image_points = [d.uv_px.astype(np.float32).reshape(-1, 1, 2) for d in detections]
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(object_points, image_points, size, None, None, flags=flags, criteria=crit)
    dist = dist.reshape(-1)[:5]
    if fix_k3:
        dist = dist[:4]
    cam = Camera(name, size, K, dist, np.zeros(3), np.zeros(3))
    per_view = np.empty(len(detections))
    for k, (det, obj, rvec, tvec) in enumerate(zip(detections, object_points, rvecs, tvecs)):
        proj, _ = cv2.projectPoints(obj.astype(np.float64), rvec, tvec, K, dist)
        per_view[k] = np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - det.uv_px) ** 2, axis=1)))
    info = lens_information(object_points, image_points, rvecs, tvecs, K, dist, float(rms))
    coverage, hit = coverage_of(detections, size)
    warnings = []
    if coverage < COVERAGE_WARN:
        warnings.append(coverage_warning(name, coverage, hit))
    if len(detections) < STEADY_VIEWS:
        warnings.append(f"{name}: only {len(detections)} usable images: 15-25 give a steadier result")
    worst = int(np.argmax(per_view))
    if per_view[worst] > max(1.0, 3.0 * float(rms)):
        which = view_names[worst] if view_names is not None else f"image {worst + 1} of the used ones"
        warnings.append(
            f"{name}: {which} fits badly ({per_view[worst]:.2f} px): it may be blurred; remove it and calibrate again"
        )
    for w in warnings:  # returned for the caller to show; logged for the record
        log.info(w)
    return IntrinsicsResult(cam, float(rms), per_view, coverage, tuple(warnings), info)


def lens_information(object_points, image_points, rvecs, tvecs, K: np.ndarray, dist: np.ndarray, rms_px: float) -> np.ndarray:
    """Information matrix of fx, fy, cx, cy and the distortion coefficients from a lens calibration.

    The Gauss-Newton normal matrix of the calibration's reprojection residuals with every view's
    pose eliminated (Schur complement), divided by the residual variance: the inverse of the
    estimate's covariance, correlations included (the focal lengths with the radial distortion,
    the principal point with the tangential one). ``cv2.projectPoints`` gives the derivatives.
    """
    n_par = 4 + dist.size
    info = np.zeros((n_par, n_par))
    for obj, rvec, tvec in zip(object_points, rvecs, tvecs):
        _, jac = cv2.projectPoints(np.asarray(obj, np.float64), rvec, tvec, K, dist)
        B, A = jac[:, :6], jac[:, 6 : 6 + n_par]  # the view's pose, the lens
        BtB = B.T @ B
        BtA = B.T @ A
        info += A.T @ A - BtA.T @ np.linalg.solve(BtB, BtA)
    sigma2 = max(rms_px, 0.05) ** 2 / 2.0  # rms is over both coordinates of a corner; floor: no infinite weight
    return info / sigma2


def steady_lens_information(information, n_views) -> list[np.ndarray | None]:
    """The information matrices of the lenses whose lens step used ``STEADY_VIEWS`` images or more,
    None for the others (and where either is unknown): the lens data the positions step refines by
    default.

    Measured (docs/CALIBRATION.md, "Lens data refined with the positions"): the information matrix is
    the real weight of a lens step's estimate (the actual errors of 24 ChArUco lens steps of 20
    images against the truth give a mean Mahalanobis distance squared of 8.0 for 8 parameters), and
    with it the refinement is a small correction. From six small images the prior is weak
    (focal length 0.16-0.30 % standard deviation) and the few held views then decide the lens,
    which made a rig 5.8 -> 9.2 mm worse; so such lens data are kept as they are.
    """
    if information is None or n_views is None:
        return [None] * (0 if information is None else len(information))
    return [i if i is not None and n is not None and n >= STEADY_VIEWS else None for i, n in zip(information, n_views)]
