"""How fast the avatar renders offscreen: frames per second at the game's resolution.

:func:`avatar_fps` replays the simulated patient raising and turning an arm through
:class:`LiveAvatar`: marker samples arrive at 30 Hz (skeleton built from them), every display
frame interpolates the pose for its time stamp, fades the looks, dresses the pose, draws the
background, floor and body into an offscreen framebuffer, and reads the pixels back (which waits for the GPU, here Mesa llvmpipe on the CPU). The figure is therefore
what one game frame of the avatar scene costs, readback included (a window swap costs less).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import moderngl
import numpy as np

from game.avatar.live import LiveAvatar
from tracking.markerset import load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose, reference_pose
from tracking.sim.renderer import create_context

SAMPLE_RATE_HZ = 30.0


def demo_markers(n: int = 60, markerset: str = "upper_limb_seated") -> tuple[tuple[str, ...], list[np.ndarray]]:
    """Marker names and ``n`` frames (M, 3) of one cycle of the simulated patient: the right arm
    rises forward to 150 degrees and back while the forearm turns from pronation to supination
    and the left elbow bends (the first frame is the reference pose)."""
    ms = load_markerset(markerset)
    body = BodyModel(BodyDimensions.from_percentile(50, "male"), ms)
    frames = [body.markers_m(reference_pose())]
    for k in range(1, n):
        s = 0.5 - 0.5 * math.cos(2.0 * math.pi * k / n)
        pose = Pose(
            trunk_lateral_lean_deg=5.0 * s,
            right=ArmPose.clinical(flexion_deg=150.0 * s, elbow_flexion_deg=20.0 + 40.0 * s,
                                   forearm_supination_deg=-80.0 + 160.0 * s),
            left=ArmPose.clinical(abduction_deg=15.0, elbow_flexion_deg=10.0 + 90.0 * s),
        )
        frames.append(body.markers_m(pose))
    return ms.names, frames


@dataclass(frozen=True, slots=True)
class AvatarBench:
    """Result of :func:`bench_avatar`.

    Attributes:
        fps: frames per second (wall clock; shares the machine with whatever else runs).
        cpu_ms_per_frame: CPU time of this process per frame, all threads (llvmpipe renders on
            one thread per core), so ``1000 / cpu_ms_per_frame`` is the rate one free core gives.
        frames: frames timed.
        size: (width, height).
        msaa: samples.
    """

    fps: float
    cpu_ms_per_frame: float
    frames: int
    size: tuple[int, int]
    msaa: int


def avatar_fps(size: tuple[int, int] = (1280, 720), seconds: float = 3.0, *, msaa: int = 0,
               ctx: moderngl.Context | None = None) -> float:
    """Frames per second of the avatar scene rendered offscreen at ``size`` (width, height).

    Args:
        size: framebuffer size in pixels.
        seconds: how long to render (after a few warm-up frames).
        msaa: multisample anti-aliasing samples (0 = off; 4 looks smoother, costs more).
        ctx: a moderngl context to use; by default a standalone EGL context (released after).

    Raises:
        tracking.sim.renderer.OffscreenGLUnavailable: no OpenGL 3.3 offscreen context.
    """
    return bench_avatar(size, seconds, msaa=msaa, ctx=ctx).fps


def bench_avatar(size: tuple[int, int] = (1280, 720), seconds: float = 3.0, *, msaa: int = 0,
                 ctx: moderngl.Context | None = None) -> AvatarBench:
    """:func:`avatar_fps` with the CPU time per frame as well (same arguments)."""
    own = ctx is None
    ctx = create_context() if ctx is None else ctx
    w, h = size
    objs: list = []
    try:
        colour = ctx.renderbuffer((w, h), samples=msaa)
        depth = ctx.depth_renderbuffer((w, h), samples=msaa)
        fbo = ctx.framebuffer(color_attachments=[colour], depth_attachment=depth)
        objs += [colour, depth, fbo]
        target = fbo
        if msaa:
            resolved = ctx.renderbuffer((w, h))
            target = ctx.framebuffer(color_attachments=[resolved])
            objs += [resolved, target]
        names, markers = demo_markers()
        status = np.ones(len(names), np.uint8)
        avatar = LiveAvatar(ctx, names)
        pixels = bytearray(w * h * 3)
        frames = 0
        t_start = c_start = None
        warmup = 5
        t0 = time.perf_counter()
        next_sample = 0
        while True:
            now = time.perf_counter() - t0
            while next_sample / SAMPLE_RATE_HZ <= now:  # the tracker's samples, skeleton included
                avatar.push(next_sample / SAMPLE_RATE_HZ, markers[next_sample % len(markers)], status)
                next_sample += 1
            fbo.use()
            avatar.render((w, h), now)
            if msaa:
                ctx.copy_framebuffer(target, fbo)
            target.read_into(pixels, components=3)
            frames += 1
            if t_start is None and frames == warmup:
                t_start, c_start, frames = time.perf_counter(), time.process_time(), 0
            elif t_start is not None and time.perf_counter() - t_start >= seconds:
                break
        wall, cpu = time.perf_counter() - t_start, time.process_time() - c_start
        avatar.release()
        return AvatarBench(frames / wall, 1000.0 * cpu / frames, frames, (w, h), msaa)
    finally:
        for obj in reversed(objs):
            obj.release()
        if own:
            ctx.release()


if __name__ == "__main__":
    for samples in (0, 4):
        b = bench_avatar(msaa=samples)
        print(f"avatar {b.size[0]}x{b.size[1]} msaa {samples}: {b.fps:.1f} frames/s, "
              f"{b.cpu_ms_per_frame:.1f} ms CPU per frame ({b.frames} frames)")
