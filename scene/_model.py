"""The renderer's scene description: plain numpy data, no GL.

Scene sources (``rtp.capture.scenes``: procedural rooms, glTF/OBJ, Quake-3 BSP) build these; the
reference renderer draws them. World space is right-handed, Y up, in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Material", "Mesh", "PointLight", "Scene", "SpawnPoint", "SunLight"]


@dataclass
class Material:
    """A surface's shading parameters.

    ``texture`` is an ``(H, W, 4)`` uint8 sRGB image with a top-left origin (row 0 is v = 0), or
    None for a constant ``base_color``. The texture is multiplied by ``base_color`` (sRGB-encoded
    factors in [0, 1], alpha last). ``alpha_cutoff`` enables alpha testing (fragments with alpha
    below it are discarded). ``emissive`` is linear radiance added to the lit colour.
    """

    name: str
    base_color: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    texture: np.ndarray | None = None
    roughness: float = 0.5
    metallic: float = 0.0
    specular: float = 0.5
    emissive: tuple[float, float, float] = (0.0, 0.0, 0.0)
    alpha_cutoff: float | None = None


@dataclass
class Mesh:
    """Triangles of one material. ``uvs`` use a top-left texture origin (v grows downwards);
    ``indices`` are counter-clockwise front faces."""

    positions: np.ndarray  # (N, 3) float32, world metres
    normals: np.ndarray  # (N, 3) float32, unit
    uvs: np.ndarray  # (N, 2) float32
    indices: np.ndarray  # (M, 3) uint32
    material: int  # index into Scene.materials


@dataclass
class SunLight:
    """A directional light. ``direction`` points from the light into the scene (unit vector)."""

    direction: tuple[float, float, float] = (-0.4, -1.0, -0.3)
    colour: tuple[float, float, float] = (1.0, 0.95, 0.85)
    intensity: float = 3.0


@dataclass
class PointLight:
    """A point light with a smooth windowed inverse-square falloff reaching 0 at ``radius``."""

    position: tuple[float, float, float]
    colour: tuple[float, float, float] = (1.0, 0.8, 0.6)
    intensity: float = 10.0
    radius: float = 10.0


@dataclass
class SpawnPoint:
    """A player start: position in metres (eye height included) and yaw in degrees
    (0 looks down -Z, positive turns left, i.e. counter-clockwise seen from above)."""

    position: tuple[float, float, float]
    yaw: float = 0.0


@dataclass
class Scene:
    """Everything the reference renderer needs to draw a level."""

    name: str
    meshes: list[Mesh]
    materials: list[Material]
    sun: SunLight = field(default_factory=SunLight)
    point_lights: list[PointLight] = field(default_factory=list)
    sky_colour: tuple[float, float, float] = (0.45, 0.6, 0.85)  # linear radiance of the sky / ambient
    ambient: float = 0.35  # strength of the sky-coloured ambient (hemisphere) light
    spawn_points: list[SpawnPoint] = field(default_factory=list)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds ``(min, max)`` of all vertices."""
        if not self.meshes:
            z = np.zeros(3, np.float32)
            return z, z
        lo = np.min([m.positions.min(axis=0) for m in self.meshes], axis=0)
        hi = np.max([m.positions.max(axis=0) for m in self.meshes], axis=0)
        return lo.astype(np.float32), hi.astype(np.float32)

    @property
    def triangle_count(self) -> int:
        return int(sum(len(m.indices) for m in self.meshes))
