"""The rehab database (SQLite, standard library only): patients, sessions, ROM and exercise results.

See :mod:`game.db.database` and docs/DATABASE.md.
"""

from game.db.database import (
    Database,
    DatabaseError,
    DatabaseLocked,
    ExerciseRow,
    PatientRow,
    ResultRecord,
    ResultRejected,
    RomRow,
    SessionRow,
    default_db_path,
    exercise_record,
    rom_record,
)
from game.db.migrations import LATEST_VERSION

__all__ = ["Database", "DatabaseError", "DatabaseLocked", "ExerciseRow", "PatientRow", "ResultRecord", "ResultRejected",
           "RomRow", "SessionRow", "default_db_path", "exercise_record", "rom_record", "LATEST_VERSION"]
