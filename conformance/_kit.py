"""The adapter conformance kit: every check of docs/adapters.md "Testing an adapter", runnable
against any adapter class, installed or not (see :func:`check_adapter`)."""

from __future__ import annotations

import importlib
import inspect
import logging
import os
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np

from rtp import sdk
from rtp.scene import Camera, Scene
from rtp.sdk.adapters import (
    Adapter,
    AdapterClosedError,
    AdapterFrameError,
    AdapterNotFoundError,
    FrameSource,
    UnsupportedChannelError,
)

log = logging.getLogger("rtp.conformance")


class Tolerance(NamedTuple):
    """How close a channel must come to the reference renderer's: within ``value`` (absolute, or
    relative to the reference when ``relative``) on at least :data:`MIN_AGREEMENT` of the pixels."""

    value: float
    relative: bool = False


#: Agreement with the reference renderer on the conformance scene, per channel. ``reprojected.*`` are
#: not compared: the previous displayed frame is each engine's own lit image.
AGREEMENT: Mapping[str, Tolerance] = {
    "seen": Tolerance(0.0),
    **{f"albedo.{c}": Tolerance(0.05) for c in "rgby"},
    **{f"normal.{c}": Tolerance(0.01) for c in "xyz"},
    "depth": Tolerance(1e-3, relative=True),
    **{f"motion.{c}": Tolerance(0.05) for c in "xy"},
    **{c: Tolerance(0.01) for c in ("roughness", "metallic")},
    "depth.edge": Tolerance(0.02),
}
#: The share of pixels on which a channel must agree.
MIN_AGREEMENT = 0.99
#: How far past its range a plane's values may go (float32 rounding: a GPU's normalize() gives 1 + 1 ulp).
RANGE_SLACK = 1e-6
#: How closely the edges of the adapter's previous frame, reprojected, must line up with the reference
#: renderer's: the correlation of their gradient magnitudes on the pixels both see (with their left and upper
#: neighbours). Engines shade differently (pyrender's lit image: 0.53-0.85 on procedural levels 0-4 at 64x48
#: and 320x192), while its previous frame handed over upside down reaches at most 0.25
#: (``python bench/conformance_margins.py``).
MIN_EDGE_CORRELATION = 0.4
#: The share of the pixels the previous frame hid (seen == 0 in the reference renderer's frame although the
#: point reprojects inside the previous frame) that must be unseen in the adapter's too: an adapter without
#: the depth test (pyrender's with a tolerance of 1) reaches at most 0.27 on procedural levels 0-4 at 64x48 and
#: 320x192; pyrender's, at least 0.78 (``python bench/conformance_margins.py``).
MIN_OCCLUDED_UNSEEN = 0.5
#: Channels that describe the engine's own shading model: compared with nothing and allowed to be
#: constant (pyrender gives every dielectric F0 = 4 %: specular 0.5 everywhere).
ENGINE_DEFINED = frozenset({"specular"})
#: The frame size the checks draw at (width, height).
DEFAULT_SIZE = (64, 48)
#: The scene the checks draw by default: the procedural level of seed 0 (``rtp.capture.scenes.procedural``).
CONFORMANCE_SCENE = "procedural:0"

Status = Literal["passed", "failed", "skipped"]


class ConformanceError(sdk.RtpError, AssertionError):
    """An adapter failed the conformance checks (:meth:`ConformanceReport.raise_for_failures`)."""


@dataclass(frozen=True)
class Check:
    """One conformance check: its group (``class``, ``planes``, ``agreement``, ``order``,
    ``predictor``, ``lifecycle``), what it checks, and how it went."""

    group: str
    name: str
    status: Status
    detail: str = ""


@dataclass(frozen=True)
class ConformanceReport:
    """What :func:`check_adapter` found. ``str(report)`` is the table ``rtp adapters check`` prints,
    so ``assert report.ok, report`` in a plugin's own tests shows every failure."""

    adapter: str
    source: str
    size: tuple[int, int]
    channels: tuple[str, ...]
    checks: tuple[Check, ...]
    #: The shipped models whose every input the adapter produces.
    runs_models: tuple[str, ...] = ()
    #: Why the checks that draw frames did not run, when they did not (the engine is not installed).
    not_run: str | None = None
    #: The picture written (``check_adapter(image=...)``): each channel beside the reference's.
    image: str | None = None
    #: The scene drawn (``check_adapter(scene=...)``).
    scene: str = CONFORMANCE_SCENE
    #: Per model fed (its name), the share of tiles where the rate chosen from the adapter's planes is the
    #: rate chosen from the reference renderer's, the planes of the engine's own lit image (``reprojected.*``)
    #: and shading model (:data:`ENGINE_DEFINED`) kept the adapter's: what the G-buffers' differences do to
    #: the decisions. A measurement, not a check (an engine's own texture filtering moves decisions near a
    #: threshold: docs/adapters.md, the pyrender adapter).
    decisions: Mapping[str, float] = field(default_factory=dict)
    #: Why the picture asked for (``check_adapter(image=...)``) was not written; None when it was, or none was asked.
    no_image: str | None = None

    @property
    def failures(self) -> tuple[Check, ...]:
        return tuple(c for c in self.checks if c.status == "failed")

    @property
    def skipped(self) -> tuple[Check, ...]:
        return tuple(c for c in self.checks if c.status == "skipped")

    @property
    def ok(self) -> bool:
        """No check failed, and the checks that draw frames ran (skipped checks are listed in :attr:`skipped`,
        with why; where the engine is not installed none drew, :attr:`not_run` says why, and a check that drew
        nothing passed nothing: not ok, as ``rtp adapters check`` exits 2)."""
        return not self.failures and self.not_run is None

    def raise_for_failures(self) -> None:
        """Raise :class:`ConformanceError` listing every failed check, if any failed, or saying why the checks
        that draw did not run (:attr:`not_run`): whenever the report is not :attr:`ok`."""
        if self.failures:
            raise ConformanceError(f"adapter {self.adapter!r} failed {len(self.failures)} of {len(self.checks)} "
                                   "conformance checks: " + "; ".join(f"{c.group}: {c.name} ({c.detail})"
                                                                     for c in self.failures))
        if self.not_run is not None:
            raise ConformanceError(f"adapter {self.adapter!r}: the checks that draw frames did not run "
                                   f"({self.not_run}), so nothing was checked of its planes")

    def to_dict(self) -> dict[str, Any]:
        return {"adapter": self.adapter, "source": self.source, "size": list(self.size), "channels": list(self.channels),
                "ok": self.ok, "runs_models": list(self.runs_models), "not_run": self.not_run, "image": self.image,
                "no_image": self.no_image, "decisions": dict(self.decisions), "scene": self.scene,
                "checks": [{"group": c.group, "name": c.name, "status": c.status, "detail": c.detail}
                           for c in self.checks]}

    def to_text(self) -> str:
        w, h = self.size
        lines = [f"adapter {self.adapter!r} ({self.source}): conformance on {self.scene} at {w}x{h}"]
        group_w = max((len(c.group) for c in self.checks), default=5)
        for c in self.checks:
            mark = {"passed": "ok  ", "failed": "FAIL", "skipped": "skip"}[c.status]
            lines.append(f"  {mark} {c.group:<{group_w}}  {c.name}" + (f": {c.detail}" if c.detail else ""))
        counts = {s: sum(c.status == s for c in self.checks) for s in ("passed", "failed", "skipped")}
        lines.append(f"{counts['passed']} passed, {counts['failed']} failed, {counts['skipped']} skipped"
                     + (f" ({self.not_run})" if self.not_run else ""))
        lines.append("runs the shipped models: " + (", ".join(m.removesuffix(".onnx") for m in self.runs_models)
                                                    if self.runs_models else "none (no shipped "
                     "model's inputs are all among its channels)"))
        if self.decisions:
            lines.append("the same rate as from the reference renderer's G-buffers (with the engine's own lit image): "
                         + ", ".join(f"{m} {share:.1%}" for m, share in self.decisions.items()) + " of the tiles")
        if self.image:
            lines.append(f"wrote {self.image}: each channel beside the reference renderer's, red where they differ "
                         "past the tolerance")
        elif self.no_image:
            lines.append(f"no picture written: {self.no_image}")
        return "\n".join(lines)

    __str__ = to_text

    def __repr__(self) -> str:  # (short: pytest shows it in `assert report.ok`; str() is the whole table)
        counts = ", ".join(f"{sum(c.status == k for c in self.checks)} {k}" for k in ("passed", "failed", "skipped"))
        return f"ConformanceReport(adapter={self.adapter!r}, scene={self.scene!r}, {counts})"


