"""The embedded rehab database: SQLite (standard library) in the user's data directory.

- Patients are pseudonymous IDs (``P001``); no names or other identifying fields exist.
- Sessions hold ROM results and exercise results; each result is committed in its own
  transaction with ``synchronous=FULL`` in WAL mode, so once :meth:`Database.add_rom_result`
  returns the result survives a killed process or a power cut, and a kill at any moment leaves
  the file consistent (SQLite's journal).
- The schema is versioned (``schema_version``) and migrated on open (:mod:`game.db.migrations`).
- Opening checks the file first (the SQLite header, ``PRAGMA integrity_check``, that it is a rehab
  database) and never writes to a file that fails: the user gets one line saying to restore a
  backup or move the file away.
- :meth:`Database.backup` copies a consistent snapshot with SQLite's backup API; CSV export and
  import round-trip every table by stable uids (an import never duplicates rows).

No video or images are stored.
"""

from __future__ import annotations

import csv
import logging
import os
import re
import sqlite3
import sys
import uuid
from dataclasses import dataclass, fields
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable, Sequence

from calibration.errors import RehabError
from game.db.migrations import LATEST_VERSION, STEPS, schema_v1_sql

log = logging.getLogger(__name__)

_SQLITE_HEADER = b"SQLite format 3\x00"
_PATIENT_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,31}$")


class DatabaseError(RehabError):
    """The database file cannot be used (damaged, not a rehab database, newer schema) or bad input."""


