"""``rtp metric``: one metric of an image pair, per pixel and per tile, as flip-evaluator's CLI does for FLIP."""

from __future__ import annotations

import argparse
import json
import logging
import warnings
from typing import Any

import numpy as np

__all__ = ["run_metric"]

log = logging.getLogger("rtp.cli")

#: ``--out``: a pair smaller than 300 pixels on a side is drawn enlarged, its longer side to at most this many
#: pixels (a larger image is drawn at one pixel a pixel)
_MAX_ZOOMED = 2000.0


def _read(path: str) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    from rtp.capture import read_image_values
    from rtp.sdk import ParameterError

    if "\0" in path:  # (the system's ValueError, from Pillow's open)
        raise ParameterError(f"{path!r}: expected the path of an image, got a text with a NUL byte")
    try:
        try:
            rgba = read_image_values(path, alpha=True)
            if rgba.shape[-1] == 4 and (rgba[..., 3] < 1.0).any():
                log.warning("%s: %.1f%% of its pixels are not opaque; the metric compares the colour alone (composite "
                            "the image over its background first to compare what is shown)", path,
                            100.0 * float((rgba[..., 3] < 1.0).mean()))
            return np.ascontiguousarray(rgba[..., :3])
        except ValueError as err:  # (a float image past [0, 1], 32-bit integers: what it holds, not its bytes)
            raise ParameterError(f"{path!r}: {err}") from None
    except FileNotFoundError:
        raise ParameterError(f"{path!r}: no such image") from None
    except (UnidentifiedImageError, OSError, Image.DecompressionBombError) as err:
        raise ParameterError(f"{path!r}: not an image Pillow can read ({err})") from None


def _header_size(path: str) -> tuple[int, int] | None:
    """The (width, height) an image file's header gives, without decoding its pixels; None where Pillow cannot
    open it (:func:`_read` says what is wrong with it)."""
    from PIL import Image

    try:
        with warnings.catch_warnings():  # (Pillow's warning past 89 million pixels: _read gives it, once)
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:  # (the header only)
                w, h = im.size
    except (OSError, ValueError, Image.DecompressionBombError):
        return None
    return int(w), int(h)


def _check_memory(args: argparse.Namespace) -> None:
    """An image pair of two sizes is refused from the two headers, before either image is decoded (it was
    said after both were: a 1080p reference against an 8K test decoded the 8K image's 33 million pixels, and one
    past the machine's memory was "out of memory", exit 1, rather than the pair's mistake); and an image pair
    whose metric cannot be computed in this machine's memory is refused before it is decoded (Pillow takes images
    up to 179 million pixels: about 32 GiB for LPIPS)."""
    from rtp import sdk
    from rtp.capture import check_memory, job_bytes

    size = _header_size(args.reference)
    if size is None:
        return
    other = _header_size(args.test)
    if other is not None and other != size:
        raise sdk.ParameterError(_differ(size, other))
    w, h = size
    need = job_bytes("metric", (w, h), metrics=(args.metric,))
    check_memory(need, f"{args.metric} of a {w}x{h} image pair takes about {need / 2**30:.1f} GiB", "reference",
                 "of memory: smaller images", job="rtp metric")


def _differ(reference: tuple[int, int], test: tuple[int, int]) -> str:
    """The error of an image pair of two sizes, each ``(width, height)``."""
    return f"the images differ in size: {reference[0]}x{reference[1]} and {test[0]}x{test[1]}"


