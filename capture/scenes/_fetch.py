"""Fetching the real levels and the split API.

``fetch`` downloads the Debian packages with ``apt-get download`` (no root needed, nothing is
installed), unpacks them with ``dpkg-deb -x`` into the cache folder, finds the .pk3 archives
and writes ``index.json`` (map name → archive). ``scene_by_name`` loads only maps that
``scenes.yaml`` lists, converting once and caching the result as ``converted/<map>.v<N>.npz``.

Cache layout::

    <cache>/debs/*.deb            downloaded packages
    <cache>/root/...              their unpacked contents
    <cache>/pk3/map-20kdm2.pk3    gunzipped from libirrlicht-doc's media/map-20kdm2.pk3.gz
    <cache>/index.json            maps → archives, texture archive groups
    <cache>/converted/*.npz       converted scenes (see _cache.py)
"""

from __future__ import annotations

import contextlib
import gzip
import json
import logging
import os
import re
import shlex
import shutil
import subprocess
import tempfile
import time
import zipfile
import zlib
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rtp.scene import Scene
from rtp.sdk import ParameterError

from ._bsp import BspConversion, convert_bsp
from ._cache import CACHE_VERSION, load_scene_npz, save_scene_npz
from ._errors import FetchError, SceneError, SceneFormatError, SceneNotFoundError, UnlistedMapError

__all__ = [
    "DEFAULT_SPLITS",
    "default_cache_dir",
    "PACKAGES",
    "fetch",
    "SPLIT_NAMES",
    "load_splits",
    "map_names",
    "scene_blockers",
    "scene_by_name",
    "scene_list",
]

log = logging.getLogger("rtp.capture")

PACKAGES = ("openarena-081-maps", "openarena-081-textures", "openarena-oacmp1", "libirrlicht-doc")
DEFAULT_SPLITS = Path(__file__).with_name("scenes.yaml")
SPLIT_NAMES = ("train", "validation", "test")
INDEX_VERSION = 1


def _progress(it, **kw):
    try:
        from tqdm.auto import tqdm
    except ImportError:  # tqdm is optional
        return it
    return tqdm(it, **kw)


# -- splits ---------------------------------------------------------------------------------------

def load_splits(path: str | Path | None = None) -> dict[str, list[str]]:
    """Read ``scenes.yaml``: ``{"train": [...], "validation": [...], "test": [...]}``.

    Raises:
        SceneNotFoundError: the file does not exist.
        SceneFormatError: a split is missing or not a list of names, or a map is in two splits.
    """
    import yaml

    p = Path(path) if path is not None else DEFAULT_SPLITS
    if not p.is_file():
        raise SceneNotFoundError(f"split file not found: {p}")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except UnicodeDecodeError as err:
        raise SceneFormatError(f"{p}: not a split file, not even UTF-8 text ({err.reason} at byte {err.start})") from err
    except yaml.YAMLError as err:
        from rtp.sdk.files import yaml_problem

        raise SceneFormatError(f"{p}: not valid YAML ({yaml_problem(err)})") from err
    if not isinstance(data, dict):
        raise SceneFormatError(f"{p}: expected a mapping with keys {SPLIT_NAMES}, got {type(data).__name__}")
    extra = set(data) - set(SPLIT_NAMES)
    if extra:  # (first: a misspelt 'trian:' read as "'train' must be a list of map names, got None")
        raise SceneFormatError(f"{p}: unknown keys {sorted(map(str, extra))}; expected {SPLIT_NAMES}")
    out: dict[str, list[str]] = {}
    seen: dict[str, str] = {}
    for split in SPLIT_NAMES:
        if split not in data:
            raise SceneFormatError(f"{p}: no '{split}' split; expected the keys {SPLIT_NAMES} (an empty list for none)")
        names = data[split]
        if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
            raise SceneFormatError(f"{p}: '{split}' must be a list of map names, got {names!r}")
        for n in names:
            if n in seen:
                where = f"listed twice in '{split}'" if seen[n] == split else f"in both '{seen[n]}' and '{split}'"
                raise SceneFormatError(f"{p}: map {n!r} is {where}")
            seen[n] = split
        out[split] = list(names)
    return out


