"""Replaying a real motion capture (C3D) on the simulated patient.

The capture's landmarks are mapped to our 14-marker set, turned into joint angles of our
:class:`~tracking.sim.body.Pose`, and those angles drive OUR body model: the real motion's angles
are reproduced, not the subject's segment lengths. Conversion per capture frame (all vectors in
the capture's marker trunk frame of ``docs/JOINT_ANGLES.md``, the left arm mirrored into the
right-side convention):

- trunk: forward and lateral lean of ``MB - MP`` in the world, and (when both acromions are
  marked) the axial rotation of the acromion line against the ASIS line, relative to the
  capture's first frame (or its mean, for a walk);
- shoulder girdle: the acromion's rise along the trunk axis relative to the same zero, minus our
  model's automatic scapulohumeral rhythm -> ``shoulder_shrug_m``;
- humerus direction: chosen so that our model's marker vector acromion -> epicondyle centre is
  parallel to the capture's (solved through our GH joint, which lies below the acromion);
- humerus axial rotation: from the epicondyle axis when the elbow is nearly straight and from the
  plane of the forearm when it is flexed (blended between 10 and 30 degrees of elbow flexion, so
  that from 30 degrees on, where docs/JOINT_ANGLES.md defines external rotation, it is reproduced);
- elbow flexion: the angle at which our model's marker-based elbow angle equals the capture's
  ``angle(E - S, W - E)``;
- forearm supination: the capture's marker reading (styloid axis against the epicondyle axis
  about the forearm), which our model reproduces exactly.

Short landmark gaps are filled by cubic interpolation in time (the filled frames are kept in
:attr:`CaptureReplay.filled`); the motion starts with a hold in the reference pose, blends into
the capture's first frame, plays it and blends back.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Literal

import ezc3d
import numpy as np
import pydantic
from scipy.interpolate import CubicSpline

from content import content_path
from tracking.content_loader import StrictModel, load_model, load_yaml
from tracking.errors import MotionError
from tracking.markerset import load_markerset
from tracking.sim.body import SIDES, ArmPose, BodyDimensions, BodyModel, Pose, reference_pose
from tracking.geometry.rotations import slerp_rotation
from tracking.sim.motion_base import MIN_REFERENCE_HOLD_S, Motion, ease

log = logging.getLogger(__name__)

TRUNK_MARKERS = ("MB", "MP", "MLH", "MRH")
ARM_PARTS = ("S", "E1", "E2", "W1", "W2")
_AXIS = Literal["+X", "-X", "+Y", "-Y", "+Z", "-Z"]


def arm_markers(side: str) -> tuple[str, ...]:
    """Our marker names of one arm, e.g. ('MRS', 'MRE1', ...)."""
    s = "R" if side == "right" else "L"
    return tuple(f"M{s}{p}" for p in ARM_PARTS)


# ---------------------------------------------------------------------------------------------
# Content schema


class _AxesSpec(StrictModel):
    """Which capture axis points up, forward (where the subject faces) and to the subject's right."""

    up: _AXIS
    forward: _AXIS
    right: _AXIS


class _MirrorSpec(StrictModel):
    delay_s: float = pydantic.Field(ge=0, le=10, description="the left arm repeats the right arm this much later")


class _LeadInSpec(StrictModel):
    hold_s: float = pydantic.Field(1.0, ge=MIN_REFERENCE_HOLD_S, le=10, description="reference pose held first")
    blend_s: float = pydantic.Field(1.5, ge=0.2, le=10, description="smooth blend into the capture's first frame")


