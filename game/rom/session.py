"""The ROM test logic over tracker samples, shared by the ROM test scene and ``rehab rom-test``.

:class:`RomTestSession` is a pure state machine fed one tracker sample at a time::

    WAITING_TRACKER -> CHECKING_START -> RECORDING -> DONE -> accept() (ACCEPTED) | discard() (CHECKING_START)

- **Checking the start position**: the test's start angles (content) must be within their ranges
  for ``start_hold_s``, held still (the test value within ``START_STILL_DEG``); the medians over
  that hold are the start values that the range and the compensation checks are measured from
  (docs/JOINT_ANGLES.md: compensation is judged as the change from the start position).
- **Recording**: the test value (``direction * angle``, 3-sample median against single-frame
  spikes) is followed; its maximum, the range from the start and the compensations seen are kept.
  The recording ends when the value has come back at least half-way from its maximum towards the
  start (the movement is over), or after ``max_duration_s``.
- **Done**: the result waits for the therapist: :meth:`accept` returns the :class:`RomResult` to
  store; :meth:`discard` starts a new attempt. A result with compensations is marked so and the
  scene asks to repeat; the therapist may still accept it (it stays flagged).

Readings that rest on estimated (hidden) markers are marked: the result names the markers of the
test's angle that were estimated in the samples that gave the maximum. A lost hip marker (a hand
in front of the hip) is held where it was last measured, since the seated pelvis does not move;
such readings count as estimated too.

No pygame, GL, files or clocks: time comes from the samples.
"""

from __future__ import annotations

import enum
import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from calibration.errors import RehabError
from game.rom.spec import MODE_ACTIVE, Compensation, RomTest, check_side, check_standard
from tracking.angles import joint_angles
from tracking.marker_status import MarkerStatus

#: Markers each arm angle rests on (docs/JOINT_ANGLES.md); ``*`` is L or R. The trunk frame needs
#: MB, MP and both hips.
_TRUNK = ("MB", "MP", "MLH", "MRH")
_ANGLE_MARKERS: dict[str, tuple[str, ...]] = {
    "shoulder_flexion": _TRUNK + ("M*S", "M*E1", "M*E2"),
    "shoulder_abduction": _TRUNK + ("M*S", "M*E1", "M*E2"),
    "shoulder_elevation": _TRUNK + ("M*S", "M*E1", "M*E2"),
    "shoulder_horizontal_flexion": _TRUNK + ("M*S", "M*E1", "M*E2"),
    "shoulder_external_rotation": _TRUNK + ("M*S", "M*E1", "M*E2", "M*W1", "M*W2"),
    "elbow_flexion": ("M*S", "M*E1", "M*E2", "M*W1", "M*W2"),
    "forearm_supination": ("M*E1", "M*E2", "M*W1", "M*W2"),
}


def angle_markers(angle: str, side: str) -> tuple[str, ...]:
    """Names of the markers an arm angle of one side is computed from, e.g. ``("MB", ..., "MRS", ...)``."""
    letter = "R" if side == "right" else "L"
    return tuple(m.replace("*", letter) for m in _ANGLE_MARKERS[angle])


def round_to_5(value_deg: float) -> int:
    """Clinical recording: the nearest multiple of 5 degrees (halves away from zero)."""
    return int(math.copysign(math.floor(abs(value_deg) / 5.0 + 0.5) * 5, value_deg)) if math.isfinite(value_deg) else 0


#: The start position must be held still: the test value may drift at most this much during the hold.
START_STILL_DEG = 5.0


class RomState(enum.IntEnum):
    """Where a ROM test attempt is."""

    WAITING_TRACKER = 0  # the tracker has not named the markers yet
    CHECKING_START = 1
    RECORDING = 2
    DONE = 3  # waiting for the therapist: accept or discard
    ACCEPTED = 4


