"""moderngl plugin: the reference deferred renderer with software VRS, and the moderngl adapter.

    from rtp.plugins.moderngl import Renderer
    from rtp.scene import Camera

    with Renderer(1280, 720) as renderer:
        renderer.load_scene(scene)
        prev = renderer.render(prev_camera)
        frame = renderer.render(camera, prev)
        frame.colour["2x2"], frame.albedo, frame.seen  # float32, top-left origin

:class:`Adapter` builds a model's inputs from an engine's G-buffer textures
(:class:`GBufferTextures`); :class:`ReferenceFrameSource` is the reference renderer feeding it
(``Adapter.frame_source(scene, width, height)``). :class:`RateSelector` makes the runtime's decision
(decode and rate selection) in a compute shader, from the network's output to the shading-rate image.
Scenes and cameras are :mod:`rtp.scene`'s (no GL);
:class:`Renderer` and :class:`Adapter` need the ``rtp[moderngl]`` extra.
"""

from __future__ import annotations

from ._adapter import Adapter, GBufferTextures
from ._renderer import Frame, Renderer, RendererError, RenderResult, create_context
from ._select import RateSelector
from ._source import ReferenceFrameSource

__all__ = [
    "Adapter",
    "Frame",
    "GBufferTextures",
    "RateSelector",
    "ReferenceFrameSource",
    "RenderResult",
    "Renderer",
    "RendererError",
    "create_context",
]
