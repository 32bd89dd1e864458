"""The live avatar for a scene: tracker samples in, the interpolated body drawn in a viewport.

Glue between :mod:`tracking.live` samples and :mod:`game.avatar`: each sample's markers become a
:class:`~game.avatar.skeleton.SkeletonPose` (:class:`~game.avatar.skeleton.SkeletonTracker`), the
poses are kept with the time their frame set was ready (``LiveSample.t_frame_ready_s``,
``time.perf_counter`` of the tracker process, the same clock as the game's) and the pose drawn
at display time ``t`` is interpolated one sample interval behind
(:class:`~game.avatar.interpolate.PoseInterpolator`), so the avatar moves smoothly at the
display's rate from 30 samples per second.
"""

from __future__ import annotations

import numpy as np

from game.avatar.interpolate import PoseInterpolator
from game.avatar.renderer import AvatarRenderer, mirror_view
from game.avatar.skeleton import SkeletonPose, SkeletonTracker

#: A sample whose markers are all unknown (tracker waiting for the reference pose) moves nothing.
MIN_KNOWN_MARKERS = 4


class AvatarView:
    """Skeleton, interpolation and renderer of one avatar.

    Args:
        ctx: the GL context to draw with.
        marker_names: the marker set's names, in sample order.
    """

    def __init__(self, ctx, marker_names) -> None:
        self.skeleton = SkeletonTracker(tuple(marker_names))
        self.poses = PoseInterpolator()
        self.renderer = AvatarRenderer(ctx)
        self.pose: SkeletonPose | None = None

    def push(self, sample) -> None:
        """Add one :class:`tracking.live.LiveSample`."""
        known = np.isfinite(sample.positions_m).all(axis=1)
        if known.sum() < MIN_KNOWN_MARKERS:
            return
        pose = self.skeleton.update(sample.positions_m, sample.status)
        self.poses.push(sample.t_frame_ready_s, pose)

    def reset(self) -> None:
        """Forget the body (a new motion or patient: proportions are learned again)."""
        self.skeleton.reset()
        self.poses.clear()
        self.pose = None

    def pose_at(self, display_time_s: float) -> SkeletonPose | None:
        """The pose to draw at ``display_time_s`` (the game clock, ``time.perf_counter``)."""
        self.pose = self.poses.sample(display_time_s)
        return self.pose

    def camera(self, aspect: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Mirror-view (view, projection) framing the current pose (None before any pose)."""
        return None if self.pose is None else mirror_view(self.pose, aspect)

    def render(self, view: np.ndarray, proj: np.ndarray) -> None:
        """Background and body into the bound framebuffer's viewport (the pose of :meth:`pose_at`)."""
        self.renderer.render_background()
        if self.pose is not None:
            self.renderer.render(self.pose, view, proj)

    def release(self) -> None:
        self.renderer.release()
