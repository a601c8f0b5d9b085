"""Reading Quake-3 data: a case-insensitive file index over several .pk3 (zip) archives, and a
parser for ``scripts/*.shader`` files that keeps what the converter needs."""

from __future__ import annotations

import logging
import re
import zipfile
import zlib
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from ._errors import SceneFormatError, SceneNotFoundError

__all__ = ["Pk3Set", "Shader", "Stage", "parse_shaders"]

log = logging.getLogger("rtp.capture")

#: The most bytes one pk3 member may unpack to (OpenArena's largest, a map's BSP, are a few tens of MB).
MAX_MEMBER_BYTES = 512 * 2**20


class Pk3Set:
    """Files of several pk3 archives under one case-insensitive namespace.

    The first archive that holds a path wins, so pass the map's own archive first and the
    shared texture archives after it.
    """

    def __init__(self, paths: Iterable[str | Path]) -> None:
        self.paths = [Path(p) for p in paths]
        self._zips: list[zipfile.ZipFile] = []
        self._index: dict[str, tuple[int, str]] = {}
        try:
            for p in self.paths:
                if not p.is_file():
                    raise SceneNotFoundError(f"pk3 archive not found: {p}")
                try:
                    z = zipfile.ZipFile(p)
                except zipfile.BadZipFile as err:
                    raise SceneFormatError(f"{p} is not a pk3 (zip) archive: {err}") from err
                k = len(self._zips)
                self._zips.append(z)
                for info in z.infolist():
                    if info.is_dir():
                        continue
                    self._index.setdefault(_key(info.filename), (k, info.filename))
        except BaseException:  # (the archives opened before the one refused: the caller never gets the set)
            self.close()
            raise

    def close(self) -> None:
        """Close every archive (twice is harmless; a read after it is refused)."""
        for z in self._zips:
            z.close()

    def __enter__(self) -> Pk3Set:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __contains__(self, path: str) -> bool:
        return _key(path) in self._index

    def names(self, prefix: str = "", suffix: str = "") -> list[str]:
        """Lower-cased paths starting with ``prefix`` and ending with ``suffix``."""
        p, s = _key(prefix), _key(suffix)
        return sorted(n for n in self._index if n.startswith(p) and n.endswith(s))

    def read(self, path: str) -> bytes:
        try:
            k, real = self._index[_key(path)]
        except KeyError:
            raise SceneNotFoundError(f"{path} is not in any of {[str(p) for p in self.paths]}") from None
        size = self._zips[k].getinfo(real).file_size  # (zipfile stops at it: a member cannot unpack to more)
        if size > MAX_MEMBER_BYTES:  # (a zip bomb: a few MB of deflated zeros unpacked into all the memory there is)
            raise SceneFormatError(f"{real} in {self.paths[k]} unpacks to {size / 2**20:.0f} MiB, more than a pk3 "
                                   f"member of a level may ({MAX_MEMBER_BYTES / 2**20:.0f} MiB): not read; the archive "
                                   "is damaged or not a game's")
        try:
            return self._zips[k].read(real)
        except (zipfile.BadZipFile, zlib.error, EOFError) as err:  # a damaged member: bad CRC, broken deflate stream
            raise SceneFormatError(f"{real} in {self.paths[k]} is damaged ({err}): replace the archive") from err
        except (NotImplementedError, RuntimeError) as err:  # zipfile's words for a method it lacks, an encrypted member
            raise SceneFormatError(f"{real} in {self.paths[k]} cannot be read ({err}): a pk3 member must be stored or "
                                   "deflated, unencrypted, as the game reads it; repack the archive") from err

    def archive_of(self, path: str) -> Path:
        return self.paths[self._index[_key(path)][0]]


def _key(path: str) -> str:
    """An archive path as the index holds it: lower case, ``/`` for a Windows tool's ``\\`` (the index turned an
    entry's backslashes into slashes, but a path asked for with one, as a shader script may write it, was not found)."""
    return path.lower().replace("\\", "/")


# -- shader scripts ------------------------------------------------------------------------------

@dataclass
class Stage:
    """One rendering stage of a shader: its image and blending."""

    map: str | None = None  # image path, or "$lightmap" / "$whiteimage"
    blend: tuple[str, str] | None = None  # (src, dst) GL factors, lower case; None = opaque
    alpha_func: str | None = None  # "gt0" | "lt128" | "ge128"
    tcgen_environment: bool = False


