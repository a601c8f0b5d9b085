"""glTF / GLB / OBJ (and anything else trimesh reads) to :class:`Scene`.

* World transforms of the scene graph are baked into the vertices (normals by the inverse
  transpose, and winding flipped for mirroring transforms).
* Texture coordinates: trimesh stores every format with a bottom-left origin (OpenGL style; its
  glTF importer flips glTF's top-left ``v`` on load, OBJ is bottom-left already), so the
  loader writes ``v' = 1 - v`` for the renderer's top-left convention.
* Normals: taken from the file when present, otherwise computed (area weighted).
* Materials: glTF PBR (base colour factor and texture, roughness, metallic, emissive, alpha mode MASK →
  ``alpha_cutoff``; the factors multiplied by the means of a metallic-roughness texture and of an emissive
  one, the emission by ``KHR_materials_emissive_strength`` matched by material name) and OBJ/MTL (Kd, map_Kd:
  the texture multiplied by Kd where the MTL states one; roughness from the Phong exponent);
  vertex colours become a constant base colour (their mean; a glTF's ``COLOR_0`` multiplies its material's base colour).
* glTF features trimesh would read as wrong geometry are refused (:func:`_check_gltf`): an extension in
  ``extensionsRequired`` that is not read (Draco without DracoPy, meshopt, mesh quantization, ...), triangle fans,
  sparse accessors and normalized positions or texture coordinates; an extension only used is ignored with a warning
  (texture transforms, unlit materials, KTX2 textures, punctual lights).
* Units and axes as given: glTF is metres, Y up; OBJ is assumed to be the same. A level whose largest
  extent is over 2 km or under 1 m, or that looks Z-up, loads as it is with a warning (saying to export it in
  metres, Y up). Geometry more than 131072 m from the origin (where float32 steps reach 1.6 cm) loads with a
  warning: it draws with coarse depth and reprojection.
"""

from __future__ import annotations

import contextlib
import contextvars
import logging
import math
import re
import urllib.parse
from collections.abc import Iterator
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

import numpy as np

from rtp.scene import Material, Mesh, Scene, SpawnPoint
from rtp.sdk import ParameterError, srgb_to_linear

from .._images import image_values
from ._errors import SceneFormatError, SceneNotFoundError
from ._geometry import vertex_normals

__all__ = ["load_mesh_file"]

log = logging.getLogger("rtp.capture")

#: The coarsest float32 resolution (metres) at the geometry's farthest coordinate that loads without a warning:
#: beyond 131072 m from the origin, float32 steps are 1.6 cm or more and reprojection degrades.
FAR_RESOLUTION = 0.01

#: The level of the file's warnings (a texture it cannot read, geometry far from the origin): DEBUG inside
#: :func:`said_before`.
_WARNING_LEVEL: contextvars.ContextVar[int] = contextvars.ContextVar("rtp_mesh_warning_level", default=logging.WARNING)


@contextlib.contextmanager
def said_before() -> Iterator[None]:
    """Load files whose warnings were logged already (``rtp capture`` reads each file in its check before any work,
    then again in the worker that renders it): inside it they are logged at DEBUG, not said twice."""
    token = _WARNING_LEVEL.set(logging.DEBUG)
    try:
        yield
    finally:
        _WARNING_LEVEL.reset(token)


def _warn(msg: str, *args: Any) -> None:
    """A warning about the file being loaded (at DEBUG inside :func:`said_before`)."""
    log.log(_WARNING_LEVEL.get(), msg, *args)


def _image_to_rgba(img) -> np.ndarray | None:
    if img is None:
        return None
    try:  # (by its values: a 16-bit texture is not clipped to white, nor a float one cast to black)
        return np.round(image_values(img, alpha=True) * 255.0).astype(np.uint8)
    except Exception as err:  # noqa: BLE001 - a broken image becomes "untextured"
        _warn("could not convert texture image: %s", err)
        return None


