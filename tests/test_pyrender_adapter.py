"""The pyrender adapter against the reference renderer (moderngl) on the same procedural scene.

Both renderers draw ``procedural(3)`` from the same cameras; the adapter's inputs are compared
with the reference :class:`rtp.plugins.moderngl.Frame` channels. Tolerances (docs/adapters.md has
the measured numbers):

* ``seen``: identical on >= 99.99 % of the pixels away from depth/normal edges (measured: 1 pixel
  of ~220k differs, a position within rounding of a texel edge) and >= 99.9 % overall.
* albedo, flat-coloured materials: within 8-bit quantisation (1/255) everywhere on geometry away
  from edges. Textured materials: pyrender filters and mip-maps textures in sRGB-encoded space,
  the reference in linear space, so minified high-contrast texels differ by up to ~0.05 (with
  every texture made constant, the difference drops to 8-bit quantisation); the test asks a mean
  error <= 0.01 and >= 99.9 % of pixels within 0.06.
* normals: within 12-bit packing (1/4095 + float16 of the reference) on every geometry pixel; 8-bit
  normals within 1/255 + 1e-4.
* depth: relative error <= 1e-4 (24-bit depth buffer) on geometry.
* rates of a random-weight MetricNet exported with rtp-export: >= 95 % of tiles agree.

Runs wherever a headless GL context exists (EGL, Mesa llvmpipe is enough; the ``gl`` mark gives every
test the shared ``gl_context`` of conftest.py, which skips without one) and pyrender is installed.
"""

from __future__ import annotations

import logging
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.sdk.adapters import AdapterClosedError, UnsupportedChannelError
from tests.conftest import in_thread, make_current, pyrender_or_skip

pytestmark = pytest.mark.gl

W, H = 256, 144
ALL = ["reprojected.r", "reprojected.g", "reprojected.b", "seen", "albedo.r", "albedo.g", "albedo.b",
       "normal.x", "normal.y", "normal.z", "roughness", "metallic", "specular", "depth", "motion.x", "motion.y"]
PAPER = ["reprojected.r", "seen", "albedo.r", "normal.z"]


def _pose(camera: Any) -> np.ndarray:
    p = np.eye(4)
    p[:3, :3] = camera.rotation()
    p[:3, 3] = camera.position
    return p


def _edges(frame: Any) -> np.ndarray:
    """Pixels next to a coverage, depth (> 2 %) or normal (> ~8 degrees) discontinuity, dilated by 1."""
    from scipy.ndimage import binary_dilation

    d, n, m = frame.depth, frame.normal, frame.depth > 0
    e = np.zeros_like(m)
    for a, b in (((slice(1, None), slice(None)), (slice(None, -1), slice(None))),
                 ((slice(None), slice(1, None)), (slice(None), slice(None, -1)))):
        jump = (m[a] != m[b]) | (np.abs(d[a] - d[b]) > 0.02 * np.maximum(d[a], d[b])) | ((n[a] * n[b]).sum(-1) < 0.99)
        e[a] |= jump
        e[b] |= jump
    return binary_dilation(e, iterations=1)


