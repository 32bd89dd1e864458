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

from tracking.blobs import binary_roundness
from tracking.jit import INSTALLED, compile_loop, plain_images

AVAILABLE = INSTALLED
"""numba is installed (numba is a dependency; the numpy path keeps the tracker working without it)."""


def _table_index(img, y, x, bits):
    """The colour table's index of pixel (x, y): ``B | G << 8 | R << 16``, quantized to ``bits``
    per channel as :func:`tracking.colour.table._quantize_index` does for a table of fewer bits."""
    word = np.int64(img[y, x, 0]) | (np.int64(img[y, x, 1]) << 8) | (np.int64(img[y, x, 2]) << 16)
    if bits < 8:
        s, m = 8 - bits, (1 << bits) - 1
        word = (((word >> s) & m) | ((word >> (8 + s - bits)) & (m << bits))
                | ((word >> (16 + s - 2 * bits)) & (m << (2 * bits))))
    return word


def _window_moments(images, lut, cam, boxes, label, bits):
    k_count = cam.shape[0]
    total = 0
    for k in range(k_count):
        total += (boxes[k, 2] - boxes[k, 0]) * (boxes[k, 3] - boxes[k, 1])
    count = np.zeros(k_count, np.int64)
    sums = np.zeros((5, k_count))
    col = np.empty(total, np.float64)
    row = np.empty(total, np.float64)
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
                if lut[_table_index(img, y, x, bits)] == own:
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
    return compile_loop(_window_moments, helpers=(_table_index,))


def usable(images) -> bool:
    """Whether :func:`window_moments` can read these images: numba present, and every image a
    C-contiguous (H, W, 3) uint8 array (one compiled variant for all)."""
    return AVAILABLE and plain_images(images) and _kernel() is not None


