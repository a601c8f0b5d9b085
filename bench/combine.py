"""rtp's rates beside an engine's own, as the hardware combines them: judged or not.

    python bench/combine.py jnyang --data data/val [--threshold T] [--savings 0.5,0.6,0.7,0.8]

An engine that already writes shading rates (a foveated periphery, rates from motion blur) combines rtp's image
with them in the hardware's combiner (docs/runtime.md "The engine's own rates"). This compares, on every sample of
``--data`` (the validation maps by default; targets of the model's metric computed), the rates the device shades:

- ``engine alone``: the engine's rates, rtp off;
- ``rtp alone``: rtp's ``select_rates``, no engine rates;
- ``unaware``: rtp's image chosen alone, combined with the engine's by ``max`` (the coarser per axis);
- ``aware``: ``select_rates(engine_rates=, combiner="max")``, which judges the rate the device shades.

Two engine images, made per sample from what an engine has: ``foveation``, fixed rings (1x1 inside 0.4 of the
half-diagonal from the centre, 2x2 to 0.7, 4x4 beyond); ``motion``, each axis coarsened to 2 where the tile's
mean screen motion along it is at least 2 pixels a frame and to 4 from 8 (the clamp of a device: no 4x1 or 1x4).
These are examples of engine images, not rtp's recommendation.

Printed (Markdown): per image, the work the device's rates save (tiles weighed by pixels), the share of tiles
whose true error at the rate shaded fails the threshold, and the share failing beyond the engine's rate (the
rate shaded differs from the engine's own: failures the combination with rtp added), and the share of tiles
shaded at a rate neither rtp's image nor the engine's holds. Then a budget (``select_rates_for_saving``) with the
foveated periphery: the saving asked, what the device saves unaware (mean, lowest and highest frame) and aware,
and the failing tiles beyond the engine's.
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import UsageError, add_model_args, check_targets, run_main, scene_ids  # bench/ is on sys.path as a script

from rtp import sdk
from rtp.capture import DatasetReader, TargetStore
from rtp.evaluate import foveation_rates, motion_rates

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

C = sdk.RATE_CODES
IMAGES = ("foveation", "motion")  # (rtp.evaluate's examples of an engine's own rates)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_model_args(ap, "a model: a shipped model's name or an .onnx path")
    ap.add_argument("--threshold", type=float, default=None, help="the threshold (default: the model's)")
    ap.add_argument("--savings", default="0.5,0.6,0.7,0.8", help="budgets to try with the foveated periphery")
    args = ap.parse_args(argv)
    try:
        # once each, in the order given (a saving given twice was tallied twice into one row: its failing tiles beyond
        # the engine's doubled, and the row printed twice)
        savings = list(dict.fromkeys(float(s) for s in args.savings.split(",")))
    except ValueError as err:
        raise UsageError(f"--savings: expected numbers, comma-separated, got {args.savings!r}") from err
    if not all(0.0 <= s <= sdk.MAX_SAVING for s in savings):  # (NaN fails too; before the samples are read)
        raise UsageError(f"--savings: expected shares of the shading work to save, each in [0, {sdk.MAX_SAVING:g}] (4x4 "
                         f"saves {sdk.MAX_SAVING:g}), got {args.savings!r}")
    pred = sdk.load(args.model)
    meta = pred.metadata
    if meta.higher_is_better:
        raise UsageError(f"{args.model} predicts {meta.metric}, higher is better: this compares error metrics")
    thr = meta.default_threshold if args.threshold is None else sdk.check_threshold(args.threshold, False)
    reader, store = DatasetReader(args.data), TargetStore(args.data)
    ids = scene_ids(reader, args.scene)
    if not ids:
        raise UsageError(f"{args.data} holds no sample of {args.scene}")
    check_targets(store, ids, meta.metric, pred.tile_size, args.model)
    kinds = ("engine alone", "rtp alone", "unaware", "aware")
    tally = {(img, k): np.zeros(5) for img in IMAGES for k in kinds}  # pixels saved, pixels, fail, beyond, neither
    budget: dict[tuple[float, str], list[float]] = {(s, k): [] for s in savings for k in ("unaware", "aware")}
    beyond_budget = {(s, k): 0.0 for s in savings for k in ("unaware", "aware")}
    fit = {"higher_is_better": False, "factors": meta.rate_factors}
    share, channel = np.zeros(256), np.zeros(256, np.intp)
    for k, r in enumerate(sdk.PREDICTED_RATES):
        share[C[r]], channel[C[r]] = sdk.work_saved(r), k
    n_tiles = 0
    for i in tqdm(ids, desc="selecting", unit="sample"):
        s = reader[i]
        est = pred.predict(s.inputs(meta.inputs))
        truth = store.load(i, meta.metric, pred.tile_size)
        h, w = s.size
        th, tw = est.shape[1:]
        n_tiles += th * tw
        pixels = np.outer(sdk.tile_extents(h, pred.tile_size), sdk.tile_extents(w, pred.tile_size)).astype(float)

        def judged(shaded: np.ndarray, engine: np.ndarray, image: np.ndarray) -> np.ndarray:
            """Pixels saved, pixels, failing tiles, those not at the engine's rate, tiles at neither's rate."""
            true = np.take_along_axis(truth, channel[shaded][None], axis=0)[0]  # noqa: B023 (used at once)
            fail = (shaded != C["1x1"]) & ~(true < thr)
            return np.array([(share[shaded] * pixels).sum(), pixels.sum(), fail.sum(),  # noqa: B023
                             (fail & (shaded != engine)).sum(), ((shaded != engine) & (shaded != image)).sum()])

        alone = sdk.select_rates(est, thr, **fit)
        full = np.zeros_like(alone)
        images = {"foveation": foveation_rates(th, tw),
                  "motion": motion_rates(s.channel("motion.x"), s.channel("motion.y"), pred.tile_size)}
        for img, engine in images.items():
            aware = sdk.select_rates(est, thr, engine_rates=engine, **fit)
            tally[img, "engine alone"] += judged(engine, engine, full)
            tally[img, "rtp alone"] += judged(alone, full, alone)
            tally[img, "unaware"] += judged(sdk.combine_rates(engine, alone, "max"), engine, alone)
            tally[img, "aware"] += judged(sdk.combine_rates(engine, aware, "max"), engine, aware)
        engine = images["foveation"]
        for saving in savings:
            for kind, kw in (("unaware", {}), ("aware", {"engine_rates": engine})):
                sel = sdk.select_rates_for_saving(est, saving, frame_size=(h, w), tile_size=pred.tile_size, **kw, **fit)
                saved_px, px, _, beyond, _ = judged(sdk.combine_rates(engine, sel.rates, "max"), engine, sel.rates)
                budget[saving, kind].append(saved_px / px)
                beyond_budget[saving, kind] += beyond
    where = f"{args.data} ({args.scene})"
    print(f"\n{meta.metric} {thr:g}, {args.model}, {len(ids)} samples of {where}, {n_tiles:,} tiles of "
          f"{pred.tile_size} px; the engine's rates combined with rtp's by max\n")
    print("| engine image | rates shaded | work saved % | failing tiles % | failing beyond the engine's rate % "
          "| shaded at a rate neither chose % |")
    print("|---|---|---:|---:|---:|---:|")
    for img in IMAGES:
        for kind in kinds:
            saved_px, px, fail, beyond, neither = tally[img, kind]
            print(f"| {img} | {kind} | {100 * saved_px / px:.1f} | {100 * fail / n_tiles:.2f} | "
                  f"{100 * beyond / n_tiles:.2f} | {100 * neither / n_tiles:.2f} |")
    print(f"\nA budget beside the foveated periphery (which saves "
          f"{100 * tally['foveation', 'engine alone'][0] / tally['foveation', 'engine alone'][1]:.1f}% alone): "
          f"what the device saves per frame\n")
    print("| saving asked | unaware: mean % | lowest frame % | highest frame % | failing beyond the engine's % "
          "| aware: mean % | lowest frame % | highest frame % | failing beyond the engine's % |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for saving in savings:
        cells = []
        for kind in ("unaware", "aware"):
            got = 100 * np.array(budget[saving, kind])
            cells += [f"{got.mean():.1f}", f"{got.min():.1f}", f"{got.max():.1f}",
                      f"{100 * beyond_budget[saving, kind] / n_tiles:.2f}"]
        print(f"| {100 * saving:g} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    run_main(main)
