"""sdk.input_planes: every channel from G-buffers in numpy arrays, as the reference renderer makes them
(docs/runtime.md "Input planes from G-buffers on the host")."""

from __future__ import annotations

import logging
from typing import Any, ClassVar

import numpy as np
import pytest

from rtp import conformance, sdk

from .test_adapter_contract import NumpyAdapter

W, H = 96, 64


@pytest.fixture(scope="module")
def rendered() -> list[tuple[Any, dict[str, Any]]]:
    """Frames of the procedural scene from the reference renderer, each with its G-buffers as input_planes
    takes them."""
    from rtp.capture import load_scene
    from rtp.capture.viewpoints import sample_viewpoints
    from rtp.plugins.moderngl import Renderer

    scene, _ = load_scene("procedural:0", None, None, None)
    out = []
    with Renderer(W, H) as r:
        r.load_scene(scene)
        for prev_cam, cam in sample_viewpoints(scene, 2, seed=3, profile="fast"):
            prev = r.render(prev_cam)
            cur = r.render(cam, prev)
            gbuffers = {"depth": cur.depth, "albedo": cur.albedo, "normal": cur.normal, "roughness": cur.roughness,
                        "metallic": cur.metallic, "specular": cur.specular, "shadow": cur.shadow,
                        "emissive": cur.emissive, "view": cam.view(), "projection": cam.projection(W / H),
                        "prev_colour": prev.colour["1x1"], "prev_depth": prev.depth,
                        "prev_view_projection": prev_cam.view_projection(W, H)}
            out.append((cur, gbuffers))
    return out


SAME_ARRAYS = [c for c in sdk.CHANNELS if not c.startswith(("reprojected.", "seen", "motion."))]


@pytest.mark.gl
def test_every_channel_is_the_renderers(rendered: list[tuple[Any, dict[str, Any]]]) -> None:
    """The planes of the G-buffers themselves are the renderer's to the bit; the reprojection (numpy here, its
    shader there) agrees on all but the pixels within rounding of an edge, and the motion vectors too."""
    channels = list(sdk.CHANNELS)
    for cur, g in rendered:
        x = sdk.input_planes(channels, **g)
        assert x.shape == (len(channels), H, W) and x.dtype == np.float32 and x.flags.c_contiguous
        planes = dict(zip(channels, x))
        for c in SAME_ARRAYS:
            np.testing.assert_array_equal(planes[c], cur.channel(c), err_msg=c)
        seen_same = planes["seen"] == cur.channel("seen")
        assert seen_same.mean() > 0.99 and 0.05 < planes["seen"].mean() < 1.0, seen_same.mean()
        both = seen_same & (planes["seen"] > 0)
        for c in ("reprojected.r", "reprojected.g", "reprojected.b", "reprojected.y"):
            assert (np.abs(planes[c] - cur.channel(c))[both] < 1e-3).mean() > 0.99, c
        for c in ("motion.x", "motion.y"):
            assert (np.abs(planes[c] - cur.channel(c)) < 0.05).mean() > 0.99, c
        assert np.abs(planes["motion.x"]).max() > 0.5  # the camera moved
        # the disocclusion test's tolerance goes to the reprojection
        strict, loose = (sdk.input_planes(["seen"], **g, tolerance=t)[0].sum() for t in (0.0, 1.0))
        assert strict < planes["seen"].sum() <= loose
        # the order is the caller's, the values the same
        back = sdk.input_planes(channels[::-1], **g)
        np.testing.assert_array_equal(back, x[::-1])


@pytest.mark.gl
def test_an_adapter_of_one_call_passes_the_kit_on_every_channel() -> None:
    """The whole of a CPU adapter is one call: every channel, every shipped model fed, the rates the reference
    renderer's G-buffers give (on all but the tiles whose reprojection rounds differently)."""

    class EveryPlane(NumpyAdapter):
        name: ClassVar[str] = "every-plane"
        supported_channels: ClassVar[frozenset[str]] = frozenset(sdk.CHANNELS)

    report = conformance.check_adapter(EveryPlane, size=(128, 80))
    assert report.ok, str(report)
    assert set(report.runs_models) == set(sdk.shipped_models())
    assert min(report.decisions.values()) > 0.97, report.decisions


def test_what_each_model_needs_read_back() -> None:
    assert sdk.gbuffers_needed(["reprojected.r", "seen", "albedo.r", "normal.z"]) == (
        "depth", "albedo", "normal", "view", "projection", "prev_colour", "prev_depth", "prev_view_projection")
    assert sdk.gbuffers_needed(["roughness", "depth.edge"]) == ("depth", "roughness")
    assert sdk.gbuffers_needed(["motion.x"]) == ("depth", "view", "projection", "prev_view_projection")
    for name in sdk.shipped_models():
        needed = sdk.gbuffers_needed(sdk.load(name).metadata.inputs)
        assert set(needed) <= set(sdk.GBUFFERS) and "prev_colour" in needed


def _frame(h: int = 20, w: int = 30) -> dict[str, Any]:
    rng = np.random.default_rng(0)
    proj = np.array([[1.0, 0, 0, 0], [0, 1.5, 0, 0], [0, 0, -1.02, -0.2], [0, 0, -1, 0]])
    depth = 2.0 + rng.random((h, w)).astype(np.float32)
    return {"depth": depth, "albedo": rng.random((h, w, 3)), "normal": rng.random((h, w, 3)) * 2 - 1,
            "view": np.eye(4), "projection": proj, "prev_colour": rng.random((h, w, 3)), "prev_depth": depth,
            "prev_view_projection": proj, "roughness": rng.random((h, w))}


