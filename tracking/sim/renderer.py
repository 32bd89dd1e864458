"""Offscreen OpenGL renderer of the simulated studio: virtual cameras imaging a SceneFrame.

One :class:`StudioRenderer` owns a moderngl context (EGL, headless) and renders every camera of
a calibration into ONE framebuffer atlas (a viewport and scissor per camera, cameras stacked top
to bottom) and reads the atlas back once per frame set.

Geometry matches :meth:`calibration.camera.Camera.project`: the GL projection is built from K
(fx, fy, cx, cy, skew) with the OpenCV pixel-centre convention (OpenCV pixel (0, 0) is GL window
(0.5, 0.5) of the camera's viewport). Image row v is drawn at window y = v + 0.5, so the
bottom-up GL readback already is the top-down OpenCV image and nothing is flipped. Lens
distortion: an ideal pinhole image is rendered (larger, so that it covers the whole distorted
field of view) and warped in a second pass through a lookup texture holding, for every distorted
output pixel, the ideal pixel it images (``Camera.undistort_points`` then K).

Primitives:
- spheres (markers, joints, capsule end caps) and ellipsoids are ray-cast on instanced
  screen-space quads bounding their exact outline (dual quadric): exact silhouettes, depths and
  normals for two triangles each (llvmpipe spends ~0.3 us per triangle, so tessellated spheres
  were the bottleneck);
- capsule sides are an instanced 96-triangle band tangent to the two end spheres;
- the room is one static mesh with its diffuse lighting baked at upload.

Anti-aliasing: marker balls always get analytic coverage (alpha = exact pixel coverage of the
outline, blended; drawn last), so marker centroids are unbiased to < 0.01 px. ``msaa`` (0, 2, 4)
additionally anti-aliases every other edge; on llvmpipe 4x MSAA costs ~2.5x the frame time, so
the default is 0.

Per-frame pipeline::

    upload instances -> clear -> per camera: ellipsoids, capsule bands, room, markers
    (+ their id pass) -> [MSAA resolve] -> [distortion warp] -> one readback (BGR + ids)
    -> marker pixel counts (np.bincount)

Colours are sRGB values in 0..1 shaded multiplicatively (Lambert + ambient + a little
Blinn-Phong on skin and clothes; marker balls matte), which keeps a marker's hue exact until a
channel saturates. Exposure and colour cast are applied before the 8-bit clamp, as in a sensor;
Gaussian sensor noise comes from a per-pixel hash of the seed, added by whichever shader writes
the pixel last.

Speed (``benchmark()``, 4 cameras, room, mannequin with 14 markers, visibility counts, readback;
Mesa llvmpipe on 2 shared CPU cores, so wall-clock rates vary with the machine's load):
320x240 ~40 frame sets/s at msaa 0 (~14 ms CPU per frame set) and ~17 at msaa 4 (~37 ms);
640x480 ~18 and ~5. Lens distortion adds the warp pass, whose bilinear texture fetches are slow
on llvmpipe (~+15 ms CPU at 320x240). Run ``python -m tracking.sim.renderer --preview out.png``
for the benchmark and a preview.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import time
from dataclasses import dataclass, field
from typing import NamedTuple, Sequence

import cv2
import moderngl
import numpy as np

from calibration.camera import Camera
from calibration.errors import RehabError
from tracking.geometry.glsl import BAND_GLSL, OUTLINE_BOX_GLSL
from tracking.geometry.meshes import cone_band
from tracking.sim.room import build_room
from tracking.sim.scene import SceneFrame

log = logging.getLogger(__name__)

DEFAULT_MSAA = 0  # markers are anti-aliased analytically; see StudioRenderer
NEAR_M = 0.05
FAR_M = 50.0
_MAX_LIGHTS = 4


class OffscreenGLUnavailable(RehabError):
    """No OpenGL 3.3 offscreen context could be created (no EGL / Mesa drivers)."""


@dataclass(frozen=True, slots=True)
class Lighting:
    """Clinic lighting: ambient plus a few directional ceiling lights (no shadows).

    Attributes:
        ambient: ambient intensity (a surface colour is multiplied by the total intensity).
        directions: unit-ish world vectors pointing TOWARDS each light (at most 4).
        intensities: intensity of each directional light.
        body_specular: Blinn-Phong strength on skin and clothes (markers are always matte).
        shininess: Blinn-Phong exponent.
    """

    ambient: float = 0.36
    directions: tuple[tuple[float, float, float], ...] = (
        (0.25, 0.65, -0.72),  # key: ceiling light in front of and above the patient
        (0.0, 1.0, 0.0),  # ceiling panel straight above
        (-0.55, 0.45, 0.7),  # fill from behind-left
    )
    intensities: tuple[float, ...] = (0.5, 0.16, 0.22)
    body_specular: float = 0.07
    shininess: float = 20.0

    def __post_init__(self) -> None:
        if len(self.directions) != len(self.intensities) or len(self.directions) > _MAX_LIGHTS:
            raise RehabError(
                f"Lighting: give one intensity per direction and at most {_MAX_LIGHTS} lights, "
                f"got {len(self.directions)} directions and {len(self.intensities)} intensities"
            )


@dataclass(frozen=True, slots=True)
class RenderResult:
    """What the cameras saw in one frame set.

    Attributes:
        images: one (H, W, 3) uint8 BGR image per camera, in camera order, OpenCV orientation
            (row 0 is the top of the image).
        marker_pixels: (n_cameras, n_markers) int32, number of pixels of each marker sphere that
            are visible (not occluded) in each camera; None when rendered with
            ``with_visibility=False``.
    """

    images: tuple[np.ndarray, ...]
    marker_pixels: np.ndarray | None


class _Viewport(NamedTuple):
    x: int
    y: int
    w: int
    h: int


def _stack_viewports(sizes: Sequence[tuple[int, int]], max_size: int, gap: int) -> tuple[list[_Viewport], tuple[int, int]]:
    """Stack images top to bottom in columns of at most ``max_size`` rows.

    With equal widths and one column (the usual case) every camera's image is a contiguous
    block of the readback. Returns the viewports and the atlas (width, height).
    """
    viewports: list[_Viewport] = []
    x = y = col_w = atlas_h = 0
    for w, h in sizes:
        if w > max_size or h > max_size:
            raise RehabError(f"a camera image of {w}x{h} exceeds the OpenGL limit of {max_size} pixels: use a smaller size")
        if y > 0 and y + h > max_size:
            x += col_w + gap
            y = col_w = 0
        viewports.append(_Viewport(x, y, w, h))
        y += h + gap
        col_w = max(col_w, w)
        atlas_h = max(atlas_h, y - gap)
    atlas_w = x + col_w
    if atlas_w > max_size:
        raise RehabError(f"{len(sizes)} cameras do not fit one {max_size}x{max_size} atlas: use fewer or smaller cameras")
    return viewports, (atlas_w, atlas_h)


def clip_from_camera(K: np.ndarray, size_px: tuple[int, int], near_m: float = NEAR_M, far_m: float = FAR_M) -> np.ndarray:
    """(4, 4) float64 OpenGL projection of an OpenCV camera frame (x right, y down, z forward).

    Maps a camera-frame point to clip space so that, within a viewport of ``size_px``, the GL
    window position is (u + 0.5, v + 0.5) where (u, v) = K (x/z, y/z): OpenCV pixel centres land
    on GL pixel centres, and image row 0 is window row 0 (the first row glReadPixels returns).
    Depth: z = near -> -1, z = far -> +1.
    """
    w, h = size_px
    fx, s, cx = K[0]
    fy, cy = K[1, 1], K[1, 2]
    a = (far_m + near_m) / (far_m - near_m)
    b = -2.0 * far_m * near_m / (far_m - near_m)
    return np.array(
        [
            [2.0 * fx / w, 2.0 * s / w, 2.0 * (cx + 0.5) / w - 1.0, 0.0],
            [0.0, 2.0 * fy / h, 2.0 * (cy + 0.5) / h - 1.0, 0.0],
            [0.0, 0.0, a, b],
            [0.0, 0.0, 1.0, 0.0],
        ]
    )


@dataclass(frozen=True, slots=True)
class _CameraPlan:
    """How one camera is rendered: the ideal pinhole pass and, with distortion, the warp."""

    camera: Camera
    K_ideal: np.ndarray  # (3, 3) intrinsics of the ideal render (principal point shifted)
    ideal_size_px: tuple[int, int]
    lookup_px: np.ndarray | None = field(default=None)  # (H, W, 2) float32 ideal pixel of each output pixel, NaN: none


def _plan_camera(cam: Camera, margin_px: int = 3, max_extent: float = 3.0) -> _CameraPlan:
    """Ideal render size/intrinsics and, for a distorted camera, the warp lookup table.

    For each distorted output pixel centre (u, v) the ideal pixel is K @ undistort(u, v). The
    ideal render is sized to cover all of them plus ``margin_px`` (bilinear footprint), but at
    most ``max_extent`` times the output size in each direction; pixels beyond, and pixels where
    the undistortion does not round-trip (strong distortion outside the calibrated field), stay
    black.
    """
    if not cam.has_distortion:
        return _CameraPlan(cam, cam.K, cam.size_px)
    w, h = cam.size_px
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    xn = cam.undistort_points(uv)
    bad = ~np.all(np.isfinite(xn), axis=1)
    bad |= np.linalg.norm(cam.distort_normalized(np.nan_to_num(xn)) - uv, axis=1) > 1e-3
    K = cam.K
    ideal = np.stack([K[0, 0] * xn[:, 0] + K[0, 1] * xn[:, 1] + K[0, 2], K[1, 1] * xn[:, 1] + K[1, 2]], axis=1)
    lim_lo = np.array([-(max_extent - 1) / 2 * w, -(max_extent - 1) / 2 * h])
    lim_hi = np.array([w - 1, h - 1]) - lim_lo
    bad |= np.any((ideal < lim_lo) | (ideal > lim_hi), axis=1)
    ideal[bad] = np.nan
    if bad.all():
        raise RehabError(f"camera {cam.name!r}: its distortion coefficients map no pixel to a valid ray; check the calibration")
    lo = np.floor(np.nanmin(ideal, axis=0)).astype(int) - margin_px
    hi = np.ceil(np.nanmax(ideal, axis=0)).astype(int) + margin_px
    K_ideal = K.copy()
    K_ideal[0, 2] -= lo[0]
    K_ideal[1, 2] -= lo[1]
    lookup = (ideal - lo).astype(np.float32).reshape(h, w, 2)
    n_bad = int(bad.sum())
    if n_bad:
        log.info("camera %s: %d of %d pixels lie outside the modelled lens field and stay black", cam.name, n_bad, w * h)
    return _CameraPlan(cam, K_ideal, (int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)), lookup)


# ----------------------------------------------------------------------------- shaders
# Shading shared by the capsule bands (per vertex) and the ray-cast spheres (per pixel).
# N_LIGHTS is a compile-time constant so that llvmpipe unrolls the loop.
_SHADE_GLSL = """
uniform vec3 u_eye;
uniform float u_ambient;
uniform vec3 u_gain;  // exposure * colour cast, RGB
#if N_LIGHTS > 0
uniform vec3 u_light_dir[N_LIGHTS];
uniform float u_light_int[N_LIGHTS];
uniform float u_shininess;
#endif
vec3 shade(vec3 n, vec3 pos, vec3 rgb, float specular) {
    float diffuse = u_ambient;
    float spec = 0.0;
#if N_LIGHTS > 0
    vec3 view = normalize(u_eye - pos);
    for (int i = 0; i < N_LIGHTS; ++i) {
        float ndl = dot(n, u_light_dir[i]);
        if (ndl > 0.0) {
            diffuse += u_light_int[i] * ndl;
            if (specular > 0.0) {
                vec3 hv = normalize(u_light_dir[i] + view);
                spec += u_light_int[i] * pow(max(dot(n, hv), 0.0), u_shininess);
            }
        }
    }
#endif
    return (rgb * diffuse + vec3(specular * spec)) * u_gain;
}
"""

# Meshes (room, capsule bands) arrive lit per vertex: the fragment stage only writes.
_FRAGMENT_FLAT = """
in vec3 v_colour;
layout(location = 0) out vec4 f_bgr;
layout(location = 1) out uint f_id;
void main() {
    // BGR in the RGB channels: the readback is OpenCV BGR as is.
    f_bgr = vec4(v_colour.bgr + sensor_noise(gl_FragCoord.xy), 1.0);
    f_id = 0u;
}
"""

_VERTEX_ROOM = """
uniform mat4 u_clip_from_world;
uniform vec3 u_gain;
in vec3 in_pos;
in vec3 in_lit;  // baked diffuse colour
out vec3 v_colour;
void main() {
    v_colour = in_lit * u_gain;
    gl_Position = u_clip_from_world * vec4(in_pos, 1.0);
}
"""

_VERTEX_CAPSULE_BAND = """
uniform mat4 u_clip_from_world;
in vec3 in_ring;  // cos(theta), sin(theta), t (0 at p0, 1 at p1)
in vec3 i_p0;
in vec3 i_p1;
in vec2 i_r;
in vec3 i_rgb;
in float i_spec;
out vec3 v_colour;
""" + BAND_GLSL + """
void main() {
    vec3 pos, n;
    band_vertex(i_p0, i_p1, i_r, in_ring, pos, n);
    v_colour = shade(n, pos, i_rgb, i_spec);
    gl_Position = u_clip_from_world * vec4(pos, 1.0);
}
"""

# Spheres and ellipsoids are ray-cast on a screen-space quad that bounds their exact outline
# (from the dual quadric), so silhouettes, depths and normals are exact and each costs two
# triangles (llvmpipe spends ~0.3 us per triangle). With MSAA the fragment writes
# gl_SampleMask from a ray test per sample, so the outline is anti-aliased like a mesh edge.
_VERTEX_ELLIPSOID = """
uniform mat4 u_clip_from_world;
uniform vec2 u_pad_ndc;  // 1.5 pixels in NDC units
in vec3 i_centre;
in vec3 i_ax0;
in vec3 i_ax1;
in vec3 i_ax2;
in vec3 i_inv0;
in vec3 i_inv1;
in vec3 i_inv2;
in vec3 i_rgb;
in vec2 i_spec_id;
flat out vec3 v_centre;
flat out mat3 v_inv;
flat out vec3 v_rgb;
flat out float v_spec;
flat out uint v_id;

