"""A seeded procedural level: a grid of rooms joined by doorways, with windows and skylights,
filled with boxes, columns, spheres, stairs and a grate; procedural textures; a sun and point
lights. Pure numpy, no downloads: the scene source for tests and the demo.

Determinism: everything is drawn from one ``numpy.random.default_rng(seed)`` in a fixed order,
so the same arguments give bit-identical arrays on every platform numpy supports.
"""

from __future__ import annotations

import colorsys
import logging
import math
from dataclasses import dataclass

import numpy as np

from rtp.scene import Material, PointLight, Scene, SpawnPoint, SunLight
from rtp.sdk import ParameterError

from ._geometry import MeshBuilder
from ._textures import make_texture

__all__ = ["procedural"]

log = logging.getLogger("rtp.capture")

WALL = 0.2  # wall and slab thickness, metres
EYE = 1.6  # spawn eye height above the floor, metres
DOOR_W, DOOR_H = 1.6, 2.4
#: The ranges :func:`procedural` accepts: a room at least 3.5 m wide (a window keeps 1.5 m from both ends of
#: its wall), ceilings above the 2.4 m doorways, at most 100 props a room, textures of 16 to 4096 texels.
ROOM_SIZE_RANGE = (3.5, 1000.0)
HEIGHT_RANGE = (2.5, 100.0)
OBJECTS_RANGE = (0, 100)
TEXTURE_SIZE_RANGE = (16, 4096)

_Rect = tuple[float, float, float, float]  # (x0, x1, z0, z1) on the floor plan
_Opening = tuple[float, float, float, float]  # (c0, c1, y0, y1) along a wall


def _colour(rng: np.random.Generator, sat: tuple[float, float], val: tuple[float, float]) -> tuple[float, float, float]:
    h = float(rng.random())
    s = float(rng.uniform(*sat))
    v = float(rng.uniform(*val))
    r, g, b = colorsys.hsv_to_rgb(h, s, v)
    return (r, g, b)


def _materials(rng: np.random.Generator, size: int) -> list[Material]:
    """The fixed material slots of a procedural scene (see ``M_*`` below)."""

    def tex(kind: str, sat=(0.1, 0.6), val=(0.35, 0.9)) -> np.ndarray:
        a = _colour(rng, sat, val)
        b = _colour(rng, sat, val)
        return make_texture(kind, rng, size, a, b)

    u = rng.uniform
    mats = [
        Material("floor", texture=tex(str(rng.choice(["tiles", "checker"]))), roughness=u(0.3, 0.7), specular=0.5),
        Material("wall", texture=tex("bricks", (0.2, 0.6), (0.4, 0.8)), roughness=u(0.7, 0.95), specular=0.4),
        Material("ceiling", texture=tex("noise", (0.0, 0.15), (0.6, 0.9)), roughness=u(0.85, 1.0), specular=0.3),
        Material("crate", texture=tex("stripes"), roughness=u(0.45, 0.8), specular=0.5),
        Material("column", texture=tex("noise", (0.0, 0.3), (0.5, 0.9)), roughness=u(0.2, 0.45), metallic=1.0,
                 specular=0.5),
        Material("plastic", texture=tex("checker", (0.5, 0.9), (0.5, 1.0)), roughness=u(0.08, 0.3), specular=0.6),
        Material("metal", texture=tex("noise", (0.0, 0.4), (0.6, 1.0)), roughness=u(0.1, 0.3), metallic=1.0,
                 specular=0.5),
        Material("stone", texture=tex("noise", (0.0, 0.25), (0.3, 0.7)), roughness=u(0.75, 0.95), specular=0.35),
        Material("grate", texture=tex("grate", (0.0, 0.2), (0.4, 0.7)), roughness=u(0.3, 0.5), metallic=1.0,
                 specular=0.5, alpha_cutoff=0.5),
        Material("light_panel", base_color=(1.0, 1.0, 1.0, 1.0), roughness=0.9, specular=0.2,
                 emissive=(4.0, 3.8, 3.4)),
    ]
    for m in mats:
        m.roughness = float(m.roughness)
    return mats


M_FLOOR, M_WALL, M_CEIL, M_CRATE, M_COLUMN, M_PLASTIC, M_METAL, M_STONE, M_GRATE, M_LIGHT = range(10)


