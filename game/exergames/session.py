"""One game session as a pure state machine: readings in, targets, score, pauses and a log out.

:func:`read_sample` turns a tracker sample (``tracking.live.LiveSample`` or any object with
``positions_m``, ``status``, ``angles_deg``, ``state``) into a :class:`Reading` of what the games
need, or says why it cannot (tracker waiting, markers lost). :class:`GameSession` is fed one
reading (or None with the reason) per frame with the game clock:

1. **get ready**: the tracker must see the arm (and, for the rotation games, the elbow at the side,
   bent) for ``READY_S``; the medians of that time are the baseline the compensation checks
   compare with, and the arm's segment lengths used to place targets;
2. **play**: a target is placed in joint-angle space inside the measured range
   (:mod:`game.exergames.targets`) and mapped to the hand's 3D position; holding it for the hold
   time collects it, letting its time limit run out misses it; the level of difficulty adapts to
   the success rate (:class:`LevelAdapter`) between the therapist's limits;
3. **paused** while the tracker does not deliver a usable reading (stopped, waiting for the
   reference pose, markers lost: no scoring on noise), while the posture is off, or while the
   patient compensates (trunk lean, shoulder hiking): the target's clock and the hold stop, the
   time is counted;
4. **done** after ``duration_s`` of play.

No I/O: the log is stored by :class:`game.exergames.visit.GameVisit`.
"""

from __future__ import annotations

import enum
import json
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from game.exergames.spec import GameSpec, TherapistLimits
from game.exergames.targets import ArmFrame, RomLimits, Target, arm_frame_from_markers

#: Tracker sample states (tracking.tracker.TrackingState) and marker status (tracking.marker_status).
TRACKING = 1
MARKER_LOST = 0
#: Seconds of good readings that make the baseline.
READY_S = 1.0
#: Pause between a target's end and the next one (the arm comes back; the cue sounds).
REST_S = 0.6
#: Normal rise of the acromion marker with arm elevation (docs/ROM.md): 0.4 mm per degree above
#: 30 degrees, at most 35 mm; a rise beyond it is shoulder hiking.
RHYTHM_M_PER_DEG, RHYTHM_FROM_DEG, RHYTHM_MAX_M = 0.0004, 30.0, 0.035
#: A compensation ends when it falls below this share of its limit (no flicker at the limit).
HYSTERESIS = 0.8

#: The arm angles read per sample (``<side>_`` + name) and the trunk angles.
ARM_ANGLES = ("shoulder_flexion", "shoulder_abduction", "shoulder_elevation", "elbow_flexion",
              "shoulder_external_rotation", "forearm_supination")
TRUNK_ANGLES = ("trunk_forward_lean", "trunk_lateral_lean")


# ============================================================================ readings
@dataclass(frozen=True, slots=True)
class Reading:
    """What the games need from one sample.

    Attributes:
        hand_m: (3,) world wrist centre of the active arm.
        angles: arm angles by name without the side (``elbow_flexion``) and the trunk angles; NaN
            where undefined.
        hiking_m: the active shoulder marker's height above the sternum marker along the trunk axis.
        frame: the arm's geometry in this sample.
    """

    hand_m: np.ndarray
    angles: dict
    hiking_m: float
    frame: ArmFrame


