"""Fuzz every kind of file rehab reads: success or one line, never a traceback, a hang or garbage.

Valid seed files of each kind (content YAML of every kind, calibration TOML and OpenCV YAML,
meta.yaml, timestamps.csv, TRC, C3D, the CSV folder of an import, the joint-angles CSV, the database file) are
mutated with a fixed seed: truncation, byte flips, a Latin-1 byte, lines deleted, duplicated or
swapped, numbers replaced by nan/inf/huge/negative/fractional/text. Each mutated file is read by
the same function the commands use, with a time bound. The outcome is one of:

- ``accepted``: read, and what was read passes the type's sanity check (finite numbers where
  numbers must be, as many frames as the header says, every colour given...);
- ``refused``: a :class:`RehabError` whose message is one line;
- ``garbage``: read although the sanity check fails; ``traceback``: any other exception;
  ``hang``: over the time bound. These three must never happen.

The cases run in a child process: ezc3d (C++) and OpenCV's parser could crash a process on a
damaged file, and a crash must show as a case (``crash``, never allowed), not as a dead test run.
"""

from __future__ import annotations

import collections
import json
import math
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from calibration.errors import RehabError

ROOT = Path(__file__).resolve().parents[1]
# CI runs seed 24; other seeds and sizes for a longer look: REHAB_FUZZ_SEED=7 REHAB_FUZZ_PER_KIND=100
SEED = int(os.environ.get("REHAB_FUZZ_SEED", "24"))
PER_KIND = int(os.environ.get("REHAB_FUZZ_PER_KIND", "40"))
CASE_LIMIT_S = 5.0
CHILD_LIMIT_S = 180.0

_NUMBER = re.compile(rb"-?\d+(\.\d+)?([eE][-+]?\d+)?")
_WORD = re.compile(rb"[A-Za-z_]{3,}")
_REPLACEMENTS = [b"nan", b"inf", b"-inf", b"1e308", b"-1", b"0", b"999", b"-5", b"2.7", b"abc", b"", b"1e-320",
                 b"99999999999999999999"]


# ------------------------------------------------------------------------------ mutations
def mutate(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """One seeded mutation of ``data``: (its name, the mutated bytes)."""
    lines = data.split(b"\n")
    op = rng.choice(["truncate", "flip", "latin1", "delete_line", "duplicate_line", "swap_lines", "number",
                     "number", "number", "word", "empty", "junk_line"])
    if op == "truncate":
        return op, data[:rng.randrange(max(1, len(data)))]
    if op == "flip":
        b = bytearray(data)
        for _ in range(rng.randint(1, 8)):
            i = rng.randrange(len(b))
            b[i] = rng.randrange(256)
        return op, bytes(b)
    if op == "latin1":
        i = rng.randrange(len(data) + 1)
        return op, data[:i] + b"# caf\xe9\n" + data[i:] if rng.random() < 0.5 else data[:i] + b"\xe9" + data[i:]
    if op in ("delete_line", "duplicate_line", "swap_lines") and len(lines) > 2:
        i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
        if op == "delete_line":
            del lines[i]
        elif op == "duplicate_line":
            lines.insert(i, lines[i])
        else:
            lines[i], lines[j] = lines[j], lines[i]
        return op, b"\n".join(lines)
    if op == "number":
        spans = [m.span() for m in _NUMBER.finditer(data)]
        if spans:
            a, b = rng.choice(spans)
            return op, data[:a] + rng.choice(_REPLACEMENTS) + data[b:]
    if op == "word":
        spans = [m.span() for m in _WORD.finditer(data)]
        if spans:
            a, b = rng.choice(spans)
            return op, data[:a] + rng.choice([b"banana", b"", b"x" * 300, b"\xff\xfe", b"[", b"{"]) + data[b:]
    if op == "empty":
        return op, b""
    i = rng.randrange(len(lines) + 1)
    lines.insert(i, rng.choice([b"garbage line", b"\t\t\t", b"key: [1, 2", b"1,2,3,4,5,6,7,8,9", b"- - -"]))
    return "junk_line", b"\n".join(lines)


# ------------------------------------------------------------------------------ sanity of what was read
def _finite_numbers(obj, where: str = "", depth: int = 0) -> None:
    """Every float inside ``obj`` (dataclasses, pydantic models, dicts, sequences, arrays) is finite."""
    if depth > 12:
        return
    if isinstance(obj, float):
        assert math.isfinite(obj), f"{where} = {obj}"
    elif isinstance(obj, np.ndarray):
        if obj.dtype.kind == "f":
            assert not np.isinf(obj).any(), f"{where}: inf"
    elif hasattr(type(obj), "model_fields"):
        for name in type(obj).model_fields:
            _finite_numbers(getattr(obj, name), f"{where}.{name}", depth + 1)
    elif is_dataclass(obj) and not isinstance(obj, type):
        for f in fields(obj):
            _finite_numbers(getattr(obj, f.name), f"{where}.{f.name}", depth + 1)
    elif isinstance(obj, dict):
        for k, v in obj.items():
            _finite_numbers(v, f"{where}[{k!r}]", depth + 1)
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj[:1000]):
            _finite_numbers(v, f"{where}[{i}]", depth + 1)


