"""Motions of the simulated patient: content, scripted keyframes, capture replays."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from calibration.errors import RehabError
from content import content_path
from tracking.errors import ContentError, MotionError
from tracking.markerset import load_markerset
from tracking.sim.body import BodyDimensions, BodyModel, is_occluded, occluded_fraction, reference_pose
from tracking.sim.capture_replay import CaptureReplay, axes_matrix, _AxesSpec
from tracking.sim.motions import ScriptedMotion, available_motions, ease, load_motion

MARKERSET = load_markerset()
DIMS = BodyDimensions.from_percentile(50, "female")
CAPTURES = ("vicon_upper_limb", "qualisys_walk")


@lru_cache(maxsize=None)
def _model(p: float = 50, sex: str = "female") -> BodyModel:
    return BodyModel(BodyDimensions.from_percentile(p, sex), MARKERSET)


@lru_cache(maxsize=None)
def _motion(name: str, p: float = 50, sex: str = "female"):
    return load_motion(name, BodyDimensions.from_percentile(p, sex))


def _eye(azimuth_deg: float, height_m: float = 1.5, distance_m: float = 2.2) -> np.ndarray:
    a = math.radians(azimuth_deg)
    return np.array([distance_m * math.sin(a), height_m, -distance_m * math.cos(a)])


def _elbow_deg(p: np.ndarray, s: str) -> float:
    """docs/JOINT_ANGLES.md elbow flexion from marker centres (M, 3)."""
    g = {n: p[i] for i, n in enumerate(MARKERSET.names)}
    e = (g[f"M{s}E1"] + g[f"M{s}E2"]) / 2
    u, f = e - g[f"M{s}S"], (g[f"M{s}W1"] + g[f"M{s}W2"]) / 2 - e
    return math.degrees(math.atan2(np.linalg.norm(np.cross(u, f)), u @ f))


# --------------------------------------------------------------------------- every content motion


def test_content_has_the_required_motions():
    names = set(available_motions())
    assert {"reference", "right_external_rotation", "shoulder_flexion", "shoulder_abduction",
            "elbow_flexion_supination", "reach", "trunk_lean_compensation", *CAPTURES} <= names


@pytest.mark.parametrize("name", available_motions())
def test_every_motion_starts_in_the_reference_pose_and_stays_finite(name):
    motion = _motion(name)
    model = _model()
    ref = model.markers_m(reference_pose())
    assert motion.duration_s >= 4.0
    for t in np.linspace(0.0, 1.0, 6):  # identification happens during this hold
        assert np.allclose(model.markers_m(motion.pose_at(t)), ref, atol=1e-9), t
    times = motion.times(20.0)
    assert times[0] == 0 and times[-1] <= motion.duration_s + 1e-9 and times[-1] > motion.duration_s - 0.05
    p = np.array([model.markers_m(motion.pose_at(t)) for t in times])
    assert np.all(np.isfinite(p))
    # No jumps: scripted markers move at most 6 cm in 1/20 s (1.2 m/s); replayed ones at most
    # 30 % faster than the capture's own landmarks (our limbs differ in length from the subject's).
    limit = 0.06
    if isinstance(motion, CaptureReplay):
        k = int(round(motion.rate_hz / 20.0))
        lm = motion.landmarks_m
        limit = 1.3 * np.linalg.norm(lm[k:] - lm[:-k], axis=2).max()
    assert np.linalg.norm(np.diff(p, axis=0), axis=2).max() < limit
    # Markers stay in the studio: above the floor, within 1.2 m of the patient.
    assert p[..., 1].min() > 0.0 and np.abs(p[..., [0, 2]]).max() < 1.2


@pytest.mark.parametrize("p, sex", [(5, "female"), (95, "male")])
def test_scripted_motions_solve_for_every_body(p, sex):
    dims = BodyDimensions.from_percentile(p, sex)
    model = BodyModel(dims, MARKERSET)
    for name in ("right_external_rotation", "reach"):
        motion = load_motion(name, dims)
        assert all(np.all(np.isfinite(model.markers_m(motion.pose_at(t)))) for t in motion.times(5.0))


# --------------------------------------------------------------------------- scripted


def test_ease_profiles():
    for kind in ("minimum_jerk", "cosine", "linear"):
        assert ease(0.0, kind) == 0.0 and ease(1.0, kind) == 1.0 and ease(0.5, kind) == pytest.approx(0.5)
        assert ease(-1.0, kind) == 0.0 and ease(2.0, kind) == 1.0
    h = 1e-4  # minimum jerk starts and ends at rest
    assert ease(h) / h < 1e-6 and (1.0 - ease(1.0 - h)) / h < 1e-6


def test_keyframes_are_reached_and_held():
    motion = _motion("shoulder_flexion")
    assert isinstance(motion, ScriptedMotion)
    t = motion.keyframe_times_s()
    pose = motion.pose_at(t[1])
    assert pose.right.elevation_deg == pytest.approx(160.0)
    assert motion.pose_at(t[1] + 0.99).right.elevation_deg == pytest.approx(160.0)  # hold_s 1.0
    assert pose.left.elevation_deg == pytest.approx(reference_pose().left.elevation_deg)
    assert motion.pose_at(t[3]).left.elevation_deg == pytest.approx(160.0)
    # Monotonic rise between the hold and the keyframe.
    rise = [motion.pose_at(x).right.elevation_deg for x in np.linspace(1.5, t[1], 20)]
    assert np.all(np.diff(rise) >= -1e-9)


def test_right_external_rotation_hides_then_reveals_mre2():
    """The seed's experiment: MRE2 hidden with the elbow at the side, visible at 65 degrees."""
    from tracking.angles import joint_angles

    motion, model = _motion("right_external_rotation"), _model()
    i = MARKERSET.index("MRE2")
    eyes = [_eye(az, h, 2.0) for az in (-40, 40, 140, -140, 0, 90, -90, 180) for h in (1.0, 1.6)]
    t = motion.keyframe_times_s()
    hidden = model.scene(motion.pose_at(t[1] + 0.5))
    assert all(is_occluded(hidden, hidden.sphere_centre_m[i], eye, skip_marker=i) for eye in eyes)
    shown = model.scene(motion.pose_at(t[2] + 0.5))
    assert sum(occluded_fraction(shown, i, _eye(az, 1.6, 2.0)) <= 0.4 for az in (-40, 40, 140, -140)) >= 2
    angles = joint_angles(model.markers_m(motion.pose_at(t[2] + 0.5)), MARKERSET.names)
    assert float(angles["right_shoulder_external_rotation"]) == pytest.approx(65, abs=5)
    assert float(angles["right_elbow_flexion"]) == pytest.approx(90, abs=8)
    assert abs(float(angles["right_shoulder_abduction"])) < 8  # elbow at the side
    assert model.trunk_gap_m(motion.pose_at(t[1] + 0.5), "right") == pytest.approx(0.0, abs=2e-3)


