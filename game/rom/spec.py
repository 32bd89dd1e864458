"""ROM tests as content: ``content/rom_tests/<name>.yaml``, validated once at load.

A ROM test says which angle of ``docs/JOINT_ANGLES.md`` it reads (an arm angle; the side is
chosen when the test runs) and in which direction, the start position in plain words and as angle
ranges that the system checks, the instructions for the patient, the compensations to watch (and
the ones the system checks itself), and the reference (normal) values of each standard, kept apart:
every reference names the test position it was measured in, and a reference for another position
is never shown as this test's normal value (e.g. external rotation: JARM 60 with the arm at the
side, AAOS 90 at 90 degrees of abduction).

Every result of these tests is *active* ROM (the patient moves the limb; nobody helps).
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Literal

import pydantic

from calibration.errors import RehabError
from tracking.angles import ARM_ANGLES, SIDES
from tracking.content_loader import StrictModel, available, load_model, resolve

#: The reference standards. Their tables are never mixed: a result is labelled with one of them.
STANDARDS: dict[str, str] = {
    "jarm": "JARM/JOA (Japanese Association of Rehabilitation Medicine and Japanese Orthopaedic "
            "Association, joint ROM display and measurement method, 1995, revised 2022)",
    "aaos": "AAOS (American Academy of Orthopaedic Surgeons, Joint Motion: Method of Measuring "
            "and Recording, 1965)",
}

#: Every stored result is active ROM (the patient's own movement).
MODE_ACTIVE = "active"

TRUNK_ANGLES: tuple[str, ...] = ("trunk_forward_lean", "trunk_lateral_lean")

KIND = "rom_tests"


class _Position(StrictModel):
    id: str = pydantic.Field(pattern=r"^[a-z0-9_]+$", description="short key compared between test and reference")
    words: str = pydantic.Field(min_length=10, description="the position in plain words, for the therapist")


class _Reference(StrictModel):
    value_deg: float = pydantic.Field(gt=0, le=180, description="the standard's normal value (degrees, positive)")
    position: str = pydantic.Field(pattern=r"^[a-z0-9_]+$", description="id of the test position it was measured in")
    position_words: str | None = pydantic.Field(None, description="plain words, when the position is not this test's")


class _Compensation(StrictModel):
    kind: Literal["trunk_lean", "shoulder_hiking", "angle_change"]
    max_deg: float | None = pydantic.Field(None, gt=0, le=90, description="trunk_lean / angle_change limit")
    angle: str | None = pydantic.Field(None, description="angle_change: the arm angle that must stay near its start value")
    max_m: float | None = pydantic.Field(None, gt=0, le=0.2, description="shoulder_hiking: rise beyond the normal rhythm")
    rhythm_m_per_deg: float = pydantic.Field(
        0.0004, ge=0, le=0.002, description="shoulder_hiking: normal acromion rise per degree of arm elevation")
    rhythm_from_deg: float = pydantic.Field(30.0, ge=0, le=180, description="shoulder_hiking: the rise starts here")
    rhythm_max_m: float = pydantic.Field(0.035, ge=0, le=0.1, description="shoulder_hiking: the normal rise stops growing")
    words: str = pydantic.Field(min_length=5, description="what the patient did, in plain words")

    @pydantic.model_validator(mode="after")
    def _fields_of_kind(self):
        need = {"trunk_lean": ("max_deg",), "shoulder_hiking": ("max_m",), "angle_change": ("max_deg", "angle")}[self.kind]
        missing = [k for k in need if getattr(self, k) is None]
        if missing:
            raise ValueError(f"a {self.kind} compensation needs {', '.join(missing)}")
        if self.angle is not None and self.angle not in ARM_ANGLES:
            raise ValueError(f"angle {self.angle!r} is not an arm angle of docs/JOINT_ANGLES.md: one of {list(ARM_ANGLES)}")
        return self


class _Start(StrictModel):
    hold_s: float = pydantic.Field(0.5, ge=0, le=5, description="how long the start position must be held")
    angles: dict[str, tuple[float, float]] = pydantic.Field(
        min_length=1, description="arm angles of the tested side or trunk angles -> [min, max] degrees")

    @pydantic.field_validator("angles")
    @classmethod
    def _known_angles(cls, value):
        for name, (lo, hi) in value.items():
            if name not in ARM_ANGLES and name not in TRUNK_ANGLES:
                raise ValueError(f"{name!r} is not an arm or trunk angle of docs/JOINT_ANGLES.md")
            if lo >= hi:
                raise ValueError(f"{name}: the range [{lo}, {hi}] is empty")
        return value


class _Sdc(StrictModel):
    sdc95_deg: float = pydantic.Field(gt=0, le=90, description="smallest detectable change, 1.96 * sqrt(2) * SEM")
    sem_deg: float = pydantic.Field(gt=0, le=45, description="standard error of measurement it came from")
    n: int = pydantic.Field(ge=3, le=100000, description="sessions it was measured on")
    side: Literal["right", "left"] = pydantic.Field(description="the side measured")
    seeds: str = pydantic.Field(pattern=r"^[0-9]+-[0-9]+$", description="first-last seed of the simulated sessions")
    measured: datetime.date = pydantic.Field(description="date of the measurement (YYYY-MM-DD)")

    @pydantic.model_validator(mode="after")
    def _consistent(self):
        if abs(self.sdc95_deg - 1.96 * 2 ** 0.5 * self.sem_deg) > 0.1 + 1e-9:
            raise ValueError(f"sdc95_deg {self.sdc95_deg} is not 1.96 * sqrt(2) * sem_deg {self.sem_deg}")
        first, last = (int(x) for x in self.seeds.split("-"))
        if last - first + 1 < self.n:
            raise ValueError(f"seeds {self.seeds} are fewer than n {self.n}")
        return self


class _RomTestSpec(StrictModel):
    title: str = pydantic.Field(min_length=3)
    angle: str = pydantic.Field(description="the arm angle of docs/JOINT_ANGLES.md the test reads")
    direction: Literal[1, -1] = pydantic.Field(description="+1 reads the angle, -1 its negative (extension = -flexion)")
    sides: tuple[Literal["right", "left"], ...] = pydantic.Field(("right", "left"), min_length=1)
    position: _Position
    instructions: str = pydantic.Field(min_length=10, description="what the patient is told, in plain words")
    start: _Start
    min_range_deg: float = pydantic.Field(15.0, gt=0, le=90, description="a movement smaller than this is not a test")
    max_duration_s: float = pydantic.Field(30.0, gt=0, le=300, description="recording stops after this long")
    watch: tuple[str, ...] = pydantic.Field(min_length=1, description="compensations the therapist watches for")
    compensations: tuple[_Compensation, ...] = ()
    references: dict[Literal["jarm", "aaos"], _Reference] = pydantic.Field(min_length=1)
    simulated_motion: dict[Literal["right", "left"], str] = pydantic.Field(
        default_factory=dict, description="built-in motion of the simulated patient that performs the test")
    sdc: _Sdc | None = pydantic.Field(
        None, description="smallest detectable change measured on the simulated patient (rehab rom-sdc; docs/ROM.md)")

    @pydantic.field_validator("angle")
    @classmethod
    def _arm_angle(cls, value):
        if value not in ARM_ANGLES:
            raise ValueError(f"{value!r} is not an arm angle of docs/JOINT_ANGLES.md: one of {list(ARM_ANGLES)}")
        return value


@dataclass(frozen=True, slots=True)
class Compensation:
    """One compensation the system checks (see :class:`game.rom.session.RomTestSession`).

    Attributes:
        kind: ``trunk_lean`` (trunk lean change from the start, any direction, degrees),
            ``shoulder_hiking`` (the tested shoulder's marker rising relative to the sternum, along
            the trunk, beyond the normal rise with arm elevation, metres) or ``angle_change``
            (another arm angle of the tested side leaving its start value, degrees).
        limit: the threshold (degrees, or metres for shoulder hiking).
        angle: the arm angle of ``angle_change`` ("" otherwise).
        rhythm_m_per_deg, rhythm_from_deg, rhythm_max_m: the normal acromion rise allowed for
            shoulder hiking: ``min(rhythm_max_m, rhythm_m_per_deg * max(0, elevation - from))``.
        words: what the patient did, in plain words.
    """

    kind: str
    limit: float
    angle: str
    rhythm_m_per_deg: float
    rhythm_from_deg: float
    rhythm_max_m: float
    words: str


@dataclass(frozen=True, slots=True)
class Reference:
    """A standard's normal value for a test, with the position it was measured in.

    Attributes:
        standard: ``jarm`` or ``aaos``.
        value_deg: the normal value in degrees.
        position: the id of the position of the reference measurement.
        comparable: True if that is the test's own position (only then is it this test's norm).
        position_words: the reference's position in plain words.
    """

    standard: str
    value_deg: float
    position: str
    comparable: bool
    position_words: str

    def label(self) -> str:
        """One line for a therapist, e.g. ``JARM 60`` or ``AAOS 90 (at 90 degrees abduction: another position)``."""
        text = f"{self.standard.upper()} {self.value_deg:g}"
        return text if self.comparable else f"{text} ({self.position_words}: another position, not comparable)"


@dataclass(frozen=True, slots=True)
class RomTest:
    """A validated ROM test definition (one content file; both sides).

    Attributes:
        name: the file stem, e.g. ``shoulder_flexion``.
        title: e.g. ``Shoulder flexion``.
        angle: the arm angle it reads (e.g. ``shoulder_flexion``); per side ``f"{side}_{angle}"``.
        direction: +1 or -1; the test value is ``direction * angle``.
        sides: the sides it is defined for.
        position_id, position_words: the test position.
        instructions: for the patient.
        start_angles: angle -> (min, max) degrees that define the start position (arm angles of the
            tested side, or trunk angles).
        start_hold_s: how long the start position must be held before recording starts.
        min_range_deg: smallest movement from the start that counts as a test.
        max_duration_s: recording stops after this long.
        watch: compensations to watch for, in plain words.
        compensations: the ones the system checks.
        references: standard -> :class:`Reference`.
        simulated_motion: side -> built-in motion of the simulated patient performing the test.
        sdc_deg: the smallest detectable change (SDC95, degrees) measured on the simulated patient
            with ``rehab rom-sdc``; None when not measured. A change between two sessions is real
            only beyond it (:func:`game.rom.sdc.change_words`).
    """

    name: str
    title: str
    angle: str
    direction: int
    sides: tuple[str, ...]
    position_id: str
    position_words: str
    instructions: str
    start_angles: dict[str, tuple[float, float]]
    start_hold_s: float
    min_range_deg: float
    max_duration_s: float
    watch: tuple[str, ...]
    compensations: tuple[Compensation, ...]
    references: dict[str, Reference]
    simulated_motion: dict[str, str]
    sdc_deg: float | None = None

    def angle_name(self, side: str) -> str:
        """The column of docs/JOINT_ANGLES.md read on ``side``, e.g. ``right_shoulder_flexion``."""
        return f"{side}_{self.angle}"

    def reference(self, standard: str) -> Reference | None:
        """The standard's reference for this test, or None if the standard has no value for it."""
        return self.references.get(standard)

    def normal_deg(self, standard: str) -> float | None:
        """The normal value of ``standard`` for this test's position (None if none or another position)."""
        ref = self.references.get(standard)
        return ref.value_deg if ref is not None and ref.comparable else None


