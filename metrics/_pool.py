"""Per-tile pooling and the Weber correction.

Tiles are ``tile x tile`` pixels anchored at the top-left corner. A frame that is not a multiple of
the tile size gets ``ceil(H / tile) x ceil(W / tile)`` tiles, like the SDK's rate images; the partial
tiles on the right and bottom edges are pooled over their real pixels only (no padding enters a max
or a mean).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np

from rtp.sdk import (
    InputChannelError,
    InputDtypeError,
    InputShapeError,
    NonFiniteInputError,
    luma,
    tile_extents,
)

from ._errors import InputRangeError, MetricParameterError
from ._image import RANGE_TOLERANCE, _is_torch, as_batch

if TYPE_CHECKING:  # (for a type checker only: importing rtp.metrics never imports torch)
    import numpy.typing as npt
    from torch import Tensor

__all__ = [
    "DEFAULT_WEBER_L",
    "PAPER_WEBER_L",
    "WEBER_BLOCK",
    "pool_tiles",
    "weber_denominator",
]

#: Default environment luminance l of the Weber correction (display-luma units, 0..1). Intel's
#: VALAR implementation of Yang et al. 2019 ships l = 0.02; it keeps near-black regions from
#: dividing by ~0. See docs/metrics.md.
DEFAULT_WEBER_L = 0.02
#: The value RT-Percept's training code used (effectively no environment term).
PAPER_WEBER_L = 1e-10
#: Side of the block whose mean reference luma is the Weber denominator.
WEBER_BLOCK = 4
#: The smallest ``l`` :func:`check_weber_l` takes: float32's smallest normal number. A JN value is at
#: most ``1 / l`` and is stored as float32; a smaller ``l`` became 0 in the float32 denominator (NaN
#: and infinite maps on black) or gave ``1 / l`` past float32's range.
MIN_WEBER_L = float(np.finfo(np.float32).tiny)

Reduce = Literal["max", "mean"]


def _check_tile(tile: int) -> int:
    if isinstance(tile, bool) or not isinstance(tile, (int, np.integer)) or int(tile) < 1:
        raise MetricParameterError(f"tile size must be a positive integer, got {tile!r}")
    return int(tile)


def _pool_np(values: np.ndarray, tile: int, reduce: Reduce) -> np.ndarray:
    h, w = values.shape[-2:]
    # a tile past an axis's length pools it whole: clamped on each axis, the padding is never more than the last
    # tile's (one clamp for both padded a 1x3000 map pooled by 3000 to 3000x3000 pixels)
    tile_h, tile_w = min(tile, h), min(tile, w)
    th, tw = -(-h // tile_h), -(-w // tile_w)
    ph, pw = th * tile_h - h, tw * tile_w - w
    lead = values.shape[:-2]
    if reduce == "max":
        v = values
        if ph or pw:
            # Padding with -inf never wins a max, so partial tiles pool over real pixels only.
            v = np.pad(values, [(0, 0)] * len(lead) + [(0, ph), (0, pw)], constant_values=-np.inf)
        return v.reshape(*lead, th, tile_h, tw, tile_w).max(axis=(-3, -1))
    v = values.astype(np.float64)
    if ph or pw:
        v = np.pad(v, [(0, 0)] * len(lead) + [(0, ph), (0, pw)])
    sums = v.reshape(*lead, th, tile_h, tw, tile_w).sum(axis=(-3, -1))
    return sums / np.outer(tile_extents(h, tile_h), tile_extents(w, tile_w))


@overload
def pool_tiles(values: np.ndarray, tile: int, reduce: Reduce = ...) -> np.ndarray: ...
@overload
def pool_tiles(values: Tensor, tile: int, reduce: Reduce = ...) -> Tensor: ...
@overload
def pool_tiles(values: npt.ArrayLike, tile: int, reduce: Reduce = ...) -> np.ndarray: ...
def pool_tiles(values: Any, tile: int, reduce: Reduce = "max") -> Any:
    """Pool a per-pixel map over ``tile x tile`` tiles.

    Args:
        values: map of shape ``(..., H, W)`` (numpy or torch).
        tile: tile side in pixels (any positive integer).
        reduce: ``"max"`` (the paper's pooling for every metric but PSNR) or ``"mean"``.

    Returns:
        ``(..., ceil(H / tile), ceil(W / tile))`` float32, same container as ``values``. Edge tiles
        pool over the pixels that exist. NaN propagates into its tile.
    """
    tile = _check_tile(tile)
    if reduce not in ("max", "mean"):
        raise MetricParameterError(f"reduce must be 'max' or 'mean', got {reduce!r}")
    device = None
    if _is_torch(values):
        device = values.device
        arr = values.detach().to("cpu").float().numpy()
    else:
        try:
            arr = np.asarray(values)
        except (TypeError, ValueError) as err:  # a ragged list
            raise InputDtypeError(f"values: expected a map of numbers, got {type(values).__name__} ({err})") from err
    if arr.dtype.kind not in "biuf":
        raise InputDtypeError(f"values: expected a map of numbers, got dtype {arr.dtype}")
    if arr.dtype.kind != "f":  # (an integer map's partial tiles are padded with -inf)
        arr = arr.astype(np.float32)
    if arr.ndim < 2 or arr.shape[-1] == 0 or arr.shape[-2] == 0:
        raise InputShapeError(
            f"expected a map of shape (..., H, W) with H, W >= 1, got {arr.shape}",
            actual=tuple(arr.shape),
            expected="(..., H, W)",
        )
    out = _pool_np(arr, tile, reduce).astype(np.float32)
    if device is not None:
        import torch

        return torch.from_numpy(out).to(device)
    return out


def check_weber_l(weber_l: float) -> float:
    """Validate the environment luminance ``l``: a finite number at least float32's smallest normal number
    (about 1.18e-38: a JN value, at most ``1 / l``, is stored as float32)."""
    if isinstance(weber_l, (bool, np.bool_)):  # (True was taken for l = 1)
        raise MetricParameterError(f"weber_l must be a number, got {weber_l!r}")
    try:
        value = float(weber_l)
    except (TypeError, ValueError, OverflowError):  # (OverflowError: an int past float's range)
        raise MetricParameterError(f"weber_l must be a number, got {weber_l!r}") from None
    if not math.isfinite(value) or value <= 0.0:
        raise MetricParameterError(f"weber_l (environment luminance l) must be finite and > 0, got {weber_l!r}")
    if value < MIN_WEBER_L:  # (1e-300 gave a denominator of 0 in float32: NaN where black pixels agree, inf elsewhere)
        raise MetricParameterError(f"weber_l (environment luminance l) must be at least {MIN_WEBER_L:.4g} (float32's "
                                   f"smallest normal number: a JN value, at most 1 / l, is stored as float32), got "
                                   f"{weber_l!r}; the paper's 'no environment term' is {PAPER_WEBER_L:g}")
    return value


@overload
def weber_denominator(reference: np.ndarray, weber_l: float = ...) -> np.ndarray: ...
@overload
def weber_denominator(reference: Tensor, weber_l: float = ...) -> Tensor: ...
@overload
def weber_denominator(reference: npt.ArrayLike, weber_l: float = ...) -> np.ndarray: ...
def weber_denominator(reference: Any, weber_l: float = DEFAULT_WEBER_L) -> Any:
    """Per-pixel Weber denominator ``L + l`` of reference images.

    ``L`` is the mean Rec.601 luma of the reference over the 4x4 block containing the pixel
    (avgpool 4x4, then nearest upsampling back to full size). When H or W is not a multiple of 4
    the last block row/column is averaged over its real pixels only.

    Args:
        reference: display-encoded RGB in [0, 1], numpy ``(..., H, W, 3)`` float, or a torch tensor
            ``(3, H, W)`` / ``(N, 3, H, W)`` as the map functions take it. Integer images (8-bit: divide
            by 255), another channel count, empty images, NaN/inf and values outside [0, 1] are refused
            as by the map functions.
        weber_l: environment luminance ``l`` > 0 in display-luma units.

    Returns:
        ``(..., H, W)`` float32, strictly positive; for a torch tensor a tensor ``(H, W)`` /
        ``(N, H, W)`` on its device, as the map functions return.
    """
    weber_l = check_weber_l(weber_l)
    if _is_torch(reference):  # (its planar (3, H, W) was read as an (H, W, 3) image: refused, or misread)
        batch = as_batch(reference, "reference")
        return batch.wrap(_denominator(batch.data, weber_l))
    try:
        arr = np.asarray(reference)
    except (TypeError, ValueError) as err:  # a ragged list
        raise InputDtypeError(f"reference: expected an image of floats in [0, 1], got {type(reference).__name__} "
                              f"({err})") from err
    if arr.dtype.kind != "f":  # (uint8 gave L in 0..255: a denominator 255 times too large, no error)
        raise InputDtypeError(f"reference: expected a floating-point image with values in [0, 1], got dtype {arr.dtype}"
                              + (" (divide 8-bit images by 255)" if arr.dtype == np.uint8 else ""))
    if arr.ndim < 3 or 0 in arr.shape[-3:-1]:  # (an empty frame was tile_grid's ParameterError "height")
        raise InputShapeError(f"reference: expected an image (..., H, W, 3) with H, W >= 1, got shape {arr.shape}",
                              tuple(arr.shape), "(..., H, W, 3)")
    if arr.shape[-1] != 3:  # (RGBA was luma's InputShapeError; the map functions' is InputChannelError)
        raise InputChannelError(f"reference: expected 3 channels (RGB) on the last axis, got shape {arr.shape}",
                                tuple(arr.shape), "(..., H, W, 3)")
    if arr.size:
        if not np.isfinite(arr).all():
            raise NonFiniteInputError("reference: contains NaN or infinite values")
        lo, hi = float(arr.min()), float(arr.max())
        if lo < -RANGE_TOLERANCE or hi > 1.0 + RANGE_TOLERANCE:
            raise InputRangeError(f"reference: expected display-encoded values in [0, 1], got [{lo:g}, {hi:g}]",
                                  low=lo, high=hi)
    return _denominator(arr, weber_l)


def _denominator(reference: np.ndarray, weber_l: float) -> np.ndarray:
    """:func:`weber_denominator` of a validated reference and ``l``."""
    y = luma(reference)
    if y.ndim < 2:
        raise InputShapeError(f"reference: expected an image (..., H, W, 3), got shape {np.shape(reference)}",
                              tuple(np.shape(reference)), "(..., H, W, 3)")
    h, w = y.shape[-2:]
    means = _pool_np(y, WEBER_BLOCK, "mean")
    up = np.repeat(np.repeat(means, WEBER_BLOCK, axis=-2), WEBER_BLOCK, axis=-1)[..., :h, :w]
    return (up + weber_l).astype(np.float32)