def resolve_adapter(spec: str | type[Adapter[Any]]) -> tuple[type[Adapter[Any]], str]:
    """The adapter class ``spec`` names and where it came from: a registry name
    (``sdk.adapters.available()``), ``"package.module:Class"`` (an adapter not yet registered), or
    the class itself. Raises :class:`rtp.sdk.adapters.AdapterNotFoundError` saying what was expected."""
    if isinstance(spec, type):
        if not issubclass(spec, Adapter):
            raise AdapterNotFoundError(f"{spec.__module__}.{spec.__qualname__} is not an rtp.sdk.adapters.Adapter subclass")
        return spec, f"{spec.__module__}:{spec.__qualname__}"
    if not isinstance(spec, str) or not spec:
        raise AdapterNotFoundError(f"expected an adapter name, 'module:Class' or an Adapter subclass, got {spec!r}")
    if ":" not in spec:
        return sdk.adapters.get(spec), "the registry"  # AdapterNotFoundError names the installed ones
    module_name, _, qualname = spec.partition(":")
    if not all(part.isidentifier() for text in (module_name, qualname) for part in text.split(".")):
        # (":X" was importlib's ValueError 'Empty module name', ".mod:X" its TypeError on a relative import)
        raise AdapterNotFoundError(f"{spec!r}: expected package.module:Class, dotted names of Python identifiers on "
                                   "both sides of the colon (an absolute module path), or an installed adapter's name")
    try:
        obj: Any = importlib.import_module(module_name)
    except ImportError as exc:
        raise AdapterNotFoundError(f"{spec}: cannot import {module_name!r} ({type(exc).__name__}: {exc}); is its "
                                   "package installed, or its folder on PYTHONPATH?") from exc
    for part in qualname.split("."):
        if not hasattr(obj, part):
            raise AdapterNotFoundError(f"{spec}: module {module_name!r} has no {qualname!r}")
        obj = getattr(obj, part)
    if not (isinstance(obj, type) and issubclass(obj, Adapter)):
        raise AdapterNotFoundError(f"{spec} is not an rtp.sdk.adapters.Adapter subclass (got {obj!r})")
    return obj, spec


def runnable_models(adapter: str | type[Adapter[Any]]) -> tuple[str, ...]:
    """The shipped models (file names) whose every input ``adapter`` declares it produces: the class, or
    what :func:`resolve_adapter` takes (a registry name, ``"package.module:Class"``)."""
    if not isinstance(adapter, type) or not issubclass(adapter, Adapter):
        adapter = resolve_adapter(adapter)[0]  # (AdapterNotFoundError saying what was expected)
    out = []
    for name in sdk.shipped_models():
        try:
            inputs = sdk.load(name).metadata.inputs
        except sdk.RtpError as exc:  # a broken install: say so, do not hide the others
            log.warning("shipped model %s does not load: %s", name, exc)
            continue
        if set(inputs) <= set(adapter.supported_channels):
            out.append(name)
    return tuple(out)


class _Failed(Exception):
    """A check's expectation did not hold (the message says how)."""


def _expect(condition: Any, detail: str) -> None:
    if not condition:
        raise _Failed(detail)


@dataclass
class _Run:
    checks: list[Check] = field(default_factory=list)

    @contextmanager
    def check(self, group: str, name: str) -> Iterator[list[str]]:
        """Record a check: passed unless the body raises (``_Failed``: its message; anything else:
        the exception). The body may append a detail for a check that passed."""
        note: list[str] = []
        try:
            yield note
        except _Failed as exc:
            self.checks.append(Check(group, name, "failed", str(exc)))
        except Exception as exc:  # the adapter's own error is a failure of the check, with its text
            self.checks.append(Check(group, name, "failed", f"raised {type(exc).__name__}: {exc}"))
        else:
            self.checks.append(Check(group, name, "passed", "; ".join(note)))

    def skip(self, group: str, name: str, why: str) -> None:
        self.checks.append(Check(group, name, "skipped", why))


def _cameras(scene: Scene) -> tuple[Camera, Camera]:
    """The conformance move: 0.3 m sideways, 0.2 m ahead, 6 degrees of turn (camera, prev_camera)."""
    spawn = scene.spawn_points[0]
    prev = Camera(spawn.position, yaw=spawn.yaw, pitch=-5.0)
    cur = Camera((spawn.position[0] + 0.3, spawn.position[1] + 0.05, spawn.position[2] - 0.2),
                 yaw=spawn.yaw + 6.0, pitch=-3.0)
    return cur, prev


