"""``rtp preview``: one dataset sample as a labelled sheet (final images at every rate, the G-buffers,
the reprojection), drawn with matplotlib so every panel says what it shows and in what range."""

from __future__ import annotations

from typing import Any

import numpy as np

from rtp.sdk import ALL_RATES, ParameterError, srgb_to_linear, work_saved

from ._dataset import _PAPER_BUFFERS, BUFFERS
from ._images import figure_image

__all__ = ["preview_sheet"]

_COLS = 4


def _paper(sample: Any) -> bool:
    """Whether ``sample`` is of the paper's released layout (PaperDatasetReader's samples say so)."""
    meta = getattr(sample, "meta", {}) or {}
    return meta.get("source") == "paper"


def _missing(sample: Any) -> frozenset[str]:
    """The buffers ``sample``'s dataset does not hold: an engine's frames imported without them
    (``sample.absent``), and what the paper's released layout has no file for (depth, metallic, motion)."""
    absent: frozenset[str] = getattr(sample, "absent", frozenset())
    if _paper(sample):
        absent |= frozenset(b for b in BUFFERS if b not in _PAPER_BUFFERS)
    return absent


def _normal(sample: Any) -> tuple[str, np.ndarray]:
    """The normal panel's title and image: the view-space normal's x, y, z in [-1, 1] as RGB in [0, 1]
    (``n * 0.5 + 0.5``; 0.5 grey is a zero component). rtp's layout holds the linear normal; the paper's
    holds it as written through an sRGB target, its negative components clamped to 0 (PaperDatasetReader),
    so it is decoded to the linear normal first (it took the stored sRGB values for the normal, which drew
    a component of 0.5 as 0.87 rather than 0.75), its negatives shown as 0."""
    label = "view-space normal (x, y, z as RGB)"
    normal = sample.buffer("normal")
    if _paper(sample):
        normal = srgb_to_linear(normal).astype(np.float32)
        label += "\nthis layout stores < 0 as 0"
    return label, np.clip(normal * 0.5 + 0.5, 0, 1)


def _panels(sample: Any) -> list[tuple[str, np.ndarray, dict[str, Any]]]:
    """``(title, image, imshow options)`` in sheet order; images are (H, W, 3) in [0, 1] or (H, W)."""
    absent = _missing(sample)
    final = sample.final("1x1")
    depth = sample.channel("depth") if "depth" not in absent else None
    geometry = depth > 0 if depth is not None else np.ones(final.shape[:2], bool)
    far = float(np.percentile(depth[geometry], 99)) if depth is not None and geometry.any() else 1.0
    grey = {"cmap": "gray", "vmin": 0.0, "vmax": 1.0}
    nothing = np.zeros(final.shape[:2], np.float32)
    normal_label, normal = _normal(sample)

    def held(name: str, label: str, options: dict[str, Any]) -> tuple[str, np.ndarray, dict[str, Any]]:
        """The panel of channel ``name``, or one saying the dataset has no such buffer."""
        if name in absent:
            return f"{name}: not in this dataset", nothing, grey
        plane = sample.channel(name)
        if name == "shadow":  # the main light's visibility alone: the reference renderer's sun (its point lights cast
            # no shadow), so that indoors, under a ceiling, the panel is black where lamps light the room; said so
            label += f"\nmean {float(plane[geometry].mean()):.2f}; other lights are not in it" if geometry.any() else ""
        return label, plane, options

    out: list[tuple[str, np.ndarray, dict[str, Any]]] = [
        (f"final {r}" + ("" if r == "1x1" else f" (saves {100 * work_saved(r):.0f}%)"), sample.final(r), {})
        for r in ALL_RATES
    ]
    out.append(("|final 1x1 - final 4x4| x 4", np.clip(np.abs(final - sample.final("4x4")) * 4, 0, 1), {}))
    out += [
        ("albedo (sRGB)", sample.buffer("albedo"), {}),
        (normal_label, normal * geometry[..., None], {}),
        held("depth", "linear depth (scene units)", {"cmap": "viridis", "vmin": 0.0, "vmax": far, "colorbar": True}),
        held("shadow", "main-light (sun) shadow, 1 = lit", grey),
        held("roughness", "roughness", {**grey, "colorbar": True}),
        held("metallic", "metallic", {**grey, "colorbar": True}),
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
    what = [f"scene {meta['scene']}" if "scene" in meta else "", f"{meta['profile']} motion" if "profile" in meta else "",
            f"{w}x{h}"]  # (the paper's layout records no motion profile: left out, not '? motion')
    fig.suptitle(title or f"sample {getattr(sample, 'id', '?')}: " + ", ".join(p for p in what if p), fontsize=10)
    return figure_image(fig)
