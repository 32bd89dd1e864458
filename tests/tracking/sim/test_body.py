"""Body model of the simulated patient: anthropometry, reference pose, markers, occlusion."""

from __future__ import annotations

import colorsys
import dataclasses
import itertools
import math
import time

import numpy as np
import pytest

from calibration.errors import RehabError
from tracking.markerset import load_markerset
from tracking.sim.body import (
    REFERENCE_ABDUCTION_DEG,
    REFERENCE_ELBOW_FLEXION_DEG,
    REFERENCE_EXTERNAL_ROTATION_DEG,
    REFERENCE_SUPINATION_DEG,
    ArmPose,
    BodyDimensions,
    BodyModel,
    Pose,
    _sdf_round_cones,
    is_occluded,
    occluded_fraction,
    reference_pose,
    scene_signed_distance,
)
from tracking.geometry.rotations import (
    direction_from_clinical,
    direction_from_plane,
    humerus_rotation,
    slerp_rotation,
    swing_twist,
)
from tracking.sim.scene import SceneFrame

MARKERSET = load_markerset()
BODIES = [(5, "female"), (50, "female"), (95, "female"), (5, "male"), (50, "male"), (95, "male")]
EXTREMES = [(5, "female"), (50, "male"), (95, "male")]
MIN_MARGIN_M = 0.015


def _model(p: float, sex: str) -> BodyModel:
    return BodyModel(BodyDimensions.from_percentile(p, sex), MARKERSET)


def _eye(azimuth_deg: float, height_m: float, distance_m: float) -> np.ndarray:
    """Camera centre around the patient: azimuth 0 = in front (-Z), + towards the patient's right."""
    a = math.radians(azimuth_deg)
    return np.array([distance_m * math.sin(a), height_m, -distance_m * math.cos(a)])


def structure_margins(p: np.ndarray) -> dict[str, float]:
    """Every inequality of docs/METHOD.md 5.2 as 'bigger minus smaller' (metres), keyed by the rule."""
    g = {n: p[i] for i, n in enumerate(MARKERSET.names)}
    left = [n for n in g if n.startswith("ML")]
    right = [n for n in g if n.startswith("MR")]
    out = {}
    for mid in ("MB", "MP"):
        out.update({f"x {n}<{mid}": g[mid][0] - g[n][0] for n in left})
        out.update({f"x {mid}<{n}": g[n][0] - g[mid][0] for n in right})
    for w in ("W1", "W2"):
        out[f"x ML{w}<MLH"] = g["MLH"][0] - g[f"ML{w}"][0]
        out[f"x MRH<MR{w}"] = g[f"MR{w}"][0] - g["MRH"][0]
    out["y MP<MB"] = g["MB"][1] - g["MP"][1]
    for s in "LR":
        for e in ("E1", "E2"):
            for low in ("H", "W1", "W2"):
                out[f"y M{s}{low}<M{s}{e}"] = g[f"M{s}{e}"][1] - g[f"M{s}{low}"][1]
            out[f"y M{s}{e}<M{s}S"] = g[f"M{s}S"][1] - g[f"M{s}{e}"][1]
        out[f"z M{s}E1<M{s}E2"] = g[f"M{s}E2"][2] - g[f"M{s}E1"][2]
        out[f"z M{s}W1<M{s}W2"] = g[f"M{s}W2"][2] - g[f"M{s}W1"][2]
    return out


# --------------------------------------------------------------------------- anthropometry


def test_percentiles_scale_the_body():
    small, big = BodyDimensions.from_percentile(5, "female"), BodyDimensions.from_percentile(95, "male")
    assert 1.45 < small.stature_m < 1.56 < 1.83 < big.stature_m < 1.92
    for name in ("upper_arm_m", "forearm_m", "biacromial_m", "seat_to_acromion_m", "chest_width_m"):
        assert getattr(big, name) > getattr(small, name)
    mid = BodyDimensions.from_percentile(50, "male")
    assert mid.upper_arm_m == pytest.approx(0.186 * mid.stature_m)
    assert mid.seat_height_m == pytest.approx(0.45)


