"""The 3D view at fewer pixels when the machine is slow: an offscreen target and a controller.

On llvmpipe (OpenGL on the CPU) the avatar's cost is mostly per pixel: shading its surfaces,
the floor and the background. Rendering the 3D view into a smaller framebuffer and drawing it
stretched (linear filtering) over the view costs a fraction of that, while the 2D layer (text,
markers) stays sharp at full resolution. :class:`DynamicScale` picks the fraction from the
measured frame time, the way games keep their frame rate: down when frames take longer than the
budget, back up when there is room.
"""

from __future__ import annotations

import math

import moderngl


class ScaledTarget:
    """An offscreen colour texture + depth buffer, reallocated only when its size changes.

    Args:
        ctx: the GL context.
    """

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.size_px: tuple[int, int] | None = None
        self.texture: moderngl.Texture | None = None
        self._depth = None
        self._fbo = None

    def use(self, size_px: tuple[int, int]) -> None:
        """Bind a framebuffer of ``size_px`` (viewport set to all of it) and clear it."""
        size_px = (max(1, int(size_px[0])), max(1, int(size_px[1])))
        if size_px != self.size_px:
            self.release()
            self.texture = self.ctx.texture(size_px, 4)
            self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
            self.texture.repeat_x = self.texture.repeat_y = False
            self._depth = self.ctx.depth_renderbuffer(size_px)
            self._fbo = self.ctx.framebuffer(color_attachments=[self.texture], depth_attachment=self._depth)
            self.size_px = size_px
        self._fbo.use()
        self.ctx.viewport = (0, 0, *size_px)
        self._fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)

    def release(self) -> None:
        for obj in (self._fbo, self._depth, self.texture):
            if obj is not None:
                obj.release()
        self._fbo = self._depth = self.texture = None
        self.size_px = None


class DynamicScale:
    """The fraction of the 3D view's pixels to render, from the measured time per frame.

    Args:
        budget_ms: the time a frame may take (e.g. 1000 / 60).
        lowest, highest: the range of the scale (linear, per axis).
        step: the scale changes in steps of this much (each change reallocates the target).
        every: frames between decisions (the frame-time mean needs a few frames to follow).
    """

    def __init__(self, budget_ms: float, *, lowest: float = 0.5, highest: float = 1.0, step: float = 0.125,
                 every: int = 30) -> None:
        self.budget_ms = float(budget_ms)
        self.lowest, self.highest, self.step = lowest, highest, step
        self.every = every
        self.scale = highest
        self._frames = 0

    def update(self, work_ms: float) -> float:
        """Account for one frame that took ``work_ms`` on average lately; returns the scale to use."""
        self._frames += 1
        if self._frames < self.every or not math.isfinite(work_ms):
            return self.scale
        self._frames = 0
        if work_ms > 0.9 * self.budget_ms and self.scale > self.lowest:
            self.scale = max(self.lowest, self.scale - self.step)
        elif work_ms < 0.55 * self.budget_ms and self.scale < self.highest:
            self.scale = min(self.highest, self.scale + self.step)
        return self.scale
