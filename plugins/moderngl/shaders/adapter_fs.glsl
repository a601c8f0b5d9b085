#version 330 core
#include "common.glsl"
// The moderngl adapter: builds a model's input planes on the GPU from an engine's own textures,
// in the channel order the model's metadata declares. The renderer builds its reprojection with
// this same shader, so captured training inputs and run-time inputs come from one code path.
//
// Reprojection (static scene) must agree with rtp.sdk._reproject.reproject (the numpy reference):
//  * the current pixel centre is unprojected with its linear depth onto the pixel's line (a ray from
//    the camera's centre, or parallel lines for an orthographic camera; background: a direction at
//    infinity, or an orthographic camera's far plane) and projected with the previous view-projection;
//  * colour and depth are fetched from the NEAREST previous texel (no filtering);
//  * geometry is seen when the nearest previous texel is geometry and the expected previous depth
//    (previous clip w; an orthographic previous camera's view depth through u_prev_inv_proj) is
//    within u_tolerance (relative) of that texel's depth, or of the bilinear depth of the 2x2
//    footprint when all four are geometry (perspective-correct, 1/z, for a perspective previous
//    camera; plain for an orthographic one);
//  * background is seen when the nearest previous texel is background too;
//  * outside the previous frame or behind the previous camera: unseen; unseen pixels are 0.

uniform sampler2D u_albedo;         // rgb albedo (display-encoded, or linear with u_albedo_linear)
uniform sampler2D u_normal;         // xyz unit normal (view space, or world with u_normal_world)
uniform sampler2D u_depth;          // depth in component u_depth_comp
uniform sampler2D u_prev_colour;    // previous final colour, display-encoded rgb
uniform sampler2D u_prev_depth;     // previous depth in component u_prev_depth_comp
uniform sampler2D u_material;       // roughness, metallic, specular in components u_material_comp
uniform ivec3 u_material_comp;      // component of each; -1: the default (specular 0.5, else 0)
uniform bool u_has_material;
uniform int u_depth_comp;
uniform int u_prev_depth_comp;
uniform bool u_has_prev;
uniform sampler2D u_motion;         // the engine's motion vectors (rg: previous - current, pixels, y down)
uniform bool u_has_motion;
uniform vec2 u_size;
uniform vec2 u_prev_size;           // the previous frame's size (its render resolution: dynamic resolution may change it)
uniform mat4 u_view;                // current world -> view
uniform mat4 u_inv_view;            // current view -> world
uniform mat4 u_inv_proj;            // current projection, inverted
uniform mat4 u_prev_inv_proj;       // previous projection, inverted (window depth; an orthographic previous camera's depth)
uniform mat4 u_prev_vp;             // world -> previous clip
uniform bool u_ortho;               // the current camera is orthographic (sdk.check_reprojection's kinds)
uniform bool u_prev_ortho;          // the previous camera is orthographic
uniform float u_tolerance;
// What the adapter was built for is fixed when it is constructed, so it is compiled in: the adapter
// (_adapter.py) #defines RTP_CHANNELS (28 channel ids, see CHANNEL_IDS; -1 = unused), RTP_COUNT and
// the flags below (true / false). The compiler then drops every value no channel reads; left to
// uniforms, llvmpipe ran all of them (the "reproject" stage of bench/render.py, docs/performance.md).
const bool u_depth_window = RTP_DEPTH_WINDOW;          // depth is window depth in [0, 1] (1 = background), not linear
const bool u_depth_reversed = RTP_DEPTH_REVERSED;      // ... reversed-Z window depth (1 = near plane, 0 = background)
const bool u_albedo_linear = RTP_ALBEDO_LINEAR;
const bool u_clamp_colour = RTP_CLAMP_COLOUR;
const bool u_normal_world = RTP_NORMAL_WORLD;
const bool u_differences = RTP_DIFFERENCES;            // reprojected.y.dx / .dy wanted: reproject the right and lower neighbours too
const bool u_blocks_reprojected = RTP_BLOCKS_REPROJECTED;  // reprojected.y.blocks wanted: reproject the pixel's 4x4 cell
const bool u_blocks_albedo = RTP_BLOCKS_ALBEDO;        // albedo.y.blocks wanted
const bool u_tiles_reprojected = RTP_TILES_REPROJECTED;  // reprojected.y.tiles wanted: the block variances of the pixel's 16x16 tile
const bool u_tiles_albedo = RTP_TILES_ALBEDO;          // albedo.y.tiles wanted
const int u_channels[28] = int[28](RTP_CHANNELS);
const int u_count = RTP_COUNT;
// RTP_LUMA_PASS: the lumas of other pixels (the .dx / .dy neighbours, the 16 texels of a .blocks cell, the 256 of a .tiles tile)
// are fetched from u_luma, which a first run of this shader for ("reprojected.y", "albedo.y") filled,
// instead of reprojecting each neighbour again (up to 18 reprojections a pixel otherwise).
const bool u_luma_pass = RTP_LUMA_PASS;
uniform sampler2D u_luma;           // x: reprojected.y, y: albedo.y of every pixel (with RTP_LUMA_PASS)

