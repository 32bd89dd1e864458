"""GLSL shared by the simulator's cameras and the game's avatar: the screen box of an ellipsoid,
and the vertices of the band tangent to a capsule's two end spheres.

Ellipsoids are ray-cast on a screen-space quad that bounds their exact outline: with M the
clip-from-unit-sphere matrix (clip_from_world times the ellipsoid's axes and centre), the
outline is the conic of the dual quadric M diag(1, 1, 1, -1) M^T, and its extreme x and y in
normalised device coordinates solve a quadratic each.
"""

OUTLINE_BOX_GLSL = """
float dual(vec4 a, vec4 b) { return dot(a.xyz, b.xyz) - a.w * b.w; }

// The NDC box (lo, hi) of the outline of the ellipsoid m * unit sphere (m: clip from unit-sphere
// coordinates); false when the ellipsoid is not wholly in front of the camera.
bool outline_box(mat4 m, out vec2 lo, out vec2 hi) {
    vec4 rx = vec4(m[0][0], m[1][0], m[2][0], m[3][0]);  // rows x, y, w: clip from unit sphere
    vec4 ry = vec4(m[0][1], m[1][1], m[2][1], m[3][1]);
    vec4 rw = vec4(m[0][3], m[1][3], m[2][3], m[3][3]);
    float cxx = dual(rx, rx), cyy = dual(ry, ry), cww = dual(rw, rw);
    float cxw = dual(rx, rw), cyw = dual(ry, rw);
    float disc_x = cxw * cxw - cxx * cww;
    float disc_y = cyw * cyw - cyy * cww;
    if (!(cww < 0.0 && disc_x >= 0.0 && disc_y >= 0.0)) return false;
    vec2 k0 = vec2(cxw - sqrt(disc_x), cyw - sqrt(disc_y)) / cww;
    vec2 k1 = vec2(cxw + sqrt(disc_x), cyw + sqrt(disc_y)) / cww;
    lo = min(k0, k1);
    hi = max(k0, k1);
    return true;
}

// This vertex's corner (from gl_VertexID, strip order (0,0), (0,1), (1,0), (1,1)) of the quad
// over the outline of m * unit sphere, padded by pad_ndc; the whole viewport when the ellipsoid
// straddles the camera plane (the ray cast sorts it out).
vec2 outline_quad_corner(mat4 m, vec2 pad_ndc) {
    vec2 corner = vec2(float((gl_VertexID >> 1) & 1), float(gl_VertexID & 1));
    vec2 lo, hi;
    if (outline_box(m, lo, hi)) return clamp(mix(lo - pad_ndc, hi + pad_ndc, corner), -1.0, 1.0);
    return corner * 2.0 - 1.0;
}
"""

# A tapered capsule's side: the cone tangent to its end spheres (p0, r.x) and (p1, r.y), as an
# instanced band mesh whose vertices are (cos theta, sin theta, t) with t 0 at p0 and 1 at p1.
BAND_GLSL = """
void band_vertex(vec3 p0, vec3 p1, vec2 r, vec3 ring, out vec3 pos, out vec3 n) {
    vec3 axis = p1 - p0;
    float d = max(length(axis), 1e-9);
    axis /= d;
    // The cone tangent to both end spheres: its normal tilts by asin((r0 - r1) / d) towards p1.
    float s = clamp((r.x - r.y) / d, -1.0, 1.0);
    float c = sqrt(max(1.0 - s * s, 0.0));
    vec3 helper = abs(axis.y) < 0.9 ? vec3(0.0, 1.0, 0.0) : vec3(1.0, 0.0, 0.0);
    vec3 u = normalize(cross(helper, axis));
    vec3 v = cross(axis, u);  // (u, v, axis) right-handed: keeps the mesh's outward winding
    n = s * axis + c * (ring.x * u + ring.y * v);
    bool at_p1 = ring.z > 0.5;
    pos = (at_p1 ? p1 : p0) + (at_p1 ? r.y : r.x) * n;
}
"""