def _wall(b: MeshBuilder, axis: int, at: float, a0: float, a1: float, h: float, openings: list[_Opening]) -> None:
    """A wall of thickness ``WALL`` centred on ``at``, running along x (``axis=0``, at = z) or z
    (``axis=1``, at = x) from ``a0`` to ``a1``, with rectangular openings ``(c0, c1, y0, y1)``."""
    def box(c0: float, c1: float, y0: float, y1: float) -> None:
        if axis == 0:
            b.box(M_WALL, (c0, y0, at - WALL / 2), (c1, y1, at + WALL / 2))
        else:
            b.box(M_WALL, (at - WALL / 2, y0, c0), (at + WALL / 2, y1, c1))

    cur = a0
    for c0, c1, y0, y1 in sorted(openings):
        box(cur, c0, 0.0, h)
        if y0 > 0:
            box(c0, c1, 0.0, y0)
        if y1 < h:
            box(c0, c1, y1, h)
        cur = c1
    box(cur, a1, 0.0, h)


def _slab_with_holes(
    b: MeshBuilder, mat: int, lo: tuple[float, float], hi: tuple[float, float], y0: float, y1: float, holes: list[_Rect]
) -> None:
    """A horizontal slab over ``[lo, hi]`` (x, z) from y0 to y1 with rectangular holes
    ``(x0, x1, z0, z1)``, split on a grid of the hole edges; faces between two solid cells are skipped."""
    xs = sorted({lo[0], hi[0], *[h[0] for h in holes], *[h[1] for h in holes]})
    zs = sorted({lo[1], hi[1], *[h[2] for h in holes], *[h[3] for h in holes]})
    nx, nz = len(xs) - 1, len(zs) - 1
    solid = np.ones((nx, nz), bool)
    for i in range(nx):
        for j in range(nz):
            cx, cz = (xs[i] + xs[i + 1]) / 2, (zs[j] + zs[j + 1]) / 2
            if any(h[0] <= cx <= h[1] and h[2] <= cz <= h[3] for h in holes):
                solid[i, j] = False
    for i in range(nx):
        for j in range(nz):
            if not solid[i, j]:
                continue
            skip = []
            if i > 0 and solid[i - 1, j]:
                skip.append("-x")
            if i < nx - 1 and solid[i + 1, j]:
                skip.append("+x")
            if j > 0 and solid[i, j - 1]:
                skip.append("-z")
            if j < nz - 1 and solid[i, j + 1]:
                skip.append("+z")
            b.box(mat, (xs[i], y0, zs[j]), (xs[i + 1], y1, zs[j + 1]), skip=tuple(skip))


def procedural(
    seed: int,
    *,
    rooms: tuple[int, int] = (2, 2),
    room_size: tuple[float, float] = (6.0, 10.0),
    height: tuple[float, float] = (3.2, 4.5),
    objects_per_room: tuple[int, int] = (4, 7),
    texture_size: int = 256,
    name: str | None = None,
) -> Scene:
    """Generate a deterministic indoor level.

    Args:
        seed: seed of the single random generator; the same arguments give identical arrays.
        rooms: grid of rooms ``(nx, nz)``; neighbouring rooms share a wall with a doorway.
        room_size: range ``(low, high)`` of room widths/depths in metres, 3.5 <= low <= high <= 1000.
        height: range ``(low, high)`` of the (common) ceiling height in metres, 2.5 <= low <= high <= 100.
        objects_per_room: range ``(low, high)`` of the number of props per room (boxes, columns,
            spheres, ...), integers, 0 <= low <= high <= 100.
        texture_size: edge of the square procedural textures, a power of two from 16 to 4096.
        name: scene name, default ``"procedural-<seed>"``.

    Returns:
        A :class:`~rtp.scene.Scene` with one mesh per used material, a sun,
        one ceiling point light per room (plus a few extras) and one spawn point per room centre.

    Raises:
        ParameterError: an argument is of the wrong type or out of its range, naming it.
    """
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ParameterError(f"seed: expected a non-negative integer, got {seed!r}", "seed")
    if not (isinstance(rooms, tuple) and len(rooms) == 2 and all(isinstance(v, int) and v >= 1 for v in rooms)):
        raise ParameterError(f"rooms: expected (nx, nz), integers of at least 1, got {rooms!r}", "rooms")
    _check_range("room_size", room_size, ROOM_SIZE_RANGE, "in metres")
    _check_range("height", height, HEIGHT_RANGE, "in metres")
    _check_range("objects_per_room", objects_per_room, OBJECTS_RANGE, "props a room", integers=True)
    lo, hi = TEXTURE_SIZE_RANGE
    if (isinstance(texture_size, bool) or not isinstance(texture_size, (int, np.integer)) or not lo <= texture_size <= hi
            or texture_size & (texture_size - 1)):
        raise ParameterError(f"texture_size: expected a power of two from {lo} to {hi}, got {texture_size!r}",
                             "texture_size")
    if name is not None and not isinstance(name, str):
        raise ParameterError(f"name: expected a string or None, got {name!r}", "name")
    nx, nz = rooms
    # Every step draws from the one generator, in this order: the order is part of the output.
    rng = np.random.default_rng(seed)
    mats = _materials(rng, texture_size)
    b = MeshBuilder(texel_metres=2.0)
    plan = _floor_plan(rng, nx, nz, room_size, height)
    _floor_and_ceiling(b, rng, plan)
    keep_clear = _walls(b, rng, plan)
    spawns, lights = _furnish_rooms(b, rng, plan, keep_clear, objects_per_room)
    lights += _accent_lights(rng, plan)
    sun = _sun(rng)
    return _assemble(name or f"procedural-{seed}", b, mats, sun, lights, spawns)