layout(location = 0) out vec4 o0;
layout(location = 1) out vec4 o1;
layout(location = 2) out vec4 o2;
layout(location = 3) out vec4 o3;
layout(location = 4) out vec4 o4;
layout(location = 5) out vec4 o5;
layout(location = 6) out vec4 o6;

float linear_depth(float raw, mat4 inv_proj) {
    if (!u_depth_window) return raw;
    if (u_depth_reversed ? raw <= 0.0 : raw >= 1.0) return 0.0;  // cleared depth: background
    // (reversed-Z holds 1 minus the window depth of the same near and far planes: its NDC depth is 1 - 2 raw)
    vec4 p = inv_proj * vec4(0.0, 0.0, u_depth_reversed ? 1.0 - 2.0 * raw : raw * 2.0 - 1.0, 1.0);
    return -p.z / p.w;
}

float depth_at(ivec2 g) { return linear_depth(texelFetch(u_depth, g, 0)[u_depth_comp], u_inv_proj); }
float inv_depth(float d) { return d > 0.0 ? 1.0 / d : 0.0; }

// depth.edge along one axis, as rtp.sdk.depth_edges: the second difference of inverse depth over the
// largest of the three; 0 where a neighbour is off the frame.
float edge_axis(ivec2 g, ivec2 step, float zc) {
    ivec2 a = g - step, b = g + step;
    if (any(lessThan(a, ivec2(0))) || any(greaterThanEqual(b, ivec2(u_size)))) return 0.0;
    float za = inv_depth(depth_at(a)), zb = inv_depth(depth_at(b));
    float top = max(max(za, zb), zc);
    return top > 0.0 ? abs(za + zb - 2.0 * zc) / top : 0.0;
}

float prev_depth_at(ivec2 g) { return linear_depth(texelFetch(u_prev_depth, g, 0)[u_prev_depth_comp], u_prev_inv_proj); }

// The view-space point of GL pixel coordinate `frag` at linear depth d (w = 1), or on background a
// perspective's direction at infinity (w = 0) and an orthographic camera's far-plane point.
vec4 view_point(vec2 frag, float d) {
    if (!u_ortho) {
        vec3 ray = view_ray(frag, u_size, u_inv_proj);
        return d > 0.0 ? vec4(ray * d, 1.0) : vec4(normalize(ray), 0.0);
    }
    mat4 ip = u_inv_proj / u_inv_proj[3][3];      // (last row 0, 0, 0, 1: no divide)
    vec3 c = (ip * vec4(frag / u_size * 2.0 - 1.0, 0.0, 1.0)).xyz;  // the line's point at NDC z = 0
    float z = d > 0.0 ? (-d - c.z) / ip[2][2] : 1.0;  // the NDC z of depth d; the far plane's
    return vec4(c + ip[2].xyz * z, 1.0);
}

