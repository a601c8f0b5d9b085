"""What onnxruntime's spinning worker threads cost the engine around a predictor: ``sdk.load``'s
default (``spin_between_runs=False``: the threads stop spinning when a run returns) next to
onnxruntime's own (``spin_between_runs=True``: they spin on, waiting for the next run).

    python bench/spinning.py [--size 1920x1080] [--repeats 15] [--threads 2] [--blocks 2] [--long-ms 500]
                             [--model jnflip] [--plot PNG]

Three tables, every setting measured in ``--blocks`` alternating blocks (the same setting's rows of
two blocks differ by the machine's noise, not by the setting):

1. **After a run**, per shipped model: ``predict`` back to back (median ms), and the CPU time the
   process burns in the 16.7 ms after ``predict`` returns while the caller sleeps (the cores a
   60 Hz engine would lose between frames), and in the ``--long-ms`` after it (the whole spin).
2. **An engine's frame** on this machine: the moderngl adapter renders ``--model``'s input planes on
   Mesa's llvmpipe (CPU threads, as an engine's GPU passes would be on a GPU) and reads them back,
   then ``predict`` runs; median ms of each and of the frame. The adapter's threads run right after
   the previous frame's ``predict``.
3. **Every shipped model in one process, in turn** (as ``rtp play`` and ``rtp evaluate`` run their
   methods): median ``predict`` ms per model; each session's spinning threads compete with the next
   session's run.

Prints Markdown tables; ``--plot PNG`` also draws the CPU time the process uses after a run of
``--model``, sampled every millisecond, with each setting (docs/img/spinning.png).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np
import onnxruntime as ort
from _common import (  # bench/ is on sys.path when run as a script
    cpu_description,
    frame_size,
    number,
    positive,
    run_main,
    save_figure,
)

from rtp import sdk

#: The wait after ``predict`` in table 1: one frame at 60 Hz.
FRAME_S = 1 / 60
#: How often table 1 waits the longer time after ``predict`` (``--long-ms``), to see the whole of the spin.
LONG_REPEATS = 3
#: Runs before timing (first-run allocations).
WARM_UP = 3
#: Seconds to wait after ``sdk.load`` (table 1 gives the CPU time used meanwhile): a new session's
#: worker threads spin before its first run whatever the setting (``jnyang-reuse``'s tail session,
#: which ``predict`` never runs, too; with ``sdk.load``'s default, only that one: ``load`` runs a
#: free-size model once itself), a one-off cost of loading that would otherwise land in the first
#: frames measured.
SETTLE_S = 0.2
SETTINGS = ((False, "stop after a run (`sdk.load` default)"), (True, "spin between runs (onnxruntime default)"))


def _frame(channels: int, width: int, height: int) -> np.ndarray:
    return np.random.default_rng(0).random((channels, height, width), dtype=np.float32)


def _ms(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    fn()
    return (time.perf_counter() - t0) * 1000


def _cpu_after(run: Callable[[], object], wait_s: float, repeats: int) -> float:
    """Median CPU ms the process uses in the ``wait_s`` after ``run`` returns, the caller asleep."""
    used = []
    for _ in range(repeats):
        run()
        c0 = time.process_time()
        time.sleep(wait_s)
        used.append((time.process_time() - c0) * 1000)
    return statistics.median(used)


def after_a_run(name: str, spin: bool, size: tuple[int, int], threads: int, repeats: int,
                long_s: float) -> tuple[float, float, float, float]:
    """CPU ms the process uses in the SETTLE_S after ``sdk.load``; median ``predict`` ms back to back;
    median CPU ms the process uses in the FRAME_S after it and in the ``long_s`` after it (the whole
    spin)."""
    pred = sdk.load(name, providers=["CPUExecutionProvider"], threads=threads, spin_between_runs=spin)
    c0 = time.process_time()
    time.sleep(SETTLE_S)
    settle = (time.process_time() - c0) * 1000
    x = _frame(len(pred.metadata.inputs), *size)
    for _ in range(WARM_UP):
        pred.predict(x)
    back_to_back = statistics.median(_ms(lambda: pred.predict(x)) for _ in range(repeats))
    return (settle, back_to_back, _cpu_after(lambda: pred.predict(x), FRAME_S, repeats),
            _cpu_after(lambda: pred.predict(x), long_s, LONG_REPEATS))


def cpu_trace(name: str, spin: bool, size: tuple[int, int], threads: int, repeats: int,
              window_s: float = 0.08, step_s: float = 0.001) -> tuple[list[float], list[float]]:
    """The process's CPU ms used since ``predict`` returned, sampled every ``step_s`` for ``window_s``
    while the caller sleeps (the mean of ``repeats`` runs): ``(wall ms, CPU ms)``."""
    import numpy as np

    pred = sdk.load(name, providers=["CPUExecutionProvider"], threads=threads, spin_between_runs=spin)
    time.sleep(SETTLE_S)
    x = _frame(len(pred.metadata.inputs), *size)
    for _ in range(WARM_UP):
        pred.predict(x)
    n = round(window_s / step_s)
    wall, cpu = np.zeros(n + 1), np.zeros(n + 1)
    for _ in range(repeats):
        pred.predict(x)
        t0, c0 = time.perf_counter(), time.process_time()
        for i in range(1, n + 1):
            time.sleep(max(0.0, t0 + i * step_s - time.perf_counter()))
            wall[i] += (time.perf_counter() - t0) * 1000
            cpu[i] += (time.process_time() - c0) * 1000
    return list(wall / repeats), list(cpu / repeats)


def plot_traces(traces: dict[str, tuple[list[float], list[float]]], cores: int, model: str, out: str) -> None:
    """Cumulative CPU time after ``predict`` returns against wall time, one curve per setting."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    end = max(w[-1] for w, _ in traces.values())
    ax.plot([0, end], [0, cores * end], color="grey", lw=0.8, ls="--", label=f"all {cores} cores busy")
    for label, (wall, cpu) in traces.items():
        ax.plot(wall, cpu, lw=2, label=label)
    top = 1.6 * max(max(c) for _, c in traces.values())
    ax.set_ylim(-0.02 * top, top)
    ax.axvline(FRAME_S * 1000, color="black", lw=0.8, ls=":")
    ax.text(FRAME_S * 1000 + 0.8, 0.05 * top, "a 60 Hz frame later", fontsize=8)
    ax.set_xlabel("ms since `predict` returned (the caller asleep)")
    ax.set_ylabel("CPU time the process used (ms)")
    ax.set_title(f"onnxruntime's worker threads after a {model} run", fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)
    save_figure(fig, out)


