"""Calibration files: the spec's TOML, round trips through TOML and OpenCV YAML/XML, one-line errors."""

from __future__ import annotations

import dataclasses

import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calibration.camera import Camera, rotation_from_rvec
from calibration.errors import CalibrationError
from calibration.files import (
    check_camera_count,
    check_frame_sizes,
    load_calibration,
    save_calibration_opencv,
    save_calibration_toml,
)

# The example of docs/INTERFACES.md, "Camera calibration file", verbatim.
SPEC_EXAMPLE = """\
[cam_1]
name = "cam1"
size = [ 640.0, 480.0,]                        # image width, height in pixels
matrix = [ [ 600.0, 0.0, 320.0,], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ 0.0, 0.0, 0.0, 0.0,]           # OpenCV order k1, k2, p1, p2 (a 5th, k3, allowed)
rotation = [ 0.1, -2.9, 0.0,]                  # Rodrigues vector, world -> camera
translation = [ 0.05, 1.1, 2.3,]               # metres, world -> camera: x_cam = R x_world + t
fisheye = false

[metadata]
adjusted = false
error = 0.0
"""

SECOND_CAMERA = """\
[cam_2]
name = "cam2"
size = [ 1280.0, 720.0,]
matrix = [ [ 1000.0, 0.0, 639.5,], [ 0.0, 1001.0, 359.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.1, 0.01, 0.001, -0.002, 0.0005,]
rotation = [ 0.0, 3.0, 0.1,]
translation = [ -0.4, 1.0, 2.0,]
fisheye = false

"""

TWO_CAMERAS = SPEC_EXAMPLE.replace("[metadata]", SECOND_CAMERA + "[metadata]")


def two_cameras_with(old: str, new: str) -> str:
    """TWO_CAMERAS with one line of the first camera changed."""
    assert old in SPEC_EXAMPLE
    return TWO_CAMERAS.replace(old, new, 1)


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def load_error(path: Path, *fragments: str, **kwargs) -> str:
    """Load ``path`` expecting a one-line CalibrationError naming the file and ``fragments``."""
    with pytest.raises(CalibrationError) as exc:
        load_calibration(path, **kwargs)
    msg = str(exc.value)
    assert "\n" not in msg, msg
    assert str(path) in msg, msg
    for fragment in fragments:
        assert fragment in msg, msg
    return msg


def random_cameras(rng: np.random.Generator, n: int, dist_len: int = 5) -> list[Camera]:
    cams = []
    for i in range(n):
        w, h = int(rng.integers(320, 2000)), int(rng.integers(240, 1200))
        f = rng.uniform(300, 3000)
        K = np.array([[f, rng.uniform(-1, 1), rng.uniform(0.4, 0.6) * w],
                      [0.0, f * rng.uniform(0.95, 1.05), rng.uniform(0.4, 0.6) * h],
                      [0.0, 0.0, 1.0]])
        axis = rng.normal(size=3)
        rvec = axis / np.linalg.norm(axis) * rng.uniform(0, np.pi)
        cams.append(Camera(f"cam{i + 1}", (w, h), K, rng.normal(0, 0.05, dist_len), rvec, rng.uniform(-3, 3, 3)))
    return cams


def assert_same_cameras(got, want, atol: float) -> None:
    assert [c.name for c in got] == [c.name for c in want]
    for a, b in zip(got, want):
        assert a.size_px == b.size_px and a.fisheye == b.fisheye
        assert a.dist.shape == b.dist.shape
        for x, y in ((a.K, b.K), (a.dist, b.dist), (a.R, b.R), (a.t_m, b.t_m)):
            np.testing.assert_allclose(x, y, rtol=0, atol=atol)


