#version 330 core
#include "common.glsl"
// G-buffer MRT pass. Every target is cleared to 0, so background stays 0 in every channel.

uniform sampler2D u_texture;   // sRGB8_ALPHA8: samples return linear values
uniform bool u_has_texture;
uniform vec4 u_base_color;     // sRGB-encoded factors, alpha last
uniform float u_alpha_cutoff;  // < 0: no alpha test
uniform vec3 u_material;       // roughness, metallic, specular
uniform vec3 u_emissive;       // linear radiance
uniform bool u_has_prev;
uniform vec2 u_size;

in vec3 v_pos_view;
in vec3 v_normal_view;
in vec2 v_uv;
in vec4 v_prev_clip;

layout(location = 0) out vec4 o_albedo;        // rgb: display-encoded albedo, a: coverage (1)
layout(location = 1) out vec4 o_normal_depth;  // xyz: unit view-space normal, w: linear depth (m)
layout(location = 2) out vec4 o_material;      // roughness, metallic, specular, emissive luminance (display)
layout(location = 3) out vec4 o_emissive;      // rgb: linear emissive radiance
layout(location = 4) out vec2 o_motion;        // pixels, previous - current, x right, y down

void main() {
    vec4 albedo = u_base_color;
    if (u_has_texture) {
        vec4 t = texture(u_texture, v_uv);
        albedo = vec4(linear_to_srgb(t.rgb), t.a) * u_base_color;
    }
    if (u_alpha_cutoff >= 0.0 && albedo.a < u_alpha_cutoff) discard;

    vec3 n = v_normal_view;
    if (dot(n, n) > 0.0) {
        n = normalize(n);
        if (!gl_FrontFacing) n = -n;  // two-sided: back faces are shaded with the flipped normal
    } else {  // a mesh's zero normal (degenerate, or none given): the geometric one, facing the camera, not NaN
        n = cross(dFdx(v_pos_view), dFdy(v_pos_view));
        n = dot(n, n) > 0.0 ? normalize(n) : vec3(0.0, 0.0, 1.0);
        if (dot(n, v_pos_view) > 0.0) n = -n;
    }

    o_albedo = vec4(clamp(albedo.rgb, 0.0, 1.0), 1.0);
    o_normal_depth = vec4(n, -v_pos_view.z);
    float e = luminance(u_emissive);
    o_material = vec4(clamp(u_material, 0.0, 1.0), linear_to_srgb(vec3(e)).r);
    o_emissive = vec4(u_emissive, 0.0);

    vec2 motion = vec2(0.0);
    // 0 where the point was behind the previous camera (w <= 0), as rtp.sdk.input_planes' motion planes: the
    // division by max(w, 1e-6) gave 1e7-1e8 pixels there (until 2026-12-07)
    if (u_has_prev && v_prev_clip.w > 0.0) {
        vec2 prev_px = (v_prev_clip.xy / v_prev_clip.w * 0.5 + 0.5) * u_size;
        vec2 d = prev_px - gl_FragCoord.xy;
        motion = vec2(d.x, -d.y);  // GL y grows upwards; images grow downwards
    }
    o_motion = motion;
}
