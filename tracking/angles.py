"""Joint angles of the seated upper body from the markers that play the anatomical roles.

Each marker is found by its role (``roles:`` of the marker set, :data:`tracking.markerset.ROLES`);
without a marker set, by the ``upper_limb_seated`` names (:data:`DEFAULT_ROLES`), which is how a
marker file is read. An angle whose roles have no marker is withheld (NaN; the reason from
:func:`withheld_angles`), never computed from another marker.

The definitions are those of ``docs/JOINT_ANGLES.md`` (clinical goniometry: 0 in the neutral
start position, positive in the named direction, degrees). They use marker positions alone, so
any TRC with the marker names gives the same numbers, and they are vectorized over any leading
(frame) axes: the live tracker calls :func:`joint_angles` with one (M, 3) frame, ``rehab angles``
with a whole (T, M, 3) file.

Frames and vectors (world frame: +Y up, the patient faces -Z, the patient's right is +X)::

    y_T = unit(MB - MP)                       up the trunk (MB: trunk_upper, MP: trunk_lower)
    x_T = unit(MRH - MLH, made orthogonal to y_T)   towards the patient's right (the hips)
    z_T = x_T x y_T                           backwards (the patient faces -z_T)
    out = +x_T (right side), -x_T (left side)
    E = (E1 + E2) / 2, W = (W1 + W2) / 2, u = E - S (upper arm), f = W - E (forearm)
    (S shoulder, E1/E2 elbow lateral/medial, W1/W2 wrist radial/ulnar of the side)

Signed rotations about an axis use the negated axis on the left side, so that a motion and its
mirror image across the sagittal plane give the same numbers.

Numerical conventions (documented choices where the spec leaves room):

- A vector is *degenerate* (its angles NaN) when its length is at most ``_REL_EPS`` times the
  size of what it was made from (coincident markers, a projection of a vector onto the plane
  normal to it). Lengths may be in any unit.
- In the planar angles (flexion, abduction, horizontal flexion) a unit-vector component smaller
  than ``_REL_EPS`` is rounding noise and is taken as exactly 0, so an arm straight up reads
  +180, not -180 or a random angle.
- Every signed angle is wrapped into (-180, 180], and -0 is written as 0 (the spec's columns, in
  files and samples).
- Near its plane's normal a planar angle is ill-conditioned by nature: every value occurs within
  a few degrees of the normal, and a reading would jump by up to 360 degrees between two frames.
  What a person reads live asks for ``near_singular="withhold"`` (an option; the spec's
  columns are the default): flexion withheld (NaN) while the upper arm is within
  ``MIN_FROM_PLANE_NORMAL_DEG`` of pointing sideways, abduction within it of pointing forward or
  backward, horizontal flexion within 45 degrees of vertical, up as well as down; flexion and
  abduction continued past 180 rather than wrapped, read in ``(PLANAR_FROM_DEG, PLANAR_FROM_DEG +
  360]`` = (-135, 225], so an arm raised overhead and a little behind the trunk (e.g. leaning
  forward) reads 185, not -175. The cut lies where the arm's projection points 45 degrees behind
  (across) the vertical, beyond every normal range.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from calibration.errors import RehabError
from tracking.markerset import DEFAULT_ROLES

MARKER_SET = "upper_limb_seated"

#: Marker names a marker file (TRC, C3D) needs for every angle: the ``upper_limb_seated`` names
#: of the roles, in that marker set's order.
REQUIRED_MARKERS: tuple[str, ...] = (
    "MB", "MP", "MLS", "MRS", "MLE1", "MLE2", "MRE1", "MRE2",
    "MLW1", "MLW2", "MRW1", "MRW2", "MLH", "MRH",
)

SIDES: tuple[str, ...] = ("left", "right")

#: Angles of one arm, in column order.
ARM_ANGLES: tuple[str, ...] = (
    "shoulder_flexion",
    "shoulder_abduction",
    "shoulder_elevation",
    "shoulder_horizontal_flexion",
    "shoulder_external_rotation",
    "elbow_flexion",
    "forearm_supination",
)

#: Column names in file order: every arm angle of the left side, then of the right side
#: (``left_shoulder_flexion`` ... ``right_forearm_supination``), then the two trunk leans.
ANGLE_COLUMNS: tuple[str, ...] = tuple(f"{side}_{angle}" for side in SIDES for angle in ARM_ANGLES) + (
    "trunk_forward_lean",
    "trunk_lateral_lean",
)

_TRUNK_AXIS = ("trunk_upper", "trunk_lower")
_TRUNK_FRAME = _TRUNK_AXIS + ("left_hip", "right_hip")
_ARM_PARTS = ("shoulder", "elbow_lateral", "elbow_medial", "wrist_radial", "wrist_ulnar")


def _arm_roles(side: str, *parts: str) -> tuple[str, ...]:
    return tuple(f"{side}_{part}" for part in parts)


#: Column -> the roles (:data:`tracking.markerset.ROLES`) whose markers the angle is computed
#: from (the trunk frame, the shoulder, the elbow centre ``E`` from both epicondyles, the wrist
#: centre ``W`` from both styloids): exactly what the formulas read, no more.
ANGLE_ROLES: dict[str, tuple[str, ...]] = {
    **{column: roles for side in SIDES for column, roles in (
        (f"{side}_shoulder_flexion", _TRUNK_FRAME + _arm_roles(side, *_ARM_PARTS[:3])),
        (f"{side}_shoulder_abduction", _TRUNK_FRAME + _arm_roles(side, *_ARM_PARTS[:3])),
        (f"{side}_shoulder_elevation", _TRUNK_AXIS + _arm_roles(side, *_ARM_PARTS[:3])),
        (f"{side}_shoulder_horizontal_flexion", _TRUNK_FRAME + _arm_roles(side, *_ARM_PARTS[:3])),
        (f"{side}_shoulder_external_rotation", _TRUNK_FRAME + _arm_roles(side, *_ARM_PARTS)),
        (f"{side}_elbow_flexion", _arm_roles(side, *_ARM_PARTS)),
        (f"{side}_forearm_supination", _arm_roles(side, *_ARM_PARTS[1:])),
    )},
    "trunk_forward_lean": _TRUNK_AXIS,
    "trunk_lateral_lean": _TRUNK_AXIS,
}


def withheld_angles(roles: Mapping[str, str] = DEFAULT_ROLES) -> dict[str, str]:
    """The columns a marker set cannot give (always NaN), each with the reason in one line.

    ``roles``: the marker set's role -> marker name (``MarkerSet.roles``).
    """
    out = {}
    for column, needed in ANGLE_ROLES.items():
        absent = [r.replace("_", " ") for r in needed if r not in roles]
        if absent:
            out[column] = f"the marker set has no marker for the {', '.join(absent)}"
    return out


def supported_angles(roles: Mapping[str, str] = DEFAULT_ROLES) -> tuple[str, ...]:
    """The columns of :data:`ANGLE_COLUMNS` that a marker set with ``roles`` can give, in order."""
    withheld = withheld_angles(roles)
    return tuple(c for c in ANGLE_COLUMNS if c not in withheld)


def axis_angles(roles: Mapping[str, str] = DEFAULT_ROLES) -> dict[str, str]:
    """Epicondyle or styloid marker name -> the angle that reads its direction to its pair (the
    elbow's flexion axis ``E2 - E1``, the wrist's ``W2 - W1``): forearm supination. The tracker
    withholds that angle (NaN) while the direction is a guess
    (:attr:`tracking.hidden.Estimator.axis_guessed`)."""
    return {roles[f"{side}_{part}"]: f"{side}_forearm_supination"
            for side in SIDES for part in _ARM_PARTS[1:] if f"{side}_{part}" in roles}


#: :func:`axis_angles` of the ``upper_limb_seated`` names.
AXIS_ANGLES: dict[str, str] = axis_angles(DEFAULT_ROLES)

#: Horizontal flexion is undefined (NaN) below this shoulder elevation (degrees).
MIN_ELEVATION_FOR_HORIZONTAL_FLEXION_DEG = 45.0
#: ... and, with ``near_singular="withhold"``, above this one (the arm within 45 degrees of
#: straight up: as ill-conditioned as down).
MAX_ELEVATION_FOR_HORIZONTAL_FLEXION_DEG = 135.0
#: Shoulder external rotation is undefined (NaN) below this elbow flexion (degrees).
MIN_ELBOW_FLEXION_FOR_ROTATION_DEG = 30.0
#: With ``near_singular="withhold"``, flexion (abduction) is withheld (NaN) while the upper arm is
#: within this angle (degrees) of the normal of its plane: pointing sideways (forward or backward). A direction error of the upper
#: arm is multiplied by 1 / sin(angle from the normal) in the planar angle: 3.9x at 15 degrees,
#: which keeps the ~0.5 degree direction noise of the tracked arm within the 2 degrees of the
#: angles' accuracy target.
MIN_FROM_PLANE_NORMAL_DEG = 15.0
#: Flexion and abduction are read in (PLANAR_FROM_DEG, PLANAR_FROM_DEG + 360] (see above).
PLANAR_FROM_DEG = -135.0
_COS_FROM_NORMAL = math.cos(math.radians(MIN_FROM_PLANE_NORMAL_DEG))

# Relative size under which a vector or a unit-vector component is rounding noise (float64 has
# ~1e-16 relative precision; real marker noise is many orders above 1e-9).
_REL_EPS = 1e-9

_SIDE_SIGN = {"left": -1.0, "right": 1.0}


class MissingMarkersError(RehabError):
    """A marker file lacks names that the joint angles need."""


def missing_markers(names: Sequence[str]) -> list[str]:
    """The names of :data:`REQUIRED_MARKERS` absent from ``names``, in marker-set order."""
    present = set(names)
    return [n for n in REQUIRED_MARKERS if n not in present]


def require_markers(names: Sequence[str], source: str) -> None:
    """Raise :class:`MissingMarkersError` (one line) if ``names`` lack any required marker.

    ``source`` names where the names came from, e.g. ``"markers.trc"``; the message lists the
    names wanted and those found: ``markers.trc lacks MRW1, MRW2 (it has MB, MP, ..., RWRA): the
    angles need the upper_limb_seated names ...``.
    """
    missing = missing_markers(names)
    if missing:
        found = ", ".join(names) if names else "no markers"
        wanted = "" if len(missing) == len(REQUIRED_MARKERS) else " " + ", ".join(REQUIRED_MARKERS)
        raise MissingMarkersError(
            f"{source} lacks {', '.join(missing)} (it has {found}): the angles need the {MARKER_SET} names"
            f"{wanted}; map your names to them with rehab angles --map FILE.yaml"
        )


def wrap180(angle_deg: np.ndarray) -> np.ndarray:
    """Wrap angles (degrees, any shape) into (-180, 180]; NaN stays NaN, -0 becomes 0."""
    a = np.asarray(angle_deg, dtype=np.float64)
    return (180.0 - np.mod(180.0 - a, 360.0)) + 0.0


#: What :func:`joint_angles` gives near a planar angle's singular pose (see the module docstring).
NEAR_SINGULAR = ("spec", "withhold")


def joint_angles(positions: np.ndarray, names: Sequence[str], *, roles: Mapping[str, str] | None = None,
                 near_singular: str = "spec") -> dict[str, np.ndarray]:
    """Joint angles (degrees) of every frame, per ``docs/JOINT_ANGLES.md``.

    Args:
        positions: (..., M, 3) float marker positions in the world frame (+Y up, the patient
            faces -Z), any length unit; typically (T, M, 3) or one frame (M, 3). NaN = missing.
        names: the M marker names, in the order of ``positions``' marker axis. Names playing
            no role are ignored; a role whose marker is absent counts as a marker missing in
            every frame (its angles NaN: :func:`withheld_angles`; :func:`require_markers`
            rejects such files).
        roles: role -> marker name (``MarkerSet.roles``); None: the ``upper_limb_seated``
            names (:data:`DEFAULT_ROLES`), as a marker file is read.
        near_singular: ``"spec"``: the spec's definitions exactly (files, samples); ``"withhold"``:
            for a person reading them live, planar angles withheld near their plane's normal and
            flexion and abduction continued past 180 (module docstring).

    Returns:
        A dict with the keys of :data:`ANGLE_COLUMNS`, in that order, each a float64 array of
        shape ``positions.shape[:-2]`` (0-d for one frame) in degrees. NaN where undefined:
        a marker it needs is missing or NaN, a vector is degenerate, horizontal flexion below 45
        degrees of elevation, external rotation below 30 degrees of elbow flexion; with
        ``"withhold"`` also flexion (abduction) with the upper arm within 15 degrees of pointing
        sideways (forward or backward) and horizontal flexion above 135 degrees of elevation.
    """
    if near_singular not in NEAR_SINGULAR:
        raise ValueError(f"near_singular must be one of {NEAR_SINGULAR}, not {near_singular!r}")
    guarded = near_singular == "withhold"
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim < 2 or p.shape[-1] != 3 or p.shape[-2] != len(names):
        raise ValueError(f"positions must be (..., {len(names)}, 3) for {len(names)} names, got {p.shape}")
    index = _role_index(names, DEFAULT_ROLES if roles is None else roles)
    if p.ndim == 2:
        return _frame_angles(p, index, guarded)
    batch = p.shape[:-2]
    absent = np.full(batch + (3,), np.nan)

    def marker(role: str) -> np.ndarray:
        i = index.get(role)
        return absent if i is None else p[..., i, :]

    mb, mp = marker("trunk_upper"), marker("trunk_lower")
    y_t = _unit(mb - mp, _norm(mb) + _norm(mp))
    hips = marker("right_hip") - marker("left_hip")
    x_t = _unit(hips - _dot(hips, y_t)[..., None] * y_t, _norm(hips))
    z_t = _cross(x_t, y_t)

    # Both arms at once: a leading side axis (left, right), so one frame costs few numpy calls.
    arm = {part: np.stack([marker(f"{side}_{part}") for side in SIDES]) for part in _ARM_PARTS}
    sign = np.array([_SIDE_SIGN[side] for side in SIDES]).reshape((len(SIDES),) + (1,) * (len(batch) + 1))
    arms = _arm_angles(arm, sign, x_t, y_t, z_t, guarded)

    out = {f"{side}_{angle}": arms[angle][i] for i, side in enumerate(SIDES) for angle in ARM_ANGLES}
    # World axes: X = right, Y = up, Z = backwards.
    out["trunk_forward_lean"] = wrap180(np.degrees(np.arctan2(-y_t[..., 2], y_t[..., 1])))
    out["trunk_lateral_lean"] = wrap180(np.degrees(np.arctan2(y_t[..., 0], y_t[..., 1])))
    return {name: np.asarray(out[name], dtype=np.float64) for name in ANGLE_COLUMNS}


def _role_index(names: Sequence[str], roles: Mapping[str, str]) -> dict[str, int]:
    """Role -> index in ``names`` of the marker playing it (roles whose marker is absent left out)."""
    position = {name: i for i, name in enumerate(names)}
    return {role: position[name] for role, name in roles.items() if name in position}


def _arm_angles(
    arm: dict[str, np.ndarray], sign: np.ndarray, x_t: np.ndarray, y_t: np.ndarray, z_t: np.ndarray,
    guarded: bool = False,
) -> dict[str, np.ndarray]:
    """The angles of :data:`ARM_ANGLES` for both sides.

    Args:
        arm: ``shoulder, elbow_lateral, elbow_medial, wrist_radial, wrist_ulnar`` -> (2, ..., 3)
            positions of (left, right).
        sign: (2, 1, ..., 1) -1 for the left side, +1 for the right.
        x_t, y_t, z_t: (..., 3) unit trunk axes.
        guarded: ``near_singular="withhold"`` of :func:`joint_angles`.

    Returns:
        angle name -> (2, ...) degrees.
    """
    shoulder, e1, e2, w1, w2 = (arm[part] for part in _ARM_PARTS)
    elbow = 0.5 * (e1 + e2)
    wrist = 0.5 * (w1 + w2)

    u = _unit(elbow - shoulder, _norm(elbow) + _norm(shoulder))
    f = _unit(wrist - elbow, _norm(wrist) + _norm(elbow))
    down, forward, outward = -y_t, -z_t, sign * x_t

    elevation = _angle_between(u, down)
    horizontal = _planar_deg(u, outward, forward)
    elbow_flexion = _angle_between(u, f)

    # External rotation: forearm direction about the upper arm, from "forearm pointing forward".
    external = _signed_angle(_reject(forward, u), _reject(f, u), sign * u)
    # Supination: wrist axis about the forearm, relative to the epicondyle axis; 0 = thumb up.
    supination = wrap180(90.0 + _signed_angle(_reject(e2 - e1, f), _reject(w2 - w1, f), sign * f))

    flexion = _planar_deg(u, down, forward)
    abduction = _planar_deg(u, down, outward)
    horizontal_defined = elevation >= MIN_ELEVATION_FOR_HORIZONTAL_FLEXION_DEG
    if guarded:
        flexion = np.where(np.abs(_dot(u, outward)) > _COS_FROM_NORMAL, np.nan, _continued(flexion))
        abduction = np.where(np.abs(_dot(u, forward)) > _COS_FROM_NORMAL, np.nan, _continued(abduction))
        horizontal_defined &= elevation <= MAX_ELEVATION_FOR_HORIZONTAL_FLEXION_DEG
    return {
        "shoulder_flexion": flexion,
        "shoulder_abduction": abduction,
        "shoulder_elevation": elevation,
        "shoulder_horizontal_flexion": np.where(horizontal_defined, horizontal, np.nan),
        "shoulder_external_rotation": np.where(
            elbow_flexion >= MIN_ELBOW_FLEXION_FOR_ROTATION_DEG, external, np.nan
        ),
        "elbow_flexion": elbow_flexion,
        "forearm_supination": supination,
    }


def _continued(angle_deg: np.ndarray) -> np.ndarray:
    """A (-180, 180] planar angle read in (PLANAR_FROM_DEG, PLANAR_FROM_DEG + 360]."""
    return np.where(angle_deg <= PLANAR_FROM_DEG, angle_deg + 360.0, angle_deg)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product over the last axis: (..., 3), (..., 3) -> (...)."""
    return _vecdot(a, b)


