"""Files written whole or not at all: a temporary file in the same folder, flushed to disk, renamed.

A killed process (or a full disk, a failure half-way) then leaves either the old file or the new
one under the user's name, never half of one; the temporary file is removed on a failure (a kill
may leave a hidden ``.NAME.*.partial*`` beside it, never a file under NAME). Used by every
writer of results (rehab track's TRC, C3D, CSV, .mot, BVH; calibrations) and by the database's
patient files (:mod:`game.db.private`). The bottom layer, so that every package can use it.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

#: Mode of the temporary file (it becomes the file): readable by the user only.
FILE_MODE = 0o600


def fsync_dir(folder: str | Path) -> None:
    """Make a rename in ``folder`` durable (no-op where folders cannot be opened, e.g. Windows)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def temp_path_beside(path: str | Path, *, keep_suffix: bool = False) -> Path:
    """A new empty private file in ``path``'s folder, named after it (for writing then renaming).

    ``keep_suffix``: the name ends with ``path``'s extension too (for writers that choose the
    format by it, e.g. ``.c3d``)."""
    path = Path(path)
    suffix = ".partial" + (path.suffix if keep_suffix else "")
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    os.chmod(name, FILE_MODE)
    return Path(name)


def commit_temp(tmp: Path, path: Path, *, overwrite: bool = True) -> None:
    """Flush ``tmp`` to disk and rename it to ``path`` (refusing an existing ``path`` unless ``overwrite``)."""
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    if overwrite:
        os.replace(tmp, path)
    else:
        os.link(tmp, path)   # fails if path exists: never replaces a file the user has
        os.unlink(tmp)
    fsync_dir(path.parent)


@contextlib.contextmanager
def written_via_temp(path: str | Path, *, keep_suffix: bool = True) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` for a writer to fill; on leaving the block it is
    flushed and renamed to ``path``; on an exception it is removed and ``path`` is untouched.

    ``path``'s folder must exist."""
    path = Path(path)
    tmp = temp_path_beside(path, keep_suffix=keep_suffix)
    try:
        yield tmp
        commit_temp(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
