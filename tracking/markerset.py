"""Marker sets: names, colours and placements, loaded from content YAML.

``roles:`` says which marker plays which anatomical role (:data:`ROLES`: the trunk points, each
side's shoulder, epicondyles and styloids); the joint angles, the avatar and the live scene find
their markers through the roles, never by name, so a new marker set is content only
(docs/ARCHITECTURE.md "Where a new thing goes").

A marker set may also say how its markers are identified on the first frame (docs/METHOD.md 5.2):
the reference pose the patient takes, structure rules of that pose written as coordinate
orderings in the patient's frame (:class:`OrderRule`), and distance ranges of markers on one
rigid body part (:class:`DistanceRule`), each with a plain-words message for the therapist
(``identification:`` in the YAML; :mod:`tracking.labelling.rules` applies them).
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, Sequence

import numpy as np
import pydantic

from tracking.content_loader import StrictModel, load_model, resolve
from tracking.errors import ContentError
from tracking.hidden import registry as hidden_registry

RGB = tuple[int, int, int]

#: The anatomical roles a marker can play (``roles:`` in a marker-set YAML), with the landmark
#: each stands for. The angles (docs/JOINT_ANGLES.md) and the avatar read their markers by role.
ROLES: dict[str, str] = {
    "trunk_upper": "upper sternum (jugular notch region)",
    "trunk_lower": "lower trunk midline (xiphoid)",
    **{f"{side}_{part}": f"{side} {landmark}" for side in ("left", "right") for part, landmark in (
        ("hip", "anterior superior iliac spine"),
        ("shoulder", "acromion"),
        ("elbow_lateral", "lateral epicondyle (thumb side)"),
        ("elbow_medial", "medial epicondyle (little-finger side)"),
        ("wrist_radial", "radial styloid (thumb side)"),
        ("wrist_ulnar", "ulnar styloid (little-finger side)"),
    )},
}

#: The roles' markers in the default ``upper_limb_seated`` set. These names are what a marker
#: file (TRC, C3D) is read by when no marker set says otherwise (``rehab angles``), so a marker
#: set may give one of them only to the marker playing that role.
DEFAULT_ROLES: dict[str, str] = {
    "trunk_upper": "MB", "trunk_lower": "MP",
    **{f"{side}_{part}": f"M{side[0].upper()}{code}" for side in ("left", "right") for part, code in (
        ("hip", "H"), ("shoulder", "S"), ("elbow_lateral", "E1"), ("elbow_medial", "E2"),
        ("wrist_radial", "W1"), ("wrist_ulnar", "W2"),
    )},
}


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


_AXES = {"x": 0, "y": 1, "z": 2, "outward": 0}
_RULE_NAME = r"[A-Za-z*][A-Za-z0-9_*]*"


def _check_names(text: str, sep: str, example: str, min_groups: int, max_groups: int | None = None) -> str:
    groups = [g.split(",") for g in text.split(sep)]
    if not min_groups <= len(groups) <= (max_groups or len(groups)):
        raise ValueError(f"{text!r}: write {example}")
    for g in groups:
        for name in g:
            if not re.fullmatch(_RULE_NAME, name.strip()):
                raise ValueError(f"{text!r}: {name.strip()!r} is not a marker name; write {example}")
    return text


class _RuleSpec(StrictModel):
    """An ordering (``order`` + ``along``) or a distance range (``distance`` + ``within_mm``)."""

    order: str | None = pydantic.Field(
        default=None,
        description="groups of marker names separated by '<', names within a group by commas; "
        "every marker of a group is before every marker of the next along the axis. "
        "'*' stands for each side letter in turn (the same side throughout the rule)",
    )
    along: Literal["x", "y", "z", "outward"] | None = pydantic.Field(
        default=None,
        description="patient-frame axis: x the patient's right, y up, z backwards (the patient "
        "faces -z), outward away from the body's midline on the rule's side (needs '*')",
    )
    min_margin_mm: float | None = pydantic.Field(default=None, ge=0, le=300)
    distance: str | None = pydantic.Field(
        default=None, description="'A, B - C': every marker of the first group to every marker of the second"
    )
    within_mm: tuple[float, float] | None = pydantic.Field(
        default=None, description="accepted [min, max] distance in mm (markers on one rigid body part)"
    )
    message: str = pydantic.Field(
        min_length=1, description="what a therapist reads when the rule fails; {side} is the side's word"
    )

    @pydantic.field_validator("order")
    @classmethod
    def _order_syntax(cls, v: str | None) -> str | None:
        return None if v is None else _check_names(v, "<", "'A, B < C' (at least two groups)", 2)

    @pydantic.field_validator("distance")
    @classmethod
    def _distance_syntax(cls, v: str | None) -> str | None:
        return None if v is None else _check_names(v, "-", "'A - B, C' (two groups)", 2, 2)

    @pydantic.field_validator("within_mm")
    @classmethod
    def _range(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None and not 0 <= v[0] < v[1]:
            raise ValueError(f"within_mm {list(v)} must be [min, max] with 0 <= min < max")
        return v

    @pydantic.field_validator("message")
    @classmethod
    def _one_line(cls, v: str) -> str:
        v = " ".join(v.split())
        if not v:
            raise ValueError("the message is empty: say in plain words what is wrong and how to fix it")
        return v

    @pydantic.model_validator(mode="after")
    def _one_kind(self) -> "_RuleSpec":
        is_order = self.order is not None or self.along is not None
        is_distance = self.distance is not None or self.within_mm is not None
        if is_order == is_distance:
            raise ValueError("give either 'order' with 'along', or 'distance' with 'within_mm'")
        if is_order and (self.order is None or self.along is None):
            raise ValueError("an ordering rule needs both 'order' and 'along'")
        if is_distance and (self.distance is None or self.within_mm is None or self.min_margin_mm is not None):
            raise ValueError("a distance rule needs 'distance' and 'within_mm' (and takes no min_margin_mm)")
        return self


class _IdentificationSpec(StrictModel):
    reference_pose: str = pydantic.Field(min_length=1, description="the start pose in plain words")
    sides: dict[str, Literal["left", "right"]] = pydantic.Field(
        default={}, description="side letter -> 'left'/'right'; '*' in a rule expands over these"
    )
    left_right_pairs: list[tuple[str, str]] = pydantic.Field(
        min_length=1, description="(left, right) marker pairs across the trunk: the patient's right is "
        "their mean horizontal direction"
    )
    max_turn_deg: float = pydantic.Field(default=30.0, gt=0, lt=90)
    min_margin_mm: float = pydantic.Field(default=0.0, ge=0, le=300)
    rules: list[_RuleSpec] = pydantic.Field(min_length=1)


#: The built-in hidden-marker estimators; others are files in tracking/hidden/methods/, named by
#: the same key (:func:`_known_estimator` checks the name against the registry).
ESTIMATORS = ("constant_velocity", "neighbours", "rigid", "hinge", "forearm")


def _known_estimator(name: str) -> str:
    if name not in hidden_registry.names():
        raise ValueError(f"{name!r} is not one of {', '.join(hidden_registry.names())} "
                         "(a new estimator is a file in tracking/hidden/methods/)")
    return name


_Estimator = Annotated[str, pydantic.AfterValidator(_known_estimator)]
_PATTERN = r"^[A-Za-z*#][A-Za-z0-9_*#]*$"


class _HiddenMarkerSpec(StrictModel):
    estimator: _Estimator = pydantic.Field(description="how the marker is estimated while hidden")
    neighbours: dict[str, float] = pydantic.Field(
        default={}, description="equation 6 weights S_i: neighbour marker -> weight (> 0)"
    )
    velocity_decay_s: float | None = pydantic.Field(
        default=None, ge=0, le=10, description="overrides hidden_markers.velocity_decay_s for this marker"
    )

    @pydantic.field_validator("neighbours")
    @classmethod
    def _positive(cls, v: dict[str, float]) -> dict[str, float]:
        for name, s in v.items():
            if not (s > 0 and s < 1e6):
                raise ValueError(f"weight of {name!r} is {s}: give a positive number")
        return v


class _ElbowSpec(StrictModel):
    markers: tuple[str, str] = pydantic.Field(description="the two epicondyle markers (on the flexion axis)")
    shoulder: str = pydantic.Field(description="the acromion marker of that arm")
    wrist: tuple[str, str] = pydantic.Field(description="the two styloid markers of that forearm")


class _ForearmSpec(StrictModel):
    markers: tuple[str, str] = pydantic.Field(description="the two styloid markers")
    elbow: tuple[str, str] = pydantic.Field(description="the two epicondyle markers of that arm")


class _TrunkSpec(StrictModel):
    upper: str
    lower: str
    left: str
    right: str


class _LimitsSpec(StrictModel):
    length_pairs: list[tuple[str, str]] = pydantic.Field(
        default=[], description="near-rigid marker pairs whose distance is checked for drift"
    )
    drift_tolerance_mm: float = pydantic.Field(default=30.0, gt=0, le=500)
    max_hidden_s: dict[_Estimator, float] = pydantic.Field(
        default={}, description="longest occlusion reported, per estimator (seconds)"
    )
    max_unsupported_s: float = pydantic.Field(default=0.5, gt=0, le=60)

    @pydantic.field_validator("max_hidden_s")
    @classmethod
    def _times(cls, v: dict[str, float]) -> dict[str, float]:
        for name, s in v.items():
            if not 0 < s <= 600:
                raise ValueError(f"max_hidden_s of {name} is {s}: give seconds in (0, 600]")
        return v


class _HiddenSpec(StrictModel):
    markers: dict[str, _HiddenMarkerSpec] = pydantic.Field(
        default={}, description="per marker (or '*' pattern): estimator and equation 6 weights"
    )
    rigid_groups: list[list[str]] = pydantic.Field(default=[], description="groups treated as rigid, in order")
    trunk: _TrunkSpec | None = None
    elbows: list[_ElbowSpec] = []
    forearms: list[_ForearmSpec] = []
    velocity_decay_s: float = pydantic.Field(default=0.15, ge=0, le=10)
    limits: _LimitsSpec = _LimitsSpec()


class _MarkerSetSpec(StrictModel):
    name: str
    description: str = ""
    marker_diameter_mm: float = pydantic.Field(gt=5, lt=200)
    soft_tissue_mm: float = pydantic.Field(default=5.0, ge=0, lt=50)
    colours: dict[str, tuple[int, int, int]] = {}
    markers: list[_MarkerSpec] = pydantic.Field(min_length=2)
    roles: dict[str, str] | None = pydantic.Field(
        default=None, description="anatomical role -> marker name (the keys of tracking.markerset.ROLES); "
        "without it, the markers named as in upper_limb_seated play their roles there",
    )
    identification: _IdentificationSpec | None = None
    hidden_markers: _HiddenSpec | None = None

    @pydantic.field_validator("colours")
    @classmethod
    def _colour_range(cls, v: dict[str, tuple[int, int, int]]):
        for key, rgb in v.items():
            if not all(0 <= c <= 255 for c in rgb):
                raise ValueError(f"colour {key!r} must have three integers 0-255")
        return v


@dataclass(frozen=True, slots=True)
class OrderRule:
    """One structure rule of the reference pose: marker groups in order along a patient axis.

    ``groups[0] < groups[1] < ...``: every marker of a group lies before (smaller coordinate)
    every marker of the next group, by at least ``min_margin_m``. A rule written with the side
    wildcard ``*`` becomes one rule per side.

    Attributes:
        text: the rule with the side filled in, e.g. ``"MLH < MLW1, MLW2 along outward"``.
        groups: marker names of each group, in order.
        axis: patient-frame axis 0 (x, the patient's right), 1 (y, up) or 2 (z, backwards).
        sign: +1, or -1 for ``outward`` on the left side (outward is -x there).
        min_margin_m: the smallest accepted separation, metres.
        message: one line for the therapist, said when the rule fails.
    """

    text: str
    groups: tuple[tuple[str, ...], ...]
    axis: int
    sign: int
    min_margin_m: float
    message: str


@dataclass(frozen=True, slots=True)
class DistanceRule:
    """Markers on one rigid body part: their distance stays in a range in any pose.

    Orderings alone let one colour for all markers (or a wrong pose) be "explained" by swapping
    markers between body parts; distances between markers on one bone forbid that.

    Attributes:
        text: the rule with the side filled in, e.g. ``"MLE1 - MLE2 within 60-170 mm"``.
        groups: two groups of marker names; every marker of the first to every one of the second.
        min_m, max_m: the accepted distance range, metres.
        message: one line for the therapist, said when the rule fails.
    """

    text: str
    groups: tuple[tuple[str, ...], tuple[str, ...]]
    min_m: float
    max_m: float
    message: str


@dataclass(frozen=True, slots=True)
class IdentificationRules:
    """How the markers are identified in the reference pose (docs/METHOD.md 5.2).

    Attributes:
        reference_pose: the pose in plain words (shown to the patient and the therapist).
        rules: the structure rules (orderings and distances), side wildcards expanded.
        left_right_pairs: (left, right) marker names across the trunk; the patient's right is
            their mean horizontal left -> right direction.
        max_turn_deg: how far the patient may sit turned about the vertical from facing -Z.
    """

    reference_pose: str
    rules: tuple[OrderRule | DistanceRule, ...]
    left_right_pairs: tuple[tuple[str, str], ...]
    max_turn_deg: float


@dataclass(frozen=True, slots=True)
class HiddenMarkerConfig:
    """How hidden markers are estimated and when an estimate is dropped (``hidden_markers:``).

    Marker names throughout, side wildcards expanded; :mod:`tracking.hidden` turns them into
    indices. A marker the file does not configure gets equation 6 (``neighbours``) with weight 1
    for every other marker of its body segment.

    Attributes:
        estimators: (M,) estimator name of each marker (:data:`ESTIMATORS` or a registered one).
        weights: marker -> {neighbour: S}, the equation 6 weights.
        velocity_decay_s: (M,) time constant of the own relative velocity kept in free directions.
        rigid_groups: groups of markers treated as rigid, in the order a hidden marker tries them.
        trunk: (upper, lower, left, right) markers of the trunk frame, or None.
        elbows: (marker a, marker b, shoulder, wrist a, wrist b) per elbow.
        forearms: (styloid a, styloid b, epicondyle a, epicondyle b) per forearm.
        length_pairs: near-rigid pairs checked for drift.
        drift_tolerance_m: allowed excursion beyond the learned distance range.
        max_hidden_s: estimator -> longest occlusion reported (seconds).
        max_unsupported_s: longest time an estimate is reported with no marker of its body segment
            measured.
    """

    estimators: tuple[str, ...]
    weights: dict[str, dict[str, float]]
    velocity_decay_s: tuple[float, ...]
    rigid_groups: tuple[tuple[str, ...], ...]
    trunk: tuple[str, str, str, str] | None
    elbows: tuple[tuple[str, str, str, str, str], ...]
    forearms: tuple[tuple[str, str, str, str], ...]
    length_pairs: tuple[tuple[str, str], ...]
    drift_tolerance_m: float
    max_hidden_s: dict[str, float]
    max_unsupported_s: float


#: Longest occlusion reported per estimator where the marker set says nothing (seconds).
DEFAULT_MAX_HIDDEN_S = {"constant_velocity": 0.5, "neighbours": 2.0, "rigid": 5.0, "hinge": 20.0, "forearm": 20.0}


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
        identification: rules for identifying the markers in the reference pose, or None if the
            marker set has none.
        hidden: how hidden markers are estimated (every marker set has one: without
            ``hidden_markers:`` equation 6 with weight 1 for the markers of the same segment).
        roles: anatomical role (a key of :data:`ROLES`) -> the marker playing it; a role the
            set has no marker for is absent, and what needs it is withheld.
    """

    name: str
    names: tuple[str, ...]
    segments: tuple[str, ...]
    landmarks: tuple[str, ...]
    rgb: np.ndarray
    radius_m: float
    soft_tissue_m: float
    identification: IdentificationRules | None = None
    hidden: HiddenMarkerConfig | None = None
    roles: dict[str, str] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.hidden is None:  # every marker set has one (see ``hidden``)
            object.__setattr__(self, "hidden", default_hidden(self.names, self.segments))

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
        return dataclasses.replace(self, rgb=rgb)


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
        identification=None if spec.identification is None else _identification(path, spec.identification, names),
        hidden=_hidden(path, spec, names),
        roles=_roles(path, spec.roles, names),
    )


