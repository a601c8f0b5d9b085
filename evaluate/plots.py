"""Evaluation figures in plain numpy + Pillow (no matplotlib): heatmaps, a density scatter, rate overlays.

Every function returns a uint8 ``(H, W, 3)`` image; :func:`save_png` writes one. Panels are laid
out by :func:`grid`: a label strip of :data:`LABEL_H` pixels above each panel and :data:`GAP`
pixels between panels, so sizes are predictable::

    height = rows * (LABEL_H + panel_h) + (rows - 1) * GAP
    width  = cols * panel_w + (cols - 1) * GAP
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rtp.sdk import PREDICTED_RATES, draw_rate_overlay

from ._baselines import BaselineError

__all__ = [
    "COLORMAPS",
    "GAP",
    "LABEL_H",
    "SCATTER_MARGIN",
    "colorize",
    "grid",
    "heatmaps",
    "rate_overlays",
    "save_png",
    "scatter",
    "upsample_tiles",
]

#: Height of the label strip above each panel, pixels.
LABEL_H = 14
#: Gap between panels, pixels.
GAP = 4
#: Left and bottom margin of :func:`scatter` for the axis labels, pixels.
SCATTER_MARGIN = 28

#: Perceptually uniform colour maps as 9 evenly spaced samples of matplotlib's ``magma`` and
#: ``viridis`` (sRGB in [0, 1]), interpolated linearly in between: a close approximation, not
#: the 256-entry tables.
COLORMAPS: dict[str, np.ndarray] = {
    "magma": np.array([
        (0.001462, 0.000466, 0.013866), (0.078815, 0.054184, 0.211667), (0.232077, 0.059889, 0.437695),
        (0.390384, 0.100379, 0.501864), (0.550287, 0.161158, 0.505719), (0.716387, 0.214982, 0.475290),
        (0.868793, 0.287728, 0.409303), (0.967671, 0.439703, 0.359810), (0.987053, 0.991438, 0.749504),
    ]),
    "viridis": np.array([
        (0.267004, 0.004874, 0.329415), (0.282623, 0.140926, 0.457517), (0.253935, 0.265254, 0.529983),
        (0.206756, 0.371758, 0.553117), (0.163625, 0.471133, 0.558148), (0.127568, 0.566949, 0.550556),
        (0.134692, 0.658636, 0.517649), (0.266941, 0.748751, 0.440573), (0.993248, 0.906157, 0.143936),
    ]),
}


def colorize(values: np.ndarray, vmin: float = 0.0, vmax: float = 1.0, cmap: str = "magma") -> np.ndarray:
    """Map values ``(...)`` to uint8 colours ``(..., 3)``; values are clipped to ``[vmin, vmax]``;
    NaN is drawn mid grey."""
    if cmap not in COLORMAPS:
        raise BaselineError(f"unknown colour map {cmap!r}; known: {', '.join(COLORMAPS)}")
    if not vmax > vmin:
        raise BaselineError(f"vmax must exceed vmin, got {vmin}, {vmax}")
    table = COLORMAPS[cmap]
    v = np.asarray(values, dtype=np.float64)
    nan = np.isnan(v)
    x = np.clip((np.where(nan, vmin, v) - vmin) / (vmax - vmin), 0.0, 1.0) * (len(table) - 1)
    i = np.minimum(x.astype(np.int64), len(table) - 2)
    f = (x - i)[..., None]
    rgb = table[i] * (1.0 - f) + table[i + 1] * f
    rgb[nan] = 0.5
    return np.round(rgb * 255.0).astype(np.uint8)


def upsample_tiles(values: np.ndarray, tile: int, size: tuple[int, int]) -> np.ndarray:
    """Per-tile values ``(th, tw)`` to pixels ``size = (H, W)`` (each tile a constant block)."""
    h, w = size
    return np.repeat(np.repeat(np.asarray(values), tile, axis=0), tile, axis=1)[:h, :w]


def _font() -> Any:
    from PIL import ImageFont

    return ImageFont.load_default()


def _label(width: int, text: str) -> np.ndarray:
    from PIL import Image, ImageDraw

    im = Image.new("RGB", (max(width, 1), LABEL_H), (255, 255, 255))
    ImageDraw.Draw(im).text((2, 1), text, fill=(0, 0, 0), font=_font())
    return np.asarray(im)


def _rgb8(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    if a.dtype != np.uint8:
        a = np.round(np.clip(a[..., :3], 0.0, 1.0) * 255.0).astype(np.uint8)
    return a[..., :3]


def grid(panels: Sequence[Sequence[np.ndarray]], labels: Sequence[Sequence[str]] | None = None) -> np.ndarray:
    """Lay out rows of equally sized panels (uint8 or float ``(h, w, 3)``, or ``(h, w)`` grey), each
    with a label strip above it, on white. See the module docstring for the size."""
    rows = [[_rgb8(p) for p in row] for row in panels]
    if not rows or not rows[0]:
        raise BaselineError("grid: no panels")
    ph, pw = rows[0][0].shape[:2]
    cols = max(len(r) for r in rows)
    if any(p.shape[:2] != (ph, pw) for r in rows for p in r):
        raise BaselineError("grid: panels must share one size")
    height = len(rows) * (LABEL_H + ph) + (len(rows) - 1) * GAP
    width = cols * pw + (cols - 1) * GAP
    out = np.full((height, width, 3), 255, np.uint8)
    for i, row in enumerate(rows):
        y = i * (LABEL_H + ph + GAP)
        for j, p in enumerate(row):
            x = j * (pw + GAP)
            text = labels[i][j] if labels is not None and j < len(labels[i]) else ""
            out[y : y + LABEL_H, x : x + pw] = _label(pw, text)
            out[y + LABEL_H : y + LABEL_H + ph, x : x + pw] = p
    return out


def heatmaps(
    truth: np.ndarray,
    prediction: np.ndarray,
    tile: int,
    size: tuple[int, int],
    *,
    seen: np.ndarray | None = None,
    rates: Sequence[str] = ("2x2", "4x4"),
    vmin: float = 0.0,
    vmax: float = 1.0,
    cmap: str = "magma",
    scale: int = 1,
) -> np.ndarray:
    """Ground truth next to prediction, one row per rate: ``truth | seen mask | prediction`` (the
    paper's Figure layout; the mask column only with ``seen``).

    ``truth`` and ``prediction`` are per-tile values ``(6, th, tw)`` (channel order
    :data:`~rtp.sdk.PREDICTED_RATES`) already scaled so that ``[vmin, vmax]`` spans the colours
    (the evaluation passes transformed values oriented so that bright means worse). ``size`` is the
    frame ``(H, W)``; ``scale`` > 1 subsamples the panels. Returns uint8, see :func:`grid` for
    the size with panels of ``(ceil(H/scale), ceil(W/scale))``.
    """
    truth, prediction = np.asarray(truth), np.asarray(prediction)
    if truth.shape != prediction.shape or truth.ndim != 3 or truth.shape[0] != len(PREDICTED_RATES):
        raise BaselineError(
            f"heatmaps: expected truth and prediction of one shape (6, th, tw), got {truth.shape} and {prediction.shape}"
        )
    panels, labels = [], []
    for r in rates:
        if r not in PREDICTED_RATES:
            raise BaselineError(f"heatmaps: unknown rate {r!r}")
        c = PREDICTED_RATES.index(r)
        row = [colorize(upsample_tiles(truth[c], tile, size), vmin, vmax, cmap)[::scale, ::scale]]
        lab = [f"{r} ground truth"]
        if seen is not None:
            row.append(_rgb8(np.clip(np.asarray(seen, np.float32), 0, 1))[::scale, ::scale])
            lab.append("seen (black: unseen)")
        row.append(colorize(upsample_tiles(prediction[c], tile, size), vmin, vmax, cmap)[::scale, ::scale])
        lab.append(f"{r} prediction")
        panels.append(row)
        labels.append(lab)
    return grid(panels, labels)


def scatter(
    prediction: np.ndarray,
    truth: np.ndarray,
    *,
    size: int = 256,
    lo: float = 0.0,
    hi: float = 1.0,
    cmap: str = "magma",
    title: str = "",
) -> np.ndarray:
    """Predicted (y, up) against true (x) per-tile values as a log-density 2D histogram (dark =
    many tiles; about ``2 sqrt(n)`` bins per axis, at most ``size``) with the diagonal in grey.
    Returns uint8 ``(size + SCATTER_MARGIN, size + SCATTER_MARGIN, 3)``: the plot square with a left
    and a bottom margin holding the axis labels (and ``title``)."""
    from PIL import Image, ImageDraw

    p = np.asarray(prediction, np.float64).ravel()
    g = np.asarray(truth, np.float64).ravel()
    if p.shape != g.shape:
        raise BaselineError(f"scatter: prediction and truth differ in size: {p.shape} vs {g.shape}")
    if not hi > lo or size < 8:
        raise BaselineError(f"scatter: need hi > lo and size >= 8, got lo={lo}, hi={hi}, size={size}")
    ok = np.isfinite(p) & np.isfinite(g)
    p, g = np.clip(p[ok], lo, hi), np.clip(g[ok], lo, hi)
    # Fewer, larger bins for few values so that single tiles stay visible; at most one per pixel.
    bins = int(np.clip(2 * np.sqrt(max(p.size, 1)), 16, size))
    hist, _, _ = np.histogram2d(p, g, bins=bins, range=[[lo, hi], [lo, hi]])  # rows: prediction, cols: truth
    dens = np.log1p(hist[::-1])  # prediction grows upwards
    dens = dens / dens.max() if dens.max() > 0 else dens
    # sparse bins light, dense bins dark (the low end of the map), empty bins white
    img = colorize(0.85 * (1.0 - dens), 0.0, 1.0, cmap)
    img[dens == 0] = 255
    idx = np.minimum(np.arange(size) * bins // size, bins - 1)
    img = img[idx][:, idx]
    diag = np.arange(size)
    img[size - 1 - diag, diag] = (64, 64, 64)
    m = SCATTER_MARGIN
    out = np.full((size + m, size + m, 3), 255, np.uint8)
    out[:size, m:] = img
    im = Image.fromarray(out)
    d = ImageDraw.Draw(im)
    f = _font()
    d.rectangle([m - 1, 0, m + size - 1, size], outline=(0, 0, 0))
    d.text((m + 2, size + 2), f"{lo:g}", fill=(0, 0, 0), font=f)
    d.text((m + size - 22, size + 2), f"{hi:g}", fill=(0, 0, 0), font=f)
    d.text((m + size // 2 - 12, size + 14), "true", fill=(0, 0, 0), font=f)
    d.text((2, size - 12), f"{lo:g}", fill=(0, 0, 0), font=f)
    d.text((2, 2), f"{hi:g}", fill=(0, 0, 0), font=f)
    d.text((2, size // 2 - 6), "pred", fill=(0, 0, 0), font=f)
    if title:
        d.text((m + 4, 2), title, fill=(0, 0, 0), font=f)
    return np.asarray(im)


def rate_overlays(image: np.ndarray, rates: Mapping[str, np.ndarray], tile: int, *, scale: int = 1) -> np.ndarray:
    """:func:`rtp.sdk.draw_rate_overlay` of each method's rate codes ``(th, tw)`` on the same
    ``(H, W, 3)`` image, side by side, labelled with the method names and the shading work they
    save. Panels are ``(ceil(H/scale), ceil(W/scale))``; see :func:`grid` for the size."""
    from rtp.sdk import RATE_NAMES, work_saved

    panels, labels = [], []
    for name, codes in rates.items():
        codes = np.asarray(codes)
        saved = float(np.mean([work_saved(RATE_NAMES[int(c)]) for c in codes.ravel()])) if codes.size else 0.0
        panels.append(draw_rate_overlay(_rgb8(image), codes.astype(np.uint8), tile)[::scale, ::scale])
        labels.append(f"{name} (saves {100 * saved:.0f}%)")
    if not panels:
        raise BaselineError("rate_overlays: no methods given")
    return grid([panels], [labels])


def save_png(path: str | os.PathLike[str], image: np.ndarray) -> None:
    """Write an image (uint8, or float in [0, 1]) as PNG, atomically."""
    from rtp.capture import write_png

    write_png(path, image)
