"""Recording folders: reading, writing, and one-line errors for bad input."""

import cv2
import numpy as np
import pytest
import yaml

from calibration.errors import RehabError
from game.cli import main
from tracking.io.recording import Recording, RecordingWriter
from tracking.sim.rigs import load_rig


def make_recording(folder, n_frames=3, size=(160, 120), images=False, n_cams=3):
    cams = load_rig("tri3", size)[:n_cams]
    w = RecordingWriter(folder, cams, 15.0, images=images)
    rng = np.random.default_rng(0)
    for _ in range(n_frames):
        w.write([rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8) for _ in cams])
    w.close()
    w.write_meta("upper_limb_seated", np.zeros((14, 3), np.uint8) + 200)
    return cams


@pytest.mark.parametrize("images", [False, True])
def test_round_trip_is_lossless(tmp_path, images):
    make_recording(tmp_path, images=images)
    with Recording(tmp_path) as rec:
        sets = list(rec)
    assert len(sets) == 3 and len(sets[0].images) == 3
    assert sets[1].time_s == pytest.approx(1 / 15)
    rng = np.random.default_rng(0)
    first = rng.integers(0, 255, (120, 160, 3), dtype=np.uint8)
    assert np.array_equal(sets[0].images[0], first)  # FFV1 and PNG are lossless


def one_line_error(capsys, argv):
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("rehab: error:") and "\n" not in err and "Traceback" not in err
    return err


def test_missing_calibration(tmp_path, capsys):
    make_recording(tmp_path)
    (tmp_path / "calibration.toml").unlink()
    err = one_line_error(capsys, ["track", str(tmp_path), "--points", str(tmp_path / "p.csv")])
    assert "calibration.toml" in err


def test_malformed_calibration(tmp_path, capsys):
    make_recording(tmp_path)
    (tmp_path / "calibration.toml").write_text("[cam_1]\nname = 'cam1'\nsize = [1, \n")
    err = one_line_error(capsys, ["track", str(tmp_path), "--points", str(tmp_path / "p.csv")])
    assert "calibration.toml" in err


def test_camera_count_mismatch(tmp_path, capsys):
    make_recording(tmp_path)
    (tmp_path / "cam3.avi").unlink()
    err = one_line_error(capsys, ["track", str(tmp_path), "--points", str(tmp_path / "p.csv")])
    assert "3 cameras" in err and "2 video" in err


def test_frame_size_mismatch(tmp_path, capsys):
    make_recording(tmp_path, images=True)
    for f in (tmp_path / "cam2").iterdir():
        cv2.imwrite(str(f), np.zeros((240, 320, 3), np.uint8))
    err = one_line_error(capsys, ["track", str(tmp_path), "--points", str(tmp_path / "p.csv")])
    assert "cam2" in err and "160x120" in err and "320x240" in err


def test_a_video_that_ends_early_leaves_the_others_tracked_to_their_end(tmp_path, caplog):
    make_recording(tmp_path, images=True, n_frames=4)
    sorted((tmp_path / "cam1").iterdir())[-1].unlink()
    with Recording(tmp_path) as rec:
        sets = list(rec)
        assert rec.ended_cameras == ("cam1",)
    assert len(sets) == 4 and not sets[3].images[0].any()   # cam1's last image black, said once
    assert caplog.text.count("cam1 ended at frame 3 while the other cameras go on") == 1


def test_missing_meta(tmp_path, capsys):
    make_recording(tmp_path)
    (tmp_path / "meta.yaml").unlink()
    err = one_line_error(capsys, ["track", str(tmp_path), "--points", str(tmp_path / "p.csv")])
    assert "meta.yaml" in err


def test_malformed_marker_colour(tmp_path, capsys):
    make_recording(tmp_path)
    err = one_line_error(capsys, ["track", str(tmp_path), "--points", str(tmp_path / "p.csv"), "--marker-color", "300,0"])
    assert "R,G,B" in err


def test_unknown_motion(tmp_path, capsys):
    err = one_line_error(capsys, ["simulate", str(tmp_path / "out"), "--motion", "cartwheel"])
    assert "cartwheel" in err and "right_external_rotation" in err


def test_not_a_recording_folder(tmp_path, capsys):
    err = one_line_error(capsys, ["track", str(tmp_path / "nowhere"), "--points", str(tmp_path / "p.csv")])
    assert "nowhere" in err
