"""Never lose an accepted result: wait for a locked database, else keep the result in a pending file.

Another program (a database browser, a second ``rehab`` importing) may hold the database locked
for longer than a statement waits, or the clinic's database server may be unreachable (network,
restart). :func:`store_durably` then tells the user (``notify``), keeps trying a lock for ``wait_s``
seconds, and finally writes the result to a pending file on this station (beside an SQLite file:
``rehab.sqlite3.pending/<uid>.json``; for a server: ``<data folder>/pending/<host_port_db>/``; 0600
in a 0700 folder, written through a temporary file and fsync). Every later open of the database
(:class:`game.db.Database`) stores the pending results and removes their files; storing is keyed
by the uids the station generated, so a kill between storing and removing the file, or two
processes sending the same queue, add nothing twice. A result is only reported stored once it is
in the database or in its file.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from calibration.errors import RehabError
from game.db.database import (BUSY_TIMEOUT_S, Database, DatabaseError, DatabaseLocked, ResultRecord,
                              ResultRejected)
from game.db.location import db_location, pending_dir
from game.db.private import make_private_dir, open_private

log = logging.getLogger(__name__)

#: How long :func:`store_durably` keeps trying a locked database before keeping the result aside.
WAIT_S = 30.0


@dataclass(frozen=True, slots=True)
class StoreOutcome:
    """Where an accepted result went.

    Attributes:
        uid: the result's uid.
        pending_file: None when it is in the database; else the file that holds it until the
            database can be written (the next open stores it).
        reason: why it is pending (one line), "" when stored.
    """

    uid: str
    pending_file: Path | None = None
    reason: str = ""

    @property
    def stored(self) -> bool:
        return self.pending_file is None

    def line(self, db_path: Path) -> str:
        """One line for the user: stored, or kept and when it will be stored."""
        if self.stored:
            return f"stored result {self.uid} in {db_path}"
        return (f"kept result {self.uid} in {self.pending_file} ({self.reason}); it is stored in {db_path} the next "
                f"time rehab opens it")


def keep_pending(db_path: str | Path, record: ResultRecord) -> Path:
    """Write ``record`` to its pending file (whole, flushed to disk, 0600); returns the file.

    Raises:
        RehabError: the file cannot be written either (the message holds the result's values).
    """
    folder = pending_dir(db_path)
    path = folder / f"{record.uid}.json"
    try:
        make_private_dir(folder)
        with open_private(path, "w", encoding="utf-8") as fh:
            fh.write(record.to_json())
    except (OSError, RehabError) as exc:
        raise RehabError(f"the result could neither be stored in {db_path} nor kept in {folder} ({exc}): note it "
                         f"down: {record.table} {record.values}") from None
    return path


def store_durably(db_path: str | Path, record: ResultRecord, *, wait_s: float = WAIT_S,
                  notify: Callable[[str], None] | None = None,
                  clock: Callable[[], float] = time.monotonic) -> StoreOutcome:
    """Store ``record`` in the database, waiting out a lock for ``wait_s``, else keep it in a pending file.

    Args:
        db_path: the database file or server URL.
        record: the result (:func:`game.db.database.rom_record`, :func:`~game.db.database.exercise_record`).
        wait_s: how long to keep trying a locked database.
        notify: called with one line when the wait begins (e.g. print it, or show it on screen).
        clock: seconds (tests).

    Returns:
        Where the result is: in the database, or in its pending file (never lost).

    Raises:
        RehabError: a bad result (unknown patient, a value out of range), or neither the database
            nor the pending folder can be written.
    """
    db_path = db_location(db_path)
    start = clock()
    told = False
    while True:
        left = wait_s - (clock() - start)
        # the first try waits a second at most, so that a long wait is announced before it begins
        timeout_s = max(0.05, min(1.0 if not told else BUSY_TIMEOUT_S, left))
        try:
            with Database(db_path, busy_timeout_s=timeout_s) as db:
                db.store_result(record)
            return StoreOutcome(record.uid)
        except ResultRejected:
            raise   # the result itself is wrong: keeping it would not help
        except DatabaseLocked as exc:
            reason = "the database is locked by another program"
            if not told and notify is not None:
                notify(f"{db_path} is in use by another program: waiting up to {wait_s:.0f} s to store the result")
            told = True
            log.info("waiting for %s: %s", db_path, exc)
            if clock() - start >= wait_s:
                break
        except DatabaseError as exc:
            reason = str(exc)
            break
    path = keep_pending(db_path, record)
    outcome = StoreOutcome(record.uid, path, reason)
    log.warning("%s", outcome.line(db_path))
    if notify is not None:
        notify(outcome.line(db_path))
    return outcome
