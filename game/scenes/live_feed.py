"""The live feed of the scenes that show the tracker's patient: one way to read the tracker link.

The live mirror (:mod:`game.scenes.live`), the games (:mod:`game.scenes.game_play`) and the ROM
test (:mod:`game.scenes.rom_test`) each hold a :class:`LiveFeed`: it takes the link's new samples
once per frame, makes the avatar once the marker set is known and moves it with the samples that
know enough markers, says when the samples stopped (one staleness rule, :data:`STALE_SAMPLE_S`)
and why there is no live reading, and sends the simulated patient's input at most
:data:`INPUT_PERIOD_S` apart, only when it changed.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

#: A sample with fewer known markers (the tracker waiting for the reference pose) moves no avatar.
MIN_KNOWN_MARKERS = 4
#: Shortest interval between two patient inputs sent to the tracker process (its camera runs at 30).
INPUT_PERIOD_S = 1.0 / 60.0
#: No new sample for this long while the tracker runs: the samples have stopped (the mirror hides
#: its angles, a game pauses, the ROM test says so). The tracker publishes 19-30 a second, so this
#: is 9-15 samples missed, and a game never credits a hold (0.3 s at the shortest) to a pose this old;
#: docs/APP.md "The live feed" says why one rule and this one.
STALE_SAMPLE_S = 0.5
#: What the scenes say while there is no sample yet, and once the samples stopped.
WAITING_LINE = "Waiting for the first images..."
STOPPED_LINE = "No new images from the cameras..."


def known_markers(sample) -> int:
    """How many of the sample's markers have a position."""
    return int(np.isfinite(sample.positions_m).all(axis=1).sum())


class LiveFeed:
    """One scene's view of the tracker link (:class:`game.live_link.LiveLink`).

    Args:
        link: the link; ``new_samples``, ``latest``, ``markerset``, ``problem()`` and
            ``set_patient_input`` are used.
        make_avatar: ``make_avatar(ctx, marker_names, roles=...)`` -> :class:`game.avatar.live.LiveAvatar`
            (None: no avatar, e.g. unit tests of the logic).
    """

    def __init__(self, link, make_avatar: Callable | None = None) -> None:
        self.link = link
        self.make_avatar = make_avatar
        self.avatar = None
        self.samples: list = []
        self.sample_clock_s = math.nan   # the app's clock when the newest sample arrived
        self._frame = None
        self._since_sent_s = 0.0
        self._sent = None

    # ------------------------------------------------------------------ samples
    def take(self, app) -> list:
        """This frame's new samples (the same list however often a frame asks): their arrival is
        noted, the avatar is made once the marker set is known and moved by the samples that know
        at least :data:`MIN_KNOWN_MARKERS` markers."""
        if self._frame == app.frames:
            return self.samples
        self._frame = app.frames
        self.samples = self.link.new_samples
        if self.samples:
            self.sample_clock_s = app.clock()
        markerset = self.link.markerset
        if self.avatar is None and self.make_avatar is not None and markerset is not None:
            self.avatar = self.make_avatar(app.screen.ctx, markerset.names, roles=markerset.roles)
        if self.avatar is not None:
            for sample in self.samples:
                if known_markers(sample) >= MIN_KNOWN_MARKERS:
                    self.avatar.push_sample(sample)
        return self.samples

    def stopped(self, now_s: float) -> bool:
        """Samples came and then none for :data:`STALE_SAMPLE_S`."""
        return math.isfinite(self.sample_clock_s) and now_s - self.sample_clock_s > STALE_SAMPLE_S

    def problem(self, now_s: float) -> tuple[str, bool] | None:
        """Why there is no live sample now, as (words, whether it is a failure); None when samples flow."""
        problem = self.link.problem()
        if problem is not None:
            return problem
        if self.link.latest is None:
            return WAITING_LINE, False
        if self.stopped(now_s):
            return STOPPED_LINE, False
        return None

    def is_live(self, now_s: float) -> bool:
        """The newest sample shows the patient now (the tracker runs and the samples flow)."""
        return self.problem(now_s) is None

    # ------------------------------------------------------------------ patient input
    def input_due(self, dt_s: float) -> float | None:
        """After a frame of ``dt_s``: the seconds since the input was last due when it is due again
        (every :data:`INPUT_PERIOD_S`), else None."""
        self._since_sent_s += dt_s
        if self._since_sent_s < INPUT_PERIOD_S - 1e-9:
            return None
        elapsed, self._since_sent_s = self._since_sent_s, 0.0
        return elapsed

    def send(self, value, *, force: bool = False) -> None:
        """Send the simulated patient's input when it changed (or ``force``)."""
        if force or value != self._sent:
            self.link.set_patient_input(value)
            self._sent = value

    def release(self) -> None:
        """Free the avatar's GPU objects (the scene exits)."""
        if self.avatar is not None:
            self.avatar.release()
            self.avatar = None
