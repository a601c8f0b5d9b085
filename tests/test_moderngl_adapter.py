"""rtp.plugins.moderngl.Adapter: model inputs from an engine's own textures, on the GPU."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.capture.scenes import procedural
from rtp.plugins.moderngl import Adapter, Frame, GBufferTextures, RateSelector, Renderer
from rtp.plugins.moderngl._adapter import CHANNEL_IDS
from rtp.plugins.moderngl._glio import is_released, write_texture
from rtp.scene import Camera
from tests.conftest import in_thread, make_current

W, H = 128, 80
pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def frames(gl_context: Any) -> Iterator[tuple[Any, Frame, Frame]]:
    ctx = make_current(gl_context)
    scene = procedural(3)
    sp = scene.spawn_points[0]
    prev_cam = Camera(sp.position, yaw=sp.yaw, pitch=-5.0)
    cam = Camera((sp.position[0] + 0.4, sp.position[1], sp.position[2] - 0.3), yaw=sp.yaw + 6.0, pitch=-3.0)
    with Renderer(W, H, ctx=ctx) as r:
        r.load_scene(scene)
        prev = r.render(prev_cam)
        cur = r.render(cam, prev)
    yield ctx, prev, cur


def _tex(ctx: Any, image: np.ndarray) -> Any:  # an engine's texture, uploaded from a top-left image
    img = image if image.ndim == 3 else image[..., None]
    t = ctx.texture((img.shape[1], img.shape[0]), img.shape[2], dtype="f4")
    write_texture(t, img.astype(np.float32))
    return t


def _engine_frame(ctx: Any, prev: Frame, cur: Frame, **overrides: Any) -> GBufferTextures:
    frame = GBufferTextures(
        albedo=_tex(ctx, cur.albedo), normal=_tex(ctx, cur.normal), depth=_tex(ctx, cur.depth),
        prev_colour=_tex(ctx, prev.colour["1x1"]), prev_depth=_tex(ctx, prev.depth),
        view=cur.camera.view(), projection=cur.camera.projection(W / H),
        prev_view_projection=prev.camera.view_projection(W, H),
    )
    return replace(frame, **overrides)


def _engine_inputs(ctx: Any, prev: Frame, cur: Frame, adapter: Adapter, **overrides: Any) -> np.ndarray:
    return adapter.inputs(_engine_frame(ctx, prev, cur, **overrides))


def test_inputs_in_the_declared_order_match_the_renderer_and_the_numpy_reference(frames) -> None:
    ctx, prev, cur = frames
    channels = ("normal.z", "seen", "albedo.r", "reprojected.r", "depth", "reprojected.b")
    a = Adapter(channels, W, H, ctx=ctx)
    x = _engine_inputs(ctx, prev, cur, a)
    assert x.shape == (6, H, W) and x.dtype == np.float32
    np.testing.assert_allclose(x[0], cur.normal[..., 2], atol=1e-3)
    np.testing.assert_allclose(x[2], cur.albedo[..., 0], atol=1e-6)
    np.testing.assert_allclose(x[4], cur.depth, rtol=1e-6)
    # The renderer's own reprojection is this adapter: identical planes.
    np.testing.assert_array_equal(x[1], cur.seen)
    np.testing.assert_allclose(x[3], cur.reprojected[..., 0], atol=1e-6)
    # And the numpy reference in rtp.sdk agrees away from depth edges.
    ref_rp, ref_seen = sdk.reproject(prev.colour["1x1"], prev.depth, cur.depth, cur.camera.view(),
                                     cur.camera.projection(W / H), prev.camera.view_projection(W, H))
    mismatch = x[1] != ref_seen
    assert mismatch.mean() < 0.002, mismatch.mean()
    ok = ~mismatch
    np.testing.assert_allclose(x[5][ok], ref_rp[..., 2][ok], atol=1e-5)
    assert 0.0 < x[1].mean() < 1.0  # the camera moved: some pixels are disoccluded or off-screen
    assert np.all(x[3][x[1] == 0] == 0)  # unseen pixels carry no stale colour
    a.close()
    # motion.x / .y: the camera's move, as the numpy reference and the renderer's own G-buffer pass give it
    with Adapter(("motion.x", "motion.y"), W, H, ctx=ctx) as m:
        motion = _engine_inputs(ctx, prev, cur, m)
    want = sdk.input_planes(("motion.x", "motion.y"), depth=cur.depth, view=cur.camera.view(),
                            projection=cur.camera.projection(W / H), prev_view_projection=prev.camera.view_projection(W, H))
    np.testing.assert_allclose(motion, want, atol=1e-3)
    np.testing.assert_allclose(motion, np.stack([cur.channel("motion.x"), cur.channel("motion.y")]), atol=0.05)
    assert np.abs(motion).max() > 1.0  # (the camera moved)


def test_paper_inputs_feed_a_predictor(frames, tiny_model) -> None:
    ctx, prev, cur = frames
    pred = sdk.load(tiny_model())
    with sdk.adapters.get("moderngl").for_predictor(pred, W, H, ctx=ctx) as a:
        assert a.channels == pred.metadata.inputs
        rates = pred.shading_rates(_engine_inputs(ctx, prev, cur, a))
    assert rates.shape == pred.tiles(H, W)


@pytest.mark.parametrize("kind", ["window", "reversed"])
def test_window_depth_world_normals_and_linear_albedo(frames, kind: str) -> None:
    ctx, prev, cur = frames
    channels = ("depth", "normal.x", "normal.y", "normal.z", "albedo.g", "seen")
    with Adapter(channels, W, H, ctx=ctx) as a:
        ref = _engine_inputs(ctx, prev, cur, a)

    def window(depth: np.ndarray, cam: Camera) -> np.ndarray:  # what a hardware depth buffer holds
        p = cam.projection(W / H)
        z = -depth
        ndc = (p[2, 2] * z + p[2, 3]) / -z
        standard = np.where(depth > 0, ndc * 0.5 + 0.5, 1.0)
        return 1.0 - standard if kind == "reversed" else standard  # reversed-Z: 1 at the near plane, 0 on sky

    world_n = cur.normal @ np.linalg.inv(cur.camera.view())[:3, :3].T
    linear_albedo = np.where(cur.albedo <= 0.04045, cur.albedo / 12.92, ((cur.albedo + 0.055) / 1.055) ** 2.4)
    b = Adapter(channels, W, H, ctx=ctx, depth_kind=kind, normal_space="world", albedo_linear=True)
    x = _engine_inputs(ctx, prev, cur, b, depth=_tex(ctx, window(cur.depth, cur.camera)),
                       prev_depth=_tex(ctx, window(prev.depth, prev.camera)), normal=_tex(ctx, world_n),
                       albedo=_tex(ctx, linear_albedo))
    b.close()
    np.testing.assert_allclose(x[0], ref[0], rtol=2e-3, atol=1e-4)
    np.testing.assert_allclose(x[1:4], ref[1:4], atol=1e-4)
    np.testing.assert_allclose(x[4], ref[4], atol=1e-4)
    assert (x[5] != ref[5]).mean() < 0.002


def test_a_depth_buffer_is_refused_through_the_projections_the_sdk_refuses(frames) -> None:
    """A hardware depth buffer through an orthographic projection sdk.input_planes does not linearise (left-handed,
    reversed-Z, for row vectors), or of points behind an orthographic camera (near -1, in the current or the
    previous frame), is the SDK's ParameterError from the adapter too, whatever its channels and with or without a
    previous frame: it drew wrong or negative depth (every pixel background) without a word where no plane
    reprojected. A camera whose near plane is behind it but whose depth buffer holds nothing behind it gives the
    SDK's planes."""
    ctx = frames[0]
    h, w = 20, 30
    near, far = 0.1, 40.0

    def ortho(n: float, f: float) -> np.ndarray:
        m = np.diag([0.125, 0.2, -2 / (f - n), 1.0])
        m[2, 3] = -(f + n) / (f - n)
        return m

    d = np.linspace(1.0, 30.0, h * w).reshape(h, w)
    window = ((d - near) / (far - near)).astype(np.float32)
    left = np.diag([0.125, 0.2, 1 / (far - near), 1.0])  # XMMatrixOrthographicLH, as column vectors
    left[2, 3] = -near / (far - near)
    reversed_z = np.diag([0.125, 0.2, 1 / (far - near), 1.0])
    reversed_z[2, 3] = far / (far - near)
    b = np.linspace(-0.5, 8.0, h * w).reshape(h, w)  # its first rows behind a near -1, far 10 camera
    behind = ((b + 1.0) / 11.0).astype(np.float32)
    grey = np.full((h, w, 3), 0.5, np.float32)
    cases = [("window", window, left, "does not rise away from the camera"),
             ("reversed", 1 - window, reversed_z, "does not rise away from the camera"),
             ("window", window, ortho(near, far).T, "neither a perspective's"),
             ("window", behind, ortho(-1.0, 10.0), "negative view depth .* near plane is behind"),
             ("reversed", 1 - behind, ortho(-1.0, 10.0), "negative view depth .* near plane is behind")]
    for kind, raw, m, match in cases:
        for channels, prev in ((("depth",), False), (("albedo.r", "depth.edge"), False), (("albedo.r",), True),
                               (("depth", "seen"), True)):
            g: dict[str, Any] = {"depth": raw, "albedo": grey, "view": np.eye(4), "projection": m}
            if prev:
                g.update(prev_colour=grey, prev_depth=raw, prev_view_projection=m)
            with pytest.raises(sdk.ParameterError, match=f"projection: .*{match}"):
                sdk.input_planes(channels, **g, depth_kind=kind)
            frame = GBufferTextures(albedo=_tex(ctx, grey), normal=_tex(ctx, grey), depth=_tex(ctx, raw),
                                    view=np.eye(4), projection=m,
                                    **({"prev_colour": _tex(ctx, grey), "prev_depth": _tex(ctx, raw),
                                        "prev_view_projection": m} if prev else {}))
            with Adapter(channels, w, h, ctx=ctx, depth_kind=kind) as a, \
                    pytest.raises(sdk.ParameterError, match=f"projection: .*{match}"):
                a.inputs(frame)
    # the previous frame's depth buffer through its own projection, where a plane reads it
    fine = np.where(b >= 0.0, behind, 1.0).astype(np.float32)  # the near -1 camera, nothing behind it
    channels = ("depth", "seen", "reprojected.g")
    g = {"depth": fine, "view": np.eye(4), "projection": ortho(-1.0, 10.0), "prev_colour": grey,
         "prev_depth": behind, "prev_view_projection": ortho(-1.0, 10.0), "prev_projection": ortho(-1.0, 10.0)}
    with pytest.raises(sdk.ParameterError, match="prev_projection: .*negative view depth"):
        sdk.input_planes(channels, **g, depth_kind="window")
    frame = GBufferTextures(albedo=_tex(ctx, grey), normal=_tex(ctx, grey), depth=_tex(ctx, fine), view=np.eye(4),
                            projection=g["projection"], prev_colour=_tex(ctx, grey), prev_depth=_tex(ctx, behind),
                            prev_view_projection=g["prev_view_projection"], prev_projection=g["prev_projection"])
    with Adapter(channels, w, h, ctx=ctx, depth_kind="window") as a:
        with pytest.raises(sdk.ParameterError, match="prev_projection: .*negative view depth"):
            a.inputs(frame)
        g["prev_depth"] = fine
        got = a.inputs(replace(frame, prev_depth=_tex(ctx, fine)))
    want = sdk.input_planes(channels, **g, depth_kind="window")
    np.testing.assert_allclose(got, want, atol=2e-6)
    assert got[0].min() >= 0.0 and got[1].mean() > 0.5


