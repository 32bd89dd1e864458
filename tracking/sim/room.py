"""A simple clinic room around the seated patient, as one static triangle mesh (pure numpy).

World frame (docs/INTERFACES.md): metres, +Y up, the patient sits at x = 0, z = 0 facing -Z.
The room spans x, z in [-3.5, 3.5] and y in [0, 2.8]: large enough for cameras 2-2.5 m from
the patient. The chair's seat top is at y = 0.45 m, centred on x = 0, z = 0, with its backrest
behind the patient (+Z).

Clutter colours avoid the marker colours (sRGB yellow 255,214,0, green 0,200,70, magenta
225,0,210). Three objects are deliberate near misses with low saturation, to exercise colour
gating: the olive plant (dull green), the khaki box (dull yellow) and the mauve towel (dull
magenta).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracking.geometry.meshes import box, icosphere

ROOM_HALF_WIDTH_M = 3.5
ROOM_HEIGHT_M = 2.8
SEAT_TOP_M = 0.45


@dataclass(frozen=True, slots=True)
class RoomMesh:
    """Static room geometry as a triangle soup (every 3 consecutive vertices form a triangle).

    Attributes:
        position_m: (N, 3) float32 vertex positions, world metres.
        normal: (N, 3) float32 unit outward normals.
        rgb: (N, 3) float32 sRGB colours in 0..1 (matte surfaces: the renderer bakes their
            diffuse lighting once).
    """

    position_m: np.ndarray
    normal: np.ndarray
    rgb: np.ndarray

    @property
    def n_triangles(self) -> int:
        return self.position_m.shape[0] // 3


class _Builder:
    def __init__(self) -> None:
        self.parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def box(self, centre_m, size_m, rgb255) -> None:
        pos, nrm = box(centre_m, size_m)
        self.parts.append((pos, nrm, np.asarray(rgb255, float) / 255.0))

    def ball(self, centre_m, radius_m: float, rgb255) -> None:
        vertices, tris = icosphere(2)
        unit = vertices[tris].reshape(-1, 3).astype(float)
        nrm = unit / np.linalg.norm(unit, axis=1, keepdims=True)
        self.parts.append((np.asarray(centre_m, float) + radius_m * unit, nrm, np.asarray(rgb255, float) / 255.0))

    def mesh(self) -> RoomMesh:
        pos = np.vstack([p for p, _, _ in self.parts]).astype(np.float32)
        nrm = np.vstack([n for _, n, _ in self.parts]).astype(np.float32)
        rgb = np.vstack([np.tile(c, (len(p), 1)) for p, _, c in self.parts]).astype(np.float32)
        return RoomMesh(pos, nrm, rgb)


def _chair(b: _Builder) -> None:
    seat_thickness = 0.05
    b.box((0.0, SEAT_TOP_M - seat_thickness / 2, 0.0), (0.46, seat_thickness, 0.46), (40, 60, 120))
    leg_h = SEAT_TOP_M - seat_thickness
    for sx in (-0.2, 0.2):
        for sz in (-0.2, 0.2):
            b.box((sx, leg_h / 2, sz), (0.035, leg_h, 0.035), (95, 95, 100))
    # Backrest behind the patient (+Z), on two posts; top at 0.9 m leaves the shoulders free.
    for sx in (-0.2, 0.2):
        b.box((sx, SEAT_TOP_M + 0.2, 0.215), (0.03, 0.4, 0.03), (95, 95, 100))
    b.box((0.0, 0.74, 0.235), (0.44, 0.3, 0.03), (40, 60, 120))


def _room_shell(b: _Builder, ceiling: bool) -> None:
    hw, h, t = ROOM_HALF_WIDTH_M, ROOM_HEIGHT_M, 0.1
    b.box((0.0, -t / 2, 0.0), (2 * hw + 2 * t, t, 2 * hw + 2 * t), (125, 122, 118))  # floor, grey linoleum
    if ceiling:
        b.box((0.0, h + t / 2, 0.0), (2 * hw + 2 * t, t, 2 * hw + 2 * t), (238, 238, 236))
    b.box((0.0, h / 2, -hw - t / 2), (2 * hw, h, t), (214, 210, 198))  # front wall (the patient faces it)
    b.box((0.0, h / 2, hw + t / 2), (2 * hw, h, t), (198, 204, 214))  # back wall, cool grey
    b.box((-hw - t / 2, h / 2, 0.0), (t, h, 2 * hw), (226, 223, 216))  # left/right walls, off-white
    b.box((hw + t / 2, h / 2, 0.0), (t, h, 2 * hw), (226, 223, 216))
    b.box((0.0, 0.05, -hw + 0.01), (2 * hw, 0.1, 0.02), (80, 80, 85))  # skirting boards
    b.box((0.0, 0.05, hw - 0.01), (2 * hw, 0.1, 0.02), (80, 80, 85))


def _clutter(b: _Builder) -> None:
    hw = ROOM_HALF_WIDTH_M
    # Door on the back wall, brown, with a grey handle.
    b.box((1.6, 1.0, hw - 0.02), (0.9, 2.0, 0.04), (115, 72, 40))
    b.box((1.25, 1.0, hw - 0.06), (0.12, 0.03, 0.05), (150, 150, 155))
    # Poster on the front wall: petrol frame (a low-saturation near-miss of the cyan markers),
    # white paper, red and blue bands.
    b.box((0.0, 1.65, -hw + 0.01), (0.9, 0.7, 0.02), (70, 118, 124))
    b.box((0.0, 1.65, -hw + 0.025), (0.78, 0.58, 0.01), (240, 240, 236))
    b.box((0.0, 1.78, -hw + 0.035), (0.6, 0.1, 0.01), (200, 35, 35))
    b.box((0.0, 1.55, -hw + 0.035), (0.6, 0.1, 0.01), (30, 70, 180))
    # Table front-left with a red box, a blue box and a mauve towel (low-saturation magenta).
    tx, tz, top = -2.2, -2.4, 0.75
    b.box((tx, top - 0.02, tz), (1.2, 0.04, 0.7), (125, 85, 50))
    for sx in (-0.55, 0.55):
        for sz in (-0.3, 0.3):
            b.box((tx + sx, (top - 0.04) / 2, tz + sz), (0.05, top - 0.04, 0.05), (70, 50, 35))
    b.box((tx - 0.3, top + 0.12, tz), (0.3, 0.24, 0.25), (205, 30, 30))
    b.box((tx + 0.15, top + 0.08, tz - 0.1), (0.25, 0.16, 0.3), (35, 60, 190))
    b.box((tx + 0.4, top + 0.015, tz + 0.15), (0.3, 0.03, 0.25), (165, 125, 160))
    # Boxes on the floor, front-right: orange and khaki (low-saturation yellow).
    b.box((2.4, 0.2, -2.5), (0.5, 0.4, 0.4), (230, 100, 20))
    b.box((2.45, 0.55, -2.5), (0.35, 0.3, 0.3), (180, 168, 125))
    # Slate-green cabinet on the right wall, white shelf unit on the left wall.
    b.box((hw - 0.25, 0.6, 0.8), (0.45, 1.2, 0.8), (72, 112, 108))
    b.box((-hw + 0.2, 0.9, 1.2), (0.35, 1.8, 0.9), (235, 235, 232))
    b.box((-hw + 0.2, 1.2, 1.2), (0.36, 0.03, 0.86), (150, 150, 150))
    # Plant in the back-left corner: terracotta pot, olive (low-saturation green) foliage.
    px, pz = -2.8, 2.8
    b.box((px, 0.2, pz), (0.35, 0.4, 0.35), (170, 90, 60))
    for dx, dy, dz, r in ((0.0, 0.75, 0.0, 0.28), (0.15, 0.95, 0.08, 0.2), (-0.12, 1.0, -0.05, 0.18), (0.05, 0.6, -0.15, 0.2)):
        b.ball((px + dx, dy, pz + dz), r, (88, 110, 64))
    # A brown exercise bench along the back wall, left of the door.
    b.box((-0.6, 0.22, hw - 0.5), (1.4, 0.44, 0.45), (100, 65, 45))


def build_room(ceiling: bool = True) -> RoomMesh:
    """The clinic room (walls, floor, optional ceiling, chair, clutter) as one static mesh."""
    b = _Builder()
    _room_shell(b, ceiling)
    _chair(b)
    _clutter(b)
    return b.mesh()
