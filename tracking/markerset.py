"""Marker sets: names, colours and placements, loaded from content YAML."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pydantic

from tracking.content import StrictModel, load_model, resolve
from tracking.errors import ContentError

RGB = tuple[int, int, int]


def parse_rgb(text: str) -> RGB:
    """'R,G,B' (sRGB 0-255) -> tuple; a ContentError says how to write it."""
    parts = text.replace(" ", "").split(",")
    try:
        values = tuple(int(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(0 <= v <= 255 for v in values):
        raise ContentError(f"colour {text!r} is malformed: write R,G,B with three integers 0-255, e.g. 0,200,70")
    return values  # type: ignore[return-value]


class _MarkerSpec(StrictModel):
    name: str = pydantic.Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$")
    colour: str | tuple[int, int, int]
    segment: str
    landmark: str = ""


class _MarkerSetSpec(StrictModel):
    name: str
    description: str = ""
    marker_diameter_mm: float = pydantic.Field(gt=5, lt=200)
    soft_tissue_mm: float = pydantic.Field(default=5.0, ge=0, lt=50)
    colours: dict[str, tuple[int, int, int]] = {}
    markers: list[_MarkerSpec] = pydantic.Field(min_length=2)

    @pydantic.field_validator("colours")
    @classmethod
    def _colour_range(cls, v: dict[str, tuple[int, int, int]]):
        for key, rgb in v.items():
            if not all(0 <= c <= 255 for c in rgb):
                raise ValueError(f"colour {key!r} must have three integers 0-255")
        return v


@dataclass(frozen=True, slots=True)
class MarkerSet:
    """A validated marker set.

    Attributes:
        name: marker set name.
        names: marker names in file order (the order of every per-marker array).
        segments: body segment of each marker.
        landmarks: anatomical landmark of each marker (free text).
        rgb: (M, 3) uint8 sRGB colour of each marker.
        radius_m: marker ball radius in metres.
        soft_tissue_m: skin/soft-tissue thickness between bone landmark and ball surface.
    """

    name: str
    names: tuple[str, ...]
    segments: tuple[str, ...]
    landmarks: tuple[str, ...]
    rgb: np.ndarray
    radius_m: float
    soft_tissue_m: float

    @property
    def n_markers(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        return self.names.index(name)

    @property
    def palette(self) -> np.ndarray:
        """(K, 3) uint8 distinct marker colours, in first-use order."""
        _, first = np.unique(self.rgb, axis=0, return_index=True)
        return self.rgb[np.sort(first)]

    @property
    def colour_index(self) -> np.ndarray:
        """(M,) int index of each marker's colour in :attr:`palette`."""
        pal = self.palette
        return np.array([int(np.flatnonzero((pal == c).all(axis=1))[0]) for c in self.rgb])

    def with_colours(self, colours: list[RGB]) -> "MarkerSet":
        """Override colours: one for all markers or one per marker (``--marker-color``)."""
        if len(colours) == 1:
            rgb = np.repeat(np.array(colours, dtype=np.uint8), self.n_markers, axis=0)
        elif len(colours) == self.n_markers:
            rgb = np.array(colours, dtype=np.uint8)
        else:
            raise ContentError(
                f"--marker-color got {len(colours)} colours: give one for all markers or "
                f"{self.n_markers}, one per marker in the order {', '.join(self.names)}"
            )
        rgb.setflags(write=False)
        return MarkerSet(self.name, self.names, self.segments, self.landmarks, rgb, self.radius_m, self.soft_tissue_m)


def load_markerset(name_or_path: str | Path = "upper_limb_seated") -> MarkerSet:
    """Load a built-in marker set by name, or a marker-set YAML file by path."""
    path = resolve("markersets", name_or_path)
    spec = load_model(path, _MarkerSetSpec)
    names = [m.name for m in spec.markers]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ContentError(f"{path}: markers: duplicate names {dupes}; every marker needs its own name")
    rgb = []
    for m in spec.markers:
        if isinstance(m.colour, str):
            if m.colour not in spec.colours:
                raise ContentError(
                    f"{path}: marker {m.name}: colour {m.colour!r} is not defined under 'colours' "
                    f"(defined: {sorted(spec.colours)})"
                )
            rgb.append(spec.colours[m.colour])
        else:
            if not all(0 <= c <= 255 for c in m.colour):
                raise ContentError(f"{path}: marker {m.name}: colour must be three integers 0-255")
            rgb.append(m.colour)
    rgb_arr = np.array(rgb, dtype=np.uint8)
    rgb_arr.setflags(write=False)
    return MarkerSet(
        name=spec.name,
        names=tuple(names),
        segments=tuple(m.segment for m in spec.markers),
        landmarks=tuple(m.landmark for m in spec.markers),
        rgb=rgb_arr,
        radius_m=spec.marker_diameter_mm / 2000.0,
        soft_tissue_m=spec.soft_tissue_mm / 1000.0,
    )
