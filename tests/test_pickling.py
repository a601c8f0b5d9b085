"""A ShadingRatePredictor pickled (multiprocessing, Ray) carries its model's bytes and load options and
loads again where it is unpickled (docs/runtime.md "Pickling and other processes")."""

from __future__ import annotations

import copy
import multiprocessing
import pickle
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from rtp import sdk
from rtp.sdk._predictor import FORCE_SPINNING_STOP

from .conftest import base_metadata, build_onnx
from .test_predictor import _config


def _frame(predictor: sdk.ShadingRatePredictor, seed: int = 0, size: tuple[int, int] = (96, 160)) -> np.ndarray:
    x = np.random.default_rng(seed).random((len(predictor.metadata.inputs), *size), dtype=np.float32)
    return x


def _same(a: sdk.ShadingRatePredictor, b: sdk.ShadingRatePredictor, x: np.ndarray) -> None:
    np.testing.assert_array_equal(a.predict(x), b.predict(x))
    np.testing.assert_array_equal(a.shading_rates(x), b.shading_rates(x))
    assert (a.metadata, a.tile_size, repr(a), a.path) == (b.metadata, b.tile_size, repr(b), b.path)


@pytest.mark.parametrize("name", ["jnyang", "jnyang-reuse", "lpips"])
def test_a_shipped_model_pickles_and_predicts_the_same(name: str) -> None:
    p = sdk.load(name, threads=1)
    q = pickle.loads(pickle.dumps(p))
    assert q._session is not p._session
    _same(p, q, _frame(p))
    if p.splits:  # the tail graph comes along
        _, feats = p.predict_split(_frame(p))
        np.testing.assert_array_equal(q.predict_tail(feats, _frame(p)), p.predict_tail(feats, _frame(p)))


def test_load_options_survive(tiny_model: Callable[..., Path]) -> None:
    """tile_size, assume_finite, threads and the spinning option are the loaded predictor's."""
    p = sdk.load(tiny_model(base_metadata()), threads=1, tile_size=8, assume_finite=True, spin_between_runs=True)
    q = pickle.loads(pickle.dumps(p))
    _same(p, q, _frame(p))
    assert q.tile_size == 8 and q._assume_finite
    assert q._session.get_session_options().intra_op_num_threads == 1
    assert _config(q._session, FORCE_SPINNING_STOP) is None  # spin_between_runs=True
    assert _config(pickle.loads(pickle.dumps(sdk.load(p.path)))._session, FORCE_SPINNING_STOP) == "1"
    bad = _frame(p)
    bad[0, 0, 0] = np.nan
    q.predict(bad)  # assume_finite: not refused
    r = pickle.loads(pickle.dumps(sdk.load(p.path)))
    with pytest.raises(sdk.NonFiniteInputError):
        r.predict(bad)


def test_the_file_need_not_exist_where_it_is_unpickled(tiny_model: Callable[..., Path]) -> None:
    path = tiny_model(base_metadata())
    p = sdk.load(path)
    data = pickle.dumps(p)
    path.unlink()
    q = pickle.loads(data)
    _same(p, q, _frame(p))
    assert q.path == path and not path.exists()


def test_metadata_pickles_and_deep_copies() -> None:
    """Its provenance is read-only (a MappingProxyType, which pickle refused)."""
    for name in sdk.shipped_models():
        meta = sdk.load(name).metadata
        assert meta.provenance
        assert pickle.loads(pickle.dumps(meta)) == meta == copy.deepcopy(meta)


def test_metadata_given_at_load_comes_along(tmp_path: Path) -> None:
    """A model without embedded metadata, loaded with metadata=, unpickles with that metadata."""
    path = build_onnx(tmp_path / "bare.onnx", weights=np.eye(4, dtype=np.float32))
    p = sdk.load(path, metadata=base_metadata(safety=0.03))
    q = pickle.loads(pickle.dumps(p))
    _same(p, q, _frame(p))
    assert q.metadata.safety == pytest.approx(0.03)


def test_bytes_changed_on_the_way_are_refused(tiny_model: Callable[..., Path]) -> None:
    """Unpickling checks the model's digest again, as load does."""
    path = tiny_model(base_metadata())
    p = sdk.load(tiny_model(base_metadata(digest=sdk.model_digest(path.read_bytes()))))
    fn, (path, data, args) = p.__reduce__()
    w = np.frombuffer(np.eye(4, dtype=np.float32).tobytes(), np.uint8).tobytes()
    assert w in data
    tampered = data.replace(w, np.frombuffer((2 * np.eye(4, dtype=np.float32)).tobytes(), np.uint8).tobytes())
    with pytest.raises(sdk.ModelIntegrityError):
        fn(path, tampered, args)


def test_copies_share_the_session(tiny_model: Callable[..., Path]) -> None:
    p = sdk.load(tiny_model(base_metadata()))
    for q in (copy.copy(p), copy.deepcopy(p)):
        assert q is not p and q._session is p._session
        _same(p, q, _frame(p))


def test_a_predictor_of_a_session_of_ones_own_says_how_to_pickle(tiny_model: Callable[..., Path]) -> None:
    import onnxruntime as ort

    path = tiny_model(base_metadata())
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    p = sdk.ShadingRatePredictor(session, sdk.load(path).metadata, path)
    with pytest.raises(TypeError, match=r"sdk\.load\(\)"):
        pickle.dumps(p)


def _rates_in_child(predictor: sdk.ShadingRatePredictor, x: np.ndarray) -> np.ndarray:
    return predictor.shading_rates(x)


def test_a_process_pool_gets_the_same_rates() -> None:
    """The user's case: a predictor handed to worker processes (spawned: no fork's copy of the parent)."""
    p = sdk.load("jnflip", threads=1)
    frames = [_frame(p, seed) for seed in range(3)]
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        got = list(pool.map(_rates_in_child, [p] * len(frames), frames))
    for x, rates in zip(frames, got, strict=True):
        np.testing.assert_array_equal(rates, p.shading_rates(x))
