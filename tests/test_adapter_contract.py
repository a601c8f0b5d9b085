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

import json
import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from importlib.metadata import EntryPoint, entry_points
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

from rtp import conformance, sdk
from rtp.scene import Camera, Scene
from rtp.sdk import RtpError, adapters
from rtp.sdk.adapters import (
    Adapter,
    AdapterNotFoundError,
    AdapterOutputError,
    FrameSource,
    UnsupportedChannelError,
)
from tests.conftest import EGL_PACKAGES, make_current, open_gl_context

ROOT = Path(__file__).resolve().parents[1]

W, H = 64, 48

THIRD_PARTY = "numpy-gbuffers"
REGISTERED = sdk.adapters.available()  # the rtp.adapters entry points (and anything registered)
ADAPTERS = [*REGISTERED, THIRD_PARTY]

#: The kit's groups of checks.
GROUPS = {"class", "planes", "agreement", "previous frame", "order", "predictor", "lifecycle"}


def run_rtp(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """The installed ``rtp`` console script (which, unlike ``python -m``, puts no folder on sys.path)."""
    script = Path(sys.executable).with_name("rtp")
    return subprocess.run([str(script), *args], capture_output=True, text=True, timeout=600, cwd=cwd,
                          env={**os.environ, "PYTHONPATH": ""})


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
    roughness: np.ndarray | None = None  # (the material planes: the reference renderer's frames have them)
    metallic: np.ndarray | None = None
    specular: np.ndarray | None = None
    shadow: np.ndarray | None = None
    emissive: np.ndarray | None = None


class NumpyAdapter(Adapter[CpuFrame]):
    """The skeleton of docs/adapters.md: planes from numpy G-buffers by sdk.input_planes (the channels of the
    shipped LPIPS, not the material planes the others read: so the kit feeds it that one model)."""

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
        return sdk.input_planes(self.channels, **vars(frame), tolerance=self.tolerance)

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
                        prev.colour["1x1"], prev.depth, prev_camera.view_projection(self.width, self.height),
                        cur.roughness, cur.metallic, cur.specular, cur.shadow, cur.emissive)

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


def _report(spec: Any, **kw: Any) -> Any:
    """The conformance kit's report on ``spec``; skips where the adapter's engine is not installed."""
    report = conformance.check_adapter(spec, **kw)
    if report.not_run and "not installed" in report.not_run:  # the plugin's optional engine (rtp[<name>])
        pytest.skip(report.not_run)
    return report


# ------------------------------------------------------------------------- every adapter, through the kit
def test_the_shipped_adapters_are_registered() -> None:
    assert {"moderngl", "pyrender"} <= set(REGISTERED), REGISTERED


@pytest.mark.gl
@pytest.mark.parametrize("name", ADAPTERS)
def test_every_adapter_passes_the_conformance_kit(registry: None, tiny_model: Callable[..., Any], name: str) -> None:
    report = _report(name, model=tiny_model())
    assert report.ok, str(report)
    assert not report.skipped, str(report)
    assert {c.group for c in report.checks} == GROUPS
    assert report.channels == tuple(c for c in sdk.CHANNELS if c in sdk.adapters.get(name).supported_channels)
    agreed = {c.name.split()[0] for c in report.checks if c.group == "agreement"}
    assert agreed == set(report.channels) & set(conformance.AGREEMENT), agreed
    # the decisions from its planes and from the reference renderer's: a measurement, per model fed
    assert list(report.decisions) == ["tiny0"] and 0.0 <= report.decisions["tiny0"] <= 1.0
    if name in ("moderngl", THIRD_PARTY):  # the reference renderer's own G-buffers: the same rates on every tile
        assert report.decisions == {"tiny0": 1.0}, report.decisions


@pytest.mark.gl
def test_the_kit_feeds_every_shipped_model_an_adapter_can_run(registry: None) -> None:
    report = _report(THIRD_PARTY)  # reprojected/albedo RGB, seen, normal: the shipped LPIPS's inputs, no material
    assert report.runs_models == ("lpips.onnx",), report.runs_models
    assert [c.name for c in report.checks if c.group == "predictor"] == ["for_predictor feeds lpips.onnx"]
    assert report.ok, str(report)
    assert report.decisions == {"lpips": 1.0} and "lpips 100.0% of the tiles" in str(report)
    flipped = conformance.check_adapter(BUGS["upside down"][0](), size=(160, 96))  # 60 tiles
    assert flipped.decisions["lpips"] < 0.9, flipped.decisions
    assert set(conformance.runnable_models(sdk.adapters.get("moderngl"))) == set(sdk.shipped_models())


# ----------------------------------------------------------------- the kit finds what a broken adapter does
def _broken(cls_name: str, planes: Callable[[NumpyAdapter, CpuFrame, np.ndarray], np.ndarray] | None = None,
            **attrs: Any) -> type[NumpyAdapter]:
    """NumpyAdapter with one bug: ``planes`` rewrites its output, ``attrs`` replace class attributes."""
    def inputs(self: NumpyAdapter, frame: CpuFrame) -> np.ndarray:
        x = NumpyAdapter.inputs(self, frame)
        return x if planes is None else np.ascontiguousarray(planes(self, frame, x), np.float32)

    return type(cls_name, (NumpyAdapter,), {"inputs": inputs, "__module__": __name__, **attrs})  # (attrs may
    # replace inputs itself: a bug in what the adapter reads rather than in what it hands over)


def _plane(adapter: Adapter[Any], x: np.ndarray, channel: str) -> np.ndarray:
    return x[adapter.channels.index(channel)] if channel in adapter.channels else np.zeros(x.shape[1:], np.float32)


def _set(adapter: Adapter[Any], x: np.ndarray, **planes: np.ndarray) -> np.ndarray:
    x = x.copy()
    for key, value in planes.items():
        c = key.replace("_", ".")
        if c in adapter.channels:
            x[adapter.channels.index(c)] = value
    return x


