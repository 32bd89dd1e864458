"""find_blobs on rendered marker balls with known centres: sub-pixel accuracy, gating, windows."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tracking.blobs import (
    ARC_EDGE_SHRINK_PX,
    ARC_SUBPIXEL_MAX_SHIFT_PX,
    DEFAULT_MIN_ROUNDNESS,
    Blobs,
    arc_centres,
    find_blobs,
)
from tracking.colour.table import ColourTable
from tracking.markerset import load_markerset

SUPERSAMPLE = 8
AMBIENT = 0.3
FRONTAL = (0.0, 0.0, -1.0)  # light from the camera (the camera looks along +z)
LIGHTS = (FRONTAL, (1.0, -1.0, -1.0), (-1.0, 0.3, -0.4), (0.2, 1.0, -0.5))
BACKGROUNDS_RGB = ((90, 90, 90), (40, 40, 50), (170, 160, 150), (224, 172, 140), (30, 40, 90))


@pytest.fixture(scope="module")
def palette() -> np.ndarray:
    return load_markerset("upper_limb_seated").palette


@pytest.fixture(scope="module")
def table(palette) -> ColourTable:
    return ColourTable.build(palette)


def canvas(w: int, h: int, background_rgb) -> np.ndarray:
    """(h, w, 3) float64 RGB image of one colour."""
    return np.broadcast_to(np.asarray(background_rgb, dtype=np.float64), (h, w, 3)).copy()


def draw_ball(image_rgb: np.ndarray, centre_px, radius_px: float, rgb, light=FRONTAL) -> None:
    """Draw a Lambert-shaded ball (ambient 0.3) into a float RGB image, anti-aliased by area.

    Each pixel averages SUPERSAMPLE x SUPERSAMPLE samples; pixel (i, j) covers [j - 0.5, j + 0.5] x
    [i - 0.5, i + 0.5], so the ball's true centre in OpenCV pixel coordinates is ``centre_px``.
    """
    cx, cy = centre_px
    h, w = image_rgb.shape[:2]
    x0, x1 = max(int(np.floor(cx - radius_px)) - 1, 0), min(int(np.ceil(cx + radius_px)) + 2, w)
    y0, y1 = max(int(np.floor(cy - radius_px)) - 1, 0), min(int(np.ceil(cy + radius_px)) + 2, h)
    offsets = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
    xs = (np.arange(x0, x1)[:, None] + offsets[None, :]).reshape(-1)
    ys = (np.arange(y0, y1)[:, None] + offsets[None, :]).reshape(-1)
    dx = (xs[None, :] - cx) / radius_px
    dy = (ys[:, None] - cy) / radius_px
    d2 = dx * dx + dy * dy
    inside = d2 < 1.0
    nz = -np.sqrt(np.clip(1.0 - d2, 0.0, 1.0))  # surface normal towards the camera
    lx, ly, lz = np.asarray(light, dtype=np.float64) / np.linalg.norm(light)
    shading = AMBIENT + (1.0 - AMBIENT) * np.clip(dx * lx + dy * ly + nz * lz, 0.0, None)
    patch = image_rgb[y0:y1, x0:x1]
    under = np.repeat(np.repeat(patch, SUPERSAMPLE, axis=0), SUPERSAMPLE, axis=1)
    samples = np.where(inside[..., None], shading[..., None] * np.asarray(rgb, dtype=np.float64), under)
    ny, nx = y1 - y0, x1 - x0
    image_rgb[y0:y1, x0:x1] = samples.reshape(ny, SUPERSAMPLE, nx, SUPERSAMPLE, 3).mean(axis=(1, 3))


def to_bgr(image_rgb: np.ndarray, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """Float RGB -> OpenCV BGR uint8, with Gaussian sensor noise of ``noise`` counts."""
    if noise:
        image_rgb = image_rgb + np.random.default_rng(seed).normal(0.0, noise, image_rgb.shape)
    return np.round(np.clip(image_rgb, 0, 255))[..., ::-1].astype(np.uint8)


def one_ball(centre, radius, rgb, *, light=FRONTAL, background=(90, 90, 90), noise=1.0, seed=0, size=(64, 56)):
    image = canvas(*size, background)
    draw_ball(image, centre, radius, rgb, light)
    return to_bgr(image, noise, seed)


@settings(max_examples=150, deadline=None, derandomize=True)
@given(
    radius=st.floats(2.5, 12.0),
    sub_px=st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
    colour=st.integers(0, 5),
    light=st.sampled_from(LIGHTS),
    background=st.sampled_from(BACKGROUNDS_RGB),
    seed=st.integers(0, 2**16),
)
def test_centroid_within_a_tenth_of_a_pixel(table, palette, radius, sub_px, colour, light, background, seed):
    colour %= len(palette)
    centre = (30.0 + sub_px[0], 27.0 + sub_px[1])
    image = one_ball(centre, radius, palette[colour], light=light, background=background, seed=seed)
    blobs = find_blobs(table.classify(image), table.n_colours, image_bgr=image)
    assert len(blobs) == 1 and blobs.colour[0] == colour
    assert blobs.uv_px.dtype == np.float64
    assert np.hypot(*(blobs.uv_px[0] - centre)) <= 0.1
    assert abs(blobs.radius_px[0] - radius) <= 0.15
    assert blobs.roundness[0] >= 0.9


def test_unmixing_beats_the_binary_centroid(table, palette):
    """Why centroids are refined from the image: the binary region's centroid is not accurate."""
    rng = np.random.default_rng(7)
    errors = {"binary": [], "refined": []}
    for trial in range(40):
        centre = (30.0 + rng.uniform(), 27.0 + rng.uniform())
        colour = trial % len(palette)
        image = one_ball(centre, 3.0, palette[colour], light=LIGHTS[trial % 4], seed=trial)
        labels = table.classify(image)
        for name, given_image in (("binary", None), ("refined", image)):
            blobs = find_blobs(labels, table.n_colours, image_bgr=given_image, min_roundness=0.0)
            errors[name].append(np.hypot(*(blobs.uv_px[0] - centre)))
    rms = {name: float(np.sqrt(np.mean(np.square(e)))) for name, e in errors.items()}
    assert max(errors["binary"]) > 0.1
    assert max(errors["refined"]) < 0.1
    assert rms["refined"] < rms["binary"] / 3


