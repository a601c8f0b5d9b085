#version 430
// A budget on the GPU: the lowest threshold whose rates save at least a share of the shading work (sdk
// select_rates_for_saving), from the decoded values select_rates_cs.glsl wrote for the hardware tiles. One
// workgroup; no read-back: the threshold is written to a buffer the selection pass reads.
//
// A tile's saving only grows with the threshold, one step per cost class of the allowed rates: it saves class
// k's share once the threshold passes T_k, the smallest (oriented) value of the allowed rates that cost no more
// than class k. The frame's saving is a sum of those steps; the lowest threshold that reaches the need is just
// above the step where the sorted, weighted steps add up to it. Here that step is found by a radix select over
// the float32 values in their order (an order-preserving 32-bit key of their bits): four rounds, each a
// histogram of the next 8 bits of the keys that share the digits found so far, in shared memory; the first bin
// whose sum, added to everything below it, reaches the need gives the next digit. Exact in integers: a step's
// gain is the tile's pixels times the share it adds, in sixteenths (8, 4, 2, 1 for 2, 4, 8, 16 pixels a sample),
// and integer sums do not depend on the order the invocations add them in.
layout(local_size_x = 256) in;

// the decoded metric of the six rates, planar (6, rows, columns) on the hardware tiles (select_rates_cs.glsl)
layout(std430, binding = 1) readonly buffer Decoded { float decoded[]; };
// out: the threshold found (metric units; the selection pass reads it) and the work its rates save, in
// sixteenths of a pixel's shading (of a tile's where u_frame is 0)
layout(std430, binding = 2) writeonly buffer Budget { float b_threshold; uint b_saved; };

uniform ivec2 u_grid;            // (columns, rows): the hardware tiles
uniform ivec2 u_frame;           // (width, height) in pixels; (0, 0): every tile counts alike
uniform int u_tile;              // the hardware tile's side in pixels
uniform bool u_higher_is_better; // PSNR: values pass above the threshold
uniform float u_rate_factors[6]; // metadata rate_factors (PREDICTED_RATES order)
uniform uint u_allowed;          // bit i: PREDICTED_RATES[i] may be chosen
uniform uint u_need;             // the work to save, in sixteenths of a pixel (of a tile where u_frame is 0)
uniform float u_lo;              // the lowest oriented threshold allowed (0; -MAX_THRESHOLD for PSNR)
uniform float u_hi;              // the highest (MAX_THRESHOLD)
uniform bool u_has_floor;        // a threshold under the budget: the higher (PSNR: lower) of the two
uniform float u_floor;           // in metric units
// the engine's own rates, one texel a hardware tile, which the hardware's combiner meets with the image (sdk
// select_rates_for_saving(engine_rates=, combiner=)): 0 none, else the enum value of min (2), max (3) or sum (4)
layout(r8ui, binding = 1) uniform readonly uimage2D u_engine;
uniform int u_combiner;

#include "combine.glsl"

const int AREA[6] = int[6](2, 2, 4, 8, 8, 16);  // PREDICTED_RATES: 1x2 2x1 2x2 2x4 4x2 4x4
const uint NAN_KEY = 0xffffffffu;              // NaN, +inf or past u_hi: never passes (-inf passes at any threshold)

shared uint s_sum[256];
shared uint s_hist[256];
shared uint s_digit, s_below, s_need;

// float32 values in their order as unsigned integers (negative values' bits reversed, positive ones' sign set); a
// value at or past the highest threshold, which none passes, is no step (it was one, and a frame that could not reach
// its need reported u_hi rather than the lowest threshold saving what it can, as the SDK does)
uint key_of(float v) {
    if (isnan(v) || v >= u_hi) return NAN_KEY;
    uint b = floatBitsToUint(v);
    return (b & 0x80000000u) != 0u ? ~b : b | 0x80000000u;
}
float value_of(uint k) { return uintBitsToFloat((k & 0x80000000u) != 0u ? k & 0x7fffffffu : ~k); }

uint weight(int at) {
    if (u_frame.x == 0) return 1u;
    ivec2 t = ivec2(at % u_grid.x, at / u_grid.x);
    ivec2 size = min(ivec2(u_tile), u_frame - t * u_tile);
    return uint(size.x * size.y);
}

uint share16(int area) { return uint(16 - 16 / area); }  // the work a rate saves, in sixteenths

