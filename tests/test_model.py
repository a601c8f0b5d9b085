"""MetricNet layout (the paper's appendix table) and the checkpoint format."""

from __future__ import annotations

import base64
import copy
import inspect
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from rtp import sdk
from rtp.train import checkpoint
from rtp.train.model import MetricNet, build_network, layer_plan

from .conftest import base_metadata


def test_w16_plan_is_the_papers_table() -> None:
    plan = layer_plan(4, 4, 16, 16)
    assert [(s.in_channels, s.out_channels, s.groups, s.pool) for s in plan] == [
        (4, 16, 1, 1),
        (16, 16, 1, 2),
        (16, 16, 4, 2),
        (16, 16, 8, 2),
        (16, 4, 1, 2),
    ]


def test_block_order_conv_relu_bn_pool_then_sigmoid() -> None:
    net = MetricNet()
    kinds = [type(m).__name__ for m in net.layers]
    assert kinds[:4] == ["Conv2d", "ReLU", "BatchNorm2d"] + ["Conv2d"]  # no pool after layer 1
    assert kinds[-3:] == ["BatchNorm2d", "MaxPool2d", "Sigmoid"]
    assert kinds.count("Conv2d") == 5 and kinds.count("MaxPool2d") == 4


@pytest.mark.parametrize("arch", ["paper", "fast"])
@pytest.mark.parametrize("tile", [1, 2, 4, 8, 16, 32])
def test_fully_convolutional_for_every_tile_size(arch: str, tile: int) -> None:
    net = build_network(arch, 3, 2, tile).eval()
    for h, w in ((64, 96), (32, 160)):
        y = net(torch.rand(2, 3, h, w))
        assert y.shape == (2, 2, h // tile, w // tile)
        assert torch.all((y > 0) & (y < 1))


def test_bad_configurations() -> None:
    with pytest.raises(ValueError, match="tile"):
        MetricNet(tile=12)
    with pytest.raises(ValueError, match="width"):
        MetricNet(width=1)


def _net() -> MetricNet:
    torch.manual_seed(0)
    return MetricNet()


def test_checkpoint_round_trip(tmp_path: Path) -> None:
    net = _net()
    path = checkpoint.save(tmp_path / "m.pt", net, base_metadata(safety=0.04), training={"step": 7})
    ck = checkpoint.load(path)
    assert ck.metadata.safety == 0.04 and ck.training == {"step": 7}
    assert ck.versions["torch"] == torch.__version__
    assert not ck.net.training
    for (k, a), (_, b) in zip(net.state_dict().items(), ck.net.state_dict().items()):
        assert torch.equal(a, b), k


def test_checkpoint_rejects_metadata_that_does_not_fit(tmp_path: Path) -> None:
    with pytest.raises(sdk.MetadataError, match="outputs"):
        checkpoint.save(tmp_path / "m.pt", _net(), base_metadata(outputs=["1x2", "2x1"]))
    with pytest.raises(sdk.MetadataError, match="tile_size"):
        checkpoint.save(tmp_path / "m.pt", _net(), base_metadata(tile_size=8))
    assert not (tmp_path / "m.pt").exists()


def test_failed_save_keeps_the_previous_checkpoint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "m.pt"
    checkpoint.save(path, _net(), base_metadata(safety=0.01))
    before = path.read_bytes()

    def boom(*a: object, **k: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(torch, "save", boom)
    with pytest.raises(OSError, match="disk full"):
        checkpoint.save(path, _net(), base_metadata(safety=0.02))
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["m.pt"]  # no temporary left behind


def test_bad_checkpoint_files(tmp_path: Path) -> None:
    with pytest.raises(sdk.ModelNotFoundError):
        checkpoint.load(tmp_path / "missing.pt")
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"garbage")
    with pytest.raises(checkpoint.CheckpointError, match="not a checkpoint"):
        checkpoint.load(junk)
    other = tmp_path / "other.pt"
    torch.save({"state_dict": {}}, other)
    with pytest.raises(checkpoint.CheckpointError, match="not an rtp checkpoint"):
        checkpoint.load(other)
    # NaN weights (a diverged training of an rtp before it stopped on them) are named, not exported into a parity
    # failure ("max abs difference nan") or resumed into a training on NaN
    net = _net()
    with torch.no_grad():
        next(net.parameters())[0].fill_(float("nan"))
    nan = checkpoint.save(tmp_path / "nan.pt", net, base_metadata(safety=0.04))
    with pytest.raises(checkpoint.CheckpointError, match=r"its weights are not finite \(.*\): the training that wrote "
                                                         r"it diverged"):
        checkpoint.load(nan)


def _refuse_large_layers(monkeypatch: pytest.MonkeyPatch, where: str) -> None:
    """Conv2d and Linear check each layer before it allocates: one of over a million weights, or a
    thousandth layer, fails the test unless it is built on torch's meta device (a real one of the old
    checkpoint code took 21 GB and the process), and so does a ten-thousandth layer on meta (whose
    module objects still take memory: a billion of them filled 15 GB)."""
    built, planned = [0], [0]

    def guarded(init: Any) -> Any:
        def run(self: torch.nn.Module, *a: Any, **k: Any) -> None:
            planned[0] += 1
            assert planned[0] <= 10**4, f"building layer {planned[0]} even on meta, {where}"
            if torch.get_default_device().type != "meta":
                args = inspect.signature(init).bind(self, *a, **k).arguments
                ins, outs = (args.get(n) for n in (("in_channels", "out_channels") if "in_channels" in args
                                                   else ("in_features", "out_features")))
                built[0] += 1
                assert ins * outs <= 10**6 and built[0] <= 1000, f"building layer {built[0]}, {ins}x{outs}, {where}"
            init(self, *a, **k)
        return run

    for cls in (torch.nn.Conv2d, torch.nn.Linear):
        monkeypatch.setattr(cls, "__init__", guarded(cls.__init__))


@pytest.mark.parametrize("change", [
    {"name": "MetricNet", "config": {"width": 24390}},  # the fuzz run's file: 21 GB of weights, the process OOM-killed
    {"name": "FastNet", "config": {"width": 2**20}},
    {"name": "FastNet", "config": {"depth": 10**9}},  # a billion blocks: a loop, before any allocation
    {"name": "FastNet", "config": {"head_width": 10**7}},
])
def test_a_checkpoint_whose_architecture_is_not_its_weights_allocates_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, change: dict[str, Any]
) -> None:
    """A damaged architecture.config is refused before the network it names is built in memory."""
    from rtp.train.model import FastNet

    net = _net() if change["name"] == "MetricNet" else FastNet()
    good = tmp_path / "good.pt"
    checkpoint.save(good, net, base_metadata())
    raw = torch.load(good, map_location="cpu", weights_only=True)
    raw["architecture"]["config"].update(change["config"])
    bad = tmp_path / "bad.pt"
    torch.save(raw, bad)

    _refuse_large_layers(monkeypatch, f"from a file of {bad.stat().st_size:,} bytes")
    key = next(iter(change["config"]))
    with pytest.raises(checkpoint.CheckpointError, match=f"weights do not fit the architecture.*{key}|is \\["):
        checkpoint.load(bad)
    assert isinstance(checkpoint.load(good).net, type(net))  # the guard lets a real one through


