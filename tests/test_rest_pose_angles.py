"""Why the simulated patient at rest reads about -11 degrees of shoulder flexion and of trunk
forward lean (issue 25): the body is upright and the arms hang straight down, but the spec's trunk
axis runs from the lower (MP, xiphoid) to the upper (MB, sternal notch) sternum marker, and the
chest's front slopes back towards the top. Both angles are measured against that axis, so both
read the slope; the angle between the upper arm and the world's vertical is zero."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tracking.angles import joint_angles
from tracking.markerset import load_markerset
from tracking.sim.body import BodyDimensions, BodyModel, Pose, reference_pose

MARKERS = load_markerset("upper_limb_seated")
BODIES = [(5, "female"), (50, "female"), (50, "male"), (95, "male")]


@pytest.mark.parametrize("percentile,sex", BODIES)
@pytest.mark.parametrize("pose", [Pose(), reference_pose()], ids=["zero", "reference"])
def test_upright_with_hanging_arms_reads_the_sternum_slope(percentile, sex, pose):
    body = BodyModel(BodyDimensions.from_percentile(percentile, sex), MARKERS)
    m = body.markers_m(pose)
    at = {n: m[i] for i, n in enumerate(MARKERS.names)}
    angles = joint_angles(m, MARKERS.names)
    # the body: no trunk rotation, each upper arm (acromion marker to elbow centre) vertical in
    # the sagittal plane
    assert pose.trunk_forward_lean_deg == 0.0
    for side in "RL":
        u = (at[f"M{side}E1"] + at[f"M{side}E2"]) / 2 - at[f"M{side}S"]
        assert abs(math.degrees(math.atan2(-u[2], -u[1]))) < 0.5
    # the markers: MB sits behind MP (the chest slopes back towards the top) by 10-13 degrees
    trunk = at["MB"] - at["MP"]
    slope_deg = math.degrees(math.atan2(trunk[2], trunk[1]))
    assert 10.0 < slope_deg < 13.0
    # the readings: exactly that slope, below zero, for the trunk and both shoulders
    for name in ("trunk_forward_lean", "right_shoulder_flexion", "left_shoulder_flexion"):
        assert float(angles[name]) == pytest.approx(-slope_deg, abs=0.5), name
    # leaning the trunk forward by that slope brings the trunk's reading to zero
    leaned = body.markers_m(Pose(trunk_forward_lean_deg=slope_deg, right=pose.right, left=pose.left))
    assert float(joint_angles(leaned, MARKERS.names)["trunk_forward_lean"]) == pytest.approx(0.0, abs=0.5)
