"""Calibration files written by other tools, read into :class:`calibration.camera.Camera`.

- OpenCV's calibration sample (``camera_matrix``, ``distortion_coefficients``, ``image_width``,
  ``image_height``, ``fisheye_model``; older versions capitalised, ``Camera_Matrix``...): one
  camera's lens data, no position.
- OpenCV's ``stereo_calib`` sample: ``intrinsics.yml`` (``M1``, ``D1``, ``M2``, ``D2``) and
  ``extrinsics.yml`` (``R``, ``T``: camera 1 -> camera 2), in one file or side by side. Camera 1
  is the world frame. It stores no image size: add ``image_width`` and ``image_height``.
- Caliscope's ``config.toml``: one ``[cam_N]`` table per camera (``matrix``, ``distortions``,
  ``size``, ``rotation`` 3x3 and ``translation`` world -> camera in metres, ``ignore``) among
  other tables and settings, which are skipped.
- Qualisys QTM's ``.qca`` (XML, often saved as ``.qca.txt``): per camera the camera's position
  (mm) and axes in the world, and intrinsics in 1/64 pixel on the sensor. Converted as
  Pose2Sim's ``calib_qca_fun`` does (its camera looks along its -Z, image y up; the distortion
  coefficients divided by 64 as there); the world frame stays QTM's (Z up).

:func:`check_units` refuses a rig whose cameras stand tens of metres apart or more: translations
in millimetres (aniposelib and OpenCV write whatever unit the board was measured in).
Every problem is a :class:`CalibrationError` with one line naming the file and what to fix.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from calibration.camera import Camera
from calibration.errors import CalibrationError

# Cameras farther apart than this (or from the origin) are not one clinic's room: millimetres.
PLAIN_MM_SPREAD_M = 25.0
STEREO_EXTRINSICS_NAMES = ("extrinsics.yml", "extrinsics.yaml", "extrinsics.xml")
_ZERO3 = np.zeros(3)


# --------------------------------------------------------------------- units
def check_units(path: Path, cameras: Sequence[Camera], *, hint: str | None = None) -> None:
    """Refuse translations that are plainly millimetres (cameras tens of metres apart or more)."""
    centres = np.array([c.centre_m for c in cameras])
    spread = float(np.max(np.linalg.norm(centres[:, None] - centres[None], axis=2))) if len(cameras) > 1 else 0.0
    far = float(np.max(np.linalg.norm(centres, axis=1)))
    if max(spread, far) > PLAIN_MM_SPREAD_M:
        fix = hint or f"rehab calibrate import {path.name} --translation-unit mm --out calibration.toml"
        raise CalibrationError(
            f"{path}: the cameras stand up to {max(spread, far):.0f} m apart: its translations are millimetres, "
            f"not metres; convert it with '{fix}'")


def scaled(cameras: Sequence[Camera], factor: float) -> tuple[Camera, ...]:
    """The cameras with their translations multiplied by ``factor`` (0.001 for millimetres)."""
    return tuple(Camera(c.name, c.size_px, c.K, c.dist, c.rvec, c.t_m * factor, c.fisheye) for c in cameras)


# --------------------------------------------------------------------- OpenCV FileStorage
def _keys_ci(fs) -> dict[str, str]:
    """Lower-case key -> key as written, for the top level of a FileStorage."""
    root = fs.root()
    return {k.lower(): k for k in root.keys()} if root.isMap() else {}


def _mat(fs, keys: dict[str, str], key: str, path: Path, sizes: Sequence[int], what: str) -> np.ndarray | None:
    name = keys.get(key.lower())
    if name is None:
        return None
    node = fs.getNode(name)
    arr = node.mat() if node.isMap() else None
    if arr is None and node.isSeq():
        arr = np.array([node.at(i).real() for i in range(node.size())])
    if arr is None and (node.isInt() or node.isReal()):
        arr = np.array([node.real()])
    if arr is None:
        raise CalibrationError(f"{path}: {name!r} is not a matrix of numbers: fix the file")
    arr = np.asarray(arr, np.float64).reshape(-1)
    if arr.size not in sizes or not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{path}: {name!r} must be {what}, got {arr.size} numbers: fix the file")
    return arr


def _size(fs, keys: dict[str, str], path: Path, size_px, who: str) -> tuple[int, int]:
    w = _mat(fs, keys, "image_width", path, (1,), "a number of pixels")
    h = _mat(fs, keys, "image_height", path, (1,), "a number of pixels")
    if w is not None and h is not None:
        return int(w[0]), int(h[0])
    if size_px is not None:
        return int(size_px[0]), int(size_px[1])
    raise CalibrationError(f"{path}: {who} holds no image size: add image_width and image_height (pixels) to it, "
                           "or give --size WxH to rehab calibrate import")


_DIST_SIZES = (4, 5, 8)


def is_opencv_single_or_stereo(fs) -> bool:
    keys = _keys_ci(fs)
    return "camera_matrix" in keys or "m1" in keys


def opencv_single_or_stereo(path: Path, fs, size_px=None) -> tuple[tuple[Camera, ...], bool]:
    """Cameras of an OpenCV calibration-sample or stereo_calib file, and whether they are placed.

    Returns:
        (cameras, placed): placed is False for lens data only (every camera at the origin).
    """
    keys = _keys_ci(fs)
    if "camera_matrix" in keys:
        K = _mat(fs, keys, "camera_matrix", path, (9,), "a 3x3 matrix").reshape(3, 3)
        fisheye_flag = _mat(fs, keys, "fisheye_model", path, (1,), "0 or 1")
        fisheye = bool(fisheye_flag is not None and fisheye_flag[0])
        dist = _mat(fs, keys, "distortion_coefficients", path, (4,) if fisheye else _DIST_SIZES,
                    "4 numbers (fisheye)" if fisheye else "4, 5 or 8 numbers")
        if dist is None:
            raise CalibrationError(f"{path}: lacks 'distortion_coefficients': add them or recalibrate")
        size = _size(fs, keys, path, size_px, "this camera file")
        return (_camera(path, path.stem.split(".")[0] or "cam1", size, K, dist, fisheye=fisheye),), False
    M1 = _mat(fs, keys, "M1", path, (9,), "a 3x3 matrix").reshape(3, 3)
    M2 = _mat(fs, keys, "M2", path, (9,), "a 3x3 matrix")
    D1 = _mat(fs, keys, "D1", path, _DIST_SIZES, "4, 5 or 8 numbers")
    D2 = _mat(fs, keys, "D2", path, _DIST_SIZES, "4, 5 or 8 numbers")
    missing = [k for k, v in (("M2", M2), ("D1", D1), ("D2", D2)) if v is None]
    if missing:
        raise CalibrationError(f"{path}: a stereo_calib file lacks {', '.join(missing)}: give the intrinsics.yml it wrote")
    size = _size(fs, keys, path, size_px, "stereo_calib's intrinsics.yml")
    R = _mat(fs, keys, "R", path, (9,), "a 3x3 rotation")
    T = _mat(fs, keys, "T", path, (3,), "3 numbers")
    if R is None or T is None:
        R, T = _stereo_extrinsics(path)
    cam1 = _camera(path, "cam1", size, M1, D1)
    if R is None:
        return (cam1, _camera(path, "cam2", size, M2.reshape(3, 3), D2)), False
    try:
        cam2 = Camera.from_rotation("cam2", size, M2.reshape(3, 3), D2, R.reshape(3, 3), T)
    except CalibrationError as exc:
        raise CalibrationError(f"{path}: {exc}: fix the file") from None
    return (cam1, cam2), True


def _stereo_extrinsics(path: Path) -> tuple[np.ndarray | None, np.ndarray | None]:
    """R, T from stereo_calib's extrinsics file beside ``path``, or (None, None)."""
    for name in STEREO_EXTRINSICS_NAMES:
        other = path.with_name(name)
        if other.is_file() and other != path:
            fs = cv2.FileStorage(str(other), cv2.FILE_STORAGE_READ)
            try:
                keys = _keys_ci(fs)
                R = _mat(fs, keys, "R", other, (9,), "a 3x3 rotation")
                T = _mat(fs, keys, "T", other, (3,), "3 numbers")
            finally:
                fs.release()
            if R is None or T is None:
                raise CalibrationError(f"{other}: lacks R or T (camera 1 -> camera 2): give stereo_calib's extrinsics.yml")
            return R, T
    return None, None


