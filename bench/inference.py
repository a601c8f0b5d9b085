"""Inference cost: every shipped model and rtp's fast networks next to the paper's network, and the
paper's network through rtp.sdk, the bare onnxruntime session and torch.

    python bench/inference.py [--repeats 7] [--threads 2] [MODEL.onnx ...]

The paper's configuration (4 inputs, outputs 1x2/2x1/2x4/4x2, 16x16 tiles, width 16) and the fast
architectures (``rtp train --arch fast``) are built with random weights (cost does not depend on the
weights) and exported with rtp-export; the shipped models are loaded from ``rtp.models``, and any
``MODEL.onnx`` given (for example the study's, ``data/study/*.onnx``) is added, named by its file name
(by its path as given where two given share one). Each is
timed in the same run at 1920x1080 and 1280x720, in rounds (each model once a round, ``--repeats``
rounds). Prints Markdown tables of medians (ms) and each model's speed-up over the paper's network:
the median over the rounds of the two times' ratio within a round, and its range; and the machine's
memory speed (a copy of nine 1080p planes), which bounds the shipped models on CPUs with little of it.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from collections.abc import Callable, Hashable
from pathlib import Path

import numpy as np
import onnxruntime as ort
from _common import (
    cpu_description,
    interleaved_ms,
    median_ms,
    paper_model,
    positive,
    run_main,
)

from rtp import sdk

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    import torch
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

FRAMES = ((1920, 1080), (1280, 720))
#: rtp's fast networks timed next to the paper's (train/model.py FastNet): (width, depth, stem, inputs,
#: stem layers).
FAST = ((16, 3, 4, 4, 1), (16, 5, 4, 4, 1), (24, 4, 4, 4, 1), (32, 3, 4, 4, 1), (16, 3, 2, 4, 1), (16, 3, 8, 4, 1),
        (16, 3, 4, 6, 1), (16, 3, 4, 7, 1), (16, 3, 4, 10, 1), (16, 3, 4, 4, 2), (16, 3, 4, 7, 2))


def _params(path: Path) -> int:
    import onnx

    return int(sum(np.prod(t.dims) for t in onnx.load(str(path)).graph.initializer))


def _models(folder: Path, threads: int, extra: list[str]) -> dict[str, tuple[sdk.ShadingRatePredictor, tuple[str, int]]]:
    """The predictors to time, by name, with (architecture, parameter count)."""
    out: dict[str, tuple[sdk.ShadingRatePredictor, tuple[str, int]]] = {}

    def add(name: str, path: Path, arch: str) -> None:
        pred = sdk.load(path, providers=["CPUExecutionProvider"], threads=threads)
        out[name] = (pred, (arch, _params(path)))

    add("paper's network (random weights)", paper_model(folder)[1], "paper")
    for width, depth, stem, inputs, layers in FAST:
        split = {"stem_layers": layers} if layers != 1 else {}
        add(f"fast, stem {stem}{' in two layers' if split else ''}, width {width}, depth {depth}, {inputs} inputs "
            "(random weights)", paper_model(folder, "fast", inputs, width=width, depth=depth, stem=stem, **split)[1], "fast")
    for name in sdk.shipped_models():
        pred = sdk.load(name)
        arch = str(pred.metadata.provenance.get("arch", "paper"))
        add(f"shipped {name}", Path(str(pred.path)), arch)
    names = [Path(p).name for p in dict.fromkeys(extra)]
    for path in dict.fromkeys(extra):  # (a file given twice: one row)
        given = sdk.load(path)
        arch = str(given.metadata.provenance.get("arch", "paper"))
        # by its file name, or its path as given where two share a name (data/old/jnyang.onnx beside
        # data/joined/jnyang.onnx: the one row of the last before); read from the file sdk.load found (a
        # shipped model's name, `jnyang`, is no file in the working folder: its parameters were read there)
        add(Path(path).name if names.count(Path(path).name) == 1 else path, Path(str(given.path)), arch)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=positive, default=7)
    ap.add_argument("--threads", type=positive, default=2, help="onnxruntime intra-op and torch threads")
    ap.add_argument("models", nargs="*", help="more .onnx models to time")
    args = ap.parse_args()
    for path in args.models:  # (a model that does not load, before a minute of timing the others)
        sdk.load(path, providers=["CPUExecutionProvider"])
    torch.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as d:
        net, onnx_path = paper_model(Path(d))
        pred = sdk.load(onnx_path, providers=["CPUExecutionProvider"], threads=args.threads)
        so = ort.SessionOptions()
        so.intra_op_num_threads = args.threads
        bare = ort.InferenceSession(str(onnx_path), so, providers=["CPUExecutionProvider"])
        rows = []
        for w, h in ((1920, 1080), (1280, 720)):
            x = np.random.default_rng(0).random((4, h, w), dtype=np.float32)
            hp, wp = sdk.padded_size(h, w, pred.tile_size)
            xp = np.pad(x[None], ((0, 0), (0, 0), (0, hp - h), (0, wp - w)), mode="edge")
            xt = torch.from_numpy(xp)

            def run_torch(xt: torch.Tensor = xt) -> object:
                with torch.inference_mode():
                    return net(xt)

            rows.append(
                (
                    f"{w}x{h}",
                    median_ms(lambda x=x: pred.predict(x), args.repeats),
                    median_ms(lambda x=x: pred.shading_rates(x), args.repeats),
                    median_ms(lambda xp=xp: bare.run(None, {"input": xp}), args.repeats),
                    median_ms(run_torch, args.repeats),
                )
            )
        models = _models(Path(d), args.threads, args.models)
        channels = {len(p.metadata.inputs) for p, _ in models.values()}
        frames = {(c, w, h): np.random.default_rng(0).random((c, h, w), dtype=np.float32)
                  for c in channels for w, h in FRAMES}
        runs: dict[Hashable, Callable[[], object]] = {}
        for name, (p, _) in models.items():
            for w, h in FRAMES:
                x = frames[len(p.metadata.inputs), w, h]
                runs[name, (w, h)] = lambda p=p, x=x: p.predict(x)
        times = interleaved_ms(runs, args.repeats)
        nine = np.random.default_rng(0).random((9, 1080, 1920), dtype=np.float32)
        into = np.empty_like(nine)
        copy_ms = median_ms(lambda: np.copyto(into, nine), 2 * args.repeats + 1)
    print(f"rtp {sdk.__version__}, onnxruntime {ort.__version__}, torch {torch.__version__}, "
          f"{cpu_description()}, {args.threads} threads, median of {args.repeats}; the models in rounds\n")
    # The memory floor: the shipped models are bound by the planes they read on CPUs with little bandwidth
    # (docs/performance.md "Input planes on AVX2 CPUs").
    print(f"Memory: a numpy copy of nine 1920x1080 planes ({nine.nbytes / 2**20:.0f} MB) {copy_ms:.1f} ms, "
          f"{2 * nine.nbytes / copy_ms / 1e6:.1f} GB/s read and written\n")
    paper = "paper's network (random weights)"
    print("| model | architecture | inputs | stored values | "
          + " | ".join(f"{w}x{h} sdk predict (ms)" for w, h in FRAMES)
          + " | speed-up over the paper's at 1920x1080 (the rounds' median; their range) |")
    print("|---|---|---:|---:|" + "---:|" * len(FRAMES) + "---:|")
    for name, (pred, (arch, n_params)) in models.items():
        cells = " | ".join(f"{statistics.median(times[name, wh]):.1f}" for wh in FRAMES)
        ratios = [a / b for a, b in zip(times[paper, FRAMES[0]], times[name, FRAMES[0]], strict=True)]
        ratio = f"{statistics.median(ratios):.1f}x ({min(ratios):.1f}-{max(ratios):.1f})"
        print(f"| {name} | {arch} | {len(pred.metadata.inputs)} | {n_params:,} | {cells} | {ratio} |")
    print("\nThe paper's network by path:\n")
    print("| frame | sdk predict (ms) | sdk shading_rates (ms) | bare onnxruntime (ms) | torch eager (ms) |")
    print("|---|---|---|---|---|")
    for name, a, b, c, e in rows:
        print(f"| {name} | {a:.1f} | {b:.1f} | {c:.1f} | {e:.1f} |")


if __name__ == "__main__":
    run_main(main)
