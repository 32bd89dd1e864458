"""Where targets go: joint-angle space inside the measured range, then the hand's 3D position.

Pure numpy. A target is first chosen in joint-angle space (``docs/JOINT_ANGLES.md``
definitions), between ``comfort_fraction`` and the current top fraction of the patient's latest
measured maximum in that direction (:class:`RomLimits`), then mapped to the world position of the
wrist centre by the forward kinematics of the patient's own arm (:class:`ArmFrame`: the shoulder
marker, the trunk axes and the measured upper-arm and forearm lengths, the same points the joint
angles are computed from), so a target is reachable by construction within the range. Each game
kind (:mod:`game.exergames.kinds`) places its targets with these:

- reach: the upper arm at elevation ``theta`` in a plane ``psi`` degrees from the sagittal plane
  towards the frontal plane (``psi`` 0: pure flexion, 90: pure abduction); the elbow bent by
  ``elbow`` in the same plane, the forearm rising further (a natural reach). The range in a plane
  between the two is interpolated from the flexion and abduction maxima (``cos^2 / sin^2``).
- rotation: the elbow at the side bent 90 degrees, the forearm turned ``value`` degrees out
  (external rotation +) from pointing forward.
- forearm: the same hand position with the forearm forward; ``value`` is the rotation
  (supination +, pronation -) the patient turns to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tracking.errors import ContentError

SIDE_SIGN = {"right": 1.0, "left": -1.0}


@dataclass(frozen=True, slots=True)
class RomLimits:
    """The patient's maxima the targets are placed under (degrees, positive).

    Attributes:
        positive_deg, negative_deg: reach: sagittal (flexion) and frontal (abduction) maxima;
            rotation/forearm: the positive direction (external rotation, supination) and the negative
            one (internal rotation, pronation), each as a positive number.
        elbow_deg: elbow flexion maximum (reach).
        sources: per direction, where the value came from ("stored 2026-11-22" or "default").
    """

    positive_deg: float
    negative_deg: float
    elbow_deg: float = 145.0
    sources: tuple[tuple[str, str], ...] = ()


def rom_limits_from_rows(spec, rows, side: str) -> RomLimits:
    """The latest stored result of each ROM test the game names (``game.db.RomRow`` list, oldest first).

    A test without a stored result on ``side`` uses the game's cautious default (said in ``sources``).
    """
    latest = {}
    for r in rows:
        if r.side == side:
            latest[r.test] = r   # rows come oldest first: the last one wins
    keys = spec.game_kind.rom_keys
    values, sources = [], []
    bounds = [(k, spec.rom[k]) for k in keys] + ([("elbow", spec.elbow)] if spec.elbow is not None else [])
    for key, bound in bounds:
        row = latest.get(bound.test)
        if row is not None and math.isfinite(row.value_deg) and row.value_deg > 0:
            values.append(float(row.value_deg))
            sources.append((bound.test, f"stored {row.session_started_utc[:10]}"))
        else:
            values.append(bound.default_deg)
            sources.append((bound.test, "default"))
    elbow = values[2] if len(values) > 2 else 145.0
    return RomLimits(values[0], values[1], elbow, tuple(sources))


@dataclass(frozen=True, slots=True)
class ArmFrame:
    """The patient's arm geometry from the markers (world metres).

    Attributes:
        shoulder_m: (3,) the shoulder (acromion) marker, the origin of the upper arm in the angles.
        trunk: (3, 3) columns ``x_T`` (towards the patient's right), ``y_T`` (up the trunk), ``z_T``
            (backwards), docs/JOINT_ANGLES.md.
        upper_arm_m: shoulder marker -> elbow centre; forearm_m: elbow centre -> wrist centre.
        side: ``right`` or ``left``.
    """

    shoulder_m: np.ndarray
    trunk: np.ndarray
    upper_arm_m: float
    forearm_m: float
    side: str

    @property
    def out(self) -> np.ndarray:
        """(3,) lateral direction of this side (``+x_T`` right, ``-x_T`` left)."""
        return SIDE_SIGN[self.side] * self.trunk[:, 0]


def arm_frame_from_markers(positions_m: np.ndarray, names, side: str) -> ArmFrame | None:
    """The :class:`ArmFrame` of one sample's markers (None when a needed marker has no position).

    Args:
        positions_m: (M, 3) float64 marker positions, NaN where lost.
        names: the M marker names (``upper_limb_seated``).
        side: ``right`` or ``left``.
    """
    s = "R" if side == "right" else "L"
    idx = {n: i for i, n in enumerate(names)}
    need = ("MB", "MP", "MRH", "MLH", f"M{s}S", f"M{s}E1", f"M{s}E2", f"M{s}W1", f"M{s}W2")
    if any(n not in idx for n in need):
        raise ContentError(f"the exercise games need the markers {', '.join(need)} (marker set upper_limb_seated)")
    p = {n: np.asarray(positions_m[idx[n]], dtype=np.float64) for n in need}
    if not all(np.isfinite(v).all() for v in p.values()):
        return None
    y = p["MB"] - p["MP"]
    y /= np.linalg.norm(y)
    x = p["MRH"] - p["MLH"]
    x -= (x @ y) * y
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    elbow = (p[f"M{s}E1"] + p[f"M{s}E2"]) / 2.0
    wrist = (p[f"M{s}W1"] + p[f"M{s}W2"]) / 2.0
    return ArmFrame(p[f"M{s}S"], np.stack([x, y, z], axis=1), float(np.linalg.norm(elbow - p[f"M{s}S"])),
                    float(np.linalg.norm(wrist - elbow)), side)


# ----------------------------------------------------------------------------- forward kinematics
def elevation_direction(frame: ArmFrame, theta_deg: float, psi_deg: float) -> np.ndarray:
    """(3,) unit vector at elevation ``theta`` from hanging down, in the plane ``psi`` from sagittal."""
    t, p = math.radians(theta_deg), math.radians(psi_deg)
    down, forward = -frame.trunk[:, 1], -frame.trunk[:, 2]
    across = math.cos(p) * forward + math.sin(p) * frame.out
    return math.cos(t) * down + math.sin(t) * across


def reach_hand_m(frame: ArmFrame, theta_deg: float, psi_deg: float, elbow_deg: float) -> np.ndarray:
    """(3,) wrist centre with the upper arm at (``theta``, ``psi``) and the elbow bent ``elbow`` in that plane."""
    upper = elevation_direction(frame, theta_deg, psi_deg)
    fore = elevation_direction(frame, theta_deg + elbow_deg, psi_deg)
    return frame.shoulder_m + frame.upper_arm_m * upper + frame.forearm_m * fore


def elbow_at_side_hand_m(frame: ArmFrame, rotation_deg: float) -> np.ndarray:
    """(3,) wrist centre with the elbow at the side bent 90 and the forearm turned ``rotation`` out."""
    r = math.radians(rotation_deg)
    elbow = frame.shoulder_m - frame.upper_arm_m * frame.trunk[:, 1]
    fore = math.cos(r) * -frame.trunk[:, 2] + math.sin(r) * frame.out
    return elbow + frame.forearm_m * fore


def flexion_abduction_deg(direction: np.ndarray, frame: ArmFrame) -> tuple[float, float]:
    """The (flexion, abduction) the angles of docs/JOINT_ANGLES.md give an upper arm along ``direction``."""
    u = np.asarray(direction, dtype=np.float64)
    down, forward = -frame.trunk[:, 1], -frame.trunk[:, 2]
    return (math.degrees(math.atan2(u @ forward, u @ down)), math.degrees(math.atan2(u @ frame.out, u @ down)))


# ----------------------------------------------------------------------------- placement
@dataclass(frozen=True, slots=True)
class Target:
    """One target in joint-angle space.

    Attributes:
        value_deg: reach: the upper arm's elevation; rotation: external rotation (+ out, - in);
            forearm: supination (+) / pronation (-).
        limit_deg: the measured (or default) maximum in that direction (positive).
        fraction: ``|value_deg| / limit_deg``.
        plane_deg: reach: the elevation plane (0 sagittal .. 90 frontal); else 0.
        elbow_deg: reach: the elbow flexion of the target; else 90 (elbow at the side).
    """

    value_deg: float
    limit_deg: float
    fraction: float
    plane_deg: float = 0.0
    elbow_deg: float = 90.0


def plane_limit_deg(limits: RomLimits, plane_deg: float) -> float:
    """The elevation maximum in a plane between sagittal (flexion) and frontal (abduction)."""
    c = math.cos(math.radians(plane_deg)) ** 2
    return c * limits.positive_deg + (1.0 - c) * limits.negative_deg