def _class_checks(run: _Run, cls: type[Adapter[Any]], registry_name: str | None) -> bool:
    """The class's declarations; False when it cannot be driven at all."""
    with run.check("class", "nothing abstract is left"):
        _expect(not inspect.isabstract(cls), f"abstract: {', '.join(sorted(cls.__abstractmethods__))} "
                "(an adapter implements inputs and close)")
    with run.check("class", "name is its registry name" if registry_name else "name is set"):
        if registry_name:
            _expect(cls.name == registry_name, f"name is {cls.name!r}, registered as {registry_name!r}")
        else:
            _expect(isinstance(cls.name, str) and cls.name, f"name is {cls.name!r}: expected the name it registers "
                    "under (its entry point's)")
    with run.check("class", "supported_channels are sdk.CHANNELS names"):
        chans = cls.supported_channels
        _expect(chans, "supported_channels is empty")
        unknown = sorted(set(chans) - set(sdk.CHANNELS))
        _expect(not unknown, f"not in sdk.CHANNELS: {', '.join(unknown)}")
    with run.check("class", "declares a frame_type"):
        _expect(isinstance(cls.frame_type, type) and cls.frame_type is not object,
                f"frame_type is {cls.frame_type!r}: expected the class of the frames inputs() reads")
    with run.check("class", "has a frame_source"):
        own = getattr(cls.frame_source, "__func__", None) is not getattr(Adapter.frame_source, "__func__", None)
        _expect(own, "frame_source is the base class's (which raises NoFrameSourceError): a registered adapter "
                "draws rtp.scene.Scene through its engine")
    with run.check("class", "constructor starts (channels, width, height)"):
        params = [p.name for p in list(inspect.signature(cls.__init__).parameters.values())[1:4]]
        _expect(params == ["channels", "width", "height"], f"it starts {tuple(params)}")
    return not any(c.status == "failed" and c.name in ("nothing abstract is left", "has a frame_source")
                   for c in run.checks)


def _plane_checks(run: _Run, x: np.ndarray, channels: Sequence[str], reference: Any, size: tuple[int, int]) -> None:
    w, h = size
    with run.check("planes", "float32, C-contiguous, (C, H, W)"):
        _expect(isinstance(x, np.ndarray), f"inputs() returned {type(x).__name__}")
        _expect(x.dtype == np.float32 and x.flags.c_contiguous, f"dtype {x.dtype}, contiguous {x.flags.c_contiguous}")
        _expect(x.shape == (len(channels), h, w), f"shape {x.shape}, expected {(len(channels), h, w)}")
    if not (isinstance(x, np.ndarray) and x.shape == (len(channels), h, w)):
        return
    with run.check("planes", "finite"):
        bad = [c for plane, c in zip(x, channels) if not np.isfinite(plane).all()]
        _expect(not bad, f"NaN or infinity in {', '.join(bad)}")
    with run.check("planes", "within each channel's range"):
        out = []
        for plane, c in zip(x, channels):
            spec = sdk.CHANNELS[c]
            lo, hi = float(np.nanmin(plane)), float(np.nanmax(plane))
            if not (spec.low - RANGE_SLACK <= lo and hi <= spec.high + RANGE_SLACK):
                out.append(f"{c} spans [{lo:.7g}, {hi:.7g}], its range is [{spec.low}, {spec.high}]")
        _expect(not out, "; ".join(out))
    with run.check("planes", "no channel is constant that the reference renderer varies"):
        const = [c for plane, c in zip(x, channels)
                 if not plane.std() > 0.0 and c not in ENGINE_DEFINED and (reference is None or reference.channel(c).std() > 0)]
        _expect(not const, f"constant: {', '.join(const)} (a moved camera in a furnished room)")
    if "seen" in channels:
        unseen = x[list(channels).index("seen")] == 0
        ref_unseen = float((reference.channel("seen") == 0).mean()) if reference is not None else 0.25
        if 0.0 < ref_unseen < 0.5:
            with run.check("planes", "some pixels are unseen after the move, most are seen"):
                _expect(0.0 < unseen.mean() < 0.5, f"{unseen.mean():.1%} of the pixels are unseen (seen == 0), "
                        f"{ref_unseen:.1%} in the reference renderer's frame: the move uncovers some and keeps most")
        else:  # (a scene of the user's where this move uncovers nothing, or most: seen's agreement still holds)
            run.skip("planes", "some pixels are unseen after the move, most are seen", f"the reference renderer's "
                     f"frame has {ref_unseen:.1%} unseen pixels after this scene's move")
        rep = [c for c in ("reprojected.r", "reprojected.g", "reprojected.b", "reprojected.y") if c in channels]
        if rep:
            with run.check("planes", "reprojected.* are 0 where seen is 0"):
                stale = [c for c in rep if x[list(channels).index(c)][unseen].any()]
                _expect(not stale, f"stale colour on unseen pixels in {', '.join(stale)}")
    for kind in ("reprojected", "albedo"):
        names = [f"{kind}.{c}" for c in "rgby"]
        if set(names) <= set(channels):
            with run.check("planes", f"{kind}.y is the luma of the adapter's own {kind}.rgb"):
                rgb = np.stack([x[list(channels).index(n)] for n in names[:3]], axis=-1)
                err = float(np.max(np.abs(x[list(channels).index(names[3])] - sdk.luma(rgb))))
                _expect(err <= 1e-5, f"differs by up to {err:.3g}")
    derived = {"blocks": sdk.block_variances, "tiles": sdk.tile_variances}
    for c in channels:
        base, _, kind = c.rpartition(".")
        if kind in derived and base in channels:
            fn = derived[kind]
            with run.check("planes", f"{c} is sdk.{fn.__name__} of the adapter's own {base}"):
                err = float(np.max(np.abs(x[list(channels).index(c)] - fn(x[list(channels).index(base)]))))
                _expect(err <= 2e-3, f"differs by up to {err:.3g} (cells anchored at the top-left pixel, "
                        "docs/adapters.md)")
    if {"reprojected.y", "reprojected.y.dx", "reprojected.y.dy"} <= set(channels):
        with run.check("planes", "reprojected.y.dx/.dy are differences of the adapter's own reprojected.y"):
            want = sdk.pixel_differences(x[list(channels).index("reprojected.y")])
            err = max(float(np.max(np.abs(x[list(channels).index(f"reprojected.y.{p}")] - v)))
                      for p, v in zip(("dx", "dy"), want))
            _expect(err <= 1e-5, f"differ by up to {err:.3g}")


