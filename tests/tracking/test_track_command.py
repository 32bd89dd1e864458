"""rehab track with the tracker: labelled outputs, and one-line errors for bad input."""

import numpy as np
import pytest

from game.cli import main
from tracking.angles import joint_angles
from tracking.recording import RecordingWriter
from tracking.sim.body import ArmPose, reference_pose
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.tables import read_angles_csv, read_status_csv
from tracking.trc import read_trc


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
    """`--marker-color R,G,B R,G,B ...` (spec/INTERFACES.md) and the repeated flag give the same colours,
    also with the recording folder written after the colours."""
    import tracking.offline as offline

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
