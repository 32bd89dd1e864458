"""Identification of the markers on the first frame from the marker set's rules (docs/METHOD.md 5.2).

Rule language -> exact truth positions (bodies, arm perturbations, turned patient, moved origin,
one colour) -> wrong poses and missing markers (one-line therapist messages) -> points measured
on rendered images of every rig.
"""

import math
import re
import time

import numpy as np
import pytest
import yaml

from calibration.errors import RehabError
from content import content_path
from tracking.colour.table import ColourTable
from tracking.errors import ContentError
from tracking.labelling.rules import (
    IdentificationError,
    Identifier,
    identify,
    identify_over_frames,
    try_identify,
)
from tracking.labelling.search import bitsets
from tracking.labelling.words import colour_word
from tracking.markerset import DistanceRule, OrderRule, load_markerset
from tracking.full_frame import FrameMeasurer
from tracking.reconstruction import Points3D
from tracking.sim.body import (
    REFERENCE_ABDUCTION_DEG,
    REFERENCE_ELBOW_FLEXION_DEG,
    REFERENCE_EXTERNAL_ROTATION_DEG,
    REFERENCE_SUPINATION_DEG,
    ArmPose,
    BodyDimensions,
    BodyModel,
    Pose,
    reference_arm,
    reference_pose,
)
from tracking.sim.rigs import load_rig
from tracking.sim.studio import Studio

MS = load_markerset()
ONE = MS.with_colours([(0, 200, 70)])
BODIES = [(5, "female"), (30, "female"), (70, "female"), (5, "male"), (50, "male"), (95, "male")]
YAML = content_path("markersets", "upper_limb_seated.yaml")


def model(p=50, sex="female") -> BodyModel:
    return BodyModel(BodyDimensions.from_percentile(p, sex), MS)


