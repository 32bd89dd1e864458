"""Wand calibration: exact centroids -> errors -> a rendered 4-camera rig (wand length RMSE < 1 mm)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.wand import calibrate_wand, triangulate
from tracking.sim.calibration_material import WAND_COLOURS_RGB255, render_wand, wand_path
from tracking.sim.rigs import load_rig


def _intrinsics_only(cams):
    return [Camera(c.name, c.size_px, c.K, c.dist, np.zeros(3), np.zeros(3)) for c in cams]


def _in_reference_frame(cams, ref):
    """The true rig expressed in camera ``ref``'s frame (the frame the wand solver returns)."""
    R0, t0 = cams[ref].R, cams[ref].t_m
    return [Camera.from_rotation(c.name, c.size_px, c.K, c.dist, c.R @ R0.T, c.t_m - c.R @ R0.T @ t0) for c in cams]


def _projected(cams, balls, noise_px, seed=0):
    rng = np.random.default_rng(seed)
    uv = np.stack([np.stack([c.project(balls[:, k]) for k in range(2)], axis=1) for c in cams])
    return uv + rng.normal(0.0, noise_px, uv.shape)


def test_triangulate_is_exact_and_marks_points_seen_once():
    cams = load_rig("ring4", (320, 240))
    pts = np.array([[0.1, 1.0, 0.05], [-0.2, 0.8, 0.1]])
    xn = np.stack([c.undistort_points(c.project(pts)) for c in cams])
    xn[1:, 1] = np.nan  # the second point only in camera 0
    out = triangulate([c.R for c in cams], [c.t_m for c in cams], xn)
    assert np.allclose(out[0], pts[0], atol=1e-9) and np.all(np.isnan(out[1]))


def test_exact_centroids_give_the_rig_and_the_wand_length():
    cams = load_rig("ring4", (640, 480))
    balls = wand_path(120, 10.0, seed=2)
    res = calibrate_wand(_intrinsics_only(cams), _projected(cams, balls, 0.05), 0.5)
    truth = _in_reference_frame(cams, res.reference)
    for a, b in zip(res.cameras, truth):
        assert np.linalg.norm(a.centre_m - b.centre_m) < 2e-3
        assert np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1, 1))) < 0.05
    assert res.length_rmse_mm < 0.3 and res.rms_px.max() < 0.1 and res.n_frames == 120


def test_missing_views_and_bad_input_are_refused():
    cams = load_rig("ring4", (640, 480))
    balls = wand_path(60, 10.0, seed=2)
    uv = _projected(cams, balls, 0.05)
    with pytest.raises(CalibrationError, match="shape"):
        calibrate_wand(_intrinsics_only(cams), uv[:, :, 0], 0.5)
    with pytest.raises(CalibrationError, match="wand length"):
        calibrate_wand(_intrinsics_only(cams), uv, 0.0)
    few = uv.copy()
    few[:, 10:] = np.nan
    with pytest.raises(CalibrationError, match="no two cameras saw both wand balls"):
        calibrate_wand(_intrinsics_only(cams), few, 0.5)
    blind = uv.copy()
    blind[3] = np.nan
    with pytest.raises(CalibrationError, match="cam4 saw too few"):
        calibrate_wand(_intrinsics_only(cams), blind, 0.5)


def test_rendered_wand_calibrates_a_4_camera_rig_to_under_1_mm_of_wand_length():
    from tracking.colour_table import ColourTable
    from tracking.wand_capture import wand_centroids_in_images

    cams = load_rig("ring4", (480, 360))
    balls = wand_path(80, 4.0, seed=1)
    table = ColourTable.build(np.asarray(WAND_COLOURS_RGB255, np.uint8))
    uv = np.stack([wand_centroids_in_images(imgs, cams, table, 0.02) for imgs in render_wand(cams, balls)], axis=1)
    assert np.isfinite(uv[..., 0]).mean() > 0.8
    res = calibrate_wand(_intrinsics_only(cams), uv, 0.5)
    assert res.length_rmse_mm < 1.0, res.length_rmse_mm
    assert res.length_error_mm.size >= 70
    assert res.rms_px.max() < 0.3
    truth = _in_reference_frame(cams, res.reference)
    for a, b in zip(res.cameras, truth):
        assert np.linalg.norm(a.centre_m - b.centre_m) < 10e-3
