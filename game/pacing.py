"""The frame rate the loop paces to: the full rate while frames keep to it, half of it while a
busy machine makes them miss it.

On a machine whose cores are taken by other work, frames made for 60 frames/s keep missing
their deadline by a varying amount: the window shows an uneven 35-55 frames/s with long gaps,
and each frame the game makes takes CPU from the tracker process, whose samples (30 per second)
are what the avatar shows. A steady half rate (every other refresh, 30 frames/s) then looks
smoother and leaves the tracker the CPU the extra frames cost. Pure logic, no clock, no GL:
:class:`FramePacer` sees each frame's interval and answers the period of the next.

The controller judges what the patient sees, the frame intervals, not the time to make a frame
(a display's vsync makes that time look full even when the machine is idle). At the full rate a
frame *misses* when its interval exceeds ``miss_at`` full periods (a refresh skipped);
``drop_misses`` misses among the last ``window`` frames (3 s) halve the rate. At the half rate
nothing tells whether the full rate would hold again, so after ``rise_after`` frames it is tried,
and judged faster, since the machine was busy a moment ago: within ``hold`` frames of the
return, ``probe_misses`` misses among the last ``probe`` frames (1 s) halve it again. A return
halved again within ``hold`` frames doubles the next wait (up to
``max_rise_after``), so a machine at the edge does not flicker between the two rates; a return
that holds resets it.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class PaceLimits:
    """How :class:`FramePacer` moves between the full and the half rate.

    Attributes:
        window: frames at the full rate over which misses are counted (180: 3 s at 60).
        drop_misses: misses among the last ``window`` frames that halve the rate (36 of 180: one
            frame in five skips a refresh over 3 s, the full rate shows less than ~50 frames/s;
            a burst of a second, such as another process starting, is no reason to halve).
        miss_at: a frame misses when its interval exceeds this many full-rate periods.
        rise_after: frames at the half rate before the full rate is tried again (150: 5 s at 30
            frames/s).
        max_rise_after: the longest that wait grows to after returns that did not hold (1200: 40 s).
        hold: frames at the full rate after which a return has held (300: 5 s at 60; with four
            CPU burners a return was halved again 1-2 s later, after the first window).
        probe, probe_misses: within ``hold`` frames of a return, this many misses among the
            last ``probe`` frames halve the rate again (12 of 60: one in five over a second).
    """

    window: int = 180
    drop_misses: int = 36
    miss_at: float = 1.5
    rise_after: int = 150
    max_rise_after: int = 1200
    hold: int = 300
    probe: int = 60
    probe_misses: int = 12

    def __post_init__(self) -> None:
        if not (1 <= self.drop_misses <= self.window and self.miss_at > 1.0 and 1 <= self.rise_after <= self.max_rise_after
                and self.hold >= self.window and 1 <= self.probe_misses <= self.probe <= self.window):
            raise ValueError("PaceLimits: need 1 <= drop_misses <= window, miss_at > 1, "
                             "1 <= rise_after <= max_rise_after, hold >= window, 1 <= probe_misses <= probe <= window")


class FramePacer:
    """The loop's frame period: ``1 / max_fps``, or twice that while frames miss it.

    Args:
        max_fps: the full rate (frames per second, > 0).
        adaptive: False keeps the full rate always.
        limits: how the rate moves.
    """

    def __init__(self, max_fps: float, *, adaptive: bool = True, limits: PaceLimits = PaceLimits()) -> None:
        if not max_fps > 0:
            raise ValueError("FramePacer: max_fps must be positive")
        self.full_period_s = 1.0 / float(max_fps)
        self.adaptive = adaptive
        self.limits = limits
        self.halved = False
        self.changes = 0                 # times the rate changed
        self._misses: deque[bool] = deque(maxlen=limits.window)
        self._halved_for = 0             # frames at the half rate since it was chosen
        self._rise_after = limits.rise_after
        self._since_rise = math.inf      # frames at the full rate since the last return to it

    @property
    def period_s(self) -> float:
        """The period of the next frame."""
        return 2.0 * self.full_period_s if self.halved else self.full_period_s

    @property
    def fps(self) -> float:
        return 1.0 / self.period_s

    def observe(self, interval_s: float) -> float:
        """Account for one frame's interval (seconds since the previous frame was drawn); returns
        the period of the next frame."""
        if not self.adaptive or not math.isfinite(interval_s) or interval_s < 0:
            return self.period_s
        lim = self.limits
        if not self.halved:
            self._since_rise += 1
            self._misses.append(interval_s > lim.miss_at * self.full_period_s)
            probing = self._since_rise <= lim.hold
            recent = sum(itertools.islice(reversed(self._misses), lim.probe)) if probing else 0
            if sum(self._misses) >= lim.drop_misses or recent >= lim.probe_misses:
                # a return that did not hold: wait longer before the next one
                if self._since_rise <= lim.hold:
                    self._rise_after = min(2 * self._rise_after, lim.max_rise_after)
                self._set(True)
        else:
            self._halved_for += 1
            if self._halved_for >= self._rise_after:
                self._set(False)
        if not self.halved and self._since_rise > lim.hold:
            self._rise_after = lim.rise_after   # the last return held
        return self.period_s

    def _set(self, halved: bool) -> None:
        self.halved = halved
        self.changes += 1
        self._misses.clear()
        self._halved_for = 0
        self._since_rise = 0
