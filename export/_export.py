"""Bake a trained checkpoint (or a foreign ONNX model) into an ONNX file that carries its metadata.

The exported graph takes its planes in one input ``input`` ``(batch, C, height, width)``, or, with
more than seven planes, in several that hold consecutive planes (``input``, ``input.K`` from plane
``K``: :func:`split_input_planes`), and has one output ``metric`` ``(batch, rates, height/w, width/w)``,
the names of the paper's published models. Where the network's first layer allows it (rtp's fast network),
a second output ``finite_probe`` (a float scalar, :func:`add_finite_probe`) lets ``rtp.sdk`` refuse
NaN and infinite input without reading the frame once more; an engine that runs the file itself asks
onnxruntime for ``metric`` alone and never computes it. The metadata is written last, as one JSON value under
``rtp.metadata`` (see docs/metadata.md), then the ONNX checker runs, then onnxruntime loads the
file through ``rtp.sdk.load`` and is compared with torch. The output appears only when all of that
passed (atomic rename).
"""

from __future__ import annotations

import base64
import contextlib
import dataclasses
import datetime as _dt
import logging
import os
import reprlib
import tempfile
import time
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from rtp.sdk import (
    METADATA_KEY,
    MetadataError,
    ModelLoadError,
    ModelMetadata,
    ModelNotFoundError,
    ParameterError,
    RtpError,
)
from rtp.sdk.files import atomic_output, check_output, read_sidecar, yaml_problem

from ._published import file_sha256, identify

__all__ = ["COMPUTED_FIELDS", "DEFAULT_OPSET", "PLANES_PER_INPUT", "PROBE_NODES", "RAW_RANGE", "RETUNE_FIELDS", "TRAINED_FIELDS",
           "ExportError", "add_finite_probe", "adopt", "export_checkpoint", "join_input_planes", "merge_slices", "restamp",
           "retune", "split_input_planes", "strip_finite_probe", "write_metadata"]

log = logging.getLogger("rtp.export")

#: The opset rtp-export writes by default: supported by onnxruntime >= 1.12 and TensorRT 8.x.
DEFAULT_OPSET = 17
INPUT_NAME = "input"
OUTPUT_NAME = "metric"
#: The second output :func:`add_finite_probe` gives a model (``metadata.finite_probe``), and the names of
#: the two nodes that compute it (``bench/ort_profile.py`` finds them in onnxruntime's profile).
PROBE_NAME = "finite_probe"
PROBE_NODES = ("rtp_finite_probe_mean", "rtp_finite_probe")
PARITY_TOLERANCE = 1e-4
#: The most input planes one graph input holds (:func:`split_input_planes`): onnxruntime's blocked (NCHWc)
#: convolution reads a layer's input where it lies only when it has fewer channels than the CPU's block
#: (8 with AVX2, 16 with AVX-512); with more it runs the generic im2col path, 2.3x slower for the stem.
PLANES_PER_INPUT = 7
#: How far a graph pass that reorders float sums (:func:`split_input_planes`) may move the network's
#: output (transformed space: 0 to 1), relative to the value: a few float32 ulps.
REASSOCIATION_TOLERANCE = 1e-5


class ExportError(RtpError):
    """The export itself failed: the exporter, the ONNX checker, or the onnxruntime/torch parity check."""


def _output(source: str | os.PathLike[str], output: str | os.PathLike[str], *, in_place: bool = True) -> Path:
    """``output`` as a place that can be written (:func:`rtp.sdk.files.check_output`), checked before
    any work; with ``in_place=False`` not ``source`` itself either (a checkpoint exported over itself
    was replaced by its model, the training lost). A model's copy may replace the model: each is
    written atomically and only once it predicts as the model did."""
    out = _path(output, "output")
    if not in_place and out.exists() and Path(source).exists() and os.path.samefile(out, source):
        raise ParameterError(f"output {str(out)!r} is the input itself; write the result to another path", "output")
    check_output(out, what="output")
    if out.is_file() and out.stat().st_size > 0 and not _is_onnx(out):  # (an empty file holds nothing to lose)
        kind = "a training checkpoint (a zip)" if _is_zip(out) else "no ONNX model"
        raise ParameterError(f"output {str(out)!r} exists and is {kind}: an export replaces only an ONNX model; "
                             "remove the file or write to another path", "output")
    return out


def _is_zip(path: Path) -> bool:
    with open(path, "rb") as f:
        return f.read(4) == b"PK\x03\x04"


def _is_onnx(path: Path) -> bool:
    """Whether ``path`` parses as an ONNX model (its weights' external files, if any, not read) that has an IR
    version and a graph, as every model onnx's checker or onnxruntime takes has: protobuf parses many short texts
    (``0``, ``x``, ``8``: a line of one) as a message of unknown fields, and such a file was replaced by an export."""
    if _is_zip(path):
        return False
    import onnx

    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception:  # (protobuf's DecodeError and its kin: anything that is no model)
        return False
    return bool(model.ir_version > 0 and model.HasField("graph"))


def _path(value: Any, what: str) -> Path:
    """``value`` as a Path, or a ParameterError (None, bytes and numbers reached pathlib's TypeError)."""
    if not isinstance(value, (str, os.PathLike)):
        raise ParameterError(f"{what}: expected a path, got {type(value).__name__}", what)
    return Path(value)


def _fields(value: Any, what: str) -> dict[str, Any]:
    """Metadata fields from a YAML sidecar's path or a mapping, or a MetadataError."""
    if isinstance(value, (str, os.PathLike)):
        return _read_yaml(value)
    if not isinstance(value, Mapping):
        raise MetadataError(f"{what}: expected a sidecar's path or a mapping of metadata fields, got "
                            f"{type(value).__name__}")
    return dict(value)


def _model(model: Any) -> Any:
    """``model`` if it is an ``onnx.ModelProto``, else a ParameterError (None reached ``.graph``)."""
    import onnx

    if not isinstance(model, onnx.ModelProto):
        raise ParameterError(f"model: expected an onnx.ModelProto, got {type(model).__name__}", "model")
    return model


