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

import numpy as np

logger = logging.getLogger(__name__)

INSTALLED = importlib.util.find_spec("numba") is not None
"""numba is installed (whether it imports is known after the first :func:`compile_loop`)."""

_compiled: dict[Callable, Callable | None] = {}
_warned = False


def compile_loop(fn: Callable, helpers: tuple[Callable, ...] = ()) -> Callable | None:
    """``fn`` compiled by numba (``njit``, cached on disk; the compilation itself happens at the
    first call, ~0.1-0.5 s), or None where numba is missing or fails to import.

    ``helpers``: plain functions ``fn`` calls (by their names in its module); each is compiled
    too and its name in ``fn``'s module rebound to the compiled one, which plain Python calls
    just as well."""
    global _warned
    if fn in _compiled:
        return _compiled[fn]
    result = None
    if INSTALLED:
        try:
            from numba import njit  # lazy: numba may be missing or fail to import: the numpy paths then run

            for helper in helpers:
                helper = getattr(helper, "py_func", helper)  # (its name may already be rebound)
                if helper not in _compiled:
                    _compiled[helper] = njit(cache=True, nogil=True)(helper)
                fn.__globals__[helper.__name__] = _compiled[helper]
            result = njit(cache=True, nogil=True)(fn)
        except Exception as exc:  # an unusable numba must not stop the tracker
            if not _warned:
                logger.warning("numba does not import (%s): the tracker runs its slower numpy paths", exc)
                _warned = True
    _compiled[fn] = result
    return result


def plain_images(images) -> bool:
    """Every image a C-contiguous (H, W, 3) uint8 array: the one layout the compiled loops that
    read images take (one compiled variant for all)."""
    return all(img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3 and img.flags.c_contiguous
               for img in images)