def _why_not_compared(channel: str) -> str:
    """Why ``channel`` (one not in :data:`AGREEMENT`) has no agreement check, in a few words."""
    base, _, kind = channel.rpartition(".")
    derived = {"blocks": "block_variances", "tiles": "tile_variances", "dx": "pixel_differences", "dy": "pixel_differences"}
    if kind in derived:
        return f"it is checked against sdk.{derived[kind]} of the adapter's own {base}"
    if channel.startswith("reprojected."):
        return "the previous frame is each engine's own lit image; its edges and depth test are checked"
    return "each engine's own shading model"


def _within(plane: np.ndarray, ref: np.ndarray, tol: Tolerance, where: np.ndarray | None = None) -> float:
    """The share of the pixels (of ``where``) on which ``plane`` is within ``tol`` of ``ref``."""
    with np.errstate(invalid="ignore", over="ignore"):
        err = np.abs(plane - ref) / (np.maximum(np.abs(ref), 1e-6) if tol.relative else 1.0)
        ok = err <= tol.value
    return float(np.mean(ok if where is None else ok[where])) if (where is None or where.any()) else 0.0


#: How well a plane must match one of :func:`_likely_cause`'s mistakes, on the geometry, for the kit to name it.
_CAUSE_AGREEMENT = 0.9
#: How closely the ranks of a depth plane in [0, 1] must follow the reference's view depth (Spearman's rho, either
#: sign: a reversed-Z buffer falls with depth) for the kit to call it a depth buffer's values.
_DEPTH_BUFFER_RANKS = 0.9


def _follows_depth(values: np.ndarray, depth: np.ndarray) -> bool:
    """Whether ``values`` rise (or fall) with ``depth`` across the pixels, as a depth buffer's do: a constant
    plane (zeros in place of a depth buffer) or another channel's does not."""
    if values.size < 2 or not (np.std(values) > 0 and np.std(depth) > 0):
        return False
    ranks = [np.argsort(np.argsort(v, kind="stable"), kind="stable").astype(np.float64) for v in (values, depth)]
    return abs(float(np.corrcoef(ranks[0], ranks[1])[0, 1])) >= _DEPTH_BUFFER_RANKS


def _likely_cause(channel: str, plane: np.ndarray, reference: Any, tol: Tolerance, share: float,
                  previous: Any = None) -> str:
    """What a plane that disagrees with the reference renderer's looks like, and the fix: the first of the usual
    convention mistakes (rows upside down, linear albedo, encoded or world-space normals, a depth buffer's values
    or the distance to the camera, motion the wrong way; for ``seen``, the engine's motion vectors in another
    convention, reprojected through ``previous``, the reference renderer's previous frame) that, applied to the
    reference's plane, agrees with the adapter's far better (empty: none does)."""
    ref = np.asarray(reference.channel(channel), np.float64)
    geo = np.asarray(reference.channel("depth")) > 0
    h, w = ref.shape
    kind = channel.partition(".")[0]
    candidates: list[tuple[str, np.ndarray, np.ndarray | None]] = [
        ("the rows are upside down (a GL read-back hands the bottom row first): flip them once, where the adapter "
         "reads back, to a top-left origin", ref[::-1], None),
        ("it is mirrored left to right", ref[:, ::-1], None)]
    if kind == "albedo":
        rgb = np.stack([reference.channel(f"albedo.{c}") for c in "rgb"], -1).astype(np.float64)
        lin, twice = sdk.srgb_to_linear(np.clip(rgb, 0, 1)), sdk.linear_to_srgb(np.clip(rgb, 0, 1))
        pick = (lambda a: sdk.luma(a)) if channel == "albedo.y" else (lambda a: a[..., "rgb".index(channel[-1])])
        candidates += [("albedo in linear light: the contract's is display-encoded sRGB (encode it with "
                        "sdk.linear_to_srgb, or input_planes(albedo_linear=True))", pick(lin), geo),
                       ("albedo encoded to sRGB twice: the texture was display-encoded already", pick(twice), geo)]
    elif kind == "normal":
        n = np.stack([reference.channel(f"normal.{c}") for c in "xyz"], -1).astype(np.float64)
        rotation = np.asarray(reference.camera.view(), np.float64)[:3, :3]
        k = "xyz".index(channel[-1])
        candidates += [("normals encoded to [0, 1] (n * 0.5 + 0.5), as an 8-bit target stores them: decode them "
                        "(n * 2 - 1)", 0.5 * ref + 0.5, geo),
                       ("normals in world space: rotate them into view space with the view matrix "
                        "(input_planes(normal_space='world', view=...))", (n @ rotation)[..., k], geo),
                       # (an engine's world-space normal target, 8-bit encoded, rotated as it was read back: the
                       # view rotation of n_world * 0.5 + 0.5 is n_view * 0.5 plus half the rotation of (1, 1, 1))
                       ("world-space normals still encoded to [0, 1] (n * 0.5 + 0.5) when rotated into view space: "
                        "decode them (n * 2 - 1) before the rotation (before input_planes(normal_space='world'))",
                        0.5 * ref + 0.5 * float(rotation[k].sum()), geo),
                       ("normals with the opposite sign: the contract's view space is right-handed, the camera "
                        "looking down -Z, z > 0 facing it (a left-handed view space negates z)", -ref, geo)]
    elif channel == "depth":
        proj = np.asarray(reference.camera.projection(w / h), np.float64)
        xs = ((np.arange(w) + 0.5) / w * 2.0 - 1.0) / proj[0, 0]
        ys = (1.0 - (np.arange(h) + 0.5) / h * 2.0) / proj[1, 1]
        radial = ref * np.sqrt(1.0 + xs[None, :] ** 2 + ys[:, None] ** 2)
        candidates.append(("the distance to the camera, not the view depth along -Z: divide by the length of "
                           "each pixel's ray at depth 1", radial, geo))
        if (geo.any() and float(ref[geo].max()) > 1.0 and float(np.abs(plane[geo]).max()) <= 1.0
                and _follows_depth(plane[geo], ref[geo])):  # (not any plane in [0, 1]: zeros, another channel)
            return (f"a depth buffer's values (in [0, 1], where the reference's reach {float(ref[geo].max()):.3g}), "
                    "not linear view depth in scene units: linearise it, or input_planes(depth_kind='window' or "
                    "'reversed')")
    elif kind == "motion":
        candidates.append(("motion the wrong way (the current minus the previous position, or for motion.y a y axis "
                           "pointing up): the contract's is the previous minus the current position, x right and y "
                           "down", -ref, geo))
    elif channel == "seen" and float(np.mean(plane > 0)) < 0.02 < float(np.mean(ref > 0)):
        return ("almost no pixel reprojects onto the previous frame: view, projection, prev_view_projection or the "
                "depths in another convention (a transposed matrix, for row vectors; a depth buffer's values)? "
                "sdk.check_gbuffers on one frame names such a mistake")
    if channel == "seen" and previous is not None:
        # an engine's own motion vectors handed to the reprojection (input_planes(motion=...)) in another convention:
        # every geometry pixel is fetched from the wrong place, and the move's depth test fails where that is another
        # surface (until 2026-12-07 seen failed naming no cause, and the previous-frame checks blamed a flipped frame)
        motion = np.asarray(reference.motion, np.float64)
        prev_depth = np.asarray(previous.depth, np.float32)
        camera, prev_camera = reference.camera, previous.camera
        motions = (
            ("the engine's motion vectors with y up: the contract's are the previous minus the current position "
             "in pixels, x right and y down (negate y; docs/runtime.md \"Objects that move\")", prev_depth,
             motion * (1.0, -1.0)),
            ("the engine's motion vectors the wrong way: the contract's are the previous minus the current "
             "position in pixels, x right and y down (negate them; docs/runtime.md \"Objects that move\")",
             prev_depth, -motion),
            ("the engine's motion vectors upside down (a GL read-back hands the bottom row first): flip their rows "
             "once, as the other G-buffers'", prev_depth, motion[::-1]),
            ("the previous frame's depth upside down (a GL read-back hands the bottom row first): flip prev_depth's "
             "rows once, where the adapter reads it back", np.ascontiguousarray(prev_depth[::-1]), None))
        for cause, depth_before, moved in motions:
            _, expected_seen = sdk.reproject(depth_before, depth_before, np.asarray(reference.depth, np.float32),
                                             camera.view(), camera.projection(w / h), prev_camera.view_projection(w, h),
                                             motion=None if moved is None else np.ascontiguousarray(moved, np.float32))
            candidates.append((cause, expected_seen, None))
    for cause, expected, where in candidates:
        # (clearly better than the reference's own plane: 5 points more, or every pixel where that is past 100%)
        if _within(plane, expected, tol, where) >= min(1.0, max(_CAUSE_AGREEMENT, share + 0.05)):
            return cause
    return ""


