"""Evaluation figures, drawn with matplotlib (Agg, no display needed): heatmaps with a colour bar,
a density scatter with real axes, rate overlays with a legend.

Every figure function returns a uint8 ``(H, W, 3)`` RGB image, so a caller can show it, stack it or
write it; :func:`save_image` (``rtp.capture``'s) writes one in the format its file extension names (``.png``, ``.jpg``,
``.webp``, ...), atomically. Each figure says what its colours mean: a colour bar with the quantity
and its range, titles on every panel, a legend for the rate classes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from rtp.capture import figure_image, save_image, text_width
from rtp.sdk import (
    OVERLAY_PALETTES,
    PREDICTED_RATES,
    RATE_NAMES,
    ParameterError,
    draw_rate_overlay,
    rate_size,
    tile_grid,
    work_saved,
)

from ._baselines import BaselineError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "colorize",
    "figure_image",
    "heatmaps",
    "play_curves",
    "play_frames",
    "rate_legend",
    "rate_overlays",
    "save_image",
    "scatter",
    "sequence_curves",
    "upsample_tiles",
    "value_map",
]

#: Dots per inch of every figure: panels are drawn at (about) one figure pixel per image pixel.
DPI = 100
#: The colour of seen pixels in the seen-mask panels (unseen pixels are black).
SEEN_GREY = "#bdbdbd"


def _colormap(cmap: str) -> Any:
    import matplotlib

    try:
        return matplotlib.colormaps[cmap]
    except KeyError:
        raise BaselineError(f"unknown colour map {cmap!r}; any of matplotlib's, e.g. magma, viridis, inferno") from None


#: The colour of a value that is NaN (no value) in a map panel, as :func:`colorize` draws it.
NAN_GREY = "#808080"


def _in_range(values: Any, vmin: float, vmax: float) -> tuple[np.ndarray, str, bool]:
    """Values to draw with colours spanning ``[vmin, vmax]``: clipped to it, so that an infinite value takes the end
    colour (matplotlib masks infinities as invalid and drew them blank, white: a PSNR of identical tiles, +inf, negated
    for bright = worse, showed the best tiles in the page's white, as bright as the worst); the colour bar's ``extend``
    (an arrow at each end some value lies beyond) and whether any value is NaN (drawn :data:`NAN_GREY`)."""
    v = np.asarray(values, np.float64)
    nan = np.isnan(v)
    finite_or_inf = v[~nan]
    over = bool(finite_or_inf.size and finite_or_inf.max() > vmax)
    under = bool(finite_or_inf.size and finite_or_inf.min() < vmin)
    extend = "both" if over and under else "max" if over else "min" if under else "neither"
    return np.clip(v, vmin, vmax), extend, bool(nan.any())


def _with_nan_grey(cmap: str) -> Any:
    return _colormap(cmap).with_extremes(bad=NAN_GREY)


def colorize(values: np.ndarray, vmin: float = 0.0, vmax: float = 1.0, cmap: str = "magma") -> np.ndarray:
    """Map values ``(...)`` to uint8 colours ``(..., 3)`` through a matplotlib colour map; values are
    clipped to ``[vmin, vmax]``; NaN is drawn mid grey."""
    if not (np.isfinite(vmin) and np.isfinite(vmax) and vmax > vmin):
        raise BaselineError(f"colour range: expected finite vmin < vmax, got {vmin}, {vmax}")
    table = _colormap(cmap)
    v = np.asarray(values, dtype=np.float64)
    nan = np.isnan(v)
    x = np.clip((np.where(nan, vmin, v) - vmin) / (vmax - vmin), 0.0, 1.0)
    rgb = np.round(table(x)[..., :3] * 255.0).astype(np.uint8)
    rgb[nan] = 128
    return rgb


def _check_scale(scale: object) -> None:
    """A figure's ``scale`` (its panels drawn that many times smaller): an integer >= 1 (0 raised ZeroDivisionError,
    a negative one matplotlib's error of a negative figure size)."""
    if isinstance(scale, bool) or not isinstance(scale, (int, np.integer)) or scale < 1:
        raise BaselineError(f"scale: expected an integer >= 1 (the panels drawn that many times smaller), got {scale!r}")


def _frame_size(size: Any) -> tuple[int, int]:
    """A frame's ``(H, W)``: two positive integers."""
    try:
        h, w = size
    except (TypeError, ValueError):
        raise BaselineError(f"size: expected the frame's (H, W), got {size!r}") from None
    for v in (h, w):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise BaselineError(f"size: expected the frame's (H, W), two positive integers, got {size!r}")
    return int(h), int(w)


def upsample_tiles(values: np.ndarray, tile: int, size: tuple[int, int]) -> np.ndarray:
    """Per-tile values ``(th, tw)`` to pixels ``size = (H, W)`` (each tile a constant block)."""
    h, w = size
    return np.repeat(np.repeat(np.asarray(values), tile, axis=0), tile, axis=1)[:h, :w]


#: The smallest a map panel is drawn, (width, height) in pixels: a smaller frame is enlarged to it, its
#: aspect kept, so that the titles and colour-bar labels around it fit (a 160x96 demo's ran into each
#: other and off the image).
MIN_PANEL = (200, 160)
#: The longest side a small panel is enlarged to (a panel already longer is not enlarged): a strip of a frame, 1600x16,
#: was enlarged until its short side reached :data:`MIN_PANEL`, its long side with it (a 48110-pixel-wide heatmaps
#: image; a (1, 3000) map's 720130 pixels wide, 550 MB). Its figure is :data:`MIN_PANEL` high still, the panel inside.
MAX_ZOOMED = 1000


def _zoom(w: float, h: float, min_w: float, min_h: float) -> float:
    """How much a ``w`` x ``h`` panel is enlarged, its aspect kept: to ``min_w`` x ``min_h`` at the least, but no side
    past :data:`MAX_ZOOMED` by it."""
    return max(1.0, min(max(min_w / w, min_h / h), MAX_ZOOMED / max(w, h)))


def _figure(width_px: float, height_px: float) -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=(width_px / DPI, height_px / DPI), dpi=DPI, layout="constrained")