def _from_spec(name: str, spec: _RomTestSpec) -> RomTest:
    refs = {
        std: Reference(std, r.value_deg, r.position, r.position == spec.position.id,
                       spec.position.words if r.position == spec.position.id else (r.position_words or r.position.replace("_", " ")))
        for std, r in spec.references.items()
    }
    comps = tuple(
        Compensation(c.kind, float(c.max_m if c.kind == "shoulder_hiking" else c.max_deg), c.angle or "",
                     c.rhythm_m_per_deg, c.rhythm_from_deg, c.rhythm_max_m, c.words)
        for c in spec.compensations
    )
    return RomTest(
        name=name, title=spec.title, angle=spec.angle, direction=int(spec.direction), sides=tuple(spec.sides),
        position_id=spec.position.id, position_words=spec.position.words, instructions=spec.instructions,
        start_angles={k: (float(lo), float(hi)) for k, (lo, hi) in spec.start.angles.items()},
        start_hold_s=spec.start.hold_s, min_range_deg=spec.min_range_deg, max_duration_s=spec.max_duration_s,
        watch=tuple(spec.watch), compensations=comps, references=refs, simulated_motion=dict(spec.simulated_motion),
        sdc_deg=None if spec.sdc is None else float(spec.sdc.sdc95_deg),
    )