def _roles(path: Path, spec: dict[str, str] | None, names: list[str]) -> dict[str, str]:
    """``roles:`` checked against :data:`ROLES` and the markers, in :data:`ROLES` order; without
    it, the markers named as in :data:`DEFAULT_ROLES` play their roles."""
    if spec is None:
        return {role: name for role, name in DEFAULT_ROLES.items() if name in names}
    unknown = [r for r in spec if r not in ROLES]
    if unknown:
        raise ContentError(f"{path}: roles: unknown role {unknown[0]!r}; the roles are {', '.join(ROLES)}")
    by_marker: dict[str, str] = {}
    for role, name in spec.items():
        if name not in names:
            raise ContentError(f"{path}: roles.{role}: unknown marker {name!r}; the markers are {', '.join(names)}")
        if name in by_marker:
            raise ContentError(f"{path}: roles: {name} plays both {by_marker[name]} and {role}; give each role its own marker")
        by_marker[name] = role
    default_role = {name: role for role, name in DEFAULT_ROLES.items()}
    for name in names:
        role = default_role.get(name)
        if role is not None and by_marker.get(name) != role:
            raise ContentError(
                f"{path}: marker {name} is the {role} marker's name in upper_limb_seated (marker files are read by it): "
                f"give it the role {role} or rename the marker"
            )
    return {role: spec[role] for role in ROLES if role in spec}


