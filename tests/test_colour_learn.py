"""Learned colour tables: the incremental rewrite, background exclusion, the colour file."""

import dataclasses

import numpy as np
import pytest

from calibration.errors import RehabError
from tracking.colour.adapt import load_colours, nominal_models, read_colours, save_colours
from tracking.colour.learn import ColourStats, LutBuilder, fit_models, hsv_bytes, label_hue_saturation
from tracking.colour.table import ColourTable
from tracking.markerset import load_markerset


@pytest.fixture(scope="module")
def markerset():
    return load_markerset("upper_limb_seated")


@pytest.fixture(scope="module")
def builder(markerset):
    return LutBuilder(markerset.palette.shape[0])


def shaded(rgb, n, rng, lo=0.3, hi=1.0, noise=2.0):
    """(n, 3) BGR pixels of an sRGB colour at random brightness, with noise."""
    scale = rng.uniform(lo, hi, (n, 1))
    px = np.asarray(rgb, float)[None, ::-1] * scale + rng.normal(0, noise, (n, 3))
    return np.clip(px.round(), 0, 255).astype(np.uint8)


def labels_of(lut, px_bgr):
    words = px_bgr[:, 0].astype(np.uint32) | px_bgr[:, 1].astype(np.uint32) << 8 | px_bgr[:, 2].astype(np.uint32) << 16
    return lut[words]


def test_nominal_models_reproduce_the_nominal_table(builder, markerset):
    lut = builder.build(label_hue_saturation(nominal_models(markerset.palette))).copy()
    nominal = ColourTable.build(markerset.palette).lut
    # the noise margin is a floor of its own here (not added to the saturation floor): 1 % differ
    assert np.mean(lut == nominal) > 0.985
    rng = np.random.default_rng(1)
    for k, rgb in enumerate(markerset.palette):
        px = shaded(rgb, 2000, rng)
        assert np.mean(labels_of(lut, px) == k + 1) > 0.99


def test_incremental_update_and_chunked_apply_equal_a_full_build(builder, markerset):
    models = nominal_models(markerset.palette)
    builder.build(label_hue_saturation(models))
    rng = np.random.default_rng(2)
    stats = ColourStats(len(models))
    stats.add(0, hsv_bytes(shaded((200, 120, 40), 5000, rng)))  # saturated orange clothes
    moved = [dataclasses.replace(m, hue_deg=(m.hue_deg + 7) % 360, sat_floor=0.6) for m in models]
    target = label_hue_saturation(moved, stats)
    queued = builder.stage(target)
    assert queued > 10_000
    rewritten = 0
    while builder.pending.size:
        rewritten += builder.apply(5000)
    assert rewritten == queued
    incremental = builder.lut.copy()
    full = LutBuilder(len(models)).build(target)
    assert np.array_equal(incremental, full)
    assert builder.update(target) == 0  # nothing changed: nothing rewritten


def test_learning_keeps_a_marker_and_leaves_clothes_of_its_hue_out(builder, markerset):
    rng = np.random.default_rng(3)
    k_yellow = 0
    assert tuple(markerset.palette[k_yellow]) == (255, 214, 0)
    stats = ColourStats(markerset.palette.shape[0])
    for k, rgb in enumerate(markerset.palette):
        stats.add(k + 1, hsv_bytes(shaded(rgb, 3000, rng)))
    clothes = (230, 160, 20)  # saturated orange, 40 deg: inside the nominal yellow's 20 deg band
    skin = (224, 172, 140)
    background = np.concatenate([shaded(clothes, 4000, rng, 0.4, 1.0), shaded(skin, 4000, rng),
                                 shaded((90, 90, 100), 4000, rng)])
    stats.add(0, hsv_bytes(background))
    models = fit_models(stats)
    for m, rgb in zip(models, markerset.palette):
        nominal_hue = nominal_models(np.array([rgb], np.uint8))[0].hue_deg
        assert abs((m.hue_deg - nominal_hue + 180) % 360 - 180) < 3.0
    lut = builder.build(label_hue_saturation(models, stats))
    test_clothes = shaded(clothes, 3000, rng, 0.4, 1.0)
    nominal = ColourTable.build(markerset.palette).lut
    assert np.mean(labels_of(nominal, test_clothes) == k_yellow + 1) > 0.5  # the nominal table takes them
    assert np.mean(labels_of(lut, test_clothes) != 0) < 0.01
    assert np.mean(labels_of(lut, shaded(skin, 3000, rng)) != 0) < 0.001
    for k, rgb in enumerate(markerset.palette):
        assert np.mean(labels_of(lut, shaded(rgb, 3000, rng, 0.35, 1.0)) == k + 1) > 0.97


def test_colour_file_round_trip_and_errors(builder, markerset, tmp_path):
    models = [dataclasses.replace(m, hue_deg=(m.hue_deg + 5) % 360) for m in nominal_models(markerset.palette)]
    labels = label_hue_saturation(models)
    path = tmp_path / "colours.toml"
    save_colours(path, markerset, models, labels)
    read_models, read_labels = read_colours(path, markerset)
    assert np.array_equal(read_labels, labels)
    assert [round(m.hue_deg, 2) for m in read_models] == [round(m.hue_deg, 2) for m in models]
    table = load_colours(path, markerset)
    assert np.array_equal(table.lut, LutBuilder(len(models)).build(labels))
    other = markerset.with_colours([(255, 0, 0)])
    with pytest.raises(RehabError, match="learn them again"):
        load_colours(path, other)
    with pytest.raises(RehabError, match="no such colour file"):
        load_colours(tmp_path / "missing.toml", markerset)
    (tmp_path / "bad.toml").write_text("colour = 3\n")
    with pytest.raises(RehabError, match="not a learned colour file"):
        load_colours(tmp_path / "bad.toml", markerset)