class _UntrackedSource(CpuFrameSource):
    """A frame source that builds its adapters itself, so closing it leaves them open."""

    def adapter(self, channels: Any, **options: Any) -> Any:
        return self.adapter_class(channels, self.width, self.height, **options)


BUGS: dict[str, tuple[Callable[[], type[NumpyAdapter]], set[str]]] = {
    # an engine whose texture origin is bottom-left, read as is
    "upside down": (lambda: _broken("UpsideDown", lambda a, f, x: x[:, ::-1]),
                    {"albedo.r agrees with the reference renderer", "normal.x agrees with the reference renderer",
                     "depth agrees with the reference renderer", "seen agrees with the reference renderer"}),
    # normals stored as 0.5 n + 0.5 in an 8-bit target, handed over without decoding
    "encoded normals": (lambda: _broken("EncodedNormals", lambda a, f, x: _set(
        a, x, **{f"normal_{c}": 0.5 * _plane(a, x, f"normal.{c}") + 0.5 for c in "xyz"})),
                        {f"normal.{c} agrees with the reference renderer" for c in "xyz"}),
    # the previous frame's colour kept where the depth test failed
    "stale colour": (lambda: _broken("StaleColour", lambda a, f, x: _set(
        a, x, reprojected_g=np.where(_plane(a, x, "seen") == 0, 0.5, _plane(a, x, "reprojected.g")))),
                     {"reprojected.* are 0 where seen is 0"}),
    # luma as the mean of RGB instead of sdk.luma (BT.709)
    "mean for luma": (lambda: _broken("MeanLuma", lambda a, f, x: _set(a, x, albedo_y=f.albedo.mean(axis=-1))),
                      {"albedo.y is the luma of the adapter's own albedo.rgb",
                       "albedo.y agrees with the reference renderer"}),
    # planes in the adapter's own order, whatever was asked
    "own order": (lambda: _broken("OwnOrder", lambda a, f, x: x[np.argsort(np.argsort(
        [list(sdk.CHANNELS).index(c) for c in a.channels]))[::-1]] if len(a.channels) > 1 else x),
                  {"planes come in the requested order"}),
    # depth in [0, 1] NDC instead of view-space metres
    "NDC depth": (lambda: _broken("NdcDepth", lambda a, f, x: _set(a, x, depth=np.clip(_plane(a, x, "depth") / 100, 0, 1))),
                  {"depth agrees with the reference renderer"}),
    # a NaN where the reprojection found no previous pixel (a division by a zero weight)
    "NaN where unseen": (lambda: _broken("NanUnseen", lambda a, f, x: _set(
        a, x, reprojected_r=np.where(_plane(a, x, "seen") == 0, np.nan, _plane(a, x, "reprojected.r")))),
                         {"finite"}),
    # an 8-bit albedo target handed over as 0..255
    "albedo in bytes": (lambda: _broken("AlbedoBytes", lambda a, f, x: _set(
        a, x, **{f"albedo_{c}": _plane(a, x, f"albedo.{c}") * 255 for c in "rgb"})),
                        {"within each channel's range", "albedo.r agrees with the reference renderer"}),
    # a GL engine's previous frame read back as is (bottom row first), its depth the right way up
    "previous frame upside down": (lambda: _broken("PrevUpsideDown", inputs=lambda a, f: sdk.input_planes(
        a.channels, **{**vars(f), "prev_colour": np.ascontiguousarray(f.prev_colour[::-1])}, tolerance=a.tolerance)),
                                   {"the previous frame's edges line up with the reference renderer's"}),
    # a disocclusion test that never fails: every pixel reprojecting inside the previous frame is seen
    "no depth test": (lambda: _broken("NoDepthTest", inputs=lambda a, f: sdk.input_planes(
        a.channels, **vars(f), tolerance=1.0)), {"pixels the previous frame hid are unseen (the depth test)"}),
    # the 4x4 cells of a .blocks plane anchored at the bottom-left pixel (computed on GL rows)
    "blocks from the bottom": (lambda: _broken("BlocksFromTheBottom", lambda a, f, x: _set(
        a, x, albedo_y_blocks=sdk.block_variances(np.ascontiguousarray(_plane(a, x, "albedo.y")[::-1]))[::-1]),
        supported_channels=NumpyAdapter.supported_channels | {"albedo.y.blocks"}),
                               {"albedo.y.blocks is sdk.block_variances of the adapter's own albedo.y"}),
    "misnamed": (lambda: _broken("Misnamed", name="numpy"), {"name is its registry name"}),
    "closing the source leaves adapters open": (
        lambda: _broken("Untracked", frame_source=classmethod(
            lambda cls, scene, w, h, **o: _UntrackedSource(cls, scene, w, h, **o))),
        {"closing the frame source closes the adapters it built"}),
}


@pytest.mark.gl
@pytest.mark.parametrize("bug", sorted(BUGS))
def test_the_kit_names_what_a_broken_adapter_gets_wrong(registry: None, monkeypatch: pytest.MonkeyPatch,
                                                        bug: str) -> None:
    make, expected = BUGS[bug]
    cls = make()
    monkeypatch.setitem(adapters._registered, THIRD_PARTY, cls)
    report = _report(THIRD_PARTY)
    failed = {c.name for c in report.failures}
    assert expected <= failed, str(report)
    assert not report.ok
    assert repr(report) == (f"ConformanceReport(adapter='{THIRD_PARTY}', scene='procedural:0', "
                            f"{len(report.checks) - len(failed)} passed, {len(failed)} failed, 0 skipped)")
    with pytest.raises(conformance.ConformanceError, match="failed") as info:
        report.raise_for_failures()
    assert isinstance(info.value, sdk.RtpError) and sdk.exit_code(info.value) == sdk.EXIT_FAILED
    assert all(name in str(info.value) for name in expected)


