"""``--angles``: the tracker's joint angles per frame as CSV (docs/JOINT_ANGLES.md).

The tracker's angles are those of its positions (as ``rehab angles`` on the TRC gives), but
without a supination whose elbow axis is a guess.
"""

from __future__ import annotations

from pathlib import Path

from tracking.exports.registry import ExportFormat, register
from tracking.exports.tracked import TrackedRecording


@register
class AnglesCsv(ExportFormat):
    name = "angles_csv"
    options = ("--angles",)
    help = "joint angles CSV (docs/JOINT_ANGLES.md)"
    suffix = ".csv"
    stem = "angles"
    rank = 30

    def write(self, run: TrackedRecording, path: Path, *, asked: Path) -> None:
        import tracking.io.csv_tables as tables_io  # lazy: loads on write, not at each command's start

        tables_io.write_angles_csv(path, run.frames, run.times_s, run.angles_deg)
