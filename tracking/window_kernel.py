"""The search windows' colour look-up and moments in one compiled pass (numba).

The per-frame tracker reads ~56 small windows per frame set (14 markers x 4 cameras, ~1000
pixels each at 640x480). In numpy that is one OpenCV conversion per window (to make each pixel a
24-bit word), one table look-up for all of them, then a dozen whole-array passes to find each
window's pixels of its marker's colour and sum their moments: about 1 ms per frame set, nearly
all of it call overhead and temporaries, a third of the tracker's time. Here one loop over each
window's pixels does all of it, reading the bytes in place: a tenth of that.

:func:`window_moments` gives exactly what the numpy path in :meth:`tracking.tracker.Tracker._windows`
gives (integer sums in float64, exact in any order), so the two agree to the bit; the numpy path
stays as the fallback where numba is missing (``AVAILABLE``) or an image is not a plain
C-contiguous BGR array. The first call compiles (about a second, then cached on disk beside this
module where it is writable).
"""

from __future__ import annotations

import numpy as np

from tracking.jit import INSTALLED, compile_loop

AVAILABLE = INSTALLED
"""numba is installed (numba is a dependency; the numpy path keeps the tracker working without it)."""


def _window_moments(images, lut, cam, boxes, label, bits):
    k_count = cam.shape[0]
    total = 0
    for k in range(k_count):
        total += (boxes[k, 2] - boxes[k, 0]) * (boxes[k, 3] - boxes[k, 1])
    count = np.zeros(k_count, np.int64)
    sums = np.zeros((5, k_count))
    col = np.empty(total, np.float64)
    row = np.empty(total, np.float64)
    s = 8 - bits
    m = (1 << bits) - 1
    n = 0
    for k in range(k_count):
        img = images[cam[k]]
        x0, y0, x1, y1 = boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3]
        own = label[k]
        c = 0
        sc = 0.0
        sr = 0.0
        scc = 0.0
        srr = 0.0
        scr = 0.0
        for y in range(y0, y1):
            fy = float(y - y0)
            for x in range(x0, x1):
                word = np.int64(img[y, x, 0]) | (np.int64(img[y, x, 1]) << 8) | (np.int64(img[y, x, 2]) << 16)
                if bits < 8:
                    word = (((word >> s) & m) | ((word >> (8 + s - bits)) & (m << bits))
                            | ((word >> (16 + s - 2 * bits)) & (m << (2 * bits))))
                if lut[word] == own:
                    fx = float(x - x0)
                    col[n] = fx
                    row[n] = fy
                    n += 1
                    c += 1
                    sc += fx
                    sr += fy
                    scc += fx * fx
                    srr += fy * fy
                    scr += fx * fy
        count[k] = c
        sums[0, k] = sc
        sums[1, k] = sr
        sums[2, k] = scc
        sums[3, k] = srr
        sums[4, k] = scr
    return count, sums, col[:n], row[:n]


def _kernel():
    return compile_loop(_window_moments)


def usable(images) -> bool:
    """Whether :func:`window_moments` can read these images: numba present, and every image a
    C-contiguous (H, W, 3) uint8 array (one compiled variant for all)."""
    return AVAILABLE and all(img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
                             and img.flags.c_contiguous for img in images) and _kernel() is not None


def window_moments(images, lut: np.ndarray, cam: np.ndarray, boxes: np.ndarray, label: np.ndarray,
                   bits: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each window's pixels of its own colour label, and their moments.

    Args:
        images: C-contiguous (H, W, 3) uint8 BGR images (:func:`usable`).
        lut: the colour table (:attr:`tracking.colour_table.ColourTable.lut`), indexed by
            ``B | G << 8 | R << 16`` (quantized to ``bits`` per channel as the table is).
        cam: (K,) int64 image of each window; boxes: (K, 4) int64 ``x0, y0, x1, y1`` inside it,
            end exclusive; label: (K,) the colour label each window looks for (non-zero).

    Returns:
        count (K,) int64 pixels of the label per window; sums (5, K) float64 of their column,
        row, column^2, row^2 and column x row (window coordinates: 0 at ``x0``, ``y0``); col, row
        (n,) float64 window coordinates of those pixels, window after window, each in row order.
    """
    kernel = _kernel()
    if kernel is None:
        raise RuntimeError("numba is not installed or does not import: the tracker uses its numpy path")
    return kernel(tuple(images), lut, np.ascontiguousarray(cam, dtype=np.int64),
                     np.ascontiguousarray(boxes, dtype=np.int64), np.ascontiguousarray(label, dtype=np.int64),
                     int(bits))


def window_moments_py(images, lut, cam, boxes, label, bits: int = 8):
    """:func:`window_moments` in plain Python (the same loop, uncompiled): the reference the tests
    hold the compiled kernel and the tracker's numpy path to, on small windows."""
    return _window_moments(tuple(images), lut, np.asarray(cam, dtype=np.int64), np.asarray(boxes, dtype=np.int64),
                           np.asarray(label, dtype=np.int64), int(bits))