""" + OUTLINE_BOX_GLSL + """
void main() {
    mat4 m = u_clip_from_world * mat4(vec4(i_ax0, 0.0), vec4(i_ax1, 0.0), vec4(i_ax2, 0.0), vec4(i_centre, 1.0));
    // The quad winds clockwise, i.e. front-facing here (see render()).
    vec2 ndc = outline_quad_corner(m, u_pad_ndc);
    v_centre = i_centre;
    v_inv = mat3(i_inv0, i_inv1, i_inv2);
    v_rgb = i_rgb;
    v_spec = i_spec_id.x;
    v_id = uint(i_spec_id.y + 0.5);
    gl_Position = vec4(ndc, 0.0, 1.0);
}
"""

# Edge modes: N_SAMPLES > 0 (MSAA): a coverage mask from one ray test per sample.
# N_SAMPLES == 0 and COVERAGE: alpha = analytic pixel coverage (blended; used for markers,
# drawn last), and with u_id_pass only the pixels whose centre is inside write the id.
# Otherwise: a hard edge at the pixel centre, like a rasterized mesh.
_FRAGMENT_ELLIPSOID = """
uniform mat4 u_clip_from_world;
uniform mat3 u_ray_from_window;  // world ray direction through window position (x, y, 1)
#if N_SAMPLES > 0
uniform vec2 u_sample_offset[N_SAMPLES];  // sample positions relative to the pixel centre
#endif
#if COVERAGE
uniform bool u_id_pass;
#endif
flat in vec3 v_centre;
flat in mat3 v_inv;
flat in vec3 v_rgb;
flat in float v_spec;
flat in uint v_id;
layout(location = 0) out vec4 f_bgr;
layout(location = 1) out uint f_id;

