"""The embedded rehab database: SQLite (standard library) in the user's data directory.

- Patients are pseudonymous IDs (``P001``); no names or other identifying fields exist.
- A result is stored with its session in one transaction (:meth:`Database.store_result`) with
  ``synchronous=FULL`` in WAL mode: once it returns the result survives a killed process or a
  power cut, and a kill at any moment leaves the file consistent (SQLite's journal). A database
  locked by another program raises :class:`DatabaseLocked`; :mod:`game.db.pending` then waits and
  keeps the result in a pending file rather than lose it.
- The schema is versioned (``schema_version``) and migrated on open (:mod:`game.db.migrations`).
- Opening checks the SQLite header and the tables before anything is written; the full
  ``PRAGMA integrity_check`` runs where it matters (``check_integrity=True``: the commands' start,
  backup, import), not on every open. A file that fails gets one line saying to restore a backup.
- Files are the user's only (0600, folders created 0700: :mod:`game.db.private`).
- :meth:`Database.backup` copies a consistent snapshot with SQLite's backup API to a temporary file
  and renames it; CSV export and import round-trip every table by stable uids (an import never
  duplicates rows, and checks every value).

No video or images are stored.
"""

from __future__ import annotations

import contextlib
import csv
import functools
import json
import logging
import math
import os
import re
import sqlite3
import uuid
from dataclasses import asdict, dataclass, fields
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import Any, Iterable, Sequence

from game.db.columns import EXERCISE_COLUMNS, LIMIT_COLUMNS, RESULT_COLUMNS, ROM_COLUMNS, insert_result_sql  # noqa: F401 (re-exported)
from game.db.copy import copy_database
from game.db.dialect import SQLITE, Dialect
from game.db.errors import (DatabaseError, DatabaseLocked, DatabaseUnreachable,  # noqa: F401 (re-exported)
                             ResultRejected, damaged, sqlite_error)
from game.db.location import ServerUrl, db_location, default_db_path, pending_dir
from game.db.migrations import LATEST_VERSION, STEPS, schema_v1_sql
from game.db.private import DIR_MODE, FILE_MODE, commit_temp, make_private, make_private_dir, open_private, temp_path_beside
from game.rom.spec import available_rom_tests

log = logging.getLogger(__name__)

_SQLITE_HEADER = b"SQLite format 3\x00"
_PATIENT_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,31}$")


#: How long one statement waits for another program's lock before :class:`DatabaseLocked`.
BUSY_TIMEOUT_S = 10.0
#: The tables of a current database (a missing one is a damaged file, not a traceback later).
_TABLES = ("schema_version", "patients", "sessions", "rom_results", "exercise_results", "game_limits", "accounts",
           "audit")
_TABLES_BY_VERSION = {1: _TABLES[:4], 2: _TABLES[:5], 3: _TABLES[:6], 4: _TABLES}
_UTC = re.compile(r"^\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2}(\.\d+)?Z$")


def utc_now(ago_s: float = 0.0) -> str:
    """ISO 8601 UTC time stamp with seconds, e.g. ``2026-11-22T01:30:00Z`` (``ago_s`` seconds before now)."""
    ago_s = ago_s if math.isfinite(ago_s) and 0.0 <= ago_s < 1e7 else 0.0
    return (datetime.now(timezone.utc) - timedelta(seconds=ago_s)).strftime("%Y-%m-%dT%H:%M:%SZ")


