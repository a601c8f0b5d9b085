"""Viewpoint sampling for capture (the paper's Appendix A, with the fixes noted in docs/scenes.md).

1. **Free space.** The scene's triangles (plus optional *blockers*, e.g. a BSP map's sky
   surfaces, which are not drawn but seal the level) are voxelised: a voxel is solid when a
   sample of a triangle falls in it (samples no further apart than half a voxel, so every
   triangle leaves a 26-connected voxel trail that a 6-connected flood cannot cross). A
   6-connected flood fill through free voxels starts at the spawn points, bounded by the scene
   bounds: the reachable space.
2. **Candidates.** Reachable voxels at least ``clearance`` from every solid voxel.
3. **A view** is a candidate position (jittered inside its voxel) with yaw ~ U[-180, 180] and
   pitch ~ U[-pitch_limit, pitch_limit]. It is kept when the exact distance from the camera to
   every triangle is at least ``clearance`` and at least ``min_coverage`` of a coarse ray grid
   (``rays``, default 32x18 over the camera frustum) hits drawn geometry within
   ``max_distance`` (rays are marched through the voxel grid; rays that reach a blocker or
   leave the bounds count as sky).
4. **The previous viewpoint** is the view moved by the motion profile: a translation uniform in a
   ball of radius ``max_translation`` and yaw/pitch offsets uniform in +-``max_rotation``
   degrees. It must be reachable, pass the same clearance and coverage tests, and the segment
   between the two positions must not cross a triangle (exact segment/triangle test).

Everything is drawn from one ``numpy.random.default_rng(seed)`` in a fixed order, so the same
scene and arguments give the same viewpoints.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from rtp.scene import Camera, Scene
from rtp.sdk import RtpError

__all__ = [
    "DEFAULT_PROFILES",
    "MOTION_PROFILES",
    "PLACEMENTS",
    "MotionProfile",
    "ViewpointError",
    "VoxelGrid",
    "free_space",
    "sample_viewpoints",
]

log = logging.getLogger("rtp.capture")

FREE, SOLID, BLOCKER, OUTSIDE = 0, 1, 2, 3


class ViewpointError(RtpError, ValueError):
    """No valid viewpoint can be sampled (no spawn point, no free space, too few valid views)."""


@dataclass(frozen=True)
class MotionProfile:
    """Camera motion between the previous and the current frame.

    ``max_translation`` (metres): the previous position is uniform in a ball of this radius
    around the current one. ``max_rotation`` (degrees): yaw and pitch offsets are uniform in
    ``[-max_rotation, max_rotation]``.
    """

    name: str
    max_translation: float
    max_rotation: float


# Tuned so the reference renderer's seen mask leaves about the paper's 14 % (slow) and 31 % (fast)
# of the pixels unseen, averaged over procedural and Quake-3 scenes (docs/scenes.md has the sweep).
# ``frame``: the motion of one frame at 60 Hz on `rtp play`'s fast path (6 m/s and its 240 deg/s turn
# after the direction of travel: 0.1 m and 4 deg; the path's sway adds up to 98 deg/s, 5.6 deg a frame in
# all), the distribution a 60 fps engine and the closed loop see (0.07-3.7 % of a frame's pixels unseen
# per frame, each test map path's mean, against 11-32 % for slow and fast). Not captured unless asked for
# (:data:`DEFAULT_PROFILES`).
MOTION_PROFILES: dict[str, MotionProfile] = {
    "slow": MotionProfile("slow", max_translation=0.35, max_rotation=4.5),
    "fast": MotionProfile("fast", max_translation=1.3, max_rotation=15.0),
    "frame": MotionProfile("frame", max_translation=0.1, max_rotation=4.0),
}

#: The profiles `rtp capture` draws by default (every dataset the shipped models were trained on).
DEFAULT_PROFILES: tuple[str, ...] = ("slow", "fast")


#: Where :func:`sample_viewpoints` puts the cameras (``placement``).
PLACEMENTS: dict[str, str] = {
    "free": "anywhere in the viewpoint domain (reachable free space up to max_height over a solid voxel)",
    "eye": "at the player's eye height over a floor (the spawn points' own), moving along the floors between "
           "the two frames, as the camera paths of rtp play do",
}


# -- parameter checks ----------------------------------------------------------------------------


def _real(name: str, value: object, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
          hi_open: bool = False) -> float:
    """``value`` as a float in the range given, or a ViewpointError saying what was expected."""
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
    try:
        v = float(value) if ok else math.nan  # type: ignore[arg-type]
    except OverflowError:  # an int past float's range
        v = math.nan
    if ok and math.isfinite(v):
        ok = (lo is None or (v > lo if lo_open else v >= lo)) and (hi is None or (v < hi if hi_open else v <= hi))
    else:
        ok = False
    if not ok:
        lo_s = "" if lo is None else f"{'>' if lo_open else '>='} {lo:g}"
        hi_s = "" if hi is None else f"{'<' if hi_open else '<='} {hi:g}"
        raise ViewpointError(f"{name}: expected a finite number {' and '.join(x for x in (lo_s, hi_s) if x)}, "
                             f"got {value!r}")
    return v


def _count(name: str, value: object, lo: int = 0) -> int:
    """``value`` as an integer >= ``lo``, or a ViewpointError (numpy's generator refuses negative seeds in its
    own words; a float count failed in ``range``)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise ViewpointError(f"{name}: expected an integer >= {lo}, got {value!r}")
    return int(value)


#: The largest distances the checks take, metres: far past any level (oa_dm3's backdrop spans 630 m),
#: short of what would fill memory (a ray march of max_distance, a dilation of clearance voxels).
MAX_METRES = 1000.0


#: The most coverage rays a camera may cast (a ray grid of 10**7 x 10**7 asked numpy for 728 TiB).
MAX_RAYS = 512 * 512

#: The widest frustum, width over height: far past any screen; at 1e308 the rays overflowed to nan.
MAX_ASPECT = 1e6


