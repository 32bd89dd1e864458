"""Labelling as a body-model fit (tracking.labelling): right on bodies, placements and poses it was
not tuned on, confident only when it is, and never wrong where it is confident."""

import warnings

import numpy as np
import pytest

from tracking.labelling import Labeller
from tracking.markerset import load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose, reference_arm, reference_pose
from tracking.sim.population import ONE_COLOUR_RGB, label_draws

FOUR = load_markerset()
ONE = FOUR.with_colours([ONE_COLOUR_RGB])


def _label(ms, p, rng, unseen=()):
    seen = np.setdiff1d(np.arange(ms.n_markers), unseen)
    order = rng.permutation(seen)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        lab = Labeller.for_markerset(ms).label(p[order], ms.colour_index[order])
    named = np.where(lab.index >= 0, order[np.maximum(lab.index, 0)], -1) if lab.index is not None else None
    return lab, named


def _arm(**kw):
    base = dict(abduction_deg=16.0, external_rotation_deg=-25.0, elbow_flexion_deg=10.0, forearm_supination_deg=25.0)
    base.update(kw)
    # the thumb stays forward: the forearm turns back what the upper arm turns
    base.setdefault("forearm_supination_deg", -base["external_rotation_deg"])
    return reference_arm(base["abduction_deg"], 0.0, base["external_rotation_deg"], base["elbow_flexion_deg"],
                         -base["external_rotation_deg"])


VARIATIONS = {
    "reference": reference_pose(),
    "elbow creases forward (upper arm not turned in)": Pose(right=_arm(external_rotation_deg=0.0),
                                                            left=_arm(external_rotation_deg=0.0)),
    "turned in 60": Pose(right=_arm(external_rotation_deg=-60.0), left=_arm(external_rotation_deg=-60.0)),
    "turned out 15": Pose(right=_arm(external_rotation_deg=15.0), left=_arm(external_rotation_deg=15.0)),
    "arms 5 from the body": Pose(right=_arm(abduction_deg=5.0), left=_arm(abduction_deg=6.0)),
    "arms 40 from the body": Pose(right=_arm(abduction_deg=40.0), left=_arm(abduction_deg=38.0)),
    "elbows flexed 30": Pose(right=_arm(elbow_flexion_deg=30.0), left=_arm(elbow_flexion_deg=30.0)),
    "leaning forward 15": Pose(trunk_forward_lean_deg=15.0, right=_arm(), left=_arm()),
    "slouching back 10": Pose(trunk_forward_lean_deg=-10.0, right=_arm(), left=_arm()),
    "leaning sideways 15": Pose(trunk_lateral_lean_deg=15.0, right=_arm(abduction_deg=25.0), left=_arm()),
    "trunk turned 15": Pose(trunk_axial_rotation_deg=15.0, right=_arm(), left=_arm()),
    "arms unequal": Pose(right=_arm(abduction_deg=30.0, external_rotation_deg=-50.0, elbow_flexion_deg=25.0),
                         left=_arm(abduction_deg=8.0, external_rotation_deg=5.0, elbow_flexion_deg=2.0)),
}


BODIES = [(5, "female"), (50, "female"), (50, "male"), (95, "male")]


def _variations(ms):
    out = {}
    for body in BODIES:
        for name, pose in VARIATIONS.items():
            p = BodyModel(BodyDimensions.from_percentile(*body), ms).markers_m(pose)
            rng = np.random.default_rng(3)
            out[body, name] = _label(ms, p + rng.normal(scale=0.0015, size=p.shape), rng)
    return out


def test_pose_variations_four_colours():
    """Every variation of the reference pose within its tolerances, on four bodies: labelled, right."""
    for key, (lab, named) in _variations(FOUR).items():
        assert lab.confident, (key, lab.score, lab.worst)
        np.testing.assert_array_equal(named, np.arange(14), err_msg=str(key))


