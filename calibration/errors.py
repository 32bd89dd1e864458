"""Domain errors. Every message is one line that says what is wrong and how to fix it."""


class RehabError(Exception):
    """Bad input that the user can fix. The CLI prints the message as one line, no traceback."""


class CalibrationError(RehabError):
    """A calibration file or camera model is missing, malformed or inconsistent."""


def utf8_text(path, data: bytes, error: type[RehabError] = RehabError) -> str:
    """``data`` (a file's bytes) as UTF-8 text (a BOM is dropped), or one line naming the byte.

    A Latin-1 accent in a comment is the usual culprit; the message gives its line and byte
    position so that it can be found and the file saved as UTF-8.
    """
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise error(f"{path}: not UTF-8 text: byte 0x{data[exc.start]:02X} at line {line} (byte position "
                    f"{exc.start}): save the file as UTF-8") from None
