"""Malformed inputs for the runtime and the dataset reader, shared by tests/test_fuzz.py (a few
thousand in CI) and bench/fuzz.py (tens of thousands, with a table).

Each :class:`Target` has a hypothesis strategy of hostile inputs, a ``call`` that feeds one to rtp and
returns what rtp returned, and an ``absurd`` predicate that looks at an *accepted* input and its
result and says whether accepting it made no sense. Running an input ends in one of:

* ``typed``: an :class:`rtp.sdk.RtpError` (what every refusal must be);
* ``accepted``: no error, and the input and its result make sense;
* ``absurd accepted``: no error although the input is absurd (a value outside its documented range,
  an array that is not what the function takes) or the result is (non-finite, silently changed);
* ``untyped``: any other exception: a bug.

The ``absurd`` predicates state the documented ranges (docs/metadata.md, the fields table and the
paragraph after it) and check results independently of the validation code where they can (a decoded prediction must be finite and
not constant, a bit flip that is accepted must leave the network's output bit-identical).
"""

from __future__ import annotations

import io
import json
import math
import os
import shutil
import signal
import tempfile
import threading
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import strategies as st

from rtp import sdk
from rtp.capture import BUFFERS, DatasetReader, DatasetWriter, open_dataset

__all__ = ["OUTCOMES", "Target", "classify", "targets"]

OUTCOMES = ("typed", "accepted", "absurd accepted", "untyped")

#: The documented ranges (docs/metadata.md), restated here so that the fuzz checks the code against them.
MAX_THRESHOLD = 1e6
MAX_PARAMETER, MIN_PARAMETER = 1e6, 1e-6
MAX_K = 100.0


def _never(_value: Any, _result: Any) -> bool:
    return False


@dataclass(frozen=True)
class Target:
    name: str
    strategy: st.SearchStrategy[Any]
    call: Callable[[Any], Any]
    absurd: Callable[[Any, Any], bool] = _never


def classify(target: Target, value: Any) -> tuple[str, BaseException | None]:
    try:
        result = target.call(value)
    except sdk.RtpError as err:
        return "typed", err
    except Exception as err:  # noqa: BLE001 - the point: anything else is an untyped escape
        return "untyped", err
    return ("absurd accepted" if target.absurd(value, result) else "accepted"), None


# -- shared building blocks ---------------------------------------------------------------------

def scratch_folder(prefix: str) -> Path:
    """A temporary folder for a fuzz module's files, removed when the process ends."""
    import atexit

    folder = Path(tempfile.mkdtemp(prefix=prefix))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    return folder


_WORK = scratch_folder("rtp-fuzz-")  # (a plain mkdtemp before: one folder left in /tmp per process that imported this)
_MODEL = Path(sdk.load("jnyang").path or "")
_MODEL_BYTES = _MODEL.read_bytes()
_PRED = sdk.load(_MODEL)
_X = np.random.default_rng(0).random((len(_PRED.metadata.inputs), 32, 48), dtype=np.float32)
_RAW = _PRED.predict_raw(_X)

json_scalars = st.one_of(
    st.none(), st.booleans(), st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
)


def _json_containers(c: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    # a def, not a lambda over two lines: hypothesis reads a lambda's source to check it recurses, and
    # warned (HypothesisDeprecationWarning, "doesn't use it's argument") on the wrapped one
    return st.one_of(st.lists(c, max_size=4), st.dictionaries(st.text(max_size=8), c, max_size=4))


json_values = st.recursive(json_scalars, _json_containers, max_leaves=12)
hostile_numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e308, -1e308, 1e-320, -1e-320, -0.0, 0.0, -1.0, 1e6, 1e6 + 1, -1e6 - 1, 1e-6, 1e-7, 101.0,
                     100.0, 1.0, 0.999, 10**400, -(10**400)]),
    st.integers(min_value=-(2**80), max_value=2**80), st.text(max_size=5), st.none(), st.booleans(),
    st.lists(st.floats(), max_size=3), st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
    st.builds(np.float32, st.floats(width=32)), st.builds(np.int64, st.integers(-(2**63), 2**63 - 1)),
)


def _finite_number(v: Any) -> float | None:
    """``v`` as a float when it is a real number (not bool) and finite, else None."""
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        return None
    try:
        f = float(v)
    except OverflowError:
        return None
    return f if math.isfinite(f) else None


# -- metadata ----------------------------------------------------------------------------------

_VALID = {
    "metric": "jnyang", "transform": {"type": "clamped", "mu_y": 0.25}, "tile_size": 16,
    "inputs": ["reprojected.r", "seen", "albedo.r", "normal.z"], "outputs": ["1x2", "2x1", "2x4", "4x2"],
    "default_threshold": 0.25, "weber_l": 0.02, "safety": 0.05,
}
_FIELDS = ("metric", "higher_is_better", "transform", "safety", "tile_size", "inputs", "outputs", "extrapolation_k",
           "default_threshold", "weber_l", "description", "provenance", "schema_version", "digest", "input_multiple",
           "finite_probe")
_TRANSFORMS = {"clamped": {"mu_y": 0.25}, "logistic": {"mu_y": 0.25, "k": 10.0}, "linear": {"factor": 0.7, "offset": 0.0}}

transforms = st.one_of(
    # a valid transform of each type with one parameter replaced by a hostile number
    st.builds(lambda kind, i, v: {"type": kind, **{**_TRANSFORMS[kind], list(_TRANSFORMS[kind])[i % len(_TRANSFORMS[kind])]: v}},
              st.sampled_from(list(_TRANSFORMS)), st.integers(0, 1), hostile_numbers),
    # every parameter drawn, including ones far apart (a flat logistic, a tiny factor)
    st.builds(lambda kind, a, b: {"type": kind, **dict(zip(_TRANSFORMS[kind], (a, b), strict=False))},
              st.sampled_from(list(_TRANSFORMS)), st.floats(-1e7, 1e7) | st.floats(-1e-5, 1e-5), st.floats(-1e7, 1e7)),
    st.builds(lambda k, v: {**_TRANSFORMS["clamped"], "type": "clamped", k: v},
              st.sampled_from(["type", "mu_y", "k", "factor", "offset", "extra"]), json_values),
    json_values,
)

metadata_dicts = st.one_of(
    st.fixed_dictionaries({}, optional={k: json_values for k in _FIELDS}),
    st.builds(lambda k, v: {**_VALID, k: v}, st.sampled_from(_FIELDS), st.one_of(json_values, hostile_numbers)),
    st.builds(lambda t: {**_VALID, "transform": t}, transforms),
    st.builds(lambda m, t, thr: {**_VALID, "metric": m, "weber_l": 0.02, "transform": t, "default_threshold": thr},
              st.sampled_from(["psnr", "flip", "jnflip", "lpips", "yang", "jnyang"]),
              st.sampled_from([{"type": "linear", "factor": -0.015, "offset": 1.0}, {"type": "clamped", "mu_y": 0.2}]),
              hostile_numbers),
    st.builds(lambda k, v: {**_VALID, k: v}, st.integers() | st.none() | st.tuples(st.integers()), st.integers()),
    json_values,
)


def _transform_absurd(t: sdk.Transform) -> bool:
    """An accepted transform must have parameters in range and decode network outputs 0, 0.5 and 1 to
    finite, distinct values (a flat one would decode every prediction to the same error)."""
    params = {"mu_y": t.mu_y, "k": t.k, "factor": t.factor}
    if any(v is not None and not MIN_PARAMETER <= abs(v) <= MAX_PARAMETER for v in params.values()):
        return True
    if t.offset is not None and not abs(t.offset) <= MAX_PARAMETER:
        return True
    if (t.mu_y is not None and t.mu_y <= 0) or (t.k is not None and t.k <= 0):
        return True
    y = t.inverse(np.array([0.0, 0.5, 1.0])).astype(np.float32)
    return bool(not np.isfinite(y).all() or y[0] == y[2])


