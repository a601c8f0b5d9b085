"""Cost of computing the metrics explicitly, per frame pair, to compare with predicting them.

    python bench/metrics.py [--repeats 3] [--threads 2] [--targets]

For one reference / test pair (a synthetic frame and its 2x2-rate version) at 1280x720 and
1920x1080, times each metric's per-pixel map plus 16x16 tile pooling through rtp.metrics (PSNR: the
per-tile MSE in dB). Prints a Markdown table of medians in ms after one warm-up run. ``--targets``
adds a row for ``tile_targets`` with the paper's five metrics over all six reduced rates (slow).
FLIP runs on flip-evaluator's OpenMP threads (``OMP_NUM_THREADS``); ``--threads`` sets torch's.
"""

from __future__ import annotations

import argparse
import functools
import os
import platform
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from _common import median_ms, paper_model, positive, run_main  # bench/ is on sys.path when run as a script

from rtp import metrics, sdk

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    import torch
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

TILE = 16


def frame(h: int, w: int) -> np.ndarray:
    """Deterministic (h, w, 3) float32 test frame: gradients, sinusoids, hard edges and noise."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = np.stack([0.5 + 0.4 * np.sin(x / 23.0), 0.5 + 0.4 * np.cos(y / 17.0), (x + y) / (h + w)], -1)
    img[((x // 64) + (y // 64)) % 2 == 0] *= 0.6
    img += 0.03 * np.random.default_rng(0).standard_normal(img.shape).astype(np.float32)
    return np.clip(img, 0, 1).astype(np.float32)


def coarse(img: np.ndarray, rw: int, rh: int) -> np.ndarray:
    out = np.repeat(np.repeat(img[::rh, ::rw], rh, axis=0), rw, axis=1)
    return np.ascontiguousarray(out[: img.shape[0], : img.shape[1]])


CASES: dict[str, Callable[[np.ndarray, np.ndarray], object]] = {
    "FLIP": lambda r, t: metrics.tile_metric("flip", r, t, TILE),
    "LPIPS": lambda r, t: metrics.tile_metric("lpips", r, t, TILE),
    "PSNR": lambda r, t: metrics.tile_metric("psnr", r, t, TILE),
    "Yang": lambda r, t: metrics.tile_metric("yang", r, t, TILE),
    "JNYang": lambda r, t: metrics.tile_metric("jnyang", r, t, TILE),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=positive, default=3)
    ap.add_argument("--threads", type=positive, default=2, help="torch intra-op threads (LPIPS)")
    ap.add_argument("--targets", action="store_true", help="also time tile_targets over six rates (slow)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    sizes = ((1280, 720), (1920, 1080))
    results: dict[str, list[float]] = {name: [] for name in CASES}
    if args.targets:
        results["tile_targets, 6 rates x 5 metrics"] = []
    key = "rtp predict (network, all 6 rates at once)"
    results[key] = []
    tmp = tempfile.TemporaryDirectory()
    predictor = sdk.load(paper_model(Path(tmp.name))[1], providers=["CPUExecutionProvider"], threads=args.threads)
    for w, h in sizes:
        ref = frame(h, w)
        test = coarse(ref, 2, 2)
        for name, fn in CASES.items():
            results[name].append(median_ms(functools.partial(fn, ref, test), args.repeats))
        if args.targets:
            rates = {r: coarse(ref, *map(int, r.split("x"))) for r in sdk.PREDICTED_RATES}
            results["tile_targets, 6 rates x 5 metrics"].append(
                median_ms(functools.partial(metrics.tile_targets, ref, rates, tile=TILE), 1)
            )
        x = np.random.default_rng(0).random((4, h, w), dtype=np.float32)
        results[key].append(median_ms(functools.partial(predictor.predict, x), args.repeats))
    tmp.cleanup()
    print(
        f"rtp {sdk.__version__}, torch {torch.__version__} ({args.threads} threads), "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}, {os.cpu_count()} CPUs, "
        f"{platform.processor() or platform.machine()}, median of {args.repeats} after a warm-up, "
        f"map + {TILE}x{TILE} tile pooling per frame pair\n"
    )
    print("| metric | " + " | ".join(f"{w}x{h} (ms)" for w, h in sizes) + " |")
    print("|---|" + "---|" * len(sizes))
    for name, values in results.items():
        print(f"| {name} | " + " | ".join(f"{v:.1f}" for v in values) + " |")


if __name__ == "__main__":
    run_main(main)
