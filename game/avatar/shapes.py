"""The avatar's body as simple solids, from a :class:`SkeletonPose` (pure numpy, no GL).

:func:`body_shapes` dresses the skeleton in ellipsoids (thorax, abdomen, pelvis, head, hands,
feet, joints) and tapered capsules (neck, shoulders, arms, thumbs, legs, chair), each tagged with
the skeleton segment it belongs to so the renderer can colour it by that segment's state. Sizes
scale with the patient's learned stature and measured widths; proportions of the solids relative
to the markers follow the simulator's body model (``tracking.sim.body``), so the avatar's surface
lies where the patient's skin is.

Untracked parts (thighs, lower legs, feet, the chair) hang from the pelvis: the seated legs are
drawn in a fixed, relaxed position with the feet on the floor, and :attr:`BodyShapes.floor_y_m`
is the floor height that this implies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from game.avatar.skeleton import SEGMENTS, SIDE_SIGN, SkeletonPose, frame_from_axes

#: ``part`` of a solid that follows no tracked segment: legs and feet (drawn in their own colours,
#: never tinted) and the chair.
PART_LEGS = -1
PART_CHAIR = -2

# sRGB 0-255: a friendly, well-separated palette (none of the marker hues matter here).
SKIN_RGB = (236, 184, 152)
PALM_RGB = (252, 214, 196)
SHIRT_RGB = (70, 132, 196)
TROUSERS_RGB = (58, 66, 96)
SHOES_RGB = (70, 70, 78)
HAIR_RGB = (96, 66, 46)
EYES_RGB = (40, 40, 52)
MOUTH_RGB = (178, 92, 92)
CHAIR_RGB = (206, 170, 126)

_SEG = {name: i for i, name in enumerate(SEGMENTS)}


@dataclass(frozen=True, slots=True, eq=False)
class BodyShapes:
    """Solids of one pose, world metres.

    Attributes:
        ellipsoid_centre_m: (E, 3) float64 centres.
        ellipsoid_axes_m: (E, 3, 3) float64; column k is the k-th semi-axis vector.
        ellipsoid_rgb: (E, 3) float32 sRGB colours in 0..1.
        ellipsoid_part: (E,) int32 index into :data:`SEGMENTS`, or PART_LEGS / PART_CHAIR.
        ellipsoid_fine: (E,) bool, large enough on screen to deserve the finer mesh.
        capsule_p0_m, capsule_p1_m: (C, 3) float64 axis end points.
        capsule_r0_m, capsule_r1_m: (C,) float64 radii at p0 and p1.
        capsule_rgb: (C, 3) float32; capsule_part: (C,) int32, as for the ellipsoids.
        capsule_caps: (C, 2) bool, whether the end sphere at p0, p1 is drawn (hidden ones are not).
        floor_y_m: world height of the floor the feet stand on.
        shadow_blobs: (B, 4) float64 soft floor shadows: world x, world z, radius (m), darkness 0..1.
    """

    ellipsoid_centre_m: np.ndarray
    ellipsoid_axes_m: np.ndarray
    ellipsoid_rgb: np.ndarray
    ellipsoid_part: np.ndarray
    ellipsoid_fine: np.ndarray
    capsule_p0_m: np.ndarray
    capsule_p1_m: np.ndarray
    capsule_r0_m: np.ndarray
    capsule_r1_m: np.ndarray
    capsule_rgb: np.ndarray
    capsule_part: np.ndarray
    capsule_caps: np.ndarray
    floor_y_m: float
    shadow_blobs: np.ndarray


class _Builder:
    def __init__(self) -> None:
        self.e: list[tuple] = []
        self.c: list[tuple] = []

    def ellipsoid(self, centre, axes, rgb, part: int, fine: bool = False) -> None:
        """(The axes are made right-handed all at once by :func:`_pack`.)"""
        self.e.append((centre, axes, rgb, part, fine))

    def sphere(self, centre, radius: float, rgb, part: int, fine: bool = False) -> None:
        self.ellipsoid(centre, np.eye(3) * radius, rgb, part, fine)

    def capsule(self, p0, p1, r0: float, r1: float, rgb, part: int, caps: tuple[bool, bool] = (True, True)) -> None:
        """``caps``: draw the end sphere at p0, p1 (False where another solid covers it: fewer triangles)."""
        self.c.append((np.asarray(p0, float), np.asarray(p1, float), float(r0), float(r1), rgb, part, caps))


def _rgb(c: tuple[int, int, int]) -> np.ndarray:
    return np.asarray(c, np.float32) / 255.0


def body_shapes(pose: SkeletonPose) -> BodyShapes:
    """Dress ``pose`` in solids (see the module docstring)."""
    props = pose.proportions
    h = props.stature_m
    b = _Builder()
    rt = pose.frame("trunk")
    rp = pose.frame("pelvis")
    mb = pose.joint("sternum")
    trunk, pelvis = _SEG["trunk"], _SEG["pelvis"]
    skin, shirt, trousers = _rgb(SKIN_RGB), _rgb(SHIRT_RGB), _rgb(TROUSERS_RGB)

    def t(v) -> np.ndarray:  # trunk-frame offset from MB, stature units -> world
        return mb + rt @ (np.asarray(v, float) * h)

    # Trunk: thorax and abdomen ellipsoids, widths from the measured shoulder marker distance.
    chest_half_w = float(np.clip(0.40 * props.shoulder_width_m, 0.07 * h, 0.12 * h))
    b.ellipsoid(t((0.0, -0.082, 0.079)), rt @ np.diag([chest_half_w, 0.14 * h, 0.074 * h]), shirt, trunk, True)
    # The abdomen bends halfway between the trunk and the upright pelvis.
    half = _halfway(rp, rt)
    abd_c = 0.5 * (t((0.0, -0.187, 0.089)) + pose.joint("pelvis") + rp @ np.array([0.0, 0.09 * h, 0.0]))
    b.ellipsoid(abd_c, half @ np.diag([0.86 * chest_half_w, 0.095 * h, 0.062 * h]), shirt, trunk, True)
    hip_half_w = float(np.clip(0.80 * props.hip_width_m, 0.09 * h, 0.14 * h))
    b.ellipsoid(pose.joint("pelvis") + rp @ np.array([0.0, -0.012 * h, 0.02 * h]),
                rp @ np.diag([hip_half_w, 0.062 * h, 0.078 * h]), trousers, pelvis, True)
    # Neck and head, with hair and eyes (the patient sees the avatar's face in the mirror view).
    b.capsule(pose.joint("neck"), t((0.0, 0.110, 0.049)), 0.032 * h, 0.029 * h, skin, trunk, caps=(False, False))
    head = pose.joint("head")
    head_axes = rt @ np.diag([0.047, 0.064, 0.056]) * h
    b.ellipsoid(head, head_axes, skin, trunk, True)
    b.ellipsoid(head + rt @ np.array([0.0, 0.018, 0.015]) * h, rt @ np.diag([0.0495, 0.057, 0.057]) * h,
                _rgb(HAIR_RGB), trunk, True)
    for sgn in (1.0, -1.0):
        b.sphere(head + rt @ np.array([sgn * 0.017, 0.004, -0.050]) * h, 0.0065 * h, _rgb(EYES_RGB), trunk)
    b.sphere(head + rt @ np.array([0.0, -0.008, -0.057]) * h, 0.008 * h, skin, trunk)  # nose
    b.ellipsoid(head + rt @ np.array([0.0, -0.027, -0.050]) * h, rt @ np.diag([0.012, 0.0032, 0.006]) * h,
                _rgb(MOUTH_RGB), trunk)

    # Shoulder line: a capsule across the top of the chest between the two shoulders.
    gh = {s: pose.joint(f"{s}_shoulder") for s in SIDE_SIGN}
    inner = {s: gh[s] + rt @ np.array([-sgn * 0.045 * h, -0.006 * h, 0.0]) for s, sgn in SIDE_SIGN.items()}
    b.capsule(inner["right"], inner["left"], 0.036 * h, 0.036 * h, shirt, trunk)

    for side, sgn in SIDE_SIGN.items():
        ua, fa = _SEG[f"{side}_upper_arm"], _SEG[f"{side}_forearm"]
        elbow, wrist = pose.joint(f"{side}_elbow"), pose.joint(f"{side}_wrist")
        rf = pose.frame(f"{side}_forearm")
        b.capsule(inner[side], gh[side], 0.036 * h, 0.029 * h, shirt, ua, caps=(False, False))
        b.sphere(gh[side], 0.030 * h, shirt, ua, True)
        b.capsule(gh[side], elbow, 0.029 * h, 0.021 * h, shirt, ua, caps=(False, False))
        b.capsule(elbow, wrist, 0.022 * h, 0.0125 * h, skin, fa)
        # Hand: a flattened ellipsoid in the forearm frame (length along -y, width along the
        # styloid axis x, thickness along the palm normal z), and a thumb on the radial (+x) side
        # bending towards the palm, so that pronation and supination read at a glance.
        palm = -sgn * rf[:, 2]
        along, radial = -rf[:, 1], rf[:, 0]
        hand_c = pose.joint(f"{side}_hand")
        b.ellipsoid(hand_c, np.stack([radial * 0.029 * h, along * 0.055 * h, rf[:, 2] * 0.014 * h], axis=1), skin, fa, True)
        # A lighter palm, showing only on the palm side: palm up and palm down look different.
        b.ellipsoid(hand_c + palm * 0.0045 * h + along * 0.004 * h,
                    np.stack([radial * 0.024 * h, along * 0.047 * h, rf[:, 2] * 0.0115 * h], axis=1), _rgb(PALM_RGB), fa)
        t0 = wrist + along * 0.012 * h + radial * 0.018 * h + palm * 0.004 * h
        t1 = wrist + along * 0.046 * h + radial * 0.036 * h + palm * 0.014 * h
        b.capsule(t0, t1, 0.0115 * h, 0.0095 * h, skin, fa, caps=(False, True))

    # Seated legs (untracked): thighs forward from the hips, lower legs down to the floor.
    fwd = -rp[:, 2]
    fwd = fwd - fwd[1] * np.array([0.0, 1.0, 0.0])
    fwd /= max(float(np.linalg.norm(fwd)), 1e-9)
    down = np.array([0.0, -1.0, 0.0])
    shank_tilt = math.radians(8.0)
    feet = []
    for side, sgn in SIDE_SIGN.items():
        hip = pose.joint(f"{side}_hip") + rp[:, 0] * (sgn * 0.012 * h)
        knee = hip + fwd * 0.245 * h + rp[:, 0] * (sgn * 0.01 * h)
        ankle = knee + 0.246 * h * (math.cos(shank_tilt) * down + math.sin(shank_tilt) * fwd)
        b.capsule(hip, knee, 0.048 * h, 0.033 * h, trousers, PART_LEGS, caps=(False, False))
        b.capsule(knee, ankle, 0.034 * h, 0.021 * h, trousers, PART_LEGS)
        foot_c = ankle + down * 0.016 * h + fwd * 0.045 * h
        b.ellipsoid(foot_c, np.stack([rp[:, 0] * 0.027 * h, -down * 0.022 * h, fwd * 0.074 * h], axis=1),
                    _rgb(SHOES_RGB), PART_LEGS)
        feet.append(foot_c)
    floor_y = float(min(f[1] for f in feet) - 0.022 * h)

    # A simple chair: seat cushion under the pelvis, four legs, a backrest behind the trunk.
    wood = _rgb(CHAIR_RGB)
    seat_y = float(pose.joint("pelvis")[1] - 0.072 * h)
    seat_c = pose.joint("pelvis") + fwd * 0.06 * h
    seat_c = np.array([seat_c[0], seat_y - 0.012 * h, seat_c[2]])
    side_ax = rp[:, 0] - rp[1, 0] * np.array([0.0, 1.0, 0.0])
    side_ax /= max(float(np.linalg.norm(side_ax)), 1e-9)
    b.ellipsoid(seat_c, np.stack([side_ax * 0.15 * h, np.array([0.0, 0.016 * h, 0.0]), fwd * 0.15 * h], axis=1),
                wood, PART_CHAIR, True)
    for sx in (1.0, -1.0):
        for sz in (1.0, -1.0):
            top = seat_c + side_ax * (sx * 0.12 * h) + fwd * (sz * 0.12 * h)
            b.capsule(top, np.array([top[0], floor_y, top[2]]), 0.011 * h, 0.009 * h, wood, PART_CHAIR, caps=(False, True))
    back_c = seat_c - fwd * 0.155 * h + np.array([0.0, 0.17 * h, 0.0])
    b.ellipsoid(back_c, np.stack([side_ax * 0.14 * h, np.array([0.0, 0.11 * h, 0.0]), fwd * 0.018 * h], axis=1),
                wood, PART_CHAIR, True)
    for sx in (1.0, -1.0):
        foot = seat_c - fwd * 0.15 * h + side_ax * (sx * 0.12 * h)
        b.capsule(foot, foot + np.array([0.0, 0.22 * h, 0.0]), 0.010 * h, 0.009 * h, wood, PART_CHAIR, caps=(False, False))

    blobs = _shadow_blobs(pose, seat_c, feet, floor_y, h)
    return _pack(b, floor_y, blobs)


def _halfway(r0: np.ndarray, r1: np.ndarray) -> np.ndarray:
    """About the rotation halfway between r0 and r1 (3, 3) (the abdomen between pelvis and thorax):
    the frame of the summed axes, exact for turns about one axis and cheaper than a slerp."""
    return frame_from_axes(r0[:, 1] + r1[:, 1], r0[:, 0] + r1[:, 0], r1)


def _shadow_blobs(pose: SkeletonPose, seat_c: np.ndarray, feet: list[np.ndarray], floor_y: float, h: float) -> np.ndarray:
    """Soft shadows under the chair, the feet and the hands (x, z, radius, darkness): (5, 4)."""
    rows = [(seat_c, 0.2 * h, 0.85)]
    rows += [(f, 0.07 * h, 0.6) for f in feet]
    for side in SIDE_SIGN:
        p = pose.joint(f"{side}_hand")
        height = max(p[1] - floor_y, 0.0)
        rows.append((p, 0.06 * h * (1.0 + height / h), 0.4 / (1.0 + 3.0 * height / h)))
    return np.array([(c[0], c[2], r, s) for c, r, s in rows], dtype=np.float64)


def _pack(b: _Builder, floor_y: float, blobs: np.ndarray) -> BodyShapes:
    e, c = b.e, b.c
    axes = np.array([x[1] for x in e], float)
    # keep the axes right-handed: the mesh's winding depends on it
    axes[np.linalg.det(axes) < 0, :, 2] *= -1.0
    return BodyShapes(
        ellipsoid_centre_m=np.array([x[0] for x in e], float),
        ellipsoid_axes_m=axes,
        ellipsoid_rgb=np.array([x[2] for x in e], np.float32),
        ellipsoid_part=np.array([x[3] for x in e], np.int32),
        ellipsoid_fine=np.array([x[4] for x in e], bool),
        capsule_p0_m=np.array([x[0] for x in c]),
        capsule_p1_m=np.array([x[1] for x in c]),
        capsule_r0_m=np.array([x[2] for x in c]),
        capsule_r1_m=np.array([x[3] for x in c]),
        capsule_rgb=np.array([x[4] for x in c], np.float32),
        capsule_part=np.array([x[5] for x in c], np.int32),
        capsule_caps=np.array([x[6] for x in c], bool).reshape(-1, 2),
        floor_y_m=floor_y,
        shadow_blobs=blobs,
    )
