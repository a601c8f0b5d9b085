"""G-buffers from pyrender: its own renderer, with a patched shader program cache.

pyrender has no G-buffer outputs and draws every mesh with ``mesh.vert`` + ``mesh.frag``. The
adapter's renderer keeps pyrender's whole pipeline (scene traversal, buffers, materials, culling,
the main framebuffer and its read-back) and swaps only the fragment shader: a subclass of
pyrender's ``ShaderProgramCache`` (``_program_cache_class``) hands out ``shaders/gbuffer.frag`` (a
copy of ``mesh.frag`` that writes one G-buffer pass instead of lighting) with a define saying which pass,
and ``shaders/gbuffer.vert`` for ``mesh.vert`` (the same, plus whether an instance's pose mirrors).

Quirks handled here (costs measured in docs/adapters.md):

* **8-bit targets.** pyrender's colour target is RGBA8 and read back as ``GL_UNSIGNED_BYTE``.
  Albedo goes through as display-encoded sRGB (8 bits per channel: error <= 0.5/255). Normals are
  packed two components per pass at 12 bits each (error <= 1/4095 in [-1, 1]), or, with
  ``normal_bits=8``, three per pass at 8 bits (error <= 1/255).
* **4x MSAA.** pyrender always renders into a 4x multisampled target and resolves it with a
  linear blit, which averages the G-buffer values of the surfaces an edge pixel straddles (and
  destroys packed values). The cache turns ``GL_MULTISAMPLE`` off for the passes it serves
  (default), so every pixel holds the sample at its centre, as in the reference renderer;
  ``msaa=True`` keeps pyrender's resolve (8-bit normals only).
* **Bottom-up rows.** GL rows grow upwards; pyrender's read-back flips them once, so every array
  here is top-left; nothing else flips.
* **Background.** pyrender clears to ``scene.bg_color``; the pass clears to 0 instead (restored
  after), and pixels without geometry (depth 0) are set to 0, the ``rtp.sdk`` convention.
"""

from __future__ import annotations

import ctypes
import logging
import os
import threading
import weakref
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rtp.sdk import ParameterError

from ._errors import PyrenderAdapterError
from ._gl import current, import_pyrender, offscreen_renderer

__all__ = ["GBufferRenderer", "GBuffers", "unpack12"]

log = logging.getLogger("rtp.plugins.pyrender")

SHADER_DIR = Path(__file__).with_name("shaders")
_MODE_ALBEDO, _MODE_8, _MODE_12 = 1, 2, 3
_SLOTS = {"normal.x": 1, "normal.y": 2, "normal.z": 3, "roughness": 4, "metallic": 5}
#: The material scalars a pass can write (pyrender's metallic-roughness model has no specular scale).
MATERIAL = ("roughness", "metallic")


def orthographic_depth(depth: np.ndarray, camera: Any) -> np.ndarray:
    """An orthographic camera's linear depth from what pyrender's read-back gives for it. pyrender linearises its
    depth buffer as a perspective camera's whatever the camera (``Renderer._read_main_framebuffer``: ``d = 2 n f /
    (f + n - z (f - n))`` of the NDC depth ``z``); an orthographic camera's depth is ``((f - n) z + f + n) / 2``,
    that is ``n + f - n f / d``. Background (0) stays 0."""
    near, far = float(camera.znear), float(camera.zfar)
    geometry = depth > 0.0
    out = np.zeros(depth.shape, np.float32)
    out[geometry] = near + far - near * far / depth[geometry].astype(np.float64)
    return out


