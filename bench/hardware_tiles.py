"""Models on one hardware tile size, on a fine threshold sweep: which saves more at matched failing tiles,
and which default threshold fails as often as a reference share.

    python bench/hardware_tiles.py jnyang jnyang-8px --data data/val8 --tile-size 8
    python bench/hardware_tiles.py jnyang-8px --data data/train --tile-size 8 --fail-share 0.078
    python bench/hardware_tiles.py psnr psnr-8px --data data/val8 --tile-size 8

Each model is loaded for ``--tile-size`` pixels (``sdk.load(model, tile_size=)``: a 16-pixel model on
8-pixel tiles takes its model tile's values; an 8-pixel model decides each tile itself) and predicts
every sample of ``--data`` on the maps of ``--scene``; the targets are the dataset's at that tile size.
A tile fails when its true error at the chosen rate is over the metric's judging threshold (the first
model's default; ``--judge``), or its PSNR under it. The decision threshold is swept over 160 log-spaced
factors of it (0.05x to 4x; for PSNR the same factors on the error's amplitude, the judging dB minus 20
log10 of each: +26 to -12 dB), finer than ``rtp evaluate``'s sqrt(2) steps, whose linear interpolation
across a wide step reads the saving at 1-5% failing tiles low. Prints per model the work saved at 1, 2, 5
and 10% failing tiles, the failing share and saving at its own default threshold, and with ``--fail-share
S`` the decision threshold at which it fails on S of the tiles (to set a default with ``rtp-export
--retune``). The work saved is the mean over tiles of 1 - 1/(W·H) of the chosen rate (``rtp evaluate`` weighs
tiles by their pixels: the same wherever the frame is whole tiles, as 1280x720 on 8- and 16-pixel tiles, every run
the docs quote; partial edge tiles count whole here). A share the sweep never
fails that rarely reads "-"; one it never fails that often reads ">=" before the sweep's best saving (a lower
bound, as ``bench/report.py`` marks it), and its threshold "-" with the failing shares the sweep covers.
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import (  # bench/ is on sys.path as a script
    UsageError,
    add_model_args,
    check_targets,
    number,
    positive,
    run_main,
    scene_ids,
    share,
)

from rtp import sdk
from rtp.capture import DatasetReader, TargetStore

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

SWEEP = np.exp(np.linspace(np.log(0.05), np.log(4.0), 160))
SHARES = (0.01, 0.02, 0.05, 0.10)
_SAVED = {sdk.RATE_CODES[r]: 1.0 - 1.0 / (int(r[0]) * int(r[2])) for r in sdk.ALL_RATES}


def outcome(pred: np.ndarray, truth: np.ndarray, decide: float, judge: float,
            factors: tuple[float, ...] | None, higher_is_better: bool = False) -> tuple[float, float]:
    """(failing share, work saved) of the decision threshold ``decide``, a tile failing over ``judge`` (under
    it for PSNR, ``higher_is_better``); ``pred`` and ``truth`` are ``(6, tiles)``."""
    codes = sdk.select_rates(pred[:, :, None], decide, factors=factors, higher_is_better=higher_is_better)[:, 0]
    saved = np.zeros(codes.shape)
    fail = np.zeros(codes.shape, bool)
    for i, r in enumerate(sdk.PREDICTED_RATES):
        m = codes == sdk.RATE_CODES[r]
        saved[m] = _SAVED[sdk.RATE_CODES[r]]
        fail[m] = truth[i][m] < judge if higher_is_better else truth[i][m] > judge
    return float(fail.mean()), float(saved.mean())


def saved_cells(fails: np.ndarray, saved: np.ndarray, shares: tuple[float, ...]) -> list[str]:
    """The work saved % at each of ``shares`` failing tiles, read off a sweep's points (``fails`` ascending, ``saved``
    the best saving up to each): "-" where the sweep never fails that rarely, ">= " before its best saving where it
    never fails that often (a lower bound: read plain, the sweep's end passed for the saving at that share)."""
    out = []
    for s in shares:
        if fails[0] > s:
            out.append("-")
            continue
        v = 100 * float(np.interp(s, fails, saved))
        out.append(f"{'>= ' if fails[-1] < s else ''}{v:.1f}")
    return out


def threshold_at(fails: np.ndarray, thresholds: list[float], share: float) -> str:
    """The decision threshold at which the sweep fails on ``share`` of the tiles (``fails``: the failing share of each
    of ``thresholds``, from the strictest to the loosest), linear between the sweep's points; where the sweep never
    fails on that share (its strictest fails more, or its loosest less), "-" and the shares it covers, not the end
    threshold that ``np.interp`` clamps to."""
    if not fails[0] <= share <= fails[-1]:
        return f"- (the sweep fails on {100 * fails[0]:.1f}-{100 * fails[-1]:.1f}%)"
    return f"{float(np.interp(share, fails, thresholds)):.4g}"


def decision(judge: float, factor: float, higher_is_better: bool) -> float:
    """The decision threshold ``factor`` of the sweep stands for: ``judge x factor`` for an error, for PSNR
    ``judge - 20 log10(factor)`` dB (a factor on the error's amplitude, as ``rate_factors``)."""
    return judge - 20.0 * float(np.log10(factor)) if higher_is_better else judge * factor


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_args(ap, "an rtp model (.onnx) or a shipped model's name")
    ap.add_argument("more", nargs="*", help="more models, on the same tiles and samples")
    ap.add_argument("--tile-size", type=positive, default=None, help="the hardware tile size (default: the first "
                    "model's own)")
    ap.add_argument("--judge", type=number(-1e6, 1e6), default=None, help="the metric threshold a tile fails over (default: the "
                    "first model's default_threshold)")
    ap.add_argument("--fail-share", type=share, default=None, help="also print each model's decision threshold "
                    "that fails on this share of the tiles")
    args = ap.parse_args(argv)
    preds = [sdk.load(m, providers=["CPUExecutionProvider"]) for m in [args.model, *args.more]]
    metas = [p.metadata for p in preds]
    if len({m.metric for m in metas}) > 1:
        raise UsageError(f"expected models of one metric, got {', '.join(sorted({m.metric for m in metas}))}")
    higher = metas[0].higher_is_better
    tile = args.tile_size or preds[0].tile_size
    preds = [sdk.load(m, providers=["CPUExecutionProvider"], tile_size=tile) for m in [args.model, *args.more]]
    try:  # (in the metric's units: checked before the predictions, which take minutes)
        judge = float(metas[0].default_threshold if args.judge is None else sdk.check_threshold(args.judge, higher))
    except sdk.ParameterError as err:
        raise UsageError(f"--judge: {str(err).removeprefix('threshold: ')}") from None
    reader, store = DatasetReader(args.data), TargetStore(args.data)
    ids = scene_ids(reader, args.scene)
    if not ids:
        raise UsageError(f"{args.data} holds no sample of {args.scene}")
    check_targets(store, ids, metas[0].metric, tile, args.model)
    truth = np.concatenate([store.load(i, metas[0].metric, tile).reshape(6, -1) for i in ids], axis=1)
    print(f"\n{metas[0].metric} on {tile}-pixel tiles: {len(ids)} samples of {args.data} ({args.scene}), a tile failing "
          f"{'under' if higher else 'over'} {judge:g}; work saved % at {' / '.join(f'{100 * s:g}' for s in SHARES)}% "
          f"failing tiles (a sweep of {len(SWEEP)} thresholds; -: it never fails that rarely, >=: never that often, "
          "a lower bound)\n")
    print("| model | model tiles | saved % at 1 / 2 / 5 / 10% failing | default threshold: failing / saved %"
          + (f" | threshold failing on {100 * args.fail_share:g}%" if args.fail_share is not None else "") + " |")
    print("|---|---:|---|---|" + ("---|" if args.fail_share is not None else ""))
    for name, p, m in zip([args.model, *args.more], preds, metas):
        est = np.concatenate([p.predict(reader[i].inputs(m.inputs)).reshape(6, -1)
                              for i in tqdm(ids, desc=str(name), unit="sample", leave=False)], axis=1)
        factors = m.rate_factors
        pts = sorted(outcome(est, truth, decision(judge, f, higher), judge, factors, higher) for f in SWEEP)
        fails = np.array([q[0] for q in pts])
        saved = np.maximum.accumulate(np.array([q[1] for q in pts]))
        d = outcome(est, truth, m.default_threshold, judge, factors, higher)
        row = (f"| {name} | {m.tile_size} | {' / '.join(saved_cells(fails, saved, SHARES))} | "
               f"{m.default_threshold:g}: {100 * d[0]:.1f} / {100 * d[1]:.1f}")
        if args.fail_share is not None:
            thrs = [decision(judge, f, higher) for f in SWEEP]  # from the strictest to the loosest
            by_thr = np.array([outcome(est, truth, t, judge, factors, higher)[0] for t in thrs])
            row += f" | {threshold_at(by_thr, thrs, args.fail_share)}"
        print(row + " |")
    return 0


if __name__ == "__main__":
    run_main(main)
