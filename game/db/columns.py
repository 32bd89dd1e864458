"""The columns of the results and game limits, as the database, its CSV export and the copy between
back-ends all write them (one place, so that none of them imports another for a tuple of names)."""

from __future__ import annotations

ROM_COLUMNS = ("uid", "test", "side", "angle", "mode", "position", "standard", "reference_deg", "value_deg",
               "start_deg", "range_deg", "compensation", "estimated_markers", "duration_s", "recorded_utc")
EXERCISE_COLUMNS = ("uid", "game", "repetitions", "duration_s", "score", "details", "recorded_utc")
RESULT_COLUMNS = {"rom_results": ROM_COLUMNS, "exercise_results": EXERCISE_COLUMNS}
LIMIT_COLUMNS = ("patient_id", "game", "limits", "updated_utc")


def insert_result_sql(table: str) -> str:
    """Insert a result of ``table`` (session id, then its columns); a result already there (uid) is left alone."""
    columns = RESULT_COLUMNS[table]
    return (f"INSERT INTO {table} (session_id, {', '.join(columns)}) VALUES (?, {', '.join('?' * len(columns))}) "
            f"ON CONFLICT DO NOTHING")
