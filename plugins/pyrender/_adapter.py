"""The pyrender adapter: a ``pyrender.Scene`` and two camera poses in, the model's input tensor out."""

from __future__ import annotations

import logging
import time
import weakref
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from rtp.sdk import (
    DEFAULT_REPROJECTION_TOLERANCE,
    MAX_REPROJECTION_TOLERANCE,
    ParameterError,
    input_planes,
    reproject_positions,
)
from rtp.sdk.adapters import Adapter as _BaseAdapter
from rtp.sdk.adapters import AdapterFrameError

from ._errors import PyrenderAdapterError
from ._gbuffer import MATERIAL, GBufferRenderer, GBuffers, one_call

if TYPE_CHECKING:
    from ._source import PyrenderFrameSource

__all__ = ["Adapter", "SceneFrame"]

log = logging.getLogger("rtp.plugins.pyrender")
#: How far past [0, 1] a float frame may reach unremarked (a display-encoded image's rounding).
_RANGE_SLACK = 1e-3

_REPROJECTED = ("reprojected.r", "reprojected.g", "reprojected.b")
_ALBEDO = ("albedo.r", "albedo.g", "albedo.b")
_NORMAL = ("normal.x", "normal.y", "normal.z")
_MOTION = ("motion.x", "motion.y")
# Planes derived from the RGB ones: Rec.601 luma (sdk.luma), as the metrics measure it.
_REPROJECTED_Y, _ALBEDO_Y = "reprojected.y", "albedo.y"
_DIFFERENCES = ("reprojected.y.dx", "reprojected.y.dy", "reprojected.y.blocks", "reprojected.y.tiles")
_ALBEDO_VARIANCES = ("albedo.y.blocks", "albedo.y.tiles")
#: The ``specular`` channel of everything pyrender shades: its dielectric F0 is a fixed 4 %
#: (``mesh.frag``: ``dialectric_spec = vec3(0.04)``), specular 0.5 in ``sdk.CHANNELS`` terms.
PYRENDER_SPECULAR = 0.5


def _pose(value: Any, name: str) -> np.ndarray:
    try:
        m = np.asarray(value)
        real = m.dtype.kind in "iuf"
        m = m.astype(np.float64) if real else m
    except (TypeError, ValueError, OverflowError):
        real, m = False, np.empty(0)
    with np.errstate(all="ignore"):  # finite in float32 too: pyrender and the shaders compute in float32
        finite = real and m.shape == (4, 4) and bool(np.isfinite(m.astype(np.float32)).all())
    if not finite:
        got = f"{m.dtype} {m.shape}" if real or isinstance(value, np.ndarray) else type(value).__name__
        raise PyrenderAdapterError(f"{name} must be a finite 4x4 camera-to-world matrix, got {got}")
    if not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0)):
        raise PyrenderAdapterError(f"{name} must be affine (last row 0, 0, 0, 1), got {m[3].tolist()}")
    try:
        with np.errstate(all="ignore"):
            invertible = bool(np.isfinite(np.linalg.inv(m).astype(np.float32)).all())
    except np.linalg.LinAlgError:
        invertible = False
    if not invertible:
        raise PyrenderAdapterError(f"{name} must be an invertible camera-to-world matrix, got a singular one")
    rotation = m[:3, :3]
    if not np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-4):  # (a camera is placed, never scaled or sheared)
        scales = np.linalg.norm(rotation, axis=0)
        raise PyrenderAdapterError(f"{name} must be a rigid camera-to-world matrix (a rotation and a translation), "
                                   f"got one that scales or shears (its axes' lengths {np.round(scales, 4).tolist()}): "
                                   "depth, normals and motion would be read in a distorted view space")
    if np.linalg.det(rotation) < 0.0:  # (orthonormal, but a reflection: a left-handed camera frame)
        raise PyrenderAdapterError(f"{name} must be a rigid camera-to-world matrix (a rotation and a translation), "
                                   "got one that mirrors (its rotation's determinant is -1): pyrender would draw the "
                                   "frame mirrored, with the faces' winding and so culling and two-sided normals "
                                   "turned; the camera's axes are right-handed (x right, y up, looking down -z)")
    return m


