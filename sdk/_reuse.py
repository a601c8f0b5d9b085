"""Prediction reuse: run the network every k-th frame and carry its per-tile estimates in between.

The paper's future work, measured in docs/results.md ("Prediction reuse"). On the frames between
network runs every kept pixel (one of every ``step`` per axis) carries where its surface was when
the network last saw it, warped frame by frame with the reprojection's fetch positions, and so the
index of the estimate it had there; each tile then reduces the estimates its pixels carry
(``REUSE_REDUCTIONS``). Warping per pixel rather than the per-tile values keeps coarse regions from
dilating frame after frame, and carrying the surface's position (not only its index) keeps the
kept pixels' spacing from adding a rounding error every frame. Tiles mostly unseen since then are
shaded at 1x1 or predicted afresh on crops around them (``REUSE_UNSEEN``).

This module is the numpy reference; an engine would warp the positions on the GPU, where it is one
gather per kept pixel. numpy only.
"""

from __future__ import annotations

import functools
import inspect
import math
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ._channels import BLOCK_CELL, BLOCK_EPS, BLOCK_RATES
from ._errors import InputChannelError, InputDtypeError, InputShapeError, ParameterError
from ._rates import (
    RateLike,
    check_engine_rates,
    check_saving,
    check_threshold,
    resolve_allowed,
    select_rates,
    select_rates_for_saving,
)
from ._reproject import _real, _shape
from ._tiles import padded_size, split_tiles, tile_grid

if TYPE_CHECKING:
    from ._predictor import ShadingRatePredictor

__all__ = ["MAX_RESCALE", "REUSE_CARRIES", "REUSE_REDUCTIONS", "REUSE_UNSEEN", "PredictionReuse", "fetch_from_motion"]

#: How a tile of a frame between network runs reduces the estimates its pixels carry. ``mean`` is
#: the default: on the validation maps it kept 92.7% / 94.7% of k = 1's saving at 2% / 5% failing
#: tiles (worst 86.8% / 91.8%, upper 90.3% / 93.2%; docs/results.md "Prediction reuse").
REUSE_REDUCTIONS = {
    "worst": "the worst estimate over the tile's pixels (the most conservative)",
    "mean": "the mean over the tile's pixels (each source tile weighted by the pixels it gives)",
    "upper": "the upper quartile over the tile's pixels (PSNR: the lower; between the mean and the worst)",
}

#: What a reused frame carries from the frame the network ran on (``PredictionReuse(carry=...)``).
REUSE_CARRIES = {
    "estimates": "the network's per-tile estimates (any model)",
    "features": "the trunk's per-tile features, and the tail runs on each frame (a model that splits: "
                "ShadingRatePredictor.splits)",
}
#: What prediction reuse does with a tile whose surface the network did not see (more than
#: ``unseen_fraction`` of its pixels unknown).
REUSE_UNSEEN = {
    "full": "shade it at 1x1 (costs nothing, saves nothing there)",
    "fresh": "run the network on crops around those tiles only (margin tiles of context each side); "
             "when the crops would cover more than half the frame, on the whole frame",
}

#: The most tiles of context :func:`context_tiles` looks for around a fresh crop.
MAX_MARGIN = 8
#: The crops' share of the frame above which ``fresh`` runs the network on the whole frame instead
#: (and restarts the interval from it).
FRESH_FULL = 0.5

#: ``x`` for :meth:`PredictionReuse.predict`: the inputs, or a function that builds them for a
#: window ``(rows, cols)`` of the frame (called only where the frame's planes are read); a function
#: with a ``channels`` parameter is asked for the planes read there alone (``channels=`` their names).
Inputs = np.ndarray | Callable[..., np.ndarray]


def _takes_channels(fn: object) -> bool:
    """Whether an input function has a ``channels`` parameter (it may be passed by keyword)."""
    try:
        p = inspect.signature(fn).parameters.get("channels")  # type: ignore[arg-type]
    except (TypeError, ValueError):  # a builtin or a callable object without a signature
        return False
    return p is not None and p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)


#: The fewest kept pixels per tile and axis the default step leaves (4: 16 of a tile's pixels).
KEPT_PER_TILE = 4


