"""Move a clinic's database between back-ends with all its history, and check a database's integrity.

``rehab db copy SQLITE_FILE postgresql://...`` (or back, or file to file) copies every patient,
session, result, game limit, account and audit row, keyed by the ids and uids the rows already have: the copy runs in
one transaction on the destination, so it lands whole or not at all, and running it again adds
nothing. Afterwards both databases are compared row by row (every column but the internal row
numbers): the copy is reported identical only when the destination holds exactly the source's
rows. :func:`integrity_problems` checks what both back-ends can check alike (orphans, missing or
duplicate uids, the schema version) and SQLite's own page-level check where it applies.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from game.db.columns import EXERCISE_COLUMNS, LIMIT_COLUMNS, ROM_COLUMNS, insert_result_sql
from game.db.migrations import LATEST_VERSION

if TYPE_CHECKING:   # the databases are given; this module never opens one
    from game.db.database import Database

#: table -> (columns compared and copied, the SELECT reading them by stable keys, in insertion order)
_SNAPSHOT = {
    "patients": ("id, created_utc, note", "SELECT id, created_utc, note FROM patients ORDER BY id"),
    "sessions": ("uid, patient_id, started_utc, ended_utc, kind, source, note",
                 "SELECT uid, patient_id, started_utc, ended_utc, kind, source, note FROM sessions ORDER BY id"),
    "rom_results": ("session_uid, " + ", ".join(ROM_COLUMNS),
                    f"SELECT s.uid, {', '.join('r.' + c for c in ROM_COLUMNS)} FROM rom_results r "
                    f"JOIN sessions s ON r.session_id = s.id ORDER BY r.id"),
    "exercise_results": ("session_uid, " + ", ".join(EXERCISE_COLUMNS),
                         f"SELECT s.uid, {', '.join('e.' + c for c in EXERCISE_COLUMNS)} FROM exercise_results e "
                         f"JOIN sessions s ON e.session_id = s.id ORDER BY e.id"),
    "game_limits": (", ".join(LIMIT_COLUMNS),
                    f"SELECT {', '.join(LIMIT_COLUMNS)} FROM game_limits ORDER BY patient_id, game"),
    "accounts": ("name, role, patient_id, secret_hash, created_utc",
                 "SELECT name, role, patient_id, secret_hash, created_utc FROM accounts ORDER BY name"),
    "audit": ("uid, at_utc, account, action, patient_id, what",
              "SELECT uid, at_utc, account, action, patient_id, what FROM audit ORDER BY id"),
}


def snapshot(db: Database) -> dict[str, list[tuple]]:
    """Every row of every table by its stable keys (no internal row numbers), in the database's order."""
    return {table: [tuple(r) for r in db.conn.execute(sql).fetchall()] for table, (_, sql) in _SNAPSHOT.items()}


def _insert(db: Database, table: str, row: tuple) -> int:
    c = db.conn
    if table in ("rom_results", "exercise_results"):
        sid = c.execute("SELECT id FROM sessions WHERE uid = ?", (row[0],)).fetchone()[0]
        return c.execute(insert_result_sql(table), (sid, *row[1:])).rowcount
    columns = _SNAPSHOT[table][0]
    n = columns.count(",") + 1
    return c.execute(f"INSERT INTO {table} ({columns}) VALUES ({', '.join('?' * n)}) ON CONFLICT DO NOTHING",
                     row).rowcount


def copy_database(src: Database, dst: Database) -> dict[str, tuple[int, int]]:
    """Copy every row of ``src`` into ``dst`` in one transaction; table -> (rows added, rows already there).

    Both are open and migrated to the same schema version. Rows whose key already exists in
    ``dst`` are left as they are (compare with :func:`differences` afterwards).
    """
    rows = snapshot(src)
    out: dict[str, tuple[int, int]] = {}
    with dst._transaction():
        for table, table_rows in rows.items():
            added = sum(_insert(dst, table, row) for row in table_rows)
            out[table] = (added, len(table_rows) - added)
    return out


def differences(src: Database, dst: Database) -> dict[str, tuple[int, int]]:
    """table -> (rows of ``src`` missing or different in ``dst``, rows of ``dst`` not in ``src``); empty = identical."""
    a, b = snapshot(src), snapshot(dst)
    out = {}
    for table in _SNAPSHOT:
        only_a, only_b = set(a[table]) - set(b[table]), set(b[table]) - set(a[table])
        if only_a or only_b or len(a[table]) != len(b[table]):
            out[table] = (len(only_a), len(only_b))
    return out


def integrity_problems(db: Database) -> list[str]:
    """What is wrong with the database's content (empty: all checks pass), one line each."""
    c = db.conn
    problems = []
    if db.dialect.name == "sqlite":
        problems += [f"SQLite integrity check: {r[0]}" for r in c.execute("PRAGMA integrity_check").fetchall()
                     if r[0] != "ok"]
        problems += [f"foreign key of {r[0]} row {r[1]} points nowhere ({r[2]})"
                     for r in c.execute("PRAGMA foreign_key_check").fetchall()]
    if db.schema_version != LATEST_VERSION:
        problems.append(f"schema version {db.schema_version}, expected {LATEST_VERSION}")
    checks = (
        ("sessions of no patient", "SELECT count(*) FROM sessions s LEFT JOIN patients p ON s.patient_id = p.id "
                                   "WHERE p.id IS NULL"),
        ("ROM results of no session", "SELECT count(*) FROM rom_results r LEFT JOIN sessions s ON r.session_id = s.id "
                                      "WHERE s.id IS NULL"),
        ("game results of no session", "SELECT count(*) FROM exercise_results e LEFT JOIN sessions s "
                                       "ON e.session_id = s.id WHERE s.id IS NULL"),
        ("game limits of no patient", "SELECT count(*) FROM game_limits g LEFT JOIN patients p ON g.patient_id = p.id "
                                      "WHERE p.id IS NULL"),
        ("sessions without a uid", "SELECT count(*) FROM sessions WHERE uid IS NULL OR uid = ''"),
        ("ROM results without a uid", "SELECT count(*) FROM rom_results WHERE uid IS NULL OR uid = ''"),
        ("duplicate session uids", "SELECT count(*) - count(DISTINCT uid) FROM sessions"),
        ("duplicate ROM result uids", "SELECT count(*) - count(DISTINCT uid) FROM rom_results"),
        ("duplicate game result uids", "SELECT count(*) - count(DISTINCT uid) FROM exercise_results"),
        ("patient accounts of no patient", "SELECT count(*) FROM accounts a LEFT JOIN patients p "
                                           "ON a.patient_id = p.id WHERE a.role = 'patient' AND p.id IS NULL"),
        ("sessions that end before they start", "SELECT count(*) FROM sessions WHERE ended_utc < started_utc"),
    )
    for what, sql in checks:
        n = c.execute(sql).fetchone()[0]
        if n:
            problems.append(f"{n} {what}")
    return problems