def read_sample(sample, marker_names, angle_names, side: str) -> tuple[Reading | None, str]:
    """(reading, "") or (None, why not) for one tracker sample.

    Args:
        sample: ``positions_m`` (M, 3) float64 metres, NaN where lost; ``status`` (M,) uint8;
            ``angles_deg`` (A,) in ``angle_names`` order; ``state`` (1 = tracking); ``message``.
        marker_names: the M marker names; angle_names: the A angle names.
        side: the active arm.
    """
    if int(sample.state) != TRACKING:
        message = getattr(sample, "message", "") or "finding the markers"
        return None, f"Waiting for the tracker: {message}"
    s = "R" if side == "right" else "L"
    need = ("MB", "MP", "MRH", "MLH", f"M{s}S", f"M{s}E1", f"M{s}E2", f"M{s}W1", f"M{s}W2")
    idx = {n: i for i, n in enumerate(marker_names)}
    status = np.asarray(sample.status)
    lost = [n for n in need if n in idx and status[idx[n]] == MARKER_LOST]
    if lost:
        return None, f"Markers lost ({', '.join(lost)}): please stay in view of the cameras"
    frame = arm_frame_from_markers(sample.positions_m, marker_names, side)
    if frame is None:
        return None, "Markers lost: please stay in view of the cameras"
    names = {n: i for i, n in enumerate(angle_names)}
    values = np.asarray(sample.angles_deg, dtype=np.float64)

    def get(name: str) -> float:
        return float(values[names[name]]) if name in names else math.nan

    angles = {a: get(f"{side}_{a}") for a in ARM_ANGLES}
    angles.update({a: get(a) for a in TRUNK_ANGLES})
    p = np.asarray(sample.positions_m, dtype=np.float64)
    hand = (p[idx[f"M{s}W1"]] + p[idx[f"M{s}W2"]]) / 2.0
    hiking = float((p[idx[f"M{s}S"]] - p[idx["MB"]]) @ frame.trunk[:, 1])
    return Reading(hand, angles, hiking, frame), ""


def shoulder_rhythm_m(elevation_deg: float) -> float:
    """The normal rise (m) of the acromion marker at a shoulder elevation (0 when unknown)."""
    if not math.isfinite(elevation_deg):
        return 0.0
    return min(RHYTHM_MAX_M, RHYTHM_M_PER_DEG * max(0.0, elevation_deg - RHYTHM_FROM_DEG))


# ============================================================================ difficulty
class LevelAdapter:
    """The level of difficulty (0 easy .. 1 hard), adapted online from the success rate.

    After every ``window`` targets the level rises by ``step`` when at least ``raise_above`` of
    them were collected, falls by ``step`` below ``lower_below``, and always stays within the
    therapist's limits. The values a level maps to (the top of the target range, the target size,
    the hold time, the time per target) are bounded by the therapist's :class:`TherapistLimits`
    whatever the level.

    Args:
        spec: the game's ``difficulty``.
        start, low, high: override the content's start level and limits (the therapist's choice).
        limits: the therapist's limits (None: none); its ``max_level`` caps ``high``, its ``min_level``
            raises ``low`` (the highest level wins when they cross).
    """

    def __init__(self, spec, start: float | None = None, low: float | None = None, high: float | None = None,
                 limits: TherapistLimits | None = None) -> None:
        self.spec = spec
        self.limits = limits if limits is not None else TherapistLimits()
        self.low = spec.min_level if low is None else float(low)
        self.high = spec.max_level if high is None else float(high)
        if self.limits.max_level is not None:
            self.high = min(self.high, self.limits.max_level)
        if self.limits.min_level is not None:
            self.low = max(self.low, self.limits.min_level)
        self.low = min(self.low, self.high)   # the therapist's highest level wins over the game's lowest
        self.level = min(max(spec.start if start is None else float(start), self.low), self.high)
        self.recent: list[bool] = []
        self.changes: list[float] = []

    def record(self, success: bool) -> int:
        """Add one target's outcome; returns +1 / -1 when the level moved, else 0."""
        self.recent.append(bool(success))
        if len(self.recent) < self.spec.window:
            return 0
        rate = sum(self.recent) / len(self.recent)
        self.recent.clear()
        old = self.level
        if rate >= self.spec.raise_above:
            self.level = min(self.high, self.level + self.spec.step)
        elif rate < self.spec.lower_below:
            self.level = max(self.low, self.level - self.spec.step)
        if self.level != old:
            self.changes.append(self.level)
            return 1 if self.level > old else -1
        return 0

    @property
    def top_fraction(self) -> float:
        top = self.spec.top_fraction.at(self.level)
        return top if self.limits.max_range is None else min(top, self.limits.max_range)

    @property
    def size(self) -> float:
        size = self.spec.size.at(self.level)
        return size if self.limits.min_size is None else max(size, self.limits.min_size)

    @property
    def hold_s(self) -> float:
        hold = self.spec.hold_s.at(self.level)
        return hold if self.limits.max_hold_s is None else min(hold, self.limits.max_hold_s)

    @property
    def time_limit_s(self) -> float:
        time = self.spec.time_limit_s.at(self.level)
        return time if self.limits.min_time_s is None else max(time, self.limits.min_time_s)

    @property
    def approach_s(self) -> float:
        """Rotation: how long a gate drifts down to the boat (a share of its time limit); else 0."""
        return self.spec.approach_share * self.time_limit_s