def _metadata_absurd(_d: Any, meta: sdk.ModelMetadata) -> bool:
    thr = meta.default_threshold
    return bool(
        not math.isfinite(thr) or abs(thr) > MAX_THRESHOLD or (not meta.higher_is_better and thr < 0)
        or not 0.0 <= meta.safety <= 1.0 or not 1.0 <= meta.extrapolation_k <= MAX_K
        or _transform_absurd(meta.transform)
        or not np.isfinite(meta.saturation)
        or not np.isfinite(meta.decode(np.full((len(meta.outputs), 2, 2), 0.5, np.float32))).all()
        or meta.tile_size not in sdk.TILE_SIZES
    )


def _json_texts() -> st.SearchStrategy[Any]:
    return st.one_of(
        st.builds(lambda d: json.dumps(d, default=str, skipkeys=True), metadata_dicts),
        st.text(max_size=300),
        st.binary(max_size=64),
        st.builds(lambda n: "[" * n + "]" * n, st.integers(1, 100_000)),
        st.builds(lambda n: '{"metric": "jnyang", "safety": 1' + "0" * n + "}", st.integers(300, 5000)),
        st.builds(lambda d, i, b: _flip_text(json.dumps(d), i, b), st.just(_VALID), st.integers(0, 10_000),
                  st.integers(0, 7)),
        st.sampled_from(["", "null", "NaN", '{"safety": NaN}', '{"safety": Infinity}', "\ud800", "\x00"]),
        json_values,
    )


def _flip_text(text: str, pos: int, bit: int) -> str:
    data = bytearray(text.encode())
    data[pos % len(data)] ^= 1 << bit
    return data.decode("utf-8", "surrogateescape")


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


def _load_bytes(data: bytes) -> np.ndarray:
    path = _WORK / f"m{os.getpid()}.onnx"
    path.write_bytes(data)
    pred = sdk.load(path)
    pred.shading_rates(_X)
    return pred.predict_raw(_X)


def _silently_changed(_m: Any, raw: np.ndarray) -> bool:
    """A corrupted file that loads must compute exactly what the original computes: the digest covers
    the graph and the weights, so a change there must have been refused."""
    return raw.shape != _RAW.shape or not np.array_equal(raw, _RAW)


model_mutations = st.tuples(st.sampled_from(["flip", "flip", "truncate", "overwrite", "insert"]),
                            st.integers(0, 2**31), st.integers(0, 7), st.binary(min_size=1, max_size=16))


def _hostile_json_model(text: Any) -> None:
    import onnx

    model = onnx.load_from_string(_MODEL_BYTES)
    value = text if isinstance(text, str) else json.dumps(text, default=str, skipkeys=True)
    # protobuf strings are UTF-8: lone surrogates become "?" here (corrupted bytes are the other target's)
    onnx.helper.set_model_props(model, {sdk.METADATA_KEY: value.encode("utf-8", "replace").decode("utf-8")})
    _load_bytes(model.SerializeToString())


_load_args = st.fixed_dictionaries({
    "path": st.one_of(st.just(str(_MODEL)), st.just("jnyang"), st.sampled_from(["", ".", "/", "a" * 5000, "a\0b",
                                                                                  "/dev/null", str(_WORK)]),
                      st.text(max_size=20), st.integers(), st.none(), st.binary(max_size=8), st.lists(st.text(), max_size=2)),
    # Counts load accepts stay small: a session built with thousands of threads (any count up to 4096 is
    # valid) spins them all on the cores, and starved the other pytest worker's calls past HANG_S.
    "threads": st.one_of(st.none(), st.integers(-(2**70), -1), st.integers(0, 3), st.integers(4097, 2**70),
                         st.sampled_from([-1, 4097, 2**31, 2**63]), st.floats(), st.text(max_size=3), st.booleans()),
    "providers": st.one_of(st.none(), st.just(["CPUExecutionProvider"]), st.integers(), st.text(max_size=5),
                           st.lists(st.one_of(st.text(max_size=5), st.integers(), st.tuples(st.text(max_size=5), st.integers())),
                                    max_size=3)),
    "metadata": st.one_of(st.none(), st.just(dict(_VALID)), metadata_dicts, st.integers(), st.text(max_size=10)),
})


def _load_call(kw: dict[str, Any]) -> sdk.ShadingRatePredictor:
    return sdk.load(**kw)


def _load_args_absurd(kw: dict[str, Any], pred: sdk.ShadingRatePredictor) -> bool:
    """Loading succeeded: with a thread count in [0, 4096] and a model file that exists."""
    t = kw["threads"]
    threads_ok = t is None or (isinstance(t, int) and not isinstance(t, bool) and 0 <= t <= 4096)
    return not threads_ok or pred.path is None or not pred.path.is_file() or not pred.provider


# -- sidecars -------------------------------------------------------------------------------

_PWNED = _WORK / "pwned"
yaml_texts = st.one_of(
    st.text(max_size=200),
    st.builds(lambda v: json.dumps(v, default=str, skipkeys=True), json_values),
    st.builds(lambda d: "\n".join(f"{k}: {json.dumps(v, default=str, skipkeys=True)}" for k, v in d.items()),
              metadata_dicts.filter(lambda d: isinstance(d, dict))),
    st.sampled_from([
        f"!!python/object/apply:os.system ['touch {_PWNED}']",
        f"metric: !!python/object/apply:pathlib.Path.touch [!!python/object/apply:pathlib.Path ['{_PWNED}']]",
        f"!!python/object/new:subprocess.Popen [['touch', '{_PWNED}']]",
        "a: &a [*a]", "[" * 5000, "metric: jnyang\ntile_size: 16\ninputs: [1, 2]", "\udcff", "!!binary AAAA",
        "default_threshold: .nan", "safety: 1e308", "extrapolation_k: .inf", "1: 2\na: 3", "? [a, b]\n: 1",
        "provenance: !!set {a, b}", "description: 2001-12-14", "tile_size: 0x10", "safety: 1" + "0" * 400,
        "a: &a {b: *a}\nprovenance: *a",
    ]),
)


def _sidecar(text: str) -> sdk.ModelMetadata:
    path = _WORK / f"s{os.getpid()}.yaml"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    try:
        return sdk.ModelMetadata.from_yaml(path)
    finally:
        if _PWNED.exists():
            raise AssertionError("a YAML sidecar executed code")


# -- arrays and thresholds --------------------------------------------------------------------

ArraySpec = tuple[str, tuple[int, ...], str]


def _array(spec: ArraySpec) -> Any:
    kind, shape, fill = spec
    if kind == "list":
        return np.zeros(shape[:3]).tolist()
    if kind == "ragged":
        return [[0.0] * (i + 1) for i in range(3)]
    if kind == "object":
        return np.empty(shape[:2], dtype=object)
    if kind == "str":
        return np.full(shape[:3], "a")
    a = np.zeros(shape, dtype=kind)
    if a.size == 0:
        return a
    if fill == "nan" and a.dtype.kind in "fc":
        a.flat[0] = np.nan
    elif fill == "inf" and a.dtype.kind in "fc":
        a.flat[-1] = -np.inf
    elif fill == "random" and a.dtype.kind in "fc":
        a[...] = np.random.default_rng(a.size).random(shape)
    elif fill == "random" and a.dtype.kind in "iu":
        a[...] = np.random.default_rng(a.size).integers(0, 12, shape)
    elif fill == "negative" and a.dtype.kind in "if":
        a[...] = -1
    return a


_DIMS = st.integers(0, 40)


