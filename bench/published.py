"""Measure default thresholds for the paper's published models (export/published.yaml).

    python bench/published.py --data data/val --data-l0 data/val-l0

The published FLIP, JNYang, LPIPS and PSNR models come with no threshold, and their output scales
are inferred (docs/export.md): the metric's usual threshold can sit at a model's output floor (every
tile 1x1) or far above it. For each of them this script picks the decision threshold at which the
published model, run on 16-pixel hardware tiles (``sdk.load(tile_size=16)``), fails on no more tiles
than rtp's shipped model of the same metric fails at its default threshold, on the same samples (a
failing tile: its chosen rate's true error is over the metric's threshold). Among those it takes the
one that saves the most shading work. Prints a Markdown table.

``--data`` holds validation-map samples with targets of every metric (default Weber l = 0.02);
``--data-l0`` the same samples with JNYang targets at the published models' l = 1e-10 (their JNYang
is luma difference over luma with a vanishing l).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
from _common import UsageError, check_targets, dataset_folder, run_main  # bench/ is on sys.path when run as a script

from rtp import export, sdk
from rtp.capture import DatasetReader, TargetStore
from rtp.capture.scenes import load_splits
from rtp.evaluate import failing_tiles

PUBLISHED = Path(__file__).resolve().parents[1] / "tests" / "data" / "published"
FILES = {"flip": "FLIP.onnx", "jnyang": "JNYang.onnx", "lpips": "LPIPS.onnx", "psnr": "PSNR.onnx"}


def _grid(thr: float, hib: bool) -> np.ndarray:
    return np.round(np.arange(thr - 25.0, thr + 25.01, 0.25), 2) if hib else thr * np.geomspace(1 / 16, 16, 161)


def _score(preds: list[np.ndarray], gts: list[np.ndarray], t: float, thr: float, hib: bool,
           factors: tuple[float, ...] | None = None) -> tuple[float, float]:
    """(failing share, work saved) of the rates ``select_rates`` chooses at ``t`` (with ``factors``, a model's
    ``rate_factors``, as that model decides) against the targets judged at ``thr``."""
    fails = saved = n = 0.0
    for p, g in zip(preds, gts, strict=True):
        codes = sdk.select_rates(p, t, higher_is_better=hib, factors=factors)
        fails += failing_tiles(codes, g, thr, hib).sum()
        saved += sdk.work_saved(codes, (p.shape[-2] * 16, p.shape[-1] * 16), 16) * codes.size
        n += codes.size
    return fails / n, saved / n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True, type=dataset_folder, help="validation samples with targets of every metric")
    ap.add_argument("--data-l0", required=True, type=dataset_folder,
                    help="the same samples with JNYang targets at Weber l = 1e-10: a copy of --data without its "
                    "targets/ folder, then `rtp targets COPY --metrics jnyang --weber-l 1e-10`")
    ap.add_argument("--models", default=str(PUBLISHED), help="folder of the published .onnx files")
    args = ap.parse_args()
    reader = DatasetReader(args.data)
    validation = set(load_splits()["validation"])
    ids = [i for i in reader.ids if str(reader[i].meta.get("scene")) in validation]
    if not ids:
        raise UsageError(f"{args.data} holds no samples of the validation maps ({', '.join(sorted(validation))})")
    # (what a row reads, checked before the first: a published file or targets missing came after the rows before)
    absent = [name for name in FILES.values() if not (Path(args.models) / name).is_file()]
    if absent:
        raise UsageError(f"--models: {args.models} has no {', '.join(absent)} (the published models)")
    for metric in FILES:
        check_targets(TargetStore(args.data), ids, metric, 16, metric)
    check_targets(TargetStore(args.data_l0), ids, "jnyang", 16, "the published JNYang (--data-l0)")
    scenes = sorted({str(reader[i].meta.get("scene")) for i in ids})
    print(f"{len(ids)} samples of the validation maps ({', '.join(scenes)}) in {args.data}; 16-pixel tiles\n")
    print("| metric | threshold | rtp model: failing / saved | published model's 2x2 range (1st-99th pct) "
          "| published at the same threshold: failing / saved | measured threshold | published at it: failing / saved |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for metric, name in FILES.items():
            info = sdk.METRICS[metric]
            ours = sdk.load(metric)
            thr, hib = ours.metadata.default_threshold, ours.metadata.higher_is_better
            store = TargetStore(args.data)
            gts = [store.load(i, metric, 16) for i in ids]
            x = [reader[i].inputs(ours.metadata.inputs) for i in ids]
            # (as the shipped model decides at its default: with its thresholds per rate; the published ones have none)
            f_ours, s_ours = _score([ours.predict(v) for v in x], gts, thr, thr, hib, ours.metadata.rate_factors)
            adopted = export.adopt(Path(args.models) / name, None, Path(tmp) / name, dynamic=True)
            theirs = sdk.load(adopted, tile_size=16)
            gts_t = [TargetStore(args.data_l0).load(i, metric, 16) for i in ids] if metric == "jnyang" else gts
            xt = [reader[i].inputs(theirs.metadata.inputs) for i in ids]
            preds = [theirs.predict(v) for v in xt]
            f_same, s_same = _score(preds, gts_t, thr, thr, hib)
            best = (float("nan"), float("nan"), -1.0)
            for t in _grid(thr, hib):
                f, s = _score(preds, gts_t, float(t), thr, hib)
                if f <= f_ours and s > best[2]:
                    best = (float(t), f, s)
            t_best, f_best, s_best = best
            unit = f" {info.units}" if info.units == "dB" else ""
            e22 = np.concatenate([p[sdk.PREDICTED_RATES.index("2x2")].ravel() for p in preds])
            lo, hi = np.percentile(e22, [1, 99])
            print(f"| {metric} | {thr:g}{unit} | {100 * f_ours:.1f}% / {100 * s_ours:.1f}% | {lo:.3g} to {hi:.3g} | "
                  f"{100 * f_same:.1f}% / "
                  f"{100 * s_same:.1f}% | {t_best:.4g}{unit} | {100 * f_best:.1f}% / {100 * s_best:.1f}% |", flush=True)


if __name__ == "__main__":
    run_main(main)