class CaptureSpec(StrictModel):
    """A C3D capture replayed on the simulated patient (``kind: capture``)."""

    kind: Literal["capture"]
    description: str = ""
    file: str = pydantic.Field(description="C3D in content/captures/, or a path relative to this YAML")
    axes: _AxesSpec
    landmarks: dict[str, str] = pydantic.Field(description="our marker name -> the capture's point label")
    remove_progression: bool = pydantic.Field(False, description="subtract the pelvis' horizontal travel (walks)")
    trunk_zero: Literal["first_frame", "mean"] = pydantic.Field(
        "first_frame", description="capture posture that maps to our upright trunk and relaxed shoulders")
    mirror_left: _MirrorSpec | None = None
    max_gap_s: float = pydantic.Field(0.5, gt=0, le=3, description="longest landmark gap that is filled")
    lead_in: _LeadInSpec = _LeadInSpec()
    lead_out_s: float = pydantic.Field(1.5, ge=0, le=10, description="blend back to the reference pose at the end")

    @pydantic.model_validator(mode="after")
    def _check(self) -> "CaptureSpec":
        ours = set(load_markerset().names)
        unknown = sorted(set(self.landmarks) - ours)
        if unknown:
            raise ValueError(f"landmarks: {unknown} are not markers of upper_limb_seated ({sorted(ours)})")
        needed = set(TRUNK_MARKERS) | set(arm_markers("right"))
        if self.mirror_left is None:
            needed |= set(arm_markers("left"))
        elif set(arm_markers("left")) & set(self.landmarks):
            raise ValueError("mirror_left replaces the left arm: leave the left-arm landmarks out")
        missing = sorted(needed - set(self.landmarks))
        if missing:
            raise ValueError(f"landmarks: map {missing} too")
        names = [self.axes.up[1], self.axes.forward[1], self.axes.right[1]]
        if len(set(names)) != 3:
            raise ValueError("axes: up, forward and right must be three different axes")
        return self


def axes_matrix(axes: _AxesSpec) -> np.ndarray:
    """(3, 3) rotation taking capture coordinates to ours (x right, y up, z backwards)."""
    def vec(a: str) -> np.ndarray:
        v = np.zeros(3)
        v["XYZ".index(a[1])] = 1.0 if a[0] == "+" else -1.0
        return v

    m = np.stack([vec(axes.right), vec(axes.up), -vec(axes.forward)])
    if np.linalg.det(m) < 0:
        raise MotionError(f"axes up {axes.up}, forward {axes.forward}, right {axes.right} are left-handed: "
                          "one of them has the wrong sign")
    return m


# ---------------------------------------------------------------------------------------------
# C3D reading and gap filling


def read_c3d_points(path: Path, labels: dict[str, str], source: str = "") -> tuple[float, np.ndarray]:
    """Read mapped points from a C3D.

    Args:
        path: the C3D file.
        labels: our marker name -> the file's point label. A label also matches a file label
            with a ``subject:`` prefix (``STER`` matches ``Daphnee:STER``).
        source: what asks for them (named in errors).

    Returns:
        rate_hz: point rate.
        points_m: (F, L, 3) float64 metres in the file's axes, NaN where missing, L in the order
            of ``labels``.

    Raises:
        MotionError: unreadable file or labels not in it (one line naming them).
    """
    try:
        c3d = ezc3d.c3d(str(path))
    except Exception as exc:  # ezc3d raises plain RuntimeError/IOError on bad files
        raise MotionError(f"{path.name}: cannot read the C3D ({exc})") from None
    params = c3d["parameters"]["POINT"]
    file_labels = [str(x).strip() for x in params["LABELS"]["value"]]
    short = {}
    for i, lab in enumerate(file_labels):
        short.setdefault(lab.rsplit(":", 1)[-1], []).append(i)
    index, missing = [], []
    for ours, theirs in labels.items():
        if theirs in file_labels:
            index.append(file_labels.index(theirs))
        elif len(short.get(theirs, [])) == 1:
            index.append(short[theirs][0])
        else:
            missing.append(f"{theirs} ({ours})")
    if missing:
        who = f" needed by {source}" if source else ""
        raise MotionError(f"{path.name}: missing point labels {', '.join(missing)}{who}; "
                          f"map them to labels the file has")
    units = str(params["UNITS"]["value"][0]).strip().lower() if params.get("UNITS", {}).get("value") else "mm"
    scale = {"mm": 1e-3, "m": 1.0, "cm": 1e-2}.get(units, 1e-3)
    rate = float(np.asarray(params["RATE"]["value"]).reshape(-1)[0])
    pts = np.asarray(c3d["data"]["points"][:3], dtype=np.float64)[:, index, :]  # (3, L, F)
    pts = np.transpose(pts, (2, 1, 0)) * scale
    pts[np.all(pts == 0.0, axis=2)] = np.nan  # some writers store missing points as zeros
    return rate, pts


