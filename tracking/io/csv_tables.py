"""CSV tables of ``docs/INTERFACES.md``: joint angles and per-marker status.

Joint angles CSV (wide, one row per frame)::

    frame,time,left_shoulder_flexion,...,trunk_lateral_lean      (ANGLE_COLUMNS order)
    0,0.000000,12.345,...,                                      (degrees, 3 decimals; empty = NaN)

Status CSV (long, one row per frame and marker, markers in marker-set order)::

    frame,time,marker,x_mm,y_mm,z_mm,status
    0,0.000000,MB,12.3456,1234.5678,-80.0000,measured
    0,0.000000,MRE2,,,,lost

``status`` is ``measured`` (triangulated from this frame's images), ``estimated`` (hidden; the
position is an estimate) or ``lost`` (no position). Positions are millimetres, world frame.
Frames are the recording's frame indices and times are seconds, as in the TRC file.
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from calibration.errors import RehabError
from tracking.angles import ANGLE_COLUMNS, REQUIRED_MARKERS, MissingMarkersError, joint_angles, require_markers
from tracking.io.trc import read_trc
from tracking.marker_status import MarkerStatus

__all__ = [
    "ANGLES_HEADER", "STATUS_HEADER", "AnglesTable", "MarkerStatus", "StatusTable", "TableError",
    "angles_csv_from_trc", "read_angles_csv", "read_marker_map", "read_status_csv", "write_angles_csv",
    "write_status_csv",
]

ANGLES_HEADER: tuple[str, ...] = ("frame", "time") + ANGLE_COLUMNS
STATUS_HEADER: tuple[str, ...] = ("frame", "time", "marker", "x_mm", "y_mm", "z_mm", "status")
_ANGLE_FORMAT = "%.3f"
_POSITION_FORMAT = "%.4f"
_TIME_FORMAT = "%.6f"


class TableError(RehabError):
    """An angles or status CSV file cannot be read: missing or malformed."""


@dataclass(frozen=True, slots=True, eq=False)  # arrays: no elementwise __eq__
class AnglesTable:
    """A joint-angles CSV.

    Attributes:
        frames: (T,) int64 frame indices.
        times_s: (T,) float64 seconds.
        angles: column name -> (T,) float64 degrees (NaN where the file is empty), in file order;
            every column after ``frame,time`` (so files with other columns still read).
    """

    frames: np.ndarray
    times_s: np.ndarray
    angles: dict[str, np.ndarray]


@dataclass(frozen=True, slots=True, eq=False)  # arrays: no elementwise __eq__
class StatusTable:
    """A status CSV in array form.

    Attributes:
        frames: (T,) int64 frame indices, ascending as in the file.
        times_s: (T,) float64 seconds.
        names: the M marker names, in order of first appearance.
        positions_mm: (T, M, 3) float64 millimetres, NaN where empty (or no row for the marker).
        status: (T, M) uint8 :class:`MarkerStatus` codes (LOST where there is no row).
    """

    frames: np.ndarray
    times_s: np.ndarray
    names: tuple[str, ...]
    positions_mm: np.ndarray
    status: np.ndarray


# ------------------------------------------------------------------------------------ angles


def write_angles_csv(
    path: str | Path, frames: np.ndarray, times_s: np.ndarray, angles: Mapping[str, np.ndarray]
) -> None:
    """Write joint angles: ``frame,time,`` then :data:`~tracking.angles.ANGLE_COLUMNS`.

    Args:
        path: CSV file to write.
        frames: (T,) integer frame indices.
        times_s: (T,) times in seconds.
        angles: every name of ANGLE_COLUMNS -> (T,) degrees, NaN where undefined (as
            :func:`tracking.angles.joint_angles` returns; other keys are ignored).
    """
    missing = [c for c in ANGLE_COLUMNS if c not in angles]
    if missing:
        raise ValueError(f"angles lacks columns {missing}")
    f, t = _frames_times(frames, times_s)
    values = np.column_stack([np.broadcast_to(np.asarray(angles[c], dtype=np.float64), f.shape)
                              for c in ANGLE_COLUMNS]) if len(f) else np.empty((0, len(ANGLE_COLUMNS)))
    row_format = "%d," + _TIME_FORMAT + "," + ",".join([_ANGLE_FORMAT] * len(ANGLE_COLUMNS))
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(",".join(ANGLES_HEADER) + "\n")
        for frame, time, row in zip(f.tolist(), t.tolist(), values.tolist()):
            fh.write(_blank_nan(row_format % (frame, time, *row)) + "\n")


def read_angles_csv(path: str | Path) -> AnglesTable:
    """Read a joint-angles CSV; every column after ``frame,time`` is returned, empty = NaN."""
    path = Path(path)
    header, rows, lines = _read_csv(path)
    if header[:2] != ["frame", "time"] or len(header) < 3:
        raise TableError(f"{path}: not a joint-angles CSV: the header must start with frame,time, then angle columns")
    _check_unique(path, header)
    table = _to_float(path, header, rows, lines, range(len(header)))
    frames = _whole_numbers(path, table[:, 0], lines)
    times = _finite(path, table[:, 1], lines, "time")
    angles = {name: table[:, j] for j, name in enumerate(header) if j >= 2}
    return AnglesTable(frames=frames, times_s=times, angles=angles)


def angles_csv_from_trc(trc_path: str | Path, out_csv: str | Path, marker_map: Mapping[str, str] | None = None,
                        roles: Mapping[str, str] | None = None) -> int:
    """``rehab angles``: joint angles of every frame of a TRC file, written as an angles CSV.

    ``marker_map`` (from :func:`read_marker_map`) names the file's marker for each name the
    angles need (the rest keep their own names). ``roles`` (a marker set's ``MarkerSet.roles``,
    ``--markerset``): the file holds that marker set's names, and the angles take their markers
    from its roles (the columns it has no markers for are left empty). Raises
    :class:`~tracking.angles.MissingMarkersError` (one line, naming the markers wanted and those
    found) if the TRC lacks a marker the angles need. Returns the number of frames written.
    """

    trc = read_trc(trc_path)
    if trc.n_frames == 0:
        raise TableError(f"{trc_path}: the file has no frames: nothing to compute angles from")
    names = list(trc.names)
    source = Path(trc_path).name
    if marker_map:
        absent = {ours: theirs for ours, theirs in marker_map.items() if theirs not in names}
        if absent:
            shown = ", ".join(f"{theirs} (for {ours})" for ours, theirs in absent.items())
            raise MissingMarkersError(f"{source} lacks {shown} named in the --map file (it has {', '.join(names)})")
        renamed = {theirs: ours for ours, theirs in marker_map.items()}
        names = [renamed.get(n, n if n not in marker_map else f"{n} (unmapped)") for n in names]
    if roles is None:
        require_markers(names, source)
    else:
        absent = [name for name in roles.values() if name not in names]
        if absent:
            raise MissingMarkersError(f"{source} lacks {', '.join(absent)} (it has {', '.join(names) or 'no markers'}): "
                                      "the marker set's roles name them; give the marker set the file was made with")
    write_angles_csv(out_csv, trc.frame_indices, trc.times_s, joint_angles(trc.positions_mm, names, roles=roles))
    return trc.n_frames


def read_marker_map(path: str | Path) -> dict[str, str]:
    """A ``rehab angles --map`` file: the angles' marker names -> the names in a TRC file.

    YAML, one line per marker whose name differs (the others keep theirs)::

        MB: STER        # upper_limb_seated name: the file's name
        MP: XIPH
        MRS: RSHO

    One-line :class:`TableError` if the file is missing, not such a mapping, names a marker the
    angles do not use, or maps two markers to one name.
    """


    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise TableError(f"{path}: no such file; give a YAML file of lines such as 'MB: STER'") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TableError(f"{path}: cannot read ({getattr(exc, 'strerror', None) or exc})") from None
    except yaml.YAMLError as exc:
        raise TableError(f"{path}: invalid YAML ({getattr(exc, 'problem', exc)}); write lines such as 'MB: STER'") from None
    if not isinstance(data, dict) or not data or not all(isinstance(v, (str, int)) for v in data.values()):
        raise TableError(f"{path}: expected lines 'angle marker: file marker', such as 'MB: STER'")
    mapping = {str(k).strip(): str(v).strip() for k, v in data.items()}
    unknown = [k for k in mapping if k not in REQUIRED_MARKERS]
    if unknown:
        raise TableError(f"{path}: {', '.join(unknown)} not used by the angles: the keys are the names "
                         f"{', '.join(REQUIRED_MARKERS)}")
    values = list(mapping.values())
    twice = sorted({v for v in values if values.count(v) > 1})
    if twice:
        raise TableError(f"{path}: {', '.join(twice)} mapped to more than one marker")
    return mapping


# ------------------------------------------------------------------------------------ status


def write_status_csv(
    path: str | Path,
    frames: np.ndarray,
    times_s: np.ndarray,
    names: Sequence[str],
    positions_mm: np.ndarray,
    status: np.ndarray,
) -> None:
    """Write per-frame, per-marker positions and status (long format, see module docstring).

    Args:
        path: CSV file to write.
        frames: (T,) integer frame indices. times_s: (T,) seconds.
        names: the M marker names.
        positions_mm: (T, M, 3) millimetres, world frame; NaN = no position (written empty).
        status: (T, M) integer :class:`MarkerStatus` codes.
    """
    f, t = _frames_times(frames, times_s)
    names = [str(n) for n in names]
    p = np.asarray(positions_mm, dtype=np.float64)
    s = np.asarray(status)
    n_frames, n_markers = len(f), len(names)
    if p.shape != (n_frames, n_markers, 3):
        raise ValueError(f"positions_mm must be ({n_frames}, {n_markers}, 3), got {p.shape}")
    if s.shape != (n_frames, n_markers):
        raise ValueError(f"status must be ({n_frames}, {n_markers}), got {s.shape}")
    codes = {int(m): m.label for m in MarkerStatus}
    unknown = sorted(set(np.unique(s).tolist()) - set(codes))
    if unknown:
        raise ValueError(f"status codes {unknown} are not MarkerStatus values {sorted(codes)}")
    bad_names = [n for n in names if not n or any(c in n for c in ',"\r\n')]
    if bad_names:
        raise ValueError(f"marker names {bad_names} cannot be written to a CSV cell")
    xyz_format = ",".join([_POSITION_FORMAT] * 3)
    missing = np.isnan(p).any(axis=2).tolist()
    xyz_text = [
        [",," if gone else xyz_format % tuple(xyz) for xyz, gone in zip(frame_xyz, frame_missing)]
        for frame_xyz, frame_missing in zip(p.tolist(), missing)
    ]
    prefix_format = "%d," + _TIME_FORMAT + ","
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(",".join(STATUS_HEADER) + "\n")
        for frame, time, xyz_row, s_row in zip(f.tolist(), t.tolist(), xyz_text, s.tolist()):
            prefix = prefix_format % (frame, time)
            fh.write("".join(
                f"{prefix}{name},{xyz},{codes[code]}\n" for name, xyz, code in zip(names, xyz_row, s_row)
            ))


def read_status_csv(path: str | Path) -> StatusTable:
    """Read a status CSV back into (T, M) arrays; one-line :class:`TableError` if malformed."""
    path = Path(path)
    header, rows, lines = _read_csv(path)
    if header != list(STATUS_HEADER):
        raise TableError(f"{path}: not a status CSV: the header must be {','.join(STATUS_HEADER)}")
    table = _to_float(path, header, rows, lines, (0, 1, 3, 4, 5))
    frame_col = _whole_numbers(path, table[:, 0], lines)
    time_col = _finite(path, table[:, 1], lines, "time")
    marker_col = [row[2] for row in rows]
    try:
        status_col = np.array([MarkerStatus.from_label(row[6]) for row in rows], dtype=np.uint8)
    except ValueError:
        for row, number in zip(rows, lines):
            try:
                MarkerStatus.from_label(row[6])
            except ValueError as exc:
                raise TableError(f"{path}: line {number}: {exc}") from None
        raise  # pragma: no cover
    if any(not m for m in marker_col):
        raise TableError(f"{path}: line {lines[marker_col.index('')]}: the marker cell is empty")

    frames, frame_index = np.unique(frame_col, return_inverse=True)
    names = tuple(dict.fromkeys(marker_col))
    marker_index = np.array([names.index(m) for m in marker_col], dtype=np.intp) if rows else np.empty(0, np.intp)
    flat = frame_index * len(names) + marker_index
    order = np.argsort(flat, kind="stable")
    repeated = order[1:][flat[order][1:] == flat[order][:-1]]  # second and later rows of a pair
    if repeated.size:
        dup = int(repeated.min())
        raise TableError(f"{path}: line {lines[dup]}: frame {frame_col[dup]} has marker {marker_col[dup]} twice")
    positions = np.full((len(frames), len(names), 3), np.nan)
    status = np.full((len(frames), len(names)), MarkerStatus.LOST, dtype=np.uint8)
    positions[frame_index, marker_index] = table[:, 3:6]
    positions[np.isnan(positions).any(axis=2)] = np.nan
    status[frame_index, marker_index] = status_col
    times = np.full(len(frames), np.nan)
    times[frame_index[::-1]] = time_col[::-1]  # first row of each frame wins
    return StatusTable(frames=frames, times_s=times, names=names, positions_mm=positions, status=status)


# ------------------------------------------------------------------------------------ helpers


def _frames_times(frames: np.ndarray, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    f = np.asarray(frames)
    t = np.asarray(times_s, dtype=np.float64)
    if f.ndim != 1 or t.shape != f.shape:
        raise ValueError(f"frames and times_s must be (T,) of one length, got {f.shape} and {t.shape}")
    if f.size and not np.array_equal(f, np.round(f)):
        raise ValueError("frames must be integers")
    if not np.isfinite(t).all():
        raise ValueError("times_s must be finite")
    return f.astype(np.int64), t


def _blank_nan(line: str) -> str:
    """'%f' writes NaN as 'nan' (also for -NaN); an empty cell is the file's NaN."""
    return line.replace("nan", "")