@pytest.mark.parametrize("p, sex", [(4.9, "female"), (95.1, "male"), (0, "male"), (50, "other")])
def test_bad_percentile_or_sex_is_a_one_line_error(p, sex):
    with pytest.raises(RehabError) as err:
        BodyDimensions.from_percentile(p, sex)
    assert "\n" not in str(err.value)


# --------------------------------------------------------------------------- clinical angles


def test_clinical_directions():
    assert np.allclose(direction_from_clinical(0, 0), [0, -1, 0])
    assert np.allclose(direction_from_clinical(90, 0), [0, 0, -1], atol=1e-12)
    assert np.allclose(direction_from_clinical(0, 90), [1, 0, 0], atol=1e-12)
    assert np.allclose(direction_from_clinical(180, 0), [0, 1, 0], atol=1e-12)
    assert np.allclose(direction_from_plane(90, 160), direction_from_clinical(160, 0))
    u = direction_from_clinical(30, 20)
    assert math.degrees(math.atan2(-u[2], -u[1])) == pytest.approx(30)
    assert math.degrees(math.atan2(u[0], -u[1])) == pytest.approx(20)
    with pytest.raises(RehabError):
        direction_from_clinical(120, 30)


@pytest.mark.parametrize("plane, elevation, er", [(0, 0, 30), (90, 90, -45), (-30, 40, 80), (135, 120, 10), (20, 170, -60)])
def test_swing_twist_round_trip(plane, elevation, er):
    rot = humerus_rotation(direction_from_plane(plane, elevation), er)
    assert np.allclose(rot @ rot.T, np.eye(3), atol=1e-12) and np.linalg.det(rot) == pytest.approx(1.0)
    d, er_back = swing_twist(rot)
    assert np.allclose(d, direction_from_plane(plane, elevation))
    assert er_back == pytest.approx(er)


def test_slerp_rotation_ends_and_midpoint():
    r0 = humerus_rotation(direction_from_plane(0, 10), -20)
    r1 = humerus_rotation(direction_from_plane(90, 120), 40)
    assert np.allclose(slerp_rotation(r0, r1, 0.0), r0)
    assert np.allclose(slerp_rotation(r0, r1, 1.0), r1)
    mid = slerp_rotation(r0, r1, 0.5)
    assert np.allclose(mid @ mid.T, np.eye(3), atol=1e-12)


def _arm_vectors(p: np.ndarray, s: str) -> dict[str, np.ndarray]:
    g = {n: p[i] for i, n in enumerate(MARKERSET.names)}
    e = (g[f"M{s}E1"] + g[f"M{s}E2"]) / 2
    w = (g[f"M{s}W1"] + g[f"M{s}W2"]) / 2
    return {"u": e - g[f"M{s}S"], "f": w - e, "e": g[f"M{s}E2"] - g[f"M{s}E1"], "w": g[f"M{s}W2"] - g[f"M{s}W1"]}


def test_forearm_conventions_match_joint_angles_spec():
    """Elbow flexed 90 at the side, forearm forward: thumb up at supination 0, palm up at +90,
    forearm rotated outward at external rotation +45; the left arm mirrors the right."""
    model = _model(50, "male")
    for side, s, sign in (("right", "R", 1.0), ("left", "L", -1.0)):
        for sup, er, expect_w, expect_f in (
            (0, 0, [0, -1, 0], [0, 0, -1]),          # ulnar below radial: thumb up; forearm forward
            (90, 0, [-sign, 0, 0], [0, 0, -1]),      # ulnar medial: palm up
            (0, 45, [0, -1, 0], [sign * 0.7071, 0, -0.7071]),
        ):
            pose = Pose().with_arm(side, ArmPose.clinical(0, 0, er, 90, sup))
            v = _arm_vectors(model.markers_m(pose), s)
            w = v["w"] / np.linalg.norm(v["w"])
            f = v["f"] / np.linalg.norm(v["f"])
            assert np.allclose(w, expect_w, atol=0.02), (side, sup, er, w)
            assert np.allclose(f, expect_f, atol=0.02), (side, sup, er, f)


# --------------------------------------------------------------------------- reference pose