def turn(p_m: np.ndarray, yaw_deg: float, shift_m=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Points of a patient turned by ``yaw_deg`` about +Y (right-hand rule), then moved."""
    a = math.radians(yaw_deg)
    rot = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    return p_m @ rot.T + np.asarray(shift_m)


def perturbed_arm(rng: np.random.Generator, deg: float = 10.0) -> ArmPose:
    d = rng.uniform(-deg, deg, 5)
    return reference_arm(REFERENCE_ABDUCTION_DEG + d[0], d[1], REFERENCE_EXTERNAL_ROTATION_DEG + d[2],
                         REFERENCE_ELBOW_FLEXION_DEG + d[3], REFERENCE_SUPINATION_DEG + d[4])


def shuffled(p_m: np.ndarray, markerset, rng):
    """Points in a random order with their colours, and the true point index of each marker."""
    perm = rng.permutation(len(p_m))
    return p_m[perm], markerset.colour_index[perm], np.argsort(perm)


# --------------------------------------------------------------------------- rule language


def test_the_default_marker_set_states_the_seed_rules():
    rules = MS.identification
    assert rules is not None and "thumbs pointing forward" in rules.reference_pose
    texts = {r.text for r in rules.rules}
    # the seed's rules (docs/METHOD.md 5.2), each side expanded from the '*' wildcard
    for text in ("MB, MP < MLS, MLE1, MLE2, MLW1, MLW2, MLH along outward",
                 "MB, MP < MRS, MRE1, MRE2, MRW1, MRW2, MRH along outward",
                 "MLH < MLW1, MLW2 along outward", "MRH < MRW1, MRW2 along outward", "MP < MB along y",
                 "MLH, MLW1, MLW2 < MLE1, MLE2 along y", "MRE1, MRE2 < MRS along y",
                 "MLE1 < MLE2 along z", "MRW1 < MRW2 along z"):
        assert text in texts, text
    outward = {r.text: r.sign for r in rules.rules if isinstance(r, OrderRule) and "outward" in r.text}
    assert outward["MLH < MLW1, MLW2 along outward"] == -1 and outward["MRH < MRW1, MRW2 along outward"] == 1
    assert any(isinstance(r, DistanceRule) for r in rules.rules)
    for r in rules.rules:
        assert "\n" not in r.message and "*" not in r.message and "{side}" not in r.message
        assert set(n for g in r.groups for n in g) <= set(MS.names)
    left_wrist = next(r for r in rules.rules if r.text == "MLH < MLW1, MLW2 along outward")
    assert left_wrist.message.startswith("the left wrist is not outside the left hip")
    assert ONE.identification is rules  # --marker-color keeps the rules


def _write(tmp_path, edit) -> str:
    data = yaml.safe_load(YAML.read_text())
    edit(data["identification"])
    path = tmp_path / "custom.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return str(path)


@pytest.mark.parametrize("edit, expect", [
    (lambda d: d.update(reference_posture="x"), "identification.reference_posture: unknown key"),
    (lambda d: d["rules"][1].update(order="M*H < M*W3"), "unknown marker 'MLW3'"),
    (lambda d: d["rules"][2].update(order="MP"), "at least two groups"),
    (lambda d: d["rules"][2].update(along="sideways"), "identification.rules.2.along"),
    (lambda d: d["rules"][2].update(along="outward"), "needs the side wildcard"),
    (lambda d: d["rules"][2].update(within_mm=[10, 20]), "either 'order' with 'along', or 'distance'"),
    (lambda d: d["rules"][-1].update(within_mm=[300, 100]), "min < max"),
    (lambda d: d["rules"][0].update(message="  "), "message"),
    (lambda d: d.update(left_right_pairs=[["MLS", "MXS"]]), "left_right_pairs.0: unknown marker 'MXS'"),
    (lambda d: d.pop("sides"), "'*' needs 'sides'"),
])
def test_bad_rules_are_one_line_errors_naming_the_key(tmp_path, edit, expect):
    with pytest.raises(ContentError) as err:
        load_markerset(_write(tmp_path, edit))
    msg = str(err.value)
    assert expect in msg and "custom.yaml" in msg and "\n" not in msg


def test_rules_are_not_tied_to_fourteen_markers(tmp_path):
    """A three-marker set, one chain rule: the general search labels it."""
    path = tmp_path / "tiny.yaml"
    colours = {"TOP": [255, 0, 0], "MID": [0, 255, 0], "LOW": [0, 0, 255]}
    path.write_text(yaml.safe_dump({
        "name": "tiny", "marker_diameter_mm": 30,
        "markers": [{"name": n, "colour": c, "segment": "arm"} for n, c in colours.items()],
        "identification": {"reference_pose": "arm down", "left_right_pairs": [["LOW", "TOP"]], "max_turn_deg": 89,
                           "rules": [{"order": "LOW < MID < TOP", "along": "y", "message": "hold the arm down"}]},
    }))
    ms = load_markerset(str(path))
    p = np.array([[0.0, 0.5, 0.0], [0.05, 1.4, 0.0], [0.02, 0.9, 0.01]])  # LOW, TOP, MID in point order
    col = np.array([2, 0, 1])
    result = identify(p, col, ms)
    assert result.index.tolist() == [1, 2, 0] and result.margin_m == pytest.approx(0.4)
    with pytest.raises(IdentificationError, match="^hold the arm down"):
        identify(p * [1, -1, 1], col, ms)


def test_colour_words():
    assert [colour_word(c) for c in MS.palette] == ["yellow", "magenta", "green", "cyan"]
    assert colour_word((200, 30, 30)) == "red" and colour_word((128, 128, 128)) == "grey"


# --------------------------------------------------------------------------- exact truth positions


@pytest.mark.parametrize("p, sex", BODIES)
@pytest.mark.parametrize("markerset", [MS, ONE], ids=["4colours", "1colour"])
def test_truth_positions_are_identified(p, sex, markerset):
    """Each arm perturbed by up to +-10 degrees on its own, the patient turned by up to +-15
    degrees, the origin anywhere: every marker gets its own point."""
    rng = np.random.default_rng(p * 7 + len(sex))
    body = model(p, sex)
    identifier = Identifier(markerset)
    for _ in range(6):
        pose = Pose(right=perturbed_arm(rng), left=perturbed_arm(rng))
        yaw = rng.uniform(-15, 15)
        pts, col, truth = shuffled(turn(body.markers_m(pose), yaw, rng.uniform(-50, 50, 3)), markerset, rng)
        result = identifier.identify(pts, col)
        assert result.index.tolist() == truth.tolist()
        assert result.margin_m >= 0.01  # every rule holds with room to spare, beyond its own margin
        assert result.yaw_deg == pytest.approx(yaw, abs=1.5)
        assert result.rule_margins_m.shape == (len(markerset.identification.rules),)


def test_one_colour_search_is_fast():
    rng = np.random.default_rng(3)
    identifier = Identifier(ONE)
    pts, col, truth = shuffled(turn(model(50, "male").markers_m(reference_pose()), 12.0), ONE, rng)
    times = []
    for _ in range(7):
        t0 = time.perf_counter()
        result = identifier.identify(pts, col)
        times.append(time.perf_counter() - t0)
    assert result.index.tolist() == truth.tolist()
    assert np.median(times) < 0.050, f"{np.median(times) * 1000:.1f} ms"


@pytest.mark.parametrize("yaw", [-29.0, 25.0])
def test_turned_within_the_limit(yaw):
    pts = turn(model(5, "female").markers_m(reference_pose()), yaw)
    assert identify(pts, MS.colour_index, MS).index.tolist() == list(range(14))


@pytest.mark.parametrize("yaw, side", [(-40.0, "right"), (35.0, "left"), (60.0, "left")])
def test_turned_too_far_says_so(yaw, side):
    pts = turn(model(50, "female").markers_m(reference_pose()), yaw)
    for ms in (MS, ONE):
        with pytest.raises(IdentificationError, match=f"turned {abs(yaw):.0f} degrees to the {side}"):
            identify(pts, ms.colour_index, ms)


def test_non_finite_points_are_ignored():
    p = model().markers_m(reference_pose())
    pts = np.vstack([p, [[np.nan, 1.0, 0.0]]])
    col = np.append(MS.colour_index, 0)
    assert identify(pts, col, MS).index.tolist() == list(range(14))


# --------------------------------------------------------------------------- wrong poses


# (pose, the words the therapist is told (a regular expression); both sides break a symmetric pose)
WRONG_POSES = {
    "hands in the lap, inside the hips": (
        Pose(right=ArmPose.clinical(0, 5, -45, 30, 0), left=ArmPose.clinical(0, 5, -45, 30, 0)),
        r"the (left|right) wrist is not outside the \1 hip: move the \1 arm slightly away from the body"),
    "arms raised": (
        Pose(right=ArmPose.clinical(0, 150, 0, 0, 0), left=ArmPose.clinical(0, 150, 0, 0, 0)),
        r"the (left|right) elbow is not below the \1 shoulder: lower the \1 arm to the side"),
    "right arm raised": (
        reference_pose().with_arm("right", ArmPose.clinical(0, 120, 0, 0, 0)),
        "the right elbow is not above the right wrist and hip"),
    "elbows bent": (reference_pose(elbow_flexion_deg=95), r"the (left|right) elbow is not above the \1 wrist and hip"),
    "palms back": (reference_pose(forearm_supination_deg=-90), r"turn the (left|right) hand so that the thumb points forward"),
    "arms crossed in front": (
        Pose(right=ArmPose.clinical(40, -20, -60, 90, 0), left=ArmPose.clinical(40, -20, -60, 90, 0)), None),
}


@pytest.mark.parametrize("name", sorted(WRONG_POSES))
@pytest.mark.parametrize("p, sex", [(5, "female"), (95, "male")])
def test_wrong_pose_is_a_one_line_therapist_message(name, p, sex):
    pose, words = WRONG_POSES[name]
    pts = turn(model(p, sex).markers_m(pose), 8.0, (1.0, 0.2, -2.0))
    rng = np.random.default_rng(1)
    pts, col, _ = shuffled(pts, MS, rng)
    with pytest.raises(IdentificationError) as err:
        identify(pts, col, MS)
    msg = str(err.value)
    assert "\n" not in msg and isinstance(err.value, RehabError)
    messages = [r.message for r in MS.identification.rules]
    assert any(msg.startswith(m) for m in messages), msg  # one of the rules, in plain words
    if words is not None:
        assert re.search(words, msg), msg


@pytest.mark.parametrize("name", ["hands in the lap, inside the hips", "arms raised", "elbows bent",
                                  "arms crossed in front"])
def test_wrong_pose_with_one_colour_raises_too(name):
    pose, words = WRONG_POSES[name]
    with pytest.raises(IdentificationError) as err:
        identify(model(50, "male").markers_m(pose), ONE.colour_index, ONE)
    assert "\n" not in str(err.value)


# --------------------------------------------------------------------------- missing points


def test_a_missing_point_names_its_colour_and_markers():
    p = model().markers_m(reference_pose())
    keep = np.arange(14) != MS.index("MP")
    with pytest.raises(IdentificationError) as err:
        identify(p[keep], MS.colour_index[keep], MS)
    msg = str(err.value)
    assert msg.startswith("3 of the 4 yellow markers are seen: the hidden one must be seen by two cameras")
    assert "MB, MP, MLH, MRH" in msg and "\n" not in msg
    with pytest.raises(IdentificationError, match="13 of the 14 green markers are seen"):
        identify(p[keep], ONE.colour_index[keep], ONE)


def test_an_extra_point_is_named_too():
    p = model().markers_m(reference_pose())
    pts = np.vstack([p, [[0.0, 1.5, 0.0]]])
    with pytest.raises(IdentificationError, match="5 yellow points are seen but there are 4 yellow markers"):
        identify(pts, np.append(MS.colour_index, 0), MS)


def _points(p_m, colour) -> Points3D:
    n = len(p_m)
    return Points3D(p_m, np.asarray(colour), np.full(n, 2), np.zeros(n), np.full((n, 4), -1))


def test_the_tracker_waits_for_certain_names_and_is_told_about_a_wrong_pose():
    p = model().markers_m(reference_pose())
    identifier = Identifier(MS)
    # four markers unseen: more than may be left for re-acquisition
    keep = ~np.isin(np.arange(14), [MS.index(n) for n in ("MLW2", "MRW2", "MRE2", "MLE2")])
    partial = _points(p[keep], MS.colour_index[keep])
    full = _points(p, MS.colour_index)
    assert try_identify(partial, identifier) is None
    assert try_identify(full, identifier).index.tolist() == list(range(14))
    n, result = identify_over_frames([partial, partial, full], MS)
    assert n == 2 and result.index.tolist() == list(range(14))
    with pytest.raises(IdentificationError, match="no frame of the first 2 shows every marker: 0 of the 4 cyan"):
        identify_over_frames([partial] * 5, MS, max_frames=2)
    raised = _points(model().markers_m(WRONG_POSES["arms raised"][0]), MS.colour_index)
    with pytest.raises(IdentificationError, match="lower the left arm"):
        identify_over_frames([partial, raised, full], MS)


# --------------------------------------------------------------------------- measured points


RIGS = ["ring4", "front4", "corners4", "tri3", "front3", "wall3"]
MEASURED_BODIES = [(5, "female"), (50, "female"), (95, "male")]


@pytest.fixture(scope="module")
def measured():
    """Points measured on rendered 320x240 images of the reference pose: {(rig, p, sex): (points, truth)}."""
    table = ColourTable.build(MS.palette)
    out = {}
    for rig in RIGS:
        cameras = load_rig(rig, (320, 240))
        for p, sex in MEASURED_BODIES:
            with Studio(cameras, MS, BodyDimensions.from_percentile(p, sex)) as studio:
                frame = studio.render(reference_pose(), 0, 0.0, noise_sigma=1.5, seed=p)
                points = FrameMeasurer(studio.cameras, table, MS.radius_m).measure(frame.frames.images)
            out[rig, p, sex] = (points, frame.markers_m)
    return out


def _measured_markers(points: Points3D, truth_m: np.ndarray) -> np.ndarray:
    """(M,) bool: a measured point lies within 10 mm of the marker."""
    d = np.linalg.norm(points.p_world_m[:, None] - truth_m[None], axis=-1)
    return d.min(axis=0) < 0.010


@pytest.mark.parametrize("rig", RIGS)
def test_measured_points_are_identified_or_the_missing_colour_is_named(measured, rig):
    """Where every marker is measured the labels are right (also with the points turned and
    moved, and all of one colour); where the rig misses some, the tracker's names (if any) are
    right and the strict identification names the missing colour."""
    rng = np.random.default_rng(7)
    identifier, one = Identifier(MS), Identifier(ONE)
    for p, sex in MEASURED_BODIES:
        points, truth_m = measured[rig, p, sex]
        seen = _measured_markers(points, truth_m)
        if seen.all() and len(points) == MS.n_markers:
            for yaw in (0.0, rng.uniform(-15, 15)):
                pts = turn(points.p_world_m, yaw, rng.uniform(-5, 5, 3))
                for ide, col in ((identifier, points.colour), (one, np.zeros(len(pts), int))):
                    result = ide.identify(pts, col)
                    d = np.linalg.norm(points.p_world_m[result.index] - truth_m, axis=1)
                    assert d.max() < 0.010, (rig, p, sex, yaw, MS.names[int(np.argmax(d))])
                    assert result.margin_m > 0.0
        else:
            result = try_identify(points, identifier)
            if result is not None:  # named without the unseen markers: every name given is right
                named = result.index >= 0
                pts_named = points.p_world_m[result.index[named]]
                nearest = np.linalg.norm(pts_named[:, None] - truth_m[None], axis=-1).argmin(axis=1)
                assert (nearest == np.flatnonzero(named)).all(), (rig, p, sex)
                # on its own ball (a partly hidden ball's point may be more than 10 mm off)
                assert np.linalg.norm(pts_named - truth_m[named], axis=1).max() < 0.02, (rig, p, sex)
                assert not seen[~named].any(), (rig, p, sex)
            with pytest.raises(IdentificationError) as err:
                identifier.identify(points.p_world_m, points.colour)
            missing_colours = {identifier.words[c] for c in MS.colour_index[~seen]}
            for word in missing_colours:
                assert f"{word} markers are seen" in str(err.value), (rig, p, sex, str(err.value))


def test_the_default_rig_measures_and_identifies_every_marker(measured):
    """ring4 (the seed's layout) sees all 14 markers of the mid and large bodies."""
    for p, sex in [(50, "female"), (95, "male")]:
        points, truth_m = measured["ring4", p, sex]
        result = identify(points.p_world_m, points.colour, MS)
        d = np.linalg.norm(points.p_world_m[result.index] - truth_m, axis=1)
        assert d.max() < 0.010


def test_bitsets_beyond_62_points_match_the_fast_path():
    rng = np.random.default_rng(0)
    ok = rng.random((3, 70, 70)) < 0.5
    big = bitsets(ok)
    for k in range(3):
        for p in range(70):
            assert big[k][p] == sum(1 << q for q in range(70) if ok[k, p, q])
    small = bitsets(ok[:, :10, :10])
    assert small[1][4] == sum(1 << q for q in range(10) if ok[1, 4, q])
