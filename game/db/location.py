"""Where the rehab database is: an SQLite file (the embedded default) or a PostgreSQL server URL.

``--db`` on every command and in the application, or the ``REHAB_DB`` environment variable, takes
either a file path or ``postgresql://[user[:password]@]host[:port]/dbname[?...]`` (a libpq URL; a
``host=/run/postgresql`` query names a unix socket folder). A URL is kept whole for connecting and
shown with its password masked in every message. Results waiting for a server that cannot be
reached are kept on this station in the user's data folder (:func:`local_folder`).
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import unquote, urlsplit

#: The environment variable naming the database when ``--db`` is not given.
ENV_VAR = "REHAB_DB"
_URL = re.compile(r"^postgres(ql)?://", re.IGNORECASE)


@dataclass(frozen=True)
class ServerUrl:
    """A PostgreSQL database named by a libpq URL; ``str()`` masks the password."""

    url: str = field(repr=False)

    def __str__(self) -> str:
        return re.sub(r"(://[^:/@?]*:)[^@/?]*@", r"\1***@", self.url)

    def __repr__(self) -> str:
        return f"ServerUrl({str(self)!r})"

    @property
    def key(self) -> str:
        """A file-name-safe name of the server and database (the station's queue folder for it)."""
        parts = urlsplit(self.url)
        host = parts.hostname or unquote(dict(p.split("=", 1) for p in parts.query.split("&") if "=" in p)
                                         .get("host", "local"))
        try:
            port = parts.port or 5432
        except ValueError:
            port = 5432
        name = f"{host}_{port}_{parts.path.lstrip('/') or 'default'}"
        return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_.")[:120]


def default_db_path() -> Path:
    """The database in the user's data directory.

    Linux and others: ``$XDG_DATA_HOME/rehab/rehab.sqlite3`` (default ``~/.local/share``);
    Windows: ``%LOCALAPPDATA%\\rehab\\rehab.sqlite3``; macOS: ``~/Library/Application Support/rehab/``.
    """
    if sys.platform.startswith("win"):
        base = Path(os.environ.get("LOCALAPPDATA") or os.environ.get("APPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Application Support"
    else:
        base = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share")
    return base / "rehab" / "rehab.sqlite3"


def is_server_url(value: object) -> bool:
    return isinstance(value, ServerUrl) or (isinstance(value, str) and bool(_URL.match(value.strip())))


def db_location(value: str | Path | ServerUrl | None = None) -> Path | ServerUrl:
    """The database ``value`` names: None -> ``$REHAB_DB`` -> the user's data folder's file."""
    if isinstance(value, ServerUrl):
        return value
    if value is None or (isinstance(value, str) and not value.strip()):
        value = os.environ.get(ENV_VAR, "").strip() or None
        if value is None:
            return default_db_path()
    if is_server_url(value):
        return ServerUrl(str(value).strip())
    return Path(value)


def local_folder(location: Path | ServerUrl) -> Path:
    """The station's own folder for files about ``location``: beside a file, or the user's data folder."""
    if isinstance(location, ServerUrl):
        return default_db_path().parent
    return Path(location).parent


def pending_dir(db_path: str | Path | ServerUrl) -> Path:
    """The folder of results waiting for the database ``db_path`` (a file or a server URL)."""
    location = db_location(db_path)
    if isinstance(location, ServerUrl):
        return local_folder(location) / "pending" / location.key
    return location.with_name(location.name + ".pending")
