"""Every file the code reads at run time is installed with it: a non-editable install once lacked
the database schema (``game/db/schema_v1.sql``) and every command that opened a database failed."""

import fnmatch
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_data_file_of_the_packages_is_declared_as_package_data():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    patterns = config["package-data"]
    missing = []
    for package in ("calibration", "tracking", "game", "content"):
        for path in (ROOT / package).rglob("*"):
            if not path.is_file() or path.suffix in (".py", ".pyc") or "__pycache__" in path.parts:
                continue
            rel = path.relative_to(ROOT / package).as_posix()
            globs = patterns.get(package, [])
            # setuptools' "**/" also matches files at the package's top level
            if not any(fnmatch.fnmatch(rel, g) or fnmatch.fnmatch(rel, g.removeprefix("**/")) for g in globs):
                missing.append(f"{package}/{rel}")
    assert not missing, f"add to [tool.setuptools.package-data] in pyproject.toml: {missing}"
