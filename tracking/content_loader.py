"""Loading content YAML files, validated once with pydantic, with one-line errors.

Content lives in the installed :mod:`content` package; a user may also pass a path to their own
file. Unknown keys are errors (``extra="forbid"`` on every model) so that a misspelt knob is never
silently ignored.
"""

from __future__ import annotations

from pathlib import Path
from typing import TypeVar

import pydantic
import yaml

from calibration.errors import utf8_text
from content import content_path
from tracking.errors import ContentError

M = TypeVar("M", bound=pydantic.BaseModel)


class StrictModel(pydantic.BaseModel):
    """Base of every content schema: unknown keys are errors, instances are immutable, numbers finite."""

    model_config = pydantic.ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


def available(kind: str) -> list[str]:
    """Names of the built-in content files of one kind (the folder name, e.g. ``markersets``)."""
    folder = content_path(kind)
    return sorted(p.stem for p in folder.glob("*.yaml")) if folder.is_dir() else []


def resolve(kind: str, name_or_path: str | Path) -> Path:
    """A built-in name (``upper_limb_seated``) or a path to a YAML file -> an existing path."""
    text = str(name_or_path)
    if text.endswith((".yaml", ".yml")) or "/" in text or "\\" in text:
        path = Path(text)
        if not path.is_file():
            raise ContentError(f"{path}: no such file; give an existing YAML file or one of {available(kind)}")
        return path
    path = content_path(kind, f"{text}.yaml")
    if not path.is_file():
        raise ContentError(f"unknown {kind[:-1] if kind.endswith('s') else kind} {text!r}: choose one of {available(kind)} or give a .yaml path")
    return path


def load_yaml(path: Path) -> object:
    """Parse a YAML file; a syntax error becomes a ContentError naming the file and line."""
    try:
        text = utf8_text(path, Path(path).read_bytes(), ContentError)
        return yaml.safe_load(text)
    except OSError as exc:
        raise ContentError(f"{path}: cannot read ({exc.strerror})") from None
    except RecursionError:
        raise ContentError(f"{path}: nested too deeply; fix the YAML structure") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise ContentError(f"{path}:{where}: {problem}; fix the YAML syntax") from None


def load_model(path: Path, model: type[M]) -> M:
    """Load and validate one YAML file against a pydantic model; errors name the file and key."""
    data = load_yaml(path)
    if not isinstance(data, dict):
        raise ContentError(f"{path}: expected a mapping of keys at the top level")
    try:
        return model.model_validate(data)
    except pydantic.ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key (misspelt?)"
        more = f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
        raise ContentError(f"{path}: {loc}: {msg}{more}") from None
