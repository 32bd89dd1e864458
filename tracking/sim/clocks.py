"""Free-running camera clocks and rolling shutters of the simulated studio (what webcams deliver).

Each camera captures on its own clock: frame k of camera c at ``(k (1 + rate_c) + offset_c) / fps``
(``offset_c`` a fraction of a frame period, ``rate_c`` its rate difference, e.g. 0.001 = 0.1 %).
A frame set ``i`` (nominal instant ``i / fps``) joins each camera's capture nearest to it, as a
recorder that groups frames by time does: the phase drifts, and a camera whose phase crosses half
a period gives one image twice (or skips one), as real free-running cameras do.

A rolling shutter exposes row ``v`` (pixel centre coordinate, 0 = top) ``v / H * readout_s``
after the camera's time stamp (the first row's instant). The simulator's approximation: each marker
ball is drawn where it is at the instant of the row of its own centre in that camera; the body
around it is drawn at the instant of the middle row (so a ball can sit up to half the readout's
motion off its skin: a few millimetres on a fast swing, which changes the occlusions only).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from calibration.camera import Camera


@dataclass(frozen=True, slots=True)
class CameraClocks:
    """Timing of each camera of a rig.

    Attributes:
        offsets_frames: (C,) phase of each camera, fractions of a frame period.
        rate_error: (C,) relative rate difference of each camera's clock (0.001: 0.1 % slow).
        readout_s: (C,) rolling-shutter readout (first row to last), seconds; 0: global shutter.
    """

    offsets_frames: tuple[float, ...]
    rate_error: tuple[float, ...]
    readout_s: tuple[float, ...]

    @staticmethod
    def synchronized(n_cameras: int) -> "CameraClocks":
        return CameraClocks((0.0,) * n_cameras, (0.0,) * n_cameras, (0.0,) * n_cameras)

    @staticmethod
    def drawn(n_cameras: int, seed: int, *, offsets: Sequence[float] | None = None, max_offset: float = 0.5,
              drift: float = 0.0, readout_s: float = 0.0) -> "CameraClocks":
        """``offsets`` as given, else drawn uniformly in +-``max_offset`` frame periods; each
        camera's rate difference drawn uniformly in +-``drift``; one readout for all cameras."""
        rng = np.random.default_rng([int(seed), 23])
        off = rng.uniform(-max_offset, max_offset, n_cameras) if offsets is None else np.asarray(offsets, float)
        rate = rng.uniform(-drift, drift, n_cameras) if drift > 0 else np.zeros(n_cameras)
        return CameraClocks(tuple(float(v) for v in off), tuple(float(v) for v in rate),
                            (float(readout_s),) * n_cameras)

    @property
    def synchronous(self) -> bool:
        return not any(self.offsets_frames) and not any(self.rate_error) and not any(self.readout_s)

    def capture_times(self, index: int, fps: float) -> np.ndarray:
        """(C,) instant (seconds) of each camera's image in frame set ``index``: its capture nearest
        to the nominal instant ``index / fps`` (the first row's instant under a rolling shutter)."""
        off = np.asarray(self.offsets_frames)
        scale = 1.0 + np.asarray(self.rate_error)
        k = np.round((index - off) / scale)
        return (k * scale + off) / fps

    def as_meta(self) -> dict:
        """For meta.yaml (the truth of how the cameras were timed)."""
        return {"offsets_frames": [round(v, 6) for v in self.offsets_frames],
                "rate_error": [round(v, 8) for v in self.rate_error],
                "rolling_shutter_s": [round(v, 6) for v in self.readout_s]}


def rolling_marker_positions(cameras: Sequence[Camera], markers_at: Callable[[float], np.ndarray], start_s: float,
                             readout_s: float) -> np.ndarray:
    """(C, M, 3) where each marker is at the instant of its own image row in each camera.

    Args:
        cameras: the cameras; markers_at: instant (s) -> (M, 3) marker centres.
        start_s: (C,) instant of each camera's first row; readout_s: (C,) first row to last row.
    Returns the positions interpolated linearly between the first and the last row's instants
    (two fixed-point passes on the row; a 25 ms readout spans less than a frame period).
    """
    start = np.asarray(start_s, float)
    readout = np.asarray(readout_s, float)
    out = []
    for c, cam in enumerate(cameras):
        p0 = markers_at(float(start[c]))
        if readout[c] <= 0:
            out.append(p0)
            continue
        p1 = markers_at(float(start[c] + readout[c]))
        frac = np.zeros(len(p0))
        for _ in range(3):
            p = p0 + (p1 - p0) * frac[:, None]
            v = cam.project(p)[:, 1]
            frac = np.clip(np.nan_to_num(v / cam.size_px[1], nan=0.5), 0.0, 1.0)
        out.append(p0 + (p1 - p0) * frac[:, None])
    return np.stack(out)
