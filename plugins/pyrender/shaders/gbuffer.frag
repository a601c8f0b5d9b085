#version 330 core
// rtp G-buffer variant of pyrender 0.1.45's shaders/mesh.frag (MIT licence, Matthew Matl).
// It links with gbuffer.vert (pyrender's mesh.vert plus frag_mirrored) and receives the same defines
// and uniforms, so pyrender's renderer binds it exactly like its lit shader. Instead of lighting it writes one
// G-buffer pass, chosen by RTP_GBUF_MODE, into pyrender's 8-bit RGB colour target:
//   1: display-encoded (sRGB) base colour, 8 bits per channel;
//   2: three scalars (slots RTP_SLOT_R, RTP_SLOT_G, RTP_SLOT_B), 8 bits each;
//   3: two scalars (slots RTP_SLOT_P, RTP_SLOT_Q), 12 bits each, packed across R, G and B.
// Slots: 0 none, 1 normal.x, 2 normal.y, 3 normal.z (view space, mapped from [-1, 1] to [0, 1]),
// 4 roughness, 5 metallic (factor x metallic-roughness texture R / G: the channels pyrender 0.1.45's
// mesh.frag shades with, where glTF says G / B; specular-glossiness materials: 1 - glossiness, 0).
// Alpha is always 1, which turns pyrender's alpha blending (alphaMode BLEND) into a plain write.
// pyrender substitutes defines textually: no define name here is a substring of another name.

struct Material {
    vec3 emissive_factor;

#ifdef USE_METALLIC_MATERIAL
    vec4 base_color_factor;
    float metallic_factor;
    float roughness_factor;
#endif

#ifdef USE_GLOSSY_MATERIAL
    vec4 diffuse_factor;
    vec3 specular_factor;
    float glossiness_factor;
#endif

#ifdef HAS_NORMAL_TEX
    sampler2D normal_texture;
#endif
#ifdef HAS_OCCLUSION_TEX
    sampler2D occlusion_texture;
#endif
#ifdef HAS_EMISSIVE_TEX
    sampler2D emissive_texture;
#endif
#ifdef HAS_BASE_COLOR_TEX
    sampler2D base_color_texture;
#endif
#ifdef HAS_METALLIC_ROUGHNESS_TEX
    sampler2D metallic_roughness_texture;
#endif
#ifdef HAS_DIFFUSE_TEX
    sampler2D diffuse_texture;
#endif
#ifdef HAS_SPECULAR_GLOSSINESS_TEX
    sampler2D specular_glossiness;
#endif
};

uniform Material material;
uniform mat4 V;          // world -> view, set by pyrender for mesh.vert
uniform vec3 cam_pos;

in vec3 frag_position;   // world space
#ifdef NORMAL_LOC
in vec3 frag_normal;     // world space
#endif
#ifdef HAS_NORMAL_TEX
#ifdef TANGENT_LOC
#ifdef NORMAL_LOC
in mat3 tbn;
#endif
#endif
#endif
#ifdef TEXCOORD_0_LOC
in vec2 uv_0;
#endif
#ifdef TEXCOORD_1_LOC
in vec2 uv_1;
#endif
#ifdef COLOR_0_LOC
in vec4 color_multiplier;
#endif
flat in int frag_mirrored;  // gbuffer.vert: 1 where the node's pose times the instance's mirrors

out vec4 frag_color;

vec3 srgb_to_linear(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(0.04045, c));
}

vec3 linear_to_srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

// World-space shading normal, as pyrender's get_normal() computes it (normal maps included), but
// with the geometric normal (screen-space derivatives) where the mesh has no normals, where
// pyrender would use the direction to the camera.
// Set by world_normal(): the normal is the geometric one, turned to face the camera, which is right
// for back faces too, so view_normal() must not flip it.
bool g_geometric = false;

// The geometric normal (screen-space derivatives), facing the camera whichever way the frame's rows run.
vec3 geometric_normal() {
    vec3 n = cross(dFdx(frag_position), dFdy(frag_position));
    n = dot(n, n) > 0.0 ? normalize(n) : normalize(cam_pos - frag_position);
    return dot(n, cam_pos - frag_position) < 0.0 ? -n : n;
}