def fill_gaps(points: np.ndarray, rate_hz: float, max_gap_s: float, names: list[str], source: str
              ) -> tuple[np.ndarray, np.ndarray]:
    """Fill missing samples of each landmark by cubic interpolation in time.

    Args:
        points: (F, L, 3) with NaN where missing.
        rate_hz: sample rate.
        max_gap_s: longest gap filled; edge gaps are held at the nearest sample.
        names: (L,) names for errors.
        source: the file, for errors.

    Returns:
        filled: (F, L, 3) without NaN.
        was_filled: (F, L) bool, True where a sample was filled.
    """
    out = points.copy()
    missing = ~np.isfinite(points).all(axis=2)
    t = np.arange(points.shape[0]) / rate_hz
    max_gap = int(round(max_gap_s * rate_hz))
    for j in np.flatnonzero(missing.any(axis=0)):
        bad = missing[:, j]
        good = np.flatnonzero(~bad)
        if good.size < 4:
            raise MotionError(f"{source}: landmark {names[j]} is missing in almost every frame")
        # Lengths of the runs of missing samples.
        edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        longest = int((ends - starts).max())
        if longest > max_gap:
            k = int(np.argmax(ends - starts))
            raise MotionError(f"{source}: landmark {names[j]} is missing for {longest / rate_hz:.2f} s from "
                              f"{starts[k] / rate_hz:.2f} s, longer than max_gap_s {max_gap_s:g}")
        spline = CubicSpline(t[good], points[good, j], axis=0)
        inner = bad & (t >= t[good[0]]) & (t <= t[good[-1]])
        out[inner, j] = spline(t[inner])
        out[: good[0], j] = points[good[0], j]
        out[good[-1] + 1:, j] = points[good[-1], j]
        log.info("%s: filled %d missing frames of %s", source, int(bad.sum()), names[j])
    return out, missing


# ---------------------------------------------------------------------------------------------
# Landmarks -> pose parameters


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unsigned angle (deg) between vectors (..., 3)."""
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), _dot(a, b)))


def _signed_angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Signed angle (deg) from a to b about the unit axis (right-hand rule), vectors (..., 3)."""
    return np.degrees(np.arctan2(_dot(np.cross(a, b), axis), _dot(a, b)))


def _wrap180(a: np.ndarray) -> np.ndarray:
    return (a + 180.0) % 360.0 - 180.0


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def marker_trunk_frame(mb: np.ndarray, mp: np.ndarray, lh: np.ndarray, rh: np.ndarray) -> np.ndarray:
    """(..., 3, 3) trunk frame of docs/JOINT_ANGLES.md; columns x_T (right), y_T (up), z_T (back)."""
    y = _unit(mb - mp)
    h = rh - lh
    x = _unit(h - _dot(h, y)[..., None] * y)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


class CaptureAngles:
    """Marker-based angles of a capture (docs/JOINT_ANGLES.md definitions), per frame.

    Attributes:
        trunk_forward_lean_deg, trunk_lateral_lean_deg: (F,).
        elbow_flexion_deg: per side, (F,) ``angle(E - S, W - E)``.
        forearm_supination_deg: per side, (F,).
    """

    def __init__(self, markers: dict[str, np.ndarray]):
        frame = marker_trunk_frame(markers["MB"], markers["MP"], markers["MLH"], markers["MRH"])
        y = frame[..., 1]
        self.trunk_forward_lean_deg = np.degrees(np.arctan2(-y[:, 2], y[:, 1]))
        self.trunk_lateral_lean_deg = np.degrees(np.arctan2(y[:, 0], y[:, 1]))
        self.elbow_flexion_deg: dict[str, np.ndarray] = {}
        self.forearm_supination_deg: dict[str, np.ndarray] = {}
        for side in SIDES:
            names = arm_markers(side)
            if names[0] not in markers:
                continue
            s, e1, e2, w1, w2 = (markers[n] for n in names)
            e, w = (e1 + e2) / 2, (w1 + w2) / 2
            u, f = e - s, w - e
            self.elbow_flexion_deg[side] = _angle(u, f)
            fh = _unit(f) * (1.0 if side == "right" else -1.0)
            ep = (e2 - e1) - _dot(e2 - e1, fh)[:, None] * fh
            wp = (w2 - w1) - _dot(w2 - w1, fh)[:, None] * fh
            self.forearm_supination_deg[side] = _wrap180(90.0 + _signed_angle(ep, wp, fh))


