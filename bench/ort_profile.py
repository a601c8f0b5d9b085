"""Where a model's time goes: onnxruntime's own per-node profile of one 1080p (or any size) frame.

    python bench/ort_profile.py [MODEL ...] [--size 1920x1080] [--repeats 10] [--threads 2]
    python bench/ort_profile.py lpips --fast grow=2,depth=5 --fast grow=2,depth=5,tail_width=48 --like lpips

MODEL is a shipped model's name (``lpips``) or an ``.onnx`` path; default: every shipped model (none when
``--fast`` is given). ``--fast OPTIONS`` (repeatable) adds rtp's fast network with those options of
``rtp train`` (``rtp.train.model.build_network``'s keywords: width, depth, stem, grow, tail_width,
separable, ...; and ``tile``, 16 unless given) and random weights, on the input planes of ``--like``
(a shipped model or ``.onnx``; default the paper's four), exported with rtp-export: what a configuration would cost before a
30-minute training run says whether it is any good (the weights do not change the cost). Each is
run through an onnxruntime session built as ``rtp.sdk.load`` builds it (same threads, same graph
optimisations, so BatchNorm folded and convolutions fused with their ReLU in onnxruntime's blocked
NCHWc layout) with profiling on; the first run is a warm-up and not counted. Prints, per model, a
Markdown table of its nodes in the order they run: operator, output shape, multiply-adds (convolutions:
output positions x output channels x input channels per group x kernel area), median kernel time
over the runs, share of the summed kernel time, and the rate (G multiply-adds per second, where a
node has them). onnxruntime's blocked layout pads a layer's channels to its block (8 or 16), so a
narrow layer (the 4-output head) counts the multiply-adds the CPU does, not the ones the model has.
What the table shows on a 2-core CPU: the stem, which reads every input plane once,
runs under the other convolutions' rate (it is bound by memory, not arithmetic), and blocks at tile
resolution cost little per block; the sum of the kernels is less than ``sdk predict``'s wall time
(``bench/inference.py``) by the session's own overhead, the layout reorders and ``predict``'s check that
the input is finite (one read of the frame). A last table sums each model's kernels and divides them by
the first model's (on a machine whose speed drifts from one minute to the next, the ratios of one run
are steadier than its milliseconds), and beside them the median wall time of ``sdk predict`` on a frame
of the same size, with and without ``assume_finite=True``, and what ``predict``'s refusal of NaN and
infinite input costs: for a model with a finite probe (``metadata.finite_probe``, every shipped model)
its kernels minus those of the same model without the probe (``rtp.export.strip_finite_probe``,
profiled the same way: the probe's reduction and the stem's ReLU it unfuses), for one without it one
float32 sum over the frame, a read of every plane (2-3 ms for eight 1080p planes on a 2-core CPU).
onnxruntime computes every node whatever outputs a run asks for, so ``assume_finite=True`` saves a
probe model nothing but the test of one number.
"""

from __future__ import annotations

import argparse
import inspect
import json
import statistics
import sys
import tempfile
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort

from rtp import sdk

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import (  # noqa: E402  (also when loaded by path, as the tests do)
    TIMING_INPUTS,
    UsageError,
    cpu_description,
    frame_size,
    median_ms,
    paper_model,
    positive,
    run_main,
)


def _macs(args: dict[str, Any]) -> int:
    """Multiply-adds of a Conv node from its profiled shapes (0 for any other operator)."""
    if args.get("op_name") not in ("Conv", "FusedConv", "NchwcConv"):
        return 0
    shapes = args.get("input_type_shape", [])
    out = args.get("output_type_shape", [])
    if len(shapes) < 2 or not out:
        return 0
    weight = next(iter(shapes[1].values()))
    y = next(iter(out[0].values()))
    return int(np.prod(weight)) * int(np.prod(y[2:])) * int(y[0])


