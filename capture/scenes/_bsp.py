"""Quake-3 BSP (IBSP version 46) to :class:`Scene`.

Conversion rules (also in docs/scenes.md):

* Geometry: polygon (type 1) and mesh (type 3) faces use ``meshverts + first vertex``; bezier
  patches (type 2) are tessellated per 3x3 control block at ``patch_level`` segments per side.
  Billboards (type 4) are dropped.
* Units and axes: Q3 units (inches) x 0.0254 = metres; Q3 is Z-up, the renderer Y-up:
  ``(x, y, z)_q3 -> (x, z, -y)``, a proper rotation, so handedness is kept.
* Winding: Q3 front faces are clockwise; indices are reversed so they are counter-clockwise.
  Patch triangles are oriented so their geometric normals agree with the interpolated vertex
  normals (majority vote per face).
* Texture coordinates: Q3 ``st`` already has a top-left origin (t = 0 is the first image row);
  they are kept as they are (REPEAT wrapping expected).
* Dropped surfaces: flags SURF_NODRAW 0x80, SURF_HINT 0x100, SURF_SKIP 0x200; contents FOG 0x40;
  shaders with ``surfaceparm nodraw|fog|sky``; tool textures ``textures/common/*`` and
  ``noshader``; shaders made only of blended stages (no opaque stage, no lightmap, no alphaFunc:
  flares, beams, glass, energy fields). Sky surfaces (SURF_SKY 0x4 or ``surfaceparm sky``) are
  not drawn but returned as blocker triangles for viewpoint sampling, since they seal the level.
* Textures: ``name + .jpg/.tga/.png`` in the archives (a dot that starts no image extension is part of the
  name, ``x.blend`` -> ``x.blend.tga``), else the first non-``$lightmap`` map stage
  of the shader script of that name (``map``/``clampMap``/``animMap``), else ``qer_editorimage``;
  a missing image gives a neutral grey material (logged).
* Materials: :func:`~._materials.pbr_for_path`; ``alphaFunc`` or an alpha-blend stage sets
  ``alpha_cutoff`` (0.5; 0.05 for GT0; LT128 inverts the alpha channel first, since the renderer
  keeps the texels at or above the cutoff), other textures are made opaque (alpha 255).
* Spawn points: ``info_player_deathmatch``, ``info_player_start``, ``team_CTF_*spawn`` and
  ``team_CTF_*player``; eye = origin + ``eye_height_units`` (9 units of spawn lift + 26 of view
  height); Camera yaw = Q3 angle (or the yaw of ``angles``, whichever the entity sets last) - 90 degrees.
* Lights: ``light`` entities if the compiler kept them (q3map2's value: ``_light``, else ``light``, else
  300; negative, darkening lights skipped), else clusters of surface-light faces
  (``q3map_surfacelight``); the sun from the sky shader's ``q3map_sun``/``q3map_sunExt``.
"""

from __future__ import annotations

import io
import logging
import math
import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rtp.scene import Material, Mesh, PointLight, Scene, SpawnPoint, SunLight
from rtp.sdk import ParameterError, srgb_to_linear

from ._errors import SceneFormatError, SceneNotFoundError
from ._geometry import vertex_normals
from ._materials import pbr_for_path
from ._pk3 import Pk3Set, Shader, parse_shaders

__all__ = ["BspConversion", "convert_bsp", "load_bsp", "q3_to_world", "q3_angle_to_yaw"]

log = logging.getLogger("rtp.capture")

UNIT = 0.0254  # metres per Q3 unit
SURF_SKY, SURF_NODRAW, SURF_HINT, SURF_SKIP = 0x4, 0x80, 0x100, 0x200
CONTENTS_FOG = 0x40
SPAWN_CLASSES = (
    "info_player_deathmatch",
    "info_player_start",
    "team_ctf_redspawn",
    "team_ctf_bluespawn",
    "team_ctf_redplayer",
    "team_ctf_blueplayer",
)
LIGHT_WORDS = ("light", "lamp", "flame", "torch", "fire", "lava")
IMAGE_EXTS = (".jpg", ".tga", ".png", ".jpeg")
#: Image extensions the engine also reads (a name ending so is tried as it is), never appended to a name.
ENGINE_ONLY_EXTS = (".pcx", ".bmp")
MAX_TEXTURE = 1024  # larger textures are downsampled (by powers of two) to this edge
#: The largest ``patch_level``: 64 segments a side are 8192 triangles per 3x3 bezier block, far past any
#: visible curvature (the default is 6); more only fills memory (10**6 asked for terabytes).
MAX_PATCH_LEVEL = 64
#: The largest ``max_point_lights``: the most point lights the reference renderer draws (its own
#: ``max_point_lights`` is at most 256; the default here keeps 16).
MAX_POINT_LIGHTS = 256
#: Half the extent of a Q3 world (``MAX_WORLD_COORD``), the bound of ``eye_height_units``.
MAX_WORLD_UNITS = 65536

TEXTURE_DT = np.dtype([("name", "S64"), ("flags", "<i4"), ("contents", "<i4")])
VERTEX_DT = np.dtype([("pos", "<f4", 3), ("uv", "<f4", 2), ("lm", "<f4", 2), ("normal", "<f4", 3), ("color", "u1", 4)])
FACE_DT = np.dtype(
    [
        ("texture", "<i4"), ("effect", "<i4"), ("type", "<i4"), ("vertex", "<i4"), ("n_vertexes", "<i4"),
        ("meshvert", "<i4"), ("n_meshverts", "<i4"), ("lm_index", "<i4"), ("lm_start", "<i4", 2),
        ("lm_size", "<i4", 2), ("lm_origin", "<f4", 3), ("lm_vecs", "<f4", (2, 3)), ("normal", "<f4", 3),
        ("size", "<i4", 2),
    ]
)
assert TEXTURE_DT.itemsize == 72 and VERTEX_DT.itemsize == 44 and FACE_DT.itemsize == 104
LUMP_ENTITIES, LUMP_TEXTURES, LUMP_VERTEXES, LUMP_MESHVERTS, LUMP_FACES = 0, 1, 10, 11, 13


