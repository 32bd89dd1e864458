"""OpenSim TRC marker files (``docs/INTERFACES.md``): write them as OpenSim does, read any.

Layout (tab-separated; OpenSim's ``TRCFileAdapter`` writes exactly this, trailing tabs included)::

    PathFileType<TAB>4<TAB>(X/Y/Z)<TAB>markers.trc
    DataRate<TAB>CameraRate<TAB>NumFrames<TAB>NumMarkers<TAB>Units<TAB>OrigDataRate<TAB>OrigDataStartFrame<TAB>OrigNumFrames
    30<TAB>30<TAB>2<TAB>14<TAB>mm<TAB>30<TAB>1<TAB>2
    Frame#<TAB>Time<TAB>MB<TAB><TAB><TAB>MP<TAB><TAB><TAB>...
    <TAB><TAB>X1<TAB>Y1<TAB>Z1<TAB>X2<TAB>Y2<TAB>Z2<TAB>...
    (blank line)
    1<TAB>0.000000<TAB>1.0000<TAB>2.0000<TAB>3.0000<TAB><TAB><TAB><TAB>...   (empty cells: no position)

Every cell of a data row, the last included, is followed by a tab, so that a row whose last
marker is missing still has its full number of cells for OpenSim's reader.

Positions are millimetres in the world frame (+Y up, the patient faces -Z). ``Frame#`` counts
from 1 as OpenSim numbers frames (and ``OrigDataStartFrame`` is the first row's number): the
recording's frame index (0 = first image, as in the status and angles CSV files) plus one.
Files this project wrote before counted from 0 (``OrigDataStartFrame`` 0); they still read, and
:attr:`TrcData.frame_indices` gives the frame indices of either.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from calibration.errors import RehabError

log = logging.getLogger(__name__)

_METADATA_KEYS = (
    "DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units", "OrigDataRate", "OrigDataStartFrame",
    "OrigNumFrames",
)
_MM_PER_UNIT = {"mm": 1.0, "millimeters": 1.0, "cm": 10.0, "m": 1000.0, "meters": 1000.0}
_POSITION_FORMAT = "%.4f"  # 0.1 micrometre: far below marker noise, keeps files compact
_TIME_FORMAT = "%.6f"


class TrcError(RehabError):
    """A TRC file cannot be read: missing, not a TRC file, or malformed."""


@dataclass(frozen=True, slots=True, eq=False)  # arrays: no elementwise __eq__
class TrcData:
    """The content of a TRC file.

    Attributes:
        names: the M marker names, in file order.
        frame_numbers: (T,) int64 ``Frame#`` column.
        times_s: (T,) float64 ``Time`` column, seconds.
        positions_mm: (T, M, 3) float64 positions in millimetres (converted from the file's
            Units), NaN where the file has no position.
        rate_hz: the file's ``DataRate``.
        frame_base: the number of the first image: 1 (OpenSim, and this project's files), or 0
            for files whose ``OrigDataStartFrame`` is 0 (this project's files before Frame#
            counted from 1).
    """

    names: tuple[str, ...]
    frame_numbers: np.ndarray
    times_s: np.ndarray
    positions_mm: np.ndarray
    rate_hz: float
    frame_base: int = 1

    @property
    def frame_indices(self) -> np.ndarray:
        """(T,) int64 frame indices counted from 0 (the status and angles CSV files' ``frame``)."""
        return self.frame_numbers - self.frame_base

    @property
    def n_frames(self) -> int:
        return int(self.positions_mm.shape[0])

    def marker(self, name: str) -> np.ndarray:
        """(T, 3) positions of one marker (mm)."""
        return self.positions_mm[:, self.names.index(name), :]


def write_trc(
    path: str | Path,
    names: Sequence[str],
    positions_mm: np.ndarray,
    rate_hz: float,
    *,
    frame_numbers: np.ndarray | None = None,
    times_s: np.ndarray | None = None,
    file_name: str | None = None,
) -> None:
    """Write marker trajectories as an OpenSim TRC file (Units mm).

    Args:
        path: file to write; its name goes in the first header line unless ``file_name`` is given.
        names: the M marker names (unique; no tabs or line breaks).
        positions_mm: (T, M, 3) float positions in millimetres, world frame; NaN = no position
            (a marker with any NaN coordinate is written as three empty cells).
        rate_hz: frame rate (DataRate, CameraRate, OrigDataRate).
        frame_numbers: (T,) integer ``Frame#`` values; default ``1 .. T`` (OpenSim counts from 1:
            give a recording's frame indices plus one).
        times_s: (T,) times in seconds; default ``(frame_numbers - frame_numbers[0]) / rate_hz``.
        file_name: the name for the first header line (a file written through a temporary file
            names the file it becomes).
    """
    path = Path(path)
    names = [str(n) for n in names]
    p = np.asarray(positions_mm, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (len(names), 3):
        raise ValueError(f"positions_mm must be (T, {len(names)}, 3) for {len(names)} names, got {p.shape}")
    _check_names(names)
    if np.isinf(p).any():
        raise ValueError("positions_mm must be finite or NaN")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be positive, got {rate_hz}")
    n_frames, n_markers = p.shape[0], p.shape[1]
    frames = np.arange(1, n_frames + 1) if frame_numbers is None else np.asarray(frame_numbers)
    if frames.shape != (n_frames,) or (frames.size and not np.array_equal(frames, np.round(frames))):
        raise ValueError(f"frame_numbers must be ({n_frames},) integers")
    frames = frames.astype(np.int64)
    if times_s is None:
        times = (frames - (frames[0] if n_frames else 0)) / float(rate_hz)
    else:
        times = np.asarray(times_s, dtype=np.float64)
        if times.shape != (n_frames,) or not np.isfinite(times).all():
            raise ValueError(f"times_s must be ({n_frames},) finite seconds")

    rate = _format_rate(rate_hz)
    first = int(frames[0]) if n_frames else 1
    header = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name if file_name is None else file_name}",
        "\t".join(_METADATA_KEYS),
        "\t".join([rate, rate, str(n_frames), str(n_markers), "mm", rate, str(first), str(n_frames)]),
        "Frame#\tTime\t" + "".join(f"{name}\t\t\t" for name in names),
        "\t\t" + "".join(f"X{i}\tY{i}\tZ{i}\t" for i in range(1, n_markers + 1)),
        "",
    ]
    # A marker with any NaN coordinate has no position: blank all three cells.
    p = np.where(np.isnan(p).any(axis=2, keepdims=True), np.nan, p).reshape(n_frames, 3 * n_markers)
    row_format = "%d\t" + _TIME_FORMAT + "\t" + (_POSITION_FORMAT + "\t") * (3 * n_markers)
    rows = (
        (row_format % (f, t, *xyz)).replace("nan", "")  # '%f' % nan == 'nan'; no number contains it
        for f, t, xyz in zip(frames.tolist(), times.tolist(), p.tolist())
    )
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(header) + "\n")
        for row in rows:
            fh.write(row + "\n")