def _read_csv(path: Path) -> tuple[list[str], list[list[str]], list[int]]:
    """Header cells, data rows (padded to the header's width) and their 1-based line numbers."""
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:
            records = list(csv.reader(fh))
    except FileNotFoundError:
        raise TableError(f"{path}: no such file") from None
    except OSError as exc:
        raise TableError(f"{path}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise TableError(f"{path}: not a UTF-8 text file") from None
    except csv.Error as exc:
        raise TableError(f"{path}: malformed CSV ({exc})") from None
    if not records:
        raise TableError(f"{path}: the file is empty; expected a header line")
    header = [c.strip() for c in records[0]]
    rows, lines = [], []
    for number, record in enumerate(records[1:], start=2):
        cells = [c.strip() for c in record]
        if not any(cells):
            continue
        if len(cells) > len(header) and any(cells[len(header):]):
            raise TableError(f"{path}: line {number} has {len(cells)} cells for the {len(header)} header columns")
        rows.append((cells + [""] * len(header))[: len(header)])
        lines.append(number)
    return header, rows, lines


def _check_unique(path: Path, header: list[str]) -> None:
    dupes = sorted({h for h in header if header.count(h) > 1})
    if dupes:
        raise TableError(f"{path}: columns {', '.join(dupes)} appear more than once in the header")


def _to_float(path: Path, header: list[str], rows: list[list[str]], lines: list[int], columns) -> np.ndarray:
    """The numeric ``columns`` of ``rows`` -> (N, len(header)) float64, NaN where empty or skipped."""
    columns = list(columns)
    out = np.full((len(rows), len(header)), np.nan)
    if not rows:
        return out
    try:
        out[:, columns] = np.array([[row[j] or "nan" for j in columns] for row in rows]).astype(np.float64)
    except ValueError:
        pass
    else:   # empty = NaN (no value); infinity is never a measurement
        bad = np.argwhere(np.isinf(out))
        if bad.size:
            i, j = bad[0]
            raise TableError(f"{path}: line {lines[i]}: {header[j]} {rows[i][j][:40]!r} is not a finite number")
        return out
    for row, number in zip(rows, lines):  # slow path only to name the culprit
        for j in columns:
            try:
                float(row[j] or "nan")
            except ValueError:
                raise TableError(f"{path}: line {number}: {header[j]} {row[j][:40]!r} is not a number") from None
    raise TableError(f"{path}: malformed numbers")  # pragma: no cover


def _whole_numbers(path: Path, column: np.ndarray, lines: list[int]) -> np.ndarray:
    bad = np.flatnonzero(~np.isfinite(column) | (column != np.round(column)))
    if bad.size:
        raise TableError(f"{path}: line {lines[bad[0]]}: the frame cell must be a whole number")
    return column.astype(np.int64)


def _finite(path: Path, column: np.ndarray, lines: list[int], label: str) -> np.ndarray:
    bad = np.flatnonzero(~np.isfinite(column))
    if bad.size:
        raise TableError(f"{path}: line {lines[bad[0]]}: the {label} cell is empty or not a number")
    return column