def test_ball_over_a_shaded_background_edge(table, palette):
    """A ball at the edge of an arm that darkens towards its outline, over a dark shirt: the
    background of the ball's edge pixels is neither uniform nor as bright as around (regression:
    unmixing against the brighter skin nearby took shaded skin for marker)."""
    rng = np.random.default_rng(11)
    errors = {"binary": [], "refined": []}
    for trial in range(60):
        colour, radius = trial % len(palette), rng.uniform(2.5, 8.0)
        centre = (32.0 + rng.uniform(), 28.0 + rng.uniform())
        image = canvas(64, 56, (58, 70, 100))
        xs = np.arange(64)
        edge = centre[0] - radius * rng.uniform(0.3, 1.2)
        arm = xs < edge
        shading = 0.4 + 0.6 * np.clip((edge - xs) / 6.0, 0.0, 1.0)
        image[:, arm] = np.array([205.0, 150.0, 125.0]) * shading[arm][:, None]
        draw_ball(image, centre, radius, palette[colour], LIGHTS[trial % 4])
        bgr = to_bgr(image, 1.0, trial)
        labels = table.classify(bgr)
        for name, given_image in (("binary", None), ("refined", bgr)):
            blobs = find_blobs(labels, table.n_colours, image_bgr=given_image, min_roundness=0.0).of_colour(colour)
            errors[name].append(np.hypot(*(blobs.uv_px[np.argmax(blobs.area_px)] - centre)))
    rms = {name: float(np.sqrt(np.mean(np.square(e)))) for name, e in errors.items()}
    # measured: refined 0.078 px RMS, binary 0.157 (refined without that check: 0.109)
    assert rms["refined"] < 0.1
    assert rms["refined"] < 0.7 * rms["binary"]