def _bare(ax: Any) -> None:
    """An image panel: no ticks, a thin frame so light content does not merge with the page."""
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_edgecolor("#404040")
        spine.set_linewidth(0.8)


def value_map(
    values: np.ndarray, *, label: str, vmin: float = 0.0, vmax: float = 1.0, cmap: str = "magma", title: str = ""
) -> np.ndarray:
    """One per-pixel map ``(H, W)`` drawn at its own size (enlarged to :data:`MIN_PANEL` where it is
    smaller, no side past :data:`MAX_ZOOMED` by it) with a colour bar naming the quantity; values beyond
    ``[vmin, vmax]`` and NaN as :func:`heatmaps` draws them."""
    v = np.asarray(values, np.float64)
    if v.ndim != 2 or v.size == 0:
        raise BaselineError(f"value_map: expected a non-empty (H, W) array, got shape {v.shape}")
    if not (np.isfinite(vmin) and np.isfinite(vmax) and vmax > vmin):
        raise BaselineError(f"colour range: expected finite vmin < vmax, got {vmin}, {vmax}")
    h, w = v.shape
    v, extend, nan = _in_range(v, vmin, vmax)
    # (a small map enlarged, to the height its colour bar's label takes too: its labels were cut off)
    min_h = max(MIN_PANEL[1], 240)
    zoom = _zoom(w, h, MIN_PANEL[0], min_h)
    # (the panel's cell as wide as its title at the least, about 7 pixels a character at 9 points: over a narrow map
    # it ran off the image; the colour bar in a column of its own, not over the title beside the narrow panel)
    pw, ph = max(w * zoom, MIN_PANEL[0], 7 * len(title)), max(h * zoom, min_h)
    fig = _figure(pw + 130, ph + (40 if title else 16))
    grid = fig.add_gridspec(1, 2, width_ratios=[pw, 0.06 * min(pw, 300)])
    ax = fig.add_subplot(grid[0, 0])
    im = ax.imshow(v, cmap=_with_nan_grey(cmap), vmin=vmin, vmax=vmax, interpolation="nearest")
    _bare(ax)
    if title:
        ax.set_title(title, fontsize=9)
    fig.colorbar(im, cax=fig.add_subplot(grid[0, 1]), label=label + ("\n(grey: no value)" if nan else ""),
                 extend=extend)
    return figure_image(fig)


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
    label: str = "per-tile error",
    threshold: float | None = None,
    title: str = "",
) -> np.ndarray:
    """True next to predicted per-tile values, one row per rate: ``truth | seen mask | prediction``
    (the paper's figure layout; the mask column only with ``seen``), with one colour bar.

    ``truth`` and ``prediction`` are per-tile values ``(6, th, tw)`` (channel order
    :data:`~rtp.sdk.PREDICTED_RATES`); ``[vmin, vmax]`` spans the colours, ``label`` names the
    quantity on the colour bar (with its units) and ``threshold``, if given, is marked on it.
    ``size`` is the frame ``(H, W)``; ``scale`` > 1 draws the panels that many times smaller (never
    smaller than :data:`MIN_PANEL`). A value beyond ``[vmin, vmax]`` (an infinite one too) takes the colour at
    that end, the colour bar an arrow there; NaN is drawn :data:`NAN_GREY`, the colour bar saying so.
    """
    truth, prediction = np.asarray(truth), np.asarray(prediction)
    if truth.shape != prediction.shape or truth.ndim != 3 or truth.shape[0] != len(PREDICTED_RATES):
        raise BaselineError(
            f"heatmaps: expected truth and prediction of one shape (6, th, tw), got {truth.shape} and {prediction.shape}"
        )
    unknown = [r for r in rates if r not in PREDICTED_RATES]
    if unknown or not rates:
        raise BaselineError(f"heatmaps: expected rates among {', '.join(PREDICTED_RATES)}, got {list(rates)}")
    if not (np.isfinite(vmin) and np.isfinite(vmax) and vmax > vmin):
        raise BaselineError(f"colour range: expected finite vmin < vmax, got {vmin}, {vmax}")
    _check_scale(scale)
    h, w = _frame_size(size)
    # (values of another grid than the frame's were drawn all the same, cut to the frame or short of it: a tile twice
    # too large showed the top-left quarter of the map as the whole frame; a mask of another size, another frame's)
    tiles = tile_grid(h, w, tile)
    if truth.shape[1:] != tiles:
        raise BaselineError(f"heatmaps: expected per-tile values (6, {tiles[0]}, {tiles[1]}) for a {w}x{h} frame of "
                            f"{tile}-pixel tiles, got {truth.shape}")
    if seen is not None and np.shape(seen) != (h, w):
        raise BaselineError(f"heatmaps: expected a seen mask of the frame's size ({h}, {w}), got shape {np.shape(seen)}")
    import matplotlib.colors as mcolors

    cols = 3 if seen is not None else 2
    pw, ph = w / scale, h / scale
    zoom = _zoom(pw, ph, *MIN_PANEL)  # (small frames enlarged: titles ran into each other)
    pw, ph = max(pw * zoom, MIN_PANEL[0]), max(ph * zoom, MIN_PANEL[1])
    fig = _figure(cols * pw + 110, len(rates) * (ph + 26) + (28 if title else 8))
    # (the colour bar in a column of its own: beside panels narrower than their cells, a tall strip's, matplotlib put it
    # beside the panels, over the last column's cells and titles)
    grid = fig.add_gridspec(len(rates), cols + 1, width_ratios=[pw] * cols + [0.06 * min(pw, 300)])
    axes = np.array([[fig.add_subplot(grid[i, j]) for j in range(cols)] for i in range(len(rates))])
    norm = mcolors.Normalize(vmin, vmax)
    # (the rates drawn only: the colour bar's arrows and its note of NaN are about what the panels show)
    shown, extend, nan = _in_range(np.stack([truth, prediction])[:, [PREDICTED_RATES.index(r) for r in rates]],
                                   vmin, vmax)
    for c, (row, r) in enumerate(zip(axes, rates)):
        panels = [(shown[0, c], f"{r}: true")]
        if seen is not None:
            panels.append((None, "seen (grey) / unseen (black)"))
        panels.append((shown[1, c], f"{r}: predicted"))
        for ax, (values, name) in zip(row, panels):
            if values is None:
                ax.imshow(np.clip(np.asarray(seen, np.float32), 0, 1),
                          cmap=mcolors.ListedColormap(["black", SEEN_GREY]), vmin=0, vmax=1, interpolation="nearest")
            else:
                ax.imshow(upsample_tiles(values, tile, size), cmap=_with_nan_grey(cmap), norm=norm,
                          interpolation="nearest")
            ax.set_title(name, fontsize=9)
            _bare(ax)
    import matplotlib.cm as mcm

    marked = threshold is not None and vmin <= threshold <= vmax
    mappable = mcm.ScalarMappable(norm=norm, cmap=_colormap(cmap))
    bar = fig.colorbar(mappable, cax=fig.add_subplot(grid[:, cols]), extend=extend,
                       label=label + ("\n(cyan line: the threshold)" if marked else "")
                       + ("\n(grey: no value)" if nan else ""))
    if marked and threshold is not None:
        bar.ax.axhline(threshold, color="#00e5ff", linewidth=2.5)
    if title:
        fig.suptitle(title, fontsize=10)
    return figure_image(fig)


