"""The colour facts live once in ``rtp.sdk``; the shaders' GLSL copies of them agree with it."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk

ROOT = Path(__file__).resolve().parents[1]
SHADERS = {
    "moderngl": ROOT / "plugins" / "moderngl" / "shaders" / "common.glsl",
    "pyrender": ROOT / "plugins" / "pyrender" / "shaders" / "gbuffer.frag",
}


def test_luma_is_rec601_of_display_values() -> None:
    rgb = np.random.default_rng(0).random((5, 7, 3)).astype(np.float32)
    want = 0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]
    assert sdk.luma(rgb).dtype == np.float32
    np.testing.assert_allclose(sdk.luma(rgb), want, rtol=1e-6)


def test_luma_refuses_a_textures_integers() -> None:
    """An 8- or 16-bit frame read back gave its luma in 0-255 (0-65535) as the display values' (white was 255, not
    1), without a word, where the sRGB curves refuse it; a Yang or Weber term built on it was 255 times too large.
    Floats of any width, Python numbers and the frame divided by 255 are taken as before."""
    for dtype, top in ((np.uint8, 255), (np.uint16, 65535)):
        with pytest.raises(sdk.InputDtypeError, match=rf"luma: .*dtype {np.dtype(dtype)} .*luma\(c / {top}\)"):
            sdk.luma(np.full((2, 2, 3), top, dtype))
    np.testing.assert_allclose(sdk.luma(np.full((2, 2, 3), 255, np.uint8) / 255), np.ones((2, 2)), rtol=1e-6)
    assert float(sdk.luma([1, 1, 1])) == pytest.approx(1.0)
    assert sdk.luma(np.ones((1, 3), np.float16)).dtype == np.float32


def test_srgb_curves_invert_each_other_and_hit_the_standard_points() -> None:
    x = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(sdk.linear_to_srgb(sdk.srgb_to_linear(x)), x, atol=1e-12)
    assert sdk.srgb_to_linear(0.5) == pytest.approx(0.21404114, abs=1e-8)
    assert sdk.linear_to_srgb(0.0031308) == pytest.approx(0.04045, abs=1e-6)
    assert sdk.srgb_to_linear(1.0) == pytest.approx(1.0)


def test_srgb_curves_refuse_a_textures_integers() -> None:
    """An 8- or 16-bit texture read back went through the curves as its 0-255 values: srgb_to_linear(255) was
    524947, without a word. Python's numbers (0, 1) and float arrays are taken as before."""
    for fn in (sdk.srgb_to_linear, sdk.linear_to_srgb):
        for dtype, top in ((np.uint8, 255), (np.uint16, 65535)):
            with pytest.raises(sdk.InputDtypeError, match=rf"dtype {np.dtype(dtype)} .*c / {top}\)"):
                fn(np.full((2, 2, 3), top, dtype))
        assert fn(1) == pytest.approx(1.0) and fn(np.array([0, 1])).tolist() == pytest.approx([0.0, 1.0])
    assert sdk.srgb_to_linear(np.full(3, 255, np.uint8) / 255.0) == pytest.approx(1.0)


def _glsl_function(source: str, name: str) -> str:
    m = re.search(r"vec3 " + name + r"\(vec3 c\) \{.*?\n\}", source, re.S)
    assert m, f"{name} not found"
    return m.group(0)


@pytest.mark.gl
@pytest.mark.parametrize("plugin", sorted(SHADERS))
def test_glsl_srgb_curves_match_the_sdk(plugin: str, gl_context: Any) -> None:
    ctx = gl_context
    src = SHADERS[plugin].read_text()
    funcs = "\n".join(_glsl_function(src, n) for n in ("srgb_to_linear", "linear_to_srgb"))
    n = 256
    x = np.linspace(0.0, 1.0, n * 3, dtype=np.float32).reshape(n, 3)
    # One fragment per value: a fullscreen triangle over an n x 1 float framebuffer with two targets.
    prog = ctx.program(
        vertex_shader="#version 330\nvoid main() { vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2); "
        "gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0); }",
        fragment_shader="#version 330\nuniform sampler2D xs; layout(location = 0) out vec4 dec; "
        "layout(location = 1) out vec4 enc;\n" + funcs + "\nvoid main() { "
        "vec3 c = texelFetch(xs, ivec2(gl_FragCoord.xy), 0).rgb; "
        "dec = vec4(srgb_to_linear(c), 1.0); enc = vec4(linear_to_srgb(c), 1.0); }",
    )
    xs = ctx.texture((n, 1), 3, x.tobytes(), dtype="f4")
    xs.filter = (ctx.NEAREST, ctx.NEAREST)
    targets = [ctx.texture((n, 1), 4, dtype="f4") for _ in range(2)]
    fbo = ctx.framebuffer(color_attachments=targets)
    fbo.use()
    xs.use(0)
    prog["xs"] = 0
    ctx.vertex_array(prog, []).render(ctx.TRIANGLES, vertices=3)
    got = np.stack([np.frombuffer(t.read(), np.float32).reshape(n, 4)[:, :3] for t in targets], axis=1)
    np.testing.assert_allclose(got[:, 0], sdk.srgb_to_linear(x), atol=2e-6)
    np.testing.assert_allclose(got[:, 1], sdk.linear_to_srgb(x), atol=2e-6)
    for obj in (*targets, fbo, xs, prog):
        obj.release()


def test_glsl_luma_weights_are_the_sdk_weights() -> None:
    shaders = ROOT / "plugins" / "moderngl" / "shaders"
    common = (shaders / "common.glsl").read_text()
    found = re.findall(r"display_luma\(vec3 c\) \{ return dot\(c, vec3\((0\.\d+), (0\.\d+), (0\.\d+)\)\)", common)
    assert len(found) == 1 and tuple(map(float, found[0])) == sdk.LUMA_WEIGHTS
    # every shader that takes luma of display values does it through display_luma, no copy of the weights
    for path in shaders.glob("*.glsl"):
        text = path.read_text()
        assert "0.299" not in text or path.name == "common.glsl", path.name
    assert "display_luma(" in (shaders / "coarse_fs.glsl").read_text()
    assert "display_luma(" in (shaders / "adapter_fs.glsl").read_text()
