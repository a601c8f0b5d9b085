"""Memory and time a predictor takes when it starts: every shipped model (and any MODEL.onnx given),
each in a process of its own, the resident set (RSS) that onnxruntime's library adds when imported,
that ``sdk.load`` adds when it builds the session, and that ``predict`` adds when it first runs at
each frame size (onnxruntime's arena and the SDK's own buffers: what an engine budgets on top of its
input planes, which the table gives beside it); then the time of ``sdk.load`` and of each of those
first runs (a new session's first runs at a size are slower than the later ones: what an engine
warms up at load time rather than in its first frames).

    python bench/memory.py [--sizes 1280x720,1920x1080] [--threads 2] [--warm-up N] [MODEL.onnx ...]

``--warm-up N`` first runs ``predict`` N times on a frame of zeros at each size (untimed; its memory
counts), as an engine would at load time, to see whether the timed runs are then as fast as later ones.

Read from /proc/self/status (Linux). Prints two Markdown tables (MB, then ms).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from _common import count, frame_size, positive, run_main  # bench/ is on sys.path when run as a script

from rtp import sdk

#: Runs at each size before the reading (the arena grows on the first; the later ones must not), each timed.
RUNS = 3


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text(encoding="utf-8", errors="replace").splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise SystemExit("no VmRSS in /proc/self/status: this script reads Linux's process status")


def measure(model: str, sizes: list[tuple[int, int]], threads: int, warm_up: int = 0) -> dict[str, float]:
    """In this process: MB added by the load, by the input planes and by the runs at each size."""
    import numpy as np

    before = _rss_mb()
    import onnxruntime  # noqa: F401  (its library, apart from the session)

    library = _rss_mb()
    t0 = time.perf_counter()
    pred = sdk.load(model, providers=["CPUExecutionProvider"], threads=threads)
    out = {"library": library - before, "load": _rss_mb() - library, "load ms": 1000 * (time.perf_counter() - t0)}
    c = len(pred.metadata.inputs)
    for w, h in sizes:
        x = np.random.default_rng(0).random((c, h, w), dtype=np.float32)
        base = _rss_mb()
        zeros = np.zeros_like(x)
        for _ in range(warm_up):
            pred.predict(zeros)
        del zeros
        for i in range(RUNS):
            t0 = time.perf_counter()
            pred.predict(x)
            out[f"{w}x{h} run {i + 1} ms"] = 1000 * (time.perf_counter() - t0)
        out[f"{w}x{h}"] = _rss_mb() - base
        out[f"{w}x{h} input"] = x.nbytes / 2**20
        del x
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1280x720,1920x1080", help="comma-separated WIDTHxHEIGHT, in this order")
    ap.add_argument("--threads", type=positive, default=2, help="onnxruntime intra-op threads")
    ap.add_argument("--warm-up", type=count, default=0, metavar="N",
                    help="predict N times on a zero frame at each size before the timed runs (default 0)")
    ap.add_argument("--one", help=argparse.SUPPRESS)  # a child process: measure this model, print JSON
    ap.add_argument("models", nargs="*", help="more .onnx models")
    args = ap.parse_args()
    try:
        # once each, in the order given (a size given twice was measured twice in one process, its second, warm runs
        # reported as its first, and its column printed twice)
        sizes = list(dict.fromkeys(frame_size(s, 16) for s in args.sizes.split(",")))
    except argparse.ArgumentTypeError as err:
        ap.error(f"--sizes: {err}")
    args.sizes = ",".join(f"{w}x{h}" for w, h in sizes)  # (what each model's process is given)
    if args.one:
        print(json.dumps(measure(args.one, sizes, args.threads, args.warm_up)))
        return
    models = list(dict.fromkeys([n.removesuffix(".onnx") for n in sdk.shipped_models()] + list(args.models)))  # (once each)
    for m in args.models:  # (a path that is no model: refused here, in one line, before the first process)
        sdk.load(m)
    rows = {}
    for m in models:
        run = subprocess.run([sys.executable, __file__, "--one", m, "--sizes", args.sizes, "--threads", str(args.threads),
                              "--warm-up", str(args.warm_up)],
                             capture_output=True, text=True, check=False)
        if run.returncode != 0:  # (its one line names its program: said once, by this one)
            said = run.stderr.strip().splitlines()[-1] if run.stderr.strip() else f"exit code {run.returncode}"
            raise sdk.RtpError(f"{m}: {said.removeprefix(Path(__file__).name + ': error: ')}")
        rows[m] = json.loads(run.stdout.strip().splitlines()[-1])
    labels = [f"{w}x{h}" for w, h in sizes]
    print(f"rtp {sdk.__version__}, {args.threads} threads, resident memory added (MB), each model in a process of "
          f"its own, after {RUNS} runs at each size in turn\n")
    print("| model | onnxruntime's library | the session (`sdk.load`) | "
          + " | ".join(f"first runs at {s} (its input planes)" for s in labels) + " |")
    print("|---|---:|---:|" + "---:|" * len(labels))
    for m, r in rows.items():
        cells = " | ".join(f"{r[s]:.0f} ({r[s + ' input']:.0f})" for s in labels)
        print(f"| {m} | {r['library']:.0f} | {r['load']:.0f} | {cells} |")
    warm = f", after {args.warm_up} on a zero frame" if args.warm_up else ""
    print(f"\nTime (ms) of `sdk.load` and of the first {RUNS} timed `predict` calls at each size in turn{warm}, the same "
          "processes\n")
    print("| model | `sdk.load` | " + " | ".join(f"runs 1 / 2 / 3 at {s}" for s in labels) + " |")
    print("|---|---:|" + "---:|" * len(labels))
    for m, r in rows.items():
        cells = " | ".join(" / ".join(f"{r[f'{s} run {i + 1} ms']:.1f}" for i in range(RUNS)) for s in labels)
        print(f"| {m} | {r['load ms']:.0f} | {cells} |")


if __name__ == "__main__":
    run_main(main)
