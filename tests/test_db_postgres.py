"""PostgreSQL as the clinic's shared store: the same schema and behaviour as SQLite, several stations
at once, kill -9 during writes, the server stopped and restarted mid-session, ``rehab db copy``.

One throwaway cluster for the whole module (tests/pg_cluster.py), a new database per test. Skipped,
with the reason shown, where PostgreSQL or psycopg is not installed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import pytest

from game.db import Database, DatabaseError, DatabaseUnreachable, LATEST_VERSION, ServerUrl, rom_record
from game.db.accounts import add_account, record
from game.db.copy import differences, integrity_problems, snapshot
from game.db.pending import pending_dir, store_durably
from pg_cluster import TempCluster, why_not
from pg_station import make_record

ROOT = Path(__file__).resolve().parents[1]
STATION = str(ROOT / "tests" / "pg_station.py")
REASON = why_not()
pytestmark = pytest.mark.skipif(bool(REASON), reason=f"PostgreSQL tests skipped: {REASON}")


@pytest.fixture(scope="module")
def cluster():
    c = TempCluster()
    yield c
    c.close()


@pytest.fixture
def url(cluster, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))   # the station's queue folder
    u = cluster.create_db(f"t_{uuid.uuid4().hex[:12]}")
    with Database(u) as db:
        db.add_patient("P001")
    return u


def _env(tmp_path: Path) -> dict:
    return {**os.environ, "XDG_DATA_HOME": str(tmp_path / "data"), "PYTHONPATH": str(ROOT)}


def _accepted(out: str) -> list[str]:
    return [line.split()[0] for line in out.splitlines() if line.endswith((" stored", " pending"))]


def _all_uids(db: Database) -> list[str]:
    return [r.uid for r in db.rom_results()] + [r.uid for r in db.exercise_results()]


def test_a_new_server_database_gets_the_same_schema_and_behaviour(cluster, url):
    with Database(url) as db:
        assert db.dialect.name == "postgresql" and db.schema_version == LATEST_VERSION
        with pytest.raises(DatabaseError, match="already exists"):
            db.add_patient("P001")
        sid = db.start_session("P001", "rom", "test")
        rec = make_record("P001", 0, __import__("random").Random(1), None)
        db.store_result(rec)
        db.store_result(rec)   # idempotent
        db.set_game_limits("P001", "reach", '{"max_level": 3}')
        db.set_game_limits("P001", "reach", '{"max_level": 4}')
        assert db.game_limits("P001") == {"reach": '{"max_level": 4}'}
        assert [r.uid for r in db.rom_results("P001")] == [rec.uid]
        assert db.rom_results()[0].value_deg == rec.values["value_deg"]   # 64-bit floats both ways
        assert sid >= 1 and len(db.sessions("P001")) == 2
        assert integrity_problems(db) == []


def test_two_stations_migrating_a_new_database_at_once_apply_each_step_once(cluster):
    u = cluster.create_db(f"m_{uuid.uuid4().hex[:12]}")
    errors, versions = [], []

    def open_it():
        try:
            with Database(u) as db:
                versions.append(db.schema_version)
        except Exception as exc:  # pragma: no cover - the failure is the assertion below
            errors.append(exc)

    threads = [threading.Thread(target=open_it) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == [] and versions == [LATEST_VERSION] * 4
    with Database(u) as db:
        assert db.conn.execute("SELECT count(*) FROM schema_version").fetchone()[0] == 1


def test_two_stations_writing_the_same_patient_and_session_at_once_lose_and_duplicate_nothing(url, tmp_path):
    session = uuid.uuid4().hex
    procs = [subprocess.Popen([sys.executable, STATION, url, "P001", "--count", "40", "--session", session,
                               "--resend", "--seed", str(seed), "--wait", "20"], stdout=subprocess.PIPE, text=True,
                              env=_env(tmp_path)) for seed in (1, 2)]
    outs = [p.communicate(timeout=240)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0]
    accepted = [u for out in outs for u in _accepted(out)]
    assert len(accepted) == 80 and all(out.count(" stored") == 40 for out in outs)
    with Database(url) as db:
        uids = _all_uids(db)
        assert sorted(uids) == sorted(accepted)   # every result once, none lost
        shared = [s for s in db.sessions("P001") if s.uid == session]
        assert len(shared) == 1   # both stations wrote into one session row
        assert len([r for r in db.rom_results("P001") if r.session_uid == session]) == 40
        assert integrity_problems(db) == []


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_a_station_killed_during_writes_loses_no_accepted_result(url, tmp_path):
    accepted = []
    for kills, seed in enumerate((3, 4, 5), 1):
        p = subprocess.Popen([sys.executable, STATION, url, "P001", "--seed", str(seed)], stdout=subprocess.PIPE,
                             text=True, env=_env(tmp_path))
        lines = []
        deadline = time.monotonic() + 60
        while len(lines) < 10 + 7 * seed and time.monotonic() < deadline:   # kill at different moments
            lines.append(p.stdout.readline())
        os.kill(p.pid, signal.SIGKILL)
        rest = p.communicate(timeout=30)[0]
        accepted += _accepted("".join(lines) + rest)
        with Database(url) as db:
            uids = _all_uids(db)
            assert set(accepted) <= set(uids)
            assert len(uids) == len(set(uids))
            assert len(uids) - len(accepted) <= kills   # at most the one in flight at each kill (stored, not printed)
            assert integrity_problems(db) == []


def test_the_server_stopped_and_restarted_mid_session_gets_every_result_exactly_once(cluster, url, tmp_path):
    p = subprocess.Popen([sys.executable, STATION, url, "P001", "--pause", "0.05", "--wait", "0.5", "--seed", "7"],
                         stdout=subprocess.PIPE, text=True, env=_env(tmp_path))
    lines = []
    try:
        while len(lines) < 15:
            lines.append(p.stdout.readline())
        cluster.stop()
        t0 = time.monotonic()
        while not any(line.endswith(" pending\n") for line in lines) or time.monotonic() - t0 < 2.0:
            lines.append(p.stdout.readline())   # the station keeps recording while the server is down
        cluster.start()
        n = len(lines)
        while len(lines) < n + 15:
            lines.append(p.stdout.readline())
    finally:
        p.kill()
        rest = p.communicate(timeout=30)[0]
        cluster.start()   # running already: a no-op; else the other tests get their server back
    accepted = _accepted("".join(lines) + rest)
    pending = [u for u in accepted if f"{u} pending" in "".join(lines) + rest]
    assert pending, "the station queued nothing while the server was down"
    with Database(url) as db:   # the last of the queue is sent by this open
        uids = _all_uids(db)
        assert sorted(uids) == sorted(accepted)
        assert integrity_problems(db) == []
    assert list(pending_dir(ServerUrl(url)).glob("*.json")) == []


def test_an_unreachable_server_is_one_line_and_the_result_waits_on_the_station(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    bad = f"postgresql://rehab:secret@127.0.0.1:{port}/clinic"
    with pytest.raises(DatabaseUnreachable) as info:
        Database(bad)
    assert "\n" not in str(info.value) and "secret" not in str(info.value) and "***" in str(info.value)
    out = store_durably(bad, make_record("P001", 0, __import__("random").Random(2), None), wait_s=0.2)
    assert not out.stored and out.pending_file.parent == tmp_path / "data" / "rehab" / "pending" / f"127.0.0.1_{port}_clinic"
    assert (out.pending_file.stat().st_mode & 0o777) == 0o600


def _clinic_file(path: Path) -> None:
    """An SQLite clinic with history: two patients, ROM and game sessions over weeks, limits."""
    import random

    rng = random.Random(11)
    with Database(path) as db:
        db.add_patient("P001", "knee")
        db.add_patient("P002")
        for week in range(6):
            for pid in ("P001", "P002"):
                day = f"2026-0{1 + week // 4}-{10 + week % 4 * 5:02d}T09:00:00Z"
                rec = make_record(pid, 0, rng, None)
                rec = rom_record(pid, _result_of(rec), started_utc=day, recorded_utc=day)
                db.store_result(rec)
                db.store_result(make_record(pid, 1, rng, None))
        db.set_game_limits("P001", "reach", '{"max_level": 5}')
        add_account(db, "anna", "therapist", "4711")
        add_account(db, "p1", "patient", "1234", "P001")
        record(db, "anna", "export", "P001", "report")


def _clinic_and_server(cluster, tmp_path, monkeypatch) -> tuple[Path, str]:
    """The SQLite clinic (its therapist signed in) and a new empty server database."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    monkeypatch.setenv("REHAB_USER", "anna")
    monkeypatch.setenv("REHAB_PIN", "4711")
    src = tmp_path / "clinic.sqlite3"
    _clinic_file(src)
    return src, cluster.create_db(f"c_{uuid.uuid4().hex[:12]}")