class _Setup:
    """Reference frames and a pyrender scene for one procedural scene and three camera moves."""

    def __init__(self, flat: bool, gl_context: Any) -> None:
        from rtp.capture.scenes import procedural
        from rtp.plugins.moderngl import Renderer
        from rtp.plugins.pyrender import to_pyrender_scene
        from rtp.scene import Camera

        pyrender = pyrender_or_skip()
        scene = procedural(3, rooms=(2, 2), texture_size=64)
        rng = np.random.default_rng(1)
        mats = []
        for m in scene.materials:
            m = replace(m, alpha_cutoff=None)  # pyrender does not alpha-test: compare like with like
            if flat:
                m = replace(m, texture=None, base_color=(*rng.uniform(0.05, 0.95, 3), 1.0))
            mats.append(m)
        scene = replace(scene, materials=mats)
        self.pairs = []
        for sp in scene.spawn_points[:3]:
            c0 = Camera(sp.position, yaw=sp.yaw, pitch=-5.0)
            c1 = Camera((sp.position[0] + 0.2, sp.position[1] + 0.05, sp.position[2] - 0.15), yaw=sp.yaw + 5.0,
                        pitch=-3.0)
            self.pairs.append((c0, c1))
        with Renderer(W, H, ctx=make_current(gl_context)) as r:  # pyrender's contexts may be current
            r.load_scene(scene)
            self.frames = []
            for c0, c1 in self.pairs:
                f0 = r.render(c0)
                self.frames.append((f0, r.render(c1, f0)))
        self.scene = to_pyrender_scene(scene)
        c = self.pairs[0][0]
        self.camera = pyrender.PerspectiveCamera(yfov=np.radians(c.fov_y), znear=c.near, zfar=c.far)
        self.scene.add(self.camera, pose=np.eye(4))
        self.edges = [_edges(f1) for _, f1 in self.frames]

    def inputs(self, channels: list[str], **kw: Any) -> list[np.ndarray]:
        from rtp.plugins.pyrender import Adapter, SceneFrame

        with Adapter(channels, W, H, **kw) as adapter:
            return [adapter.inputs(SceneFrame(self.scene, _pose(c1), _pose(c0), f0.colour["1x1"], f0.depth))
                    for (c0, c1), (f0, _) in zip(self.pairs, self.frames)]

    def errors(self, xs: list[np.ndarray], channels: list[str], name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(|error|, edge, geometry)`` of one channel, flattened over the three frames."""
        i = channels.index(name)
        err = np.concatenate([np.abs(x[i] - f1.channel(name)).ravel() for x, (_, f1) in zip(xs, self.frames)])
        edge = np.concatenate([e.ravel() for e in self.edges])
        geo = np.concatenate([(f1.depth > 0).ravel() for _, f1 in self.frames])
        return err, edge, geo


@pytest.fixture(scope="module")
def textured(gl_context: Any) -> _Setup:
    return _Setup(flat=False, gl_context=gl_context)


@pytest.fixture(scope="module")
def textured_inputs(textured: _Setup) -> list[np.ndarray]:
    return textured.inputs(ALL)


@pytest.fixture(scope="module")
def flat(gl_context: Any) -> _Setup:
    return _Setup(flat=True, gl_context=gl_context)


# ---------------------------------------------------------------------------------------------- agreement


def test_shape_dtype_and_order(textured: _Setup, textured_inputs: list[np.ndarray]) -> None:
    x = textured_inputs[0]
    assert x.shape == (len(ALL), H, W) and x.dtype == np.float32 and x.flags.c_contiguous
    paper = textured.inputs(PAPER)[0]
    np.testing.assert_array_equal(paper, x[[ALL.index(c) for c in PAPER]])


def test_seen_mask_identical_away_from_edges(textured: _Setup, textured_inputs: list[np.ndarray]) -> None:
    err, edge, _ = textured.errors(textured_inputs, ALL, "seen")
    away = err[~edge]
    assert np.mean(away == 0) >= 0.9999, f"seen identical on {np.mean(away == 0):.5f} of non-edge pixels"
    assert np.mean(err == 0) >= 0.999
    assert 0.05 < np.mean(edge) < 0.2  # the edge band is a small part of the frame
    # the reprojected colour is the same texel wherever both call a pixel seen
    rep, _, _ = textured.errors(textured_inputs, ALL, "reprojected.g")
    assert np.mean(rep[~edge] <= 1e-3) >= 0.9999


def test_albedo_flat_within_8bit(flat: _Setup) -> None:
    xs = flat.inputs(["albedo.r", "albedo.g", "albedo.b"])
    for c in ("albedo.r", "albedo.g", "albedo.b"):
        err, edge, geo = flat.errors(xs, ["albedo.r", "albedo.g", "albedo.b"], c)
        tol = 1.0 / 255.0  # 8-bit target (<= 0.5/255) + float16 reference (<= 2.5e-4)
        assert err[geo & ~edge].max() <= tol, c
        assert np.mean(err[geo] <= tol) >= 0.999, c


def test_albedo_textured(textured: _Setup, textured_inputs: list[np.ndarray]) -> None:
    for c in ("albedo.r", "albedo.g", "albedo.b"):
        err, edge, geo = textured.errors(textured_inputs, ALL, c)
        e = err[geo & ~edge]
        # measured: max 0.052 (blue, mortar lines of a minified brick texture), mean <= 0.006
        assert e.mean() <= 0.01, (c, e.mean())
        assert np.mean(e <= 0.06) >= 0.999, (c, np.mean(e <= 0.06))


def test_normals_within_12bit(textured: _Setup, textured_inputs: list[np.ndarray]) -> None:
    for c in ("normal.x", "normal.y", "normal.z"):
        err, edge, geo = textured.errors(textured_inputs, ALL, c)
        tol = 1.0 / 4095.0 + 5e-5  # 12-bit packing + float32 reference
        assert err[geo & ~edge].max() <= tol, (c, err[geo & ~edge].max())
        assert np.mean(err[geo] <= tol) >= 0.999, c  # at edges a pixel may see another surface
        assert not err[~geo].any()  # background is 0 in both


def test_material_within_12bit(textured: _Setup, textured_inputs: list[np.ndarray]) -> None:
    for name in ("roughness", "metallic"):
        err, edge, geo = textured.errors(textured_inputs, ALL, name)
        assert np.all(err[geo & ~edge] <= 1.0 / 4095 + 2e-3), (name, err[geo & ~edge].max())
        assert np.mean(err[geo] <= 0.01) >= 0.99, name
    i = ALL.index("metallic")
    assert any(x[i].max() == 1.0 for x in textured_inputs) and all(x[ALL.index("roughness")].std() > 0 for x in textured_inputs)
    # specular: pyrender shades every dielectric with F0 = 4 % (specular 0.5), whatever the rtp scene said
    for x, (_, f1) in zip(textured_inputs, textured.frames):
        geo = f1.depth > 0
        assert np.all(x[ALL.index("specular")][geo] == 0.5) and not x[ALL.index("specular")][~geo].any()


def test_normals_8bit(textured: _Setup) -> None:
    chans = ["normal.x", "normal.y", "normal.z"]
    xs = textured.inputs(chans, normal_bits=8)
    for c in chans:
        err, edge, geo = textured.errors(xs, chans, c)
        assert err[geo & ~edge].max() <= 1.0 / 255.0 + 1e-4, (c, err[geo & ~edge].max())
        assert np.mean(err[geo] <= 1.0 / 255.0 + 1e-4) >= 0.999, c


def test_msaa_costs_accuracy_at_edges(textured: _Setup, textured_inputs: list[np.ndarray]) -> None:
    """pyrender's own 4x MSAA resolve: fine inside surfaces, wrong G-buffer values at edges."""
    chans = ["seen", "albedo.r", "normal.z", "depth"]
    xs = textured.inputs(chans, msaa=True, normal_bits=8)
    err, edge, geo = textured.errors(xs, chans, "normal.z")
    assert np.mean(err[geo & ~edge] <= 1.0 / 255.0 + 1e-4) >= 0.99
    bad_msaa = np.mean(err[geo & edge] > 0.05)
    ref, _, _ = textured.errors(textured_inputs, ALL, "normal.z")
    assert bad_msaa > 0.02 and np.mean(ref[geo & edge] > 0.05) < 0.001, (bad_msaa, np.mean(ref[geo & edge] > 0.05))
    seen, _, _ = textured.errors(xs, chans, "seen")
    assert np.mean(seen[~edge] == 0) >= 0.999
    from rtp.plugins.pyrender import Adapter, PyrenderUnavailableError

    with pytest.raises(sdk.ParameterError, match="normal_bits=8"):  # (an RtpError, still a ValueError)
        Adapter(["normal.z"], W, H, msaa=True)
    # each setting an RtpError naming it: bare ValueError, TypeError or AttributeError before
    for options, error, word in (({"normal_bits": 0}, sdk.ParameterError, "normal_bits"),
                                 ({"normal_bits": "12"}, sdk.ParameterError, "normal_bits"),
                                 ({"msaa": "yes"}, sdk.ParameterError, "msaa"),
                                 ({"reprojection_tolerance": float("nan")}, sdk.ParameterError, "reprojection_tolerance"),
                                 ({"reprojection_tolerance": "x"}, sdk.ParameterError, "reprojection_tolerance"),
                                 # (past sdk.input_planes' range: made, then every frame was refused, as "tolerance")
                                 ({"reprojection_tolerance": sdk.MAX_REPROJECTION_TOLERANCE * 2}, sdk.ParameterError,
                                  r"reprojection_tolerance: expected .* in \[0, 1\]"),
                                 ({"platform": 5}, PyrenderUnavailableError, "platform"),
                                 ({"renderer": object()}, sdk.adapters.AdapterFrameError, "renderer")):
        with pytest.raises(error, match=word):
            Adapter(["normal.z"], W, H, **options)
    with pytest.raises(sdk.adapters.UnsupportedChannelError, match="NoneType"):
        Adapter(None, W, H)  # type: ignore[arg-type]


def test_depth_and_motion(textured: _Setup, textured_inputs: list[np.ndarray]) -> None:
    err, edge, geo = textured.errors(textured_inputs, ALL, "depth")
    ref = np.concatenate([f1.depth.ravel() for _, f1 in textured.frames])
    assert (err[geo] / ref[geo]).max() <= 1e-4
    assert err[~geo].max() == 0.0
    for c in ("motion.x", "motion.y"):
        err, edge, geo = textured.errors(textured_inputs, ALL, c)
        assert err[geo & ~edge].max() <= 0.01, c  # pixels
        assert np.mean(np.abs(np.concatenate([x[ALL.index(c)].ravel() for x in textured_inputs])) > 1.0) > 0.1


def test_rates_agree_on_most_tiles(tmp_path: Path, textured: _Setup, textured_inputs: list[np.ndarray]) -> None:
    import torch

    from rtp import export
    from rtp.train import checkpoint
    from rtp.train.model import MetricNet

    torch.manual_seed(0)
    net = MetricNet(in_channels=4, out_channels=4)
    net.train()
    with torch.no_grad():  # BatchNorm statistics that are not the identity, as after training
        net(torch.rand(4, 4, 64, 64))
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.2, 0.2)
    meta = {"metric": "jnyang", "transform": {"type": "clamped", "mu_y": 0.25}, "tile_size": 16,
            "inputs": PAPER, "outputs": ["1x2", "2x1", "2x4", "4x2"], "default_threshold": 0.2, "weber_l": 0.02}
    path = export.export_checkpoint(checkpoint.save(tmp_path / "random.pt", net.eval(), meta), tmp_path / "random.onnx")
    predictor = sdk.load(path)
    idx = [ALL.index(c) for c in predictor.metadata.inputs]
    ours = np.stack([x[idx] for x in textured_inputs])
    ref = np.stack([np.stack([f1.channel(c) for c in predictor.metadata.inputs]) for _, f1 in textured.frames])
    # a threshold in the middle of each tile's smallest predicted error, so that the rates are mixed
    thr = float(np.median(predictor.predict(ref).min(axis=1)))
    a, b = predictor.shading_rates(ours, threshold=thr), predictor.shading_rates(ref, threshold=thr)
    assert a.shape == (3, -(-H // 16), -(-W // 16))
    assert len(np.unique(b)) >= 2
    share = float(np.mean(a == b))
    assert share >= 0.95, f"rates agree on {share:.3f} of tiles"


# ---------------------------------------------------------------------------------------------- contract


def test_unsupported_and_unknown_channels() -> None:
    from rtp.plugins.pyrender import Adapter

    with pytest.raises(UnsupportedChannelError, match="emissive"):
        Adapter(["albedo.r", "roughness", "emissive"], W, H)
    with pytest.raises(UnsupportedChannelError, match="unknown channel"):
        Adapter(["albedo.q"], W, H)
    assert "shadow" not in Adapter.supported_channels
    assert set(sdk.DEFAULT_INPUTS) <= Adapter.supported_channels


def test_entry_point_lookup() -> None:
    from rtp.plugins.pyrender import Adapter

    if "pyrender" not in sdk.adapters.available():  # entry points not installed in this environment
        sdk.adapters.register("pyrender", Adapter)
    assert sdk.adapters.get("pyrender") is Adapter
    assert Adapter.name == "pyrender" and issubclass(Adapter, sdk.adapters.Adapter)


def _asymmetric_scene(pyrender: Any) -> Any:
    """A red floor below the camera and a green wall on its left only."""
    import trimesh

    scene = pyrender.Scene(bg_color=(0.2, 0.3, 0.4, 1.0))

    def add(extents: tuple[float, float, float], centre: tuple[float, float, float], rgb: tuple[float, ...]) -> None:
        box = trimesh.creation.box(extents=extents)
        mat = pyrender.MetallicRoughnessMaterial(baseColorFactor=(*rgb, 1.0))
        pose = np.eye(4)
        pose[:3, 3] = centre
        scene.add(pyrender.Mesh.from_trimesh(box, material=mat, smooth=False), pose=pose)

    add((20.0, 0.1, 40.0), (0.0, -1.05, -10.0), (1.0, 0.0, 0.0))
    add((0.1, 10.0, 40.0), (-2.0, 0.0, -10.0), (0.0, 1.0, 0.0))
    scene.add(pyrender.PerspectiveCamera(yfov=np.radians(60.0)), pose=np.eye(4))
    return scene


def test_orientation_is_top_left() -> None:
    from rtp.plugins.pyrender import Adapter, SceneFrame

    pyrender = pyrender_or_skip()
    scene = _asymmetric_scene(pyrender)
    with Adapter(["albedo.r", "albedo.g", "normal.y", "normal.x", "depth"], 64, 48) as adapter:
        x = adapter.inputs(SceneFrame(scene, np.eye(4)))
    red, green, ny, nx, depth = x
    assert depth[0, 40:].max() == 0.0 and depth[-1].min() > 0.0  # sky on top, floor at the bottom
    assert red[-1, 40:].min() > 0.99 and ny[-1, 40:].min() > 0.99  # floor: red, normal up (+y in view space)
    assert green[24, :5].min() > 0.99 and green[24, -5:].max() == 0.0  # the wall is on the left
    assert nx[24, :5].min() > 0.99  # its visible side faces right (+x)


def test_zero_mesh_normals_give_the_geometric_normal() -> None:
    """A mesh whose normals are zero read normal.z -1 everywhere (the normalised zero vector); the
    geometric normal is drawn instead, as for a mesh without normals: on procedural(0)'s flat faces,
    the normals the mesh should have had."""
    import copy

    from rtp.capture.scenes import procedural
    from rtp.capture.viewpoints import sample_viewpoints

    pyrender_or_skip()
    scene = procedural(0)
    prev_camera, camera = sample_viewpoints(scene, 1, seed=0)[0]
    flat = copy.deepcopy(scene)
    for mesh in flat.meshes:
        mesh.normals = np.zeros_like(mesh.normals)
    planes = []
    for s in (scene, flat):
        with sdk.adapters.get("pyrender").frame_source(s, W, H) as source, sdk.adapters.get("pyrender")(
            ["normal.x", "normal.y", "normal.z", "depth", "reprojected.r"], W, H, **source.adapter_options()
        ) as adapter:
            planes.append(adapter.inputs(source.frame(camera, prev_camera)))
    want, got = planes
    geo = want[3] > 0
    # (pyrender's own lit image, the previous frame, is shaded from the zero normals too: darker, on
    # procedural(0) about half as bright, but finite in its 8-bit target, and so the reprojected plane)
    assert np.isfinite(got).all()
    assert ((got[:3] * want[:3]).sum(0)[geo] > 0.99).mean() > 0.999
    # seen from behind (two-sided), the geometric normal faces the camera as the flipped mesh normal does
    # (pyrender's mesh.vert normalises the zero normal into NaN; that read -1 here)
    from rtp.scene import Camera, Material, Scene, quad_mesh

    back = quad_mesh((0.0, 0.0, -5.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))  # front normal (0, 0, -1): away
    back.normals = np.zeros_like(back.normals)
    eye = Camera(position=(0.0, 0.0, 0.0), yaw=0.0, pitch=0.0, fov_y=60.0, near=0.05, far=100.0)
    with sdk.adapters.get("pyrender").frame_source(Scene("back", [back], [Material("m")]), 64, 48) as source, \
            sdk.adapters.get("pyrender")(["normal.z", "depth"], 64, 48, **source.adapter_options()) as adapter:
        nz, depth = adapter.inputs(source.frame(eye, eye))
    assert (depth > 0).mean() > 0.05 and np.allclose(nz[depth > 0], 1.0, atol=1e-3)


def test_scene_is_restored_and_errors_are_typed(caplog: pytest.LogCaptureFixture) -> None:
    from rtp.plugins.pyrender import Adapter, PyrenderAdapterError, SceneFrame

    pyrender = pyrender_or_skip()
    scene = _asymmetric_scene(pyrender)
    node = scene.main_camera_node
    bg = np.array(scene.bg_color)
    moved = np.eye(4)
    moved[:3, 3] = (0.3, 0.1, 0.0)
    with Adapter(PAPER, 64, 48) as adapter:
        f_prev = adapter.gbuffers(scene, np.eye(4))
        prev_u8 = (np.random.default_rng(0).random((48, 64, 3)) * 255).astype(np.uint8)
        a = adapter.inputs(SceneFrame(scene, moved, np.eye(4), prev_u8, f_prev.depth))
        b = adapter.inputs(SceneFrame(scene, moved, np.eye(4), prev_u8.astype(np.float32) / 255.0))  # depth rendered
        np.testing.assert_array_equal(a, b)
        assert 0.3 < a[1].mean() < 1.0
        np.testing.assert_array_equal(scene.get_pose(node), np.eye(4))
        np.testing.assert_array_equal(scene.bg_color, bg)
        assert isinstance(PyrenderAdapterError("x"), sdk.RtpError)
        with pytest.raises(PyrenderAdapterError, match="prev_pose"):
            adapter.inputs(SceneFrame(scene, moved))
        with pytest.raises(PyrenderAdapterError, match="prev_colour"):
            adapter.inputs(SceneFrame(scene, moved, np.eye(4), np.zeros((10, 10, 3))))
        with pytest.raises(PyrenderAdapterError, match="4x4"):
            adapter.inputs(SceneFrame(scene, np.eye(3), np.eye(4), prev_u8))
        # an HDR previous frame is clipped to [0, 1], as before, and said so once (it was silent)
        with caplog.at_level(logging.WARNING, logger="rtp.plugins.pyrender"):
            hdr = prev_u8.astype(np.float32) / 255.0 * 4.0
            clipped = adapter.inputs(SceneFrame(scene, moved, np.eye(4), hdr, f_prev.depth))
            adapter.inputs(SceneFrame(scene, moved, np.eye(4), hdr, f_prev.depth))
        np.testing.assert_array_equal(clipped, adapter.inputs(SceneFrame(scene, moved, np.eye(4), np.clip(hdr, 0, 1),
                                                                          f_prev.depth)))
        said = [r.getMessage() for r in caplog.records if "clipped to [0, 1]" in r.getMessage()]
        assert len(said) == 1 and said[0].startswith("prev_colour spans [0, 3.98]: clipped"), said
        no_cam = pyrender.Scene()
        with pytest.raises(PyrenderAdapterError, match="no camera"):
            adapter.inputs(SceneFrame(no_cam, np.eye(4), np.eye(4), prev_u8))
        # an explicit camera works on a scene without one, and leaves no node behind
        cam = pyrender.PerspectiveCamera(yfov=np.radians(60.0))
        x = adapter.inputs(SceneFrame(no_cam, moved, np.eye(4), prev_u8, camera=cam))
        assert x.shape == (4, 48, 64) and no_cam.main_camera_node is None and len(no_cam.camera_nodes) == 0
        with pytest.raises(sdk.adapters.AdapterFrameError, match="SceneFrame"):
            adapter.inputs((scene, moved, np.eye(4), prev_u8))  # type: ignore[arg-type]
    for use in (lambda: adapter.inputs(SceneFrame(scene, moved, np.eye(4), prev_u8)),
                lambda: adapter.render(scene, moved), lambda: adapter.gbuffers(scene, moved),
                lambda: adapter.renderer):  # (the renderer: a PyrenderAdapterError, not the adapters' closed error)
        with pytest.raises(AdapterClosedError, match="pyrender adapter has been closed"):
            use()
    adapter.close()  # closing twice is fine


def test_no_gl_context_is_a_typed_error(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where pyrender imports but cannot create its context (a missing driver), the adapter and the frame
    source both raise PyrenderUnavailableError naming the platform and the packages, and keep the cause."""
    from rtp.capture.scenes import procedural
    from rtp.plugins.pyrender import Adapter, PyrenderUnavailableError
    from rtp.plugins.pyrender._source import PyrenderFrameSource

    pyrender = pyrender_or_skip()

    def no_context(width: int, height: int) -> None:
        raise RuntimeError("eglInitialize failed")

    monkeypatch.setattr(pyrender, "OffscreenRenderer", no_context)
    for build in (lambda: Adapter(PAPER, 64, 48),
                  lambda: PyrenderFrameSource(Adapter, procedural(3, rooms=(1, 1), texture_size=16), 64, 48)):
        with pytest.raises(PyrenderUnavailableError, match="could not create a egl context .*eglInitialize "
                                                           "failed.*libegl-mesa0") as info:
            build()
        assert isinstance(info.value.__cause__, RuntimeError)


def test_a_frame_source_gives_a_users_scene_back() -> None:
    """A ``pyrender.Scene`` of the caller's: the source's camera node is its main camera while the source is
    open; close() removes the node and gives back the scene's own main camera (it stayed, a second camera and
    the main one, so the caller's next render drew from the source's last pose)."""
    from rtp.plugins.pyrender import Adapter, to_pyrender_scene
    from rtp.scene import Camera, Material, Scene, box_mesh

    pyrender = pyrender_or_skip()
    for own_camera in (True, False):
        scene = to_pyrender_scene(Scene("box", [box_mesh((-1, -1, -5), (1, 1, -3))], [Material("m")]))
        own = scene.add(pyrender.PerspectiveCamera(yfov=1.0), pose=np.eye(4)) if own_camera else None
        nodes = set(scene.nodes)
        with Adapter.frame_source(scene, 32, 24) as source:
            assert source.scene is scene and scene.main_camera_node not in nodes
            source.frame(Camera((0.0, 0.0, 0.0), yaw=5.0, fov_y=50.0), Camera((0.0, 0.0, 0.1), near=0.1))
        assert set(scene.nodes) == nodes and scene.main_camera_node is own
    # numpy's True is a flag like True (msaa= refused it; albedo= and to_pyrender_scene's flags took it)
    with Adapter(["depth"], 8, 8, msaa=np.True_, normal_bits=8) as adapter:
        assert adapter.msaa is True


def test_previous_depth_is_reused_only_for_the_same_scene_and_camera(monkeypatch: pytest.MonkeyPatch) -> None:
    """With ``prev_depth=None`` the adapter reuses the previous ``inputs`` call's depth when the scene, the camera and
    the pose match. They were matched by ``id()``: a new scene (and camera) at the address of a freed one was taken for
    it and got the freed scene's depth. ``id`` is made to give every object the same number here, as a reused address
    would: a scene with a box in front of the camera still gets its own depth (a static camera sees every pixel again),
    and the same scene and camera still reuse theirs (one render a frame, not two)."""
    from rtp.plugins.pyrender import Adapter, SceneFrame, _adapter

    pyrender = pyrender_or_skip()
    import trimesh

    first = _asymmetric_scene(pyrender)
    second = _asymmetric_scene(pyrender)  # the same, and a box filling the middle of the view 1.5 m away
    box = pyrender.Mesh.from_trimesh(trimesh.creation.box(extents=(1.5, 1.0, 0.1)), smooth=False)
    second.add(box, pose=np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -1.5], [0, 0, 0, 1.0]]))
    monkeypatch.setattr(_adapter, "id", lambda obj: 1, raising=False)
    with Adapter(["seen"], 64, 48) as adapter:
        renders = []
        gbuffers = adapter._gbuffers  # (what inputs draws its G-buffers with)

        def counted(*args: Any, **kwargs: Any) -> Any:
            renders.append(1)
            return gbuffers(*args, **kwargs)

        monkeypatch.setattr(adapter, "_gbuffers", counted)
        before, _ = adapter.render(first, np.eye(4))
        assert adapter.inputs(SceneFrame(first, np.eye(4), np.eye(4), before))[0].mean() == 1.0
        assert len(renders) == 2  # (no previous call: this frame's G-buffers and the previous depth)
        assert adapter.inputs(SceneFrame(first, np.eye(4), np.eye(4), before))[0].mean() == 1.0
        assert len(renders) == 3  # the same scene and camera: the previous depth reused
        before, _ = adapter.render(second, np.eye(4))
        assert adapter.inputs(SceneFrame(second, np.eye(4), np.eye(4), before))[0].mean() == 1.0
        assert len(renders) == 5  # another scene: its own previous depth rendered


def test_borrowed_renderer_and_bound_scene_error() -> None:
    """pyrender binds a scene to one renderer's context: borrow the user's, or say so clearly."""
    from rtp.plugins.pyrender import Adapter, PyrenderAdapterError, SceneFrame
    from rtp.plugins.pyrender._gbuffer import _delete_renderer

    pyrender = pyrender_or_skip()
    scene = _asymmetric_scene(pyrender)
    user = pyrender.OffscreenRenderer(64, 48)
    try:
        before, before_depth = user.render(scene)  # the user's own lit image: the scene is now bound to `user`
        with Adapter(["seen", "albedo.g"], 64, 48) as own:
            with pytest.raises(PyrenderAdapterError, match="renderer=r"):
                own.inputs(SceneFrame(scene, np.eye(4), np.eye(4), before, before_depth))
        with pytest.raises(PyrenderAdapterError, match="64x48"):
            Adapter(["seen"], 32, 24, renderer=user)
        # a frame source draws the displayed frame with a renderer of its own: pyrender's ValueError came out raw
        from rtp.scene import Camera

        with Adapter.frame_source(scene, 64, 48) as source, \
                pytest.raises(PyrenderAdapterError, match="bound to another pyrender renderer.*no other renderer"):
            source.frame(Camera((0.0, 0.0, 0.0)), Camera((0.0, 0.0, 0.1)))
        with Adapter(["seen", "albedo.g"], 64, 48, renderer=user) as adapter:
            x = adapter.inputs(SceneFrame(scene, np.eye(4), np.eye(4), before))  # prev depth: the adapter's own
            assert x[0].mean() == 1.0  # a static camera sees everything again
            # pyrender's display depth is an MSAA sample off the pixel centre: the grazing floor fails
            # the 2 % depth test far away (this is why prev_depth=None is recommended)
            x_msaa = adapter.inputs(SceneFrame(scene, np.eye(4), np.eye(4), before, before_depth))
            assert 0.5 < x_msaa[0].mean() < 1.0
            colour, _ = adapter.render(scene, np.eye(4))
            np.testing.assert_array_equal(colour, before)  # display draws are pyrender's own, MSAA included
        after, _ = user.render(scene)  # the borrowed renderer got its own program cache back
        np.testing.assert_array_equal(after, before)
        # a camera is placed, not scaled or sheared: such a pose read depth and normals in a distorted view space
        for bad in (np.diag([2.0, 2.0, 2.0, 1.0]), np.array([[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])):
            with Adapter(["seen"], 64, 48, renderer=user) as adapter, \
                    pytest.raises(PyrenderAdapterError, match="pose must be a rigid camera-to-world matrix"):
                adapter.inputs(SceneFrame(scene, bad, np.eye(4), before))
        # nor mirrored (orthonormal, determinant -1: a left-handed frame, its z axis turned): it was taken, and drew
        # the frame mirrored with every two-sided normal turned away from the camera
        with Adapter(["seen", "normal.z"], 64, 48, renderer=user) as adapter:
            for where in ("pose", "prev_pose"):
                frame = SceneFrame(scene, np.eye(4), np.eye(4), before)
                with pytest.raises(PyrenderAdapterError, match=f"^{where} must be a rigid .*mirrors"):
                    adapter.inputs(replace(frame, **{where: np.diag([1.0, 1.0, -1.0, 1.0])}))
            with pytest.raises(PyrenderAdapterError, match="mirrors"):
                adapter.render(scene, np.diag([-1.0, 1.0, 1.0, 1.0]))
    finally:
        _delete_renderer(user)  # not user.delete(): pyrender's terminates the EGL display every context shares
    # a deleted renderer was taken, and the first inputs() failed with an AttributeError from inside pyrender
    with pytest.raises(PyrenderAdapterError, match="this pyrender.OffscreenRenderer has been deleted"):
        Adapter(["seen"], 64, 48, renderer=user)


_DROPPED_UNCLOSED = """
import gc
import numpy as np
from rtp import sdk
from rtp.capture import load_scene
from rtp.scene import Camera
Adapter = sdk.adapters.get("pyrender")
scene, _ = load_scene("procedural:0", None, None, None)
sp = scene.spawn_points[0]
cam = Camera(sp.position, yaw=sp.yaw)
with Adapter.frame_source(scene, 64, 48) as source:
    with source.adapter(["albedo.y", "seen"]) as adapter:
        before = adapter.inputs(source.frame(cam, cam))
        own = Adapter(["albedo.y"], 64, 48)  # an adapter with a renderer of its own, never closed
        del own
        gc.collect()
        Adapter(["seen"], 64, 48).renderer.delete()  # pyrender's own delete() called on a renderer rtp made
        gc.collect()
        np.testing.assert_array_equal(adapter.inputs(source.frame(cam, cam)), before)
print("ok")
"""


def test_a_renderer_rtp_made_never_ends_the_display_the_others_share() -> None:
    """pyrender's OffscreenRenderer.delete() (also run when one is dropped) terminates the EGL display every
    renderer of the process shares: an adapter built with a renderer of its own and dropped unclosed inside a
    frame source broke the source (EGL_BAD_DISPLAY on its next draw and on close). The renderers rtp makes delete
    only their own context, however they go. In a process of its own: a regression would break every context."""
    import subprocess
    import sys

    pyrender_or_skip()
    run = subprocess.run([sys.executable, "-c", _DROPPED_UNCLOSED], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and run.stdout.strip().endswith("ok"), run.stderr[-2000:]


def test_adapters_sharing_one_renderer_each_draw_their_own_passes() -> None:
    """Two adapters may borrow one renderer (a light one every frame, a full one where the network runs:
    examples/pyrender_vrs.py); each gives what it gives alone, in whichever order they were built and run
    (the first built used to draw pyrender's lit image for every pass once the second had replaced the
    renderer's program cache)."""
    from rtp.plugins.pyrender import Adapter, SceneFrame
    from rtp.plugins.pyrender._gbuffer import _delete_renderer

    pyrender = pyrender_or_skip()
    scene = _asymmetric_scene(pyrender)
    full_ch, light_ch = ["albedo.g", "normal.y", "roughness", "depth"], ["albedo.r", "depth"]
    moved = np.eye(4)
    moved[:3, 3] = (0.2, 0.0, 0.0)
    user = pyrender.OffscreenRenderer(64, 48)
    try:
        with Adapter(full_ch, 64, 48, renderer=user) as alone:
            want_full = alone.inputs(SceneFrame(scene, moved))
        with Adapter(light_ch, 64, 48, renderer=user) as alone:
            want_light = alone.inputs(SceneFrame(scene, moved))
        lit_before, _ = user.render(scene)
        with Adapter(full_ch, 64, 48, renderer=user) as full, Adapter(light_ch, 64, 48, renderer=user) as light:
            for _ in range(2):
                np.testing.assert_array_equal(full.inputs(SceneFrame(scene, moved)), want_full)
                np.testing.assert_array_equal(light.inputs(SceneFrame(scene, moved)), want_light)
            lit, _ = full.render(scene, np.eye(4))
        np.testing.assert_array_equal(lit, lit_before)  # the displayed frame: pyrender's own draw
        np.testing.assert_array_equal(user.render(scene)[0], lit_before)
    finally:
        _delete_renderer(user)  # not user.delete(): pyrender's terminates the EGL display every context shares


def test_osmesa_gives_the_inputs_egl_gives(tmp_path) -> None:
    """The OSMesa platform (needs libosmesa6 and PyOpenGL >= 3.1.5) against EGL, each in its own process."""
    import ctypes.util
    import os
    import subprocess
    import sys
    from pathlib import Path

    if ctypes.util.find_library("OSMesa") is None:
        pytest.skip("libOSMesa is not installed (apt-get install libosmesa6; .ci/run installs it)")
    probe = Path(__file__).parent / "data" / "pyrender_platform_probe.py"
    out = {}
    for platform in ("egl", "osmesa"):
        env = {**os.environ, "PYOPENGL_PLATFORM": platform}
        r = subprocess.run([sys.executable, str(probe), platform, str(tmp_path / f"{platform}.npy")],
                           capture_output=True, text=True, env=env, timeout=300)
        assert r.returncode == 0, r.stderr[-2000:]
        out[platform] = np.load(tmp_path / f"{platform}.npy")
    egl, osm = out["egl"], out["osmesa"]
    assert 0.0 < egl[1].mean() < 1.0
    assert np.array_equal(egl[1], osm[1])  # seen mask
    np.testing.assert_allclose(osm[2:], egl[2:], atol=1 / 255 + 1e-6)  # albedo, normal z, depth
    # Reprojection fetches the nearest previous texel: a position on a texel boundary may round to
    # the neighbour on one platform (a 1e-7 depth difference), so allow a few such pixels.
    assert (np.abs(osm[0] - egl[0]) > 1 / 255 + 1e-6).mean() < 0.001


def test_opengl_imported_on_screen_first_names_fixes_that_work() -> None:
    """`import pyrender` before any PYOPENGL_PLATFORM is PyOpenGL on an on-screen platform, which no process
    can change: refused, naming two fixes. The second it named, "import rtp.plugins.pyrender first", did not
    help (importing the plugin sets nothing); each fix it names now is run here and works."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "PYOPENGL_PLATFORM"}
    pyrender_or_skip()
    first = ("import pyrender\nfrom rtp.plugins.pyrender import import_pyrender\nimport_pyrender()\n")
    r = subprocess.run([sys.executable, "-c", first], env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode != 0 and "PyOpenGL was imported before PYOPENGL_PLATFORM was set" in r.stderr, r.stderr
    assert "import_pyrender() instead of `import pyrender`" in r.stderr and "os.environ.setdefault" in r.stderr
    for fix in ('import os; os.environ.setdefault("PYOPENGL_PLATFORM", "egl")\nimport pyrender\n'
                "from rtp.plugins.pyrender import import_pyrender\nimport_pyrender()\n",
                "from rtp.plugins.pyrender import import_pyrender\npyrender = import_pyrender()\nimport pyrender\n"):
        r = subprocess.run([sys.executable, "-c", fix], env=env, capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr


def _moving_box_scene(pyrender: Any, parent: bool = False) -> tuple[Any, Any, Any]:
    """A grey wall 5 m in front of a fixed camera and a red box 3 m in front of it (under a parent node if
    ``parent``): (scene, the node to move, the box's mesh node)."""
    import trimesh

    scene = pyrender.Scene(bg_color=(0.0, 0.0, 0.0, 1.0), ambient_light=(0.5, 0.5, 0.5))
    wall = pyrender.Mesh.from_trimesh(trimesh.creation.box(extents=(30.0, 30.0, 0.1)), smooth=False,
                                      material=pyrender.MetallicRoughnessMaterial(baseColorFactor=(0.5, 0.5, 0.5, 1)))
    scene.add(wall, pose=np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -5.0], [0, 0, 0, 1]]))
    box = pyrender.Mesh.from_trimesh(trimesh.creation.box(extents=(1.0, 1.0, 0.2)), smooth=False,
                                     material=pyrender.MetallicRoughnessMaterial(baseColorFactor=(0.9, 0.1, 0.1, 1)))
    at = np.array([[1, 0, 0, -0.4], [0, 1, 0, 0], [0, 0, 1, -3.0], [0, 0, 0, 1]], float)
    if parent:
        holder = pyrender.Node(matrix=at)
        scene.add_node(holder)
        node = scene.add(box, parent_node=holder)
        moved = holder
    else:
        node = moved = scene.add(box, pose=at)
    scene.add(pyrender.PerspectiveCamera(yfov=np.radians(60.0)), pose=np.eye(4))
    return scene, moved, node


@pytest.mark.parametrize("parent", [False, True])
@pytest.mark.parametrize("given_depth", [True, False])
def test_moving_objects_are_fetched_from_where_they_were(parent: bool, given_depth: bool) -> None:
    """A box 1 m wide moved 0.8 m right between two frames of a fixed camera: given its previous pose, its pixels are
    fetched from where it was (seen, its own colour, its motion vector), and the wall it uncovered stays
    unseen; without it, most of the box is taken for something new. The previous depth, when the adapter
    renders it, is drawn with the box where it was."""
    from rtp.plugins.pyrender import Adapter, SceneFrame

    pyrender = pyrender_or_skip()
    scene, moved, _ = _moving_box_scene(pyrender, parent)
    w, h, eye = 160, 96, np.eye(4)
    with Adapter(["seen", "reprojected.r", "motion.x", "motion.y", "depth"], w, h) as adapter:
        prev_colour, _ = adapter.render(scene, eye)
        prev_depth = adapter.gbuffers(scene, eye, albedo=False, normals=()).depth
        before = np.array(moved.matrix, copy=True)
        after = before.copy()
        after[0, 3] += 0.8
        scene.set_pose(moved, after)
        frame = SceneFrame(scene, eye, prev_pose=eye, prev_colour=prev_colour, prev_depth=prev_depth)
        static = adapter.inputs(frame)
        adapter._last = None  # (no cached depth: the adapter draws the previous one itself)
        moving = adapter.inputs(replace(frame, prev_node_poses={moved: before},
                                        prev_depth=prev_depth if given_depth else None))
        assert np.array_equal(np.asarray(moved.matrix), after)  # (the scene is left as it was given)
    seen, red, mx, my, depth = moving
    focal = (h / 2) / np.tan(np.radians(30.0))  # pixels per unit at depth 1
    box = np.abs(depth - 2.9) < 0.05  # the box's front face, 2.9 m away
    inner = box.copy()
    for axis in (0, 1):
        inner &= np.roll(box, 1, axis) & np.roll(box, -1, axis)
    assert inner.sum() > 200
    # (without the node's move, only the fifth of the box that overlaps where it was is seen)
    assert seen[inner].mean() > 0.97 and static[0][inner].mean() < 0.35, (seen[inner].mean(), static[0][inner].mean())
    np.testing.assert_allclose(mx[inner], -0.8 * focal / 2.9, atol=0.05)  # previous minus current: to the left
    np.testing.assert_allclose(my[inner], 0.0, atol=0.05)
    assert np.abs(red[inner] - red[inner].mean()).max() < 0.02 and red[inner].mean() > 0.3  # the box's colour
    uncovered = (np.abs(prev_depth - 2.9) < 0.05) & (np.abs(depth - 5.0) < 0.1)  # wall where the box was
    assert uncovered.sum() > 20 and seen[uncovered].max() == 0.0
    assert np.abs(mx[np.abs(depth - 5.0) < 0.1]).max() < 1e-4  # the wall did not move


@pytest.mark.parametrize("winding", ["front", "back", "mirrored"])
def test_a_moving_double_sided_surface_seen_from_behind_has_its_motion(winding: str) -> None:
    """A double-sided quad 3 m in front of a fixed camera moved 0.8 m: pyrender's segmentation pass culls back
    faces whatever the material, so the quad seen from behind (or a mirrored node's, whose winding turns) was
    missing there, its pixels took the wall's id (no motion) and about 80 % of it was unseen. The pass that turns
    the winding leaves pyrender's own image as it was (the wall box is single-sided: culled as before)."""
    import trimesh

    from rtp.plugins.pyrender import Adapter, SceneFrame

    pyrender = pyrender_or_skip()
    scene, _, box = _moving_box_scene(pyrender)
    scene.remove_node(box)
    corners = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]])
    faces = np.array([[0, 2, 1], [0, 3, 2]]) if winding == "back" else np.array([[0, 1, 2], [0, 2, 3]])
    quad = pyrender.Mesh.from_trimesh(trimesh.Trimesh(corners, faces, process=False), smooth=False,
                                      material=pyrender.MetallicRoughnessMaterial(baseColorFactor=(0.9, 0.1, 0.1, 1),
                                                                                  doubleSided=True))
    moved = scene.add(quad)
    before = np.diag([-1.0 if winding == "mirrored" else 1.0, 1.0, 1.0, 1.0])
    before[:3, 3] = (-0.4, 0.0, -3.0)
    scene.set_pose(moved, before)  # (set_pose keeps a mirroring, which pyrender's add(pose=) takes apart)
    w, h, eye = 160, 96, np.eye(4)
    with Adapter(["seen", "motion.x", "motion.y", "depth"], w, h) as adapter:
        prev_colour, _ = adapter.render(scene, eye)
        after = before.copy()
        after[0, 3] += 0.8
        scene.set_pose(moved, after)
        lit, lit_depth = adapter.render(scene, eye)
        seen, mx, my, depth = adapter.inputs(SceneFrame(scene, eye, eye, prev_colour, prev_node_poses={moved: before}))
        again, again_depth = adapter.render(scene, eye)
        np.testing.assert_array_equal(again, lit)
        np.testing.assert_array_equal(again_depth, lit_depth)
    focal = (h / 2) / np.tan(np.radians(30.0))
    quad_px = np.abs(depth - 3.0) < 0.05
    assert quad_px.sum() > 500
    assert seen[quad_px].mean() > 0.97, seen[quad_px].mean()
    np.testing.assert_allclose(mx[quad_px], -0.8 * focal / 3.0, atol=0.05)
    np.testing.assert_allclose(my[quad_px], 0.0, atol=0.05)
    assert np.abs(mx[np.abs(depth - 4.95) < 0.1]).max() < 1e-4  # the wall did not move


