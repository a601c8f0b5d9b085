"""Cost of the per-tile targets of real samples: per metric, before / after, and end to end.

    python bench/targets.py [--data data/val] [--samples 6] [--workers 1,2] [--device cpu]

Part 1 times ``tile_targets`` on ``--samples`` samples of a captured dataset (1280x720 by default),
one metric at a time, in this process (torch on 2 threads), with FLIP through ``flip-evaluator`` image
by image ("before", rtp <= 0.6) and through the batched torch port that filters the reference once
("after"); JNFLIP shares FLIP's map, so its row is the FLIP map plus the Weber division. Part 2 runs
``compute_targets`` over a copy of those samples (all five metrics, reading and writing included)
with each worker count and prints the wall time per sample. Prints Markdown tables (medians).
``--device`` runs the torch work ("after": FLIP's port and LPIPS) there, a GPU say (``rtp targets
--device``); "before" (``flip-evaluator``) and the numpy metrics stay on the CPU. With a device other
than the CPU, part 3 computes each sample's targets on the CPU and on the device and prints the
largest difference of a tile's target per metric, beside the targets' spread.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import dataset_folder, positive, positives, run_main  # bench/ is on sys.path when run as a script

from rtp import metrics, sdk
from rtp.capture import DatasetReader, compute_targets
from rtp.capture._dataset import sample_path

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    import torch
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

METRICS = ("flip", "jnflip", "lpips", "psnr", "jnyang")


def per_metric(reader: DatasetReader, ids: list[str], device: str = "cpu") -> list[tuple[str, float, float]]:
    rows = []
    samples = [reader[i] for i in ids]
    frames = [(s.final("1x1"), {r: s.final(r) for r in sdk.PREDICTED_RATES}) for s in samples]
    # warm-up: LPIPS weights, torch start-up (and on a GPU its context, cuDNN's kernels, the network's copy)
    metrics.tile_targets(*frames[0], ("lpips", "flip"), 4, device=device)
    fresh = DatasetReader(reader.root)  # samples cache what they decoded: read through a new reader
    t0 = time.perf_counter()
    for i in ids:
        s = fresh[i]
        s.final("1x1"), [s.final(r) for r in sdk.PREDICTED_RATES]
    rows.append(("read the 7 images", (time.perf_counter() - t0) * 1000 / len(samples), float("nan")))
    for m in (*METRICS, "all five"):
        names = METRICS if m == "all five" else (m,)
        times = {}
        for backend in ("flip-evaluator", "torch"):
            ts = []
            for ref, imgs in frames:
                t0 = time.perf_counter()
                metrics.tile_targets(ref, imgs, names, 4, flip_backend=backend,
                                     device=device if backend == "torch" else "cpu")
                ts.append((time.perf_counter() - t0) * 1000)
            times[backend] = statistics.median(ts)
        rows.append((m, times["flip-evaluator"], times["torch"]))
    return rows


def agreement(reader: DatasetReader, ids: list[str], device: str) -> list[tuple[str, float, float]]:
    """Per metric: the largest |CPU - device| of a tile target over the samples, and the largest spread
    (standard deviation) of a sample's targets. Non-finite targets (PSNR's identical tiles) must agree."""
    worst: dict[str, float] = dict.fromkeys(METRICS, 0.0)
    spread: dict[str, float] = dict.fromkeys(METRICS, 0.0)
    for i in ids:
        s = reader[i]
        ref, imgs = s.final("1x1"), {r: s.final(r) for r in sdk.PREDICTED_RATES}
        cpu = metrics.tile_targets(ref, imgs, METRICS, 4, device="cpu")
        other = metrics.tile_targets(ref, imgs, METRICS, 4, device=device)
        for m in METRICS:
            a, b = cpu[m], other[m]
            if not np.array_equal(np.isfinite(a), np.isfinite(b)):
                raise RuntimeError(f"{i}: {m} targets finite on one device and not on the other")
            fin = np.isfinite(a)
            worst[m] = max(worst[m], float(np.abs(a[fin] - b[fin]).max()))
            spread[m] = max(spread[m], float(a[fin].std()))
    return [(m, worst[m], spread[m]) for m in METRICS]


def end_to_end(src: Path, ids: list[str], workers: int, device: str = "cpu") -> float:
    with tempfile.TemporaryDirectory(prefix="rtp-bench-targets-") as d:
        root = Path(d) / "ds"
        (root / "samples").mkdir(parents=True)
        shutil.copy(src / "manifest.json", root / "manifest.json")
        for i in ids:
            os.link(sample_path(src, i), sample_path(root, i)) if _same_fs(src, root) else shutil.copy(
                sample_path(src, i), sample_path(root, i))
        _restrict_manifest(root, ids)
        t0 = time.perf_counter()
        compute_targets(root, METRICS, workers=workers, device=device)
        return (time.perf_counter() - t0) / len(ids)


def _same_fs(a: Path, b: Path) -> bool:
    return os.stat(a).st_dev == os.stat(b).st_dev


def _restrict_manifest(root: Path, ids: list[str]) -> None:
    import json

    m = json.loads((root / "manifest.json").read_text(encoding="utf-8"))
    m["samples"] = ids
    (root / "manifest.json").write_text(json.dumps(m), encoding="utf-8")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=dataset_folder, default="data/val", help="a captured dataset (rtp capture)")
    ap.add_argument("--samples", type=positive, default=6)
    ap.add_argument("--workers", type=positives, default="1,2",
                    help="comma-separated worker counts for the end-to-end part (default: 1,2)")
    ap.add_argument("--device", default="cpu", help="where the batched port and LPIPS run: cpu (default), cuda, "
                    "cuda:N, mps, auto")
    args = ap.parse_args()
    dev = metrics.device_name(metrics.resolve_device(args.device))  # (refused before any work)
    torch.set_num_threads(2)
    reader = DatasetReader(args.data)
    step = max(1, len(reader.ids) // args.samples)
    ids = reader.ids[::step][: args.samples]
    h, w = reader[ids[0]].size
    print(f"{len(ids)} samples of {args.data} ({w}x{h}), {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs, torch {torch.__version__} ({torch.get_num_threads()} threads); the torch work on "
          f"{dev}\n")
    print(f"| per sample, six rates | before: flip-evaluator (ms) | after: batched port, {dev} (ms) | speed-up |")
    print("|---|---:|---:|---:|")
    for name, before, after in per_metric(reader, ids, args.device):
        if after != after:  # nan: not backend dependent
            print(f"| {name} | {before:.0f} | {before:.0f} | |")
        else:
            print(f"| {name} | {before:.0f} | {after:.0f} | {before / after:.2f}x |")
    print("\n| `compute_targets`, all five metrics | workers | s per sample |")
    print("|---|---:|---:|")
    for n in args.workers:
        print(f"| read, compute, write | {n} | {end_to_end(Path(args.data), ids, n, args.device):.2f} |", flush=True)
    if dev != "cpu":  # (auto on a machine without a GPU: the CPU, nothing to compare)
        print(f"\n| metric | largest \\|CPU - {dev}\\| of a tile target | the targets' spread (std) |")
        print("|---|---:|---:|")
        for m, worst, spread in agreement(reader, ids, args.device):
            print(f"| {m} | {worst:.1e} | {spread:.3f} |")


if __name__ == "__main__":
    run_main(main)
