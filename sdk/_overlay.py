"""The paper's rate overlay: full rate uncoloured, fine green, medium yellow, coarse red."""

from __future__ import annotations

import numpy as np

from ._errors import InputDtypeError, InputShapeError, NonFiniteInputError, ParameterError
from ._rates import RATE_CODES, RATE_NAMES, rate_size
from ._tiles import tile_grid

__all__ = ["OVERLAY_COLOURS", "OVERLAY_PALETTES", "draw_rate_overlay"]

#: The paper's overlay colour (RGB in [0, 1], blended into the image's own values) by shaded area: 2 pixels =
#: fine, 4 = medium, 8 or 16 = coarse.
OVERLAY_COLOURS: dict[str, tuple[float, float, float]] = {
    "fine": (0.0, 0.85, 0.0),
    "medium": (1.0, 0.9, 0.0),
    "coarse": (1.0, 0.0, 0.0),
}

#: The overlay's palettes by name (``draw_rate_overlay(palette=)``), each its classes' colours: ``"paper"``,
#: :data:`OVERLAY_COLOURS`, the default; ``"cvd"``, Okabe and Ito's sky blue, yellow and vermillion, told apart
#: under protanopia, deuteranopia and tritanopia (the paper's fine green and medium yellow come within a CIEDE2000
#: of about 4 of each other under simulated protanopia, blended at the default alpha; these stay about 10 or more
#: apart under each, the untinted one too). Both are blended into the image's own values.
OVERLAY_PALETTES: dict[str, dict[str, tuple[float, float, float]]] = {
    "paper": OVERLAY_COLOURS,
    "cvd": {
        "fine": (86 / 255, 180 / 255, 233 / 255),
        "medium": (240 / 255, 228 / 255, 66 / 255),
        "coarse": (213 / 255, 94 / 255, 0.0),
    },
}


def _overlay_colours(palette: object) -> dict[str, tuple[float, float, float]]:
    """The class colours of ``palette`` (a name of :data:`OVERLAY_PALETTES`); a :class:`ParameterError` naming
    them otherwise."""
    if not isinstance(palette, str) or palette not in OVERLAY_PALETTES:
        names = ", ".join(repr(p) for p in OVERLAY_PALETTES)
        raise ParameterError(f"palette: expected one of {names} (the overlay's colours: 'paper' the paper's, 'cvd' "
                             f"told apart under colour-vision deficiency), got {palette!r}", "palette")
    return OVERLAY_PALETTES[palette]


def _array(x: object, name: str) -> np.ndarray:
    try:
        return np.asarray(x)
    except (TypeError, ValueError, OverflowError) as err:  # ragged nested lists and the like
        raise InputDtypeError(f"{name}: expected an array, got {type(x).__name__} ({err})") from err


#: The legend's rows: the class (None = full rate, drawn untinted) and the rates it holds.
LEGEND_ROWS: tuple[tuple[str | None, str], ...] = (
    (None, "1x1"), ("fine", "1x2,2x1"), ("medium", "2x2"), ("coarse", "2x4,4x2,4x4"),
)

# A 3x5 bitmap font for the legend's characters (the runtime draws text without a font library).
_GLYPHS: dict[str, tuple[str, ...]] = {
    "1": ("010", "110", "010", "010", "111"),
    "2": ("111", "001", "111", "100", "111"),
    "4": ("101", "101", "111", "001", "001"),
    "x": ("000", "101", "010", "101", "000"),
    ",": ("000", "000", "000", "010", "100"),
}


def _text_mask(text: str) -> np.ndarray:
    """A (5, 4 * len(text) - 1) boolean mask of ``text`` in the 3x5 font."""
    cols: list[np.ndarray] = []
    for i, ch in enumerate(text):
        if i:
            cols.append(np.zeros((5, 1), bool))
        cols.append(np.array([[c == "1" for c in row] for row in _GLYPHS[ch]], bool))
    return np.concatenate(cols, axis=1)


