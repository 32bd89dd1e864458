"""Labelled marker trajectories to and from C3D files (with ezc3d).

Writing follows the C3D conventions that biomechanics software expects: floating-point points
in millimetres (``POINT:UNITS = mm``), a missing point has residual -1 (and zero coordinates), a
present point a residual >= 0, and ``POINT:X_SCREEN = +X``, ``POINT:Y_SCREEN = +Y`` tell viewers
that +Y is up (the project's world frame: +Y up, the patient faces -Z).

Residuals are stored in one byte scaled by ``POINT:SCALE``; with the scale written here (-0.1)
they are kept to 0.1 mm and at most 25.5 mm (larger values are clipped).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from calibration.errors import RehabError

_RESIDUAL_STEP_MM = 0.1
_RESIDUAL_MAX_MM = 255 * _RESIDUAL_STEP_MM
_MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0}


class C3dError(RehabError):
    """A C3D file cannot be read, or lacks the markers asked for."""


def write_c3d(
    path: str | Path,
    names: Sequence[str],
    positions_mm: np.ndarray,
    rate_hz: float,
    residuals: np.ndarray | None = None,
) -> None:
    """Write labelled marker trajectories as a C3D file.

    Args:
        path: file to write.
        names: the M marker labels (unique, at most 30 characters in many C3D readers).
        positions_mm: (T, M, 3) float millimetres, world frame; NaN = no position (a marker with
            any NaN coordinate is missing in that frame: residual -1).
        rate_hz: frame rate (``POINT:RATE``).
        residuals: optional (T, M) residuals in mm (e.g. mean reprojection distance) for the
            present points; default 0. NaN counts as 0. Ignored where the point is missing.
    """
    import ezc3d  # heavy import, only where C3D files are written

    names = [str(n) for n in names]
    p = np.asarray(positions_mm, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (len(names), 3):
        raise ValueError(f"positions_mm must be (T, {len(names)}, 3) for {len(names)} names, got {p.shape}")
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes or any(not n.strip() for n in names):
        raise ValueError(f"marker names must be non-empty and unique (duplicates: {dupes})")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be positive, got {rate_hz}")
    if np.isinf(p).any():
        raise ValueError("positions_mm must be finite or NaN")
    n_frames, n_markers = p.shape[:2]
    missing = np.isnan(p).any(axis=2)  # (T, M)
    if residuals is None:
        res = np.zeros((n_frames, n_markers))
    else:
        res = np.asarray(residuals, dtype=np.float64)
        if res.shape != (n_frames, n_markers):
            raise ValueError(f"residuals must be ({n_frames}, {n_markers}), got {res.shape}")
        if (res < 0).any():
            raise ValueError("residuals must be >= 0 (missing points are marked by NaN positions)")
        res = np.clip(np.nan_to_num(res, nan=0.0), 0.0, _RESIDUAL_MAX_MM)
    # Quantize to the stored step ourselves, nudged up so that the writer's truncation keeps it.
    res = (np.round(res / _RESIDUAL_STEP_MM) + 0.01) * _RESIDUAL_STEP_MM
    res[missing] = -1.0

    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"] = [float(rate_hz)]
    point["LABELS"]["value"] = tuple(names)
    point["UNITS"]["value"] = ["mm"]
    point["SCALE"]["value"] = [-_RESIDUAL_STEP_MM]  # negative scale: floating-point points
    c3d.add_parameter("POINT", "X_SCREEN", "+X")
    c3d.add_parameter("POINT", "Y_SCREEN", "+Y")
    points = np.ones((4, n_markers, n_frames))
    points[:3] = np.where(missing[..., None], 0.0, p).transpose(2, 1, 0)
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"] = {
        "residuals": res.T[None, :, :],
        "camera_masks": np.zeros((7, n_markers, n_frames), dtype=bool),
    }
    c3d.write(str(path))


def read_c3d_points(
    path: str | Path, labels: Sequence[str] | None = None
) -> tuple[tuple[str, ...], np.ndarray, float]:
    """Labelled marker trajectories of a C3D file, in millimetres.

    Args:
        path: C3D file.
        labels: the markers wanted, in the order wanted; default all. A label matches a point
            label exactly or, failing that, the part after a ``Subject:`` prefix (Vicon style).

    Returns:
        names: the M labels (as asked for, or all of the file's, stripped).
        positions_mm: (T, M, 3) float64 millimetres in the file's own axes; NaN where the point
            is missing (residual < 0).
        rate_hz: ``POINT:RATE``.
    """
    import ezc3d

    path = Path(path)
    if not path.is_file():
        raise C3dError(f"{path}: no such file")
    frame_bytes, data_offset, declared = check_c3d_layout(path)
    held = max(0, path.stat().st_size - data_offset) // max(1, frame_bytes)
    if held < declared:   # checked before ezc3d: a damaged count made it read for minutes
        raise C3dError(f"{path}: the file says {declared} frames but holds {held}: it is truncated (an interrupted "
                       f"copy or write?); export it again")
    try:
        c3d = ezc3d.c3d(str(path))
    except (OSError, RuntimeError, ValueError, IndexError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else "invalid"
        raise C3dError(f"{path}: not a readable C3D file ({reason})") from None
    point = c3d["parameters"]["POINT"]
    points = np.asarray(c3d["data"]["points"], dtype=np.float64)  # (4, M, T)
    n_points = points.shape[1]
    all_names = _point_labels(point)[:n_points]
    if len(all_names) < n_points:
        all_names += [f"point{i + 1}" for i in range(len(all_names), n_points)]
    units = _param_text(point, "UNITS") or "mm"
    if units.lower() not in _MM_PER_UNIT:
        raise C3dError(f"{path}: POINT:UNITS {units!r} unknown: expected mm, cm or m")
    rate = point.get("RATE", {}).get("value", [])
    rate_hz = float(rate[0]) if len(rate) else float(c3d["header"]["points"]["frame_rate"])
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise C3dError(f"{path}: POINT:RATE {rate_hz} is not a positive frame rate")

    if points.shape[2] < declared or held < points.shape[2]:
        raise C3dError(f"{path}: the file says {declared} frames but holds {min(held, points.shape[2])}: it is "
                       f"truncated (an interrupted copy or write?); export it again")
    positions = points[:3].transpose(2, 1, 0) * _MM_PER_UNIT[units.lower()]
    if np.isinf(positions).any():
        raise C3dError(f"{path}: the points hold infinite coordinates: the file is damaged; export it again")
    residuals = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=np.float64)
    if residuals.shape == (1, n_points, positions.shape[0]):
        positions[residuals[0].T < 0] = np.nan
    positions[np.isnan(positions).any(axis=2)] = np.nan
    if labels is None:
        return tuple(all_names), positions, rate_hz
    index = [_find_label(all_names, label) for label in labels]
    absent = [label for label, i in zip(labels, index) if i is None]
    if absent:
        shown = ", ".join(all_names[:12]) + (", ..." if len(all_names) > 12 else "")
        raise C3dError(f"{path} lacks markers {', '.join(absent)} (it has {shown})")
    return tuple(labels), positions[:, index, :], rate_hz


_BLOCK = 512


def check_c3d_layout(path: Path) -> tuple[int, int, int]:
    """Check a C3D file's header and parameter blocks before ezc3d reads it.

    ezc3d (C++) can crash the process on a damaged header or parameter section, and reads a
    truncated file as a shorter or zero-filled motion; these checks turn both into one line.
    Returns (bytes per frame, byte offset of the data, frames declared) for checking the length
    once ezc3d has read the frames (it reads what is there and adjusts its header to match).
    The declared count is ``POINT:FRAMES`` where present (as ezc3d and long files use it), else
    the header's first and last frame.

    Raises:
        C3dError: not a C3D file, or a damaged header or parameter section.
    """
    import struct

    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(_BLOCK)
        if len(head) < _BLOCK or head[1] != 0x50:
            raise C3dError(f"{path}: not a readable C3D file (no C3D header): give a .c3d file")
        param_block = head[0]
        fh.seek((param_block - 1) * _BLOCK)
        param_head = fh.read(4)
        if param_block < 2 or len(param_head) < 4:
            raise C3dError(f"{path}: the C3D header points to no parameter section: the file is damaged or truncated")
        n_param_blocks, processor = param_head[2], param_head[3]
        if processor not in (84, 85, 86):
            raise C3dError(f"{path}: the parameter section names processor type {processor} (Intel, DEC or MIPS "
                           f"expected): the file is damaged")
        endian = ">" if processor == 86 else "<"
        fh.seek((param_block - 1) * _BLOCK)
        params = fh.read(n_param_blocks * _BLOCK)
    if n_param_blocks == 0 or len(params) < n_param_blocks * _BLOCK:
        raise C3dError(f"{path}: the parameter section is cut short: the file is truncated; export it again")
    numbers = _walk_parameters(path, params, endian)
    frames_param = numbers.get((b"POINT", b"FRAMES"))
    words = struct.unpack(f"{endian}hhHHhh", head[2:14])
    n_points, n_analog, first, last = words[0], words[1], words[2], words[3]
    declared = frames_param if frames_param is not None else max(0, last - first + 1)
    scale = struct.unpack(f"{endian}f", head[12:16])[0] if processor != 85 else -1.0   # DEC floats: no check
    data_start = struct.unpack(f"{endian}H", head[16:18])[0]
    if n_points < 0 or n_analog < 0 or data_start < param_block + 1 or not np.isfinite(scale):
        raise C3dError(f"{path}: the C3D header is damaged (points {n_points}, analog {n_analog}, data start "
                       f"block {data_start}): export the file again")
    bytes_per = 4 if scale < 0 else 2
    rotation_start = numbers.get((b"ROTATION", b"DATA_START"))
    if any(group == b"ROTATION" for group, _ in numbers) and (
            rotation_start is None or not 1 < rotation_start <= size // _BLOCK + 1):
        # without it ezc3d searched for the rotations for half a minute
        raise C3dError(f"{path}: the ROTATION group has no valid DATA_START: the file is damaged; export it again")
    if (data_start - 1) * _BLOCK > size:
        raise C3dError(f"{path}: the C3D data would start after the end of the file: it is truncated; export it "
                       f"again")
    return (4 * n_points + n_analog) * bytes_per, (data_start - 1) * _BLOCK, declared


def _walk_parameters(path: Path, params: bytes, endian: str) -> dict[tuple[bytes, bytes], int]:
    """Follow the parameter records' offsets: each must stay inside the section and belong to a group.

    Returns the whole-number scalar parameters, e.g. ``{(b"POINT", b"FRAMES"): 580}``.
    """
    import struct

    groups: dict[int, bytes] = {}
    owners: set[int] = set()
    numbers: dict[tuple[int, bytes], int] = {}
    i, n, ended = 4, 0, False
    while i < len(params) - 4 and n <= 100_000:
        n_chars = struct.unpack("b", params[i:i + 1])[0]
        if n_chars == 0:
            ended = True
            break
        name = params[i + 2:i + 2 + abs(n_chars)].upper()
        name_end = i + 2 + abs(n_chars)
        if name_end + 2 > len(params):
            break
        offset = struct.unpack(f"{endian}H", params[name_end:name_end + 2])[0]
        group_id = struct.unpack("b", params[i + 1:i + 2])[0]
        if group_id < 0:
            groups[-group_id] = name
        elif name_end + 4 <= len(params):   # a parameter: its type and dimensions must fit in the section
            kind, n_dims = struct.unpack("bB", params[name_end + 2:name_end + 4])
            dims = params[name_end + 4:name_end + 4 + n_dims]
            count = int(np.prod([d for d in dims])) if n_dims else 1
            start = name_end + 4 + n_dims
            if kind not in (-1, 1, 2, 4) or len(dims) < n_dims or start + abs(kind) * count > len(params):
                break
            owners.add(group_id)
            if count >= 1 and kind in (2, 4):
                value = struct.unpack(f"{endian}{'H' if kind == 2 else 'f'}", params[start:start + kind])[0]
                if np.isfinite(value) and 0 <= value < 2**31:
                    numbers[(group_id, name)] = int(value)
        else:
            break
        if offset == 0:
            ended = True
            break
        if name_end + offset > len(params):
            break
        i = name_end + offset
        n += 1
    else:
        ended = True
    if not ended:
        raise C3dError(f"{path}: the C3D parameter section is damaged (record {n + 1}): export the file again")
    orphans = sorted(owners - set(groups))
    if orphans:   # ezc3d searched for half a minute on such a file
        raise C3dError(f"{path}: the C3D parameter section is damaged (parameters of a group {orphans[0]} that does "
                       f"not exist): export the file again")
    return {(groups[g], name): value for (g, name), value in numbers.items()}


def _param_text(group: dict, name: str) -> str:
    value = group.get(name, {}).get("value", [])
    return str(value[0]).strip() if len(value) else ""


def _point_labels(point: dict) -> list[str]:
    """POINT:LABELS, then LABELS2, LABELS3, ... (files with more than 255 points)."""
    names = [str(n).strip() for n in point.get("LABELS", {}).get("value", [])]
    k = 2
    while f"LABELS{k}" in point:
        names += [str(n).strip() for n in point[f"LABELS{k}"]["value"]]
        k += 1
    return names


def _find_label(names: list[str], label: str) -> int | None:
    if label in names:
        return names.index(label)
    suffix = [i for i, n in enumerate(names) if n.rsplit(":", 1)[-1] == label]
    return suffix[0] if len(suffix) == 1 else None
