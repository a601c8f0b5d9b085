"""Every registered adapter follows one contract, checked by one generic driver.

The adapters are the ones the registry lists (``sdk.adapters.available()``: the ``rtp.adapters``
entry-point group), plus a third-party adapter written here and declared through a (simulated)
entry point of its own. Each is driven only through the generic path of docs/adapters.md:

    Adapter = sdk.adapters.get(name)
    with Adapter.frame_source(scene, W, H) as source, source.adapter(channels) as adapter:
        x = adapter.inputs(source.frame(camera, prev_camera))

on the procedural scene ``procedural(0)``, and its planes are compared with the reference renderer's
for the same cameras. Nothing here knows what a frame of a given engine holds.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any, ClassVar

import numpy as np
import pytest

from rtp import sdk
from rtp.capture.scenes import procedural
from rtp.scene import Camera, Scene
from rtp.sdk import adapters
from rtp.sdk.adapters import (
    Adapter,
    AdapterClosedError,
    AdapterFrameError,
    AdapterNotFoundError,
    AdapterOutputError,
    FrameSource,
    UnsupportedChannelError,
)
from tests.conftest import EGL_PACKAGES, make_current, open_gl_context

W, H = 64, 48
SCENE = procedural(0)
_SPAWN = SCENE.spawn_points[0]
PREV_CAMERA = Camera(_SPAWN.position, yaw=_SPAWN.yaw, pitch=-5.0)
CAMERA = Camera((_SPAWN.position[0] + 0.3, _SPAWN.position[1] + 0.05, _SPAWN.position[2] - 0.2),
                yaw=_SPAWN.yaw + 6.0, pitch=-3.0)

THIRD_PARTY = "numpy-gbuffers"
REGISTERED = sdk.adapters.available()  # the rtp.adapters entry points (and anything registered)
ADAPTERS = [*REGISTERED, THIRD_PARTY]

#: Agreement with the reference renderer on the conformance scene: (tolerance, relative?) per
#: channel, to hold on >= 99 % of the pixels. reprojected.* are not compared: the previous
#: displayed frame is each engine's own lit image.
AGREEMENT: dict[str, tuple[float, bool]] = {
    "seen": (0.0, False),
    **{f"albedo.{c}": (0.05, False) for c in "rgby"},
    **{f"normal.{c}": (0.01, False) for c in "xyz"},
    "depth": (1e-3, True),
    **{f"motion.{c}": (0.05, False) for c in "xy"},
    **{c: (0.01, False) for c in ("roughness", "metallic")},
    "depth.edge": (0.02, False),
}
#: Channels that describe the engine's own shading model, compared with nothing and allowed to be
#: constant: pyrender gives every dielectric F0 = 4 % (specular 0.5 everywhere); the moderngl
#: adapter's specular is checked against the renderer in tests/test_moderngl_adapter.py.
ENGINE_DEFINED = {"specular"}


# ------------------------------------------------------------------------------------ a third-party adapter
@dataclass(frozen=True)
class CpuFrame:
    """What a CPU engine hands its adapter: G-buffers and the previous frame as numpy arrays."""

    albedo: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    view: np.ndarray
    projection: np.ndarray
    prev_colour: np.ndarray
    prev_depth: np.ndarray
    prev_view_projection: np.ndarray


class NumpyAdapter(Adapter[CpuFrame]):
    """The skeleton of docs/adapters.md: planes from numpy G-buffers, reprojection by sdk.reproject."""

    name: ClassVar[str] = THIRD_PARTY
    supported_channels: ClassVar[frozenset[str]] = frozenset(
        {"reprojected.r", "reprojected.g", "reprojected.b", "reprojected.y", "seen", "albedo.r", "albedo.g", "albedo.b",
         "albedo.y", "normal.x", "normal.y", "normal.z", "depth"})
    frame_type: ClassVar[type] = CpuFrame

    def __init__(self, channels: Sequence[str], width: int, height: int, *,
                 tolerance: float = sdk.DEFAULT_REPROJECTION_TOLERANCE) -> None:
        super().__init__(channels, width, height)
        self.tolerance = tolerance
        self.closes = 0  # not idempotent by itself: the base class makes close() run once

    def inputs(self, frame: CpuFrame) -> np.ndarray:
        planes = {"depth": frame.depth}
        planes.update({f"albedo.{c}": frame.albedo[..., i] for i, c in enumerate("rgb")})
        planes["albedo.y"] = sdk.luma(frame.albedo)
        planes.update({f"normal.{c}": frame.normal[..., i] for i, c in enumerate("xyz")})
        rep, seen = sdk.reproject(frame.prev_colour, frame.prev_depth, frame.depth, frame.view, frame.projection,
                                  frame.prev_view_projection, tolerance=self.tolerance)
        planes.update({f"reprojected.{c}": rep[..., i] for i, c in enumerate("rgb")})
        planes["reprojected.y"] = sdk.luma(rep)
        planes["seen"] = seen
        return np.ascontiguousarray(np.stack([planes[c] for c in self.channels]), np.float32)

    def close(self) -> None:
        self.closes += 1

    @classmethod
    def frame_source(cls, scene: Any, width: int, height: int, **options: Any) -> CpuFrameSource:
        return CpuFrameSource(cls, scene, width, height, **options)


class CpuFrameSource(FrameSource[CpuFrame]):
    """The engine behind NumpyAdapter: the reference renderer, read back to numpy."""

    def __init__(self, adapter_class: type[NumpyAdapter], scene: Scene, width: int, height: int,
                 **options: Any) -> None:
        from rtp.plugins.moderngl import Renderer

        super().__init__(adapter_class, width, height)
        self.renderer = Renderer(width, height, **options)
        self.renderer.load_scene(scene)

    def frame(self, camera: Camera, prev_camera: Camera) -> CpuFrame:
        make_current(self.renderer.ctx)
        prev = self.renderer.render(prev_camera)
        cur = self.renderer.render(camera, prev)
        return CpuFrame(cur.albedo, cur.normal, cur.depth, camera.view(), camera.projection(self.width / self.height),
                        prev.colour["1x1"], prev.depth, prev_camera.view_projection(self.width, self.height))

    def close(self) -> None:
        self.renderer.release()


# ------------------------------------------------------------------------------------------------ fixtures
@pytest.fixture
def registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """The installed entry points plus the third party's, discovered afresh."""
    ours = EntryPoint(THIRD_PARTY, f"{__name__}:NumpyAdapter", adapters.ENTRY_POINT_GROUP)

    def with_third_party(group: str) -> list[Any]:
        return [*entry_points(group=group), *([ours] if group == ours.group else [])]

    monkeypatch.setattr(adapters, "entry_points", with_third_party)
    monkeypatch.setattr(adapters, "_registered", {})
    monkeypatch.setattr(adapters, "_discovered", None)