def available_rom_tests() -> list[str]:
    """Names of the built-in ROM tests."""
    return available(KIND)


@lru_cache(maxsize=64)
def _load_path(path: Path) -> RomTest:
    stem = path.stem
    return _from_spec(stem, load_model(path, _RomTestSpec))


def load_rom_test(name_or_path: str | Path) -> RomTest:
    """A built-in test name (``shoulder_flexion``) or a YAML path -> :class:`RomTest`.

    Raises:
        tracking.errors.ContentError: unknown name, or a file that does not validate (one line
            naming the file and key).
    """
    return _load_path(resolve(KIND, name_or_path).resolve())


def load_all_rom_tests() -> list[RomTest]:
    """Every built-in ROM test, in name order."""
    return [load_rom_test(n) for n in available_rom_tests()]


def check_side(test: RomTest, side: str) -> None:
    """Raise a one-line RehabError if ``side`` is not one of the test's sides."""
    if side not in SIDES or side not in test.sides:
        raise RehabError(f"side {side!r}: the test {test.name} is defined for {', '.join(test.sides)}")


def check_standard(standard: str) -> None:
    """Raise a one-line RehabError if ``standard`` is not a known standard."""
    if standard not in STANDARDS:
        raise RehabError(f"standard {standard!r}: choose one of {', '.join(STANDARDS)}")