def test_binary_centroids_are_not_truncated(table, palette):
    image = one_ball((20.37, 18.81), 6.0, palette[0])
    blobs = find_blobs(table.classify(image), table.n_colours)
    assert len(blobs) == 1
    assert np.all(blobs.uv_px != np.round(blobs.uv_px))
    assert np.hypot(*(blobs.uv_px[0] - (20.37, 18.81))) < 0.3


def test_area_gates(table, palette):
    small = one_ball((20.3, 20.6), 1.5, palette[1])
    labels = table.classify(small)
    assert len(find_blobs(labels, table.n_colours, image_bgr=small)) == 0
    assert len(find_blobs(labels, table.n_colours, image_bgr=small, min_area_px=4)) == 1
    big = one_ball((28.0, 28.0), 20.0, palette[1], size=(64, 64))
    labels = table.classify(big)
    assert len(find_blobs(labels, table.n_colours, image_bgr=big)) == 1
    assert len(find_blobs(labels, table.n_colours, image_bgr=big, max_area_px=1000)) == 0


def test_touching_markers_of_one_colour_are_one_unround_blob(table, palette):
    image = canvas(80, 48, (90, 90, 90))
    draw_ball(image, (30.2, 24.4), 6.0, palette[2])
    draw_ball(image, (42.0, 24.9), 6.0, palette[2])
    bgr = to_bgr(image, 1.0)
    labels = table.classify(bgr)
    assert len(find_blobs(labels, table.n_colours, image_bgr=bgr)) == 0  # rejected by roundness
    flagged = find_blobs(labels, table.n_colours, image_bgr=bgr, min_roundness=0.0)
    assert len(flagged) == 1  # merged, not split
    assert flagged.roundness[0] < DEFAULT_MIN_ROUNDNESS
    assert flagged.area_px[0] > 1.5 * np.pi * 36


def test_touching_markers_of_two_colours_stay_apart(table, palette):
    image = canvas(80, 48, (90, 90, 90))
    draw_ball(image, (30.2, 24.4), 6.0, palette[0])
    draw_ball(image, (42.0, 24.9), 6.0, palette[1])
    bgr = to_bgr(image, 1.0)
    blobs = find_blobs(table.classify(bgr), table.n_colours, image_bgr=bgr)
    assert blobs.colour.tolist() == [0, 1]
    assert np.all(np.hypot(*(blobs.uv_px - [(30.2, 24.4), (42.0, 24.9)]).T) < 0.25)


def test_specular_highlight_hole_is_filled(table, palette):
    image = canvas(64, 56, (90, 90, 90))
    draw_ball(image, (30.4, 27.7), 7.0, palette[0])
    image[25:28, 28:31] = 255.0  # white highlight, fails the saturation test
    bgr = to_bgr(image, 1.0)
    labels = table.classify(bgr)
    assert np.all(labels[25:28, 28:31] == 0)
    blobs = find_blobs(labels, table.n_colours, image_bgr=bgr)
    assert len(blobs) == 1
    assert np.hypot(*(blobs.uv_px[0] - (30.4, 27.7))) < 0.1
    assert abs(blobs.area_px[0] - np.pi * 49) < 3.0


def test_window_results_land_in_full_image_coordinates(table, palette):
    image = canvas(320, 240, (90, 90, 90))
    centres = [(40.3, 50.6), (200.8, 60.1), (150.5, 190.4), (300.2, 200.9)]
    for i, c in enumerate(centres):
        draw_ball(image, c, 5.0, palette[i % 3], LIGHTS[i])
    bgr = to_bgr(image, 1.0)
    whole = find_blobs(table.classify(bgr), table.n_colours, image_bgr=bgr)
    assert len(whole) == len(centres)
    for c in centres:
        x0, y0 = int(c[0]) - 15, int(c[1]) - 15
        x1, y1 = min(x0 + 30, 320), min(y0 + 30, 240)
        labels = table.classify_window(bgr, x0, y0, x1, y1)
        found = find_blobs(labels, table.n_colours, image_bgr=bgr[y0:y1, x0:x1], offset_px=(x0, y0))
        assert len(found) == 1
        match = np.argmin(np.hypot(*(whole.uv_px - found.uv_px[0]).T))
        np.testing.assert_allclose(found.uv_px[0], whole.uv_px[match], atol=1e-9)
        assert np.hypot(*(found.uv_px[0] - c)) < 0.1