def _camera(path: Path, name: str, size, K, dist, R=None, t=_ZERO3, fisheye: bool = False) -> Camera:
    try:
        if R is None:
            return Camera(name, size, K, dist, _ZERO3, t, fisheye)
        return Camera.from_rotation(name, size, K, dist, R, t, fisheye)
    except CalibrationError as exc:
        raise CalibrationError(f"{path}: {exc}: fix the file") from None


# --------------------------------------------------------------------- Caliscope
def is_caliscope(doc: dict) -> bool:
    """Caliscope's config.toml: cameras with a ``port``, or its own settings and tables."""
    return any(isinstance(v, dict) and "port" in v for v in doc.values()) or any(
        k in doc for k in ("fps_recording", "fps_intrinsic_calibration", "capture_volume"))


def caliscope(path: Path, doc: dict) -> tuple[tuple[Camera, ...], bool]:
    """The cameras of a Caliscope ``config.toml`` and whether they are placed (all have poses)."""
    tables = [(k, v) for k, v in doc.items() if isinstance(v, dict) and k.startswith("cam_") and not v.get("ignore", False)]
    if not tables:
        raise CalibrationError(f"{path}: a Caliscope config.toml without [cam_N] tables: calibrate the cameras in Caliscope first")
    cams, placed = [], True
    for key, t in tables:
        lacking = [k for k in ("size", "matrix", "distortions") if k not in t]
        if lacking:
            raise CalibrationError(f"{path}: [{key}] lacks {', '.join(lacking)}: calibrate this camera's intrinsics in "
                                   "Caliscope, or set ignore = true")
        try:
            K = np.array(t["matrix"], np.float64)
            dist = np.array(t["distortions"], np.float64)
            size = tuple(int(v) for v in t["size"])
            has_pose = "rotation" in t and "translation" in t
            R = np.array(t["rotation"], np.float64) if has_pose else None
            tv = np.array(t["translation"], np.float64).reshape(-1) if has_pose else _ZERO3
        except (TypeError, ValueError):
            raise CalibrationError(f"{path}: [{key}] holds a value that is not numbers: fix the file") from None
        placed &= has_pose
        if R is not None and R.size == 3:
            R = cv2.Rodrigues(R.reshape(3, 1))[0]
        cams.append(_camera(path, key, size, K, dist, None if R is None else R.reshape(3, 3), tv))
    if not placed:
        cams = [Camera(c.name, c.size_px, c.K, c.dist, _ZERO3, _ZERO3) for c in cams]
    return tuple(cams), placed