def profile(path: Path, n_inputs: int, size: tuple[int, int], repeats: int, threads: int) -> list[dict[str, Any]]:
    """Per node, in the order the nodes run (a topological order of onnxruntime's optimised graph): name,
    operator, output shape, multiply-adds and the median kernel ms."""
    w, h = size
    with tempfile.TemporaryDirectory() as d:
        so = ort.SessionOptions()
        so.intra_op_num_threads = threads
        so.enable_profiling = True
        so.profile_file_prefix = str(Path(d) / "profile")
        session = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])
        x = np.random.default_rng(0).random((1, n_inputs, h, w), dtype=np.float32)
        ins = session.get_inputs()  # the planes in one input, or in groups (rtp.export.split_input_planes)
        ends = np.cumsum([0] + [i.shape[1] for i in ins]).tolist() if len(ins) > 1 else [0, n_inputs]
        feed = {i.name: x[:, a:b] for i, a, b in zip(ins, ends[:-1], ends[1:])}
        for _ in range(repeats + 1):
            session.run(None, feed)
        events = json.loads(Path(session.end_profiling()).read_text(encoding="utf-8"))
    runs = sorted((e["ts"], e["ts"] + e["dur"]) for e in events if e.get("name") == "model_run")
    if len(runs) < 2:
        raise RuntimeError(f"onnxruntime recorded {len(runs)} runs of {path}, expected {repeats + 1}")
    warm_end = runs[0][1]
    times: dict[str, list[float]] = defaultdict(list)
    info: dict[str, dict[str, Any]] = {}
    # when each node first ran: its place in the run (onnxruntime's node_index numbers the nodes its optimiser
    # adds after the others: a group's Sum and the probe's ReduceSum were listed before the convolutions they read)
    order: dict[str, int] = {}
    for e in events:
        if e.get("cat") != "Node" or not e["name"].endswith("_kernel_time") or e["ts"] <= warm_end:
            continue
        name = e["name"].removesuffix("_kernel_time")
        args = e.get("args", {})
        times[name].append(e["dur"] / 1000.0)
        order[name] = min(order.get(name, e["ts"]), e["ts"])
        out = args.get("output_type_shape", [])
        info[name] = {"op": args.get("op_name", "?"), "shape": next(iter(out[0].values())) if out else [],
                      "macs": _macs(args)}
    return [{"name": n, **info[n], "ms": statistics.median(times[n])} for n in sorted(times, key=order.__getitem__)]


def _fast_options(text: str) -> dict[str, Any]:
    """``KEY=VALUE[,KEY=VALUE]`` with the keywords of the fast network (``build_network``) into a dict
    of ints and booleans."""
    from rtp.train.model import build_network

    allowed = ["tile"] + [k for k, v in inspect.signature(build_network).parameters.items()
                          if v.kind is inspect.Parameter.KEYWORD_ONLY and k != "head"]
    out: dict[str, Any] = {}
    for item in filter(None, (t.strip() for t in text.split(","))):
        key, sep, value = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in allowed:
            raise argparse.ArgumentTypeError(f"expected KEY=VALUE pairs with KEY one of {', '.join(allowed)}, got {item!r}")
        v = value.strip().lower()
        if key == "block_contrast":  # input channel indices joined by '+': block_contrast=7+8
            try:
                out[key] = tuple(int(t) for t in v.split("+"))
            except ValueError as err:
                raise argparse.ArgumentTypeError(f"block_contrast: expected channel indices joined by '+', got "
                                                 f"{value!r}") from err
        elif v in ("true", "false"):
            out[key] = v == "true"
        else:
            try:
                out[key] = int(v)
            except ValueError as err:
                raise argparse.ArgumentTypeError(f"{key}: expected an integer or true/false, got {value!r}") from err
    return out


