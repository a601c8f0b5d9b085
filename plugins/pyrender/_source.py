"""The pyrender adapter's frame source: pyrender draws an rtp scene, the adapter reads it.

This is how a caller that does not know pyrender drives :class:`rtp.plugins.pyrender.Adapter`
(``sdk.adapters.get("pyrender").frame_source(scene, w, h)``); an application with its own
``pyrender.Scene`` builds :class:`SceneFrame` s itself.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

import numpy as np

from rtp.scene import Camera
from rtp.sdk import ParameterError
from rtp.sdk.adapters import FrameSource

from ._adapter import SceneFrame
from ._convert import to_pyrender_scene
from ._gbuffer import _delete_renderer, busy_lock, draw, one_call
from ._gl import import_pyrender, offscreen_renderer

if TYPE_CHECKING:
    from ._adapter import Adapter

__all__ = ["PyrenderFrameSource"]

log = logging.getLogger("rtp.plugins.pyrender")


class PyrenderFrameSource(FrameSource[SceneFrame]):
    """A pyrender ``OffscreenRenderer`` drawing a scene, as an application feeding the pyrender
    adapter: each :meth:`frame` draws pyrender's lit image from the previous camera (the displayed
    frame) and returns a :class:`SceneFrame` for the current camera.

    Args:
        adapter_class: the adapter class :meth:`adapter` builds (``Adapter`` or a subclass).
        scene: an :class:`rtp.scene.Scene` (converted with :func:`to_pyrender_scene`) or a
            ``pyrender.Scene`` (used as it is; the source adds a camera node and makes it the
            main camera while it is open: :meth:`close` removes that node and gives the scene back
            its own main camera).
        width, height: frame size in pixels.
        platform: ``"egl"`` (default) or ``"osmesa"``, see :func:`import_pyrender`.

    pyrender binds a scene to one renderer's GL context, so :meth:`adapter` lends the adapter this
    source's renderer (``renderer=``); closing the source closes those adapters first. The source and its
    adapters take one call at a time (they move one camera node): :meth:`frame` while another thread's call
    holds the renderer is a :class:`PyrenderAdapterError`, and :meth:`close` waits for that call.
    """

    def __init__(self, adapter_class: type[Adapter], scene: Any, width: int, height: int, *,
                 platform: str | None = None) -> None:
        super().__init__(adapter_class, width, height)
        self._pyrender = pyrender = import_pyrender(platform)
        self.scene = scene if isinstance(scene, pyrender.Scene) else to_pyrender_scene(scene)
        self.renderer = offscreen_renderer(pyrender, self.width, self.height)
        self._busy = busy_lock(self.renderer)  # (its adapters' too: they borrow the renderer)
        self._cameras: dict[tuple[float, float, float], Any] = {}
        self._own_main = self.scene.main_camera_node  # (a user's scene gets it back on close)
        self._camera0 = self._camera_for(None)  # (pyrender files the node under this camera: removed with it)
        self._node = self.scene.add(self._camera0, pose=np.eye(4))
        self.scene.main_camera_node = self._node

    def _camera_for(self, camera: Camera | None) -> Any:
        """The ``pyrender.PerspectiveCamera`` with ``camera``'s field of view and clip planes."""
        key = (70.0, 0.05, 200.0) if camera is None else (float(camera.fov_y), float(camera.near), float(camera.far))
        if key not in self._cameras:
            self._cameras[key] = self._pyrender.PerspectiveCamera(
                yfov=np.radians(key[0]), aspectRatio=self.width / self.height, znear=key[1], zfar=key[2])
        return self._cameras[key]

    def adapter_options(self) -> dict[str, Any]:
        return {"renderer": self.renderer}

    def frame(self, camera: Camera, prev_camera: Camera) -> SceneFrame:
        for name, cam in (("camera", camera), ("prev_camera", prev_camera)):
            if not isinstance(cam, Camera):
                raise ParameterError(f"{name}: expected an rtp.scene.Camera, got {type(cam).__name__}", name)
        with one_call(self._busy, "PyrenderFrameSource.frame"):  # (it moves the camera node its adapters move)
            return self._frame(camera, prev_camera)

    def _frame(self, camera: Camera, prev_camera: Camera) -> SceneFrame:
        cam, prev_cam = self._camera_for(camera), self._camera_for(prev_camera)
        pose, prev_pose = np.linalg.inv(camera.view()), np.linalg.inv(prev_camera.view())
        self._node.camera = prev_cam
        self.scene.set_pose(self._node, prev_pose)
        prev_colour, _ = draw(self.renderer, self.scene, self._pyrender.RenderFlags.NONE,  # the displayed frame
                              fix="the source draws with a renderer of its own, so give it a scene no other "
                                  "renderer draws, or build the SceneFrames yourself with Adapter(..., renderer=r)")
        self._node.camera = cam
        self.scene.set_pose(self._node, pose)
        return SceneFrame(scene=self.scene, pose=pose, prev_pose=prev_pose, prev_colour=prev_colour,
                          camera=cam, prev_camera=prev_cam)

    def close(self) -> None:
        """Free the renderer's GL context (only its own: other renderers keep working), and take the camera node
        this source added out of the scene, whose main camera is again the one it had (a ``pyrender.Scene`` of
        the caller's was left with a second camera, the source's, as its main one). A :meth:`frame` under way in
        another thread is waited for."""
        with self._busy:
            self._close()

    def _close(self) -> None:
        try:
            _delete_renderer(self.renderer)
        finally:
            scene, node = self.scene, self._node
            if scene.has_node(node):
                node.camera = self._camera0  # (frame() swaps it; pyrender looks the node up by the one it was added with)
                scene.remove_node(node)
            own = self._own_main
            if own is not None and scene.has_node(own):
                scene.main_camera_node = own