# --------------------------------------------------------------------- Qualisys
def is_qualisys(path: Path) -> bool:
    name = path.name.lower()
    return name.endswith(".qca") or name.endswith(".qca.txt")


_QTM_AXES = np.diag([1.0, -1.0, -1.0])  # QTM's camera looks along -Z with image y up; OpenCV's along +Z, y down


def qualisys(path: Path) -> tuple[Camera, ...]:
    """The cameras of a Qualisys QTM calibration (``.qca`` XML), world -> camera in metres."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise CalibrationError(f"{path}: not a readable Qualisys calibration (XML): {exc}") from None
    cams = []
    for k, cam in enumerate(root.iter("camera")):
        name = cam.get("serial") or f"cam{k + 1}"
        fov, tr, intr = cam.find("fov_video"), cam.find("transform"), cam.find("intrinsic")
        if fov is None or tr is None or intr is None:
            missing = [n for n, e in (("fov_video", fov), ("transform", tr), ("intrinsic", intr)) if e is None]
            raise CalibrationError(f"{path}: camera {name} lacks <{'>, <'.join(missing)}>: export the calibration from QTM again")
        try:
            f = lambda e, a: float(e.attrib[a])  # noqa: E731
            left, top = f(fov, "left"), f(fov, "top")
            size = (int(f(fov, "right") - left + 1), int(f(fov, "bottom") - top + 1))
            K = np.array([[f(intr, "focalLengthU") / 64, 0.0, f(intr, "centerPointU") / 64 - left],
                          [0.0, f(intr, "focalLengthV") / 64, f(intr, "centerPointV") / 64 - top], [0.0, 0.0, 1.0]])
            dist = np.array([f(intr, "radialDistortion1"), f(intr, "radialDistortion2"), f(intr, "tangentalDistortion1"),
                             f(intr, "tangentalDistortion2")]) / 64
            axes = np.array([[f(tr, f"r{i}{j}") for j in (1, 2, 3)] for i in (1, 2, 3)])
            position_m = np.array([f(tr, a) for a in "xyz"]) / 1000.0
        except (KeyError, ValueError) as exc:
            raise CalibrationError(f"{path}: camera {name}: attribute {exc} missing or not a number: export it from QTM again") from None
        R = _QTM_AXES @ axes
        cams.append(_camera(path, name, size, K, dist, R, -R @ position_m))
    if not cams:
        raise CalibrationError(f"{path}: no <camera> in this Qualisys calibration")
    return tuple(cams)
