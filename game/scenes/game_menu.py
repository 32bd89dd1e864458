"""Choose an exercise game for a patient: the games of ``content/games`` in large type.

Up/Down choose, Left/Right switch the arm, Q/E lower/raise the therapist's highest level (the
difficulty adapts up to it), M switches the automatic demo (the simulated patient plays by
itself), Enter starts, Esc goes back; mouse: hover and click.
"""

from __future__ import annotations

from typing import Callable, Sequence

from game.app import BaseScene, Frame
from game.exergames.spec import GameSpec, load_all_games
from game.gfx import theme
from game.input import Action, InputEvent, Pointer, PointerKind, Press


class ChooseGameScene(BaseScene):
    """The list of games; Enter opens ``open_game(spec, patient_id, side=, auto=, max_level=)`` on top.

    Args:
        patient_id: the patient who plays.
        open_game: makes the game scene.
        side: the arm first chosen.
        games: the games offered (default: every built-in game).
        max_level: the therapist's highest level, 1..10 (None: each game's own limit).
    """

    def __init__(self, patient_id: str, open_game: Callable[..., BaseScene], *, side: str = "right",
                 games: Sequence[GameSpec] | None = None, max_level: int | None = None) -> None:
        self.patient_id = patient_id
        self.open_game = open_game
        self.side = side
        self.games = list(games) if games is not None else load_all_games()
        self.selected = 0
        self.auto = False
        self.max_level = max_level

    def _rows(self):
        w, h = self.app.screen.size_px
        s = min(w / 1280.0, h / 720.0)
        return s, [(theme.MARGIN * s, (150 + i * 130) * s, w - 2 * theme.MARGIN * s, 112 * s)
                   for i in range(len(self.games))]

    def start(self) -> None:
        if self.games:
            self.app.push(self.open_game(self.games[self.selected], self.patient_id, side=self.side, auto=self.auto,
                                         max_level=self.max_level))

    def change_max_level(self, step: int) -> None:
        """Q/E: the highest level the difficulty may reach (1..10; above 10: the games' own limits)."""
        level = (self.max_level or 11) + step
        self.max_level = None if level > 10 else max(1, level)

    def handle(self, event: InputEvent) -> None:
        n = len(self.games)
        if isinstance(event, Press):
            if not event.down:
                return
            a = event.action
            if a is Action.UP and n:
                self.selected = (self.selected - 1) % n
            elif a is Action.DOWN and n:
                self.selected = (self.selected + 1) % n
            elif a in (Action.LEFT, Action.RIGHT, Action.SWITCH_ARM):
                self.side = "left" if self.side == "right" else "right"
            elif a is Action.NEXT_MOTION:
                self.auto = not self.auto
            elif a in (Action.ROTATE_IN, Action.ROTATE_OUT):
                self.change_max_level(1 if a is Action.ROTATE_OUT else -1)
            elif a is Action.SELECT:
                self.start()
            elif a is Action.BACK:
                self.app.pop()
        elif isinstance(event, Pointer) and event.kind in (PointerKind.MOVE, PointerKind.PRESS):
            w, h = self.app.screen.size_px
            x, y = event.x * w, event.y * h
            _, rows = self._rows()
            for i, (rx, ry, rw, rh) in enumerate(rows):
                if rx <= x < rx + rw and ry <= y < ry + rh:
                    self.selected = i
                    if event.kind is PointerKind.PRESS and event.button == 1:
                        self.start()

    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        s, rows = self._rows()
        m = theme.MARGIN * s
        c.text(f"Games: patient {self.patient_id}", (m, 36 * s), round(theme.LARGE * s), theme.TEXT)
        demo = "demo on: plays by itself" if self.auto else "demo off"
        limit = "each game's own" if self.max_level is None else str(self.max_level)
        c.text(f"{self.side.capitalize()} arm   Highest level: {limit}   ({demo})", (m, 100 * s), round(theme.SMALL * s),
               theme.TEXT_DIM)
        for i, (rect, g) in enumerate(zip(rows, self.games)):
            chosen = i == self.selected
            c.rect(rect, (*theme.ACCENT_DARK, 255) if chosen else theme.PANEL, radius=16 * s, border=3 * s,
                   border_colour=theme.ACCENT if chosen else theme.PANEL_EDGE)
            c.circle((rect[0] + 56 * s, rect[1] + rect[3] / 2), 30 * s, (*g.colour, 255))
            c.text(g.title, (rect[0] + 110 * s, rect[1] + 18 * s), round(theme.MEDIUM * s), theme.TEXT)
            c.text(g.exercises, (rect[0] + 110 * s, rect[1] + 66 * s), round(theme.SMALL * s), theme.TEXT_DIM)
        c.text("Up / Down: game   Left / Right: arm   Q / E: highest level   M: demo   Enter: play   Esc: back", (w / 2, h - 20 * s),
               round(theme.SMALL * s), theme.TEXT_FAINT, anchor="midbottom")