def _texture_mean(img, what: str, srgb: bool = False) -> np.ndarray | None:
    """The mean RGB of a glTF texture that the renderer has no map for (metallic-roughness, emissive), in [0, 1]: its
    values as stored, or with ``srgb`` decoded to linear before they are averaged; the constant its factor is
    multiplied with (None without one, or for one that cannot be read, with a warning: the factor then stands
    alone)."""
    if img is None:
        return None
    try:
        values = image_values(img)
    except Exception as err:  # noqa: BLE001 - a broken image: the factor alone
        _warn("could not convert %s texture image: %s", what, err)
        return None
    if values.size == 0:
        return None
    values = np.asarray(values, np.float64).reshape(-1, 3)
    return (srgb_to_linear(values) if srgb else values).mean(axis=0)


def _gltf_json(p: Path) -> dict[str, Any] | None:
    """The JSON of a glTF / GLB file, None where it cannot be read (trimesh then says what it cannot read)."""
    import json

    try:
        data = p.read_bytes()
        if data[:4] == b"glTF":  # GLB: a 12-byte header, then the JSON chunk (length, type, bytes)
            (length,) = np.frombuffer(data[12:16], "<u4")
            data = data[20:20 + int(length)]
        doc = json.loads(data.decode("utf-8"))
    except (OSError, ValueError, TypeError, AttributeError):
        return None
    return doc if isinstance(doc, dict) else None


def _draco_readable() -> bool:
    """Whether trimesh can decompress ``KHR_draco_mesh_compression`` here (its decoder, and DracoPy, installed)."""
    import importlib.util

    try:
        from trimesh.exchange.gltf import extensions
    except ImportError:
        return False
    return hasattr(extensions, "draco_decode") and importlib.util.find_spec("DracoPy") is not None


#: The glTF extensions the loader reads (with trimesh), so a file may require them.
_READ_EXTENSIONS = frozenset({"KHR_materials_emissive_strength", "EXT_texture_webp"})

#: What is lost of a glTF extension the loader does not read, and what to do of a file that requires it (a file that
#: only uses it loads without it, as the glTF specification intends, with a warning saying what is lost; one that
#: requires it is refused).
_TOOL = "a glTF tool (gltf-transform, gltfpack)"
_IGNORED_EXTENSIONS = {
    "KHR_draco_mesh_compression": ("its Draco-compressed geometry is not decompressed", "install DracoPy (pip install "
                                   "DracoPy), through which trimesh decompresses it, or export it without Draco "
                                   f"compression (Blender: untick Compression in the glTF exporter) or decompress it "
                                   f"with {_TOOL}"),
    "EXT_meshopt_compression": ("its meshopt-compressed buffers are not decompressed",
                                f"export it without meshopt compression, or decompress it with {_TOOL}"),
    "KHR_mesh_quantization": ("its quantized (integer) positions and texture coordinates are not dequantized",
                              f"export it without quantization, or dequantize it with {_TOOL}"),
    "KHR_texture_transform": ("texture offsets, scales and rotations are not applied",
                              f"bake the transforms into the texture coordinates with {_TOOL}"),
    "KHR_texture_basisu": ("KTX2 / Basis Universal textures are not read (a PNG or JPEG fallback is)",
                           "export its textures as PNG or JPEG"),
    "KHR_materials_unlit": ("unlit materials are drawn lit", "export its materials as PBR (metallic-roughness)"),
    "KHR_lights_punctual": ("its lights are ignored (the scene keeps the default sun)", "export it without lights"),
}

#: The primitive attributes the loader reads (trimesh reads no sparse or normalized accessor values of them).
_READ_ATTRIBUTES = ("POSITION", "NORMAL", "TEXCOORD_0", "COLOR_0")