def map_names(split: str | None = None, splits: str | Path | None = None) -> list[str]:
    """Maps of one split (``"train"``, ``"validation"``, ``"test"``) or of all splits.

    Raises:
        ParameterError: ``split`` is not one of :data:`SPLIT_NAMES` (nor None).
    """
    if split is not None and split not in SPLIT_NAMES:  # (checked before the file: a bad argument, not a bad map)
        raise ParameterError(f"split: expected one of {', '.join(SPLIT_NAMES)} (or None for every split), "
                             f"got {split!r}", "split")
    s = load_splits(splits)
    if split is None:
        return [n for k in SPLIT_NAMES for n in s[k]]
    return list(s[split])


def _check_listed(name: str, split: str | None, splits: str | Path | None) -> None:
    if not isinstance(name, str):  # (a bare TypeError from the suggestions below: 'int' object is not iterable)
        raise ParameterError(f"name: expected a map name (a string of `rtp scenes list`), got "
                             f"{type(name).__name__} {name!r}", "name")
    allowed = map_names(split, splits)
    if name not in allowed:
        import difflib

        where = f"split '{split}'" if split else "any split"
        close = difflib.get_close_matches(name, allowed, n=3)  # (a typo's neighbours before the first three maps)
        listed = f"did you mean {', '.join(close)}?" if close else f"e.g. {', '.join(allowed[:3])}"
        raise UnlistedMapError(
            f"map {name!r} is not listed in {where} of {splits or DEFAULT_SPLITS}; only listed maps may be used "
            f"({len(allowed)} listed: {listed}; `rtp scenes list` lists them)"
        )


# -- fetch ----------------------------------------------------------------------------------------

def check_map(name: str, cache_dir: str | Path, *, split: str | None = None,
              splits: str | Path | None = None) -> None:
    """That ``name`` is listed (in ``split``) and fetched into ``cache_dir``, without loading it: what
    a job checks before it writes anything. Raises :class:`UnlistedMapError` or
    :class:`SceneNotFoundError`, as :func:`scene_by_name` would."""
    _check_listed(name, split, splits)
    cache = Path(cache_dir)
    if name not in _read_index(cache)["maps"]:
        raise SceneNotFoundError(f"map {name!r} is not in the scene cache {cache}: run `rtp scenes fetch --cache-dir "
                                 f"{shlex.quote(str(cache))}` first")


def _run(cmd: Sequence[str], cwd: Path, debs: Path | None = None) -> None:
    """``cmd`` in ``cwd``, a :class:`FetchError` if it cannot run or fails (``debs``: the folder the
    packages go to, named where the command is missing; default ``cwd``)."""
    exe = shutil.which(cmd[0])
    if exe is None:
        raise FetchError(
            f"{cmd[0]} not found: fetching needs a Debian/Ubuntu system (or put the packages' .deb files "
            f"{list(PACKAGES)} into {debs or cwd} yourself)"
        )
    try:  # (errors="replace": a byte its output cannot decode was a UnicodeDecodeError, not the command's failure)
        res = subprocess.run([exe, *cmd[1:]], cwd=cwd, capture_output=True, text=True, errors="replace", check=False)
    except OSError as err:
        raise FetchError(f"could not run {' '.join(cmd)}: {err}") from err
    if res.returncode != 0:
        lines = [ln.strip() for ln in (res.stderr or res.stdout).strip().splitlines() if ln.strip()]
        errors = [ln for ln in lines if ln.startswith("E: ")]  # (apt's errors, not its warnings: "W: Download is
        tail = (errors or lines)[-5:]                           # performed unsandboxed as root" hid the cause)
        raise FetchError(f"{' '.join(cmd)} failed with exit code {res.returncode}: " + " | ".join(tail))


def _unpack_again(cache: Path) -> str:
    """What to do about a damaged archive of the fetched cache ``cache``: unpack the packages again."""
    return (f"delete {cache / 'root' / '.unpacked'} and the folder {cache / 'pk3'}, then run `rtp scenes fetch "
            f"--cache-dir {shlex.quote(str(cache))}` again: it unpacks the packages again (if the archive is still "
            f"damaged, delete the packages in {cache / 'debs'} as well, to download them again)")


