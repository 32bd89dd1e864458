"""An exercise game, live: the avatar, the targets in its 3D view, big counters, cues, pauses.

A thin scene over :class:`game.exergames.session.GameSession`: every frame the tracker's new
samples move the avatar and become one :class:`~game.exergames.session.Reading` (or the reason
there is none: the tracker starting, restarting, stalled, waiting for the reference pose, markers
lost), the session advances on the game clock, its cues sound (:class:`game.exergames.audio.Sounds`)
and flash. Targets are drawn as solids in the avatar's 3D view (a star to touch, gate posts, the
key's lock beside the hand) with a 2D ring that fills while the target is held; the panel shows
the stars collected, the time left, the level and what to do. When the session ends (time up or
Esc) its log is stored for the patient (``exercise_results``, shown in the progress review).

Play: with the simulated patient the mouse moves the hand (on a plane through the current
target), Q/E turn the forearm; with ``auto`` the simulated patient plays by itself
(:class:`game.exergames.autoplay.AutoPlayer`), through the tracker like any patient.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from game.app import BaseScene, Frame
from game.avatar.renderer import look_at, perspective
from game.avatar.shapes import PART_CHAIR, body_shapes
from game.exergames.audio import Sounds
from game.exergames.autoplay import AutoPlayer
from game.exergames.kinds import FOREARM_LIMIT_DEG, Aim, Framing
from game.exergames.session import Cue, GameSession, Phase, read_sample
from game.exergames.spec import GameSpec
from game.exergames.visit import GameVisit
from game.exergames.river import river_for
from game.exergames.targets import elbow_at_side_hand_m
from game.gfx import theme
from game.gfx.view3d import Viewport, project_px
from game.input import Action, InputEvent, Pointer, PointerKind
from game.scenes.live_feed import LiveFeed
from game.scenes.river_view import RiverView
from tracking.live import PatientInput

log = logging.getLogger(__name__)

VIEW_SHARE = 0.64
#: The rotation game: the avatar's view, then the river up to this share of the width, then the panel.
ROTATION_VIEW_SHARE, RIVER_END_SHARE = 0.36, 0.68
#: How long a cue's flash stays on the screen.
FLASH_S = 0.8
GOOD = (120, 220, 120)
#: The camera is re-aimed when the pelvis moved this far.
CAMERA_REAIM_M = 0.08


def level_shown(level: float) -> int:
    """The level as the patient sees it, 1..10, from the session's 0..1."""
    return 1 + round(min(max(level, 0.0), 1.0) * 9)


def level_from_shown(shown: int) -> float:
    """The session's level 0..1 of a shown level 1..10."""
    return (min(max(int(shown), 1), 10) - 1) / 9.0


def game_camera(pose, aspect: float, framing: Framing, side: str) -> tuple[np.ndarray, np.ndarray]:
    """(view, mirrored projection) framing the upper body and the game's targets.

    Closer than the live mirror (:func:`game.avatar.renderer.mirror_view`, the whole seated body),
    as the game kind's :class:`~game.exergames.kinds.Framing` says: e.g. reach from the hips to a
    hand raised above the head, turned 25 degrees towards the active side so forward reaches show
    their depth; the rotation games the trunk and the forearm in front of it, turned 15 degrees.
    """
    rp = pose.frame("pelvis")
    fwd = -rp[:, 2].copy()
    fwd[1] = 0.0
    fwd /= max(float(np.linalg.norm(fwd)), 1e-9)
    right = np.array([-fwd[2], 0.0, fwd[0]])
    sign = 1.0 if side == "right" else -1.0
    yaw = math.radians(framing.yaw_deg * sign)
    direction = math.cos(yaw) * fwd + math.sin(yaw) * right
    shoulders = (pose.joint("right_acromion") + pose.joint("left_acromion")) / 2.0
    pelvis = pose.joint("pelvis")
    k = framing.trunk_share
    target = ((1.0 - k) * shoulders + k * pelvis + np.array([0.0, framing.up_m, 0.0]) + framing.forward_m * fwd
              + framing.aside_m * sign * right)
    half = max(framing.half_m, framing.half_m * 0.9 / aspect)
    fov = 30.0
    distance = half / math.tan(math.radians(fov) / 2.0)
    pitch = math.radians(framing.pitch_deg)
    eye = target + distance * (math.cos(pitch) * direction + math.sin(pitch) * np.array([0.0, 1.0, 0.0]))
    proj = perspective(fov, aspect, near_m=0.1, far_m=distance + 6.0)
    return look_at(eye, target), proj @ np.diag([-1.0, 1.0, 1.0, 1.0])