def _check_gltf(p: Path, doc: dict[str, Any]) -> None:
    """Refuse a glTF / GLB file that trimesh would load as wrong geometry without a word, and warn of the extensions
    it uses that are not read.

    Refused (:class:`SceneFormatError` naming the file, the feature and what to do): an extension in
    ``extensionsRequired`` that is not read (Draco geometry where DracoPy is not installed: trimesh loaded every
    vertex at the origin; meshopt: a bare ``KeyError: 'uri'``; ``KHR_mesh_quantization``: normalized positions
    32767 times too large); a triangle fan (``mode`` 6: trimesh dropped it, so a level of fans "contained no
    triangles"); a sparse accessor (trimesh reads only its base values, or zeros) or a normalized integer
    position or texture coordinate (read as the integers: texture coordinates 65535 times too large; core glTF
    allows them without any extension) read by a triangle primitive."""
    ext_used = doc.get("extensionsUsed")
    ext_req = doc.get("extensionsRequired")
    used = [e for e in ext_used if isinstance(e, str)] if isinstance(ext_used, list) else []
    required = [e for e in ext_req if isinstance(e, str)] if isinstance(ext_req, list) else []
    readable = _READ_EXTENSIONS | ({"KHR_draco_mesh_compression"} if _draco_readable() else set())
    for ext in required:
        if ext not in readable:
            lost, fix = _IGNORED_EXTENSIONS.get(ext, ("", f"export it without it, or convert it with {_TOOL}"))
            raise SceneFormatError(f"{p}: it requires the glTF extension {ext}, which rtp does not read"
                                   f"{f' ({lost})' if lost else ''}: {fix}")
    ignored = [e for e in dict.fromkeys(used) if e not in readable and e not in required]
    if ignored:
        _warn("%s: it uses glTF extension(s) rtp does not read, loaded without them: %s", p,
              "; ".join(f"{e} ({_IGNORED_EXTENSIONS[e][0]})" if e in _IGNORED_EXTENSIONS else e for e in ignored))
    accessors = doc.get("accessors")
    accessors = accessors if isinstance(accessors, list) else []
    meshes = doc.get("meshes")
    for mi, mesh in enumerate(meshes if isinstance(meshes, list) else []):
        prims = mesh.get("primitives") if isinstance(mesh, dict) else None
        for pi, prim in enumerate(prims if isinstance(prims, list) else []):
            if not isinstance(prim, dict):
                continue
            where = f"{p}: mesh {mesh.get('name', mi)!r} primitive {pi}"
            mode = prim.get("mode", 4)
            if mode == 6:
                raise SceneFormatError(f"{where} is a triangle fan (mode 6), which rtp does not read: export it "
                                       f"as triangles (mode 4) or convert it with {_TOOL}")
            if mode not in (4, 5):
                continue  # (points and lines: skipped, as there is nothing to draw of them)
            attrs = prim.get("attributes")
            used_by = [(k, v) for k, v in (attrs.items() if isinstance(attrs, dict) else ()) if k in _READ_ATTRIBUTES]
            if "indices" in prim:
                used_by.append(("indices", prim["indices"]))
            for key, index in used_by:
                a = accessors[index] if isinstance(index, int) and 0 <= index < len(accessors) else None
                if not isinstance(a, dict):
                    continue  # (trimesh says what it cannot read)
                if "sparse" in a:
                    raise SceneFormatError(f"{where}: its {key} is a sparse accessor (accessor {index}), which rtp "
                                           f"does not read: write it as a plain one with {_TOOL}")
                if a.get("normalized") and key in ("POSITION", "TEXCOORD_0"):
                    raise SceneFormatError(f"{where}: its {key} is quantized (normalized integers, accessor "
                                           f"{index}), which rtp does not dequantize: export it without quantization, "
                                           f"or dequantize it with {_TOOL}")


def _emissive_strengths(p: Path, doc: dict[str, Any] | None) -> dict[str, float]:
    """The ``KHR_materials_emissive_strength`` of a glTF / GLB file's materials, by material name (trimesh drops the
    extension, and its materials keep only their names of the file): a lamp's emission of strength 4 loaded with its
    factor alone, a quarter as bright. A strength that no name of the file's names alone (an unnamed material, two
    of one name with other strengths) is not applied, with a warning; a file whose JSON cannot be read (``doc``
    None: :func:`_gltf_json`) gives none."""
    materials = (doc or {}).get("materials") or []
    found: dict[str, set[float]] = {}
    lost = 0
    for mat in materials if isinstance(materials, list) else []:
        exts = mat.get("extensions") if isinstance(mat, dict) else None
        ext = exts.get("KHR_materials_emissive_strength") if isinstance(exts, dict) else None
        if not isinstance(ext, dict):  # (not a material, or none of the extension: trimesh says what it cannot read)
            continue
        strength = ext.get("emissiveStrength", 1.0)
        if not isinstance(strength, (int, float)) or isinstance(strength, bool) or not math.isfinite(strength) \
                or strength < 0:
            continue  # (not a strength: the factor alone)
        name = mat.get("name")
        if isinstance(name, str) and name:
            found.setdefault(name, set()).add(float(strength))
        elif strength != 1.0:
            lost += 1
    strengths = {name: next(iter(v)) for name, v in found.items() if len(v) == 1 and v != {1.0}}
    lost += sum(1 for v in found.values() if len(v) > 1)
    if lost:
        _warn("%s: the emissive strength (KHR_materials_emissive_strength) of %d material(s) is not applied: they have "
              "no name, or share it with another of another strength; give each its own name", p, lost)
    return strengths


