"""``--mot``: the joint angles as an OpenSim motion file (docs/FILES.md "OpenSim .mot")."""

from __future__ import annotations

from pathlib import Path

from tracking.exports.registry import ExportFormat, register
from tracking.exports.tracked import TrackedRecording


@register
class Mot(ExportFormat):
    name = "mot"
    options = ("--mot",)
    help = "joint angles as an OpenSim motion file (.mot)"
    suffix = ".mot"
    stem = "angles"
    rank = 50

    def write(self, run: TrackedRecording, path: Path, *, asked: Path) -> None:
        import tracking.io.opensim_mot as mot_io  # lazy: loads on write, not at each command's start

        # the header's name is the asked file's, not the temporary file's
        mot_io.write_mot(path, run.times_s, run.angles_deg, name=Path(asked).stem)
