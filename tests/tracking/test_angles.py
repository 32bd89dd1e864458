"""Joint angles against docs/JOINT_ANGLES.md on exact synthetic markers.

The markers come from a small kinematic helper (trunk upright, shoulder at a point, upper-arm
direction, humeral rotation, elbow flexion, forearm rotation; epicondyle and styloid pairs placed
on their anatomical sides), and each canonical pose also checks the placed markers against its
plain-words description (thumb up = radial styloid above ulnar styloid, ...), so the helper cannot
quietly share a sign error with the code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.errors import RehabError
from tracking.angles import (
    ANGLE_COLUMNS,
    ARM_ANGLES,
    MIN_FROM_PLANE_NORMAL_DEG,
    REQUIRED_MARKERS,
    MissingMarkersError,
    joint_angles,
    missing_markers,
    require_markers,
    wrap180,
)

X, Y, Z = np.eye(3)
UPPER_ARM_M, FOREARM_M = 0.30, 0.25
ELBOW_HALF_M, WRIST_HALF_M = 0.035, 0.025
SIGN = {"left": -1.0, "right": 1.0}


# ---------------------------------------------------------------- synthetic markers


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def rotate(v, axis, angle_deg) -> np.ndarray:
    """Rodrigues rotation of ``v`` about ``axis`` by ``angle_deg`` (right-hand rule)."""
    k = unit(axis)
    a = np.radians(angle_deg)
    v = np.asarray(v, dtype=float)
    return v * np.cos(a) + np.cross(k, v) * np.sin(a) + k * np.dot(k, v) * (1 - np.cos(a))


def rotation_matrix(axis, angle_deg) -> np.ndarray:
    return np.stack([rotate(e, axis, angle_deg) for e in np.eye(3)], axis=1)


def arm_markers(
    side: str,
    upper_dir=-Y,
    lateral_dir=None,
    *,
    humeral_rotation_deg: float = 0.0,
    elbow_flexion_deg: float = 0.0,
    supination_deg: float = 0.0,
    shoulder=None,
) -> dict[str, np.ndarray]:
    """The five markers of one arm (metres, world frame, trunk upright and facing -Z).

    upper_dir: direction shoulder -> elbow. lateral_dir: where the lateral epicondyle (E1) points
    before humeral rotation (made orthogonal to the upper arm; default the patient's outside).
    humeral_rotation_deg: external (+) / internal (-) rotation about the upper arm.
    elbow_flexion_deg: the forearm turns forwards about the epicondyle axis.
    supination_deg: 0 = neutral (thumb up with the elbow flexed 90 at the side), + = palm up.
    """
    sign = SIGN[side]
    letter = "R" if side == "right" else "L"
    s = np.array([0.18 * sign, 1.25, 0.0]) if shoulder is None else np.asarray(shoulder, float)
    u = unit(upper_dir)
    lat = sign * X if lateral_dir is None else np.asarray(lateral_dir, float)
    lat = unit(lat - np.dot(lat, u) * u)
    lat = rotate(lat, sign * u, humeral_rotation_deg)
    flex_axis = sign * lat  # flexing the elbow brings the forearm forwards on both sides
    f = rotate(u, flex_axis, elbow_flexion_deg)
    neutral_w = rotate(u, flex_axis, elbow_flexion_deg - 90.0)  # ulnar side (W2) of a neutral forearm
    w = rotate(neutral_w, sign * f, supination_deg)
    e = s + UPPER_ARM_M * u
    wr = e + FOREARM_M * f
    return {
        f"M{letter}S": s,
        f"M{letter}E1": e + ELBOW_HALF_M * lat,
        f"M{letter}E2": e - ELBOW_HALF_M * lat,
        f"M{letter}W1": wr - WRIST_HALF_M * w,
        f"M{letter}W2": wr + WRIST_HALF_M * w,
    }


def body(right: dict | None = None, left: dict | None = None, *, names=REQUIRED_MARKERS) -> np.ndarray:
    """(14, 3) markers of an upright seated trunk (MB above MP) with two arms (kwargs of :func:`arm_markers`)."""
    markers = {
        "MB": np.array([0.0, 1.20, -0.10]),
        "MP": np.array([0.0, 0.95, -0.10]),
        "MLH": np.array([-0.12, 0.55, -0.08]),
        "MRH": np.array([0.12, 0.55, -0.08]),
    }
    markers.update(arm_markers("right", **(right or {})))
    markers.update(arm_markers("left", **(left or {})))
    return np.stack([markers[n] for n in names])


def mirror(positions: np.ndarray, names=REQUIRED_MARKERS) -> np.ndarray:
    """Mirror markers across the sagittal plane x = 0 and swap the left and right names."""
    mirrored = positions * np.array([-1.0, 1.0, 1.0])
    swap = {n: n.replace("L", "#").replace("R", "L").replace("#", "R") for n in names}
    return mirrored[..., [list(names).index(swap[n]) for n in names], :]


def transform(positions: np.ndarray, rotation: np.ndarray, translation) -> np.ndarray:
    return positions @ rotation.T + np.asarray(translation, float)


def angles_of(positions, names=REQUIRED_MARKERS) -> dict[str, float]:
    return {k: float(v) for k, v in joint_angles(positions, names).items()}


def at(names: tuple[str, ...], p: np.ndarray, name: str) -> np.ndarray:
    return p[list(names).index(name)]


# ---------------------------------------------------------------- columns and names


def test_columns_order_and_names():
    assert len(ANGLE_COLUMNS) == 16
    assert ANGLE_COLUMNS[:7] == tuple(f"left_{a}" for a in ARM_ANGLES)
    assert ANGLE_COLUMNS[7:14] == tuple(f"right_{a}" for a in ARM_ANGLES)
    assert ANGLE_COLUMNS[14:] == ("trunk_forward_lean", "trunk_lateral_lean")
    assert ARM_ANGLES == (
        "shoulder_flexion", "shoulder_abduction", "shoulder_elevation", "shoulder_horizontal_flexion",
        "shoulder_external_rotation", "elbow_flexion", "forearm_supination",
    )
    assert list(joint_angles(body(), REQUIRED_MARKERS)) == list(ANGLE_COLUMNS)


def test_required_markers_are_the_marker_set():
    from tracking.markerset import load_markerset

    assert set(REQUIRED_MARKERS) == set(load_markerset("upper_limb_seated").names)


def test_missing_markers_and_one_line_error():
    names = [n for n in REQUIRED_MARKERS if n not in ("MRW2", "MLW2")] + ["EXTRA"]
    assert missing_markers(names) == ["MLW2", "MRW2"]
    assert missing_markers(REQUIRED_MARKERS) == []
    with pytest.raises(MissingMarkersError) as info:
        require_markers(names, "markers.trc")
    assert isinstance(info.value, RehabError)
    message = str(info.value)
    assert message.startswith("markers.trc lacks MLW2, MRW2 (it has MB, MP, ")  # wanted and found
    assert ", EXTRA): the angles need the upper_limb_seated names MB, MP, MLS" in message
    assert message.endswith("rehab angles --map FILE.yaml") and "\n" not in message
    require_markers(REQUIRED_MARKERS, "markers.trc")


def test_shape_is_checked():
    with pytest.raises(ValueError, match="14"):
        joint_angles(np.zeros((5, 13, 3)), REQUIRED_MARKERS)
    with pytest.raises(ValueError):
        joint_angles(np.zeros((14, 2)), REQUIRED_MARKERS)


# ---------------------------------------------------------------- canonical poses

HANGING = dict(upper_dir=-Y)
FORWARD = dict(upper_dir=-Z)
SIDEWAYS = dict(upper_dir=X, lateral_dir=Y)
UP = dict(upper_dir=Y, lateral_dir=-X)
ELBOW_90 = dict(upper_dir=-Y, elbow_flexion_deg=90.0)

# (pose of the right arm, expected angles without the side prefix)
CANONICAL = {
    "hanging, elbow straight, thumb forward": (
        HANGING,
        dict(shoulder_flexion=0, shoulder_abduction=0, shoulder_elevation=0, elbow_flexion=0, forearm_supination=0),
    ),
    "straight forward": (
        FORWARD,
        dict(shoulder_flexion=90, shoulder_abduction=0, shoulder_elevation=90, shoulder_horizontal_flexion=90),
    ),
    "straight sideways": (
        SIDEWAYS,
        dict(shoulder_flexion=0, shoulder_abduction=90, shoulder_elevation=90, shoulder_horizontal_flexion=0),
    ),
    "straight up": (
        UP,
        dict(shoulder_flexion=180, shoulder_abduction=180, shoulder_elevation=180),
    ),
    "elbow 90 at the side, forearm forward, thumb up": (
        ELBOW_90,
        dict(shoulder_external_rotation=0, forearm_supination=0, elbow_flexion=90, shoulder_flexion=0),
    ),
    "forearm rotated 45 outward": (
        dict(ELBOW_90, humeral_rotation_deg=45.0),
        dict(shoulder_external_rotation=45, elbow_flexion=90, forearm_supination=0),
    ),
    "forearm rotated 60 inward": (
        dict(ELBOW_90, humeral_rotation_deg=-60.0),
        dict(shoulder_external_rotation=-60, elbow_flexion=90, forearm_supination=0),
    ),
    "palm up": (dict(ELBOW_90, supination_deg=90.0), dict(forearm_supination=90, shoulder_external_rotation=0)),
    "palm down": (dict(ELBOW_90, supination_deg=-90.0), dict(forearm_supination=-90, shoulder_external_rotation=0)),
}


def mirrored_pose(pose: dict) -> dict:
    """The same arm pose for the left arm: direction vectors mirrored across x = 0."""
    flip = np.array([-1.0, 1.0, 1.0])
    return {k: (np.asarray(v) * flip if k in ("upper_dir", "lateral_dir") else v) for k, v in pose.items()}


def assert_angles(got: dict[str, float], side: str, expected: dict, tol: float = 1e-6):
    for name, value in expected.items():
        assert got[f"{side}_{name}"] == pytest.approx(value, abs=tol), f"{side}_{name}"


@pytest.mark.parametrize("label", CANONICAL)
def test_canonical_pose_right(label):
    pose, expected = CANONICAL[label]
    assert_angles(angles_of(body(right=pose)), "right", expected)


@pytest.mark.parametrize("label", CANONICAL)
def test_canonical_pose_left_built_mirrored(label):
    pose, expected = CANONICAL[label]
    assert_angles(angles_of(body(left=mirrored_pose(pose))), "left", expected)


@pytest.mark.parametrize("label", CANONICAL)
def test_canonical_pose_left_from_mirrored_markers(label):
    pose, expected = CANONICAL[label]
    p = body(right=pose)
    right, left = angles_of(p), angles_of(mirror(p))
    assert_angles(left, "left", expected)
    for angle in ARM_ANGLES:
        np.testing.assert_allclose(left[f"left_{angle}"], right[f"right_{angle}"], atol=1e-9, equal_nan=True)


# ------------------------------------------------ what a person reads live: near_singular="withhold"


def test_arm_overhead_and_out_with_the_trunk_leaning_forward_reads_past_180_not_negative():
    """The left arm raised high and out (160 degrees up in the world's frontal plane), the trunk
    leaning 24 degrees forward: relative to the trunk the arm points up, out and back. Read live,
    flexion continues past 180 (the spec's column wraps it to about -138: the live view showed
    that); the spec's own value stays in files and samples."""
    lean = 24.0
    world = unit(-X * math.sin(math.radians(160.0)) + Y * -math.cos(math.radians(160.0)))
    in_trunk = rotate(world, X, lean)        # a forward lean tilts the world's vertical back (+Z) for the trunk
    p = body(left=dict(upper_dir=in_trunk, lateral_dir=Y))
    live = joint_angles(p, REQUIRED_MARKERS, near_singular="withhold")
    assert 180.0 < live["left_shoulder_flexion"] <= 225.0
    assert live["left_shoulder_abduction"] == pytest.approx(160.0, abs=2.0)
    spec = angles_of(p)
    assert spec["left_shoulder_flexion"] == pytest.approx(float(live["left_shoulder_flexion"]) - 360.0)


def test_withholding_leaves_the_spec_columns_alone_and_agrees_across_paths():
    p = body(right=SIDEWAYS, left=mirrored_pose(FORWARD))
    spec, live = angles_of(p), joint_angles(p, REQUIRED_MARKERS, near_singular="withhold")
    assert spec["right_shoulder_flexion"] == pytest.approx(0.0, abs=1e-9)   # the spec's canonical pose
    assert np.isnan(live["right_shoulder_flexion"]) and np.isnan(live["left_shoulder_abduction"])
    frames = np.stack([p, body(right=UP)])
    batch = joint_angles(frames, REQUIRED_MARKERS, near_singular="withhold")
    for t in range(2):
        single = joint_angles(frames[t], REQUIRED_MARKERS, near_singular="withhold")
        for c in ANGLE_COLUMNS:
            np.testing.assert_allclose(single[c], batch[c][t], rtol=0, atol=PATHS_AGREE_DEG, equal_nan=True)
    with pytest.raises(ValueError, match="near_singular"):
        joint_angles(p, REQUIRED_MARKERS, near_singular="hide")


@pytest.mark.parametrize("elevation, defined", [(134.0, True), (136.0, False)])
def test_live_horizontal_flexion_is_withheld_near_straight_up(elevation, defined):
    p = body(right=dict(upper_dir=rotate(-Y, Z, elevation), lateral_dir=Y))
    assert np.isfinite(angles_of(p)["right_shoulder_horizontal_flexion"])  # the spec: defined above 45
    live = joint_angles(p, REQUIRED_MARKERS, near_singular="withhold")
    assert np.isnan(live["right_shoulder_horizontal_flexion"]) != defined


@pytest.mark.parametrize("side", ["right", "left"])
def test_live_planar_angles_never_jump_along_continuous_arm_paths(side):
    """Arm directions swept in steps of 0.5 degrees along great circles through every region of
    the sphere (sideways, forward, straight up, behind): between two consecutive live readings
    that are not withheld, flexion and abduction change by at most 1 / sin(15 degrees) of the step
    (no jump near the planes' normals, none at 180 overhead), except across the one cut, which
    lies where the arm's projection points 45 degrees behind (flexion; across, abduction) the
    vertical overhead: beyond every normal range of motion."""
    sign = 1.0 if side == "right" else -1.0
    step = 0.5
    bound = 1.05 * step / math.sin(math.radians(MIN_FROM_PLANE_NORMAL_DEG))
    rng = np.random.default_rng(4)
    starts = [unit(v) for v in rng.normal(size=(12, 3))] + [X, Y, -Z, Z]
    for k, a in enumerate(starts):
        b = unit(np.cross(a, unit(rng.normal(size=3)) if k < 12 else Y if abs(a[1]) < 0.9 else X))
        dirs = [math.cos(t) * a + math.sin(t) * b for t in np.radians(np.arange(0.0, 360.0, step))]
        dirs = [d * np.array([sign, 1.0, 1.0]) for d in dirs]
        frames = np.stack([body(**{side: dict(upper_dir=d, lateral_dir=Y if abs(d[1]) < 0.9 else X)}) for d in dirs])
        got = joint_angles(frames, REQUIRED_MARKERS, near_singular="withhold")
        u = np.array(dirs) * np.array([sign, 1.0, 1.0])       # right-side convention: out = +X
        for name, across in (("shoulder_flexion", -u[:, 2]), ("shoulder_abduction", u[:, 0])):
            v = got[f"{side}_{name}"]
            both = np.isfinite(v[1:]) & np.isfinite(v[:-1])
            jump = np.abs(np.diff(v)) > bound
            for i in np.flatnonzero(both & jump):
                # only the cut: a full turn, the arm's projection 45 degrees behind / across the vertical
                assert abs(abs(v[i + 1] - v[i]) - 360.0) <= bound, (name, k, v[i], v[i + 1])
                assert u[i, 1] > 0.0 and across[i] < 0.0 and abs(abs(across[i]) - u[i, 1]) < 0.05, (name, k, u[i])
            assert np.all(~np.isfinite(v) | ((v > -135.0) & (v <= 225.0)))


def test_straight_up_reads_plus_180_not_minus_180():
    got = angles_of(body(right=UP, left=mirrored_pose(UP)))
    for side in ("left", "right"):
        assert got[f"{side}_shoulder_flexion"] == 180.0
        assert got[f"{side}_shoulder_abduction"] == 180.0


def test_canonical_markers_match_their_description():
    """The helper puts the landmarks where the words of docs/JOINT_ANGLES.md put them (right arm)."""
    n = REQUIRED_MARKERS
    p = body(right=HANGING)
    assert at(n, p, "MRW1")[2] < at(n, p, "MRW2")[2]  # thumb forward
    assert at(n, p, "MRE1")[0] > at(n, p, "MRE2")[0]  # lateral epicondyle outside
    p = body(right=ELBOW_90)
    assert at(n, p, "MRW1")[1] > at(n, p, "MRW2")[1]  # thumb up
    assert at(n, p, "MRW1")[2] < at(n, p, "MRE1")[2] - 0.2  # forearm forward
    p = body(right=dict(ELBOW_90, humeral_rotation_deg=45.0))
    assert at(n, p, "MRW1")[0] > at(n, p, "MRE1")[0] + 0.1  # forearm turned outward (+X)
    p = body(right=dict(ELBOW_90, humeral_rotation_deg=-60.0))
    assert at(n, p, "MRW1")[0] < at(n, p, "MRE2")[0] - 0.1  # forearm turned inward
    p = body(right=dict(ELBOW_90, supination_deg=90.0))
    assert at(n, p, "MRW1")[0] > at(n, p, "MRW2")[0] + 0.04  # palm up: thumb outside
    p = body(right=dict(ELBOW_90, supination_deg=-90.0))
    assert at(n, p, "MRW1")[0] < at(n, p, "MRW2")[0] - 0.04  # palm down: thumb inside


def test_neutral_arms_give_zero_and_undefined_where_the_spec_says():
    got = angles_of(body())
    for side in ("left", "right"):
        for angle in ("shoulder_flexion", "shoulder_abduction", "shoulder_elevation", "elbow_flexion",
                      "forearm_supination"):
            assert got[f"{side}_{angle}"] == pytest.approx(0.0, abs=1e-9)
        assert np.isnan(got[f"{side}_shoulder_horizontal_flexion"])  # elevation 0 < 45
        assert np.isnan(got[f"{side}_shoulder_external_rotation"])  # elbow flexion 0 < 30
    assert got["trunk_forward_lean"] == pytest.approx(0.0, abs=1e-9)
    assert got["trunk_lateral_lean"] == pytest.approx(0.0, abs=1e-9)


def test_extension_and_adduction_are_negative():
    back = angles_of(body(right=dict(upper_dir=rotate(-Y, X, -40.0))))
    assert back["right_shoulder_flexion"] == pytest.approx(-40.0)
    across = angles_of(body(right=dict(upper_dir=rotate(-Y, Z, -20.0))))  # elbow towards the midline
    assert across["right_shoulder_abduction"] == pytest.approx(-20.0)
    horizontal = rotate(X, Y, -30.0)  # from sideways, 30 degrees backwards (towards +Z)
    got = angles_of(body(right=dict(upper_dir=horizontal, lateral_dir=Y)))
    assert got["right_shoulder_horizontal_flexion"] == pytest.approx(-30.0)
    across = angles_of(body(right=dict(upper_dir=unit(-Z - X), lateral_dir=Y)))
    assert across["right_shoulder_horizontal_flexion"] == pytest.approx(135.0)


# ---------------------------------------------------------------- thresholds and undefined values


@pytest.mark.parametrize("elevation, defined", [(44.0, False), (46.0, True), (135.0, True)])
def test_horizontal_flexion_needs_45_degrees_of_elevation(elevation, defined):
    got = angles_of(body(right=dict(upper_dir=rotate(-Y, Z, elevation), lateral_dir=Y)))
    assert got["right_shoulder_elevation"] == pytest.approx(elevation)
    assert np.isnan(got["right_shoulder_horizontal_flexion"]) != defined


@pytest.mark.parametrize("flexion, defined", [(29.0, False), (31.0, True), (150.0, True)])
def test_external_rotation_needs_30_degrees_of_elbow_flexion(flexion, defined):
    got = angles_of(body(right=dict(HANGING, elbow_flexion_deg=flexion, humeral_rotation_deg=20.0)))
    assert got["right_elbow_flexion"] == pytest.approx(flexion)
    if defined:
        assert got["right_shoulder_external_rotation"] == pytest.approx(20.0)
    else:
        assert np.isnan(got["right_shoulder_external_rotation"])


def test_external_rotation_at_90_abduction_forearm_up_is_plus_90():
    pose = dict(upper_dir=X, lateral_dir=Y, elbow_flexion_deg=90.0, humeral_rotation_deg=90.0)
    p = body(right=pose)
    assert at(REQUIRED_MARKERS, p, "MRW1")[1] > at(REQUIRED_MARKERS, p, "MRE1")[1] + 0.2  # forearm up
    assert angles_of(p)["right_shoulder_external_rotation"] == pytest.approx(90.0)


def test_external_rotation_undefined_with_the_arm_straight_forward():
    # -z_T projected on the plane normal to an arm pointing forward is the null vector.
    got = angles_of(body(right=dict(FORWARD, elbow_flexion_deg=90.0)))
    assert np.isnan(got["right_shoulder_external_rotation"])
    assert got["right_elbow_flexion"] == pytest.approx(90.0)


def test_nan_marker_propagates_only_to_what_needs_it():
    p = np.stack([body(right=ELBOW_90, left=mirrored_pose(ELBOW_90))] * 3)
    names = REQUIRED_MARKERS
    p[1, names.index("MRW2")] = np.nan
    p[2, names.index("MLE1"), 0] = np.nan  # one coordinate is enough
    got = joint_angles(p, names)
    assert all(np.isfinite(got[c][0]) for c in ANGLE_COLUMNS if "horizontal" not in c)
    for angle in ("shoulder_external_rotation", "elbow_flexion", "forearm_supination"):
        assert np.isnan(got[f"right_{angle}"][1])
    for angle in ("shoulder_flexion", "shoulder_abduction", "shoulder_elevation"):
        assert np.isfinite(got[f"right_{angle}"][1])
    assert all(np.isfinite(got[f"left_{a}"][1]) for a in ARM_ANGLES if a != "shoulder_horizontal_flexion")
    assert all(np.isnan(got[f"left_{a}"][2]) for a in ARM_ANGLES)
    assert np.isfinite(got["right_elbow_flexion"][2]) and np.isfinite(got["trunk_forward_lean"][2])


# Elbow flexion and supination are angles between arm markers alone: no trunk marker needed.
ARM_ONLY = {f"{side}_{a}" for side in ("left", "right") for a in ("elbow_flexion", "forearm_supination")}
# Elevation needs the trunk axis MB-MP but not the hips.
TRUNK_AXIS_ONLY = {f"{side}_shoulder_elevation" for side in ("left", "right")}


def test_missing_trunk_marker_blanks_only_the_angles_that_need_it():
    names = REQUIRED_MARKERS
    p = body(right=ELBOW_90, left=mirrored_pose(ELBOW_90))
    p_hip = p.copy()
    p_hip[names.index("MRH")] = np.nan
    got = angles_of(p_hip)
    assert all(np.isnan(got[c]) for c in ANGLE_COLUMNS[:14] if c not in ARM_ONLY | TRUNK_AXIS_ONLY)
    assert all(np.isfinite(got[c]) for c in ARM_ONLY | TRUNK_AXIS_ONLY)
    assert got["trunk_forward_lean"] == pytest.approx(0.0, abs=1e-9)
    p_mb = p.copy()
    p_mb[names.index("MB")] = np.nan
    got = angles_of(p_mb)
    assert all(np.isnan(got[c]) for c in ANGLE_COLUMNS if c not in ARM_ONLY)
    assert got["right_elbow_flexion"] == pytest.approx(90.0)


def test_absent_name_counts_as_missing_marker_and_extra_names_are_ignored():
    names = list(REQUIRED_MARKERS)
    p = body(right=ELBOW_90)
    keep = [i for i, n in enumerate(names) if n != "MLW1"]
    got = angles_of(p[keep], [names[i] for i in keep])
    assert np.isnan(got["left_forearm_supination"])
    assert got["right_elbow_flexion"] == pytest.approx(90.0)
    extra = np.vstack([np.full((1, 3), 7.0), p[::-1]])
    got2 = angles_of(extra, ["XTRA"] + names[::-1])
    np.testing.assert_allclose([got2[c] for c in ANGLE_COLUMNS], [angles_of(p)[c] for c in ANGLE_COLUMNS],
                               atol=1e-9)


def test_coincident_trunk_markers_give_nan():
    names = REQUIRED_MARKERS
    p = body(right=ELBOW_90)
    p[names.index("MB")] = p[names.index("MP")]
    got = angles_of(p)
    assert all(np.isnan(got[c]) for c in ANGLE_COLUMNS if c not in ARM_ONLY)
    assert got["right_elbow_flexion"] == pytest.approx(90.0)


def test_elbow_on_the_shoulder_gives_nan_for_that_arm():
    names = REQUIRED_MARKERS
    p = body(right=ELBOW_90)
    s = p[names.index("MRS")]
    p[names.index("MRE1")] = s + [0.03, 0.0, 0.0]
    p[names.index("MRE2")] = s - [0.03, 0.0, 0.0]
    got = angles_of(p)
    assert all(np.isnan(got[f"right_{a}"]) for a in ARM_ANGLES if a != "forearm_supination")
    assert np.isfinite(got["left_shoulder_flexion"])


def test_hip_line_along_the_trunk_leaves_no_trunk_frame():
    names = REQUIRED_MARKERS
    p = body()
    mb, mp = p[names.index("MB")], p[names.index("MP")]
    p[names.index("MLH")] = mp - 0.3 * (mb - mp)
    p[names.index("MRH")] = mp - 0.1 * (mb - mp)
    got = angles_of(p)
    assert all(np.isnan(got[c]) for c in ANGLE_COLUMNS[:14] if c not in ARM_ONLY | TRUNK_AXIS_ONLY)
    assert np.isfinite(got["trunk_forward_lean"]) and np.isfinite(got["right_shoulder_elevation"])


def test_coincident_epicondyles_blank_supination_only():
    names = REQUIRED_MARKERS
    p = body(right=ELBOW_90)
    p[names.index("MRE1")] = p[names.index("MRE2")]
    got = angles_of(p)
    assert np.isnan(got["right_forearm_supination"])
    assert got["right_elbow_flexion"] == pytest.approx(90.0, abs=5.0)


# ---------------------------------------------------------------- frames, units, vectorization


def test_vectorized_over_frames_equals_per_frame():
    rng = np.random.default_rng(3)
    frames = [
        body(right=dict(upper_dir=unit(rng.normal(size=3)), elbow_flexion_deg=rng.uniform(0, 150),
                        supination_deg=rng.uniform(-90, 90), humeral_rotation_deg=rng.uniform(-60, 60)),
             left=dict(upper_dir=unit(rng.normal(size=3)), elbow_flexion_deg=rng.uniform(0, 150)))
        for _ in range(20)
    ]
    batch = joint_angles(np.stack(frames), REQUIRED_MARKERS)
    for t, frame in enumerate(frames):
        single = joint_angles(frame, REQUIRED_MARKERS)
        for c in ANGLE_COLUMNS:
            assert single[c].shape == ()
            np.testing.assert_allclose(batch[c][t], single[c], atol=1e-12, equal_nan=True)
    assert all(v.shape == (20,) for v in batch.values())


#: How closely the one-frame path (Python floats) and the array path (numpy) must agree. The two
#: round differently in the last bit (libm against numpy's vectorised atan2 and sqrt, which change
#: between releases); 1e-9 degrees is ten orders of magnitude below what markers can measure, and
#: far below any real disagreement (a sign flip, +180 against -180, a missed NaN).
PATHS_AGREE_DEG = 1e-9


def test_one_frame_path_agrees_with_the_array_path():
    """One frame is computed in Python floats (speed); it must give the array code's angles, with
    the same missing values and the same side of +-180."""
    rng = np.random.default_rng(11)
    frames = rng.normal(0.0, 0.3, (400, len(REQUIRED_MARKERS), 3))
    frames[rng.random(frames.shape[:2]) < 0.05] = np.nan  # missing markers
    frames[:40, 5] = frames[:40, 4]  # coincident epicondyles
    frames[40:80, 1] = frames[40:80, 0]  # coincident trunk markers
    frames[80:120] = np.round(frames[80:120], 1)  # exact zeros and axis-aligned vectors
    frames[120] = body(right=dict(upper_dir=(0.0, 1.0, 0.0)))  # straight up: +180, not -180
    batch = joint_angles(frames, REQUIRED_MARKERS)
    for t, frame in enumerate(frames):
        single = joint_angles(frame, REQUIRED_MARKERS)
        for c in ANGLE_COLUMNS:
            a, b = float(single[c]), float(batch[c][t])
            assert (np.isnan(a) and np.isnan(b)) or abs(a - b) <= PATHS_AGREE_DEG, (t, c, a, b)


def test_unit_independent():
    p = body(right=dict(ELBOW_90, humeral_rotation_deg=30.0, supination_deg=40.0), left=FORWARD)
    metres, millimetres = joint_angles(p, REQUIRED_MARKERS), joint_angles(p * 1000.0, REQUIRED_MARKERS)
    for c in ANGLE_COLUMNS:
        np.testing.assert_allclose(metres[c], millimetres[c], atol=1e-9, equal_nan=True)


def test_invariant_to_translation_and_vertical_rotation():
    p = body(right=dict(ELBOW_90, humeral_rotation_deg=30.0, supination_deg=40.0),
             left=dict(upper_dir=unit([-1, -0.2, -1]), elbow_flexion_deg=60.0))
    ref = angles_of(p)
    for yaw in (0.0, 37.0, 90.0, 180.0, -123.0):
        moved = angles_of(transform(p, rotation_matrix(Y, yaw), [1.5, -0.3, 2.0]))
        for c in ANGLE_COLUMNS:
            np.testing.assert_allclose(moved[c], ref[c], atol=1e-9, equal_nan=True, err_msg=f"{c} yaw {yaw}")


def test_arm_angles_are_relative_to_the_trunk():
    p = body(right=dict(ELBOW_90, humeral_rotation_deg=-30.0, supination_deg=60.0), left=SIDEWAYS)
    ref = angles_of(p)
    tilted = angles_of(transform(p, rotation_matrix([1, 0.4, -0.3], 25.0), [0.2, 0.0, -0.4]))
    for c in ANGLE_COLUMNS[:14]:
        np.testing.assert_allclose(tilted[c], ref[c], atol=1e-9, equal_nan=True, err_msg=c)
    assert abs(tilted["trunk_forward_lean"]) > 1.0 or abs(tilted["trunk_lateral_lean"]) > 1.0


def lean(p: np.ndarray, axis, angle_deg) -> np.ndarray:
    """Rotate the whole body about an axis through the hip midpoint."""
    names = REQUIRED_MARKERS
    centre = 0.5 * (p[names.index("MLH")] + p[names.index("MRH")])
    return transform(p - centre, rotation_matrix(axis, angle_deg), centre)


@pytest.mark.parametrize("angle", [5.0, 20.0, 45.0, -10.0])
def test_trunk_leans_of_known_angle(angle):
    p = body()
    forward = angles_of(lean(p, X, -angle))  # rotating about +X by -a tips +Y towards -Z (forwards)
    assert forward["trunk_forward_lean"] == pytest.approx(angle)
    assert forward["trunk_lateral_lean"] == pytest.approx(0.0, abs=1e-9)
    right = angles_of(lean(p, Z, -angle))  # rotating about +Z by -a tips +Y towards +X (right)
    assert right["trunk_lateral_lean"] == pytest.approx(angle)
    assert right["trunk_forward_lean"] == pytest.approx(0.0, abs=1e-9)
    # Arm angles ride with the trunk.
    for c in ANGLE_COLUMNS[:14]:
        np.testing.assert_allclose(forward[c], angles_of(p)[c], atol=1e-9, equal_nan=True)


def test_trunk_leans_use_world_axes():
    """A leaning trunk turned about the vertical changes which lean it shows (world X/Z axes)."""
    p = lean(body(), X, -20.0)
    turned = angles_of(transform(p, rotation_matrix(Y, 90.0), [0.0, 0.0, 0.0]))
    # Turned 90 degrees to its left about +Y, the patient now faces -X and leans towards -X.
    assert turned["trunk_forward_lean"] == pytest.approx(0.0, abs=1e-9)
    assert turned["trunk_lateral_lean"] == pytest.approx(-20.0)
    upright = angles_of(transform(body(), rotation_matrix(Y, 63.0), [0.0, 0.0, 0.0]))
    assert upright["trunk_forward_lean"] == pytest.approx(0.0, abs=1e-9)
    assert upright["trunk_lateral_lean"] == pytest.approx(0.0, abs=1e-9)


# ---------------------------------------------------------------- wrap180

@given(st.floats(-1e4, 1e4, allow_nan=False))
def test_wrap180_range_and_congruence(a):
    w = float(wrap180(a))
    assert -180.0 < w <= 180.0
    assert np.isclose(np.cos(np.radians(w)), np.cos(np.radians(a)), atol=1e-9)
    assert np.isclose(np.sin(np.radians(w)), np.sin(np.radians(a)), atol=1e-9)


def test_wrap180_edges():
    np.testing.assert_array_equal(wrap180([-180.0, 180.0, 540.0, -0.0, 270.0]), [180.0, 180.0, 180.0, 0.0, -90.0])
    assert np.signbit(wrap180(-0.0)) == np.False_
    assert np.isnan(wrap180(np.nan))


# ---------------------------------------------------------------- properties

directions = st.tuples(*[st.floats(-1, 1) for _ in range(3)]).map(np.array).filter(
    lambda v: np.linalg.norm(v) > 0.2
).map(unit)
arm_configs = st.fixed_dictionaries({
    "upper_dir": directions,
    "lateral_dir": directions,
    "humeral_rotation_deg": st.floats(-90, 90),
    "elbow_flexion_deg": st.floats(1, 160),
    "supination_deg": st.floats(-170, 170),
}).filter(lambda c: abs(np.dot(c["upper_dir"], c["lateral_dir"])) < 0.95)


def trunk_coordinates(u: np.ndarray, side: str) -> tuple[float, float, float]:
    """(out, down, forward) components of a world direction for an upright trunk."""
    return float(u[0] * SIGN[side]), float(-u[1]), float(-u[2])


@settings(max_examples=200, deadline=None)
@given(directions, st.sampled_from(["left", "right"]))
def test_shoulder_angles_are_consistent(u, side):
    lat = SIGN[side] * X if abs(u[0]) < 0.9 else Y
    pose = {"upper_dir": u, "lateral_dir": lat}
    got = angles_of(body(**{side: pose}))
    out, down, forward = trunk_coordinates(u, side)
    elevation = got[f"{side}_shoulder_elevation"]
    flexion, abduction = got[f"{side}_shoulder_flexion"], got[f"{side}_shoulder_abduction"]
    # Elevation is the angle to -y_T.
    assert elevation == pytest.approx(np.degrees(np.arccos(np.clip(down, -1, 1))), abs=1e-6)
    # Flexion and abduction are the sagittal and frontal projections of the same direction.
    norm_sag, norm_front = np.hypot(down, forward), np.hypot(down, out)
    if norm_sag > 1e-3:
        assert np.cos(np.radians(flexion)) == pytest.approx(down / norm_sag, abs=1e-6)
        assert np.sin(np.radians(flexion)) == pytest.approx(forward / norm_sag, abs=1e-6)
    if norm_front > 1e-3:
        assert np.cos(np.radians(abduction)) == pytest.approx(down / norm_front, abs=1e-6)
        assert np.sin(np.radians(abduction)) == pytest.approx(out / norm_front, abs=1e-6)
    if abs(down) > 0.05:
        tan2 = np.tan(np.radians(flexion)) ** 2 + np.tan(np.radians(abduction)) ** 2
        assert tan2 == pytest.approx(np.tan(np.radians(elevation)) ** 2, rel=1e-6, abs=1e-6)
    # Elevation and horizontal flexion are spherical coordinates of the arm: they rebuild it.
    horizontal = got[f"{side}_shoulder_horizontal_flexion"]
    if elevation < 45.0:
        assert np.isnan(horizontal)
    elif elevation < 179.0:
        e, h = np.radians(elevation), np.radians(horizontal)
        rebuilt = (np.sin(e) * np.cos(h), np.cos(e), np.sin(e) * np.sin(h))
        np.testing.assert_allclose(rebuilt, (out, down, forward), atol=1e-6)


@settings(max_examples=150, deadline=None)
@given(arm_configs, st.sampled_from(["left", "right"]))
def test_elbow_flexion_and_supination_follow_the_kinematics(config, side):
    got = angles_of(body(**{side: config}))
    assert got[f"{side}_elbow_flexion"] == pytest.approx(config["elbow_flexion_deg"], abs=1e-6)
    assert got[f"{side}_forearm_supination"] == pytest.approx(config["supination_deg"], abs=1e-6)


@settings(max_examples=100, deadline=None)
@given(st.floats(-90, 90), st.floats(31, 160), st.sampled_from(["left", "right"]))
def test_external_rotation_at_the_side_is_the_humeral_rotation(rotation, flexion, side):
    got = angles_of(body(**{side: dict(HANGING, humeral_rotation_deg=rotation, elbow_flexion_deg=flexion)}))
    assert got[f"{side}_shoulder_external_rotation"] == pytest.approx(rotation, abs=1e-6)


@settings(max_examples=100, deadline=None)
@given(arm_configs, arm_configs)
def test_mirrored_body_gives_the_same_numbers(right, left):
    p = body(right=right, left=left)
    a, b = angles_of(p), angles_of(mirror(p))
    for angle in ARM_ANGLES:
        np.testing.assert_allclose(b[f"left_{angle}"], a[f"right_{angle}"], atol=1e-7, equal_nan=True)
        np.testing.assert_allclose(b[f"right_{angle}"], a[f"left_{angle}"], atol=1e-7, equal_nan=True)
    assert b["trunk_forward_lean"] == pytest.approx(a["trunk_forward_lean"], abs=1e-9)
    assert b["trunk_lateral_lean"] == pytest.approx(-a["trunk_lateral_lean"], abs=1e-9)


@settings(max_examples=100, deadline=None)
@given(arm_configs, arm_configs, directions, st.floats(-180, 180),
       st.tuples(*[st.floats(-5000, 5000) for _ in range(3)]))
def test_arm_angles_invariant_to_any_rigid_motion(right, left, axis, angle, shift):
    p = body(right=right, left=left)
    a = joint_angles(p, REQUIRED_MARKERS)
    b = joint_angles(transform(p, rotation_matrix(axis, angle), shift), REQUIRED_MARKERS)
    # Skip what is ill-conditioned at this pose (an arm along a plane's normal, a value on a
    # NaN gate): there a 1 nm nudge of the markers already moves the angle.
    nudged = joint_angles(p + np.random.default_rng(0).normal(scale=1e-9, size=p.shape), REQUIRED_MARKERS)
    gates = {f"{side}_{angle}": (f"{side}_{gate}", limit) for side in ("left", "right") for angle, gate, limit in
             (("shoulder_horizontal_flexion", "shoulder_elevation", 45.0),
              ("shoulder_external_rotation", "elbow_flexion", 30.0))}
    for c in ANGLE_COLUMNS[:14]:
        if np.isnan(a[c]) != np.isnan(nudged[c]) or abs(float(wrap180(nudged[c] - a[c]))) > 1e-5:
            continue
        if c in gates and abs(a[gates[c][0]] - gates[c][1]) < 1e-6:
            continue
        assert np.isnan(a[c]) == np.isnan(b[c]), c
        if np.isfinite(a[c]):
            # Angles near +-180 may come out on either side of the wrap: compare on the circle.
            assert abs(float(wrap180(b[c] - a[c]))) < 1e-6, c


# ---------------------------------------------------------------- real capture

VICON_NAMES = {  # ours -> the Vicon capture's labels (content/captures/README.md)
    "MB": "STER", "MP": "XIPH", "MRS": "ACRO_tip", "MRE1": "EPICl", "MRE2": "EPICm",
    "MRW1": "STYLr", "MRW2": "STYLu", "MRH": "ASISr", "MLH": "ASISl",
}


def test_real_vicon_capture_gives_physiological_angles():
    """A real right-arm capture (Z up, right +Y, forward -X) turned into our frame."""
    from content import content_path
    from tracking.io.c3d import read_c3d_points

    _, theirs, _ = read_c3d_points(content_path("captures", "ezc3d_vicon_upper_limb.c3d"),
                                   labels=list(VICON_NAMES.values()))
    ours = theirs[..., [1, 2, 0]]  # (X, Y, Z) = (their Y, their Z, their X): a proper rotation
    got = joint_angles(ours, list(VICON_NAMES))
    assert all(np.isnan(got[f"left_{a}"]).all() for a in ARM_ANGLES)  # left arm not marked
    elevation = got["right_shoulder_elevation"]
    assert np.isfinite(elevation).all() and elevation.min() < 30 and 80 < elevation.max() < 120
    flexion = got["right_elbow_flexion"]
    assert np.nanmin(flexion) >= 0 and 120 < np.nanmax(flexion) < 160
    assert np.isnan(flexion).sum() == np.isnan(theirs[:, 6, 0]).sum()  # exactly STYLu's gaps
    assert np.nanmax(np.abs(got["right_forearm_supination"])) < 100
    assert np.nanmax(np.abs(got["trunk_forward_lean"])) < 30 and np.nanmax(np.abs(got["trunk_lateral_lean"])) < 30