@pytest.mark.parametrize(("change", "error", "match"), [
    ({"albedo": None}, sdk.ParameterError, r"albedo= is needed for albedo\.r \(\(H, W, 3\), base colour"),
    ({"depth": None}, sdk.ParameterError, r"depth= is needed for .*depth \(\(H, W\), linear view depth"),
    ({"prev_colour": None, "prev_depth": None}, sdk.ParameterError,
     r"prev_colour= is needed for reprojected\.r, seen .*; prev_depth= is needed"),
    ({"prev_colour": np.full((20, 30, 3), 2.5)}, sdk.ParameterError,
     r"prev_colour: expected values in \[0, 1\] .* got \[2\.5, 2\.5\]: tone-map it .*linear_to_srgb"),
    ({"albedo": np.zeros((3, 20, 30))}, sdk.InputShapeError, r"albedo: expected shape \(20, 30, 3\).*np\.moveaxis"),
    ({"albedo": np.zeros((20, 31, 3))}, sdk.InputShapeError, r"albedo: expected shape \(20, 30, 3\)"),
    ({"depth": np.zeros((20, 30, 2))}, sdk.InputShapeError, r"depth: expected shape \('H', 'W'\)"),  # ((H, W, 1): taken)
    ({"depth": -np.ones((20, 30))}, sdk.ParameterError, r"depth: expected values in \[0, inf\]"),
    # normals past [-1, 1] (an encoded texture copied to floats undivided, vectors longer than 1) were taken as
    # they were, normal.* planes outside their channel's range, although the docs refuse values out of range
    ({"normal": np.full((20, 30, 3), 127.0)}, sdk.ParameterError,
     r"normal: expected values in \[-1, 1\] .* got \[127, 127\].*n / 255 \* 2 - 1"),
    ({"normal": np.dstack([np.zeros((20, 30, 2)), np.full((20, 30), -1.5)])}, sdk.ParameterError,
     r"normal: expected values in \[-1, 1\] .* got \[-1\.5, 0\].*normalise"),
    ({"view": np.eye(3)}, sdk.InputShapeError, r"view: expected shape \(4, 4\)"),
    ({"roughness": np.full((20, 30), np.nan)}, sdk.NonFiniteInputError, "roughness: holds NaN"),
    ({"albedo": np.full((20, 30, 3), "a")}, sdk.InputDtypeError, "albedo: expected an array of numbers"),
])
def test_bad_gbuffers_are_named(change: dict[str, Any], error: type, match: str) -> None:
    g = {**_frame(), **change}
    with pytest.raises(error, match=match):
        sdk.input_planes(["reprojected.r", "seen", "albedo.r", "normal.z", "roughness", "depth"], **g)


def test_bad_channels_are_named() -> None:
    g = _frame()
    with pytest.raises(sdk.ParameterError, match=r"unknown channel 'albedo\.red' \(did you mean albedo\.r"):
        sdk.input_planes(["albedo.red"], **g)
    with pytest.raises(sdk.ParameterError, match="expected a sequence of channel names"):
        sdk.input_planes("albedo.r", **g)
    with pytest.raises(sdk.ParameterError, match="at least one"):
        sdk.input_planes([], **g)


def test_gbuffers_no_channel_reads_are_not_looked_at() -> None:
    """A model of the material planes only needs no previous frame, and a bad one given is ignored."""
    g = {**_frame(), "prev_colour": "not read"}
    x = sdk.input_planes(["roughness", "albedo.y", "depth.edge"], **g)
    assert x.shape == (3, 20, 30)
    np.testing.assert_array_equal(x[1], sdk.luma(g["albedo"]))
    np.testing.assert_array_equal(x[2], sdk.depth_edges(g["depth"]))



def _hardware_depth(depth: np.ndarray, projection: np.ndarray, kind: str) -> np.ndarray:
    """What an engine's float32 depth buffer holds for linear ``depth`` drawn with ``projection`` (OpenGL's):
    the window depth (1 on background), or, reversed-Z, 1 minus it (0 on background)."""
    z = -depth.astype(np.float64)
    clip_z, clip_w = projection[2, 2] * z + projection[2, 3], projection[3, 2] * z + projection[3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):  # (the background's w is 0)
        window = np.where(depth > 0, (clip_z / clip_w + 1.0) / 2.0, 1.0)
    return (1.0 - window if kind == "reversed" else window).astype(np.float32)


@pytest.mark.gl
@pytest.mark.parametrize("kind", ["window", "reversed"])
def test_an_engines_own_conventions_give_the_same_planes(rendered: list[tuple[Any, dict[str, Any]]],
                                                         kind: str) -> None:
    """A linear albedo, world-space normals, junk on the background and a hardware depth
    buffer (standard or reversed-Z), with the options that say so (the moderngl adapter's): the same planes,
    within the precision of a float32 depth buffer."""
    channels = list(sdk.CHANNELS)
    for _, g in rendered:
        want = dict(zip(channels, sdk.input_planes(channels, **g)))
        sky = g["depth"] <= 0
        rotation = g["view"][:3, :3]
        albedo = sdk.srgb_to_linear(g["albedo"]).astype(np.float32)
        albedo[sky] = 0.7  # the engine's clear colour, not read
        normal = g["normal"] @ rotation  # world space
        normal[sky] = 0.3

        engine = {**g, "albedo": albedo, "normal": normal, "depth": _hardware_depth(g["depth"], g["projection"], kind),
                  "prev_depth": _hardware_depth(g["prev_depth"], g["projection"], kind)}
        got = dict(zip(channels, sdk.input_planes(channels, **engine, albedo_linear=True, normal_space="world",
                                                   depth_kind=kind)))
        for c in ("albedo.r", "albedo.g", "albedo.b", "albedo.y", "normal.x", "normal.y", "normal.z"):
            np.testing.assert_allclose(got[c], want[c], atol=2e-5, err_msg=c)
        np.testing.assert_allclose(got["depth"], want["depth"], rtol=2e-3, err_msg="depth")
        assert (got["seen"] == want["seen"]).mean() > 0.99
        assert (np.abs(got["depth.edge"] - want["depth.edge"]) < 0.02).mean() > 0.99


