"""Tiles: the sizes a model may use and the grid maths every room shares.

A frame of ``H x W`` pixels has ``ceil(H / w) x ceil(W / w)`` tiles of ``w x w``. When ``H`` or ``W``
is not a multiple of ``w`` the last tile row / column is partial: it covers only the real pixels
(``tile_extents``), the model sees the frame padded up to ``padded_size`` by repeating its last row
and column (docs/runtime.md), and no tile of the real frame is dropped.
"""

from __future__ import annotations

import numpy as np

from ._errors import ParameterError

__all__ = ["DEFAULT_TILE_SIZE", "TILE_SIZES", "padded_size", "tile_extents", "tile_grid"]

#: The tile size of the paper and of NVIDIA's VRS hardware (16x16 pixels share one rate).
DEFAULT_TILE_SIZE = 16
#: Tile sizes a model's metadata may declare (powers of two, the network halves resolution per block).
TILE_SIZES: tuple[int, ...] = (1, 2, 4, 8, 16, 32)


def _positive(name: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or int(value) < 1:
        raise ParameterError(f"{name}: expected a positive integer, got {value!r}")
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