@pytest.mark.parametrize("p, sex", BODIES)
def test_reference_pose_structure_rules_with_margin(p, sex):
    """docs/METHOD.md 5.2 holds by >= 15 mm for every body and every +-10 degree arm perturbation."""
    model = _model(p, sex)
    worst = (math.inf, "", None)
    for dv in itertools.product((-10.0, 0.0, 10.0), repeat=5):
        pose = reference_pose(
            abduction_deg=REFERENCE_ABDUCTION_DEG + dv[0],
            flexion_deg=dv[1],
            external_rotation_deg=REFERENCE_EXTERNAL_ROTATION_DEG + dv[2],
            elbow_flexion_deg=REFERENCE_ELBOW_FLEXION_DEG + dv[3],
            forearm_supination_deg=REFERENCE_SUPINATION_DEG + dv[4],
        )
        for rule, margin in structure_margins(model.markers_m(pose)).items():
            if margin < worst[0]:
                worst = (margin, rule, dv)
    assert worst[0] >= MIN_MARGIN_M, f"rule {worst[1]} has margin {worst[0] * 1000:.1f} mm at perturbation {worst[2]}"


def test_reference_pose_is_mirror_symmetric():
    model = _model(50, "female")
    p = model.markers_m(reference_pose())
    idx = MARKERSET.index
    for n in MARKERSET.names:
        if n.startswith("MR"):
            right, left = p[idx(n)], p[idx("ML" + n[2:])]
            assert np.allclose(right * [-1, 1, 1], left, atol=1e-12), n
    assert np.allclose(p[[idx("MB"), idx("MP")], 0], 0.0, atol=1e-12)
    # Same numbers on both arms of any pose -> mirror images.
    arm = ArmPose.globe(40, 75, 30, 60, -45, 0.02)
    p = model.markers_m(Pose(right=arm, left=arm))
    assert np.allclose(p[idx("MRW1")] * [-1, 1, 1], p[idx("MLW1")])


def test_reference_pose_sits_on_the_seat_and_faces_minus_z():
    dims = BodyDimensions.from_percentile(50, "male")
    model = BodyModel(dims, MARKERSET)
    p = model.markers_m(reference_pose())
    g = {n: p[i] for i, n in enumerate(MARKERSET.names)}
    seat = dims.seat_height_m
    assert g["MRH"][1] > seat and g["MRS"][1] == pytest.approx(seat + dims.seat_to_acromion_m + MARKERSET.radius_m, abs=0.01)
    assert g["MB"][2] < 0 and g["MP"][2] < 0            # front markers are on the -Z side
    assert abs(g["MB"][0]) < 1e-9 and abs(np.mean(p[:, 0])) < 1e-9
    assert np.linalg.norm((g["MRS"] - g["MLS"])[[0]]) > dims.biacromial_m


# --------------------------------------------------------------------------- markers on the skin


@pytest.mark.parametrize("p, sex", EXTREMES)
def test_markers_sit_radius_plus_tissue_off_their_landmarks(p, sex):
    model = _model(p, sex)
    for pose in (reference_pose(), Pose(15, -5, 10, ArmPose.globe(60, 110, 40, 70, -30, 0.02), ArmPose.clinical(30, 10, -20, 120, 80))):
        markers = model.markers_m(pose)
        landmarks, normals = model.landmarks_m(pose)
        assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
        offset = MARKERSET.radius_m + MARKERSET.soft_tissue_m
        assert np.allclose(markers - landmarks, offset * normals, atol=1e-12)
    # In the reference pose every ball touches the skin: neither buried nor floating.
    pose = reference_pose()
    gap = scene_signed_distance(model.scene(pose), model.markers_m(pose), markers=False) - MARKERSET.radius_m
    assert np.all(gap > -0.001) and np.all(gap < 0.002), dict(zip(MARKERSET.names, np.round(gap * 1000, 1)))


