"""Sail through the gates: shoulder external/internal rotation with the elbow at the side.

The forearm steers a boat across a river whose banks are the measured range
(:mod:`game.exergames.river`); a target is a gate at a rotation, drifting down to the boat. The
mouse puts the hand where the pointer is across the view, the forearm swinging within the river's
banks; the automatic demo corrects itself from the measured rotation
(:meth:`game.exergames.autoplay.AutoPlayer.steer_by_measure`).
"""

from __future__ import annotations

import math

import numpy as np

from game.exergames.kinds import AngleGame, Aim, Framing, register
from game.exergames.targets import elbow_at_side_hand_m
from game.gfx import theme
from game.gfx.view3d import project_px


class Rotation(AngleGame):
    name = "rotation"
    angle = "shoulder_external_rotation"
    river = True
    direction_words = ("in", "out")
    # the trunk and the forearm in front of it, from higher up and a little towards the active side
    # (the forearm swings out in a horizontal plane)
    framing = Framing(15.0, 28.0, 0.52, trunk_share=0.5, up_m=0.05, forward_m=0.10, aside_m=0.10)

    def hand_m(self, target, frame) -> np.ndarray:
        return elbow_at_side_hand_m(frame, target.value_deg)

    def aim(self, aim: Aim, x_px: float, y_px: float):
        # the rotation (within the river's banks) whose hand is drawn nearest the pointer, across
        rotations = np.arange(aim.river.in_deg, aim.river.out_deg + 0.5, 1.0)
        hands = np.array([elbow_at_side_hand_m(aim.frame, r) for r in rotations])
        xs = project_px(hands, aim.view_proj, aim.view)[:, 0]
        if not np.isfinite(xs).any():
            return None, None
        rotation = float(rotations[np.nanargmin(np.abs(xs - x_px))])
        return tuple(float(x) for x in elbow_at_side_hand_m(aim.frame, rotation)), None

    def auto_input(self, player, target, dt_s: float):
        return player.steer_by_measure(target, dt_s)

    def draw_readout(self, scene, canvas, x: float, y: float, right: float) -> float:
        v = scene.session.value_now()
        if math.isfinite(v):
            words = self.direction_words[1] if v >= 0 else self.direction_words[0]
            canvas.text(f"Turned {abs(round(v)):d}\N{DEGREE SIGN} {words}", (x, y), round(theme.BODY * scene.scale),
                        theme.TEXT)
        return y + 50 * scene.scale


register(Rotation())
