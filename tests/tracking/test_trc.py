"""TRC files: header exactly as OpenSim writes it, round trips with gaps, other tools' files, errors."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.errors import RehabError
from tracking.io.trc import TrcData, TrcError, read_trc, write_trc

NAMES = ("MB", "MP", "MRW2")


def positions(n_frames: int = 4, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1500.0, 1500.0, size=(n_frames, len(NAMES), 3))
    p[1, 2] = np.nan  # last marker lost: the row ends in empty cells
    p[2, 0] = np.nan
    return p


def test_header_lines_exactly_as_opensim(tmp_path):
    path = tmp_path / "markers.trc"
    write_trc(path, NAMES, positions(), 30.0)
    lines = path.read_text().split("\n")
    assert lines[0] == "PathFileType\t4\t(X/Y/Z)\tmarkers.trc"
    assert lines[1] == "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames"
    assert lines[2] == "30\t30\t4\t3\tmm\t30\t1\t4"  # OpenSim counts frames from 1
    assert lines[3] == "Frame#\tTime\tMB\t\t\tMP\t\t\tMRW2\t\t\t"
    assert lines[4] == "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\tX3\tY3\tZ3\t"
    assert lines[5] == ""
    assert len(lines) == 6 + 4 + 1 and lines[-1] == ""  # four rows and the final newline


def test_rows_have_empty_cells_for_missing_markers(tmp_path):
    path = tmp_path / "m.trc"
    p = positions()
    write_trc(path, NAMES, p, 30.0)
    rows = path.read_text().split("\n")[6:10]
    cells = [row.split("\t") for row in rows]
    assert all(len(c) == 2 + 9 + 1 and c[-1] == "" for c in cells)  # every cell followed by a tab
    assert cells[1][8:11] == ["", "", ""]
    assert cells[2][2:5] == ["", "", ""]
    assert cells[0][0] == "1" and cells[0][1] == "0.000000"
    assert cells[3][1] == "0.100000"
    assert float(cells[0][2]) == pytest.approx(p[0, 0, 0], abs=1e-4)


def test_round_trip_with_nans(tmp_path):
    path = tmp_path / "m.trc"
    p = positions(50, seed=1)
    write_trc(path, NAMES, p, 60.0)
    data = read_trc(path)
    assert isinstance(data, TrcData)
    assert data.names == NAMES
    assert data.rate_hz == 60.0
    np.testing.assert_array_equal(data.frame_numbers, np.arange(1, 51))
    np.testing.assert_array_equal(data.frame_indices, np.arange(50))
    np.testing.assert_allclose(data.times_s, np.arange(50) / 60.0, atol=1e-6)
    np.testing.assert_array_equal(np.isnan(data.positions_mm), np.isnan(p))
    np.testing.assert_allclose(data.positions_mm, p, atol=1e-4, equal_nan=True)
    assert data.positions_mm.shape == (50, 3, 3) and data.n_frames == 50
    np.testing.assert_allclose(data.marker("MP"), p[:, 1], atol=1e-4)
    with pytest.raises(ValueError):
        data.positions_mm[0, 0, 0] = 1.0  # read-only


def test_partial_nan_blanks_the_whole_marker(tmp_path):
    path = tmp_path / "m.trc"
    p = positions()
    p[0, 1, 2] = np.nan
    write_trc(path, NAMES, p, 30.0)
    assert np.isnan(read_trc(path).positions_mm[0, 1]).all()


def test_explicit_frames_and_times(tmp_path):
    path = tmp_path / "m.trc"
    write_trc(path, NAMES, positions(), 29.97, frame_numbers=[10, 11, 12, 14], times_s=[1.0, 1.5, 2.0, 3.0])
    lines = path.read_text().split("\n")
    assert lines[2] == "29.97\t29.97\t4\t3\tmm\t29.97\t10\t4"
    data = read_trc(path)
    np.testing.assert_array_equal(data.frame_numbers, [10, 11, 12, 14])
    np.testing.assert_allclose(data.times_s, [1.0, 1.5, 2.0, 3.0])
    assert data.rate_hz == pytest.approx(29.97)
    write_trc(path, NAMES, positions(), 20.0, frame_numbers=[5, 6, 7, 8])
    np.testing.assert_allclose(read_trc(path).times_s, [0.0, 0.05, 0.1, 0.15])


def test_files_written_from_frame_0_still_read(tmp_path):
    """Files of this project's earlier versions count Frame# from 0 (OrigDataStartFrame 0)."""
    path = tmp_path / "old.trc"
    write_trc(path, NAMES, positions(), 30.0)
    text = path.read_text().split("\n")
    text[2] = text[2].replace("\t30\t1\t4", "\t30\t0\t4")
    text[6:10] = [str(int(r.split("\t", 1)[0]) - 1) + "\t" + r.split("\t", 1)[1] for r in text[6:10]]
    path.write_text("\n".join(text))
    data = read_trc(path)
    np.testing.assert_array_equal(data.frame_numbers, np.arange(4))
    np.testing.assert_array_equal(data.frame_indices, np.arange(4))
    assert data.frame_base == 0