vec3 world_normal() {
#ifdef NORMAL_LOC
    // a zero normal (a degenerate vertex's) takes the geometric one, as a mesh without normals does;
    // pyrender's mesh.vert has normalised it already, so it arrives NaN (no comparison holds) or zero
    g_geometric = !(dot(frag_normal, frag_normal) > 0.0);
    vec3 ng = g_geometric ? geometric_normal() : normalize(frag_normal);
#else
    g_geometric = true;
    vec3 ng = geometric_normal();
#endif
#ifdef HAS_NORMAL_TEX
#ifdef TEXCOORD_0_LOC
#ifdef HAS_TANGENTS
    mat3 tbn_n = tbn;
#else
    vec3 pos_dx = dFdx(frag_position);
    vec3 pos_dy = dFdy(frag_position);
    vec3 tex_dx = dFdx(vec3(uv_0, 0.0));
    vec3 tex_dy = dFdy(vec3(uv_0, 0.0));
    vec3 t = (tex_dy.t * pos_dx - tex_dx.t * pos_dy) / (tex_dx.s * tex_dy.t - tex_dy.s * tex_dx.t);
    t = normalize(t - ng * dot(ng, t));
    vec3 b = normalize(cross(ng, t));
    mat3 tbn_n = mat3(t, b, ng);
#endif
    vec3 nt = texture(material.normal_texture, uv_0).rgb;
    return normalize(tbn_n * (2.0 * nt - 1.0));
#else
    return ng;
#endif
#else
    return ng;
#endif
}

// Linear base colour (glTF: factor x sRGB-decoded texture x vertex colour).
vec3 base_colour() {
    vec4 c = vec4(1.0);
#ifdef USE_METALLIC_MATERIAL
    c = material.base_color_factor;
#ifdef HAS_BASE_COLOR_TEX
    vec4 t = texture(material.base_color_texture, uv_0);
    c *= vec4(srgb_to_linear(t.rgb), t.a);
#endif
#endif
#ifdef USE_GLOSSY_MATERIAL
    c = material.diffuse_factor;
#ifdef HAS_DIFFUSE_TEX
    vec4 t = texture(material.diffuse_texture, uv_0);
    c *= vec4(srgb_to_linear(t.rgb), t.a);
#endif
#endif
#ifdef COLOR_0_LOC
    c *= color_multiplier;
#endif
    return c.rgb;
}

vec3 view_normal() {
    vec3 n = world_normal();
    // two-sided surfaces: back faces show the flipped normal. A mirrored node or instance (negative determinant
    // of M * inst_m) turns its triangles' winding on screen, so its front faces arrive with gl_FrontFacing false
    bool front = gl_FrontFacing != (frag_mirrored != 0);
    if (!front && !g_geometric) n = -n;
    return normalize(mat3(V) * n);
}

// GGX perceptual roughness and metalness, read as pyrender's mesh.frag reads them: the model must see
// the parameters the displayed image is shaded with (for a metallic-roughness texture pyrender reads
// roughness from R and metalness from G, not glTF's G and B).
vec2 roughness_metallic() {
    vec2 rm = vec2(1.0, 0.0);
#ifdef USE_METALLIC_MATERIAL
    rm = vec2(material.roughness_factor, material.metallic_factor);
#ifdef HAS_METALLIC_ROUGHNESS_TEX
    rm *= texture(material.metallic_roughness_texture, uv_0).rg;
#endif
#endif
#ifdef USE_GLOSSY_MATERIAL
    float gloss = material.glossiness_factor;
#ifdef HAS_SPECULAR_GLOSSINESS_TEX
    gloss *= texture(material.specular_glossiness, uv_0).a;
#endif
    rm = vec2(1.0 - gloss, 0.0);
#endif
    return clamp(rm, 0.0, 1.0);
}

float slot(int id, vec3 n) {  // a scalar mapped to [0, 1]
    if (id == 1) return n.x * 0.5 + 0.5;
    if (id == 2) return n.y * 0.5 + 0.5;
    if (id == 3) return n.z * 0.5 + 0.5;
    if (id == 4) return roughness_metallic().x;
    if (id == 5) return roughness_metallic().y;
    return 0.0;
}

void main() {
#if RTP_GBUF_MODE == 1
    frag_color = vec4(linear_to_srgb(base_colour()), 1.0);
#elif RTP_GBUF_MODE == 2
    vec3 n = view_normal();
    frag_color = vec4(slot(RTP_SLOT_R, n), slot(RTP_SLOT_G, n), slot(RTP_SLOT_B, n), 1.0);
#else
    vec3 n = view_normal();
    uint a = uint(clamp(slot(RTP_SLOT_P, n), 0.0, 1.0) * 4095.0 + 0.5);
    uint b = uint(clamp(slot(RTP_SLOT_Q, n), 0.0, 1.0) * 4095.0 + 0.5);
    uvec3 bytes = uvec3(a >> 4u, ((a & 15u) << 4u) | (b >> 8u), b & 255u);
    frag_color = vec4(vec3(bytes) / 255.0, 1.0);
#endif
}