# np.vecdot (numpy >= 2.0) is the cheapest per call on one frame; einsum is as fast on many.
_vecdot = getattr(np, "vecdot", None) or (lambda a, b: np.einsum("...i,...i->...", a, b))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (np.cross costs ~50 us per call on one frame)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(_dot(v, v))


def _unit(v: np.ndarray, size: np.ndarray) -> np.ndarray:
    """``v`` normalized; NaN where its length is at most ``_REL_EPS * size`` (degenerate) or NaN."""
    length = _norm(v)
    ok = length > _REL_EPS * size
    return np.where(ok[..., None], v / np.where(ok, length, 1.0)[..., None], np.nan)


def _reject(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """``v`` projected on the plane normal to the unit ``axis``; NaN where degenerate."""
    return _unit(v - _dot(v, axis)[..., None] * axis, _norm(v))


def _angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unsigned angle (degrees, 0..180) between (..., 3) vectors; atan2 keeps it exact near 0/180."""
    return np.degrees(np.arctan2(_norm(_cross(a, b)), _dot(a, b)))


def _signed_angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angle (degrees, (-180, 180]) from ``a`` to ``b`` about ``axis`` (right-hand rule).

    ``a`` and ``b`` lie in the plane normal to ``axis``.
    """
    return wrap180(np.degrees(np.arctan2(_dot(_cross(a, b), axis), _dot(a, b))))


def _planar_deg(v: np.ndarray, zero_axis: np.ndarray, positive_axis: np.ndarray) -> np.ndarray:
    """``atan2d(v . positive_axis, v . zero_axis)`` for unit ``v``, rounding noise taken as 0."""
    along = _dot(v, zero_axis)
    across = _dot(v, positive_axis)
    along = np.where(np.abs(along) < _REL_EPS, 0.0, along)
    across = np.where(np.abs(across) < _REL_EPS, 0.0, across)
    return wrap180(np.degrees(np.arctan2(across, along)))



# --------------------------------------------------------------------------- one frame
# The live tracker asks for one frame at a time, where numpy's per-call cost dominates (~300 calls
# on 3-vectors). The same formulas in Python floats take a tenth of the time; every step is the
# same operation in the same order, but numpy's vectorised atan2 and sqrt may round the last bit
# differently from the C library (and change between releases): tests/tracking/test_angles.py
# checks both paths agree to 1e-9 degrees, with the same missing values.
_NAN3 = (math.nan, math.nan, math.nan)


def _frame_angles(p: np.ndarray, index: Mapping[str, int], guarded: bool = False) -> dict[str, np.ndarray]:
    """:func:`joint_angles` of one (M, 3) frame, in Python floats; ``index``: role -> marker index."""
    rows = p.tolist()

    def marker(role: str) -> tuple[float, float, float]:
        i = index.get(role)
        return _NAN3 if i is None else tuple(rows[i])

    mb, mp = marker("trunk_upper"), marker("trunk_lower")
    y_t = _f_unit(_f_sub(mb, mp), _f_norm(mb) + _f_norm(mp))
    hips = _f_sub(marker("right_hip"), marker("left_hip"))
    x_t = _f_unit(_f_sub(hips, _f_scale(_f_dot(hips, y_t), y_t)), _f_norm(hips))
    z_t = _f_cross(x_t, y_t)
    down = _f_scale(-1.0, y_t)
    forward = _f_scale(-1.0, z_t)
    out: dict[str, float] = {}
    for side in SIDES:
        sign = _SIDE_SIGN[side]
        shoulder, e1, e2, w1, w2 = (marker(f"{side}_{part}") for part in _ARM_PARTS)
        elbow = _f_scale(0.5, _f_add(e1, e2))
        wrist = _f_scale(0.5, _f_add(w1, w2))
        u = _f_unit(_f_sub(elbow, shoulder), _f_norm(elbow) + _f_norm(shoulder))
        f = _f_unit(_f_sub(wrist, elbow), _f_norm(wrist) + _f_norm(elbow))
        outward = _f_scale(sign, x_t)
        elevation = _f_angle_between(u, down)
        elbow_flexion = _f_angle_between(u, f)
        horizontal = _f_planar_deg(u, outward, forward)
        external = _f_signed_angle(_f_reject(forward, u), _f_reject(f, u), _f_scale(sign, u))
        supination = _f_wrap180(90.0 + _f_signed_angle(_f_reject(_f_sub(e2, e1), f), _f_reject(_f_sub(w2, w1), f),
                                                       _f_scale(sign, f)))
        flexion = _f_planar_deg(u, down, forward)
        abduction = _f_planar_deg(u, down, outward)
        horizontal_defined = elevation >= MIN_ELEVATION_FOR_HORIZONTAL_FLEXION_DEG
        if guarded:
            flexion = math.nan if abs(_f_dot(u, outward)) > _COS_FROM_NORMAL else _f_continued(flexion)
            abduction = math.nan if abs(_f_dot(u, forward)) > _COS_FROM_NORMAL else _f_continued(abduction)
            horizontal_defined = horizontal_defined and elevation <= MAX_ELEVATION_FOR_HORIZONTAL_FLEXION_DEG
        out[f"{side}_shoulder_flexion"] = flexion
        out[f"{side}_shoulder_abduction"] = abduction
        out[f"{side}_shoulder_elevation"] = elevation
        out[f"{side}_shoulder_horizontal_flexion"] = horizontal if horizontal_defined else math.nan
        out[f"{side}_shoulder_external_rotation"] = (
            external if elbow_flexion >= MIN_ELBOW_FLEXION_FOR_ROTATION_DEG else math.nan)
        out[f"{side}_elbow_flexion"] = elbow_flexion
        out[f"{side}_forearm_supination"] = supination
    out["trunk_forward_lean"] = _f_wrap180(math.degrees(math.atan2(-y_t[2], y_t[1])))
    out["trunk_lateral_lean"] = _f_wrap180(math.degrees(math.atan2(y_t[0], y_t[1])))
    return {name: np.array(out[name]) for name in ANGLE_COLUMNS}


def _f_add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _f_sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _f_scale(k, a):
    return (k * a[0], k * a[1], k * a[2])


def _f_dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _f_cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _f_norm(v) -> float:
    return math.sqrt(_f_dot(v, v))


def _f_unit(v, size: float):
    length = _f_norm(v)
    if length > _REL_EPS * size:
        return (v[0] / length, v[1] / length, v[2] / length)
    return _NAN3


def _f_reject(v, axis):
    d = _f_dot(v, axis)
    return _f_unit((v[0] - d * axis[0], v[1] - d * axis[1], v[2] - d * axis[2]), _f_norm(v))


def _f_wrap180(a: float) -> float:
    return (180.0 - (180.0 - a) % 360.0) + 0.0


def _f_continued(a: float) -> float:
    return a + 360.0 if a <= PLANAR_FROM_DEG else a


def _f_angle_between(a, b) -> float:
    return math.degrees(math.atan2(_f_norm(_f_cross(a, b)), _f_dot(a, b)))


def _f_signed_angle(a, b, axis) -> float:
    return _f_wrap180(math.degrees(math.atan2(_f_dot(_f_cross(a, b), axis), _f_dot(a, b))))


def _f_planar_deg(v, zero_axis, positive_axis) -> float:
    along = _f_dot(v, zero_axis)
    across = _f_dot(v, positive_axis)
    along = 0.0 if abs(along) < _REL_EPS else along
    across = 0.0 if abs(across) < _REL_EPS else across
    return _f_wrap180(math.degrees(math.atan2(across, along)))
