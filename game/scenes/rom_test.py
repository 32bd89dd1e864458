"""The ROM test: choose the test, then measure it live with the same logic as ``rehab rom-test``.

Two scenes over one :class:`game.rom.visit.RomVisit` (the patient, the database, the standard; it
stores the accepted results, the scenes never write to the database themselves):

- :class:`ChooseTestScene`: the tests of ``content/rom_tests`` for the chosen side, with the start
  position and the patient's instructions in large type, the normal value of the standard.
  Up/Down choose, Left/Right or Tab switch the side, Enter starts, Esc goes back; mouse: hover and
  click (the standard chip switches JARM/AAOS for the whole visit: the tables are never mixed).
- :class:`RomTestScene`: the avatar (:class:`game.avatar.live.LiveAvatar`, mirror view) beside a big live readout of the test value,
  the steps (start position -> hold still -> move -> done), the maximum so far, compensation
  warnings in plain words, the standard's reference value with its position, the patient's
  previous results of this test and side. The tracker's samples (``LiveLink.new_samples``,
  :class:`tracking.live.LiveSample`) are fed to a :class:`game.rom.session.RomTestSession`, the
  logic ``rehab rom-test`` runs on the offline tracker. When the attempt is done: **Accept**
  stores the raw result (one durable transaction, :meth:`game.db.Database.add_rom_result`),
  **Repeat** throws it away and measures again, **Discard** throws it away and goes back to the
  tests. Values are shown rounded to 5 degrees; a maximum that rested on estimated (hidden)
  markers says so. With the simulated patient, "Demo motion" (M) plays the test's scripted motion
  on the tracker process (``simulated_motion`` of the test), so anyone can try a test.

Buttons: Left/Right choose, Enter presses; mouse: hover and click. Esc goes back (an attempt not
accepted is not stored).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Callable, Sequence


from calibration.errors import RehabError
from game.app import BaseScene, Frame
from game.gfx import theme
from game.gfx.view3d import Viewport
from game.input import Action, InputEvent, Pointer, PointerKind, Press
from game.rom.session import RomProgress, RomState, RomTestSession, round_to_5
from game.rom.spec import RomTest, load_all_rom_tests
from game.rom.visit import RomVisit
from game.scenes.live_feed import STOPPED_LINE, LiveFeed

log = logging.getLogger(__name__)

Rect = tuple[float, float, float, float]

#: Share of the window's width the avatar takes in the test scene.
VIEW_SHARE = 0.46
#: Previous results listed beside the test.
PREVIOUS_SHOWN = 4


def hit(rects: Sequence[Rect], x_px: float, y_px: float) -> int | None:
    """Index of the rectangle holding the point, or None."""
    for i, (rx, ry, rw, rh) in enumerate(rects):
        if rx <= x_px < rx + rw and ry <= y_px < ry + rh:
            return i
    return None


def is_simulated(link) -> bool:
    """Whether the tracker measures the simulated patient (demo motions exist only there)."""
    source = getattr(getattr(link, "tracker", None), "source", None)
    return getattr(source, "kind", "sim") == "sim"


def range_words(result) -> tuple[str, str]:
    """The range moved beside the raw maximum, with the start it is counted from: "moved 157° from
    the start" / "(the start position read -12°)" (a lone "active ROM, from start 157" beside a 145
    result was not understood)."""
    return (f"moved {result.range_deg:.0f}\N{DEGREE SIGN} from the start",
            f"(the start position read {result.start_deg:.0f}\N{DEGREE SIGN})")


def reference_line(test: RomTest, standard: str) -> str:
    """The normal value of ``standard`` in words, never another standard's: e.g. ``JARM normal 180``."""
    ref = test.reference(standard)
    if ref is None:
        return f"{standard.upper()}: no normal value for this test"
    if not ref.comparable:
        return f"{standard.upper()} {ref.value_deg:g} was measured {ref.position_words}: another position, not comparable"
    return f"{standard.upper()} normal {ref.value_deg:g}\N{DEGREE SIGN} ({test.position_id.replace('_', ' ')})"


def previous_line(row) -> str:
    """One stored result for the list: date, rounded value, its flags."""
    text = f"{row.session_started_utc[:10]}   {round_to_5(row.value_deg)}\N{DEGREE SIGN}"
    flags = []
    if row.compensation:
        flags.append("compensated")
    if row.estimated_markers:
        flags.append("estimated markers")
    if flags:
        text += f"  ({', '.join(flags)})"
    return text


