"""Virtual camera layouts around the seated patient, from content/rigs/*.yaml."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pydantic

from calibration.camera import Camera
from tracking.content_loader import StrictModel, load_model, resolve
from tracking.errors import ContentError


class _RigCamera(StrictModel):
    name: str
    azimuth_deg: float = pydantic.Field(ge=-360, le=360)
    distance_m: float = pydantic.Field(gt=0.5, lt=10)
    height_m: float = pydantic.Field(gt=0.1, lt=5)
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)


class _RigSpec(StrictModel):
    name: str
    description: str = ""
    target_m: tuple[float, float, float]
    horizontal_fov_deg: float = pydantic.Field(gt=20, lt=120)
    cameras: list[_RigCamera] = pydantic.Field(min_length=2)


def load_rig(name_or_path: str | Path, size_px: tuple[int, int]) -> tuple[Camera, ...]:
    """Cameras of a layout at the given image size (width, height).

    Azimuth 0 is straight in front of the patient (who faces -Z); positive azimuths go towards
    the patient's right (+X). Each camera looks at the rig's target.
    """
    path = resolve("rigs", name_or_path)
    spec = load_model(path, _RigSpec)
    names = [c.name for c in spec.cameras]
    if len(set(names)) != len(names):
        raise ContentError(f"{path}: cameras: names must be unique, got {names}")
    w, h = size_px
    f_px = (w / 2.0) / np.tan(np.radians(spec.horizontal_fov_deg) / 2.0)
    cams = []
    for c in spec.cameras:
        az = np.radians(c.azimuth_deg)
        eye = (c.distance_m * np.sin(az), c.height_m, -c.distance_m * np.cos(az))
        cams.append(Camera.look_at(c.name, (w, h), f_px, eye, spec.target_m, dist=c.distortion))
    return tuple(cams)
