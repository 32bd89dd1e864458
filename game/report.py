"""Progress report of one patient for the clinic record (``rehab report PATIENT --out report.html``).

One self-contained HTML file: per ROM test a plot of the recorded maximum over the sessions (in
session order, both sides, with the normal band of the chosen standard and the 5-degree recording
grid), the table of every ROM result (raw and rounded, labelled active ROM with the test position
and the standard it was recorded with), and the games' repetitions and session durations. Plots
are PNG (matplotlib, Agg, no pyplot state) embedded as data URIs; the ROM table is also written
as CSV beside the HTML. Nothing but the pseudonymous ID identifies the patient. A change between
two sessions is called real only beyond the test's smallest detectable change (content ``sdc:``,
:mod:`game.rom.sdc`), in words, per side and per row.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from calibration.errors import RehabError
from game.db.database import Database, ExerciseRow, RomRow, utc_now
from game.db.private import make_private_dir, open_private
from game.rom.sdc import change_words, is_real_change
from game.rom.session import round_to_5
from game.rom.spec import STANDARDS, check_standard, load_rom_test
from tracking.errors import ContentError

#: The normal band: from this fraction below the standard's normal value up to it.
NORMAL_BAND_FRACTION = 0.10


@dataclass(frozen=True, slots=True)
class SessionChange:
    """The change of one test and side from one session to the next.

    Attributes:
        side: ``right`` or ``left``.
        previous, latest: the two results (:class:`game.db.RomRow`), in session order.
        change_deg: ``latest.value_deg - previous.value_deg`` (raw maxima).
        real: beyond the smallest detectable change (None: no SDC measured for the test).
        words: the change in words (:func:`game.rom.sdc.change_words`).
    """

    side: str
    previous: RomRow
    latest: RomRow
    change_deg: float
    real: bool | None
    words: str


def session_changes(rows: Sequence[RomRow], order: dict[str, int], sdc_deg: float | None) -> list[SessionChange]:
    """Every change between consecutive sessions of one test's results (both sides), in order."""
    out = []
    for side in ("right", "left"):
        mine = sorted((r for r in rows if r.side == side), key=lambda r: (order[r.session_uid], r.recorded_utc))
        for prev, last in zip(mine, mine[1:]):
            change = last.value_deg - prev.value_deg
            out.append(SessionChange(side, prev, last, change, is_real_change(change, sdc_deg),
                                     change_words(change, sdc_deg)))
    return out


def latest_changes(rows: Sequence[RomRow], order: dict[str, int], sdc_deg: float | None) -> list[SessionChange]:
    """Per side, the change from the previous session to the latest one (sides with one result: none)."""
    latest: dict[str, SessionChange] = {}
    for ch in session_changes(rows, order, sdc_deg):
        latest[ch.side] = ch
    return [latest[s] for s in ("right", "left") if s in latest]


def change_line(ch: SessionChange, order: dict[str, int]) -> str:
    """``Right, #2 to #3: +8 degrees: within ... not a real change yet`` (session numbers)."""
    return f"{ch.side.capitalize()}, #{order[ch.previous.session_uid]} to #{order[ch.latest.session_uid]}: {ch.words}"


def sdc_words(sdc_deg: float | None) -> str:
    """The test's smallest detectable change in one sentence."""
    if sdc_deg is None:
        return "No smallest detectable change has been measured for this test: changes are not judged."
    return (f"Smallest detectable change of this test: {sdc_deg:.0f} degrees (measured on the simulated patient); "
            f"a change between two sessions is real only beyond it.")