@pytest.mark.parametrize("arch, sizes, words", [
    ("fast", {"width": 30000}, r"would hold 24,302,280,004 parameters \(90.5 GiB"),  # a width with extra digits
    ("paper", {"width": 30000}, "would hold"),
    ("fast", {"head_width": 10**7}, "head_width 10000000"),
    ("fast", {"depth": 257}, r"depth in \[0, 256\]"),
    ("fast", {"depth": 10**9}, r"depth in \[0, 256\]"),  # refused before a billion-block loop
    ("fast", {"depth": 300, "coarse": 300}, r"depth in \[0, 256\]"),
    ("fast", {"depth": 3, "coarse": 10**9, "coarse_width": 8}, "coarse"),
])
def test_networks_past_the_size_limits_are_refused_before_their_memory_is_taken(
    monkeypatch: pytest.MonkeyPatch, arch: str, sizes: dict[str, int], words: str
) -> None:
    from rtp.train.model import MAX_PARAMETERS, build_network

    _refuse_large_layers(monkeypatch, f"build_network({arch!r}, **{sizes})")
    with pytest.raises(sdk.ParameterError, match=words):
        build_network(arch, 4, 4, 16, **sizes)
    big = build_network("fast", 4, 4, 16, width=512, depth=3)  # large but real networks are built
    assert 10**6 < sum(p.numel() for p in big.parameters()) <= MAX_PARAMETERS


def test_the_fast_network_layout() -> None:
    from rtp.train.model import ARCHS, FastNet, build_network

    net = FastNet()
    kinds = [type(m).__name__ for m in net.layers]
    # strided stem; every convolution but the head is conv -> BatchNorm -> ReLU (BatchNorm folds at export)
    assert kinds[:3] == ["Conv2d", "BatchNorm2d", "ReLU"] and net.layers[0].stride == (4, 4)
    convs = [i for i, k in enumerate(kinds) if k == "Conv2d"]
    assert all(kinds[i + 1:i + 3] == ["BatchNorm2d", "ReLU"] for i in convs[:-1])
    assert kinds[-2:] == ["Conv2d", "Sigmoid"] and kinds.count("MaxPool2d") == 2
    assert sum(p.numel() for p in net.parameters()) == 8132
    assert set(ARCHS) == {"paper", "fast"} and isinstance(build_network("fast", 4, 4, 16), FastNet)
    with pytest.raises(ValueError, match="arch"):
        build_network("resnet", 4, 4, 16)
    with pytest.raises(ValueError, match="tile"):
        FastNet(tile=12)
    assert "grow" not in net.config  # configs of checkpoints from before the option stay as they were


@pytest.mark.parametrize(("arch", "option"), [
    ("fast", {"head": "linear"}), ("fast", {"head": "bogus"}),
    ("paper", {"depth": 5}), ("paper", {"head_width": 8}), ("paper", {"separable": True}),
    ("paper", {"block_contrast": (0,)}),
])
def test_one_networks_option_with_the_other_arch_is_refused_not_ignored(arch: str, option: dict[str, Any]) -> None:
    # (rtp train refuses these; the Python builder took them and built the network without them)
    from rtp.train.model import FastNet

    (name,) = option
    with pytest.raises(sdk.ParameterError, match=f"^{name}: ") as err:
        build_network(arch, 4, 4, 16, **option)
    assert err.value.name == name
    assert isinstance(build_network("fast", 4, 4, 16, head="paper"), FastNet)  # each default is taken by both
    assert isinstance(build_network("paper", 4, 4, 16, head="linear", coarse_width=32), MetricNet)


def test_a_contrast_cell_without_block_contrast_is_refused_not_ignored() -> None:
    """``contrast_cell`` without ``block_contrast`` built a network without any contrast and recorded no cell
    (``rtp train`` refuses it; the Python builder took it without a word)."""
    with pytest.raises(sdk.ParameterError, match="^contrast_cell: .*only with block_contrast") as err:
        build_network("fast", 4, 4, 16, contrast_cell=8)
    assert err.value.name == "contrast_cell"
    assert build_network("fast", 4, 4, 16, block_contrast=(0,), contrast_cell=8).config["contrast_cell"] == 8