def test_the_options_are_checked_and_named() -> None:
    g = _frame()
    chans = ["normal.z", "seen"]
    with pytest.raises(sdk.ParameterError, match="normal_space: expected one of view, world"):
        sdk.input_planes(chans, **g, normal_space="object")
    with pytest.raises(sdk.ParameterError, match="depth_kind: expected one of linear, window, reversed"):
        sdk.input_planes(chans, **g, depth_kind="reverse")
    with pytest.raises(sdk.ParameterError, match="normal_space: expected one of view, world"):
        sdk.input_planes(chans, **g, normal_space=np.zeros(0))  # type: ignore[arg-type]  (numpy's ValueError before)
    with pytest.raises(sdk.ParameterError, match=r"depth= is needed for every channel \(the frame's size"):
        sdk.input_planes(["albedo.y"], **{**g, "depth": None})  # (a KeyError before)
    with pytest.raises(sdk.ParameterError, match="albedo_linear: expected True or False"):
        sdk.input_planes(chans, **g, albedo_linear="yes")
    with pytest.raises(sdk.ParameterError, match=r"depth: expected values in \[0, 1\]"):
        sdk.input_planes(chans, **g, depth_kind="window")  # linear depth of 2-3 m given as window depth
    with pytest.raises(sdk.ParameterError, match=r"view= is needed for normal_space='world'"):
        sdk.input_planes(["normal.z"], **{**g, "view": None}, normal_space="world")
    with pytest.raises(sdk.ParameterError, match=r"projection= is needed for depth_kind='window'"):
        sdk.input_planes(["depth"], depth=np.full((4, 4), 0.5), depth_kind="window")
    # a world-space normal seen by a camera turned 90 degrees about y: view-space x is world z
    turn = np.array([[0.0, 0, -1, 0], [0, 1, 0, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
    n = np.zeros((20, 30, 3))
    n[..., 2] = 1.0
    x = sdk.input_planes(["normal.x", "normal.z"], **{**g, "normal": n, "view": turn}, normal_space="world")
    np.testing.assert_allclose(x[0], -1.0) and np.testing.assert_allclose(x[1], 0.0, atol=1e-7)


def test_unorm_textures_read_back_as_integers() -> None:
    """An RGBA8 albedo or previous frame and an R16 roughness read back as integers are the same planes as their
    floats; an 8-bit normal texture is refused with how to decode it."""
    g = _frame()
    chans = ["albedo.r", "albedo.y", "reprojected.g", "seen", "roughness"]
    as_bytes = {"albedo": np.round(g["albedo"] * 255).astype(np.uint8),
                "prev_colour": np.round(g["prev_colour"] * 255).astype(np.uint8),
                "roughness": np.round(g["roughness"] * 65535).astype(np.uint16)}
    floats = {"albedo": as_bytes["albedo"] / 255.0, "prev_colour": as_bytes["prev_colour"] / 255.0,
              "roughness": as_bytes["roughness"] / 65535.0}
    np.testing.assert_allclose(sdk.input_planes(chans, **{**g, **as_bytes}), sdk.input_planes(chans, **{**g, **floats}),
                               atol=1e-6)
    with pytest.raises(sdk.InputDtypeError, match=r"normal: .*got dtype uint8 .*n / 255 \* 2 - 1"):
        sdk.input_planes(["normal.z"], **{**g, "normal": np.full((20, 30, 3), 128, np.uint8)})


@pytest.mark.gl
def test_fetch_from_motion_is_the_reprojections_nearest_texel(rendered: list[tuple[Any, dict[str, Any]]]) -> None:
    """PredictionReuse's fetch from the motion planes: where a geometry pixel was last frame, as the reprojection's
    nearest texel (which the seen mask reads), on all but the pixels within float32 rounding of a texel edge."""
    for _, g in rendered:
        mx, my, seen = sdk.input_planes(["motion.x", "motion.y", "seen"], **g)
        rows, cols = sdk.fetch_from_motion(mx, my)
        assert rows.dtype == cols.dtype == np.intp and rows.shape == (H, W)
        qx, qy, _ = sdk.reproject_positions(g["depth"], g["view"], g["projection"], g["prev_view_projection"])
        on = (seen > 0) & (g["depth"] > 0)  # (the motion of the background is 0: PredictionReuse's background)
        same = (cols == np.floor(qx)) & (rows == H - 1 - np.floor(qy))
        assert same[on].mean() > 0.995, same[on].mean()


def test_fetch_from_motion_by_hand() -> None:
    still = np.zeros((3, 4))
    rows, cols = sdk.fetch_from_motion(still, still)
    np.testing.assert_array_equal(rows, np.indices((3, 4))[0])
    np.testing.assert_array_equal(cols, np.indices((3, 4))[1])
    rows, cols = sdk.fetch_from_motion(np.full((3, 4), 1.0), np.full((3, 4), -0.6))  # from the right, from above
    np.testing.assert_array_equal(cols, [[1, 2, 3, 3]] * 3)  # (kept inside the frame)
    np.testing.assert_array_equal(rows[:, 0], [0, 0, 1])
    with pytest.raises(sdk.InputShapeError, match="one shape"):
        sdk.fetch_from_motion(still, np.zeros((3, 5)))
    with pytest.raises(sdk.NonFiniteInputError, match="motion_y"):
        sdk.fetch_from_motion(still, np.full((3, 4), np.nan))
    with pytest.raises(sdk.InputDtypeError, match="motion_x"):
        sdk.fetch_from_motion(np.full((3, 4), "a"), still)
    with pytest.raises(sdk.InputShapeError, match=r"motion_x: expected a non-empty \(H, W\)"):
        sdk.fetch_from_motion(np.zeros((2, 3, 4)), still)


def _infinite_reversed_z(near: float) -> np.ndarray:
    """The OpenGL projection of an infinite far plane (90 degrees, 3:2) whose reversed-Z depth is near / z."""
    return np.array([[1.0, 0, 0, 0], [0, 1.5, 0, 0], [0, 0, -1, -2 * near], [0, 0, -1, 0]])


def test_reversed_z_with_an_infinite_far_plane_keeps_its_precision_to_the_horizon() -> None:
    """A reversed-Z buffer of an infinite far plane holds near / z: linear depth comes back to float32 precision
    from 10 cm to 100 km (its precision is why engines use it), and 0 (the far plane) is background."""
    near = 0.1
    z = np.geomspace(0.1, 1e5, 600).reshape(20, 30)
    depth = (near / z).astype(np.float32)
    depth[0, :5] = 0.0  # sky
    x = sdk.input_planes(["depth"], depth=depth, projection=_infinite_reversed_z(near), depth_kind="reversed")[0]
    want = np.divide(near, depth.astype(np.float64), out=np.zeros(depth.shape), where=depth > 0)
    np.testing.assert_allclose(x, want, rtol=1e-6)
    assert (x[0, :5] == 0).all() and (x[0, 5:] > 0).all()


def test_a_d16_depth_buffer_read_back_as_uint16() -> None:
    """A D16_UNORM buffer read back is its integers over 65535, for both hardware kinds; linear depth in uint16 is
    a number of scene units, as any integer."""
    near = 0.5
    raw = np.array([[0, 1000, 30000, 65535]] * 4, np.uint16)
    p = _infinite_reversed_z(near)
    x = sdk.input_planes(["depth"], depth=raw, projection=p, depth_kind="reversed")[0]
    np.testing.assert_allclose(x[0], [0.0, near * 65535 / 1000, near * 65535 / 30000, near], rtol=1e-6)
    w = sdk.input_planes(["depth"], depth=65535 - raw, projection=p, depth_kind="window")[0]
    np.testing.assert_allclose(w, x, rtol=1e-4)
    np.testing.assert_array_equal(sdk.input_planes(["depth"], depth=raw)[0], raw.astype(np.float32))


def test_a_depth_buffer_of_the_other_kind_is_named_in_a_warning(caplog: pytest.LogCaptureFixture,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A reversed-Z buffer given as ``window`` puts the sky at the near plane and every plane made of depth goes
    wrong without an error: where no pixel holds the background's value and some hold the near plane's, a
    warning says which kind it looks like, once per kind."""
    from rtp.sdk import _planes

    monkeypatch.setattr(_planes, "_warned_kinds", set())
    p = _infinite_reversed_z(0.1)
    reversed_z = np.full((20, 30), 0.01, np.float32)
    reversed_z[:5] = 0.0  # sky
    with caplog.at_level(logging.WARNING, logger="rtp.sdk"):
        sdk.input_planes(["depth"], depth=reversed_z, projection=p, depth_kind="window")
        sdk.input_planes(["depth"], depth=reversed_z, projection=p, depth_kind="window")
    assert [r.getMessage() for r in caplog.records] == [
        "depth: depth_kind='window', but 150 pixels hold 0 (the near plane) and none 1 (background): a reversed-Z "
        "depth buffer? (depth_kind='reversed'); warned once"]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtp.sdk"):
        sdk.input_planes(["depth"], depth=1.0 - reversed_z, projection=p, depth_kind="reversed")
        sdk.input_planes(["depth"], depth=reversed_z, projection=p, depth_kind="reversed")  # right: no warning
        sdk.input_planes(["depth"], depth=1.0 - reversed_z, projection=p, depth_kind="window")  # right: none
    assert [r.getMessage() for r in caplog.records] == [
        "depth: depth_kind='reversed', but 150 pixels hold 1 (the near plane) and none 0 (background): a standard "
        "depth buffer? (depth_kind='window'); warned once"]


def test_threads_making_planes_warn_of_a_depth_kind_once(caplog: pytest.LogCaptureFixture,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Two views' threads making planes of the same wrong-kind depth buffer at once: one warning, not one from each
    thread that tested the kinds warned of before the other added it (forced interleaving)."""
    from concurrent.futures import ThreadPoolExecutor

    from rtp.sdk import _planes

    from .test_predictor import Meeting

    meeting = Meeting()
    monkeypatch.setattr(_planes, "_warned_kinds", meeting.add_blocks())
    monkeypatch.setattr(_planes, "_warned_lock", meeting.gate(), raising=False)
    p = _infinite_reversed_z(0.1)
    reversed_z = np.full((20, 30), 0.01, np.float32)
    reversed_z[:5] = 0.0  # sky
    caplog.set_level(logging.WARNING, logger="rtp.sdk")
    with ThreadPoolExecutor(2) as pool:
        for done in [pool.submit(sdk.input_planes, ["depth"], depth=reversed_z, projection=p, depth_kind="window")
                     for _ in range(2)]:
            done.result(timeout=30)
    assert len(caplog.records) == 1 and "a reversed-Z depth buffer?" in caplog.text


# -- matrices from Direct3D, Vulkan and Metal ------------------------------------------------------------------

def _xm_look_at_lh(eye: np.ndarray, at: np.ndarray, up: np.ndarray) -> np.ndarray:
    """DirectXMath's XMMatrixLookAtLH: a left-handed view matrix (+z ahead) for row vectors."""
    z = (at - eye) / np.linalg.norm(at - eye)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = x, y, z
    m[3, :3] = -x @ eye, -y @ eye, -z @ eye
    return m


def _xm_perspective_fov_lh(fov_y: float, aspect: float, near: float, far: float) -> np.ndarray:
    """DirectXMath's XMMatrixPerspectiveFovLH (clip depth in [0, 1]) for row vectors; reversed-Z with near and far
    swapped, as engines make it."""
    ys = 1.0 / np.tan(fov_y / 2)
    r = far / (far - near)
    return np.array([[ys / aspect, 0, 0, 0], [0, ys, 0, 0], [0, 0, r, 1], [0, 0, -r * near, 0]])


def _d3d_frame(reversed_z: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A left-handed, row-vector camera pair of a Direct3D engine (reversed-Z or not): view, projection and the
    previous view-projection, and world points in front of it."""
    near, far = (100.0, 0.1) if reversed_z else (0.1, 100.0)
    proj = _xm_perspective_fov_lh(1.1, 16 / 9, near, far)
    view = _xm_look_at_lh(np.array([1.0, 1.7, -3.0]), np.array([0.5, 1.2, 2.0]), np.array([0.0, 1.0, 0.0]))
    prev = _xm_look_at_lh(np.array([1.1, 1.7, -3.2]), np.array([0.7, 1.2, 2.0]), np.array([0.0, 1.0, 0.0]))
    points = np.random.default_rng(3).uniform([-3, 0, 2], [3, 3, 40], (200, 3))
    return view, proj, prev @ proj, points


def _rtp_matrices(view: np.ndarray, proj: np.ndarray, prev_vp: np.ndarray, reversed_z: bool
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """docs/runtime.md "Matrices from Direct3D, Vulkan and Metal", for a left-handed row-vector engine."""
    s = np.diag([1.0, 1.0, -1.0, 1.0])
    to_gl = np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, -2, 1] if reversed_z else [0, 0, 2, -1], [0, 0, 0, 1]])
    return s @ view.T, to_gl @ proj.T @ s, to_gl @ prev_vp.T


@pytest.mark.parametrize("reversed_z", [False, True])
def test_direct3d_matrices_converted_as_the_docs_say_put_every_point_where_direct3d_does(reversed_z: bool) -> None:
    """A Direct3D engine's camera (left-handed, row vectors, clip depth in [0, 1], reversed-Z or not), converted
    by the docs' recipe: the same pixel for every point, and a window depth whose reversed-Z is the engine's
    buffer, in this frame and through the previous view-projection."""
    view, proj, prev_vp, points = _d3d_frame(reversed_z)
    gl_view, gl_proj, gl_prev = _rtp_matrices(view, proj, prev_vp, reversed_z)
    assert sdk.check_projection(gl_proj) is not None
    h4 = np.c_[points, np.ones(len(points))]
    for d3d, gl in ((h4 @ view @ proj, (gl_proj @ gl_view @ h4.T).T), (h4 @ prev_vp, (gl_prev @ h4.T).T)):
        d_ndc, g_ndc = d3d[:, :3] / d3d[:, 3:], gl[:, :3] / gl[:, 3:]
        assert (d3d[:, 3] > 0).all() and (gl[:, 3] > 0).all()  # in front of both
        np.testing.assert_allclose(g_ndc[:, :2], d_ndc[:, :2], atol=1e-12)  # the same pixels
        window = (g_ndc[:, 2] + 1) / 2
        np.testing.assert_allclose(1 - window if reversed_z else window, d_ndc[:, 2], atol=1e-12)


def test_another_apis_projection_is_named_with_its_conversion() -> None:
    """A row-vector matrix, a left-handed one, a reversed-Z one and Vulkan's y-down one are each a typed error
    naming the convention and pointing at the conversion, in check_projection, input_planes and reproject."""
    view, proj, prev_vp, _ = _d3d_frame(reversed_z=True)
    gl_view, gl_proj, gl_prev = _rtp_matrices(view, proj, prev_vp, reversed_z=True)
    s = np.diag([1.0, 1.0, -1.0, 1.0])
    cases = {
        "row vectors": proj,                                      # not transposed
        "left-handed": proj.T,                                    # transposed, not flipped
        "reversed-Z": proj.T @ s,                                 # flipped, its depth not converted
        "Vulkan": np.diag([1.0, -1.0, 1.0, 1.0]) @ gl_proj,       # clip y down
    }
    depth = np.full((20, 30), 0.5, np.float32)
    for what, m in cases.items():
        for call in (lambda m=m: sdk.check_projection(m),
                     lambda m=m: sdk.input_planes(["depth"], depth=depth, projection=m, depth_kind="reversed"),
                     lambda m=m: sdk.reproject(np.zeros((20, 30, 3)), depth, depth, gl_view, m, gl_prev)):
            with pytest.raises(sdk.ParameterError, match=what) as err:
                call()
            assert 'docs/runtime.md "Matrices from Direct3D, Vulkan and Metal"' in str(err.value)
    # OpenGL's own, perspective (finite or infinite far plane) or orthographic, pass unchanged
    for m in (gl_proj, _infinite_reversed_z(0.1), np.diag([0.5, 0.8, -0.1, 1.0])):
        np.testing.assert_array_equal(sdk.check_projection(m), m)


def test_a_depth_buffer_is_linearised_only_through_an_opengl_orthographic_projection() -> None:
    """A hardware depth buffer read through an orthographic projection in another convention (left-handed or
    reversed-Z, as Direct3D builds them; or for row vectors, not transposed) is a typed error naming the matrix, as a
    perspective's is, also where no plane reprojects: the depth came out wrong (a left-handed one's 40 - 2 d for d),
    or negative and every pixel background, without one. OpenGL's own gives the depth back."""
    near, far = 0.1, 40.0
    gl = np.diag([0.125, 0.2, -2 / (far - near), 1.0])
    gl[2, 3] = -(far + near) / (far - near)
    d = np.linspace(1.0, 30.0, 600).reshape(20, 30)
    window = ((d - near) / (far - near)).astype(np.float32)  # an orthographic window depth is affine in d
    np.testing.assert_allclose(sdk.input_planes(["depth"], depth=window, projection=gl, depth_kind="window")[0], d,
                               rtol=1e-5)
    left = np.diag([0.125, 0.2, 1 / (far - near), 1.0])  # XMMatrixOrthographicLH, as column vectors
    left[2, 3] = -near / (far - near)
    reversed_z = np.diag([0.125, 0.2, 1 / (far - near), 1.0])  # right-handed, reversed-Z: (f - d) / (f - n)
    reversed_z[2, 3] = far / (far - near)
    for kind, m, match in (("window", left, "does not rise away from the camera"),
                           ("reversed", reversed_z, "does not rise away from the camera"),
                           ("window", gl.T, r"neither a perspective's .* a matrix for row vectors")):
        raw = window if kind == "window" else 1 - window
        with pytest.raises(sdk.ParameterError, match=match):
            sdk.input_planes(["depth", "depth.edge"], depth=raw, projection=m, depth_kind=kind)
        with pytest.raises(sdk.ParameterError, match=match):
            sdk.check_gbuffers(depth=raw, projection=m, depth_kind=kind)
    # the previous frame's depth through its own projection, where given
    with pytest.raises(sdk.ParameterError, match="prev_projection: an orthographic projection whose clip depth"):
        sdk.input_planes(["seen"], depth=window, prev_depth=window, prev_colour=np.zeros((20, 30, 3)),
                         view=np.eye(4), projection=gl, prev_view_projection=gl, prev_projection=left,
                         depth_kind="window")


def test_a_depth_buffer_of_points_behind_an_orthographic_camera_is_named() -> None:
    """An orthographic projection whose near plane is behind the camera (glOrtho's near of -1) draws points of
    negative view depth, which rtp's depth (>= 0, 0 on background) cannot hold: a typed error naming the projection,
    not negative depth values taken as background. A near plane at 0 gives its own points 0 (background), no error."""
    def ortho(near: float, far: float) -> np.ndarray:
        m = np.diag([0.125, 0.2, -2 / (far - near), 1.0])
        m[2, 3] = -(far + near) / (far - near)
        return m

    d = np.linspace(-0.5, 8.0, 600).reshape(20, 30)  # its first rows behind the camera
    window = ((d + 1.0) / 11.0).astype(np.float32)  # near -1, far 10
    for kind, raw in (("window", window), ("reversed", 1 - window)):
        with pytest.raises(sdk.ParameterError, match=r"projection: .*negative view depth .* near plane is behind"):
            sdk.input_planes(["depth"], depth=raw, projection=ortho(-1.0, 10.0), depth_kind=kind)
    ahead = np.where(d >= 0.0, window, 1.0).astype(np.float32)  # the same camera, nothing behind it: its depth back
    got = sdk.input_planes(["depth"], depth=ahead, projection=ortho(-1.0, 10.0), depth_kind="window")[0]
    np.testing.assert_allclose(got, np.where(d >= 0.0, d, 0.0), atol=2e-6)
    assert got.min() >= 0.0
    at_zero = np.linspace(0.0, 0.5, 600).reshape(20, 30).astype(np.float32)  # near 0, far 7: the first pixel at 0
    got = sdk.input_planes(["depth"], depth=at_zero, projection=ortho(0.0, 7.0), depth_kind="window")[0]
    assert got.min() >= 0.0 and got[0, 0] == 0.0
    np.testing.assert_allclose(got, at_zero * 7.0, atol=2e-6)


def test_textures_read_back_as_rgba_or_with_one_channel_kept() -> None:
    """An engine reads RGBA textures back (RGBA8 albedo, RGBA16F normals): the alpha is not read. A single-channel
    G-buffer kept as (H, W, 1) is its (H, W). A matrix as 16 numbers in a row is named with how to shape it."""
    g = _frame()
    chans = ["albedo.r", "albedo.y", "normal.z", "roughness", "depth", "seen"]
    want = sdk.input_planes(chans, **g)
    rng = np.random.default_rng(1)
    albedo8 = np.round(g["albedo"] * 255).astype(np.uint8)
    rgba = {**g, "albedo": np.dstack([albedo8, rng.integers(0, 256, albedo8.shape[:2], np.uint8)]),
            "normal": np.dstack([g["normal"], rng.random(g["depth"].shape)]),
            "prev_colour": np.dstack([g["prev_colour"], np.full(g["depth"].shape, 7.0)]),  # (an alpha past 1: not read)
            "roughness": g["roughness"][..., None], "depth": g["depth"][..., None]}
    got = sdk.input_planes(chans, **rgba)
    np.testing.assert_allclose(got[:2], want[:2], atol=1 / 255)  # (the albedo's 8 bits)
    np.testing.assert_array_equal(got[2:], want[2:])
    with pytest.raises(sdk.InputShapeError, match=r"16 numbers in a row: np.reshape\(m, \(4, 4\)\)"):
        sdk.input_planes(chans, **{**g, "view": g["view"].ravel()})
    with pytest.raises(sdk.InputShapeError, match=r"albedo: expected shape \(20, 30, 3\)"):
        sdk.input_planes(chans, **{**g, "albedo": np.dstack([g["albedo"]] * 2)})  # 6 channels: not a texture's


# -- the engine's motion vectors: objects that move --------------------------------------------------------------

def _moving_square(shift: int = 4) -> tuple[dict[str, Any], np.ndarray]:
    """A red square 3 m away moving ``shift`` pixels right over a wall 5 m away, the camera still: the G-buffers
    (current frame) and the engine's motion vectors (-shift on the square)."""
    h, w = 24, 32
    proj = np.array([[1.0, 0, 0, 0], [0, 1.5, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]])

    def frame(c0: int) -> tuple[np.ndarray, np.ndarray]:
        depth = np.full((h, w), 5.0, np.float32)
        depth[8:16, c0:c0 + 6] = 3.0
        colour = np.full((h, w, 3), 0.2, np.float32)
        colour[8:16, c0:c0 + 6] = (0.9, 0.1, 0.1)
        return depth, colour

    prev_depth, prev_colour = frame(10)
    depth, colour = frame(10 + shift)
    motion = np.zeros((h, w, 2), np.float32)
    motion[8:16, 10 + shift:16 + shift, 0] = -shift
    g = {"depth": depth, "view": np.eye(4), "projection": proj, "prev_colour": prev_colour, "prev_depth": prev_depth,
         "prev_view_projection": proj, "colour": colour}
    return g, motion


def test_the_engines_motion_vectors_reproject_objects_that_move() -> None:
    """The camera's move alone fetches a moving square from where it is now: the wall behind it (unseen) or its
    own trailing half. With the engine's motion vectors every square pixel is fetched from the square, seen, and
    the wall it uncovered is still unseen (disoccluded); motion.x/y are the engine's."""
    g, motion = _moving_square()
    colour = g.pop("colour")
    chans = ["reprojected.r", "reprojected.g", "seen", "motion.x", "motion.y"]
    static = sdk.input_planes(chans, **g)
    moving = sdk.input_planes(chans, **g, motion=motion)
    square, uncovered = (slice(8, 16), slice(14, 20)), (slice(8, 16), slice(10, 14))
    assert static[2][square].mean() < 0.5  # the camera alone: most of the square unseen
    assert (moving[2][square] == 1).all()
    np.testing.assert_array_equal(moving[0][square], colour[square][..., 0])
    np.testing.assert_array_equal(moving[1][square], colour[square][..., 1])
    assert (moving[2][uncovered] == 0).all() and (static[2][uncovered] == 0).all()
    np.testing.assert_array_equal(moving[3], motion[..., 0])
    np.testing.assert_array_equal(moving[4], motion[..., 1])
    rep, seen = sdk.reproject(g["prev_colour"], g["prev_depth"], g["depth"], g["view"], g["projection"],
                              g["prev_view_projection"], motion=motion)
    np.testing.assert_array_equal(seen, moving[2])
    with pytest.raises(sdk.InputShapeError, match=r"motion must be \(H, W, 2\)"):
        sdk.reproject(g["prev_colour"], g["prev_depth"], g["depth"], g["view"], g["projection"],
                      g["prev_view_projection"], motion=motion[..., 0])


@pytest.mark.gl
def test_motion_vectors_of_the_camera_alone_give_the_same_planes(rendered: list[tuple[Any, dict[str, Any]]]) -> None:
    """On the reference renderer's frames (a static scene) its own motion vectors, given as the engine's, give
    the planes the camera's move gives, but for pixels within rounding of a texel's edge."""
    channels = ["reprojected.r", "reprojected.y", "seen", "reprojected.y.blocks", "motion.x", "motion.y"]
    for frame, g in rendered:
        want = sdk.input_planes(channels, **g)
        got = sdk.input_planes(channels, **g, motion=frame.motion)
        assert (got[2] != want[2]).mean() < 0.001  # (measured: 0 and 0)
        assert (np.abs(got[0] - want[0]) > 1e-6).mean() < 0.001  # (6.5e-5 and 0)
        np.testing.assert_allclose(got[4:], want[4:], atol=5e-4)  # (float32 motion: 1e-4 at most)


# -- check_gbuffers: convention mistakes named ---------------------------------------------------------------------

@pytest.mark.gl
def test_convention_mistakes_are_named_and_a_right_frame_has_none(rendered: list[tuple[Any, dict[str, Any]]]) -> None:
    """Each mistake an engine makes wiring its G-buffers up gives planes without an error; check_gbuffers names
    it (and the frames as rendered have no warning)."""
    (_, g), (_, other) = rendered
    for _, frame in rendered:
        assert sdk.check_gbuffers(**frame) == []
        assert sdk.check_gbuffers(**frame, albedo_linear=False, tolerance=0.02) == []  # input_planes' keywords
    view, proj = g["view"], g["projection"]
    window, prev_window = (_hardware_depth(g[k], proj, "window") for k in ("depth", "prev_depth"))
    mistakes = {
        "face away from the camera: world-space normals given as view-space": {"normal": g["normal"] @ view[:3, :3]},
        "not unit vectors with no component below 0: an encoded texture": {"normal": g["normal"] * 0.5 + 0.5},
        "view: its last row is": {"view": view.T},
        "view: a reflection (determinant -1): a left-handed view space": {"view": np.diag([1.0, 1, -1, 1]) @ view},
        "view: its rotation is not orthonormal (a scale?)": {"view": np.diag([0.01, 0.01, 0.01, 1]) @ view},  # cm
        "prev_view_projection: its last row": {"prev_view_projection": g["prev_view_projection"].T},
        "a depth buffer (depth_kind='window'": {"depth": window},
        "seen: only": {k: other[k] for k in ("prev_colour", "prev_depth", "prev_view_projection")},  # another frame's
    }
    for text, change in mistakes.items():
        warnings = sdk.check_gbuffers(**{**g, **change})
        assert any(text in w for w in warnings), (text, warnings)
    # the right options for the engine's conventions: no warning
    assert sdk.check_gbuffers(**{**g, "normal": g["normal"] @ view[:3, :3]}, normal_space="world") == []
    assert sdk.check_gbuffers(**{**g, "depth": window, "prev_depth": prev_window}, depth_kind="window") == []
    with pytest.raises(sdk.ParameterError, match="normals: not a G-buffer"):
        sdk.check_gbuffers(**g, normals=g["normal"])


@pytest.mark.gl
@pytest.mark.parametrize("prev_projection", [False, True])
def test_a_zero_to_one_depth_projection_with_a_window_depth_is_named_with_its_conversion(
        rendered: list[tuple[Any, dict[str, Any]]], prev_projection: bool) -> None:
    """A Direct3D-style projection (clip depth in [0, 1]) with depth_kind='window' passes check_projection (it is
    an OpenGL one of other planes) and linearises the depth buffer wrong: the warning names it and its conversion
    rather than only a share of surfaces seen; another frame's buffers are not taken for it."""
    (_, g), (_, other) = rendered
    window, prev_window = (_hardware_depth(g[k], g["projection"], "window") for k in ("depth", "prev_depth"))
    to_d3d = np.linalg.inv(np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, -1], [0, 0, 0, 1]]))
    d3d = {**g, "depth": window, "prev_depth": prev_window, "projection": to_d3d @ g["projection"],
           "prev_view_projection": to_d3d @ g["prev_view_projection"]}
    if prev_projection:
        d3d["prev_projection"] = to_d3d @ g["projection"]
    (warning,) = sdk.check_gbuffers(**d3d, depth_kind="window")
    assert warning.startswith("seen: only ") and "projection looks like a [0, 1]-depth matrix (Direct3D's, Vulkan's, " \
        "Metal's), which depth_kind='window' linearises as OpenGL's [-1, 1]" in warning, warning
    assert "pass D @ projection and D @ prev_view_projection" in warning
    assert ("and D @ prev_projection" in warning) == prev_projection
    assert 'D = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, -1], [0, 0, 0, 1]]' in warning
    assert 'docs/runtime.md "Matrices from Direct3D, Vulkan and Metal"' in warning
    # converted as it says: no warning; another frame's previous buffers: the plain warning, no [0, 1] guess
    d = np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, -1], [0, 0, 0, 1]])
    fixed = {k: d @ v if k in ("projection", "prev_view_projection", "prev_projection") else v for k, v in d3d.items()}
    assert sdk.check_gbuffers(**fixed, depth_kind="window") == []
    cut = {**g, "depth": window, **{k: other[k] for k in ("prev_colour", "prev_view_projection")},
           "prev_depth": _hardware_depth(other["prev_depth"], g["projection"], "window")}
    (warning,) = sdk.check_gbuffers(**cut, depth_kind="window")
    assert warning.startswith("seen: only ") and "[0, 1]-depth" not in warning, warning