def test_depth_edges_on_the_gpu_follow_the_sdk_definition(frames) -> None:
    ctx, prev, cur = frames
    a = Adapter(("depth.edge", "depth"), W, H, ctx=ctx)
    x = _engine_inputs(ctx, prev, cur, a)
    want = sdk.depth_edges(cur.depth)
    np.testing.assert_allclose(x[0], want, atol=1e-4)
    np.testing.assert_allclose(x[0], cur.channel("depth.edge"), atol=1e-4)
    assert 0.0 < (want > 0.1).mean() < 0.2, "the moved camera sees silhouettes and steps"
    # from a hardware depth buffer too (linearised first, then the same definition)
    p = cur.camera.projection(W / H)
    ndc = (p[2, 2] * -cur.depth + p[2, 3]) / cur.depth
    window = np.where(cur.depth > 0, ndc * 0.5 + 0.5, 1.0).astype(np.float32)
    b = Adapter(("depth.edge",), W, H, ctx=ctx, depth_kind="window")
    y = _engine_inputs(ctx, prev, cur, b, depth=_tex(ctx, window), prev_depth=_tex(ctx, window))
    assert np.mean(np.abs(y[0] - want) <= 0.01) >= 0.995
    a.close()
    b.close()


def test_pixel_differences_on_the_gpu_follow_the_sdk_definition(frames) -> None:
    ctx, prev, cur = frames
    a = Adapter(("reprojected.y.dy", "reprojected.y", "reprojected.y.dx"), W, H, ctx=ctx)
    x = _engine_inputs(ctx, prev, cur, a)
    dx, dy = sdk.pixel_differences(x[1])  # each neighbour reprojected as itself: exactly its own luma
    np.testing.assert_allclose(x[2], dx, atol=1e-6)
    np.testing.assert_allclose(x[0], dy, atol=1e-6)
    ref_dx, ref_dy = sdk.pixel_differences(cur.channel("reprojected.y"))
    np.testing.assert_allclose(cur.channel("reprojected.y.dx"), ref_dx)
    assert np.mean(np.abs(x[2] - ref_dx) <= 1e-3) >= 0.99 and np.mean(np.abs(x[0] - ref_dy) <= 1e-3) >= 0.99
    assert 0.01 < (dx > 0.02).mean() < 0.9 and 0.01 < (dy > 0.02).mean() < 0.9, "the room has edges and texture"
    a.close()


def test_block_variances_on_the_gpu_follow_the_sdk_definition(frames) -> None:
    ctx, prev, cur = frames
    a = Adapter(("albedo.y.blocks", "reprojected.y", "reprojected.y.blocks", "albedo.y"), W, H, ctx=ctx)
    x = _engine_inputs(ctx, prev, cur, a)
    for got, source in ((x[0], x[3]), (x[2], x[1])):  # each of the adapter's own luma planes
        want = sdk.block_variances(source)
        assert np.mean(np.abs(got - want) <= 1e-3) >= 0.999, np.abs(got - want).max()
        assert 0.05 < (want > 0.2).mean() < 0.375  # textured and edged cells; at most 6 of 16 pixels carry values
    np.testing.assert_allclose(cur.channel("albedo.y.blocks"), sdk.block_variances(sdk.luma(cur.albedo)))
    a.close()