def _check_space(voxel: float, clearance: float, max_height: float | None) -> None:
    _real("voxel", voxel, 0.0, MAX_METRES, lo_open=True)
    _real("clearance", clearance, 0.0, MAX_METRES)
    if max_height is not None:
        _real("max_height", max_height, 0.0, lo_open=True)


# -- geometry helpers -----------------------------------------------------------------------------

def scene_triangles(scene: Scene) -> np.ndarray:
    """All triangles of ``scene`` as ``(T, 3, 3)`` float64 world positions."""
    parts = [m.positions.astype(np.float64)[m.indices.astype(np.int64)] for m in scene.meshes if len(m.indices)]
    return np.concatenate(parts) if parts else np.zeros((0, 3, 3))


def _triangle_samples(tris: np.ndarray, step: float, chunk: int = 4_000_000):
    """Yield ``(P, 3)`` sample points covering each triangle with spacing <= ``step``.

    Each triangle is parameterised from the vertex opposite its longest edge,
    ``a + (i/n1) e1 + (j/n2) e2`` with ``i/n1 + j/n2 <= 1``, so slivers cost few points."""
    if len(tris) == 0:
        return
    e = np.stack([tris[:, 2] - tris[:, 1], tris[:, 0] - tris[:, 2], tris[:, 1] - tris[:, 0]], 1)  # opposite v0, v1, v2
    k = np.argmax(np.linalg.norm(e, axis=2), axis=1)  # vertex opposite the longest edge
    ar = np.arange(len(tris))
    a = tris[ar, k]
    e1 = tris[ar, (k + 1) % 3] - a
    e2 = tris[ar, (k + 2) % 3] - a
    n1 = np.maximum(1, np.ceil(np.linalg.norm(e1, axis=1) / step)).astype(np.int64)
    n2 = np.maximum(1, np.ceil(np.linalg.norm(e2, axis=1) / step)).astype(np.int64)
    counts = ((n1 + 1) * (n2 + 2)) // 2 + n1 + 1  # upper bound of points per triangle
    start = 0
    while start < len(tris):
        cum = np.cumsum(counts[start:])
        stop = start + max(1, int(np.searchsorted(cum, chunk)))
        sl = slice(start, stop)
        t_of_row = np.repeat(np.arange(start, stop), n1[sl] + 1)
        i = np.arange(len(t_of_row)) - np.repeat(np.cumsum(n1[sl] + 1) - (n1[sl] + 1), n1[sl] + 1)
        s = i / n1[t_of_row]
        jn = np.floor(n2[t_of_row] * (1.0 - s) + 1e-9).astype(np.int64) + 1
        t_of_pt = np.repeat(t_of_row, jn)
        s_pt = np.repeat(s, jn)
        j = np.arange(len(t_of_pt)) - np.repeat(np.cumsum(jn) - jn, jn)
        u = j / n2[t_of_pt]
        yield a[t_of_pt] + s_pt[:, None] * e1[t_of_pt] + u[:, None] * e2[t_of_pt]
        start = stop