def _round_trip(net: torch.nn.Module, key: str, meta: dict[str, Any] | None = None, seed: int = 0) -> None:
    """``net`` (BatchNorm statistics made non-trivial) saved, reloaded with its config's ``key``, exported,
    and the SDK's raw prediction equal to torch's."""
    from rtp.export import export_checkpoint

    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.1, 0.1)
    meta = meta or base_metadata()
    with tempfile.TemporaryDirectory() as d:
        ck = checkpoint.save(Path(d) / "n.pt", net, meta)
        assert checkpoint.load(ck).net.config[key] == net.config[key]  # type: ignore[index]
        pred = sdk.load(export_checkpoint(ck, Path(d) / "n.onnx"))
        x = np.random.default_rng(seed).random((len(meta["inputs"]), 48, 80), dtype=np.float32)
        with torch.inference_mode():
            want = net(torch.from_numpy(x)[None])[0].numpy()
        np.testing.assert_allclose(pred.predict_raw(x), want, atol=1e-5)


def test_the_growing_fast_network_doubles_channels_after_each_pool() -> None:
    from rtp.train.model import FastNet

    net = FastNet(7, grow=2).eval()
    widths = [m.out_channels for m in net.layers if isinstance(m, torch.nn.Conv2d)]
    assert widths == [16, 16, 32, 64, 4] and net.config["grow"] == 2
    assert [m.out_channels for m in FastNet(grow=2, depth=5).layers if isinstance(m, torch.nn.Conv2d)] == \
        [16, 16, 32, 64, 64, 64, 4]  # blocks at tile resolution keep the last width
    assert sum(p.numel() for p in net.parameters()) == 1792 + 2304 + 4608 + 18432 + 2 * (16 + 16 + 32 + 64) + 260
    with pytest.raises(ValueError, match="grow"):
        FastNet(grow=3)
    # it round-trips through a checkpoint and exports like any other
    _round_trip(net, "grow", base_metadata(inputs=["reprojected.r", "seen", "albedo.r", "normal.z", "roughness",
                                                   "metallic", "specular"]))


def test_max_width_caps_the_growing_channels_and_exports() -> None:
    from rtp.train.model import FastNet

    net = FastNet(4, grow=2, depth=5, max_width=32).eval()
    assert [m.out_channels for m in net.layers if isinstance(m, torch.nn.Conv2d)] == [16, 16, 32, 32, 32, 32, 4]
    assert net.config["max_width"] == 32 and "max_width" not in FastNet(grow=2).config
    assert sum(p.numel() for p in net.parameters()) == \
        1024 + 2304 + 4608 + 3 * 9216 + 2 * (16 + 16 + 32 * 4) + 132
    for bad in ({"max_width": 32}, {"grow": 2, "max_width": 8}):  # no grow to cap; a cap under the width
        with pytest.raises(ValueError, match="max_width"):
            FastNet(**bad)
    _round_trip(net, "max_width", seed=1)


def test_separable_blocks_are_depthwise_then_pointwise_and_export() -> None:
    from rtp.train.model import FastNet

    net = FastNet(4, width=32, depth=5, separable=True).eval()
    convs = [m for m in net.layers if isinstance(m, torch.nn.Conv2d)]
    assert [(m.kernel_size[0], m.groups) for m in convs[1:-1]] == [(3, 32), (1, 1)] * 5  # five blocks, each split
    assert net.config["separable"] is True and "separable" not in FastNet().config
    assert sum(p.numel() for p in net.parameters()) == 4 * 16 * 32 + 5 * (32 * 9 + 32 * 32 + 4 * 32) + 2 * 32 + 132
    _round_trip(net, "separable", seed=2)


def test_a_separable_tail_splits_only_the_tile_resolution_blocks_and_exports() -> None:
    from rtp.train.model import FastNet

    net = FastNet(4, depth=5, grow=2, separable_tail=True).eval()
    convs = [m for m in net.layers if isinstance(m, torch.nn.Conv2d)]
    # stem; full 3x3 blocks at 1/4 and 1/8 (16, 32); three split blocks at 1/16 (to 64); head
    assert [(m.kernel_size[0], m.groups, m.out_channels) for m in convs[1:-1]] == [
        (3, 1, 16), (3, 1, 32), (3, 32, 32), (1, 1, 64), (3, 64, 64), (1, 1, 64), (3, 64, 64), (1, 1, 64)]
    assert net.config["separable_tail"] is True and "separable_tail" not in FastNet().config
    full = FastNet(4, depth=5, grow=2)
    assert sum(p.numel() for p in net.parameters()) < sum(p.numel() for p in full.parameters()) / 3
    _round_trip(net, "separable_tail", seed=3)


def test_tail_width_widens_only_the_tile_resolution_blocks_and_exports() -> None:
    from rtp.train.model import FastNet

    net = FastNet(8, depth=5, tail_width=48).eval()
    # stem and the blocks at 1/4 and 1/8 keep the width; the three at 1/16 take the tail's
    assert [m.out_channels for m in net.layers if isinstance(m, torch.nn.Conv2d)] == [16, 16, 16, 48, 48, 48, 4]
    assert net.config["tail_width"] == 48 and "tail_width" not in FastNet().config
    assert sum(p.numel() for p in net.parameters()) == \
        8 * 16 * 16 + 2 * 2304 + 16 * 48 * 9 + 2 * 48 * 48 * 9 + 2 * (3 * 16 + 3 * 48) + 4 * 48 + 4
    # with grow 2 it overrides what grow gives the tail (16, 32, then 24 at 1/16)
    assert [m.out_channels for m in FastNet(depth=4, grow=2, tail_width=24).layers
            if isinstance(m, torch.nn.Conv2d)] == [16, 16, 32, 24, 24, 4]
    for bad in ({"depth": 2, "tail_width": 48}, {"depth": 5, "tail_width": 1}):  # no tile block; too narrow
        with pytest.raises(ValueError, match="tail_width"):
            FastNet(**bad)
    _round_trip(net, "tail_width", base_metadata(inputs=["reprojected.r", "reprojected.g", "reprojected.b", "seen",
                                                         "albedo.r", "albedo.g", "albedo.b", "normal.z"]), seed=4)