def test_reach_puts_the_wrist_on_its_target():
    motion, model = _motion("reach"), _model()
    d = model.dims
    t = motion.keyframe_times_s()
    for k, side, target in ((1, "right", (0.05, 0.1, 0.95)), (3, "right", (-0.5, -0.05, 0.75))):
        joints = model.joint_centres_m(motion.pose_at(t[k]), side)
        reach = np.linalg.norm(joints["wrist"] - joints["gh"])
        want = min(np.linalg.norm(target), 0.985) * (d.upper_arm_m + d.forearm_m)
        assert reach == pytest.approx(want, abs=0.03)  # GH rises with the rhythm; the target does not


def test_trunk_lean_compensation_differs_only_in_the_second_repetition():
    motion, model = _motion("trunk_lean_compensation"), _model()
    t = motion.keyframe_times_s()
    clean, comp = motion.pose_at(t[1] + 0.5), motion.pose_at(t[3] + 0.5)
    assert clean.right.elevation_deg == pytest.approx(comp.right.elevation_deg)
    assert clean.trunk_lateral_lean_deg == 0 and comp.trunk_lateral_lean_deg == -10
    assert comp.right.shoulder_shrug_m == pytest.approx(0.03)
    rs = MARKERSET.index("MRS")
    assert model.markers_m(comp)[rs][1] - model.markers_m(clean)[rs][1] > 0.01


# --------------------------------------------------------------------------- errors


