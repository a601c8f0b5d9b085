"""Tests of the reference deferred renderer (rtp.plugins.moderngl) and the numpy reprojection
reference (rtp.sdk._reproject).

The GL tests run on the session's headless EGL context (``gl_context`` in conftest.py; Mesa
llvmpipe is enough). They skip only when no GL context can be created at all; the numpy tests
always run.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from rtp.plugins.moderngl import Renderer, RendererError
from rtp.scene import Camera, Material, Mesh, PointLight, Scene, SunLight, box_mesh, checker_texture, quad_mesh
from rtp.sdk import ALL_RATES as RATES
from rtp.sdk import RATE_CODES, InputShapeError
from rtp.sdk._reproject import reproject, reproject_positions
from rtp.sdk.adapters import UnsupportedChannelError
from tests.conftest import make_current

# 162 x 98: not a multiple of 4, so the partial edge blocks (clamped shading samples) are exercised.
W, H = 162, 98


# ----------------------------------------------------------------------------- helpers
@pytest.fixture(scope="module")
def renderer(gl_context: Any) -> Iterator[Renderer]:
    r = Renderer(W, H, ctx=make_current(gl_context), shadow_map_size=1024)
    yield r
    make_current(gl_context)
    r.release()


def _sample_index(n: int, block: int) -> np.ndarray:
    """Index of the shading sample of every pixel along one axis (docs/renderer.md, clamped)."""
    i = np.arange(n)
    return np.minimum(i // block * block + block // 2, n - 1)


def _textured_scene() -> Scene:
    """A checkered floor, a wall, a few boxes and a textured quad facing the camera."""
    materials = [
        Material("floor", texture=checker_texture(64, 8), roughness=0.7),
        Material("box", base_color=(0.8, 0.3, 0.2, 1.0), roughness=0.3),
        Material("wall", base_color=(0.7, 0.7, 0.6, 1.0), roughness=0.9),
        Material("poster", texture=checker_texture(32, 16, (250, 200, 40), (20, 60, 200)), roughness=0.5),
    ]
    meshes = [
        quad_mesh((0, 0, -5), (8, 0, 0), (0, 0, -8), 0, (8, 8)),
        box_mesh((-1.0, 0.0, -4.0), (0.5, 1.5, -2.5), 1),
        box_mesh((1.5, 0.0, -7.0), (2.5, 2.5, -6.0), 1),
        box_mesh((-6.0, 0.0, -11.0), (6.0, 4.0, -10.0), 2),
        quad_mesh((-2.5, 2.2, -9.9), (1.5, 0, 0), (0, 1.0, 0), 3),
    ]
    return Scene("textured", meshes, materials, point_lights=[PointLight((0.0, 2.0, -1.5), intensity=6.0, radius=6.0)])


def _flat_scene() -> Scene:
    """Two large camera-facing quads whose lighting is constant: an unlit emissive one (black
    albedo, no specular) and an ambient-only Lambertian one (the sun is off)."""
    materials = [
        Material("emissive", base_color=(0.0, 0.0, 0.0, 1.0), specular=0.0, roughness=1.0, emissive=(0.6, 0.3, 0.1)),
        Material("matte", base_color=(0.5, 0.6, 0.3, 1.0), specular=0.0, roughness=1.0),
    ]
    meshes = [
        quad_mesh((-1.6, 0.0, -5.0), (1.4, 0, 0), (0, 2.0, 0), 0),
        quad_mesh((1.6, 0.0, -5.0), (1.4, 0, 0), (0, 2.0, 0), 1),
    ]
    return Scene("flat", meshes, materials, sun=SunLight(intensity=0.0), ambient=0.8)


def _front_camera(**kw) -> Camera:
    return Camera((0.0, 1.0, 2.0), **kw)


# ----------------------------------------------------------------------------- numpy reference (no GL)
def test_reference_reprojection_static_camera_is_identity():
    cam = Camera((0.5, 1.0, 2.0), yaw=20.0, pitch=-5.0)
    rng = np.random.default_rng(0)
    depth = rng.uniform(1.0, 20.0, (24, 40)).astype(np.float32)
    depth[:3] = 0.0  # some background
    colour = rng.uniform(0, 1, (24, 40, 3)).astype(np.float32)
    out, seen = reproject(colour, depth, depth, cam.view(), cam.projection(40 / 24), cam.view_projection(40, 24))
    assert seen.dtype == np.float32 and out.dtype == np.float32
    assert np.all(seen == 1.0)
    np.testing.assert_array_equal(out, colour)
    qx, qy, w = reproject_positions(depth, cam.view(), cam.projection(40 / 24), cam.view_projection(40, 24))
    np.testing.assert_allclose(qx, np.arange(40)[None, :] + 0.5 + 0 * qx, atol=1e-6)
    np.testing.assert_allclose(qy, 24 - (np.arange(24)[:, None] + 0.5) + 0 * qy, atol=1e-6)
    np.testing.assert_allclose(w[3:], depth[3:], rtol=1e-6)


def test_reference_reprojection_rejects_offscreen_occluded_and_sky_mismatch():
    cur = Camera((0.0, 0.0, 0.0))
    prev = Camera((0.0, 0.0, 0.0), yaw=30.0)  # looked further left: the right part of the view is new
    h, w = 20, 40
    depth = np.full((h, w), 10.0, np.float32)
    colour = np.ones((h, w, 3), np.float32)
    # (a constant depth is not a consistent surface under rotation: a loose tolerance here)
    out, seen = reproject(colour, depth, depth, cur.view(), cur.projection(w / h), prev.view_projection(w, h),
                          tolerance=1.0)
    assert seen[:, 0].all() and not seen[:, -1].any()
    assert np.all(out[seen == 0] == 0)
    # an occluder in the previous frame (depth 2 instead of 10) fails the depth test
    _, seen_occ = reproject(colour, np.full((h, w), 2.0, np.float32), depth, cur.view(), cur.projection(w / h),
                            cur.view_projection(w, h))
    assert not seen_occ.any()
    # current geometry where the previous frame saw sky, and the other way round: unseen
    _, s1 = reproject(colour, np.zeros((h, w), np.float32), depth, cur.view(), cur.projection(w / h), cur.view_projection(w, h))
    _, s2 = reproject(colour, depth, np.zeros((h, w), np.float32), cur.view(), cur.projection(w / h), cur.view_projection(w, h))
    assert not s1.any() and not s2.any()
    # a previous depth of another size than the previous colour: the typed error, not numpy's reshape ValueError
    with pytest.raises(InputShapeError, match=r"prev_colour must be \(H', W'\[, C\]\) with \(H', W'\) = \(20, 39\)"):
        reproject(colour, depth[:, :-1], depth, cur.view(), cur.projection(2.0), cur.view_projection(w, h))


def test_reference_reprojection_keeps_grazing_planes_seen():
    # A floor seen at a grazing angle: depth changes by far more than 2 % per pixel near the
    # horizon; the perspective-correct footprint test keeps it seen under a small camera move.
    h, w = 48, 64
    cur = Camera((0.0, 0.3, 0.0), pitch=-2.0)
    prev = Camera((0.02, 0.3, 0.05), pitch=-2.0)

    def floor_depth(cam: Camera) -> np.ndarray:
        inv = np.linalg.inv(cam.projection(w / h))
        xs = (np.arange(w) + 0.5) / w * 2 - 1
        ys = 1 - (np.arange(h) + 0.5) / h * 2
        ndc = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], -1.0, 1.0), -1)
        q = ndc @ inv.T
        ray_v = q[..., :3] / q[..., 3:]
        ray_w = ray_v @ cam.rotation().T
        t = -cam.position[1] / np.where(ray_w[..., 1] < 0, ray_w[..., 1], np.nan)
        d = t * -ray_v[..., 2]
        return np.where(np.isfinite(d) & (d > 0) & (d < 150), d, 0.0).astype(np.float32)

    d_cur, d_prev = floor_depth(cur), floor_depth(prev)
    colour = np.ones((h, w, 3), np.float32)
    _, seen = reproject(colour, d_prev, d_cur, cur.view(), cur.projection(w / h), prev.view_projection(w, h))
    geo = (d_cur > 0)[2:-2, 2:-2]
    assert seen[2:-2, 2:-2][geo].mean() > 0.97


# ----------------------------------------------------------------------------- G-buffers
@pytest.mark.gl
def test_gbuffer_sanity(renderer):
    renderer.load_scene(_textured_scene())
    f = renderer.render(_front_camera(pitch=-8.0))
    geo = f.mask > 0.5
    assert 0.3 < geo.mean() < 0.95, "the view should show geometry and sky"
    for name in ("albedo", "normal", "roughness", "metallic", "specular", "emissive", "depth", "shadow", "motion", "mask"):
        arr = getattr(f, name)
        assert arr.dtype == np.float32 and arr.shape[:2] == (H, W), name
    assert f.normal.shape == (H, W, 3) and f.motion.shape == (H, W, 2)
    n = f.normal[geo]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=2e-3)
    # every visible face faces the camera: n . (camera - p) > 0 with p rebuilt from the depth
    cam = f.camera
    inv_proj = np.linalg.inv(cam.projection(W / H))
    xs = (np.arange(W) + 0.5) / W * 2 - 1
    ys = 1 - (np.arange(H) + 0.5) / H * 2
    ndc = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], -1.0, 1.0), -1)
    q = ndc @ inv_proj.T
    ray = q[..., :3] / q[..., 3:]
    pos = ray / -ray[..., 2:3] * f.depth[..., None]
    assert np.all(np.einsum("nc,nc->n", n, -pos[geo]) > 0.0), "visible faces must face the camera"
    assert np.all(n[:, 2] > -1e-4), "no visible face points away along the view axis"
    assert np.all(f.depth[geo] > 0.0) and np.all(f.depth[~geo] == 0.0)
    for arr in (f.albedo, f.normal, f.roughness, f.shadow, f.motion):
        assert np.all(arr[~geo] == 0.0)
    assert np.all((f.albedo >= 0) & (f.albedo <= 1))
    rough = np.unique(f.roughness[geo])
    assert np.all(np.abs(rough[:, None] - np.array([0.3, 0.5, 0.7, 0.9])).min(axis=1) < 1e-3), rough
    assert np.all(f.motion == 0.0), "no previous camera: no motion"
    assert 0.0 < f.shadow[geo].mean() < 1.0, "the sun casts some shadow and lights something"
    assert set(f.colour) == set(RATES)
    for img in f.colour.values():
        assert img.shape == (H, W, 3) and img.dtype == np.float32
        assert img.min() >= 0.0 and img.max() <= 1.0
    assert np.all(f.reprojected == 0) and np.all(f.seen == 0), "no previous frame: nothing reprojected"
    from rtp.sdk import CHANNELS

    for name in CHANNELS:  # every model input channel the SDK knows is available from a frame
        plane = f.channel(name)
        assert plane.shape == (H, W), name
        assert np.all(plane >= CHANNELS[name].low) and np.all(plane <= CHANNELS[name].high), name
    assert np.array_equal(f.channel("albedo.g"), f.albedo[..., 1])
    with pytest.raises(UnsupportedChannelError, match="does not exist"):
        f.channel("albedo.w")
    with pytest.raises(UnsupportedChannelError, match="several components"):
        f.channel("albedo")


@pytest.mark.gl
def test_zero_mesh_normals_draw_the_geometric_normal(renderer):
    """A mesh whose normals are zero (degenerate vertices, or an asset without them) drew NaN normals,
    which the lighting pass and every model input then read; the geometric normal facing the camera is
    drawn instead, and on this scene of flat faces it is the mesh normal."""
    import copy

    from rtp.capture.scenes import procedural
    from rtp.capture.viewpoints import sample_viewpoints

    scene = procedural(0)
    camera = sample_viewpoints(scene, 1, seed=0)[0][1]
    flat = copy.deepcopy(scene)
    for mesh in flat.meshes:
        mesh.normals = np.zeros_like(mesh.normals)
    renderer.load_scene(scene)
    want = renderer.render(camera)
    renderer.load_scene(flat)
    got = renderer.render(camera)
    geo = want.depth > 0
    assert np.isfinite(got.normal).all() and np.isfinite(got.colour["1x1"]).all()
    np.testing.assert_allclose(np.linalg.norm(got.normal[geo], axis=-1), 1.0, atol=1e-5)
    assert ((got.normal * want.normal).sum(-1)[geo] > 0.99).mean() > 0.999
    back = quad_mesh((0.0, 0.0, -5.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))  # seen from behind (two-sided)
    back.normals = np.zeros_like(back.normals)
    renderer.load_scene(Scene("back", [back], [Material("m")]))
    f = renderer.render(Camera(position=(0.0, 0.0, 0.0), yaw=0.0, pitch=0.0, fov_y=60.0, near=0.05, far=100.0))
    assert (f.depth > 0).mean() > 0.05 and np.allclose(f.normal[f.depth > 0], (0.0, 0.0, 1.0), atol=1e-5)


def test_linear_depth_and_normal_of_a_facing_quad(renderer):
    renderer.load_scene(_flat_scene())
    f = renderer.render(Camera((0.0, 0.0, 0.0)))
    geo = f.mask > 0.5
    np.testing.assert_allclose(f.depth[geo], 5.0, rtol=1e-5)
    np.testing.assert_allclose(f.normal[geo], np.broadcast_to([0.0, 0.0, 1.0], f.normal[geo].shape), atol=1e-5)
    assert np.allclose(f.emissive[geo].max(), f.emissive[geo].max()) and f.emissive[geo].max() > 0.5


@pytest.mark.gl
def test_orientation_top_left(renderer):
    mats = [Material("red", base_color=(1.0, 0.0, 0.0, 1.0)), Material("green", base_color=(0.0, 1.0, 0.0, 1.0))]
    meshes = [box_mesh((-2.6, 1.2, -6.0), (-1.8, 2.0, -5.2), 0), box_mesh((1.8, -2.0, -6.0), (2.6, -1.2, -5.2), 1)]
    renderer.load_scene(Scene("orientation", meshes, mats))
    f = renderer.render(Camera((0.0, 0.0, 0.0)))
    red = (f.albedo[..., 0] > 0.9) & (f.albedo[..., 1] < 0.1)
    green = (f.albedo[..., 1] > 0.9) & (f.albedo[..., 0] < 0.1)
    ry, rx = np.nonzero(red)
    gy, gx = np.nonzero(green)
    assert len(ry) > 20 and len(gy) > 20
    assert ry.mean() < H / 2 and rx.mean() < W / 2, "an object at the top-left of the view is top-left in the array"
    assert gy.mean() > H / 2 and gx.mean() > W / 2
    fc = f.colour["1x1"][ry, rx]
    assert np.all(fc[:, 0] > fc[:, 1]), "final colour is oriented like the G-buffer"


@pytest.mark.gl
def test_motion_vectors_match_reprojection_geometry(renderer):
    renderer.load_scene(_textured_scene())
    cur = _front_camera(pitch=-8.0)
    prev_cam = Camera((-0.15, 0.9, 2.1), yaw=2.0, pitch=-7.0)
    f = renderer.render(cur, prev_camera=prev_cam)
    geo = f.mask > 0.5
    qx, qy, _ = reproject_positions(f.depth, cur.view(), cur.projection(W / H), prev_cam.view_projection(W, H))
    yy, xx = np.mgrid[0:H, 0:W]
    ref = np.stack([qx - (xx + 0.5), (H - qy) - (yy + 0.5)], axis=-1)
    np.testing.assert_allclose(f.motion[geo], ref[geo], atol=0.05)
    # the camera moved right and down relative to the previous one: the scene was further right
    # and higher on screen before (x right, y down)
    assert np.median(f.motion[geo][:, 0]) > 0


@pytest.mark.gl
def test_motion_is_zero_where_the_point_was_behind_the_previous_camera(renderer):
    """The G-buffer pass divided the previous clip position by max(w, 1e-6): a visible point behind the previous
    camera (it stood ahead of the current one: a backward step, a viewpoint pair of the capture) got motion of
    1e7-1e8 pixels, where sdk.input_planes' motion planes and the adapters give 0. Two of the 72 validation samples of
    data/val720 held such pixels (0.36% of all)."""
    renderer.load_scene(_textured_scene())
    cur = _front_camera(pitch=-8.0)
    prev_cam = Camera((0.0, 1.0, -3.0), pitch=-8.0)  # 5 m ahead: the floor and the near box were behind it
    f = renderer.render(cur, prev_camera=prev_cam)
    geo = f.mask > 0.5
    qx, qy, cw = reproject_positions(f.depth, cur.view(), cur.projection(W / H), prev_cam.view_projection(W, H))
    behind = geo & (cw <= 0)
    assert behind.sum() > 100 and (geo & (cw > 0)).sum() > 100
    assert np.all(f.motion[behind] == 0), np.abs(f.motion[behind]).max()
    yy, xx = np.mgrid[0:H, 0:W]
    ref = np.stack([qx - (xx + 0.5), (H - qy) - (yy + 0.5)], axis=-1)
    front = geo & (cw > 1e-3)
    np.testing.assert_allclose(f.motion[front], ref[front], atol=0.05)


# ----------------------------------------------------------------------------- software VRS
@pytest.mark.gl
def test_vrs_lighting_is_block_constant_before_post(renderer):
    renderer.load_scene(_textured_scene())
    f = renderer.render(_front_camera(pitch=-8.0, yaw=4.0), debug=True)
    assert f.lighting is not None and set(f.lighting) == set(RATES)
    l1 = f.lighting["1x1"]
    geo = f.mask > 0.5
    for rate in RATES:
        bw, bh = (int(v) for v in rate.split("x"))
        sy, sx = _sample_index(H, bh), _sample_index(W, bw)
        sample_geo = geo[np.ix_(sy, sx)]
        gathered = l1[np.ix_(sy, sx)]
        lit = f.lighting[rate]
        # blocks whose shading sample is geometry take exactly that sample's lighting
        np.testing.assert_array_equal(lit[sample_geo], gathered[sample_geo], err_msg=rate)
        # background stays full rate: sky pixels of sky-sampled blocks are the per-pixel sky
        sky = ~sample_geo & ~geo
        np.testing.assert_array_equal(lit[sky], l1[sky], err_msg=rate)
        # and hence constant over each aligned block (partial edge blocks included)
        for y0 in range(0, H, bh):
            for x0 in range(0, W, bw):
                if sample_geo[y0, x0]:
                    block = lit[y0 : y0 + bh, x0 : x0 + bw].reshape(-1, 3)
                    assert np.all(block == block[0]), (rate, y0, x0)
    # the 1x1 lighting is itself the lighting of every pixel
    assert np.all(l1[geo].sum(axis=1) > 0)


@pytest.mark.gl
def test_per_tile_vrs_takes_each_tile_from_its_rate_on_ragged_frames(gl_context: Any) -> None:
    """``shade_rates`` on a frame whose sides are no whole number of tiles nor of 4 pixels (98 rows: the GL
    rows run bottom-up, so a tile row flipped by the frame's height instead of the grid's is off by rows
    there): every pixel is its tile's uniform-rate image (FXAA off, so exactly); all-1x1 is full rate."""
    rng = np.random.default_rng(3)
    with Renderer(W, H, ctx=make_current(gl_context), shadow_map_size=512, fxaa=False) as r:
        r.load_scene(_textured_scene())
        f = r.render(_front_camera(pitch=-8.0, yaw=4.0))
        for tile in (4, 12, 16):
            th, tw = -(-H // tile), -(-W // tile)
            assert np.array_equal(r.shade_rates(np.zeros((th, tw), np.uint8), tile), f.colour["1x1"])
            codes = rng.choice([RATE_CODES[rate] for rate in RATES], (th, tw)).astype(np.uint8)
            per_pixel = np.repeat(np.repeat(codes, tile, 0), tile, 1)[:H, :W]
            want = np.zeros((H, W, 3), np.float32)
            for rate in RATES:
                m = per_pixel == RATE_CODES[rate]
                want[m] = f.colour[rate][m]
            got = r.shade_rates(codes, tile)
            bad = np.argwhere((got != want).any(-1))
            assert bad.size == 0, (tile, len(bad), bad[:4].tolist())


@pytest.mark.gl
def test_reduced_rates_differ_on_texture(renderer):
    renderer.load_scene(_textured_scene())
    f = renderer.render(_front_camera(pitch=-8.0))
    ref = f.colour["1x1"]
    diffs = {r: float(np.abs(f.colour[r] - ref).max()) for r in RATES[1:]}
    assert all(d > 0.1 for d in diffs.values()), diffs
    means = {r: float(np.abs(f.colour[r] - ref).mean()) for r in RATES[1:]}
    assert means["4x4"] > means["2x2"] > 0.0 and means["2x2"] > min(means["1x2"], means["2x1"]), means


@pytest.mark.gl
def test_rates_match_exactly_on_flat_constant_regions(renderer):
    renderer.load_scene(_flat_scene())
    f = renderer.render(Camera((0.0, 0.0, 0.0)))
    geo = f.mask > 0.5
    # interior of the quads: at least 6 px from any edge of the coverage
    interior = geo.copy()
    for dy in range(-6, 7):
        for dx in range(-6, 7):
            interior &= np.roll(np.roll(geo, dy, 0), dx, 1)
    interior[:6], interior[-6:], interior[:, :6], interior[:, -6:] = False, False, False, False
    assert interior.sum() > 500
    ref = f.colour["1x1"]
    for rate in RATES[1:]:
        np.testing.assert_array_equal(f.colour[rate][interior], ref[interior], err_msg=rate)
    # the emissive quad shows its (tone-mapped) emission, the matte one its ambient light
    left = interior & (np.arange(W)[None, :] < W // 2)
    right = interior & (np.arange(W)[None, :] >= W // 2)
    assert ref[left][:, 0].mean() > ref[left][:, 2].mean()
    assert ref[right][:, 1].mean() > ref[right][:, 2].mean()


@pytest.mark.gl
def test_fixed_exposure_overrides_auto_exposure(renderer):
    renderer.load_scene(_flat_scene())
    cam = Camera((0.0, 0.0, 0.0))
    auto = renderer.render(cam)
    assert np.isfinite(auto.log_avg_luminance) and auto.exposure > 0
    dark = renderer.render(cam, exposure=auto.exposure / 4)
    assert dark.exposure == pytest.approx(auto.exposure / 4)
    assert dark.colour["1x1"].mean() < auto.colour["1x1"].mean()



@pytest.mark.gl
def test_ao_strength_zero_turns_ambient_occlusion_off_where_it_was_total(gl_context: Any) -> None:
    """``ao_strength`` is the exponent of the SSAO term, 0 allowed: x**0 is 1, AO off. GLSL leaves pow(0, 0)
    undefined, and a fully occluded pixel (raw term 0: one sample, occluded) stayed 0 on llvmpipe (a black ambient
    where every other pixel had none taken; a NaN, and through the exposure a NaN frame, where a driver computes
    pow as exp2(y * log2 x)). Now every pixel's term is 1 and the frame is the one with no occlusion applied."""
    from rtp.capture.scenes import procedural
    from rtp.capture.viewpoints import sample_viewpoints

    scene = procedural(0)
    camera = sample_viewpoints(scene, 6, seed=0)[3][1]  # (a view with a fully occluded pixel under one sample)
    with Renderer(64, 48, ctx=make_current(gl_context), shadow_map_size=256, ao_samples=1) as full, \
            Renderer(64, 48, ctx=gl_context, shadow_map_size=256, ao_samples=1, ao_strength=0.0) as off:
        full.load_scene(scene)
        off.load_scene(scene)
        assert (full.render(camera).ao == 0.0).any()  # (the case: a raw term of exactly 0)
        f = off.render(camera)
        assert np.all(f.ao == 1.0), np.argwhere(f.ao != 1.0)[:4].tolist()
        assert all(np.isfinite(img).all() for img in f.colour.values())


@pytest.mark.gl
def test_past_max_point_lights_the_strongest_light_the_frame(gl_context):
    """With more point lights touching the view than max_point_lights, the frame is lit by the
    strongest (radiance over squared distance) as if the others did not exist; a light out of reach
    of the view never takes a slot, however bright."""
    wall = quad_mesh((0.0, 0.0, -4.0), (4.0, 0, 0), (0, 3.0, 0), 0)
    strong = PointLight((-1.0, 0.0, -3.0), colour=(1.0, 0.2, 0.1), intensity=8.0, radius=5.0)
    weak = PointLight((1.0, 0.0, -3.0), colour=(0.1, 0.2, 1.0), intensity=2.0, radius=5.0)
    behind = PointLight((0.0, 0.0, 30.0), intensity=1e4, radius=5.0)  # behind the camera: would outrank both

    def lit(lights: list[PointLight], n: int) -> np.ndarray:
        scene = Scene("wall", [wall], [Material("m", base_color=(0.8, 0.8, 0.8, 1.0), roughness=1.0, specular=0.0)],
                      point_lights=lights, sun=SunLight(intensity=0.0), ambient=0.0)
        with Renderer(64, 48, ctx=make_current(gl_context), shadow_map_size=64, max_point_lights=n) as r:
            r.load_scene(scene)
            return r.render(Camera((0.0, 0.0, 0.0)), exposure=1.0, debug=True).lighting["1x1"]

    one = lit([behind, weak, strong], 1)
    np.testing.assert_array_equal(one, lit([strong], 1))
    assert one[..., 0].mean() > 3 * one[..., 2].mean() > 0  # red: the strong light's colour
    both = lit([behind, weak, strong], 2)
    np.testing.assert_allclose(both, lit([strong], 1) + lit([weak], 1), rtol=2e-3, atol=1e-5)  # (half-float targets)

@pytest.mark.gl
def test_alpha_cutoff_cuts_holes(renderer):
    tex = checker_texture(64, 8, alpha_holes=True)
    mats = [Material("fence", texture=tex, alpha_cutoff=0.5)]
    renderer.load_scene(Scene("fence", [quad_mesh((0.0, 0.0, -3.0), (3.0, 0, 0), (0, 3.0, 0), 0)], mats))
    f = renderer.render(Camera((0.0, 0.0, 0.0), fov_y=40.0))
    expected = 1.0 - (tex[..., 3] == 0).mean()
    assert f.mask.mean() == pytest.approx(expected, abs=0.05)


# ----------------------------------------------------------------------------- reprojection
@pytest.mark.gl
def test_reprojection_static_camera(renderer):
    renderer.load_scene(_textured_scene())
    cam = _front_camera(pitch=-8.0)
    prev = renderer.render(cam)
    cur = renderer.render(cam, prev)
    assert np.all(cur.seen == 1.0), "a static camera sees everything it saw"
    np.testing.assert_array_equal(cur.reprojected, prev.colour["1x1"])
    np.testing.assert_allclose(cur.motion, 0.0, atol=1e-3)


@pytest.mark.gl
def test_a_prev_camera_that_is_not_prevs_own_is_refused(renderer):
    """`render(cam, prev, prev_camera=X)` took X for prev's camera in silence: motion vectors and the reprojection
    of prev's pixels from a camera that did not draw them. X that differs from prev.camera is refused naming both;
    X that repeats it (as an equal Camera, its position an array) draws what prev alone draws."""
    from rtp.sdk import ParameterError

    renderer.load_scene(_textured_scene())
    prev_cam = Camera((-0.6, 1.0, 2.0), yaw=-4.0, pitch=-8.0)
    cur_cam = Camera((0.3, 1.1, 1.8), yaw=3.0, pitch=-8.0)
    prev = renderer.render(prev_cam)
    with pytest.raises(ParameterError, match=r"^prev_camera and prev\.camera: two different previous cameras") as info:
        renderer.render(cur_cam, prev, prev_camera=cur_cam)
    assert isinstance(info.value, ValueError) and info.value.name == "prev_camera"
    assert repr(cur_cam) in str(info.value) and repr(prev_cam) in str(info.value)
    alone = renderer.render(cur_cam, prev)
    same = renderer.render(cur_cam, prev, prev_camera=Camera(np.array([-0.6, 1.0, 2.0]), yaw=-4.0, pitch=-8.0))
    np.testing.assert_array_equal(same.reprojected, alone.reprojected)
    np.testing.assert_array_equal(same.motion, alone.motion)


@pytest.mark.gl
def test_reprojection_moving_camera_matches_reference(renderer):
    renderer.load_scene(_textured_scene())
    prev_cam = Camera((-0.6, 1.0, 2.0), yaw=-4.0, pitch=-8.0)
    cur_cam = Camera((0.3, 1.1, 1.8), yaw=3.0, pitch=-8.0)
    prev = renderer.render(prev_cam)
    cur = renderer.render(cur_cam, prev)
    ref_col, ref_seen = reproject(
        prev.colour["1x1"], prev.depth, cur.depth, cur_cam.view(), cur_cam.projection(W / H),
        prev_cam.view_projection(W, H), tolerance=renderer.reprojection_tolerance,
    )
    # away from depth edges (where the 2 % test is decided by rounding) the masks are identical
    d = cur.depth
    pad = np.pad(d, 1, mode="edge")
    nb = np.stack([pad[1 + dy : 1 + dy + H, 1 + dx : 1 + dx + W] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    edge = (nb.max(0) - nb.min(0)) > 0.1 * np.maximum(d, 1e-3)
    away = ~edge
    mismatch = cur.seen != ref_seen
    assert mismatch[away].sum() <= 2, int(mismatch[away].sum())
    assert mismatch.mean() < 0.005
    both = (cur.seen == 1) & (ref_seen == 1)
    # nearest-texel fetches of the same previous image: equal, up to the odd texel-edge rounding
    differs = np.abs(cur.reprojected[both] - ref_col[both]).max(axis=1) > 1e-6
    assert differs.mean() < 0.002
    # unseen pixels carry no colour
    assert np.all(cur.reprojected[cur.seen == 0] == 0.0)
    # some geometry is disoccluded: on screen in the previous frame but hidden there (depth test)
    qx, qy, w = reproject_positions(cur.depth, cur_cam.view(), cur_cam.projection(W / H), prev_cam.view_projection(W, H))
    onscreen = (w > 0) & (qx >= 0) & (qx < W) & (qy >= 0) & (qy < H)
    disoccluded = (cur.mask > 0.5) & onscreen & (cur.seen == 0)
    assert disoccluded.sum() > 20
    assert (cur.seen[cur.mask > 0.5] == 1).mean() > 0.6


@pytest.mark.gl
def test_a_frame_within_the_side_limit_but_past_the_context_s_memory_is_a_renderer_error() -> None:
    """llvmpipe takes 16384 a side but cannot allocate a 16384x16384 frame's targets: moderngl said only
    "the framebuffer is not complete", and `rtp capture` had written its manifest by then."""
    with pytest.raises(RendererError, match="could not allocate the render targets of a 16384x16384 frame"):
        Renderer(16384, 16384)


@pytest.mark.gl
def test_two_renderers_each_draw_in_their_own_context(gl_context: Any, renderer: Renderer) -> None:
    """A renderer makes its context current in each call: with a second renderer's (or any other)
    context current, a draw used that context's objects of the same names (garbage, or a crash in
    free() with another scene). The borrowed context of the module's renderer is made current too."""
    cam = _front_camera()
    renderer.load_scene(_flat_scene())
    with Renderer(W, H) as a:
        a.load_scene(_textured_scene())
        alone = a.render(cam, a.render(_front_camera(yaw=3.0)))
        for c in (renderer.render(cam), None):  # the module's renderer, on the shared context, draws in between
            with Renderer(96, 64) as b:  # another size and scene; its new context is the current one
                b.load_scene(_flat_scene())
                b_frame = b.render(cam)
                again = a.render(cam, a.render(_front_camera(yaw=3.0)))
                np.testing.assert_array_equal(again.colour["1x1"], alone.colour["1x1"])
                np.testing.assert_array_equal(again.seen, alone.seen)
                np.testing.assert_array_equal(b.render(cam).colour["1x1"], b_frame.colour["1x1"])
                assert c is None or renderer.render(cam).colour["1x1"].shape == (H, W, 3)


def test_renderer_errors_and_lifetime(gl_context):
    ctx = gl_context
    with Renderer(32, 16, ctx=ctx, shadow_map_size=64) as r:
        with pytest.raises(RendererError, match="no scene"):
            r.render(Camera((0.0, 0.0, 0.0)))
        bad = Mesh(np.zeros((3, 3), np.float32), np.zeros((3, 3), np.float32), np.zeros((3, 2), np.float32),
                   np.array([[0, 1, 2]], np.uint32), 0)
        bad.normals = np.zeros((2, 3), np.float32)  # changed after it was made (its constructor refuses this)
        with pytest.raises(RendererError, match="mesh 0"):
            r.load_scene(Scene("bad", [bad], [Material("m")]))
        r.load_scene(Scene("empty", [], [Material("m")]))
        f = r.render(Camera((0.0, 0.0, 0.0)))
        assert np.all(f.mask == 0) and f.colour["4x4"].max() > 0  # sky only
        with Renderer(16, 16, ctx=ctx, shadow_map_size=64) as r2:
            r2.load_scene(Scene("empty", [], [Material("m")]))
            with pytest.raises(RendererError, match="previous frame"):
                r2.render(Camera((0.0, 0.0, 0.0)), f)
    with pytest.raises(RendererError, match="released"):
        r.render(Camera((0.0, 0.0, 0.0)))
    from rtp.plugins.moderngl import create_context

    gone = create_context()
    gone.release()
    with pytest.raises(RendererError, match="ctx: this moderngl context has been released"):  # was an AttributeError
        Renderer(16, 16, ctx=gone)
    with pytest.raises(RendererError, match="ctx: expected a moderngl.Context, got object"):
        Renderer(16, 16, ctx=object())
    # the SDK's range (sdk.MAX_REPROJECTION_TOLERANCE): above it the renderer's adapter refused it at the first frame
    with pytest.raises(RendererError, match=r"reprojection_tolerance: expected a number in \[0, 1\], got 1.5"):
        Renderer(16, 16, ctx=ctx, reprojection_tolerance=1.5)
    make_current(ctx)
    # past the context's largest texture moderngl only said "the framebuffer is not complete"
    limit = Renderer.max_frame_side(ctx)
    assert limit >= 4096
    for size, options in (((limit + 1, 16), {}), ((16, 16), {"shadow_map_size": limit + 1})):
        with pytest.raises(RendererError, match=f"at most {limit} pixels a side"):
            Renderer(*size, ctx=ctx, **options)
    for size, options in (((2.5, 16), {}), (("abc", 16), {}), ((16, 16), {"shadow_map_size": 0})):
        with pytest.raises(RendererError, match="positive integer"):
            Renderer(*size, ctx=ctx, **options)  # type: ignore[arg-type]
    for options, word in (({"ao_samples": -1}, "ao_samples"), ({"max_point_lights": 10**6}, "max_point_lights"),
                          ({"exposure_key": float("nan")}, "exposure_key"), ({"ao_radius": 0.0}, "ao_radius"),
                          ({"shadow_distance": -1.0}, "shadow_distance")):
        with pytest.raises(RendererError, match=f"^{word}: expected"):  # a GLSL compiler dump, or nothing, before
            Renderer(16, 16, ctx=ctx, **options)
    make_current(ctx)
    ctx.texture((2, 2), 1).release()  # a borrowed context stays open after a refused size


@pytest.mark.gl
def test_a_refused_scene_leaves_the_loaded_one(gl_context: Any) -> None:
    """A scene whose second mesh is malformed (appended after the scene was made, with a material index past its
    list) is refused before the loaded scene is let go: the renderer went on with no scene and the new scene's first
    mesh uploaded; now it draws the scene loaded before exactly as before."""
    with Renderer(40, 24, ctx=make_current(gl_context), shadow_map_size=64) as r:
        scene = _flat_scene()
        r.load_scene(scene)
        cam = _front_camera()
        before = r.render(cam)
        bad = Scene("bad", [quad_mesh((0, 0, -5), (1, 0, 0), (0, 1, 0), 0)], [Material("m")])
        bad.meshes.append(quad_mesh((0, 1, -5), (1, 0, 0), (0, 1, 0), 3))  # (Scene's own check ran before it)
        with pytest.raises(RendererError, match="mesh 1: material 3 not in 0..0"):
            r.load_scene(bad)
        assert r.scene is scene
        after = r.render(cam)
        for rate in RATES:
            np.testing.assert_array_equal(after.colour[rate], before.colour[rate], err_msg=rate)
        np.testing.assert_array_equal(after.albedo, before.albedo)


@pytest.mark.gl
def test_a_renderer_whose_borrowed_context_went_first_releases_quietly(gl_context: Any) -> None:
    """An engine that released its context before the renderer borrowing it: release() (and the with block's
    exit) raised an AttributeError from the released context; now the objects went with it, release marks the
    renderer released, closes its adapter without a ResourceWarning, and a second release does nothing."""
    import warnings

    from rtp.plugins.moderngl import create_context

    ctx = create_context()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", ResourceWarning)
            with Renderer(64, 48, ctx=ctx) as r:
                r.load_scene(_flat_scene())
                r.render(_front_camera())
                ctx.release()
            r.release()
        assert r._reprojector.closed
        with pytest.raises(RendererError, match="released"):
            r.render(_front_camera())
    finally:
        make_current(gl_context)


@pytest.mark.gl
def test_a_float_rate_image_and_a_texture_past_the_context_s_limit_are_refused(gl_context: Any) -> None:
    """shade_rates took a float image of codes ("expected integer D3D12 rate codes" said its own error; the SDK's
    engine_rates refuses one too); load_scene took a material texture past GL_MAX_TEXTURE_SIZE, a GL error moderngl
    does not check (the texture was never filled: black), and now refuses it with the scene loaded kept."""
    ctx = make_current(gl_context)
    with Renderer(64, 48, ctx=ctx) as r:
        r.load_scene(_flat_scene())
        r.render(_front_camera())
        th, tw = 3, 4
        assert r.shade_rates(np.full((th, tw), 5, np.int64), 16).shape == (48, 64, 3)  # (any integer dtype)
        with pytest.raises(RendererError, match=r"rates: expected integer D3D12 rate codes \(uint8\), got float64"):
            r.shade_rates(np.full((th, tw), 5.0), 16)
        limit = Renderer.max_frame_side(ctx)
        wide = Scene("wide", [quad_mesh((0, 0, -3), (1, 0, 0), (0, 1, 0), 0)],
                     [Material("strip", texture=np.full((1, limit + 1, 4), 255, np.uint8))])
        with pytest.raises(RendererError, match=f"material 0 \\('strip'\\): .* at most {limit} texels a side"):
            r.load_scene(wide)
        assert r.scene is not None and r.scene.name == _flat_scene().name  # (still drawing the scene it had)
        r.render(_front_camera())


@pytest.mark.gl
def test_resize_draws_as_a_renderer_made_at_that_size(gl_context: Any) -> None:
    """Dynamic resolution with one renderer: after ``resize`` a frame, its VRS image and its reprojection
    are those of a renderer made at the new size with the same shadow map (every plane bit for bit), the
    scene stays loaded, the old frame's targets are freed, and a bad size is a typed error that keeps the
    renderer drawing at its size."""
    ctx = make_current(gl_context)
    scene = _textured_scene()
    cams = (_front_camera(), _front_camera(yaw=4.0))
    rates = {}
    with Renderer(W, H, ctx=ctx, shadow_map_size=512) as r, \
            Renderer(96, 58, ctx=ctx, shadow_map_size=512) as fresh:
        r.load_scene(scene)
        fresh.load_scene(scene)
        r.render(cams[0])
        r.shade_rates(np.zeros((7, 11), np.uint8), 16)  # (the VRS targets of the old size, made and then freed)
        gl_objects = [o for o in vars(r).values() if hasattr(o, "mglo")]
        gl_objects += [o for d in vars(r).values() if isinstance(d, dict) for o in d.values() if hasattr(o, "mglo")]
        kept = {id(o) for o in (r._white, r._p_gbuffer, r._p_coarse)}  # (not of the frame's size)
        old_targets = [o for o in gl_objects + list(r._vrs or ()) if id(o) not in kept and type(o).__name__ in
                       ("Texture", "Framebuffer", "Renderbuffer", "Texture2D")]
        r.resize(96, 58)
        assert (r.width, r.height) == (96, 58) and r.settings["size"] == [96, 58] and r.shadow_map_size == 512
        with pytest.raises(RendererError, match="call render"):
            r.shade_rates(np.zeros((4, 6), np.uint8), 16)  # the frame before the resize is not the current one
        for renderer in (r, fresh):
            first = renderer.render(cams[0])
            second = renderer.render(cams[1], first)
            rng = np.random.default_rng(1)
            codes = rng.choice([0, 1, 4, 5, 6, 9, 10], size=(4, 6)).astype(np.uint8)
            rates[id(renderer)] = (second, renderer.shade_rates(codes, 16))
        (a, vrs_a), (b, vrs_b) = rates[id(r)], rates[id(fresh)]
        for name in ("depth", "normal", "albedo", "motion", "seen", "reprojected"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
        for rate in RATES:
            np.testing.assert_array_equal(a.colour[rate], b.colour[rate], err_msg=rate)
        np.testing.assert_array_equal(vrs_a, vrs_b)
        from rtp.plugins.moderngl._glio import is_released

        # nothing of the old size is left behind: its textures and framebuffers (the VRS ones too) are freed,
        # the scene's and the programs' are not
        assert len(old_targets) > 20 and all(is_released(o) for o in old_targets)
        assert not any(is_released(o) for o in (r._white, r._p_gbuffer, *(m.texture for m in r._materials if m.texture)))
        limit = Renderer.max_frame_side(ctx)
        for bad, word in (((0, 16), "positive integers"), ((2.5, 16), "positive integers"),
                          ((True, 16), "positive integers"), ((limit + 1, 16), f"at most {limit} pixels a side")):
            with pytest.raises(RendererError, match=f"resize: .*{word}"):
                r.resize(*bad)  # type: ignore[arg-type]
        assert (r.width, r.height) == (96, 58)
        np.testing.assert_array_equal(r.render(cams[0]).colour["1x1"], fresh.render(cams[0]).colour["1x1"])
        with pytest.raises(RendererError, match="could not allocate the render targets of a 16384x16384 frame"
                                                ".*kept 96x58"):
            r.resize(16384, 16384)
        assert (r.width, r.height) == (96, 58)
        np.testing.assert_array_equal(r.render(cams[0]).colour["1x1"], fresh.render(cams[0]).colour["1x1"])
    with pytest.raises(RendererError, match="released"):
        r.resize(32, 32)


def test_the_default_shadow_map_follows_the_frame_size(gl_context):
    """At least 4 shadow texels a pixel of a small frame's longer side (256 up to 64 px, 512 up to 128), 1024
    up to 1024 px, 2048 above; a size given is kept."""
    for (w, h), side in (((64, 48), 256), ((16, 64), 256), ((96, 64), 512), ((65, 8), 512), ((128, 128), 512),
                         ((129, 16), 1024), ((320, 192), 1024), ((1024, 1024), 1024), ((1025, 8), 2048)):
        with Renderer(w, h, ctx=gl_context) as r:
            assert r.shadow_map_size == side, (w, h)
    with Renderer(64, 48, ctx=gl_context, shadow_map_size=1024) as r:
        assert r.shadow_map_size == 1024


@pytest.mark.gl
def test_a_renderer_refusing_its_own_context_releases_it(gl_context: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """A context of too old an OpenGL (the renderer's own, made through EGL) was refused with the context left
    held: the renderer was never returned, so nothing released it (the frame-size and settings refusals did). Now
    every refusal after the context is made releases the one it made, and leaves a borrowed one alone."""
    from rtp.plugins.moderngl import _renderer, create_context
    from rtp.plugins.moderngl._glio import is_released

    made: list[Any] = []

    def recorded(require: int = 330) -> Any:  # an OpenGL 3.2 context
        made.append(create_context(require))
        made[-1].version_code = 320
        return made[-1]

    try:
        monkeypatch.setattr(_renderer, "create_context", recorded)
        with pytest.raises(RendererError, match="needs OpenGL >= 3.3"):
            Renderer(32, 16)
        assert len(made) == 1 and is_released(made[0])
        borrowed = create_context()
        borrowed.version_code = 320
        with pytest.raises(RendererError, match="needs OpenGL >= 3.3"):
            Renderer(32, 16, ctx=borrowed)
        assert not is_released(borrowed)
        borrowed.release()
    finally:
        monkeypatch.undo()
        make_current(gl_context)


@pytest.mark.gl
def test_shade_rates_whose_targets_could_not_be_made_works_on(gl_context: Any) -> None:
    """A rate image of a new grid (another tile size) whose targets the context had no room for left the renderer
    holding the old ones released: every later shade_rates failed with an AttributeError. Now the call fails alone,
    and what it made before the failure is released (a borrowed context keeps what is not)."""
    from rtp.plugins.moderngl import create_context
    from rtp.plugins.moderngl._glio import is_released

    ctx = create_context()
    texture = ctx.texture
    try:
        with Renderer(64, 48, ctx=ctx) as r:
            r.load_scene(_flat_scene())
            r.render(_front_camera())
            want = r.shade_rates(np.full((3, 4), 5, np.uint8), 16)
            made: list[Any] = []

            def one_then_none(*args: Any, **kwargs: Any) -> Any:  # room for the rate map, not the images
                if made:
                    raise MemoryError("no room")
                made.append(texture(*args, **kwargs))
                return made[-1]

            ctx.texture = one_then_none
            with pytest.raises(MemoryError):
                r.shade_rates(np.full((6, 8), 5, np.uint8), 8)
            ctx.texture = texture
            assert len(made) == 1 and is_released(made[0])
            np.testing.assert_array_equal(r.shade_rates(np.full((3, 4), 5, np.uint8), 16), want)
            np.testing.assert_array_equal(r.shade_rates(np.full((6, 8), 5, np.uint8), 8), want)  # (2x2 either way)
    finally:
        ctx.release()
        make_current(gl_context)


@pytest.mark.gl
def test_a_borrowed_context_s_gl_state_does_not_change_what_the_renderer_draws(gl_context: Any) -> None:
    """An engine that lends its context leaves its own GL state set between the renderer's calls. The passes took
    it as they found it: clockwise front faces flipped every normal of the two-sided G-buffer, a reverse-Z depth
    test ('>=') drew no geometry at all, wireframe drew edges, a depth range moved the shadow map's depths, a
    sampler object bound to a texture unit overrode the shadow map's comparison and FXAA's filtering, blending
    mixed shade_rates' composite and the reprojection with what their targets held, and a viewport or scissor the
    engine set while the renderer's framebuffer was still bound (moderngl sets them on it) cut the next image to
    that rectangle. Each call that draws now sets the state it assumes first: every frame, composite and
    reprojection is the one GL's default state draws."""
    import moderngl

    from rtp.plugins.moderngl import create_context

    ctx = create_context()
    try:
        with Renderer(97, 33, ctx=ctx, shadow_map_size=256) as r:
            r.load_scene(_textured_scene())
            cam, prev_cam = _front_camera(pitch=-8.0, yaw=4.0), _front_camera(pitch=-6.0)
            prev = r.render(prev_cam)
            codes = np.random.default_rng(0).choice([RATE_CODES[rate] for rate in RATES], (3, 7)).astype(np.uint8)
            want = r.render(cam, prev)
            want_vrs = r.shade_rates(codes, 16)
            want_rp = r.reproject(prev.colour["1x1"], prev.depth, prev_cam)
            other = np.full_like(codes, RATE_CODES["4x4"])

            def engine_state() -> None:
                ctx.enable(moderngl.BLEND)
                ctx.blend_func = moderngl.ONE, moderngl.ONE
                ctx.front_face = "cw"
                ctx.depth_func = ">="
                ctx.wireframe = True
                ctx.depth_clamp_range = (0.25, 1.0)
                ctx.viewport = ctx.scissor = (0, 0, 10, 10)  # (moderngl sets them on the bound framebuffer: the renderer's)
                sampler = ctx.sampler(filter=(moderngl.NEAREST, moderngl.NEAREST), repeat_x=True, repeat_y=True)
                for unit in range(8):
                    sampler.use(unit)

            r.shade_rates(other, 16)  # (the composite's target then holds another image: blending mixed it in, and
            engine_state()             # a viewport cut to 10x10 showed it around)
            np.testing.assert_array_equal(r.shade_rates(codes, 16), want_vrs)
            r.render(prev_cam)  # (the same: the targets hold another view)
            engine_state()
            got = r.render(cam, prev)
            for name in ("normal", "depth", "albedo", "shadow", "ao", "reprojected", "seen"):
                np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
            for rate in RATES:
                np.testing.assert_array_equal(got.colour[rate], want.colour[rate], err_msg=rate)
            r.reproject(np.ones_like(prev.colour["1x1"]), prev.depth, prev_cam)
            engine_state()
            for a, b in zip(r.reproject(prev.colour["1x1"], prev.depth, prev_cam), want_rp):
                np.testing.assert_array_equal(a, b)
    finally:
        ctx.release()
        make_current(gl_context)
