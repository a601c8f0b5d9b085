"""The moderngl adapter: a model's input tensor built on the GPU from an engine's own textures.

For an engine that owns its moderngl context::

    from rtp import sdk
    from rtp.plugins.moderngl import Adapter, GBufferTextures

    predictor = sdk.load("jnyang.onnx")
    with Adapter.for_predictor(predictor, width, height, ctx=ctx) as adapter:
        x = adapter.inputs(GBufferTextures(albedo=gbuf_albedo, normal=gbuf_normal, depth=gbuf_depth,
                                           view=V, projection=P, prev_colour=last_frame,
                                           prev_depth=last_depth, prev_view_projection=prev_P @ prev_V,
                                           material=gbuf_material))   # roughness, metallic, specular
        rates = predictor.shading_rates(x)

One fragment shader (``shaders/adapter_fs.glsl``) reprojects the previous frame with a depth test
and packs the requested channels, in the order given, into up to seven RGBA32F targets; only those
are read back (a single flip to the top-left origin, in ``_glio``). Each adapter compiles the shader
for its channel list, so it runs only the work those channels need; when a plane reads other
pixels' lumas (``reprojected.y.dx`` / ``.dy``, the ``.blocks`` and ``.tiles`` planes), a first run of the same
shader writes every pixel's reprojected and albedo luma, and the second fetches them. The reference renderer builds its
``reprojected`` and ``seen`` planes with this very adapter, so captured training inputs and run-time
inputs come from one code path.
"""

from __future__ import annotations

import logging
import threading
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from rtp.sdk import (
    DEFAULT_REPROJECTION_TOLERANCE,
    DEPTH_KINDS,
    MAX_REPROJECTION_TOLERANCE,
    NORMAL_SPACES,
    ParameterError,
    check_projection,
    check_reprojection,
    gbuffers_needed,
)
from rtp.sdk.adapters import Adapter as _AdapterBase
from rtp.sdk.adapters import AdapterFrameError, UnsupportedChannelError

from ._glio import CurrentCheck, is_released, max_texture_side, read_planes, read_texture, warn_not_freed
from ._shaders import load_source

if TYPE_CHECKING:
    from ._source import ReferenceFrameSource

__all__ = ["CHANNEL_IDS", "Adapter", "GBufferTextures"]

log = logging.getLogger("rtp.plugins.moderngl")

#: Channel name -> index into the shader's value table.
CHANNEL_IDS: dict[str, int] = {
    "reprojected.r": 0, "reprojected.g": 1, "reprojected.b": 2, "seen": 3,
    "albedo.r": 4, "albedo.g": 5, "albedo.b": 6,
    "normal.x": 7, "normal.y": 8, "normal.z": 9, "depth": 10,
    "roughness": 11, "metallic": 12, "specular": 13, "depth.edge": 14, "reprojected.y": 15, "albedo.y": 16,
    "reprojected.y.dx": 17, "reprojected.y.dy": 18, "reprojected.y.blocks": 19, "albedo.y.blocks": 20,
    "reprojected.y.tiles": 21, "albedo.y.tiles": 22, "motion.x": 23, "motion.y": 24,
}
_MATERIAL = ("roughness", "metallic", "specular")
_LUMA_PASS = ("reprojected.y", "albedo.y")  # the first pass of adapters whose planes read neighbours' lumas
_MAX_CHANNELS = 28  # seven RGBA float targets (adapter_fs.glsl)
_RGB_TEXTURES = {"albedo": 3, "normal": 3, "prev_colour": 3}  # GBufferTextures fields the shader reads as .rgb


def _mat(m: np.ndarray) -> bytes:
    return np.ascontiguousarray(np.asarray(m, dtype=np.float64).T, dtype=np.float32).tobytes()


def _matrix(value: Any, name: str, *, invertible: bool = False) -> np.ndarray:
    """``value`` as a finite float64 4x4 matrix (finite in float32, the shader's precision), or a
    :class:`ParameterError` naming the field."""
    try:
        m = np.asarray(value)
        ok = m.dtype.kind in "iuf" and m.shape == (4, 4)
        if ok:
            m = m.astype(np.float64)
            with np.errstate(all="ignore"):
                ok = bool(np.isfinite(m.astype(np.float32)).all())
            if ok and invertible:
                with np.errstate(all="ignore"):
                    ok = bool(np.isfinite(np.linalg.inv(m).astype(np.float32)).all())
    except (TypeError, ValueError, OverflowError, np.linalg.LinAlgError):
        ok = False
    if not ok:
        what = "an invertible" if invertible else "a"
        got = f"{m.dtype} {m.shape}" if isinstance(value, np.ndarray) else type(value).__name__
        raise ParameterError(f"{name}: expected {what} finite 4x4 matrix, got {got}", name)
    return m


