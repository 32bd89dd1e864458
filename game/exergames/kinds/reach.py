"""Reach for the stars: the hand touches targets in front of the patient.

A target is a shoulder elevation in a plane between the sagittal (flexion, 0 degrees) and the
frontal (abduction, 90 degrees) plane with the elbow a little bent; it is collected by holding the
wrist centre inside its sphere. The mouse moves the hand on a vertical plane through the target.
"""

from __future__ import annotations

import numpy as np

from game.exergames.kinds import Aim, Framing, GameKind, register
from game.exergames.targets import Target, elbow_at_side_hand_m, plane_limit_deg, reach_hand_m
from game.gfx.view3d import intersect_plane, pointer_ray


class Reach(GameKind):
    name = "reach"
    rom_keys = ("sagittal", "frontal")
    needs_elbow = True
    logged_angles = ("shoulder_flexion", "shoulder_abduction", "shoulder_elevation", "elbow_flexion")
    size_step = 0.01
    # from the hips to a hand raised above the head, turned towards the active side so that
    # forward reaches show their depth
    framing = Framing(25.0, 10.0, 0.80, up_m=0.10, forward_m=0.12)

    def check(self, spec) -> None:
        if any(not 0 <= p <= 90 for p in spec.planes_deg):
            raise ValueError("planes_deg must lie in 0..90")

    def size_words(self, size: float) -> str:
        return f"{size * 100:.0f} cm"

    def place(self, limits, low_fraction, top_fraction, rng, *, direction, planes_deg, elbow_range_deg):
        fraction = float(rng.uniform(low_fraction, top_fraction))
        plane = float(rng.choice(np.asarray(planes_deg, dtype=np.float64)))
        limit = plane_limit_deg(limits, plane)
        lo, hi = elbow_range_deg
        elbow = float(min(rng.uniform(lo, hi), limits.elbow_deg))
        return Target(fraction * limit, limit, fraction, plane, elbow)

    def hand_m(self, target, frame) -> np.ndarray:
        return reach_hand_m(frame, target.value_deg, target.plane_deg, target.elbow_deg)

    def value(self, reading, target) -> float:
        """The hand's distance (m) from the target."""
        return float(np.linalg.norm(reading.hand_m - target.hand_m)) if target is not None else float("nan")

    def inside(self, reading, target) -> bool:
        return bool(np.linalg.norm(reading.hand_m - target.hand_m) <= target.size)

    def solid(self, target, frame):
        return target.hand_m, np.eye(3) * target.size * 0.7

    def ring_m(self, target) -> float:
        return target.size

    def aim(self, aim: Aim, x_px: float, y_px: float):
        origin, direction = pointer_ray(x_px, y_px, aim.view_proj, aim.view)
        anchor = aim.target_hand_m if aim.target_hand_m is not None else elbow_at_side_hand_m(aim.frame, 0.0)
        hit = intersect_plane(origin, direction, anchor, aim.frame.trunk[:, 2])
        return (tuple(float(x) for x in hit) if hit is not None else None), None


register(Reach())
