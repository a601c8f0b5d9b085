#version 330 core
// 4x4 depth-aware box blur of the raw SSAO term (matches the 4x4 rotation pattern), then strength.
uniform sampler2D u_ao;
uniform sampler2D u_normal_depth;
uniform float u_strength;
out float o_ao;

void main() {
    ivec2 p = ivec2(gl_FragCoord.xy);
    ivec2 size = textureSize(u_ao, 0);
    float d = texelFetch(u_normal_depth, p, 0).w;
    if (d <= 0.0) { o_ao = 1.0; return; }
    float sum = 0.0, wsum = 0.0;
    for (int y = -2; y < 2; ++y) {
        for (int x = -2; x < 2; ++x) {
            ivec2 q = clamp(p + ivec2(x, y), ivec2(0), size - 1);
            float dq = texelFetch(u_normal_depth, q, 0).w;
            float w = (dq > 0.0 && abs(dq - d) <= 0.05 * d) ? 1.0 : 0.0;
            sum += w * texelFetch(u_ao, q, 0).r;
            wsum += w;
        }
    }
    float ao = wsum > 0.0 ? sum / wsum : 1.0;
    // strength 0 turns AO off (x^0 = 1): GLSL leaves pow(0, 0) undefined (llvmpipe gives 0, exp2(0 * log2 0) is NaN
    // on drivers that compute it so), so a fully occluded pixel stayed 0, or turned the frame NaN through exposure
    o_ao = u_strength > 0.0 ? pow(clamp(ao, 0.0, 1.0), u_strength) : 1.0;
}
