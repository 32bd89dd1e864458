"""The rehab database (SQLite, standard library only): patients, sessions, ROM and exercise results.

See :mod:`game.db.database` and docs/DATABASE.md.
"""

from game.db.database import (
    Database,
    DatabaseError,
    ExerciseRow,
    PatientRow,
    RomRow,
    SessionRow,
    default_db_path,
)
from game.db.migrations import LATEST_VERSION

__all__ = ["Database", "DatabaseError", "ExerciseRow", "PatientRow", "RomRow", "SessionRow", "default_db_path",
           "LATEST_VERSION"]