def _path_in_packages(archive: Path, root: Path, pk3_dir: Path) -> tuple[str, ...]:
    """The folders and name of ``archive`` (resolved) inside the unpacked packages ``root``, which decide its
    texture group: not the folders above the cache (a cache folder under one named ``openarena`` put every
    archive in the OpenArena group); none for the archives gunzipped into ``pk3_dir``; the whole path for one
    that a link leads out of the cache."""
    for base, inside in ((root.resolve(), True), (pk3_dir.resolve(), False)):
        if archive.is_relative_to(base):
            return archive.relative_to(base).parts if inside else ()
    return archive.parts


def _scan_archives(root: Path, pk3_dir: Path, stale: Path | None = None) -> dict:
    """Find pk3 archives (gunzipping ``*.pk3.gz``, again where the ``.pk3`` is not a zip archive: cut short by
    a full disk, say) and the maps inside them. ``stale``: the index of an earlier fetch, removed before an archive
    is gunzipped again (it lists the archive, which this fetch may not finish)."""
    pk3_dir.mkdir(parents=True, exist_ok=True)
    for gz in sorted(root.rglob("*.pk3.gz")):
        out = pk3_dir / gz.name[:-3]
        if not out.is_file() or not zipfile.is_zipfile(out):
            if stale is not None:
                stale.unlink(missing_ok=True)
            tmp = out.with_suffix(".tmp")
            try:
                with gzip.open(gz, "rb") as src, open(tmp, "wb") as dst:
                    shutil.copyfileobj(src, dst)
            except (OSError, EOFError, zlib.error) as err:  # BadGzipFile is an OSError, a cut file an EOFError
                tmp.unlink(missing_ok=True)
                raise FetchError(f"could not gunzip {gz}: {err}") from err
            tmp.replace(out)
    archives = {p.resolve() for p in [*root.rglob("*.pk3"), *pk3_dir.glob("*.pk3")] if p.is_file()}
    maps: dict[str, str] = {}
    groups: dict[str, list[str]] = {}
    for a in sorted(archives):
        # OpenArena archives share textures and shader scripts; others stand alone
        inside = _path_in_packages(a, root, pk3_dir)
        group = "openarena" if "openarena" in inside or "baseoa" in inside else a.stem
        groups.setdefault(group, []).append(str(a))
        try:
            with zipfile.ZipFile(a) as z:
                names = z.namelist()
        except zipfile.BadZipFile as err:
            raise FetchError(f"{a} is not a pk3 (zip) archive ({err}): {_unpack_again(root.parent)}") from err
        for n in names:
            low = n.lower()
            if low.startswith("maps/") and low.endswith(".bsp"):
                maps.setdefault(Path(low).stem, str(a))
    # paths relative to the cache folder, so the folder can move
    base = root.parent.resolve()
    rel = lambda s: str(Path(s).relative_to(base)) if Path(s).is_relative_to(base) else s  # noqa: E731
    return {"version": INDEX_VERSION, "maps": {k: rel(v) for k, v in maps.items()},
            "groups": {k: [rel(x) for x in v] for k, v in groups.items()}}


