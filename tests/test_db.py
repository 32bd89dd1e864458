"""The rehab database: results, migration from v1, damaged files, backup, CSV round trip, paths."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

import pytest

from game.db import Database, DatabaseError, LATEST_VERSION, default_db_path
from game.db.migrations import schema_v1_sql
from game.rom.session import RomResult


def rom_result(test="shoulder_flexion", side="right", value=142.3, start=-11.0, comp=(), est=()) -> RomResult:
    return RomResult(test=test, title="Shoulder flexion", side=side, angle=f"{side}_shoulder_flexion", direction=1,
                     mode="active", position="seated_arm_at_side", position_words="Seated.", standard="jarm",
                     reference_deg=180.0, max_deg=value, start_deg=start, range_deg=value - start, max_time_s=3.0,
                     started_s=1.0, ended_s=6.5, compensations=comp, estimated_markers=est, n_samples=165)


def filled(path: Path) -> Database:
    db = Database(path)
    db.add_patient("P001", "left hemiparesis")
    db.add_patient("P002")
    s1 = db.start_session("P001", "rom", "sim:shoulder_flexion", started_utc="2026-01-05T10:00:00Z")
    db.add_rom_result(s1, rom_result(value=120.5), recorded_utc="2026-01-05T10:01:00Z")
    db.add_rom_result(s1, rom_result(side="left", value=150.0, comp=("the trunk leaned 9 degrees back",), est=("MLE2",)),
                      recorded_utc="2026-01-05T10:02:00Z")
    db.end_session(s1, "2026-01-05T10:10:00Z")
    s2 = db.start_session("P001", "exercise", "cameras", started_utc="2026-01-12T10:00:00Z")
    db.add_exercise_result(s2, "reach", 24, 310.0, 0.75, details='{"level": 2}', recorded_utc="2026-01-12T10:06:00Z")
    db.set_game_limits("P001", "reach", '{"max_range":0.8}')
    db.set_game_limits("P001", "reach", '{"max_range":0.9}')   # replaces
    return db


def test_a_new_database_is_current_in_wal_mode_with_full_sync(tmp_path):
    with Database(tmp_path / "sub" / "rehab.sqlite3") as db:
        assert db.schema_version == LATEST_VERSION
        assert db.conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert db.conn.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
        assert db.patients() == []


def test_results_are_stored_with_their_labels(tmp_path):
    with filled(tmp_path / "db.sqlite3") as db:
        pats = {p.id: p for p in db.patients()}
        assert pats["P001"].sessions == 2 and pats["P001"].rom_results == 2 and pats["P001"].exercise_results == 1
        assert pats["P002"].sessions == 0
        right, left = db.rom_results("P001")
        assert (right.side, right.value_deg, right.start_deg, right.range_deg) == ("right", 120.5, -11.0, 131.5)
        assert right.mode == "active" and right.standard == "jarm" and right.position == "seated_arm_at_side"
        assert right.reference_deg == 180.0 and right.compensation == "" and right.duration_s == pytest.approx(5.5)
        assert left.compensation == "the trunk leaned 9 degrees back" and left.estimated_markers == "MLE2"
        (game,) = db.exercise_results("P001")
        assert (game.game, game.repetitions, game.duration_s, game.score) == ("reach", 24, 310.0, 0.75)
        assert db.rom_results("P002") == []


def test_patient_ids_are_pseudonyms_and_unique(tmp_path):
    with Database(tmp_path / "db.sqlite3") as db:
        for bad in ("", "John Smith", "x" * 40, "../etc"):
            with pytest.raises(DatabaseError, match="pseudonym"):
                db.add_patient(bad)
        db.add_patient("P-001.a")
        with pytest.raises(DatabaseError, match="already exists"):
            db.add_patient("P-001.a")
        with pytest.raises(DatabaseError, match="rehab patients --add P9"):
            db.start_session("P9", "rom")


def v1_database(path: Path) -> None:
    """A database as the first release wrote it, from the stored v1 schema script."""
    conn = sqlite3.connect(path)
    conn.executescript(schema_v1_sql())
    conn.execute("INSERT INTO patients VALUES ('P007', '2025-03-01T08:00:00Z', '')")
    conn.execute("INSERT INTO sessions (patient_id, started_utc, kind) VALUES ('P007', '2025-03-01T08:00:00Z', 'rom')")
    conn.execute("INSERT INTO rom_results (session_id, test, side, position, standard, value_deg, start_deg, "
                 "compensation, recorded_utc) VALUES (1, 'forearm_pronation', 'left', 'seated_arm_at_side_elbow_90', "
                 "'aaos', 75.2, 1.5, '', '2025-03-01T08:05:00Z')")
    conn.commit()
    conn.close()


def test_a_v1_database_is_migrated_on_open_and_keeps_its_results(tmp_path):
    path = tmp_path / "old.sqlite3"
    v1_database(path)
    with Database(path) as db:
        assert db.schema_version == LATEST_VERSION
        (r,) = db.rom_results("P007")
        assert (r.test, r.side, r.value_deg, r.start_deg, r.standard) == ("forearm_pronation", "left", 75.2, 1.5, "aaos")
        assert r.range_deg == pytest.approx(73.7) and r.angle == "left_forearm_supination" and len(r.uid) == 32
        s = db.start_session("P007", "exercise")
        db.add_exercise_result(s, "reach", 5, 60.0)  # the table added by the migration works
    with Database(path) as db:  # opening again does not migrate twice
        assert db.schema_version == LATEST_VERSION and len(db.rom_results("P007")) == 1


def test_a_newer_schema_is_refused(tmp_path):
    path = tmp_path / "new.sqlite3"
    Database(path).close()
    conn = sqlite3.connect(path)
    conn.execute("UPDATE schema_version SET version = ?", (LATEST_VERSION + 1,))
    conn.commit()
    conn.close()
    with pytest.raises(DatabaseError, match="newer than this rehab knows"):
        Database(path)


def _damaged_files(tmp_path: Path) -> dict[str, Path]:
    good = tmp_path / "good.sqlite3"
    filled(good).close()
    raw = good.read_bytes()
    files = {
        "random": os.urandom(20000),
        "truncated": raw[: len(raw) // 2],
        "text": b"patient,value\nP001,120\n",
    }
    out = {}
    for name, data in files.items():
        out[name] = tmp_path / f"{name}.sqlite3"
        out[name].write_bytes(data)
    other = tmp_path / "other_app.sqlite3"
    conn = sqlite3.connect(other)
    conn.execute("CREATE TABLE photos (id INTEGER PRIMARY KEY, name TEXT)")
    conn.commit()
    conn.close()
    out["other_app"] = other
    return out


def test_a_damaged_or_foreign_file_gets_one_line_and_is_never_written(tmp_path):
    for name, path in _damaged_files(tmp_path).items():
        before = path.read_bytes()
        with pytest.raises(DatabaseError) as err:
            Database(path)
        text = str(err.value)
        assert "is not a rehab database or is damaged" in text and "rehab backup" in text, name
        assert "\n" not in text and str(path) in text
        assert path.read_bytes() == before, f"{name} was modified"
        assert not Path(f"{path}-wal").exists() or Path(f"{path}-wal").stat().st_size == 0


def test_backup_is_a_consistent_copy_and_never_overwrites(tmp_path):
    with filled(tmp_path / "db.sqlite3") as db:
        out = db.backup(tmp_path / "backups" / "b1.sqlite3")
        with pytest.raises(DatabaseError, match="exists"):
            db.backup(out)
        expected = db.rom_results()
    with Database(out) as copy:
        assert copy.rom_results() == expected


def test_csv_round_trip_and_import_is_idempotent(tmp_path):
    with filled(tmp_path / "a.sqlite3") as db:
        counts = db.export_csv(tmp_path / "csv")
        rom, ex, pats = db.rom_results(), db.exercise_results(), db.patients()
    assert counts == {"patients": 2, "sessions": 2, "rom_results": 2, "exercise_results": 1, "game_limits": 1}
    with Database(tmp_path / "b.sqlite3") as db:
        assert db.import_csv(tmp_path / "csv") == counts
        assert db.rom_results() == rom and db.exercise_results() == ex and db.patients() == pats
        assert db.game_limits("P001") == {"reach": '{"max_range":0.9}'}
        assert db.import_csv(tmp_path / "csv") == {k: 0 for k in counts}
        assert len(db.rom_results()) == 2


def test_export_of_one_patient(tmp_path):
    with filled(tmp_path / "a.sqlite3") as db:
        counts = db.export_csv(tmp_path / "csv", "P002")
    assert counts == {"patients": 1, "sessions": 0, "rom_results": 0, "exercise_results": 0, "game_limits": 0}


def test_a_bad_csv_imports_nothing(tmp_path):
    with filled(tmp_path / "a.sqlite3") as db:
        db.export_csv(tmp_path / "csv")
    path = tmp_path / "csv" / "rom_results.csv"
    lines = path.read_text(encoding="utf-8").splitlines()
    lines[-1] = lines[-1].replace("150.0", "lots", 1)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with Database(tmp_path / "b.sqlite3") as db:
        with pytest.raises(DatabaseError, match=r"rom_results.csv line 3: value_deg 'lots' is not a number"):
            db.import_csv(tmp_path / "csv")
        assert db.patients() == [] and db.rom_results() == []
    (tmp_path / "csv" / "sessions.csv").write_text("uid,patient_id\n", encoding="utf-8")
    with Database(tmp_path / "c.sqlite3") as db, pytest.raises(DatabaseError, match="missing column"):
        db.import_csv(tmp_path / "csv")


def test_default_path_is_in_the_user_data_directory(monkeypatch, tmp_path):
    monkeypatch.setattr("sys.platform", "linux")
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert default_db_path() == tmp_path / "xdg" / "rehab" / "rehab.sqlite3"
    monkeypatch.delenv("XDG_DATA_HOME")
    assert default_db_path() == Path.home() / ".local" / "share" / "rehab" / "rehab.sqlite3"
    monkeypatch.setattr("sys.platform", "win32")
    monkeypatch.setenv("LOCALAPPDATA", str(tmp_path / "local"))
    assert default_db_path() == tmp_path / "local" / "rehab" / "rehab.sqlite3"
    monkeypatch.setattr("sys.platform", "darwin")
    assert default_db_path() == Path.home() / "Library" / "Application Support" / "rehab" / "rehab.sqlite3"
