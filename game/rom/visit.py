"""One patient's ROM tests in one sitting: reading the previous results and storing the accepted ones.

The ROM test scenes (:mod:`game.scenes.rom_test`) show and measure; every database access of the
visit is here (one database session per visit, each accepted result stored durably), so that a
scene never writes to the database itself.
"""

from __future__ import annotations

import logging
import uuid
from dataclasses import replace
from pathlib import Path

from calibration.errors import RehabError
from game.db import Database, rom_record
from game.db.location import db_location
from game.db.pending import store_durably
from game.rom.session import RomResult

log = logging.getLogger(__name__)


class RomVisit:
    """One patient's ROM tests in this sitting: the database, the standard, one database session.

    The database session (kind ``rom``) is stored with the first accepted result, in the same
    transaction, and its end time follows each result; :meth:`close` sets the visit's end. A
    database locked by another program does not lose a result: it waits briefly and then keeps it
    in a pending file that the next open stores (:func:`game.db.pending.store_durably`).

    Args:
        db_path: the database file.
        patient_id: a patient that exists in it.
        standard: ``jarm`` or ``aaos``: every result of the visit is labelled with it.
        source: what measured the results (stored with the session), e.g. ``sim`` or ``cameras``.
        wait_s: how long a locked database is waited for before a result is kept aside.
        accepted_by: the signed-in therapist account ("" = none): audited with each result.
    """

    def __init__(self, db_path: Path, patient_id: str, standard: str = "jarm", source: str = "sim",
                 wait_s: float = 3.0, accepted_by: str = "") -> None:
        self.db_path = db_location(db_path)
        self.patient_id = patient_id
        self.standard = standard
        self.source = source
        self.wait_s = wait_s
        self.accepted_by = accepted_by
        self.session_uid = uuid.uuid4().hex
        self.session_started_utc: str | None = None
        self.stored: list[str] = []
        self.last_outcome = None

    def previous(self, test: str, side: str) -> list:
        """Stored results of this patient for ``test`` on ``side``, oldest first (:class:`game.db.RomRow`)."""
        with Database(self.db_path) as db:
            return [r for r in db.rom_results(self.patient_id) if r.test == test and r.side == side]

    def store(self, result: RomResult, source: str | None = None) -> str:
        """Store an accepted result; returns its uid once it is on disk (in the database or its pending file).

        :attr:`last_outcome` says which (:class:`game.db.pending.StoreOutcome`).
        """
        record = replace(rom_record(self.patient_id, result, session_uid=self.session_uid, source=source or self.source,
                                    started_utc=self.session_started_utc), accepted_by=self.accepted_by)
        self.session_started_utc = record.session_started_utc
        self.last_outcome = store_durably(self.db_path, record, wait_s=self.wait_s)
        self.stored.append(record.uid)
        log.info("%s (%s %s %.1f deg) for %s", self.last_outcome.line(self.db_path), result.test, result.side,
                 result.max_deg, self.patient_id)
        return record.uid

    def close(self) -> None:
        """Set the session's end to now (if a result was stored; it already ends at its last result)."""
        if self.session_started_utc is not None:
            try:
                with Database(self.db_path, busy_timeout_s=self.wait_s) as db:
                    db.end_session_uid(self.session_uid)
            except RehabError as exc:
                log.warning("the ROM session's end time stays at its last result: %s", exc)
            self.session_started_utc = None
