"""Marker sets as content: the roles in the YAML, the angles and the avatar taking their markers
from the roles, angles withheld (with a reason) where a set lacks their markers, and a second,
one-arm marker set with other names (content/markersets/right_arm_seated.yaml)."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest

from game.avatar.skeleton import SEGMENTS, SkeletonTracker
from tracking.angles import (
    ANGLE_COLUMNS, ANGLE_ROLES, AXIS_ANGLES, REQUIRED_MARKERS, axis_angles, joint_angles, supported_angles,
    withheld_angles,
)
from tracking.errors import ContentError
from tracking.live.source import angle_names_for
from tracking.markerset import DEFAULT_ROLES, ROLES, load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose, reference_pose
from tracking.sim.motions import load_motion
from tracking.marker_status import MarkerStatus

SEATED = load_markerset("upper_limb_seated")
ONE_ARM = load_markerset("right_arm_seated")
RIGHT_AND_TRUNK = tuple(c for c in ANGLE_COLUMNS if not c.startswith("left_"))


@lru_cache(maxsize=None)
def _dims(p: float, sex: str) -> BodyDimensions:
    return BodyDimensions.from_percentile(p, sex)


def _frames(markerset, motion: str, p: float = 50, sex: str = "male", n: int = 25) -> np.ndarray:
    """(n, M, 3) the simulated body's markers of ``markerset`` over a built-in motion."""
    dims = _dims(p, sex)
    body, m = BodyModel(dims, markerset), load_motion(motion, dims)
    return np.array([body.markers_m(m.pose_at(t)) for t in np.linspace(0.0, m.duration_s, n)])


# every angle defined (elevation > 45, elbow flexion > 30), arms not mirror images
ALL_DEFINED = Pose(trunk_forward_lean_deg=8.0, trunk_lateral_lean_deg=-4.0,
                   right=ArmPose.clinical(flexion_deg=80, abduction_deg=20, external_rotation_deg=25,
                                          elbow_flexion_deg=70, forearm_supination_deg=30),
                   left=ArmPose.clinical(flexion_deg=75, abduction_deg=50, external_rotation_deg=-20,
                                         elbow_flexion_deg=100, forearm_supination_deg=-40))


# ------------------------------------------------------------------------------------ the YAML
def test_the_default_set_names_every_role_by_its_documented_name():
    assert SEATED.roles == DEFAULT_ROLES and list(SEATED.roles) == list(ROLES)
    assert sorted(DEFAULT_ROLES.values()) == sorted(REQUIRED_MARKERS)
    assert AXIS_ANGLES == axis_angles(SEATED.roles)
    assert angle_names_for(SEATED) == ANGLE_COLUMNS


def _write(tmp_path, text: str):
    path = tmp_path / "set.yaml"
    path.write_text(
        "name: test_set\nmarker_diameter_mm: 40\nmarkers:\n"
        "  - {name: A, colour: [255, 0, 0], segment: trunk}\n"
        "  - {name: B, colour: [0, 255, 0], segment: trunk}\n"
        "  - {name: MB, colour: [0, 0, 255], segment: trunk}\n" + text, encoding="utf-8")
    return path


@pytest.mark.parametrize("roles, message", [
    ("{trunk_top: A}", r"unknown role 'trunk_top'; the roles are trunk_upper, trunk_lower, left_hip"),
    ("{trunk_lower: C, trunk_upper: MB}", r"roles.trunk_lower: unknown marker 'C'; the markers are A, B, MB"),
    ("{trunk_lower: A, left_hip: A, trunk_upper: MB}", r"A plays both trunk_lower and left_hip"),
    ("{trunk_lower: MB, trunk_upper: A}", r"marker MB is the trunk_upper marker's name in upper_limb_seated"),
    ("{trunk_lower: A}", r"marker MB is the trunk_upper marker's name"),
])
def test_bad_roles_are_one_line_errors_that_say_what_to_fix(tmp_path, roles, message):
    with pytest.raises(ContentError, match=message) as info:
        load_markerset(_write(tmp_path, f"roles: {roles}\n"))
    assert "\n" not in str(info.value)