vec4 reproject_prev(vec2 frag, float d) {
    ivec2 size = ivec2(u_prev_size);
    vec4 pc = u_prev_vp * (u_inv_view * view_point(frag, d));
    if (pc.w <= 0.0) return vec4(0.0);
    float e = pc.w;                                // the expected previous linear depth
    if (u_prev_ortho) {
        vec4 v = u_prev_inv_proj * pc;
        e = v.w > 0.0 ? -v.z / v.w : 0.0;
        if (e <= 0.0) return vec4(0.0);            // behind the previous camera
    }
    vec2 q = (pc.xy / pc.w * 0.5 + 0.5) * u_prev_size;  // previous GL pixel coordinates (the previous frame's)
    if (u_has_motion && d > 0.0) {                 // the engine's motion places geometry (objects move); the
        vec2 m = texelFetch(u_motion, ivec2(frag), 0).xy;  // expected depth stays the camera's, e
        q = (frag + vec2(m.x, -m.y)) * (u_prev_size / u_size);  // (this frame's pixels to the previous frame's)
    }
    if (any(lessThan(q, vec2(0.0))) || any(greaterThanEqual(q, u_prev_size))) return vec4(0.0);
    ivec2 pi = ivec2(floor(q));
    float pd = prev_depth_at(pi);
    bool seen;
    if (d > 0.0) {
        seen = pd > 0.0 && abs(pd - e) <= u_tolerance * e;
        if (!seen && pd > 0.0) {
            vec2 f = q - 0.5;
            ivec2 o = ivec2(floor(f));
            vec2 t = f - vec2(o);
            ivec2 o0 = clamp(o, ivec2(0), size - 1);
            ivec2 o1 = clamp(o + 1, ivec2(0), size - 1);
            float d00 = prev_depth_at(ivec2(o0.x, o0.y));
            float d10 = prev_depth_at(ivec2(o1.x, o0.y));
            float d01 = prev_depth_at(ivec2(o0.x, o1.y));
            float d11 = prev_depth_at(ivec2(o1.x, o1.y));
            if (min(min(d00, d10), min(d01, d11)) > 0.0) {
                float bil = u_prev_ortho ? mix(mix(d00, d10, t.x), mix(d01, d11, t.x), t.y)
                                         : 1.0 / mix(mix(1.0 / d00, 1.0 / d10, t.x), mix(1.0 / d01, 1.0 / d11, t.x), t.y);
                seen = abs(bil - e) <= u_tolerance * e;
            }
        }
    } else {
        seen = pd <= 0.0;
    }
    // a colour outside [0, 1] (an HDR frame not yet tonemapped) is clamped to the display range sdk.CHANNELS gives
    vec3 colour = texelFetch(u_prev_colour, pi, 0).rgb;
    return seen ? vec4(u_clamp_colour ? clamp(colour, 0.0, 1.0) : colour, 1.0) : vec4(0.0);
}

// *.y.blocks, as rtp.sdk.block_variances: per 4x4 cell (top-left origin, edge repeated past the frame)
// the log variance inside the blocks of rate k (1x2, 2x1, 2x2, 2x4, 4x2, 4x4) on the cell's k-th pixel.
const ivec2 BLOCK_RATES[6] = ivec2[6](ivec2(1, 2), ivec2(2, 1), ivec2(2, 2), ivec2(2, 4), ivec2(4, 2), ivec2(4, 4));
const float BLOCK_EPS = 1e-4;

float block_value(float vals[16], ivec2 rate) {
    float acc = 0.0;
    int blocks = 0;
    for (int by = 0; by < 4; by += rate.y) {
        for (int bx = 0; bx < 4; bx += rate.x) {
            float s = 0.0, s2 = 0.0;
            for (int y = by; y < by + rate.y; ++y)
                for (int x = bx; x < bx + rate.x; ++x) { float v = vals[y * 4 + x]; s += v; s2 += v * v; }
            float n = float(rate.x * rate.y);
            float m = s / n;
            acc += max(s2 / n - m * m, 0.0);
            blocks += 1;
        }
    }
    return clamp(log(acc / float(blocks) + BLOCK_EPS) / -log(BLOCK_EPS) + 1.0, 0.0, 1.0);
}