def run_metric(args: argparse.Namespace) -> int:
    from rtp import metrics, sdk

    from ._main import _picture_modules

    params = _parameters(args)
    if args.out:
        _check_not_an_input(args)
        _picture_modules(args.out)  # (without Pillow or matplotlib: said before the metric runs, not after)
    _check_memory(args)
    metrics.check_dependencies([args.metric])  # (a plugin's missing module was blamed on its error_map)
    ref, test = _read(args.reference), _read(args.test)
    if ref.shape != test.shape:
        raise sdk.ParameterError(_differ((ref.shape[1], ref.shape[0]), (test.shape[1], test.shape[0])))
    if "ppd" in params:  # ('width' as its number, printed; of an image too narrow for it refused before FLIP runs,
        # in the command line's words: a command-line user has no ppd= to pass, only the flag)
        params["ppd"] = metrics.image_ppd(params["ppd"], ref.shape[1], "--ppd")
    info = metrics.metric_info(args.metric)
    # the map once, pooled as tile_metric pools it (tile_metric and error_map both computed it: FLIP and LPIPS twice)
    pixel_map: Any = None if info.pooling == "mse" else metrics.error_map(args.metric, ref, test, **params)
    tiles = (metrics.tile_metric(args.metric, ref, test, args.tile) if pixel_map is None
             else metrics.pool_tiles(pixel_map, args.tile, "mean" if info.pooling == "mean" else "max"))
    finite = tiles[np.isfinite(tiles)]
    worst = (finite.min() if info.higher_is_better else finite.max()) if finite.size else float("nan")
    if args.out:
        _figure(args, ref, pixel_map, tiles, info)
    if args.json:  # (stdout is the JSON alone: the picture written is named in it, not on a line after it)
        print(json.dumps({"metric": args.metric, "units": info.units, "tile": args.tile, **params,
                          "tiles": [[None if not np.isfinite(v) else float(v) for v in row] for row in tiles],
                          **({"wrote": args.out} if args.out else {})}))
        return 0
    h, w = ref.shape[:2]
    used = "".join(f", {k} {v:.4g}" for k, v in params.items())
    print(f"{args.metric} ({info.units}), {w}x{h}, {tiles.shape[1]}x{tiles.shape[0]} tiles of {args.tile}px{used}")
    if pixel_map is not None:
        print(f"per pixel  mean {float(pixel_map.mean()):.4g}, max {float(pixel_map.max()):.4g}")
    if not finite.size:  # (identical images: no finite tile to average, "mean nan, worst (min) nan")
        print(f"per tile   all {tiles.size} tiles identical (+inf dB)")
    else:
        print(f"per tile   mean {float(finite.mean()):.4g}, "
              f"{'worst (min)' if info.higher_is_better else 'worst (max)'} {float(worst):.4g}"
              + (f", {tiles.size - finite.size} identical tiles (+inf dB)" if finite.size < tiles.size else ""))
    if args.out:
        print(f"wrote {args.out}")
    return 0


def _check_not_an_input(args: argparse.Namespace) -> None:
    """``--out`` naming one of the two images compared (``rtp metric flip ref.png test.png --out test.png``, a
    slip of the shell's history) replaced that image with the map: it is refused before any work."""
    import os

    from rtp import sdk

    for which, path in (("reference", args.reference), ("test", args.test)):
        try:
            same = os.path.samefile(args.out, path)
        except (OSError, ValueError):  # (either is not there, or not a path: nothing to overwrite, or _read says so)
            continue
        if same:
            raise sdk.ParameterError(f"--out {args.out!r} is the {which} image itself; the map would replace it: write "
                                     "it to another path")