def test_a_mirrored_node_keeps_its_normals_facing_the_camera() -> None:
    """A double-sided box whose node is mirrored (scale -1 on x, kept by ``scene.set_pose``) draws the same picture
    as the plain box (the box is symmetric): its normals must be the same. Its triangles reach the screen with
    the winding turned, gl_FrontFacing false on every face the camera sees, and the shader flipped them all
    (normal.z -0.9 where the camera looks at the box's front)."""
    import trimesh

    from rtp.plugins.pyrender import Adapter

    pyrender = pyrender_or_skip()
    out = []
    for mirror in (1.0, -1.0):
        scene = pyrender.Scene(ambient_light=(0.3, 0.3, 0.3))
        material = pyrender.MetallicRoughnessMaterial(baseColorFactor=(0.5, 0.5, 0.5, 1.0), doubleSided=True)
        node = scene.add(pyrender.Mesh.from_trimesh(trimesh.creation.box((2.0, 2.0, 2.0)), smooth=False,
                                                    material=material))
        scene.set_pose(node, np.diag([mirror, 1.0, 1.0, 1.0]))
        scene.add(pyrender.PerspectiveCamera(yfov=1.0, zfar=100.0))
        pose = np.eye(4)
        pose[:3, 3] = (0.0, 0.5, 5.0)
        with Adapter(["normal.z"], 40, 30) as adapter:
            out.append(adapter.gbuffers(scene, pose))
    plain, mirrored = out
    assert plain.normal[15, 20, 2] > 0.9  # (the box's front, seen from 5 m)
    np.testing.assert_array_equal(mirrored.depth, plain.depth)
    np.testing.assert_allclose(mirrored.normal, plain.normal, atol=1e-3)


