"""rehab track with the tracker: labelled outputs, and one-line errors for bad input."""

import numpy as np
import pytest

from game.cli import main
from tracking.angles import joint_angles
from tracking.io.recording import RecordingWriter
from tracking.sim.body import ArmPose, reference_pose
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.io.csv_tables import read_angles_csv, read_status_csv
from tracking.io.trc import read_trc


def write_recording(folder, poses, size=(320, 240)):
    studio, _ = studio_from_settings(SimulationSettings(motion="reference", size_px=size))
    with studio:
        writer = RecordingWriter(folder, studio.cameras, 15.0)
        for i, pose in enumerate(poses):
            writer.write(studio.render(pose, i, i / 15.0, noise_sigma=1.5).frames.images)
        writer.close()
        writer.write_meta(studio.markerset.name, studio.markerset.rgb)


def test_labelled_outputs(tmp_path):
    write_recording(tmp_path / "rec", [reference_pose()] * 6)
    out = tmp_path / "out"
    assert main(["track", str(tmp_path / "rec"), "--out", str(out / "m.trc"), "--status", str(out / "s.csv"),
                 "--angles", str(out / "a.csv"), "--c3d", str(out / "m.c3d")]) == 0
    trc = read_trc(out / "m.trc")
    assert trc.n_frames == 6 and np.isfinite(trc.positions_mm).all()
    status = read_status_csv(out / "s.csv")
    assert (status.status == 1).all()  # every marker measured in the still reference pose
    angles = read_angles_csv(out / "a.csv")
    assert np.isfinite(angles.angles["right_elbow_flexion"]).all()
    # the tracker's angles: those of its positions (no axis guessed here)
    from_trc = joint_angles(trc.positions_mm, trc.names)
    for name, values in angles.angles.items():
        np.testing.assert_allclose(values, from_trc[name], atol=0.01)
    assert (out / "m.c3d").stat().st_size > 0