def test_opensim_reads_the_file_with_frames_from_1(tmp_path):
    """OpenSim's own TRC reader (where the opensim package is installed): labels, rate, frames, gaps."""
    opensim = pytest.importorskip("opensim")
    path = tmp_path / "m.trc"
    p = positions()
    write_trc(path, NAMES, p, 30.0)
    table = opensim.TimeSeriesTableVec3(str(path))
    assert tuple(table.getColumnLabels()) == NAMES
    assert table.getNumRows() == 4 and table.getTableMetaDataAsString("DataRate") == "30"
    assert table.getTableMetaDataAsString("OrigDataStartFrame") == "1"
    for j in range(3):
        column = table.getDependentColumnAtIndex(j)
        for i in range(4):
            v = column[i]
            got = np.array([v.get(0), v.get(1), v.get(2)])
            np.testing.assert_allclose(got, p[i, j], atol=1e-4, equal_nan=True)


def test_zero_frames(tmp_path):
    path = tmp_path / "m.trc"
    write_trc(path, NAMES, np.empty((0, 3, 3)), 30.0)
    data = read_trc(path)
    assert data.names == NAMES and data.positions_mm.shape == (0, 3, 3)


def test_writer_rejects_bad_arguments(tmp_path):
    path = tmp_path / "m.trc"
    with pytest.raises(ValueError, match="positions_mm"):
        write_trc(path, NAMES, np.zeros((2, 2, 3)), 30.0)
    with pytest.raises(ValueError, match="duplicate"):
        write_trc(path, ("A", "A", "B"), np.zeros((2, 3, 3)), 30.0)
    with pytest.raises(ValueError, match="name"):
        write_trc(path, ("A", "B\tC", "D"), np.zeros((2, 3, 3)), 30.0)
    with pytest.raises(ValueError, match="rate"):
        write_trc(path, NAMES, np.zeros((2, 3, 3)), 0.0)
    with pytest.raises(ValueError, match="frame_numbers"):
        write_trc(path, NAMES, np.zeros((2, 3, 3)), 30.0, frame_numbers=[1])
    with pytest.raises(ValueError, match="finite"):
        write_trc(path, NAMES, np.full((2, 3, 3), np.inf), 30.0)


# An OpenSim-written file (header, trailing tabs, 16-digit numbers, 1-based frames).
OPENSIM = (
    "PathFileType\t4\t(X/Y/Z)\t/home/user/walk.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
    "100\t100\t2\t2\tmm\t100\t1\t2\n"
    "Frame#\tTime\tR.Shoulder\t\t\tL Elbow\t\t\t\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\t\n"
    "\n"
    "1\t0\t1.234567890123457\t2\t3\t4\t5\t6\t\n"
    "2\t0.01\t7\t8\t9\t\t\t\t\n"
)


def test_reads_opensim_file(tmp_path):
    path = tmp_path / "walk.trc"
    path.write_text(OPENSIM)
    data = read_trc(path)
    assert data.names == ("R.Shoulder", "L Elbow")
    np.testing.assert_array_equal(data.frame_numbers, [1, 2])
    np.testing.assert_allclose(data.times_s, [0.0, 0.01])
    np.testing.assert_allclose(data.positions_mm[0], [[1.234567890123457, 2, 3], [4, 5, 6]])
    assert np.isnan(data.positions_mm[1, 1]).all()