def scatter(
    prediction: np.ndarray,
    truth: np.ndarray,
    *,
    size: int = 360,
    lo: float = 0.0,
    hi: float = 1.0,
    cmap: str = "magma_r",
    title: str = "",
    label: str = "value",
) -> np.ndarray:
    """Predicted against true per-tile values as a 2D histogram with a logarithmic colour bar (tiles
    per bin), the diagonal ``prediction = truth`` dashed, labelled axes and the title above the plot.
    Values outside ``[lo, hi]`` are drawn in the edge bins; pairs with a NaN or infinite value are left out,
    the title saying how many. ``size`` is the plot's side in pixels (the image adds the axes, colour bar,
    title and the diagonal's key below the plot, off the data)."""
    p = np.asarray(prediction, np.float64).ravel()
    g = np.asarray(truth, np.float64).ravel()
    if p.shape != g.shape:
        raise BaselineError(f"scatter: prediction and truth differ in size: {p.shape} vs {g.shape}")
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo) or size < 64:
        raise BaselineError(f"scatter: need finite lo < hi and size >= 64, got lo={lo}, hi={hi}, size={size}")
    import matplotlib.colors as mcolors

    ok = np.isfinite(p) & np.isfinite(g)
    p, g = np.clip(p[ok], lo, hi), np.clip(g[ok], lo, hi)
    bins = int(np.clip(2 * np.sqrt(max(p.size, 1)), 16, 128))  # fewer, larger bins for few values
    fig = _figure(size + 150, size + 106)
    ax = fig.subplots()
    hist, xe, ye = np.histogram2d(g, p, bins=bins, range=[[lo, hi], [lo, hi]])
    mesh = ax.pcolormesh(xe, ye, np.ma.masked_equal(hist.T, 0), cmap=_colormap(cmap),
                         norm=mcolors.LogNorm(vmin=1, vmax=max(hist.max(), 2)))
    ax.plot([lo, hi], [lo, hi], color="#555555", linewidth=1, linestyle="--", label="prediction = truth")
    ax.set_xlim(lo, hi)
    ax.set_ylim(lo, hi)
    ax.set_aspect("equal")
    ax.set_xlabel(f"true {label}")
    ax.set_ylabel(f"predicted {label}")
    # (the diagonal's key below the plot: in its upper-left corner it lay over the over-predicted tiles, true low and
    # predicted high, where a model that over-predicts puts them)
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower left", fontsize=8, frameon=False)
    # (pairs with a NaN or infinite value have no place on the axes: said, not dropped silently under a title
    # that counts every value)
    dropped = int(ok.size - p.size)
    counted = f"{p.size} tile{'' if p.size == 1 else 's'}"  # ("1 tiles" it said of one)
    ax.set_title((title or counted) + (f"\n({dropped} not finite, not drawn)" if dropped else ""), fontsize=10)
    fig.colorbar(mesh, ax=ax, label="tiles per bin (log)", shrink=0.85)
    return figure_image(fig)