def test_a_mirrored_instance_keeps_its_normals_facing_the_camera() -> None:
    """pyrender's instancing (``Mesh.from_trimesh(..., poses=...)``) with one instance mirrored (scale -1 on x, the
    box symmetric so the picture is the same): the shader took a mirror from the node's pose only, not the
    instance's, so that instance's two-sided normals all faced away (normal.z -1 on its front, check_gbuffers
    warning of 49% of the surfaces facing away). Now the same normals as with both instances plain."""
    import trimesh

    from rtp.plugins.pyrender import Adapter

    pyrender = pyrender_or_skip()
    pose = np.eye(4)
    pose[:3, 3] = (0.3, 0.5, 4.0)
    out = []
    with Adapter(["normal.x", "normal.y", "normal.z"], 64, 48) as adapter:
        for mirror in (1.0, -1.0):
            scene = pyrender.Scene()
            scene.add(pyrender.PerspectiveCamera(yfov=1.0, zfar=100.0))
            material = pyrender.MetallicRoughnessMaterial(baseColorFactor=(0.5, 0.5, 0.5, 1.0), doubleSided=True)
            poses = np.tile(np.eye(4), (2, 1, 1))
            poses[:, 0, 3] = (-1.2, 1.2)
            poses[1, 0, 0] = mirror
            scene.add(pyrender.Mesh.from_trimesh(trimesh.creation.box((1.0, 1.0, 1.0)), smooth=False,
                                                 material=material, poses=poses))
            out.append(adapter.gbuffers(scene, pose))
            projection = adapter.projection(scene)
    plain, mirrored = out
    assert (plain.depth > 0).sum() > 300
    np.testing.assert_array_equal(mirrored.depth, plain.depth)
    np.testing.assert_allclose(mirrored.normal, plain.normal, atol=1e-3)
    assert sdk.check_gbuffers(depth=mirrored.depth, normal=mirrored.normal, view=np.linalg.inv(pose),
                              projection=projection) == []


