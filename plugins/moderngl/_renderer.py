"""The reference deferred renderer with software variable-rate shading (moderngl, headless EGL).

One :meth:`Renderer.render` call draws one frame:

1. sun shadow map (one orthographic map fitted to the view frustum inside the scene bounds),
2. G-buffer MRT pass,
3. SSAO (full rate) and its 4x4 blur,
4. deferred lighting at full rate (GGX sun + point lights + hemisphere ambient x AO + emissive),
5. auto-exposure: log-average luminance of the 1x1 HDR image, computed once and shared,
6. per shading rate (``1x1 ... 4x4``): gather the lighting of each block's shading sample (the
   software VRS emulation), tone map (ACES) and sRGB-encode at full rate, then FXAA at full rate,
7. reprojection of the previous frame's final 1x1 colour with a disocclusion test.

Everything comes back as float32 numpy arrays with a top-left origin (:class:`Frame`).
See ``docs/renderer.md`` for the definitions and the measured timings.
"""

from __future__ import annotations

import logging
import math
import numbers
import threading
import time
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any

import numpy as np

from rtp.scene import Camera, Scene
from rtp.sdk import (
    ALL_RATES,
    DEFAULT_REPROJECTION_TOLERANCE,
    MAX_REPROJECTION_TOLERANCE,
    RATE_CODES,
    ParameterError,
    RtpError,
    block_variances,
    depth_edges,
    luma,
    pixel_differences,
    rate_size,
    tile_grid,
    tile_variances,
)
from rtp.sdk.adapters import UnsupportedChannelError

from ._adapter import Adapter
from ._glio import CurrentCheck, is_released, max_texture_side, read_texture, warn_not_freed, write_texture
from ._shaders import load_source

__all__ = ["Frame", "RenderResult", "Renderer", "RendererError", "create_context"]

logger = logging.getLogger("rtp.plugins.moderngl")

_EGL_FIX = "apt-get install libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri"
_GL_SRGB8_ALPHA8 = 0x8C43


class RendererError(RtpError, RuntimeError):
    """The renderer cannot run: no GL context, a shader failed to build, a malformed scene, ..."""


def _import_moderngl() -> Any:
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            "the rtp reference renderer needs moderngl; install the extra: pip install 'rtp[moderngl]'"
        ) from exc
    return moderngl


def create_context(require: int = 330) -> Any:
    """Create a headless moderngl context through EGL (Mesa llvmpipe works; no display needed).

    Raises :class:`RendererError` naming the packages to install when EGL is unavailable, and
    :class:`rtp.sdk.ParameterError` when ``require`` is not an OpenGL version such as 330 or 430.
    """
    if not isinstance(require, numbers.Integral) or isinstance(require, bool) or not 100 <= int(require) <= 999:
        raise ParameterError(f"require: expected an OpenGL version as an integer such as 330 or 430, got {require!r}",
                             "require")
    require = int(require)
    moderngl = _import_moderngl()
    try:
        return moderngl.create_standalone_context(backend="egl", require=require)
    except Exception as exc:
        raise RendererError(
            f"could not create a headless OpenGL {require // 100}.{require % 100 // 10} context through EGL "
            f"({type(exc).__name__}: {exc}). Install Mesa's EGL and GL drivers, e.g. `{_EGL_FIX}` on "
            "Debian/Ubuntu; GLCONTEXT_LINUX_LIBEGL / GLCONTEXT_LINUX_LIBGL override the library paths."
        ) from exc


def _default_shadow_map_size(width: int, height: int) -> int:
    """The sun shadow map's side a renderer of ``width`` x ``height`` draws by default: 1024 for frames up to
    1024 pixels a side, 2048 above; a small frame (a side of at most 128 pixels) the smallest power of two of
    at least 4 texels per pixel of its longer side, and 256 at least. A 64 x 48 frame with a 1024² map spent
    nine tenths of its drawing on shadow texels it could not show (llvmpipe: 150 ms a frame against 40)."""
    side = max(int(width), int(height))
    if side > 1024:
        return 2048
    size = 256
    while size < min(4 * side, 1024):
        size *= 2
    return size


def _floats(values: Any, n: int) -> Any:
    """``n`` floats as a tuple (a material's colour factors as the GPU record holds them)."""
    out = tuple(float(v) for v in values)
    if len(out) != n:
        raise RendererError(f"expected {n} colour components, got {len(out)}: {values!r}")
    return out


def _check_ctx(ctx: Any) -> Any:
    """``ctx`` when it is a moderngl context (what ``create_context`` returns), else a :class:`RendererError`."""
    if not all(callable(getattr(ctx, name, None)) for name in ("program", "texture", "framebuffer")) \
            or not isinstance(getattr(ctx, "version_code", None), int):
        raise RendererError(f"ctx: expected a moderngl.Context, got {type(ctx).__name__}")
    if is_released(ctx):
        raise RendererError("ctx: this moderngl context has been released; pass a live one (or none: the renderer "
                            "then makes its own)")
    return ctx