def _close_wall(h: int = 36, w: int = 64) -> dict[str, Any]:
    """Two frames of a slanted wall filling the view about 0.35 m in front of a camera that moves 5 cm towards it and turns
    a degree (near plane 0.05, far 200): linear depth from rays cast at each pixel centre, no background."""
    from rtp.scene import Camera

    normal = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
    point = np.array([0.0, 1.5, -0.35])

    def depth(camera: Camera) -> np.ndarray:
        p = camera.projection(w / h)
        xs = ((np.arange(w) + 0.5) / w * 2 - 1)[None, :].repeat(h, 0)
        ys = (1 - (np.arange(h) + 0.5) / h * 2)[:, None].repeat(w, 1)
        rays = np.stack([xs / p[0, 0], ys / p[1, 1], -np.ones_like(xs)], -1) @ camera.rotation().T  # (view z -1)
        return (((point - np.asarray(camera.position)) @ normal) / (rays @ normal)).astype(np.float32)

    prev, cur = Camera((0.0, 1.5, 0.0), yaw=0.0, pitch=0.0), Camera((0.02, 1.5, -0.05), yaw=1.0, pitch=0.5)
    rng = np.random.default_rng(5)
    return {"depth": depth(cur), "view": cur.view(), "projection": cur.projection(w / h),
            "prev_colour": rng.random((h, w, 3)).astype(np.float32), "prev_depth": depth(prev),
            "prev_view_projection": prev.view_projection(w, h)}


