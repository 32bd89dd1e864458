"""Dynamic resolution of the 3D view: the share of the window's pixels the 3D pass renders,
chosen each frame from the measured time to make a frame against the frame budget.

Without a GPU (Mesa llvmpipe) a frame's cost is mostly rasterizing, which grows with the pixels;
on a busy machine the rasterizer waits for a core and frames stall. As games do, the 3D view is
then rendered smaller and upscaled (the 2D text stays at full resolution, see
:meth:`game.gfx.screen.Screen.view_3d`). Pure logic, no GL: :class:`RenderScaler` sees frame
times and answers a scale.

The controller: an exponentially smoothed frame time against the budget, with a dead band
between ``lower_at`` and ``raise_at`` (hysteresis). Over the band it lowers at once, in
proportion to the excess (pixels cost ~ scale squared); under it, it raises one small step only
after the frame time has stayed low for ``raise_after`` frames. After a change it waits
``settle_frames`` frames for the smoothed time to show the new cost before it changes again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class ScaleLimits:
    """How :class:`RenderScaler` moves the scale.

    Attributes:
        min_scale: the smallest scale (share of the window's pixels along each axis).
        step: scales are multiples of this (a new framebuffer size only every few percent).
        lower_at: lower when the smoothed frame time exceeds this share of the budget.
        raise_at: raise when it stays under this share of the budget (below ``lower_at``).
        raise_after: frames it must stay under ``raise_at`` before a step up.
        settle_frames: frames after a change before another one.
        smoothing: weight of the newest frame time in the smoothed estimate (0..1).
    """

    min_scale: float = 0.5
    step: float = 0.05
    lower_at: float = 0.9
    raise_at: float = 0.6
    raise_after: int = 45
    settle_frames: int = 8
    smoothing: float = 0.15

    def __post_init__(self) -> None:
        if not (0.0 < self.min_scale <= 1.0 and 0.0 < self.step <= 0.5 and 0.0 < self.raise_at < self.lower_at
                and 0.0 < self.smoothing <= 1.0 and self.raise_after >= 1 and self.settle_frames >= 0):
            raise ValueError("ScaleLimits: need 0 < min_scale <= 1, 0 < raise_at < lower_at, 0 < smoothing <= 1")


class RenderScaler:
    """The 3D view's render scale, following the frame time.

    Args:
        budget_s: the time a frame may take (1 / the target frame rate).
        fixed: a fixed scale (0 < fixed <= 1) instead of the controller; None: dynamic.
        limits: how the scale moves.
    """

    def __init__(self, budget_s: float, *, fixed: float | None = None, limits: ScaleLimits = ScaleLimits()) -> None:
        if not budget_s > 0:
            raise ValueError("RenderScaler: budget_s must be positive")
        if fixed is not None and not 0.0 < fixed <= 1.0:
            raise ValueError("RenderScaler: a fixed scale is in (0, 1]")
        self.budget_s = float(budget_s)
        self.fixed = fixed
        self.limits = limits
        self.scale = 1.0 if fixed is None else float(fixed)
        self.smoothed_s = math.nan
        self._under = 0      # frames in a row under raise_at
        self._settle = 0     # frames left before the next change

    @property
    def dynamic(self) -> bool:
        return self.fixed is None

    def observe(self, frame_s: float) -> float:
        """Account for one frame's time (seconds, without the pacing sleep); returns the scale of
        the next frame."""
        if self.fixed is not None or not math.isfinite(frame_s) or frame_s < 0:
            return self.scale
        lim = self.limits
        a = lim.smoothing
        self.smoothed_s = frame_s if math.isnan(self.smoothed_s) else (1 - a) * self.smoothed_s + a * frame_s
        load = self.smoothed_s / self.budget_s
        self._under = self._under + 1 if load < lim.raise_at else 0
        if self._settle > 0:
            self._settle -= 1
            return self.scale
        if load > lim.lower_at and self.scale > lim.min_scale:
            # pixels cost ~ scale^2: aim at the middle of the band, at least one step down
            target = self.scale * math.sqrt(0.5 * (lim.lower_at + lim.raise_at) / load)
            self._set(min(self._quantize(target), self.scale - lim.step))
        elif self._under >= lim.raise_after and self.scale < 1.0:
            self._set(self.scale + lim.step)
        return self.scale

    def _quantize(self, scale: float) -> float:
        return math.floor(scale / self.limits.step + 1e-9) * self.limits.step

    def _set(self, scale: float) -> None:
        new = min(max(round(scale, 6), self.limits.min_scale), 1.0)
        if new != self.scale:
            self.scale = new
            self._settle = self.limits.settle_frames
            self._under = 0