def window_moments(images, lut: np.ndarray, cam: np.ndarray, boxes: np.ndarray, label: np.ndarray,
                   bits: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each window's pixels of its own colour label, and their moments.

    Args:
        images: C-contiguous (H, W, 3) uint8 BGR images (:func:`usable`).
        lut: the colour table (:attr:`tracking.colour.table.ColourTable.lut`), indexed by
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


def _own_mask(img, lut, bits, x0, y0, x1, y1, own):
    """(h, w) int64 of the window ``img[y0:y1, x0:x1]``: -2 where a pixel has colour label ``own``
    (not yet given a region), -1 elsewhere."""
    h, w = y1 - y0, x1 - x0
    comp = np.full((h, w), -1, np.int64)
    for y in range(h):
        for x in range(w):
            if lut[_table_index(img, y0 + y, x0 + x, bits)] == own:
                comp[y, x] = -2  # own colour, not yet labelled
    return comp


def _label_regions(comp, stack, bx0, by0, bx1, by1):
    """Give the own-colour cells of ``comp`` (-2) their 8-connected region's number, regions
    numbered in raster order of their first pixels; each region's box (inclusive) goes to
    ``bx0, by0, bx1, by1``. Returns the number of regions."""
    h, w = comp.shape
    n_comp = 0
    for y in range(h):
        for x in range(w):
            if comp[y, x] != -2:
                continue
            lab = n_comp
            n_comp += 1
            bx0[lab], by0[lab], bx1[lab], by1[lab] = x, y, x, y
            comp[y, x] = lab
            top = 0
            stack[top] = y * w + x
            top += 1
            while top > 0:
                top -= 1
                p = stack[top]
                py, px = p // w, p % w
                bx0[lab] = min(bx0[lab], px)
                bx1[lab] = max(bx1[lab], px)
                by0[lab] = min(by0[lab], py)
                by1[lab] = max(by1[lab], py)
                for dy in range(-1, 2):
                    qy = py + dy
                    if qy < 0 or qy >= h:
                        continue
                    for dx in range(-1, 2):
                        qx = px + dx
                        if qx < 0 or qx >= w or comp[qy, qx] != -2:
                            continue
                        comp[qy, qx] = lab
                        stack[top] = qy * w + qx
                        top += 1
    return n_comp


def _outside(comp, lab, gx0, gy0, gw, gh, stack):
    """(gh, gw) bool: the cells of region ``lab``'s box grown by one (corner ``gx0, gy0``) that
    the outside reaches through 4-connected cells of other labels; the rest is the region with
    its holes filled."""
    outside = np.zeros((gh, gw), np.bool_)
    top = 0
    for i in range(gh):
        for j in range(gw):
            if i == 0 or j == 0 or i == gh - 1 or j == gw - 1:
                outside[i, j] = True
                stack[top] = i * gw + j
                top += 1
    while top > 0:
        top -= 1
        p = stack[top]
        i, j = p // gw, p % gw
        for k in range(4):
            ii = i + (1 if k == 0 else -1 if k == 1 else 0)
            jj = j + (1 if k == 2 else -1 if k == 3 else 0)
            if ii <= 0 or jj <= 0 or ii >= gh - 1 or jj >= gw - 1 or outside[ii, jj]:
                continue
            if comp[gy0 + ii, gx0 + jj] == lab:
                continue
            outside[ii, jj] = True
            stack[top] = ii * gw + jj
            top += 1
    return outside


def _filled_moments(comp, lab, bx0, by0, bx1, by1, stack, nested, sums):
    """The moments of region ``lab`` with its holes filled, as find_blobs takes them in its patch
    (the box less 3 px, cut at 0): integer sums into ``sums`` (n, x, y, xx, yy, xy); a region
    inside its holes is marked ``nested`` (it has no outer outline of its own). Returns the
    patch's corner (px0, py0)."""
    gx0, gy0 = bx0[lab] - 1, by0[lab] - 1
    gw, gh = bx1[lab] - bx0[lab] + 3, by1[lab] - by0[lab] + 3
    outside = _outside(comp, lab, gx0, gy0, gw, gh, stack)
    px0, py0 = max(bx0[lab] - 3, 0), max(by0[lab] - 3, 0)
    n = 0.0
    sx = sy = sxx = syy = sxy = 0.0
    for i in range(1, gh - 1):
        for j in range(1, gw - 1):
            if outside[i, j]:
                continue
            other = comp[gy0 + i, gx0 + j]
            if other >= 0 and other != lab:
                nested[other] = True
            fx, fy = float(gx0 + j - px0), float(gy0 + i - py0)
            n += 1.0
            sx += fx
            sy += fy
            sxx += fx * fx
            syy += fy * fy
            sxy += fx * fy
    sums[0], sums[1], sums[2], sums[3], sums[4], sums[5] = n, sx, sy, sxx, syy, sxy
    return px0, py0


def _nearest_region(comp, n_comp, bx0, by0, bx1, by1, stack, pred_u, pred_v, min_area, max_area,
                    min_roundness, out):
    """Of the regions that pass the gates (area with holes filled, roundness), the one whose
    centroid is nearest (pred_u, pred_v), ties to the first in raster order. ``out`` receives its
    centroid, area and roundness; returns its number, -1 if none passes."""
    nested = np.zeros(max(n_comp, 1), np.bool_)
    sums = np.zeros(6)
    best = -1
    best_d = np.inf
    for lab in range(n_comp):
        if nested[lab]:
            continue
        px0, py0 = _filled_moments(comp, lab, bx0, by0, bx1, by1, stack, nested, sums)
        n, sx, sy, sxx, syy, sxy = sums[0], sums[1], sums[2], sums[3], sums[4], sums[5]
        if (bx1[lab] - bx0[lab] + 1) * (by1[lab] - by0[lab] + 1) < min_area or n < min_area or n > max_area:
            continue
        roundness = binary_roundness(n, sx, sy, sxx, syy, sxy)
        u, v = px0 + sx / n, py0 + sy / n
        if roundness < min_roundness:
            continue
        d = np.sqrt((u - pred_u) ** 2 + (v - pred_v) ** 2)
        if d < best_d:  # (regions in raster order of their first pixels: ties to the first)
            best, best_d = lab, d
            out[0], out[1], out[2], out[3] = u, v, n, roundness
    return best


def _region_pixels_near(comp, bu, bv):
    """The pixels (raster order, window coordinates) of the region that holds the marker-coloured
    pixel nearest (bu, bv), first in raster order on a tie (the arc fit's region, as
    ``ArcRegions.add_region`` picks it)."""
    h, w = comp.shape
    near, near_d = -1, np.inf
    for y in range(h):
        for x in range(w):
            if comp[y, x] >= 0:
                d2 = (x - bu) ** 2 + (y - bv) ** 2
                if d2 < near_d:
                    near, near_d = comp[y, x], d2
    count = 0
    for y in range(h):
        for x in range(w):
            if comp[y, x] == near:
                count += 1
    xs = np.empty(count, np.float64)
    ys = np.empty(count, np.float64)
    count = 0
    for y in range(h):
        for x in range(w):
            if comp[y, x] == near:
                xs[count] = x
                ys[count] = y
                count += 1
    return xs, ys


def _crowded_window(img, lut, bits, x0, y0, x1, y1, own, pred_u, pred_v, min_area, max_area, min_roundness):
    """The regions of colour label ``own`` in the window ``img[y0:y1, x0:x1]`` and the one nearest
    the prediction, as :func:`tracking.blobs.find_blobs` (binary centroids, one colour) measures
    and gates them: 8-connected regions whose outer outline's area (holes filled) lies in
    [min_area, max_area] and whose roundness is >= min_roundness; the nearest to (pred_u, pred_v)
    (window coordinates) of those, ties to the first in raster order of the regions' first pixels.

    Returns (found, u, v, area, roundness, xs, ys): the centroid in window coordinates, and the
    pixels (raster order) of the region that holds the marker-coloured pixel nearest that
    centroid (the arc fit's region, as ``_ArcRegions.add_region`` picks it).
    """
    comp = _own_mask(img, lut, bits, x0, y0, x1, y1, own)
    h, w = comp.shape
    # (the fill pushes each cell of a region's box grown by one at most once: up to
    # (h + 2) (w + 2) cells, more than the window's when a region spans it, e.g. a diagonal line)
    stack = np.empty((h + 2) * (w + 2), np.int64)
    bx0 = np.empty(h * w, np.int64)
    by0 = np.empty(h * w, np.int64)
    bx1 = np.empty(h * w, np.int64)
    by1 = np.empty(h * w, np.int64)
    n_comp = _label_regions(comp, stack, bx0, by0, bx1, by1)
    out = np.zeros(4)
    best = _nearest_region(comp, n_comp, bx0, by0, bx1, by1, stack, pred_u, pred_v, min_area, max_area,
                           min_roundness, out)
    if best < 0:
        return False, 0.0, 0.0, 0.0, 0.0, np.empty(0, np.float64), np.empty(0, np.float64)
    xs, ys = _region_pixels_near(comp, out[0], out[1])
    return True, out[0], out[1], out[2], out[3], xs, ys


_CROWDED_HELPERS = (_table_index, binary_roundness, _own_mask, _label_regions, _outside, _filled_moments,
                    _nearest_region, _region_pixels_near)


def crowded_window(image, lut: np.ndarray, bits: int, box, own: int, pred_px, gate):
    """:func:`_crowded_window` compiled, for one C-contiguous (H, W, 3) uint8 image (:func:`usable`);
    ``box`` (x0, y0, x1, y1) inside it, ``pred_px`` the predicted centre in full-image pixels,
    ``gate`` a :class:`tracking.full_frame.BlobGates`. Returns (found, (u, v) full-image pixels,
    area, roundness, xs, ys window pixels of the arc fit's region)."""
    x0, y0, x1, y1 = (int(v) for v in box)
    found, u, v, area, roundness, xs, ys = compile_loop(_crowded_window, helpers=_CROWDED_HELPERS)(
        image, lut, int(bits), x0, y0, x1, y1, int(own), float(pred_px[0]) - x0, float(pred_px[1]) - y0,
        float(gate.min_area_px), float(gate.max_area_px), float(gate.min_roundness))
    return found, (u + x0, v + y0), area, roundness, xs, ys


def _fill_labels(images, lut, cam, boxes, bits, labels):
    for k in range(cam.shape[0]):
        img = images[cam[k]]
        out = labels[cam[k]]
        for y in range(boxes[k, 1], boxes[k, 3]):
            for x in range(boxes[k, 0], boxes[k, 2]):
                out[y, x] = lut[_table_index(img, y, x, bits)]


def fill_labels(images, lut: np.ndarray, cam: np.ndarray, boxes: np.ndarray, bits: int, labels) -> None:
    """Write the colour table's label of every pixel of each box into ``labels``, all boxes in one
    compiled pass (:func:`usable` images).

    Args:
        images: the frame set's C-contiguous (H, W, 3) uint8 BGR images.
        lut: the colour table; ``bits`` its bits per channel.
        cam: (K,) image of each box; boxes: (K, 4) ``x0, y0, x1, y1`` inside it, end exclusive.
        labels: one C-contiguous (H, W) uint8 array per image, written in the boxes only.
    """
    kernel = compile_loop(_fill_labels, helpers=(_table_index,))
    if kernel is None:
        raise RuntimeError("numba is not installed or does not import: the tracker uses its numpy path")
    kernel(tuple(images), lut, np.ascontiguousarray(cam, dtype=np.int64),
           np.ascontiguousarray(boxes, dtype=np.int64), int(bits), tuple(labels))
