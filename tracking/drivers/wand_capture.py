"""Wand ball centroids from a wand recording, for :func:`calibration.wand.calibrate_wand`.

A wand recording is a recording folder (docs/INTERFACES.md: one video or image folder per
camera, meta.yaml with the frame rate) of a wand with two balls of different marker colours.
Each frame of each camera is classified with the colour table of the two colours and the blobs
are found as for tracking; a ball counts in a frame only when exactly one blob of its colour
passes the size and roundness gates (two candidates are ambiguous, so neither is used).

Both balls may have one colour: then a camera's frame counts when exactly two blobs of it pass
the gates, in arbitrary order, and :func:`calibration.wand.match_same_colour_balls` makes the
cameras agree on which is which. Without meta.yaml the frame rate comes from the videos.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Sequence

import numpy as np
from tqdm import tqdm

from calibration.camera import Camera
from calibration.files import load_calibration
from tracking.blobs import find_blobs
from tracking.colour.table import ColourTable
from tracking.full_frame import blob_gates
from tracking.io.recording import Recording

log = logging.getLogger(__name__)

MIN_ROUNDNESS = 0.85


def wand_centroids_in_images(images: Sequence[np.ndarray], cameras: Sequence[Camera], table: ColourTable,
                             ball_radius_m: float, min_roundness: float = MIN_ROUNDNESS) -> np.ndarray:
    """(C, 2, 2) centroids of ball 0 and ball 1 in one frame set, NaN where not seen once exactly.

    A ball partly hidden (by the stick, the other ball or furniture) has its centroid pulled
    off the centre, so blobs less round than ``min_roundness`` are left out.
    """
    out = np.full((len(cameras), 2, 2), np.nan)
    for c, (img, cam) in enumerate(zip(images, cameras)):
        gate = blob_gates(cam, ball_radius_m, near_m=0.5, min_roundness=min_roundness)
        blobs = find_blobs(table.classify(img), table.n_colours, image_bgr=img, min_area_px=gate.min_area_px,
                           max_area_px=gate.max_area_px, min_roundness=gate.min_roundness)
        if table.n_colours == 1:  # one colour for both balls: exactly two blobs, order settled later
            mine = blobs.of_colour(0)
            if len(mine) == 2:
                out[c] = mine.uv_px
            continue
        for k in range(2):
            mine = blobs.of_colour(k)
            if len(mine) == 1:
                out[c, k] = mine.uv_px[0]
    return out


def wand_centroids(folder: str | Path, intrinsics: str | Path, colours_rgb255: Sequence[Sequence[int]],
                   ball_radius_m: float = 0.02, *, progress: bool = False) -> tuple[list[Camera], np.ndarray]:
    """Read a wand recording and return the cameras of ``intrinsics`` and (C, T, 2, 2) centroids.

    Two equal colours mean a wand with balls of one colour: the centroids come back in arbitrary
    order per camera and frame (see :func:`calibration.wand.match_same_colour_balls`).
    """
    cameras = load_calibration(intrinsics)
    rgb = np.asarray(colours_rgb255, dtype=np.uint8).reshape(2, 3)
    table = ColourTable.build(rgb[:1] if np.array_equal(rgb[0], rgb[1]) else rgb)
    rows = []
    with Recording(folder, intrinsics, meta_optional=True) as rec:
        for fs in tqdm(rec, total=rec.n_frames, desc="wand centroids", unit="frame", disable=not progress):
            rows.append(wand_centroids_in_images(fs.images, cameras, table, ball_radius_m))
    if not rows:
        return list(cameras), np.full((len(cameras), 0, 2, 2), np.nan)
    return list(cameras), np.stack(rows, axis=1)