def _result_of(rec):
    from types import SimpleNamespace

    v = rec.values
    return SimpleNamespace(test=v["test"], side=v["side"], angle=v["angle"], mode="active", position=v["position"],
                           standard="jarm", reference_deg=v["reference_deg"], max_deg=v["value_deg"],
                           start_deg=v["start_deg"], range_deg=v["range_deg"], started_s=0.0,
                           ended_s=v["duration_s"], compensations=(), estimated_markers=())


def test_db_copy_moves_a_sqlite_clinic_with_all_history_and_the_reports_are_identical(cluster, tmp_path, monkeypatch,
                                                                                        capsys):
    from game.cli import main
    from game import report

    src, dest = _clinic_and_server(cluster, tmp_path, monkeypatch)
    assert main(["db", "copy", str(src), dest]) == 0
    out = capsys.readouterr().out
    assert "now holds exactly the rows" in out and "rom_results           12 copied" in out
    assert main(["db", "copy", str(src), dest]) == 0   # again: nothing added
    assert "0 copied, 12 already in" in capsys.readouterr().out
    monkeypatch.setattr(report, "utc_now", lambda *a: "2026-11-27T12:00:00Z")
    with Database(src) as a, Database(dest) as b:
        assert differences(a, b) == {} and snapshot(a) == snapshot(b)
        for pid in ("P001", "P002"):
            ha, ca = report.write_report(a, pid, tmp_path / "from_sqlite" / f"{pid}.html")
            hb, cb = report.write_report(b, pid, tmp_path / "from_server" / f"{pid}.html")
            assert ha.read_bytes() == hb.read_bytes() and ca.read_bytes() == cb.read_bytes()
        back = tmp_path / "back.sqlite3"
        b.backup(back)   # a server's backup is a new SQLite file with the same rows
    with Database(src) as a, Database(back) as c:
        assert differences(a, c) == {}
    assert main(["db", "check", "--db", dest]) == 0
    assert main(["db", "migrate", "--db", dest]) == 0
    assert f"schema version {LATEST_VERSION}" in capsys.readouterr().out


def test_db_copy_into_a_database_with_other_rows_says_they_differ(cluster, tmp_path, monkeypatch, capsys):
    from game.cli import main

    src, dest = _clinic_and_server(cluster, tmp_path, monkeypatch)
    with Database(dest) as db:
        db.add_patient("P009")
    assert main(["db", "copy", str(src), dest]) == 1
    assert "patients: 0 rows" in capsys.readouterr().out


def test_rehab_db_env_variable_names_the_server(url, monkeypatch, capsys):
    from game.cli import main

    monkeypatch.setenv("REHAB_DB", url)
    assert main(["patients"]) == 0
    assert "P001" in capsys.readouterr().out