def _check_range(field: str, value: object, bounds: tuple[float, float], unit: str, integers: bool = False) -> None:
    """``value`` a pair ``(low, high)`` of finite numbers (integers with ``integers``), ``bounds[0] <= low <= high
    <= bounds[1]``, else a ParameterError naming ``field``, what it expected and what it got."""
    kind = "integers" if integers else "numbers"
    number = (int, np.integer) if integers else (int, float, np.integer, np.floating)
    ok = (isinstance(value, (tuple, list)) and len(value) == 2
          and all(isinstance(v, number) and not isinstance(v, bool)
                  and (isinstance(v, (int, np.integer)) or math.isfinite(v)) for v in value)
          and bounds[0] <= value[0] <= value[1] <= bounds[1])
    if not ok:
        raise ParameterError(f"{field}: expected (low, high) {unit}, {kind} with {bounds[0]:g} <= low <= high <= "
                             f"{bounds[1]:g}, got {value!r}", field)


@dataclass(frozen=True)
class _Plan:
    """The level's grid: ceiling height and the x / z lines of the room walls, centred on the origin."""

    h: float
    xs: np.ndarray
    zs: np.ndarray

    @property
    def nx(self) -> int:
        return len(self.xs) - 1

    @property
    def nz(self) -> int:
        return len(self.zs) - 1


def _floor_plan(
    rng: np.random.Generator, nx: int, nz: int, room_size: tuple[float, float], height: tuple[float, float]
) -> _Plan:
    """Draw the ceiling height and the room widths and depths; centre the level on the origin."""
    h = float(rng.uniform(*height))
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(*room_size, nx))])
    zs = np.concatenate([[0.0], np.cumsum(rng.uniform(*room_size, nz))])
    xs -= xs[-1] / 2
    zs -= zs[-1] / 2
    return _Plan(h, xs, zs)


def _floor_and_ceiling(b: MeshBuilder, rng: np.random.Generator, plan: _Plan) -> None:
    """The floor slab, and the ceiling slab with a skylight over about half of the rooms."""
    xs, zs, h, W2 = plan.xs, plan.zs, plan.h, WALL / 2
    b.box(M_FLOOR, (xs[0] - W2, -WALL, zs[0] - W2), (xs[-1] + W2, 0.0, zs[-1] + W2))
    holes: list[_Rect] = []
    for i in range(plan.nx):
        for j in range(plan.nz):
            if rng.random() < 0.5:
                cx, cz = (xs[i] + xs[i + 1]) / 2, (zs[j] + zs[j + 1]) / 2
                hw, hd = rng.uniform(0.6, 1.4), rng.uniform(0.6, 1.4)
                ox, oz = rng.uniform(-1.0, 1.0, 2)
                holes.append((cx + ox - hw, cx + ox + hw, cz + oz - hd, cz + oz + hd))
    _slab_with_holes(b, M_CEIL, (xs[0] - W2, zs[0] - W2), (xs[-1] + W2, zs[-1] + W2), h, h + WALL, holes)