def test_landmark_text_selects_the_body_landmark(tmp_path):
    """A custom marker set (other names, order, subset) is placed by its landmark text."""
    (tmp_path / "mine.yaml").write_text(
        "name: mine\nmarker_diameter_mm: 40\nsoft_tissue_mm: 5\nmarkers:\n"
        "  - {name: A, colour: [0, 0, 255], segment: arm, landmark: right medial epicondyle}\n"
        "  - {name: B, colour: [0, 0, 255], segment: trunk, landmark: xiphoid}\n"
        "  - {name: C, colour: [0, 0, 255], segment: arm, landmark: Left ulnar styloid}\n",
        encoding="utf-8",
    )
    mine = load_markerset(tmp_path / "mine.yaml")
    dims = BodyDimensions.from_percentile(50, "female")
    pose = reference_pose()
    full = BodyModel(dims, MARKERSET).markers_m(pose)
    got = BodyModel(dims, mine).markers_m(pose)
    assert np.allclose(got, full[[MARKERSET.index(n) for n in ("MRE2", "MP", "MLW2")]])
    (tmp_path / "bad.yaml").write_text(
        "name: bad\nmarker_diameter_mm: 40\nmarkers:\n"
        "  - {name: A, colour: [0, 0, 255], segment: arm, landmark: right knee}\n"
        "  - {name: B, colour: [0, 0, 255], segment: trunk, landmark: xiphoid}\n",
        encoding="utf-8",
    )
    with pytest.raises(RehabError, match="right knee"):
        BodyModel(dims, load_markerset(tmp_path / "bad.yaml"))


# --------------------------------------------------------------------------- scene


def test_scene_primitives_shapes_and_colours():
    model = _model(50, "female")
    scene = model.scene(reference_pose())
    assert isinstance(scene, SceneFrame)
    s, c, e = scene.sphere_radius_m.shape[0], scene.capsule_r0_m.shape[0], scene.ellipsoid_rgb.shape[0]
    assert scene.sphere_centre_m.shape == (s, 3) and scene.sphere_rgb.dtype == np.float32
    assert scene.sphere_marker_index.dtype == np.int32 and scene.n_markers == 14
    assert scene.capsule_p0_m.shape == scene.capsule_p1_m.shape == (c, 3) and c >= 10
    assert scene.ellipsoid_axes_m.shape == (e, 3, 3) and e >= 5
    is_marker = scene.sphere_marker_index >= 0
    assert np.array_equal(scene.sphere_marker_index[is_marker], np.arange(14))
    assert np.allclose(scene.sphere_radius_m[is_marker], MARKERSET.radius_m)
    assert np.allclose(scene.sphere_centre_m[is_marker], model.markers_m(reference_pose()))
    assert np.allclose(scene.sphere_rgb[is_marker], MARKERSET.rgb / 255.0)
    for axes in scene.ellipsoid_axes_m:  # semi-axes are orthogonal
        gram = axes.T @ axes
        assert np.allclose(gram, np.diag(np.diag(gram)), atol=1e-12)
    # Body colours are far in hue from every marker colour (or nearly grey).
    marker_hues = [colorsys.rgb_to_hsv(*c)[0] * 360 for c in MARKERSET.palette / 255.0]
    body = np.concatenate([scene.sphere_rgb[~is_marker], scene.capsule_rgb, scene.ellipsoid_rgb])
    for rgb in np.unique(body, axis=0):
        h, s_, _ = colorsys.rgb_to_hsv(*rgb)
        for mh in marker_hues:
            dh = abs((h * 360 - mh + 180) % 360 - 180)
            assert dh >= 25 or s_ < 0.3, (rgb, mh)


def test_scene_is_fast():
    model = _model(50, "female")
    pose = Pose(10, 5, 5, ArmPose.clinical(90, 0, 20, 45, 30), reference_pose().left)
    model.scene(pose)
    times = []
    for _ in range(50):
        t0 = time.perf_counter()
        model.scene(pose)
        times.append(time.perf_counter() - t0)
    assert np.median(times) < 0.004  # typically ~0.5 ms; generous for loaded CI machines


# --------------------------------------------------------------------------- occlusion


