"""The avatar's skeleton from the upper-body markers, found by their roles (pure numpy, no GL).

:class:`SkeletonTracker` turns one frame of tracked markers (positions + :class:`MarkerStatus`)
into a :class:`SkeletonPose`: joint centres, segment frames and a per-segment state, in the
world frame of ``docs/INTERFACES.md`` (metres, +Y up, the patient faces -Z, the patient's right
is +X). Each marker is found by its role (``roles:`` of the marker set; below by its
``upper_limb_seated`` name: MB trunk_upper, MP trunk_lower, M*H hip, M*S shoulder, M*E1/M*E2
elbow lateral/medial, M*W1/M*W2 wrist radial/ulnar). A role the marker set has no marker for is a
marker never seen: it sits where it would on an average adult and its segment's state is LOST.
The frames follow ``docs/JOINT_ANGLES.md``::

    trunk      y = unit(MB - MP), x = MRH - MLH made orthogonal to y, z = x cross y (backwards)
    pelvis     x = unit(MRH - MLH), y = world up made orthogonal to x, z = x cross y
    upper arm  y = unit(shoulder - elbow), x = E1 - E2 (medial -> lateral epicondyle) made
               orthogonal, z = x cross y
    forearm    y = unit(E - W), x = W1 - W2 (ulnar -> radial styloid, i.e. towards the thumb)
               made orthogonal, z = x cross y

so the forearm frame turns with pronation/supination and the hand drawn in it shows the rotation;
the palm faces ``-z`` on the right forearm and ``+z`` on the left (:meth:`SkeletonPose.palm_normal`).

Joint centres: elbow ``E = (E1 + E2) / 2`` and wrist ``W = (W1 + W2) / 2`` as in the angle
definitions; the glenohumeral centre a fixed fraction of the stature below the acromion marker
in the trunk frame; the hip joint centres from the ASIS markers (Bell et al. 1990); neck base and
head centre from the sternum marker in the trunk frame, scaled by the patient's stature.

Hidden markers: a marker without a position keeps its last known position relative to its
parent (trunk markers relative to the trunk frame, elbow markers relative to the shoulder in the
trunk frame, wrist markers relative to the elbow in the upper-arm frame), so a lost forearm
follows the upper arm rigidly instead of vanishing or jumping, and the segment's state says LOST.
Before a marker is first seen it sits where it would on an average adult in the reference pose.

Proportions (:class:`Proportions`): shoulder and hip marker widths, trunk, upper-arm and forearm
lengths are the running medians of the frames in which their markers were all measured, and the
stature estimate behind every body radius comes from them, so the avatar takes the patient's size.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from tracking.angles import MissingMarkersError
from tracking.markerset import DEFAULT_ROLES
from tracking.marker_status import MarkerStatus

#: Joint centres of a :class:`SkeletonPose`, in ``joints_m`` order.
JOINTS: tuple[str, ...] = (
    "pelvis", "right_hip", "left_hip", "sternum", "neck", "head",
    "right_acromion", "right_shoulder", "right_elbow", "right_wrist", "right_hand",
    "left_acromion", "left_shoulder", "left_elbow", "left_wrist", "left_hand",
)

#: Segments of a :class:`SkeletonPose`, in ``frames`` and ``state`` order.
SEGMENTS: tuple[str, ...] = ("pelvis", "trunk", "right_upper_arm", "right_forearm", "left_upper_arm", "left_forearm")

SIDES: tuple[str, ...] = ("right", "left")
SIDE_SIGN = {"right": 1.0, "left": -1.0}

# Roles (tracking.markerset.ROLES) whose markers' states make up each segment's state.
_SEGMENT_MARKERS = {
    "pelvis": ("left_hip", "right_hip"),
    "trunk": ("trunk_upper", "trunk_lower"),
    "right_upper_arm": ("right_shoulder", "right_elbow_lateral", "right_elbow_medial"),
    "right_forearm": ("right_wrist_radial", "right_wrist_ulnar"),
    "left_upper_arm": ("left_shoulder", "left_elbow_lateral", "left_elbow_medial"),
    "left_forearm": ("left_wrist_radial", "left_wrist_ulnar"),
}
_TRUNK_MARKERS = ("trunk_upper", "trunk_lower", "left_hip", "right_hip", "left_shoulder", "right_shoulder")

# Marker positions of an average adult in the reference pose (seated upright, arms hanging a
# little away from the body, thumbs forward), relative to MB in the trunk frame, in units of
# stature; right side (x > 0). Measured on tracking.sim.body at the 50th percentile (the ratios
# vary by < 0.01 H over 5th-95th percentile bodies). Used only until a marker is first seen.
_DEFAULT_LAYOUT_H = {
    "trunk_upper": (0.0, 0.0, 0.0),
    "trunk_lower": (0.0, -0.106, -0.021),
    "right_shoulder": (0.116, 0.026, 0.051),
    "right_elbow_lateral": (0.191, -0.184, 0.036),
    "right_elbow_medial": (0.131, -0.201, 0.065),
    "right_wrist_radial": (0.189, -0.329, -0.003),
    "right_wrist_ulnar": (0.192, -0.338, 0.058),
    "right_hip": (0.072, -0.228, 0.0),
}

# Ratios of stature behind the stature estimate (tracking.sim.body anthropometry, same source).
_STATURE_RATIOS = {"shoulder_width_m": 0.230, "trunk_height_m": 0.226, "upper_arm_m": 0.222, "forearm_m": 0.146}
DEFAULT_STATURE_M = 1.70
_STATURE_LIMITS_M = (1.30, 2.10)
# Glenohumeral centre relative to the acromion marker, trunk frame: at 0.0381 stature below it,
# 10 degrees medial of the trunk axis with the arm down; the scapula's upward rotation turns the
# acromion medially over the humeral head by half the humerus elevation beyond 30 degrees (the
# simulator's scapulohumeral rhythm), so a raised arm's centre lies lateral of the marker.
_GH_DISTANCE_H = 0.0381
_GH_TILT_DEG = 10.0
_GH_FORWARD_H = 0.0076
# Neck base and head centre relative to MB, trunk frame, stature units (the marker sits ~2.5 cm
# in front of the sternum skin). Same source as the layout.
_NECK_FROM_MB_H = (0.0, 0.0, 0.078)
_HEAD_FROM_MB_H = (0.0, 0.133, 0.031)
_HAND_CENTRE_FROM_WRIST_H = 0.053  # wrist centre -> middle of the palm, along the forearm


@dataclass(frozen=True, slots=True)
class Proportions:
    """The patient's body measures, learned from measured frames (metres).

    Attributes:
        shoulder_width_m: MLS <-> MRS marker distance.
        hip_width_m: MLH <-> MRH marker distance (the ASIS markers).
        trunk_height_m: MB <-> midpoint of the ASIS markers.
        upper_arm_m: acromion marker <-> elbow centre, both sides pooled.
        forearm_m: elbow centre <-> wrist centre, both sides pooled.
        stature_m: standing height estimated from the four lengths above (anthropometric ratios),
            which scales every body radius of the avatar.
        n_frames: number of measured frames behind the medians (0: the defaults of an average adult).
    """

    shoulder_width_m: float
    hip_width_m: float
    trunk_height_m: float
    upper_arm_m: float
    forearm_m: float
    stature_m: float
    n_frames: int = 0

    @classmethod
    def default(cls, stature_m: float = DEFAULT_STATURE_M) -> "Proportions":
        """An average adult of ``stature_m``."""
        r = _STATURE_RATIOS
        return cls(r["shoulder_width_m"] * stature_m, 0.150 * stature_m, r["trunk_height_m"] * stature_m,
                   r["upper_arm_m"] * stature_m, r["forearm_m"] * stature_m, stature_m, 0)


@dataclass(frozen=True, slots=True, eq=False)
class SkeletonPose:
    """The avatar's pose at one instant (world frame, metres).

    Attributes:
        joints_m: (len(JOINTS), 3) float64 joint centres in :data:`JOINTS` order.
        frames: (len(SEGMENTS), 3, 3) float64 rotation matrices in :data:`SEGMENTS` order; the
            columns are the segment's x, y, z axes in world coordinates (see the module docstring).
        state: (len(SEGMENTS),) uint8 :class:`MarkerStatus` per segment: MEASURED when all its
            markers were measured, ESTIMATED when some were estimated by the tracker, LOST when
            some had no position (the segment then shows its last known pose).
        proportions: the body measures the avatar is drawn with.
    """

    joints_m: np.ndarray
    frames: np.ndarray
    state: np.ndarray
    proportions: Proportions

    def joint(self, name: str) -> np.ndarray:
        """(3,) world position of joint ``name`` (one of :data:`JOINTS`)."""
        return self.joints_m[JOINTS.index(name)]

    def frame(self, segment: str) -> np.ndarray:
        """(3, 3) rotation of ``segment`` (one of :data:`SEGMENTS`), columns x, y, z."""
        return self.frames[SEGMENTS.index(segment)]

    def segment_state(self, segment: str) -> MarkerStatus:
        return MarkerStatus(int(self.state[SEGMENTS.index(segment)]))

    def palm_normal(self, side: str) -> np.ndarray:
        """(3,) unit vector out of the palm of the ``side`` hand (up when supinated 90 degrees)."""
        return -SIDE_SIGN[side] * self.frame(f"{side}_forearm")[:, 2]


# ----------------------------------------------------------------------------- small vector maths
def _unit(v: np.ndarray) -> np.ndarray | None:
    n = float(np.sqrt(v @ v))
    return v / n if n > 1e-9 and np.isfinite(n) else None


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def frame_from_axes(y_axis: np.ndarray, x_hint: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Right-handed frame (3, 3) with columns x, y, z: y along ``y_axis``, x = ``x_hint`` made
    orthogonal to y, z = x cross y. Returns ``fallback`` when either vector is degenerate."""
    y = _unit(y_axis)
    if y is None:
        return fallback
    x = _unit(x_hint - (x_hint @ y) * y)
    if x is None:
        return fallback
    return np.stack([x, y, _cross(x, y)], axis=1)