def _colour01(c, default=(0.8, 0.8, 0.8, 1.0)) -> tuple[float, float, float, float]:
    if c is None:
        return default
    a = np.asarray(c, np.float64).ravel()
    if a.size == 3:
        a = np.append(a, 255.0 if a.max() > 1.0 else 1.0)
    if a.max() > 1.0 or np.issubdtype(np.asarray(c).dtype, np.integer):
        a = a / 255.0
    return tuple(float(x) for x in np.clip(a[:4], 0.0, 1.0))  # type: ignore[return-value]


def _vertex_colour_mean(colors: Any, n: int) -> np.ndarray | None:
    """The mean RGBA, in [0, 1], of a glTF primitive's ``COLOR_0`` as trimesh reads it (float, or unsigned 8- or
    16-bit integers standing for [0, 1]; RGB or RGBA, alpha 1 where there is none); None without one for each of its
    ``n`` vertices."""
    if colors is None:
        return None
    c = np.asarray(colors)
    if c.ndim != 2 or c.shape[1] not in (3, 4) or len(c) != n or n == 0:
        return None
    scale = float(np.iinfo(c.dtype).max) if np.issubdtype(c.dtype, np.integer) else 1.0
    mean = np.clip(c.astype(np.float64) / scale, 0.0, 1.0).mean(axis=0)
    return np.append(mean, 1.0) if mean.size == 3 else mean


def _rgb(value: Any) -> tuple[float, float, float]:
    r, g, b = (float(x) for x in np.asarray(value, np.float64).ravel()[:3])
    return r, g, b


def _resolver(p: Path) -> Any:
    """The resolver through which trimesh reads the files that ``p`` names (an OBJ's material library and
    textures, a glTF's buffers and images), and :func:`_obj_library` the library. A name is looked for relative
    to ``p``'s folder as the formats intend, ``../textures/wall.png`` included (trimesh's default refuses
    anything outside that folder: a glTF's texture there was dropped without a word, an OBJ's library there
    gave trimesh's grey placeholder texture); then by its last part there (an absolute path from another
    machine, ``C:\\art\\room.mtl`` or ``/home/me/room.mtl``); then in the folders of ``also`` (an OBJ's material
    library's, whose ``map_Kd`` names are relative to it); a percent-encoded glTF URI (``my%20wall.png``, as
    exporters write a name with a space) also by its decoded name. The names it cannot read are kept in
    ``missing``."""
    from trimesh.resolvers import FilePathResolver

    class _Resolver(FilePathResolver):
        def __init__(self) -> None:
            super().__init__(str(p), allow_anywhere=True)
            self.missing: list[str] = []
            self.also: list[Path] = []

        def where(self, name: str) -> Path | None:
            for text in dict.fromkeys((name.strip(), urllib.parse.unquote(name.strip()))):
                if not text:
                    continue
                # (an absolute name is never read where it points: /etc/passwd or /home/me/.ssh/id_rsa of this
                # machine was read as a buffer or texture, into the scene; it is a path of the machine the scene was
                # made on, looked for below the scene's folder and by its last part)
                absolute = PurePosixPath(text).is_absolute() or PureWindowsPath(text).anchor != ""
                below = text[len(PureWindowsPath(text).drive):].lstrip("/\\") if absolute else text.lstrip("/")
                parts = ((text,) if not absolute else ()) + (below, PureWindowsPath(text).name)
                for base in (Path(self.parent), *self.also):
                    for part in dict.fromkeys(parts):
                        path = base / part
                        if path.is_file():
                            return path
            return None

        def get(self, name: str) -> bytes:
            path = self.where(name)
            if path is None:
                self.missing.append(name)
                raise FileNotFoundError(f"{name}: no such file (looked for in {self.parent})")
            return path.read_bytes()

    return _Resolver()


