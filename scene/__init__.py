"""The renderer-neutral scene model that scene sources, renderers and adapters share.

Plain numpy data, no GL: :class:`Scene` (meshes, materials, lights, spawn points) and
:class:`Camera`. World space is right-handed, Y up, in metres; view space looks down -Z.

    from rtp.scene import Camera, Scene
    from rtp.capture.scenes import procedural     # a source that builds a Scene
    scene = procedural(0)
    camera = Camera(position=(0.0, 1.6, 0.0), yaw=30.0, pitch=-5.0)

The small builders (:func:`box_mesh`, :func:`quad_mesh`, :func:`sphere_mesh`,
:func:`checker_texture`) make hand-made scenes for tests and benchmarks.
"""

from __future__ import annotations

from ._camera import Camera
from ._model import Material, Mesh, PointLight, Scene, SpawnPoint, SunLight
from ._primitives import box_mesh, checker_texture, quad_mesh, sphere_mesh

__all__ = [
    "Camera",
    "Material",
    "Mesh",
    "PointLight",
    "Scene",
    "SpawnPoint",
    "SunLight",
    "box_mesh",
    "checker_texture",
    "quad_mesh",
    "sphere_mesh",
]

# Public objects report their stable path, not the private module they live in.
for _name in __all__:
    _obj = globals()[_name]
    try:
        _obj.__module__ = __name__
    except (AttributeError, TypeError):
        pass
del _name, _obj
