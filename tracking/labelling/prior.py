"""The body model the labelling fits: population ranges and the reference pose's tolerances.

Every term is a quantity of a candidate labelling (a length, an angle) with the range it may take;
its cost is the squared excess over the range in units of the term's scale (``scale``: 10 mm for
lengths, 5 degrees for angles), 0 inside. A labelling's score is the sum over the terms, so a
labelling that keeps every range scores 0 and one that breaks a range by its scale scores 1.
Terms whose markers are not seen cost nothing.

Lengths are population ranges for 5th-percentile women to 95th-percentile men (Winter's segment
ratios of stature, docs/SIMULATOR.md's body model) between marker *centres* (the balls sit 25 mm
off the bone), widened by twice the 15 mm a marker may be placed off its landmark. The angles
are the reference pose's tolerances (docs/TRACKING.md, "Labelling as a fit"): upper arm 5-40
degrees from the body and turned from clearly in (the lateral epicondyle up to 70 degrees in
front of the medial one) to slightly out (20 degrees), elbow up to 30 degrees flexed, thumb
forward, trunk lean and turn up to 15 degrees; each range is widened by the lean (the angles are
taken in the patient's frame, not the trunk's) and by what 15 mm of placement error turns an
elbow's or a wrist's marker pair (about 15 degrees).

Angles use the patient's frame: x the patient's right, y up, z backwards. For an arm, "out" is
+x on the right and -x on the left, so one set of numbers serves both arms.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: cost scales: a length this much outside its range costs 1, an angle this many degrees
LENGTH_SCALE_M = 0.010
ANGLE_SCALE_DEG = 5.0
RATIO_SCALE = 0.04


@dataclass(frozen=True, slots=True)
class BodyPrior:
    """Ranges of the body model (metres, degrees). See the module docstring for their sources."""

    # lengths between marker centres
    upper_arm_m: tuple[float, float] = (0.22, 0.46)      # shoulder marker -> mid-epicondyles
    forearm_m: tuple[float, float] = (0.17, 0.33)        # mid-epicondyles -> mid-styloids
    # bone breadths across the epicondyles and the styloids (5th percentile women to 95th
    # percentile men); the markers' distance adds twice ``ball_offset_m`` (ball radius and soft
    # tissue), and ``width_slack_m`` for placement (a marker moved 15 mm along the skin around
    # the joint changes the pair's distance by a few millimetres only)
    elbow_bone_m: tuple[float, float] = (0.054, 0.077)
    wrist_bone_m: tuple[float, float] = (0.045, 0.062)
    ball_offset_m: float = 0.025
    width_slack_m: float = 0.012
    sternum_m: tuple[float, float] = (0.07, 0.32)        # upper - lower trunk markers
    hips_m: tuple[float, float] = (0.14, 0.42)           # hip markers
    shoulders_m: tuple[float, float] = (0.24, 0.58)      # shoulder markers
    sternum_shoulder_m: tuple[float, float] = (0.09, 0.36)
    # redundant terms, so that a marker keeps constraints when a neighbour is unseen
    reach_m: tuple[float, float] = (0.36, 0.80)           # shoulder marker -> mid-styloids (elbow < 40 deg)
    shoulder_over_lower_m: tuple[float, float] = (0.08, 0.45)   # shoulder above the lower trunk marker
    shoulder_over_upper_m: tuple[float, float] = (-0.08, 0.16)  # shoulder above the upper trunk marker
    shoulder_out_m: float = 0.07    # a shoulder marker lies at least this far out of the upper trunk marker
    arm_out_m: float = 0.0          # the elbow and wrist markers lie out of the upper trunk marker
    hips_below_m: tuple[float, float] = (0.02, 0.30)   # hip markers below the lower trunk marker
    hip_inside_m: float = 0.03      # a hip marker lies this far inside its side's lateral epicondyle marker
    # the elbow's markers are not lower than this below their side's hip marker (seated elbow
    # rest height is 2-10 cm above the hip markers; a 15 degree lean to the side lowers an elbow ~5 cm)
    elbow_over_hip_m: float = -0.04
    # reference-pose angles, degrees
    abduction_deg: tuple[float, float] = (-10.0, 58.0)   # upper arm from the vertical, outwards
    arm_flexion_deg: tuple[float, float] = (-35.0, 35.0)  # upper arm from the vertical, forwards
    elbow_flexion_deg: tuple[float, float] = (0.0, 40.0)
    # the forearm from straight down: the upper arm's 40 degrees, the elbow's 40 and the lean's 15
    forearm_down_deg: tuple[float, float] = (0.0, 100.0)
    # lateral epicondyle's direction about the upper arm: + turned in (in front of the medial one)
    humeral_rotation_deg: tuple[float, float] = (-35.0, 85.0)
    # thumb (radial styloid) direction about the forearm, from forward, + outwards
    thumb_deg: tuple[float, float] = (-75.0, 75.0)
    trunk_lean_deg: tuple[float, float] = (0.0, 45.0)    # lower -> upper trunk marker from vertical
    # the pelvis sits level on the chair (obliquity under 8 degrees, and 15 mm of placement error
    # over the hips' distance)
    hips_tilt_deg: tuple[float, float] = (-12.0, 12.0)
    hips_turn_deg: tuple[float, float] = (-35.0, 35.0)   # hip line from the patient's x
    hips_centre_m: tuple[float, float] = (-0.08, 0.08)
    # the hip markers (front of the pelvis) lie within this depth of the lower trunk marker (front
    # of the chest), + behind: a 15 degree lean moves the chest ~5 cm, placement 3 cm
    hips_depth_m: tuple[float, float] = (-0.07, 0.12)   # mid-hips from the lower trunk marker, along x
    # pose-independent: the elbow's marker pair across the upper arm, the wrist's across the
    # forearm (the bones' axes are at right angles to them; placement error tilts them)
    elbow_axis_deg: tuple[float, float] = (70.0, 110.0)
    wrist_axis_deg: tuple[float, float] = (70.0, 110.0)
    # proportions of one body (scale-free): upper arm and shoulder-to-wrist reach over the
    # shoulders' distance (Winter's ratios 0.186 and ~0.3 of stature over 0.22-0.23; the reach
    # shortens with elbow flexion)
    upper_arm_ratio: tuple[float, float] = (0.72, 1.28)
    reach_ratio: tuple[float, float] = (1.15, 2.05)
    # the two sides of one body: upper arm, forearm, elbow and wrist widths differ by at most
    # this much between left and right (placement error included)
    symmetry_m: tuple[float, float] = (0.0, 0.045)
    # pose-independent: forearm rotation (radial styloid about the forearm from the lateral
    # epicondyle's direction, + pronation; 0 = palm forward with the arm at the side)
    forearm_rotation_deg: tuple[float, float] = (-40.0, 200.0)


def over(value: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """How far ``value`` lies outside [lo, hi] (0 inside; NaN stays NaN)."""
    return np.maximum(np.maximum(lo - value, value - hi), 0.0)


def cost(value: np.ndarray, rng: tuple[float, float], scale: float) -> np.ndarray:
    """Squared excess over ``rng`` in units of ``scale``; 0 where ``value`` is NaN (not seen)."""
    c = (over(value, *rng) / scale) ** 2
    return np.where(np.isnan(c), 0.0, c)


def norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def unit(v: np.ndarray) -> np.ndarray:
    return v / norm(v)[..., None]


def mid(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Midpoint of two markers; the one seen where the other is not (NaN)."""
    return np.where(np.isnan(a), b, np.where(np.isnan(b), a, 0.5 * (a + b)))


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between vectors (degrees)."""
    c = np.einsum("...i,...i->...", unit(a), unit(b))
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def about_deg(v: np.ndarray, axis: np.ndarray, ref: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Direction of ``v`` about the unit ``axis``: the angle from ``ref`` towards ``right`` (both
    made perpendicular to the axis), degrees in (-180, 180]."""
    def perp(w: np.ndarray) -> np.ndarray:
        return w - np.einsum("...i,...i->...", w, axis)[..., None] * axis
    r = unit(perp(ref))
    s = perp(right)
    s = unit(s - np.einsum("...i,...i->...", s, r)[..., None] * r)
    p = perp(v)
    return np.degrees(np.arctan2(np.einsum("...i,...i->...", p, s), np.einsum("...i,...i->...", p, r)))


