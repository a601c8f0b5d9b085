"""examples/runtime_without_rtp.py, the runtime contract written out with numpy and onnxruntime alone,
gives the shading-rate image rtp.sdk gives, tile for tile, for every shipped model: what docs/metadata.md
and docs/runtime.md say is all an engine needs (a step the pages leave out would show here)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from rtp import sdk

from .test_shipped_models import rendered_inputs  # noqa: F401 (a fixture)

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "runtime_without_rtp.py"


@pytest.fixture(scope="module")
def port() -> ModuleType:
    spec = importlib.util.spec_from_file_location("runtime_without_rtp", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _planes(frame: object, names: tuple[str, ...]) -> np.ndarray:
    return np.stack([frame.channel(c) for c in names]).astype(np.float32)  # type: ignore[attr-defined]


@pytest.mark.gl
@pytest.mark.parametrize("name", sdk.shipped_models())
def test_the_port_picks_the_sdks_rates_on_rendered_frames(name: str, port: ModuleType, rendered_inputs: list) -> None:  # noqa: F811
    import onnxruntime as ort

    p = sdk.load(name)
    session = ort.InferenceSession(str(p.path), providers=["CPUExecutionProvider"])
    own = p.metadata.tile_size
    tiles = [own, 32] + ([8] if own == 16 else [16])
    uniform, combinations = [], 0
    for frame in rendered_inputs:
        x = _planes(frame, p.metadata.inputs)[:, :-5, 3:]  # a frame of partial tiles (219x381)
        values = p.predict(x)
        # thresholds where the decisions are mixed: quantiles of the model's own predictions
        for threshold in [None, *np.quantile(values[np.isfinite(values)], [0.2, 0.5, 0.8]).tolist()]:
            for tile in tiles:
                for allowed in (port.RATES, ("1x2", "2x1", "2x2")):
                    theirs = sdk.load(name, tile_size=tile).shading_rates(x, threshold, allowed=allowed)
                    ours = port.shading_rates(session, x, threshold, tile, allowed)
                    assert ours.dtype == np.uint8 and ours.shape == theirs.shape
                    np.testing.assert_array_equal(ours, theirs, err_msg=f"{name} threshold {threshold} tile {tile} "
                                                                          f"allowed {allowed}")
                    if threshold is not None:
                        combinations += 1
                        if len(np.unique(theirs)) < 2:
                            uniform.append((threshold, tile, allowed))
        for tile in tiles:  # a budget (step 7) on the same frames
            for allowed in (port.RATES, ("1x2", "2x1", "2x2")):
                theirs = sdk.load(name, tile_size=tile).shading_rates(x, allowed=allowed, saving=0.55)
                np.testing.assert_array_equal(port.shading_rates(session, x, None, tile, allowed, 0.55), theirs,
                                              err_msg=f"{name} saving 0.55 tile {tile} allowed {allowed}")
    # at the quantiles the decisions are mixed, not one rate everywhere (on 32-pixel tiles, each the worst of
    # four, a high quality threshold can leave every tile at full rate)
    assert len(uniform) <= combinations // 8, uniform


def test_the_port_imports_nothing_of_rtp(tmp_path: Path) -> None:
    """Run with rtp made unimportable: the port needs only numpy and onnxruntime (and --check, rtp)."""
    frame = tmp_path / "planes.npy"
    p = sdk.load("flip")
    rng = np.random.default_rng(0)
    np.save(frame, rng.random((len(p.metadata.inputs), 90, 150), dtype=np.float32) * 0.2)
    blocked = ("import runpy, sys; sys.modules['rtp'] = None; sys.argv = sys.argv[1:]; "
               "runpy.run_path(sys.argv[0], run_name='__main__')")
    r = subprocess.run([sys.executable, "-c", blocked, str(EXAMPLE), str(p.path), "--frame", str(frame),
                        "--threshold", "0.05"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("flip.onnx: 6x10 tiles;"), r.stdout
    r = subprocess.run([sys.executable, str(EXAMPLE), str(p.path), "--frame", str(frame), "--threshold", "0.05",
                        "--tile-size", "8", "--check"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "the same rate on 100.00% of the tiles" in r.stdout, r.stdout + r.stderr


# (a steep logistic, k mu_y past 709, overflowed the port's 1 / (1 + exp(-v)) where the SDK's tanh form does not)
TRANSFORMS = [{"type": "clamped", "mu_y": 0.12}, {"type": "logistic", "mu_y": 0.3, "k": 10.0},
              {"type": "logistic", "mu_y": 0.5, "k": 2000.0},
              {"type": "linear", "factor": -0.015, "offset": 1.0}, {"type": "linear", "factor": 0.7, "offset": 0.0}]


@pytest.mark.parametrize("outputs", [["1x2", "2x1"], ["1x2", "2x1", "2x4", "4x2"], list(sdk.PREDICTED_RATES), ["2x2"]])
@pytest.mark.parametrize("transform", TRANSFORMS, ids=lambda t: f"{t['type']}{t.get('factor', '')}{t.get('k', '')}")
@pytest.mark.parametrize("metric", ["jnyang", "psnr"])
def test_the_ports_decode_is_the_sdks_for_every_transform_and_output_set(
    metric: str, transform: dict, outputs: list[str], port: ModuleType,
) -> None:
    """What no shipped model reads (two outputs, one 2x2 output, a logistic transform) decodes the same too."""
    meta = {"metric": metric, "transform": transform, "tile_size": 16, "inputs": ["reprojected.y", "seen"],
            "outputs": outputs, "default_threshold": 30.0 if metric == "psnr" else 0.2, "safety": 0.05,
            "extrapolation_k": 2.5, **({"weber_l": 0.02} if metric.startswith("jn") else {})}
    raw = np.random.default_rng(len(outputs)).random((len(outputs), 7, 9), dtype=np.float32)
    np.testing.assert_array_equal(port.decode(raw, meta), sdk.ModelMetadata.from_dict(meta).decode(raw))


@pytest.mark.parametrize("higher_is_better", [False, True])
def test_the_ports_selection_is_the_sdks_on_ties_nans_and_factors(higher_is_better: bool, port: ModuleType) -> None:
    """Values on a coarse grid of levels (equal-cost rates tie often), NaNs, and a threshold per rate."""
    rng = np.random.default_rng(int(higher_is_better))
    values = rng.integers(0, 6, (6, 40, 50)).astype(np.float32) * (6.0 if higher_is_better else 0.05)
    values[rng.random(values.shape) < 0.05] = np.nan
    factors = dict(zip(sdk.PREDICTED_RATES, [1.0, 1.0, 0.9, 1.2, 1.2, 0.8]))
    for rate_factors in (None, factors):
        meta = {"metric": "psnr" if higher_is_better else "flip", "higher_is_better": higher_is_better,
                **({"rate_factors": rate_factors} if rate_factors else {})}
        for threshold in ((12.0, 18.0, 24.0) if higher_is_better else (0.1, 0.15, 0.2)):
            for allowed in (port.RATES, ("1x2", "2x1", "2x4", "4x2"), ("2x2",)):
                theirs = sdk.select_rates(values, threshold, higher_is_better=higher_is_better, allowed=allowed,
                                          factors=rate_factors)
                np.testing.assert_array_equal(port.select(values, meta, threshold, allowed), theirs)


@pytest.mark.parametrize("higher_is_better", [False, True])
def test_the_ports_budget_is_the_sdks(higher_is_better: bool, port: ModuleType) -> None:
    """Step 7 (a saving instead of a threshold) gives the SDK's rates and threshold: ties, NaNs, a threshold
    per rate, allowed subsets, partial edge tiles, no saving and the most there is."""
    rng = np.random.default_rng(2 + int(higher_is_better))
    values = rng.integers(0, 12, (6, 40, 50)).astype(np.float32) * (3.0 if higher_is_better else 0.03)
    values[rng.random(values.shape) < 0.03] = np.nan
    factors = dict(zip(sdk.PREDICTED_RATES, [1.0, 1.0, 0.9, 1.2, 1.2, 0.8]))
    frame = (40 * 16 - 5, 50 * 16 - 11)
    for rate_factors in (None, factors):
        meta = {"metric": "psnr" if higher_is_better else "flip", "higher_is_better": higher_is_better,
                **({"rate_factors": rate_factors} if rate_factors else {})}
        for allowed in (port.RATES, ("1x2", "2x1", "2x4", "4x2"), ("2x2",)):
            top = max(sdk.work_saved(r) for r in allowed)
            for saving in (0.0, 0.3, 0.6, top):
                theirs = sdk.select_rates_for_saving(values, saving, higher_is_better=higher_is_better, allowed=allowed,
                                                     factors=rate_factors, frame_size=frame, tile_size=16)
                rates, threshold = port.select_for_saving(values, meta, saving, allowed, frame, 16)
                np.testing.assert_array_equal(rates, theirs.rates, err_msg=f"{allowed} {saving}")
                assert threshold == theirs.threshold, (allowed, saving)
                for under in ((6.0, 18.0) if higher_is_better else (0.06, 0.18)):  # the saving a floor under it
                    floor = sdk.select_rates_for_saving(values, saving, higher_is_better=higher_is_better,
                                                        allowed=allowed, factors=rate_factors, frame_size=frame,
                                                        tile_size=16, threshold=under)
                    rates, threshold = port.select_for_saving(values, meta, saving, allowed, frame, 16, under)
                    np.testing.assert_array_equal(rates, floor.rates, err_msg=f"{allowed} {saving} under {under}")
                    assert threshold == floor.threshold, (allowed, saving, under)


@pytest.mark.parametrize("higher_is_better", [False, True])
def test_the_ports_selection_beside_engine_rates_is_the_sdks(higher_is_better: bool, port: ModuleType) -> None:
    """Step 8: the port's rates beside an engine's, for each combiner, allowed sets where the device clamps (and
    may choose between two), ties, NaNs and a threshold per rate, are the SDK's."""
    rng = np.random.default_rng(5 + int(higher_is_better))
    values = rng.integers(0, 6, (6, 30, 40)).astype(np.float32) * (6.0 if higher_is_better else 0.05)
    values[rng.random(values.shape) < 0.05] = np.nan
    factors = dict(zip(sdk.PREDICTED_RATES, [1.0, 1.0, 0.9, 1.2, 1.2, 0.8]))
    meta = {"metric": "psnr" if higher_is_better else "flip", "higher_is_better": higher_is_better,
            "rate_factors": factors}
    threshold = 18.0 if higher_is_better else 0.15
    for allowed in (port.RATES, ("1x2", "2x1", "4x4"), ("1x2", "2x1", "2x4", "4x2"), ("2x2",), ("1x2",)):
        supported = [sdk.RATE_CODES[r] for r in ("1x1", *allowed)]
        engine = rng.choice(supported, size=(30, 40)).astype(np.uint8)
        for combiner in ("min", "max", "sum"):
            theirs = sdk.select_rates(values, threshold, higher_is_better=higher_is_better, allowed=allowed,
                                      factors=factors, engine_rates=engine, combiner=combiner)
            np.testing.assert_array_equal(port.select_beside(values, meta, threshold, engine, combiner, allowed), theirs,
                                          err_msg=f"{allowed} {combiner}")