def _red_pixels(path: Path) -> int:
    from PIL import Image

    rgb = np.asarray(Image.open(path).convert("RGB")).astype(int)
    return int(((rgb[..., 0] > 200) & (rgb[..., 1] < 40) & (rgb[..., 2] < 40)).sum())


@pytest.mark.gl
def test_the_kit_draws_where_an_adapter_differs_from_the_reference(tmp_path: Path) -> None:
    good = conformance.check_adapter(NumpyAdapter, image=tmp_path / "good.png")
    assert good.ok and good.image == str(tmp_path / "good.png") and "wrote " + good.image in str(good)
    flipped = conformance.check_adapter(BUGS["upside down"][0](), image=tmp_path / "flipped.jpg", model="lpips")
    assert not flipped.ok and flipped.image == str(tmp_path / "flipped.jpg")
    # a row a channel; red only where a plane is past its tolerance: none for the good one, rows of it flipped
    from PIL import Image

    assert Image.open(tmp_path / "good.png").size == Image.open(tmp_path / "flipped.jpg").size
    assert Image.open(tmp_path / "good.png").size[1] > 13 * 48 * 3  # 13 channels, each at least 3x its 48 rows
    assert _red_pixels(tmp_path / "good.png") == 0
    assert _red_pixels(tmp_path / "flipped.jpg") > 5000
    with pytest.raises(sdk.ParameterError, match="image"):  # a path that cannot be written: before any drawing
        conformance.check_adapter(NumpyAdapter, image=tmp_path / "planes.txt")
    none = conformance.check_adapter(_broken("Boom", lambda a, f, x: x[:1]), image=tmp_path / "none.png")
    assert none.image is None and not (tmp_path / "none.png").exists()  # no planes of the right shape: no picture
    assert none.no_image == "the adapter produced no planes of the shape (channels, 48, 64) to draw beside the " \
                            "reference renderer's" and none.to_dict()["no_image"] == none.no_image
    assert f"no picture written: {none.no_image}" in str(none)  # (it said nothing: the picture was just not there)
    assert good.no_image is None and "no picture" not in str(good)


