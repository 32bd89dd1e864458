"""Checkerboard model and detection: errors -> canonical corner order -> accuracy -> bad images skipped."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.board import Checkerboard, detect_board, detect_in_files
from calibration.camera import Camera, rotation_from_rvec
from calibration.errors import CalibrationError
from tracking.sim.calibration_material import BoardPose, BoardRaycaster

BOARD = Checkerboard(9, 6, 0.03)


def _camera() -> Camera:
    return Camera.look_at("cam1", (480, 360), 450.0, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), up=(0.0, -1.0, 0.0),
                          dist=(-0.1, 0.02, 0.0, 0.0))


def _pose_facing(cam: Camera, roll_rad: float, tilt=(0.0, 0.0), depth_m: float = 0.6) -> BoardPose:
    """The board centred on the optical axis, turned in its plane by ``roll_rad`` and tilted."""
    bw, bh = 8 * BOARD.square_m, 5 * BOARD.square_m
    R_cb = rotation_from_rvec(np.array([tilt[0], tilt[1], 0.0])) @ rotation_from_rvec(np.array([0.0, 0.0, roll_rad]))
    t_cb = np.array([0.0, 0.0, depth_m]) - R_cb @ np.array([bw / 2, bh / 2, 0.0])
    return BoardPose(cam.R.T @ R_cb, cam.R.T @ (t_cb - cam.t_m))


@pytest.fixture(scope="module")
def caster() -> BoardRaycaster:
    return BoardRaycaster(_camera(), BOARD, supersample=3)


def test_board_needs_one_even_and_one_odd_count():
    with pytest.raises(CalibrationError, match="even and the other odd"):
        Checkerboard(8, 6, 0.03)
    with pytest.raises(CalibrationError, match="COLSxROWS"):
        Checkerboard.parse("nine by six", 25)
    with pytest.raises(CalibrationError, match="square"):
        Checkerboard.parse("9x6", 0.0)
    b = Checkerboard.parse("9x6", 25)
    assert (b.cols, b.rows, b.square_m) == (9, 6, 0.025)
    pts = b.object_points()
    assert pts.shape == (54, 3) and np.allclose(pts[1], [0.025, 0, 0]) and np.allclose(pts[9], [0, 0.025, 0])


@pytest.mark.parametrize("roll_deg", [0.0, 90.0, 180.0, 270.0, 200.0])
@pytest.mark.parametrize("tilt", [(0.0, 0.0), (0.5, -0.4)])
def test_detection_numbers_the_same_physical_corners_whatever_the_view(caster, roll_deg, tilt):
    cam = caster.camera
    pose = _pose_facing(cam, np.radians(roll_deg), tilt)
    image = caster.draw(np.full((360, 480, 3), 110, np.uint8), pose)
    det, reason = detect_board(image, BOARD)
    assert det is not None, reason
    truth = caster.corners_px(pose)
    err = np.linalg.norm(det.uv_px - truth, axis=1)
    assert err.max() < 0.35, err.max()  # canonical order: corner k is the true corner k
    assert np.sqrt(np.mean(err**2)) < 0.15


def test_unreadable_and_boardless_images_are_skipped_with_a_reason(caster, tmp_path):
    cam = caster.camera
    good = caster.draw(np.full((360, 480, 3), 110, np.uint8), _pose_facing(cam, 0.3))
    cv2.imwrite(str(tmp_path / "good.png"), good)
    cv2.imwrite(str(tmp_path / "blank.png"), np.full((360, 480), 128, np.uint8))
    half = good.copy()
    half[:, 240:] = 110  # the board cut in half
    cv2.imwrite(str(tmp_path / "half.png"), half)
    (tmp_path / "broken.png").write_bytes(b"not a png at all")
    files = [tmp_path / n for n in ("good.png", "blank.png", "half.png", "broken.png", "missing.png")]
    detections, skipped = detect_in_files(files, BOARD)
    assert list(detections) == [str(tmp_path / "good.png")]
    assert "uniform" in skipped[str(tmp_path / "blank.png")]
    assert "no 9x6 board found" in skipped[str(tmp_path / "half.png")]
    assert "not an image" in skipped[str(tmp_path / "broken.png")]
    assert "no such file" in skipped[str(tmp_path / "missing.png")]