def fetch(
    cache_dir: str | Path,
    maps: Iterable[str] | None = None,
    *,
    splits: str | Path | None = None,
    convert: bool = False,
    progress: bool = True,
) -> dict[str, Path]:
    """Download and unpack the scene packages into ``cache_dir`` and check the listed maps.

    Args:
        cache_dir: cache folder (created); packages already there are not downloaded again.
        maps: maps that must be present, a name or a list of names (default: every map of
            ``scenes.yaml``); each must be listed there.
        splits: path of ``scenes.yaml`` (default: the copy shipped with rtp).
        convert: also convert the maps now (otherwise on first :func:`scene_by_name`).
        progress: show tqdm progress bars when tqdm is installed.

    Returns:
        ``{map name: pk3 archive}`` for the requested maps.

    Raises:
        FetchError: apt-get/dpkg-deb failed, a requested map is not in the packages, another fetch
            into ``cache_dir`` is running (one at a time: the second is refused at once), or ``cache_dir``
            cannot be written and its index lacks a requested map (where it lists them all: they are
            returned, with a warning).
        UnlistedMapError: a requested map is not listed in ``scenes.yaml``.
        ParameterError: ``maps`` is not a name or a non-empty list of names, or ``cache_dir`` is a file.
    """
    cache = Path(cache_dir).resolve()
    _check_cache_folder(cache)
    wanted: list[object]
    try:
        wanted = [maps] if isinstance(maps, str) else list(maps) if maps is not None else list(map_names(None, splits))
    except TypeError:  # not iterable (maps=5): the ParameterError promised, not a bare TypeError
        wanted = [maps]
    if not all(isinstance(m, str) for m in wanted):
        raise ParameterError(f"maps: expected a map name or a list of map names, got {maps!r}", "maps")
    if maps is not None and not wanted:  # (an empty list downloaded and unpacked every package, ~400 MB, for no map)
        raise ParameterError(f"maps: expected one or more map names (None: every listed map), got an empty "
                             f"{type(maps).__name__}", "maps")
    names = [m for m in wanted if isinstance(m, str)]
    for m in names:
        _check_listed(m, None, splits)
    from rtp.sdk.files import writer_lock

    # (two fetches into one cache unpacked into the same folder at once, and the second one's gunzip of 20kdm2 found
    # its temporary file renamed away by the first: a FileNotFoundError)
    busy = lambda holder: FetchError(  # noqa: E731
        f"another fetch into {cache} is running ({holder}): wait for it to end, then run `rtp scenes fetch` again "
        "(it finds the packages that one fetched)")
    with contextlib.ExitStack() as guard:
        try:
            cache.mkdir(parents=True, exist_ok=True)
            guard.enter_context(writer_lock(cache, "rtp scenes fetch", busy))
        except OSError as err:  # (a read-only shared cache: the bare "Read-only file system: '.../.rtp-writer.lock'")
            return _fetched_read_only(cache, names, splits, convert, progress, err)
        return _fetch_locked(cache, names, splits, convert, progress)


def _fetched_read_only(cache: Path, names: list[str], splits: str | Path | None, convert: bool, progress: bool,
                       err: OSError) -> dict[str, Path]:
    """:func:`fetch` into ``cache``, a folder it cannot write (``err``): the maps, where its index lists every one (a
    shared cache fetched by someone else, read-only: nothing to do), else a :class:`FetchError` saying so."""
    why = f"{err.strerror}: {err.filename}" if err.strerror and err.filename else str(err)
    try:
        index = _read_index(cache)
    except (SceneError, OSError):
        index = None
    if index is not None and all(m in index["maps"] for m in names):
        log.warning("the scene cache %s cannot be written (%s); its index lists every map asked for (%d), so they "
                    "are used as fetched there", cache, why, len(names))
        if convert:
            for m in _progress(names, desc="convert", unit="map", disable=not progress):
                _load_cached(m, cache, index)
        return {m: cache / index["maps"][m] for m in names}
    raise FetchError(f"cannot write to the scene cache {cache} ({why}): fetch into a folder you can write "
                     f"(--cache-dir, or $RTP_SCENE_CACHE), or have the folder's owner run `rtp scenes fetch` there") from err