def _openings(
    rng: np.random.Generator, h: float, outer: bool, a0: float, a1: float, other_axis: int, at: float
) -> tuple[list[_Opening], list[_Rect]]:
    """The openings of one wall segment from ``a0`` to ``a1``: sometimes a window in an outer wall,
    always a doorway in an inner one; with the floor area kept clear of props in front of it."""
    ops: list[_Opening] = []
    keep_clear: list[_Rect] = []
    if outer:
        if rng.random() < 0.35:
            c = rng.uniform(a0 + 1.5, a1 - 1.5)
            ops.append((c - 0.75, c + 0.75, 1.0, min(2.2, h - 0.4)))
    else:
        c = float(rng.uniform(a0 + 1.2, a1 - 1.2))
        ops.append((c - DOOR_W / 2, c + DOOR_W / 2, 0.0, DOOR_H))
        m = DOOR_W / 2 + 0.4
        if other_axis == 0:  # wall along x at z = at
            keep_clear.append((c - m, c + m, at - 1.4, at + 1.4))
        else:
            keep_clear.append((at - 1.4, at + 1.4, c - m, c + m))
    return ops, keep_clear


def _walls(b: MeshBuilder, rng: np.random.Generator, plan: _Plan) -> list[_Rect]:
    """Walls along x at each z line and along z at each x line (doors inside, windows outside) and
    the posts where they cross; returns the floor areas in front of the doorways."""
    xs, zs, h, nx, nz, W2 = plan.xs, plan.zs, plan.h, plan.nx, plan.nz, WALL / 2
    keep_clear: list[_Rect] = []
    for j, z in enumerate(zs):
        outer = j in (0, nz)
        for i in range(nx):
            a0, a1 = xs[i], xs[i + 1]
            ops, clear = _openings(rng, h, outer, a0, a1, 0, z)
            keep_clear += clear
            _wall(b, 0, z, a0 - W2 if i == 0 else a0 + W2, a1 + W2 if i == nx - 1 else a1 - W2, h, ops)
    for i in range(1, nx):  # posts where interior x lines cross the z lines
        for z in zs:
            b.box(M_WALL, (xs[i] - W2, 0.0, z - W2), (xs[i] + W2, h, z + W2))
    for i, x in enumerate(xs):
        outer = i in (0, nx)
        for j in range(nz):
            a0, a1 = zs[j] + W2, zs[j + 1] - W2
            ops, clear = _openings(rng, h, outer, a0, a1, 1, x)
            keep_clear += clear
            _wall(b, 1, x, a0, a1, h, ops)
    return keep_clear


class _Room:
    """One room's floor inside its walls, and the footprints already taken in it: props are placed
    by rejection sampling."""

    def __init__(self, rng: np.random.Generator, plan: _Plan, i: int, j: int, keep_clear: list[_Rect]) -> None:
        W2 = WALL / 2
        self.rng = rng
        self.h = plan.h
        self.x0, self.x1 = plan.xs[i] + W2, plan.xs[i + 1] - W2
        self.z0, self.z1 = plan.zs[j] + W2, plan.zs[j + 1] - W2
        self.cx, self.cz = (self.x0 + self.x1) / 2, (self.z0 + self.z1) / 2
        cx, cz = self.cx, self.cz
        self.placed: list[_Rect] = [(cx - 1.0, cx + 1.0, cz - 1.0, cz + 1.0)]  # the spawn point's square
        self.placed += keep_clear

    def free(self, r: _Rect) -> bool:
        """Whether footprint ``r`` lies inside the room and overlaps nothing placed."""
        if r[0] < self.x0 + 0.05 or r[1] > self.x1 - 0.05 or r[2] < self.z0 + 0.05 or r[3] > self.z1 - 0.05:
            return False
        return not any(r[0] < q[1] and q[0] < r[1] and r[2] < q[3] and q[2] < r[3] for q in self.placed)

    def place(self, w: float, d: float, tries: int = 30) -> tuple[float, float] | None:
        """Centre of a free ``w`` x ``d`` footprint (now taken), or None after ``tries`` misses."""
        x0, x1, z0, z1 = self.x0, self.x1, self.z0, self.z1
        for _ in range(tries):
            px = float(self.rng.uniform(x0 + w / 2, x1 - w / 2)) if x1 - x0 > w else None
            pz = float(self.rng.uniform(z0 + d / 2, z1 - d / 2)) if z1 - z0 > d else None
            if px is None or pz is None:
                return None
            r = (px - w / 2, px + w / 2, pz - d / 2, pz + d / 2)
            if self.free(r):
                self.placed.append(r)
                return px, pz
        return None


