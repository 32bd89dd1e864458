"""The PostgreSQL back-end: several stations of a clinic on one database server (psycopg 3).

Imported only when ``--db``/``REHAB_DB`` is a ``postgresql://`` URL, so the embedded SQLite default
needs no driver. The connection runs in autocommit mode and the storage layer opens its own write
transactions (``BEGIN`` ... ``COMMIT``, READ COMMITTED): every write is keyed by a unique uid and
written with ``INSERT ... ON CONFLICT DO NOTHING``, so two stations writing the same patient or
the same session at once wait for each other's row and neither loses nor duplicates anything.
A server that cannot be reached raises :class:`DatabaseUnreachable` (the results then wait on the
station, :mod:`game.db.pending`); a lock held past the wait raises ``DatabaseLocked``.
"""

from __future__ import annotations

import logging
from functools import lru_cache

from game.db.dialect import POSTGRESQL_DDL, Dialect
from game.db.errors import DatabaseError, DatabaseLocked, DatabaseUnreachable
from game.db.location import ServerUrl

log = logging.getLogger(__name__)

try:
    import psycopg
    from psycopg import errors as pg_errors
    from psycopg.pq import TransactionStatus
except ImportError:   # pragma: no cover - the optional extra is missing
    psycopg = None

#: Seconds to wait for the server to answer a connection (then the results wait on the station).
CONNECT_TIMEOUT_S = 5


def _first_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:300]


def server_error(location: ServerUrl, exc: BaseException) -> DatabaseError:
    """The one-line error for a PostgreSQL failure: unreachable, locked, refused."""
    text = _first_line(exc)
    if isinstance(exc, (pg_errors.LockNotAvailable, pg_errors.DeadlockDetected, pg_errors.SerializationFailure,
                        pg_errors.QueryCanceled)):
        return DatabaseLocked(f"{location} is busy (another station holds the rows: {text}): try again")
    if isinstance(exc, pg_errors.InsufficientPrivilege):
        return DatabaseError(f"{location}: the database user may not do this ({text}): ask the clinic's database "
                             f"administrator to grant it")
    if isinstance(exc, pg_errors.DiskFull):
        return DatabaseError(f"{location}: the server's disk is full ({text})")
    if isinstance(exc, (psycopg.OperationalError, psycopg.InterfaceError)):
        return DatabaseUnreachable(f"cannot reach the database server {location} ({text}): check that the server "
                                   f"runs and the address; results are kept on this station meanwhile")
    return DatabaseError(f"{location}: the database server refused ({text})")


POSTGRESQL = Dialect(
    name="postgresql",
    begin="BEGIN",
    tables_sql="SELECT table_name FROM information_schema.tables WHERE table_schema = current_schema()",
    # two stations starting on a new database at once: one migrates, the other then sees it done
    migration_lock="SELECT pg_advisory_xact_lock(7283001)",
    read_snapshot="BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY",
    ddl=POSTGRESQL_DDL,
    errors=(psycopg.Error,) if psycopg is not None else (),
    error=server_error,
)


@lru_cache(maxsize=512)
def _placeholders(sql: str) -> str:
    """``?`` parameters (the storage layer's, as SQLite) as psycopg's ``%s`` (no ``?`` or ``%`` in quotes there)."""
    return sql.replace("%", "%%").replace("?", "%s")


class PgConnection:
    """A psycopg connection with the subset of ``sqlite3.Connection`` the storage layer uses."""

    def __init__(self, raw):
        self.raw = raw

    def execute(self, sql: str, params=()):
        params = tuple(params)
        return self.raw.execute(_placeholders(sql), params) if params else self.raw.execute(sql)

    @property
    def in_transaction(self) -> bool:
        return self.raw.info.transaction_status != TransactionStatus.IDLE

    def close(self) -> None:
        self.raw.close()


def connect(location: ServerUrl, *, busy_timeout_s: float) -> PgConnection:
    """Connect to the server (autocommit; locks waited for ``busy_timeout_s``).

    Raises:
        DatabaseError: psycopg is not installed (one line saying how to add it).
        DatabaseUnreachable: the server does not answer or refuses the connection.
    """
    if psycopg is None:
        raise DatabaseError(f"{location}: PostgreSQL needs the psycopg driver: pip install 'rehab-mocap[postgres]'")
    try:
        raw = psycopg.connect(location.url, autocommit=True, connect_timeout=CONNECT_TIMEOUT_S,
                              application_name="rehab")
    except psycopg.Error as exc:
        raise server_error(location, exc) from None
    try:
        raw.execute(f"SET lock_timeout = {max(1, int(busy_timeout_s * 1000))}")
        raw.execute("SET TIME ZONE 'UTC'")
    except psycopg.Error as exc:
        raw.close()
        raise server_error(location, exc) from None
    return PgConnection(raw)