def _fetch_locked(cache: Path, names: list[str], splits: str | Path | None, convert: bool,
                  progress: bool) -> dict[str, Path]:
    """:func:`fetch`'s work, once its arguments are checked and it holds the cache's lock."""
    debs, root = cache / "debs", cache / "root"
    debs.mkdir(parents=True, exist_ok=True)
    stamp = root / ".unpacked"
    have = stamp.read_text(encoding="utf-8").split("\n") if stamp.exists() else []
    # (a package unpacked already needs no .deb: with debs/ deleted to free its 169 MB, every later fetch downloaded
    # the four packages again, or failed offline, for archives it had)
    missing = [p for p in PACKAGES if not list(debs.glob(f"{p}_*.deb")) and not any(n.startswith(f"{p}_") for n in have)]
    if missing:
        log.info("downloading %s into %s", " ".join(missing), debs)
        _download(missing, debs, progress)
    deb_files = sorted(debs.glob("*.deb"))
    todo = [d for d in deb_files if d.name not in have]
    if todo:  # (the archives change under the index of an earlier fetch: one that failed or was interrupted while it
        # unpacked them again left it, and `rtp scenes list` counted every map as fetched, their archives cut short)
        (cache / "index.json").unlink(missing_ok=True)
    for d in _progress(todo, desc="unpack", unit="deb", disable=not progress or not todo):
        try:
            _run(["dpkg-deb", "-x", str(d), str(root)], cache)
        except FetchError as err:
            if _deb_is_whole(d):  # (a full disk while unpacking removed the good package: 177 MB to download again)
                raise FetchError(f"{err} (kept {d}, a whole package: the unpacking failed, so if the disk is full free "
                                 f"some space and run `rtp scenes fetch` again; should it fail the same way again, "
                                 f"delete {d.name} for the next fetch to download it again)") from err
            # a damaged package (cut short by an older rtp's failed download): fetched again next time
            d.unlink(missing_ok=True)
            raise FetchError(f"{err} (removed {d.name}: the next `rtp scenes fetch` downloads it again)") from err
        have.append(d.name)
        _write_text(stamp, "\n".join(have))
    index = _scan_archives(root, cache / "pk3", cache / "index.json")
    _write_text(cache / "index.json", json.dumps(index, indent=1, sort_keys=True))
    absent = [m for m in names if m not in index["maps"]]
    if absent:
        raise FetchError(f"maps listed in {splits or DEFAULT_SPLITS} but not found in the packages {list(PACKAGES)}: "
                         f"{absent}")
    log.info("%d maps available in %s (%d requested)", len(index["maps"]), cache, len(names))
    if convert:
        for m in _progress(names, desc="convert", unit="map", disable=not progress):
            _load_cached(m, cache, index)
    return {m: cache / index["maps"][m] for m in names}


def _deb_is_whole(path: Path) -> bool:
    """Whether ``path`` is a whole Debian package by its ``ar`` structure: the magic line, then member headers whose
    sizes lead exactly to the end of the file, with ``debian-binary`` and ``data.tar*`` among them. A package cut
    short (a download or copy that stopped) or not a package at all is not; damage inside a member is not seen."""
    try:
        size = path.stat().st_size
        names: list[bytes] = []
        with open(path, "rb") as f:
            if f.read(8) != b"!<arch>\n":
                return False
            pos = 8
            while pos < size:
                f.seek(pos)
                head = f.read(60)
                if len(head) != 60 or head[58:60] != b"`\n":
                    return False
                n = int(head[48:58])
                names.append(head[:16].rstrip(b" /"))
                pos += 60 + n + (n & 1)
    except (OSError, ValueError):
        return False
    return pos in (size, size + 1) and b"debian-binary" in names and any(n.startswith(b"data.tar") for n in names)