void main() {
    // In the ellipsoid's unit-sphere space the ray o + t d meets |x| = 1 where
    // a t^2 + 2 b t + c = 0; the ray hits in front of the camera iff b < 0 and disc > 0.
    vec3 o = v_inv * (u_eye - v_centre);
    vec3 ray = u_ray_from_window * vec3(gl_FragCoord.xy, 1.0);
    vec3 d = v_inv * ray;
    float c = dot(o, o) - 1.0;
    float a = dot(d, d);
    float b = dot(o, d);
    float disc = b * b - a * c;
    float alpha = 1.0;
#if N_SAMPLES > 0
    vec3 ddx = v_inv * u_ray_from_window[0];
    vec3 ddy = v_inv * u_ray_from_window[1];
    int mask = 0;
    for (int i = 0; i < N_SAMPLES; ++i) {
        vec3 ds = d + u_sample_offset[i].x * ddx + u_sample_offset[i].y * ddy;
        float bs = dot(o, ds);
        if (bs < 0.0 && bs * bs - dot(ds, ds) * c > 0.0) mask |= 1 << i;
    }
    if (mask == 0) discard;
    gl_SampleMask[0] = mask;
#elif COVERAGE
    if (b >= 0.0) discard;
    // Signed distance (pixels) from the pixel centre to the outline disc = 0, to first order;
    // a straight edge at distance s covers 0.5 + s of the pixel.
    vec3 ddx = v_inv * u_ray_from_window[0];
    vec3 ddy = v_inv * u_ray_from_window[1];
    vec2 grad = 2.0 * vec2(b * dot(o, ddx) - c * dot(d, ddx), b * dot(o, ddy) - c * dot(d, ddy));
    alpha = clamp(0.5 + disc / max(length(grad), 1e-30), 0.0, 1.0);
    if (alpha <= 0.0 || (u_id_pass && disc <= 0.0)) discard;
#else
    if (b >= 0.0 || disc <= 0.0) discard;
#endif
    disc = max(disc, 0.0);  // an edge pixel whose centre misses: shade the rim
    float t = (-b - sqrt(disc)) / a;
    vec3 unit = o + t * d;
    vec3 pos = u_eye + t * ray;
    vec4 clip = u_clip_from_world * vec4(pos, 1.0);
    float z_ndc = clip.z / clip.w;
    if (z_ndc < -1.0 || z_ndc > 1.0) discard;
    gl_FragDepth = 0.5 * z_ndc + 0.5;
    vec3 n = normalize(transpose(v_inv) * unit);
    f_bgr = vec4(shade(n, pos, v_rgb, v_spec).bgr + sensor_noise(gl_FragCoord.xy), alpha);
    f_id = v_id;
}
"""

_VERTEX_FULLSCREEN = """
void main() {
    vec2 p = vec2(float(gl_VertexID & 1), float((gl_VertexID >> 1) & 1)) * 2.0 - 1.0;
    gl_Position = vec4(p, 0.0, 1.0);
}
"""

# Gaussian sensor noise from a hash of (output pixel, seed): reproducible, independent per
# channel, no state. Added where the final colour of a pixel is written: by the geometry
# shaders (blending a marker edge keeps the pixel's noise, as both layers carry the same), or
# by the distortion warp when there is one.
_NOISE_GLSL = """
uniform float u_sigma;  // 0..1 units; 0 = off
uniform uint u_seed_hash;  // the frame's seed, hashed on the CPU
uint pcg(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}
// Unit normal deviate from one 32-bit hash: the sum of its four bytes (Irwin-Hall, n = 4) is
// close to Gaussian (tails cut at 3.5 sigma) and avoids log/sqrt/cos, which llvmpipe
// evaluates slowly.
float gauss(uint h) {
    uint s = (h & 255u) + ((h >> 8u) & 255u) + ((h >> 16u) & 255u) + (h >> 24u);
    return (float(s) - 510.0) * (1.0 / 147.80);
}
vec3 sensor_noise(vec2 frag_coord) {
    if (u_sigma <= 0.0) return vec3(0.0);
    uvec2 px = uvec2(frag_coord);
    uint h = pcg(px.x + pcg(px.y + u_seed_hash));
    return u_sigma * vec3(gauss(h), gauss(pcg(h ^ 0x9e3779b9u)), gauss(pcg(h + 0x85ebca6bu)));
}
"""

_FRAGMENT_POST = """
uniform sampler2D u_colour;  // resolved ideal atlas, BGR
uniform usampler2D u_id;
uniform sampler2D u_lookup;  // output atlas: ideal-atlas window coordinates of each output pixel
uniform bool u_use_lookup;
uniform ivec2 u_shift;  // ideal-atlas origin minus output-atlas origin (no lookup)
layout(location = 0) out vec4 f_bgr;
layout(location = 1) out uint f_id;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec3 c;
    uint id;
    if (u_use_lookup) {
        vec2 src = texelFetch(u_lookup, px, 0).xy;
        if (src.x < 0.0) {
            c = vec3(0.0);
            id = 0u;
        } else {
            c = texture(u_colour, src / vec2(textureSize(u_colour, 0))).rgb;
            id = texelFetch(u_id, ivec2(floor(src)), 0).r;
        }
    } else {
        c = texelFetch(u_colour, px + u_shift, 0).rgb;
        id = texelFetch(u_id, px + u_shift, 0).r;
    }
    f_bgr = vec4(c + sensor_noise(gl_FragCoord.xy), 1.0);
    f_id = id;
}
"""

# Sample positions of Mesa llvmpipe (the D3D standard patterns), pixel units from the corner.
# Any pattern centred on the pixel keeps coverage-weighted centroids unbiased.
_SAMPLE_POSITIONS = {
    2: ((0.75, 0.75), (0.25, 0.25)),
    4: ((0.375, 0.125), (0.875, 0.375), (0.125, 0.625), (0.625, 0.875)),
}


def _pcg_hash(v: int) -> int:
    """The shader's pcg() on the CPU (32-bit unsigned arithmetic)."""
    state = (v * 747796405 + 2891336453) & 0xFFFFFFFF
    word = (((state >> ((state >> 28) + 4)) ^ state) * 277803737) & 0xFFFFFFFF
    return (word >> 22) ^ word


