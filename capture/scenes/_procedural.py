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

import numpy as np

from rtp.scene import Material, PointLight, Scene, SpawnPoint, SunLight

from ._geometry import MeshBuilder
from ._textures import make_texture

__all__ = ["procedural"]

log = logging.getLogger("rtp.capture")

WALL = 0.2  # wall and slab thickness, metres
EYE = 1.6  # spawn eye height above the floor, metres
DOOR_W, DOOR_H = 1.6, 2.4


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


def _wall(b: MeshBuilder, axis: int, at: float, a0: float, a1: float, h: float, openings) -> None:
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


def _slab_with_holes(b: MeshBuilder, mat: int, lo, hi, y0: float, y1: float, holes: list[tuple[float, float, float, float]]) -> None:
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
        room_size: range of room widths/depths in metres.
        height: range of the (common) ceiling height in metres.
        objects_per_room: range of the number of props per room (boxes, columns, spheres, ...).
        texture_size: edge of the square procedural textures (a power of two).
        name: scene name, default ``"procedural-<seed>"``.

    Returns:
        A :class:`~rtp.plugins.moderngl._scene.Scene` with one mesh per used material, a sun,
        one ceiling point light per room (plus a few extras) and one spawn point per room centre.
    """
    nx, nz = rooms
    if nx < 1 or nz < 1:
        raise ValueError(f"rooms must be at least (1, 1), got {rooms}")
    rng = np.random.default_rng(seed)
    mats = _materials(rng, texture_size)
    b = MeshBuilder(texel_metres=2.0)
    h = float(rng.uniform(*height))
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(*room_size, nx))])
    zs = np.concatenate([[0.0], np.cumsum(rng.uniform(*room_size, nz))])
    xs -= xs[-1] / 2  # centre the level on the origin
    zs -= zs[-1] / 2
    W2 = WALL / 2

    # floor slab and ceiling with skylights
    b.box(M_FLOOR, (xs[0] - W2, -WALL, zs[0] - W2), (xs[-1] + W2, 0.0, zs[-1] + W2))
    holes = []
    for i in range(nx):
        for j in range(nz):
            if rng.random() < 0.5:
                cx, cz = (xs[i] + xs[i + 1]) / 2, (zs[j] + zs[j + 1]) / 2
                hw, hd = rng.uniform(0.6, 1.4), rng.uniform(0.6, 1.4)
                ox, oz = rng.uniform(-1.0, 1.0, 2)
                holes.append((cx + ox - hw, cx + ox + hw, cz + oz - hd, cz + oz + hd))
    _slab_with_holes(b, M_CEIL, (xs[0] - W2, zs[0] - W2), (xs[-1] + W2, zs[-1] + W2), h, h + WALL, holes)

    # walls: along x at each z line, along z at each x line; doors inside, windows outside
    forbidden: list[tuple[float, float, float, float]] = []  # (x0, x1, z0, z1) kept clear of props

    def openings_for(line_is_outer: bool, a0: float, a1: float, other_axis: int, at: float):
        ops = []
        if line_is_outer:
            if rng.random() < 0.35:
                c = rng.uniform(a0 + 1.5, a1 - 1.5)
                ops.append((c - 0.75, c + 0.75, 1.0, min(2.2, h - 0.4)))
        else:
            c = float(rng.uniform(a0 + 1.2, a1 - 1.2))
            ops.append((c - DOOR_W / 2, c + DOOR_W / 2, 0.0, DOOR_H))
            m = DOOR_W / 2 + 0.4
            if other_axis == 0:  # wall along x at z = at
                forbidden.append((c - m, c + m, at - 1.4, at + 1.4))
            else:
                forbidden.append((at - 1.4, at + 1.4, c - m, c + m))
        return ops

    for j, z in enumerate(zs):
        outer = j in (0, nz)
        for i in range(nx):
            a0, a1 = xs[i], xs[i + 1]
            ops = openings_for(outer, a0, a1, 0, z)
            _wall(b, 0, z, a0 - W2 if i == 0 else a0 + W2, a1 + W2 if i == nx - 1 else a1 - W2, h, ops)
    for i in range(1, nx):  # posts where interior x lines cross the z lines
        for z in zs:
            b.box(M_WALL, (xs[i] - W2, 0.0, z - W2), (xs[i] + W2, h, z + W2))
    for i, x in enumerate(xs):
        outer = i in (0, nx)
        for j in range(nz):
            a0, a1 = zs[j] + W2, zs[j + 1] - W2
            _wall(b, 1, x, a0, a1, h, openings_for(outer, a0, a1, 1, x))

    # props, placed by rejection sampling on the floor plan
    spawns: list[SpawnPoint] = []
    lights: list[PointLight] = []
    grate_done = False
    stairs_done = False
    for i in range(nx):
        for j in range(nz):
            x0, x1, z0, z1 = xs[i] + W2, xs[i + 1] - W2, zs[j] + W2, zs[j + 1] - W2
            cx, cz = (x0 + x1) / 2, (z0 + z1) / 2
            spawns.append(SpawnPoint((float(cx), EYE, float(cz)), yaw=float(rng.uniform(-180.0, 180.0))))
            placed: list[tuple[float, float, float, float]] = [(cx - 1.0, cx + 1.0, cz - 1.0, cz + 1.0)]
            placed += forbidden

            def free(r: tuple[float, float, float, float]) -> bool:
                if r[0] < x0 + 0.05 or r[1] > x1 - 0.05 or r[2] < z0 + 0.05 or r[3] > z1 - 0.05:
                    return False
                return not any(r[0] < q[1] and q[0] < r[1] and r[2] < q[3] and q[2] < r[3] for q in placed)

            def place(w: float, d: float, tries: int = 30) -> tuple[float, float] | None:
                for _ in range(tries):
                    px = float(rng.uniform(x0 + w / 2, x1 - w / 2)) if x1 - x0 > w else None
                    pz = float(rng.uniform(z0 + d / 2, z1 - d / 2)) if z1 - z0 > d else None
                    if px is None or pz is None:
                        return None
                    r = (px - w / 2, px + w / 2, pz - d / 2, pz + d / 2)
                    if free(r):
                        placed.append(r)
                        return px, pz
                return None

            if not stairs_done:
                steps = int(rng.integers(6, 11))
                sw, sd, sh = 1.2, 0.32, min(0.2, (h - 2.2) / steps)
                plat = 2.0
                w, d = sw, steps * sd + plat
                at = place(w + 0.1, d + 0.1)
                if at is not None:
                    px, pz = at
                    zstart = pz - d / 2
                    for k in range(steps):
                        b.box(M_STONE, (px - sw / 2, 0.0, zstart + k * sd), (px + sw / 2, (k + 1) * sh, zstart + (k + 1) * sd))
                    top = steps * sh
                    b.box(M_STONE, (px - sw / 2, 0.0, zstart + steps * sd), (px + sw / 2, top, zstart + d))
                    stairs_done = True

            n_obj = int(rng.integers(objects_per_room[0], objects_per_room[1] + 1))
            for _ in range(n_obj):
                kind = rng.choice(["box", "stack", "column", "sphere", "pillar"])
                if kind in ("box", "stack"):
                    s = float(rng.uniform(0.5, 1.4))
                    at = place(s, s)
                    if at is None:
                        continue
                    px, pz = at
                    b.box(M_CRATE, (px - s / 2, 0.0, pz - s / 2), (px + s / 2, s, pz + s / 2))
                    if kind == "stack":
                        s2 = s * float(rng.uniform(0.4, 0.8))
                        ox, oz = rng.uniform(-(s - s2) / 2, (s - s2) / 2, 2)
                        if rng.random() < 0.5:
                            b.box(M_CRATE, (px + ox - s2 / 2, s, pz + oz - s2 / 2), (px + ox + s2 / 2, s + s2, pz + oz + s2 / 2))
                        else:
                            r = s2 / 2
                            b.sphere(M_PLASTIC if rng.random() < 0.5 else M_METAL, (px + ox, s + r, pz + oz), r)
                elif kind == "column":
                    r = float(rng.uniform(0.2, 0.4))
                    at = place(2 * r, 2 * r)
                    if at is None:
                        continue
                    b.cylinder(M_COLUMN, (at[0], 0.0, at[1]), r, h)
                elif kind == "pillar":
                    s = float(rng.uniform(0.3, 0.6))
                    at = place(s, s)
                    if at is None:
                        continue
                    b.box(M_STONE, (at[0] - s / 2, 0.0, at[1] - s / 2), (at[0] + s / 2, h, at[1] + s / 2))
                else:
                    r = float(rng.uniform(0.3, 0.9))
                    at = place(2 * r, 2 * r)
                    if at is None:
                        continue
                    mat = int(rng.choice([M_PLASTIC, M_METAL, M_STONE]))
                    b.sphere(mat, (at[0], r, at[1]), r)

            if not grate_done and rng.random() < 0.7:
                gw = float(rng.uniform(1.5, 2.5))
                at = place(gw, 0.1)
                if at is not None:
                    b.box(M_GRATE, (at[0] - gw / 2, 0.0, at[1] - 0.03), (at[0] + gw / 2, min(2.0, h - 0.5), at[1] + 0.03))
                    grate_done = True

            # ceiling light: an emissive panel and a point light just below it
            lx, lz = cx + float(rng.uniform(-1, 1)), cz + float(rng.uniform(-1, 1))
            b.box(M_LIGHT, (lx - 0.3, h - 0.05, lz - 0.3), (lx + 0.3, h, lz + 0.3), skip=("+y",))
            warm = rng.random() < 0.6
            col = (1.0, 0.85, 0.65) if warm else (0.7, 0.85, 1.0)
            diag = math.hypot(x1 - x0, z1 - z0)
            lights.append(PointLight((lx, h - 0.3, lz), col, float(rng.uniform(8.0, 16.0)), float(diag * 1.2)))

    # a few coloured accent lights near the floor
    for _ in range(int(rng.integers(1, 4))):
        px = float(rng.uniform(xs[0] + 0.5, xs[-1] - 0.5))
        pz = float(rng.uniform(zs[0] + 0.5, zs[-1] - 0.5))
        col = _colour(rng, (0.5, 0.9), (0.9, 1.0))
        lights.append(PointLight((px, float(rng.uniform(0.5, 1.5)), pz), col, float(rng.uniform(2.0, 6.0)), 5.0))

    az = math.radians(float(rng.uniform(0, 360)))
    el = math.radians(float(rng.uniform(30, 70)))
    sun_dir = (-math.cos(el) * math.sin(az), -math.sin(el), -math.cos(el) * math.cos(az))
    sun = SunLight(direction=sun_dir, colour=(1.0, 0.95, 0.85), intensity=float(rng.uniform(2.5, 4.0)))

    meshes = b.meshes()
    used = {m.material for m in meshes}
    # keep material indices stable: unused slots stay in the list (cheap, no geometry refers to them)
    scene = Scene(
        name=name or f"procedural-{seed}",
        meshes=meshes,
        materials=mats,
        sun=sun,
        point_lights=lights,
        spawn_points=spawns,
    )
    log.debug("procedural scene %s: %d triangles, %d/%d materials used", scene.name, scene.triangle_count,
              len(used), len(mats))
    return scene