def test_a_depth_convention_mistake_on_a_close_up_frame_is_named() -> None:
    """A wall within a metre fills the view: a standard depth buffer's values there are about 0.84 (not past 0.9,
    none at the clear value 1) and a reversed-Z one's 0.08 and over (past the near plane 0.05, the surfaces being
    that near), so the values alone named nothing and only the generic `seen` warning was given, naming no depth
    kind (nor for one kind given as the other, or a depth over the far plane); the reprojection in each other
    convention now names the one it is."""
    g = _close_wall()
    assert sdk.check_gbuffers(**g) == []
    proj = g["projection"]
    window, prev_window = (_hardware_depth(g[k], proj, "window") for k in ("depth", "prev_depth"))
    reversed_z, prev_reversed = (_hardware_depth(g[k], proj, "reversed") for k in ("depth", "prev_depth"))
    assert 0.8 < float(np.median(window)) < 0.9 and float(reversed_z.min()) > 0.05  # (what the values show)
    assert sdk.check_gbuffers(**{**g, "depth": window, "prev_depth": prev_window}, depth_kind="window") == []
    assert sdk.check_gbuffers(**{**g, "depth": reversed_z, "prev_depth": prev_reversed}, depth_kind="reversed") == []
    cases = [
        ("linear", window, prev_window, "taken as a standard depth buffer (depth_kind='window')"),
        ("linear", reversed_z, prev_reversed, "taken as a reversed-Z depth buffer (depth_kind='reversed')"),
        ("window", reversed_z, prev_reversed, "taken as a reversed-Z depth buffer (depth_kind='reversed')"),
        ("reversed", window, prev_window, "taken as a standard depth buffer (depth_kind='window')"),
        ("linear", g["depth"] / 200.0, g["prev_depth"] / 200.0,
         "taken as a depth divided by the far plane (Unity's Linear01Depth): multiply both by far (200)"),
    ]
    for kind, depth, prev_depth, named in cases:
        warnings = sdk.check_gbuffers(**{**g, "depth": depth, "prev_depth": prev_depth}, depth_kind=kind)
        seen = [w for w in warnings if w.startswith("seen: ")]
        assert len(seen) == 1 and seen[0].startswith("seen: only ") and seen[0].endswith(named), (kind, named, warnings)
    # another frame's previous buffers (a cut to another close-up): the plain warning, no depth kind guessed
    from rtp.scene import Camera

    moved = Camera((0.3, 1.2, 0.1), yaw=30.0, pitch=-20.0)
    cut = {**g, "prev_view_projection": moved.view_projection(64, 36), "prev_depth": g["prev_depth"][::-1].copy()}
    (warning,) = sdk.check_gbuffers(**cut)
    assert warning.startswith("seen: only ") and "taken as" not in warning, warning