def _adapter_class(name: str) -> type[Adapter[Any]]:
    try:
        return sdk.adapters.get(name)
    except AdapterNotFoundError as exc:
        pytest.fail(f"registered adapter {name!r} does not load: {exc}")


def _all_channels(cls: type[Adapter[Any]]) -> list[str]:
    return [c for c in sdk.CHANNELS if c in cls.supported_channels]


@pytest.fixture(scope="module")
def reference(gl_context: Any) -> Any:
    """The reference renderer's current frame for CAMERA after PREV_CAMERA."""
    from rtp.plugins.moderngl import Renderer

    with Renderer(W, H, ctx=make_current(gl_context)) as r:
        r.load_scene(SCENE)
        return r.render(CAMERA, r.render(PREV_CAMERA))


def drive(cls: type[Adapter[Any]], channels: Sequence[str]) -> tuple[np.ndarray, Adapter[Any], FrameSource[Any]]:
    """The generic path: frame source -> adapter -> inputs; closes both; returns the planes."""
    try:
        source = cls.frame_source(SCENE, W, H)
    except ImportError as exc:  # the plugin's optional engine (pip install 'rtp[<name>]') is missing
        pytest.skip(f"the {cls.name} adapter's engine is not installed: {exc}")
    with source:
        assert isinstance(source, FrameSource) and source.adapter_class is cls
        assert (source.width, source.height) == (W, H)
        with source.adapter(channels) as adapter:
            assert isinstance(adapter, cls) and adapter.channels == tuple(channels)
            assert (adapter.width, adapter.height) == (W, H)
            x = adapter.inputs(source.frame(CAMERA, PREV_CAMERA))
    return x, adapter, source