def _furnish_rooms(
    b: MeshBuilder, rng: np.random.Generator, plan: _Plan, keep_clear: list[_Rect], objects_per_room: tuple[int, int]
) -> tuple[list[SpawnPoint], list[PointLight]]:
    """Room by room: a spawn point at the centre, the level's one staircase and one grate (in the
    first rooms that fit them), the props, and a ceiling light."""
    spawns: list[SpawnPoint] = []
    lights: list[PointLight] = []
    grate_done = False
    stairs_done = False
    for i in range(plan.nx):
        for j in range(plan.nz):
            room = _Room(rng, plan, i, j, keep_clear)
            spawns.append(SpawnPoint((float(room.cx), EYE, float(room.cz)), yaw=float(rng.uniform(-180.0, 180.0))))
            if not stairs_done:
                stairs_done = _stairs(b, room)
            _props(b, room, objects_per_room)
            if not grate_done and rng.random() < 0.7:
                grate_done = _grate(b, room)
            lights.append(_ceiling_light(b, room))
    return spawns, lights


def _stairs(b: MeshBuilder, room: _Room) -> bool:
    """A flight of stone steps up to a landing, if it fits; returns whether it was built."""
    steps = int(room.rng.integers(6, 11))
    sw, sd, sh = 1.2, 0.32, min(0.2, (room.h - 2.2) / steps)
    plat = 2.0
    w, d = sw, steps * sd + plat
    at = room.place(w + 0.1, d + 0.1)
    if at is None:
        return False
    px, pz = at
    zstart = pz - d / 2
    for k in range(steps):
        b.box(M_STONE, (px - sw / 2, 0.0, zstart + k * sd), (px + sw / 2, (k + 1) * sh, zstart + (k + 1) * sd))
    top = steps * sh
    b.box(M_STONE, (px - sw / 2, 0.0, zstart + steps * sd), (px + sw / 2, top, zstart + d))
    return True


def _props(b: MeshBuilder, room: _Room, objects_per_room: tuple[int, int]) -> None:
    """A random number of props of random kinds; one that finds no free spot is skipped."""
    n_obj = int(room.rng.integers(objects_per_room[0], objects_per_room[1] + 1))
    for _ in range(n_obj):
        kind = room.rng.choice(["box", "stack", "column", "sphere", "pillar"])
        if kind in ("box", "stack"):
            _crate(b, room, stacked=kind == "stack")
        elif kind == "column":
            _column(b, room)
        elif kind == "pillar":
            _pillar(b, room)
        else:
            _ball(b, room)


def _crate(b: MeshBuilder, room: _Room, stacked: bool) -> None:
    """A crate; ``stacked`` puts a smaller crate or a ball on top."""
    rng = room.rng
    s = float(rng.uniform(0.5, 1.4))
    at = room.place(s, s)
    if at is None:
        return
    px, pz = at
    b.box(M_CRATE, (px - s / 2, 0.0, pz - s / 2), (px + s / 2, s, pz + s / 2))
    if stacked:
        s2 = s * float(rng.uniform(0.4, 0.8))
        ox, oz = rng.uniform(-(s - s2) / 2, (s - s2) / 2, 2)
        if rng.random() < 0.5:
            b.box(M_CRATE, (px + ox - s2 / 2, s, pz + oz - s2 / 2), (px + ox + s2 / 2, s + s2, pz + oz + s2 / 2))
        else:
            r = s2 / 2
            b.sphere(M_PLASTIC if rng.random() < 0.5 else M_METAL, (px + ox, s + r, pz + oz), r)


