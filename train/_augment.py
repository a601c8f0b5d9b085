"""Augmentations that keep the targets true: the eight symmetries of a square crop.

A horizontal or vertical flip of a tile-aligned crop maps every VRS block onto a block of the same
shape, so each rate's target moves with its tile. A transpose (rows <-> columns) turns a W x H block
into an H x W one: the targets of 1x2 and 2x1, and of 2x4 and 4x2, swap. Channels that hold a
direction change with the image: view-space normal x points right and y up, screen motion x right
and y down (rtp.sdk.CHANNELS). A ``.dx`` / ``.dy`` plane (rtp.sdk.pixel_differences) holds each pixel's
difference to its right / lower neighbour: a transpose swaps the two, and a flip moves each value
to the pixel its pair now begins at (one over), so that a 2-pixel block's difference stays on its
first pixel. The pixel past the crop that the new last column (row) would need is not in it: that
column (row) reads 0, as a frame's last one does.

The packed planes (``.blocks``: six values on the first pixels of each 4x4 cell; ``.tiles``: twelve on
the first pixels of each 16x16 tile) flip by cells: the cells (tiles) change places and each keeps
its layout, because a cell's values are unchanged by a flip (a rate's blocks, aligned to the cell,
are mirrored onto the same blocks; a tile's mean and maximum over its cells do not depend on their
order). A transpose would swap values inside a cell, so it refuses them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rtp.sdk import BLOCK_CELL, BLOCK_TILE

__all__ = ["SYMMETRIES", "augment_batch", "augment_sample", "move_tiles"]

#: (transpose, flip rows, flip columns), applied in that order; index 0 is the identity, index 1 the
#: left-right mirror (``TrainConfig.mirror`` draws from the first two).
SYMMETRIES: tuple[tuple[bool, bool, bool], ...] = tuple(
    (t, v, h) for t in (False, True) for v in (False, True) for h in (False, True)
)
_SWAPPED_RATES = {"1x2": "2x1", "2x1": "1x2", "2x4": "4x2", "4x2": "2x4"}


def _transpose_channels(x: np.ndarray, inputs: Sequence[str]) -> np.ndarray:
    """Transpose (C, H, W) and fix the channels that hold an image direction."""
    out = np.ascontiguousarray(x.swapaxes(-1, -2))
    src = {name: x.swapaxes(-1, -2)[i] for i, name in enumerate(inputs)}
    for i, name in enumerate(inputs):
        # the new right is the old down, the new down the old right (view-space y points up)
        if name == "normal.x" and "normal.y" in src:
            out[i] = -src["normal.y"]
        elif name == "normal.y" and "normal.x" in src:
            out[i] = -src["normal.x"]
        elif name == "motion.x" and "motion.y" in src:
            out[i] = src["motion.y"]
        elif name == "motion.y" and "motion.x" in src:
            out[i] = src["motion.x"]
        elif name in ("normal.x", "normal.y", "motion.x", "motion.y"):
            raise ValueError(f"augment: transposing needs both {name[:-1]}x and {name[:-1]}y among the inputs")
        elif name.endswith((".dx", ".dy")):  # the difference to the right neighbour is the old one to the lower
            other = name[:-1] + ("y" if name.endswith("x") else "x")
            if other not in src:
                raise ValueError(f"augment: transposing needs both {name[:-1]}x and {name[:-1]}y among the inputs")
            out[i] = src[other]
    return out


def _shift_differences(plane: np.ndarray, axis: int) -> np.ndarray:
    """A flipped ``.dx`` (``axis`` 1) or ``.dy`` (``axis`` 0) plane, each pixel's difference to its next
    neighbour: the plain flip left each value on the second pixel of its pair; moved one back, the last
    column (row), whose neighbour lies outside the crop, reads 0 (as a frame's last one does)."""
    out = np.zeros_like(plane)
    if axis == 0:
        out[:-1] = plane[1:]
    else:
        out[:, :-1] = plane[:, 1:]
    return out


def move_tiles(t: np.ndarray, symmetry: int) -> np.ndarray:
    """A per-tile array ``(..., th, tw)`` (targets of one rate, a mask of the scored tiles) moved with its crop
    under ``SYMMETRIES[symmetry]`` (no rate renamed: :func:`augment_sample` swaps the transposed rates)."""
    transpose, flip_rows, flip_cols = SYMMETRIES[symmetry]
    if transpose:
        t = t.swapaxes(-1, -2)
    if flip_rows:
        t = t[..., ::-1, :]
    if flip_cols:
        t = t[..., ::-1]
    return t


def packed_cell(name: str) -> int:
    """The cell a packed plane keeps its values in (``.blocks``: 4, ``.tiles``: 16), or 0 for a plain plane."""
    return BLOCK_CELL if name.endswith(".blocks") else BLOCK_TILE if name.endswith(".tiles") else 0


def _flip_cells(plane: np.ndarray, cell: int, axis: int) -> np.ndarray:
    """``plane`` (H, W) with the order of its ``cell``-pixel cells reversed along ``axis``, each cell as it was."""
    h, w = plane.shape
    if axis == 0:
        return plane.reshape(h // cell, cell, w)[::-1].reshape(h, w)
    return plane.reshape(h, w // cell, cell)[:, ::-1].reshape(h, w)


def augment_sample(x: np.ndarray, y: np.ndarray, inputs: Sequence[str], outputs: Sequence[str],
                   symmetry: int) -> tuple[np.ndarray, np.ndarray]:
    """One crop ``x`` (C, H, W) and its targets ``y`` (R, th, tw) under ``SYMMETRIES[symmetry]``."""
    transpose, flip_rows, flip_cols = SYMMETRIES[symmetry]
    packed = [(i, packed_cell(n)) for i, n in enumerate(inputs) if packed_cell(n)]
    if packed and (transpose or (flip_rows or flip_cols) and any(x.shape[1 + a] % c for _, c in packed for a in (0, 1))):
        names = ", ".join(inputs[i] for i, _ in packed)
        raise ValueError(f"augment: {names} pack values per cell or tile: they flip on whole cells, never transpose"
                         if transpose else f"augment: {names} flip on whole cells; the crop {x.shape[1:]} is not")
    original = x
    if transpose:
        x = _transpose_channels(x, inputs)
        order = [list(outputs).index(_SWAPPED_RATES.get(r, r)) for r in outputs]
        y = y[order].swapaxes(-1, -2)
    sign = np.ones(len(inputs), x.dtype)
    if flip_rows:
        x, y = x[:, ::-1], y[:, ::-1]
        sign[[i for i, n in enumerate(inputs) if n in ("normal.y", "motion.y")]] *= -1
    if flip_cols:
        x, y = x[:, :, ::-1], y[:, :, ::-1]
        sign[[i for i, n in enumerate(inputs) if n in ("normal.x", "motion.x")]] *= -1
    if (sign != 1).any():
        x = x * sign[:, None, None]
    differences = [(i, 1 if n.endswith(".dx") else 0) for i, n in enumerate(inputs) if n.endswith((".dx", ".dy"))]
    if differences and (flip_rows or flip_cols):
        x = np.array(x)  # a copy: the flipped differences move one pixel back along their axis
        for i, axis in differences:
            if flip_cols if axis else flip_rows:
                x[i] = _shift_differences(x[i], axis)
    if packed and (flip_rows or flip_cols):
        x = np.array(x)  # a copy: the packed planes are rebuilt from the crop's own
        for i, c in packed:
            plane = original[i]
            if flip_rows:
                plane = _flip_cells(plane, c, 0)
            if flip_cols:
                plane = _flip_cells(plane, c, 1)
            x[i] = plane
    return np.ascontiguousarray(x), np.ascontiguousarray(y)


def augment_batch(xb: np.ndarray, yb: np.ndarray, inputs: Sequence[str], outputs: Sequence[str],
                  symmetries: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`augment_sample` over a batch (square crops), one symmetry per crop."""
    pairs = [augment_sample(x, y, inputs, outputs, s) for x, y, s in zip(xb, yb, symmetries, strict=True)]
    return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])
