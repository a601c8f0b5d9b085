"""Several views a frame, and ``predict`` beside an engine's Python: what an engine gets from one
predictor when it renders two views (stereo, split screen) and when it calls ``predict`` from a
thread of its own.

    python bench/views.py [--size 1920x1080] [--views 2] [--threads 2] [--rounds 7] [--seconds 2]
                          [--switch 0.005,0.0005] [MODEL ...]

Every shipped model unless models are named. The first table times, in rounds (each way once a round,
after a warm-up round), the ways to predict ``--views`` frames:

- one after the other, ``predict`` on each frame (``threads`` intra-op threads);
- one batch, ``predict`` on the ``(views, C, H, W)`` stack (a model whose planes come in several graph
  inputs runs it frame by frame on views of the stack);
- the same batch as one onnxruntime run, the session fed copies of each group (what the SDK did
  before it ran a grouped model's batch frame by frame);
- a thread per view, each calling ``predict`` on one predictor shared by the threads and loaded with
  one intra-op thread.

Every way's predictions are checked against the first's (``same``). The second table runs a pure-Python
loop (the stand-in for an engine's game logic: small-object work that holds the GIL) for ``--seconds``
alone, then with a worker thread calling ``shading_rates`` back to back, and prints the loop's speed
kept and the call's time on the worker, at each ``sys.setswitchinterval`` of ``--switch``. onnxruntime
releases the GIL while the network runs, and numpy while it works on the tiles; each time the worker
takes it back from a thread running Python it waits for that thread's switch interval (5 ms by
default). The third table counts those waits per step of ``shading_rates`` (JNYang: the shipped ``jnyang`` where
named, by name or path, else the first model named whose metadata's metric is ``jnyang``, else the first model
named), at a 50 ms interval where each shows.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import onnxruntime as ort
from _common import (  # bench/ is on sys.path when run as a script
    cpu_description,
    frame_size,
    interleaved_ms,
    median_ms,
    number,
    positive,
    run_main,
)

from rtp import sdk


def _one_run(pred: sdk.ShadingRatePredictor, threads: int) -> Callable[[np.ndarray], np.ndarray]:
    """The batch as one run of a bare session (the model's own options: threads, no spinning), padded as
    ``predict`` pads it (the last row and column repeated up to ``metadata.pad_multiple``: a 1366x768 view
    to 1368 columns for a model of ``input_multiple`` 4), each graph input fed a contiguous copy of its
    planes: the network's raw output."""
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.add_session_config_entry("session.force_spinning_stop", "1")
    session = ort.InferenceSession(str(pred.path), opts, providers=["CPUExecutionProvider"])
    bounds, start = [], 0
    for name, planes in pred.graph_inputs:
        bounds.append((name, start, start + len(planes)))
        start += len(planes)
    output = session.get_outputs()[0].name

    def run(xb: np.ndarray) -> np.ndarray:
        # (unpadded, a size off the multiple ran a frame the SDK never runs, and its output read "differs!")
        h, w = xb.shape[2:]
        ph, pw = sdk.padded_size(h, w, pred.metadata.pad_multiple)
        if (ph, pw) != (h, w):
            xb = np.pad(xb, ((0, 0), (0, 0), (0, ph - h), (0, pw - w)), mode="edge")
        feed = {name: np.ascontiguousarray(xb[:, a:b]) for name, a, b in bounds}
        return session.run([output], feed)[0]

    return run


#: A switch interval of ``--switch``: seconds in (0, 1] (Python's own is 0.005).
SWITCH = number(0, 1, above_low=True)


def views_table(model: str, size: tuple[int, int], views: int, threads: int, rounds: int) -> dict[str, object]:
    """Median ms of each way to predict ``views`` frames of ``size``, and whether each gave the first's
    predictions (the bare run: its raw output against ``predict_raw``)."""
    pred = sdk.load(model, providers=["CPUExecutionProvider"], threads=threads)
    single = sdk.load(model, providers=["CPUExecutionProvider"], threads=1)
    w, h = size
    c = len(pred.metadata.inputs)
    xb = np.random.default_rng(0).random((views, c, h, w), dtype=np.float32)
    frames = list(xb)
    pool = ThreadPoolExecutor(views)
    bare = _one_run(pred, threads)
    ways: dict[str, Callable[[], object]] = {
        "one after the other": lambda: [pred.predict(f) for f in frames],
        "one batch": lambda: pred.predict(xb),
        "one batch as one onnxruntime run (groups copied)": lambda: bare(xb),
        "a thread per view, one predictor of 1 thread": lambda: list(pool.map(single.predict, frames)),
    }
    first = np.stack([pred.predict(f) for f in frames])
    th, tw = pred.tiles(h, w)
    same = {
        "one after the other": True,
        "one batch": bool(np.array_equal(pred.predict(xb), first)),
        "one batch as one onnxruntime run (groups copied)": bool(
            np.allclose(bare(xb)[:, :, :th, :tw], pred.predict_raw(xb), rtol=1e-5, atol=1e-6)),
        "a thread per view, one predictor of 1 thread": bool(
            np.array_equal(np.stack(list(pool.map(single.predict, frames))), first)),
    }
    times = interleaved_ms(ways, rounds)
    pool.shutdown()
    groups = len(pred.graph_inputs)
    return {"model": model, "groups": groups, "ms": {k: statistics.median(v) for k, v in times.items()}, "same": same}


def _python_work(stop: threading.Event) -> int:
    """Iterations of a small-object loop (dicts, lists, attribute-free arithmetic) until ``stop``."""
    n = 0
    state = {"x": 0.0, "items": [0] * 16}
    while not stop.is_set():
        for i in range(64):
            state["x"] = state["x"] * 0.5 + i
            state["items"][i & 15] += 1
        n += 1
    return n


def _loop_rate(seconds: float) -> float:
    """Iterations per second of :func:`_python_work` run for ``seconds``."""
    stop = threading.Event()
    timer = threading.Timer(seconds, stop.set)
    timer.start()
    t0 = time.perf_counter()
    n = _python_work(stop)
    return n / (time.perf_counter() - t0)


def beside_python(model: str, size: tuple[int, int], threads: int, seconds: float, switch: float) -> dict[str, float]:
    """The Python loop's iterations a second alone and with ``shading_rates`` looping on a worker thread
    (``sys.setswitchinterval(switch)`` meanwhile), and the worker's ms a call: alone (back to back on
    this thread, nothing beside it) and beside the loop."""
    pred = sdk.load(model, providers=["CPUExecutionProvider"], threads=threads)
    w, h = size
    x = np.random.default_rng(0).random((len(pred.metadata.inputs), h, w), dtype=np.float32)
    pred.shading_rates(x)
    t0, runs = time.perf_counter(), 0
    while time.perf_counter() - t0 < seconds:
        pred.shading_rates(x)
        runs += 1
    alone_ms = (time.perf_counter() - t0) * 1000 / runs
    before = sys.getswitchinterval()
    sys.setswitchinterval(switch)
    try:
        loop_alone = _loop_rate(seconds)
        stop, done = threading.Event(), []

        def worker() -> None:
            while not stop.is_set():
                s = time.perf_counter()
                pred.shading_rates(x)
                done.append((time.perf_counter() - s) * 1000)

        thread = threading.Thread(target=worker)
        thread.start()
        time.sleep(0.1)  # the worker's first call under way
        loop_beside = _loop_rate(seconds)
        stop.set()
        thread.join()
    finally:
        sys.setswitchinterval(before)
    return {"loop kept": loop_beside / loop_alone, "alone": alone_ms, "beside": statistics.median(done),
            "calls": float(len(done))}


def gil_waits(model: str, size: tuple[int, int], switch: float = 0.05, repeats: int = 5) -> dict[str, tuple[float, float]]:
    """Per step of ``shading_rates`` (the network's run, the decode on the tiles, the rate selection):
    its median ms alone and how many times it waited to take the GIL back from a thread running Python,
    read at a long switch interval where each wait shows: (ms beside the loop - ms alone) / interval."""
    pred = sdk.load(model, providers=["CPUExecutionProvider"], threads=1)
    w, h = size
    x = np.random.default_rng(0).random((len(pred.metadata.inputs), h, w), dtype=np.float32)
    raw = pred.predict_raw(x)
    values = pred.metadata.decode(raw)
    steps: dict[str, Callable[[], object]] = {
        "predict_raw (checks, the network)": lambda: pred.predict_raw(x),
        "metadata.decode": lambda: pred.metadata.decode(raw),
        "select_rates": lambda: sdk.select_rates(values, pred.metadata.default_threshold,
                                                 higher_is_better=pred.metadata.higher_is_better,
                                                 factors=pred.metadata.rate_factors),
    }

    alone = {k: median_ms(fn, 11 * repeats) for k, fn in steps.items()}
    before = sys.getswitchinterval()
    sys.setswitchinterval(switch)
    stop = threading.Event()
    loop = threading.Thread(target=_python_work, args=(stop,))
    loop.start()
    try:
        time.sleep(2 * switch)
        beside = {k: median_ms(fn, repeats) for k, fn in steps.items()}
    finally:
        stop.set()
        loop.join()
        sys.setswitchinterval(before)
    return {k: (alone[k], max(0.0, (beside[k] - alone[k]) / (switch * 1000))) for k in steps}


def gil_model(models: list[str]) -> str:
    """The model of the third table: the shipped ``jnyang`` where ``models`` name it (``jnyang``, ``jnyang.onnx`` or
    a path to it: the file ``sdk.load`` reads), else the first model whose metadata's metric is ``jnyang`` (a copy
    of it elsewhere, ``jnyang-8px``), else the first model."""
    shipped = sdk.load("jnyang", providers=["CPUExecutionProvider"]).path if "jnyang.onnx" in sdk.shipped_models() \
        else None
    preds = [(m, sdk.load(m, providers=["CPUExecutionProvider"])) for m in models]
    for m, pred in preds:
        if shipped is not None and pred.path is not None and pred.path.resolve() == shipped.resolve():
            return m
    return next((m for m, pred in preds if pred.metadata.metric == "jnyang"), models[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("models", nargs="*", help="shipped model names or .onnx paths (default: every shipped model)")
    ap.add_argument("--size", type=lambda s: frame_size(s, 16), default=(1920, 1080),
                    help="WIDTHxHEIGHT of each view (default 1920x1080)")
    ap.add_argument("--views", type=positive, default=2, help="views a frame (default 2: stereo)")
    ap.add_argument("--threads", type=positive, default=2, help="onnxruntime intra-op threads of the predictor (default 2)")
    ap.add_argument("--rounds", type=positive, default=7, help="timed rounds (default 7)")
    ap.add_argument("--seconds", type=number(0, 600, above_low=True), default=2.0,
                    help="length of each Python-loop reading (default 2)")
    ap.add_argument("--switch", default="0.005,0.0005",
                    help="comma-separated sys.setswitchinterval values in seconds for the second table (default "
                         "0.005, Python's own, and 0.0005)")
    args = ap.parse_args()
    try:  # (inf passed as a switch interval of 0, NaN and what sys.setswitchinterval refuses failed after the first table)
        switches = [SWITCH(v) for v in args.switch.split(",")]
    except argparse.ArgumentTypeError:
        ap.error(f"--switch: expected comma-separated seconds in (0, 1] such as 0.005,0.0005, got {args.switch!r}")
    models = args.models or [m.removesuffix(".onnx") for m in sdk.shipped_models()]
    for m in args.models:  # (a name that is no model: refused before the header, not after it)
        sdk.load(m, providers=["CPUExecutionProvider"])
    w, h = args.size
    print(f"CPU: {cpu_description()}; onnxruntime {ort.__version__}; {args.views} views of {w}x{h}, {args.threads} "
          f"threads, median of {args.rounds} rounds (ms for all the views)\n")
    rows = [views_table(m, args.size, args.views, args.threads, args.rounds) for m in models]
    ways = list(rows[0]["ms"])  # type: ignore[call-overload]
    print("| model | graph inputs | " + " | ".join(ways) + " |")
    print("|---|---|" + "---|" * len(ways))
    for r in rows:
        ms, same = r["ms"], r["same"]
        cells = [f"{ms[k]:.1f}{'' if same[k] else ' (differs!)'}" for k in ways]  # type: ignore[index]
        print(f"| {r['model']} | {r['groups']} | " + " | ".join(cells) + " |")
    print(f"\nA pure-Python loop on the main thread for {args.seconds:g} s, alone and with a worker thread calling "
          f"shading_rates back to back on one {w}x{h} frame, at each switch interval\n")
    print("| model | predictor threads | switch interval, ms | loop speed kept | shading_rates alone, ms | "
          "beside the loop, ms |")
    print("|---|---|---|---|---|---|")
    for m in models:
        for t in sorted({1, args.threads}):
            for switch in switches:
                b = beside_python(m, args.size, t, args.seconds, switch)
                print(f"| {m} | {t} | {switch * 1000:g} | {b['loop kept']:.0%} | {b['alone']:.1f} | {b['beside']:.1f} |")
    first = gil_model(models)
    print(f"\nWhere shading_rates waits for the GIL ({first}, one thread, {w}x{h}): each step alone (median), and the "
          "times it took the GIL back from the loop, read at a 50 ms switch interval\n")
    print("| step | alone, ms | GIL waits |")
    print("|---|---|---|")
    for step, (ms, waits) in gil_waits(first, args.size).items():
        print(f"| {step} | {ms:.2f} | {waits:.0f} |")

if __name__ == "__main__":
    run_main(main)
