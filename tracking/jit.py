"""Compiling the tracker's hot loops with numba, where it is installed and imports.

The loops (:mod:`tracking.window_kernel`, the triangulation, the arc fits' iterations) are plain
Python functions over arrays; :func:`compile_loop` returns them compiled, or None where numba is
missing or cannot be imported (e.g. a numpy it does not support), and the callers then take
their numpy paths. numba is imported on the first call only: importing it costs a few tenths of a
second that commands without a tracker need not pay.
"""

from __future__ import annotations

import importlib.util
import logging
from typing import Callable

logger = logging.getLogger(__name__)

INSTALLED = importlib.util.find_spec("numba") is not None
"""numba is installed (whether it imports is known after the first :func:`compile_loop`)."""

_compiled: dict[Callable, Callable | None] = {}
_warned = False


def compile_loop(fn: Callable) -> Callable | None:
    """``fn`` compiled by numba (``njit``, cached on disk; the compilation itself happens at the
    first call, ~0.1-0.5 s), or None where numba is missing or fails to import."""
    global _warned
    if fn in _compiled:
        return _compiled[fn]
    result = None
    if INSTALLED:
        try:
            from numba import njit

            result = njit(cache=True, nogil=True)(fn)
        except Exception as exc:  # an unusable numba must not stop the tracker
            if not _warned:
                logger.warning("numba does not import (%s): the tracker runs its slower numpy paths", exc)
                _warned = True
    _compiled[fn] = result
    return result
