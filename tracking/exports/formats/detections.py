"""``--detections``: the 2D centroids each position was triangulated from, per camera, as CSV
(docs/FILES.md)."""

from __future__ import annotations

from pathlib import Path

from tracking.exports.registry import ExportFormat, register
from tracking.exports.tracked import TrackedRecording


@register
class Detections(ExportFormat):
    name = "detections"
    options = ("--detections",)
    help = "2D marker centroids per camera CSV: frame,time,camera,marker,u_px,v_px"
    suffix = ".csv"
    stem = "detections"
    rank = 70

    def write(self, run: TrackedRecording, path: Path, *, asked: Path) -> None:
        import tracking.io.detections as detections_io  # lazy: loads on write, not at each command's start

        detections_io.write_detections_csv(path, run.frames, run.times_s, [c.name for c in run.cameras], run.names,
                                           run.uv_px)
