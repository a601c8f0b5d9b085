"""Training frames held in memory: float16 planes, ``.blocks`` planes packed to what they hold.

Training reads every frame of the split into memory once (:class:`rtp.train._loop._Split`). A
``.blocks`` plane (:func:`rtp.sdk.block_variances`) holds values at only
``len(sdk.BLOCK_RATES)`` of the ``sdk.BLOCK_CELL ** 2`` pixels of each cell, zeros elsewhere, so it
is kept packed, ``(6, H / 4, W / 4)``: 6/16 of a dense plane's memory (about 0.9 GB instead of
2.4 GB per plane on the shipped dataset), which lets eight dense planes and two ``.blocks`` planes
fit in the 24 GB of the project's machines. Crops and whole frames are unpacked exactly; a plane
that is not zero off the value pixels (or a frame whose sides are not multiples of the cell) stays
dense.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rtp import sdk

__all__ = ["Frame"]

_CELL = sdk.BLOCK_CELL
_VALUES = len(sdk.BLOCK_RATES)
#: (row, column) of each value pixel inside a cell, in sdk.block_variances' raster order
_SPOTS = tuple((k // _CELL, k % _CELL) for k in range(_VALUES))


class Frame:
    """One frame's input planes, ``(C, H, W)`` float16 when unpacked, in the order given."""

    def __init__(self, x: np.ndarray, names: Sequence[str]) -> None:
        if x.ndim != 3 or x.shape[0] != len(names):
            raise ValueError(f"expected planes of shape ({len(names)}, H, W) for {list(names)}, got {x.shape}")
        c, h, w = x.shape
        self.shape: tuple[int, int, int] = (c, h, w)
        packable = h % _CELL == 0 and w % _CELL == 0
        self._packed: list[int] = [i for i, n in enumerate(names) if n.endswith(".blocks") and packable
                                   and _off_spots_zero(x[i])]
        self._dense_idx = [i for i in range(c) if i not in self._packed]
        self._dense = np.ascontiguousarray(x[self._dense_idx], dtype=np.float16)
        self._cells = np.stack([np.stack([x[i][r::_CELL, q::_CELL] for r, q in _SPOTS]) for i in self._packed]
                               ).astype(np.float16) if self._packed else None

    @property
    def nbytes(self) -> int:
        """The memory the frame holds."""
        return int(self._dense.nbytes + (self._cells.nbytes if self._cells is not None else 0))

    def crop(self, y: int, x: int, side: int) -> np.ndarray:
        """The planes of the ``side`` x ``side`` window at row ``y``, column ``x``: float16 ``(C, side, side)``."""
        if self._cells is None:
            return self._dense[:, y : y + side, x : x + side]
        if y % _CELL or x % _CELL or side % _CELL:
            return self.full()[:, y : y + side, x : x + side]
        out = np.zeros((self.shape[0], side, side), np.float16)
        out[self._dense_idx] = self._dense[:, y : y + side, x : x + side]
        cy, cx, n = y // _CELL, x // _CELL, side // _CELL
        for k, (r, q) in enumerate(_SPOTS):
            out[self._packed, r::_CELL, q::_CELL] = self._cells[:, k, cy : cy + n, cx : cx + n]
        return out

    def full(self) -> np.ndarray:
        """Every plane of the frame, float16 ``(C, H, W)``."""
        if self._cells is None:
            return self._dense
        out = np.zeros(self.shape, np.float16)
        out[self._dense_idx] = self._dense
        for k, (r, q) in enumerate(_SPOTS):
            out[self._packed, r::_CELL, q::_CELL] = self._cells[:, k]
        return out


def _off_spots_zero(plane: np.ndarray) -> bool:
    """Whether ``plane`` is zero on every pixel of every cell but the value pixels."""
    h, w = plane.shape
    cells = plane.reshape(h // _CELL, _CELL, w // _CELL, _CELL)
    mask = np.ones((_CELL, _CELL), bool)
    for r, q in _SPOTS:
        mask[r, q] = False
    return not np.any(cells.transpose(1, 3, 0, 2)[mask])