def _rgb01(c) -> np.ndarray:
    return np.asarray(c[:3], np.float32) / 255.0


def target_shapes(shapes, spec: GameSpec, session: GameSession):
    """The avatar's solids plus the current target's (BodyShapes with rows appended)."""
    t, frame = session.target, session.frame
    if t is None or frame is None:
        return shapes
    solid = session.kind.solid(t, frame)   # e.g. the rotation game's gates are on the river instead
    if solid is None:
        return shapes
    centre, axes = solid
    colour = _rgb01(spec.colour)
    glow = np.clip(colour + (1.0 - colour) * 0.6 * t.hold_fraction, 0, 1)   # whitens as it fills
    return replace(
        shapes,
        ellipsoid_centre_m=np.concatenate([shapes.ellipsoid_centre_m, np.asarray(centre).reshape(-1, 3)]),
        ellipsoid_axes_m=np.concatenate([shapes.ellipsoid_axes_m, np.asarray(axes).reshape(-1, 3, 3)]),
        ellipsoid_rgb=np.concatenate([shapes.ellipsoid_rgb, np.asarray(glow, np.float32).reshape(-1, 3)]),
        ellipsoid_part=np.concatenate([shapes.ellipsoid_part, np.full(1, PART_CHAIR, np.int32)]),
        ellipsoid_fine=np.concatenate([shapes.ellipsoid_fine, np.ones(1, bool)]),
    )