# ============================================================================ the session
class Phase(enum.IntEnum):
    GET_READY = 0
    PLAYING = 1
    DONE = 2


class Cue(enum.Enum):
    """Things the scene makes heard and seen once."""

    READY = "ready"
    NEW_TARGET = "new target"
    COLLECTED = "collected"
    MISSED = "missed"
    PAUSED = "paused"
    RESUMED = "resumed"
    LEVEL_UP = "level up"
    LEVEL_DOWN = "level down"
    DONE = "done"


@dataclass
class ActiveTarget:
    """The target on screen: where it is, how long it has waited, how long it has been held."""

    target: Target
    hand_m: np.ndarray
    size: float
    hold_s: float
    time_limit_s: float
    level: float
    approach_s: float = 0.0
    age_s: float = 0.0
    held_s: float = 0.0

    @property
    def arrived(self) -> bool:
        """The target can be collected (a rotation gate has drifted down to the boat)."""
        return self.age_s >= self.approach_s

    @property
    def hold_fraction(self) -> float:
        return min(1.0, self.held_s / self.hold_s) if self.hold_s > 0 else 1.0


@dataclass
class GameLog:
    """What a session stores (``details`` of ``exercise_results`` as JSON)."""

    game: str
    side: str
    reached: int = 0
    missed: int = 0
    started_s: float = math.nan
    ended_s: float = math.nan
    active_s: float = 0.0
    demo_s: float = 0.0
    paused_s: float = 0.0
    compensation_s: float = 0.0
    level_start: float = math.nan
    level_end: float = math.nan
    limits: dict = field(default_factory=dict)
    fractions: dict = field(default_factory=dict)
    therapist: dict = field(default_factory=dict)
    range_used: dict = field(default_factory=dict)
    targets: list = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return 0.0 if not math.isfinite(self.started_s) else max(0.0, self.ended_s - self.started_s)

    @property
    def score(self) -> float | None:
        n = self.reached + self.missed
        return self.reached / n if n else None

    def details_json(self) -> str:
        d = asdict(self)
        d.pop("game")
        d["duration_s"] = round(self.duration_s, 2)
        return json.dumps(d, separators=(",", ":"), allow_nan=False, default=float)


