"""Scene sources for capture: every function returns a
:class:`rtp.scene.Scene` (numpy data, world metres, Y up, CCW front faces,
top-left texture origin).

* :func:`procedural` - a seeded generator of indoor levels; no downloads (tests, demo).
* :func:`load_mesh_file` - glTF/GLB/OBJ through trimesh.
* :func:`load_bsp` / :func:`convert_bsp` - Quake-3 BSP (IBSP v46) maps from .bsp/.pk3 files.
* :func:`fetch`, :func:`scene_by_name`, :func:`scene_blockers`, :func:`load_splits`,
  :func:`map_names` - the real levels of ``scenes.yaml`` (Debian packages, fetched into a cache).

Only maps listed in ``scenes.yaml`` can be loaded by name; the errors are in :mod:`._errors`.
See docs/scenes.md.
"""

from __future__ import annotations

from ._bsp import BspConversion, convert_bsp, load_bsp
from ._errors import FetchError, SceneError, SceneFormatError, SceneNotFoundError, UnlistedMapError
from ._fetch import (
    DEFAULT_SPLITS,
    PACKAGES,
    SPLIT_NAMES,
    check_map,
    default_cache_dir,
    fetch,
    load_splits,
    map_names,
    scene_blockers,
    scene_by_name,
    scene_list,
)
from ._mesh import load_mesh_file
from ._procedural import procedural

__all__ = [
    "DEFAULT_SPLITS",
    "PACKAGES",
    "SPLIT_NAMES",
    "BspConversion",
    "FetchError",
    "SceneError",
    "SceneFormatError",
    "SceneNotFoundError",
    "UnlistedMapError",
    "check_map",
    "convert_bsp",
    "default_cache_dir",
    "fetch",
    "load_bsp",
    "load_mesh_file",
    "load_splits",
    "map_names",
    "procedural",
    "scene_blockers",
    "scene_by_name",
    "scene_list",
]