def _agreement_checks(run: _Run, x: np.ndarray, channels: Sequence[str], reference: Any,
                      tolerances: Mapping[str, Tolerance], previous: Any = None) -> None:
    for plane, c in zip(x, channels):
        if c not in tolerances:
            continue
        tol = tolerances[c]
        with run.check("agreement", f"{c} agrees with the reference renderer") as note:
            share = _within(plane, reference.channel(c), tol)
            within = f"within {tol.value:g}{' (relative)' if tol.relative else ''}"
            if share < MIN_AGREEMENT:  # (the usual mistakes named, with their fix)
                cause = _likely_cause(c, plane, reference, tol, share, previous)
                raise _Failed(f"{share:.1%} of the pixels {within}, needs {MIN_AGREEMENT:.0%}"
                              + (f"; it looks like {cause}" if cause else ""))
            note.append(f"{share:.1%} {within}")


def _gradient(plane: np.ndarray) -> np.ndarray:
    """Each pixel's larger absolute difference to its left and upper neighbour (0 on the first row and column)."""
    g = np.zeros(plane.shape, np.float64)
    g[:, 1:] = np.abs(np.diff(plane, axis=1))
    g[1:] = np.maximum(g[1:], np.abs(np.diff(plane, axis=0)))
    return g


def _previous_frame_checks(run: _Run, x: np.ndarray, channels: Sequence[str], reference: Any) -> None:
    """What can be checked of the previous frame, although each engine lights its own: its edges, reprojected,
    line up with the reference renderer's (an upside-down or shifted previous frame does not), and the pixels the
    previous frame hid are unseen (the depth test)."""
    index = {c: i for i, c in enumerate(channels)}
    seen = x[index["seen"]] > 0 if "seen" in index else np.ones(x.shape[1:], bool)
    both = seen & (reference.channel("seen") > 0)
    both[1:] &= both[:-1].copy()  # (a gradient of seen pixels only: the edges of the unseen regions are both
    both[:, 1:] &= both[:, :-1].copy()  # frames', whatever the colour)
    both[0] = both[:, 0] = False
    if "reprojected.y" in index:
        luma = x[index["reprojected.y"]]
    elif {"reprojected.r", "reprojected.g", "reprojected.b"} <= set(index):
        luma = sdk.luma(np.stack([x[index[f"reprojected.{c}"]] for c in "rgb"], axis=-1))
    else:
        luma = None
    # (where seen itself disagrees, the reprojection fetches from the wrong place, which the checks below see first:
    # until 2026-12-07 they named a flipped frame or a missing depth test for an engine's motion vectors with y up)
    seen_failed = any(c.group == "agreement" and c.name.startswith("seen ") and c.status == "failed"
                      for c in run.checks)
    also = ("; seen disagrees with the reference renderer's too (its agreement line): the frame is fetched from where "
            "the reprojection puts each pixel, so mend that first") if seen_failed else ""
    name = "the previous frame's edges line up with the reference renderer's"
    if luma is not None:
        mine, ref = _gradient(luma)[both], _gradient(reference.channel("reprojected.y"))[both]
        if both.sum() < 64 or not (mine.std() > 0 and ref.std() > 0):
            run.skip("previous frame", name, f"{int(both.sum())} pixels seen in both frames, or no edges among them")
        else:
            with run.check("previous frame", name) as note:
                r = float(np.corrcoef(mine, ref)[0, 1])
                _expect(r >= MIN_EDGE_CORRELATION, f"the gradient magnitudes of its reprojected luma correlate "
                        f"{r:.2f} with the reference's, needs {MIN_EDGE_CORRELATION}: the previous frame handed over "
                        "upside down (a GL texture's rows), mirrored or shifted?" + also)
                note.append(f"correlation {r:.2f}")
    name = "pixels the previous frame hid are unseen (the depth test)"
    if "seen" in index:
        h, w = int(x.shape[1]), int(x.shape[2])
        rows, cols = np.indices((h, w))
        px, py = cols + reference.channel("motion.x"), rows + reference.channel("motion.y")
        hidden = ((reference.channel("seen") == 0) & (reference.channel("depth") > 0)
                  & (px >= 0) & (px < w) & (py >= 0) & (py < h))
        if hidden.sum() < 5:
            run.skip("previous frame", name, f"the move hides {int(hidden.sum())} of the drawn pixels in the "
                     "previous frame (a larger --size shows more)")
        else:
            with run.check("previous frame", name) as note:
                share = float((~seen[hidden]).mean())
                _expect(share >= MIN_OCCLUDED_UNSEEN, f"{share:.0%} of the {int(hidden.sum())} pixels the previous "
                        f"frame hid are unseen, needs {MIN_OCCLUDED_UNSEEN:.0%}: a disocclusion test that never "
                        "fails (no depth comparison, or a tolerance too wide)?" + also)
                note.append(f"{share:.0%} of {int(hidden.sum())}")