# ============================================================================ test choice
class ChooseTestScene(BaseScene):
    """The list of tests for a side; Enter opens :class:`RomTestScene` on top.

    Args:
        visit: the patient's visit (closed when this scene exits).
        open_test: ``open_test(visit, test, side)`` makes the test scene.
        side: the side shown first.
        tests: the tests offered (default: every built-in test).
    """

    def __init__(self, visit: RomVisit, open_test: Callable[[RomVisit, RomTest, str], BaseScene], *,
                 side: str = "right", tests: Sequence[RomTest] | None = None) -> None:
        self.visit = visit
        self.open_test = open_test
        self.side = side
        self._all = list(tests) if tests is not None else load_all_rom_tests()
        self.selected = 0

    @property
    def tests(self) -> list[RomTest]:
        return [t for t in self._all if self.side in t.sides]

    def exit(self) -> None:
        self.visit.close()

    def _layout(self):
        w, h = self.app.screen.size_px
        s = min(w / 1280.0, h / 720.0)
        n = len(self.tests)
        top = 150 * s
        row_h = min(54 * s, (h - top - 70 * s) / max(n, 1) - 6 * s)
        rows = [(theme.MARGIN * s, top + i * (row_h + 6 * s), 440 * s, row_h) for i in range(n)]
        chip = (w - theme.MARGIN * s - 300 * s, 40 * s, 300 * s, 56 * s)
        side_chip = (w - theme.MARGIN * s - 620 * s, 40 * s, 300 * s, 56 * s)
        return s, rows, chip, side_chip

    def switch_side(self) -> None:
        self.side = "left" if self.side == "right" else "right"
        self.selected = min(self.selected, len(self.tests) - 1)

    def switch_standard(self) -> None:
        self.visit.standard = "aaos" if self.visit.standard == "jarm" else "jarm"

    def start(self) -> None:
        if self.tests:
            self.app.push(self.open_test(self.visit, self.tests[self.selected], self.side))

    def handle(self, event: InputEvent) -> None:
        n = len(self.tests)
        if isinstance(event, Press):
            if not event.down:
                return
            a = event.action
            if a is Action.UP and n:
                self.selected = (self.selected - 1) % n
            elif a is Action.DOWN and n:
                self.selected = (self.selected + 1) % n
            elif a in (Action.LEFT, Action.RIGHT, Action.SWITCH_ARM):
                self.switch_side()
            elif a is Action.SELECT:
                self.start()
            elif a is Action.BACK:
                self.app.pop()
        elif isinstance(event, Pointer) and event.kind in (PointerKind.MOVE, PointerKind.PRESS):
            w, h = self.app.screen.size_px
            x, y = event.x * w, event.y * h
            _, rows, chip, side_chip = self._layout()
            k = hit(rows, x, y)
            if k is not None:
                self.selected = k
                if event.kind is PointerKind.PRESS and event.button == 1:
                    self.start()
            elif event.kind is PointerKind.PRESS and event.button == 1:
                if hit([chip], x, y) is not None:
                    self.switch_standard()
                elif hit([side_chip], x, y) is not None:
                    self.switch_side()

    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        s, rows, chip, side_chip = self._layout()
        m = theme.MARGIN * s
        c.text(f"ROM test: patient {self.visit.patient_id}", (m, 36 * s), round(theme.LARGE * s), theme.TEXT)
        c.text("Choose the test", (m, 100 * s), round(theme.SMALL * s), theme.TEXT_DIM)
        for rect, label in ((side_chip, f"Side: {self.side}"), (chip, f"Standard: {self.visit.standard.upper()}")):
            c.rect(rect, theme.PANEL, radius=12 * s, border=2 * s, border_colour=theme.PANEL_EDGE)
            c.text(label, (rect[0] + rect[2] / 2, rect[1] + rect[3] / 2), round(theme.BODY * s), theme.TEXT,
                   anchor="center")
        tests = self.tests
        for i, (rect, t) in enumerate(zip(rows, tests)):
            chosen = i == self.selected
            if chosen:
                c.rect(rect, (*theme.ACCENT_DARK, 255), radius=12 * s, border=3 * s, border_colour=theme.ACCENT)
            # inside the row's box (the longest titles ran past the highlight at 1280x720)
            title, size = c.fit(t.title, round(theme.BODY * s), rect[2] - 32 * s)
            c.text(title, (rect[0] + 20 * s, rect[1] + rect[3] / 2), size, theme.TEXT if chosen else theme.TEXT_DIM,
                   anchor="midleft")
        if not tests:
            return
        t = tests[self.selected]
        x = 500 * s
        width = w - x - m
        y = 150 * s
        c.text(f"{t.title}, {self.side} side", (x, y), round(theme.MEDIUM * s), theme.TEXT)
        y += 56 * s
        for heading, body, size in (("Start position", t.position_words, theme.BODY),
                                    ("Tell the patient", t.instructions, theme.BODY)):
            c.text(heading, (x, y), round(theme.SMALL * s), theme.ACCENT)
            y += 32 * s
            for line in c.wrap(body, round(size * s), width):
                c.text(line, (x, y), round(size * s), theme.TEXT)
                y += 36 * s
            y += 18 * s
        c.text("Normal value", (x, y), round(theme.SMALL * s), theme.ACCENT)
        y += 32 * s
        for line in c.wrap(reference_line(t, self.visit.standard), round(theme.BODY * s), width):
            c.text(line, (x, y), round(theme.BODY * s), theme.TEXT_DIM)
            y += 36 * s
        c.text("Up / Down: test   Left / Right: side   Enter: start   Esc: back", (w / 2, h - 20 * s),
               round(theme.SMALL * s), theme.TEXT_FAINT, anchor="midbottom")


