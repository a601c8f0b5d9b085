"""Tiles: the sizes a model may use and the grid maths every room shares.

A frame of ``H x W`` pixels has ``ceil(H / w) x ceil(W / w)`` tiles of ``w x w``. When ``H`` or ``W``
is not a multiple of ``w`` the last tile row / column is partial: it covers only the real pixels
(``tile_extents``), the model sees the frame padded up to ``padded_size`` by repeating its last row
and column (docs/runtime.md), and no tile of the real frame is dropped.
"""

from __future__ import annotations

import numpy as np

from ._errors import ParameterError

__all__ = ["DEFAULT_TILE_SIZE", "TILE_SIZES", "hardware_tiles", "padded_size", "pool_tiles", "split_tiles", "tile_extents",
           "tile_grid"]

#: The tile size of the paper and of NVIDIA's VRS hardware (16x16 pixels share one rate).
DEFAULT_TILE_SIZE = 16
#: Tile sizes a model's metadata may declare (powers of two, the network halves resolution per block).
TILE_SIZES: tuple[int, ...] = (1, 2, 4, 8, 16, 32)
#: The finest hardware shading-rate tile a model's decisions are split to: one 4x4 coarse pixel.
MIN_HARDWARE_TILE = 4
#: The most values :func:`split_tiles` returns (a 16K frame's 4-pixel tiles for six rates are 50 million).
MAX_SPLIT_TILES = 2**28
#: The largest length in pixels (or tiles) the tile helpers take: far past any frame, inside int64 sums.
MAX_PIXELS = 2**31 - 1