def _parameters(args: argparse.Namespace) -> dict[str, Any]:
    """The metric's parameters, each where the metric takes it: FLIP's pixels per degree (flip, jnflip) and the
    environment luminance (jnflip, jnyang), the defaults where not given. One given to a metric that does not use it
    is refused (it would be ignored)."""
    from rtp import metrics, sdk

    from ._main import _ppd

    takes_ppd = args.metric in metrics.PPD_METRICS  # (rtp's own: a plugin's map takes neither parameter)
    takes_l = args.metric in sdk.METRICS and sdk.METRICS[args.metric].weber
    ppd, weber_l = _ppd(args.ppd), args.weber_l
    if ppd is not None and not takes_ppd:
        raise sdk.ParameterError(f"--ppd: FLIP's pixels per degree, which only {' and '.join(metrics.PPD_METRICS)} use, "
                                 f"not {args.metric}")
    if weber_l is not None and not takes_l:
        raise sdk.ParameterError(f"--weber-l: the environment luminance of the just-noticeable metrics ("
                                 f"{', '.join(m for m in sdk.METRICS if sdk.METRICS[m].weber)}), which {args.metric} "
                                 f"does not use")
    params: dict[str, Any] = {}
    if takes_ppd:
        params["ppd"] = metrics.DEFAULT_PPD if ppd is None else ppd
    if takes_l:
        params["weber_l"] = metrics.check_weber_l(metrics.DEFAULT_WEBER_L if weber_l is None else weber_l)
    if takes_ppd and not isinstance(params["ppd"], str):
        params["ppd"] = metrics.resolve_ppd(params["ppd"], 1)  # (its range, before any image is read)
    return params


def _figure(args: argparse.Namespace, ref: np.ndarray, pixel_map: Any, tiles: np.ndarray, info: Any) -> None:
    from matplotlib.figure import Figure

    from rtp.capture import figure_image, save_image, wrap_to_width

    h, w = ref.shape[:2]
    shown = pixel_map if pixel_map is not None else np.repeat(np.repeat(tiles, args.tile, 0), args.tile, 1)[:h, :w]
    finite = shown[np.isfinite(shown)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    vmin, vmax = (0.0, max(hi, 1e-6)) if not info.higher_is_better else (lo, max(hi, lo + 1e-6))
    # (the picture at one pixel a pixel, enlarged to 3 inches on its shorter side where it is smaller:
    # a 130x100 pair's colour bar label and title were cut off; but its longer side to no more than
    # _MAX_ZOOMED pixels: a 400x2 strip was drawn 60,160 pixels wide, a 1000x1 one 300,160, 2.8 GB)
    zoom = max(1.0, min(300.0 / min(h, w), _MAX_ZOOMED / max(h, w)))
    wide = w * zoom >= 3 * max(h * zoom, 300)  # (a strip's colour bar, as high as the picture, was cut: below it)
    fig = Figure(figsize=(w * zoom / 100 + (0.3 if wide else 1.6), h * zoom / 100 + (1.4 if wide else 0.6)), dpi=100,
                 layout="constrained")
    ax = fig.subplots()
    import matplotlib

    # bright = worse for every metric; identical tiles (PSNR's +inf) grey, apart from the best finite one
    cmap = matplotlib.colormaps["magma_r" if info.higher_is_better else "magma"].with_extremes(bad="#9a9a9a")
    im = ax.imshow(np.ma.masked_invalid(shown), cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
    kind = "per pixel" if pixel_map is not None else f"per {args.tile}px tile"
    same = "" if finite.size else f" (every {'tile' if pixel_map is None else 'pixel'} identical: +inf {info.units})"
    if finite.size and finite.size < shown.size:
        same = f" (grey: identical, +inf {info.units})"
    title = f"{args.metric} {kind}: {args.reference} vs {args.test}{same}"
    # (wrapped to the picture's width as the text is drawn: at a guess of 6 pixels a character, wider than 9-point
    # text is, a 160x96 pair's title ran off both sides of the image, 'psnr per 16px tile' read 'r 16px tile')
    # (no narrower than the figure beside its colour bar: a 1000x1 strip's title wrapped one character a line)
    room = max(w * zoom, fig.get_figwidth() * fig.dpi - (30 if wide else 110))
    ax.set_title(wrap_to_width(title, room, 9), fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    fig.colorbar(im, ax=ax, label=f"{args.metric} ({info.units}); bright = worse",
                 orientation="horizontal" if wide else "vertical", aspect=60 if wide else 20)  # (20: matplotlib's)
    save_image(args.out, figure_image(fig))