def test_the_mlp_head_reads_the_last_block_through_a_hidden_layer_and_exports() -> None:
    from rtp.train.model import FastNet

    net = FastNet(4, depth=5, head_width=64).eval()
    convs = [m for m in net.layers if isinstance(m, torch.nn.Conv2d)]
    # the 3x3 blocks stay at width 16; the head is 1x1 16 -> 64 (BatchNorm, ReLU), then 1x1 64 -> outputs
    assert [(m.kernel_size[0], m.out_channels) for m in convs] == [(4, 16)] + [(3, 16)] * 5 + [(1, 64), (1, 4)]
    assert isinstance(net.layers[-3], torch.nn.ReLU) and isinstance(net.layers[-1], torch.nn.Sigmoid)
    assert net.config["head_width"] == 64 and "head_width" not in FastNet().config
    plain = sum(p.numel() for p in FastNet(4, depth=5).parameters())
    assert sum(p.numel() for p in net.parameters()) == plain - 68 + 16 * 64 + 2 * 64 + 64 * 4 + 4
    with pytest.raises(ValueError, match="head_width"):
        FastNet(head_width=-1)
    _round_trip(net, "head_width", seed=3)


def test_the_context_pool_appends_the_neighbourhood_mean_and_exports() -> None:
    from rtp.train.model import ContextPool, FastNet

    net = FastNet(8, depth=5, context_pool=9).eval()
    convs = [m for m in net.layers if isinstance(m, torch.nn.Conv2d)]
    assert isinstance(net.layers[-3], ContextPool) and (convs[-1].in_channels, convs[-1].out_channels) == (32, 4)
    assert net.config["context_pool"] == 9 and "context_pool" not in FastNet().config
    # the appended channels are each feature's mean over the window, the border averaging only what it has
    pool = ContextPool(3)
    x = torch.arange(16.0).reshape(1, 1, 4, 4)
    y = pool(x)
    assert torch.equal(y[:, :1], x) and y[0, 1, 0, 0] == (0 + 1 + 4 + 5) / 4 and y[0, 1, 1, 1] == x[0, 0, :3, :3].mean()
    for bad in (-1, 1, 2, 8):
        with pytest.raises(ValueError, match="context_pool"):
            FastNet(context_pool=bad)
    _round_trip(net, "context_pool", base_metadata(inputs=["reprojected.r", "reprojected.g", "reprojected.b", "seen",
                                                           "albedo.r", "albedo.g", "albedo.b", "normal.z"]), seed=4)


def test_the_coarse_context_appends_features_at_twice_the_tile_scale_and_exports() -> None:
    from rtp.train.model import CoarseContext, FastNet

    net = FastNet(8, depth=5, coarse=2).eval()
    kinds = [type(m).__name__ for m in net.layers]
    # after the first block at tile resolution (the third 3x3 block), so the two after it read 32 channels
    assert kinds.index("CoarseContext") == kinds.index("MaxPool2d", kinds.index("MaxPool2d") + 1) + 4
    convs = [m for m in net.layers if isinstance(m, torch.nn.Conv2d)]
    assert [(m.in_channels, m.out_channels) for m in convs[-3:]] == [(32, 16), (16, 16), (16, 4)]
    assert net.config["coarse"] == 2 and net.config["coarse_width"] == 64 and "coarse" not in FastNet().config
    ctx = next(m for m in net.layers if isinstance(m, CoarseContext))
    assert sum(p.numel() for p in ctx.parameters()) == 16 * 64 * 9 + 64 * 64 * 9 + 64 * 16 + 2 * (64 + 64 + 16)
    # each coarse position covers its 2x2 tiles; a partial last row and column of tiles keep theirs (3x5 tiles)
    x = torch.rand(1, 16, 3, 5)
    y = ctx.eval()(x)
    assert y.shape == (1, 32, 3, 5) and torch.equal(y[:, :16], x)
    assert torch.equal(y[:, 16:, 0, 0], y[:, 16:, 1, 1]) and torch.equal(y[:, 16:, 2, 4], ctx.body(x)[:, :, 1, 2])
    for bad in ({"depth": 2, "coarse": 2}, {"depth": 5, "coarse": -1}, {"depth": 5, "coarse": 1, "coarse_width": 1}):
        with pytest.raises(ValueError, match="coarse"):
            FastNet(**bad)
    _round_trip(net, "coarse", base_metadata(inputs=["reprojected.r", "reprojected.g", "reprojected.b", "seen",
                                                     "albedo.r", "albedo.g", "albedo.b", "normal.z"]), seed=5)