# ------------------------------------------------------------------------------ the file kinds
class Kind:
    """A kind of file: its seed files and how to read one (and check what was read).

    ``whole``: the file says how long it is (a TRC's NumFrames, a C3D's header, SQLite's pages),
    so a truncated copy that is read anyway is garbage accepted.
    """

    def __init__(self, name: str, seeds: list[Path], read: Callable[[Path], object], suffix: str,
                 whole: bool = False):
        self.name, self.seeds, self.read, self.suffix, self.whole = name, seeds, read, suffix, whole


def _content_kinds(tmp: Path) -> list[Kind]:
    from game.exergames.spec import load_game
    from game.rom.spec import load_rom_test
    from tracking.markerset import load_markerset
    from tracking.sim.body import BodyDimensions
    from tracking.sim.motions import load_motion
    from tracking.sim.rigs import load_rig

    dims = BodyDimensions.from_percentile(50, "female")
    content = ROOT / "content"

    def motion(p):
        m = load_motion(p, dims)
        _finite_numbers(m, "motion")
        return m

    def checked(load):
        def read(p):
            out = load(p)
            _finite_numbers(out, p.name)
            return out
        return read

    return [
        Kind("markerset YAML", [content / "markersets" / "upper_limb_seated.yaml"], checked(load_markerset), ".yaml"),
        Kind("rom_test YAML", sorted((content / "rom_tests").glob("*.yaml"))[:3], checked(load_rom_test), ".yaml"),
        Kind("game YAML", sorted((content / "games").glob("*.yaml")), checked(load_game), ".yaml"),
        Kind("motion YAML", [content / "motions" / "shoulder_flexion.yaml", content / "motions" / "reach.yaml"],
             motion, ".yaml"),
        Kind("rig YAML", [content / "rigs" / "ring4.yaml"], checked(lambda p: load_rig(p, (320, 240))), ".yaml"),
    ]


def _calibration_kinds(tmp: Path) -> list[Kind]:
    from calibration.files import load_calibration, save_calibration_opencv, save_calibration_toml
    from tracking.sim.rigs import load_rig

    cams = load_rig("ring4", (320, 240))
    save_calibration_toml(tmp / "seed.toml", cams)
    save_calibration_opencv(tmp / "seed_cv.yaml", cams)

    def read(p):
        cameras = load_calibration(p)
        assert cameras, "no cameras"
        for c in cameras:
            assert np.isfinite(c.K).all() and c.K[0, 0] > 0 and c.K[1, 1] > 0, f"{c.name}: K {c.K}"
            assert np.isfinite(c.dist).all() and np.isfinite(c.P).all(), c.name
            assert min(c.size_px) > 0, c.size_px
        return cameras

    return [Kind("calibration TOML", [tmp / "seed.toml"], read, ".toml"),
            Kind("calibration OpenCV YAML", [tmp / "seed_cv.yaml"], read, ".yaml")]


