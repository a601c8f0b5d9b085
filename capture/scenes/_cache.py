"""Converted-scene cache: one uncompressed ``.npz`` per scene (fast to load, no pickle).

Layout: ``meta`` (a JSON string: lights, spawn points, materials without their textures,
stats), ``m{i}_pos|nrm|uv|idx`` per mesh, ``tex{j}`` per textured material, ``sky`` (blocker
triangles). Bump :data:`CACHE_VERSION` whenever the conversion changes.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import asdict
from pathlib import Path

import numpy as np

from rtp.scene import Material, Mesh, PointLight, Scene, SpawnPoint, SunLight
from rtp.sdk import ParameterError
from rtp.sdk.files import atomic_output

from ._errors import SceneFormatError

__all__ = ["CACHE_VERSION", "load_scene_npz", "save_scene_npz"]

CACHE_VERSION = 1


def save_scene_npz(path: str | Path, scene: Scene, sky: np.ndarray | None = None, stats: dict | None = None) -> None:
    """Write ``scene`` (and blocker triangles ``sky``, ``(K, 3, 3)``) atomically to ``path``.

    Raises:
        ParameterError: ``sky`` is not finite triangles of shape ``(K, 3, 3)``.
    """
    arrays: dict[str, np.ndarray] = {}
    mats = []
    for j, m in enumerate(scene.materials):
        d = asdict(m)
        d.pop("texture")
        d["has_texture"] = m.texture is not None
        if m.texture is not None:
            arrays[f"tex{j}"] = np.ascontiguousarray(m.texture, np.uint8)
        mats.append(d)
    meshes = []
    for i, mesh in enumerate(scene.meshes):
        arrays[f"m{i}_pos"] = mesh.positions
        arrays[f"m{i}_nrm"] = mesh.normals
        arrays[f"m{i}_uv"] = mesh.uvs
        arrays[f"m{i}_idx"] = mesh.indices
        meshes.append(mesh.material)
    meta = {
        "version": CACHE_VERSION,
        "name": scene.name,
        "materials": mats,
        "meshes": meshes,
        "sun": asdict(scene.sun),
        "point_lights": [asdict(p) for p in scene.point_lights],
        "sky_colour": list(scene.sky_colour),
        "ambient": scene.ambient,
        "spawn_points": [asdict(s) for s in scene.spawn_points],
        "stats": stats or {},
    }
    arrays["meta"] = np.array(json.dumps(meta))
    sky_arr = np.zeros((0, 3, 3), np.float32) if sky is None else np.asarray(sky)
    ok = sky_arr.ndim == 3 and sky_arr.shape[1:] == (3, 3) and sky_arr.dtype.kind in "iuf"
    if ok:
        sky_arr = sky_arr.astype(np.float32)  # (finite after the cast: past float32's range is an infinity)
    if not ok or not np.isfinite(sky_arr).all():  # (a cache that no load would take, as it did)
        raise ParameterError(f"sky: expected finite triangles of shape (K, 3, 3), got {sky_arr.dtype} {sky_arr.shape}",
                             "sky")
    arrays["sky"] = sky_arr
    with atomic_output(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)  # type: ignore[arg-type]


def load_scene_npz(path: str | Path) -> tuple[Scene, np.ndarray, dict]:
    """Read a cache file written by :func:`save_scene_npz`: ``(scene, sky_triangles, stats)``.

    Raises:
        SceneFormatError: the file is not such a cache file: not an npz, cut short, of another
            cache version, or its header or arrays not of the shape this rtp writes (an unknown
            material field, ``"sun": null``, a list for an object, a value out of its range, ...).
        OSError: the file cannot be opened.
    """
    try:
        return _load_scene_npz(path)
    except SceneFormatError:
        raise
    except (ValueError, KeyError, TypeError, AttributeError, IndexError, EOFError, zipfile.BadZipFile) as err:
        # (an sdk.ParameterError of the scene model is a ValueError: a value out of its range)
        raise SceneFormatError(f"{path}: not a converted scene of this rtp ({type(err).__name__}: {err})") from err


def _load_scene_npz(path: str | Path) -> tuple[Scene, np.ndarray, dict]:
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        if not isinstance(meta, dict):
            raise SceneFormatError(f"{path}: its header is a JSON {type(meta).__name__}, not an object")
        if meta.get("version") != CACHE_VERSION:
            raise SceneFormatError(f"{path}: cache version {meta.get('version')}, expected {CACHE_VERSION}")
        materials = []
        for j, d in enumerate(meta["materials"]):
            has = d.pop("has_texture")
            d["base_color"] = tuple(d["base_color"])
            d["emissive"] = tuple(d["emissive"])
            materials.append(Material(texture=z[f"tex{j}"] if has else None, **d))
        meshes = [
            Mesh(z[f"m{i}_pos"], z[f"m{i}_nrm"], z[f"m{i}_uv"], z[f"m{i}_idx"], material=int(mat))
            for i, mat in enumerate(meta["meshes"])
        ]
        sky = z["sky"]
    if sky.ndim != 3 or sky.shape[1:] != (3, 3) or sky.dtype.kind != "f" or not np.isfinite(sky).all():
        # (it was returned as it was: the capture failed later, in sample_viewpoints, instead of converting again)
        raise SceneFormatError(f"{path}: its sky triangles are {sky.dtype} {sky.shape}, not finite floats of "
                               "shape (K, 3, 3)")
    sun = meta["sun"]
    scene = Scene(
        name=meta["name"],
        meshes=meshes,
        materials=materials,
        sun=SunLight(tuple(sun["direction"]), tuple(sun["colour"]), sun["intensity"]),
        point_lights=[PointLight(tuple(p["position"]), tuple(p["colour"]), p["intensity"], p["radius"])
                      for p in meta["point_lights"]],
        sky_colour=tuple(meta["sky_colour"]),
        ambient=meta["ambient"],
        spawn_points=[SpawnPoint(tuple(s["position"]), s["yaw"]) for s in meta["spawn_points"]],
    )
    stats = meta.get("stats", {})
    if not isinstance(stats, dict):
        raise SceneFormatError(f"{path}: its header's stats are a JSON {type(stats).__name__}, not an object")
    return scene, sky, stats
