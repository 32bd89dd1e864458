"""Calibration files: Pose2Sim/anipose TOML and OpenCV FileStorage YAML/XML.

Both formats hold cameras in calibration order with extrinsics world -> camera
(``x_cam = R @ x_world + t``, metres; world frame of docs/INTERFACES.md) and intrinsics in pixels
with OpenCV distortion (k1, k2, p1, p2[, k3[, k4, k5, k6]]).

TOML (``.toml``): exactly the "Camera calibration file" of docs/INTERFACES.md. One table per
camera in file order with the keys ``name``, ``size`` ([width, height] px), ``matrix`` (3x3 px),
``distortions``, ``rotation`` (Rodrigues vector, world -> camera), ``translation`` (metres) and
``fisheye`` (optional, as aniposelib omits it for pinhole cameras), then ``[metadata]`` with
``adjusted`` and ``error`` (other metadata keys are tolerated). Every table except ``metadata`` is
a camera, and a camera table with any other key is an error.

Extensions: the project stores further calibration results (the learnt marker colours) as
sub-tables of ``[metadata]`` (``[metadata.marker_colours]``): Pose2Sim and aniposelib skip
``metadata`` when they read cameras, and this module tolerates any metadata key, so such a file
stays a valid calibration for every reader (:func:`read_metadata_section`,
:func:`write_metadata_section`).

OpenCV FileStorage (``.yaml``, ``.yml``, ``.xml``), read and written with ``cv2.FileStorage``: a
top-level sequence ``cameras`` with one map per camera, in calibration order::

    %YAML 1.2
    ---
    cameras:
       -
          name: cam1                  # optional; default "cam<i>" (1-based)
          image_size: [ 640, 480 ]    # width, height in pixels
          K: !!opencv-matrix          # 3x3 intrinsic matrix, pixels
             rows: 3
             cols: 3
             dt: d
             data: [ 600., 0., 320., 0., 600., 240., 0., 0., 1. ]
          dist: !!opencv-matrix       # 1xN, N in {4, 5, 8}
             ...
          R: !!opencv-matrix          # 3x3 rotation world -> camera (or rvec: 3 numbers, Rodrigues)
             ...
          t: !!opencv-matrix          # 3x1 translation world -> camera, metres
             ...
          fisheye: 0                  # optional
       -
          ...

The XML form is the same tree (``<cameras><_>...</_></cameras>``). Matrices may be
``!!opencv-matrix`` nodes or plain (nested) sequences, read row-major. The key names of OpenCV's
own calibration sample are read as aliases (``camera_matrix`` for ``K``,
``distortion_coefficients`` for ``dist``, ``tvec`` for ``t``, ``image_width`` and
``image_height`` for ``image_size``); other keys in a camera map and at the top level are
ignored, because OpenCV users keep extra results (rms, projection matrices) in these files.

Other tools' files (OpenCV's calibration sample and stereo_calib, Caliscope, Qualisys) are read
by :mod:`calibration.foreign` through :func:`read_cameras`; :func:`load_calibration` also refuses
translations that are plainly millimetres.

Every problem raises :class:`calibration.errors.CalibrationError` with a one-line message that
names the file and says how to fix it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import tomllib
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from calibration import foreign
from calibration.camera import Camera, check_rotation
from calibration.errors import CalibrationError, utf8_text

__all__ = [
    "load_calibration",
    "read_metadata_section",
    "write_metadata_section",
    "read_lens_information",
    "read_lens_views",
    "write_lens_information",
    "save_calibration_toml",
    "save_calibration_opencv",
    "check_frame_sizes",
    "check_camera_count",
]

TOML_SUFFIXES = (".toml",)
OPENCV_SUFFIXES = (".yaml", ".yml", ".xml")

_TOML_CAMERA_KEYS = ("name", "size", "matrix", "distortions", "rotation", "translation", "fisheye",
                     "rolling_shutter_s")
_TOML_REQUIRED_KEYS = _TOML_CAMERA_KEYS[:-2]  # fisheye and rolling_shutter_s are optional
_FIX_FILE = "fix the file or recalibrate with 'rehab calibrate'"
_DIST_LENGTHS = (4, 5, 8)
# R and rvec given together must agree to this angle (rad); files store about 16 digits.
_RVEC_AGREEMENT_RAD = 1e-6


# ===================================================================== loading
def load_calibration(path: str | os.PathLike, *, allow_fisheye: bool = True) -> tuple[Camera, ...]:
    """Read the cameras of a calibration file, in calibration order.

    Args:
        path: a ``.toml`` (Pose2Sim/anipose, or Caliscope's config.toml) or ``.yaml``/``.yml``/``.xml``
            (OpenCV FileStorage as in the module docstring, or OpenCV's stereo_calib files) file,
            or a Qualisys ``.qca``/``.qca.txt`` (calibration/foreign.py).
        allow_fisheye: kept for callers of older versions; fisheye cameras are projected with
            their own model now, so they are always accepted.
    Returns:
        The cameras (2 or more, unique names), extrinsics world -> camera in metres.
    Raises:
        CalibrationError: missing, unreadable or inconsistent file, one camera's lens data only,
            or translations in millimetres (one line naming the file).
    """
    path = Path(path)
    cameras, placed = read_cameras(path)
    if not placed:
        what = "one camera's lens data" if len(cameras) == 1 else "the cameras' lens data but not where they stand"
        raise CalibrationError(
            f"{path}: holds {what}: gather every camera into one rig file with 'rehab calibrate import FILE... "
            "--out intrinsics.toml', then place them with 'rehab calibrate extrinsics' or 'wand'"
        )
    _check_camera_set(path, cameras)

    foreign.check_units(path, cameras)
    return cameras


def read_cameras(path: str | os.PathLike, *, size_px=None) -> tuple[tuple[Camera, ...], bool]:
    """The cameras of any supported calibration file and whether they are placed in a world frame.

    ``placed`` is False for files holding lens data only (OpenCV's single-camera file,
    stereo_calib's intrinsics.yml alone, a Caliscope config without poses); the project's own
    files count as placed (lens-only ones hold zeros). ``size_px`` is the image size for formats
    that do not store it (stereo_calib). No camera-count or units check here.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if not (suffix in TOML_SUFFIXES + OPENCV_SUFFIXES or foreign.is_qualisys(path)):
        raise CalibrationError(
            f"{path}: unknown calibration format {suffix or '(no extension)'!r}: give a .toml (Pose2Sim, anipose, "
            "Caliscope), an OpenCV .yaml/.yml/.xml or a Qualisys .qca file"
        )
    if not path.exists():
        raise CalibrationError(
            f"{path}: calibration file not found: run 'rehab calibrate' or give --calibration FILE"
        )
    if not path.is_file():
        raise CalibrationError(f"{path}: is not a file: give --calibration FILE with a calibration file")
    if foreign.is_qualisys(path):
        return foreign.qualisys(path), True
    if suffix in TOML_SUFFIXES:
        doc = _read_toml(path)
        if foreign.is_caliscope(doc):
            return foreign.caliscope(path, doc)
        return _cameras_from_toml(path, doc), True
    fs = _open_filestorage(path)
    try:
        if fs.getNode("cameras").empty() and foreign.is_opencv_single_or_stereo(fs):
            return foreign.opencv_single_or_stereo(path, fs, size_px)
    finally:
        fs.release()
    return _cameras_from_opencv(path), True


def _check_camera_set(path: Path, cameras: Sequence[Camera]) -> None:
    """At least two cameras with unique names."""
    if len(cameras) < 2:
        raise CalibrationError(
            f"{path}: holds {len(cameras)} camera{'' if len(cameras) == 1 else 's'} but triangulation "
            "needs 2 or more: calibrate all cameras together into one file"
        )
    seen: set[str] = set()
    for cam in cameras:
        with np.errstate(over="ignore", invalid="ignore"):
            finite = bool(np.isfinite(cam.P).all())
        if not finite:   # each value finite, but so large that the projection overflows
            raise CalibrationError(f"{path}: camera {cam.name!r} has values too large to project with (e.g. a "
                                   f"position of 1e300 m): {_FIX_FILE}")
        if cam.name in seen:
            raise CalibrationError(
                f"{path}: two cameras are named {cam.name!r}: give every camera a unique name"
            )
        seen.add(cam.name)


def _wrap_camera(path: Path, build) -> Camera:
    """Run a Camera constructor, prefixing its one-line error with the file name."""
    try:
        return build()
    except CalibrationError as exc:
        raise CalibrationError(f"{path}: {exc}: {_FIX_FILE}") from None


def _to_array(value, where: str, key: str) -> np.ndarray:
    """Nested lists of numbers (never booleans or strings) -> float64 array; one-line errors."""

    def walk(v):
        if isinstance(v, bool) or not isinstance(v, (int, float, list)):
            raise CalibrationError(
                f"{where}: {key!r} must hold numbers, found {type(v).__name__} {v!r}: {_FIX_FILE}"
            )
        return [walk(x) for x in v] if isinstance(v, list) else float(v)

    try:
        arr = np.array(walk(value), dtype=np.float64)
    except ValueError:  # ragged nesting
        raise CalibrationError(f"{where}: {key!r} has rows of different lengths: {_FIX_FILE}") from None
    return arr


def _check_shape(arr: np.ndarray, shapes: Sequence[tuple[int, ...]], where: str, key: str, what: str) -> None:
    if arr.shape not in shapes:
        got = "x".join(str(n) for n in arr.shape) or "a single number"
        raise CalibrationError(f"{where}: {key!r} must be {what}, got {got}: {_FIX_FILE}")
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{where}: {key!r} holds a non-finite number (nan or inf): {_FIX_FILE}")


def _whole_size(arr: np.ndarray, where: str, key: str) -> tuple[int, int]:
    """[width, height] in pixels, whole and positive."""
    if np.any(arr < 1) or np.any(np.abs(arr - np.round(arr)) > 1e-6):
        raise CalibrationError(
            f"{where}: {key!r} must be the image [width, height] in whole pixels, got "
            f"{arr.tolist()}: {_FIX_FILE}"
        )
    return int(round(arr[0])), int(round(arr[1]))


# --------------------------------------------------------------------- TOML
def _read_toml(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise CalibrationError(f"{path}: is not UTF-8 text: {_FIX_FILE}") from None
    except tomllib.TOMLDecodeError as exc:  # its message ends "(at line L, column C)"
        raise CalibrationError(f"{path}: not valid TOML: {exc}: {_FIX_FILE}") from None
    except OSError as exc:
        raise CalibrationError(f"{path}: cannot be read ({exc.strerror}): check its permissions") from None


def _cameras_from_toml(path: Path, doc: dict) -> tuple[Camera, ...]:
    cameras = []
    for key, value in doc.items():
        if key == "metadata":
            _check_toml_metadata(path, value)
        elif isinstance(value, dict):
            cameras.append(_camera_from_toml_table(path, key, value))
        else:
            raise CalibrationError(
                f"{path}: unexpected top-level key {key!r}: put each camera in its own table "
                "such as [cam_1] and other information under [metadata]"
            )
    return tuple(cameras)


def _check_toml_metadata(path: Path, meta) -> None:
    """[metadata] is a table; adjusted is a boolean and error a number when present."""
    if not isinstance(meta, dict):
        raise CalibrationError(f"{path}: 'metadata' must be a table [metadata]: {_FIX_FILE}")
    if "adjusted" in meta and not isinstance(meta["adjusted"], bool):
        raise CalibrationError(f"{path}: [metadata] 'adjusted' must be true or false: {_FIX_FILE}")
    err = meta.get("error", 0.0)
    if isinstance(err, bool) or not isinstance(err, (int, float)) or not math.isfinite(err):
        raise CalibrationError(f"{path}: [metadata] 'error' must be a finite number: {_FIX_FILE}")


def _camera_from_toml_table(path: Path, key: str, table: dict) -> Camera:
    name = table.get("name")
    where = f"{path}: camera [{key}]" + (f" ({name!r})" if isinstance(name, str) else "")
    for k in _TOML_REQUIRED_KEYS:
        if k not in table:
            raise CalibrationError(
                f"{where} lacks {k!r}: add it (keys: {', '.join(_TOML_CAMERA_KEYS)}) "
                "or recalibrate with 'rehab calibrate'"
            )
    for k in table:
        if k not in _TOML_CAMERA_KEYS:
            raise CalibrationError(
                f"{where}: unknown key {k!r}: the keys are {', '.join(_TOML_CAMERA_KEYS)}"
            )
    if not isinstance(name, str) or not name.strip():
        raise CalibrationError(f"{where}: 'name' must be a non-empty string: {_FIX_FILE}")
    size = _to_array(table["size"], where, "size")
    _check_shape(size, [(2,)], where, "size", "[width, height] in pixels")
    K = _to_array(table["matrix"], where, "matrix")
    _check_shape(K, [(3, 3)], where, "matrix", "3x3 numbers")
    dist = _to_array(table["distortions"], where, "distortions")
    _check_shape(dist, [(n,) for n in _DIST_LENGTHS], where, "distortions", "4, 5 or 8 numbers")
    rvec = _to_array(table["rotation"], where, "rotation")
    _check_shape(rvec, [(3,)], where, "rotation", "a Rodrigues vector of 3 numbers")
    t_m = _to_array(table["translation"], where, "translation")
    _check_shape(t_m, [(3,)], where, "translation", "3 numbers in metres")
    fisheye = table.get("fisheye", False)
    if not isinstance(fisheye, bool):
        raise CalibrationError(f"{where}: 'fisheye' must be true or false: {_FIX_FILE}")
    readout = table.get("rolling_shutter_s", 0.0)
    if isinstance(readout, bool) or not isinstance(readout, (int, float)) or not 0.0 <= readout < 1.0:
        raise CalibrationError(f"{where}: 'rolling_shutter_s' must be the rolling-shutter readout in seconds "
                               f"(0 for a global shutter, e.g. 0.025): {_FIX_FILE}")
    size_px = _whole_size(size, where, "size")
    return _wrap_camera(path, lambda: Camera(name, size_px, K, dist, rvec, t_m, fisheye, float(readout)))


# --------------------------------------------------------------------- OpenCV FileStorage
def _open_filestorage(path: Path):
    """cv2.FileStorage opened for reading, or a one-line CalibrationError with the parser's line."""
    try:   # OpenCV's strings are UTF-8: a stray Latin-1 byte would end in a UnicodeDecodeError later
        utf8_text(path, path.read_bytes(), CalibrationError)
    except OSError as exc:
        raise CalibrationError(f"{path}: cannot be read ({exc.strerror}): check its permissions") from None
    fs = cv2.FileStorage()
    try:
        opened = fs.open(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:
        raise CalibrationError(
            f"{path}: not a valid OpenCV FileStorage file ({_parse_error_text(exc, path)}): {_FIX_FILE}"
        ) from None
    if not opened:
        raise CalibrationError(f"{path}: cannot be opened by OpenCV FileStorage: {_FIX_FILE}")
    return fs


def _parse_error_text(exc: BaseException, path: Path) -> str:
    """'line N: reason' from an OpenCV persistence error, on one line."""
    if isinstance(exc, SystemError) and isinstance(exc.__cause__, cv2.error):
        exc = exc.__cause__
    # OpenCV's parsers put "<file>(<line>): <reason>" in the function-name slot, so look in both.
    candidates = [str(getattr(exc, "func", "")), str(getattr(exc, "err", ""))]
    prefix = f"{path}("
    for text in candidates:
        if text.startswith(prefix) and "): " in text:
            line, reason = text[len(prefix):].split("): ", 1)
            return f"line {line}: {reason}".replace("\n", " ")
    text = candidates[1] or str(exc)
    return " ".join(text.split())


def _node_numbers(node, where: str, key: str) -> np.ndarray:
    """A FileStorage number, (nested) sequence of numbers or !!opencv-matrix -> float64 array."""
    if node.isMap():
        mat = _opencv_matrix(node)
        if mat is None:
            raise CalibrationError(
                f"{where}: {key!r} is neither numbers nor a valid !!opencv-matrix "
                f"(rows x cols must match data): {_FIX_FILE}"
            )
        return mat
    if node.isSeq():
        rows = [_node_numbers(node.at(i), where, key) for i in range(node.size())]
        try:
            return np.array(rows, dtype=np.float64)
        except ValueError:
            raise CalibrationError(f"{where}: {key!r} has rows of different lengths: {_FIX_FILE}") from None
    if node.isInt() or node.isReal():
        return np.array(node.real(), dtype=np.float64)
    raise CalibrationError(f"{where}: {key!r} must hold numbers: {_FIX_FILE}")


def _opencv_matrix(node) -> np.ndarray | None:
    """An ``!!opencv-matrix`` map read field by field, or None when rows, cols and data disagree.

    ``FileNode.mat()`` is not used: on a matrix without ``cols`` it corrupted the heap and the
    process crashed later (found by tests/test_fuzz_inputs.py).
    """
    rows, cols, data = node.getNode("rows"), node.getNode("cols"), node.getNode("data")
    if not (rows.isInt() and cols.isInt() and data.isSeq()):
        return None
    n_rows, n_cols = int(rows.real()), int(cols.real())
    if not (0 < n_rows <= 1000 and 0 < n_cols <= 1000) or data.size() != n_rows * n_cols:
        return None
    items = [data.at(i) for i in range(data.size())]
    if not all(item.isInt() or item.isReal() for item in items):
        return None
    return np.array([item.real() for item in items], dtype=np.float64).reshape(n_rows, n_cols)


def _node_sized(node, n: Sequence[int], where: str, key: str, what: str) -> np.ndarray:
    """Numbers of ``node`` flattened row-major; their count must be in ``n``."""
    arr = _node_numbers(node, where, key).reshape(-1)
    if arr.size not in n:
        raise CalibrationError(f"{where}: {key!r} must be {what}, got {arr.size} numbers: {_FIX_FILE}")
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{where}: {key!r} holds a non-finite number (nan or inf): {_FIX_FILE}")
    return arr


def _aliased(node, keys: Sequence[str], where: str, required: bool = True):
    """(key, node) of the one key of ``keys`` present in the map ``node``, or (None, None)."""
    present = [k for k in keys if not node.getNode(k).empty() and not node.getNode(k).isNone()]
    if len(present) > 1:
        raise CalibrationError(
            f"{where}: both {present[0]!r} and {present[1]!r} are given: keep only one of them"
        )
    if not present:
        if required:
            names = " or ".join(repr(k) for k in keys)
            raise CalibrationError(f"{where} lacks {names}: add it (see calibration/files.py for the layout)")
        return None, None
    return present[0], node.getNode(present[0])


def _cameras_from_opencv(path: Path) -> tuple[Camera, ...]:
    fs = _open_filestorage(path)
    try:
        seq = fs.getNode("cameras")
        if seq.empty() or seq.isNone():
            if any(not fs.getNode(k).empty() for k in ("K", "camera_matrix")):
                raise CalibrationError(
                    f"{path}: holds a single camera but triangulation needs 2 or more: list every "
                    "camera under a 'cameras' sequence (layout in calibration/files.py)"
                )
            raise CalibrationError(
                f"{path}: no 'cameras' sequence: list one map per camera (K, dist, R or rvec, t, "
                "image_size) under 'cameras' (layout in calibration/files.py)"
            )
        if not seq.isSeq():
            raise CalibrationError(f"{path}: 'cameras' must be a sequence with one map per camera: {_FIX_FILE}")
        return tuple(_camera_from_opencv_node(path, i, seq.at(i)) for i in range(seq.size()))
    finally:
        fs.release()


def _camera_from_opencv_node(path: Path, index: int, node) -> Camera:
    where = f"{path}: cameras[{index}]"
    if not node.isMap():
        raise CalibrationError(f"{where} must be a map with K, dist, R or rvec, t, image_size: {_FIX_FILE}")
    keys = list(node.keys())
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise CalibrationError(f"{where}: key {dup[0]!r} appears twice: keep only one")
    name_node = node.getNode("name")
    if name_node.empty() or name_node.isNone():
        name = f"cam{index + 1}"
    elif name_node.isString():
        name = name_node.string()
    elif name_node.isInt():
        name = str(int(name_node.real()))
    else:
        name = ""
    if not name.strip():
        raise CalibrationError(f"{where}: 'name' must be a non-empty string: {_FIX_FILE}")
    where = f"{path}: camera {name!r} (cameras[{index}])"

    k_key, k_node = _aliased(node, ("K", "camera_matrix"), where)
    K = _node_sized(k_node, (9,), where, k_key, "a 3x3 matrix").reshape(3, 3)
    d_key, d_node = _aliased(node, ("dist", "distortion_coefficients"), where)
    dist = _node_sized(d_node, _DIST_LENGTHS, where, d_key, "4, 5 or 8 numbers (k1, k2, p1, p2[, k3...])")
    t_key, t_node = _aliased(node, ("t", "tvec"), where)
    t_m = _node_sized(t_node, (3,), where, t_key, "3 numbers in metres")
    size_px = _opencv_size(node, where)
    fisheye = False
    _, f_node = _aliased(node, ("fisheye",), where, required=False)
    if f_node is not None:
        flag = _node_numbers(f_node, where, "fisheye").reshape(-1) if not f_node.isString() else None
        if flag is None or flag.size != 1 or flag[0] not in (0.0, 1.0):
            raise CalibrationError(f"{where}: 'fisheye' must be 0 or 1: {_FIX_FILE}")
        fisheye = bool(flag[0])
    readout = 0.0
    _, s_node = _aliased(node, ("rolling_shutter_s",), where, required=False)
    if s_node is not None:
        value = _node_numbers(s_node, where, "rolling_shutter_s").reshape(-1) if not s_node.isString() else None
        if value is None or value.size != 1 or not 0.0 <= value[0] < 1.0:
            raise CalibrationError(f"{where}: 'rolling_shutter_s' must be the rolling-shutter readout in seconds "
                                   f"(0 for a global shutter, e.g. 0.025): {_FIX_FILE}")
        readout = float(value[0])

    r_node = node.getNode("R")
    v_node = node.getNode("rvec")
    has_r = not (r_node.empty() or r_node.isNone())
    has_v = not (v_node.empty() or v_node.isNone())
    if not (has_r or has_v):
        raise CalibrationError(f"{where} lacks 'R' (3x3 rotation) or 'rvec' (Rodrigues): add one")
    rvec = None
    if has_v:
        rvec = _node_sized(v_node, (3,), where, "rvec", "a Rodrigues vector of 3 numbers")
    if has_r:
        R = _node_numbers(r_node, where, "R").reshape(-1)
        if R.size == 3:
            raise CalibrationError(
                f"{where}: 'R' must be a 3x3 rotation matrix; write a Rodrigues vector as 'rvec'"
            )
        R = _node_sized(r_node, (9,), where, "R", "a 3x3 rotation matrix").reshape(3, 3)
        check_rotation(R, f"{where}: 'R'")
        cam = _wrap_camera(path, lambda: dataclasses.replace(
            Camera.from_rotation(name, size_px, K, dist, R, t_m, fisheye), rolling_shutter_s=readout))
        if rvec is not None:
            dR = cam.R.T @ Camera(name, size_px, K, dist, rvec, t_m).R
            angle = math.acos(min(1.0, max(-1.0, (np.trace(dR) - 1.0) / 2.0)))
            if angle > _RVEC_AGREEMENT_RAD:
                raise CalibrationError(
                    f"{where}: 'R' and 'rvec' describe different rotations ({math.degrees(angle):.3g} deg "
                    "apart): keep only one of them"
                )
        return cam
    return _wrap_camera(path, lambda: Camera(name, size_px, K, dist, rvec, t_m, fisheye, readout))


def _opencv_size(node, where: str) -> tuple[int, int]:
    """image_size [w, h], or image_width and image_height as OpenCV's calibration sample writes."""
    s_node = node.getNode("image_size")
    if not (s_node.empty() or s_node.isNone()):
        size = _node_sized(s_node, (2,), where, "image_size", "[width, height] in pixels")
        return _whole_size(size, where, "image_size")
    w_node, h_node = node.getNode("image_width"), node.getNode("image_height")
    if not (w_node.empty() or h_node.empty()):
        w = _node_sized(w_node, (1,), where, "image_width", "a number of pixels")
        h = _node_sized(h_node, (1,), where, "image_height", "a number of pixels")
        return _whole_size(np.concatenate([w, h]), where, "image_width/image_height")
    raise CalibrationError(f"{where} lacks 'image_size' ([width, height] in pixels): add it")


# ===================================================================== extensions
def read_metadata_section(path: str | os.PathLike, name: str) -> dict | None:
    """The ``[metadata.<name>]`` table of a TOML calibration file, or None when it has none.

    Raises:
        CalibrationError: the file is missing or not valid TOML.
    """
    path = Path(path)
    if path.suffix.lower() not in TOML_SUFFIXES:
        return None  # OpenCV files carry no extensions
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CalibrationError(f"{path}: calibration file not found: run 'rehab calibrate' or give --calibration FILE") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: not valid TOML: {exc}: {_FIX_FILE}") from None
    meta = doc.get("metadata")
    section = meta.get(name) if isinstance(meta, dict) else None
    return section if isinstance(section, dict) else None


def write_metadata_section(path: str | os.PathLike, name: str, toml_text: str) -> None:
    """Put (or replace) the ``[metadata.<name>]`` section of a TOML calibration file.

    The rest of the file is kept line for line; the section is appended at the end, after the
    lines of an older one are removed (its headers ``[metadata.<name>...]`` and
    ``[[metadata.<name>...]]`` and the lines under them).

    Args:
        path: an existing TOML calibration file; replaced atomically.
        name: the section name, e.g. ``"marker_colours"``.
        toml_text: the section as TOML, every table header starting with ``[metadata.<name>``
            or ``[[metadata.<name>``.
    Raises:
        CalibrationError: the file is not a calibration, or the section would make it invalid.
    """
    path = Path(path)
    if path.suffix.lower() not in TOML_SUFFIXES:
        raise CalibrationError(f"{path}: results are added to TOML calibrations only: convert it with 'rehab calibrate'")
    cameras = load_calibration(path, allow_fisheye=True)
    prefix = f"metadata.{name}"
    kept: list[str] = []
    inside = False
    for line in path.read_text(encoding="utf-8").splitlines():
        head = line.strip()
        if head.startswith("["):
            key = head.strip("[] \t").split("]")[0].strip()
            inside = key == prefix or key.startswith(prefix + ".")
        if not inside:
            kept.append(line)
    while kept and not kept[-1].strip():
        kept.pop()
    text = "\n".join(kept) + "\n\n" + toml_text.strip() + "\n"
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{path}: the [{prefix}] section is not valid TOML ({exc})") from None
    if set(doc) - {"metadata"} != {k for k, v in tomllib.loads(path.read_text(encoding="utf-8")).items() if k != "metadata"}:
        raise CalibrationError(f"{path}: the [{prefix}] section may only hold tables under [{prefix}]")
    _write_atomically(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    if len(load_calibration(path, allow_fisheye=True)) != len(cameras):
        raise CalibrationError(f"{path}: adding [{prefix}] changed the cameras read from it")  # pragma: no cover - guarded above


LENS_INFORMATION = "lens_information"
LENS_VIEWS = "lens_views"


def write_lens_information(path: str | os.PathLike, information: dict[str, np.ndarray],
                           views: dict[str, int] | None = None) -> None:
    """Keep how exact each camera's lens data are in a TOML calibration file: the information
    matrix (inverse covariance) of fx, fy, cx, cy and the distortion coefficients from the lens
    step (:attr:`calibration.intrinsics.IntrinsicsResult.information`), as
    ``[metadata.lens_information]`` with one ``"camera name" = [[...], ...]`` row list per camera;
    with ``views``, the number of images each lens step used as ``[metadata.lens_views]``.
    The positions step then refines the lens data with this weight (docs/CALIBRATION.md).
    """
    rows = [f"[metadata.{LENS_INFORMATION}]"]
    for name, info in information.items():
        info = np.asarray(info, np.float64)
        info = 0.5 * (info + info.T)
        rows.append(f"{json.dumps(name, ensure_ascii=False)} = [ {' '.join(_toml_list(r) + ',' for r in info)}]")
    write_metadata_section(path, LENS_INFORMATION, "\n".join(rows))
    if views:
        write_metadata_section(path, LENS_VIEWS, "\n".join(
            [f"[metadata.{LENS_VIEWS}]"] + [f"{json.dumps(name, ensure_ascii=False)} = {int(n)}" for name, n in views.items()]))


def read_lens_views(path: str | os.PathLike, cameras: Sequence[Camera]) -> list[int | None]:
    """How many images each camera's lens step used (:func:`write_lens_information`), None where
    the file does not say (or says something that is not a count)."""
    section = read_metadata_section(path, LENS_VIEWS) or {}
    out: list[int | None] = []
    for cam in cameras:
        n = section.get(cam.name)
        out.append(n if isinstance(n, int) and not isinstance(n, bool) and n >= 0 else None)
    return out


def read_lens_information(path: str | os.PathLike, cameras: Sequence[Camera]) -> list[np.ndarray | None]:
    """Each camera's lens information matrix from the file (:func:`write_lens_information`), None
    for a camera without one (lens data from another tool, or written before it was kept).

    Raises:
        CalibrationError: an entry is not a symmetric square matrix of the camera's lens parameters.
    """
    section = read_metadata_section(path, LENS_INFORMATION) or {}
    out: list[np.ndarray | None] = []
    for cam in cameras:
        value = section.get(cam.name)
        if value is None:
            out.append(None)
            continue
        where = f"{path}: [metadata.{LENS_INFORMATION}]"
        n = 4 + cam.dist.size
        info = _to_array(value, where, cam.name)
        _check_shape(info, [(n, n)], where, cam.name, f"{n}x{n} numbers (fx, fy, cx, cy and the {cam.dist.size} distortions)")
        if not np.all(np.isfinite(info)) or not np.allclose(info, info.T, rtol=1e-6, atol=0.0):
            raise CalibrationError(f"{where}: {cam.name!r} must be a symmetric matrix: remove the section or calibrate the lens again")
        out.append(info)
    return out


# ===================================================================== saving
def save_calibration_toml(
    path: str | os.PathLike,
    cameras: Sequence[Camera],
    *,
    adjusted: bool = False,
    error: float = 0.0,
) -> None:
    """Write ``cameras`` as a Pose2Sim/anipose TOML calibration (docs/INTERFACES.md).

    Tables ``[cam_1]``, ``[cam_2]``, ... in the given order, then ``[metadata]``. Numbers are
    written with Python's shortest round-trip repr, so reading the file back gives the same
    float64 values bit for bit.

    Args:
        path: destination file; replaced atomically.
        cameras: 2 or more cameras with unique names, extrinsics world -> camera in metres.
        adjusted: whether the extrinsics were refined by bundle adjustment (Pose2Sim's flag).
        error: mean reprojection error of the calibration in pixels.
    """
    path = Path(path)
    _check_camera_set(path, cameras)
    if not math.isfinite(float(error)):
        raise CalibrationError(f"{path}: the calibration error must be a finite number of pixels")
    lines: list[str] = []
    for i, cam in enumerate(cameras, start=1):
        w, h = cam.size_px
        lines += [
            f"[cam_{i}]",
            f"name = {json.dumps(cam.name, ensure_ascii=False)}",
            f"size = {_toml_list([float(w), float(h)])}",
            f"matrix = [ {' '.join(_toml_list(row) + ',' for row in cam.K)}]",
            f"distortions = {_toml_list(cam.dist)}",
            f"rotation = {_toml_list(cam.rvec)}",
            f"translation = {_toml_list(cam.t_m)}",
            f"fisheye = {'true' if cam.fisheye else 'false'}",
            *([f"rolling_shutter_s = {cam.rolling_shutter_s!r}"] if cam.rolling_shutter_s else []),
            "",
        ]
    lines += ["[metadata]", f"adjusted = {'true' if adjusted else 'false'}", f"error = {float(error)!r}", ""]
    _write_atomically(path, lambda tmp: tmp.write_text("\n".join(lines), encoding="utf-8"))


def _toml_list(values) -> str:
    """Floats the way Pose2Sim's toml writer lays them out: ``[ 1.0, 2.5,]``."""
    return "[ " + " ".join(f"{float(v)!r}," for v in values) + "]"


def save_calibration_opencv(path: str | os.PathLike, cameras: Sequence[Camera]) -> None:
    """Write ``cameras`` as OpenCV FileStorage YAML (``.yaml``/``.yml``) or XML (``.xml``).

    The layout is the ``cameras`` sequence of the module docstring, with ``R`` as a 3x3 matrix.
    OpenCV writes 17 significant digits, so values read back agree to about 1e-16 relative.

    Args:
        path: destination; the extension picks YAML or XML. Replaced atomically.
        cameras: 2 or more cameras with unique names, extrinsics world -> camera in metres.
    """
    path = Path(path)
    if path.suffix.lower() not in OPENCV_SUFFIXES:
        raise CalibrationError(f"{path}: OpenCV calibration files end in .yaml, .yml or .xml: rename it")
    _check_camera_set(path, cameras)

    def write(tmp: Path) -> None:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise CalibrationError(f"{path}: cannot be written: check the folder exists and is writable")
        try:
            fs.writeComment("cameras in calibration order; world -> camera: x_cam = R x_world + t (metres)")
            fs.startWriteStruct("cameras", cv2.FileNode_SEQ)
            for cam in cameras:
                fs.startWriteStruct("", cv2.FileNode_MAP)
                fs.write("name", cam.name)
                fs.startWriteStruct("image_size", cv2.FileNode_SEQ | cv2.FileNode_FLOW)
                for n in cam.size_px:
                    fs.write("", int(n))
                fs.endWriteStruct()
                fs.write("K", np.ascontiguousarray(cam.K))
                fs.write("dist", cam.dist.reshape(1, -1).copy())
                fs.write("R", np.ascontiguousarray(cam.R))
                fs.write("t", cam.t_m.reshape(3, 1).copy())
                fs.write("fisheye", int(cam.fisheye))
                if cam.rolling_shutter_s:
                    fs.write("rolling_shutter_s", float(cam.rolling_shutter_s))
                fs.endWriteStruct()
            fs.endWriteStruct()
        finally:
            fs.release()

    _write_atomically(path, write)


def _write_atomically(path: Path, write) -> None:
    """Call ``write(tmp)`` on a sibling temporary file with the same extension, then rename it."""
    if not path.parent.is_dir():
        raise CalibrationError(f"{path}: cannot be written: the folder {path.parent} does not exist")
    tmp = path.with_name(f".{path.name}.tmp{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except (OSError, cv2.error) as exc:
        reason = getattr(exc, "strerror", None) or "OpenCV could not open it"
        raise CalibrationError(
            f"{path}: cannot be written ({reason}): check the folder exists and is writable"
        ) from None
    finally:
        if tmp.exists():
            tmp.unlink()


# ===================================================================== consistency with the sources
def check_frame_sizes(
    cameras: Sequence[Camera],
    sizes: Sequence[tuple[int, int]],
    source_names: Sequence[str],
) -> None:
    """Raise CalibrationError if a source's frames do not have its camera's calibrated size.

    Args:
        cameras: the calibration, in order.
        sizes: (width, height) in pixels of each source's frames, one per camera, same order
            (an OpenCV image of shape (H, W, 3) has size (W, H)).
        source_names: what to call each source in the message, e.g. ``"cam2.avi"``.
    Raises:
        CalibrationError: "the calibration of cam2 is for 640x480 but cam2.avi delivers 1280x720: ...".
        ValueError: the three sequences differ in length (call check_camera_count first).
    """
    if not len(cameras) == len(sizes) == len(source_names):
        raise ValueError(
            f"check_frame_sizes: {len(cameras)} cameras, {len(sizes)} sizes and "
            f"{len(source_names)} source names; call check_camera_count first"
        )
    for cam, size, source in zip(cameras, sizes, source_names):
        cam.check_image_size(size, source)


def check_camera_count(
    cameras: Sequence[Camera],
    n_sources: int,
    what: str,
    *,
    kind: str = "videos or image folders",
    calibration_name: str = "the calibration",
) -> None:
    """Raise CalibrationError unless there is one source per calibrated camera.

    Args:
        cameras: the calibration, in order.
        n_sources: how many videos, image folders or live cameras there are.
        what: what holds the sources, e.g. ``"the recording"``, ``"the recording rec/"`` or
            ``"this computer"``.
        kind: plural noun for the sources, e.g. ``"videos"`` or ``"cameras"`` (made singular
            word by word for a count of 1).
        calibration_name: the calibration's file name for the message, e.g. ``"calibration.toml"``.
    Raises:
        CalibrationError: "calibration.toml has 4 cameras but the recording has 3 videos: ...".
    """
    if len(cameras) == n_sources:
        return
    if n_sources == 1:
        kind = " ".join(w[:-1] if w.endswith("s") else w for w in kind.split())
    raise CalibrationError(
        f"{calibration_name} has {len(cameras)} cameras but {what} has {n_sources} {kind}: "
        "give one per camera in calibration order, or the matching calibration with --calibration FILE"
    )
