"""Faults of the database: another program holding a lock, killed backups, permissions, damaged schemas.

A second connection (as a database browser would) holds a write transaction; results accepted
meanwhile must never be lost or reported stored before they are on disk.
"""

from __future__ import annotations

import json
import os
import sqlite3
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from game.db import Database, DatabaseError, DatabaseLocked, exercise_record, rom_record
from game.db.pending import pending_dir, store_durably

ROOT = Path(__file__).resolve().parents[1]


def rom(value=120.0, test="shoulder_flexion"):
    return SimpleNamespace(test=test, side="right", angle="right_shoulder_flexion", mode="active",
                           position="seated_arm_at_side", standard="jarm", reference_deg=180.0, max_deg=value,
                           start_deg=-10.0, range_deg=value + 10.0, started_s=1.0, ended_s=4.0, compensations=(),
                           estimated_markers=())


def new_db(path: Path) -> Path:
    with Database(path) as db:
        db.add_patient("P001")
    return path


class Locker:
    """Another program: holds a write transaction (``BEGIN IMMEDIATE``) until released."""

    def __init__(self, path: Path, exclusive: bool = False):
        self.conn = sqlite3.connect(path, isolation_level=None, timeout=0.1, check_same_thread=False)
        if exclusive:
            self.conn.execute("PRAGMA locking_mode = EXCLUSIVE")
            self.conn.execute("BEGIN EXCLUSIVE")
            self.conn.execute("INSERT INTO patients (id, created_utc) VALUES ('LOCK', '2026-01-01T00:00:00Z')")
        else:
            self.conn.execute("BEGIN IMMEDIATE")

    def release(self):
        self.conn.execute("ROLLBACK")
        self.conn.close()


# ------------------------------------------------------------------------------ item 1: a locked database
def test_a_locked_database_says_locked_not_damaged(tmp_path):
    path = new_db(tmp_path / "r.sqlite3")
    lock = Locker(path)
    try:
        with Database(path, busy_timeout_s=0.2) as db:
            assert [p.id for p in db.patients()] == ["P001"]   # WAL: reading goes on
            with pytest.raises(DatabaseLocked, match="in use by another program"):
                db.add_patient("P002")
    finally:
        lock.release()


def test_an_exclusively_locked_database_is_reported_locked_on_open(tmp_path):
    path = new_db(tmp_path / "r.sqlite3")
    with sqlite3.connect(path) as c:   # an older tool switched the file back to a rollback journal
        c.execute("PRAGMA journal_mode = DELETE")
    lock = Locker(path, exclusive=True)
    try:
        with pytest.raises(DatabaseLocked) as err:
            Database(path, busy_timeout_s=0.2)
        assert "damaged" not in str(err.value) and "\n" not in str(err.value)
    finally:
        lock.release()


def test_a_result_accepted_while_locked_is_kept_then_stored_once_the_lock_goes(tmp_path):
    path = new_db(tmp_path / "r.sqlite3")
    lock = Locker(path)
    told = []
    try:
        t0 = time.monotonic()
        outcome = store_durably(path, rom_record("P001", rom(131.0)), wait_s=0.6, notify=told.append)
        waited = time.monotonic() - t0
    finally:
        lock.release()
    assert not outcome.stored and outcome.pending_file.is_file() and waited >= 0.6
    assert told[0].startswith(f"{path} is in use by another program: waiting")   # the visible message
    assert "is stored in" in told[-1] and "next time" in told[-1]
    assert stat.S_IMODE(outcome.pending_file.stat().st_mode) == 0o600
    assert stat.S_IMODE(pending_dir(path).stat().st_mode) == 0o700
    assert json.loads(outcome.pending_file.read_text())["values"]["value_deg"] == 131.0
    with Database(path) as db:   # the next start stores it
        (row,) = db.rom_results("P001")
        (session,) = db.sessions("P001")
    assert row.uid == outcome.uid and row.value_deg == 131.0 and session.ended_utc   # session, result, end: one go
    assert not outcome.pending_file.exists()
    with Database(path) as db:   # and only once
        assert len(db.rom_results("P001")) == 1


