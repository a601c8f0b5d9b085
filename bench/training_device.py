"""Training speed per device: the same recipe, data and seed trained for a few hundred steps on the CPU
and on each GPU torch can use, timed step by step, with the validation score each run ends on.

    python bench/training_device.py --data data/train [--metric jnyang] [--steps 400] [--devices cpu,cuda]
                                    [--config shipped]

The training is ``rtp.train.train`` (what ``rtp train --device D`` runs) into a temporary checkpoint,
from the same seed on every device: the same initial weights and the same crops in the same order, so
the runs differ only by the devices' float arithmetic. A step's time is the wall-clock time between two
steps (cutting and copying the batch on the host, the forward and backward passes, the optimizer); the
table gives the median after the first ``--warmup`` steps (cuDNN's autotuner and the allocator settle
there), the recipe's whole schedule at that pace, and the peak GPU memory. Reading the samples takes
the same time on every device and is printed once per run. ``--devices`` defaults to the CPU and, where
torch sees one, ``cuda``; a device torch cannot use is refused before any work.

Each checkpoint a GPU run writes is loaded back with plain ``torch.load`` onto the CPU, without
``map_location``: a checkpoint with a tensor left on the GPU would not load on a machine without one
(the script fails, exit 1, if it finds one). Prints Markdown tables.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from _common import cpu_description, dataset_folder, positive, run_main  # bench/ is on sys.path as a script

from rtp import sdk
from rtp.metrics import device_name, resolve_device

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    import torch

    from rtp.train import TrainConfig, train
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

#: Steps whose time is left out of the median: the first steps pay cuDNN's autotuner, the caching
#: allocator's first allocations and the CPU's cold caches.
WARMUP = 20


def _devices(text: str) -> list[str]:
    """``--devices``: a comma-separated list of ``rtp train --device`` values, at least one."""
    names = [d.strip() for d in text.split(",") if d.strip()]
    if not names:
        raise argparse.ArgumentTypeError("expected device names, comma-separated (cpu, cuda, cuda:1, mps)")
    return names


def _tensors_off_cpu(value: Any, where: str = "") -> list[str]:
    """The paths (``training.optimizer.state.0.exp_avg``) of the tensors in ``value`` not on the CPU."""
    if isinstance(value, torch.Tensor):
        return [] if value.device.type == "cpu" else [f"{where} ({value.device})"]
    if isinstance(value, dict):
        return [p for k, v in value.items() for p in _tensors_off_cpu(v, f"{where}.{k}" if where else str(k))]
    if isinstance(value, (list, tuple)):
        return [p for k, v in enumerate(value) for p in _tensors_off_cpu(v, f"{where}.{k}")]
    return []


def run(cfg: TrainConfig, warmup: int = WARMUP) -> dict[str, Any]:
    """Train ``cfg`` and time it: the read, the steps' median and the run's end (validation, peak memory)."""
    dev = resolve_device(cfg.device)
    if dev.type == "cuda":
        torch.cuda.reset_peak_memory_stats(dev)
    marks: list[float] = []
    read: list[float] = []
    start = time.perf_counter()
    result = train(cfg, progress=lambda step, total, loss: marks.append(time.perf_counter()),
                   loading=lambda k, n: read.append(time.perf_counter()))
    steps = [b - a for a, b in zip(marks, marks[1:])][max(0, warmup - 1):]
    if not steps:  # (main refuses such --steps first)
        raise sdk.ParameterError(f"steps: {cfg.steps} steps leave none to time after the {warmup} of warm-up", "steps")
    off = _tensors_off_cpu(torch.load(cfg.out, weights_only=True)) if dev.type != "cpu" else []
    return {
        "device": device_name(dev),
        "threads": torch.get_num_threads() if dev.type == "cpu" else None,
        "read_s": (read[-1] - start) if read else 0.0,
        "step_ms": 1000 * statistics.median(steps),
        "total_s": time.perf_counter() - start,
        "r2": result.val["transformed"]["r2"],
        "mae": result.val["transformed"]["mae"],
        "peak_mib": torch.cuda.max_memory_allocated(dev) / 2**20 if dev.type == "cuda" else None,
        "off_cpu": off,
    }


def table(rows: list[dict[str, Any]], recipe_steps: int) -> str:
    """The runs as a Markdown table, the CPU's step time as the speed-up's reference where it ran."""
    cpu = next((r["step_ms"] for r in rows if r["device"] == "cpu"), None)
    lines = [f"| device | ms a step | steps / s | the recipe's {recipe_steps:,} steps (min) | speed-up over the CPU "
             f"| validation R² / MAE (transformed) | peak GPU memory (MiB) |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        name = r["device"] + (f", {r['threads']} threads" if r["threads"] else "")
        up = f"{cpu / r['step_ms']:.1f}x" if cpu else "-"
        peak = f"{r['peak_mib']:.0f}" if r["peak_mib"] is not None else "-"
        lines.append(f"| {name} | {r['step_ms']:.1f} | {1000 / r['step_ms']:.0f} | "
                     f"{recipe_steps * r['step_ms'] / 60000:.1f} | {up} | {r['r2']:.3f} / {r['mae']:.4f} | {peak} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, type=dataset_folder, help="dataset folder with targets (rtp targets)")
    p.add_argument("--metric", default="jnyang", choices=tuple(sdk.METRICS), help="the targets trained on")
    p.add_argument("--config", default="shipped", help="training recipe: a YAML file or a packaged recipe's name")
    p.add_argument("--steps", type=positive, default=400, help="steps trained on each device (default 400)")
    p.add_argument("--warmup", type=positive, default=WARMUP, help=f"steps left out of the median (default {WARMUP})")
    p.add_argument("--devices", type=_devices, default=None,
                   help="comma-separated rtp train --device values (default: cpu, and cuda where torch sees it)")
    args = p.parse_args(argv)
    if args.steps <= args.warmup:
        p.error(f"--steps {args.steps} leaves no step to time after --warmup {args.warmup}")
    devices = args.devices or ["cpu", *(["cuda"] if torch.cuda.is_available() else [])]
    for d in devices:  # a device torch cannot use, before any run
        resolve_device(d)
    print(f"# rtp training speed: {args.metric}, recipe {args.config}, {args.steps} steps on {args.data}")
    print(f"# CPU: {cpu_description()}; torch {torch.__version__}")
    recipe_steps = TrainConfig.from_recipe(args.config, data=args.data, metric=args.metric, out="unused.pt").steps
    rows = []
    with tempfile.TemporaryDirectory(prefix="rtp-bench-train-") as tmp:
        for k, d in enumerate(devices):  # (a checkpoint each: a device named twice trains twice)
            cfg = TrainConfig.from_recipe(args.config, data=args.data, metric=args.metric,
                                          out=str(Path(tmp) / f"{k}-{d.replace(':', '-')}.pt"), device=d,
                                          steps=args.steps, val_every=args.steps, save_every=args.steps)
            r = run(cfg, args.warmup)
            print(f"# {r['device']}: samples read in {r['read_s']:.1f} s, {args.steps} steps and the validation in "
                  f"{r['total_s'] - r['read_s']:.1f} s", flush=True)
            rows.append(r)
    print()
    print(table(rows, recipe_steps))
    off = [f"{r['device']}: {p}" for r in rows for p in r["off_cpu"]]
    if off:
        print(f"\nthe checkpoint holds tensors off the CPU (it would not load without the GPU): {'; '.join(off[:5])}",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    run_main(main)
