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
    from tracking.colour.table import ColourTable
    from tracking.drivers.wand_capture import wand_centroids_in_images

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


@pytest.mark.parametrize("rig", ["ring4", "tri3", "corners4"])
def test_balls_of_one_colour_are_told_apart_by_the_rigs_geometry(rig):
    """Exact projections (0.2 px noise), the two balls in random order in every camera and frame:
    the cameras come to agree frame by frame, and the rig calibrates as with two colours."""
    from calibration.wand import match_same_colour_balls

    cams = load_rig(rig, (640, 480))
    balls = wand_path(150, 10.0, seed=3)
    uv = _projected(cams, balls, 0.2, seed=4)
    swap = np.random.default_rng(5).random(uv.shape[:2]) < 0.5
    shuffled = uv.copy()
    shuffled[swap] = uv[swap][:, ::-1]
    matched, dropped = match_same_colour_balls(_intrinsics_only(cams), shuffled)
    kept = np.all(np.isfinite(matched), axis=(2, 3))
    assert dropped == int((~kept).sum()) and kept.mean() > 0.8
    for t in range(uv.shape[1]):
        cs = np.flatnonzero(kept[:, t])
        if len(cs) < 2:
            continue
        same = [np.allclose(matched[c, t], uv[c, t]) for c in cs]
        crossed = [np.allclose(matched[c, t], uv[c, t, ::-1]) for c in cs]
        assert all(same) or all(crossed), (t, same, crossed)
    res = calibrate_wand(_intrinsics_only(cams), matched, 0.5)
    truth = _in_reference_frame(cams, res.reference)
    for a, b in zip(res.cameras, truth):
        assert np.linalg.norm(a.centre_m - b.centre_m) < 5e-3
        assert np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1, 1))) < 0.2
    assert res.length_rmse_mm < 1.0


def test_rendered_wand_of_one_colour_without_meta_file_through_the_command(tmp_path, capsys):
    """Two yellow balls, no meta.yaml (the frame rate from the videos): rehab calibrate wand."""
    from calibration.files import load_calibration, save_calibration_toml
    from game.cli import main
    from tracking.sim.calibration_material import write_wand_sequence

    cams = load_rig("ring4", (480, 360))
    yellow = (WAND_COLOURS_RGB255[0], WAND_COLOURS_RGB255[0])
    write_wand_sequence(tmp_path / "wand", cams, wand_path(80, 4.0, seed=1), 12.0, colours_rgb255=yellow)
    (tmp_path / "wand" / "meta.yaml").unlink()
    intr = tmp_path / "intrinsics.toml"
    save_calibration_toml(intr, _intrinsics_only(cams))
    out = tmp_path / "wand.toml"
    assert main(["calibrate", "wand", str(tmp_path / "wand"), "--intrinsics", str(intr), "--length-mm", "500",
                 "--colour", ",".join(map(str, yellow[0])), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "balls of one colour told apart" in text
    assert float(text.split("wand length error ")[1].split(" mm")[0]) < 1.0
    got = load_calibration(out)
    ref = next(k for k, c in enumerate(got) if np.allclose(c.R, np.eye(3)) and not np.any(c.t_m))
    for a, b in zip(got, _in_reference_frame(cams, ref)):
        assert np.linalg.norm(a.centre_m - b.centre_m) < 10e-3