def test_an_orthographic_camera_pans_over_a_scene() -> None:
    """pyrender's OrthographicCamera: its depth is linear depth (pyrender's read-back linearises every camera's as a
    perspective's), and panning it k pixels reprojects every pixel from k columns on (seen, the previous colour,
    motion.x = k), the k columns that came into view unseen; the box in front of the wall keeps its depth."""
    from rtp.plugins.pyrender import Adapter, SceneFrame

    pyrender = pyrender_or_skip()
    scene, _, _ = _moving_box_scene(pyrender)
    scene.remove_node(scene.main_camera_node)
    w, h, k = 160, 96, 6
    camera = pyrender.OrthographicCamera(xmag=4.0, ymag=4.0 * h / w, znear=0.5, zfar=20.0)
    scene.add(camera, pose=np.eye(4))
    eye, panned = np.eye(4), np.eye(4)
    panned[0, 3] = k * 8.0 / w  # k pixels of the 8 m the frame spans
    with Adapter(["seen", "reprojected.r", "motion.x", "motion.y", "depth"], w, h) as adapter:
        prev_colour, prev_depth = adapter.render(scene, eye)
        seen, red, mx, my, depth = adapter.inputs(SceneFrame(scene, panned, prev_pose=eye, prev_colour=prev_colour))
    box = np.abs(depth - 2.9) < 1e-3  # its front face, 2.9 m away, as the wall is 4.95 m: linear depths
    assert box.sum() > 200 and (np.abs(depth[~box] - 4.95) < 1e-3).all()
    np.testing.assert_allclose(prev_depth, np.roll(depth, k, axis=1), atol=1e-3)  # (where both are in the frame)
    inner = box & np.roll(box, 1, 1) & np.roll(box, -1, 1)  # (away from the box's sides, where 8-bit colour blends)
    assert (seen[:, :w - k] == 1).mean() > 0.995 and (seen[:, w - k:] == 0).all()
    np.testing.assert_allclose(red[:, :w - k][inner[:, :w - k]], prev_colour[:, k:, 0][inner[:, :w - k]] / 255.0,
                               atol=1e-6)
    np.testing.assert_allclose(mx, k, atol=1e-3)
    np.testing.assert_allclose(my, 0.0, atol=1e-3)