@pytest.mark.parametrize("cell", [2, 4, 8, 16])
def test_block_contrast_is_the_variance_inside_each_rates_blocks(cell: int) -> None:
    from rtp.train.model import BlockContrast, haar_details

    details = np.stack([d.ravel() for d in haar_details(cell)])
    # with the cell's mean, an orthonormal basis of the cell
    np.testing.assert_allclose(details @ details.T, np.eye(cell * cell - 1), atol=1e-12)
    np.testing.assert_allclose(details.sum(axis=1), 0.0, atol=1e-12)
    m = BlockContrast((2, 0), 3, cell, eps=0.0)
    assert m.rates == (("1x2", "2x1", "2x2") if cell == 2 else ("1x2", "2x1", "2x2", "2x4", "4x2", "4x4"))
    x = torch.rand(2, 3, 2 * cell, 3 * cell, dtype=torch.float64).float()
    out = m(x).exp()
    assert out.shape == (2, 2 * len(m.rates), 2, 3)
    r = len(m.rates)
    for n, (i, j) in ((0, (0, 0)), (1, (1, 2))):
        for a, plane in enumerate((2, 0)):
            cellx = x[n, plane, i * cell:(i + 1) * cell, j * cell:(j + 1) * cell].numpy().astype(np.float64)
            for k, rate in enumerate(m.rates):
                w, h = sdk.rate_size(rate)
                blocks = cellx.reshape(cell // h, h, cell // w, w)
                want = ((blocks - blocks.mean(axis=(1, 3), keepdims=True)) ** 2).mean()
                assert float(out[n, a * r + k, i, j]) == pytest.approx(want, rel=1e-4, abs=1e-6)
    # a plane constant on 2x2 blocks loses nothing at 1x2, 2x1 and 2x2
    flat = torch.rand(1, 3, cell // 2, cell).repeat_interleave(2, 2).repeat_interleave(2, 3)
    assert torch.all(m(flat)[0, :3].exp() < 1e-9)
    for bad in ((), (0, 0), (3,), (-1,)):
        with pytest.raises(ValueError, match="block_contrast"):
            BlockContrast(bad, 3, 4)
    with pytest.raises(ValueError, match="power-of-two"):
        haar_details(3)


def test_block_contrast_of_a_large_cell_adds_its_worst_4x4_cell_with_tile_max() -> None:
    """``tile_max``: per plane the cell means, then the maxima over the cell's 4x4 cells of theirs."""
    from rtp.train.model import BlockContrast, FastNet

    x = torch.rand(1, 2, 32, 48)
    mean_only, both = BlockContrast((1, 0), 2, 16, eps=0.0), BlockContrast((1, 0), 2, 16, eps=0.0, tile_max=True)
    fine = BlockContrast((1, 0), 2, 4, eps=0.0)(x).exp()  # (1, 12, 8, 12): every 4x4 cell
    out = both(x).exp()
    assert both.channels == 24 and out.shape == (1, 24, 2, 3)
    torch.testing.assert_close(out[:, [*range(6), *range(12, 18)]], mean_only(x).exp())
    for a in range(2):  # plane a: means at 12a .. 12a + 5, maxima at 12a + 6 .. 12a + 11
        want = torch.nn.functional.max_pool2d(fine[:, 6 * a:6 * a + 6], 4)
        torch.testing.assert_close(out[:, 12 * a + 6:12 * a + 12], want)
    net = FastNet(7, head_width=16, block_contrast=(0, 2), contrast_cell=16, contrast_max=True).eval()
    assert net.config["contrast_max"] is True and net.contrast is not None and net.contrast.channels == 24
    assert net(torch.rand(1, 7, 32, 32)).shape == (1, 4, 2, 2)
    for bad in ({"contrast_cell": 4}, {"block_contrast": ()}):
        with pytest.raises(ValueError, match="contrast_max"):
            FastNet(7, **{"block_contrast": (0,), "contrast_cell": 16, "contrast_max": True, **bad})


@pytest.mark.parametrize("cell", [4, 16])
def test_stored_block_contrast_reads_the_blocks_planes_as_the_computed_contrast(cell: int) -> None:
    """``.blocks`` planes (``sdk.block_variances``) read by ``StoredBlockContrast`` give what
    ``BlockContrast`` computes from the luma planes, means and worst cells alike."""
    from rtp.train.model import BlockContrast, StoredBlockContrast

    rng = np.random.default_rng(cell)
    luma = rng.uniform(0, 1, (2, 32, 48)).astype(np.float32)
    luma[0, :16, :16] = 0.5  # a flat tile: the variance floor
    blocks = np.stack([sdk.block_variances(p) for p in luma])
    x = torch.from_numpy(np.concatenate([luma, blocks])[None])
    want = BlockContrast((0, 1), 4, cell, tile_max=cell > 4)(x)
    got = StoredBlockContrast((2, 3), 4, cell, tile_max=cell > 4)(x)
    assert got.shape == want.shape == (1, 2 * 6 * (2 if cell > 4 else 1), 32 // cell, 48 // cell)
    torch.testing.assert_close(got, want, rtol=1e-4, atol=2e-4)


def test_a_network_with_stored_contrast_splits_into_trunk_and_tail_and_exports() -> None:
    """``contrast_stored``: the stem reads every plane but is blind to the .blocks planes (weights held at
    zero, through training too: the trunk ignores them), the tail on the trunk's own features is the whole
    network, and it exports."""
    from rtp.train.model import FastNet, StoredBlockContrast

    net = FastNet(9, head_width=16, block_contrast=(7, 8), contrast_cell=16, contrast_max=True,
                  contrast_stored=True)
    assert isinstance(net.contrast, StoredBlockContrast) and net.blind == 2
    stem = net.layers[0]
    assert stem.weight.shape[1] == 9 and not stem.weight[:, 7:].any() and stem.weight[:, :7].abs().sum() > 0
    trained = copy.deepcopy(net)
    opt = torch.optim.AdamW(trained.parameters(), lr=0.1, weight_decay=0.1)
    for _ in range(3):  # training leaves the blind weights at exactly zero
        opt.zero_grad()
        trained(torch.rand(2, 9, 32, 32)).square().mean().backward()
        opt.step()
    assert not trained.layers[0].weight[:, 7:].any() and trained.layers[0].weight[:, :7].ne(stem.weight[:, :7]).any()
    net.eval()
    assert net.config["contrast_stored"] is True
    x = torch.rand(1, 9, 32, 48)
    y = x.clone()
    y[:, 7:] = torch.rand(1, 2, 32, 48)  # other .blocks planes
    with torch.inference_mode():
        torch.testing.assert_close(net.trunk(x), net.trunk(y))
        torch.testing.assert_close(net.tail(net.trunk(x), x), net(x))
        assert not torch.allclose(net(x), net(y))
    with pytest.raises(ValueError, match="last input channels"):
        FastNet(9, block_contrast=(0, 8), contrast_cell=16, contrast_stored=True)
    # frames need only be multiples of 4: the partial last tile pools the cells it has, in the trunk and the
    # contrast alike (a 1080-row frame is not padded to 1088)
    assert net.input_multiple == 4
    with torch.inference_mode():
        z = torch.rand(1, 9, 36, 52)
        assert net(z).shape == (1, 4, 3, 4) and torch.isfinite(net(z)).all()
        c = net.contrast(z)  # the corner tile holds one 4x4 cell: its mean and its maximum are that cell's
        cell = (z[0, 7, 32:36, 48:52].reshape(-1)[:6] - 1.0) * net.contrast.scale
        torch.testing.assert_close(c[0, :6, 2, 3], cell, rtol=1e-4, atol=1e-4)
        torch.testing.assert_close(c[0, 6:12, 2, 3], cell, rtol=1e-4, atol=1e-4)
    _round_trip(net, "contrast_stored", base_metadata(inputs=["reprojected.y", "seen", "albedo.y", "normal.z",
                                                              "roughness", "metallic", "specular",
                                                              "reprojected.y.blocks", "albedo.y.blocks"]), seed=6)
    # exported, the rates' values are one Slice of the cells' first rows (no chain of copies) and a one-hot
    # convolution, the stem is still the only convolution of the frame (so the finite probe stays), and a frame
    # with partial tiles matches torch
    import onnx

    from rtp.export import export_checkpoint

    meta = base_metadata(inputs=["reprojected.y", "seen", "albedo.y", "normal.z", "roughness", "metallic", "specular",
                                 "reprojected.y.blocks", "albedo.y.blocks"])
    with tempfile.TemporaryDirectory() as d:
        path = export_checkpoint(checkpoint.save(Path(d) / "n.pt", net, meta), Path(d) / "n.onnx")
        graph = onnx.load(str(path)).graph
        slices = [n for n in graph.node if n.op_type == "Slice"]
        made = {o for n in slices for o in n.output}
        assert not any(n.input[0] in made for n in slices)
        shapes = {i.name: list(i.dims) for i in graph.initializer}
        shapes.update({n.output[0]: list(n.attribute[0].t.dims) for n in graph.node if n.op_type == "Constant"})
        assert [n for n in graph.node if n.op_type == "Conv" and shapes.get(n.input[1]) == [12, 2, 2, 4]]
        assert sum(n.op_type == "Conv" and n.input[0] == "input" for n in graph.node) == 1
        pred = sdk.load(path)
        assert pred.metadata.finite_probe
        z = np.random.default_rng(7).random((9, 36, 52), dtype=np.float32)
        with torch.inference_mode():
            want = net(torch.from_numpy(z)[None])[0].numpy()
        np.testing.assert_allclose(pred.predict_raw(z), want, atol=1e-5)
        # the SDK runs the two graphs: the features with the prediction, the tail on them (or carried ones)
        assert pred.splits and pred.metadata.tail and pred.metadata.schema_version == 4
        est, feats = pred.predict_split(z)
        np.testing.assert_allclose(est, pred.predict(z), atol=1e-6)
        assert feats.shape == (16, 3, 4) and feats.dtype == np.float32
        np.testing.assert_allclose(pred.predict_tail(feats, z), est, atol=1e-6)
        other = np.random.default_rng(8).random((9, 36, 52), dtype=np.float32)
        _, moved = pred.predict_split(other)
        with torch.inference_mode():
            ref = net.tail(torch.from_numpy(moved)[None], torch.from_numpy(z)[None])[0].numpy()
        np.testing.assert_allclose(pred.predict_tail(moved, z), pred.metadata.decode(ref), atol=1e-5)
        with pytest.raises(sdk.InputShapeError, match="features"):
            pred.predict_tail(feats[:, :2], z)
        bad = z.copy()
        bad[8, 3, 3] = np.nan
        with pytest.raises(sdk.NonFiniteInputError):
            pred.predict_tail(feats, bad)
        with pytest.raises(sdk.ParameterError, match="does not split"):
            sdk.load("jnyang").predict_split(z[:, :32, :48])
        # a damaged tail graph is refused at load
        model = onnx.load(str(path))
        props = {p.key: p.value for p in model.metadata_props}
        raw = bytearray(base64.b64decode(props[sdk.TAIL_KEY]))
        raw[-20] ^= 1
        props[sdk.TAIL_KEY] = base64.b64encode(bytes(raw)).decode()
        onnx.helper.set_model_props(model, props)
        onnx.save(model, str(Path(d) / "damaged.onnx"))
        with pytest.raises(sdk.ModelLoadError, match="tail"):
            sdk.load(Path(d) / "damaged.onnx")


def test_tile_contrast_reads_the_tiles_planes_as_the_stored_contrast() -> None:
    """``.tiles`` planes (``sdk.tile_variances``) read by ``TileContrast`` give what ``StoredBlockContrast``
    computes from the ``.blocks`` planes of the same lumas, partial tiles included, with and without the
    maxima; its weights are fixed buffers, not parameters."""
    from rtp.train.model import StoredBlockContrast, TileContrast

    rng = np.random.default_rng(5)
    for h, w in ((32, 48), (36, 52), (44, 20)):
        luma = rng.uniform(0, 1, (2, h, w)).astype(np.float32) ** 2
        luma[0, :16, :16] = 0.5  # a flat tile: the variance floor
        x = torch.from_numpy(np.concatenate([np.stack([sdk.block_variances(p) for p in luma]),
                                             np.stack([sdk.tile_variances(p) for p in luma])])[None])
        for tile_max in (True, False):
            want = StoredBlockContrast((0, 1), 4, 16, tile_max=tile_max)(x)
            module = TileContrast((2, 3), 4, 16, tile_max=tile_max)
            got = module(x)
            assert got.shape == want.shape == (1, 2 * 6 * (2 if tile_max else 1), -(-h // 16), -(-w // 16))
            torch.testing.assert_close(got, want, rtol=1e-4, atol=2e-5)
            assert not list(module.parameters())
    with pytest.raises(ValueError, match="the cell must be their tile, 16"):
        TileContrast((0,), 2, 8)


def test_a_network_with_tile_contrast_splits_and_exports_a_tail_that_reads_the_tile_grid(tmp_path: Path) -> None:
    """``contrast_tiles``: the same network as ``contrast_stored`` on .blocks planes (the same weights give
    the same outputs on the same frame); exported, its contrast is one strided convolution beside the stem
    (the finite probe stays on the stem), the tail reads nothing finer than the tile grid, and the SDK's
    split methods match torch at partial tiles."""
    import onnx

    from rtp.train.model import FastNet, TileContrast

    from .conftest import split_model

    torch.manual_seed(0)
    blocks = FastNet(9, head_width=16, block_contrast=(7, 8), contrast_cell=16, contrast_max=True,
                     contrast_stored=True).eval()
    tiles = FastNet(9, head_width=16, block_contrast=(7, 8), contrast_cell=16, contrast_max=True,
                    contrast_stored=True, contrast_tiles=True).eval()
    tiles.load_state_dict(blocks.state_dict())
    assert isinstance(tiles.contrast, TileContrast) and tiles.config["contrast_tiles"] is True and tiles.blind == 2
    assert tiles.input_multiple == 4
    rng = np.random.default_rng(9)
    planes = rng.uniform(0, 1, (7, 36, 52)).astype(np.float32)
    xb = np.concatenate([planes, np.stack([sdk.block_variances(planes[i]) for i in (0, 2)])])
    xt = np.concatenate([planes, np.stack([sdk.tile_variances(planes[i]) for i in (0, 2)])])
    with torch.inference_mode():
        torch.testing.assert_close(tiles(torch.from_numpy(xt)[None]), blocks(torch.from_numpy(xb)[None]),
                                   rtol=1e-4, atol=1e-5)
    for bad in ({"contrast_cell": 8}, {"contrast_stored": False}):
        with pytest.raises(ValueError, match="contrast_tiles reads the block contrast from .tiles planes"):
            FastNet(9, **{"block_contrast": (7, 8), "contrast_cell": 16, "contrast_stored": True, "contrast_tiles": True,
                          **bad})
    path = split_model(tmp_path, "tiles")
    graph = onnx.load(str(path)).graph
    # the stem reads the seven planes, the tile contrast the two .tiles planes (rtp.export.split_input_planes)
    readers = sorted(n.input[0] for n in graph.node if n.op_type == "Conv" and n.input[0].startswith("input"))
    assert readers == ["input", "input.7"] and not any(n.op_type in ("Slice", "Exp", "AveragePool") for n in graph.node)
    pred = sdk.load(path)
    assert pred.metadata.finite_probe and pred.splits
    tail = onnx.load_from_string(base64.b64decode(
        {p.key: p.value for p in onnx.load(str(path)).metadata_props}[sdk.TAIL_KEY]))
    convs = [n for n in tail.graph.node if n.op_type == "Conv" and n.input[0] == "input"]
    strides = [list(a.ints) for n in convs for a in n.attribute if a.name == "strides"]
    assert strides == [[16, 16]]  # the tail's one read of the frame: twelve pixels a tile
    est, feats = pred.predict_split(xt)
    with torch.inference_mode():
        net = checkpoint.load(tmp_path / "split-tiles.pt").net.eval()
        want = net(torch.from_numpy(xt)[None])[0].numpy()
    np.testing.assert_allclose(pred.predict_raw(xt), want, atol=1e-5)
    np.testing.assert_allclose(pred.predict_tail(feats, xt), est, atol=1e-6)
    bad = xt.copy()
    bad[8, 16 + 2, 3] = np.inf  # a value the tail reads (tile row 1, column 0: third row, fourth column)
    with pytest.raises(sdk.NonFiniteInputError):
        pred.predict_tail(feats, bad)
    with pytest.raises(sdk.NonFiniteInputError):
        pred.predict(bad)


def test_the_fast_network_reads_block_contrast_beside_its_stem_and_exports() -> None:
    from rtp.train.model import BlockContrast, FastNet

    net = FastNet(7, head_width=64, block_contrast=(0, 2)).eval()
    assert isinstance(net.contrast, BlockContrast) and net.config["block_contrast"] == [0, 2]
    assert "block_contrast" not in FastNet().config and FastNet().contrast is None
    convs = [m for m in net.layers if isinstance(m, torch.nn.Conv2d)]
    assert convs[1].in_channels == 16 + 12  # the first 3x3 block reads the stem and 2 planes x 6 rates
    # nothing fixed is stored: the checkpoint holds what trains, the Haar weights are rebuilt
    assert not any("contrast.weight" in k or "contrast.reduce" in k for k in net.state_dict())
    with pytest.raises(ValueError, match="block_contrast"):
        FastNet(4, block_contrast=(4,))
    _round_trip(net, "block_contrast", base_metadata(inputs=["reprojected.y", "seen", "albedo.y", "normal.z",
                                                             "roughness", "metallic", "specular"]), seed=5)
    # measured over 8-pixel cells it joins after the first pool, and frames must hold whole cells
    net8 = FastNet(7, head_width=64, block_contrast=(0,), contrast_cell=8).eval()
    assert net8.config["contrast_cell"] == 8 and net8.input_multiple == 8 and net.input_multiple == 4
    kinds = [type(m).__name__ for m in net8.layers]
    assert kinds[net8._contrast_at - 1] == "MaxPool2d"
    assert [m.in_channels for m in net8.layers if isinstance(m, torch.nn.Conv2d)][:3] == [7, 16, 16 + 6]
    assert "contrast_cell" not in FastNet(7, block_contrast=(0,), contrast_cell=4).config  # the stem's: the default
    for bad in (2, 6, 32):
        with pytest.raises(ValueError, match="contrast_cell"):
            FastNet(7, block_contrast=(0,), contrast_cell=bad)
    _round_trip(net8, "contrast_cell", base_metadata(inputs=["reprojected.y", "seen", "albedo.y", "normal.z",
                                                              "roughness", "metallic", "specular"]), seed=6)


def test_the_fast_network_takes_partial_tiles() -> None:
    from rtp.train.model import FastNet

    net = FastNet().eval()
    assert net.input_multiple == 4 and FastNet(stem=8, tile=4).input_multiple == 4
    assert MetricNet().input_multiple is None
    x = torch.rand(1, 4, 64, 96)
    with torch.inference_mode():
        whole = net(x)
        # 1920x1080 at 16-pixel tiles is 120 x 67.5 tiles: a frame 4 pixels past whole tiles gets the extra row
        ragged = net(torch.nn.functional.pad(x, (0, 0, 0, 4)))
    assert whole.shape == (1, 4, 4, 6) and ragged.shape == (1, 4, 5, 6)
    # tiles whose receptive field stays inside the frame do not change
    torch.testing.assert_close(ragged[:, :, :2], whole[:, :, :2])


def test_the_energy_norm_divides_by_the_local_energy_and_exports() -> None:
    from rtp.export import export_checkpoint
    from rtp.train.model import EnergyNorm, FastNet

    # per position: channels over their root mean square, the log of the mean square appended
    x = torch.tensor([[3.0, 0.0], [4.0, 0.0]]).reshape(1, 2, 1, 2)
    y = EnergyNorm(eps=0.0 + 1e-2)(x)
    e = (9.0 + 16.0) / 2 + 1e-2
    torch.testing.assert_close(y[0, :, 0, 0], torch.tensor([3.0 / e ** 0.5, 4.0 / e ** 0.5, float(np.log(e))]))
    # a dark, flat position stays finite: features 0, energy log(eps)
    torch.testing.assert_close(y[0, :, 0, 1], torch.tensor([0.0, 0.0, float(np.log(1e-2))]))
    # scaling a position's features leaves the normalised ones alone (up to eps) and shifts the log energy
    z = torch.rand(1, 16, 3, 3) + 1.0
    a, b = EnergyNorm()(z), EnergyNorm()(10 * z)
    torch.testing.assert_close(a[:, :16], b[:, :16], atol=1e-2, rtol=0)
    torch.testing.assert_close(b[:, 16] - a[:, 16], torch.full((1, 3, 3), float(np.log(100.0))), atol=1e-2, rtol=0)

    net = FastNet(4, depth=5, energy_norm=True).eval()
    kinds = [type(m).__name__ for m in net.layers]
    # after the first block's pool (1/8 resolution), one more channel into the next block
    assert kinds[:8] == ["Conv2d", "BatchNorm2d", "ReLU", "Conv2d", "BatchNorm2d", "ReLU", "MaxPool2d", "EnergyNorm"]
    assert net.layers[8].in_channels == 17 and net.config["energy_norm"] is True
    assert "energy_norm" not in FastNet(4).config  # checkpoints from before the option read the same
    # without a pool (a stem as wide as the tile) it follows the stem
    assert [type(m).__name__ for m in FastNet(4, tile=4, energy_norm=True).layers][3] == "EnergyNorm"
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.1, 0.1)
            m.running_var.uniform_(0.5, 1.5)
    with tempfile.TemporaryDirectory() as d:
        ck = checkpoint.save(Path(d) / "e.pt", net, base_metadata())
        assert checkpoint.load(ck).net.config["energy_norm"] is True
        pred = sdk.load(export_checkpoint(ck, Path(d) / "e.onnx"))
        x = np.random.default_rng(1).random((4, 44, 84), dtype=np.float32)
        with torch.inference_mode():
            want = net(torch.from_numpy(x)[None])[0].numpy()
        np.testing.assert_allclose(pred.predict_raw(x), want, atol=1e-5)


def test_the_two_layer_stem_reads_each_cell_twice() -> None:
    from rtp.export import export_checkpoint
    from rtp.train.model import FastNet, build_network

    net = FastNet(7, stem_layers=2).eval()
    convs = [m for m in net.layers if isinstance(m, torch.nn.Conv2d)]
    # two 2x2 stride-2 reads (7 -> 8 -> 16 channels) with BatchNorm and ReLU between, then the blocks
    assert [(c.kernel_size, c.stride, c.out_channels) for c in convs[:2]] == [((2, 2), (2, 2), 8), ((2, 2), (2, 2), 16)]
    kinds = [type(m).__name__ for m in net.layers]
    assert kinds[:6] == ["Conv2d", "BatchNorm2d", "ReLU", "Conv2d", "BatchNorm2d", "ReLU"]
    assert net.config["stem_layers"] == 2 and net.input_multiple == 4
    assert sum(p.numel() for p in net.parameters()) == 7 * 4 * 8 + 8 * 4 * 16 + 3 * 2304 + 2 * (8 + 4 * 16) + 68
    assert [c.kernel_size for c in build_network("fast", 4, 4, 16, stem=8, stem_layers=2).layers
            if isinstance(c, torch.nn.Conv2d)][:2] == [(4, 4), (2, 2)]
    for bad in ({"stem_layers": 3}, {"stem_layers": 2, "stem": 1}):
        with pytest.raises(ValueError, match="stem_layers"):
            FastNet(**bad)
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.1, 0.1)
            m.running_var.uniform_(0.5, 1.5)
    with tempfile.TemporaryDirectory() as d:
        meta = base_metadata(inputs=["reprojected.r", "seen", "albedo.r", "normal.z", "roughness", "metallic", "specular"])
        ck = checkpoint.save(Path(d) / "s.pt", net, meta)
        assert checkpoint.load(ck).net.config["stem_layers"] == 2
        pred = sdk.load(export_checkpoint(ck, Path(d) / "s.onnx"))
        x = np.random.default_rng(0).random((7, 44, 84), dtype=np.float32)  # partial tiles: multiples of 4
        with torch.inference_mode():
            want = net(torch.from_numpy(x)[None])[0].numpy()
        np.testing.assert_allclose(pred.predict_raw(x), want, atol=1e-5)