def _affine(value: Any, name: str) -> np.ndarray:
    """``value`` as a finite affine 4x4 float64 matrix (a node's local pose), or a PyrenderAdapterError."""
    try:
        m = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        m = np.empty(0)
    if m.shape != (4, 4) or not np.isfinite(m).all() or not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0)):
        raise PyrenderAdapterError(f"{name} must be a finite affine 4x4 pose (last row 0, 0, 0, 1), got "
                                   f"{m.shape if m.size else type(value).__name__}")
    return m


@contextmanager
def _nodes_at(scene: Any, poses: dict[Any, np.ndarray] | None) -> Iterator[None]:
    """``scene`` with the nodes of ``poses`` (checked local poses; None: none) at those poses, put back
    afterwards."""
    poses = poses or {}
    saved = {n: np.array(n.matrix, copy=True) for n in poses}
    try:
        for n, m in poses.items():
            scene.set_pose(n, m)
        yield
    finally:
        for n, m in saved.items():
            scene.set_pose(n, m)


def _id_colour(i: int) -> tuple[int, int, int]:
    """The segmentation colour of mesh node number ``i`` (0: not moved), 24 bits."""
    return i & 255, (i >> 8) & 255, (i >> 16) & 255


def _names(value: Any, allowed: tuple[str, ...], name: str) -> tuple[str, ...]:
    """``value`` as a tuple of names from ``allowed`` (a :class:`ParameterError` naming ``name`` otherwise)."""
    items = None
    if not isinstance(value, (str, bytes)) and isinstance(value, Iterable):
        try:
            items = tuple(value)
        except (TypeError, ValueError):
            items = None
    if items is None or not all(isinstance(v, str) and v in allowed for v in items):
        raise ParameterError(f"{name}: expected names from {allowed}, got {value!r}", name)
    return items


@dataclass(frozen=True)
class SceneFrame:
    """One frame of a ``pyrender.Scene``: the frame :meth:`Adapter.inputs` reads.

    Attributes:
        scene: the ``pyrender.Scene`` (static between the two frames; only the camera moves). Its
            main camera node is moved to each pose while rendering and put back after.
        pose: current 4x4 camera-to-world matrix (pyrender/OpenGL camera convention: the camera
            looks down its -Z axis, Y up).
        prev_pose: previous camera-to-world matrix; needed for ``reprojected.*``, ``seen`` and
            ``motion.*``.
        prev_colour: the previous displayed frame, ``(H, W, 3)`` (or RGBA) uint8 or float in
            [0, 1], display-encoded, top-left origin (what ``OffscreenRenderer.render`` returns);
            needed for ``reprojected.*`` and ``seen``.
        prev_depth: its ``(H, W)`` linear depth, 0 on background. None (recommended): the depth of
            the previous ``inputs`` call when it was at ``prev_pose`` with the same scene and camera
            (the usual frame loop), else rendered (one extra pass). pyrender's own ``render()``
            depth comes from its 4x MSAA target (a sample off the pixel centre), which costs the
            disocclusion test on grazing surfaces (docs/adapters.md). With an ``OrthographicCamera`` that
            depth is not linear depth at all (pyrender linearises every camera's as a perspective's):
            :meth:`Adapter.render` gives it converted; a renderer's own needs ``n + f - n f / d``.
        camera, prev_camera: ``pyrender`` cameras (for their projections); default: the scene's
            main camera for both.
        prev_node_poses: the nodes that moved since the previous frame, each with its previous *local*
            pose (its ``node.matrix`` before this frame's ``scene.set_pose``): a mapping of
            ``pyrender.Node`` to 4x4 matrix. None (default): nothing but the camera moved. With it, the
            adapter makes the frame's motion vectors (a segmentation pass tells which mesh node each
            pixel shows, and each moved node's pixels are followed by its own move, its children's
            too), so that a moving object is fetched from where it was (``sdk.input_planes``'
            ``motion``) rather than from what was behind it.
    """

    scene: Any
    pose: Any
    prev_pose: Any | None = None
    prev_colour: Any | None = None
    prev_depth: Any | None = None
    camera: Any | None = None
    prev_camera: Any | None = None
    prev_node_poses: Any | None = None