def test_tile_variances_on_the_gpu_follow_the_sdk_definition(frames) -> None:
    ctx, prev, cur = frames
    a = Adapter(("reprojected.y.tiles", "albedo.y", "albedo.y.tiles", "reprojected.y"), W, H, ctx=ctx)
    x = _engine_inputs(ctx, prev, cur, a)
    tiles = np.prod(sdk.tile_grid(H, W, sdk.BLOCK_TILE))
    for got, source in ((x[0], x[3]), (x[2], x[1])):  # each of the adapter's own luma planes
        want = sdk.tile_variances(source)
        assert np.abs(got - want).max() <= 1e-3, np.abs(got - want).max()
        assert 0.3 * tiles <= (want > 0.2).sum() <= 12 * tiles  # textured and edged tiles; 12 values a tile
        assert not want.reshape(H // 16, 16, W // 16, 16)[:, 3:].any()  # below the tile's first three rows: 0
    np.testing.assert_allclose(cur.channel("albedo.y.tiles"), sdk.tile_variances(sdk.luma(cur.albedo)))
    a.close()


def test_material_channels_from_an_engine_texture(frames) -> None:
    ctx, prev, cur = frames
    channels = ("metallic", "seen", "roughness", "specular")
    a = Adapter(channels, W, H, ctx=ctx)
    rms = np.stack([cur.roughness, cur.metallic, cur.specular], axis=-1)
    x = _engine_inputs(ctx, prev, cur, a, material=_tex(ctx, rms))
    for plane, name in zip(x, channels):
        np.testing.assert_allclose(plane, cur.channel(name), atol=1e-6, err_msg=name)
    assert x[0].max() == 1.0 and 0.0 < x[2].mean() < 1.0  # the scene has metals and varied roughness
    # a glTF occlusion-roughness-metallic texture: no specular there, so the dielectric default 0.5
    orm = np.stack([np.ones_like(cur.roughness), cur.roughness, cur.metallic, np.zeros_like(cur.roughness)], -1)
    y = _engine_inputs(ctx, prev, cur, a, material=_tex(ctx, orm), material_components=(1, 2, -1))
    np.testing.assert_allclose(y[[0, 2]], x[[0, 2]], atol=1e-6)
    geo = cur.depth > 0
    assert np.all(y[3][geo] == 0.5) and not y[3][~geo].any()
    with pytest.raises(ValueError, match="material texture"):
        _engine_inputs(ctx, prev, cur, a)
    with pytest.raises(ValueError, match="material_components"):
        _engine_inputs(ctx, prev, cur, a, material=_tex(ctx, rms), material_components=(0, 1, 3))
    a.close()


def test_each_channel_is_the_same_whatever_else_the_adapter_builds(frames) -> None:
    """The shader is compiled for each adapter's channel list (the rest is dropped as dead code):
    an adapter of every channel and adapters of one channel each give the same planes, bit for bit."""
    ctx, prev, cur = frames
    rms = _tex(ctx, np.stack([cur.roughness, cur.metallic, cur.specular], axis=-1))
    every = tuple(reversed(sorted(Adapter.supported_channels)))  # not the id order either
    with Adapter(every, W, H, ctx=ctx) as a:
        x = _engine_inputs(ctx, prev, cur, a, material=rms)
    assert x.shape == (len(every), H, W)
    for i, name in enumerate(every):
        with Adapter((name,), W, H, ctx=ctx) as one:
            y = _engine_inputs(ctx, prev, cur, one, material=rms)
        np.testing.assert_array_equal(y[0], x[i], err_msg=name)
        assert name == "seen" or np.ptp(y[0]) > 0, name  # every plane carries something on this frame


def test_the_adapter_benchmark_times_every_shipped_channel_list() -> None:
    """bench/adapter.py builds each shipped model's inputs and the renderer's reprojection."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, str(root / "bench" / "adapter.py"), "--sizes", "48x32", "--repeats", "1"],
                         capture_output=True, text=True, check=True).stdout
    rows = [line.split("|")[1].strip() for line in out.splitlines() if line.startswith("| ") and "ms" not in line]
    assert rows == ["reprojection (renderer)"] + [p.stem for p in sorted((root / "models").glob("*.onnx"))], out


def test_no_previous_frame_and_channel_errors(frames) -> None:
    ctx, prev, cur = frames
    a = Adapter(("seen", "reprojected.g", "albedo.b"), W, H, ctx=ctx)
    no_prev = _engine_frame(ctx, prev, cur, prev_colour=None, prev_depth=None, prev_view_projection=None)
    x = a.inputs(no_prev)
    assert not x[:2].any() and x[2].any()
    with pytest.raises(sdk.adapters.UnsupportedChannelError, match="cannot produce shadow"):
        Adapter(("seen", "shadow"), W, H, ctx=ctx)
    with Adapter(("motion.x", "motion.y"), W, H, ctx=ctx) as m:  # (no previous camera: no move to measure)
        assert not m.inputs(no_prev).any()
    with pytest.raises(TypeError, match="moderngl.Context"):
        Adapter(("seen",), W, H, ctx=None)
    with pytest.raises(sdk.ParameterError, match="prev_depth"):
        a.inputs(replace(no_prev, prev_colour=_tex(ctx, prev.colour["1x1"])))
    # every bad setting or frame field an RtpError (a ParameterError, still a ValueError), never a bare one
    with pytest.raises(sdk.ParameterError, match="material texture"):
        with Adapter(("seen", "roughness"), W, H, ctx=ctx) as m:
            m.inputs(replace(no_prev, material=None))
    with pytest.raises(sdk.ParameterError, match="left-handed projection"):  # Direct3D's: named, with the conversion
        a.inputs(replace(no_prev, projection=no_prev.projection @ np.diag([1.0, 1.0, -1.0, 1.0])))
    with pytest.raises(sdk.ParameterError, match="prev_projection: .* row vectors"):
        a.inputs(replace(no_prev, prev_projection=no_prev.projection.T))
    neither = np.diag([0.5, 0.8, -0.1, 1.0])
    neither[3, 2] = 0.5  # neither a perspective nor an orthographic camera: named where a plane reprojects
    with pytest.raises(sdk.ParameterError, match="projection: .* neither a perspective's"):
        a.inputs(replace(no_prev, projection=neither, prev_colour=_tex(ctx, prev.colour["1x1"]),
                         prev_depth=_tex(ctx, prev.depth), prev_view_projection=prev.camera.view_projection(W, H)))
    assert a.inputs(replace(no_prev, projection=neither)).shape == (3, H, W)  # (without a previous frame: not read)
    with Adapter(("albedo.b", "depth"), W, H, ctx=ctx) as d:
        assert d.inputs(replace(no_prev, projection=neither)).shape == (2, H, W)
    for options in ({"normal_space": "bogus"}, {"depth_kind": "bogus"}, {"tolerance": float("nan")},
                    {"tolerance": -1.0}, {"tolerance": "0.02"}):
        with pytest.raises(sdk.ParameterError):
            Adapter(("seen",), W, H, ctx=ctx, **options)
    # the SDK's range: above it the GPU reprojected what sdk.input_planes and the adapter's own check() refused
    with pytest.raises(sdk.ParameterError, match=r"tolerance: expected a relative depth tolerance in \[0, 1\]"):
        Adapter(("seen",), W, H, ctx=ctx, tolerance=1.5)
    Adapter(("seen",), W, H, ctx=ctx, tolerance=sdk.MAX_REPROJECTION_TOLERANCE).close()
    for size in ((2.7, H), ("abc", H), (W, None), (W, float("inf")), (0, H), (True, H)):
        with pytest.raises(sdk.ParameterError, match="positive integers"):
            Adapter(("seen",), *size, ctx=ctx)  # type: ignore[arg-type]
    with pytest.raises(sdk.adapters.AdapterFrameError, match="GBufferTextures"):
        a.inputs({"albedo": no_prev.albedo})  # type: ignore[arg-type]
    from rtp.plugins.moderngl import create_context

    gone = create_context()
    gone.release()
    with pytest.raises(sdk.adapters.AdapterFrameError, match="ctx: this moderngl context has been released"):
        Adapter(("seen",), W, H, ctx=gone)  # ("ctx must be the engine's moderngl.Context, got Context")
    make_current(ctx)
    a.close()
    with pytest.raises(sdk.adapters.AdapterClosedError):
        a.inputs(no_prev)
    with pytest.raises(sdk.adapters.AdapterClosedError):
        a.read(0)



def test_read_gives_one_plane_of_the_last_run_and_frame_fields_are_checked(frames) -> None:
    """Adapter.read(i) is plane i of the last inputs()/run() (six planes: two render targets), an index
    past the planes a ParameterError; a texture of another size, a missing albedo and material
    components that are not three indices are refused by name."""
    from rtp.plugins.moderngl._adapter import _MAX_CHANNELS

    ctx, prev, cur = frames
    channels = ("seen", "reprojected.g", "albedo.b", "normal.z", "depth", "albedo.r")
    a = Adapter(channels, W, H, ctx=ctx)
    x = _engine_inputs(ctx, prev, cur, a)
    for i in range(len(channels)):
        np.testing.assert_array_equal(a.read(i), x[i])
    for bad in (len(channels), -1):
        with pytest.raises(sdk.ParameterError, match="index"):
            a.read(bad)
    small = _tex(ctx, cur.albedo[: H // 2, : W // 2])
    with pytest.raises(sdk.ParameterError, match=f"albedo: expected a texture of the adapter's size {W}x{H}, got "
                                                 f"{W // 2}x{H // 2}"):
        _engine_inputs(ctx, prev, cur, a, albedo=small)
    with pytest.raises(sdk.ParameterError, match="albedo: expected a moderngl.Texture of the adapter's context, got None"):
        _engine_inputs(ctx, prev, cur, a, albedo=None)
    m = Adapter(("roughness", "seen"), W, H, ctx=ctx)
    for comps in ((0, 1), 5, (0, 1, 2, 3)):
        with pytest.raises(sdk.ParameterError, match="material_components: expected three component indices"):
            _engine_inputs(ctx, prev, cur, m, material=_tex(ctx, cur.albedo), material_components=comps)
    with pytest.raises(sdk.adapters.UnsupportedChannelError, match=f"at most {_MAX_CHANNELS} channels"):
        Adapter(("seen",) * (_MAX_CHANNELS + 1), W, H, ctx=ctx)  # (the adapter makes 25 channels; repeats count)
    a.close()
    m.close()

def test_zero_normals_on_geometry_read_zero_and_rgb_fields_need_three_components(frames) -> None:
    """A G-buffer with zero normals under geometry (a degenerate mesh's) gives normal.z 0 there, as on
    the background, not NaN; the other pixels are unchanged. A texture of fewer than three components
    where the shader reads .rgb (albedo, normal, prev_colour) is refused by name."""
    ctx, prev, cur = frames
    a = Adapter(("normal.z", "albedo.y", "seen"), W, H, ctx=ctx)
    normal = cur.normal.copy()
    zeroed = np.zeros(normal.shape[:2], bool)
    zeroed[: H // 2] = cur.depth[: H // 2] > 0  # the upper half's geometry
    assert zeroed.any()
    normal[zeroed] = 0.0
    full = _engine_inputs(ctx, prev, cur, a)
    x = _engine_inputs(ctx, prev, cur, a, normal=_tex(ctx, normal))
    assert np.isfinite(x).all()
    assert not x[0][zeroed].any()
    np.testing.assert_array_equal(x[0][~zeroed], full[0][~zeroed])
    np.testing.assert_array_equal(x[1:], full[1:])
    for field in ("albedo", "normal", "prev_colour"):
        with pytest.raises(sdk.ParameterError, match=f"{field}: expected a texture of at least 3 components"):
            _engine_inputs(ctx, prev, cur, a, **{field: _tex(ctx, cur.depth)})
    a.close()


def test_reference_frame_source_hands_over_the_renderer_g_buffers(frames) -> None:
    """The generic path (frame_source -> adapter -> inputs) gives what the renderer computed."""
    ctx, prev, cur = frames
    channels = ("depth", "seen", "albedo.g", "normal.x", "reprojected.r", "roughness", "metallic", "specular")
    with Adapter.frame_source(procedural(3), W, H, ctx=ctx) as source:
        adapter = source.adapter(channels)
        x = adapter.inputs(source.frame(cur.camera, prev.camera))
        assert source.frames is not None
        ref = source.frames[1]
        np.testing.assert_array_equal(x[1], ref.seen)
        for plane, name in zip(x, channels):  # normals are renormalised in the shader: 1 ulp
            np.testing.assert_allclose(plane, ref.channel(name), rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(x[0], cur.depth, rtol=1e-6)  # the same frame as the fixture's own renderer
        assert not adapter.closed
    assert adapter.closed and source.closed  # the source closed the adapter it lent its context to
    make_current(ctx)
    ctx.texture((2, 2), 1).release()  # a borrowed context stays open (a released one raises here)


def test_a_frame_source_on_a_context_its_engine_released_first_closes(frames) -> None:
    """ReferenceFrameSource(ctx=) whose borrowed context the engine released first: close() raised an AttributeError
    (making the released context current); now it closes, and its adapter, whose objects went with the context."""
    from rtp.plugins.moderngl import create_context

    ctx = create_context()
    try:
        source = Adapter.frame_source(procedural(3), 64, 48, ctx=ctx)
        adapter = source.adapter(("seen", "depth"))
        ctx.release()
        source.close()
        assert source.closed and adapter.closed
    finally:
        make_current(frames[0])


def test_a_frame_source_builds_its_adapters_in_its_own_context(frames) -> None:
    """Two reference frame sources (each its own context): an adapter of the first built while the second's
    context is current gives the first's planes (its GL objects were made in the second's context, and it
    read garbage, before ReferenceFrameSource.adapter made its context current)."""
    _, prev, cur = frames
    channels = ("reprojected.y", "seen", "albedo.y", "normal.z")
    with Adapter.frame_source(procedural(3), W, H) as a:
        with a.adapter(channels) as first:
            want = first.inputs(a.frame(cur.camera, prev.camera))
        with Adapter.frame_source(procedural(3), W, H):  # its new context is the current one now
            with a.adapter(channels) as built_meanwhile:
                np.testing.assert_array_equal(built_meanwhile.inputs(a.frame(cur.camera, prev.camera)), want)


def test_an_adapter_called_from_a_thread_where_its_context_is_not_current_is_refused(frames) -> None:
    """A GL context is current in one thread at a time, and the adapter never makes its context current itself:
    ``inputs`` from a worker thread while the engine's thread held the context (even after ``ctx.__enter__()`` there,
    which EGL refuses in silence) drew in no context and returned all-zero planes (``[0. 0. 0.]`` for an albedo of
    0.5), and ``read`` zeros. Now every GL call (``inputs``, ``run``, ``read``, ``check``, the constructor) is a
    RendererError naming the thread, and the context handed over (released in one thread, made current in the other)
    gives identical planes there."""
    from rtp.plugins.moderngl import RendererError, create_context

    _, prev, cur = frames
    ctx = create_context()
    try:
        make_current(ctx)
        frame = _engine_frame(ctx, prev, cur)
        channels = ("albedo.r", "seen", "reprojected.y.dx", "depth")  # (.dx: a first pass, an adapter of its own)
        with Adapter(channels, W, H, ctx=ctx) as a:
            want = a.inputs(frame)
            refused = "Adapter: its moderngl context is not current in this thread .*'worker'.*ctx.__exit__"

            def entered(call: Any) -> Any:  # (the engine's own try: EGL refuses it, moderngl says nothing)
                ctx.__enter__()
                return call()

            for call in (lambda: a.inputs(frame), lambda: entered(lambda: a.inputs(frame)), lambda: a.read(0),
                         lambda: a.check(frame), lambda: a.run(**{f: getattr(frame, f) for f in ("albedo", "normal",
                                                                  "depth", "view", "projection")}),
                         lambda: Adapter(channels, W, H, ctx=ctx)):
                with pytest.raises(RendererError, match=refused):
                    in_thread(call)
            np.testing.assert_array_equal(a.inputs(frame), want)  # (the engine's thread: as before)
            ctx.__exit__(None, None, None)  # handed over: released here, made current there

            def there() -> tuple[np.ndarray, np.ndarray]:
                ctx.__enter__()
                try:
                    return a.inputs(frame), a.read(0)
                finally:
                    ctx.__exit__(None, None, None)  # (handed back)

            planes, plane = in_thread(there)
            np.testing.assert_array_equal(planes, want)
            np.testing.assert_array_equal(plane, want[0])
            with pytest.raises(RendererError, match="not current in this thread"):  # (held by no thread now)
                a.inputs(frame)
            make_current(ctx)
            np.testing.assert_array_equal(a.inputs(frame), want)
    finally:
        ctx.release()
        make_current(frames[0])


def test_a_renderer_or_frame_source_called_from_a_thread_where_its_context_cannot_be_current_is_refused(
        frames) -> None:
    """The reference renderer and its frame source make their context current themselves, but EGL refuses it to a
    worker thread while another thread holds it, and moderngl's ``ctx.__enter__()`` says nothing: ``render`` there drew
    in no context and returned NaN frames, ``ReferenceFrameSource.frame`` NaN G-buffers. Now a RendererError naming the
    thread, and the context handed over (released in the thread holding it) gives identical frames there."""
    from rtp.plugins.moderngl import RendererError

    _, prev, cur = frames
    refused = "Renderer: its moderngl context could not be made current in this thread .*'worker'"
    try:
        with Renderer(W, H) as r:
            r.load_scene(procedural(3))
            first = r.render(prev.camera)
            want = r.render(cur.camera, first)
            for call in (lambda: r.render(cur.camera, first), lambda: r.load_scene(procedural(3)),
                         lambda: r.reproject(first.colour["1x1"], first.depth, prev.camera)):
                with pytest.raises(RendererError, match=refused):
                    in_thread(call)
            r.ctx.__exit__(None, None, None)  # handed over

            def there() -> Frame:
                try:
                    return r.render(cur.camera, first)
                finally:
                    r.ctx.__exit__(None, None, None)  # (handed back)

            got = in_thread(there)
            for name in ("albedo", "depth", "reprojected", "seen"):
                np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
            np.testing.assert_array_equal(r.render(cur.camera, first).colour["1x1"], want.colour["1x1"])
        with Adapter.frame_source(procedural(3), W, H) as source:
            adapter = source.adapter(("albedo.g", "seen"))
            x = adapter.inputs(source.frame(cur.camera, prev.camera))
            with pytest.raises(RendererError, match=refused):
                in_thread(lambda: source.frame(cur.camera, prev.camera))
            with pytest.raises(RendererError, match="Adapter: its moderngl context is not current"):
                in_thread(lambda: source.adapter(("albedo.g", "seen")))
            np.testing.assert_array_equal(adapter.inputs(source.frame(cur.camera, prev.camera)), x)
    finally:
        make_current(frames[0])


def close_beside_another_context(close: Any) -> list[str]:
    """``close()`` in a worker thread where another context is current, one holding buffers and textures of the
    first GL names (each its own value): the ones whose contents ``close`` changed (deleted under it)."""
    from rtp.plugins.moderngl import create_context
    from rtp.plugins.moderngl._glio import read_texture

    def work() -> list[str]:
        other = make_current(create_context())
        try:
            buffers = [other.buffer(np.full(4, i, np.float32).tobytes()) for i in range(1, 17)]
            textures = [other.texture((2, 2), 1, np.full(4, i, np.float32).tobytes(), dtype="f4") for i in range(1, 17)]
            close()
            changed = []
            for i, (b, t) in enumerate(zip(buffers, textures), 1):
                try:
                    ok = np.frombuffer(b.read(), np.float32)[0] == i
                except Exception:  # (a deleted buffer cannot be mapped)
                    ok = False
                changed += [] if ok else [f"buffer {b.glo}"]
                changed += [] if read_texture(t)[0, 0, 0] == i else [f"texture {t.glo}"]
            return changed
        finally:
            other.release()

    return in_thread(work)


def test_closing_from_a_thread_where_the_context_is_not_current_frees_nothing_and_says_so(
        frames, caplog: pytest.LogCaptureFixture) -> None:
    """An adapter (or a renderer of a borrowed context) closed in a worker thread while the engine's thread held its
    context freed its GL objects by name in whatever context was current there: an engine's other context lost the
    buffers and textures of those names (they read another's data, or failed to map), in silence; with none current
    they leaked, in silence. Now nothing is freed there, one warning names the object, the thread and the fix, and
    the object is closed all the same (no refusal: a close runs in a with block's exit, after an error)."""
    import logging

    from rtp.plugins.moderngl import RendererError, create_context

    _, prev, cur = frames
    ctx = make_current(create_context())  # (a context of few objects: its names are the other context's too)
    try:
        frame = _engine_frame(ctx, prev, cur)
        with caplog.at_level(logging.WARNING, logger="rtp.plugins.moderngl"):
            a = Adapter(("albedo.r", "reprojected.y.dx"), W, H, ctx=ctx)  # (.dx: a first pass, said with it)
            a.inputs(frame)
            assert close_beside_another_context(a.close) == []
            assert a.closed
            r = Renderer(W, H, ctx=ctx)
            r.load_scene(procedural(3))
            r.render(cur.camera)
            assert close_beside_another_context(r.release) == []
            with pytest.raises(RendererError, match="this renderer has been released"):
                r.render(cur.camera)
        said = [rec.getMessage() for rec in caplog.records]
        assert len(said) == 2, said
        assert said[0].startswith(f"an rtp moderngl Adapter ({W}x{H}, 2 channels) closed in thread 'worker', where its "
                                  "moderngl context is not current: its GL program, targets and framebuffer were not "
                                  "freed") and "ctx.__enter__()" in said[0], said[0]
        assert said[1].startswith(f"an rtp moderngl Renderer ({W}x{H}) closed in thread 'worker'") \
            and "renderer.ctx.__exit__(None, None, None)" in said[1], said[1]
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="rtp.plugins.moderngl"):
            with Adapter(("albedo.r",), W, H, ctx=ctx) as b:  # (in the thread holding the context: freed, unsaid)
                b.inputs(frame)
        assert not caplog.records
    finally:
        ctx.release()
        make_current(frames[0])


def test_a_renderer_or_frame_source_of_its_own_context_closed_in_another_thread_releases_it(
        frames, caplog: pytest.LogCaptureFixture) -> None:
    """A renderer (and a frame source) that made its context: released from a worker thread while the building
    thread held it, its objects were freed by name in the worker's current context (another context's buffers and
    textures deleted). Now the context itself is released (any thread may; its objects go with it), nothing else
    is touched, and nothing is said (nothing is left behind)."""
    import logging

    _, prev, cur = frames
    try:
        with caplog.at_level(logging.WARNING, logger="rtp.plugins.moderngl"):
            r = Renderer(W, H)
            r.load_scene(procedural(3))
            r.render(cur.camera)
            assert close_beside_another_context(r.release) == []
            assert is_released(r.ctx)
            source = Adapter.frame_source(procedural(3), W, H)
            adapter = source.adapter(("albedo.g", "seen"))
            adapter.inputs(source.frame(cur.camera, prev.camera))
            assert close_beside_another_context(source.close) == []
            assert source.closed and adapter.closed and is_released(source.renderer.ctx)
        assert not caplog.records, [rec.getMessage() for rec in caplog.records]
    finally:
        make_current(frames[0])


def test_leaving_a_with_ctx_block_unbinds_every_context(gl_context) -> None:
    """Why the adapter runs in the current context instead of wrapping its passes in ``with ctx:``
    (docs/adapters.md "Frame sources"): on EGL, leaving the block makes no context current, not the
    one current before it, so the engine's context would be unbound after each call. If glcontext
    ever restores the previous context, this fails and the adapter can switch and restore."""
    import moderngl

    outer, inner = (moderngl.create_standalone_context(backend="egl") for _ in range(2))
    try:
        make_current(outer)
        assert outer.buffer(b"abcd").read() == b"abcd"
        with inner:
            assert inner.buffer(b"efgh").read() == b"efgh"
        with pytest.raises(moderngl.Error, match="cannot create buffer"):
            outer.buffer(b"abcd")
    finally:
        for ctx in (inner, outer):
            make_current(ctx)
            ctx.release()
        make_current(gl_context)


def _motion_as_in_the_sdk(ctx: Any, frame: GBufferTextures, g: dict[str, Any], **given: Any) -> np.ndarray:
    """The adapter's motion.x / motion.y planes of ``frame``, checked against sdk.input_planes of the same G-buffers
    ``g`` (and ``given``: the engine's motion) to a thousandth of a pixel (the shader's float32 projection)."""
    h, w = g["depth"].shape
    with Adapter(("motion.y", "motion.x"), w, h, ctx=ctx) as a:
        got = a.inputs(frame)
    want = sdk.input_planes(("motion.y", "motion.x"), **g, **given)
    np.testing.assert_allclose(got, want, atol=1e-3)
    assert (got[:, g["depth"] == 0] == 0).all()  # (background: no motion)
    return got


def test_the_engines_motion_vectors_move_objects_on_the_gpu_as_in_the_sdk(frames) -> None:
    """GBufferTextures.motion: a square moving over a wall, the camera still, reprojected by the shader as by
    sdk.input_planes with the same motion vectors (every square pixel seen and fetched from the square)."""
    from .test_input_planes import _moving_square

    ctx = frames[0]
    g, motion = _moving_square()
    colour = g.pop("colour")
    h, w = g["depth"].shape
    channels = ("reprojected.r", "reprojected.g", "seen", "reprojected.y")
    want = sdk.input_planes(channels, **g, motion=motion)
    zeros = np.zeros((h, w, 3), np.float32)
    with Adapter(channels, w, h, ctx=ctx) as a:
        frame = GBufferTextures(albedo=_tex(ctx, zeros), normal=_tex(ctx, zeros), depth=_tex(ctx, g["depth"]),
                                view=g["view"], projection=g["projection"], prev_colour=_tex(ctx, g["prev_colour"]),
                                prev_depth=_tex(ctx, g["prev_depth"]), prev_view_projection=g["prev_view_projection"])
        static = a.inputs(frame)
        got = a.inputs(replace(frame, motion=_tex(ctx, motion)))
        with pytest.raises(sdk.ParameterError, match="motion"):
            a.inputs(replace(frame, motion=_tex(ctx, g["depth"])))  # one component: not motion vectors
    np.testing.assert_allclose(got, want, atol=1e-6)
    assert (got[2][8:16, 14:20] == 1).all() and static[2][8:16, 14:20].mean() < 0.5
    # motion.x / .y: the engine's on geometry, the camera's (still: none) without them
    moved = _motion_as_in_the_sdk(ctx, replace(frame, motion=_tex(ctx, motion)), g, motion=motion)
    geo = g["depth"] > 0
    np.testing.assert_array_equal(moved[1][geo], motion[..., 0][geo])
    assert np.abs(_motion_as_in_the_sdk(ctx, frame, g)).max() < 1e-3
    np.testing.assert_allclose(got[0][8:16, 14:20], colour[8:16, 14:20, 0], atol=1e-6)


@pytest.mark.parametrize(("shift", "turn"), [(5, 0.0), (0.25, 0.0), (2, 0.5)])
def test_an_orthographic_camera_reprojects_on_the_gpu_as_in_the_sdk(frames, shift: float, turn: float) -> None:
    """An isometric camera panning (tests/test_reproject.py): the shader follows its parallel lines and reads its
    previous depth through the previous projection as sdk.input_planes does; a quarter pixel over a steep plane is
    seen through the plain bilinear depth; turning, its background (the far plane's points) moves as the SDK's."""
    from .test_reproject import _isometric_pan

    ctx = frames[0]
    steep = (lambda x, y: 5.0 + 0.5 * x + 0.0 * y) if shift < 1 else None
    g = _isometric_pan(shift, steep, turn)
    h, w = g["depth"].shape
    channels = ("reprojected.r", "seen", "reprojected.y", "reprojected.b")
    tolerance = 0.001 if steep else sdk.DEFAULT_REPROJECTION_TOLERANCE
    want = sdk.input_planes(channels, **g, tolerance=tolerance)
    zeros = np.zeros((h, w, 3), np.float32)
    with Adapter(channels, w, h, ctx=ctx, tolerance=tolerance) as a:
        got = a.inputs(GBufferTextures(albedo=_tex(ctx, zeros), normal=_tex(ctx, zeros), depth=_tex(ctx, g["depth"]),
                                       view=g["view"], projection=g["projection"],
                                       prev_colour=_tex(ctx, g["prev_colour"]), prev_depth=_tex(ctx, g["prev_depth"]),
                                       prev_view_projection=g["prev_view_projection"]))
    np.testing.assert_array_equal(got[1], want[1])
    np.testing.assert_allclose(got, want, atol=1e-6)
    frame = GBufferTextures(albedo=_tex(ctx, zeros), normal=_tex(ctx, zeros), depth=_tex(ctx, g["depth"]),
                            view=g["view"], projection=g["projection"], prev_colour=_tex(ctx, g["prev_colour"]),
                            prev_depth=_tex(ctx, g["prev_depth"]), prev_view_projection=g["prev_view_projection"])
    motion = _motion_as_in_the_sdk(ctx, frame, g)
    mx = motion[1][g["depth"] > 0]  # the pan: every surface point was `shift` pixels to the right (turning: more)
    assert np.abs(mx - shift).max() < 1e-3 if not turn else (mx > shift).all()
    if turn:
        assert 0.05 < got[1].mean() < 0.95 and (got[1][g["depth"] == 0] == 1).any()
    else:
        k = int(np.ceil(shift))
        assert (got[1][:, :w - k] == 1).all() and got[1].mean() < 1.0


@pytest.mark.parametrize("up", [True, False])
def test_a_previous_frame_at_another_render_resolution_on_the_gpu(frames, up: bool) -> None:
    """Dynamic resolution: prev_colour and prev_depth textures at the previous frame's size (three times this one's,
    or a third), reprojected by the shader as by sdk.input_planes, with and without the engine's motion vectors;
    a prev_colour of another size than prev_depth is named."""
    from .test_reproject import _resized_frames

    ctx = frames[0]
    g = _resized_frames(3, up)
    h, w = g["depth"].shape
    motion = np.zeros((h, w, 2), np.float32)
    motion[..., 0] = 1.0
    channels = ("reprojected.r", "seen", "reprojected.y", "reprojected.b")
    zeros = np.zeros((h, w, 3), np.float32)
    frame = GBufferTextures(albedo=_tex(ctx, zeros), normal=_tex(ctx, zeros), depth=_tex(ctx, g["depth"]),
                            view=g["view"], projection=g["projection"], prev_colour=_tex(ctx, g["prev_colour"]),
                            prev_depth=_tex(ctx, g["prev_depth"]), prev_view_projection=g["prev_view_projection"])
    with Adapter(channels, w, h, ctx=ctx) as a:
        got = a.inputs(frame)
        moved = a.inputs(replace(frame, motion=_tex(ctx, motion)))
        with pytest.raises(sdk.ParameterError, match="prev_colour: expected a texture of prev_depth's size"):
            a.inputs(replace(frame, prev_colour=_tex(ctx, zeros[:-1])))
    still = sdk.input_planes(channels, **g)
    np.testing.assert_array_equal(got[1], still[1])
    np.testing.assert_allclose(got, still, atol=1e-6)  # (the shader's luma in float32)
    assert (got[1] == 1).all()
    want = sdk.input_planes(channels, **g, motion=motion)
    np.testing.assert_array_equal(moved[1], want[1])
    np.testing.assert_allclose(moved, want, atol=1e-6)
    _motion_as_in_the_sdk(ctx, frame, g)  # (in this frame's pixels, whatever the previous frame's size)
    _motion_as_in_the_sdk(ctx, replace(frame, motion=_tex(ctx, motion)), g, motion=motion)


def _corner(ctx: Any, image: np.ndarray, width: int, height: int, fill: float) -> Any:
    """A ``width`` x ``height`` texture holding ``image`` (top-left origin) in its bottom-left GL corner, as a frame
    of a lower render resolution drawn with a viewport at the origin leaves it; ``fill`` elsewhere."""
    img = image if image.ndim == 3 else image[..., None]
    big = np.full((height, width, img.shape[2]), fill, np.float32)
    big[height - img.shape[0]:, : img.shape[1]] = img  # (the image's last rows are GL's first)
    return _tex(ctx, big)


_REGION_CHANNELS = ("reprojected.r", "seen", "reprojected.y.dx", "reprojected.y.dy", "reprojected.y.blocks",
                    "albedo.y.tiles", "depth.edge", "normal.z", "albedo.g", "depth", "reprojected.y.tiles")


@pytest.mark.parametrize("case", ["rendered", "prev-larger", "prev-smaller"])
def test_a_frame_in_the_corner_of_larger_textures_gives_the_planes_of_its_size(frames, case: str) -> None:
    """Dynamic resolution drawn into the bottom-left corner of the engine's largest targets: GBufferTextures.size
    (and prev_size, the previous frame's corner, of another size) give, from an adapter built at the largest size,
    the planes an adapter of the frame's size gives from textures of that size, bit for bit, whatever the rest of
    the textures holds, neighbours' lumas (.dx, .blocks, .tiles, depth.edge) included; the same adapter then runs
    a frame of its full size and the corner again. check() reads the corners alone."""
    ctx, prev, cur = frames
    if case == "rendered":
        g = {"albedo": cur.albedo, "normal": cur.normal, "depth": cur.depth, "prev_colour": prev.colour["1x1"],
             "prev_depth": prev.depth, "view": cur.camera.view(), "projection": cur.camera.projection(W / H),
             "prev_view_projection": prev.camera.view_projection(W, H)}
    else:
        from .test_reproject import _resized_frames

        g = _resized_frames(2, case == "prev-larger")
        rng = np.random.default_rng(5)
        shape = g["depth"].shape
        g["albedo"] = rng.uniform(0, 1, (*shape, 3)).astype(np.float32)
        n = rng.normal(size=(*shape, 3)) + [0.0, 0.0, 3.0]
        g["normal"] = (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    h, w = g["depth"].shape
    ph, pw = g["prev_depth"].shape
    big_w, big_h = w + 37, h + 21
    textures = {k: _tex(ctx, g[k]) for k in ("albedo", "normal", "depth", "prev_colour", "prev_depth")}
    mats = {k: g[k] for k in ("view", "projection", "prev_view_projection")}
    exact = GBufferTextures(**textures, **mats)
    corners = {k: _corner(ctx, g[k], big_w, big_h, fill) for k, fill in (("albedo", 0.9), ("normal", 0.3),
                                                                          ("depth", 0.7))}
    corners.update({k: _corner(ctx, g[k], pw + 11, ph + 3, fill) for k, fill in (("prev_colour", 5.0),
                                                                                ("prev_depth", 0.4))})
    framed = GBufferTextures(**corners, **mats, size=(w, h), prev_size=(pw, ph))
    with Adapter(_REGION_CHANNELS, w, h, ctx=ctx) as small, Adapter(_REGION_CHANNELS, big_w, big_h, ctx=ctx) as a:
        want = small.inputs(exact)
        got = a.inputs(framed)
        assert a.frame_size(framed) == (w, h) and got.shape == want.shape == (len(_REGION_CHANNELS), h, w)
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(a.read(5), want[5])
        assert 0.1 < got[1].mean() and got[0].max() <= 1.0  # (seen, and no texel of the fill)
        whole = a.inputs(replace(framed, size=None, prev_size=None, prev_colour=corners["albedo"],
                                 prev_depth=corners["depth"]))
        assert whole.shape == (len(_REGION_CHANNELS), big_h, big_w) and a.read(0).shape == (big_h, big_w)
        np.testing.assert_array_equal(a.inputs(framed), want)
        assert a.check(framed) == small.check(exact)


def test_a_frames_size_is_checked_against_the_adapter_and_its_textures(frames) -> None:
    """GBufferTextures.size larger than the adapter's, not a pair of positive integers, or larger than a texture of
    the frame; prev_size larger than prev_colour or prev_depth: each a ParameterError naming the field and what was
    expected; without size a texture of another size than the adapter's points to size."""
    ctx, prev, cur = frames
    frame = _engine_frame(ctx, prev, cur)
    with Adapter(("seen", "albedo.y"), W, H, ctx=ctx) as a:
        with pytest.raises(sdk.ParameterError, match=f"size: this frame's render resolution {W + 1}x{H} is larger "
                                                     f"than the adapter's {W}x{H}"):
            a.inputs(replace(frame, size=(W + 1, H)))
        for bad in ((0, 4), (4.0, 4), (True, 4), (4, 4, 4), "ab", 7):
            with pytest.raises(sdk.ParameterError, match=r"size: expected \(width, height\) in pixels"):
                a.inputs(replace(frame, size=bad))
            with pytest.raises(sdk.ParameterError, match=r"prev_size: expected \(width, height\) in pixels"):
                a.inputs(replace(frame, prev_size=bad))
        small = _tex(ctx, cur.albedo[: H // 2, : W // 2])
        with pytest.raises(sdk.ParameterError, match=f"normal: expected a texture at least size {W // 2 + 1}x{H // 2} "
                                                     r"\(the frame in its bottom-left corner\), got "
                                                     f"{W // 2}x{H // 2}"):
            a.inputs(replace(frame, normal=small, size=(W // 2 + 1, H // 2)))
        with pytest.raises(sdk.ParameterError, match=f"prev_depth: expected a texture at least prev_size {W}x{H + 1}"):
            a.inputs(replace(frame, prev_colour=_tex(ctx, np.zeros((H + 1, W, 3), np.float32)), prev_size=(W, H + 1)))
        with pytest.raises(sdk.ParameterError, match=r"albedo: .* got 64x40 \(a frame of a lower render resolution in "
                                                     r"the corner of larger textures: GBufferTextures.size\)"):
            a.inputs(replace(frame, albedo=small))
        assert a.inputs(replace(frame, albedo=small, normal=small, depth=small, prev_size=(W // 2, H // 2),
                                size=(W // 2, H // 2))).shape == (2, H // 2, W // 2)


def test_check_names_convention_mistakes_in_the_engines_textures(frames) -> None:
    """Adapter.check(frame): sdk.check_gbuffers on the textures read back with the adapter's options: nothing
    on the renderer's own frame; normals in an 8-bit texture's encoding, named; world-space normals to an
    adapter told so, nothing."""
    ctx, prev, cur = frames
    world_n = cur.normal @ np.linalg.inv(cur.camera.view())[:3, :3].T
    with Adapter(("seen", "normal.z"), W, H, ctx=ctx) as a:
        assert a.check(_engine_frame(ctx, prev, cur)) == []
        warnings = a.check(_engine_frame(ctx, prev, cur, normal=_tex(ctx, cur.normal * 0.5 + 0.5)))
        assert any("not unit vectors with no component below 0: an encoded texture" in w for w in warnings)
        warnings = a.check(_engine_frame(ctx, prev, cur, view=np.diag([1.0, 1, -1, 1]) @ cur.camera.view()))
        assert any("a left-handed view space" in w for w in warnings), warnings
        with pytest.raises(sdk.adapters.AdapterFrameError, match="GBufferTextures"):
            a.check({"normal": None})  # type: ignore[arg-type]
    with Adapter(("seen", "normal.z"), W, H, ctx=ctx, normal_space="world") as b:
        assert b.check(_engine_frame(ctx, prev, cur, normal=_tex(ctx, world_n))) == []


def test_check_reads_normalised_textures_as_inputs_does(frames) -> None:
    """An engine's 8- and 16-bit UNORM / SNORM textures (moderngl's nu1, nu2, ni1, ni2), which inputs() reads: check()
    read them back through a table of f1, f2 and f4 alone and failed with a KeyError; read_texture now scales them
    as GL's samplers do."""
    from rtp.plugins.moderngl._glio import read_texture

    ctx, prev, cur = frames
    for dtype, values in (("nu1", [0, 51, 255]), ("nu2", [0, 13107, 65535]), ("ni1", [0, 127, 127]),
                          ("ni2", [0, 16384, 32767])):
        kind = {"nu1": np.uint8, "nu2": np.uint16, "ni1": np.int8, "ni2": np.int16}[dtype]
        t = ctx.texture((3, 1), 1, np.array(values, kind).tobytes(), dtype=dtype)
        np.testing.assert_allclose(read_texture(t)[0, :, 0], np.array(values) / np.iinfo(kind).max, rtol=1e-6)
        t.release()
    with Adapter(("seen", "reprojected.g"), W, H, ctx=ctx) as a:
        unorm = ctx.texture((W, H), 3, dtype="nu1")
        write_texture(unorm, np.round(prev.colour["1x1"] * 255).astype(np.uint8))
        frame = _engine_frame(ctx, prev, cur, prev_colour=unorm)
        assert a.check(frame) == a.check(_engine_frame(ctx, prev, cur)) == []
        np.testing.assert_allclose(a.inputs(frame)[1], cur.reprojected[..., 1], atol=0.5 / 255 + 1e-6)


def test_a_draw_leaves_the_engines_framebuffer_and_viewport_and_reads_a_comparing_depth_texture(frames) -> None:
    """After inputs() the engine's framebuffer is bound again with its viewport (its next clear lands in its own
    texture), closing leaves GL a framebuffer to draw into, and a moderngl depth texture, which compares by
    default, is read as the depth it holds (comparison off during the draw, then put back)."""
    ctx, prev, cur = frames
    _ = ctx.error  # (read: cleared; GL keeps an error until it is read)
    target = ctx.texture((W, H), 4, dtype="f4")
    engine = ctx.framebuffer(color_attachments=[target])
    engine.use()
    ctx.viewport = (1, 2, W - 3, H - 5)
    a = Adapter(("depth", "albedo.y.blocks", "seen"), W, H, ctx=ctx, depth_kind="window")
    p = cur.camera.projection(W / H)
    window = np.where(cur.depth > 0, (p[2, 2] * -cur.depth + p[2, 3]) / cur.depth * 0.5 + 0.5, 1.0)
    depth = ctx.depth_texture((W, H))
    assert depth.compare_func  # (moderngl's default: a shadow-map sampler)
    write_texture(depth, window.astype(np.float32))
    x = _engine_inputs(ctx, prev, cur, a, depth=depth)
    assert ctx.error == "GL_NO_ERROR"
    assert ctx.fbo is engine and ctx.viewport == (1, 2, W - 3, H - 5)
    ctx.clear(0.25, 0.5, 0.75, 1.0)
    assert np.allclose(np.frombuffer(target.read(), np.float32).reshape(H, W, 4)[H // 2, W // 2], (0.25, 0.5, 0.75, 1))
    np.testing.assert_allclose(x[0], cur.depth, rtol=2e-3, atol=1e-4)  # (as the same window depth in a float texture)
    assert depth.compare_func == "<="
    a.close()
    assert ctx.fbo is engine
    ctx.framebuffer(color_attachments=[ctx.texture((4, 4), 4)]).release()
    assert ctx.error == "GL_NO_ERROR"
    b = Adapter(("albedo.r",), W, H, ctx=ctx)
    b.inputs(_engine_frame(ctx, prev, cur))  # (nothing of the engine's bound: GL's framebuffer 0 after the draw)
    b.close()
    ctx.framebuffer(color_attachments=[ctx.texture((4, 4), 4)]).release()
    assert ctx.error == "GL_NO_ERROR"


def test_textures_an_adapter_cannot_read_are_refused_and_colours_are_clamped(frames) -> None:
    """Integer, multisample, released and other contexts' textures are refused by name (they read as garbage);
    albedo, material and the previous frame outside [0, 1] read clamped, as sdk.CHANNELS' ranges; a context
    released under an adapter is named; an adapter dropped unclosed says so (ResourceWarning)."""
    import gc
    import warnings

    from rtp.plugins.moderngl import create_context

    ctx, prev, cur = frames
    a = Adapter(("albedo.r", "reprojected.g", "roughness", "seen"), W, H, ctx=ctx)
    x = _engine_inputs(ctx, prev, cur, a, albedo=_tex(ctx, cur.albedo * 4.0),
                       prev_colour=_tex(ctx, prev.colour["1x1"] * 4.0), material=_tex(ctx, np.full((H, W, 3), 7.0)))
    geo = cur.depth > 0
    assert x[0].max() == 1.0 and x[1].max() == 1.0 and (x[2][geo] == 1.0).all()
    with Adapter(("reprojected.g",), W, H, ctx=ctx, clamp_colour=False) as through:  # (pixel coordinates, say)
        assert _engine_inputs(ctx, prev, cur, through, prev_colour=_tex(ctx, prev.colour["1x1"] * 4.0)).max() > 1.0
    with pytest.raises(sdk.ParameterError, match="clamp_colour: expected True or False"):
        Adapter(("seen",), W, H, ctx=ctx, clamp_colour="no")
    released = _tex(ctx, cur.albedo)
    released.release()
    refused = {"an integer dtype": ctx.texture((W, H), 4, dtype="u1"), "multisample": ctx.texture((W, H), 4, samples=4),
               "released": released}
    for why, tex in refused.items():
        with pytest.raises(sdk.ParameterError, match=r"albedo: .*(integer dtype|multisample|released)") as info:
            _engine_inputs(ctx, prev, cur, a, albedo=tex)
        assert why.split()[-1] in str(info.value) or why in str(info.value)
    other = create_context()
    try:
        foreign = other.texture((W, H), 4, dtype="f4")
        make_current(ctx)
        with pytest.raises(sdk.ParameterError, match="albedo: expected a texture of the adapter's context, got one of "
                                                     "another moderngl.Context"):
            _engine_inputs(ctx, prev, cur, a, albedo=foreign)
    finally:
        make_current(other)
        other.release()
        make_current(ctx)
    a.close()
    lost = create_context()
    c = Adapter(("albedo.r",), 8, 8, ctx=lost)
    lost.release()
    make_current(ctx)
    with pytest.raises(sdk.adapters.AdapterFrameError, match="context was released under this adapter"):
        c.inputs(GBufferTextures(albedo=None, normal=None, depth=None, view=np.eye(4), projection=np.eye(4)))
    c.close()  # (its objects went with the context)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        d = Adapter(("albedo.r", "albedo.y.blocks"), W, H, ctx=ctx)
        del d
        gc.collect()
    assert [w.category for w in caught] == [ResourceWarning]  # (one: its first pass is closed with it)


def test_block_and_tile_variances_on_the_gpu_at_a_ragged_size(gl_context: Any) -> None:
    # 70x50: partial 4x4 cells (edge repeated) and partial 16x16 tiles on the right and at the bottom
    ctx = make_current(gl_context)
    w, h = 70, 50
    rng = np.random.default_rng(5)
    albedo = rng.random((h, w, 3)).astype(np.float32)
    depth = np.full((h, w), 2.0, np.float32)
    cam = Camera((0.0, 1.0, 0.0))
    frame = GBufferTextures(albedo=_tex(ctx, albedo), normal=_tex(ctx, np.zeros((h, w, 3), np.float32)),
                            depth=_tex(ctx, depth), prev_colour=_tex(ctx, rng.random((h, w, 3)).astype(np.float32)),
                            prev_depth=_tex(ctx, depth), view=cam.view(), projection=cam.projection(w / h),
                            prev_view_projection=cam.view_projection(w, h))
    channels = ("albedo.y", "albedo.y.blocks", "albedo.y.tiles", "reprojected.y", "reprojected.y.blocks",
                "reprojected.y.tiles")
    with Adapter(channels, w, h, ctx=ctx) as a:
        x = a.inputs(frame)
    np.testing.assert_allclose(x[0], sdk.luma(albedo), atol=1e-6)
    for i in (0, 3):
        np.testing.assert_allclose(x[i + 1], sdk.block_variances(x[i]), atol=2e-4)
        np.testing.assert_allclose(x[i + 2], sdk.tile_variances(x[i]), atol=2e-4)
    assert x[1][48:, 68:].any() and x[2][48:, 64:].any()  # the partial edge cell and tile hold values


def test_an_adapter_whose_construction_fails_releases_what_it_made(gl_context: Any,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """A shader that did not compile, or targets the context had no room for, left the program, the targets made so
    far and the first pass's adapter held in the engine's context (the adapter was never returned: nothing could close
    it), and said so as an unclosed adapter's ResourceWarning when Python collected it. Now the constructor frees them
    before the error goes on, and the context stays the engine's."""
    import gc
    import warnings

    from rtp.plugins.moderngl import _adapter, create_context

    ctx = create_context()
    try:
        made: list[Any] = []

        def recording(name: str) -> None:
            make = getattr(ctx, name)

            def wrapped(*args: Any, **kwargs: Any) -> Any:
                made.append(make(*args, **kwargs))
                return made[-1]
            setattr(ctx, name, wrapped)

        for name in ("program", "vertex_array", "texture", "framebuffer"):
            recording(name)
        channels = ("reprojected.y.blocks", "seen", "albedo.r", "depth", "normal.z")  # a first pass, two targets
        source = _adapter.load_source

        def broken(name: str, defines: Any = None) -> str:  # the second pass's shader does not compile
            text = source(name, defines)
            return text + "\nthis is no GLSL;\n" if defines and defines.get("RTP_LUMA_PASS") == "true" else text

        monkeypatch.setattr(_adapter, "load_source", broken)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with pytest.raises(Exception, match="(?i)compil|error"):
                Adapter(channels, 32, 16, ctx=ctx)
            gc.collect()
        assert len(made) == 4 and all(is_released(o) for o in made), [type(o).__name__ for o in made]  # the first pass
        assert not [w for w in caught if w.category is ResourceWarning]
        monkeypatch.undo()
        made.clear()

        def no_room(*args: Any, **kwargs: Any) -> Any:  # the framebuffer, after the program and both targets
            raise MemoryError("no room for the framebuffer")

        framebuffer = ctx.framebuffer
        ctx.framebuffer = no_room
        with pytest.raises(MemoryError):
            Adapter(channels, 32, 16, ctx=ctx)
        assert made and all(is_released(o) for o in made if o is not None), [type(o).__name__ for o in made]
        ctx.framebuffer = framebuffer
        assert not is_released(ctx)
        Adapter(channels, 32, 16, ctx=ctx).close()  # (the context still builds one)
    finally:
        ctx.release()
        make_current(gl_context)


_ENGINE_VS = "#version 330\nin vec2 p;\nvoid main() { gl_Position = vec4(p, 0.0, 1.0); }\n"
_ENGINE_FS = "#version 330\nout vec4 c;\nvoid main() { c = vec4(0.25); }\n"


def _engine_gl_state(ctx: Any, engine: Any, vao: Any) -> None:
    """What an engine's frame leaves on its context before it calls the adapter: its framebuffer, program and
    vertex array bound, blending ONE, ONE, clockwise front faces culled at the back, a reverse-Z depth test,
    rasterizer discard, wireframe, a viewport and a small scissor, sampler objects (comparing, linear) bound to
    the adapter's units, another active texture unit, a pixel-store alignment of 8."""
    import moderngl

    engine.use()
    vao.render(vertices=3)
    ctx.enable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.RASTERIZER_DISCARD)
    ctx.blend_func = moderngl.ONE, moderngl.ONE
    ctx.front_face, ctx.cull_face, ctx.depth_func = "cw", "back", ">"
    ctx.wireframe = True
    ctx.viewport, ctx.scissor = (3, 2, 40, 30), (5, 4, 16, 12)
    for unit in range(10):
        ctx.sampler(compare_func=">=", filter=(moderngl.LINEAR, moderngl.LINEAR)).use(unit)
    ctx.texture((2, 2), 4).use(location=9)
    ctx.texture((3, 3), 1).read(alignment=8)


def test_an_engines_gl_state_changes_neither_the_planes_nor_the_rates_and_is_left_as_it_was(frames, tiny_model,
                                                                                           gl_context: Any) -> None:
    """Inside an engine's frame the adapter and RateSelector run on its context as the engine left it. Blending
    ONE, ONE added each draw to the last one's planes; clockwise front faces culled the full-screen triangle, and
    so did wireframe (edges only) and rasterizer discard: the planes were the last frame's or zeros. Now every plane
    and rate is the same, bit for bit, as on a clean context, twice over, and the engine's framebuffer, viewport,
    scissor, wireframe and enable flags are its own again afterwards, after an error inside the draw too."""
    import moderngl

    _, prev, cur = frames
    channels = tuple(CHANNEL_IDS)  # (every one, a first pass for the lumas included)
    pred = sdk.load(tiny_model())
    p, pp = cur.camera.projection(W / H), prev.camera.projection(W / H)

    def window(depth: np.ndarray, proj: np.ndarray) -> np.ndarray:
        return np.where(depth > 0, (proj[2, 2] * -depth + proj[2, 3]) / np.where(depth > 0, depth, 1) * 0.5 + 0.5,
                        1.0).astype(np.float32)

    def run(dirty: bool) -> list[np.ndarray]:
        ctx = moderngl.create_standalone_context(backend="egl", require=430)
        try:
            ctx.__enter__()
            depth, prev_depth = ctx.depth_texture((W, H)), ctx.depth_texture((W, H))  # (comparing, by default)
            write_texture(depth, window(cur.depth, p))
            write_texture(prev_depth, window(prev.depth, pp))
            frame = _engine_frame(ctx, prev, cur, depth=depth, prev_depth=prev_depth, material=_tex(ctx, cur.albedo),
                                  motion=_tex(ctx, np.stack([cur.channel("motion.x"), cur.channel("motion.y")], -1)))
            engine = ctx.framebuffer(color_attachments=[ctx.texture((W, H), 4, dtype="f4")])
            prog = ctx.program(vertex_shader=_ENGINE_VS, fragment_shader=_ENGINE_FS)
            cw = ctx.vertex_array(prog, [(ctx.buffer(np.array([-1, -1, -1, 3, 3, -1], "f4")), "2f", "p")])
            ccw = ctx.vertex_array(prog, [(ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], "f4")), "2f", "p")])
            out: list[np.ndarray] = []
            with Adapter(channels, W, H, ctx=ctx, depth_kind="window") as a, RateSelector(pred, ctx) as selector:
                if dirty:
                    _engine_gl_state(ctx, engine, cw)
                    assert ctx.error == "GL_NO_ERROR"
                for _ in range(2):
                    out.append(a.inputs(frame))
                    raw = pred.predict_raw(np.stack([out[-1][channels.index(c)] for c in pred.metadata.inputs]))
                    out += [selector.select(raw), selector.select(raw, saving=0.5), selector.decoded()]
                if not dirty:
                    return out
                assert ctx.fbo is engine and ctx.viewport == (3, 2, 40, 30) and ctx.scissor == (5, 4, 16, 12)
                assert ctx.wireframe and depth.compare_func == "<="

                def engine_draws() -> np.ndarray:  # what the engine's own draws do after the call
                    engine.use()
                    write_texture(engine.color_attachments[0], np.zeros((H, W, 4), np.float32))
                    cw.render(vertices=3)  # rasterizer discard: nothing
                    ctx.disable(moderngl.RASTERIZER_DISCARD)
                    ctx.wireframe = False
                    for v in (cw, cw, ccw):  # blended twice: 0.5; the counter-clockwise one culled
                        v.render(vertices=3)
                    ctx.enable(moderngl.RASTERIZER_DISCARD)
                    ctx.wireframe = True
                    return np.frombuffer(engine.color_attachments[0].read(), np.float32).reshape(H, W, 4)[..., 0]

                want = np.zeros((H, W), np.float32)
                want[4:16, 5:21] = 0.5  # (the scissor's rectangle, inside the viewport)
                np.testing.assert_array_equal(engine_draws(), want)

                class Failing:  # an error inside the draw
                    def render(self, **_: Any) -> None:
                        raise RuntimeError("draw failed")

                a._vao, vao = Failing(), a._vao
                with pytest.raises(RuntimeError, match="draw failed"):
                    a.inputs(frame)
                a._vao = vao
                assert ctx.fbo is engine and ctx.viewport == (3, 2, 40, 30) and ctx.scissor == (5, 4, 16, 12)
                assert ctx.wireframe and depth.compare_func == "<="
                np.testing.assert_array_equal(engine_draws(), want)
                assert ctx.error == "GL_NO_ERROR"
            return out
        finally:
            ctx.release()
            make_current(gl_context)

    clean, dirty = run(False), run(True)
    assert len(clean) == len(dirty) == 8
    for i, (c, d) in enumerate(zip(clean, dirty)):
        np.testing.assert_array_equal(d, c, err_msg=f"output {i}")
    assert clean[0][channels.index("seen")].any() and clean[0][channels.index("depth")].any()