def _component(value: Any, name: str, lo: int, hi: int) -> int:
    """``value`` as an integer component index in ``[lo, hi)``, else a :class:`ParameterError`."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value < hi:
        raise ParameterError(f"{name}: expected a component index in [{lo}, {hi - 1}], got {value!r}", name)
    return int(value)


@dataclass(frozen=True)
class GBufferTextures:
    """One frame of an engine's moderngl G-buffers: the frame :meth:`Adapter.inputs` reads.

    Textures are live, single-sample ``moderngl.Texture`` objects of the adapter's context (float or
    normalised, not integer), at the adapter's size, with the engine's bottom-left GL origin. Colours,
    albedo and material values are read clamped to [0, 1] (tonemap an HDR frame first; ``Adapter.check``
    reports one). Matrices are 4x4 numpy arrays.

    Attributes:
        albedo: base colour (RGB[A]); display-encoded unless the adapter has ``albedo_linear=True``.
        normal: unit normals (RGB[A]), view space unless the adapter has ``normal_space="world"``.
        depth: depth in component ``depth_component``: linear view depth (0 = background) or, with
            ``depth_kind="window"``, the hardware depth buffer (1 = background), or with
            ``depth_kind="reversed"`` a reversed-Z one (0 = background).
        view, projection: world-to-view and OpenGL view-to-clip of the current camera.
        prev_colour, prev_depth, prev_view_projection: the previous displayed frame, its depth
            and its camera's view-projection; needed for ``reprojected.*`` and ``seen`` (without
            them those planes are 0). The two textures are the previous frame's size, its render
            resolution: the adapter's, or another where dynamic resolution changed it.
        prev_projection: the previous projection when it differs: it linearises a window depth and gives an
            orthographic previous camera's depth (else `projection` does).
        depth_component, prev_depth_component: the component holding depth (e.g. 3 for a
            normal+depth texture).
        material: the material parameters (``roughness``, ``metallic``, ``specular`` channels,
            ``sdk.CHANNELS`` conventions: GGX perceptual roughness, metalness, dielectric specular
            scale with 0.5 = F0 of 4 %); needed only by models with those inputs.
        material_components: the component of ``material`` holding roughness, metallic and
            specular, in that order (default RGB); -1 where the G-buffer has none (specular then
            reads 0.5, the glTF dielectric default, the others 0). A glTF occlusion-roughness-metallic
            texture is ``(1, 2, -1)``.
        motion: the engine's motion vectors (RG: each pixel's previous minus current position in
            this frame's pixels, x right, y down, objects' own motion included), optional: where given, each
            geometry pixel is reprojected from there (``sdk.reproject``'s ``motion``), else the
            camera's move alone places it (a static scene).
        size: ``(width, height)`` of this frame's render resolution where dynamic resolution draws it into
            the bottom-left corner (a viewport at the origin) of larger textures: the current frame's
            textures are then at least that large, the adapter's size at most, and the planes are
            ``(C, height, width)``. None (default): the textures are the adapter's size, and so are the planes.
        prev_size: ``(width, height)`` of the previous frame in the bottom-left corner of ``prev_colour`` and
            ``prev_depth``, at least that large; None (default): their whole size (the two the same).
    """

    albedo: Any
    normal: Any
    depth: Any
    view: np.ndarray
    projection: np.ndarray
    prev_colour: Any = None
    prev_depth: Any = None
    prev_view_projection: np.ndarray | None = None
    prev_projection: np.ndarray | None = None
    depth_component: int = 0
    prev_depth_component: int = 0
    material: Any = None
    material_components: tuple[int, int, int] = (0, 1, 2)
    motion: Any = None
    size: tuple[int, int] | None = None
    prev_size: tuple[int, int] | None = None


def _size(value: Any, name: str) -> tuple[int, int] | None:
    """``value`` (None, or a pair of positive integers) as ``(width, height)``, else a :class:`ParameterError`."""
    if value is None:
        return None
    try:
        ok = len(value) == 2 and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1
                                     for v in value)
    except TypeError:
        ok = False
    if not ok:
        raise ParameterError(f"{name}: expected (width, height) in pixels, two positive integers, got {value!r}", name)
    return int(value[0]), int(value[1])


class Adapter(_AdapterBase[GBufferTextures]):
    """Builds model inputs from G-buffer textures of an engine's moderngl context.

    Args:
        channels: channel names in network order, usually ``predictor.metadata.inputs``.
        width, height: frame size in pixels.
        ctx: the engine's ``moderngl.Context`` (the adapter creates its program and targets in it;
            the context stays the engine's: :meth:`close` frees only the adapter's objects).
        tolerance: relative depth tolerance of the disocclusion test (default 2 %).
        albedo_linear: the albedo texture holds linear values (they are sRGB-encoded to match
            ``sdk.CHANNELS``); default False: display-encoded.
        normal_space: ``"view"`` (default) or ``"world"`` (rotated into view space with ``view``).
        depth_kind: ``"linear"`` (default: view depth in scene units, 0 = background),
            ``"window"`` (the hardware depth buffer in [0, 1], 1 = background; linearised with the
            inverse projection) or ``"reversed"`` (a reversed-Z depth buffer, 1 at the near plane and
            0 on background, as ``glClipControl(GL_LOWER_LEFT, GL_ZERO_TO_ONE)`` with a depth clear of
            0 and ``GL_GREATER`` makes; linearised with the inverse of the OpenGL ``projection`` of the
            same near and far planes): ``sdk.DEPTH_KINDS``. With a depth buffer, a projection
            ``sdk.input_planes`` would not linearise it through (an orthographic one not in OpenGL's
            convention; one whose near plane is behind the camera, where the depth buffer holds points
            behind it) is its ``ParameterError``, whatever the channels.
        clamp_colour: read the previous frame's colour clamped to [0, 1] (default True: display-encoded
            colour, an HDR frame not yet tonemapped kept in range); False passes any value through (the
            reference renderer reprojects pixel coordinates this way: ``Renderer.reprojection_source``).

    The adapter draws in the current GL context, which must be ``ctx`` (it is in an engine of one
    context; with several, make ``ctx`` current first). It never makes ``ctx`` current itself: called from a
    thread where ``ctx`` is not current (another thread holds it), it is a :class:`RendererError` naming the
    thread; hand the context over first (``ctx.__exit__(None, None, None)`` in the thread holding it, then
    ``ctx.__enter__()`` in the calling one). A draw runs with GL's default rasterisation
    state whatever the engine left (blending, culling, depth test, rasterizer discard off, filled polygons),
    binds the frame's textures to units 0-7 (with no sampler object), its program and vertex array, and puts
    back the engine's framebuffer binding, viewport, wireframe and (moderngl's) enable flags, after an
    error in the draw too (docs/adapters.md). Close it (or use it in
    a ``with`` block): an adapter dropped unclosed keeps its GL objects and says so with a
    ``ResourceWarning``.
    """

    name: ClassVar[str] = "moderngl"
    supported_channels: ClassVar[frozenset[str]] = frozenset(CHANNEL_IDS)
    frame_type: ClassVar[type] = GBufferTextures

    def __init__(
        self,
        channels: Iterable[str],
        width: int,
        height: int,
        *,
        ctx: Any,
        tolerance: float = DEFAULT_REPROJECTION_TOLERANCE,
        albedo_linear: bool = False,
        normal_space: str = "view",
        depth_kind: str = "linear",
        clamp_colour: bool = True,
    ) -> None:
        super().__init__(channels, width, height)
        if len(self.channels) > _MAX_CHANNELS:
            raise UnsupportedChannelError(f"at most {_MAX_CHANNELS} channels, got {len(self.channels)}")
        if not isinstance(normal_space, str) or normal_space not in NORMAL_SPACES:
            raise ParameterError(f"normal_space must be one of {', '.join(NORMAL_SPACES)}, got {normal_space!r}",
                                 "normal_space")
        if not isinstance(depth_kind, str) or depth_kind not in DEPTH_KINDS:
            raise ParameterError(f"depth_kind must be one of {', '.join(DEPTH_KINDS)}, got {depth_kind!r}",
                                 "depth_kind")
        number = isinstance(tolerance, (int, float, np.integer, np.floating)) and not isinstance(tolerance, bool)
        # (the SDK's range, as sdk.input_planes and check_gbuffers take it: above 1 the GPU reprojected what the CPU
        # reference, and this adapter's own check(), refused)
        if not number or not 0.0 <= tolerance <= MAX_REPROJECTION_TOLERANCE:
            raise ParameterError(f"tolerance: expected a relative depth tolerance in [0, {MAX_REPROJECTION_TOLERANCE:g}] "
                                 f"(sdk.MAX_REPROJECTION_TOLERANCE), got {tolerance!r}", "tolerance")
        for flag, value in (("albedo_linear", albedo_linear), ("clamp_colour", clamp_colour)):
            if not isinstance(value, (bool, np.bool_)):
                raise ParameterError(f"{flag}: expected True or False, got {value!r}", flag)
        if is_released(ctx):
            raise AdapterFrameError("ctx: this moderngl context has been released; pass the engine's live one")
        if not callable(getattr(ctx, "program", None)) or not hasattr(ctx, "info"):
            raise AdapterFrameError(f"ctx must be the engine's moderngl.Context, got {type(ctx).__name__}")
        import moderngl

        limit = max_texture_side(ctx)
        if max(self.width, self.height) > limit:
            raise ParameterError(f"frame size: this OpenGL context draws at most {limit} pixels a side "
                                 f"(GL_MAX_TEXTURE_SIZE), got {self.width}x{self.height}", "size")
        self.ctx = ctx
        self.tolerance = float(tolerance)
        self.normal_space, self.depth_kind = normal_space, depth_kind  # (what check() tells check_gbuffers)
        ids = [CHANNEL_IDS[c] for c in self.channels] + [-1] * (_MAX_CHANNELS - len(self.channels))
        wanted = set(self.channels)
        flags = {  # compiled in (adapter_fs.glsl): the shader keeps only the work these channels need
            "RTP_ALBEDO_LINEAR": albedo_linear, "RTP_CLAMP_COLOUR": clamp_colour, "RTP_NORMAL_WORLD": normal_space == "world",
            "RTP_DEPTH_WINDOW": depth_kind != "linear", "RTP_DEPTH_REVERSED": depth_kind == "reversed",
            "RTP_DIFFERENCES": bool({"reprojected.y.dx", "reprojected.y.dy"} & wanted),
            "RTP_BLOCKS_REPROJECTED": "reprojected.y.blocks" in wanted,
            "RTP_BLOCKS_ALBEDO": "albedo.y.blocks" in wanted,
            "RTP_TILES_REPROJECTED": "reprojected.y.tiles" in wanted,
            "RTP_TILES_ALBEDO": "albedo.y.tiles" in wanted,
        }
        # Planes that read other pixels' lumas (.dx / .dy, .blocks, .tiles) take them from a first pass that
        # writes every pixel's reprojected and albedo luma, instead of reprojecting each neighbour again.
        self._luma: Adapter | None = None
        self._framebuffer_zero: Any = None
        # Whether the engine's context is the one current in the calling thread, read back where a call comes from
        # another thread than the last (_glio.CurrentCheck): made current in no thread (EGL refuses a context another
        # thread holds, and moderngl's ctx.__enter__() does not say so), the draw ran in no context and inputs()
        # returned zeros or garbage planes, in silence.
        self._current: CurrentCheck | None = None
        try:
            self._build(ids, flags, tolerance, albedo_linear, normal_space, depth_kind, clamp_colour, moderngl)
        except BaseException:  # (a shader that did not compile, no room for the targets: the caller never gets the
            self.close()       # adapter, so what it made so far is freed here; close() marks it closed, unwarned)
            raise

    def _build(self, ids: list[int], flags: dict[str, bool], tolerance: float, albedo_linear: bool, normal_space: str,
               depth_kind: str, clamp_colour: bool, moderngl: Any) -> None:
        """The constructor's GL part: the first pass (where wanted), the program for the channels, the targets."""
        ctx, width, height = self.ctx, self.width, self.height
        self._current = CurrentCheck(
            ctx, "Adapter", "is not current",
            "The adapter draws in the context current in the calling thread and never makes it current itself: call "
            "it from the thread where the engine's context is current, or hand the context over (ctx.__exit__(None, "
            "None, None) in that thread, then ctx.__enter__() in this one, before the call)")
        if any(flags[f] for f in ("RTP_DIFFERENCES", "RTP_BLOCKS_REPROJECTED", "RTP_BLOCKS_ALBEDO",
                                  "RTP_TILES_REPROJECTED", "RTP_TILES_ALBEDO")):
            self._luma = Adapter(_LUMA_PASS, width, height, ctx=ctx, tolerance=tolerance, albedo_linear=albedo_linear,
                                 normal_space=normal_space, depth_kind=depth_kind, clamp_colour=clamp_colour)
            self._luma.__dict__["_first_pass"] = True  # (closed with this one: its own unclosed warning would say it twice)
        flags["RTP_LUMA_PASS"] = self._luma is not None
        defines: dict[str, Any] = {k: str(bool(v)).lower() for k, v in flags.items()}
        defines.update(RTP_CHANNELS=", ".join(map(str, ids)), RTP_COUNT=len(self.channels))
        self._prog = ctx.program(vertex_shader=load_source("fullscreen_vs.glsl"),
                                 fragment_shader=load_source("adapter_fs.glsl", defines))
        self._vao = ctx.vertex_array(self._prog, [])
        n_targets = -(-len(self.channels) // 4)
        self._targets: list[Any] = []
        for _ in range(n_targets):  # (one by one: a failure part-way frees the ones made)
            self._targets.append(ctx.texture((self.width, self.height), 4, dtype="f4"))
            self._targets[-1].filter = (moderngl.NEAREST, moderngl.NEAREST)
        self._fbo = ctx.framebuffer(color_attachments=self._targets)
        self._region_drawn = (self.width, self.height)  # (the size of the last run's planes)

    def _set(self, name: str, value: Any) -> None:
        u = self._prog.get(name, None)  # the GLSL compiler drops uniforms a program does not use
        if u is None:
            return
        if isinstance(value, np.ndarray) and value.shape == (4, 4):
            u.write(_mat(value))
        elif isinstance(value, list):
            u.write(np.asarray(value, dtype=np.int32).tobytes())
        else:
            u.value = value

    def run(
        self,
        *,
        albedo: Any,
        normal: Any,
        depth: Any,
        view: np.ndarray,
        projection: np.ndarray,
        prev_colour: Any = None,
        prev_depth: Any = None,
        prev_view_projection: np.ndarray | None = None,
        prev_projection: np.ndarray | None = None,
        depth_component: int = 0,
        prev_depth_component: int = 0,
        material: Any = None,
        material_components: tuple[int, int, int] = (0, 1, 2),
        motion: Any = None,
        size: tuple[int, int] | None = None,
        prev_size: tuple[int, int] | None = None,
    ) -> None:
        """Render the input planes into the adapter's targets without reading them back (the
        reference renderer's path; the keyword arguments are the fields of :class:`GBufferTextures`)."""
        self._check_live()
        has_prev = prev_colour is not None
        if has_prev and (prev_depth is None or prev_view_projection is None):
            raise ParameterError("prev_colour needs prev_depth and prev_view_projection as well", "prev_colour")
        region, prev_region = self._check_textures(
            {"albedo": albedo, "normal": normal, "depth": depth, "prev_colour": prev_colour, "prev_depth": prev_depth,
             "material": material, "motion": motion}, size, prev_size)
        view = _matrix(view, "view", invertible=True)
        projection = check_projection(_matrix(projection, "projection", invertible=True), "projection")
        if prev_view_projection is not None:
            prev_view_projection = _matrix(prev_view_projection, "prev_view_projection")
        if prev_projection is not None:
            prev_projection = check_projection(_matrix(prev_projection, "prev_projection", invertible=True),
                                               "prev_projection")
        kinds = ("perspective", "perspective")  # (the shader's reprojection reads them only with a previous frame)
        if has_prev and "prev_view_projection" in gbuffers_needed(self.channels):
            kinds = check_reprojection(projection, prev_view_projection, prev_projection)
        for c, tex, name in ((depth_component, depth, "depth_component"),
                             (prev_depth_component, prev_depth, "prev_depth_component")):
            _component(c, name, 0, 4 if tex is None else tex.components)
        if self.depth_kind != "linear":  # a depth buffer is linearised through them, as in sdk.input_planes
            self._check_depth_buffer(depth, projection, "projection", region, depth_component)
            if has_prev and "prev_depth" in gbuffers_needed(self.channels):
                prev_name = "projection" if prev_projection is None else "prev_projection"
                self._check_depth_buffer(prev_depth, projection if prev_projection is None else prev_projection,
                                         prev_name, prev_region, prev_depth_component)
        wanted = [c for c in self.channels if c in _MATERIAL]
        if wanted and material is None:
            raise ParameterError(f"the inputs {wanted} need the material texture (GBufferTextures.material: "
                                 "roughness, metallic, specular)", "material")
        try:
            comps = tuple(material_components)
        except TypeError:
            comps = ()
        n_material = 4 if material is None else material.components
        if len(comps) != 3:
            raise ParameterError(f"material_components: expected three component indices of the material texture "
                                 f"(or -1), got {material_components!r}", "material_components")
        comps = tuple(_component(c, "material_components", -1, n_material) for c in comps)
        if self._luma is not None:  # first pass: every pixel's lumas, read by the second
            self._luma.run(albedo=albedo, normal=normal, depth=depth, view=view, projection=projection,
                           prev_colour=prev_colour, prev_depth=prev_depth, prev_view_projection=prev_view_projection,
                           prev_projection=prev_projection, depth_component=depth_component,
                           prev_depth_component=prev_depth_component, motion=motion, size=size, prev_size=prev_size)
        textures = {"u_albedo": albedo, "u_normal": normal, "u_depth": depth,
                    "u_prev_colour": prev_colour if has_prev else albedo,
                    "u_prev_depth": prev_depth if has_prev else depth,
                    "u_material": material if material is not None else albedo,
                    "u_motion": motion if motion is not None else albedo}
        if self._luma is not None:
            textures["u_luma"] = self._luma._targets[0]
        for loc, (name, tex) in enumerate(textures.items()):
            tex.use(location=loc)
            self._set(name, loc)
        self._set("u_has_prev", has_prev)
        self._set("u_has_material", material is not None)
        self._set("u_has_motion", motion is not None)
        self._set("u_material_comp", comps)
        self._set("u_depth_comp", int(depth_component))
        self._set("u_prev_depth_comp", int(prev_depth_component))
        self._set("u_tolerance", self.tolerance)
        self._set("u_view", view)
        self._set("u_inv_view", np.linalg.inv(view))
        self._set("u_inv_proj", np.linalg.inv(projection))
        self._set("u_prev_inv_proj", np.linalg.inv(projection if prev_projection is None else prev_projection))
        self._set("u_prev_vp", np.eye(4) if prev_view_projection is None else np.asarray(prev_view_projection))
        self._set("u_size", (float(region[0]), float(region[1])))
        self._set("u_prev_size", (float(region[0]), float(region[1])) if prev_region is None
                  else (float(prev_region[0]), float(prev_region[1])))
        self._set("u_ortho", kinds[0] == "orthographic")
        self._set("u_prev_ortho", kinds[1] == "orthographic")
        self._fbo.viewport = (0, 0, *region)  # (the planes in the targets' bottom-left corner, as the G-buffers)
        self._region_drawn = region
        # The engine's framebuffer binding and viewport are put back after the draw (its next clear or draw goes
        # where it went before), and a depth texture's comparison mode is off while the shader reads its depth
        # (texelFetch on a comparing sampler2D is undefined in GLSL; moderngl's depth textures compare by default;
        # a sampler object bound to the unit overrides the texture's mode, so units 0-7 are left with none).
        # The draw's rasterisation is GL's default whatever the engine left: its enable flags (blending, culling,
        # a depth test, rasterizer discard) are off for the draw through a moderngl scope, which puts back the
        # flags moderngl tracks after it, and wireframe is off and put back (blending ONE, ONE added every
        # draw to the last one's planes; clockwise front faces culled the full-screen triangle, so did wireframe
        # and rasterizer discard, leaving the last frame's planes or zeros).
        import moderngl

        ctx = self.ctx
        bound, viewport, wireframe = ctx.fbo, ctx.viewport, ctx.wireframe
        if bound is None or is_released(bound):  # (the scope puts back the framebuffer bound when it is made)
            bound = self._default_framebuffer()
            bound.use()
        comparing = [(t, t.compare_func) for t in {id(t): t for t in textures.values()}.values()
                     if getattr(t, "depth", False) and t.compare_func]
        scope = None
        try:
            for t, _ in comparing:
                t.compare_func = ""
            ctx.clear_samplers(0, len(textures))
            ctx.wireframe = False
            scope = ctx.scope(self._fbo, enable_only=moderngl.NOTHING)
            with scope:  # (binds the adapter's framebuffer; on leaving, the engine's flags and framebuffer)
                self._vao.render(vertices=3)
        finally:
            if scope is not None:
                scope.release()
            ctx.wireframe = wireframe
            for t, func in comparing:
                t.compare_func = func
            bound.use()
            ctx.viewport = viewport

    def _check_depth_buffer(self, tex: Any, projection: np.ndarray, name: str, region: tuple[int, int] | None,
                            component: int) -> None:
        """What ``sdk.input_planes`` refuses of a depth buffer (``depth_kind`` ``window`` or ``reversed``) linearised
        through ``projection`` (named ``name``), refused here too: a projection neither a perspective nor an
        orthographic one of OpenGL's convention (a left-handed, reversed-Z or row-vector orthographic one gave wrong
        or negative depth, every pixel then background), and, through an orthographic projection whose near plane is
        behind the camera (glOrtho's near -1), points behind it (negative depth, taken as background). Only for such a
        projection is the depth texture read back (``region``, its ``component``), to find the points."""
        m = check_projection(projection, name, depth_kind=self.depth_kind)  # (a perspective or an orthographic one)
        if abs(m[3, 2]) > abs(m[3, 3]):
            return  # (a perspective's depth buffer holds no point behind its camera)
        inv = np.linalg.inv(m)  # (invertible: check_projection's orthographic checks invert it)
        near = inv @ np.array([0.0, 0.0, -1.0, 1.0])  # the view point of the near plane's depth (window 0, reversed 1)
        if -near[2] / near[3] < 0.0:
            raw = read_texture(tex, size=region)[..., component]
            check_projection(projection, name, depth_kind=self.depth_kind, depth=raw)

    def _default_framebuffer(self) -> Any:
        """The context's framebuffer 0 (what a standalone context has bound before anything is used)."""
        if self._framebuffer_zero is None:
            self._framebuffer_zero = self.ctx.detect_framebuffer(0)
        return self._framebuffer_zero

    def _check_live(self) -> None:
        """:meth:`_check_open`, the engine's context not released under the adapter, and current in this thread (checked
        where the call comes from another thread than the last)."""
        self._check_open()
        if is_released(self.ctx):
            raise AdapterFrameError("ctx: the engine's moderngl context was released under this adapter; build a new "
                                    "adapter in the live context")
        current = self._current
        if current is not None and threading.get_ident() != current.thread:  # (one comparison in the same thread)
            current()

    def _region(self, size: Any) -> tuple[int, int]:
        """``(width, height)`` of a frame whose :class:`GBufferTextures` ``size`` is ``size``: the adapter's size where
        None, else that one, at most the adapter's (its targets)."""
        region = _size(size, "size")
        if region is None:
            return self.width, self.height
        if region[0] > self.width or region[1] > self.height:
            raise ParameterError(f"size: this frame's render resolution {region[0]}x{region[1]} is larger than the "
                                 f"adapter's {self.width}x{self.height}: build the adapter at the largest one", "size")
        return region

    def frame_size(self, frame: GBufferTextures) -> tuple[int, int]:
        """``(width, height)`` of the planes :meth:`inputs` returns for ``frame``: its ``size``, else the
        adapter's."""
        return self._region(getattr(frame, "size", None))

    def _check_textures(self, textures: dict[str, Any], size: Any,
                        prev_size: Any) -> tuple[tuple[int, int], tuple[int, int] | None]:
        """Check a frame's ``textures`` (the :class:`GBufferTextures` fields by name; ``albedo``, ``normal`` and
        ``depth`` required where given) and return its region and its previous frame's (None without one):
        ``size``, else the adapter's size; ``prev_size``, else ``prev_depth``'s (as dynamic resolution leaves
        it)."""
        import moderngl

        region = self._region(size)
        prev_region = _size(prev_size, "prev_size")
        prev_depth = textures.get("prev_depth")
        if prev_region is None and textures.get("prev_colour") is not None and isinstance(prev_depth, moderngl.Texture):
            prev_region = tuple(prev_depth.size)
        for name, tex in textures.items():
            if tex is None and name in ("albedo", "normal", "depth"):
                raise ParameterError(f"{name}: expected a moderngl.Texture of the adapter's context, got None", name)
            prev = name in ("prev_colour", "prev_depth")
            self._check_texture(tex, name, _RGB_TEXTURES.get(name, 2 if name == "motion" else 1),
                                prev_region if prev else (None if size is None else region),
                                corner=(prev_size if prev else size) is not None)
        return region, prev_region

    def _check_texture(self, tex: Any, name: str, components: int = 1, size: tuple[int, int] | None = None, *,
                       corner: bool = False) -> None:
        """``tex``, unless None, is a moderngl texture of the adapter's size (one frame of its G-buffers), or of
        ``size`` (``(width, height)``: the previous frame's), or with ``corner`` at least ``size`` (a frame of that
        size in its bottom-left corner), with at least ``components`` components."""
        if tex is None:
            return
        import moderngl

        if not isinstance(tex, moderngl.Texture):
            raise ParameterError(f"{name}: expected a moderngl.Texture of the adapter's context, got "
                                 f"{type(tex).__name__}", name)
        if is_released(tex):
            raise ParameterError(f"{name}: this texture has been released; pass the frame's live texture", name)
        if getattr(tex, "ctx", self.ctx) is not self.ctx:
            raise ParameterError(f"{name}: expected a texture of the adapter's context, got one of another "
                                 "moderngl.Context (an adapter reads only textures of the ctx it was built with)", name)
        if tex.samples:
            raise ParameterError(f"{name}: expected a single-sample texture, got a multisample one ({tex.samples} "
                                 "samples): resolve it first (ctx.copy_framebuffer into a single-sample texture)", name)
        if tex.dtype[0] in "ui":
            raise ParameterError(f"{name}: expected a float or normalised texture (dtype f1, f2, f4, nu1, nu2, ni1, "
                                 f"ni2), got the integer dtype {tex.dtype!r} (its bits would be read as floats)", name)
        field = "prev_size" if name.startswith("prev_") else "size"
        if corner and size is not None and (tex.size[0] < size[0] or tex.size[1] < size[1]):
            raise ParameterError(f"{name}: expected a texture at least {field} {size[0]}x{size[1]} (the frame in its "
                                 f"bottom-left corner), got {tex.size[0]}x{tex.size[1]}", name)
        if not corner and size is not None and tuple(tex.size) != size:
            raise ParameterError(f"{name}: expected a texture of prev_depth's size {size[0]}x{size[1]} (the previous "
                                 f"frame's render resolution; prev_size for a frame in their corner), got "
                                 f"{tex.size[0]}x{tex.size[1]}", name)
        if size is None and tuple(tex.size) != (self.width, self.height):
            raise ParameterError(f"{name}: expected a texture of the adapter's size {self.width}x{self.height}, got "
                                 f"{tex.size[0]}x{tex.size[1]} (a frame of a lower render resolution in the corner of "
                                 "larger textures: GBufferTextures.size)", name)
        if tex.components < components:
            raise ParameterError(f"{name}: expected a texture of at least {components} components (RGB[A]), got "
                                 f"{tex.components} (the shader reads .rgb: a depth or two-component texture here "
                                 "would be read as a colour or a normal)", name)

    def inputs(self, frame: GBufferTextures) -> np.ndarray:
        """The model's input planes for ``frame``: float32 ``(C, H, W)``, top-left origin, channels
        in order. Without a previous frame in ``frame`` the reprojected channels and ``seen`` are 0."""
        self.run(**{f.name: getattr(frame, f.name) for f in fields(frame)})
        return read_planes(self._fbo, len(self.channels), self._region_drawn)

    def check(self, frame: GBufferTextures) -> list[str]:
        """``sdk.check_gbuffers`` on ``frame``'s textures read back, with this adapter's ``normal_space``,
        ``depth_kind`` and ``tolerance``: what in the engine's G-buffers looks like a convention mistake
        (world-space normals given as view-space, encoded normals, a row-vector or left-handed view, a
        depth buffer given as linear depth, a previous frame that does not reproject), each a warning
        naming the likely cause; empty where none is seen. It reads every texture back: run it once,
        where the engine is wired up, not every frame. Values no G-buffer can hold (NaN depth, a colour
        outside [0, 1]) are errors, not warnings: :class:`rtp.sdk.ParameterError`, as ``sdk.check_gbuffers``."""
        self._check_live()
        if not isinstance(frame, GBufferTextures):
            raise AdapterFrameError(f"expected a GBufferTextures frame, got {type(frame).__name__}")
        region, prev_region = self._check_textures(
            {name: getattr(frame, name) for name in ("normal", "depth", "prev_colour", "prev_depth", "motion")},
            frame.size, frame.prev_size)
        for c, tex, name in ((frame.depth_component, frame.depth, "depth_component"),
                             (frame.prev_depth_component, frame.prev_depth, "prev_depth_component")):
            _component(c, name, 0, 4 if tex is None else tex.components)
        g: dict[str, Any] = {"depth": read_texture(frame.depth, size=region)[..., frame.depth_component],
                             "normal": read_texture(frame.normal, 3, region), "view": frame.view,
                             "projection": frame.projection}
        if frame.prev_colour is not None and frame.prev_depth is not None:
            g.update(prev_colour=read_texture(frame.prev_colour, 3, prev_region),
                     prev_depth=read_texture(frame.prev_depth, size=prev_region)[..., frame.prev_depth_component],
                     prev_view_projection=frame.prev_view_projection, prev_projection=frame.prev_projection)
        if frame.motion is not None:
            g["motion"] = read_texture(frame.motion, 2, region)
        from rtp.sdk import check_gbuffers

        return check_gbuffers(**g, tolerance=self.tolerance, normal_space=self.normal_space,
                              depth_kind=self.depth_kind)

    def read(self, index: int) -> np.ndarray:
        """Plane ``index`` of the last :meth:`run`, ``(H, W)`` float32 (reads back one target; the last frame's
        ``size``)."""
        self._check_live()
        index = _component(index, "index", 0, len(self.channels))
        return read_texture(self._targets[index // 4], size=self._region_drawn)[..., index % 4]

    def close(self) -> None:
        """Free the adapter's program, targets and framebuffer (not the engine's context; where the engine
        released its context first, they went with it). In a thread where the context is not current (another
        thread holds it, or another context is current here) nothing is freed: a warning says so, and the adapter
        is closed all the same (close it where the context is current, or make it current first)."""
        made = self.__dict__  # (a constructor that failed part-way closes what it made so far)
        current = made.get("_current")  # (None: the constructor failed before it made anything)
        here = not is_released(self.ctx) and (current is None or current.holds())
        if not here and not is_released(self.ctx) and not made.get("_quiet_close"):
            # (freed here, they were the same names in whatever context is current in this thread: an engine's own
            # textures and buffers deleted under it, in silence)
            warn_not_freed(f"an rtp moderngl Adapter ({self.width}x{self.height}, {len(self.channels)} channels)",
                           "GL program, targets and framebuffer",
                           "Close the adapter in the thread where its context is current, or make the context "
                           "current there first (ctx.__enter__(), after ctx.__exit__(None, None, None) in the thread "
                           "holding it)")
        if here:
            fbo = made.get("_fbo")
            if fbo is not None and self.ctx.fbo is fbo:  # (a framebuffer deleted while bound leaves GL none to draw into)
                self._default_framebuffer().use()
            for obj in (fbo, *made.get("_targets", ()), made.get("_vao"), made.get("_prog"), made.get("_current")):
                if obj is not None:
                    obj.release()
        if self._luma is not None:
            self._luma.__dict__["_quiet_close"] = True  # (said with this one's warning, where it was not freed)
            self._luma.close()

    def __del__(self) -> None:
        # moderngl frees nothing a Python object held (its objects live until released, in the engine's context, which
        # need not be current when Python collects this one): an adapter dropped unclosed keeps its program and
        # targets, so it says so, as an unclosed file does
        if "_prog" in self.__dict__ and not self.closed and not self.__dict__.get("_first_pass"):
            warnings.warn(f"an unclosed rtp moderngl Adapter ({self.width}x{self.height}, {len(self.channels)} "
                          "channels) keeps its GL program and targets in the engine's context until the context "
                          "goes: close() it, or use it in a with block", ResourceWarning, stacklevel=2)

    @classmethod
    def frame_source(cls, scene: Any, width: int, height: int, **options: Any) -> ReferenceFrameSource:
        """The reference renderer drawing ``scene`` (an :class:`rtp.scene.Scene`), handing over its
        G-buffers as :class:`GBufferTextures`; ``options`` go to :class:`Renderer` (``ctx=`` to
        borrow a context). See :class:`rtp.plugins.moderngl.ReferenceFrameSource`."""
        from ._source import ReferenceFrameSource

        return ReferenceFrameSource(cls, scene, width, height, **options)
