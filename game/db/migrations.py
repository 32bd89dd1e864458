"""Schema versions of the rehab database and the ordered steps between them.

Version 1 is ``schema_v1.sql`` (kept verbatim). Each later version is one step of SQL applied in
one transaction together with the new ``schema_version``, so a step is either wholly applied or
not at all (SQLite DDL is transactional). A new database runs the same steps as an old one.
"""

from __future__ import annotations

from importlib import resources

#: The schema version this code writes.
LATEST_VERSION = 4


def schema_v1_sql() -> str:
    """The stored version-1 schema script."""
    return resources.files(__package__).joinpath("schema_v1.sql").read_text(encoding="utf-8")


_V2 = """
-- Stable ids for CSV export/import round trips (an import never duplicates a row).
ALTER TABLE sessions ADD COLUMN uid TEXT;
ALTER TABLE sessions ADD COLUMN ended_utc TEXT;
ALTER TABLE sessions ADD COLUMN source TEXT NOT NULL DEFAULT '';
UPDATE sessions SET uid = lower(hex(randomblob(16))) WHERE uid IS NULL;
CREATE UNIQUE INDEX sessions_uid ON sessions(uid);
CREATE INDEX sessions_patient ON sessions(patient_id, started_utc);

-- ROM results: the angle column read, the normal value shown, the range from the start, the markers
-- that were estimated (hidden) at the maximum, the recording's length.
ALTER TABLE rom_results ADD COLUMN uid TEXT;
ALTER TABLE rom_results ADD COLUMN angle TEXT NOT NULL DEFAULT '';
ALTER TABLE rom_results ADD COLUMN reference_deg REAL;
ALTER TABLE rom_results ADD COLUMN range_deg REAL;
ALTER TABLE rom_results ADD COLUMN estimated_markers TEXT NOT NULL DEFAULT '';
ALTER TABLE rom_results ADD COLUMN duration_s REAL;
UPDATE rom_results SET uid = lower(hex(randomblob(16))) WHERE uid IS NULL;
UPDATE rom_results SET range_deg = value_deg - start_deg WHERE range_deg IS NULL;
UPDATE rom_results SET angle = side || '_' || CASE test
    WHEN 'shoulder_extension' THEN 'shoulder_flexion'
    WHEN 'shoulder_horizontal_extension' THEN 'shoulder_horizontal_flexion'
    WHEN 'shoulder_internal_rotation' THEN 'shoulder_external_rotation'
    WHEN 'forearm_pronation' THEN 'forearm_supination'
    ELSE test END
  WHERE angle = '';
CREATE UNIQUE INDEX rom_results_uid ON rom_results(uid);
CREATE INDEX rom_results_session ON rom_results(session_id);

-- Exercise results from the games: repetitions, duration, score.
CREATE TABLE exercise_results (
    id           INTEGER PRIMARY KEY,
    uid          TEXT NOT NULL UNIQUE,
    session_id   INTEGER NOT NULL REFERENCES sessions(id),
    game         TEXT NOT NULL,
    repetitions  INTEGER NOT NULL,
    duration_s   REAL NOT NULL,
    score        REAL,
    details      TEXT NOT NULL DEFAULT '',
    recorded_utc TEXT NOT NULL
);
CREATE INDEX exercise_results_session ON exercise_results(session_id);
"""

_V3 = """
-- The therapist's limits of each exercise game for a patient (JSON of
-- game.exergames.spec.TherapistLimits), set on the game menu; one row per patient and game.
CREATE TABLE game_limits (
    patient_id  TEXT NOT NULL REFERENCES patients(id),
    game        TEXT NOT NULL,
    limits      TEXT NOT NULL,
    updated_utc TEXT NOT NULL,
    PRIMARY KEY (patient_id, game)
);
"""

_V4 = """
-- Who may do what (game/db/accounts.py): therapist and patient accounts, the secret (password or
-- PIN) only as a scrypt hash; a patient account belongs to one pseudonymous patient.
CREATE TABLE accounts (
    name        TEXT PRIMARY KEY,
    role        TEXT NOT NULL,
    patient_id  TEXT REFERENCES patients(id),
    secret_hash TEXT NOT NULL,
    created_utc TEXT NOT NULL
);

-- Who accepted, changed or exported what, and when (one row per act; never updated).
CREATE TABLE audit (
    id         INTEGER PRIMARY KEY,
    uid        TEXT NOT NULL UNIQUE,
    at_utc     TEXT NOT NULL,
    account    TEXT NOT NULL,
    action     TEXT NOT NULL,
    patient_id TEXT,
    what       TEXT NOT NULL DEFAULT ''
);
CREATE INDEX audit_patient ON audit(patient_id, at_utc);
"""

#: version -> the SQL that brings version-1 to it (applied in order).
STEPS: dict[int, str] = {2: _V2, 3: _V3, 4: _V4}
