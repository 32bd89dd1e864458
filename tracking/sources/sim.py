"""The simulated patient as a frame source: a scripted motion rendered by the virtual cameras."""

from __future__ import annotations

import numpy as np

from tracking.sources.base import SourceFrameSet


class SimulatedSource:
    """Plays a scripted motion once, rendered by the studio (software GL), frame set by frame set.

    The true marker centres come with each frame set (``truth_m``). The live tracker's own
    simulated source (:class:`tracking.live.source.SimSource`) adds the interactive patient and
    loops the motion; this one is for recording and tests.

    Args:
        settings: :class:`tracking.sim.studio.SimulationSettings` (motion, rig, size, fps, body,
            noise, seconds...).
    """

    def __init__(self, settings) -> None:
        from tracking.sim.studio import studio_from_settings

        self.settings = settings
        self.studio, self.motion = studio_from_settings(settings)
        self.cameras = self.studio.cameras
        self.markerset = self.studio.markerset
        self.fps = float(settings.fps)
        self.n_frames = self.studio.n_frames(self.motion, self.fps, settings.seconds)
        self._frames = None
        self._ended = False

    def open(self) -> None:
        if self._frames is None:
            s = self.settings
            self._frames = self.studio.play(self.motion, self.fps, seconds=s.seconds, noise_sigma=s.noise_sigma,
                                            brightness_drop=s.brightness_drop, colour_cast=s.colour_cast,
                                            seed=s.seed, with_visibility=False)

    def read(self) -> SourceFrameSet | None:
        self.open()
        sim = next(self._frames, None)
        if sim is None:
            self._ended = True
            return None
        fs = sim.frames
        c = len(self.cameras)
        return SourceFrameSet(fs.index, fs.time_s, tuple(fs.images), np.full(c, fs.time_s), np.zeros(c, bool),
                              sim.markers_m)

    def warnings(self) -> tuple[str, ...]:
        return ()

    def end_reason(self) -> str:
        return f"the motion {self.settings.motion!r} ended" if self._ended else ""

    def close(self) -> None:
        self._frames = None
        self.studio.close()

    def __enter__(self) -> "SimulatedSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
