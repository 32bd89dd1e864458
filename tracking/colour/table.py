"""Colour extraction with a lookup table: every pixel's bytes index a table of colour labels.

The seed method (docs/METHOD.md, "Colour extraction with a lookup table") fills a table indexed by a
pixel's (R, G, B) bytes in advance, so that classifying a pixel is one memory read. Here the table
holds 0 for background and ``k + 1`` for palette colour ``k``.

Decision rule (evaluated once, when the table is built)
-------------------------------------------------------
A colour belongs to palette colour ``k`` when, in HSV terms,

* its hue is within ``hue_tol_deg`` of the palette hue (nearest palette hue wins),
* its saturation ``(max - min) / max`` is at least ``min_saturation`` times the palette colour's
  own saturation plus ``noise_counts / max`` (sensor noise moves a dark colour's saturation more),
* its value ``max(R, G, B) / 255`` is at least ``min_value``.

Hue and saturation do not change when a colour is scaled, so Lambert shading (a ball's dark side
at 25-30 % of full brightness, +-30 % lighting change) only meets the ``min_value`` floor (0.12:
the darkest palette colour, green, at 18 % brightness is still 0.14). A mild colour cast (channel
gains such as (1.1, 1.0, 0.85)) moves the hue: the palette magenta (hue 304 deg) by 13 deg, the
yellow (50 deg) by 5-10 deg; ``hue_tol_deg = 20`` leaves room for that plus sensor noise.
Saturation is what separates the markers from skin and wood: the palette colours have one channel
at zero (saturation 1.0, and >= 0.89 on the dark side under noise), while skin and wood have
saturation 0.3-0.75 at hues of 20-40 deg, next to the yellow; a warm cast brings dark skin
(141, 85, 36) to saturation 0.80 at 26 deg, so ``min_saturation = 0.8`` plus the noise margin
(``noise_counts = 2``) keeps it out. White speculars, greys, black and dark clothes fail the
saturation or the value floor. With sensor noise of 2.5 counts the table keeps > 99.9 % of marker
pixels down to 30 % brightness (> 95 % at 18 %); deep-shadow dark skin leaks ~1-10 % scattered
pixels, which ``find_blobs``'s area and roundness gates reject. Any saturated object within the
hue tolerance of a marker is marker-coloured to the table: orange and olive pass as yellow, purple
as magenta, teal and (with a cyan marker at 191 deg) saturated denim blue (213 deg) under a warm
cast as cyan; clothes and props must avoid the marker hues.

Full and quantized tables
-------------------------
``bits = 8`` is the FULL table: 2**24 entries (16 MiB), index ``B | G << 8 | R << 16``, which is
the little-endian 32-bit word starting at a pixel's B byte with its top byte masked off. OpenCV
widens a window's BGR pixels to BGRA words (``cv2.cvtColor`` straight into the index buffer) and
one AND clears the alpha byte; the look-up is one ``np.take``. (Reading the words through an
unaligned, stride-3 ``uint32`` view of the image bytes, as first done, makes numpy buffer the
reads: 0.30 ms for a 640x480 index against 0.12 ms, 11 us against 7 us for a 61x61 window,
minimum CPU times on the shared machine.) :meth:`ColourTable.classify_windows` labels the search
windows of all markers in all cameras with one look-up.

``bits < 8`` is a QUANTIZED table: 2**(3*bits) entries (2**18 = 256 KiB for 6 bits), index
``(B >> s) | (G >> s) << bits | (R >> s) << 2*bits`` with ``s = 8 - bits``; each bin holds the label
of the colour at the bin's centre. The smaller table stays in cache, but the index needs three
shifts, three ANDs and two ORs more.

Measured with ``benchmark()`` (median of 50 calls; 640x480 frames with a shaded background, a skin
patch, 14 anti-aliased marker discs of radius 7 px and noise) on 2 cores shared with other jobs;
ranges over three runs at a load average of ~1.5 and of 3-7:

==========================================  ==================  ==================
                                             load ~1.5           load 3-7
==========================================  ==================  ==================
classify 640x480, full table                 0.49-0.61 ms        0.51-0.97 ms
classify 640x480, quantized 6-bit            0.71-0.91 ms        0.79-1.21 ms
classify_window 40x40, full                  11-12 us            11-26 us
classify_window 40x40, quantized             19-20 us            19-45 us
4 windows of 40x40, full                     45-66 us            47-102 us
classify + find_blobs, 4 frames, binary      4-7 ms              6-9 ms
classify + find_blobs, 4 frames, refined     16-18 ms            22-31 ms
build, full / quantized                      0.09-0.12 s / 3 ms  0.12-0.21 s / 3-12 ms
==========================================  ==================  ==================

Interleaved A/B timing (400 frame pairs, 4000 window pairs, load ~3.5): the full table was
faster in 96 % of frame pairs (median 0.98 vs 1.18 ms) and 99 % of window pairs (11.8 vs
20.2 us). Its index costs one operation (0.2-0.3 ms of a frame) and the look-up ~0.4-0.6 ms; the
quantized index costs eight operations, which outweighs the cache benefit of a 256 KiB table
(its look-up alone is ~25 % faster). There is no pre-filter: the look-up costs ~2 ns per pixel,
about what any per-pixel test that could skip it would cost; preallocating the index buffer saved
nothing measurable. Refined blob centroids cost ~0.1-0.3 ms per blob (tracking.blobs; the 16-18 ms
row predates its last guard, which adds ~10 %).

So the full table is the default (``DEFAULT_BITS = 8``); it is also exact. On uniformly random
colours the 6-bit table agrees with the full one on 99.43 % (7 bits 99.74 %, 5 bits 98.87 %):
a bin cut by an oblique hue or saturation boundary cannot agree on all its colours, so 99.9 % is
out of reach for any quantized table with this rule; on the colours of markers and backgrounds
under the test lights and noise the agreement is > 99.9 %.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field
from typing import Sequence

import cv2
import numpy as np

from tracking.errors import ContentError

DEFAULT_BITS = 8
"""Bits per channel of the default table: 8 = full table (measured faster, see module doc)."""
DEFAULT_HUE_TOL_DEG = 20.0
"""Hue half-width around each palette hue: colour casts move the palette magenta by 13 deg."""
DEFAULT_MIN_SATURATION = 0.8
"""Minimum saturation as a fraction of the palette colour's saturation: skin and wood reach 0.75."""
DEFAULT_MIN_VALUE = 0.12
"""Minimum HSV value max(R,G,B)/255: the dark side of a ball at 25 % under 30 % less light."""
DEFAULT_NOISE_COUNTS = 2.0
"""Saturation margin for noise, in counts: cuts noisy dark-skin pixels to a third for 0.2 % of marker pixels."""
MIN_PALETTE_SATURATION = 0.5
"""Palette colours less saturated than this cannot be told from skin, wood and greys."""
MIN_PALETTE_VALUE = 0.3
"""Palette colours darker than this vanish in shadow."""

