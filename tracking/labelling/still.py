"""Whether the patient holds still: the labelling identifies only on a still reference pose.

A frame set is still when nearly every point of it (``share``) has a point of its colour within
``step_m`` in one of the few frame sets before it (the hold's length, at least two). A point that
flickers in and out (a ball seen by two cameras in one frame set and by one in the next, or its
views failing the matching's gates now and then, as they do under MJPEG) finds itself in an
earlier frame set and does not stop the hold; a moving arm's points find no earlier position
within ``step_m`` and do. The patient has held still for ``hold_s`` once that many seconds of
consecutive frame sets were still; :meth:`Stillness.update` returns the share of it done (the
progress the therapist sees).

(Until 2026-11-28 a frame set was compared with the one before alone, both ways: on the
validation population's webcam images, where 5-10 of 14 points are made and their number
changes from frame set to frame set, one point more or less failed the share, and 6 of 12 draws
never saw the hold done although no point moved more than 2 mm; docs/TRACKING.md.)
"""

from __future__ import annotations

from collections import deque

import numpy as np


class Stillness:
    """Counts consecutive still frame sets.

    Args:
        fps: frame sets per second.
        hold_s: how long the pose must be held.
        step_m: largest movement of a point between two frame sets that counts as still
            (measurement noise included: a point moves 1-2 mm between frames when nothing moves).
    """

    def __init__(self, fps: float, hold_s: float = 0.2, step_m: float = 0.006, share: float = 0.85):
        self.frames_needed = max(int(round(hold_s * fps)), 1)
        self.step_m = float(step_m)
        self.share = float(share)
        self.reset()

    def reset(self) -> None:
        self._recent: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=max(self.frames_needed, 2))
        self.count = 0

    def update(self, p_world_m: np.ndarray, colour: np.ndarray) -> float:
        """Add one frame set's points; the share (0..1) of the hold done, 1 when held long enough."""
        p_world_m = np.asarray(p_world_m, dtype=np.float64).reshape(-1, 3)
        colour = np.asarray(colour).reshape(-1)
        finite = np.isfinite(p_world_m).all(axis=1)
        p, c = p_world_m[finite], colour[finite]
        if self._recent and self._still(p, c):
            self.count += 1
        else:
            self.count = 0
        self._recent.append((p, c))
        return min(self.count / self.frames_needed, 1.0)

    def _still(self, p: np.ndarray, c: np.ndarray) -> bool:
        """Whether nearly every point has one of its colour within ``step_m`` in a recent frame set."""
        if len(p) == 0:
            return False
        near = np.zeros(len(p), dtype=bool)
        for p0, c0 in self._recent:
            if len(p0):
                same = c[:, None] == np.asarray(c0)[None, :]
                d = np.where(same, np.linalg.norm(p[:, None, :] - p0[None, :, :], axis=-1), np.inf)
                near |= d.min(axis=1) <= self.step_m
        return bool(np.mean(near) >= self.share)


class Snapshot:
    """The points a labelling was last judged on: while the pose stays as it was (the same number
    of points and single-camera rays of each colour, every point within ``step_m`` of one of its
    colour then), the judgement stands and the fit is not run again (its cost is paid once per
    pose, not every frame set while the patient waits), for at most ``max_age`` frame sets (then
    it is judged again on fresh measurements)."""

    def __init__(self, step_m: float = 0.004, max_age: int = 15):
        self.step_m = float(step_m)
        self.max_age = int(max_age)
        self.reset()

    def reset(self) -> None:
        self._last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._age = 0

    def same(self, p_world_m: np.ndarray, colour: np.ndarray, ray_colour: np.ndarray) -> bool:
        """Whether these points and rays are the snapshot's (then nothing is judged again);
        otherwise they become the snapshot."""
        p_world_m = np.asarray(p_world_m, dtype=np.float64).reshape(-1, 3)
        finite = np.isfinite(p_world_m).all(axis=1)
        p, c = p_world_m[finite], np.asarray(colour).reshape(-1)[finite]
        rays = np.sort(np.asarray(ray_colour).reshape(-1))
        last, self._last = self._last, (p, c, rays)
        self._age += 1
        if last is None or self._age > self.max_age:
            self._age = 0
            return False
        if len(p) != len(last[0]) or not np.array_equal(np.sort(c), np.sort(last[1])) \
                or not np.array_equal(rays, last[2]):
            self._age = 0
            return False
        same = c[:, None] == last[1][None, :]
        d = np.where(same, np.linalg.norm(p[:, None, :] - last[0][None, :, :], axis=-1), np.inf)
        if not len(p) or bool(np.all(d.min(axis=1) <= self.step_m)):
            self._last = last  # (judged on the first: drift is measured from it)
            return True
        self._age = 0
        return False