def test_ball_cut_by_the_image_border(table, palette):
    image = one_ball((2.0, 20.0), 6.0, palette[0], size=(40, 40))
    blobs = find_blobs(table.classify(image), table.n_colours, image_bgr=image, min_roundness=0.0)
    assert len(blobs) == 1
    assert 0.0 <= blobs.uv_px[0, 0] < 6.0


def test_order_is_by_colour_then_raster(table, palette):
    image = canvas(120, 60, (90, 90, 90))
    for centre, colour in (((100.0, 15.0), 1), ((20.0, 45.0), 0), ((60.0, 15.0), 0), ((20.0, 15.0), 2)):
        draw_ball(image, centre, 5.0, palette[colour])
    bgr = to_bgr(image, 1.0)
    blobs = find_blobs(table.classify(bgr), table.n_colours, image_bgr=bgr)
    assert blobs.colour.tolist() == [0, 0, 1, 2]
    np.testing.assert_allclose(blobs.uv_px, [(60, 15), (20, 45), (100, 15), (20, 15)], atol=0.1)
    assert blobs.of_colour(0).uv_px.shape == (2, 2)


def hide_behind_edge(image_rgb: np.ndarray, centre_px, normal_deg: float, distance_px: float, rgb) -> None:
    """Cover the half-plane beyond the line ``distance_px`` from ``centre_px`` along the direction
    ``normal_deg`` with an occluder of colour ``rgb`` (an arm in front of a ball), anti-aliased."""
    h, w = image_rgb.shape[:2]
    offsets = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
    xs = (np.arange(w)[:, None] + offsets).reshape(-1)
    ys = (np.arange(h)[:, None] + offsets).reshape(-1)
    a = np.deg2rad(normal_deg)
    beyond = (xs[None, :] - centre_px[0]) * np.cos(a) + (ys[:, None] - centre_px[1]) * np.sin(a) > distance_px
    cover = beyond.reshape(h, SUPERSAMPLE, w, SUPERSAMPLE).mean(axis=(1, 3))[..., None]
    image_rgb[:] = image_rgb * (1.0 - cover) + cover * np.asarray(rgb, dtype=np.float64)


def region_arc_centre(mask: np.ndarray, radius_px: float, box_hi=None) -> tuple[np.ndarray, np.ndarray]:
    """(centroid, arc centre) of the pixels of ``mask`` taken as one region searched in the whole image."""
    ys, xs = np.nonzero(mask)
    start = np.array([[xs.mean(), ys.mean()]])
    hi = np.array([box_hi if box_hi is not None else (mask.shape[1] - 1.0, mask.shape[0] - 1.0)], dtype=np.float64)
    fitted = arc_centres(np.zeros(xs.size, dtype=np.int64), xs.astype(np.float64), ys.astype(np.float64), start,
                         np.array([radius_px - ARC_EDGE_SHRINK_PX]), np.zeros((1, 2)), hi)
    return start[0], fitted[0]


