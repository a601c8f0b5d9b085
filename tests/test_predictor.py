"""ShadingRatePredictor on small real ONNX models built with onnx.helper."""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk

from .conftest import base_metadata, build_onnx


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-x))


def test_predict_matches_the_closed_form(tiny_model: Callable[..., Path]) -> None:
    meta = base_metadata(safety=0.02)
    p = sdk.load(tiny_model(meta))
    rng = np.random.default_rng(0)
    x = rng.standard_normal((4, 64, 48)).astype(np.float32)
    got = p.predict(x)
    assert got.shape == (6, 4, 3) and got.dtype == np.float32
    # Channel i of the tiny model is sigmoid(max over the tile of input channel i).
    raw = _sigmoid(x.reshape(4, 4, 16, 3, 16).max(axis=(2, 4)))
    expected = sdk.ModelMetadata.from_dict(meta).decode(raw)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(p.predict_raw(x), raw, rtol=1e-5, atol=1e-6)


def test_one_predictor_serves_several_threads_at_once(tiny_model: Callable[..., Path]) -> None:
    """docs/runtime.md "Threads": predict and shading_rates keep no state between calls, so threads may
    share one predictor (onnxruntime's run is thread-safe); each gets its own frame's answer."""
    from concurrent.futures import ThreadPoolExecutor

    p = sdk.load(tiny_model(base_metadata()), threads=1)
    frames = [np.random.default_rng(i).random((4, 96, 160), dtype=np.float32) for i in range(8)]
    serial = [(p.predict(f), p.shading_rates(f)) for f in frames]
    with ThreadPoolExecutor(4) as pool:
        for _ in range(5):
            got = list(pool.map(lambda f: (p.predict(f), p.shading_rates(f)), frames))
            for (values, rates), (v0, r0) in zip(got, serial, strict=True):
                np.testing.assert_array_equal(values, v0)
                np.testing.assert_array_equal(rates, r0)


def test_threads_share_a_splitting_predictor_and_load_at_once() -> None:
    """docs/runtime.md "Threads": predict_split and predict_tail keep nothing between calls either (frames of
    several sizes, padded), and threads loading at once each get a predictor of their own that predicts alike."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(4) as pool:
        loaded = list(pool.map(lambda n: sdk.load(n, threads=1), ["jnyang-reuse", "jnflip"] * 2))
    p = loaded[0]
    c = len(p.metadata.inputs)
    frames = [np.random.default_rng(i).random((c, *((72, 128), (50, 70))[i % 2]), dtype=np.float32) for i in range(8)]

    def split(f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        values, feats = p.predict_split(f)
        return values, feats, p.predict_tail(feats, f)

    serial = [split(f) for f in frames]
    with ThreadPoolExecutor(4) as pool:
        for _ in range(3):
            for got, want in zip(pool.map(split, frames), serial, strict=True):
                for a, b in zip(got, want, strict=True):
                    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(loaded[2].predict(frames[0]), p.predict(frames[0]))
    f = np.ascontiguousarray(frames[0][:7])
    np.testing.assert_array_equal(loaded[1].predict(f), loaded[3].predict(f))


class Meeting:
    """Forces two threads through a warn-once test-and-add together: ``add_blocks()``, a set whose ``add`` holds each
    thread until two threads have arrived (at the ``add`` or at the ``gate()``, the code's lock around the test and
    the add). Without that lock both threads pass the test before either adds, and both log; with it the second waits
    at the gate, arriving, and finds the first one's entry."""

    def __init__(self) -> None:
        self._arrived: set[int] = set()
        self._mutex = threading.Lock()
        self._both = threading.Event()

    def arrive(self) -> None:
        with self._mutex:
            self._arrived.add(threading.get_ident())
            if len(self._arrived) >= 2:
                self._both.set()

    def add_blocks(self) -> set[Any]:
        meeting = self

        class _Set(set):  # type: ignore[type-arg]
            def add(self, item: Any) -> None:
                meeting.arrive()
                assert meeting._both.wait(20), "the second thread never came"
                super().add(item)

        return _Set()

    def gate(self) -> Any:
        meeting, lock = self, threading.Lock()

        class _Gate:
            def __enter__(self) -> None:
                meeting.arrive()
                lock.acquire()

            def __exit__(self, *exc: object) -> None:
                lock.release()

        return _Gate()


