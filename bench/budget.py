"""The cost of a budget: ``sdk.select_rates_for_saving`` next to ``sdk.select_rates`` on one frame's predictions.

    python bench/budget.py [--model jnyang] [--repeats 50] [--saving 0.5] [--gpu]

A budget finds, per frame, the lowest threshold whose rates save the share asked for (docs/runtime.md "A budget:
a share of the work saved instead of a threshold"): it sorts four steps a tile. This times it and the plain
selection at one threshold on the predictions of the model for a frame of random planes at 1280x720, 1920x1080
and 3840x2160 (the cost depends on the number of tiles, not on the values), on the model's tiles and on 8-pixel
hardware tiles, and both again beside an engine's own rates combined by ``max`` (``engine_rates=``, which judges
the rate the device shades: random engine rates), and prints a Markdown table of medians (ms).

``--gpu`` adds a table of the decision on the GPU (``rtp.plugins.moderngl.RateSelector``: ``select`` at the
default threshold, and ``select(saving=, frame_size=)``, whose compute dispatch finds the threshold), from the
network's output in host memory to the rates read back, on whatever OpenGL 4.3 context EGL gives (Mesa's
llvmpipe on a machine without a GPU: its numbers say what a software rasteriser pays, not a GPU).
"""

from __future__ import annotations

import argparse
from functools import partial

import numpy as np
from _common import cpu_description, median_ms, number, positive, run_main  # bench/ is on sys.path as a script

from rtp import sdk

FRAMES = ((1280, 720), (1920, 1080), (3840, 2160))


def _row(pred: sdk.ShadingRatePredictor, x: np.ndarray, saving: float, repeats: int) -> str:
    """One frame's table row: both selections timed on the predictions of ``x``."""
    meta = pred.metadata
    h, w = x.shape[1:]
    values = pred.predict(x)
    kw = {"higher_is_better": meta.higher_is_better, "factors": meta.rate_factors}
    plain = median_ms(lambda: sdk.select_rates(values, meta.default_threshold, **kw), repeats)
    budget = median_ms(lambda: sdk.select_rates_for_saving(values, saving, frame_size=(h, w), tile_size=pred.tile_size,
                                                           **kw), repeats)
    sel = sdk.select_rates_for_saving(values, saving, frame_size=(h, w), tile_size=pred.tile_size, **kw)
    # beside an engine's own rates (docs/runtime.md "The engine's own rates"): random ones, the cost is the tiles'
    engine = np.random.default_rng(1).choice(list(sdk.RATE_CODES.values()), values.shape[1:]).astype(np.uint8)
    kw_engine = {**kw, "engine_rates": engine, "combiner": "max"}
    plain_engine = median_ms(lambda: sdk.select_rates(values, meta.default_threshold, **kw_engine), repeats)
    budget_engine = median_ms(lambda: sdk.select_rates_for_saving(values, saving, frame_size=(h, w),
                                                                  tile_size=pred.tile_size, **kw_engine), repeats)
    return (f"| {w}x{h} | {values.shape[1] * values.shape[2]:,} | {pred.tile_size}px | {plain:.2f} | {budget:.2f} "
            f"| {float(sel.threshold):.4g} | {100 * float(sel.saved):.1f}% | {plain_engine:.2f} | {budget_engine:.2f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="jnyang", help="a shipped model's name or an .onnx path (default: jnyang)")
    ap.add_argument("--repeats", type=positive, default=50, help="timed runs of each (default 50; the median)")
    ap.add_argument("--saving", type=number(0, sdk.MAX_SAVING), default=0.5, help="the share of the work saved asked "
                    f"for, in [0, {sdk.MAX_SAVING:g}] (4x4 saves {sdk.MAX_SAVING:g}; default 0.5)")
    ap.add_argument("--gpu", action="store_true", help="also time RateSelector's decision and budget on OpenGL")
    args = ap.parse_args(argv)
    sdk.load(args.model)  # (a model that is not there: refused before the table)
    rng = np.random.default_rng(0)
    print(f"{cpu_description()}; model {args.model}, a saving of {args.saving:g}, median of {args.repeats} runs\n")
    print("| frame | tiles | tiles of | select_rates (ms) | select_rates_for_saving (ms) | threshold reached | saved "
          "| select_rates beside engine rates (ms) | select_rates_for_saving beside engine rates (ms) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for tile in (None, 8):
        pred = sdk.load(args.model, tile_size=tile)
        for w, h in FRAMES:
            print(_row(pred, rng.random((len(pred.metadata.inputs), h, w), dtype=np.float32), args.saving, args.repeats))
    if args.gpu:
        _gpu_table(args.model, args.saving, args.repeats, rng)
    return 0


def _gpu_table(model: str, saving: float, repeats: int, rng: np.random.Generator) -> None:
    from rtp.plugins.moderngl import RateSelector, create_context

    ctx = create_context(430)
    print(f"\nRateSelector on {ctx.info['GL_RENDERER']}, the network's output in host memory, median of {repeats} runs\n")
    print("| frame | tiles | tiles of | select (ms) | select(saving=) (ms) | threshold reached | saved |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for tile in (None, 8):
        pred = sdk.load(model, tile_size=tile)
        with RateSelector(pred, ctx) as selector:
            for w, h in FRAMES:
                raw = pred.predict_raw(rng.random((len(pred.metadata.inputs), h, w), dtype=np.float32))
                grid = pred.tiles(h, w)
                plain = median_ms(partial(selector.select, raw, grid=grid), repeats)
                budget = median_ms(partial(selector.select, raw, grid=grid, saving=saving, frame_size=(h, w)), repeats)
                threshold, saved = selector.budget()
                print(f"| {w}x{h} | {grid[0] * grid[1]:,} | {pred.tile_size}px | {plain:.2f} | {budget:.2f} | "
                      f"{threshold:.4g} | {100 * saved:.1f}% |")
    ctx.release()


if __name__ == "__main__":
    run_main(main)