def _draw_legend(out: np.ndarray, alpha: float, colours: dict[str, tuple[float, float, float]] = OVERLAY_COLOURS) -> None:
    """Draw the rate legend into the bottom-left corner of ``out`` ((H, W, 3) float in [0, 1]), in place:
    a dark box with one row per class, its swatch (tinted as the tiles are) and its rates. The legend
    scales with the image (one font pixel per 270 image rows, fewer where the image is too narrow for that
    scale: a 540x100 frame had no key at all) and is left out where it does not fit at one font pixel."""
    h, w = out.shape[:2]
    masks = [_text_mask(label) for _, label in LEGEND_ROWS]
    # the box at one font pixel (54 x 33); every part of it scales with s
    unit_w = 2 + 5 + 2 + max(m.shape[1] for m in masks) + 2
    unit_h = 2 + 8 * len(LEGEND_ROWS) - 3 + 2
    if unit_w > w or unit_h > h:
        return
    s = max(1, min(h // 270, w // unit_w))
    pad, row_h, swatch = 2 * s, 8 * s, 5 * s
    box_w, box_h = unit_w * s, unit_h * s
    y0, x0 = h - box_h, 0
    out[y0:, :box_w] *= 0.25
    grey = np.array([0.5, 0.5, 0.5], np.float32)
    for i, ((cls, _), mask) in enumerate(zip(LEGEND_ROWS, masks, strict=True)):
        top = y0 + pad + i * row_h
        sw = out[top:top + swatch, x0 + pad:x0 + pad + swatch]
        sw[...] = grey if cls is None else grey * (1.0 - alpha) + np.array(colours[cls], np.float32) * alpha
        big = np.repeat(np.repeat(mask, s, 0), s, 1)
        left = x0 + pad + swatch + 2 * s
        out[top:top + big.shape[0], left:left + big.shape[1]][big] = 1.0


def _class_of(code: int) -> str | None:
    w, h = rate_size(RATE_NAMES[code])
    area = w * h
    if area == 1:
        return None
    return "fine" if area == 2 else "medium" if area == 4 else "coarse"


def draw_rate_overlay(
    image: np.ndarray,
    rates: np.ndarray,
    tile_size: int,
    *,
    alpha: float = 0.45,
    grid: bool = True,
    legend: bool = False,
    palette: str = "paper",
) -> np.ndarray:
    """Tint each tile of ``image`` by the class of its shading rate.

    ``image`` is ``(H, W, 3)`` (uint8, or float in [0, 1]: float values outside it, an HDR frame's, are clipped
    to it before the tint, so the tint shows; tone-map such a frame first to see it); ``rates`` is ``(ceil(H/w), ceil(W/w))``
    of uint8 rate codes as returned by ``shading_rates``. Coarser rates (2x4, 4x2, 4x4) are tinted
    red, 2x2 yellow, 1x2 and 2x1 green, 1x1 is left as is. With ``grid`` a faint line marks the
    tiles. With ``legend`` a key in the bottom-left corner names the rates of each colour (full rate
    1x1 untinted; it is left out of images too small to hold it: narrower than 54 pixels or shorter than 33).
    ``palette``: ``"paper"`` (the default, :data:`OVERLAY_COLOURS`) or ``"cvd"``, sky blue, yellow and vermillion,
    whose classes stay apart under protanopia, deuteranopia and tritanopia (the paper's green and yellow do not under
    protanopia).
    Returns a new image of the same dtype and shape (an ``(H, W, 4)`` image keeps its alpha as it is).
    """
    img = _array(image, "image")
    if img.dtype != np.uint8 and img.dtype.kind != "f":  # (a uint16 image read as floats came back white)
        raise InputDtypeError(f"image: expected uint8 or float values in [0, 1], got dtype {img.dtype}")
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise InputShapeError(f"image: expected an (H, W, 3) or (H, W, 4) image, got shape {img.shape}",
                              tuple(img.shape), "(H, W, 3)")
    if img.dtype.kind == "f" and not np.isfinite(img).all():
        raise NonFiniteInputError("image: holds NaN or infinite values; expected colours in [0, 1]")
    for name, flag in (("grid", grid), ("legend", legend)):
        if not isinstance(flag, (bool, np.bool_)):
            raise ParameterError(f"{name}: expected True or False, got {flag!r}", name)
    if isinstance(alpha, (bool, np.bool_)) or not isinstance(alpha, (int, float, np.integer, np.floating)) \
            or not 0.0 <= alpha <= 1.0:
        raise ParameterError(f"alpha: expected a number in [0, 1] (the tint's opacity), got {alpha!r}", "alpha")
    colours = _overlay_colours(palette)
    h, w = img.shape[:2]
    th, tw = tile_grid(h, w, tile_size)
    rates = _array(rates, "rates")
    if rates.dtype.kind not in "ui":
        raise InputDtypeError(f"rates: expected integer shading-rate codes (uint8, as shading_rates returns), got "
                              f"dtype {rates.dtype}")
    if rates.shape != (th, tw):
        raise InputShapeError(
            f"expected rates of shape {(th, tw)} for a {w}x{h} image with {tile_size}-pixel tiles, got {rates.shape}",
            tuple(rates.shape),
            f"({th}, {tw})",
        )
    unknown = set(np.unique(rates).tolist()) - set(RATE_CODES.values())
    if unknown:
        raise ParameterError(f"rates: hold codes that are no shading rate: {sorted(unknown)}; expected codes from "
                             f"{sorted(RATE_NAMES)}", "rates")
    is_uint8 = img.dtype == np.uint8
    # (an HDR frame's values over 1 are clipped before the tint, not after: a frame of 4.0 came back white everywhere,
    # every tint and the grid clipped away with it)
    out = np.clip(img[..., :3].astype(np.float32) / (255.0 if is_uint8 else 1.0), 0.0, 1.0)
    tint = np.zeros((th, tw, 3), np.float32)
    weight = np.zeros((th, tw, 1), np.float32)
    for code in np.unique(rates).tolist():
        cls = _class_of(int(code))
        if cls is None:
            continue
        mask = rates == code
        tint[mask] = colours[cls]
        weight[mask] = alpha
    tint_px = np.repeat(np.repeat(tint, tile_size, 0), tile_size, 1)[:h, :w]
    weight_px = np.repeat(np.repeat(weight, tile_size, 0), tile_size, 1)[:h, :w]
    out = out * (1.0 - weight_px) + tint_px * weight_px
    if grid and tile_size >= 4:
        out[::tile_size, :, :] *= 0.75
        out[:, ::tile_size, :] *= 0.75
    if legend:
        _draw_legend(out, alpha, colours)
    out = np.clip(out, 0.0, 1.0)
    if is_uint8:
        res = np.round(out * 255.0).astype(np.uint8)
    else:
        res = out.astype(img.dtype if np.issubdtype(img.dtype, np.floating) else np.float32)
    if img.shape[2] == 4:
        res = np.concatenate([res, img[..., 3:]], axis=2)
    return res