def _guarded(method):
    """Turn an SQLite failure inside a Database method into a one-line :class:`DatabaseError`."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except sqlite3.Error as exc:
            raise sqlite_error(self.path, exc) from None
        except self._dialect.errors as exc:
            raise self._dialect.error(self.path, exc) from None
        except UnicodeDecodeError:   # a TEXT cell that is not UTF-8: the file was damaged
            raise damaged(self.path, "text that is not UTF-8") from None

    return wrapper


_DATE = re.compile(r"\b\d{1,4}\s*[-/.]\s*\d{1,2}\s*[-/.]\s*\d{1,4}\b|\b(19|20)\d{2}\b")
_NAME = re.compile(r"\b[A-Z][a-z\u00C0-\u024F'-]+\s+[A-Z][a-z\u00C0-\u024F'-]+\b")
_IDENTIFYING = re.compile(r"\b(born|birth|dob|name|geb|n[ée]e?|address|street|phone|tel)\b", re.IGNORECASE)


def identifying_hint(note: str) -> str:
    """What in a free-text note looks like it could identify the patient ("" when nothing does).

    A heuristic for a warning (a date, two capitalised words in a row, words like "born"); notes
    must never hold names, birth dates or addresses.
    """
    for pattern, what in ((_DATE, "a date"), (_NAME, "a name"), (_IDENTIFYING, "identifying words")):
        m = pattern.search(note or "")
        if m:
            return f"{what} ({m.group(0)!r})"
    return ""


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


# --------------------------------------------------------------------------------- a result to store
@dataclass(frozen=True, slots=True)
class ResultRecord:
    """One result with its session, stored in one transaction (or kept in a pending file meanwhile).

    Storing is idempotent: the session and the result are keyed by their uids, so storing a record
    twice (a pending file stored again after a kill) adds nothing.

    Attributes:
        patient_id: the patient (must exist in the database).
        session_uid, session_kind, session_source, session_started_utc: the session the result
            belongs to (created by the first of its results).
        table: ``rom_results`` or ``exercise_results``.
        values: the result's columns (``ROM_COLUMNS`` or ``EXERCISE_COLUMNS``).
        accepted_by: the account that accepted it ("" = none signed in); stored as an audit row in
            the result's own transaction.
    """

    patient_id: str
    session_uid: str
    session_kind: str
    session_source: str
    session_started_utc: str
    table: str
    values: dict
    accepted_by: str = ""

    @property
    def uid(self) -> str:
        return str(self.values["uid"])

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1, sort_keys=True, allow_nan=False)

    @classmethod
    def from_json(cls, text: str, where: str) -> "ResultRecord":
        """Parse and check a record written by :meth:`to_json`.

        Raises:
            DatabaseError: ``where`` is not such a record.
        """
        try:
            data = json.loads(text)
            data.setdefault("accepted_by", "")   # pending files of rehab before accounts
            record = cls(**{f.name: data[f.name] for f in fields(cls)})
        except (ValueError, TypeError, KeyError) as exc:
            raise DatabaseError(f"{where}: not a pending result ({exc})") from None
        record.check(where)
        return record

    def check(self, where: str) -> None:
        """Raise a one-line DatabaseError if any field or value is out of place."""
        if self.table not in RESULT_COLUMNS or not isinstance(self.values, dict) or \
                set(self.values) != set(RESULT_COLUMNS[self.table]):
            raise DatabaseError(f"{where}: not a result of rom_results or exercise_results")
        check_session_fields(self.session_kind, self.session_started_utc, None, where)
        check_result_values(self.table, self.values, where)


def rom_record(patient_id: str, result: Any, *, session_uid: str | None = None, source: str = "",
               started_utc: str | None = None, recorded_utc: str | None = None) -> ResultRecord:
    """The record of an accepted :class:`game.rom.session.RomResult` (in a new session unless ``session_uid``)."""
    now = recorded_utc or utc_now()
    values = {"uid": uuid.uuid4().hex, "test": result.test, "side": result.side, "angle": result.angle,
              "mode": result.mode, "position": result.position, "standard": result.standard,
              "reference_deg": None if result.reference_deg is None else float(result.reference_deg),
              "value_deg": float(result.max_deg), "start_deg": float(result.start_deg),
              "range_deg": float(result.range_deg), "compensation": "; ".join(result.compensations),
              "estimated_markers": " ".join(result.estimated_markers),
              "duration_s": float(result.ended_s - result.started_s), "recorded_utc": now}
    return ResultRecord(patient_id, session_uid or uuid.uuid4().hex, "rom", source, started_utc or now,
                        "rom_results", values)


def exercise_record(patient_id: str, game: str, repetitions: int, duration_s: float, score: float | None = None,
                    details: str = "", *, source: str = "", started_utc: str | None = None,
                    recorded_utc: str | None = None) -> ResultRecord:
    """The record of one game's result in a new ``exercise`` session."""
    now = recorded_utc or utc_now()
    values = {"uid": uuid.uuid4().hex, "game": game, "repetitions": int(repetitions), "duration_s": float(duration_s),
              "score": None if score is None else float(score), "details": details, "recorded_utc": now}
    return ResultRecord(patient_id, uuid.uuid4().hex, "exercise", source, started_utc or now, "exercise_results",
                        values)


# --------------------------------------------------------------------------------- value checks
def _finite(value: Any, name: str, where: str, *, optional: bool = False, low: float = -math.inf,
            high: float = math.inf) -> float | None:
    if value is None or (optional and isinstance(value, str) and value.strip() == ""):
        if optional:
            return None
        raise DatabaseError(f"{where}: {name} is missing: give a number")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise DatabaseError(f"{where}: {name} {value!r} is not a number") from None
    if not math.isfinite(x) or not low <= x <= high:
        raise DatabaseError(f"{where}: {name} {value!r} is out of range ({low:g} to {high:g})")
    return x


def _utc_text(value: Any, name: str, where: str, *, optional: bool = False) -> str | None:
    if optional and (value is None or value == ""):
        return None
    if not isinstance(value, str) or not _UTC.match(value):
        raise DatabaseError(f"{where}: {name} {value!r} is not a UTC time like 2026-01-05T10:00:00Z")
    try:
        datetime.strptime(value[:19], "%Y-%m-%dT%H:%M:%S")
    except ValueError:
        raise DatabaseError(f"{where}: {name} {value!r} is not a valid date and time") from None
    return value