// The GL pixel of top-left (column, row), clamped to the frame.
ivec2 top_left_texel(int col, int row) {
    ivec2 size = ivec2(u_size);
    return ivec2(min(col, size.x - 1), size.y - 1 - min(row, size.y - 1));
}

float albedo_luma_at(ivec2 t) {
    if (u_luma_pass) return texelFetch(u_luma, t, 0).y;
    if (depth_at(t) <= 0.0) return 0.0;
    vec3 a = texelFetch(u_albedo, t, 0).rgb;
    return display_luma(clamp(u_albedo_linear ? linear_to_srgb(a) : a, 0.0, 1.0));
}

float reprojected_luma_at(ivec2 t) {
    if (u_luma_pass) return texelFetch(u_luma, t, 0).x;
    return display_luma(reproject_prev(vec2(t) + 0.5, depth_at(t)).rgb);
}

// *.y.tiles, as rtp.sdk.tile_variances: per 16x16 tile, value j (0-11) on pixel (j / 4, j % 4) of the tile:
// for rate k = j % 6, over the tile's 4x4 cells inside the frame, the mean (j < 6, as log(mean of
// exp(s (v - 1))) / s + 1) or the maximum (j >= 6) of the cells' .blocks values v.
float tile_value(bool reprojected, int j, int c0, int r0) {
    ivec2 rate = BLOCK_RATES[j % 6];
    float s = -log(BLOCK_EPS);
    float acc = 0.0, top = 0.0;
    int cells = 0;
    for (int cy = 0; cy < 4; ++cy) {
        for (int cx = 0; cx < 4; ++cx) {
            int x0 = c0 + 4 * cx, y0 = r0 + 4 * cy;
            if (x0 >= int(u_size.x) || y0 >= int(u_size.y)) continue;
            float vals[16];
            for (int i = 0; i < 16; ++i) {
                ivec2 t = top_left_texel(x0 + i % 4, y0 + i / 4);
                vals[i] = reprojected ? reprojected_luma_at(t) : albedo_luma_at(t);
            }
            float v = block_value(vals, rate);
            acc += exp(s * (v - 1.0));
            top = max(top, v);
            cells += 1;
        }
    }
    return j < 6 ? log(acc / float(cells)) / s + 1.0 : top;
}

// motion.x / motion.y, as rtp.sdk.input_planes: each geometry pixel's previous minus current position in this
// frame's pixels (x right, y down): the engine's motion vectors where given, else the camera's move (its point
// projected with the previous view-projection); 0 on background, where the point was behind the previous
// camera, and without a previous frame.
vec2 motion_at(vec2 frag, float d) {
    if (d <= 0.0 || !u_has_prev) return vec2(0.0);
    if (u_has_motion) return texelFetch(u_motion, ivec2(frag), 0).xy;
    vec4 pc = u_prev_vp * (u_inv_view * view_point(frag, d));
    if (pc.w <= 0.0) return vec2(0.0);
    vec2 q = (pc.xy / pc.w * 0.5 + 0.5) * u_size;  // (GL pixel coordinates: y up)
    return vec2(q.x - frag.x, frag.y - q.y);
}

