"""The automatic demo: the simulated patient plays the game by itself.

:class:`AutoPlayer` looks at the game as a patient would (where the target is, what the gauge
shows) and answers with a :class:`tracking.live.PatientInput` for the interactive simulated patient
in the tracker process, who solves the arm to it; the game then scores what the tracker
*measures*, never this input. Like a person, it reacts after a short delay and goes back to a
rest position (elbow at the side, forearm forward) between targets.

Rotation: the simulated patient only takes a hand position, and its arm solver swings the elbow a
little out as the hand goes out, so a hand placed at rotation ``r`` measures less than ``r``.
The player corrects itself as a patient watching the gauge would: the command integrates the
difference between the target and the *measured* rotation (and remembers the offset for the
next gate).
"""

from __future__ import annotations

import math

from game.exergames.session import GameSession, Phase
from game.exergames.targets import elbow_at_side_hand_m
from tracking.live import PatientInput

#: Seconds between a target appearing and the hand starting to move.
REACTION_S = 0.35
#: Rotation correction: command change per second per degree of error.
CORRECTION_GAIN_PER_S = 1.5
#: Largest command beyond the target (degrees).
MAX_CORRECTION_DEG = 45.0


class AutoPlayer:
    """Turns a :class:`GameSession` into the simulated patient's input.

    Args:
        session: the game being played.
        reaction_s: delay before moving to a new target.
    """

    def __init__(self, session: GameSession, reaction_s: float = REACTION_S) -> None:
        self.session = session
        self.reaction_s = reaction_s
        self.offset_deg = 0.0        # command - measured, learned on the previous targets
        self._target = None
        self._command_deg = 0.0

    def patient_input(self, dt_s: float = 0.0):
        """The :class:`tracking.live.PatientInput` for the game's current state, ``dt_s`` after the last call."""
        s = self.session
        frame = s.frame if s.frame is not None else (s.last.frame if s.last is not None else None)
        if frame is None:
            # Before the arm is seen: keep still (the tracker identifies the markers in the reference pose).
            return PatientInput(side=s.side)
        t = s.target
        if s.phase is not Phase.PLAYING or t is None or t.age_s < self.reaction_s:
            rest = elbow_at_side_hand_m(frame, 0.0)
            return PatientInput(side=s.side, hand_target_m=tuple(float(x) for x in rest))
        return s.kind.auto_input(self, t, dt_s)

    def hand_at(self, hand_m, forearm_rotation_deg: float = 0.0):
        """The input that puts the hand at ``hand_m`` (and turns the forearm): what a game kind
        whose target is a place asks for."""
        return PatientInput(side=self.session.side, hand_target_m=tuple(float(x) for x in hand_m),
                            forearm_rotation_deg=forearm_rotation_deg)

    def steer_by_measure(self, t, dt_s: float):
        """The input that brings the *measured* rotation to the target's: the command integrates
        the difference (the module's docstring), the elbow at the side."""
        s = self.session
        goal = t.target.value_deg
        if t is not self._target:
            self._target = t
            self._command_deg = goal + self.offset_deg
        measured = s.value_now()
        if math.isfinite(measured) and not s.paused:
            self._command_deg += CORRECTION_GAIN_PER_S * (goal - measured) * dt_s
            self._command_deg = min(max(self._command_deg, goal - MAX_CORRECTION_DEG), goal + MAX_CORRECTION_DEG)
            if abs(goal - measured) < t.size:
                self.offset_deg = self._command_deg - goal
        hand = elbow_at_side_hand_m(s.frame if s.frame is not None else s.last.frame, self._command_deg)
        return PatientInput(side=s.side, hand_target_m=tuple(float(x) for x in hand))