def read_trc(path: str | Path) -> TrcData:
    """Read a TRC file written by this project, OpenSim or other tools.

    Tolerates trailing tabs, CRLF line ends, a missing blank line or X1/Y1/Z1 line, blank lines
    between rows, rows that stop before their trailing empty cells, ``NaN`` text, and Units m/cm
    (converted to mm). A marker with any empty coordinate has no position (NaN, as OpenSim reads
    it). Anything else raises a one-line :class:`TrcError` naming the file and the problem.
    """
    path = Path(path)
    text = _read_text(path)
    lines = text.splitlines()
    if not lines or not lines[0].split() or lines[0].split()[0] != "PathFileType":
        raise TrcError(f"{path}: not a TRC file: the first line must start with PathFileType")
    if len(lines) < 4:
        raise TrcError(f"{path}: the header is incomplete: a TRC file needs the PathFileType, metadata "
                       f"keys, metadata values and Frame#/Time name lines")
    meta = _metadata(path, lines[1], lines[2])
    rate_hz = _rate(path, meta)
    units = meta.get("Units", "mm")
    if units.lower() not in _MM_PER_UNIT:
        raise TrcError(f"{path}: Units {units!r} unknown: expected mm, cm or m")
    scale = _MM_PER_UNIT[units.lower()]

    label_cells = [c.strip() for c in lines[3].split("\t")]
    if len(label_cells) < 2 or not label_cells[0].startswith("Frame") or label_cells[1] != "Time":
        raise TrcError(f"{path}: line 4 must start with Frame# and Time, then the marker names")
    names = tuple(c for c in label_cells[2:] if c)
    _check_file_names(path, names)
    if "NumMarkers" in meta and meta["NumMarkers"] != str(len(names)):
        log.warning("%s: NumMarkers says %s but line 4 names %d markers; using the names",
                    path, meta["NumMarkers"], len(names))

    body_start = 4
    if body_start < len(lines) and lines[body_start].strip()[:1] in ("X", "x"):
        body_start += 1  # the X1 Y1 Z1 ... line
    n_cells = 2 + 3 * len(names)
    rows, line_numbers = [], []
    cut = not text.endswith(("\n", "\r"))   # the last line has no line end: maybe cut short
    for number, line in enumerate(lines[body_start:], start=body_start + 1):
        if not line.strip():
            continue
        cells = [c.strip() for c in line.split("\t")]
        if cut and number == len(lines) and len(cells) < n_cells:
            raise TrcError(f"{path}: line {number} stops after {len(cells)} of {n_cells} values without a line end: "
                           f"the file is truncated (an interrupted write?); write it again")
        if len(cells) > n_cells:
            if any(cells[n_cells:]):
                raise TrcError(f"{path}: line {number} has {sum(1 for c in cells if c)} values, more than "
                               f"frame, time and 3 coordinates of {len(names)} markers")
            cells = cells[:n_cells]
        elif len(cells) < n_cells:
            cells += [""] * (n_cells - len(cells))
        rows.append(cells)
        line_numbers.append(number)

    _check_frame_count(path, meta, len(rows))
    table = _to_float(path, rows, line_numbers, n_cells)
    frame_col, times = table[:, 0], table[:, 1]
    for column, label in ((frame_col, "Frame#"), (times, "Time")):
        bad = np.flatnonzero(~np.isfinite(column))
        if bad.size:
            raise TrcError(f"{path}: line {line_numbers[bad[0]]}: the {label} cell is empty or not a number")
    if not np.array_equal(frame_col, np.round(frame_col)) or (np.abs(frame_col) > 2**53).any():
        bad = np.flatnonzero((frame_col != np.round(frame_col)) | (np.abs(frame_col) > 2**53))[0]
        raise TrcError(f"{path}: line {line_numbers[bad]}: Frame# {frame_col[bad]:g} is not a whole frame number")
    positions = table[:, 2:].reshape(len(rows), len(names), 3) * scale
    if np.isinf(positions).any():
        bad = int(np.argwhere(np.isinf(positions))[0][0])
        raise TrcError(f"{path}: line {line_numbers[bad]}: a coordinate is infinite or too large: fix or export "
                       f"the file again")
    positions[np.isnan(positions).any(axis=2)] = np.nan
    frames = frame_col.astype(np.int64)
    for array in (frames, times, positions):
        array.setflags(write=False)
    base = 0 if meta.get("OrigDataStartFrame") == "0" else 1
    return TrcData(names=names, frame_numbers=frames, times_s=times, positions_mm=positions, rate_hz=rate_hz,
                   frame_base=base)


