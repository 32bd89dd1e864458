"""Geometric primitives of one simulated frame: what the body model hands to the renderer.

The renderer knows nothing of bodies: it draws spheres (markers, joints, head), tapered capsules
(limb segments) and ellipsoids (trunk, pelvis, thighs) in world metres (docs/INTERFACES.md frame:
+Y up, the patient faces -Z). Colours are linear-ish RGB in 0..1 (sRGB values / 255).
A sphere with ``marker_index >= 0`` is a marker; the renderer reports how many of its pixels are
visible in each camera so that the studio knows the ground-truth visibility.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class SceneFrame:
    """All primitives of one instant.

    Attributes:
        sphere_centre_m: (S, 3) float64 sphere centres, world metres.
        sphere_radius_m: (S,) float64 radii in metres.
        sphere_rgb: (S, 3) float32 colours in 0..1.
        sphere_marker_index: (S,) int32, index into the marker set, or -1 for a non-marker sphere.
        capsule_p0_m, capsule_p1_m: (C, 3) float64 segment end points, world metres.
        capsule_r0_m, capsule_r1_m: (C,) float64 radii at p0 and p1 (tapered capsule = cone + two
            end spheres).
        capsule_rgb: (C, 3) float32 colours in 0..1.
        ellipsoid_centre_m: (E, 3) float64 centres.
        ellipsoid_axes_m: (E, 3, 3) float64; column k is the k-th semi-axis vector in world metres
            (so the ellipsoid is centre + axes @ unit_sphere).
        ellipsoid_rgb: (E, 3) float32 colours in 0..1.
    """

    sphere_centre_m: np.ndarray
    sphere_radius_m: np.ndarray
    sphere_rgb: np.ndarray
    sphere_marker_index: np.ndarray
    capsule_p0_m: np.ndarray
    capsule_p1_m: np.ndarray
    capsule_r0_m: np.ndarray
    capsule_r1_m: np.ndarray
    capsule_rgb: np.ndarray
    ellipsoid_centre_m: np.ndarray
    ellipsoid_axes_m: np.ndarray
    ellipsoid_rgb: np.ndarray

    @property
    def n_markers(self) -> int:
        idx = self.sphere_marker_index
        return int(idx.max()) + 1 if idx.size and idx.max() >= 0 else 0

    @staticmethod
    def empty() -> "SceneFrame":
        z3 = np.zeros((0, 3))
        return SceneFrame(
            z3, np.zeros(0), np.zeros((0, 3), np.float32), np.zeros(0, np.int32),
            z3, z3, np.zeros(0), np.zeros(0), np.zeros((0, 3), np.float32),
            z3, np.zeros((0, 3, 3)), np.zeros((0, 3), np.float32),
        )