class Adapter(_BaseAdapter[SceneFrame]):
    """Builds a model's input tensor from a ``pyrender.Scene`` (headless EGL or OSMesa).

    Channels (names and value conventions of :data:`rtp.sdk.CHANNELS`):

    * ``reprojected.r/g/b`` and ``seen``: the previous displayed frame fetched where each pixel
      was in the previous frame, with the depth-tested seen mask, computed on the CPU by
      :func:`rtp.sdk.reproject` (the reference definition both plugins follow).
    * ``reprojected.y``, ``albedo.y``: the Rec.601 luma (:func:`rtp.sdk.luma`) of those RGB planes.
    * ``albedo.r/g/b``: glTF base colour (factor x texture x vertex colour), display-encoded sRGB.
    * ``normal.x/y/z``: unit view-space shading normal (normal maps included; two-sided). Where the
      mesh has no normals, or a zero one, the geometric normal (screen-space derivatives), facing the
      camera as the reference renderer's does.
    * ``roughness``, ``metallic``: the material's perceptual roughness and metalness as pyrender
      shades with them (factor x metallic-roughness texture, read from its R and G channels as
      pyrender 0.1.45 does; specular-glossiness materials: 1 - glossiness and 0); 12 bits, sharing
      passes with the normal components.
    * ``specular``: 0.5 on geometry. pyrender's metallic-roughness shading gives every dielectric
      F0 = 4 %, which is specular 0.5 in rtp's convention: the value the image is shaded with (a
      scene converted from rtp loses its own specular values, which pyrender cannot shade).
    * ``depth``: linear view depth from pyrender's 24-bit depth buffer.
    * ``depth.edge``: :func:`rtp.sdk.depth_edges` of that depth.
    * ``reprojected.y.dx/dy``: :func:`rtp.sdk.pixel_differences` of ``reprojected.y``.
    * ``reprojected.y.blocks``, ``albedo.y.blocks``: :func:`rtp.sdk.block_variances` of the luma.
    * ``reprojected.y.tiles``, ``albedo.y.tiles``: :func:`rtp.sdk.tile_variances` of the luma.
    * ``motion.x/y``: screen motion of a static scene under the camera move (pixels, previous
      minus current position, x right, y down), from depth and the two cameras; 0 on background.

    Anything else (shadow, emissive) raises :class:`rtp.sdk.adapters.UnsupportedChannelError` at
    construction: pyrender's shading has no buffer that means the same thing.

    Args:
        channels: the channels to produce, in order; normally ``predictor.metadata.inputs``.
        width, height: frame size in pixels (the size of the previous frame and of the output).
        msaa: keep pyrender's 4x MSAA resolve in the G-buffer passes (edge pixels then average the
            surfaces they cover); default off: point-sampled G-buffers like the reference renderer.
            Needs ``normal_bits=8``.
        normal_bits: 12 (default; two normal components per pass) or 8 (three per pass).
        reprojection_tolerance: relative depth tolerance of the disocclusion test, in
            [0, ``sdk.MAX_REPROJECTION_TOLERANCE``] (default ``sdk.DEFAULT_REPROJECTION_TOLERANCE``).
        platform: ``"egl"`` (default) or ``"osmesa"``; must be decided before anything imports
            PyOpenGL.
        renderer: the ``pyrender.OffscreenRenderer`` (same size) that draws the displayed frames,
            to borrow. pyrender binds a scene's meshes to one renderer's GL context, so a scene
            drawn by another renderer cannot be drawn by the adapter's own. Either pass that
            renderer here, or draw the displayed frames with :meth:`render`. While borrowed its
            program cache is the adapter's; its own draws are unchanged (:meth:`close` restores it).

    Each call (the constructor and :meth:`close` too) makes the renderer's GL context current and then
    gives back what was current before in the calling thread (an engine's own context, or none), so the
    adapter may be built in one thread and used or closed in another, one call at a time: a call (:meth:`inputs`,
    :meth:`render`, :meth:`gbuffers`) while another thread's holds the renderer (this adapter's, another adapter's
    borrowing it, or its frame source's) is a :class:`PyrenderAdapterError`, and the call under way goes on
    unharmed; :meth:`close` waits for it. A borrowed
    renderer that pyrender drew with in another thread stays current there (pyrender never releases it):
    the call is then a :class:`PyrenderAdapterError` naming the thread (docs/adapters.md).

    Example::

        with Adapter.for_predictor(predictor, 640, 360) as adapter:
            prev_colour, _ = adapter.render(scene, prev_pose)   # pyrender's lit image
            x = adapter.inputs(SceneFrame(scene, pose, prev_pose, prev_colour))   # (C, H, W) float32
            rates = predictor.shading_rates(x[None])
    """

    name: ClassVar[str] = "pyrender"
    supported_channels: ClassVar[frozenset[str]] = frozenset(
        (*_REPROJECTED, _REPROJECTED_Y, *_DIFFERENCES, "seen", *_ALBEDO, _ALBEDO_Y, *_ALBEDO_VARIANCES, *_NORMAL,
         *MATERIAL, "specular", "depth", "depth.edge", *_MOTION)
    )
    frame_type: ClassVar[type] = SceneFrame

    def __init__(
        self,
        channels: Iterable[str],
        width: int,
        height: int,
        *,
        msaa: bool = False,
        normal_bits: int = 12,
        reprojection_tolerance: float = DEFAULT_REPROJECTION_TOLERANCE,
        platform: str | None = None,
        renderer: Any | None = None,
    ) -> None:
        super().__init__(channels, width, height)
        tol = reprojection_tolerance
        # (the range sdk.input_planes takes, checked here: past it the adapter was made, then refused every frame)
        if isinstance(tol, bool) or not isinstance(tol, (int, float, np.integer, np.floating)) \
                or not 0.0 <= tol <= MAX_REPROJECTION_TOLERANCE:
            raise ParameterError(f"reprojection_tolerance: expected a relative depth tolerance in "
                                 f"[0, {MAX_REPROJECTION_TOLERANCE:g}], got {tol!r}", "reprojection_tolerance")
        if renderer is not None and not hasattr(renderer, "viewport_width"):
            raise AdapterFrameError(f"renderer: expected a pyrender.OffscreenRenderer to borrow, got "
                                    f"{type(renderer).__name__}")
        self.reprojection_tolerance = float(reprojection_tolerance)
        self._gbuf = GBufferRenderer(self.width, self.height, msaa=msaa, normal_bits=normal_bits, platform=platform,
                                     renderer=renderer)
        self.msaa, self.normal_bits = self._gbuf.msaa, self._gbuf.normal_bits
        # the last inputs() call's (scene, camera, pose, depth): the scene and camera held by weak references, so
        # that a later scene or camera given the address of a freed one (its id()) is not taken for it
        self._last: tuple[weakref.ref[Any], weakref.ref[Any], np.ndarray, np.ndarray] | None = None
        self._warned: set[str] = set()  # frame fields already said to be out of [0, 1]
        log.debug("pyrender adapter %dx%d for %s (msaa=%s, normal_bits=%d)", self.width, self.height,
                  ", ".join(self.channels), self.msaa, self.normal_bits)

    # ------------------------------------------------------------------ cameras
    def _check_scene(self, scene: Any, camera: Any | None = None, prev_camera: Any | None = None) -> None:
        """``scene`` is a ``pyrender.Scene`` and the cameras, where given, ``pyrender`` cameras."""
        pyrender = self._gbuf._pyrender
        if not isinstance(scene, pyrender.Scene):
            raise PyrenderAdapterError(f"scene: expected a pyrender.Scene, got {type(scene).__name__}")
        for name, cam in (("camera", camera), ("prev_camera", prev_camera)):
            if cam is not None and not isinstance(cam, pyrender.Camera):
                raise PyrenderAdapterError(f"{name}: expected a pyrender camera (or None), got {type(cam).__name__}")

    def _camera(self, scene: Any, camera: Any | None) -> Any:
        """``camera``, else the scene's main camera, checked to give a depth buffer."""
        self._check_scene(scene, camera)
        if camera is None:
            node = scene.main_camera_node
            if node is None:
                raise PyrenderAdapterError("the scene has no camera; add one (scene.add(camera)) or pass camera=...")
            camera = node.camera
        if not float(camera.znear) > 0.0:  # (pyrender's PerspectiveCamera and IntrinsicsCamera take znear=0)
            raise PyrenderAdapterError(
                f"{type(camera).__name__} has znear={camera.znear}: its projection is singular and every pixel of its "
                "depth buffer reads as background, so the G-buffers would be all 0; give the camera a znear > 0")
        return camera

    def projection(self, scene: Any, camera: Any | None = None) -> np.ndarray:
        """The 4x4 OpenGL projection (view to clip) pyrender uses for ``camera`` (default: the
        scene's main camera) at this adapter's size."""
        return np.asarray(self._camera(scene, camera).get_projection_matrix(self.width, self.height), np.float64)

    @contextmanager
    def _posed(self, scene: Any, camera: Any | None, pose: np.ndarray) -> Iterator[None]:
        """Temporarily make ``camera`` at ``pose`` the scene's main camera; restored afterwards."""
        node = scene.main_camera_node
        if node is not None and (camera is None or node.camera is camera):
            # scene.set_pose sets the node's *local* pose and get_pose gives the world one: a camera under a
            # parent node (a rig) gets the local pose that puts it at ``pose`` in the world, and its own back
            old = np.array(node.matrix, copy=True)
            try:
                scene.set_pose(node, np.eye(4))
                parent = scene.get_pose(node)
                try:
                    local = pose if np.array_equal(parent, np.eye(4)) else np.linalg.solve(parent, pose)
                except np.linalg.LinAlgError:
                    raise PyrenderAdapterError("the main camera's parent node has a singular world pose (a zero "
                                               "scale): the camera cannot be placed at the pose asked for") from None
                scene.set_pose(node, local)
                yield
            finally:
                scene.set_pose(node, old)
            return
        if camera is None:
            raise PyrenderAdapterError("the scene has no camera; add one (scene.add(camera)) or pass camera=...")
        tmp = scene.add(camera, pose=pose)
        scene.main_camera_node = tmp
        try:
            yield
        finally:
            scene.remove_node(tmp)
            if node is not None:
                scene.main_camera_node = node

    # ------------------------------------------------------------------ rendering
    @property
    def renderer(self) -> Any:
        """The ``pyrender.OffscreenRenderer`` the adapter draws with (its own or the borrowed one);
        :class:`rtp.sdk.adapters.AdapterClosedError` once the adapter is closed."""
        self._check_open()
        return self._gbuf.renderer

    def render(self, scene: Any, pose: Any, *, camera: Any | None = None, flags: int | None = None) -> Any:
        """pyrender's own image of ``scene`` from ``pose``, on the adapter's renderer: what
        ``OffscreenRenderer.render(scene, flags)`` returns (by default ``(colour (H, W, 3) uint8,
        depth (H, W) float32)``, top-left origin), with the camera moved to ``pose`` and back."""
        self._check_open()
        self._check_scene(scene, camera)
        pose = _pose(pose, "pose")
        all_flags = sum(v for k, v in vars(self._gbuf._pyrender.RenderFlags).items() if k.isupper() and
                        isinstance(v, int) and v & (v - 1) == 0)
        if flags is not None and (isinstance(flags, bool) or not isinstance(flags, (int, np.integer))
                                  or flags < 0 or flags & ~all_flags):
            raise ParameterError(f"flags: expected None or pyrender.RenderFlags values combined with |, got {flags!r}",
                                 "flags")
        with self._one_call("render"), self._posed(scene, camera, pose):
            return self._gbuf.draw(scene, flags)

    def gbuffers(self, scene: Any, pose: Any, *, camera: Any | None = None, albedo: bool = True,
                 normals: Iterable[str] = _NORMAL, material: Iterable[str] = ()) -> GBuffers:
        """Render the G-buffers of ``scene`` seen from ``pose`` (4x4 camera-to-world, OpenGL camera
        convention: the camera looks down its -Z axis, Y up).

        Returns:
            :class:`GBuffers`: ``depth`` ``(H, W)``, ``albedo`` ``(H, W, 3)``, ``normal`` ``(H, W, 3)``,
            and the ``material`` scalars asked for (``"roughness"``, ``"metallic"``) ``(H, W)``,
            float32, top-left origin, 0 on background.
        """
        self._check_open()
        with self._one_call("gbuffers"):
            return self._gbuffers(scene, pose, camera=camera, albedo=albedo, normals=normals, material=material)

    def _gbuffers(self, scene: Any, pose: Any, *, camera: Any | None = None, albedo: bool = True,
                  normals: Iterable[str] = _NORMAL, material: Iterable[str] = ()) -> GBuffers:
        """:meth:`gbuffers` of a call that holds the renderer (:meth:`inputs`' too: a close() waiting meanwhile in
        another thread has marked the adapter closed, and the call under way finishes)."""
        self._check_scene(scene, camera)
        pose = _pose(pose, "pose")
        if not isinstance(albedo, (bool, np.bool_)):
            raise ParameterError(f"albedo: expected True or False, got {albedo!r}", "albedo")
        normals, material = _names(normals, _NORMAL, "normals"), _names(material, MATERIAL, "material")
        self._camera(scene, camera)  # (one whose depth the passes can read)
        with self._posed(scene, camera, pose):
            return self._gbuf.render(scene, albedo=bool(albedo), normals=normals, material=material)

    def _one_call(self, what: str) -> Any:
        """Hold the renderer for one call (``what``), or a :class:`PyrenderAdapterError` where another thread's
        call holds it (:func:`~._gbuffer.one_call`)."""
        return one_call(self._gbuf.busy, f"pyrender Adapter.{what}")

    def _frame(self, image: Any, name: str) -> np.ndarray:
        try:
            a = np.asarray(image)
        except (TypeError, ValueError, OverflowError) as exc:
            raise PyrenderAdapterError(f"{name} must be an (H, W, 3) or (H, W, 4) image, got {type(image).__name__}") \
                from exc
        if a.ndim != 3 or a.shape[:2] != (self.height, self.width) or a.shape[2] not in (3, 4):
            raise PyrenderAdapterError(
                f"{name} must be (H, W, 3) or (H, W, 4) with (H, W) = ({self.height}, {self.width}), got {a.shape}"
            )
        a = a[..., :3]
        if a.dtype == np.uint8:
            return a.astype(np.float32) / 255.0
        if not np.issubdtype(a.dtype, np.floating):
            raise PyrenderAdapterError(f"{name} must be uint8 or float in [0, 1], got {a.dtype}")
        if not np.isfinite(a).all():
            raise PyrenderAdapterError(f"{name} must be finite, got NaN or infinity")
        lo, hi = float(a.min(initial=0.0)), float(a.max(initial=0.0))
        if (lo < -_RANGE_SLACK or hi > 1.0 + _RANGE_SLACK) and name not in self._warned:
            self._warned.add(name)  # (once an adapter: an engine hands the same kind of frame every frame)
            log.warning("%s spans [%.3g, %.3g]: clipped to [0, 1]; the adapter reads display-encoded colour, so tone-map "
                        "an HDR frame first (said once for this adapter)", name, lo, hi)
        return np.clip(a.astype(np.float32), 0.0, 1.0)

    def inputs(self, frame: SceneFrame) -> np.ndarray:
        """The model input for ``frame`` (see :class:`SceneFrame`): float32 ``(C, H, W)`` in the
        order of :attr:`channels`, top-left origin."""
        with self._one_call("inputs"):
            return self._inputs(frame)

    def _inputs(self, frame: SceneFrame) -> np.ndarray:
        """:meth:`inputs` of a call that holds the renderer."""
        scene, pose, prev_pose, prev_colour, prev_depth = (frame.scene, frame.pose, frame.prev_pose,
                                                           frame.prev_colour, frame.prev_depth)
        camera, prev_camera = frame.camera, frame.prev_camera
        t0 = time.perf_counter()
        self._check_scene(scene, camera, prev_camera)
        pose = _pose(pose, "pose")
        wanted = set(self.channels)
        temporal = wanted & {*_REPROJECTED, _REPROJECTED_Y, *_DIFFERENCES, "seen", *_MOTION}
        if temporal and prev_pose is None:
            raise PyrenderAdapterError(f"{', '.join(sorted(temporal))} need prev_pose")
        node_poses = self._node_poses(scene, frame.prev_node_poses)
        reproj = wanted & {*_REPROJECTED, _REPROJECTED_Y, *_DIFFERENCES, "seen"}
        if reproj and prev_colour is None:
            raise PyrenderAdapterError(f"{', '.join(sorted(reproj))} need prev_colour (the previous displayed frame)")
        cam = self._camera(scene, camera)
        prev_cam = cam if prev_camera is None else self._camera(scene, prev_camera)

        g = self._gbuffers(scene, pose, camera=camera, albedo=bool(wanted & {*_ALBEDO, _ALBEDO_Y, *_ALBEDO_VARIANCES}),
                          normals=[c for c in _NORMAL if c in wanted], material=[c for c in MATERIAL if c in wanted])
        buffers: dict[str, Any] = {"depth": g.depth, "albedo": g.albedo, "normal": g.normal,
                                   **{name: getattr(g, name) for name in MATERIAL}}
        if "specular" in wanted:  # pyrender's fixed dielectric F0 of 4 %
            buffers["specular"] = np.where(g.depth > 0.0, np.float32(PYRENDER_SPECULAR), np.float32(0.0))
        if temporal:
            prev_pose = _pose(prev_pose, "prev_pose")
            prev_projection = self.projection(scene, prev_cam)  # (an orthographic one's depth comes from it)
            buffers.update(view=np.linalg.inv(pose), projection=self.projection(scene, cam),
                           prev_view_projection=prev_projection @ np.linalg.inv(prev_pose),
                           prev_projection=prev_projection)
            if reproj:
                buffers["prev_colour"] = self._frame(prev_colour, "prev_colour")
                if prev_depth is None:
                    last = self._last
                    if (last is not None and last[0]() is scene and last[1]() is prev_cam
                            and np.array_equal(last[2], prev_pose)):
                        prev_depth = last[3]
                    else:
                        log.debug("no prev_depth given: rendering it at prev_pose")
                        with _nodes_at(scene, node_poses):  # (objects that moved: where they were)
                            prev_depth = self._gbuffers(scene, prev_pose, camera=prev_cam, albedo=False,
                                                        normals=()).depth
                try:
                    pd = np.asarray(prev_depth)
                    real = pd.dtype.kind in "iuf"
                except (TypeError, ValueError, OverflowError):
                    real, pd = False, np.empty(0)
                if not real or pd.shape != (self.height, self.width):
                    got = f"{pd.dtype} {pd.shape}" if real or isinstance(prev_depth, np.ndarray) else \
                        type(prev_depth).__name__
                    raise PyrenderAdapterError(f"prev_depth must be a real ({self.height}, {self.width}) array, got {got}")
                with np.errstate(over="ignore"):
                    pd = pd.astype(np.float32)
                if not np.isfinite(pd).all() or (pd < 0).any():
                    raise PyrenderAdapterError("prev_depth must be finite linear depth >= 0 (0 on background)")
                buffers["prev_depth"] = pd
        if temporal and node_poses is not None:  # objects that moved: their motion vectors
            motion = self._object_motion(scene, camera, pose, node_poses, g.depth, buffers)
            if motion is not None:
                buffers["motion"] = motion
        # the planes from the G-buffers: what every CPU adapter does (sdk.input_planes)
        out = input_planes(self.channels, **buffers, tolerance=self.reprojection_tolerance)
        try:
            self._last = (weakref.ref(scene), weakref.ref(cam), pose.copy(), g.depth)
        except TypeError:  # (a Scene or camera subclass with __slots__ and no __weakref__: no reuse)
            self._last = None
        log.debug("inputs %s in %.3f s", out.shape, time.perf_counter() - t0)
        return out

    def _node_poses(self, scene: Any, prev_node_poses: Any) -> dict[Any, np.ndarray] | None:
        """``prev_node_poses`` checked: nodes of ``scene`` to finite affine 4x4 matrices (None: None)."""
        if prev_node_poses is None:
            return None
        if not isinstance(prev_node_poses, Mapping):
            raise PyrenderAdapterError(f"prev_node_poses: expected a mapping of pyrender nodes to their previous local "
                                       f"4x4 poses, got {type(prev_node_poses).__name__}")
        moved = {}
        for node, m in prev_node_poses.items():
            if not isinstance(node, self._gbuf._pyrender.Node) or not scene.has_node(node):
                raise PyrenderAdapterError(f"prev_node_poses: {node!r} is not a node of the scene")
            moved[node] = _affine(m, f"prev_node_poses[{getattr(node, 'name', None) or 'node'}]")
        return moved

    def _object_motion(self, scene: Any, camera: Any | None, pose: np.ndarray, prev_node_poses: dict[Any, np.ndarray],
                       depth: np.ndarray,
                       buffers: dict[str, Any]) -> np.ndarray | None:
        """The frame's motion vectors ``(H, W, 2)`` (previous minus current pixel position, x right, y down)
        where some mesh node moved in the world since the previous frame, else None (the camera's move
        alone, which ``input_planes`` computes from the matrices)."""
        moved = prev_node_poses
        meshes = list(scene.mesh_nodes)
        now = {n: scene.get_pose(n) for n in meshes}
        saved = {n: np.array(n.matrix, copy=True) for n in moved}
        try:  # the previous world pose of every mesh node: the moved ones put back, their children with them
            for n, m in moved.items():
                scene.set_pose(n, m)
            then = {n: scene.get_pose(n) for n in meshes}
        finally:
            for n, m in saved.items():
                scene.set_pose(n, m)
        deltas = {n: then[n] @ np.linalg.inv(now[n]) for n in meshes if not np.allclose(then[n], now[n], atol=1e-9)}
        if not deltas:
            return None
        ids = {n: i + 1 for i, n in enumerate(deltas)}
        with self._posed(scene, camera, pose):  # which node each pixel shows: black for those that did not move
            seg = self._gbuf.segment(scene, {n: _id_colour(ids.get(n, 0)) for n in meshes}, depth).astype(np.int64)
        shown = seg[..., 0] | seg[..., 1] << 8 | seg[..., 2] << 16
        h, w = depth.shape
        xs = np.arange(w, dtype=np.float64)[None, :] + 0.5
        ys = np.arange(h, dtype=np.float64)[:, None] + 0.5
        motion = np.zeros((h, w, 2), np.float64)
        view, proj, prev_vp = buffers["view"], buffers["projection"], buffers["prev_view_projection"]
        for vp, pixels in [(prev_vp, (shown == 0) | ~np.isin(shown, list(ids.values()))),
                           *((prev_vp @ deltas[n], shown == i) for n, i in ids.items())]:
            where = pixels & (depth > 0)
            if not where.any():
                continue
            # (GL window coordinates, y up)
            qx, qy, cw = reproject_positions(depth, view, proj, vp, prev_proj=buffers["prev_projection"])
            mx = np.where(cw > 0, qx - xs, -xs - 1.0)  # (behind the previous camera: off the frame, unseen)
            my = np.where(cw > 0, (h - qy) - ys, 0.0)
            motion[where] = np.stack([mx, my], -1)[where]
        log.debug("motion vectors of %d moved mesh node(s)", len(deltas))
        return motion.astype(np.float32)

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Free the adapter's GL context, or give a borrowed renderer its program cache back. A call under way in
        another thread (this adapter's, another's borrowing its renderer, its frame source's) is waited for."""
        self._gbuf.close()

    @classmethod
    def frame_source(cls, scene: Any, width: int, height: int, **options: Any) -> PyrenderFrameSource:
        """pyrender drawing ``scene`` (an :class:`rtp.scene.Scene`, converted with
        :func:`to_pyrender_scene`), handing over :class:`SceneFrame` s; ``options``:
        ``platform=``. See :class:`rtp.plugins.pyrender.PyrenderFrameSource`."""
        from ._source import PyrenderFrameSource

        return PyrenderFrameSource(cls, scene, width, height, **options)