def check_adapter(adapter: str | type[Adapter[Any]], *, size: tuple[int, int] = DEFAULT_SIZE,
                  tolerances: Mapping[str, float | Tolerance] | None = None,
                  model: str | Path | sdk.ShadingRatePredictor | None = None,
                  frame_source_options: Mapping[str, Any] | None = None,
                  image: str | Path | None = None, scene: str = CONFORMANCE_SCENE,
                  cache_dir: str | os.PathLike[str] | None = None) -> ConformanceReport:
    """Run every conformance check of docs/adapters.md on an adapter and report each.

    The adapter is driven only through the generic path (``frame_source`` -> ``adapter`` ->
    ``inputs``) on a scene (by default the procedural level ``procedural:0``), after a camera move
    of 0.3 m and 6 degrees from its first spawn point, and its planes are compared with the reference renderer's
    (:class:`rtp.plugins.moderngl.Renderer`) for the same cameras.

    Args:
        adapter: a registry name (``sdk.adapters.available()``), ``"package.module:Class"``, or
            the class.
        size: the frame size (width, height) drawn; at least 16 x 16.
        tolerances: per-channel agreement tolerances replacing those of :data:`AGREEMENT` (a float
            keeps the channel's relative flag), for an engine that filters or encodes differently; only
            the channels :data:`AGREEMENT` compares take one.
        model: the predictor ``for_predictor`` feeds (a path, a shipped model's name, or a loaded
            predictor); default every shipped model the adapter can run.
        frame_source_options: keyword arguments of the adapter's ``frame_source``.
        scene: the scene drawn, as ``rtp capture --scene`` names one: ``procedural:<seed>``, your
            own glTF / GLB / OBJ file, or a map of ``rtp scenes list`` (fetched).
        cache_dir: the scene cache a map is read from (``rtp adapters check --cache-dir``); default
            :func:`rtp.capture.scenes.default_cache_dir`.
        image: write a picture here (its extension names the format: ``.png``, ``.jpg``, ...): a
            row per channel, the adapter's plane beside the reference renderer's and their
            difference, red where it is past the channel's tolerance. Written whenever the adapter
            produced planes of the right shape, failed checks or not.

    Returns:
        the report; nothing raises for a failed check (:meth:`ConformanceReport.raise_for_failures`
        does). Where the adapter's engine is not installed (its ``frame_source`` raises
        ImportError), the checks that draw are skipped and ``not_run`` says why.

    Raises:
        rtp.sdk.adapters.AdapterNotFoundError: ``adapter`` names no adapter.
        rtp.sdk.ParameterError: a bad ``size`` or ``tolerances`` (one for a channel the adapter does
            not produce, or one the kit does not compare with the reference renderer, which no check would
            use, included).
        rtp.plugins.moderngl.RendererError: no headless OpenGL for the reference renderer.
    """
    cls, source_text = resolve_adapter(adapter)
    registry_name = adapter if isinstance(adapter, str) and ":" not in adapter else None
    if not (isinstance(size, (tuple, list)) and len(size) == 2
            and all(isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) and v >= 16
                    for v in size)):
        raise sdk.ParameterError(f"size: expected (width, height), integers of at least 16, got {size!r}", "size")
    size = (int(size[0]), int(size[1]))
    if image is not None:
        from rtp.capture import check_image_output

        check_image_output(image, what="image")  # (before any drawing: a bad path is a ParameterError now)
    tols = dict(AGREEMENT)
    if tolerances is not None and not isinstance(tolerances, Mapping):
        raise sdk.ParameterError(f"tolerances: expected a mapping of channel names to tolerances, got "
                                 f"{type(tolerances).__name__}", "tolerances")
    for c, t in (tolerances or {}).items():
        if c not in sdk.CHANNELS:
            raise sdk.ParameterError(f"tolerances: {c!r} is not a channel of sdk.CHANNELS", "tolerances")
        if c not in (cls.supported_channels or ()):  # (else nothing compares it: a tolerance silently unused)
            raise sdk.ParameterError(f"tolerances: the {c} channel is not among the adapter's, so no check uses its "
                                     f"tolerance; it produces {', '.join(sorted(cls.supported_channels or ())) or 'none'}",
                                     "tolerances")
        if c not in AGREEMENT:  # (it added a comparison the kit never makes: reprojected.* against another lit image)
            raise sdk.ParameterError(f"tolerances: the {c} channel is not compared with the reference renderer "
                                     f"({_why_not_compared(c)}), so no check uses its tolerance; the compared "
                                     f"channels are {', '.join(AGREEMENT)}", "tolerances")
        value = t.value if isinstance(t, Tolerance) else t
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not (value >= 0):
            raise sdk.ParameterError(f"tolerances[{c!r}]: expected a number >= 0, got {value!r}", "tolerances")
        tols[c] = t if isinstance(t, Tolerance) else Tolerance(float(t), AGREEMENT.get(c, Tolerance(0.0)).relative)
    if not isinstance(scene, str) or not scene:
        raise sdk.ParameterError(f"scene: expected a scene name such as {CONFORMANCE_SCENE!r} or a mesh file, got "
                                 f"{scene!r}", "scene")
    if cache_dir is not None and (not isinstance(cache_dir, (str, os.PathLike)) or not os.fspath(cache_dir)):
        raise sdk.ParameterError(f"cache_dir: expected the scene cache's folder path, or None for the default one, got "
                                 f"{cache_dir!r}", "cache_dir")
    from rtp.capture import load_scene

    drawn, _ = load_scene(scene, cache_dir, None, None)  # (SceneError names what is wrong with it)
    if not drawn.spawn_points:
        raise sdk.ParameterError(f"scene: {scene} has no spawn point to move the camera from", "scene")
    scene_name = scene
    name = registry_name or (cls.name if isinstance(cls.name, str) and cls.name else cls.__qualname__)
    run = _Run()
    channels = tuple(c for c in sdk.CHANNELS if c in (cls.supported_channels or ()))
    runs = runnable_models(cls) if channels else ()
    given = None if model is None else _given_model(model, cls)
    drivable = _class_checks(run, cls, registry_name)

    written: list[str] = []
    decisions: dict[str, float] = {}

    def report(not_run: str | None = None) -> ConformanceReport:
        no_image = None
        if image is not None and not written:  # (asked for: say why there is none rather than nothing)
            no_image = (f"{not_run}, so there are no planes to draw" if not_run else "the adapter produced no "
                        f"planes of the shape (channels, {size[1]}, {size[0]}) to draw beside the reference renderer's")
        return ConformanceReport(name, source_text, size, channels, tuple(run.checks), runs, not_run,
                                 written[0] if written else None, scene_name, dict(decisions), no_image)

    if not drivable or not channels:
        return report("the class cannot be driven")
    from rtp.plugins.moderngl import Renderer  # (the reference renderer: only when driven)

    camera, prev_camera = _cameras(drawn)
    w, h = size
    options = dict(frame_source_options or {})

    def open_source() -> FrameSource[Any]:
        return cls.frame_source(drawn, w, h, **options)

    opens = "frame_source opens on the conformance scene"
    try:
        open_source().close()  # (opened to learn whether the engine is there before anything is drawn)
    except ImportError as exc:
        why = f"the {name} adapter's engine is not installed: {exc}"
        for group in ("class", "planes", "agreement", "previous frame", "order", "predictor", "lifecycle"):
            run.skip(group, opens if group == "class" else "driven on the conformance scene", why)
        return report(why)
    except Exception as exc:  # the engine's own error: the adapter cannot be driven
        run.checks.append(Check("class", opens, "failed", f"raised {type(exc).__name__}: {exc}"))
        return report("the frame source did not open")
    run.checks.append(Check("class", opens, "passed"))
    # the reference renderer's frame for the same cameras, drawn while no source of the engine is open: a GL
    # engine's sources then start as in an engine, with their own context the current one
    with Renderer(w, h) as ref:
        ref.load_scene(drawn)
        previous = ref.render(prev_camera)
        reference = ref.render(camera, previous)

    def draw(chans: Sequence[str], source: FrameSource[Any] | None = None) -> np.ndarray:
        own = source is None
        src = open_source() if source is None else source
        try:
            _expect(isinstance(src, FrameSource), f"frame_source returned {type(src).__name__}, not a FrameSource")
            _expect(src.adapter_class is cls and (src.width, src.height) == (w, h),
                    f"frame_source's adapter_class {src.adapter_class!r} and size {src.width}x{src.height}")
            with src.adapter(chans) as a:
                _expect(isinstance(a, cls), f"the source built a {type(a).__name__}, not a {cls.__name__}")
                _expect(a.channels == tuple(chans), f"channels {a.channels}, asked for {tuple(chans)}")
                _expect((a.width, a.height) == (w, h), f"size {a.width}x{a.height}, asked for {w}x{h}")
                return a.inputs(src.frame(camera, prev_camera))
        finally:
            if own:
                src.close()

    x: np.ndarray | None = None
    with run.check("planes", "frame source -> adapter -> inputs, every supported channel"):
        x = draw(channels)
    if x is None:
        for group in ("agreement", "previous frame", "order"):
            run.skip(group, "driven on the conformance scene", "the adapter produced no planes (above)")
    else:
        _plane_checks(run, x, channels, reference, size)
        if isinstance(x, np.ndarray) and x.shape == (len(channels), h, w):
            _agreement_checks(run, x, channels, reference, tols, previous)
            _previous_frame_checks(run, x, channels, reference)
            if image is not None:
                from rtp.capture import save_image

                from ._picture import planes_picture

                save_image(image, planes_picture(x, channels, reference, tols, title=f"adapter {name!r} and the "
                                                 f"reference renderer: {scene_name} at {w}x{h}"))
                written.append(str(image))
            _order_checks(run, x, channels, draw)
    _predictor_checks(run, cls, runs, given, open_source, camera, prev_camera, size, reference, decisions)
    _lifecycle_checks(run, cls, channels, open_source, camera, prev_camera, drew=x is not None)
    return report()


