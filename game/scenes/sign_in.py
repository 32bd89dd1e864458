"""The sign-in screen: an account name and its password or PIN, typed in the application.

Where the database has accounts (:mod:`game.db.accounts`) and ``rehab play`` was given none (or
no PIN, without a terminal to ask it on: a desktop launcher), the application opens here. Enter
checks the name and secret with :func:`~game.db.accounts.authenticate` and hands the account to
``then(account)``, which opens the screens that account may open; this screen stays underneath,
emptied, so a patient leaving the game menu comes back here for the next person (the home screen
quits with Esc twice, as without accounts). A wrong name or secret is said in one
line that does not tell which of the two was wrong; after three wrong tries in a row the next try
waits a few seconds. The secret is shown as dots. Keyboard: type, Up/Down/Tab change the field,
Backspace erases, Enter signs in, Esc quits; mouse: click a field.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import pygame

from calibration.errors import RehabError
from game.app import BaseScene, Frame
from game.db import Database
from game.db.accounts import AccessDenied, authenticate
from game.db.location import db_location
from game.gfx import theme
from game.input import Action, InputEvent, Pointer, PointerKind, Press, Typed

WRONG = "Wrong account name or password/PIN: try again"
#: wrong tries in a row before each further try waits :data:`WAIT_S`
FREE_TRIES = 3
WAIT_S = 5.0
MAX_CHARS = 64


class SignInScene(BaseScene):
    """Type an account name and its password or PIN; Enter opens ``then(account)``.

    Args:
        db_path: the database holding the accounts (``rehab play --db``).
        then: opens the screens of the signed-in account (it pushes them over this scene); raises
            :class:`~game.db.accounts.AccessDenied` where the account may open none of what was asked.
        name: the account name already given (``--user`` without a PIN): the PIN field is chosen.
        clock: seconds, for the wait after wrong tries.
    """

    def __init__(self, db_path: Path, then: Callable[[object], None], *, name: str = "",
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.db_path = db_location(db_path)
        self.then = then
        self.clock = clock
        self.fields = [name, ""]
        self.field = 1 if name else 0
        self.message = ""
        self.wrong = 0
        self.wait_until = 0.0

    def enter(self, app) -> None:
        super().enter(app)
        try:
            pygame.key.start_text_input()
        except Exception:   # pragma: no cover - no keyboard text input on this display
            pass

    # ------------------------------------------------------------------ sign in
    def sign_in(self) -> None:
        now = self.clock()
        if now < self.wait_until:
            self.message = f"Too many wrong tries: wait {self.wait_until - now:.0f} s"
            self.fields[1], self.field = "", 1   # not checked: typed again after the wait
            return
        name, secret = self.fields[0].strip(), self.fields[1]
        if not name or not secret:
            self.message = "Type the account name and the password or PIN"
            self.field = 0 if not name else 1
            return
        try:
            with Database(self.db_path) as db:
                account = authenticate(db, name, secret)
        except AccessDenied:
            self.wrong += 1
            if self.wrong >= FREE_TRIES:
                self.wait_until = self.clock() + WAIT_S
            self.fields[1], self.field, self.message = "", 1, WRONG
            return
        except RehabError as exc:
            self.message = str(exc)
            return
        self.wrong, self.wait_until = 0, 0.0
        self.fields, self.field, self.message = ["", ""], 0, ""
        try:
            self.then(account)
        except RehabError as exc:   # AccessDenied: this account may open none of what was asked
            self.message = str(exc)

    # ------------------------------------------------------------------ input
    def _rects(self):
        w, h = self.app.screen.size_px
        s = min(w / 1280.0, h / 720.0)
        fw, fh = 560 * s, 64 * s
        return [((w - fw) / 2, (250 + i * 130) * s, fw, fh) for i in range(2)]

    def handle(self, event: InputEvent) -> None:
        if isinstance(event, Typed):
            text = "".join(ch for ch in event.text if ch.isprintable())
            self.fields[self.field] = (self.fields[self.field] + text)[:MAX_CHARS]
            return
        if isinstance(event, Press):
            if not event.down or len(event.key) == 1 or event.key == "space":
                return   # a letter, digit or space key: its text comes as Typed
            if event.key == "backspace":
                self.fields[self.field] = self.fields[self.field][:-1]
            elif event.action is Action.BACK:
                self.app.pop()
            elif event.action in (Action.UP, Action.DOWN, Action.SWITCH_ARM):
                self.field = 1 - self.field
            elif event.action is Action.SELECT:
                if self.field == 0 and not self.fields[1]:
                    self.field = 1
                else:
                    self.sign_in()
        elif isinstance(event, Pointer) and event.kind is PointerKind.PRESS and event.button == 1:
            w, h = self.app.screen.size_px
            for i, (x, y, rw, rh) in enumerate(self._rects()):
                if x <= event.x * w < x + rw and y <= event.y * h < y + rh:
                    self.field = i

    # ------------------------------------------------------------------ drawing
    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        s = min(w / 1280.0, h / 720.0)
        c.text("Sign in", (w / 2, 60 * s), round(theme.LARGE * s), theme.TEXT, anchor="midtop")
        c.text("Your account name and your password or PIN", (w / 2, 140 * s), round(theme.SMALL * s),
               theme.TEXT_DIM, anchor="midtop")
        labels = ("Account name", "Password or PIN")
        for i, rect in enumerate(self._rects()):
            x, y, rw, rh = rect
            chosen = i == self.field
            c.text(labels[i], (x, y - 8 * s), round(theme.SMALL * s), theme.TEXT_DIM, anchor="bottomleft")
            if chosen:
                c.rect(rect, (*theme.ACCENT_DARK, 255), radius=theme.RADIUS * s, border=4 * s,
                       border_colour=theme.ACCENT)
            else:
                c.rect(rect, theme.PANEL, radius=theme.RADIUS * s, border=2 * s, border_colour=theme.PANEL_EDGE)
            shown = self.fields[i] if i == 0 else "\u2022" * len(self.fields[i])
            cursor = "_" if chosen else ""
            size = round(theme.MEDIUM * s)
            while shown and c.measure(shown + cursor, size)[0] > rw - 48 * s:
                shown = shown[1:]   # the end of a long entry stays in view
            c.text(shown + cursor, (x + 24 * s, y + rh / 2), size, theme.TEXT if chosen else theme.TEXT_DIM,
                   anchor="midleft")
        if self.message:
            for k, line in enumerate(c.wrap(self.message, round(theme.BODY * s), w - 200 * s)[:2]):
                c.text(line, (w / 2, 480 * s + k * 40 * s), round(theme.BODY * s), theme.FAILURE, anchor="midtop")
        c.text("Type, Up / Down to change the field, Enter to sign in, Esc to quit", (w / 2, h - 24 * s),
               round(theme.SMALL * s), theme.TEXT_FAINT, anchor="midbottom")