def test_without_roles_the_upper_limb_seated_names_play_theirs(tmp_path):
    ms = load_markerset(_write(tmp_path, ""))
    assert ms.roles == {"trunk_upper": "MB"}
    ms = load_markerset(_write(tmp_path, "roles: {trunk_upper: MB, trunk_lower: B}\n"))
    assert ms.roles == {"trunk_upper": "MB", "trunk_lower": "B"}


# ------------------------------------------------------------------------------------ angles
def test_each_columns_roles_are_exactly_the_markers_its_formula_reads():
    """Hiding one role's marker empties exactly the columns that name that role, and leaves
    every other column as it was, to the last bit (several poses, both paths)."""
    frames = np.concatenate([_frames(SEATED, "shoulder_flexion", n=6), _frames(SEATED, "reach", n=6),
                             BodyModel(_dims(50, "male"), SEATED).markers_m(ALL_DEFINED)[None]])
    for mode in ("spec", "withhold"):
        base = joint_angles(frames, SEATED.names, near_singular=mode)
        assert all(np.isfinite(base[c][-1]) for c in ANGLE_COLUMNS)  # the last pose defines all
        for role, name in SEATED.roles.items():
            hidden = frames.copy()
            hidden[:, SEATED.index(name)] = np.nan
            per_frame = [joint_angles(f, SEATED.names, near_singular=mode) for f in hidden]
            for angles in (joint_angles(hidden, SEATED.names, near_singular=mode),
                           {c: np.array([float(a[c]) for a in per_frame]) for c in ANGLE_COLUMNS}):
                for column in ANGLE_COLUMNS:
                    if role in ANGLE_ROLES[column]:
                        assert np.isnan(angles[column]).all(), (role, column)
                    else:
                        np.testing.assert_allclose(angles[column], base[column], rtol=0, atol=1e-9,
                                                   err_msg=f"{role} {column}")


def test_renamed_markers_give_the_same_angles_through_their_roles():
    """The default set with every marker renamed: the same numbers through the roles (both
    paths, both modes); without the roles, not one number comes from another marker."""
    frames = np.concatenate([_frames(SEATED, "elbow_flexion_supination", 5, "female", 12),
                             _frames(SEATED, "shoulder_abduction", 95, "male", 12)])
    renamed = tuple(f"X{n.lower()}" for n in SEATED.names)
    roles = {role: f"X{name.lower()}" for role, name in SEATED.roles.items()}
    order = np.random.default_rng(3).permutation(SEATED.n_markers)  # another marker order too
    for mode in ("spec", "withhold"):
        base = joint_angles(frames, SEATED.names, near_singular=mode)
        moved = joint_angles(frames[:, order], [renamed[i] for i in order], roles=roles, near_singular=mode)
        one = [joint_angles(f, [renamed[i] for i in order], roles=roles, near_singular=mode) for f in frames[:, order]]
        for c in ANGLE_COLUMNS:
            np.testing.assert_allclose(moved[c], base[c], rtol=0, atol=1e-9, equal_nan=True)
            np.testing.assert_allclose([float(a[c]) for a in one], base[c], rtol=0, atol=1e-9, equal_nan=True)
        assert all(np.isnan(v).all() for v in joint_angles(frames, renamed, near_singular=mode).values())


def test_a_set_that_lacks_an_angles_markers_withholds_it_with_the_reason():
    assert withheld_angles(SEATED.roles) == {}
    withheld = withheld_angles(ONE_ARM.roles)
    assert set(withheld) == {c for c in ANGLE_COLUMNS if c.startswith("left_")}
    assert withheld["left_forearm_supination"] == (
        "the marker set has no marker for the left elbow lateral, left elbow medial, left wrist radial, left wrist ulnar")
    assert supported_angles(ONE_ARM.roles) == angle_names_for(ONE_ARM) == RIGHT_AND_TRUNK
    # an elbow with one marker: no elbow centre, so nothing that needs it (never the one marker)
    one_elbow_marker = {r: n for r, n in SEATED.roles.items() if r != "right_elbow_medial"}
    assert set(withheld_angles(one_elbow_marker)) == {c for c in ANGLE_COLUMNS if c.startswith("right_")}
    frame = BodyModel(_dims(50, "male"), SEATED).markers_m(ALL_DEFINED)
    got = joint_angles(frame, SEATED.names, roles=one_elbow_marker)
    assert all(math.isnan(got[c]) == c.startswith("right_") for c in ANGLE_COLUMNS)