def _column(b: MeshBuilder, room: _Room) -> None:
    """A round metal column from floor to ceiling."""
    r = float(room.rng.uniform(0.2, 0.4))
    at = room.place(2 * r, 2 * r)
    if at is None:
        return
    b.cylinder(M_COLUMN, (at[0], 0.0, at[1]), r, room.h)


def _pillar(b: MeshBuilder, room: _Room) -> None:
    """A square stone pillar from floor to ceiling."""
    s = float(room.rng.uniform(0.3, 0.6))
    at = room.place(s, s)
    if at is None:
        return
    b.box(M_STONE, (at[0] - s / 2, 0.0, at[1] - s / 2), (at[0] + s / 2, room.h, at[1] + s / 2))


def _ball(b: MeshBuilder, room: _Room) -> None:
    """A ball resting on the floor, plastic, metal or stone."""
    r = float(room.rng.uniform(0.3, 0.9))
    at = room.place(2 * r, 2 * r)
    if at is None:
        return
    mat = int(room.rng.choice([M_PLASTIC, M_METAL, M_STONE]))
    b.sphere(mat, (at[0], r, at[1]), r)


def _grate(b: MeshBuilder, room: _Room) -> bool:
    """An alpha-tested metal grate standing on the floor, if it fits; returns whether it was built."""
    gw = float(room.rng.uniform(1.5, 2.5))
    at = room.place(gw, 0.1)
    if at is None:
        return False
    b.box(M_GRATE, (at[0] - gw / 2, 0.0, at[1] - 0.03), (at[0] + gw / 2, min(2.0, room.h - 0.5), at[1] + 0.03))
    return True


def _ceiling_light(b: MeshBuilder, room: _Room) -> PointLight:
    """An emissive panel near the room's centre and the point light just below it."""
    rng, h = room.rng, room.h
    lx, lz = room.cx + float(rng.uniform(-1, 1)), room.cz + float(rng.uniform(-1, 1))
    b.box(M_LIGHT, (lx - 0.3, h - 0.05, lz - 0.3), (lx + 0.3, h, lz + 0.3), skip=("+y",))
    warm = rng.random() < 0.6
    col = (1.0, 0.85, 0.65) if warm else (0.7, 0.85, 1.0)
    diag = math.hypot(room.x1 - room.x0, room.z1 - room.z0)
    return PointLight((lx, h - 0.3, lz), col, float(rng.uniform(8.0, 16.0)), float(diag * 1.2))


def _accent_lights(rng: np.random.Generator, plan: _Plan) -> list[PointLight]:
    """A few coloured lights near the floor anywhere in the level."""
    xs, zs = plan.xs, plan.zs
    lights = []
    for _ in range(int(rng.integers(1, 4))):
        px = float(rng.uniform(xs[0] + 0.5, xs[-1] - 0.5))
        pz = float(rng.uniform(zs[0] + 0.5, zs[-1] - 0.5))
        col = _colour(rng, (0.5, 0.9), (0.9, 1.0))
        lights.append(PointLight((px, float(rng.uniform(0.5, 1.5)), pz), col, float(rng.uniform(2.0, 6.0)), 5.0))
    return lights


def _sun(rng: np.random.Generator) -> SunLight:
    """A sun from a random azimuth, 30 to 70 degrees above the horizon."""
    az = math.radians(float(rng.uniform(0, 360)))
    el = math.radians(float(rng.uniform(30, 70)))
    sun_dir = (-math.cos(el) * math.sin(az), -math.sin(el), -math.cos(el) * math.cos(az))
    return SunLight(direction=sun_dir, colour=(1.0, 0.95, 0.85), intensity=float(rng.uniform(2.5, 4.0)))


def _assemble(
    name: str, b: MeshBuilder, mats: list[Material], sun: SunLight, lights: list[PointLight], spawns: list[SpawnPoint]
) -> Scene:
    """The scene: one mesh per used material; unused material slots stay so indices are stable."""
    meshes = b.meshes()
    used = {m.material for m in meshes}
    scene = Scene(
        name=name,
        meshes=meshes,
        materials=mats,
        sun=sun,
        point_lights=lights,
        spawn_points=spawns,
    )
    log.debug("procedural scene %s: %d triangles, %d/%d materials used", scene.name, scene.triangle_count,
              len(used), len(mats))
    return scene
