"""Checked option values of the ``rehab`` command line: every number finite and in its range.

``nan`` and ``inf`` parse as floats and pass ``> 0``; a frame rate of ``inf`` or a length of
``nan`` then hangs or crashes deep inside a command. :func:`number` builds an argparse type that
refuses them, and :class:`OneLineParser` reports a bad option as one line (no usage block).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr (exit code 2)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def size_px(text: str) -> tuple[int, int]:
    """An image or window size option ``WxH`` (16..8192 pixels each)."""
    try:
        w, h = text.lower().split("x")
        size = (int(w), int(h))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r} must look like 640x480") from None
    if min(size) < 16 or max(size) > 8192:
        raise argparse.ArgumentTypeError(f"size {text!r} is out of range (16..8192 pixels)")
    return size


def number(low: float | None = None, high: float | None = None, *, integer: bool = False,
           above: bool = False):
    """An argparse type for a finite number in ``[low, high]`` (``(low, high]`` when ``above``).

    Args:
        low, high: the range (None: unbounded on that side; ``nan``/``inf`` are always refused).
        integer: whole numbers only (``2.7`` is refused, not truncated).
        above: the value must be greater than ``low`` (rates, lengths, sizes).
    """

    def parse(text: str) -> float | int:
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {'whole ' if integer else ''}number") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r}: give a finite number")
        too_low = low is not None and (value <= low if above else value < low)
        if too_low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"{text!r} is out of range: give {describe()}")
        return value

    def describe() -> str:
        kind = "a whole number" if integer else "a number"
        if low is not None and high is not None:
            return f"{kind} {'above' if above else 'from'} {low:g} {'up ' if above else ''}to {high:g}"
        if low is not None:
            return f"{kind} {'above' if above else 'of at least'} {low:g}"
        return f"{kind} up to {high:g}"

    parse.__name__ = "number"
    return parse


#: Common ranges. Rates in frames per second, lengths of time in seconds.
FPS = number(0.0, 1000.0, above=True)
SECONDS = number(0.0, 7 * 86400.0, above=True)
NOISE = number(0.0, 100.0)
SEED = number(0, 2**32 - 1, integer=True)
COUNT = number(1, 1_000_000, integer=True)
LENGTH_MM = number(0.0, 100_000.0, above=True)


def handle_broken_pipe() -> int:
    """``rehab ... | head`` closed the pipe: end quietly (exit 141 like a shell), no traceback."""
    import os

    try:   # Python flushes stdout at exit: point it at /dev/null so that flush cannot fail again
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return 141


def check_outputs(outputs: dict[str, Path | None], examples: dict[str, str] | None = None) -> None:
    """Check the files a command will write, before its work: each writable, none a folder, no two the same.

    Missing folders are created (as the writers do); a probe file shows that the folder takes
    files (a read-only disk, a folder of someone else). ``outputs`` maps an option (``--out``) to
    its path (None: not asked for); ``examples`` an option to a file name the fix suggests
    (``markers.trc``).

    Raises:
        RehabError: one line naming the option, the path and the fix.
    """
    import os
    import tempfile

    from calibration.errors import RehabError

    seen: dict[Path, str] = {}
    for option, path in outputs.items():
        if path is None:
            continue
        path = Path(path)
        key = path.resolve()
        if key in seen:
            raise RehabError(f"{option} {path} is also given to {seen[key]}: give each output its own file")
        seen[key] = option
        if path.is_dir():
            name = (examples or {}).get(option, "out")
            raise RehabError(f"{option} {path} is a folder: give a file name, e.g. {path / name}")
        if path.name in ("", ".", ".."):
            raise RehabError(f"{option} {path}: give a file name")
        folder = path.parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, probe = tempfile.mkstemp(prefix=".rehab-probe-", dir=folder)
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise RehabError(f"{option} {path}: cannot write in {folder} ({exc.strerror or exc}): choose a folder "
                             f"you can write") from None