def _obj_library(p: Path, resolver: Any) -> tuple[Path | None, dict[str, str] | None]:
    """The material library an OBJ file names (its first ``mtllib``, the one trimesh reads) and the texture
    (``map_Kd``) each of its materials names; ``(None, {})`` without a library, None for a library that cannot be
    read (logged as a warning naming it: trimesh only logs it at DEBUG; its grey stand-in material is replaced
    by the untextured default in :func:`_material_of`). The library is read through ``resolver``, trimesh's
    (:func:`_resolver`), so both find the same file (an absolute path from another machine, ``C:/art/room.mtl``
    or ``/home/me/room.mtl``, is looked for by its name beside the OBJ, as trimesh does)."""
    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None, {}
    m = re.search(r"^[ \t]*mtllib[ \t]+(\S.*?)[ \t]*\r?$", text, re.MULTILINE)
    if m is None:
        return None, {}
    found = resolver.where(m.group(1))
    lib = p.parent / m.group(1) if found is None else found
    try:
        if found is None:  # (not read where it points: an absolute name of this machine, /etc/..., was read, and
            raise FileNotFoundError(2, "No such file or directory")  # its folder searched for trimesh's library)
        mtl = lib.read_text(encoding="utf-8", errors="replace")
    except OSError as err:
        _warn("%s: its material library %s cannot be read (%s): its materials are dropped (the meshes "
                    "untextured, in the default material)", p, lib, err.strerror or err)
        return lib, None
    if lib.parent.resolve() != Path(resolver.parent).resolve():
        resolver.also.append(lib.parent)  # (its map_Kd names are relative to it)
    textures: dict[str, str] = {}
    current = ""
    for line in mtl.splitlines():
        words = line.split()
        if len(words) < 2:
            continue
        key = words[0].lower()
        if key == "newmtl":
            current = " ".join(words[1:])
        elif key == "map_kd":
            textures[current] = line[line.lower().index("map_kd") + 6:].strip()
    return lib, textures


def _material_of(geom: Any, name: str, library_lost: bool = False,
                 strengths: dict[str, float] | None = None) -> tuple[Material, bool]:
    """Material of a trimesh geometry and whether it carries texture coordinates (``library_lost``: the
    OBJ names no material library, or one that could not be read, so trimesh's placeholder material, a grey
    2x2 texture, is dropped for the untextured default: a constant albedo of ``Material.base_color``;
    ``strengths``: a glTF's emissive strengths by material name, :func:`_emissive_strengths`)."""
    vis: Any = getattr(geom, "visual", None)
    kind = getattr(vis, "kind", None)
    if kind == "texture" and getattr(vis, "material", None) is not None:
        m = vis.material
        has_uv = getattr(vis, "uv", None) is not None and len(vis.uv) == len(geom.vertices)
        if library_lost and not (hasattr(m, "baseColorFactor") or hasattr(m, "roughnessFactor")):
            return Material(name=name), has_uv  # (not trimesh's grey placeholder texture)
        if hasattr(m, "baseColorFactor") or hasattr(m, "roughnessFactor"):  # PBRMaterial
            tex = _image_to_rgba(getattr(m, "baseColorTexture", None)) if has_uv else None
            cutoff = None
            if str(getattr(m, "alphaMode", "") or "").upper() == "MASK":
                cutoff = float(m.alphaCutoff) if getattr(m, "alphaCutoff", None) is not None else 0.5
            rough = float(1.0 if getattr(m, "roughnessFactor", None) is None else m.roughnessFactor)
            metal = float(1.0 if getattr(m, "metallicFactor", None) is None else m.metallicFactor)
            # the factors multiply their textures (glTF): a metallic-roughness texture's green channel is roughness,
            # its blue one metalness (linear), an emissive texture is sRGB; the scene holds one value a material, so
            # the factors are multiplied by the textures' means (the factor alone, 1 by default, drew a material with
            # a metallic-roughness texture fully metallic, and one with an emissive texture glowing all over)
            mr_mean = _texture_mean(getattr(m, "metallicRoughnessTexture", None), "metallic-roughness")
            if mr_mean is not None:
                rough, metal = rough * float(mr_mean[1]), metal * float(mr_mean[2])
            emis = getattr(m, "emissiveFactor", None)
            emissive = _rgb(emis) if emis is not None else (0.0, 0.0, 0.0)
            if any(emissive):
                e_mean = _texture_mean(getattr(m, "emissiveTexture", None), "emissive", srgb=True)
                if e_mean is not None:
                    emissive = _rgb(np.asarray(emissive) * e_mean)
                strength = (strengths or {}).get(str(getattr(m, "name", None)), 1.0)
                emissive = _rgb(np.asarray(emissive) * strength)
            base = _colour01(getattr(m, "baseColorFactor", None), (1.0, 1.0, 1.0, 1.0))
            vcol = _vertex_colour_mean((getattr(vis, "vertex_attributes", None) or {}).get("color"), len(geom.vertices))
            if vcol is not None:  # (glTF: COLOR_0 multiplies the base colour; trimesh keeps it beside the material)
                base = tuple(float(b * c) for b, c in zip(base, vcol))  # type: ignore[assignment]
            return Material(
                name=str(getattr(m, "name", None) or name),
                base_color=base,
                texture=tex,
                roughness=rough,
                metallic=metal,
                emissive=emissive,
                alpha_cutoff=cutoff,
            ), has_uv
        # SimpleMaterial (OBJ/MTL)
        tex = _image_to_rgba(getattr(m, "image", None)) if has_uv else None
        gloss = float(getattr(m, "glossiness", None) or 0.0)
        rough = math.sqrt(2.0 / (gloss + 2.0)) if gloss > 0 else 0.8  # Blinn-Phong exponent → roughness
        # Kd multiplies map_Kd, as in the MTL convention (Blender, trimesh's own viewer); an MTL without a Kd leaves the
        # texture as it is (trimesh's diffuse is then its 0.4 grey default, not the file's)
        stated = "kd" in (getattr(m, "kwargs", None) or {})
        base = (1.0, 1.0, 1.0, 1.0) if tex is not None and not stated else _colour01(getattr(m, "diffuse", None))
        return Material(name=str(getattr(m, "name", None) or name), base_color=base, texture=tex,
                        roughness=float(np.clip(rough, 0.05, 1.0))), has_uv
    if kind == "vertex" or kind == "face":
        cols = vis.vertex_colors if kind == "vertex" else vis.face_colors
        return Material(name=name, base_color=_colour01(np.asarray(cols, np.float64).mean(0))), False
    return Material(name=name), False


