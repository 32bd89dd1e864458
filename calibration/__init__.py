"""Camera models, calibration from images, and calibration files (no dependency on tracking or game).

The solvers that need scipy (extrinsics, wand) load on first use, so that importing the camera
model (every tracker process does) stays quick.
"""

from importlib import import_module

from calibration.board import Checkerboard, Detection, detect_board
from calibration.camera import Camera
from calibration.errors import CalibrationError, RehabError
from calibration.intrinsics import IntrinsicsResult, calibrate_intrinsics

_LAZY = {
    "ExtrinsicsResult": "calibration.extrinsics",
    "calibrate_extrinsics": "calibration.extrinsics",
    "world_from_floor_board": "calibration.extrinsics",
    "WandResult": "calibration.wand",
    "calibrate_wand": "calibration.wand",
}

__all__ = [
    "Camera",
    "CalibrationError",
    "Checkerboard",
    "Detection",
    "IntrinsicsResult",
    "RehabError",
    "calibrate_intrinsics",
    "detect_board",
    *_LAZY,
]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'calibration' has no attribute {name!r}")