def default_step(tile: int) -> int:
    """The pixels per axis the carry keeps one of by default: the largest divisor of the tile that
    leaves at least :data:`KEPT_PER_TILE` kept pixels per tile and axis (4 for 16-pixel tiles, 2 for
    8, 1 for odd tiles up to 7). On the validation maps every fourth pixel of 16-pixel tiles kept
    as much of every frame's saving as every second to within 1.1 points at 1-5% failing tiles, at
    about half the cost (docs/results.md "Prediction reuse that follows the surfaces")."""
    return max(d for d in range(1, tile + 1) if tile % d == 0 and tile // d >= KEPT_PER_TILE) if tile >= 4 else 1


def _check_step(step: int | None, tile: int) -> int:
    """``step`` (None: :func:`default_step`) as an int that divides ``tile``, or a ParameterError."""
    if step is None:
        return default_step(tile)
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 1 or tile % step:
        divisors = [d for d in range(1, tile + 1) if tile % d == 0]
        raise ParameterError(f"step: expected None (one pixel of every {default_step(tile)} per axis) or a divisor of the "
                             f"model's {tile}-pixel tile ({', '.join(map(str, divisors))}), got {step!r}", "step")
    return int(step)


@functools.lru_cache(maxsize=8)
def _tile_index_map(shape: tuple[int, int], tile: int, s: int) -> np.ndarray:
    h, w = shape
    _, tw = tile_grid(h, w, tile)
    ph, pw = padded_size(h, w, tile)
    ys, xs = np.arange(0, ph, s), np.arange(0, pw, s)
    out = ((ys[:, None] // tile) * tw + xs[None, :] // tile).astype(np.int32)  # 32 bits: half the memory traffic
    out.setflags(write=False)  # shared between calls: read-only
    return out


def tile_index_map(shape: tuple[int, int], tile: int, step: int | None = None) -> np.ndarray:
    """Per kept pixel (every ``step``-th per axis, default :func:`default_step`, padded to whole
    tiles) the index of its tile (read-only: one array per frame size, built once)."""
    return _tile_index_map((int(shape[0]), int(shape[1])), int(tile), _check_step(step, int(tile)))


#: A place is packed into one int32, ``row << PLACE_BITS | column`` (one gather instead of two).
PLACE_BITS = 16


@dataclass(frozen=True)
class Track:
    """What each kept pixel of a frame carries between network runs (int32 arrays on the kept-pixel
    grid of :func:`tile_index_map`): ``index``, the entry of the estimates its surface is in, and
    ``place``, where that surface was (``row << PLACE_BITS | column``) on frame ``gen`` of the frames
    the entries were predicted on (0: the network's whole-frame run; g: the g-th frame of fresh crops
    since); both -1 where unknown. ``lut`` is ``(generations, tiles)``: the entry of each tile of each
    of those frames (-1: none there). ``shape`` is ``(H, W)`` of those frames, whose pixels the places
    are in and whose tiles ``lut`` lists: one size for all. ``origin`` is the size of the frame the
    network ran on whole, whose tiles are the first entries in row-major order (sky takes the entry of
    its tile at the same place on the screen); None: ``shape``. ``cell`` is what a row of ``lut``
    lists: None, the tiles of ``shape``; a step ``s``, its kept pixels (the grid of
    :func:`tile_index_map`, one of every ``s`` per axis). On a frame of another size (dynamic
    resolution) :class:`PredictionReuse` moves the track onto that frame: each kept pixel keeps the
    entry its surface carries and its place where it is now, and ``lut``'s one row lists each kept
    pixel's entry (``cell`` the step), so that every surface carries its own entry from there on and,
    as at one size, a place moved by offsets smaller than a step finds the entry it had (the fetched
    kept pixel's own entry instead moved the estimates a whole step a frame against a pan of a pixel a
    frame)."""

    index: np.ndarray
    place: np.ndarray
    gen: np.ndarray
    lut: np.ndarray
    shape: tuple[int, int]
    origin: tuple[int, int] | None = None
    cell: int | None = None


@functools.lru_cache(maxsize=8)
def _start_places(shape: tuple[int, int], tile: int, s: int) -> np.ndarray:
    h, w = shape
    gh, gw = _tile_index_map(shape, tile, s).shape
    ys = np.minimum(np.arange(gh, dtype=np.int32) * s, h - 1)
    xs = np.minimum(np.arange(gw, dtype=np.int32) * s, w - 1)
    out = (ys[:, None] << PLACE_BITS) | xs[None, :]
    out.setflags(write=False)
    return out


def _scaled_places(shape: tuple[int, int], prev: tuple[int, int], tile: int, s: int) -> tuple[np.ndarray, np.ndarray]:
    """Each kept pixel of a frame of ``shape`` at the same place on the screen in a frame of ``prev``'s size
    (the pixel its centre falls in): that frame's tile there and the place, packed as a track's."""
    (h, w), (ph, pw) = shape, prev
    gh, gw = _tile_index_map(shape, tile, s).shape
    ys = np.minimum(np.arange(gh) * s, h - 1)
    xs = np.minimum(np.arange(gw) * s, w - 1)
    py = np.minimum(((2 * ys + 1) * ph) // (2 * h), ph - 1).astype(np.int32)  # (exact: integers)
    px = np.minimum(((2 * xs + 1) * pw) // (2 * w), pw - 1).astype(np.int32)
    ptw = tile_grid(ph, pw, tile)[1]
    at = (py // tile)[:, None] * ptw + (px // tile)[None, :]
    return at.astype(np.int32), (py[:, None] << PLACE_BITS) | px[None, :]


def check_track_size(shape: tuple[int, int]) -> None:
    """An :class:`InputShapeError` for a frame too large for a track's packed places (:data:`PLACE_BITS`):
    32768 rows or 65536 columns."""
    h, w = int(shape[0]), int(shape[1])
    if h >= 1 << (31 - PLACE_BITS) or w >= 1 << PLACE_BITS:
        raise InputShapeError(f"prediction reuse takes frames of fewer than {1 << (31 - PLACE_BITS)} rows and "
                              f"{1 << PLACE_BITS} columns, got {w}x{h}", (h, w), "(H, W)")


def start_track(shape: tuple[int, int], tile: int, step: int | None = None) -> Track:
    """The track of the frame the network ran on: each kept pixel in its own tile, at its own place."""
    h, w = int(shape[0]), int(shape[1])
    check_track_size((h, w))
    s = _check_step(step, tile)
    index = tile_index_map((h, w), tile, s)
    th, tw = tile_grid(h, w, tile)
    return Track(index, _start_places((h, w), int(tile), s), np.zeros(index.shape, np.int32),
                 np.arange(th * tw, dtype=np.int32)[None], (h, w))


def _kept(a: np.ndarray, s: int, gh: int, gw: int, dtype: type | None = None) -> np.ndarray:
    """``a`` at the kept pixels: row ``min(i * s, H - 1)``, column ``min(j * s, W - 1)`` (the padding
    repeats the last row and column), as ``dtype`` (None: ``a``'s). A strided view where the frame is
    whole tiles and the dtype ``a``'s."""
    h, w = a.shape
    view = a[::s, ::s]
    ny, nx = view.shape
    if (ny, nx) == (gh, gw):
        return view if dtype is None else view.astype(dtype)
    out = np.empty((gh, gw), a.dtype if dtype is None else dtype)  # a strided copy and the padding: a fifth of np.ix_'s time
    out[:ny, :nx] = view
    out[:ny, nx:] = a[::s, w - 1:w]
    out[ny:, :nx] = a[h - 1, ::s]
    out[ny:, nx:] = a[h - 1, w - 1]
    return out


def carry_estimates(est: np.ndarray, track: Track, rows: np.ndarray, cols: np.ndarray, seen: np.ndarray,
                    background: np.ndarray | None, tile: int, higher_is_better: bool, unseen_fraction: float,
                    reduce: str = "mean", step: int | None = None) -> tuple[np.ndarray, Track, np.ndarray]:
    """Carry the estimates ``est`` into this frame.

    ``est`` is ``(outputs, entries)``: the tiles of the frame the network last ran on in row-major
    order, then any tiles predicted afresh since. ``track`` is what each kept pixel of the previous
    frame carries (:class:`Track`), that frame of the size of the track's (its ``shape``). This frame may
    be of another size (dynamic resolution): its tiles are its own. Every kept pixel of this frame fetches
    the pixel it was at in the previous one (``rows``, ``cols``: top-left pixel indices of the previous
    frame, inside it); its surface was where the kept pixel at or above-left of that one (one of every
    ``step`` per axis) was, moved by the fetched pixel's offset from it, so it takes the entry of the tile
    there, or of the kept pixel there on a track moved onto a frame of another size (``track.cell``;
    the fetched kept pixel's own entry where that tile or kept pixel has none). Unseen pixels (``seen`` 0) get -1,
    background pixels the tile at their own position (the same place on the screen, on the grid of the
    frame the network ran on whole: ``track.origin``). Each tile then takes the worst, the mean or the
    upper quartile (towards the worse side) of the estimates over its known pixels, and tiles with more
    than ``unseen_fraction`` unknown the worst value there is (1x1): of its kept pixels inside the frame,
    a partial edge tile's padding being none of its pixels. Returns the ``(outputs, tile rows,
    tile cols)`` estimates, this frame's track and the tiles given the worst value for want of known
    pixels, all on this frame's tiles (on a frame of another size the track's places stay in the
    previous frame's pixels: move the track onto this frame, as :class:`PredictionReuse` does,
    :class:`Track`). ``step``: a divisor of ``tile`` (None: :func:`default_step`), as ``track`` was
    built."""
    h, w = seen.shape
    th, tw = tile_grid(h, w, tile)
    s = _check_step(step, tile)
    own = tile_index_map((h, w), tile, s)
    gh, gw = own.shape
    ph, pw = track.shape  # the previous frame's, whose kept pixels and tiles the track holds (this one's but
    pth, ptw = tile_grid(ph, pw, tile)  # where dynamic resolution changed the size)
    pgw = track.index.shape[1]
    r, c = _kept(rows, s, gh, gw, np.int32), _kept(cols, s, gh, gw, np.int32)
    # the previous frame's kept pixel at or above-left of the fetched one, as a flat index (a 1-D take is 3x a
    # 2-D gather; rows and cols lie in the frame, so r // s < gh; a shift is a fifth of a division's time)
    if s & (s - 1) == 0:
        shift = s.bit_length() - 1
        ky, kx = r >> shift, c >> shift
    else:
        ky, kx = r // s, c // s
    k = ky * pgw + kx
    # where the fetched pixel's surface was: the kept pixel's place plus the offset (0 .. s - 1 each way)
    # from it, so that the rounding to kept pixels does not add up frame after frame
    place = np.take(track.place, k)
    known = (_kept(seen, s, gh, gw) > 0) & (place >= 0)
    place += ((r - ky * s) << PLACE_BITS) + (c - kx * s)
    # the tile there (past the last row or column only by the padding's offset)
    if tile & (tile - 1) == 0:
        bits = tile.bit_length() - 1
        ty, tx = place >> (PLACE_BITS + bits), (place & ((1 << PLACE_BITS) - 1)) >> bits
    else:
        ty, tx = (place >> PLACE_BITS) // tile, (place & ((1 << PLACE_BITS) - 1)) // tile
    cell = np.minimum(ty, pth - 1) * ptw + np.minimum(tx, ptw - 1)
    cells = pth * ptw
    if track.cell is not None:  # lut lists the kept pixels of a frame of another size: the one at or above-left there
        pgh = track.index.shape[0]
        cy, cx = (place >> PLACE_BITS) // track.cell, (place & ((1 << PLACE_BITS) - 1)) // track.cell
        cell, cells = np.minimum(cy, pgh - 1) * pgw + np.minimum(cx, pgw - 1), pgh * pgw
    if track.cell is None and len(track.lut) == 1 and track.lut[0, 0] >= 0:  # only the whole-frame run's tiles: the
        gen = track.gen if track.gen.shape == (gh, gw) else np.zeros((gh, gw), track.gen.dtype)  # tile is the entry
        new = np.where(known, cell, -1)
    else:  # and the tiles predicted afresh since, each frame of them a generation; none there: the kept pixel's
        gen = np.take(track.gen, k)
        moved = np.take(track.lut, gen * cells + np.where(known, cell, 0))
        new = np.where(known, np.where(moved >= 0, moved, np.take(track.index, k)), -1)
    place = np.where(known, place, -1)
    if background is not None:  # the estimate at its own screen position, on the whole-frame run's grid
        sky = _kept(background, s, gh, gw) > 0.5
        if sky.any():
            origin = track.origin or track.shape
            at = own if (h, w) == origin else _scaled_places((h, w), origin, tile, s)[0]
            there = _start_places((h, w), tile, s) if (h, w) == (ph, pw) else _scaled_places((h, w), (ph, pw), tile, s)[1]
            new = np.where(sky, at, new)
            place = np.where(sky, there, place)
            gen = np.where(sky, 0, gen)
    k = tile // s
    # A partial edge tile's kept pixels past the frame's last row or column are the padding (_kept repeats the last
    # row and column there): no pixels of the tile. They are left out of its reduction and of its unseen share, as a
    # partial tile covers only its real pixels (tile_extents); counted, they repeated the last row's and column's
    # estimates and unseen pixels in the tile's mean and unseen share (a 40x24 frame's last tiles: half their kept
    # pixels padding, all of them copies of the edge).
    inside_y, inside_x = np.arange(gh) * s < h, np.arange(gw) * s < w
    counted = new
    if not (inside_y.all() and inside_x.all()):
        counted = np.where(inside_y[:, None] & inside_x[None, :], new, -1)
    real = np.outer(inside_y.reshape(th, k).sum(axis=1), inside_x.reshape(tw, k).sum(axis=1))  # kept pixels per tile
    known = counted >= 0
    # known pixels per tile (rows first: a column of a tile sums to at most k, 16 bits hold it)
    count = known.reshape(th, k, gw).sum(axis=1, dtype=np.int16).reshape(th, tw, k).sum(axis=-1, dtype=np.int64)
    flat = est.reshape(len(est), -1)
    if reduce == "mean":  # per tile, the sums over its known pixels; float64 sums of a tile's float32 values are exact
        # entries as rows (unknown, -1: the zero row appended), so one gather fetches all of a pixel's values
        # together (1.6x faster than a gather per output for the 16 features of a split network's trunk)
        vals = np.take(np.pad(flat.T, ((0, 1), (0, 0))), counted, axis=0).reshape(th, k, gw, len(est))
        # a tile's k rows first (whole rows add as vectors), then its k columns, each an in-place add in float64
        # (the same exact sums as numpy's sum with dtype float64, in 0.6 of its time)
        rows = vals[:, 0].astype(np.float64)
        for i in range(1, k):
            rows += vals[:, i]
        cols = rows.reshape(th, tw, k, len(est))
        total = cols[:, :, 0].copy()
        for j in range(1, k):
            total += cols[:, :, j]
        with np.errstate(invalid="ignore", divide="ignore"):  # no known pixel: nan, the worst below
            out = np.moveaxis(total, -1, 0) / count
    else:
        fill = np.inf if higher_is_better else -np.inf  # neutral for the reduction below
        src = np.take(np.pad(flat, ((0, 0), (0, 1)), constant_values=fill), counted, axis=1)  # unknown (-1): fill
        if reduce == "upper":  # sorted worst first, unknown pixels last; the quartile of the known ones
            vals = src.reshape(len(est), th, k, tw, k).transpose(0, 1, 3, 2, 4).reshape(len(est), th, tw, k * k)
            vals = np.sort(vals if higher_is_better else -vals, axis=-1)
            at = np.maximum(np.floor(0.25 * (count - 1)), 0).astype(np.int64)
            out = np.take_along_axis(vals, np.broadcast_to(at[None, ..., None], vals.shape[:3] + (1,)), -1)[..., 0]
            out = out if higher_is_better else -out
            out[:, count == 0] = np.nan
        else:  # rows first, then columns, as for the mean
            pick = np.minimum if higher_is_better else np.maximum
            out = pick.reduce(pick.reduce(src.reshape(len(est), th, k, gw), axis=2).reshape(len(est), th, tw, k), axis=-1)
    missing = (1.0 - count / real > unseen_fraction) | ~np.isfinite(out).all(axis=0)
    out[:, missing] = -np.inf if higher_is_better else np.inf
    return (np.ascontiguousarray(out, dtype=np.float32),
            Track(new, place, gen, track.lut, track.shape, track.origin, track.cell), missing)


def crop_alignment(predictor: ShadingRatePredictor, limit: int = MAX_MARGIN) -> int:
    """The tiles a crop's first row and column must be a multiple of for the network to see it as the
    whole frame does: 1 for a network whose pooling ends at its tile (any tile-aligned crop), 2 for one
    that pools the tile grid once more (rtp's fast network with a coarse context, ``coarse``: its 2x2
    cells of tiles start at the frame's first tile, and a crop that starts at an odd tile pairs other
    tiles, so none of its estimates is the whole frame's however wide its margin). Measured on a random
    frame, as :func:`context_tiles` measures the reach: the smallest shift of 1, 2, 4 or 8 tiles whose
    crop gives the whole frame's estimates ``limit`` tiles past its edge; 1 where none does (a reach
    past ``limit``)."""
    t = predictor.tile_size
    n = limit + 9
    x = np.random.default_rng(1).random((len(predictor.metadata.inputs), n * t, n * t), dtype=np.float32)
    whole = predictor.predict(x)
    for a in (1, 2, 4, 8):
        part = predictor.predict(np.ascontiguousarray(x[:, a * t:, a * t:]))
        if np.allclose(part[:, limit:, limit:], whole[:, a + limit:, a + limit:], rtol=1e-5, atol=1e-6):
            return a
    return 1


def context_tiles(predictor: ShadingRatePredictor, limit: int = MAX_MARGIN, align: int = 1) -> int:
    """The tiles of context a crop needs around a tile for the network's estimate there to be the
    whole frame's: the model's reach (a deeper network reaches further), measured once on a random
    frame of ``2 * limit + 2 * align - 1`` tiles square by cropping it ever wider around a tile near
    its middle (a few small predictions). ``align`` (:func:`crop_alignment`) > 1: each crop starts at
    a multiple of ``align`` tiles, at least the margin before the tile (as :class:`PredictionReuse`
    places its crops), for the tile at each position within such a cell. ``limit`` if even that many
    tiles do not give the whole frame's estimate."""
    t = predictor.tile_size
    n = 2 * limit + 2 * align - 1
    x = np.random.default_rng(0).random((len(predictor.metadata.inputs), n * t, n * t), dtype=np.float32)
    whole = predictor.predict(x)
    for m in range(limit):
        for p in range(align):  # the tile at each position of a cell of align tiles
            c = limit + align - 1 + p
            o = (c - m) // align * align  # (>= align: the crop never starts at the frame's edge; ends before its end)
            part = predictor.predict(np.ascontiguousarray(x[:, o * t:(c + m + 1) * t, o * t:(c + m + 1) * t]))
            if not np.allclose(part[:, c - o, c - o], whole[:, c, c], rtol=1e-5, atol=1e-6):
                break
        else:
            return m
    return limit


def cover(tiles: np.ndarray, margin: int) -> list[tuple[int, int, int, int]]:
    """Rectangles ``(top, bottom, left, right)`` in tiles (bottom and right exclusive) that hold every
    True tile of ``tiles`` with ``margin`` tiles of context around it: the bounding boxes of the
    connected groups of the dilated mask (runs of each row joined to the runs they touch in the row
    above), merged where they overlap."""
    th, tw = tiles.shape
    if not tiles.any():
        return []
    grown = np.zeros((th + 2 * margin, tw + 2 * margin), bool)
    for dy in range(2 * margin + 1):
        for dx in range(2 * margin + 1):
            grown[dy:dy + th, dx:dx + tw] |= tiles
    grown = grown[margin:margin + th, margin:margin + tw]
    edges = np.diff(np.pad(grown, ((0, 0), (1, 1))).astype(np.int8), axis=1)
    parent: list[int] = []
    boxes: list[list[int]] = []  # per run: top, bottom, left, right

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    above: list[tuple[int, int, int]] = []  # the previous row's runs: start, end, run number
    for y in range(th):
        here = []
        for x0, x1 in zip(np.nonzero(edges[y] == 1)[0].tolist(), np.nonzero(edges[y] == -1)[0].tolist()):
            i = len(parent)
            parent.append(i)
            boxes.append([y, y + 1, x0, x1])
            for a0, a1, j in above:
                if a0 < x1 and x0 < a1:  # touching (4-connected): one group
                    ri, rj = root(i), root(j)
                    if ri != rj:
                        parent[rj] = ri
            here.append((x0, x1, i))
        above = here
    groups: dict[int, list[int]] = {}
    for i, b in enumerate(boxes):
        g = groups.setdefault(root(i), list(b))
        g[0], g[1], g[2], g[3] = min(g[0], b[0]), max(g[1], b[1]), min(g[2], b[2]), max(g[3], b[3])
    out = list(groups.values())
    merged = True
    while merged:  # boxes of different groups can overlap: merge them
        merged = False
        for i in range(len(out)):
            for j in range(i + 1, len(out)):
                a, b = out[i], out[j]
                if a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]:
                    out[i] = [min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3])]
                    del out[j]
                    merged = True
                    break
            if merged:
                break
    return [(a[0], a[1], a[2], a[3]) for a in out]


#: The largest ``rescale`` exponent :class:`PredictionReuse` takes.
MAX_RESCALE = 2.0
#: ``PredictionReuse(carry_scale=...)`` lies in [1 / this, this].
MAX_CARRY_SCALE = 4.0


def _group_sums(a: np.ndarray, m: int, axis: int) -> np.ndarray:
    """Sums of consecutive groups of ``m`` along ``axis`` (0 or 1) of a 2-D array, the last group
    partial where the length is not a multiple: reshapes, not ``np.add.reduceat`` (slow on axis 0)."""
    n = a.shape[axis]
    full = n // m
    b = a if axis == 0 else a.T
    parts = [b[:full * m].reshape(full, m, *b.shape[1:]).sum(axis=1)] if full else []
    if n % m:
        parts.append(b[full * m:].sum(axis=0, keepdims=True))
    out = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=0)
    return out if axis == 0 else out.T


def _to_length(a: np.ndarray, n: int, axis: int) -> np.ndarray:
    """``a`` (2-D, at most ``n`` long on ``axis``) extended to ``n`` by repeating its last entry
    (zeros if it has none)."""
    have = a.shape[axis]
    if have == n:
        return a
    shape = list(a.shape)
    shape[axis] = n - have
    edge = np.zeros(shape, a.dtype) if have == 0 else np.repeat(np.take(a, [-1], axis=axis), n - have, axis=axis)
    return np.concatenate([a, edge], axis=axis)


def tile_block_levels(planes: np.ndarray, tile: int) -> np.ndarray:
    """Per tile and reduced rate, the mean over the tile's 4x4 cells of ``.blocks`` planes
    (:func:`block_variances`: each rate's log variance inside its blocks, normalised to [0, 1]),
    averaged over the planes given: ``(P, H, W)`` -> float32 ``(6, tile rows, tile cols)`` in
    :data:`BLOCK_RATES` order. ``tile`` must be a multiple of :data:`BLOCK_CELL`; a partial last
    tile averages the cells it has. Where a side is not a multiple of the cell, a value that
    :func:`block_variances` cropped off the last cells is the same rate's in the cell before (zero
    where there is none: a frame narrower than a cell)."""
    if planes.ndim != 3 or 0 in planes.shape:
        raise InputShapeError(f"expected .blocks planes (P, H, W), got shape {planes.shape}", tuple(planes.shape),
                              "(P, H, W)")
    _, h, w = planes.shape
    c = BLOCK_CELL
    th, tw = tile_grid(h, w, tile)
    m = tile // c
    ch, cw = -(-h // c), -(-w // c)
    counts = np.outer(_group_sums(np.ones((ch, 1), np.float32), m, 0)[:, 0],
                      _group_sums(np.ones((1, cw), np.float32), m, 1)[0])  # cells per tile
    out = np.empty((len(BLOCK_RATES), th, tw), np.float32)
    for row in range(-(-len(BLOCK_RATES) // c)):
        rows = planes[:, row::c]  # the row-th pixel row of every cell: whole rows, each read once
        level = rows[0].astype(np.float32)  # a copy: the planes are added into it
        for plane in rows[1:]:
            level += plane
        summed = _group_sums(_to_length(level, ch, 0), m, 0) / len(planes)  # (tile rows, W)
        for col in range(c):
            k = row * c + col
            if k < len(BLOCK_RATES):
                out[k] = _group_sums(_to_length(summed[:, col::c], cw, 1), m, 1) / counts
    return out


#: What the numeric options refuse although ``float()`` takes it: a flag (numpy's too: ``rescale=np.True_`` was
#: taken for an exponent of 1, ``unseen_fraction=np.False_`` for 0) or text.
_NOT_NUMBERS = (bool, np.bool_, str, bytes)


def _in_unit_interval(value: object, name: str, expected: str) -> float:
    """``value`` as a float in [0, 1), or a ParameterError naming ``name`` and what was ``expected``."""
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        x = math.nan
    if isinstance(value, _NOT_NUMBERS) or not 0.0 <= x < 1.0:
        raise ParameterError(f"{name}: expected {expected}, got {value!r}", name)
    return x


class PredictionReuse:
    """Run a predictor's network every ``every``-th frame and carry its per-tile estimates between.

        reuse = sdk.PredictionReuse(predictor, every=4, unseen="fresh")
        rates = reuse.shading_rates(x)                              # first frame: the network runs
        rates = reuse.shading_rates(x, fetch=(rows, cols), seen=seen, background=sky)   # each next one

    ``fetch`` gives, per pixel of this frame, the top-left ``(row, col)`` of the previous frame's
    pixel it reprojects from (the nearest texel of :func:`reproject_positions`, or the pixel minus
    its motion vector), ``seen`` 1 where that pixel passed the disocclusion test (as
    :func:`reproject` returns it) and ``background`` 1 on sky, which keeps the estimate at its own
    screen position. A frame without ``fetch`` (the first, a camera cut) runs the network. A frame of
    another size than the last (dynamic resolution) is carried too, its ``fetch`` indexing the previous
    frame's pixels (:func:`fetch_from_motion` with ``prev_shape``): its tiles reduce the estimates
    their pixels' surfaces carry, and each pixel carries its surface's own entry on from there, as at
    one size.

    ``reduce`` (:data:`REUSE_REDUCTIONS`) is how a tile reduces the estimates its pixels carry,
    ``unseen`` (:data:`REUSE_UNSEEN`) what becomes of tiles more than ``unseen_fraction`` unseen
    since the network ran; ``margin`` the tiles of context around a fresh crop (None: the model's
    own reach, measured by :func:`context_tiles` when ``unseen="fresh"``: two tiles for the
    three-block shipped models, four for LPIPS's five blocks; each crop starts at a multiple of
    :attr:`align` tiles, :func:`crop_alignment`'s measure: 2 for a coarse context). After each frame :attr:`work` is the
    network's work on it as a share of a whole-frame run (1, 0, or the crops' share; not counting the tail that
    ``carry="features"`` runs on a carried frame). One instance
    per view, one frame at a time: a call while another thread's holds the instance is a :class:`ParameterError`
    (docs/runtime.md "Threads and several views").

    A predictor loaded for hardware tiles finer than the model's (``sdk.load(..., tile_size=8)`` of a
    16-pixel model, AMD's and Intel's VRS tiles) is reused on the model's tiles (runs, crops,
    ``margin`` and ``step`` are the model's) and each hardware tile takes its model tile's estimate:
    the rates of the model-tile reuse, split (:func:`split_tiles`).

    ``refresh`` (a share of the frame's tiles, or None) shortens the interval when the camera
    uncovers much: once more than that share of the tiles is unseen since the network ran (tiles
    that would go to 1x1, or to crops), it runs on the whole frame before the interval is up. The
    interval so adapts to the camera's speed: a walk keeps ``every``, a run refreshes sooner. At
    equal network work it ties a fixed interval but lifts the worst path (docs/results.md "An
    interval that adapts to the camera").

    ``step`` is how densely the carry follows the surfaces: one pixel of every ``step`` per axis
    carries its surface's place (a divisor of the tile size; None: :func:`default_step`, every fourth
    pixel of a 16-pixel tile). A larger step costs less per carried frame (docs/performance.md
    "Prediction reuse on a CPU") and samples each tile's surfaces more coarsely.

    ``rescale`` > 0 (models with ``.blocks`` inputs, error metrics) rescales carried estimates by how
    the content now falls on each rate's blocks: the carry holds each tile's estimate divided by
    ``(v + eps) ** rescale``, ``v`` the geometric mean over the tile of the variance inside the
    rate's blocks in the model's ``.blocks`` planes (:func:`block_variances`) where the network ran,
    and a carried frame multiplies by the same of its own planes. The network's estimates follow
    those planes, which change with every sub-pixel move of the camera; a carried estimate alone
    cannot (docs/results.md "Carried estimates rescaled by the blocks' variance"). It reads the
    frame's inputs on carried frames too (``x`` is called on the whole frame, or for its ``.blocks``
    planes alone when it takes ``channels``).

    ``carry_scale`` (error metrics) multiplies the carried estimates of the frames the network does not
    run on (not unseen tiles, not fresh crops): above 1 the carried frames choose as if under a
    threshold that much lower. Carried estimates miss what the network would read on the new frame,
    so a slightly stricter threshold for them and a looser one overall (the engine's threshold
    sweep) keep more work at the same failing share (docs/results.md "A threshold of their own for
    carried estimates").

    ``carry="features"`` (a model that splits, :attr:`ShadingRatePredictor.splits`) carries the trunk's
    per-tile features instead of the estimates (each tile the mean of its carried pixels' features)
    and runs the network's tail on every carried frame: the tail reads what changes with every
    sub-pixel move of the camera (the variance inside each rate's blocks, from the frame's ``.tiles``
    planes, which summarise it per tile, or its ``.blocks`` planes) at tile resolution, where it costs a
    small part of a network run (a tenth with ``.tiles`` planes on a CPU), and the trunk, which
    reads the frame at full resolution, runs every ``every``-th frame. Unseen tiles go to 1x1 or to
    fresh crops as with estimates; ``x`` is read on every frame (an input function that takes
    ``channels`` is asked for the tail's planes alone there). Not with ``rescale`` or ``history``
    (both act on carried estimates), and ``reduce`` must be ``"mean"`` (docs/runtime.md).

    ``history`` > 0 also filters the estimates over time, as temporal anti-aliasing filters colour:
    on the frames the network runs, each tile's estimate is ``(1 - history)`` times the network's
    plus ``history`` times the estimate carried into that tile from the previous frame (its pixels'
    warped estimates, reduced as above; the network's alone where the tile is unseen). With
    ``every=1`` that runs the network on every frame and averages its estimates along the surfaces'
    motion. It steadies the rates but costs saving at matched failing tiles: the network's errors
    persist on a surface rather than average out (docs/results.md "Estimates filtered over time").
    """

    def __init__(self, predictor: ShadingRatePredictor, every: int = 4, *, reduce: str = "mean",
                 unseen: str = "full", unseen_fraction: float = 0.5, margin: int | None = None,
                 history: float = 0.0, refresh: float | None = None, step: int | None = None,
                 rescale: float = 0.0, carry_scale: float = 1.0, carry: str = "estimates") -> None:
        from ._predictor import ShadingRatePredictor  # (its module imports this one)

        if not isinstance(predictor, ShadingRatePredictor):
            raise ParameterError(f"predictor: expected an sdk.ShadingRatePredictor (sdk.load(...)), got "
                                 f"{type(predictor).__name__}", "predictor")
        # On hardware tiles finer than the model's (load(tile_size=8) of a 16-pixel model) the network's runs,
        # crops and carries work on whole model tiles and each hardware tile takes its model tile's estimates
        # afterwards, as predict() gives them: the rates are the model tiles' to the bit.
        finer = predictor.tile_size < predictor.metadata.tile_size
        net = predictor._on_model_tiles() if finer else predictor
        if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
            raise ParameterError(f"every: expected an integer >= 1 (1: the network on every frame), got {every!r}",
                                 "every")
        if not isinstance(reduce, str) or reduce not in REUSE_REDUCTIONS:
            raise ParameterError(f"reduce: expected one of {', '.join(REUSE_REDUCTIONS)}, got {reduce!r}", "reduce")
        if not isinstance(unseen, str) or unseen not in REUSE_UNSEEN:
            raise ParameterError(f"unseen: expected one of {', '.join(REUSE_UNSEEN)}, got {unseen!r}", "unseen")
        share = _in_unit_interval(unseen_fraction, "unseen_fraction", "a share in [0, 1)")
        if margin is not None and (isinstance(margin, bool) or not isinstance(margin, (int, np.integer))
                                   or margin < 0):
            raise ParameterError(f"margin: expected None (the model's reach) or an integer >= 0 (tiles), "
                                 f"got {margin!r}", "margin")
        weight = _in_unit_interval(history, "history", "a weight in [0, 1) (0: the network's estimate alone)")
        limit = None if refresh is None else _in_unit_interval(refresh, "refresh",
                                                               "None or a share of the frame's tiles in [0, 1)")
        if unseen == "fresh" and predictor.static_size is not None:
            h, w = predictor.static_size
            raise ParameterError(f"unseen='fresh' runs the network on crops, but this model takes only {w}x{h} "
                                 "frames (export it with dynamic sizes)", "unseen")
        try:
            scale = float(carry_scale)
        except (TypeError, ValueError, OverflowError):
            scale = math.nan
        if isinstance(carry_scale, _NOT_NUMBERS) or not 1.0 / MAX_CARRY_SCALE <= scale <= MAX_CARRY_SCALE:
            raise ParameterError(f"carry_scale: expected a factor in [{1 / MAX_CARRY_SCALE:g}, {MAX_CARRY_SCALE:g}] "
                                 f"(1: carried estimates as they are), got {carry_scale!r}", "carry_scale")
        if scale != 1.0 and predictor.metadata.higher_is_better:
            raise ParameterError("carry_scale: this model's metric is better when higher; carry_scale multiplies an "
                                 "error estimate", "carry_scale")
        if not isinstance(carry, str) or carry not in REUSE_CARRIES:
            raise ParameterError(f"carry: expected one of {', '.join(REUSE_CARRIES)}, got {carry!r}", "carry")
        if carry == "features":
            clash = ("the model does not split (ShadingRatePredictor.splits is False: metadata.tail is null)"
                     if not predictor.splits else
                     f"the predictor pools the model's {predictor.metadata.tile_size}-pixel tiles to "
                     f"{predictor.tile_size} (load it without tile_size)"
                     if predictor.tile_size > predictor.metadata.tile_size else
                     "rescale acts on carried estimates" if rescale else
                     "history blends carried estimates" if history else
                     f"features are carried as each tile's mean, not reduce={reduce!r}" if reduce != "mean" else "")
            if clash:
                raise ParameterError(f"carry='features': {clash}", "carry")
        self.carry = carry
        self.carry_scale = scale
        self.step = _check_step(step, net.tile_size)
        self.rescale, self._blocks = self._check_rescale(net, rescale)
        self.predictor = predictor
        self._net = net
        #: hardware tiles per model tile side (1 unless the predictor was loaded for finer tiles)
        self._split = predictor.metadata.tile_size // predictor.tile_size if finer else 1
        self.every = int(every)
        self.reduce = reduce
        self.unseen = unseen
        self.unseen_fraction = share
        #: the tiles a fresh crop's first row and column are a multiple of (:func:`crop_alignment`)
        self.align = crop_alignment(net) if unseen == "fresh" else 1
        if margin is None and unseen == "fresh":  # only fresh crops need it: measure the model's reach
            margin = context_tiles(net, align=self.align)
        self.margin: int | None = None if margin is None else int(margin)
        self.history = weight
        self.refresh = limit
        self.work = 0.0
        self._busy = threading.Lock()  # (held through a frame: a second caller meanwhile is refused, _enter)
        self.reset()

    def __getstate__(self) -> dict[str, object]:
        """Copied or pickled without its lock (a lock cannot be pickled, and a copy is another view's: its own)."""
        return {k: v for k, v in self.__dict__.items() if k != "_busy"}

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self._busy = threading.Lock()

    def _enter(self, what: str) -> None:
        """Take the instance for one call (``what``), or refuse it where another call holds it: two threads at once
        moved one carry in silence (another frame's estimates carried, the track of one size under another's), or
        failed far inside it (an IndexError, a fetch refused as out of a frame it was not of)."""
        if not self._busy.acquire(blocking=False):
            raise ParameterError(f"PredictionReuse.{what}: this reuse is in a call already (another thread's, or its "
                                 "own input function's): it holds one view's carry and takes one frame at a time; "
                                 "give each thread its own PredictionReuse (they may share the predictor), or call "
                                 "it from one thread at a time (docs/runtime.md \"Threads and several views\")")

    @staticmethod
    def _check_rescale(predictor: ShadingRatePredictor, rescale: object) -> tuple[float, list[int]]:
        try:
            a = float(rescale)  # type: ignore[arg-type]
        except (TypeError, ValueError, OverflowError):
            a = math.nan
        if isinstance(rescale, _NOT_NUMBERS) or not 0.0 <= a <= MAX_RESCALE:
            raise ParameterError(f"rescale: expected an exponent in [0, {MAX_RESCALE:g}] (0: carry the estimates as they "
                                 f"are), got {rescale!r}", "rescale")
        if a == 0.0:
            return 0.0, []
        meta = predictor.metadata
        blocks = [i for i, c in enumerate(meta.inputs) if c.endswith(".blocks")]
        problem = ("it has no .blocks input (sdk.block_variances)" if not blocks else
                   "its metric is better when higher (rescale divides an error)" if meta.higher_is_better else
                   f"its {predictor.tile_size}-pixel tiles are not whole {BLOCK_CELL}x{BLOCK_CELL} cells"
                   if predictor.tile_size % BLOCK_CELL else "")
        if problem:
            raise ParameterError(f"rescale: this model cannot rescale carried estimates: {problem}", "rescale")
        return a, blocks

    def _levels(self, blocks: np.ndarray) -> np.ndarray:
        """Per tile and rate, the factor ``(v + eps) ** rescale`` of this frame's ``.blocks`` planes."""
        v = tile_block_levels(blocks, self._net.tile_size)
        return np.exp(self.rescale * -math.log(BLOCK_EPS) * v.astype(np.float64))

    def reset(self) -> None:
        """Forget the carried estimates: the next frame runs the network."""
        self._enter("reset")
        try:
            self._cache: np.ndarray | None = None
            self._track: Track | None = None
            self._shape: tuple[int, int] | None = None
            self._age = 0
            self._zeros: np.ndarray | None = None
        finally:
            self._busy.release()

    @property
    def age(self) -> int | None:
        """Frames since the network last ran on a whole frame (None before the first)."""
        return None if self._cache is None else self._age

    def __repr__(self) -> str:
        return (f"PredictionReuse(every={self.every}, reduce={self.reduce!r}, unseen={self.unseen!r}, "
                f"unseen_fraction={self.unseen_fraction:g}, margin={self.margin}, history={self.history:g}, "
                f"refresh={self.refresh!r}, step={self.step}, rescale={self.rescale:g}, "
                f"carry_scale={self.carry_scale:g}, carry={self.carry!r})")

    def _window(self, x: Inputs, ys: slice, xs: slice) -> np.ndarray:
        """Every input plane of a window of the frame."""
        if callable(x):
            names = self._net.metadata.inputs
            if _takes_channels(x):
                return self._asked(x, ys, xs, names)
            return self._checked(x(ys, xs), ys, xs, names, "the input function")
        return x[:, ys, xs]

    def _some(self, x: Inputs, hw: tuple[int, int], which: list[int]) -> np.ndarray:
        """The input planes ``which`` (indices into ``metadata.inputs``) of the whole frame: an input
        function that takes ``channels`` builds those alone."""
        ys, xs = slice(0, hw[0]), slice(0, hw[1])
        if callable(x) and _takes_channels(x):
            names = self._net.metadata.inputs
            return self._asked(x, ys, xs, tuple(names[i] for i in which))
        return self._window(x, ys, xs)[which]

    def _tail_frame(self, x: Inputs, hw: tuple[int, int]) -> np.ndarray:
        """A carried frame's inputs for the tail: the whole frame, or where the input function takes
        ``channels``, the tail's planes in a frame whose other planes (which the tail never reads) are 0."""
        if not (callable(x) and _takes_channels(x)):
            return self._window(x, slice(0, hw[0]), slice(0, hw[1]))
        names = self._net.metadata.inputs
        which = [i for i, c in enumerate(names) if c in self._net.tail_inputs]
        shape = (len(names), *hw)
        if self._zeros is None or self._zeros.shape != shape:  # kept: only the tail's planes are written again
            self._zeros = np.zeros(shape, np.float32)
        self._zeros[which] = self._some(x, hw, which)
        return self._zeros

    def _asked(self, x: Callable[..., np.ndarray], ys: slice, xs: slice, names: tuple[str, ...]) -> np.ndarray:
        """``x(ys, xs, channels=names)``, checked: float32 ``(len(names), rows, cols)``."""
        return self._checked(x(ys, xs, channels=names), ys, xs, names,
                             f"the input function, asked for channels {list(names)}")

    @staticmethod
    def _checked(planes: object, ys: slice, xs: slice, names: tuple[str, ...], what: str) -> np.ndarray:
        """What an input function returned, checked: float32 ``(len(names), rows, cols)`` of the window
        it was asked for (a larger frame would have been read as this one, with no error)."""
        want = (len(names), ys.stop - ys.start, xs.stop - xs.start)
        if not isinstance(planes, np.ndarray) or planes.dtype != np.float32:
            got = f"dtype {planes.dtype}" if isinstance(planes, np.ndarray) else type(planes).__name__
            raise InputDtypeError(f"{what}: expected a float32 numpy array, got {got}")
        if planes.shape != want:
            raise InputShapeError(f"{what}, of rows {ys.start}:{ys.stop} and columns {xs.start}:{xs.stop}: expected "
                                  f"shape {want}, got {planes.shape}", tuple(planes.shape), str(want))
        return planes

    def _shape_of(self, x: Inputs, seen: np.ndarray | None) -> tuple[int, int]:
        if isinstance(x, np.ndarray):
            if x.ndim != 3:
                raise InputShapeError(f"expected one frame's inputs (C, H, W), got shape {x.shape}", tuple(x.shape),
                                      "(C, H, W)")
            # its dtype and planes on every frame, as the network's frames check them (cheap: not its values), not
            # refused only every ``every``-th frame as if that frame's inputs were the wrong ones
            if x.dtype != np.float32:
                raise InputDtypeError(f"expected the inputs as float32, got dtype {x.dtype}; convert with "
                                      "x.astype(np.float32)")
            names = self._net.metadata.inputs
            if x.shape[0] != len(names):
                raise InputChannelError(f"expected {len(names)} channels {list(names)} on axis 0, got shape {x.shape}",
                                        tuple(x.shape), f"({len(names)}, H, W)")
            return self._non_empty(int(x.shape[1]), int(x.shape[2]), "the inputs")
        if not callable(x):
            raise InputDtypeError(f"expected the inputs as a float32 numpy array (C, H, W) or a function of a window, "
                                  f"got {type(x).__name__}")
        if not isinstance(seen, np.ndarray) or seen.ndim != 2:
            raise ParameterError("with inputs given as a function, pass seen, an (H, W) array (its shape is the "
                                 "frame's)", "seen")
        return self._non_empty(int(seen.shape[0]), int(seen.shape[1]), "seen")

    @staticmethod
    def _non_empty(h: int, w: int, what: str) -> tuple[int, int]:
        """``(h, w)``, or an :class:`InputShapeError` for a frame without pixels, on every frame (on a carried frame
        it was a ParameterError about a ``height`` never passed)."""
        if h == 0 or w == 0:
            raise InputShapeError(f"{what}: expected a frame of at least one pixel, got {w}x{h}", (h, w), "(H, W)")
        return h, w

    def _run(self, x: Inputs, hw: tuple[int, int],
             carried: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        h, w = hw
        planes = self._window(x, slice(0, h), slice(0, w))
        if self.carry == "features":  # the trunk's features are what the frames between carry
            est, feats = self._net.predict_split(planes)
            self._cache = feats.reshape(len(feats), -1)
            self._track = start_track(hw, self._net.tile_size, self.step) if self.every > 1 else None
            self._shape, self._age, self.work = hw, 0, 1.0
            return est
        est = self._net.predict(planes)
        if carried is not None and self.history > 0:  # blend with the carried estimates where they are known
            old, missing = carried
            mix = ((1.0 - self.history) * est + self.history * np.where(missing[None], est, old)).astype(est.dtype)
            est = np.where(missing[None], est, mix)
        kept = est if not self.rescale else (est / self._levels(planes[self._blocks])).astype(np.float32)
        self._cache = kept.reshape(len(kept), -1)
        self._track = (start_track(hw, self._net.tile_size, self.step) if self.every > 1 or self.history > 0
                       else None)
        self._shape = hw
        self._age = 0
        self.work = 1.0
        return est

    @staticmethod
    def _check_fetch_kind(fetch: object) -> None:
        """``fetch`` is two integer arrays, checked on every frame that gives it, the network's too: a
        frame where the network runs reads no fetch, and a float one passed there was refused only on
        the next frame, as if that frame's were the wrong one (the shape and range are checked where
        the fetch is read: a resize's frame may give the old size's)."""
        if not isinstance(fetch, (tuple, list)) or len(fetch) != 2:
            raise ParameterError(f"fetch: expected (rows, cols), two integer arrays of the frame's shape, got "
                                 f"{type(fetch).__name__}", "fetch")
        for a, name in zip(fetch, ("fetch rows", "fetch cols")):
            if not isinstance(a, np.ndarray):
                raise ParameterError(f"{name}: expected a numpy array of integer pixel indices, got {type(a).__name__}",
                                     "fetch")
            if not np.issubdtype(a.dtype, np.integer):
                raise ParameterError(f"{name}: expected integer pixel indices, got dtype {a.dtype}", "fetch")

    @staticmethod
    def _plane(a: object, name: str, hw: tuple[int, int], limit: int | None = None, step: int = 1) -> np.ndarray:
        if not isinstance(a, np.ndarray):
            raise ParameterError(f"{name}: expected a numpy array of shape {hw}, got {type(a).__name__}",
                                 "fetch" if limit is not None else name)
        arr = a
        if arr.dtype.kind not in "biuf":
            raise ParameterError(f"{name}: expected a numeric array, got dtype {arr.dtype}",
                                 "fetch" if limit is not None else name)
        if arr.shape != hw:
            raise InputShapeError(f"{name}: expected shape {hw} (the frame's), got {arr.shape}", tuple(arr.shape),
                                  str(hw))
        if limit is not None:
            if not np.issubdtype(arr.dtype, np.integer):
                raise ParameterError(f"{name}: expected integer pixel indices, got dtype {arr.dtype}", "fetch")
            # one pass: read as unsigned, a negative index is larger than any limit (half the time of min and max);
            # only the pixels the carry reads (one of every `step` per axis, and the last row and column: _kept's,
            # whose padding's corner is the last pixel: unchecked, it was read past the frame on frames not of whole
            # tiles), a sixteenth of the map at the default step
            unsigned = arr.view(np.dtype(f"u{arr.itemsize}")) if arr.dtype.kind == "i" else arr
            read = unsigned if step == 1 else (unsigned[::step, ::step], unsigned[::step, -1:], unsigned[-1:, ::step],
                                               unsigned[-1:, -1:])
            if arr.size and max(int(r.max()) for r in (read if isinstance(read, tuple) else (read,))) >= limit:
                raise ParameterError(f"{name}: expected indices in [0, {limit}) (the previous frame's pixels), got "
                                     f"{arr.min()}..{arr.max()}", "fetch")
        return arr

    def predict(self, x: Inputs, fetch: tuple[np.ndarray, np.ndarray] | None = None,
                seen: np.ndarray | None = None, background: np.ndarray | None = None) -> np.ndarray:
        """Per-tile estimates of this frame, as :meth:`ShadingRatePredictor.predict` returns them:
        the network's on its frames, carried ones in between (1x1's worst value, or fresh ones, on
        unseen tiles). ``x`` is the frame's inputs ``(C, H, W)`` or a function ``(rows, cols) ->``
        the inputs of that window, called only where the frame's planes are read. A function with a
        ``channels`` parameter is called ``x(rows, cols, channels=names)`` and returns those planes
        alone, float32 ``(len(names), rows, cols)``: every plane where the network runs, the tail's
        (:attr:`ShadingRatePredictor.tail_inputs`) on a frame whose features are carried, the
        ``.blocks`` planes for ``rescale``. On a predictor loaded for hardware tiles finer than the
        model's (``load(tile_size=8)``) the estimates are on those tiles, each its model tile's.

        One call at a time: a call while another holds this instance (another thread's) is a
        :class:`ParameterError`, and the other call goes on unharmed."""
        self._enter("predict")
        try:
            return self._estimates(x, fetch, seen, background)
        finally:
            self._busy.release()

    def _estimates(self, x: Inputs, fetch: tuple[np.ndarray, np.ndarray] | None, seen: np.ndarray | None,
                   background: np.ndarray | None) -> np.ndarray:
        """:meth:`predict` of a call that holds the instance."""
        est = self._predict(x, fetch, seen, background)
        if self._split == 1:
            return est
        assert self._shape is not None  # (every frame sets it)
        return split_tiles(est, self._split, tile_grid(*self._shape, self.predictor.tile_size))

    def _predict(self, x: Inputs, fetch: tuple[np.ndarray, np.ndarray] | None,
                 seen: np.ndarray | None, background: np.ndarray | None) -> np.ndarray:
        """:meth:`predict` on the model's own tiles."""
        hw = self._shape_of(x, seen)
        if self.every > 1 or self.history > 0:  # a frame too large for the track is refused before the network runs:
            # refused by the track after the run, it left that frame's estimates as the carry under the last frame's
            # track, and the next frame carried another frame's estimates, silently
            check_track_size(hw)
        runs = self._age + 1 >= self.every
        if fetch is not None:  # its kind every frame; its shape and range only where it is read
            self._check_fetch_kind(fetch)
        # seen and background are of this frame's shape on every frame: checked on the network's too, where they are
        # not read (refused only on the next frame, as if that frame's were the wrong ones)
        seen_ = None if seen is None else self._plane(seen, "seen", hw)
        bg = None if background is None else self._plane(background, "background", hw)
        if self._cache is None or fetch is None or (runs and self.history == 0):
            return self._run(x, hw)
        assert self._track is not None and self._shape is not None
        tile = self._net.tile_size
        step = _check_step(self.step, tile)
        # (the fetch indexes the previous frame's pixels: another size where dynamic resolution changed it)
        rows = self._plane(fetch[0], "fetch rows", hw, self._shape[0], step)
        cols = self._plane(fetch[1], "fetch cols", hw, self._shape[1], step)
        seen_ = np.ones(hw, np.float32) if seen_ is None else seen_
        hib = self._net.metadata.higher_is_better
        est, track, missing = carry_estimates(self._cache, self._track, rows, cols, seen_, bg, tile, hib,
                                              self.unseen_fraction, self.reduce, self.step)
        resized = hw != self._shape
        if resized:  # dynamic resolution: the track moves onto this frame (Track): each kept pixel keeps the entry its
            # surface carries (no tile's mean of them), its place where it is now, and lut's one row lists each kept
            # pixel's entry, so every surface carries its own and small moves add up as at one size; the first entries
            # stay the whole-frame run's tiles (sky's)
            here = start_track(hw, tile, self.step)
            track = Track(track.index, np.where(track.index >= 0, here.place, -1), np.zeros_like(track.gen),
                          track.index.reshape(1, -1).copy(), hw, self._track.origin or self._track.shape, step)
            # (the size is kept with the track below, once the frame is through: set here, a frame refused further
            # on, an input function's or a crop's NaN, left the old size's track under the new size, and the same
            # frame given again had its fetch refused as out of the previous frame, or was carried unmoved)
        if self.refresh is not None and missing.mean() > self.refresh:
            runs = True  # too much of the frame unseen since the network ran: run it before the interval is up
        feats = None
        if self.carry == "features" and not runs:  # the tail on the carried features and this frame
            feats = est
            feats[:, missing] = 0.0  # (their estimates go to 1x1 or fresh crops below)
            est = self._net.predict_tail(feats, self._tail_frame(x, hw))
            est[:, missing] = -np.inf if hib else np.inf
        levels = None
        if self.rescale and not (runs and self.history == 0):  # to this frame's blocks (unseen tiles stay worst)
            levels = self._levels(self._some(x, hw, self._blocks))
            est = np.where(missing[None], est, est * levels).astype(np.float32)
        if runs:  # the network's frame, blended with what was carried here (history > 0)
            return self._run(x, hw, (est, missing))
        carried = est  # (a whole-frame run below blends these, not carry_scale's: that is for carried frames alone)
        if self.carry_scale != 1.0:  # a stricter threshold for carried estimates (unseen tiles stay worst)
            est = np.where(missing[None], est, est * self.carry_scale).astype(np.float32)
        work = 0.0
        if self.unseen == "fresh" and missing.any():
            h, w = hw
            # (each crop starting at a multiple of the alignment: a coarse context's 2x2 cells of tiles as the whole frame's)
            boxes = [(y0 // self.align * self.align, y1, x0 // self.align * self.align, x1)
                     for y0, y1, x0, x1 in cover(missing, self.margin or 0)]
            area = sum((min(y1 * tile, h) - y0 * tile) * (min(x1 * tile, w) - x0 * tile) for y0, y1, x0, x1 in boxes)
            if area > FRESH_FULL * h * w:  # cheaper to run the whole frame, and it restarts the interval
                return self._run(x, hw, (carried, missing))
            for y0, y1, x0, x1 in boxes:
                window = self._window(x, slice(y0 * tile, min(y1 * tile, h)), slice(x0 * tile, min(x1 * tile, w)))
                sel = missing[y0:y1, x0:x1]
                if feats is not None:  # the crop's features join the carry too
                    part, part_feats = self._net.predict_split(window)
                    feats[:, y0:y1, x0:x1][:, sel] = part_feats[:, sel]
                else:
                    part = self._net.predict(window)
                est[:, y0:y1, x0:x1][:, sel] = part[:, sel]
            work = area / (h * w)
            kept = feats if feats is not None else est if levels is None else (est / levels).astype(np.float32)
            # the fresh tiles become entries of the cache, this frame a generation of the track: their pixels
            # carry them on from here, from where they are now
            slot = np.full(missing.size, -1, np.int32)
            slot[missing.ravel()] = self._cache.shape[1] + np.arange(int(missing.sum()), dtype=np.int32)
            self._cache = np.concatenate([self._cache, kept.reshape(len(kept), -1)[:, missing.ravel()]], axis=1)
            here = start_track(hw, tile, self.step)
            mine = slot[here.index]
            fresh = mine >= 0
            row = slot if track.cell is None else mine.ravel()  # (lut's cells: the tiles, or the kept pixels)
            track = Track(np.where(fresh, mine, track.index), np.where(fresh, here.place, track.place),
                          np.where(fresh, len(track.lut), track.gen), np.concatenate([track.lut, row[None]]),
                          track.shape, track.origin, track.cell)
            missing = np.zeros_like(missing)  # (every tile the network's now)
        self._track = track
        self._shape = hw  # (with the track: another size's where dynamic resolution changed it)
        self._age += 1
        self.work = work
        return est

    def shading_rates(self, x: Inputs, fetch: tuple[np.ndarray, np.ndarray] | None = None,
                      seen: np.ndarray | None = None, background: np.ndarray | None = None,
                      threshold: float | None = None, allowed: Iterable[RateLike] | None = None, *,
                      saving: float | None = None, engine_rates: RateLike | np.ndarray | None = None,
                      combiner: str | int = "max") -> np.ndarray:
        """:meth:`predict`, then per tile the cheapest allowed rate whose estimate passes ``threshold``
        (default: the model's), as :meth:`ShadingRatePredictor.shading_rates` picks them; or with ``saving``, a
        budget: the rates that save that share of the frame's work at the lowest threshold that does
        (:func:`~rtp.sdk.select_rates_for_saving`; with a ``threshold`` too, a floor under its rates). With
        ``engine_rates`` and a ``combiner``, the rates the device shades where the engine's meet them are judged
        (:meth:`ShadingRatePredictor.shading_rates`). One call at a time, as :meth:`predict`."""
        self._enter("shading_rates")
        try:
            return self._rates(x, fetch, seen, background, threshold, allowed, saving, engine_rates, combiner)
        finally:
            self._busy.release()

    def _rates(self, x: Inputs, fetch: tuple[np.ndarray, np.ndarray] | None, seen: np.ndarray | None,
               background: np.ndarray | None, threshold: float | None, allowed: Iterable[RateLike] | None,
               saving: float | None, engine_rates: RateLike | np.ndarray | None, combiner: str | int) -> np.ndarray:
        """:meth:`shading_rates` of a call that holds the instance."""
        meta = self._net.metadata
        # Every argument of the choice is refused before the frame moves the carry on (a bad threshold, rate or
        # combiner refused after predict() had aged the carry by a frame), and ``allowed`` is read once: an
        # iterator read here was empty where the choice read it again (only 1x1 allowed, a valid budget refused).
        allowed = resolve_allowed(allowed)
        if saving is not None:
            check_saving(saving, allowed)
        if threshold is not None:
            check_threshold(threshold, meta.higher_is_better)
        check_engine_rates(engine_rates, combiner, allowed,  # (the combiner too, without engine rates)
                           tile_grid(*self._shape_of(x, seen), self.predictor.tile_size))
        estimates = self._estimates(x, fetch, seen, background)
        if saving is not None:
            assert self._shape is not None  # (predict set it)
            chosen = select_rates_for_saving(estimates, saving, higher_is_better=meta.higher_is_better,
                                             allowed=allowed, factors=meta.rate_factors, frame_size=self._shape,
                                             tile_size=self.predictor.tile_size, threshold=threshold,
                                             engine_rates=engine_rates, combiner=combiner).rates
            if threshold is not None:  # (a floor past saturation, as the predictor's shading_rates says)
                self.predictor._warn_beyond_saturation(threshold, budget=True)
            return chosen
        thr = meta.default_threshold if threshold is None else threshold
        rates = select_rates(estimates, thr, higher_is_better=meta.higher_is_better, allowed=allowed,
                             factors=meta.rate_factors, engine_rates=engine_rates, combiner=combiner)
        # (the predictor's own shading_rates says once when every tile passes at every rate; through a reuse it
        # was silent)
        self.predictor._warn_beyond_saturation(thr)
        return rates


def fetch_from_motion(motion_x: object, motion_y: object,
                      prev_shape: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:class:`PredictionReuse`'s ``fetch`` from an engine's motion vectors: per pixel, the top-left ``(row,
    col)`` of the previous frame's pixel it comes from, the nearest texel of the pixel centre moved by its
    motion vector (``motion.x``/``motion.y`` of ``sdk.CHANNELS``: pixels, previous minus current position,
    x right and y down), kept inside the frame: the texel :func:`reproject` fetches and tests for the same
    ``motion``, a position on a texel's edge taking the texel right of it and above it (OpenGL's window
    coordinates, y up, as the shader's). ``prev_shape = (H', W')``: the previous frame's size where
    dynamic resolution changed it (the motion stays in this frame's pixels; the place is scaled to the
    previous frame's). ``(H, W)`` arrays of real numbers in, two ``intp`` ``(H, W)`` arrays out; anything
    else is a typed error naming the argument."""
    planes = []
    for name, value in (("motion_x", motion_x), ("motion_y", motion_y)):
        a = _real(value, name)  # (finite float64, else a typed error naming it)
        if a.ndim != 2 or a.size == 0:
            raise InputShapeError(f"{name}: expected a non-empty (H, W) array, got shape {a.shape}", tuple(a.shape),
                                  "(H, W)")
        planes.append(a)
    mx, my = planes
    if mx.shape != my.shape:
        raise InputShapeError(f"motion_x and motion_y must have one shape, got {mx.shape} and {my.shape}",
                              tuple(my.shape), str(mx.shape))
    h, w = mx.shape
    ph, pw = (h, w) if prev_shape is None else _shape(prev_shape)
    ys, xs = np.indices((h, w), dtype=np.float64)
    # The texel :func:`reproject` (and the shader) fetches and tests for the same motion, to the bit: its position in
    # the previous frame's GL window coordinates (y up), floored there. A position on a texel's edge is the texel
    # above it on the screen (rows counted from the top: ``ph - 1 - floor(gl_y)``); rounding the top-left y down,
    # as before 2026-12-07, took the one below on every vertical motion of a whole number and a half of pixels,
    # another texel than the one whose disocclusion test gave ``seen``.
    gl_y = ((h - (ys + 0.5)) - my) * (ph / h)
    rows = np.clip(ph - 1 - np.floor(gl_y), 0, ph - 1).astype(np.intp)
    cols = np.clip(np.floor((xs + 0.5 + mx) * (pw / w)), 0, pw - 1).astype(np.intp)
    return rows, cols

