"""Every bad argument that reaches rtp.sdk is refused with a typed error (an RtpError that is also the
standard type it resembles), and every value outside its documented range (docs/metadata.md, "Value
ranges") is refused with the range in the message. The cases here are the escapes fuzzing found;
tests/test_fuzz.py generates many more."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.scene import Camera

from .conftest import base_metadata, build_onnx

_X = np.zeros((len(sdk.load("jnyang").metadata.inputs), 32, 48), np.float32)  # the shipped model's planes
_I = np.eye(4)
_P = Camera((0.0, 0.0, 0.0)).projection(1.0)  # (the identity is no projection the reprojection takes)


@functools.cache
def _predictor() -> sdk.ShadingRatePredictor:
    return sdk.load("jnyang")


def _meta(**overrides: Any) -> sdk.ModelMetadata:
    return sdk.ModelMetadata.from_dict(base_metadata(**overrides))


def _transform(**params: Any) -> sdk.ModelMetadata:
    return _meta(transform=params)


def _nested(depth: int) -> dict[str, Any]:
    d: dict[str, Any] = {}
    for _ in range(depth):
        d = {"a": d}
    return d


# (what, call, error class, words the message must hold)
CASES: list[tuple[str, Callable[[], Any], type[Exception], str]] = [
    # metadata: numbers
    ("safety huge int", lambda: _meta(safety=10**400), sdk.MetadataError, "finite"),
    ("safety 1e308", lambda: _meta(safety=1e308), sdk.MetadataError, "<= 1"),
    ("safety negative", lambda: _meta(safety=-0.1), sdk.MetadataError, ">= 0"),
    ("safety nan", lambda: _meta(safety=math.nan), sdk.MetadataError, "finite"),
    ("extrapolation_k 1e308", lambda: _meta(extrapolation_k=1e308), sdk.MetadataError, "<= 100"),
    ("extrapolation_k 0.5", lambda: _meta(extrapolation_k=0.5), sdk.MetadataError, ">= 1"),
    ("extrapolation_k inf", lambda: _meta(extrapolation_k=math.inf), sdk.MetadataError, "finite"),
    ("default_threshold negative", lambda: _meta(default_threshold=-0.1), sdk.MetadataError, ">= 0"),
    ("default_threshold 1e308", lambda: _meta(default_threshold=1e308), sdk.MetadataError, "<= 1e+06"),
    ("default_threshold nan", lambda: _meta(default_threshold=math.nan), sdk.MetadataError, "finite"),
    ("psnr default_threshold -1e7",
     lambda: _meta(metric="psnr", weber_l=None, default_threshold=-1e7), sdk.MetadataError, ">= -1e+06"),
    # metadata: structure
    ("field names not strings", lambda: sdk.ModelMetadata.from_dict({**base_metadata(), 1: 2, "x": 3}),
     sdk.MetadataError, "strings"),
    ("tile_size an array", lambda: _meta(tile_size=np.array([16, 16])), sdk.MetadataError, "tile_size"),
    ("metric with a newline", lambda: _meta(metric="jnyang\n"), sdk.MetadataError, "lower-case"),
    ("digest with a newline", lambda: _meta(digest="sha256:" + "a" * 64 + "\n"), sdk.MetadataError, "digest"),
    ("provenance nested too deep", lambda: _meta(provenance=_nested(5000)), sdk.MetadataError,
     "provenance: nested more than 100 levels deep"),  # (a bare RecursionError on Python 3.13: json.dumps took it)
    ("provenance one level too deep", lambda: _meta(provenance=_nested(100)), sdk.MetadataError, "more than 100 levels"),
    ("from_json not text", lambda: sdk.ModelMetadata.from_json(42), sdk.MetadataError, "JSON"),  # type: ignore[arg-type]
    ("from_json bad UTF-8", lambda: sdk.ModelMetadata.from_json(b"\xff\xfe"), sdk.MetadataError, "JSON"),
    ("from_json huge int", lambda: sdk.ModelMetadata.from_json('{"safety": 1' + "0" * 400 + "}"),
     sdk.MetadataError, ""),
    ("from_yaml not a path", lambda: sdk.ModelMetadata.from_yaml(5), sdk.MetadataError, "path"),  # type: ignore[arg-type]
    ("from_yaml NUL in the path", lambda: sdk.ModelMetadata.from_yaml("side\0.yaml"), sdk.MetadataError, "YAML"),
    # transforms
    ("transform.type a list", lambda: _transform(type=["clamped"], mu_y=0.2), sdk.MetadataError, "transform.type"),
    ("transform.type a dict", lambda: _transform(type={"a": 1}, mu_y=0.2), sdk.MetadataError, "transform.type"),
    ("mu_y huge int", lambda: _transform(type="clamped", mu_y=10**400), sdk.MetadataError, "1e+06"),
    ("mu_y nan", lambda: _transform(type="clamped", mu_y=math.nan), sdk.MetadataError, "finite"),
    ("mu_y subnormal", lambda: _transform(type="clamped", mu_y=1e-320), sdk.MetadataError, "[1e-06, 1e+06]"),
    ("factor subnormal", lambda: _transform(type="linear", factor=1e-320, offset=0.0), sdk.MetadataError,
     "[1e-06, 1e+06]"),
    ("offset inf", lambda: _transform(type="linear", factor=1.0, offset=math.inf), sdk.MetadataError, "finite"),
    ("k tiny", lambda: _transform(type="logistic", mu_y=0.2, k=1e-9), sdk.MetadataError, "[1e-06, 1e+06]"),
    ("logistic flat over [0, 1]", lambda: _transform(type="logistic", mu_y=5.0, k=10.0), sdk.MetadataError, "flat"),
    ("Transform.clamped of a string", lambda: sdk.Transform.clamped("a"), sdk.MetadataError, "mu_y"),  # type: ignore[arg-type]
    ("Transform.inverse of strings", lambda: sdk.Transform.clamped(0.2).inverse(np.array(["a"])), sdk.InputDtypeError,
     "real numbers"),
    ("decode of objects", lambda: _meta().decode(np.empty((4, 1, 1), object)), sdk.InputDtypeError, "real numbers"),
    # extrapolate
    ("extrapolate wrong channels", lambda: sdk.extrapolate(np.zeros((3, 2, 2)), ["1x2", "2x1"]), sdk.InputShapeError,
     "2 channels"),
    ("extrapolate k 0 (PSNR)", lambda: sdk.extrapolate(np.zeros((2, 2, 2)), ["1x2", "2x1"], 0, higher_is_better=True),
     sdk.ParameterError, "[1, 100]"),
    ("extrapolate k 1e308", lambda: sdk.extrapolate(np.zeros((2, 2, 2)), ["1x2", "2x1"], 1e308), sdk.ParameterError,
     "[1, 100]"),
    ("extrapolate k a string", lambda: sdk.extrapolate(np.zeros((2, 2, 2)), ["1x2", "2x1"], "2"), sdk.ParameterError,
     "[1, 100]"),  # type: ignore[arg-type]
    ("extrapolate objects", lambda: sdk.extrapolate(np.empty((2, 2, 2), object), ["1x2", "2x1"]), sdk.InputDtypeError,
     "numeric"),
    ("extrapolate ragged list", lambda: sdk.extrapolate([[[1.0]], [[1.0, 2.0]]], ["1x2", "2x1"]), sdk.InputDtypeError,
     "numeric"),
    ("extrapolate outputs a string", lambda: sdk.extrapolate(np.zeros((2, 2, 2)), "1x2"), sdk.MetadataError,
     "cannot extrapolate"),
    # thresholds, rates
    ("threshold a string", lambda: _predictor().shading_rates(_X, threshold="a"), sdk.ParameterError, "number"),  # type: ignore[arg-type]
    ("threshold a list", lambda: _predictor().shading_rates(_X, threshold=[0.2]), sdk.ParameterError, "number"),  # type: ignore[arg-type]
    ("threshold nan", lambda: _predictor().shading_rates(_X, threshold=math.nan), sdk.ParameterError, "[0, 1e+06]"),
    ("threshold -inf", lambda: _predictor().shading_rates(_X, threshold=-math.inf), sdk.ParameterError, "[0, 1e+06]"),
    ("threshold negative", lambda: _predictor().shading_rates(_X, threshold=-0.1), sdk.ParameterError, "error metric"),
    ("threshold 1e308", lambda: _predictor().shading_rates(_X, threshold=1e308), sdk.ParameterError, "[0, 1e+06]"),
    ("threshold huge int", lambda: _predictor().shading_rates(_X, threshold=10**400), sdk.ParameterError, "[0, 1e+06]"),
    ("PSNR threshold 1e7", lambda: sdk.select_rates(np.zeros((6, 1, 1)), 1e7, higher_is_better=True),
     sdk.ParameterError, "[-1e+06, 1e+06]"),
    ("select_rates objects", lambda: sdk.select_rates(np.empty((6, 1, 1), object), 0.2), sdk.InputDtypeError, "dtype"),
    ("select_rates higher_is_better a string", lambda: sdk.select_rates(np.zeros((6, 1, 1)), 0.2,
                                                                         higher_is_better="no"),  # type: ignore[arg-type]
     sdk.ParameterError, "higher_is_better"),
    ("allowed a 0-d array", lambda: _predictor().shading_rates(_X, allowed=np.array(5)), sdk.ParameterError,
     "allowed"),
    ("allowed a dict", lambda: _predictor().shading_rates(_X, allowed={"2x2": 1}), sdk.ParameterError, "allowed"),  # type: ignore[arg-type]
    ("rate_size unknown", lambda: sdk.rate_size("3x3"), sdk.ParameterError, "unknown shading rate"),
    ("rate_size a list", lambda: sdk.rate_size(["2x2"]), sdk.ParameterError, "unknown shading rate"),  # type: ignore[arg-type]
    ("work_saved negative code", lambda: sdk.work_saved(np.array([[-5]], np.int8)), sdk.ParameterError, "[-5]"),
    ("work_saved ragged", lambda: sdk.work_saved([[1], [1, 2]]), sdk.InputDtypeError, "rate"),  # type: ignore[arg-type]
    ("work_saved frame_size an int", lambda: sdk.work_saved(np.zeros((1, 1), np.uint8), 5, 16),  # type: ignore[arg-type]
     sdk.ParameterError, "frame_size"),
    # overlay
    ("overlay unknown code", lambda: sdk.draw_rate_overlay(np.zeros((16, 16, 3)), np.full((1, 1), 3, np.uint8), 16),
     sdk.ParameterError, "no shading rate"),
    ("overlay string rates", lambda: sdk.draw_rate_overlay(np.zeros((16, 16, 3)), np.array([["a"]]), 16),
     sdk.InputDtypeError, "integer"),
    ("overlay object image", lambda: sdk.draw_rate_overlay(np.empty((16, 16, 3), object), np.zeros((1, 1), np.uint8),
                                                           16), sdk.InputDtypeError, "image"),
    ("overlay NaN image", lambda: sdk.draw_rate_overlay(np.full((16, 16, 3), np.nan), np.zeros((1, 1), np.uint8), 16),
     sdk.NonFiniteInputError, "image"),
    ("overlay alpha nan", lambda: sdk.draw_rate_overlay(np.zeros((16, 16, 3)), np.zeros((1, 1), np.uint8), 16,
                                                        alpha=math.nan), sdk.ParameterError, "[0, 1]"),
    ("overlay tile_size 0", lambda: sdk.draw_rate_overlay(np.zeros((16, 16, 3)), np.zeros((1, 1), np.uint8), 0),
     sdk.ParameterError, "tile_size"),
    # reprojection
    ("reproject string depth", lambda: sdk.reproject(np.zeros((4, 4, 3)), np.ones((4, 4)), "x", _I, _I, _I),
     sdk.InputDtypeError, "depth"),
    ("reproject singular view", lambda: sdk.reproject(np.zeros((4, 4, 3)), np.ones((4, 4)), np.ones((4, 4)),
                                                      np.zeros((4, 4)), _P, _P), sdk.ParameterError, "singular"),
    ("reproject NaN matrix", lambda: sdk.reproject(np.zeros((4, 4, 3)), np.ones((4, 4)), np.ones((4, 4)), _I, _P,
                                                   np.full((4, 4), np.nan)), sdk.NonFiniteInputError, "prev_view_proj"),
    ("reproject 3x3 matrix", lambda: sdk.reproject(np.zeros((4, 4, 3)), np.ones((4, 4)), np.ones((4, 4)), np.eye(3),
                                                   _I, _I), sdk.InputShapeError, "4x4"),
    ("reproject tolerance a string", lambda: sdk.reproject(np.zeros((4, 4, 3)), np.ones((4, 4)), np.ones((4, 4)), _I,
                                                           _I, _I, tolerance="a"), sdk.ParameterError, "[0, 1]"),  # type: ignore[arg-type]
    ("reproject tolerance inf", lambda: sdk.reproject(np.zeros((4, 4, 3)), np.ones((4, 4)), np.ones((4, 4)), _I, _I,
                                                      _I, tolerance=math.inf), sdk.ParameterError, "[0, 1]"),
    # (the previous frame may be of another size than this one, dynamic resolution's; its colour and depth not)
    ("reproject shapes differ", lambda: sdk.reproject(np.zeros((4, 5, 3)), np.ones((4, 4)), np.ones((4, 5)), _I, _I,
                                                      _I), sdk.InputShapeError, "prev_depth's"),
    ("reproject NaN depth", lambda: sdk.reproject(np.zeros((4, 4, 3)), np.ones((4, 4)), np.full((4, 4), np.nan), _I,
                                                  _I, _I), sdk.NonFiniteInputError, "depth"),
    ("reproject negative depth", lambda: sdk.reproject(np.zeros((4, 4, 3)), np.ones((4, 4)), -np.ones((4, 4)), _I, _I,
                                                       _I), sdk.ParameterError, ">= 0"),
    ("reproject empty", lambda: sdk.reproject(np.zeros((0, 0, 3)), np.ones((0, 0)), np.ones((0, 0)), _I, _I, _I),
     sdk.InputShapeError, "non-empty"),
    # load
    ("load an int", lambda: sdk.load(5), sdk.ParameterError, "path"),  # type: ignore[arg-type]
    ("load None", lambda: sdk.load(None), sdk.ParameterError, "path"),  # type: ignore[arg-type]
    ("load a name too long", lambda: sdk.load("a" * 10000), sdk.ModelNotFoundError, "no model file"),
    ("load threads 2**40", lambda: sdk.load("jnyang", threads=2**40), sdk.ParameterError, "[0, 4096]"),
    ("load threads 4097", lambda: sdk.load("jnyang", threads=4097), sdk.ParameterError, "[0, 4096]"),
    ("load threads -1", lambda: sdk.load("jnyang", threads=-1), sdk.ParameterError, "[0, 4096]"),
    ("load providers an int", lambda: sdk.load("jnyang", providers=5), sdk.ProviderUnavailableError, "providers"),  # type: ignore[arg-type]
]


@pytest.mark.parametrize(("what", "call", "error", "words"), CASES, ids=[c[0] for c in CASES])
def test_bad_values_are_refused_with_a_typed_error(what: str, call: Callable[[], Any], error: type[Exception],
                                                   words: str) -> None:
    with pytest.raises(error) as info:
        call()
    assert isinstance(info.value, sdk.RtpError)
    assert words in str(info.value), str(info.value)


def test_the_bounds_themselves_are_accepted() -> None:
    m = _meta(safety=1.0, extrapolation_k=100.0, default_threshold=1e6)
    assert m.safety == 1.0 and m.extrapolation_k == 100.0
    assert _meta(safety=0, extrapolation_k=1, default_threshold=0).default_threshold == 0.0
    psnr = _meta(metric="psnr", weber_l=None, transform={"type": "linear", "factor": -0.015, "offset": 1.0},
                 default_threshold=-40.0)  # PSNR may be negative
    assert psnr.default_threshold == -40.0
    assert _transform(type="linear", factor=-1e-6, offset=-1e6).transform.factor == -1e-6
    assert _transform(type="logistic", mu_y=1e-6, k=1e6).transform.k == 1e6
    values = np.random.default_rng(0).random((6, 3, 5)).astype(np.float32)
    assert sdk.select_rates(values, 1e6).max() == sdk.RATE_CODES["4x4"]
    assert sdk.select_rates(-values, -1e6, higher_is_better=True).max() == sdk.RATE_CODES["4x4"]
    assert sdk.select_rates(values, np.float32(0.5), allowed=np.array([5, 10])).dtype == np.uint8
    assert sdk.extrapolate(values[:2], ["1x2", "2x1"], 100.0).shape == (6, 3, 5)
    # bool and unsigned predictions are compared as numbers, not wrapped around when negated
    codes = sdk.select_rates(np.full((6, 1, 1), 200, np.uint8), 100, higher_is_better=True)
    assert codes[0, 0] == sdk.RATE_CODES["4x4"]
    out, seen = sdk.reproject(np.ones((4, 4, 3)), np.ones((4, 4)), np.ones((4, 4)), _I, _P, _P, tolerance=1.0)
    assert out.shape == (4, 4, 3) and seen.shape == (4, 4)


def test_metadata_given_to_load_does_not_skip_the_integrity_check(tmp_path: Path) -> None:
    """A model whose own metadata records a digest is checked even when ``metadata=`` replaces that
    metadata, and a digest given in ``metadata=`` is checked against the file too."""
    src = Path(_predictor().path or "")
    data = bytearray(src.read_bytes())
    import onnx

    model = onnx.load_from_string(bytes(data))
    raw = max((i.raw_data for i in model.graph.initializer), key=len)
    pos = bytes(data).find(raw) + len(raw) // 2
    data[pos] ^= 0x10
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(bytes(data))
    sidecar = _predictor().metadata.to_dict()
    del sidecar["digest"]
    with pytest.raises(sdk.ModelIntegrityError, match="differ from what was exported"):
        sdk.load(bad, metadata=sidecar)
    # a plain model (no digest anywhere) given a sidecar that claims one
    plain = build_onnx(tmp_path / "plain.onnx", weights=np.eye(4, dtype=np.float32), metadata=None)
    with pytest.raises(sdk.ModelIntegrityError):
        sdk.load(plain, metadata=base_metadata(digest="sha256:" + "0" * 64))
    assert sdk.load(plain, metadata=base_metadata()).metadata.digest is None
    right = sdk.model_digest(plain.read_bytes())
    assert sdk.load(plain, metadata=base_metadata(digest=right)).metadata.digest == right


def test_provenance_as_deep_as_allowed_round_trips() -> None:
    """100 levels (the limit; the shipped models' provenance has 4) load, write and read back on any
    Python; one more is refused by the SDK itself, not by whichever recursion limit comes first."""
    meta = _meta(provenance=_nested(99))
    again = sdk.ModelMetadata.from_json(meta.to_json())
    assert again.provenance == meta.provenance and again.to_json() == meta.to_json()