def hidden_ball_errors(table, palette, *, seed: int, trials: int, radius_px, hidden) -> dict[str, np.ndarray]:
    """Balls of a radius in ``radius_px`` (low, high), a share in ``hidden`` (low, high) of each
    hidden behind a straight edge (skin or a dark sleeve, any direction): the distances of the
    binary region's centroid and of its arc fit from the true centre, px."""
    rng = np.random.default_rng(seed)
    errors = {"centroid": [], "arc": []}
    angle = np.linspace(0.0, np.pi, 2001)
    cut_area = (angle - np.sin(angle)) / (2.0 * np.pi)  # area fraction cut off by a chord
    for trial in range(trials):
        radius, colour = rng.uniform(*radius_px), trial % len(palette)
        centre = (30.0 + rng.uniform(), 27.0 + rng.uniform())
        image = canvas(64, 56, BACKGROUNDS_RGB[trial % len(BACKGROUNDS_RGB)])
        draw_ball(image, centre, radius, palette[colour], LIGHTS[trial % len(LIGHTS)])
        chord_distance = radius * np.cos(np.interp(rng.uniform(*hidden), cut_area, angle) / 2.0)
        hide_behind_edge(image, centre, rng.uniform(0.0, 360.0), chord_distance,
                         (224, 172, 140) if trial % 2 else (60, 60, 70))
        mask = table.classify(to_bgr(image, 1.0, trial)) == colour + 1
        centroid, fitted = region_arc_centre(mask, radius)
        errors["centroid"].append(np.hypot(*(centroid - centre)))
        errors["arc"].append(np.hypot(*(fitted - centre)))
    return {name: np.array(e) for name, e in errors.items()}


def test_partly_hidden_ball_centre_from_its_visible_arc(table, palette):
    """A ball 10-35 % hidden behind a straight edge (skin or a dark sleeve, any direction, radius
    3.5-8 px): the binary region's centroid lies 0.46-2.0 px towards the visible part (1.25 px
    RMS); the circle of the ball's radius fitted to the visible arc is 0.22 px RMS, 0.40 max."""
    errors = hidden_ball_errors(table, palette, seed=3, trials=30, radius_px=(3.5, 8.0), hidden=(0.1, 0.35))
    rms = {name: float(np.sqrt(np.mean(np.square(e)))) for name, e in errors.items()}
    assert min(errors["centroid"]) > 0.4 and rms["centroid"] > 1.0
    assert rms["arc"] < 0.3 and max(errors["arc"]) < 0.5


def test_small_ball_half_hidden_starts_its_arc_fit_from_the_arc_not_the_centroid(table, palette):
    """Balls of 2.5-3.8 px (320x240 at 2-3 m) 25-50 % hidden behind a straight edge: the binary
    region's centroid is 0.5-1.7 px towards the visible part (1.1 px RMS, 62 of 100 over 1 px). The
    Gauss-Newton fit from there dropped the visible arc as lying inside the circle and kept the
    centroid (1.0 px RMS, 20 over 1 px); started from the centre that best puts the arc on the
    circle (a grid search), 0.69 px RMS and 10 over 1 px (slivers under 40 % of the ball keep the
    centroid). What is left: regions of 7-15 pixels that a circle fits from either side (the
    occluder's straight edge taken for the arc)."""
    err = hidden_ball_errors(table, palette, seed=7, trials=100, radius_px=(2.5, 3.8), hidden=(0.25, 0.5))
    rms = {name: float(np.sqrt(np.mean(e**2))) for name, e in err.items()}
    assert rms["centroid"] > 1.0 and (err["centroid"] > 1.0).sum() >= 50
    assert rms["arc"] < 0.8 and (err["arc"] > 1.0).sum() <= 13
    assert np.median(err["arc"]) < 0.4


def test_small_ball_start_weighs_the_prediction_against_a_mirror_fit():
    """The region of a ball of 2.7 px half hidden by a hand in the simulated walk at 320x240 (a
    3 x 5 pixel block, frame 26 of the @15 run): its edges fit a circle better on the mirror side
    (1.66 px off the true centre, which put the marker 11 mm off in 3D). A prediction 0.23 px off
    the true centre, sure to 1-2 px, pulls the start to its side; an unsure one (10 px) leaves the
    edges to decide."""
    pix = [(x, y) for y in (3, 4, 5) for x in (3, 4, 5)] + [(x, y) for y in (6, 7) for x in (4, 5)]
    x = np.array([p[0] for p in pix], dtype=np.float64)
    y = np.array([p[1] for p in pix], dtype=np.float64)
    args = (np.zeros(len(pix), dtype=np.int64), x, y, np.array([[x.mean(), y.mean()]]), np.array([2.5165]),
            np.zeros((1, 2)), np.array([[8.0, 10.0]]))
    true_centre, prior = np.array([3.04, 5.16]), np.array([[3.27, 5.21]])

    def error(**kw):
        return float(np.hypot(*(arc_centres(*args, **kw)[0] - true_centre)))

    assert error() > 1.5  # the edges alone: the mirror side
    assert error(prior_px=prior, prior_sigma_px=np.array([10.0])) > 1.5
    for sure in (1.0, 2.0):
        assert error(prior_px=prior, prior_sigma_px=np.array([sure])) < 0.7


