"""The avatar's skeleton from markers: joint centres, frames, forearm rotation, states, proportions."""

from __future__ import annotations

import numpy as np
import pytest

from game.avatar.skeleton import JOINTS, SEGMENTS, SkeletonTracker
from tracking.angles import MissingMarkersError, joint_angles
from tracking.markerset import load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose, reference_pose
from tracking.marker_status import MarkerStatus

MS = load_markerset()
MEASURED = np.full(MS.n_markers, MarkerStatus.MEASURED, np.uint8)


def body(p: float = 50, sex: str = "male") -> BodyModel:
    return BodyModel(BodyDimensions.from_percentile(p, sex), MS)


def elbow_90(supination_deg: float, external_rotation_deg: float = 0.0) -> ArmPose:
    """Elbow at the side flexed 90 degrees, forearm forward (docs/JOINT_ANGLES.md canonical poses)."""
    return ArmPose.clinical(elbow_flexion_deg=90.0, forearm_supination_deg=supination_deg,
                            external_rotation_deg=external_rotation_deg)


@pytest.mark.parametrize("p, sex", [(5, "female"), (50, "male"), (95, "male")])
def test_joint_centres_match_the_simulated_body(p, sex):
    model = body(p, sex)
    tracker = SkeletonTracker(MS.names)
    poses = [reference_pose(), Pose(right=ArmPose.clinical(flexion_deg=120, elbow_flexion_deg=40)),
             Pose(trunk_forward_lean_deg=15, left=ArmPose.clinical(abduction_deg=90))]
    for pose in poses:
        sk = tracker.update(model.markers_m(pose), MEASURED)
        for side in ("right", "left"):
            truth = model.joint_centres_m(pose, side)
            # Elbow and wrist centres are the marker midpoints: they sit on the true joint axis.
            assert np.linalg.norm(sk.joint(f"{side}_elbow") - truth["elbow"]) < 1e-9
            assert np.linalg.norm(sk.joint(f"{side}_wrist") - truth["wrist"]) < 1e-9
            # The shoulder centre is a fixed offset from the acromion marker: within 2.5 cm.
            assert np.linalg.norm(sk.joint(f"{side}_shoulder") - truth["gh"]) < 0.025
        assert sk.joints_m.shape == (len(JOINTS), 3) and np.isfinite(sk.joints_m).all()
        assert (sk.state == MarkerStatus.MEASURED).all()


def test_frames_are_rotations_and_the_trunk_frame_is_the_angle_definition():
    model = body()
    pose = Pose(trunk_forward_lean_deg=20, trunk_lateral_lean_deg=-10, right=ArmPose.clinical(flexion_deg=70))
    m = model.markers_m(pose)
    sk = SkeletonTracker(MS.names).update(m, MEASURED)
    for r in sk.frames:
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)
    ix = {n: i for i, n in enumerate(MS.names)}
    y_t = m[ix["MB"]] - m[ix["MP"]]
    np.testing.assert_allclose(sk.frame("trunk")[:, 1], y_t / np.linalg.norm(y_t), atol=1e-12)
    assert sk.frame("trunk")[:, 0] @ (m[ix["MRH"]] - m[ix["MLH"]]) > 0
    # The trunk lean of the frame is the one joint_angles reports.
    lean = np.degrees(np.arctan2(-sk.frame("trunk")[2, 1], sk.frame("trunk")[1, 1]))
    assert lean == pytest.approx(float(joint_angles(m, MS.names)["trunk_forward_lean"]), abs=1e-9)


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("supination, palm", [(90.0, (0, 1, 0)), (-90.0, (0, -1, 0))])
def test_palm_faces_up_when_supinated_and_down_when_pronated(side, supination, palm):
    """docs/JOINT_ANGLES.md: elbow at the side flexed 90, forearm forward, palm up = supination 90."""
    pose = Pose().with_arm(side, elbow_90(supination))
    sk = SkeletonTracker(MS.names).update(body().markers_m(pose), MEASURED)
    assert sk.palm_normal(side) @ np.array(palm, float) > 0.99


