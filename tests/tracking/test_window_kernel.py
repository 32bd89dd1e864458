"""The compiled kernels (search windows, triangulation) give the numpy paths' results."""

import numpy as np
import pytest

from tracking import window_kernel
from tracking.colour.table import ColourTable
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.tracker import Tracker
from tracking.triangulation import Triangulator, _triangulate_loop

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
    x1, y1 = np.minimum(x0 + rng.integers(0, 30, k), 160), np.minimum(y0 + rng.integers(0, 30, k), 120)
    boxes = np.stack([x0, y0, x1, y1], axis=1)
    label = rng.integers(1, 4, k)
    got = window_kernel.window_moments(images, table.lut, cam, boxes, label, table.bits)
    ref = window_kernel._window_moments(tuple(images), table.lut, cam, boxes, label, table.bits)  # uncompiled
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
@pytest.mark.parametrize("bits", [8, 6])
def test_tracker_is_the_same_with_and_without_the_kernel(bits):
    studio, motion = studio_from_settings(SimulationSettings(motion="reach", size_px=(320, 240), fps=15.0))
    with studio:
        table = ColourTable.build(studio.markerset.palette, bits=bits)
        compiled = Tracker(studio.cameras, studio.markerset, table=table, fps=15.0)
        plain = Tracker(studio.cameras, studio.markerset, table=table, fps=15.0, compiled=False)
        for i, sf in enumerate(studio.play(motion, 15.0, seconds=2.0, noise_sigma=1.5)):
            a = compiled.step(sf.frames.images, sf.frames.time_s)
            b = plain.step(sf.frames.images, sf.frames.time_s)
            # the windows' moments are equal to the bit; the triangulation's 3x3 solves differ in
            # rounding (cofactors against LAPACK's LU)
            np.testing.assert_allclose(a.positions_m, b.positions_m, rtol=0, atol=1e-9)
            np.testing.assert_array_equal(a.status, b.status)
    assert i >= 20


def _rig(rng, n_cams=4):
    import cv2

    ext = []
    for c in range(n_cams):
        rot, _ = cv2.Rodrigues(rng.normal(size=3) * 0.3)
        ext.append(np.hstack([rot, np.array([[0.1 * c], [-0.2], [3.0]])]))
    return np.array(ext)


@pytest.mark.parametrize("compiled", [False, True])
def test_triangulation_loop_equals_the_numpy_path(compiled):
    if compiled and not window_kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(1)
    ext = _rig(rng)
    pts = rng.normal(size=(30, 3)) * 0.4
    cam = np.einsum("cij,nj->nci", ext[:, :, :3], pts) + ext[None, :, :, 3]
    xn = cam[..., :2] / cam[..., 2:3] + rng.normal(size=(30, 4, 2)) * 2e-4
    seen = rng.random((30, 4)) > 0.35
    xn[~seen] = np.nan
    want = Triangulator(ext)(xn, seen)
    if compiled:
        got = Triangulator(ext, compiled=True)(xn, seen)
    else:  # the loop uncompiled, as numba compiles it
        tri = Triangulator(ext)
        got = np.empty((30, 3))
        _triangulate_loop(np.ascontiguousarray(xn), seen, tri._basis, tri._depth_rot, tri._depth_t, got)
    one_view = seen.sum(axis=1) < 2
    assert one_view.any() and (~one_view).sum() > 10
    assert np.isnan(got[one_view]).all()
    np.testing.assert_allclose(got[~one_view], want[~one_view], rtol=0, atol=1e-12)
    # and near the truth (noise 2e-4 in normalized coordinates, cameras 0.1-0.3 m apart at ~3 m)
    assert np.abs(got[~one_view] - pts[~one_view]).max() < 0.02


def _cut_discs(rng, count=25):
    """Pixel regions of discs (radius 2.5-9 px) cut by a straight edge, in one arc_centres call."""
    win, xs, ys, starts, radii = [], [], [], [], []
    yy, xx = np.mgrid[0:40, 0:40]
    for k in range(count):
        r = rng.uniform(2.5, 9.0)
        c = 20.0 + rng.uniform(-1, 1, 2)
        ang = rng.uniform(0, 2 * np.pi)
        inside = ((xx - c[0]) ** 2 + (yy - c[1]) ** 2 <= r * r)
        inside &= (xx - c[0]) * np.cos(ang) + (yy - c[1]) * np.sin(ang) < rng.uniform(0.0, 0.8) * r
        py, px = np.nonzero(inside)
        win.append(np.full(px.size, k))
        xs.append(px.astype(float))
        ys.append(py.astype(float))
        starts.append([px.mean(), py.mean()])
        radii.append(r - 0.5)
    n = count
    return (np.concatenate(win), np.concatenate(xs), np.concatenate(ys), np.array(starts), np.array(radii),
            np.zeros((n, 2)), np.full((n, 2), 39.0))


def test_arc_fit_loop_equals_the_numpy_iterations(monkeypatch):
    from tracking import blobs

    args = _cut_discs(np.random.default_rng(4))
    want = blobs.arc_centres(*args)
    assert np.abs(want - args[3]).max() > 0.3, "the cuts must move the centres off the centroids"
    # the loop uncompiled (as numba compiles it), then compiled
    monkeypatch.setattr(blobs, "_arc_loop", lambda: blobs._arc_gauss_newton)
    np.testing.assert_allclose(blobs.arc_centres(*args, compiled=True), want, rtol=0, atol=1e-9)
    if window_kernel.AVAILABLE:
        monkeypatch.undo()
        np.testing.assert_allclose(blobs.arc_centres(*args, compiled=True), want, rtol=0, atol=1e-9)