def _arrays(dims: st.SearchStrategy[int] = _DIMS, max_rank: int = 5) -> st.SearchStrategy[ArraySpec]:
    return st.tuples(
        st.sampled_from(["float32", "float32", "float64", "float16", "int32", "int8", "uint8", "bool", "complex64",
                         "list", "ragged", "object", "str"]),
        st.lists(dims, min_size=0, max_size=max_rank).map(tuple).filter(lambda s: int(np.prod(s)) <= 200_000),
        st.sampled_from(["zero", "nan", "inf", "random", "negative"]),
    )


arrays = _arrays()
_KINDS = st.sampled_from(["float32", "float32", "float32", "float64", "float16", "int32", "uint8", "bool"])
_FILLS = st.sampled_from(["zero", "nan", "inf", "random", "random", "negative"])
_SIDE = st.integers(1, 40)


def _near(shape: st.SearchStrategy[tuple[int, ...]]) -> st.SearchStrategy[ArraySpec]:
    """Arrays of nearly the right shape: the right layout, a dtype and a fill that may be wrong."""
    return st.tuples(_KINDS, shape, _FILLS)


#: (C, H, W) or (N, C, H, W) model inputs, C = 4 mostly.
_C = len(_PRED.metadata.inputs)  # the shipped model's planes
model_arrays = st.one_of(arrays, _near(st.tuples(st.sampled_from([_C, _C, _C, _C - 1]), _SIDE, _SIDE)),
                         _near(st.tuples(st.integers(0, 3), st.sampled_from([_C, _C, _C + 1]), _SIDE, _SIDE)))
#: (6, th, tw) or (N, 6, th, tw) predictions.
prediction_arrays = st.one_of(_arrays(st.sampled_from([0, 1, 2, 3, 6]), 4),
                              _near(st.tuples(st.just(6), st.integers(1, 5), st.integers(1, 5))),
                              _near(st.tuples(st.integers(1, 2), st.just(6), st.integers(1, 5), st.integers(1, 5))))
thresholds = st.one_of(hostile_numbers, st.just(None), st.floats(-10, 10), st.text(max_size=3))


def _threshold_absurd(t: Any, higher_is_better: bool = False) -> bool:
    """A threshold is a finite number of magnitude <= 1e6, >= 0 for an error metric; None means the default."""
    if t is None:
        return False
    v = _finite_number(t)
    return v is None or abs(v) > MAX_THRESHOLD or (not higher_is_better and v < 0)


def _predict_absurd(spec: ArraySpec, _out: Any) -> bool:
    """Accepted: a finite, non-empty float32 (C, H, W) or (N, C, H, W) array with the model's channels."""
    kind, shape, fill = spec
    ok_shape = len(shape) in (3, 4) and shape[-3] == _C and 0 not in shape
    return not (kind == "float32" and ok_shape and fill not in ("nan", "inf"))


allowed_values = st.one_of(st.none(), json_values, st.lists(st.one_of(st.integers(-3, 20), st.text(max_size=4)),
                                                            max_size=4), st.builds(np.array, st.integers(0, 12)))


def _select_call(v: tuple[ArraySpec, Any, Any]) -> np.ndarray:
    spec, thr, hib = v
    return sdk.select_rates(_array(spec), thr, higher_is_better=hib)


def _select_absurd(v: tuple[ArraySpec, Any, Any], codes: np.ndarray) -> bool:
    spec, thr, hib = v
    kind, shape, _ = spec
    if kind == "list":  # a nested list of zeros is array-like: np.asarray makes it a (6, th, tw) array when shaped so
        shape = shape[:3]
    return (
        not isinstance(hib, bool) or _threshold_absurd(thr, hib) or thr is None
        or kind in ("ragged", "object", "str", "complex64") or len(shape) < 3 or shape[-3] != 6
        or codes.dtype != np.uint8 or not set(np.unique(codes).tolist()) <= set(sdk.RATE_CODES.values())
    )


rate_factor_values = st.one_of(
    st.none(), json_values,
    st.lists(st.one_of(st.floats(), st.integers(-2, 6), st.booleans()), max_size=7),
    st.dictionaries(st.sampled_from([*sdk.ALL_RATES, "3x3", "4X4"]), st.one_of(st.floats(), json_scalars), max_size=7),
)


def _factor_ok(f: Any) -> bool:
    return (not isinstance(f, bool) and isinstance(f, (int, float)) and math.isfinite(f)
            and 1 / sdk.MAX_RATE_FACTOR <= f <= sdk.MAX_RATE_FACTOR)


def _factors_absurd(factors: Any, codes: np.ndarray) -> bool:
    """Returned rates although the factors are not six numbers in [1/4, 4] (a mapping of predicted rates, or None)."""
    if factors is None:
        ok = True
    elif isinstance(factors, dict):
        ok = set(factors) <= set(sdk.PREDICTED_RATES) and all(_factor_ok(v) for v in factors.values())
    else:
        ok = isinstance(factors, list) and len(factors) == 6 and all(_factor_ok(v) for v in factors)
    return not ok or codes.shape != (4, 5) or not set(np.unique(codes).tolist()) <= set(sdk.RATE_CODES.values())


_VALUES = np.random.default_rng(7).random((6, 4, 5)).astype(np.float32)


def _work_saved_call(v: tuple[ArraySpec, Any]) -> float:
    spec, size = v
    a = _array(spec)
    return sdk.work_saved(a) if size is None else sdk.work_saved(a, size, 16)


def _work_saved_absurd(v: tuple[ArraySpec, Any], saved: float) -> bool:
    a = np.asarray(_array(v[0]))
    known = set(sdk.RATE_CODES.values())
    return not 0.0 <= saved < 1.0 or a.dtype.kind not in "ui" or not set(np.unique(a).tolist()) <= known


def _saving_call(v: tuple[ArraySpec, Any, Any, Any, Any]) -> Any:
    spec, saving, hib, size, threshold = v
    kw = {} if size is None else {"frame_size": size, "tile_size": 16}
    return sdk.select_rates_for_saving(_array(spec), saving, higher_is_better=hib, threshold=threshold, **kw)


def _saving_absurd(v: tuple[ArraySpec, Any, Any, Any, Any], sel: Any) -> bool:
    """Accepted: a saving that is no number in [0, 0.9375], a threshold (a floor's) out of range, predictions that
    are not (..., 6, th, tw) numbers, rates that are no codes, or less saved than asked of predictions without NaN."""
    spec, saving, hib, _, threshold = v
    if isinstance(hib, bool) and _threshold_absurd(threshold, hib):
        return True
    kind, shape, fill = spec
    if kind == "list":
        shape = shape[:3]
    share = _finite_number(saving)
    return (
        share is None or not 0.0 <= share <= sdk.MAX_SAVING or not isinstance(hib, bool)
        or kind in ("ragged", "object", "str", "complex64") or len(shape) < 3 or shape[-3] != 6 or 0 in shape
        or sel.rates.dtype != np.uint8 or not set(np.unique(sel.rates).tolist()) <= set(sdk.RATE_CODES.values())
        or (fill != "nan" and not np.all(np.asarray(sel.saved) >= share - 1e-9))
    )


def _rates_input(v: tuple[str, Any]) -> Any:
    """A tagged rate input: ``("spec", ArraySpec)`` an array made from it, ``("raw", value)`` the value itself."""
    tag, value = v
    return _array(value) if tag == "spec" else value


def _combine_call(v: tuple[Any, Any, Any, Any]) -> np.ndarray:
    a, b, combiner, allowed = v
    return sdk.combine_rates(_rates_input(a), _rates_input(b), combiner, allowed=allowed)