def check_session_fields(kind: Any, started_utc: Any, ended_utc: Any, where: str) -> None:
    """Raise a one-line DatabaseError for a session kind or time that the rest cannot use."""
    if kind not in ("rom", "exercise"):
        raise DatabaseError(f"{where}: session kind {kind!r}: use rom or exercise")
    _utc_text(started_utc, "started_utc", where)
    _utc_text(ended_utc, "ended_utc", where, optional=True)


def check_result_values(table: str, values: dict, where: str) -> dict:
    """Check (and convert) a result's values; returns them ready to insert.

    Numbers must be finite and plausible (angles within +-360 degrees, durations and repetitions not
    negative, repetitions whole), sides ``right``/``left``, standards ``jarm``/``aaos``, ROM tests
    ones this rehab knows, times UTC stamps.
    """
    v = dict(values)
    if not str(v.get("uid") or "").strip():
        raise DatabaseError(f"{where}: a result has no uid")
    _utc_text(v.get("recorded_utc"), "recorded_utc", where)
    if table == "rom_results":
        if v.get("test") not in available_rom_tests():
            raise DatabaseError(f"{where}: unknown ROM test {v.get('test')!r}: use one of "
                                f"{', '.join(available_rom_tests())}")
        if v.get("side") not in ("right", "left"):
            raise DatabaseError(f"{where}: side {v.get('side')!r}: use right or left")
        if v.get("standard") not in ("jarm", "aaos"):
            raise DatabaseError(f"{where}: standard {v.get('standard')!r}: use jarm or aaos")
        if v.get("mode") != "active":
            raise DatabaseError(f"{where}: mode {v.get('mode')!r}: only active ROM is stored")
        for key in ("value_deg", "start_deg"):
            v[key] = _finite(v.get(key), key, where, low=-360.0, high=360.0)
        v["range_deg"] = _finite(v.get("range_deg"), "range_deg", where, low=-720.0, high=720.0)
        v["reference_deg"] = _finite(v.get("reference_deg"), "reference_deg", where, optional=True, low=-360.0,
                                     high=360.0)
        v["duration_s"] = _finite(v.get("duration_s"), "duration_s", where, optional=True, low=0.0, high=86400.0)
    else:
        reps = _finite(v.get("repetitions"), "repetitions", where, low=0.0, high=1e6)
        if reps != int(reps):
            raise DatabaseError(f"{where}: repetitions {v.get('repetitions')!r} is not a whole number")
        v["repetitions"] = int(reps)
        v["duration_s"] = _finite(v.get("duration_s"), "duration_s", where, low=0.0, high=86400.0)
        v["score"] = _finite(v.get("score"), "score", where, optional=True, low=-1e9, high=1e9)
        if not str(v.get("game") or "").strip():
            raise DatabaseError(f"{where}: a game result has no game name")
    return v


