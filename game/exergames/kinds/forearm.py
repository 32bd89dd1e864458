"""Turn the key: forearm pronation/supination with the elbow at the side.

A target is a lock angle on a dial beside the hand; the patient turns the palm down or up to it
and holds. The mouse's position across the view turns the forearm (as Q/E do); the panel shows
the dial (:meth:`game.scenes.game_play.GameScene.draw_gauge`).
"""

from __future__ import annotations

import numpy as np

from game.exergames.kinds import FOREARM_LIMIT_DEG, AngleGame, Aim, Framing, register
from game.exergames.targets import elbow_at_side_hand_m


class Forearm(AngleGame):
    name = "forearm"
    angle = "forearm_supination"
    direction_words = ("palm down", "palm up")
    # wide, from the head to the knees (a closer view filled it with the trunk, and llvmpipe pays
    # per pixel: 0.52 m cost ~7 ms more CPU per frame)
    framing = Framing(15.0, 10.0, 0.66, trunk_share=0.5, up_m=0.05, forward_m=0.10)

    def hand_m(self, target, frame) -> np.ndarray:
        return elbow_at_side_hand_m(frame, 0.0)

    def solid(self, target, frame):
        """The lock: a flat disc beside the hand, on the side the key must turn to."""
        out, up = frame.out, frame.trunk[:, 1]
        centre = target.hand_m + 0.10 * up + 0.02 * out
        return centre, np.stack([0.05 * out, 0.05 * up, 0.015 * frame.trunk[:, 2]], axis=1)

    def aim(self, aim: Aim, x_px: float, y_px: float):
        v = aim.view
        across = (x_px - v.x) / v.w * 2.0 - 1.0          # -1 at the view's left edge .. +1 at its right
        mirror = 1.0 if aim.side == "right" else -1.0    # as the gauge: the right arm's palm up to the right
        forearm = float(np.clip(mirror * across * 90.0, -FOREARM_LIMIT_DEG, FOREARM_LIMIT_DEG))
        return tuple(float(x) for x in elbow_at_side_hand_m(aim.frame, 0.0)), forearm

    def auto_input(self, player, target, dt_s: float):
        return player.hand_at(target.hand_m, forearm_rotation_deg=float(target.target.value_deg))

    def draw_readout(self, scene, canvas, x: float, y: float, right: float) -> float:
        return scene.draw_gauge(canvas, x, y, right)


register(Forearm())
