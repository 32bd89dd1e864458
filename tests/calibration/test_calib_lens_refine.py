"""Lens data refined in the positions step, weighted by how exact the lens step found them.

The lens step's information matrix against OpenCV's own standard deviations; the board
adjustment with the lens prior on a synthetic rig with known truth (the lens data from a lens
calibration on noisy corners, so their error is the kind a lens step leaves); the file
section round trip and its refusals; the calibration scene's reuse of lens data by name.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.board import Checkerboard, Detection
from calibration.camera import Camera, rotation_from_rvec
from calibration.errors import CalibrationError, RehabError
from calibration.extrinsics import calibrate_extrinsics, rig_errors
from calibration.files import (load_calibration, read_lens_information, read_lens_views, save_calibration_toml,
                               write_lens_information)
from calibration.intrinsics import calibrate_intrinsics, steady_lens_information
from tracking.sim.calibration_material import extrinsics_poses, seat_board_pose
from tracking.sim.renderer import DEMO_LENS
from tracking.sim.rigs import load_rig

BOARD = Checkerboard(9, 6, 0.06)


def _truth(rig="tri3"):
    return [Camera(c.name, c.size_px, c.K, DEMO_LENS, c.rvec, c.t_m) for c in load_rig(rig, (640, 480))]


def _lens_step(cam, rng, n_views=12, noise_px=0.25):
    """A lens calibration from noisy corners of the board held 0.8-1.6 m in front of the camera."""
    obj = BOARD.object_points()
    alone = Camera(cam.name, cam.size_px, cam.K, cam.dist, np.zeros(3), np.zeros(3))
    dets = []
    while len(dets) < n_views:
        R = rotation_from_rvec(rng.normal(0, 0.35, 3))
        t = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2), rng.uniform(0.8, 1.6)])
        uv = alone.project((obj - obj.mean(0)) @ R.T + t)
        if np.all((uv > 5) & (uv < np.array(cam.size_px) - 5)):
            dets.append(Detection(uv + rng.normal(0, noise_px, uv.shape), cam.size_px))
    return calibrate_intrinsics(cam.name, dets, BOARD)


def _shape_error_mm(cams, truth):
    """Camera centres after the best rigid fit to the truth (the rig's shape, not its world frame)."""
    A = np.array([c.centre_m for c in cams])
    B = np.array([c.centre_m for c in truth])
    a0, b0 = A.mean(0), B.mean(0)
    U, _, Vt = np.linalg.svd((A - a0).T @ (B - b0))
    R = (U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt).T
    return 1000 * np.linalg.norm((A - a0) @ R.T + b0 - B, axis=1)


def test_lens_information_agrees_with_opencv_standard_deviations():
    import cv2

    cam = _truth()[0]
    rng = np.random.default_rng(3)
    res = _lens_step(cam, rng)
    assert res.information.shape == (8, 8)
    assert np.allclose(res.information, res.information.T, rtol=1e-9, atol=0)
    assert np.all(np.linalg.eigvalsh(res.information) > 0)
    # the same views through calibrateCameraExtended: its standard deviations of fx, fy, cx, cy
    rng = np.random.default_rng(3)
    obj = BOARD.object_points()
    alone = Camera(cam.name, cam.size_px, cam.K, cam.dist, np.zeros(3), np.zeros(3))
    pts_o, pts_i = [], []
    while len(pts_o) < 12:
        R = rotation_from_rvec(rng.normal(0, 0.35, 3))
        t = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2), rng.uniform(0.8, 1.6)])
        uv = alone.project((obj - obj.mean(0)) @ R.T + t)
        if np.all((uv > 5) & (uv < np.array(cam.size_px) - 5)):
            pts_o.append(obj.astype(np.float32))
            pts_i.append((uv + rng.normal(0, 0.25, uv.shape)).astype(np.float32).reshape(-1, 1, 2))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    out = cv2.calibrateCameraExtended(pts_o, pts_i, cam.size_px, None, None, flags=cv2.CALIB_FIX_K3, criteria=crit)
    std_cv = out[5].ravel()[:4]
    std_ours = np.sqrt(np.diag(np.linalg.inv(res.information)))[:4]
    assert np.allclose(std_ours, std_cv, rtol=0.05), (std_ours, std_cv)


