"""The interactive simulated patient: a hand target, forearm rotation and trunk lean -> a pose.

The game turns the mouse and keys into a ``PatientInput`` (hand target in the world, forearm
rotation, trunk leans, which arm); :class:`InteractivePatient` turns the input into a body
:class:`~tracking.sim.body.Pose` once per frame, as a person would follow it:

- the hand (the wrist centre) moves towards the target at most ``hand_speed_m_s`` (2 m/s),
  speeding up and braking at most ``hand_accel_m_s2`` (a hand does not start at full speed, and
  the tracker predicts from the last velocity), stopping on the target; the forearm turns and
  the trunk leans at bounded rates, so a jump of the mouse never teleports a marker and tracking
  is not broken by it;
- the arm angles come from an analytic two-bone inverse kinematics (:func:`solve_arm`): the
  shoulder (glenohumeral centre) of the body model, the upper-arm and forearm lengths of
  :class:`~tracking.sim.body.BodyDimensions`, the elbow swivelled as low and as far out as the
  target allows (the natural way to hold an arm); a target out of reach is replaced by the
  nearest reachable point on the line from the shoulder, and the elbow bends at most
  ``MAX_ELBOW_FLEXION_DEG``;
- the other arm keeps its pose.

The studio renders the pose and the tracker measures the images: nothing here reaches the
tracker. Pure numpy on the body model: no GL, processes or files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from tracking.sim.body import ArmPose, BodyModel, Pose, reference_pose
from tracking.geometry.rotations import swing_twist

#: Largest elbow flexion the solver uses (a normal active range ends near 145 degrees).
MAX_ELBOW_FLEXION_DEG = 145.0
#: The arm never straightens completely (a fully straight elbow makes the swivel undefined).
MAX_REACH_FRACTION = 0.985
#: Where the elbow points when the target leaves it free: down and a little out (right-side
#: convention, trunk frame).
ELBOW_PREFERENCE = np.array([0.3, -1.0, 0.0])
_MIRROR = np.array([-1.0, 1.0, 1.0])


@dataclass(frozen=True, slots=True)
class PatientLimits:
    """How fast and how far the interactive patient moves.

    Attributes:
        hand_speed_m_s: largest speed of the active hand.
        hand_accel_m_s2: largest acceleration (and braking) of the active hand.
        forearm_speed_deg_s: largest forearm rotation speed.
        lean_speed_deg_s: largest trunk lean speed.
        forearm_range_deg: (pronation, supination) limits of the forearm rotation.
        forward_lean_range_deg: (back, forward) limits of the trunk's forward lean.
        lateral_lean_range_deg: (left, right) limits of the trunk's lateral lean.
    """

    hand_speed_m_s: float = 2.0
    hand_accel_m_s2: float = 5.0
    forearm_speed_deg_s: float = 180.0
    lean_speed_deg_s: float = 90.0
    forearm_range_deg: tuple[float, float] = (-90.0, 90.0)
    forward_lean_range_deg: tuple[float, float] = (-20.0, 45.0)
    lateral_lean_range_deg: tuple[float, float] = (-30.0, 30.0)


@dataclass(frozen=True, slots=True)
class ArmSolution:
    """What :func:`solve_arm` found.

    Attributes:
        arm: the arm pose (right-side convention, as :class:`Pose` stores it).
        wrist_m: (3,) world position the wrist centre reaches.
        reachable: the target itself was reachable (else ``wrist_m`` is the nearest reachable point).
    """

    arm: ArmPose
    wrist_m: np.ndarray
    reachable: bool


def _trunk_offset(model: BodyModel, pose: Pose, side: str) -> tuple[np.ndarray, np.ndarray]:
    """(rotation, offset) with ``world = rotation @ local + offset`` for the trunk of ``pose``.

    ``local`` is the upright trunk's frame (the body model's arm coordinates, both sides); the
    offset comes from one point seen both ways, through the body model's public kinematics.
    """
    rot = model.trunk_rotation(pose)
    upright = Pose(right=pose.right, left=pose.left)
    gh_local = model.joint_centres_m(upright, side)["gh"]
    gh_world = model.joint_centres_m(pose, side)["gh"]
    return rot, gh_world - rot @ gh_local


def _two_bone(t: np.ndarray, lu: float, lf: float) -> tuple[np.ndarray, float, float, bool]:
    """Humerus direction, elbow flexion and external rotation that put the wrist at ``t``.

    Args:
        t: (3,) target from the shoulder (GH), right-side trunk frame, metres.
        lu, lf: upper-arm and forearm lengths.

    Returns:
        (direction (3,), elbow_flexion_deg, external_rotation_deg or NaN when undefined, reachable).
    """
    dist = float(np.linalg.norm(t))
    min_interior = math.radians(180.0 - MAX_ELBOW_FLEXION_DEG)
    d_min = math.sqrt(lu * lu + lf * lf - 2.0 * lu * lf * math.cos(min_interior))
    d_max = MAX_REACH_FRACTION * (lu + lf)
    t_hat = t / dist if dist > 1e-9 else np.array([0.0, -1.0, 0.0])
    reachable = d_min <= dist <= d_max
    dist = min(max(dist, d_min), d_max)
    t = t_hat * dist
    cos_int = (lu * lu + lf * lf - dist * dist) / (2.0 * lu * lf)
    elbow_deg = 180.0 - math.degrees(math.acos(max(-1.0, min(1.0, cos_int))))
    alpha = math.acos(max(-1.0, min(1.0, (lu * lu + dist * dist - lf * lf) / (2.0 * lu * dist))))
    n = ELBOW_PREFERENCE - (ELBOW_PREFERENCE @ t_hat) * t_hat
    if np.linalg.norm(n) < 1e-6:  # target straight along the preference: any swivel; take lateral
        n = np.array([1.0, 0.0, 0.0]) - t_hat[0] * t_hat
    n = n / np.linalg.norm(n)
    u = math.cos(alpha) * t_hat + math.sin(alpha) * n
    f = t - lu * u
    f_perp = f - (f @ u) * u
    if np.linalg.norm(f_perp) < 1e-6 * lf:
        return u, elbow_deg, math.nan, reachable
    z_h = -f_perp / np.linalg.norm(f_perp)
    y_h = -u
    rot = np.stack([np.cross(y_h, z_h), y_h, z_h], axis=1)
    return u, elbow_deg, swing_twist(rot)[1], reachable


def solve_arm(model: BodyModel, pose: Pose, side: str, wrist_target_m: np.ndarray,
              forearm_supination_deg: float, *, iterations: int = 3) -> ArmSolution:
    """The arm of ``side`` with its wrist centre on a world target, the trunk as in ``pose``.

    The shoulder rises with the arm's elevation (the body model's shoulder rhythm), which moves
    the shoulder the solution starts from; a few fixed-point iterations settle it (the rise is a
    few centimetres and smooth, so three are plenty for millimetres).

    Args:
        model: the body.
        pose: the current pose (its trunk and the arm's shoulder shrug are kept).
        side: "right" or "left".
        wrist_target_m: (3,) world metres.
        forearm_supination_deg: forearm rotation of the result.
        iterations: shoulder-rise iterations.
    """
    dims = model.dims
    arm0 = pose.arm(side)
    rot, offset = _trunk_offset(model, pose, side)
    local = rot.T @ (np.asarray(wrist_target_m, dtype=np.float64) - offset)
    if side == "left":
        local = local * _MIRROR
    elevation = arm0.elevation_deg
    er_keep = arm0.external_rotation_deg
    for _ in range(max(1, iterations)):
        gh = model.shoulder_local_m(elevation, arm0.shoulder_shrug_m)[0]
        u, elbow_deg, er, reachable = _two_bone(local - gh, dims.upper_arm_m, dims.forearm_m)
        elevation = math.degrees(math.acos(max(-1.0, min(1.0, -float(u[1])))))
    arm = ArmPose.from_direction(u, er_keep if math.isnan(er) else er, elbow_deg, forearm_supination_deg,
                                 arm0.shoulder_shrug_m)
    solved = pose.with_arm(side, arm)
    return ArmSolution(arm, model.joint_centres_m(solved, side)["wrist"], reachable)


def _approach(current: float, target: float, max_step: float) -> float:
    return current + max(-max_step, min(max_step, target - current))


def hand_step(position: np.ndarray, velocity: np.ndarray, target: np.ndarray, dt_s: float, max_speed: float,
              max_accel: float) -> tuple[np.ndarray, np.ndarray]:
    """One step of a hand going to ``target`` with bounded speed and acceleration.

    The wanted velocity points at the target with the speed from which the hand can still brake
    to a stop on it (about ``sqrt(2 a d)``, at most ``max_speed``); the velocity turns towards it by at
    most ``max_accel * dt_s``. The hand lands on the target when the step would pass it.

    Args:
        position, velocity, target: (3,) metres, metres per second (world).
        dt_s: step, seconds.
        max_speed, max_accel: limits, m/s and m/s^2.

    Returns:
        (new position, new velocity).
    """
    to_target = target - position
    dist = float(np.linalg.norm(to_target))
    if dist < 1e-9:
        return target.copy(), np.zeros(3)
    # brake in time: the speed from which braking by max_accel * dt_s per step stops within the
    # distance left (v^2 / 2a + v dt / 2 = d for the stepped motion)
    speed = min(max_speed, max_accel * (math.sqrt(dt_s * dt_s / 4.0 + 2.0 * dist / max_accel) - dt_s / 2.0))
    wanted = to_target / dist * speed
    dv = wanted - velocity
    dv_norm = float(np.linalg.norm(dv))
    if dv_norm > max_accel * dt_s:
        dv *= max_accel * dt_s / dv_norm
    velocity = velocity + dv
    step = velocity * dt_s
    if float(step @ to_target) >= dist * dist:  # would pass the target: stop on it
        return target.copy(), np.zeros(3)
    return position + step, velocity


class InteractivePatient:
    """The simulated patient following a ``PatientInput``, one frame at a time.

    Args:
        model: the body.
        limits: speeds and ranges.

    ``step(input, dt_s)`` returns the pose of the next frame; :meth:`take_reference_pose` puts
    the patient in the seed's reference pose at once (what a patient does when the tracker asks
    to identify the markers: the tracker is not tracking then, so the jump breaks nothing).
    """

    def __init__(self, model: BodyModel, limits: PatientLimits = PatientLimits()) -> None:
        self.model = model
        self.limits = limits
        self.pose = reference_pose()
        self._hand_velocity = {side: np.zeros(3) for side in ("right", "left")}

    def take_reference_pose(self) -> Pose:
        self.pose = reference_pose()
        for v in self._hand_velocity.values():
            v[:] = 0.0
        return self.pose

    def wrist_m(self, side: str) -> np.ndarray:
        """(3,) world position of a wrist centre in the current pose."""
        return self.model.joint_centres_m(self.pose, side)["wrist"]

    def step(self, value, dt_s: float) -> Pose:
        """Move towards ``value`` (a ``tracking.live.PatientInput``) for ``dt_s`` seconds.

        Args:
            value: side, hand target (world metres or None), forearm rotation, trunk leans.
            dt_s: frame interval, seconds (simulated time).
        """
        lim = self.limits
        side = value.side if value.side in ("right", "left") else "right"
        old = self.pose
        fwd = _approach(old.trunk_forward_lean_deg, float(np.clip(value.trunk_forward_lean_deg, *lim.forward_lean_range_deg)),
                        lim.lean_speed_deg_s * dt_s)
        lat = _approach(old.trunk_lateral_lean_deg, float(np.clip(value.trunk_lateral_lean_deg, *lim.lateral_lean_range_deg)),
                        lim.lean_speed_deg_s * dt_s)
        arm = old.arm(side)
        sup = _approach(arm.forearm_supination_deg, float(np.clip(value.forearm_rotation_deg, *lim.forearm_range_deg)),
                        lim.forearm_speed_deg_s * dt_s)
        hand_now = self.model.joint_centres_m(old, side)["wrist"]
        pose = replace(old, trunk_forward_lean_deg=fwd, trunk_lateral_lean_deg=lat)
        for other in ("right", "left"):
            if other != side:
                self._hand_velocity[other][:] = 0.0  # only the active hand moves
        if value.hand_target_m is None:
            self._hand_velocity[side][:] = 0.0
            pose = pose.with_arm(side, replace(arm, forearm_supination_deg=sup))
        else:
            target = np.asarray(value.hand_target_m, dtype=np.float64)
            goal, velocity = hand_step(hand_now, self._hand_velocity[side], target, dt_s, lim.hand_speed_m_s,
                                       lim.hand_accel_m_s2)
            solution = solve_arm(self.model, pose, side, goal, sup)
            if not solution.reachable:  # held back by the arm's reach: no speed builds up against it
                velocity = (solution.wrist_m - hand_now) / dt_s if dt_s > 0 else np.zeros(3)
            self._hand_velocity[side] = velocity
            pose = pose.with_arm(side, solution.arm)
        self.pose = pose
        return pose
