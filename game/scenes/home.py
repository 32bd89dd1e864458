"""The home screen: large buttons leading to the modes that exist.

Entries are handed in (:class:`MenuEntry`), so that a mode added later (ROM test, games,
progress) plugs in with one line where the application is assembled
(:func:`game.scenes.build_home`). Keyboard: Up/Down (or W/S) choose, Enter/Space open, Esc twice
quits (one Esc too many coming back from a mode only asks). Mouse: hovering chooses, a click
opens. A mode says "Opening ..." while it is built (:meth:`game.app.App.open`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from game.app import BaseScene, Frame
from game.gfx import theme
from game.input import Action, InputEvent, Pointer, PointerKind, Press

Rect = tuple[float, float, float, float]


@dataclass(frozen=True, slots=True)
class MenuEntry:
    """One button of the home screen.

    Attributes:
        label: what it opens, in a few words.
        hint: one line saying what it is for.
        open: makes the scene to push (None: the entry closes the application).
    """

    label: str
    hint: str
    open: Callable[[], BaseScene] | None


#: A second Esc within this many seconds quits; the first only asks.
QUIT_CONFIRM_S = 3.0

BUTTON_W = 700
BUTTON_H = 104
BUTTON_GAP = 22


def menu_rects(size_px: tuple[int, int], n: int) -> list[Rect]:
    """Screen rectangles of ``n`` buttons, a centred column below the title."""
    w, h = size_px
    scale = min(w / 1280.0, h / 720.0)
    bw, bh, gap = BUTTON_W * scale, BUTTON_H * scale, BUTTON_GAP * scale
    room = h - 210 * scale - 90 * scale  # below the title, above the footer and status lines
    columns = 1 if n * bh + (n - 1) * gap <= room else 2   # many entries: two columns, same buttons
    rows = -(-n // columns)
    if columns == 2:
        bw = min(bw, (w - 2 * theme.MARGIN * scale - gap) / 2)
    total = rows * bh + (rows - 1) * gap
    top = max(210 * scale, (h - total) / 2 + 60 * scale)
    if total > room:   # still too many: lower buttons from just below the subtitle, above the status line
        top = 180 * scale
        bh = (h - 100 * scale - top - (rows - 1) * gap) / rows
    x0 = (w - columns * bw - (columns - 1) * gap) / 2
    return [(x0 + (i % columns) * (bw + gap), top + (i // columns) * (bh + gap), bw, bh) for i in range(n)]


def hit(rects: list[Rect], x_px: float, y_px: float) -> int | None:
    """Index of the rectangle holding the point, or None."""
    for i, (rx, ry, rw, rh) in enumerate(rects):
        if rx <= x_px < rx + rw and ry <= y_px < ry + rh:
            return i
    return None


class HomeScene(BaseScene):
    """The first screen.

    Args:
        entries: the buttons, top to bottom.
        status: returns one line about the system shown at the bottom (e.g. the tracker's state),
            or None.
    """

    def __init__(self, entries: list[MenuEntry], status: Callable[[], str] | None = None) -> None:
        if not entries:
            raise ValueError("HomeScene needs at least one entry")
        self.entries = list(entries)
        self.selected = 0
        self._status = status
        self._glow = 0.0  # eases the highlight of the selected button in
        self._quit_asked_s: float | None = None   # when Esc asked to quit (the app's clock)

    def _rects(self) -> list[Rect]:
        return menu_rects(self.app.screen.size_px, len(self.entries))

    def activate(self, index: int) -> None:
        entry = self.entries[index]
        self._quit_asked_s = None
        if entry.open is None:
            self.app.quit()
        else:
            self.app.open(entry.open, f"Opening {entry.label}...")

    def ask_quit(self) -> None:
        """Esc: the first asks, a second within ``QUIT_CONFIRM_S`` quits."""
        now = self.app.clock()
        if self._quit_asked_s is not None and now - self._quit_asked_s <= QUIT_CONFIRM_S:
            self.app.quit()
        else:
            self._quit_asked_s = now

    @property
    def quit_asked(self) -> bool:
        return self._quit_asked_s is not None and self.app.clock() - self._quit_asked_s <= QUIT_CONFIRM_S

    def _select(self, index: int) -> None:
        if index != self.selected:
            self.selected = index
            self._glow = 0.0

    def handle(self, event: InputEvent) -> None:
        if isinstance(event, Press):
            if not event.down:
                return
            if event.action is Action.UP:
                self._select((self.selected - 1) % len(self.entries))
            elif event.action is Action.DOWN:
                self._select((self.selected + 1) % len(self.entries))
            elif event.action is Action.SELECT:
                self.activate(self.selected)
            elif event.action is Action.BACK:
                self.ask_quit()
        elif isinstance(event, Pointer) and event.kind in (PointerKind.MOVE, PointerKind.PRESS):
            w, h = self.app.screen.size_px
            index = hit(self._rects(), event.x * w, event.y * h)
            if index is None:
                return
            self._select(index)
            if event.kind is PointerKind.PRESS and event.button == 1:
                self.activate(index)

    def update(self, dt_s: float) -> None:
        self._glow = min(1.0, self._glow + dt_s / 0.15)

    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        scale = min(w / 1280.0, h / 720.0)
        c.text("Rehab motion capture", (w / 2, 62 * scale), round(theme.TITLE * scale), theme.TEXT, anchor="midtop")
        c.text("Move, and see yourself move.", (w / 2, 136 * scale), round(theme.BODY * scale), theme.TEXT_DIM,
               anchor="midtop")
        for i, ((x, y, bw, bh), entry) in enumerate(zip(self._rects(), self.entries)):
            chosen = i == self.selected
            if chosen:
                glow = 0.6 + 0.4 * self._glow
                fill = tuple(round(a + (b - a) * glow) for a, b in zip(theme.PANEL[:3], theme.ACCENT_DARK)) + (255,)
                c.rect((x, y, bw, bh), fill, radius=theme.RADIUS * scale, border=4 * scale, border_colour=theme.ACCENT)
            else:
                c.rect((x, y, bw, bh), theme.PANEL, radius=theme.RADIUS * scale, border=2 * scale,
                       border_colour=theme.PANEL_EDGE)
            label_colour = theme.TEXT if chosen else theme.TEXT_DIM
            k = scale * min(1.0, bh / (BUTTON_H * scale))   # lowered buttons (many entries): smaller text
            if not entry.hint:
                c.text(entry.label, (x + 34 * scale, y + bh / 2), round(theme.LARGE * k), label_colour,
                       anchor="midleft")
                continue
            c.text(entry.label, (x + 34 * scale, y + 18 * k), round(theme.LARGE * k), label_colour)
            c.text(entry.hint, (x + 36 * scale, y + bh - 16 * k), round(theme.SMALL * k),
                   theme.TEXT_DIM if chosen else theme.TEXT_FAINT, anchor="bottomleft")
        footer_y = h - 24 * scale
        if self.quit_asked:
            c.text("Press Esc again to quit", (w / 2, footer_y), round(theme.BODY * scale), theme.ATTENTION,
                   anchor="midbottom")
        else:
            c.text("Up / Down to choose, Enter to open, Esc twice to quit; or use the mouse", (w / 2, footer_y),
                   round(theme.SMALL * scale), theme.TEXT_FAINT, anchor="midbottom")
        if self._status is not None:
            line = self._status()
            if line:
                c.text(line, (theme.MARGIN * scale, footer_y - 40 * scale), round(theme.SMALL * scale),
                       theme.TEXT_DIM, anchor="bottomleft")