def test_board_extrinsics_refine_the_lens_data_and_keep_them_without_information():
    """ring4 with held views and the seat board (exact corners + 0.15 px): the lens prior moves the
    lens data towards the truth; cameras without information keep theirs exactly."""
    truth = [Camera(c.name, c.size_px, c.K, DEMO_LENS, c.rvec, c.t_m) for c in load_rig("ring4", (640, 480))]
    rng = np.random.default_rng(5)
    steps = [_lens_step(c, rng, n_views=10, noise_px=0.3) for c in truth]
    lenses = [r.camera for r in steps]
    poses = [*extrinsics_poses(truth, BOARD, 4, np.random.default_rng(6)), seat_board_pose(BOARD)]
    names = [f"{k:03d}" for k in range(len(poses) - 1)] + ["seat"]
    obj = BOARD.object_points()
    views = {}
    for name, pose in zip(names, poses):
        row = []
        for cam in truth:
            uv = cam.project(obj @ pose.R.T + pose.t_m)
            w, h = cam.size_px
            inside = np.all(np.isfinite(uv)) and uv.min() > 0 and uv[:, 0].max() < w - 1 and uv[:, 1].max() < h - 1
            front = float((cam.R @ pose.R)[:, 2] @ (cam.R @ pose.t_m + cam.t_m)) > 0
            row.append(Detection(uv + rng.normal(0, 0.15, uv.shape), cam.size_px) if inside and front else None)
        views[name] = row
    origin = tuple(poses[-1].t_m)
    a = calibrate_extrinsics(lenses, BOARD, views, floor_view="seat", origin_m=origin)
    info = [r.information for r in steps]
    info[1] = None
    b = calibrate_extrinsics(lenses, BOARD, views, floor_view="seat", origin_m=origin, lens_information=info)
    assert np.array_equal(b.cameras[1].K, lenses[1].K) and np.array_equal(b.cameras[1].dist, lenses[1].dist)
    moved = [c for c in (0, 2, 3) if not np.array_equal(b.cameras[c].K, lenses[c].K)]
    assert moved == [0, 2, 3]
    pa, _ = rig_errors(a.cameras, truth)
    pb, ab = rig_errors(b.cameras, truth)
    assert pb.mean() < pa.mean(), (pa, pb)
    with pytest.raises(CalibrationError, match="lens information"):
        calibrate_extrinsics(lenses, BOARD, views, floor_view="seat", origin_m=origin, lens_information=[np.eye(5)] * 4)


def test_lens_information_round_trips_through_the_calibration_file(tmp_path):
    truth = _truth()
    rng = np.random.default_rng(1)
    steps = [_lens_step(c, rng, n_views=6) for c in truth[:2]]
    path = tmp_path / "intrinsics.toml"
    save_calibration_toml(path, [r.camera for r in steps])
    assert read_lens_information(path, load_calibration(path)) == [None, None]   # a file without the section
    write_lens_information(path, {steps[0].camera.name: steps[0].information}, views={steps[0].camera.name: 6})
    cams = load_calibration(path)   # the cameras read as before
    back = read_lens_information(path, cams)
    assert back[1] is None
    assert np.allclose(back[0], steps[0].information, rtol=1e-12)
    assert read_lens_views(path, cams) == [6, None]
    # refined by default only from steady lens steps (10 images or more); unknown counts: not by default
    assert steady_lens_information(back, [6, None]) == [None, None]
    kept = steady_lens_information([back[0], back[0], None], [10, 9, 12])
    assert kept[0] is back[0] and kept[1] is None and kept[2] is None
    text = path.read_text().replace("[metadata.lens_information]", "[metadata.lens_information]\ncam2 = [[1.0, 2.0], [2.0, 1.0]]")
    path.write_text(text)
    with pytest.raises(CalibrationError, match=r"'cam2' must be 8x8 numbers") as exc:
        read_lens_information(path, load_calibration(path))
    assert "\n" not in str(exc.value)


class _Feed:
    def __init__(self, name, size_px):
        self.name, self.size_px = name, size_px


def test_the_scene_reuses_lens_data_by_camera_name(tmp_path):
    from game.scenes.calibrate import lenses_for_feeds

    truth = _truth()
    path = tmp_path / "lenses.toml"
    save_calibration_toml(path, truth)
    cams = lenses_for_feeds(path, [_Feed("cam2", (640, 480)), _Feed("cam1", (320, 240))])
    assert [c.name for c in cams] == ["cam2", "cam1"]
    assert np.array_equal(cams[0].K, truth[1].K)
    assert cams[1].size_px == (320, 240) and np.isclose(cams[1].K[0, 0], truth[0].K[0, 0] / 2)
    with pytest.raises(RehabError, match="no lens data for cam9"):
        lenses_for_feeds(path, [_Feed("cam9", (640, 480))])
    with pytest.raises(RehabError, match="are for 640x480 pictures, the camera gives 640x360"):
        lenses_for_feeds(path, [_Feed("cam1", (640, 360))])
