"""Full-frame measurement: images of all cameras -> unlabelled 3D marker points.

The first half of the seed pipeline (docs/METHOD.md sections 4 and 5.1): the colour lookup table over
each whole image, connected regions to sub-pixel centroids gated by area and roundness, then
cross-camera matching and triangulation. The tracker (search windows) reuses the same pieces;
this module is also the full-frame baseline it is benchmarked against.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from calibration.camera import Camera
from tracking.blobs import DEFAULT_MAX_PER_COLOUR, Blobs, find_blobs
from tracking.colour.table import ColourTable
from tracking.reconstruction import (
    CameraObservations,
    Points3D,
    ReconstructionParams,
    RigGeometry,
    reconstruct,
)


@dataclass(frozen=True, slots=True)
class BlobGates:
    """Plausible blob sizes for one camera, from the marker size and the working distances."""

    min_area_px: float
    max_area_px: float
    min_roundness: float


def blob_gates(camera: Camera, marker_radius_m: float, near_m: float = 0.8, far_m: float = 5.0,
               min_roundness: float = 0.5) -> BlobGates:
    """Area gates for a ball of ``marker_radius_m`` seen between ``near_m`` and ``far_m``.

    The lower gate keeps a ball that is up to ~75 % hidden at the far distance (but at least
    3 pixels, below which a centroid is noise); the upper gate allows 1.5x the nearest full ball.
    """
    f = float(camera.K[0, 0] + camera.K[1, 1]) / 2.0
    r_far = f * marker_radius_m / far_m
    r_near = f * marker_radius_m / near_m
    return BlobGates(
        min_area_px=max(3.0, 0.25 * np.pi * r_far**2),
        max_area_px=1.5 * np.pi * r_near**2,
        min_roundness=min_roundness,
    )


def observations_from_blobs(blobs: Blobs) -> CameraObservations:
    return CameraObservations(blobs.uv_px, blobs.colour, blobs.radius_px, blobs.roundness)


class StageTimes:
    """Accumulated seconds per named pipeline stage, for benchmarks and summaries.

    Args:
        stages: the stage names, in report order.
    """

    def __init__(self, stages: Sequence[str]):
        self.stages = tuple(stages)
        self.reset()

    def reset(self) -> None:
        self.seconds = dict.fromkeys(self.stages, 0.0)
        self.frames = 0

    def add(self, stage: str, seconds: float) -> None:
        self.seconds[stage] += seconds

    def per_frame_ms(self) -> dict[str, float]:
        n = max(self.frames, 1)
        return {k: 1000.0 * v / n for k, v in self.seconds.items()}


def regions_cap(n_markers: int) -> int:
    """Regions of a colour worth measuring in one image when ``n_markers`` wear it: each marker's
    region, as many again (a partly hidden ball split in two, a marker-coloured object) and 4 spare;
    never more than :data:`tracking.blobs.DEFAULT_MAX_PER_COLOUR`."""
    return min(2 * int(n_markers) + 4, DEFAULT_MAX_PER_COLOUR)


@dataclass
class FrameMeasurer:
    """Measures unlabelled marker points from full images of every camera.

    Args:
        cameras: calibrated cameras, in the order of the images.
        table: colour lookup table of the marker palette.
        marker_radius_m: radius of the marker balls.
        params: reconstruction gates.
        markers_per_colour: (K,) how many markers wear each palette colour. Given, each image's
            regions of a colour are capped at :func:`regions_cap` of it (the most marker-like kept)
            instead of :data:`tracking.blobs.DEFAULT_MAX_PER_COLOUR`: sensor noise or MJPEG blocks
            of a marker colour make hundreds of regions, and every one kept costs in the matching
            across cameras.
        luma_centres: check each ball's colour centre against a fit of it in the luma and take the
            fit's where they disagree (``find_blobs(luma=True)``; docs/TRACKING.md, "Marker centres
            from the luma"): webcams send colour at half resolution (MJPEG, YUYV), which moves the
            colour edge by a third to half a pixel; the luma is at full resolution.
    """

    cameras: Sequence[Camera]
    table: ColourTable
    marker_radius_m: float
    params: ReconstructionParams | None = None
    markers_per_colour: Sequence[int] | None = None
    luma_centres: bool = True
    times: StageTimes = field(default_factory=lambda: StageTimes(("colour table", "centroids", "triangulation")))

    def __post_init__(self) -> None:
        self.geometry = RigGeometry.from_cameras(self.cameras)
        self.gates = [blob_gates(c, self.marker_radius_m) for c in self.cameras]
        if self.params is None:
            self.params = ReconstructionParams(marker_radius_m=self.marker_radius_m)
        self._cap = (DEFAULT_MAX_PER_COLOUR if self.markers_per_colour is None
                     else [regions_cap(n) for n in self.markers_per_colour])

    def blobs(self, images: Sequence[np.ndarray]) -> list[Blobs]:
        """Centroids of marker-coloured regions in each whole image."""
        out = []
        for img, gate in zip(images, self.gates):
            t0 = time.perf_counter()
            labels = self.table.classify(img)
            t1 = time.perf_counter()
            out.append(
                find_blobs(
                    labels,
                    self.table.n_colours,
                    min_area_px=gate.min_area_px,
                    max_area_px=gate.max_area_px,
                    min_roundness=gate.min_roundness,
                    image_bgr=img,
                    max_per_colour=self._cap,
                    luma=self.luma_centres,
                )
            )
            t2 = time.perf_counter()
            self.times.add("colour table", t1 - t0)
            self.times.add("centroids", t2 - t1)
        return out

    def measure(self, images: Sequence[np.ndarray]) -> Points3D:
        """(H, W, 3) uint8 BGR images, one per camera -> unlabelled 3D points (world metres)."""
        return self.measure_views(images)[0]

    def measure_views(self, images: Sequence[np.ndarray]) -> tuple[Points3D, list[CameraObservations]]:
        """As :meth:`measure`, with each camera's centroids (``Points3D.obs_index`` indexes them)."""
        if len(images) != len(self.cameras):
            raise ValueError(f"expected {len(self.cameras)} images, got {len(images)}")
        blobs = self.blobs(images)
        t0 = time.perf_counter()
        observations = [observations_from_blobs(b) for b in blobs]
        points = reconstruct(self.geometry, observations, self.params)
        self.times.add("triangulation", time.perf_counter() - t0)
        self.times.frames += 1
        return points, observations