@dataclass(frozen=True, slots=True)
class RomProgress:
    """What the scene shows after each sample.

    Attributes:
        state: the session state.
        message: one line in plain words for the therapist and the patient.
        value_deg: the current test value (direction * angle, degrees), NaN if unknown.
        start_deg: the start value (NaN before recording).
        max_deg: the maximum so far (NaN before recording).
        hold_fraction: 0..1 of the start-position hold done (CHECKING_START).
        compensations: the compensations seen so far, plain words.
        estimated: the current value rests on estimated (hidden) markers.
        start_problems: CHECKING_START: what keeps the patient from the start position, each
            in plain words with its current value ("elbow flexion 12 (needs 65 to 115)").
    """

    state: RomState
    message: str
    value_deg: float
    start_deg: float
    max_deg: float
    hold_fraction: float
    compensations: tuple[str, ...]
    estimated: bool
    start_problems: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class RomResult:
    """One finished ROM test attempt (active ROM), ready to be accepted and stored.

    Attributes:
        test, title, side: which test (content name), its title, the side.
        angle: the column of docs/JOINT_ANGLES.md read (e.g. ``right_shoulder_flexion``).
        direction: +1 or -1 (the value is ``direction * angle``).
        mode: always ``active``.
        position: the test position id; position_words: in plain words.
        standard: the reference standard the result is labelled with (``jarm`` or ``aaos``).
        reference_deg: that standard's normal value for this position, None if it has none.
        max_deg: the maximum reached (raw, degrees; the goniometer reading, 0 = neutral).
        start_deg: the value in the start position.
        range_deg: max_deg - start_deg.
        max_time_s: sample time of the maximum; started_s, ended_s: the recording.
        compensations: what the patient compensated with, plain words (empty: clean).
        estimated_markers: markers of the angle that were estimated (hidden) at the maximum.
        n_samples: samples recorded.
    """

    test: str
    title: str
    side: str
    angle: str
    direction: int
    mode: str
    position: str
    position_words: str
    standard: str
    reference_deg: float | None
    max_deg: float
    start_deg: float
    range_deg: float
    max_time_s: float
    started_s: float
    ended_s: float
    compensations: tuple[str, ...]
    estimated_markers: tuple[str, ...]
    n_samples: int

    @property
    def compensated(self) -> bool:
        return bool(self.compensations)

    @property
    def estimated(self) -> bool:
        """The maximum rests on at least one estimated (hidden) marker."""
        return bool(self.estimated_markers)

    @property
    def rounded_deg(self) -> int:
        """The maximum rounded to 5 degrees, as a therapist records it."""
        return round_to_5(self.max_deg)

    def line(self) -> str:
        """One line for a therapist."""
        ref = f"{self.standard.upper()} normal {self.reference_deg:g}" if self.reference_deg is not None \
            else f"no {self.standard.upper()} normal for this position"
        text = (f"{self.title}, {self.side}: {self.rounded_deg} deg (raw {self.max_deg:.1f}; moved "
                f"{self.range_deg:.1f} from the start position, which read {self.start_deg:.1f}), active ROM, "
                f"{self.position_words.rstrip('.')}; {ref}")
        if self.estimated:
            text += f"; relied on estimated markers {', '.join(self.estimated_markers)}"
        if self.compensated:
            text += f"; COMPENSATION: {'; '.join(self.compensations)}"
        return text


@dataclass
class _Median3:
    """Median of the last three finite values (a single-frame spike never counts)."""

    values: deque = field(default_factory=lambda: deque(maxlen=3))

    def push(self, v: float) -> float:
        if math.isfinite(v):
            self.values.append(v)
        if not self.values:
            return math.nan
        return float(np.median(self.values))

    def clear(self) -> None:
        self.values.clear()


def _angle(sample: Any, name: str) -> float:
    """An angle from a TrackerSample (``angles_deg`` dict) or a LiveSample (``angle(name)``)."""
    getter = getattr(sample, "angle", None)
    if callable(getter):
        try:
            return float(getter(name))
        except (KeyError, ValueError):
            return math.nan
    return float(sample.angles_deg.get(name, math.nan))


