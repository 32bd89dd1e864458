"""The avatar's skeleton driven by the tracked joint angles, as a BVH animation file.

Hierarchy (centimetres, +Y up, facing -Z as the world frame; the rest pose is upright with the
arms hanging, as the simulated body's identity pose)::

    Hips (root: position and rotation channels, fixed on the seat)
      Spine (lumbar pivot: the trunk's leans)
        Neck -> Head -> End Site
        RightArm (shoulder centre) -> RightForeArm (elbow) -> RightHand (wrist) -> End Site
        LeftArm ...

Every joint has ``Zrotation Xrotation Yrotation`` channels (the most common order; Blender's
importer reads any). The rotations come from the angles alone, with the kinematics of the
simulated body (``tracking/sim/body.py``):

- trunk: the tilt whose forward and lateral leans are the tracked ones (no axial rotation: the
  angles do not measure it);
- upper arm: the direction whose elevation and plane give the tracked flexion, abduction and
  horizontal flexion, twisted so that the forearm's direction gives the tracked external rotation;
- forearm: elbow flexion about the epicondyle axis, then supination about its long axis.

An angle that is undefined in a frame (NaN: horizontal flexion below 45 degrees of elevation,
external rotation with the elbow nearly straight, a lost marker) keeps its last defined value
(0 before the first), as BVH has no missing values. Segment lengths: medians of the tracked
markers' distances where given, else those of an average adult.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from tracking.angles import ANGLE_COLUMNS
from tracking.geometry.rotations import direction_from_plane, swing_matrix

_MIRROR = np.diag([-1.0, 1.0, 1.0])
_CM_PER_M = 100.0


@dataclass(frozen=True, slots=True)
class BvhSkeleton:
    """Segment lengths of the BVH skeleton, metres (defaults: an average adult, seated).

    Attributes:
        hip_height_m: the root's height above the floor (seat height plus a little).
        lumbar_m: root to the lumbar pivot (Spine).
        shoulder_height_m: lumbar pivot to the line of the shoulder centres.
        shoulder_half_width_m: half the distance between the shoulder centres.
        neck_m: lumbar pivot to the neck's base; head_m: the head's height.
        upper_arm_m, forearm_m, hand_m: shoulder to elbow, elbow to wrist, wrist to fingertips.
    """

    hip_height_m: float = 0.50
    lumbar_m: float = 0.10
    shoulder_height_m: float = 0.42
    shoulder_half_width_m: float = 0.18
    neck_m: float = 0.48
    head_m: float = 0.12
    upper_arm_m: float = 0.30
    forearm_m: float = 0.26
    hand_m: float = 0.18

    @classmethod
    def from_markers(cls, names: Sequence[str], positions_mm: np.ndarray) -> "BvhSkeleton":
        """Arm lengths and shoulder width from tracked ``upper_limb_seated`` markers (medians over
        the frames where they have positions); defaults for what the markers do not give."""
        p = np.asarray(positions_mm, dtype=np.float64) / 1000.0
        index = {n: i for i, n in enumerate(names)}

        def centre(*markers: str) -> np.ndarray | None:
            if not all(m in index for m in markers):
                return None
            return np.mean([p[:, index[m]] for m in markers], axis=0)

        def median_distance(a, b) -> float | None:
            if a is None or b is None:
                return None
            d = np.linalg.norm(a - b, axis=-1)
            d = d[np.isfinite(d)]
            return float(np.median(d)) if d.size else None

        lengths = {}
        upper, fore = [], []
        for s in ("R", "L"):
            shoulder, elbow, wrist = centre(f"M{s}S"), centre(f"M{s}E1", f"M{s}E2"), centre(f"M{s}W1", f"M{s}W2")
            upper.append(median_distance(shoulder, elbow))
            fore.append(median_distance(elbow, wrist))
        for key, values in (("upper_arm_m", upper), ("forearm_m", fore)):
            found = [v for v in values if v is not None]
            if found:
                lengths[key] = float(np.mean(found))
        width = median_distance(centre("MRS"), centre("MLS"))
        if width is not None:
            lengths["shoulder_half_width_m"] = width / 2.0
        return cls(**lengths)


def trunk_rotation(forward_lean_deg: float, lateral_lean_deg: float) -> np.ndarray:
    """(3, 3) trunk frame with these leans (docs/JOINT_ANGLES.md), hips along +X (no axial rotation):
    columns x_T (world X made orthogonal to y_T), y_T, z_T = x_T x y_T, as the angles build it."""
    f, lat = math.radians(forward_lean_deg), math.radians(lateral_lean_deg)
    # y_T . -Z / y_T . Y = tan(forward), y_T . X / y_T . Y = tan(lateral): exact for both at once
    y = np.array([math.sin(lat) * math.cos(f), math.cos(lat) * math.cos(f), -math.sin(f) * math.cos(lat)])
    y /= np.linalg.norm(y)
    x = np.array([1.0, 0.0, 0.0]) - y[0] * y
    x /= np.linalg.norm(x)
    return np.column_stack([x, y, np.cross(x, y)])


def humerus_rotation(flexion_deg: float, abduction_deg: float, elevation_deg: float, horizontal_flexion_deg: float,
                     external_rotation_deg: float) -> np.ndarray:
    """(3, 3) upper-arm frame in the trunk frame, right-side convention (``tracking/sim/body.py``:
    columns lateral epicondyle axis, elbow -> shoulder, posterior; identity = hanging, forearm
    forward when flexed), from the tracked shoulder angles (degrees; horizontal flexion may be NaN).
    """
    if math.isfinite(horizontal_flexion_deg):
        plane = horizontal_flexion_deg
    else:  # the plane from the sagittal and frontal projections (both below 90 here)
        f, a = math.radians(flexion_deg), math.radians(abduction_deg)
        plane = math.degrees(math.atan2(math.sin(f) * abs(math.cos(a)), math.sin(a) * abs(math.cos(f))))
    u = direction_from_plane(plane, elevation_deg)
    forward = np.array([0.0, 0.0, -1.0])
    r = forward - np.dot(forward, u) * u  # the spec's zero of external rotation
    if np.linalg.norm(r) < 1e-6:  # arm pointing straight forward: the body model's swing frame
        return swing_matrix(u) @ Rotation.from_euler("y", -external_rotation_deg, degrees=True).as_matrix()
    r /= np.linalg.norm(r)
    f_p = Rotation.from_rotvec(u * math.radians(external_rotation_deg)).apply(r)
    x_h = np.cross(u, f_p)
    return np.column_stack([x_h / np.linalg.norm(x_h), -u, -f_p])


def forearm_rotation(elbow_flexion_deg: float, supination_deg: float) -> np.ndarray:
    """(3, 3) forearm frame in the upper arm's, right-side convention: flexion about the epicondyle
    axis, then supination about the forearm's long axis."""
    return Rotation.from_euler("XY", [elbow_flexion_deg, -supination_deg], degrees=True).as_matrix()


