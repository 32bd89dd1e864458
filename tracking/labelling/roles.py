"""Which marker stands for which body landmark, read from the marker set's YAML.

The body model of the labelling needs the trunk (upper and lower trunk markers, left and right
hip markers) and, per arm, the shoulder, the lateral and medial epicondyle and the radial and
ulnar styloid markers. The marker set's ``hidden_markers`` section names them already (its
``trunk`` entry, and each ``elbows`` entry: ``markers: [lateral, medial]``, ``shoulder``,
``wrist: [radial, ulnar]``); the side of an arm is the side of its shoulder in
``identification.left_right_pairs``.
"""

from __future__ import annotations

from dataclasses import dataclass

from tracking.markerset import MarkerSet


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
        """The roles of ``markerset``'s markers, or None when its YAML does not name them all."""
        from tracking.hidden import estimator_config

        if markerset.identification is None or markerset.hidden is None:
            return None
        cfg = estimator_config(markerset)
        trunk, hinges = cfg.get("trunk"), cfg.get("hinges") or []
        if trunk is None or len(trunk) != 4:
            return None
        idx = {n: i for i, n in enumerate(markerset.names)}
        pairs = [(idx.get(a), idx.get(b)) for a, b in markerset.identification.left_right_pairs]
        left_of = {a: b for a, b in pairs}
        arms = {}
        for h in hinges:
            if len(h.wrists) != 2:
                continue
            if h.shoulder in left_of:
                side, sign = "left", -1.0
            elif h.shoulder in left_of.values():
                side, sign = "right", 1.0
            else:
                continue
            # each elbow is listed once per marker: the first entry lists (lateral, medial)
            arms.setdefault(side, ArmRoles(side, sign, h.shoulder, h.marker, h.partner, h.wrists[0], h.wrists[1]))
        if set(arms) != {"left", "right"}:
            return None
        upper, lower, left_hip, right_hip = (int(k) for k in trunk)
        used = [upper, lower, left_hip, right_hip, *arms["right"].markers, *arms["left"].markers]
        if len(set(used)) != len(used) or len(used) != markerset.n_markers:
            return None
        return BodyRoles(upper, lower, left_hip, right_hip, (arms["right"], arms["left"]))
