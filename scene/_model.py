"""The renderer's scene description: plain numpy data, no GL.

Scene sources (``rtp.capture.scenes``: procedural rooms, glTF/OBJ, Quake-3 BSP) build these; the
reference renderer draws them. World space is right-handed, Y up, in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rtp.sdk import ParameterError

from ._checks import array, real, vector

__all__ = ["Material", "Mesh", "PointLight", "Scene", "SpawnPoint", "SunLight"]

#: The shortest sun direction taken: shorter ones are no direction to normalise (a denormal's is NaN).
_MIN_DIRECTION = 1e-6


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

    def __post_init__(self) -> None:
        vector("Material", "base_color", self.base_color, 4, 0.0, 1.0)
        for key in ("roughness", "metallic", "specular"):
            real("Material", key, getattr(self, key), 0.0, 1.0)
        vector("Material", "emissive", self.emissive, 3, 0.0)
        if self.alpha_cutoff is not None:
            real("Material", "alpha_cutoff", self.alpha_cutoff, 0.0, 1.0)
        t = self.texture
        if t is not None and (not isinstance(t, np.ndarray) or t.dtype != np.uint8 or t.ndim != 3 or t.shape[2] != 4
                              or t.shape[0] < 1 or t.shape[1] < 1):
            got = f"{t.dtype} {t.shape}" if isinstance(t, np.ndarray) else type(t).__name__
            raise ParameterError(f"Material.texture: expected None or a uint8 array of shape (H, W, 4), got {got}",
                                 "texture")


@dataclass
class Mesh:
    """Triangles of one material. ``uvs`` use a top-left texture origin (v grows downwards);
    ``indices`` are counter-clockwise front faces."""

    positions: np.ndarray  # (N, 3) float32 (other floats are converted), world metres
    normals: np.ndarray  # (N, 3) float32, unit; a zero row is drawn with the geometric normal
    uvs: np.ndarray  # (N, 2) float32
    indices: np.ndarray  # (M, 3) uint32
    material: int  # index into Scene.materials

    def __post_init__(self) -> None:
        # (float32, what every renderer uploads: float64 positions past its range were taken and drawn as infinities)
        self.positions = array("Mesh", "positions", self.positions, 3, "f", dtype=np.float32)
        n = len(self.positions)
        self.normals = array("Mesh", "normals", self.normals, 3, "f", dtype=np.float32)
        self.uvs = array("Mesh", "uvs", self.uvs, 2, "f", dtype=np.float32)
        self.indices = array("Mesh", "indices", self.indices, 3, "iu")
        for key, a in (("normals", self.normals), ("uvs", self.uvs)):
            if len(a) != n:
                raise ParameterError(f"Mesh.{key}: expected one row per vertex ({n}), got {len(a)}", key)
        if self.indices.size and (int(self.indices.min()) < 0 or int(self.indices.max()) >= n):
            raise ParameterError(f"Mesh.indices: expected vertex indices in [0, {n}), got "
                                 f"[{int(self.indices.min())}, {int(self.indices.max())}]", "indices")
        m = self.material
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 0:
            raise ParameterError(f"Mesh.material: expected an index into Scene.materials (an integer >= 0), got {m!r}",
                                 "material")


@dataclass
class SunLight:
    """A directional light. ``direction`` points from the light into the scene: a vector of any finite length
    from 1e-6 up (it is normalised where used)."""

    direction: tuple[float, float, float] = (-0.4, -1.0, -0.3)
    colour: tuple[float, float, float] = (1.0, 0.95, 0.85)
    intensity: float = 3.0

    def __post_init__(self) -> None:
        vector("SunLight", "direction", self.direction, 3)
        with np.errstate(all="ignore"):
            length = float(np.linalg.norm(np.asarray([float(x) for x in self.direction], np.float64)))
        # (a denormal one has no direction, 1e308s an infinite length: NaN light poses, a LinAlgError in
        # to_pyrender_scene; the reference renderer normalises by at least 1e-12, so a shorter one drew a dimmed sun)
        if not _MIN_DIRECTION <= length < math.inf:
            raise ParameterError(f"SunLight.direction: expected a vector of finite length >= {_MIN_DIRECTION:g}, got "
                                 f"{tuple(self.direction)!r}", "direction")
        vector("SunLight", "colour", self.colour, 3, 0.0)
        real("SunLight", "intensity", self.intensity, 0.0)


@dataclass
class PointLight:
    """A point light with a smooth windowed inverse-square falloff reaching 0 at ``radius``."""

    position: tuple[float, float, float]
    colour: tuple[float, float, float] = (1.0, 0.8, 0.6)
    intensity: float = 10.0
    radius: float = 10.0

    def __post_init__(self) -> None:
        vector("PointLight", "position", self.position, 3)
        vector("PointLight", "colour", self.colour, 3, 0.0)
        real("PointLight", "intensity", self.intensity, 0.0)
        real("PointLight", "radius", self.radius, 0.0, lo_open=True)


@dataclass
class SpawnPoint:
    """A player start: position in metres (eye height included) and yaw in degrees
    (0 looks down -Z, positive turns left, i.e. counter-clockwise seen from above)."""

    position: tuple[float, float, float]
    yaw: float = 0.0

    def __post_init__(self) -> None:
        vector("SpawnPoint", "position", self.position, 3)
        real("SpawnPoint", "yaw", self.yaw)


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

    def __post_init__(self) -> None:
        for key, items, kind in (("meshes", self.meshes, Mesh), ("materials", self.materials, Material),
                                 ("point_lights", self.point_lights, PointLight),
                                 ("spawn_points", self.spawn_points, SpawnPoint)):
            if not isinstance(items, list) or not all(isinstance(x, kind) for x in items):
                raise ParameterError(f"Scene.{key}: expected a list of {kind.__name__}, got "
                                     f"{type(items).__name__ if not isinstance(items, list) else 'other items'}", key)
        if not isinstance(self.sun, SunLight):
            raise ParameterError(f"Scene.sun: expected a SunLight, got {type(self.sun).__name__}", "sun")
        for i, m in enumerate(self.meshes):
            if m.material >= len(self.materials):
                raise ParameterError(f"Scene.meshes[{i}].material: expected an index below the {len(self.materials)} "
                                     f"materials, got {m.material}", "meshes")
        vector("Scene", "sky_colour", self.sky_colour, 3, 0.0)
        real("Scene", "ambient", self.ambient, 0.0)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds ``(min, max)`` of all vertices."""
        meshes = [m for m in self.meshes if len(m.positions)]  # (a mesh of no vertices was a ValueError of numpy's)
        if not meshes:
            z = np.zeros(3, np.float32)
            return z, z
        lo = np.min([m.positions.min(axis=0) for m in meshes], axis=0)
        hi = np.max([m.positions.max(axis=0) for m in meshes], axis=0)
        return lo.astype(np.float32), hi.astype(np.float32)

    @property
    def triangle_count(self) -> int:
        return int(sum(len(m.indices) for m in self.meshes))