# ----------------------------------------------------------------------------- the spec's TOML
def test_spec_example_verbatim_is_read_and_needs_a_second_camera(tmp_path):
    path = write(tmp_path, "calibration.toml", SPEC_EXAMPLE)
    load_error(path, "1 camera", "2 or more")
    (cam,) = load_calibration(write(tmp_path, "two.toml", TWO_CAMERAS))[:1]
    assert cam.name == "cam1" and cam.size_px == (640, 480) and not cam.fisheye
    np.testing.assert_array_equal(cam.K, [[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(cam.dist, np.zeros(4))
    np.testing.assert_array_equal(cam.rvec, [0.1, -2.9, 0.0])
    np.testing.assert_array_equal(cam.t_m, [0.05, 1.1, 2.3])
    np.testing.assert_allclose(cam.R, rotation_from_rvec([0.1, -2.9, 0.0]), atol=1e-15)


def test_cameras_come_in_file_order(tmp_path):
    swapped = SECOND_CAMERA.replace("[cam_2]", "[cam_0]") + SPEC_EXAMPLE
    cams = load_calibration(write(tmp_path, "c.toml", swapped))
    assert [c.name for c in cams] == ["cam2", "cam1"]
    assert cams[0].size_px == (1280, 720) and cams[0].dist.size == 5


def test_anipose_style_file_loads(tmp_path):
    """aniposelib omits 'fisheye' for pinhole cameras, writes integer sizes and its own metadata."""
    text = (
        TWO_CAMERAS.replace("fisheye = false\n", "")
        .replace("size = [ 640.0, 480.0,]", "size = [640, 480]")
        .replace("error = 0.0", "error = 0.0\nboard = \"charuco\"\n[metadata.extra]\nseed = 3")
    )
    cams = load_calibration(write(tmp_path, "anipose.toml", text))
    assert cams[0].size_px == (640, 480) and not cams[0].fisheye


def test_metadata_table_is_optional(tmp_path):
    cams = load_calibration(write(tmp_path, "c.toml", TWO_CAMERAS.split("[metadata]")[0]))
    assert len(cams) == 2


# ----------------------------------------------------------------------------- round trips
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(0, 2**32 - 1), st.integers(2, 6), st.sampled_from([4, 5, 8]), st.booleans(), st.floats(0, 5))
def test_toml_round_trip_is_exact(tmp_path, seed, n, dist_len, adjusted, error_px):
    cams = random_cameras(np.random.default_rng(seed), n, dist_len)
    path = tmp_path / "calibration.toml"
    save_calibration_toml(path, cams, adjusted=adjusted, error=error_px)
    back = load_calibration(path)
    assert_same_cameras(back, cams, atol=0.0)
    for a, b in zip(back, cams):
        np.testing.assert_array_equal(a.rvec, b.rvec)
    meta = tomllib.loads(path.read_text())["metadata"]
    assert meta == {"adjusted": adjusted, "error": error_px}


def test_toml_written_in_the_spec_layout(tmp_path):
    cams = load_calibration(write(tmp_path, "in.toml", TWO_CAMERAS))
    out = tmp_path / "out.toml"
    save_calibration_toml(out, cams)
    text = out.read_text()
    assert text.startswith('[cam_1]\nname = "cam1"\nsize = [ 640.0, 480.0,]\n')
    assert "matrix = [ [ 600.0, 0.0, 320.0,], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]\n" in text
    assert "distortions = [ 0.0, 0.0, 0.0, 0.0,]\nrotation = [ 0.1, -2.9, 0.0,]\n" in text
    assert text.endswith("[metadata]\nadjusted = false\nerror = 0.0\n")
    doc = tomllib.loads(text)
    assert list(doc) == ["cam_1", "cam_2", "metadata"]
    assert list(doc["cam_1"]) == ["name", "size", "matrix", "distortions", "rotation", "translation", "fisheye"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.toml", "out.toml"]  # no temporary left


def test_toml_names_are_escaped(tmp_path):
    cams = random_cameras(np.random.default_rng(1), 2)
    cams[0] = Camera('left "A" \\ é', cams[0].size_px, cams[0].K, cams[0].dist, cams[0].rvec, cams[0].t_m)
    save_calibration_toml(tmp_path / "c.toml", cams)
    assert load_calibration(tmp_path / "c.toml")[0].name == 'left "A" \\ é'


def test_fisheye_cameras_round_trip(tmp_path):
    """Fisheye cameras are projected with their own model (tests/calibration/test_foreign.py)."""
    cams = random_cameras(np.random.default_rng(2), 2, dist_len=4)
    cams[1] = Camera("cam2", cams[1].size_px, cams[1].K, cams[1].dist, cams[1].rvec, cams[1].t_m, fisheye=True)
    for name in ("c.toml", "c.yaml"):
        path = tmp_path / name
        (save_calibration_toml if name.endswith("toml") else save_calibration_opencv)(path, cams)
        assert [c.fisheye for c in load_calibration(path)] == [False, True]


@pytest.mark.parametrize("suffix", [".yaml", ".yml", ".xml"])
@pytest.mark.parametrize("dist_len", [4, 5, 8])
def test_opencv_round_trip(tmp_path, suffix, dist_len):
    rng = np.random.default_rng(dist_len)
    cams = random_cameras(rng, 4, dist_len)
    # Rotations that cv2.Rodrigues handles poorly: exactly and nearly the identity and a half turn.
    for i, rvec in enumerate([[0.0, 0.0, 0.0], [1e-7, 0.0, 0.0], [0.0, np.pi, 0.0], [0.0, np.pi - 1e-7, 1e-8]]):
        c = cams[i]
        cams[i] = Camera(c.name, c.size_px, c.K, c.dist, rvec, c.t_m)
    cams += random_cameras(rng, 3, dist_len)
    cams[4:] = [Camera(f"extra{i}", c.size_px, c.K, c.dist, c.rvec, c.t_m) for i, c in enumerate(cams[4:])]
    path = tmp_path / f"calibration{suffix}"
    save_calibration_opencv(path, cams)
    assert_same_cameras(load_calibration(path), cams, atol=1e-12)
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_toml_to_opencv_to_toml(tmp_path):
    cams = load_calibration(write(tmp_path, "a.toml", TWO_CAMERAS))
    save_calibration_opencv(tmp_path / "b.xml", cams)
    save_calibration_toml(tmp_path / "c.toml", load_calibration(tmp_path / "b.xml"))
    assert_same_cameras(load_calibration(tmp_path / "c.toml"), cams, atol=1e-12)


# ----------------------------------------------------------------------------- OpenCV files written by hand
HAND_YAML = """\
%YAML:1.0
---
calibration_time: "today"
cameras:
   - name: left
     image_size: [ 640, 480 ]
     K: [ [ 600., 0., 320. ], [ 0., 600., 240. ], [ 0., 0., 1. ] ]
     dist: [ 0.1, -0.01, 0., 0., 0.001 ]
     rvec: [ 0.1, -2.9, 0. ]
     t: [ 0.05, 1.1, 2.3 ]
     rms: 0.3
   - image_width: 1280
     image_height: 720
     camera_matrix: !!opencv-matrix
        rows: 3
        cols: 3
        dt: d
        data: [ 1000., 0., 639.5, 0., 1000., 359.5, 0., 0., 1. ]
     distortion_coefficients: !!opencv-matrix
        rows: 5
        cols: 1
        dt: d
        data: [ 0., 0., 0., 0., 0. ]
     R: !!opencv-matrix
        rows: 3
        cols: 3
        dt: d
        data: [ 1., 0., 0., 0., -1., 0., 0., 0., -1. ]
     tvec: [ 0., 1., 3. ]
"""


def test_hand_written_opencv_yaml_with_aliases_and_plain_sequences(tmp_path):
    left, cam2 = load_calibration(write(tmp_path, "calib.yaml", HAND_YAML))
    assert (left.name, left.size_px) == ("left", (640, 480))
    np.testing.assert_array_equal(left.rvec, [0.1, -2.9, 0.0])
    np.testing.assert_array_equal(left.dist, [0.1, -0.01, 0.0, 0.0, 0.001])
    assert (cam2.name, cam2.size_px) == ("cam2", (1280, 720))  # unnamed: cam<i>
    np.testing.assert_allclose(cam2.R, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    np.testing.assert_array_equal(cam2.t_m, [0.0, 1.0, 3.0])
    assert cam2.K[0, 0] == 1000.0


def test_yaml_with_consistent_R_and_rvec(tmp_path):
    R = rotation_from_rvec([0.1, -2.9, 0.0])
    rows = ", ".join("[ " + ", ".join(repr(float(x)) for x in r) + " ]" for r in R)
    text = HAND_YAML.replace("     rvec: [ 0.1, -2.9, 0. ]\n", f"     rvec: [ 0.1, -2.9, 0. ]\n     R: [ {rows} ]\n")
    cams = load_calibration(write(tmp_path, "ok.yaml", text))
    np.testing.assert_allclose(cams[0].R, R, atol=1e-15)
    bad = HAND_YAML.replace("     rvec: [ 0.1, -2.9, 0. ]\n", f"     rvec: [ 0.1, -2.8, 0. ]\n     R: [ {rows} ]\n")
    load_error(write(tmp_path, "bad.yaml", bad), "'left'", "different rotations", "keep only one")


# ----------------------------------------------------------------------------- errors: the file itself
def test_missing_file(tmp_path):
    load_error(tmp_path / "calibration.toml", "not found", "run 'rehab calibrate' or give --calibration FILE")
    load_error(tmp_path / "calibration.yaml", "not found")


def test_directory_instead_of_file(tmp_path):
    (tmp_path / "rec.toml").mkdir()
    load_error(tmp_path / "rec.toml", "not a file", "--calibration FILE")


def test_unknown_extension(tmp_path):
    load_error(write(tmp_path, "calibration.json", "{}"), "'.json'", ".toml", ".yaml")


def test_malformed_toml_names_the_line(tmp_path):
    text = TWO_CAMERAS.replace("fisheye = false\n", "fisheye = \n", 1)
    msg = load_error(write(tmp_path, "c.toml", text), "not valid TOML", "line 8")
    assert "rehab calibrate" in msg


def test_toml_that_is_not_utf8(tmp_path):
    path = tmp_path / "c.toml"
    path.write_bytes(b'[cam_1]\nname = "\xff"\n')
    load_error(path, "UTF-8")


def test_malformed_yaml_names_the_line(tmp_path):
    text = HAND_YAML.replace("dist: [ 0.1, -0.01, 0., 0., 0.001 ]", "dist: [ 0.1, -0.01, 0., 0., 0.001")
    load_error(write(tmp_path, "c.yaml", text), "not a valid OpenCV FileStorage file", "line ")


@pytest.mark.parametrize("text", ["", "just text\n", "<opencv_storage><a>1</b></opencv_storage>"])
def test_unparseable_opencv_files(tmp_path, text):
    load_error(write(tmp_path, "c.xml", text))


# ----------------------------------------------------------------------------- errors: TOML cameras
@pytest.mark.parametrize("key", ["name", "size", "matrix", "distortions", "rotation", "translation"])
def test_toml_camera_missing_a_key(tmp_path, key):
    lines = [line for line in TWO_CAMERAS.splitlines(keepends=True)]
    # drop the key from the second camera
    second = lines.index("[cam_2]\n")
    drop = next(i for i in range(second, len(lines)) if lines[i].startswith(f"{key} ="))
    text = "".join(lines[:drop] + lines[drop + 1:])
    load_error(write(tmp_path, "c.toml", text), "[cam_2]", f"lacks {key!r}")


@pytest.mark.parametrize(
    "old, new, fragments",
    [
        ("matrix = [ [ 600.0, 0.0, 320.0,], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]",
         "matrix = [ [ 600.0, 0.0, 320.0,], [ 0.0, 600.0, 240.0,],]", ("'matrix'", "3x3", "got 2x3")),
        ("matrix = [ [ 600.0, 0.0, 320.0,], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]",
         "matrix = [ [ 600.0, 0.0, 320.0,], [ 0.0, 600.0,], [ 0.0, 0.0, 1.0,],]", ("'matrix'", "different lengths")),
        ("matrix = [ [ 600.0, 0.0, 320.0,], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]",
         'matrix = [ [ 600.0, 0.0, "320",], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]', ("'matrix'", "numbers")),
        ("matrix = [ [ 600.0, 0.0, 320.0,], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]",
         "matrix = [ [ 0.0, 0.0, 320.0,], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]", ("'cam1'", "fx, fy > 0")),
        ("distortions = [ 0.0, 0.0, 0.0, 0.0,]", "distortions = [ 0.0, 0.0, 0.0,]",
         ("'distortions'", "4, 5 or 8", "got 3")),
        ("rotation = [ 0.1, -2.9, 0.0,]", "rotation = [ [ 1.0, 0.0, 0.0,], [ 0.0, 1.0, 0.0,], [ 0.0, 0.0, 1.0,],]",
         ("'rotation'", "Rodrigues", "got 3x3")),
        ("rotation = [ 0.1, -2.9, 0.0,]", "rotation = [ true, false, false,]", ("'rotation'", "numbers")),
        ("translation = [ 0.05, 1.1, 2.3,]", "translation = [ 0.05, 1.1,]", ("'translation'", "metres")),
        ("translation = [ 0.05, 1.1, 2.3,]", "translation = 2.3", ("'translation'", "single number")),
        ("size = [ 640.0, 480.0,]", "size = [ 640.0, 480.0, 3.0,]", ("'size'", "width, height")),
        ("size = [ 640.0, 480.0,]", "size = [ 640.5, 480.0,]", ("'size'", "whole pixels")),
        ("size = [ 640.0, 480.0,]", "size = [ 0.0, 480.0,]", ("'size'", "whole pixels")),
        ('name = "cam1"', "name = 1", ("[cam_1]", "'name'", "string")),
        ('name = "cam1"', 'name = ""', ("'name'", "string")),
        ("fisheye = false", 'fisheye = "no"', ("'fisheye'", "true or false")),
        ("fisheye = false", "fisheye = false\nfocal = 3.0", ("unknown key 'focal'",)),
    ],
)
def test_toml_camera_with_a_bad_value(tmp_path, old, new, fragments):
    msg = load_error(write(tmp_path, "c.toml", two_cameras_with(old, new)), *fragments)
    assert "cam_1" in msg or "cam1" in msg


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("translation = [ 0.05, 1.1, 2.3,]", "translation = [ 0.05, nan, 2.3,]", "translation"),
        ("rotation = [ 0.1, -2.9, 0.0,]", "rotation = [ 0.1, -inf, 0.0,]", "rotation"),
        ("matrix = [ [ 600.0, 0.0, 320.0,], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]",
         "matrix = [ [ inf, 0.0, 320.0,], [ 0.0, 600.0, 240.0,], [ 0.0, 0.0, 1.0,],]", "matrix"),
        ("distortions = [ 0.0, 0.0, 0.0, 0.0,]", "distortions = [ 0.0, nan, 0.0, 0.0,]", "distortions"),
        ("size = [ 640.0, 480.0,]", "size = [ 640.0, inf,]", "size"),
    ],
)
def test_toml_non_finite_numbers(tmp_path, old, new, key):
    load_error(write(tmp_path, "c.toml", two_cameras_with(old, new)), "[cam_1]", f"{key!r}", "non-finite")


def test_toml_non_finite_metadata_error(tmp_path):
    load_error(write(tmp_path, "c.toml", TWO_CAMERAS.replace("error = 0.0", "error = nan")), "'error'", "finite")


@pytest.mark.parametrize(
    "text, fragments",
    [
        ('version = 2\n' + TWO_CAMERAS, ("unexpected top-level key 'version'",)),
        ("metadata = 3\n" + TWO_CAMERAS.split("[metadata]")[0], ("'metadata'", "table")),
        (TWO_CAMERAS.replace("adjusted = false", "adjusted = 0"), ("'adjusted'", "true or false")),
    ],
)
def test_toml_bad_layout(tmp_path, text, fragments):
    load_error(write(tmp_path, "c.toml", text), *fragments)


def test_toml_fewer_than_two_cameras(tmp_path):
    load_error(write(tmp_path, "one.toml", SPEC_EXAMPLE), "holds 1 camera", "2 or more")
    load_error(write(tmp_path, "none.toml", "[metadata]\nadjusted = false\nerror = 0.0\n"), "holds 0 cameras")


def test_toml_duplicate_camera_names(tmp_path):
    text = TWO_CAMERAS.replace('name = "cam2"', 'name = "cam1"')
    load_error(write(tmp_path, "c.toml", text), "'cam1'", "unique name")


# ----------------------------------------------------------------------------- errors: OpenCV cameras
def yaml_with(old: str, new: str) -> str:
    assert old in HAND_YAML
    return HAND_YAML.replace(old, new, 1)


ROTATION_ROWS = "data: [ 1., 0., 0., 0., -1., 0., 0., 0., -1. ]"


@pytest.mark.parametrize(
    "old, new, fragments",
    [
        (ROTATION_ROWS, "data: [ 1., 0., 0., 0., 1., 0., 0., 0., -1. ]", ("'cam2'", "'R'", "not a rotation")),
        (ROTATION_ROWS, "data: [ 2., 0., 0., 0., -1., 0., 0., 0., -1. ]", ("'cam2'", "'R'", "not a rotation")),
        (ROTATION_ROWS, "data: [ 1., 0., 0., 0., -1., 0., 0., 0., .nan ]", ("'cam2'", "'R'", "non-finite")),
        ("        rows: 3\n        cols: 3\n        dt: d\n        " + ROTATION_ROWS,
         "        rows: 3\n        cols: 1\n        dt: d\n        data: [ 0., 3.1, 0. ]", ("'R'", "3x3", "'rvec'")),
        ("        rows: 3\n        cols: 3\n        dt: d\n        " + ROTATION_ROWS,
         "        rows: 3\n        cols: 3\n        dt: d\n        data: [ 1., 0., 0. ]", ("'R'", "opencv-matrix")),
        ("     rvec: [ 0.1, -2.9, 0. ]\n", "", ("'left'", "'R'", "'rvec'")),
        ("     t: [ 0.05, 1.1, 2.3 ]\n", "", ("'left'", "'t'")),
        ("     t: [ 0.05, 1.1, 2.3 ]\n", "     t: [ 0.05, .inf, 2.3 ]\n", ("'left'", "'t'", "non-finite")),
        ("     t: [ 0.05, 1.1, 2.3 ]\n", "     t: [ 0.05, 1.1 ]\n", ("'left'", "'t'", "3 numbers")),
        ("     t: [ 0.05, 1.1, 2.3 ]\n", "     t: [ 0.05, 1.1, 2.3 ]\n     t: [ 0., 0., 0. ]\n", ("'t'", "twice")),
        ("     t: [ 0.05, 1.1, 2.3 ]\n", "     t: [ 0.05, 1.1, 2.3 ]\n     tvec: [ 0., 0., 0. ]\n",
         ("'t'", "'tvec'", "only one")),
        ("     t: [ 0.05, 1.1, 2.3 ]\n", '     t: [ 0.05, "a", 2.3 ]\n', ("'t'", "numbers")),
        ("     K: [ [ 600., 0., 320. ], [ 0., 600., 240. ], [ 0., 0., 1. ] ]\n", "",
         ("'left'", "'K' or 'camera_matrix'")),
        ("[ [ 600., 0., 320. ], [ 0., 600., 240. ], [ 0., 0., 1. ] ]", "[ [ 600., 0., 320. ], [ 0., 600., 240. ] ]",
         ("'K'", "3x3", "6 numbers")),
        ("[ [ 600., 0., 320. ], [ 0., 600., 240. ], [ 0., 0., 1. ] ]", "[ [ 600., 0., 320. ], [ 0., 600. ], [ 0., 0., 1. ] ]",
         ("'K'", "different lengths")),
        ("dist: [ 0.1, -0.01, 0., 0., 0.001 ]", "dist: [ 0.1, -0.01, 0. ]", ("'dist'", "4, 5 or 8")),
        ("image_size: [ 640, 480 ]", "image_size: [ 640.5, 480 ]", ("'image_size'", "whole pixels")),
        ("     image_size: [ 640, 480 ]\n", "", ("'left'", "'image_size'")),
        ("image_width: 1280", "image_width: 0", ("'image_width/image_height'", "whole pixels")),
        ("     rms: 0.3\n", "     fisheye: 2\n", ("'left'", "'fisheye'", "0 or 1")),
        ("     rms: 0.3\n", "     fisheye: yes\n", ("'left'", "'fisheye'", "0 or 1")),
        ("name: left", "name: [ 1, 2 ]", ("cameras[0]", "'name'")),
        ("name: left", "name: cam2", ("'cam2'", "unique name")),
    ],
)
def test_opencv_camera_with_a_bad_value(tmp_path, old, new, fragments):
    load_error(write(tmp_path, "calib.yaml", yaml_with(old, new)), *fragments)


def test_opencv_layout_errors(tmp_path):
    one = HAND_YAML.split("   - image_width")[0]
    load_error(write(tmp_path, "one.yaml", one), "holds 1 camera", "2 or more")
    single = "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ncamera_matrix: [ 600., 0., 320., 0., 600., 240., 0., 0., 1. ]\n"
    load_error(write(tmp_path, "single.yaml", single), "lacks 'distortion_coefficients'")
    load_error(write(tmp_path, "single2.yaml", single + "distortion_coefficients: [ 0.1, 0., 0., 0. ]\n"),
               "one camera's lens data", "rehab calibrate import")
    load_error(write(tmp_path, "other.yaml", "%YAML:1.0\n---\nfoo: 1\n"), "no 'cameras' sequence")
    load_error(write(tmp_path, "map.yaml", "%YAML:1.0\n---\ncameras:\n  a: 1\n"), "'cameras' must be a sequence")
    load_error(write(tmp_path, "item.yaml", "%YAML:1.0\n---\ncameras: [ 1, 2 ]\n"), "cameras[0]", "map")


# ----------------------------------------------------------------------------- errors: saving
def test_save_rejects_what_load_would_reject(tmp_path):
    cams = random_cameras(np.random.default_rng(5), 2)
    for save, name in ((save_calibration_toml, "c.toml"), (save_calibration_opencv, "c.yaml")):
        with pytest.raises(CalibrationError, match="2 or more"):
            save(tmp_path / name, cams[:1])
        with pytest.raises(CalibrationError, match="unique name"):
            save(tmp_path / name, [cams[0], cams[0]])
        with pytest.raises(CalibrationError, match="does not exist"):
            save(tmp_path / "missing" / name, cams)
    with pytest.raises(CalibrationError, match=r"\.yaml, \.yml or \.xml"):
        save_calibration_opencv(tmp_path / "c.toml", cams)
    with pytest.raises(CalibrationError, match="finite"):
        save_calibration_toml(tmp_path / "c.toml", cams, error=float("nan"))
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- consistency with the sources
def test_check_frame_sizes():
    cams = [Camera.look_at(f"cam{i}", (640, 480), 600.0, [i, 1.0, 2.0], [0.0, 1.0, 0.0]) for i in (1, 2)]
    check_frame_sizes(cams, [(640, 480), (640, 480)], ["cam1.avi", "cam2.avi"])
    with pytest.raises(CalibrationError) as exc:
        check_frame_sizes(cams, [(640, 480), (1280, 720)], ["cam1.avi", "cam2.avi"])
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith("the calibration of cam2 is for 640x480 but cam2.avi delivers 1280x720: recalibrate")
    with pytest.raises(ValueError):
        check_frame_sizes(cams, [(640, 480)], ["cam1.avi"])


def test_check_camera_count():
    cams = [Camera.look_at(f"cam{i}", (640, 480), 600.0, [i, 1.0, 2.0], [0.0, 1.0, 0.0]) for i in range(4)]
    check_camera_count(cams, 4, "the recording")
    with pytest.raises(CalibrationError) as exc:
        check_camera_count(cams, 3, "the recording", kind="videos", calibration_name="calibration.toml")
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith("calibration.toml has 4 cameras but the recording has 3 videos: ")
    assert "--calibration FILE" in msg
    with pytest.raises(CalibrationError, match="the calibration has 4 cameras but rec/ has 2 videos or image folders"):
        check_camera_count(cams, 2, "rec/")
    with pytest.raises(CalibrationError, match="this computer has 1 camera: "):
        check_camera_count(cams, 1, "this computer", kind="cameras")
    with pytest.raises(CalibrationError, match="rec/ has 1 video or image folder: "):
        check_camera_count(cams, 1, "rec/")


def test_rolling_shutter_readout_is_an_optional_key_of_both_formats(tmp_path):
    cams = random_cameras(np.random.default_rng(3), 3)
    cams[1] = dataclasses.replace(cams[1], rolling_shutter_s=0.025)
    for name in ("c.toml", "c.yaml"):
        path = tmp_path / name
        (save_calibration_toml if name.endswith("toml") else save_calibration_opencv)(path, cams)
        assert [c.rolling_shutter_s for c in load_calibration(path)] == [0.0, 0.025, 0.0]
    assert "rolling_shutter_s" not in (tmp_path / "c.toml").read_text().split("[cam_2]")[0]  # 0: not written
    text = (tmp_path / "c.toml").read_text().replace("rolling_shutter_s = 0.025", "rolling_shutter_s = -1.0")
    (tmp_path / "bad.toml").write_text(text)
    with pytest.raises(CalibrationError, match="rolling_shutter_s"):
        load_calibration(tmp_path / "bad.toml")
