"""The moderngl adapter's frame source: the reference renderer hands its G-buffers over as textures.

This is how a caller that does not know moderngl drives :class:`rtp.plugins.moderngl.Adapter`
(``sdk.adapters.get("moderngl").frame_source(scene, w, h)``); an engine of its own builds
:class:`GBufferTextures` from its own textures instead.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

from rtp.scene import Camera
from rtp.sdk import ParameterError
from rtp.sdk.adapters import Adapter as SdkAdapter
from rtp.sdk.adapters import FrameSource

from ._adapter import GBufferTextures
from ._glio import is_released, warn_not_freed, write_texture
from ._renderer import Frame, Renderer

if TYPE_CHECKING:
    from rtp.scene import Scene

    from ._adapter import Adapter

__all__ = ["ReferenceFrameSource"]

log = logging.getLogger("rtp.plugins.moderngl")


class ReferenceFrameSource(FrameSource[GBufferTextures]):
    """The reference :class:`Renderer` drawing an :class:`rtp.scene.Scene`, as an engine feeding
    the moderngl adapter: each :meth:`frame` draws the previous and the current camera and uploads
    the current G-buffers (albedo, normal, depth, material) and the previous displayed frame (final 1x1
    colour and depth) into textures of the renderer's context.

    Args:
        adapter_class: the adapter class :meth:`adapter` builds (``Adapter`` or a subclass).
        scene: the scene to draw.
        width, height: frame size in pixels.
        **renderer_options: passed to :class:`Renderer` (``ctx=`` borrows a context, which the
            source then leaves open).

    The textures are reused: a frame is valid until the next :meth:`frame` call. moderngl never
    switches contexts by itself, so :meth:`frame` makes the renderer's context current (and leaves
    it current, for the adapter's ``inputs`` that follows), as pyrender does for its own. From a thread
    other than the one holding the context, :meth:`frame` and :meth:`adapter` are a
    :class:`RendererError` naming the thread: release it there first (``renderer.ctx.__exit__(None, None,
    None)``).
    """

    def __init__(self, adapter_class: type[Adapter], scene: Scene, width: int, height: int,
                 **renderer_options: Any) -> None:
        super().__init__(adapter_class, width, height)
        self.renderer = Renderer(self.width, self.height, **renderer_options)
        try:
            self._use()
            self.renderer.load_scene(scene)
            ctx = self.renderer.ctx
            size = (self.width, self.height)
            self._textures = {name: ctx.texture(size, components, dtype="f4")
                              for name, components in (("albedo", 3), ("normal", 3), ("depth", 1),
                                                       ("material", 3), ("prev_colour", 3), ("prev_depth", 1))}
        except BaseException:
            self.renderer.release()
            raise
        for t in self._textures.values():
            t.filter = (ctx.NEAREST, ctx.NEAREST)
        self._last: tuple[Camera, Frame] | None = None
        #: The reference frames of the last :meth:`frame` call: ``(previous, current)``.
        self.frames: tuple[Frame, Frame] | None = None

    def _use(self) -> None:
        """Make the renderer's context current (moderngl's only call for it is ``__enter__``)."""
        self.renderer.ctx.__enter__()

    def adapter_options(self) -> dict[str, Any]:
        return {"ctx": self.renderer.ctx}

    def frame(self, camera: Camera, prev_camera: Camera) -> GBufferTextures:
        for name, cam in (("camera", camera), ("prev_camera", prev_camera)):
            if not isinstance(cam, Camera):
                raise ParameterError(f"{name}: expected an rtp.scene.Camera, got {type(cam).__name__}", name)
        self._use()
        last = self._last
        prev = last[1] if last is not None and last[0] == prev_camera else self.renderer.render(prev_camera)
        cur = self.renderer.render(camera, prev)
        self._last = (camera, cur)
        self.frames = (prev, cur)
        images = {"albedo": cur.albedo, "normal": cur.normal, "depth": cur.depth,
                  "material": np.stack([cur.roughness, cur.metallic, cur.specular], axis=-1),
                  "prev_colour": prev.colour["1x1"], "prev_depth": prev.depth}
        for name, image in images.items():
            write_texture(self._textures[name], np.asarray(image, np.float32))
        t = self._textures
        return GBufferTextures(
            albedo=t["albedo"], normal=t["normal"], depth=t["depth"],
            view=camera.view(), projection=camera.projection(self.width / self.height),
            prev_colour=t["prev_colour"], prev_depth=t["prev_depth"],
            prev_view_projection=prev_camera.view_projection(self.width, self.height),
            material=t["material"],
        )

    def adapter(self, channels: Iterable[str], **options: Any) -> SdkAdapter[GBufferTextures]:
        """The adapter, built in this source's context (made current first: the adapter's GL objects
        are created in whatever context is current, and another source's may be)."""
        self._check_open()  # (a closed source's context is gone: AdapterClosedError, as the base class says)
        self._use()
        return super().adapter(channels, **options)

    def _here(self) -> bool:
        """Make the renderer's context current, and say whether it is (EGL refuses it in silence where another
        thread holds it); False where the context is released."""
        renderer = self.renderer
        if is_released(renderer.ctx) or renderer._released:
            return False
        self._use()
        return renderer._current is None or renderer._current.holds()

    def _close_dependents(self) -> None:
        if not self._here():  # (the adapters free their GL objects in this context: not in another thread's)
            for ref in self._adapters:
                adapter = ref()
                if adapter is not None:  # (said once, by close(); nothing freed)
                    adapter.__dict__["_quiet_close"] = True
        super()._close_dependents()

    def close(self) -> None:
        """Free the textures and the renderer (and its context, unless it was borrowed; a borrowed context the
        engine released first took them with it). From a thread where the context cannot be made current (another
        thread holds it) a borrowed context's textures, renderer and adapters are not freed: a warning says so, and
        the source is closed all the same; a context the renderer made is released from any thread, and everything
        goes with it."""
        renderer = self.renderer
        if self._here():
            for t in self._textures.values():
                t.release()
        elif not is_released(renderer.ctx) and not renderer._released:
            if not renderer._owns_ctx:
                warn_not_freed(f"an rtp ReferenceFrameSource ({self.width}x{self.height})",
                               "textures, its renderer's GL objects and its adapters'",
                               "Close it in the thread where its renderer's context is current, or release the "
                               "context there first (source.renderer.ctx.__exit__(None, None, None))")
            renderer.__dict__["_quiet_close"] = True
        renderer.release()
