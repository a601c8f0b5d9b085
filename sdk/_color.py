"""Colour facts shared by every room: Rec.601 luma of display values and the sRGB transfer curve.

Final images are display-encoded (sRGB) in [0, 1] everywhere in rtp; metrics and baselines take
their luma from those display values, as the paper's code and Yang et al. 2019 do. The GLSL copies
of the sRGB curve (``plugins/*/shaders``) are checked against these functions by the tests.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["LUMA_WEIGHTS", "linear_to_srgb", "luma", "srgb_to_linear"]

#: Rec.601 luma weights of display-encoded R, G, B.
LUMA_WEIGHTS: tuple[float, float, float] = (0.299, 0.587, 0.114)


def luma(rgb: ArrayLike) -> np.ndarray:
    """Rec.601 luma ``0.299 R + 0.587 G + 0.114 B`` of display values in [0, 1]: ``(..., 3) -> (...)`` float32
    (``uint8`` and ``uint16`` arrays, a texture's integers, are refused, as by :func:`srgb_to_linear`: divide them
    by 255 or 65535 first)."""
    r, g, b = LUMA_WEIGHTS
    _refuse_texture_integers(rgb, "luma")  # (white uint8 was luma 255, not 1, without a word)
    a = as_numbers(rgb, "luma", np.float32)
    if a.ndim < 1 or a.shape[-1] != 3:  # a planar (3, H, W) image would be read as rows of pixels
        from ._errors import InputShapeError

        raise InputShapeError(f"luma: expected colours on the last axis (..., 3), got shape {a.shape} (a planar "
                              "(3, H, W) image: luma(np.moveaxis(image, 0, -1)))", tuple(a.shape), "(..., 3)")
    return (r * a[..., 0] + g * a[..., 1] + b * a[..., 2]).astype(np.float32, copy=False)


def as_numbers(value: ArrayLike, what: str, dtype: type[np.floating]) -> np.ndarray:
    """``value`` as a real array of ``dtype``, or an :class:`~rtp.sdk.InputDtypeError` naming ``what``
    (strings, objects and complex values were a bare numpy error, or a warning and a dropped imaginary
    part)."""
    from ._errors import InputDtypeError

    try:
        if np.iscomplexobj(value):
            raise InputDtypeError(f"{what}: expected real numbers, got complex ones")
        return np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as err:
        raise InputDtypeError(f"{what}: expected numbers, got {type(value).__name__} ({err})") from err


def _refuse_texture_integers(c: ArrayLike, what: str) -> None:
    """The ``uint8``/``uint16`` of a texture read back (its 0-255 or 0-65535) given for values in [0, 1]: an
    :class:`~rtp.sdk.InputDtypeError` naming the division."""
    dtype = getattr(c, "dtype", None)
    if dtype is not None and np.dtype(dtype) in (np.uint8, np.uint16):
        from ._errors import InputDtypeError

        top = np.iinfo(np.dtype(dtype)).max
        raise InputDtypeError(f"{what}: expected values in [0, 1], got dtype {np.dtype(dtype)} (a texture's integers: "
                              f"{what}(c / {top}))")


def _unit_values(c: ArrayLike, what: str) -> np.ndarray:
    """``c`` as float64 for the sRGB curves, which take values in [0, 1]: the ``uint8``/``uint16`` of a texture read
    back (its 0-255 or 0-65535) is an :class:`~rtp.sdk.InputDtypeError` naming the division (255 came out as
    524947 from ``srgb_to_linear``, without a word)."""
    _refuse_texture_integers(c, what)
    return as_numbers(c, what, np.float64)


def srgb_to_linear(c: ArrayLike) -> np.ndarray:
    """The sRGB decoding curve (IEC 61966-2-1) of values in [0, 1], elementwise, float32 or float64 in, float64 out
    (``uint8`` and ``uint16`` arrays, a texture's integers, are refused: divide them by 255 or 65535 first)."""
    a = _unit_values(c, "srgb_to_linear")
    return np.where(a <= 0.04045, a / 12.92, ((np.maximum(a, 0.04045) + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: ArrayLike) -> np.ndarray:
    """The sRGB encoding curve (IEC 61966-2-1) of linear values in [0, 1], elementwise, float64 out (``uint8`` and
    ``uint16`` arrays are refused, as by :func:`srgb_to_linear`)."""
    a = _unit_values(c, "linear_to_srgb")
    return np.where(a <= 0.0031308, a * 12.92, 1.055 * np.maximum(a, 0.0031308) ** (1.0 / 2.4) - 0.055)