def q3_to_world(p: np.ndarray, scale: float = UNIT) -> np.ndarray:
    """Q3 ``(x, y, z)`` (Z up) → world ``(x, z, -y) * scale`` (Y up, right-handed)."""
    p = np.asarray(p, np.float64)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1) * scale


def q3_angle_to_yaw(angle: float) -> float:
    """Q3 entity ``angle`` (degrees, 0 = +X, counter-clockwise from above) → Camera yaw
    (0 looks down -Z, positive turns left), wrapped to [-180, 180)."""
    return (angle - 90.0 + 180.0) % 360.0 - 180.0


@dataclass
class BspConversion:
    """Result of :func:`convert_bsp`: the scene, the sky triangles ``(K, 3, 3)`` (world metres) that
    seal the level for viewpoint sampling, and counters for reports."""

    scene: Scene
    sky_triangles: np.ndarray
    stats: dict[str, int] = field(default_factory=dict)
    missing_textures: list[str] = field(default_factory=list)


# -- low level ------------------------------------------------------------------------------------

def _lumps(data: bytes, source: str) -> list[tuple[int, int]]:
    if len(data) < 8 + 17 * 8:
        raise SceneFormatError(f"{source}: too short for a BSP header ({len(data)} bytes)")
    magic, version = data[:4], struct.unpack_from("<i", data, 4)[0]
    if magic != b"IBSP" or version != 46:
        raise SceneFormatError(f"{source}: expected an IBSP version 46 file, got {magic!r} version {version}")
    lumps = [struct.unpack_from("<ii", data, 8 + 8 * i) for i in range(17)]
    for i, (off, ln) in enumerate(lumps):
        if off < 0 or ln < 0 or off + ln > len(data):
            raise SceneFormatError(f"{source}: lump {i} (offset {off}, length {ln}) runs past the file end")
    return lumps


