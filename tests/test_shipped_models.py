"""The models that ship in rtp.models: found by name, complete metadata, and they run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rtp import sdk

SHIPPED = sdk.shipped_models()
REQUIRED_PROVENANCE = ("train_scenes", "val_scenes", "train_samples", "resolution", "validation", "versions", "export")


def test_the_jnyang_model_ships() -> None:
    # The README's demo runs it; everything else in the package assumes it is there.
    assert "jnyang.onnx" in SHIPPED


def test_every_shipped_model_is_named_for_its_metric() -> None:
    # One model per metric, named for it; a variant for a use is METRIC-USE (the model for
    # prediction reuse, jnyang-reuse: docs/runtime.md; the models for AMD's and Intel's 8-pixel VRS
    # tiles, jnyang-8px, flip-8px, psnr-8px, jnflip-8px), beside its metric's every-frame model.
    metrics = {n.removesuffix(".onnx") for n in SHIPPED if "-" not in n}
    assert metrics == {"jnyang", "psnr", "flip", "jnflip", "lpips"}
    variants = {n.removesuffix(".onnx") for n in SHIPPED} - metrics
    assert variants == {"jnyang-reuse", "jnyang-8px", "flip-8px", "psnr-8px", "jnflip-8px"}
    for v in variants:
        assert v.split("-")[0] in metrics


def test_the_reuse_model_splits_and_carries_its_features() -> None:
    # jnyang-reuse is the network that splits (docs/results.md "The tail at tile resolution"): its
    # trunk's features are carried between network runs and its tail runs on every frame.
    pred = sdk.load("jnyang-reuse")
    assert pred.splits and pred.metadata.metric == "jnyang"
    assert {"reprojected.y.tiles", "albedo.y.tiles"} <= set(pred.metadata.inputs)
    reuse = sdk.PredictionReuse(pred, 4, carry="features")
    assert reuse.carry == "features" and reuse.every == 4
    # A camera that does not move: the frames between network runs read only the .tiles planes (the
    # variance inside each rate's blocks) of the new frame, the trunk's features are the last run's;
    # every fourth frame the whole network runs again.
    rng = np.random.default_rng(5)
    h, w = 96, 160
    rows, cols = np.indices((h, w))
    tiles = [pred.metadata.inputs.index(c) for c in ("reprojected.y.tiles", "albedo.y.tiles")]
    seen = pred.metadata.inputs.index("seen")
    ran = None
    for i in range(8):
        x = rng.random((len(pred.metadata.inputs), h, w), dtype=np.float32)
        x[seen] = 1.0
        got = reuse.predict(x, (rows, cols))
        if i % 4 == 0:
            ran = x.copy()
            assert np.allclose(got, pred.predict(x), atol=1e-5), i
        else:  # the last run's trunk with this frame's tail
            assert ran is not None
            mixed = ran.copy()
            mixed[tiles] = x[tiles]
            assert np.allclose(got, pred.predict(mixed), atol=1e-4), i
            assert not np.allclose(got, pred.predict(x), atol=1e-2), i


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_model_loads_by_name_and_predicts(name: str) -> None:
    by_name = sdk.load(name.removesuffix(".onnx"))
    assert by_name.path is not None and by_name.path.name == name
    m = by_name.metadata
    assert m.metric == name.removesuffix(".onnx").split("-")[0]  # jnyang-reuse: a JNYang model
    # NVIDIA's 16-pixel VRS tiles; the 8px variant AMD's and Intel's 8
    assert m.tile_size == (8 if name.endswith("-8px.onnx") else 16) and {"seen", "normal.z"} <= set(m.inputs)
    for kind in ("reprojected", "albedo"):  # the paper's brightness planes: red, or luma ("Luma instead of red")
        assert len({f"{kind}.r", f"{kind}.y"} & set(m.inputs)) == 1, (kind, m.inputs)
    assert m.outputs == ("1x2", "2x1", "2x4", "4x2")
    for key in REQUIRED_PROVENANCE:
        assert key in m.provenance, key
    from rtp.capture.scenes import load_splits

    splits = load_splits()
    assert set(m.provenance["train_scenes"]) <= set(splits["train"])  # trained on the train split only
    assert set(m.provenance["val_scenes"]) <= set(splits["validation"])
    x = np.zeros((len(m.inputs), 72, 128), np.float32)
    x[m.inputs.index("seen")] = 1.0
    out = by_name.predict(x)
    grid = (-(-72 // m.tile_size), 128 // m.tile_size)
    assert out.shape == (6, *grid) and np.all(np.isfinite(out))
    assert by_name.shading_rates(x).shape == grid


@pytest.mark.parametrize("name", SHIPPED)
def test_both_adapters_produce_every_input_of_a_shipped_model(name: str) -> None:
    # issue "Networks that beat the paper's": a shipped model uses only channels the moderngl and the
    # pyrender adapter both produce (the classes declare them; their tests check the values)
    from rtp.plugins.moderngl import Adapter as ModernglAdapter
    from rtp.plugins.pyrender import Adapter as PyrenderAdapter

    inputs = set(sdk.load(name).metadata.inputs)
    assert inputs <= ModernglAdapter.supported_channels and inputs <= PyrenderAdapter.supported_channels



@pytest.fixture(scope="module")
def rendered_inputs() -> list:
    """Two frames of the built-in procedural scene as the renderer hands them to a model."""
    from rtp.capture import load_scene
    from rtp.cli._demo import _camera_path
    from rtp.plugins.moderngl import Renderer

    scene, blockers = load_scene("procedural:0", None, None, None)
    w, h = 384, 224
    frames = []
    with Renderer(w, h) as r:
        r.load_scene(scene)
        for seed in (0, 1):
            prev = None
            for cam in _camera_path(scene, 2, blockers, w / h, seed):
                prev = r.render(cam, prev)
            frames.append(prev)
    return frames


@pytest.mark.gl
@pytest.mark.parametrize("name", SHIPPED)
def test_every_output_of_a_shipped_model_responds_to_the_frame(name: str, rendered_inputs: list) -> None:
    # A dead output (a ReLU of the paper's head that stopped firing) predicts one constant whatever
    # the frame shows: the LPIPS model once shipped with a dead 2x1 output, which this test caught
    # (the failure message lists every output's spread). Synthetic stripes did not show it.
    p = sdk.load(name)
    raw = np.concatenate([
        p.predict_raw(np.stack([f.channel(c) for c in p.metadata.inputs]).astype(np.float32)).reshape(len(p.metadata.outputs), -1)
        for f in rendered_inputs
    ], axis=1)
    spread = raw.std(axis=1)
    assert (spread > 0.01).all(), dict(zip(p.metadata.outputs, spread.round(5)))


# The models trained on AMD's and Intel's 8-pixel VRS tiles: each default decides at a share of the judging
# threshold (the rate factors, every rate alike) chosen so that it fails on as many 8-pixel tiles of the
# validation maps as its metric's 16-pixel model on its own tiles (docs/results.md "A model trained on
# 8-pixel tiles", "FLIP and PSNR on 8-pixel tiles").
#: model -> (metric, default threshold, rate_factors): one factor for every rate, or (FLIP, PSNR, JNFLIP) one per rate fitted
#: by bench/per_rate.py and scaled to the default's failing share (docs/results.md "Factors per rate on 8-pixel tiles")
EIGHT_PX = {"jnyang-8px": ("jnyang", 0.25, (0.94,) * 6),
            "flip-8px": ("flip", 0.15, (1.078, 1.078, 0.8982, 0.8982, 0.8982, 0.7635)),
            "psnr-8px": ("psnr", 35.0, (1.142, 1.142, 0.8087, 0.9514, 0.9514, 0.8087)),
            "jnflip-8px": ("jnflip", 0.2, (0.8838, 1.061, 0.8838, 0.8838, 0.8838, 0.7513))}


@pytest.mark.parametrize("name", sorted(EIGHT_PX))
def test_the_8px_model_decides_each_8_pixel_tile(name: str, caplog: pytest.LogCaptureFixture) -> None:
    """An 8px model predicts per 8-pixel tile itself; on NVIDIA's 16-pixel tiles each takes the worst of its four
    (for PSNR the lowest). A threshold past the worst value it can express (its clamped transform's end) is said
    once, not passed silently."""
    metric, judge, factors = EIGHT_PX[name]
    pred = sdk.load(name)
    m = pred.metadata
    assert (pred.tile_size, m.tile_size, m.metric, m.default_threshold) == (8, 8, metric, judge)
    assert m.rate_factors == factors and "8x8" in m.description
    factor = min(factors)  # (the rate whose threshold is the last to pass every tile)
    x = np.random.default_rng(8).random((len(m.inputs), 72, 128), dtype=np.float32)
    assert pred.predict(x).shape == (6, 9, 16)
    nvidia = sdk.load(name, tile_size=16)
    np.testing.assert_array_equal(nvidia.predict(x), sdk.pool_tiles(pred.predict(x), 2, higher_is_better=m.higher_is_better))
    caplog.set_level("WARNING", logger="rtp")
    # each rate's threshold is its factor's share of it (PSNR: the dB over it); the last one inside, the first past
    hib, sat = m.higher_is_better, m.saturation
    edge = sat + 20.0 * np.log10(factor) if hib else sat / factor
    inside, past = (edge + 0.01, edge - 0.01) if hib else (edge - 0.001, edge + 0.001)
    pred.shading_rates(x, inside)
    assert not caplog.records
    for _ in range(2):
        assert (pred.shading_rates(x, past) == sdk.RATE_CODES["4x4"]).all()  # every tile passes
    assert len(caplog.records) == 1
    assert f"can express ({sat:g}): every tile passes it at every rate; use one {'above' if hib else 'below'}" in caplog.text
    assert {n.removesuffix(".onnx") for n in SHIPPED if n.endswith("-8px.onnx")} == set(EIGHT_PX)


@pytest.mark.parametrize("name", sorted(EIGHT_PX))
def test_splitting_a_model_on_8_pixel_tiles_names_the_one_trained_for_them(name: str, caplog: pytest.LogCaptureFixture,
                                                                          tmp_path: Path) -> None:
    # sdk.load("flip", tile_size=8) works (each 8-pixel tile takes its 16-pixel tile's rates) and says, at INFO, that
    # flip-8px ships; not on NVIDIA's own 16-pixel tiles, and not for a copy of the model outside the package; and
    # sdk.load("flip-8px", tile_size=16) names flip.
    metric = EIGHT_PX[name][0]
    caplog.set_level("INFO", logger="rtp")
    sdk.load(metric, tile_size=8)
    hints = [r for r in caplog.records if "ships, trained on 8-pixel tiles" in r.getMessage()]
    assert len(hints) == 1 and hints[0].levelname == "INFO"
    assert f"{metric}.onnx on 8-pixel tiles: each takes its 16-pixel tile's rates; {name} ships" in hints[0].getMessage()
    assert f"sdk.load({name!r})" in hints[0].getMessage()
    caplog.clear()
    sdk.load(metric)
    sdk.load(name)
    copy = tmp_path / f"{metric}.onnx"
    copy.write_bytes(Path(str(sdk.load(metric).path)).read_bytes())
    sdk.load(copy, tile_size=8)
    sdk.load(name, tile_size=8)
    sdk.load(name, tile_size=32)
    assert not [r for r in caplog.records if "ships, trained on" in r.getMessage()]
    # the other way: an 8-pixel model on NVIDIA's 16-pixel tiles names the 16-pixel one, whose default is set for them
    sdk.load(name, tile_size=16)
    hints = [r for r in caplog.records if "ships, trained on 16-pixel tiles" in r.getMessage()]
    assert len(hints) == 1 and hints[0].levelname == "INFO"
    assert (f"{name}.onnx on 16-pixel tiles: each takes the worst of the 8-pixel tiles it covers, and its default "
            f"threshold was set for those; {metric} ships") in hints[0].getMessage()
    assert f"sdk.load({metric!r})" in hints[0].getMessage()
    caplog.clear()
    copy = tmp_path / f"{name}.onnx"
    copy.write_bytes(Path(str(sdk.load(name).path)).read_bytes())
    sdk.load(copy, tile_size=16)
    assert not [r for r in caplog.records if "ships, trained on" in r.getMessage()]


def test_the_jnyang_8px_saturation_is_the_documented_one(caplog: pytest.LogCaptureFixture) -> None:
    # jnyang-8px's clamped transform ends at 0.288 (docs/results.md): 0.94 x 0.31 = 0.2914 passes every tile
    pred = sdk.load("jnyang-8px")
    x = np.random.default_rng(8).random((len(pred.metadata.inputs), 72, 128), dtype=np.float32)
    caplog.set_level("WARNING", logger="rtp")
    pred.shading_rates(x, 0.3)
    assert not caplog.records
    assert (pred.shading_rates(x, 0.31) == sdk.RATE_CODES["4x4"]).all()
    assert "can express (0.287865): every tile passes it at every rate; use one below 0.306" in caplog.text