def _image(value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``value`` as a finite float32 array of ``shape``, or a :class:`RendererError` naming ``what``."""
    try:
        a = np.asarray(value)
        ok = a.dtype.kind in "biuf"
        if ok:
            a = a.astype(np.float32, copy=False)
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok or a.shape != shape:
        got = f"{a.dtype} {a.shape}" if ok or isinstance(value, np.ndarray) else type(value).__name__
        raise RendererError(f"{what}: expected a real array of shape {shape}, got {got}")
    if not np.isfinite(a).all():
        raise RendererError(f"{what}: expected finite values, got NaN or infinity")
    return a


def _check_camera(camera: Any, what: str) -> Camera:
    if not isinstance(camera, Camera):
        raise RendererError(f"{what}: expected an rtp.scene.Camera, got {type(camera).__name__}")
    return camera


def _same_view(a: Camera, b: Camera, width: int, height: int) -> bool:
    """Whether cameras ``a`` and ``b`` draw the same frame (the same view and projection; compared by their
    matrices: a position given as an array makes the dataclass's ``==`` ambiguous)."""
    return a is b or bool(np.array_equal(a.view_projection(width, height), b.view_projection(width, height)))


def _check_flag(value: Any, what: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise RendererError(f"{what}: expected True or False, got {value!r}")
    return bool(value)


@dataclass(eq=False)
class Frame:
    """One rendered frame. Every image is float32, row-major ``(H, W[, C])``, top-left origin.

    G-buffer (background pixels are 0 unless stated):

    * ``albedo`` ``(H, W, 3)``: base colour, display-encoded sRGB in [0, 1].
    * ``normal`` ``(H, W, 3)``: unit view-space normal (right-handed, camera looks down -Z;
      ``z > 0`` faces the camera; back faces are shaded two-sided with the flipped normal).
    * ``roughness``, ``metallic``, ``specular`` ``(H, W)``: material parameters in [0, 1]
      (``specular`` 0.5 = F0 of 4 %).
    * ``emissive`` ``(H, W)``: emissive luminance, clamped to [0, 1] and display-encoded.
    * ``depth`` ``(H, W)``: linear depth, metres along -Z.
    * ``shadow`` ``(H, W)``: sun shadow-map visibility (PCF), 1 = lit.
    * ``motion`` ``(H, W, 2)``: pixels, previous minus current position, x right, y down; 0 without
      a previous camera, on background and where the point was behind the previous camera.
    * ``mask`` ``(H, W)``: coverage, 1 on geometry, 0 on background (sky).
    * ``ao`` ``(H, W)``: the SSAO term applied to the ambient light (1 = unoccluded, 1 on background).

    Shading:

    * ``colour``: rate name (``"1x1"``, ``"1x2"``, ... ``"4x4"``) to the final ``(H, W, 3)`` image,
      display-encoded sRGB in [0, 1], after tone mapping and FXAA.
    * ``lighting``: only with ``render(..., debug=True)``: rate name to the linear HDR ``(H, W, 3)``
      image before post-processing (the software-VRS output: constant over each aligned block
      whose shading sample is geometry).
    * ``exposure``: the exposure multiplier all rates used; ``log_avg_luminance``: what it came from.

    Temporal:

    * ``reprojected`` ``(H, W, 3)``: the previous frame's final 1x1 colour fetched (nearest texel)
      where each pixel was in the previous frame; 0 where unseen or without a previous frame.
    * ``seen`` ``(H, W)``: 1 where that position was on screen and passed the depth test, else 0.
    """

    camera: Camera
    prev_camera: Camera | None
    albedo: np.ndarray
    normal: np.ndarray
    roughness: np.ndarray
    metallic: np.ndarray
    specular: np.ndarray
    emissive: np.ndarray
    depth: np.ndarray
    shadow: np.ndarray
    motion: np.ndarray
    mask: np.ndarray
    ao: np.ndarray
    colour: dict[str, np.ndarray]
    reprojected: np.ndarray
    seen: np.ndarray
    exposure: float
    log_avg_luminance: float
    lighting: dict[str, np.ndarray] | None = None
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def width(self) -> int:
        return int(self.depth.shape[1])

    @property
    def height(self) -> int:
        return int(self.depth.shape[0])

    def channel(self, name: str) -> np.ndarray:
        """One ``(H, W)`` plane by its ``rtp.sdk`` channel name (``"albedo.r"``, ``"normal.z"``,
        ``"seen"``, ``"reprojected.g"``, ``"motion.x"``, ``"depth"``, ``"depth.edge"``, ``"reprojected.y.dx"``, ...)."""
        if not isinstance(name, str):
            raise UnsupportedChannelError(f"channel: expected a channel name (str), got {type(name).__name__}")
        if name == "depth.edge":
            return depth_edges(self.depth)
        if name in ("reprojected.y.dx", "reprojected.y.dy"):
            return pixel_differences(luma(self.reprojected))[name.endswith(".dy")]
        if name in ("reprojected.y.blocks", "albedo.y.blocks"):
            return block_variances(luma(self.reprojected if name.startswith("r") else self.albedo))
        if name in ("reprojected.y.tiles", "albedo.y.tiles"):
            return tile_variances(luma(self.reprojected if name.startswith("r") else self.albedo))
        base, _, comp = name.partition(".")
        planes = {
            "albedo": self.albedo, "normal": self.normal, "reprojected": self.reprojected, "motion": self.motion,
            "roughness": self.roughness, "metallic": self.metallic, "specular": self.specular,
            "emissive": self.emissive, "depth": self.depth, "shadow": self.shadow, "seen": self.seen,
            "mask": self.mask, "ao": self.ao,
        }
        if base not in planes:
            raise UnsupportedChannelError(f"unknown channel {name!r}; known planes: {', '.join(sorted(planes))}")
        arr = planes[base]
        if not comp:
            if arr.ndim != 2:
                example = f"{name}.{'r' if base in ('albedo', 'reprojected') else 'x'}"
                raise UnsupportedChannelError(f"{name!r} has several components; name one, e.g. {example}")
            return arr
        if base in ("albedo", "reprojected") and comp == "y":  # colour planes: y is luma, as sdk.CHANNELS says
            return luma(arr)
        index = {"r": 0, "g": 1, "b": 2, "x": 0, "y": 1, "z": 2}.get(comp)
        if arr.ndim != 3 or index is None or index >= arr.shape[2]:
            raise UnsupportedChannelError(f"channel {name!r} does not exist")
        return arr[..., index]


#: Alias: the object :meth:`Renderer.render` returns.
RenderResult = Frame


def _mat(m: np.ndarray) -> bytes:
    """Column-major float32 bytes of a (row-major, column-vector) numpy matrix, as GL expects."""
    return np.ascontiguousarray(np.asarray(m, dtype=np.float32).T).tobytes()


def _set(prog: Any, name: str, value: Any) -> None:
    """Set a uniform if the linker kept it."""
    try:
        uniform = prog[name]
    except KeyError:
        return
    if isinstance(value, np.ndarray):
        uniform.write(_mat(value) if value.ndim == 2 and value.shape[0] == value.shape[1] else value.astype(np.float32).tobytes())
    else:
        uniform.value = value


@dataclass
class _SunFit:
    light_vp: np.ndarray  # world -> light clip
    texel: float  # world size of one shadow texel (metres)


def _fit_sun_shadow(
    camera: Camera, aspect: float, direction: np.ndarray, lo: np.ndarray, hi: np.ndarray, distance: float | None
) -> _SunFit | None:
    """An orthographic sun projection that covers the view frustum (up to ``distance``) inside
    the scene bounds in x/y, and every potential caster of the scene along the light."""
    d = np.asarray(direction, np.float64)
    if not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-9:
        return None
    d = d / np.linalg.norm(d)
    up = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.99 else np.array([1.0, 0.0, 0.0])
    right = np.cross(d, up)
    right /= np.linalg.norm(right)
    upv = np.cross(right, d)
    rot = np.stack([right, upv, -d])  # rows: light-view axes (looks down -Z along d)

    far = camera.far if distance is None else min(camera.far, distance)
    ty = math.tan(math.radians(camera.fov_y) / 2)
    pts = []
    for z in (camera.near, far):
        for sx in (-1, 1):
            for sy in (-1, 1):
                pts.append([sx * z * ty * aspect, sy * z * ty, -z])
    cam_rot = camera.rotation()
    frustum = np.asarray(pts) @ cam_rot.T + np.asarray(camera.position, np.float64)
    box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], np.float64)
    fl, sl = frustum @ rot.T, box @ rot.T
    ext = max(float(np.max(sl.max(0) - sl.min(0))), 1e-3)
    lo_xy = np.maximum(fl.min(0)[:2], sl.min(0)[:2])
    hi_xy = np.minimum(fl.max(0)[:2], sl.max(0)[:2])
    if np.any(hi_xy - lo_xy <= 1e-6):  # frustum misses the scene: nothing to shadow
        return None
    margin = 1e-3 * ext + 1e-3
    lo_xy -= margin
    hi_xy += margin
    z_near = -(sl[:, 2].max() + margin)  # closest to the light
    z_far = -(max(sl[:, 2].min(), fl[:, 2].min()) - margin)
    if z_far <= z_near:
        z_far = z_near + 1.0
    left, r = lo_xy[0], hi_xy[0]
    b, t = lo_xy[1], hi_xy[1]
    ortho = np.array(
        [
            [2 / (r - left), 0, 0, -(r + left) / (r - left)],
            [0, 2 / (t - b), 0, -(t + b) / (t - b)],
            [0, 0, -2 / (z_far - z_near), -(z_far + z_near) / (z_far - z_near)],
            [0, 0, 0, 1],
        ]
    )
    view = np.eye(4)
    view[:3, :3] = rot
    return _SunFit(ortho @ view, float(max(r - left, t - b)))


@dataclass
class _GpuMesh:
    vao: Any
    vao_shadow: Any
    vbo: Any
    ibo: Any
    material: int


@dataclass
class _GpuMaterial:
    texture: Any | None
    base_color: tuple[float, float, float, float]
    rms: tuple[float, float, float]
    emissive: tuple[float, float, float]
    alpha_cutoff: float


@dataclass
class _FrameSetup:
    """What the passes of one frame share: the scene, cameras, matrices, sun and sky terms."""

    scene: Scene
    camera: Camera
    prev_camera: Camera | None
    size: tuple[float, float]  # frame size in pixels, for the shaders
    view: np.ndarray  # world -> view
    proj: np.ndarray  # view -> clip
    inv_proj: np.ndarray
    inv_view: np.ndarray
    v2w: np.ndarray  # view -> world rotation
    prev_vp: np.ndarray  # the previous camera's world -> clip (the current one's without a previous camera)
    to_sun: np.ndarray  # unit vector towards the sun, world
    sun_rad: np.ndarray  # sun radiance, float32
    sky: tuple[float, ...]  # sky colour

    def sky_uniforms(self) -> dict[str, Any]:
        """The uniforms of the passes that shade background pixels with the sky."""
        return {
            "u_size": self.size, "u_inv_proj": self.inv_proj, "u_view_to_world": self.v2w, "u_sky_colour": self.sky,
            "u_to_sun_world": tuple(float(c) for c in self.to_sun), "u_sun_radiance": tuple(float(c) for c in self.sun_rad),
        }


class _StageTimer:
    """Wall time of each stage of a frame; with ``profile`` it waits for the GPU at every mark."""

    def __init__(self, ctx: Any, profile: bool) -> None:
        self.ctx, self.profile = ctx, profile
        self.timings: dict[str, float] = {}
        self.start = self.last = time.perf_counter()

    def mark(self, name: str) -> None:
        """Record the time since the previous mark as stage ``name``."""
        if self.profile:
            self.ctx.finish()
        now = time.perf_counter()
        self.timings[name] = now - self.last
        self.last = now

    def finish(self, width: int, height: int) -> None:
        """Record the total time and log every stage's."""
        t = self.timings
        t["total"] = time.perf_counter() - self.start
        logger.debug("frame %dx%d in %.3f s (%s)", width, height, t["total"],
                     ", ".join(f"{k} {v * 1e3:.0f} ms" for k, v in t.items() if k != "total"))


class Renderer:
    """Headless deferred renderer with software VRS.

    Args:
        width, height: frame size in pixels.
        ctx: a moderngl context to borrow (it is not released by :meth:`release`); by default the
            renderer creates its own headless EGL context.
        shadow_map_size: sun shadow map resolution (square); default
            1024 for frames up to 1024 pixels wide and high, else 2048, and for small frames the
            power of two of at least 4 texels per pixel of their longer side (256 up to 64 pixels,
            512 up to 128).
        shadow_distance: cap (metres) on the part of the view frustum the shadow map covers;
            None covers up to the camera's far plane (always clipped to the scene bounds).
        ao_samples, ao_radius, ao_strength: SSAO kernel size, radius (metres) and exponent (0: no occlusion,
            the term is 1 everywhere).
        anisotropy: maximum anisotropic filtering of material textures (clamped to the driver's).
            Ignored on Mesa's software rasterizers (llvmpipe, softpipe): llvmpipe 22.3 can spin
            forever in its anisotropic sampler on some views (seen at 1280x720), so textures
            there use trilinear filtering.
        fxaa: run FXAA on every rate's image (the paper does).
        max_point_lights: point lights per frame; the most influential ones that touch the view
            frustum are kept.
        exposure_key: middle-grey key of the auto-exposure (``exposure = key / log-average``).
        reprojection_tolerance: relative depth tolerance of the disocclusion test.
        cull_back_faces: cull back faces in the G-buffer pass (default off: shade two-sided).
        profile: wait for the GPU after every stage so that ``Frame.timings`` holds per-stage
            times (slightly slower); otherwise only ``timings["total"]`` is meaningful.
    """

    @staticmethod
    def max_frame_side(ctx: Any | None = None) -> int:
        """The largest frame side (and shadow map) ``ctx`` draws, its ``GL_MAX_TEXTURE_SIZE`` and
        ``GL_MAX_RENDERBUFFER_SIZE``; without ``ctx``, a headless context's (made and released for the
        question): a job checks its frame size with it before it writes anything."""
        own = ctx is None
        ctx = create_context() if ctx is None else _check_ctx(ctx)
        try:
            return max_texture_side(ctx)
        finally:
            if own:
                ctx.release()

    def __init__(
        self,
        width: int,
        height: int,
        *,
        ctx: Any | None = None,
        shadow_map_size: int | None = None,
        shadow_distance: float | None = None,
        ao_samples: int = 12,
        ao_radius: float = 0.5,
        ao_strength: float = 1.0,
        anisotropy: float = 8.0,
        fxaa: bool = True,
        max_point_lights: int = 32,
        exposure_key: float = 0.18,
        reprojection_tolerance: float = DEFAULT_REPROJECTION_TOLERANCE,
        cull_back_faces: bool = False,
        profile: bool = False,
    ) -> None:
        if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in (width, height)) \
                or int(width) < 1 or int(height) < 1:
            raise RendererError(f"frame size: expected positive integers (pixels), got {width!r}x{height!r}")
        if shadow_map_size is not None and (not isinstance(shadow_map_size, numbers.Integral)
                                            or isinstance(shadow_map_size, bool) or int(shadow_map_size) < 1):
            raise RendererError(f"shadow_map_size: expected a positive integer (pixels), got {shadow_map_size!r}")
        for name, flag in (("fxaa", fxaa), ("cull_back_faces", cull_back_faces), ("profile", profile)):
            _check_flag(flag, name)
        self._mgl = _import_moderngl()
        self.width, self.height = int(width), int(height)
        self._owns_ctx = ctx is None
        self.ctx = create_context() if ctx is None else _check_ctx(ctx)
        self._current: CurrentCheck | None = None
        try:  # (a refusal here releases the context the renderer made: the caller never gets the renderer)
            self.ctx.__enter__()  # (a borrowed context may not be the current one: its objects are made in it)
            # whether it is current in the calling thread, read back where a call comes from another thread than the
            # last: EGL refuses a context another thread holds, and moderngl's ctx.__enter__() does not say so (a
            # render() from a worker thread drew in no context and returned NaN frames, in silence)
            self._current = CurrentCheck(
                self.ctx, "Renderer", "could not be made current",
                "Call the renderer from the thread where its context is current, or release it there first "
                "(renderer.ctx.__exit__(None, None, None)): each call makes it current in the calling thread")
            if self.ctx.version_code < 330:
                raise RendererError(f"the renderer needs OpenGL >= 3.3, the context offers {self.ctx.version_code}")
            if shadow_map_size is None:
                shadow_map_size = _default_shadow_map_size(self.width, self.height)
            self.shadow_map_size = int(shadow_map_size)
            # The context's own limit, before any texture: past it moderngl only says "the framebuffer is not
            # complete".
            limit = self.max_frame_side(self.ctx)
            for what, side in (("frame size", max(self.width, self.height)), ("shadow_map_size", self.shadow_map_size)):
                if side > limit:
                    raise RendererError(f"{what}: this OpenGL context draws at most {limit} pixels a side "
                                        f"(GL_MAX_TEXTURE_SIZE), got {self.width}x{self.height}, shadow map "
                                        f"{self.shadow_map_size}")
            self._check_settings(ao_samples=ao_samples, max_point_lights=max_point_lights, ao_radius=ao_radius,
                                 ao_strength=ao_strength, anisotropy=anisotropy, exposure_key=exposure_key,
                                 reprojection_tolerance=reprojection_tolerance, shadow_distance=shadow_distance)
        except BaseException:
            if self._owns_ctx:
                self.ctx.release()
            raise
        self.shadow_distance = shadow_distance
        self.ao_samples = int(ao_samples)
        self.ao_radius = float(ao_radius)
        self.ao_strength = float(ao_strength)
        self.anisotropy = float(anisotropy)
        gl_renderer = str(self.ctx.info.get("GL_RENDERER", "")).lower()
        if self.anisotropy > 1.0 and ("llvmpipe" in gl_renderer or "softpipe" in gl_renderer):
            logger.debug("anisotropic filtering disabled on %s (trilinear instead)", gl_renderer)
            self.anisotropy = 1.0
        self.fxaa = bool(fxaa)
        self.max_point_lights = max(1, int(max_point_lights))
        self.exposure_key = float(exposure_key)
        self.reprojection_tolerance = float(reprojection_tolerance)
        self.cull_back_faces = bool(cull_back_faces)
        self.profile = bool(profile)
        self.scene: Scene | None = None
        self._meshes: list[_GpuMesh] = []
        self._materials: list[_GpuMaterial] = []
        self._released = False
        self._last: tuple[_FrameSetup, float] | None = None  # the frame rendered last, for shade_rates/reproject
        self._vrs: tuple[Any, ...] | None = None  # rate map, LDR and final textures and framebuffers of shade_rates
        logger.debug(
            "renderer %dx%d on %s (GL %d)", self.width, self.height, self.ctx.info.get("GL_RENDERER"), self.ctx.version_code
        )
        try:
            self._build_programs()
            self._allocate_targets()
        except Exception as exc:
            self.release()
            if isinstance(exc, RendererError):
                raise
            # Within the side limit, a context can still run out of room for the frame's targets (llvmpipe at
            # 16384x16384): moderngl says only "the framebuffer is not complete".
            raise RendererError(f"could not allocate the render targets of a {self.width}x{self.height} frame on "
                                f"this OpenGL context ({type(exc).__name__}: {exc}); try a smaller size") from exc

    #: The range of a fixed ``render(..., exposure=)`` (the auto-exposure stays within 2**-10 .. 2**10).
    MIN_EXPOSURE, MAX_EXPOSURE = 2.0**-20, 2.0**20

    #: The settings' ranges: the SSAO kernel and the point lights are arrays in the shaders (a uniform
    #: array's size is capped by the context; these stay far inside every GL 3.3 one).
    MAX_AO_SAMPLES = 64
    MAX_POINT_LIGHTS = 256

    @classmethod
    def _check_settings(cls, **values: Any) -> None:
        """Each setting of the constructor in its range, as a :class:`RendererError` naming it: out of
        range they failed as a GLSL compiler dump (``ao_samples=-1``) or not at all (``exposure_key=nan``)."""
        def number(v: Any) -> bool:
            if not isinstance(v, (int, float, np.integer, np.floating)) or isinstance(v, bool):
                return False
            try:
                return math.isfinite(float(v))
            except OverflowError:  # an int past float's range (compared exactly, it passed `v < inf`)
                return False

        ranges = {"ao_samples": (1, cls.MAX_AO_SAMPLES, True), "max_point_lights": (1, cls.MAX_POINT_LIGHTS, True),
                  "ao_radius": (0.0, math.inf, False), "ao_strength": (0.0, math.inf, False),
                  "anisotropy": (1.0, math.inf, False), "exposure_key": (0.0, math.inf, False),
                  "reprojection_tolerance": (0.0, MAX_REPROJECTION_TOLERANCE, False), "shadow_distance": (0.0, math.inf, False)}
        for name, v in values.items():
            lo, hi, integral = ranges[name]
            if name == "shadow_distance" and v is None:
                continue
            ok = number(v) and (not integral or isinstance(v, (int, np.integer))) and lo <= v <= hi
            if name in ("ao_radius", "exposure_key", "shadow_distance") and ok:
                ok = v > 0
            if not ok:
                strict = name in ("ao_radius", "exposure_key", "shadow_distance")
                bound = f"an integer in [{lo}, {hi}]" if integral else f"a finite number {'>' if strict else '>='} {lo:g}" \
                    if math.isinf(hi) else f"a number in [{lo:g}, {hi:g}]"
                raise RendererError(f"{name}: expected {bound}, got {v!r}")

    # ------------------------------------------------------------------ set-up
    def _program(self, vs: str, fs: str, defines: dict[str, Any] | None = None) -> Any:
        try:
            return self.ctx.program(vertex_shader=load_source(vs, defines), fragment_shader=load_source(fs, defines))
        except Exception as exc:
            raise RendererError(f"failed to build shader program {vs} + {fs}: {exc}") from exc

    def _build_programs(self) -> None:
        fs = "fullscreen_vs.glsl"
        self._p_gbuffer = self._program("gbuffer_vs.glsl", "gbuffer_fs.glsl")
        self._p_shadow = self._program("shadow_vs.glsl", "shadow_fs.glsl")
        self._p_ssao = self._program(fs, "ssao_fs.glsl", {"AO_SAMPLES": self.ao_samples})
        self._p_blur = self._program(fs, "ao_blur_fs.glsl")
        self._p_light = self._program(fs, "lighting_fs.glsl", {"MAX_POINT_LIGHTS": self.max_point_lights})
        self._p_expo = self._program(fs, "exposure_fs.glsl")
        self._p_coarse = self._program(fs, "coarse_fs.glsl")
        self._p_fxaa = self._program(fs, "fxaa_fs.glsl")
        self._fullscreen = {
            name: self.ctx.vertex_array(p, [])
            for name, p in [
                ("ssao", self._p_ssao), ("blur", self._p_blur), ("light", self._p_light), ("expo", self._p_expo),
                ("coarse", self._p_coarse), ("fxaa", self._p_fxaa),
            ]
        }
        # SSAO kernel: deterministic, denser near the centre.
        rng = np.random.default_rng(7)
        k = rng.normal(size=(self.ao_samples, 3))
        k[:, 2] = np.abs(k[:, 2]) + 0.15
        k /= np.linalg.norm(k, axis=1, keepdims=True)
        scale = 0.1 + 0.9 * (np.arange(self.ao_samples) / self.ao_samples) ** 2
        self._ao_kernel = (k * (rng.uniform(0.3, 1.0, self.ao_samples) * scale)[:, None]).astype(np.float32)
        self._white = self.ctx.texture((1, 1), 4, b"\xff\xff\xff\xff")

    def resize(self, width: int, height: int) -> None:
        """Draw frames of ``width`` x ``height`` from now on (an engine's dynamic resolution): the frame's
        render targets are made anew at that size; the programs, the loaded scene and every setting stay,
        the shadow map's size too (an engine scales its view, not its shadow maps). A frame renders at the
        new size exactly as a renderer made at that size with the same ``shadow_map_size`` draws it.
        :meth:`shade_rates`, :meth:`reproject` and :meth:`reprojection_source` then need a frame rendered
        at the new size; the previous frame's planes, at the old size, reproject into it through
        :func:`rtp.sdk.reproject`. The same size is a no-op. Raises :class:`RendererError` on a size that
        is not positive integers or that the context cannot draw, keeping the current size."""
        self._check_alive()
        if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in (width, height)) \
                or int(width) < 1 or int(height) < 1:
            raise RendererError(f"resize: expected positive integers (pixels), got {width!r}x{height!r}")
        width, height = int(width), int(height)
        if (width, height) == (self.width, self.height):
            return
        limit = self.max_frame_side(self.ctx)
        if max(width, height) > limit:
            raise RendererError(f"resize: this OpenGL context draws at most {limit} pixels a side "
                                f"(GL_MAX_TEXTURE_SIZE), got {width}x{height}")
        self.ctx.__enter__()  # (its objects are freed and made in its own context)
        old = (self.width, self.height)
        self._release_targets()
        self._last = None
        self.width, self.height = width, height
        try:
            self._allocate_targets()
        except Exception as exc:  # (out of room at the new size: back to the old one, which fitted)
            self._release_targets()
            self.width, self.height = old
            self._allocate_targets()
            raise RendererError(f"resize: could not allocate the render targets of a {width}x{height} frame on "
                                f"this OpenGL context ({type(exc).__name__}: {exc}); kept {old[0]}x{old[1]}") from exc
        logger.debug("renderer resized %dx%d -> %dx%d", old[0], old[1], width, height)

    def _release_targets(self) -> None:
        """Free what :meth:`_allocate_targets` and :meth:`shade_rates` made at the frame's size."""
        for obj in self._vrs or ():
            obj.release()
        self._vrs = None
        for name in getattr(self, "_target_names", ()):
            obj = vars(self).pop(name, None)
            if isinstance(obj, dict):
                for o in obj.values():
                    o.release()
            elif isinstance(obj, Adapter):
                obj.close()
            elif obj is not None:
                obj.release()

    def _allocate_targets(self) -> None:
        before = set(vars(self))
        try:
            self._make_targets()
        finally:  # (what a failed allocation made is released with the rest)
            self._target_names = tuple(sorted(set(vars(self)) - before))

    def _make_targets(self) -> None:
        ctx, size, mgl = self.ctx, (self.width, self.height), self._mgl
        nearest = (mgl.NEAREST, mgl.NEAREST)

        def tex(components: int, dtype: str, sz: tuple[int, int] = size, filt: tuple[int, int] = nearest) -> Any:
            t = ctx.texture(sz, components, dtype=dtype)
            t.filter = filt
            t.repeat_x = t.repeat_y = False
            return t

        self._t_albedo = tex(4, "f2")
        self._t_nd = tex(4, "f4")
        self._t_material = tex(4, "f2")
        self._t_emissive = tex(4, "f2")
        self._t_motion = tex(2, "f4")
        self._rb_depth = ctx.depth_renderbuffer(size)
        self._fbo_g = ctx.framebuffer(
            color_attachments=[self._t_albedo, self._t_nd, self._t_material, self._t_emissive, self._t_motion],
            depth_attachment=self._rb_depth,
        )
        s = self.shadow_map_size
        self._t_shadow = ctx.depth_texture((s, s))
        self._t_shadow.compare_func = "<="
        self._t_shadow.filter = (mgl.LINEAR, mgl.LINEAR)
        self._t_shadow.repeat_x = self._t_shadow.repeat_y = False
        self._fbo_shadow = ctx.framebuffer(depth_attachment=self._t_shadow)
        self._t_ao_raw = tex(1, "f2")
        self._t_ao = tex(1, "f2")
        self._fbo_ao_raw = ctx.framebuffer(color_attachments=[self._t_ao_raw])
        self._fbo_ao = ctx.framebuffer(color_attachments=[self._t_ao])
        self._t_lit = tex(4, "f2")
        self._fbo_lit = ctx.framebuffer(color_attachments=[self._t_lit])
        rows, cols = tile_grid(self.height, self.width, 4)  # the exposure pass reduces 4x4 blocks
        esize = (cols, rows)
        self._t_expo = tex(2, "f4", esize)
        self._fbo_expo = ctx.framebuffer(color_attachments=[self._t_expo])
        linear = (mgl.LINEAR, mgl.LINEAR)
        self._t_ldr = {r: tex(4, "f2", filt=linear) for r in ALL_RATES}
        self._t_final = {r: tex(4, "f2") for r in ALL_RATES}
        self._t_hdr: dict[str, Any] = {}
        self._fbo_ldr = {r: ctx.framebuffer(color_attachments=[self._t_ldr[r]]) for r in ALL_RATES}
        self._fbo_ldr_debug: dict[str, Any] = {}
        self._fbo_final = {r: ctx.framebuffer(color_attachments=[self._t_final[r]]) for r in ALL_RATES}
        self._t_prev_colour = tex(3, "f4")
        self._t_prev_depth = tex(1, "f4")
        self._reprojector = Adapter(("reprojected.r", "reprojected.g", "reprojected.b", "seen"), self.width,
                                    self.height, ctx=ctx, tolerance=self.reprojection_tolerance,
                                    clamp_colour=False)  # (reprojection_source carries pixel coordinates through it)

    def _debug_fbo(self, rate: str) -> Any:
        if rate not in self._fbo_ldr_debug:
            t = self.ctx.texture((self.width, self.height), 4, dtype="f2")
            t.filter = (self._mgl.NEAREST, self._mgl.NEAREST)
            self._t_hdr[rate] = t
            self._fbo_ldr_debug[rate] = self.ctx.framebuffer(color_attachments=[self._t_ldr[rate], t])
        return self._fbo_ldr_debug[rate]

    # ------------------------------------------------------------------ scene
    @property
    def settings(self) -> dict[str, Any]:
        """The renderer's parameters and the GL implementation, for dataset manifests."""
        return {
            "size": [self.width, self.height], "shadow_map_size": self.shadow_map_size,
            "shadow_distance": self.shadow_distance, "ao_samples": self.ao_samples, "ao_radius": self.ao_radius,
            "ao_strength": self.ao_strength, "anisotropy": self.anisotropy, "fxaa": self.fxaa,
            "max_point_lights": self.max_point_lights, "exposure_key": self.exposure_key,
            "reprojection_tolerance": self.reprojection_tolerance, "cull_back_faces": self.cull_back_faces,
            "gl_renderer": str(self.ctx.info.get("GL_RENDERER", "")), "gl_version": int(self.ctx.version_code),
            "moderngl": str(getattr(self._mgl, "__version__", "")),
        }

    def load_scene(self, scene: Scene) -> None:
        """Upload a scene's meshes and textures (replacing the previous scene's GPU resources).

        Textures are uploaded as sRGB (filtered in linear space), mip-mapped, with anisotropic
        filtering where the driver offers it. Raises :class:`RendererError` on malformed meshes or materials
        and on a texture larger than the context holds (``GL_MAX_TEXTURE_SIZE``), all checked before the loaded
        scene is let go: after a refusal the scene loaded before stays loaded.
        """
        self._check_alive()
        if not isinstance(scene, Scene):
            raise RendererError(f"load_scene: expected an rtp.scene.Scene, got {type(scene).__name__}")
        limit = max_texture_side(self.ctx)
        for i, m in enumerate(scene.materials):  # (before the scene loaded is let go)
            if m.texture is None:
                continue
            img = np.asarray(m.texture)
            if img.ndim != 3 or img.shape[2] != 4 or img.dtype != np.uint8:
                raise RendererError(
                    f"material {i} ({m.name!r}): texture must be (H, W, 4) uint8, got {img.shape} {img.dtype}"
                )
            if max(img.shape[:2]) > limit:  # (past it moderngl made a texture GL never filled: sampled as black)
                raise RendererError(f"material {i} ({m.name!r}): this OpenGL context holds textures of at most {limit} "
                                    f"texels a side (GL_MAX_TEXTURE_SIZE), got {img.shape[1]}x{img.shape[0]}: scale it "
                                    "down")
        # Every mesh and material checked before the loaded scene is let go: a scene whose list was changed after it
        # was made (a mesh appended with a material index past the list) left the renderer with no scene and half of
        # the new one's meshes uploaded.
        factors = [(_floats(m.base_color, 4), _floats(m.emissive, 3)) for m in scene.materials]
        arrays = []
        for i, mesh in enumerate(scene.meshes):
            pos = np.asarray(mesh.positions, np.float32)
            nrm = np.asarray(mesh.normals, np.float32)
            uv = np.asarray(mesh.uvs, np.float32)
            idx = np.asarray(mesh.indices)
            n = len(pos)
            if pos.ndim != 2 or pos.shape[1] != 3 or nrm.shape != (n, 3) or uv.shape != (n, 2):
                raise RendererError(
                    f"mesh {i}: positions (N, 3), normals (N, 3) and uvs (N, 2) must agree; "
                    f"got {pos.shape}, {nrm.shape}, {uv.shape}"
                )
            if idx.ndim != 2 or idx.shape[1] != 3:
                raise RendererError(f"mesh {i}: indices must be (M, 3), got {idx.shape}")
            if len(idx) and (idx.min() < 0 or idx.max() >= n):
                raise RendererError(f"mesh {i}: an index is outside 0..{n - 1}")
            if not 0 <= mesh.material < len(scene.materials):
                raise RendererError(f"mesh {i}: material {mesh.material} not in 0..{len(scene.materials) - 1}")
            arrays.append((pos, nrm, uv, idx, mesh.material))
        self._release_scene()
        mgl = self._mgl
        t0 = time.perf_counter()
        for m, (base_color, emissive) in zip(scene.materials, factors):
            tex = None
            if m.texture is not None:
                img = np.asarray(m.texture)
                tex = self.ctx.texture((img.shape[1], img.shape[0]), 4, np.ascontiguousarray(img).tobytes(),
                                       internal_format=_GL_SRGB8_ALPHA8)
                tex.build_mipmaps()
                tex.filter = (mgl.LINEAR_MIPMAP_LINEAR, mgl.LINEAR)
                if self.anisotropy > 1.0:
                    tex.anisotropy = min(self.anisotropy, float(self.ctx.max_anisotropy or 1.0))
            cutoff = -1.0 if m.alpha_cutoff is None else float(m.alpha_cutoff)
            self._materials.append(_GpuMaterial(tex, base_color, (m.roughness, m.metallic, m.specular), emissive, cutoff))
        for pos, nrm, uv, idx, material in arrays:
            if len(idx) == 0:
                continue
            vbo = self.ctx.buffer(np.concatenate([pos, nrm, uv], axis=1).astype(np.float32).tobytes())
            ibo = self.ctx.buffer(idx.astype(np.uint32).tobytes())
            vao = self.ctx.vertex_array(
                self._p_gbuffer, [(vbo, "3f 3f 2f", "in_position", "in_normal", "in_uv")], ibo, index_element_size=4
            )
            vao_s = self.ctx.vertex_array(
                self._p_shadow, [(vbo, "3f 12x 2f", "in_position", "in_uv")], ibo, index_element_size=4
            )
            self._meshes.append(_GpuMesh(vao, vao_s, vbo, ibo, material))
        self.scene = scene
        logger.info(
            "loaded scene %r: %d meshes, %d triangles, %d materials in %.2f s",
            scene.name, len(self._meshes), scene.triangle_count, len(self._materials), time.perf_counter() - t0,
        )

    def _release_scene(self) -> None:
        for m in self._meshes:
            for obj in (m.vao, m.vao_shadow, m.vbo, m.ibo):
                obj.release()
        for mat in self._materials:
            if mat.texture is not None:
                mat.texture.release()
        self._meshes, self._materials, self.scene = [], [], None

    # ------------------------------------------------------------------ frame
    def _bind_material(self, prog: Any, mat: _GpuMaterial) -> None:
        (mat.texture or self._white).use(location=0)
        _set(prog, "u_texture", 0)
        _set(prog, "u_has_texture", mat.texture is not None)
        _set(prog, "u_alpha_cutoff", mat.alpha_cutoff)

    def _select_lights(self, scene: Scene, view: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        aspect = self.width / self.height
        ty = math.tan(math.radians(camera.fov_y) / 2)
        tx = ty * aspect
        planes = np.array([[1, 0, tx], [-1, 0, tx], [0, 1, ty], [0, -1, ty]], np.float64)
        planes /= np.linalg.norm(planes, axis=1, keepdims=True)
        keep: list[tuple[float, np.ndarray, np.ndarray]] = []
        for light in scene.point_lights:
            p = view @ np.array([*light.position, 1.0])
            r = float(light.radius)
            if r <= 0 or light.intensity <= 0:
                continue
            if p[2] - r > -camera.near or p[2] + r < -camera.far or np.any(planes @ p[:3] > r):
                continue
            rad = np.asarray(light.colour, np.float64) * light.intensity
            score = float(rad.max()) / max(float(p[:3] @ p[:3]) - r * r, 1.0)
            keep.append((score, np.array([*p[:3], r]), rad))
        if len(keep) > self.max_point_lights:
            logger.debug("%d point lights touch the view; keeping the %d strongest", len(keep), self.max_point_lights)
            keep.sort(key=lambda k: -k[0])
            keep = keep[: self.max_point_lights]
        pos = np.zeros((self.max_point_lights, 4), np.float32)
        col = np.zeros((self.max_point_lights, 3), np.float32)
        for i, (_, p4, c) in enumerate(keep):
            pos[i], col[i] = p4, c
        return pos[: len(keep)], col[: len(keep)]

    def render(
        self,
        camera: Camera,
        prev: Frame | None = None,
        *,
        prev_camera: Camera | None = None,
        exposure: float | None = None,
        debug: bool = False,
    ) -> Frame:
        """Render one frame of the loaded scene from ``camera``.

        Args:
            camera: the current camera.
            prev: the previous frame (from this renderer or any frame of the same size); its final
                1x1 colour and depth are reprojected, and its camera drives motion vectors.
                Without it, ``reprojected`` and ``seen`` are 0.
            prev_camera: the previous camera, for motion vectors without a previous frame (``prev``
                None). With ``prev`` it defaults to ``prev.camera`` and may only repeat it (or stand in
                for a ``prev`` whose ``camera`` is None): a camera that differs from ``prev.camera`` is
                a :class:`rtp.sdk.ParameterError` (a ``ValueError``) naming both.
            exposure: a fixed exposure multiplier instead of auto-exposure.
            debug: also read back the pre-post-processing lighting of every rate (``Frame.lighting``).

        Returns:
            A :class:`Frame` with the G-buffers, the 7 final images and the reprojection.
        """
        _check_camera(camera, "camera")
        _check_flag(debug, "debug")
        if exposure is not None:
            number = isinstance(exposure, (int, float, np.integer, np.floating)) and not isinstance(exposure, bool)
            if not number or not self.MIN_EXPOSURE <= exposure <= self.MAX_EXPOSURE:
                raise RendererError(f"exposure: expected None (auto-exposure) or a finite multiplier in "
                                    f"[2**-20, 2**20], got {exposure!r}")
        scene = self._check_can_render(prev)
        if prev_camera is None and prev is not None:
            prev_camera = prev.camera
        elif prev is not None and isinstance(prev.camera, Camera) and not _same_view(
                _check_camera(prev_camera, "prev_camera"), prev.camera, self.width, self.height):
            # (it took prev_camera's in silence: motion vectors and the reprojection of prev's pixels from a camera
            # that did not draw them)
            raise ParameterError(f"prev_camera and prev.camera: two different previous cameras ({prev_camera!r} and "
                                 f"{prev.camera!r}); prev's own camera drew the pixels reprojected: give prev alone, or "
                                 "prev_camera alone (motion vectors without a previous frame)", "prev_camera")
        if prev_camera is not None or prev is not None:  # a previous frame needs its camera (a Frame with camera=None)
            _check_camera(prev_camera, "prev_camera" if prev is None else "prev_camera (or prev.camera)")
        timer = _StageTimer(self.ctx, self.profile)
        setup = self._frame_setup(scene, camera, prev_camera)
        fit = self._shadow_pass(setup)
        timer.mark("shadow")
        self._gbuffer_pass(setup)
        timer.mark("gbuffer")
        self._ssao_pass(setup)
        timer.mark("ssao")
        self._lighting_pass(setup, fit)
        timer.mark("lighting")
        log_avg, exposure = self._exposure_pass(setup, exposure)
        timer.mark("exposure")
        self._vrs_tonemap_pass(setup, exposure, debug)
        timer.mark("vrs_tonemap")
        self._fxaa_pass()
        timer.mark("fxaa")
        reprojection = self._reprojection_pass(setup, prev)
        timer.mark("reproject")
        frame = self._read_back(setup, reprojection, exposure, log_avg, debug, timer.timings)
        timer.mark("readback")
        timer.finish(self.width, self.height)
        self._last = (setup, exposure)
        return frame

    # ------------------------------------------------------------------ closed-loop VRS
    def _last_frame(self, what: str) -> tuple[_FrameSetup, float]:
        self._check_alive()
        if self._last is None:
            raise RendererError(f"{what} works on the frame rendered last; call render() first")
        return self._last

    #: The largest ``shade_rates`` tile (pixels a side).
    MAX_TILE = 1 << 16

    def shade_rates(self, rates: np.ndarray, tile_size: int) -> np.ndarray:
        """Software VRS with a rate image: the frame rendered last, each ``tile_size`` tile shaded at
        its own rate (``rates``: uint8 D3D12 codes ``(th, tw)``, top-left origin, as
        :func:`rtp.sdk.select_rates` returns), then tone mapping and FXAA over the whole image, as an
        engine's post-processing would run on its VRS output. Returns the final ``(H, W, 3)`` image
        (display-encoded sRGB). A uniform rate image gives that rate's ``Frame.colour`` image exactly."""
        setup, exposure = self._last_frame("shade_rates")
        if (not isinstance(tile_size, numbers.Integral) or isinstance(tile_size, bool) or int(tile_size) % 4
                or not 4 <= int(tile_size) <= self.MAX_TILE):
            raise RendererError(f"tile_size must be a positive multiple of 4 (the largest rate) up to {self.MAX_TILE}, "
                                f"got {tile_size!r}")
        tile_size = int(tile_size)
        th, tw = tile_grid(self.height, self.width, tile_size)
        try:
            codes = np.asarray(rates)
        except (TypeError, ValueError, OverflowError) as exc:
            raise RendererError(f"rates: expected an array of D3D12 rate codes, got {type(rates).__name__}") from exc
        if codes.shape != (th, tw):
            raise RendererError(f"rates: expected a {tw}x{th} tile grid ({th}, {tw}) for {tile_size}px tiles of a "
                                f"{self.width}x{self.height} frame, got shape {codes.shape}")
        if codes.dtype.kind not in "iu":  # (as sdk.select_rates' engine_rates: a float image is no rate image)
            raise RendererError(f"rates: expected integer D3D12 rate codes (uint8), got {codes.dtype}")
        valid = np.isin(codes, [RATE_CODES[r] for r in ALL_RATES])
        if not valid.all():
            bad = np.unique(codes[~valid]).tolist()[:8]
            raise RendererError(f"rates: unknown rate codes {bad}; expected D3D12 codes of {', '.join(ALL_RATES)}")
        if self._vrs is None or self._vrs[0].size != (tw, th):
            mgl = self._mgl
            if self._vrs is not None:
                for obj in self._vrs:
                    obj.release()
                # (not held released: where the new ones could not be made, every later call used or released them)
                self._vrs = None
            made: list[Any] = []
            try:
                made.append(self.ctx.texture((tw, th), 1, dtype="f4"))
                made[0].filter = (mgl.NEAREST, mgl.NEAREST)
                made.append(self.ctx.texture((self.width, self.height), 4, dtype="f2"))
                made[1].filter = (mgl.LINEAR, mgl.LINEAR)
                made[1].repeat_x = made[1].repeat_y = False
                made.append(self.ctx.texture((self.width, self.height), 4, dtype="f2"))
                made.append(self.ctx.framebuffer(color_attachments=[made[1]]))
                made.append(self.ctx.framebuffer(color_attachments=[made[2]]))
            except BaseException:  # (a borrowed context keeps what is not released)
                for obj in made:
                    obj.release()
                raise
            self._vrs = tuple(made)
        rate_map, ldr, final, fbo_ldr, fbo_final = self._vrs
        write_texture(rate_map, codes.astype(np.float32))
        p = self._p_coarse
        self._t_lit.use(location=0)
        self._t_nd.use(location=1)
        rate_map.use(location=2)
        _set(p, "u_lit", 0)
        _set(p, "u_normal_depth", 1)
        _set(p, "u_rate_map", 2)
        _set(p, "u_tile", int(tile_size))
        _set(p, "u_exposure", float(exposure))
        for k, v in setup.sky_uniforms().items():
            _set(p, k, v)
        fbo_ldr.use()
        self._fullscreen["coarse"].render(self._mgl.TRIANGLES, vertices=3)
        _set(p, "u_tile", 0)
        if not self.fxaa:
            return read_texture(ldr, 3)
        q = self._p_fxaa
        _set(q, "u_ldr", 0)
        _set(q, "u_rcp", (1.0 / self.width, 1.0 / self.height))
        ldr.use(location=0)
        fbo_final.use()
        self._fullscreen["fxaa"].render(self._mgl.TRIANGLES, vertices=3)
        return read_texture(final, 3)

    def reproject(self, colour: np.ndarray, depth: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """Reproject any earlier image into the frame rendered last, with the same depth test as
        ``render(camera, prev)`` uses: ``colour`` ``(H, W, 3)`` was seen from ``camera`` with linear
        ``depth`` ``(H, W)``. Returns ``(reprojected (H, W, 3), seen (H, W))``. A closed-loop VRS run
        reprojects each method's own displayed frame this way."""
        setup, _ = self._last_frame("reproject")
        colour = _image(colour, (self.height, self.width, 3), "reproject: colour")
        depth = _image(depth, (self.height, self.width), "reproject: depth")
        return self._reproject(setup, colour, depth, _check_camera(camera, "reproject: camera"))

    def reprojection_source(self, depth: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where :meth:`reproject` fetches each pixel of the frame rendered last: ``(rows, cols, seen)``,
        ``(H, W)`` each, top-left pixel indices into the earlier image (0 where unseen). Colour does not
        enter the depth test, so ``np.where(seen[..., None] > 0, image[rows, cols], 0)`` equals
        ``reproject(image, depth, camera)[0]`` for every image seen from ``camera`` with ``depth``: one
        GL pass serves any number of histories (the closed loop's methods)."""
        setup, _ = self._last_frame("reprojection_source")
        depth = _image(depth, (self.height, self.width), "reprojection_source: depth")
        _check_camera(camera, "reprojection_source: camera")
        rows, cols = np.indices((self.height, self.width), dtype=np.float32)
        coords = np.stack([cols, rows, np.zeros_like(rows)], -1)
        src, seen = self._reproject(setup, coords, depth, camera)
        return src[..., 1].astype(np.intp), src[..., 0].astype(np.intp), seen

    # The steps of render(), in the order it runs them: each leaves its result in the GL targets.
    def _check_can_render(self, prev: Frame | None) -> Scene:
        """The loaded scene, after checking the renderer is alive and ``prev`` has the frame size."""
        self._check_alive()
        if self.scene is None:
            raise RendererError("no scene loaded; call load_scene(scene) first")
        if prev is None:
            return self.scene
        if not isinstance(prev, Frame):
            raise RendererError(f"prev: expected the previous Frame (or None), got {type(prev).__name__}")
        depth = np.asarray(prev.depth) if isinstance(prev.depth, np.ndarray) else None
        if depth is not None and depth.ndim == 2 and depth.shape != (self.height, self.width):
            raise RendererError(f"previous frame is {prev.width}x{prev.height}, the renderer draws {self.width}x{self.height}")
        colour = prev.colour.get("1x1") if isinstance(prev.colour, dict) else None
        _image(colour, (self.height, self.width, 3), "prev.colour['1x1']")
        _image(prev.depth, (self.height, self.width), "prev.depth")
        return self.scene

    def _frame_setup(self, scene: Scene, camera: Camera, prev_camera: Camera | None) -> _FrameSetup:
        """The frame's matrices and sun and sky terms."""
        W, H = self.width, self.height
        view = camera.view()
        proj = camera.projection(W / H)
        inv_view = np.linalg.inv(view)
        sun = scene.sun
        to_sun = -np.asarray(sun.direction, np.float64)
        to_sun = to_sun / max(float(np.linalg.norm(to_sun)), 1e-12)
        return _FrameSetup(
            scene=scene, camera=camera, prev_camera=prev_camera, size=(float(W), float(H)),
            view=view, proj=proj, inv_proj=np.linalg.inv(proj), inv_view=inv_view, v2w=inv_view[:3, :3],
            prev_vp=prev_camera.view_projection(W, H) if prev_camera is not None else proj @ view,
            to_sun=to_sun, sun_rad=np.asarray(sun.colour, np.float32) * np.float32(sun.intensity),
            sky=tuple(float(c) for c in scene.sky_colour),
        )

    def _shadow_pass(self, f: _FrameSetup) -> _SunFit | None:
        """1. The sun shadow map, fitted to the view; None when the sun casts no shadow into it."""
        ctx, mgl, sun = self.ctx, self._mgl, f.scene.sun
        lo, hi = f.scene.bounds
        fit = None
        if self._meshes and sun.intensity > 0:
            fit = _fit_sun_shadow(f.camera, self.width / self.height, np.asarray(sun.direction), lo, hi, self.shadow_distance)
        if fit is not None:
            self._fbo_shadow.use()
            self._fbo_shadow.clear(depth=1.0)
            ctx.enable_only(mgl.DEPTH_TEST)
            ctx.polygon_offset = (1.5, 2.0)
            p = self._p_shadow
            _set(p, "u_light_vp", fit.light_vp)
            for gm in self._meshes:
                mat = self._materials[gm.material]
                self._bind_material(p, mat)
                _set(p, "u_base_alpha", mat.base_color[3])
                gm.vao_shadow.render(mgl.TRIANGLES)
            ctx.polygon_offset = (0.0, 0.0)
        return fit

    def _gbuffer_pass(self, f: _FrameSetup) -> None:
        """2. The G-buffer: albedo, normal and depth, material, emissive, motion."""
        ctx, mgl = self.ctx, self._mgl
        self._fbo_g.use()
        self._fbo_g.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable_only(mgl.DEPTH_TEST | (mgl.CULL_FACE if self.cull_back_faces else 0))
        p = self._p_gbuffer
        _set(p, "u_view", f.view)
        _set(p, "u_proj", f.proj)
        _set(p, "u_prev_vp", f.prev_vp)
        _set(p, "u_has_prev", f.prev_camera is not None)
        _set(p, "u_size", f.size)
        for gm in self._meshes:
            mat = self._materials[gm.material]
            self._bind_material(p, mat)
            _set(p, "u_base_color", mat.base_color)
            _set(p, "u_material", mat.rms)
            _set(p, "u_emissive", mat.emissive)
            gm.vao.render(mgl.TRIANGLES)
        ctx.disable(mgl.DEPTH_TEST | mgl.CULL_FACE)

    def _ssao_pass(self, f: _FrameSetup) -> None:
        """3. SSAO at full rate, then its 4x4 blur."""
        mgl = self._mgl
        self._t_nd.use(location=1)
        p = self._p_ssao
        _set(p, "u_normal_depth", 1)
        _set(p, "u_proj", f.proj)
        _set(p, "u_inv_proj", f.inv_proj)
        _set(p, "u_size", f.size)
        p["u_kernel"].write(self._ao_kernel.tobytes())
        _set(p, "u_radius", self.ao_radius)
        _set(p, "u_bias", 0.02 * self.ao_radius)
        self._fbo_ao_raw.use()
        self._fullscreen["ssao"].render(mgl.TRIANGLES, vertices=3)
        self._t_ao_raw.use(location=2)
        p = self._p_blur
        _set(p, "u_ao", 2)
        _set(p, "u_normal_depth", 1)
        _set(p, "u_strength", self.ao_strength)
        self._fbo_ao.use()
        self._fullscreen["blur"].render(mgl.TRIANGLES, vertices=3)

    def _lighting_pass(self, f: _FrameSetup, fit: _SunFit | None) -> None:
        """4. Deferred lighting at full rate: sun (shadowed by ``fit``), point lights, ambient x AO, emissive."""
        for loc, t in enumerate((self._t_albedo, self._t_nd, self._t_material, self._t_emissive, self._t_ao)):
            t.use(location=loc)
        self._t_shadow.use(location=5)
        p = self._p_light
        for loc, name in enumerate(("u_albedo", "u_normal_depth", "u_material", "u_emissive", "u_ao", "u_shadow_map")):
            _set(p, name, loc)
        _set(p, "u_size", f.size)
        _set(p, "u_inv_proj", f.inv_proj)
        _set(p, "u_view_to_world", f.v2w)
        _set(p, "u_shadows", fit is not None)
        if fit is not None:
            _set(p, "u_light_from_view", fit.light_vp @ f.inv_view)
            _set(p, "u_shadow_texel", 1.0 / self.shadow_map_size)
            _set(p, "u_normal_offset", 1.5 * fit.texel / self.shadow_map_size)
        _set(p, "u_to_sun_view", tuple(float(c) for c in f.view[:3, :3] @ f.to_sun))
        _set(p, "u_sun_radiance", tuple(float(c) for c in f.sun_rad))
        _set(p, "u_sky_colour", f.sky)
        _set(p, "u_ambient", float(f.scene.ambient))
        self._set_point_lights(p, f)
        self._fbo_lit.use()
        self._fullscreen["light"].render(self._mgl.TRIANGLES, vertices=3)

    def _set_point_lights(self, p: Any, f: _FrameSetup) -> None:
        """Upload the point lights that touch the view (at most ``max_point_lights``)."""
        lpos, lcol = self._select_lights(f.scene, f.view, f.camera)
        _set(p, "u_num_lights", len(lpos))
        if len(lpos):
            full_pos = np.zeros((self.max_point_lights, 4), np.float32)
            full_col = np.zeros((self.max_point_lights, 3), np.float32)
            full_pos[: len(lpos)], full_col[: len(lcol)] = lpos, lcol
            p["u_light_pos"].write(full_pos.tobytes())
            p["u_light_col"].write(full_col.tobytes())

    def _exposure_pass(self, f: _FrameSetup, exposure: float | None) -> tuple[float, float]:
        """5. Log-average luminance of the 1x1 HDR image, and the exposure: ``exposure`` if given,
        else the auto-exposure from it."""
        self._t_lit.use(location=0)
        self._t_nd.use(location=1)
        p = self._p_expo
        _set(p, "u_lit", 0)
        _set(p, "u_normal_depth", 1)
        for k, v in f.sky_uniforms().items():
            _set(p, k, v)
        self._fbo_expo.use()
        self._fullscreen["expo"].render(self._mgl.TRIANGLES, vertices=3)
        sums = read_texture(self._t_expo).astype(np.float64)
        log_avg = float(sums[..., 0].sum() / max(sums[..., 1].sum(), 1.0))
        if exposure is None:
            exposure = float(np.clip(self.exposure_key / math.exp(log_avg), 2.0**-10, 2.0**10))
        return log_avg, exposure

    def _vrs_tonemap_pass(self, f: _FrameSetup, exposure: float, debug: bool) -> None:
        """6a. Per shading rate: software VRS (each block shaded by its sample), tone map and sRGB encode."""
        p = self._p_coarse
        _set(p, "u_lit", 0)
        _set(p, "u_normal_depth", 1)
        _set(p, "u_tile", 0)
        _set(p, "u_exposure", float(exposure))
        for k, v in f.sky_uniforms().items():
            _set(p, k, v)
        for rate in ALL_RATES:
            _set(p, "u_rate", rate_size(rate))
            (self._debug_fbo(rate) if debug else self._fbo_ldr[rate]).use()
            self._fullscreen["coarse"].render(self._mgl.TRIANGLES, vertices=3)

    def _fxaa_pass(self) -> None:
        """6b. FXAA on every rate's image (when enabled)."""
        if not self.fxaa:
            return
        p = self._p_fxaa
        _set(p, "u_ldr", 0)
        _set(p, "u_rcp", (1.0 / self.width, 1.0 / self.height))
        for rate in ALL_RATES:
            self._t_ldr[rate].use(location=0)
            self._fbo_final[rate].use()
            self._fullscreen["fxaa"].render(self._mgl.TRIANGLES, vertices=3)

    def _reprojection_pass(self, f: _FrameSetup, prev: Frame | None) -> tuple[np.ndarray, np.ndarray] | None:
        """7. The previous frame's final 1x1 colour reprojected (by the same adapter engines use) and
        the seen mask; None without a previous frame."""
        if prev is None:
            return None
        return self._reproject(f, prev.colour["1x1"], prev.depth, f.prev_camera)  # type: ignore[arg-type]

    def _reproject(self, f: _FrameSetup, colour: np.ndarray, depth: np.ndarray, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        write_texture(self._t_prev_colour, colour)
        write_texture(self._t_prev_depth, depth)
        self._reprojector.run(
            albedo=self._t_albedo, normal=self._t_nd, depth=self._t_nd, depth_component=3,
            view=f.view, projection=f.proj, prev_colour=self._t_prev_colour, prev_depth=self._t_prev_depth,
            prev_view_projection=camera.view_projection(self.width, self.height),
        )
        rp = read_texture(self._reprojector._targets[0])
        return rp[..., :3], rp[..., 3]

    def _read_back(
        self, f: _FrameSetup, reprojection: tuple[np.ndarray, np.ndarray] | None, exposure: float, log_avg: float,
        debug: bool, timings: dict[str, float],
    ) -> Frame:
        """Read every target back into a :class:`Frame`."""
        albedo = read_texture(self._t_albedo)
        nd = read_texture(self._t_nd)
        material = read_texture(self._t_material)
        lit = read_texture(self._t_lit)
        final_src = self._t_final if self.fxaa else self._t_ldr
        colour = {r: read_texture(final_src[r], 3) for r in ALL_RATES}
        lighting = {r: read_texture(self._t_hdr[r], 3) for r in ALL_RATES} if debug else None
        if reprojection is None:
            reprojection = np.zeros((self.height, self.width, 3), np.float32), np.zeros((self.height, self.width), np.float32)
        reprojected, seen = reprojection
        return Frame(
            camera=f.camera,
            prev_camera=f.prev_camera,
            albedo=albedo[..., :3],
            normal=nd[..., :3],
            roughness=material[..., 0],
            metallic=material[..., 1],
            specular=material[..., 2],
            emissive=material[..., 3],
            depth=nd[..., 3],
            shadow=lit[..., 3],
            motion=read_texture(self._t_motion),
            mask=albedo[..., 3],
            ao=read_texture(self._t_ao)[..., 0],
            colour=colour,
            reprojected=reprojected,
            seen=seen,
            exposure=float(exposure),
            log_avg_luminance=log_avg,
            lighting=lighting,
            timings=timings,
        )

    # ------------------------------------------------------------------ lifetime
    def _check_alive(self) -> None:
        """At the top of every public method that draws: the renderer is not released, and its context
        is the current one (moderngl never switches by itself: with a second renderer's context current,
        a draw used that context's objects of the same names and could corrupt memory), checked where the call
        comes from another thread than the last (a RendererError where another thread holds the context)."""
        if self._released:
            raise RendererError("this renderer has been released")
        self.ctx.__enter__()  # (moderngl's only call for it; cheap when it is current already)
        current = self._current
        if current is not None and threading.get_ident() != current.thread:  # (one comparison in the same thread)
            current()
        self._reset_gl_state()

    def _reset_gl_state(self) -> None:
        """The context's GL state the passes assume (GL's defaults), set before every call that draws: a borrowed
        context keeps what its engine last set, and with blending on, clockwise front faces (the two-sided
        G-buffer's ``gl_FrontFacing`` flips every normal), a reverse-Z depth test (nothing drawn), wireframe,
        a depth range or sampler objects bound to the renderer's texture units, the frames came out wrong in
        silence. Left so afterwards, as the bound framebuffer is (the engine sets its own again). The viewport and
        scissor of every framebuffer of the renderer's are made whole again too: moderngl's ``ctx.viewport`` and
        ``ctx.scissor`` set them on the bound framebuffer, which after a call is the renderer's (an engine that set
        its window's viewport before binding its own framebuffer cut the next composite to that rectangle)."""
        ctx, mgl = self.ctx, self._mgl
        for obj in list(vars(self).values()) + list(self._vrs or ()):
            for fbo in obj.values() if isinstance(obj, dict) else (obj,):
                if isinstance(fbo, mgl.Framebuffer) and fbo is not ctx.screen:
                    fbo.viewport, fbo.scissor = (0, 0, *fbo.size), None
        ctx.enable_only(mgl.NOTHING)
        ctx.front_face = "ccw"
        ctx.cull_face = "back"
        ctx.depth_func = "<"
        ctx.wireframe = False
        ctx.polygon_offset = (0.0, 0.0)
        ctx.depth_clamp_range = None
        ctx.clear_samplers()

    def release(self) -> None:
        """Free every GL resource (and the context, when the renderer created it). Idempotent; after the engine
        released a borrowed context first (its objects went with it) it only marks the renderer released. From a
        thread where the context cannot be made current (another thread holds it) a borrowed context's objects are
        not freed: a warning says so, and the renderer is released all the same; a context the renderer made is
        released from any thread, and its objects go with it."""
        if self._released:
            return
        gone = is_released(self.ctx)  # (a borrowed context its engine released first: every object went with it)
        if not gone:
            self.ctx.__enter__()  # (its objects are freed in its own context)
        if gone or (self._current is not None and not self._current.holds()):
            # (the context not current here, EGL refusing it in silence: freed here, the objects were the same names
            # in the context current in this thread, an engine's own textures and buffers deleted under it)
            if not gone and self._owns_ctx:
                self.ctx.release()  # (any thread may: the driver destroys it once the thread holding it lets go)
            elif not gone and not self.__dict__.get("_quiet_close"):
                warn_not_freed(f"an rtp moderngl Renderer ({self.width}x{self.height})",
                               "meshes, textures, programs and framebuffers",
                               "Release it in the thread where its context is current, or release the context there "
                               "first (renderer.ctx.__exit__(None, None, None))")
            for obj in vars(self).values():  # (closed, not left to warn unclosed; nothing freed: said above)
                if isinstance(obj, Adapter):
                    obj.__dict__["_quiet_close"] = True
                    obj.close()
            self._meshes, self._materials, self.scene, self._vrs = [], [], None, None
            self._released = True
            return
        self._release_scene()
        if self._owns_ctx:
            for obj in vars(self).values():  # (closed, not left to warn unclosed: their objects go with the context)
                if isinstance(obj, Adapter):
                    obj.close()
            self.ctx.release()
        else:
            if hasattr(self, "_reprojector"):  # (a constructor that failed part-way releases what it made)
                self._reprojector.close()
            for obj in self._vrs or ():
                obj.release()
            self._vrs = None
            if self._current is not None:
                self._current.release()
            for obj in list(vars(self).values()):
                if isinstance(obj, dict):
                    for o in obj.values():
                        if hasattr(o, "release") and hasattr(o, "glo"):
                            o.release()
                elif hasattr(obj, "release") and hasattr(obj, "glo") and obj is not self.ctx:
                    obj.release()
            bound = self.ctx.fbo
            if bound is not None and is_released(bound):  # (GL then has none to draw into: the context's own 0)
                self.ctx.detect_framebuffer(0).use()
        self._released = True

    def __enter__(self) -> Renderer:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.release()
