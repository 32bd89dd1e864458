"""The progress review: one patient's ROM results over the sessions, and the games played.

Left, the tests the patient has results for (Up/Down or the mouse choose); right, the chosen
test's maxima over the sessions as a plot (both sides, in session order), with the normal band
of the standard (from the normal value down 10 %, as in ``rehab report``; none when the standard's
value is for another position) and the 5-degree recording grid; rings mark compensated attempts,
crosses maxima that rested on estimated markers. Under the plot, per side, the change from the
previous session in words, called real only beyond the test's smallest detectable change
(``+8 degrees: within the measurement's smallest detectable change of 9 degrees — not a real
change yet``). Below, the games' repetitions and minutes per session, or "No games yet".

Plots are drawn by matplotlib (Agg, no pyplot state) into an RGB array once per choice and
uploaded as one texture; the scene's colours match the application's theme. **Export report**
(the button, or Enter) writes what ``rehab report`` writes (HTML with the plots and the table, CSV
beside it) into ``reports/`` beside the database, readable by the user only, and says where.
matplotlib is imported where a plot is drawn, not with the scene: the application imports the
scene at its start, and matplotlib's import took 3-6 s on the loaded 2-core machine.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from calibration.errors import RehabError
from game.app import BaseScene, Frame
from game.db import Database
from game.db.database import utc_now
from game.db.location import db_location, local_folder
from game.gfx import theme
from game.input import Action, InputEvent, Pointer, PointerKind, Press
from game.report import (HistoryLook, change_line, latest_changes, plot_games, plot_rom_history, sdc_words,
                         session_order, write_report)
from game.rom.session import round_to_5
from game.rom.spec import load_rom_test
from tracking.errors import ContentError

#: Height of the change lines under the plot (at 1280x720).
CHANGE_LINES_H = 56

#: Plot colours (sRGB hex) on the application's dark background.
BAND_COLOUR = "#5ec8be"
SIDE_COLOURS = {"right": ("#f2be5c", "o"), "left": ("#8fb4ff", "s")}
_BG = "#%02x%02x%02x" % theme.BACKGROUND
_TEXT = "#%02x%02x%02x" % theme.TEXT
_DIM = "#%02x%02x%02x" % theme.TEXT_DIM
_GRID = "#3a4556"
_GAME_LOOK = HistoryLook(
    band_rgb=BAND_COLOUR, band_alpha=0.30, band_line_width=1.5, band_label="normal, {standard} {normal:g}",
    side_style=SIDE_COLOURS, line_width=2.5, marker_size=10, line_zorder=4,
    compensation_rgb="#e87068", compensation_size=330, compensation_width=2.5,
    estimated_rgb=_TEXT, estimated_size=90,
    minor_grid_rgb=_GRID, major_grid_rgb="#56637a", minor_grid_width=0.7, major_grid_width=1.0,
    coarse_above_deg=100, date_chars=slice(5, 10))


def _figure_rgb(fig) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a matplotlib figure drawn by Agg."""
    # lazy: matplotlib (0.4 s to import) only when a plot is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()


def _style(ax) -> None:
    ax.set_facecolor(_BG)
    for spine in ax.spines.values():
        spine.set_color(_GRID)
    ax.tick_params(colors=_DIM, labelsize=13)
    ax.xaxis.label.set_color(_DIM)
    ax.yaxis.label.set_color(_DIM)