@pytest.mark.parametrize(
    "label, text",
    [
        ("CRLF line ends", OPENSIM.replace("\n", "\r\n")),
        ("no blank line", OPENSIM.replace("\t\n\n1\t", "\t\n1\t")),
        ("no trailing tabs", OPENSIM.replace("\t\n", "\n").replace("6\t\n", "6\n")),
        ("trailing empty cells dropped", OPENSIM.replace("9\t\t\t\t\n", "9\n")),
        ("NaN text", OPENSIM.replace("9\t\t\t\t\n", "9\tNaN\tNaN\tNaN\n")),
        ("blank line at the end", OPENSIM + "\n\n"),
        ("utf-8 BOM", "\ufeff" + OPENSIM),
        ("no X1 Y1 Z1 line", OPENSIM.replace("\t\tX1\tY1\tZ1\tX2\tY2\tZ2\t\n", "")),
    ],
)
def test_reads_files_of_other_tools(tmp_path, label, text):
    path = tmp_path / "other.trc"
    path.write_bytes(text.encode("utf-8"))
    data = read_trc(path)
    assert data.names == ("R.Shoulder", "L Elbow"), label
    assert data.positions_mm.shape == (2, 2, 3)
    np.testing.assert_allclose(data.positions_mm[1, 0], [7, 8, 9])
    assert np.isnan(data.positions_mm[1, 1]).all()


def test_metres_are_converted_to_millimetres(tmp_path):
    path = tmp_path / "pose2sim.trc"
    path.write_text(OPENSIM.replace("\tmm\t", "\tm\t"))
    np.testing.assert_allclose(read_trc(path).positions_mm[1, 0], [7000, 8000, 9000])


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "not a TRC file"),
        ("hello\tworld\n", "not a TRC file"),
        ("PathFileType\t4\t(X/Y/Z)\tx.trc\n", "header is incomplete"),
        (OPENSIM.replace("DataRate\tCameraRate", "Rate\tCamRate"), "line 2"),
        (OPENSIM.replace("100\t100\t2\t2\tmm\t100\t1\t2", "100\t100\t2"), "line 3"),
        (OPENSIM.replace("100\t100\t2", "fast\tfast\t2"), "DataRate"),
        (OPENSIM.replace("\tmm\t", "\tinches\t"), "Units 'inches'"),
        (OPENSIM.replace("Frame#\tTime", "Time\tFrame#"), "line 4"),
        (OPENSIM.replace("L Elbow", "R.Shoulder"), "more than once"),
        (OPENSIM.replace("\t8\t", "\tabc\t"), "line 8: 'abc' is not a number"),
        (OPENSIM.replace("9\t\t\t\t\n", "9\t1\t2\t3\t4\n"), "line 8 has 9 values"),
        (OPENSIM.replace("2\t0.01\t", "2\t\t"), "line 8: the Time cell"),
        (OPENSIM.replace("2\t0.01\t", "2.5\t0.01\t"), "Frame# 2.5"),
    ],
)
def test_malformed_files_give_one_line_errors(tmp_path, text, message):
    path = tmp_path / "bad.trc"
    path.write_text(text)
    with pytest.raises(TrcError) as info:
        read_trc(path)
    text = str(info.value)
    assert isinstance(info.value, RehabError)
    assert "\n" not in text
    assert text.startswith(str(path))
    assert message in text


def test_missing_file(tmp_path):
    with pytest.raises(TrcError, match="no such file"):
        read_trc(tmp_path / "absent.trc")


def test_latin1_names(tmp_path):
    path = tmp_path / "old.trc"
    path.write_bytes(OPENSIM.replace("L Elbow", "Ellbogen_\u00e4").encode("latin-1"))
    assert read_trc(path).names[1] == "Ellbogen_\u00e4"


def test_big_file_round_trip_is_fast(tmp_path):
    import time

    rng = np.random.default_rng(2)
    p = rng.normal(size=(3000, 14, 3)) * 500
    p[rng.random((3000, 14)) < 0.05] = np.nan
    names = [f"M{i}" for i in range(14)]
    path = tmp_path / "big.trc"
    start = time.perf_counter()
    write_trc(path, names, p, 30.0)
    data = read_trc(path)
    assert time.perf_counter() - start < 10.0
    np.testing.assert_allclose(data.positions_mm, p, atol=1e-4, equal_nan=True)
