"""The patient picker: pseudonymous IDs from the database, and "New patient".

Shared by the ROM test and the progress review: the scene lists the patients of the database
(``P001``, their sessions and last session date; no names exist anywhere) and hands the chosen ID
to ``then(patient_id)``, which makes the next scene (it replaces the picker, so Esc there comes
back to the home screen). "New patient" adds the next free ID (:func:`next_patient_id`) and
chooses it; the first existing patient is chosen when the picker opens, so that Enter never adds
one by mistake. Keyboard: Up/Down choose, Enter opens, Esc goes back; mouse: hover and click.

The database is opened for each read or write (:class:`game.db.Database`, path handed in), so the
picker holds no connection while other scenes run.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Callable, Sequence

from calibration.errors import RehabError
from game.app import BaseScene, Frame
from game.db import Database
from game.db.location import db_location
from game.gfx import theme
from game.input import Action, InputEvent, Pointer, PointerKind, Press

Rect = tuple[float, float, float, float]

NEW_PATIENT = "New patient"
_NUMBERED = re.compile(r"^P(\d+)$")


def next_patient_id(existing: Sequence[str]) -> str:
    """The next pseudonymous ID after the highest ``P<number>`` in use: P001, P002, ... (at least 3 digits)."""
    numbers = [int(m.group(1)) for m in map(_NUMBERED.match, existing) if m]
    return f"P{max(numbers, default=0) + 1:03d}"


def list_rects(size_px: tuple[int, int], n: int, top_px: float, row_h_px: float) -> list[Rect]:
    """Rows of a centred list of ``n`` entries starting at ``top_px`` (window pixels)."""
    w, _ = size_px
    scale = min(w / 1280.0, size_px[1] / 720.0)
    row_w = 760 * scale
    gap = 12 * scale
    x = (w - row_w) / 2
    return [(x, top_px + i * (row_h_px + gap), row_w, row_h_px) for i in range(n)]


def hit(rects: Sequence[Rect], x_px: float, y_px: float) -> int | None:
    """Index of the rectangle holding the point, or None."""
    for i, (rx, ry, rw, rh) in enumerate(rects):
        if rx <= x_px < rx + rw and ry <= y_px < ry + rh:
            return i
    return None



def patient_counts(rom_results: int, games: int) -> str:
    """"1 ROM result, 2 games" (the picker's line of a patient's stored results)."""
    return (f"{rom_results} ROM result{'' if rom_results == 1 else 's'}, "
            f"{games} game{'' if games == 1 else 's'}")


class PatientsScene(BaseScene):
    """Choose a patient (or add one), then open ``then(patient_id)`` in place of this scene.

    Args:
        db_path: the database file (``rehab play --db``; default the user's data directory).
        then: makes the scene for the chosen patient.
        title: what the choice is for, e.g. "ROM test: choose the patient".
        allow_new: show "New patient" (the progress review has nothing to show for a new one).
    """

    #: Rows shown at once; the list scrolls with the selection.
    VISIBLE_ROWS = 6

    def __init__(self, db_path: Path, then: Callable[[str], BaseScene], *, title: str,
                 allow_new: bool = True) -> None:
        self.db_path = db_location(db_path)
        self.then = then
        self.title = title
        self.allow_new = allow_new
        self.patients: list = []
        self.selected = 0
        self.first = 0
        self.error = ""
        self._chosen = False   # the user moved the selection (a reload keeps it)

    # ------------------------------------------------------------------ data
    def enter(self, app) -> None:
        super().enter(app)
        self.reload()

    def reload(self) -> None:
        try:
            with Database(self.db_path) as db:
                self.patients = db.patients()
            self.error = ""
        except RehabError as exc:
            self.patients, self.error = [], str(exc)
        if not self._chosen and self.allow_new and self.patients:
            self.selected = 1   # the first patient, not "New patient": Enter must not add one by mistake
        self.selected = min(self.selected, max(len(self.entries) - 1, 0))

    @property
    def entries(self) -> list[str]:
        """What the rows say, top to bottom: the new-patient row first, then the IDs."""
        ids = [p.id for p in self.patients]
        return ([NEW_PATIENT] if self.allow_new and not self.error else []) + ids

    def add_patient(self) -> str:
        """Add the next free ID to the database; returns it."""
        with Database(self.db_path) as db:
            patient_id = next_patient_id([p.id for p in db.patients()])
            db.add_patient(patient_id)
        return patient_id

    def choose(self, index: int) -> None:
        entries = self.entries
        if not entries:
            return
        label = entries[index]
        patient_id = self.add_patient() if label == NEW_PATIENT and self.allow_new else label
        self.app.open(lambda: self.then(patient_id), f"Opening patient {patient_id}...", replace=True)

    # ------------------------------------------------------------------ input
    def _rects(self) -> list[Rect]:
        w, h = self.app.screen.size_px
        s = min(w / 1280.0, h / 720.0)
        n = min(len(self.entries) - self.first, self.VISIBLE_ROWS)
        return list_rects((w, h), max(n, 0), 190 * s, 72 * s)

    def _select(self, index: int) -> None:
        n = len(self.entries)
        if n == 0:
            return
        self._chosen = True
        self.selected = index % n
        if self.selected < self.first:
            self.first = self.selected
        elif self.selected >= self.first + self.VISIBLE_ROWS:
            self.first = self.selected - self.VISIBLE_ROWS + 1

    def handle(self, event: InputEvent) -> None:
        if isinstance(event, Press):
            if not event.down:
                return
            if event.action is Action.UP:
                self._select(self.selected - 1)
            elif event.action is Action.DOWN:
                self._select(self.selected + 1)
            elif event.action is Action.SELECT:
                self.choose(self.selected)
            elif event.action is Action.BACK:
                self.app.pop()
        elif isinstance(event, Pointer):
            w, h = self.app.screen.size_px
            if event.kind is PointerKind.WHEEL:
                self._select(self.selected - int(event.wheel))
                return
            if event.kind not in (PointerKind.MOVE, PointerKind.PRESS):
                return
            k = hit(self._rects(), event.x * w, event.y * h)
            if k is None:
                return
            self.selected = self.first + k
            self._chosen = True
            if event.kind is PointerKind.PRESS and event.button == 1:
                self.choose(self.selected)

    # ------------------------------------------------------------------ drawing
    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        s = min(w / 1280.0, h / 720.0)
        c.text(self.title, (w / 2, 50 * s), round(theme.LARGE * s), theme.TEXT, anchor="midtop")
        c.text("Patients are kept under pseudonymous IDs only (no names).", (w / 2, 122 * s),
               round(theme.SMALL * s), theme.TEXT_DIM, anchor="midtop")
        if self.error:
            for k, line in enumerate(c.wrap(self.error, round(theme.BODY * s), w - 200 * s)[:4]):
                c.text(line, (w / 2, 230 * s + k * 40 * s), round(theme.BODY * s), theme.FAILURE, anchor="midtop")
        elif not self.entries:
            c.text("No patients yet.", (w / 2, 260 * s), round(theme.MEDIUM * s), theme.TEXT_DIM, anchor="midtop")
        by_id = {p.id: p for p in self.patients}
        entries = self.entries
        for k, rect in enumerate(self._rects()):
            i = self.first + k
            label = entries[i]
            chosen = i == self.selected
            x, y, rw, rh = rect
            if chosen:
                c.rect(rect, (*theme.ACCENT_DARK, 255), radius=theme.RADIUS * s, border=4 * s, border_colour=theme.ACCENT)
            else:
                c.rect(rect, theme.PANEL, radius=theme.RADIUS * s, border=2 * s, border_colour=theme.PANEL_EDGE)
            colour = theme.TEXT if chosen else theme.TEXT_DIM
            if label == NEW_PATIENT:
                c.text(f"+  {NEW_PATIENT}", (x + 30 * s, y + rh / 2), round(theme.MEDIUM * s), colour, anchor="midleft")
                hint = f"adds {next_patient_id(list(by_id))}"
                c.text(hint, (x + rw - 30 * s, y + rh / 2), round(theme.SMALL * s), theme.TEXT_FAINT, anchor="midright")
                continue
            p = by_id[label]
            c.text(label, (x + 30 * s, y + rh / 2), round(theme.MEDIUM * s), colour, anchor="midleft")
            last = p.last_utc[:10] if p.last_utc else "no sessions yet"
            info = f"{patient_counts(p.rom_results, p.exercise_results)}, last {last}" if p.last_utc else last
            c.text(info, (x + rw - 30 * s, y + rh / 2), round(theme.SMALL * s), theme.TEXT_DIM, anchor="midright")
        if self.first > 0:
            c.text("more above", (w / 2, 166 * s), round(theme.SMALL * 0.8 * s), theme.TEXT_FAINT, anchor="midbottom")
        if self.first + self.VISIBLE_ROWS < len(entries):
            c.text("more below", (w / 2, h - 64 * s), round(theme.SMALL * 0.8 * s), theme.TEXT_FAINT, anchor="midbottom")
        c.text("Up / Down to choose, Enter to open, Esc to go back; or use the mouse", (w / 2, h - 24 * s),
               round(theme.SMALL * s), theme.TEXT_FAINT, anchor="midbottom")
