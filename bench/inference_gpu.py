"""GPU cost of the shipped models and the paper's network, on CUDA through torch (and onnxruntime's
CUDA provider where the installed onnxruntime has it).

    python bench/inference_gpu.py [--repeats 200] [--frames 1920x1080,2560x1440,3840x2160] [MODEL.onnx ...]

Needs a CUDA GPU: where torch sees none it says so and exits with status 2. The networks timed are the
exported ONNX files themselves (every shipped model, the paper's network with random weights as
``bench/inference.py`` builds it, any ``MODEL.onnx`` given), rebuilt op for op as torch modules from
their graphs (Conv, Relu, BatchNormalization, MaxPool, Sigmoid, Concat where a network that splits
joins its tail's block contrast, and Sum where a model's planes come in groups: the ops ``rtp-export``
writes), so the
weights, the folded BatchNorm and the ceil-mode pooling are the shipped ones. Each is timed at batch 1
on an input already on the GPU (an engine's G-buffers live there) in three ways:

- ``fp32``: eager torch, float32, cuDNN's autotuner on, then the same replayed from a CUDA graph
  (one launch per frame, as an engine records it: small networks at batch 1 are launch-bound eagerly),
  in full float32: cuDNN's TF32 convolutions, torch's default on Ampere and later GPUs (10 bits of
  mantissa, as fp16's), are off for these columns and for the reference the fp16 output is compared with;
- ``fp16``: half precision, channels-last (the layout tensor cores want), eager and from a CUDA graph.

Times are CUDA-event medians over ``--repeats`` frames after a warm-up. The largest difference between
the fp16 and fp32 outputs (the estimates, in transformed space) is printed per model, so a reader can
judge whether half precision is safe. With onnxruntime's CUDA execution provider installed
(``onnxruntime-gpu``) it also times ``sdk predict`` through it: host arrays in and out, so that column
includes the copies a numpy caller pays. Prints Markdown tables.
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import sys
import tempfile
from functools import partial
from pathlib import Path

import numpy as np
import onnxruntime as ort
from _common import frame_sizes, paper_model, positive, run_main  # bench/ is on sys.path when run as a script

from rtp import sdk

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    import onnx
    import torch
    from onnx import numpy_helper
    from torch import nn
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

DEFAULT_FRAMES = "1920x1080,2560x1440,3840x2160"


def _attrs(node: onnx.NodeProto) -> dict[str, object]:
    return {a.name: onnx.helper.get_attribute_value(a) for a in node.attribute}


class OnnxGraph(nn.Module):
    """An ONNX graph's layers run in the graph's order, each reading the tensors its node names: a
    chain, or the branches of a network that splits (its block contrast read from the input and
    joined to the trunk's features by a Concat). The graph's inputs are consecutive planes of the one
    tensor ``forward`` takes (``sources``: name, first plane, end), as ``rtp.sdk`` feeds them; a Sum
    adds the convolutions of the groups a model's planes come in (``rtp.export.split_input_planes``)."""

    def __init__(self, layers: list[nn.Module], plan: list[tuple[int, list[str], str]],
                 sources: list[tuple[str, int, int]], result: str) -> None:
        super().__init__()
        self.layers = nn.ModuleList(layers)
        self.plan, self.sources, self.result = plan, sources, result

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        values = {name: x[:, a:b] for name, a, b in self.sources}
        for i, ins, out in self.plan:
            if i == CONCAT:
                values[out] = torch.cat([values[n] for n in ins], dim=1)
            elif i == SUM:
                values[out] = sum((values[n] for n in ins[1:]), values[ins[0]])
            else:
                values[out] = self.layers[i](values[ins[0]])
        return values[self.result]


#: Plan entries that are not layers: a Concat over channels and a Sum.
CONCAT, SUM = -1, -2


def _sources(model: onnx.ModelProto) -> list[tuple[str, int, int]]:
    """``(name, first plane, end)`` of each graph input, as ``rtp.sdk`` feeds them."""
    weights = {t.name for t in model.graph.initializer}
    inputs = [i for i in model.graph.input if i.name not in weights]
    if len(inputs) == 1:
        return [(inputs[0].name, 0, 1 << 30)]
    sizes = [i.type.tensor_type.shape.dim[1].dim_value for i in inputs]
    bounds = np.cumsum([0, *sizes]).tolist()
    return [(i.name, int(a), int(b)) for i, a, b in zip(inputs, bounds[:-1], bounds[1:])]


def torch_from_onnx(path: Path) -> nn.Module:
    """The layers in ``path`` as a torch module with its weights (:class:`OnnxGraph`). Only what
    rtp-export writes for rtp's networks is understood: Conv, Relu, BatchNormalization, MaxPool,
    Sigmoid, Identity, Concat over channels and Sum; anything else raises ``ValueError`` naming the op.
    Nodes the first output (``metric``) does not need, the finite probe's (docs/export.md) and a split
    network's second output, are left out: the probe is the SDK's check of its input on a CPU, not
    part of the network."""
    model = onnx.load(str(path))
    weights = {t.name: torch.from_numpy(numpy_helper.to_array(t).copy()) for t in model.graph.initializer}
    needed = {model.graph.output[0].name}
    for node in reversed(model.graph.node):  # topological order: walk back from the metric output
        if needed & set(node.output):
            needed.update(node.input)
    layers: list[nn.Module] = []
    plan: list[tuple[int, list[str], str]] = []
    for node in model.graph.node:
        if not needed & set(node.output):
            continue
        a = _attrs(node)
        if node.op_type == "Identity":
            if node.input[0] in weights:  # exported weight aliases
                weights[node.output[0]] = weights[node.input[0]]
            else:
                plan.append((CONCAT, [node.input[0]], node.output[0]))  # a Concat of one: the tensor itself
            continue
        if node.op_type == "Concat":
            if int(a.get("axis", 0)) != 1:  # type: ignore[call-overload]
                raise ValueError(f"{path}: Concat over axis {a.get('axis')} is not supported (only channels)")
            plan.append((CONCAT, list(node.input), node.output[0]))
            continue
        if node.op_type == "Sum":
            plan.append((SUM, list(node.input), node.output[0]))
            continue
        plan.append((len(layers), [node.input[0]], node.output[0]))
        if node.op_type == "Conv":
            w = weights[node.input[1]]
            pads = list(a.get("pads", [0, 0, 0, 0]))  # type: ignore[call-overload]
            if pads[:2] != pads[2:]:
                raise ValueError(f"{path}: asymmetric Conv padding {pads} is not supported")
            conv = nn.Conv2d(w.shape[1] * int(a.get("group", 1)), w.shape[0], tuple(w.shape[2:]),  # type: ignore[call-overload]
                             stride=tuple(a.get("strides", [1, 1])), padding=tuple(pads[:2]),  # type: ignore[arg-type]
                             dilation=tuple(a.get("dilations", [1, 1])), groups=int(a.get("group", 1)),  # type: ignore[arg-type, call-overload]
                             bias=len(node.input) > 2)
            conv.weight.data.copy_(w)
            if conv.bias is not None:
                conv.bias.data.copy_(weights[node.input[2]])
            layers.append(conv)
        elif node.op_type == "Relu":
            layers.append(nn.ReLU())
        elif node.op_type == "Sigmoid":
            layers.append(nn.Sigmoid())
        elif node.op_type == "MaxPool":
            k = tuple(a["kernel_shape"])  # type: ignore[arg-type]
            if any(p for p in a.get("pads", [0]) or [0]):  # type: ignore[union-attr]
                raise ValueError(f"{path}: padded MaxPool is not supported")
            layers.append(nn.MaxPool2d(k, stride=tuple(a.get("strides", k)),  # type: ignore[arg-type]
                                       ceil_mode=bool(a.get("ceil_mode", 0))))
        elif node.op_type == "BatchNormalization":
            scale, bias, mean, var = (weights[n] for n in node.input[1:5])
            bn = nn.BatchNorm2d(scale.numel(), eps=float(a.get("epsilon", 1e-5)))  # type: ignore[arg-type]
            bn.weight.data.copy_(scale)
            bn.bias.data.copy_(bias)
            bn.running_mean.copy_(mean)
            bn.running_var.copy_(var)
            layers.append(bn)
        else:
            raise ValueError(f"{path}: op {node.op_type} is not one rtp-export writes for its networks")
    return OnnxGraph(layers, plan, _sources(model), model.graph.output[0].name).eval()


def _cuda_ms(fn, repeats: int) -> float:  # type: ignore[no-untyped-def]
    """Median CUDA-event time of ``fn`` in milliseconds, after a warm-up."""
    for _ in range(10):
        fn()
    torch.cuda.synchronize()
    times = []
    for _ in range(repeats):
        start, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
        start.record()
        fn()
        end.record()
        end.synchronize()
        times.append(start.elapsed_time(end))
    return statistics.median(times)


def _graphed(net: nn.Module, x: torch.Tensor):  # type: ignore[no-untyped-def]
    """``net(x)`` recorded once as a CUDA graph; returns the replay function."""
    stream = torch.cuda.Stream()
    stream.wait_stream(torch.cuda.current_stream())
    with torch.cuda.stream(stream), torch.inference_mode():
        for _ in range(3):
            net(x)
    torch.cuda.current_stream().wait_stream(stream)
    graph = torch.cuda.CUDAGraph()
    with torch.cuda.graph(graph), torch.inference_mode():
        net(x)
    return graph.replay


def full_float32() -> contextlib.AbstractContextManager[None]:
    """Convolutions and matrix products in full float32 while it lasts (torch's settings before restored after):
    cuDNN's TF32 kernels, torch's default for convolutions, round a float32 convolution's inputs to 10 bits of
    mantissa on Ampere and later GPUs, so the "fp32" columns timed TF32 and the fp16 difference was read against a
    TF32 output. The targets' own switch, ``rtp.metrics._device.full_float32``, for a CUDA device (torch's flags are
    the process's, whatever the device)."""
    from rtp.metrics._device import full_float32 as targets_float32

    return targets_float32(torch.device("cuda"))


def time_network(n32: nn.Module, n16: nn.Module, x32: torch.Tensor, repeats: int) -> tuple[float, float, float, float,
                                                                                          float]:
    """One network at one frame: ms of fp32 eager and replayed from a CUDA graph (full float32: :func:`full_float32`),
    of fp16 channels-last eager and replayed, and the largest difference of the fp16 output from the fp32 one."""
    with full_float32():  # (the graph is captured with the kernels chosen here: its replay stays float32)
        with torch.inference_mode():
            ref = n32(x32)
            t32 = _cuda_ms(partial(n32, x32), repeats)
        t32g = _cuda_ms(_graphed(n32, x32), repeats)
    x16 = x32.half().contiguous(memory_format=torch.channels_last)
    with torch.inference_mode():
        diff = float((n16(x16).float() - ref).abs().max())
        t16 = _cuda_ms(partial(n16, x16), repeats)
    t16g = _cuda_ms(_graphed(n16, x16), repeats)
    return t32, t32g, t16, t16g, diff


def given_models(models: list[str]) -> dict[str, Path]:
    """The files of the models given (``MODEL.onnx`` or a shipped model's name, which is no file in the working
    folder: rebuilt from the file ``sdk.load`` finds), each once, by file name, or by the path as given where two
    share one (``data/old/jnyang.onnx`` beside ``data/joined/jnyang.onnx`` were one row, the last), as
    ``bench/inference.py`` names them."""
    found = {m: Path(str(sdk.load(m, providers=["CPUExecutionProvider"]).path)) for m in dict.fromkeys(models)}
    names = [Path(m).name for m in found]
    return {(Path(m).name if names.count(Path(m).name) == 1 else m): path for m, path in found.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=positive, default=200)
    ap.add_argument("--frames", type=frame_sizes(1), default=DEFAULT_FRAMES, help="frame sizes, WxH comma-separated")
    ap.add_argument("models", nargs="*", help="more .onnx models to time")
    args = ap.parse_args()
    frames = args.frames
    given = given_models(args.models)  # (a model that does not load: refused before the GPU is asked for)
    if not torch.cuda.is_available():
        print("bench/inference_gpu.py needs a CUDA GPU, and torch sees none (CPU timings: bench/inference.py)",
              file=sys.stderr)
        raise SystemExit(2)
    torch.backends.cudnn.benchmark = True
    dev = torch.device("cuda")
    with tempfile.TemporaryDirectory() as d:
        paths = {"paper's network (random weights)": paper_model(Path(d))[1]}
        paths.update({f"shipped {n}": Path(str(sdk.load(n).path)) for n in sdk.shipped_models()})
        paths.update(given)
        meta = {name: sdk.load(p).metadata for name, p in paths.items()}
        nets = {name: torch_from_onnx(p) for name, p in paths.items()}
        has_cuda_ep = "CUDAExecutionProvider" in ort.get_available_providers()
        preds = ({name: sdk.load(p, providers=["CUDAExecutionProvider"]) for name, p in paths.items()}
                 if has_cuda_ep else {})
        rows = []
        for name, net in nets.items():
            m = meta[name]
            c = len(m.inputs)
            for w, h in frames:
                hp, wp = sdk.padded_size(h, w, m.pad_multiple)
                gen = torch.Generator(device=dev).manual_seed(0)
                x32 = torch.rand((1, c, hp, wp), device=dev, generator=gen)
                n32 = net.to(dev).float()
                n16 = torch_from_onnx(paths[name]).to(dev).half().to(memory_format=torch.channels_last)
                t32, t32g, t16, tg, diff = time_network(n32, n16, x32, args.repeats)
                tort = None
                if has_cuda_ep:
                    xh = np.random.default_rng(0).random((c, h, w), dtype=np.float32)
                    pr = preds[name]
                    tort = _cuda_ms(lambda pr=pr, xh=xh: pr.predict(xh), max(args.repeats // 10, 10))
                rows.append((name, c, f"{w}x{h}", t32, t32g, t16, tg, diff, tort))
    props = torch.cuda.get_device_properties(0)
    print(f"rtp {sdk.__version__}, torch {torch.__version__}, CUDA {torch.version.cuda}, cuDNN "
          f"{torch.backends.cudnn.version()}, {props.name}, onnxruntime {ort.__version__} "
          f"({'with' if has_cuda_ep else 'without'} its CUDA provider); batch 1, median of {args.repeats}; fp32 in "
          "full float32 (TF32 off)\n")
    ort_head = " | sdk predict, onnxruntime CUDA (ms)" if has_cuda_ep else ""
    print("| model | inputs | frame | fp32 eager (ms) | fp32 CUDA graph (ms) | fp16 eager (ms) | fp16 CUDA graph (ms) "
          f"| fp16 - fp32, largest |{ort_head}")
    print("|---|---:|---|---:|---:|---:|---:|---:|" + ("---:|" if has_cuda_ep else ""))
    for name, c, frame, t32, t32g, t16, tg, diff, tort in rows:
        extra = f" | {tort:.2f}" if tort is not None else ""
        print(f"| {name} | {c} | {frame} | {t32:.3f} | {t32g:.3f} | {t16:.3f} | {tg:.3f} | {diff:.4f}{extra} |")
    paper = "paper's network (random weights)"
    print("\nSpeed-up over the paper's network, CUDA graphs, fp32 / fp16:\n")
    print("| model | " + " | ".join(f"{w}x{h}" for w, h in frames) + " |")
    print("|---|" + "---:|" * len(frames))
    g32 = {(r[0], r[2]): r[4] for r in rows}
    g16 = {(r[0], r[2]): r[6] for r in rows}
    for name in nets:
        cells = " | ".join(f"{g32[paper, f] / g32[name, f]:.1f}x / {g16[paper, f] / g16[name, f]:.1f}x"
                           for f in (f"{w}x{h}" for w, h in frames))
        print(f"| {name} | {cells} |")


if __name__ == "__main__":
    run_main(main)
