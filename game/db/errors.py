"""The database's one-line errors (each a :class:`calibration.errors.RehabError`), and the one line
for an SQLite failure; shared by the storage layer and its back-ends (``dialect``, ``server``)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

from calibration.errors import RehabError


class DatabaseError(RehabError):
    """The database file cannot be used (damaged, not a rehab database, newer schema) or bad input."""


class DatabaseLocked(DatabaseError):
    """Another program holds the database (a write transaction or an exclusive lock) past the wait."""


class DatabaseUnreachable(DatabaseError):
    """The database server does not answer (or the connection broke): results wait on the station."""


class ResultRejected(DatabaseError):
    """A result that cannot be stored in any database: a value out of range, an unknown patient."""


def damaged(path: Path, detail: str) -> DatabaseError:
    """The one-line error for a file that is not a rehab database or is damaged."""
    detail = " ".join(str(detail).split())   # SQLite's integrity report spans lines
    return DatabaseError(f"{path} is not a rehab database or is damaged ({detail}): restore a backup "
                         f"(rehab backup) or move it away")


def sqlite_error(path: Path, exc: sqlite3.Error) -> DatabaseError:
    """The one-line error for an SQLite failure: locked, read-only, unopenable, full disk or damaged."""
    code = (getattr(exc, "sqlite_errorcode", None) or 0) & 0xFF
    text = str(exc)
    if code in (5, 6) or "locked" in text or "busy" in text:   # SQLITE_BUSY, SQLITE_LOCKED
        return DatabaseLocked(f"{path} is in use by another program (a database browser or another rehab) that "
                              f"holds it locked: close that program and try again")
    if code == 8 or "readonly" in text or "read-only" in text:   # SQLITE_READONLY
        return DatabaseError(f"{path} is read-only ({text}): make the file and its folder writable "
                             f"(chmod u+w), or copy it to a folder you can write")
    if code == 14 or "unable to open" in text:   # SQLITE_CANTOPEN (also the -wal/-shm beside it)
        return DatabaseError(f"{path}: cannot open the database ({text}): check the path and that you can write "
                             f"its folder")
    if code == 13 or "full" in text:   # SQLITE_FULL
        return DatabaseError(f"{path}: the disk is full ({text}): free some space and try again")
    return damaged(path, text)