def test_node_poses_are_checked() -> None:
    from rtp.plugins.pyrender import Adapter, PyrenderAdapterError, SceneFrame

    pyrender = pyrender_or_skip()
    scene, moved, _ = _moving_box_scene(pyrender)
    eye = np.eye(4)
    with Adapter(["seen"], 32, 24) as adapter:
        colour, _ = adapter.render(scene, eye)
        frame = SceneFrame(scene, eye, prev_pose=eye, prev_colour=colour)
        for bad, match in [([moved], "expected a mapping"), ({pyrender.Node(): eye}, "is not a node of the scene"),
                           ({moved: np.ones((3, 3))}, "must be a finite affine 4x4"),
                           ({moved: np.full((4, 4), np.nan)}, "must be a finite affine 4x4")]:
            with pytest.raises(PyrenderAdapterError, match=match):
                adapter.inputs(replace(frame, prev_node_poses=bad))
        # nothing moved in the world: the camera's planes, exactly
        assert np.array_equal(adapter.inputs(replace(frame, prev_node_poses={moved: np.array(moved.matrix)})),
                              adapter.inputs(frame))


def test_a_camera_under_a_parent_node_is_drawn_from_the_world_pose() -> None:
    """A main camera under a parent node (a rig 2 m up): the pose given is where it is in the world. The adapter
    set it as the node's *local* pose, so every pass drew from the rig's pose times it (depth, motion, seen all
    off) and, putting back the world pose as the local one, left the camera 2 m higher than it was."""
    from rtp.plugins.pyrender import Adapter, SceneFrame

    pyrender = pyrender_or_skip()
    flat = _asymmetric_scene(pyrender)
    rigged = _asymmetric_scene(pyrender)
    rigged.remove_node(rigged.main_camera_node)
    rig = pyrender.Node(name="rig", translation=(0.0, 2.0, 0.0))
    rigged.add_node(rig)
    node = rigged.add(pyrender.PerspectiveCamera(yfov=np.radians(60.0)), pose=np.eye(4), parent_node=rig)
    before_local, before_world = np.array(node.matrix), rigged.get_pose(node)
    moved = np.eye(4)
    moved[:3, 3] = (0.3, 0.1, 0.0)
    channels = ["seen", "reprojected.r", "albedo.r", "normal.y", "depth", "motion.x", "motion.y"]
    out = []
    with Adapter(channels, 64, 48) as adapter:
        for scene in (flat, rigged):
            prev_colour, _ = adapter.render(scene, np.eye(4))
            out.append(adapter.inputs(SceneFrame(scene, moved, np.eye(4), prev_colour)))
            out.append(adapter.gbuffers(scene, moved).depth)
    np.testing.assert_array_equal(out[2], out[0])
    np.testing.assert_array_equal(out[3], out[1])
    np.testing.assert_array_equal(node.matrix, before_local)
    np.testing.assert_array_equal(rigged.get_pose(node), before_world)