@pytest.mark.gl
def test_an_adapter_that_raises_fails_with_its_error_and_the_rest_still_runs(registry: None,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    def boom(self: NumpyAdapter, frame: CpuFrame) -> np.ndarray:
        raise RuntimeError("shader failed to compile")

    monkeypatch.setitem(adapters._registered, THIRD_PARTY, type("Boom", (NumpyAdapter,), {"inputs": boom}))
    report = _report(THIRD_PARTY)
    first = next(c for c in report.checks if c.group == "planes")
    assert first.status == "failed" and first.detail == "raised RuntimeError: shader failed to compile"
    assert [c.status for c in report.checks if c.group in ("agreement", "previous frame", "order")] == ["skipped"] * 3
    assert {c.group for c in report.checks if c.status == "passed"} >= {"class"}



@pytest.mark.gl
def test_an_error_of_inputs_fails_no_lifecycle_check_it_does_not_name(registry: None,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    # a frame one row short: the planes and the predictor fail with the adapter's AdapterOutputError, and the
    # lifecycle passes (until 2026-12-07 "a foreign frame raises AdapterFrameError" failed with it too)
    monkeypatch.setitem(adapters._registered, THIRD_PARTY, _broken("ShortRows", lambda a, f, x: x[:, :-1]))
    report = _report(THIRD_PARTY)
    assert {(c.group, c.name) for c in report.failures} == {
        ("planes", "frame source -> adapter -> inputs, every supported channel"),
        ("predictor", "for_predictor feeds lpips.onnx")}, str(report)
    assert all("AdapterOutputError" in c.detail and "(C, H, W)" in c.detail for c in report.failures)
    lifecycle = [c for c in report.checks if c.group == "lifecycle"]
    assert len(lifecycle) == 7 and all(c.status == "passed" for c in lifecycle), str(report)

    # inputs that fail for the lifecycle's two channels alone (every channel at once drew): the check that drew
    # them says so, and the foreign frame's still passes
    def two_fail(self: NumpyAdapter, frame: CpuFrame) -> np.ndarray:
        if len(self.channels) == 2:
            raise RuntimeError("two planes are one texture too few")
        return NumpyAdapter.inputs(self, frame)

    monkeypatch.setitem(adapters._registered, THIRD_PARTY, _broken("TwoFail", inputs=two_fail))
    report = _report(THIRD_PARTY)
    assert [(c.group, c.name) for c in report.failures] == [
        ("lifecycle", "closing the frame source closes the adapters it built")], str(report)
    assert report.failures[0].detail == ("the source's adapters closed, but inputs() of reprojected.r, reprojected.g "
                                         "alone raised RuntimeError: two planes are one texture too few")


def _view_rotation(f: CpuFrame) -> np.ndarray:
    return np.asarray(f.view, np.float64)[:3, :3]


def _window_depth(f: CpuFrame, d: np.ndarray) -> np.ndarray:
    """A depth buffer's [0, 1] values of linear depth ``d`` (0 on background)."""
    p = np.asarray(f.projection, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        ndc = (p[2, 2] * -d + p[2, 3]) / np.where(d > 0, d, 1.0)
    return np.where(d > 0, ndc * 0.5 + 0.5, 0.0).astype(np.float32)


def _radial_depth(f: CpuFrame, d: np.ndarray) -> np.ndarray:
    """The distance to the camera of each pixel of linear depth ``d``."""
    p, (h, w) = np.asarray(f.projection, np.float64), d.shape
    xs = ((np.arange(w) + 0.5) / w * 2 - 1) / p[0, 0]
    ys = (1 - (np.arange(h) + 0.5) / h * 2) / p[1, 1]
    return (d * np.sqrt(1 + xs[None] ** 2 + ys[:, None] ** 2)).astype(np.float32)


def _motion_y_up(f: CpuFrame) -> np.ndarray:
    """The camera's motion vectors of ``f`` as a GL engine keeps them: pixels, previous minus current, y up."""
    mx, my = sdk.input_planes(("motion.x", "motion.y"), depth=f.depth, view=f.view, projection=f.projection,
                              prev_view_projection=f.prev_view_projection)
    return np.stack([mx, -my], axis=-1)


def _with(**changed: Callable[[CpuFrame], Any]) -> Callable[[NumpyAdapter, CpuFrame], np.ndarray]:
    """An adapter's inputs from its frame with the G-buffers of ``changed`` (each made from the frame) replaced."""
    def inputs(a: NumpyAdapter, f: CpuFrame) -> np.ndarray:
        return sdk.input_planes(a.channels, **{**vars(f), **{k: fn(f) for k, fn in changed.items()}},
                                tolerance=a.tolerance)
    return inputs


#: An engine's usual convention mistakes: the adapter, and per channel what the kit's failure says it looks like
#: (None: it fails naming no cause).
CAUSES: dict[str, tuple[Callable[[], type[NumpyAdapter]], dict[str, str | None]]] = {
    "green for luma": (lambda: NoLumaAdapter, {"albedo.y": None}),
    # (seen: 96% of it agrees upside down, so its cause is named only where the flip matches every pixel: until
    # 2026-12-07 a cause needed 5 points more than the plane's own share, past 100% for a share over 95%)
    "upside down": (BUGS["upside down"][0], {c: "the rows are upside down" for c in ("albedo.r", "normal.x", "depth",
                                                                                    "seen")}),
    # a plane in [0, 1] that does not follow the depth is no depth buffer's (until 2026-12-07 the kit told an adapter
    # filling depth with zeros, or handing another channel's plane in its place, to linearise its depth buffer)
    "zeros for depth": (lambda: _broken("ZeroDepth", lambda a, f, x: _set(a, x, depth=np.zeros(x.shape[1:]))),
                        {"depth": None}),
    "planes in the adapter's own order": (BUGS["own order"][0], {"depth": None}),
    "linear albedo": (lambda: _broken("LinearAlbedo", inputs=_with(albedo=lambda f: sdk.srgb_to_linear(f.albedo))),
                      {f"albedo.{c}": "albedo in linear light" for c in "rgby"}),
    "world-space normals": (lambda: _broken("WorldNormals", inputs=_with(normal=lambda f: (
        f.normal.astype(np.float64) @ _view_rotation(f)).astype(np.float32))),
                            {f"normal.{c}": "normals in world space" for c in "xyz"}),
    "encoded normals": (BUGS["encoded normals"][0], {f"normal.{c}": "normals encoded to [0, 1]" for c in "xyz"}),
    # an engine's world-space normal target read back 8-bit encoded and rotated as it is (until 2026-12-07 no cause)
    "encoded world-space normals": (lambda: _broken("EncodedWorldNormals", inputs=_with(
        normal=lambda f: (f.normal.astype(np.float64) @ _view_rotation(f) * 0.5 + 0.5).astype(np.float32),
        normal_space=lambda f: "world")),
                                    {f"normal.{c}": "world-space normals still encoded to [0, 1]" for c in "xyz"}),
    # a GL engine's own motion vectors (y up) handed to the reprojection unconverted: seen is wrong (until 2026-12-07
    # with no cause named, and the previous-frame checks blamed an upside-down frame or a missing depth test)
    "engine motion vectors with y up": (lambda: _broken("MotionYUp", inputs=_with(motion=_motion_y_up),
                                                        supported_channels=NumpyAdapter.supported_channels
                                                        | {"motion.x", "motion.y"}),
                                        {"seen": "the engine's motion vectors with y up",
                                         "motion.y": "motion the wrong way"}),
    "engine motion vectors upside down": (lambda: _broken("MotionRowsUp", inputs=_with(
        motion=lambda f: _motion_y_up(f)[::-1] * np.array([1.0, -1.0], np.float32))),
                                          {"seen": "the engine's motion vectors upside down"}),
    "previous depth upside down": (lambda: _broken("PrevDepthUpsideDown", inputs=_with(
        prev_depth=lambda f: np.ascontiguousarray(f.prev_depth[::-1]))),
                                   {"seen": "the previous frame's depth upside down"}),
    "left-handed normals": (lambda: _broken("NegatedNormals", inputs=_with(normal=lambda f: -f.normal)),
                            {f"normal.{c}": "normals with the opposite sign" for c in "yz"}),
    "a depth buffer's values": (lambda: _broken("WindowDepth", inputs=_with(
        depth=lambda f: _window_depth(f, f.depth), prev_depth=lambda f: _window_depth(f, f.prev_depth))),
                                {"depth": "a depth buffer's values", "seen": "almost no pixel reprojects"}),
    "distance to the camera": (lambda: _broken("RadialDepth", inputs=_with(depth=lambda f: _radial_depth(f, f.depth))),
                               {"depth": "the distance to the camera"}),
    "a transposed view": (lambda: _broken("TransposedView", inputs=_with(view=lambda f: np.ascontiguousarray(f.view.T))),
                          {"seen": "almost no pixel reprojects"}),
    "motion the wrong way": (lambda: _broken("MotionTheWrongWay", lambda a, f, x: _set(
        a, x, motion_x=-_plane(a, x, "motion.x"), motion_y=-_plane(a, x, "motion.y")),
        supported_channels=NumpyAdapter.supported_channels | {"motion.x", "motion.y"}),
                             {"motion.x": "motion the wrong way"}),
}


@pytest.mark.gl
@pytest.mark.parametrize("mistake", sorted(CAUSES))
def test_the_kit_names_the_likely_convention_mistake_and_its_fix(registry: None, monkeypatch: pytest.MonkeyPatch,
                                                                mistake: str) -> None:
    make, causes = CAUSES[mistake]
    monkeypatch.setitem(adapters._registered, THIRD_PARTY, make())
    report = _report(THIRD_PARTY)
    failed = {c.name.split()[0]: c.detail for c in report.failures if c.group == "agreement"}
    for channel, cause in causes.items():
        assert channel in failed, (channel, str(report))
        if cause is None:  # a mistake that is none of the usual ones: none is named
            assert "it looks like" not in failed[channel], failed[channel]
        else:
            assert f"; it looks like {cause}" in failed[channel], (channel, str(report))


@pytest.mark.gl
def test_the_previous_frame_checks_point_at_a_seen_that_disagrees(registry: None,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """Motion vectors with y up fetch the previous frame from the wrong place: its edge and depth-test checks fail,
    and say that seen disagrees too, rather than naming only an upside-down frame or a missing depth test."""
    monkeypatch.setitem(adapters._registered, THIRD_PARTY, CAUSES["engine motion vectors with y up"][0]())
    report = _report(THIRD_PARTY)
    previous = [c for c in report.failures if c.group == "previous frame"]
    assert previous, str(report)
    assert all("seen disagrees with the reference renderer's too" in c.detail for c in previous), str(report)
    # (a previous frame handed over upside down, seen right: no such pointer)
    monkeypatch.setitem(adapters._registered, THIRD_PARTY, BUGS["previous frame upside down"][0]())
    report = _report(THIRD_PARTY)
    edges = [c for c in report.failures if c.group == "previous frame"]
    assert edges and not any("seen disagrees" in c.detail for c in edges), str(report)


def test_the_kit_checks_the_class_before_drawing(registry: None, monkeypatch: pytest.MonkeyPatch) -> None:
    class NoClose(Adapter[CpuFrame]):  # an abstract method left: nothing is drawn
        name = THIRD_PARTY
        supported_channels = frozenset({"seen"})
        frame_type = CpuFrame

        def inputs(self, frame: CpuFrame) -> np.ndarray:
            return np.zeros((1, H, W), np.float32)

    report = conformance.check_adapter(NoClose)
    assert [c.name for c in report.failures] == ["nothing abstract is left", "has a frame_source"], str(report)
    assert report.failures[0].detail.startswith("abstract: close") and report.not_run == "the class cannot be driven"
    assert {c.group for c in report.checks} == {"class"}
    assert report.source.endswith(":test_the_kit_checks_the_class_before_drawing.<locals>.NoClose")


@pytest.mark.gl
def test_an_engine_that_is_not_installed_skips_the_drawing_checks_saying_so(tmp_path: Path) -> None:
    class NoEngine(NumpyAdapter):
        @classmethod
        def frame_source(cls, scene: Any, width: int, height: int, **options: Any) -> Any:
            raise ImportError("No module named 'myengine'")

    report = conformance.check_adapter(NoEngine)
    assert not report.ok and not report.failures and report.not_run is not None and "No module named 'myengine'" in report.not_run
    assert {c.group for c in report.skipped} == GROUPS
    assert [c.name for c in report.checks if c.group == "class" and c.status == "skipped"] == [
        "frame_source opens on the conformance scene"]
    assert "skipped (the numpy-gbuffers adapter's engine is not installed" in report.to_text()
    assert report.no_image is None  # (no picture asked for)
    pictured = conformance.check_adapter(NoEngine, image=tmp_path / "planes.png")
    assert pictured.no_image is not None and pictured.no_image.startswith("the numpy-gbuffers adapter's engine is not "
                                                                          "installed") and "no planes to draw" in \
        pictured.no_image and "no picture written: the numpy" in str(pictured)


@pytest.mark.gl
def test_the_kit_draws_another_scene_and_skips_what_its_move_cannot_show(monkeypatch: pytest.MonkeyPatch) -> None:
    other = conformance.check_adapter(NumpyAdapter, scene="procedural:1", model="lpips")
    assert other.ok and other.scene == "procedural:1" and "conformance on procedural:1 at 64x48" in str(other)
    assert other.to_dict()["scene"] == "procedural:1"
    # a camera that does not move uncovers nothing: the unseen-share check says so instead of failing
    from rtp.conformance import _kit

    moved = _kit._cameras
    monkeypatch.setattr(_kit, "_cameras", lambda scene: (moved(scene)[1],) * 2)
    still = conformance.check_adapter(NumpyAdapter, model="lpips")
    assert still.ok, str(still)
    skip, hidden = still.skipped
    assert skip.name == "some pixels are unseen after the move, most are seen"
    assert skip.detail == "the reference renderer's frame has 0.0% unseen pixels after this scene's move"
    assert hidden.name == "pixels the previous frame hid are unseen (the depth test)"
    assert hidden.detail.startswith("the move hides 0 of the drawn pixels in the previous frame")
    for bad, error in (("procedural:x", RtpError), ("no/such/level.glb", RtpError), ("", sdk.ParameterError)):
        with pytest.raises(error, match="scene|mesh file"):
            conformance.check_adapter(NumpyAdapter, scene=bad)


def test_a_map_is_read_from_the_scene_cache_given(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """check_adapter(scene=MAP) read only the default scene cache (`rtp adapters check` had no --cache-dir): it
    takes ``cache_dir`` now, the default cache when None; a cache_dir that is no path is a ParameterError."""
    default, given = tmp_path / "default-cache", tmp_path / "given"
    monkeypatch.setenv("RTP_SCENE_CACHE", str(default))
    with pytest.raises(RtpError, match=f"no scene index at {given / 'index.json'}"):
        conformance.check_adapter(NumpyAdapter, scene="oa_dm1", cache_dir=given)
    with pytest.raises(RtpError, match=f"no scene index at {default / 'index.json'}"):
        conformance.check_adapter(NumpyAdapter, scene="oa_dm1", cache_dir=None)
    for bad in (3, ""):
        with pytest.raises(sdk.ParameterError, match="cache_dir: expected the scene cache's folder path"):
            conformance.check_adapter(NumpyAdapter, scene="oa_dm1", cache_dir=bad)  # type: ignore[arg-type]


def test_resolving_an_adapter_says_what_was_expected() -> None:
    assert conformance.resolve_adapter(f"{__name__}:NumpyAdapter") == (NumpyAdapter, f"{__name__}:NumpyAdapter")
    assert conformance.resolve_adapter(NumpyAdapter)[0] is NumpyAdapter
    for spec, message in [("no-such-adapter", "no adapter named 'no-such-adapter'; available: "),
                          ("no_such_module:X", "cannot import 'no_such_module'"),
                          (f"{__name__}:Nope", f"module '{__name__}' has no 'Nope'"),
                          (f"{__name__}:CpuFrame", "is not an rtp.sdk.adapters.Adapter subclass"),
                          (CpuFrame, "is not an rtp.sdk.adapters.Adapter subclass"),
                          ("", "expected an adapter name")]:
        with pytest.raises(AdapterNotFoundError, match=message):
            conformance.resolve_adapter(spec)  # type: ignore[arg-type]
    with pytest.raises(sdk.ParameterError, match="jnyang reads roughness, metallic, specular, reprojected.y.blocks, "
                       r"albedo.y.blocks, which the adapter does not declare; give a model it can feed \(lpips\)"):
        conformance.check_adapter(NumpyAdapter, model="jnyang")
    with pytest.raises(sdk.ModelNotFoundError, match="no-such-model"):
        conformance.check_adapter(NumpyAdapter, model="no-such-model")
    with pytest.raises(sdk.ParameterError, match="model: expected a model path"):
        conformance.check_adapter(NumpyAdapter, model=3)  # type: ignore[arg-type]
    with pytest.raises(sdk.ParameterError, match="integers of at least 16"):
        conformance.check_adapter(NumpyAdapter, size=(8, 8))
    with pytest.raises(sdk.ParameterError, match="'albedo.q' is not a channel"):
        conformance.check_adapter(NumpyAdapter, tolerances={"albedo.q": 0.1})
    with pytest.raises(sdk.ParameterError, match=r"tolerances\['depth'\]: expected a number >= 0"):
        conformance.check_adapter(NumpyAdapter, tolerances={"depth": float("nan")})


def test_a_malformed_module_class_spec_is_refused_saying_what_was_expected() -> None:
    # an empty or relative module name reached importlib: its ValueError ('Empty module name') and TypeError (a
    # relative import without a package) came out of `rtp adapters check` as tracebacks
    for spec in (":NumpyAdapter", ".test_adapter_contract:NumpyAdapter", f"{__name__}:", "a..b:X", f"{__name__}:.X"):
        with pytest.raises(AdapterNotFoundError, match=r"expected package\.module:Class, dotted names of Python "
                           "identifiers"):
            conformance.resolve_adapter(spec)


def test_a_tolerance_no_check_would_use_is_refused() -> None:
    # a tolerance for a channel the adapter does not produce compared nothing, silently (--tolerance shadow=0.1 on
    # the pyrender adapter: the report as without it, exit 0); refused before the scene is loaded or drawn
    with pytest.raises(sdk.ParameterError, match=r"tolerances: the roughness channel is not among the adapter's, so "
                       r"no check uses its tolerance; it produces albedo\.b, albedo\.g"):
        conformance.check_adapter(NumpyAdapter, tolerances={"roughness": 0.1}, scene="no-such-map")
    with pytest.raises(sdk.ParameterError, match="tolerances: expected a mapping of channel names to tolerances, got list"):
        conformance.check_adapter(NumpyAdapter, tolerances=[("albedo.r", 0.1)])  # type: ignore[arg-type]


def test_a_tolerance_for_a_channel_the_kit_does_not_compare_is_refused() -> None:
    # a tolerance for a produced channel outside AGREEMENT (reprojected.*, specular, the derived planes) added an
    # agreement check the kit never makes: `--tolerance reprojected.r=0.1` on the pyrender adapter compared its own
    # lit image with the reference renderer's and failed (12% of the pixels within 1e-4), `--tolerance specular=0`
    # failed pyrender's F0 of 4 %, where docs/adapters.md says both are not compared and --tolerance loosens
    class Derived(NumpyAdapter):
        supported_channels: ClassVar[frozenset[str]] = NumpyAdapter.supported_channels | {"specular",
                                                                                           "albedo.y.blocks"}

    for channel, why in (("reprojected.r", "the previous frame is each engine's own lit image"),
                         ("specular", "each engine's own shading model"),
                         ("albedo.y.blocks", r"it is checked against sdk\.block_variances of the adapter's own albedo\.y")):
        with pytest.raises(sdk.ParameterError, match=rf"tolerances: the {channel} channel is not compared with the "
                           rf"reference renderer \({why}.*\), so no check uses its tolerance; the compared channels "
                           r"are seen, albedo\.r"):
            conformance.check_adapter(Derived, tolerances={channel: 0.1}, scene="no-such-map")


@pytest.mark.gl
def test_a_tolerance_can_be_relaxed_per_channel(registry: None, monkeypatch: pytest.MonkeyPatch) -> None:
    # an engine whose albedo is filtered (here: off by 0.08) passes at the tolerance it can meet
    class Tinted(NumpyAdapter):
        def inputs(self, frame: CpuFrame) -> np.ndarray:
            return super().inputs(replace(frame, albedo=np.clip(frame.albedo + [0.08, 0.0, 0.0], 0, 1).astype(np.float32)))

    cls = Tinted
    strict = conformance.check_adapter(cls, model=None)
    assert "albedo.r agrees with the reference renderer" in {c.name for c in strict.failures}
    relaxed = conformance.check_adapter(cls, tolerances={"albedo.r": 0.1, "depth": conformance.Tolerance(0.01, True)})
    assert relaxed.ok, str(relaxed)
    assert any(c.detail == "100.0% within 0.1" for c in relaxed.checks if c.name.startswith("albedo.r "))


# ---------------------------------------------------------------------------------------------- the command
@pytest.mark.gl
def test_rtp_adapters_check_from_a_plugin_checkout(tmp_path: Path) -> None:
    # run in the plugin's folder with module:Class, before any entry point is declared
    ok = run_rtp("adapters", "check", f"{__name__}:NumpyAdapter", "--size", "80x48", cwd=ROOT)
    assert ok.returncode == 0, ok.stderr
    assert "conformance on procedural:0 at 80x48" in ok.stdout and " 0 failed, 0 skipped" in ok.stdout
    assert "runs the shipped models: lpips" in ok.stdout
    bad = run_rtp("adapters", "check", f"{__name__}:NoLumaAdapter", "--json", "--image", str(tmp_path / "p.png"),
                  cwd=ROOT)
    assert bad.returncode == sdk.EXIT_FAILED, bad.stderr
    out = json.loads(bad.stdout)
    assert not out["ok"] and [c["name"] for c in out["checks"] if c["status"] == "failed"] == [
        "albedo.y is the luma of the adapter's own albedo.rgb", "albedo.y agrees with the reference renderer"]
    assert "failed 2 of" in bad.stderr and "albedo.y is the luma" in bad.stderr
    assert out["image"] == str(tmp_path / "p.png") and _red_pixels(tmp_path / "p.png") > 0  # albedo.y's row
    listed = run_rtp("adapters", "list")
    assert listed.returncode == 0 and listed.stdout.split("\n")[1].split()[:2] == ["moderngl", "25"], listed.stdout
    usage = run_rtp("adapters", "check", "moderngl", "--tolerance", "albedo=0.1")
    assert usage.returncode == sdk.EXIT_USAGE and "'albedo' is not a channel" in usage.stderr


def test_rtp_adapters_list_names_a_broken_plugin_and_lists_the_rest(registry: None, monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from rtp.cli import main

    broken = EntryPoint("brokenengine", "no_such_package.adapter:Adapter", adapters.ENTRY_POINT_GROUP)
    found = adapters.entry_points

    monkeypatch.setattr(adapters, "entry_points", lambda group: [*found(group), broken])
    assert main(["adapters", "list", "--json"]) == 0
    rows = {r["adapter"]: r for r in json.loads(capsys.readouterr().out)}
    assert set(rows) == {*REGISTERED, THIRD_PARTY, "brokenengine"}
    assert rows[THIRD_PARTY]["state"] == "ready" and rows[THIRD_PARTY]["runs_models"] == ["lpips"]
    assert "failed to load (ModuleNotFoundError" in rows["brokenengine"]["state"]
    assert rows["moderngl"]["channels"] == sorted(sdk.adapters.get("moderngl").supported_channels)
    assert main(["adapters", "list"]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split() == ["adapter", "channels", "runs", "the", "shipped", "models"]
    assert any(line.split()[:3] == [THIRD_PARTY, "13", "lpips"] for line in table), table
    assert any(line.startswith("brokenengine") and "failed to load" in line for line in table), table


class NoEngineAdapter(NumpyAdapter):
    """An adapter whose engine is not installed (the CLI test's)."""

    @classmethod
    def frame_source(cls, scene: Any, width: int, height: int, **options: Any) -> Any:
        raise ImportError("No module named 'myengine'")


@pytest.mark.gl
def test_rtp_adapters_check_fails_when_the_engine_is_missing(capsys: pytest.CaptureFixture[str]) -> None:
    from rtp.cli import main

    assert main(["adapters", "check", f"{__name__}:NoEngineAdapter"]) == sdk.EXIT_USAGE  # a missing install
    out, err = capsys.readouterr()
    assert "6 passed, 0 failed, 7 skipped" in out
    assert err.strip().splitlines()[-1] == (
        "rtp adapters check: error: the checks that draw frames did not run (the numpy-gbuffers adapter's engine is "
        "not installed: No module named 'myengine'): install the adapter's engine and run again")


class NoLumaAdapter(NumpyAdapter):
    """An adapter whose albedo.y is green alone (the CLI test's failing plugin)."""

    def inputs(self, frame: CpuFrame) -> np.ndarray:
        x = super().inputs(frame)
        if "albedo.y" in self.channels:
            x[self.channels.index("albedo.y")] = frame.albedo[..., 1] * 0.9
        return x


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


def test_the_output_is_checked_against_the_frames_size() -> None:
    """Adapter.frame_size(frame) is the adapter's size unless an adapter says a frame's (dynamic resolution in a
    corner of larger targets): the planes are checked against it, so an adapter that reads the whole target where
    the frame is smaller is caught, and one returning the frame's size passes."""
    class Corner(NumpyAdapter):
        def frame_size(self, frame: CpuFrame) -> tuple[int, int]:
            return W // 2, H // 2

    class Whole(Corner):
        def inputs(self, frame: CpuFrame) -> np.ndarray:
            return np.zeros((1, H, W), np.float32)

    class Cropped(Corner):
        def inputs(self, frame: CpuFrame) -> np.ndarray:
            return np.zeros((1, H // 2, W // 2), np.float32)

    assert NumpyAdapter(["seen"], W, H).frame_size(_cpu_frame()) == (W, H)
    with pytest.raises(AdapterOutputError, match=rf"shape \(1, {H}, {W}\).*\(1, {H // 2}, {W // 2}\)"):
        Whole(["seen"], W, H).inputs(_cpu_frame())
    assert Cropped(["seen"], W, H).inputs(_cpu_frame()).shape == (1, H // 2, W // 2)


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


def test_ci_fails_a_run_in_which_a_test_skipped(tmp_path: Path) -> None:
    """Every skip of the suite names a package or library to install, and CI installs them all: a run there that
    skipped a test (lost EGL, a dropped extra) was green with "N skipped". With $RTP_TESTS_NO_SKIPS set, as
    .ci/run sets it, the run fails naming the test; an xfail, and a run without it, pass as before."""
    from tests.conftest import NO_SKIPS_ENV

    assert f"{NO_SKIPS_ENV}=1 make test\n" in (ROOT / ".ci" / "run").read_text()
    (tmp_path / "test_one.py").write_text("import pytest\n\ndef test_ok():\n    pass\n\n"
                                          "def test_gone():\n    pytest.skip('libfoo is not installed')\n\n"
                                          "@pytest.mark.xfail(reason='known')\ndef test_known():\n    assert False\n")
    env = {k: v for k, v in os.environ.items() if k not in (NO_SKIPS_ENV, "PYTEST_XDIST_WORKER")}
    for workers in ([], ["-n", "2"]):
        runs = {}
        for value in ("", "1"):
            runs[value] = subprocess.run(
                [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "tests.conftest", *workers,
                 str(tmp_path / "test_one.py")], cwd=ROOT, env={**env, NO_SKIPS_ENV: value}, capture_output=True,
                text=True, timeout=300)
        assert runs[""].returncode == 0 and "1 skipped" in runs[""].stdout, runs[""].stdout[-2000:]
        failed = runs["1"]
        assert failed.returncode == pytest.ExitCode.TESTS_FAILED, (workers, failed.stdout[-2000:])
        assert "1 skipped with $RTP_TESTS_NO_SKIPS set: each is a missing install step" in failed.stdout
        assert "test_one.py::test_gone: Skipped: libfoo is not installed" in failed.stdout, failed.stdout[-2000:]
        assert "test_known" not in failed.stdout.split("missing install step")[1]


@pytest.mark.gl
def test_gl_tests_set_up_the_shared_context_before_their_own_fixtures(request: pytest.FixtureRequest) -> None:
    # conftest puts gl_context first, so that without EGL a gl test skips before a module fixture renders
    assert request.fixturenames[0] == "gl_context"
    assert request.getfixturevalue("gl_context").version_code >= 330


# ----------------------------------------------------------------------- lifecycle and report edges, no GL
def test_closing_a_source_frees_the_engine_and_every_adapter_when_one_close_raises() -> None:
    # one adapter whose close raised left the source's own close (the engine) unrun and the adapters after it
    # open, while the source said it was closed: the engine leaked, and an adapter kept borrowing it
    freed: list[str] = []

    class Failing(NumpyAdapter):
        def close(self) -> None:
            raise RuntimeError("driver gone")

    class Source(FrameSource[CpuFrame]):
        def frame(self, camera: Any, prev_camera: Any) -> CpuFrame:
            return _cpu_frame()

        def close(self) -> None:
            freed.append("engine")

    source = Source(Failing, W, H)
    first, second = source.adapter(["seen"]), source.adapter(["seen"])
    with pytest.raises(RuntimeError, match="driver gone"):
        source.close()
    assert freed == ["engine"] and first.closed and second.closed and source.closed
    source.close()  # once
    assert freed == ["engine"]


def test_a_subclass_that_does_not_call_super_init_is_refused_at_construction() -> None:
    # it was built, then failed at first use with "'NoSuper' object has no attribute '_channels'" (repr too)
    class NoSuper(NumpyAdapter):
        def __init__(self, channels: Sequence[str], width: int, height: int) -> None:
            self.tolerance = sdk.DEFAULT_REPROJECTION_TOLERANCE

    class NoSuperSource(CpuFrameSource):
        def __init__(self, adapter_class: type[NumpyAdapter], width: int, height: int) -> None:
            self.engine = None

    with pytest.raises(AdapterOutputError, match=r"NoSuper.__init__ did not call super\(\).__init__\(channels, width, "
                       r"height\): every rtp.sdk.adapters.Adapter subclass calls it first"):
        NoSuper(["seen"], W, H)
    with pytest.raises(AdapterOutputError, match=r"NoSuperSource.__init__ did not call super\(\).__init__\("
                       r"adapter_class, width, height\)"):
        NoSuperSource(NumpyAdapter, W, H)

    class Child(NumpyAdapter):  # an override that does call it, with the signature the kit reads
        def __init__(self, channels: Sequence[str], width: int, height: int, *, extra: int = 0) -> None:
            super().__init__(channels, width, height)
            self.extra = extra

    assert Child(["seen"], W, H, extra=1).extra == 1
    import inspect

    assert list(inspect.signature(Child.__init__).parameters)[1:4] == ["channels", "width", "height"]


def test_runnable_models_takes_what_check_adapter_takes() -> None:
    # runnable_models("moderngl") was AttributeError: 'str' object has no attribute 'supported_channels'
    assert conformance.runnable_models(f"{__name__}:NumpyAdapter") == conformance.runnable_models(NumpyAdapter) == (
        "lpips.onnx",)
    assert conformance.runnable_models("moderngl") == conformance.runnable_models(sdk.adapters.get("moderngl"))
    with pytest.raises(AdapterNotFoundError, match="expected an adapter name, 'module:Class' or an Adapter subclass"):
        conformance.runnable_models(3)  # type: ignore[arg-type]


def test_a_report_that_drew_nothing_is_not_ok(monkeypatch: pytest.MonkeyPatch) -> None:
    # the engine not installed: report.ok was True, --json said "ok": true while the command exited 2, and the
    # plugin test of docs/adapters.md (assert report.ok) passed in a CI whose engine failed to import
    monkeypatch.setitem(adapters._registered, "myengine", type("MyEngine", (NoEngineAdapter,), {"name": "myengine"}))
    report = conformance.check_adapter("myengine")
    assert report.not_run is not None and not report.failures and not report.ok
    assert report.to_dict()["ok"] is False
    with pytest.raises(conformance.ConformanceError, match="the checks that draw frames did not run .*No module named "
                       "'myengine'.*nothing was checked"):
        report.raise_for_failures()
    text = (ROOT / "docs" / "adapters.md").read_text()
    snippet = text[text.index("from rtp import conformance\n\ndef test_my_adapter_conforms"):]
    namespace: dict[str, Any] = {}
    exec(snippet[:snippet.index("```")], namespace)  # the plugin's test, as the docs write it
    with pytest.raises(AssertionError, match="skipped"):
        namespace["test_my_adapter_conforms"]()