def test_a_numba_that_does_not_import_leaves_the_numpy_paths(monkeypatch, caplog):
    import sys

    from tracking import jit

    def twice(x):
        return 2 * x

    monkeypatch.setattr(jit, "INSTALLED", True)
    monkeypatch.setitem(sys.modules, "numba", None)  # "import numba" raises ImportError
    monkeypatch.setattr(jit, "_warned", False)
    assert jit.compile_loop(twice) is None
    assert "numpy paths" in caplog.text


def _crowded_scene(rng, h=48, w=56):
    """Balls of one colour, some touching, some with a highlight hole or a ring with a ball inside,
    plus specks: the cases a crowded window meets."""
    img = rng.integers(40, 110, (h, w, 3)).astype(np.uint8)
    yy, xx = np.mgrid[0:h, 0:w]
    green = PALETTE[1][::-1]
    for _ in range(rng.integers(1, 5)):
        cx, cy, r = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(1.0, 9.0)
        disc = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
        img[disc] = green
        if r > 5 and rng.random() < 0.5:  # a highlight: a hole of background colour
            img[(xx - cx - 1) ** 2 + (yy - cy - 1) ** 2 <= 2.0] = (230, 230, 230)
    if rng.random() < 0.3:  # a ring with a ball inside its hole
        cx, cy = rng.uniform(15, w - 15), rng.uniform(15, h - 15)
        d2 = (xx - cx) ** 2 + (yy - cy) ** 2
        img[(d2 <= 100) & (d2 >= 49)] = green
        img[d2 <= 6] = green
    for _ in range(rng.integers(0, 6)):  # specks
        img[rng.integers(0, h), rng.integers(0, w)] = green
    if rng.random() < 0.2:  # a diagonal line across the whole image: its filled box is all outside
        k = np.arange(min(h, w))
        img[k, k] = green
    return img


@needs_numba
@pytest.mark.parametrize("bits", [8, 6])
def test_crowded_window_equals_find_blobs_and_the_arc_region(bits):
    from tracking.blobs import find_blobs
    from tracking.full_frame import BlobGates

    table = ColourTable.build(PALETTE, bits=bits)
    rng = np.random.default_rng(11)
    gate = BlobGates(min_area_px=3.0, max_area_px=400.0, min_roundness=0.5)
    checked = 0
    for trial in range(150):
        img = _crowded_scene(rng)
        box = (int(rng.integers(0, 8)), int(rng.integers(0, 8)), int(rng.integers(44, 57)), int(rng.integers(38, 49)))
        x0, y0, x1, y1 = box
        labels = table.classify_window(img, x0, y0, x1, y1)
        blobs = find_blobs(labels, table.n_colours, min_area_px=gate.min_area_px, max_area_px=gate.max_area_px,
                           min_roundness=gate.min_roundness, offset_px=(x0, y0), colours=(1,))
        for pred in rng.uniform((x0, y0), (x1, y1), (3, 2)):
            found, uv, area, roundness, xs, ys = window_kernel.crowded_window(
                img, table.lut, table.bits, box, 2, pred, gate)
            assert found == (len(blobs) > 0)
            if not found:
                continue
            j = np.argmin(np.linalg.norm(blobs.uv_px - pred, axis=1))
            np.testing.assert_allclose(uv, blobs.uv_px[j], rtol=0, atol=1e-9)
            assert area == blobs.area_px[j]
            assert abs(roundness - blobs.roundness[j]) < 1e-9
            # the arc fit's region: the 8-connected region of the coloured pixel nearest the centroid
            import cv2

            mask = labels == 2
            _, regions = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
            py, px = np.nonzero(mask)
            near = np.argmin((px - (uv[0] - x0)) ** 2 + (py - (uv[1] - y0)) ** 2)
            ry, rx = np.nonzero(regions == regions[py[near], px[near]])
            np.testing.assert_array_equal(xs, rx)
            np.testing.assert_array_equal(ys, ry)
            checked += 1
    assert checked > 200


@needs_numba
def test_compile_loops_compiles_every_loop_for_the_frames_types():
    """The tracker process compiles the loops before it reports ready (a first compilation takes
    seconds, longer than the heartbeat allows); the loops a frame set then calls need no other
    compilation."""
    from tracking import blobs, jit, triangulation

    studio, motion = studio_from_settings(SimulationSettings(motion="reach", size_px=(320, 240), fps=15.0))
    with studio:
        tracker = Tracker(studio.cameras, studio.markerset, fps=15.0)
        frames = [sf.frames for _, sf in zip(range(4), studio.play(motion, 15.0, seconds=1.0))]
        tracker.compile_loops(frames[0].images)
        loops = [jit.compile_loop(f) for f in (window_kernel._window_moments, window_kernel._crowded_window,
                                              triangulation._triangulate_loop, blobs._arc_gauss_newton,
                                              blobs._subpixel_share_loop, blobs._arc_starts_loop)]
        before = [len(loop.signatures) for loop in loops]
        assert all(n >= 1 for n in before)
        for f in frames:
            tracker.step(f.images, f.time_s)
        assert [len(loop.signatures) for loop in loops] == before