// the steps of tile `at`: per cost class (dearest first) its key and its gain, `n` of them; `forced`, what the tile
// saves at any threshold (the engine's rates alone; 0 without them)
void steps(int at, int plane, out uint keys[4], out uint gains[4], out int n, out uint forced) {
    const int AREAS[4] = int[4](2, 4, 8, 16);
    uint w = weight(at);
    float v[6];
    for (int r = 0; r < 6; ++r) v[r] = decoded[r * plane + at];
    n = 0;
    forced = 0u;
    uint best[4] = uint[4](NAN_KEY, NAN_KEY, NAN_KEY, NAN_KEY);
    if (u_combiner == 0) {
        bool present[4] = bool[4](false, false, false, false);
        for (int r = 0; r < 6; ++r) {
            if ((u_allowed & (1u << uint(r))) == 0u) continue;
            int c = findLSB(uint(AREA[r])) - 1;  // 2, 4, 8, 16 -> 0 .. 3
            present[c] = true;
            best[c] = min(best[c], key_of(oriented(v, r + 1)));
        }
        for (int c = 2; c >= 0; --c) best[c] = min(best[c], best[c + 1]);  // T_k: class k or a cheaper one
        uint before = 0u;  // the share of the class before (1x1)
        for (int c = 0; c < 4; ++c) {
            if (!present[c]) continue;
            keys[n] = best[c];
            gains[n] = w * (share16(AREAS[c]) - before);
            before = share16(AREAS[c]);
            ++n;
        }
        return;
    }
    // beside the engine's rate: each candidate (the allowed rates and 1x1) by the rate the device shades for it
    // (sdk _combined_values); a class's share counts only past what the engine's rates save alone (the 1x1
    // candidate's), which the tile saves at any threshold (sdk _lowest_threshold_shaded)
    int e = rate_of(imageLoad(u_engine, ivec2(at % u_grid.x, at / u_grid.x)).r);
    int alone = 1;
    for (int c = 0; c < 7; ++c) {
        if (!supported(c)) continue;
        int first, last;
        device_rates(combined(e, c), first, last);
        int area = SIZE[first].x * SIZE[first].y;
        if (c == 0) alone = area;
        if (area < 2) continue;
        int k = findLSB(uint(area)) - 1;
        best[k] = min(best[k], key_of(shaded_value(v, first, last)));
    }
    for (int c = 2; c >= 0; --c) best[c] = min(best[c], best[c + 1]);
    uint before = share16(alone);
    forced = w * before;
    for (int c = 0; c < 4; ++c) {
        uint lifted = max(share16(AREAS[c]), share16(alone));
        keys[n] = best[c];
        gains[n] = w * (lifted - before);
        before = lifted;
        ++n;
    }
}

// `x` summed over the workgroup (every invocation calls it, and gets the sum)
uint workgroup_sum(uint x) {
    s_sum[gl_LocalInvocationIndex] = x;
    barrier();
    for (uint half_ = 128u; half_ > 0u; half_ >>= 1) {
        if (gl_LocalInvocationIndex < half_) s_sum[gl_LocalInvocationIndex] += s_sum[gl_LocalInvocationIndex + half_];
        barrier();
    }
    uint total = s_sum[0];
    barrier();  // (every invocation has read it before the next sum writes)
    return total;
}

// the gains of every step at or below key `k` (below NAN_KEY: finite steps only), and what the tiles save at any
// threshold, summed over the workgroup
uint gained(uint k, int tiles, int plane) {
    uint sum = 0u;
    for (int at = int(gl_LocalInvocationIndex); at < tiles; at += 256) {
        uint keys[4], gains[4], forced;
        int n;
        steps(at, plane, keys, gains, n, forced);
        sum += forced;
        for (int i = 0; i < n; ++i) if (keys[i] <= k && keys[i] != NAN_KEY) sum += gains[i];
    }
    return workgroup_sum(sum);
}

// the steps' gains by the 8 bits of their keys at `shift`, among the keys whose higher bits are `prefix`'s
void histogram(uint prefix, int shift, int tiles, int plane) {
    s_hist[gl_LocalInvocationIndex] = 0u;
    barrier();
    for (int at = int(gl_LocalInvocationIndex); at < tiles; at += 256) {
        uint keys[4], gains[4], forced;
        int n;
        steps(at, plane, keys, gains, n, forced);
        for (int i = 0; i < n; ++i) {
            if (keys[i] == NAN_KEY || (shift < 24 && (keys[i] >> uint(shift + 8)) != (prefix >> uint(shift + 8))))
                continue;
            atomicAdd(s_hist[(keys[i] >> uint(shift)) & 255u], gains[i]);
        }
    }
    barrier();
}

void main() {
    int tiles = u_grid.x * u_grid.y;
    int plane = tiles;
    float thr = u_lo;
    // what the engine's rates save alone: the sum of no step (no key is 0: -inf's is 0x007fffff) and the forced share
    uint forced = u_combiner == 0 ? 0u : gained(0u, tiles, plane);
    if (u_need > forced) {
        uint prefix = 0u, below = 0u;  // the key's digits found so far; the gains of the keys below them
        for (int shift = 24; shift >= 0; shift -= 8) {
            histogram(prefix, shift, tiles, plane);
            if (gl_LocalInvocationIndex == 0u) {
                if (shift == 24) {  // every finite step: the most the frame can save (NaN tiles: just past its last)
                    uint total = 0u;
                    for (int d = 0; d < 256; ++d) total += s_hist[d];
                    s_need = min(u_need - forced, total);
                }
                uint acc = below;
                s_digit = 0u;
                for (int d = 0; d < 256; ++d) {
                    if (acc + s_hist[d] >= s_need && s_hist[d] > 0u) { s_digit = uint(d); break; }
                    acc += s_hist[d];
                }
                s_below = acc;
            }
            barrier();
            prefix |= s_digit << uint(shift);
            below = s_below;
            barrier();  // (every invocation has read them before the next round writes)
        }
        // just above that step (the selection passes values below the threshold), within [u_lo, u_hi]
        if (s_need > 0u) thr = clamp(value_of(prefix + 1u), u_lo, u_hi);
    }
    float metric = u_higher_is_better ? -thr : thr;
    if (u_has_floor) metric = u_higher_is_better ? min(metric, u_floor) : max(metric, u_floor);
    float oriented_thr = u_higher_is_better ? -metric : metric;
    // what the rates of that threshold save: the steps below it, and the engine's rates alone
    uint saved = key_of(oriented_thr) == 0u ? forced : gained(key_of(oriented_thr) - 1u, tiles, plane);
    if (gl_LocalInvocationIndex == 0u) {
        b_threshold = metric;
        b_saved = saved;
    }
}