#: The rate overlay's palettes (:func:`rtp.sdk.draw_rate_overlay`'s ``palette``): the paper's, the default, and one
#: whose classes stay apart under colour-vision deficiency.
PALETTES = tuple(OVERLAY_PALETTES)


#: The swatch of the untinted class (1x1, full rate) in every rate key: the mid grey of the key draw_rate_overlay draws
#: into a frame (``legend=True``), the tints' swatches its palette's colours. (The figures' legends drew it white, the
#: GIFs' key grey: one class, two colours.)
UNTINTED_SWATCH = (0.5, 0.5, 0.5)


def rate_legend(palette: str = "paper") -> list[tuple[str, tuple[float, float, float] | None]]:
    """The overlay's colour classes and the rates in each: ``[(label, colour or None for 1x1)]``, in ``palette``'s
    colours (:data:`PALETTES`); a key draws the None (untinted) class's swatch :data:`UNTINTED_SWATCH`."""
    if not isinstance(palette, str) or palette not in OVERLAY_PALETTES:
        raise ParameterError(f"palette: expected one of {', '.join(map(repr, OVERLAY_PALETTES))} (the rate overlay's "
                             f"colours), got {palette!r}", "palette")
    colours = OVERLAY_PALETTES[palette]
    classes: dict[str, list[str]] = {"fine": [], "medium": [], "coarse": []}
    for r in PREDICTED_RATES:
        w, h = rate_size(r)
        classes["fine" if w * h == 2 else "medium" if w * h == 4 else "coarse"].append(r)
    out: list[tuple[str, tuple[float, float, float] | None]] = [("1x1 (untinted)", None)]
    out += [(f"{k}: {', '.join(v)}", colours[k]) for k, v in classes.items()]
    return out


