"""Labelled marker trajectories to and from C3D files (with ezc3d).

Writing follows the C3D conventions that biomechanics software (ezc3d, the ``c3d`` package,
kineticstoolkit, pyomeca, Vicon/Qualisys tools) expects:

- floating-point points in millimetres (``POINT:UNITS = mm``); ``POINT:X_SCREEN = +X``,
  ``POINT:Y_SCREEN = +Y`` tell viewers that +Y is up (the project's world frame: +Y up, the
  patient faces -Z);
- the header's scale factor equals ``POINT:SCALE`` (-0.1: floating point, residuals in steps of
  0.1 mm, at most 25.5 mm; larger values are clipped);
- the **residual** says what a sample rests on: **> 0** measured (triangulated from this frame's
  images: the mean reprojection distance in mm, at least 0.1), **0** estimated (a hidden marker's
  position modelled from its neighbours: the C3D convention for filled or interpolated samples),
  **-1** lost (no position; coordinates 0);
- the **camera mask** has bit k set when camera k+1 (calibration order) saw the marker in the
  views it was triangulated from; only cameras 1-7 fit in the mask's seven bits;
- joint angles are extra points listed in ``POINT:ANGLES`` (``POINT:ANGLE_UNITS = deg``), one
  point per angle named as in the angles CSV, the angle in X (Y = Z = 0), residual -1 where the
  angle is undefined, as gait labs store model outputs beside the markers;
- ``SUBJECTS`` (name, marker set) and ``EVENT`` (label, context, description, time) groups
  where they are known;
- an ``ESTIMATED`` group lists the runs of estimated samples again (point, first and last frame),
  for readers that decode the residual word differently or not at all (ezc3d 1.7 swaps its
  bytes; pyomeca shows no residuals): every C3D reader exposes parameters.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import ezc3d
import numpy as np

from calibration.errors import RehabError
from tracking.marker_status import MarkerStatus

log = logging.getLogger(__name__)

_RESIDUAL_STEP_MM = 0.1
_RESIDUAL_MAX_MM = 255 * _RESIDUAL_STEP_MM
_MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
#: Bits of a C3D camera mask (the eighth is the residual word's sign).
MASK_CAMERAS = 7
#: ``POINT`` parameters listing points that are model outputs, not markers.
_MODEL_OUTPUT_GROUPS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS")
_HEADER_SCALE_OFFSET = 12  # bytes 13-16 of the header: the points' scale factor (float32)
#: Runs per ``ESTIMATED:RANGES`` parameter (a C3D dimension holds at most 255), and parameters at
#: most: 8160 runs, ~100 kB of the parameter section's 130 kB.
_RUNS_PER_PARAMETER = 255
_MAX_RANGE_PARAMETERS = 32


class C3dError(RehabError):
    """A C3D file cannot be read, or lacks the markers asked for."""


@dataclass(frozen=True, slots=True)
class C3dEvent:
    """One entry of the ``EVENT`` group: what happened when (seconds from the first frame)."""

    label: str
    time_s: float
    context: str = "General"
    description: str = ""


def write_c3d(
    path: str | Path,
    names: Sequence[str],
    positions_mm: np.ndarray,
    rate_hz: float,
    residuals: np.ndarray | None = None,
    *,
    status: np.ndarray | None = None,
    camera_masks: np.ndarray | None = None,
    angles_deg: Mapping[str, np.ndarray] | None = None,
    subject: str | None = None,
    markerset: str | None = None,
    events: Sequence[C3dEvent] = (),
) -> None:
    """Write labelled marker trajectories (and joint angles) as a C3D file.

    Args:
        path: file to write.
        names: the M marker labels (unique, at most 30 characters in many C3D readers).
        positions_mm: (T, M, 3) float millimetres, world frame; NaN = no position (a marker with
            any NaN coordinate is missing in that frame: residual -1).
        rate_hz: frame rate (``POINT:RATE``).
        residuals: optional (T, M) residuals in mm (e.g. mean reprojection distance) of the
            measured points; NaN or below 0.1 mm is written as 0.1 mm (a measured point's
            residual is positive). Ignored where the point is estimated or missing.
        status: optional (T, M) :class:`~tracking.marker_status.MarkerStatus` codes: ESTIMATED points get
            residual 0 and no camera, LOST points residual -1. Default: every point with a
            position was measured.
        camera_masks: optional (T, M, C) bool, the cameras (calibration order) that saw each
            marker; cameras beyond the seventh are left out of the file's masks.
        angles_deg: optional angle name -> (T,) degrees (NaN = undefined), written as
            ``POINT:ANGLES`` points after the markers.
        subject: the subject's (pseudonymous) name for ``SUBJECTS:NAMES``; markerset: the marker
            set's name for ``SUBJECTS:MARKER_SETS``. Neither: no ``SUBJECTS`` group.
        events: entries of the ``EVENT`` group.
    """

    names = [str(n) for n in names]
    p = np.asarray(positions_mm, dtype=np.float64)
    if p.ndim != 3 or p.shape[1:] != (len(names), 3):
        raise ValueError(f"positions_mm must be (T, {len(names)}, 3) for {len(names)} names, got {p.shape}")
    n_frames, n_markers = p.shape[:2]
    angles = {str(k): np.broadcast_to(np.asarray(v, dtype=np.float64), (n_frames,)) for k, v in (angles_deg or {}).items()}
    labels = names + list(angles)
    dupes = sorted({n for n in labels if labels.count(n) > 1})
    if dupes or any(not n.strip() for n in labels):
        raise ValueError(f"marker and angle names must be non-empty and unique (duplicates: {dupes})")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be positive, got {rate_hz}")
    if np.isinf(p).any():
        raise ValueError("positions_mm must be finite or NaN")
    missing = np.isnan(p).any(axis=2)  # (T, M)
    estimated = np.zeros_like(missing)
    if status is not None:
        s = np.asarray(status)
        if s.shape != (n_frames, n_markers):
            raise ValueError(f"status must be ({n_frames}, {n_markers}), got {s.shape}")
        missing |= s == MarkerStatus.LOST
        estimated = (s == MarkerStatus.ESTIMATED) & ~missing
    if residuals is None:
        res = np.zeros((n_frames, n_markers))
    else:
        res = np.asarray(residuals, dtype=np.float64)
        if res.shape != (n_frames, n_markers):
            raise ValueError(f"residuals must be ({n_frames}, {n_markers}), got {res.shape}")
        if (res < 0).any():
            raise ValueError("residuals must be >= 0 (missing points are marked by NaN positions)")
    steps = np.round(np.clip(np.nan_to_num(res, nan=0.0), _RESIDUAL_STEP_MM, _RESIDUAL_MAX_MM) / _RESIDUAL_STEP_MM)
    masks = np.zeros((n_frames, n_markers), dtype=np.int64)
    if camera_masks is not None:
        seen = np.asarray(camera_masks, dtype=bool)
        if seen.ndim != 3 or seen.shape[:2] != (n_frames, n_markers):
            raise ValueError(f"camera_masks must be ({n_frames}, {n_markers}, C), got {seen.shape}")
        if seen.shape[2] > MASK_CAMERAS:
            log.info("C3D camera masks hold %d cameras: cameras %d-%d are left out", MASK_CAMERAS,
                     MASK_CAMERAS + 1, seen.shape[2])
        k = min(seen.shape[2], MASK_CAMERAS)
        masks = seen[:, :, :k].astype(np.int64) @ (1 << np.arange(k))
    # the fourth word of each point (C3D: camera mask in the high byte, residual / |SCALE| in the
    # low byte, -1 = invalid); estimated: 0 (no camera, no residual)
    words = np.where(estimated, 0, (masks << 8) | steps.astype(np.int64))
    words = np.where(missing, -1, words)

    c3d = ezc3d.c3d()
    point = c3d["parameters"]["POINT"]
    point["RATE"]["value"] = [float(rate_hz)]
    point["LABELS"]["value"] = tuple(labels)
    point["DESCRIPTIONS"]["value"] = tuple(["marker"] * n_markers + ["joint angle, degrees"] * len(angles))
    point["UNITS"]["value"] = ["mm"]
    point["SCALE"]["value"] = [-_RESIDUAL_STEP_MM]  # negative scale: floating-point points
    c3d.add_parameter("POINT", "X_SCREEN", "+X")
    c3d.add_parameter("POINT", "Y_SCREEN", "+Y")
    points = np.ones((4, len(labels), n_frames))
    points[:3, :n_markers] = np.where(missing[..., None], 0.0, p).transpose(2, 1, 0)
    all_words = np.empty((n_frames, len(labels)), dtype=np.int64)
    all_words[:, :n_markers] = words
    if angles:
        c3d.add_parameter("POINT", "ANGLES", list(angles))
        c3d.add_parameter("POINT", "ANGLE_UNITS", "deg")
        values = np.stack(list(angles.values()))  # (A, T)
        undefined = ~np.isfinite(values)
        points[0, n_markers:] = np.where(undefined, 0.0, values)
        points[1:3, n_markers:] = 0.0
        all_words[:, n_markers:] = np.where(undefined, -1, 0).T  # a model output: residual 0, or -1
    if subject is not None or markerset is not None:
        c3d.add_parameter("SUBJECTS", "USED", 1)
        c3d.add_parameter("SUBJECTS", "NAMES", [subject or ""])
        c3d.add_parameter("SUBJECTS", "MARKER_SETS", [markerset or ""])
        c3d.add_parameter("SUBJECTS", "IS_STATIC", 0)
        c3d.add_parameter("SUBJECTS", "USES_PREFIXES", 0)
        c3d.add_parameter("SUBJECTS", "LABEL_PREFIXES", [""])
    if events:
        c3d.add_parameter("EVENT", "USED", len(events))
        c3d.add_parameter("EVENT", "LABELS", [e.label for e in events])
        c3d.add_parameter("EVENT", "CONTEXTS", [e.context for e in events])
        c3d.add_parameter("EVENT", "DESCRIPTIONS", [e.description or e.label for e in events])
        # TIMES is (2, n): minutes and seconds of each event; all in the seconds here
        c3d.add_parameter("EVENT", "TIMES", np.array([[0.0] * len(events), [float(e.time_s) for e in events]]))
    _add_estimated_runs(c3d, estimated)
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"] = {
        "residuals": np.where(all_words < 0, -1.0, 0.0).T[None, :, :],
        "camera_masks": np.zeros((MASK_CAMERAS, len(labels), n_frames), dtype=bool),
    }
    c3d.write(str(path))
    _finish(Path(path), -_RESIDUAL_STEP_MM, all_words)


def estimated_runs(estimated: np.ndarray) -> np.ndarray:
    """(T, M) bool -> (R, 3) int64 runs of estimated samples: point (from 1), first and last frame
    (from 1, the file's frame numbers), by point, then frame."""
    e = np.asarray(estimated, dtype=bool)
    edges = np.diff(np.pad(e.T.astype(np.int8), ((0, 0), (1, 1))), axis=1)  # (M, T + 1)
    point, first = np.nonzero(edges == 1)
    _, after = np.nonzero(edges == -1)
    return np.column_stack([point + 1, first + 1, after]).astype(np.int64)


def _add_estimated_runs(c3d, estimated: np.ndarray) -> None:
    """The ``ESTIMATED`` group (module docstring): ``USED`` runs, ``RANGES``, ``RANGES2``, ...
    each (3, <= 255) floats (exact integers): point, first frame, last frame."""
    runs = estimated_runs(estimated)
    if len(runs) > _RUNS_PER_PARAMETER * _MAX_RANGE_PARAMETERS:
        log.warning("%d runs of estimated samples do not fit in the C3D parameters: no ESTIMATED group (the "
                    "residuals, 0 where estimated, still mark them)", len(runs))
        return
    c3d.add_parameter("ESTIMATED", "DESCRIPTION", "runs of estimated samples: point (POINT:LABELS from 1), first "
                                                  "frame, last frame (from 1)")
    c3d.add_parameter("ESTIMATED", "USED", len(runs))
    for k, start in enumerate(range(0, len(runs), _RUNS_PER_PARAMETER)):
        c3d.add_parameter("ESTIMATED", "RANGES" if k == 0 else f"RANGES{k + 1}",
                          runs[start:start + _RUNS_PER_PARAMETER].T.astype(np.float64))


def _finish(path: Path, scale: float, words: np.ndarray) -> None:
    """Fix what ezc3d (1.7) writes differently from the C3D standard, in place.

    - the header's scale factor: ezc3d leaves -1 there whatever ``POINT:SCALE`` says, and readers
      such as the ``c3d`` package refuse a file whose header and parameter disagree;
    - the fourth word of each floating-point sample: the standard puts the camera mask in the
      high byte and the residual in the low byte; ezc3d swaps them (its issue 386).

    ``words``: (T, P) signed integers of the fourth words, in frame and point order.
    """
    with open(path, "r+b") as fh:
        head = fh.read(512 + 4)
        if len(head) < 516 or head[515] != 84:  # parameter block's processor type: 84 = Intel
            raise C3dError(f"{path}: the C3D writer did not write an Intel-format file; cannot fix its header")
        fh.seek(_HEADER_SCALE_OFFSET)
        fh.write(struct.pack("<f", scale))
        data_start = struct.unpack_from("<H", head, 16)[0]  # header word 9: first block of the data
        n_frames, n_points = words.shape
        fh.seek((data_start - 1) * 512)
        block = np.frombuffer(fh.read(n_frames * n_points * 16), dtype="<f4").reshape(n_frames, n_points, 4).copy()
        if block.shape != (n_frames, n_points, 4):  # pragma: no cover - ezc3d wrote fewer bytes
            raise C3dError(f"{path}: the C3D writer wrote a short data block")
        block[:, :, 3] = words
        fh.seek((data_start - 1) * 512)
        fh.write(block.tobytes())


def read_c3d_points(
    path: str | Path, labels: Sequence[str] | None = None
) -> tuple[tuple[str, ...], np.ndarray, float]:
    """Labelled marker trajectories of a C3D file, in millimetres.

    Args:
        path: C3D file.
        labels: the markers wanted, in the order wanted; default all. A label matches a point
            label exactly or, failing that, the part after a ``Subject:`` prefix (Vicon style).

    Returns:
        names: the M labels (as asked for, or all of the file's markers, stripped: points listed
            in ``POINT:ANGLES``, ``FORCES``, ``MOMENTS``, ``POWERS`` or ``SCALARS`` are left out).
        positions_mm: (T, M, 3) float64 millimetres in the file's own axes; NaN where the point
            is missing (residual < 0).
        rate_hz: ``POINT:RATE``.
    """

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
    if labels is None:  # the markers: not the model outputs (POINT:ANGLES ...)
        outputs = {n for group in _MODEL_OUTPUT_GROUPS for n in _param_list(point, group)}
        keep = [i for i, n in enumerate(all_names) if n not in outputs]
        return tuple(all_names[i] for i in keep), positions[:, keep, :], rate_hz
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


def _param_list(group: dict, name: str) -> list[str]:
    return [str(v).strip() for v in group.get(name, {}).get("value", [])]


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
