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
    assert out.index("kept result") > out.index("-> accepted") - 200   # both printed after storing
    with Database(path) as db:
        assert len(db.rom_results("P001")) == 1
    assert cli_clinic is not None


def test_the_game_scene_store_keeps_a_result_while_locked(tmp_path):
    from game.exergames.session import GameLog, store_log

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