def _arm_params(model: BodyModel, v: dict[str, np.ndarray], rise: np.ndarray, elbow_c: np.ndarray,
                sup_c: np.ndarray) -> dict[str, np.ndarray]:
    """Our arm parameters from capture vectors in OUR upright trunk coordinates (right convention).

    Args:
        model: our body.
        v: (F, 3) vectors: ``u`` acromion -> epicondyle centre, ``f`` forearm, ``epi`` medial ->
            lateral epicondyle.
        rise: (F,) acromion rise to reproduce (m), relative to the relaxed shoulder.
        elbow_c: (F,) capture marker elbow angle, degrees.
        sup_c: (F,) capture supination reading, degrees.
    """
    lu = model.dims.upper_arm_m
    vu = _unit(v["u"])
    elev = np.degrees(np.arccos(np.clip(-vu[:, 1], -1, 1)))
    for _ in range(5):  # elevation -> our shoulder geometry -> humerus direction -> elevation
        shrug = rise - model.girdle_rise_m(elev)
        gh, skin, normal = model.shoulder_local_m(elev, shrug)
        d = skin + model.markerset.radius_m * normal - gh  # GH -> acromion marker
        b = _dot(vu, d)
        lam = -b + np.sqrt(np.maximum(b * b - _dot(d, d) + lu * lu, 0.0))
        u = (d + lam[:, None] * vu) / lu
        u = _unit(u)
        elev = np.degrees(np.arccos(np.clip(-u[:, 1], -1, 1)))
    shrug = rise - model.girdle_rise_m(elev)
    # Humerus axial rotation: epicondyle axis (straight elbow) or forearm plane (flexed elbow).
    epi = v["epi"] - _dot(v["epi"], u)[:, None] * u
    x1 = _unit(epi)
    f_perp = v["f"] - _dot(v["f"], u)[:, None] * u
    n_f = np.linalg.norm(f_perp, axis=1)
    x2 = np.cross(u, f_perp / np.maximum(n_f, 1e-12)[:, None])
    w = _smoothstep((elbow_c - 10.0) / 20.0)[:, None] * (n_f > 1e-9)[:, None]
    x_h = _unit((1.0 - w) * x1 + w * x2)
    x_h = _unit(x_h - _dot(x_h, u)[:, None] * u)
    y_h = -u
    rot = np.stack([x_h, y_h, np.cross(x_h, y_h)], axis=-1)  # (F, 3, 3) columns
    # Elbow: our marker angle angle(v_u, f(theta)) must equal the capture's.
    vh = np.einsum("fji,fj->fi", rot, vu)
    fh = np.einsum("fji,fj->fi", rot, _unit(v["f"]))
    r = np.hypot(vh[:, 1], vh[:, 2])
    phi = np.arctan2(-vh[:, 2], -vh[:, 1])
    delta = np.arccos(np.clip(np.cos(np.radians(elbow_c)) / np.maximum(r, 1e-9), -1.0, 1.0))
    hinge = np.arctan2(-fh[:, 2], -fh[:, 1])
    cand = np.stack([phi + delta, phi - delta], axis=1)
    pick = np.argmin(np.abs(_wrap180(np.degrees(cand - hinge[:, None]))), axis=1)
    theta = np.degrees(cand[np.arange(len(pick)), pick])
    theta = np.clip(_wrap180(theta), 0.0, 165.0)
    return {"rot": rot, "elbow": theta, "sup": sup_c, "shrug": shrug}