_HUE_UNITS_PER_DEG = 256.0 / 360.0  # OpenCV *_FULL hue: 0..255 for 0..360 deg


def hsv_deg(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) sRGB 0..255 -> (N, 3) float64 hue in deg [0, 360), saturation 0..1, value 0..1."""
    rgb = np.asarray(rgb, dtype=np.float64)
    mx = rgb.max(axis=1)
    mn = rgb.min(axis=1)
    chroma = mx - mn
    r, g, b = rgb.T
    safe = np.where(chroma > 0, chroma, 1.0)
    hue = np.where(
        mx == r, (g - b) / safe, np.where(mx == g, 2.0 + (b - r) / safe, 4.0 + (r - g) / safe)
    )
    hue = np.where(chroma > 0, (60.0 * hue) % 360.0, 0.0)
    sat = np.where(mx > 0, chroma / np.where(mx > 0, mx, 1.0), 0.0)
    return np.stack([hue, sat, mx / 255.0], axis=1)


def _hue_labels(palette_hsv: np.ndarray, hue_tol_deg: float) -> np.ndarray:
    """(256,) uint8: for each hue byte of OpenCV's 8-bit *_FULL HSV, 0 or k + 1 for the nearest
    palette hue within the tolerance (ties -> lower k)."""
    hue_deg = np.arange(256, dtype=np.float64) / _HUE_UNITS_PER_DEG
    dh = np.abs((hue_deg[None, :] - palette_hsv[:, 0:1] + 180.0) % 360.0 - 180.0)  # (K, 256)
    dh = np.where(dh <= hue_tol_deg, dh, np.inf)
    return np.where(np.isfinite(dh.min(axis=0)), np.argmin(dh, axis=0) + 1, 0).astype(np.uint8)


def value_saturation_gate(
    palette_hsv: np.ndarray, min_saturation: float, min_value: float, noise_counts: float
) -> np.ndarray:
    """(K + 1, 256, 256) uint8 ``gate[label, V, S]``: the label if a colour of that hue label with
    value byte V and saturation byte S passes the value and saturation floors, else 0.

    The saturation floor of colour k is ``min_saturation * S_k + noise_counts / V``: noise of a few
    counts moves a dark colour's saturation ``(max - min) / max`` far more than a bright one's.
    """
    k1 = palette_hsv.shape[0] + 1
    value = np.arange(256, dtype=np.float64)
    floor = np.empty((k1, 256))
    floor[0] = np.inf
    floor[1:] = min_saturation * palette_hsv[:, 1:2] + noise_counts / np.maximum(value, 1.0)[None, :]
    floor[:, value < min_value * 255.0 - 1e-9] = np.inf
    sat = np.arange(256, dtype=np.float64) / 255.0
    passes = sat[None, None, :] >= floor[:, :, None] - 1e-9
    return np.where(passes, np.arange(k1, dtype=np.uint8)[:, None, None], 0).astype(np.uint8)


def _fill_table(
    bits: int,
    palette_hsv: np.ndarray,
    hue_tol_deg: float,
    min_saturation: float,
    min_value: float,
    noise_counts: float,
) -> np.ndarray:
    """Evaluate the decision rule for every table entry.

    Returns:
        (2**(3*bits),) uint8 labels in table-index order ``B | G << bits | R << 2*bits``; a
        quantized bin holds the label of its centre colour (rounded up, e.g. 2 for bin 0..3).

    One R level at a time (a 2**bits x 2**bits image of G, B) keeps the work in cache. OpenCV's
    8-bit HSV bytes are looked up in place: the hue byte gives a label, then the little-endian
    word ``S | V << 8`` at the next byte, with the label above it, indexes the gate.
    """
    n = 1 << bits
    step = 1 << (8 - bits)
    levels = (np.arange(n) * step + step // 2).astype(np.uint8)
    hue_label = _hue_labels(palette_hsv, hue_tol_deg)
    gate = value_saturation_gate(palette_hsv, min_saturation, min_value, noise_counts).reshape(-1)
    table = np.empty((n, n, n), dtype=np.uint8)  # [R, G, B]
    plane = np.empty((n, n, 3), dtype=np.uint8)  # [G, B] -> BGR
    plane[..., 0] = levels[None, :]
    plane[..., 1] = levels[:, None]
    hsv = np.empty((n, n, 3), dtype=np.uint8)
    hue = hsv.reshape(-1, 3)[:, 0]
    sat_val = np.ndarray((n * n,), dtype="<u2", buffer=hsv, offset=1, strides=(3,))
    label = np.empty(n * n, dtype=np.uint8)
    index = np.empty(n * n, dtype=np.uint32)
    for r in range(n):
        plane[..., 2] = levels[r]
        cv2.cvtColor(plane, cv2.COLOR_BGR2HSV_FULL, dst=hsv)
        np.take(hue_label, hue, out=label)
        np.left_shift(label, 16, out=index, dtype=np.uint32)
        index |= sat_val
        np.take(gate, index, out=table[r].reshape(-1), mode="clip")
    return table.reshape(-1)


@dataclass(frozen=True, slots=True, eq=False)
class ColourTable:
    """A lookup table from a pixel's BGR bytes to a palette label (0 = background, k+1 = colour k).

    Build it once with :meth:`build`; it is immutable and safe to share between threads.

    Attributes:
        palette_rgb: (K, 3) uint8 sRGB palette, read-only.
        bits: bits per channel used to index the table (8 = full table).
        hue_tol_deg: hue half-width around each palette hue, degrees.
        min_saturation: saturation floor as a fraction of each palette colour's saturation.
        min_value: floor of max(R, G, B) / 255.
        noise_counts: sensor noise allowance in 8-bit counts (raises the saturation floor of dark
            colours by noise_counts / max(R, G, B)).
        lut: (2**(3*bits),) uint8 labels, read-only.
    """

    palette_rgb: np.ndarray = field(repr=False)
    bits: int
    hue_tol_deg: float
    min_saturation: float
    min_value: float
    noise_counts: float
    lut: np.ndarray = field(repr=False)

    @classmethod
    def build(
        cls,
        palette_rgb: np.ndarray,
        *,
        bits: int = DEFAULT_BITS,
        hue_tol_deg: float = DEFAULT_HUE_TOL_DEG,
        min_saturation: float = DEFAULT_MIN_SATURATION,
        min_value: float = DEFAULT_MIN_VALUE,
        noise_counts: float = DEFAULT_NOISE_COUNTS,
    ) -> "ColourTable":
        """Fill the table for a palette (deterministic; ~0.1 s for the full table).

        Args:
            palette_rgb: (K, 3) uint8 sRGB marker colours, 1 <= K <= 254.
            bits: bits per channel, 4..8; 8 is the full 2**24 table, 6 a 2**18 table.
            hue_tol_deg: hue half-width in degrees, 1..60.
            min_saturation: 0..1, fraction of each palette colour's HSV saturation.
            min_value: 0..1, floor of max(R, G, B) / 255.
            noise_counts: >= 0, sensor noise in 8-bit counts; the saturation floor rises by
                ``noise_counts / max(R, G, B)`` so that noisy dark skin stays out.

        Raises:
            ContentError: a palette colour is too grey or too dark to track, or two palette
                colours are too close in hue to be told apart.
            ValueError: a numeric argument is out of range.
        """
        pal = np.asarray(palette_rgb)
        if pal.ndim != 2 or pal.shape[1] != 3 or not 1 <= pal.shape[0] <= 254:
            raise ValueError(f"palette_rgb must have shape (K, 3) with 1 <= K <= 254, got {pal.shape}")
        if not np.issubdtype(pal.dtype, np.integer) or pal.min() < 0 or pal.max() > 255:
            raise ValueError("palette_rgb must hold integers 0..255")
        if not 4 <= bits <= 8:
            raise ValueError(f"bits must be 4..8, got {bits}")
        if not 1.0 <= hue_tol_deg <= 60.0:
            raise ValueError(f"hue_tol_deg must be 1..60, got {hue_tol_deg}")
        if not (0.0 <= min_saturation <= 1.0 and 0.0 <= min_value <= 1.0):
            raise ValueError("min_saturation and min_value must be 0..1")
        if not 0.0 <= noise_counts <= 50.0:
            raise ValueError(f"noise_counts must be 0..50, got {noise_counts}")
        pal = pal.astype(np.uint8)
        palette_hsv = hsv_deg(pal)
        for rgb, (_, s, v) in zip(pal.tolist(), palette_hsv):
            if s < MIN_PALETTE_SATURATION or v < MIN_PALETTE_VALUE:
                raise ContentError(
                    f"marker colour {tuple(rgb)} is too grey or dark to track (HSV saturation {s:.2f}, "
                    f"value {v:.2f}): choose a colour with saturation >= {MIN_PALETTE_SATURATION} "
                    f"and value >= {MIN_PALETTE_VALUE}, e.g. 0,200,70"
                )
        for i in range(len(pal)):
            for j in range(i + 1, len(pal)):
                dh = abs((palette_hsv[i, 0] - palette_hsv[j, 0] + 180.0) % 360.0 - 180.0)
                if dh < hue_tol_deg:
                    raise ContentError(
                        f"marker colours {tuple(pal[i].tolist())} and {tuple(pal[j].tolist())} differ "
                        f"by {dh:.0f} deg in hue, less than the tolerance {hue_tol_deg:.0f} deg: "
                        "choose colours further apart in hue"
                    )
        lut = _fill_table(bits, palette_hsv, hue_tol_deg, min_saturation, min_value, noise_counts)
        lut.setflags(write=False)
        pal.setflags(write=False)
        return cls(
            pal, int(bits), float(hue_tol_deg), float(min_saturation), float(min_value), float(noise_counts), lut
        )

    @classmethod
    def from_lut(
        cls,
        palette_rgb: np.ndarray,
        lut: np.ndarray,
        *,
        hue_tol_deg: float = DEFAULT_HUE_TOL_DEG,
        min_saturation: float = DEFAULT_MIN_SATURATION,
        min_value: float = DEFAULT_MIN_VALUE,
        noise_counts: float = DEFAULT_NOISE_COUNTS,
    ) -> "ColourTable":
        """Wrap a full table filled elsewhere (e.g. from learned colours, :mod:`tracking.colour.learn`).

        The array is used as is, not copied: its owner may rewrite it between frames (online
        adaptation); the numeric attributes only describe it.

        Args:
            palette_rgb: (K, 3) uint8 representative sRGB colours of the labels 1..K.
            lut: (2**24,) uint8 labels 0..K in the index order of the full table.
        """
        pal = np.asarray(palette_rgb, dtype=np.uint8).reshape(-1, 3)
        lut = np.asarray(lut)
        if lut.dtype != np.uint8 or lut.shape != (1 << 24,):
            raise ValueError(f"lut must be a (2**24,) uint8 full table, got {lut.dtype} {lut.shape}")
        return cls(pal, 8, float(hue_tol_deg), float(min_saturation), float(min_value), float(noise_counts), lut)

    @property
    def n_colours(self) -> int:
        """Number of palette colours K; labels run 0..K."""
        return int(self.palette_rgb.shape[0])

    def classify(self, image_bgr: np.ndarray) -> np.ndarray:
        """Label every pixel.

        Args:
            image_bgr: (H, W, 3) uint8 OpenCV BGR image.

        Returns:
            (H, W) uint8 labels: 0 background, k + 1 palette colour k.
        """
        _check_image(image_bgr)
        h, w = image_bgr.shape[:2]
        return self.classify_window(image_bgr, 0, 0, w, h)

    def classify_window(self, image_bgr: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """Label the pixels of the window ``image_bgr[y0:y1, x0:x1]`` without copying the image.

        Args:
            image_bgr: (H, W, 3) uint8 OpenCV BGR image (the whole frame).
            x0, y0, x1, y1: window in pixels, 0 <= x0 <= x1 <= W, 0 <= y0 <= y1 <= H; the end is
                exclusive, like a slice.

        Returns:
            (y1 - y0, x1 - x0) uint8 labels; add (x0, y0) to their pixel coordinates to get
            full-image coordinates (``find_blobs(..., offset_px=(x0, y0))`` does).
        """
        _check_image(image_bgr)
        h, w = image_bgr.shape[:2]
        if not (0 <= x0 <= x1 <= w and 0 <= y0 <= y1 <= h):
            raise ValueError(f"window ({x0}, {y0})-({x1}, {y1}) is not inside the {w}x{h} image")
        index = _pixel_words(image_bgr, x0, y0, x1, y1)
        if self.bits < 8:
            index = _quantize_index(index, self.bits)
        labels = np.empty(index.shape, dtype=np.uint8)
        np.take(self.lut, index, out=labels, mode="wrap")  # (in range: wrap is numpy's cheapest check)
        return labels

    def classify_windows(self, images: Sequence[np.ndarray], image_index: np.ndarray, boxes: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Label the pixels of many windows, in several images, with one table look-up.

        The per-frame tracker's search windows are small (a few hundred to a few thousand pixels):
        gathering all of them into one array and reading the table once costs far less than one
        call per window.

        Args:
            images: (H, W, 3) uint8 OpenCV BGR images.
            image_index: (K,) int index into ``images`` of each window.
            boxes: (K, 4) int ``x0, y0, x1, y1`` of each window, inside its image, end exclusive.

        Returns:
            labels: (P,) uint8 labels of all windows' pixels, window after window, each window in
                row order (row-major ``(y1 - y0, x1 - x0)``).
            starts: (K + 1,) int64 offset of each window's first pixel in ``labels``; the last
                entry is P.
        """
        for img in images:
            _check_image(img)
        boxes = np.asarray(boxes, dtype=np.int64).reshape(-1, 4)
        image_index = np.asarray(image_index, dtype=np.int64).reshape(-1)
        # (w, h) of each window's image, then 0 <= x0 <= x1 <= w and 0 <= y0 <= y1 <= h as one test
        size = np.array([img.shape[1::-1] for img in images], dtype=np.int64).reshape(-1, 2)[image_index]
        corners = np.concatenate((np.zeros_like(size), boxes, size), axis=1)  # 0, 0, x0, y0, x1, y1, w, h
        if (corners[:, 2:] < corners[:, :-2]).any():
            raise ValueError("window boxes must satisfy 0 <= x0 <= x1 <= W and 0 <= y0 <= y1 <= H")
        extent = boxes[:, 2:] - boxes[:, :2]
        starts = np.zeros(len(boxes) + 1, dtype=np.int64)
        np.cumsum(extent[:, 0] * extent[:, 1], out=starts[1:])
        words = np.empty(int(starts[-1]), dtype=np.uint32)
        # images whose pixels OpenCV can read in place (any row stride); others go through numpy
        plain = [img.strides[1:] == (3, 1) for img in images]
        as_bytes = words.view(np.uint8)
        bgra = cv2.COLOR_BGR2BGRA
        for img_k, (x0, y0, x1, y1), a, b in zip(image_index.tolist(), boxes.tolist(), starts[:-1].tolist(),
                                                 starts[1:].tolist()):
            if b == a:
                continue
            if plain[img_k]:  # the loop body of _pixel_words, without its checks
                cv2.cvtColor(images[img_k][y0:y1, x0:x1], bgra, as_bytes[4 * a:4 * b].reshape(y1 - y0, x1 - x0, 4))
            else:
                _pixel_words(images[img_k], x0, y0, x1, y1, out=words[a:b].reshape(y1 - y0, x1 - x0))
        np.bitwise_and(words, 0xFFFFFF, out=words)
        if self.bits < 8:
            words = _quantize_index(words, self.bits)
        labels = np.empty(words.shape, dtype=np.uint8)
        np.take(self.lut, words, out=labels, mode="wrap")  # (in range: wrap is numpy's cheapest check)
        return labels, starts