@pytest.mark.parametrize("higher_is_better", [False, True])
def test_the_ports_budget_beside_engine_rates_is_the_sdks(higher_is_better: bool, port: ModuleType) -> None:
    """Steps 7 and 8 together: the port's rates and threshold for a saving beside an engine's rates (each combiner,
    allowed sets where the device clamps, ties, NaNs, a threshold per rate, partial edge tiles, a floor, a saving
    the engine's rates already make) are the SDK's."""
    rng = np.random.default_rng(7 + int(higher_is_better))
    values = rng.integers(0, 12, (6, 30, 40)).astype(np.float32) * (3.0 if higher_is_better else 0.03)
    values[:, 15:] = rng.random((6, 15, 40)) * (36.0 if higher_is_better else 0.36)  # (ties above, none below)
    values[rng.random(values.shape) < 0.03] = np.nan
    factors = dict(zip(sdk.PREDICTED_RATES, [1.0, 1.0, 0.9, 1.2, 1.2, 0.8]))
    frame = (30 * 16 - 5, 40 * 16 - 11)
    meta = {"metric": "psnr" if higher_is_better else "flip", "higher_is_better": higher_is_better,
            "rate_factors": factors}
    for allowed in (port.RATES, ("1x2", "2x1", "4x4"), ("1x2", "2x1", "2x4", "4x2"), ("2x2",)):
        supported = [sdk.RATE_CODES[r] for r in ("1x1", *allowed)]
        engine = rng.choice(supported, size=(30, 40)).astype(np.uint8)
        top = max(sdk.work_saved(r) for r in allowed)
        for combiner in ("min", "max", "sum"):
            for saving, under in ((0.05, None), (0.2, None), (0.3, None), (0.4, None), (0.45, None), (0.7 * top, None),
                                  (top, None), (0.4, 12.0 if higher_is_better else 0.12)):
                theirs = sdk.select_rates_for_saving(values, saving, higher_is_better=higher_is_better,
                                                     allowed=allowed, factors=factors, frame_size=frame, tile_size=16,
                                                     threshold=under, engine_rates=engine, combiner=combiner)
                rates, threshold = port.select_for_saving(values, meta, saving, allowed, frame, 16, under, engine,
                                                          combiner)
                np.testing.assert_array_equal(rates, theirs.rates, err_msg=f"{allowed} {combiner} {saving} {under}")
                assert threshold == theirs.threshold, (allowed, combiner, saving, under)