class CaptureReplay(Motion):
    """A real capture driving our body: lead-in hold and blend, the capture, blend back.

    Attributes:
        name: motion name.
        duration_s: total length.
        rate_hz: capture rate.
        capture_start_s: when the capture's first frame is reached (after the lead-in).
        capture_duration_s: length of the capture itself.
        landmarks_m: (F, L, 3) capture landmarks in our world axes (metres, progression removed
            if asked), gaps filled; ``landmark_names`` (L,) our marker names.
        filled: (F, L) True where a landmark was missing and filled.
        angles: :class:`CaptureAngles` of the capture (the left arm's are absent if mirrored).
        mirror_delay_s: the left arm replays the right this much later, or None.
    """

    def __init__(self, name: str, model: BodyModel, spec: CaptureSpec, rate_hz: float, landmarks: np.ndarray,
                 filled: np.ndarray, names: list[str]):
        self.name = name
        self.rate_hz = rate_hz
        self.landmarks_m = landmarks
        self.filled = filled
        self.landmark_names = list(names)
        n = landmarks.shape[0]
        self.capture_duration_s = (n - 1) / rate_hz
        self._hold = spec.lead_in.hold_s
        self._blend = spec.lead_in.blend_s
        self._out = spec.lead_out_s
        self.capture_start_s = self._hold + self._blend
        self.mirror_delay_s = spec.mirror_left.delay_s if spec.mirror_left is not None else None
        delay = self.mirror_delay_s or 0.0
        self.duration_s = self.capture_start_s + self.capture_duration_s + self._out + delay
        m = {nm: landmarks[:, i] for i, nm in enumerate(names)}
        self.angles = CaptureAngles(m)
        self._ref = reference_pose()
        self._convert(model, m, spec)

    # ----------------------------------------------------------------- conversion
    def _convert(self, model: BodyModel, m: dict[str, np.ndarray], spec: CaptureSpec) -> None:
        frame = marker_trunk_frame(m["MB"], m["MP"], m["MLH"], m["MRH"])  # (F, 3, 3)
        zero = (lambda a: a[0]) if spec.trunk_zero == "first_frame" else (lambda a: np.mean(a, axis=0))
        fwd = self.angles.trunk_forward_lean_deg
        lat = self.angles.trunk_lateral_lean_deg
        if "MLS" in m:
            def heading(vec):
                return np.degrees(np.arctan2(-vec[:, 2], vec[:, 0]))
            axial = _wrap180(heading(m["MRS"] - m["MLS"]) - heading(m["MRH"] - m["MLH"]))
        else:
            axial = np.zeros(len(fwd))
        axial = axial - zero(axial)
        self._trunk = np.stack([fwd - zero(fwd), lat - zero(lat), axial], axis=1)
        # Capture thorax frame: the marker trunk frame turned by the axial rotation about y_T.
        a = np.radians(axial)
        c, s = np.cos(a), np.sin(a)
        x, y, z = frame[..., 0], frame[..., 1], frame[..., 2]
        thorax = np.stack([c[:, None] * x - s[:, None] * z, y, s[:, None] * x + c[:, None] * z], axis=-1)
        # Our model's marker trunk frame in its own trunk coordinates (upright reference).
        ours = model.markers_m(reference_pose())
        ix = model.markerset.index
        b_model = marker_trunk_frame(ours[ix("MB")], ours[ix("MP")], ours[ix("MLH")], ours[ix("MRH")])

        def local(vec: np.ndarray, mirror: bool) -> np.ndarray:
            comp = np.einsum("fji,fj->fi", thorax, vec)  # components in the capture thorax frame
            if mirror:
                comp = comp * np.array([-1.0, 1.0, 1.0])
            return comp @ b_model.T

        self._arms: dict[str, dict[str, np.ndarray]] = {}
        for side in SIDES:
            names = arm_markers(side)
            if names[0] not in m:
                continue
            sm, e1, e2, w1, w2 = (m[n] for n in names)
            e, w = (e1 + e2) / 2, (w1 + w2) / 2
            mirror = side == "left"
            height = np.einsum("fi,fi->f", sm - m["MB"], thorax[..., 1])
            elev0 = _angle(local(e - sm, mirror), np.array([0.0, -1.0, 0.0]))
            rise = height - zero(height) + model.girdle_rise_m(zero(elev0))
            v = {"u": local(e - sm, mirror), "f": local(w - e, mirror), "epi": local(e1 - e2, mirror)}
            self._arms[side] = _arm_params(model, v, rise, self.angles.elbow_flexion_deg[side],
                                           self.angles.forearm_supination_deg[side])

    # ----------------------------------------------------------------- playback
    def _capture_index(self, tau_s: float) -> tuple[int, float]:
        x = min(max(tau_s * self.rate_hz, 0.0), self.landmarks_m.shape[0] - 1.0)
        i = min(int(x), self.landmarks_m.shape[0] - 2)
        return i, x - i

    def _arm_at(self, side: str, tau_s: float) -> ArmPose:
        """The captured arm at capture time ``tau_s`` (clamped)."""
        a = self._arms[side]
        i, w = self._capture_index(tau_s)
        lin = lambda k: float(a[k][i] + (a[k][i + 1] - a[k][i]) * w)  # noqa: E731
        rot = slerp_rotation(a["rot"][i], a["rot"][i + 1], w)
        return ArmPose(rot, lin("shrug"), lin("elbow"), lin("sup"))

    def _trunk_at(self, tau_s: float) -> np.ndarray:
        i, w = self._capture_index(tau_s)
        return self._trunk[i] + (self._trunk[i + 1] - self._trunk[i]) * w

    def _blend_weight(self, t_s: float) -> tuple[float, float]:
        """(weight of the capture against the reference, capture time) at motion time t_s."""
        tau = t_s - self.capture_start_s
        if tau < 0:
            return float(ease((t_s - self._hold) / self._blend)), 0.0
        if tau <= self.capture_duration_s:
            return 1.0, tau
        if self._out <= 0:
            return 1.0, self.capture_duration_s
        return 1.0 - float(ease((tau - self.capture_duration_s) / self._out)), self.capture_duration_s

    @staticmethod
    def _mix_arm(ref: ArmPose, arm: ArmPose, w: float) -> ArmPose:
        if w >= 1.0:
            return arm
        if w <= 0.0:
            return ref
        lin = lambda a, b: a + (b - a) * w  # noqa: E731
        return ArmPose(slerp_rotation(ref.humerus_rot, arm.humerus_rot, w), lin(ref.shoulder_shrug_m, arm.shoulder_shrug_m),
                       lin(ref.elbow_flexion_deg, arm.elbow_flexion_deg),
                       lin(ref.forearm_supination_deg, arm.forearm_supination_deg))

    def _side_at(self, side: str, t_s: float) -> ArmPose:
        src = side
        if side == "left" and self.mirror_delay_s is not None:
            src, t_s = "right", t_s - self.mirror_delay_s
        w, tau = self._blend_weight(t_s)
        return self._mix_arm(self._ref.arm(side), self._arm_at(src, tau), w)

    def pose_at(self, t_s: float) -> Pose:
        t_s = min(max(t_s, 0.0), self.duration_s)
        w, tau = self._blend_weight(t_s)
        trunk = self._trunk_at(tau) * w
        return Pose(float(trunk[0]), float(trunk[1]), float(trunk[2]),
                    self._side_at("right", t_s), self._side_at("left", t_s))

    def capture_time_s(self, t_s: float) -> float | None:
        """Capture time shown at motion time ``t_s`` (right arm), or None outside the capture."""
        tau = t_s - self.capture_start_s
        return tau if 0.0 <= tau <= self.capture_duration_s else None