# ------------------------------------------------------------------------------------ the one-arm set
@pytest.mark.parametrize("motion, p, sex", [("shoulder_flexion", 5, "female"), ("elbow_flexion_supination", 50, "male"),
                                            ("reach", 95, "male")])
def test_the_one_arm_set_gives_the_right_arm_and_trunk_angles_of_the_full_set(motion, p, sex):
    """The simulator places the one-arm set's markers on the same landmarks: its angles are the
    full set's for the right arm and the trunk, and the left arm's are withheld."""
    def frames(markerset):  # the motion, then a pose that defines every angle
        return np.concatenate([_frames(markerset, motion, p, sex),
                               BodyModel(_dims(p, sex), markerset).markers_m(ALL_DEFINED)[None]])

    full = joint_angles(frames(SEATED), SEATED.names)
    one = joint_angles(frames(ONE_ARM), ONE_ARM.names, roles=ONE_ARM.roles)
    for c in ANGLE_COLUMNS:
        if c.startswith("left_"):
            assert np.isnan(one[c]).all()
        else:
            np.testing.assert_allclose(one[c], full[c], rtol=0, atol=1e-9, equal_nan=True)
            assert np.isfinite(one[c]).any()


def test_the_avatar_is_built_from_the_one_arm_set():
    body_full, body_one = BodyModel(_dims(50, "male"), SEATED), BodyModel(_dims(50, "male"), ONE_ARM)
    full, one = SkeletonTracker(SEATED.names), SkeletonTracker(ONE_ARM.names, roles=ONE_ARM.roles)
    measured = np.full(ONE_ARM.n_markers, MarkerStatus.MEASURED, np.uint8)
    for pose in (reference_pose(), ALL_DEFINED):
        a = full.update(body_full.markers_m(pose), np.full(SEATED.n_markers, MarkerStatus.MEASURED, np.uint8))
        b = one.update(body_one.markers_m(pose), measured)
        for seg in SEGMENTS:
            want = MarkerStatus.LOST if seg.startswith("left_") else MarkerStatus.MEASURED
            assert b.segment_state(seg) is want
        # the joints placed from markers alone are where the full set puts them
        for joint in ("sternum", "right_acromion", "right_elbow", "right_wrist"):
            np.testing.assert_allclose(b.joint(joint), a.joint(joint), rtol=0, atol=1e-12)
        np.testing.assert_allclose(b.frame("right_forearm"), a.frame("right_forearm"), rtol=0, atol=1e-12)
        np.testing.assert_allclose(b.frame("trunk"), a.frame("trunk"), rtol=0, atol=1e-12)
    # the left arm, never seen, hangs from the trunk where an average adult's would
    assert b.joint("left_elbow")[0] < b.joint("sternum")[0] < b.joint("right_elbow")[0]


def test_a_marker_set_is_content_only():
    """The one-arm set's names appear in no module: it reaches the angles, the avatar and the
    live scene through its YAML alone."""
    import pathlib

    root = pathlib.Path(__file__).resolve().parents[2]
    code = "".join(p.read_text(encoding="utf-8") for d in ("tracking", "game") for p in (root / d).rglob("*.py"))
    assert not [n for n in ONE_ARM.names if f'"{n}"' in code or f"'{n}'" in code]