@pytest.mark.parametrize("side, medial", [("right", (-1, 0, 0)), ("left", (1, 0, 0))])
def test_thumb_up_in_the_neutral_forearm(side, medial):
    pose = Pose().with_arm(side, elbow_90(0.0))
    m = body().markers_m(pose)
    sk = SkeletonTracker(MS.names).update(m, MEASURED)
    # Forearm x points to the radial (thumb) side: up; the palm faces the body's midline.
    assert sk.frame(f"{side}_forearm")[:, 0] @ np.array([0.0, 1.0, 0.0]) > 0.99
    assert sk.palm_normal(side) @ np.array(medial, float) > 0.99
    assert float(joint_angles(m, MS.names)[f"{side}_forearm_supination"]) == pytest.approx(0.0, abs=1.0)


@pytest.mark.parametrize("supination", [-70.0, -30.0, 20.0, 60.0])
def test_hand_turns_with_the_measured_supination(supination):
    """The palm normal turns about the forearm by the angle joint_angles measures."""
    m = body().markers_m(Pose(right=elbow_90(supination)))
    sk = SkeletonTracker(MS.names).update(m, MEASURED)
    measured = float(joint_angles(m, MS.names)["right_forearm_supination"])
    palm = sk.palm_normal("right")
    # Forearm forward: the palm turns in the frontal plane from medial (-X, 0 deg) to up (+Y, +90).
    assert np.degrees(np.arctan2(palm[1], -palm[0])) == pytest.approx(measured, abs=1.0)


def test_segment_states_follow_the_marker_status():
    model = body()
    m = model.markers_m(reference_pose())
    status = MEASURED.copy()
    status[MS.index("MRW2")] = MarkerStatus.ESTIMATED
    lost = m.copy()
    lost[MS.index("MLE1")] = np.nan
    status[MS.index("MLE1")] = MarkerStatus.LOST
    sk = SkeletonTracker(MS.names).update(lost, status)
    expect = {"pelvis": 1, "trunk": 1, "right_upper_arm": 1, "right_forearm": 2, "left_upper_arm": 0, "left_forearm": 1}
    assert {s: int(sk.state[k]) for k, s in enumerate(SEGMENTS)} == expect


def test_a_lost_forearm_follows_the_upper_arm_without_jumping():
    model = body()
    tracker = SkeletonTracker(MS.names)
    wrists = [MS.index("MRW1"), MS.index("MRW2")]
    before = tracker.update(model.markers_m(Pose(right=ArmPose.clinical(flexion_deg=10, elbow_flexion_deg=60))), MEASURED)
    status = MEASURED.copy()
    status[wrists] = MarkerStatus.LOST
    lengths, angles = [], []
    for k, flexion in enumerate([10.0, 40.0, 80.0]):
        m = model.markers_m(Pose(right=ArmPose.clinical(flexion_deg=flexion, elbow_flexion_deg=60)))
        m[wrists] = np.nan
        sk = tracker.update(m, status)
        if k == 0:  # first lost frame: exactly where it was
            np.testing.assert_allclose(sk.joint("right_wrist"), before.joint("right_wrist"), atol=1e-12)
        u = sk.joint("right_elbow") - sk.joint("right_shoulder")
        f = sk.joint("right_wrist") - sk.joint("right_elbow")
        lengths.append(np.linalg.norm(f))
        angles.append(np.degrees(np.arccos(u @ f / np.linalg.norm(u) / np.linalg.norm(f))))
        assert sk.segment_state("right_forearm") == MarkerStatus.LOST
        assert sk.segment_state("right_upper_arm") == MarkerStatus.MEASURED
    # Rigid with the upper arm: same length, same elbow angle, while the upper arm rose 70 degrees.
    np.testing.assert_allclose(lengths, lengths[0], atol=1e-9)
    np.testing.assert_allclose(angles, angles[0], atol=1e-6)