def default_hidden(names: Sequence[str], segments: Sequence[str]) -> HiddenMarkerConfig:
    """The configuration of a marker set without ``hidden_markers:``: equation 6, every marker of
    the same body segment a neighbour of weight 1, no rigid groups, no length checks."""
    weights = {n: {o: 1.0 for o, so in zip(names, segments) if so == s and o != n} for n, s in zip(names, segments)}
    return HiddenMarkerConfig(
        estimators=("neighbours",) * len(names), weights={n: w for n, w in weights.items() if w},
        velocity_decay_s=(0.15,) * len(names), rigid_groups=(), trunk=None, elbows=(), forearms=(),
        length_pairs=(), drift_tolerance_m=0.03, max_hidden_s=dict(DEFAULT_MAX_HIDDEN_S), max_unsupported_s=0.5,
    )


def _hidden(path: Path, spec: _MarkerSetSpec, names: list[str]) -> HiddenMarkerConfig:
    """Expand the side wildcards of ``hidden_markers:`` and check every name and estimator."""
    segments = [m.segment for m in spec.markers]
    if spec.hidden_markers is None:
        return default_hidden(names, segments)
    h = spec.hidden_markers
    known = set(names)
    letters = list(spec.identification.sides) if spec.identification is not None else []

    def sides_of(where: str, patterns: Sequence[str]) -> list[str]:
        """The side letters a group of patterns expands over ('' if it has no wildcard)."""
        if not any("*" in p or "#" in p for p in patterns):
            return [""]
        if not letters:
            raise ContentError(f"{path}: hidden_markers.{where}: '*' needs identification.sides (e.g. {{L: left, R: right}})")
        if any("#" in p for p in patterns) and len(letters) != 2:
            raise ContentError(f"{path}: hidden_markers.{where}: '#' (the other side) needs exactly two sides")
        return letters

    def expand(where: str, pattern: str, side: str) -> str:
        other = "".join(s for s in letters if s != side) if side else ""
        name = pattern.replace("*", side).replace("#", other)
        if not re.fullmatch(_PATTERN, pattern) or name not in known:
            raise ContentError(f"{path}: hidden_markers.{where}: unknown marker {name!r}; the markers are {', '.join(names)}")
        return name

    def groups(where: str, patterns: Sequence[str]) -> list[tuple[str, ...]]:
        out = []
        for side in sides_of(where, patterns):
            group = tuple(expand(where, p, side) for p in patterns)
            if len(set(group)) != len(group):
                raise ContentError(f"{path}: hidden_markers.{where}: a marker appears twice in {list(group)}")
            out.append(group)
        return out

    estimators = ["neighbours"] * len(names)
    decay = [h.velocity_decay_s] * len(names)
    weights: dict[str, dict[str, float]] = {}
    set_by: dict[str, str] = {}
    for pattern, m in h.markers.items():
        where = f"markers.{pattern}"
        for side in sides_of(where, [pattern, *m.neighbours]):
            name = expand(where, pattern, side)
            if name in set_by:
                raise ContentError(f"{path}: hidden_markers.{where}: {name} is already configured by {set_by[name]!r}")
            set_by[name] = pattern
            row = {expand(f"{where}.neighbours", k, side): s for k, s in m.neighbours.items()}
            if name in row:
                raise ContentError(f"{path}: hidden_markers.{where}.neighbours: {name} cannot be its own neighbour")
            i = names.index(name)
            estimators[i] = m.estimator
            if row:
                weights[name] = row
            if m.velocity_decay_s is not None:
                decay[i] = m.velocity_decay_s
    rigid = [g for i, pats in enumerate(h.rigid_groups) for g in groups(f"rigid_groups.{i}", pats)]
    if any(len(g) < 2 for g in rigid):
        raise ContentError(f"{path}: hidden_markers.rigid_groups: a rigid group needs at least two markers")
    elbows = [g for i, e in enumerate(h.elbows) for g in groups(f"elbows.{i}", [*e.markers, e.shoulder, *e.wrist])]
    forearms = [g for i, f in enumerate(h.forearms) for g in groups(f"forearms.{i}", [*f.markers, *f.elbow])]
    pairs = [g for i, p in enumerate(h.limits.length_pairs) for g in groups(f"limits.length_pairs.{i}", p)]
    trunk = None
    if h.trunk is not None:
        trunk = groups("trunk", [h.trunk.upper, h.trunk.lower, h.trunk.left, h.trunk.right])[0]
    in_elbow = {n for e in elbows for n in e[:2]}
    in_forearm = {n for f in forearms for n in f[:2]}
    for name, est in zip(names, estimators):
        if est == "hinge" and name not in in_elbow:
            raise ContentError(f"{path}: hidden_markers.markers.{set_by[name]}: estimator hinge needs {name} in an 'elbows' entry")
        if est == "forearm" and name not in in_forearm:
            raise ContentError(f"{path}: hidden_markers.markers.{set_by[name]}: estimator forearm needs {name} in a 'forearms' entry")
    # a marker the file does not configure: equation 6 over its own body segment
    fallback = default_hidden(names, segments).weights
    weights.update({n: row for n, row in fallback.items() if n not in set_by})
    return HiddenMarkerConfig(
        estimators=tuple(estimators),
        weights=weights,
        velocity_decay_s=tuple(decay),
        rigid_groups=tuple(rigid),
        trunk=trunk,
        elbows=tuple(elbows),
        forearms=tuple(forearms),
        length_pairs=tuple(pairs),
        drift_tolerance_m=h.limits.drift_tolerance_mm / 1000.0,
        max_hidden_s={**DEFAULT_MAX_HIDDEN_S, **h.limits.max_hidden_s},
        max_unsupported_s=h.limits.max_unsupported_s,
    )