class GameSession:
    """One game on one side.

    Args:
        spec: the game.
        limits: the patient's maxima (:func:`game.exergames.targets.rom_limits_from_rows`).
        side: the active arm.
        seed: the targets' random generator (a session is reproducible).
        level, level_low, level_high: the therapist's start level and limits (None: the content's).
        therapist: the therapist's limits on the adaptation (None: the content's ``limits``).
    """

    def __init__(self, spec: GameSpec, limits: RomLimits, side: str = "right", *, seed: int = 0,
                 level: float | None = None, level_low: float | None = None, level_high: float | None = None,
                 therapist: TherapistLimits | None = None) -> None:
        self.spec = spec
        self.kind = spec.game_kind
        self.limits = limits
        self.side = side
        self.rng = np.random.default_rng(seed)
        self.therapist = spec.limits if therapist is None else therapist
        self.adapter = LevelAdapter(spec.difficulty, level, level_low, level_high, self.therapist)
        self.phase = Phase.GET_READY
        self.frame: ArmFrame | None = None
        self.target: ActiveTarget | None = None
        self.rest_s = 0.0
        self.pause_reason = "Waiting for the tracker"
        self.compensation = ""
        self.cues: list[Cue] = []
        self.last: Reading | None = None
        self._ready: list[Reading] = []
        self._ready_s = 0.0
        self._baseline: dict[str, float] = {}
        self._direction = 1
        self._now_s = math.nan
        self._demo = False
        self.log = GameLog(spec.name, side, level_start=self.adapter.level,
                           limits={"positive_deg": limits.positive_deg, "negative_deg": limits.negative_deg,
                                   "elbow_deg": limits.elbow_deg, "sources": dict(limits.sources)},
                           fractions={"comfort": spec.comfort_fraction, "stretch": spec.stretch_fraction},
                           therapist=self.therapist.model_dump(exclude_none=True))

    # ------------------------------------------------------------------ facts
    @property
    def paused(self) -> bool:
        return bool(self.pause_reason or self.compensation)

    @property
    def reached(self) -> int:
        return self.log.reached

    @property
    def level(self) -> float:
        return self.adapter.level

    @property
    def remaining_s(self) -> float:
        return max(0.0, self.spec.duration_s - self.log.active_s)

    def value_now(self) -> float:
        """The controlled quantity now (the kind's): reach: hand-to-target distance (m); else the angle (deg)."""
        r = self.last
        if r is None:
            return math.nan
        return self.kind.value(r, self.target)

    # ------------------------------------------------------------------ feeding
    def update(self, now_s: float, reading: Reading | None, reason: str = "", *, demo: bool = False) -> None:
        """Advance to ``now_s`` (the game clock, seconds) with this frame's reading.

        Args:
            now_s: monotonic seconds.
            reading: the newest reading, or None when there is none (then ``reason`` says why).
            reason: why there is no reading ("The tracker stopped: restarting...").
            demo: the automatic demo plays now, not the patient: its play time (``demo_s``) and
                the targets it ends (``"demo": true``) are logged apart, so that the progress
                review and the report never count them as the patient's.
        """
        self._demo = bool(demo)
        dt = 0.0 if not math.isfinite(self._now_s) else max(0.0, now_s - self._now_s)
        self._now_s = now_s
        if not math.isfinite(self.log.started_s):
            self.log.started_s = now_s
        if self.phase is Phase.DONE:
            return
        self.log.ended_s = now_s
        was_paused = self.paused and self.phase is Phase.PLAYING
        if reading is None:
            self._set_pause(reason or "Waiting for the tracker")
        else:
            self.last = reading
            self._set_pause(self._posture_problem(reading))
        if self.phase is Phase.GET_READY:
            self._get_ready(dt, reading)
            return
        if not self.pause_reason and reading is not None:
            self._check_compensation(reading)
        if self.paused:
            self.log.paused_s += dt
            if self.compensation and not self.pause_reason:
                self.log.compensation_s += dt
            if not was_paused:
                self.cues.append(Cue.PAUSED)
            return
        if was_paused:
            self.cues.append(Cue.RESUMED)
        self.log.active_s += dt
        if self._demo:
            self.log.demo_s += dt
        self._use_range(reading)
        self._play(dt, reading)
        if self.log.active_s >= self.spec.duration_s:
            self.finish()

    def finish(self) -> GameLog:
        """End the session (a target on screen is not counted); returns the log."""
        if self.phase is not Phase.DONE:
            self.phase = Phase.DONE
            self.target = None
            self.log.level_end = self.adapter.level
            self.cues.append(Cue.DONE)
        return self.log

    def take_cues(self) -> list[Cue]:
        out, self.cues = self.cues, []
        return out

    # ------------------------------------------------------------------ steps
    def _set_pause(self, reason: str) -> None:
        self.pause_reason = reason

    def _posture_problem(self, r: Reading) -> str:
        posture = self.spec.posture
        if posture is None:
            return ""
        lo, hi = posture.elbow_flexion_deg
        elbow, elevation = r.angles["elbow_flexion"], r.angles["shoulder_elevation"]
        if not (math.isfinite(elbow) and math.isfinite(elevation)):
            return "Markers unclear: keep the arm in view"
        if elevation > posture.max_shoulder_elevation_deg:
            return "Keep your elbow at your side"
        if not lo <= elbow <= hi:
            return "Bend your elbow like an L" if elbow < lo else "Open your elbow a little, like an L"
        return ""

    def _get_ready(self, dt: float, reading: Reading | None) -> None:
        if reading is None or self.pause_reason:
            self._ready.clear()
            self._ready_s = 0.0
            return
        self._ready.append(reading)
        self._ready_s += dt
        if self._ready_s < READY_S or len(self._ready) < 5:
            return
        rs = self._ready
        med = lambda xs: float(np.nanmedian(np.asarray(xs, dtype=np.float64)))  # noqa: E731
        self._baseline = {a: med([r.angles[a] for r in rs]) for a in (*TRUNK_ANGLES, "shoulder_elevation")}
        self._baseline["hiking_m"] = med([r.hiking_m for r in rs])
        last = rs[-1].frame
        self.frame = ArmFrame(np.median([r.frame.shoulder_m for r in rs], axis=0),
                              last.trunk, med([r.frame.upper_arm_m for r in rs]),
                              med([r.frame.forearm_m for r in rs]), self.side)
        self._ready.clear()
        self.phase = Phase.PLAYING
        self.pause_reason = ""
        self.rest_s = REST_S
        self.cues.append(Cue.READY)

    def _check_compensation(self, r: Reading) -> None:
        b, c = self._baseline, self.spec.compensation
        lean = math.hypot(r.angles["trunk_forward_lean"] - b["trunk_forward_lean"],
                          r.angles["trunk_lateral_lean"] - b["trunk_lateral_lean"])
        rise = (r.hiking_m - b["hiking_m"]) - (shoulder_rhythm_m(r.angles["shoulder_elevation"])
                                               - shoulder_rhythm_m(b["shoulder_elevation"]))
        factor = HYSTERESIS if self.compensation else 1.0
        if math.isfinite(lean) and lean > factor * c.trunk_lean_deg:
            self.compensation = "Sit up straight: keep your trunk upright"
        elif math.isfinite(rise) and rise > factor * c.shoulder_hiking_mm / 1000.0:
            self.compensation = "Relax your shoulder: keep it down"
        else:
            self.compensation = ""

    def _use_range(self, r: Reading) -> None:
        for name in self.kind.logged_angles:
            v = r.angles[name]
            if math.isfinite(v):
                lo, hi = self.log.range_used.get(name, (v, v))
                self.log.range_used[name] = (round(min(lo, v), 1), round(max(hi, v), 1))

    def _play(self, dt: float, r: Reading) -> None:
        if self.target is None:
            self.rest_s -= dt
            if self.rest_s <= 0.0:
                self._new_target()
            return
        t = self.target
        t.age_s += dt
        if self._inside(r, t):
            t.held_s += dt
            if t.held_s >= t.hold_s:
                self._end_target(True)
                return
        else:
            t.held_s = max(0.0, t.held_s - 2.0 * dt)   # leaving drains the hold quickly, not at once
        if t.age_s >= t.time_limit_s:
            self._end_target(False)

    def _inside(self, r: Reading, t: ActiveTarget) -> bool:
        return t.arrived and self.kind.inside(r, t)

    def _new_target(self) -> None:
        a, spec = self.adapter, self.spec
        target = self.kind.place(self.limits, spec.comfort_fraction, a.top_fraction, self.rng,
                                 direction=self._direction, planes_deg=spec.planes_deg,
                                 elbow_range_deg=spec.elbow_flexion_deg)
        self._direction = -self._direction   # rotation games alternate out and in
        self.target = ActiveTarget(target, self.kind.hand_m(target, self.frame), a.size, a.hold_s,
                                   a.time_limit_s, a.level, a.approach_s)
        self.cues.append(Cue.NEW_TARGET)

    def _end_target(self, success: bool) -> None:
        t = self.target
        self.log.targets.append({
            "value_deg": round(t.target.value_deg, 2), "limit_deg": round(t.target.limit_deg, 2),
            "fraction": round(t.target.fraction, 4), "plane_deg": t.target.plane_deg,
            "elbow_deg": round(t.target.elbow_deg, 1), "hand_m": [round(float(x), 4) for x in t.hand_m],
            "level": round(t.level, 3), "size": round(t.size, 4), "hold_s": round(t.hold_s, 2),
            "time_limit_s": round(t.time_limit_s, 2), "approach_s": round(t.approach_s, 2), "reached": success,
            "time_s": round(t.age_s, 2), "demo": self._demo,
        })
        if success:
            self.log.reached += 1
        else:
            self.log.missed += 1
        self.cues.append(Cue.COLLECTED if success else Cue.MISSED)
        change = self.adapter.record(success)
        if change:
            self.cues.append(Cue.LEVEL_UP if change > 0 else Cue.LEVEL_DOWN)
        self.log.level_end = self.adapter.level
        self.target = None
        self.rest_s = REST_S
