"""Pictures: images read to float values, written in the format their file extension names, and
matplotlib figures as images.

Shared by the dataset preview, the paper's dataset layout, ``rtp metric`` and :mod:`rtp.evaluate`'s figures.
"""

from __future__ import annotations

import logging
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from rtp.sdk import ParameterError
from rtp.sdk.files import atomic_output, check_output

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from PIL import Image

__all__ = ["check_image_output", "figure_image", "image_values", "read_image_values", "save_image"]

log = logging.getLogger(__name__)

#: Pillow's modes of one 16-bit integer channel (a 16-bit greyscale PNG or TIFF)
_MODES_16 = ("I;16", "I;16L", "I;16B", "I;16N")
#: Pillow's raw modes of the 16-bit PNGs it reads with 8 bits a channel (RGB, RGBA, greyscale with alpha)
_PNG_16_TRUNCATED = ("RGB;16B", "RGBA;16B", "LA;16B")


def image_values(im: Image.Image, alpha: bool = False) -> np.ndarray:
    """A Pillow image's pixels as float32 ``(H, W, 3)`` RGB in [0, 1], the values as stored
    (display-encoded, as a PNG holds them), with alpha as a fourth channel if ``alpha`` (1 where the
    image has none). 8-bit images of every mode Pillow converts to RGB, 16-bit greyscale ones (divided
    by 65535) and float ones already in [0, 1] are read; a 16-bit RGB PNG arrives with 8 bits a channel
    (Pillow's reading: :func:`read_image_values` reads a file with all 16).
    Raises ``ValueError`` saying what was expected for the rest: float values outside
    [0, 1] (an HDR image, to tone-map first), 32-bit integer pixels, a mode Pillow cannot convert
    (``convert('RGB')`` alone would clip a 16-bit image to white and cast a float one to black)."""
    mode = im.mode
    if mode in _MODES_16 or mode == "F":
        grey = np.asarray(im, np.float32)
        if mode == "F":
            finite = np.isfinite(grey)
            if not finite.all():
                raise ValueError(f"a float image with {int((~finite).sum())} NaN or infinite pixels: expected "
                                 f"values in [0, 1]")
            lo, hi = (float(grey.min()), float(grey.max())) if grey.size else (0.0, 0.0)
            if lo < 0.0 or hi > 1.0:
                raise ValueError(f"a float image with values in [{lo:.4g}, {hi:.4g}]: expected display-encoded "
                                 f"values in [0, 1] (tone-map an HDR image first)")
        else:
            grey = grey / 65535.0
        planes = [grey] * 3 + ([np.ones_like(grey)] if alpha else [])
        return np.stack(planes, axis=-1)
    if mode == "I":
        raise ValueError("32-bit integer pixels: expected 8- or 16-bit integer channels, or float ones in [0, 1]")
    try:
        rgb = im.convert("RGBA" if alpha else "RGB")
    except ValueError as err:  # (a mode Pillow has no conversion for)
        raise ValueError(f"a {mode} image, which Pillow cannot convert to RGB ({err})") from None
    return np.asarray(rgb, np.float32) / 255.0


def read_image_values(path: str | os.PathLike[str], alpha: bool = False) -> np.ndarray:
    """The pixels of the image file at ``path`` as :func:`image_values` gives them, a 16-bit RGB, RGBA or
    greyscale-with-alpha PNG with all 16 bits a channel (divided by 65535; Pillow reads such a file with the
    top 8, so it is decoded with pypng, installed with ``rtp[capture]`` and ``rtp[train]``; without pypng it is
    read with 8 bits a channel, with a warning). Raises what Pillow raises for a file it cannot open
    (``OSError``, ``PIL.UnidentifiedImageError``, ``PIL.Image.DecompressionBombError``), ``OSError`` for a
    16-bit PNG pypng cannot decode, and ``ValueError`` for pixels :func:`image_values` refuses."""
    from PIL import Image

    with Image.open(path) as im:
        raw = im.tile[0][3] if im.format == "PNG" and len(im.tile) == 1 else None
        if raw in _PNG_16_TRUNCATED:
            try:
                import png  # (pypng)
            except ImportError:
                log.warning("%s: a 16-bit %s PNG, read with 8 bits a channel (pip install pypng to read all 16)",
                            os.fspath(path), im.mode)
            else:
                return _png16_values(png, path, alpha)
        im.load()
        return image_values(im, alpha)


def _png16_values(png: Any, path: str | os.PathLike[str], alpha: bool) -> np.ndarray:
    """A 16-bit PNG's pixels through pypng, as float32 ``(H, W, 3)`` (``(H, W, 4)`` with ``alpha``) in [0, 1]."""
    try:
        width, height, rows, info = png.Reader(filename=os.fspath(path)).asDirect()
        # (asDirect expands a tRNS colour to alpha and scales by an sBIT chunk: bitdepth is what the rows hold)
        planes, depth = int(info["planes"]), int(info["bitdepth"])
        a = np.vstack([np.asarray(row, np.float32) for row in rows]).reshape(height, width, planes)
    except Exception as err:  # (pypng meets damaged bytes with png.Error, zlib.error, struct.error, IndexError, ...)
        raise OSError(f"a damaged 16-bit PNG ({type(err).__name__}: {err})") from None
    a /= float(2**depth - 1)
    colour = a[..., :3] if planes >= 3 else np.repeat(a[..., :1], 3, axis=-1)
    if not alpha:
        return np.ascontiguousarray(colour)
    a_plane = a[..., -1:] if info["alpha"] else np.ones_like(a[..., :1])
    return np.concatenate([colour, a_plane], axis=-1)