def test_lost_trunk_markers_are_recovered_from_the_visible_ones():
    model = body()
    tracker = SkeletonTracker(MS.names)
    tracker.update(model.markers_m(reference_pose()), MEASURED)
    pose = Pose(trunk_lateral_lean_deg=12.0)
    m = model.markers_m(pose)
    truth = SkeletonTracker(MS.names).update(m, MEASURED)
    hidden = m.copy()
    status = MEASURED.copy()
    for name in ("MB", "MP"):
        hidden[MS.index(name)] = np.nan
        status[MS.index(name)] = MarkerStatus.LOST
    sk = tracker.update(hidden, status)
    # The shoulders and hips still fix the trunk: its lean is followed (within a few degrees;
    # the shoulder markers ride on the shoulder girdle, not rigidly on the trunk).
    cos = sk.frame("trunk")[:, 1] @ truth.frame("trunk")[:, 1]
    assert np.degrees(np.arccos(min(cos, 1.0))) < 3.0
    assert sk.segment_state("trunk") == MarkerStatus.LOST


def test_nothing_seen_yet_gives_a_default_lost_pose():
    nan = np.full((MS.n_markers, 3), np.nan)
    sk = SkeletonTracker(MS.names).update(nan, np.zeros(MS.n_markers, np.uint8))
    assert np.isfinite(sk.joints_m).all()
    assert (sk.state == MarkerStatus.LOST).all()
    assert sk.joint("head")[1] > sk.joint("pelvis")[1]


@pytest.mark.parametrize("p, sex", [(5, "female"), (95, "male")])
def test_proportions_fit_the_patient_despite_mislabelled_frames(p, sex):
    model = body(p, sex)
    rng = np.random.default_rng(1)
    tracker = SkeletonTracker(MS.names)
    for k in range(60):
        m = model.markers_m(Pose(right=ArmPose.clinical(flexion_deg=2.0 * k)))
        m = m + rng.normal(0.0, 0.002, m.shape)
        if k % 10 == 3:  # a wrist swapped with a hip marker now and then: the median ignores it
            i, j = MS.index("MRW1"), MS.index("MRH")
            m[[i, j]] = m[[j, i]]
        tracker.update(m, MEASURED)
    props = tracker.proportions
    assert props.stature_m == pytest.approx(model.dims.stature_m, rel=0.03)
    assert props.forearm_m == pytest.approx(model.dims.forearm_m, abs=0.005)
    assert props.n_frames == 60


def test_estimated_markers_do_not_teach_proportions():
    tracker = SkeletonTracker(MS.names)
    m = body(95, "male").markers_m(reference_pose())
    tracker.update(m, np.full(MS.n_markers, MarkerStatus.ESTIMATED, np.uint8))
    assert tracker.proportions.n_frames == 0


def test_a_role_without_a_marker_leaves_its_segment_lost_and_the_rest_drawn():
    names = [n for n in MS.names if n != "MRW2"]
    m = body().markers_m(reference_pose())
    keep = [MS.index(n) for n in names]
    full = SkeletonTracker(MS.names).update(m, MEASURED)
    sk = SkeletonTracker(names).update(m[keep], MEASURED[keep])
    assert sk.segment_state("right_forearm") is MarkerStatus.LOST
    for seg in SEGMENTS:
        if seg != "right_forearm":
            assert sk.segment_state(seg) is MarkerStatus.MEASURED
    # the other segments are drawn from their own markers, exactly as with the full set
    for joint in ("sternum", "right_elbow", "left_wrist", "left_hand"):
        np.testing.assert_array_equal(sk.joint(joint), full.joint(joint))


def test_a_marker_set_without_any_role_is_a_one_line_error():
    with pytest.raises(MissingMarkersError, match="no marker for any role.*roles:"):
        SkeletonTracker(["A", "B", "C"])


def test_bad_array_shapes_are_rejected():
    with pytest.raises(ValueError, match=r"\(14, 3\)"):
        SkeletonTracker(MS.names).update(np.zeros((13, 3)), MEASURED)