def test_unknown_motion_lists_the_available_names():
    with pytest.raises(MotionError) as err:
        load_motion("no_such_motion", DIMS)
    msg = str(err.value)
    assert "\n" not in msg and "no_such_motion" in msg
    assert all(name in msg for name in ("reference", "right_external_rotation", "vicon_upper_limb"))
    with pytest.raises(RehabError):
        load_motion("/nowhere/motion.yaml", DIMS)


@pytest.mark.parametrize(
    "body, fragment",
    [
        ("kind: scripted\nkeyframes:\n  - {t_s: 0, hold_s: 2, wobble: 1}\n", "wobble"),
        ("kind: scripted\nkeyframes:\n  - {t_s: 0, hold_s: 0.5}\n", "reference pose"),
        ("kind: scripted\nkeyframes:\n  - {t_s: 0, hold_s: 2, right: {flexion_deg: 20}}\n", "reference pose"),
        ("kind: scripted\nkeyframes:\n  - {t_s: 0, hold_s: 2}\n  - {t_s: 1.5}\n", "after the previous"),
        ("kind: scripted\nkeyframes:\n  - {t_s: 0, hold_s: 2}\n  - {t_s: 3, right: {flexion_deg: 20, plane_deg: 3, elevation_deg: 4}}\n", "one way"),
        ("kind: dance\n", "scripted"),
    ],
)
def test_bad_motion_yaml_is_a_one_line_content_error(tmp_path, body, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text(body, encoding="utf-8")
    with pytest.raises(ContentError) as err:
        load_motion(path, DIMS)
    assert "\n" not in str(err.value) and fragment in str(err.value) and "bad.yaml" in str(err.value)


def _write_c3d(path: Path, labels: list[str], frames: int = 30) -> None:
    import ezc3d

    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = labels
    pts = np.ones((4, len(labels), frames))
    pts[:3] = np.random.default_rng(0).uniform(100, 1000, size=(3, len(labels), frames))
    c3d["data"]["points"] = pts
    c3d.write(str(path))


def test_c3d_missing_a_landmark_is_a_one_line_error(tmp_path):
    labels = ["STER", "XIPH", "ACRO_tip", "EPICl", "EPICm", "STYLr", "ASISr", "ASISl"]  # no STYLu
    _write_c3d(tmp_path / "short.c3d", labels)
    text = (content_path("motions", "vicon_upper_limb.yaml").read_text(encoding="utf-8")
            .replace("file: ezc3d_vicon_upper_limb.c3d", "file: short.c3d"))
    (tmp_path / "short.yaml").write_text(text, encoding="utf-8")
    with pytest.raises(MotionError) as err:
        load_motion(tmp_path / "short.yaml", DIMS)
    msg = str(err.value)
    assert "\n" not in msg and "short.c3d" in msg and "STYLu" in msg and "STER" not in msg.split("labels")[1]


def test_c3d_without_a_known_mapping(tmp_path):
    _write_c3d(tmp_path / "odd.c3d", ["A", "B", "C"])
    with pytest.raises(MotionError, match="odd.c3d.*mapping"):
        load_motion(tmp_path / "odd.c3d", DIMS)


def test_c3d_path_loads_with_the_bundled_mapping():
    motion = load_motion(content_path("captures", "ezc3d_qualisys_walk.c3d"), DIMS)
    assert isinstance(motion, CaptureReplay) and motion.rate_hz == 200


def test_axes_mapping():
    m = axes_matrix(_AxesSpec(up="+Z", forward="-X", right="+Y"))  # Vicon
    assert np.allclose(m @ [0, 0, 1], [0, 1, 0]) and np.allclose(m @ [-1, 0, 0], [0, 0, -1])
    assert np.allclose(m @ [0, 1, 0], [1, 0, 0])
    with pytest.raises(MotionError, match="left-handed"):
        axes_matrix(_AxesSpec(up="+Z", forward="-X", right="-Y"))


# --------------------------------------------------------------------------- capture replays


@pytest.mark.parametrize("name", CAPTURES)
def test_capture_replay_reproduces_the_elbow_flexion(name):
    """The capture's elbow angle (from its landmarks, docs/JOINT_ANGLES.md) is what our body shows."""
    motion, model = _motion(name), _model()
    frames = np.arange(0, motion.landmarks_m.shape[0], 4)
    for side, s in (("right", "R"), ("left", "L")):
        if side not in motion.angles.elbow_flexion_deg:
            continue
        cap = motion.angles.elbow_flexion_deg[side][frames]
        poses = [motion.pose_at(motion.capture_start_s + f / motion.rate_hz) for f in frames]
        ours = np.array([_elbow_deg(model.markers_m(p), s) for p in poses])
        assert np.abs(ours - cap).max() < 2.0
        # The pose's anatomical elbow angle (about GH, not the acromion marker) differs from the
        # marker reading by the acromion-GH offset seen from the elbow: at most ~15 degrees.
        hinge = np.array([p.arm(side).elbow_flexion_deg for p in poses])
        assert np.abs(hinge - cap).max() < 15.0 and np.abs(np.median(hinge - cap)) < 10.0
        assert np.ptp(cap) > 25.0  # the captures do move the elbow


def test_capture_replay_reproduces_the_shoulder_angles():
    from tracking.angles import joint_angles

    motion, model = _motion("vicon_upper_limb"), _model()
    frames = np.arange(0, motion.landmarks_m.shape[0], 10)
    cap = joint_angles(motion.landmarks_m[frames], motion.landmark_names)
    ours = joint_angles(np.array([model.markers_m(motion.pose_at(motion.capture_start_s + f / motion.rate_hz))
                                  for f in frames]), MARKERSET.names)
    for k in ("right_shoulder_elevation", "right_shoulder_flexion", "right_shoulder_abduction",
              "right_forearm_supination"):
        assert np.nanmax(np.abs(ours[k] - cap[k])) < 2.0, k
    assert np.nanmax(cap["right_shoulder_elevation"]) > 80  # large elevations


def test_vicon_left_arm_mirrors_the_right_with_a_delay():
    motion, model = _motion("vicon_upper_limb"), _model()
    delay = motion.mirror_delay_s
    assert delay and delay > 0.5
    for t in np.linspace(motion.capture_start_s, motion.capture_start_s + motion.capture_duration_s, 9):
        p_right = model.markers_m(motion.pose_at(t))
        p_left = model.markers_m(motion.pose_at(t + delay))
        assert _elbow_deg(p_left, "L") == pytest.approx(_elbow_deg(p_right, "R"), abs=1e-6)


def test_vicon_gap_is_filled_smoothly():
    motion = _motion("vicon_upper_limb")
    j = motion.landmark_names.index("MRW2")
    filled = motion.filled[:, j]
    assert 20 <= filled.sum() <= 40 and not motion.filled[:, motion.landmark_names.index("MB")].any()
    x = motion.landmarks_m[:, j]
    assert np.all(np.isfinite(x))
    # The filled stretch moves like the radial styloid beside it (the wrist width stays plausible).
    width = np.linalg.norm(x - motion.landmarks_m[:, motion.landmark_names.index("MRW1")], axis=1)
    assert width[filled].min() > 0.02 and width[filled].max() < 0.09


def test_capture_blends_in_from_the_reference_and_back():
    motion, model = _motion("qualisys_walk"), _model()
    ref = model.markers_m(reference_pose())
    assert np.allclose(model.markers_m(motion.pose_at(0.99)), ref)
    assert np.allclose(model.markers_m(motion.pose_at(motion.duration_s)), ref, atol=1e-9)
    start = model.markers_m(motion.pose_at(motion.capture_start_s))
    just_after = model.markers_m(motion.pose_at(motion.capture_start_s + 1e-3))
    assert np.abs(start - just_after).max() < 0.002  # no jump into the capture
    # Resampling: any rate, poses between capture frames are interpolated.
    t = motion.capture_start_s + 10.5 / motion.rate_hz
    a, b = (model.markers_m(motion.pose_at(motion.capture_start_s + k / motion.rate_hz)) for k in (10, 11))
    assert np.abs(model.markers_m(motion.pose_at(t)) - (a + b) / 2).max() < 0.002
    assert len(motion.times(7.3)) == int(motion.duration_s * 7.3 + 1e-9) + 1
