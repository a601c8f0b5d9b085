"""Augmentations that keep the targets true: the eight symmetries of a square crop.

A horizontal or vertical flip of a tile-aligned crop maps every VRS block onto a block of the same
shape, so each rate's target moves with its tile. A transpose (rows <-> columns) turns a W x H block
into an H x W one: the targets of 1x2 and 2x1, and of 2x4 and 4x2, swap. Channels that hold a
direction change with the image: view-space normal x points right and y up, screen motion x right
and y down (rtp.sdk.CHANNELS).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["SYMMETRIES", "augment_batch", "augment_sample"]

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
    return out


def augment_sample(x: np.ndarray, y: np.ndarray, inputs: Sequence[str], outputs: Sequence[str],
                   symmetry: int) -> tuple[np.ndarray, np.ndarray]:
    """One crop ``x`` (C, H, W) and its targets ``y`` (R, th, tw) under ``SYMMETRIES[symmetry]``."""
    transpose, flip_rows, flip_cols = SYMMETRIES[symmetry]
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
    return np.ascontiguousarray(x), np.ascontiguousarray(y)


def augment_batch(xb: np.ndarray, yb: np.ndarray, inputs: Sequence[str], outputs: Sequence[str],
                  symmetries: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`augment_sample` over a batch (square crops), one symmetry per crop."""
    pairs = [augment_sample(x, y, inputs, outputs, s) for x, y, s in zip(xb, yb, symmetries, strict=True)]
    return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])
