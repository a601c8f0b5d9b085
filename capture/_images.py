"""Writing pictures: images in the format their file extension names, and matplotlib figures as images.

Shared by the dataset preview and by :mod:`rtp.evaluate`'s figures.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

from rtp.sdk import ParameterError
from rtp.sdk.files import atomic_output, check_output

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["check_image_output", "figure_image", "save_image"]


def save_image(path: str | os.PathLike[str], image: np.ndarray) -> None:
    """Write an image (uint8, or float in [0, 1]; ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)``)
    atomically, in the format the file extension names (``.png``, ``.jpg``, ``.webp``, ...)."""
    from PIL import Image

    a = np.asarray(image)
    if a.dtype != np.uint8:
        a = np.round(np.clip(np.nan_to_num(a.astype(np.float64)), 0.0, 1.0) * 255.0).astype(np.uint8)
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)):
        raise ParameterError(f"save_image: expected (H, W), (H, W, 3) or (H, W, 4), got shape {a.shape}")
    fmt = _format(path)
    im = Image.fromarray(a)
    if fmt == "JPEG" and im.mode == "RGBA":
        im = im.convert("RGB")
    with atomic_output(path) as tmp:
        im.save(tmp, format=fmt)


def check_image_output(path: str | os.PathLike[str], what: str = "output") -> None:
    """What :func:`save_image` would refuse at ``path`` (an extension Pillow cannot write, a folder,
    a place that cannot be written), before the work that makes the image."""
    _format(path)
    check_output(path, what=what)


def _format(path: str | os.PathLike[str]) -> str:
    from PIL import Image

    fmt = Image.registered_extensions().get(os.path.splitext(os.fspath(path))[1].lower())
    if fmt is None:
        raise ParameterError(f"{os.fspath(path)!r}: not an image extension Pillow can write (.png, .jpg, .webp, ...)")
    return str(fmt)


def figure_image(fig: Figure) -> np.ndarray:
    """Render a matplotlib figure (Agg, no display) to a uint8 ``(H, W, 3)`` RGB image."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.array(canvas.buffer_rgba())[..., :3]
