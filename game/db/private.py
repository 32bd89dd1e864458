"""Patient files readable by the user only, written whole or not at all.

The database, its backups, the pending results, CSV exports and reports hold patient data: files
are created 0600 and folders this program creates 0700, whatever the umask. A file is written to a
temporary name in its folder, flushed to disk (fsync) and renamed, so a killed process leaves
either the old file or the new one, never half of one under the user's name.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import IO, Iterator

from calibration.atomic import FILE_MODE, commit_temp, fsync_dir, temp_path_beside  # noqa: F401 (used by the database)
from calibration.errors import RehabError

DIR_MODE = 0o700


def make_private_dir(path: str | Path) -> Path:
    """Create ``path`` (and missing parents) as 0700; an existing folder is left as it is.

    Raises:
        RehabError: the folder cannot be created (one line naming it).
    """
    path = Path(path)
    missing = []
    p = path
    while not p.exists():
        missing.append(p)
        if p.parent == p:
            break
        p = p.parent
    try:
        path.mkdir(mode=DIR_MODE, parents=True, exist_ok=True)
        for folder in missing:   # mkdir's mode is masked by the umask: set it explicitly
            os.chmod(folder, DIR_MODE)
    except OSError as exc:
        raise RehabError(f"{path}: cannot create the folder ({exc.strerror or exc}): choose a folder you can write")
    if not path.is_dir():
        raise RehabError(f"{path} is not a folder: choose a folder")
    return path


def make_private(path: str | Path, mode: int = FILE_MODE) -> None:
    """Make an existing file (or, with ``mode=DIR_MODE``, folder) of ours private; others' are left alone."""
    with contextlib.suppress(OSError):
        st = os.stat(path)
        if hasattr(os, "getuid") and st.st_uid == os.getuid() and st.st_mode & 0o077:
            os.chmod(path, mode)


@contextlib.contextmanager
def open_private(path: str | Path, mode: str = "w", *, overwrite: bool = True, **kwargs) -> Iterator[IO]:
    """Write ``path`` as a private file through a temporary file: whole or not at all.

    Args:
        path: the file to write; its folder must exist.
        mode: ``"w"`` (text; ``encoding``/``newline`` go in ``kwargs``) or ``"wb"``.
        overwrite: replace an existing file (else raise FileExistsError at the end).

    On an exception inside the block the temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    tmp = temp_path_beside(path)
    try:
        with open(tmp, mode, **kwargs) as fh:
            yield fh
        commit_temp(tmp, path, overwrite=overwrite)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