def test_trying_other_depth_kinds_logs_nothing(caplog: pytest.LogCaptureFixture,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """check_gbuffers tries the other depth kinds where few surfaces reproject; trying reversed-Z on a standard
    depth buffer with sky (1 on background, the reversed-Z near plane, none 0) must not log input_planes' once-a-process
    'depth_kind='reversed', but ...' warning, which the caller never said and which a later real one then lacked."""
    from rtp.sdk import _planes

    monkeypatch.setattr(_planes, "_warned_kinds", set())
    g = _close_wall()
    g["depth"][:6], g["prev_depth"][:6] = 0.0, 0.0  # (some sky)
    window, prev_window = (_hardware_depth(g[k], g["projection"], "window") for k in ("depth", "prev_depth"))
    with caplog.at_level(logging.WARNING, logger="rtp.sdk"):
        warnings = sdk.check_gbuffers(**{**g, "depth": window, "prev_depth": prev_window})
    assert any(w.endswith("taken as a standard depth buffer (depth_kind='window')") for w in warnings), warnings
    assert caplog.records == [] and _planes._warned_kinds == set()


def test_a_gbuffer_at_another_resolution_is_named_with_its_likely_cause() -> None:
    """An upscaler's displayed frame (1.5x the render resolution) as prev_colour: the error says to give it at the
    G-buffers' resolution; a half-resolution albedo says every G-buffer is at the depth's."""
    g = _frame(20, 30)
    with pytest.raises(sdk.InputShapeError, match=r"prev_colour: .*1\.5x prev_depth's size: the displayed frame "
                                                  r"of an upscaler \(DLSS, FSR, XeSS\)\?"):
        sdk.input_planes(["seen"], **{**g, "prev_colour": np.zeros((30, 45, 3))})
    with pytest.raises(sdk.InputShapeError, match=r"albedo: .*at 0\.5x depth's size: every G-buffer at the render"):
        sdk.input_planes(["albedo.r"], **{**g, "albedo": np.zeros((10, 15, 3))})
    with pytest.raises(sdk.InputShapeError) as err:  # another shape, not a scale: no guess
        sdk.input_planes(["albedo.r"], **{**g, "albedo": np.zeros((20, 40, 3))})
    assert str(err.value).endswith("got (20, 40, 3)")
    for empty in (np.zeros((0, 0, 3)), np.zeros((0, 30, 3))):  # (no scale to guess: a ZeroDivisionError before)
        with pytest.raises(sdk.InputShapeError, match=r"albedo: expected shape \(20, 30, 3\)"):
            sdk.input_planes(["albedo.r"], **{**g, "albedo": empty})


def test_check_gbuffers_needs_depth_and_names_what_is_no_gbuffer() -> None:
    g = _frame()
    with pytest.raises(sdk.ParameterError, match=r"depth= is needed \(\(H, W\), linear view depth"):
        sdk.check_gbuffers(**{**g, "depth": None})
    with pytest.raises(sdk.ParameterError, match="normals: not a G-buffer"):
        sdk.check_gbuffers(**g, normals=g["normal"])
    assert sdk.check_gbuffers(depth=g["depth"]) == []  # (depth alone: only what it shows is checked)
    with pytest.raises(sdk.ParameterError, match="projection is singular"):  # (numpy's LinAlgError before)
        sdk.check_gbuffers(depth=g["depth"], normal=g["normal"], projection=np.full((4, 4), 255, np.uint8))
    # a perspective's rows with no x scale: no inverse to linearise a window depth through (a LinAlgError before)
    singular = np.array([[0.0, 0, 0, 0], [0, 1.5, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]])
    window = np.full(g["depth"].shape, 0.5, np.float32)
    with pytest.raises(sdk.ParameterError, match="projection is singular") as err:
        sdk.input_planes(["depth"], depth=window, projection=singular, depth_kind="window")
    assert err.value.name == "projection"
    # one through which the depth buffer is no finite view depth (-inf planes, accepted, before)
    huge = np.array([[1.0, 0, 0, 0], [0, 1.5, 0, 0], [0, 0, -1.002, 1e300], [0, 0, -1, 0]])
    for call in (sdk.input_planes, sdk.check_gbuffers):
        args = (["depth"],) if call is sdk.input_planes else ()
        with pytest.raises(sdk.ParameterError, match="no finite view depth at 600 of 600 pixels") as err:
            call(*args, depth=window, projection=huge, depth_kind="window")
        assert err.value.name == "projection"


def test_normals_left_unwritten_are_named() -> None:
    """A normal G-buffer of zeros on the surfaces (the normal target never written, or another texture bound) makes
    normal.* planes of 0 without an error; check_gbuffers named nothing, since it measured the length of the
    written normals alone: none."""
    g = _frame()
    facing = np.zeros((*g["depth"].shape, 3), np.float32)
    facing[..., 2] = 1.0
    assert sdk.check_gbuffers(depth=g["depth"], normal=facing, projection=g["projection"]) == []
    unwritten = facing.copy()
    unwritten[:, 10:] = 0.0  # (two thirds of the surfaces)
    warnings = sdk.check_gbuffers(depth=g["depth"], normal=unwritten, projection=g["projection"])
    assert warnings == ["normal: 67% of the surfaces have no normal (length 0): the normal target not written, or "
                        "another texture given?"], warnings
    assert sdk.check_gbuffers(depth=g["depth"], normal=np.zeros_like(facing))[0].startswith(
        "normal: 100% of the surfaces have no normal")
    few = facing.copy()
    few[:, :5] = 0.0  # (a few surfaces without one, as decals or particles may leave: not named)
    assert sdk.check_gbuffers(depth=g["depth"], normal=few, projection=g["projection"]) == []
