"""Frame sources: where the synchronized camera images come from, behind one interface.

- ``"recording"`` (:mod:`tracking.sources.recording`): a recording folder (videos or image
  folders, docs/INTERFACES.md), read frame set by frame set;
- ``"cameras"`` (:mod:`tracking.sources.cameras`): live cameras through OpenCV, one reader thread
  per camera, frames grouped by their time stamps;
- ``"sim"`` (:mod:`tracking.sources.sim`): the simulated patient, a scripted motion or the
  interactive patient, rendered by the virtual cameras.

Each is a :class:`~tracking.sources.base.FrameSource` (``read() -> FrameSet | None``,
``warnings()``, ``end_reason()``, ``handle(command)``, ``close()``, ``cameras``, ``markerset``,
``fps``); ``rehab track``, ``rehab record``, the live tracker process and the benchmarks use
only that. A kind is found by name in :data:`KINDS`: a new camera type is one module with
``from_config(config)`` and ``geometry(config)`` (and, if it has them, ``calibration_file(config)``
and ``resolve(config)``) and one line there (or :func:`register`).
"""

from __future__ import annotations

import importlib

from tracking.sources.base import FrameRequest, FrameSet, FrameSource, SourceError

#: Source kind -> the module that makes it: ``from_config(config) -> FrameSource`` opens one from
#: a :class:`tracking.live.protocol.SourceConfig`, ``geometry(config) -> (cameras, markerset)``
#: reads its cameras and marker set without opening devices; optionally ``calibration_file(config)
#: -> Path | None`` (where learnt marker colours are kept) and ``resolve(config) -> config`` (the
#: image size and frame rate the source itself decides).
KINDS: dict[str, str] = {
    "sim": "tracking.sources.sim",
    "recording": "tracking.sources.recording",
    "cameras": "tracking.sources.cameras",
}


def register(kind: str, module: str) -> None:
    """Make source kind ``kind`` the module ``module`` (dotted name, imported when first used)."""
    KINDS[kind] = module


def source_kinds() -> tuple[str, ...]:
    """The registered source kinds."""
    return tuple(KINDS)


def kind_module(kind: str):
    """The module of a registered kind, imported now: a source's module is imported only when it
    is used, so that ``rehab track`` never loads the simulator's OpenGL."""
    try:
        name = KINDS[kind]
    except KeyError:
        raise SourceError(f"source kind {kind!r}: give one of {', '.join(KINDS)}") from None
    return importlib.import_module(name)


def open_source(config) -> FrameSource:
    """The source of ``config`` (a :class:`tracking.live.protocol.SourceConfig` of a registered kind)."""
    return kind_module(config.kind).from_config(config)


def source_geometry(config) -> tuple:
    """(cameras, marker set) of ``config``'s source without opening it (content, calibration and
    meta.yaml files only)."""
    return kind_module(config.kind).geometry(config)


def calibration_file(config):
    """The calibration file of ``config``'s source (a Path), None if it has none (the simulator)."""
    hook = getattr(kind_module(config.kind), "calibration_file", None)
    return None if hook is None else hook(config)


def resolve(config):
    """``config`` with what its source decides itself (a recording's image size and frame rate)."""
    hook = getattr(kind_module(config.kind), "resolve", None)
    return config if hook is None else hook(config)


__all__ = ["KINDS", "FrameRequest", "FrameSet", "FrameSource", "SourceError", "calibration_file", "open_source",
           "register", "resolve", "source_geometry", "source_kinds"]