def test_threads_sharing_a_predictor_warn_of_a_threshold_once(tiny_model: Callable[..., Path],
                                                              caplog: pytest.LogCaptureFixture,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """Two viewports' threads calling ``shading_rates`` with a threshold past saturation: the warning is logged once,
    not by each thread that tested the thresholds warned of before the other added it (forced interleaving)."""
    from concurrent.futures import ThreadPoolExecutor

    from rtp.sdk import _predictor

    p = sdk.load(tiny_model(base_metadata()), threads=1)
    meta = p.metadata
    factor = min(meta.rate_factors or (1.0,))
    past = meta.saturation + 20.0 * np.log10(factor) - 0.01 if meta.higher_is_better else meta.saturation / factor * 1.01
    meeting = Meeting()
    p.__dict__["_saturation_warned"] = meeting.add_blocks()
    monkeypatch.setattr(_predictor, "_WARNED_LOCK", meeting.gate(), raising=False)
    frame = np.random.default_rng(0).random((4, 32, 48), dtype=np.float32)
    caplog.set_level(logging.WARNING, logger="rtp.sdk")
    with ThreadPoolExecutor(2) as pool:
        for done in [pool.submit(p.shading_rates, frame, past) for _ in range(2)]:
            done.result(timeout=30)
    warned = [r.getMessage() for r in caplog.records]
    assert len(warned) == 1 and f"threshold {past:g} is beyond the worst value the model can express" in warned[0]


def test_warn_once_sets_stay_bounded_for_a_threshold_controller_and_dynamic_resolution(
        tiny_model: Callable[..., Path], caplog: pytest.LogCaptureFixture) -> None:
    """An engine's threshold controller past saturation hands ``shading_rates`` a new float every frame, and a
    dynamic-resolution engine a new frame size every few: each was logged once and kept for ever, so the warning came
    every frame and the predictor's sets grew by one every frame, without bound. Now the first ``MAX_WARNED`` of each
    are logged, the last saying that no more are, and the sets stay that size."""
    from rtp.sdk import _predictor

    limit = _predictor.MAX_WARNED
    p = sdk.load(tiny_model(base_metadata()), threads=1)
    meta = p.metadata
    factor = min(meta.rate_factors or (1.0,))
    past = meta.saturation + 20.0 * np.log10(factor) - 0.01 if meta.higher_is_better else meta.saturation / factor * 1.01
    step = -1e-3 if meta.higher_is_better else 1e-3  # (further past saturation, frame after frame)
    frame = np.random.default_rng(0).random((4, 32, 48), dtype=np.float32)
    caplog.set_level(logging.WARNING, logger="rtp.sdk")
    for i in range(3 * limit):
        p.shading_rates(frame, past + i * step)
    warned = [r.getMessage() for r in caplog.records if "beyond the worst value" in r.getMessage()]
    assert len(warned) == limit and len(p.__dict__["_saturation_warned"]) == limit
    assert "further thresholds are not logged" in warned[-1] and "not logged" not in warned[-2]
    caplog.clear()
    blocks = sdk.load("jnyang", threads=1)
    for i in range(3 * limit):  # frame sizes that cut the .blocks planes' last cells (widths not multiples of 4)
        blocks.predict(np.zeros((len(blocks.metadata.inputs), 32, 33 + 4 * i), np.float32))
    cut = [r.getMessage() for r in caplog.records if "cuts the last" in r.getMessage()]
    assert len(cut) == limit and len(blocks.__dict__["_cut_cells_warned"]) == limit
    assert "further frame sizes are not logged" in cut[-1]


def test_views_on_finer_hardware_tiles_warn_of_a_frame_size_once(caplog: pytest.LogCaptureFixture) -> None:
    """docs/runtime.md "Threads and several views": each warning is logged once, whichever threads pass it. A
    PredictionReuse of a predictor loaded for hardware tiles finer than the model's (AMD's and Intel's 8-pixel tiles)
    runs a copy of it on the model's tiles, and a copy made before the predictor's first warning had sets of its own:
    a frame size that cuts the .blocks planes' last cells was logged by the predictor, then again by each view's
    reuse (three times for two views on their threads). Copies now share what was warned of, as they share the
    session; the views' estimates are the predictor's."""
    import copy
    from concurrent.futures import ThreadPoolExecutor

    p = sdk.load("jnyang", threads=1, tile_size=8)
    views = [sdk.PredictionReuse(p, every=2) for _ in range(2)]
    twin = copy.copy(p)
    frame = np.random.default_rng(0).random((len(p.metadata.inputs), 32, 50), dtype=np.float32)  # (50: cut cells)
    caplog.set_level(logging.WARNING, logger="rtp.sdk")
    want = p.predict(frame)
    with ThreadPoolExecutor(2) as pool:
        for est in pool.map(lambda r: r.predict(frame), views):
            np.testing.assert_array_equal(est, want)
    np.testing.assert_array_equal(twin.predict(frame), want)
    cut = [r.getMessage() for r in caplog.records if "cuts the last" in r.getMessage()]
    assert len(cut) == 1 and "a 50x32 frame cuts the last 4x4 cells" in cut[0]


def test_batched_and_single_frames_agree(tiny_model: Callable[..., Path]) -> None:
    p = sdk.load(tiny_model())
    x = np.random.default_rng(1).random((3, 4, 32, 32), dtype=np.float32)
    batched = p.predict(x)
    assert batched.shape == (3, 6, 2, 2)
    for i in range(3):
        np.testing.assert_allclose(batched[i], p.predict(x[i]), rtol=1e-6)
    assert p.shading_rates(x).shape == (3, 2, 2)


def test_padding_repeats_the_edge_and_loses_no_tile(tiny_model: Callable[..., Path]) -> None:
    p = sdk.load(tiny_model())
    x = np.full((4, 20, 37), -3.0, np.float32)
    x[0, 19, 36] = 2.0  # the last pixel of the frame, alone in the last tile
    out = p.predict_raw(x)
    assert out.shape == (4, 2, 3)  # ceil(20/16) x ceil(37/16)
    assert out[0, 1, 2] == pytest.approx(_sigmoid(2.0), rel=1e-6)
    # Edge replication, not zeros: the padded region of an all-negative channel stays negative.
    assert out[1, 1, 2] == pytest.approx(_sigmoid(-3.0), rel=1e-6)
    assert p.tiles(20, 37) == (2, 3)


def test_a_model_taking_partial_tiles_is_padded_only_to_its_multiple(tiny_model: Callable[..., Path]) -> None:
    x = np.random.default_rng(3).standard_normal((4, 21, 37)).astype(np.float32)
    padded = sdk.load(tiny_model())  # pads to 32x48 by repeating the edge
    for multiple in (1, 4):
        p = sdk.load(tiny_model(base_metadata(input_multiple=multiple), ceil_mode=True))
        assert p.metadata.pad_multiple == multiple
        # a max over a partial tile equals the max over the tile padded with its own edge
        np.testing.assert_array_equal(p.predict_raw(x), padded.predict_raw(x))
        np.testing.assert_array_equal(p.predict(x[:, :20]), padded.predict(x[:, :20]))
        assert p.predict(x).shape == (6, 2, 3)


def test_input_multiple_on_a_model_that_needs_whole_tiles_is_a_clear_error(tiny_model: Callable[..., Path]) -> None:
    p = sdk.load(tiny_model(base_metadata(input_multiple=4)))  # floor-mode pooling drops the partial tile
    assert p.predict(np.zeros((4, 32, 48), np.float32)).shape == (6, 2, 3)
    with pytest.raises(sdk.InferenceError, match="does not fit this model"):
        p.predict(np.zeros((4, 20, 36), np.float32))


def test_metadata_of_another_tile_size_is_refused_at_load(tiny_model: Callable[..., Path]) -> None:
    """A sidecar of the 8-pixel model given to a 16-pixel one loaded, and the first frame failed with an
    InferenceError in the engine's frame loop: the graph's tile grid is checked when the model loads."""
    for meta_tile, graph_tile in ((8, 16), (16, 8), (32, 16)):
        path = tiny_model(base_metadata(tile_size=meta_tile), tile=graph_tile)
        with pytest.raises(sdk.MetadataError, match=rf"tile_size: .*metadata says {meta_tile}, but the model maps "
                                                    rf".* \(tiles of {graph_tile} pixels\)") as info:
            sdk.load(path)
        assert info.value.key == "tile_size"
    assert sdk.load(tiny_model(base_metadata(tile_size=8), tile=8)).tile_size == 8


def test_shading_rates_uses_the_default_threshold(tiny_model: Callable[..., Path]) -> None:
    meta = base_metadata(default_threshold=0.3)
    p = sdk.load(tiny_model(meta))
    x = np.full((4, 16, 32), -10.0, np.float32)  # raw ~ 0: tiny errors everywhere
    x[:, :, 16:] = 10.0  # raw ~ 1: error 2 mu = 0.5 in the right tile
    rates = p.shading_rates(x)
    assert rates.dtype == np.uint8
    assert rates.tolist() == [[sdk.RATE_CODES["4x4"], sdk.RATE_CODES["1x1"]]]
    assert p.shading_rates(x, threshold=0.6).tolist() == [[10, 10]]
    assert p.shading_rates(x, allowed=["1x2", "2x1", "2x2"]).tolist() == [[5, 0]]


def test_shading_rates_for_a_saving(tiny_model: Callable[..., Path]) -> None:
    """A budget: the work held, the threshold the frame's own; the worst tile reduced last."""
    p = sdk.load(tiny_model(base_metadata(default_threshold=0.3)))
    x = np.full((4, 16, 48), -10.0, np.float32)  # tiny errors ...
    x[:, :, 16:32] = 0.0  # ... a middling tile ...
    x[:, :, 32:] = 10.0  # ... and the worst
    assert p.shading_rates(x, saving=0.3).tolist() == [[10, 0, 0]]  # one tile at 4x4 saves 0.3125
    assert p.shading_rates(x, saving=0.32).tolist() == [[10, 10, 0]]  # the middling one next (its rates alike)
    assert p.shading_rates(x, saving=0.9375).tolist() == [[10, 10, 10]]
    assert p.shading_rates(x, saving=0).tolist() == [[0, 0, 0]]
    assert p.shading_rates(x, saving=0.5, allowed=["1x2", "2x1", "2x2"]).tolist() == [[5, 5, 0]]
    values = p.predict(x)
    sel = sdk.select_rates_for_saving(values, 0.32)
    assert p.shading_rates(x, threshold=sel.threshold).tolist() == [[10, 10, 0]]
    both = np.stack([x, x[:, :, ::-1]])  # a batch: each frame its own threshold
    assert p.shading_rates(both, saving=0.3).tolist() == [[[10, 0, 0]], [[0, 0, 10]]]
    # partial edge tiles weigh their pixels: in a 40-pixel-wide frame two whole tiles at 4x4 save 0.75 of
    # its work (counted per tile, the last one would have to be reduced too)
    assert p.shading_rates(x[:, :, :40], saving=0.75).tolist() == [[10, 10, 0]]
    # both: the threshold's rates, the saving a floor under them
    assert p.shading_rates(x, threshold=0.2).tolist() == [[10, 0, 0]]
    assert p.shading_rates(x, threshold=0.2, saving=0.3).tolist() == [[10, 0, 0]]  # (it saves 0.3125 already)
    assert p.shading_rates(x, threshold=0.2, saving=0.32).tolist() == [[10, 10, 0]]  # the floor's
    with pytest.raises(sdk.ParameterError, match=r"saving: expected .* \[0, 0.5\]"):
        p.shading_rates(x, saving=0.6, allowed=["1x2"])


def test_properties(tiny_model: Callable[..., Path]) -> None:
    p = sdk.load(tiny_model(), threads=1)
    assert p.rates == ("1x2", "2x1", "2x2", "2x4", "4x2", "4x4")
    assert p.provider == "CPUExecutionProvider"
    assert p.tile_size == 16 and p.static_size is None
    assert "jnyang" in repr(p)


def test_more_threads_than_cores_loads_with_a_warning(
    tiny_model: Callable[..., Path], caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    from rtp.sdk import _predictor

    monkeypatch.setattr(_predictor, "_usable_cores", lambda: 2)
    with caplog.at_level("WARNING", logger="rtp.sdk"):
        sdk.load(tiny_model(), threads=2)
        assert not caplog.records
        p = sdk.load(tiny_model(), threads=3)
    assert [r.getMessage() for r in caplog.records] == [
        "threads=3 is more than the 2 cores this process may run on: onnxruntime starts that many worker threads, "
        "which spin-wait when the session is built and during each run, and take the cores from every other thread "
        "of the process"
    ]
    assert p.predict(np.zeros((4, 16, 16), np.float32)).shape[-2:] == (1, 1)  # still loaded and running
    monkeypatch.undo()
    assert 1 <= _predictor._usable_cores() <= (os.cpu_count() or 1)


@pytest.mark.parametrize(
    ("x", "error", "match"),
    [
        ([[[0.0]]], sdk.InputDtypeError, "numpy.ndarray"),
        (np.zeros((4, 16, 16), np.float64), sdk.InputDtypeError, "float32"),
        (np.zeros((16, 16), np.float32), sdk.InputShapeError, r"\(4, H, W\)"),
        (np.zeros((1, 1, 4, 16, 16), np.float32), sdk.InputShapeError, "got"),
        (np.zeros((3, 16, 16), np.float32), sdk.InputChannelError, "expected 4 channels"),
        (np.zeros((1, 16, 16, 4), np.float32), sdk.InputChannelError, r"channels-last.*transpose\(0, 3, 1, 2\)"),
        (np.zeros((16, 16, 4), np.float32), sdk.InputChannelError, r"channels-last.*transpose\(2, 0, 1\)"),
        (np.zeros((0, 4, 16, 16), np.float32), sdk.InputShapeError, "non-empty"),
    ],
)
def test_bad_inputs_raise_typed_errors(tiny_model: Callable[..., Path], x: object, error: type, match: str) -> None:
    p = sdk.load(tiny_model())
    with pytest.raises(error, match=match) as info:
        p.predict(x)  # type: ignore[arg-type]
    assert isinstance(info.value, sdk.RtpError)
    if issubclass(error, sdk.InputShapeError):
        assert isinstance(info.value, ValueError)
    with pytest.raises(error):
        p.shading_rates(x)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_inputs_are_rejected(tiny_model: Callable[..., Path], bad: float) -> None:
    p = sdk.load(tiny_model())
    x = np.zeros((4, 16, 16), np.float32)
    x[2, 3, 4] = bad
    with pytest.raises(sdk.NonFiniteInputError, match="albedo.r"):
        p.predict(x)
    # a masked array's mask hides the value from numpy's reductions, not from the model, which reads its data
    with pytest.raises(sdk.NonFiniteInputError, match="albedo.r"):
        p.predict(np.ma.masked_invalid(x))


def test_assume_finite_skips_the_check_and_nothing_else(tiny_model: Callable[..., Path]) -> None:
    checked, trusted = sdk.load(tiny_model()), sdk.load(tiny_model(), assume_finite=True)
    x = np.random.default_rng(0).random((4, 32, 48), dtype=np.float32)
    np.testing.assert_array_equal(trusted.predict(x), checked.predict(x))
    x[1, 5, 7] = np.nan
    with pytest.raises(sdk.NonFiniteInputError):
        checked.predict(x)
    assert trusted.predict(x).shape == (6, 2, 3)  # the caller's promise: no error, the value is unspecified
    with pytest.raises(sdk.InputChannelError):  # every other check still runs
        trusted.predict(x[:3])
    with pytest.raises(sdk.ParameterError, match="assume_finite"):
        sdk.load(tiny_model(), assume_finite="yes")  # type: ignore[arg-type]


def _config(session: object, key: str) -> str | None:
    try:
        return session.get_session_options().get_session_config_entry(key)  # type: ignore[attr-defined, no-any-return]
    except RuntimeError:  # onnxruntime: "SessionOptions does not have configuration with key"
        return None


def test_onnxruntime_threads_stop_spinning_when_a_run_returns() -> None:
    """By default the worker threads stop spinning when ``predict`` returns (a splitting model's tail
    session too); ``spin_between_runs=True`` leaves onnxruntime's default."""
    from rtp.sdk._predictor import FORCE_SPINNING_STOP

    reuse = sdk.load("jnyang-reuse")
    assert reuse.splits
    for session in (reuse._session, reuse._tail):
        assert _config(session, FORCE_SPINNING_STOP) == "1"
    assert _config(sdk.load("jnyang", spin_between_runs=True)._session, FORCE_SPINNING_STOP) is None
    with pytest.raises(sdk.ParameterError, match="spin_between_runs"):
        sdk.load("jnyang", spin_between_runs=1)  # type: ignore[arg-type]


def test_an_idle_predictor_leaves_the_cores_to_the_engine() -> None:
    """The behaviour the option is for: after ``predict`` returns, a caller that does something else (here
    it sleeps for three 60 Hz frames) gets the cores; with onnxruntime's default its worker thread
    spins there, 38-50 ms of CPU time (bench/spinning.py)."""
    p = sdk.load("jnyang", threads=2, providers=["CPUExecutionProvider"])
    x = np.random.default_rng(0).random((len(p.metadata.inputs), 360, 640), dtype=np.float32)
    time.sleep(0.2)  # a new session's threads spin for a while whatever the setting, a one-off cost of loading
    p.predict(x)
    burned = []
    for _ in range(3):
        p.predict(x)
        c0 = time.process_time()
        time.sleep(0.05)
        burned.append(time.process_time() - c0)
    assert sorted(burned)[1] < 0.005, f"the process used {burned} s of CPU while the caller slept 0.05 s"


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(sdk.ModelNotFoundError) as info:
        sdk.load(tmp_path / "nope.onnx")
    assert isinstance(info.value, FileNotFoundError)
    with pytest.raises(FileNotFoundError, match="no model file"):
        sdk.load("definitely_not_shipped")
    with pytest.raises(sdk.ModelNotFoundError, match="not a file"):
        sdk.load(tmp_path)
    with pytest.raises(sdk.ModelNotFoundError, match="got an empty path; shipped models: .*jnyang.onnx"):
        sdk.load("")  # not "'.' exists but is not a file"


@pytest.mark.parametrize("content", [b"", b"not an onnx model at all", b"\x08\x07\x12\x04junk" * 10])
def test_corrupt_file(tmp_path: Path, content: bytes) -> None:
    f = tmp_path / "broken.onnx"
    f.write_bytes(content)
    with pytest.raises(sdk.ModelLoadError, match="cannot load"):
        sdk.load(f)


def test_truncated_model(tiny_model: Callable[..., Path], tmp_path: Path) -> None:
    data = tiny_model().read_bytes()
    f = tmp_path / "cut.onnx"
    f.write_bytes(data[: len(data) // 2])
    with pytest.raises(sdk.ModelLoadError):
        sdk.load(f)


def test_model_without_metadata_needs_a_sidecar(tmp_path: Path) -> None:
    path = build_onnx(tmp_path / "bare.onnx", weights=np.eye(4, dtype=np.float32))
    with pytest.raises(sdk.MetadataError, match="rtp-export --adopt"):
        sdk.load(path)
    p = sdk.load(path, metadata=base_metadata())
    assert p.metadata.metric == "jnyang"
    side = tmp_path / "side.yaml"
    side.write_text("metric: lpips\ntransform: {type: clamped, mu_y: 0.1}\ntile_size: 16\n"
                    "inputs: [reprojected.r, seen, albedo.r, normal.z]\noutputs: [1x2, 2x1, 2x4, 4x2]\n"
                    "default_threshold: 0.1\n")
    assert sdk.load(path, metadata=side).metadata.metric == "lpips"


def test_corrupt_embedded_metadata(tmp_path: Path) -> None:
    import onnx

    path = build_onnx(tmp_path / "m.onnx", weights=np.eye(4, dtype=np.float32))
    model = onnx.load(str(path))
    onnx.helper.set_model_props(model, {"rtp.metadata": "{not json"})
    onnx.save(model, str(path))
    with pytest.raises(sdk.MetadataError, match="not valid JSON"):
        sdk.load(path)


def test_metadata_that_does_not_fit_the_graph(tmp_path: Path) -> None:
    path = build_onnx(tmp_path / "m.onnx", weights=np.ones((2, 4), np.float32), static=(1, 64, 64))
    with pytest.raises(sdk.MetadataError, match="outputs") as info:
        sdk.load(path, metadata=base_metadata())  # 4 outputs declared, the model has 2
    assert info.value.key == "outputs"
    with pytest.raises(sdk.MetadataError, match="tile_size"):
        sdk.load(path, metadata=base_metadata(outputs=["1x2", "2x1"], tile_size=8))
    with pytest.raises(sdk.MetadataError, match="inputs"):
        sdk.load(path, metadata=base_metadata(outputs=["1x2", "2x1"], inputs=["seen", "albedo.r", "normal.z"]))


def test_tile_size_mismatch_on_a_dynamic_model_is_caught_at_load(tmp_path: Path) -> None:
    """Caught at load (it was caught at the first predict), and blamed on the metadata the caller gave: the message
    said "'m.onnx''s metadata says 16" of a sidecar passed as metadata=, sending the reader to the wrong file."""
    path = build_onnx(tmp_path / "m.onnx", weights=np.eye(4, dtype=np.float32), tile=8)
    with pytest.raises(sdk.MetadataError, match="the metadata given as metadata= says 16, but the model maps 128x128 "
                                                "pixels to 16x16 tiles") as info:
        sdk.load(path, metadata=base_metadata(tile_size=16))
    assert "m.onnx'" not in str(info.value) and info.value.key == "tile_size"


def test_fixed_size_model_pads_smaller_frames(tmp_path: Path) -> None:
    # Like the paper's published models (1x4x1088x1920 for 1080p frames), scaled down.
    path = build_onnx(tmp_path / "m.onnx", weights=np.ones((2, 4), np.float32), static=(1, 48, 64))
    p = sdk.load(path, metadata=base_metadata(outputs=["1x2", "2x1"]))
    assert p.static_size == (48, 64)
    assert p.predict(np.zeros((2, 4, 40, 64), np.float32)).shape == (2, 6, 3, 4)  # batch looped, padded
    with pytest.raises(sdk.InputShapeError, match="fixed input"):
        p.predict(np.zeros((4, 64, 64), np.float32))


def test_a_fixed_size_model_that_takes_partial_tiles_loads(tmp_path: Path) -> None:
    """A fixed input that is no multiple of the tile size, on a network that takes partial tiles (input_multiple):
    its 40x40 input gives 3x3 16-pixel tiles, as predict expects, but load compared them with 40 // 16 = 2 and
    refused the model ("metadata says 16 but the model maps 40x40 to 3x3 tiles")."""
    path = build_onnx(tmp_path / "m.onnx", weights=np.eye(4, dtype=np.float32), static=(1, 40, 40), ceil_mode=True)
    p = sdk.load(path, metadata=base_metadata(input_multiple=4))
    x = np.zeros((4, 40, 40), np.float32)
    x[0, 39, 39] = 5.0  # in the last, partial tile
    raw = p.predict_raw(x)
    assert raw.shape == (4, 3, 3)
    assert raw[0, 2, 2] == pytest.approx(1 / (1 + np.exp(-5.0)), rel=1e-6) and raw[0, 1, 1] == 0.5


def test_a_fixed_size_model_that_drops_its_partial_tiles_is_refused_at_load(tmp_path: Path) -> None:
    """A fixed 40x40 input pooled to 2x2 16-pixel tiles loses the frame's last tiles: load took it and every
    predict failed with InferenceError (output (1, 4, 2, 2), expected (1, 4, 3, 3)); now load names it."""
    path = build_onnx(tmp_path / "m.onnx", weights=np.eye(4, dtype=np.float32), static=(1, 40, 40))
    with pytest.raises(sdk.MetadataError, match="maps 40x40 to 2x2 tiles, expected 3x3 .*partial") as info:
        sdk.load(path, metadata=base_metadata())
    assert info.value.key == "tile_size"


def test_unavailable_provider(tiny_model: Callable[..., Path], caplog: pytest.LogCaptureFixture) -> None:
    path = tiny_model()
    with pytest.raises(sdk.ProviderUnavailableError, match="not available"):
        sdk.load(path, providers=["NoSuchExecutionProvider"], strict=True)
    with caplog.at_level(logging.WARNING, logger="rtp"):
        p = sdk.load(path, providers=["NoSuchExecutionProvider", "CPUExecutionProvider"])
    assert p.provider == "CPUExecutionProvider"
    assert "NoSuchExecutionProvider" in caplog.text
    with pytest.raises(sdk.ProviderUnavailableError, match="name"):
        sdk.load(path, providers=[42])  # type: ignore[list-item]
    assert sdk.load(path, providers=[("CPUExecutionProvider", {})], strict=True).provider == "CPUExecutionProvider"


def test_threshold_beyond_saturation_warns(tiny_model: Callable[..., Path], caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="rtp"):
        sdk.load(tiny_model(base_metadata(default_threshold=0.9)))  # clamped, mu 0.25: saturates at 0.5
    assert "every tile will pass" in caplog.text


def test_saturation_warnings_count_the_extrapolated_rates(tiny_model: Callable[..., Path],
                                                          caplog: pytest.LogCaptureFixture) -> None:
    """A model of outputs [1x2, 2x1] saturates at 0.5 there (clamped, mu 0.25), but its extrapolated 2x4, 4x2 and
    4x4 reach 2.13 times that: a threshold of 0.6 was said to pass every tile at every rate (at load and per call)
    while a saturated tile got 2x2, not 4x4."""
    w = np.zeros((2, 4), np.float32)
    w[:, 0] = 40.0  # sigmoid(40 x): the worst output where plane 0 is 1
    with caplog.at_level(logging.WARNING, logger="rtp"):
        p = sdk.load(tiny_model(base_metadata(outputs=["1x2", "2x1"], default_threshold=0.6), weights=w))
        x = np.zeros((4, 16, 16), np.float32)
        x[0] = 1.0
        assert p.shading_rates(x).tolist() == [[sdk.RATE_CODES["2x2"]]]  # (4x4's 1.065 fails 0.6)
    assert "beyond the worst value" not in caplog.text
    assert p.metadata.saturation == pytest.approx(2.13 * 0.5)
    with caplog.at_level(logging.WARNING, logger="rtp"):
        assert p.shading_rates(x, threshold=1.1).tolist() == [[sdk.RATE_CODES["4x4"]]]
    assert "threshold 1.1 is beyond the worst value the model can express (1.065)" in caplog.text
    assert "use one below 1.065" in caplog.text


def _with_probe(path: Path, meta: dict | None = None, name: str = "probe") -> Path:
    """The tiny model with a second output: the sum of its convolution's output (what rtp-export's
    ``add_finite_probe`` adds to a fast network), named in the metadata as ``finite_probe``."""
    import json

    import onnx
    from onnx import helper

    model = onnx.load(str(path))
    model.graph.node.append(helper.make_node("ReduceSum", ["conv"], [name], keepdims=0))
    model.graph.output.append(helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, []))
    helper.set_model_props(model, {"rtp.metadata": json.dumps(base_metadata(finite_probe=name) if meta is None
                                                              else meta)})
    onnx.save(model, str(path))
    return path


class _Recording:
    """An onnxruntime session that records which outputs each run asked for."""

    def __init__(self, session: object) -> None:
        self.session, self.asked = session, []  # type: ignore[var-annotated]

    def run(self, names: list[str], feed: dict) -> list:
        self.asked.append(list(names))
        return self.session.run(names, feed)  # type: ignore[attr-defined]

    def __getattr__(self, name: str) -> object:
        return getattr(self.session, name)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_finite_probe_replaces_the_frame_read_and_refuses_the_same_inputs(
    tiny_model: Callable[..., Path], bad: float
) -> None:
    plain, probed = sdk.load(tiny_model()), sdk.load(_with_probe(tiny_model()))
    assert probed.metadata.finite_probe == "probe" and probed.metadata.schema_version == 3
    rec = probed._session = _Recording(probed._session)
    x = np.random.default_rng(0).random((2, 4, 40, 56), dtype=np.float32)  # a batch, partial tiles
    np.testing.assert_array_equal(probed.predict(x), plain.predict(x))
    assert rec.asked == [["metric", "probe"]]
    x[1, 2, 39, 55] = bad  # the last pixel of the second frame: the padded copy repeats it
    for p in (plain, probed):
        with pytest.raises(sdk.NonFiniteInputError, match=r"first at index \(1, 2, 39, 55\), channel 'albedo.r'"):
            p.predict(x)
    trusted = sdk.load(_with_probe(tiny_model()), assume_finite=True)
    rec = trusted._session = _Recording(trusted._session)
    assert trusted.predict(x).shape == (2, 6, 3, 4)  # the caller's promise: the probe is not fetched
    assert rec.asked == [["metric"]]


def test_a_probe_that_overflows_on_huge_finite_values_lets_them_through(tiny_model: Callable[..., Path]) -> None:
    p = sdk.load(_with_probe(tiny_model()))
    x = np.full((4, 32, 32), 3e38, np.float32)  # finite, but their sum is not
    assert np.isfinite(p.predict(x)).all()


def test_the_finite_probe_must_be_an_output_and_the_only_extra_one(tiny_model: Callable[..., Path]) -> None:
    with pytest.raises(sdk.MetadataError, match="finite_probe: the metadata names the output 'nowhere'") as info:
        sdk.load(_with_probe(tiny_model(), base_metadata(finite_probe="nowhere")))
    assert info.value.key == "finite_probe"
    # a second output the metadata does not explain: a scalar one is named as the finite probe a sidecar left out
    # (the error said only "got 1 inputs and 2 outputs", nothing of the field)
    with pytest.raises(sdk.MetadataError, match="one output.* got 1 inputs and 2 outputs: the model's scalar output "
                                                r"'probe' looks like a finite probe, .*add finite_probe: probe\)") as info:
        sdk.load(_with_probe(tiny_model(), base_metadata()))
    assert info.value.key == "finite_probe"


def test_no_bare_onnxruntime_error_escapes(tiny_model: Callable[..., Path]) -> None:
    import onnxruntime

    p = sdk.load(tiny_model())
    # Make onnxruntime itself fail (a feed name the graph does not have): the error must be ours.
    p._session = onnxruntime.InferenceSession(str(tiny_model(weights=np.ones((4, 4), np.float32))))
    p._groups = (("wrong_name", 0, 4),)
    with pytest.raises(sdk.InferenceError, match="onnxruntime failed"):
        p.predict(np.zeros((4, 16, 16), np.float32))


def _undecodable(data: bytes | bytearray) -> bytes:
    """An ONNX graph's bytes with a node input name that is no longer UTF-8: onnxruntime refuses it."""
    data = bytearray(data)
    data[data.find(b"\n\x05input") + 2] ^= 0x80
    return bytes(data)


def _refused_quietly(capfd: pytest.CaptureFixture[str], path: Path, match: str) -> None:
    """``sdk.load(path)`` is a ModelLoadError matching ``match``, and nothing was printed on the way."""
    capfd.readouterr()
    with pytest.raises(sdk.ModelLoadError, match=match):
        sdk.load(path)
    out, err = capfd.readouterr()
    assert out == "" and "EP Error" not in err


@pytest.mark.parametrize("old_release", [False, True])
def test_a_corrupted_graph_is_refused_without_printing(
    old_release: bool, tmp_path: Path, capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """onnxruntime's Python layer prints an "EP Error" banner to stdout and retries when a session fails
    to build; the SDK never prints, so it turns that fallback off and refuses the file itself. Releases
    1.17-1.22 (``onnxruntime>=1.17`` is the SDK's floor) have no ``enable_fallback`` argument: the
    banner printed there (found by ``make test-floor``); their sessions are built by a subclass that
    clears the flag, a path forced here on the installed release, which reads the same flag."""
    from rtp.sdk import _predictor

    if old_release:
        monkeypatch.setattr(_predictor, "_FALLBACK_KWARG", (10**9,))
        assert sdk.load("jnyang").predict(np.zeros((9, 64, 96), np.float32)).shape == (6, 4, 6)  # it builds sessions
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(_undecodable(Path(sdk.load("jnyang").path or "").read_bytes()))
    _refused_quietly(capfd, bad, "onnxruntime cannot load")


def test_a_checkpoint_or_a_sidecar_given_as_a_model_is_named(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    """`rtp info model.pt` and `sdk.load('model.yaml')` gave protobuf's parsing error alone; what the file looks
    like instead is named, with the step that makes a model of it."""
    import zipfile

    ck = tmp_path / "m.pt"
    with zipfile.ZipFile(ck, "w") as z:  # (a torch checkpoint is a zip)
        z.writestr("m/data.pkl", b"x")
    _refused_quietly(capfd, ck, r"cannot load '.*m\.pt' \(a zip, as a training checkpoint is: export it first, "
                                r"rtp-export .*m\.pt\)")
    sidecar = tmp_path / "m.yaml"
    sidecar.write_text("default_threshold: 0.2\n")
    _refused_quietly(capfd, sidecar, r"\(a metadata sidecar: load the \.onnx model it describes\)")
    other = tmp_path / "x.onnx"
    other.write_bytes(b"\x08garbage")
    with pytest.raises(sdk.ModelLoadError) as info:
        sdk.load(other)
    assert "(a " not in str(info.value)


def test_onnxruntime_releases_are_read_as_numbers() -> None:
    from rtp.sdk import _predictor

    assert _predictor._version(type("ort", (), {"__version__": "1.17.3"})) == (1, 17, 3)
    assert _predictor._version(type("ort", (), {"__version__": "1.22.1"})) < _predictor._FALLBACK_KWARG
    assert _predictor._version(type("ort", (), {"__version__": "1.23.0rc1+cpu"})) >= _predictor._FALLBACK_KWARG
    assert _predictor._version(object()) >= _predictor._FALLBACK_KWARG  # a stand-in without a version


@pytest.mark.parametrize("old_release", [False, True])
def test_a_tail_graph_that_does_not_load_is_refused_without_printing(
    old_release: bool, tmp_path: Path, capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A splitting model whose tail graph matches its digest but does not load (a foreign exporter's
    bug) is a ModelLoadError naming the tail; its session was built with onnxruntime's fallback on,
    so it printed the "EP Error" banner first."""
    import base64
    import json

    import onnx

    from rtp.sdk import _predictor

    if old_release:
        monkeypatch.setattr(_predictor, "_FALLBACK_KWARG", (10**9,))
    model = onnx.load(str(sdk.load("jnyang-reuse").path))
    props = {p.key: p.value for p in model.metadata_props}
    raw = _undecodable(base64.b64decode(props[sdk.TAIL_KEY]))
    props[sdk.TAIL_KEY] = base64.b64encode(raw).decode()
    meta = json.loads(props[sdk.METADATA_KEY])
    meta["tail"] = sdk.model_digest(raw)  # the digest matches: only onnxruntime can refuse it
    props[sdk.METADATA_KEY] = json.dumps(meta)
    onnx.helper.set_model_props(model, props)
    onnx.save(model, str(tmp_path / "tail.onnx"))
    _refused_quietly(capfd, tmp_path / "tail.onnx", "onnxruntime cannot load its tail graph")


def _fake_provider(monkeypatch: pytest.MonkeyPatch, build: Callable[..., object]) -> None:
    """onnxruntime as the SDK sees it, listing a FakeExecutionProvider before CPU and building its
    sessions with ``build(path, sess_options, providers, **kw)``."""
    import types

    import onnxruntime

    from rtp.sdk import _predictor

    fake = types.SimpleNamespace(
        InferenceSession=build, SessionOptions=onnxruntime.SessionOptions,
        get_available_providers=lambda: ["FakeExecutionProvider", "CPUExecutionProvider"],
    )
    monkeypatch.setattr(_predictor, "_ort", lambda: fake)


def test_a_provider_that_cannot_build_the_session_falls_back_to_cpu(
    tiny_model: Callable[..., Path], monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    import onnxruntime

    def session(path: str, sess_options: object = None, providers: list[str] | None = None, **kw: object) -> object:
        if providers != ["CPUExecutionProvider"]:
            raise RuntimeError("FakeExecutionProvider: no device")
        return onnxruntime.InferenceSession(path, sess_options=sess_options, providers=providers, **kw)

    _fake_provider(monkeypatch, session)
    path = tiny_model()
    with caplog.at_level(logging.WARNING, logger="rtp"):
        p = sdk.load(path, providers=["FakeExecutionProvider"])
    assert p.provider == "CPUExecutionProvider" and "no device" in caplog.text
    with pytest.raises(sdk.ProviderUnavailableError, match="could not be built on FakeExecutionProvider"):
        sdk.load(path, providers=["FakeExecutionProvider"], strict=True)



def test_a_session_that_quietly_lands_on_another_provider(
    tiny_model: Callable[..., Path], monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """onnxruntime may build a session for a provider and still place it on CPU (a provider that
    accepts no node of the graph): a warning naming both, an error with strict=True."""
    import onnxruntime

    def session(path: str, sess_options: object = None, providers: list[str] | None = None, **kw: object) -> object:
        return onnxruntime.InferenceSession(path, sess_options=sess_options, providers=["CPUExecutionProvider"], **kw)

    _fake_provider(monkeypatch, session)
    path = tiny_model()
    with caplog.at_level(logging.WARNING, logger="rtp"):
        assert sdk.load(path, providers="FakeExecutionProvider").provider == "CPUExecutionProvider"  # one name
    assert "requested FakeExecutionProvider but the session runs on CPUExecutionProvider" in caplog.text
    with pytest.raises(sdk.ProviderUnavailableError, match="requested FakeExecutionProvider but the session runs on CPU"):
        sdk.load(path, providers="FakeExecutionProvider", strict=True)


def test_providers_that_name_nothing_available(tiny_model: Callable[..., Path], caplog: pytest.LogCaptureFixture) -> None:
    """A list of providers none of which this onnxruntime has falls back to CPU with a warning; with
    strict=True an empty list is refused, not silently run on CPU."""
    path = tiny_model()
    with caplog.at_level(logging.WARNING, logger="rtp"):
        assert sdk.load(path, providers=["NoSuchExecutionProvider"]).provider == "CPUExecutionProvider"
    assert "none of the requested providers is available; falling back to CPUExecutionProvider" in caplog.text
    with pytest.raises(sdk.ProviderUnavailableError, match=r"none of the requested providers \[\] is available"):
        sdk.load(path, providers=[], strict=True)
    assert sdk.load(path, providers="CPUExecutionProvider", strict=True).provider == "CPUExecutionProvider"


def test_metadata_given_as_an_object_or_nothing_usable(tmp_path: Path) -> None:
    """load(metadata=) takes a ModelMetadata (the engine's own, edited; validated as a dict is), and names what
    it takes when given something else."""
    path = build_onnx(tmp_path / "bare.onnx", weights=np.eye(4, dtype=np.float32))
    meta = sdk.ModelMetadata.from_dict(base_metadata(default_threshold=0.125))
    assert sdk.load(path, metadata=meta).metadata == meta
    with pytest.raises(sdk.MetadataError, match="metadata=: expected a dict, a ModelMetadata or a YAML path, got int"):
        sdk.load(path, metadata=42)  # type: ignore[arg-type]


def test_a_model_metadata_object_is_validated_as_a_dict_is(tmp_path: Path) -> None:
    """load(metadata=ModelMetadata) checked nothing: one edited with dataclasses.replace was taken as it was (a
    NaN safety gave every tile 1x1 without a word, a PSNR direction on JNYang inverted every decision, a text
    threshold was a bare TypeError at the first shading_rates)."""
    import dataclasses

    path = build_onnx(tmp_path / "bare.onnx", weights=np.eye(4, dtype=np.float32))
    meta = sdk.ModelMetadata.from_dict(base_metadata())
    assert sdk.load(path, metadata=dataclasses.replace(meta, default_threshold=0.3)).metadata.default_threshold == 0.3
    for change, key in (({"safety": float("nan")}, "safety"), ({"higher_is_better": True}, "higher_is_better"),
                        ({"default_threshold": "0.3"}, "default_threshold"), ({"tile_size": 7}, "tile_size"),
                        ({"inputs": ("albedo.r", "nope", "seen", "normal.z")}, "inputs")):
        with pytest.raises(sdk.MetadataError, match=f"metadata=: {key}") as err:
            sdk.load(path, metadata=dataclasses.replace(meta, **change))
        assert err.value.key == key
    with pytest.raises(sdk.MetadataError, match="metadata=: a ModelMetadata whose fields are not valid"):
        sdk.load(path, metadata=dataclasses.replace(meta, transform={"type": "clamped"}))  # type: ignore[arg-type]


def test_load_takes_numpy_integers_and_flags(tiny_model: Callable[..., Path]) -> None:
    """load(tile_size=np.int64(8)) was refused with "expected one of [4, 8, 16, 32] ..., got np.int64(8)" (a
    tile size read from an array or a device query), threads=np.int64(1) and strict=np.False_ likewise; they are
    kept as Python's, which a pickled copy is loaded again with."""
    import pickle

    path = tiny_model(base_metadata())
    p = sdk.load(path, tile_size=np.int64(8), threads=np.int64(1), strict=np.False_, assume_finite=np.False_,
                 spin_between_runs=np.False_)
    assert p.tile_size == 8 and type(p.tile_size) is int and p.tiles(40, 40) == (5, 5)
    assert p._pickled is not None and all(type(v) in (int, bool) for k, v in p._pickled[1].items()
                                          if k in ("threads", "strict", "assume_finite", "spin_between_runs"))
    assert pickle.loads(pickle.dumps(p)).tile_size == 8
    for bad in (np.float64(8.0), np.True_, 12):
        with pytest.raises(sdk.ParameterError, match="tile_size"):
            sdk.load(path, tile_size=bad)  # type: ignore[arg-type]


def test_a_budget_refuses_what_is_no_frame_with_the_typed_error(tiny_model: Callable[..., Path]) -> None:
    """shading_rates(x, saving=) read the frame's H and W before predict checked it: a scalar or None was a bare
    ValueError ("not enough values to unpack") instead of predict's InputDtypeError."""
    p = sdk.load(tiny_model(base_metadata()))
    for bad in (None, 3.0, np.float32(1.0), "frame"):
        with pytest.raises(sdk.InputDtypeError, match="numpy.ndarray of float32"):
            p.shading_rates(bad, saving=0.5)  # type: ignore[arg-type]


def test_a_fixed_batch_model_takes_exactly_its_batch(tmp_path: Path) -> None:
    """A model exported for a batch of 2 (say, two eyes) runs a batch of 2 as one run and refuses
    any other batch with the shape it expects (only a fixed batch of 1 is looped over frames)."""
    path = build_onnx(tmp_path / "m.onnx", weights=np.ones((2, 4), np.float32), static=(2, 32, 48))
    p = sdk.load(path, metadata=base_metadata(outputs=["1x2", "2x1"]))
    x = np.random.default_rng(0).random((2, 4, 32, 48), dtype=np.float32)
    assert p.predict(x).shape == (2, 6, 2, 3)
    for bad in (x[0], np.concatenate([x, x[:1]])):
        with pytest.raises(sdk.InputShapeError, match="this model has a fixed batch of 2, got [13]") as info:
            p.predict(bad)
        assert info.value.expected == "(2, ...)"


def _odd_model(path: Path, *, int_input: bool = False, rank3_output: bool = False) -> Path:
    """The tiny model's conv, with an int32 input cast to float or an output reduced to rank 3."""
    import onnx
    from onnx import TensorProto, helper

    nodes, src = [], "input"
    if int_input:
        nodes.append(helper.make_node("Cast", ["input"], ["as_float"], to=TensorProto.FLOAT))
        src = "as_float"
    nodes.append(helper.make_node("Conv", [src, "W"], ["conv"], kernel_shape=[1, 1]))
    nodes.append(helper.make_node("MaxPool", ["conv"], ["pool"], kernel_shape=[16, 16], strides=[16, 16]))
    if rank3_output:
        nodes.append(helper.make_node("ReduceMax", ["pool"], ["metric"], keepdims=0, axes=[0]))
        out = helper.make_tensor_value_info("metric", TensorProto.FLOAT, [4, "ty", "tx"])
    else:
        nodes.append(helper.make_node("Identity", ["pool"], ["metric"]))
        out = helper.make_tensor_value_info("metric", TensorProto.FLOAT, ["n", 4, "ty", "tx"])
    graph = helper.make_graph(
        nodes, "odd",
        [helper.make_tensor_value_info("input", TensorProto.INT32 if int_input else TensorProto.FLOAT, ["n", 4, "h", "w"])],
        [out], initializer=[helper.make_tensor("W", TensorProto.FLOAT, [4, 4, 1, 1], np.eye(4).ravel().tolist())],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def test_models_that_are_not_float_nchw_are_refused_at_load(tmp_path: Path) -> None:
    """The SDK feeds float32 NCHW planes and reads an NCHW grid of tiles: a model taking integers or
    giving a rank-3 output is refused when loaded, naming the input or output, not at predict."""
    with pytest.raises(sdk.MetadataError, match=r"expected float32 NCHW inputs, got input input tensor\(int32\)"):
        sdk.load(_odd_model(tmp_path / "int.onnx", int_input=True), metadata=base_metadata())
    with pytest.raises(sdk.MetadataError, match="expected a rank-4 output, got output metric"):
        sdk.load(_odd_model(tmp_path / "r3.onnx", rank3_output=True), metadata=base_metadata())
    p = sdk.load(_odd_model(tmp_path / "ok.onnx"), metadata=base_metadata())  # the same graph, float and rank 4
    assert p.predict_raw(np.ones((4, 32, 32), np.float32)).shape == (4, 2, 2)

# -- a model's tiles on coarser hardware tiles -------------------------------------------------------

def test_pool_tiles_takes_the_worst_fine_tile() -> None:
    v = np.arange(30, dtype=np.float32).reshape(1, 5, 6)  # a partial last row of coarse tiles
    err = sdk.pool_tiles(v, 2)
    assert err.shape == (1, 3, 3) and err.dtype == np.float32
    assert err[0, 0, 0] == 7 and err[0, 2, 2] == 29  # max of [[0, 1], [6, 7]]; the partial tile pools its own
    q = sdk.pool_tiles(v, 2, higher_is_better=True)  # PSNR: the lowest quality is the worst
    assert q[0, 0, 0] == 0 and q[0, 2, 2] == 28
    assert np.array_equal(sdk.pool_tiles(v, 1), v)
    with pytest.raises(sdk.ParameterError):
        sdk.pool_tiles(v, 0)
    # a factor past the grid pools one tile without padding to its size (100000: 224 GiB before)
    assert np.array_equal(sdk.pool_tiles(v, 100000), v.max(axis=(-2, -1), keepdims=True))
    with pytest.raises(sdk.ParameterError, match="numbers"):
        sdk.pool_tiles(np.array([["a", "b"], ["c", "d"]]), 2)
    # a direction that is no flag ('no' was taken for True: errors pooled to their best tile, not their worst)
    for flag in ("no", None, 0):
        with pytest.raises(sdk.ParameterError, match="higher_is_better"):
            sdk.pool_tiles(v, 2, higher_is_better=flag)  # type: ignore[arg-type]
    assert np.array_equal(sdk.pool_tiles(v, 2, higher_is_better=np.True_), q)
    # integers pool exactly, in their own type (through float64 2**60 + 1 came back as 2**60)
    big = np.array([[2**60 + 1, 1, 5], [2, 3, 7]], np.int64)
    assert sdk.pool_tiles(big, 2).tolist() == [[2**60 + 1, 7]]
    assert sdk.pool_tiles(big, 2, higher_is_better=True).tolist() == [[1, 5]]
    assert sdk.pool_tiles(np.array([[True, False, False]]), 2).tolist() == [[True, False]]


def test_the_small_helpers_refuse_what_they_cannot_read() -> None:
    """Found by an error-handling audit: each gave a bare IndexError, TypeError, OverflowError or
    KeyError, or read a planar image as rows of pixels."""
    with pytest.raises(sdk.InputShapeError, match=r"\(\.\.\., 3\)"):
        sdk.luma(0.5)
    with pytest.raises(sdk.InputShapeError, match="planar"):
        sdk.luma(np.zeros((3, 8, 16), np.float32))
    assert sdk.luma(np.ones((2, 3), np.float32)).shape == (2,)
    for bad in (b"garbage\xff\xff", "a string", None):
        with pytest.raises(sdk.ParameterError, match="model_digest"):
            sdk.model_digest(bad)  # type: ignore[arg-type]
    for length in (2**70, 0, 1.5):
        with pytest.raises(sdk.ParameterError, match="length"):
            sdk.tile_extents(length)  # type: ignore[arg-type]
    with pytest.raises(sdk.ParameterError, match="strict"):
        sdk.load("jnyang", strict="yes")  # type: ignore[arg-type]
    for fn in (sdk.luma, sdk.srgb_to_linear, sdk.linear_to_srgb, sdk.psnr_from_mse, sdk.mse_from_psnr):
        for bad, words in (("abc", "expected numbers"), (np.ones((2, 3), complex), "real numbers")):
            with pytest.raises(sdk.InputDtypeError, match=words):
                fn(bad)
    with pytest.raises(sdk.ParameterError, match=r"\['2x1'\] missing"):
        sdk.complete_rates({"1x2": np.zeros(2)}, ("1x2", "2x1"), 2.13, False, np.maximum, np.minimum)


def test_an_8_pixel_model_on_16_pixel_hardware_tiles(tiny_model: Callable[..., Path]) -> None:
    meta = base_metadata(tile_size=8, default_threshold=0.5)
    path = tiny_model(meta, tile=8)
    fine, coarse = sdk.load(path), sdk.load(path, tile_size=16)
    assert (fine.tile_size, coarse.tile_size, coarse.metadata.tile_size) == (8, 16, 8)
    x = np.random.default_rng(3).standard_normal((4, 40, 56)).astype(np.float32)  # 5x7 fine, 3x4 coarse tiles
    assert coarse.tiles(40, 56) == (3, 4) and coarse.predict(x).shape == (6, 3, 4)
    np.testing.assert_array_equal(coarse.predict(x), sdk.pool_tiles(fine.predict(x), 2))
    assert coarse.predict_raw(x).shape == fine.predict_raw(x).shape == (4, 5, 7)  # the network's own tiles
    rates = coarse.shading_rates(x)
    assert rates.shape == (3, 4)
    # a coarse tile's rate passes on every fine tile it covers (the worst of them decided)
    fine_pred = fine.predict(x)
    for (r, c), code in np.ndenumerate(rates):
        if code != sdk.RATE_CODES["1x1"]:
            i = sdk.PREDICTED_RATES.index(sdk.RATE_NAMES[int(code)])
            assert (fine_pred[i, 2 * r:2 * r + 2, 2 * c:2 * c + 2] < 0.5).all()
    for bad in (2, 12, 64, True, "16"):  # (4 is a finer hardware tile: the next test)
        with pytest.raises(sdk.ParameterError, match="tile_size"):
            sdk.load(path, tile_size=bad)  # type: ignore[arg-type]


def test_split_tiles_gives_each_fine_tile_its_coarse_tiles_value() -> None:
    v = np.arange(12, dtype=np.float32).reshape(1, 3, 4)
    fine = sdk.split_tiles(v, 2)
    assert fine.shape == (1, 6, 8) and fine.dtype == np.float32
    assert (fine[0, 2:4, 4:6] == v[0, 1, 2]).all() and np.array_equal(sdk.pool_tiles(fine, 2), v)
    # cropped to a frame's fine grid: 40x56 pixels are 3x4 16-pixel tiles and 5x7 8-pixel ones
    assert np.array_equal(sdk.split_tiles(v, 2, (5, 7)), fine[..., :5, :7])
    codes = np.full((2, 2), sdk.RATE_CODES["2x2"], np.uint8)
    assert sdk.split_tiles(codes, 4).dtype == np.uint8 and np.array_equal(sdk.split_tiles(codes, 1), codes)
    for grid in ((4, 7), (6, 9), (5,), "57", (5, 0), {"a": 5, "b": 7}, 5):  # no fine grid of these tiles (a mapping, a number)
        with pytest.raises(sdk.ParameterError, match="grid"):
            sdk.split_tiles(v, 2, grid)  # type: ignore[arg-type]
    for bad in (0, 1.5, True):
        with pytest.raises(sdk.ParameterError, match="factor"):
            sdk.split_tiles(v, bad)  # type: ignore[arg-type]
    with pytest.raises(sdk.ParameterError, match="factor"):
        sdk.split_tiles(v, 2**30)  # (past any frame: refused, not 8 EiB asked of numpy)
    with pytest.raises(sdk.ParameterError, match="values"):
        sdk.split_tiles(np.zeros(3), 2)


def test_a_16_pixel_model_on_8_pixel_hardware_tiles(tiny_model: Callable[..., Path]) -> None:
    """AMD's and Intel's shading-rate images have 8-pixel tiles (NVIDIA's 16): ``load(tile_size=8)`` of
    a 16-pixel model gives each hardware tile the values, and so the rate, of the model tile it lies in,
    on the frame's own 8-pixel grid (a partial last model tile may hold one 8-pixel row fewer)."""
    meta = base_metadata(tile_size=16, default_threshold=0.5)
    path = tiny_model(meta, tile=16)
    own, fine = sdk.load(path), sdk.load(path, tile_size=8)
    assert (fine.tile_size, fine.metadata.tile_size) == (8, 16) and "tile=8 (model 16)" in repr(fine)
    x = np.random.default_rng(4).standard_normal((4, 40, 56)).astype(np.float32)  # 3x4 model, 5x7 hardware tiles
    assert fine.tiles(40, 56) == (5, 7) and fine.predict(x).shape == (6, 5, 7)
    np.testing.assert_array_equal(fine.predict(x), sdk.split_tiles(own.predict(x), 2, (5, 7)))
    np.testing.assert_array_equal(fine.shading_rates(x), sdk.split_tiles(own.shading_rates(x), 2, (5, 7)))
    batch = np.stack([x, -x])
    assert fine.predict(batch).shape == (2, 6, 5, 7)
    assert fine.predict_raw(x).shape == own.predict_raw(x).shape  # the network's own tiles
    assert sdk.load(path, tile_size=4).predict(x).shape == (6, 10, 14)
    with pytest.raises(sdk.ParameterError, match=r"expected one of \[4, 8, 16, 32\].*finer, down to one 4x4"):
        sdk.load(path, tile_size=2)
    # the sizes a model runs on, public for an engine to ask before it loads one for its hardware
    assert sdk.hardware_tiles(16) == (4, 8, 16, 32) and sdk.hardware_tiles(2) == (2, 4, 8, 16, 32)
    for bad in (12, 0, True, 16.0, "16"):
        with pytest.raises(sdk.ParameterError, match=r"model_tile: expected a model's tile size, one of \[1, 2"):
            sdk.hardware_tiles(bad)  # type: ignore[arg-type]
    assert sdk.PredictionReuse(fine).predictor is fine  # reused on the model's tiles, then split (test_reuse.py)


def test_big_endian_planes_and_a_combiner_without_engine_rates_are_named() -> None:
    """'>f4' planes were refused as "expected dtype float32, got >f4" (float32, by the look of it), and a
    misspelt combiner passed unnoticed until engine rates came along."""
    predictor = sdk.load("jnyang")
    x = np.zeros((len(predictor.metadata.inputs), 32, 32), np.float32)
    with pytest.raises(sdk.InputDtypeError, match="expected dtype float32 in native byte order, got >f4"):
        predictor.predict(x.astype(">f4"))
    with pytest.raises(sdk.InputDtypeError, match="expected dtype float32, got float64"):
        predictor.predict(x.astype(np.float64))
    with pytest.raises(sdk.ParameterError, match="combiner: expected one of min, max, sum"):
        predictor.shading_rates(x, combiner="avg")
    assert predictor.shading_rates(x, combiner="min").shape == (2, 2)


def test_frames_that_cut_packed_planes_warn_once_per_size(caplog: pytest.LogCaptureFixture) -> None:
    """A .blocks plane packs each 4x4 cell's six values on its first two rows, four columns: a 97x33 frame's last
    cell column is one pixel wide, so five of its values were lost and the network read copies of the last
    column in their place (the shipped JNYang's last tile column moved by up to 0.48 in transformed space
    against the planes of the edge-padded frame), with no word. A .tiles plane's twelve values need W mod 16
    outside 1-3 and H mod 16 outside 1-2."""
    rng = np.random.default_rng(0)

    def warned(model: sdk.ShadingRatePredictor, h: int, w: int) -> list[str]:
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="rtp"):
            model.predict(rng.random((len(model.metadata.inputs), h, w), dtype=np.float32))
        return [r.getMessage() for r in caplog.records if "cuts the last" in r.getMessage()]

    blocks, tiles, plain = sdk.load("jnyang"), sdk.load("jnyang-reuse"), sdk.load("lpips")
    got = warned(blocks, 33, 97)
    assert len(got) == 1 and "a 97x33 frame cuts the last 4x4 cells of its reprojected.y.blocks, albedo.y.blocks" \
        in got[0] and "multiples of 4" in got[0]
    assert warned(blocks, 33, 97) == []  # once per size
    assert len(warned(blocks, 33, 96)) == 1  # a height of 4k + 1: the cells' second row (4x2, 4x4) is lost
    assert len(warned(blocks, 36, 98)) == 1
    for h, w in ((36, 96), (35, 96), (34, 100), (60, 100)):  # every value inside the frame
        assert warned(blocks, h, w) == [], (h, w)
    got = warned(tiles, 33, 96)
    assert len(got) == 1 and "16-pixel tiles of its reprojected.y.tiles, albedo.y.tiles planes" in got[0]
    assert len(warned(tiles, 32, 99)) == 1
    for h, w in ((35, 97 + 3), (36, 100), (60, 100)):  # W mod 16 of 4, H mod 16 of 3: all twelve inside
        assert warned(tiles, h, w) == [], (h, w)
    assert warned(plain, 33, 97) == []  # no packed planes: nothing is cut


def test_a_threshold_no_tile_can_pass_is_said(tiny_model: Callable[..., Path], caplog: pytest.LogCaptureFixture) -> None:
    """A threshold beyond the best value the model can express (its margin moves every output towards the worse
    side: clamped, mu 0.25, safety 0.1 predicts no error below 0.05) passes no tile at any rate: every tile got 1x1 on
    every frame, and the predictor saved nothing without a word (a threshold in another metric's units, a percentage
    read as a share). Now ``shading_rates`` says so once per threshold, through a ``PredictionReuse`` too, and names
    the threshold to go past; a PSNR one beyond its best (highest) value the same."""
    w = np.zeros((2, 4), np.float32)
    w[:, 0] = -40.0  # sigmoid(-40 x): the best output, 0, where plane 0 is 1
    x = np.zeros((4, 16, 16), np.float32)
    x[0] = 1.0
    p = sdk.load(tiny_model(base_metadata(outputs=["1x2", "2x1"], safety=0.1, default_threshold=0.2), weights=w))
    assert float(p.predict(x).min()) == pytest.approx(0.05)
    caplog.set_level(logging.WARNING, logger="rtp")
    for _ in range(2):
        assert p.shading_rates(x, threshold=0.04).tolist() == [[sdk.RATE_CODES["1x1"]]]
    warned = [r.getMessage() for r in caplog.records]
    assert len(warned) == 1 and "threshold 0.04 is beyond the best value the model can express (0.05)" in warned[0]
    assert "no tile passes it at any rate" in warned[0] and "use one above 0.05" in warned[0]
    caplog.clear()
    assert p.shading_rates(x, threshold=0.06).tolist() == [[sdk.RATE_CODES["2x2"]]]  # (just past it: some pass)
    assert p.shading_rates(x).tolist() == [[sdk.RATE_CODES["4x4"]]] and not caplog.records  # (0.2 > 2.13 x 0.05)
    reuse = sdk.PredictionReuse(p, 2)
    assert reuse.shading_rates(x, threshold=0.01).tolist() == [[sdk.RATE_CODES["1x1"]]]
    assert len(caplog.records) == 1 and "threshold 0.01 is beyond the best value" in caplog.text
    caplog.clear()
    psnr = sdk.load(tiny_model(base_metadata(metric="psnr", higher_is_better=True, weber_l=None,
                                             transform={"type": "clamped", "mu_y": 25.0}, safety=0.1,
                                             outputs=["1x2", "2x1"], default_threshold=30.0), weights=-w))
    assert float(psnr.predict(x).max()) == pytest.approx(45.0)  # (2 mu (1 - safety): the best PSNR it can say)
    assert psnr.shading_rates(x, threshold=46.0).tolist() == [[sdk.RATE_CODES["1x1"]]]
    assert "threshold 46 is beyond the best value the model can express (45)" in caplog.text
    assert "use one below 45" in caplog.text
    caplog.clear()
    assert psnr.shading_rates(x, threshold=44.0).tolist() == [[sdk.RATE_CODES["2x2"]]] and not caplog.records


def test_shading_rates_refuses_a_bad_threshold_before_the_network_runs(tiny_model: Callable[..., Path],
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """A threshold shading_rates refuses (NaN, negative, past the metric's range) came back only after a whole frame's
    network run: it is checked first, with or without a saving."""
    p = sdk.load(tiny_model(base_metadata(outputs=["1x2", "2x1"])))
    x = np.zeros((4, 16, 16), np.float32)
    runs = [0]
    real = type(p).predict

    def counted(self: Any, *args: Any, **kwargs: Any) -> Any:
        runs[0] += 1
        return real(self, *args, **kwargs)

    monkeypatch.setattr(type(p), "predict", counted)
    for kw in ({}, {"saving": 0.5}):
        for bad in (float("nan"), -1.0):
            with pytest.raises(sdk.ParameterError, match="threshold"):
                p.shading_rates(x, threshold=bad, **kw)
    assert runs[0] == 0
    p.shading_rates(x, threshold=0.2)
    assert runs[0] == 1


def test_a_budget_s_floor_past_saturation_is_said(tiny_model: Callable[..., Path],
                                                   caplog: pytest.LogCaptureFixture) -> None:
    """A ``threshold`` beside a ``saving`` is a floor under the budget: the rates of the looser of the two. A floor
    beyond the worst value the model can express passes every tile at the coarsest rate on every frame, whatever the
    budget, and shading_rates(saving=, threshold=) (and PredictionReuse's) said nothing, where the same threshold
    alone is warned of. Now it is said once per threshold, in the same words; a floor beyond the best value is not
    (the budget's rates are taken, as without a floor: nothing is switched off)."""
    p = sdk.load(tiny_model(base_metadata(outputs=["1x2", "2x1"], safety=0.1, default_threshold=0.2)))
    x = np.random.default_rng(0).random((4, 32, 32)).astype(np.float32)
    caplog.set_level(logging.WARNING, logger="rtp")
    for _ in range(2):
        assert (p.shading_rates(x, threshold=100.0, saving=0.1) == sdk.RATE_CODES["4x4"]).all()
    warned = [r.getMessage() for r in caplog.records]
    assert len(warned) == 1 and "threshold 100 is beyond the worst value the model can express" in warned[0]
    assert warned[0] == p.metadata.threshold_warning(100.0).join([f"{p.path.name}: ", ""])  # type: ignore[union-attr]
    caplog.clear()
    assert p.shading_rates(x, threshold=0.01, saving=0.5) is not None and not caplog.records  # (the budget decides)
    assert p.metadata.threshold_warning(0.01) is not None and p.metadata.threshold_warning(0.01, budget=True) is None
    reuse = sdk.PredictionReuse(p, 2)
    assert (reuse.shading_rates(x, threshold=150.0, saving=0.1) == sdk.RATE_CODES["4x4"]).all()
    assert len(caplog.records) == 1 and "threshold 150 is beyond the worst value" in caplog.text
