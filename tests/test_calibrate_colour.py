"""rehab calibrate colour: the learnt colours saved in calibration.toml as [metadata.marker_colours], the
file still a valid calibration for every reader, and rehab track using the colours when present."""

import tomllib

import numpy as np
import pytest

from calibration.errors import CalibrationError
from calibration.files import load_calibration, read_metadata_section, write_metadata_section
from game.cli import main
from tests.test_colour_learn_cli import write_recording
from tracking.colour.adapt import calibration_colours
from tracking.markerset import load_markerset
from tracking.marker_status import MarkerStatus
from tracking.io.csv_tables import read_status_csv

CAST = (1.15, 1.0, 0.85)  # a warm cast the nominal table still identifies the reference pose under


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    rec = tmp_path_factory.mktemp("colour") / "rec"
    write_recording(rec, 4, exposure=0.8, cast=CAST)
    return rec


def test_colours_saved_in_the_calibration_and_used_by_track(recording, tmp_path, capsys, caplog):
    calib = recording / "calibration.toml"
    before = load_calibration(calib)
    out = tmp_path / "with_colours.toml"
    assert main(["calibrate", "colour", str(recording), "--out", str(out), "--frames", "3"]) == 0
    assert "[metadata.marker_colours]" in capsys.readouterr().out
    assert "marker_colours" not in calib.read_text()  # --out: the recording's own file is untouched
    # Still the same cameras for our reader; Pose2Sim / anipose skip [metadata]: the camera tables are unchanged.
    after = load_calibration(out)
    assert [c.name for c in after] == [c.name for c in before]
    assert all(np.array_equal(a.K, b.K) and np.array_equal(a.rvec, b.rvec) for a, b in zip(after, before))
    doc = tomllib.loads(out.read_text())
    assert set(doc) == {f"cam_{k + 1}" for k in range(len(before))} | {"metadata"}
    assert doc["metadata"]["adjusted"] is False and "error" in doc["metadata"]
    ms = load_markerset("upper_limb_seated")
    models, label_hs = calibration_colours(out, ms)
    assert len(models) == ms.palette.shape[0] and label_hs.shape == (256, 256) and label_hs.max() == len(models)
    # Learning again replaces the section (one section, not two).
    assert main(["calibrate", "colour", str(recording), "--calibration", str(out), "--frames", "2"]) == 0
    assert out.read_text().count("[metadata.marker_colours]") == 1 and len(load_calibration(out)) == len(before)

    # The learnt magenta is the cast one, not the nominal 304 deg.
    assert abs(models[ms.palette.tolist().index([225, 0, 210])].hue_deg - 304.0) > 5.0

    # rehab track picks the colours up from the calibration.
    status = tmp_path / "a.csv"
    with caplog.at_level("INFO", logger="tracking.drivers.offline"):
        assert main(["track", str(recording), "--calibration", str(out), "--status", str(status)]) == 0
    assert any("marker colours learnt into" in r.getMessage() for r in caplog.records)
    assert np.all(read_status_csv(status).status == MarkerStatus.MEASURED)


def test_the_extension_section_is_replaced_and_checked(recording, tmp_path):
    calib = tmp_path / "c.toml"
    calib.write_text((recording / "calibration.toml").read_text())
    assert read_metadata_section(calib, "x") is None
    write_metadata_section(calib, "x", "[metadata.x]\na = 1\n[metadata.x.sub]\nb = 2\n")
    write_metadata_section(calib, "x", "[metadata.x]\na = 3\n")
    assert read_metadata_section(calib, "x") == {"a": 3}
    assert len(load_calibration(calib)) == 4
    with pytest.raises(CalibrationError, match="may only hold tables"):
        write_metadata_section(calib, "x", "[metadata.x]\na = 1\n[cam_9]\nname = 'x'\n")
    with pytest.raises(CalibrationError, match="not valid TOML"):
        write_metadata_section(calib, "x", "[metadata.x\n")
    assert read_metadata_section(calib, "x") == {"a": 3}


def test_calibrate_colour_fails_in_one_line(tmp_path, capsys):
    assert main(["calibrate", "colour", str(tmp_path / "none")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such recording folder" in err[0]