# ---------------------------------------------------------------------------------------------- the class
def test_the_shipped_adapters_are_registered() -> None:
    assert {"moderngl", "pyrender"} <= set(REGISTERED), REGISTERED


@pytest.mark.parametrize("name", ADAPTERS)
def test_adapter_class_declares_the_contract(registry: None, name: str) -> None:
    cls = _adapter_class(name)
    assert inspect.isclass(cls) and issubclass(cls, Adapter)
    assert not inspect.isabstract(cls), f"{name} leaves abstract: {sorted(cls.__abstractmethods__)}"
    assert {"inputs", "close"} <= Adapter.__abstractmethods__  # ... so both are implemented
    assert cls.name == name
    assert cls.supported_channels and cls.supported_channels <= set(sdk.CHANNELS)
    assert isinstance(cls.frame_type, type) and cls.frame_type is not object
    assert cls.frame_source.__func__ is not Adapter.frame_source.__func__, f"{name} has no frame source"  # type: ignore[attr-defined]
    params = list(inspect.signature(cls.__init__).parameters.values())[1:4]
    assert [p.name for p in params] == ["channels", "width", "height"], params


# ------------------------------------------------------------------------------------------ driven on a scene
@pytest.mark.gl
@pytest.mark.parametrize("name", ADAPTERS)
def test_inputs_follow_the_channel_conventions(registry: None, reference: Any, name: str) -> None:
    cls = _adapter_class(name)
    channels = _all_channels(cls)
    x, _, _ = drive(cls, channels)
    assert isinstance(x, np.ndarray) and x.dtype == np.float32 and x.flags.c_contiguous
    assert x.shape == (len(channels), H, W)
    assert np.isfinite(x).all()
    for plane, c in zip(x, channels):
        spec = sdk.CHANNELS[c]
        assert spec.low <= plane.min() and plane.max() <= spec.high, (c, plane.min(), plane.max())
        # a moved camera in a furnished room: nothing is constant that the reference renderer varies
        # (no metal is in view: metallic is 0 in both)
        assert plane.std() > 0.0 or reference.channel(c).std() == 0.0 or c in ENGINE_DEFINED, f"{c} is constant"
    if "seen" in channels:  # unseen pixels carry no stale colour
        unseen = x[channels.index("seen")] == 0
        assert 0.0 < unseen.mean() < 0.5
        for c in ("reprojected.r", "reprojected.g", "reprojected.b", "reprojected.y"):
            if c in channels:
                assert not x[channels.index(c)][unseen].any(), c
    for kind in ("reprojected", "albedo"):  # the luma planes are the luma of the adapter's own RGB planes
        if {f"{kind}.{c}" for c in "rgby"} <= set(channels):
            rgb = np.stack([x[channels.index(f"{kind}.{c}")] for c in "rgb"], axis=-1)
            np.testing.assert_allclose(x[channels.index(f"{kind}.y")], sdk.luma(rgb), atol=1e-5, err_msg=kind)
    if {"reprojected.y", "reprojected.y.dx", "reprojected.y.dy"} <= set(channels):  # of the adapter's own luma
        for plane, want in zip(("dx", "dy"), sdk.pixel_differences(x[channels.index("reprojected.y")])):
            np.testing.assert_allclose(x[channels.index(f"reprojected.y.{plane}")], want, atol=1e-5, err_msg=plane)
    for plane, c in zip(x, channels):
        if c not in AGREEMENT:
            continue
        tol, relative = AGREEMENT[c]
        ref = reference.channel(c)
        err = np.abs(plane - ref) / (np.maximum(np.abs(ref), 1e-6) if relative else 1.0)
        assert np.mean(err <= tol) >= 0.99, f"{c} agrees with the reference renderer on {np.mean(err <= tol):.3f}"


