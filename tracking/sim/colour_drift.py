"""The lighting-drift experiment: the fixed nominal colour table against the adapted one.

One simulated recording is rendered once; every frame set goes to two trackers, one with the
nominal table (:meth:`tracking.colour.table.ColourTable.build`) and one whose table a
:class:`tracking.colour.adapt.ColourAdapter` learns from the markers it tracks. Both are scored
against the simulator's truth per marker: the shares of frames after identification in which the
marker is measured, estimated or lost, and identity swaps (a marker measured on another marker's
ball, as in :func:`tracking.sim.validate.validate_tracking`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from tracking.colour.adapt import ColourAdapter
from tracking.colour.table import ColourTable
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker, TrackingState

DRIFT_SETTINGS = SimulationSettings(
    motion="shoulder_abduction", rig="ring4", size_px=(320, 240), seconds=10.0,
    brightness_drop=0.4, colour_cast=(1.3, 1.0, 0.7), drift_start_s=1.0, drift_s=6.0,
)
"""The experiment of docs/COLOUR.md: 40 % darker and a warm cast, ramped from 1 s to 7 s."""


@dataclass
class DriftScore:
    """One tracker on the drift recording, filled frame by frame with :meth:`add`.

    Attributes:
        names: marker names.
        identified_at: first frame with names (-1: never).
        status: per frame after identification, (M,) :class:`MarkerStatus` codes (see
            :meth:`shares`).
        swaps: (M,) frames in which the marker was measured on another marker's ball (within
            20 mm of it and more than 20 mm from its own).
    """

    names: list[str]
    identified_at: int = -1
    status: list[np.ndarray] = field(default_factory=list)
    swaps: np.ndarray | None = None

    def add(self, index: int, positions_m: np.ndarray, status: np.ndarray, truth_m: np.ndarray) -> None:
        if self.identified_at < 0:
            self.identified_at = index
            self.swaps = np.zeros(len(self.names), np.int64)
        d = np.linalg.norm(positions_m[:, None, :] - truth_m[None, :, :], axis=-1)
        own = np.diag(d)
        meas = status == MarkerStatus.MEASURED
        with np.errstate(invalid="ignore"):
            swap = meas & (own > 0.02) & (np.nanmin(np.where(np.isfinite(d), d, np.inf), axis=1) < 0.02) & (
                np.argmin(np.where(np.isfinite(d), d, np.inf), axis=1) != np.arange(len(own)))
        self.swaps += swap
        self.status.append(np.asarray(status, np.uint8).copy())

    def shares(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(measured, estimated, lost) per marker, shares of the frames after identification."""
        if not self.status:
            m = len(self.names)
            return np.zeros(m), np.zeros(m), np.ones(m)
        st = np.stack(self.status)
        return ((st == MarkerStatus.MEASURED).mean(0), (st == MarkerStatus.ESTIMATED).mean(0),
                (st == MarkerStatus.LOST).mean(0))

    def unmeasured_at_end(self, frames: int = 15) -> np.ndarray:
        """(M,) bool: markers never measured in the last ``frames`` frame sets."""
        if not self.status:
            return np.ones(len(self.names), bool)
        st = np.stack(self.status[-frames:])
        return ~(st == MarkerStatus.MEASURED).any(axis=0)


@dataclass
class DriftResult:
    """Both trackers on one drift recording, and the adaptation's cost.

    Attributes:
        settings: the simulated recording.
        fixed, adaptive: the two trackers' scores.
        adapt_seconds, adapt_cpu_seconds: (frames,) wall and CPU time of each adaptation call.
        every: learning period in frame sets.
        final_hues_deg: the adapted models' hues at the end.
    """

    settings: SimulationSettings
    fixed: DriftScore
    adaptive: DriftScore
    adapt_seconds: np.ndarray
    adapt_cpu_seconds: np.ndarray
    every: int
    final_hues_deg: list[float]

    def table(self) -> str:
        """A plain-text comparison table, one row per marker."""
        fm, fe, fl = self.fixed.shares()
        am, ae, al = self.adaptive.shares()
        lines = [f"{'marker':7s} | {'fixed: meas  est   lost  swaps':31s} | adaptive: meas  est   lost  swaps",
                 "-" * 80]
        for i, name in enumerate(self.fixed.names):
            lines.append(f"{name:7s} |       {100 * fm[i]:5.1f} {100 * fe[i]:5.1f} {100 * fl[i]:5.1f} {self.fixed.swaps[i]:5d}"
                         f"   |           {100 * am[i]:5.1f} {100 * ae[i]:5.1f} {100 * al[i]:5.1f} {self.adaptive.swaps[i]:5d}")
        lines.append("-" * 80)
        lines.append(f"{'all':7s} |       {100 * fm.mean():5.1f} {100 * fe.mean():5.1f} {100 * fl.mean():5.1f} "
                     f"{int(self.fixed.swaps.sum()):5d}   |           {100 * am.mean():5.1f} {100 * ae.mean():5.1f} "
                     f"{100 * al.mean():5.1f} {int(self.adaptive.swaps.sum()):5d}")
        lines.append(f"unmeasured in the last 0.5 s: fixed {int(self.fixed.unmeasured_at_end().sum())}, "
                     f"adaptive {int(self.adaptive.unmeasured_at_end().sum())} of {len(self.fixed.names)} markers")
        for what, sec in (("wall", self.adapt_seconds), ("CPU", self.adapt_cpu_seconds)):
            s = sec * 1000.0
            lines.append(f"adaptation cost per frame set ({what}): mean {s.mean():.2f} ms, median {np.median(s):.2f} ms, "
                         f"max {s.max():.1f} ms (learning every {self.every} frame sets)")
        return "\n".join(lines)


def run_drift(settings: SimulationSettings = DRIFT_SETTINGS, *, every: int = 60, rate: float = 0.3,
              progress: bool = False) -> DriftResult:
    """Render ``settings`` once and track it with the fixed and the adaptive colour table."""
    studio, motion = studio_from_settings(settings)
    with studio:
        ms = studio.markerset
        fixed = Tracker(studio.cameras, ms, table=ColourTable.build(ms.palette), fps=settings.fps)
        adapter = ColourAdapter(studio.cameras, ms, every=every, rate=rate, seed=settings.seed)
        adaptive = Tracker(studio.cameras, ms, table=adapter.table, fps=settings.fps)
        scores = DriftScore(list(ms.names)), DriftScore(list(ms.names))
        frames = studio.play(motion, settings.fps, seconds=settings.seconds, noise_sigma=settings.noise_sigma,
                             brightness_drop=settings.brightness_drop, colour_cast=settings.colour_cast,
                             seed=settings.seed, with_visibility=False, drift_start_s=settings.drift_start_s,
                             drift_s=settings.drift_s)
        total = studio.n_frames(motion, settings.fps, settings.seconds)
        for sf in tqdm(frames, total=total, unit="frame", desc="lighting drift", leave=False, disable=not progress):
            for tracker, score in zip((fixed, adaptive), scores):
                s = tracker.step(sf.frames.images, sf.frames.time_s)
                if s.state == TrackingState.TRACKING:
                    score.add(s.frame_index, s.positions_m, s.status, sf.markers_m)
                    if tracker is adaptive:
                        adapter.observe(sf.frames.images, s.positions_m, s.status)
    return DriftResult(settings, scores[0], scores[1], np.asarray(adapter.seconds),
                       np.asarray(adapter.cpu_seconds), every, [m.hue_deg for m in adapter.models])
