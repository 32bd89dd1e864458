"""The tracker process's frame source: which source a :class:`SourceConfig` names, its geometry
before it is opened, and what its calibration holds.

The sources themselves are :mod:`tracking.sources` (one interface for the simulated patient,
recordings and live cameras, found by kind name); a ``"module:function"`` kind names a factory
``function(config) -> FrameSource`` (how tests inject a faulty source).
"""

from __future__ import annotations

import importlib
from dataclasses import replace
from pathlib import Path

from calibration.camera import Camera
from tracking.angles import supported_angles
from tracking.colour.adapt import calibration_colours
from tracking.live.protocol import LiveError, SourceConfig
from tracking.markerset import MarkerSet
from tracking.sources import FrameSource
from tracking.sources import calibration_file as kind_calibration_file
from tracking.sources import open_source as open_kind
from tracking.sources import resolve as kind_resolve
from tracking.sources import source_geometry as kind_geometry


def source_geometry(config: SourceConfig) -> tuple[tuple[Camera, ...], MarkerSet]:
    """Cameras and marker set of a source, without opening it (content, calibration and
    meta.yaml files only).

    The game sizes the shared memory from them before the tracker process starts; a
    ``"module:function"`` factory's source has the simulated patient's rig and marker set.
    """
    config.check()
    return kind_geometry(config if ":" not in config.kind else replace(config, kind="sim"))


def calibration_file_for(config: SourceConfig) -> Path | None:
    """The calibration file of a camera or recording source, None for a simulated one."""
    return None if ":" in config.kind else kind_calibration_file(config)


def learnt_colours_for(config: SourceConfig, markerset: MarkerSet):
    """The marker colours learnt into the source's calibration file (``rehab calibrate colour``):
    (models, label_hs), or None (none saved, or a simulated source: the nominal table)."""
    path = calibration_file_for(config)
    return None if path is None else calibration_colours(path, markerset)


def resolve_config(config: SourceConfig) -> SourceConfig:
    """``config`` with the image size (and, for a recording, the frame rate) its source decides.

    Raises:
        LiveError: the cameras' image sizes differ (the live image block holds one size).
        RehabError: the recording or the calibration cannot be read (one line).
    """
    config.check()
    return config if ":" in config.kind else kind_resolve(config)


def angle_names_for(markerset: MarkerSet) -> tuple[str, ...]:
    """The joint angles the tracker reports for a marker set: those its roles' markers give."""
    return supported_angles(markerset.roles)


def open_source(config: SourceConfig) -> FrameSource:
    """The source that ``config`` names, opened: a registered kind (``"sim"``, ``"recording"``,
    ``"cameras"``, :data:`tracking.sources.KINDS`) or a ``"module:function"`` factory."""
    if ":" not in config.kind:
        source = open_kind(config)
        source.open()
        return source
    module_name, _, attr = config.kind.partition(":")
    try:
        factory = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise LiveError(f"source kind {config.kind!r}: cannot import it ({exc}); give 'sim' or module:function") from None
    return factory(config)