# --------------------------------------------------------------------------------- database
class Database:
    """A rehab database, open and migrated. Use as a context manager or call :meth:`close`.

    Args:
        path: the SQLite file (created 0600, with its folder 0700, if missing), or a PostgreSQL
            server's ``postgresql://`` URL (:mod:`game.db.location`; ``None``: ``$REHAB_DB`` or
            the user's data folder). Both hold the same schema, migrated the same way.
        check_integrity: run SQLite's full ``integrity_check`` first (seconds on a large file: at
            a command's start, before a backup or an import; not on every open).
        busy_timeout_s: how long a statement waits for another program's lock.
        store_pending: store the results kept in pending files while the database was locked
            (:mod:`game.db.pending`); anything left is logged, never raised.

    Raises:
        DatabaseLocked: another program holds the database locked (one line).
        DatabaseUnreachable: the database server does not answer.
        DatabaseError: the file is damaged, not a rehab database, read-only, or from a newer rehab.
    """

    def __init__(self, path: str | Path | ServerUrl | None, *, check_integrity: bool = False,
                 busy_timeout_s: float = BUSY_TIMEOUT_S, store_pending: bool = True):
        self.path = db_location(path)
        self._conn = None
        if isinstance(self.path, ServerUrl):
            # lazy: game.db.server loads psycopg (an optional extra): only for a server URL
            from game.db.server import POSTGRESQL, connect

            self._dialect = POSTGRESQL
            self._conn = connect(self.path, busy_timeout_s=busy_timeout_s)
            self._prepare_server()
        else:
            self._dialect = SQLITE
            self._conn = _open_checked(self.path, check_integrity=check_integrity, busy_timeout_s=busy_timeout_s)
        if store_pending:
            self.store_pending_results()

    @_guarded
    def _prepare_server(self) -> None:
        try:
            self.conn.execute(self._dialect.read_snapshot)   # one moment, though another station migrates
            try:
                version = _checked_version(self.conn, self._dialect, self.path)
            finally:
                self.conn.execute("ROLLBACK")
            _migrate(self.conn, self._dialect, version, self.path)
        except BaseException:
            self.close()
            raise

    @property
    def dialect(self) -> Dialect:
        """The back-end's differences (:mod:`game.db.dialect`)."""
        return self._dialect

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
    @_guarded
    def schema_version(self) -> int:
        return _version(self.conn, self.path)

    def _write(self, sql: str, params: Sequence[Any] = ()) -> sqlite3.Cursor:
        """One statement in its own durable transaction."""
        with self._transaction():
            return self.conn.execute(sql, params)

    def _transaction(self) -> "_transaction":
        return _transaction(self.conn, self._dialect.begin)

    # ------------------------------------------------------------------ patients
    @_guarded
    def add_patient(self, patient_id: str, note: str = "") -> None:
        """Add a patient under a pseudonymous ID (letters, digits, ``_.-``; up to 32 characters)."""
        if not _PATIENT_ID.match(patient_id or ""):
            raise DatabaseError(f"patient ID {patient_id!r}: use a pseudonym of letters, digits, '_', '.', '-' "
                                f"(up to 32 characters, e.g. P001), never a name")
        cur = self._write("INSERT INTO patients (id, created_utc, note) VALUES (?, ?, ?) ON CONFLICT DO NOTHING",
                          (patient_id, utc_now(), note))
        if cur.rowcount != 1:   # another station may have added it a moment ago: the unique key decides
            raise DatabaseError(f"patient {patient_id} already exists in {self.path}")

    @_guarded
    def has_patient(self, patient_id: str) -> bool:
        return self.conn.execute("SELECT 1 FROM patients WHERE id = ?", (patient_id,)).fetchone() is not None

    def require_patient(self, patient_id: str) -> None:
        """Raise a one-line DatabaseError if the patient does not exist."""
        if not patient_id:
            raise DatabaseError("give a patient ID (see rehab patients)")
        if not self.has_patient(patient_id):
            raise DatabaseError(f"no patient {patient_id!r} in {self.path}: add it with rehab patients --add {patient_id}")

    @_guarded
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
    @_guarded
    def start_session(self, patient_id: str, kind: str, source: str = "", note: str = "",
                      started_utc: str | None = None) -> int:
        """Open a session (``kind`` ``rom`` or ``exercise``); returns its id."""
        self.require_patient(patient_id)
        started_utc = started_utc or utc_now()
        check_session_fields(kind, started_utc, None, f"session of {patient_id}")
        uid = uuid.uuid4().hex
        with self._transaction():
            self.conn.execute("INSERT INTO sessions (patient_id, started_utc, kind, note, uid, source) "
                              "VALUES (?, ?, ?, ?, ?, ?)", (patient_id, started_utc, kind, note, uid, source))
            return int(self.conn.execute("SELECT id FROM sessions WHERE uid = ?", (uid,)).fetchone()[0])

    @_guarded
    def end_session(self, session_id: int, ended_utc: str | None = None) -> None:
        self._write("UPDATE sessions SET ended_utc = ? WHERE id = ?", (ended_utc or utc_now(), session_id))

    @_guarded
    def end_session_uid(self, session_uid: str, ended_utc: str | None = None) -> None:
        """Set the end time of the session with this uid (no-op if it was never stored)."""
        self._write("UPDATE sessions SET ended_utc = ? WHERE uid = ?", (ended_utc or utc_now(), session_uid))

    @_guarded
    def sessions(self, patient_id: str) -> list[SessionRow]:
        rows = self.conn.execute(
            "SELECT uid, patient_id, started_utc, coalesce(ended_utc, ''), kind, source, note FROM sessions "
            "WHERE patient_id = ? ORDER BY started_utc, id", (patient_id,)).fetchall()
        return [SessionRow(*r) for r in rows]

    # ------------------------------------------------------------------ results
    def store_pending_results(self) -> int:
        """Store every result kept pending for this database (:mod:`game.db.pending`) and remove its
        file; returns how many were stored.

        A file that cannot be stored now stays (logged); one that is not a pending result is renamed
        ``.bad`` and logged, never deleted.
        """
        folder = pending_dir(self.path)
        if not folder.is_dir():
            return 0
        n = 0
        for path in sorted(folder.glob("*.json")):
            try:
                record = ResultRecord.from_json(path.read_text(encoding="utf-8"), str(path))
            except FileNotFoundError:
                continue   # another process of this station has just sent it
            except (OSError, UnicodeDecodeError, DatabaseError) as exc:
                log.warning("pending result %s cannot be read (%s): kept as %s.bad", path, exc, path.name)
                with contextlib.suppress(OSError):
                    path.rename(path.with_suffix(".json.bad"))
                continue
            try:
                self.store_result(record)
            except DatabaseError as exc:
                log.warning("pending result %s not stored yet: %s", path.name, exc)
                if isinstance(exc, (DatabaseLocked, DatabaseUnreachable)):
                    break
                continue
            path.unlink(missing_ok=True)
            n += 1
            log.info("stored pending result %s in %s", record.uid, self.path)
        return n

    @_guarded
    def store_result(self, record: ResultRecord) -> str:
        """Store a result with its session in one durable transaction; returns its uid once on disk.

        The session is created by its first result and its end time follows its latest result, so
        a kill never leaves a session without its result or its end. Storing a record again adds
        nothing (uids).

        Raises:
            DatabaseLocked: another program holds the database (see :mod:`game.db.pending`).
            ResultRejected: an unknown patient or a value the rest cannot use.
            DatabaseError: the file cannot be written (read-only, full, damaged).
        """
        try:
            record.check(f"result {record.uid} of {record.patient_id}")
            values = check_result_values(record.table, record.values, f"result of {record.patient_id}")
        except DatabaseError as exc:
            raise ResultRejected(str(exc)) from None
        columns = RESULT_COLUMNS[record.table]
        c = self.conn
        with self._transaction():
            if not self.has_patient(record.patient_id):
                raise ResultRejected(f"no patient {record.patient_id!r} in {self.path}: add it with rehab patients "
                                     f"--add {record.patient_id}")
            c.execute("INSERT INTO sessions (uid, patient_id, started_utc, ended_utc, kind, source, note) "
                      "VALUES (?, ?, ?, ?, ?, ?, '') ON CONFLICT DO NOTHING",
                      (record.session_uid, record.patient_id, record.session_started_utc, values["recorded_utc"],
                       record.session_kind, record.session_source))
            sid = c.execute("SELECT id FROM sessions WHERE uid = ?", (record.session_uid,)).fetchone()[0]
            c.execute(insert_result_sql(record.table), (sid, *(values[k] for k in columns)))
            c.execute("UPDATE sessions SET ended_utc = ? WHERE id = ? AND (ended_utc IS NULL OR ended_utc < ?)",
                      (values["recorded_utc"], sid, values["recorded_utc"]))
            if record.accepted_by:
                what = (f"{values['test']} {values['side']} {values['value_deg']:.1f} deg"
                        if record.table == "rom_results" else f"{values['game']} {values['repetitions']} repetitions")
                c.execute("INSERT INTO audit (uid, at_utc, account, action, patient_id, what) "
                          "VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT DO NOTHING", (f"accept-{record.uid}", values["recorded_utc"], record.accepted_by,
                                                     "accept", record.patient_id, f"{what} (result {record.uid})"))
        return record.uid

    def add_rom_result(self, session_id: int, result: Any, recorded_utc: str | None = None) -> str:
        """Store an accepted :class:`game.rom.session.RomResult` in an open session; returns its uid once durable."""
        record = rom_record("", result, recorded_utc=recorded_utc)
        return self._add_to_session(session_id, record)

    def add_exercise_result(self, session_id: int, game: str, repetitions: int, duration_s: float,
                            score: float | None = None, details: str = "", recorded_utc: str | None = None) -> str:
        """Store one game's result (repetitions, duration, score); returns its uid once it is durable."""
        record = exercise_record("", game, repetitions, duration_s, score, details, recorded_utc=recorded_utc)
        return self._add_to_session(session_id, record)

    @_guarded
    def _add_to_session(self, session_id: int, record: ResultRecord) -> str:
        values = check_result_values(record.table, record.values, f"result of session {session_id}")
        columns = RESULT_COLUMNS[record.table]
        self._write(f"INSERT INTO {record.table} (session_id, {', '.join(columns)}) "
                    f"VALUES (?, {', '.join('?' * len(columns))})", (session_id, *(values[k] for k in columns)))
        return record.uid

    @_guarded
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

    @_guarded
    def exercise_results(self, patient_id: str | None = None) -> list[ExerciseRow]:
        where, params = ("WHERE s.patient_id = ?", (patient_id,)) if patient_id else ("", ())
        rows = self.conn.execute(f"""
            SELECT e.uid, s.uid, s.patient_id, s.started_utc, e.game, e.repetitions, e.duration_s, e.score, e.details,
                   e.recorded_utc
            FROM exercise_results e JOIN sessions s ON e.session_id = s.id {where}
            ORDER BY s.started_utc, e.recorded_utc, e.id""", params).fetchall()
        return [ExerciseRow(*r) for r in rows]

    # ------------------------------------------------------------------ game limits
    @_guarded
    def set_game_limits(self, patient_id: str, game: str, limits_json: str, updated_utc: str | None = None) -> None:
        """Store the therapist's limits of one game for a patient (replacing the previous ones)."""
        self.require_patient(patient_id)
        self._write("INSERT INTO game_limits (patient_id, game, limits, updated_utc) VALUES (?, ?, ?, ?) "
                    "ON CONFLICT (patient_id, game) DO UPDATE SET limits = excluded.limits, "
                    "updated_utc = excluded.updated_utc", (patient_id, game, limits_json, updated_utc or utc_now()))

    @_guarded
    def game_limits(self, patient_id: str) -> dict[str, str]:
        """The therapist's stored limits of each game for a patient: game -> JSON text."""
        rows = self.conn.execute("SELECT game, limits FROM game_limits WHERE patient_id = ? ORDER BY game",
                                 (patient_id,)).fetchall()
        return {game: text for game, text in rows}

    # ------------------------------------------------------------------ backup
    @_guarded
    def backup(self, dest: str | Path) -> Path:
        """Copy a consistent snapshot to the SQLite file ``dest``; refuses to overwrite.

        SQLite uses its online backup API; a server's database is copied row by row in one
        repeatable-read transaction (:func:`game.db.copy.copy_database`) into a new SQLite file.
        The copy is written to a temporary file beside ``dest``, checked, flushed to disk and then
        renamed: a killed backup never leaves a file under ``dest``.
        """
        dest = Path(dest)
        if dest.exists():
            raise DatabaseError(f"{dest} exists: give a new file name for the backup")
        make_private_dir(dest.parent)
        try:
            tmp = temp_path_beside(dest)
        except OSError as exc:
            raise DatabaseError(f"{dest}: cannot write the backup ({exc.strerror or exc}): choose a folder you can "
                                f"write") from None
        try:
            if self._dialect is not SQLITE:
                self._backup_server(tmp)
            target = sqlite3.connect(tmp)
            try:
                if self._dialect is SQLITE:
                    self.conn.backup(target)
                target.execute("PRAGMA journal_mode = DELETE")   # a backup is one self-contained file
                check = target.execute("PRAGMA integrity_check").fetchone()[0]
            finally:
                target.close()
            if check != "ok":
                raise DatabaseError(f"{dest}: the copy failed its integrity check ({check}): try again")
            commit_temp(tmp, dest, overwrite=False)
        except FileExistsError:
            raise DatabaseError(f"{dest} exists: give a new file name for the backup") from None
        except OSError as exc:
            raise DatabaseError(f"{dest}: cannot write the backup ({exc.strerror or exc}): check the folder and "
                                f"the free space") from None
        finally:
            if tmp.exists():
                tmp.unlink()
        return dest

    def _backup_server(self, tmp: Path) -> None:
        tmp.unlink()
        self.conn.execute(self._dialect.read_snapshot)   # one consistent snapshot
        try:
            with Database(tmp, store_pending=False) as target:
                copy_database(self, target)
        finally:
            self.conn.execute("ROLLBACK")

    # ------------------------------------------------------------------ CSV
    @_guarded
    def export_csv(self, out_dir: str | Path, patient_id: str | None = None) -> dict[str, int]:
        """Write ``patients.csv``, ``sessions.csv``, ``rom_results.csv``, ``exercise_results.csv``, ``game_limits.csv``.

        ``patient_id`` None exports everyone; an empty ID is an error (never "everyone" by mistake).
        The folder is created 0700 and the files 0600, each written whole or not at all.
        """
        out = Path(out_dir)
        if patient_id is not None:
            self.require_patient(patient_id)
        if out.exists() and not out.is_dir():
            raise DatabaseError(f"{out} is a file: give a folder for the CSV files")
        make_private_dir(out)
        pats = [p for p in self.patients() if patient_id is None or p.id == patient_id]
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
            "game_limits": _write_csv(out / "game_limits.csv", LIMIT_COLUMNS, [
                row for p in pats for row in self.conn.execute(
                    f"SELECT {', '.join(LIMIT_COLUMNS)} FROM game_limits WHERE patient_id = ? ORDER BY game", (p.id,))]),
        }
        return counts

    @_guarded
    def import_csv(self, in_dir: str | Path) -> dict[str, int]:
        """Read a folder written by :meth:`export_csv`; rows already present (same id/uid) are skipped.

        Every value is checked (finite numbers in range, known tests and sides, UTC times) and
        everything is imported in one transaction: a bad row imports nothing and is named in one
        line. Returns new rows per table.
        """
        src = Path(in_dir)
        if not src.is_dir():
            raise DatabaseError(f"{src}: no such folder; import a folder written by rehab export")
        pats = _read_csv(src / "patients.csv", ("id", "created_utc", "note"))
        sess = _read_csv(src / "sessions.csv", [f.name for f in fields(SessionRow)])
        roms = _read_csv(src / "rom_results.csv", [f.name for f in fields(RomRow)])
        exes = _read_csv(src / "exercise_results.csv", [f.name for f in fields(ExerciseRow)])
        # exports of schema 2 have no game limits
        lims = _read_csv(src / "game_limits.csv", LIMIT_COLUMNS) if (src / "game_limits.csv").is_file() else []
        added = {"patients": 0, "sessions": 0, "rom_results": 0, "exercise_results": 0, "game_limits": 0}
        c = self.conn
        with self._transaction():
            path = src / "patients.csv"
            for line, p in pats:
                if not _PATIENT_ID.match(p["id"]):
                    raise DatabaseError(f"{path} line {line}: patient ID {p['id']!r} is not a pseudonymous ID")
                _utc_text(p["created_utc"], "created_utc", f"{path} line {line}")
                added["patients"] += c.execute("INSERT INTO patients (id, created_utc, note) VALUES (?, ?, ?) "
                                               "ON CONFLICT DO NOTHING",
                                               (p["id"], p["created_utc"], p["note"])).rowcount
            path = src / "sessions.csv"
            for line, s in sess:
                where = f"{path} line {line}"
                if c.execute("SELECT 1 FROM patients WHERE id = ?", (s["patient_id"],)).fetchone() is None:
                    raise DatabaseError(f"{where}: patient {s['patient_id']!r} is not in patients.csv")
                if not s["uid"].strip():
                    raise DatabaseError(f"{where}: the session has no uid")
                check_session_fields(s["kind"], s["started_utc"], s["ended_utc"], where)
                added["sessions"] += c.execute(
                    "INSERT INTO sessions (uid, patient_id, started_utc, ended_utc, kind, source, note) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?) ON CONFLICT DO NOTHING",
                    (s["uid"], s["patient_id"], s["started_utc"], s["ended_utc"] or None, s["kind"], s["source"],
                     s["note"])).rowcount
            for table, rows in (("rom_results", roms), ("exercise_results", exes)):
                path = src / f"{table}.csv"
                columns = RESULT_COLUMNS[table]
                for line, r in rows:
                    where = f"{path} line {line}"
                    sid = _session_id(c, r["session_uid"], path, line)
                    values = check_result_values(table, {k: r[k] for k in columns}, where)
                    added[table] += c.execute(
                        insert_result_sql(table), (sid, *(values[k] for k in columns))).rowcount
            path = src / "game_limits.csv"
            for line, g in lims:
                where = f"{path} line {line}"
                if c.execute("SELECT 1 FROM patients WHERE id = ?", (g["patient_id"],)).fetchone() is None:
                    raise DatabaseError(f"{where}: patient {g['patient_id']!r} is not in patients.csv")
                try:
                    if not isinstance(json.loads(g["limits"], parse_constant=_no_constant), dict):
                        raise ValueError("not a JSON object")
                except ValueError as exc:
                    raise DatabaseError(f"{where}: limits are not valid JSON ({exc})") from None
                _utc_text(g["updated_utc"], "updated_utc", where)
                added["game_limits"] += c.execute(
                    "INSERT INTO game_limits (patient_id, game, limits, updated_utc) VALUES (?, ?, ?, ?) "
                    "ON CONFLICT DO NOTHING",
                    tuple(g[k] for k in LIMIT_COLUMNS)).rowcount
        return added



