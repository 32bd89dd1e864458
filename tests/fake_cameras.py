"""Fake cameras for the frame-source tests: objects with ``cv2.VideoCapture``'s ``read``,
``isOpened`` and ``release``."""

import threading
import time

import numpy as np

from tracking.sim.rigs import load_rig

SIZE = (32, 24)


class FakeDevice:
    """A camera delivering frame k at ``t0 + phase_s + k / fps``.

    ``stop_after``: after this many frames it either hangs in ``read`` until released
    (``mode="hang"``) or reports failure (``mode="fail"``). ``skip``: frame numbers it never
    delivers (a driver dropping frames).
    """

    def __init__(self, t0, fps, *, size=SIZE, phase_s=0.0, stop_after=None, mode="hang", skip=(), frames=None,
                 opened=True):
        self.t0, self.fps, self.size, self.phase_s = t0, fps, size, phase_s
        self.stop_after, self.mode, self.skip, self.frames = stop_after, mode, set(skip), frames
        self.k = 0
        self.opened = opened
        self.released = threading.Event()

    def isOpened(self):
        return self.opened

    def read(self):
        while self.k in self.skip:
            self.k += 1
        if self.stop_after is not None and self.k >= self.stop_after:
            if self.mode == "hang":
                self.released.wait()
            else:
                time.sleep(0.002)
            return False, None
        due = self.t0 + self.phase_s + self.k / self.fps
        delay = due - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        if self.frames is not None:
            img = self.frames[self.k % len(self.frames)]
        else:
            img = np.full((self.size[1], self.size[0], 3), self.k % 256, np.uint8)
        self.k += 1
        return True, img

    def release(self):
        self.released.set()


def cameras(n=3, size=SIZE):
    return load_rig("ring4", size)[:n]


def factory_of(devices):
    """A capture factory handing out the given fake devices by device string ("0", "1", ...)."""
    return lambda device, size_px, fps: devices[int(device)]