def test_field_formats_read_by_independent_readers(tmp_path):
    """C3D (the `c3d` package), .mot, BVH (the `bvh` package) and the detections CSV of one run."""
    import csv
    import warnings

    c3d = pytest.importorskip("c3d")
    bvh = pytest.importorskip("bvh")
    write_recording(tmp_path / "rec", [reference_pose()] * 5)
    out = tmp_path / "out"
    assert main(["track", str(tmp_path / "rec"), "--out", str(out / "m.trc"), "--c3d", str(out / "m.c3d"),
                 "--mot", str(out / "a.mot"), "--bvh", str(out / "s.bvh"), "--detections", str(out / "d.csv"),
                 "--angles", str(out / "a.csv")]) == 0
    trc = read_trc(out / "m.trc")
    np.testing.assert_array_equal(trc.frame_numbers, np.arange(1, 6))  # OpenSim counts from 1
    angles = read_angles_csv(out / "a.csv")
    with open(out / "m.c3d", "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = c3d.Reader(fh)
        frames = np.stack([p.copy() for _, p, _ in reader.read_frames()])
        assert [s.strip() for s in reader.get("EVENT:LABELS").string_array] == ["Identified"]
        angle_labels = [s.strip() for s in reader.get("POINT:ANGLES").string_array]
    m = len(trc.names)
    np.testing.assert_allclose(frames[:, :m, :3], trc.positions_mm, atol=1e-3)
    assert (frames[:, :m, 3] > 0).all()  # all measured in the still reference pose: residual > 0
    assert (frames[:, :m, 3] < 2.0).all()  # mean reprojection distance, mm: small on the simulator
    # the cameras whose centroids made each position (the identifying frame set's too, measured in
    # the full frame): at least two of the four
    masks = frames[:, :m, 4].astype(int)
    assert (masks < 16).all() and (np.array([bin(b).count("1") for b in masks.ravel()]) >= 2).all()
    k = angle_labels.index("right_elbow_flexion")
    np.testing.assert_allclose(frames[:, m + k, 0], angles.angles["right_elbow_flexion"], atol=1e-3)
    mot_lines = (out / "a.mot").read_text().splitlines()
    assert mot_lines[1:7] == ["version=3", "nRows=5", f"nColumns={1 + len(angle_labels)}", "inDegrees=yes",
                              "DataType=double", "endheader"]
    skeleton = bvh.Bvh((out / "s.bvh").read_text())
    assert skeleton.nframes == 5 and skeleton.frame_time == pytest.approx(1 / 15.0)
    # the upper arm as long as the tracked acromion-to-elbow-centre distances (mean of the sides, cm)
    upper_cm = np.mean([np.median(np.linalg.norm((trc.marker(f"M{s}E1") + trc.marker(f"M{s}E2")) / 2
                                                 - trc.marker(f"M{s}S"), axis=1)) for s in "RL"]) / 10.0
    assert skeleton.joint_offset("RightForeArm") == pytest.approx([0.0, -upper_cm, 0.0], abs=0.05)
    with open(out / "d.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["camera"] for r in rows} <= {"cam1", "cam2", "cam3", "cam4"} and len(rows) >= 4 * m * 2
    assert {int(r["frame"]) for r in rows} == set(range(5))


def test_recording_without_reference_pose_is_one_clear_line(tmp_path, capsys):
    raised = reference_pose().with_arm("right", ArmPose.clinical(flexion_deg=170)).with_arm(
        "left", ArmPose.clinical(flexion_deg=170))
    write_recording(tmp_path / "rec", [raised] * 4)
    assert main(["track", str(tmp_path / "rec"), "--out", str(tmp_path / "m.trc")]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]  # after the progress bar
    assert err.startswith("rehab: error:") and "reference pose" in err and "lower the" in err
    assert not (tmp_path / "m.trc").exists()


@pytest.mark.parametrize("argv_tail, needle", [
    (["--markerset", "no_such_set"], "no_such_set"),
    (["--marker-color", "1,2"], "R,G,B"),
])
def test_bad_options_are_one_line(tmp_path, capsys, argv_tail, needle):
    write_recording(tmp_path / "rec", [reference_pose()] * 2)
    assert main(["track", str(tmp_path / "rec"), "--out", str(tmp_path / "m.trc"), *argv_tail]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("rehab: error:") and needle in err


def test_marker_color_once_with_many_values_or_repeated(tmp_path, monkeypatch):
    """`--marker-color R,G,B R,G,B ...` (docs/INTERFACES.md) and the repeated flag give the same colours,
    also with the recording folder written after the colours."""
    import tracking.drivers.offline as offline

    seen = []
    monkeypatch.setattr(offline, "track_recording", lambda folder, **kw: seen.append((folder, kw["marker_colours"])) or "")
    colours = [f"{k},{2 * k},{3 * k}" for k in range(14)]
    rec, out = str(tmp_path / "rec"), str(tmp_path / "m.trc")
    assert main(["track", rec, "--out", out, "--marker-color", *colours]) == 0
    assert main(["track", rec, "--out", out, *[a for c in colours for a in ("--marker-color", c)]]) == 0
    assert main(["track", "--marker-color", *colours, rec, "--out", out]) == 0
    assert main(["track", rec, "--marker-color", "0,200,70", "--out", out]) == 0
    assert [str(f) for f, _ in seen] == [rec] * 4
    assert seen[0][1] == seen[1][1] == seen[2][1] == colours and seen[3][1] == ["0,200,70"]


def test_marker_color_fourteen_values_track(tmp_path):
    """The 14 colours of the marker set given with one flag track like the marker set's own."""
    write_recording(tmp_path / "rec", [reference_pose()] * 3)
    from tracking.markerset import load_markerset

    colours = [",".join(str(int(v)) for v in c) for c in load_markerset().rgb]
    assert main(["track", str(tmp_path / "rec"), "--marker-color", *colours, "--status", str(tmp_path / "s.csv")]) == 0
    assert (read_status_csv(tmp_path / "s.csv").status == 1).all()


def test_track_without_folder_is_one_line(capsys):
    assert main(["track", "--out", "m.trc"]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("rehab: error:") and "recording folder" in err


@pytest.fixture(scope="module")
def small_recording(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rec") / "rec"
    write_recording(folder, [reference_pose()] * 3)
    return folder


def test_outputs_in_a_missing_folder_are_written_there(small_recording, tmp_path):
    out = tmp_path / "new" / "folder"
    assert main(["track", str(small_recording), "--out", str(out / "m.trc"), "--mot", str(out / "a.mot")]) == 0
    assert read_trc(out / "m.trc").n_frames == 3 and (out / "a.mot").stat().st_size > 0
    assert sorted(p.name for p in out.iterdir()) == ["a.mot", "m.trc"]   # no temporary file left


@pytest.mark.parametrize("writer, option, name", [
    ("tracking.io.opensim_mot.write_mot", "--mot", "a.mot"),
    ("tracking.io.trc.write_trc", "--out", "m.trc"),
    ("tracking.io.c3d.write_c3d", "--c3d", "m.c3d"),
    ("tracking.io.bvh.write_bvh", "--bvh", "a.bvh"),
])
def test_a_failure_half_way_through_a_file_leaves_no_half_file(small_recording, tmp_path, monkeypatch, capsys,
                                                               writer, option, name):
    """The writer dies after writing part of the file (a full disk, a kill): the asked name keeps
    what it held before (here an older result), no half file and no temporary file is left."""
    import importlib

    module_name, fn = writer.rsplit(".", 1)
    module = importlib.import_module(module_name)
    real = getattr(module, fn)

    def fails_half_way(path, *args, **kwargs):
        real(path, *args, **kwargs)
        with open(path, "r+b") as fh:
            fh.truncate(max(1, fh.seek(0, 2) // 2))
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(module, fn, fails_half_way)
    if fn == "write_trc":   # offline imports it by name when it writes
        import tracking.drivers.offline  # noqa: F401
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_text("an older result\n")
    code = main(["track", str(small_recording), option, str(out / name)])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 1 and err.startswith("rehab: error:") and "No space left" in err, err
    assert (out / name).read_text() == "an older result\n"
    assert sorted(p.name for p in out.iterdir()) == [name]