def _no_constant(name: str):
    raise ValueError(f"{name} is not a number")


# --------------------------------------------------------------------------------- helpers
class _transaction:
    """The dialect's ``begin`` (SQLite: ``BEGIN IMMEDIATE``) ... ``COMMIT`` (``ROLLBACK`` on error), autocommit connection."""

    def __init__(self, conn, begin: str = "BEGIN IMMEDIATE"):
        self.conn = conn
        self.begin = begin

    def __enter__(self):
        self.conn.execute(self.begin)
        return self.conn

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            try:
                self.conn.execute("COMMIT")
                return False
            except Exception:
                self._rollback()
                raise
        self._rollback()
        return False

    def _rollback(self) -> None:
        try:
            if self.conn.in_transaction:
                self.conn.execute("ROLLBACK")
        except Exception:   # a broken connection: the server rolls back; the first error is the one to tell
            pass


def _version(conn: sqlite3.Connection, path: Path) -> int:
    row = conn.execute("SELECT max(version) FROM schema_version").fetchone()
    if not row or row[0] is None:
        return 0
    if isinstance(row[0], float) or not isinstance(row[0], int):
        raise damaged(path, f"schema_version {row[0]!r} is not a whole number")
    return row[0]


def _create_private_file(path: Path) -> None:
    """Create the empty database file 0600 (and its folder 0700) before SQLite does, whatever the umask."""
    make_private_dir(path.parent)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, FILE_MODE)
        os.close(fd)
        os.chmod(path, FILE_MODE)
    except FileExistsError:
        pass
    except OSError as exc:
        raise DatabaseError(f"{path}: cannot create the database ({exc.strerror or exc}): choose a folder you can "
                            f"write with --db") from None


