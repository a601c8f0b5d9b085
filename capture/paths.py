"""Camera paths at a fixed frame rate through a level's valid viewpoint domain.

The closed-loop VRS benchmark moves a camera through a map the way a player would and lets every
method choose rates frame after frame. :func:`camera_path` makes such a path, deterministic for a
seed: a walker on the level's floors, its eye at the player's eye height (measured from the map's
own spawn points), climbing steps of at most ``_STEP_UP`` and stepping down
ledges of at most ``_DROP`` (higher ones are walls), inside the capture's viewpoint domain
(:func:`rtp.capture.viewpoints.free_space`: flood-filled free space at least ``clearance`` from any
geometry), steering away from walls it sees coming, smoothed, resampled at ``fps`` at the profile's
speed; the view follows the direction of travel (the short way round) with a limited turn rate plus a
look-around sway.
Two profiles (:data:`PATH_PROFILES`): ``slow`` walks and turns gently, ``fast`` runs and turns
quickly. :func:`unseen_shares` renders a path and gives each frame's unseen share, the part of the
frame the previous one did not show.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rtp.scene import Camera, Scene

from .viewpoints import (
    _DROP,
    _EYE,
    _STEP_UP,
    ViewpointError,
    _count,
    _Floors,
    _real,
    _spawn_eye_height,
    _Validator,
    free_space,
)

__all__ = ["MAX_FRAMES", "MAX_SECONDS", "PATH_PROFILES", "CameraPath", "DynamicResolution", "PathFrame", "PathPlayer",
           "PathProfile", "camera_path", "composite", "frame_unseen_share", "unseen_shares"]

log = logging.getLogger("rtp.capture")


@dataclass(frozen=True)
class PathProfile:
    """How a path moves: ``speed`` (m/s), the peak rate ``turn_rate`` (degrees/s) at which the view turns
    after the direction of travel, how sharply the walker changes course (``wander``, degrees of heading
    noise per metre), and a look-around sway of ``sway`` degrees with period ``sway_period``
    seconds on top of the heading (and 0.3 ``sway`` in pitch, 1.7 times slower). The sway turns the view by
    up to ``2 pi sway / sway_period`` degrees/s more: the view's peak yaw rate is 55 degrees/s on ``slow``
    and 338 on ``fast``."""

    name: str
    speed: float
    turn_rate: float
    wander: float
    sway: float
    sway_period: float


#: ``slow``: walking pace and gentle turns; ``fast``: running and quick turns.
PATH_PROFILES: dict[str, PathProfile] = {
    "slow": PathProfile("slow", speed=1.5, turn_rate=45.0, wander=8.0, sway=8.0, sway_period=5.0),
    "fast": PathProfile("fast", speed=6.0, turn_rate=240.0, wander=20.0, sway=25.0, sway_period=1.6),
}

#: The longest camera path, in frames: ten minutes at 60 frames a second (the benchmark's are 150-300).
#: Planning one takes about 0.8 ms a frame and playing it about a second a frame and method on 2 cores,
#: so a mistyped count (``--frames 1000000000``) would run for days without a word; it is refused.
MAX_FRAMES = 36_000
#: The longest camera path in time, seconds (ten minutes): at a low ``fps`` a few frames walk far (at
#: 0.01 frames a second ten frames asked for a 5 km walk, and failed after 13 s; at 1e-10, for ever).
MAX_SECONDS = 600.0

_STEP = 0.25  # metres per walker step
_LOOK = 2.0  # metres of free space the walker wants ahead


@dataclass
class CameraPath:
    """A camera path: ``cameras`` at ``fps`` frames per second, made by :func:`camera_path`."""

    scene: str
    profile: str
    seed: int
    fps: float
    cameras: list[Camera] = field(default_factory=list)
    eye_height: float = _EYE  #: the walker's eye above its floor, metres

    def __len__(self) -> int:
        return len(self.cameras)

    def length(self) -> float:
        """Distance travelled, metres."""
        p = np.array([c.position for c in self.cameras])
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) if len(p) > 1 else 0.0


# The fastest path profile, m/s: far past a player's run (Quake 3's 320 units/s, about 8 m/s), short of a
# walk that plans for hours (a profile's speed of inf walked for ever, 0 and a sway period of 0 made nan yaws).
_MAX_SPEED = 100.0


def _check_profile(prof: PathProfile) -> None:
    """A :class:`PathProfile` of usable numbers, or a ViewpointError saying what was expected."""
    if not isinstance(prof.name, str):
        raise ViewpointError(f"path profile name: expected a string, got {prof.name!r}")
    _real(f"path profile {prof.name!r}: speed (m/s)", prof.speed, 0.0, _MAX_SPEED, lo_open=True)
    _real(f"path profile {prof.name!r}: turn_rate (degrees/s)", prof.turn_rate, 0.0)
    _real(f"path profile {prof.name!r}: wander (degrees per metre)", prof.wander, 0.0)
    _real(f"path profile {prof.name!r}: sway (degrees)", prof.sway, 0.0, 180.0)
    _real(f"path profile {prof.name!r}: sway_period (s)", prof.sway_period, 0.0, lo_open=True)


def _smooth(a: np.ndarray, window: int) -> np.ndarray:
    """Moving average along axis 0 with edge replication (``window`` odd, >= 1)."""
    if window <= 1:
        return a.copy()
    pad = window // 2
    padded = np.concatenate([np.repeat(a[:1], pad, 0), a, np.repeat(a[-1:], pad, 0)])
    c = np.cumsum(np.concatenate([np.zeros((1, *a.shape[1:])), padded]), axis=0)
    return (c[window:] - c[:-window]) / window


def camera_path(
    scene: Scene,
    frames: int,
    profile: str | PathProfile = "slow",
    seed: int = 0,
    *,
    fps: float = 60.0,
    blockers: np.ndarray | None = None,
    voxel: float = 0.25,
    clearance: float = 0.3,
    fov_y: float = 70.0,
    max_height: float | None = 6.0,
    eye_height: float | None = None,
) -> CameraPath:
    """A ``frames``-long camera path through ``scene`` at ``fps`` (module docstring).

    Deterministic: the same scene, profile, seed and arguments give the same cameras. Every camera
    is inside the flood-filled free space, at least ``clearance`` from the geometry before smoothing and 0.9
    ``clearance`` after it (exact test),
    ``eye_height`` (default: the spawn points' own, :attr:`CameraPath.eye_height`) over a floor
    before smoothing, with nothing drawn between it and that floor, and the segment between
    consecutive cameras crosses no triangle, and each frame moves on at the profile's speed (the walk
    goes on where smoothing shortened it). Raises :class:`ViewpointError` when the scene has no free
    space for a path, or none the walker can cross for ``frames`` at the profile's speed.
    """
    prof = PATH_PROFILES.get(profile) if isinstance(profile, str) else profile
    if not isinstance(prof, PathProfile):
        raise ViewpointError(f"unknown path profile {profile!r}; expected one of {sorted(PATH_PROFILES)} or a "
                             "PathProfile")
    _check_profile(prof)
    frames, seed = _count("frames", frames, 1), _count("seed", seed)
    if frames > MAX_FRAMES:
        raise ViewpointError(f"frames: expected at most {MAX_FRAMES} (ten minutes at 60 frames a second), got {frames}")
    fps = _real("fps", fps, 0.0, lo_open=True)
    if (frames - 1) / fps > MAX_SECONDS:
        raise ViewpointError(f"fps: {frames} frames at {fps:g} frames a second last {(frames - 1) / fps:,.0f} s; expected "
                             f"a path of at most {MAX_SECONDS:.0f} s (ten minutes): more frames a second, or fewer frames")
    _real("fov_y", fov_y, 0.0, 180.0, lo_open=True, hi_open=True)
    if eye_height is not None:
        _real("eye_height (metres)", eye_height, 0.0, 10.0, lo_open=True, hi_open=True)
    tris, grid, _, cand = free_space(scene, blockers=blockers, voxel=voxel, clearance=clearance, max_height=max_height,
                                   focus=True)
    free = np.flatnonzero(cand)
    if len(free) == 0:
        raise ViewpointError(f"no free space in {scene.name!r} at {clearance} m from the geometry for a camera path")
    val = _Validator(tris)
    rng = np.random.default_rng(seed)
    floors = _Floors(grid)
    eye = float(eye_height) if eye_height is not None else _spawn_eye_height(scene, floors)

    def inside(p: np.ndarray) -> bool:
        return bool(cand[tuple(grid.index(p))])

    def stand(x: float, z: float, top: float, floor: float | None) -> tuple[np.ndarray, float] | None:
        """The camera over ``(x, z)`` standing on the highest floor at or below ``top`` (at most
        _DROP under ``floor`` when given), or None where there is none or no room for a body."""
        probe = np.array([x, top, z])
        f = floors.below(probe)
        if f is None or (floor is not None and f < floor - _DROP):
            return None
        cam = np.array([x, f + eye, z])
        if not inside(cam) or not floors.same_floor(np.array([x, min(top, cam[1]), z]), cam):
            return None
        return cam, f

    def step(p: np.ndarray, floor: float, h: float, dist: float) -> tuple[np.ndarray, float] | None:
        return stand(p[0] - math.sin(h) * dist, p[2] - math.cos(h) * dist, floor + _STEP_UP, floor)

    def ahead(p: np.ndarray, floor: float, h: float) -> float:
        n = int(_LOOK / _STEP)
        for i in range(1, n + 1):
            nxt = step(p, floor, h, _STEP)
            if nxt is None:
                return (i - 1) * _STEP
            p, floor = nxt
        return _LOOK

    t = np.arange(frames) * prof.speed / fps  # arc length of each frame, metres
    need = (frames - 1) * prof.speed / fps + 2 * _LOOK
    covered = 0.0  # the longest smoothed walk that fell short of t[-1], metres
    done = False
    for _attempt in range(20):  # another start point when a walker gets stuck at once
        for _draw in range(200):  # a free voxel, dropped onto the floor below it
            c = grid.centre(np.array([free[rng.integers(len(free))]]))[0]
            got = stand(c[0], c[2], c[1], None)
            if got is not None and val.clearance(got[0], clearance):
                break
        else:
            continue
        assert got is not None
        heading = float(rng.uniform(-math.pi, math.pi))
        pts, fl = [got[0]], [got[1]]
        stuck = 0
        goal = need  # metres of walking (steps), raised when smoothing leaves the path short
        while True:
            while (len(pts) - 1) * _STEP < goal and stuck < 50:
                heading += math.radians(float(rng.normal(0.0, prof.wander * math.sqrt(_STEP))))
                best = None
                for k in range(0, 37):  # 0, +10, -10, +20, ... degrees: the first with room ahead
                    off = math.radians(10.0 * ((k + 1) // 2) * (1 if k % 2 else -1))
                    h = heading + off
                    room = ahead(pts[-1], fl[-1], h)
                    if room >= _LOOK * 0.5:
                        best = h
                        break
                    if room > 0 and best is None:
                        best = h
                if best is None:
                    stuck += 1
                    heading += math.pi
                    continue
                got = step(pts[-1], fl[-1], best, _STEP)
                if got is None or not val.segment_clear(pts[-1], got[0]):
                    stuck += 1
                    heading += math.pi / 2
                    continue
                heading = best
                pts.append(got[0])
                fl.append(got[1])
                stuck = 0
            if (len(pts) - 1) * _STEP < goal:
                log.debug("%s: camera path walker stuck after %.1f m; starting elsewhere", scene.name,
                          (len(pts) - 1) * _STEP)
                break
            raw = np.array(pts)
            for window in (9, 5, 3, 1):  # the smoothest path whose every camera is valid
                path = _smooth(raw, window)
                seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
                s = np.concatenate([[0.0], np.cumsum(seg)])
                pos = np.stack([np.interp(t, s, path[:, i]) for i in range(3)], -1)
                ok = all(val.clearance(p, clearance * 0.9) for p in pos) and all(
                    val.segment_clear(a, b) for a, b in zip(pos[:-1], pos[1:]))
                if ok:
                    break
            else:
                if goal > need:  # (a walk made longer below: another start)
                    break
                raise ViewpointError(f"the camera path in {scene.name!r} could not be smoothed into valid cameras "
                                     f"({prof.speed / fps:.2g} m between frames at {fps:g} frames a second: at a "
                                     "higher rate they are closer)")
            # The smoothing shortens a walk that bends, most of all one pacing to and fro in a pocket of the
            # domain: a path shorter than its frames' t[-1] stood the camera still for its last frames (a slow
            # path of 300 frames in a 2.5 m room walked 1.3 m and stood for 239 frames). Walk on, up to twice
            # the metres asked for; a walk that smoothing halves is pacing: start elsewhere.
            if s[-1] >= t[-1]:
                done = True
                break
            covered = max(covered, float(s[-1]))
            if goal >= 2 * need or s[-1] < 0.5 * (len(pts) - 1) * _STEP:
                log.debug("%s: camera path walker paced %.1f m in %.1f m of walking; starting elsewhere", scene.name,
                          s[-1], (len(pts) - 1) * _STEP)
                break
            goal = min(2 * need, goal + 2 * (t[-1] - s[-1]) + _LOOK)
        if done:
            break
    else:
        raise ViewpointError(
            f"no camera path of {t[-1]:.1f} m ({frames} frames at {prof.speed:g} m/s and {fps:g} frames a second) "
            f"found in {scene.name!r} (profile {prof.name}) in 20 tries"
            + (f": the longest smoothed walk covered {covered:.1f} m, pacing to and fro" if covered else
               ": the walker found no start or got stuck each time")
            + "; expected a viewpoint domain the walker can cross (fewer frames or a slower profile walk less)")
    # heading towards the point 1 m further along the path, turned at most turn_rate degrees per
    # second, plus the sway (t / speed is each frame's time in seconds)
    look = np.stack([np.interp(t + 1.0, s, path[:, i]) for i in (0, 2)], -1) - pos[:, [0, 2]]
    target = np.degrees(np.unwrap(np.arctan2(-look[:, 0], -look[:, 1])))
    yaw = np.empty(frames)
    yaw[0] = target[0]
    limit = prof.turn_rate / fps
    for i in range(1, frames):
        turn = target[i] - yaw[i - 1]
        if abs(turn) > 180.0:  # (the unwrapped target a half turn or more ahead, after a loop or a U-turn the view
            # lagged: the short way round; it turned the long way, a whole extra turn past the direction of travel)
            turn = (turn + 180.0) % 360.0 - 180.0
        yaw[i] = yaw[i - 1] + float(np.clip(turn, -limit, limit))
    phase = float(rng.uniform(0, 2 * math.pi))
    sway = prof.sway * np.sin(2 * math.pi * t / (prof.speed * prof.sway_period) + phase)
    pitch = 0.3 * prof.sway * np.sin(2 * math.pi * t / (prof.speed * prof.sway_period * 1.7) + 2 * phase)
    cams = [Camera((float(p[0]), float(p[1]), float(p[2])), yaw=float((y + w + 180.0) % 360.0 - 180.0),
                   pitch=float(q), fov_y=fov_y) for p, y, w, q in zip(pos, yaw, sway, pitch)]
    return CameraPath(scene.name, prof.name, seed, fps, cams, eye)


def frame_unseen_share(seen: np.ndarray) -> float:
    """The unseen share of a frame: the part of its pixels the previous frame did not show, from its
    ``seen`` plane. Background counts like geometry: sky reprojects as a direction at infinity and is
    seen where the previous frame showed sky there (``sdk.reproject``), so a frame of open sky is
    seen, not new (a share over geometry pixels alone read 100% when a few new pixels of geometry
    were all a frame looking over a level's edge held)."""
    return float(1.0 - np.mean(np.asarray(seen) > 0.5))


def unseen_shares(path: CameraPath, scene: Scene, size: tuple[int, int] = (1280, 720), renderer: Any = None) -> np.ndarray:
    """Render ``path`` (the reference renderer, ``size`` = (width, height), or a loaded ``renderer``)
    and return each frame's unseen share (:func:`frame_unseen_share`; the first frame, with no history,
    counts as 1)."""
    from rtp.plugins.moderngl import Renderer

    if not isinstance(path, CameraPath):
        raise ViewpointError(f"path: expected a CameraPath (camera_path makes one), got {type(path).__name__}")
    if renderer is None and (not isinstance(size, (tuple, list)) or len(size) != 2):
        raise ViewpointError(f"size: expected (width, height) in pixels, got {size!r}")
    own = renderer is None
    r = Renderer(*size) if own else renderer
    try:
        if own:
            r.load_scene(scene)
        out, prev = [], None
        for cam in path.cameras:
            frame = r.render(cam, prev)
            out.append(frame_unseen_share(frame.seen) if prev is not None else 1.0)
            prev = frame
        return np.array(out)
    finally:
        if own:
            r.release()


@dataclass
class PathFrame:
    """One frame of a played path: ``frame`` (the renderer's :class:`~rtp.plugins.moderngl.Frame`:
    G-buffers, every uniform rate's final image, motion; not its reprojection, whose ``reprojected``
    and ``seen`` are 0: each method reprojects its own history) and where each of its pixels was in the
    previous frame (``rows``, ``cols``: top-left indices, ``seen``: 1 where that pixel passed the
    depth test; all 0 on the first frame). ``reproject(image)`` fetches any image of the previous
    frame the way the renderer's reprojection does; ``source_size``, the previous frame's ``(H, W)`` (None on
    the first frame, or where not known), is the size that image must have."""

    index: int
    frame: Any
    rows: np.ndarray
    cols: np.ndarray
    seen: np.ndarray
    _gather: dict[Any, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict, repr=False, compare=False)
    _planes: dict[str, np.ndarray] = field(default_factory=dict, repr=False, compare=False)
    #: Terms the methods compute from this frame's motion and ``seen`` alone, shared among them (the
    #: classic methods' per-tile speeds: ``rtp.evaluate.Frame.terms``).
    terms: dict[Any, np.ndarray] = field(default_factory=dict, repr=False, compare=False)
    #: The previous frame's ``(H, W)``, the size of every image :meth:`reproject` takes (None: not known).
    source_size: tuple[int, int] | None = None

    def reproject(self, image: np.ndarray) -> np.ndarray:
        """``image`` (the previous frame's, ``(H', W', C)`` or one plane ``(H', W')``, at its own size)
        reprojected into this frame (``(H, W, C)`` or ``(H, W)``); 0 where unseen. An image of another size
        than the previous frame's (:attr:`source_size`; where not known, one too small for the fetch
        positions) is a ``ParameterError``: its pixels are not the ones the positions index."""
        from rtp.sdk import ParameterError

        image = np.asarray(image, np.float32)
        if image.ndim not in (2, 3):
            raise ParameterError(f"image: expected the previous frame's (H, W, C) image or (H, W) plane, got shape "
                                 f"{image.shape}", "image")
        key = image.shape[:2]
        cached = self._gather.get(key)
        if cached is None:  # the flat source index and the unseen pixels, once per frame (every method reuses them)
            # (an image of another size was fetched from in silence: a larger one at the wrong pixels, a smaller one's
            # indices clipped into it; under dynamic resolution, the current frame's size given for the previous one's)
            if self.source_size is not None:
                need, wrong, more = tuple(self.source_size), key != tuple(self.source_size), ""
            else:  # (the previous frame's size not known: at least what the fetch positions index)
                need = (int(self.rows.max()) + 1, int(self.cols.max()) + 1) if self.rows.size else (0, 0)
                wrong, more = key[0] < need[0] or key[1] < need[1], " or more"
            if wrong:
                raise ParameterError(f"image: expected the previous frame's image, {need[1]}x{need[0]} pixels{more} "
                                     f"(shape {need}), got {key[1]}x{key[0]} (shape {image.shape})", "image")
            cached = ((self.rows * image.shape[1] + self.cols).ravel(), np.flatnonzero(~(self.seen > 0)))
            self._gather[key] = cached
        index, unseen = cached
        if image.ndim == 2:  # (one plane: it was reshaped as rows of width-long pixels, a ValueError)
            return self.reproject(image[..., None])[..., 0]
        # The indices are in range by construction: mode="clip" only spares numpy's bounds check (2.5x
        # faster at 720p), and zeroing the unseen pixels by index beats multiplying every channel by a
        # broadcast mask; both give exactly the values of the gather-and-multiply (displayed values are
        # finite and >= 0).
        out = np.take(image.reshape(-1, image.shape[-1]), index, axis=0, mode="clip")
        out[unseen] = 0.0
        return out.reshape(self.seen.shape + image.shape[2:])  # (this frame's size: dynamic resolution)

    def plane(self, name: str) -> np.ndarray:
        """The frame's channel ``name`` (``Frame.channel``) as float32, computed once per frame: the
        methods of a closed loop that read the same G-buffer planes share them."""
        got = self._planes.get(name)
        if got is None:
            got = np.ascontiguousarray(self.frame.channel(name), np.float32)
            self._planes[name] = got
        return got


def composite(colour: dict[str, np.ndarray], rates: np.ndarray, tile: int) -> np.ndarray:
    """A VRS image put together from a frame's uniform-rate images (``Frame.colour``): every tile
    taken from the final image of the rate chosen for it. Before post-processing this is exactly
    what per-tile VRS shades (rate blocks never cross a tile); after it, pixels next to a tile of
    another rate differ slightly from FXAA run over the VRS image (``Renderer.shade_rates``).
    ``rates`` must be the frame's grid of ``tile``-pixel tiles (``sdk.tile_grid``, partial edge tiles
    included), as ``Renderer.shade_rates`` wants it: another grid is a ``ParameterError``, and so are a
    ``tile`` that is no multiple of 4 (``shade_rates`` refuses it too: a 4x4 block would straddle two
    tiles) and a chosen rate whose image is missing from ``colour`` or of another shape than ``"1x1"``'s."""
    from rtp import sdk

    if not isinstance(colour, Mapping) or "1x1" not in colour:
        raise sdk.ParameterError(f"colour: expected a frame's uniform-rate images by rate name (Frame.colour), with "
                                 f"'1x1', got {type(colour).__name__}"
                                 + (f" of {sorted(map(str, colour))}" if isinstance(colour, Mapping) else ""), "colour")
    ref = np.asarray(colour["1x1"])
    if ref.ndim not in (2, 3):
        raise sdk.ParameterError(f"colour: expected (H, W, C) images or (H, W) planes, got '1x1' of shape {ref.shape}",
                                 "colour")
    h, w = ref.shape[:2]
    grid = sdk.tile_grid(h, w, tile)  # (a tile that is no positive integer: its ParameterError)
    tile = int(tile)
    if tile % 4:  # (the frame-aligned 4x4 blocks of colour["4x4"] straddled 6-pixel tiles: an image no VRS shades)
        raise sdk.ParameterError(f"tile_size: expected a multiple of 4 pixels (the largest rate, 4x4, whole in every "
                                 f"tile, as Renderer.shade_rates wants it), got {tile}", "tile_size")
    rates = np.asarray(rates)
    if rates.shape != grid:  # (a grid of other tiles: a larger one was cropped to its top-left corner in silence)
        raise sdk.ParameterError(f"rates: expected the {grid[1]}x{grid[0]} tile grid {grid} of {tile}-pixel tiles "
                                 f"over a {w}x{h} frame, got shape {rates.shape}", "rates")
    known = sorted(sdk.RATE_CODES.values())
    # (in range before bincount: a stray code of 10**12 asked it for 7 TiB, a MemoryError, not this error)
    ok = rates.dtype.kind in "iu" and (rates.size == 0 or 0 <= int(rates.min()) <= int(rates.max()) <= known[-1])
    counts = np.bincount(rates.ravel(), minlength=known[-1] + 1) if ok else np.zeros(0, np.intp)
    if not ok or np.any(np.delete(counts, known)):
        got = sorted({int(c) for c in np.unique(rates)} - set(known)) if rates.dtype.kind in "iu" else rates.dtype
        raise sdk.ParameterError(f"rates: expected the rate codes of {', '.join(sdk.ALL_RATES)} ({known}), got {got}",
                                 "rates")
    for used in np.flatnonzero(counts):  # (an image of another size with as many values, (W, H, C) for (H, W, C), was
        # reshaped into tiles in silence: other pixels; a missing one was a bare KeyError)
        name = sdk.RATE_NAMES[int(used)]
        shape = np.shape(colour[name]) if name in colour else None
        if shape != ref.shape:
            raise sdk.ParameterError(f"colour[{name!r}]: expected an image of the shape of colour['1x1'], {ref.shape}, "
                                     f"for the tiles at {name}, got " + ("none" if shape is None else f"shape {shape}"),
                                     "colour")
    out = np.empty(ref.shape, ref.dtype)
    th, tw = h // tile, w // tile
    if h % tile or w % tile:  # ragged edge tiles: per pixel
        per_pixel = np.repeat(np.repeat(rates, tile, 0), tile, 1)[:h, :w]
        for rate, code in sdk.RATE_CODES.items():
            m = per_pixel == code
            if m.any():
                out[m] = colour[rate][m]
        return out
    # whole tiles: the commonest rate's image copied whole (one contiguous copy), then every other tile's
    # block from its rate's image (a gather and a scatter per tile: about twice a plain copy's time a byte)
    common = int(np.argmax(counts))
    np.copyto(out, colour[sdk.RATE_NAMES[common]])
    blocks = out.reshape(th, tile, tw, tile, -1)
    for rate, code in sdk.RATE_CODES.items():
        if code == common:
            continue
        ys, xs = np.nonzero(rates == code)
        if ys.size:
            src = np.ascontiguousarray(colour[rate]).reshape(th, tile, tw, tile, -1)
            blocks[ys, :, xs, :] = src[ys, :, xs, :]
    return out


@dataclass(frozen=True)
class DynamicResolution:
    """An engine's dynamic resolution as a schedule for :class:`PathPlayer`: the frames' render resolution
    cycles through ``scales`` of the full size (each in (0, 1]: of the width and of the height), each held
    ``every`` frames. ``DynamicResolution((1.0, 0.75), 30)`` draws frames 0-29 at the full size, 30-59 at
    three quarters of it, 60-89 at the full size again, and so on; ``DynamicResolution.parse("1,0.75@30")``
    is the same (``rtp play --dynamic-resolution``). A frame's size is the full size times its scale,
    rounded, at least 16 pixels a side (a side of the full size under 16 pixels: that side, never more than
    the full size; :meth:`size`). Bad values are a ``ParameterError``."""

    scales: tuple[float, ...]
    every: int

    def __post_init__(self) -> None:
        from rtp.sdk import ParameterError

        def scale(v: Any) -> bool:
            if not isinstance(v, (int, float, np.integer, np.floating)) or isinstance(v, (bool, np.bool_)):
                return False
            try:
                return math.isfinite(float(v)) and 0.0 < float(v) <= 1.0
            except OverflowError:  # (an int past float's range)
                return False

        scales = self.scales
        ok = isinstance(scales, (tuple, list)) and len(scales) > 0 and all(scale(v) for v in scales)
        if not ok:
            given = (",".join(f"{v:g}" if isinstance(v, float) else repr(v) for v in scales)
                     if isinstance(scales, (tuple, list)) else repr(scales))  # (2@10: "2", not "(2.0,)")
            raise ParameterError(f"dynamic resolution: expected scales of the full size, numbers in (0, 1], got "
                                 f"{given}", "scales")
        if isinstance(self.every, (bool, np.bool_)) or not isinstance(self.every, (int, np.integer)) or self.every < 1:
            raise ParameterError(f"dynamic resolution: expected every, the frames each scale is held, an integer >= 1, "
                                 f"got {self.every!r}", "every")
        object.__setattr__(self, "scales", tuple(float(v) for v in scales))
        object.__setattr__(self, "every", int(self.every))

    @classmethod
    def parse(cls, text: str) -> DynamicResolution:
        """``"SCALES@FRAMES"``: comma-separated scales, each held FRAMES frames (``"1,0.75@30"``)."""
        from rtp.sdk import ParameterError

        scales, at, every = str(text).partition("@")
        try:
            values = tuple(float(v) for v in scales.split(","))
            frames = int(every)
        except ValueError:
            values, frames = (), 0
        if not at or not values:
            raise ParameterError(f"dynamic resolution: expected SCALES@FRAMES, scales of the full size in (0, 1] "
                                 f"held FRAMES frames each, as 1,0.75@30; got {text!r}", "dynamic_resolution")
        return cls(values, frames)

    def size(self, index: int, full: tuple[int, int]) -> tuple[int, int]:
        """``(width, height)`` of frame ``index`` on a path drawn at ``full`` = ``(width, height)``."""
        scale = self.scales[(index // self.every) % len(self.scales)]
        # (16 pixels or the full side, the smaller: a 12x8 path drew 16x16 frames at scale 1, past its largest size)
        w, h = full[0], full[1]
        return max(min(16, w), round(w * scale)), max(min(16, h), round(h * scale))

    def sizes(self, full: tuple[int, int]) -> list[tuple[int, int]]:
        """Every size the schedule draws at ``full``, in the schedule's order, once each."""
        return list(dict.fromkeys(self.size(i * self.every, full) for i in range(len(self.scales))))


def _source_across_sizes(frame: Any, prev: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rows, cols, seen)`` of :class:`PathFrame` for a ``frame`` rendered at another size than ``prev``,
    the frame before it (dynamic resolution): where each of its pixels was in ``prev``'s pixels, through
    ``rtp.sdk.reproject`` (the runtime's reprojection, with its disocclusion test and tolerance) of an image
    of ``prev``'s own pixel indices; 0 where unseen. The renderer's own GL reprojection
    (``Renderer.reprojection_source``) takes frames of its one size."""
    from rtp import sdk

    ph, pw = prev.depth.shape
    h, w = frame.depth.shape
    rows, cols = np.indices((ph, pw), dtype=np.float32)
    index = np.stack([rows, cols], -1)  # (float32 holds each side's indices exactly: below 2**24)
    fetched, seen = sdk.reproject(index, prev.depth, frame.depth, frame.camera.view(), frame.camera.projection(w / h),
                                  prev.camera.view_projection(pw, ph))
    return fetched[..., 0].astype(np.intp), fetched[..., 1].astype(np.intp), seen


class PathPlayer:
    """Plays a :class:`CameraPath` through the reference renderer for closed-loop VRS runs
    (``rtp play``, :func:`rtp.evaluate.play`): :meth:`frames` renders each camera once (the
    G-buffers and every uniform rate), and while a frame is current :meth:`shade` shades it with a
    per-tile rate image, as an engine with VRS would display it. Any number of methods share one
    render per frame, each keeping its own displayed frames as history (``PathFrame.reproject``).
    ``exact=False`` shades by :func:`composite` instead (several times faster on a CPU; differs from
    the renderer's VRS only by FXAA next to tiles of another rate). ``dynamic`` (a
    :class:`DynamicResolution`) draws each frame at its schedule's size of ``size`` (the largest), the one
    renderer resized (``Renderer.resize``: its scene and shadow map kept, as an engine's dynamic resolution
    keeps them; a renderer given is resized back to its own size by :meth:`close`); a frame of another
    size than the one before reprojects from the earlier frame's pixels (``sdk.reproject`` of its pixel
    indices), so each method's history is the frame it displayed, at the size it was drawn."""

    def __init__(self, scene: Scene, size: tuple[int, int] = (1280, 720), *, renderer: Any = None,
                 exact: bool = True, dynamic: DynamicResolution | None = None) -> None:
        from rtp.plugins.moderngl import Renderer
        from rtp.sdk import ParameterError

        if dynamic is not None and not isinstance(dynamic, DynamicResolution):
            raise ParameterError(f"dynamic: expected a DynamicResolution (or None), got {type(dynamic).__name__}",
                                 "dynamic")
        self.exact = bool(exact)
        self.dynamic = dynamic
        self._current: Any = None
        self._own = renderer is None
        self.renderer = Renderer(*size) if self._own else renderer
        if self._own:
            try:
                self.renderer.load_scene(scene)
            except BaseException:  # (the renderer made here is released: the caller never gets it to close)
                self.renderer.release()
                raise
        self.size = (self.renderer.width, self.renderer.height)

    def frames(self, path: CameraPath) -> Any:
        """Yield a :class:`PathFrame` per camera of ``path``."""
        prev = None
        for i, cam in enumerate(path.cameras):
            size = self.size if self.dynamic is None else self.dynamic.size(i, self.size)
            self.renderer.resize(*size)  # (dynamic resolution; the same size is a no-op)
            # the previous camera for the motion vectors, not the previous frame: every method reprojects
            # its own history through reprojection_source, so the renderer's reprojection of the
            # full-rate frame (Frame.reprojected and .seen, left 0 here) would be read by none
            frame = self.renderer.render(cam, prev_camera=prev.camera if prev is not None else None)
            self._current = frame
            h, w = size[1], size[0]
            if prev is None:
                zeros = np.zeros((h, w), np.intp)
                yield PathFrame(i, frame, zeros, zeros, np.zeros((h, w), np.float32))
            elif prev.depth.shape == (h, w):
                rows, cols, seen = self.renderer.reprojection_source(prev.depth, prev.camera)
                yield PathFrame(i, frame, rows, cols, seen, source_size=prev.depth.shape)
            else:  # (dynamic resolution: the previous frame at its own size)
                yield PathFrame(i, frame, *_source_across_sizes(frame, prev), source_size=prev.depth.shape)
            prev = frame

    def shade(self, rates: np.ndarray, tile_size: int) -> np.ndarray:
        """The current frame shaded per tile at ``rates`` (uint8 codes), tone-mapped and post-processed. Before
        :meth:`frames` has given a frame there is none to shade: a ``RendererError``, in either shading."""
        if not self.exact:
            if self._current is None:  # (an AttributeError of None's .colour; the renderer's pass says this)
                from rtp.plugins.moderngl import RendererError

                raise RendererError("shade works on the current frame of frames(); iterate frames() first")
            return composite(self._current.colour, rates, tile_size)
        return np.asarray(self.renderer.shade_rates(rates, tile_size))

    def close(self) -> None:
        if self._own:
            self.renderer.release()
        elif self.dynamic is not None and (self.renderer.width, self.renderer.height) != self.size:
            self.renderer.resize(*self.size)  # (the caller's renderer back at its size)

    def __enter__(self) -> PathPlayer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