def subpixel_arc_errors(table, palette, *, seed: int, trials: int, radius_px, hidden, compiled: bool = False
                        ) -> dict[str, np.ndarray]:
    """As :func:`hidden_ball_errors`, on every background: the binary arc fit's and the sub-pixel
    arc fit's (``colours`` given) distances from the true centre, and how far the second moved
    from the first, px."""
    rng = np.random.default_rng(seed)
    angle = np.linspace(0.0, np.pi, 2001)
    cut_area = (angle - np.sin(angle)) / (2.0 * np.pi)
    out = {"binary": [], "subpixel": [], "moved": []}
    for trial in range(trials):
        radius, colour = rng.uniform(*radius_px), trial % len(palette)
        centre = np.array([30.0 + rng.uniform(), 27.0 + rng.uniform()])
        image = canvas(64, 56, BACKGROUNDS_RGB[trial % len(BACKGROUNDS_RGB)])
        draw_ball(image, centre, radius, palette[colour], LIGHTS[trial % len(LIGHTS)])
        chord_distance = radius * np.cos(np.interp(rng.uniform(*hidden), cut_area, angle) / 2.0)
        hide_behind_edge(image, centre, rng.uniform(0.0, 360.0), chord_distance,
                         (224, 172, 140) if trial % 2 else (60, 60, 70))
        bgr = to_bgr(image, 1.0, trial)
        ys, xs = np.nonzero(table.classify(bgr) == colour + 1)
        args = (np.zeros(xs.size, dtype=np.int64), xs.astype(np.float64), ys.astype(np.float64),
                np.array([[xs.mean(), ys.mean()]]), np.array([radius - ARC_EDGE_SHRINK_PX]), np.zeros((1, 2)),
                np.array([[63.0, 55.0]]))
        binary = arc_centres(*args, compiled=compiled)[0]
        fine = arc_centres(*args, compiled=compiled, colours=([bgr], np.array([0]), np.zeros((1, 2))))[0]
        out["binary"].append(np.hypot(*(binary - centre)))
        out["subpixel"].append(np.hypot(*(fine - centre)))
        out["moved"].append(np.hypot(*(fine - binary)))
    return {name: np.array(e) for name, e in out.items()}


@pytest.mark.parametrize("radius_px, median_before, median_after", [((2.5, 3.8), 0.245, 0.122), ((4.0, 8.0), 0.172, 0.05)])
def test_subpixel_arc_fit_places_the_edges_by_coverage(table, palette, radius_px, median_before, median_after):
    """Balls 10-35 % hidden behind a straight edge, on the five backgrounds (100 each size): the
    binary region reaches into a dark background and stops short of a bright one, so the arc
    fit on its edges is off by a median 0.245 px (balls of 2.5-3.8 px) and 0.172 px (4-8 px).
    With each edge placed by its pixels' coverage the median is 0.122 / 0.05 px, and the RMS is
    no worse (0.499 -> 0.461, 0.224 -> 0.155: a few small regions that fit either side keep the
    binary fit, which the sub-pixel fit may not leave by more than ARC_SUBPIXEL_MAX_SHIFT_PX)."""
    err = subpixel_arc_errors(table, palette, seed=11, trials=100, radius_px=radius_px, hidden=(0.1, 0.35))
    assert np.median(err["binary"]) == pytest.approx(median_before, abs=0.03)
    assert np.median(err["subpixel"]) < 0.6 * np.median(err["binary"])
    assert np.median(err["subpixel"]) == pytest.approx(median_after, abs=0.03)
    rms = {name: float(np.sqrt(np.mean(e**2))) for name, e in err.items()}
    assert rms["subpixel"] <= rms["binary"] + 0.01
    assert err["moved"].max() <= ARC_SUBPIXEL_MAX_SHIFT_PX + 1e-9


