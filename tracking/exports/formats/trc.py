"""``--out``: the labelled markers as an OpenSim TRC file in millimetres (docs/FILES.md "TRC")."""

from __future__ import annotations

from pathlib import Path

from tracking.exports.registry import ExportFormat, register
from tracking.exports.tracked import TrackedRecording


@register
class Trc(ExportFormat):
    name = "trc"
    options = ("--out",)
    help = "labelled markers as an OpenSim TRC file (mm)"
    suffix = ".trc"
    stem = "markers"
    rank = 10

    def write(self, run: TrackedRecording, path: Path, *, asked: Path) -> None:
        import tracking.io.trc as trc_io  # lazy: loads on write, not at each command's start

        # Frame# from 1 as OpenSim numbers frames: the first image (index 0) is frame 1
        trc_io.write_trc(path, run.names, run.positions_mm, run.rate_hz, frame_numbers=run.frames + 1,
                         times_s=run.times_s, file_name=Path(asked).name)