_UP = np.array([0.0, 1.0, 0.0])
_FORWARD = np.array([0.0, 0.0, -1.0])


def upper_arm_terms(prior: BodyPrior, sign: float, s: np.ndarray, e1: np.ndarray, e2: np.ndarray
                    ) -> dict[str, np.ndarray]:
    """Values of the terms of a shoulder and its elbow's two markers (patient frame, (..., 3))."""
    out = np.array([sign, 0.0, 0.0])
    e = mid(e1, e2)
    u = e - s
    down = -u[..., 1]
    return {
        "upper_arm": norm(u),
        "elbow_width": norm(e1 - e2),
        "abduction": np.degrees(np.arctan2(u @ out, down)),
        "arm_flexion": np.degrees(np.arctan2(u @ _FORWARD, down)),
        # 0: lateral epicondyle straight out; +: turned in (in front)
        "humeral_rotation": about_deg(e1 - e2, unit(u), out, _FORWARD),
        "elbow_axis": angle_deg(e1 - e2, u),
    }


def forearm_terms(prior: BodyPrior, sign: float, s: np.ndarray, e1: np.ndarray, e2: np.ndarray, w1: np.ndarray,
                  w2: np.ndarray) -> dict[str, np.ndarray]:
    """Values of the terms that need the wrist markers (patient frame, (..., 3))."""
    out = np.array([sign, 0.0, 0.0])
    e, w = mid(e1, e2), mid(w1, w2)
    f = w - e
    return {
        "forearm": norm(f),
        "reach": norm(w - s),
        "forearm_down": angle_deg(f, -_UP),
        "wrist_width": norm(w1 - w2),
        "elbow_flexion": angle_deg(e - s, f),
        "thumb": about_deg(w1 - w2, unit(f), _FORWARD, out),
        "wrist_axis": angle_deg(w1 - w2, f),
        "forearm_rotation": forearm_rotation_deg(sign, e1, e2, w1, w2),
    }


