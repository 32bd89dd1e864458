"""``rehab simulate-calibration`` then ``rehab calibrate intrinsics|extrinsics|wand`` on its output."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml

from calibration.extrinsics import rig_errors
from calibration.files import load_calibration, read_lens_information
from game.cli import main


@pytest.fixture(scope="module")
def material(tmp_path_factory):
    from tracking.sim.calibration_material import write_calibration_material
    from tracking.sim.rigs import load_rig

    out = tmp_path_factory.mktemp("material")
    cams = load_rig("ring4", (320, 240))
    write_calibration_material(out, cams, n_intrinsics=6, per_pair=1, wand_seconds=6.0, wand_fps=8.0)
    return out


def test_simulated_material_calibrates_end_to_end(material, tmp_path, capsys):
    truth = load_calibration(material / "truth_calibration.toml")
    meta = yaml.safe_load((material / "material.yaml").read_text())
    origin = ",".join(str(v) for v in meta["seat_board"]["origin_m"])
    (material / "intrinsics" / "cam2" / "zz_broken.png").write_bytes(b"\x89PNG broken")
    intr = tmp_path / "intrinsics.toml"
    assert main(["calibrate", "intrinsics", str(material / "intrinsics"), "--board", "9x6", "--square-mm", "60",
                 "--out", str(intr), "--opencv", str(tmp_path / "intrinsics.yaml")]) == 0
    out = capsys.readouterr().out
    assert "skipped zz_broken.png: not an image OpenCV can read" in out
    cams = load_calibration(intr)
    assert [c.name for c in cams] == ["cam1", "cam2", "cam3", "cam4"]
    assert all(abs(c.K[0, 0] / t.K[0, 0] - 1) < 0.01 for c, t in zip(cams, truth))  # 6 small images only
    assert len(load_calibration(tmp_path / "intrinsics.yaml")) == 4
    info = read_lens_information(intr, cams)   # how exact each lens is, for extrinsics --refine-lenses
    assert all(i is not None and i.shape == (8, 8) for i in info)

    board_calib = tmp_path / "board.toml"
    assert main(["calibrate", "extrinsics", str(material / "extrinsics"), "--intrinsics", str(intr), "--board", "9x6",
                 "--square-mm", "60", f"--origin={origin}", "--out", str(board_calib)]) == 0
    # six lens images each: the lens data are kept as the lens step found them (refined from 10 images on)
    assert "lens data kept as they are for cam1, cam2, cam3, cam4 (lens step from fewer than 10 images)" in capsys.readouterr().out
    assert load_calibration(board_calib)[1].K.tolist() == cams[1].K.tolist()
    pos, ang = rig_errors(load_calibration(board_calib), truth)
    assert pos.max() < 10.0 and ang.max() < 0.3  # the strict figures: test_calib_extrinsics.py

    wand_calib = tmp_path / "wand.toml"
    assert main(["calibrate", "wand", str(material / "wand"), "--intrinsics", str(intr), "--floor-views",
                 str(material / "extrinsics"), "--square-mm", "60", f"--origin={origin}", "--out", str(wand_calib)]) == 0
    out = capsys.readouterr().out
    rmse = float(out.split("wand length error ")[1].split(" mm")[0])
    assert rmse < 1.5
    pos, ang = rig_errors(load_calibration(wand_calib), truth)
    assert pos.max() < 20.0 and ang.max() < 0.5


@pytest.mark.parametrize("case, message", [
    ("missing", "no such folder"),
    ("empty", "holds no images"),
    ("blank", "was found in none of its 2 images"),
])
def test_bad_input_gives_one_line_errors(tmp_path, capsys, case, message):
    folder = tmp_path / "cam1"
    if case != "missing":
        folder.mkdir()
    if case == "blank":
        for k in range(2):
            cv2.imwrite(str(folder / f"{k}.png"), np.full((240, 320), 128, np.uint8))
    code = main(["calibrate", "intrinsics", str(folder if case != "empty" else tmp_path), "--board", "9x6",
                 "--square-mm", "25", "--out", str(tmp_path / "x.toml")])
    err = capsys.readouterr().err
    assert code == 1 and message in err and len(err.strip().splitlines()) == 1


def test_bad_board_and_output_names_give_one_line_errors(material, tmp_path, capsys):
    assert main(["calibrate", "intrinsics", str(material / "intrinsics"), "--board", "8x6", "--square-mm", "60",
                 "--out", str(tmp_path / "x.toml")]) == 1
    assert "even and the other odd" in capsys.readouterr().err
    assert main(["calibrate", "extrinsics", str(material / "extrinsics"), "--intrinsics",
                 str(material / "truth_calibration.toml"), "--board", "9x6", "--square-mm", "60", "--floor", "nope",
                 "--out", str(tmp_path / "x.toml")]) == 1
    assert "no image named 'nope'" in capsys.readouterr().err
    assert main(["calibrate", "extrinsics", str(material / "extrinsics"), "--intrinsics",
                 str(material / "truth_calibration.toml"), "--board", "9x6", "--square-mm", "60", "--refine-lenses",
                 "--out", str(tmp_path / "x.toml")]) == 1
    err = capsys.readouterr().err
    assert "does not say how exact its lens data are" in err and len(err.strip().splitlines()) == 1


def _extrinsics(material, tmp_path, *extra):
    out = tmp_path / "c.toml"
    code = main(["calibrate", "extrinsics", str(material / "extrinsics"), "--intrinsics", str(material / "truth_calibration.toml"),
                 "--board", "9x6", "--square-mm", "60", *extra, "--out", str(out)])
    return code, out


def test_world_frame_options_and_a_separate_floor_folder(material, tmp_path, capsys):
    """--origin (first inner corner, negative without '='), --board-centre, --floor-views: one world frame."""
    import shutil

    truth = load_calibration(material / "truth_calibration.toml")
    meta = yaml.safe_load((material / "material.yaml").read_text())
    origin = np.array(meta["seat_board"]["origin_m"])
    assert origin[0] < 0  # the simulator's board is centred on the seat: corner 0 at negative X
    code, out = _extrinsics(material, tmp_path, "--origin", ",".join(map(str, origin)))
    assert code == 0
    text = capsys.readouterr().out
    pos, ang = rig_errors(load_calibration(out), truth)
    assert pos.max() < 10.0 and ang.max() < 0.3
    # quiet: the images of cameras that do not face a view are summed up in one line
    assert "(--list-skipped names them)" in text or text.count("  skipped ") <= 5
    assert len(text.strip().splitlines()) <= 4 + 1 + 5 + 1
    centre = origin + np.array([4 * 0.06, 0.0, 2.5 * 0.06])  # 9x6 corners of 60 mm: centre 4 and 2.5 squares in
    assert np.allclose(centre[[0, 2]], 0.0, atol=1e-9)
    views = tmp_path / "views"
    floor = tmp_path / "floor"
    for cam in truth:
        shutil.copytree(material / "extrinsics" / cam.name, views / cam.name, ignore=shutil.ignore_patterns("seat.png"))
        (floor / cam.name).mkdir(parents=True)
        shutil.copy(material / "extrinsics" / cam.name / "seat.png", floor / cam.name / "seat.png")
    out2 = tmp_path / "c2.toml"
    assert main(["calibrate", "extrinsics", str(views), "--intrinsics", str(material / "truth_calibration.toml"), "--board",
                 "9x6", "--square-mm", "60", "--board-centre", ",".join(map(str, centre)), "--floor-views", str(floor),
                 "--out", str(out2)]) == 0
    for a, b in zip(load_calibration(out), load_calibration(out2)):
        assert np.allclose(a.centre_m, b.centre_m, atol=1e-9) and np.allclose(a.R, b.R, atol=1e-9)
    assert main(["calibrate", "extrinsics", str(views), "--intrinsics", str(material / "truth_calibration.toml"), "--board",
                 "9x6", "--square-mm", "60", "--out", str(out2)]) == 1
    assert "no image named 'seat'" in capsys.readouterr().err
    # the floor board named on its own (as after ChArUco views): the rig solved first, then placed by it
    out3 = tmp_path / "c3.toml"
    assert main(["calibrate", "extrinsics", str(views), "--intrinsics", str(material / "truth_calibration.toml"), "--board",
                 "9x6", "--square-mm", "60", "--floor-views", str(floor), "--floor-board", "9x6:60",
                 "--board-centre", ",".join(map(str, centre)), "--out", str(out3)]) == 0
    pos, ang = rig_errors(load_calibration(out3), truth)
    assert pos.max() < 10.0 and ang.max() < 0.3


def test_a_held_board_taken_for_the_floor_board_is_refused(material, tmp_path, capsys):
    """The first shared view (a board held up between two cameras) named as the floor view: the
    world frame it gives puts cameras below the floor or facing away, and nothing is written."""
    code, out = _extrinsics(material, tmp_path, "--floor", "000")
    err = capsys.readouterr().err
    assert code == 1 and not out.exists()
    assert len(err.strip().splitlines()) == 1 and any(w in err for w in ("below the floor", "away from the floor board", "on its side"))
    assert "--floor" in err