def _check_image(image_bgr: np.ndarray) -> None:
    if image_bgr.dtype != np.uint8 or image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise ValueError(
            f"expected an OpenCV BGR uint8 image of shape (H, W, 3), got {image_bgr.dtype} {image_bgr.shape}"
        )


def _pixel_words(image_bgr: np.ndarray, x0: int, y0: int, x1: int, y1: int,
                 out: np.ndarray | None = None) -> np.ndarray:
    """Full 24-bit table index ``B | G << 8 | R << 16`` of each pixel of a window.

    Args:
        out: (y1 - y0, x1 - x0) C-contiguous uint32 array to write into (default: a new one).
    Returns:
        (y1 - y0, x1 - x0) uint32 (``out`` when given).

    OpenCV widens the window's BGR pixels to BGRA (alpha 255 in the top byte of each
    little-endian word) straight into ``out``, and the top byte is masked off: about 3x faster
    than numpy reading 4-byte words at the unaligned stride of 3 bytes (which it buffers).
    """
    nh, nw = y1 - y0, x1 - x0
    if out is None:
        out = np.empty((nh, nw), dtype=np.uint32)
    if nh == 0 or nw == 0:
        return out
    win = image_bgr[y0:y1, x0:x1]
    if win.strides[1:] == (3, 1) and out.flags.c_contiguous:
        cv2.cvtColor(win, cv2.COLOR_BGR2BGRA, dst=out.view(np.uint8).reshape(nh, nw, 4))
        np.bitwise_and(out, 0xFFFFFF, out=out)
    else:  # an unusual memory layout (e.g. a channel-reversed view)
        np.left_shift(win[..., 2], 16, out=out, dtype=np.uint32)
        out |= np.left_shift(win[..., 1], 8, dtype=np.uint32)
        out |= win[..., 0]
    return out