def _random_fast(folder: Path, options: list[dict[str, Any]], like: str | None) -> list[tuple[str, Path]]:
    """rtp's fast network with each of ``options`` and random weights, on the inputs of ``like``, exported
    into ``folder``: (label, onnx path) per configuration."""
    inputs = list(sdk.load(like, providers=["CPUExecutionProvider"]).metadata.inputs) if like else list(TIMING_INPUTS[4])
    out = []
    for i, opts in enumerate(options):
        label = "fast " + (",".join(f"{k}={v}" for k, v in opts.items()) or "defaults") + " (random weights)"
        try:
            path = paper_model(folder / str(i), "fast", inputs, **opts)[1]
        except ValueError as err:  # (a usage error, exit 2: a SystemExit said it with exit 1, after the header)
            raise UsageError(f"--fast {','.join(f'{k}={v}' for k, v in opts.items())}: {err}") from err
        out.append((label, path))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("models", nargs="*", help="shipped model names or .onnx paths (default: every shipped model)")
    ap.add_argument("--size", type=frame_size, default=(1920, 1080), help="frame WIDTHxHEIGHT (default 1920x1080)")
    ap.add_argument("--repeats", type=positive, default=10, help="profiled runs after one warm-up (default 10)")
    ap.add_argument("--threads", type=positive, default=2, help="onnxruntime intra-op threads (default 2)")
    ap.add_argument("--fast", type=_fast_options, action="append", default=[], metavar="KEY=VALUE[,...]",
                    help="add rtp's fast network with these options and random weights (repeatable)")
    ap.add_argument("--like", help="the --fast networks read this model's input planes (default: the paper's four)")
    args = ap.parse_args()
    if args.like and not args.fast:
        ap.error("--like sets the inputs of the --fast networks: give at least one --fast")
    with tempfile.TemporaryDirectory() as tmp:
        models = [(m, m) for m in (args.models or ([] if args.fast else list(sdk.shipped_models())))]
        for _, m in models:  # (a name that is no model: refused before the header, not after the models before it)
            sdk.load(m, providers=["CPUExecutionProvider"])
        models += [(label, str(path)) for label, path in _random_fast(Path(tmp), args.fast, args.like)]
        print(f"rtp {sdk.__version__}, onnxruntime {ort.__version__}, {cpu_description()}, {args.threads} threads, "
              f"{args.size[0]}x{args.size[1]}, median of {args.repeats} runs per node\n")
        totals = [(label, *_report(label, model, args)) for label, model in models]
    print("| model | ms of kernels | x the first | sdk predict ms | same, `assume_finite=True` | "
          "the finite-input check ms |\n|---|---:|---:|---:|---:|---|")
    for label, total, wall, trusted, check in totals:
        print(f"| {label} | {total:.1f} | {total / totals[0][1]:.2f} | {wall:.1f} | {trusted:.1f} | {check} |")


def _report(label: str, model: str, args: argparse.Namespace) -> tuple[float, float, float, str]:
    """Profile ``model`` and print its table; returns its summed kernel ms, the median ms of ``sdk
    predict`` on the same frame with and without ``assume_finite``, and what ``predict``'s
    finite-input check costs: the kernel ms of the graph's finite probe (``metadata.finite_probe``),
    or, for a model without one, the median ms of one float32 sum over the frame (one read of every
    plane, the reduction the SDK then makes)."""
    pred = sdk.load(model, providers=["CPUExecutionProvider"])
    pad = sdk.padded_size(args.size[1], args.size[0], pred.metadata.pad_multiple)
    rows = profile(Path(str(pred.path)), len(pred.metadata.inputs), (pad[1], pad[0]), args.repeats, args.threads)
    total = sum(r["ms"] for r in rows)
    print(f"### {label} ({len(pred.metadata.inputs)} inputs, {total:.1f} ms of kernels)\n")
    print("| node | operator | output | M multiply-adds | ms | share | G multiply-adds/s |")
    print("|---|---|---|---:|---:|---:|---:|")
    for r in rows:
        rate = f"{r['macs'] / r['ms'] / 1e6:.0f}" if r["macs"] and r["ms"] > 0 else ""
        macs = f"{r['macs'] / 1e6:.0f}" if r["macs"] else ""
        shape = "x".join(str(v) for v in r["shape"])
        print(f"| {r['name']} | {r['op']} | {shape} | {macs} | {r['ms']:.2f} | {100 * r['ms'] / total:.0f}% | {rate} |")
    print()
    x = np.random.default_rng(0).random((len(pred.metadata.inputs), args.size[1], args.size[0]), dtype=np.float32)
    run = sdk.load(model, providers=["CPUExecutionProvider"], threads=args.threads)
    trusted = sdk.load(model, providers=["CPUExecutionProvider"], threads=args.threads, assume_finite=True)
    wall, trusted_wall = median_ms(lambda: run.predict(x), args.repeats), median_ms(lambda: trusted.predict(x), args.repeats)
    if pred.metadata.finite_probe is not None:
        # the probe's reduction and what it costs the stem (its ReLU no longer fused into the convolution):
        # the kernels of the model minus those of the same model without the probe
        from rtp.export import strip_finite_probe

        with tempfile.TemporaryDirectory() as tmp:
            bare = strip_finite_probe(str(pred.path), Path(tmp) / "bare.onnx")
            bare_total = sum(r["ms"] for r in profile(bare, len(pred.metadata.inputs), (pad[1], pad[0]), args.repeats,
                                                      args.threads))
        check = f"{total - bare_total:.1f} (in the graph: kernels with the probe minus without)"
    else:
        check = f"{median_ms(lambda: float(x.sum()), args.repeats):.1f} (a float32 sum of the frame)"
    return total, wall, trusted_wall, check


if __name__ == "__main__":
    run_main(main)