@dataclass(frozen=True, slots=True)
class HistoryLook:
    """How :func:`plot_rom_history` draws (the HTML report's light figure, the game's dark one).

    Attributes:
        band_rgb, band_alpha, band_line_width: the normal band and its upper line.
        band_label: the band's legend entry, formatted with ``standard`` and ``normal_deg``.
        side_style: per side, (colour, marker); line_width, marker_size: of the sides' lines.
        compensation_rgb, compensation_size, compensation_width: rings round compensated maxima.
        estimated_rgb, estimated_size: crosses on maxima that relied on estimated markers.
        minor_grid_rgb, major_grid_rgb, minor_grid_width, major_grid_width: the y grid (5-degree
            minor lines, the clinical recording grid).
        coarse_above_deg: a y span over this many degrees gets 20-degree major lines, else 10.
        date_chars: the slice of the session's UTC time stamp shown under its number.
        line_zorder: of the sides' lines (None: matplotlib's default).
    """

    band_rgb: str
    band_alpha: float
    band_line_width: float
    band_label: str
    side_style: dict
    line_width: float
    marker_size: float
    compensation_rgb: str
    compensation_size: float
    compensation_width: float
    estimated_rgb: str
    estimated_size: float
    minor_grid_rgb: str
    major_grid_rgb: str
    minor_grid_width: float
    major_grid_width: float
    coarse_above_deg: float
    date_chars: slice
    line_zorder: float | None = None


_REPORT_LOOK = HistoryLook(
    band_rgb="#2ca02c", band_alpha=0.18, band_line_width=1.2,
    band_label="normal ({standard} {normal:g}, band to -" + f"{100 * NORMAL_BAND_FRACTION:.0f}" + " %)",
    side_style={"right": ("#1f77b4", "o"), "left": ("#d62728", "s")}, line_width=1.5, marker_size=7,
    compensation_rgb="#ff7f0e", compensation_size=180, compensation_width=2,
    estimated_rgb="black", estimated_size=60,
    minor_grid_rgb="#dddddd", major_grid_rgb="#bbbbbb", minor_grid_width=0.6, major_grid_width=0.8,
    coarse_above_deg=120, date_chars=slice(0, 10))


