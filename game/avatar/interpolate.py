"""Smooth avatar motion at the display rate from tracker samples at 15-30 Hz (pure numpy).

The tracker publishes a pose every 33-67 ms; the display shows 60+ frames per second. Drawing the
newest pose as is makes the avatar step. :class:`PoseInterpolator` keeps the last few poses with
their time stamps and shows the body as it was one sample interval ago, interpolated between the
two samples around that instant: joint positions linearly, segment rotations by slerp. Both are
convex (every interpolated joint lies on the segment between its two samples; every rotation on
the geodesic between them), so the avatar never overshoots a measured pose; when the tracker is
late the newest pose is held, never extrapolated. The price is one sample interval of latency
(33 ms at 30 Hz) plus the wait for the next sample.

Time stamps: any clock shared by the samples and the display, e.g. ``time.perf_counter()`` in
both processes (``LiveSample.t_frame_ready_s``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import numpy as np

from game.avatar.skeleton import SkeletonPose
from tracking.marker_status import MarkerStatus


def _quat_from_matrix(r: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations -> (..., 4) unit quaternions (w, x, y, z), numerically safe branch."""
    m = np.asarray(r, dtype=np.float64)
    tr = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    # Candidates 4 w^2, 4 x^2, 4 y^2, 4 z^2; build from the largest (Shepperd's method).
    cand = np.stack([1 + tr, 1 + 2 * m[..., 0, 0] - tr, 1 + 2 * m[..., 1, 1] - tr, 1 + 2 * m[..., 2, 2] - tr], -1)
    k = np.argmax(cand, axis=-1)
    s = np.sqrt(np.maximum(np.take_along_axis(cand, k[..., None], -1)[..., 0], 1e-300))
    q = np.empty(m.shape[:-2] + (4,))
    a, b_, c = m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]
    d, e, f = m[..., 1, 0] + m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 2, 1] + m[..., 1, 2]
    rows = [
        np.stack([s * s, a, b_, c], -1),
        np.stack([a, s * s, d, e], -1),
        np.stack([b_, d, s * s, f], -1),
        np.stack([c, e, f, s * s], -1),
    ]
    for i in range(4):
        sel = k == i
        q[sel] = rows[i][sel] / (2.0 * s[sel][..., None])
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _matrix_from_quat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def slerp_frames(r0: np.ndarray, r1: np.ndarray, w: float) -> np.ndarray:
    """Geodesic interpolation of rotations: (..., 3, 3), (..., 3, 3), w in [0, 1] -> (..., 3, 3).

    w = 0 gives r0, w = 1 gives r1; the result turns from r0 by ``w`` times the (shortest)
    angle between them, about their relative axis.
    """
    return _slerp_quats(_quat_from_matrix(r0), _quat_from_matrix(r1), w)


def _slerp_quats(q0: np.ndarray, q1: np.ndarray, w: float) -> np.ndarray:
    """:func:`slerp_frames` of rotations given as unit quaternions (..., 4)."""
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where((dot < 0)[..., None], -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-6
    safe = np.where(small, 1.0, sin)
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / safe)
    b = np.where(small, w, np.sin(w * theta) / safe)
    q = a[..., None] * q0 + b[..., None] * q1
    return _matrix_from_quat(q / np.linalg.norm(q, axis=-1, keepdims=True))


def lerp_pose(a: SkeletonPose, b: SkeletonPose, w: float, quats: tuple[np.ndarray, np.ndarray] | None = None) -> SkeletonPose:
    """The pose a fraction ``w`` (clipped to 0..1) of the way from ``a`` to ``b``.

    Joints move linearly, segment frames by slerp; the state and the proportions are those of
    the nearer pose (the state of a segment switches at the midpoint, not gradually).
    ``quats``: the two poses' frames as unit quaternions, if known (saves converting them).
    """
    w = float(min(max(w, 0.0), 1.0))
    near = a if w < 0.5 else b
    q0, q1 = quats if quats is not None else (_quat_from_matrix(a.frames), _quat_from_matrix(b.frames))
    return replace(
        near,
        joints_m=(1.0 - w) * a.joints_m + w * b.joints_m,
        frames=_slerp_quats(q0, q1, w),
    )