#: The largest extents, metres, outside which a mesh file's level loads with a warning that it is in other units
#: than metres: over 2 km (a 20 m level modelled in centimetres), under 1 m (a 50 m one scaled down 100 times
#: once too often; a 1 m test quad or a small prop is no level either, but loads without a word).
PLAUSIBLE_EXTENT = (1.0, 2000.0)

#: The largest extent, metres, from which a mesh file's level is checked for a Z-up look (a single quad or a
#: prop smaller than a room says nothing of its axes).
AXES_CHECKED_FROM = 2.0


def _check_units_and_axes(scene: Scene, file: str) -> None:
    """Warn (nothing more) when ``scene`` looks modelled in other units than metres or with another axis than Y up:
    its largest extent outside :data:`PLAUSIBLE_EXTENT`, or (from :data:`AXES_CHECKED_FROM` across) its thinnest
    extent along X or Z (less than half its height) with more of its surface facing along that axis than up or
    down (a Z-up level read as Y-up stands on its side: its floors face a horizontal axis)."""
    lo, hi = (np.asarray(b, np.float64) for b in scene.bounds)
    ext = hi - lo
    fix = "rtp reads a mesh file as it is (no scale or axis option): export the level in metres, Y up"
    if not PLAUSIBLE_EXTENT[0] <= float(ext.max()) <= PLAUSIBLE_EXTENT[1]:
        _warn("%s: its geometry spans %s m, implausible for a level in metres (a level modelled in centimetres loads "
              "100 times too large); %s", file, " x ".join(f"{v:.4g}" for v in ext), fix)
    thin = int(np.argmin(ext))
    if thin == 1 or ext[thin] >= 0.5 * ext[1] or float(ext.max()) < AXES_CHECKED_FROM:
        return
    tris = np.concatenate([m.positions.astype(np.float64)[m.indices.astype(np.int64)] for m in scene.meshes])
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    area = np.linalg.norm(n, axis=1)
    facing = [float(area[np.abs(n[:, k]) > 0.9 * area].sum()) for k in range(3)]  # (within 26 degrees of the axis)
    if facing[thin] > facing[1]:
        axis = "XYZ"[thin]
        _warn("%s: it looks modelled with %s up (it spans %s m, thinnest along %s, and more of its surface faces "
              "along %s than up or down): it stands on its side, its spawn point and viewpoints with it; %s", file,
              axis, " x ".join(f"{v:.4g}" for v in ext), axis, axis, fix)


