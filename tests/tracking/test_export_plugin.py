"""A new export format is one file: registered by name on import, it becomes an option of
``rehab track`` (help, "nothing to write", overwrite checks) and a keyword of ``write_results``,
written whole through a temporary file, and no other file changes."""

import hashlib
import importlib.util
import sys

import numpy as np
import pytest

from game.cli import main
from tests.tracking.test_track_command import write_recording
from tracking import exports
from tracking.drivers.offline import write_results
from tracking.io.trc import read_trc
from tracking.sim.body import reference_pose

#: The whole plug-in, as a developer would add it to tracking/exports/formats/.
MARKER_COUNTS = '''
"""``--marker-counts``: how many frame sets gave each marker a position, as CSV."""

from pathlib import Path

from tracking.exports.registry import ExportFormat, register
from tracking.exports.tracked import TrackedRecording
from tracking.marker_status import MarkerStatus


@register
class MarkerCounts(ExportFormat):
    name = "marker_counts"
    options = ("--marker-counts",)
    help = "frame sets with a position per marker (CSV: marker,frames)"
    suffix = ".csv"
    stem = "counts"

    def write(self, run: TrackedRecording, path: Path, *, asked: Path) -> None:
        found = (run.status != MarkerStatus.LOST).sum(axis=0)
        with open(path, "w", encoding="utf-8", newline="") as fh:
            fh.write("marker,frames\\n")
            fh.writelines(f"{name},{int(n)}\\n" for name, n in zip(run.names, found))
'''


@pytest.fixture(scope="module")
def marker_counts(tmp_path_factory):
    """The plug-in file imported (registered) for this module's tests, forgotten afterwards."""
    path = tmp_path_factory.mktemp("plugin") / "marker_counts.py"
    path.write_text(MARKER_COUNTS, encoding="utf-8")
    spec = importlib.util.spec_from_file_location("marker_counts_plugin", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    yield exports.get("marker_counts")
    exports.unregister("marker_counts")
    del sys.modules[spec.name]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rec") / "rec"
    write_recording(folder, [reference_pose()] * 3)
    return folder


def _digest(folder):
    """Every file under ``folder`` -> its SHA-256."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_one_file_format_is_written_by_its_option_and_nothing_else_changes(marker_counts, recording, tmp_path):
    before = _digest(recording)
    alone = tmp_path / "alone"
    assert main(["track", str(recording), "--out", str(alone / "m.trc")]) == 0
    out = tmp_path / "out"
    assert main(["track", str(recording), "--out", str(out / "m.trc"), "--marker-counts", str(out / "c.csv")]) == 0

    assert sorted(p.name for p in out.iterdir()) == ["c.csv", "m.trc"]   # no temporary file left
    assert _digest(recording) == before
    # the other format's file is byte for byte what it is without the new one (its header names
    # the asked file, not the temporary file it was written to)
    assert (out / "m.trc").read_bytes() == (alone / "m.trc").read_bytes()
    assert (out / "m.trc").read_text(encoding="utf-8").splitlines()[0] == "PathFileType\t4\t(X/Y/Z)\tm.trc"
    trc = read_trc(out / "m.trc")
    lines = (out / "c.csv").read_text(encoding="utf-8").splitlines()
    assert lines[0] == "marker,frames"
    counts = dict(line.split(",") for line in lines[1:])
    assert list(counts) == list(trc.names)
    for k, name in enumerate(trc.names):
        assert int(counts[name]) == int(np.isfinite(trc.positions_mm[:, k, 0]).sum()) == 3


def test_the_new_format_joins_the_help_the_message_and_the_overwrite_checks(marker_counts, recording, tmp_path,
                                                                            capsys):
    with pytest.raises(SystemExit):
        main(["track", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--marker-counts MARKER_COUNTS frame sets with a position per marker (CSV: marker,frames)" in help_text
    assert help_text.index("--detections") < help_text.index("--marker-counts") < help_text.index("--colours")

    assert main(["track", str(recording)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == ("rehab: error: nothing to write: give --out markers.trc (and/or --status, --angles, --c3d, "
                   "--mot, --bvh, --detections, --marker-counts, --points)")

    same = tmp_path / "same.csv"
    assert main(["track", str(recording), "--angles", str(same), "--marker-counts", str(same)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"rehab: error: --marker-counts {same} is also given to --angles: give each output its own file"
    assert not same.exists()


def test_a_failing_writer_leaves_no_file_and_keeps_the_older_one(marker_counts, recording, tmp_path, monkeypatch,
                                                                 capsys):
    def fails_half_way(self, run, path, *, asked):
        path.write_text("half")
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(type(marker_counts), "write", fails_half_way)
    (tmp_path / "c.csv").write_text("an older result\n")
    assert main(["track", str(recording), "--marker-counts", str(tmp_path / "c.csv")]) == 1
    assert "No space left" in capsys.readouterr().err
    assert (tmp_path / "c.csv").read_text() == "an older result\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.csv"]


def test_write_results_refuses_a_format_that_is_not_registered(tmp_path):
    with pytest.raises(TypeError, match="'gltf'"):
        write_results(None, gltf=tmp_path / "a.gltf")
    assert not (tmp_path / "a.gltf").exists()


def test_the_built_in_formats_in_the_order_of_rehab_track_help():
    assert [f.option for f in exports.formats()[:7]] == [
        "--out", "--status", "--angles", "--c3d", "--mot", "--bvh", "--detections"]
    assert exports.names()[:7] == ("trc", "status_csv", "angles_csv", "c3d", "mot", "bvh", "detections")


@pytest.mark.parametrize("attrs, needle", [
    ({"name": "Bad-Name"}, "lower-case"),
    ({"options": ("out",)}, "options"),
    ({"options": ("--out",)}, "already 'trc'"),
    ({"suffix": "csv"}, "suffix"),
])
def test_a_malformed_format_is_refused_at_registration(attrs, needle):
    fields = {"name": "probe", "options": ("--probe",), "help": "a probe", "suffix": ".txt", "stem": "probe", **attrs}
    cls = type("Probe", (exports.ExportFormat,), fields)
    with pytest.raises(ValueError, match=needle):
        exports.register(cls)
    assert "probe" not in exports.names()