@dataclass
class Shader:
    """What the converter keeps of a shader definition."""

    name: str
    surfaceparms: set[str] = field(default_factory=set)
    stages: list[Stage] = field(default_factory=list)
    editor_image: str | None = None
    sun: tuple[float, ...] | None = None  # r g b intensity azimuth elevation (q3map_sun / sunExt)
    surface_light: float = 0.0  # q3map_surfacelight
    light_rgb: tuple[float, float, float] | None = None  # q3map_lightRGB
    farbox: str | None = None  # skyparms far box base name

    def first_image(self) -> str | None:
        """The first stage image that is a real texture, preferring stages without environment
        mapping; ``$lightmap``/``$whiteimage`` are skipped; else the editor image."""
        real = [s for s in self.stages if s.map and not s.map.startswith("$")]
        for s in real:
            if not s.tcgen_environment:
                return s.map
        if real:
            return real[0].map
        return self.editor_image

    @property
    def alpha_func(self) -> str | None:
        for s in self.stages:
            if s.alpha_func:
                return s.alpha_func
        return None

    def is_additive_only(self) -> bool:
        """True when no stage is opaque or a lightmap: flares, beams, glass, energy fields."""
        if not self.stages:
            return False
        for s in self.stages:
            if s.map == "$lightmap" or s.blend is None or s.alpha_func:
                return False
            if s.blend in (("gl_one", "gl_zero"),):
                return False
        return True


_BLEND_SHORT = {
    "add": ("gl_one", "gl_one"),
    "filter": ("gl_dst_color", "gl_zero"),
    "blend": ("gl_src_alpha", "gl_one_minus_src_alpha"),
}

_TOKEN = re.compile(r'"[^"]*"|\{|\}|[^\s{}"]+')


def _strip_comments(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    return re.sub(r"//[^\n]*", "", text)


def parse_shaders(text: str, into: dict[str, Shader] | None = None) -> dict[str, Shader]:
    """Parse a shader script into ``{lower-case name: Shader}``; earlier definitions win.

    The parser is line-based inside braces (Q3 directives end at the line end) and tolerant:
    unknown directives are ignored, unbalanced braces end the file with a debug log.
    """
    out: dict[str, Shader] = {} if into is None else into
    lines = _strip_comments(text).splitlines()
    depth = 0
    cur: Shader | None = None
    stage: Stage | None = None
    pending_name: str | None = None
    for raw in lines:
        toks = [t.strip('"') for t in _TOKEN.findall(raw)]
        while toks:
            t = toks.pop(0)
            if t == "{":
                depth += 1
                if depth == 1:
                    cur = Shader(pending_name or "")
                elif depth == 2 and cur is not None:
                    stage = Stage()
                continue
            if t == "}":
                depth -= 1
                if depth == 1 and cur is not None and stage is not None:
                    cur.stages.append(stage)
                    stage = None
                elif depth == 0 and cur is not None:
                    if cur.name and cur.name.lower() not in out:
                        out[cur.name.lower()] = cur
                    cur, pending_name = None, None
                elif depth < 0:
                    log.debug("unbalanced '}' in shader script")
                    return out
                continue
            if depth == 0:
                pending_name = t.replace("\\", "/")
                continue
            # a directive: the rest of the line up to a brace
            args: list[str] = []
            while toks and toks[0] not in ("{", "}"):
                args.append(toks.pop(0))
            key = t.lower()
            largs = [a.lower() for a in args]
            if depth == 1 and cur is not None:
                if key == "surfaceparm" and largs:
                    cur.surfaceparms.add(largs[0])
                elif key == "qer_editorimage" and args:
                    cur.editor_image = args[0]
                elif key in ("q3map_sun", "q3map_sunext") and len(args) >= 6:
                    try:
                        cur.sun = tuple(float(a) for a in args[:6])
                    except ValueError:
                        pass
                elif key == "q3map_surfacelight" and args:
                    try:
                        cur.surface_light = float(args[0])
                    except ValueError:
                        pass
                elif key == "q3map_lightrgb" and len(args) >= 3:
                    try:
                        cur.light_rgb = (float(args[0]), float(args[1]), float(args[2]))
                    except ValueError:
                        pass
                elif key == "skyparms" and args and args[0] != "-":
                    cur.farbox = args[0]
            elif depth == 2 and stage is not None:
                if key in ("map", "clampmap") and args:
                    stage.map = args[0]
                elif key == "animmap" and len(args) >= 2:
                    stage.map = args[1]
                elif key == "blendfunc" and largs:
                    if largs[0] in _BLEND_SHORT:
                        stage.blend = _BLEND_SHORT[largs[0]]
                    elif len(largs) >= 2:
                        stage.blend = (largs[0], largs[1])
                elif key == "alphafunc" and largs:
                    stage.alpha_func = largs[0]
                elif key == "tcgen" and largs and largs[0] in ("environment", "environmentmodel"):
                    stage.tcgen_environment = True
    return out
