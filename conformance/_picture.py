"""The conformance kit's picture: each channel of the adapter beside the reference renderer's, and
where they differ, so that a failed agreement shows where (a flipped image, encoded normals)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rtp import sdk

__all__ = ["BEYOND", "planes_picture"]

#: The colour of the pixels whose difference is beyond the channel's tolerance (pure red: nothing
#: else in the picture uses it).
BEYOND = (1.0, 0.0, 0.0)


def _range(adapter: np.ndarray, reference: np.ndarray, channel: str) -> tuple[float, float]:
    """The colour scale of a channel's panels: its declared range where it is finite, else the
    range both planes span."""
    spec = sdk.CHANNELS[channel]
    lo, hi = float(spec.low), float(spec.high)
    if np.isfinite(lo) and np.isfinite(hi):
        return lo, hi
    values = np.concatenate([p[np.isfinite(p)].ravel() for p in (adapter, reference)])
    if values.size == 0:
        return 0.0, 1.0
    lo, hi = float(values.min()), float(values.max())
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def _difference(adapter: np.ndarray, reference: np.ndarray, tolerance: Any) -> tuple[np.ndarray, float]:
    """An RGB image of ``|adapter - reference|``: grey up to the tolerance, :data:`BEYOND` past it
    (and where either is not finite); and the share of pixels within it."""
    err = np.abs(adapter.astype(np.float64) - reference)
    if tolerance.relative:
        err = err / np.maximum(np.abs(reference), 1e-6)
    err = np.where(np.isfinite(err), err, np.inf)
    beyond = err > tolerance.value
    scale = tolerance.value if tolerance.value > 0 else 1.0
    grey = np.clip(np.where(beyond, 0.0, err / scale), 0.0, 1.0) * 0.8
    rgb = np.repeat(grey[..., None], 3, axis=-1)
    rgb[beyond] = BEYOND
    return rgb, float(1.0 - beyond.mean())


def _not_compared(channel: str, channels: Sequence[str]) -> str:
    """Why a channel's row has no difference panel, in a few lines."""
    base, _, kind = channel.rpartition(".")
    if kind in ("blocks", "tiles", "dx", "dy") and base in channels:
        return f"not compared: checked\nagainst the sdk's {kind} of\nthe adapter's own {base}"
    if channel.startswith("reprojected."):
        return "not compared\n(the engine's own lit image;\nits edges and depth test\nare checked)"
    return "not compared\n(the engine's own\nshading model)"


def planes_picture(x: np.ndarray, channels: Sequence[str], reference: Any,
                   tolerances: Mapping[str, Any], title: str = "") -> np.ndarray:
    """A uint8 ``(H, W, 3)`` picture, a row per channel: the adapter's plane, the reference
    renderer's, and their difference (grey up to the channel's tolerance, red past it) where the
    channel is compared; the reference's alone where it is not (``reprojected.*``: each engine's own
    lit image; engine-defined channels)."""
    from matplotlib.figure import Figure

    from rtp.capture import figure_image

    n = len(channels)
    h, w = x.shape[1:]
    zoom = max(1, 160 // max(w, 1))
    panel_w, panel_h = w * zoom / 100.0, h * zoom / 100.0
    head = 0.7  # inches for the title and the legend
    fig = Figure(figsize=(max(3 * (panel_w + 0.3) + 0.4, 6.0), n * (panel_h + 0.45) + head), dpi=100)
    fig.suptitle((title + "\n" if title else "") + "the difference is grey up to each channel's tolerance, red past it",
                 fontsize=9, y=1 - 0.08 / fig.get_figheight())
    axes = fig.subplots(n, 3, squeeze=False)
    for row, (plane, c) in enumerate(zip(x, channels)):
        ref = np.asarray(reference.channel(c), np.float64)
        lo, hi = _range(plane, ref, c)
        for col, (image, title) in enumerate(((plane, f"{c}: adapter"), (ref, "reference renderer"))):
            axes[row, col].imshow(np.nan_to_num(image, nan=lo), cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
            axes[row, col].set_title(title, fontsize=8)
        ax = axes[row, 2]
        if c in tolerances:
            tol = tolerances[c]
            rgb, share = _difference(plane, ref, tol)
            ax.imshow(rgb, interpolation="nearest")
            ax.set_title(f"difference: {share:.1%} within {tol.value:g}{' (rel.)' if tol.relative else ''}",
                         fontsize=8)
        else:
            ax.set_facecolor("white")
            ax.text(0.5, 0.5, _not_compared(c, channels), ha="center", va="center", fontsize=7, transform=ax.transAxes)
        for a in axes[row]:
            a.set_xticks([])
            a.set_yticks([])
    fig.subplots_adjust(left=0.02, right=0.98, top=1 - head / fig.get_figheight(), bottom=0.1 / fig.get_figheight(),
                        wspace=0.08, hspace=0.45 / (panel_h + 0.45) * 1.4)
    return figure_image(fig)
