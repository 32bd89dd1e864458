"""The avatar of the live patient in one object: tracker samples in, a drawn frame out.

:class:`LiveAvatar` ties the components together the way a game scene uses them: each tracker
sample goes through the :class:`SkeletonTracker` into the :class:`PoseInterpolator`; each display
frame samples the interpolator at the display time, fades the segment looks
(:class:`LookFader`) and draws with :class:`AvatarRenderer` from a mirror camera that stays still
while the patient moves (it is re-aimed only when the patient's seat position or size changes).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence

import moderngl
import numpy as np

from game.avatar.interpolate import LookFader, PoseInterpolator
from game.avatar.renderer import AvatarRenderer, AvatarStyle, mirror_view
from game.avatar.skeleton import SEGMENTS, SkeletonPose, SkeletonTracker

# The camera is re-aimed when the pelvis moved this far or the stature estimate changed this much.
_REAIM_M = 0.08
_REAIM_STATURE = 0.03


class LiveAvatar:
    """Skeleton, interpolation, look fading, camera and renderer of one patient's avatar.

    Args:
        ctx: the moderngl context (OpenGL 3.3 core or later).
        marker_names: the marker set's names (``LiveTracker.markerset.names``).
        roles: role -> marker name (``MarkerSet.roles``); None: the ``upper_limb_seated`` names.
        style: colours and strengths of the look.
        yaw_deg: camera turn about the vertical towards the patient's right (0 = straight front).
        mirror: show the avatar as the patient's mirror image.
    """

    def __init__(self, ctx: moderngl.Context, marker_names: Sequence[str], *, roles: Mapping[str, str] | None = None,
                 style: AvatarStyle = AvatarStyle(), yaw_deg: float = 20.0, mirror: bool = True) -> None:
        self.skeleton = SkeletonTracker(marker_names, roles=roles)
        self.interpolator = PoseInterpolator()
        self.fader = LookFader(len(SEGMENTS))
        self.renderer = AvatarRenderer(ctx, style)
        self.yaw_deg, self.mirror = float(yaw_deg), bool(mirror)
        self._camera: tuple[np.ndarray, np.ndarray] | None = None
        self._camera_key: tuple[np.ndarray, float, float] | None = None  # pelvis, stature, aspect
        self._prepared = None  # (size, pose, PreparedAvatar) of the next render

    def reset(self) -> None:
        """Forget the patient (a new patient, or the tracker identified the markers again)."""
        self.skeleton.reset()
        self.interpolator.clear()
        self.fader.reset()
        self._camera = self._camera_key = None
        self._prepared = None

    def push(self, time_s: float, positions_m: np.ndarray, status: np.ndarray) -> SkeletonPose:
        """One tracker sample: (M, 3) positions (NaN lost), (M,) MarkerStatus, its time stamp
        (``LiveSample.t_frame_ready_s``, the clock of :func:`time.perf_counter`)."""
        pose = self.skeleton.update(positions_m, status)
        self.interpolator.push(time_s, pose)
        return pose

    def push_sample(self, sample) -> SkeletonPose:
        """:meth:`push` from a ``tracking.live.LiveSample`` (or anything with its three fields)."""
        return self.push(sample.t_frame_ready_s, sample.positions_m, sample.status)

    def camera(self, pose: SkeletonPose, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        """The (view, proj) for ``pose``, kept still unless the patient moved seat or size."""
        key = (pose.joint("pelvis"), pose.proportions.stature_m, float(aspect))
        old = self._camera_key
        if (self._camera is None or old is None or old[2] != key[2]
                or np.linalg.norm(old[0] - key[0]) > _REAIM_M or abs(old[1] / key[1] - 1.0) > _REAIM_STATURE):
            self._camera = mirror_view(pose, aspect, yaw_deg=self.yaw_deg, mirror=self.mirror)
            self._camera_key = key
        return self._camera

    def prepare(self, size: tuple[int, int], display_time_s: float | None = None) -> SkeletonPose | None:
        """The CPU side of :meth:`render` for the frame at ``display_time_s`` (no GL calls): the
        interpolated pose, its camera and its solids, kept for the next :meth:`render` of the same
        size. Returns the pose (None before the first sample)."""
        now = time.perf_counter() if display_time_s is None else float(display_time_s)
        pose = self.interpolator.sample(now)
        if pose is None:
            self._prepared = None
            return None
        view, proj = self.camera(pose, size[0] / size[1])
        looks = self.fader.update(pose.state, now)
        self._prepared = (tuple(size), pose, self.renderer.prepare(pose, view, proj, looks=looks))
        return pose

    def render(self, size: tuple[int, int], display_time_s: float | None = None, *, background: bool = True,
               floor: bool = True) -> SkeletonPose | None:
        """Draw the avatar as it should look at ``display_time_s`` into the bound framebuffer:
        what :meth:`prepare` made for this size if it was called since the last render (its
        time then counts, not ``display_time_s``), else prepared now.

        Args:
            size: (width, height) of the viewport, for the aspect ratio.
            display_time_s: the frame's time (default: now, :func:`time.perf_counter`).
            background: draw the background gradient first (it also resets the depth buffer;
                without it, clear colour and depth yourself).
            floor: draw the floor disc.
        Returns:
            The pose drawn, or None before the first sample (nothing is drawn but the background).
        """
        if self._prepared is None or self._prepared[0] != tuple(size):
            self.prepare(size, display_time_s)
        prepared, self._prepared = self._prepared, None
        if background:
            self.renderer.render_background()
        if prepared is None:
            return None
        _, pose, ready = prepared
        self.renderer.draw(ready, floor=floor)
        return pose

    def release(self) -> None:
        self.renderer.release()