def _recording_kinds(tmp: Path) -> list[Kind]:
    from tracking.markerset import load_markerset
    from tracking.io.recording import read_meta

    ms = load_markerset("upper_limb_seated")
    colours = [[int(v) for v in c] for c in ms.rgb]
    seed = tmp / "meta_seed.yaml"
    meta = {"fps": 30.0, "markerset": "upper_limb_seated", "n_frames": 90, "source": "simulated",
            "marker_colours": colours}
    import yaml

    seed.write_text("# a recording's meta.yaml\n" + yaml.safe_dump(meta, sort_keys=False), encoding="utf-8")

    def read(p):
        folder = p.parent / (p.stem + "_rec")
        folder.mkdir()
        shutil.copy(p, folder / "meta.yaml")
        m = read_meta(folder)
        assert math.isfinite(m.fps) and 0 < m.fps <= 1000, m.fps
        if m.marker_colours is not None:
            assert all(len(c) == 3 and all(0 <= v <= 255 for v in c) for c in m.marker_colours), m.marker_colours
        if m.n_frames is not None:
            assert m.n_frames >= 0
        return m

    stamps_seed = tmp / "timestamps_seed.csv"
    rng = np.random.default_rng(3)
    phase = rng.uniform(-0.4, 0.4, 4) / 30.0
    rows = ["frame,time,cam1,cam2,cam3,cam4"] + [
        f"{k},{k / 30:.6f}," + ",".join(f"{k / 30 + p + rng.normal(0, 2e-4):.6f}" for p in phase) for k in range(30)]
    stamps_seed.write_text("\n".join(rows) + "\n", encoding="utf-8")

    def read_stamps(p):
        from tracking.sources.recording import check_skews
        from tracking.io.recording import read_timestamps

        folder = p.parent / (p.stem + "_rec")
        folder.mkdir()
        shutil.copy(p, folder / "timestamps.csv")
        times, stamps = read_timestamps(folder, ["cam1", "cam2", "cam3", "cam4"])
        skew = stamps - times[:, None]
        check_skews(folder / "timestamps.csv", times, skew, 30.0)
        assert np.isfinite(times).all() and (np.diff(times) > 0).all(), times
        assert stamps.shape == (len(times), 4) and not np.isinf(stamps).any()
        assert (np.abs(np.nan_to_num(skew)) <= 1 / 30).all(), skew
        return times, stamps

    return [Kind("recording meta.yaml", [seed], read, ".yaml"),
            Kind("recording timestamps.csv", [stamps_seed], read_stamps, ".csv")]


def _trc_kinds(tmp: Path) -> list[Kind]:
    from tracking.io.trc import read_trc, write_trc

    rng = np.random.default_rng(0)
    pos = rng.normal(0, 300, (12, 4, 3))
    pos[3, 1] = np.nan
    write_trc(tmp / "seed.trc", ["RSHO", "RELB", "RWRI", "C7"], pos, 30.0)

    def read(p):
        d = read_trc(p)
        assert d.n_frames > 0, "no frames"
        assert np.isfinite(d.times_s).all() and not np.isinf(d.positions_mm).any()
        assert math.isfinite(d.rate_hz) and d.rate_hz > 0
        return d

    return [Kind("TRC", [tmp / "seed.trc"], read, ".trc", whole=True)]


def _table_kinds(tmp: Path) -> list[Kind]:
    from tracking.angles import ANGLE_COLUMNS
    from tracking.io.csv_tables import read_angles_csv, write_angles_csv

    frames = np.arange(6)
    write_angles_csv(tmp / "seed_angles.csv", frames, frames / 30.0,
                     {c: np.linspace(-10, 80, 6) + i for i, c in enumerate(ANGLE_COLUMNS)})

    def read(p):
        t = read_angles_csv(p)
        assert np.isfinite(t.times_s).all()
        for v in t.angles.values():
            assert not np.isinf(v).any()
        return t

    return [Kind("joint-angles CSV", [tmp / "seed_angles.csv"], read, ".csv")]


