"""The search windows' whole balls centred from the luma (``TrackerParams.window_luma``): under
MJPEG's half-resolution colour (4:2:0) a window's colour centroid is off by a third to half a
pixel, the luma fit is not; on lossless images the fit leaves the centroids alone or better."""

from types import SimpleNamespace

import numpy as np
import pytest

from tracking import window_kernel
from tracking.full_frame import BlobGates
from tracking.pipeline.params import TrackerParams
from tracking.pipeline.windows import LumaLabels, SearchWindows, luma_windows, window_moments
from tracking.sim.imaging import jpeg_roundtrip
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.tracker import Tracker
from tests.tracking.test_blobs import BACKGROUNDS_RGB, LIGHTS, canvas, draw_ball, palette, table, to_bgr  # noqa: F401 (fixtures)

TRIALS = 24


def _balls(palette, quality, chroma="420"):
    """One rendered ball per image (radius 3-7 px, frontal and oblique light, the five
    backgrounds), its true centre, radius and colour; each image its own camera's."""
    rng = np.random.default_rng(21)
    images, centres, radii, colours = [], [], [], []
    for t in range(TRIALS):
        centre = np.array([24.0 + rng.uniform(0, 1), 20.0 + rng.uniform(0, 1)])
        radius = rng.uniform(3.0, 7.0)
        image = canvas(48, 40, BACKGROUNDS_RGB[t % len(BACKGROUNDS_RGB)])
        draw_ball(image, centre, radius, palette[t % len(palette)], LIGHTS[(t // 5) % 2])
        bgr = to_bgr(image, 1.5, seed=t)
        images.append(bgr if quality is None else jpeg_roundtrip(bgr, quality, chroma))
        centres.append(centre)
        radii.append(radius)
        colours.append(t % len(palette))
    return images, np.array(centres), np.array(radii), np.array(colours)


def _window_centres(table, palette, quality, compiled, confirm_px=TrackerParams().window_luma_confirm_px):
    """(colour centroid errors, luma-checked errors) in px of each ball's window (marker t seen
    in camera t only, the prediction 1.5 px off its ball)."""
    images, centres, radii, colours = _balls(palette, quality)
    n = TRIALS
    valid = np.eye(n, dtype=bool)
    uv = np.full((n, n, 2), np.nan)
    uv[np.arange(n), np.arange(n)] = centres + [1.0, -1.1]
    r_px = np.where(valid, radii[:, None], np.nan)
    win = SearchWindows(valid, uv, np.where(valid, radii[:, None] + 6.0, np.nan), r_px, np.where(valid, 1.0, np.nan),
                        np.tile([48, 40], (n, 1)))
    gate = BlobGates(min_area_px=3.0, max_area_px=600.0, min_roundness=0.5)
    setup = SimpleNamespace(label=(colours + 1).astype(np.uint8), colour=colours, gates=[gate] * n,
                            min_area_px=np.full(n, 3.0))
    wm = window_moments(setup, TrackerParams(), table, images, win, compiled)
    assert wm.simple.sum() >= n - 2  # (MJPEG can leave a small ball's mask not round: not one ball)
    colour_uv = wm.centre + wm.mxy
    out = np.full((n, n, 2), np.nan)
    out[wm.mi, wm.ci] = colour_uv
    luma_windows(setup, table, images, wm, wm.simple, LumaLabels(), compiled, out, confirm_px)
    keep = wm.simple
    colour_uv, luma_uv, truth = colour_uv[keep], out[wm.mi, wm.ci][keep], centres[wm.mi[keep]]
    return np.linalg.norm(colour_uv - truth, axis=1), np.linalg.norm(luma_uv - truth, axis=1)


@pytest.mark.parametrize("compiled", [True, False])
def test_window_centres_are_unbiased_under_420_chroma(table, palette, compiled):
    if compiled and not window_kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    colour_err, fit_err = _window_centres(table, palette, 75, compiled, confirm_px=0.0)
    assert np.median(colour_err) > 0.2  # the colour mask's centroid: MJPEG moved its edge
    assert np.median(fit_err) < 0.15  # every sure fit taken
    assert np.percentile(fit_err, 90) < 0.7 * np.percentile(colour_err, 90)
    luma_err = _window_centres(table, palette, 75, compiled)[1]  # the fit where it differs by > 0.2 px
    assert np.median(luma_err) < 0.65 * np.median(colour_err)


def test_fill_labels_equals_the_table(table, palette):
    """The compiled pass writes each box's labels as the table classifies them, nothing outside."""
    if not window_kernel.AVAILABLE:
        pytest.skip("numba is not installed")
    images = _balls(palette, 75)[0][:3]
    boxes = np.array([[5, 4, 30, 22], [0, 0, 48, 40], [40, 30, 48, 40]])
    labels = [np.full((40, 48), 255, np.uint8) for _ in images]
    window_kernel.fill_labels(images, table.lut, np.arange(3), boxes, table.bits, labels)
    for img, lab, (x0, y0, x1, y1) in zip(images, labels, boxes):
        expect = np.full((40, 48), 255, np.uint8)
        expect[y0:y1, x0:x1] = table.classify(img)[y0:y1, x0:x1]
        np.testing.assert_array_equal(lab, expect)


def test_window_luma_makes_lossless_centres_no_worse(table, palette):
    """A binary mask's centroid leans towards the lit side of a shaded ball; where the fit of the
    shaded ball disagrees by more than 0.2 px it is the better."""
    colour_err, luma_err = _window_centres(table, palette, None, window_kernel.AVAILABLE)
    assert np.median(luma_err) < np.median(colour_err)
    assert np.percentile(luma_err, 90) <= np.percentile(colour_err, 90) + 1e-9


def test_tracker_with_window_luma_tracks_as_without():
    """The option through the tracker: the same markers measured, the points within a few
    millimetres of the colour centroids' (the luma moves centres by fractions of a pixel), and
    some moved (the fits are used)."""
    studio, motion = studio_from_settings(SimulationSettings(motion="reach", size_px=(320, 240), fps=15.0))
    with studio:
        plain = Tracker(studio.cameras, studio.markerset, fps=15.0)
        luma = Tracker(studio.cameras, studio.markerset, fps=15.0, params=TrackerParams(window_luma=True))
        luma.compile_loops(next(iter(studio.play(motion, 15.0, seconds=0.1))).frames.images)
        moved = 0.0
        for i, sf in enumerate(studio.play(motion, 15.0, seconds=1.0, noise_sigma=1.5)):
            a = plain.step(sf.frames.images, sf.frames.time_s)
            b = luma.step(sf.frames.images, sf.frames.time_s)
            np.testing.assert_array_equal(a.status, b.status)
            d = np.linalg.norm(a.positions_m - b.positions_m, axis=1)
            assert np.nanmax(d) < 0.004
            moved = max(moved, float(np.nanmax(d)))
    assert i >= 10 and moved > 1e-5