def _order_checks(run: _Run, x: np.ndarray, channels: Sequence[str], draw: Any) -> None:
    if len(channels) < 2:
        run.skip("order", "planes come in the requested order", "the adapter has one channel")
        return
    perm = np.random.default_rng(7).permutation(len(channels))
    if (perm == np.arange(len(channels))).all():
        perm = np.roll(perm, 1)
    shuffled = [channels[i] for i in perm]
    y = None
    with run.check("order", "planes come in the requested order"):
        y = draw(shuffled)
        want = x[[channels.index(c) for c in shuffled]]
        _expect(isinstance(y, np.ndarray) and y.shape == want.shape, "a shuffled channel list gave another shape")
        bad = [c for c, a, b in zip(shuffled, y, want) if not np.allclose(a, b, rtol=1e-6, atol=1e-6)]
        _expect(not bad, f"a shuffled channel list gave other planes for {', '.join(bad)}")
    with run.check("order", "one channel alone is the same plane"):
        one = draw([shuffled[0]])
        _expect(np.allclose(one[0], x[channels.index(shuffled[0])], rtol=1e-6, atol=1e-6),
                f"{shuffled[0]} alone differs from {shuffled[0]} among all the channels")


def _given_model(model: str | Path | sdk.ShadingRatePredictor, cls: type[Adapter[Any]]) -> tuple[str, Any]:
    """``check_adapter``'s ``model=``, loaded and checked against the adapter's channels before any drawing."""
    if isinstance(model, sdk.ShadingRatePredictor):
        label, predictor = "the given model", model
    elif isinstance(model, (str, Path)):
        label, predictor = Path(model).name, sdk.load(model)  # ModelNotFoundError names the shipped ones
    else:
        raise sdk.ParameterError(f"model: expected a model path, a shipped model's name or a ShadingRatePredictor, "
                                 f"got {type(model).__name__}", "model")
    missing = [c for c in predictor.metadata.inputs if c not in cls.supported_channels]
    if missing:
        feeds = ", ".join(m.removesuffix(".onnx") for m in runnable_models(cls)) or "no shipped one"
        raise sdk.ParameterError(f"model: {label} reads {', '.join(missing)}, which the adapter does not declare; "
                                 f"give a model it can feed ({feeds}), or none", "model")
    return label, predictor


