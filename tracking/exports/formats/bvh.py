"""``--bvh``: the avatar's skeleton driven by the joint angles (docs/FILES.md "BVH").

Segment lengths come from the measured positions only: an estimate must not teach them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tracking.exports.registry import ExportFormat, register
from tracking.exports.tracked import TrackedRecording
from tracking.marker_status import MarkerStatus


@register
class Bvh(ExportFormat):
    name = "bvh"
    options = ("--bvh",)
    help = "the avatar's skeleton driven by the joint angles (.bvh)"
    suffix = ".bvh"
    stem = "skeleton"
    rank = 60

    def write(self, run: TrackedRecording, path: Path, *, asked: Path) -> None:
        # the writer's scipy (0.2-0.4 s) loads when a BVH is written, not at every command's
        # start (`rehab --help` reads this registry)
        import tracking.io.bvh as bvh_io  # lazy: loads on write, not at each command's start

        measured_mm = np.where((run.status == MarkerStatus.MEASURED)[..., None], run.positions_mm, np.nan)
        skeleton = bvh_io.BvhSkeleton.from_markers(run.names, measured_mm)
        bvh_io.write_bvh(path, run.times_s, run.angles_deg, run.rate_hz, skeleton)
