"""The simulated seated patient: anthropometry, pose, marker positions and render primitives.

Pure numpy, no GL. World frame (docs/INTERFACES.md): right-handed, metres, +Y up, floor at
``y = 0``, the patient sits on a chair seat centred near ``x = 0, z = 0`` and faces -Z, so the
patient's right is +X.

Kinematic chain (all rotations are 3x3 matrices acting on column vectors):

- The pelvis is fixed on the seat: pelvis, anterior superior iliac spines (ASIS), thighs,
  lower legs and feet never move.
- The trunk (thorax, neck, head, shoulder girdles, arms) rotates about a lumbar pivot above the
  pelvis; the abdomen takes half of that rotation, so that the lumbar region bends smoothly.
- Each shoulder girdle (acromion and glenohumeral centre, GH) rises with the humerus elevation
  (a simple scapulohumeral rhythm) plus ``shoulder_shrug_m``; the acromion's top face turns
  medially with the scapular upward rotation so the raised arm does not swallow its marker.
- The humerus rotates about GH, the forearm about the epicondyle axis (elbow flexion) and about
  its own long axis (pronation/supination).

Arm conventions are those of ``docs/JOINT_ANGLES.md`` and are written for the RIGHT arm; the left
arm uses the same numbers mirrored across the sagittal plane, so equal numbers mean the same
motion on both sides. The humerus frame (right-side convention) has ``x_h`` = medial->lateral
epicondyle axis, ``y_h`` = elbow->shoulder, ``z_h = x_h x y_h`` (posterior); the identity means
arm hanging, epicondyle axis frontal, and with the elbow flexed 90 degrees the forearm points
forward (external rotation 0). Elbow flexion rotates the forearm about ``+x_h``; supination
rotates it about its distal-pointing long axis: 0 = thumb up when the elbow is flexed 90 degrees
with the forearm forward, +90 = palm up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from statistics import NormalDist

import numpy as np

from tracking.errors import ContentError, MotionError
from tracking.geometry.rotations import (
    direction_from_clinical, direction_from_plane, humerus_rotation, rot_x, rot_y, rot_z, rotation_exp, rotation_log, swing_twist, unit,
)
from tracking.markerset import MarkerSet
from tracking.sim.scene import SceneFrame

# Adult stature (mean, SD) in metres, roughly ANSUR II / western European adults.
_STATURE_M = {"female": (1.625, 0.064), "male": (1.755, 0.070)}

# Render colours, sRGB 0-255, kept away from the saturated marker colours (yellow, green,
# magenta, cyan): a moderately saturated skin tone (hue ~18 deg, 30 deg from the yellow), a dark
# grey shirt with a hint of blue (saturation 0.2), dark grey trousers and shoes.
SKIN_RGB = (205, 150, 125)
SHIRT_RGB = (62, 66, 78)
TROUSERS_RGB = (46, 46, 54)
SHOES_RGB = (30, 28, 28)

SIDES = ("right", "left")


# ---------------------------------------------------------------------------------------------
# Anthropometry


@dataclass(frozen=True, slots=True)
class BodyDimensions:
    """Anthropometry of a seated adult, metres.

    Ratios of stature after Drillis & Contini as tabulated by Winter (Biomechanics and Motor
    Control of Human Movement) for segment lengths and heights, and adult breadths/circumferences
    (ANSUR-like) for widths and radii. Heights are measured from the seat surface; radii are skin
    surfaces used by the render primitives.

    Attributes:
        sex: "female" or "male".
        stature_m: standing height.
        seat_height_m: chair seat above the floor (world y of the seat surface).
        upper_arm_m: glenohumeral centre -> elbow centre (0.186 H).
        forearm_m: elbow centre -> wrist centre (0.146 H).
        hand_m: wrist centre -> fingertip (0.108 H).
        biacromial_m: distance between the acromion landmarks.
        bi_asis_m: distance between the anterior superior iliac spines.
        seat_to_asis_m, seat_to_xiphoid_m, seat_to_sternum_m, seat_to_acromion_m: landmark
            heights above the seat (skin), seated upright.
        sitting_height_m: seat -> vertex.
        chest_width_m, chest_depth_m: thorax breadth and depth (skin).
        waist_width_m, waist_depth_m: abdomen breadth and depth at the elbow level.
        hip_width_m: seated hip breadth.
        upper_arm_radius_m: upper arm at the deltoid.
        forearm_radius_m: proximal forearm.
        wrist_radius_m: distal forearm.
        epicondyle_half_width_m: elbow centre -> each epicondyle (bone).
        styloid_half_width_m: wrist centre -> each styloid (bone).
        thigh_length_m, shank_length_m: hip -> knee, knee -> ankle.
        thigh_radius_m, knee_radius_m, calf_radius_m, ankle_radius_m: leg skin radii.
        neck_radius_m: neck.
        head_half_axes_m: (width, height, depth) half axes of the head ellipsoid.
    """

    sex: str
    stature_m: float
    seat_height_m: float
    upper_arm_m: float
    forearm_m: float
    hand_m: float
    biacromial_m: float
    bi_asis_m: float
    seat_to_asis_m: float
    seat_to_xiphoid_m: float
    seat_to_sternum_m: float
    seat_to_acromion_m: float
    sitting_height_m: float
    chest_width_m: float
    chest_depth_m: float
    waist_width_m: float
    waist_depth_m: float
    hip_width_m: float
    upper_arm_radius_m: float
    forearm_radius_m: float
    wrist_radius_m: float
    epicondyle_half_width_m: float
    styloid_half_width_m: float
    thigh_length_m: float
    shank_length_m: float
    thigh_radius_m: float
    knee_radius_m: float
    calf_radius_m: float
    ankle_radius_m: float
    neck_radius_m: float
    head_half_axes_m: tuple[float, float, float]

    @classmethod
    def from_stature(cls, stature_m: float, sex: str = "female", seat_height_m: float = 0.45) -> "BodyDimensions":
        """Dimensions from stature (m) and sex by fixed ratios."""
        if sex not in _STATURE_M:
            raise MotionError(f"body sex {sex!r} is unknown: choose 'female' or 'male'")
        if not 1.2 <= stature_m <= 2.2:
            raise MotionError(f"stature {stature_m:g} m is outside 1.2-2.2 m: give the standing height in metres")
        H = float(stature_m)
        f = sex == "female"
        bi_asis = (0.150 if f else 0.137) * H
        hjc_height = 0.060 * H  # hip joint centre above the seat
        return cls(
            sex=sex,
            stature_m=H,
            seat_height_m=float(seat_height_m),
            upper_arm_m=0.186 * H,
            forearm_m=0.146 * H,
            hand_m=0.108 * H,
            biacromial_m=(0.222 if f else 0.229) * H,
            bi_asis_m=bi_asis,
            # Bell et al. (1990): hip joint centre 0.30 x bi-ASIS below the ASIS.
            seat_to_asis_m=hjc_height + 0.30 * bi_asis,
            seat_to_xiphoid_m=0.225 * H,
            seat_to_sternum_m=0.325 * H,
            seat_to_acromion_m=0.345 * H,
            sitting_height_m=0.520 * H,
            chest_width_m=(0.178 if f else 0.186) * H,
            chest_depth_m=(0.146 if f else 0.142) * H,
            waist_width_m=(0.172 if f else 0.170) * H,
            waist_depth_m=(0.128 if f else 0.124) * H,
            hip_width_m=(0.250 if f else 0.222) * H,
            upper_arm_radius_m=(0.0272 if f else 0.0280) * H,
            forearm_radius_m=(0.0245 if f else 0.0260) * H,
            wrist_radius_m=(0.0110 if f else 0.0115) * H,  # wrist thickness / 2; the styloids stick out
            epicondyle_half_width_m=(0.0185 if f else 0.0200) * H,
            styloid_half_width_m=(0.0155 if f else 0.0165) * H,
            thigh_length_m=0.245 * H,
            shank_length_m=0.246 * H,
            thigh_radius_m=(0.056 if f else 0.051) * H,
            knee_radius_m=0.033 * H,
            calf_radius_m=0.034 * H,
            ankle_radius_m=0.020 * H,
            neck_radius_m=(0.030 if f else 0.033) * H,
            head_half_axes_m=(0.044 * H, 0.065 * H, 0.055 * H),
        )

    @classmethod
    def from_percentile(cls, p: float, sex: str = "female", seat_height_m: float = 0.45) -> "BodyDimensions":
        """Dimensions of the ``p``-th stature percentile (5..95) of adult women or men."""
        if sex not in _STATURE_M:
            raise MotionError(f"body sex {sex!r} is unknown: choose 'female' or 'male'")
        if not 5.0 <= p <= 95.0:
            raise MotionError(f"body percentile {p:g} is outside 5-95: the ratios hold for the 5th to the 95th percentile")
        mean, sd = _STATURE_M[sex]
        return cls.from_stature(mean + sd * NormalDist().inv_cdf(p / 100.0), sex, seat_height_m)


# ---------------------------------------------------------------------------------------------
# Pose


@dataclass(frozen=True, slots=True, eq=False)
class ArmPose:
    """Pose of one arm, right-side convention (the left arm mirrors it).

    Attributes:
        humerus_rot: (3, 3) float64 humerus frame in the trunk frame (columns x_h, y_h, z_h; see
            the module docstring). Build it with the constructors rather than by hand.
        shoulder_shrug_m: extra elevation of the shoulder girdle (acromion and GH) along the trunk
            axis, metres; + raises the shoulder ("hiking"), - depresses it.
        elbow_flexion_deg: 0 straight, + flexed.
        forearm_supination_deg: + supination (palm up), - pronation; 0 = thumb up with the elbow
            flexed 90 degrees and the forearm forward.
    """

    humerus_rot: np.ndarray
    shoulder_shrug_m: float = 0.0
    elbow_flexion_deg: float = 0.0
    forearm_supination_deg: float = 0.0

    @classmethod
    def clinical(
        cls,
        flexion_deg: float = 0.0,
        abduction_deg: float = 0.0,
        external_rotation_deg: float = 0.0,
        elbow_flexion_deg: float = 0.0,
        forearm_supination_deg: float = 0.0,
        shoulder_shrug_m: float = 0.0,
    ) -> "ArmPose":
        """From clinical shoulder angles (see :func:`direction_from_clinical`), degrees."""
        d = direction_from_clinical(flexion_deg, abduction_deg)
        return cls.from_direction(d, external_rotation_deg, elbow_flexion_deg, forearm_supination_deg, shoulder_shrug_m)

    @classmethod
    def globe(
        cls,
        plane_deg: float,
        elevation_deg: float,
        external_rotation_deg: float = 0.0,
        elbow_flexion_deg: float = 0.0,
        forearm_supination_deg: float = 0.0,
        shoulder_shrug_m: float = 0.0,
    ) -> "ArmPose":
        """From plane of elevation and elevation (ISB-like globe coordinates), degrees."""
        d = direction_from_plane(plane_deg, elevation_deg)
        return cls.from_direction(d, external_rotation_deg, elbow_flexion_deg, forearm_supination_deg, shoulder_shrug_m)

    @classmethod
    def from_direction(
        cls,
        direction: np.ndarray,
        external_rotation_deg: float = 0.0,
        elbow_flexion_deg: float = 0.0,
        forearm_supination_deg: float = 0.0,
        shoulder_shrug_m: float = 0.0,
    ) -> "ArmPose":
        """From the humerus direction (3,) (shoulder -> elbow, trunk frame) and axial rotation."""
        rot = humerus_rotation(np.asarray(direction, dtype=np.float64), external_rotation_deg)
        rot.setflags(write=False)
        return cls(rot, float(shoulder_shrug_m), float(elbow_flexion_deg), float(forearm_supination_deg))

    @property
    def direction(self) -> np.ndarray:
        """(3,) humerus unit vector shoulder -> elbow, trunk frame, right-side convention."""
        return -self.humerus_rot[:, 1]

    @property
    def elevation_deg(self) -> float:
        """Humerus elevation from hanging down, 0..180 degrees."""
        return math.degrees(math.acos(max(-1.0, min(1.0, -float(self.direction[1])))))

    @property
    def external_rotation_deg(self) -> float:
        """Axial rotation relative to the swing frame of :func:`swing_matrix`, degrees."""
        return swing_twist(self.humerus_rot)[1]


@dataclass(frozen=True, slots=True, eq=False)
class Pose:
    """Whole-body pose of the seated patient.

    Attributes:
        trunk_forward_lean_deg: + trunk leans forward (rotation about the lumbar pivot).
        trunk_lateral_lean_deg: + trunk leans to the patient's right.
        trunk_axial_rotation_deg: + the chest turns towards the patient's left (right-hand rule
            about +Y).
        right, left: the arms, each in the right-side convention (same numbers = same motion).

    ``Pose()`` is upright with both arms hanging straight down (external rotation 0, thumbs
    forward); the seed's start pose is :func:`reference_pose`.
    """

    trunk_forward_lean_deg: float = 0.0
    trunk_lateral_lean_deg: float = 0.0
    trunk_axial_rotation_deg: float = 0.0
    right: ArmPose = field(default_factory=lambda: ArmPose.clinical())
    left: ArmPose = field(default_factory=lambda: ArmPose.clinical())

    def arm(self, side: str) -> ArmPose:
        """The arm of ``side`` ("right" or "left")."""
        return self.right if side == "right" else self.left

    def with_arm(self, side: str, arm: ArmPose) -> "Pose":
        """A copy with one arm replaced."""
        return replace(self, right=arm) if side == "right" else replace(self, left=arm)


# Reference pose of the seed paper: seated upright, arms hanging slightly away from the body,
# elbows nearly straight, thumbs forward. The humerus is internally rotated (as a relaxed
# hanging arm is), which brings the lateral epicondyle forward (rule M*E1 before M*E2 in Z); the
# forearm supination compensates so that the thumb points forward.
REFERENCE_ABDUCTION_DEG = 16.0
REFERENCE_EXTERNAL_ROTATION_DEG = -25.0
REFERENCE_ELBOW_FLEXION_DEG = 10.0
REFERENCE_SUPINATION_DEG = 25.0


def reference_arm(
    abduction_deg: float = REFERENCE_ABDUCTION_DEG,
    flexion_deg: float = 0.0,
    external_rotation_deg: float = REFERENCE_EXTERNAL_ROTATION_DEG,
    elbow_flexion_deg: float = REFERENCE_ELBOW_FLEXION_DEG,
    forearm_supination_deg: float = REFERENCE_SUPINATION_DEG,
) -> ArmPose:
    """One arm in the reference pose (right-side convention); arguments perturb it."""
    return ArmPose.clinical(flexion_deg, abduction_deg, external_rotation_deg, elbow_flexion_deg, forearm_supination_deg)


def reference_pose(
    abduction_deg: float = REFERENCE_ABDUCTION_DEG,
    flexion_deg: float = 0.0,
    external_rotation_deg: float = REFERENCE_EXTERNAL_ROTATION_DEG,
    elbow_flexion_deg: float = REFERENCE_ELBOW_FLEXION_DEG,
    forearm_supination_deg: float = REFERENCE_SUPINATION_DEG,
) -> Pose:
    """The seed's reference pose (docs/METHOD.md 5.2), the same on both sides; arguments perturb it."""
    arm = reference_arm(abduction_deg, flexion_deg, external_rotation_deg, elbow_flexion_deg, forearm_supination_deg)
    return Pose(right=arm, left=arm)


