"""Whether the patient holds still: the labelling identifies only on a still reference pose.

The unlabelled points of consecutive frame sets are compared: a frame set is still when nearly
every point (``share``) has a point of its colour in the one before within ``step_m``, and
nearly every point there one in this frame set (a point that flickers in and out, a ball seen by
two cameras in one frame set and by one in the next, does not stop the hold; a moving arm does). The patient has held still for ``hold_s`` once that many seconds of
consecutive frame sets were still; :meth:`Stillness.update` returns the share of it done (the
progress the therapist sees).
"""

from __future__ import annotations

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
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self.count = 0

    def update(self, p_world_m: np.ndarray, colour: np.ndarray) -> float:
        """Add one frame set's points; the share (0..1) of the hold done, 1 when held long enough."""
        p_world_m = np.asarray(p_world_m, dtype=np.float64).reshape(-1, 3)
        colour = np.asarray(colour).reshape(-1)
        finite = np.isfinite(p_world_m).all(axis=1)
        p, c = p_world_m[finite], colour[finite]
        if self._last is not None and self._same(p, c, *self._last):
            self.count += 1
        else:
            self.count = 0
        self._last = (p, c)
        return min(self.count / self.frames_needed, 1.0)

    def _same(self, p: np.ndarray, c: np.ndarray, p0: np.ndarray, c0: np.ndarray) -> bool:
        if len(p) == 0 or len(p0) == 0:
            return False
        same = np.asarray(c)[:, None] == np.asarray(c0)[None, :]
        d = np.where(same, np.linalg.norm(p[:, None, :] - p0[None, :, :], axis=-1), np.inf)
        now = np.mean(d.min(axis=1) <= self.step_m)
        before = np.mean(d.min(axis=0) <= self.step_m)
        return bool(now >= self.share and before >= self.share)


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
