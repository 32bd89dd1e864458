-- rehab database, schema version 1 (the first released layout). Kept verbatim: a fresh database
-- is built from this script and then migrated step by step (game/db/migrations.py), so new and old
-- databases follow the same path, and tests build a v1 file from it to check the migration.
CREATE TABLE schema_version (version INTEGER NOT NULL);

-- Patients under pseudonymous IDs (no names).
CREATE TABLE patients (
    id          TEXT PRIMARY KEY,
    created_utc TEXT NOT NULL,
    note        TEXT NOT NULL DEFAULT ''
);

CREATE TABLE sessions (
    id          INTEGER PRIMARY KEY,
    patient_id  TEXT NOT NULL REFERENCES patients(id),
    started_utc TEXT NOT NULL,
    kind        TEXT NOT NULL,              -- 'rom' or 'exercise'
    note        TEXT NOT NULL DEFAULT ''
);

-- Active ROM results: the maximum reached (raw degrees), the start value, the test position and
-- the standard the result is labelled with.
CREATE TABLE rom_results (
    id           INTEGER PRIMARY KEY,
    session_id   INTEGER NOT NULL REFERENCES sessions(id),
    test         TEXT NOT NULL,
    side         TEXT NOT NULL,
    mode         TEXT NOT NULL DEFAULT 'active',
    position     TEXT NOT NULL,
    standard     TEXT NOT NULL,
    value_deg    REAL NOT NULL,
    start_deg    REAL NOT NULL,
    compensation TEXT NOT NULL DEFAULT '',
    recorded_utc TEXT NOT NULL
);

INSERT INTO schema_version (version) VALUES (1);