def save_image(path: str | os.PathLike[str], image: np.ndarray) -> None:
    """Write an image (uint8, or float in [0, 1]; ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)``)
    atomically, in the format the file extension names (``.png``, ``.jpg``, ``.webp``, ...)."""
    from PIL import Image

    a = _image_bytes(np.asarray(image), "save_image")
    fmt = _format(path)
    im = Image.fromarray(a)
    if fmt == "JPEG" and im.mode == "RGBA":
        im = im.convert("RGB")
    with atomic_output(path) as tmp:
        im.save(tmp, format=fmt)


def _image_bytes(a: np.ndarray, what: str) -> np.ndarray:
    """An image to write as uint8: uint8 as it is, bool and float values in [0, 1] (NaN as 0) scaled by 255;
    other integers, which held 0-255 or 0-65535 and were clipped to white, and empty or oddly shaped arrays are a
    :class:`ParameterError`."""
    if a.dtype.kind in "iu" and a.dtype != np.uint8:
        raise ParameterError(f"{what}: {a.dtype} pixels; expected uint8 (0-255) or float values in [0, 1] (other "
                             f"integers were clipped to white): convert with .astype(np.uint8) for 0-255, or divide "
                             f"by the largest value")
    if a.dtype != np.uint8 and a.dtype.kind not in "bf":
        raise ParameterError(f"{what}: {a.dtype} pixels; expected uint8 or float values in [0, 1]")
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)) or 0 in a.shape:
        raise ParameterError(f"{what}: expected a non-empty (H, W), (H, W, 3) or (H, W, 4), got shape {a.shape}")
    if a.dtype != np.uint8:
        a = np.round(np.clip(np.nan_to_num(a.astype(np.float64)), 0.0, 1.0) * 255.0).astype(np.uint8)
    return a


def check_image_output(path: str | os.PathLike[str], what: str = "output") -> None:
    """What :func:`save_image` would refuse at ``path`` for an RGB picture (an extension Pillow cannot write, or
    cannot write RGB pixels to, a folder, a place that cannot be written), before the work that makes the image."""
    import io

    from PIL import Image

    fmt = _format(path)
    try:  # (.xbm, .msp, .palm take 1-bit pixels alone, .blp palette ones, .h5 and .emf a handler rtp has none of:
        # each failed after the work, a traceback)
        Image.new("RGB", (2, 2)).save(io.BytesIO(), format=fmt)
    except Exception as err:  # noqa: BLE001 - Pillow's writers refuse with OSError, ValueError, KeyError, ...
        raise ParameterError(f"{os.fspath(path)!r}: Pillow cannot write an RGB image as {fmt} ({err}); use .png, .jpg "
                             f"or .webp") from None
    check_output(path, what=what)


def _format(path: str | os.PathLike[str]) -> str:
    from PIL import Image

    fmt = Image.registered_extensions().get(os.path.splitext(os.fspath(path))[1].lower())
    if fmt is None or fmt not in Image.SAVE:  # (.psd, .fits, .cur: formats Pillow reads only, a KeyError at the save)
        raise ParameterError(f"{os.fspath(path)!r}: not an image extension Pillow can write (.png, .jpg, .webp, ...)")
    return str(fmt)


def figure_image(fig: Figure) -> np.ndarray:
    """Render a matplotlib figure (Agg, no display) to a uint8 ``(H, W, 3)`` RGB image."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.array(canvas.buffer_rgba())[..., :3]


def text_width(text: str, fontsize: float, dpi: float = 100.0) -> float:
    """The width in pixels ``text`` takes drawn by matplotlib's Agg at ``fontsize`` points in a figure of ``dpi`` (its
    widest line): what a figure is sized to where a title must fit (a guess of a few pixels a character ran wide
    titles off the image)."""
    from matplotlib.backends.backend_agg import RendererAgg
    from matplotlib.font_manager import FontProperties

    renderer, font = RendererAgg(1, 1, dpi), FontProperties(size=fontsize)
    return max(renderer.get_text_width_height_descent(line, font, ismath=False)[0] for line in text.split("\n"))


def wrap_to_width(text: str, width_px: float, fontsize: float, dpi: float = 100.0) -> str:
    """``text`` wrapped (at its spaces, a longer word broken) into lines each at most ``width_px`` pixels wide as
    :func:`text_width` measures them; one character a line at the narrowest."""
    import textwrap

    if text_width(text, fontsize, dpi) <= width_px:
        return text
    for chars in range(len(text) - 1, 0, -1):
        wrapped = "\n".join(textwrap.wrap(text, chars))
        if text_width(wrapped, fontsize, dpi) <= width_px:
            return wrapped
    return "\n".join(text)