def test_a_lock_released_during_the_wait_stores_the_result_directly(tmp_path):
    path = new_db(tmp_path / "r.sqlite3")
    lock = Locker(path)
    timer = threading.Timer(0.5, lock.release)
    timer.start()
    outcome = store_durably(path, exercise_record("P001", "reach", 12, 95.0, 0.5), wait_s=20.0)
    timer.join()
    assert outcome.stored and not pending_dir(path).exists()
    with Database(path) as db:
        assert [e.uid for e in db.exercise_results("P001")] == [outcome.uid]


def test_a_pending_result_stored_twice_after_a_kill_is_stored_once(tmp_path):
    path = new_db(tmp_path / "r.sqlite3")
    record = rom_record("P001", rom())
    with Database(path) as db:
        db.store_result(record)
    folder = pending_dir(path)   # killed after the commit, before the file was removed
    folder.mkdir()
    (folder / f"{record.uid}.json").write_text(record.to_json())
    (folder / "junk.json").write_text("{not json")
    with Database(path) as db:
        assert len(db.rom_results("P001")) == 1 and len(db.sessions("P001")) == 1
    assert not (folder / f"{record.uid}.json").exists() and (folder / "junk.json.bad").exists()


def test_rom_test_cli_waits_keeps_and_never_says_accepted_before_stored(tmp_path, capsys, monkeypatch):
    from game import cli_clinic
    from game.cli import main
    from game.db import pending

    path = new_db(tmp_path / "r.sqlite3")
    monkeypatch.setattr(pending, "WAIT_S", 0.5)
    lock = Locker(path)
    try:
        code = main(["rom-test", "--patient", "P001", "--test", "elbow_flexion", "--db", str(path)])
    finally:
        lock.release()
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "waiting up to" in err and "kept result" in out and "-> accepted" in out
    lines = out.splitlines()   # both printed together, after storing (the result line's length varies)
    kept = next(i for i, line in enumerate(lines) if "kept result" in line)
    accepted = next(i for i, line in enumerate(lines) if "-> accepted" in line)
    assert abs(kept - accepted) == 1
    with Database(path) as db:
        assert len(db.rom_results("P001")) == 1
    assert cli_clinic is not None


def test_the_game_scene_store_keeps_a_result_while_locked(tmp_path):
    from game.exergames.session import GameLog
    from game.exergames.visit import store_log

    path = new_db(tmp_path / "r.sqlite3")
    log = GameLog("reach", "right", level_start=1.0, level_end=1.5)
    log.started_s, log.ended_s, log.reached, log.active_s = 0.0, 60.0, 7, 55.0
    lock = Locker(path)
    try:
        uid = store_log(path, "P001", log, wait_s=0.3)
    finally:
        lock.release()
    assert (pending_dir(path) / f"{uid}.json").is_file()
    with Database(path) as db:
        (row,) = db.exercise_results("P001")
    assert row.uid == uid and row.repetitions == 7


# ------------------------------------------------------------------------------ item 2: a killed backup
BACKUP_CHILD = """
import sys
from game.db import Database
with Database(sys.argv[1]) as db:
    print("ready", flush=True)
    db.backup(sys.argv[2])
    print("done", flush=True)
"""


