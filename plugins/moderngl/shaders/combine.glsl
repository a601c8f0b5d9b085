// The engine's own rates beside the image (sdk combine_rates, select_rates(engine_rates=)): the rates a device
// shades where a combiner meets two rates, and the value judged for them. Included by select_rates_cs.glsl and
// select_budget_cs.glsl after their uniforms (u_allowed, u_combiner, u_rate_factors, u_higher_is_better).

// every rate, finest first (sdk ALL_RATES): sizes and codes
const ivec2 SIZE[7] = ivec2[7](ivec2(1, 1), ivec2(1, 2), ivec2(2, 1), ivec2(2, 2), ivec2(2, 4), ivec2(4, 2), ivec2(4, 4));
const uint ALL_CODES[7] = uint[7](0u, 1u, 4u, 5u, 6u, 9u, 10u);

bool supported(int i) { return i == 0 || (u_allowed & (1u << uint(i - 1))) != 0u; }

int rate_of(uint code) {  // an ALL_RATES index (an unknown code: 1x1, as the checks on the CPU refuse them)
    for (int i = 0; i < 7; ++i) if (ALL_CODES[i] == code) return i;
    return 0;
}

// among the supported rates that fit inside `want` (or, `swapped`, inside it either way round), those of the
// largest area and then the lowest W + H: the first and the last of them in ALL_RATES order
void largest(ivec2 want, bool swapped, out int first, out int last) {
    int area = 0, sum = 0;
    first = 0; last = 0;
    for (int i = 0; i < 7; ++i) {
        ivec2 s = SIZE[i];
        if (!supported(i) || !((s.x <= want.x && s.y <= want.y) || (swapped && s.x <= want.y && s.y <= want.x))) continue;
        if (s.x * s.y > area || (s.x * s.y == area && s.x + s.y < sum)) { area = s.x * s.y; sum = s.x + s.y; first = i; last = i; }
        else if (s.x * s.y == area && s.x + s.y == sum) last = i;
    }
}

// the rates a device may shade where a combiner asks for `want` (sdk _device_rates): the rate where supported,
// else Vulkan's clamp, the tall one first; `last` another a device may take (first where there is none)
void device_rates(ivec2 want, out int first, out int last) {
    for (int i = 0; i < 7; ++i) if (supported(i) && SIZE[i] == want) { first = i; last = i; return; }
    int a0, a1, b0, b1;
    largest(want, false, a0, a1);
    largest(want, true, b0, b1);
    first = a0; last = a1;
    if (b0 != a0 && b0 != a1) last = b0;
    if (b1 != a0 && b1 != a1) last = b1;
}

ivec2 combined(int e, int r) {
    ivec2 a = SIZE[e], b = SIZE[r];
    return u_combiner == 2 ? min(a, b) : u_combiner == 3 ? max(a, b) : a * b;
}

// a rate's value oriented as "smaller passes", against its own threshold; 1x1 costs nothing to judge
float oriented(float v[6], int i) {
    if (i == 0) return uintBitsToFloat(0xff800000u);  // -inf
    float f = u_rate_factors[i - 1];
    return u_higher_is_better ? -(v[i - 1] + 20.0 * log(f) / log(10.0)) : v[i - 1] / f;
}

// the value judged for a candidate the device shades as `first` (or `last`, a rate of the same area it may take
// instead): the worse of the two, NaN where either is
float shaded_value(float v[6], int first, int last) {
    float a = oriented(v, first), b = oriented(v, last);
    if (isnan(a) || isnan(b)) return uintBitsToFloat(0x7fc00000u);
    return max(a, b);
}