def _open_checked(path: Path, *, check_integrity: bool, busy_timeout_s: float) -> sqlite3.Connection:
    """Open (or create) the database; check it before anything is written; migrate it."""
    existed = path.exists()
    if existed:
        if not path.is_file():
            raise DatabaseError(f"{path} is not a file: give a database file path with --db")
        try:
            with open(path, "rb") as fh:
                head = fh.read(len(_SQLITE_HEADER))
        except OSError as exc:
            raise DatabaseError(f"{path}: cannot read the database ({exc.strerror or exc}): check its "
                                f"permissions") from None
        if head and head != _SQLITE_HEADER:
            raise damaged(path, "no SQLite header")
        for p in (path, Path(f"{path}-wal"), Path(f"{path}-shm")):
            make_private(p)
        if path.parent.absolute() == default_db_path().parent.absolute():
            make_private(path.parent, DIR_MODE)   # rehab's own data folder, maybe made 0755 by an older rehab
    else:
        _create_private_file(path)
    try:
        conn = sqlite3.connect(path, isolation_level=None, timeout=busy_timeout_s)
    except sqlite3.Error as exc:
        raise sqlite_error(path, exc) from None
    try:
        conn.execute(f"PRAGMA busy_timeout = {int(busy_timeout_s * 1000)}")
        if check_integrity and _table_names(conn, SQLITE):
            problems = [r[0] for r in conn.execute("PRAGMA integrity_check").fetchall()]
            if problems != ["ok"]:
                raise damaged(path, f"integrity check: {problems[0]}")
        version = _checked_version(conn, SQLITE, path)
        conn.execute("PRAGMA journal_mode = WAL")
        conn.execute("PRAGMA synchronous = FULL")  # a commit that returned survives a crash or power cut
        conn.execute("PRAGMA foreign_keys = ON")
        _migrate(conn, SQLITE, version, path)
    except sqlite3.Error as exc:
        conn.close()
        raise sqlite_error(path, exc) from None
    except UnicodeDecodeError:
        conn.close()
        raise damaged(path, "text that is not UTF-8") from None
    except BaseException:
        conn.close()
        raise
    return conn


