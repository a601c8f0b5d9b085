"""Malformed inputs for the runtime and the dataset reader, shared by tests/test_fuzz.py (a few
thousand in CI) and bench/fuzz.py (tens of thousands, with a table).

Each :class:`Target` has a hypothesis strategy of hostile inputs, a ``call`` that feeds one to rtp,
and an ``absurd`` predicate naming the inputs that must be refused. Running an input ends in one of:

* ``typed``: an :class:`rtp.sdk.RtpError` (what every refusal must be);
* ``accepted``: no error, and the input is not absurd;
* ``absurd accepted``: no error although ``absurd`` says it should have been refused;
* ``untyped``: any other exception: a bug.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import strategies as st

from rtp import sdk
from rtp.capture import BUFFERS, DatasetReader, DatasetWriter

__all__ = ["OUTCOMES", "Target", "classify", "targets"]

OUTCOMES = ("typed", "accepted", "absurd accepted", "untyped")


@dataclass(frozen=True)
class Target:
    name: str
    strategy: st.SearchStrategy[Any]
    call: Callable[[Any], Any]
    absurd: Callable[[Any], bool] = lambda _: False


def classify(target: Target, value: Any) -> tuple[str, BaseException | None]:
    try:
        target.call(value)
    except sdk.RtpError as err:
        return "typed", err
    except Exception as err:  # noqa: BLE001 - the point: anything else is an untyped escape
        return "untyped", err
    return ("absurd accepted" if target.absurd(value) else "accepted"), None


# -- shared building blocks ---------------------------------------------------------------------

_WORK = Path(tempfile.mkdtemp(prefix="rtp-fuzz-"))
_MODEL = Path(sdk.load("jnyang").path)
_MODEL_BYTES = _MODEL.read_bytes()
_PRED = sdk.load(_MODEL)
_X = np.random.default_rng(0).random((4, 32, 48), dtype=np.float32)

json_scalars = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
)
json_values = st.recursive(json_scalars, lambda c: st.one_of(st.lists(c, max_size=4),
                                                              st.dictionaries(st.text(max_size=8), c, max_size=4)),
                           max_leaves=12)
hostile_numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([1e308, -1e308, 1e-320, -0.0, 0.0, -1.0, 1e6, 101.0]),
    st.integers(min_value=-(2**80), max_value=2**80), st.text(max_size=5), st.none(), st.booleans(),
    st.lists(st.floats(), max_size=3), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)

_VALID = {
    "metric": "jnyang", "transform": {"type": "clamped", "mu_y": 0.25}, "tile_size": 16,
    "inputs": ["reprojected.r", "seen", "albedo.r", "normal.z"], "outputs": ["1x2", "2x1", "2x4", "4x2"],
    "default_threshold": 0.25, "weber_l": 0.02, "safety": 0.05,
}
_FIELDS = ("metric", "higher_is_better", "transform", "safety", "tile_size", "inputs", "outputs", "extrapolation_k",
           "default_threshold", "weber_l", "description", "provenance", "schema_version", "digest")


def _bad_metadata_value(meta: sdk.ModelMetadata) -> bool:
    """An accepted metadata that makes no sense: the checks every accepted value must pass."""
    t = meta.transform
    params = [v for v in (t.mu_y, t.k, t.factor, t.offset) if v is not None]
    return bool(
        not math.isfinite(meta.default_threshold) or (not meta.higher_is_better and meta.default_threshold < 0)
        or not 0.0 <= meta.safety <= 1.0 or not 1.0 <= meta.extrapolation_k <= 100.0
        or not all(math.isfinite(v) and abs(v) <= 1e6 for v in params)
        or not np.isfinite(meta.saturation)
    )


_accepted_meta: dict[int, sdk.ModelMetadata] = {}


def _metadata_call(d: Any) -> None:
    meta = sdk.ModelMetadata.from_dict(d)
    _accepted_meta[id(d)] = meta
    # an accepted metadata must decode a network output to finite values for every rate
    out = meta.decode(np.full((len(meta.outputs), 1, 1), 0.5, np.float32))
    if not np.isfinite(out).all():
        raise AssertionError(f"accepted metadata decodes to non-finite values: {d}")


def _metadata_absurd(d: Any) -> bool:
    meta = _accepted_meta.pop(id(d), None)
    return meta is not None and _bad_metadata_value(meta)


metadata_dicts = st.one_of(
    st.fixed_dictionaries({}, optional={k: json_values for k in _FIELDS}),
    st.builds(lambda k, v: {**_VALID, k: v}, st.sampled_from(_FIELDS), st.one_of(json_values, hostile_numbers)),
    st.builds(lambda k, v: {**_VALID, "transform": {**_VALID["transform"], k: v}},
              st.sampled_from(["type", "mu_y", "k", "factor", "offset"]), st.one_of(json_values, hostile_numbers)),
    json_values,
)


# -- model files ----------------------------------------------------------------------------

def _mutate_model(mutation: tuple[str, int, int, bytes]) -> bytes:
    kind, pos, bit, junk = mutation
    data = bytearray(_MODEL_BYTES)
    pos %= len(data)
    if kind == "flip":
        data[pos] ^= 1 << (bit % 8)
    elif kind == "truncate":
        del data[pos:]
    elif kind == "overwrite":
        data[pos:pos + len(junk)] = junk
    elif kind == "insert":
        data[pos:pos] = junk
    return bytes(data)


def _load_bytes(data: bytes) -> None:
    path = _WORK / f"m{os.getpid()}.onnx"
    path.write_bytes(data)
    pred = sdk.load(path)
    pred.shading_rates(_X)


model_mutations = st.tuples(st.sampled_from(["flip", "truncate", "overwrite", "insert"]), st.integers(0, 2**31),
                            st.integers(0, 7), st.binary(min_size=1, max_size=16))


def _hostile_json_model(text: str) -> None:
    import onnx

    model = onnx.load_from_string(_MODEL_BYTES)
    onnx.helper.set_model_props(model, {sdk.METADATA_KEY: text})
    _load_bytes(model.SerializeToString())


# -- sidecars -------------------------------------------------------------------------------

_PWNED = _WORK / "pwned"
yaml_texts = st.one_of(
    st.text(max_size=200),
    st.builds(lambda v: json.dumps(v, default=str), json_values),
    st.sampled_from([
        f"!!python/object/apply:os.system ['touch {_PWNED}']",
        f"metric: !!python/object/apply:pathlib.Path.touch [!!python/object/apply:pathlib.Path ['{_PWNED}']]",
        "a: &a [*a]", "[" * 5000, "metric: jnyang\ntile_size: 16\ninputs: [1, 2]", "\udcff", "!!binary AAAA",
        "default_threshold: .nan", "safety: 1e308", "extrapolation_k: .inf",
    ]),
)


def _sidecar(text: str) -> None:
    path = _WORK / f"s{os.getpid()}.yaml"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    try:
        sdk.ModelMetadata.from_yaml(path)
    finally:
        if _PWNED.exists():
            raise AssertionError("a YAML sidecar executed code")


# -- arrays and thresholds --------------------------------------------------------------------

def _array(spec: tuple[str, tuple[int, ...], str]) -> Any:
    kind, shape, fill = spec
    if kind == "list":
        return np.zeros(shape[:3]).tolist()
    if kind == "object":
        return np.empty(shape[:2], dtype=object)
    a = np.zeros(shape, dtype=kind)
    if a.size == 0:
        return a
    if fill == "nan" and a.dtype.kind == "f":
        a.flat[0] = np.nan
    elif fill == "inf" and a.dtype.kind == "f":
        a.flat[-1] = -np.inf
    elif fill == "random" and a.dtype.kind == "f":
        a[...] = np.random.default_rng(a.size).random(shape)
    return a


arrays = st.tuples(
    st.sampled_from(["float32", "float64", "float16", "int32", "uint8", "bool", "list", "object"]),
    st.lists(st.integers(0, 40), min_size=0, max_size=5).map(tuple).filter(lambda s: int(np.prod(s)) <= 200_000),
    st.sampled_from(["zero", "nan", "inf", "random"]),
)
thresholds = st.one_of(hostile_numbers, st.just(None), st.floats(-10, 10), st.text(max_size=3))


def _threshold_absurd(t: Any) -> bool:
    if t is None:
        return False
    try:
        v = float(t)
    except (TypeError, ValueError):
        return True
    return isinstance(t, (bool, str)) or not math.isfinite(v) or v < 0


allowed_values = st.one_of(st.none(), json_values, st.lists(st.one_of(st.integers(-3, 20), st.text(max_size=4)),
                                                            max_size=4))


# -- the dataset reader ---------------------------------------------------------------------

def _dataset() -> Path:
    root = _WORK / "ds"
    if not (root / "manifest.json").exists():
        w = DatasetWriter(root, settings={"size": [40, 24]})
        rng = np.random.default_rng(0)
        bufs = {n: rng.random((24, 40, len(s.channels) or 3) if (len(s.channels) or 3) > 1 else (24, 40),
                              dtype=np.float32) for n, s in BUFFERS.items()}
        w.write("s0", bufs, {"scene": "a"})
        w.finalize()
    return root


def _read_mutated_dataset(mutation: tuple[str, int, bytes]) -> None:
    import shutil

    which, pos, junk = mutation
    src = _dataset()
    dst = _WORK / f"ds{os.getpid()}"
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(src, dst)
    files = sorted(p for p in dst.rglob("*") if p.is_file())
    target = files[{"manifest": 0, "sample": -1}[which] if which in ("manifest", "sample") else pos % len(files)]
    if which == "member":  # a well-formed archive whose members are junk
        with zipfile.ZipFile(target, "w") as z:
            z.writestr("meta.npy", junk)
            z.writestr("final_1x1.npy", junk)
    else:
        data = bytearray(target.read_bytes())
        p = pos % max(len(data), 1)
        data[p:p + len(junk)] = junk
        target.write_bytes(bytes(data))
    reader = DatasetReader(dst)
    for sid in reader.ids:
        s = reader[sid]
        s.inputs(sdk.DEFAULT_INPUTS)
        s.final("1x1")


dataset_mutations = st.tuples(st.sampled_from(["manifest", "sample", "member", "any"]), st.integers(0, 2**20),
                              st.binary(min_size=1, max_size=64))


def targets() -> list[Target]:
    return [
        Target("load: corrupted model files", model_mutations, lambda m: _load_bytes(_mutate_model(m))),
        Target("load: hostile metadata JSON", st.one_of(st.text(max_size=300),
                                                        st.builds(lambda v: json.dumps(v), metadata_dicts)),
               _hostile_json_model),
        Target("ModelMetadata.from_dict", metadata_dicts, _metadata_call, _metadata_absurd),
        Target("ModelMetadata.from_yaml (sidecars)", yaml_texts, _sidecar),
        Target("Transform.from_dict", st.one_of(json_values, metadata_dicts.map(lambda d: d.get("transform")
                                                                                if isinstance(d, dict) else d)),
               lambda d: sdk.Transform.from_dict(d)),
        Target("predict: arrays", arrays, lambda spec: _PRED.predict(_array(spec))),
        Target("shading_rates: thresholds", thresholds, lambda t: _PRED.shading_rates(_X, threshold=t),
               _threshold_absurd),
        Target("shading_rates: allowed rates", allowed_values, lambda a: _PRED.shading_rates(_X, allowed=a)),
        Target("select_rates / work_saved", st.tuples(arrays, thresholds),
               lambda v: (sdk.select_rates(_array(v[0]), v[1]), sdk.work_saved(_array(v[0]))),
               lambda v: _threshold_absurd(v[1]) and v[1] is not None),
        Target("draw_rate_overlay", st.tuples(arrays, arrays, st.one_of(st.integers(-2, 40), hostile_numbers)),
               lambda v: sdk.draw_rate_overlay(_array(v[0]), _array(v[1]), v[2])),
        Target("dataset reader: corrupted files", dataset_mutations, _read_mutated_dataset),
    ]
