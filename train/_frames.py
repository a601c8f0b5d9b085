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

__all__ = ["Frame", "crop_batch"]

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
        # (a slice where the planes are consecutive, as they are in every recipe: a view, not a gather)
        self._dense_sel = _selector(self._dense_idx)
        #: which planes are packed in which cells: frames of one layout unpack their crops together
        self._layout = tuple((cell, tuple(idx)) for cell, _, idx, _ in self._groups)

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


def _selector(idx: list[int]) -> slice | list[int]:
    """``idx`` as a slice where it is a run of consecutive indices (indexing with it gives a view)."""
    return slice(idx[0], idx[-1] + 1) if idx and idx == list(range(idx[0], idx[-1] + 1)) else idx


def crop_batch(frames: Sequence[Frame], ys: Sequence[int], xs: Sequence[int], side: int) -> np.ndarray:
    """``frames[b].crop(ys[b], xs[b], side)`` for every ``b``, as one float16 ``(B, C, side, side)``
    array. A training step's batch: the packed planes of the crops of frames of one layout are unpacked
    in a few array operations for the whole batch, not a dozen per crop (a step of the shipped JNYang
    recipe, 128 crops of 64 pixels, cut its batch in about half the time)."""
    if not frames:
        raise ValueError("crop_batch: expected at least one frame")
    out = np.zeros((len(frames), frames[0].shape[0], side, side), np.float16)
    together: dict[tuple[tuple[int, tuple[int, ...]], ...], list[int]] = {}
    for b, (f, y, x) in enumerate(zip(frames, ys, xs)):
        if not f._groups or any(y % cell or x % cell or side % cell for cell, *_ in f._groups):
            out[b] = f.crop(y, x, side)
            continue
        out[b, f._dense_sel] = f._dense[:, y : y + side, x : x + side]
        together.setdefault(f._layout, []).append(b)
    for layout, rows in together.items():
        for g, (cell, idx) in enumerate(layout):
            n = side // cell
            spots = frames[rows[0]]._groups[g][1]
            values = np.stack([frames[b]._groups[g][3][:, :, ys[b] // cell : ys[b] // cell + n,
                                                        xs[b] // cell : xs[b] // cell + n] for b in rows])
            sel = _selector(list(idx))
            if len(rows) == len(frames) and isinstance(sel, slice):  # (every crop, consecutive planes: a view)
                view = out[:, sel].reshape(len(rows), len(idx), n, cell, n, cell)
                for k, (r, q) in enumerate(spots):
                    view[:, :, :, r, :, q] = values[:, :, k]
                continue
            cells = np.zeros((len(rows), len(idx), cell * cell, n, n), np.float16)
            cells[:, :, [r * cell + q for r, q in spots]] = values
            # (rows, planes, cell row, cell column, n, n) -> (rows, planes, n, cell row, n, cell column)
            out[np.ix_(rows, idx)] = cells.reshape(len(rows), len(idx), cell, cell, n, n).transpose(
                0, 1, 4, 2, 5, 3).reshape(len(rows), len(idx), side, side)
    return out


def _off_spots_zero(plane: np.ndarray, cell: int, spots: tuple[tuple[int, int], ...]) -> bool:
    """Whether ``plane`` is zero on every pixel of every cell but the value pixels."""
    h, w = plane.shape
    cells = plane.reshape(h // cell, cell, w // cell, cell)
    mask = np.ones((cell, cell), bool)
    for r, q in spots:
        mask[r, q] = False
    return not np.any(cells.transpose(1, 3, 0, 2)[mask])