@pytest.mark.skipif(not hasattr(os, "kill") or sys.platform.startswith("win"), reason="needs SIGKILL")
def test_a_killed_backup_leaves_no_file_under_the_chosen_name(tmp_path):
    import random
    import signal

    path = new_db(tmp_path / "big.sqlite3")
    with Database(path) as db:   # ~4 MB, so that the copy takes a while
        big = "x" * 4000
        db.conn.execute("BEGIN")
        for i in range(1000):
            db.conn.execute("INSERT INTO patients (id, created_utc, note) VALUES (?, ?, ?)",
                            (f"Q{i:04d}", "2026-01-01T00:00:00Z", big))
        db.conn.execute("COMMIT")
    rng = random.Random(3)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    outcomes = {"killed before done": 0, "complete": 0}
    for k in range(8):
        dest = tmp_path / f"backup{k}.sqlite3"
        child = subprocess.Popen([sys.executable, "-c", BACKUP_CHILD, str(path), str(dest)], stdout=subprocess.PIPE,
                                 cwd=ROOT, env=env, text=True)
        assert child.stdout.readline().strip() == "ready"
        time.sleep(rng.uniform(0.0, 0.08))
        child.send_signal(signal.SIGKILL)
        out, _ = child.communicate(timeout=30)
        if dest.exists():   # then it is whole: every patient there, and a later open is no "new database"
            with Database(dest, check_integrity=True) as db:
                assert len(db.patients()) == 1001
            assert stat.S_IMODE(dest.stat().st_mode) == 0o600
            outcomes["complete"] += 1
        else:
            assert "done" not in out
            outcomes["killed before done"] += 1
            with Database(path) as db:   # the same name is free for the next try
                db.backup(dest)
            with Database(dest) as db:
                assert len(db.patients()) == 1001
    assert outcomes["killed before done"] >= 1, outcomes


def test_a_backup_refuses_an_existing_file_and_checks_the_copy(tmp_path):
    path = new_db(tmp_path / "r.sqlite3")
    with Database(path) as db:
        out = db.backup(tmp_path / "b" / "copy.sqlite3")
        with pytest.raises(DatabaseError, match="exists: give a new file name"):
            db.backup(out)
    assert sorted(p.name for p in out.parent.iterdir()) == ["copy.sqlite3"]   # no temporary file left
    with sqlite3.connect(out) as c:
        assert c.execute("PRAGMA journal_mode").fetchone()[0] == "delete"   # one self-contained file


# ------------------------------------------------------------------------------ item 9: the user's only
@pytest.mark.skipif(sys.platform.startswith("win"), reason="POSIX permissions")
@pytest.mark.parametrize("umask", [0o022, 0o000])
def test_patient_files_are_0600_in_a_0700_folder_whatever_the_umask(tmp_path, umask, capsys):
    from game.cli import main

    old = os.umask(umask)
    try:
        folder = tmp_path / "data" / "rehab"
        db_path = folder / "rehab.sqlite3"
        with Database(db_path) as db:
            db.add_patient("P001")
            db.store_result(rom_record("P001", rom()))
            db.backup(tmp_path / "backups" / "b.sqlite3")
            db.export_csv(tmp_path / "export")
        assert main(["report", "P001", "--out", str(tmp_path / "reports" / "p.html"), "--db", str(db_path)]) == 0
        keep = folder / "rehab.sqlite3.pending"
        from game.db.pending import keep_pending

        keep_pending(db_path, rom_record("P001", rom()))
    finally:
        os.umask(old)
    for d in (tmp_path / "data", folder, keep, tmp_path / "backups", tmp_path / "export", tmp_path / "reports"):
        assert stat.S_IMODE(d.stat().st_mode) == 0o700, d
    files = [p for d in (folder, keep, tmp_path / "backups", tmp_path / "export", tmp_path / "reports")
             for p in d.iterdir() if p.is_file()]
    assert len(files) >= 10
    for f in files:
        assert stat.S_IMODE(f.stat().st_mode) == 0o600, f


def test_an_existing_world_readable_database_is_made_private(tmp_path):
    path = new_db(tmp_path / "r.sqlite3")
    os.chmod(path, 0o644)
    with Database(path):
        pass
    assert stat.S_IMODE(path.stat().st_mode) == 0o600


