"""sdk.input_planes: every channel from G-buffers in numpy arrays, as the reference renderer makes them
(docs/runtime.md "Input planes from G-buffers on the host")."""

from __future__ import annotations

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
    ({"prev_colour": None, "prev_depth": None}, sdk.ParameterError,
     r"prev_colour= is needed for reprojected\.r, seen .*; prev_depth= is needed"),
    ({"prev_colour": np.full((20, 30, 3), 2.5)}, sdk.ParameterError,
     r"prev_colour: expected values in \[0, 1\] .* got \[2\.5, 2\.5\]: tone-map it .*linear_to_srgb"),
    ({"normal": np.full((20, 30, 3), 0.5) * 2 + 0.5}, sdk.ParameterError, r"normal: expected values in \[-1, 1\]"),
    ({"albedo": np.zeros((3, 20, 30))}, sdk.InputShapeError, r"albedo: expected shape \(20, 30, 3\).*np\.moveaxis"),
    ({"albedo": np.zeros((20, 31, 3))}, sdk.InputShapeError, r"albedo: expected shape \(20, 30, 3\)"),
    ({"depth": np.zeros((20, 30, 1))}, sdk.InputShapeError, r"depth: expected shape \('H', 'W'\)"),
    ({"depth": -np.ones((20, 30))}, sdk.ParameterError, r"depth: expected values in \[0, inf\]"),
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