class RomTestSession:
    """One ROM test on one side, fed tracker samples in time order.

    Args:
        test: the test definition (:func:`game.rom.spec.load_rom_test`).
        side: ``right`` or ``left``.
        standard: ``jarm`` or ``aaos``: the results are labelled with it and show its normal value.
        marker_names: the tracker's marker names, in the order of the samples' position arrays.

    Feed with :meth:`feed` (anything with ``time_s``, ``state``, ``positions_m`` (M, 3), ``status``
    (M,) and angles: :class:`tracking.tracker.TrackerSample` or ``tracking.live.LiveSample``).
    """

    def __init__(self, test: RomTest, side: str, standard: str, marker_names: Sequence[str]):
        check_side(test, side)
        check_standard(standard)
        self.test = test
        self.side = side
        self.standard = standard
        names = list(marker_names)
        index = {n: i for i, n in enumerate(names)}
        need = set(angle_markers(test.angle, side)) | {"MB", "MP", f"M{side[0].upper()}S"}
        missing = sorted(need - set(index))
        if missing:
            raise RehabError(f"the marker set lacks {', '.join(missing)}: the test {test.name} needs the upper_limb_seated markers")
        self._angle_idx = np.array([index[m] for m in angle_markers(test.angle, side)])
        self._angle_names = angle_markers(test.angle, side)
        self._mb, self._mp, self._shoulder = index["MB"], index["MP"], index[f"M{side[0].upper()}S"]
        self._names = tuple(names)
        self._hip_idx = [index[h] for h in ("MLH", "MRH") if h in index]
        self._hips_seen: list[np.ndarray | None] = [None] * len(self._hip_idx)
        self._held: tuple[str, ...] = ()
        self.angle_name = test.angle_name(side)
        self.restart()

    # ------------------------------------------------------------------ state
    def restart(self) -> None:
        """Start a new attempt: check the start position again (after a discard, or any time)."""
        self.state = RomState.WAITING_TRACKER
        self._hold: list[dict[str, float]] = []  # channels of the samples in the start position
        self._hold_t0 = math.nan
        self._start: dict[str, float] = {}
        self._value = _Median3()
        self._channels: dict[str, _Median3] = {}
        self._recent_estimated: deque = deque(maxlen=3)
        self._max = -math.inf
        self._max_t = math.nan
        self._max_estimated: tuple[str, ...] = ()
        self._t0 = math.nan
        self._t_last = math.nan
        self._n = 0
        self._worst: dict[int, float] = {}  # compensation index -> worst excess seen
        self._comp_words: dict[int, str] = {}
        self._result: RomResult | None = None
        self._last = RomProgress(self.state, "waiting for the tracker to name the markers (reference pose)",
                                 math.nan, math.nan, math.nan, 0.0, (), False)

    @property
    def progress(self) -> RomProgress:
        """What the last sample showed (before any sample: waiting for the tracker)."""
        return self._last

    @property
    def result(self) -> RomResult | None:
        """The finished attempt (DONE or ACCEPTED), else None."""
        return self._result

    def accept(self) -> RomResult:
        """The therapist accepts the finished attempt: returns the result to store."""
        if self.state not in (RomState.DONE, RomState.ACCEPTED) or self._result is None:
            raise RehabError(f"nothing to accept: the test is {self.state.name.lower().replace('_', ' ')}")
        self.state = RomState.ACCEPTED
        return self._result

    def discard(self) -> None:
        """The therapist discards the finished attempt (or aborts a running one): start again."""
        self.restart()

    # ------------------------------------------------------------------ feeding
    def _view(self, sample: Any):
        """(angle getter, names of hip markers held) for one sample.

        The trunk frame needs both hip markers, and a hand in front of the hip (internal rotation)
        hides one: then every shoulder angle is undefined. The seated pelvis does not move during an
        upper-limb test, so a lost hip marker is held where it was last measured and the angles are
        recomputed (docs/JOINT_ANGLES.md, :func:`tracking.angles.joint_angles`); the reading counts
        as resting on an estimated marker.
        """
        p = np.asarray(sample.positions_m, dtype=np.float64)
        st = np.asarray(sample.status)
        held = []
        for k, i in enumerate(self._hip_idx):
            if st[i] == MarkerStatus.MEASURED and np.isfinite(p[i]).all():
                self._hips_seen[k] = p[i].copy()
            elif not np.isfinite(p[i]).all() and self._hips_seen[k] is not None:
                held.append(k)
        if not held:
            return (lambda name: _angle(sample, name)), ()
        q = p.copy()
        for k in held:
            q[self._hip_idx[k]] = self._hips_seen[k]
        angles = joint_angles(q, self._names)
        # an angle the tracker withheld from these positions (a supination whose elbow axis is a
        # guess) stays withheld
        for name, value in joint_angles(p, self._names).items():
            if np.isfinite(value) and not np.isfinite(_angle(sample, name)):
                angles[name] = math.nan
        return (lambda name: float(angles[name]) if name in angles else math.nan), \
            tuple(self._names[self._hip_idx[k]] for k in held)

    def _channels_of(self, sample: Any, get) -> dict[str, float]:
        """Every number the checks need from one sample (NaN where unknown)."""
        ch = {"value": self.test.direction * get(self.angle_name)}
        for name in self.test.start_angles:
            ch[f"start:{name}"] = get(name if name.startswith("trunk_") else f"{self.side}_{name}")
        for c in self.test.compensations:
            if c.kind == "trunk_lean":
                ch["trunk_forward_lean"] = get("trunk_forward_lean")
                ch["trunk_lateral_lean"] = get("trunk_lateral_lean")
            elif c.kind == "shoulder_hiking":
                p = np.asarray(sample.positions_m, dtype=np.float64)
                y_t = p[self._mb] - p[self._mp]
                n = float(np.linalg.norm(y_t))
                ch["hiking_m"] = float((p[self._shoulder] - p[self._mb]) @ y_t / n) if n > 1e-9 else math.nan
                ch["elevation"] = get(f"{self.side}_shoulder_elevation")
            else:
                ch[f"angle:{c.angle}"] = get(f"{self.side}_{c.angle}")
        return ch

    def _estimated_now(self, sample: Any) -> tuple[str, ...]:
        st = np.asarray(sample.status)[self._angle_idx]
        est = {n for n, s in zip(self._angle_names, st) if s == MarkerStatus.ESTIMATED}
        return tuple(n for n in self._angle_names if n in est or n in self._held)

    def feed(self, sample: Any) -> RomProgress:
        """Process one tracker sample; returns what to show."""
        if self.state in (RomState.DONE, RomState.ACCEPTED):
            return self._last
        t = float(sample.time_s)
        if int(sample.state) != 1:  # TrackingState.TRACKING
            if self.state == RomState.RECORDING:
                return self._progress(math.nan, f"tracking lost: {getattr(sample, 'message', '') or 'waiting'}")
            self.state = RomState.WAITING_TRACKER
            self._hold.clear()
            msg = getattr(sample, "message", "") or "waiting for the reference pose"
            self._last = RomProgress(self.state, f"waiting for the tracker: {msg}", math.nan, math.nan, math.nan, 0.0, (), False)
            return self._last
        get, self._held = self._view(sample)
        ch = self._channels_of(sample, get)
        if self.state in (RomState.WAITING_TRACKER, RomState.CHECKING_START):
            return self._check_start(t, ch, sample)
        return self._record(t, ch, sample)

    def finish(self) -> RomProgress:
        """The sample stream ended (e.g. the end of a recorded motion): end a recording that moved enough."""
        if self.state == RomState.RECORDING and self._max - self._start["value"] >= self.test.min_range_deg:
            self._done("the recording ended")
        return self._last

    # ------------------------------------------------------------------ start position
    def _check_start(self, t: float, ch: dict[str, float], sample: Any) -> RomProgress:
        self.state = RomState.CHECKING_START
        wrong = []
        for name, (lo, hi) in self.test.start_angles.items():
            v = ch[f"start:{name}"]
            if not math.isfinite(v):
                wrong.append(f"{name.replace('_', ' ')} not measured")
            elif not lo <= v <= hi:
                wrong.append(f"{name.replace('_', ' ')} {v:.0f} (needs {lo:g} to {hi:g})")
        needed = [k for k in ch if not k.startswith("start:")]
        if wrong or not all(math.isfinite(ch[k]) for k in needed):
            self._hold.clear()
            problems = tuple(wrong) or ("the test's markers are not all measured",)
            self._last = RomProgress(self.state,
                                     f"take the start position: {self.test.position_words.rstrip('.')} ({'; '.join(problems)})",
                                     ch["value"], math.nan, math.nan, 0.0, (), bool(self._estimated_now(sample)),
                                     problems)
            return self._last
        if self._hold and abs(ch["value"] - self._hold[0]["value"]) > START_STILL_DEG:
            self._hold.clear()  # still moving (e.g. coming down from the last attempt): hold again
        if not self._hold:
            self._hold_t0 = t
        self._hold.append(ch)
        held = t - self._hold_t0
        hold_s = self.test.start_hold_s
        if held + 1e-9 < hold_s:
            self._last = RomProgress(self.state, "hold the start position", ch["value"], math.nan, math.nan,
                                     held / hold_s if hold_s > 0 else 1.0, (), bool(self._estimated_now(sample)))
            return self._last
        self._start = {k: float(np.nanmedian([h[k] for h in self._hold])) for k in self._hold[-1]}
        self._hold.clear()
        self.state = RomState.RECORDING
        self._t0 = t
        self._max = -math.inf
        return self._record(t, ch, sample, message=f"go: {self.test.instructions}")

    # ------------------------------------------------------------------ recording
    def _record(self, t: float, ch: dict[str, float], sample: Any, message: str = "") -> RomProgress:
        self._t_last = t
        self._n += 1
        est = self._estimated_now(sample)
        if math.isfinite(ch["value"]):
            self._recent_estimated.append(est)
        value = self._value.push(ch["value"])
        if math.isfinite(value) and value > self._max:
            self._max, self._max_t = value, t
            self._max_estimated = tuple(sorted(set().union(*self._recent_estimated))) if self._recent_estimated else ()
        self._check_compensations(ch)
        start = self._start["value"]
        moved = self._max - start
        if moved >= self.test.min_range_deg and math.isfinite(value) and \
                value <= self._max - max(0.5 * moved, 0.5 * self.test.min_range_deg):
            return self._done("done")
        if t - self._t0 >= self.test.max_duration_s:
            if moved >= self.test.min_range_deg:
                return self._done("time is up")
            self.restart()
            self._last = RomProgress(self.state, f"no movement in {self.test.max_duration_s:g} s: take the start position again",
                                     value, math.nan, math.nan, 0.0, (), bool(est))
            return self._last
        return self._progress(value, message or "recording: move as far as you can, then come back", bool(est))

    def _check_compensations(self, ch: dict[str, float]) -> None:
        s = self._start
        for i, c in enumerate(self.test.compensations):
            if c.kind == "trunk_lean":
                dfw = self._smooth("fw", ch["trunk_forward_lean"] - s["trunk_forward_lean"])
                dlat = self._smooth("lat", ch["trunk_lateral_lean"] - s["trunk_lateral_lean"])
                size = math.hypot(dfw, dlat)
                if size > c.limit:
                    self._note(i, size - c.limit, f"{c.words} {size:.0f} degrees {_lean_words(dfw, dlat, self.side)} "
                                                   f"(limit {c.limit:g}): keep the trunk upright")
            elif c.kind == "shoulder_hiking":
                # the normal rise at this elevation is subtracted frame by frame, then smoothed
                normal = _rhythm(c, ch["elevation"]) - _rhythm(c, s["elevation"])
                excess = self._smooth("hike", ch["hiking_m"] - s["hiking_m"] - normal)
                if excess > c.limit:
                    self._note(i, excess, f"{c.words} {1000 * excess:.0f} mm more than the arm's normal rise "
                                          f"(limit {1000 * c.limit:.0f} mm): keep the shoulder down")
            else:
                d = self._smooth(f"a{i}", ch[f"angle:{c.angle}"] - s[f"angle:{c.angle}"])
                if abs(d) > c.limit:
                    self._note(i, abs(d) - c.limit, f"{c.words} ({c.angle.replace('_', ' ')} changed {abs(d):.0f} degrees, "
                                                    f"limit {c.limit:g})")

    def _smooth(self, key: str, v: float) -> float:
        return self._channels.setdefault(key, _Median3()).push(v)

    def _note(self, i: int, excess: float, words: str) -> None:
        if excess > self._worst.get(i, -math.inf):
            self._worst[i] = excess
            self._comp_words[i] = words

    def _compensations(self) -> tuple[str, ...]:
        return tuple(self._comp_words[i] for i in sorted(self._comp_words))

    def _progress(self, value: float, message: str, estimated: bool = False) -> RomProgress:
        self._last = RomProgress(self.state, message, value, self._start.get("value", math.nan),
                                 self._max if math.isfinite(self._max) else math.nan, 1.0, self._compensations(), estimated)
        return self._last

    def _done(self, why: str) -> RomProgress:
        self.state = RomState.DONE
        start = self._start["value"]
        ref = self.test.reference(self.standard)
        comps = self._compensations()
        self._result = RomResult(
            test=self.test.name, title=self.test.title, side=self.side, angle=self.angle_name,
            direction=self.test.direction, mode=MODE_ACTIVE, position=self.test.position_id,
            position_words=self.test.position_words, standard=self.standard,
            reference_deg=ref.value_deg if ref is not None and ref.comparable else None,
            max_deg=float(self._max), start_deg=start, range_deg=float(self._max - start),
            max_time_s=float(self._max_t), started_s=float(self._t0), ended_s=float(self._t_last),
            compensations=comps, estimated_markers=self._max_estimated, n_samples=self._n,
        )
        msg = f"{why}: {self._result.rounded_deg} degrees"
        msg += f"; compensation seen ({'; '.join(comps)}): repeat the test" if comps else ": accept or discard"
        return self._progress(math.nan, msg)


def _rhythm(c: Compensation, elevation_deg: float) -> float:
    """The normal rise of the acromion marker (m) at a shoulder elevation (deg); NaN if unknown."""
    if not math.isfinite(elevation_deg):
        return math.nan
    return min(c.rhythm_max_m, c.rhythm_m_per_deg * max(0.0, elevation_deg - c.rhythm_from_deg))


def _lean_words(d_forward: float, d_lateral: float, side: str) -> str:
    """Plain words for a trunk lean change: ``back and to the left``."""
    parts = []
    if abs(d_forward) >= 3:
        parts.append("forward" if d_forward > 0 else "back")
    if abs(d_lateral) >= 3:
        parts.append("to the right" if d_lateral > 0 else "to the left")
    return " and ".join(parts) if parts else "off upright"