def test_a_camera_with_znear_0_is_refused() -> None:
    """pyrender takes znear=0 for a PerspectiveCamera or an IntrinsicsCamera; its depth buffer then reads as
    background everywhere, and the adapter returned all-0 G-buffers in silence (pyrender's lit image showing the
    scene). Now a PyrenderAdapterError naming the camera and the fix."""
    from rtp.plugins.pyrender import Adapter, PyrenderAdapterError, SceneFrame

    pyrender = pyrender_or_skip()
    good = pyrender.PerspectiveCamera(yfov=np.radians(60.0))
    with Adapter(["albedo.r", "depth"], 32, 24) as adapter:
        for camera in (pyrender.PerspectiveCamera(yfov=np.radians(60.0), znear=0.0),
                       pyrender.IntrinsicsCamera(fx=30.0, fy=30.0, cx=16.0, cy=12.0, znear=0.0)):
            scene = _asymmetric_scene(pyrender)
            with pytest.raises(PyrenderAdapterError, match=f"{type(camera).__name__} has znear=0.0.*znear > 0"):
                adapter.gbuffers(scene, np.eye(4), camera=camera)
            with pytest.raises(PyrenderAdapterError, match="znear > 0"):
                adapter.inputs(SceneFrame(scene, np.eye(4), camera=camera))
            with pytest.raises(PyrenderAdapterError, match="znear > 0"):
                adapter.inputs(SceneFrame(scene, np.eye(4), camera=good, prev_camera=camera))
            scene.main_camera_node.camera = camera  # (pyrender's own: the main camera)
            with pytest.raises(PyrenderAdapterError, match="znear > 0"):
                adapter.inputs(SceneFrame(scene, np.eye(4)))
        assert adapter.gbuffers(_asymmetric_scene(pyrender), np.eye(4)).depth.max() > 0  # (znear 0.05)


def test_a_missing_gl_library_names_the_packages(monkeypatch: pytest.MonkeyPatch) -> None:
    """PyOpenGL reports a missing libEGL / libOSMesa as ``ImportError("Unable to load EGL library", ...)`` (no
    module name) while pyrender imports: that was "pyrender failed to import" without the packages to install,
    which the other ways the platform fails to load name. pyrender itself missing names the extra."""
    import importlib.abc
    import sys

    from rtp.plugins.pyrender import PyrenderUnavailableError, _gl, import_pyrender

    pyrender_or_skip()

    class NoEGL(importlib.abc.MetaPathFinder):
        def find_spec(self, name: str, path: Any = None, target: Any = None) -> None:
            if name == "pyrender":
                raise ImportError("Unable to load EGL library", "EGL: cannot open shared object file")
            return None

    monkeypatch.setattr(_gl, "_pyrender", None)
    monkeypatch.delitem(sys.modules, "pyrender")
    monkeypatch.setattr(sys, "meta_path", [NoEGL(), *sys.meta_path])
    with pytest.raises(PyrenderUnavailableError, match="could not load its egl platform .*Unable to load EGL library"
                                                       ".*apt-get install libegl1 libgl1 libegl-mesa0") as info:
        import_pyrender("egl")
    assert isinstance(info.value.__cause__, ImportError)
    monkeypatch.setitem(sys.modules, "pyrender", None)  # (not installed)
    with pytest.raises(ImportError, match=r"needs pyrender 0\.1\.45; install the extra: pip install 'rtp\[pyrender\]'"):
        import_pyrender("egl")


def test_an_adapter_and_a_frame_source_built_in_one_thread_work_in_another(caplog: pytest.LogCaptureFixture) -> None:
    """pyrender leaves a renderer's context current in the thread that last drew (its EGL ``make_uncurrent``
    does nothing), and a context is current in one thread at a time. An adapter (or frame source) built in one
    thread and called in a worker failed there ("pyrender failed to draw (EGLError ... EGL_BAD_ACCESS)"), and one
    a worker had drawn with, closed in the first thread, kept its context (close() only logged at debug level).
    The adapter's calls now leave current what was current before them: the worker's planes are the main
    thread's, and close() in the main thread frees the context."""
    from rtp.plugins.pyrender import Adapter, SceneFrame, to_pyrender_scene
    from rtp.scene import Camera, Material, Scene, box_mesh

    pyrender = pyrender_or_skip()
    scene = _asymmetric_scene(pyrender)
    moved = np.eye(4)
    moved[:3, 3] = (0.2, 0.0, 0.0)
    channels = ["reprojected.r", "seen", "albedo.g", "normal.y", "depth", "motion.x"]
    with caplog.at_level(logging.WARNING, logger="rtp.plugins.pyrender"):
        adapter = Adapter(channels, 64, 48)
        renderer = adapter.renderer

        def frame() -> np.ndarray:
            colour, _ = adapter.render(scene, np.eye(4))
            return adapter.inputs(SceneFrame(scene, moved, np.eye(4), colour))

        here = frame()
        np.testing.assert_array_equal(in_thread(frame), here)
        np.testing.assert_array_equal(frame(), here)  # (and back)
        in_thread(frame)
        adapter.close()
        assert renderer._platform is None  # its context destroyed, not left behind

        level = to_pyrender_scene(Scene("box", [box_mesh((-1, -1, -5), (1, 1, -3))], [Material("m")]))
        cam = Camera((0.0, 0.0, 0.0), yaw=5.0, fov_y=50.0)
        source = Adapter.frame_source(level, 32, 24)
        x = in_thread(lambda: source.adapter(["albedo.y", "seen"]).inputs(source.frame(cam, cam)))
        assert x.shape == (2, 24, 32) and x[0].max() > 0.0 and x[1].min() == 1.0
        renderer = source.renderer
        source.close()
        assert renderer._platform is None
    assert not caplog.records, [r.getMessage() for r in caplog.records]