@pytest.mark.parametrize(("args", "words"), [
    (["--tile-size", "7"], "invalid choice: 7"),
    (["--allowed", "3x3"], "--allowed: 3x3 is no reduced rate"),
    (["--allowed", "2x2,2x2"], "--allowed: each rate once, got 2x2 more than once in '2x2,2x2'"),
    (["--threshold", "nan"], "--threshold: expected a finite number"),
    (["--size", "abc"], "--size: expected WIDTHxHEIGHT"),
    (["--size", "0x0"], "--size: expected WIDTHxHEIGHT"),
    # what the SDK refuses (ParameterError) the port ran: a budget past what the allowed rates save (every tile at
    # 1x2, 50% saved for 90% asked, in silence), an error threshold below 0, an engine rate the device lacks
    (["--allowed", "1x2", "--saving", "0.9"], "--saving: expected a share of the shading work in [0, 0.5]"),
    (["--allowed", "", "--saving", "0.1"], "--saving: expected a share of the shading work in [0, 0]"),
    (["--threshold", "-5"], "--threshold: expected a finite number in [0, 1e+06] for an error metric"),
    (["--threshold", "2e6"], "--threshold: expected a finite number in [0, 1e+06]"),
    (["--engine-rate", "4x4", "--allowed", "1x2"], "--engine-rate: 4x4 is not among the rates allowed (1x1, 1x2)"),
])
def test_the_ports_command_line_refuses_what_it_cannot_run(port: ModuleType, args: list[str], words: str,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """The file engines port ran a 7-pixel tile on the 8-pixel grid, an unknown rate and a NaN threshold in
    silence, and ended --size abc and 0x0 in tracebacks (a ZeroDivisionError for --tile-size 0); a rate
    allowed twice (--allowed 2x2,2x2) ran as that rate alone, as rtp predict's did. The ranges the SDK takes
    it refuses as the SDK does (with --check these were the SDK's traceback after the port's rates)."""
    with pytest.raises(SystemExit) as info:
        port.main([str(sdk.load("jnyang").path), *args])
    assert info.value.code == 2 and words in capsys.readouterr().err


def test_the_ports_command_line_says_what_is_wrong_with_its_files(port: ModuleType, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A --frame that is not there, not a .npy, empty or holding a NaN, and a model file that is no ONNX model, were
    tracebacks (FileNotFoundError, onnxruntime's InvalidProtobuf) or ran (a NaN frame, which the SDK refuses); each is
    now a usage error, exit 2, naming the file and what was expected."""
    model = str(sdk.load("jnyang").path)
    nan = np.zeros((9, 20, 24), np.float32)
    nan[7, 3, 5] = np.nan
    np.save(tmp_path / "nan.npy", nan)
    np.save(tmp_path / "empty.npy", np.zeros((9, 0, 24), np.float32))
    (tmp_path / "text.npy").write_text("not an array")
    (tmp_path / "model.onnx").write_text("not a model")
    for args, words in (([model, "--frame", str(tmp_path / "none.npy")], "--frame: cannot read"),
                        ([model, "--frame", str(tmp_path / "text.npy")], "--frame: cannot read"),
                        ([model, "--frame", str(tmp_path / "empty.npy")], "H and W at least 1, got float32 (9, 0, 24)"),
                        ([model, "--frame", str(tmp_path / "nan.npy")],
                         "--frame: holds 1 NaN or infinite values (first at (7, 3, 5), plane 'reprojected.y.blocks')"),
                        ([str(tmp_path / "model.onnx")], "cannot be read as an rtp ONNX model")):
        with pytest.raises(SystemExit) as info:
            port.main(args)
        err = capsys.readouterr().err
        assert info.value.code == 2 and words in err, (args, err)


@pytest.mark.parametrize("name", ["jnyang", "jnyang-reuse", "jnflip"])
def test_the_port_warns_where_the_frame_cuts_its_packed_planes(name: str, port: ModuleType,
                                                                caplog: pytest.LogCaptureFixture) -> None:
    """docs/runtime.md (step 2) says predict warns, once per frame size, where a frame cuts the cells of its .blocks
    or .tiles planes; the port, what an engine ports, said nothing. It warns at the sizes the SDK does, once each."""
    import logging

    import onnxruntime as ort

    p = sdk.load(name)
    session = ort.InferenceSession(str(p.path), providers=["CPUExecutionProvider"])
    port._WARNED_CUTS.clear()
    for h, w in ((33, 97), (34, 97), (35, 98), (33, 100), (34, 96), (60, 100), (18, 19), (19, 16), (36, 99)):
        x = np.random.default_rng(h * w).random((len(p.metadata.inputs), h, w), dtype=np.float32)
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            p.predict(x)
            sdk_warned = any("cuts the last" in r.getMessage() for r in caplog.records)
            caplog.clear()
            port.shading_rates(session, x)
            port.shading_rates(session, x)  # (once per frame size)
        ours = [r for r in caplog.records if r.name == "runtime_without_rtp"]
        assert len(ours) == int(sdk_warned), (name, h, w, [r.getMessage() for r in ours])
        assert bool(port.cut_planes(p.metadata.to_dict(), h, w)) == sdk_warned, (name, h, w)
        if ours:
            assert f"a {w}x{h} frame cuts the last cells of its" in ours[0].getMessage()
    if name == "jnflip":  # (no packed planes: no warning at any size)
        assert not port._WARNED_CUTS


def _free_plane_count(path: Path) -> Path:
    """The model at ``path`` with its one input's plane count made symbolic, as an exporter with every axis
    dynamic writes it (sdk.load takes it: one input takes every plane)."""
    import onnx

    model = onnx.load(str(path))
    dim = model.graph.input[0].type.tensor_type.shape.dim[1]
    dim.ClearField("dim_value")
    dim.dim_param = "planes"
    onnx.save(model, str(path))
    return path


@pytest.mark.parametrize(("case", "overrides", "build", "tiles"), [
    ("free plane count", {}, {}, (None, 8, 32)),
    ("fixed size", {}, {"static": (1, 64, 80)}, (None, 8, 32)),
    ("fixed size of partial tiles", {}, {"static": (1, 40, 56), "ceil_mode": True}, (None, 8)),
    ("2x2 alone", {"outputs": ["2x2"]}, {}, (None, 8, 32)),
    ("8-pixel tiles", {"tile_size": 8}, {}, (None, 4, 16, 32)),
    ("psnr, 2x2 alone", {"metric": "psnr", "outputs": ["2x2"], "default_threshold": 30.0, "weber_l": None,
                         "transform": {"type": "linear", "factor": -0.015, "offset": 1.0}}, {}, (None, 16)),
])
def test_the_port_picks_the_sdks_rates_on_models_none_ships(case: str, overrides: dict, build: dict, tiles: tuple,
                                                            port: ModuleType, tiny_model: Callable[..., Path]) -> None:
    """What no shipped model is (a graph input whose plane count is free, a fixed input size, one 2x2 output,
    8-pixel tiles pooled to 16 and 32), on a frame of partial tiles: the port's rates are the SDK's. The port
    read a free plane count as a number (a TypeError) where the SDK gives that one input every plane."""
    import onnxruntime as ort

    from .conftest import base_metadata

    meta = base_metadata(**overrides)
    path = tiny_model(meta, np.random.default_rng(1).normal(size=(len(meta["outputs"]), 4)).astype(np.float32),
                      tile=meta["tile_size"], **build)
    if case == "free plane count":
        _free_plane_count(path)
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    x = np.random.default_rng(2).random((4, 37, 53), dtype=np.float32)
    for tile in tiles:
        p = sdk.load(path, tile_size=tile)
        values = p.predict(x)
        for threshold in np.quantile(values, [0.2, 0.5, 0.8]).tolist():
            theirs = p.shading_rates(x, threshold)
            ours = port.shading_rates(session, x, threshold, tile)
            assert ours.shape == theirs.shape, (case, tile)
            np.testing.assert_array_equal(ours, theirs, err_msg=f"{case} tile {tile} threshold {threshold}")


def test_the_port_refuses_a_frame_larger_than_a_fixed_size_model(port: ModuleType, tiny_model: Callable[..., Path],
                                                                 tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A frame past a fixed-size model's input is refused saying so (the SDK's InputShapeError), not with numpy's
    "index can't contain negative values" from the padding, nor as a traceback on the command line."""
    import onnxruntime as ort

    path = tiny_model(static=(1, 32, 48))
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    x = np.zeros((4, 40, 48), np.float32)
    with pytest.raises(sdk.InputShapeError):
        sdk.load(path).predict(x)
    with pytest.raises(ValueError, match="fixed input of 48x32; a 48x40 frame does not fit"):
        port.shading_rates(session, x, 0.2)
    assert port.shading_rates(session, x[:, :30, :40], 0.2).shape == (2, 3)  # (smaller: padded up to it)
    frame = tmp_path / "planes.npy"
    np.save(frame, x)
    for args in (["--frame", str(frame)], ["--size", "64x16"]):
        with pytest.raises(SystemExit) as info:
            port.main([str(path), *args])
        assert info.value.code == 2 and "the model has a fixed input of 48x32" in capsys.readouterr().err


def test_the_ports_budget_past_every_threshold_is_the_sdks(port: ModuleType) -> None:
    """A tile predicted past 1e6 never passes, as NaN never does: the port's budget, like the SDK's, reports the
    lowest threshold saving what the frame can, not 1e6 (its unreachable step once counted)."""
    values = np.full((6, 1, 2), 0.1)
    values[5, 0, 0] = 2e6
    for better in (False, True):
        v = -values if better else values
        meta = {"metric": "psnr" if better else "jnyang", "higher_is_better": better}
        want = sdk.select_rates_for_saving(v, sdk.MAX_SAVING, higher_is_better=better)
        got = port._budget(v, meta, sdk.MAX_SAVING, sdk.PREDICTED_RATES, None, None)
        assert got == want.threshold == (-1 if better else 1) * np.nextafter(0.1, 1.0)
