"""Calibration files of other tools: OpenCV's calibration sample and stereo_calib, Caliscope, Qualisys,
the fisheye model, and the millimetre check; on the tools' own public files (third_party/) and on
files written here with OpenCV."""

from __future__ import annotations

import tomllib
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibration.camera import Camera, CameraStack
from calibration.errors import CalibrationError
from calibration.files import load_calibration, read_cameras, save_calibration_toml
from game.cli import main
from tracking.triangulation import triangulate

DATA = Path(__file__).parent / "third_party"


def _points(n=40, seed=0):
    return np.random.default_rng(seed).uniform(-0.5, 0.5, (n, 3)) + np.array([0.0, 1.0, 0.0])


def _in_view(cam: Camera, n=40, seed=0):
    """World points in front of a camera, within about 35 degrees of its axis, 1-3 m away."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(1.0, 3.0, n)
    p_cam = np.column_stack([rng.uniform(-0.7, 0.7, n) * z, rng.uniform(-0.5, 0.5, n) * z, z])
    return (p_cam - cam.t_m) @ cam.R


# --------------------------------------------------------------------- Qualisys
def test_qualisys_qca_matches_pose2sims_conversion_of_the_same_file():
    cams = load_calibration(DATA / "Calib.qca.txt")
    ref = tomllib.loads((DATA / "Calib_qualisys_S00.toml").read_text())
    assert [c.name for c in cams] == ["cam01", "cam02", "cam03", "cam04"]
    for cam, table in zip(cams, (v for k, v in ref.items() if k != "metadata")):
        assert cam.size_px == tuple(int(v) for v in table["size"])
        assert np.allclose(cam.K, table["matrix"], atol=1e-9)
        assert np.allclose(cam.dist, table["distortions"], atol=1e-12)
        assert np.allclose(cam.R, cv2.Rodrigues(np.array(table["rotation"]))[0], atol=1e-12)
        assert np.allclose(cam.t_m, table["translation"], atol=1e-9)


def test_qualisys_file_without_intrinsics_is_refused_in_one_line(tmp_path):
    text = (DATA / "Calib.qca.txt").read_text()
    start = text.index("<intrinsic ")
    bad = tmp_path / "bad.qca.txt"
    bad.write_text(text[:start] + text[text.index("/>", start) + 2:])
    with pytest.raises(CalibrationError, match=r"camera cam01 lacks <intrinsic>") as exc:
        load_calibration(bad)
    assert "\n" not in str(exc.value)


# --------------------------------------------------------------------- Caliscope
def test_caliscope_config_loads_its_cameras_and_skips_its_settings():
    cams = load_calibration(DATA / "caliscope_config_4cam_recording_first2cams.toml")
    doc = tomllib.loads((DATA / "caliscope_config_4cam_recording_first2cams.toml").read_text())
    assert [c.name for c in cams] == ["cam_0", "cam_1"]
    for cam, key in zip(cams, ("cam_0", "cam_1")):
        t = doc[key]
        assert cam.size_px == (1280, 720) and not cam.fisheye
        p = _in_view(cam)
        ref, _ = cv2.projectPoints(p, cv2.Rodrigues(np.array(t["rotation"]))[0], np.array(t["translation"]),
                                   np.array(t["matrix"]), np.array(t["distortions"]))
        assert np.abs(cam.project(p) - ref.reshape(-1, 2)).max() < 1e-9


def test_caliscope_camera_without_intrinsics_is_named(tmp_path):
    text = (DATA / "caliscope_config_4cam_recording_first2cams.toml").read_text()
    path = tmp_path / "config.toml"
    path.write_text(text.replace("matrix = [ [ 703.95", "matrix_ = [ [ 703.95"))
    with pytest.raises(CalibrationError, match=r"\[cam_1\] lacks matrix"):
        load_calibration(path)


# --------------------------------------------------------------------- fisheye and millimetres
def test_fisheye_anipose_file_in_millimetres_is_refused_then_imported(tmp_path, capsys):
    src = DATA / "anipose_videos_calibration_fisheye.toml"
    with pytest.raises(CalibrationError, match="translations are millimetres, not metres") as exc:
        load_calibration(src)
    assert "\n" not in str(exc.value) and "--translation-unit mm" in str(exc.value)
    out = tmp_path / "calibration.toml"
    assert main(["calibrate", "import", str(src), "--translation-unit", "mm", "--out", str(out)]) == 0
    assert "wrote the calibration of 3 cameras" in capsys.readouterr().out
    cams = load_calibration(out)
    doc = tomllib.loads(src.read_text())
    for cam, key in zip(cams, ("cam_0", "cam_1", "cam_2")):
        t = doc[key]
        assert cam.fisheye and cam.name == t["name"]
        p = _in_view(cam, seed=1)
        ref, _ = cv2.fisheye.projectPoints(p.reshape(-1, 1, 3), np.array(t["rotation"]), np.array(t["translation"]) / 1000,
                                           np.array(t["matrix"]), np.array(t["distortions"]))
        assert np.abs(cam.project(p) - ref.reshape(-1, 2)).max() < 1e-9


def test_fisheye_projection_undistortion_and_triangulation():
    K = np.array([[300.0, 0, 320], [0, 300, 240], [0, 0, 1]])
    d = np.array([-0.05, 0.012, -0.003, 0.0006])
    views = [Camera.look_at(f"c{k}", (640, 480), 300, eye, (0, 1, 0)) for k, eye in
             enumerate([(-1.5, 1.6, -1.8), (1.6, 1.8, -1.7), (0.2, 2.0, 2.0)])]
    cams = [Camera(c.name, c.size_px, K, d, c.rvec, c.t_m, fisheye=True) for c in views]
    p = _points(60, seed=2)
    stack = CameraStack(tuple(cams))
    uv, _ = stack.project(p)
    for c, cam in enumerate(cams):
        ref, _ = cv2.fisheye.projectPoints(p.reshape(-1, 1, 3), cam.rvec, cam.t_m, K, d)
        assert np.abs(uv[:, c] - ref.reshape(-1, 2)).max() < 1e-9
        # far off the axis (60 degrees), where pinhole and fisheye part most
        off = cam.centre_m + cam.R.T @ np.array([np.tan(np.radians(60)), 0.1, 1.0])
        xn = cam.undistort_points(cam.project(off[None]))
        assert np.allclose(xn, [[np.tan(np.radians(60)), 0.1]], atol=1e-7)
    xn = stack.undistort_points(uv)
    got = triangulate(np.stack([c.extrinsic for c in cams]), xn)
    assert np.abs(got - p).max() < 1e-7
    # the same pixels read as pinhole with these coefficients would be centimetres off
    pin = CameraStack(tuple(Camera(c.name, c.size_px, K, d, c.rvec, c.t_m) for c in cams))
    assert np.abs(triangulate(np.stack([c.extrinsic for c in cams]), pin.undistort_points(uv)) - p).max() > 0.005
    assert cams[0].undistort_image(np.zeros((480, 640, 3), np.uint8)).shape == (480, 640, 3)


def test_a_rig_written_in_millimetres_is_refused(tmp_path):
    cams = [Camera.look_at(f"cam{k}", (640, 480), 500, eye, (0, 1, 0)) for k, eye in enumerate([(-2, 1.5, -2), (2, 1.5, -2)])]
    mm = [Camera(c.name, c.size_px, c.K, c.dist, c.rvec, c.t_m * 1000.0) for c in cams]
    path = tmp_path / "mm.toml"
    save_calibration_toml(path, cams)  # valid in metres
    text = path.read_text()
    for c, m in zip(cams, mm):
        text = text.replace(repr(float(c.t_m[2])), repr(float(m.t_m[2])))
    path.write_text(text)
    with pytest.raises(CalibrationError, match=r"mm.toml: the cameras stand up to \d+ m apart"):
        load_calibration(path)


# --------------------------------------------------------------------- OpenCV's samples
def test_opencv_calibration_sample_files_make_a_rig_of_lens_data(tmp_path, capsys):
    sample = DATA / "opencv_sample_out_camera_data_head.yml"
    with pytest.raises(CalibrationError, match="holds one camera's lens data: gather every camera"):
        load_calibration(sample)
    # the newer sample's lower-case keys, as written by OpenCV itself, for a second camera
    K2 = np.array([[612.0, 0, 331.0], [0, 611.0, 236.5], [0, 0, 1]])
    second = tmp_path / "camB.xml"
    fs = cv2.FileStorage(str(second), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", K2)
    fs.write("distortion_coefficients", np.array([[0.1, -0.2, 0.001, 0.0, 0.05]]))
    fs.release()
    out = tmp_path / "intrinsics.toml"
    assert main(["calibrate", "import", str(sample), str(second), "--names", "cam1,cam2", "--out", str(out)]) == 0
    assert "lens data of 2 cameras" in capsys.readouterr().out
    a, b = load_calibration(out)
    assert a.size_px == (640, 480) and np.isclose(a.K[0, 0], 657.46697810243404) and a.dist.size == 5
    assert np.isclose(a.dist[4], -0.57843596847939704) and np.array_equal(b.K, K2) and not np.any(b.t_m)


def _write_stereo(folder: Path, *, with_size: bool, split: bool, T=(-0.12, 0.002, 0.004)):
    M1 = np.array([[700.0, 0, 318], [0, 701, 242], [0, 0, 1]])
    M2 = np.array([[705.0, 0, 322], [0, 704, 238], [0, 0, 1]])
    R = cv2.Rodrigues(np.array([0.01, -0.2, 0.005]))[0]
    fs = cv2.FileStorage(str(folder / "intrinsics.yml"), cv2.FILE_STORAGE_WRITE)
    for k, v in (("M1", M1), ("D1", np.array([[-0.1, 0.02, 0, 0, 0, 0, 0, 0]])), ("M2", M2), ("D2", np.zeros((1, 8)))):
        fs.write(k, v)
    if with_size:
        fs.write("image_width", 640)
        fs.write("image_height", 480)
    if not split:
        fs.write("R", R)
        fs.write("T", np.array(T).reshape(3, 1))
    fs.release()
    if split:
        fs = cv2.FileStorage(str(folder / "extrinsics.yml"), cv2.FILE_STORAGE_WRITE)
        fs.write("R", R)
        fs.write("T", np.array(T).reshape(3, 1))
        fs.write("Q", np.eye(4))
        fs.release()
    return R, np.array(T)


def test_stereo_calib_files_side_by_side_give_the_rig(tmp_path, capsys):
    R, T = _write_stereo(tmp_path, with_size=False, split=True)
    with pytest.raises(CalibrationError, match="holds no image size: add image_width and image_height"):
        load_calibration(tmp_path / "intrinsics.yml")
    out = tmp_path / "rig.toml"
    assert main(["calibrate", "import", str(tmp_path / "intrinsics.yml"), "--size", "640x480", "--out", str(out)]) == 0
    cam1, cam2 = load_calibration(out)
    assert not np.any(cam1.rvec) and not np.any(cam1.t_m) and cam1.dist.size == 8
    assert np.allclose(cam2.R, R, atol=1e-12) and np.allclose(cam2.t_m, T) and cam2.K[0, 0] == 705.0


def test_stereo_calib_in_one_file_and_its_missing_parts(tmp_path):
    R, T = _write_stereo(tmp_path, with_size=True, split=False)
    cam1, cam2 = load_calibration(tmp_path / "intrinsics.yml")
    assert np.allclose(cam2.R, R) and cam1.size_px == (640, 480)
    _write_stereo(tmp_path, with_size=True, split=False, T=(-120.0, 2.0, 4.0))  # squareSize given in mm
    with pytest.raises(CalibrationError, match="millimetres"):
        load_calibration(tmp_path / "intrinsics.yml")
    fs = cv2.FileStorage(str(tmp_path / "only.yml"), cv2.FILE_STORAGE_WRITE)
    fs.write("M1", np.eye(3))
    fs.release()
    with pytest.raises(CalibrationError, match="lacks M2, D1, D2"):
        read_cameras(tmp_path / "only.yml")
    cams, placed = read_cameras(tmp_path / "intrinsics.yml")
    assert placed and len(cams) == 2
