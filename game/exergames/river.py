"""The rotation game's river, as numbers: where the boat and the gates are (pure, no drawing).

The patient's measured shoulder rotation steers a boat across a river seen from above; the
river's banks are the ends of the measured range (internal rotation on one side, external on the
other, at the game's stretch fraction plus a margin), so the river *is* the patient's range. A
gate (two buoys) drifts down the river towards the boat at the place of its target rotation, its
width the target's tolerance; it cannot be passed before it reaches the boat
(:attr:`game.exergames.session.ActiveTarget.arrived`). At the boat, the boat sails through it
while it stays between the buoys (the hold), and is held back at the gate's line while it is not.

The screen is a mirror (``docs/AVATAR.md``): the right arm turning out moves the boat to the
right, the left arm turning out moves it to the left.

Positions are fractions: across the river 0 (left bank) .. 1 (right bank); along the river a
gate's distance ahead of the boat's bow, 1 at the far end of the visible river, 0 at the bow,
negative while the boat passes it (in boat lengths).
"""

from __future__ import annotations

from dataclasses import dataclass

#: Degrees of water beyond the stretch goal on each side (the boat is never at the very bank).
MARGIN_DEG = 6.0


@dataclass(frozen=True, slots=True)
class River:
    """The river of one patient's rotation range.

    Attributes:
        in_deg: the internal-rotation bank (degrees, negative).
        out_deg: the external-rotation bank (degrees, positive).
        side: the arm played; ``left`` puts external rotation on the left (mirror).
    """

    in_deg: float
    out_deg: float
    side: str = "right"

    @property
    def span_deg(self) -> float:
        return self.out_deg - self.in_deg

    def across(self, rotation_deg: float) -> float:
        """0..1 across the river (from the left bank on the screen) of a rotation, clamped to the banks."""
        f = (rotation_deg - self.in_deg) / self.span_deg
        f = min(max(f, 0.0), 1.0)
        return f if self.side == "right" else 1.0 - f

    def rotation_at(self, across: float) -> float:
        """The rotation (degrees) at ``across`` (0..1 from the left bank): the inverse of :meth:`across`."""
        f = min(max(across, 0.0), 1.0)
        f = f if self.side == "right" else 1.0 - f
        return self.in_deg + f * self.span_deg

    def width(self, degrees: float) -> float:
        """A rotation difference as a fraction of the river's width."""
        return abs(degrees) / self.span_deg


def river_for(limits, stretch_fraction: float, side: str) -> River:
    """The river of :class:`game.exergames.targets.RomLimits` (rotation: positive = external)."""
    return River(-(limits.negative_deg * stretch_fraction + MARGIN_DEG),
                 limits.positive_deg * stretch_fraction + MARGIN_DEG, side)


def gate_distance(target) -> float:
    """How far an :class:`game.exergames.session.ActiveTarget` gate is ahead of the boat's bow.

    1 when it appears at the far end, falling linearly to 0 when it arrives (``approach_s``);
    then minus the share held (0 .. -1 boat length) while the boat sails through it.
    """
    if not target.arrived:
        return 1.0 - target.age_s / target.approach_s
    return -target.hold_fraction