def test_subpixel_arc_fit_compiled_equals_numpy(table, palette):
    """The compiled loops of the sub-pixel pass (coverage per edge pair, the searched start) give
    the numpy path's centres."""
    kw = dict(seed=5, trials=30, radius_px=(2.5, 6.0), hidden=(0.1, 0.5))
    compiled = subpixel_arc_errors(table, palette, compiled=True, **kw)
    plain = subpixel_arc_errors(table, palette, compiled=False, **kw)
    np.testing.assert_allclose(compiled["subpixel"], plain["subpixel"], atol=1e-9)


def test_subpixel_arc_fit_without_contrast_keeps_the_midpoints():
    """An edge whose ball colour and background colour are too close to unmix (here: the same
    grey) keeps the binary midpoint, so the fit equals the one on binary edges with the full
    radius."""
    img = np.full((20, 20, 3), 100, dtype=np.uint8)
    ys, xs = np.nonzero((np.arange(20)[:, None] - 10.0) ** 2 + (np.arange(20)[None, :] - 9.6) ** 2 < 9.0)
    args = (np.zeros(xs.size, dtype=np.int64), xs.astype(np.float64), ys.astype(np.float64),
            np.array([[xs.mean(), ys.mean()]]), np.array([3.0 - ARC_EDGE_SHRINK_PX]), np.zeros((1, 2)),
            np.array([[19.0, 19.0]]))
    binary = arc_centres(*args)[0]
    fine = arc_centres(*args, colours=([img], np.array([0]), np.zeros((1, 2))))[0]
    assert np.hypot(*(fine - binary)) <= ARC_SUBPIXEL_MAX_SHIFT_PX
    assert np.hypot(*(fine - (9.6, 10.0))) < 0.3


def test_arc_centre_of_a_whole_ball_is_its_centroid_and_a_cut_window_is_no_edge(table, palette):
    """A whole ball: the arc fit stays within 0.1 px of the (binary) centroid. The same
    ball cut by the border of the searched window (the box): the cut is not the ball's outline,
    so the fit uses the rest of the circle, while the centroid lies inside the window."""
    centre, radius = (30.4, 27.7), 6.0
    mask = table.classify(one_ball(centre, radius, palette[2], seed=5)) == 3
    centroid, fitted = region_arc_centre(mask, radius)
    assert np.hypot(*(fitted - centroid)) < 0.1 and np.hypot(*(fitted - centre)) < 0.25
    last_col = 32  # the window ends 1.6 px right of the centre: a quarter of the ball is outside
    cut = mask.copy()
    cut[:, last_col + 1:] = False
    centroid, fitted = region_arc_centre(cut, radius, box_hi=(last_col, mask.shape[0] - 1.0))
    assert np.hypot(*(centroid - centre)) > 0.8
    assert np.hypot(*(fitted - centre)) < 0.25


def test_empty_inputs_give_empty_blobs(table):
    for labels in (np.zeros((0, 0), dtype=np.uint8), np.zeros((48, 64), dtype=np.uint8)):
        blobs = find_blobs(labels, table.n_colours)
        assert len(blobs) == 0
        assert blobs.uv_px.shape == (0, 2) and blobs.uv_px.dtype == np.float64
        assert blobs.area_px.shape == blobs.roundness.shape == blobs.radius_px.shape == (0,)
        assert blobs.colour.shape == (0,) and blobs.colour.dtype == np.int64
    assert len(Blobs.empty().of_colour(0)) == 0


