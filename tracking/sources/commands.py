"""What a reader tells a source while it runs: the simulated patient's motion and input, and a new
identification (the patient takes the reference pose again).

The live tracker's game sends them through its control pipe (:mod:`tracking.live.protocol`
re-exports them); a source applies them in :meth:`tracking.sources.base.FrameSource.handle`.
"""

from __future__ import annotations

from dataclasses import dataclass

from calibration.errors import RehabError


class LiveError(RehabError):
    """The live tracker cannot start or was asked for something it cannot do (a motion of a
    recording)."""


@dataclass(frozen=True, slots=True)
class PatientInput:
    """Drives the interactive simulated patient (``SourceConfig.motion`` None).

    Attributes:
        side: the active arm, ``"right"`` or ``"left"``.
        hand_target_m: where the active hand (the wrist centre) should go, world metres
            (docs/INTERFACES.md frame); None: the arm keeps its pose relative to the trunk.
        forearm_rotation_deg: forearm supination (+, palm up) / pronation (-) of the active arm;
            0 = thumb up.
        trunk_forward_lean_deg: + leaning forward.
        trunk_lateral_lean_deg: + leaning to the patient's right.
    """

    side: str = "right"
    hand_target_m: tuple[float, float, float] | None = None
    forearm_rotation_deg: float = 0.0
    trunk_forward_lean_deg: float = 0.0
    trunk_lateral_lean_deg: float = 0.0


@dataclass(frozen=True, slots=True)
class Reidentify:
    """Identify the markers again (the patient takes the reference pose)."""


@dataclass(frozen=True, slots=True)
class SetMotion:
    """Play a scripted motion in a loop (from its start), or None for the interactive patient."""

    name: str | None


@dataclass(frozen=True, slots=True)
class SetPatientInput:
    """New input for the interactive patient."""

    value: PatientInput