def _check_frame_count(path: Path, meta: dict[str, str], n_rows: int) -> None:
    """Fewer frames than the header's NumFrames, or none it did not declare: a truncated file."""
    try:
        declared = int(meta.get("NumFrames", ""))
    except ValueError:
        declared = None   # no usable NumFrames: the rows are the frames
    if n_rows == 0 and declared != 0:
        raise TrcError(f"{path}: the file has a header but no frames: write it again")
    if declared is None:
        return
    if n_rows < declared:
        raise TrcError(f"{path}: NumFrames says {declared} but the file holds {n_rows} frames: the file is truncated "
                       f"(an interrupted write?); write it again")
    if n_rows > declared:
        log.warning("%s: NumFrames says %d but the file holds %d frames; reading them all", path, declared, n_rows)


def _check_names(names: list[str]) -> None:
    for name in names:
        if not name.strip() or any(c in name for c in "\t\r\n"):
            raise ValueError(f"marker name {name!r} cannot be written to a TRC file (empty or with tabs/newlines)")
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"duplicate marker names {dupes}")


def _check_file_names(path: Path, names: tuple[str, ...]) -> None:
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise TrcError(f"{path}: marker names {', '.join(dupes)} appear more than once on line 4; rename them")


def _format_rate(rate_hz: float) -> str:
    return str(int(rate_hz)) if float(rate_hz).is_integer() else format(float(rate_hz), ".10g")


def _read_text(path: Path) -> str:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise TrcError(f"{path}: no such file") from None
    except OSError as exc:
        raise TrcError(f"{path}: cannot read ({exc.strerror})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")  # older Windows tools write marker names in a code page


def _metadata(path: Path, keys_line: str, values_line: str) -> dict[str, str]:
    keys = [k.strip() for k in keys_line.split("\t") if k.strip()]
    values = [v.strip() for v in values_line.split("\t") if v.strip()]
    if len(values) != len(keys):
        keys, values = keys_line.split(), values_line.split()
    if "DataRate" not in keys and "CameraRate" not in keys:
        raise TrcError(f"{path}: line 2 must name the metadata (DataRate CameraRate NumFrames NumMarkers "
                       f"Units ...), got {keys_line.strip()[:60]!r}")
    if len(values) != len(keys):
        raise TrcError(f"{path}: line 3 has {len(values)} metadata values for the {len(keys)} keys of line 2")
    return dict(zip(keys, values))


def _rate(path: Path, meta: dict[str, str]) -> float:
    for key in ("DataRate", "CameraRate"):
        try:
            rate = float(meta.get(key, "nan"))
        except ValueError:
            continue
        if np.isfinite(rate) and rate > 0:
            return rate
    raise TrcError(f"{path}: DataRate {meta.get('DataRate')!r} is not a positive frame rate")


def _to_float(path: Path, rows: list[list[str]], line_numbers: list[int], n_cells: int) -> np.ndarray:
    """Cells -> (T, n_cells) float64 with NaN for empty cells; a bad cell names its line."""
    if not rows:
        return np.empty((0, n_cells))
    try:
        return np.array([[c if c else "nan" for c in row] for row in rows]).astype(np.float64)
    except ValueError:
        pass
    for row, number in zip(rows, line_numbers):  # slow path only to name the culprit
        for cell in row:
            try:
                float(cell or "nan")
            except ValueError:
                raise TrcError(f"{path}: line {number}: {cell[:40]!r} is not a number") from None
    raise TrcError(f"{path}: malformed numbers")  # pragma: no cover - the loop above finds the cell
