"""Every file the code reads at run time is installed with it: a non-editable install once lacked
the database schema (``game/db/schema_v1.sql``) and every command that opened a database failed.
The lock file pins every declared dependency inside its declared range."""

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


def _locked_versions() -> dict[str, list]:
    from packaging.utils import canonicalize_name
    from packaging.version import Version

    pins: dict[str, list] = {}
    for line in (ROOT / "requirements.lock").read_text().splitlines():
        requirement = line.split("#", 1)[0].split(";", 1)[0].strip()
        if requirement:
            name, sep, version = requirement.partition("==")
            assert sep, f"requirements.lock: {line!r} is not pinned with =="
            pins.setdefault(canonicalize_name(name), []).append(Version(version))
    return pins


def test_the_lock_pins_every_declared_dependency_inside_its_range():
    """A dependency added to (or a bound raised in) pyproject.toml without regenerating the lock
    would make the README's install ignore it silently (a constraint pins only what it names)."""
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    pins = _locked_versions()
    declared = list(project["dependencies"]) + [r for extra in project["optional-dependencies"].values() for r in extra]
    for text in declared:
        requirement = Requirement(text)
        versions = pins.get(canonicalize_name(requirement.name))
        assert versions, f"{requirement.name} is not in requirements.lock: regenerate it (README, Reproducible installs)"
        outside = [str(v) for v in versions if not requirement.specifier.contains(v, prereleases=True)]
        assert not outside, f"requirements.lock pins {requirement.name} {outside}, outside {text!r}: regenerate it"
