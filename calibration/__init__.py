"""Camera models, calibration from images, and calibration files (no dependency on tracking or game)."""

from calibration.camera import Camera
from calibration.errors import CalibrationError, RehabError

__all__ = ["Camera", "CalibrationError", "RehabError"]