# ------------------------------------------------------------------------------ item 14: integrity where it matters
def test_integrity_check_runs_at_start_up_backup_and_import_not_on_every_open(tmp_path, monkeypatch, capsys):
    import game.db.database as dbmod
    from game.cli import main

    path = new_db(tmp_path / "r.sqlite3")
    seen: list[str] = []
    real_connect = sqlite3.connect

    def traced(*args, **kwargs):
        conn = real_connect(*args, **kwargs)
        conn.set_trace_callback(seen.append)
        return conn

    monkeypatch.setattr(dbmod.sqlite3, "connect", traced)

    def checks() -> int:
        n = sum(s.lstrip().startswith("PRAGMA integrity_check") for s in seen)   # not the audit row naming tmp_path
        seen.clear()
        return n

    for _ in range(5):   # a game session opens the database several times
        with Database(path) as db:
            db.patients()
    assert checks() == 0
    with Database(path, check_integrity=True):
        pass
    assert checks() == 1
    assert main(["patients", "--db", str(path)]) == 0 and checks() == 1   # a command's start
    assert main(["backup", "--out", str(tmp_path / "b.sqlite3"), "--db", str(path)]) == 0
    assert checks() == 2   # at the start and of the copy
    assert main(["export", "--out", str(tmp_path / "csv"), "--db", str(path)]) == 0 and checks() == 1
    assert main(["import", str(tmp_path / "csv"), "--db", str(path)]) == 0 and checks() == 1


# ------------------------------------------------------------------------------ item 12: damaged schemas
@pytest.mark.parametrize("damage, words", [
    ("UPDATE schema_version SET version = 'abc'", "schema_version 'abc' is not a whole number"),
    ("DROP TABLE rom_results", "missing table rom_results"),
    ("DROP TABLE game_limits", "missing table game_limits"),
    ("UPDATE schema_version SET version = 2.5", "is not a whole number"),
])
def test_a_damaged_schema_is_one_line(tmp_path, damage, words, capsys):
    from game.cli import main

    path = new_db(tmp_path / "r.sqlite3")
    with sqlite3.connect(path) as c:
        c.execute(damage)
    before = path.read_bytes()
    code = main(["patients", "--db", str(path)])
    err = capsys.readouterr().err
    assert code == 1 and words in err and "restore a backup" in err and err.count("\n") == 1, err
    assert path.read_bytes() == before


def test_a_read_only_database_is_one_line(tmp_path, capsys):
    from game.db.database import sqlite_error

    path = new_db(tmp_path / "r.sqlite3")
    ro = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        with pytest.raises(sqlite3.OperationalError) as raw:
            ro.execute("INSERT INTO patients (id, created_utc) VALUES ('X', 'y')")
    finally:
        ro.close()
    err = sqlite_error(path, raw.value)
    assert "read-only" in str(err) and "writable" in str(err) and "damaged" not in str(err)


# ------------------------------------------------------------------------------ items 3, 11: imports' values
def _export(tmp_path) -> Path:
    path = new_db(tmp_path / "a.sqlite3")
    with Database(path) as db:
        db.store_result(rom_record("P001", rom(120.0)))
        db.store_result(exercise_record("P001", "reach", 12, 95.0, 0.5))
        db.export_csv(tmp_path / "csv")
    return tmp_path / "csv"


