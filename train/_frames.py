"""Training frames held in memory: float16 planes, ``.blocks`` and ``.tiles`` planes packed to what they hold.

Training reads every frame of the split into memory once (:class:`rtp.train._loop._Split`). A
``.blocks`` plane (:func:`rtp.sdk.block_variances`) holds values at only
``len(sdk.BLOCK_RATES)`` of the ``sdk.BLOCK_CELL ** 2`` pixels of each cell, zeros elsewhere, so it
is kept packed, ``(6, H / 4, W / 4)``: 6/16 of a dense plane's memory (about 0.9 GB instead of
2.4 GB per plane on the shipped dataset), which lets eight dense planes and two ``.blocks`` planes
fit in the 24 GB of the project's machines. A ``.tiles`` plane (:func:`rtp.sdk.tile_variances`)
likewise holds twelve values per 16x16 tile: packed ``(12, H / 16, W / 16)``, 12/256 of a dense plane.
Crops and whole frames are unpacked exactly; a plane that is not zero off the value pixels (or a
frame whose sides are not multiples of the cell) stays dense.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rtp import sdk

__all__ = ["Frame"]

#: plane suffix -> (its cell, the (row, column) of each value pixel inside a cell)
_LAYOUTS: dict[str, tuple[int, tuple[tuple[int, int], ...]]] = {
    ".blocks": (sdk.BLOCK_CELL, tuple((k // sdk.BLOCK_CELL, k % sdk.BLOCK_CELL) for k in range(len(sdk.BLOCK_RATES)))),
    ".tiles": (sdk.BLOCK_TILE, tuple((j // sdk.BLOCK_CELL, j % sdk.BLOCK_CELL) for j in range(2 * len(sdk.BLOCK_RATES)))),
}


class Frame:
    """One frame's input planes, ``(C, H, W)`` float16 when unpacked, in the order given."""

    def __init__(self, x: np.ndarray, names: Sequence[str]) -> None:
        if x.ndim != 3 or x.shape[0] != len(names):
            raise ValueError(f"expected planes of shape ({len(names)}, H, W) for {list(names)}, got {x.shape}")
        c, h, w = x.shape
        self.shape: tuple[int, int, int] = (c, h, w)
        #: per layout: (the planes packed, their values (planes, spots, H / cell, W / cell))
        self._groups: list[tuple[int, tuple[tuple[int, int], ...], list[int], np.ndarray]] = []
        for suffix, (cell, spots) in _LAYOUTS.items():
            idx = [i for i, n in enumerate(names) if n.endswith(suffix) and h % cell == 0 and w % cell == 0
                   and _off_spots_zero(x[i], cell, spots)]
            if idx:
                values = np.stack([np.stack([x[i][r::cell, q::cell] for r, q in spots]) for i in idx]).astype(np.float16)
                self._groups.append((cell, spots, idx, values))
        packed = {i for _, _, idx, _ in self._groups for i in idx}
        self._dense_idx = [i for i in range(c) if i not in packed]
        self._dense = np.ascontiguousarray(x[self._dense_idx], dtype=np.float16)

    @property
    def nbytes(self) -> int:
        """The memory the frame holds."""
        return int(self._dense.nbytes + sum(v.nbytes for *_, v in self._groups))

    def crop(self, y: int, x: int, side: int) -> np.ndarray:
        """The planes of the ``side`` x ``side`` window at row ``y``, column ``x``: float16 ``(C, side, side)``."""
        if not self._groups:
            return self._dense[:, y : y + side, x : x + side]
        if any(y % cell or x % cell or side % cell for cell, *_ in self._groups):
            return self.full()[:, y : y + side, x : x + side]
        out = np.zeros((self.shape[0], side, side), np.float16)
        out[self._dense_idx] = self._dense[:, y : y + side, x : x + side]
        for cell, spots, idx, values in self._groups:
            cy, cx, n = y // cell, x // cell, side // cell
            for k, (r, q) in enumerate(spots):
                out[idx, r::cell, q::cell] = values[:, k, cy : cy + n, cx : cx + n]
        return out

    def full(self) -> np.ndarray:
        """Every plane of the frame, float16 ``(C, H, W)``."""
        if not self._groups:
            return self._dense
        out = np.zeros(self.shape, np.float16)
        out[self._dense_idx] = self._dense
        for cell, spots, idx, values in self._groups:
            for k, (r, q) in enumerate(spots):
                out[idx, r::cell, q::cell] = values[:, k]
        return out


def _off_spots_zero(plane: np.ndarray, cell: int, spots: tuple[tuple[int, int], ...]) -> bool:
    """Whether ``plane`` is zero on every pixel of every cell but the value pixels."""
    h, w = plane.shape
    cells = plane.reshape(h // cell, cell, w // cell, cell)
    mask = np.ones((cell, cell), bool)
    for r, q in spots:
        mask[r, q] = False
    return not np.any(cells.transpose(1, 3, 0, 2)[mask])
