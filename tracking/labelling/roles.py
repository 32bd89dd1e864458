"""Which marker stands for which body landmark, read from the marker set's YAML.

The body model of the labelling needs the trunk (upper and lower trunk markers, left and right
hip markers) and, per arm, the shoulder, the lateral and medial epicondyle and the radial and
ulnar styloid markers: the marker set's ``roles:`` (:data:`tracking.markerset.ROLES`), the same
roles the joint angles and the avatar read.
"""

from __future__ import annotations

from dataclasses import dataclass

from tracking.markerset import ROLES, MarkerSet


@dataclass(frozen=True, slots=True)
class ArmRoles:
    """Marker indices of one arm; ``sign`` +1 for the patient's right (+x), -1 for the left."""

    side: str
    sign: float
    shoulder: int
    lateral_epicondyle: int
    medial_epicondyle: int
    radial_styloid: int
    ulnar_styloid: int

    @property
    def markers(self) -> tuple[int, int, int, int, int]:
        """(shoulder, lateral epicondyle, medial epicondyle, radial styloid, ulnar styloid)."""
        return (self.shoulder, self.lateral_epicondyle, self.medial_epicondyle, self.radial_styloid,
                self.ulnar_styloid)


@dataclass(frozen=True, slots=True)
class BodyRoles:
    """The markers the body model of the labelling knows.

    Attributes:
        upper, lower: upper and lower trunk markers (sternum, xiphoid).
        left_hip, right_hip: the hip markers.
        arms: (right arm, left arm).
    """

    upper: int
    lower: int
    left_hip: int
    right_hip: int
    arms: tuple[ArmRoles, ArmRoles]

    @property
    def trunk(self) -> tuple[int, int, int, int]:
        return (self.upper, self.lower, self.left_hip, self.right_hip)

    @staticmethod
    def of(markerset: MarkerSet) -> "BodyRoles | None":
        """The roles of ``markerset``'s markers, or None when it has no identification rules or
        its roles do not name every marker of both arms and the trunk (the body model needs all)."""
        roles = markerset.roles
        if markerset.identification is None or len(roles) != len(ROLES) or markerset.n_markers != len(ROLES):
            return None
        ix = {role: markerset.index(name) for role, name in roles.items()}

        def arm(side: str, sign: float) -> ArmRoles:
            return ArmRoles(side, sign, *(ix[f"{side}_{part}"] for part in (
                "shoulder", "elbow_lateral", "elbow_medial", "wrist_radial", "wrist_ulnar")))

        return BodyRoles(ix["trunk_upper"], ix["trunk_lower"], ix["left_hip"], ix["right_hip"],
                         (arm("right", 1.0), arm("left", -1.0)))