def _combine_absurd(v: tuple[Any, Any, Any, Any], out: np.ndarray) -> bool:
    """Accepted: rates that are no codes of the allowed rates, a combiner that is none, or a result that is not
    uint8 codes of the allowed rates in the inputs' broadcast shape."""
    a, b, _, allowed = v
    try:
        known = {sdk.RATE_CODES[r] for r in ("1x1", *sdk.resolve_allowed(allowed))}
    except sdk.RtpError:
        return True
    inputs = [np.asarray(sdk.RATE_CODES.get(x, -1) if isinstance(x, str) else x) for x in map(_rates_input, (a, b))]
    return (any(x.dtype.kind not in "ui" or not set(np.unique(x).tolist()) <= known for x in inputs)
            or out.dtype != np.uint8 or not set(np.unique(out).tolist()) <= known
            or out.shape != np.broadcast_shapes(*(x.shape for x in inputs)))


def _engine_call(v: tuple[Any, Any, Any]) -> np.ndarray:
    engine, combiner, saving = v
    if saving is None:
        return sdk.select_rates(_VALUES, 0.5, engine_rates=_rates_input(engine), combiner=combiner)
    return sdk.select_rates_for_saving(_VALUES, saving, engine_rates=_rates_input(engine), combiner=combiner).rates


def _engine_absurd(v: tuple[Any, Any, Any], out: np.ndarray) -> bool:
    """Accepted: engine rates that are no codes broadcasting over the 4x5 tiles, a combiner other than min, max or
    sum, a saving out of range, or rates that are not uint8 codes of the tiles' shape."""
    engine, combiner, saving = v
    e = _rates_input(engine)
    share = None if saving is None else _finite_number(saving)
    if e is None:  # (no engine rates: the combiner is not read)
        return (saving is not None and (share is None or not 0.0 <= share <= sdk.MAX_SAVING)) or out.shape != (4, 5)
    e = np.asarray(sdk.RATE_CODES.get(e, -1) if isinstance(e, str) else e)
    try:
        np.broadcast_shapes(e.shape, (4, 5))
    except ValueError:
        return True
    named = combiner.strip().lower() if isinstance(combiner, str) else None
    known_combiner = named in ("min", "max", "sum", "mul") or (
        isinstance(combiner, int) and not isinstance(combiner, bool) and 2 <= combiner <= 4)
    return (e.dtype.kind not in "ui" or not set(np.unique(e).tolist()) <= set(sdk.RATE_CODES.values())
            or not known_combiner or (saving is not None and (share is None or not 0.0 <= share <= sdk.MAX_SAVING))
            or out.dtype != np.uint8 or out.shape != (4, 5)
            or not set(np.unique(out).tolist()) <= set(sdk.RATE_CODES.values()))


def _split_call(v: tuple[ArraySpec, Any, Any]) -> np.ndarray:
    spec, factor, grid = v
    return sdk.split_tiles(_array(spec), factor, grid)


def _split_absurd(v: tuple[ArraySpec, Any, Any], out: np.ndarray) -> bool:
    """Accepted: a factor that is no positive integer, a grid that is no fine grid of the tiles, or a
    result of another shape than the tiles split (and cropped)."""
    spec, factor, grid = v
    a = np.asarray(_array(spec))
    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1 or a.ndim < 2:
        return True
    th, tw = a.shape[-2:]
    want = (th * int(factor), tw * int(factor)) if grid is None else tuple(grid)
    return out.shape != (*a.shape[:-2], *want) or (grid is not None and not (
        th * factor - factor < want[0] <= th * factor and tw * factor - factor < want[1] <= tw * factor))


def _extrapolate_call(v: tuple[ArraySpec, Any, Any, Any]) -> np.ndarray:
    spec, outputs, k, hib = v
    return sdk.extrapolate(_array(spec), outputs, k, higher_is_better=hib)


def _extrapolate_absurd(v: tuple[ArraySpec, Any, Any, Any], out: np.ndarray) -> bool:
    spec, outputs, k, hib = v
    kv = _finite_number(k)
    if kv is None or not 1.0 <= kv <= MAX_K or not isinstance(hib, bool) or tuple(outputs) not in sdk.OUTPUT_SETS:
        return True
    values = np.asarray(_array(spec), dtype=np.float64)
    if out.shape[-3] != 6 or out.shape[:-3] != values.shape[:-3]:
        return True
    if np.isfinite(values).all() and not hib and tuple(outputs) in (("1x2", "2x1"), ("2x2",)):
        # extrapolated coarser rates are never better than the finer ones they come from
        e = {r: out[..., i, :, :] for i, r in enumerate(sdk.PREDICTED_RATES)}
        ok = (e["2x2"] >= np.maximum(e["1x2"], e["2x1"])).all() and (e["4x4"] >= np.maximum(e["2x4"], e["4x2"])).all()
        return not ok
    return False


