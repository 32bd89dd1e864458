"""rehab colour learn, rehab track --colours/--adapt-colours, and their one-line errors."""

import numpy as np

from game.cli import main
from tracking.io.recording import RecordingWriter
from tracking.sim.body import reference_pose
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.marker_status import MarkerStatus
from tracking.io.csv_tables import read_status_csv


def write_recording(folder, n, exposure=1.0, cast=(1.0, 1.0, 1.0)):
    studio, _ = studio_from_settings(SimulationSettings(motion="reference", size_px=(320, 240)))
    with studio:
        writer = RecordingWriter(folder, studio.cameras, 15.0)
        pose = reference_pose()
        for i in range(n):
            writer.write(studio.render(pose, i, i / 15.0, exposure=exposure, colour_cast=cast, noise_sigma=1.5,
                                       seed=i).frames.images)
        writer.close()
        writer.write_meta(studio.markerset.name, studio.markerset.rgb)


def test_learn_then_track_with_the_learned_colours(tmp_path, capsys):
    rec = tmp_path / "rec"
    write_recording(rec, 4, exposure=0.8, cast=(1.15, 1.0, 0.85))
    colours = tmp_path / "colours.toml"
    assert main(["colour", "learn", str(rec), "--out", str(colours), "--frames", "3"]) == 0
    out = capsys.readouterr().out
    assert "learned from 3 frame sets" in out and colours.exists()
    status = tmp_path / "s.csv"
    assert main(["track", str(rec), "--colours", str(colours), "--adapt-colours", "--status", str(status)]) == 0
    codes = read_status_csv(status).status
    assert codes.shape == (4, 14) and np.all(codes == MarkerStatus.MEASURED)


def test_colour_commands_fail_in_one_line(tmp_path, capsys):
    assert main(["colour", "learn", str(tmp_path / "nothing"), "--out", str(tmp_path / "c.toml")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rehab: error:")
    assert main(["colour", "drift-check", "--size", "big"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--size WxH" in err[0]
