"""pyrender adapter plugin: a shipped rtp model on a ``pyrender.Scene``, without writing any GL.

    from rtp import sdk
    from rtp.plugins.pyrender import Adapter, SceneFrame

    predictor = sdk.load("model.onnx")
    with Adapter.for_predictor(predictor, 640, 360) as adapter:
        prev_colour, _ = adapter.render(scene, prev_pose)                        # the displayed frame
        x = adapter.inputs(SceneFrame(scene, pose, prev_pose, prev_colour))     # (C, H, W) float32
        rates = predictor.shading_rates(x[None])

Entry point ``pyrender`` in the ``rtp.adapters`` group (``sdk.adapters.get("pyrender")``). Needs the
``rtp[pyrender]`` extra (pyrender 0.1.45) and a headless GL platform: EGL (default) or OSMesa,
chosen through ``PYOPENGL_PLATFORM`` before anything imports PyOpenGL; importing this package
does not import pyrender. See docs/adapters.md.
"""

from __future__ import annotations

from ._adapter import Adapter, SceneFrame
from ._convert import to_pyrender_scene, to_trimesh_scene
from ._errors import PyrenderAdapterError, PyrenderUnavailableError
from ._gbuffer import GBuffers
from ._gl import PLATFORMS, import_pyrender
from ._source import PyrenderFrameSource

__all__ = [
    "PLATFORMS",
    "Adapter",
    "GBuffers",
    "PyrenderAdapterError",
    "PyrenderFrameSource",
    "PyrenderUnavailableError",
    "SceneFrame",
    "import_pyrender",
    "to_pyrender_scene",
    "to_trimesh_scene",
]
