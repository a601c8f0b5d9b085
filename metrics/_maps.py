"""Yang, JNYang, JNFLIP, squared error and PSNR, as RT-Percept's ``api/perceptual.py`` defines them.

All functions take a reference (the 1x1-rate image) and a test (a reduced-rate image), display-encoded
sRGB in [0, 1], numpy ``(H, W, 3)`` / ``(N, H, W, 3)`` or torch ``(3, H, W)`` / ``(N, 3, H, W)``,
and return numpy or torch like the input.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, overload

import numpy as np

from rtp.sdk import DEFAULT_TILE_SIZE, luma, psnr_from_mse

from ._flip import DEFAULT_PPD, Ppd, flip_pixels, image_ppd
from ._image import as_pair
from ._pool import DEFAULT_WEBER_L, _denominator, check_weber_l, pool_tiles

if TYPE_CHECKING:  # (for a type checker only: importing rtp.metrics never imports torch)
    from torch import Tensor

__all__ = ["jnflip_map", "jnyang_map", "psnr_tiles", "squared_error_map", "yang_map"]


@overload
def squared_error_map(reference: np.ndarray, test: np.ndarray | Tensor) -> np.ndarray: ...
@overload
def squared_error_map(reference: Tensor, test: np.ndarray | Tensor) -> Tensor: ...
def squared_error_map(reference: Any, test: Any) -> Any:
    """Per-pixel squared error averaged over RGB, ``mean_c (ref - test)^2``: ``(H, W)`` float32 in [0, 1]."""
    ref, tst = as_pair(reference, test)
    d = ref.data - tst.data
    return ref.wrap((d * d).mean(axis=-1))


@overload
def psnr_tiles(reference: np.ndarray, test: np.ndarray | Tensor, tile: int = ...) -> np.ndarray: ...
@overload
def psnr_tiles(reference: Tensor, test: np.ndarray | Tensor, tile: int = ...) -> Tensor: ...
def psnr_tiles(reference: Any, test: Any, tile: int = DEFAULT_TILE_SIZE) -> Any:
    """Per-tile PSNR in dB (peak 1): ``-10 log10(mse)`` of each tile's mean squared error.

    The MSE averages over the tile's pixels and the three channels; partial edge tiles average over
    their real pixels. ``+inf`` where a tile is identical. Returns ``(ceil(H/tile), ceil(W/tile))``
    (or with a leading N) float32.
    """
    ref, tst = as_pair(reference, test)
    d = ref.data - tst.data
    mse = pool_tiles((d * d).mean(axis=-1), tile, "mean")
    return ref.wrap(psnr_from_mse(mse))


@overload
def yang_map(reference: np.ndarray, test: np.ndarray | Tensor) -> np.ndarray: ...
@overload
def yang_map(reference: Tensor, test: np.ndarray | Tensor) -> Tensor: ...
def yang_map(reference: Any, test: Any) -> Any:
    """Yang error ``|luma(ref) - luma(test)|`` with Rec.601 luma of display values: ``(H, W)`` float32 in [0, 1]."""
    ref, tst = as_pair(reference, test)
    return ref.wrap(np.abs(luma(ref.data) - luma(tst.data)))


@overload
def jnyang_map(reference: np.ndarray, test: np.ndarray | Tensor, *, weber_l: float = ...) -> np.ndarray: ...
@overload
def jnyang_map(reference: Tensor, test: np.ndarray | Tensor, *, weber_l: float = ...) -> Tensor: ...
def jnyang_map(reference: Any, test: Any, *, weber_l: float = DEFAULT_WEBER_L) -> Any:
    """Weber-corrected Yang: :func:`yang_map` divided by (4x4 mean reference luma + ``weber_l``).

    Units: multiples of the local luminance (a just-noticeable-difference scale); >= 0, unbounded
    (at most ``1 / weber_l``).
    """
    ref, tst = as_pair(reference, test)
    err = np.abs(luma(ref.data) - luma(tst.data))
    return ref.wrap(err / _denominator(ref.data, check_weber_l(weber_l)))


@overload
def jnflip_map(reference: np.ndarray, test: np.ndarray | Tensor, *, ppd: Ppd = ..., weber_l: float = ...) -> np.ndarray: ...
@overload
def jnflip_map(reference: Tensor, test: np.ndarray | Tensor, *, ppd: Ppd = ..., weber_l: float = ...) -> Tensor: ...
def jnflip_map(reference: Any, test: Any, *, ppd: Ppd = DEFAULT_PPD, weber_l: float = DEFAULT_WEBER_L) -> Any:
    """Weber-corrected FLIP (JNFLIP): the LDR-FLIP map divided by (4x4 mean reference luma + ``weber_l``).

    ``ppd`` as in :func:`~rtp.metrics.flip_map`. Returns ``(H, W)`` float32 >= 0.
    """
    ref, tst = as_pair(reference, test)
    value = image_ppd(ppd, ref.shape_hw[1])
    env = check_weber_l(weber_l)  # (before FLIP runs, not after seconds of it)
    flip = np.stack([flip_pixels(r, t, value) for r, t in zip(ref.data, tst.data)])
    return ref.wrap(flip / _denominator(ref.data, env))