#: The skeleton's joints and their parents, in the file's order (depth first).
JOINTS: tuple[tuple[str, str | None], ...] = (
    ("Hips", None), ("Spine", "Hips"), ("Neck", "Spine"), ("Head", "Neck"),
    ("RightArm", "Spine"), ("RightForeArm", "RightArm"), ("RightHand", "RightForeArm"),
    ("LeftArm", "Spine"), ("LeftForeArm", "LeftArm"), ("LeftHand", "LeftForeArm"),
)
_JOINTS = tuple(name for name, _ in JOINTS)
_CHANNELS = "CHANNELS 3 Zrotation Xrotation Yrotation"


def joint_offsets_m(sk: BvhSkeleton) -> dict[str, np.ndarray]:
    """Joint name -> (3,) offset from its parent (the root: from the floor), metres; ``"<joint>
    End"`` -> the end sites' offsets (head top, fingertips)."""
    out = {"Hips": (0.0, sk.hip_height_m, 0.0), "Spine": (0.0, sk.lumbar_m, 0.0), "Neck": (0.0, sk.neck_m, 0.0),
           "Head": (0.0, sk.head_m / 2, 0.0), "Head End": (0.0, sk.head_m, 0.0)}
    for side, sign in (("Right", 1.0), ("Left", -1.0)):
        out[f"{side}Arm"] = (sign * sk.shoulder_half_width_m, sk.shoulder_height_m, 0.0)
        out[f"{side}ForeArm"] = (0.0, -sk.upper_arm_m, 0.0)
        out[f"{side}Hand"] = (0.0, -sk.forearm_m, 0.0)
        out[f"{side}Hand End"] = (0.0, -sk.hand_m, 0.0)
    return {k: np.array(v) for k, v in out.items()}


