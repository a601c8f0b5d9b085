#version 430
// The runtime's per-tile decision on the GPU: the network's raw output (transformed space, one plane
// per metadata `outputs` rate) -> the metric for all six reduced rates -> the shading-rate image.
// A port of rtp.sdk's ModelMetadata.decode (safety margin, inverse transform, extrapolation; paper
// Section 4.3) and select_rates (the cheapest allowed rate whose value passes the threshold, the
// better value among rates of equal cost, else 1x1), one invocation per tile, in float32 where the
// SDK computes in float64 (docs/runtime.md, "The decision on the GPU"). An engine that runs the
// network on the GPU binds its output buffer here and never reads the prediction back.
layout(local_size_x = 8, local_size_y = 8) in;

// the network's output for one frame, planar (C, th, tw) float32 as onnxruntime returns it
layout(std430, binding = 0) readonly buffer Raw { float raw[]; };
// the decoded metric of the six rates, planar (6, th, tw): what sdk's predict returns
layout(std430, binding = 1) writeonly buffer Decoded { float decoded[]; };
// the D3D12 / Vulkan rate codes, one texel a tile (top-left origin: row 0 is the top tile row)
layout(r8ui, binding = 0) uniform writeonly uimage2D u_rates;

uniform ivec2 u_tiles;           // (tw, th): the model's tiles across and down
uniform ivec2 u_grid;            // (columns, rows): the hardware tiles, one texel each
uniform int u_pool;              // hardware tiles of u_pool x u_pool model tiles (1: the model's own)
uniform int u_split;             // or model tiles of u_split x u_split hardware tiles (1: the model's own)
uniform int u_outputs[6];        // the PREDICTED_RATES index of each output plane; -1 past the last
uniform float u_shift;           // safety margin x its conservative direction, added in transformed space
uniform int u_transform;         // 0 clamped, 1 logistic, 2 linear
uniform float u_mu_y;            // clamped, logistic
uniform float u_logistic_k;      // logistic
uniform float u_logistic_span;   // logistic: S(1) - S(0)
uniform vec2 u_logistic_a;      // logistic: shift + S(0) / span, as float32 high + low parts
uniform vec2 u_logistic_b;      // logistic: (1 - S(1)) / span - shift, as float32 high + low parts
uniform float u_factor;          // linear
uniform float u_offset;          // linear
uniform float u_k;               // extrapolation_k
uniform bool u_higher_is_better; // PSNR: values pass above the threshold
uniform float u_threshold;       // in metric units
// a budget's threshold (select_budget_cs.glsl wrote it), read instead of u_threshold where u_budget is set
layout(std430, binding = 2) readonly buffer Budget { float b_threshold; };
uniform bool u_budget;
uniform float u_rate_factors[6]; // metadata rate_factors (PREDICTED_RATES order): each rate's threshold factor
uniform uint u_allowed;          // bit i: PREDICTED_RATES[i] may be chosen (1x2, 2x1, 2x2, 2x4, 4x2, 4x4)
// the engine's own rates, one texel a hardware tile, which the hardware's combiner meets with this image (sdk
// select_rates(engine_rates=, combiner=)): 0 none, else the enum value of min (2), max (3) or sum (4)
layout(r8ui, binding = 1) uniform readonly uimage2D u_engine;
uniform int u_combiner;

float threshold() { return u_budget ? b_threshold : u_threshold; }

const float LOGIT_EPS = 1e-7;
// PREDICTED_RATES order
const int R12 = 0, R21 = 1, R22 = 2, R24 = 3, R42 = 4, R44 = 5;
const uint CODES[6] = uint[6](1u, 4u, 5u, 6u, 9u, 10u);  // sdk.RATE_CODES

// the network output x plus the margin's shift, back to metric units
float inverse_transform(float x, float shift) {
    float p = x + shift;
    if (isnan(p)) return p;  // GLSL's clamp would turn a NaN into a number; numpy's clip keeps it
    if (u_transform == 0) return p * (2.0 * u_mu_y);
    if (u_transform == 1) {
        // S = S(0) + p span = span (x + a) and 1 - S = span ((1 - x) + b), a and b summed in float64 on the CPU
        // and given as high + low float32 parts: where the margin carries p past 0 or 1, S or 1 - S is a few
        // ulps of the terms it is made of, and float32 rounding of the margin, of x + margin or of p span + S(0)
        // missed the SDK's float64 logit by up to 2e-3 of the value. x + a.x and (1 - x) + b.x are exact where
        // they cancel (Sterbenz), the low part then adds what float32 lost; `precise`: not reassociated.
        precise float q = (x + u_logistic_a.x) + u_logistic_a.y;
        precise float q1 = ((1.0 - x) + u_logistic_b.x) + u_logistic_b.y;
        float s = clamp(u_logistic_span * q, LOGIT_EPS, 1.0 - LOGIT_EPS);
        float r = clamp(u_logistic_span * q1, LOGIT_EPS, 1.0 - LOGIT_EPS);
        return u_mu_y + (log(s) - log(r)) / u_logistic_k;
    }
    return (p - u_offset) / u_factor;
}

// the worse of two values; NaN if either is (as numpy's maximum: GLSL's max may return the other operand),
// so a rate extrapolated from a NaN output never passes either
float worse(float a, float b) {
    if (isnan(a) || isnan(b)) return isnan(a) ? a : b;
    return u_higher_is_better ? min(a, b) : max(a, b);
}
// a k times larger error amplitude: k x the error, or 20 log10 k dB less PSNR
float scaled(float v) { return u_higher_is_better ? v - 20.0 * log(u_k) / log(10.0) : v * u_k; }