def load_mesh_file(path: str | Path, *, name: str | None = None, eye_height: float = 1.6) -> Scene:
    """Load a glTF/GLB/OBJ file (or any format trimesh reads) as a :class:`Scene`.

    One :class:`Mesh` and one :class:`Material` per geometry instance. No lights are read (a glTF's
    ``KHR_lights_punctual`` ones are ignored, with a warning) and there are no spawn points in these formats: the scene
    keeps the default sun, no point lights, and one
    spawn point at the centre of the bounds, ``eye_height`` above their bottom, unless that point lies outside the
    level's free space (inside a closed object, or outside a closed level: around a dome, beside an L-shaped
    corridor): then at the nearest voxel of the level's free space (``viewpoints._roomiest_spawn``). A level in
    implausible units (over 2 km or under 1 m across) or that looks Z-up loads as it is, with a warning.

    Raises:
        SceneNotFoundError: no such file.
        SceneFormatError: trimesh cannot read it, it has no triangles, or a value in it is not one a scene may
            hold (a triangle indexing a vertex it does not have, a NaN or float32-overflowing vertex, a material
            factor outside [0, 1]), named with the file and geometry; a glTF requiring an extension rtp does not
            read, or with a triangle fan, a sparse accessor or a normalized position or texture coordinate
            (:func:`_check_gltf`).
        ImportError: trimesh is not installed (``pip install 'rtp[capture]'``).
    """
    try:
        import trimesh
    except ImportError as err:
        raise ImportError("load_mesh_file needs trimesh and pillow: pip install 'rtp[capture]'") from err
    p = Path(path)
    if not p.is_file():
        raise SceneNotFoundError(f"mesh file not found: {p}")
    resolver = _resolver(p)
    obj = p.suffix.lower() == ".obj"
    lib, textures = _obj_library(p, resolver) if obj else (None, {})
    strengths: dict[str, float] = {}
    if p.suffix.lower() in (".gltf", ".glb"):
        doc = _gltf_json(p)
        if doc is not None:
            _check_gltf(p, doc)
        strengths = _emissive_strengths(p, doc)
    try:
        loaded: Any = trimesh.load(str(p), force="scene", process=False, resolver=resolver)
    except Exception as err:  # noqa: BLE001 - trimesh raises many types
        raise SceneFormatError(f"trimesh could not read {p}: {err}") from err

    if not obj:  # (an OBJ's lost library and textures are said below, by material)
        for missing in dict.fromkeys(resolver.missing):
            _warn("%s: the file %s it names cannot be read (no such file): what uses it is dropped (a texture: "
                        "the material untextured)", p, missing)
    # an OBJ without a material library: trimesh gives it (where it has texture coordinates) the same grey
    # placeholder texture as an unreadable one; both become the untextured default material
    no_library = p.suffix.lower() == ".obj" and lib is None
    unread: set[str] = set()
    meshes: list[Mesh] = []
    materials: list[Material] = []
    for node in sorted(loaded.graph.nodes_geometry):
        transform, geom_name = loaded.graph[node]
        geom = loaded.geometry.get(geom_name)
        if geom is None or not hasattr(geom, "faces") or len(geom.faces) == 0:
            continue
        T = np.asarray(transform, np.float64)
        v = np.asarray(geom.vertices, np.float64)
        f = np.asarray(geom.faces, np.int64)
        if int(f.min()) < 0 or int(f.max()) >= len(v):  # (trimesh does not check them with process=False)
            raise SceneFormatError(f"{p}: geometry {geom_name!r}: its triangles index vertices in "
                                   f"[{int(f.min())}, {int(f.max())}], expected [0, {len(v)})")
        with np.errstate(all="ignore"):  # (a NaN or infinite vertex or transform is refused by Mesh below)
            pos = v @ T[:3, :3].T + T[:3, 3]
        try:
            mat, has_uv = _material_of(geom, f"{p.stem}:{geom_name}", library_lost=no_library or textures is None,
                                       strengths=strengths)
        except ParameterError as err:  # (a factor outside [0, 1]: "Material.roughness: ...", naming no file)
            raise SceneFormatError(f"{p}: geometry {geom_name!r}: its material: {err}") from err
        obj_mat = getattr(getattr(geom, "visual", None), "material", None)
        obj_name = str(getattr(obj_mat, "name", None))
        if textures and obj_name in textures and getattr(obj_mat, "image", None) is None and obj_name not in unread:
            unread.add(obj_name)  # (trimesh drops a map_Kd it cannot read, logging it at DEBUG only)
            _warn("%s: texture %s of material %r cannot be read (no such file, or not an image): the "
                        "material is untextured", lib, textures[obj_name], obj_name)
        if has_uv:
            uv = np.asarray(geom.visual.uv, np.float64)[:, :2].copy()
            uv[:, 1] = 1.0 - uv[:, 1]  # trimesh bottom-left → top-left
        else:
            uv = np.zeros((len(v), 2))
        nrm = None
        if "vertex_normals" in geom._cache:  # normals came from the file
            nrm = np.asarray(geom.vertex_normals, np.float64)
        det = np.linalg.det(T[:3, :3])
        if det < 0:
            f = f[:, ::-1]
        if nrm is not None and len(nrm) == len(v):
            nrm = nrm @ np.linalg.inv(T[:3, :3])  # rows: n^T M^-1 == (M^-T n)^T
            ln = np.linalg.norm(nrm, axis=1, keepdims=True)
            nrm = np.where(ln > 1e-12, nrm / np.maximum(ln, 1e-12), np.nan)
            if np.isnan(nrm).any():
                nrm = None
        try:
            if nrm is None:
                with np.errstate(all="ignore"):
                    nrm = vertex_normals(pos, f)
            meshes.append(Mesh(pos, nrm.astype(np.float32), uv.astype(np.float32), f.astype(np.uint32),
                               material=len(materials)))
        except ParameterError as err:  # (a NaN vertex: "Mesh.positions: ...", naming no file)
            raise SceneFormatError(f"{p}: geometry {geom_name!r}: {err}") from err
        materials.append(mat)
    if not meshes:
        raise SceneFormatError(f"{p} contains no triangles")
    scene = Scene(name=name or p.stem, meshes=meshes, materials=materials)
    lo, hi = scene.bounds
    far = float(np.max(np.abs(np.concatenate([lo, hi]))))
    if float(np.spacing(np.float32(far))) > FAR_RESOLUTION:
        _warn("%s: its geometry lies up to %.0f m from the origin, where float32 (what the renderers draw "
                    "with) resolves only %.3f m: depth, motion and reprojection are that coarse (a capture's unseen "
                    "share grows: 10%% at the origin, 20%% at 2e5 m, 66%% at 1e6 m for one room); move the model "
                    "near the origin", p.name, far, float(np.spacing(np.float32(far))))
    _check_units_and_axes(scene, p.name)
    c = (lo + hi) / 2
    spawn = np.array([c[0], lo[1] + eye_height, c[2]], np.float64)
    from ..viewpoints import _roomiest_spawn

    found = _roomiest_spawn(scene, spawn)
    if found is None:  # (a flat quad, a prop; the capture then says where its spawn point lies and the level's bounds)
        log.info("%s: within its bounds no free space lies over its geometry (at most 6 m over a floor, at the spawn "
                 "search's resolution): its spawn point stays at the centre of the bounds, %.1f m over their bottom, "
                 "and its viewpoints may lie outside the level, or none be found", p.name, eye_height)
    elif not np.array_equal(found[0], spawn):  # the centre is not in the level's free space
        log.info("%s: the centre of its bounds lies in a free region of %.1f m^3 (inside an object, or outside the "
                 "level); its spawn point is at (%.2f, %.2f, %.2f) instead, in the level's (%.1f m^3)", p.name,
                 found[2], *found[0], found[1])
        spawn = found[0]
    scene.spawn_points = [SpawnPoint((float(spawn[0]), float(spawn[1]), float(spawn[2])), 0.0)]
    log.info("loaded %s: %d triangles, %d materials", p.name, scene.triangle_count, len(materials))
    return scene
