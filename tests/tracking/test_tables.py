"""Angles and status CSV files, the `rehab angles` file path, and C3D marker files."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.errors import RehabError
from content import content_path
from tracking.angles import ANGLE_COLUMNS, REQUIRED_MARKERS, MissingMarkersError, joint_angles
from tracking.io.c3d import C3dError, read_c3d_points, write_c3d
from tracking.marker_status import MarkerStatus
from tracking.io.csv_tables import (
    AnglesTable,
    StatusTable,
    TableError,
    angles_csv_from_trc,
    read_angles_csv,
    read_status_csv,
    write_angles_csv,
    write_status_csv,
)
from tracking.io.trc import write_trc


def angle_values(n_frames: int = 5, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    angles = {c: rng.uniform(-180.0, 180.0, n_frames) for c in ANGLE_COLUMNS}
    angles["right_shoulder_horizontal_flexion"][1] = np.nan
    angles["trunk_lateral_lean"][:] = np.nan  # the last column empty: rows end in a comma
    angles["left_forearm_supination"][0] = -0.0001  # rounds to -0.000
    return angles


def assert_one_line_error(info, path, message: str):
    text = str(info.value)
    assert isinstance(info.value, RehabError)
    assert "\n" not in text and text.startswith(str(path)), text
    assert message in text, text


# ------------------------------------------------------------------------------ angles CSV


def test_marker_status_codes():
    assert [int(s) for s in MarkerStatus] == [0, 1, 2]
    assert [s.label for s in MarkerStatus] == ["lost", "measured", "estimated"]
    assert MarkerStatus.from_label(" Measured ") is MarkerStatus.MEASURED
    with pytest.raises(ValueError, match="lost, measured, estimated"):
        MarkerStatus.from_label("guessed")


def test_angles_header_and_row_format(tmp_path):
    path = tmp_path / "angles.csv"
    frames = np.arange(5)
    write_angles_csv(path, frames, frames / 30.0, angle_values())
    lines = path.read_text().split("\n")
    assert lines[0] == "frame,time," + ",".join(ANGLE_COLUMNS)
    assert lines[0].startswith("frame,time,left_shoulder_flexion,left_shoulder_abduction,")
    assert lines[0].endswith(",right_forearm_supination,trunk_forward_lean,trunk_lateral_lean")
    cells = lines[2].split(",")
    assert cells[0] == "1" and cells[1] == "0.033333"
    assert len(cells) == 2 + len(ANGLE_COLUMNS)
    assert cells[2 + ANGLE_COLUMNS.index("right_shoulder_horizontal_flexion")] == ""
    assert cells[-1] == ""
    assert all(len(c.split(".")[1]) == 3 for c in cells[2:-1] if c)
    assert len(lines) == 7 and lines[-1] == ""


def test_angles_round_trip(tmp_path):
    path = tmp_path / "angles.csv"
    angles = angle_values(40, seed=3)
    frames = np.arange(100, 140)
    write_angles_csv(path, frames, (frames - 100) / 15.0, angles)
    table = read_angles_csv(path)
    assert isinstance(table, AnglesTable)
    np.testing.assert_array_equal(table.frames, frames)
    np.testing.assert_allclose(table.times_s, (frames - 100) / 15.0, atol=1e-6)
    assert list(table.angles) == list(ANGLE_COLUMNS)
    for c in ANGLE_COLUMNS:
        np.testing.assert_allclose(table.angles[c], angles[c], atol=5e-4, equal_nan=True)


def test_angles_from_joint_angles_directly(tmp_path):
    path = tmp_path / "angles.csv"
    p = np.random.default_rng(1).normal(size=(3, 14, 3))
    write_angles_csv(path, [0, 1, 2], [0.0, 0.1, 0.2], joint_angles(p, REQUIRED_MARKERS))
    assert read_angles_csv(path).frames.tolist() == [0, 1, 2]


def test_angles_writer_needs_every_column(tmp_path):
    angles = angle_values()
    del angles["trunk_forward_lean"]
    with pytest.raises(ValueError, match="trunk_forward_lean"):
        write_angles_csv(tmp_path / "a.csv", np.arange(5), np.arange(5) / 30, angles)
    with pytest.raises(ValueError, match="frames"):
        write_angles_csv(tmp_path / "a.csv", np.arange(4), np.arange(5) / 30, angle_values())


def test_angles_reader_keeps_other_columns_and_tolerates_crlf(tmp_path):
    path = tmp_path / "a.csv"
    path.write_bytes(b"frame,time,right_elbow_flexion,custom\r\n0,0,10.5,\r\n\r\n1,0.1,,3\r\n")
    table = read_angles_csv(path)
    assert list(table.angles) == ["right_elbow_flexion", "custom"]
    np.testing.assert_allclose(table.angles["right_elbow_flexion"], [10.5, np.nan])
    np.testing.assert_allclose(table.angles["custom"], [np.nan, 3.0])


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "empty"),
        ("time,frame,x\n", "not a joint-angles CSV"),
        ("frame,time,a,a\n", "more than once"),
        ("frame,time,a\n0,0,abc\n", "line 2: a 'abc' is not a number"),
        ("frame,time,a\n0,0,1\n1.5,0,1\n", "line 3: the frame cell"),
        ("frame,time,a\n0,,1\n", "line 2: the time cell"),
        ("frame,time,a\n0,0,1,2\n", "line 2 has 4 cells"),
    ],
)
def test_angles_reader_errors(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(TableError) as info:
        read_angles_csv(path)
    assert_one_line_error(info, path, message)


def test_angles_reader_missing_file(tmp_path):
    with pytest.raises(TableError, match="no such file"):
        read_angles_csv(tmp_path / "none.csv")


# ------------------------------------------------------------------------------ rehab angles


def test_angles_csv_from_trc_matches_joint_angles(tmp_path):
    rng = np.random.default_rng(4)
    p = rng.normal(size=(6, 14, 3)) * 300.0
    p[2, 5] = np.nan
    trc = tmp_path / "markers.trc"
    write_trc(trc, REQUIRED_MARKERS, p, 30.0)
    out = tmp_path / "angles.csv"
    assert angles_csv_from_trc(trc, out) == 6
    table = read_angles_csv(out)
    expected = joint_angles(p, REQUIRED_MARKERS)
    for c in ANGLE_COLUMNS:
        np.testing.assert_allclose(table.angles[c], expected[c], atol=2e-3, equal_nan=True)
    np.testing.assert_array_equal(table.frames, np.arange(6))


def test_angles_csv_from_trc_names_missing_markers(tmp_path):
    names = [n for n in REQUIRED_MARKERS if n not in ("MRW2", "MLW2")]
    trc = tmp_path / "markers.trc"
    write_trc(trc, names, np.zeros((2, len(names), 3)), 30.0)
    with pytest.raises(MissingMarkersError) as info:
        angles_csv_from_trc(trc, tmp_path / "angles.csv")
    assert str(info.value).startswith("markers.trc lacks MLW2, MRW2 (it has MB, MP, ")
    assert not (tmp_path / "angles.csv").exists()


VICON_NAMES = {"MB": "STER", "MP": "XIPH", "MRS": "RSHO", "MLS": "LSHO", "MRE1": "RELB", "MRE2": "RMEL",
               "MLE1": "LELB", "MLE2": "LMEL", "MRW1": "RWRA", "MRW2": "RWRB", "MLW1": "LWRA", "MLW2": "LWRB",
               "MRH": "RASI", "MLH": "LASI"}


def test_rehab_angles_map_renames_other_marker_sets(tmp_path, capsys):
    from game.cli import main

    rng = np.random.default_rng(3)
    p = rng.uniform(-500, 500, size=(4, 14, 3))
    theirs = [VICON_NAMES[n] for n in REQUIRED_MARKERS]
    trc = tmp_path / "vicon.trc"
    write_trc(trc, ["EXTRA", *theirs[::-1]], np.concatenate([p[:, :1], p[:, ::-1]], axis=1), 100.0)
    mapping = tmp_path / "map.yaml"
    mapping.write_text("".join(f"{ours}: {name}  # the file's name\n" for ours, name in VICON_NAMES.items()))
    assert main(["angles", str(trc), "--out", str(tmp_path / "a.csv"), "--map", str(mapping)]) == 0
    table = read_angles_csv(tmp_path / "a.csv")
    expected = joint_angles(p, REQUIRED_MARKERS)
    for c in ANGLE_COLUMNS:
        np.testing.assert_allclose(table.angles[c], expected[c], atol=2e-3, equal_nan=True)
    # without the map: wanted and found names in one line
    assert main(["angles", str(trc), "--out", str(tmp_path / "b.csv")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "lacks MB, MP," in err and "(it has EXTRA, RASI, LASI," in err and "--map" in err
    # a map naming a marker the file lacks
    mapping.write_text("MB: STERNUM\nMP: XIPH\n")
    assert main(["angles", str(trc), "--out", str(tmp_path / "c.csv"), "--map", str(mapping)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "lacks STERNUM (for MB) named in the --map file (it has EXTRA, RASI" in err


@pytest.mark.parametrize("text, needle", [
    ("MB: [1, 2]\n", "expected lines"),
    ("- MB\n", "expected lines"),
    ("HEAD: STER\n", "HEAD not used by the angles: the keys are the names MB, MP"),
    ("MB: STER\nMP: STER\n", "STER mapped to more than one marker"),
    ("MB: [\n", "invalid YAML"),
    (None, "no such file"),
])
def test_marker_map_errors_are_one_line(tmp_path, text, needle):
    from tracking.io.csv_tables import read_marker_map

    path = tmp_path / "map.yaml"
    if text is not None:
        path.write_text(text)
    with pytest.raises(TableError) as info:
        read_marker_map(path)
    assert_one_line_error(info, path, needle)


def test_rehab_angles_command_writes_csv_and_reports_missing_markers(tmp_path, capsys):
    from game.cli import main

    trc = tmp_path / "m.trc"
    write_trc(trc, REQUIRED_MARKERS, np.ones((1, 14, 3)), 30.0)
    assert main(["angles", str(trc), "--out", str(tmp_path / "a.csv")]) == 0
    assert read_angles_csv(tmp_path / "a.csv").frames.tolist() == [0]
    bad = tmp_path / "bad.trc"
    write_trc(bad, REQUIRED_MARKERS[:-1], np.ones((1, 13, 3)), 30.0)
    assert main(["angles", str(bad), "--out", str(tmp_path / "b.csv")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "MRH" in err


# ------------------------------------------------------------------------------ status CSV

NAMES = ("MB", "MRE2", "nano")  # a lower-case 'nan' in a name must survive


def status_data(n_frames: int = 4):
    rng = np.random.default_rng(5)
    p = rng.uniform(-1000, 1000, size=(n_frames, len(NAMES), 3))
    s = np.full((n_frames, len(NAMES)), MarkerStatus.MEASURED, dtype=np.uint8)
    s[1, 1] = MarkerStatus.LOST
    p[1, 1] = np.nan
    s[2, 2] = MarkerStatus.ESTIMATED
    return np.arange(n_frames), np.arange(n_frames) / 15.0, p, s


def test_status_header_and_rows(tmp_path):
    path = tmp_path / "status.csv"
    frames, times, p, s = status_data()
    write_status_csv(path, frames, times, NAMES, p, s)
    lines = path.read_text().split("\n")
    assert lines[0] == "frame,time,marker,x_mm,y_mm,z_mm,status"
    assert len(lines) == 1 + 4 * 3 + 1
    assert lines[1].startswith("0,0.000000,MB,") and lines[1].endswith(",measured")
    assert lines[5] == "1,0.066667,MRE2,,,,lost"
    assert lines[9].startswith("2,0.133333,nano,") and lines[9].endswith(",estimated")
    assert lines[1].split(",")[3] == f"{p[0, 0, 0]:.4f}"


def test_status_round_trip(tmp_path):
    path = tmp_path / "status.csv"
    frames, times, p, s = status_data(30)
    write_status_csv(path, frames + 7, times, NAMES, p, s)
    table = read_status_csv(path)
    assert isinstance(table, StatusTable)
    assert table.names == NAMES
    np.testing.assert_array_equal(table.frames, frames + 7)
    np.testing.assert_allclose(table.times_s, times, atol=1e-6)
    np.testing.assert_allclose(table.positions_mm, p, atol=1e-4, equal_nan=True)
    np.testing.assert_array_equal(table.status, s)
    assert table.status.dtype == np.uint8


def test_status_reader_fills_absent_rows_as_lost(tmp_path):
    path = tmp_path / "status.csv"
    path.write_text("frame,time,marker,x_mm,y_mm,z_mm,status\n"
                    "0,0,A,1,2,3,measured\n0,0,B,4,5,6,estimated\n1,0.1,B,7,8,9,measured\n")
    table = read_status_csv(path)
    assert table.names == ("A", "B")
    np.testing.assert_array_equal(table.status, [[1, 2], [0, 1]])
    assert np.isnan(table.positions_mm[1, 0]).all()
    np.testing.assert_allclose(table.positions_mm[1, 1], [7, 8, 9])


def test_status_writer_rejects_bad_input(tmp_path):
    frames, times, p, s = status_data()
    with pytest.raises(ValueError, match="status codes"):
        write_status_csv(tmp_path / "s.csv", frames, times, NAMES, p, s + 5)
    with pytest.raises(ValueError, match="positions_mm"):
        write_status_csv(tmp_path / "s.csv", frames, times, NAMES, p[:, :2], s)
    with pytest.raises(ValueError, match="CSV cell"):
        write_status_csv(tmp_path / "s.csv", frames, times, ("A,B", "C", "D"), p, s)


HEADER = "frame,time,marker,x_mm,y_mm,z_mm,status\n"


@pytest.mark.parametrize(
    "text, message",
    [
        ("frame,time,marker,x,y,z,status\n", "not a status CSV"),
        (HEADER + "0,0,A,1,2,3,guessed\n", "line 2: status 'guessed' is not one of lost, measured, estimated"),
        (HEADER + "0,0,A,1,2,3,measured\n0,0,A,1,2,3,measured\n", "line 3: frame 0 has marker A twice"),
        (HEADER + "0,0,,1,2,3,measured\n", "line 2: the marker cell is empty"),
        (HEADER + "0,0,A,1,two,3,measured\n", "line 2: y_mm 'two' is not a number"),
        (HEADER + "x,0,A,1,2,3,measured\n", "line 2: frame 'x' is not a number"),
    ],
)
def test_status_reader_errors(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(TableError) as info:
        read_status_csv(path)
    assert_one_line_error(info, path, message)


# ------------------------------------------------------------------------------ C3D


def test_c3d_round_trip_with_nans_and_residuals(tmp_path):
    path = tmp_path / "markers.c3d"
    rng = np.random.default_rng(6)
    p = rng.uniform(-1500, 1500, size=(25, 14, 3))
    p[3, 4] = np.nan
    p[10:14, 13] = np.nan
    p[5, 2, 1] = np.nan  # one NaN coordinate: the marker is missing
    residuals = rng.uniform(0, 5, size=(25, 14))
    write_c3d(path, REQUIRED_MARKERS, p, 15.0, residuals=residuals)
    names, q, rate = read_c3d_points(path)
    assert names == REQUIRED_MARKERS and rate == 15.0
    expected = p.copy()
    expected[5, 2] = np.nan
    np.testing.assert_array_equal(np.isnan(q), np.isnan(expected))
    np.testing.assert_allclose(q, expected, rtol=1e-6, atol=1e-3, equal_nan=True)

    import ezc3d

    c3d = ezc3d.c3d(str(path))
    point = c3d["parameters"]["POINT"]
    # the fourth word as the C3D standard reads it: float -> signed integer, residual / 0.1 in the
    # low byte, -1 = missing (ezc3d 1.7 swaps the bytes; tests/tracking/test_c3d_readers.py)
    start = (int(point["DATA_START"]["value"][0]) - 1) * 512
    words = np.frombuffer(path.read_bytes()[start:start + 25 * 14 * 16], "<f4").reshape(25, 14, 4)[:, :, 3]
    words = words.astype(np.int32)
    assert (words[np.isnan(expected).any(axis=2)] == -1).all()
    present = ~np.isnan(expected).any(axis=2)
    np.testing.assert_allclose((words[present] & 0xFF) * 0.1, np.maximum(np.round(residuals[present], 1), 0.1),
                               atol=1e-3)
    assert point["UNITS"]["value"] == ["mm"]
    assert point["Y_SCREEN"]["value"] == ["+Y"] and point["X_SCREEN"]["value"] == ["+X"]
    # Missing points carry zero coordinates and residual -1 in the file, as C3D readers expect
    # (ezc3d itself returns NaN for them, so look at the bytes: 4 float32 per point and frame).
    import struct

    start = (int(point["DATA_START"]["value"][0]) - 1) * 512 + (3 * 14 + 4) * 16
    x, y, z, _ = struct.unpack("<4f", path.read_bytes()[start:start + 16])
    assert (x, y, z) == (0.0, 0.0, 0.0)


def test_c3d_default_residuals_and_label_selection(tmp_path):
    path = tmp_path / "m.c3d"
    p = np.arange(2 * 3 * 3, dtype=float).reshape(2, 3, 3)
    write_c3d(path, ["Sub:MB", "MP", "X"], p, 100.0)
    names, q, rate = read_c3d_points(path, labels=["MP", "MB"])
    assert names == ("MP", "MB") and rate == 100.0
    np.testing.assert_allclose(q, p[:, [1, 0]])
    with pytest.raises(C3dError) as info:
        read_c3d_points(path, labels=["MB", "MRW2"])
    assert_one_line_error(info, path, "lacks markers MRW2 (it has Sub:MB, MP, X)")


def test_c3d_reads_a_real_vicon_capture():
    path = content_path("captures", "ezc3d_vicon_upper_limb.c3d")
    names, q, rate = read_c3d_points(path, labels=["STER", "XIPH", "STYLu"])
    assert rate == 100.0 and q.shape == (580, 3, 3)
    assert names == ("STER", "XIPH", "STYLu")
    assert 0 < np.isnan(q[:, 2, 0]).sum() < 100  # STYLu has gaps
    assert np.isfinite(q[:, 0]).all()
    assert 50 < np.linalg.norm(q[0, 0] - q[0, 1]) < 400  # sternum to xiphoid, millimetres


@pytest.mark.parametrize("content, message", [(b"not a c3d", "not a readable C3D file"), (None, "no such file")])
def test_c3d_read_errors(tmp_path, content, message):
    path = tmp_path / "bad.c3d"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(C3dError) as info:
        read_c3d_points(path)
    assert_one_line_error(info, path, message)


def test_c3d_writer_rejects_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="positions_mm"):
        write_c3d(tmp_path / "m.c3d", ["A"], np.zeros((2, 2, 3)), 30.0)
    with pytest.raises(ValueError, match="unique"):
        write_c3d(tmp_path / "m.c3d", ["A", "A"], np.zeros((2, 2, 3)), 30.0)
    with pytest.raises(ValueError, match="residuals"):
        write_c3d(tmp_path / "m.c3d", ["A"], np.zeros((2, 1, 3)), 30.0, residuals=-np.ones((2, 1)))