def point_triangle_distance(p: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Exact distances from one point ``p`` (3,) to each triangle of ``tris`` (T, 3, 3)."""
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    n = np.cross(b - a, c - a)
    ln = np.linalg.norm(n, axis=1)
    nn = n / np.maximum(ln, 1e-20)[:, None]
    d_plane = np.einsum("ij,ij->i", p - a, nn)
    q = p - d_plane[:, None] * nn
    inside = ln > 1e-20
    for v0, v1 in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v1 - v0, q - v0), n) >= 0

    def seg(v0: np.ndarray, v1: np.ndarray) -> np.ndarray:
        d = v1 - v0
        t = np.clip(np.einsum("ij,ij->i", p - v0, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-20), 0.0, 1.0)
        return np.linalg.norm(p - (v0 + t[:, None] * d), axis=1)

    edge = np.minimum(np.minimum(seg(a, b), seg(b, c)), seg(c, a))
    return np.where(inside, np.abs(d_plane), edge)


def segment_hits_triangles(p0: np.ndarray, p1: np.ndarray, tris: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """Which triangles the segment ``p0``-``p1`` crosses (Moeller-Trumbore, both faces)."""
    d = p1 - p0
    e1 = tris[:, 1] - tris[:, 0]
    e2 = tris[:, 2] - tris[:, 0]
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(det) > eps
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = p0 - tris[:, 0]
    u = inv * np.einsum("ij,ij->i", s, h)
    q = np.cross(s, e1)
    v = inv * (q @ d)
    t = inv * np.einsum("ij,ij->i", e2, q)
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= 1)


# -- the voxel grid -------------------------------------------------------------------------------

def _within(tris: np.ndarray, bounds: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The parts of the triangles inside the box ``bounds`` = ``(lo, hi)``, as triangles: those wholly
    inside as they are, those crossing its faces clipped to it (Sutherland-Hodgman, then a fan), so
    that a kilometre-wide backdrop costs samples only where it is in the box."""
    t = np.asarray(tris, np.float64)
    if len(t) == 0:
        return t
    lo, hi = (np.asarray(b, np.float64) for b in bounds)
    tmin, tmax = t.min(1), t.max(1)
    overlap = np.all((tmin <= hi) & (tmax >= lo), axis=1)
    inside = np.all((tmin >= lo) & (tmax <= hi), axis=1)
    out = [t[inside]]
    for tri in t[overlap & ~inside]:
        poly = list(tri)
        for axis in range(3):
            for bound, sign in ((lo[axis], 1.0), (hi[axis], -1.0)):
                if not poly:
                    break
                clipped = []
                for a, b in zip(poly, poly[1:] + poly[:1]):
                    da, db = sign * (a[axis] - bound), sign * (b[axis] - bound)
                    if da >= 0:
                        clipped.append(a)
                    if (da >= 0) != (db >= 0):
                        clipped.append(a + (b - a) * (da / (da - db)))
                poly = clipped
        if len(poly) >= 3:
            out.append(np.array([[poly[0], poly[i], poly[i + 1]] for i in range(1, len(poly) - 1)]))
    return np.concatenate(out)


class VoxelGrid:
    """Occupancy of the scene bounds (padded by one voxel of ``OUTSIDE``) at ``voxel`` metres.

    ``occ`` is uint8 ``(nx, ny, nz)``: 0 free, 1 drawn geometry, 2 blocker, 3 outside the bounds.
    """

    def __init__(self, triangles: np.ndarray, voxel: float, blockers: np.ndarray | None = None,
                 max_voxels: int = 24_000_000, bounds: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        if bounds is not None:  # only the triangles that reach into the box; the rest is OUTSIDE
            triangles, blockers = _within(triangles, bounds), None if blockers is None else _within(blockers, bounds)
            lo, hi = (np.asarray(b, np.float64) for b in bounds)
        else:
            allt = triangles if blockers is None or len(blockers) == 0 else np.concatenate([triangles, blockers])
            lo, hi = allt.reshape(-1, 3).min(0), allt.reshape(-1, 3).max(0)
        ext = hi - lo
        if np.prod(ext / voxel + 3) > max_voxels:
            new = max(voxel, float((np.prod(ext) / max_voxels) ** (1 / 3)) * 1.05)
            # The volume's cube root leaves out the padding and a flat level's zero extent (a 10 km ground quad
            # alone kept 0.25 m: 4.8e9 voxels, a MemoryError): coarser still until the grid itself fits. (No
            # map of the scene cache comes here: their grids, and the datasets planned on them, are as they were.)
            while np.prod(np.ceil(ext / new) + 3) > max_voxels and bool((ext > new).any()):
                new *= 1.05
            log.info("voxel %.3f m gives more than %d voxels: using %.3f m", voxel, max_voxels, new)
            voxel = new
        self.voxel = float(voxel)
        self.origin = lo - voxel  # one padding voxel
        self.shape = tuple(int(x) for x in np.ceil(ext / voxel).astype(int) + 3)
        occ = np.zeros(self.shape, np.uint8)
        self._mark(occ, triangles, SOLID)
        if blockers is not None and len(blockers):
            mask = np.zeros(self.shape, bool)
            for pts in _triangle_samples(np.asarray(blockers, np.float64), voxel * 0.5):
                mask[tuple(self.index(pts).T)] = True
            occ[mask & (occ == FREE)] = BLOCKER
        occ[0, :, :] = occ[-1, :, :] = OUTSIDE
        occ[:, 0, :] = occ[:, -1, :] = OUTSIDE
        occ[:, :, 0] = occ[:, :, -1] = OUTSIDE
        self.occ = occ

    def _mark(self, occ: np.ndarray, tris: np.ndarray, value: int) -> None:
        for pts in _triangle_samples(tris, self.voxel * 0.5):
            occ[tuple(self.index(pts).T)] = value

    def index(self, p: np.ndarray) -> np.ndarray:
        """Voxel indices ``(..., 3)`` of points, clipped to the grid."""
        i = np.floor((np.asarray(p) - self.origin) / self.voxel).astype(np.int64)
        return np.clip(i, 0, np.array(self.shape) - 1)

    def centre(self, flat: np.ndarray) -> np.ndarray:
        return (np.stack(np.unravel_index(flat, self.shape), -1) + 0.5) * self.voxel + self.origin

    def flood(self, seeds: np.ndarray, passable: np.ndarray) -> np.ndarray:
        """6-connected flood fill through ``passable`` from seed points; returns a bool grid."""
        nx, ny, nz = self.shape
        pas = passable.ravel()
        visited = np.zeros(pas.size, bool)
        offs = np.array([1, -1, nz, -nz, ny * nz, -ny * nz], np.int64)
        seeds_found = [f for f in (self.seed(s, pas) for s in np.atleast_2d(seeds)) if f is not None]
        front = np.unique(np.array(seeds_found, np.int64))
        visited[front] = True
        while front.size:
            nb = (front[:, None] + offs[None, :]).ravel()
            nb = nb[pas[nb] & ~visited[nb]]
            nb = np.unique(nb)
            visited[nb] = True
            front = nb
        return visited.reshape(self.shape)

    def near(self, point: np.ndarray | Sequence[float]) -> bool:
        """Whether ``point`` lies within 2 voxels of the grid's inside (the bounds), where :meth:`seed` looks."""
        raw = np.floor((np.asarray(point, np.float64) - self.origin) / self.voxel)
        return bool(np.all(raw >= -1) and np.all(raw <= np.array(self.shape)))

    def seed(self, point: np.ndarray, passable_flat: np.ndarray) -> int | None:
        """The flat index of the passable voxel nearest ``point`` within 2 voxels (where a flood from it
        starts), or None. None too for a point further outside the grid (:meth:`near`): clipped onto the
        grid's side, a spawn point 100 m over a closed room flooded the room."""
        if not self.near(point):
            return None
        r = np.arange(-2, 3)
        g = np.stack(np.meshgrid(r, r, r, indexing="ij"), -1).reshape(-1, 3)
        g = g[np.argsort(np.abs(g).sum(1), kind="stable")]
        cand = np.clip(self.index(point) + g, 1, np.array(self.shape) - 2)
        flat = np.ravel_multi_index(tuple(cand.T), self.shape)
        ok = flat[passable_flat[flat]]
        return int(ok[0]) if len(ok) else None

    def dilate(self, mask: np.ndarray, k: int) -> np.ndarray:
        """Dilate ``mask`` by ``k`` voxels in the 26-neighbourhood (a cube of side 2k+1)."""
        out = mask.copy()
        for axis in range(3):
            for _ in range(min(k, out.shape[axis])):  # (past the grid's side it changes nothing more)
                cur = out.copy()
                sl_a = [slice(None)] * 3
                sl_b = [slice(None)] * 3
                sl_a[axis], sl_b[axis] = slice(1, None), slice(None, -1)
                cur[tuple(sl_a)] |= out[tuple(sl_b)]
                cur[tuple(sl_b)] |= out[tuple(sl_a)]
                out = cur
        return out

    def march(self, origin: np.ndarray, dirs: np.ndarray, max_distance: float) -> np.ndarray:
        """First non-free value along each ray (``FREE`` when nothing is met within range)."""
        step = self.voxel * 0.5
        ts = np.arange(step, max_distance + step, step)
        res = np.zeros(len(dirs), np.uint8)
        finite = np.isfinite(dirs).all(1) & bool(np.isfinite(origin).all())
        res[~finite] = OUTSIDE  # (a ray that goes nowhere, as an absurd aspect's overflow makes: sky)
        todo = np.flatnonzero(finite)
        top = np.array(self.shape, np.float64) - 1
        _, ny, nz = self.shape
        occ = self.occ.ravel()
        # Steps in chunks that grow (most rays meet something within the first metres). A point
        # outside the grid is clipped onto its border, whose voxels are all OUTSIDE (__init__), so it
        # reads OUTSIDE without a test of its own. The arithmetic up to the floor is the same as it
        # always was, so the same rays meet the same voxels (and capture plans the same cameras).
        c0, size = 0, 16
        while c0 < len(ts) and len(todo):
            t = ts[c0 : c0 + size]
            c0, size = c0 + size, min(2 * size, 128)
            q = origin + dirs[todo, None, :] * t[None, :, None]  # (R, K, 3)
            q -= self.origin
            q /= self.voxel
            np.floor(q, out=q)
            np.clip(q, 0.0, top, out=q)
            i = q.astype(np.int64)
            v = occ[(i[..., 0] * ny + i[..., 1]) * nz + i[..., 2]]
            hit = v != FREE
            any_hit = hit.any(1)
            first = np.argmax(hit, axis=1)
            res[todo[any_hit]] = v[any_hit, first[any_hit]]
            todo = todo[~any_hit]
        return res


# -- sampling -------------------------------------------------------------------------------------

def ray_grid(camera: Camera, aspect: float, nx: int, ny: int) -> np.ndarray:
    """Unit world directions ``(ny*nx, 3)`` through the centres of an ``nx`` x ``ny`` grid."""
    th = math.tan(math.radians(camera.fov_y) / 2)
    x = ((np.arange(nx) + 0.5) / nx * 2 - 1) * th * aspect
    y = (1 - (np.arange(ny) + 0.5) / ny * 2) * th
    X, Y = np.meshgrid(x, y)
    d = np.stack([X.ravel(), Y.ravel(), -np.ones(X.size)], 1) @ camera.rotation().T
    return d / np.linalg.norm(d, axis=1, keepdims=True)


class _Validator:
    """Exact clearance and segment tests against the triangles, with AABB pre-filtering."""

    def __init__(self, tris: np.ndarray) -> None:
        self.tris = tris
        self.lo = tris.min(1)
        self.hi = tris.max(1)

    def clearance(self, p: np.ndarray, r: float) -> bool:
        m = ((self.lo <= p + r) & (self.hi >= p - r)).all(1)
        if not m.any():
            return True
        return bool(point_triangle_distance(p, self.tris[m]).min() >= r)

    def segment_clear(self, p0: np.ndarray, p1: np.ndarray) -> bool:
        lo, hi = np.minimum(p0, p1), np.maximum(p0, p1)
        m = ((self.lo <= hi) & (self.hi >= lo)).all(1)
        if not m.any():
            return True
        return not segment_hits_triangles(p0, p1, self.tris[m]).any()


def _coverage(grid: VoxelGrid, cam: Camera, aspect: float, rays: tuple[int, int], max_distance: float) -> float:
    hits = grid.march(np.asarray(cam.position, np.float64), ray_grid(cam, aspect, *rays), max_distance)
    return float((hits == SOLID).mean())


def free_space(
    scene: Scene,
    *,
    blockers: np.ndarray | None = None,
    voxel: float = 0.25,
    clearance: float = 0.3,
    max_height: float | None = 6.0,
    focus: bool = False,
) -> tuple[np.ndarray, VoxelGrid, np.ndarray, np.ndarray]:
    """The valid viewpoint domain of ``scene``: ``(triangles, grid, reachable, candidates)``.

    ``reachable`` (bool grid) is the free space flood-filled from the spawn points (at most
    ``max_height`` above a solid voxel below, when set); ``candidates`` is the part of it at least
    ``clearance`` (rounded up to whole voxels) from any geometry. :func:`sample_viewpoints` and the
    camera paths of :mod:`rtp.capture.paths` draw from it. Raises :class:`ViewpointError` for a
    scene without spawn points or triangles, or whose spawn points all lie outside it (more than two voxels
    past its bounds; one such among others is logged as a warning and starts no flood).

    A map whose geometry spans too much for ``voxel`` (more than :class:`VoxelGrid`'s voxel budget)
    gets a coarser grid. ``focus=True`` (the camera paths, whose walker needs floors and steps)
    then, when that grid is more than :data:`FOCUS_COARSENING` times coarser than ``voxel``, floods
    it once and voxelises again only the box around what it reached and the spawn points (plus
    :data:`FOCUS_MARGIN`, and ``max_height`` below), at ``voxel`` where that fits: oa_dm3's drawn
    backdrop spans 590 x 280 x 630 m around a 75 x 9 x 48 m arena (1.72 m voxels over the whole
    map, where no path was found). The test maps oacmpctf3 and oasago2 (0.32-0.39 m) keep their
    whole-map grids, so their published paths stay as they were; the capture's viewpoints keep the
    one grid (the datasets were captured with it).
    """
    _check_space(voxel, clearance, max_height)
    if not isinstance(scene, Scene):
        raise ViewpointError(f"scene: expected an rtp.scene.Scene (rtp.capture.load_scene makes one from a name), got "
                             f"{type(scene).__name__}")
    if blockers is not None:
        ok = isinstance(blockers, np.ndarray) and blockers.dtype.kind in "iuf" and blockers.ndim == 3 \
            and blockers.shape[1:] == (3, 3)
        if not ok or not np.isfinite(blockers).all():
            got = f"{blockers.dtype} {blockers.shape}" if isinstance(blockers, np.ndarray) else type(blockers).__name__
            raise ViewpointError(f"blockers: expected finite triangles of shape (K, 3, 3), got {got}")
    if not scene.spawn_points:
        raise ViewpointError(f"scene {scene.name!r} has no spawn points to start the flood fill from")
    tris = scene_triangles(scene)
    if len(tris) == 0:
        raise ViewpointError(f"scene {scene.name!r} has no triangles")
    grid = VoxelGrid(tris, voxel, blockers)
    if focus and grid.voxel > FOCUS_COARSENING * voxel:
        _, reach = _flood(scene, grid, max_height)
        pts = np.concatenate([grid.centre(np.flatnonzero(reach)),
                              np.array([sp.position for sp in scene.spawn_points], np.float64)])
        pad = max(FOCUS_MARGIN, 2 * grid.voxel)
        lo = pts.min(0) - pad - np.array([0.0, max_height or 0.0, 0.0])
        hi = pts.max(0) + pad
        log.info("%s: %.3f m voxels over the whole map; %.3f m around its %.0f x %.0f x %.0f m playable box",
                 scene.name, grid.voxel, voxel, *(hi - lo))
        grid = VoxelGrid(tris, voxel, blockers, bounds=(lo, hi))
    _, reach = _flood(scene, grid, max_height)
    k = int(math.ceil(clearance / grid.voxel))
    return tris, grid, reach, reach & ~grid.dilate(grid.occ != FREE, k)


#: How much coarser than asked the whole-map grid may be before ``free_space(focus=True)``
#: voxelises again around the playable part.
FOCUS_COARSENING = 2.0

#: Metres kept around the spawn points and the coarse grid's reachable space when ``free_space``
#: voxelises again around them (``focus=True``).
FOCUS_MARGIN = 8.0


def _passable(grid: VoxelGrid, max_height: float | None) -> np.ndarray:
    """The free voxels of ``grid`` a viewpoint may take: at most ``max_height`` over a solid one, when set."""
    passable = grid.occ == FREE
    if max_height is not None:
        solid = grid.occ != FREE
        ny = grid.shape[1]
        last = np.where(solid, np.arange(ny)[None, :, None], -1)
        last = np.maximum.accumulate(last, axis=1)
        height = (np.arange(ny)[None, :, None] - last) * grid.voxel
        passable &= (last >= 0) & (height <= max_height)
    return passable


def _flood(scene: Scene, grid: VoxelGrid, max_height: float | None) -> tuple[np.ndarray, np.ndarray]:
    """``(passable, reachable)`` of ``grid``: free voxels (at most ``max_height`` over a solid one,
    when set), and those of them flood-filled from the spawn points."""
    passable = _passable(grid, max_height)
    seeds = np.array([sp.position for sp in scene.spawn_points], np.float64)
    away = [p for p in seeds if not grid.near(p)]
    if away:
        lo, hi = grid.origin + grid.voxel, grid.origin + (np.array(grid.shape) - 1) * grid.voxel
        where = (f"its voxel grid spans ({', '.join(f'{v:.2f}' for v in lo)}) to "
                 f"({', '.join(f'{v:.2f}' for v in hi)}) m, the first spawn point outside it is at "
                 f"({', '.join(f'{v:.2f}' for v in away[0])})")
        if len(away) == len(seeds):
            raise ViewpointError(f"scene {scene.name!r}: none of its {len(seeds)} spawn points lies within the level "
                                 f"({where}; spawn points in other units or axes than the level's?)")
        log.warning("%s: %d of its %d spawn points lie outside the level, where no flood starts (%s)", scene.name,
                    len(away), len(seeds), where)
    return passable, grid.flood(seeds, passable)


#: The voxel budget of :func:`_roomiest_spawn`'s grid: coarser than the capture's, as it runs when a mesh file
#: loads.
_SPAWN_VOXELS = 2_000_000

#: The share of a free region's volume over another region (that region the lowest free space of the column)
#: past which :func:`_roomiest_spawn` takes it for the outside of that one (the space over a dome's roof), not a
#: level of its own.
_ROOF_SHARE = 0.5

#: The distance, metres, that :func:`_roomiest_spawn` keeps a moved spawn point from the geometry where it can.
_SPAWN_CLEARANCE = 0.5


def _regions(passable: np.ndarray) -> np.ndarray:
    """The 6-connected regions of ``passable``: for each passable voxel the smallest flat index of its region,
    -1 elsewhere (a flat int64 array). Minimum-label propagation with pointer jumping (numpy only)."""
    n = passable.size
    pas = passable.ravel()
    lab = np.where(pas, np.arange(n, dtype=np.int64), n)
    grid = lab.reshape(passable.shape)
    while True:
        before = lab.copy()
        for axis in range(3):
            lo = [slice(None)] * 3
            hi = [slice(None)] * 3
            lo[axis], hi[axis] = slice(None, -1), slice(1, None)
            np.minimum(grid[tuple(hi)], grid[tuple(lo)], out=grid[tuple(hi)])
            np.minimum(grid[tuple(lo)], grid[tuple(hi)], out=grid[tuple(lo)])
            lab[~pas] = n  # (only passable voxels carry labels across)
        while True:  # every label is a passable voxel's index: follow it to that voxel's label
            jumped = lab[np.minimum(lab, n - 1)]
            jumped[~pas] = n
            if np.array_equal(jumped, lab):
                break
            lab[:] = jumped
        if np.array_equal(lab, before):
            return np.where(pas, lab, -1)


def _roomiest_spawn(scene: Scene, target: Sequence[float] | np.ndarray, *, voxel: float = 0.25,
                    max_height: float | None = 6.0) -> tuple[np.ndarray, float, float] | None:
    """Where the flood fill of a scene without spawn points of its own starts, near ``target`` (a mesh file's:
    the centre of its bounds, eye height over their bottom).

    The free space of the scene's grid (``_SPAWN_VOXELS`` at most) at most ``max_height`` over drawn geometry
    (free space over nothing but the bounds' bottom is outside the level: around an L-shaped corridor, below a
    dome) falls into 6-connected regions. A region of which more than :data:`_ROOF_SHARE` of the volume lies
    over another region (in columns whose lowest free space is that other one's) is that region's outside (the
    space over a dome's roof, the inside of a ball standing in a room), not a level of its own; of the others the
    largest is the level. Returns ``(point, volume, own)``: ``target`` where it lies in that region, else the
    region's voxel nearest to it (at its height where the region has voxels there, and
    :data:`_SPAWN_CLEARANCE` from the geometry where it can); the region's volume; and ``target``'s own
    region's (0 where it lies in none), in m³. None when no free space lies over the geometry. (A target inside
    a closed object flooded the object's inside; the bounds' empty corners around a dome or an L-shaped
    corridor, the largest region where they counted, put the spawn point outside the level.)
    """
    tris = scene_triangles(scene)
    if len(tris) == 0:
        return None
    grid = VoxelGrid(tris, voxel, max_voxels=_SPAWN_VOXELS)
    ny = grid.shape[1]
    last = np.maximum.accumulate(np.where(grid.occ == SOLID, np.arange(ny)[None, :, None], -1), axis=1)
    passable = (grid.occ == FREE) & (last >= 0)  # (the OUTSIDE padding below the bounds is no floor)
    if max_height is not None:  # (two voxels at least: a grid coarsened past max_height has free space over floors)
        passable &= (np.arange(ny)[None, :, None] - last) * grid.voxel <= max(max_height, 2 * grid.voxel)
    lab = _regions(passable)
    flat = np.flatnonzero(lab >= 0)
    if not len(flat):
        return None
    roots, region = np.unique(lab[flat], return_inverse=True)
    volumes = np.bincount(region).astype(np.float64) * grid.voxel ** 3
    # the lowest region of each column (x, z): the first passable voxel from the bottom
    lab3 = lab.reshape(grid.shape)
    has = passable.any(axis=1)
    bottom = np.take_along_axis(lab3, np.argmax(passable, axis=1)[:, None, :], axis=1)[:, 0, :]
    bottom = np.where(has, bottom, -1)
    ix, _, iz = np.unravel_index(flat, grid.shape)
    over = np.bincount(region, weights=(bottom[ix, iz] != lab[flat]).astype(np.float64)) * grid.voxel ** 3
    level = volumes * (over <= _ROOF_SHARE * volumes)  # (roofs count 0; one at least is no roof: the lowest)
    best = int(np.argmax(level if level.max() > 0 else volumes))
    t = np.asarray(target, np.float64)
    start = grid.seed(t, passable.ravel())
    own = float(volumes[np.searchsorted(roots, lab[start])]) if start is not None else 0.0
    if start is not None and lab[start] == roots[best]:
        return t, float(volumes[best]), own
    members = flat[region == best]
    clear = ~grid.dilate(grid.occ != FREE, int(math.ceil(_SPAWN_CLEARANCE / grid.voxel))).ravel()[members]
    layer = np.unravel_index(members, grid.shape)[1] == grid.index(t)[1]
    pick = next(m for m in (layer & clear, layer, clear, np.ones(len(members), bool)) if m.any())
    centres = grid.centre(members[pick])
    if layer[pick].all():  # (the target's height, as a spawn point over the bounds' bottom stands)
        centres[:, 1] = t[1]
    point = centres[int(np.argmin(np.sum((centres - t) ** 2, axis=1)))]
    return point, float(volumes[best]), own


# -- standing on floors (eye-height viewpoints and the camera paths) --------------------------------

_STEP_UP = 0.6  # the highest step a player climbs, metres (Q3's 18 units plus a voxel of rounding)
_DROP = 1.2  # the deepest ledge a player steps down; deeper ones are walls
_EYE = 1.6  # eye height above the floor where a scene's spawn points do not tell it, metres


class _Floors:
    """The floor under a point: the centre of the highest drawn-geometry voxel at or below it in its
    column (blockers such as a BSP map's sky are not floors)."""

    def __init__(self, grid: VoxelGrid) -> None:
        self.grid = grid
        ny = grid.shape[1]
        last = np.where(grid.occ == SOLID, np.arange(ny, dtype=np.int16)[None, :, None], np.int16(-1))
        self.last = np.maximum.accumulate(last, axis=1)

    def below(self, p: np.ndarray) -> float | None:
        i = self.grid.index(p)
        j = int(self.last[i[0], i[1], i[2]])
        return None if j < 0 else float(self.grid.origin[1] + (j + 0.5) * self.grid.voxel)

    def same_floor(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether no drawn geometry lies between two points of one column (``a`` below ``b``)."""
        i, j = self.grid.index(a), self.grid.index(b)
        return bool(self.last[i[0], i[1], i[2]] == self.last[j[0], j[1], j[2]])


def _spawn_eye_height(scene: Scene, floors: _Floors) -> float:
    """The player's eye height in ``scene``: the lowest height of a spawn point over the floor below
    it (between 0.5 and 3 m), or :data:`_EYE` when no spawn point stands over a floor. The lowest,
    because map authors lift spawn entities over the floor (a game drops them): on the test maps
    spawns stand 1.39-1.67 m over their floors at the lowest and up to 2.37 m."""
    heights = []
    for sp in scene.spawn_points:
        p = np.asarray(sp.position, np.float64)
        f = floors.below(p)
        if f is not None and 0.5 <= p[1] - f <= 3.0:
            heights.append(p[1] - f)
    return float(min(heights)) if heights else _EYE


def sample_viewpoints(
    scene: Scene,
    n: int,
    seed: int,
    profile: str | MotionProfile = "slow",
    *,
    blockers: np.ndarray | None = None,
    voxel: float = 0.25,
    clearance: float = 0.3,
    pitch_limit: float = 20.0,
    min_coverage: float | Sequence[float] = 0.85,
    max_distance: float = 100.0,
    rays: tuple[int, int] = (32, 18),
    aspect: float = 16 / 9,
    fov_y: float = 70.0,
    max_height: float | None = 6.0,
    max_attempts: int | None = None,
    prev_tries: int = 20,
    stats: dict | None = None,
    placement: str = "free",
    progress: Callable[[int], None] | None = None,
) -> list[tuple[Camera, Camera]]:
    """Sample ``n`` valid ``(previous, current)`` camera pairs in ``scene``.

    Args:
        scene: the scene; its spawn points seed the flood fill of free space.
        n: number of pairs.
        seed: seed of the random generator (same inputs → same cameras).
        profile: ``"slow"``, ``"fast"``, ``"frame"`` (see :data:`MOTION_PROFILES`) or a :class:`MotionProfile`.
        blockers: extra ``(K, 3, 3)`` triangles that are not drawn but bound free space (a BSP
            map's sky, from :func:`rtp.capture.scenes.scene_blockers`).
        voxel: voxel edge in metres (coarsened automatically above 24 M voxels).
        clearance: minimum distance from a camera to any triangle, metres.
        pitch_limit: pitch is drawn from U[-pitch_limit, pitch_limit] degrees.
        min_coverage: minimum fraction of the ray grid that must hit drawn geometry, or a
            decreasing sequence of them: when a pair cannot be found at one level within
            ``max_attempts`` draws, sampling goes on at the next level (and stays there).
        max_distance: range of the coverage rays, metres.
        rays: ray grid (columns, rows) over the frustum.
        aspect, fov_y: the frustum of the cameras (fov_y is stored in the cameras).
        max_height: if set, free space is limited to voxels at most this high above a solid voxel
            below (keeps cameras near walkable floors in open maps).
        max_attempts: candidate draws per pair and coverage level before moving to the next level
            or giving up (default 1200).
        prev_tries: previous-viewpoint draws per accepted current view.
        stats: if a dict is given, it is filled with ``voxel``, ``grid_shape``, ``reachable``,
            ``candidates``, ``draws`` and ``rejected`` (counts per rule).
        placement: :data:`PLACEMENTS`. ``"free"`` (the default, every dataset so far): a candidate
            voxel anywhere in the domain. ``"eye"``: the candidates are the voxels at the player's
            eye height (:func:`_spawn_eye_height`) over a floor, one per standing column; the camera
            stands exactly that high over its floor, and the previous one is moved horizontally
            (uniform in a disc of ``max_translation``) and stands on its own floor, between
            ``_DROP`` (1.2 m, a jump's height) below and ``_STEP_UP`` (0.6 m) above the current
            one's. Yaw, pitch and every test are as for ``"free"``.
        progress: called with the number of pairs found so far as each is found (a pair takes a
            few milliseconds: ``rtp capture`` shows it while it plans many).

    Returns:
        ``n`` tuples ``(previous_camera, current_camera)``. The pairs are a stream: the first ``k``
        pairs of a call with ``n > k`` are the pairs of the call with ``n = k`` (the fallback
        between coverage levels included), so a dataset captured with a small ``n`` and extended
        later holds the same cameras as one captured in one go.

    Raises:
        ViewpointError: no spawn point, no reachable free space, or fewer than ``n`` valid pairs
            within ``max_attempts`` draws.
    """
    prof = MOTION_PROFILES.get(profile) if isinstance(profile, str) else profile
    if not isinstance(prof, MotionProfile):
        raise ViewpointError(f"unknown motion profile {profile!r}; expected one of {sorted(MOTION_PROFILES)} or a "
                             "MotionProfile")
    _real("max_translation", prof.max_translation, 0.0, MAX_METRES)
    _real("max_rotation", prof.max_rotation, 0.0, 180.0)
    if not isinstance(placement, str) or placement not in PLACEMENTS:
        raise ViewpointError(f"unknown placement {placement!r}; expected one of {', '.join(PLACEMENTS)}")
    n, seed, prev_tries = _count("n", n), _count("seed", seed), _count("prev_tries", prev_tries, 1)
    if max_attempts is not None:
        _count("max_attempts", max_attempts)
    pitch_limit = _real("pitch_limit", pitch_limit, 0.0, 90.0) + 0.0  # (-0.0: numpy's "high - low < 0")
    _real("max_distance", max_distance, 0.0, MAX_METRES, lo_open=True)
    if stats is not None and not isinstance(stats, dict):
        raise ViewpointError(f"stats: expected None or a dict to fill, got {type(stats).__name__}")
    if progress is not None and not callable(progress):
        raise ViewpointError(f"progress: expected None or a function of the pairs found, got {type(progress).__name__}")
    _real("aspect", aspect, 0.0, MAX_ASPECT, lo_open=True)
    _real("fov_y", fov_y, 0.0, 180.0, lo_open=True, hi_open=True)
    if not isinstance(rays, (tuple, list)) or len(rays) != 2:
        raise ViewpointError(f"rays: expected (columns, rows), got {rays!r}")
    rays = (_count("rays' columns", rays[0], 1), _count("rays' rows", rays[1], 1))
    if rays[0] * rays[1] > MAX_RAYS:
        raise ViewpointError(f"rays: expected at most {MAX_RAYS} rays in all (the default is 32 x 18), got {rays}")
    coverages = [min_coverage] if isinstance(min_coverage, (int, float, np.number)) else min_coverage
    if not isinstance(coverages, Sequence) or not coverages:
        raise ViewpointError(f"min_coverage: expected a number or a non-empty sequence of numbers, got {min_coverage!r}")
    levels = [_real("min_coverage", c, 0.0) for c in coverages]  # (above 1: never met)
    if any(b >= a for a, b in zip(levels, levels[1:])):  # (a level not below the one before is never a fallback)
        raise ViewpointError(f"min_coverage: expected a number or a decreasing sequence of numbers (each level a "
                             f"lower fallback, e.g. (0.85, 0.5, 0.15)), got {min_coverage!r}")
    _check_space(voxel, clearance, max_height)
    tris, grid, reach, cand_mask = free_space(scene, blockers=blockers, voxel=voxel, clearance=clearance,
                                              max_height=max_height)
    floors = eye = None
    if placement == "eye":
        floors = _Floors(grid)
        eye = _spawn_eye_height(scene, floors)
        ny = grid.shape[1]
        over = (np.arange(ny)[None, :, None] - floors.last) * grid.voxel  # centre height over the floor's centre
        cand_mask = cand_mask & (floors.last >= 0) & (np.abs(over - eye) <= 0.5 * grid.voxel)
    cand = np.flatnonzero(cand_mask)
    if len(cand) == 0:
        cand = np.flatnonzero(reach)  # narrow levels: rely on the exact clearance test
    if len(cand) == 0:
        raise ViewpointError(f"no free space reachable from the spawn points of {scene.name!r}")
    log.debug("%s: grid %s at %.3f m, %d reachable, %d candidate voxels", scene.name, grid.shape, grid.voxel,
              int(reach.sum()), len(cand))

    val = _Validator(tris)
    rng = np.random.default_rng(seed)
    out: list[tuple[Camera, Camera]] = []
    limit = max_attempts if max_attempts is not None else 1200
    level = 0
    attempts = tries = 0  # draws in total, draws for the current pair at the current level
    rejected = {"clearance": 0, "coverage": 0, "previous": 0}
    if floors is not None:
        rejected["floor"] = 0

    def reachable(p: np.ndarray) -> bool:
        return bool(reach[tuple(grid.index(p))])

    while len(out) < n:
        if tries >= limit:
            if level + 1 >= len(levels):
                break
            level += 1
            tries = 0
            log.info("%s (%s): no pair at coverage %.2f within %d draws; going on at %.2f", scene.name, prof.name,
                     levels[level - 1], limit, levels[level])
        attempts += 1
        tries += 1
        coverage = levels[level]
        v = cand[rng.integers(len(cand))]
        pos = grid.centre(np.array([v]))[0] + rng.uniform(-0.5, 0.5, 3) * grid.voxel
        floor = None
        if floors is not None and eye is not None:
            floor = floors.below(pos)
            if floor is None:
                rejected["floor"] += 1
                continue
            pos[1] = floor + eye
        cam = Camera((float(pos[0]), float(pos[1]), float(pos[2])), yaw=float(rng.uniform(-180.0, 180.0)),
                     pitch=float(rng.uniform(-pitch_limit, pitch_limit)), fov_y=fov_y)
        if not val.clearance(pos, clearance):
            rejected["clearance"] += 1
            continue
        if _coverage(grid, cam, aspect, rays, max_distance) < coverage:
            rejected["coverage"] += 1
            continue
        for _ in range(prev_tries):
            if floors is not None and eye is not None and floor is not None:  # a step along the floors
                a = rng.uniform(0.0, 2.0 * math.pi)
                r = prof.max_translation * math.sqrt(rng.random())
                ppos = pos + np.array([math.cos(a) * r, 0.0, math.sin(a) * r])
                pfloor = floors.below(ppos) if reachable(ppos) else None
                if pfloor is None or not -_DROP <= pfloor - floor <= _STEP_UP:  # from a jump up to a drop
                    continue
                ppos[1] = pfloor + eye
            else:
                d = rng.normal(size=3)
                d /= max(float(np.linalg.norm(d)), 1e-12)
                r = prof.max_translation * rng.random() ** (1 / 3)
                ppos = pos + d * r
            dyaw, dpitch = rng.uniform(-prof.max_rotation, prof.max_rotation, 2)
            prev = Camera((float(ppos[0]), float(ppos[1]), float(ppos[2])), yaw=float((cam.yaw + dyaw + 180) % 360 - 180),
                          pitch=float(np.clip(cam.pitch + dpitch, -pitch_limit, pitch_limit)), fov_y=fov_y)
            if not reachable(ppos) or not val.clearance(ppos, clearance) or not val.segment_clear(pos, ppos):
                continue
            if _coverage(grid, prev, aspect, rays, max_distance) < coverage:
                continue
            out.append((prev, cam))
            tries = 0
            if progress is not None:
                progress(len(out))
            break
        else:
            rejected["previous"] += 1
    if stats is not None:
        stats.update(voxel=grid.voxel, grid_shape=grid.shape, reachable=int(reach.sum()), candidates=len(cand),
                     draws=attempts, rejected=dict(rejected), coverage=levels[level], placement=placement)
        if eye is not None:
            stats["eye_height"] = eye
    if len(out) < n:
        if attempts and rejected["clearance"] == attempts:  # (more draws or a lower coverage change nothing)
            hint = (f"no point drawn from the space reachable from the spawn points is {clearance:g} m from every "
                    f"triangle (a level narrower than that, or spawn points in a closed corner of it): lower clearance")
        else:
            hint = "lower min_coverage or raise max_attempts"
        raise ViewpointError(
            f"only {len(out)} of {n} valid viewpoints in {scene.name!r} after {attempts} draws "
            f"(coverage down to {levels[level]:.2f}; rejected: {rejected}); {hint}"
        )
    log.info("%s: %d viewpoints (%s) from %d draws, rejected %s", scene.name, n, prof.name, attempts, rejected)
    return out