def _database_kinds(tmp: Path) -> list[Kind]:
    import dataclasses
    from types import SimpleNamespace

    from game.db import Database, exercise_record, rom_record
    from game.db import database as dbmod

    r = SimpleNamespace(test="shoulder_flexion", side="right", angle="right_shoulder_flexion", mode="active",
                        position="seated_arm_at_side", standard="jarm", reference_deg=180.0, max_deg=120.0,
                        start_deg=-10.0, range_deg=130.0, started_s=1.0, ended_s=4.0, compensations=(),
                        estimated_markers=())
    db_path = tmp / "seed.sqlite3"

    def fixed(record, k):   # the same bytes every run: fixed uids and times
        t = f"2026-01-0{k}T10:00:00Z"
        return dataclasses.replace(record, session_uid=f"{k:032x}", session_started_utc=t,
                                   values={**record.values, "uid": f"{k + 10:032x}", "recorded_utc": t})

    real_now = dbmod.utc_now
    dbmod.utc_now = lambda ago_s=0.0: "2026-01-01T09:00:00Z"
    try:
        with Database(db_path) as db:
            db.add_patient("P001", "note")
            db.store_result(fixed(rom_record("P001", r), 1))
            db.store_result(fixed(exercise_record("P001", "reach", 12, 95.0, 0.5, '{"level": 2}'), 2))
            db.set_game_limits("P001", "reach", '{"max_range": 0.9}')
            db.export_csv(tmp / "export")
            db.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    finally:
        dbmod.utc_now = real_now
    seeds = sorted((tmp / "export").glob("*.csv"))

    def import_one(p):
        folder = p.parent / (p.stem + "_import")
        shutil.copytree(tmp / "export", folder)
        target = re.sub(r"_\d+$", "", p.stem.split("__")[-1])
        shutil.copy(p, folder / f"{target}.csv")
        with Database(p.parent / (p.stem + ".sqlite3")) as db:
            db.import_csv(folder)
            for row in db.rom_results():
                assert -360 <= row.value_deg <= 360 and math.isfinite(row.range_deg), row
                assert row.side in ("right", "left"), row.side
            for row in db.exercise_results():
                assert row.repetitions >= 0 and math.isfinite(row.duration_s) and row.duration_s >= 0, row
            for s in db.sessions("P001"):
                assert s.kind in ("rom", "exercise"), s.kind
        return folder

    def open_db(p):
        with Database(p, check_integrity=True) as db:
            for pat in db.patients():
                db.rom_results(pat.id)
                db.exercise_results(pat.id)
                db.sessions(pat.id)
                db.game_limits(pat.id)
        return p

    return [Kind("CSV import", seeds, import_one, ".csv"), Kind("database file", [db_path], open_db, ".sqlite3", whole=True)]


# ------------------------------------------------------------------------------ running the cases
class _Timeout(BaseException):
    pass


def _alarm(signum, frame):
    raise _Timeout()


def run_case(kind: Kind, path: Path) -> tuple[str, str]:
    """(outcome, detail) of reading one file."""
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, CASE_LIMIT_S)
    try:
        kind.read(path)
        return "accepted", ""
    except RehabError as exc:
        text = str(exc)
        return ("refused", text) if "\n" not in text and text.strip() else ("traceback", f"multi-line: {text!r}")
    except AssertionError as exc:
        return "garbage", (str(exc).splitlines() or [""])[0][:200]
    except _Timeout:
        return "hang", f"over {CASE_LIMIT_S} s"
    except Exception as exc:   # noqa: BLE001 - the point is to catch what escapes
        return "traceback", f"{type(exc).__name__}: {str(exc)[:200]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def fuzz_kinds(kinds: list[Kind], tmp: Path, n_per_kind: int, rng: random.Random, start: int = 0,
               begin: Callable[[int, str, str], None] | None = None):
    """Mutate each kind's seeds ``n_per_kind`` times and read each: yields (kind, mutation, outcome, detail).

    Every mutation is drawn (so the sequence is the same), but cases before ``start`` are not run
    (a child process that crashed is restarted after the case that crashed it); ``begin`` is told
    of each case before it runs.
    """
    index = -1
    for kind in kinds:
        for k in range(n_per_kind):
            index += 1
            seed = kind.seeds[k % len(kind.seeds)]
            op, data = mutate(seed.read_bytes(), rng)
            if index < start:
                continue
            if begin is not None:
                begin(index, kind.name, op)
            folder = tmp / f"case{index:04d}"
            folder.mkdir()
            path = folder / f"{seed.stem}{kind.suffix}"
            path.write_bytes(data)
            outcome, detail = run_case(kind, path)
            cut = seed.read_bytes()[len(data):].strip(b"\0 \t\r\n")   # padding and line ends may go
            if outcome == "accepted" and kind.whole and op == "truncate" and cut:
                outcome, detail = "garbage", f"truncated to {len(data)} of {seed.stat().st_size} bytes and read"
            yield kind.name, op, outcome, detail