def _identification(path: Path, spec: _IdentificationSpec, names: list[str]) -> IdentificationRules:
    """Expand the side wildcards and check every name against the marker set."""
    known = set(names)

    def check(where: str, name: str) -> str:
        if name not in known:
            raise ContentError(
                f"{path}: identification.{where}: unknown marker {name!r}; the markers are {', '.join(names)}"
            )
        return name

    for i, (left, right) in enumerate(spec.left_right_pairs):
        check(f"left_right_pairs.{i}", left)
        check(f"left_right_pairs.{i}", right)
    rules: list[OrderRule | DistanceRule] = []
    for i, r in enumerate(spec.rules):
        where = f"rules.{i}"
        text = r.order if r.order is not None else r.distance
        sided = "*" in text
        if r.along == "outward" and not sided:
            raise ContentError(f"{path}: identification.{where}: 'along: outward' needs the side wildcard '*' in the order")
        if sided and not spec.sides:
            raise ContentError(f"{path}: identification.{where}: '*' needs 'sides' (e.g. {{L: left, R: right}})")
        for letter, word in (spec.sides.items() if sided else [("", "")]):
            sep = "<" if r.order is not None else "-"
            groups = tuple(tuple(check(where, n.strip()) for n in g.split(",")) for g in text.replace("*", letter).split(sep))
            flat = [n for g in groups for n in g]
            if len(set(flat)) != len(flat):
                raise ContentError(f"{path}: identification.{where}: a marker appears twice in {text.replace('*', letter)!r}")
            message = r.message.replace("{side}", word).replace("*", letter)
            joined = f" {sep} ".join(", ".join(g) for g in groups)
            if r.order is not None:
                margin_mm = r.min_margin_mm if r.min_margin_mm is not None else spec.min_margin_mm
                sign = -1 if (r.along == "outward" and word == "left") else 1
                rules.append(OrderRule(f"{joined} along {r.along}", groups, _AXES[r.along], sign, margin_mm / 1000.0, message))
            else:
                lo, hi = r.within_mm
                rules.append(DistanceRule(f"{joined} within {lo:g}-{hi:g} mm", groups, lo / 1000.0, hi / 1000.0, message))
    return IdentificationRules(
        reference_pose=" ".join(spec.reference_pose.split()),
        rules=tuple(rules),
        left_right_pairs=tuple((a, b) for a, b in spec.left_right_pairs),
        max_turn_deg=spec.max_turn_deg,
    )
