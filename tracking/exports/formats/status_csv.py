"""``--status``: each marker's position and status (measured, estimated, lost) per frame as CSV
(docs/FILES.md)."""

from __future__ import annotations

from pathlib import Path

from tracking.exports.registry import ExportFormat, register
from tracking.exports.tracked import TrackedRecording


@register
class StatusCsv(ExportFormat):
    name = "status_csv"
    options = ("--status",)
    help = "per-marker status CSV: frame,time,marker,x_mm,y_mm,z_mm,status"
    suffix = ".csv"
    stem = "status"
    rank = 20

    def write(self, run: TrackedRecording, path: Path, *, asked: Path) -> None:
        import tracking.io.csv_tables as tables_io  # lazy: loads on write, not at each command's start

        tables_io.write_status_csv(path, run.frames, run.times_s, run.names, run.positions_mm, run.status)