#: The width in pixels the rate legend takes in one row (its four entries at 8 points).
_RATE_LEGEND_ROW = 600
#: The most panels :func:`rate_overlays` puts in a row (more go on further rows).
_RATE_PANELS_PER_ROW = 3


def _add_rate_legend(fig: Figure, ncols: int, palette: str = "paper") -> None:
    from matplotlib.patches import Patch

    handles = [Patch(facecolor=c if c is not None else UNTINTED_SWATCH, edgecolor="#404040", label=name)
               for name, c in rate_legend(palette)]
    fig.legend(handles=handles, loc="outside lower center", ncols=ncols, fontsize=8, frameon=False)


def rate_overlays(image: np.ndarray, rates: Mapping[str, np.ndarray], tile: int, *, scale: int = 1,
                  title: str = "", palette: str = "paper") -> np.ndarray:
    """:func:`rtp.sdk.draw_rate_overlay` of each method's rate codes ``(th, tw)`` on the same
    ``(H, W, 3)`` image (an ``(H, W, 4)`` one's colour, its alpha left out), side by side
    (three a row at most), titled with the
    method and the shading work it saves (of the image's pixels, a partial edge tile counting its real ones),
    with the legend of the rate colours below and ``title``, if given, above; ``palette`` the overlay's colours
    (:data:`PALETTES`)."""
    if not rates:
        raise BaselineError("rate_overlays: no methods given")
    rate_legend(palette)  # (an unknown palette refused before any drawing)
    _check_scale(scale)
    img = np.asarray(image)
    h, w = img.shape[:2]
    # at most _RATE_PANELS_PER_ROW panels a row (the evaluation's six methods in one row made a 3860-pixel strip,
    # its titles unreadable at a page's width)
    per_row = min(len(rates), _RATE_PANELS_PER_ROW)
    rows = -(-len(rates) // per_row)
    panels = []
    for name, codes in rates.items():
        codes = np.asarray(codes)  # (checked by draw_rate_overlay: a uint8 cast made a code of 256 draw as 1x1)
        # a share of the frame's pixels (a partial edge tile its real ones), as the decision table counts it
        drawn = draw_rate_overlay(img, codes, tile, palette=palette)
        saved = (0.0 if not codes.size else work_saved(codes, (h, w), tile) if codes.shape == tile_grid(h, w, tile)
                 else float(np.mean([work_saved(RATE_NAMES[int(c)]) for c in codes.ravel()])))
        panels.append((drawn, f"{name}: saves {100 * saved:.0f}%"))
    # (each cell as wide as its longest panel title, the figure as its title: a small frame's six methods, 160 pixels
    # a panel, ran 'yang2019-unseen-1x1: saves 52%' into its neighbours' titles and the first and last off the image,
    # and cut the figure's title at both ends)
    cell = max(w / scale, 160, max(text_width(t, 9) for _, t in panels) + 12)
    width = max(per_row * cell + 20, text_width(title, 10) + 24 if title else 0)
    # (the legend in as many columns as the figure holds: in one row it was cut off below a narrow figure)
    ncols = 4 if width >= _RATE_LEGEND_ROW else 2 if width >= _RATE_LEGEND_ROW / 2 else 1
    fig = _figure(width, rows * (max(h / scale, 90) + 30) + 40 + 18 * (4 // ncols - 1) + (24 if title else 0))
    axes = np.atleast_1d(fig.subplots(rows, per_row)).ravel()
    for ax in axes[len(rates):]:  # (the last row's empty places)
        ax.set_axis_off()
    for ax, (drawn, name) in zip(axes, panels):
        # (its colour only: an engine's (H, W, 4) frame kept its alpha, and an alpha of 0, a back buffer's, drew the
        # panel blank, the page's white)
        ax.imshow(drawn[..., :3], interpolation="nearest")
        ax.set_title(name, fontsize=9)
        _bare(ax)
    _add_rate_legend(fig, ncols, palette)
    if title:
        fig.suptitle(title, fontsize=10)
    return figure_image(fig)


#: The markers and line styles that tell the methods of a closed-loop figure apart beside their colours (in greyscale
#: and under colour-vision deficiency, where colours alone do not): the i-th method takes the i-th of each, cycling,
#: so that no two methods of up to 28 (7 markers by 4 styles) share a marker and a style.
_METHOD_MARKERS = ("o", "s", "^", "D", "v", "P", "X")
_METHOD_LINESTYLES = ("-", "--", ":", "-.")


def _method_styles(methods: Sequence[str]) -> dict[str, dict[str, Any]]:
    """Each method's ``color``, ``marker`` and ``linestyle`` (``Axes.plot``'s keywords), by its place in ``methods``:
    the same in every figure of one run. Tab10's colours (the 11th method takes the first's again), and a marker and
    a line style of their own for each of up to 28 methods."""
    import matplotlib

    cmap = matplotlib.colormaps["tab10"]
    return {m: {"color": cmap(i % 10), "marker": _METHOD_MARKERS[i % len(_METHOD_MARKERS)],
                "linestyle": _METHOD_LINESTYLES[i % len(_METHOD_LINESTYLES)]}
            for i, m in enumerate(methods)}


def _report_styles(report: Any, methods: Sequence[str]) -> dict[str, dict[str, Any]]:
    """:func:`_method_styles` of a closed-loop report's methods in the order its run names them (``settings``'
    ``methods``), then any other of ``methods``: each method the same style in the curves and the per-frame plot."""
    named = report.settings.get("methods") if isinstance(report.settings, Mapping) else None
    return _method_styles(list(dict.fromkeys([*(named if isinstance(named, list) else []), *methods])))


def _method_legend(fig: Figure, axes: Any, loc: Literal["outside right upper", "outside lower center"],
                   ncols: int = 1, marks: Sequence[Any] = ()) -> None:
    """One legend of the methods of every panel, outside the panels (a legend inside one hid the
    points and lines under it: on a short path most methods meet in the same corner), then ``marks``, artists
    labelled with what a figure's other marks mean."""
    handles: dict[str, Any] = {}
    for ax in np.ravel(axes):
        for h, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, h)
    for h in marks:
        handles.setdefault(h.get_label(), h)
    if handles:
        fig.legend(list(handles.values()), list(handles), loc=loc, ncols=ncols, fontsize=8, frameon=False)


#: Where play_curves' axis of failing tiles (%, symlog, linear below 1%) starts: room left of 0 for a point's
#: default ring (8 points across, about 0.03% at the figure's size).
_CURVES_LEFT = 0.06


def play_curves(report: Any) -> np.ndarray:
    """Closed-loop sweeps (:func:`rtp.evaluate.play`): per path, each method's work saved against
    its share of failing tiles over its parameter sweep (each method its colour, marker and line style), the default
    parameter ringed, the matched failing shares dashed; the legend names the methods, then those two marks."""
    from matplotlib.lines import Line2D

    from ._play import FAIL_LEVELS

    paths = list(report.unseen)
    methods = list(dict.fromkeys(r["method"] for r in report.rows))
    styles = _report_styles(report, methods)
    fig = _figure(520 * len(paths) + 220, 420)  # (220: the legend at the right)
    axes = np.atleast_1d(fig.subplots(1, len(paths), sharey=True))
    s = report.settings
    for ax, path in zip(axes, paths):
        for m in methods:
            rows = sorted((r for r in report.rows if r["path"] == path and r["method"] == m), key=lambda r: r["fail_share"])
            if not rows:
                continue
            x = [100 * r["fail_share"] for r in rows]
            y = [100 * r["work_saved"] for r in rows]
            ax.plot(x, y, markersize=4, linewidth=1.2, label=m, **styles[m])
            for r in rows:
                if r["default"]:
                    ax.plot([100 * r["fail_share"]], [100 * r["work_saved"]], marker="o", markersize=8,
                            markerfacecolor="none", linestyle="none", color=styles[m]["color"])
        for f in FAIL_LEVELS:
            ax.axvline(100 * f, color="#999999", linewidth=0.8, linestyle="--")
        ax.set_xscale("symlog", linthresh=1.0)
        # (a little left of 0: a point failing on no tile, the oracle's and often a strict threshold's, sat on the
        # axis with half its marker and its default's ring cut off)
        ax.set_xlim(-_CURVES_LEFT, 100)
        ax.set_xlabel(f"tiles failing ({_failing(s['fail_metric'], s['fail_threshold'])}), % (symlog)")
        ax.set_title(f"{s['scene']}, {path} path, {s['frames']} frames", fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("shading work saved, %")
    # (the ring and the dashed lines were explained nowhere in the figure)
    levels = ", ".join(f"{100 * f:g}" for f in FAIL_LEVELS)
    marks = [Line2D([], [], marker="o", markersize=8, markerfacecolor="none", linestyle="none", color="#404040",
                    label="default parameter"),
             Line2D([], [], color="#999999", linewidth=0.8, linestyle="--", label=f"matched failing\n({levels}%)")]
    _method_legend(fig, axes, "outside right upper", marks=marks)
    return figure_image(fig)


def _failing(metric: str, threshold: float) -> str:
    """When a tile fails, as a formula: ``jnyang ≥ 0.25``; a higher-is-better metric's ``psnr ≤ 35`` (``>`` was
    written for PSNR too, whose tiles fail under the threshold); ``metric at threshold`` for a metric this
    installation does not know (a plugin's report read elsewhere)."""
    from rtp import metrics
    from rtp.sdk import RtpError

    try:
        hib = metrics.metric_info(metric).higher_is_better
    except RtpError:
        return f"{metric} at {threshold:g}"
    return f"{metric} {'≤' if hib else '≥'} {threshold:g}"  # (failing_tiles: not better than the threshold)


def _series(ax: Any, t: np.ndarray, y: np.ndarray, style: Mapping[str, Any], label: str, place: float = 0.0) -> None:
    """One method's per-frame series as a line in its ``style`` (:func:`_method_styles`), its marker on about ten of
    its frames (from ``place``, a share of the spacing: methods apart, their markers not on one another), and each
    value with no finite neighbour as a dot: a line drew nothing of it (rate changes under dynamic resolution with
    short holds: one value between NaNs)."""
    every = max(1, len(t) // 10)
    ax.plot(t, y, linewidth=0.9, markersize=3.5, markevery=(min(round(place * every), every - 1), every),
            label=label, **style)
    ok = np.isfinite(y)
    alone = ok & ~np.concatenate([[False], ok[:-1]]) & ~np.concatenate([ok[1:], [False]])
    if alone.any():
        ax.plot(t[alone], y[alone], linestyle="none", marker=style["marker"], markersize=3, color=style["color"])


def play_frames(report: Any) -> np.ndarray:
    """Closed-loop runs frame by frame at each method's default parameter: work saved, failing
    tiles and the share of tiles whose rate changed (each method its colour, marker and line style), with the path's
    unseen share per frame."""
    from matplotlib.ticker import MaxNLocator

    paths = list(report.unseen)
    methods = list(dict.fromkeys(m for p in paths for m in report.frames[p]))
    styles = _report_styles(report, methods)
    s = report.settings
    fig = _figure(1300, 300 * len(paths) + 40 + 20 * -(-len(methods) // 7))  # (and the legend's rows below)
    axes = np.atleast_2d(fig.subplots(len(paths), 4, squeeze=False))
    smaller = _smaller_frames(s, max((len(u) for u in report.unseen.values()), default=0))
    failing = _failing(s["fail_metric"], s["fail_threshold"])
    for row, path in zip(axes, paths):
        t = np.arange(len(report.unseen[path]))
        for a, b in smaller:  # (dynamic resolution: the frames drawn below the largest size, shaded)
            for ax in row:
                ax.axvspan(a - 0.5, b - 0.5, color="#000000", alpha=0.07, linewidth=0)
        for m, series in report.frames[path].items():
            for ax, key in zip(row[:3], ("saved", "fail", "change")):
                # (frame 0 has no history; frame 1's rate change is from frame 0's rates: both left out, as the
                # summaries leave them out)
                first = 2 if key == "change" else 1
                _series(ax, t[first:], 100 * np.asarray(series[key][first:], np.float64), styles[m], m,
                        methods.index(m) / len(methods))
        row[3].plot(t[1:], 100 * np.asarray(report.unseen[path][1:]), color="#333333", linewidth=0.9)
        # (the failing panel names its threshold, as play_curves' axis does: "jnyang" alone did not say over what)
        for ax, title in zip(row, ("work saved, %", f"tiles failing ({failing}), %",
                                   "tiles whose rate changed, %", "unseen share of the frame, %")):
            ax.set_title(f"{path}: {title}", fontsize=9)
            # (whole frames: a 3-frame run's axes read 1.0, 1.2, ... 2.0, its rate changes' 1.90 ... 2.10)
            ax.xaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
            ax.set_xlabel(f"frame ({s['fps']:g} Hz" + ("; grey: drawn at a smaller size)" if smaller else ")"),
                          fontsize=8)
            ax.grid(alpha=0.3)
    _method_legend(fig, axes, "outside lower center", ncols=min(len(methods), 7))
    return figure_image(fig)


def _smaller_frames(settings: Mapping[str, Any], frames: int) -> list[tuple[int, int]]:
    """The runs of frames ``[a, b)`` a run with dynamic resolution drew below its largest size (none without)."""
    dyn = settings.get("dynamic_resolution")
    if not dyn:
        return []
    from rtp.capture.paths import DynamicResolution

    schedule, full = DynamicResolution(tuple(dyn["scales"]), dyn["every"]), tuple(settings["size"])
    runs: list[tuple[int, int]] = []
    for i in range(frames):
        if schedule.size(i, (full[0], full[1])) == full:
            continue
        if runs and runs[-1][1] == i:
            runs[-1] = (runs[-1][0], i + 1)
        else:
            runs.append((i, i + 1))
    return runs


def sequence_curves(rows: Sequence[Mapping[str, Any]], thresholds: bool = False, *,
                    higher_is_better: bool = False, title: str = "") -> np.ndarray:
    """A model over a sequence of an engine's frames (``rtp predict`` on several frames), frame by frame: the
    shading work its rates save, the share of tiles whose rate changed from the frame before, and its
    predict time. ``rows``: one mapping a frame with ``work_saved``, ``changed`` (None on the first) and
    ``predict_ms``. ``thresholds``: a fourth panel, each frame's ``threshold`` (what a budget,
    ``--saving``, reached); ``higher_is_better``: the model's metric is (PSNR), its reduced tiles predicted above
    the threshold (the panel's title said "below" for every metric). ``title``, if given, above the panels (``rtp
    predict`` names the model, its metric and the threshold or budget held)."""
    from matplotlib.ticker import MaxNLocator

    panels = [([100 * r["work_saved"] for r in rows], "shading work saved, %"),
              ([np.nan if r["changed"] is None else 100 * r["changed"] for r in rows], "tiles whose rate changed, %"),
              ([r["predict_ms"] for r in rows], "predict, ms")]
    if thresholds:
        panels.append(([r["threshold"] for r in rows], "threshold reached (each reduced tile predicted "
                       f"{'above' if higher_is_better else 'below'} it)"))
    width = 1300 if len(panels) == 3 else 1700
    fig = _figure(max(width, text_width(title, 10) + 24) if title else width, 300 + (24 if title else 0))
    axes = fig.subplots(1, len(panels))
    t = np.arange(len(rows))
    for ax, (y, name) in zip(axes, panels):
        # (unclipped: every point lies within the limits below, and a marker on 0, a frame whose rates did not
        # change, was drawn as half a dot on the axis)
        ax.plot(t, y, marker="o" if len(rows) <= 30 else None, markersize=3, linewidth=1.0, color="#1f77b4",
                clip_on=False)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("frame", fontsize=8)
        ax.set_xlim(-0.5, max(len(rows) - 0.5, 0.5))
        # (whole frames only, one tick at the least: with fewer than two matplotlib's integer locator gave up, a
        # folder of one frame's axis read -0.5, -0.4, ... 0.5)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
        # from 0, with room above the highest point (matplotlib's margin is a share of the data's own spread: a
        # series of 55-57% drew its top markers cut in half on the panel's edge, a constant one its whole line on
        # it); a series all 0, or none (the first frame's change), on 0 to 1 rather than matplotlib's 0 to 0.055
        finite = np.asarray(y, np.float64)[np.isfinite(np.asarray(y, np.float64))]
        top = float(finite.max()) if finite.size else 0.0
        low = min(0.0, float(finite.min()) if finite.size else 0.0)
        ax.set_ylim(low, top + 0.08 * (top - low) if top > low else low + 1.0)
        ax.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=10)
    return figure_image(fig)