def plot_rom_history(ax, rows: Sequence[RomRow], order: dict[str, int], normal_deg: float | None, standard: str,
                     look: HistoryLook) -> tuple[list[int], dict[int, str]]:
    """Draw one test's maxima over the sessions (both sides, the normal band, compensation and
    estimated-marker flags, the 5-degree grid) on ``ax``.

    Returns:
        The session numbers shown and each one's date text, for the caller's x tick labels.
    """
    from matplotlib.ticker import MultipleLocator  # lazy: matplotlib (0.4 s to import) only when a plot is drawn

    values = [r.value_deg for r in rows]
    if normal_deg is not None:
        lo = normal_deg * (1.0 - NORMAL_BAND_FRACTION)
        ax.axhspan(lo, normal_deg, color=look.band_rgb, alpha=look.band_alpha, lw=0,
                   label=look.band_label.format(standard=standard.upper(), normal=normal_deg))
        ax.axhline(normal_deg, color=look.band_rgb, lw=look.band_line_width)
        values += [lo, normal_deg]
    for side in ("right", "left"):
        pts = sorted(((order[r.session_uid], r) for r in rows if r.side == side), key=lambda p: p[0])
        if not pts:
            continue
        colour, marker = look.side_style[side]
        extra = {} if look.line_zorder is None else {"zorder": look.line_zorder}
        ax.plot([p[0] for p in pts], [p[1].value_deg for p in pts], color=colour, lw=look.line_width, marker=marker,
                ms=look.marker_size, label=side, **extra)
        flagged = [(x, r.value_deg) for x, r in pts if r.compensation]
        if flagged:
            ax.scatter(*zip(*flagged), s=look.compensation_size, facecolors="none", edgecolors=look.compensation_rgb,
                       linewidths=look.compensation_width, zorder=5, label=f"{side}: compensation")
        est = [(x, r.value_deg) for x, r in pts if r.estimated_markers]
        if est:
            ax.scatter(*zip(*est), s=look.estimated_size, marker="x", color=look.estimated_rgb, zorder=6,
                       label=f"{side}: estimated markers")
    lo_y = 5 * (int(min(values) // 5) - 2)
    hi_y = 5 * (int(max(values) // 5) + 3)
    ax.set_ylim(lo_y, hi_y)
    ax.yaxis.set_minor_locator(MultipleLocator(5))   # the clinical 5-degree recording grid
    ax.yaxis.set_major_locator(MultipleLocator(10 if hi_y - lo_y <= look.coarse_above_deg else 20))
    ax.grid(True, which="minor", axis="y", color=look.minor_grid_rgb, lw=look.minor_grid_width)
    ax.grid(True, which="major", axis="y", color=look.major_grid_rgb, lw=look.major_grid_width)
    xs = sorted({order[r.session_uid] for r in rows})
    dates = {order[r.session_uid]: r.session_started_utc[look.date_chars] for r in rows}
    return xs, dates

_CSV_COLUMNS = ("session_started_utc", "test", "side", "angle", "mode", "position", "standard", "reference_deg",
                "value_deg", "rounded_deg", "start_deg", "range_deg", "compensation", "estimated_markers",
                "duration_s", "recorded_utc", "uid")


@dataclass(frozen=True, slots=True)
class _TestInfo:
    title: str
    normal_deg: float | None
    position_words: str
    sdc_deg: float | None


def _test_info(test: str, standard: str) -> _TestInfo:

    try:
        t = load_rom_test(test)
    except ContentError:  # a result of a test this installation does not define
        return _TestInfo(test.replace("_", " "), None, "", None)
    return _TestInfo(t.title, t.normal_deg(standard), t.position_words, t.sdc_deg)


def _png(fig) -> str:
    # lazy: matplotlib (0.4 s to import) only when a plot is drawn
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def session_order(rows: Sequence[RomRow | ExerciseRow]) -> dict[str, int]:
    """Session uid -> 1-based number in time order (over the rows given)."""
    seen: dict[str, str] = {}
    for r in rows:
        seen.setdefault(r.session_uid, r.session_started_utc)
    ordered = sorted(seen, key=lambda uid: (seen[uid], uid))
    return {uid: i + 1 for i, uid in enumerate(ordered)}


def rom_plot_png(title: str, rows: Sequence[RomRow], order: dict[str, int], normal_deg: float | None,
                 standard: str) -> str:
    """One test's maxima over the sessions (both sides) as a base64 PNG."""
    from matplotlib.figure import Figure  # lazy: matplotlib (0.4 s to import) only when a plot is drawn

    fig = Figure(figsize=(7.5, 3.4))
    ax = fig.add_subplot(1, 1, 1)
    xs, dates = plot_rom_history(ax, rows, order, normal_deg, standard, _REPORT_LOOK)
    ax.set_xticks(xs)
    ax.set_xticklabels([f"#{x}\n{dates[x]}" for x in xs], fontsize=8)
    ax.set_xlim(min(xs) - 0.5, max(xs) + 0.5)
    ax.set_xlabel("session")
    ax.set_ylabel("maximum (deg, active ROM)")
    ax.set_title(title)
    ax.legend(fontsize=8, loc="best", framealpha=0.85)
    fig.tight_layout()
    return _png(fig)


@dataclass(frozen=True, slots=True)
class DemoPart:
    """What the automatic demo played of a stored game result (from its details).

    Attributes:
        repetitions: targets collected while the demo played.
        seconds: active play time of the demo.
        active_s: active play time of the whole session.
    """

    repetitions: int
    seconds: float
    active_s: float

    @property
    def words(self) -> str:
        """Who played: ``patient``, ``demo``, or ``patient + demo (40 s)``."""
        if self.seconds <= 0.0:
            return "patient"
        if self.seconds >= self.active_s - 0.05:
            return "demo"
        return f"patient + demo ({self.seconds:.0f} s)"


def demo_part(row: ExerciseRow) -> DemoPart:
    """The demo's share of a game result (none for results stored before it was logged)."""
    try:
        d = json.loads(row.details) if row.details else {}
    except ValueError:
        d = {}
    if not isinstance(d, dict):
        d = {}
    reps = sum(1 for t in d.get("targets", ()) if isinstance(t, dict) and t.get("demo") and t.get("reached"))
    return DemoPart(int(min(reps, row.repetitions)), float(d.get("demo_s", 0.0) or 0.0), float(d.get("active_s", 0.0) or 0.0))


def score_words(row: ExerciseRow) -> str:
    """The share of targets collected, in whole percent (empty when none was shown)."""
    return "" if row.score is None else f"{round(100.0 * row.score):d} %"


#: How the demo's part of a bar is drawn: hatched and faded over the patient's own.
DEMO_HATCH, DEMO_ALPHA = "///", 0.35


def plot_games(ax_reps, ax_minutes, rows: Sequence[ExerciseRow], order: dict[str, int], colours: Sequence[str],
               minutes_rgb: str, demo_edge_rgb: str) -> list:
    """Repetitions per game and minutes per session as bars, the demo's part of each stacked on
    the patient's own, hatched and faded; returns the legend handles (one per game, and one for
    the demo when it played)."""
    from matplotlib.patches import Patch  # lazy: matplotlib (0.4 s to import) only when a plot is drawn
    from matplotlib.ticker import MaxNLocator  # lazy: matplotlib (0.4 s to import) only when a plot is drawn

    games = sorted({r.game for r in rows})
    width = 0.8 / max(len(games), 1)
    handles = []
    for k, game in enumerate(games):
        own: dict[int, int] = defaultdict(int)
        demo: dict[int, int] = defaultdict(int)
        for r in rows:
            if r.game == game:
                part = demo_part(r)
                own[order[r.session_uid]] += r.repetitions - part.repetitions
                demo[order[r.session_uid]] += part.repetitions
        xs = sorted(own)
        pos = [x - 0.4 + width * (k + 0.5) for x in xs]
        colour = colours[k % len(colours)]
        ax_reps.bar(pos, [own[x] for x in xs], width=width, color=colour)
        if any(demo.values()):
            ax_reps.bar(pos, [demo[x] for x in xs], width=width, bottom=[own[x] for x in xs], color=colour,
                        alpha=DEMO_ALPHA, hatch=DEMO_HATCH, edgecolor=demo_edge_rgb, linewidth=0)
        handles.append(Patch(color=colour, label=game.replace("_", " ")))
    own_min: dict[int, float] = defaultdict(float)
    demo_min: dict[int, float] = defaultdict(float)
    for r in rows:
        part = demo_part(r)
        share = min(part.seconds / part.active_s, 1.0) if part.active_s > 0 else 0.0
        own_min[order[r.session_uid]] += r.duration_s / 60.0 * (1.0 - share)
        demo_min[order[r.session_uid]] += r.duration_s / 60.0 * share
    xs = sorted(own_min)
    ax_minutes.bar(xs, [own_min[x] for x in xs], width=0.6, color=minutes_rgb)
    if any(demo_min.values()):
        ax_minutes.bar(xs, [demo_min[x] for x in xs], width=0.6, bottom=[own_min[x] for x in xs], color=minutes_rgb,
                       alpha=DEMO_ALPHA, hatch=DEMO_HATCH, edgecolor=demo_edge_rgb, linewidth=0)
    if any(demo_part(r).seconds > 0 for r in rows):
        handles.append(Patch(facecolor="none", hatch=DEMO_HATCH, edgecolor=demo_edge_rgb, label="played by the demo"))
    # counts and minutes from zero, repetitions in whole numbers (a game with none collected drew an
    # axis from -0.05 to 0.05)
    ax_reps.yaxis.set_major_locator(MaxNLocator(integer=True))
    for ax, least in ((ax_reps, 1.0), (ax_minutes, 0.5)):
        ax.set_ylim(0.0, max(ax.get_ylim()[1], least))
    return handles


def exercise_plot_png(rows: Sequence[ExerciseRow], order: dict[str, int]) -> str:
    """Repetitions per game and session, and session durations, as a base64 PNG (the demo's part hatched)."""
    from matplotlib.figure import Figure  # lazy: matplotlib (0.4 s to import) only when a plot is drawn

    fig = Figure(figsize=(7.5, 4.6))
    ax1, ax2 = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2, sharex=None)
    handles = plot_games(ax1, ax2, rows, order, ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"), "#7f7f7f", "#333333")
    xs = sorted({order[r.session_uid] for r in rows})
    dates = {order[r.session_uid]: r.session_started_utc[:10] for r in rows}
    for ax in (ax1, ax2):
        ax.set_xticks(xs)
        ax.set_xticklabels([f"#{x}\n{dates[x]}" for x in xs], fontsize=8)
        ax.grid(True, axis="y", color="#dddddd")
    ax1.set_ylabel("repetitions")
    ax1.legend(handles=handles, fontsize=8)
    ax1.set_title("Games")
    ax2.set_ylabel("minutes played")
    ax2.set_xlabel("session")
    fig.tight_layout()
    return _png(fig)


def _csv_row(r: RomRow) -> list:
    return [r.session_started_utc, r.test, r.side, r.angle, r.mode, r.position, r.standard,
            "" if r.reference_deg is None else f"{r.reference_deg:g}", f"{r.value_deg:.1f}", round_to_5(r.value_deg),
            f"{r.start_deg:.1f}", f"{r.range_deg:.1f}", r.compensation, r.estimated_markers,
            "" if r.duration_s is None else f"{r.duration_s:.1f}", r.recorded_utc, r.uid]


def write_report(db: Database, patient_id: str, out_html: str | Path, *, standard: str = "jarm") -> tuple[Path, Path]:
    """Write the HTML report and the CSV beside it; returns both paths.

    Raises:
        DatabaseError: unknown patient.
        RehabError: the output folder cannot be written.
    """
    check_standard(standard)
    db.require_patient(patient_id)
    out_html = Path(out_html)
    csv_path = out_html.with_suffix(".csv")
    roms = db.rom_results(patient_id)
    games = db.exercise_results(patient_id)
    order = session_order(list(roms) + list(games))
    esc = html.escape

    parts = [f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>ROM progress: {esc(patient_id)}</title>
<style>
body {{ font-family: sans-serif; margin: 24px; color: #222; max-width: 1100px; }}
h1 {{ font-size: 22px; margin-bottom: 4px; }} h2 {{ font-size: 18px; margin-top: 28px; }}
.meta {{ color: #555; font-size: 13px; }}
table {{ border-collapse: collapse; font-size: 12px; margin-top: 8px; }}
th, td {{ border: 1px solid #ccc; padding: 3px 6px; text-align: left; }}
td.num {{ text-align: right; }} li.real {{ font-weight: bold; }} tr.flag td {{ background: #fff4e5; }} tr.demo td {{ color: #777777; }}
img {{ display: block; margin: 8px 0 16px 0; max-width: 100%; }}
</style></head><body>
<h1>Range of motion progress: patient {esc(patient_id)}</h1>
<p class="meta">Report written {esc(utc_now())}. Active ROM (the patient's own movement), maxima in degrees,
shown rounded to 5 degrees as recorded clinically (raw values in the table and in {esc(csv_path.name)}).
Normal values: {esc(STANDARDS[standard])}; a normal value measured in another test position is not shown
as a band. Orange rings: the attempt showed compensation. Crosses: the maximum rested on estimated (hidden)
markers.</p>
"""]
    if not roms:
        parts.append("<p>No ROM results yet.</p>")
    by_test: dict[str, list[RomRow]] = defaultdict(list)
    for r in roms:
        by_test[r.test].append(r)
    for test in sorted(by_test, key=lambda t: min(order[r.session_uid] for r in by_test[t])):
        info = _test_info(test, standard)
        rows = by_test[test]
        png = rom_plot_png(info.title, rows, order, info.normal_deg, standard)
        latest = {side: max((r for r in rows if r.side == side), key=lambda r: order[r.session_uid], default=None)
                  for side in ("right", "left")}
        summary = "; ".join(f"{side} latest {round_to_5(r.value_deg)} deg" for side, r in latest.items() if r is not None)
        changes = latest_changes(rows, order, info.sdc_deg)
        change_html = "".join(f"<li class=\"{'real' if ch.real else 'noise'}\">{esc(change_line(ch, order))}</li>"
                              for ch in changes)
        parts.append(f"<h2>{esc(info.title)}</h2><p class=\"meta\">{esc(info.position_words)} {esc(summary)}.</p>"
                     f"<p class=\"meta\">{esc(sdc_words(info.sdc_deg))}</p>"
                     + (f"<ul class=\"changes\">{change_html}</ul>" if changes else "")
                     + f"<img alt=\"{esc(info.title)} over the sessions\" src=\"data:image/png;base64,{png}\">")
    if roms:
        parts.append("<h2>All ROM results</h2><table><tr><th>session</th><th>date (UTC)</th><th>test</th><th>side</th>"
                     "<th>recorded</th><th>raw</th><th>start</th><th>range</th><th>normal</th><th>mode</th>"
                     "<th>position</th><th>compensation</th><th>estimated markers</th>"
                     "<th>change from the previous session</th></tr>")
        row_change = {ch.latest.uid: ch for t in by_test
                      for ch in session_changes(by_test[t], order, _test_info(t, standard).sdc_deg)}
        for r in roms:
            ch = row_change.get(r.uid)
            normal = f"{r.standard.upper()} {r.reference_deg:g}" if r.reference_deg is not None else f"{r.standard.upper()}: none for this position"
            parts.append(
                f"<tr class=\"{'flag' if r.compensation else ''}\"><td class=\"num\">#{order[r.session_uid]}</td>"
                f"<td>{esc(r.session_started_utc.replace('T', ' ').rstrip('Z'))}</td><td>{esc(r.test.replace('_', ' '))}</td>"
                f"<td>{esc(r.side)}</td><td class=\"num\"><b>{round_to_5(r.value_deg)}</b></td>"
                f"<td class=\"num\">{r.value_deg:.1f}</td><td class=\"num\">{r.start_deg:.1f}</td>"
                f"<td class=\"num\">{r.range_deg:.1f}</td><td>{esc(normal)}</td><td>{esc(r.mode)}</td>"
                f"<td>{esc(r.position.replace('_', ' '))}</td><td>{esc(r.compensation) or '-'}</td>"
                f"<td>{esc(r.estimated_markers) or '-'}</td><td>{esc(ch.words) if ch else '-'}</td></tr>")
        parts.append("</table>")
    parts.append("<h2>Games</h2>")
    if games:
        parts.append(f"<img alt=\"repetitions and durations over the sessions\" "
                     f"src=\"data:image/png;base64,{exercise_plot_png(games, order)}\">")
        parts.append("<table><tr><th>session</th><th>date (UTC)</th><th>game</th><th>played by</th>"
                     "<th>repetitions</th><th>minutes</th><th>targets collected</th></tr>")
        for g in games:
            part = demo_part(g)
            reps = f"{g.repetitions}" + (f" ({part.repetitions} by the demo)" if part.repetitions else "")
            row_class = ' class="demo"' if part.seconds > 0 else ""
            parts.append(f"<tr{row_class}><td class=\"num\">#{order[g.session_uid]}</td>"
                         f"<td>{esc(g.session_started_utc.replace('T', ' ').rstrip('Z'))}</td><td>{esc(g.game)}</td>"
                         f"<td>{esc(part.words)}</td>"
                         f"<td class=\"num\">{esc(reps)}</td><td class=\"num\">{g.duration_s / 60:.1f}</td>"
                         f"<td class=\"num\">{esc(score_words(g))}</td></tr>")
        parts.append("</table>")
    else:
        parts.append("<p>No game results yet.</p>")
    parts.append("</body></html>\n")

    try:   # patient data: the user's only (0600), each file whole or not at all
        make_private_dir(out_html.parent)
        with open_private(out_html, "w", encoding="utf-8") as fh:
            fh.write("".join(parts))
        with open_private(csv_path, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(_CSV_COLUMNS)
            for r in roms:
                w.writerow(_csv_row(r))
    except OSError as exc:
        raise RehabError(f"{out_html}: cannot write the report ({exc.strerror}): check the folder") from None
    return out_html, csv_path
