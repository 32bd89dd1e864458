"""The search windows' moments in numpy: the reference of :func:`tracking.window_kernel.window_moments`
and its fallback where numba is missing or an image is not C-contiguous."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from tracking.colour.table import ColourTable


def window_moments_numpy(table: ColourTable, images: Sequence[np.ndarray], labels_k: np.ndarray, ci: np.ndarray,
                         lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`tracking.window_kernel.window_moments` in numpy: count (K,), sums (5, K), col, row (n,)
    of each window's pixels of its marker's colour (``labels_k`` (K,) that colour's label in the
    table, ``ci`` (K,) the camera, ``lo``/``hi`` (K, 2) the window's corners, ``hi`` exclusive)."""
    labels, starts = table.classify_windows(images, ci, np.concatenate([lo, hi], axis=1))
    # the marker's own colour among the (few) marker-coloured pixels of each window; the
    # pixels come window after window, so each window's share is one run of them, found by
    # K binary searches (runs and repeats: no per-pixel window look-up)
    hit = np.flatnonzero(labels != 0)  # (a bool array has numpy's fast nonzero)
    bounds = np.searchsorted(hit, starts)
    own = labels[hit] == np.repeat(labels_k, np.diff(bounds))
    hit = hit[own]
    n = hit.size
    run = np.concatenate(([0], np.cumsum(own)))[bounds]  # each window's first own pixel, and n
    count = np.diff(run)
    run = run[:-1]
    # pixel -> column and row in its window, in float64 (exact for these small integers; a
    # float division is cheaper than an integer one)
    local = (hit - np.repeat(starts[:-1], count)).astype(np.float64)
    width = np.repeat((hi[:, 0] - lo[:, 0]).astype(np.float64), count)
    cr = np.empty((5, n + 1))  # per pixel: column, row, their squares and product; one 0 column
    cr[:, n] = 0.0
    col, row = cr[0, :n], cr[1, :n]
    np.floor(local / width, out=row)
    np.subtract(local, row * width, out=col)
    np.multiply(cr[:2, :n], cr[:2, :n], out=cr[2:4, :n])
    np.multiply(col, row, out=cr[4, :n])
    # the five sums of every window as one reduction over the runs (the zero column ends the
    # last; an empty run gives the next run's first element: set to 0), then taken about the
    # window's centre pixel (offset ``first`` from the window's first pixel): sums of
    # integers, exact in float64 whatever the order
    sums = np.add.reduceat(cr, run, axis=1)
    sums[:, count == 0] = 0.0
    return count, sums, col, row
