"""``--c3d``: the labelled markers and joint angles as a C3D file (docs/FILES.md "C3D").

Each point's residual says how it was found (> 0 measured: its reprojection residual in
millimetres, 0 estimated, -1 lost), its camera mask which cameras saw it; an ``Identified``
event marks each instant the tracker identified the markers.
"""

from __future__ import annotations

from pathlib import Path

from tracking.exports.registry import ExportFormat, register
from tracking.exports.tracked import TrackedRecording


@register
class C3d(ExportFormat):
    name = "c3d"
    options = ("--c3d",)
    help = "labelled markers and joint angles as a C3D file (residual > 0 measured, 0 estimated, -1 lost)"
    suffix = ".c3d"
    stem = "markers"
    rank = 40

    def write(self, run: TrackedRecording, path: Path, *, asked: Path) -> None:
        import tracking.io.c3d as c3d_io  # lazy: loads on write, not at each command's start
        import tracking.io.detections as detections_io  # lazy: loads on write, not at each command's start

        residuals = detections_io.reprojection_residuals_mm(run.cameras, run.positions_mm / 1000.0, run.uv_px)
        events = [c3d_io.C3dEvent("Identified", float(t - run.times_s[0]), "General",
                                  "markers identified in the reference pose; tracking starts")
                  for t in run.times_s[run.identified]]
        c3d_io.write_c3d(path, run.names, run.positions_mm, run.rate_hz, residuals=residuals, status=run.status,
                         camera_masks=detections_io.seen_by(run.uv_px), angles_deg=run.angles_deg,
                         subject=run.subject, markerset=run.markerset, events=events)