@dataclass
class GBuffers:
    """One view's G-buffers. Arrays are float32, row-major ``(H, W[, C])``, top-left origin; 0 on
    background.

    * ``depth`` ``(H, W)``: linear view depth in scene units (distance along -Z), from pyrender's
      24-bit depth buffer (an orthographic camera's as such: :func:`orthographic_depth`).
    * ``albedo`` ``(H, W, 3)`` or None: base colour, display-encoded sRGB in [0, 1].
    * ``normal`` ``(H, W, 3)`` or None: unit view-space normal (components not asked for are 0).
    * ``roughness``, ``metallic`` ``(H, W)`` or None: the material's perceptual roughness and
      metalness as pyrender shades with them (factor x metallic-roughness texture R / G).
    """

    depth: np.ndarray
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None
    roughness: np.ndarray | None = None
    metallic: np.ndarray | None = None

    def __post_init__(self) -> None:
        d = self.depth
        if not isinstance(d, np.ndarray) or d.ndim != 2 or d.dtype.kind != "f":
            got = f"{d.dtype} {d.shape}" if isinstance(d, np.ndarray) else type(d).__name__
            raise ParameterError(f"GBuffers.depth: expected a float (H, W) array, got {got}", "depth")
        for name, channels in (("albedo", 3), ("normal", 3), ("roughness", 0), ("metallic", 0)):
            v = getattr(self, name)
            shape = (*d.shape, channels) if channels else d.shape
            if v is not None and (not isinstance(v, np.ndarray) or v.shape != shape or v.dtype.kind != "f"):
                got = f"{v.dtype} {v.shape}" if isinstance(v, np.ndarray) else type(v).__name__
                raise ParameterError(f"GBuffers.{name}: expected None or a float {shape} array, got {got}", name)

    @property
    def mask(self) -> np.ndarray:
        """``(H, W)`` bool, True on geometry."""
        return self.depth > 0.0