def _c3d_kinds(tmp: Path) -> list[Kind]:
    from tracking.io.c3d import read_c3d_points, write_c3d

    rng = np.random.default_rng(1)
    write_c3d(tmp / "seed.c3d", ["RSHO", "RELB", "RWRI"], rng.normal(0, 300, (20, 3, 3)), 30.0)
    shutil.copy(ROOT / "content" / "captures" / "ezc3d_vicon_upper_limb.c3d", tmp / "sample.c3d")

    def read(p):
        names, pos, rate = read_c3d_points(p)
        assert pos.shape[0] > 0 and not np.isinf(pos).any() and rate > 0
        assert pos.shape[0] in (20, 580), f"{pos.shape[0]} frames: the seeds have 20 and 580"
        return names

    return [Kind("C3D", [tmp / "seed.c3d", tmp / "sample.c3d"], read, ".c3d", whole=True)]


def all_kinds(tmp: Path) -> list[Kind]:
    """Every kind of file, with its seeds written into ``tmp`` (the same bytes every time)."""
    return (_content_kinds(tmp) + _calibration_kinds(tmp) + _recording_kinds(tmp) + _trc_kinds(tmp)
            + _table_kinds(tmp) + _database_kinds(tmp) + _c3d_kinds(tmp))


# ezc3d (C++) and OpenCV's FileStorage parser can crash a process on a damaged file: the cases run
# in a child process; a crash is a case of its own, and the child starts again after it.
CHILD = r"""
import json, random, sys
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from tests import test_fuzz_inputs as F

tmp, start = Path(sys.argv[2]), int(sys.argv[3])
tmp.mkdir()
kinds = F.all_kinds(tmp)
begin = lambda i, kind, op: print(json.dumps(["begin", i, kind, op]), flush=True)
for case in F.fuzz_kinds(kinds, tmp, F.PER_KIND, random.Random(F.SEED), start, begin):
    print(json.dumps(["case", *case]), flush=True)
"""


def run_all(tmp: Path) -> list[tuple[str, str, str, str]]:
    """Every case, in child processes (restarted after a crash): (kind, mutation, outcome, detail)."""
    cases: list[tuple[str, str, str, str]] = []
    start, run = 0, 0
    while True:
        try:
            proc = subprocess.run([sys.executable, "-c", CHILD, str(ROOT), str(tmp / f"run{run}"), str(start)],
                                  capture_output=True, text=True, timeout=CHILD_LIMIT_S, cwd=ROOT)
            stdout, code = proc.stdout, proc.returncode
        except subprocess.TimeoutExpired as exc:   # stuck in C code, where the case's alarm cannot reach
            out = exc.stdout or b""
            stdout, code = out.decode() if isinstance(out, bytes) else out, "timeout"
        begun = None
        for line in stdout.splitlines():
            if not line.startswith("["):
                continue
            item = json.loads(line)
            if item[0] == "begin":
                begun = item[1:]
            else:
                cases.append(tuple(item[1:]))
                begun = None
        if code == 0:
            return cases
        if begun is None or run >= 20:
            raise AssertionError(f"the fuzz process ended with {code} outside a case")
        index, kind, op = begun
        cases.append((kind, op, "hang" if code == "timeout" else "crash",
                      f"case {index}: the process ended with {code}"))
        start, run = index + 1, run + 1


def summary(cases) -> str:
    by_kind = collections.defaultdict(collections.Counter)
    for kind, _, outcome, _ in cases:
        by_kind[kind][outcome] += 1
    lines = [f"{kind:24s} " + ", ".join(f"{k} {v}" for k, v in sorted(c.items())) for kind, c in by_kind.items()]
    total = collections.Counter(outcome for _, _, outcome, _ in cases)
    lines.append(f"{'all':24s} {len(cases)} inputs: " + ", ".join(f"{k} {v}" for k, v in sorted(total.items())))
    return "\n".join(lines)


@pytest.mark.skipif(not hasattr(signal, "setitimer"), reason="needs SIGALRM for the time bound")
def test_every_mutated_input_is_read_or_refused_in_one_line(tmp_path):
    t0 = time.monotonic()
    cases = run_all(tmp_path)
    wall = time.monotonic() - t0
    print(f"\n{summary(cases)}\nwall {wall:.1f} s")
    bad = [c for c in cases if c[2] not in ("accepted", "refused")]
    assert not bad, "\n".join(f"{k} / {op}: {outcome}: {detail}" for k, op, outcome, detail in bad[:30])
    assert len(cases) == 14 * PER_KIND and len(cases) >= 200 and {c[0] for c in cases} >= {"TRC", "C3D", "CSV import", "calibration TOML"}
    assert sum(c[2] == "refused" for c in cases) >= 50   # the mutations do reach the checks