def _kabsch(local: np.ndarray, world: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Rotation R and translation t with world ~ t + R @ local (least squares), or None if
    the points are (nearly) collinear. local, world: (N, 3), N >= 3."""
    lc, wc = local.mean(axis=0), world.mean(axis=0)
    h = (local - lc).T @ (world - wc)
    u, s, vt = np.linalg.svd(h)
    if s[1] < 1e-6 * max(s[0], 1e-12):
        return None
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, wc - r @ lc


def _gh_offset(upper_arm_trunk: np.ndarray, sgn: float, stature_m: float) -> np.ndarray:
    """Glenohumeral centre minus acromion marker in the trunk frame (3,), metres.

    upper_arm_trunk: (3,) acromion -> elbow in the trunk frame; sgn: +1 right, -1 left.
    """
    u = _unit(upper_arm_trunk)
    elevation = 0.0 if u is None else float(np.degrees(np.arccos(np.clip(-u[1], -1.0, 1.0))))
    tilt = np.radians(_GH_TILT_DEG - 0.5 * np.clip(elevation - 30.0, 0.0, 120.0))
    d = _GH_DISTANCE_H * stature_m
    return np.array([-sgn * d * np.sin(tilt), -d * np.cos(tilt), _GH_FORWARD_H * stature_m])


# ----------------------------------------------------------------------------- proportions
class ProportionLearner:
    """Running medians of the body measures over the last ``window`` measured frames.

    A measure is sampled only in frames where all its markers are MEASURED (never estimated),
    and the median ignores occasional mislabelled frames.
    """

    def __init__(self, index: Mapping[str, int], window: int = 600, refresh_every: int = 15) -> None:
        self._ix = index
        self._values = {k: deque(maxlen=window) for k in _STATURE_RATIOS} | {"hip_width_m": deque(maxlen=window)}
        self._refresh_every = refresh_every
        self._updates = 0
        self._frames = 0
        self._current = Proportions.default()

    @property
    def proportions(self) -> Proportions:
        return self._current

    def update(self, positions_m: np.ndarray, measured: np.ndarray) -> None:
        """positions_m: (M, 3) float64; measured: (M,) bool, the marker was MEASURED."""
        ix = self._ix

        def ok(*roles: str) -> bool:
            return all(role in ix and measured[ix[role]] for role in roles)

        def p(role: str) -> np.ndarray:
            return positions_m[ix[role]]

        added = False
        if ok("left_shoulder", "right_shoulder"):
            self._values["shoulder_width_m"].append(float(np.linalg.norm(p("right_shoulder") - p("left_shoulder"))))
            added = True
        if ok("left_hip", "right_hip"):
            self._values["hip_width_m"].append(float(np.linalg.norm(p("right_hip") - p("left_hip"))))
            added = True
        if ok("trunk_upper", "left_hip", "right_hip"):
            mid_hips = 0.5 * (p("left_hip") + p("right_hip"))
            self._values["trunk_height_m"].append(float(np.linalg.norm(p("trunk_upper") - mid_hips)))
            added = True
        for s in SIDES:
            if ok(f"{s}_shoulder", f"{s}_elbow_lateral", f"{s}_elbow_medial"):
                e = 0.5 * (p(f"{s}_elbow_lateral") + p(f"{s}_elbow_medial"))
                self._values["upper_arm_m"].append(float(np.linalg.norm(e - p(f"{s}_shoulder"))))
                added = True
            if ok(f"{s}_elbow_lateral", f"{s}_elbow_medial", f"{s}_wrist_radial", f"{s}_wrist_ulnar"):
                e = 0.5 * (p(f"{s}_elbow_lateral") + p(f"{s}_elbow_medial"))
                w = 0.5 * (p(f"{s}_wrist_radial") + p(f"{s}_wrist_ulnar"))
                self._values["forearm_m"].append(float(np.linalg.norm(w - e)))
                added = True
        if not added:
            return
        self._frames += 1
        self._updates += 1
        # Early on every frame counts; later a refresh every few frames is plenty (medians move slowly).
        if self._frames <= 30 or self._updates >= self._refresh_every:
            self._updates = 0
            self._current = self._compute()

    def _compute(self) -> Proportions:
        med = {k: float(np.median(v)) for k, v in self._values.items() if len(v)}
        estimates = [med[k] / r for k, r in _STATURE_RATIOS.items() if k in med]
        stature = float(np.clip(np.median(estimates), *_STATURE_LIMITS_M)) if estimates else DEFAULT_STATURE_M
        d = Proportions.default(stature)
        return Proportions(
            shoulder_width_m=med.get("shoulder_width_m", d.shoulder_width_m),
            hip_width_m=med.get("hip_width_m", d.hip_width_m),
            trunk_height_m=med.get("trunk_height_m", d.trunk_height_m),
            upper_arm_m=med.get("upper_arm_m", d.upper_arm_m),
            forearm_m=med.get("forearm_m", d.forearm_m),
            stature_m=stature,
            n_frames=self._frames,
        )


# ----------------------------------------------------------------------------- skeleton
class SkeletonTracker:
    """Per-frame markers -> :class:`SkeletonPose`, remembering hidden markers and proportions.

    Args:
        marker_names: the marker set's names (``MarkerSet.names``), in the order of the arrays
            passed to :meth:`update`.
        roles: role -> marker name (``MarkerSet.roles``); None: the ``upper_limb_seated`` names.
        learn_window: number of measured frames the proportion medians run over.

    Raises:
        tracking.angles.MissingMarkersError: no marker plays any of the avatar's roles.
    """

    def __init__(self, marker_names: Sequence[str], *, roles: Mapping[str, str] | None = None,
                 learn_window: int = 600) -> None:
        names = tuple(marker_names)
        self._roles = dict(DEFAULT_ROLES if roles is None else roles)
        position = {n: i for i, n in enumerate(names)}
        self._names = names
        # role -> marker index; a role without a marker is a marker never seen
        self._ix = {role: position[n] for role, n in self._roles.items() if n in position}
        if not self._ix:
            raise MissingMarkersError(
                f"the avatar's marker set ({', '.join(names) or 'no markers'}) has no marker for any role: "
                "name them under 'roles:' in its YAML (docs/INTERFACES.md)")
        self._learner = ProportionLearner(self._ix, window=learn_window)
        self._window = learn_window
        self._trunk_r = np.eye(3)
        self._pelvis_r = np.eye(3)
        self._trunk_o: np.ndarray | None = None  # world position of MB's frame origin
        self._local: dict[str, np.ndarray] = {}  # marker -> last position in its parent frame
        self._ua_frames = {s: np.eye(3) for s in SIDES}
        self._fa_frames = {s: np.eye(3) for s in SIDES}

    @property
    def proportions(self) -> Proportions:
        return self._learner.proportions

    def reset(self) -> None:
        """Forget remembered marker positions and learned proportions (a new patient)."""
        self.__init__(self._names, roles=self._roles, learn_window=self._window)

    # ------------------------------------------------------------------ helpers
    def _default_local_trunk(self, role: str, stature_m: float) -> np.ndarray:
        """Default position of ``role``'s marker relative to MB in the trunk frame (metres)."""
        right = not role.startswith("left_")
        key = role if right else "right_" + role.removeprefix("left_")
        v = np.array(_DEFAULT_LAYOUT_H[key], float) * stature_m
        if not right:
            v[0] = -v[0]
        return v

    def _trunk_frame(self, p: np.ndarray, finite: np.ndarray, stature_m: float) -> None:
        """Update the trunk frame (rotation, origin at MB) from whatever trunk markers exist."""
        ix = self._ix
        have = {n: n in ix and bool(finite[ix[n]]) for n in _TRUNK_MARKERS}
        if have["trunk_upper"] and have["trunk_lower"] and have["left_hip"] and have["right_hip"]:
            self._trunk_r = frame_from_axes(p[ix["trunk_upper"]] - p[ix["trunk_lower"]],
                                            p[ix["right_hip"]] - p[ix["left_hip"]], self._trunk_r)
            self._trunk_o = p[ix["trunk_upper"]].copy()
            return
        # Rigid fit of the remembered (or default) trunk-frame positions of the visible ones.
        names = [n for n in _TRUNK_MARKERS if have[n]]
        local = np.array([self._local.get(n, self._default_local_trunk(n, stature_m)) for n in names]).reshape(-1, 3)
        world = p[[ix[n] for n in names]].reshape(-1, 3)
        fit = _kabsch(local, world) if len(names) >= 3 else None
        if fit is not None:
            self._trunk_r, self._trunk_o = fit
        elif names and self._trunk_o is not None:
            self._trunk_o = np.mean(world - local @ self._trunk_r.T, axis=0)
        elif names:  # first sight of the patient with too few trunk markers: keep upright
            self._trunk_o = np.mean(world - local, axis=0)

    def _fill(self, name: str, p: np.ndarray, finite: np.ndarray, origin: np.ndarray, rot: np.ndarray,
              stature_m: float, default_world: np.ndarray) -> np.ndarray:
        """Role ``name``'s marker position: measured/estimated if finite (remembered in the parent
        frame ``origin + rot @ local``), else the remembered one, else ``default_world``."""
        i = self._ix.get(name)
        if i is not None and finite[i]:
            self._local[name] = rot.T @ (p[i] - origin)
            return p[i]
        if name in self._local:
            return origin + rot @ self._local[name]
        return default_world

    # ------------------------------------------------------------------ update
    def update(self, positions_m: np.ndarray, status: np.ndarray) -> SkeletonPose:
        """One frame of markers -> the pose.

        Args:
            positions_m: (M, 3) float64 marker positions, world metres, NaN where lost.
            status: (M,) uint8 :class:`MarkerStatus` per marker.

        Returns:
            The pose; segments whose markers are missing keep their last pose (state LOST).
        """
        p = np.asarray(positions_m, dtype=np.float64)
        st = np.asarray(status)
        m = len(self._names)
        if p.shape != (m, 3) or st.shape != (m,):
            raise ValueError(f"positions_m must be ({m}, 3) and status ({m},), got {p.shape} and {st.shape}")
        finite = np.isfinite(p).all(axis=1) & (st != MarkerStatus.LOST)
        self._learner.update(p, finite & (st == MarkerStatus.MEASURED))
        props = self._learner.proportions
        h = props.stature_m

        self._trunk_frame(p, finite, h)
        if self._trunk_o is None:  # nothing seen yet: an upright default patient at the origin
            self._trunk_o = np.array([0.0, 1.0, 0.0])
        rt, o = self._trunk_r, self._trunk_o
        q: dict[str, np.ndarray] = {}
        for n in _TRUNK_MARKERS:
            q[n] = self._fill(n, p, finite, o, rt, h, o + rt @ self._default_local_trunk(n, h))

        joints: dict[str, np.ndarray] = {}
        frames: dict[str, np.ndarray] = {"trunk": rt}
        # Pelvis: the ASIS line, upright (the seated pelvis barely tilts; the trunk frame carries the lean).
        asis_mid = 0.5 * (q["left_hip"] + q["right_hip"])
        w = float(np.linalg.norm(q["right_hip"] - q["left_hip"]))
        across = q["right_hip"] - q["left_hip"]
        x = _unit(across)
        up = np.array([0.0, 1.0, 0.0])
        rp = self._pelvis_r if x is None else frame_from_axes(up - x[1] * x, across, self._pelvis_r)
        self._pelvis_r = rp
        frames["pelvis"] = rp
        for side, sgn in SIDE_SIGN.items():
            joints[f"{side}_hip"] = asis_mid + rp @ np.array([sgn * 0.36 * w, -0.30 * w, 0.19 * w])
        joints["pelvis"] = 0.5 * (joints["right_hip"] + joints["left_hip"])
        joints["sternum"] = q["trunk_upper"]
        joints["neck"] = q["trunk_upper"] + rt @ (np.array(_NECK_FROM_MB_H) * h)
        joints["head"] = q["trunk_upper"] + rt @ (np.array(_HEAD_FROM_MB_H) * h)

        for side, sgn in SIDE_SIGN.items():
            acromion = q[f"{side}_shoulder"]
            lat, med, rad, uln = (f"{side}_{part}" for part in ("elbow_lateral", "elbow_medial", "wrist_radial", "wrist_ulnar"))
            dflt = {n: o + rt @ self._default_local_trunk(n, h) for n in (lat, med, rad, uln)}
            e1 = self._fill(lat, p, finite, acromion, rt, h, dflt[lat])
            e2 = self._fill(med, p, finite, acromion, rt, h, dflt[med])
            elbow = 0.5 * (e1 + e2)
            gh = acromion + rt @ _gh_offset(rt.T @ (elbow - acromion), sgn, h)
            # Upper arm: along shoulder -> elbow, x from the medial to the lateral epicondyle.
            rua = frame_from_axes(gh - elbow, e1 - e2, self._ua_frames[side])
            self._ua_frames[side] = rua
            w1 = self._fill(rad, p, finite, elbow, rua, h, dflt[rad])
            w2 = self._fill(uln, p, finite, elbow, rua, h, dflt[uln])
            wrist = 0.5 * (w1 + w2)
            rfa = frame_from_axes(elbow - wrist, w1 - w2, self._fa_frames[side])
            self._fa_frames[side] = rfa
            frames[f"{side}_upper_arm"] = rua
            frames[f"{side}_forearm"] = rfa
            joints[f"{side}_acromion"] = acromion
            joints[f"{side}_shoulder"] = gh
            joints[f"{side}_elbow"] = elbow
            joints[f"{side}_wrist"] = wrist
            joints[f"{side}_hand"] = wrist - _HAND_CENTRE_FROM_WRIST_H * h * rfa[:, 1]

        state = np.empty(len(SEGMENTS), np.uint8)
        for k, seg in enumerate(SEGMENTS):
            idx = [self._ix[n] for n in _SEGMENT_MARKERS[seg] if n in self._ix]
            if len(idx) < len(_SEGMENT_MARKERS[seg]) or not finite[idx].all():
                state[k] = MarkerStatus.LOST
            elif (st[idx] == MarkerStatus.ESTIMATED).any():
                state[k] = MarkerStatus.ESTIMATED
            else:
                state[k] = MarkerStatus.MEASURED
        return SkeletonPose(
            joints_m=np.array([joints[j] for j in JOINTS]),
            frames=np.array([frames[s] for s in SEGMENTS]),
            state=state,
            proportions=props,
        )
