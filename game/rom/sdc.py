"""The smallest detectable change (SDC) of a ROM test, and what a change between sessions means.

A change between two sessions is real only when it is larger than what repeating the measurement
on an unchanged patient gives. With the standard error of measurement SEM (the spread of repeated
results of one patient whose range has not changed), the difference of two sessions has the
spread ``sqrt(2) * SEM``, and ``SDC95 = 1.96 * sqrt(2) * SEM`` is the change that measurement
error alone exceeds in only 5 % of pairs.

:func:`measure_sdc` measures it on the simulated patient through the real pipeline (rendered
frames, the tracker, the ROM test session): every draw is a new session with new sensor noise and
the markers put on again (:mod:`tracking.sim.redonning`), while the patient's movement is the
same. The result is stored in the test's content file (``sdc:``) and the figures in docs/ROM.md.
:func:`change_words` says in words whether a change is beyond it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

from game.rom.simulated import run_simulated_test
from game.rom.spec import RomTest
from tracking.angles import joint_angles
from tracking.markerset import load_markerset

#: 1.96 * sqrt(2): SDC95 = SDC_FACTOR * SEM
SDC_FACTOR = 1.96 * math.sqrt(2.0)


@dataclass(frozen=True, slots=True)
class SdcEstimate:
    """SEM and SDC95 from repeated results of one unchanged patient.

    Attributes:
        n: results used.
        mean_deg, sd_deg: their mean and standard deviation (ddof 1) = the SEM.
        sem_deg: the standard error of measurement (= ``sd_deg``: every draw has the same truth).
        sem_ci_deg: its 95 % confidence interval (chi-square, n - 1 degrees of freedom).
        sdc95_deg: ``1.96 * sqrt(2) * sem_deg``.
        min_deg, max_deg: the smallest and largest result.
    """

    n: int
    mean_deg: float
    sd_deg: float
    sem_deg: float
    sem_ci_deg: tuple[float, float]
    sdc95_deg: float
    min_deg: float
    max_deg: float


def sdc_from_results(values_deg: Iterable[float]) -> SdcEstimate:
    """SEM and SDC95 of repeated results (degrees) of one patient whose range did not change.

    Raises:
        ValueError: fewer than 3 finite results.
    """
    from scipy.stats import chi2  # lazy: scipy.stats (0.8 s to import) only to compute the SDC

    v = np.asarray([x for x in values_deg if math.isfinite(x)], dtype=np.float64)
    if v.size < 3:
        raise ValueError(f"{v.size} results: the SDC needs at least 3")
    n = int(v.size)
    sd = float(np.std(v, ddof=1))
    lo = sd * math.sqrt((n - 1) / chi2.ppf(0.975, n - 1))
    hi = sd * math.sqrt((n - 1) / chi2.ppf(0.025, n - 1))
    return SdcEstimate(n, float(v.mean()), sd, sd, (lo, hi), SDC_FACTOR * sd, float(v.min()), float(v.max()))


@dataclass(frozen=True, slots=True)
class SdcDraw:
    """One simulated session of the SDC measurement.

    Attributes:
        seed: the draw's seed (sensor noise and donning).
        value_deg: the measured maximum (NaN when the test did not finish).
        true_deg: the maximum from the simulator's true markers (NaN likewise).
        message: why the test did not finish ("" when it did).
        wall_s: how long the draw took.
    """

    seed: int
    value_deg: float
    true_deg: float
    message: str
    wall_s: float


@dataclass(frozen=True, slots=True)
class SdcMeasurement:
    """The draws of one test and side, and the estimate from the finished ones (None: fewer than 3)."""

    test: str
    side: str
    draws: tuple[SdcDraw, ...]
    estimate: SdcEstimate | None

    @property
    def failed(self) -> int:
        return sum(1 for d in self.draws if not math.isfinite(d.value_deg))


def motion_peak_s(test: RomTest, side: str, fps: float = 30.0) -> tuple[float, float]:
    """When the test's simulated motion is at its peak: the first and last time its test value
    (true markers, no rendering) is within :data:`PEAK_BAND_DEG` of its largest value (a motion
    holds its peak a moment, and the recorded maximum may fall anywhere in that hold)."""
    from tracking.sim.body import BodyDimensions, BodyModel  # lazy: only to run the simulated patient
    from tracking.sim.motions import load_motion  # lazy: only to run the simulated patient
    from tracking.sim.studio import SimulationSettings  # lazy: only to run the simulated patient

    settings = SimulationSettings()
    dims = BodyDimensions.from_percentile(settings.percentile, settings.sex)
    markerset = load_markerset(settings.markerset)
    body = BodyModel(dims, markerset)
    motion = load_motion(test.simulated_motion[side], dims)
    times = motion.times(fps)
    values = [test.direction * joint_angles(body.markers_m(motion.pose_at(t)), markerset.names)[test.angle_name(side)]
              for t in times]
    at_peak = np.flatnonzero(np.asarray(values) >= np.nanmax(values) - PEAK_BAND_DEG)
    return float(times[at_peak[0]]), float(times[at_peak[-1]])


#: the longest the simulated patient holds the start pose waiting for "go" before the draw fails
WAIT_S = 10.0
#: the motion's peak: where its test value is within this of the largest value
PEAK_BAND_DEG = 5.0
#: a recorded maximum further than this outside the motion's peak caught another part of the motion
PEAK_TOLERANCE_S = 0.5


def measure_sdc(test: RomTest, side: str, seeds: Iterable[int], *, size_px: tuple[int, int] = (320, 240),
                fps: float = 30.0, noise_sigma: float = 1.5, rig: str = "ring4", wait_s: float = WAIT_S,
                on_draw: Callable[[SdcDraw], None] | None = None) -> SdcMeasurement:
    """Repeat ``test`` on the simulated patient once per seed (new noise, markers put on again).

    The patient, its movement and the cameras stay the same: only what changes between two
    sessions of an unchanged patient changes. Each draw runs the renderer, the tracker and the
    ROM test session (:func:`game.rom.simulated.run_simulated_test`); the attempt is taken
    whether or not it was flagged for compensation (the flags are the therapist's decision, the
    number is what is measured). The patient holds the start pose until the session says "go"
    (at most ``wait_s``; a draw whose start position is never recognised fails with the session's
    reason, e.g. a marker put on so far off that the start angle is outside the start window). A
    draw whose recorded maximum is not the motion's peak is counted as failed with the reason.
    """
    peak_from_s, peak_to_s = motion_peak_s(test, side, fps)
    draws = []
    for seed in seeds:
        t0 = time.perf_counter()
        run = run_simulated_test(test, side, "jarm", size_px=size_px, fps=fps, noise_sigma=noise_sigma, rig=rig,
                                 seed=int(seed), donning=int(seed), wait_for_go_s=wait_s, decide=lambda r: True)
        got = run.accepted
        if got is None:
            draw = SdcDraw(int(seed), math.nan, math.nan, run.last.message or "the test did not finish",
                           time.perf_counter() - t0)
        elif not peak_from_s - PEAK_TOLERANCE_S <= got.result.max_time_s - run.motion_start_s \
                <= peak_to_s + PEAK_TOLERANCE_S:
            draw = SdcDraw(int(seed), math.nan, float(got.true_max_deg),
                           f"the recording missed the movement's peak (maximum {got.result.max_deg:.1f} degrees "
                           f"{got.result.max_time_s - run.motion_start_s:.1f} s into the motion, the peak is "
                           f"{peak_from_s:.1f}-{peak_to_s:.1f} s)", time.perf_counter() - t0)
        else:
            draw = SdcDraw(int(seed), float(got.result.max_deg), float(got.true_max_deg), "", time.perf_counter() - t0)
        draws.append(draw)
        if on_draw is not None:
            on_draw(draw)
    values = [d.value_deg for d in draws if math.isfinite(d.value_deg)]
    estimate = sdc_from_results(values) if len(values) >= 3 else None
    return SdcMeasurement(test.name, side, tuple(draws), estimate)


# --------------------------------------------------------------------------------- words
def _deg(x: float) -> str:
    return f"{x:.0f} degree" + ("" if round(abs(x)) == 1 else "s")


def change_words(change_deg: float, sdc_deg: float | None) -> str:
    """A change between two sessions in words, judged against the test's SDC.

    ``+8 degrees: within the measurement's smallest detectable change of 9 degrees — not a real
    change yet``; beyond it: ``+12 degrees: beyond the smallest detectable change of 9 degrees — a
    real change``. Without a measured SDC the words say so instead of judging.
    """
    sign = "+" if change_deg > 0 else "-" if change_deg < 0 else "\u00b1"
    amount = f"{sign}{_deg(abs(change_deg))}"
    if sdc_deg is None:
        return f"{amount} (no smallest detectable change measured for this test: not judged)"
    if abs(change_deg) <= sdc_deg:
        return (f"{amount}: within the measurement's smallest detectable change of {_deg(sdc_deg)} "
                f"\u2014 not a real change yet")
    what = "a real improvement" if change_deg > 0 else "a real loss"
    return f"{amount}: beyond the smallest detectable change of {_deg(sdc_deg)} \u2014 {what}"


def is_real_change(change_deg: float, sdc_deg: float | None) -> bool | None:
    """True beyond the SDC, False within it, None when no SDC was measured."""
    return None if sdc_deg is None else abs(change_deg) > sdc_deg
