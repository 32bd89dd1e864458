"""Motions of the simulated patient: scripted keyframes and replays of real captures.

A :class:`Motion` maps time (seconds from its start) to a :class:`~tracking.sim.body.Pose`. Every
motion starts in the seed's reference pose and holds it for at least a second, because the
tracker identifies the markers there (docs/METHOD.md 5.2).

Motions are content YAML files in ``content/motions/`` (or a path), validated once at load:

- ``kind: scripted``: keyframes of clinical pose parameters (``t_s``, optional ``hold_s``),
  joined by minimum-jerk (default), cosine or linear interpolation. A keyframe is the reference
  pose with the keys it names overridden: arm direction as ``flexion_deg``/``abduction_deg``,
  ``plane_deg``/``elevation_deg``, ``reach`` (hand target) or ``elbow_at_side``, plus
  ``external_rotation_deg``, ``elbow_flexion_deg``, ``forearm_supination_deg``,
  ``shoulder_shrug_m``; ``right``, ``left`` or ``both`` arms; and ``trunk`` leans.
- ``kind: capture``: a C3D motion capture mapped to our landmarks and converted to poses
  (:mod:`tracking.sim.capture_replay`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pydantic

from content import content_path
from tracking.content_loader import StrictModel, available, load_model, load_yaml
from tracking.errors import ContentError, MotionError
from tracking.markerset import load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose, SIDES, reference_arm
from tracking.sim.motion_base import MIN_REFERENCE_HOLD_S, Motion, ease
from tracking.geometry.rotations import direction_from_clinical, direction_from_plane, swing_twist

log = logging.getLogger(__name__)

# ---------------------------------------------------------------------------------------------
# Interpolation


def slerp_unit(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """Great-circle interpolation between unit vectors (3,) a and b."""
    cos_t = float(np.clip(a @ b, -1.0, 1.0))
    theta = math.acos(cos_t)
    if theta < 1e-6:
        return a
    if theta > math.pi - 1e-3:  # opposite directions: no unique circle, go through the normalized chord
        v = (1.0 - w) * a + w * b
        n = np.linalg.norm(v)
        return v / n if n > 1e-9 else a
    s = math.sin(theta)
    return (math.sin((1.0 - w) * theta) * a + math.sin(w * theta) * b) / s


@dataclass(frozen=True, slots=True)
class ArmKey:
    """One arm at a keyframe, in interpolation coordinates (right-side convention).

    Attributes:
        direction: (3,) humerus unit vector shoulder -> elbow, trunk frame.
        external_rotation_deg: axial rotation about it (swing-twist, see body.swing_matrix).
        elbow_flexion_deg, forearm_supination_deg: degrees.
        shoulder_shrug_m: metres.
    """

    direction: np.ndarray
    external_rotation_deg: float
    elbow_flexion_deg: float
    forearm_supination_deg: float
    shoulder_shrug_m: float

    @classmethod
    def of(cls, arm: ArmPose) -> "ArmKey":
        d, er = swing_twist(arm.humerus_rot)
        return cls(d, er, arm.elbow_flexion_deg, arm.forearm_supination_deg, arm.shoulder_shrug_m)

    def arm(self) -> ArmPose:
        return ArmPose.from_direction(self.direction, self.external_rotation_deg, self.elbow_flexion_deg,
                                      self.forearm_supination_deg, self.shoulder_shrug_m)

    def towards(self, other: "ArmKey", w: float) -> "ArmKey":
        """Blend: direction along the great circle, the rest linearly."""
        lin = lambda a, b: a + (b - a) * w  # noqa: E731
        return ArmKey(
            slerp_unit(self.direction, other.direction, w),
            lin(self.external_rotation_deg, other.external_rotation_deg),
            lin(self.elbow_flexion_deg, other.elbow_flexion_deg),
            lin(self.forearm_supination_deg, other.forearm_supination_deg),
            lin(self.shoulder_shrug_m, other.shoulder_shrug_m),
        )


class ScriptedMotion(Motion):
    """Keyframed motion: holds and smooth transitions between clinical poses.

    Args:
        name: motion name.
        times_s: (K,) keyframe start times, strictly increasing, first 0.
        holds_s: (K,) how long each keyframe is held before moving on to the next.
        trunk_deg: (K, 3) trunk forward lean, lateral lean, axial rotation per keyframe.
        arms: per side ("right", "left"), K :class:`ArmKey` each.
        interpolation: "minimum_jerk", "cosine" or "linear".
        description: free text.
    """

    def __init__(self, name: str, times_s: np.ndarray, holds_s: np.ndarray, trunk_deg: np.ndarray,
                 arms: dict[str, list[ArmKey]], interpolation: str = "minimum_jerk", description: str = ""):
        self.name = name
        self.description = description
        self._t = np.asarray(times_s, dtype=np.float64)
        self._hold = np.asarray(holds_s, dtype=np.float64)
        self._trunk = np.asarray(trunk_deg, dtype=np.float64)
        self._arms = arms
        self._interp = interpolation
        self._poses = [self._pose(k, k, 0.0) for k in range(len(self._t))]
        self.duration_s = float(self._t[-1] + self._hold[-1])

    def _pose(self, k0: int, k1: int, w: float) -> Pose:
        trunk = self._trunk[k0] + (self._trunk[k1] - self._trunk[k0]) * w
        arms = {s: self._arms[s][k0].towards(self._arms[s][k1], w).arm() for s in SIDES}
        return Pose(float(trunk[0]), float(trunk[1]), float(trunk[2]), arms["right"], arms["left"])

    def pose_at(self, t_s: float) -> Pose:
        k = int(np.searchsorted(self._t, t_s, side="right")) - 1
        if k < 0:
            return self._poses[0]
        if k >= len(self._t) - 1:
            return self._poses[-1]
        start = self._t[k] + self._hold[k]
        if t_s <= start:
            return self._poses[k]
        w = float(ease((t_s - start) / (self._t[k + 1] - start), self._interp))
        return self._pose(k, k + 1, w)

    def keyframe_times_s(self) -> np.ndarray:
        """(K,) keyframe start times."""
        return self._t.copy()


# ---------------------------------------------------------------------------------------------
# Content schemas


class _ArmSpec(StrictModel):
    """One arm in a keyframe; anything left out keeps its reference-pose value."""

    flexion_deg: float | None = pydantic.Field(None, ge=-90, le=180, description="sagittal projection angle")
    abduction_deg: float | None = pydantic.Field(None, ge=-60, le=180, description="frontal projection angle")
    plane_deg: float | None = pydantic.Field(None, ge=-180, le=180, description="0 sideways, 90 forward")
    elevation_deg: float | None = pydantic.Field(None, ge=0, le=175, description="from hanging down")
    reach: tuple[float, float, float] | None = pydantic.Field(
        None, description="hand target [out, up, forward] from the shoulder, in arm lengths (upper arm + forearm)"
    )
    elbow_at_side: bool = pydantic.Field(False, description="adduct until the elbow touches the trunk")
    external_rotation_deg: float | None = pydantic.Field(None, ge=-100, le=110)
    elbow_flexion_deg: float | None = pydantic.Field(None, ge=0, le=150)
    forearm_supination_deg: float | None = pydantic.Field(None, ge=-100, le=100)
    shoulder_shrug_m: float | None = pydantic.Field(None, ge=-0.03, le=0.08)

    @pydantic.model_validator(mode="after")
    def _one_direction(self) -> "_ArmSpec":
        ways = [
            self.flexion_deg is not None or self.abduction_deg is not None,
            self.plane_deg is not None or self.elevation_deg is not None,
            self.reach is not None,
        ]
        if sum(ways) > 1:
            raise ValueError("give the arm direction one way: flexion/abduction, plane/elevation or reach")
        if (self.plane_deg is None) != (self.elevation_deg is None):
            raise ValueError("plane_deg and elevation_deg go together")
        if self.elbow_at_side and (ways[1] or ways[2] or self.abduction_deg is not None):
            raise ValueError("elbow_at_side sets the abduction itself: give at most flexion_deg with it")
        if self.reach is not None:
            if self.elbow_flexion_deg is not None:
                raise ValueError("reach sets the elbow flexion itself: leave out elbow_flexion_deg")
            if not 0.25 <= float(np.linalg.norm(self.reach)) <= 1.0:
                raise ValueError("reach must be 0.25..1.0 arm lengths from the shoulder")
        return self


class _TrunkSpec(StrictModel):
    forward_lean_deg: float = pydantic.Field(0.0, ge=-30, le=60)
    lateral_lean_deg: float = pydantic.Field(0.0, ge=-40, le=40, description="+ towards the patient's right")
    axial_rotation_deg: float = pydantic.Field(0.0, ge=-60, le=60, description="+ chest turns to the patient's left")


class _KeyframeSpec(StrictModel):
    t_s: float = pydantic.Field(ge=0, description="when the keyframe pose is reached, seconds")
    hold_s: float = pydantic.Field(0.0, ge=0, description="how long it is held before moving on")
    trunk: _TrunkSpec | None = None
    right: _ArmSpec | None = None
    left: _ArmSpec | None = None
    both: _ArmSpec | None = pydantic.Field(None, description="the same numbers for both arms (mirrored)")

    @pydantic.model_validator(mode="after")
    def _both_alone(self) -> "_KeyframeSpec":
        if self.both is not None and (self.right is not None or self.left is not None):
            raise ValueError("give 'both' or 'right'/'left', not both")
        return self

    @property
    def is_reference(self) -> bool:
        return self.trunk is None and self.right is None and self.left is None and self.both is None


class _ScriptedSpec(StrictModel):
    kind: Literal["scripted"]
    description: str = ""
    interpolation: Literal["minimum_jerk", "cosine", "linear"] = "minimum_jerk"
    keyframes: list[_KeyframeSpec] = pydantic.Field(min_length=1)

    @pydantic.model_validator(mode="after")
    def _timeline(self) -> "_ScriptedSpec":
        first = self.keyframes[0]
        if first.t_s != 0 or not first.is_reference or first.hold_s < MIN_REFERENCE_HOLD_S:
            raise ValueError(
                f"the first keyframe must be the reference pose at t_s 0 (no other keys) held for "
                f"hold_s >= {MIN_REFERENCE_HOLD_S:g} s: the tracker identifies the markers there"
            )
        for a, b in zip(self.keyframes, self.keyframes[1:]):
            if b.t_s <= a.t_s + a.hold_s:
                raise ValueError(f"keyframe at t_s {b.t_s:g} must come after the previous one and its hold "
                                 f"(t_s {a.t_s:g} + hold_s {a.hold_s:g})")
        return self


# ---------------------------------------------------------------------------------------------
# Scripted motions from content


def _reach_arm(model: BodyModel, target: tuple[float, float, float], er_default: float, sup: float,
               shrug: float) -> ArmKey:
    """Two-link inverse kinematics: the wrist on ``target`` [out, up, forward] (arm lengths from GH).

    The elbow hangs as low as the target allows (elbow-down swivel, slightly outward).
    """
    d = model.dims
    lu, lf = d.upper_arm_m, d.forearm_m
    t = np.array([target[0], target[1], -target[2]]) * (lu + lf)
    dist = float(np.clip(np.linalg.norm(t), abs(lu - lf) + 1e-3, 0.985 * (lu + lf)))
    t_hat = t / np.linalg.norm(t)
    t = t_hat * dist
    elbow = math.pi - math.acos(np.clip((lu * lu + lf * lf - dist * dist) / (2 * lu * lf), -1.0, 1.0))
    alpha = math.acos(np.clip((lu * lu + dist * dist - lf * lf) / (2 * lu * dist), -1.0, 1.0))
    pref = np.array([0.3, -1.0, 0.0])
    n = pref - (pref @ t_hat) * t_hat
    if np.linalg.norm(n) < 1e-6:
        n = np.array([1.0, 0.0, 0.0]) - t_hat[0] * t_hat
    n /= np.linalg.norm(n)
    u = math.cos(alpha) * t_hat + math.sin(alpha) * n
    f = t - lu * u
    f_perp = f - (f @ u) * u
    if np.linalg.norm(f_perp) < 1e-6 * lf:
        er = er_default
    else:
        z_h = -f_perp / np.linalg.norm(f_perp)
        y_h = -u
        rot = np.stack([np.cross(y_h, z_h), y_h, z_h], axis=1)
        er = swing_twist(rot)[1]
    return ArmKey(u, er, math.degrees(elbow), sup, shrug)


def _arm_key(spec: _ArmSpec | None, model: BodyModel, trunk: _TrunkSpec | None, side: str) -> ArmKey:
    ref = ArmKey.of(reference_arm())
    if spec is None:
        return ref
    er = ref.external_rotation_deg if spec.external_rotation_deg is None else spec.external_rotation_deg
    elbow = ref.elbow_flexion_deg if spec.elbow_flexion_deg is None else spec.elbow_flexion_deg
    sup = ref.forearm_supination_deg if spec.forearm_supination_deg is None else spec.forearm_supination_deg
    shrug = ref.shoulder_shrug_m if spec.shoulder_shrug_m is None else spec.shoulder_shrug_m
    if spec.reach is not None:
        return _reach_arm(model, spec.reach, er, sup, shrug)
    if spec.plane_deg is not None:
        direction = direction_from_plane(spec.plane_deg, spec.elevation_deg)
    elif spec.elbow_at_side:
        flexion = spec.flexion_deg or 0.0
        t = trunk or _TrunkSpec()
        probe = Pose(t.forward_lean_deg, t.lateral_lean_deg, t.axial_rotation_deg).with_arm(
            side, ArmPose.clinical(flexion, 0.0, er, elbow, sup, shrug))
        direction = direction_from_clinical(flexion, model.elbow_at_side_abduction_deg(probe, side))
    elif spec.flexion_deg is not None or spec.abduction_deg is not None:
        direction = direction_from_clinical(spec.flexion_deg or 0.0, spec.abduction_deg or 0.0)
    else:
        direction = ref.direction
    return ArmKey(direction, er, elbow, sup, shrug)


def scripted_motion(spec: _ScriptedSpec, name: str, dims: BodyDimensions) -> ScriptedMotion:
    """Resolve a validated scripted spec for one body (reach and elbow_at_side depend on it)."""
    model = BodyModel(dims, load_markerset())
    trunk, arms = [], {s: [] for s in SIDES}
    for kf in spec.keyframes:
        t = kf.trunk or _TrunkSpec()
        trunk.append((t.forward_lean_deg, t.lateral_lean_deg, t.axial_rotation_deg))
        for side in SIDES:
            arms[side].append(_arm_key(kf.both if kf.both is not None else getattr(kf, side), model, kf.trunk, side))
    return ScriptedMotion(
        name,
        np.array([kf.t_s for kf in spec.keyframes]),
        np.array([kf.hold_s for kf in spec.keyframes]),
        np.array(trunk),
        arms,
        spec.interpolation,
        spec.description,
    )


# ---------------------------------------------------------------------------------------------
# Loading


def available_motions() -> list[str]:
    """Names of the built-in motions."""
    return available("motions")


def _resolve(name_or_path: str | Path) -> Path:
    text = str(name_or_path)
    if text.lower().endswith((".yaml", ".yml", ".c3d")) or "/" in text or "\\" in text:
        path = Path(text)
        if not path.is_file():
            raise MotionError(f"{path}: no such motion file; give an existing .yaml (or .c3d) or one of {available_motions()}")
        return path
    path = content_path("motions", f"{text}.yaml")
    if not path.is_file():
        raise MotionError(f"unknown motion {text!r}: choose one of {available_motions()} or give a motion .yaml path")
    return path


def load_motion(name_or_path: str | Path, dims: BodyDimensions) -> Motion:
    """A built-in motion by name, a motion YAML file, or a C3D whose landmark mapping is known.

    Args:
        name_or_path: e.g. ``"right_external_rotation"``, ``"my_motion.yaml"``, ``"capture.c3d"``.
        dims: the body that will perform it (reach targets, elbow contact and capture replays are
            solved for this body).

    Raises:
        MotionError: unknown name, missing file, C3D without a known mapping or missing landmarks.
        ContentError: a malformed motion YAML (the message names the file and key).
    """
    path = _resolve(name_or_path)
    if path.suffix.lower() == ".c3d":
        # lazy: the replay pulls in ezc3d and scipy.interpolate: only for a capture
        from tracking.sim.capture_replay import replay_c3d

        motion: Motion = replay_c3d(path, dims)
    else:
        data = load_yaml(path)
        kind = data.get("kind") if isinstance(data, dict) else None
        if kind == "scripted":
            motion = scripted_motion(load_model(path, _ScriptedSpec), path.stem, dims)
        elif kind == "capture":
            # lazy: the replay pulls in ezc3d and scipy.interpolate: only for a capture
            from tracking.sim.capture_replay import CaptureSpec, capture_motion

            motion = capture_motion(load_model(path, CaptureSpec), path, dims)
        else:
            raise ContentError(f"{path}: kind: must be 'scripted' or 'capture' (got {kind!r})")
    log.info("motion %s: %.1f s for a %.2f m %s", motion.name, motion.duration_s, dims.stature_m, dims.sex)
    return motion
