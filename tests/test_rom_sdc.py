"""The smallest detectable change: its statistic, its words, the markers put on again, the content
key validated at load, and a short measurement on the simulated patient (tuning seeds only)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from game.rom.sdc import SDC_FACTOR, change_words, is_real_change, measure_sdc, sdc_from_results
from game.rom.spec import available_rom_tests, load_rom_test
from tracking.errors import ContentError
from tracking.sim.population import REPORTED_SEEDS_FROM


def test_sem_and_sdc95_of_repeated_results():
    values = [100.0, 102.0, 98.0, 101.0, 99.0]
    e = sdc_from_results(values + [math.nan])          # a test that did not finish is left out
    sd = float(np.std(values, ddof=1))
    assert e.n == 5 and e.sem_deg == pytest.approx(sd) and e.sdc95_deg == pytest.approx(1.96 * math.sqrt(2) * sd)
    assert e.sem_ci_deg[0] < sd < e.sem_ci_deg[1] and (e.min_deg, e.max_deg) == (98.0, 102.0)
    assert SDC_FACTOR == pytest.approx(2.772, abs=1e-3)
    with pytest.raises(ValueError):
        sdc_from_results([1.0, 2.0])


def test_change_words():
    assert change_words(8.2, 9.0) == ("+8 degrees: within the measurement's smallest detectable change of 9 degrees "
                                      "\u2014 not a real change yet")
    assert change_words(-12.0, 9.0) == "-12 degrees: beyond the smallest detectable change of 9 degrees \u2014 a real loss"
    assert change_words(12.0, 9.0).endswith("a real improvement")
    assert change_words(1.0, 3.0).startswith("+1 degree: within")
    assert change_words(0.0, 3.0).startswith("\u00b10 degrees: within")
    assert change_words(8.0, None) == "+8 degrees (no smallest detectable change measured for this test: not judged)"
    assert (is_real_change(9.5, 9.0), is_real_change(-9.0, 9.0), is_real_change(50.0, None)) == (True, False, None)


def test_every_rom_test_has_a_measured_sdc_from_reported_seeds():
    for name in available_rom_tests():
        t = load_rom_test(name)
        assert t.sdc_deg is not None and 0 < t.sdc_deg < 45, name
    from game.rom.spec import _RomTestSpec
    from tracking.content_loader import load_model, resolve

    for name in available_rom_tests():
        spec = load_model(resolve("rom_tests", name), _RomTestSpec)
        first = int(spec.sdc.seeds.split("-")[0])
        assert first >= REPORTED_SEEDS_FROM, name   # tuning seeds are never reported


def _with_sdc(tmp_path, sdc: str, name: str = "x"):
    from content import content_path

    text = (content_path("rom_tests") / "elbow_flexion.yaml").read_text(encoding="utf-8")
    body = "\n".join(line for line in text.splitlines() if not line.startswith("sdc:"))
    path = tmp_path / f"elbow_flexion_{name}.yaml"   # a new name each: loaded tests are cached by path
    path.write_text(body + "\n" + sdc + "\n", encoding="utf-8")
    return path


def test_the_sdc_key_is_validated_at_load(tmp_path):
    good = "sdc: {sdc95_deg: 2.8, sem_deg: 1.0, n: 10, side: right, seeds: 100000-100009, measured: 2026-11-27}"
    assert load_rom_test(_with_sdc(tmp_path, good)).sdc_deg == 2.8
    for bad, words in [
        ("sdc: {sdc95_deg: 5.0, sem_deg: 1.0, n: 10, side: right, seeds: 100000-100009, measured: 2026-11-27}",
         "is not 1.96 * sqrt(2) * sem_deg"),
        ("sdc: {sdc95_deg: 2.8, sem_deg: 1.0, n: 10, side: right, seeds: 100000-100004, measured: 2026-11-27}",
         "fewer than n"),
        ("sdc: {sdc95_deg: 2.8, sem_deg: 1.0, n: 10, side: right, seeds: 100000-100009}", "measured"),
        ("sdc: {sdc95_deg: -1, sem_deg: 1.0, n: 10, side: right, seeds: 100000-100009, measured: 2026-11-27}",
         "sdc95_deg"),
    ]:
        with pytest.raises(ContentError) as info:
            load_rom_test(_with_sdc(tmp_path, bad, words.split()[0].strip("*_")))
        assert words in str(info.value) and "\n" not in str(info.value), bad


def test_markers_put_on_again_stay_on_their_body_part(tmp_path):
    from tracking.markerset import load_markerset
    from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose
    from tracking.sim.redonning import MAX_PLACEMENT_M, RedonnedBody

    ms = load_markerset()
    body = BodyModel(BodyDimensions.from_percentile(50.0, "female"), ms)
    a, b, again = RedonnedBody(body, 7), RedonnedBody(body, 8), RedonnedBody(body, 7)
    poses = [Pose(right=ArmPose.clinical(flexion_deg=f, elbow_flexion_deg=e, forearm_supination_deg=s))
             for f, e, s in ((0, 0, 0), (60, 45, 40), (120, 90, -60))]
    k = ms.names.index("MRW1")   # right radial styloid: on the forearm
    dist = []
    for pose in poses:
        off = a.offsets_m(pose)
        _, normal = body.landmarks_m(pose)
        lengths = np.linalg.norm(off, axis=1)
        assert np.all(lengths <= MAX_PLACEMENT_M + 1e-12) and lengths.max() > 0.003
        assert np.allclose(np.sum(off * normal, axis=1), 0.0, atol=1e-12)   # along the skin
        c = body.joint_centres_m(pose, "right")
        dist.append([np.linalg.norm(a.markers_m(pose)[k] - c[j]) for j in ("elbow", "wrist")])
        np.testing.assert_array_equal(off, again.offsets_m(pose))           # one donning, one placement
        assert not np.allclose(off, b.offsets_m(pose))                      # another donning, another
        scene = a.scene(pose)
        idx = scene.sphere_marker_index
        np.testing.assert_allclose(scene.sphere_centre_m[idx >= 0][np.argsort(idx[idx >= 0])], a.markers_m(pose))
    # the ball moves with the forearm: its distances to the elbow and the wrist centres stay
    np.testing.assert_allclose(dist, [dist[0]] * len(dist), atol=1e-9)


def test_a_short_measurement_on_tuning_seeds():
    """Three sessions of the forearm supination test through the renderer and the tracker."""
    test = load_rom_test("forearm_supination")
    seen = []
    m = measure_sdc(test, "right", range(11, 14), fps=15.0, on_draw=seen.append)
    assert [d.seed for d in m.draws] == [11, 12, 13] and seen == list(m.draws)
    done = [d for d in m.draws if not d.message]
    assert len(done) >= 2, [d.message for d in m.draws]
    for d in done:   # the recorded maximum follows the true markers of that donning
        assert abs(d.value_deg - d.true_deg) < 3.0 and 60.0 < d.value_deg < 110.0
    if m.estimate is not None:
        assert m.estimate.sdc95_deg == pytest.approx(SDC_FACTOR * m.estimate.sem_deg)
