"""Learned colours on simulated images: learning, adaptation under drift, tracking through it."""

from dataclasses import replace

import numpy as np
import pytest

from tracking.colour.adapt import ColourAdapter, learn_colours, nominal_models
from tracking.colour.learn import disc_pixels, outside_discs_sample
from tracking.colour.table import ColourTable
from tracking.sim.colour_drift import DRIFT_SETTINGS, run_drift
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.marker_status import MarkerStatus


@pytest.fixture(scope="module")
def studio_and_motion():
    studio, motion = studio_from_settings(SimulationSettings(motion="shoulder_abduction", size_px=(320, 240)))
    yield studio, motion
    studio.close()


def disc_geometry(cam, markers_m, radius_m):
    uv = cam.project(markers_m)
    depth = cam.world_to_camera(markers_m)[:, 2]
    return uv, (cam.K[0, 0] + cam.K[1, 1]) / 2.0 * radius_m / depth


def own_label_share(table, cameras, sf, markerset):
    """(C, M) share of each fully visible marker's inner-disc pixels with its own label (NaN: hidden)."""
    out = np.full(sf.visible_fraction.shape, np.nan)
    colour = markerset.colour_index
    for c, (cam, img) in enumerate(zip(cameras, sf.frames.images)):
        uv, r = disc_geometry(cam, sf.markers_m, markerset.radius_m)
        labels = table.classify(img)
        for m in np.flatnonzero(sf.visible_fraction[c] >= 0.95):
            px = disc_pixels(labels[..., None], uv[m], 0.6 * r[m])[:, 0]
            if len(px) >= 3:
                out[c, m] = np.mean(px == colour[m] + 1)
    return out


def test_colours_learned_from_the_reference_pose_classify_markers_and_background(studio_and_motion):
    studio, motion = studio_and_motion
    ms = studio.markerset
    frames = (sf.frames for sf in studio.play(motion, 30.0, seconds=0.3, noise_sigma=1.5, with_visibility=False))
    adapter = learn_colours(frames, studio.cameras, ms, frames=5)
    nominal = ColourTable.build(ms.palette)
    for m, rgb in zip(adapter.models, ms.palette):
        nominal_hue = nominal_models(np.array([rgb], np.uint8))[0].hue_deg
        assert abs((m.hue_deg - nominal_hue + 180) % 360 - 180) < 6.0
    sf = studio.render(motion.pose_at(0.5), 0, 0.5, noise_sigma=1.5, seed=7)
    shares = own_label_share(adapter.table, studio.cameras, sf, ms)
    assert np.nanmin(shares) > 0.9
    assert np.nanmean(shares) > 0.98
    # the rest of the images (skin, clothes, chair, room): marker labels on < 0.1 % of the pixels
    rng = np.random.default_rng(0)
    for cam, img in zip(studio.cameras, sf.frames.images):
        uv, r = disc_geometry(cam, sf.markers_m, ms.radius_m)
        bg = outside_discs_sample(img, uv, 2.0 * r + 3.0, 20000, rng)
        words = bg[:, 0].astype(np.uint32) | bg[:, 1].astype(np.uint32) << 8 | bg[:, 2].astype(np.uint32) << 16
        assert np.mean(adapter.table.lut[words] != 0) < 0.001
        assert np.mean(adapter.table.lut[words] != 0) <= np.mean(nominal.lut[words] != 0) + 1e-4


def test_adapted_table_keeps_the_markers_that_the_nominal_table_loses_when_light_drifts(studio_and_motion):
    studio, motion = studio_and_motion
    ms = studio.markerset
    adapter = ColourAdapter(studio.cameras, ms, every=1)
    nominal = ColourTable.build(ms.palette)
    cast_end = np.array([1.3, 1.0, 0.7])
    steps = np.linspace(0.0, 1.0, 7)
    for i, frac in enumerate(steps):  # the lighting drifts while the markers are tracked
        t = 0.1 * i
        sf = studio.render(motion.pose_at(t), i, t, exposure=1.0 - 0.4 * frac,
                           colour_cast=tuple(1.0 + (cast_end - 1.0) * frac), noise_sigma=1.5, seed=i)
        seen2 = (sf.visible_fraction >= 0.75).sum(axis=0) >= 2
        status = np.where(seen2, MarkerStatus.MEASURED, MarkerStatus.ESTIMATED).astype(np.uint8)
        adapter.observe(sf.frames.images, sf.markers_m, status)
        adapter.flush()
    fixed_share = own_label_share(nominal, studio.cameras, sf, ms)
    adapted_share = own_label_share(adapter.table, studio.cameras, sf, ms)
    magenta = [ms.index(n) for n in ("MLS", "MLE1", "MLW1")]
    # the nominal table has lost the magenta balls (hue moved ~25 deg); the adapted one keeps them
    assert np.nanmax(fixed_share[:, magenta]) < 0.3
    assert np.nanmin(adapted_share[:, magenta]) > 0.8
    assert np.nanmean(adapted_share) > 0.97


def test_tracker_uses_a_swapped_colour_table_from_the_next_frame(studio_and_motion):
    from tracking.tracker import Tracker, TrackingState

    studio, motion = studio_and_motion
    ms = studio.markerset
    blind = ColourTable.from_lut(ms.palette, np.zeros(1 << 24, np.uint8))
    tracker = Tracker(studio.cameras, ms, table=blind)
    images = studio.render(motion.pose_at(0.0), 0, 0.0, noise_sigma=1.5).frames.images
    assert tracker.step(images).state == TrackingState.WAITING  # a table that sees no colour
    tracker.set_colour_table(ColourTable.build(ms.palette))
    sample = tracker.step(images)
    assert sample.state == TrackingState.TRACKING
    assert np.all(sample.status == MarkerStatus.MEASURED)


def test_short_drift_recording_is_tracked_with_zero_swaps_by_the_adapted_table():
    # last in this file: it opens a studio of its own, and a studio renders wrong images after
    # another studio was opened and closed (a renderer context issue, not the colour code's)
    settings = replace(DRIFT_SETTINGS, seconds=3.0, drift_start_s=0.3, drift_s=2.0)
    result = run_drift(settings, every=10)
    assert result.adaptive.identified_at == 0 and result.fixed.identified_at == 0
    assert result.adaptive.swaps.sum() == 0
    measured, _, lost = result.adaptive.shares()
    assert lost.max() == 0.0 and measured.min() > 0.95
    assert not result.adaptive.unmeasured_at_end().any()
    assert result.fixed.unmeasured_at_end().sum() >= 3  # the magenta markers