def engine_frames(name: str, spin: bool, size: tuple[int, int], threads: int, repeats: int) -> tuple[float, float, float]:
    """Median ms of the adapter's planes, of ``predict`` and of the frame, in a loop of both."""
    from adapter import engine_frame

    from rtp.plugins.moderngl import Adapter, Renderer

    pred = sdk.load(name, providers=["CPUExecutionProvider"], threads=threads, spin_between_runs=spin)
    time.sleep(SETTLE_S)
    width, height = size
    rows = []
    with Renderer(width, height) as r:
        frame = engine_frame(r)
        with Adapter(pred.metadata.inputs, width, height, ctx=r.ctx) as adapter:
            pred.predict(adapter.inputs(frame))
            for _ in range(repeats):
                t0 = time.perf_counter()
                x = adapter.inputs(frame)
                t1 = time.perf_counter()
                pred.predict(x)
                t2 = time.perf_counter()
                rows.append(((t1 - t0) * 1000, (t2 - t1) * 1000, (t2 - t0) * 1000))
    a, p, f = (statistics.median(col) for col in zip(*rows, strict=True))
    return a, p, f


def in_turn(spin: bool, size: tuple[int, int], threads: int, repeats: int) -> dict[str, float]:
    """Median ``predict`` ms of every shipped model, the models run one after another ``repeats`` times."""
    preds = {n: sdk.load(n, providers=["CPUExecutionProvider"], threads=threads, spin_between_runs=spin)
             for n in sdk.shipped_models()}
    time.sleep(SETTLE_S)
    xs = {n: _frame(len(p.metadata.inputs), *size) for n, p in preds.items()}
    for n, p in preds.items():
        p.predict(xs[n])
    times: dict[str, list[float]] = {n: [] for n in preds}
    for _ in range(repeats):
        for n, p in preds.items():
            times[n].append(_ms(lambda p=p, x=xs[n]: p.predict(x)))
    return {n: statistics.median(t) for n, t in times.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=lambda s: frame_size(s, 16), default=(1920, 1080), help="WIDTHxHEIGHT")
    ap.add_argument("--repeats", type=positive, default=15)
    ap.add_argument("--threads", type=positive, default=2, help="onnxruntime intra-op threads")
    ap.add_argument("--long-ms", type=number(0, 60_000), default=500, help="the longer wait after a run in table 1 (ms)")
    ap.add_argument("--blocks", type=positive, default=2, help="alternating blocks of each setting")
    ap.add_argument("--plot", metavar="PNG", help="also draw the CPU time after a run of --model, both settings")
    ap.add_argument("--model", default="jnflip",
                    help="the model of the engine-frame table (default: jnflip, whose planes llvmpipe builds fastest)")
    args = ap.parse_args()
    sdk.load(args.model)  # (its table comes after the first's minutes: a name that is no model is refused first)
    w, h = args.size
    print(f"rtp {sdk.__version__}, onnxruntime {ort.__version__}, {cpu_description()}, {args.threads} threads, "
          f"{w}x{h}, median of {args.repeats}, {args.blocks} blocks a setting\n")
    blocks = [(b, spin, label) for b in range(1, args.blocks + 1) for spin, label in SETTINGS]

    print(f"After a run: `predict` back to back, and CPU ms the process uses in the {FRAME_S * 1000:.1f} ms after it "
          f"and in the {args.long_ms:.0f} ms after it (median of {LONG_REPEATS})\n")
    print(f"| model | threads after a run | block | CPU in the {SETTLE_S * 1000:.0f} ms after `sdk.load` (ms) | "
          f"predict (ms) | CPU in the next frame (ms) | CPU in the next {args.long_ms:.0f} ms (ms) |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name in sdk.shipped_models():
        for b, spin, label in blocks:
            settle, t, burned, whole = after_a_run(name, spin, args.size, args.threads, args.repeats,
                                                   args.long_ms / 1000)
            print(f"| {name.removesuffix('.onnx')} | {label} | {b} | {settle:.1f} | {t:.1f} | {burned:.1f} | "
                  f"{whole:.1f} |")

    print(f"\nAn engine's frame: the moderngl adapter's planes for {args.model} on llvmpipe, then `predict`\n")
    print("| threads after a run | block | adapter (ms) | predict (ms) | frame (ms) |")
    print("|---|---:|---:|---:|---:|")
    for b, spin, label in blocks:
        a, p, f = engine_frames(args.model, spin, args.size, args.threads, args.repeats)
        print(f"| {label} | {b} | {a:.1f} | {p:.1f} | {f:.1f} |")

    print("\nEvery shipped model in one process, in turn: `predict` (ms)\n")
    names = sdk.shipped_models()
    print("| threads after a run | block | " + " | ".join(n.removesuffix(".onnx") for n in names) + " |")
    print("|---|---:|" + "---:|" * len(names))
    for b, spin, label in blocks:
        t = in_turn(spin, args.size, args.threads, args.repeats)
        print(f"| {label} | {b} | " + " | ".join(f"{t[n]:.1f}" for n in names) + " |")
    if args.plot:
        traces = {label: cpu_trace(args.model, spin, args.size, args.threads, args.repeats) for spin, label in SETTINGS}
        plot_traces(traces, args.threads, args.model, args.plot)


if __name__ == "__main__":
    run_main(main)
