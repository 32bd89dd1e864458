"""The interactive simulated patient: inverse kinematics, clamping, rate limits, poses."""

import math

import numpy as np
import pytest

from tracking.angles import joint_angles
from tracking.live.protocol import PatientInput
from tracking.markerset import load_markerset
from tracking.sim.body import BodyDimensions, BodyModel, Pose, reference_pose
from tracking.sim.interactive import MAX_ELBOW_FLEXION_DEG, InteractivePatient, PatientLimits, solve_arm

DT = 1.0 / 30.0


@pytest.fixture(scope="module")
def model():
    return BodyModel(BodyDimensions.from_percentile(50, "male"), load_markerset("upper_limb_seated"))


@pytest.mark.parametrize("side", ["right", "left"])
def test_the_hand_reaches_reachable_targets_within_5_mm(model, side):
    rng = np.random.default_rng(1)
    ref = reference_pose()
    reach = model.dims.upper_arm_m + model.dims.forearm_m
    for _ in range(100):
        pose = Pose(trunk_forward_lean_deg=rng.uniform(-10, 30), trunk_lateral_lean_deg=rng.uniform(-20, 20),
                    right=ref.right, left=ref.left)
        gh = model.joint_centres_m(pose, side)["gh"]
        d = rng.normal(size=3)
        target = gh + d / np.linalg.norm(d) * rng.uniform(0.45, 0.9) * reach
        sol = solve_arm(model, pose, side, target, 20.0)
        assert sol.reachable
        assert np.linalg.norm(sol.wrist_m - target) < 0.005
        # the body model agrees: the solved arm puts that wrist where the solver says
        solved = pose.with_arm(side, sol.arm)
        np.testing.assert_allclose(model.joint_centres_m(solved, side)["wrist"], sol.wrist_m, atol=1e-9)
        assert sol.arm.forearm_supination_deg == 20.0


def test_out_of_reach_targets_are_clamped_to_the_nearest_reachable_point(model):
    pose = reference_pose()
    gh = model.joint_centres_m(pose, "right")["gh"]
    far = gh + np.array([0.0, 0.0, -2.0])  # 2 m in front
    sol = solve_arm(model, pose, "right", far, 0.0)
    assert not sol.reachable
    reach = model.dims.upper_arm_m + model.dims.forearm_m
    to_wrist = sol.wrist_m - gh
    assert np.linalg.norm(to_wrist) == pytest.approx(0.985 * reach, abs=0.01)  # (GH rises a little with the arm)
    assert to_wrist[2] / np.linalg.norm(to_wrist) < -0.99  # straight forward
    near = gh + np.array([0.0, -0.02, -0.02])  # inside the shoulder: elbow bent to the limit
    sol = solve_arm(model, pose, "right", near, 0.0)
    assert not sol.reachable
    assert sol.arm.elbow_flexion_deg == pytest.approx(MAX_ELBOW_FLEXION_DEG, abs=0.5)


def test_the_elbow_hangs_low_and_out(model):
    """A reach forward at shoulder height: the elbow sits below the shoulder-wrist line, outside it."""
    pose = reference_pose()
    c = model.joint_centres_m(pose, "right")
    target = c["gh"] + np.array([0.05, -0.05, -0.4])
    sol = solve_arm(model, pose, "right", target, 0.0)
    solved = model.joint_centres_m(pose.with_arm("right", sol.arm), "right")
    mid = (solved["gh"] + solved["wrist"]) / 2
    assert solved["elbow"][1] < mid[1] - 0.03
    assert solved["elbow"][0] > mid[0]