class GameScene(BaseScene):
    """One exercise game for one patient.

    Args:
        link: the live tracker link.
        spec: the game; side: the active arm.
        db_path, patient_id: where the ROM is read from and the session stored.
        make_avatar: ``make_avatar(ctx, marker_names, roles=...)`` -> :class:`game.avatar.live.LiveAvatar`.
        auto: the simulated patient plays by itself.
        mute: no sound.
        seed: the targets' random generator.
        level, level_low, level_high: the therapist's start level and limits (None: the game's).
        therapist: the therapist's limits of the adaptation (None: the game's own ``limits``).
        source: stored with the session (e.g. ``sim``).
    """

    #: The depth is reset by the 3D view's background (:meth:`render_3d`), not by the frame's clear.
    clear_depth = False

    def __init__(self, link, spec: GameSpec, side: str, db_path: Path, patient_id: str, *,
                 make_avatar: Callable | None = None, auto: bool = False, mute: bool = False, seed: int = 0,
                 level: float | None = None, level_low: float | None = None, level_high: float | None = None,
                 therapist=None, source: str = "sim") -> None:
        self.link = link
        self.spec = spec
        self.kind = spec.game_kind
        self.side = side
        self.visit = GameVisit(db_path, patient_id, source)
        self.patient_id = patient_id
        self.feed = LiveFeed(link, make_avatar)
        self.auto = auto
        self.mute = mute
        self.limits = self.visit.rom_limits(spec, side)
        self.session = GameSession(spec, self.limits, side, seed=seed, level=level, level_low=level_low,
                                   level_high=level_high, therapist=therapist)
        self.player = AutoPlayer(self.session)
        self.sounds: Sounds | None = None
        self._flash: tuple[str, tuple, float] | None = None
        self._frame_consumed = -1
        self._read = (None, (None, ""))   # (the sample read last, its (reading, reason))
        self._forearm_deg = 0.0
        self._turn = 0
        self._hand_target = None
        self._pointer_px: tuple[float, float] | None = None
        self.view_m = self.proj_m = None
        self._camera_pelvis = None
        self._prepared = None  # the avatar and targets of this frame (prepare -> render_3d)
        self.river = river_for(self.limits, spec.stretch_fraction, side) if self.kind.river else None
        self.river_view: RiverView | None = None
        self._river_clock_s = math.nan

    # ------------------------------------------------------------------ life cycle
    def enter(self, app) -> None:
        super().enter(app)
        w, h = app.screen.size_px
        self.scale = min(w / 1280.0, h / 720.0)
        share = ROTATION_VIEW_SHARE if self.river is not None else VIEW_SHARE
        self.view = Viewport(0, 0, round(w * share), h)
        self.panel_x = self.view.w
        if self.river is not None:
            gap = 12 * self.scale
            right = round(w * RIVER_END_SHARE)
            self.river_view = RiverView(app.screen.ctx, (self.view.w + gap, gap, right - self.view.w - 2 * gap, h - 2 * gap),
                                        self.scale, self.spec.colour)
            self.panel_x = right
        self.sounds = Sounds(self.mute)
        self.link.set_motion(None)   # the interactive patient: the mouse or the auto player moves the arm

    def exit(self) -> None:
        self.save()
        self.feed.release()
        if self.river_view is not None:
            self.river_view.release()
            self.river_view = None

    def save(self) -> str | None:
        """End the session and store its log (once; nothing for a session that never played)."""
        return self.visit.store(self.session)

    @property
    def stored_uid(self) -> str | None:
        return self.visit.stored_uid

    @property
    def store_error(self) -> str:
        return self.visit.error

    # ------------------------------------------------------------------ input
    def handle(self, event: InputEvent) -> None:
        if isinstance(event, Pointer):
            if event.kind in (PointerKind.MOVE, PointerKind.PRESS) and not self.auto:
                self._aim(event.x * self.app.screen.size_px[0], event.y * self.app.screen.size_px[1])
            return
        if event.action in (Action.ROTATE_IN, Action.ROTATE_OUT):
            sign = 1 if event.action is Action.ROTATE_OUT else -1
            self._turn = sign if event.down else 0
            return
        if not event.down:
            return
        if event.action is Action.BACK:
            self.app.pop()
        elif event.action is Action.REIDENTIFY:
            self.link.reidentify()
        elif event.action is Action.NEXT_MOTION:
            self.auto = not self.auto

    def _arm_frame(self):
        """The arm's geometry the mouse aims with: the session's baseline, or before it (getting
        ready) the last reading's, so that the mouse can bring the arm into the start position."""
        s = self.session
        if s.frame is not None:
            return s.frame
        return s.last.frame if s.last is not None else None

    def _aim(self, x_px: float, y_px: float) -> None:
        """The mouse moves the simulated hand: on the river the boat goes where the pointer is; in
        the avatar's view as the game kind says (:meth:`game.exergames.kinds.GameKind.aim`: reach on a
        vertical plane through the target, the rotation game's hand where the pointer is across the
        view, the key game's forearm turned by the pointer's position across the view, as Q/E do).
        """
        self._pointer_px = (x_px, y_px)
        v = self.view
        s = self.session
        frame = self._arm_frame()
        if frame is None:
            return
        if self.river_view is not None:
            rx, ry, rw, rh = self.river_view.rect
            if rx <= x_px < rx + rw and ry <= y_px < ry + rh:   # on the river: the boat goes where the mouse is
                rotation = self.river_view.rotation_at_px(self.river, x_px)
                self._hand_target = tuple(float(x) for x in elbow_at_side_hand_m(frame, rotation))
                return
        if self.proj_m is None or not (v.x <= x_px < v.x + v.w):
            return
        target = s.target.hand_m if s.target is not None else None
        hand, forearm = self.kind.aim(Aim(v, self.proj_m @ self.view_m, frame, self.side, self.river, target), x_px, y_px)
        if forearm is not None:
            self._forearm_deg = forearm
        if hand is not None:
            self._hand_target = hand

    def update(self, dt_s: float) -> None:
        self._forearm_deg = float(np.clip(self._forearm_deg + self._turn * 90.0 * dt_s, -FOREARM_LIMIT_DEG,
                                          FOREARM_LIMIT_DEG))
        if self._hand_target is None and self._pointer_px is not None and not self.auto:
            self._aim(*self._pointer_px)   # the pointer moved before the arm was seen: aim now
        elapsed = self.feed.input_due(dt_s)
        if elapsed is None:
            return
        if self.auto:
            value = self.player.patient_input(elapsed)
        else:
            value = PatientInput(side=self.side, hand_target_m=self._hand_target, forearm_rotation_deg=self._forearm_deg)
        self.feed.send(value)

    # ------------------------------------------------------------------ samples -> session
    @property
    def avatar(self):
        """The avatar (:class:`game.avatar.live.LiveAvatar`), made by the feed once the marker set is known."""
        return self.feed.avatar

    def no_reading_reason(self) -> str:
        """Why there is no usable sample now ("" when samples flow)."""
        problem = self.feed.problem(self.app.clock())
        return "" if problem is None else problem[0]

    def consume(self) -> None:
        """This frame's samples: the avatar, one reading, the session, the cues (once per frame)."""
        if self._frame_consumed == self.app.frames:
            return
        self._frame_consumed = self.app.frames
        now = self.app.clock()
        samples = self.feed.take(self.app)   # the avatar moves with them
        markerset = self.link.markerset
        reading, reason = None, self.no_reading_reason()
        if not reason and markerset is not None:
            latest = samples[-1] if samples else self.link.latest
            if latest is not self._read[0]:   # frames outnumber samples: a sample is read once
                self._read = (latest, read_sample(latest, markerset.names, self.link.angle_names, self.side))
            reading, reason = self._read[1]
        self.session.update(now, reading, reason, demo=self.auto)
        for cue in self.session.take_cues():
            self._cue(cue, now)
        if self.river_view is not None:
            dt = 0.0 if not math.isfinite(self._river_clock_s) else now - self._river_clock_s
            self._river_clock_s = now
            self.river_view.advance(dt, self.river, self.session.value_now(), self.session.target, self.session.paused)
        if self.session.phase is Phase.DONE and self.stored_uid is None and not self.store_error:
            self.save()

    def _cue(self, cue: Cue, now: float) -> None:
        if self.sounds is not None:
            self.sounds.play(cue)
        if cue in (Cue.COLLECTED, Cue.MISSED) and self.river_view is not None and self.session.log.targets:
            last = self.session.log.targets[-1]
            self.river_view.target_ended(last["value_deg"], last["size"], last["reached"], now)
        words = {Cue.COLLECTED: ("Great!", GOOD), Cue.MISSED: ("Next one!", theme.TEXT_DIM),
                 Cue.LEVEL_UP: ("Level up!", theme.ACCENT), Cue.LEVEL_DOWN: ("A little easier", theme.TEXT_DIM),
                 Cue.READY: ("Go!", GOOD), Cue.DONE: ("Well done!", GOOD)}.get(cue)
        if words is not None:
            self._flash = (*words, now)

    # ------------------------------------------------------------------ drawing
    def prepare(self, frame: Frame) -> None:
        """This frame's samples, and the avatar with the targets made ready to draw (while the
        previous frame is still being rasterized)."""
        self.consume()
        self._prepared = None
        if self.avatar is None:
            return
        now = self.app.clock()
        pose = self.avatar.interpolator.sample(now)
        if pose is None:
            return
        if self.proj_m is None or self._camera_pelvis is None or \
                np.linalg.norm(pose.joint("pelvis") - self._camera_pelvis) > CAMERA_REAIM_M:
            # a still camera: re-aimed only when the patient moves on the seat
            self.view_m, self.proj_m = game_camera(pose, self.view.aspect, self.kind.framing, self.side)
            self._camera_pelvis = pose.joint("pelvis").copy()
        shapes = target_shapes(body_shapes(pose), self.spec, self.session)
        self._prepared = self.avatar.renderer.prepare(pose, self.view_m, self.proj_m, shapes=shapes,
                                                      looks=self.avatar.fader.update(pose.state, now))

    def render_3d(self, frame: Frame) -> None:
        if self.avatar is None:
            return
        with frame.screen.view_3d(self.view, frame.render_scale):
            # the gradient at the far plane resets the view's depth (the frame's clear spares it:
            # nothing else of the frame is depth-tested)
            self.avatar.renderer.render_background(depth=not self.clear_depth)
            if self._prepared is not None:
                self.avatar.renderer.draw(self._prepared)

    def _project(self, p_m) -> tuple[float, float] | None:
        if self.proj_m is None:
            return None
        xy = project_px(np.asarray(p_m, dtype=np.float64).reshape(1, 3), self.proj_m @ self.view_m, self.view)[0]
        return (float(xy[0]), float(xy[1])) if np.isfinite(xy).all() else None

    def render_2d(self, frame: Frame) -> None:
        self.consume()
        c = frame.canvas
        if self.river_view is not None:
            self.river_view.draw(c, self.river, self.session, self.app.clock())
        else:
            self._draw_target_ring(c)
        self._draw_panel(c, frame.size_px)
        self._draw_banner(c)
        self._draw_flash(c)

    def _draw_target_ring(self, c) -> None:
        sess, s = self.session, self.scale
        t = sess.target
        if t is None or sess.frame is None:
            return
        centre = self._project(t.hand_m)
        if centre is None:
            return
        edge = self._project(t.hand_m + self.kind.ring_m(t) * sess.frame.trunk[:, 1])
        r = max(22 * s, abs(edge[1] - centre[1]) if edge is not None else 30 * s) + 8 * s
        colour = tuple(self.spec.colour)
        dim = sess.paused
        c.circle(centre, r, (0, 0, 0, 0), border=3 * s, border_colour=(*colour, 110 if dim else 230))
        n = 24
        filled = round(n * t.hold_fraction)
        for k in range(n):
            a = -math.pi / 2 + 2 * math.pi * k / n
            p = (centre[0] + (r + 9 * s) * math.cos(a), centre[1] + (r + 9 * s) * math.sin(a))
            c.circle(p, 4.5 * s, (*GOOD, 255) if k < filled else (255, 255, 255, 50))
        # time left of the target: a thin bar under the ring
        left = max(0.0, 1.0 - t.age_s / t.time_limit_s)
        c.rect((centre[0] - r, centre[1] + r + 22 * s, 2 * r, 7 * s), (255, 255, 255, 40), radius=3 * s)
        c.rect((centre[0] - r, centre[1] + r + 22 * s, 2 * r * left, 7 * s), (*colour, 220), radius=3 * s)

    def _draw_panel(self, c, size_px) -> None:
        sess, s = self.session, self.scale
        w, h = size_px
        x = self.panel_x + 30 * s
        right = w - theme.MARGIN * s
        y = theme.MARGIN * s
        title, title_size = c.fit(self.spec.title, round(theme.MEDIUM * s), right - x)
        c.text(title, (x, y), title_size, theme.TEXT)
        y += 48 * s
        c.text(f"Patient {self.patient_id}, {self.side} arm" + ("   (demo: plays by itself)" if self.auto else ""),
               (x, y), round(theme.SMALL * 0.85 * s), theme.TEXT_DIM)
        y += 42 * s
        # the big counter
        c.rect((x, y, right - x, 150 * s), theme.PANEL, radius=20 * s, border=2 * s, border_colour=theme.PANEL_EDGE)
        c.circle((x + 70 * s, y + 75 * s), 44 * s, (*self.spec.colour, 255))
        c.text(f"{sess.reached}", (x + 140 * s, y + 75 * s), round(110 * s), theme.TEXT, anchor="midleft")
        c.text("collected", (right - 20 * s, y + 50 * s), round(theme.SMALL * s), theme.TEXT_DIM, anchor="midright")
        c.text(f"{sess.log.missed} missed", (right - 20 * s, y + 100 * s), round(theme.SMALL * s), theme.TEXT_FAINT,
               anchor="midright")
        y += 172 * s
        # time left and level
        frac = sess.remaining_s / sess.spec.duration_s
        c.text(f"Time {int(sess.remaining_s) // 60}:{int(sess.remaining_s) % 60:02d}", (x, y), round(theme.BODY * s),
               theme.TEXT)
        c.text(f"Level {level_shown(sess.level)}", (right, y), round(theme.BODY * s), theme.ACCENT, anchor="topright")
        y += 44 * s
        c.rect((x, y, right - x, 12 * s), (255, 255, 255, 30), radius=6 * s)
        c.rect((x, y, (right - x) * frac, 12 * s), theme.ACCENT, radius=6 * s)
        y += 36 * s
        y = self.kind.draw_readout(self, c, x, y, right)
        size = round(theme.SMALL * s)
        for line in c.wrap(self.spec.instructions, size, right - x)[:4]:
            c.text(line, (x, y), size, theme.TEXT_DIM)
            y += 30 * s
        keys_size = round(theme.SMALL * 0.75 * s)   # on two lines where one does not fit (not smaller)
        lines = c.wrap("Mouse: move the arm   Q/E: turn forearm   M: demo on/off   Esc: end and save", keys_size,
                       right - x)[:2]
        for k, line in enumerate(reversed(lines)):
            c.text(line.strip(), (x, h - 20 * s - k * (keys_size + 6 * s)), keys_size, theme.TEXT_FAINT,
                   anchor="bottomleft")

    def draw_gauge(self, c, x: float, y: float, right: float) -> float:
        """The rotation range as a half dial: the measured range, the target, the arm now (a game
        kind's readout, e.g. the key's); returns the next y."""
        sess, s = self.session, self.scale
        r = min((right - x) / 2 - 10 * s, 120 * s)
        cx, cy = (x + right) / 2, y + r + 10 * s
        lim = self.limits
        lo, hi = -lim.negative_deg * sess.spec.stretch_fraction, lim.positive_deg * sess.spec.stretch_fraction
        span = max(hi, -lo, 1.0)

        mirror = 1.0 if self.side == "right" else -1.0   # a mirror: the left arm's supination turns to the left

        def at(v: float, rr: float) -> tuple[float, float]:
            a = math.radians(mirror * v / span * 90.0)   # 0 up, + to the arm's side (supination)
            return (cx + rr * math.sin(a), cy - rr * math.cos(a))

        for k in range(41):
            v = lo + (hi - lo) * k / 40
            c.circle(at(v, r), 3 * s, (255, 255, 255, 60))
        t = sess.target
        if t is not None:
            for dv in np.linspace(-t.size, t.size, 7):
                c.circle(at(t.target.value_deg + dv, r), 9 * s, (*sess.spec.colour, 235))
        v = sess.value_now()
        if math.isfinite(v):
            needle = min(max(v, lo), hi)   # beyond the dial's ends it would point down, over the text below
            for k in range(1, 9):
                c.circle(at(needle, r * k / 9), 5 * s, theme.TEXT)
            c.circle(at(needle, r), 12 * s,
                     GOOD if (t is not None and abs(v - t.target.value_deg) <= t.size) else theme.TEXT)
            c.text(f"{round(v):d}\N{DEGREE SIGN}", (cx, cy + 6 * s), round(theme.BODY * s), theme.TEXT, anchor="midtop")
        words = self.kind.direction_words
        for v_end, word in ((lo, words[0]), (hi, words[1])):   # under the dial's ends, clear of its dots
            ex, ey = at(v_end, r)
            c.text(word, (ex, max(ey, cy) + 14 * s), round(theme.SMALL * 0.8 * s), theme.TEXT_FAINT, anchor="midtop")
        return cy + 50 * s

    def _draw_banner(self, c) -> None:
        sess, s = self.session, self.scale
        v = self.view
        if sess.phase is Phase.DONE:
            text = f"Well done! {sess.reached} collected." + (" Saved." if self.stored_uid else "")
            colour = GOOD
        elif sess.phase is Phase.GET_READY:
            text = sess.pause_reason or "Get ready: sit up straight, arm relaxed"
            colour = theme.ATTENTION
        elif sess.pause_reason:
            text, colour = f"Paused: {sess.pause_reason}", theme.ATTENTION
        elif sess.compensation:
            text, colour = f"Paused: {sess.compensation}", theme.FAILURE
        else:
            return
        width = self.panel_x - v.x - 2 * theme.MARGIN * s   # over the river too: the patient looks there
        c.banner(text, (v.x + theme.MARGIN * s, theme.MARGIN * s), width, round(theme.BODY * s),
                 theme.OVERLAY, colour, theme.TEXT, scale=s)

    def _draw_flash(self, c) -> None:
        if self._flash is None:
            return
        text, colour, t0 = self._flash
        age = self.app.clock() - t0
        if age > FLASH_S:
            self._flash = None
            return
        s = self.scale
        v = self.view
        alpha = round(255 * (1.0 - age / FLASH_S))
        if self.river_view is not None:   # over the river, above the boat
            rx, ry, rw, rh = self.river_view.rect
            centre = (rx + rw / 2, self.river_view.bow_y - 90 * s - 30 * s * age)
        else:
            centre = (v.x + v.w / 2, v.h * 0.78 - 30 * s * age)
        size = theme.LARGE if self.river_view is not None else theme.TITLE
        c.text(text, centre, round(size * s), (*colour[:3], alpha),
               anchor="center")