def _engine_image(channel: str) -> bool:
    """A channel of the engine's own lit image (``reprojected.*`` and the planes derived from it) or of its
    shading model (:data:`ENGINE_DEFINED`): what an adapter is not compared with the reference renderer on."""
    return channel.startswith("reprojected.") or channel in ENGINE_DEFINED


def _predictor_checks(run: _Run, cls: type[Adapter[Any]], runs: Sequence[str], given: tuple[str, Any] | None,
                      open_source: Any, camera: Camera, prev_camera: Camera, size: tuple[int, int],
                      reference: Any, decisions: dict[str, float]) -> None:
    """``for_predictor`` feeds each model; ``decisions`` gets, per model, the share of tiles whose rate from
    the adapter's planes is the rate from the reference renderer's (the planes of the engine's own lit
    image and shading model, :func:`_engine_image`, stay the adapter's)."""
    w, h = size
    if given is None:
        if not runs:
            run.skip("predictor", "for_predictor feeds a predictor", "no shipped model's inputs are all among the "
                     "adapter's channels; pass model= (rtp adapters check --model) to check with your own")
            return
        predictors = [(m, sdk.load(m)) for m in runs]
    else:
        predictors = [given]
    src = None
    try:
        for label, predictor in predictors:
            with run.check("predictor", f"for_predictor feeds {label}"):
                src = open_source() if src is None else src  # one source (one engine start) for every model
                with cls.for_predictor(predictor, w, h, **src.adapter_options()) as a:
                    _expect(a.channels == predictor.metadata.inputs, f"channels {a.channels}, the model's inputs are "
                            f"{predictor.metadata.inputs}")
                    xa = a.inputs(src.frame(camera, prev_camera))
                    rates = predictor.shading_rates(xa)
                _expect(rates.shape == predictor.tiles(h, w), f"rates of shape {rates.shape}, the tile grid is "
                        f"{predictor.tiles(h, w)}")
                xr = np.stack([plane if _engine_image(c) else reference.channel(c)
                               for c, plane in zip(predictor.metadata.inputs, xa)]).astype(np.float32)
                decisions[label.removesuffix(".onnx")] = float(np.mean(predictor.shading_rates(xr) == rates))
    finally:
        if src is not None:
            src.close()


def _lifecycle_checks(run: _Run, cls: type[Adapter[Any]], channels: Sequence[str], open_source: Any,
                      camera: Camera, prev_camera: Camera, drew: bool = True) -> None:
    """The lifecycle, each check failing for what it names: an error of ``inputs`` on a real frame, which the
    planes checks report (``drew`` False), fails none of them; where every channel drew (``drew``) but the
    two drawn here raise, the check of the source's adapters says so."""
    unsupported = [c for c in sdk.CHANNELS if c not in cls.supported_channels]
    some = list(channels[:2])
    source = None
    with run.check("lifecycle", "with on a frame source returns it and closes it"):
        source = open_source()
        with source as entered:
            _expect(entered is source and not source.closed, "with returned another object, or a closed one")
        _expect(source.closed, "the source is still open after its with block")
    with run.check("lifecycle", "an unknown channel raises UnsupportedChannelError"):
        with open_source() as src:
            try:
                src.adapter(["albedo.q"]).close()
            except UnsupportedChannelError as exc:
                _expect("unknown channel" in str(exc), f"its message does not say 'unknown channel': {exc}")
            else:
                raise _Failed("the adapter took the channel 'albedo.q'")
    if unsupported:
        with run.check("lifecycle", "an undeclared channel raises UnsupportedChannelError"):
            with open_source() as src:
                try:
                    src.adapter([unsupported[0]]).close()
                except UnsupportedChannelError:
                    pass
                else:
                    raise _Failed(f"the adapter took {unsupported[0]!r}, which it does not declare")
    adapter = first = None
    first_error: Exception | None = None
    src = open_source()
    try:
        with run.check("lifecycle", "a foreign frame raises AdapterFrameError"):
            with src.adapter(some) as adapter:
                _expect(not adapter.closed, "a new adapter reports closed")
                try:
                    adapter.inputs(object())
                except AdapterFrameError:
                    pass
                else:
                    raise _Failed("inputs(object()) returned")
                try:  # the planes of a real frame, for the second adapter below: its error is not this check's
                    first = adapter.inputs(src.frame(camera, prev_camera))  # (before 2026-12-07 a wrong shape or a
                except Exception as exc:  # NaN G-buffer failed this check, as if a foreign frame were taken)
                    first_error = exc
        if adapter is not None:
            with run.check("lifecycle", "with closes the adapter; inputs after close raises AdapterClosedError"):
                _expect(adapter.closed, "the adapter is open after its with block")
                try:
                    adapter.inputs(src.frame(camera, prev_camera))
                except AdapterClosedError:
                    pass
                else:
                    raise _Failed("inputs() after close() returned planes")
                adapter.close()  # twice: nothing happens
                try:
                    with adapter:
                        pass
                except AdapterClosedError:
                    pass
                else:
                    raise _Failed("with on a closed adapter entered")
            with run.check("lifecycle", "closing the frame source closes the adapters it built"):
                lent = src.adapter(some)
                if first is not None:
                    again = lent.inputs(src.frame(camera, prev_camera))
                    _expect(np.array_equal(again, first), "a second adapter on the same frame gave other planes")
                src.close()
                _expect(src.closed and lent.closed, "the adapter is still open after its source closed")
                if first_error is not None and drew:  # (where every channel drew: an error of these alone)
                    raise _Failed(f"the source's adapters closed, but inputs() of {', '.join(some)} alone raised "
                                  f"{type(first_error).__name__}: {first_error}")
    finally:
        src.close()
    with run.check("lifecycle", "a closed frame source refuses frame() and adapter()"):
        for call, what in ((lambda: src.frame(camera, prev_camera), "frame()"), (lambda: src.adapter(some), "adapter()")):
            try:
                call()
            except AdapterClosedError:
                pass
            else:
                raise _Failed(f"{what} on a closed source returned")
