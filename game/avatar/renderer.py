"""The avatar drawn with moderngl: shaded solids, soft light, a floor with contact shadows.

:class:`AvatarRenderer` draws a :class:`SkeletonPose` (dressed by :func:`body_shapes`) into
whatever framebuffer is bound, with any view and projection; :func:`mirror_view` gives the view
a patient expects (the avatar faces them and moves like their mirror image). It needs an
OpenGL 3.3 core context and nothing of pygame, so the game's window and headless tests (EGL)
use it alike.

Geometry: the small ellipsoids (eyes, nose, hands, shoes, joints) and the capsules' end spheres
are ray-cast on instanced screen-space quads bounding their exact outline, as the simulator's
cameras draw them (two triangles each instead of 80 for an icosphere: llvmpipe pays per
triangle); the large ones (trunk, head, chair) are instanced 320-triangle icospheres, depth-tested
before shading; tapered capsules are an instanced band tangent to the two end spheres (the
simulator's band, ``tracking.geometry.meshes.cone_band``); end spheres hidden inside other solids are
not drawn. About 4.8k triangles in all (the floor's 544 among them).

Lighting, in linear RGB then encoded to sRGB (per pixel on the ray-cast ellipsoids, per vertex on
the meshes, whose colours are interpolated): a sky/ground hemisphere ambient, a warm
key light from above the viewer's left shoulder, a cool rim light from behind that outlines the
body against the background, and a little Blinn-Phong sheen. The lights are fixed relative to
the camera, so every view is lit from the front. The floor disc carries soft contact shadows
(blobs under the chair, the feet and the hands) and fades out at its edge into the background.

Segment states (:class:`tracking.marker_status.MarkerStatus` from the skeleton):
- MEASURED: the normal skin and clothes colours;
- ESTIMATED: tinted amber with a glowing amber outline (the tracker guessed these markers);
- LOST: desaturated grey and translucent (the segment shows its last known pose).
The looks are amounts 0..1 per segment, so a caller can fade them
(:class:`game.avatar.interpolate.LookFader`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import moderngl
import numpy as np

from game.avatar.interpolate import state_looks
from game.avatar.shapes import BodyShapes, body_shapes
from game.avatar.skeleton import SkeletonPose
from game.gfx.view3d import look_at, perspective  # noqa: F401  (re-exported)
from tracking.geometry.glsl import BAND_GLSL, OUTLINE_BOX_GLSL
from tracking.geometry.meshes import cone_band, icosphere



@dataclass(frozen=True, slots=True)
class AvatarStyle:
    """Colours (sRGB 0..1) and strengths of the avatar's look.

    Attributes:
        estimated_rgb: tint and outline of estimated segments.
        estimated_tint: how far an estimated segment's colour moves towards ``estimated_rgb``.
        lost_alpha: opacity of lost segments.
        background_top_rgb, background_bottom_rgb: the gradient of :meth:`AvatarRenderer.render_background`.
        background_gradient: draw that gradient; False clears to the mean colour instead (a
            full-screen pass less: ~1.5-2 ms per 1280x720 frame on llvmpipe).
        floor_rgb: the floor disc.
        floor_radius_m: its radius around the chair.
    """

    estimated_rgb: tuple[float, float, float] = (1.0, 0.66, 0.0)
    estimated_tint: float = 0.45
    lost_alpha: float = 0.38
    background_top_rgb: tuple[float, float, float] = (0.80, 0.87, 0.94)
    background_bottom_rgb: tuple[float, float, float] = (0.96, 0.95, 0.92)
    background_gradient: bool = True
    floor_rgb: tuple[float, float, float] = (0.90, 0.88, 0.84)
    floor_radius_m: float = 1.3


_TRANSLUCENT = 0.01  # lost-look amount above which a solid is drawn in the translucent pass


# ----------------------------------------------------------------------------- camera helpers
# look_at and perspective are game.gfx.view3d's (re-exported here for the avatar's callers)
def mirror_view(
    pose: SkeletonPose,
    aspect: float,
    *,
    yaw_deg: float = 0.0,
    pitch_deg: float = 12.0,
    fov_y_deg: float = 30.0,
    margin: float = 1.05,
    mirror: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """View and projection showing the whole seated avatar from the front, as in a mirror.

    The camera stands in front of the patient (along the pelvis's forward direction), turned by
    ``yaw_deg`` about the vertical (+ towards the patient's right), looking down by ``pitch_deg``,
    far enough for the body from the floor to a raised hand (about the stature) to fit with
    ``margin``. With ``mirror`` the image is flipped left-right, so the patient's right hand is on
    the right of the screen and moves like their reflection. The framing depends only on the
    pelvis and the stature, which barely move, so the camera stays still while the arms move.

    Returns:
        view: (4, 4) float64; proj: (4, 4) float64 (mirrored when ``mirror``).
    """
    h = pose.proportions.stature_m
    rp = pose.frame("pelvis")
    fwd = -rp[:, 2].copy()
    fwd[1] = 0.0
    fwd /= max(float(np.linalg.norm(fwd)), 1e-9)
    yaw = math.radians(yaw_deg)
    right = np.array([-fwd[2], 0.0, fwd[0]])  # fwd turned -90 degrees about +Y: the patient's right
    direction = math.cos(yaw) * fwd + math.sin(yaw) * right
    pelvis = pose.joint("pelvis")
    # From the floor (~0.36 H below the hip joints) to a hand raised straight up (~0.75 H above),
    # and sideways to a hand held out to the side (~0.58 H from the midline) on narrow screens.
    target = pelvis + np.array([0.0, 0.20 * h, 0.0])
    half_extent = max(0.56, 0.58 / aspect) * h * margin
    fov = math.radians(fov_y_deg)
    distance = half_extent / math.tan(fov / 2.0) + 0.2 * h
    pitch = math.radians(pitch_deg)
    eye = target + distance * (math.cos(pitch) * direction + math.sin(pitch) * np.array([0.0, 1.0, 0.0]))
    view = look_at(eye, target)
    proj = perspective(fov_y_deg, aspect, near_m=0.1, far_m=distance + 4.0 * h)
    if mirror:
        proj = proj @ np.diag([-1.0, 1.0, 1.0, 1.0])
    return view, proj


# ----------------------------------------------------------------------------- shaders
_LIGHTING = """
uniform vec3 u_eye;
uniform vec3 u_key_dir;   // towards the key light, world
uniform vec3 u_rim_dir;   // towards the rim light, world
uniform vec3 u_estimated_rgb;  // linear
uniform float u_estimated_tint;
uniform float u_lost_alpha;
const vec3 SKY = vec3(0.62, 0.68, 0.78);
const vec3 GROUND = vec3(0.34, 0.30, 0.27);
const vec3 KEY = vec3(1.05, 0.98, 0.90);
const vec3 RIM = vec3(0.55, 0.65, 0.85);

// Gamma 2 instead of the sRGB curve: squares and square roots are much cheaper than pow() on
// llvmpipe, and the difference does not show.
vec3 to_linear(vec3 c) { return c * c; }
vec3 to_srgb(vec3 c) { return sqrt(c); }

// look: how much of the estimated (x) and of the lost (y) look, 0..1 each (faded by the caller).
vec3 shade(vec3 n, vec3 pos, vec3 srgb, vec2 look) {
    vec3 albedo = to_linear(srgb);
    albedo = mix(albedo, u_estimated_rgb, u_estimated_tint * look.x);
    float grey = dot(albedo, vec3(0.30, 0.59, 0.11));
    albedo = mix(albedo, vec3(0.55 * grey + 0.12), look.y);
    vec3 v = normalize(u_eye - pos);
    float ndv = max(dot(n, v), 0.0);
    vec3 ambient = mix(GROUND, SKY, 0.5 + 0.5 * n.y) * 0.55;
    float wrap = clamp((dot(n, u_key_dir) + 0.25) / 1.25, 0.0, 1.0);
    vec3 colour = albedo * (ambient + KEY * wrap * 0.85);
    vec3 hv = normalize(u_key_dir + v);
    float sp = max(dot(n, hv), 0.0);
    sp *= sp; sp *= sp; sp *= sp; sp *= sp; sp *= sp;  // ^32
    colour += KEY * 0.12 * sp * step(0.0, dot(n, u_key_dir));
    float edge = 1.0 - ndv;
    colour += RIM * (edge * edge * edge) * (0.25 + 0.55 * max(dot(n, u_rim_dir), 0.0));
    colour += u_estimated_rgb * (1.6 * look.x * (1.0 - look.y)) * edge * edge;  // amber outline
    colour = colour / (1.0 + 0.15 * colour);  // soft shoulder instead of a hard clip
    return to_srgb(colour);
}
"""

# Per-instance inputs of an ellipsoid, for both of its programs (ray-cast and meshed).
_ELLIPSOID_INSTANCE_GLSL = """in vec3 i_centre;
in vec3 i_ax0;
in vec3 i_ax1;
in vec3 i_ax2;
in vec3 i_nrm0;  // columns of the inverse transpose of (ax0, ax1, ax2): normals
in vec3 i_nrm1;
in vec3 i_nrm2;
in vec3 i_rgb;
in vec2 i_style;  // estimated and lost look amounts
"""

# Ellipsoids (and spheres) are ray-cast on a screen-space quad bounding their exact outline
# (from the dual quadric, as the simulator's cameras draw them): two triangles each instead of an
# 80-320 triangle icosphere. llvmpipe pays per triangle (setup and binning, ~0.3 us each) more
# than per ray-cast pixel: the avatar's ~5.4k sphere triangles had cost ~5 ms CPU per frame.
# Exact silhouettes, depths and normals; edges are hard at the pixel centre, like a mesh's.
_VERTEX_ELLIPSOID = """
#version 330
uniform mat4 u_clip_from_world;
uniform vec2 u_pad_ndc;  // 1.5 pixels in NDC units
""" + _ELLIPSOID_INSTANCE_GLSL + """flat out vec3 v_centre;
flat out mat3 v_nrm;
flat out vec3 v_rgb;
flat out vec2 v_style;

""" + OUTLINE_BOX_GLSL + """
void main() {
    mat4 m = u_clip_from_world * mat4(vec4(i_ax0, 0.0), vec4(i_ax1, 0.0), vec4(i_ax2, 0.0), vec4(i_centre, 1.0));
    vec2 ndc = outline_quad_corner(m, u_pad_ndc);
    v_centre = i_centre;
    v_nrm = mat3(i_nrm0, i_nrm1, i_nrm2);
    v_rgb = i_rgb;
    v_style = i_style;
    gl_Position = vec4(ndc, 0.0, 1.0);
}
"""

_FRAGMENT_ELLIPSOID = """
#version 330
uniform mat4 u_clip_from_world;
uniform mat3 u_ray_from_window;  // world ray direction through window position (x, y, 1)
flat in vec3 v_centre;
flat in mat3 v_nrm;  // inverse transpose of the axes: its transpose maps world to unit-sphere space
flat in vec3 v_rgb;
flat in vec2 v_style;
out vec4 f_colour;
""" + _LIGHTING + """
void main() {
    // In the unit-sphere space of the ellipsoid the ray o + t d meets |x| = 1 where
    // a t^2 + 2 b t + c = 0; it hits in front of the eye iff b < 0 and the discriminant > 0.
    mat3 inv = transpose(v_nrm);
    vec3 ray = u_ray_from_window * vec3(gl_FragCoord.xy, 1.0);
    vec3 o = inv * (u_eye - v_centre);
    vec3 d = inv * ray;
    float a = dot(d, d);
    float b = dot(o, d);
    float disc = b * b - a * (dot(o, o) - 1.0);
    if (b >= 0.0 || disc <= 0.0) discard;
    float t = (-b - sqrt(disc)) / a;
    vec3 pos = u_eye + t * ray;
    vec4 clip = u_clip_from_world * vec4(pos, 1.0);
    float z_ndc = clip.z / clip.w;
    if (z_ndc < -1.0 || z_ndc > 1.0) discard;
    gl_FragDepth = 0.5 * z_ndc + 0.5;
    vec3 n = normalize(v_nrm * (o + t * d));
    f_colour = vec4(shade(n, pos, v_rgb, v_style), mix(1.0, u_lost_alpha, v_style.y));
}
"""

# The large ellipsoids (trunk, head, chair: the 'fine' ones) are icosphere meshes: in a close
# view they fill many pixels, and a mesh is depth-tested before shading, whereas a ray cast
# writes its depth and so shades every pixel of its quad (measured: the close game views
# drew ~2-3 ms of CPU per frame faster with meshed large ellipsoids, the live view ~1 ms
# faster with ray-cast small ones).
_VERTEX_ELLIPSOID_MESH = """
#version 330
uniform mat4 u_clip_from_world;
in vec3 in_pos;  // unit sphere: position = normal
""" + _ELLIPSOID_INSTANCE_GLSL + """out vec3 v_colour;
flat out float v_alpha;
""" + _LIGHTING + """
void main() {
    vec3 pos = i_centre + mat3(i_ax0, i_ax1, i_ax2) * in_pos;
    vec3 n = normalize(mat3(i_nrm0, i_nrm1, i_nrm2) * in_pos);
    v_colour = shade(n, pos, i_rgb, i_style);
    v_alpha = mix(1.0, u_lost_alpha, i_style.y);
    gl_Position = u_clip_from_world * vec4(pos, 1.0);
}
"""

_VERTEX_BAND = """
#version 330
uniform mat4 u_clip_from_world;
in vec3 in_ring;  // cos(theta), sin(theta), t (0 at p0, 1 at p1)
in vec3 i_p0;
in vec3 i_p1;
in vec2 i_r;
in vec3 i_rgb;
in vec2 i_style;
out vec3 v_colour;
flat out float v_alpha;
""" + BAND_GLSL + _LIGHTING + """
void main() {
    vec3 pos, n;
    band_vertex(i_p0, i_p1, i_r, in_ring, pos, n);
    v_colour = shade(n, pos, i_rgb, i_style);
    v_alpha = mix(1.0, u_lost_alpha, i_style.y);
    gl_Position = u_clip_from_world * vec4(pos, 1.0);
}
"""

# The meshes (large ellipsoids, capsule bands) are lit per vertex and their colours interpolated:
# per-pixel lighting of them cost ~3-5 ms CPU per frame in the games' close views on llvmpipe, and
# at the meshes' resolution (320-triangle icospheres, 16-sided bands) the two look alike (mean
# difference under one level of 255; the highlights and the rim a little softer).
_FRAGMENT_BODY = """
#version 330
in vec3 v_colour;
flat in float v_alpha;
out vec4 f_colour;
void main() {
    f_colour = vec4(v_colour, v_alpha);
}
"""

# The floor is a polar mesh whose vertex colours carry the radial fade and the contact shadows
# (computed on the CPU per vertex): a per-pixel floor shader (Gaussian blobs, an anti-aliased
# grid) cost ~3 ms more per frame at 1280x720 on llvmpipe.
_VERTEX_COLOURED = """
#version 330
uniform mat4 u_clip_from_world;
in vec3 in_pos;
in vec4 in_rgba;
out vec4 v_rgba;
void main() {
    v_rgba = in_rgba;
    gl_Position = u_clip_from_world * vec4(in_pos, 1.0);
}
"""

_FRAGMENT_COLOURED = """
#version 330
in vec4 v_rgba;
out vec4 f_colour;
void main() {
    f_colour = v_rgba;
}
"""

# The gradient is interpolated per vertex: a full-screen fragment shader doing anything more
# costs several milliseconds per frame at 1280x720 on llvmpipe.
_VERTEX_FULLSCREEN = """
#version 330
uniform vec3 u_top;
uniform vec3 u_bottom;
out vec3 v_colour;
void main() {
    vec2 p = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1));
    v_colour = mix(u_bottom, u_top, p.y);
    gl_Position = vec4(p * 2.0 - 1.0, 1.0, 1.0);
}
"""

_FRAGMENT_BACKGROUND = """
#version 330
in vec3 v_colour;
out vec4 f_colour;
void main() {
    f_colour = vec4(v_colour, 1.0);
}
"""

_ELLIPSOID_FORMAT = "3f 3f 3f 3f 3f 3f 3f 3f 2f/i"
_ELLIPSOID_NAMES = ("i_centre", "i_ax0", "i_ax1", "i_ax2", "i_nrm0", "i_nrm1", "i_nrm2", "i_rgb", "i_style")
_BAND_FORMAT = "3f 3f 2f 3f 2f/i"
_BAND_NAMES = ("i_p0", "i_p1", "i_r", "i_rgb", "i_style")


def _ray_from_window(clip: np.ndarray, eye: np.ndarray, viewport: tuple[int, int, int, int]) -> bytes:
    """The (3, 3) matrix taking window coordinates ``(x, y, 1)`` (``gl_FragCoord``) to the world
    direction of the ray from ``eye`` through that pixel, as float32 column-major bytes.

    The point where the ray crosses the near plane is ``clip^-1 (ndc_x, ndc_y, -1, 1)``; its
    homogeneous w is the same all over the plane for any perspective projection (mirrored or
    not), so the direction is affine in (x, y) and three pixels give the matrix.
    """
    vx, vy, vw, vh = viewport
    inv = np.linalg.inv(clip)

    def direction(x: float, y: float) -> np.ndarray:
        p = inv @ np.array([2.0 * (x - vx) / vw - 1.0, 2.0 * (y - vy) / vh - 1.0, -1.0, 1.0])
        return p[:3] / p[3] - eye

    d00 = direction(0.0, 0.0)
    m = np.column_stack([direction(1.0, 0.0) - d00, direction(0.0, 1.0) - d00, d00])
    return np.ascontiguousarray(m.T, np.float32).tobytes()


class _Instanced:
    """One static mesh drawn with a growable per-instance float32 buffer; without a mesh
    (``vertices`` None), a 4-vertex triangle strip per instance that the vertex shader places
    from ``gl_VertexID`` (the ray-cast quads)."""

    def __init__(self, ctx: moderngl.Context, program: moderngl.Program, vertices: np.ndarray | None,
                 triangles: np.ndarray | None, vertex_name: str, inst_format: str, inst_names: tuple[str, ...]) -> None:
        self._ctx, self._program = ctx, program
        self._vbo = self._ibo = None
        if vertices is not None:
            self._vbo = ctx.buffer(np.ascontiguousarray(vertices, np.float32).tobytes())
            self._ibo = ctx.buffer(np.ascontiguousarray(triangles, np.int32).tobytes())
        self._vertex_name = vertex_name
        self._format, self._names = inst_format, inst_names
        self._floats = sum(int(n) for n in re.findall(r"(\d+)f", inst_format))
        self._capacity = 0
        self._buffer: moderngl.Buffer | None = None
        self._vao: moderngl.VertexArray | None = None
        self._grow(32)

    def _grow(self, capacity: int) -> None:
        if self._vao is not None:
            self._vao.release()
            self._buffer.release()
        self._capacity = capacity
        self._buffer = self._ctx.buffer(reserve=capacity * self._floats * 4, dynamic=True)
        instances = (self._buffer, self._format, *self._names)
        if self._vbo is None:
            self._vao = self._ctx.vertex_array(self._program, [instances])
        else:
            self._vao = self._ctx.vertex_array(self._program, [(self._vbo, "3f", self._vertex_name), instances],
                                               index_buffer=self._ibo)

    def draw(self, rows: np.ndarray) -> None:
        """rows: (N, floats) float32 instance data."""
        n = rows.shape[0]
        if not n:
            return
        if n > self._capacity:
            self._grow(max(n, 2 * self._capacity))
        self._buffer.write(np.ascontiguousarray(rows, np.float32).tobytes())
        if self._vbo is None:
            self._vao.render(moderngl.TRIANGLE_STRIP, vertices=4, instances=n)
        else:
            self._vao.render(moderngl.TRIANGLES, instances=n)

    def release(self) -> None:
        for obj in (self._vao, self._buffer, self._vbo, self._ibo):
            if obj is not None:
                obj.release()
        self._vao = self._buffer = None


class _Floor:
    """The floor disc, vertex-coloured per frame (radial fade, contact shadows).

    A polar mesh of rings x ``segments``: rings every ~12 cm where the shadow blobs are (out to
    0.55 of the radius), fewer in the outer fade, which needs no detail. llvmpipe pays per triangle
    and per tile it touches: 1104 triangles (12 even rings of 48) cost 1.3-1.8 ms CPU per frame in
    the rotation and turn the key views, these 544 0.8-1.4 ms, and they look alike.
    """

    #: Ring radii, in units of the disc's radius.
    RINGS = (0.09, 0.18, 0.27, 0.36, 0.45, 0.55, 0.70, 0.85, 1.0)

    def __init__(self, ctx: moderngl.Context, program: moderngl.Program, radius_m: float, rgb: tuple[float, float, float],
                 segments: int = 32) -> None:
        self._radius, self._rgb = radius_m, np.asarray(rgb, np.float64)
        # Centre vertex, then each ring of `segments` vertices.
        theta = 2.0 * np.pi * np.arange(segments) / segments
        radii = np.asarray(self.RINGS)
        ring_xz = np.stack([np.outer(radii, np.cos(theta)), np.outer(radii, np.sin(theta))], axis=-1).reshape(-1, 2)
        self._unit = np.vstack([[0.0, 0.0], ring_xz])  # (V, 2) in units of the radius
        r = np.linalg.norm(self._unit, axis=1)
        edge = np.clip((r - 0.7) / 0.3, 0.0, 1.0)
        self._alpha = 1.0 - edge * edge * (3.0 - 2.0 * edge)  # smooth fade into the background
        self._shade = 1.0 - 0.10 * r * r
        j = np.arange(segments)
        jn = (j + 1) % segments
        tris = [np.stack([np.zeros(segments, int), 1 + j, 1 + jn], axis=1)]
        for k in range(len(radii) - 1):
            a, b = 1 + k * segments, 1 + (k + 1) * segments
            tris += [np.stack([a + j, b + j, b + jn], axis=1), np.stack([a + j, b + jn, a + jn], axis=1)]
        tris = np.concatenate(tris)
        # Opaque triangles first (drawn without blending, which costs a read per pixel), then
        # the fading rim.
        opaque = (self._alpha[tris] >= 1.0).all(axis=1)
        self._n_opaque = 3 * int(opaque.sum())
        self._n_rim = 3 * int((~opaque).sum())
        self._vbo = ctx.buffer(reserve=len(self._unit) * 7 * 4, dynamic=True)
        self._ibo = ctx.buffer(np.concatenate([tris[opaque], tris[~opaque]]).astype(np.int32).tobytes())
        self._vao = ctx.vertex_array(program, [(self._vbo, "3f 4f", "in_pos", "in_rgba")], index_buffer=self._ibo)

    def rows(self, centre: np.ndarray, floor_y: float, blobs: np.ndarray) -> np.ndarray:
        """The vertex rows (x, y, z, r, g, b, a) float32 of the disc centred on ``centre`` (its y
        is ignored) at height ``floor_y``, with ``blobs`` (B, 4: x, z, radius, darkness) shaded in."""
        xz = centre[[0, 2]] + self._radius * self._unit
        shadow = np.zeros(len(xz))
        for bx, bz, br, dark in blobs:
            f = np.maximum(1.0 - ((xz[:, 0] - bx) ** 2 + (xz[:, 1] - bz) ** 2) / (br * br), 0.0)
            shadow = np.maximum(shadow, dark * f * f)
        rows = np.empty((len(xz), 7), np.float32)
        rows[:, 0] = xz[:, 0]
        rows[:, 1] = floor_y
        rows[:, 2] = xz[:, 1]
        rows[:, 3:6] = self._rgb[None, :] * (self._shade * (1.0 - 0.55 * shadow))[:, None]
        rows[:, 6] = self._alpha
        return rows

    def draw_rows(self, rows: np.ndarray) -> None:
        """Draw the disc of :meth:`rows` over what is there, without depth (the floor is behind
        everything on it). Leaves blending enabled."""
        self._vbo.write(rows.tobytes())
        ctx = self._vao.ctx
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
        self._vao.render(moderngl.TRIANGLES, vertices=self._n_opaque)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        self._vao.render(moderngl.TRIANGLES, vertices=self._n_rim, first=self._n_opaque)

    def draw(self, centre: np.ndarray, floor_y: float, blobs: np.ndarray) -> None:
        """:meth:`rows` then :meth:`draw_rows`."""
        self.draw_rows(self.rows(centre, floor_y, blobs))

    def release(self) -> None:
        for obj in (self._vao, self._vbo, self._ibo):
            obj.release()

@dataclass(frozen=True, slots=True, eq=False)
class PreparedAvatar:
    """One frame of the avatar made ready to draw (:meth:`AvatarRenderer.prepare`).

    Attributes:
        shapes: the solids.
        clip: (4, 4) clip-from-world matrix; eye: (3,) camera centre; key_dir, rim_dir: (3,)
            unit directions towards the lights (world).
        mirrored: the view is a mirror image (front faces wind the other way).
        ellipsoids: float32 instance rows of (opaque ray-cast ellipsoids and end caps, opaque
            meshed large ellipsoids, the same two when lost).
        bands: float32 instance rows of (opaque capsule bands, lost ones).
        floor_rows: the floor mesh's vertex rows (positions and colours).
    """

    shapes: BodyShapes
    clip: np.ndarray
    eye: np.ndarray
    key_dir: np.ndarray
    rim_dir: np.ndarray
    mirrored: bool
    ellipsoids: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    bands: tuple[np.ndarray, np.ndarray]
    floor_rows: np.ndarray


class AvatarRenderer:
    """Draws the avatar into the bound framebuffer of ``ctx`` (needs a depth attachment).

    Args:
        ctx: a moderngl context, OpenGL 3.3 core or later.
        style: colours and strengths.

    :meth:`render` enables depth testing, face culling and blending and leaves them enabled; it
    sets ``ctx.front_face`` to suit the projection's handedness (a mirrored projection flips it).
    """

    def __init__(self, ctx: moderngl.Context, style: AvatarStyle = AvatarStyle()) -> None:
        self._ctx = ctx
        self.style = style
        self._prog_ellipsoid = ctx.program(vertex_shader=_VERTEX_ELLIPSOID, fragment_shader=_FRAGMENT_ELLIPSOID)
        self._prog_mesh = ctx.program(vertex_shader=_VERTEX_ELLIPSOID_MESH, fragment_shader=_FRAGMENT_BODY)
        self._prog_band = ctx.program(vertex_shader=_VERTEX_BAND, fragment_shader=_FRAGMENT_BODY)
        self._prog_floor = ctx.program(vertex_shader=_VERTEX_COLOURED, fragment_shader=_FRAGMENT_COLOURED)
        self._prog_background = ctx.program(vertex_shader=_VERTEX_FULLSCREEN, fragment_shader=_FRAGMENT_BACKGROUND)
        self._ellipsoids = _Instanced(ctx, self._prog_ellipsoid, None, None, "", _ELLIPSOID_FORMAT, _ELLIPSOID_NAMES)
        # 320 triangles: at the sizes the avatar appears on screen the outline stays within half
        # a pixel of the true ellipse.
        fine_v, fine_t = icosphere(2)
        self._fine = _Instanced(ctx, self._prog_mesh, fine_v, fine_t, "in_pos", _ELLIPSOID_FORMAT, _ELLIPSOID_NAMES)
        # 16 sides: a limb's outline is within half a pixel of round at its on-screen size, and
        # the band's long thin triangles are what llvmpipe spends the most on (32 sides: +2.4 ms).
        # (Ray-casting the tapered capsules on quads along them cost ~1 ms more than the bands.)
        band_v, band_t = cone_band(16)
        self._band = _Instanced(ctx, self._prog_band, band_v, band_t, "in_ring", _BAND_FORMAT, _BAND_NAMES)
        self._floor = _Floor(ctx, self._prog_floor, style.floor_radius_m, style.floor_rgb)
        self._empty_vao_bg = ctx.vertex_array(self._prog_background, [])
        est = np.asarray(style.estimated_rgb, np.float32) ** 2.2
        for prog in (self._prog_ellipsoid, self._prog_mesh, self._prog_band):
            prog["u_estimated_rgb"].value = tuple(float(x) for x in est)
            prog["u_estimated_tint"].value = float(style.estimated_tint)
            prog["u_lost_alpha"].value = float(style.lost_alpha)
        self._prog_background["u_top"].value = style.background_top_rgb
        self._prog_background["u_bottom"].value = style.background_bottom_rgb

    # ------------------------------------------------------------------ drawing
    def render_background(self, *, depth: bool = True) -> None:
        """Fill the bound framebuffer's viewport with the soft background gradient and reset its
        depth to the far plane (a clear for the avatar's scene).

        Args:
            depth: also reset the depth; False when the caller cleared it already (then the
                gradient is an opaque pass without a depth test: llvmpipe paints it faster and
                drops the tiles' earlier clear).
        """
        ctx = self._ctx
        if not self.style.background_gradient:
            rgb = 0.5 * (np.asarray(self.style.background_top_rgb) + np.asarray(self.style.background_bottom_rgb))
            ctx.clear(*(float(c) for c in rgb), 1.0, depth=1.0, viewport=ctx.viewport)
            return
        ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
        if not depth:
            ctx.disable(moderngl.DEPTH_TEST)
            self._empty_vao_bg.render(moderngl.TRIANGLE_STRIP, vertices=4)
            return
        # Drawn at the far plane with the depth test always passing: it also resets the depth.
        # (Framebuffer.color_mask is not used anywhere here: moderngl applies it only on use().)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.depth_func = "1"
        self._empty_vao_bg.render(moderngl.TRIANGLE_STRIP, vertices=4)
        ctx.depth_func = "<"

    def prepare(self, pose: SkeletonPose, view: np.ndarray, proj: np.ndarray, *, shapes: BodyShapes | None = None,
                looks: np.ndarray | None = None) -> PreparedAvatar:
        """The CPU side of :meth:`render` (no GL calls): solids, instance rows, matrices, floor
        colours. The app prepares a frame while the previous one is still being rasterized."""
        shapes = body_shapes(pose) if shapes is None else shapes
        view = np.asarray(view, np.float64)
        proj = np.asarray(proj, np.float64)
        clip = proj @ view
        eye_from_world_inv = np.linalg.inv(view)
        # Lights fixed to the camera: key above the viewer's left shoulder, rim from behind.
        cam = eye_from_world_inv[:3, :3]
        key = cam @ np.array([-0.45, 0.75, 0.55])
        rim = cam @ np.array([0.3, 0.45, -0.85])
        looks = state_looks(pose.state) if looks is None else np.asarray(looks, np.float32)
        e_rows, e_lost, fine = self._ellipsoid_rows(looks, shapes)
        c_rows, c_lost = self._capsule_rows(looks, shapes)
        caps, cap_lost = self._cap_rows(c_rows, c_lost, shapes.capsule_caps)  # end caps are spheres
        centre = np.array([shapes.shadow_blobs[0, 0], shapes.floor_y_m, shapes.shadow_blobs[0, 1]])
        return PreparedAvatar(
            shapes=shapes,
            clip=clip,
            eye=eye_from_world_inv[:3, 3].copy(),
            key_dir=key / np.linalg.norm(key),
            rim_dir=rim / np.linalg.norm(rim),
            mirrored=bool(np.linalg.det(proj[:3, :3] @ view[:3, :3]) > 0),
            ellipsoids=(np.concatenate([e_rows[~e_lost & ~fine], caps[~cap_lost]]), e_rows[~e_lost & fine],
                        np.concatenate([e_rows[e_lost & ~fine], caps[cap_lost]]), e_rows[e_lost & fine]),
            bands=(c_rows[~c_lost], c_rows[c_lost]),
            floor_rows=self._floor.rows(centre, shapes.floor_y_m, shapes.shadow_blobs),
        )

    def draw(self, prepared: PreparedAvatar, *, floor: bool = True) -> BodyShapes:
        """The GL side of :meth:`render`: draw what :meth:`prepare` made into the bound
        framebuffer's viewport. Returns the solids drawn."""
        ctx = self._ctx
        p = prepared
        clip_bytes = p.clip.T.astype(np.float32).tobytes()
        vx, vy, vw, vh = ctx.viewport
        self._prog_ellipsoid["u_ray_from_window"].write(_ray_from_window(p.clip, p.eye, (vx, vy, vw, vh)))
        self._prog_ellipsoid["u_pad_ndc"].value = (3.0 / vw, 3.0 / vh)
        for prog in (self._prog_ellipsoid, self._prog_mesh, self._prog_band):
            prog["u_clip_from_world"].write(clip_bytes)
            prog["u_eye"].value = tuple(float(x) for x in p.eye)
            prog["u_key_dir"].value = tuple(float(x) for x in p.key_dir)
            prog["u_rim_dir"].value = tuple(float(x) for x in p.rim_dir)
        if floor:  # first, without depth: everything else stands on it
            self._prog_floor["u_clip_from_world"].write(clip_bytes)
            self._floor.draw_rows(p.floor_rows)
        cast_opaque, fine_opaque, cast_lost, fine_lost = p.ellipsoids
        c_opaque, c_lost = p.bands
        ctx.enable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.disable(moderngl.BLEND)  # blending costs a read per pixel on llvmpipe: opaque first
        ctx.front_face = "cw" if p.mirrored else "ccw"
        self._draw_solids(cast_opaque, fine_opaque, c_opaque)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        # Lost segments, translucent: a depth-only pass first, so that a lost segment shows only
        # its front surface (no inner overlaps), then its colour over it.
        if len(cast_lost) or len(fine_lost) or len(c_lost):
            ctx.blend_func = moderngl.ZERO, moderngl.ONE  # depth only: the colour stays as it is
            self._draw_solids(cast_lost, fine_lost, c_lost)
            ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
            ctx.depth_func = "<="
            self._draw_solids(cast_lost, fine_lost, c_lost)
            ctx.depth_func = "<"
        ctx.front_face = "ccw"
        return p.shapes

    def render(self, pose: SkeletonPose, view: np.ndarray, proj: np.ndarray, *, floor: bool = True,
               shapes: BodyShapes | None = None, looks: np.ndarray | None = None) -> BodyShapes:
        """Draw the avatar (and the floor) with depth testing into the bound framebuffer
        (:meth:`prepare` then :meth:`draw`).

        Args:
            pose: the pose to show.
            view: (4, 4) world -> eye matrix (OpenGL convention, the camera looks down -z).
            proj: (4, 4) eye -> clip matrix; a left-right mirrored one is fine.
            floor: draw the floor disc with its contact shadows.
            shapes: the solids, if already built from ``pose`` (else built here).
            looks: (len(SEGMENTS), 2) amounts 0..1 of the estimated and the lost look per
                segment, e.g. faded by :class:`game.avatar.interpolate.LookFader`; by default
                :func:`state_looks` of ``pose.state`` (all or nothing).

        Returns:
            The solids drawn (for picking or tests).
        """
        return self.draw(self.prepare(pose, view, proj, shapes=shapes, looks=looks), floor=floor)

    def release(self) -> None:
        for obj in (self._ellipsoids, self._fine, self._band, self._floor):
            obj.release()
        for obj in (self._empty_vao_bg, self._prog_ellipsoid, self._prog_mesh, self._prog_band,
                    self._prog_floor, self._prog_background):
            obj.release()

    # ------------------------------------------------------------------ internals
    @staticmethod
    def _style_of(looks: np.ndarray, parts: np.ndarray) -> np.ndarray:
        """(N, 2) float32 look amounts (estimated, lost) of solids of ``parts`` (untracked: 0)."""
        out = np.zeros((len(parts), 2), np.float32)
        tracked = parts >= 0
        out[tracked] = looks[parts[tracked]]
        return out

    def _ellipsoid_rows(self, looks: np.ndarray, s: BodyShapes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        style = self._style_of(looks, s.ellipsoid_part)
        axes = np.transpose(s.ellipsoid_axes_m, (0, 2, 1)).reshape(-1, 9)  # columns ax0, ax1, ax2
        normal = np.linalg.inv(s.ellipsoid_axes_m).reshape(-1, 9)  # columns of inv(A)^T = rows of inv(A)
        rows = np.hstack([s.ellipsoid_centre_m, axes, normal, s.ellipsoid_rgb, style]).astype(np.float32)
        return rows, style[:, 1] > _TRANSLUCENT, s.ellipsoid_fine

    def _capsule_rows(self, looks: np.ndarray, s: BodyShapes) -> tuple[np.ndarray, np.ndarray]:
        style = self._style_of(looks, s.capsule_part)
        rows = np.hstack([s.capsule_p0_m, s.capsule_p1_m, s.capsule_r0_m[:, None], s.capsule_r1_m[:, None],
                          s.capsule_rgb, style]).astype(np.float32)
        return rows, style[:, 1] > _TRANSLUCENT

    @staticmethod
    def _cap_rows(c: np.ndarray, lost: np.ndarray, caps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ellipsoid rows of the capsules' drawn end spheres, and which are lost."""
        rows, flags = [], []
        for end, (p, r) in enumerate(((c[:, 0:3], c[:, 6]), (c[:, 3:6], c[:, 7]))):
            keep = caps[:, end]
            axes = np.zeros((int(keep.sum()), 9), np.float32)
            axes[:, [0, 4, 8]] = r[keep, None]
            normal = np.zeros_like(axes)
            normal[:, [0, 4, 8]] = 1.0 / r[keep, None]
            rows.append(np.hstack([p[keep], axes, normal, c[keep, 8:13]]))
            flags.append(lost[keep])
        return np.concatenate(rows).astype(np.float32), np.concatenate(flags)

    def _draw_solids(self, cast_rows: np.ndarray, fine_rows: np.ndarray, band_rows: np.ndarray) -> None:
        # The limbs first: in the games' close views the arms and the legs lie in front of the trunk
        # and the seat, and the depth test then spares the pixels they hide (measured on the river
        # and turn the key views: ~0.4-1.4 ms CPU less per frame than the large ellipsoids first).
        self._band.draw(band_rows)
        self._fine.draw(fine_rows)
        # The ray-cast quads face either way (a mirrored projection flips them): no culling.
        self._ctx.disable(moderngl.CULL_FACE)
        self._ellipsoids.draw(cast_rows)
        self._ctx.enable(moderngl.CULL_FACE)
