"""The live mirror: the avatar follows the patient, with the active arm's joint angles in large
text and the tracker's state in plain words.

What the scene shows, left to right: the avatar seen from the front as in a mirror (the
patient's right hand on the screen's right), the measured markers as small dots on it (teal
measured, amber estimated), and the hand target of the interactive patient; on the right a panel
with the active arm's angles (value and a bar over the normal range), the trunk's lean and how
many markers are measured, estimated or lost. A banner on top says what to do or what is wrong:
the tracker's one-line message while it waits for the reference pose, "The tracker stopped:
restarting..." while its process is replaced (the last pose stays on the screen, the window
keeps drawing).

The interactive simulated patient (no scripted motion playing) is driven from here
(:class:`PatientControl`): the mouse moves the active hand on a plane in front of its shoulder
(the pointer ray meets the plane; the wheel moves the plane forward and back), Tab switches the
arm, Q/E turn the forearm, the arrows lean the trunk while held. M cycles the scripted motions
and back to the mouse, R re-identifies the markers, C opens the camera check, Esc goes back.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from game.app import BaseScene, Frame
from game.gfx import theme
from game.gfx.view3d import Viewport, intersect_plane, look_at, mirrored, perspective, pointer_ray, project_px
from game.input import Action, InputEvent, Pointer, PointerKind
from game.live_link import LinkState, LiveLink
from game.scenes.live_feed import WAITING_LINE, LiveFeed
from tracking.angles import joint_angles, withheld_angles
from tracking.live import PatientInput

log = logging.getLogger(__name__)

#: The mirror camera: in front of the seated patient (who faces -Z), at chest height.
EYE_M = (0.0, 1.0, -3.0)
LOOK_AT_M = (0.0, 0.93, 0.0)
FOVY_DEG = 34.0
NEAR_M, FAR_M = 0.1, 20.0
#: Share of the window's width the 3D view takes (the panel takes the rest).
VIEW_SHARE = 0.62
#: Said over the angles while they are hidden (no live sample).
PAUSED_LINE = "Angles paused: no live measurement"

#: Why the rest pose reads below zero (docs/SIMULATOR.md, "At rest"): the spec's trunk axis runs from the
#: lower to the upper sternum marker, and the chest's front slopes back towards the top.
REST_NOTE = ("At rest (upright, arms hanging) shoulder flexion and trunk forward read below 0{example}: the trunk's "
             "axis follows the sloping breastbone. ROM tests count from the start position.")

MARKER_LOST, MARKER_MEASURED, MARKER_ESTIMATED = 0, 1, 2
TRACKING = 1

#: Angle rows of the panel: (suffix after ``<side>_`` or full name, label, bar range in degrees).
ARM_ROWS = (
    ("shoulder_flexion", "Shoulder flexion", (-50.0, 180.0)),
    ("shoulder_abduction", "Shoulder abduction", (-30.0, 180.0)),
    ("elbow_flexion", "Elbow flexion", (0.0, 150.0)),
    ("forearm_supination", "Forearm rotation", (-90.0, 90.0)),
)
TRUNK_ROWS = (
    ("trunk_forward_lean", "Trunk forward", (-30.0, 45.0)),
    ("trunk_lateral_lean", "Trunk sideways", (-30.0, 30.0)),
)


@dataclass(frozen=True, slots=True)
class LiveLayout:
    """Where things go: the 3D view on the left, the panel on the right (window pixels)."""

    view: Viewport
    panel: tuple[float, float, float, float]
    scale: float


def live_layout(size_px: tuple[int, int]) -> LiveLayout:
    w, h = size_px
    scale = min(w / 1280.0, h / 720.0)
    view_w = round(w * VIEW_SHARE)
    margin = theme.MARGIN * scale
    panel = (view_w, margin, w - view_w - margin, h - 2 * margin)
    return LiveLayout(Viewport(0, 0, view_w, h), panel, scale)


def mirror_camera(viewport: Viewport) -> tuple[np.ndarray, np.ndarray]:
    """(view, projection) of the mirror view for ``viewport`` (the projection is mirrored)."""
    view = look_at(EYE_M, LOOK_AT_M)
    proj = mirrored(perspective(FOVY_DEG, viewport.aspect, NEAR_M, FAR_M))
    return view, proj


# ============================================================================ patient control
@dataclass(frozen=True, slots=True)
class ControlLimits:
    """How the keys move the interactive patient.

    Attributes:
        forearm_speed_deg_s: forearm turning speed while Q or E is held.
        forearm_range_deg: (pronation, supination) limits.
        lean_speed_deg_s: trunk lean speed while an arrow is held, and back to upright after.
        forward_range_deg: (back, forward) lean limits.
        lateral_range_deg: (left, right) lean limits.
        depth_range_m: how far in front of the shoulder the hand's plane may be.
        depth_step_m: plane movement per wheel click.
    """

    forearm_speed_deg_s: float = 90.0
    forearm_range_deg: tuple[float, float] = (-85.0, 85.0)
    lean_speed_deg_s: float = 30.0
    forward_range_deg: tuple[float, float] = (-15.0, 35.0)
    lateral_range_deg: tuple[float, float] = (-25.0, 25.0)
    depth_range_m: tuple[float, float] = (0.0, 0.55)
    depth_step_m: float = 0.05


def _approach(value: float, target: float, step: float) -> float:
    return min(value + step, target) if value < target else max(value - step, target)


class PatientControl:
    """Keys and pointer -> the interactive patient's input (pure state, no I/O).

    Args:
        limits: speeds and ranges.
        depth_m: starting distance of the hand's plane in front of the shoulder.
    """

    def __init__(self, limits: ControlLimits = ControlLimits(), depth_m: float = 0.25) -> None:
        self.limits = limits
        self.side = "right"
        self.hand_target_m: tuple[float, float, float] | None = None
        self.forearm_deg = 0.0
        self.forward_lean_deg = 0.0
        self.lateral_lean_deg = 0.0
        self.depth_m = depth_m
        self.held: set[Action] = set()

    def switch_arm(self) -> None:
        self.side = "left" if self.side == "right" else "right"
        self.hand_target_m = None  # the newly active arm stays where it is until the pointer moves
        self.forearm_deg = 0.0

    def wheel(self, clicks: float) -> None:
        lo, hi = self.limits.depth_range_m
        self.depth_m = min(hi, max(lo, self.depth_m + clicks * self.limits.depth_step_m))

    def aim(self, origin_m: np.ndarray, direction: np.ndarray, shoulder_m: np.ndarray) -> bool:
        """Point the hand where the pointer ray meets the plane ``depth_m`` in front of the shoulder.

        Returns:
            Whether the ray meets the plane (a target was set).
        """
        plane_point = np.asarray(shoulder_m, dtype=np.float64) + np.array([0.0, 0.0, -self.depth_m])
        hit = intersect_plane(origin_m, direction, plane_point, (0.0, 0.0, 1.0))
        if hit is None:
            return False
        self.hand_target_m = (float(hit[0]), float(hit[1]), float(hit[2]))
        return True

    def update(self, dt_s: float) -> None:
        """Advance the held keys' effects by ``dt_s``; the trunk returns upright when no arrow is held."""
        lim, held = self.limits, self.held
        turn = (Action.ROTATE_OUT in held) - (Action.ROTATE_IN in held)
        lo, hi = lim.forearm_range_deg
        self.forearm_deg = min(hi, max(lo, self.forearm_deg + turn * lim.forearm_speed_deg_s * dt_s))
        step = lim.lean_speed_deg_s * dt_s
        forward = (Action.UP in held) - (Action.DOWN in held)
        target = {1: lim.forward_range_deg[1], -1: lim.forward_range_deg[0], 0: 0.0}[forward]
        self.forward_lean_deg = _approach(self.forward_lean_deg, target, step)
        # Mirror view: the left arrow leans the avatar to the screen's left, the patient's left (-).
        lateral = (Action.RIGHT in held) - (Action.LEFT in held)
        target = {1: lim.lateral_range_deg[1], -1: lim.lateral_range_deg[0], 0: 0.0}[lateral]
        self.lateral_lean_deg = _approach(self.lateral_lean_deg, target, step)

    def patient_input(self):
        """The :class:`tracking.live.PatientInput` for the current state."""
        return PatientInput(side=self.side, hand_target_m=self.hand_target_m, forearm_rotation_deg=self.forearm_deg,
                            trunk_forward_lean_deg=self.forward_lean_deg,
                            trunk_lateral_lean_deg=self.lateral_lean_deg)


