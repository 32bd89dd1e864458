"""Learned marker colours: colour models from pixels, and the lookup table built from them.

The nominal table (:mod:`tracking.colour.table`) labels a colour by its distance in hue from the
marker set's nominal sRGB colours. Under clinic lighting the markers' colours in the images are
not the nominal ones: a warm cast moves the magenta's hue by 20-30 deg, past the nominal table's
20 deg tolerance, and a 40 % darker room moves noisy dark-side pixels further. Here each marker
colour is learned from the pixels of the markers themselves, and everything that is not a marker
(skin, clothing, background) is learned from the rest of the image and kept out of the table.

Colour model
------------
A pixel's colour is described by OpenCV's 8-bit full-range HSV bytes (hue 0..255 for 0..360 deg,
saturation, value). :class:`ColourStats` holds, per class (0 = not a marker, ``k + 1`` = marker
colour ``k``), a 2-D histogram of (hue byte, saturation byte / 4) of the pixels whose value is at
least ``min_value``; an update multiplies the old counts by ``1 - rate`` first (exponential
forgetting). :func:`fit_models` reduces each marker class to a :class:`ColourModel`: the circular
mean hue, a hue half-width of ``2.5`` standard deviations plus ``8`` deg (whole degrees, clipped
to 18..25 deg: the band must leave room for the next drift step) and a saturation floor at
``0.75`` of the median saturation (in steps of 0.05, clipped to 0.35..0.8; the steps keep noise
in the statistics from rewriting the table).

Decision rule
-------------
:func:`label_hue_saturation` evaluates, for each (hue byte, saturation byte), the label ``k + 1``
of the nearest model hue whose band holds the hue and whose saturation floor the saturation
passes, then drops to 0 every cell where the background histogram (smoothed over +-2 hue bytes and
+-1 saturation bin) holds at least ``min_background_count`` pixels and a larger share of the
background pixels than of the class's pixels: skin, clothes and walls seen in the images are out,
even where they share a marker's hue. The value floor and the sensor-noise margin on the
saturation floor (``noise_counts / max(R, G, B)``) are the nominal table's gate.

Incremental rebuild
-------------------
The 2**24 RGB table is ``gate[label_hs[H, S], V, S]`` of each colour's HSV bytes. A
:class:`LutBuilder` converts all 2**24 colours to HSV once and sorts them by their ``(H, S)`` key
(cached per process); a new ``label_hs`` then changes only the colours of its changed keys (256
colours per key on average), which :meth:`LutBuilder.update` rewrites in place, or
:meth:`LutBuilder.apply` a budget at a time. A full rebuild (:meth:`LutBuilder.build`) goes
through the same path; the tests check that updates give the same table as a full build.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from tracking.colour.table import (
    DEFAULT_MIN_VALUE,
    DEFAULT_NOISE_COUNTS,
    ColourTable,
    hsv_deg,
    value_saturation_gate,
)
from tracking.errors import ContentError

SAT_BINS = 64
"""Saturation bins of the histograms (saturation byte // 4)."""
HUE_UNITS_PER_DEG = 256.0 / 360.0
MIN_HUE_TOL_DEG = 18.0
MAX_HUE_TOL_DEG = 25.0
MIN_SAT_FLOOR = 0.35
MAX_SAT_FLOOR = 0.8
MIN_BACKGROUND_COUNT = 3.0
"""Smoothed background pixels needed in a (hue, saturation) cell before it can be excluded."""


def hsv_bytes(pixels_bgr: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 BGR pixels -> (N, 3) uint8 OpenCV full-range HSV (hue 0..255 = 0..360 deg)."""
    px = np.ascontiguousarray(pixels_bgr, dtype=np.uint8).reshape(-1, 1, 3)
    if px.shape[0] == 0:
        return np.zeros((0, 3), np.uint8)
    return cv2.cvtColor(px, cv2.COLOR_BGR2HSV_FULL).reshape(-1, 3)


@dataclass(frozen=True, slots=True)
class ColourModel:
    """One marker colour as seen by the cameras.

    Attributes:
        hue_deg: circular mean hue, degrees [0, 360).
        hue_tol_deg: half-width of the accepted hue band, degrees.
        sat_floor: lowest accepted HSV saturation (0..1) before the noise margin.
        rgb: (3,) a representative sRGB colour (the model hue at the median saturation, full value).
    """

    hue_deg: float
    hue_tol_deg: float
    sat_floor: float
    rgb: tuple[int, int, int]


class ColourStats:
    """Per-class (hue, saturation) histograms with exponential forgetting.

    Args:
        n_colours: number of marker colours K (classes 1..K; class 0 is everything else).
        min_value: pixels darker than this HSV value (0..1) are ignored.
    """

    def __init__(self, n_colours: int, min_value: float = DEFAULT_MIN_VALUE):
        self.n_colours = int(n_colours)
        self.min_value = float(min_value)
        self.hist = np.zeros((self.n_colours + 1, 256, SAT_BINS))

    def add(self, label: int, hsv: np.ndarray, rate: float = 1.0) -> int:
        """Forget ``rate`` of class ``label``'s counts and add the pixels (N, 3) HSV bytes.

        Returns:
            the number of pixels added (those at least ``min_value`` bright).
        """
        hsv = np.asarray(hsv).reshape(-1, 3)
        keep = hsv[:, 2] >= self.min_value * 255.0
        h = hsv[keep, 0].astype(np.intp)
        s = (hsv[keep, 1] // (256 // SAT_BINS)).astype(np.intp)
        new = np.bincount(h * SAT_BINS + s, minlength=256 * SAT_BINS).reshape(256, SAT_BINS)
        if new.sum() == 0:
            return 0
        old = self.hist[label]
        if old.sum() > 0:
            scale = old.sum() / new.sum()  # the update replaces ``rate`` of the class's mass
            self.hist[label] = (1.0 - rate) * old + rate * scale * new
        else:
            self.hist[label] = new.astype(np.float64)
        return int(keep.sum())

    def counts(self) -> np.ndarray:
        """(K + 1,) total (forgetting-weighted) pixels per class."""
        return self.hist.sum(axis=(1, 2))


def _circular_hue(weights: np.ndarray) -> tuple[float, float]:
    """Hue histogram (256,) -> (circular mean deg, circular std deg)."""
    ang = np.arange(256) * (2 * np.pi / 256.0)
    c, s = (weights * np.cos(ang)).sum(), (weights * np.sin(ang)).sum()
    total = max(weights.sum(), 1e-12)
    r = min(np.hypot(c, s) / total, 1.0)
    mean = float(np.degrees(np.arctan2(s, c)) % 360.0)
    std = float(np.degrees(np.sqrt(max(-2.0 * np.log(max(r, 1e-12)), 0.0))))
    return mean, std


def _rgb_from_hsv(hue_deg: float, sat: float) -> tuple[int, int, int]:
    px = np.array([[[hue_deg * HUE_UNITS_PER_DEG, sat * 255.0, 255.0]]]).round().clip(0, 255).astype(np.uint8)
    b, g, r = cv2.cvtColor(px, cv2.COLOR_HSV2BGR_FULL)[0, 0]
    return int(r), int(g), int(b)


def fit_models(stats: ColourStats) -> list[ColourModel]:
    """Reduce each marker class's histogram to a :class:`ColourModel`.

    Raises:
        ContentError: a marker colour has no pixels (it was not seen).
    """
    models = []
    sat_centres = (np.arange(SAT_BINS) + 0.5) * (256 // SAT_BINS) / 255.0
    for k in range(1, stats.n_colours + 1):
        hist = stats.hist[k]
        if hist.sum() <= 0:
            raise ContentError(f"marker colour {k - 1} was not seen in any image: show every marker to the cameras")
        mean, std = _circular_hue(hist.sum(axis=1))
        tol = float(np.clip(np.round(2.5 * std + 8.0), MIN_HUE_TOL_DEG, MAX_HUE_TOL_DEG))
        sat_w = hist.sum(axis=0)
        cdf = np.cumsum(sat_w) / sat_w.sum()
        median_sat = float(sat_centres[np.searchsorted(cdf, 0.5)])
        floor = float(np.clip(np.round(0.75 * median_sat / 0.05) * 0.05, MIN_SAT_FLOOR, MAX_SAT_FLOOR))
        models.append(ColourModel(mean, tol, floor, _rgb_from_hsv(mean, median_sat)))
    return models


def _smooth(hist: np.ndarray) -> np.ndarray:
    """(..., 256, SAT_BINS) box-sum over +-2 hue bytes (circular) and +-1 saturation bin."""
    out = hist.copy()
    for dh in (-2, -1, 1, 2):
        out += np.roll(hist, dh, axis=-2)
    res = out.copy()
    res[..., 1:] += out[..., :-1]
    res[..., :-1] += out[..., 1:]
    return res


def label_hue_saturation(models: list[ColourModel], stats: ColourStats | None = None) -> np.ndarray:
    """(256 hue bytes, 256 saturation bytes) uint8 labels: 0 or k + 1 (see the module doc)."""
    hue_deg = np.arange(256) / HUE_UNITS_PER_DEG
    sat = np.arange(256) / 255.0
    centres = np.array([m.hue_deg for m in models])
    tols = np.array([m.hue_tol_deg for m in models])
    floors = np.array([m.sat_floor for m in models])
    dh = np.abs((hue_deg[None, :] - centres[:, None] + 180.0) % 360.0 - 180.0)  # (K, 256)
    dh = np.where(dh <= tols[:, None], dh, np.inf)
    nearest = np.argmin(dh, axis=0)
    in_band = np.isfinite(dh.min(axis=0))
    labels = np.where(in_band[:, None] & (sat[None, :] >= floors[nearest][:, None] - 1e-9),
                      nearest[:, None] + 1, 0).astype(np.uint8)
    if stats is not None and stats.hist[0].sum() > 0:
        smooth = _smooth(stats.hist)  # (K + 1, 256, SAT_BINS)
        share = smooth / np.maximum(stats.counts(), 1e-12)[:, None, None]
        step = 256 // SAT_BINS
        binned = labels[:, step - 1 :: step].astype(np.intp)  # a bin's label at its top byte
        own = np.take_along_axis(share, binned[None], axis=0)[0]
        exclude = (smooth[0] >= MIN_BACKGROUND_COUNT) & (share[0] > own)
        labels[np.repeat(exclude, step, axis=1)] = 0
    return labels


class LutBuilder:
    """Builds and updates a full 2**24 RGB table from a (hue, saturation) label table.

    All colours are sorted once by their (hue byte, saturation byte) key (cached per process:
    64 MiB of indices and 16 MiB of value bytes in that order, ~1-2 s); the colours of one key are
    then a contiguous run whose value bytes are read in order, and only the table writes scatter.
    Changes can be applied at once (:meth:`update`) or staged (:meth:`stage`) and applied a budget
    of colours at a time (:meth:`apply`), spreading a rewrite over several frames; a colour whose
    key is still pending keeps its previous (valid) label meanwhile.

    Args:
        n_colours: number of marker colours K.
        min_value: value floor (0..1) of the gate.
        noise_counts: sensor-noise margin, counts: a colour's saturation must also be at least
            ``noise_counts / max(R, G, B)`` (a floor of its own, not added to the learned one).
    """

    _cache: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def __init__(self, n_colours: int, min_value: float = DEFAULT_MIN_VALUE, noise_counts: float = DEFAULT_NOISE_COUNTS):
        self.n_colours = int(n_colours)
        self.min_value = float(min_value)
        self.noise_counts = float(noise_counts)
        dummy = np.zeros((self.n_colours, 3))
        # min_saturation 0: the learned saturation floor is in label_hs; the gate keeps the value
        # floor and the noise margin
        self.gate = value_saturation_gate(dummy, 0.0, self.min_value, self.noise_counts).reshape(-1)
        self.order, self.value_sorted, self.starts = self._sorted_colours()
        self.label_hs: np.ndarray | None = None  # the target labels (staged or applied)
        self.pending = np.zeros(0, np.int64)  # keys H << 8 | S still to rewrite
        self.lut = np.zeros(1 << 24, dtype=np.uint8)

    @classmethod
    def _sorted_colours(cls) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(order, value bytes in that order, run starts per key) of all 2**24 colours (cached)."""
        if LutBuilder._cache is None:
            plane = np.empty((256, 256, 3), np.uint8)
            plane[..., 0] = np.arange(256)[None, :]
            plane[..., 1] = np.arange(256)[:, None]
            hsv = np.empty((256, 256, 256, 3), np.uint8)
            for r in range(256):
                plane[..., 2] = r
                cv2.cvtColor(plane, cv2.COLOR_BGR2HSV_FULL, dst=hsv[r])
            hsv = hsv.reshape(-1, 3)
            key = hsv[:, 0].astype(np.uint16) << 8 | hsv[:, 1]
            order = np.argsort(key, kind="stable").astype(np.uint32)
            value_sorted = hsv[order, 2]
            starts = np.zeros(65537, np.int64)
            starts[1:] = np.cumsum(np.bincount(key, minlength=65536))
            for arr in (order, value_sorted, starts):
                arr.setflags(write=False)
            LutBuilder._cache = (order, value_sorted, starts)
        return LutBuilder._cache

    def _rewrite(self, keys: np.ndarray) -> int:
        lo, hi = self.starts[keys], self.starts[keys + 1]
        n = hi - lo
        total = int(n.sum())
        if total == 0:
            return 0
        pos = np.arange(total) + np.repeat(lo - (np.cumsum(n) - n), n)  # runs lo..hi-1, concatenated
        lab = np.repeat(self.label_hs.reshape(-1)[keys].astype(np.uint32) << 16 | (keys & 255).astype(np.uint32), n)
        lab |= self.value_sorted[pos].astype(np.uint32) << 8
        self.lut[self.order[pos]] = self.gate[lab]
        return total

    def build(self, label_hs: np.ndarray) -> np.ndarray:
        """Fill the whole table for ``label_hs``; returns the (2**24,) table (owned, updated in place)."""
        self.label_hs = np.asarray(label_hs, dtype=np.uint8).copy()
        self.pending = np.zeros(0, np.int64)
        for k0 in range(0, 65536, 4096):  # chunks keep the temporaries small
            self._rewrite(np.arange(k0, k0 + 4096))
        return self.lut

    def stage(self, label_hs: np.ndarray, priority: np.ndarray | None = None) -> int:
        """Make ``label_hs`` the target; queue its changed keys. Returns the colours queued.

        Args:
            label_hs: (256, 256) uint8 labels by (hue byte, saturation byte).
            priority: (256, 256) weights; pending keys of higher weight are applied first (e.g.
                how often the cameras see that hue and saturation), ties in key order.
        """
        label_hs = np.asarray(label_hs, dtype=np.uint8)
        if self.label_hs is None:
            self.build(label_hs)
            return 0
        changed = np.flatnonzero((label_hs != self.label_hs).reshape(-1))
        self.label_hs = label_hs.copy()
        pending = np.union1d(self.pending, changed)
        if priority is not None and pending.size:
            pending = pending[np.argsort(-np.asarray(priority, float).reshape(-1)[pending], kind="stable")]
        self.pending = pending
        return int((self.starts[changed + 1] - self.starts[changed]).sum())

    def apply(self, max_colours: int | None = None) -> int:
        """Rewrite pending keys, at most ``max_colours`` colours (at least one key). Returns colours rewritten."""
        if self.pending.size == 0:
            return 0
        if max_colours is None:
            take = self.pending.size
        else:
            sizes = self.starts[self.pending + 1] - self.starts[self.pending]
            take = max(int(np.searchsorted(np.cumsum(sizes), max_colours, side="right")), 1)
        keys, self.pending = self.pending[:take], self.pending[take:]
        return self._rewrite(keys)

    def update(self, label_hs: np.ndarray) -> int:
        """Stage ``label_hs`` and rewrite every changed colour now. Returns colours rewritten."""
        self.stage(label_hs)
        return self.apply()

    def table(self, models: list[ColourModel]) -> ColourTable:
        """A :class:`ColourTable` whose ``lut`` IS this builder's table (later updates show in it)."""
        return ColourTable.from_lut(
            np.array([m.rgb for m in models], dtype=np.uint8), self.lut,
            hue_tol_deg=max(m.hue_tol_deg for m in models), min_saturation=min(m.sat_floor for m in models),
            min_value=self.min_value, noise_counts=self.noise_counts,
        )


def disc_pixels(image_bgr: np.ndarray, centre_uv: np.ndarray, radius_px: float) -> np.ndarray:
    """(N, 3) BGR pixels whose centres lie within ``radius_px`` of ``centre_uv`` (inside the image)."""
    h, w = image_bgr.shape[:2]
    u, v = float(centre_uv[0]), float(centre_uv[1])
    r = float(radius_px)
    x0, x1 = max(int(np.floor(u - r)), 0), min(int(np.ceil(u + r)) + 1, w)
    y0, y1 = max(int(np.floor(v - r)), 0), min(int(np.ceil(v + r)) + 1, h)
    if x0 >= x1 or y0 >= y1:
        return np.zeros((0, 3), np.uint8)
    yy, xx = np.ogrid[y0:y1, x0:x1]
    inside = (xx - u) ** 2 + (yy - v) ** 2 <= r * r
    return image_bgr[y0:y1, x0:x1][inside]


def outside_discs_sample(image_bgr: np.ndarray, centres_uv: np.ndarray, radii_px: np.ndarray, n: int,
                         rng: np.random.Generator) -> np.ndarray:
    """(<= n, 3) BGR pixels drawn at random from outside every disc (centre, radius)."""
    h, w = image_bgr.shape[:2]
    xs = rng.integers(0, w, n)
    ys = rng.integers(0, h, n)
    c = np.asarray(centres_uv, float).reshape(-1, 2)
    r = np.asarray(radii_px, float).reshape(-1)
    use = np.isfinite(c).all(axis=1) & np.isfinite(r)
    c, r = c[use], r[use]
    ok = ((xs[:, None] - c[None, :, 0]) ** 2 + (ys[:, None] - c[None, :, 1]) ** 2 > (r * r)[None, :]).all(axis=1)
    return image_bgr[ys[ok], xs[ok]]


def nominal_hue_deg(palette_rgb: np.ndarray) -> np.ndarray:
    """(K,) hue in degrees of each nominal palette colour."""
    return hsv_deg(np.asarray(palette_rgb))[:, 0]
