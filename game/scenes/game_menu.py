"""Choose an exercise game for a patient and set the therapist's limits, in large type.

Left: the games of ``content/games``. Right: the therapist's limits of the chosen game for this
patient (:mod:`game.exergames.limits`): the lowest level (the session starts there at least and
never falls below), the highest level, the farthest target (a fraction of the
measured range), the smallest target, the longest hold, the time per target. The adaptation of
the game never goes beyond them. Changes are stored for the patient at once (``game_limits``)
when the menu has a database, else they hold for the sessions started from this menu.

Keys: Up/Down choose a game, Enter goes to its column: the Play button and the limits (Up/Down
move, Left/Right change a limit, Enter plays, Esc goes back to the games). Left/Right on a game
or on Play and Tab switch the arm; Q/E lower/raise the highest level; M switches the automatic
demo (the simulated patient plays by itself); Esc on the games goes back. Mouse: click a game to
choose it, the - and + of a limit, Play.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Callable, Sequence

from calibration.errors import RehabError
from game.app import BaseScene, Frame
from game.db.location import db_location
from game.exergames.limits import LABELS, LIMIT_KEYS, describe, load_limits, save_limits, step_limit, whose
from game.exergames.spec import GameSpec, TherapistLimits, load_all_games
from game.gfx import theme
from game.input import Action, InputEvent, Pointer, PointerKind, Press

log = logging.getLogger(__name__)

#: Share of the width of the games' column.
GAMES_SHARE = 0.55


class ChooseGameScene(BaseScene):
    """The games and the chosen game's limits; Enter opens ``open_game(spec, patient_id, side=, auto=, limits=)``.

    Args:
        patient_id: the patient who plays.
        open_game: makes the game scene.
        side: the arm first chosen.
        games: the games offered (default: every built-in game).
        max_level: the therapist's highest level, 1..10, for every game (None: the stored or the game's own).
        db_path: where the limits are read and stored per patient (None: only for this menu's sessions).
        account: the signed-in therapist ("" without accounts), audited with each change of a limit.
        may_change_limits: False for a patient's own account: the limits are shown, only a therapist changes them.
    """

    def __init__(self, patient_id: str, open_game: Callable[..., BaseScene], *, side: str = "right",
                 games: Sequence[GameSpec] | None = None, max_level: int | None = None,
                 db_path: Path | None = None, account: str = "", may_change_limits: bool = True) -> None:
        self.patient_id = patient_id
        self.account = account
        self.may_change_limits = may_change_limits
        self.open_game = open_game
        self.side = side
        self.games = list(games) if games is not None else load_all_games()
        self.db_path = db_location(db_path) if db_path is not None else None
        self.selected = 0          # the game
        self.column = None         # None: the games; 0: Play; 1..: the limits
        self.auto = False
        self.error = ""
        self._played: tuple[GameSpec, BaseScene] | None = None   # the game last opened from here
        self.limits: dict[str, TherapistLimits] = {g.name: g.limits for g in self.games}
        if self.db_path is not None:
            try:
                self.limits.update(load_limits(self.db_path, patient_id, self.games))
            except RehabError as exc:
                self.error = str(exc)
        if max_level is not None:
            for name, lim in self.limits.items():
                self.limits[name] = lim.model_copy(update={"max_level": (min(max(max_level, 1), 10) - 1) / 9.0})

    # ------------------------------------------------------------------ state
    @property
    def game(self) -> GameSpec | None:
        return self.games[self.selected] if self.games else None

    @property
    def max_level(self) -> int | None:
        """The chosen game's highest level as shown, 1..10 (None: no limit)."""
        g = self.game
        level = None if g is None else self.limits[g.name].max_level
        return None if level is None else 1 + round(level * 9)

    def start(self) -> None:
        g = self.game
        if g is not None:
            scene = self.open_game(g, self.patient_id, side=self.side, auto=self.auto, limits=self.limits[g.name])
            self._played = (g, scene)
            self.app.push(scene)

    def last_session(self) -> tuple[str, tuple[int, int, int]] | None:
        """What became of the game last played from this menu, in one line, and its colour: stored
        (with its count), or why not; None before a game or when it never started playing."""
        if self._played is None:
            return None
        g, scene = self._played
        error = getattr(scene, "store_error", "")
        if error:
            return f"{g.title}: not saved ({error})", theme.FAILURE
        if getattr(scene, "stored_uid", None) is None:
            return None
        log = scene.session.log
        return f"Saved: {g.title}, {log.reached} collected, {log.missed} missed", theme.ACCENT

    def change_limit(self, key: str, direction: int) -> None:
        """Step one limit of the chosen game and store it for the patient."""
        g = self.game
        if g is None:
            return
        if not self.may_change_limits:
            self.error = "Only a therapist changes the limits"
            return
        self.limits[g.name] = step_limit(g, self.limits[g.name], key, direction)
        if self.db_path is not None:
            try:
                save_limits(self.db_path, self.patient_id, g, self.limits[g.name], account=self.account)
                self.error = ""
            except RehabError as exc:
                self.error = str(exc)
                log.error("limits not stored: %s", exc)

    def change_max_level(self, step: int) -> None:
        """Q/E: the highest level the difficulty may reach (1..10; above 10: no limit)."""
        self.change_limit("max_level", step)

    # ------------------------------------------------------------------ layout
    def _layout(self):
        """(scale, game rows, limit rows, (minus, plus) button centres and radius per limit row)."""
        w, h = self.app.screen.size_px
        s = min(w / 1280.0, h / 720.0)
        m = theme.MARGIN * s
        games = [(m, (150 + i * 118) * s, w * GAMES_SHARE - m, 104 * s) for i in range(len(self.games))]
        x0 = w * GAMES_SHARE + 24 * s
        limits = [(x0, (242 + i * 68) * s, w - m - x0, 60 * s) for i in range(len(LIMIT_KEYS))]
        r = 24 * s
        buttons = [((x + ww - 96 * s, y + hh / 2), (x + ww - 36 * s, y + hh / 2)) for x, y, ww, hh in limits]
        play = (x0, 150 * s, w - m - x0, 60 * s)
        return s, games, limits, buttons, r, play

    # ------------------------------------------------------------------ input
    def handle(self, event: InputEvent) -> None:
        n, k = len(self.games), len(LIMIT_KEYS)
        if isinstance(event, Press):
            if not event.down:
                return
            a = event.action
            col = self.column
            if a in (Action.UP, Action.DOWN) and n:
                step = 1 if a is Action.DOWN else -1
                if col is None:
                    self.selected = (self.selected + step) % n
                else:
                    self.column = (col + step) % (k + 1)
            elif a in (Action.LEFT, Action.RIGHT) and col:
                self.change_limit(LIMIT_KEYS[col - 1], 1 if a is Action.RIGHT else -1)
            elif a in (Action.LEFT, Action.RIGHT, Action.SWITCH_ARM):
                self.side = "left" if self.side == "right" else "right"
            elif a is Action.NEXT_MOTION:
                self.auto = not self.auto
            elif a in (Action.ROTATE_IN, Action.ROTATE_OUT):
                self.change_max_level(1 if a is Action.ROTATE_OUT else -1)
            elif a is Action.SELECT and n:
                if col is None:
                    self.column = 0
                else:
                    self.start()
            elif a is Action.BACK:
                if col is None:
                    self.app.pop()
                else:
                    self.column = None
        elif isinstance(event, Pointer) and event.kind in (PointerKind.MOVE, PointerKind.PRESS):
            w, h = self.app.screen.size_px
            x, y = event.x * w, event.y * h
            _, games, limits, buttons, r, play = self._layout()
            click = event.kind is PointerKind.PRESS and event.button == 1

            def inside(rect) -> bool:
                return rect[0] <= x < rect[0] + rect[2] and rect[1] <= y < rect[1] + rect[3]

            for i, rect in enumerate(games):
                if inside(rect) and click:
                    self.selected, self.column = i, 0
                    return
            if inside(play):
                self.column = 0
                if click and n:
                    self.start()
                return
            for j, (rect, (minus, plus)) in enumerate(zip(limits, buttons)):
                if inside(rect):
                    self.column = j + 1
                    for direction, (bx, by) in ((-1, minus), (1, plus)):
                        if click and (x - bx) ** 2 + (y - by) ** 2 <= (r * 1.2) ** 2:
                            self.change_limit(LIMIT_KEYS[j], direction)
                    return

    # ------------------------------------------------------------------ drawing
    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        s, games, limits, buttons, r, play = self._layout()
        m = theme.MARGIN * s
        c.text(f"Games: patient {self.patient_id}", (m, 36 * s), round(theme.LARGE * s), theme.TEXT)
        demo = "demo on: plays by itself" if self.auto else "demo off"
        c.text(f"{self.side.capitalize()} arm   ({demo})", (m, 100 * s), round(theme.BODY * s), theme.TEXT_DIM)
        for i, (rect, g) in enumerate(zip(games, self.games)):
            chosen = i == self.selected
            focus = chosen and self.column is None
            c.rect(rect, (*theme.ACCENT_DARK, 255) if chosen else theme.PANEL, radius=16 * s, border=3 * s,
                   border_colour=theme.ACCENT if focus else theme.PANEL_EDGE)
            c.circle((rect[0] + 50 * s, rect[1] + rect[3] / 2), 28 * s, (*g.colour, 255))
            c.text(g.title, (rect[0] + 98 * s, rect[1] + 14 * s), round(theme.MEDIUM * s), theme.TEXT)
            size = round(theme.SMALL * s)
            line = c.wrap(g.exercises, size, rect[2] - 110 * s)[0]
            c.text(line, (rect[0] + 98 * s, rect[1] + 62 * s), size, theme.TEXT_DIM)
        last = self.last_session()
        if last is not None and games:
            below = games[-1][1] + games[-1][3] + 24 * s
            text, size = c.fit(last[0], round(theme.BODY * s), games[-1][2])
            c.text(text, (games[-1][0], below), size, last[1])
        g = self.game
        if g is not None:
            x0 = limits[0][0]
            c.rect(play, (*theme.ACCENT_DARK, 255) if self.column == 0 else theme.PANEL, radius=14 * s, border=3 * s,
                   border_colour=theme.ACCENT if self.column == 0 else theme.PANEL_EDGE)
            c.text(f"Play {g.title}", (play[0] + play[2] / 2, play[1] + play[3] / 2), round(theme.BODY * s), theme.TEXT,
                   anchor="center")
            c.text("Therapist's limits", (x0, 238 * s), round(theme.SMALL * s), theme.TEXT_DIM, anchor="bottomleft")
            lim = self.limits[g.name]
            for j, (rect, key, (minus, plus)) in enumerate(zip(limits, LIMIT_KEYS, buttons)):
                focus = self.column == j + 1
                c.rect(rect, theme.PANEL, radius=14 * s, border=3 * s,
                       border_colour=theme.ACCENT if focus else theme.PANEL_EDGE)
                room = min(minus[0], plus[0]) - r - 10 * s - (rect[0] + 18 * s)   # left of the - and +
                label, label_size = c.fit(f"{LABELS[key]}: {whose(lim, key)}", round(theme.SMALL * s), room)
                c.text(label, (rect[0] + 18 * s, rect[1] + 5 * s), label_size, theme.TEXT_DIM)
                value, value_size = c.fit(describe(g, lim, key), round(theme.BODY * s), room)
                c.text(value, (rect[0] + 18 * s, rect[1] + 30 * s), value_size,
                       theme.TEXT if getattr(lim, key) is not None else theme.TEXT_FAINT)
                for centre, sign in ((minus, "-"), (plus, "+")):
                    c.circle(centre, r, (*theme.ACCENT_DARK, 255), border=2 * s, border_colour=theme.ACCENT)
                    c.text(sign, centre, round(theme.MEDIUM * s), theme.TEXT, anchor="center")
            where = "stored for this patient" if self.db_path is not None else "for this visit"
            c.text(self.error or f"Limits of {g.title}: {where}", (x0, limits[-1][1] + limits[-1][3] + 12 * s),
                   round(theme.SMALL * 0.85 * s), theme.FAILURE if self.error else theme.TEXT_FAINT)
        keys = ("Up / Down: game   Left / Right: arm   Enter: to Play and the limits   M: demo   Esc: back"
                if self.column is None else "Up / Down: Play or a limit   Left / Right: change   Enter: play   Esc: the games")
        c.text(keys,
               (w / 2, h - 16 * s), round(theme.SMALL * s), theme.TEXT_FAINT, anchor="midbottom")