def test_round_cone_distance_matches_brute_force():
    rng = np.random.default_rng(1)
    a, b = np.array([[0.0, 0.0, 0.0]]), np.array([[0.3, 0.1, 0.0]])
    ra, rb = np.array([0.05]), np.array([0.03])
    pts = rng.uniform(-0.1, 0.4, size=(400, 3))
    sd = _sdf_round_cones(pts, a, b, ra, rb)[:, 0]
    # Brute force: the round cone is the union of spheres swept along the axis.
    t = np.linspace(0, 1, 4001)
    centres = a + t[:, None] * (b - a)
    radii = ra + t * (rb - ra)
    brute = (np.linalg.norm(pts[:, None] - centres[None], axis=2) - radii[None]).min(axis=1)
    inside = brute < -1e-3
    outside = brute > 1e-3
    assert np.all(sd[inside] < 0) and np.all(sd[outside] > 0)
    assert np.allclose(sd[outside], brute[outside], atol=2e-3)


def test_is_occluded_simple_scene():
    scene = SceneFrame.empty()
    scene = SceneFrame(
        np.array([[0.0, 1.0, 0.0], [0.0, 1.0, -0.5]]), np.array([0.02, 0.1]), np.zeros((2, 3), np.float32),
        np.array([0, -1], np.int32),
        scene.capsule_p0_m, scene.capsule_p1_m, scene.capsule_r0_m, scene.capsule_r1_m, scene.capsule_rgb,
        np.array([[1.0, 1.0, 0.0]]), np.diag([0.1, 0.2, 0.1])[None], np.zeros((1, 3), np.float32),
    )
    assert is_occluded(scene, [0, 1, 0], [0, 1, -2], skip_marker=0)           # blocker sphere in front
    assert not is_occluded(scene, [0, 1, 0], [0, 1, 2], skip_marker=0)        # free from behind
    assert is_occluded(scene, [0, 1, 0], [2, 1, 0], skip_marker=0)            # ellipsoid on the right
    assert occluded_fraction(scene, 0, [0, 1, -2]) == 1.0
    assert occluded_fraction(scene, 0, [0, 1, 2]) == 0.0
    # Eye placed so that the line of sight grazes the blocker's rim: about half the disc hidden.
    assert 0.3 < occluded_fraction(scene, 0, [0.4, 1, -2.0], n_rays=64) < 0.7


def with_chair(scene: SceneFrame) -> SceneFrame:
    """The scene plus the studio chair (tracking/sim/room.py: seat top 0.45 m, 0.46 m square;
    backrest 0.44 m wide from 0.59 to 0.89 m at z = 0.235 on two posts), as capsules that cover
    the boards, so that visibility is checked with the chair's occlusion (slightly overstated)."""
    p0, p1, r = [], [], []
    for y in (0.62, 0.70, 0.78, 0.86):  # backrest
        p0.append((-0.19, y, 0.235)), p1.append((0.19, y, 0.235)), r.append(0.03)
    for x in (-0.2, 0.2):  # posts
        p0.append((x, 0.45, 0.215)), p1.append((x, 0.86, 0.215)), r.append(0.02)
    for z in (-0.18, -0.06, 0.06, 0.18):  # seat
        p0.append((-0.2, 0.425, z)), p1.append((0.2, 0.425, z)), r.append(0.025)
    p0, p1, r = np.array(p0), np.array(p1), np.array(r)
    return dataclasses.replace(
        scene,
        capsule_p0_m=np.concatenate([scene.capsule_p0_m, p0]), capsule_p1_m=np.concatenate([scene.capsule_p1_m, p1]),
        capsule_r0_m=np.concatenate([scene.capsule_r0_m, r]), capsule_r1_m=np.concatenate([scene.capsule_r1_m, r]),
        capsule_rgb=np.concatenate([scene.capsule_rgb, np.zeros((r.size, 3), np.float32)]),
    )


# (azimuth deg, height m, distance m) of each camera, and the visible disc fraction that counts
# as seen: the studio's 60 % for its ring4 rig; half the disc for the lower cameras of the brief.
TYPICAL_RIGS = {
    "brief": ([(az, 1.5, 2.2) for az in (-35, 35, 145, -145)], 0.5),
    "ring4": ([(-40, 1.6, 2.0), (40, 1.6, 2.0), (140, 1.7, 2.0), (-140, 1.7, 2.0)], 0.6),
}