def _hierarchy(sk: BvhSkeleton) -> str:
    offsets = joint_offsets_m(sk)
    cm = lambda v: " ".join(f"{_CM_PER_M * x:.4f}" for x in v)  # noqa: E731
    lines = ["HIERARCHY"]

    def joint(name: str, depth: int) -> None:
        pad = "  " * depth
        if depth == 0:
            lines.extend([f"ROOT {name}", "{", f"  OFFSET {cm(offsets[name])}",
                          "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"])
        else:
            lines.extend([f"{pad}JOINT {name}", f"{pad}{{", f"{pad}  OFFSET {cm(offsets[name])}", f"{pad}  {_CHANNELS}"])
        children = [child for child, parent in JOINTS if parent == name]
        for child in children:
            joint(child, depth + 1)
        if not children:
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {cm(offsets[name + ' End'])}", f"{pad}  }}"])
        lines.append(f"{pad}}}")

    joint("Hips", 0)
    return "\n".join(lines)


def _hold(values: np.ndarray) -> np.ndarray:
    """(T,) with each NaN replaced by the last finite value before it (0 before the first)."""
    v = np.asarray(values, dtype=np.float64)
    index = np.where(np.isfinite(v), np.arange(len(v)), -1)
    np.maximum.accumulate(index, out=index)
    return np.where(index >= 0, v[np.maximum(index, 0)], 0.0)


def local_rotations(angles_deg: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Joint name -> (T, 3, 3) rotation relative to its parent, from the angles (module docstring)."""
    a = {k: _hold(v) for k, v in angles_deg.items()}
    n = len(next(iter(a.values())))
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    out = {"Hips": eye, "Neck": eye, "Head": eye, "RightHand": eye, "LeftHand": eye}
    out["Spine"] = np.stack([trunk_rotation(f, lat) for f, lat in zip(a["trunk_forward_lean"], a["trunk_lateral_lean"])])
    for side in ("right", "left"):
        k = lambda name: a[f"{side}_{name}"]  # noqa: E731
        upper = np.stack([humerus_rotation(*v) for v in zip(
            k("shoulder_flexion"), k("shoulder_abduction"), k("shoulder_elevation"),
            # horizontal flexion as measured: NaN below 45 degrees of elevation, where the
            # (held) flexion and abduction give the plane
            np.asarray(angles_deg[f"{side}_shoulder_horizontal_flexion"], np.float64), k("shoulder_external_rotation"))])
        fore = np.stack([forearm_rotation(e, s) for e, s in zip(k("elbow_flexion"), k("forearm_supination"))])
        if side == "left":  # the same numbers mirrored across the sagittal plane
            upper, fore = _MIRROR @ upper @ _MIRROR, _MIRROR @ fore @ _MIRROR
        name = side.capitalize()
        out[f"{name}Arm"], out[f"{name}ForeArm"] = upper, fore
    return out


def write_bvh(path: str | Path, times_s: np.ndarray, angles_deg: Mapping[str, np.ndarray], rate_hz: float,
              skeleton: BvhSkeleton | None = None) -> None:
    """Write the skeleton driven by the angles as a BVH file, one frame per angles row.

    Args:
        path: file to write.
        times_s: (T,) seconds (frames are written at ``1 / rate_hz``, BVH has no time column).
        angles_deg: every column of the angles CSV -> (T,) degrees, NaN where undefined.
        rate_hz: frame rate.
        skeleton: segment lengths (default :class:`BvhSkeleton`).
    """

    missing = [c for c in ANGLE_COLUMNS if c not in angles_deg]
    if missing:
        raise ValueError(f"angles lacks columns {missing}")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be positive, got {rate_hz}")
    n = len(np.asarray(times_s))
    sk = skeleton or BvhSkeleton()
    columns = [np.tile([0.0, _CM_PER_M * sk.hip_height_m, 0.0], (n, 1))]
    if n:
        rotations = local_rotations({c: np.broadcast_to(np.asarray(angles_deg[c], np.float64), (n,)) for c in ANGLE_COLUMNS})
        for joint in _JOINTS:
            # a copy: older SciPy (1.11) refuses a read-only matrix (a broadcast view)
            columns.append(Rotation.from_matrix(np.array(rotations[joint])).as_euler("ZXY", degrees=True))
    body = np.hstack(columns) if n else np.empty((0, 3 + 3 * len(_JOINTS)))
    body[np.abs(body) < 5e-7] = 0.0  # no "-0.000000"
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(_hierarchy(sk) + "\n")
        fh.write(f"MOTION\nFrames: {n}\nFrame Time: {1.0 / rate_hz:.8f}\n")
        for row in body:
            fh.write(" ".join(f"{v:.6f}" for v in row) + "\n")