def _table_names(conn, dialect: Dialect) -> set[str]:
    return {r[0] for r in conn.execute(dialect.tables_sql).fetchall()}


def _checked_version(conn, dialect: Dialect, path) -> int:
    """The schema version (0: an empty database), after checking the tables it should have."""
    tables = _table_names(conn, dialect)
    if not tables:
        return 0
    if "schema_version" not in tables:
        raise damaged(path, "no schema_version table")
    version = _version(conn, path)
    if version > LATEST_VERSION:
        raise DatabaseError(f"{path} has schema version {version}, newer than this rehab knows "
                            f"({LATEST_VERSION}): update rehab")
    missing = [t for t in _TABLES_BY_VERSION.get(version, _TABLES) if t not in tables]
    if version < 1 or missing:
        raise damaged(path, f"missing table {missing[0]}" if missing else f"schema version {version}")
    return version


def _migrate(conn, dialect: Dialect, version: int, path) -> None:
    """Bring the schema from ``version`` to :data:`LATEST_VERSION`, one transaction per step.

    Each step re-reads the version inside its transaction (after the dialect's migration lock), so
    two stations opening a new database at once apply every step exactly once.
    """
    for target in range(version + 1, LATEST_VERSION + 1):
        with _transaction(conn, dialect.begin):
            if dialect.migration_lock:
                conn.execute(dialect.migration_lock)
            now = _version(conn, path) if "schema_version" in _table_names(conn, dialect) else 0
            if now >= target:
                continue
            log.info("migrating %s from schema version %d to %d", path, now, target)
            script = schema_v1_sql() if target == 1 else STEPS[target]
            for statement in _statements(dialect.translate(script)):
                conn.execute(statement)
            if target > 1:
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
    try:
        with open_private(path, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            for row in rows:
                w.writerow(["" if v is None else v for v in row])
                n += 1
    except OSError as exc:
        raise DatabaseError(f"{path}: cannot write ({exc.strerror or exc}): choose a folder you can write") from None
    return n


def _read_csv(path: Path, need: Sequence[str]) -> list[tuple[int, dict[str, str]]]:
    if not path.is_file():
        raise DatabaseError(f"{path}: missing; import a folder written by rehab export")
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            missing = [k for k in need if k not in (reader.fieldnames or ())]
            if missing:
                raise DatabaseError(f"{path}: missing column(s) {', '.join(missing)}; import a folder written by "
                                    f"rehab export")
            rows = []
            for i, row in enumerate(reader):
                if None in row or any(row.get(k) is None for k in need):
                    raise DatabaseError(f"{path} line {reader.line_num}: {'too many' if None in row else 'too few'} "
                                        f"values for the header")
                rows.append((i + 2, row))
            return rows
    except UnicodeDecodeError as exc:
        raise DatabaseError(f"{path}: not UTF-8 text (byte {exc.start}): save it as UTF-8") from None
    except csv.Error as exc:
        raise DatabaseError(f"{path}: not a CSV file ({exc})") from None
    except OSError as exc:
        raise DatabaseError(f"{path}: cannot read ({exc.strerror or exc})") from None


def _session_id(conn: sqlite3.Connection, uid: str, path: Path, line: int) -> int:
    row = conn.execute("SELECT id FROM sessions WHERE uid = ?", (uid,)).fetchone()
    if row is None:
        raise DatabaseError(f"{path} line {line}: session {uid!r} is not in sessions.csv")
    return int(row[0])
