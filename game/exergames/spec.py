"""Exercise games as content: ``content/games/<name>.yaml``, validated once at load.

A game names the motion it exercises (``kind``, a registered :mod:`game.exergames.kinds` module), the stored ROM tests that bound its targets
(with a cautious default for a patient who has none yet), where targets go inside that range
(from ``comfort_fraction`` of the measured maximum up to a top that rises with the difficulty, at
most ``stretch_fraction``: slightly beyond the maximum, the stretch goal), how difficulty adapts
to the success rate between the therapist's limits, the posture the game needs, the compensation
limits that pause scoring, and how long a session lasts.

Kinds (one module each in ``game/exergames/kinds/``): ``reach`` (the hand touches targets in
front of the patient), ``rotation`` (shoulder rotation with the elbow at the side steers a boat
through gates), ``forearm`` (pronation/supination: turn the key to the marked angle).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import pydantic

from game.exergames.kinds import GameKind, game_kind
from tracking.content_loader import StrictModel, available, load_model, resolve

KIND = "games"


class RomBound(StrictModel):
    """One stored ROM test that bounds the targets, with the value used when none is stored."""

    test: str = pydantic.Field(pattern=r"^[a-z_]+$", description="content/rom_tests name, e.g. shoulder_flexion")
    default_deg: float = pydantic.Field(gt=0, le=180, description="used when the patient has no stored result")


class Ramp(StrictModel):
    """A value at difficulty 0 and at difficulty 1 (linear in between)."""

    easy: float
    hard: float

    def at(self, level: float) -> float:
        return self.easy + (self.hard - self.easy) * min(max(level, 0.0), 1.0)


class Difficulty(StrictModel):
    """How the game adapts: a level in 0..1 moves by ``step`` with the recent success rate."""

    start: float = pydantic.Field(0.3, ge=0, le=1, description="level of a first session")
    min_level: float = pydantic.Field(0.0, ge=0, le=1, description="therapist's lower limit")
    max_level: float = pydantic.Field(1.0, ge=0, le=1, description="therapist's upper limit")
    step: float = pydantic.Field(0.15, gt=0, le=1, description="level change per adaptation")
    window: int = pydantic.Field(4, ge=2, le=20, description="targets judged together")
    raise_above: float = pydantic.Field(0.75, gt=0, le=1, description="success rate that raises the level")
    lower_below: float = pydantic.Field(0.5, ge=0, lt=1, description="success rate that lowers the level")
    top_fraction: Ramp = pydantic.Field(description="top of the target range as a fraction of the measured maximum")
    size: Ramp = pydantic.Field(description="target radius (m, reach) or tolerance (deg, rotation and forearm)")
    hold_s: Ramp = pydantic.Field(description="time to hold a target to collect it")
    time_limit_s: Ramp = pydantic.Field(description="time a target waits before it is missed")
    approach_share: float = pydantic.Field(
        0.0, ge=0, le=0.6, description="rotation: share of a gate's time limit it drifts down the river to the boat "
        "(it cannot be passed before it arrives); 0 for the other kinds")

    @pydantic.model_validator(mode="after")
    def _limits(self) -> "Difficulty":
        if not self.min_level <= self.start <= self.max_level:
            raise ValueError(f"start {self.start} must lie between min_level {self.min_level} and max_level {self.max_level}")
        if self.lower_below >= self.raise_above:
            raise ValueError("lower_below must be smaller than raise_above")
        return self


class TherapistLimits(StrictModel):
    """The therapist's limits on what the adaptation may ask (``limits:`` in the YAML, or set per patient).

    Each is optional (None: the difficulty ramp alone decides). The level still adapts from the
    success rate; these bound the values it maps to, whatever the level.
    """

    min_level: float | None = pydantic.Field(
        None, ge=0, le=1, description="lowest level (0..1): the session starts there at least and never falls below")
    max_level: float | None = pydantic.Field(None, ge=0, le=1, description="highest level (0..1) the adaptation reaches")
    max_range: float | None = pydantic.Field(
        None, gt=0, le=1.3, description="targets never beyond this fraction of the measured maximum")
    min_size: float | None = pydantic.Field(
        None, gt=0, description="smallest target: radius (m, reach) or tolerance (deg, rotation and forearm)")
    max_hold_s: float | None = pydantic.Field(None, gt=0, le=10, description="longest time a target must be held")
    min_time_s: float | None = pydantic.Field(
        None, gt=0, le=120, description="the speed: the least time a target waits before it is missed")


class Posture(StrictModel):
    """The arm position the rotation games need (elbow at the side, bent): outside it scoring pauses."""

    elbow_flexion_deg: tuple[float, float] = pydantic.Field(description="allowed elbow flexion range")
    max_shoulder_elevation_deg: float = pydantic.Field(gt=0, le=90, description="the elbow stays at the side")


class Compensation(StrictModel):
    """Limits of the compensations that pause scoring (changes from the posture at the start)."""

    trunk_lean_deg: float = pydantic.Field(10.0, gt=0, le=45, description="forward and lateral lean together")
    shoulder_hiking_mm: float = pydantic.Field(20.0, gt=0, le=100,
                                               description="shoulder rise beyond the normal rise with elevation")


class GameSpec(StrictModel):
    """One exercise game (``content/games/<name>.yaml``)."""

    name: str = pydantic.Field(pattern=r"^[a-z0-9_]+$")
    title: str = pydantic.Field(min_length=2)
    kind: str = pydantic.Field(description="the game kind (game/exergames/kinds), e.g. reach, rotation, forearm")
    exercises: str = pydantic.Field(min_length=5, description="the motions exercised, in plain words")
    instructions: str = pydantic.Field(min_length=10, description="what the patient does, in plain words")
    rom: dict[str, RomBound] = pydantic.Field(
        description="the kind's keys: reach: the tests of the sagittal (flexion) and frontal (abduction) planes; "
        "rotation and forearm: the tests of the positive (external rotation, supination) and negative direction")
    elbow: RomBound | None = pydantic.Field(None, description="reach: the elbow flexion test (bends the arm)")
    comfort_fraction: float = pydantic.Field(0.5, gt=0, le=1, description="lowest target, fraction of the maximum")
    stretch_fraction: float = pydantic.Field(1.05, ge=1, le=1.3, description="highest target ever, fraction of the maximum")
    planes_deg: tuple[float, ...] = pydantic.Field((0.0,), description="reach: elevation planes, 0 flexion .. 90 abduction")
    elbow_flexion_deg: tuple[float, float] = pydantic.Field((20.0, 40.0), description="reach: elbow bend of a target")
    difficulty: Difficulty
    limits: TherapistLimits = pydantic.Field(TherapistLimits(), description="the content's therapist limits "
                                             "(the game menu overrides them per patient)")
    posture: Posture | None = None
    compensation: Compensation = Compensation()
    duration_s: float = pydantic.Field(90.0, gt=5, le=1800, description="active play time of a session")
    colour: tuple[int, int, int] = pydantic.Field((255, 196, 64), description="sRGB of the targets")

    @pydantic.field_validator("kind")
    @classmethod
    def _known_kind(cls, value: str) -> str:
        game_kind(value)   # ValueError naming the known kinds
        return value

    @property
    def game_kind(self) -> GameKind:
        """The registered kind of this game (:mod:`game.exergames.kinds`)."""
        return game_kind(self.kind)

    @pydantic.model_validator(mode="after")
    def _consistent(self) -> "GameSpec":
        if self.comfort_fraction >= self.stretch_fraction:
            raise ValueError("comfort_fraction must be smaller than stretch_fraction")
        for ramp in (self.difficulty.top_fraction.easy, self.difficulty.top_fraction.hard):
            if not self.comfort_fraction < ramp <= self.stretch_fraction:
                raise ValueError(f"difficulty.top_fraction {ramp} must lie in (comfort_fraction, stretch_fraction]")
        d, kind = self.difficulty, self.game_kind
        if kind.river != (d.approach_share > 0):
            raise ValueError("difficulty.approach_share (the gates drift down the river) is needed by a game whose "
                             "gates drift down a river (rotation) and only by it")
        for end in ("easy", "hard"):
            moving = getattr(d.time_limit_s, end) * d.approach_share
            if getattr(d.time_limit_s, end) <= moving + getattr(d.hold_s, end):
                raise ValueError(f"difficulty.time_limit_s.{end} leaves no time to hold the target "
                                 "(approach and hold take all of it)")
        check_limits(self, self.limits)
        need = set(kind.rom_keys)
        if set(self.rom) != need:
            raise ValueError(f"a {self.kind} game's rom needs exactly the keys {sorted(need)}")
        if kind.needs_elbow and self.elbow is None:
            raise ValueError(f"a {self.kind} game needs 'elbow' (the elbow flexion test)")
        if kind.needs_posture and self.posture is None:
            raise ValueError(f"a {self.kind} game needs 'posture' (elbow at the side)")
        kind.check(self)
        return self


def limit_bounds(spec: GameSpec) -> dict[str, tuple[float, float]]:
    """The values each therapist limit may take for this game (lowest, highest)."""
    d = spec.difficulty
    size_lo, size_hi = sorted((d.size.easy, d.size.hard))
    time_lo, time_hi = sorted((d.time_limit_s.easy, d.time_limit_s.hard))
    hold_lo, hold_hi = sorted((d.hold_s.easy, d.hold_s.hard))
    return {
        "min_level": (0.0, 1.0),
        "max_level": (0.0, 1.0),
        "max_range": (round(spec.comfort_fraction + 0.05, 4), spec.stretch_fraction),
        "min_size": (size_lo, 2.0 * size_hi),
        "max_hold_s": (min(0.2, hold_lo), hold_hi),
        "min_time_s": (time_lo, 2.0 * time_hi),
    }


def check_limits(spec: GameSpec, limits: TherapistLimits) -> TherapistLimits:
    """``limits`` if every value lies within :func:`limit_bounds`; ValueError naming the first that does not."""
    for key, (lo, hi) in limit_bounds(spec).items():
        value = getattr(limits, key)
        if value is not None and not lo - 1e-9 <= value <= hi + 1e-9:
            raise ValueError(f"limits.{key} {value:g} must lie in {lo:g}..{hi:g} for the game {spec.name}")
    return limits


def available_games() -> list[str]:
    return available(KIND)


@lru_cache(maxsize=64)
def _load(path: Path) -> GameSpec:
    return load_model(path, GameSpec)


def load_game(name_or_path: str | Path) -> GameSpec:
    """A built-in game by name or a YAML file; :class:`tracking.errors.ContentError` otherwise."""
    return _load(resolve(KIND, name_or_path).resolve())


def load_all_games() -> list[GameSpec]:
    return [load_game(n) for n in available_games()]
