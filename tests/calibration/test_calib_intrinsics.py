"""Intrinsic calibration on simulated board images: accuracy against the true lens, coverage warnings."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.board import Checkerboard, Detection, detect_board
from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.intrinsics import calibrate_intrinsics, coverage_of
from tracking.sim.calibration_material import render_intrinsics_images

BOARD = Checkerboard(9, 6, 0.04)
LENS = (-0.12, 0.03, 0.0005, -0.0004)


@pytest.fixture(scope="module")
def truth_and_detections():
    truth = Camera.look_at("cam1", (480, 360), 492.0, (0.5, 1.6, -2.0), (0.0, 1.0, 0.0), dist=LENS)
    rows = np.linspace(70, 150, 360)[:, None, None]
    background = np.broadcast_to(rows + np.linspace(0, 30, 480)[None, :, None], (360, 480, 3)).astype(np.uint8)
    images, _ = render_intrinsics_images(truth, background, BOARD, 12, seed=3, noise_sigma=1.5)
    detections = [d for d, _ in (detect_board(im, BOARD) for im in images) if d is not None]
    return truth, detections


def test_intrinsics_from_simulated_board_images_match_the_true_lens(truth_and_detections):
    truth, detections = truth_and_detections
    assert len(detections) >= 11
    res = calibrate_intrinsics("cam1", detections, BOARD)
    K, K0 = res.camera.K, truth.K
    assert abs(K[0, 0] / K0[0, 0] - 1) < 0.005 and abs(K[1, 1] / K0[1, 1] - 1) < 0.005  # focal within 0.5 %
    assert np.abs(K[:2, 2] - K0[:2, 2]).max() < 2.0
    assert res.rms_px < 0.3
    assert res.per_view_rms_px.shape == (len(detections),) and res.per_view_rms_px.max() < 0.3
    # The lens distortion as a displacement field (pixels moved by the lens): within 0.3 px everywhere.
    u, v = np.meshgrid(np.linspace(5, 474, 12), np.linspace(5, 354, 9))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    xn = truth.undistort_points(uv)

    def lens_shift(cam: Camera) -> np.ndarray:
        return cam.distort_normalized(xn) - (xn @ cam.K[:2, :2].T + cam.K[:2, 2])

    assert np.abs(lens_shift(res.camera) - lens_shift(truth)).max() < 0.3
    assert res.coverage > 0.7 and not any("cover" in w for w in res.warnings)
    assert res.camera.size_px == (480, 360) and np.allclose(res.camera.t_m, 0)


def test_corners_only_in_the_middle_give_a_coverage_warning(truth_and_detections):
    _, detections = truth_and_detections
    centre = np.array([240.0, 180.0])
    squeezed = [Detection(centre + 0.3 * (d.uv_px - centre), d.size_px) for d in detections]
    frac, hit = coverage_of(squeezed, (480, 360))
    assert frac < 0.5 and hit[3, 4] and not hit[0, 0]
    res = calibrate_intrinsics("cam1", squeezed, BOARD)
    (warning,) = [w for w in res.warnings if "cover" in w]
    assert "top-left" in warning and "bottom-right" in warning and "corners of the picture" in warning


def test_sparse_corners_everywhere_give_a_coverage_warning_that_reads_well():
    """Every ninth of the picture holds a corner but most cells none: no empty list of regions."""
    from calibration.intrinsics import coverage_warning

    dots = np.array([[x, y] for x in (20, 240, 460) for y in (15, 180, 345)], float)
    frac, hit = coverage_of([Detection(dots, (480, 360))], (480, 360))
    assert frac < 0.3
    text = coverage_warning("cam1", frac, hit)
    assert "(gaps in every part of it)" in text and "none in the" not in text
    hit[:2, :3] = False
    assert "(none in the top-left)" in coverage_warning("cam1", frac, hit)


def test_too_few_views_or_mixed_sizes_are_refused(truth_and_detections):
    _, detections = truth_and_detections
    with pytest.raises(CalibrationError, match="found in 3 images"):
        calibrate_intrinsics("cam1", detections[:3], BOARD)
    other = Detection(detections[0].uv_px, (640, 480))
    with pytest.raises(CalibrationError, match="different sizes"):
        calibrate_intrinsics("cam1", [*detections[:4], other], BOARD)
