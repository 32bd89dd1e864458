"""The reported bad inputs of the readers, one by one: each is one line that names the file and the fix."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from calibration.errors import RehabError
from content import content_path

ROOT = Path(__file__).resolve().parents[1]


def test_a_latin1_accent_in_a_content_yaml_names_the_line_and_byte(tmp_path):
    from game.exergames.spec import load_game

    text = content_path("games", "reach.yaml").read_bytes()
    path = tmp_path / "mine.yaml"
    path.write_bytes(b"# caf\xe9 du matin\n" + text)
    with pytest.raises(RehabError) as err:
        load_game(path)
    assert str(err.value) == f"{path}: not UTF-8 text: byte 0xE9 at line 1 (byte position 5): save the file as UTF-8"


def test_a_latin1_accent_in_meta_yaml_is_one_line(tmp_path):
    from tracking.io.recording import read_meta

    (tmp_path / "meta.yaml").write_bytes(b"fps: 30\n# r\xe9glage\n")
    with pytest.raises(RehabError, match=r"meta.yaml: not UTF-8 text: byte 0xE9 at line 2"):
        read_meta(tmp_path)


@pytest.mark.parametrize("text, words", [
    ("fps: .nan\n", "'fps' must be a positive number"),
    ("fps: .inf\n", "'fps' must be a positive number"),
    ("fps: 30\nn_frames: 1.0e-320\n", "'n_frames' must be a whole number"),
    ("fps: 30\nmarker_colours: [[999, 0, 0]]\n", "whole numbers 0-255"),
    ("fps: 30\nmarker_colours: [[1, 2]]\n", "whole numbers 0-255"),
    ("fps: 30\nmarkerset: [a, b]\n", "'markerset' must be a marker set name"),
])
def test_meta_yaml_values_are_checked_once_at_load(tmp_path, text, words):
    from tracking.io.recording import read_meta

    (tmp_path / "meta.yaml").write_text(text)
    with pytest.raises(RehabError, match=words):
        read_meta(tmp_path)


def test_meta_yaml_with_3_of_14_colours_is_refused_not_ignored(tmp_path):
    from types import SimpleNamespace

    from tracking.sources.recording import markerset_for
    from tracking.io.recording import RecordingMeta

    rec = SimpleNamespace(folder=tmp_path, meta=RecordingMeta(fps=30.0, marker_colours=((255, 0, 0),) * 3))
    with pytest.raises(RehabError, match="gives 3 marker_colours but the marker set upper_limb_seated has 14"):
        markerset_for(rec, None, None)


def test_a_nan_in_a_game_yaml_is_refused(tmp_path):
    from game.exergames.spec import load_game

    path = tmp_path / "nan.yaml"
    path.write_text(content_path("games", "reach.yaml").read_text().replace("limits: {}", "limits: {max_level: .nan}"))
    with pytest.raises(RehabError, match=r"limits.max_level: Input should be a finite number"):
        load_game(path)


def _trc(tmp_path) -> Path:
    from tracking.io.trc import write_trc

    path = tmp_path / "m.trc"
    write_trc(path, ["RSHO", "RELB", "RWRI"], np.arange(60, dtype=float).reshape(5, 4, 3)[:, :3], 30.0)
    return path


def test_a_trc_cut_mid_row_is_refused(tmp_path):
    from tracking.io.trc import read_trc

    path = _trc(tmp_path)
    data = path.read_bytes()
    path.write_bytes(data[:data.rindex(b"\t", 0, len(data) - 8)])
    with pytest.raises(RehabError, match="without a line end: the file is truncated"):
        read_trc(path)


def test_a_trc_with_its_header_only_is_refused(tmp_path):
    from tracking.io.trc import read_trc

    path = _trc(tmp_path)
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:6]))
    with pytest.raises(RehabError, match="NumFrames says 5 but the file holds|header but no frames"):
        read_trc(path)


def test_a_c3d_cut_to_30_percent_is_refused(tmp_path):
    from tracking.io.c3d import read_c3d_points

    data = content_path("captures", "ezc3d_vicon_upper_limb.c3d").read_bytes()
    path = tmp_path / "cut.c3d"
    path.write_bytes(data[:int(0.3 * len(data))])
    with pytest.raises(RehabError, match="the file says 580 frames but holds 171: it is truncated"):
        read_c3d_points(path)
    path.write_bytes(data[:700])   # a header and part of the parameters: ezc3d would crash on it
    with pytest.raises(RehabError, match="parameter section is cut short"):
        read_c3d_points(path)


def test_a_marker_colour_of_999_is_one_line(capsys):
    from game.cli import main

    code = main(["track", str(ROOT / "nothing"), "--marker-color", "999,0,0", "--out", "x.trc"])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1, err


# ------------------------------------------------------------------------------ recordings and outputs
def _recording(folder: Path, n_cams: int = 3):
    from tests.tracking.test_recording import make_recording

    return make_recording(folder, n_frames=2, n_cams=n_cams)


def test_a_calibration_missing_one_of_the_recordings_cameras_is_stated(tmp_path, capsys):
    from calibration.files import save_calibration_toml
    from game.cli import main

    cams = _recording(tmp_path / "rec")
    save_calibration_toml(tmp_path / "two.toml", cams[:2])
    code = main(["track", str(tmp_path / "rec"), "--calibration", str(tmp_path / "two.toml"),
                 "--points", str(tmp_path / "p.csv")])
    err = capsys.readouterr().err
    assert code == 1 and "two.toml has 2 cameras (cam1, cam2) but the recording" in err and "cam3" in err
    assert err.count("\n") == 1


def test_one_image_of_another_size_is_one_line(tmp_path):
    import cv2

    from tracking.io.recording import Recording, RecordingWriter
    from tracking.sim.rigs import load_rig

    cams = load_rig("tri3", (160, 120))
    w = RecordingWriter(tmp_path, cams, 15.0, images=True)
    for _ in range(3):
        w.write([np.zeros((120, 160, 3), np.uint8) for _ in cams])
    w.close()
    w.write_meta("upper_limb_seated", np.zeros((14, 3), np.uint8) + 200)
    second = sorted((tmp_path / "cam2").iterdir())[1]
    cv2.imwrite(str(second), np.zeros((100, 80, 3), np.uint8))
    with Recording(tmp_path) as rec, pytest.raises(RehabError, match=r"80x100 pixels but the other images of cam2"):
        list(rec)


@pytest.mark.parametrize("option", ["--out", "--status", "--angles", "--c3d", "--mot", "--bvh", "--detections",
                                    "--points"])
def test_track_refuses_an_impossible_output_before_the_work(tmp_path, capsys, monkeypatch, option):
    option_suffix = {"--out": ".trc", "--c3d": ".c3d", "--mot": ".mot", "--bvh": ".bvh"}
    """A folder given as the file, a folder under a regular file, a folder that takes no files
    (/proc refuses new files even to root, as a read-only disk does): one line naming the
    option and the path, before any tracking."""
    import tracking.drivers.offline
    from game.cli import main

    _recording(tmp_path / "rec")
    monkeypatch.setattr(tracking.drivers.offline, "track_recording", lambda *a, **k: pytest.fail("the work began"))
    (tmp_path / "file").write_text("x")
    for target, words in [(tmp_path / "rec", "is a folder"), (tmp_path / "file" / "out.trc", "cannot write in"),
                          (Path("/proc/rehab-test-out.trc"), "cannot write in /proc")]:
        code = main(["track", str(tmp_path / "rec"), option, str(target)])
        err = capsys.readouterr().err
        assert code == 1 and words in err and option in err and str(target) in err and err.count("\n") == 1, err
        if words == "is a folder":   # the fix names a file of the option's kind
            suffix = ".csv" if option in ("--status", "--angles", "--detections", "--points") else option_suffix[option]
            assert f"e.g. {target}{os.sep}" in err and err.rstrip().endswith(suffix), err


def test_the_same_file_for_two_outputs_is_refused(tmp_path, capsys):
    from game.cli import main

    code = main(["track", str(tmp_path), "--out", str(tmp_path / "a"), "--angles", str(tmp_path / "a")])
    assert code == 1 and "is also given to --out" in capsys.readouterr().err


# ------------------------------------------------------------------------------ crashes found by the fuzz test
def test_an_opencv_matrix_without_cols_is_one_line_and_no_crash(tmp_path):
    """FileNode.mat() on it corrupted the heap: the process died later (malloc abort or segfault)."""
    import os
    import subprocess
    import sys

    from calibration.files import save_calibration_opencv
    from tracking.sim.rigs import load_rig

    path = tmp_path / "cv.yaml"
    save_calibration_opencv(path, load_rig("ring4", (320, 240)))
    lines = path.read_text().splitlines(keepends=True)
    t = [i for i, line in enumerate(lines) if line.strip() == "t: !!opencv-matrix"][2]
    del lines[t + 2]   # the third camera's "cols: 1" (the case tests/test_fuzz_inputs.py found)
    path.write_text("".join(lines))
    copies = []   # the corruption shows in some heap layouts only: vary them with the path's length
    for k in range(12):
        copies.append(tmp_path / f"cv{'x' * k}.yaml")
        copies[-1].write_bytes(path.read_bytes())
    code = ("import sys\nfrom calibration.files import load_calibration\n"
            "for p in sys.argv[1:]:\n    try:\n        load_calibration(p)\n"
            "    except Exception as e:\n        print(type(e).__name__, e)\n")
    # glibc's heap checks make the corruption abort at once instead of some time later
    env = dict(os.environ, MALLOC_CHECK_="3", MALLOC_PERTURB_="165")
    proc = subprocess.run([sys.executable, "-c", code, *map(str, copies)], capture_output=True, text=True, cwd=ROOT,
                          timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr[-300:]
    assert proc.stdout.count("CalibrationError") == 12 and "'t' is neither numbers" in proc.stdout


def _c3d_bytes(tmp_path) -> bytearray:
    from tracking.io.c3d import write_c3d

    path = tmp_path / "s.c3d"
    write_c3d(path, ["A", "B", "C"], np.zeros((20, 3, 3)) + 1.0, 30.0)
    return bytearray(path.read_bytes())


def test_a_c3d_whose_rotation_group_lost_its_data_start_is_refused_quickly(tmp_path):
    import time

    from tracking.io.c3d import read_c3d_points

    data = _c3d_bytes(tmp_path)
    i = data.index(b"DATA_START", data.index(b"ROTATION"))
    data[i + 1] = 0xF9   # D?TA_START: ezc3d searched for the rotations for 20 s
    path = tmp_path / "rot.c3d"
    path.write_bytes(bytes(data))
    t0 = time.monotonic()
    with pytest.raises(RehabError, match="ROTATION group has no valid DATA_START"):
        read_c3d_points(path)
    assert time.monotonic() - t0 < 2.0


def test_a_c3d_parameter_of_no_group_is_refused(tmp_path):
    from tracking.io.c3d import read_c3d_points

    data = _c3d_bytes(tmp_path)
    i = data.index(b"LABELS", data.index(b"ANALOG"))
    data[i - 1] = 47   # the parameter's group id: no group 47
    path = tmp_path / "orphan.c3d"
    path.write_bytes(bytes(data))
    with pytest.raises(RehabError, match="parameters of a group 47 that does not exist"):
        read_c3d_points(path)