@pytest.mark.gl
@pytest.mark.parametrize("name", ADAPTERS)
def test_planes_come_in_the_requested_order(registry: None, name: str) -> None:
    cls = _adapter_class(name)
    channels = _all_channels(cls)
    shuffled = [channels[i] for i in np.random.default_rng(7).permutation(len(channels))]
    assert shuffled != channels
    x, _, _ = drive(cls, channels)
    y, _, _ = drive(cls, shuffled)
    np.testing.assert_allclose(y, x[[channels.index(c) for c in shuffled]], rtol=1e-6, atol=1e-6)
    one, _, _ = drive(cls, [shuffled[0]])
    np.testing.assert_allclose(one[0], y[0], rtol=1e-6, atol=1e-6)


@pytest.mark.gl
@pytest.mark.parametrize("name", ADAPTERS)
def test_for_predictor_feeds_the_predictor(registry: None, tiny_model: Callable[..., Any], name: str) -> None:
    cls = _adapter_class(name)
    predictor = sdk.load(tiny_model())
    try:
        source = cls.frame_source(SCENE, W, H)
    except ImportError as exc:
        pytest.skip(f"the {name} adapter's engine is not installed: {exc}")
    with source, cls.for_predictor(predictor, W, H, **source.adapter_options()) as adapter:
        assert adapter.channels == predictor.metadata.inputs
        rates = predictor.shading_rates(adapter.inputs(source.frame(CAMERA, PREV_CAMERA)))
    assert rates.shape == predictor.tiles(H, W)


@pytest.mark.gl
@pytest.mark.parametrize("name", ADAPTERS)
def test_lifecycle_context_manager_close_and_errors(registry: None, name: str) -> None:
    cls = _adapter_class(name)
    channels = sorted(cls.supported_channels)[:2]
    unsupported = [c for c in sdk.CHANNELS if c not in cls.supported_channels]
    try:
        source = cls.frame_source(SCENE, W, H)
    except ImportError as exc:
        pytest.skip(f"the {name} adapter's engine is not installed: {exc}")
    with source as entered:
        assert entered is source and not source.closed
        with pytest.raises(UnsupportedChannelError, match="unknown channel"):
            source.adapter(["albedo.q"])
        if unsupported:
            with pytest.raises(UnsupportedChannelError, match=f"cannot produce {unsupported[0]}"):
                source.adapter([unsupported[0]])
        frame = source.frame(CAMERA, PREV_CAMERA)
        with source.adapter(channels) as adapter:
            assert not adapter.closed
            with pytest.raises(AdapterFrameError, match="frames, got builtins.object"):
                adapter.inputs(object())
            first = adapter.inputs(frame)
        assert adapter.closed
        with pytest.raises(AdapterClosedError, match="has been closed") as info:
            adapter.inputs(frame)
        assert isinstance(info.value, sdk.RtpError)
        adapter.close()  # twice: nothing happens
        if isinstance(adapter, NumpyAdapter):
            assert adapter.closes == 1
        with pytest.raises(AdapterClosedError):
            with adapter:
                pass
        lent = source.adapter(channels)  # never closed by hand ...
        np.testing.assert_array_equal(lent.inputs(source.frame(CAMERA, PREV_CAMERA)), first)
    assert source.closed and lent.closed  # ... the source closed it first
    source.close()
    with pytest.raises(AdapterClosedError, match="frame source has been closed"):
        source.frame(CAMERA, PREV_CAMERA)
    with pytest.raises(AdapterClosedError):
        source.adapter(channels)


# --------------------------------------------------------------------------------- the base class, no GL
def _cpu_frame(value: float = 0.5) -> CpuFrame:
    """A wall 2 m in front of a camera that did not move, in colour ``value``."""
    view, proj = np.eye(4), Camera((0.0, 0.0, 0.0)).projection(W / H)
    img = np.full((H, W, 3), value, np.float32)
    depth = np.full((H, W), 2.0, np.float32)
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 2] = 1.0
    return CpuFrame(img, normal, depth, view, proj, img, depth, proj @ view)


def test_a_cpu_adapter_runs_without_gl() -> None:
    with NumpyAdapter(["seen", "albedo.g", "normal.z", "reprojected.b"], W, H) as a:
        x = a.inputs(_cpu_frame(0.25))
    assert x.shape == (4, H, W)
    np.testing.assert_array_equal(x[0], 1.0)  # a static camera sees every pixel again
    np.testing.assert_allclose(x[[1, 3]], 0.25)
    np.testing.assert_array_equal(x[2], 1.0)
    assert "closed" in repr(a) and THIRD_PARTY in repr(a)