@pytest.mark.parametrize("rig", sorted(TYPICAL_RIGS))
@pytest.mark.parametrize("p, sex", EXTREMES)
def test_every_marker_seen_by_two_cameras_in_the_reference_pose(rig, p, sex):
    """Every marker is seen by two cameras, with the studio's chair in place (its backrest hides
    each wrist from the opposite rear camera, the thighs from the opposite front camera)."""
    model = _model(p, sex)
    scene = with_chair(model.scene(reference_pose()))
    cameras, seen = TYPICAL_RIGS[rig]
    eyes = [_eye(*c) for c in cameras]
    for i, name in enumerate(MARKERSET.names):
        visible = [1.0 - occluded_fraction(scene, i, eye, n_rays=64) for eye in eyes]
        assert sum(v >= seen for v in visible) >= 2, (name, np.round(visible, 2))


@pytest.mark.parametrize("p, sex", EXTREMES)
def test_medial_elbow_marker_hidden_with_elbow_against_the_trunk(p, sex):
    """The seed's experiment: elbow at the side, flexed 90, forearm forward -> MRE2 hidden from
    every camera position around the patient; at 60 degrees external rotation it reappears."""
    model = _model(p, sex)
    i = MARKERSET.index("MRE2")
    at_side = reference_pose().with_arm("right", ArmPose.clinical(0, 0, 0, 90, 0))
    abduction = model.elbow_at_side_abduction_deg(at_side)
    assert -15 < abduction < 10
    pose = at_side.with_arm("right", ArmPose.clinical(0, abduction, 0, 90, 0))
    assert abs(model.trunk_gap_m(pose, "right")) < 1e-4
    scene = model.scene(pose)
    centre = scene.sphere_centre_m[scene.sphere_marker_index == i][0]
    # Ball centre inside (or within a few mm of) the trunk, between the elbow and the trunk.
    assert scene_signed_distance(scene, centre[None], skip_sphere=i, markers=False)[0] < 0.003
    eyes = [_eye(az, h, 2.2) for az in range(0, 360, 30) for h in (0.5, 1.0, 1.5, 2.2)]
    for eye in eyes:
        assert is_occluded(scene, centre, eye, skip_marker=i), eye
        assert occluded_fraction(scene, i, eye, n_rays=24) >= 0.95, eye
    rotated = model.scene(pose.with_arm("right", ArmPose.clinical(0, abduction, 60, 90, 0)))
    front = [_eye(az, 1.5, 2.2) for az in (-35, 0, 35)]
    assert all(occluded_fraction(rotated, i, eye) <= 0.2 for eye in front)


# --------------------------------------------------------------------------- trunk and girdle


def test_trunk_lean_moves_the_trunk_not_the_pelvis():
    model = _model(50, "male")
    idx = MARKERSET.index
    upright = model.markers_m(reference_pose())
    ref = reference_pose()
    for fwd, lat in ((20.0, 0.0), (0.0, -15.0), (10.0, 10.0)):
        lean = Pose(fwd, lat, 0.0, ref.right, ref.left)
        p = model.markers_m(lean)
        assert np.allclose(p[[idx("MLH"), idx("MRH")]], upright[[idx("MLH"), idx("MRH")]])
        def reading(q):
            y = q[idx("MB")] - q[idx("MP")]
            return math.degrees(math.atan2(-y[2], y[1])), math.degrees(math.atan2(y[0], y[1]))
        f0, l0 = reading(upright)
        f1, l1 = reading(p)
        assert f1 - f0 == pytest.approx(fwd, abs=1.5) and l1 - l0 == pytest.approx(lat, abs=1.5)


def test_shrug_and_rhythm_raise_the_acromion():
    model = _model(50, "female")
    idx = MARKERSET.index("MRS")
    base = model.markers_m(Pose())[idx]
    shrug = model.markers_m(Pose(right=ArmPose.clinical(shoulder_shrug_m=0.03)))[idx]
    assert shrug - base == pytest.approx([0, 0.03, 0], abs=1e-9)
    raised = model.markers_m(Pose(right=ArmPose.clinical(150, 0)))[idx]
    assert raised[1] - base[1] == pytest.approx(model.girdle_rise_m(150), abs=0.01)
    assert model.girdle_rise_m(150) > 0.02
