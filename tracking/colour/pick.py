"""Teaching a marker colour by hand: the ball under a click, and the colour table rebuilt from it.

The fallback of colour calibration when the automatic learning cannot start (a cast so strong
that the nominal table finds no marker to learn from): a person clicks a ball of each colour in
a camera image (the camera monitor scene) and says which colour it is.

- :func:`pick_blob`: the ball under the click: the coloured pixels connected to the clicked one
  whose hue is within ``hue_tol_deg`` of its hue, inside a window of ``max_radius_px``; a region
  that reaches the window's edge is no ball (a wall, a shirt) and is refused, as is a click on
  grey. The region's rim (mixed with the background) is eroded away.
- :class:`ManualColours`: per colour the pixels of its picks (a running mean over picks), and
  the rest of each picked image (random pixels outside the ball that the current table does not
  take for a marker) as "not a marker". A colour with a pick gets its model from its pixels
  (:func:`tracking.colour.learn.fit_models`) and its table cells where the background is more
  likely are dropped; a colour without a pick keeps its current model and cells.

Pure arrays: images in, models and tables out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from calibration.errors import RehabError
from tracking.colour.learn import (
    HUE_UNITS_PER_DEG,
    ColourModel,
    ColourStats,
    LutBuilder,
    fit_models,
    hsv_bytes,
    label_hue_saturation,
    outside_discs_sample,
)
from tracking.colour.table import ColourTable

MIN_BLOB_PX = 6


class ColourPickError(RehabError):
    """A click that does not land on a marker ball (the message says what to do)."""


@dataclass(frozen=True, slots=True)
class BlobPick:
    """The ball under a click.

    Attributes:
        pixels_bgr: (N, 3) uint8 BGR pixels of its inside (rim eroded).
        centre_uv: (2,) float64 centroid of the region, pixels.
        radius_px: radius of a disc of the region's area, pixels.
        hue_deg: circular mean hue of the pixels, degrees.
    """

    pixels_bgr: np.ndarray
    centre_uv: np.ndarray
    radius_px: float
    hue_deg: float


def _circular_mean_deg(hue_bytes: np.ndarray) -> float:
    ang = hue_bytes.astype(np.float64) * (2 * np.pi / 256.0)
    return float(np.degrees(np.arctan2(np.sin(ang).mean(), np.cos(ang).mean())) % 360.0)


def pick_blob(image_bgr: np.ndarray, uv_px, *, search_px: int = 4, max_radius_px: int = 40, hue_tol_deg: float = 20.0,
              min_saturation: float = 0.25, min_value: float = 0.12) -> BlobPick:
    """The marker ball at (or within ``search_px`` of) a clicked pixel.

    Args:
        image_bgr: (H, W, 3) uint8 BGR camera image.
        uv_px: (2,) clicked position, image pixels (pixel centres at integers).
    Raises:
        ColourPickError: outside the image, no coloured pixel near the click, a region too small
            or larger than a ball.
    """
    h, w = image_bgr.shape[:2]
    u, v = float(uv_px[0]), float(uv_px[1])
    if not (np.isfinite(u) and np.isfinite(v) and -0.5 <= u < w - 0.5 and -0.5 <= v < h - 0.5):
        raise ColourPickError("the click is outside the camera image: click the middle of a marker ball")
    cu, cv_ = int(round(u)), int(round(v))
    x0, x1 = max(cu - max_radius_px, 0), min(cu + max_radius_px + 1, w)
    y0, y1 = max(cv_ - max_radius_px, 0), min(cv_ + max_radius_px + 1, h)
    window = np.ascontiguousarray(image_bgr[y0:y1, x0:x1])
    hsv = cv2.cvtColor(window, cv2.COLOR_BGR2HSV_FULL)
    coloured = (hsv[..., 1] >= min_saturation * 255) & (hsv[..., 2] >= min_value * 255)
    # The seed: the most saturated coloured pixel near the click.
    sy0, sy1 = max(cv_ - y0 - search_px, 0), min(cv_ - y0 + search_px + 1, y1 - y0)
    sx0, sx1 = max(cu - x0 - search_px, 0), min(cu - x0 + search_px + 1, x1 - x0)
    near = np.where(coloured[sy0:sy1, sx0:sx1], hsv[sy0:sy1, sx0:sx1, 1].astype(int), -1)
    if near.max() < 0:
        raise ColourPickError("no coloured pixel under the click: click the middle of a marker ball")
    ry, rx = np.unravel_index(int(np.argmax(near)), near.shape)
    seed = (sy0 + ry, sx0 + rx)
    patch = hsv[max(seed[0] - 1, 0) : seed[0] + 2, max(seed[1] - 1, 0) : seed[1] + 2]
    patch_ok = coloured[max(seed[0] - 1, 0) : seed[0] + 2, max(seed[1] - 1, 0) : seed[1] + 2]
    seed_hue = _circular_mean_deg(patch[..., 0][patch_ok])
    hue_deg = hsv[..., 0].astype(np.float64) / HUE_UNITS_PER_DEG
    similar = coloured & (np.abs((hue_deg - seed_hue + 180.0) % 360.0 - 180.0) <= hue_tol_deg)
    _, labels = cv2.connectedComponents(similar.astype(np.uint8), connectivity=8)
    region = labels == labels[seed]
    if region.sum() < MIN_BLOB_PX:
        raise ColourPickError(f"only {int(region.sum())} pixels of that colour there: click the middle of a "
                              "marker ball (closer to the camera if it looks tiny)")
    ys, xs = np.nonzero(region)
    at_edge = ((ys == 0) & (y0 > 0)) | ((ys == region.shape[0] - 1) & (y1 < h)) \
        | ((xs == 0) & (x0 > 0)) | ((xs == region.shape[1] - 1) & (x1 < w))
    if at_edge.any():
        raise ColourPickError(f"that coloured region is larger than a marker ball ({2 * max_radius_px} px): "
                              "click a ball, not clothing or the background")
    inner = region
    if region.sum() >= 30:  # the rim mixes the ball with what is behind it
        inner = cv2.erode(region.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    pixels = window[inner]
    centre = np.array([xs.mean() + x0, ys.mean() + y0])
    return BlobPick(pixels, centre, float(np.sqrt(region.sum() / np.pi)), _circular_mean_deg(hsv[..., 0][inner]))


class ManualColours:
    """Marker colours taught by clicks (module docstring).

    Args:
        models: the colour models to start from, one per marker colour (the nominal ones, or
            learnt ones from the calibration).
        background_samples: pixels drawn per picked image for "not a marker".
        seed: random seed of the background sampling.
    """

    def __init__(self, models: Sequence[ColourModel], *, background_samples: int = 3000, seed: int = 0) -> None:
        self.models = list(models)
        self.stats = ColourStats(len(self.models))
        self.picks = np.zeros(len(self.models), int)
        self.background_samples = int(background_samples)
        self.rng = np.random.default_rng(seed)
        self._builder: LutBuilder | None = None

    def teach(self, colour: int, image_bgr: np.ndarray, uv_px, table: ColourTable | None = None) -> BlobPick:
        """Learn colour ``colour`` (0-based palette index) from the ball clicked at ``uv_px``.

        Args:
            table: the table in use: background pixels it takes for a marker are left out of
                "not a marker" (other balls in the picture).
        Returns:
            the ball picked.
        Raises:
            ColourPickError: the click is not on a ball (nothing is learnt).
        """
        if not 0 <= colour < len(self.models):
            raise ColourPickError(f"colour {colour}: choose one of the {len(self.models)} marker colours")
        blob = pick_blob(image_bgr, uv_px)
        n = self.picks[colour]
        self.stats.add(colour + 1, hsv_bytes(blob.pixels_bgr), rate=1.0 / (n + 1))
        bg = outside_discs_sample(image_bgr, blob.centre_uv[None], np.array([2.0 * blob.radius_px + 3.0]),
                                  self.background_samples, self.rng)
        if table is not None and len(bg):
            words = bg[:, 0].astype(np.uint32) | bg[:, 1].astype(np.uint32) << 8 | bg[:, 2].astype(np.uint32) << 16
            bg = bg[table.lut[words] == 0]
        self.stats.add(0, hsv_bytes(bg), rate=1.0 / (int(self.picks.sum()) + 1))
        self.picks[colour] += 1
        one = ColourStats(1, self.stats.min_value)
        one.hist[1] = self.stats.hist[colour + 1]
        self.models[colour] = fit_models(one)[0]
        return blob

    def label_hs(self) -> np.ndarray:
        """(256, 256) uint8 (hue byte, saturation byte) labels of the current models."""
        plain = label_hue_saturation(self.models)
        if not self.picks.any():
            return plain
        checked = label_hue_saturation(self.models, self.stats)
        taught = np.isin(plain, np.flatnonzero(self.picks) + 1)
        # background exclusion only where a taught colour's own pixels are known
        return np.where(taught, checked, plain).astype(np.uint8)

    def table(self) -> ColourTable:
        """The full colour table of the current models (a 2^24 rebuild: ~0.1-1 s)."""
        if self._builder is None:
            self._builder = LutBuilder(len(self.models))
            self._builder.build(self.label_hs())
        else:
            self._builder.update(self.label_hs())
        return self._builder.table(self.models)
