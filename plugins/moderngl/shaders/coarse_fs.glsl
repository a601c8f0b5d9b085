#version 330 core
#include "common.glsl"
// Software VRS + tone mapping for one shading rate W x H (u_rate).
// Every pixel of the aligned block (blocks aligned at the image's TOP-LEFT corner) takes the
// lighting of the G-buffer sample at (x0 + W/2, y0 + H/2) in top-left image coordinates, clamped
// to the frame for partial edge blocks (docs/renderer.md "Software VRS": the pixel a point-sampled
// read at a D3D12 coarse pixel's SV_Position, its block's centre, fetches). Where that sample is
// background the block shows the sky, evaluated per pixel (as a coarse pass that discards background
// invocations leaves the full-rate sky). Then exposure (shared by all rates), ACES and sRGB encoding,
// at full rate.
// With u_tile > 0 the rate comes per tile from u_rate_map instead (a VRS rate image: one texel per
// u_tile x u_tile tile, the rate's D3D12 code (log2 W << 2) | log2 H, rows uploaded top-left first
// by write_texture, i.e. stored bottom-up like every texture here).

uniform sampler2D u_lit;
uniform sampler2D u_normal_depth;
uniform ivec2 u_rate;
uniform int u_tile;
uniform sampler2D u_rate_map;
uniform vec2 u_size;
uniform float u_exposure;
uniform mat4 u_inv_proj;
uniform mat3 u_view_to_world;
uniform vec3 u_sky_colour;
uniform vec3 u_to_sun_world;
uniform vec3 u_sun_radiance;

layout(location = 0) out vec4 o_ldr;  // rgb: display-encoded sRGB, a: luma for FXAA
layout(location = 1) out vec4 o_hdr;  // rgb: linear HDR lighting before post-processing (debug)

// Narkowicz's fit of the ACES filmic curve.
vec3 aces(vec3 x) {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}

void main() {
    ivec2 g = ivec2(gl_FragCoord.xy);
    ivec2 size = ivec2(u_size);
    int yt = size.y - 1 - g.y;  // top-left row
    ivec2 rate = u_rate;
    if (u_tile > 0) {
        ivec2 grid = textureSize(u_rate_map, 0);
        int code = int(texelFetch(u_rate_map, ivec2(g.x / u_tile, grid.y - 1 - yt / u_tile), 0).r + 0.5);
        rate = ivec2(1 << (code >> 2), 1 << (code & 3));
    }
    int sx = min((g.x / rate.x) * rate.x + rate.x / 2, size.x - 1);
    int syt = min((yt / rate.y) * rate.y + rate.y / 2, size.y - 1);
    ivec2 s = ivec2(sx, size.y - 1 - syt);

    vec3 hdr;
    if (texelFetch(u_normal_depth, s, 0).w > 0.0) {
        hdr = texelFetch(u_lit, s, 0).rgb;
    } else {
        vec3 d = normalize(u_view_to_world * view_ray(gl_FragCoord.xy, u_size, u_inv_proj));
        hdr = sky_radiance(d, u_sky_colour, u_to_sun_world, u_sun_radiance);
    }
    o_hdr = vec4(hdr, 1.0);
    vec3 ldr = linear_to_srgb(aces(max(hdr, vec3(0.0)) * u_exposure));
    o_ldr = vec4(ldr, display_luma(ldr));
}
