// Shared helpers, pasted into other shaders by the renderer's include step (_load_source).
// Conventions: GL pixel coordinates (gl_FragCoord, texelFetch) have a bottom-left origin inside the
// shaders; images are flipped to a top-left origin exactly once, when read back on the CPU.

const float PI = 3.14159265358979;

vec3 srgb_to_linear(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c / 12.92, pow((c + 0.055) / 1.055, vec3(2.4)), step(0.04045, c));
}

vec3 linear_to_srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

float luminance(vec3 c) { return dot(c, vec3(0.2126, 0.7152, 0.0722)); }

// Rec.601 luma of display-encoded colour (rtp.sdk.luma, sdk.LUMA_WEIGHTS): what the metrics measure.
float display_luma(vec3 c) { return dot(c, vec3(0.299, 0.587, 0.114)); }

// Point on the view ray through GL pixel coordinate `frag` (pixel centres at .5), scaled so that
// its view-space z is -1. `inv_proj` is the inverse of the current projection matrix.
vec3 view_ray(vec2 frag, vec2 size, mat4 inv_proj) {
    vec2 ndc = frag / size * 2.0 - 1.0;
    vec4 q = inv_proj * vec4(ndc, -1.0, 1.0);
    vec3 r = q.xyz / q.w;
    return r / -r.z;
}

// Sky radiance (linear) seen in world direction `d`: a vertical gradient from a bright, desaturated
// horizon to the scene's sky colour at the zenith and a dark ground below, plus a soft sun glow.
vec3 sky_radiance(vec3 d, vec3 sky_colour, vec3 to_sun, vec3 sun_radiance) {
    float y = clamp(d.y, -1.0, 1.0);
    vec3 horizon = mix(sky_colour, vec3(luminance(sky_colour)), 0.6) * 1.35 + 0.05;
    vec3 ground = sky_colour * 0.25;
    vec3 c = y >= 0.0 ? mix(horizon, sky_colour, sqrt(y)) : mix(horizon, ground, sqrt(-y));
    float s = max(dot(d, to_sun), 0.0);
    c += sun_radiance * (0.03 * pow(s, 16.0) + 1.5 * pow(s, 1024.0));
    return c;
}
