"""OpenSim .mot and BVH files read by independent readers.

.mot: a parser written here from OpenSim's documented Storage format (header lines up to
``endheader``, ``key=value`` metadata, a tab-separated label line, rows of numbers), checked on
two real OpenSim files' headers as well, and OpenSim's own ``TimeSeriesTable`` where installed.
BVH: the ``bvh`` package parses the file; forward kinematics written here from the BVH
conventions turn it back into marker-like points whose joint angles must be the ones written.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tracking.angles import ANGLE_COLUMNS, joint_angles
from tracking.io.bvh import BvhSkeleton, write_bvh
from tracking.markerset import load_markerset
from tracking.io.opensim_mot import write_mot
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose

MS = load_markerset("upper_limb_seated")


# ------------------------------------------------------------------------------------ .mot


def parse_storage(text: str) -> tuple[dict[str, str], list[str], np.ndarray]:
    """OpenSim Storage / .mot text -> (metadata, labels, (rows, columns) values), by OpenSim 4's
    rules (opensim-core's Storage and DelimFileAdapter): header lines up to ``endheader``,
    ``key=value`` metadata, then the label line. A file of ``version`` 1 or less is read the
    legacy way, number after number from a C++ stream, which fails on ``NaN`` and keeps the rows
    before it; a higher version line by line, each cell as ``std::stod`` reads it (``NaN`` and
    ``inf`` in any case are numbers)."""
    lines = text.splitlines()
    end = next(i for i, line in enumerate(lines) if line.strip().lower() == "endheader")
    meta = {}
    for line in lines[:end]:
        if "=" in line:
            key, value = line.split("=", 1)
            meta[key.strip()] = value.strip()
    labels = lines[end + 1].split()
    body = [line for line in lines[end + 2:] if line.strip()]
    if int(meta.get("version", "0")) <= 1:
        tokens = " ".join(body).split()
        numbers = []
        for token in tokens:   # a C++ stream's double: digits, sign, point, exponent; no NaN or inf
            try:
                if not all(c in "0123456789+-.eE" for c in token):
                    raise ValueError(token)
                numbers.append(float(token))
            except ValueError:
                break
        rows = [numbers[k:k + len(labels)] for k in range(0, len(numbers) - len(labels) + 1, len(labels))]
    else:
        assert meta.get("DataType", "double") == "double"
        rows = [[float(v) for v in line.split("\t")] for line in body]
        assert all(len(r) == len(labels) for r in rows)
    values = np.array(rows, dtype=np.float64).reshape(len(rows), len(labels))
    return meta, labels, values


# The openings of two files of opensim-org/opensim-models (Apache-2.0): what the IK tool writes
# (Arm26/OutputReference/InverseKinematics/arm26_InverseKinematics.mot) and an older SIMM-style
# header (Gait2392_Simbody/OutputReference/subject01_walk1_ik.mot, first columns only).
OPENSIM_IK = (
    "Coordinates\nversion=1\nnRows=3\nnColumns=3\ninDegrees=yes\n\n"
    "Units are S.I. units (second, meters, Newtons, ...)\nAngles are in degrees.\n\nendheader\n"
    "time\tr_shoulder_elev\tr_elbow_flex\n"
    "      0.00000000\t     -0.03394423\t     -0.05440752\n"
    "      0.00833333\t     -0.03657365\t      0.01417949\n"
    "      0.01666667\t     -0.03908443\t      0.08815700\n"
)
SIMM_STYLE = (
    "first trial\nnRows=2\nnColumns=3\n\n# SIMM Motion File Header:\nname first trial\ndatacolumns 3\n"
    "datarows 2\notherdata 1\nrange 0.500000 4.000000\nendheader\n"
    "time\tpelvis_tx\tpelvis_ty\n"
    "      0.50000000000000000000\t      0.58979038325851030000\t      1.03317669587242710000\n"
    "      0.51700000000000002000\t      0.58848815987056491000\t      1.02962882297190790000\n"
)


def test_parser_reads_opensim_files():
    meta, labels, values = parse_storage(OPENSIM_IK)
    assert meta["inDegrees"] == "yes" and labels == ["time", "r_shoulder_elev", "r_elbow_flex"]
    np.testing.assert_allclose(values[:, 2], [-0.05440752, 0.01417949, 0.08815700])
    meta, labels, values = parse_storage(SIMM_STYLE)
    assert labels == ["time", "pelvis_tx", "pelvis_ty"] and values.shape == (2, 3)
    # OpenSim's legacy reader stops at a NaN (as opensim 4.6's Storage does, measured): the rule
    _, _, values = parse_storage(OPENSIM_IK.replace("0.01417949", "NaN"))
    assert values.shape == (1, 3)
    _, _, values = parse_storage(OPENSIM_IK.replace("version=1", "version=3").replace("0.01417949", "NaN"))
    assert values.shape == (3, 3) and np.isnan(values[1, 2])


def angles_table(n: int = 6, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    a = {c: rng.uniform(-40, 120, n) for c in ANGLE_COLUMNS}
    a["right_shoulder_horizontal_flexion"][2] = np.nan
    a["left_shoulder_external_rotation"][:] = np.nan
    return a


def test_mot_parses_as_opensim_storage(tmp_path):
    path = tmp_path / "angles.mot"
    a = angles_table()
    times = np.arange(6) / 30.0
    write_mot(path, times, a, name="angles")
    text = path.read_text()
    assert text.splitlines()[0] == "angles"
    meta, labels, values = parse_storage(text)
    assert meta == {"version": "3", "nRows": "6", "nColumns": str(1 + len(ANGLE_COLUMNS)), "inDegrees": "yes",
                    "DataType": "double"}
    assert labels == ["time", *ANGLE_COLUMNS] and values.shape == (6, 1 + len(ANGLE_COLUMNS))  # NaN rows too
    np.testing.assert_allclose(values[:, 0], times, atol=1e-8)
    for j, name in enumerate(ANGLE_COLUMNS, start=1):
        np.testing.assert_allclose(values[:, j], a[name], atol=1e-6, equal_nan=True)


def test_opensim_table_reader_reads_the_mot(tmp_path):
    opensim = pytest.importorskip("opensim")
    path = tmp_path / "angles.mot"
    a = angles_table(seed=3)
    write_mot(path, np.arange(6) / 30.0, a)
    table = opensim.TimeSeriesTable(str(path))
    assert list(table.getColumnLabels()) == list(ANGLE_COLUMNS) and table.getNumRows() == 6
    assert table.getTableMetaDataAsString("inDegrees") == "yes"
    for name in ("right_shoulder_horizontal_flexion", "left_shoulder_external_rotation", "trunk_forward_lean"):
        np.testing.assert_allclose(table.getDependentColumn(name).to_numpy(), a[name], atol=1e-6, equal_nan=True)


def test_opensim_storage_reads_the_whole_mot(tmp_path):
    """OpenSim's Storage (the GUI's File > Load Motion, the tools' inputs) reads every row, NaN
    where an angle is undefined (a version-1 header made it stop at the first NaN)."""
    opensim = pytest.importorskip("opensim", reason="opensim (PyPI wheel) not installed: not a dependency")
    path = tmp_path / "angles.mot"
    a = angles_table(n=40, seed=5)
    write_mot(path, np.arange(40) / 30.0, a)
    storage = opensim.Storage(str(path))
    assert storage.getSize() == 40 and storage.isInDegrees()
    for name in ("right_shoulder_horizontal_flexion", "left_shoulder_external_rotation", "right_elbow_flexion"):
        column = opensim.ArrayDouble()
        storage.getDataColumn(name, column)
        np.testing.assert_allclose([column.get(i) for i in range(column.getSize())], a[name], atol=1e-6,
                                   equal_nan=True)


def test_mot_rejects_bad_labels(tmp_path):
    with pytest.raises(ValueError, match="labels"):
        write_mot(tmp_path / "a.mot", np.zeros(1), {"left elbow": np.zeros(1)})


# ------------------------------------------------------------------------------------ BVH


def euler_zxy(z: float, x: float, y: float) -> np.ndarray:
    c, s = math.cos, math.sin
    rz = np.array([[c(z), -s(z), 0], [s(z), c(z), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, c(x), -s(x)], [0, s(x), c(x)]])
    ry = np.array([[c(y), 0, s(y)], [0, 1, 0], [-s(y), 0, c(y)]])
    return rz @ rx @ ry


def children(mocap, name: str) -> list[str]:
    """The joints whose parent is ``name``, in file order."""
    return [j for j in mocap.get_joints_names()
            if mocap.joint_parent(j) is not None and mocap.joint_parent(j).name == name]


def forward_kinematics(mocap, frame: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Joint name -> (world position cm, world rotation) of one frame, from the parsed BVH."""
    out = {}

    def visit(name: str, parent: tuple[np.ndarray, np.ndarray] | None) -> None:
        offset = np.array(mocap.joint_offset(name))
        z, x, y = (math.radians(v) for v in mocap.frame_joint_channels(frame, name, ["Zrotation", "Xrotation", "Yrotation"]))
        if parent is None:
            pos = np.array(mocap.frame_joint_channels(frame, name, ["Xposition", "Yposition", "Zposition"]))
            rot = euler_zxy(z, x, y)
        else:
            pos = parent[0] + parent[1] @ offset
            rot = parent[1] @ euler_zxy(z, x, y)
        out[name] = (pos, rot)
        for child in children(mocap, name):
            visit(child, out[name])

    visit(mocap.get_joints_names()[0], None)
    return out


def markers_from_skeleton(joints) -> np.ndarray:
    """(14, 3) marker-like points in marker-set order, built on the BVH's joints: trunk markers on
    the spine's axis, epicondyles along the upper arm's x, styloids along the forearm's z (as the
    simulated body places them), the left side mirrored."""
    spine_p, spine_r = joints["Spine"]
    hips_p = joints["Hips"][0]
    pts = {"MP": spine_p, "MB": spine_p + spine_r @ [0, 30.0, 0],
           "MRH": hips_p + [12.0, 0, 0], "MLH": hips_p + [-12.0, 0, 0]}
    for side, s, sign in (("Right", "R", 1.0), ("Left", "L", -1.0)):
        arm_p, arm_r = joints[f"{side}Arm"]
        elbow_p, elbow_r = joints[f"{side}ForeArm"]
        wrist_p = joints[f"{side}Hand"][0]
        pts[f"M{s}S"] = arm_p
        pts[f"M{s}E1"], pts[f"M{s}E2"] = elbow_p + arm_r @ [sign * 3.0, 0, 0], elbow_p - arm_r @ [sign * 3.0, 0, 0]
        pts[f"M{s}W1"], pts[f"M{s}W2"] = wrist_p - elbow_r @ [0, 0, 2.5], wrist_p + elbow_r @ [0, 0, 2.5]
    return np.array([pts[n] for n in MS.names])


def simulated_angles(n: int, seed: int) -> dict[str, np.ndarray]:
    """Joint angles of random poses of the simulated body (consistent sets, as the tracker gives)."""
    rng = np.random.default_rng(seed)
    body = BodyModel(BodyDimensions.from_percentile(50, "female"), MS)
    frames = []
    for _ in range(n):
        arms = [ArmPose.globe(plane_deg=rng.uniform(-30, 130), elevation_deg=rng.uniform(5, 160),
                              external_rotation_deg=rng.uniform(-60, 60), elbow_flexion_deg=rng.uniform(0, 140),
                              forearm_supination_deg=rng.uniform(-80, 80)) for _ in range(2)]
        pose = Pose(trunk_forward_lean_deg=rng.uniform(-10, 30), trunk_lateral_lean_deg=rng.uniform(-15, 15),
                    right=arms[0], left=arms[1])
        frames.append(body.markers_m(pose))
    return joint_angles(np.stack(frames), MS.names)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_bvh_parses_and_gives_back_the_angles(tmp_path, seed):
    bvh = pytest.importorskip("bvh")
    angles = simulated_angles(25, seed)
    path = tmp_path / "skeleton.bvh"
    write_bvh(path, np.arange(25) / 30.0, angles, 30.0)
    mocap = bvh.Bvh(path.read_text())
    assert mocap.get_joints_names() == ["Hips", "Spine", "Neck", "Head", "RightArm", "RightForeArm", "RightHand",
                                        "LeftArm", "LeftForeArm", "LeftHand"]
    assert children(mocap, "Spine") == ["Neck", "RightArm", "LeftArm"]
    assert children(mocap, "RightArm") == ["RightForeArm"] and children(mocap, "LeftForeArm") == ["LeftHand"]
    assert mocap.nframes == 25 and mocap.frame_time == pytest.approx(1 / 30.0)
    back = joint_angles(np.stack([markers_from_skeleton(forward_kinematics(mocap, i)) for i in range(25)]), MS.names)
    for name in ANGLE_COLUMNS:
        defined = np.isfinite(angles[name]) & np.isfinite(back[name])
        # both defined in the same frames, except external rotation, whose NaN (elbow < 30) is held
        if not name.endswith("external_rotation"):
            np.testing.assert_array_equal(np.isfinite(back[name]), np.isfinite(angles[name]), err_msg=name)
        diff = (back[name][defined] - angles[name][defined] + 180.0) % 360.0 - 180.0
        assert np.abs(diff).max(initial=0.0) < 1e-3, name


def test_bvh_holds_undefined_angles_and_takes_lengths_from_markers(tmp_path):
    bvh = pytest.importorskip("bvh")
    angles = simulated_angles(4, 7)
    angles["right_elbow_flexion"][2] = np.nan  # e.g. a lost wrist
    skeleton = BvhSkeleton.from_markers(["MRS", "MRE1", "MRE2"],
                                        np.array([[[0, 0, 0], [10, -310, 0], [-10, -310, 0]]] * 3, float))
    assert skeleton.upper_arm_m == pytest.approx(0.310) and skeleton.forearm_m == BvhSkeleton().forearm_m
    path = tmp_path / "s.bvh"
    write_bvh(path, np.arange(4) / 30.0, angles, 30.0, skeleton)
    mocap = bvh.Bvh(path.read_text())
    assert mocap.joint_offset("RightForeArm") == pytest.approx([0.0, -31.0, 0.0])
    row = [mocap.frame_joint_channels(i, "RightForeArm", ["Zrotation", "Xrotation", "Yrotation"]) for i in range(4)]
    # Z X Y of Rx(flexion) Ry(-supination): flexion is the X channel; the NaN one holds frame 1's
    assert row[2][0] == 0.0 and row[2][1] == row[1][1] == pytest.approx(angles["right_elbow_flexion"][1], abs=1e-5)
    assert row[2][2] == pytest.approx(-angles["right_forearm_supination"][2], abs=1e-5)


# Run inside Blender: import the BVH with Blender's own importer (File > Import > Motion Capture)
# and write the armature's bones, the scene's rate, the action's frames and the posed joints.
BLENDER_DUMP = '''
import builtins, json, sys
import bpy
import io_anim_bvh.import_bvh as importer
path, out = sys.argv[sys.argv.index("--") + 1:]
# Debian's Blender 3.4 runs its bundled importer on Python 3.11, which refuses the importer's
# open(path, "rU"): the same read without the removed "U" (Blender's own builds are unaffected)
importer.open = lambda file, mode="r", *args, **kw: builtins.open(file, mode.replace("U", ""), *args, **kw)
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath=path, update_scene_fps=True, update_scene_duration=True)
arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
scene = bpy.context.scene
first, last = (int(round(f)) for f in arm.animation_data.action.frame_range)
heads = []
for frame in range(first, last + 1):
    scene.frame_set(frame)
    heads.append({pb.name: list(arm.matrix_world @ pb.head) for pb in arm.pose.bones})
json.dump({"parents": [[b.name, b.parent.name if b.parent else None] for b in arm.data.bones],
           "fps": scene.render.fps / scene.render.fps_base, "frames": [first, last], "heads": heads}, open(out, "w"))
'''


@pytest.mark.parametrize("seed", [0, 1])
def test_blender_imports_the_bvh_as_the_avatar(tmp_path, seed):
    """Blender's importer (headless): the armature's bones and parents are the avatar's, the scene
    rate and the action's frames the file's, and every posed joint is where the BVH's forward
    kinematics (which give the angles back) put it, Blender's Z up (x, -z, y) against BVH's Y up."""
    import json
    import shutil
    import subprocess

    blender = shutil.which("blender")
    if blender is None:
        pytest.skip("Blender is not installed (apt-get install blender, or blender.org)")
    bvh = pytest.importorskip("bvh")
    from tracking.io.bvh import JOINTS

    angles = simulated_angles(12, seed)
    path, script, out = tmp_path / "skeleton.bvh", tmp_path / "dump.py", tmp_path / "out.json"
    write_bvh(path, np.arange(12) / 25.0, angles, 25.0)
    script.write_text(BLENDER_DUMP)
    run = subprocess.run([blender, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(script),
                          "--", str(path), str(out)], capture_output=True, text=True, timeout=180)
    assert run.returncode == 0 and out.is_file(), run.stdout[-2000:] + run.stderr[-2000:]
    result = json.loads(out.read_text())
    assert [tuple(p) for p in result["parents"]] == list(JOINTS)
    assert result["fps"] == pytest.approx(25.0, abs=1e-4) and result["frames"] == [1, 12]
    mocap = bvh.Bvh(path.read_text())
    for frame, heads in enumerate(result["heads"]):
        for name, (p, _) in forward_kinematics(mocap, frame).items():
            np.testing.assert_allclose(heads[name], [p[0], -p[2], p[1]], atol=1e-3, err_msg=f"{name}, frame {frame}")