# ---------------------------------------------------------------------------------------------
# Loading


def _c3d_path(spec: CaptureSpec, yaml_path: Path) -> Path:
    p = Path(spec.file)
    for cand in ((yaml_path.parent / p) if not p.is_absolute() else p, content_path("captures", p.name)):
        if cand.is_file():
            return cand
    raise MotionError(f"{yaml_path}: file {spec.file!r} not found next to it or in content/captures/")


def capture_motion(spec: CaptureSpec, yaml_path: Path, dims: BodyDimensions, c3d_path: Path | None = None
                   ) -> CaptureReplay:
    """Build the replay of a validated capture spec on a body of ``dims``."""
    path = c3d_path or _c3d_path(spec, yaml_path)
    source = f"motion {yaml_path.stem}"
    names = list(spec.landmarks)
    rate, pts = read_c3d_points(path, spec.landmarks, source)
    pts = pts @ axes_matrix(spec.axes).T
    pts, filled = fill_gaps(pts, rate, spec.max_gap_s, [spec.landmarks[n] for n in names], path.name)
    if spec.remove_progression:
        pelvis = (pts[:, names.index("MLH")] + pts[:, names.index("MRH")]) / 2
        travel = pelvis - pelvis[0]
        travel[:, 1] = 0.0
        pts = pts - travel[:, None, :]
    model = BodyModel(dims, load_markerset())
    return CaptureReplay(yaml_path.stem, model, spec, rate, pts, filled, names)


def _bundled_specs() -> list[tuple[Path, CaptureSpec]]:
    out = []
    for p in sorted(content_path("motions").glob("*.yaml")):
        data = load_yaml(p)
        if isinstance(data, dict) and data.get("kind") == "capture":
            out.append((p, load_model(p, CaptureSpec)))
    return out


def replay_c3d(path: Path, dims: BodyDimensions) -> CaptureReplay:
    """Replay a C3D directly when a bundled capture motion's mapping fits it.

    The mapping of the bundled motion naming the same file is used first; otherwise the first
    bundled mapping whose labels are all in the file.
    """
    specs = _bundled_specs()
    same = [(p, s) for p, s in specs if Path(s.file).name == path.name]
    for yaml_path, spec in same + [x for x in specs if x not in same]:
        try:
            return capture_motion(spec, yaml_path, dims, c3d_path=path)
        except MotionError as exc:
            if "missing point labels" not in str(exc):
                raise
    raise MotionError(f"{path.name}: no known landmark mapping fits this C3D; write a motion YAML with "
                      "kind: capture mapping its labels (see content/motions/vicon_upper_limb.yaml)")
