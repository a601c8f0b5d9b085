"""rtp scenes (``rtp.scene.Scene``: numpy meshes, sRGB materials) as pyrender or
trimesh scenes, so the same procedural level can be drawn by both renderers.

The rtp scene is read by duck typing (``meshes``, ``materials``, ``sun``, ``point_lights``,
``sky_colour``, ``ambient``); nothing of ``rtp.plugins.moderngl`` is imported.

Semantics kept equal to the reference renderer's G-buffer:

* A textured material's albedo is ``texture x base_color`` in sRGB space (rtp's definition). glTF
  multiplies in linear space, so the factor is baked into the texture (8-bit, rounded) and the
  glTF factor is 1. An untextured material gets the linear factor ``srgb_to_linear(base_color)``,
  which the adapter's shader encodes back exactly.
* rtp texture coordinates have a top-left origin (v down); pyrender and trimesh flip images on
  upload, so ``v`` becomes ``1 - v``.
* Materials are double-sided (the reference renderer shades two-sided by default).
* ``alpha_cutoff`` has no pyrender equivalent: pyrender does not alpha-test (glTF ``MASK`` is
  drawn opaque), so alpha-tested surfaces draw solid in pyrender. :func:`to_trimesh_scene` writes
  each material's glTF alpha mode (``MASK`` with the cutoff, else ``OPAQUE``), which ``rtp capture``
  reads back as ``alpha_cutoff``; pyrender's own trimesh loader ignores it and blends every material
  (examples/pyrender_vrs.py's ``load_scene`` keeps it, docs/adapters.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rtp.scene import Scene
from rtp.sdk import ParameterError, srgb_to_linear

from ._gl import import_pyrender

__all__ = ["to_pyrender_scene", "to_trimesh_scene"]


def _baked_texture(material: Any) -> np.ndarray | None:
    if material.texture is None:
        return None
    tex = np.asarray(material.texture)
    factor = np.asarray(material.base_color, np.float64)
    return np.clip(np.rint(tex.astype(np.float64) * factor[None, None, :]), 0, 255).astype(np.uint8)


def _linear_factor(material: Any) -> np.ndarray:
    if material.texture is not None:
        return np.ones(4)
    bc = np.asarray(material.base_color, np.float64)
    return np.concatenate([srgb_to_linear(np.clip(bc[:3], 0.0, 1.0)), bc[3:4]])


def _check_scene(scene: Any, **flags: Any) -> None:
    """``scene`` is an :class:`rtp.scene.Scene` (its fields were checked when it was made) and the
    ``flags`` are True or False: a :class:`rtp.sdk.ParameterError` otherwise."""
    if not isinstance(scene, Scene):
        raise ParameterError(f"scene: expected an rtp.scene.Scene, got {type(scene).__name__}", "scene")
    for name, value in flags.items():
        if not isinstance(value, (bool, np.bool_)):
            raise ParameterError(f"{name}: expected True or False, got {value!r}", name)


def _look_at_direction(direction: Any) -> np.ndarray:
    """A 4x4 pose whose -Z axis points along ``direction`` (pyrender's light/camera convention)."""
    d = np.asarray(direction, np.float64)
    d = d / max(float(np.linalg.norm(d)), 1e-12)
    up = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.99 else np.array([1.0, 0.0, 0.0])
    right = np.cross(d, up)
    right /= np.linalg.norm(right)
    upv = np.cross(right, d)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, upv, -d], axis=1)
    return pose