def _glsl(version: int, defines: dict[str, int], *parts: str) -> str:
    head = f"#version {version}\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items())
    return head + "\n".join(parts)


def create_context() -> moderngl.Context:
    """A standalone OpenGL 3.3+ context: EGL (headless) first, then the platform default.

    Raises:
        OffscreenGLUnavailable: neither works.
    """
    errors = []
    for kwargs in ({"backend": "egl"}, {}):
        try:
            return moderngl.create_standalone_context(require=330, **kwargs)
        except Exception as exc:  # glcontext raises plain Exceptions of several types
            errors.append(f"{kwargs.get('backend', 'default')}: {exc}")
    reasons = "; ".join(errors).replace("\n", " ")
    raise OffscreenGLUnavailable(
        f"OpenGL offscreen rendering is unavailable ({reasons}): install Mesa EGL "
        "(apt-get install libegl1 libgl1-mesa-dri)"
    )


class _InstanceStream:
    """A growable per-instance float32 buffer and its vertex array (one mesh, one program)."""

    def __init__(self, ctx: moderngl.Context, program: moderngl.Program, mesh: tuple | None, inst_format: str, inst_names: tuple[str, ...], floats_per_instance: int, vertices: int = 0) -> None:
        self._ctx, self._program, self._mesh = ctx, program, mesh
        self._format, self._names, self._floats = inst_format, inst_names, floats_per_instance
        self._vertices = vertices
        self._capacity = 0
        self.count = 0
        self.buffer: moderngl.Buffer | None = None
        self.vao: moderngl.VertexArray | None = None
        self._grow(64)

    def _grow(self, capacity: int) -> None:
        self.release()
        self._capacity = capacity
        self.buffer = self._ctx.buffer(reserve=capacity * self._floats * 4, dynamic=True)
        # Attributes the compiler optimised away (e.g. specular without lights) become padding.
        tokens = self._format.split(" ")
        suffix = tokens[-1][tokens[-1].index("/"):]
        tokens[-1] = tokens[-1][: tokens[-1].index("/")]
        fmt, names = [], []
        for token, name in zip(tokens, self._names):
            if name in self._program:
                fmt.append(token)
                names.append(name)
            else:
                fmt.append(f"{4 * int(token[:-1])}x")
        content = [(self.buffer, " ".join(fmt) + suffix, *names)]
        if self._mesh is None:
            self.vao = self._ctx.vertex_array(self._program, content)
        else:
            vbo, ibo, fmt, name = self._mesh
            self.vao = self._ctx.vertex_array(self._program, [(vbo, fmt, name), *content], index_buffer=ibo)

    def upload(self, data: np.ndarray) -> None:
        """data: (N, floats_per_instance) float32 rows, one per instance."""
        self.count = data.shape[0]
        if self.count > self._capacity:
            self._grow(max(self.count, 2 * self._capacity))
        if self.count:
            self.buffer.write(np.ascontiguousarray(data, dtype=np.float32))

    def draw(self) -> None:
        if not self.count:
            return
        if self._mesh is None:
            self.vao.render(moderngl.TRIANGLE_STRIP, vertices=self._vertices, instances=self.count)
        else:
            self.vao.render(moderngl.TRIANGLES, instances=self.count)

    def release(self) -> None:
        if self.vao is not None:
            self.vao.release()
            self.buffer.release()
            self.vao = self.buffer = None


