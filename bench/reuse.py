"""Prediction reuse's cost on a CPU: a frame the network runs on against a frame whose estimates are
carried (``sdk.PredictionReuse``, each reduction at the default pixel step, the mean also at every
second and every eighth pixel, rescaled by the blocks' variance for models with ``.blocks`` inputs,
the trunk's features carried and the tail run for a model that splits, ``carry="features"``, at the
default step and at every eighth pixel), and the ``unseen="fresh"`` crops.

    python bench/reuse.py [--model jnyang] [--repeats 7] [--threads 2] [--spin-between-runs]

The camera pans: every pixel comes from 3 pixels to its left, and a strip at the left edge is new
(unseen). With a 3-pixel strip no tile is more than half unseen (nothing to predict afresh); wider
strips (a share of the frame's width) give ``fresh`` that many tiles to predict on crops. Inputs
are random (the cost does not depend on them). Prints a Markdown table of medians (ms) and, for
``fresh``, the crops' share of a whole-frame run.
"""

from __future__ import annotations

import argparse
import platform
from typing import Any

import numpy as np
import onnxruntime as ort
from _common import median_ms, positive, run_main  # bench/ is on sys.path when run as a script

from rtp import sdk

FRAMES = ((1920, 1080), (1280, 720))
STRIPS = (0.02, 0.05, 0.10)


def _pan(h: int, w: int, strip: int) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    rows, cols = np.indices((h, w))
    seen = np.ones((h, w), np.float32)
    seen[:, :strip] = 0
    return (rows, np.maximum(cols - 3, 0)), seen


def _carried(pred: sdk.ShadingRatePredictor, x: np.ndarray, strip: int, repeats: int,
             **kw: Any) -> tuple[float, float]:
    """Median ms of a frame between network runs, and its network work share."""
    reuse = sdk.PredictionReuse(pred, every=10**9, **kw)
    fetch, seen = _pan(x.shape[1], x.shape[2], strip)
    reuse.predict(x)
    ms = median_ms(lambda: reuse.predict(x, fetch, seen), repeats)
    return ms, reuse.work


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="jnyang", help="a shipped model name or an .onnx path")
    ap.add_argument("--repeats", type=positive, default=7)
    ap.add_argument("--threads", type=positive, default=2, help="onnxruntime intra-op threads")
    ap.add_argument("--spin-between-runs", action="store_true",
                    help="onnxruntime's worker threads spin on between runs (its default; sdk.load stops them)")
    args = ap.parse_args()
    pred = sdk.load(args.model, providers=["CPUExecutionProvider"], threads=args.threads,
                    spin_between_runs=args.spin_between_runs)
    print(f"rtp {sdk.__version__}, onnxruntime {ort.__version__}, {platform.processor() or platform.machine()}, "
          f"{args.threads} threads, median of {args.repeats}, model {args.model}\n")
    blocks = any(c.endswith(".blocks") for c in pred.metadata.inputs)
    print("| ms | network runs (sdk predict) | carried: mean | worst | upper | mean, step 2 | mean, step 8 | "
          + ("mean, rescale 0.25 | " if blocks else "")
          + ("features carried, tail run | the same, step 8 | the tail alone | " if pred.splits else "")
          + " | ".join(f"fresh, {100 * s:g}% of the width new" for s in STRIPS) + " |")
    print("|---|---:|---:|---:|---:|---:|---:|" + "---:|" * (len(STRIPS) + blocks + 3 * pred.splits))
    for w, h in FRAMES:
        # a session of its own per frame size, as an engine runs at one: onnxruntime sessions that ran at
        # another size first ran a split model's tail at 720p in 8.5 ms instead of 4.8
        pred = sdk.load(args.model, providers=["CPUExecutionProvider"], threads=args.threads,
                        spin_between_runs=args.spin_between_runs)
        x = np.random.default_rng(0).random((len(pred.metadata.inputs), h, w), dtype=np.float32)
        net = median_ms(lambda x=x, pred=pred: pred.predict(x), args.repeats)
        carried = [_carried(pred, x, 3, args.repeats, reduce=r)[0] for r in ("mean", "worst", "upper")]
        carried += [_carried(pred, x, 3, args.repeats, step=step)[0] for step in (2, 8)]
        if blocks:  # the inputs given on carried frames too: the .blocks planes' per-tile means
            carried.append(_carried(pred, x, 3, args.repeats, rescale=0.25)[0])
        if pred.splits:
            carried += [_carried(pred, x, 3, args.repeats, carry="features", step=step)[0] for step in (None, 8)]
            feats = pred.predict_split(x)[1]
            carried.append(median_ms(lambda x=x, feats=feats, pred=pred: pred.predict_tail(feats, x), args.repeats))
        fresh = [_carried(pred, x, int(s * w), args.repeats, unseen="fresh") for s in STRIPS]
        print(f"| {w}x{h} | {net:.1f} | " + " | ".join(f"{c:.1f}" for c in carried) + " | "
              + " | ".join(f"{ms:.1f} (crops {100 * work:.0f}%)" for ms, work in fresh) + " |")
    print("\nA frame at k = 4 costs on average (one network run + three carried frames) / 4.")


if __name__ == "__main__":
    run_main(main)
