"""``rtp preview``: one dataset sample as a labelled sheet (final images at every rate, the G-buffers,
the reprojection), drawn with matplotlib so every panel says what it shows and in what range."""

from __future__ import annotations

from typing import Any

import numpy as np

from rtp.sdk import ALL_RATES, ParameterError, work_saved

from ._images import figure_image

__all__ = ["preview_sheet"]

_COLS = 4


def _panels(sample: Any) -> list[tuple[str, np.ndarray, dict[str, Any]]]:
    """``(title, image, imshow options)`` in sheet order; images are (H, W, 3) in [0, 1] or (H, W)."""
    depth = sample.channel("depth")
    absent: frozenset[str] = getattr(sample, "absent", frozenset())
    far = float(np.percentile(depth[depth > 0], 99)) if np.any(depth > 0) else 1.0
    grey = {"cmap": "gray", "vmin": 0.0, "vmax": 1.0}
    out: list[tuple[str, np.ndarray, dict[str, Any]]] = [
        (f"final {r}" + ("" if r == "1x1" else f" (saves {100 * work_saved(r):.0f}%)"), sample.final(r), {})
        for r in ALL_RATES
    ]
    out.append(("|final 1x1 - final 4x4| x 4", np.clip(np.abs(sample.final("1x1") - sample.final("4x4")) * 4, 0, 1), {}))
    out += [
        ("albedo (sRGB)", sample.buffer("albedo"), {}),
        ("view-space normal (x, y, z as RGB)", np.clip(sample.buffer("normal") * 0.5 + 0.5, 0, 1) * (depth > 0)[..., None],
         {}),
        ("linear depth (scene units)", depth, {"cmap": "viridis", "vmin": 0.0, "vmax": far, "colorbar": True}),
        *((f"{name}{label}", sample.channel(name), {**grey, **extra}) if name not in absent else
          (f"{name}: not in this dataset", np.zeros_like(depth), grey)  # (an engine's frames imported without it)
          for name, label, extra in (("shadow", " (1 = lit)", {}), ("roughness", "", {"colorbar": True}),
                                     ("metallic", "", {"colorbar": True}))),
        ("reprojected previous frame", sample.buffer("reprojected"), {}),
        ("seen (white) / unseen (black)", sample.channel("seen"), grey),
    ]
    return out


def preview_sheet(sample: Any, *, scale: int = 1, title: str | None = None) -> np.ndarray:
    """A labelled picture of one sample (uint8 ``(H, W, 3)``): four rows of four panels, the seven
    final images and the 1x1 - 4x4 difference, then the G-buffers and the reprojection, each with a
    title (and a colour bar where the values are not colours). ``scale`` > 1 draws the panels that
    many times smaller, down to panels of 160x90 pixels (a larger ``scale`` draws those: it
    subsampled the images below their panels, to a single pixel at ``--scale 1000``)."""
    from matplotlib.figure import Figure

    if isinstance(scale, bool) or not isinstance(scale, (int, np.integer)) or scale < 1:  # (0: ZeroDivisionError)
        raise ParameterError(f"scale: expected an integer >= 1 (1: full size), got {scale!r}", "scale")
    panels = _panels(sample)
    h, w = panels[0][1].shape[:2]
    step = max(1, min(int(scale), w // 160, h // 90))  # (no finer than the smallest panel shows)
    pw, ph = max(w / step, 160), max(h / step, 90)
    rows = -(-len(panels) // _COLS)
    fig = Figure(figsize=(_COLS * (pw + 70) / 100, rows * (ph + 30) / 100 + 0.4), dpi=100, layout="constrained")
    axes = fig.subplots(rows, _COLS, squeeze=False).ravel()
    for ax, (name, img, opts) in zip(axes, panels):
        opts = dict(opts)
        bar = opts.pop("colorbar", False)
        shown = ax.imshow(img[::step, ::step], interpolation="nearest", **opts)
        ax.set_title(name, fontsize=8)
        ax.set_xticks([])
        ax.set_yticks([])
        if bar:
            fig.colorbar(shown, ax=ax, fraction=0.046, pad=0.02)
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    meta = getattr(sample, "meta", {}) or {}
    fig.suptitle(title or f"sample {getattr(sample, 'id', '?')}: scene {meta.get('scene', '?')}, "
                 f"{meta.get('profile', '?')} motion, {w}x{h}", fontsize=10)
    return figure_image(fig)
