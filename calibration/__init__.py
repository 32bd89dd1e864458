"""Camera models, calibration from images, and calibration files (no dependency on tracking or game)."""

from calibration.board import Checkerboard, Detection, detect_board
from calibration.camera import Camera
from calibration.errors import CalibrationError, RehabError
from calibration.extrinsics import ExtrinsicsResult, calibrate_extrinsics, world_from_floor_board
from calibration.intrinsics import IntrinsicsResult, calibrate_intrinsics
from calibration.wand import WandResult, calibrate_wand

__all__ = [
    "Camera",
    "CalibrationError",
    "Checkerboard",
    "Detection",
    "ExtrinsicsResult",
    "IntrinsicsResult",
    "RehabError",
    "WandResult",
    "calibrate_extrinsics",
    "calibrate_intrinsics",
    "calibrate_wand",
    "detect_board",
    "world_from_floor_board",
]
