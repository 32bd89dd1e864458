"""A ROM test on the simulated patient, through the real pipeline (``rehab rom-test --source sim``).

The simulator renders the motion (:mod:`tracking.sim.studio`), the :class:`tracking.tracker.Tracker`
measures the images (never the truth) and a :class:`game.rom.session.RomTestSession` runs the test
on its samples, exactly as the live scene does. The truth (joint angles of the simulator's true
markers) is kept beside each attempt for tests and the accuracy table only.

The simulator is imported when a run starts (it needs OpenGL), not with this module.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from calibration.errors import RehabError
from game.rom.session import RomProgress, RomResult, RomState, RomTestSession
from game.rom.spec import RomTest
from tracking.angles import joint_angles


@dataclass(frozen=True, slots=True)
class SimAttempt:
    """One finished attempt of a simulated ROM test.

    Attributes:
        result: what the session measured (from the tracker).
        true_max_deg: the maximum of the test value computed from the simulator's true markers over
            the same recording samples.
        accepted: whether the decision callback accepted it.
    """

    result: RomResult
    true_max_deg: float
    accepted: bool

    @property
    def error_deg(self) -> float:
        return self.result.max_deg - self.true_max_deg


@dataclass(frozen=True, slots=True)
class SimRun:
    """A simulated ROM test run: its attempts, the frames processed and the wall time.

    ``motion_start_s``: the sample time minus the motion's own time at "go" (the pauses before
    it); 0 without pauses, NaN when the session never said "go".
    """

    test: str
    side: str
    motion: str
    attempts: tuple[SimAttempt, ...]
    frames: int
    motion_s: float
    wall_s: float
    last: RomProgress
    motion_start_s: float = 0.0

    @property
    def accepted(self) -> SimAttempt | None:
        return next((a for a in self.attempts if a.accepted), None)


def run_simulated_test(test: RomTest, side: str, standard: str, *, motion: str | None = None, rig: str = "ring4",
                       size_px: tuple[int, int] = (320, 240), fps: float = 30.0, percentile: float = 50.0,
                       sex: str = "female", noise_sigma: float = 1.5, seed: int = 0, donning: int | None = None,
                       wait_for_go_s: float | None = None, max_attempts: int = 1,
                       decide: Callable[[RomResult], bool] = lambda r: not r.compensated,
                       on_progress: Callable[[RomProgress], None] | None = None) -> SimRun:
    """Run a ROM test on the simulated patient performing ``motion`` (default: the test's own motion).

    Each finished attempt goes to ``decide`` (the therapist's accept/discard); a discarded attempt
    is followed by another (the patient repeats) until one is accepted, ``max_attempts`` are done or
    the motion ends. Rendering stops as soon as the run is over. ``donning`` puts the markers on
    again with a placement error of that seed (:mod:`tracking.sim.redonning`; None: on their
    landmarks). With ``wait_for_go_s`` the patient holds still while the tracker names the
    markers and while the start position is being held, as a patient told to hold still does, for
    at most that long in all; by default the scripted motion plays without waiting for the session.

    Raises:
        RehabError: no motion for this test and side, or an unknown motion/rig.
    """
    from tracking.sim.studio import SimulationSettings, studio_from_settings  # lazy: only to run the simulated patient
    # lazy: the tracker only with the simulated patient (the game imports this module)
    from tracking.tracker import Tracker

    name = motion or test.simulated_motion.get(side)
    if not name:
        raise RehabError(f"the test {test.name} has no simulated motion for the {side} side: give --motion NAME")
    settings = SimulationSettings(motion=name, rig=rig, size_px=size_px, fps=fps, percentile=percentile, sex=sex,
                                  noise_sigma=noise_sigma, seed=seed)
    t_start = time.perf_counter()
    studio, mot = studio_from_settings(settings)
    attempts: list[SimAttempt] = []
    frames = 0
    with studio:
        if donning is not None:
            from tracking.sim.redonning import redon  # lazy: only to run the simulated patient

            redon(studio, donning)
        names = studio.markerset.names
        tracker = Tracker(studio.cameras, studio.markerset, fps=fps)
        session = RomTestSession(test, side, standard, names)
        truth: list[float] = []
        progress = session.progress
        go_s = [0.0 if wait_for_go_s is None else math.nan]

        def patient_frames():
            """The frames of a patient who holds still while the tracker names the markers and
            while the start position is held, and otherwise follows the script (seeded as
            ``studio.play``); the pauses add up to at most ``wait_for_go_s``."""
            i, motion_t, paused_s = 0, 0.0, 0.0
            while motion_t <= mot.duration_s:
                t = i / fps
                state = session.state
                if math.isnan(go_s[0]) and state >= RomState.RECORDING:
                    go_s[0] = t - motion_t
                yield studio.render(mot.pose_at(motion_t), i, t, noise_sigma=noise_sigma, seed=seed * 1_000_003 + i,
                                    with_visibility=False)
                i += 1
                state = session.state   # after the tracker and the session have seen this frame
                holding = state == RomState.WAITING_TRACKER or (
                    state == RomState.CHECKING_START and session.progress.hold_fraction > 0.0)
                if holding and paused_s < wait_for_go_s:
                    paused_s += 1.0 / fps
                else:
                    motion_t += 1.0 / fps

        frame_sets = (studio.play(mot, fps, noise_sigma=noise_sigma, seed=seed, with_visibility=False)
                      if wait_for_go_s is None else patient_frames())
        for sf in frame_sets:
            frames += 1
            sample = tracker.step(sf.frames.images, sf.frames.time_s)
            was = session.state
            progress = session.feed(sample)
            if on_progress is not None:
                on_progress(progress)
            if progress.state == RomState.RECORDING or (was == RomState.RECORDING and progress.state == RomState.DONE):
                true_value = float(joint_angles(sf.markers_m, names)[test.angle_name(side)])
                truth.append(test.direction * true_value)
            elif progress.state != RomState.DONE:
                truth.clear()
            if progress.state == RomState.DONE:
                result = session.result
                ok = bool(decide(result))
                attempts.append(SimAttempt(result, float(np.nanmax(truth)) if truth else math.nan, ok))
                truth.clear()
                if ok:
                    session.accept()
                    break
                if len(attempts) >= max_attempts:
                    break
                session.discard()
        else:
            progress = session.finish()
            if progress.state == RomState.DONE and session.result is not None:
                result = session.result
                ok = bool(decide(result))
                attempts.append(SimAttempt(result, float(np.nanmax(truth)) if truth else math.nan, ok))
                if ok:
                    session.accept()
    return SimRun(test.name, side, name, tuple(attempts), frames, frames / fps, time.perf_counter() - t_start, progress,
                  go_s[0])