def test_rehab_angles_reads_a_file_of_another_marker_set_through_its_roles(tmp_path, capsys):
    from game.cli import main
    from tracking.io.csv_tables import read_angles_csv
    from tracking.io.trc import write_trc

    markers_mm = 1000.0 * np.concatenate([_frames(ONE_ARM, "reach", n=6),
                                          BodyModel(_dims(50, "male"), ONE_ARM).markers_m(ALL_DEFINED)[None]])
    trc = tmp_path / "one_arm.trc"
    write_trc(trc, ONE_ARM.names, markers_mm, 30.0)
    assert main(["angles", str(trc), "--out", str(tmp_path / "a.csv"), "--markerset", "right_arm_seated"]) == 0
    out = capsys.readouterr().out
    assert "left empty: left_shoulder_flexion," in out
    table = read_angles_csv(tmp_path / "a.csv")
    expected = joint_angles(markers_mm, ONE_ARM.names, roles=ONE_ARM.roles)
    for c in ANGLE_COLUMNS:  # the file keeps 3 decimals
        np.testing.assert_allclose(table.angles[c], expected[c], rtol=0, atol=1e-3, equal_nan=True)
    assert np.isfinite(table.angles["right_shoulder_external_rotation"]).any()
    assert np.isnan(table.angles["left_elbow_flexion"]).all()
    # the file lacks the marker set's markers, or two ways of naming them: one line each
    assert main(["angles", str(trc), "--out", str(tmp_path / "b.csv"), "--markerset", "upper_limb_seated"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "lacks MB, MP," in err and "(it has STRN, XIPH," in err
    assert main(["angles", str(trc), "--out", str(tmp_path / "c.csv"), "--markerset", "right_arm_seated",
                 "--map", str(trc)]) == 1
    assert "not both" in capsys.readouterr().err


def test_the_one_arm_set_is_tracked_on_the_simulator():
    """Rendered at 320x240 (4 cameras, 10 frames/s, the first 3 s of shoulder flexion) and
    tracked frame by frame: identified by its own rules, the measured markers on their balls, and
    its angles (through its roles) within 2 degrees RMS of the truth's where their markers are
    measured (as tests/tracking/test_tracker.py asks of the full set)."""
    from itertools import islice

    from tracking.sim.studio import SimulationSettings, studio_from_settings
    from tracking.tracker import Tracker, TrackingState

    studio, motion = studio_from_settings(SimulationSettings(
        motion="shoulder_flexion", markerset="right_arm_seated", size_px=(320, 240), fps=10.0))
    with studio:
        tracker = Tracker(studio.cameras, studio.markerset, fps=10.0)
        runs = [(tracker.step(sf.frames.images, sf.frames.time_s), sf.markers_m)
                for sf in islice(studio.play(motion, 10.0, noise_sigma=1.5), 30)]
    assert studio.markerset.names == ONE_ARM.names
    assert all(s.state == TrackingState.TRACKING for s, _ in runs)
    measured = np.array([s.status == MarkerStatus.MEASURED for s, _ in runs])
    err_m = np.array([np.linalg.norm(s.positions_m - t, axis=1) for s, t in runs])[measured]
    assert measured.mean() > 0.9 and np.sqrt(np.mean(err_m ** 2)) < 0.004
    tracked = joint_angles(np.array([s.positions_m for s, _ in runs]), ONE_ARM.names, roles=ONE_ARM.roles)
    truth = joint_angles(np.array([t for _, t in runs]), ONE_ARM.names, roles=ONE_ARM.roles)
    moved = np.nanmax(truth["right_shoulder_flexion"]) - np.nanmin(truth["right_shoulder_flexion"])
    assert moved > 30.0                                     # the arm rose in these 3 s
    checked = []
    for c in supported_angles(ONE_ARM.roles):
        reads = [ONE_ARM.index(ONE_ARM.roles[r]) for r in ANGLE_ROLES[c]]
        ok = measured[:, reads].all(axis=1) & np.isfinite(truth[c])
        if ok.sum() >= 10:  # (horizontal flexion and external rotation need a raised arm, a bent elbow)
            assert np.sqrt(np.mean((tracked[c][ok] - truth[c][ok]) ** 2)) < 2.0, c
            checked.append(c)
    assert {"right_shoulder_flexion", "right_shoulder_elevation", "right_elbow_flexion", "right_forearm_supination",
            "trunk_forward_lean"} <= set(checked)
    assert all(np.isnan(tracked[c]).all() for c in withheld_angles(ONE_ARM.roles))