def to_pyrender_scene(scene: Any, *, double_sided: bool = True, lights: bool = True) -> Any:
    """Build a ``pyrender.Scene`` from an rtp scene.

    Args:
        scene: an ``rtp.scene.Scene`` (for example ``rtp.capture.scenes.procedural(0)``).
        double_sided: draw every material two-sided (the reference renderer's default).
        lights: add the sun (a ``DirectionalLight``), the point lights and the ambient term, for
            a lit display image (pyrender's own shading, not the reference renderer's).

    Returns:
        A ``pyrender.Scene`` without a camera; add one (``scene.add(camera, pose=...)``).
    """
    _check_scene(scene, double_sided=double_sided, lights=lights)
    pyrender = import_pyrender()
    sky = np.asarray(getattr(scene, "sky_colour", (0.45, 0.6, 0.85)), np.float64)
    amb = float(getattr(scene, "ambient", 0.35)) if lights else 0.0
    out = pyrender.Scene(bg_color=np.concatenate([sky, [1.0]]), ambient_light=sky * amb)
    materials = []
    for m in scene.materials:
        tex = _baked_texture(m)
        materials.append(
            pyrender.MetallicRoughnessMaterial(
                name=m.name,
                baseColorFactor=_linear_factor(m),
                baseColorTexture=None if tex is None else pyrender.Texture(source=tex, source_channels="RGBA"),
                metallicFactor=float(m.metallic),
                roughnessFactor=float(m.roughness),
                emissiveFactor=np.sqrt(np.clip(np.asarray(m.emissive, np.float64), 0.0, None)),  # pyrender squares it
                doubleSided=bool(double_sided),
                alphaMode="OPAQUE",
            )
        )
    for mesh in scene.meshes:
        if len(mesh.indices) == 0:
            continue
        uv = np.asarray(mesh.uvs, np.float32).copy()
        uv[:, 1] = 1.0 - uv[:, 1]
        prim = pyrender.Primitive(
            positions=np.asarray(mesh.positions, np.float32),
            normals=np.asarray(mesh.normals, np.float32),
            texcoord_0=uv,
            indices=np.asarray(mesh.indices, np.uint32),
            material=materials[mesh.material],
        )
        out.add(pyrender.Mesh([prim]))
    if lights:
        sun = scene.sun
        if sun.intensity > 0:
            out.add(pyrender.DirectionalLight(color=np.asarray(sun.colour), intensity=float(sun.intensity)),
                    pose=_look_at_direction(sun.direction))
        for pl in scene.point_lights:
            pose = np.eye(4)
            pose[:3, 3] = pl.position
            out.add(pyrender.PointLight(color=np.asarray(pl.colour), intensity=float(pl.intensity), range=float(pl.radius)),
                    pose=pose)
    return out


def to_trimesh_scene(scene: Any) -> Any:
    """Build a ``trimesh.Scene`` (PBR materials, textures as images) from an rtp scene, ready to
    export as glTF/GLB: ``to_trimesh_scene(s).export("level.glb")``. Same conventions as
    :func:`to_pyrender_scene` (factor baked into textures; double-sided)."""
    _check_scene(scene)
    import trimesh
    from PIL import Image

    out = trimesh.Scene()
    for i, mesh in enumerate(scene.meshes):
        if len(mesh.indices) == 0:
            continue
        m = scene.materials[mesh.material]
        tex = _baked_texture(m)
        factor = _linear_factor(m)
        material = trimesh.visual.material.PBRMaterial(
            name=m.name,
            baseColorFactor=np.clip(np.rint(factor * 255.0), 0, 255).astype(np.uint8),
            baseColorTexture=None if tex is None else Image.fromarray(tex, "RGBA"),
            metallicFactor=float(m.metallic),
            roughnessFactor=float(m.roughness),
            doubleSided=True,
            # what the reference renderer draws: alpha-tested or opaque, never blended. Left unset, the
            # export wrote BLEND, which pyrender draws in the order of a set: a grate's holes then showed
            # the sky or the room behind by the process's hash seed
            alphaMode="OPAQUE" if m.alpha_cutoff is None else "MASK",
            alphaCutoff=None if m.alpha_cutoff is None else float(m.alpha_cutoff),
        )
        uv = np.asarray(mesh.uvs, np.float64).copy()
        uv[:, 1] = 1.0 - uv[:, 1]  # trimesh keeps OBJ's bottom-left uv origin and flips glTF's on export
        tm = trimesh.Trimesh(
            vertices=np.asarray(mesh.positions, np.float64),
            faces=np.asarray(mesh.indices, np.int64),
            vertex_normals=np.asarray(mesh.normals, np.float64),
            visual=trimesh.visual.TextureVisuals(uv=uv, material=material),
            process=False,
        )
        out.add_geometry(tm, node_name=f"mesh{i}_{m.name}", geom_name=f"mesh{i}_{m.name}")
    return out