def _quantize_index(index: np.ndarray, bits: int) -> np.ndarray:
    """24-bit ``B | G << 8 | R << 16`` -> quantized ``B' | G' << bits | R' << 2*bits`` (uint32)."""
    s = 8 - bits
    m = (1 << bits) - 1
    q = np.right_shift(index, s)
    q &= m
    tmp = np.right_shift(index, 8 + s - bits)
    tmp &= m << bits
    q |= tmp
    np.right_shift(index, 16 + s - 2 * bits, out=tmp)
    tmp &= m << (2 * bits)
    q |= tmp
    return q


def benchmark(*, repeats: int = 30, seed: int = 0) -> dict[str, float]:
    """Time the colour extraction stages on a synthetic 640x480 scene.

    Returns:
        seconds per call (median of ``repeats``) for the keys ``build_full_s``,
        ``build_quantized_s``, ``classify_full_640x480_s``, ``classify_quantized_640x480_s``,
        ``classify_window_full_40x40_s``, ``classify_window_quantized_40x40_s``,
        ``classify_windows_4x40x40_s`` (4 windows, full table),
        ``classify_find_blobs_4cams_640x480_s`` (4 cameras, full table + find_blobs with the
        image, i.e. refined centroids) and ``classify_find_blobs_binary_4cams_640x480_s`` (binary
        centroids). The scene has 14 marker discs of radius 7 px per frame.
    """
    # lazy: tracking.blobs (scipy, 0.2 s) only for this benchmark; the game imports this module
    from tracking.blobs import find_blobs

    palette = np.array([(255, 214, 0), (0, 200, 70), (225, 0, 210)], dtype=np.uint8)
    rng = np.random.default_rng(seed)
    frames = [_bench_scene(rng, palette) for _ in range(4)]
    result: dict[str, float] = {}

    t0 = time.perf_counter()
    full = ColourTable.build(palette, bits=8)
    result["build_full_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    quant = ColourTable.build(palette, bits=6)
    result["build_quantized_s"] = time.perf_counter() - t0

    def median_time(fn, n: int = repeats) -> float:
        fn()
        times = []
        for _ in range(n):
            t = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t)
        return statistics.median(times)

    frame = frames[0]
    result["classify_full_640x480_s"] = median_time(lambda: full.classify(frame))
    result["classify_quantized_640x480_s"] = median_time(lambda: quant.classify(frame))
    windows = [(x, y, x + 40, y + 40) for x, y in ((100, 80), (300, 200), (500, 400), (20, 300))]
    result["classify_window_full_40x40_s"] = median_time(
        lambda: full.classify_window(frame, *windows[0]), 10 * repeats
    )
    result["classify_window_quantized_40x40_s"] = median_time(
        lambda: quant.classify_window(frame, *windows[0]), 10 * repeats
    )
    result["classify_windows_4x40x40_s"] = median_time(
        lambda: [full.classify_window(frame, *win) for win in windows], 10 * repeats
    )
    result["classify_find_blobs_4cams_640x480_s"] = median_time(
        lambda: [find_blobs(full.classify(f), full.n_colours, image_bgr=f) for f in frames]
    )
    result["classify_find_blobs_binary_4cams_640x480_s"] = median_time(
        lambda: [find_blobs(full.classify(f), full.n_colours) for f in frames]
    )
    return result


def _bench_scene(rng: np.random.Generator, palette_rgb: np.ndarray) -> np.ndarray:
    """A 640x480 BGR frame: shaded background, a skin-coloured patch, 14 marker discs, noise."""
    h, w = 480, 640
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    base = 70.0 + 40.0 * np.sin(xx / 53.0) + 30.0 * np.cos(yy / 71.0)
    img = base[..., None] * np.array([1.1, 1.0, 0.9], dtype=np.float32)  # BGR, cool grey
    img[120:360, 220:420] = (140, 172, 224)  # skin (BGR)
    for i in range(14):
        centre = (int(rng.integers(20, w - 20)), int(rng.integers(20, h - 20)))
        bgr = tuple(float(c) for c in palette_rgb[i % len(palette_rgb)][::-1])
        cv2.circle(img, centre, 7, bgr, -1, lineType=cv2.LINE_AA)
    img += rng.normal(0.0, 2.5, img.shape).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8)
