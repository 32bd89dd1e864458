"""One game session's database side: the patient's measured range read, the session's log stored.

The game scene (:mod:`game.scenes.game_play`) shows and plays; every database access of a game
session is here, so that a scene never writes to the database itself.
"""

from __future__ import annotations

import logging
from pathlib import Path

from calibration.errors import RehabError
from game.db import Database, exercise_record
from game.db.database import utc_now
from game.db.location import db_location
from game.db.pending import store_durably
from game.exergames.session import GameLog, GameSession
from game.exergames.spec import GameSpec
from game.exergames.targets import RomLimits, rom_limits_from_rows

log = logging.getLogger(__name__)


class GameVisit:
    """Where a game session's patient and results live.

    Args:
        db_path: the database (:func:`game.db.location.db_location`).
        patient_id: a patient that exists in it (checked by :meth:`rom_limits`).
        source: stored with the session, e.g. ``sim`` or ``cameras``.
    """

    def __init__(self, db_path: Path, patient_id: str, source: str = "sim") -> None:
        self.db_path = db_location(db_path)
        self.patient_id = patient_id
        self.source = source
        self.stored_uid: str | None = None
        self.error = ""

    def rom_limits(self, spec: GameSpec, side: str) -> RomLimits:
        """The patient's latest stored ROM for the game (the game's defaults where none is stored)."""
        with Database(self.db_path) as db:
            db.require_patient(self.patient_id)
            rows = db.rom_results(self.patient_id)
        return rom_limits_from_rows(spec, rows, side)

    def store(self, session: GameSession) -> str | None:
        """End the session and store its log, once (later calls return the same uid); nothing for a
        session that never played. An error is kept in :attr:`error` (and logged), not raised."""
        if self.stored_uid is not None or self.error:
            return self.stored_uid
        game_log = session.finish()
        try:
            self.stored_uid = store_log(self.db_path, self.patient_id, game_log, source=self.source)
        except RehabError as exc:
            self.error = str(exc)
            log.error("game session not stored: %s", exc)
        if self.stored_uid:
            log.info("stored %s session %s for %s: %d reached, %d missed, %.0f s", game_log.game, self.stored_uid,
                     self.patient_id, game_log.reached, game_log.missed, game_log.duration_s)
        return self.stored_uid


def store_log(db_path: Path, patient_id: str, log: GameLog, source: str = "", wait_s: float = 3.0) -> str | None:
    """Store a session's log as an exercise result of a new ``exercise`` session; returns its uid.

    The session and its result are one transaction, its span on the wall clock: it ends now and
    starts the log's duration earlier; a session the automatic demo played throughout is stored
    with the source ``demo``. A database locked by another program is waited for ``wait_s``, then
    the result is kept in a pending file that the next open stores
    (:func:`game.db.pending.store_durably`): the uid is returned either way, never lost. Nothing
    is stored for a session that never started playing (no active time).
    """
    if log.active_s <= 0.0:
        return None
    if log.demo_s >= log.active_s - 1e-9:
        source = "demo"   # played by the automatic demo from start to end: not the patient's
    record = exercise_record(patient_id, log.game, log.reached, log.duration_s, log.score, log.details_json(),
                             source=source, started_utc=utc_now(ago_s=log.duration_s))
    return store_durably(db_path, record, wait_s=wait_s).uid