def default_db_path() -> Path:
    """The database in the user's data directory.

    Linux and others: ``$XDG_DATA_HOME/rehab/rehab.sqlite3`` (default ``~/.local/share``);
    Windows: ``%LOCALAPPDATA%\\rehab\\rehab.sqlite3``; macOS: ``~/Library/Application Support/rehab/``.
    """
    if sys.platform.startswith("win"):
        base = Path(os.environ.get("LOCALAPPDATA") or os.environ.get("APPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Application Support"
    else:
        base = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share")
    return base / "rehab" / "rehab.sqlite3"


def utc_now() -> str:
    """ISO 8601 UTC time stamp with seconds, e.g. ``2026-11-22T01:30:00Z``."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def _damaged(path: Path, detail: str) -> DatabaseError:
    return DatabaseError(f"{path} is not a rehab database or is damaged ({detail}): restore a backup "
                         f"(rehab backup) or move it away")


# --------------------------------------------------------------------------------- rows
@dataclass(frozen=True, slots=True)
class PatientRow:
    """A patient: pseudonymous id, when added, a free note (never a name), counts."""

    id: str
    created_utc: str
    note: str
    sessions: int
    rom_results: int
    exercise_results: int
    last_utc: str


@dataclass(frozen=True, slots=True)
class SessionRow:
    """A session of one patient."""

    uid: str
    patient_id: str
    started_utc: str
    ended_utc: str
    kind: str
    source: str
    note: str


@dataclass(frozen=True, slots=True)
class RomRow:
    """A stored ROM result (always active ROM), with its session.

    ``value_deg`` is the raw maximum; ``compensation`` the compensations seen ("" = clean);
    ``estimated_markers`` the markers estimated at the maximum ("" = all measured).
    """

    uid: str
    session_uid: str
    patient_id: str
    session_started_utc: str
    test: str
    side: str
    angle: str
    mode: str
    position: str
    standard: str
    reference_deg: float | None
    value_deg: float
    start_deg: float
    range_deg: float
    compensation: str
    estimated_markers: str
    duration_s: float | None
    recorded_utc: str


@dataclass(frozen=True, slots=True)
class ExerciseRow:
    """A stored exercise (game) result."""

    uid: str
    session_uid: str
    patient_id: str
    session_started_utc: str
    game: str
    repetitions: int
    duration_s: float
    score: float | None
    details: str
    recorded_utc: str


# --------------------------------------------------------------------------------- database
class Database:
    """A rehab database file, open and migrated. Use as a context manager or call :meth:`close`.

    Args:
        path: the SQLite file (created with its folder if missing).

    Raises:
        DatabaseError: the file is damaged, not a rehab database, or from a newer rehab.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._conn = _open_checked(self.path)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def __enter__(self) -> "Database":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def conn(self) -> sqlite3.Connection:
        if self._conn is None:
            raise DatabaseError(f"{self.path}: the database is closed")
        return self._conn

    @property
    def schema_version(self) -> int:
        return _version(self.conn)

    def _write(self, sql: str, params: Sequence[Any] = ()) -> sqlite3.Cursor:
        """One statement in its own durable transaction."""
        with _transaction(self.conn):
            return self.conn.execute(sql, params)

    # ------------------------------------------------------------------ patients
    def add_patient(self, patient_id: str, note: str = "") -> None:
        """Add a patient under a pseudonymous ID (letters, digits, ``_.-``; up to 32 characters)."""
        if not _PATIENT_ID.match(patient_id or ""):
            raise DatabaseError(f"patient ID {patient_id!r}: use a pseudonym of letters, digits, '_', '.', '-' "
                                f"(up to 32 characters, e.g. P001), never a name")
        if self.has_patient(patient_id):
            raise DatabaseError(f"patient {patient_id} already exists in {self.path}")
        self._write("INSERT INTO patients (id, created_utc, note) VALUES (?, ?, ?)", (patient_id, utc_now(), note))

    def has_patient(self, patient_id: str) -> bool:
        return self.conn.execute("SELECT 1 FROM patients WHERE id = ?", (patient_id,)).fetchone() is not None

    def require_patient(self, patient_id: str) -> None:
        """Raise a one-line DatabaseError if the patient does not exist."""
        if not self.has_patient(patient_id):
            raise DatabaseError(f"no patient {patient_id!r} in {self.path}: add it with rehab patients --add {patient_id}")

    def patients(self) -> list[PatientRow]:
        """Every patient with counts of sessions and results and the last activity."""
        rows = self.conn.execute("""
            SELECT p.id, p.created_utc, p.note,
                   (SELECT count(*) FROM sessions s WHERE s.patient_id = p.id),
                   (SELECT count(*) FROM rom_results r JOIN sessions s ON r.session_id = s.id WHERE s.patient_id = p.id),
                   (SELECT count(*) FROM exercise_results e JOIN sessions s ON e.session_id = s.id WHERE s.patient_id = p.id),
                   coalesce((SELECT max(s.started_utc) FROM sessions s WHERE s.patient_id = p.id), '')
            FROM patients p ORDER BY p.id""").fetchall()
        return [PatientRow(*r) for r in rows]

    # ------------------------------------------------------------------ sessions
    def start_session(self, patient_id: str, kind: str, source: str = "", note: str = "",
                      started_utc: str | None = None) -> int:
        """Open a session (``kind`` ``rom`` or ``exercise``); returns its id."""
        self.require_patient(patient_id)
        if kind not in ("rom", "exercise"):
            raise DatabaseError(f"session kind {kind!r}: use rom or exercise")
        cur = self._write("INSERT INTO sessions (patient_id, started_utc, kind, note, uid, source) VALUES (?, ?, ?, ?, ?, ?)",
                          (patient_id, started_utc or utc_now(), kind, note, uuid.uuid4().hex, source))
        return int(cur.lastrowid)

    def end_session(self, session_id: int, ended_utc: str | None = None) -> None:
        self._write("UPDATE sessions SET ended_utc = ? WHERE id = ?", (ended_utc or utc_now(), session_id))

    def sessions(self, patient_id: str) -> list[SessionRow]:
        rows = self.conn.execute(
            "SELECT uid, patient_id, started_utc, coalesce(ended_utc, ''), kind, source, note FROM sessions "
            "WHERE patient_id = ? ORDER BY started_utc, id", (patient_id,)).fetchall()
        return [SessionRow(*r) for r in rows]

    # ------------------------------------------------------------------ results
    def add_rom_result(self, session_id: int, result: Any, recorded_utc: str | None = None) -> str:
        """Store an accepted :class:`game.rom.session.RomResult`; returns its uid once it is durable."""
        uid = uuid.uuid4().hex
        duration = float(result.ended_s - result.started_s)
        self._write(
            "INSERT INTO rom_results (uid, session_id, test, side, angle, mode, position, standard, reference_deg, "
            "value_deg, start_deg, range_deg, compensation, estimated_markers, duration_s, recorded_utc) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (uid, session_id, result.test, result.side, result.angle, result.mode, result.position, result.standard,
             result.reference_deg, float(result.max_deg), float(result.start_deg), float(result.range_deg),
             "; ".join(result.compensations), " ".join(result.estimated_markers), duration,
             recorded_utc or utc_now()))
        return uid

    def add_exercise_result(self, session_id: int, game: str, repetitions: int, duration_s: float,
                            score: float | None = None, details: str = "", recorded_utc: str | None = None) -> str:
        """Store one game's result (repetitions, duration, score); returns its uid once it is durable."""
        if repetitions < 0 or duration_s < 0:
            raise DatabaseError(f"exercise result of {game}: repetitions and duration must not be negative")
        uid = uuid.uuid4().hex
        self._write("INSERT INTO exercise_results (uid, session_id, game, repetitions, duration_s, score, details, "
                    "recorded_utc) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                    (uid, session_id, game, int(repetitions), float(duration_s), score, details, recorded_utc or utc_now()))
        return uid

    def rom_results(self, patient_id: str | None = None) -> list[RomRow]:
        """ROM results (of one patient, or all) in session order."""
        where, params = ("WHERE s.patient_id = ?", (patient_id,)) if patient_id else ("", ())
        rows = self.conn.execute(f"""
            SELECT r.uid, s.uid, s.patient_id, s.started_utc, r.test, r.side, r.angle, r.mode, r.position, r.standard,
                   r.reference_deg, r.value_deg, r.start_deg, r.range_deg, r.compensation, r.estimated_markers,
                   r.duration_s, r.recorded_utc
            FROM rom_results r JOIN sessions s ON r.session_id = s.id {where}
            ORDER BY s.started_utc, r.recorded_utc, r.id""", params).fetchall()
        return [RomRow(*r) for r in rows]

    def exercise_results(self, patient_id: str | None = None) -> list[ExerciseRow]:
        where, params = ("WHERE s.patient_id = ?", (patient_id,)) if patient_id else ("", ())
        rows = self.conn.execute(f"""
            SELECT e.uid, s.uid, s.patient_id, s.started_utc, e.game, e.repetitions, e.duration_s, e.score, e.details,
                   e.recorded_utc
            FROM exercise_results e JOIN sessions s ON e.session_id = s.id {where}
            ORDER BY s.started_utc, e.recorded_utc, e.id""", params).fetchall()
        return [ExerciseRow(*r) for r in rows]

    # ------------------------------------------------------------------ game limits
    def set_game_limits(self, patient_id: str, game: str, limits_json: str, updated_utc: str | None = None) -> None:
        """Store the therapist's limits of one game for a patient (replacing the previous ones)."""
        self.require_patient(patient_id)
        self._write("INSERT INTO game_limits (patient_id, game, limits, updated_utc) VALUES (?, ?, ?, ?) "
                    "ON CONFLICT (patient_id, game) DO UPDATE SET limits = excluded.limits, "
                    "updated_utc = excluded.updated_utc", (patient_id, game, limits_json, updated_utc or utc_now()))

    def game_limits(self, patient_id: str) -> dict[str, str]:
        """The therapist's stored limits of each game for a patient: game -> JSON text."""
        rows = self.conn.execute("SELECT game, limits FROM game_limits WHERE patient_id = ? ORDER BY game",
                                 (patient_id,)).fetchall()
        return {game: text for game, text in rows}

    # ------------------------------------------------------------------ backup
    def backup(self, dest: str | Path) -> Path:
        """Copy a consistent snapshot to ``dest`` (SQLite's online backup API); refuses to overwrite."""
        dest = Path(dest)
        if dest.exists():
            raise DatabaseError(f"{dest} exists: give a new file name for the backup")
        dest.parent.mkdir(parents=True, exist_ok=True)
        target = sqlite3.connect(dest)
        try:
            self.conn.backup(target)
        finally:
            target.close()
        return dest

    # ------------------------------------------------------------------ CSV
    def export_csv(self, out_dir: str | Path, patient_id: str | None = None) -> dict[str, int]:
        """Write ``patients.csv``, ``sessions.csv``, ``rom_results.csv``, ``exercise_results.csv``, ``game_limits.csv``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        if patient_id:
            self.require_patient(patient_id)
        pats = [p for p in self.patients() if not patient_id or p.id == patient_id]
        sess = [s for p in pats for s in self.sessions(p.id)]
        counts = {
            "patients": _write_csv(out / "patients.csv", ("id", "created_utc", "note"),
                                   [(p.id, p.created_utc, p.note) for p in pats]),
            "sessions": _write_csv(out / "sessions.csv", [f.name for f in fields(SessionRow)],
                                   [tuple(getattr(s, f.name) for f in fields(SessionRow)) for s in sess]),
            "rom_results": _write_csv(out / "rom_results.csv", [f.name for f in fields(RomRow)],
                                      [tuple(getattr(r, f.name) for f in fields(RomRow)) for r in self.rom_results(patient_id)]),
            "exercise_results": _write_csv(out / "exercise_results.csv", [f.name for f in fields(ExerciseRow)],
                                           [tuple(getattr(r, f.name) for f in fields(ExerciseRow))
                                            for r in self.exercise_results(patient_id)]),
            "game_limits": _write_csv(out / "game_limits.csv", _LIMIT_COLUMNS, [
                row for p in pats for row in self.conn.execute(
                    f"SELECT {', '.join(_LIMIT_COLUMNS)} FROM game_limits WHERE patient_id = ? ORDER BY game", (p.id,))]),
        }
        return counts

    def import_csv(self, in_dir: str | Path) -> dict[str, int]:
        """Read a folder written by :meth:`export_csv`; rows already present (same id/uid) are skipped.

        Everything is imported in one transaction: a bad file imports nothing. Returns new rows per table.
        """
        src = Path(in_dir)
        pats = _read_csv(src / "patients.csv", ("id", "created_utc", "note"))
        sess = _read_csv(src / "sessions.csv", [f.name for f in fields(SessionRow)])
        roms = _read_csv(src / "rom_results.csv", [f.name for f in fields(RomRow)])
        exes = _read_csv(src / "exercise_results.csv", [f.name for f in fields(ExerciseRow)])
        # exports of schema 2 have no game limits
        lims = _read_csv(src / "game_limits.csv", _LIMIT_COLUMNS) if (src / "game_limits.csv").is_file() else []
        added = {"patients": 0, "sessions": 0, "rom_results": 0, "exercise_results": 0, "game_limits": 0}
        c = self.conn
        with _transaction(c):
            for line, p in pats:
                if not _PATIENT_ID.match(p["id"]):
                    raise DatabaseError(f"{src / 'patients.csv'} line {line}: patient ID {p['id']!r} is not a pseudonymous ID")
                added["patients"] += c.execute("INSERT OR IGNORE INTO patients (id, created_utc, note) VALUES (?, ?, ?)",
                                               (p["id"], p["created_utc"], p["note"])).rowcount
            for line, s in sess:
                if c.execute("SELECT 1 FROM patients WHERE id = ?", (s["patient_id"],)).fetchone() is None:
                    raise DatabaseError(f"{src / 'sessions.csv'} line {line}: patient {s['patient_id']!r} is not in patients.csv")
                added["sessions"] += c.execute(
                    "INSERT OR IGNORE INTO sessions (uid, patient_id, started_utc, ended_utc, kind, source, note) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?)",
                    (s["uid"], s["patient_id"], s["started_utc"], s["ended_utc"] or None, s["kind"], s["source"],
                     s["note"])).rowcount
            path = src / "rom_results.csv"
            for line, r in roms:
                sid = _session_id(c, r["session_uid"], path, line)
                added["rom_results"] += c.execute(
                    "INSERT OR IGNORE INTO rom_results (uid, session_id, test, side, angle, mode, position, standard, "
                    "reference_deg, value_deg, start_deg, range_deg, compensation, estimated_markers, duration_s, "
                    "recorded_utc) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (r["uid"], sid, r["test"], r["side"], r["angle"], r["mode"], r["position"], r["standard"],
                     _num(r["reference_deg"], path, line, True), _num(r["value_deg"], path, line),
                     _num(r["start_deg"], path, line), _num(r["range_deg"], path, line), r["compensation"],
                     r["estimated_markers"], _num(r["duration_s"], path, line, True), r["recorded_utc"])).rowcount
            path = src / "exercise_results.csv"
            for line, e in exes:
                sid = _session_id(c, e["session_uid"], path, line)
                added["exercise_results"] += c.execute(
                    "INSERT OR IGNORE INTO exercise_results (uid, session_id, game, repetitions, duration_s, score, "
                    "details, recorded_utc) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                    (e["uid"], sid, e["game"], int(_num(e["repetitions"], path, line)), _num(e["duration_s"], path, line),
                     _num(e["score"], path, line, True), e["details"], e["recorded_utc"])).rowcount
            for line, g in lims:
                if c.execute("SELECT 1 FROM patients WHERE id = ?", (g["patient_id"],)).fetchone() is None:
                    raise DatabaseError(f"{src / 'game_limits.csv'} line {line}: patient {g['patient_id']!r} is not in "
                                        "patients.csv")
                added["game_limits"] += c.execute(
                    "INSERT OR IGNORE INTO game_limits (patient_id, game, limits, updated_utc) VALUES (?, ?, ?, ?)",
                    tuple(g[k] for k in _LIMIT_COLUMNS)).rowcount
        return added


_LIMIT_COLUMNS = ("patient_id", "game", "limits", "updated_utc")


# --------------------------------------------------------------------------------- helpers
class _transaction:
    """``BEGIN IMMEDIATE`` ... ``COMMIT`` (``ROLLBACK`` on error) on an autocommit connection."""

    def __init__(self, conn: sqlite3.Connection):
        self.conn = conn

    def __enter__(self):
        self.conn.execute("BEGIN IMMEDIATE")
        return self.conn

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.conn.execute("COMMIT")
        else:
            self.conn.execute("ROLLBACK")
        return False


def _version(conn: sqlite3.Connection) -> int:
    row = conn.execute("SELECT max(version) FROM schema_version").fetchone()
    return int(row[0]) if row and row[0] is not None else 0


def _open_checked(path: Path) -> sqlite3.Connection:
    """Open (or create) the database; check it before anything is written; migrate it."""
    existed = path.exists()
    if existed:
        if not path.is_file():
            raise DatabaseError(f"{path} is not a file: give a database file path with --db")
        with open(path, "rb") as fh:
            head = fh.read(len(_SQLITE_HEADER))
        if head and head != _SQLITE_HEADER:
            raise _damaged(path, "no SQLite header")
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
    try:
        conn = sqlite3.connect(path, isolation_level=None, timeout=10.0)
    except sqlite3.Error as exc:
        raise DatabaseError(f"{path}: cannot open the database ({exc}): check the path and its permissions") from None
    try:
        conn.execute("PRAGMA busy_timeout = 10000")
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if existed and tables:
            problems = [r[0] for r in conn.execute("PRAGMA integrity_check").fetchall()]
            if problems != ["ok"]:
                raise _damaged(path, f"integrity check: {problems[0]}")
            if "schema_version" not in tables:
                raise _damaged(path, "no schema_version table")
        version = _version(conn) if tables else 0
        if version > LATEST_VERSION:
            raise DatabaseError(f"{path} has schema version {version}, newer than this rehab knows "
                                f"({LATEST_VERSION}): update rehab")
        conn.execute("PRAGMA journal_mode = WAL")
        conn.execute("PRAGMA synchronous = FULL")  # a commit that returned survives a crash or power cut
        conn.execute("PRAGMA foreign_keys = ON")
        _migrate(conn, version, path)
    except sqlite3.DatabaseError as exc:
        conn.close()
        raise _damaged(path, str(exc)) from None
    except BaseException:
        conn.close()
        raise
    return conn


def _migrate(conn: sqlite3.Connection, version: int, path: Path) -> None:
    """Bring the schema from ``version`` to :data:`LATEST_VERSION`, one transaction per step."""
    if version == 0:
        with _transaction(conn):
            for statement in _statements(schema_v1_sql()):
                conn.execute(statement)
        version = 1
    for target in range(version + 1, LATEST_VERSION + 1):
        log.info("migrating %s from schema version %d to %d", path, target - 1, target)
        with _transaction(conn):
            for statement in _statements(STEPS[target]):
                conn.execute(statement)
            conn.execute("UPDATE schema_version SET version = ?", (target,))


def _statements(script: str) -> list[str]:
    """Split an SQL script into statements (``sqlite3.complete_statement`` knows quoting)."""
    out, buf = [], ""
    for line in script.splitlines(keepends=True):
        if not buf and line.strip().startswith("--"):
            continue
        buf += line
        if sqlite3.complete_statement(buf):
            out.append(buf.strip())
            buf = ""
    if buf.strip():
        out.append(buf.strip())
    return out


def _write_csv(path: Path, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> int:
    n = 0
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for row in rows:
            w.writerow(["" if v is None else v for v in row])
            n += 1
    return n


def _read_csv(path: Path, need: Sequence[str]) -> list[tuple[int, dict[str, str]]]:
    if not path.is_file():
        raise DatabaseError(f"{path}: missing; import a folder written by rehab export")
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        missing = [k for k in need if k not in (reader.fieldnames or ())]
        if missing:
            raise DatabaseError(f"{path}: missing column(s) {', '.join(missing)}; import a folder written by rehab export")
        return [(i + 2, row) for i, row in enumerate(reader)]


def _num(text: str, path: Path, line: int, optional: bool = False) -> float | None:
    if optional and text.strip() == "":
        return None
    try:
        return float(text)
    except ValueError:
        raise DatabaseError(f"{path} line {line}: {text!r} is not a number") from None


def _session_id(conn: sqlite3.Connection, uid: str, path: Path, line: int) -> int:
    row = conn.execute("SELECT id FROM sessions WHERE uid = ?", (uid,)).fetchone()
    if row is None:
        raise DatabaseError(f"{path} line {line}: session {uid!r} is not in sessions.csv")
    return int(row[0])