def forearm_rotation_deg(sign: float, e1: np.ndarray, e2: np.ndarray, w1: np.ndarray, w2: np.ndarray) -> np.ndarray:
    """Pronation (degrees) of the radial styloid marker about the forearm from the lateral
    epicondyle's direction: 0 palm forward with the arm at the side, 90 thumb forward; the same
    numbers on both arms. Pose-independent (the elbow's axis is on the humerus)."""
    f = unit(mid(w1, w2) - mid(e1, e2))
    e, w = e1 - e2, w1 - w2
    ep = e - np.einsum("...i,...i->...", e, f)[..., None] * f
    wp = w - np.einsum("...i,...i->...", w, f)[..., None] * f
    # pronation turns the radius about the upward axis (-f) on the right arm, mirrored on the left
    sin = sign * np.einsum("...i,...i->...", np.cross(ep, wp), -f)
    r = np.degrees(np.arctan2(sin, np.einsum("...i,...i->...", ep, wp)))
    return np.where(r < -90.0, r + 360.0, r)  # (-90, 270]: the anatomical range is in one piece


#: lengths of an arm compared with the other arm's ("symmetry")
SYMMETRIC = ("upper_arm", "forearm", "elbow_width", "wrist_width")
#: lengths of an arm compared with the shoulders' distance (name -> the length's column in
#: the arm's lengths, after the SYMMETRIC ones)
PROPORTIONS = {"upper_arm_ratio": 0, "reach_ratio": 4}


def trunk_terms(prior: BodyPrior, upper: np.ndarray, lower: np.ndarray, lhip: np.ndarray, rhip: np.ndarray
                ) -> dict[str, np.ndarray]:
    """Values of the trunk's terms (patient frame, (..., 3))."""
    h = rhip - lhip
    flat = np.sqrt(h[..., 0] ** 2 + h[..., 2] ** 2)
    return {
        "sternum": norm(upper - lower),
        "trunk_lean": angle_deg(upper - lower, _UP),
        "hips": norm(h),
        "hips_tilt": np.degrees(np.arctan2(h[..., 1], flat)),
        "hips_turn": np.degrees(np.arctan2(-h[..., 2], h[..., 0])),
        "hips_below": lower[..., 1] - np.fmax(lhip[..., 1], rhip[..., 1]),
        "hips_centre": 0.5 * (lhip[..., 0] + rhip[..., 0]) - lower[..., 0],
        "hips_depth": np.fmax(lhip[..., 2], rhip[..., 2]) - lower[..., 2],
    }