# ---------------------------------------------------------------------------------------------
# Signed distances and ray casting on SceneFrame primitives


def _sdf_spheres(p: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(N, 3) points vs (S,) spheres -> (N, S) signed distances, metres."""
    return np.linalg.norm(p[:, None, :] - c[None, :, :], axis=2) - r[None, :]


def _sdf_round_cones(p: np.ndarray, a: np.ndarray, b: np.ndarray, ra: np.ndarray, rb: np.ndarray) -> np.ndarray:
    """(N, 3) points vs (C,) tapered capsules (convex hull of the end spheres) -> (N, C).

    Exact distance of the round cone (after I. Quilez's sdRoundCone).
    """
    ba = b - a  # (C, 3)
    l2 = np.einsum("ij,ij->i", ba, ba)
    rr = ra - rb
    a2 = l2 - rr * rr
    il2 = 1.0 / l2
    pa = p[:, None, :] - a[None, :, :]  # (N, C, 3)
    y = np.einsum("ncj,cj->nc", pa, ba)
    z = y - l2
    q = pa * l2[None, :, None] - ba[None, :, :] * y[:, :, None]
    x2 = np.einsum("ncj,ncj->nc", q, q)
    y2 = y * y * l2
    z2 = z * z * l2
    k = np.sign(rr) * rr * rr * x2
    d_b = np.sqrt(x2 + z2) * il2 - rb
    d_a = np.sqrt(x2 + y2) * il2 - ra
    d_side = (np.sqrt(np.maximum(x2 * a2 * il2, 0.0)) + y * rr) * il2 - ra
    return np.where(np.sign(z) * a2 * z2 > k, d_b, np.where(np.sign(y) * a2 * y2 < k, d_a, d_side))


def _sdf_ellipsoids(p: np.ndarray, c: np.ndarray, axes: np.ndarray, bound: bool = False) -> np.ndarray:
    """(N, 3) points vs (E,) ellipsoids with (E, 3, 3) orthogonal semi-axis columns -> (N, E).

    The sign is exact. The magnitude is the usual first-order approximation (exact on the
    surface, good to a fraction of a millimetre within a centimetre of it), or with ``bound`` a
    lower bound of the distance outside, ``(|q| - 1) * shortest half axis`` (safe for marching).
    """
    lengths = np.linalg.norm(axes, axis=1)  # (E, 3): length of each column
    units = axes / lengths[:, None, :]
    local = np.einsum("ekj,nek->nej", units, p[:, None, :] - c[None, :, :])  # (N, E, 3)
    k0 = np.linalg.norm(local / lengths[None], axis=2)
    if bound:
        return (k0 - 1.0) * lengths.min(axis=1)[None, :]
    k1 = np.linalg.norm(local / (lengths[None] ** 2), axis=2)
    return np.where(k1 > 1e-12, k0 * (k0 - 1.0) / np.maximum(k1, 1e-12), -lengths.min(axis=1)[None, :])


def scene_signed_distance(scene: SceneFrame, points_m: np.ndarray, skip_sphere: int = -1,
                          markers: bool = True, bound: bool = False) -> np.ndarray:
    """Signed distance (m) from points to the union of a scene's primitives.

    Args:
        scene: the primitives.
        points_m: (N, 3) world points.
        skip_sphere: index of a sphere to leave out (e.g. the marker being tested), or -1.
        markers: include marker spheres (False: body surfaces only).
        bound: return a lower bound of the distance (exact sign) that is safe for sphere tracing.

    Returns:
        (N,) float64, negative inside a primitive.
    """
    p = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    parts = [np.full((p.shape[0], 1), np.inf)]
    keep = np.ones(scene.sphere_radius_m.shape[0], dtype=bool)
    if skip_sphere >= 0:
        keep[skip_sphere] = False
    if not markers:
        keep &= scene.sphere_marker_index < 0
    if keep.any():
        parts.append(_sdf_spheres(p, scene.sphere_centre_m[keep], scene.sphere_radius_m[keep]))
    if scene.capsule_r0_m.size:
        parts.append(_sdf_round_cones(p, scene.capsule_p0_m, scene.capsule_p1_m, scene.capsule_r0_m, scene.capsule_r1_m))
    if scene.ellipsoid_centre_m.size:
        parts.append(_sdf_ellipsoids(p, scene.ellipsoid_centre_m, scene.ellipsoid_axes_m, bound))
    return np.min(np.concatenate(parts, axis=1), axis=1)


def _scene_bounds(scene: SceneFrame) -> tuple[np.ndarray, np.ndarray]:
    lo = [scene.sphere_centre_m - scene.sphere_radius_m[:, None]]
    hi = [scene.sphere_centre_m + scene.sphere_radius_m[:, None]]
    for p, r in ((scene.capsule_p0_m, scene.capsule_r0_m), (scene.capsule_p1_m, scene.capsule_r1_m)):
        lo.append(p - r[:, None])
        hi.append(p + r[:, None])
    ext = np.linalg.norm(scene.ellipsoid_axes_m, axis=2)  # (E, 3): extent along world axes
    lo.append(scene.ellipsoid_centre_m - ext)
    hi.append(scene.ellipsoid_centre_m + ext)
    return np.concatenate(lo).min(axis=0), np.concatenate(hi).max(axis=0)


def _segments_blocked(scene: SceneFrame, starts_m: np.ndarray, eye_m: np.ndarray, skip_sphere: int,
                      step_m: float) -> np.ndarray:
    """(R, 3) segment starts to one eye -> (R,) bool: does any primitive cut the segment?"""
    lo, hi = _scene_bounds(scene)
    lo, hi = lo - 0.01, hi + 0.01
    d = eye_m[None, :] - starts_m  # (R, 3)
    # Clip each segment to the scene box (slab method) so that samples are spent near the body.
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = (lo[None] - starts_m) / d
        t1 = (hi[None] - starts_m) / d
    tmin = np.nanmax(np.where(np.isfinite(t0), np.minimum(t0, t1), -np.inf), axis=1)
    tmax = np.nanmin(np.where(np.isfinite(t0), np.maximum(t0, t1), np.inf), axis=1)
    tmin = np.clip(tmin, 0.0, 1.0)
    tmax = np.clip(tmax, 0.0, 1.0)
    length = np.linalg.norm(d, axis=1)
    # Sphere tracing: step by the distance bound (at least step_m) until inside a primitive or out.
    t = tmin.copy()
    blocked = np.zeros(starts_m.shape[0], dtype=bool)
    active = t < tmax
    while active.any():
        idx = np.flatnonzero(active)
        pts = starts_m[idx] + t[idx, None] * d[idx]
        sd = scene_signed_distance(scene, pts, skip_sphere=skip_sphere, bound=True)
        hit = sd < 0.0
        blocked[idx[hit]] = True
        t[idx] += np.maximum(sd, step_m) / length[idx]
        active[idx] = ~hit & (t[idx] <= tmax[idx])
    return blocked


def is_occluded(scene: SceneFrame, point_m: np.ndarray, eye_m: np.ndarray, skip_marker: int = -1,
                step_m: float = 0.002) -> bool:
    """Whether the straight segment from ``point_m`` (3,) to ``eye_m`` (3,) hits a primitive.

    Args:
        scene: the primitives, world metres.
        point_m: the point looked at.
        eye_m: the camera centre.
        skip_marker: marker index whose own sphere is ignored (-1: none).
        step_m: sampling step along the segment (geometry thinner than this may be missed).
    """
    skip = _sphere_of_marker(scene, skip_marker)
    p = np.asarray(point_m, dtype=np.float64).reshape(1, 3)
    return bool(_segments_blocked(scene, p, np.asarray(eye_m, dtype=np.float64), skip, step_m)[0])


def _sphere_of_marker(scene: SceneFrame, marker_index: int) -> int:
    if marker_index < 0:
        return -1
    hits = np.flatnonzero(scene.sphere_marker_index == marker_index)
    if hits.size != 1:
        raise ValueError(f"marker index {marker_index} has {hits.size} spheres in the scene")
    return int(hits[0])


def occluded_fraction(scene: SceneFrame, marker_index: int, eye_m: np.ndarray, n_rays: int = 48,
                      step_m: float = 0.002) -> float:
    """Fraction (0..1) of a marker ball's projected disk hidden from a camera at ``eye_m`` (3,).

    Rays start on the ball's cap facing the eye at points spread evenly over its projected disk
    (so the fraction approximates the hidden fraction of the marker's pixels) and are tested
    against every other primitive, including other markers. Ignores the field of view.
    """
    s = _sphere_of_marker(scene, marker_index)
    c = scene.sphere_centre_m[s]
    r = float(scene.sphere_radius_m[s])
    eye = np.asarray(eye_m, dtype=np.float64)
    v = unit(eye - c)
    e1 = unit(np.cross(v, [0.0, 1.0, 0.0]) if abs(v[1]) < 0.9 else np.cross(v, [1.0, 0.0, 0.0]))
    e2 = np.cross(v, e1)
    i = np.arange(n_rays) + 0.5
    rho = np.sqrt(i / n_rays) * 0.97
    psi = i * math.pi * (3.0 - math.sqrt(5.0))  # golden-angle sunflower
    lift = np.sqrt(1.0 - rho**2)
    starts = c + (r + 5e-4) * (rho[:, None] * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2) + lift[:, None] * v)
    return float(_segments_blocked(scene, starts, eye, s, step_m).mean())


# ---------------------------------------------------------------------------------------------
# Body model


# Canonical landmarks computed by the model, in a fixed order.
_LANDMARKS = (
    "sternum", "xiphoid",
    "right_acromion", "left_acromion",
    "right_lateral_epicondyle", "right_medial_epicondyle",
    "left_lateral_epicondyle", "left_medial_epicondyle",
    "right_radial_styloid", "right_ulnar_styloid",
    "left_radial_styloid", "left_ulnar_styloid",
    "right_asis", "left_asis",
)

# Marker-set landmark text -> canonical landmark (side words decide left/right).
_KEYWORDS = (
    ("xiphoid", "xiphoid"),
    ("sternum", "sternum"),
    ("acromion", "acromion"),
    ("lateral epicondyle", "lateral_epicondyle"),
    ("medial epicondyle", "medial_epicondyle"),
    ("radial styloid", "radial_styloid"),
    ("ulnar styloid", "ulnar_styloid"),
    ("iliac spine", "asis"),
    ("asis", "asis"),
)


def _landmark_of(name: str, text: str) -> str:
    words = text.lower()
    for key, base in _KEYWORDS:
        if key in words:
            if base in ("sternum", "xiphoid"):
                return base
            side = "left" if "left" in words else "right" if "right" in words else ""
            if side:
                return f"{side}_{base}"
    raise ContentError(
        f"marker {name}: landmark {text!r} is not one the simulated body knows; name one of: "
        "upper sternum, xiphoid, left/right acromion, lateral/medial epicondyle, radial/ulnar styloid, "
        "anterior superior iliac spine"
    )


@dataclass(frozen=True, slots=True)
class _Geometry:
    """Pose-independent geometry, body coordinates (= world with the trunk upright)."""

    lumbar_m: np.ndarray          # (3,) pivot of the trunk
    thorax_c: np.ndarray          # (3,) ellipsoid centre
    thorax_r: np.ndarray          # (3,) half axes x, y, z
    abdomen_c: np.ndarray
    abdomen_r: np.ndarray
    neck: tuple[np.ndarray, np.ndarray, float, float]
    head_c: np.ndarray
    head_r: np.ndarray
    gh_right_m: np.ndarray        # (3,) right GH centre, trunk upright, no shrug
    sternum_skin: np.ndarray      # (3,) MB skin point and its (3,) normal
    sternum_n: np.ndarray
    xiphoid_skin: np.ndarray
    xiphoid_n: np.ndarray
    upper_arm_r: tuple[float, float]   # proximal, distal (elbow) skin radius
    forearm_r: tuple[float, float]
    forearm_start_m: float             # forearm capsule starts this far distal of the elbow centre
    girdle_medial_m: np.ndarray        # (3,) medial end of the right shoulder-girdle capsule
    girdle_r: tuple[float, float]      # its radii (medial, lateral)
    styloid_bump_r: float              # radius of the skin bumps over the styloids
    hand_half_axes: np.ndarray         # (3,) along, width, thickness


class BodyModel:
    """Marker positions and render primitives of one simulated patient.

    Args:
        dims: the patient's anthropometry.
        markerset: which markers to place (their landmark text selects the body landmark), their
            colours, ball radius and soft-tissue thickness.
        marker_offsets_m: (M, 3) each ball moved off its landmark (placement error), world metres;
            fixed in the world, so meant for one pose (the population's reference poses).
    """

    def __init__(self, dims: BodyDimensions, markerset: MarkerSet, marker_offsets_m: np.ndarray | None = None) -> None:
        self.dims = dims
        self.markerset = markerset
        self._offsets = (np.zeros((markerset.n_markers, 3)) if marker_offsets_m is None
                         else np.asarray(marker_offsets_m, dtype=np.float64).reshape(markerset.n_markers, 3))
        self._offset_m = markerset.radius_m + markerset.soft_tissue_m
        self._marker_landmark = np.array(
            [_LANDMARKS.index(_landmark_of(n, t)) for n, t in zip(markerset.names, markerset.landmarks)], dtype=np.intp
        )
        self._geo = self._build_geometry()
        self._static = self._build_static()
        self._constant = self._build_constant()

    def _build_constant(self) -> dict[str, np.ndarray]:
        """Radii and colours of the scene, the same in every frame (read-only arrays).

        Spheres: markers, ASIS bumps, styloid bumps. Capsules: per side (right, left) upper arm,
        forearm, shoulder girdle; neck; thighs; lower legs. Ellipsoids: thorax, head, right
        hand, left hand, abdomen; pelvis, feet.
        """
        ms, g, st = self.markerset, self._geo, self._static
        n_m, n_asis = ms.n_markers, st["sphere_r"].shape[0]
        rgb = lambda *colours: np.array(colours, np.float32) / 255.0  # noqa: E731
        arm_r0 = [g.upper_arm_r[0], g.forearm_r[0], g.girdle_r[0]]
        arm_r1 = [g.upper_arm_r[1], g.forearm_r[1], g.girdle_r[1]]
        out = {
            "sphere_r": np.concatenate([np.full(n_m, ms.radius_m), st["sphere_r"], np.full(4, g.styloid_bump_r)]),
            "sphere_rgb": np.concatenate([ms.rgb.astype(np.float32) / 255.0, rgb(*[TROUSERS_RGB] * n_asis),
                                          rgb(*[SKIN_RGB] * 4)]),
            "sphere_marker_index": np.concatenate([np.arange(n_m, dtype=np.int32), np.full(n_asis + 4, -1, np.int32)]),
            "capsule_r0": np.concatenate([arm_r0 * 2 + [g.neck[2]], st["capsule_r0"]]),
            "capsule_r1": np.concatenate([arm_r1 * 2 + [g.neck[3]], st["capsule_r1"]]),
            "capsule_rgb": rgb(*[SHIRT_RGB, SKIN_RGB, SHIRT_RGB] * 2, SKIN_RGB, *[TROUSERS_RGB] * 4),
            "ellipsoid_rgb": np.concatenate([rgb(SHIRT_RGB, SKIN_RGB, SKIN_RGB, SKIN_RGB, SHIRT_RGB), st["ellipsoid_rgb"]]),
        }
        for a in out.values():
            a.setflags(write=False)
        return out

    # ------------------------------------------------------------------ construction
    def _build_geometry(self) -> _Geometry:
        d = self.dims
        H, seat, tissue = d.stature_m, d.seat_height_m, self.markerset.soft_tissue_m
        thorax_r = np.array([d.chest_width_m / 2, 0.13 * H, d.chest_depth_m / 2])
        thorax_c = np.array([0.0, seat + 0.235 * H, 0.0])
        abdomen_r = np.array([d.waist_width_m / 2, 0.085 * H, d.waist_depth_m / 2])
        # GH lies a little in front of the thorax's mid-coronal plane; the waist is centred on the
        # same plane, so a hanging elbow meets the side of the waist, not its front.
        gh_z = -0.15 * thorax_r[2]
        abdomen_c = np.array([0.0, seat + 0.13 * H, gh_z])
        lumbar = np.array([0.0, seat + 0.10 * H, abdomen_c[2] + 0.5 * abdomen_r[2]])

        def front_point(y: float) -> tuple[np.ndarray, np.ndarray]:
            t = (y - thorax_c[1]) / thorax_r[1]
            z = thorax_c[2] - thorax_r[2] * math.sqrt(max(1.0 - t * t, 1e-6))
            p = np.array([0.0, y, z])
            n = unit((p - thorax_c) / thorax_r**2)
            return p, n

        sternum_skin, sternum_n = front_point(seat + d.seat_to_sternum_m)
        xiphoid_skin, xiphoid_n = front_point(seat + d.seat_to_xiphoid_m)
        r_ua = d.upper_arm_radius_m
        # Acromion skin sits on the top of the deltoid sphere around GH, 8 mm lateral of GH.
        gh = np.array([d.biacromial_m / 2 - 0.008, seat + d.seat_to_acromion_m - r_ua, gh_z])
        elbow_skin = d.epicondyle_half_width_m + tissue
        r_elbow = min(elbow_skin - 0.001, r_ua)
        r_wrist = min(d.wrist_radius_m, d.styloid_half_width_m + tissue - 0.001)
        r_forearm = d.forearm_radius_m
        # The bulky proximal forearm starts distal of the elbow centre, just clear of the
        # epicondyle marker balls (which lie on the flexion axis, perpendicular to the forearm).
        ball = self.markerset.radius_m
        reach = elbow_skin + ball
        forearm_start = math.sqrt(max(0.0, (r_forearm + ball + 0.002) ** 2 - reach**2))
        neck_base = np.array([0.0, sternum_skin[1] - 0.01 * H, 0.2 * thorax_r[2]])
        head_r = np.array(d.head_half_axes_m)
        head_c = np.array([0.0, seat + d.sitting_height_m - head_r[1], -0.1 * head_r[2]])
        neck_top = head_c + np.array([0.0, -0.4 * head_r[1], 0.25 * head_r[2]])
        return _Geometry(
            lumbar_m=lumbar, thorax_c=thorax_c, thorax_r=thorax_r, abdomen_c=abdomen_c, abdomen_r=abdomen_r,
            neck=(neck_base, neck_top, d.neck_radius_m, d.neck_radius_m * 0.95),
            head_c=head_c, head_r=head_r, gh_right_m=gh,
            sternum_skin=sternum_skin, sternum_n=sternum_n, xiphoid_skin=xiphoid_skin, xiphoid_n=xiphoid_n,
            upper_arm_r=(r_ua, r_elbow), forearm_r=(r_forearm, r_wrist), forearm_start_m=forearm_start,
            girdle_medial_m=np.array([0.2 * thorax_r[0], sternum_skin[1] + 0.01 * H, 0.1 * thorax_r[2]]),
            girdle_r=(0.6 * d.neck_radius_m, 0.75 * r_ua),
            styloid_bump_r=0.006 * H,
            hand_half_axes=np.array([0.45 * d.hand_m, 1.5 * d.styloid_half_width_m, 0.55 * r_wrist]),
        )

    def _build_static(self) -> dict[str, np.ndarray]:
        """Pelvis, ASIS, legs: they never move."""
        d, g = self.dims, self._geo
        H, seat = d.stature_m, d.seat_height_m
        w = d.bi_asis_m
        # ASIS skin: in front of the lower abdomen, 35 mm behind the xiphoid skin (seated data).
        asis_skin = np.array([w / 2, seat + d.seat_to_asis_m, g.xiphoid_skin[2] + 0.02 * H])
        asis_n = unit(np.array([0.35, 0.15, -1.0]))
        # Bell et al. (1990) hip joint centre from the ASIS: 0.36 w medial... measured from the
        # ASIS midpoint: lateral 0.36 w, posterior 0.19 w, inferior 0.30 w.
        hjc = np.array([0.36 * w, asis_skin[1] - 0.30 * w, asis_skin[2] + 0.19 * w + 0.01 * H])
        pelvis_r = np.array([d.hip_width_m / 2, 0.06 * H, 0.075 * H])
        pelvis_c = np.array([0.0, seat + 0.045 * H, hjc[2] + 0.02 * H])
        bump_r = 0.02 * H
        bump_c = asis_skin - bump_r * asis_n
        knee = np.array([hjc[0] + 0.02 * H, seat + 0.092 * H - d.knee_radius_m, hjc[2] - d.thigh_length_m])
        ankle_h = 0.039 * H
        drop = knee[1] - ankle_h
        beta = math.acos(min(1.0, drop / d.shank_length_m)) if drop > 0 else 0.0
        ankle = knee + d.shank_length_m * np.array([0.0, -math.cos(beta), -math.sin(beta)])
        foot_c = ankle + np.array([0.005 * H, -0.5 * ankle_h, -0.045 * H])
        foot_r = np.array([0.025 * H, 0.5 * ankle_h + 0.005, 0.075 * H])
        mirror = np.array([-1.0, 1.0, 1.0])
        both = lambda p: np.stack([p, p * mirror])  # noqa: E731  right then left
        # The thigh is flattened on the seat: its top (thigh clearance, ~0.092 H) stays below the
        # ASIS so that the ASIS markers show above the hip crease.
        thigh_p0 = np.array([hjc[0], seat + 0.092 * H - d.thigh_radius_m, hjc[2] - 0.01 * H])
        return {
            "asis_skin": both(asis_skin), "asis_n": both(asis_n),
            "sphere_c": both(bump_c), "sphere_r": np.full(2, bump_r),
            "capsule_p0": np.concatenate([both(thigh_p0), both(knee)]),
            "capsule_p1": np.concatenate([both(knee), both(ankle)]),
            "capsule_r0": np.array([d.thigh_radius_m] * 2 + [d.calf_radius_m] * 2),
            "capsule_r1": np.array([d.knee_radius_m] * 2 + [d.ankle_radius_m] * 2),
            "ellipsoid_c": np.stack([pelvis_c, *both(foot_c)]),
            "ellipsoid_axes": np.stack([np.diag(pelvis_r), np.diag(foot_r), np.diag(foot_r)]),
            "ellipsoid_rgb": np.array([TROUSERS_RGB, SHOES_RGB, SHOES_RGB], np.float32) / 255.0,
        }

    # ------------------------------------------------------------------ kinematics
    def trunk_rotation(self, pose: Pose) -> np.ndarray:
        """(3, 3) trunk orientation in the world (identity = upright, facing -Z)."""
        return (rot_z(-math.radians(pose.trunk_lateral_lean_deg))
                @ rot_x(-math.radians(pose.trunk_forward_lean_deg))
                @ rot_y(math.radians(pose.trunk_axial_rotation_deg)))

    def girdle_rise_m(self, elevation_deg: float | np.ndarray) -> float | np.ndarray:
        """Automatic rise (m) of the acromion marker with humerus elevation (scapulohumeral rhythm).

        Smoothly 0 below 30 degrees to 0.017 x stature (3 cm for 1.75 m) at 150 degrees and above,
        close to the acromion rise relative to the sternum in the bundled Vicon capture. Works on
        scalars and arrays.
        """
        s = np.clip((np.asarray(elevation_deg, dtype=np.float64) - 30.0) / 120.0, 0.0, 1.0)
        return 0.017 * self.dims.stature_m * s * s * (3.0 - 2.0 * s)

    @staticmethod
    def scapular_rotation_deg(elevation_deg: float | np.ndarray) -> float | np.ndarray:
        """Upward rotation (deg) that turns the acromion's top face medially as the arm rises."""
        return 0.5 * np.clip(np.asarray(elevation_deg, dtype=np.float64) - 30.0, 0.0, 120.0)

    def shoulder_local_m(self, elevation_deg: float | np.ndarray, shrug_m: float | np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Right shoulder in upright-trunk coordinates for humerus elevations and shrugs.

        Args:
            elevation_deg: (...) humerus elevation from hanging, degrees.
            shrug_m: (...) shoulder shrug, metres.

        Returns:
            gh: (..., 3) glenohumeral centre.
            acromion_skin: (..., 3) skin point over the acromion (the marker rests on it).
            acromion_normal: (..., 3) outward unit normal there.
        """
        r_ua = self._geo.upper_arm_r[0]
        gamma0 = math.asin(0.008 / r_ua)
        gamma = gamma0 - np.radians(self.scapular_rotation_deg(elevation_deg))
        zero = 0.0 * gamma
        acr_n = np.stack([np.sin(gamma), np.cos(gamma), zero], axis=-1)
        # The acromion marker turns medially over the humeral head; GH rises by what that turn
        # takes away so that the marker itself rises by the rhythm plus the shrug.
        turn_drop = (r_ua + self.markerset.radius_m) * (math.cos(gamma0) - np.cos(gamma))
        rise = self.girdle_rise_m(elevation_deg) + shrug_m + turn_drop
        gh = self._geo.gh_right_m + np.stack([zero, rise + zero, zero], axis=-1)
        return gh, gh + r_ua * acr_n, acr_n

    def _arm(self, arm: ArmPose) -> dict[str, np.ndarray]:
        """One arm in trunk coordinates, right-side convention (x = lateral)."""
        d = self.dims
        h = arm.humerus_rot
        u = -h[:, 1]
        elev = math.degrees(math.acos(max(-1.0, min(1.0, -u[1]))))
        gh, acr_skin, acr_n = self.shoulder_local_m(elev, arm.shoulder_shrug_m)
        r_ua = self._geo.upper_arm_r[0]
        elbow = gh + d.upper_arm_m * u
        fore = h @ rot_x(math.radians(arm.elbow_flexion_deg)) @ rot_y(-math.radians(arm.forearm_supination_deg))
        wrist = elbow - d.forearm_m * fore[:, 1]
        return {
            "gh": gh, "elbow": elbow, "wrist": wrist, "fore": fore,
            "girdle": gh + np.array([-0.6 * r_ua, -0.35 * r_ua, 0.0]),
            "acr_skin": acr_skin, "acr_n": acr_n,
            "lat": h[:, 0], "ulnar": fore[:, 2],
        }

    def _solve(self, pose: Pose) -> dict[str, np.ndarray]:
        """Everything pose-dependent, in world coordinates."""
        g = self._geo
        d = self.dims
        rt = self.trunk_rotation(pose)
        lumbar = g.lumbar_m
        mirror = np.array([-1.0, 1.0, 1.0])
        eh, sh = d.epicondyle_half_width_m, d.styloid_half_width_m
        skin = np.empty((14, 3))
        normal = np.empty((14, 3))
        skin[0], normal[0] = g.sternum_skin, g.sternum_n
        skin[1], normal[1] = g.xiphoid_skin, g.xiphoid_n
        arms = {}
        tissue = self.markerset.soft_tissue_m
        for k, side in enumerate(SIDES):
            a = self._arm(pose.arm(side))
            m = mirror if side == "left" else np.ones(3)
            arms[side] = a
            skin[2 + k], normal[2 + k] = a["acr_skin"] * m, a["acr_n"] * m
            e0 = 4 + 2 * k
            skin[e0] = (a["elbow"] + (eh + tissue) * a["lat"]) * m
            skin[e0 + 1] = (a["elbow"] - (eh + tissue) * a["lat"]) * m
            normal[e0], normal[e0 + 1] = a["lat"] * m, -a["lat"] * m
            w0 = 8 + 2 * k
            skin[w0] = (a["wrist"] - (sh + tissue) * a["ulnar"]) * m
            skin[w0 + 1] = (a["wrist"] + (sh + tissue) * a["ulnar"]) * m
            normal[w0], normal[w0 + 1] = -a["ulnar"] * m, a["ulnar"] * m
        # Trunk-borne points: rotate about the lumbar pivot.
        skin[:12] = lumbar + (skin[:12] - lumbar) @ rt.T
        normal[:12] = normal[:12] @ rt.T
        skin[12:] = self._static["asis_skin"]
        normal[12:] = self._static["asis_n"]
        return {"rt": rt, "arms": arms, "skin": skin, "normal": normal}

    def landmarks_m(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """Bone landmarks and outward skin normals of the marker set's markers.

        Returns:
            landmarks: (M, 3) float64 world metres (bone, one soft-tissue thickness under the skin).
            normals: (M, 3) float64 unit outward normals.
        """
        s = self._solve(pose)
        n = s["normal"][self._marker_landmark]
        return s["skin"][self._marker_landmark] - self.markerset.soft_tissue_m * n, n

    def markers_m(self, pose: Pose) -> np.ndarray:
        """(M, 3) float64 marker ball centres, world metres, in marker-set order.

        Each centre is its bone landmark moved along the outward skin normal by the soft tissue
        thickness plus the ball radius, so the ball rests on the skin.
        """
        s = self._solve(pose)
        return (s["skin"][self._marker_landmark] + self.markerset.radius_m * s["normal"][self._marker_landmark]
                + self._offsets)

    def joint_centres_m(self, pose: Pose, side: str) -> dict[str, np.ndarray]:
        """World positions (3,) of one arm's ``gh``, ``elbow`` and ``wrist`` centres."""
        a = self._arm(pose.arm(side))
        m = np.array([-1.0, 1.0, 1.0]) if side == "left" else np.ones(3)
        rt, lumbar = self.trunk_rotation(pose), self._geo.lumbar_m
        return {k: lumbar + rt @ (a[k] * m - lumbar) for k in ("gh", "elbow", "wrist")}

    def trunk_gap_m(self, pose: Pose, side: str) -> float:
        """Distance (m) from the elbow's skin to the trunk surface (thorax, abdomen); < 0 inside."""
        scene = self.scene(pose)
        elbow = self.joint_centres_m(pose, side)["elbow"]
        trunk = [0, 4]  # thorax and abdomen (see _build_constant)
        sd = _sdf_ellipsoids(elbow[None], scene.ellipsoid_centre_m[trunk], scene.ellipsoid_axes_m[trunk])
        return float(sd.min()) - self._geo.upper_arm_r[1]

    def elbow_at_side_abduction_deg(self, pose: Pose, side: str = "right") -> float:
        """Abduction (deg) that brings the elbow's skin against the trunk.

        The humerus keeps the arm's flexion (its sagittal projection angle), external rotation,
        elbow and forearm angles; only its abduction changes (found by bisection), with the
        trunk as in ``pose``. Used for the seed experiment: with the elbow at the side the medial
        epicondyle marker is squeezed between the elbow and the trunk.
        """
        arm = pose.arm(side)
        d = arm.direction
        flexion = math.degrees(math.atan2(-d[2], -d[1]))
        er = arm.external_rotation_deg

        def gap(abduction: float) -> float:
            a = ArmPose.clinical(flexion, abduction, er, arm.elbow_flexion_deg, arm.forearm_supination_deg, arm.shoulder_shrug_m)
            return self.trunk_gap_m(pose.with_arm(side, a), side)

        lo, hi = -40.0, 45.0
        if gap(lo) > 0 or gap(hi) < 0:
            raise MotionError(f"the {side} elbow cannot touch the trunk at {flexion:.0f} degrees of flexion")
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if gap(mid) < 0 else (lo, mid)
        return 0.5 * (lo + hi)

    def scene(self, pose: Pose) -> SceneFrame:
        """All render primitives of ``pose``: marker balls, body capsules and ellipsoids."""
        s = self._solve(pose)
        g, st = self._geo, self._static
        rt = s["rt"]
        lumbar = g.lumbar_m
        mirror = np.array([-1.0, 1.0, 1.0])
        # Trunk ellipsoids: thorax and head with the trunk, abdomen with half of it.
        half = rotation_exp(0.5 * rotation_log(rt))
        markers = (s["skin"][self._marker_landmark] + self.markerset.radius_m * s["normal"][self._marker_landmark]
                   + self._offsets)

        cap_p0, cap_p1 = [], []
        hand_c, hand_axes = [], []
        ha = g.hand_half_axes
        for side in SIDES:
            a = s["arms"][side]
            m = mirror if side == "left" else np.ones(3)
            fore = a["fore"]
            hc = a["wrist"] - (0.008 * self.dims.stature_m + ha[0]) * fore[:, 1]
            cap_p0 += [a["gh"] * m, (a["elbow"] - g.forearm_start_m * fore[:, 1]) * m, g.girdle_medial_m * m]
            cap_p1 += [a["elbow"] * m, a["wrist"] * m, a["girdle"] * m]
            hand_c.append(hc * m)
            # Hand: long axis along the forearm, width along the styloid axis, thickness palmar.
            axes = np.stack([fore[:, 1] * ha[0], fore[:, 2] * ha[1], fore[:, 0] * ha[2]], axis=1)
            hand_axes.append(m[:, None] * axes)
        cap_p0.append(g.neck[0])
        cap_p1.append(g.neck[1])
        p0 = lumbar + (np.array(cap_p0) - lumbar) @ rt.T
        p1 = lumbar + (np.array(cap_p1) - lumbar) @ rt.T

        e_c = np.stack([g.thorax_c, g.head_c, hand_c[0], hand_c[1], g.abdomen_c])
        e_axes = np.stack([np.diag(g.thorax_r), np.diag(g.head_r), hand_axes[0], hand_axes[1], np.diag(g.abdomen_r)])
        e_c[:4] = lumbar + (e_c[:4] - lumbar) @ rt.T
        e_axes[:4] = rt[None] @ e_axes[:4]
        e_c[4] = lumbar + half @ (e_c[4] - lumbar)
        e_axes[4] = half @ e_axes[4]

        bumps = s["skin"][8:12] - g.styloid_bump_r * s["normal"][8:12]
        c = self._constant
        return SceneFrame(
            sphere_centre_m=np.concatenate([markers, st["sphere_c"], bumps]),
            sphere_radius_m=c["sphere_r"],
            sphere_rgb=c["sphere_rgb"],
            sphere_marker_index=c["sphere_marker_index"],
            capsule_p0_m=np.concatenate([p0, st["capsule_p0"]]),
            capsule_p1_m=np.concatenate([p1, st["capsule_p1"]]),
            capsule_r0_m=c["capsule_r0"],
            capsule_r1_m=c["capsule_r1"],
            capsule_rgb=c["capsule_rgb"],
            ellipsoid_centre_m=np.concatenate([e_c, st["ellipsoid_c"]]),
            ellipsoid_axes_m=np.concatenate([e_axes, st["ellipsoid_axes"]]),
            ellipsoid_rgb=c["ellipsoid_rgb"],
        )