def _download(packages: Sequence[str], debs: Path, progress: bool = False) -> None:
    """``apt-get download`` of ``packages``, one at a time, into a folder of its own inside ``debs``, each ``.deb``
    moved into ``debs`` as soon as apt-get has downloaded (and checked) it: a download that fails (a full disk, the
    network, Ctrl-C) leaves no file cut short for the next fetch to take for a package, and keeps the packages that
    arrived whole before it, so the next fetch downloads only the rest. ``progress``: a bar counting packages."""
    for old in debs.glob(".download-*"):  # (a fetch killed outright, kill -9 or SIGTERM, left its folder with up to
        if old.is_dir():                  # 177 MB in it for good; the caller holds the cache's lock: none is live)
            shutil.rmtree(old, ignore_errors=True)
    part = Path(tempfile.mkdtemp(prefix=".download-", dir=debs))
    try:
        for i, pkg in enumerate(_progress(packages, desc="download", unit="package", disable=not progress)):
            try:
                _run(["apt-get", "download", pkg], part, debs)
            except FetchError as err:
                if "not found: fetching needs" in str(err):  # (no apt-get: its message says what to do already)
                    raise
                text = str(err)
                if "Unable to locate package" in text:
                    why = ("the system's package lists do not know them: run `sudo apt-get update` (on Ubuntu with the "
                           "'universe' component enabled)")
                elif re.search(r"\b404\s+Not Found|Hash Sum mismatch|unexpected size|Mirror sync", text):
                    why = ("the mirror does not have the version the system's package lists name, or sent something "
                           "else (a proxy's or captive portal's page): run `sudo apt-get update`, then fetch again")
                else:
                    why = "no network, or no mirror reachable? check the connection (and apt's proxy settings)"
                rest = list(packages[i:])
                kept = f"kept the {i} package{'' if i == 1 else 's'} downloaded before it; " if i else ""
                raise FetchError(f"{err} ({why}; {kept}or put the packages' .deb files, from any machine's `apt-get "
                                 f"download {' '.join(rest)}`, into {debs} and run `rtp scenes fetch` again)") from err
            for f in sorted(part.glob("*.deb")):
                os.replace(f, debs / f.name)
    finally:
        shutil.rmtree(part, ignore_errors=True)