def _lump_array(data: bytes, lump: tuple[int, int], dtype: np.dtype, what: str, source: str) -> np.ndarray:
    off, ln = lump
    if ln % dtype.itemsize:
        raise SceneFormatError(f"{source}: {what} lump length {ln} is not a multiple of {dtype.itemsize}")
    return np.frombuffer(data, dtype=dtype, count=ln // dtype.itemsize, offset=off)


def parse_entities(text: str) -> list[dict[str, str]]:
    """The entity lump as a list of ``{key: value}`` dicts (keys lower case)."""
    ents = []
    for block in re.findall(r"\{([^{}]*)\}", text):
        ents.append({k.lower(): v for k, v in re.findall(r'"([^"]*)"\s+"([^"]*)"', block)})
    return ents


def _bezier_weights(level: int) -> np.ndarray:
    t = np.linspace(0.0, 1.0, level + 1)
    return np.stack([(1 - t) ** 2, 2 * t * (1 - t), t**2], axis=1)  # (L+1, 3)


def _tessellate_patch(verts: np.ndarray, w: int, h: int, level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Tessellate a ``w`` x ``h`` control grid (row-major, ``verts`` structured) into positions,
    normals, uvs (Q3 space) and triangles, oriented to agree with the normals; an even, too small or
    too large size (more control points than ``verts`` holds) gives no triangles."""
    w, h = int(w), int(h)  # (the face lump's int32: w * h wrapped, 3 x 1431655769 read as 11 control points)
    if w < 3 or h < 3 or w % 2 == 0 or h % 2 == 0 or len(verts) < w * h:
        return (np.zeros((0, 3)),) * 2 + (np.zeros((0, 2)), np.zeros((0, 3), np.int64))
    attrs = np.concatenate([verts["pos"], verts["normal"], verts["uv"]], axis=1).astype(np.float64)[: w * h]
    grid = attrs.reshape(h, w, -1)
    pu, pv = (w - 1) // 2, (h - 1) // 2
    # control blocks (pv, pu, 3, 3, D)
    blocks = np.stack(
        [np.stack([grid[2 * j : 2 * j + 3, 2 * i : 2 * i + 3] for i in range(pu)]) for j in range(pv)]
    ).reshape(pv * pu, 3, 3, -1)
    B = _bezier_weights(level)
    tess = np.einsum("va,ub,pabd->pvud", B, B, blocks)  # (P, L+1, L+1, D): v rows, u columns
    n = level + 1
    pos = tess[..., 0:3].reshape(-1, 3)
    nrm = tess[..., 3:6].reshape(-1, 3)
    uv = tess[..., 6:8].reshape(-1, 2)
    r, c = np.meshgrid(np.arange(level), np.arange(level), indexing="ij")
    a = (r * n + c).ravel()
    quads = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)])
    tris = (quads[None] + (np.arange(len(blocks)) * n * n)[:, None, None]).reshape(-1, 3)
    p = pos[tris]
    gn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    vote = np.einsum("ij,ij->i", gn, nrm[tris].sum(axis=1)).sum()
    if vote < 0:
        tris = tris[:, ::-1]
    ln = np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.where(ln > 1e-9, nrm / np.maximum(ln, 1e-9), 0.0)
    area = np.linalg.norm(gn, axis=1)
    return pos, nrm, uv, tris[area > 1e-12]


# -- textures and materials ----------------------------------------------------------------------

def _decode_image(data: bytes, name: str) -> np.ndarray | None:
    try:
        from PIL import Image
    except ImportError as err:  # pragma: no cover - pillow is a dependency of the capture extra
        raise ImportError("reading BSP textures needs pillow: pip install 'rtp[capture]'") from err
    try:
        im: Image.Image = Image.open(io.BytesIO(data)).convert("RGBA")
    except Exception as err:  # noqa: BLE001 - any decoder failure means "unusable texture"
        log.warning("could not decode texture %s: %s", name, err)
        return None
    while max(im.size) > MAX_TEXTURE:
        im = im.resize((max(1, im.size[0] // 2), max(1, im.size[1] // 2)), Image.Resampling.BILINEAR)
    return np.asarray(im, dtype=np.uint8).copy()


def _find_image(pk3: Pk3Set, path: str) -> str | None:
    """The archive path of image ``path``, as the engine looks for it: a name with an image extension as it
    is, then with the others in its place; any other name (none, or a dot that belongs to it, as in
    ``ceil1_22a.blend``) with each image extension appended (``ceil1_22a.blend.tga``, never ``ceil1_22a.tga``)."""
    base = path.replace("\\", "/").lower()
    leaf = base.rsplit("/", 1)[-1]
    ext = "." + leaf.rsplit(".", 1)[1] if "." in leaf else ""
    if ext in IMAGE_EXTS or ext in ENGINE_ONLY_EXTS:
        cands = [base] + [base[: -len(ext)] + e for e in IMAGE_EXTS]
    else:
        cands = [base + e for e in IMAGE_EXTS]
    for c in cands:
        if c in pk3:
            return c
    return None


class _MaterialFactory:
    """Resolves BSP texture names to materials (with caching of decoded images)."""

    def __init__(self, pk3: Pk3Set, shaders: dict[str, Shader]) -> None:
        self.pk3 = pk3
        self.shaders = shaders
        self.missing: list[str] = []

    def image_for(self, name: str) -> tuple[np.ndarray | None, str | None]:
        shader = self.shaders.get(name.lower())
        path = _find_image(self.pk3, name)
        if path is None and shader is not None:
            img = shader.first_image()
            if img:
                path = _find_image(self.pk3, img)
        if path is None and shader is not None and shader.editor_image:
            path = _find_image(self.pk3, shader.editor_image)
        if path is None:
            return None, None
        return _decode_image(self.pk3.read(path), path), path

    def material(self, name: str) -> Material:
        """The material of texture ``name``: its image, alpha test and emission (grey without an image)."""
        shader = self.shaders.get(name.lower())
        tex, path = self.image_for(name)
        rough, metal, spec = pbr_for_path(name)
        mat = Material(name=name, roughness=rough, metallic=metal, specular=spec)
        if tex is None:
            self.missing.append(name)
            log.debug("no image for %s: neutral grey material", name)
            mat.base_color = (0.5, 0.5, 0.5, 1.0)
            return mat
        if shader is not None and shader.alpha_func == "lt128":
            # LT128 keeps the texels of alpha below 128, the renderer's alpha test those at or above its
            # cutoff: inverted, alpha a is kept iff 255 - a >= 128, iff a < 128 (it drew the holes instead)
            tex[..., 3] = 255 - tex[..., 3]
        cutoff = _alpha_cutoff(shader, tex)
        if cutoff is None:
            tex[..., 3] = 255
        mat.texture = tex
        mat.alpha_cutoff = cutoff
        emissive = _emissive(name, shader, tex)
        if emissive is not None:
            mat.emissive = emissive
        return mat

    @staticmethod
    def light_colour(shader: Shader, tex: np.ndarray | None) -> tuple[float, float, float]:
        if shader.light_rgb is not None:
            c = np.asarray(shader.light_rgb, np.float64)
        elif tex is not None:
            c = srgb_to_linear(tex[..., :3].reshape(-1, 3).mean(0) / 255.0)
        else:
            c = np.ones(3)
        m = float(c.max())
        c = c / m if m > 1e-6 else np.ones(3)
        return (float(c[0]), float(c[1]), float(c[2]))


def _alpha_cutoff(shader: Shader | None, tex: np.ndarray) -> float | None:
    """The alpha test of a texture: from the shader's ``alphaFunc`` or alpha-blend stage (0.05 for
    GT0, else 0.5), None without one or when every texel is opaque."""
    cutoff = None
    if shader is not None:
        af = shader.alpha_func
        if af == "gt0":
            cutoff = 0.05
        elif af in ("ge128", "lt128"):
            cutoff = 0.5
        elif any(s.blend == ("gl_src_alpha", "gl_one_minus_src_alpha") for s in shader.stages):
            cutoff = 0.5
    if cutoff is not None and (tex[..., 3] == 255).all():
        cutoff = None  # nothing to cut
    return cutoff


def _emissive(name: str, shader: Shader | None, tex: np.ndarray) -> tuple[float, float, float] | None:
    """Emission of a surface-light shader (its light colour) or of lava (its mean colour), else None."""
    if shader is not None and shader.surface_light > 0:
        r, g, b = _MaterialFactory.light_colour(shader, tex)
        return (r * 1.5, g * 1.5, b * 1.5)
    if "lava" in name.lower():
        mean = srgb_to_linear(tex[..., :3].reshape(-1, 3).mean(0) / 255.0)
        return (float(mean[0]) * 2.0, float(mean[1]) * 2.0, float(mean[2]) * 2.0)
    return None


# -- conversion -----------------------------------------------------------------------------------

def _open_source(source: str | Path, map_name: str | None, pk3s: Sequence[str | Path]) -> tuple[bytes, Pk3Set, str]:
    src = Path(source)
    if not src.is_file():
        raise SceneNotFoundError(f"BSP source not found: {src}")
    if src.suffix.lower() not in (".bsp", ".pk3"):
        raise SceneFormatError(f"expected a .bsp or .pk3 file, got {src}")
    bsp = src.suffix.lower() == ".bsp"
    pk3 = Pk3Set(pk3s if bsp else [src, *[p for p in pk3s if Path(p) != src]])
    try:  # (the archives are closed on any refusal: only a map read whole leaves them open, for its textures)
        if bsp:
            return src.read_bytes(), pk3, map_name or src.stem
        if map_name is None:
            maps = [n for n in pk3.names("maps/", ".bsp") if Path(pk3.archive_of(n)) == src]
            if len(maps) != 1:
                raise SceneFormatError(f"{src} holds {len(maps)} maps ({maps}); pass map_name")
            map_name = Path(maps[0]).stem
        bsp_path = f"maps/{map_name}.bsp"
        if bsp_path not in pk3:
            raise SceneNotFoundError(f"maps/{map_name}.bsp is not in {src} or the other archives given")
        return pk3.read(bsp_path), pk3, map_name  # (a damaged map member: SceneFormatError)
    except BaseException:
        pk3.close()
        raise


def convert_bsp(
    source: str | Path,
    map_name: str | None = None,
    *,
    pk3s: Sequence[str | Path] = (),
    patch_level: int = 6,
    eye_height_units: float = 35.0,
    max_point_lights: int = 16,
    name: str | None = None,
) -> BspConversion:
    """Convert a Quake-3 map to a :class:`Scene` plus sky blocker triangles.

    Args:
        source: a ``.bsp`` file, or a ``.pk3`` archive holding ``maps/<map_name>.bsp``.
        map_name: map inside the pk3 (optional when the archive holds exactly one map).
        pk3s: further archives searched for textures and ``scripts/*.shader`` (after ``source``).
        patch_level: segments per side of each tessellated 3x3 bezier block, an integer from 1 to
            :data:`MAX_PATCH_LEVEL` (64).
        eye_height_units: camera height above a spawn entity's origin, in Q3 units (within
            +-:data:`MAX_WORLD_UNITS`).
        max_point_lights: cap on the number of point lights, an integer from 0 to
            :data:`MAX_POINT_LIGHTS` (256).
        name: scene name (default: the map name).

    Raises:
        SceneNotFoundError: the file, an archive or the map inside it is missing.
        SceneFormatError: not an IBSP v46 file, a lump is inconsistent, or the map's values make no
            valid scene (vertices that are NaN, ...), naming the file.
        ParameterError: ``patch_level``, ``max_point_lights`` or ``eye_height_units`` is out of its range.
    """
    _check_int("patch_level", patch_level, 1, MAX_PATCH_LEVEL)
    _check_int("max_point_lights", max_point_lights, 0, MAX_POINT_LIGHTS)
    if (isinstance(eye_height_units, bool) or not isinstance(eye_height_units, (int, float, np.integer, np.floating))
            or not abs(eye_height_units) <= MAX_WORLD_UNITS):  # (NaN fails the comparison)
        raise ParameterError(f"eye_height_units: expected a finite number of Q3 units from {-MAX_WORLD_UNITS} to "
                             f"{MAX_WORLD_UNITS}, got {eye_height_units!r}", "eye_height_units")
    data, pk3, map_name = _open_source(source, map_name, pk3s)
    try:
        return _convert(data, pk3, map_name, patch_level, eye_height_units, max_point_lights, name or map_name)
    except ParameterError as err:  # the scene model refused a value the map holds (NaN vertices, ...)
        where = source if Path(source).suffix.lower() == ".bsp" else f"maps/{map_name}.bsp in {source}"
        raise SceneFormatError(f"{where}: its data makes no valid scene ({err})") from err
    finally:
        pk3.close()


def _check_int(field: str, value: Any, lo: int, hi: int) -> None:
    """``value`` an integer in ``[lo, hi]``, else a ParameterError naming ``field`` and the range."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise ParameterError(f"{field}: expected an integer from {lo} to {hi}, got {value!r}", field)


def load_bsp(source: str | Path, map_name: str | None = None, **kwargs) -> Scene:
    """Load a Quake-3 map as a :class:`Scene` (see :func:`convert_bsp` for the arguments)."""
    return convert_bsp(source, map_name, **kwargs).scene


def _convert(data: bytes, pk3: Pk3Set, map_name: str, patch_level: int, eye_units: float, max_lights: int,
             scene_name: str) -> BspConversion:
    """Convert one map's bytes, its textures and shaders coming from ``pk3``."""
    bsp = _read_bsp(data, f"maps/{map_name}.bsp")
    shaders = _load_shaders(pk3)
    tex_kind = _classify_textures(bsp, shaders)
    face_kind = _face_kinds(bsp, tex_kind)
    sky = _sky_triangles(bsp, face_kind)
    per_tex, patches = _drawable_parts(bsp, face_kind, patch_level)
    factory = _MaterialFactory(pk3, shaders)
    meshes, materials = _meshes(per_tex, bsp.tex_names, factory)
    spawns, entity_lights = _entities(bsp.entities, eye_units)
    lights = _choose_lights(entity_lights, spawns, per_tex, bsp.tex_names, shaders, materials, max_lights)
    sun, sky_colour = _sun_and_sky(pk3, shaders, bsp.tex_names, tex_kind)
    scene = Scene(name=scene_name, meshes=meshes, materials=materials, sun=sun, point_lights=lights,
                  spawn_points=spawns, sky_colour=sky_colour)
    stats = _stats(bsp, face_kind, patches)
    stats.update(triangles=scene.triangle_count, materials=len(materials), missing_textures=len(factory.missing),
                 sky_triangles=len(sky), spawn_points=len(spawns), point_lights=len(lights))
    if factory.missing:  # one line per map, not one per texture (a map can miss dozens)
        shown = ", ".join(factory.missing[:3]) + (f" and {len(factory.missing) - 3} more" if len(factory.missing) > 3 else "")
        log.warning("%s: %d textures have no image and get a neutral grey material (%s)", map_name,
                    len(factory.missing), shown)
    log.info("converted %s: %d triangles, %d materials (%d without image), %d spawn points, %d lights",
             map_name, scene.triangle_count, len(materials), len(factory.missing), len(spawns), len(lights))
    return BspConversion(scene, sky, stats, factory.missing)


#: Texture (and face) kinds: drawn, sky (not drawn; blocks viewpoints), dropped.
_DRAW, _SKY, _DROP = 0, 1, 2

#: One piece of a texture's geometry in Q3 space: positions, normals, uvs, triangles (local indices).
_Part = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


@dataclass
class _Bsp:
    """The lumps a conversion reads, as arrays, plus what is derived from them once."""

    source: str  # "maps/<name>.bsp", for messages
    textures: np.ndarray  # TEXTURE_DT
    verts: np.ndarray  # VERTEX_DT
    meshverts: np.ndarray  # int64
    faces: np.ndarray  # FACE_DT
    entities: list[dict[str, str]]
    tex_names: list[str]
    face_tex: np.ndarray  # each face's texture index, int64
    positions: np.ndarray  # vertex positions, Q3 space, float64
    normals: np.ndarray  # vertex normals, Q3 space, float64
    uvs: np.ndarray  # vertex texture coordinates, float64


def _read_bsp(data: bytes, src: str) -> _Bsp:
    """Check the header and read the texture, vertex, meshvert, face and entity lumps."""
    lumps = _lumps(data, src)
    textures = _lump_array(data, lumps[LUMP_TEXTURES], TEXTURE_DT, "texture", src)
    verts = _lump_array(data, lumps[LUMP_VERTEXES], VERTEX_DT, "vertex", src)
    meshverts = _lump_array(data, lumps[LUMP_MESHVERTS], np.dtype("<i4"), "meshvert", src).astype(np.int64)
    faces = _lump_array(data, lumps[LUMP_FACES], FACE_DT, "face", src)
    off, ln = lumps[LUMP_ENTITIES]
    entities = parse_entities(data[off : off + ln].split(b"\0", 1)[0].decode("latin-1"))
    return _Bsp(
        source=src, textures=textures, verts=verts, meshverts=meshverts, faces=faces, entities=entities,
        tex_names=[t.split(b"\0", 1)[0].decode("latin-1") for t in textures["name"]],
        face_tex=faces["texture"].astype(np.int64),
        positions=verts["pos"].astype(np.float64), normals=verts["normal"].astype(np.float64),
        uvs=verts["uv"].astype(np.float64),
    )


def _load_shaders(pk3: Pk3Set) -> dict[str, Shader]:
    """Every ``scripts/*.shader`` of the archives; a script that fails to parse is skipped."""
    shaders: dict[str, Shader] = {}
    for script in pk3.names("scripts/", ".shader"):
        try:
            parse_shaders(pk3.read(script).decode("latin-1"), into=shaders)
        except Exception as err:  # noqa: BLE001 - one broken script must not stop the map
            log.warning("skipping shader script %s: %s", script, err)
    return shaders


def _classify_textures(bsp: _Bsp, shaders: dict[str, Shader]) -> np.ndarray:
    """Each texture's kind (``_DRAW``, ``_SKY`` or ``_DROP``) from its flags, contents and shader."""
    textures = bsp.textures
    kind = np.zeros(len(textures), np.int8)
    for i, nm in enumerate(bsp.tex_names):
        fl, ct = int(textures["flags"][i]), int(textures["contents"][i])
        sh = shaders.get(nm.lower())
        low = nm.lower()
        parms = sh.surfaceparms if sh else set()
        if fl & SURF_SKY or "sky" in parms:
            kind[i] = _SKY
        elif (fl & (SURF_NODRAW | SURF_HINT | SURF_SKIP) or ct & CONTENTS_FOG or parms & {"nodraw", "fog"}
              or low.startswith("textures/common/") or low == "noshader"
              or (sh is not None and sh.is_additive_only())):
            kind[i] = _DROP
    return kind


def _face_kinds(bsp: _Bsp, tex_kind: np.ndarray) -> np.ndarray:
    """Each face's kind (its texture's), after checking that the faces index inside the texture,
    vertex and meshvert lumps."""
    faces, ftex, n_tex, src = bsp.faces, bsp.face_tex, len(bsp.textures), bsp.source
    if len(faces) and (ftex.min() < 0 or ftex.max() >= n_tex):
        bad = ftex[(ftex < 0) | (ftex >= n_tex)][0]
        raise SceneFormatError(f"{src}: a face refers to texture {bad} of {n_tex}")
    if len(faces):
        if min(int(faces[k].min()) for k in ("vertex", "n_vertexes", "meshvert", "n_meshverts")) < 0:
            raise SceneFormatError(f"{src}: a face has a negative vertex or meshvert offset or count")
        vmax = (faces["vertex"].astype(np.int64) + faces["n_vertexes"]).max()
        mmax = (faces["meshvert"].astype(np.int64) + faces["n_meshverts"]).max()
        if vmax > len(bsp.verts) or mmax > len(bsp.meshverts):
            raise SceneFormatError(f"{src}: faces index past the vertex ({vmax}/{len(bsp.verts)}) or meshvert "
                                   f"({mmax}/{len(bsp.meshverts)}) lumps")
    return tex_kind[ftex] if len(faces) else np.zeros(0, np.int8)


def _triangle_soup(bsp: _Bsp, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (global vertex indices, CCW) and their face ids for polygon/mesh faces ``sel``."""
    f = bsp.faces[sel]
    n = f["n_meshverts"].astype(np.int64)
    n = n - n % 3
    total = int(n.sum())
    if total == 0:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    starts = np.repeat(f["meshvert"].astype(np.int64), n)
    within = np.arange(total) - np.repeat(np.cumsum(n) - n, n)
    idx = bsp.meshverts[starts + within] + np.repeat(f["vertex"].astype(np.int64), n)
    tri = idx.reshape(-1, 3)[:, ::-1]  # Q3 clockwise → CCW
    fid = np.repeat(np.nonzero(sel)[0], n // 3)
    ok = (tri >= 0).all(1) & (tri < len(bsp.verts)).all(1)
    return tri[ok], fid[ok]


def _patch(bsp: _Bsp, face: int | np.integer, level: int) -> _Part:
    """Bezier patch face ``face`` tessellated at ``level`` segments per side (Q3 space)."""
    f = bsp.faces[face]
    w, h = f["size"]
    return _tessellate_patch(bsp.verts[f["vertex"] : f["vertex"] + f["n_vertexes"]], w, h, level)


def _sky_triangles(bsp: _Bsp, face_kind: np.ndarray) -> np.ndarray:
    """The sky faces' triangles ``(K, 3, 3)`` float32 in world metres (patches at level 2)."""
    ftype = bsp.faces["type"]
    sky_tris, _ = _triangle_soup(bsp, np.isin(ftype, (1, 3)) & (face_kind == _SKY))
    sky_parts = [q3_to_world(bsp.positions[sky_tris])] if len(sky_tris) else []
    for fi in np.nonzero((ftype == 2) & (face_kind == _SKY))[0]:
        p, _, _, t = _patch(bsp, fi, 2)
        if len(t):
            sky_parts.append(q3_to_world(p[t]))
    return np.concatenate(sky_parts).astype(np.float32) if sky_parts else np.zeros((0, 3, 3), np.float32)


def _drawable_parts(bsp: _Bsp, face_kind: np.ndarray, patch_level: int) -> tuple[dict[int, list[_Part]], int]:
    """The drawn geometry grouped by texture index (polygon and mesh faces, then tessellated
    patches), and the number of patches that produced triangles."""
    ftype = bsp.faces["type"]
    draw_tris, draw_fid = _triangle_soup(bsp, np.isin(ftype, (1, 3)) & (face_kind == _DRAW))
    per_tex = _group_by_texture(bsp, draw_tris, draw_fid)
    patches = 0
    for fi in np.nonzero((ftype == 2) & (face_kind == _DRAW))[0]:
        p, nr, uv, t = _patch(bsp, fi, patch_level)
        if len(t):
            patches += 1
            per_tex.setdefault(int(bsp.faces[fi]["texture"]), []).append((p, nr, uv, t))
    return per_tex, patches


def _group_by_texture(bsp: _Bsp, tris: np.ndarray, fids: np.ndarray) -> dict[int, list[_Part]]:
    """Triangles (global indices) of faces ``fids`` as one part per texture, holding only the
    vertices its triangles use."""
    per_tex: dict[int, list[_Part]] = {}
    if not len(tris):
        return per_tex
    tex_of_tri = bsp.face_tex[fids]
    order = np.argsort(tex_of_tri, kind="stable")
    bounds = np.flatnonzero(np.diff(tex_of_tri[order])) + 1
    for grp in np.split(order, bounds):
        tex = int(tex_of_tri[grp[0]])
        used, inv = np.unique(tris[grp], return_inverse=True)
        per_tex.setdefault(tex, []).append((bsp.positions[used], bsp.normals[used], bsp.uvs[used], inv.reshape(-1, 3)))
    return per_tex


def _meshes(
    per_tex: dict[int, list[_Part]], tex_names: list[str], factory: _MaterialFactory
) -> tuple[list[Mesh], list[Material]]:
    """One mesh and one material per texture, in texture index order."""
    materials: list[Material] = []
    meshes: list[Mesh] = []
    for tex in sorted(per_tex):
        meshes.append(_mesh(per_tex[tex], material=len(materials)))
        materials.append(factory.material(tex_names[tex]))
    return meshes, materials


def _mesh(parts: list[_Part], material: int) -> Mesh:
    """Parts joined into one world-space mesh; missing or zero normals are recomputed from the faces."""
    offs = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
    pos = q3_to_world(np.concatenate([p[0] for p in parts])).astype(np.float32)
    nrm = q3_to_world(np.concatenate([p[1] for p in parts]), 1.0)
    idx = np.concatenate([p[3] + o for p, o in zip(parts, offs)]).astype(np.int64)
    uv = np.concatenate([p[2] for p in parts]).astype(np.float32)
    ln = np.linalg.norm(nrm, axis=1)
    bad = ~(ln > 0.5)
    if bad.any():
        nrm[bad] = vertex_normals(pos, idx)[bad]
        ln[bad] = 1.0
    nrm = (nrm / ln[:, None]).astype(np.float32)
    return Mesh(pos, nrm, uv, idx.astype(np.uint32), material=material)


def _entities(entities: list[dict[str, str]], eye_units: float) -> tuple[list[SpawnPoint], list[PointLight]]:
    """Spawn points (eye ``eye_units`` above the origin) and ``light`` entities."""
    spawns: list[SpawnPoint] = []
    lights: list[PointLight] = []
    for e in entities:
        cls = e.get("classname", "").lower()
        origin = _vec(e.get("origin"))
        if origin is None:
            continue
        if cls in SPAWN_CLASSES:
            eye = q3_to_world(origin + np.array([0.0, 0.0, eye_units]))
            spawns.append(SpawnPoint(_vec3(eye), yaw=q3_angle_to_yaw(_entity_yaw(e))))
        elif cls == "light":
            # q3map2's value: "_light", where it is 0 (or absent) "light", where that is 0 too 300
            val = _float(e.get("_light"), 0.0) or _float(e.get("light"), 0.0) or 300.0
            if val < 0:  # a negative light darkens (q3map2); as a point light it would shine
                log.debug("skipping the negative light at %s (value %g)", e.get("origin"), val)
                continue
            col = _vec(e.get("_color")) if e.get("_color") else np.ones(3)
            col = np.maximum(col, 0.0) if col is not None else np.ones(3)  # (a negative component: none of it)
            col = col / float(np.max(col)) if np.max(col) > 1e-6 else np.ones(3)  # ("0 0 0": white, as q3map2)
            lights.append(_point_light(q3_to_world(origin), col, val))
    return spawns, lights


def _entity_yaw(e: dict[str, str]) -> float:
    """An entity's yaw in Q3 degrees, as the game reads it: ``angle``, or the second of ``angles`` (pitch yaw
    roll), whichever of the two the entity sets last; 0 without either (an unreadable ``angle`` is 0, as the
    game's ``atof`` makes it; an ``angles`` of fewer than two numbers is passed over)."""
    yaw = 0.0
    for key, value in e.items():  # (in the order the entity sets them)
        if key == "angle":
            yaw = _float(value, 0.0)
        elif key == "angles":
            try:
                yaw = float(value.split()[1])
            except (IndexError, ValueError):
                pass
    return yaw


def _choose_lights(
    lights: list[PointLight], spawns: list[SpawnPoint], per_tex: dict[int, list[_Part]], tex_names: list[str],
    shaders: dict[str, Shader], materials: list[Material], max_lights: int,
) -> list[PointLight]:
    """The map's light entities if it kept any, else lights at clusters of light-emitting faces,
    else one above each spawn point; at most ``max_lights``, the strongest."""
    if not lights:
        values = _surface_light_values(per_tex, tex_names, shaders)
        lights = _surface_lights(per_tex, tex_names, shaders, materials, values, max_lights)
    if not lights:  # last resort: a light above each spawn point
        lights = [_point_light(np.asarray(sp.position) + [0.0, 1.0, 0.0], np.ones(3), 400.0)
                  for sp in spawns[:max_lights]]
    elif len(lights) > max_lights:
        lights = sorted(lights, key=lambda light: -light.intensity)[:max_lights]
    return lights


def _surface_light_values(
    per_tex: dict[int, list[_Part]], tex_names: list[str], shaders: dict[str, Shader]
) -> dict[int, float]:
    """Q3 surface-light value per drawn texture that emits: from ``q3map_surfacelight``, or, when no
    shader has one, 500 for textures whose names look like lights."""
    values = {}
    for t in per_tex:
        sh = shaders.get(tex_names[t].lower())
        if sh is not None and sh.surface_light > 0:
            values[t] = sh.surface_light
    if not values:
        values = {t: 500.0 for t in per_tex if any(k in tex_names[t].lower() for k in LIGHT_WORDS)}
    return values


def _sun_and_sky(
    pk3: Pk3Set, shaders: dict[str, Shader], tex_names: list[str], tex_kind: np.ndarray
) -> tuple[SunLight, tuple[float, float, float]]:
    """The sun and sky colour from the first sky texture that has a shader (defaults otherwise)."""
    sun = SunLight()
    sky_colour: tuple[float, float, float] = Scene("", [], []).sky_colour
    for i in np.nonzero(tex_kind == _SKY)[0]:
        sh = shaders.get(tex_names[i].lower())
        if sh is None:
            continue
        if sh.sun is not None:
            sun = _sun_from_shader(sh.sun)
        sky_colour = _sky_colour(pk3, sh) or sky_colour
        break
    return sun, sky_colour


def _vec3(v: Any) -> tuple[float, float, float]:
    x, y, z = (float(c) for c in np.asarray(v, np.float64).ravel()[:3])
    return x, y, z


def _sun_from_shader(q3_sun: tuple[float, ...]) -> SunLight:
    """``q3map_sun`` / ``q3map_sunExt`` (r g b intensity azimuth elevation) as a sun light."""
    r, g, b, inten, az, el = q3_sun
    c = np.array([r, g, b], np.float64)
    c = c / max(float(c.max()), 1e-6)
    a, e_ = math.radians(az), math.radians(el)
    to_sun = np.array([math.cos(e_) * math.cos(a), math.cos(e_) * math.sin(a), math.sin(e_)])
    d = q3_to_world(-to_sun, 1.0)
    intensity = float(np.clip(3.0 * inten / 100.0, 1.0, 6.0))
    return SunLight(direction=_vec3(d / np.linalg.norm(d)), colour=_vec3(c), intensity=intensity)


def _stats(bsp: _Bsp, face_kind: np.ndarray, patches: int) -> dict[str, int]:
    """The face counters of a conversion report."""
    ftype = bsp.faces["type"]
    return {
        "faces": len(bsp.faces),
        "dropped_faces": int(((face_kind == _DROP) | ~np.isin(ftype, (1, 2, 3))).sum()),
        "sky_faces": int((face_kind == _SKY).sum()),
        "patches": patches,
    }


def _float(s: str | None, default: float) -> float:
    try:
        return float(s) if s is not None else default
    except ValueError:
        return default


def _vec(s: str | None) -> np.ndarray | None:
    if not s:
        return None
    try:
        v = np.array([float(x) for x in s.split()[:3]], np.float64)
    except ValueError:
        return None
    return v if len(v) == 3 else None


def _point_light(pos: np.ndarray, colour, value: float) -> PointLight:
    """Q3 light value (default 300, roughly the reach in units) → renderer units: intensity
    ``value / 30`` and radius ``1.5 * value`` units, clamped to sane ranges."""
    return PointLight(
        position=_vec3(pos),
        colour=_vec3(colour),
        intensity=float(np.clip(value / 30.0, 1.0, 40.0)),
        radius=float(np.clip(value * 1.5 * UNIT, 2.0, 25.0)),
    )


def _surface_lights(
    per_tex: dict[int, list[_Part]], tex_names: list[str], shaders: dict[str, Shader], materials: list[Material],
    values: dict[int, float], max_lights: int,
) -> list[PointLight]:
    """Point lights at clusters (4 m cells) of the faces of light-emitting textures ``values``
    (texture index → Q3 surface-light value), the strongest ``max_lights``."""
    cells = _emitter_cells(per_tex, tex_names, shaders, materials, values)
    lights = [_cluster(items) for items in cells.values()]
    lights.sort(key=lambda x: -x[0])
    out = []
    for power, pos, col in lights[:max_lights]:
        value = float(np.clip(300.0 * math.sqrt(power / 300.0), 100.0, 1000.0))
        out.append(_point_light(pos, col / max(col.max(), 1e-6), value))
    return out


_Emitter = tuple[np.ndarray, float, np.ndarray]  # light position (world), power (m² x surface light), colour


def _emitter_cells(
    per_tex: dict[int, list[_Part]], tex_names: list[str], shaders: dict[str, Shader], materials: list[Material],
    values: dict[int, float],
) -> dict[tuple[int, ...], list[_Emitter]]:
    """Every triangle of an emitting texture as an emitter 0.3 m in front of its centre, binned by 4 m cell."""
    cells: dict[tuple[int, ...], list[_Emitter]] = {}
    for k, t in enumerate(sorted(per_tex)):
        if t not in values:
            continue
        sh = shaders.get(tex_names[t].lower()) or Shader(tex_names[t])
        col = np.asarray(_MaterialFactory.light_colour(sh, materials[k].texture))
        value = values[t]
        for p, nr, _, tri in per_tex[t]:
            pw = q3_to_world(p)
            nw = q3_to_world(nr, 1.0)
            c = pw[tri].mean(1)
            area = 0.5 * np.linalg.norm(np.cross(pw[tri[:, 1]] - pw[tri[:, 0]], pw[tri[:, 2]] - pw[tri[:, 0]]), axis=1)
            n = nw[tri].mean(1)
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)
            for ci, ai, ni in zip(c, area, n):
                key = tuple(np.floor(ci / 4.0).astype(int))
                cells.setdefault(key, []).append((ci + 0.3 * ni, ai * value, col))
    return cells


def _cluster(items: list[_Emitter]) -> tuple[float, np.ndarray, np.ndarray]:
    """A cell's emitters as one: total power, power-weighted position and colour."""
    w = np.array([i[1] for i in items])
    pos = np.average(np.array([i[0] for i in items]), axis=0, weights=w + 1e-9)
    col = np.average(np.array([i[2] for i in items]), axis=0, weights=w + 1e-9)
    power = float(w.sum())  # m^2 * surfacelight
    return power, pos, col


def _sky_colour(pk3: Pk3Set, sh: Shader) -> tuple[float, float, float] | None:
    """Mean linear colour of the sky's far box top (or first image), for ambient light."""
    cands = [f"{sh.farbox}_up"] if sh.farbox else []
    img = sh.first_image()
    if img:
        cands.append(img)
    for c in cands:
        p = _find_image(pk3, c)
        if p is None:
            continue
        tex = _decode_image(pk3.read(p), p)
        if tex is None:
            continue
        m = srgb_to_linear(tex[..., :3].reshape(-1, 3).mean(0) / 255.0)
        # keep the sky's hue (desaturated by half) at the default sky luminance
        default = np.asarray(Scene.__dataclass_fields__["sky_colour"].default)
        lum = np.array([0.2126, 0.7152, 0.0722])
        if m @ lum < 1e-4:
            return None
        tint = m / (m @ lum)
        tint = 0.5 * tint + 0.5
        c = tint * (default @ lum)
        return (float(c[0]), float(c[1]), float(c[2]))
    return None