def test_pose_variations_one_colour():
    """The same with one colour for all markers: never wrong; labelled in nearly every case. The
    cases left waiting are smaller bodies holding the arms close to the body: the
    inner elbow marker then lies near the hip marker, and exchanging them breaks no range by much
    (docs/TRACKING.md, "Labelling as a fit")."""
    results = _variations(ONE)
    for key, (lab, named) in results.items():
        if lab.confident:
            np.testing.assert_array_equal(named, np.arange(14), err_msg=str(key))
    waiting = [key for key, (lab, _) in results.items() if not lab.confident]
    assert len(waiting) <= 0.15 * len(results), waiting
    assert all(body[1] == "female" for body, _ in waiting), waiting


@pytest.mark.parametrize("ms", [ONE, FOUR], ids=["one colour", "four colours"])
def test_placement_errors_of_15_mm(ms):
    """Every marker 15 mm off its landmark along the skin, in random directions, several draws."""
    body = BodyModel(BodyDimensions.from_percentile(50, "male"), ms)
    pose = VARIATIONS["elbow creases forward (upper arm not turned in)"]
    _, normal = body.landmarks_m(pose)
    for seed in range(8):
        rng = np.random.default_rng(seed)
        v = rng.normal(size=normal.shape)
        v -= np.sum(v * normal, axis=1, keepdims=True) * normal
        p = body.markers_m(pose) + 0.015 * v / np.linalg.norm(v, axis=1, keepdims=True)
        lab, named = _label(ms, p, rng)
        assert lab.confident and np.array_equal(named, np.arange(ms.n_markers)), (seed, lab.worst)


def test_population_tuning_seeds_all_seen():
    """The tuning seeds of the population (tracking.sim.population), every marker seen: none wrong;
    all labelled with four colours, nearly all with one."""
    res = [r for r in label_draws(range(0, 200)) if r.n_unseen == 0]
    four = [r for r in res if not r.one_colour]
    one = [r for r in res if r.one_colour]
    assert len(four) > 20 and len(one) > 20
    assert sum(r.wrong for r in res) == 0
    assert all(r.confident for r in four), [(r.seed, r.worst) for r in four if not r.confident]
    assert sum(r.confident for r in one) >= 0.9 * len(one)


def test_unseen_markers_never_wrong():
    """With 1-2 markers without a point the labelling waits or leaves markers to join later; it never
    names a point wrongly."""
    res = [r for r in label_draws(range(200, 260)) if r.n_unseen > 0]
    assert sum(r.wrong for r in res) == 0
    four = [r for r in res if not r.one_colour and r.n_unseen == 1]
    assert four and sum(r.confident for r in four) >= 0.6 * len(four)


def test_unseen_inner_elbow_joins_later():
    p = BodyModel(BodyDimensions.from_percentile(50, "female"), FOUR).markers_m(reference_pose())
    lab, named = _label(FOUR, p, np.random.default_rng(0), unseen=(FOUR.index("MRE2"),))
    assert lab.confident
    expected = np.arange(14)
    expected[FOUR.index("MRE2")] = -1
    np.testing.assert_array_equal(named, expected)


@pytest.mark.parametrize("ms", [ONE, FOUR], ids=["one colour", "four colours"])
def test_pose_outside_the_tolerances_is_not_labelled(ms):
    raised = Pose(right=ArmPose.clinical(abduction_deg=90.0), left=ArmPose.clinical(abduction_deg=90.0))
    p = BodyModel(BodyDimensions.from_percentile(50, "female"), ms).markers_m(raised)
    lab, _ = _label(ms, p, np.random.default_rng(0))
    assert not lab.confident


def test_colours_decide():
    """With four colours no marker is ever given a point of another colour, whatever the geometry:
    two markers' colours exchanged in the points give a labelling that follows the colours or none."""
    p = BodyModel(BodyDimensions.from_percentile(50, "female"), FOUR).markers_m(reference_pose())
    colour = FOUR.colour_index.copy()
    lab = Labeller.for_markerset(FOUR).label(p, colour)
    assert lab.confident
    assert np.array_equal(colour[lab.index], FOUR.colour_index)