def test_the_hand_moves_at_most_2_m_per_s_and_arrives(model):
    patient = InteractivePatient(model)
    start = patient.wrist_m("right")
    target = np.array([0.25, 1.15, -0.35])
    inp = PatientInput(side="right", hand_target_m=tuple(target))
    prev = start
    steps = []
    for _ in range(60):
        patient.step(inp, DT)
        now = patient.wrist_m("right")
        steps.append(np.linalg.norm(now - prev))
        prev = now
    assert max(steps) <= 2.0 * DT + 0.002
    # it speeds up and brakes gradually (5 m/s^2): no jump from rest to full speed
    assert steps[0] <= 5.0 * DT * DT + 0.002
    assert np.abs(np.diff(steps)).max() <= 5.0 * DT * DT + 0.003
    assert np.linalg.norm(prev - target) < 0.005
    # the other arm did not move
    np.testing.assert_allclose(patient.wrist_m("left"), InteractivePatient(model).wrist_m("left"))


def test_hand_step_brakes_onto_the_target():
    from tracking.sim.interactive import hand_step

    p, v = np.zeros(3), np.zeros(3)
    target = np.array([0.5, 0.0, 0.0])
    speeds = []
    for _ in range(200):
        p, v = hand_step(p, v, target, DT, 2.0, 5.0)
        speeds.append(np.linalg.norm(v))
    np.testing.assert_allclose(p, target)
    assert max(speeds) <= 2.0 + 1e-9 and speeds[-1] == 0.0
    # a target behind the moving hand: it brakes first, then comes back
    p, v = np.zeros(3), np.array([2.0, 0.0, 0.0])
    p, v2 = hand_step(p, v, np.array([-0.5, 0.0, 0.0]), DT, 2.0, 5.0)
    assert np.linalg.norm(v2 - v) == pytest.approx(5.0 * DT)


def test_forearm_and_trunk_follow_the_input_at_bounded_rates(model):
    limits = PatientLimits()
    patient = InteractivePatient(model, limits)
    inp = PatientInput(side="left", forearm_rotation_deg=-80.0, trunk_forward_lean_deg=20.0, trunk_lateral_lean_deg=-10.0)
    pose = patient.step(inp, DT)
    assert pose.trunk_forward_lean_deg == pytest.approx(limits.lean_speed_deg_s * DT)
    for _ in range(30):
        pose = patient.step(inp, DT)
    assert pose.left.forearm_supination_deg == pytest.approx(-80.0)
    assert pose.trunk_forward_lean_deg == pytest.approx(20.0)
    assert pose.trunk_lateral_lean_deg == pytest.approx(-10.0)
    # the marker-based angles see it (the markers of an upright trunk already read some lean)
    angles = joint_angles(model.markers_m(pose), model.markerset.names)
    upright = joint_angles(model.markers_m(Pose(right=pose.right, left=pose.left)), model.markerset.names)
    assert angles["trunk_forward_lean"] - upright["trunk_forward_lean"] == pytest.approx(20.0, abs=3.0)
    assert angles["trunk_lateral_lean"] - upright["trunk_lateral_lean"] == pytest.approx(-10.0, abs=3.0)
    assert float(angles["left_forearm_supination"]) < -45.0


def test_extreme_inputs_are_clamped_to_the_limits(model):
    patient = InteractivePatient(model)
    inp = PatientInput(forearm_rotation_deg=500.0, trunk_forward_lean_deg=-90.0, trunk_lateral_lean_deg=math.inf)
    for _ in range(200):
        pose = patient.step(inp, DT)
    lim = patient.limits
    assert pose.right.forearm_supination_deg == lim.forearm_range_deg[1]
    assert pose.trunk_forward_lean_deg == lim.forward_lean_range_deg[0]
    assert pose.trunk_lateral_lean_deg == lim.lateral_lean_range_deg[1]


def test_take_reference_pose(model):
    patient = InteractivePatient(model)
    for _ in range(10):
        patient.step(PatientInput(hand_target_m=(0.3, 1.2, -0.4)), DT)
    ref = model.markers_m(reference_pose())
    assert np.abs(model.markers_m(patient.pose) - ref).max() > 0.05
    np.testing.assert_allclose(model.markers_m(patient.take_reference_pose()), ref)