def _merge(base: dict[str, Any], extra: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in extra.items():
        if isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = _merge(dict(out[k]), v)
        else:
            out[k] = v
    return out


def _read_yaml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A metadata sidecar's fields, read as ``sdk.load(..., metadata=PATH)`` reads them (:func:`read_sidecar`)."""
    import yaml

    p = Path(path)
    if not p.is_file():
        what = "is a folder, not a sidecar file" if p.is_dir() else "not found"
        raise ModelNotFoundError(f"metadata file {what}: {str(p)!r}")
    try:
        d = read_sidecar(p.read_text(encoding="utf-8"))
    except UnicodeDecodeError as err:
        raise MetadataError(f"{p}: not a YAML sidecar, not even UTF-8 text ({err.reason} at byte {err.start})") from err
    except (yaml.YAMLError, RecursionError, ValueError) as err:  # (nested too deep, a value PyYAML cannot build: a
        # bare RecursionError or ValueError, with its traceback, where `rtp info --metadata` said "not valid YAML")
        raise MetadataError(f"{p}: not valid YAML ({yaml_problem(err)})") from err
    if d is None:
        return {}
    if not isinstance(d, dict):
        raise MetadataError(f"{p}: expected a mapping of metadata fields, got {type(d).__name__}")
    return d


def write_metadata(model: Any, meta: ModelMetadata) -> None:
    """Set the rtp metadata on an ``onnx.ModelProto``, keeping every other metadata_props entry, with
    the digest of the model's graph and weights (``sdk.model_digest``) that ``sdk.load`` checks: call
    it last, once the graph is final.

    ``onnx.helper.set_model_props`` replaces all entries, so existing ones are merged first; the
    key is written exactly once (the ONNX checker rejects duplicates).
    """
    import dataclasses

    import onnx

    from rtp import sdk

    _model(model)
    if not isinstance(meta, ModelMetadata):
        raise ParameterError(f"meta: expected an sdk.ModelMetadata, got {type(meta).__name__}", "meta")
    body = onnx.ModelProto()
    body.CopyFrom(model)
    del body.metadata_props[:]
    meta = dataclasses.replace(meta, digest=sdk.model_digest(body.SerializeToString()))
    props = {p.key: p.value for p in model.metadata_props}
    props[METADATA_KEY] = meta.to_json()
    onnx.helper.set_model_props(model, props)


def add_finite_probe(model: Any, pad_multiple: int) -> str | None:
    """Give an ``onnx.ModelProto`` the output :data:`PROBE_NAME`: the summed per-channel means of its
    first convolution's output before any activation, a float scalar that is NaN or infinite whenever the input holds a
    NaN or an infinity (IEEE arithmetic: a product with one is one, or NaN for 0 x inf, and a sum
    that holds one is one). ``sdk.ShadingRatePredictor`` checks that scalar instead of reading the
    whole frame once more (``metadata.finite_probe``; docs/runtime.md). Returns the output's name,
    or None, changing nothing, where the probe would not see every pixel or would not be cheaper than
    reading the frame: exactly one of the ``Conv`` nodes the input feeds must have no padding or
    dilation, a kernel equal to its stride (every pixel in exactly one window) and a stride that
    divides ``pad_multiple`` (no row or column left over), with fewer output values than input values
    (rtp's fast network: a 4x4 stride-4 stem, 16 channels from eight planes, beside which a split
    network's tile contrast reads a few pixels of each tile; the paper's full-resolution 3x3 first
    layer has none)."""
    import onnx
    from onnx import helper

    graph = _model(model).graph
    if any(o.name == PROBE_NAME for o in graph.output):
        return PROBE_NAME
    stem = _stem_output(graph, pad_multiple)
    if stem is None:
        return None
    # GlobalAveragePool, not one ReduceSum over the whole tensor: onnxruntime's CPU provider runs it in
    # the convolution's blocked (NCHWc) layout, where a ReduceSum would first reorder the 1/4-resolution
    # tensor back (about 0.8 ms more at 1080p); the ReduceSum then adds up one value per channel
    mean = PROBE_NAME + "_mean"
    graph.node.append(helper.make_node("GlobalAveragePool", [stem], [mean], name=PROBE_NODES[0]))
    graph.node.append(helper.make_node("ReduceSum", [mean], [PROBE_NAME], keepdims=0, name=PROBE_NODES[1]))
    graph.output.append(helper.make_tensor_value_info(PROBE_NAME, onnx.TensorProto.FLOAT, []))
    return PROBE_NAME


def _plane_inputs(graph: Any) -> list[Any]:
    """The graph's inputs that are not weights (an older IR lists initializers among the inputs)."""
    init = {i.name for i in graph.initializer}
    return [i for i in graph.input if i.name not in init]


def _stem_output(graph: Any, pad_multiple: int) -> str | None:
    """The tensor of a graph that has seen every pixel of every input plane once, before any activation:
    the output of the one convolution of the input that reads every pixel (other nodes may read it too:
    a split network's contrast of its .blocks or .tiles planes; the stem sees those planes as well, with
    weights held at zero, and 0 x NaN is NaN), or for planes in groups (:func:`split_input_planes`) the
    Sum of such a convolution of each group. None where there is none."""
    init = {i.name: i for i in graph.initializer}
    inputs = [i.name for i in _plane_inputs(graph)]
    covering = []
    for name in inputs:
        readers = [n for n in graph.node if n.op_type == "Conv" and n.input[0] == name]
        if not readers or any(name in n.input[1:] for n in readers):
            return None
        found = [n for n in readers if _reads_every_pixel(n, init, pad_multiple)]
        if len(found) != 1:
            return None
        covering.append(found[0].output[0])
    if not covering:  # (a graph without inputs)
        return None
    if len(covering) == 1:
        return covering[0]
    # follow the first group's convolution through the Sums that add the others' to it, one by one
    summed, tensor = {covering[0]}, covering[0]
    while summed != set(covering):
        users = [n for n in graph.node if tensor in n.input]
        if len(users) != 1 or users[0].op_type != "Sum" or not set(users[0].input) - {tensor} <= set(covering):
            return None
        summed |= set(users[0].input) - {tensor}
        tensor = users[0].output[0]
    return tensor


def _reads_every_pixel(conv: Any, init: dict[str, Any], pad_multiple: int) -> bool:
    """Whether ``conv`` reads each pixel of its input exactly once and leaves fewer values than it
    reads: no padding or dilation, a kernel equal to its stride, a stride that divides
    ``pad_multiple`` (no row or column left over)."""
    from onnx import helper

    attrs = {a.name: helper.get_attribute_value(a) for a in conv.attribute}
    weight = init.get(conv.input[1]) if len(conv.input) > 1 else None
    if weight is None or len(weight.dims) != 4:
        return False
    kernel = list(attrs.get("kernel_shape", weight.dims[2:]))
    strides = list(attrs.get("strides", [1, 1]))
    auto_pad = attrs.get("auto_pad", b"NOTSET")
    if (kernel != strides or any(v != 0 for v in attrs.get("pads", [0, 0, 0, 0]))
            or any(v != 1 for v in attrs.get("dilations", [1, 1])) or auto_pad not in (b"NOTSET", "NOTSET")
            or any(pad_multiple % st for st in strides)):
        return False
    in_channels = weight.dims[1] * attrs.get("group", 1)
    return bool(weight.dims[0] < in_channels * strides[0] * strides[1])


def merge_slices(model: Any) -> int:
    """Merge each chain of ONNX ``Slice`` nodes with constant parameters on distinct axes into one
    ``Slice`` of the chain's first input, in place; returns how many were merged away. The TorchScript
    exporter writes ``x[:, 7:8, 0::4, 1::4]`` as three slices, and onnxruntime runs each as a copy: the
    first of two full-resolution planes, where the merged one reads only the pixels it keeps (a split
    network's stored block contrast, :class:`rtp.train.model.StoredBlockContrast`)."""
    from onnx import helper, numpy_helper

    graph = _model(model).graph
    consts: dict[str, np.ndarray] = {i.name: numpy_helper.to_array(i) for i in graph.initializer}
    for n in graph.node:
        if n.op_type == "Constant" and n.attribute and n.attribute[0].name == "value":
            consts[n.output[0]] = numpy_helper.to_array(n.attribute[0].t)
    producer = {o: n for n in graph.node for o in n.output}
    outputs = {o.name for o in graph.output}

    def params(node: Any) -> list[np.ndarray] | None:
        if len(node.input) < 3:  # opset 9's Slice: starts, ends and axes as attributes (a KeyError here): left as is
            return None
        names = list(node.input[1:]) + [""] * (5 - len(node.input))
        if any(name and name not in consts for name in names[:2]) or (names[2] and names[2] not in consts) \
                or (names[3] and names[3] not in consts):
            return None
        starts, ends = consts[names[0]].astype(np.int64), consts[names[1]].astype(np.int64)
        axes = consts[names[2]].astype(np.int64) if names[2] else np.arange(len(starts), dtype=np.int64)
        steps = consts[names[3]].astype(np.int64) if names[3] else np.ones(len(starts), dtype=np.int64)
        return None if (axes < 0).any() else [starts, ends, axes, steps]

    merged = 0
    for node in list(graph.node):
        if node.op_type != "Slice":
            continue
        first = producer.get(node.input[0])
        if first is None or first.op_type != "Slice" or first.output[0] in outputs:
            continue
        a, b = params(first), params(node)
        if a is None or b is None or set(a[2].tolist()) & set(b[2].tolist()):
            continue
        name = node.name or node.output[0]
        tensors = []
        for i, label in enumerate(("starts", "ends", "axes", "steps")):
            t = numpy_helper.from_array(np.concatenate([a[i], b[i]]), f"{name}_merged_{label}")
            graph.initializer.append(t)
            consts[t.name] = numpy_helper.to_array(t)
            tensors.append(t.name)
        new = helper.make_node("Slice", [first.input[0], *tensors], list(node.output), name=name)
        graph.node.insert(list(graph.node).index(node), new)
        graph.node.remove(node)
        producer[node.output[0]] = new
        merged += 1
    # slices no node reads any more (every reader now reads their input)
    read = {i for n in graph.node for i in n.input} | outputs
    for node in [n for n in graph.node if n.op_type == "Slice" and n.output[0] not in read]:
        graph.node.remove(node)
    # and the constants only they read (onnxruntime warns of unused initializers)
    read = {i for n in graph.node for i in n.input}
    for node in [n for n in graph.node if n.op_type == "Constant" and n.output[0] not in read]:
        graph.node.remove(node)
    for init in [i for i in graph.initializer if i.name not in read]:
        graph.initializer.remove(init)
    return merged


def split_input_planes(model: Any, most: int = PLANES_PER_INPUT) -> int:
    """Give an ``onnx.ModelProto`` whose one input holds its planes several inputs of consecutive planes,
    in place, where that lets onnxruntime read less or read faster; ``input`` holds the first group,
    ``input.K`` the group that starts at plane ``K``, in plane order. Returns the number of inputs the
    planes now come in (1: unchanged; more than 1 and unchanged for a graph already split, or one whose
    planes a node other than a plain convolution reads).

    Two rules make the groups. Planes that different convolutions read (a weight not zero) go to
    different groups, each convolution then reading only its own: a split network's stem weighs its
    ``.tiles`` planes zero and its tile contrast reads nothing else, so those planes come in a group of
    their own that the stem no longer reads (``jnyang-reuse``: 7 + 2 planes, the stem's two dead planes
    a 1080p frame's 16 MB unread). And no group holds more than ``most`` planes: a run of more is
    split as evenly as can be (nine planes all read by the stem: 5 and 4). Each convolution becomes
    one convolution per group it reads (its weights' slices, its bias on the first) and ``Sum`` s of
    them (onnxruntime runs them in the blocked layout too); the last keeps the name the convolution's
    output had, so the rest of the graph reads what it read before. The finite probe
    (:func:`add_finite_probe`), which reads the stem's output, gets the mean of every group the stem no
    longer reads added, so that a NaN in any plane still reaches it.

    Why the limit: onnxruntime's CPU provider runs a convolution in its blocked layout (NCHWc) straight
    from the caller's planes only when they are fewer than its block, 8 channels with AVX2 and 16 with
    AVX-512; eight or more planes on an AVX2-only CPU (most desktop and laptop CPUs) take the generic
    im2col path instead: the 4x4 stride-4 stem of a nine-plane model costs 21.5 ms of 32.3 ms of kernels
    for a 1080p frame there, split in two 9.4 ms and their sum 2.3 (docs/performance.md "Input planes on
    AVX2 CPUs"). ``rtp.sdk`` feeds each input its planes as views of the one array it is given, so
    splitting copies nothing."""
    import onnx
    from onnx import helper, numpy_helper

    if isinstance(most, bool) or not isinstance(most, (int, np.integer)) or most < 1:  # (0 was a ZeroDivisionError)
        raise ParameterError(f"most: expected the most planes one input holds, an integer >= 1, got {most!r}", "most")
    graph = _model(model).graph
    init = {i.name: i for i in graph.initializer}
    inputs = _plane_inputs(graph)
    if len(inputs) != 1:
        return len(inputs)
    x = inputs[0]
    dims = x.type.tensor_type.shape.dim
    c = dims[1].dim_value if len(dims) == 4 else 0
    readers = [n for n in graph.node if x.name in n.input]

    def plain(n: Any) -> bool:
        attrs = {a.name: helper.get_attribute_value(a) for a in n.attribute}
        return (n.op_type == "Conv" and n.input[0] == x.name and x.name not in n.input[1:] and len(n.input) > 1
                and n.input[1] in init and attrs.get("group", 1) == 1 and attrs.get("auto_pad", b"NOTSET")
                in (b"NOTSET", "NOTSET"))

    if c < 2 or not readers or not all(plain(n) for n in readers):
        if readers and not all(plain(n) for n in readers):
            log.debug("split_input_planes: %s is read by %s, not only by plain convolutions; left whole", x.name,
                      sorted({n.op_type for n in readers}))
        return 1
    weights = [numpy_helper.to_array(init[n.input[1]]) for n in readers]
    runs = _reader_runs([frozenset(k for k, w in enumerate(weights) if np.any(w[:, p])) for p in range(c)])
    if len(runs) == 1 and c <= most:
        return 1
    bounds, group_readers = [0], []
    for a, b, who in runs:  # each run as few and as even groups as can be
        k = -(-(b - a) // most)
        for g in range(k):
            bounds.append(bounds[-1] + (b - a) // k + (1 if g < (b - a) % k else 0))
            group_readers.append(who)
    sizes = np.diff(bounds).tolist()
    names = [x.name] + [f"{x.name}.{a}" for a in bounds[1:-1]]
    new_inputs = []
    for name, n_planes in zip(names, sizes):
        vi = onnx.ValueInfoProto()
        vi.CopyFrom(x)
        vi.name = name
        vi.type.tensor_type.shape.dim[1].dim_value = n_planes
        new_inputs.append(vi)
    nodes, seen_by = [], {}
    for node in graph.node:
        if node not in readers:
            nodes.append(node)
            continue
        k = readers.index(node)
        groups = [g for g, who in enumerate(group_readers) if k in who] or [0]  # a convolution of zeros: the first
        seen_by[node.output[0]] = set(groups)
        w, label, parts = weights[k], node.name or node.output[0], []
        for j, g in enumerate(groups):
            a, b = bounds[g], bounds[g + 1]
            wname = f"{label}/planes{a}_weight"
            graph.initializer.append(numpy_helper.from_array(np.ascontiguousarray(w[:, a:b]), wname))
            ins = [names[g], wname] + ([node.input[2]] if j == 0 and len(node.input) > 2 and node.input[2] else [])
            out = node.output[0] if len(groups) == 1 else f"{label}/planes{a}"
            nodes.append(helper.make_node("Conv", ins, [out], name=f"{label}/planes{a}"))
            nodes[-1].attribute.extend(node.attribute)
            parts.append(out)
        acc = parts[0]
        for j, part in enumerate(parts[1:], 1):  # Sums of two, the first group's convolution first
            out = node.output[0] if j == len(parts) - 1 else f"{label}/planes_sum{j}"
            nodes.append(helper.make_node("Sum", [acc, part], [out], name=f"{label}/planes_sum{j}"))
            acc = out
    nodes += _probe_every_group(nodes, names, seen_by)
    del graph.node[:]
    graph.node.extend(nodes)
    read = {i for n in graph.node for i in n.input}
    for t in [i for i in graph.initializer if i.name not in read]:
        graph.initializer.remove(t)
    others = [i for i in graph.input if i.name != x.name and (i.name not in init or i.name in read)]
    del graph.input[:]
    graph.input.extend(new_inputs + others)
    return len(names)


def _reader_runs(reads: list[frozenset[int]]) -> list[tuple[int, int, frozenset[int]]]:
    """``(first plane, end, readers)`` of each run of consecutive planes that the same convolutions read
    (``reads[p]``: the convolutions with a weight on plane ``p`` that is not zero). A plane that none
    reads joins the run before it (the first planes: the run after them), so that every group is read."""
    known = [r for r in reads if r]
    if not known:
        return [(0, len(reads), frozenset())]
    filled, last = [], known[0]
    for r in reads:
        last = r or last
        filled.append(last)
    runs: list[tuple[int, int, frozenset[int]]] = []
    for p, r in enumerate(filled):
        if runs and runs[-1][2] == r:
            runs[-1] = (runs[-1][0], p + 1, r)
        else:
            runs.append((p, p + 1, r))
    return runs


def _probe_every_group(nodes: list[Any], names: list[str], seen_by: dict[str, set[int]]) -> list[Any]:
    """The nodes that make the finite probe (:func:`add_finite_probe`, if ``nodes`` hold it) see every
    group of input planes: the mean of each group the tensor it reads does not cover (``seen_by``: the
    groups each convolution's output has seen), summed with it. Renames the probe's own reduction's output."""
    from onnx import helper

    probe = next((n for n in nodes if n.name == PROBE_NODES[1]), None)
    mean = next((n for n in nodes if n.name == PROBE_NODES[0]), None)
    if probe is None or mean is None:
        return []
    missing = [g for g in range(len(names)) if g not in seen_by.get(mean.input[0], set())]
    if not missing:
        return []
    extra, parts = [], [f"{PROBE_NAME}/stem"]
    probe.output[0] = parts[0]
    for g in missing:
        extra.append(helper.make_node("GlobalAveragePool", [names[g]], [f"{PROBE_NAME}/{names[g]}_mean"],
                                      name=f"{PROBE_NODES[0]}/{names[g]}"))
        extra.append(helper.make_node("ReduceSum", [extra[-1].output[0]], [f"{PROBE_NAME}/{names[g]}"], keepdims=0,
                                      name=f"{PROBE_NODES[1]}/{names[g]}"))
        parts.append(extra[-1].output[0])
    extra.append(helper.make_node("Sum", parts, [PROBE_NAME], name=f"{PROBE_NODES[1]}/groups"))
    return extra


def _join_groups(model: Any) -> int:
    """Undo :func:`split_input_planes` on an ``onnx.ModelProto``, in place: the planes of the inputs
    ``input``, ``input.K``, ... in one input ``input`` again, each set of per-group convolutions and the
    Sums that add them one convolution of the concatenated weights (zeros for the planes of a group it
    did not read; the bias it had), whose output keeps the last Sum's name, and the finite probe back to
    the stem's output alone (which now sees every plane again). Returns the number of inputs the planes
    came in; raises :class:`ExportError` for a graph whose inputs are not groups of one input's planes."""
    import onnx
    from onnx import helper, numpy_helper

    graph = model.graph
    init = {i.name: i for i in graph.initializer}
    inputs = _plane_inputs(graph)
    if len(inputs) < 2:
        return len(inputs)
    first = inputs[0]

    def planes(vi: Any) -> int:
        dims = vi.type.tensor_type.shape.dim
        return dims[1].dim_value if len(dims) == 4 and dims[1].HasField("dim_value") else 0

    sizes = [planes(i) for i in inputs]
    bounds = np.cumsum([0, *sizes]).tolist()
    if 0 in sizes or [i.name for i in inputs] != [first.name] + [f"{first.name}.{b}" for b in bounds[1:-1]]:
        raise ExportError(f"the graph's inputs {[i.name for i in inputs]} are not planes in groups as rtp-export "
                          f"writes them ({first.name}, {first.name}.K, ... of fixed plane counts): nothing joined")
    group = {i.name: g for g, i in enumerate(inputs)}
    failure = ExportError(f"{first.name}'s planes are read by nodes other than one convolution per group added by "
                          "Sums (rtp-export's split_input_planes): nothing joined")
    nodes = [n for n in graph.node if not n.name.startswith((f"{PROBE_NODES[0]}/", f"{PROBE_NODES[1]}/"))]
    for n in nodes:  # the probe reads the stem's output alone again
        if n.name == PROBE_NODES[1]:
            n.output[0] = PROBE_NAME
    members: dict[str, list[Any]] = {}  # tensor -> the per-group convolutions whose sum it is
    summed: set[str] = set()
    dropped: set[int] = set()
    for n in nodes:
        if n.input and n.input[0] in group:
            if n.op_type != "Conv" or n.input[1] not in init or any(i in group for i in n.input[1:]):
                raise failure
            members[n.output[0]] = [n]
        elif n.op_type == "Sum" and len(n.input) == 2 and all(i in members for i in n.input):
            members[n.output[0]] = members[n.input[0]] + members[n.input[1]]
            summed |= set(n.input)
            dropped.add(id(n))
        elif any(i in group for i in n.input):
            raise failure
    if any(sum(t in n.input for n in nodes) != 1 for t in summed):  # a partial sum read by another node too
        raise failure
    joined: dict[int, Any] = {}
    for tensor, convs in members.items():
        if tensor in summed:
            continue
        groups = [group[c.input[0]] for c in convs]
        biases = [c.input[2] for c in convs if len(c.input) > 2 and c.input[2]]
        if len(set(groups)) != len(groups) or len(biases) > 1 or any(list(c.attribute) != list(convs[0].attribute)
                                                                      for c in convs):
            raise failure
        parts = {g: numpy_helper.to_array(init[c.input[1]]) for g, c in zip(groups, convs)}
        shape = next(iter(parts.values())).shape
        if any(w.shape[1] != sizes[g] or w.shape[0] != shape[0] or w.shape[2:] != shape[2:] for g, w in parts.items()):
            raise failure
        w = np.concatenate([parts.get(g, np.zeros((shape[0], sizes[g], *shape[2:]), np.float32))
                            for g in range(len(inputs))], axis=1)
        graph.initializer.append(numpy_helper.from_array(w, f"{tensor}/joined_weight"))
        new = helper.make_node("Conv", [first.name, f"{tensor}/joined_weight", *biases], [tensor],
                               name=convs[0].name.rsplit("/planes", 1)[0] or tensor)
        new.attribute.extend(convs[0].attribute)
        joined[id(convs[0])] = new
        dropped |= {id(c) for c in convs[1:]}
    rebuilt = [joined.get(id(n), n) for n in nodes if id(n) not in dropped]
    del graph.node[:]
    graph.node.extend(rebuilt)
    read = {i for n in graph.node for i in n.input}
    for t in [i for i in graph.initializer if i.name not in read]:
        graph.initializer.remove(t)
    one = onnx.ValueInfoProto()
    one.CopyFrom(first)
    one.type.tensor_type.shape.dim[1].dim_value = int(bounds[-1])
    others = [i for i in graph.input if i.name not in group and (i.name not in init or i.name in read)]
    del graph.input[:]
    graph.input.extend([one, *others])
    return len(inputs)


def join_input_planes(model_path: str | os.PathLike[str], output: str | os.PathLike[str]) -> Path:
    """Write a copy of an rtp model (a path, or a shipped model's name) whose planes come in groups
    (:func:`split_input_planes`) with every plane in the one input ``input`` again: for an engine that
    binds one tensor and runs on an AVX-512 CPU or a GPU, where the groups gain nothing
    (docs/export.md "Input planes in groups"). The weights and every metadata field stay as they are;
    the copy is checked to predict as the model within float rounding (the stem's sums are reordered)
    before it is written (atomically). A split network's tail graph has one input already and stays."""
    import onnx

    from rtp import sdk

    before = sdk.load(model_path, providers=["CPUExecutionProvider"])
    src = Path(str(before.path))
    out = _output(src, output)
    if len(before.graph_inputs) < 2:
        raise ParameterError(f"{src} takes its planes in one input already ({before.graph_inputs[0][0]}): "
                             "nothing to join")
    model = onnx.load(str(src))
    _join_groups(model)
    write_metadata(model, before.metadata)
    _save_unchanged(model, before, out, f"joining the input planes of {src} changed its predictions; nothing "
                    "written", reassociated=True)
    return out


def _doc_string(meta: ModelMetadata) -> str:
    """The ONNX model's ``doc_string`` of an rtp model with metadata ``meta``: its description, else what it is."""
    return meta.description or f"rtp {meta.metric} predictor, {meta.tile_size}x{meta.tile_size} tiles"


#: The metadata fields :func:`retune` may change: how the runtime decides, never what the network predicts.
RETUNE_FIELDS = ("default_threshold", "rate_factors", "description")


def retune(model_path: str | os.PathLike[str], metadata: Mapping[str, Any] | str | os.PathLike[str],
           output: str | os.PathLike[str]) -> Path:
    """Write a copy of an rtp model (a path, or a shipped model's name) whose decision fields
    (:data:`RETUNE_FIELDS`: the default threshold, the threshold factors per rate, the description) are
    replaced by those of ``metadata`` (a YAML sidecar or a mapping; ``rate_factors: null`` returns to one
    threshold for every rate). Graph, weights, tail and every other field stay (the ONNX doc string follows the
    description, as export writes it); the copy records what changed in
    ``provenance.retuned`` and is checked to predict exactly as the model before it is written
    (atomically; ``output`` may be the model itself). Other fields are refused: a safety margin or a
    transform changes the predictions, and belongs to training (``rtp train``) or export."""
    import onnx

    from rtp import sdk

    before = sdk.load(model_path, providers=["CPUExecutionProvider"])
    src = Path(str(before.path))
    out = _output(src, output)
    d = _read_yaml(metadata) if isinstance(metadata, (str, os.PathLike)) else metadata
    if not isinstance(d, Mapping):
        raise MetadataError(f"retune: expected a mapping of metadata fields, got {type(d).__name__}")
    # (a sidecar's refusals name it, as its invalid values' do below)
    source = f"{metadata}: " if isinstance(metadata, (str, os.PathLike)) else ""
    other = sorted(str(k) for k in d if k not in RETUNE_FIELDS)
    if other:
        raise MetadataError(f"{source}{other[0]}: retune changes only the decision fields {', '.join(RETUNE_FIELDS)}; "
                            f"{other[0]} changes what the model predicts (set it in training or at export)", other[0])
    if not d:
        raise MetadataError(f"{source or 'retune: '}the sidecar sets none of {', '.join(RETUNE_FIELDS)}: nothing to "
                            "change")
    if d.get("default_threshold", 0.0) is None:
        raise MetadataError(f"{source}default_threshold: retune replaces it, it cannot be removed (null)",
                            "default_threshold")
    fields = before.metadata.to_dict()
    for k, v in d.items():  # null: rate_factors back to one threshold, description empty
        fields.pop(k, None)
        if v is not None:
            fields[k] = v
    fields["provenance"] = _merge(fields.get("provenance") or {}, {"retuned": {
        "fields": sorted(str(k) for k in d), "from": src.name, "rtp": str(sdk.__version__),
        "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()}})
    fields.pop("schema_version", None)  # written as the lowest version that holds the fields
    try:
        meta = ModelMetadata.from_dict(fields)
    except MetadataError as err:  # (the model's own fields were valid as it loaded: the sidecar's, named)
        raise MetadataError(f"{source}{err}", err.key) from err
    model = onnx.load(str(src))
    if "description" in d:  # the doc string states the description, as export wrote it (a retuned description
        # left the old one there, which Netron and onnx's tools show); the digest covers it: a new description, a new
        # digest. (Only then: an adopted model's own doc string stays through a retune of its thresholds.)
        model.doc_string = _doc_string(meta)
    write_metadata(model, meta)
    _save_unchanged(model, before, out, f"retuning {src} changed its predictions; nothing written")
    log.info("retuned %s -> %s (%s)", src, out, ", ".join(sorted(str(k) for k in d)))
    return out


def strip_finite_probe(model_path: str | os.PathLike[str], output: str | os.PathLike[str]) -> Path:
    """Write a copy of an rtp model (a path, or a shipped model's name) without its finite probe
    (:func:`add_finite_probe`): for an engine that runs the file with its own onnxruntime session and
    checks its input itself. onnxruntime computes every node whatever outputs a run asks for, so the
    probe costs such an engine its reduction and the stem's unfused ReLU (about 1 ms of a 1080p frame
    on a 2-core CPU) for nothing. The weights, the ``metric`` output and every other metadata field
    stay as they are; the copy is checked to predict exactly as the model before it is written
    (atomically)."""
    import onnx

    from rtp import sdk

    before = sdk.load(model_path, providers=["CPUExecutionProvider"])  # a path or a shipped model's name
    src = Path(str(before.path))
    out = _output(src, output)
    probe = before.metadata.finite_probe
    if probe is None:
        raise ParameterError(f"{src} has no finite probe (metadata.finite_probe is null): nothing to strip")
    model = onnx.load(str(src))
    graph = model.graph
    nodes = list(graph.node)
    kept_outputs = {o.name for o in graph.output} - {probe}
    dead: set[int] = set()
    for i in reversed(range(len(nodes))):  # the probe's own nodes: all they compute feeds only the probe
        users = [j for j, n in enumerate(nodes) if set(n.input) & set(nodes[i].output)]
        if probe in nodes[i].output or (users and set(users) <= dead and not set(nodes[i].output) & kept_outputs):
            dead.add(i)
    keep = [n for i, n in enumerate(nodes) if i not in dead]
    del graph.node[:]
    graph.node.extend(keep)
    outs = [o for o in graph.output if o.name != probe]
    del graph.output[:]
    graph.output.extend(outs)
    write_metadata(model, dataclasses.replace(before.metadata, finite_probe=None))
    _save_unchanged(model, before, out, f"stripping the probe of {src} changed its predictions; nothing written")
    return out


def _save_unchanged(model: Any, before: Any, out: Path, failure: str, *, reassociated: bool = False) -> None:
    """Check and save ``model`` to ``out`` atomically if it predicts exactly as the predictor ``before``
    (on a random frame of 5 x 7 of its tiles), or within :data:`REASSOCIATION_TOLERANCE` where a pass
    reordered float sums (``reassociated``: :func:`split_input_planes`); else :class:`ExportError` with
    ``failure``, nothing written."""
    from rtp import sdk

    t = before.tile_size
    x = np.random.default_rng(0).random((len(before.metadata.inputs), 5 * t, 7 * t), dtype=np.float32)
    with atomic_output(out) as tmp:
        _check_and_save(model, tmp)
        after = sdk.load(tmp, providers=["CPUExecutionProvider"])
        want, got = before.predict_raw(x), after.predict_raw(x)
        tol = REASSOCIATION_TOLERANCE if reassociated else 0.0
        if want.shape != got.shape or not np.allclose(got, want, rtol=tol, atol=tol):
            raise ExportError(failure)


def _export_provenance(opset: int) -> dict[str, Any]:
    import onnx
    import torch

    from rtp import sdk

    return {
        "rtp": str(sdk.__version__),
        "torch": str(torch.__version__),
        "onnx": str(onnx.__version__),
        "opset": opset,
        "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
    }


def _parity_sizes(tile: int, multiple: int | None = None) -> list[tuple[int, int]]:
    """Frame sizes the exported model is checked at: two of whole tiles and, for a network that takes
    partial tiles (``input_multiple`` below the tile size), one that ends in a partial tile."""
    base = max(tile, 16)
    sizes = [(base * 4, base * 6), (base * 3, base * 5)]
    if multiple is not None and multiple < tile:
        sizes.append((base * 3 + multiple, base * 5 + tile - multiple))
    return sizes


def export_checkpoint(
    checkpoint: str | os.PathLike[str],
    output: str | os.PathLike[str] | None = None,
    *,
    opset: int = DEFAULT_OPSET,
    extra_metadata: Mapping[str, Any] | str | os.PathLike[str] | None = None,
    finite_probe: bool = True,
    split_planes: bool = True,
) -> Path:
    """Export a checkpoint written by ``rtp.train.checkpoint.save`` to ONNX with its metadata.

    ``extra_metadata`` (a mapping or a YAML path) is merged over the checkpoint's metadata, e.g. to
    set a description or a default threshold. ``finite_probe=False`` leaves out the finite probe
    (:func:`add_finite_probe`) for an engine that runs the file itself. ``split_planes=False`` keeps
    every input plane in the one input ``input`` where :func:`split_input_planes` would give more than
    seven planes several inputs. Returns the output path (default: the checkpoint's path with ``.onnx``).
    """
    import onnx
    import torch

    from rtp import sdk
    from rtp.train import checkpoint as ckpt_mod

    # (numpy's integers and flags as Python's, as rtp.sdk takes them: np.int64(17) was "expected 9 to 20")
    if isinstance(opset, (bool, np.bool_)) or not isinstance(opset, (int, np.integer)) or not 9 <= opset <= 20:
        raise ParameterError(f"opset: expected an integer from 9 to 20 (default {DEFAULT_OPSET}), got {opset!r}",
                             "opset")
    opset = int(opset)
    if not isinstance(finite_probe, (bool, np.bool_)):
        raise ParameterError(f"finite_probe: expected True or False, got {finite_probe!r}", "finite_probe")
    if not isinstance(split_planes, (bool, np.bool_)):
        raise ParameterError(f"split_planes: expected True or False, got {split_planes!r}", "split_planes")
    finite_probe, split_planes = bool(finite_probe), bool(split_planes)
    ckpt = ckpt_mod.load(checkpoint)
    out = _output(checkpoint, output if output is not None else Path(checkpoint).with_suffix(".onnx"), in_place=False)
    if ckpt.training is not None and ckpt.training.get("done") is False:
        log.warning("%s holds a training that has not finished (step %s; its safety margin, calibrated at the end, is "
                    "%g): the model is exported as it stands; the same rtp train command finishes it",
                    checkpoint, ckpt.training.get("step", "?"), ckpt.metadata.safety)
    # (`rtp train` exits 1 on dead outputs and calls the checkpoint not fit to export; exporting it anyway was silent)
    dead = ckpt.metadata.provenance.get("dead_outputs")
    if isinstance(dead, (list, tuple)) and dead:
        paper = ckpt.metadata.provenance.get("arch", "paper") == "paper"  # (the fast network has no --head)
        log.warning("%s: output(s) %s predicted the same value on every validation tile when rtp train finished "
                    "(provenance.dead_outputs): such a model picks rates blindly; it is exported as it stands (a dead "
                    "output does not recover with more steps): train again with %s", checkpoint,
                    ", ".join(map(str, dead)), "--head linear or another --seed" if paper else "another --seed")
    meta_dict = ckpt.metadata.to_dict()
    # (a sidecar's fields named no file: "default_threshold: expected a finite number, got nan")
    source = f"{extra_metadata}: " if isinstance(extra_metadata, (str, os.PathLike)) else ""
    if extra_metadata is not None:
        extra = _fields(extra_metadata, "extra_metadata")
        _check_not_computed(extra, source)
        if "provenance" in extra and not isinstance(extra["provenance"], Mapping):
            # (merged below, the export's own entry replaced it: the checkpoint's provenance was lost, without a word)
            raise MetadataError(f"{source}provenance: expected a mapping (merged into the checkpoint's provenance), got "
                                f"{reprlib.repr(extra['provenance'])}", "provenance")
        # (before the merged metadata is validated: `metric: psnr` was refused as "higher_is_better: psnr is
        # higher-is-better", `tile_size: 8` and `outputs: [1x2, 2x1]` by the network check without the sidecar's name)
        _check_trained_extra(ckpt.metadata, extra, source)
        meta_dict = _merge(meta_dict, extra)
    meta_dict = _merge(meta_dict, {"provenance": {"export": _export_provenance(opset)}})
    net = ckpt.net.eval()
    # the network decides which frame sizes it takes (FastNet: multiples of its stem)
    meta_dict["input_multiple"] = getattr(net, "input_multiple", None)
    try:
        meta = ModelMetadata.from_dict(meta_dict)
    except MetadataError as err:  # (the checkpoint's own metadata was validated as it loaded: the sidecar's)
        raise MetadataError(f"{source}{err}", err.key) from err
    ckpt_mod.check_fits(net, meta)
    _check_trained_fields(ckpt.metadata, meta, source)

    c, t = net.config["in_channels"], net.config["tile"]
    h, w = _parity_sizes(t)[0]
    dummy = torch.rand(1, c, h, w, generator=torch.Generator().manual_seed(0))
    # a trunk to carry across frames and a tail: two graphs (a stored contrast that joins at tile resolution; one
    # that joins at a finer cell has no per-tile features to carry, and exported as two failed the tail's check)
    split = bool(getattr(net, "splits", False))
    t0 = time.perf_counter()
    with atomic_output(out) as tmp:
        try:
            _torch_export(_with_features(net) if split else net, (dummy,), tmp, opset, split=split)
        except OSError:  # the file system's (a full disk): atomic_output names the file
            raise
        except Exception as err:
            raise _exporter_failure(err, opset) from err
        model = onnx.load(str(tmp))
        merge_slices(model)
        model.producer_name = "rtp-export"
        model.producer_version = str(sdk.__version__)
        model.doc_string = _doc_string(meta)
        if finite_probe:
            meta = dataclasses.replace(meta, finite_probe=add_finite_probe(model, meta.pad_multiple))
        if split_planes:  # after the probe, which reads the stem's output: the groups' sum keeps its name
            split_input_planes(model)
        if split:
            with _scratch_beside(out) as scratch:  # (not TMP.tail: a kill -9 left that beside the model for good)
                tail = _tail_model(net, dummy, scratch, opset)
            onnx.helper.set_model_props(model, {**{p.key: p.value for p in model.metadata_props},
                                                sdk.TAIL_KEY: base64.b64encode(tail).decode("ascii")})
            meta = dataclasses.replace(meta, tail=sdk.model_digest(tail))
        write_metadata(model, meta)  # the last change to the model
        _check_and_save(model, tmp)
        _torch_parity(tmp, net, meta)
    log.info("exported %s -> %s in %.1f s", checkpoint, out, time.perf_counter() - t0)
    return out


#: The metadata fields a checkpoint's network was trained for: the metric and its target parameters, the
#: input planes in order, the predicted rates in order, the tile and the target transform. Extra metadata
#: that changes one would describe another network (a model trained on luma told to read red, its 1x2
#: output labelled 2x1): ``export_checkpoint`` refuses it (a sidecar may restate them). ``higher_is_better`` too: the
#: safety margin was calibrated in the metric's worse direction, and a plugin metric's (which the SDK cannot check
#: against rtp's own list) flipped by a sidecar applied the margin the optimistic way and inverted every decision.
TRAINED_FIELDS = ("metric", "higher_is_better", "inputs", "outputs", "tile_size", "transform", "weber_l")


def _check_trained_fields(trained: ModelMetadata, meta: ModelMetadata, source: str = "") -> None:
    """Refuse extra metadata that changes what the checkpoint's network was trained for (:data:`TRAINED_FIELDS`);
    ``source`` ("SIDECAR.yaml: ") starts the message where the extra metadata came from a file."""
    for key in TRAINED_FIELDS:
        was, now = getattr(trained, key), getattr(meta, key)
        if key == "transform":
            was, now = was.to_dict(), now.to_dict()
        if was != now:
            raise _trained_field_error(key, was, now, source)


def _check_trained_extra(trained: ModelMetadata, extra: Mapping[Any, Any], source: str = "") -> None:
    """:func:`_check_trained_fields` on the extra metadata as given, before it is merged and validated: a change of a
    trained field (the transform's aside, compared once validated) is named as such, where the validation of the
    merged metadata or the network check refused it by a consequence (``metric: psnr``: "higher_is_better: psnr is
    higher-is-better") or without the sidecar's name (``tile_size: 8``). A value that restates the field in
    another spelling (a list for a tuple, ``16.0`` for 16) passes here and is checked once validated."""
    for key in TRAINED_FIELDS:
        if key == "transform" or key not in extra:
            continue
        was, now = getattr(trained, key), extra[key]
        if isinstance(was, tuple):
            same = isinstance(now, (list, tuple)) and list(now) == list(was)
        elif was is None or isinstance(was, str) or isinstance(now, (bool, np.bool_)):
            same = now == was
        else:
            try:
                same = float(now) == float(was)
            except (TypeError, ValueError):
                same = False
        if not same:
            raise _trained_field_error(key, was, now, source)


def _trained_field_error(key: str, was: Any, now: Any, source: str) -> MetadataError:
    return MetadataError(f"{source}{key}: the checkpoint's network was trained for {_shown(was)}, the extra metadata says "
                         f"{_shown(now)}; extra metadata sets descriptive and decision fields (description, "
                         f"default_threshold, rate_factors, provenance, ...), not what the network was trained "
                         f"on: train another model", key)


def _shown(value: Any) -> Any:
    if isinstance(value, (bool, np.bool_)):  # (as the metadata and a sidecar spell it)
        return "true" if value else "false"
    return ", ".join(map(str, value)) if isinstance(value, (tuple, list)) else value


#: The metadata fields the export computes from the network and the file it writes, with what each is: extra
#: metadata that set one was overwritten without a word (or, for ``finite_probe`` with ``finite_probe=False``
#: and ``tail`` on a network that does not split, kept, and the export failed once done, loading its own file).
#: ``export_checkpoint`` refuses them in extra metadata.
_COMPUTED = {
    "input_multiple": "the multiple of the frame sizes the network takes, from the network",
    "finite_probe": "the name of the finite probe's output the export adds, or null",
    "tail": "the digest of a splitting network's tail graph",
    "schema_version": "the lowest metadata schema that holds the fields",
    "digest": "the SHA-256 of the exported graph and weights",
}
COMPUTED_FIELDS = tuple(_COMPUTED)


def _check_not_computed(extra: Mapping[Any, Any], source: str = "") -> None:
    """Refuse extra metadata that sets a field the export computes (:data:`COMPUTED_FIELDS`); ``source``
    ("SIDECAR.yaml: ") starts the message where the extra metadata came from a file."""
    for key, what in _COMPUTED.items():
        if key in extra:
            raise MetadataError(f"{source}{key}: computed by the export ({what}), expected no {key} in the extra metadata, "
                                f"got {reprlib.repr(extra[key])}: leave it out", key)


def _with_features(net: Any) -> Any:
    """A splitting network (``FastNet.splits``: a stored contrast at tile resolution) as a module whose graph also outputs the
    trunk's features (``sdk.FEATURES_NAME``)."""
    import torch

    class WithFeatures(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.net = net

        def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            h = self.net.trunk(x)
            return self.net.tail(h, x), h

    return WithFeatures().eval()


@contextlib.contextmanager
def _scratch_beside(out: Path) -> Iterator[Path]:
    """A scratch file beside ``out`` named as :func:`~rtp.sdk.files.atomic_output` names its temporary files
    (``.NAME.k2j4x9ab.tmp``), held by an ``flock`` while it lives (where the system has one) and removed at the end:
    one that an export killed outright leaves (``kill -9``, the OOM killer: no cleanup ran) is an orphan the next
    write of ``out`` removes, as it removes its own. A split network's tail was exported to ``TMP.tail``, a name no
    sweep knew, which stayed beside the model for good."""
    fd, name = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent)
    try:
        import fcntl

        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except (ImportError, OSError):  # (no flock: closed at once, as atomic_output does; Windows keeps an open file)
        os.close(fd)
        fd = -1
    try:
        yield Path(name)
    finally:
        Path(name).unlink(missing_ok=True)
        if fd >= 0:
            os.close(fd)


def _tail_model(net: Any, dummy: Any, path: Path, opset: int) -> bytes:
    """The serialized ONNX tail of a splitting network: ``(features, input) -> metric``, its slices merged."""
    import onnx
    import torch

    from rtp import sdk

    class Tail(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.net = net

        def forward(self, features: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
            return self.net.tail(features, x)

    with torch.inference_mode():
        features = net.trunk(dummy)
    try:
        _torch_export(Tail().eval(), (features, dummy), path, opset, tail=True)
        model = onnx.load(str(path))
    except OSError:  # the file system's (a full disk): the caller's atomic_output names the file
        raise
    except Exception as err:
        raise _exporter_failure(err, opset, " on the tail") from err
    finally:
        path.unlink(missing_ok=True)
    merge_slices(model)
    model.producer_name = "rtp-export"
    model.producer_version = str(sdk.__version__)
    model.doc_string = "rtp split network: the tail (trunk features and a frame -> per-tile outputs)"
    try:
        onnx.checker.check_model(model, full_check=True)
    except Exception as err:
        raise ExportError(f"the ONNX checker rejected the tail: {err}") from err
    return bytes(model.SerializeToString())


def _exporter_failure(err: BaseException, opset: int, what: str = "") -> ExportError:
    """The TorchScript exporter's error as one short line: its first, without the IR graph it appends
    (``[Caused by the value ...``, kilobytes) or its request for a pull request; for an opset below the
    default, which one to try (opset 9 cannot express the fast network's ceil-mode max-pool)."""
    lines = str(err).split("[Caused by", 1)[0].strip().splitlines()
    first = (lines[0] if lines else "").split(" Please feel free to request support", 1)[0].strip().rstrip(".")
    if len(first) > 300:
        first = first[:297] + "..."
    hint = (f"; opset {opset} may not express this network: try the default, --opset {DEFAULT_OPSET}"
            if opset < DEFAULT_OPSET else "")
    return ExportError(f"torch.onnx.export failed{what} at opset {opset}: {first or type(err).__name__}{hint} "
                       "(-v shows the exporter's whole error)")


def _torch_export(net: Any, args: tuple[Any, ...], path: Path, opset: int, *, split: bool = False,
                  tail: bool = False) -> None:
    """torch.onnx.export with rtp's names: ``input`` -> ``metric`` (``split``: and ``features``; ``tail``:
    ``features``, ``input`` -> ``metric``). The exporter's own log (the whole TorchScript graph when it
    fails, which torch 2.x writes to stdout, where ``rtp-export`` prints only the output's path) goes to
    this module's logger at DEBUG instead."""
    import torch

    def to_log(*parts: Any) -> None:
        log.debug("torch.onnx: %s", " ".join(str(p) for p in parts))

    hook = "_jit_onnx_log"  # (torch's setup_onnx_logging turns the log on for every export: a bug of torch 2.x)
    torch_log = getattr(torch._C, hook, None)
    if torch_log is not None:
        setattr(torch._C, hook, to_log)
    try:
        _export_quietly(net, args, path, opset, split=split, tail=tail)
    finally:
        if torch_log is not None:
            setattr(torch._C, hook, torch_log)


def _export_quietly(net: Any, args: tuple[Any, ...], path: Path, opset: int, *, split: bool, tail: bool) -> None:
    import torch

    from rtp import sdk

    with warnings.catch_warnings():
        # The TorchScript exporter is chosen on purpose (fast, no onnxscript dependency, the same
        # graph for this network); its deprecation notice is not addressed to our users.
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        # strided slices (a split network's stored block contrast) are not folded, and need not be: they read
        # the input, and merge_slices merges them
        warnings.filterwarnings("ignore", message="Constant folding - Only steps=1")
        tiles = {0: "batch", 2: "tiles_y", 3: "tiles_x"}
        torch.onnx.export(
            net,
            args,
            str(path),
            input_names=[sdk.FEATURES_NAME, INPUT_NAME] if tail else [INPUT_NAME],
            output_names=[OUTPUT_NAME, sdk.FEATURES_NAME] if split else [OUTPUT_NAME],
            dynamic_axes={
                INPUT_NAME: {0: "batch", 2: "height", 3: "width"},
                OUTPUT_NAME: tiles,
                **({sdk.FEATURES_NAME: tiles} if split or tail else {}),
            },
            opset_version=opset,
            do_constant_folding=True,
            dynamo=False,
        )


def _check_and_save(model: Any, path: Path) -> None:
    import onnx

    try:
        onnx.checker.check_model(model, full_check=True)
    except Exception as err:
        raise ExportError(f"the ONNX checker rejected the model: {err}") from err
    onnx.save(model, str(path))


def _torch_parity(path: Path, net: Any, meta: ModelMetadata) -> None:
    """Run the file through ``rtp.sdk.load`` and torch at two resolutions; fail past the tolerance."""
    import torch

    from rtp import sdk

    pred = sdk.load(path, providers=["CPUExecutionProvider"], metadata=None)
    gen = torch.Generator().manual_seed(1)
    for h, w in _parity_sizes(meta.tile_size, meta.input_multiple):
        x = torch.rand(2, len(meta.inputs), h, w, generator=gen)
        with torch.inference_mode():
            ref = net(x).numpy()
        got = pred.predict_raw(x.numpy())
        err = float(np.max(np.abs(got - ref)))
        if not err <= PARITY_TOLERANCE:
            raise ExportError(
                f"onnxruntime and torch disagree at {w}x{h}: max abs difference {err:.3g} > {PARITY_TOLERANCE}"
            )
        log.info("parity at %dx%d: max abs difference %.2g", w, h, err)
        if pred.splits:  # the trunk's features, and the tail on them and on another frame's
            with torch.inference_mode():
                feats = [net.trunk(x[i:i + 1]) for i in range(2)]
                want = [net.tail(feats[1], x[:1]).numpy()[0], feats[0].numpy()[0]]
            est, got_feats = pred.predict_split(x[0].numpy())
            carried = pred.predict_tail(np.ascontiguousarray(feats[1].numpy()[0]), x[0].numpy())
            for name, a, b in (("features", got_feats, want[1]), ("tail", carried, meta.decode(want[0])),
                               ("split", est, meta.decode(ref[0]))):
                err = float(np.max(np.abs(a - b)))
                if not err <= PARITY_TOLERANCE:
                    raise ExportError(f"onnxruntime and torch disagree on the {name} at {w}x{h}: max abs difference "
                                      f"{err:.3g} > {PARITY_TOLERANCE}")


def _dims(value_info: Any) -> list[int | str]:
    return [d.dim_value if d.HasField("dim_value") else d.dim_param for d in value_info.type.tensor_type.shape.dim]


#: The most bytes one serialized ONNX model (protobuf message) may hold: an adopted model keeps every
#: tensor inside its file, which its digest covers (``sdk.load`` refuses weights in external data).
PROTOBUF_LIMIT = 2**31 - 1
#: The operator domains onnxruntime implements (ONNX's, ONNX-ML's, its own contrib operators).
ONNXRUNTIME_DOMAINS = frozenset({"", "ai.onnx", "ai.onnx.ml", "com.microsoft"})
#: Where an adopted model's raw outputs (transformed space, 0 to 1: docs/metadata.md) may lie on adopt's check
#: frames; a model most of whose outputs lie outside predicts in another space (the metric's own units).
RAW_RANGE = (-0.5, 1.5)


def _size_inside(model: Any, path: Path) -> int:
    """The bytes ``model`` (read without its external data) holds once its tensors in external data files beside
    ``path`` are inside it: its own, and each such tensor's ``length`` (else its file's size past its ``offset``)."""
    import onnx
    from onnx.external_data_helper import ExternalDataInfo, uses_external_data

    tensors = list(model.graph.initializer)
    tensors += [a.t for n in model.graph.node for a in n.attribute if a.type == onnx.AttributeProto.TENSOR]
    size = model.ByteSize()
    for t in tensors:
        if uses_external_data(t):
            info = ExternalDataInfo(t)
            data = path.parent / info.location
            size += int(info.length) if info.length else max(data.stat().st_size - int(info.offset or 0), 0) \
                if data.is_file() else 0
    return size


def _as_adopted(err: RtpError, tmp: Path, name: str, source: str) -> RtpError:
    """``err`` (raised loading or running the adopted model's temporary file) of the same class and fields, its
    message naming the model by ``name`` and its metadata by ``source`` (the sidecar) instead of the temporary
    file, which is gone once adopt fails."""
    import copy

    text = str(err).replace(f"{str(tmp)!r}'s metadata", f"the metadata ({source})")
    text = text.replace(": the metadata is another model's, or was edited", ": the metadata does not describe this "
                        "model")
    text = text.replace(repr(str(tmp)), repr(name)).replace(str(tmp), name)
    new = copy.copy(err)
    new.args = (text,)
    return new


def adopt(
    foreign: str | os.PathLike[str],
    metadata: Mapping[str, Any] | str | os.PathLike[str] | None,
    output: str | os.PathLike[str],
    *,
    dynamic: bool = False,
    replace: bool = False,
) -> Path:
    """Bake rtp metadata into an ONNX model that has none (e.g. the paper's published models).

    Checks that the model has one float input ``(N, C, H, W)`` with C = len(inputs) and one output
    ``(N, R, H/w, W/w)`` with R = len(outputs) wherever the dims are fixed. With ``dynamic`` the
    batch, height and width become symbolic so any frame size runs (verified at a second size). The result is
    loaded and run on random frames and a frame of zeros: non-finite outputs, outputs mostly outside
    :data:`RAW_RANGE` (not the transformed metric), a channels-last input, another tile size, operators onnxruntime
    lacks and a model of more than 2 GB with its external data are refused, nothing written (docs/export.md).

    ``metadata`` (a sidecar path or a mapping) may be None for the paper's published models
    (:func:`published_models`): the file is recognised by its SHA-256 and gets the sidecar rtp ships
    for it. The adopted model's ``provenance.adopted`` records the source file's name and SHA-256,
    where it was published (for a recognised file) and where its metadata came from.
    """
    import onnx

    from rtp import sdk

    src = _path(foreign, "foreign")
    if not src.is_file():
        raise ModelNotFoundError(f"no ONNX model at {str(src)!r}")
    out = _output(src, output)
    try:
        size = _size_inside(onnx.load(str(src), load_external_data=False), src)
        if size > PROTOBUF_LIMIT:  # (write_metadata's digest and the save failed on it in protobuf's own words)
            raise ModelLoadError(
                f"{src}: the model holds {size / 1e9:.2f} GB with its weights in external data, more than one ONNX "
                f"file can hold ({PROTOBUF_LIMIT / 1e9:.2f} GB, protobuf's limit); an adopted model keeps every tensor "
                "inside its file, which its digest covers (sdk.load refuses weights in external data): adopt a "
                "smaller model")
        model = onnx.load(str(src))
    except ModelLoadError:
        raise
    except Exception as err:
        raise ModelLoadError(f"{src}: not a readable ONNX model ({err})") from err
    known = identify(src)
    carries = any(p.key == METADATA_KEY for p in model.metadata_props)
    if metadata is None and known is None and carries:
        raise MetadataError(
            f"{src} already carries rtp metadata ({METADATA_KEY}): load it as it is (sdk.load), or pass a sidecar "
            "(--metadata SIDECAR.yaml) with --replace to replace it", METADATA_KEY
        )
    if metadata is None:
        if known is None:
            raise MetadataError(
                f"{src}: metadata is required: the file is not one of the paper's published models rtp "
                f"recognises (its SHA-256 is {file_sha256(src)[:16]}...); pass a sidecar (metadata=, or "
                "--metadata SIDECAR.yaml on the command line)"
            )
        d, source = dict(known.metadata), "rtp's sidecar for this published model (rtp/export/published.yaml)"
    elif isinstance(metadata, (str, os.PathLike)):
        d, source = _read_yaml(metadata), str(metadata)
        if not d:
            raise MetadataError(f"{metadata}: the sidecar is empty; it gives the model's metadata (metric, transform, "
                                "inputs, outputs, tile_size, ...: docs/metadata.md)")
    else:
        d, source = _fields(metadata, "metadata"), "given as a mapping"
    adopted: dict[str, Any] = {"file": src.name, "sha256": file_sha256(src), "metadata": source,
                               "rtp": str(sdk.__version__),
                               "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()}
    if known is not None:
        adopted["published"] = known.origin
        log.info("%s is the paper's published %s model (%s, %s)", src.name, known.name, known.repository, known.path)
    given = d.get("provenance")
    if given is not None and not isinstance(given, Mapping):
        # (replaced by rtp's own entry: a sidecar's `provenance: trained on ...` was dropped without a word)
        raise MetadataError(f"{source}: provenance: expected a mapping (rtp adds provenance.adopted to it), got "
                            f"{reprlib.repr(given)}", "provenance")
    d["provenance"] = _merge(dict(given or {}), {"adopted": adopted})
    try:
        meta = ModelMetadata.from_dict(d)
    except MetadataError as err:  # (the field's key kept, as export and retune keep it: it was None here)
        raise MetadataError(f"{source}: {err}", err.key) from err
    if carries and not replace:
        raise MetadataError(
            f"{src} already carries {METADATA_KEY}; pass --replace to overwrite it", METADATA_KEY
        )
    graph = model.graph
    inputs = _plane_inputs(graph)
    if len(inputs) != 1 or len(graph.output) != 1:
        raise MetadataError(
            f"{src}: expected one input and one output, found inputs {[i.name for i in inputs]} and outputs "
            f"{[o.name for o in graph.output]}"
        )
    i, o = inputs[0], graph.output[0]
    di, do = _dims(i), _dims(o)
    if i.type.tensor_type.elem_type != onnx.TensorProto.FLOAT or len(di) != 4 or len(do) != 4:
        raise MetadataError(f"{src}: expected a float32 (N, C, H, W) input and a rank-4 output, got {di} and {do}")
    c = len(meta.inputs)
    if di[3] == c and di[1] != c:
        # (channels last: the planes fed as (N, C, H, W) reached the graph as N x C rows x H columns x W planes)
        raise MetadataError(
            f"{src}: the model input {i.name!r} {di} is channels-last (N, H, W, C) with its {c} planes last; rtp "
            f"feeds (N, C, H, W), the {c} planes of the sidecar's inputs {list(meta.inputs)} second: export the "
            "model channels-first (without the input's transpose to NHWC)", "inputs")
    if isinstance(di[1], int) and di[1] != len(meta.inputs):
        raise MetadataError(
            f"inputs: the sidecar lists {len(meta.inputs)} channels {list(meta.inputs)}, the model input "
            f"{i.name!r} {di} has {di[1]}",
            "inputs",
        )
    if isinstance(do[1], int) and do[1] != len(meta.outputs):
        raise MetadataError(
            f"outputs: the sidecar lists {len(meta.outputs)} rates {list(meta.outputs)}, the model output "
            f"{o.name!r} {do} has {do[1]} channels",
            "outputs",
        )
    t = meta.tile_size
    if all(isinstance(v, int) and v > 0 for v in (di[2], di[3], do[2], do[3])):
        # (as the SDK reads the output: every tile, a partial last one included; the floor refused a model that
        # predicts its partial tiles and passed one that drops them, which every predict then failed on)
        grid = sdk.tile_grid(int(di[2]), int(di[3]), t)
        if (do[2], do[3]) != grid:
            raise MetadataError(
                f"tile_size: the sidecar says {t}, but the model maps {di[3]}x{di[2]} to {do[3]}x{do[2]} tiles, "
                f"expected {grid[1]}x{grid[0]}" + (" (its partial last tiles included)" if di[2] % t or di[3] % t
                                                   else ""),
                "tile_size",
            )
    static_hw = (di[2], di[3]) if isinstance(di[2], int) and isinstance(di[3], int) and di[2] > 0 else None
    if dynamic:
        for vi, names in ((i, ("batch", None, "height", "width")), (o, ("batch", None, "tiles_y", "tiles_x"))):
            for dim, name in zip(vi.type.tensor_type.shape.dim, names):
                if name is not None:
                    dim.Clear()
                    dim.dim_param = name
        del graph.value_info[:]  # intermediate shapes were inferred for the fixed size
    write_metadata(model, meta)
    with atomic_output(out) as tmp:
        _check_and_save(model, tmp)
        try:
            pred = sdk.load(tmp, providers=["CPUExecutionProvider"])
        except RtpError as err:  # (its message named the temporary file, gone by the time the user read it)
            new = _as_adopted(err, tmp, str(src), source)
            custom = sorted({f"{n.domain}:{n.op_type}" for n in graph.node if n.domain not in ONNXRUNTIME_DOMAINS})
            if isinstance(err, ModelLoadError) and custom:
                new.args = (f"{new}; the model uses operators onnxruntime does not implement ({', '.join(custom)}), and "
                            "rtp runs a model on onnxruntime's own: export it with standard ONNX operators",)
            raise new from err
        fixed = static_hw is not None and not dynamic  # (frames padded up to its one size)
        sizes = [static_hw] if static_hw is not None and fixed else [(t * 8, t * 12), (t * 5, t * 9)]
        if dynamic and static_hw:
            sizes.append(static_hw)
        m = meta.input_multiple
        partial = None if fixed or m is None or m >= t else (t * 5 + m, t * 9 + t - m)
        if partial is not None:  # the frames of partial tiles the sidecar says it takes (run as they are, not padded)
            sizes.append(partial)
        rng = np.random.default_rng(0)
        # random frames, and a blank one (black, unseen, no normals: a frame of background), on which a model that
        # divides by its input's statistics was adopted and then predicted NaN for every such frame
        frames = [(f"a random frame at {w}x{h}", rng.random((1, len(meta.inputs), h, w), dtype=np.float32))
                  for h, w in sizes]
        frames.append((f"a frame of zeros at {sizes[0][1]}x{sizes[0][0]}",
                       np.zeros((1, len(meta.inputs), *sizes[0]), np.float32)))
        raws = []
        for what, x in frames:
            h, w = x.shape[-2:]
            try:
                raw = pred.predict_raw(x)
                y = meta.decode(raw)
            except RtpError as err:
                if (h, w) == partial:  # (adopted, it failed every predict of such a frame: 1920x1080 with tile 16)
                    raise MetadataError(
                        f"input_multiple: the metadata ({source}) says the model takes frames of multiples of {m} "
                        f"pixels, partial {t}-pixel tiles included, but it does not run at {w}x{h}: {err}; leave "
                        "input_multiple out (frames padded to whole tiles)", "input_multiple") from err
                raise ExportError(f"the adopted model does not run at {w}x{h} (fed float32 (N, C, H, W) planes, C = "
                                  f"{len(meta.inputs)}): {err}") from err
            if not np.all(np.isfinite(raw)) or not np.all(np.isfinite(y)):
                raise ExportError(f"the adopted model produced non-finite predictions on {what}: a model rtp runs "
                                  "must predict a finite value for every frame of finite planes")
            raws.append(raw.ravel())
        values = np.concatenate(raws)
        lo, hi = RAW_RANGE
        outside = float(np.mean((values < lo) | (values > hi)))
        if outside > 0.5:
            raise MetadataError(
                f"transform: the metadata ({source}) says the model outputs its metric transformed ({meta.transform.type}), "
                f"in 0 to 1 (docs/metadata.md, \"Transforms\"), but {outside:.0%} of its outputs on adopt's check frames "
                f"lie outside {lo} to {hi} ({float(values.min()):.4g} to {float(values.max()):.4g}): it predicts in "
                "other units (the metric's own?); give the transform that maps the metric to what the network outputs, "
                "or add to the graph the operators that do", "transform")
    log.info("adopted %s -> %s", src, out)
    return out


def restamp(model_path: str | os.PathLike[str]) -> Path:
    """Bring an rtp model exported by an older rtp up to this one's format: rewrite its metadata
    through :func:`write_metadata` so that it records the digest of the graph and weights (models
    exported before rtp wrote digests), give it the finite probe (:func:`add_finite_probe`) where
    its first layer allows one, and its planes in the groups :func:`split_input_planes` gives them
    today (a model in groups is joined first). The weights, the metric output and every other metadata field stay as
    they are; the file is replaced atomically and loaded back to check that it predicts as before
    (exactly, or within float rounding where the planes were split)."""
    import onnx

    from rtp import sdk

    path = _path(model_path, "model_path")
    if not path.is_file():
        shipped = f"{path.name}.onnx" if path.suffix != ".onnx" else path.name
        hint = (" (a shipped model's name: the models that ship are this rtp's format already; restamp rewrites a "
                "file of your own in place)" if shipped in sdk.shipped_models() and path.parent == Path(".") else "")
        raise ModelNotFoundError(f"no model file at {str(path)!r}{hint}")
    before = sdk.load(path, providers=["CPUExecutionProvider"])
    try:
        model = onnx.load(str(path))
    except Exception as err:  # onnx raises DecodeError and friends
        raise ModelLoadError(f"{str(path)!r} is not an ONNX model onnx can read: {err}") from err
    meta = before.metadata
    grouped = _join_groups(model) > 1  # one input again, then the groups of today's rules
    if meta.finite_probe is None:
        meta = dataclasses.replace(meta, finite_probe=add_finite_probe(model, meta.pad_multiple))
    split = split_input_planes(model) > 1
    write_metadata(model, meta)
    _save_unchanged(model, before, path, f"restamping {path} changed its predictions; the file is left as it was",
                    reassociated=split or grouped)
    return path