def _positive(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= int(value) <= MAX_PIXELS:
        raise ParameterError(f"{name}: expected a positive integer (at most {MAX_PIXELS}), got {value!r}")
    return int(value)


def tile_grid(height: int, width: int, tile_size: int = DEFAULT_TILE_SIZE) -> tuple[int, int]:
    """Tile rows and columns of a ``height x width`` frame: ``(ceil(H / w), ceil(W / w))``."""
    t = _positive("tile_size", tile_size)
    h = _positive("height", height)
    w = _positive("width", width)
    return -(-h // t), -(-w // t)


def padded_size(height: int, width: int, tile_size: int = DEFAULT_TILE_SIZE) -> tuple[int, int]:
    """``(H, W)`` rounded up to whole tiles: the size a frame is padded to before inference."""
    th, tw = tile_grid(height, width, tile_size)
    return th * int(tile_size), tw * int(tile_size)


def tile_extents(length: int, tile_size: int = DEFAULT_TILE_SIZE) -> np.ndarray:
    """Pixels each tile covers along an axis of ``length`` pixels: ``tile_size`` for every tile but a
    partial last one. int64 ``(ceil(length / tile_size),)``; the values sum to ``length``."""
    t = _positive("tile_size", tile_size)
    n = _positive("length", length)
    return np.minimum(t, n - t * np.arange(-(-n // t), dtype=np.int64))


def pool_tiles(values: np.ndarray, factor: int, *, higher_is_better: bool = False) -> np.ndarray:
    """Per-tile values on a grid ``factor`` times coarser: each coarse tile takes the worst of the
    ``factor x factor`` fine tiles it covers (the maximum of an error, the minimum of a quality such as
    PSNR), so a rate chosen for the coarse tile passes wherever it passed for every fine one.

    ``values`` is ``(..., th, tw)``; the result ``(..., ceil(th / factor), ceil(tw / factor))``, which
    is the coarse tile grid of the same frame (a partial coarse tile pools the fine tiles it has). Use
    it to run a model with 8-pixel tiles on hardware with 16-pixel shading-rate tiles.
    """
    f = _positive("factor", factor)
    if not isinstance(higher_is_better, (bool, np.bool_)):  # ('no' was taken for True: the minimum of errors)
        raise ParameterError(f"higher_is_better: expected True or False, got {higher_is_better!r}", "higher_is_better")
    v = _tile_values(values)
    if f == 1:
        return v.copy()
    th, tw = v.shape[-2:]
    # a factor past an axis's tiles pools them all into one: clamped on each axis, the padding is never more than
    # the last coarse tile's (one clamp for both padded a 1x3000 strip pooled by 3000 to 3000x3000 values)
    fh, fw = min(f, th), min(f, tw)
    ch, cw = -(-th // fh), -(-tw // fw)
    # the padding never wins: +-inf, or the integer type's own extreme (in floats, int64 values past 2**53 were rounded)
    if v.dtype.kind in "iu":
        fill: object = np.iinfo(v.dtype).max if higher_is_better else np.iinfo(v.dtype).min
    else:
        fill = bool(higher_is_better) if v.dtype.kind == "b" else np.inf if higher_is_better else -np.inf
    padded = np.full((*v.shape[:-2], ch * fh, cw * fw), fill, dtype=v.dtype)
    padded[..., :th, :tw] = v
    blocks = padded.reshape(*v.shape[:-2], ch, fh, cw, fw)
    return blocks.min(axis=(-3, -1)) if higher_is_better else blocks.max(axis=(-3, -1))


def _tile_values(values: object) -> np.ndarray:
    """``values`` as a numeric array of shape ``(..., tile rows, tile columns)``, else a ParameterError."""
    try:
        v = np.asarray(values)
    except (ValueError, TypeError) as err:  # (a ragged list: numpy's ValueError)
        raise ParameterError(f"values: expected an array of per-tile numbers, got {type(values).__name__} ({err})") \
            from None
    if v.ndim < 2 or v.shape[-2] < 1 or v.shape[-1] < 1:
        raise ParameterError(f"values: expected an array of shape (..., tile rows, tile columns), got {v.shape}")
    if v.dtype.kind not in "biuf":
        raise ParameterError(f"values: expected numbers, got dtype {v.dtype}")
    return v


def split_tiles(values: np.ndarray, factor: int, grid: tuple[int, int] | None = None) -> np.ndarray:
    """Per-tile values (or rate codes) on a grid ``factor`` times finer: each tile's value for each of
    the ``factor x factor`` tiles it holds, the counterpart of :func:`pool_tiles`. Use it to run a model
    with 16-pixel tiles on hardware with 8-pixel shading-rate tiles (AMD's and Intel's).

    ``values`` is ``(..., th, tw)``; the result ``(..., th * factor, tw * factor)``, or cropped to
    ``grid`` ``(rows, columns)``, the fine tile grid of the frame (``tile_grid(H, W, fine_tile)``: a
    frame whose last coarse tile is partial may end a fine tile row or column sooner). A rate chosen for
    a coarse tile holds for every fine tile of it where the metric takes the worst pixel of a tile
    (FLIP, JNFLIP, LPIPS, JNYang: a part's worst is no worse); PSNR averages a tile's squared error, so
    one of its quarters may be worse than the tile (docs/runtime.md).
    """
    f = _positive("factor", factor)
    v = _tile_values(values)
    th, tw = v.shape[-2:]
    rows, cols = th * f, tw * f
    if rows * cols > MAX_SPLIT_TILES or v.size * f * f > MAX_SPLIT_TILES:  # (no frame has that many tiles)
        raise ParameterError(f"factor: {th}x{tw} tiles split {f} ways are {rows}x{cols}, past the {MAX_SPLIT_TILES} "
                             f"values split_tiles gives")
    if grid is not None:
        try:
            gr, gc = (int(_positive("grid rows", grid[0])), int(_positive("grid columns", grid[1]))) \
                if len(grid) == 2 else (0, 0)
        except (TypeError, LookupError):  # (not a pair: a number, a set; a mapping of two keys)
            gr = gc = 0
        if not (rows - f < gr <= rows and cols - f < gc <= cols):
            raise ParameterError(f"grid: expected the fine tile grid of these {th}x{tw} tiles split {f} ways "
                                 f"(rows in ({rows - f}, {rows}], columns in ({cols - f}, {cols}]), got {grid!r}")
        rows, cols = gr, gc
    # (indexing, not np.repeat then a crop: only what is returned is allocated)
    return v[..., (np.arange(rows) // f)[:, None], np.arange(cols) // f]


def hardware_tiles(model_tile: int) -> tuple[int, ...]:
    """The hardware shading-rate tile sizes a model of ``model_tile``-pixel tiles runs on
    (``sdk.load(tile_size=)``): its own, the coarser :data:`TILE_SIZES` (each hardware tile takes the
    worst of the model tiles it covers) and the finer ones down to :data:`MIN_HARDWARE_TILE` (each takes
    its model tile's values). ``hardware_tiles(16)`` is ``(4, 8, 16, 32)``: NVIDIA's 16, AMD's and
    Intel's 8."""
    if isinstance(model_tile, bool) or not isinstance(model_tile, (int, np.integer)) or model_tile not in TILE_SIZES:
        raise ParameterError(f"model_tile: expected a model's tile size, one of {list(TILE_SIZES)}, got {model_tile!r}",
                             "model_tile")
    return tuple(t for t in TILE_SIZES if t >= min(int(model_tile), MIN_HARDWARE_TILE))