def unpack12(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two 12-bit values in [0, 1] from the three bytes ``gbuffer.frag`` mode 3 writes."""
    b = rgb.astype(np.uint32)
    a = (b[..., 0] << 4) | (b[..., 1] >> 4)
    c = ((b[..., 1] & 15) << 8) | b[..., 2]
    return a.astype(np.float32) / 4095.0, c.astype(np.float32) / 4095.0


def draw(renderer: Any, scene: Any, flags: int, seg_node_map: dict[Any, Any] | None = None, *, fix: str) -> Any:
    """``renderer.render(scene, flags, seg_node_map)``, with pyrender's errors turned into
    :class:`PyrenderAdapterError` (``fix``: what to do when the scene is bound to another renderer).

    The renderer's context is current only during the draw: what was current in this thread before (an
    engine's context, or none) is current again after it (:func:`~._gl.current`), so that another thread may
    draw with the renderer next."""
    with current(renderer):
        return _render(renderer, scene, flags, seg_node_map, fix)


def _render(renderer: Any, scene: Any, flags: int, seg_node_map: dict[Any, Any] | None, fix: str) -> Any:
    try:
        return renderer.render(scene, flags, seg_node_map)
    except ValueError as exc:
        if "already bound to a context" in str(exc):
            raise PyrenderAdapterError(
                "this scene's meshes are bound to another pyrender renderer's GL context (pyrender binds a "
                f"scene to one renderer at a time): {fix}") from exc
        raise PyrenderAdapterError(f"pyrender failed to draw ({type(exc).__name__}: {exc})") from exc
    except Exception as exc:
        raise PyrenderAdapterError(f"pyrender failed to draw ({type(exc).__name__}: {exc})") from exc


#: One lock per pyrender renderer (weakly keyed), held by the adapter's and the frame source's calls that draw with it:
#: a call moves the scene's camera node and swaps the renderer's program cache outside the GL context, so a second
#: call meanwhile (another thread's) drew with the first one's camera or passes, or moved them under it.
_BUSY: weakref.WeakKeyDictionary[Any, threading.RLock] = weakref.WeakKeyDictionary()
_BUSY_GUARD = threading.Lock()


def busy_lock(renderer: Any) -> threading.RLock:
    """The lock of ``renderer`` (a ``pyrender.OffscreenRenderer``) that its callers here hold through a call: one
    for every adapter borrowing the renderer and its frame source."""
    with _BUSY_GUARD:
        lock = _BUSY.get(renderer)
        if lock is None:
            lock = _BUSY[renderer] = threading.RLock()
        return lock


@contextmanager
def one_call(lock: threading.RLock, what: str) -> Iterator[None]:
    """Hold ``lock`` for the block, or refuse the call (``what``: the object and the method) with a
    :class:`PyrenderAdapterError` where another thread's call holds it; the call under way goes on unharmed."""
    if not lock.acquire(blocking=False):
        raise PyrenderAdapterError(
            f"{what}: its pyrender renderer is in a call already (another thread's): a call moves the scene's "
            "camera and the renderer's shader programs while it draws, so it takes one call at a time (the "
            "renderer's adapters and frame source together); call them from one thread at a time, or give each "
            "thread an adapter with a renderer and a scene of its own (docs/adapters.md)")
    try:
        yield
    finally:
        lock.release()


def _same_depth(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Where two linear depths of one view are the same surface (24-bit depth buffers, drawn by different
    shaders): within 1e-4 relative, and neither background."""
    return (a > 0.0) & (b > 0.0) & (np.abs(a - b) <= 1e-4 * np.maximum(a, b))


def _program_cache_class() -> type:
    pyrender = import_pyrender()
    from OpenGL import GL

    base = pyrender.shader_program.ShaderProgramCache

    class _Cache(base):  # type: ignore[misc, valid-type]
        """pyrender's program cache, serving ``gbuffer.frag`` / ``gbuffer.vert`` in place of ``mesh.frag`` /
        ``mesh.vert``."""

        def __init__(self) -> None:
            super().__init__()  # pyrender's own shader folder for everything else
            self.defines: dict[str, int] | None = None  # the current pass; None: pyrender's shaders
            self.msaa = False
            self.clockwise = False  # a pass that takes clockwise triangles for front faces (segment())

        def get_program(self, vertex_shader: str, fragment_shader: str, geometry_shader: str | None = None,
                        defines: dict[str, Any] | None = None) -> Any:
            if self.defines is not None:  # a G-buffer pass; otherwise exactly pyrender's behaviour
                # pyrender asks for a program per primitive right after enabling GL_MULTISAMPLE in
                # its forward pass: the one place to turn it off without editing pyrender.
                if not self.msaa:
                    GL.glDisable(GL.GL_MULTISAMPLE)
                # (pyrender never sets the winding; segment() turns it for one pass and back after)
                GL.glFrontFace(GL.GL_CW if self.clockwise else GL.GL_CCW)
                if fragment_shader == "mesh.frag":
                    defines = {**(defines or {}), **self.defines}
                    fragment_shader = os.fspath(SHADER_DIR / "gbuffer.frag")  # absolute: os.path.join keeps it
                    if vertex_shader == "mesh.vert":  # (mesh.vert + frag_mirrored: an instance's mirror, inst_m)
                        vertex_shader = os.fspath(SHADER_DIR / "gbuffer.vert")
            return super().get_program(vertex_shader, fragment_shader, geometry_shader, defines)

    return _Cache


def _delete_renderer(r: Any) -> None:
    """``OffscreenRenderer.delete()`` without its ``eglTerminate``.

    pyrender 0.1.45's EGL platform terminates the EGL display when a renderer is deleted; every
    renderer of the process shares that display, so deleting one breaks the others
    (``eglMakeCurrent`` fails with EGL_BAD_DISPLAY). This frees the GL objects and destroys only
    this renderer's context.
    """
    platform = r._platform
    if platform is None:
        return
    with current(r):  # (what was current in this thread before, an engine's context say, is current again after)
        r._renderer.delete()  # GL objects; also unbinds the scene's meshes from this context
    if type(platform).__name__ == "EGLPlatform" and getattr(platform, "_egl_display", None) is not None:
        from OpenGL import EGL

        if ctypes.cast(EGL.eglGetCurrentContext(), ctypes.c_void_p).value == \
                ctypes.cast(platform._egl_context, ctypes.c_void_p).value:  # (destroyed only once released)
            EGL.eglMakeCurrent(platform._egl_display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
        if platform._egl_context is not None:
            EGL.eglDestroyContext(platform._egl_display, platform._egl_context)
        platform._egl_context = None
        platform._egl_display = None  # not eglTerminate: the display is shared
    else:
        platform.delete_context()
    r._renderer = None
    r._platform = None


class GBufferRenderer:
    """A pyrender ``OffscreenRenderer`` that draws G-buffer passes of a ``pyrender.Scene``.

    Args:
        width, height: frame size in pixels.
        msaa: keep pyrender's 4x MSAA resolve (edge pixels average the surfaces they cover);
            default off: point-sampled G-buffers. Requires ``normal_bits=8``.
        normal_bits: 12 (two components per pass, packed) or 8 (three per pass).
        platform: ``"egl"`` or ``"osmesa"`` (see :func:`rtp.plugins.pyrender._gl.import_pyrender`).
        renderer: a ``pyrender.OffscreenRenderer`` of the same size to borrow (pyrender binds a
            scene's meshes to one renderer's context, so the one that draws the displayed frames
            must also draw the G-buffers). Its program cache is replaced during this renderer's own
            passes only (so several adapters may borrow one renderer); its own draws are unchanged.
            Default: a renderer of its own.
    """

    def __init__(self, width: int, height: int, *, msaa: bool = False, normal_bits: int = 12,
                 platform: str | None = None, renderer: Any | None = None) -> None:
        if isinstance(normal_bits, bool) or normal_bits not in (8, 12):
            raise ParameterError(f"normal_bits: expected 8 or 12, got {normal_bits!r}", "normal_bits")
        if not isinstance(msaa, (bool, np.bool_)):  # (numpy's True was refused; albedo= and the flags take it)
            raise ParameterError(f"msaa: expected True or False, got {msaa!r}", "msaa")
        if msaa and normal_bits != 8:
            raise ParameterError("msaa=True averages samples, which breaks 12-bit packed normals; use normal_bits=8",
                                 "msaa")
        self.width, self.height = int(width), int(height)
        self.msaa, self.normal_bits = bool(msaa), int(normal_bits)
        self._pyrender = import_pyrender(platform)
        self._owns = renderer is None
        if renderer is None:
            renderer = offscreen_renderer(self._pyrender, self.width, self.height)
        elif getattr(renderer, "_renderer", True) is None or getattr(renderer, "_platform", True) is None:
            raise PyrenderAdapterError("renderer: this pyrender.OffscreenRenderer has been deleted (delete() frees its "
                                       "context); borrow the renderer the engine draws with, while it lives")
        elif (renderer.viewport_width, renderer.viewport_height) != (self.width, self.height):
            raise PyrenderAdapterError(
                f"the renderer draws {renderer.viewport_width}x{renderer.viewport_height}, the adapter "
                f"{self.width}x{self.height}"
            )
        self._renderer: Any | None = renderer
        self.busy = busy_lock(renderer)  # (held through each call of the adapter's: one_call)
        # pyrender.Renderer owns one program cache; this one stands in for it during the G-buffer passes
        # (_render), so that adapters sharing a renderer each draw with their own
        self._cache = _program_cache_class()()
        self._cache.msaa = self.msaa

    @property
    def renderer(self) -> Any:
        """The ``pyrender.OffscreenRenderer`` the passes run on (the adapter's own or a borrowed one)."""
        if self._renderer is None:
            raise PyrenderAdapterError("this adapter has been closed")
        return self._renderer

    def close(self) -> None:
        """Free the G-buffer programs and, unless the renderer is borrowed, the GL context. Idempotent. Waits for a
        call under way in another thread (of any adapter borrowing the renderer, or its frame source) to return."""
        with self.busy:
            self._close()

    def _close(self) -> None:
        r, self._renderer = self._renderer, None
        if r is None:
            return
        try:
            with current(r):
                self._cache.clear()  # our programs live in the renderer's context
        except PyrenderAdapterError as exc:  # (another thread holds the context: they are left in it)
            log.warning("could not free the pyrender adapter's G-buffer programs: %s", exc)
        except Exception as exc:  # pragma: no cover - a context already gone
            log.debug("could not free the G-buffer programs: %s", exc)
        if self._owns:
            try:
                _delete_renderer(r)
            except PyrenderAdapterError as exc:
                log.warning("could not delete the pyrender adapter's renderer (its GL context is left): %s", exc)
            except Exception as exc:  # (the shared EGL display terminated under it, by a renderer rtp did not make)
                log.debug("could not delete the adapter's renderer: %s", exc)

    @property
    def closed(self) -> bool:
        return self._renderer is None

    def _passes(self, scalars: Sequence[str]) -> list[tuple[dict[str, int], list[str]]]:
        """``(defines, slots)`` of the scalar passes (normal components, roughness, metallic) for the
        ones asked for, packed two per pass at 12 bits (or three at 8)."""
        per = 3 if self.normal_bits == 8 else 2
        names = [n for n in ("normal.z", "normal.x", "normal.y", *MATERIAL) if n in scalars]
        out = []
        for i in range(0, len(names), per):
            group = names[i : i + per]
            ids = [_SLOTS[n] for n in group] + [0] * (per - len(group))
            if per == 3:
                d = {"RTP_GBUF_MODE": _MODE_8, "RTP_SLOT_R": ids[0], "RTP_SLOT_G": ids[1], "RTP_SLOT_B": ids[2]}
            else:
                d = {"RTP_GBUF_MODE": _MODE_12, "RTP_SLOT_P": ids[0], "RTP_SLOT_Q": ids[1]}
            out.append((d, group))
        return out

    @contextmanager
    def _black_background(self, scene: Any) -> Iterator[None]:
        old = np.array(scene.bg_color, copy=True)
        scene.bg_color = np.zeros(4)
        try:
            yield
        finally:
            scene.bg_color = old

    def draw(self, scene: Any, flags: int | None = None, seg_node_map: dict[Any, Any] | None = None) -> Any:
        """pyrender's own ``render(scene, flags, seg_node_map)`` on this renderer (no G-buffer patch), with
        pyrender's errors turned into :class:`PyrenderAdapterError`."""
        flags = self._pyrender.RenderFlags.NONE if flags is None else flags
        renderer = self.renderer
        if (renderer.viewport_width, renderer.viewport_height) != (self.width, self.height):
            # (a borrowed renderer resized since: its images came back at the new size, and inputs() failed
            # with numpy's broadcast ValueError)
            raise PyrenderAdapterError(
                f"the renderer now draws {renderer.viewport_width}x{renderer.viewport_height}, the adapter "
                f"{self.width}x{self.height}: its viewport was changed after the adapter borrowed it; make an "
                "adapter of the new size (or give the renderer its size back)")
        out = draw(renderer, scene, flags, seg_node_map,
                   fix="pass that renderer to the adapter (Adapter(..., renderer=r)), or draw the displayed frames "
                       "with adapter.render(...)")
        camera = scene.main_camera_node.camera
        if not isinstance(camera, self._pyrender.OrthographicCamera):
            return out
        if flags & self._pyrender.RenderFlags.DEPTH_ONLY:
            return orthographic_depth(out, camera)
        return out[0], orthographic_depth(out[1], camera)

    def _render(self, scene: Any, defines: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
        inner = self.renderer._renderer
        before, inner._program_cache = inner._program_cache, self._cache
        self._cache.defines = defines
        try:
            with self._black_background(scene):
                # Not RenderFlags.DEPTH_ONLY: pyrender culls back faces of double-sided materials there.
                out = self.draw(scene)
        finally:
            self._cache.defines = None
            inner._program_cache = before
        colour, depth = out
        return np.ascontiguousarray(colour[..., :3]), np.ascontiguousarray(depth, dtype=np.float32)

    def segment(self, scene: Any, colours: dict[Any, tuple[int, int, int]], depth: np.ndarray | None = None
                ) -> np.ndarray:
        """pyrender's segmentation image (``RenderFlags.SEG``) of the mesh nodes in ``colours`` (RGB, 0-255
        each), without multisampling, so that every pixel holds one node's colour, never a blend of two:
        ``(H, W, 3)`` uint8, top-left origin, black on background.

        pyrender culls back faces in its segmentation pass whatever the material, so a double-sided surface
        seen from behind (or a mirrored node's) is missing there and the pixel shows what lies behind it.
        Given ``depth``, the G-buffers' depth (which draws such surfaces), the pixels whose segmentation depth
        is not that depth take their colour from a second pass that draws the back faces, where its depth is."""
        colour, seg_depth = self._segment_pass(scene, colours, clockwise=False)
        if depth is None:
            return colour
        missed = (depth > 0.0) & ~_same_depth(seg_depth, depth)
        if missed.any():
            back, back_depth = self._segment_pass(scene, colours, clockwise=True)
            take = missed & _same_depth(back_depth, depth)
            colour[take] = back[take]
            log.debug("segmentation: %d pixel(s) of back faces", int(take.sum()))
        return colour

    def _segment_pass(self, scene: Any, colours: dict[Any, tuple[int, int, int]], *, clockwise: bool
                      ) -> tuple[np.ndarray, np.ndarray]:
        renderer = self.renderer
        inner = renderer._renderer
        before, inner._program_cache = inner._program_cache, self._cache
        self._cache.defines = {}  # (a pass of ours: multisampling off; pyrender's segmentation shaders untouched)
        self._cache.clockwise = clockwise
        try:
            colour, depth = self.draw(scene, self._pyrender.RenderFlags.SEG, colours)
        finally:
            self._cache.defines = None
            self._cache.clockwise = False
            inner._program_cache = before
            if clockwise:  # (the renderer's own draws take pyrender's counter-clockwise front faces)
                from OpenGL import GL

                with current(renderer):
                    GL.glFrontFace(GL.GL_CCW)
        return np.array(colour[..., :3]), np.asarray(depth, np.float32)

    def render(self, scene: Any, *, albedo: bool = False, normals: Sequence[str] = (),
               material: Sequence[str] = ()) -> GBuffers:
        """Draw the passes needed for ``albedo``, the normal components in ``normals``
        (``"normal.x"``, ``"normal.y"``, ``"normal.z"``) and the material scalars in ``material``
        (``"roughness"``, ``"metallic"``) from the scene's main camera; the scalars share passes.

        Depth always comes back (from the first pass; an albedo pass when nothing else is asked).
        """
        unknown = [m for m in material if m not in MATERIAL]
        if unknown:
            raise ParameterError(f"material: expected names from {MATERIAL}, got {unknown}", "material")
        depth: np.ndarray | None = None
        out_albedo: np.ndarray | None = None
        out_normal: np.ndarray | None = None
        scalars: dict[str, np.ndarray] = {}
        if albedo:
            rgb, depth = self._render(scene, {"RTP_GBUF_MODE": _MODE_ALBEDO})
            out_albedo = rgb.astype(np.float32) / 255.0
        passes = self._passes([*normals, *material])
        if any(n.startswith("normal.") for _, group in passes for n in group):
            out_normal = np.zeros((self.height, self.width, 3), np.float32)
        for defines, group in passes:
            rgb, d = self._render(scene, defines)
            depth = d if depth is None else depth
            if self.normal_bits == 8:
                vals = [rgb[..., k].astype(np.float32) / 255.0 for k in range(3)]
            else:
                vals = list(unpack12(rgb))
            for name, v in zip(group, vals):
                if name.startswith("normal."):
                    out_normal[..., "xyz".index(name[-1])] = v * 2.0 - 1.0  # type: ignore[index]
                else:
                    scalars[name] = v
        if depth is None:
            _, depth = self._render(scene, {"RTP_GBUF_MODE": _MODE_ALBEDO})
        mask = depth > 0.0
        if out_albedo is not None:
            out_albedo[~mask] = 0.0
        if out_normal is not None:
            out_normal[~mask] = 0.0
        for v in scalars.values():
            v[~mask] = 0.0
        return GBuffers(depth=np.where(mask, depth, 0.0).astype(np.float32), albedo=out_albedo, normal=out_normal,
                        roughness=scalars.get("roughness"), metallic=scalars.get("metallic"))
