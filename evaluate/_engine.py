"""Example shading rates of an engine's own, to meet rtp's in the hardware's combiner (docs/runtime.md "The
engine's own rates: the hardware's combiners"): fixed foveation rings and motion-blur rates. ``rtp play
--engine-rates`` and ``bench/combine.py`` use them; they are examples of what engines write, not rtp's advice."""

from __future__ import annotations

import numpy as np

from rtp import sdk

from ._baselines import _tile_mean

__all__ = ["ENGINE_IMAGES", "engine_rates", "foveation_rates", "motion_rates"]

#: The engine images :func:`engine_rates` makes.
ENGINE_IMAGES: tuple[str, ...] = ("foveation", "motion")

_C = sdk.RATE_CODES


def foveation_rates(th: int, tw: int) -> np.ndarray:
    """Fixed foveated rings over a ``th x tw`` tile grid, uint8 codes: 1x1, then 2x2, then 4x4 by the tile centre's
    distance from the frame's centre over the half-diagonal (< 0.4, < 0.7, beyond)."""
    if not all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1 for n in (th, tw)):
        raise sdk.ParameterError(f"th, tw: expected a tile grid of positive integers, got {th!r} x {tw!r}", "th")
    y, x = np.mgrid[0:th, 0:tw]
    r = np.hypot((x + 0.5) / tw - 0.5, (y + 0.5) / th - 0.5) / np.hypot(0.5, 0.5)
    return np.select([r < 0.4, r < 0.7], [_C["1x1"], _C["2x2"]], _C["4x4"]).astype(np.uint8)


def motion_rates(motion_x: np.ndarray, motion_y: np.ndarray, tile: int) -> np.ndarray:
    """Motion-blur rates from a frame's motion vectors (pixels a frame, ``sdk.CHANNELS``' ``motion.x``/``.y``), uint8
    codes on ``tile``-pixel tiles: per tile and axis 2 where the mean screen motion along it is >= 2 pixels a frame,
    4 from 8; a 4 beside a 1 becomes 2 (no device shades 4x1 or 1x4)."""
    if np.ndim(motion_x) != 2 or np.shape(motion_x) != np.shape(motion_y):
        raise sdk.InputShapeError(f"motion_x and motion_y: expected two (H, W) planes of one size, got "
                                  f"{np.shape(motion_x)} and {np.shape(motion_y)}", np.shape(motion_y), "(H, W)")
    h0, w0 = np.shape(motion_x)[:2]
    th, tw = sdk.tile_grid(h0, w0, tile)

    def size(m: np.ndarray) -> np.ndarray:
        h, w = m.shape
        a = np.abs(m)
        pad = np.pad(a, ((0, th * tile - h), (0, tw * tile - w)), mode="edge")
        mean = pad.reshape(th, tile, tw, tile).mean(axis=(1, 3))
        if h % tile or w % tile:  # a partial edge tile: the mean of its own pixels (the edge copies weighed
            # its last row or column up to tile times over)
            real = _tile_mean(a, tile)
            if h % tile:
                mean[-1, :] = real[-1, :]
            if w % tile:
                mean[:, -1] = real[:, -1]
        return np.select([mean >= 8.0, mean >= 2.0], [4, 2], 1)

    w, h = size(np.asarray(motion_x)), size(np.asarray(motion_y))
    w = np.where((w == 4) & (h == 1), 2, w)
    h = np.where((h == 4) & (w == 1), 2, h)
    return ((np.log2(w).astype(np.uint8) << 2) | np.log2(h).astype(np.uint8)).astype(np.uint8)


def engine_rates(kind: str, motion_x: np.ndarray, motion_y: np.ndarray, tile: int) -> np.ndarray:
    """The engine image ``kind`` (:data:`ENGINE_IMAGES`) of a frame with these motion vectors, on ``tile``-pixel
    tiles."""
    if kind == "foveation":
        h, w = np.shape(motion_x)[:2]
        return foveation_rates(*sdk.tile_grid(h, w, tile))
    if kind == "motion":
        return motion_rates(motion_x, motion_y, tile)
    raise sdk.ParameterError(f"engine_rates: expected one of {', '.join(ENGINE_IMAGES)}, got {kind!r}", "engine_rates")