def _write_text(path: Path, text: str) -> None:
    """Write ``path`` atomically: a fetch killed mid-write leaves the previous file, never half of one."""
    from rtp.sdk.files import atomic_output

    with atomic_output(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


# -- loading --------------------------------------------------------------------------------------

def _read_index(cache: Path) -> dict:
    p = cache / "index.json"
    if not p.is_file():
        raise SceneNotFoundError(f"no scene index at {p}: run `rtp scenes fetch --cache-dir {shlex.quote(str(cache))}` first")
    again = f"run `rtp scenes fetch --cache-dir {shlex.quote(str(cache))}` again"
    try:
        index = json.loads(p.read_text(encoding="utf-8"))
    except ValueError as err:  # a truncated or overwritten file (also UnicodeDecodeError)
        raise SceneFormatError(f"{p} is not a scene index ({err}): {again}") from err
    if not isinstance(index, dict):
        raise SceneFormatError(f"{p} is not a scene index (a JSON {type(index).__name__}, not an object): {again}")
    if index.get("version") != INDEX_VERSION:
        raise SceneFormatError(f"{p} was written by another rtp version (index version {index.get('version')!r}, "
                               f"this rtp reads {INDEX_VERSION}): {again}")
    if not isinstance(index.get("maps"), dict) or not isinstance(index.get("groups"), dict):
        raise SceneFormatError(f"{p} lacks the 'maps' or 'groups' table of a scene index: {again}")
    return index


def _cache_path(name: str, cache: Path) -> Path:
    return cache / "converted" / f"{name}.v{CACHE_VERSION}.npz"


def _load_cached(name: str, cache: Path, index: dict) -> tuple[Scene, np.ndarray]:
    path = _cache_path(name, cache)
    if path.is_file():
        try:
            scene, sky, _ = load_scene_npz(path)
            return scene, sky
        except (SceneFormatError, OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
            log.warning("ignoring unreadable cache %s: %s", path, err)
    conv = convert_from_cache(name, cache, index)
    try:
        save_scene_npz(path, conv.scene, conv.sky_triangles, conv.stats)
    except OSError as err:  # (a read-only shared cache, a full disk: the scene, converted, was lost to the error)
        log.warning("could not cache the converted scene %r (%s); it is converted again at its next load", name, err)
    return conv.scene, conv.sky_triangles


def convert_from_cache(name: str, cache_dir: str | Path, index: dict | None = None) -> BspConversion:
    """Convert a fetched map from its archives (no npz cache involved; for benchmarks/tools)."""
    cache = Path(cache_dir)
    index = index if index is not None else _read_index(cache)
    if name not in index["maps"]:
        raise SceneNotFoundError(f"map {name!r} is not in the fetched packages (cache {cache})")
    archive = index["maps"][name]
    group = next((g for g in index["groups"].values() if archive in g), [archive])
    archive, group = str(cache / archive), [str(cache / a) for a in group]
    t0 = time.perf_counter()
    try:
        conv = convert_bsp(archive, name, pk3s=[a for a in group if a != archive])
    except SceneFormatError as err:
        if not isinstance(err.__cause__, (zipfile.BadZipFile, zlib.error, EOFError)):
            raise
        # a damaged archive (a member failing its CRC, no zip at all): say what to delete
        raise SceneFormatError(f"{err} (in the fetched cache: {_unpack_again(cache)})") from err
    log.info("converted %s in %.2f s", name, time.perf_counter() - t0)
    return conv


def scene_by_name(name: str, cache_dir: str | Path, *, split: str | None = None,
                  splits: str | Path | None = None) -> Scene:
    """Load a map listed in ``scenes.yaml`` (optionally required to be in ``split``).

    The first call converts the BSP and caches it (where the cache can be written: else a warning); later calls
    read the cache.

    Raises:
        UnlistedMapError: the map is not listed (in that split).
        ParameterError: ``split`` is not one of :data:`SPLIT_NAMES` (nor None), or ``name`` is not a string.
        SceneNotFoundError: the cache has not been fetched, or the map is missing from it.
        SceneFormatError: the cache's ``index.json`` or an archive of the map is damaged, naming what to do.
    """
    _check_listed(name, split, splits)
    cache = Path(cache_dir)
    return _load_cached(name, cache, _read_index(cache))[0]


def scene_blockers(name: str, cache_dir: str | Path, *, splits: str | Path | None = None) -> np.ndarray:
    """Sky triangles ``(K, 3, 3)`` of a listed map: not drawn, but they seal the level for
    :func:`rtp.capture.viewpoints.sample_viewpoints` (pass them as ``blockers=``)."""
    _check_listed(name, None, splits)
    cache = Path(cache_dir)
    return _load_cached(name, cache, _read_index(cache))[1]


def _check_cache_folder(cache: Path) -> None:
    """A ``cache_dir`` that is a file is a :class:`ParameterError` (``scene_list`` called it a cache with nothing
    fetched; ``fetch`` failed with the system's "Not a directory: '.../debs'")."""
    if cache.exists() and not cache.is_dir():
        raise ParameterError(f"cache_dir: expected the scene cache's folder (`rtp scenes fetch` makes it), got {cache}, "
                             "which is a file", "cache_dir")


def scene_list(cache_dir: str | Path | None = None, splits: str | Path | None = None) -> list[dict[str, Any]]:
    """Every map of ``scenes.yaml``: its name, split, and whether the cache holds it fetched and
    converted (``[{"name", "split", "fetched", "converted"}]`` in split order). A cache whose ``index.json``
    cannot be read lists no map as fetched, with a warning saying so and what to do; a ``cache_dir`` that is a
    file is a :class:`ParameterError`."""
    cache = Path(default_cache_dir() if cache_dir is None else cache_dir)
    _check_cache_folder(cache)
    try:
        fetched = set(_read_index(cache)["maps"])
    except SceneNotFoundError:  # nothing fetched yet
        fetched = set()
    except SceneFormatError as err:  # a damaged index: said, not taken for an empty cache
        log.warning("the scene index is damaged or out of date, so no map counts as fetched: %s", err)
        fetched = set()
    except OSError as err:
        log.warning("the scene index cannot be read, so no map counts as fetched: %s", err)
        fetched = set()
    s = load_splits(splits)
    return [{"name": m, "split": split, "fetched": m in fetched, "converted": _cache_path(m, cache).is_file()}
            for split in SPLIT_NAMES for m in s[split]]


def default_cache_dir() -> str:
    """Where fetched and converted scenes live: ``$RTP_SCENE_CACHE`` when set and not empty, else
    ``~/.cache/rtp/scenes`` (an empty ``RTP_SCENE_CACHE=`` counts as unset, not as the current folder; a ``~``
    in it is the home folder, as a shell expands it unquoted: quoted, it made a folder named ``~`` here)."""
    return os.path.expanduser(os.environ.get("RTP_SCENE_CACHE") or str(Path.home() / ".cache" / "rtp" / "scenes"))