def test_a_context_another_thread_holds_is_a_typed_error_naming_the_thread() -> None:
    """A borrowed renderer that an engine thread drew with last is current there (pyrender never releases it):
    the adapter's call from another thread says so, names the thread and the fix (it was "pyrender failed to
    draw (EGLError(...EGL_BAD_ACCESS...))"), and works once that thread releases the context."""
    import threading

    from rtp.plugins.pyrender import Adapter, PyrenderAdapterError, SceneFrame
    from rtp.plugins.pyrender._gbuffer import _delete_renderer

    pyrender = pyrender_or_skip()
    if os.environ.get("PYOPENGL_PLATFORM") != "egl":
        pytest.skip("EGL refuses a context current in another thread; OSMesa does not")
    from OpenGL import EGL

    scene = _asymmetric_scene(pyrender)
    drawn, release, released = threading.Event(), threading.Event(), threading.Event()
    made: dict[str, Any] = {}

    def engine() -> None:  # the engine's thread: makes its renderer, draws, holds the context until told
        made["renderer"] = user = pyrender.OffscreenRenderer(64, 48)
        made["colour"], _ = user.render(scene)
        drawn.set()
        release.wait(300)
        EGL.eglMakeCurrent(user._platform._egl_display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
        released.set()

    t = threading.Thread(target=engine, name="engine-thread")
    t.start()
    try:
        assert drawn.wait(300)
        with Adapter(["seen", "albedo.g"], 64, 48, renderer=made["renderer"]) as adapter:
            frame = SceneFrame(scene, np.eye(4), np.eye(4), made["colour"])
            with pytest.raises(PyrenderAdapterError, match="cannot be made current in thread 'MainThread'.*EGL_BAD_ACCESS"
                                                           ".*another thread holds this one.*release the context"):
                adapter.inputs(frame)
            release.set()
            assert released.wait(300)
            x = adapter.inputs(frame)
            assert x[0].mean() == 1.0 and x[1].max() > 0.99  # (a static camera sees everything again; the green wall)
    finally:
        release.set()
        t.join(300)
        if "renderer" in made:
            _delete_renderer(made["renderer"])


def _held_first_draw(monkeypatch: pytest.MonkeyPatch) -> tuple[Any, Any]:
    """``GBufferRenderer.render`` and ``.draw`` patched so that the first call of either stops before it draws (the
    camera already moved to its pose) until ``go`` is set; ``inside`` is set once it is there. Later calls draw."""
    import threading

    from rtp.plugins.pyrender._gbuffer import GBufferRenderer

    inside, go = threading.Event(), threading.Event()
    first = [True]

    def held(real: Any) -> Any:
        def call(self: Any, *args: Any, **kwargs: Any) -> Any:
            if first[0]:
                first[0] = False
                inside.set()
                assert go.wait(300)
            return real(self, *args, **kwargs)
        return call

    monkeypatch.setattr(GBufferRenderer, "render", held(GBufferRenderer.render))
    monkeypatch.setattr(GBufferRenderer, "draw", held(GBufferRenderer.draw))
    return inside, go


def test_a_second_threads_call_while_one_is_under_way_is_refused_and_close_waits(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The adapter moves the scene's camera (and swaps the renderer's programs) outside the GL context, so a second
    thread's call during a first one's went ahead: it moved the camera under the first one's draw (or drew from the
    first one's pose) and both returned wrong planes in silence, unless EGL happened to refuse the context; and a
    close() from another thread deleted the renderer under the call. Now the second call (``inputs``, ``render``,
    ``gbuffers``) is a PyrenderAdapterError naming it, the first call's planes are what it gives alone, and close()
    waits for it, then frees the context."""
    import threading

    from rtp.plugins.pyrender import Adapter, PyrenderAdapterError, SceneFrame

    pyrender = pyrender_or_skip()
    scene = _asymmetric_scene(pyrender)
    moved = np.eye(4)
    moved[:3, 3] = (0.2, 0.0, 0.0)
    adapter = Adapter(["reprojected.r", "seen", "albedo.g", "normal.y", "depth"], 64, 48)
    renderer = adapter.renderer
    colour, _ = adapter.render(scene, np.eye(4))
    frame = SceneFrame(scene, moved, np.eye(4), colour)
    want = adapter.inputs(frame)
    inside, go = _held_first_draw(monkeypatch)
    out: dict[str, Any] = {}

    def first() -> None:
        try:
            out["x"] = adapter.inputs(frame)
        except BaseException as exc:  # (handed back to the test's thread)
            out["error"] = exc

    t = threading.Thread(target=first, name="first")
    t.start()
    closer = threading.Thread(target=adapter.close, name="closer")
    try:
        assert inside.wait(300)  # (the first call holds the camera at its pose)
        for name, call in (("inputs", lambda: adapter.inputs(frame)), ("render", lambda: adapter.render(scene, np.eye(4))),
                           ("gbuffers", lambda: adapter.gbuffers(scene, np.eye(4)))):
            with pytest.raises(PyrenderAdapterError, match=rf"pyrender Adapter\.{name}: its pyrender renderer is in a "
                                                           r"call already \(another thread's\).*one thread at a time"):
                in_thread(call)
        closer.start()
        closer.join(0.5)
        assert closer.is_alive()  # (waiting for the call under way)
    finally:
        go.set()
        t.join(300)
        if closer.ident is not None:
            closer.join(300)
    assert "error" not in out, out.get("error")
    np.testing.assert_array_equal(out["x"], want)
    assert adapter.closed and renderer._platform is None  # (freed once the call returned)


def test_a_frame_sources_call_and_its_adapters_take_turns(monkeypatch: pytest.MonkeyPatch) -> None:
    """A pyrender frame source and its adapters share one renderer and one camera node: ``frame`` from a second
    thread while an adapter's ``inputs`` drew moved the node under it. Now it is a PyrenderAdapterError naming it,
    and the adapter's call under way in another thread is refused the same way while ``frame`` draws."""
    import threading

    from rtp.plugins.pyrender import Adapter, PyrenderAdapterError
    from rtp.scene import Camera, Material, Scene, box_mesh

    pyrender_or_skip()
    level = Scene("box", [box_mesh((-1, -1, -5), (1, 1, -3))], [Material("m")])
    cam, prev = Camera((0.0, 0.0, 0.0), yaw=5.0, fov_y=50.0), Camera((0.1, 0.0, 0.0), yaw=5.0, fov_y=50.0)
    with Adapter.frame_source(level, 32, 24) as source:
        adapter = source.adapter(["albedo.y", "seen"])
        frame = source.frame(cam, prev)
        want = adapter.inputs(frame)
        inside, go = _held_first_draw(monkeypatch)
        out: dict[str, Any] = {}
        t = threading.Thread(target=lambda: out.setdefault("x", adapter.inputs(frame)), name="first")
        t.start()
        try:
            assert inside.wait(300)
            with pytest.raises(PyrenderAdapterError, match=r"PyrenderFrameSource\.frame: its pyrender renderer is in "
                                                           r"a call already"):
                in_thread(lambda: source.frame(cam, prev))
        finally:
            go.set()
            t.join(300)
        np.testing.assert_array_equal(out["x"], want)
        np.testing.assert_array_equal(adapter.inputs(source.frame(cam, prev)), want)  # (one at a time: as before)


def test_an_engines_context_stays_current_across_the_adapters_calls(gl_context: Any) -> None:
    """pyrender's constructor and draws make its context current and leave it so: building a pyrender adapter
    while an engine's own (moderngl) context was current left pyrender's current in its place, and the engine's
    next GL calls went to the wrong context (here: "cannot map the buffer" reading one of its buffers back). The
    adapter's construction, calls and close now give back the context that was current before them."""
    from rtp.plugins.pyrender import Adapter, SceneFrame

    pyrender = pyrender_or_skip()
    scene = _asymmetric_scene(pyrender)
    buffer = make_current(gl_context).buffer(np.arange(4, dtype="f4").tobytes())
    try:
        adapter = Adapter(["albedo.r", "seen"], 32, 24)
        np.testing.assert_array_equal(np.frombuffer(buffer.read(), "f4"), np.arange(4))
        colour, _ = adapter.render(scene, np.eye(4))
        adapter.inputs(SceneFrame(scene, np.eye(4), np.eye(4), colour))
        np.testing.assert_array_equal(np.frombuffer(buffer.read(), "f4"), np.arange(4))
        adapter.close()
        np.testing.assert_array_equal(np.frombuffer(buffer.read(), "f4"), np.arange(4))
    finally:
        make_current(gl_context)
        buffer.release()


def test_a_borrowed_renderer_resized_after_is_refused() -> None:
    """The adapter has one size; a borrowed renderer whose viewport was changed after it was borrowed drew at its
    new size, and ``inputs`` failed with numpy's "could not broadcast input array" ValueError (``render`` returned
    an image of the new size). Both now say what changed."""
    from rtp.plugins.pyrender import Adapter, PyrenderAdapterError, SceneFrame
    from rtp.plugins.pyrender._gbuffer import _delete_renderer

    pyrender = pyrender_or_skip()
    scene = _asymmetric_scene(pyrender)
    user = pyrender.OffscreenRenderer(64, 48)
    try:
        with Adapter(["seen", "albedo.r", "normal.z"], 64, 48, renderer=user) as adapter:
            colour, _ = adapter.render(scene, np.eye(4))
            user.viewport_width = 32
            for call in (lambda: adapter.inputs(SceneFrame(scene, np.eye(4), np.eye(4), colour)),
                         lambda: adapter.render(scene, np.eye(4))):
                with pytest.raises(PyrenderAdapterError, match="renderer now draws 32x48, the adapter 64x48"):
                    call()
            user.viewport_width = 64  # its size back: the adapter draws again
            assert adapter.inputs(SceneFrame(scene, np.eye(4), np.eye(4), colour)).shape == (3, 48, 64)
    finally:
        _delete_renderer(user)


def test_python_optimize_is_a_typed_error_naming_it() -> None:
    """pyrender 0.1.45 makes its context inside ``assert`` statements, which ``python -O`` strips: that failed as
    "could not create a egl context (EGLError ...)" with the hint to apt-get install packages that were installed."""
    import subprocess
    import sys

    pyrender_or_skip()
    code = ("from rtp.plugins.pyrender import Adapter, PyrenderUnavailableError\n"
            "try:\n    Adapter(['depth'], 8, 8)\nexcept PyrenderUnavailableError as exc:\n    print(exc)\n")
    run = subprocess.run([sys.executable, "-O", "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and "python -O / PYTHONOPTIMIZE strips: run without -O" in run.stdout, \
        run.stdout[-2000:] + run.stderr[-2000:]
