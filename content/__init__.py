"""Content: YAML files that define marker sets, motions, camera rigs, ROM tests, games and scenes.

This is a data package; the files are read through :func:`content_path`.
"""

from importlib import resources
from pathlib import Path


def content_path(*parts: str) -> Path:
    """Path of a file or folder inside the installed content package."""
    return Path(str(resources.files(__name__).joinpath(*parts)))
