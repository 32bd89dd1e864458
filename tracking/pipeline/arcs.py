"""Window regions of partly hidden balls, gathered over a frame set for one arc fit."""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from tracking.blobs import arc_centres


class ArcRegions:
    """Window regions of partly hidden balls gathered for one :func:`~tracking.blobs.arc_centres`
    call (one vectorized fit for all of a frame's), each with its own pixel origin."""

    def __init__(self) -> None:
        self.count = 0
        self._parts: list[tuple[np.ndarray, ...]] = []

    def add_many(self, region: np.ndarray, x: np.ndarray, y: np.ndarray, start_px: np.ndarray, prior_px: np.ndarray,
                 radius_px: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray, origin_px: np.ndarray,
                 marker: np.ndarray, camera: np.ndarray, prior_sigma_px: np.ndarray) -> None:
        """K regions: (P,) region index 0..K-1, pixel x, y relative to each region's (K, 2) origin
        (full-image pixels); (K, 2) centroids and predicted centres, (K,) radii, (K, 2) searched
        boxes (inclusive), all relative to the origin; (K,) marker and camera of each, and the
        prediction's uncertainty (px)."""
        self._parts.append((region + self.count, np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64),
                            start_px, prior_px, radius_px, np.asarray(box_lo, dtype=np.float64),
                            np.asarray(box_hi, dtype=np.float64), np.asarray(origin_px, dtype=np.float64),
                            marker, camera, np.asarray(prior_sigma_px, dtype=np.float64)))
        self.count += len(radius_px)

    def add_region(self, mask: np.ndarray, centroid_px: np.ndarray, prior_px: np.ndarray, origin_px: tuple[int, int],
                   radius_px: float, marker: int, camera: int, prior_sigma_px: float) -> None:
        """The 8-connected region of ``mask`` (a whole searched window at ``origin_px``) nearest
        the (full-image) ``centroid_px``; ``prior_px`` the (full-image) predicted centre, uncertain
        by ``prior_sigma_px``."""
        origin = np.array(origin_px, dtype=np.float64)
        local = centroid_px - origin
        _, regions = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
        ys, xs = np.nonzero(mask)
        nearest = np.argmin((xs - local[0]) ** 2 + (ys - local[1]) ** 2)
        ys, xs = np.nonzero(regions == regions[ys[nearest], xs[nearest]])
        self.add_pixels(xs, ys, centroid_px, prior_px, origin_px, mask.shape[::-1], radius_px, marker, camera,
                        prior_sigma_px)

    def add_pixels(self, xs: np.ndarray, ys: np.ndarray, centroid_px: np.ndarray, prior_px: np.ndarray,
                   origin_px: tuple[int, int], size_px: tuple[int, int], radius_px: float, marker: int, camera: int,
                   prior_sigma_px: float) -> None:
        """One region given by its pixels (window coordinates, raster order) in a searched window
        of ``size_px`` (width, height) at ``origin_px``; the rest as :meth:`add_region`."""
        origin = np.array(origin_px, dtype=np.float64)
        w, h = size_px
        self.add_many(np.zeros(len(xs), dtype=np.int64), xs, ys, (np.asarray(centroid_px) - origin)[None, :],
                      (np.asarray(prior_px) - origin)[None, :], np.array([radius_px]),
                      np.zeros((1, 2)), np.array([[w - 1.0, h - 1.0]]), origin[None, :], np.array([marker]),
                      np.array([camera]), np.array([prior_sigma_px]))

    def fit(self, compiled: bool = False, images: Sequence[np.ndarray] | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(K,) markers, (K,) cameras and (K, 2) fitted centres in full-image pixels (``compiled``:
        see :func:`~tracking.blobs.arc_centres`; ``images``: the frame set's images, for the
        sub-pixel fit on the pixels' coverage, ``colours`` there)."""
        if len(self._parts) == 1:
            cols = self._parts[0]
        else:
            cols = [np.concatenate(parts) for parts in zip(*self._parts)]
        region, x, y, start, prior, radius, lo, hi, origin, marker, camera, prior_sigma = cols
        colours = None if images is None else (images, camera, origin)
        return marker, camera, origin + arc_centres(region, x, y, start, radius, lo, hi, prior_px=prior,
                                                    prior_sigma_px=prior_sigma, compiled=compiled,
                                                    colours=colours)