class PoseInterpolator:
    """Time-stamped poses in, the pose to show at a display time out.

    Args:
        capacity: poses kept (a few sample intervals are enough).
        min_delay_s, max_delay_s: bounds of the display delay (one sample interval, estimated
            as the median of the recent intervals).
    """

    def __init__(self, capacity: int = 8, *, min_delay_s: float = 1.0 / 120.0, max_delay_s: float = 0.2) -> None:
        if capacity < 2:
            raise ValueError(f"capacity must be at least 2, got {capacity}")
        # (time, pose, its frames as quaternions: converted once per sample, not per frame)
        self._samples: deque[tuple[float, SkeletonPose, np.ndarray]] = deque(maxlen=capacity)
        self._min_delay, self._max_delay = min_delay_s, max_delay_s

    def clear(self) -> None:
        self._samples.clear()

    def __len__(self) -> int:
        return len(self._samples)

    def push(self, time_s: float, pose: SkeletonPose) -> None:
        """Add the pose sampled at ``time_s``; a sample not newer than the newest is ignored."""
        if self._samples and time_s <= self._samples[-1][0]:
            return
        self._samples.append((float(time_s), pose, _quat_from_matrix(pose.frames)))

    @property
    def delay_s(self) -> float:
        """How far behind the display time the shown pose is: one sample interval."""
        if len(self._samples) < 2:
            return self._min_delay
        times = np.array([t for t, _, _ in self._samples])
        return float(np.clip(np.median(np.diff(times)), self._min_delay, self._max_delay))

    def sample(self, display_time_s: float) -> SkeletonPose | None:
        """The pose to draw at ``display_time_s``; None before the first :meth:`push`."""
        if not self._samples:
            return None
        t = display_time_s - self.delay_s
        samples = self._samples
        if t >= samples[-1][0]:
            return samples[-1][1]
        if t <= samples[0][0]:
            return samples[0][1]
        for (t0, p0, q0), (t1, p1, q1) in zip(list(samples)[-2::-1], list(samples)[::-1]):
            if t0 <= t:
                return lerp_pose(p0, p1, (t - t0) / (t1 - t0), (q0, q1))
        return samples[0][1]


def state_looks(state: np.ndarray) -> np.ndarray:
    """(S,) uint8 :class:`MarkerStatus` per segment -> (S, 2) float32 amounts 0/1 of the estimated
    and the lost look (what :class:`game.avatar.renderer.AvatarRenderer` draws)."""
    st = np.asarray(state)
    return np.stack([st == MarkerStatus.ESTIMATED, st == MarkerStatus.LOST], axis=1).astype(np.float32)


class LookFader:
    """Fades each segment's estimated/lost look in and out instead of switching it.

    A marker that flickers between measured and estimated would make its segment blink amber at
    the sample rate; patients watch the avatar, so the look approaches its target exponentially
    with time constant ``tau_s`` (~0.15 s: a real change shows within a few tenths of a second,
    one-sample flickers barely tint). Pure numpy, stateful.

    Args:
        n_segments: number of segments (``len(SEGMENTS)``).
        tau_s: time constant of the fade.
    """

    def __init__(self, n_segments: int, tau_s: float = 0.15) -> None:
        if tau_s <= 0:
            raise ValueError(f"tau_s must be positive, got {tau_s}")
        self._tau = float(tau_s)
        self._looks: np.ndarray | None = None
        self._n = int(n_segments)
        self._time: float | None = None

    def reset(self) -> None:
        self._looks = None
        self._time = None

    def update(self, state: np.ndarray, time_s: float) -> np.ndarray:
        """The looks to draw at ``time_s`` for segment states ``state``.

        Args:
            state: (S,) uint8 :class:`MarkerStatus` per segment (the shown pose's ``state``).
            time_s: display time, seconds (any monotonic clock).
        Returns:
            (S, 2) float32 amounts 0..1 of the estimated and the lost look.
        """
        st = np.asarray(state)
        if st.shape != (self._n,):
            raise ValueError(f"state must be ({self._n},), got {st.shape}")
        target = state_looks(st).astype(np.float64)
        if self._looks is None or self._time is None:
            self._looks = target
        else:
            dt = max(float(time_s) - self._time, 0.0)
            self._looks = target + (self._looks - target) * np.exp(-dt / self._tau)
        self._time = float(time_s)
        return self._looks.astype(np.float32)