def test_mismatched_inputs_raise(table):
    with pytest.raises(ValueError, match="same window"):
        find_blobs(np.zeros((10, 10), dtype=np.uint8), 3, image_bgr=np.zeros((10, 11, 3), dtype=np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        find_blobs(np.zeros((10, 10), dtype=np.int32), 3)
    with pytest.raises(ValueError, match="Blobs arrays"):
        Blobs(np.zeros((2, 2)), np.zeros(1), np.zeros(2, dtype=np.int64), np.zeros(2), np.zeros(2))


def jpeg_ball_errors(table, palette, *, luma: bool, chroma: str = "420", quality: int | None = 75, trials: int = 24):
    """Centroid errors (px) of rendered balls (radius 3-7 px, frontal and oblique light, the five
    backgrounds) after a JPEG round trip (``quality`` None: lossless)."""
    from tracking.sim.imaging import jpeg_roundtrip

    rng = np.random.default_rng(21)
    errors = []
    for t in range(trials):
        centre = np.array([24.0 + rng.uniform(0, 1), 20.0 + rng.uniform(0, 1)])
        colour = t % len(palette)
        image = canvas(48, 40, BACKGROUNDS_RGB[t % len(BACKGROUNDS_RGB)])
        draw_ball(image, centre, rng.uniform(3.0, 7.0), palette[colour], LIGHTS[(t // 5) % 2])
        bgr = to_bgr(image, 1.5, seed=t)
        if quality is not None:
            bgr = jpeg_roundtrip(bgr, quality, chroma)
        blobs = find_blobs(table.classify(bgr), table.n_colours, image_bgr=bgr, luma=luma).of_colour(colour)
        if len(blobs):
            errors.append(float(np.linalg.norm(blobs.uv_px - centre, axis=1).min()))
    return np.array(errors)


def test_luma_centres_hold_under_mjpeg_chroma_subsampling(table, palette):
    """JPEG 4:2:0 moves the colour edge (colour at half resolution); the luma fit does not."""
    colour_only = jpeg_ball_errors(table, palette, luma=False)
    with_luma = jpeg_ball_errors(table, palette, luma=True)
    assert len(with_luma) == len(colour_only) >= 20
    assert np.median(colour_only) > 0.2  # the colour centres alone (this test fails on them)
    assert np.median(with_luma) < 0.15
    assert np.percentile(with_luma, 90) < 0.7 * np.percentile(colour_only, 90)


def test_luma_centres_leave_lossless_images_as_they_were(table, palette):
    colour_only = jpeg_ball_errors(table, palette, luma=False, quality=None)
    with_luma = jpeg_ball_errors(table, palette, luma=True, quality=None)
    # (a hard light from the side leaves a few balls worse: docs/TRACKING.md, "Marker centres from the luma")
    assert np.median(with_luma) <= np.median(colour_only) + 0.01
    assert np.percentile(with_luma, 75) < 0.05


def test_luma_centre_compiled_equals_numpy(table, palette):
    from tracking.blobs import luma_centre
    from tracking.sim.imaging import jpeg_roundtrip

    rng = np.random.default_rng(5)
    for t in range(6):
        centre = (24.0 + rng.uniform(0, 1), 20.0 + rng.uniform(0, 1))
        image = canvas(48, 40, BACKGROUNDS_RGB[t % 5])
        draw_ball(image, centre, 3.0 + t, palette[t % 4], LIGHTS[t % 2])
        bgr = jpeg_roundtrip(to_bgr(image, 1.5, seed=t), 70, "420")
        labels = table.classify(bgr)
        start = (centre[0] + 0.4, centre[1] - 0.3)
        a = luma_centre(bgr, labels, t % 4, *start, 3.0 + t, compiled=True)
        b = luma_centre(bgr, labels, t % 4, *start, 3.0 + t, compiled=False)
        assert (a is None) == (b is None)
        if a is not None:
            assert np.hypot(a[0] - b[0], a[1] - b[1]) < 0.01
            assert np.hypot(a[0] - centre[0], a[1] - centre[1]) < 0.2
