"""A game kind that is not built in, as one module: bend the elbow to the marked angle.

It shows what a new kind takes (docs/GAMES.md "A new game"): a :class:`GameKind` subclass
registered by name, plus a game YAML naming it (``tests/game/test_game_kinds.py`` writes one).
"""

from __future__ import annotations

from game.exergames.kinds import AngleGame, register
from game.exergames.targets import elbow_at_side_hand_m


class ElbowBend(AngleGame):
    name = "elbow_bend"
    angle = "elbow_flexion"
    needs_posture = False
    direction_words = ("straight", "bent")

    def place(self, limits, low_fraction, top_fraction, rng, *, direction, planes_deg, elbow_range_deg):
        # always a bend (the elbow does not flex below 0): the positive direction only
        return super().place(limits, low_fraction, top_fraction, rng, direction=1, planes_deg=planes_deg,
                             elbow_range_deg=elbow_range_deg)

    def hand_m(self, target, frame):
        return elbow_at_side_hand_m(frame, 0.0)

    def draw_readout(self, scene, canvas, x, y, right):
        return scene.draw_gauge(canvas, x, y, right)


KIND = register(ElbowBend())