class StudioRenderer:
    """Renders SceneFrames as seen by a set of calibrated cameras, offscreen.

    Args:
        cameras: the studio's cameras (sizes may differ), in calibration order.
        room: draw the clinic room (walls, floor, ceiling, chair, clutter) around the patient.
        msaa: multisample anti-aliasing samples: 0 (off), 2 or 4.
        ctx: an existing moderngl context to share; by default a standalone EGL context is
            created (and released by :meth:`release`). ``render`` changes a shared context's
            state (bound framebuffer, enables, front face, blending): rebind your own after it.
        lighting: lights and specular strength.
        ceiling: draw the room's ceiling.

    Raises:
        OffscreenGLUnavailable: no OpenGL 3.3 context can be created.
        RehabError: bad arguments (no cameras, unsupported msaa, atlas too large).
    """

    def __init__(
        self,
        cameras: Sequence[Camera],
        *,
        room: bool = True,
        msaa: int = DEFAULT_MSAA,
        ctx: moderngl.Context | None = None,
        lighting: Lighting = Lighting(),
        ceiling: bool = True,
    ) -> None:
        self._cameras = tuple(cameras)
        if not self._cameras:
            raise RehabError("StudioRenderer needs at least one camera")
        self._owned: list = []
        self._streams: list[_InstanceStream] = []
        self._own_ctx = ctx is None
        self._ctx = create_context() if ctx is None else ctx
        self._released = False
        try:
            self._setup(room, int(msaa), lighting, ceiling)
        except Exception:
            self.release()
            raise

    # ------------------------------------------------------------------ setup
    def _setup(self, room: bool, msaa: int, lighting: Lighting, ceiling: bool) -> None:
        ctx = self._ctx
        if msaa not in (0, *_SAMPLE_POSITIONS) or msaa > ctx.max_samples:
            raise RehabError(f"msaa={msaa} is not supported here: use 0 (off) or one of {sorted(_SAMPLE_POSITIONS)} up to {ctx.max_samples}")
        self._msaa = msaa
        self._lighting = lighting
        max_size = int(ctx.info["GL_MAX_TEXTURE_SIZE"])
        self._plans = [_plan_camera(c) for c in self._cameras]
        self._distorted = any(p.lookup_px is not None for p in self._plans)
        self._out_vps, out_size = _stack_viewports([c.size_px for c in self._cameras], max_size, gap=0)
        if self._distorted:  # a gap keeps the bilinear warp from reading a neighbour's pixels
            self._ideal_vps, ideal_size = _stack_viewports([p.ideal_size_px for p in self._plans], max_size, gap=2)
        else:
            self._ideal_vps, ideal_size = self._out_vps, out_size
        self._out_size, self._ideal_size = out_size, ideal_size
        self._per_camera = [self._camera_uniforms(plan, vp) for plan, vp in zip(self._plans, self._ideal_vps)]

        # Programs.
        version = 400 if msaa else 330  # gl_SampleMask needs GLSL 4.00
        n_lights = len(lighting.directions)
        defs = {"N_LIGHTS": n_lights}
        self._prog_ellipsoid = ctx.program(
            vertex_shader=_glsl(version, defs, _VERTEX_ELLIPSOID),
            fragment_shader=_glsl(version, {**defs, "N_SAMPLES": msaa, "COVERAGE": 0}, _SHADE_GLSL, _NOISE_GLSL, _FRAGMENT_ELLIPSOID),
        )
        # Markers always get analytic coverage: continuous, so centroids are exact to < 0.01 px
        # (4x MSAA quantizes edge coverage to quarters: errors up to ~0.06 px).
        self._prog_marker = ctx.program(
            vertex_shader=_glsl(330, defs, _VERTEX_ELLIPSOID),
            fragment_shader=_glsl(330, {**defs, "N_SAMPLES": 0, "COVERAGE": 1}, _SHADE_GLSL, _NOISE_GLSL, _FRAGMENT_ELLIPSOID),
        )
        self._owned.append(self._prog_marker)
        self._prog_band = ctx.program(
            vertex_shader=_glsl(330, defs, _SHADE_GLSL, _VERTEX_CAPSULE_BAND), fragment_shader=_glsl(330, {}, _NOISE_GLSL, _FRAGMENT_FLAT)
        )
        self._prog_room = ctx.program(vertex_shader=_glsl(330, {}, _VERTEX_ROOM), fragment_shader=_glsl(330, {}, _NOISE_GLSL, _FRAGMENT_FLAT))
        self._prog_post = ctx.program(vertex_shader=_glsl(330, {}, _VERTEX_FULLSCREEN), fragment_shader=_glsl(330, {}, _NOISE_GLSL, _FRAGMENT_POST))
        self._owned += [self._prog_ellipsoid, self._prog_band, self._prog_room, self._prog_post]
        self._programs = tuple(dict.fromkeys((self._prog_ellipsoid, self._prog_marker, self._prog_band, self._prog_room)))
        # Per camera: (uniform, bytes) for every program that uses it, resolved once.
        self._camera_uniform_bytes = [
            [(prog[name], data) for prog in self._programs for name, data in per_cam.items() if name in prog]
            for per_cam in self._per_camera
        ]
        self._light_dirs = np.zeros((n_lights, 3))
        if n_lights:
            d = np.asarray(lighting.directions, float)
            self._light_dirs = d / np.linalg.norm(d, axis=1, keepdims=True)
        for prog in dict.fromkeys((self._prog_ellipsoid, self._prog_marker, self._prog_band)):
            self._set(prog, "u_ambient", float(lighting.ambient))
            if n_lights:
                prog["u_light_dir"].write(self._light_dirs.astype(np.float32).tobytes())
                prog["u_light_int"].write(np.asarray(lighting.intensities, np.float32).tobytes())
                self._set(prog, "u_shininess", float(lighting.shininess))
        if msaa:
            offsets = np.asarray(_SAMPLE_POSITIONS[msaa], np.float32) - 0.5
            self._prog_ellipsoid["u_sample_offset"].write(offsets.tobytes())

        # Instance streams: ray-cast ellipsoids (4-vertex quads) and capsule bands (mesh).
        inst_names = ("i_centre", "i_ax0", "i_ax1", "i_ax2", "i_inv0", "i_inv1", "i_inv2", "i_rgb", "i_spec_id")
        inst_format = "3f 3f 3f 3f 3f 3f 3f 3f 2f/i"
        self._ellipsoids = _InstanceStream(ctx, self._prog_ellipsoid, None, inst_format, inst_names, 26, vertices=4)
        self._markers = _InstanceStream(ctx, self._prog_marker, None, inst_format, inst_names, 26, vertices=4)
        verts, tris = cone_band(48)
        band_vbo, band_ibo = ctx.buffer(verts.tobytes()), ctx.buffer(tris.astype(np.int32).tobytes())
        self._owned += [band_vbo, band_ibo]
        self._bands = _InstanceStream(
            ctx, self._prog_band, (band_vbo, band_ibo, "3f", "in_ring"), "3f 3f 2f 3f 1f/i",
            ("i_p0", "i_p1", "i_r", "i_rgb", "i_spec"), 12,
        )
        self._streams = [self._ellipsoids, self._markers, self._bands]
        self._room_vao = None
        if room:
            mesh = build_room(ceiling=ceiling)
            lit = mesh.rgb * self._diffuse(mesh.normal)[:, None]
            room_vbo = ctx.buffer(np.hstack([mesh.position_m, lit]).astype(np.float32).tobytes())
            self._room_vao = ctx.vertex_array(self._prog_room, [(room_vbo, "3f 3f", "in_pos", "in_lit")])
            self._owned += [room_vbo, self._room_vao]
            log.debug("room: %d triangles", mesh.n_triangles)

        # Framebuffers: draw (MSAA or not) -> resolved textures -> optional post pass.
        self._colour_tex = ctx.texture(ideal_size, 4)
        self._id_tex = ctx.texture(ideal_size, 1, dtype="u2")
        self._id_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._owned += [self._colour_tex, self._id_tex]
        if msaa:
            colour = ctx.renderbuffer(ideal_size, 4, samples=msaa)
            ids = ctx.renderbuffer(ideal_size, 1, samples=msaa, dtype="u2")
            depth = ctx.depth_renderbuffer(ideal_size, samples=msaa)
            self._fbo_resolved = {True: ctx.framebuffer([self._colour_tex, self._id_tex]), False: ctx.framebuffer([self._colour_tex])}
            self._owned += [colour, ids, depth, *self._fbo_resolved.values()]
        else:
            colour, ids, depth = self._colour_tex, self._id_tex, ctx.depth_renderbuffer(ideal_size)
            self._owned.append(depth)
        # Without visibility the id attachment is left out: less to write, resolve and read.
        self._fbo_draw = {True: ctx.framebuffer([colour, ids], depth), False: ctx.framebuffer([colour], depth)}
        self._owned += list(self._fbo_draw.values())
        if not msaa:
            self._fbo_resolved = self._fbo_draw

        self._post_vao = ctx.vertex_array(self._prog_post, [])
        self._owned.append(self._post_vao)
        self._set(self._prog_post, "u_colour", 0)
        self._set(self._prog_post, "u_id", 1)
        self._set(self._prog_post, "u_lookup", 2)
        out_colour = ctx.texture(out_size, 4)
        out_id = ctx.renderbuffer(out_size, 1, dtype="u2")
        self._fbo_post = {True: ctx.framebuffer([out_colour, out_id]), False: ctx.framebuffer([out_colour])}
        self._owned += [out_colour, out_id, *self._fbo_post.values()]
        lookup = np.full((out_size[1], out_size[0], 2), -1.0, np.float32)
        for plan, ivp, ovp in zip(self._plans, self._ideal_vps, self._out_vps):
            if plan.lookup_px is not None:
                win = plan.lookup_px + np.array([ivp.x + 0.5, ivp.y + 0.5], np.float32)
                win[~np.isfinite(win)] = -1.0
                lookup[ovp.y : ovp.y + ovp.h, ovp.x : ovp.x + ovp.w] = win
        self._lookup_tex = ctx.texture(out_size, 2, lookup.tobytes(), dtype="f4")
        self._lookup_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._owned.append(self._lookup_tex)
        log.info(
            "StudioRenderer: %d cameras, atlas %dx%d (ideal %dx%d), msaa %d, room %s, on %s",
            len(self._cameras), *out_size, *ideal_size, msaa, room, ctx.info.get("GL_RENDERER", "?"),
        )

    @staticmethod
    def _set(prog: moderngl.Program, name: str, value) -> None:
        """Set a uniform unless the compiler removed it as unused."""
        if name in prog:
            prog[name].value = value

    def _diffuse(self, normal: np.ndarray) -> np.ndarray:
        """(N, 3) unit normals -> (N,) ambient + Lambert intensity (the shader's diffuse term)."""
        total = np.full(len(normal), float(self._lighting.ambient))
        for d, k in zip(self._light_dirs, self._lighting.intensities):
            total += k * np.maximum(normal @ d, 0.0)
        return total

    @staticmethod
    def _camera_uniforms(plan: _CameraPlan, vp: _Viewport) -> dict[str, bytes]:
        """Per-camera uniform values as float32 bytes (matrices column-major)."""
        cam = plan.camera
        clip = clip_from_camera(plan.K_ideal, plan.ideal_size_px) @ np.vstack([cam.extrinsic, [0.0, 0.0, 0.0, 1.0]])
        window_to_pixel = np.array([[1.0, 0.0, -vp.x - 0.5], [0.0, 1.0, -vp.y - 0.5], [0.0, 0.0, 1.0]])
        ray = cam.R.T @ np.linalg.inv(plan.K_ideal) @ window_to_pixel
        f32 = lambda m: np.ascontiguousarray(np.asarray(m).T, dtype=np.float32).tobytes()  # noqa: E731
        return {
            "u_clip_from_world": f32(clip),
            "u_ray_from_window": f32(ray),
            "u_eye": f32(cam.centre_m),
            "u_pad_ndc": f32([3.0 / plan.ideal_size_px[0], 3.0 / plan.ideal_size_px[1]]),
        }

    # ------------------------------------------------------------------ public
    @property
    def cameras(self) -> tuple[Camera, ...]:
        return self._cameras

    @property
    def msaa(self) -> int:
        return self._msaa

    @property
    def ctx(self) -> moderngl.Context:
        return self._ctx

    def render(
        self,
        scene: SceneFrame | Sequence[SceneFrame],
        *,
        exposure: float = 1.0,
        colour_cast: Sequence[float] = (1.0, 1.0, 1.0),
        noise_sigma: float = 0.0,
        seed: int = 0,
        with_visibility: bool = True,
    ) -> RenderResult:
        """Render one frame set: every camera's image and the markers' visible pixel counts.

        Args:
            scene: the primitives of this instant (world metres); or one SceneFrame per camera
                (cameras that image at their own instants: free-running clocks, rolling shutter).
            exposure: gain on all channels (brightness drift); applied before the 8-bit clamp.
            colour_cast: (3,) per-channel gains in R, G, B order (white balance error).
            noise_sigma: standard deviation of additive Gaussian sensor noise in 8-bit units.
            seed: noise seed; the same seed gives the same noise.
            with_visibility: also count each marker's visible pixels per camera.
        Returns:
            RenderResult with one (H, W, 3) uint8 BGR image per camera.
        """
        if self._released:
            raise RehabError("StudioRenderer.render called after release(): create a new renderer")
        ctx = self._ctx
        # Make this renderer's context current: another renderer released in this thread (or a
        # game's window context) may have left none, or its own, current.
        ctx.__enter__()
        vis = bool(with_visibility)
        per_camera = not isinstance(scene, SceneFrame)
        if per_camera and len(scene) != len(self._cameras):
            raise RehabError(f"StudioRenderer.render: {len(scene)} scenes for {len(self._cameras)} cameras")
        if not per_camera:
            self._upload_scene(scene)
        gain = tuple(float(exposure) * float(g) for g in colour_cast)
        for prog in self._programs:
            prog["u_gain"].value = gain
        # Noise goes where each output pixel is last written: the warp pass if there is one.
        sigma = float(noise_sigma) / 255.0
        seed_hash = _pcg_hash(int(seed) & 0xFFFFFFFF)
        for prog in (*self._programs, self._prog_post):
            self._set(prog, "u_sigma", 0.0 if self._distorted and prog is not self._prog_post else sigma)
            self._set(prog, "u_seed_hash", seed_hash)

        ctx.enable_only(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        # OpenCV's camera frame (y down) is mirrored relative to GL's (y up): outward-wound
        # triangles appear clockwise in the window.
        ctx.front_face = "cw"
        ctx.cull_face = "back"
        fbo = self._fbo_draw[vis]
        fbo.use()
        fbo.scissor = None
        fbo.viewport = (0, 0, *self._ideal_size)
        fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        for c, (vp, uniform_bytes) in enumerate(zip(self._ideal_vps, self._camera_uniform_bytes)):
            if per_camera:
                self._upload_scene(scene[c])
            fbo.viewport = vp
            fbo.scissor = vp  # guard-band clipping must not spill into a neighbour's viewport
            for uniform, data in uniform_bytes:
                uniform.write(data)
            # Near to far, so that early depth tests spare the room's pixels behind the body.
            self._ellipsoids.draw()
            self._bands.draw()
            if self._room_vao is not None:
                self._room_vao.render(moderngl.TRIANGLES)
            self._draw_markers(fbo, vis)
        fbo.scissor = None
        if self._msaa:
            ctx.copy_framebuffer(self._fbo_resolved[vis], fbo)
        out_fbo = self._fbo_resolved[vis]
        if self._distorted:
            out_fbo = self._post_pass(vis)
        return self._read(out_fbo, vis, scene[0].n_markers if per_camera else scene.n_markers)

    def release(self) -> None:
        """Free every GL object (and the context if this renderer created it). Idempotent."""
        if self._released:
            return
        self._released = True
        for stream in self._streams:
            stream.release()
        for obj in reversed(self._owned):
            obj.release()
        if self._own_ctx:
            self._ctx.release()

    def __enter__(self) -> "StudioRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    # ------------------------------------------------------------------ per frame
    def _upload_scene(self, scene: SceneFrame) -> None:
        """Pack spheres, capsule end caps and ellipsoids (one ray-cast stream) and capsule bands."""
        spec = self._lighting.body_specular
        sc = np.asarray(scene.sphere_centre_m, np.float64).reshape(-1, 3)
        sr = np.asarray(scene.sphere_radius_m, np.float64).reshape(-1)
        s_id = np.asarray(scene.sphere_marker_index).reshape(-1).astype(np.float64) + 1.0
        p0 = np.asarray(scene.capsule_p0_m, np.float64).reshape(-1, 3)
        p1 = np.asarray(scene.capsule_p1_m, np.float64).reshape(-1, 3)
        r0 = np.asarray(scene.capsule_r0_m, np.float64).reshape(-1)
        r1 = np.asarray(scene.capsule_r1_m, np.float64).reshape(-1)
        c_rgb = np.asarray(scene.capsule_rgb, np.float64).reshape(-1, 3)
        ec = np.asarray(scene.ellipsoid_centre_m, np.float64).reshape(-1, 3)
        ea = np.asarray(scene.ellipsoid_axes_m, np.float64).reshape(-1, 3, 3)

        n_sph = len(sc) + 2 * len(p0)
        n = n_sph + len(ec)
        data = np.empty((n, 26), np.float32)
        data[:, 0:3] = np.vstack([sc, p0, p1, ec])
        radii = np.concatenate([sr, r0, r1])
        axes = np.zeros((n_sph, 3, 3))  # row-major copy of the column vectors below
        inv = np.zeros((n_sph, 3, 3))
        idx = np.arange(3)
        axes[:, idx, idx] = radii[:, None]
        with np.errstate(divide="ignore"):
            inv[:, idx, idx] = 1.0 / radii[:, None]
        if len(ec):
            axes = np.concatenate([axes, ea.transpose(0, 2, 1)])  # rows = semi-axis vectors
            inv = np.concatenate([inv, np.linalg.pinv(ea).transpose(0, 2, 1)])  # rows = columns of A^-1
        data[:, 3:12] = axes.reshape(n, 9)
        data[:, 12:21] = inv.reshape(n, 9)
        data[:, 21:24] = np.vstack([np.asarray(scene.sphere_rgb, np.float64).reshape(-1, 3), c_rgb, c_rgb, np.asarray(scene.ellipsoid_rgb, np.float64).reshape(-1, 3)])
        data[:, 24] = spec
        data[: len(sc), 24] = np.where(s_id > 0, 0.0, spec)  # marker balls are matte
        data[:, 25] = 0.0
        data[: len(sc), 25] = s_id
        is_marker = np.zeros(n, bool)
        is_marker[: len(sc)] = s_id > 0
        drawable = np.ones(n, bool)  # zero-radius spheres would ray-cast to NaN
        drawable[:n_sph] = radii > 0.0
        self._ellipsoids.upload(data[~is_marker & drawable])
        self._markers.upload(data[is_marker & drawable])

        keep = np.linalg.norm(p1 - p0, axis=1) > 1e-9
        band = np.hstack([p0, p1, np.stack([r0, r1], 1), c_rgb, np.full((len(p0), 1), spec)])[keep]
        self._bands.upload(band.astype(np.float32))

    def _draw_markers(self, fbo: moderngl.Framebuffer, vis: bool) -> None:
        """Marker balls, last: blended with their analytic pixel coverage, then their ids.

        The id pass writes where the pixel centre lies inside the outline and the depth equals
        the marker's own (depth test <=, no depth writes), so counts are whole visible pixels.
        """
        if not self._markers.count:
            return
        ctx = self._ctx
        on, off = (True,) * 4, (False,) * 4
        prog = self._prog_marker
        if vis:
            fbo.color_mask = (on, off)
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        prog["u_id_pass"].value = False
        self._markers.draw()
        ctx.disable(moderngl.BLEND)
        if vis:  # ids where the pixel centre is inside and the depth equals the marker's own
            fbo.color_mask = (off, on)
            fbo.depth_mask = False
            ctx.depth_func = "<="
            prog["u_id_pass"].value = True
            self._markers.draw()
            ctx.depth_func = "<"
            fbo.depth_mask = True
            fbo.color_mask = (on, on)

    def _post_pass(self, vis: bool) -> moderngl.Framebuffer:
        """Distortion warp and sensor noise from the resolved ideal atlas into the output atlas."""
        ctx = self._ctx
        fbo = self._fbo_post[vis]
        fbo.use()
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self._colour_tex.use(0)
        self._id_tex.use(1)
        self._lookup_tex.use(2)
        prog = self._prog_post
        for plan, ivp, ovp in zip(self._plans, self._ideal_vps, self._out_vps):
            fbo.viewport = ovp
            fbo.scissor = ovp
            self._set(prog, "u_use_lookup", plan.lookup_px is not None)
            self._set(prog, "u_shift", (ivp.x - ovp.x, ivp.y - ovp.y))
            self._post_vao.render(moderngl.TRIANGLE_STRIP, vertices=4)
        fbo.scissor = None
        return fbo

    def _read(self, fbo: moderngl.Framebuffer, vis: bool, n_markers: int) -> RenderResult:
        """One readback of the output atlas (and its id attachment), cut into camera images."""
        w, h = self._out_size
        bgra = np.empty((h, w, 4), np.uint8)
        fbo.read_into(bgra, viewport=(0, 0, w, h), components=4, alignment=1)  # RGBA reads are fastest
        bgr = cv2.cvtColor(bgra, cv2.COLOR_BGRA2BGR)
        # Stacked cameras of the atlas width are contiguous views: no copy.
        images = tuple(np.ascontiguousarray(bgr[vp.y : vp.y + vp.h, vp.x : vp.x + vp.w]) for vp in self._out_vps)
        if not vis:
            return RenderResult(images, None)
        marker_pixels = np.zeros((len(self._cameras), n_markers), np.int32)
        if n_markers:
            ids = np.empty((h, w), np.uint16)
            fbo.read_into(ids, viewport=(0, 0, w, h), components=1, attachment=1, alignment=1, dtype="u2")
            for i, vp in enumerate(self._out_vps):
                counts = np.bincount(ids[vp.y : vp.y + vp.h, vp.x : vp.x + vp.w].ravel(), minlength=n_markers + 1)
                marker_pixels[i] = counts[1 : n_markers + 1]
        return RenderResult(images, marker_pixels)


# ----------------------------------------------------------------------------- demo studio
def typical_studio_cameras(size_px: tuple[int, int] = (320, 240), dist=(0.0, 0.0, 0.0, 0.0)) -> list[Camera]:
    """Four cameras 2.3 m around a seated patient (front-left, front-right, left, right).

    Heights 1.6-1.9 m, all aimed at the chest (0, 0.9, 0); the focal length lets the seated
    patient with raised arms fill the image height.
    """
    w, h = size_px
    f_px = 1.4 * h
    cams = []
    for i, (az_deg, height_m) in enumerate(((-40.0, 1.75), (40.0, 1.75), (-105.0, 1.6), (105.0, 1.9))):
        az = np.radians(az_deg)
        eye = (2.3 * np.sin(az), height_m, -2.3 * np.cos(az))  # azimuth 0 = in front (-Z)
        cams.append(Camera.look_at(f"cam{i + 1}", (w, h), f_px, eye, (0.0, 0.9, 0.0), dist=dist))
    return cams


def mannequin_scene(marker_rgb255: Sequence[tuple[int, int, int]] | None = None) -> SceneFrame:
    """A crude seated figure with the 14 upper-limb markers, for benchmarks and previews.

    Not the body model (tracking/sim/body.py): fixed primitives in a plausible seated pose.
    Markers in the order of ``upper_limb_seated``: MB, MP, MLS, MRS, MLE1, MLE2, MRE1, MRE2,
    MLW1, MLW2, MRW1, MRW2, MLH, MRH (left = -X, right = +X).
    """
    skin, shirt, trousers = (224, 172, 140), (70, 95, 150), (55, 55, 65)
    yellow, green, magenta = (255, 214, 0), (0, 200, 70), (225, 0, 210)
    ell_c, ell_a, ell_rgb = [], [], []
    for c, a, col in (
        ((0.0, 0.58, 0.02), (0.17, 0.11, 0.12), trousers),  # pelvis
        ((0.0, 0.88, 0.03), (0.16, 0.27, 0.1), shirt),  # trunk
    ):
        ell_c.append(c)
        ell_a.append(np.diag(a))
        ell_rgb.append(col)
    caps = []  # p0, p1, r0, r1, rgb
    for s in (-1.0, 1.0):
        hip, knee, ankle = (s * 0.1, 0.52, 0.0), (s * 0.12, 0.5, -0.44), (s * 0.12, 0.07, -0.47)
        shoulder, elbow, wrist = (s * 0.19, 1.1, 0.03), (s * 0.26, 0.85, -0.04), (s * 0.24, 0.92, -0.3)
        caps += [
            (hip, knee, 0.08, 0.06, trousers), (knee, ankle, 0.055, 0.04, trousers),
            (shoulder, elbow, 0.05, 0.04, shirt), (elbow, wrist, 0.038, 0.028, skin),
        ]
    caps.append(((0.0, 1.12, 0.03), (0.0, 1.22, 0.03), 0.05, 0.05, skin))  # neck
    sph = [((0.0, 1.32, 0.02), 0.1, skin, -1)]  # head
    for s in (-1.0, 1.0):
        sph.append(((s * 0.24, 0.93, -0.37), 0.045, skin, -1))  # hands
    markers = [
        (0.0, 1.02, -0.1), (0.0, 0.74, -0.1),  # MB, MP
        (-0.2, 1.17, 0.0), (0.2, 1.17, 0.0),  # MLS, MRS
        (-0.31, 0.86, -0.04), (-0.21, 0.85, -0.05), (0.31, 0.86, -0.04), (0.21, 0.85, -0.05),  # elbows
        (-0.28, 0.93, -0.3), (-0.2, 0.92, -0.3), (0.28, 0.93, -0.3), (0.2, 0.92, -0.3),  # wrists
        (-0.24, 0.99, -0.39), (0.24, 0.99, -0.39),  # hands
    ]
    palette = marker_rgb255 or [yellow, yellow, green, green, magenta, magenta, magenta, magenta,
                                green, green, green, green, yellow, yellow]
    for i, p in enumerate(markers):
        sph.append((p, 0.02, palette[i % len(palette)], i))
    f32 = lambda cols: np.asarray(cols, np.float32).reshape(-1, 3) / 255.0  # noqa: E731
    return SceneFrame(
        sphere_centre_m=np.array([s[0] for s in sph], float),
        sphere_radius_m=np.array([s[1] for s in sph], float),
        sphere_rgb=f32([s[2] for s in sph]),
        sphere_marker_index=np.array([s[3] for s in sph], np.int32),
        capsule_p0_m=np.array([c[0] for c in caps], float),
        capsule_p1_m=np.array([c[1] for c in caps], float),
        capsule_r0_m=np.array([c[2] for c in caps], float),
        capsule_r1_m=np.array([c[3] for c in caps], float),
        capsule_rgb=f32([c[4] for c in caps]),
        ellipsoid_centre_m=np.array(ell_c, float),
        ellipsoid_axes_m=np.array(ell_a, float),
        ellipsoid_rgb=f32(ell_rgb),
    )


def atlas_2x2(images: Sequence[np.ndarray]) -> np.ndarray:
    """Tile up to four equally sized (H, W, 3) images into one (2H, 2W, 3) preview."""
    h, w = images[0].shape[:2]
    out = np.zeros((2 * h, 2 * w, 3), np.uint8)
    for i, img in enumerate(images[:4]):
        out[(i // 2) * h : (i // 2 + 1) * h, (i % 2) * w : (i % 2 + 1) * w] = img
    return out


# A moderate barrel lens (OpenCV k1, k2, p1, p2) for benchmarks and previews.
DEMO_LENS = (-0.12, 0.03, 0.0005, -0.0004)


def benchmark(
    n_frames: int = 60,
    sizes: Sequence[tuple[int, int]] = ((320, 240), (640, 480)),
    msaa_values: Sequence[int] = (0, 4),
    lens_values: Sequence[bool] = (False, True),
    with_visibility: bool = True,
) -> dict[str, dict[str, float]]:
    """Speed of the 4-camera demo studio (room, mannequin, 14 markers), readback included.

    The mannequin sways each frame so that instance uploads are real; visibility counts are
    included by default. With ``lens`` the cameras have lens distortion (warp pass) and the
    frames get sensor noise (sigma 2).

    Returns:
        {"WxH msaaN[ lens]": {"fps": frame sets per second (wall clock),
                              "cpu_ms": process CPU time per frame set, all threads}}.
        On a shared machine the CPU time is the steadier figure.
    """
    scene = mannequin_scene()
    results: dict[str, dict[str, float]] = {}
    ctx = create_context()
    try:
        for w, h in sizes:
            for lens in lens_values:
                cameras = typical_studio_cameras((w, h), dist=DEMO_LENS if lens else (0.0, 0.0, 0.0, 0.0))
                for msaa in msaa_values:
                    with StudioRenderer(cameras, msaa=msaa, ctx=ctx) as renderer:
                        renderer.render(scene)  # warm-up: shader compilation
                        t0, c0 = time.perf_counter(), time.process_time()
                        for k in range(n_frames):
                            dx = 0.02 * np.sin(0.3 * k)
                            moved = dataclasses.replace(
                                scene,
                                sphere_centre_m=scene.sphere_centre_m + (dx, 0.0, 0.0),
                                capsule_p0_m=scene.capsule_p0_m + (dx, 0.0, 0.0),
                                capsule_p1_m=scene.capsule_p1_m + (dx, 0.0, 0.0),
                            )
                            renderer.render(moved, with_visibility=with_visibility, noise_sigma=2.0 if lens else 0.0, seed=k)
                        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                    key = f"{w}x{h} msaa{msaa}" + (" lens" if lens else "")
                    results[key] = {"fps": n_frames / wall, "cpu_ms": 1e3 * cpu / n_frames}
                    log.info("4 cameras %s: %.1f frame sets/s, %.1f ms CPU per frame set", key, n_frames / wall, 1e3 * cpu / n_frames)
    finally:
        ctx.release()
    return results


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m tracking.sim.renderer [--frames N] [--preview PNG]``: benchmark and preview."""
    parser = argparse.ArgumentParser(description="Benchmark the studio renderer; optionally save a 2x2 preview.")
    parser.add_argument("--frames", type=int, default=60, help="frame sets per benchmark case (0: no benchmark)")
    parser.add_argument("--preview", default=None, help="write a 2x2 atlas PNG of the demo scene here")
    parser.add_argument("--size", default="320x240", help="preview size WxH")
    parser.add_argument("--msaa", type=int, default=DEFAULT_MSAA, help="preview MSAA samples")
    parser.add_argument("--lens", action="store_true", help="preview with lens distortion and sensor noise")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.preview:
        w, h = (int(v) for v in args.size.lower().split("x"))
        cameras = typical_studio_cameras((w, h), dist=DEMO_LENS if args.lens else (0.0, 0.0, 0.0, 0.0))
        with StudioRenderer(cameras, msaa=args.msaa) as renderer:
            result = renderer.render(mannequin_scene(), noise_sigma=2.0 if args.lens else 0.0)
        cv2.imwrite(args.preview, atlas_2x2(result.images))
        log.info("preview written to %s; marker pixels per camera:\n%s", args.preview, result.marker_pixels)
    if args.frames > 0:
        benchmark(args.frames)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