def _overlay_case(tile: int, h: int, w: int, kind: str, fill: str, rates_kind: str, alpha: Any) -> tuple[Any, ...]:
    th, tw = -(-h // tile), -(-w // tile)
    return ((kind, (h, w, 3), fill), (rates_kind, (th, tw), "random"), tile, alpha)


#: A right-sized image and rate image with a dtype, fill or alpha that may be wrong.
overlays = st.builds(_overlay_case, st.sampled_from([1, 2, 4, 8, 16]), st.integers(1, 40), st.integers(1, 40),
                     st.sampled_from(["uint8", "float32", "float64", "float16", "int32", "bool"]), _FILLS,
                     st.sampled_from(["uint8", "uint8", "int32", "float32"]),
                     st.one_of(st.floats(-0.5, 1.5), hostile_numbers))
#: (th, tw) arrays of codes: the seven rates' codes and some that are none.
code_arrays = st.tuples(st.sampled_from(["uint8", "int8", "int64"]), st.tuples(st.integers(1, 4), st.integers(1, 4)),
                        st.sampled_from(["random", "negative", "zero"]))
#: A rate input of combine_rates or engine_rates: an array of codes, one code, a rate name, or anything at all.
rate_inputs = st.one_of(st.tuples(st.just("spec"), st.one_of(_arrays(st.integers(0, 4), 3), code_arrays)),
                        st.tuples(st.just("raw"), st.one_of(st.sampled_from(list(sdk.RATE_CODES.values())),
                                                            st.sampled_from(sdk.ALL_RATES), json_values)))


def _overlay_call(v: tuple[ArraySpec, ArraySpec, Any, Any]) -> np.ndarray:
    img, rates, tile, alpha = v
    return sdk.draw_rate_overlay(_array(img), _array(rates), tile, alpha=alpha)


def _overlay_absurd(v: tuple[ArraySpec, ArraySpec, Any, Any], out: np.ndarray) -> bool:
    a = _finite_number(v[3])
    img = np.asarray(_array(v[0]))
    return a is None or not 0.0 <= a <= 1.0 or out.shape != img.shape or not np.isfinite(out.astype(np.float64)).all()


# -- reprojection -------------------------------------------------------------------------------

_VIEW = np.eye(4)
_PROJ = np.array([[1.0, 0, 0, 0], [0, 1.5, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]])
#: glOrtho of a box 8 x 6 wide, near 1, far 51: the reprojection takes it as it takes _PROJ.
_ORTHO = np.array([[0.25, 0, 0, 0], [0, 1 / 3, 0, 0], [0, 0, -0.04, -1.04], [0, 0, 0, 1.0]])
_REPROJ_VALID: dict[str, Any] = {"prev_colour": np.full((6, 8, 3), 0.5), "prev_depth": np.full((6, 8), 2.0),
                                 "depth": np.full((6, 8), 2.0), "cur_view": _VIEW, "cur_proj": _PROJ,
                                 "prev_view_proj": _PROJ, "tolerance": 0.02, "motion": None, "prev_proj": None}


def _reproject_value(v: Any, base: Any) -> Any:
    if isinstance(v, tuple) and len(v) == 2 and v[0] == "matrix":
        return v[1]
    if isinstance(v, tuple) and len(v) == 3 and isinstance(v[1], tuple):
        return _array(v)
    if v == "scaled":
        return base * -1.0 if isinstance(base, np.ndarray) else base
    return v


reprojections = st.builds(
    lambda key, v: (key, v),
    st.sampled_from(list(_REPROJ_VALID)),
    st.one_of(_arrays(st.integers(0, 9), 3), hostile_numbers, st.just("scaled"), st.none(),
              st.deferred(lambda: projections)),
)


def _reproject_call(v: tuple[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    key, value = v
    kw = dict(_REPROJ_VALID)
    kw[key] = _reproject_value(value, kw[key])
    return sdk.reproject(**kw)


def _reproject_absurd(v: tuple[str, Any], result: tuple[np.ndarray, np.ndarray]) -> bool:
    key, value = v
    kw = dict(_REPROJ_VALID)
    kw[key] = _reproject_value(value, kw[key])
    out, seen = result
    tol = _finite_number(kw["tolerance"])
    depths_ok = all(np.asarray(kw[k]).dtype.kind in "biuf" and (np.asarray(kw[k]) >= 0).all()
                    for k in ("depth", "prev_depth"))
    return bool(
        tol is None or not 0.0 <= tol <= 1.0 or not depths_ok
        or not np.isfinite(out).all() or not set(np.unique(seen).tolist()) <= {0.0, 1.0}
        or out.shape != (*np.shape(kw["depth"]), *np.shape(kw["prev_colour"])[2:])  # (this frame's size)
        or seen.shape != np.shape(kw["depth"])
    )


# -- projection matrices ---------------------------------------------------------------------------------

_ENTRIES = st.sampled_from([0.0, 0.0, 0.0, 1.0, -1.0, 0.5, -0.2002, -1.002, 2.0, 1e-300, 1e300, float("nan"),
                            float("inf")])
projections = st.one_of(
    _arrays(st.integers(0, 5), 3),
    st.lists(_ENTRIES, min_size=16, max_size=16).map(lambda v: ("matrix", np.reshape(v, (4, 4)))),
    st.sampled_from([_PROJ, _PROJ.T, _PROJ @ np.diag([1.0, 1.0, -1.0, 1.0]), _ORTHO, _ORTHO.T,
                     np.diag([1.0, -1.0, 1.0, 1.0]) @ _ORTHO, _ORTHO @ np.diag([1.0, 1.0, -1.0, 1.0])],
                    ).map(lambda m: ("matrix", m)),
    json_scalars,
)


def _projection_value(v: Any) -> Any:
    if isinstance(v, tuple) and len(v) == 2 and v[0] == "matrix":
        return v[1]
    return _array(v) if isinstance(v, tuple) else v


def _projection_absurd(v: Any, m: np.ndarray) -> bool:
    """Accepted: a finite float64 4x4 matrix equal to the one given, never one whose w is +z (left-handed)."""
    given = np.asarray(_projection_value(v))
    return bool(m.shape != (4, 4) or m.dtype != np.float64 or not np.isfinite(m).all()
                or not np.array_equal(m, given.astype(np.float64))
                or (m[3, 2] > 0 and not m[3, :2].any() and m[3, 3] == 0))


# -- input planes from G-buffers ------------------------------------------------------------------

_PLANES_VALID: dict[str, Any] = {
    "depth": np.full((6, 8), 2.0), "albedo": np.full((6, 8, 3), 0.5), "normal": np.dstack([np.zeros((6, 8, 2)),
                                                                                          np.ones((6, 8))]),
    "roughness": np.full((6, 8), 0.5), "metallic": np.zeros((6, 8)), "specular": np.full((6, 8), 0.5),
    "shadow": np.ones((6, 8)), "emissive": np.zeros((6, 8)), "view": _VIEW, "projection": _PROJ,
    "prev_colour": np.full((6, 8, 3), 0.5), "prev_depth": np.full((6, 8), 2.0), "prev_view_projection": _PROJ,
    "prev_projection": None, "motion": np.zeros((6, 8, 2)), "tolerance": 0.02, "albedo_linear": False,
    "normal_space": "view", "depth_kind": "linear",
}
_PLANE_CHANNELS = st.one_of(st.lists(st.sampled_from(list(sdk.CHANNELS)), min_size=1, max_size=6),
                            st.just(list(sdk.CHANNELS)), json_scalars, st.lists(json_scalars, max_size=3))

planes_cases = st.builds(
    lambda channels, key, v, kind: (channels, key, v, kind),
    _PLANE_CHANNELS, st.sampled_from(list(_PLANES_VALID)),
    st.one_of(_arrays(st.integers(0, 9), 3), hostile_numbers, st.just("scaled"), st.none(), json_scalars,
              st.deferred(lambda: projections)),  # (any key: a matrix where an image goes, and singular projections)
    st.sampled_from(sdk.DEPTH_KINDS),  # (a hardware kind's valid depths are a depth buffer's 0.4)
)


def _planes_kw(v: tuple[Any, str, Any, str]) -> dict[str, Any]:
    _, key, value, kind = v
    kw = dict(_PLANES_VALID)
    if kind != "linear":
        kw.update(depth_kind=kind, depth=np.full((6, 8), 0.4), prev_depth=np.full((6, 8), 0.4))
    kw[key] = _reproject_value(value, kw[key])
    return kw


def _planes_call(v: tuple[Any, str, Any, str]) -> np.ndarray:
    return sdk.input_planes(v[0], **_planes_kw(v))


def _planes_absurd(v: tuple[Any, str, Any, str], x: np.ndarray) -> bool:
    """Accepted: the planes asked for, float32 and finite, of the depth's size; and nothing the channels read
    was past its range (a hardware depth past 1 among it)."""
    kw = _planes_kw(v)
    try:
        names = list(v[0])
        depth = np.asarray(kw["depth"], np.float64)
    except (TypeError, ValueError):
        return True
    hardware = kw["depth_kind"] in ("window", "reversed") and np.asarray(kw["depth"]).dtype != np.uint16
    return bool(x.shape != (len(names), *depth.shape) or x.dtype != np.float32 or not np.isfinite(x).all()
                or (depth < 0).any() or (hardware and (depth > 1 + 1e-3).any()))


def _fetch_absurd(v: tuple[ArraySpec, ArraySpec, Any], out: tuple[np.ndarray, np.ndarray]) -> bool:
    """Accepted: two index arrays of the motion's (H, W) shape, inside the previous frame (``prev_shape``, two
    positive integers, else the motion's)."""
    rows, cols = out
    shape = np.shape(_array(v[0]))
    prev = v[2] if v[2] is not None else shape
    valid = (isinstance(prev, (tuple, list)) and len(prev) == 2
             and all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) and 0 < n < 2**31 for n in prev))
    return bool(not valid or len(shape) != 2 or rows.shape != shape or cols.shape != shape or rows.min() < 0
                or cols.min() < 0 or rows.max() >= prev[0] or cols.max() >= prev[1])


# -- a user's own metric (rtp.metrics.Metric) ----------------------------------------------

_PLUGIN_REF = np.random.default_rng(7).random((19, 27, 3), dtype=np.float32)
_PLUGIN_IMAGES = {r: np.clip(_PLUGIN_REF + 0.03 * (i + 1), 0, 1).astype(np.float32)
                  for i, r in enumerate(sdk.PREDICTED_RATES)}
#: A plugin's declaration (name, default threshold, pooling, params, requires) and what its map returns:
#: an array spec, or a value that is not an array.
_PLUGIN_OUTPUTS = st.one_of(_near(st.just((19, 27))), _near(st.just((19, 27))), arrays, json_values)
plugin_metrics = st.one_of(
    st.tuples(  # a good declaration, its map's output anything
        st.sampled_from(["mine", "ssim2", "x_1"]), st.floats(1e-3, 10), st.sampled_from(["max", "mean"]),
        st.one_of(st.just({}), st.dictionaries(st.text(max_size=4), st.integers(), max_size=2)),
        st.sampled_from([(), ("numpy",)]), _PLUGIN_OUTPUTS),
    st.tuples(  # anything declared
        st.one_of(st.sampled_from(["mine", "flip", "jnx", "Mine", "1a", "a-b", "a" * 65, ""]), st.text(max_size=8),
                  json_scalars),
        st.one_of(hostile_numbers, st.floats(1e-3, 10)),
        st.one_of(st.sampled_from(["max", "mean", "mse", "min", ""]), json_scalars),
        st.one_of(st.just({}), json_values),
        st.one_of(st.just(()), st.sampled_from([("numpy",), ("rtp_no_such_module",), "numpy", ("",)]), json_values),
        _PLUGIN_OUTPUTS),
)


def _plugin_call(v: tuple[Any, ...]) -> dict[str, np.ndarray]:
    from rtp import metrics

    name, threshold, pooling, params, requires, output = v
    result = _array(output) if isinstance(output, tuple) and len(output) == 3 and output[0] in (
        "float32", "float64", "float16", "int32", "int8", "uint8", "bool", "complex64", "list", "ragged", "object",
        "str") else output
    m = metrics.Metric(name, lambda r, t: result, threshold, pooling=pooling, params=params, requires=requires)
    metrics.register_metric(m)
    try:
        metrics.check_dependencies([m.name])
        return metrics.tile_targets(_PLUGIN_REF, _PLUGIN_IMAGES, (m.name,), 8)
    finally:
        from rtp.metrics import _plugins

        _plugins._registered.pop(m.name, None)
        _plugins._explicit.discard(m.name)


def _plugin_absurd(v: tuple[Any, ...], out: dict[str, np.ndarray]) -> bool:
    """Accepted: a name of the documented pattern that is not rtp's own nor jn*, a finite threshold > 0, a
    known pooling, and targets of the frame's tiles, finite and >= 0."""
    import re

    name, threshold = v[0], _finite_number(v[1])
    values = out.get(name) if isinstance(out, dict) else None
    return bool(not isinstance(name, str) or not re.fullmatch(sdk.METRIC_NAME_PATTERN, name) or len(name) > 64
                or name in sdk.METRICS or name.startswith("jn") or threshold is None or threshold <= 0
                or v[2] not in ("max", "mean") or values is None or values.shape != (6, 3, 4)
                or values.dtype != np.float32 or not np.isfinite(values).all() or (values < 0).any())


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


def _read_all(root: Path) -> dict[str, Any]:
    """Everything a reader gives for a dataset folder: the manifest's format and every buffer and meta."""
    reader = open_dataset(root)
    out: dict[str, Any] = {}
    for sid in reader.ids:
        s = reader[sid]
        out[sid] = ({n: s.buffer(n) for n in BUFFERS}, dict(s.meta), s.inputs(sdk.DEFAULT_INPUTS))
    return out


_ORIGINAL: dict[str, Any] = {}


def _copy_dataset() -> tuple[Path, Path]:
    src = _dataset()
    if not _ORIGINAL:
        _ORIGINAL.update(_read_all(src))
    dst = _WORK / f"ds{os.getpid()}"
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(src, dst)
    return src, dst


def _read_mutated_dataset(mutation: tuple[str, int, bytes]) -> dict[str, Any]:
    which, pos, junk = mutation
    _, dst = _copy_dataset()
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
    return _read_all(dst)


def _same_as_original(_m: Any, got: dict[str, Any]) -> bool:
    """Absurd: a corrupted dataset that reads without error but gives other data than was written
    (the .npz members carry CRCs; an undetected change would be silent corruption)."""
    if set(got) != set(_ORIGINAL):
        return True
    for sid, (bufs, meta, x) in got.items():
        obufs, ometa, ox = _ORIGINAL[sid]
        if meta != ometa or not np.array_equal(x, ox) or any(not np.array_equal(bufs[n], obufs[n]) for n in bufs):
            return True
    return False


dataset_mutations = st.tuples(st.sampled_from(["manifest", "sample", "member", "any"]), st.integers(0, 2**20),
                              st.binary(min_size=1, max_size=64))

_MEMBERS = [*BUFFERS, "meta"]
member_replacements = st.tuples(st.sampled_from(_MEMBERS),
                                st.one_of(_arrays(st.sampled_from([0, 1, 2, 3, 4, 24, 40]), 4),
                                          st.builds(lambda d: ("meta-json", d), json_values)))


def _replace_member(v: tuple[str, Any]) -> dict[str, Any]:
    name, spec = v
    _, dst = _copy_dataset()
    path = dst / "samples" / "s0.npz"
    members = dict(np.load(path))
    if spec[0] == "meta-json":
        members[name] = np.frombuffer(json.dumps(spec[1], default=str, skipkeys=True).encode(), np.uint8)
    else:
        a = _array(spec)
        members[name] = np.asarray(a) if not isinstance(a, list) or spec[0] != "ragged" else np.array(a, dtype=object)
    buf = io.BytesIO()
    np.savez(buf, **members)  # type: ignore[arg-type]
    path.write_bytes(buf.getvalue())
    return _read_all(dst)


def _member_absurd(v: tuple[str, Any], got: dict[str, Any]) -> bool:
    name, spec = v
    if spec[0] == "meta-json":  # JSON bytes: a meta that is an object, or a buffer that is not one
        return name != "meta" or not isinstance(spec[1], dict)
    if name == "meta":
        return False
    kind, shape, fill = spec
    n = len(BUFFERS[name].channels) or 3
    want = (24, 40, n) if n > 1 else (24, 40)
    stored = "uint8" if BUFFERS[name].dtype == "u8" else "float16"
    bufs = got["s0"][0]
    # (a NaN or infinity fill is absurd only in floats: _array leaves an integer array at zero, a valid buffer;
    # the deep fuzz run of 2026-12-04 drew ('seen', ('uint8', (24, 40), 'nan')) and called its zeros absurd)
    return kind != stored or shape != want or (fill in ("nan", "inf") and np.dtype(kind).kind in "fc") \
        or not all(np.isfinite(b).all() for b in bufs.values())


manifests = st.one_of(
    json_values,
    st.builds(lambda k, v: {"format": "rtp-dataset", "format_version": 1, "settings": {}, k: v},
              st.sampled_from(["format", "format_version", "settings", "samples"]), st.one_of(json_values, hostile_numbers)),
    st.builds(lambda d: d, st.just({"format": "rtp-dataset", "format_version": 1, "settings": {}})),
)


def _manifest_call(m: Any) -> DatasetReader:
    _, dst = _copy_dataset()
    (dst / "manifest.json").write_text(json.dumps(m, default=str, skipkeys=True))
    reader = DatasetReader(dst)
    _read_all(dst)
    return reader


def _manifest_absurd(_m: Any, reader: DatasetReader) -> bool:
    fv = reader.manifest.get("format_version", 0)
    return reader.manifest.get("format") != "rtp-dataset" or not isinstance(fv, int) or isinstance(fv, bool) \
        or not 0 <= fv <= 1


# -- prediction reuse ------------------------------------------------------------------------

_RH, _RW = _X.shape[1:]
_RPLANE = (_RH, _RW)
#: (constructor arguments, fetch rows, fetch cols, seen, background): arrays of nearly the frame's
#: shape, any dtype and fill, or None.
_reuse_planes = st.one_of(st.none(), arrays, _near(st.sampled_from([_RPLANE, _RPLANE, _RPLANE, (_RH, _RW - 1)])))
reuse_cases = st.tuples(
    st.fixed_dictionaries({}, optional={
        "every": st.one_of(st.integers(-2, 6), hostile_numbers), "reduce": st.one_of(st.sampled_from(
            list(sdk.REUSE_REDUCTIONS)), json_scalars), "unseen": st.one_of(st.sampled_from(list(sdk.REUSE_UNSEEN)),
                                                                          json_scalars),
        "unseen_fraction": st.one_of(st.floats(-1, 2), hostile_numbers), "margin": st.one_of(st.integers(-2, 4),
                                                                                              hostile_numbers),
        "history": st.one_of(st.floats(-1, 2), hostile_numbers),
        "refresh": st.one_of(st.none(), st.floats(-1, 2), hostile_numbers),
        # not an argument: the predictor loaded for AMD's and Intel's finer hardware tiles (reused on the model's)
        "hardware_tile": st.sampled_from([8, 4])}),
    _reuse_planes, _reuse_planes, _reuse_planes, _reuse_planes)
#: The predictor loaded for each finer hardware tile than the model's 16 pixels.
_FINE = {t: sdk.load(_MODEL, tile_size=t) for t in (8, 4)}


def _reuse_predictor(kw: dict[str, Any]) -> sdk.ShadingRatePredictor:
    return _FINE[kw["hardware_tile"]] if "hardware_tile" in kw else _PRED


def _reuse_call(v: tuple[dict[str, Any], Any, Any, Any, Any]) -> np.ndarray:
    kw, rows, cols, seen, bg = v
    reuse = sdk.PredictionReuse(_reuse_predictor(kw), **{k: a for k, a in kw.items() if k != "hardware_tile"})
    reuse.predict(_X)
    fetch = None if rows is None and cols is None else (None if rows is None else _array(rows),
                                                         None if cols is None else _array(cols))
    return reuse.predict(_X, fetch, None if seen is None else _array(seen), None if bg is None else _array(bg))


def _reuse_absurd(v: tuple[dict[str, Any], Any, Any, Any, Any], est: np.ndarray) -> bool:
    """Accepted: arguments in range, and when the estimates were carried (every > 1 and fetch given)
    integer fetch arrays of the frame's shape inside it and numeric seen / background of that shape."""
    kw, rows, cols, seen, bg = v
    every, fraction, margin = kw.get("every", 4), kw.get("unseen_fraction", 0.5), kw.get("margin")
    history, refresh = kw.get("history", 0.0), kw.get("refresh")
    if (isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1
            or isinstance(history, (bool, str)) or _finite_number(history) is None or not 0 <= history < 1
            or (refresh is not None and (_finite_number(refresh) is None or not 0 <= refresh < 1))
            or kw.get("reduce", "mean") not in sdk.REUSE_REDUCTIONS or kw.get("unseen", "full") not in sdk.REUSE_UNSEEN
            or _finite_number(fraction) is None or not 0 <= fraction < 1
            or (margin is not None and (isinstance(margin, bool) or not isinstance(margin, (int, np.integer))
                                        or margin < 0))):
        return True
    if est.shape != (6, *_reuse_predictor(kw).tiles(_RH, _RW)) or est.dtype != np.float32:
        return True
    if (every == 1 and history == 0) or (rows is None and cols is None):
        return False
    for spec in (rows, cols):
        a = _array(spec) if spec is not None else None
        if not isinstance(a, np.ndarray) or a.dtype.kind not in "iu" or a.shape != _RPLANE or a.min() < 0:
            return True
    for spec in (seen, bg):
        a = _array(spec) if spec is not None else np.zeros(_RPLANE)
        if not isinstance(a, np.ndarray) or a.dtype.kind not in "biuf" or a.shape != _RPLANE:
            return True
    return False


#: (previous frame's (H, W), this frame's, how far past the previous frame the fetch may reach, every, unseen, seed):
#: a frame of another size than the last, as dynamic resolution gives it, a fifth of it sky.
resize_cases = st.tuples(st.tuples(st.integers(1, 60), st.integers(1, 60)), st.tuples(st.integers(1, 60), st.integers(1, 60)),
                         st.integers(-2, 2), st.integers(1, 4), st.sampled_from(list(sdk.REUSE_UNSEEN)),
                         st.integers(0, 2**16))


def _resize_fetch(v: tuple[Any, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    (ph, pw), (h, w), over, _, _, seed = v
    rng = np.random.default_rng(seed)
    return (rng.integers(min(over, 0), ph + max(over, 0), (h, w)), rng.integers(min(over, 0), pw + max(over, 0), (h, w)),
            (rng.random((h, w)) > 0.2).astype(np.float32))


def _resize_call(v: tuple[Any, ...]) -> np.ndarray:
    (ph, pw), (h, w), _, every, unseen, seed = v
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(_PRED, every, unseen=unseen)
    reuse.predict(rng.random((len(_PRED.metadata.inputs), ph, pw), dtype=np.float32))
    rows, cols, seen = _resize_fetch(v)
    sky = rng.random((h, w)) > 0.8  # (background: its estimate from its own place on the screen)
    return reuse.predict(rng.random((len(_PRED.metadata.inputs), h, w), dtype=np.float32), (rows, cols), seen, sky)


def _resize_absurd(v: tuple[Any, ...], est: np.ndarray) -> bool:
    """Accepted: estimates of this frame's tiles, none NaN, and where they were carried (every > 1) a fetch inside
    the previous frame at the pixels the carry reads (one of every ``step`` per axis, and the last row and column;
    the others are not read)."""
    (ph, pw), (h, w), _, every, _, _ = v
    rows, cols, _ = _resize_fetch(v)
    s = sdk.PredictionReuse(_PRED).step

    def read(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a[::s, ::s].ravel(), a[::s, -1].ravel(), a[-1, ::s].ravel()])

    outside = read(rows).min() < 0 or read(cols).min() < 0 or read(rows).max() >= ph or read(cols).max() >= pw
    return bool(est.shape != (6, *_PRED.tiles(h, w)) or np.isnan(est).any() or (every > 1 and outside))


def targets() -> list[Target]:
    return [
        Target("load: corrupted model files", model_mutations, lambda m: _load_bytes(_mutate_model(m)),
               _silently_changed),
        Target("load: hostile metadata JSON", _json_texts(), _hostile_json_model),
        Target("load: arguments (path, threads, providers, metadata)", _load_args, _load_call, _load_args_absurd),
        Target("ModelMetadata.from_dict", metadata_dicts, sdk.ModelMetadata.from_dict, _metadata_absurd),
        Target("ModelMetadata.from_json", _json_texts(), sdk.ModelMetadata.from_json, _metadata_absurd),
        Target("ModelMetadata.from_yaml (sidecars)", yaml_texts, _sidecar, _metadata_absurd),
        Target("Transform.from_dict", transforms, sdk.Transform.from_dict, lambda _d, t: _transform_absurd(t)),
        Target("predict: arrays", model_arrays, lambda spec: _PRED.predict(_array(spec)), _predict_absurd),
        Target("shading_rates: thresholds", thresholds, lambda t: _PRED.shading_rates(_X, threshold=t),
               lambda t, _r: _threshold_absurd(t)),
        Target("shading_rates: allowed rates", allowed_values, lambda a: _PRED.shading_rates(_X, allowed=a)),
        Target("select_rates", st.tuples(prediction_arrays, thresholds, st.one_of(st.booleans(), st.booleans(), json_scalars)),
               _select_call, _select_absurd),
        Target("select_rates: factors", rate_factor_values, lambda f: sdk.select_rates(_VALUES, 0.5, factors=f),
               _factors_absurd),
        Target("select_rates_for_saving", st.tuples(prediction_arrays, st.one_of(st.floats(0, 1), hostile_numbers),
                                                    st.one_of(st.booleans(), st.booleans(), json_scalars),
                                                    st.one_of(st.none(), st.tuples(st.integers(-2, 90),
                                                                                   st.integers(-2, 90)), json_values),
                                                    st.one_of(st.none(), st.none(), thresholds)),
               _saving_call, _saving_absurd),
        Target("combine_rates", st.tuples(rate_inputs, rate_inputs,
                                          st.one_of(st.sampled_from([*sdk.COMBINERS, "keep", "replace", "mul", "MAX"]),
                                                    st.integers(-2, 7), json_values),
                                          st.one_of(st.none(), st.lists(st.sampled_from(sdk.PREDICTED_RATES)),
                                                    json_values)), _combine_call, _combine_absurd),
        Target("select_rates: engine_rates", st.tuples(rate_inputs, st.one_of(
                   st.sampled_from(["min", "max", "sum", "mul", "passthrough", "Max"]), st.integers(-2, 7), json_values),
                   st.one_of(st.none(), st.none(), st.floats(0, 1), hostile_numbers)), _engine_call, _engine_absurd),
        Target("work_saved", st.tuples(st.one_of(_arrays(st.integers(0, 4), 3), code_arrays),
                                       st.one_of(st.none(), st.tuples(st.integers(-2, 70), st.integers(-2, 70)),
                                                 json_values)), _work_saved_call, _work_saved_absurd),
        Target("split_tiles", st.tuples(_arrays(st.sampled_from([0, 1, 2, 3, 5]), 4),
                                        st.one_of(st.integers(-2, 9), hostile_numbers),
                                        st.one_of(st.none(), st.tuples(st.integers(-1, 30), st.integers(-1, 30)),
                                                  json_values)), _split_call, _split_absurd),
        Target("extrapolate", st.one_of(
                   st.tuples(_arrays(st.sampled_from([0, 1, 2, 4, 6]), 4),
                             st.one_of(st.sampled_from([list(s) for s in sdk.OUTPUT_SETS]), json_values),
                             hostile_numbers, st.one_of(st.booleans(), json_scalars)),
                   st.sampled_from(sdk.OUTPUT_SETS).flatmap(lambda outs: st.tuples(
                       _near(st.tuples(st.just(len(outs)), st.integers(1, 4), st.integers(1, 4))), st.just(list(outs)),
                       st.one_of(hostile_numbers, st.floats(0.5, 120)), st.booleans()))),
               _extrapolate_call, _extrapolate_absurd),
        Target("draw_rate_overlay", st.one_of(
                   st.tuples(_arrays(st.sampled_from([0, 1, 3, 4, 16, 17]), 3), _arrays(st.sampled_from([0, 1, 2]), 3),
                             st.one_of(st.integers(-2, 40), hostile_numbers), hostile_numbers),
                   overlays),
               _overlay_call, _overlay_absurd),
        Target("reproject", reprojections, _reproject_call, _reproject_absurd),
        Target("input_planes", planes_cases, _planes_call, _planes_absurd),
        Target("check_gbuffers", planes_cases,
               lambda v: sdk.check_gbuffers(**_planes_kw(v)),  # (input_planes' keywords, all of them)
               lambda _v, out: not (isinstance(out, list) and all(isinstance(w, str) and w for w in out))),
        Target("check_projection", projections, lambda v: sdk.check_projection(_projection_value(v)),
               _projection_absurd),
        Target("check_reprojection", st.tuples(projections, projections, st.one_of(st.none(), projections)),
               lambda v: sdk.check_reprojection(*(None if p is None else _projection_value(p) for p in v)),
               lambda _v, kinds: not (isinstance(kinds, tuple) and len(kinds) == 2
                                      and all(k in sdk.CAMERA_KINDS for k in kinds))),
        Target("fetch_from_motion", st.tuples(_arrays(st.integers(0, 6), 3), _arrays(st.integers(0, 6), 3),
                                              st.one_of(st.none(), st.tuples(st.integers(-1, 12), st.integers(-1, 12)),
                                                        st.tuples(hostile_numbers, hostile_numbers), json_values,
                                                        # (indices past int64 were accepted as garbage)
                                                        st.sampled_from([(2**31, 3), (2**70, 3), (2**31 - 1, 2)]))),
               lambda v: sdk.fetch_from_motion(_array(v[0]), _array(v[1]), v[2]), _fetch_absurd),
        Target("PredictionReuse: arguments, fetch, seen, background", reuse_cases, _reuse_call, _reuse_absurd),
        Target("PredictionReuse: a frame of another size", resize_cases, _resize_call, _resize_absurd),
        Target("a user's metric: declaration and map output", plugin_metrics, _plugin_call, _plugin_absurd),
        Target("dataset reader: corrupted files", dataset_mutations, _read_mutated_dataset, _same_as_original),
        Target("dataset reader: malformed members", member_replacements, _replace_member, _member_absurd),
        Target("dataset reader: manifests", manifests, _manifest_call, _manifest_absurd),
    ]


#: Seconds one call may take before it counts as a hang.
HANG_S = 10.0


class Hang(BaseException):
    """A call that did not return within HANG_S (a BaseException: no ``except Exception`` in rtp hides it)."""


def bounded(call: Callable[[Any], Any]) -> Callable[[Any], Any]:
    """``call`` with a SIGALRM watchdog (main thread only) and numpy's warnings silenced: a warning is
    not an escape, a hang is."""

    def run(value: Any) -> Any:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
                return call(value)

            def alarm(_signum: int, _frame: Any) -> None:
                raise Hang(f"no answer within {HANG_S:g} s")

            old = signal.signal(signal.SIGALRM, alarm)
            signal.setitimer(signal.ITIMER_REAL, HANG_S)
            try:
                return call(value)
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
                signal.signal(signal.SIGALRM, old)

    return run


def small_or_absurd(v: Any) -> bool:
    """Keep a count that sizes an allocation or a loop either <= 40 or not a count at all."""
    return isinstance(v, bool) or not isinstance(v, (int, np.integer)) or int(v) <= 40


def classify_bounded(target: Target, value: Any) -> tuple[str, BaseException | None]:
    """:func:`classify` of one value with the watchdog of :func:`bounded`: ``"hang"`` when the call
    did not return within :data:`HANG_S`."""
    guarded = Target(target.name, target.strategy, bounded(target.call), target.absurd)
    try:
        return classify(guarded, value)
    except Hang as err:
        return "hang", err


def scaled(examples: int) -> int:
    """``examples`` times ``RTP_FUZZ_SCALE`` (an integer >= 1, default 1): every fuzz suite's example
    count, so a deep run needs no edit (``RTP_FUZZ_SCALE=20 pytest tests/test_fuzz*.py``)."""
    text = os.environ.get("RTP_FUZZ_SCALE", "1")
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"RTP_FUZZ_SCALE: expected an integer >= 1, got {text!r}")
    return examples * int(text)


def fuzz_bounded(target: Target, examples: int, refused: tuple[str, ...] = ("untyped", "hang")) -> None:
    """Run ``target`` on ``examples`` generated values (no example database: each run draws anew) and
    fail on the first whose outcome (:func:`classify_bounded`) is one of ``refused``."""
    from hypothesis import HealthCheck, given, settings

    @settings(max_examples=scaled(examples), deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(target.strategy)
    def run(value: object) -> None:
        outcome, err = classify_bounded(target, value)
        assert outcome not in refused, f"{outcome} for {value!r}: {err!r}"

    run()


