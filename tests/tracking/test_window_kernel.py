"""The compiled window kernel gives the numpy path's results to the bit."""

import numpy as np
import pytest

from tracking import window_kernel
from tracking.colour_table import ColourTable
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.tracker import Tracker

needs_numba = pytest.mark.skipif(not window_kernel.AVAILABLE, reason="numba is not installed")

PALETTE = np.array([(255, 214, 0), (0, 200, 70), (225, 0, 210)], dtype=np.uint8)


def _scene(rng, h=120, w=160):
    """A noisy grey image with discs of the palette's colours, shaded."""
    img = rng.integers(40, 120, (h, w, 3)).astype(np.uint8)
    yy, xx = np.mgrid[0:h, 0:w]
    for i in range(12):
        cx, cy, r = rng.integers(0, w), rng.integers(0, h), rng.integers(2, 9)
        disc = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
        shade = rng.uniform(0.5, 1.0)
        img[disc] = (PALETTE[i % 3][::-1] * shade).astype(np.uint8)
    return img


def _numpy_moments(table, images, cam, boxes, label):
    """The numpy path's counts, sums and coordinates for the same windows (the tracker's code)."""
    labels, starts = table.classify_windows(images, cam, boxes)
    count, sums, cols, rows = [], [], [], []
    for k, (x0, y0, x1, y1) in enumerate(boxes):
        win = labels[starts[k]:starts[k + 1]].reshape(y1 - y0, x1 - x0)
        r, c = np.nonzero(win == label[k])
        c, r = c.astype(float), r.astype(float)
        count.append(c.size)
        sums.append([c.sum(), r.sum(), (c * c).sum(), (r * r).sum(), (c * r).sum()])
        cols.append(c)
        rows.append(r)
    return np.array(count), np.array(sums).T, np.concatenate(cols), np.concatenate(rows)


@needs_numba
@pytest.mark.parametrize("bits", [8, 6])
def test_kernel_equals_the_table_look_up_and_moments(bits):
    rng = np.random.default_rng(3)
    table = ColourTable.build(PALETTE, bits=bits)
    images = [_scene(rng) for _ in range(3)]
    k = 40
    cam = rng.integers(0, 3, k)
    x0, y0 = rng.integers(0, 150, k), rng.integers(0, 110, k)
    boxes = np.stack([x0, y0, np.minimum(x0 + rng.integers(0, 30, k), 160), np.minimum(y0 + rng.integers(0, 30, k), 120)], axis=1)
    label = rng.integers(1, 4, k)
    got = window_kernel.window_moments(images, table.lut, cam, boxes, label, table.bits)
    ref = window_kernel.window_moments_py(images, table.lut, cam, boxes, label, table.bits)
    want = _numpy_moments(table, images, cam, boxes, label)
    assert want[0].sum() > 50, "the windows must hold pixels of the colours"
    for a, b, c in zip(got, ref, want):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


def test_only_plain_images_go_to_the_kernel():
    img = np.zeros((10, 12, 3), dtype=np.uint8)
    assert window_kernel.usable([img, img]) == window_kernel.AVAILABLE
    assert not window_kernel.usable([img, img[:, ::-1]])  # a flipped view: the numpy path
    assert not window_kernel.usable([img[..., 0:1]])


@needs_numba
def test_tracker_is_the_same_with_and_without_the_kernel():
    studio, motion = studio_from_settings(SimulationSettings(motion="reach", size_px=(320, 240), fps=15.0))
    with studio:
        compiled = Tracker(studio.cameras, studio.markerset, fps=15.0)
        plain = Tracker(studio.cameras, studio.markerset, fps=15.0, compiled=False)
        for i, sf in enumerate(studio.play(motion, 15.0, seconds=2.0, noise_sigma=1.5)):
            a = compiled.step(sf.frames.images, sf.frames.time_s)
            b = plain.step(sf.frames.images, sf.frames.time_s)
            np.testing.assert_array_equal(a.positions_m, b.positions_m)
            np.testing.assert_array_equal(a.status, b.status)
    assert i >= 20