# ============================================================================ the scene
def _humanize(name: str | None) -> str:
    if name is None:
        return "Mouse control"
    text = name.replace("_", " ").strip()
    return text[:1].upper() + text[1:]


def truth_error_mm(positions_m: np.ndarray, truth_m: np.ndarray, status: np.ndarray) -> float:
    """RMS distance (mm) of the measured markers from the simulator's truth (NaN for real cameras)."""
    measured = (np.asarray(status) == MARKER_MEASURED) & np.isfinite(truth_m).all(axis=1)
    measured &= np.isfinite(positions_m).all(axis=1)
    if not measured.any():
        return math.nan
    d = np.linalg.norm(positions_m[measured] - truth_m[measured], axis=1)
    return float(np.sqrt(np.mean(d**2)) * 1000.0)


def format_angle(value_deg: float) -> str:
    """Whole degrees for the live display ("-" when undefined); ROM results round to 5 elsewhere."""
    if not math.isfinite(value_deg):
        return "-"
    return f"{round(value_deg):d}\N{DEGREE SIGN}"


class LiveScene(BaseScene):
    """The avatar mirror.

    Args:
        link: the live tracker link (started by the application).
        motions: scripted motion names M cycles through (None in the list: mouse control).
        motion: what plays when the scene opens (None: mouse control).
        open_monitor: makes the camera-check scene for C (None: C does nothing).
        make_avatar: ``make_avatar(ctx, marker_names, roles=...)`` builds the avatar
            (:class:`game.avatar.live.LiveAvatar`); None: markers only.
        show_markers: draw the measured markers over the avatar.
    """

    #: The avatar's gradient resets the view's depth (:meth:`game.avatar.live.LiveAvatar.render`):
    #: the frame's clear spares it.
    clear_depth = False

    def __init__(self, link: LiveLink, *, motions: Sequence[str | None] = (None,), motion: str | None = None,
                 open_monitor: Callable[[], BaseScene] | None = None,
                 make_avatar: Callable | None = None, show_markers: bool = True, source_kind: str = "sim") -> None:
        self.link = link
        self.source_kind = source_kind
        self.motions = list(motions) if motions else [None]
        if motion not in self.motions:
            self.motions.insert(0, motion)
        self.motion = motion
        self.open_monitor = open_monitor
        self.feed = LiveFeed(link, make_avatar)
        self.show_markers = show_markers
        self.control = PatientControl()
        self._shown_for = None  # the sample whose angles _shown holds
        self._shown: dict[str, float] = {}
        self._last_shoulder_m: dict[str, np.ndarray] = {}   # per side

    # ------------------------------------------------------------------ life cycle
    def enter(self, app) -> None:
        super().enter(app)
        self.layout = live_layout(app.screen.size_px)
        self.view_m, self.proj_m = mirror_camera(self.layout.view)
        if self.simulated:
            self.link.set_motion(self.motion)
        if self.interactive:
            self._send_input(force=True)

    def exit(self) -> None:
        self.feed.release()

    @property
    def avatar(self):
        """The avatar (:class:`game.avatar.live.LiveAvatar`), made by the feed once the marker set is known."""
        return self.feed.avatar

    # ------------------------------------------------------------------ input
    @property
    def simulated(self) -> bool:
        """The tracker measures the simulated patient (not a recording or cameras)."""
        return self.source_kind == "sim"

    @property
    def interactive(self) -> bool:
        """The mouse and keys move the simulated patient (no scripted motion playing)."""
        return self.simulated and self.motion is None

    def handle(self, event: InputEvent) -> None:
        if isinstance(event, Pointer):
            self._pointer_event(event)
            return
        action = event.action
        if not event.down:
            self.control.held.discard(action)
            return
        if action in (Action.UP, Action.DOWN, Action.LEFT, Action.RIGHT, Action.ROTATE_IN, Action.ROTATE_OUT):
            self.control.held.add(action)
        elif action is Action.SWITCH_ARM:
            self.control.switch_arm()
        elif action is Action.NEXT_MOTION and self.simulated:
            k = self.motions.index(self.motion)
            self.motion = self.motions[(k + 1) % len(self.motions)]
            self.link.set_motion(self.motion)
        elif action is Action.REIDENTIFY:
            self.link.reidentify()
        elif action is Action.MONITOR and self.open_monitor is not None:
            self.app.push(self.open_monitor())
        elif action is Action.BACK:
            self.app.pop()

    def _shoulder_m(self) -> np.ndarray:
        """The active shoulder marker's last position (a typical seated one before any sample)."""
        side = self.control.side
        sample, markerset = self.link.latest, self.link.markerset
        name = None if markerset is None else markerset.roles.get(f"{side}_shoulder")
        if sample is not None and name in markerset.names:
            p = sample.positions_m[markerset.names.index(name)]
            if np.isfinite(p).all():
                self._last_shoulder_m[side] = np.array(p, dtype=np.float64)
        default = np.array([0.19 if side == "right" else -0.19, 1.05, 0.0])
        return self._last_shoulder_m.get(side, default)

    def _pointer_event(self, event: Pointer) -> None:
        if event.kind is PointerKind.WHEEL:
            self.control.wheel(event.wheel)
        w, h = self.app.screen.size_px
        x_px, y_px = event.x * w, event.y * h
        v = self.layout.view
        if not (v.x <= x_px < v.x + v.w and v.y <= y_px < v.y + v.h):
            return
        if self.interactive:
            origin, direction = pointer_ray(x_px, y_px, self.proj_m @ self.view_m, v)
            self.control.aim(origin, direction, self._shoulder_m())

    def _send_input(self, force: bool = False) -> None:
        self.feed.send(self.control.patient_input(), force=force)

    # ------------------------------------------------------------------ update
    def update(self, dt_s: float) -> None:
        self.control.update(dt_s)
        # at most 60 messages a second to the tracker process (the feed's period)
        if self.feed.input_due(dt_s) is not None and self.interactive:
            self._send_input()

    # ------------------------------------------------------------------ drawing
    def prepare(self, frame: Frame) -> None:
        """This frame's samples into the avatar and its solids made (while the last frame rasterizes)."""
        self.feed.take(self.app)
        if self.avatar is not None:
            v = self.layout.view
            self.avatar.prepare((v.w, v.h), self.app.clock())

    def render_3d(self, frame: Frame) -> None:
        if self.avatar is None:
            return
        v = self.layout.view
        with frame.screen.view_3d(v, frame.render_scale):
            pose = self.avatar.render((v.w, v.h), self.app.clock())
        if pose is not None:
            # The avatar's still mirror camera: markers, the hand target and the pointer use it too.
            self.view_m, self.proj_m = self.avatar.camera(pose, v.aspect)

    def render_2d(self, frame: Frame) -> None:
        c, s = frame.canvas, self.layout.scale
        sample = self.link.latest
        if self.show_markers and sample is not None:
            self._draw_markers(frame, sample)
        if self.interactive and self.control.hand_target_m is not None:
            xy = project_px(np.array([self.control.hand_target_m]), self.proj_m @ self.view_m, self.layout.view)[0]
            if np.isfinite(xy).all():
                c.circle(tuple(xy), 13 * s, (0, 0, 0, 0), border=3 * s, border_colour=(*theme.TEXT, 150))
        self._draw_panel(frame, sample)
        self._draw_banner(frame, sample)
        self._draw_help(frame)

    def _draw_markers(self, frame: Frame, sample) -> None:
        c, s = frame.canvas, self.layout.scale
        xy = project_px(sample.positions_m, self.proj_m @ self.view_m, self.layout.view)
        for (x, y), st in zip(xy, sample.status):
            if not (math.isfinite(x) and math.isfinite(y)) or st == MARKER_LOST:
                continue
            colour = theme.STATUS_COLOURS.get(int(st), theme.TEXT)
            if st == MARKER_ESTIMATED:
                c.circle((x, y), 7 * s, (0, 0, 0, 0), border=3 * s, border_colour=colour)
            else:
                c.circle((x, y), 5.5 * s, colour, border=1.5 * s, border_colour=(20, 24, 30))

    def _angle(self, sample, name: str) -> float:
        """The sample's angle as a person reads it: where the tracker gives a value, the same
        angle withheld near its plane's normal and continued past 180 (``near_singular=
        "withhold"``): the spec's wrapped value jumped by up to 360 degrees there."""
        if sample is None or name not in self.link.angle_names:
            return math.nan
        if self._shown_for is not sample:
            self._shown_for = sample
            names = self.link.angle_names
            markerset = self.link.markerset
            live = joint_angles(sample.positions_m, markerset.names, roles=markerset.roles, near_singular="withhold")
            self._shown = {n: float(live[n]) if n in live and math.isfinite(sample.angles_deg[i])
                           else float(sample.angles_deg[i]) for i, n in enumerate(names)}
        return self._shown[name]

    def _rows(self, side: bool) -> list[tuple[str, str, tuple[float, float]]]:
        """The panel's angle rows (column, label, bar range): the active arm's and the trunk's
        under mouse control, else both arms'; an angle the marker set cannot give (its roles have
        no marker: :func:`tracking.angles.withheld_angles`) has no row."""
        sides = (self.control.side,) if side else ("right", "left")
        rows = [(f"{sd}_{suffix}", label if side else f"{sd.capitalize()} {label[0].lower()}{label[1:]}", rng)
                for sd in sides for suffix, label, rng in ARM_ROWS]
        if side:
            rows += TRUNK_ROWS
        markerset = self.link.markerset
        withheld = withheld_angles(markerset.roles) if markerset is not None else {}
        return [row for row in rows if row[0] not in withheld]

    def _draw_panel(self, frame: Frame, sample) -> None:
        c, s = frame.canvas, self.layout.scale
        # The panel is the window's plain background (no large shape to fill: llvmpipe pays per pixel).
        px, py, pw, ph = self.layout.panel
        x, y, right = px + 26 * s, py + 6 * s, px + pw - 10 * s
        side = self.control.side if self.interactive else None
        if side:
            title, mode = f"{self.control.side.capitalize()} arm", "Mouse moves the hand"
        elif self.simulated:
            title, mode = _humanize(self.motion), "Scripted motion, M for the next"
        else:
            title = "Live"
            mode = "From the cameras" if self.source_kind == "cameras" else "From a recording"
        title, title_size = c.fit(title, round(theme.LARGE * s), right - x)
        c.text(title, (x, y), title_size, theme.TEXT)
        y += 58 * s
        live = self.sample_is_live(sample)
        if sample is not None and not live:
            # the tracker is restarting or the samples stopped: the last angles are not the patient's now
            mode, size = c.fit(PAUSED_LINE, round(theme.SMALL * s), right - x)
            c.text(mode, (x, y), size, theme.ATTENTION)
        else:
            c.text(mode, (x, y), round(theme.SMALL * s), theme.TEXT_DIM)
        y += 40 * s
        rows = self._rows(side)
        # from the bottom up: the key help, the note on the rest pose, the marker counts, the rows
        note, note_size, note_h = self._rest_note(frame, right - x)
        note_y = self._help_top(frame) - 8 * s - len(note) * note_h
        counts_y = note_y - 64 * s
        row_h = (counts_y - 8 * s - y) / max(len(rows), 1)
        row_h = min(row_h, 74 * s)
        size = round((theme.BODY if row_h >= 60 * s else theme.SMALL) * s)
        value_size = round((theme.MEDIUM if row_h >= 60 * s else theme.BODY) * s)
        for name, label, (lo, hi) in rows:
            value = self._angle(sample, name) if live else math.nan
            c.text(label, (x, y + 4 * s), size, theme.TEXT_DIM)
            c.text(format_angle(value), (right, y), value_size, theme.TEXT, anchor="topright")
            bar_y = y + row_h - 22 * s
            c.rect((x, bar_y, right - x, 8 * s), (255, 255, 255, 22), radius=4 * s)
            if math.isfinite(value):
                zero = x + (right - x) * (0.0 - lo) / (hi - lo)
                at = x + (right - x) * (min(max(value, lo), hi) - lo) / (hi - lo)
                a, b = min(zero, at), max(zero, at)
                c.rect((a, bar_y, max(b - a, 3 * s), 8 * s), theme.ACCENT, radius=4 * s)
            y += row_h
        self._draw_marker_counts(frame, sample, (x, counts_y), right)
        for k, line in enumerate(note):
            c.text(line, (x, note_y + k * note_h), note_size, theme.TEXT_FAINT)

    def _rest_note(self, frame: Frame, width: float) -> tuple[list[str], int, float]:
        """Why sitting upright with the arms hanging reads below zero: lines, size, line height."""
        c, s = frame.canvas, self.layout.scale
        size = round(theme.SMALL * 0.8 * s)
        example = " (-11\N{DEGREE SIGN} on the simulated patient)" if self.simulated else ""
        return c.wrap(REST_NOTE.format(example=example), size, width), size, c.measure("Ag", size)[1] + 3 * s

    def _draw_marker_counts(self, frame: Frame, sample, pos, right: float) -> None:
        c, s = frame.canvas, self.layout.scale
        if sample is None:
            return
        status = np.asarray(sample.status)
        counts = ((int((status == MARKER_MEASURED).sum()), "measured", theme.ACCENT),
                  (int((status == MARKER_ESTIMATED).sum()), "estimated", theme.ATTENTION),
                  (int((status == MARKER_LOST).sum()), "lost", theme.FAILURE))
        x, y = pos
        size = round(theme.SMALL * s)
        for n, word, colour in counts:
            c.circle((x + 7 * s, y + 10 * s), 7 * s, colour)
            _, _, w, _ = c.text(f"{n} {word}", (x + 20 * s, y), size, theme.TEXT_DIM)
            x += w + 44 * s
        error_mm = truth_error_mm(sample.positions_m, sample.truth_m, status)
        if math.isfinite(error_mm):
            text, size = c.fit(f"Simulated patient: measured markers {error_mm:.1f} mm from the truth (RMS)",
                               round(theme.SMALL * 0.8 * s), right - pos[0])
            c.text(text, (pos[0], pos[1] + 34 * s), size, theme.TEXT_FAINT)

    def sample_is_live(self, sample) -> bool:
        """The sample shows the patient now: the tracker runs and the samples flow
        (:meth:`game.scenes.live_feed.LiveFeed.is_live`; while the tracker restarts, its last angles
        are hidden, not shown as live)."""
        return sample is not None and self.feed.is_live(self.app.clock())

    def banner(self, sample) -> tuple[str, tuple] | None:
        """The line on top of the view and its colour (None: all is well)."""
        problem = self.feed.problem(self.app.clock())
        if problem is not None:
            return problem[0], theme.FAILURE if problem[1] else theme.ATTENTION
        if sample is None:
            return WAITING_LINE, theme.ATTENTION
        if sample.state != TRACKING:
            return sample.message or "Finding the markers...", theme.ATTENTION
        warning = getattr(self.link, "warning", "")
        if warning:  # e.g. a camera stopped: tracking goes on with the others, the therapist must know
            return warning[:1].upper() + warning[1:], theme.ATTENTION
        return None

    def _draw_banner(self, frame: Frame, sample) -> None:
        got = self.banner(sample)
        if got is None:
            return
        text, colour = got
        c, s = frame.canvas, self.layout.scale
        v = self.layout.view
        if sample is None and self.link.state is not LinkState.FAILED:
            # Nothing to show yet: say it large in the middle of the empty view.
            c.text(text, (v.x + v.w / 2, v.y + v.h / 2 - 20 * s), round(theme.MEDIUM * s), theme.TEXT, anchor="center")
            c.text("The avatar appears as soon as the markers are found.", (v.x + v.w / 2, v.y + v.h / 2 + 28 * s),
                   round(theme.SMALL * s), theme.TEXT_DIM, anchor="center")
            return
        c.banner(text, (v.x + theme.MARGIN * s, theme.MARGIN * s), v.w - 2 * theme.MARGIN * s, round(theme.BODY * s),
                 theme.OVERLAY, colour, theme.TEXT, scale=s)

    def _help_lines(self, frame: Frame) -> tuple[list[str], int, float]:
        """The key help's lines, their size and line height."""
        c, s = frame.canvas, self.layout.scale
        if self.interactive:
            text = "Mouse: hand, wheel: nearer/farther   Tab: other arm   Q/E: turn forearm   Arrows: lean   "
        else:
            text = ""
        text += ("M: motions   " if self.simulated else "") + "R: find markers   C: cameras   Esc: back"
        size = round(theme.SMALL * 0.8 * s)
        return c.wrap(text, size, self.layout.panel[2] - 36 * s), size, c.measure("Ag", size)[1] + 5 * s

    def _help_top(self, frame: Frame) -> float:
        lines, _, line_h = self._help_lines(frame)
        px, py, pw, ph = self.layout.panel
        return py + ph - len(lines) * line_h

    def _draw_help(self, frame: Frame) -> None:
        c, s = frame.canvas, self.layout.scale
        px, py, pw, ph = self.layout.panel
        lines, size, line_h = self._help_lines(frame)
        y = py + ph - len(lines) * line_h
        for k, line in enumerate(lines):
            c.text(line, (px + 26 * s, y + k * line_h), size, theme.TEXT_FAINT)