def coupling_terms(prior: BodyPrior, sign: float, upper: np.ndarray, lower: np.ndarray, hip: np.ndarray,
                   s: np.ndarray, limbs: np.ndarray) -> dict[str, np.ndarray]:
    """Values of the terms linking an arm to the trunk; ``hip`` the arm's side's hip marker,
    ``limbs`` (..., 4, 3) its elbow and wrist markers (lateral epicondyle first)."""
    return {
        "hip_inside": sign * (limbs[..., 0, 0] - hip[..., 0]),
        "elbow_over_hip": np.fmin(limbs[..., 0, 1], limbs[..., 1, 1]) - hip[..., 1],
        "sternum_shoulder": norm(s - upper),
        "shoulder_over_lower": s[..., 1] - lower[..., 1],
        "shoulder_over_upper": s[..., 1] - upper[..., 1],
        "shoulder_out": sign * (s[..., 0] - upper[..., 0]),
        "arm_out": np.fmin.reduce(sign * (limbs[..., 0] - upper[..., None, 0]), axis=-1),
    }


def _width(prior: BodyPrior, bone_m: tuple[float, float]) -> tuple[float, float]:
    """Range of the distance of a marker pair either side of a joint of ``bone_m`` breadth."""
    add = 2.0 * prior.ball_offset_m
    return (bone_m[0] + add - prior.width_slack_m, bone_m[1] + add + prior.width_slack_m)


def ranges(prior: BodyPrior) -> dict[str, tuple[tuple[float, float], float]]:
    """Each term's range and scale."""
    inf = np.inf
    L, A = LENGTH_SCALE_M, ANGLE_SCALE_DEG
    return {
        "upper_arm": (prior.upper_arm_m, L), "elbow_width": (_width(prior, prior.elbow_bone_m), L),
        "abduction": (prior.abduction_deg, A), "arm_flexion": (prior.arm_flexion_deg, A),
        "humeral_rotation": (prior.humeral_rotation_deg, A),
        "forearm": (prior.forearm_m, L), "reach": (prior.reach_m, L),
        "forearm_down": (prior.forearm_down_deg, A),
        "shoulder_over_lower": (prior.shoulder_over_lower_m, L),
        "shoulder_over_upper": (prior.shoulder_over_upper_m, L), "wrist_width": (_width(prior, prior.wrist_bone_m), L),
        "elbow_flexion": (prior.elbow_flexion_deg, A), "thumb": (prior.thumb_deg, A),
        "forearm_rotation": (prior.forearm_rotation_deg, A),
        "sternum": (prior.sternum_m, L), "trunk_lean": (prior.trunk_lean_deg, A), "hips": (prior.hips_m, L),
        "hips_tilt": (prior.hips_tilt_deg, A), "hips_turn": (prior.hips_turn_deg, A),
        "hips_centre": (prior.hips_centre_m, L), "hips_depth": (prior.hips_depth_m, L), "hip_inside": ((prior.hip_inside_m, inf), L),
        "elbow_over_hip": ((prior.elbow_over_hip_m, inf), L), "elbow_axis": (prior.elbow_axis_deg, A),
        "wrist_axis": (prior.wrist_axis_deg, A),
        "hips_below": (prior.hips_below_m, L),
        "sternum_shoulder": (prior.sternum_shoulder_m, L), "shoulder_out": ((prior.shoulder_out_m, inf), L),
        "arm_out": ((prior.arm_out_m, inf), L), "shoulders": (prior.shoulders_m, L),
        "symmetry": (prior.symmetry_m, L),
        "upper_arm_ratio": (prior.upper_arm_ratio, RATIO_SCALE), "reach_ratio": (prior.reach_ratio, RATIO_SCALE),
    }


def total(values: dict[str, np.ndarray], table: dict[str, tuple[tuple[float, float], float]]) -> np.ndarray:
    """Sum of the costs of ``values`` (term name -> values)."""
    out = 0.0
    for name, v in values.items():
        rng, scale = table[name]
        out = out + cost(v, rng, scale)
    return out
