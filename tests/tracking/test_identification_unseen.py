"""Identification with markers unseen (seen by one camera only in the reference pose): the seen
ones are named right or not at all, wrong poses are never named, and the distance rules place an
unseen marker later. Exact truth positions, no rendering."""

import itertools

import numpy as np
import pytest

from tracking.labelling.rules import IdentificationError, Identifier
from tracking.markerset import load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose, reference_pose
from tracking.sim.identify_sweep import perturbed_poses, seat_clash, wrong_poses

MS = load_markerset()
INNER = ("MLE2", "MRE2", "MLW2", "MRW2")


def _drop(p_m, names):
    keep = ~np.isin(np.arange(MS.n_markers), [MS.index(n) for n in names])
    return p_m[keep], MS.colour_index[keep], np.flatnonzero(keep)


@pytest.mark.parametrize("p, sex", [(5, "female"), (95, "male")])
def test_seen_markers_are_named_right_or_not_at_all(p, sex):
    """Every perturbed reference pose with one to three inner markers unseen: whatever is named is
    right, and with the unperturbed pose the names are given."""
    body = BodyModel(BodyDimensions.from_percentile(p, sex), MS)
    identifier = Identifier(MS)
    named_cases = cases = 0
    for case in perturbed_poses(n_corners=4, n_random=2):
        if seat_clash(body, case.pose, MS):
            continue
        p_m = body.markers_m(case.pose)
        for k in (1, 2, 3):
            for unseen in itertools.islice(itertools.combinations(INNER, k), 3):
                pts, col, point_marker = _drop(p_m, unseen)
                result = identifier.identify_with_unseen(pts, col)
                cases += 1
                if result is None:
                    assert case.name != "reference" or k < 3, (case.name, unseen)
                    continue
                named_cases += 1
                named = result.index >= 0
                assert sorted(np.array(MS.names)[~named]) == sorted(unseen)
                assert (point_marker[result.index[named]] == np.flatnonzero(named)).all(), (case.name, unseen)
    assert named_cases > 0.8 * cases


@pytest.mark.parametrize("p, sex", [(5, "female"), (50, "male"), (95, "male")])
@pytest.mark.parametrize("case", wrong_poses(), ids=lambda c: c.name)
def test_wrong_poses_with_hidden_markers_are_never_named(p, sex, case):
    body = BodyModel(BodyDimensions.from_percentile(p, sex), MS)
    identifier = Identifier(MS)
    p_m = body.markers_m(case.pose)
    for k in (0, 1, 2, 3):
        for unseen in itertools.islice(itertools.combinations(INNER, k), 2):
            pts, col, _ = _drop(p_m, unseen)
            try:
                assert identifier.identify_with_unseen(pts, col) is None, (case.name, unseen)
            except IdentificationError as err:
                assert "\n" not in str(err)


def test_hands_on_the_thighs_is_explained_with_the_inner_wrist_markers_hidden():
    """The rendered pose hides MLW2 and MRW2: the wrist rule still speaks."""
    pose = wrong_poses()[0].pose
    pts, col, _ = _drop(BodyModel(BodyDimensions.from_percentile(95, "male"), MS).markers_m(pose), ("MLW2", "MRW2"))
    with pytest.raises(IdentificationError, match=r"the (left|right) wrist is not outside the \1 hip"):
        Identifier(MS).identify_with_unseen(pts, col)


def test_a_swap_that_the_missing_marker_would_have_caught_is_not_named():
    """Hands on the thighs (wrists above the elbows) with both inner elbow markers hidden: swapping
    the elbow and wrist markers keeps every rule, but only within a few mm."""
    arm = ArmPose.clinical(20.0, 0.0, -30.0, 70.0, 0.0)
    p_m = BodyModel(BodyDimensions.from_percentile(50, "male"), MS).markers_m(Pose(right=arm, left=arm))
    pts, col, _ = _drop(p_m, ("MLW2", "MRW2"))
    try:
        assert Identifier(MS).identify_with_unseen(pts, col) is None
    except IdentificationError:
        pass


def test_more_unseen_than_allowed_waits_and_strays_wait():
    p_m = BodyModel(BodyDimensions.from_percentile(50, "female"), MS).markers_m(reference_pose())
    identifier = Identifier(MS, max_unseen=1)
    pts, col, _ = _drop(p_m, ("MLE2", "MRE2"))
    assert identifier.identify_with_unseen(pts, col) is None
    assert Identifier(MS).identify_with_unseen(pts, col) is not None
    stray = np.vstack([p_m, [[0.0, 1.6, -0.3]]])
    assert identifier.identify_with_unseen(stray, np.append(MS.colour_index, 0)) is None


def test_distance_rules_place_an_unseen_marker():
    p_m = BodyModel(BodyDimensions.from_percentile(50, "female"), MS).markers_m(reference_pose())
    identifier = Identifier(MS)
    m = MS.index("MRE2")
    known = np.ones(MS.n_markers, bool)
    known[m] = False
    cands = np.stack([p_m[m], p_m[MS.index("MLE2")], p_m[MS.index("MRW2")], p_m[m] + [0.0, 0.3, 0.0]])
    fit = identifier.distance_fit_m(m, cands, p_m, known)
    assert fit[0] > 0.0 and (fit[1:] < 0.0).all()
    assert np.isinf(identifier.distance_fit_m(m, cands, p_m, np.zeros(MS.n_markers, bool))).all()