def _set(folder: Path, table: str, column: str, value: str) -> None:
    import csv

    with open(folder / f"{table}.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    rows[-1][column] = value
    with open(folder / f"{table}.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


@pytest.mark.parametrize("table, column, value, words", [
    ("rom_results", "value_deg", "inf", "value_deg 'inf' is out of range"),
    ("rom_results", "value_deg", "nan", "value_deg 'nan' is out of range"),
    ("rom_results", "value_deg", "1e300", "out of range"),
    ("rom_results", "start_deg", "-1e9", "out of range"),
    ("rom_results", "range_deg", "lots", "range_deg 'lots' is not a number"),
    ("rom_results", "side", "up", "side 'up': use right or left"),
    ("rom_results", "test", "knee_bend", "unknown ROM test 'knee_bend'"),
    ("rom_results", "standard", "who", "standard 'who'"),
    ("rom_results", "recorded_utc", "yesterday", "recorded_utc 'yesterday' is not a UTC time"),
    ("rom_results", "duration_s", "-10", "duration_s '-10' is out of range"),
    ("exercise_results", "repetitions", "-5", "repetitions '-5' is out of range"),
    ("exercise_results", "repetitions", "2.7", "repetitions '2.7' is not a whole number"),
    ("exercise_results", "duration_s", "-10", "duration_s '-10' is out of range"),
    ("exercise_results", "score", "nan", "score 'nan' is out of range"),
    ("sessions", "kind", "banana", "session kind 'banana'"),
    ("sessions", "started_utc", "yesterday", "started_utc 'yesterday'"),
    ("sessions", "ended_utc", "2026-13-45T99:00:00Z", "not a valid date"),
    ("patients", "created_utc", "", "created_utc ''"),
    ("game_limits", "limits", "{\"max\": NaN}", "limits are not valid JSON"),
])
def test_an_import_refuses_values_the_rest_cannot_handle(tmp_path, table, column, value, words, capsys):
    from game.cli import main

    folder = _export(tmp_path)
    if table == "game_limits":
        (folder / "game_limits.csv").write_text("patient_id,game,limits,updated_utc\n"
                                                "P001,reach,\"{\"\"max\"\": NaN}\",2026-01-01T00:00:00Z\n")
    else:
        _set(folder, table, column, value)
    target = tmp_path / "b.sqlite3"
    code = main(["import", str(folder), "--db", str(target)])
    err = capsys.readouterr().err
    assert code == 1 and words in err and f"{table}.csv line" in err and err.count("\n") == 1, err
    with Database(target) as db:   # one transaction: nothing imported
        assert db.patients() == []


def test_an_import_of_the_export_round_trips(tmp_path):
    folder = _export(tmp_path)
    with Database(tmp_path / "b.sqlite3") as db:
        assert db.import_csv(folder) == {"patients": 1, "sessions": 2, "rom_results": 1, "exercise_results": 1,
                                         "game_limits": 0}


def test_export_of_an_empty_patient_id_is_refused_not_everyone(tmp_path, capsys):
    from game.cli import main

    path = new_db(tmp_path / "r.sqlite3")
    code = main(["export", "--out", str(tmp_path / "x"), "--patient", "", "--db", str(path)])
    err = capsys.readouterr().err
    assert code == 1 and "give a patient ID" in err and not (tmp_path / "x").exists()


@pytest.mark.parametrize("note, warned", [("left hemiparesis, 2nd visit", False), ("born 1961-03-02", True),
                                          ("Jane Doe", True), ("stroke in 2019", True), ("", False)])
def test_a_note_that_looks_identifying_is_warned_about(tmp_path, capsys, note, warned):
    from game.cli import main

    assert main(["patients", "--add", "P001", "--note", note, "--db", str(tmp_path / "r.sqlite3")]) == 0
    err = capsys.readouterr().err
    assert ("must not identify the patient" in err) == warned, err


@pytest.mark.skipif(sys.platform.startswith("win"), reason="POSIX permissions")
def test_rehabs_own_data_folder_made_0755_earlier_is_made_0700(tmp_path, monkeypatch):
    from game.db import default_db_path

    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "share"))
    folder = default_db_path().parent
    folder.mkdir(parents=True, mode=0o755)
    os.chmod(folder, 0o755)
    new_db(default_db_path())
    os.chmod(folder, 0o755)   # as an older rehab left it
    with Database(default_db_path()):
        pass
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    other = tmp_path / "shared"   # a folder the user chose: left as it is
    other.mkdir(mode=0o755)
    os.chmod(other, 0o755)
    new_db(other / "r.sqlite3")
    assert stat.S_IMODE(other.stat().st_mode) == 0o755