// the six rates of model tile `at` (sdk ModelMetadata.decode: margin, inverse transform, complete_rates)
void decode(int at, int plane, out float v[6]) {
    bool have[6] = bool[6](false, false, false, false, false, false);
    for (int i = 0; i < 6; ++i) {
        int r = u_outputs[i];
        if (r < 0) break;
        v[r] = inverse_transform(raw[i * plane + at], u_shift);
        have[r] = true;
    }
    if (have[R22] && !have[R12]) { v[R12] = v[R22]; v[R21] = v[R22]; }  // a single 2x2 output: an upper bound
    if (!have[R22]) v[R22] = worse(v[R12], v[R21]);
    if (!have[R24]) { v[R24] = worse(scaled(v[R12]), v[R22]); v[R42] = worse(scaled(v[R21]), v[R22]); }
    if (!have[R44]) v[R44] = worse(v[R24], v[R42]);
}

#include "combine.glsl"

// the image's code beside engine rate `e`: per candidate (the allowed rates cheapest first, then 1x1) the rate the
// device shades and the worse value of the two it may shade; the cheapest passing, then the better value, then
// one shaded as judged, then the first; else the 1x1 candidate. The image holds the rate shaded where combining it
// with the engine's gives it back, else the finest candidate that gives the same.
uint select_beside(float v[6], int e) {
    const int ORDER[7] = int[7](6, 4, 5, 3, 1, 2, 0);  // ALL_RATES indices: cost classes cheapest first, then 1x1
    float thr = u_higher_is_better ? -threshold() : threshold();
    int pick = -1, pick_first = 0, pick_last = 0, pick_area = 0;
    float pick_value = 0.0;
    bool pick_exact = false;
    for (int j = 0; j < 7; ++j) {
        int c = ORDER[j];
        if (!supported(c)) continue;
        int first, last;
        device_rates(combined(e, c), first, last);
        float value = shaded_value(v, first, last);
        int area = SIZE[first].x * SIZE[first].y;
        bool exact = first == last;
        if (!(value < thr)) continue;  // NaN never passes
        if (pick < 0 || area > pick_area || (area == pick_area && (value < pick_value
                || (value == pick_value && exact && !pick_exact)))) {
            pick = c; pick_first = first; pick_last = last; pick_area = area; pick_value = value; pick_exact = exact;
        }
    }
    if (pick < 0) { pick = 0; device_rates(combined(e, 0), pick_first, pick_last); }
    int f0, f1;
    device_rates(combined(e, pick_first), f0, f1);
    if (f0 == pick_first && f1 == pick_last) return ALL_CODES[pick_first];
    for (int k = 0; k < 7; ++k) {  // ALL_RATES order: by area, then the tall one first
        if (!supported(k)) continue;
        device_rates(combined(e, k), f0, f1);
        if (f0 == pick_first && f1 == pick_last) return ALL_CODES[k];
    }
    return ALL_CODES[pick];
}

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);  // a hardware tile
    ivec2 grid = u_grid;
    if (t.x >= grid.x || t.y >= grid.y) return;
    int plane = u_tiles.x * u_tiles.y;

    // the worst of the model tiles the hardware tile covers (sdk pool_tiles; a partial one pools those it has),
    // or on finer hardware tiles the one model tile it lies in (sdk split_tiles)
    float v[6];
    bool first = true;
    for (int dy = 0; dy < u_pool; ++dy) {
        for (int dx = 0; dx < u_pool; ++dx) {
            ivec2 m = t * u_pool / u_split + ivec2(dx, dy);
            if (m.x >= u_tiles.x || m.y >= u_tiles.y) continue;
            float w[6];
            decode(m.y * u_tiles.x + m.x, plane, w);
            for (int r = 0; r < 6; ++r) v[r] = first ? w[r] : worse(v[r], w[r]);
            first = false;
        }
    }
    int out_plane = grid.x * grid.y;
    for (int r = 0; r < 6; ++r) decoded[r * out_plane + t.y * grid.x + t.x] = v[r];

    if (u_combiner != 0) {
        imageStore(u_rates, t, uvec4(select_beside(v, rate_of(imageLoad(u_engine, t).r)), 0u, 0u, 0u));
        return;
    }
    // the cheapest cost class with a passing rate; within a class the better value (the first on a tie);
    // NaN never passes (every comparison with it is false)
    uint code = 0u;  // 1x1
    const int CLASSES[6] = int[6](R44, R24, R42, R22, R12, R21);
    const int CLASS_OF[6] = int[6](0, 1, 1, 2, 3, 3);
    for (int c = 0; c < 4 && code == 0u; ++c) {
        float best = 0.0;
        for (int j = 0; j < 6; ++j) {
            int r = CLASSES[j];
            if (CLASS_OF[j] != c || (u_allowed & (1u << uint(r))) == 0u) continue;
            // against the rate's own threshold (sdk select_rates(factors=)): an error over its factor, a PSNR
            // plus 20 log10 of it
            float f = u_rate_factors[r];
            float e = u_higher_is_better ? -(v[r] + 20.0 * log(f) / log(10.0)) : v[r] / f;
            float thr = u_higher_is_better ? -threshold() : threshold();
            if (e < thr && (code == 0u || e < best)) { code = CODES[r]; best = e; }
        }
    }
    imageStore(u_rates, t, uvec4(code, 0u, 0u, 0u));
}