def rom_plot_rgb(title: str, rows: Sequence, order: dict[str, int], normal_deg: float | None, standard: str,
                 size_px: tuple[int, int]) -> np.ndarray:
    """One test's maxima over the sessions as an (H, W, 3) uint8 RGB image of ``size_px`` (w, h).

    Args:
        rows: the test's :class:`game.db.RomRow` (both sides).
        order: session uid -> session number (:func:`game.report.session_order`).
        normal_deg: the standard's normal value for the test's position (None: no band).
    """
    from matplotlib.figure import Figure  # lazy: matplotlib (0.4 s to import) only when a plot is drawn

    dpi = 100
    fig = Figure(figsize=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi, facecolor=_BG)
    ax = fig.add_subplot(1, 1, 1)
    _style(ax)
    xs, dates = plot_rom_history(ax, rows, order, normal_deg, standard, _GAME_LOOK)
    ax.set_xticks(xs)
    ax.set_xticklabels([f"#{x}\n{dates[x]}" for x in xs])
    ax.set_xlim(min(xs) - 0.5, max(xs) + 0.5)
    ax.set_ylabel("degrees (active ROM)", fontsize=13)
    ax.set_title(title, color=_TEXT, fontsize=17, loc="left")
    # beside the axes: over the plot it would hide the band or the points
    legend = ax.legend(fontsize=12, loc="upper left", bbox_to_anchor=(1.01, 1.0), facecolor=_BG, edgecolor=_GRID)
    for text in legend.get_texts():
        text.set_color(_TEXT)
    fig.tight_layout()
    return _figure_rgb(fig)


def games_plot_rgb(rows: Sequence, order: dict[str, int], size_px: tuple[int, int]) -> np.ndarray:
    """Repetitions per game and minutes played per session as an (H, W, 3) uint8 RGB image; what
    the automatic demo played is stacked on the patient's own, hatched and faded."""
    from matplotlib.figure import Figure  # lazy: matplotlib (0.4 s to import) only when a plot is drawn

    dpi = 100
    fig = Figure(figsize=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi, facecolor=_BG)
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    handles = plot_games(ax1, ax2, rows, order, ("#5ec8be", "#f2be5c", "#8fb4ff", "#e87068"), "#a3aebe", _DIM)
    xs = sorted({order[r.session_uid] for r in rows})
    for ax, label in ((ax1, "repetitions"), (ax2, "minutes played")):
        _style(ax)
        ax.set_xticks(xs)
        ax.set_xticklabels([f"#{x}" for x in xs])
        ax.set_title(label, color=_TEXT, fontsize=13, loc="left")
        ax.grid(True, axis="y", color=_GRID)
    # the legend right of both plots: inside one it covered the bars
    legend = fig.legend(handles=handles, fontsize=11, loc="center right", facecolor=_BG, edgecolor=_GRID)
    for text in legend.get_texts():
        text.set_color(_TEXT)
    fig.tight_layout(rect=(0.0, 0.0, _legend_share(fig, legend), 1.0))
    return _figure_rgb(fig)


def _legend_share(fig, legend) -> float:
    """The share of the figure's width left of a legend placed at its right edge."""
    # lazy: matplotlib (0.4 s to import) only when a plot is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    width = legend.get_window_extent(renderer).width
    return max(0.5, 1.0 - (width + 8.0) / (fig.get_figwidth() * fig.dpi))


@dataclass(frozen=True, slots=True)
class TestInfo:
    """A stored test's title and the standard's normal value for its position (None: no band)."""

    title: str
    normal_deg: float | None
    sdc_deg: float | None = None


def _inside(rect, x: float, y: float) -> bool:
    return rect[0] <= x < rect[0] + rect[2] and rect[1] <= y < rect[1] + rect[3]


def test_info(test: str, standard: str) -> TestInfo:
    """What the content says about a stored test (a test this installation lacks keeps its name)."""
    try:
        t = load_rom_test(test)
    except ContentError:
        return TestInfo(test.replace("_", " ").capitalize(), None)
    return TestInfo(t.title, t.normal_deg(standard), t.sdc_deg)