def _ray_to(ms, p, markers, seed=0, whole_share=1.0):
    from tracking.sim.population import single_camera_rays

    idx = [ms.index(m) for m in markers]
    return single_camera_rays(p[idx], ms.colour_index[idx], np.random.default_rng(seed), whole_share=whole_share)


@pytest.mark.parametrize("ms", [ONE, FOUR], ids=["one colour", "four colours"])
@pytest.mark.parametrize("hidden", [("MRE2",), ("MRW2",), ("MLE2", "MRW2")])
def test_markers_on_single_camera_rays(ms, hidden):
    """A marker seen by one camera lies on its blob's ray: with one colour its partner is named right
    (without the ray either marker of the pair could take the point), or nothing is named; never
    wrong. Several bodies and pose variations. With one colour and an inner wrist marker on a ray,
    the ray's range (the blob's size gives the distance within 8 %, +-16 cm at 2 m) often holds a
    place for the thumb-side marker too, with the pair exchanged: then nothing is named."""
    named_any = 0
    for body in ((5, "female"), (50, "male"), (95, "male")):
        for name in ("reference", "elbow creases forward (upper arm not turned in)", "elbows flexed 30",
                     "leaning sideways 15"):
            p = BodyModel(BodyDimensions.from_percentile(*body), ms).markers_m(VARIATIONS[name])
            rng = np.random.default_rng(5)
            p = p + rng.normal(scale=0.0015, size=p.shape)
            unseen = tuple(ms.index(m) for m in hidden)
            seen = np.setdiff1d(np.arange(ms.n_markers), unseen)
            order = rng.permutation(seen)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                lab = Labeller.for_markerset(ms).label(p[order], ms.colour_index[order], _ray_to(ms, p, hidden))
            if not lab.confident:
                continue
            named_any += 1
            named = np.where(lab.index >= 0, order[np.maximum(lab.index, 0)], -1)
            expected = np.arange(ms.n_markers)
            expected[list(unseen)] = -1
            np.testing.assert_array_equal(named, expected, err_msg=f"{body} {name}")
    assert named_any >= (0 if ms is ONE and any(h.endswith("W2") for h in hidden) else 8), named_any


def test_a_stray_ray_names_nothing_wrong():
    """A blob that is no marker (clutter seen by one camera) where a marker has no point: the fit
    places nothing on it that it cannot explain; whatever it names is right."""
    p = BodyModel(BodyDimensions.from_percentile(50, "female"), ONE).markers_m(reference_pose())
    rays = _ray_to(ONE, p + np.array([0.0, 0.0, 0.3]), ("MRE2",))  # 30 cm in front of the elbow
    seen = np.setdiff1d(np.arange(14), [ONE.index("MRE2")])
    lab = Labeller.for_markerset(ONE).label(p[seen], ONE.colour_index[seen], rays)
    if lab.confident:
        assert np.array_equal(np.where(lab.index >= 0, seen[np.maximum(lab.index, 0)], -1)[lab.index >= 0],
                              np.flatnonzero(lab.index >= 0))


def test_population_tuning_seeds_on_rays():
    """Tuning seeds with 1-2 markers without a point, each seen by one camera: never wrong; four
    colours nearly always named, one colour mostly (docs/TRACKING.md has the reported seeds)."""
    res = [r for r in label_draws(range(0, 60), rays=True) if r.n_unseen > 0]
    assert sum(r.wrong for r in res) == 0
    four = [r for r in res if not r.one_colour]
    one = [r for r in res if r.one_colour]
    assert sum(r.confident for r in four) >= 0.9 * len(four)
    assert sum(r.confident for r in one) >= 0.5 * len(one)