# ============================================================================ the test
@dataclass(frozen=True, slots=True)
class Button:
    key: str
    label: str


_STEPS = (("Start position", RomState.CHECKING_START), ("Move", RomState.RECORDING), ("Done", RomState.DONE))


class RomTestScene(BaseScene):
    """One ROM test on one side, live.

    Args:
        link: the live tracker link (``new_samples`` read once per frame; ``markerset`` names the
            samples' markers; ``set_motion`` plays the demo motion).
        visit: the patient, database and standard.
        test: the test; side: ``right`` or ``left``.
        make_avatar: ``make_avatar(ctx, marker_names, roles=...)`` -> :class:`game.avatar.live.LiveAvatar`
            (None: no avatar, e.g. unit tests of the logic).
        demo: play the test's scripted motion on the simulated patient from the start.
    """

    #: The avatar's gradient resets the view's depth (:meth:`game.avatar.live.LiveAvatar.render`):
    #: the frame's clear spares it.
    clear_depth = False

    def __init__(self, link, visit: RomVisit, test: RomTest, side: str, *, make_avatar: Callable | None = None,
                 demo: bool = False) -> None:
        self.link = link
        self.visit = visit
        self.test = test
        self.side = side
        self.feed = LiveFeed(link, make_avatar)
        self.demo_motion = test.simulated_motion.get(side)
        self.demo = bool(demo and self.demo_motion and is_simulated(link))
        self.session: RomTestSession | None = None
        self.progress: RomProgress | None = None
        self.selected = 0
        self.notice = ("", theme.TEXT)
        self.previous: list = []
        self.stored_uid: str | None = None
        self._frame_consumed = -1

    # ------------------------------------------------------------------ life cycle
    def enter(self, app) -> None:
        super().enter(app)
        w, h = app.screen.size_px
        self.scale = min(w / 1280.0, h / 720.0)
        self.view = Viewport(0, 0, round(w * VIEW_SHARE), h)
        self._load_previous()
        if is_simulated(self.link):
            self.link.set_motion(self.demo_motion if self.demo else None)

    def exit(self) -> None:
        self.feed.release()

    @property
    def avatar(self):
        """The avatar (:class:`game.avatar.live.LiveAvatar`), made by the feed once the marker set is known."""
        return self.feed.avatar

    def _load_previous(self) -> None:
        try:
            self.previous = self.visit.previous(self.test.name, self.side)
        except RehabError as exc:
            self.previous = []
            self.notice = (str(exc), theme.FAILURE)

    # ------------------------------------------------------------------ samples
    @property
    def state(self) -> RomState:
        return self.session.state if self.session is not None else RomState.WAITING_TRACKER

    def consume(self) -> None:
        """Feed this frame's new samples to the session and the avatar (once per frame)."""
        if self._frame_consumed == self.app.frames:
            return
        self._frame_consumed = self.app.frames
        samples = self.feed.take(self.app)   # the avatar moves with them
        markerset = self.link.markerset
        if markerset is None:
            return
        if self.session is None:
            self.session = RomTestSession(self.test, self.side, self.visit.standard, markerset.names)
        for sample in samples:
            was = self.session.state
            self.progress = self.session.feed(sample)
            if was != RomState.DONE and self.session.state == RomState.DONE:
                # compensation: the scene asks to repeat (Repeat is chosen first); else Accept
                self.selected = 1 if self.session.result.compensated else 0

    # ------------------------------------------------------------------ actions
    def buttons(self) -> list[Button]:
        """The buttons for the current state, left to right."""
        state = self.state
        if state == RomState.DONE:
            return [Button("accept", "Accept"), Button("repeat", "Repeat"), Button("discard", "Discard")]
        if state == RomState.ACCEPTED:
            return [Button("again", "Another attempt"), Button("back", "Back to the tests")]
        out = [Button("restart", "Start again"), Button("back", "Back")]
        if self.demo_motion and is_simulated(self.link):
            out.insert(0, Button("demo", "Stop the demo" if self.demo else "Demo motion"))
        return out

    def press(self, key: str) -> None:
        """Do what a button says (tests call it with the button's key)."""
        session = self.session
        if key == "accept" and session is not None and session.state == RomState.DONE:
            result = session.result
            try:
                self.stored_uid = self.visit.store(result, source=f"sim:{self.demo_motion}" if self.demo else None)
            except RehabError as exc:
                self.notice = (f"Not stored: {exc}", theme.FAILURE)
                return
            session.accept()
            self.notice = (f"Stored: {result.rounded_deg}\N{DEGREE SIGN} for patient {self.visit.patient_id}",
                           theme.ACCENT)
            if not self.visit.last_outcome.stored:   # another program holds the database
                self.notice = (f"Kept safe: {result.rounded_deg}\N{DEGREE SIGN} is stored when the database is free "
                               f"(another program is using it)", theme.ACCENT)
            self._load_previous()
            self.selected = 0
        elif key in ("repeat", "again", "restart") and session is not None:
            session.discard()
            self.notice = ("", theme.TEXT)
            self.stored_uid = None
            self.selected = 0
        elif key == "discard":
            if session is not None:
                session.discard()
            self.app.pop()
        elif key == "back":
            self.app.pop()
        elif key == "demo":
            self.set_demo(not self.demo)

    def set_demo(self, on: bool) -> None:
        """Play (or stop) the test's motion on the simulated patient; a running attempt starts over."""
        if not (self.demo_motion and is_simulated(self.link)):
            return
        self.demo = on
        self.link.set_motion(self.demo_motion if on else None)
        if self.session is not None and self.session.state not in (RomState.DONE, RomState.ACCEPTED):
            self.session.restart()

    def handle(self, event: InputEvent) -> None:
        buttons = self.buttons()
        if isinstance(event, Press):
            if not event.down:
                return
            a = event.action
            if a is Action.LEFT:
                self.selected = (self.selected - 1) % len(buttons)
            elif a is Action.RIGHT:
                self.selected = (self.selected + 1) % len(buttons)
            elif a is Action.SELECT:
                self.press(buttons[min(self.selected, len(buttons) - 1)].key)
            elif a is Action.NEXT_MOTION:
                self.press("demo")
            elif a is Action.REIDENTIFY:
                self.link.reidentify()
            elif a is Action.BACK:
                self.app.pop()
        elif isinstance(event, Pointer) and event.kind in (PointerKind.MOVE, PointerKind.PRESS):
            w, h = self.app.screen.size_px
            k = hit(self._button_rects(len(buttons)), event.x * w, event.y * h)
            if k is None:
                return
            self.selected = k
            if event.kind is PointerKind.PRESS and event.button == 1:
                self.press(buttons[k].key)

    # ------------------------------------------------------------------ drawing
    def _panel(self) -> tuple[float, float, float]:
        """(x, right edge, bottom) of the panel right of the avatar."""
        w, h = self.app.screen.size_px
        s = self.scale
        return self.view.w + 30 * s, w - theme.MARGIN * s, h - theme.MARGIN * s

    def _button_rects(self, n: int) -> list[Rect]:
        x, right, bottom = self._panel()
        s = self.scale
        gap = 14 * s
        bw = (right - x - gap * (n - 1)) / n
        bh = 64 * s
        return [(x + i * (bw + gap), bottom - bh, bw, bh) for i in range(n)]

    def prepare(self, frame: Frame) -> None:
        """This frame's samples into the test and the avatar, its solids made (while the last
        frame rasterizes)."""
        self.consume()
        if self.avatar is not None:
            self.avatar.prepare((self.view.w, self.view.h), self.app.clock())

    def render_3d(self, frame: Frame) -> None:
        if self.avatar is None:
            return
        v = self.view
        with frame.screen.view_3d(v, frame.render_scale):
            self.avatar.render((v.w, v.h), self.app.clock())

    def status_line(self) -> tuple[str, tuple]:
        """What the scene says now, and its colour."""
        problem = self.link.problem()
        if problem is not None:
            return problem[0], theme.FAILURE if problem[1] else theme.ATTENTION
        p = self.progress
        if self.notice[0]:
            return self.notice
        if p is None:
            return "Waiting for the tracker...", theme.ATTENTION
        if self.state == RomState.DONE:
            r = self.session.result
            if r.compensated:
                return "Compensation seen: please repeat the test.", theme.ATTENTION
            return "Done: accept or discard the result.", theme.ACCENT
        if self.feed.stopped(self.app.clock()):   # the value shown is not the patient's now
            return STOPPED_LINE, theme.ATTENTION
        if p.state == RomState.CHECKING_START:
            if p.hold_fraction > 0:
                return "Hold still...", theme.ACCENT
            return f"Get into the start position: {'; '.join(p.start_problems)}", theme.ATTENTION
        if p.state == RomState.RECORDING:
            return "Move as far as you can, then come back.", theme.ACCENT
        return p.message[:1].upper() + p.message[1:], theme.ATTENTION

    def status_lines(self, c, width: float) -> tuple[list[str], int, tuple]:
        """The status line wrapped to ``width`` (at most 3 lines), its text size and colour."""
        text, colour = self.status_line()
        size = round(theme.BODY * self.scale)
        return c.wrap(text, size, width)[:3], size, colour

    def render_2d(self, frame: Frame) -> None:
        self.consume()
        c, s = frame.canvas, self.scale
        x, right, bottom = self._panel()
        width = right - x
        y = theme.MARGIN * s
        patient = f"Patient {self.visit.patient_id}"
        patient_w = c.measure(patient, round(theme.SMALL * s))[0]
        title, title_size = c.fit(f"{self.test.title}, {self.side}", round(theme.MEDIUM * s), width - patient_w - 24 * s)
        c.text(title, (x, y), title_size, theme.TEXT)
        c.text(patient, (right, y + 6 * s), round(theme.SMALL * s), theme.TEXT_DIM, anchor="topright")
        y += 50 * s
        self._draw_steps(c, x, y, width)
        y += 48 * s
        y = self._draw_readout(c, x, y, right)
        lines, size, colour = self.status_lines(c, width)
        for line in lines:
            c.text(line, (x, y), size, colour)
            y += 34 * s
        y += 6 * s
        y = self._draw_compensation(c, x, y, width)
        c.text(reference_line(self.test, self.visit.standard), (x, y), round(theme.SMALL * s), theme.TEXT_DIM)
        y += 32 * s
        buttons_top = self._button_rects(1)[0][1]
        self._draw_previous(c, x, y, buttons_top - 12 * s)
        self._draw_buttons(c)
        if self.demo:
            v = self.view
            c.text(f"Demo: simulated patient playing {self.demo_motion.replace('_', ' ')}",
                   (v.x + v.w / 2, v.h - 16 * s), round(theme.SMALL * 0.9 * s), theme.TEXT_DIM, anchor="midbottom")

    def _draw_steps(self, c, x: float, y: float, width: float) -> None:
        s = self.scale
        state = self.state
        n = len(_STEPS)
        step_w = width / n
        for i, (label, st) in enumerate(_STEPS):
            done = state > st or state == RomState.ACCEPTED
            current = state == st or (st == RomState.DONE and state == RomState.ACCEPTED)
            colour = theme.ACCENT if current else (theme.TEXT_DIM if done else theme.TEXT_FAINT)
            cx = x + i * step_w
            c.circle((cx + 14 * s, y + 14 * s), 12 * s, colour if (current or done) else (0, 0, 0, 0),
                     border=2 * s, border_colour=colour)
            c.text(label, (cx + 34 * s, y + 14 * s), round(theme.SMALL * s), colour, anchor="midleft")

    def _draw_readout(self, c, x: float, y: float, right: float) -> float:
        """The live value (whole degrees), the maximum so far (rounded to 5, raw below); returns the next y."""
        s = self.scale
        p = self.progress
        value = p.value_deg if p is not None else math.nan
        result = self.session.result if self.session is not None else None
        big = round(150 * s)
        if result is not None:
            text = f"{result.rounded_deg}\N{DEGREE SIGN}"
            label = "Result (rounded to 5)"
        else:
            text = f"{round(value):d}\N{DEGREE SIGN}" if math.isfinite(value) else "-"
            label = "Now"
        c.text(label, (x, y), round(theme.SMALL * s), theme.TEXT_DIM)
        c.text(text, (x - 6 * s, y + 22 * s), big, theme.TEXT)
        best = p.max_deg if p is not None else math.nan
        mx = right - 250 * s
        c.text("Maximum", (mx, y), round(theme.SMALL * s), theme.TEXT_DIM)
        if result is not None:
            c.text(f"raw {result.max_deg:.1f}\N{DEGREE SIGN}", (mx, y + 30 * s), round(theme.MEDIUM * s), theme.TEXT)
            # the range moved differs from the raw maximum by the start position's own angle: say so
            for k, line in enumerate(range_words(result)):
                line, size = c.fit(line, round(theme.SMALL * s), right - mx)
                c.text(line, (mx, y + (74 + 26 * k) * s), size, theme.TEXT_DIM)
        elif math.isfinite(best):
            # whole degrees while moving (never below "now"); the result is rounded to 5
            c.text(f"{round(best):d}\N{DEGREE SIGN}", (mx, y + 24 * s), round(theme.TITLE * s), theme.ACCENT)
        else:
            c.text("-", (mx, y + 24 * s), round(theme.TITLE * s), theme.TEXT_FAINT)
        estimated = result.estimated if result is not None else (p is not None and p.estimated)
        if estimated:
            words = ("Relied on estimated (hidden) markers: " + ", ".join(result.estimated_markers)) if result \
                else "Now reading estimated (hidden) markers"
            c.text(words, (x, y + 160 * s), round(theme.SMALL * s), theme.ATTENTION)
        if p is not None and p.state == RomState.CHECKING_START and p.hold_fraction > 0:
            c.rect((mx, y + 110 * s, 220 * s, 12 * s), (255, 255, 255, 30), radius=6 * s)
            c.rect((mx, y + 110 * s, 220 * s * min(p.hold_fraction, 1.0), 12 * s), theme.ACCENT, radius=6 * s)
        return y + 196 * s

    def _draw_compensation(self, c, x: float, y: float, width: float) -> float:
        s = self.scale
        p = self.progress
        comps = self.session.result.compensations if self.session is not None and self.session.result is not None \
            else (p.compensations if p is not None else ())
        if not comps:
            return y
        size = round(theme.SMALL * s)
        lines = [ln for comp in comps for ln in c.wrap(comp[:1].upper() + comp[1:], size, width - 30 * s)][:4]
        h = len(lines) * 30 * s + 20 * s
        c.rect((x, y, width, h), theme.OVERLAY, radius=12 * s, border=3 * s, border_colour=theme.ATTENTION)
        for k, line in enumerate(lines):
            c.text(line, (x + 15 * s, y + 10 * s + k * 30 * s), size, theme.TEXT)
        return y + h + 12 * s

    def _draw_previous(self, c, x: float, y: float, bottom: float) -> None:
        """The latest previous results that fit above ``bottom`` (at most :data:`PREVIOUS_SHOWN`)."""
        s = self.scale
        size = round(theme.SMALL * s)
        if not self.previous:
            c.text("No previous results for this test and side.", (x, y), size, theme.TEXT_FAINT)
            return
        fit = min(PREVIOUS_SHOWN, int((bottom - y - 30 * s) // (28 * s)))
        if fit < 1:
            return
        more = len(self.previous) - fit
        c.text("Previous results" + (f" (latest {fit} of {len(self.previous)})" if more > 0 else ""), (x, y), size,
               theme.TEXT_DIM)
        y += 30 * s
        for row in self.previous[-fit:]:
            c.text(previous_line(row), (x + 12 * s, y), size, theme.TEXT)
            y += 28 * s

    def _draw_buttons(self, c) -> None:
        s = self.scale
        buttons = self.buttons()
        self.selected = min(self.selected, len(buttons) - 1)
        for i, (rect, b) in enumerate(zip(self._button_rects(len(buttons)), buttons)):
            chosen = i == self.selected
            if chosen:
                c.rect(rect, (*theme.ACCENT_DARK, 255), radius=14 * s, border=3 * s, border_colour=theme.ACCENT)
            else:
                c.rect(rect, theme.PANEL, radius=14 * s, border=2 * s, border_colour=theme.PANEL_EDGE)
            c.text(b.label, (rect[0] + rect[2] / 2, rect[1] + rect[3] / 2), round(theme.BODY * s),
                   theme.TEXT if chosen else theme.TEXT_DIM, anchor="center")