@pytest.mark.parametrize(("result", "problem"), [
    (lambda: np.zeros((1, H, W), np.float64), "dtype float64"),
    (lambda: np.zeros((1, W, H), np.float32), r"shape \(1, 64, 48\)"),
    (lambda: np.zeros((1, H, 2 * W), np.float32)[..., ::2], "non-contiguous"),
    (lambda: [[0.0]], "a list"),
])
def test_an_adapter_breaking_the_output_contract_is_caught(result: Callable[[], Any], problem: str) -> None:
    class Broken(NumpyAdapter):
        def inputs(self, frame: CpuFrame) -> np.ndarray:
            return result()  # type: ignore[no-any-return]

    with pytest.raises(AdapterOutputError, match=problem) as info:
        Broken(["seen"], W, H).inputs(_cpu_frame())
    assert isinstance(info.value, sdk.RtpError) and "(1, 48, 64)" in str(info.value)


def test_abstract_methods_are_enforced() -> None:
    class NoClose(Adapter[CpuFrame]):
        supported_channels = frozenset({"seen"})

        def inputs(self, frame: CpuFrame) -> np.ndarray:
            return np.zeros((1, H, W), np.float32)

    with pytest.raises(TypeError, match="abstract"):
        NoClose(["seen"], W, H)  # type: ignore[abstract]


def test_an_override_chain_closes_once_even_when_close_fails() -> None:
    calls: list[str] = []

    class Child(NumpyAdapter):
        def close(self) -> None:
            calls.append("child")
            super().close()
            raise RuntimeError("driver gone")

    a = Child(["seen"], W, H)
    with pytest.raises(RuntimeError, match="driver gone"):
        a.close()
    assert calls == ["child"] and a.closes == 1 and a.closed
    a.close()
    assert calls == ["child"] and a.closes == 1


def test_construction_errors() -> None:
    with pytest.raises(UnsupportedChannelError, match="no channels"):
        NumpyAdapter([], W, H)
    with pytest.raises(UnsupportedChannelError, match="sequence of channel names"):
        NumpyAdapter("seen", W, H)
    with pytest.raises(sdk.ParameterError, match="positive"):
        NumpyAdapter(["seen"], 0, H)
    with pytest.raises(adapters.AdapterFrameError, match="needs a predictor"):
        NumpyAdapter.for_predictor(["seen"], W, H)  # type: ignore[arg-type]


def test_the_registry_takes_only_adapters(registry: None, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(sdk.ParameterError, match="subclass of rtp.sdk.adapters.Adapter"):
        sdk.adapters.register("callable", lambda *a: None)  # type: ignore[arg-type]
    fake = EntryPoint("not-an-adapter", "rtp.sdk:load", adapters.ENTRY_POINT_GROUP)
    monkeypatch.setattr(adapters, "entry_points", lambda group: [fake])
    monkeypatch.setattr(adapters, "_discovered", None)
    with pytest.raises(AdapterNotFoundError, match="not an rtp.sdk.adapters.Adapter subclass"):
        sdk.adapters.get("not-an-adapter")


def test_the_gl_fixture_skips_naming_the_packages(monkeypatch: pytest.MonkeyPatch) -> None:
    import rtp.plugins.moderngl as plugin

    def no_egl(require: int = 330) -> Any:
        raise plugin.RendererError("eglGetDisplay failed")

    monkeypatch.setattr(plugin, "create_context", no_egl)
    with pytest.raises(pytest.skip.Exception) as info:
        open_gl_context()
    assert EGL_PACKAGES in str(info.value) and "eglGetDisplay failed" in str(info.value)


@pytest.mark.gl
def test_gl_tests_set_up_the_shared_context_before_their_own_fixtures(request: pytest.FixtureRequest) -> None:
    # conftest puts gl_context first, so that without EGL a gl test skips before a module fixture renders
    assert request.fixturenames[0] == "gl_context"
    assert request.getfixturevalue("gl_context").version_code >= 330
