"""The rehab database (SQLite embedded, or a clinic's PostgreSQL server): patients, sessions, results.

See :mod:`game.db.database` and docs/DATABASE.md.
"""

from game.db.database import (
    Database,
    DatabaseError,
    DatabaseLocked,
    DatabaseUnreachable,
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
from game.db.location import ENV_VAR, ServerUrl, db_location, local_folder
from game.db.migrations import LATEST_VERSION

__all__ = ["Database", "DatabaseError", "DatabaseLocked", "DatabaseUnreachable", "ENV_VAR", "ServerUrl", "db_location",
           "local_folder", "ExerciseRow", "PatientRow", "ResultRecord", "ResultRejected",
           "RomRow", "SessionRow", "default_db_path", "exercise_record", "rom_record", "LATEST_VERSION"]
