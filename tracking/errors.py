"""Errors of the tracking package; each message is one line that says how to fix the input."""

from calibration.errors import RehabError


class ContentError(RehabError):
    """A content YAML file (marker set, motion, rig, ...) is missing, malformed or unknown."""


class RecordingError(RehabError):
    """A recording folder is incomplete or inconsistent (videos, calibration, meta.yaml)."""


class MotionError(RehabError):
    """A motion (scripted or captured) cannot be played: unknown name, missing landmarks."""