void main() {
    ivec2 g = ivec2(gl_FragCoord.xy);
    float d = depth_at(g);
    bool geo = d > 0.0;
    vec4 rp = u_has_prev ? reproject_prev(gl_FragCoord.xy, d) : vec4(0.0);
    // reprojected.y.dx / .dy, as rtp.sdk.pixel_differences: |luma| to the right neighbour and to the one
    // below (top-left origin: GL row - 1), each reprojected as itself; 0 in the last column / row
    float ry = u_luma_pass ? reprojected_luma_at(g) : display_luma(rp.rgb);
    float rdx = 0.0, rdy = 0.0;
    if (u_has_prev && u_differences) {
        if (g.x + 1 < int(u_size.x))
            rdx = abs(reprojected_luma_at(g + ivec2(1, 0)) - ry);
        if (g.y > 0)
            rdy = abs(reprojected_luma_at(g - ivec2(0, 1)) - ry);
    }
    vec3 albedo = texelFetch(u_albedo, g, 0).rgb;
    if (u_albedo_linear) albedo = linear_to_srgb(albedo);
    albedo = clamp(albedo, 0.0, 1.0);  // (as the previous frame's colour, and the material below)
    vec3 n = texelFetch(u_normal, g, 0).xyz;
    if (u_normal_world) n = mat3(u_view) * n;
    float n_length = length(n);  // a zero normal on geometry (a degenerate mesh's) reads 0 like the background, not NaN
    n = geo && n_length > 0.0 ? n / n_length : vec3(0.0);
    if (!geo) albedo = vec3(0.0);
    vec3 mat = vec3(0.0, 0.0, 0.5);
    if (u_has_material) {
        vec4 m = texelFetch(u_material, g, 0);
        for (int i = 0; i < 3; ++i) if (u_material_comp[i] >= 0) mat[i] = m[u_material_comp[i]];
    }
    mat = geo ? clamp(mat, 0.0, 1.0) : vec3(0.0);
    float rblocks = 0.0, ablocks = 0.0;
    int row = int(u_size.y) - 1 - g.y;  // top-left origin
    int k = (row % 4) * 4 + g.x % 4;
    if (k < 6 && (u_blocks_albedo || (u_blocks_reprojected && u_has_prev))) {
        int r0 = row - row % 4, c0 = g.x - g.x % 4;
        float av[16], rv[16];
        for (int i = 0; i < 16; ++i) {
            ivec2 t = top_left_texel(c0 + i % 4, r0 + i / 4);
            av[i] = u_blocks_albedo ? albedo_luma_at(t) : 0.0;
            rv[i] = (u_blocks_reprojected && u_has_prev) ? reprojected_luma_at(t) : 0.0;
        }
        if (u_blocks_albedo) ablocks = block_value(av, BLOCK_RATES[k]);
        if (u_blocks_reprojected && u_has_prev) rblocks = block_value(rv, BLOCK_RATES[k]);
    }
    float rtiles = 0.0, atiles = 0.0;
    int trow = row % 16, tcol = g.x % 16;
    if (trow < 3 && tcol < 4 && (u_tiles_albedo || (u_tiles_reprojected && u_has_prev))) {
        int j = trow * 4 + tcol;
        if (u_tiles_albedo) atiles = tile_value(false, j, g.x - tcol, row - trow);
        if (u_tiles_reprojected && u_has_prev) rtiles = tile_value(true, j, g.x - tcol, row - trow);
    }
    float zc = inv_depth(d);
    float edge = clamp(max(edge_axis(g, ivec2(1, 0), zc), edge_axis(g, ivec2(0, 1), zc)), 0.0, 1.0);
    vec2 motion = motion_at(gl_FragCoord.xy, d);
    float v[25] = float[25](rp.r, rp.g, rp.b, rp.a, albedo.r, albedo.g, albedo.b, n.x, n.y, n.z, d,
                            mat.x, mat.y, mat.z, edge, ry, display_luma(albedo), rdx, rdy, rblocks, ablocks,
                            rtiles, atiles, motion.x, motion.y);
    float outv[28];
    for (int i = 0; i < 28; ++i) outv[i] = (i < u_count && u_channels[i] >= 0) ? v[u_channels[i]] : 0.0;
    o0 = vec4(outv[0], outv[1], outv[2], outv[3]);
    o1 = vec4(outv[4], outv[5], outv[6], outv[7]);
    o2 = vec4(outv[8], outv[9], outv[10], outv[11]);
    o3 = vec4(outv[12], outv[13], outv[14], outv[15]);
    o4 = vec4(outv[16], outv[17], outv[18], outv[19]);
    o5 = vec4(outv[20], outv[21], outv[22], outv[23]);
    o6 = vec4(outv[24], outv[25], outv[26], outv[27]);
}
