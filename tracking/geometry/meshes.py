"""Unit triangle meshes for the simulated studio and the game's avatar (pure numpy, no GL).

Every mesh is a pair ``(vertices, triangles)``: float32 vertex attributes and an (F, 3) int32
index array whose triangles wind counter-clockwise seen from outside (outward normals by the
right-hand rule), the convention the renderer's back-face culling relies on.
"""

from __future__ import annotations

import functools

import numpy as np


def _frozen(a: np.ndarray) -> np.ndarray:
    """Cached meshes are shared: make them read-only."""
    a.setflags(write=False)
    return a


def _orient_outward(vertices: np.ndarray, triangles: np.ndarray, centre_of: np.ndarray) -> np.ndarray:
    """Swap the winding of triangles whose right-hand normal points towards ``centre_of``.

    Args:
        vertices: (V, 3) positions.
        triangles: (F, 3) int indices.
        centre_of: (F, 3) for each triangle a point inside the solid it bounds.
    Returns:
        (F, 3) int32 triangles, all wound outward.
    """
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    inward = np.einsum("ij,ij->i", normal, (a + b + c) / 3.0 - centre_of) < 0
    out = triangles.copy()
    out[inward] = out[inward][:, [0, 2, 1]]
    return out.astype(np.int32)


@functools.lru_cache(maxsize=8)
def icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere, slightly inflated so that its silhouette has the sphere's mean radius.

    An inscribed polyhedron is smaller than its sphere; scaling the vertices by
    2 / (1 + mean face-centre distance) makes the polygonal outline straddle the true circle,
    so rendered areas and centroids of small spheres stay unbiased.

    Args:
        subdivisions: 0 gives the icosahedron (20 faces); each level multiplies faces by 4.
    Returns:
        vertices: (V, 3) float32 positions; a vertex's direction is also its normal.
        triangles: (20 * 4**subdivisions, 3) int32 indices, outward winding.
    """
    g = (1.0 + 5.0**0.5) / 2.0
    verts = [
        (-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0),
        (0, -1, g), (0, 1, g), (0, -1, -g), (0, 1, -g),
        (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1),
    ]
    faces = [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11),
        (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
        (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
        (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ]
    v = [np.asarray(p, float) / np.linalg.norm(p) for p in verts]
    for _ in range(subdivisions):
        midpoint: dict[tuple[int, int], int] = {}

        def mid(i: int, j: int) -> int:
            key = (min(i, j), max(i, j))
            if key not in midpoint:
                m = v[i] + v[j]
                v.append(m / np.linalg.norm(m))
                midpoint[key] = len(v) - 1
            return midpoint[key]

        new_faces = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    vertices = np.array(v)
    tris = np.array(faces, dtype=np.int64)
    tris = _orient_outward(vertices, tris, np.zeros((len(tris), 3)))
    face_centre_dist = np.linalg.norm(vertices[tris].mean(axis=1), axis=1).mean()
    vertices *= 2.0 / (1.0 + face_centre_dist)
    return _frozen(vertices.astype(np.float32)), _frozen(tris)


@functools.lru_cache(maxsize=4)
def cone_band(segments: int = 48) -> tuple[np.ndarray, np.ndarray]:
    """The side band of a (tapered) capsule: two rings of ``segments`` vertices.

    The renderer places ring ``t`` (0 at p0, 1 at p1) on the sphere of radius r_t around p_t,
    along the cone's outward normal, so the band meets its two end spheres tangentially.

    Returns:
        vertices: (2 * segments, 3) float32 rows (cos(theta), sin(theta), t).
        triangles: (2 * segments, 3) int32 indices, outward winding for a right-handed
            (u, v, axis) basis with radial direction cos(theta) u + sin(theta) v.
    """
    theta = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    vertices = np.vstack([np.hstack([ring, np.zeros((segments, 1))]), np.hstack([ring, np.ones((segments, 1))])])
    i = np.arange(segments)
    j = (i + 1) % segments
    a, b, c, d = i, j, j + segments, i + segments
    tris = np.vstack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    # Check winding on the reference cylinder (u = x, v = y, axis = z).
    ref = np.hstack([vertices[:, :2], vertices[:, 2:]])
    centre = np.hstack([np.zeros((len(tris), 2)), ref[tris][:, :, 2].mean(axis=1, keepdims=True)])
    tris = _orient_outward(ref, tris, centre)
    return _frozen(vertices.astype(np.float32)), _frozen(tris)


def box(centre_m, size_m) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box as 12 outward-wound triangles with flat normals.

    Args:
        centre_m: (3,) box centre, metres.
        size_m: (3,) full extents along x, y, z, metres.
    Returns:
        positions: (36, 3) float64 triangle-soup vertices.
        normals: (36, 3) float64 face normals.
    """
    c = np.asarray(centre_m, float)
    h = np.asarray(size_m, float) / 2.0
    positions, normals = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u, w = [k for k in range(3) if k != axis]
            corners = []
            for du, dw in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = c + n * h
                p[u] += du * h[u]
                p[w] += dw * h[w]
                corners.append(p)
            quad = [corners[0], corners[1], corners[2], corners[0], corners[2], corners[3]]
            tri_n = np.cross(quad[1] - quad[0], quad[2] - quad[0])
            if tri_n @ n < 0:
                quad = [corners[0], corners[2], corners[1], corners[0], corners[3], corners[2]]
            positions += quad
            normals += [n] * 6
    return np.array(positions), np.array(normals)
