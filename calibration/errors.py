"""Domain errors. Every message is one line that says what is wrong and how to fix it."""


class RehabError(Exception):
    """Bad input that the user can fix. The CLI prints the message as one line, no traceback."""


class CalibrationError(RehabError):
    """A calibration file or camera model is missing, malformed or inconsistent."""