class ProgressScene(BaseScene):
    """One patient's progress.

    Args:
        db_path: the database file.
        patient_id: the patient (must exist).
        standard: ``jarm`` or ``aaos``: the normal band shown (never both).
    """

    def __init__(self, db_path: Path, patient_id: str, *, standard: str = "jarm") -> None:
        self.db_path = db_location(db_path)
        self.patient_id = patient_id
        self.standard = standard
        self.roms: list = []
        self.games: list = []
        self.order: dict[str, int] = {}
        self.tests: list[str] = []
        self.titles: dict[str, str] = {}
        self.selected = 0
        self.error = ""
        self._textures: dict[str, object] = {}
        self._shown: tuple | None = None          # (test, size) of the ROM plot's texture
        self._games_shown: tuple | None = None    # size of the games plot's texture
        self._rom_plots: dict[tuple, np.ndarray] = {}   # (test, size) -> the plot's RGB image
        self.notice: tuple[str, tuple] = ("", theme.TEXT_DIM)   # what the export did

    # ------------------------------------------------------------------ data
    def enter(self, app) -> None:
        super().enter(app)
        self.load()
        if not self.error:   # the first plots now, while "Opening ..." is on the screen (matplotlib takes seconds)
            _, _, plot, games = self._layout()
            self._ensure_plots(plot, games)

    def load(self) -> None:
        try:
            with Database(self.db_path) as db:
                db.require_patient(self.patient_id)
                self.roms = db.rom_results(self.patient_id)
                self.games = db.exercise_results(self.patient_id)
        except RehabError as exc:
            self.error = str(exc)
            return
        self.order = session_order(list(self.roms) + list(self.games))
        first: dict[str, int] = {}
        for r in self.roms:
            first.setdefault(r.test, self.order[r.session_uid])
        self.tests = sorted(first, key=lambda t: (first[t], t))
        self.infos = {t: test_info(t, self.standard) for t in self.tests}
        self.selected = min(self.selected, max(len(self.tests) - 1, 0))

    def exit(self) -> None:
        for tex in self._textures.values():
            tex.release()
        self._textures.clear()

    # ------------------------------------------------------------------ layout
    def _layout(self):
        w, h = self.app.screen.size_px
        s = min(w / 1280.0, h / 720.0)
        m = theme.MARGIN * s
        list_w = 330 * s
        top = 120 * s
        # every test's row fits above the key line at the bottom
        pitch = min(58 * s, (h - 60 * s - top) / max(len(self.tests), 1))
        rows = [(m, top + i * pitch, list_w, pitch - 8 * s) for i in range(len(self.tests))]
        plot_x = m + list_w + 24 * s
        plot = (plot_x, top, w - plot_x - m, (h - top - 60 * s) * 0.66 - CHANGE_LINES_H * s)
        below = plot[1] + plot[3] + CHANGE_LINES_H * s
        games = (plot_x, below + 14 * s, plot[2], h - 60 * s - below - 14 * s)
        return s, rows, plot, games

    def change_lines(self, test: str) -> list[tuple[str, bool | None]]:
        """The lines under the chosen test's plot: per side the latest change in words and whether
        it is real (None: no SDC measured), or the SDC sentence when no side has two sessions."""
        info = self.infos[test]
        changes = latest_changes([r for r in self.roms if r.test == test], self.order, info.sdc_deg)
        if not changes:
            return [(sdc_words(info.sdc_deg), None)]
        return [(change_line(ch, self.order), ch.real) for ch in changes]

    def export_rect(self) -> tuple[float, float, float, float]:
        """The Export report button, top right under the standard's line."""
        w, h = self.app.screen.size_px
        s = min(w / 1280.0, h / 720.0)
        bw, bh = 230 * s, 44 * s
        return (w - theme.MARGIN * s - bw, 66 * s, bw, bh)

    def export(self) -> Path | None:
        """Write the report (HTML and CSV) into ``reports/`` beside the database; says where."""
        folder = local_folder(self.db_path) / "reports"
        out = folder / f"{self.patient_id}_{utc_now()[:10]}.html"
        try:
            folder.mkdir(mode=0o700, parents=True, exist_ok=True)
            with Database(self.db_path) as db:
                html_path, csv_path = write_report(db, self.patient_id, out, standard=self.standard)
            for path in (html_path, csv_path):   # patient data: readable by the user only
                path.chmod(0o600)
        except (RehabError, OSError) as exc:
            self.notice = (f"Not exported: {exc}", theme.FAILURE)
            return None
        self.notice = (f"Exported: {html_path} (and the CSV beside it)", theme.ACCENT)
        return html_path

    def _texture(self, key: str, rgb: np.ndarray):
        old = self._textures.pop(key, None)
        if old is not None:
            old.release()
        h, w = rgb.shape[:2]
        tex = self.app.screen.ctx.texture((w, h), 3, np.ascontiguousarray(rgb).tobytes(), alignment=1)
        self._textures[key] = tex
        return tex

    def _ensure_plots(self, plot: tuple, games: tuple) -> None:
        """The selected test's plot and the games' plot as textures. Each is drawn by matplotlib
        once per size (a second or more on a busy machine, in the frame that needs it): moving
        through the list shows a test drawn before from memory, and never redraws the games."""
        rom_size, games_size = (round(plot[2]), round(plot[3])), (round(games[2]), round(games[3]))
        if self.tests:  # a patient may have played games before any ROM test
            test = self.tests[self.selected]
            key = (test, rom_size)
            if self._shown != key:
                rgb = self._rom_plots.get(key)
                if rgb is None:
                    info = self.infos[test]
                    rows = [r for r in self.roms if r.test == test]
                    rgb = self._rom_plots[key] = rom_plot_rgb(info.title, rows, self.order, info.normal_deg,
                                                              self.standard, rom_size)
                self.plot_rgb = rgb
                self._texture("rom", rgb)
                self._shown = key
        if self.games and games[3] > 40 and self._games_shown != games_size:
            self._texture("games", games_plot_rgb(self.games, self.order, games_size))
            self._games_shown = games_size

    # ------------------------------------------------------------------ input
    def handle(self, event: InputEvent) -> None:
        n = len(self.tests)
        if isinstance(event, Press):
            if not event.down:
                return
            if event.action is Action.UP and n:
                self.selected = (self.selected - 1) % n
            elif event.action is Action.DOWN and n:
                self.selected = (self.selected + 1) % n
            elif event.action is Action.SELECT and not self.error:
                self.app.busy("Writing the report...", self.export)
            elif event.action is Action.BACK:
                self.app.pop()
        elif isinstance(event, Pointer) and event.kind is PointerKind.PRESS and event.button == 1 and not self.error \
                and _inside(self.export_rect(), event.x * self.app.screen.size_px[0], event.y * self.app.screen.size_px[1]):
            self.app.busy("Writing the report...", self.export)
        elif isinstance(event, Pointer) and event.kind in (PointerKind.MOVE, PointerKind.PRESS) and n:
            w, h = self.app.screen.size_px
            _, rows, _, _ = self._layout()
            for i, (rx, ry, rw, rh) in enumerate(rows):
                if rx <= event.x * w < rx + rw and ry <= event.y * h < ry + rh:
                    self.selected = i

    def latest_words(self, test: str) -> str:
        """The latest result per side, rounded to 5: ``R 145°  L 140°``."""
        parts = []
        for side in ("right", "left"):
            rows = [r for r in self.roms if r.test == test and r.side == side]
            if rows:
                parts.append(f"{side[0].upper()} {round_to_5(rows[-1].value_deg)}\N{DEGREE SIGN}")
        return "  ".join(parts)

    # ------------------------------------------------------------------ drawing
    def row_texts(self, c, rect: tuple, test: str) -> list[tuple[str, int, tuple[float, float], str]]:
        """A test's row of the list: (text, size, position, anchor) of its title, made to fit
        beside the latest values (on two lines when long), and of the values."""
        s = min(self.app.screen.size_px[0] / 1280.0, self.app.screen.size_px[1] / 720.0)
        size = round(theme.SMALL * s)
        values = self.latest_words(test)
        values_w = c.measure(values, size)[0]
        room = rect[2] - 16 * s - 14 * s - values_w - 14 * s
        mid = rect[1] + rect[3] / 2
        out = [(values, size, (rect[0] + rect[2] - 14 * s, mid), "midright")]
        title = self.infos[test].title
        if c.measure(title, size)[0] <= room:
            return [(title, size, (rect[0] + 16 * s, mid), "midleft")] + out
        # a long title: two lines, a little smaller (cut with an ellipsis only beyond that)
        small = round(size * 0.85)
        lines = c.wrap(title, small, room)
        if len(lines) > 2:
            lines = [lines[0], c.fit(" ".join(lines[1:]), small, room, min_size=small)[0]]
        lines = [c.fit(line, small, room, min_size=small)[0] for line in lines]
        step = c.measure("Ag", small)[1] * 0.95
        top = mid - step * (len(lines) - 1) / 2
        return [(line, small, (rect[0] + 16 * s, top + k * step), "midleft") for k, line in enumerate(lines)] + out

    def render_2d(self, frame: Frame) -> None:
        c = frame.canvas
        w, h = frame.size_px
        s, rows, plot, games = self._layout()
        m = theme.MARGIN * s
        c.text(f"Progress: patient {self.patient_id}", (m, 30 * s), round(theme.LARGE * s), theme.TEXT)
        c.text(f"Active ROM, maxima per session; normal band {self.standard.upper()}", (w - m, 44 * s),
               round(theme.SMALL * s), theme.TEXT_DIM, anchor="topright")
        if self.error:
            for k, line in enumerate(c.wrap(self.error, round(theme.BODY * s), w - 2 * m)[:4]):
                c.text(line, (m, 140 * s + 40 * s * k), round(theme.BODY * s), theme.FAILURE)
            return
        if not self.tests:
            c.text("No ROM results yet.", (plot[0] + plot[2] / 2, plot[1] + plot[3] / 2), round(theme.MEDIUM * s),
                   theme.TEXT_DIM, anchor="center")
        for i, (rect, test) in enumerate(zip(rows, self.tests)):
            chosen = i == self.selected
            if chosen:
                c.rect(rect, (*theme.ACCENT_DARK, 255), radius=12 * s, border=3 * s, border_colour=theme.ACCENT)
            colour = theme.TEXT if chosen else theme.TEXT_DIM
            for text, size, pos, anchor in self.row_texts(c, rect, test):
                c.text(text, pos, size, colour, anchor=anchor)
        self._ensure_plots(plot, games)
        if self.tests:
            c.texture(self._textures["rom"], plot)
            lines = self.change_lines(self.tests[self.selected])[:2]
            size = round(theme.SMALL * s)
            size = min(c.fit(line, size, plot[2], min_size=round(size * 0.75))[1] for line, _ in lines)  # one size
            for k, (line, real) in enumerate(lines):
                text, _ = c.fit(line, size, plot[2], min_size=size)
                c.text(text, (plot[0], plot[1] + plot[3] + 6 * s + k * 26 * s), size,
                       theme.ACCENT if real else theme.TEXT_DIM)
        if self.games and "games" in self._textures:
            c.texture(self._textures["games"], games)
        else:
            c.text("No games yet.", (games[0] + 20 * s, games[1] + 20 * s), round(theme.BODY * s), theme.TEXT_DIM)
        if not self.error:
            bx, by, bw, bh = self.export_rect()
            c.rect((bx, by, bw, bh), (*theme.ACCENT_DARK, 255), radius=12 * s, border=2 * s, border_colour=theme.ACCENT)
            c.text("Export report", (bx + bw / 2, by + bh / 2), round(theme.BODY * s), theme.TEXT, anchor="center")
        notice, colour = self.notice
        if notice:
            text, size = c.fit(notice, round(theme.SMALL * s), w - 2 * m)
            c.text(text, (w / 2, h - 16 * s), size, colour, anchor="midbottom")
        else:
            c.text("Up / Down: test   Enter or the button: export the report (HTML and CSV)   Esc: back",
                   (w / 2, h - 16 * s), round(theme.SMALL * s), theme.TEXT_FAINT, anchor="midbottom")
