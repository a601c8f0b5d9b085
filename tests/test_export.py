"""rtp-export: checkpoint -> ONNX round trip, parity with the torch pipeline, CLI, adoption."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rtp import export, sdk
from rtp.train import checkpoint
from rtp.train import transforms as tt
from rtp.train.model import MetricNet

from .conftest import base_metadata, split_model, trained_like_fast_net


def _trained_like_net(out_channels: int = 4, tile: int = 16, seed: int = 0) -> MetricNet:
    """A random network whose BatchNorm statistics are not the identity, as after training."""
    torch.manual_seed(seed)
    net = MetricNet(out_channels=out_channels, tile=tile)
    net.train()
    with torch.no_grad():
        for _ in range(3):
            net(torch.rand(4, 4, 4 * tile if tile >= 16 else 64, 64) * 2 - 0.5)
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.2, 0.2)
    return net.eval()


def _torch_pipeline(net: MetricNet, meta: sdk.ModelMetadata, x: np.ndarray) -> np.ndarray:
    """What predict must equal: edge padding to the tile size, the network, crop, decode."""
    t = meta.tile_size
    h, w = x.shape[-2:]
    xt = torch.from_numpy(x)[None]
    xt = F.pad(xt, (0, -w % t, 0, -h % t), mode="replicate")
    with torch.inference_mode():
        raw = net(xt)[:, :, : -(-h // t), : -(-w // t)]
    return tt.decode(raw, meta)[0].numpy()


@pytest.mark.parametrize(
    "meta",
    [
        base_metadata(safety=0.03),
        base_metadata(metric="flip", weber_l=None, transform={"type": "logistic", "mu_y": 0.2, "k": 10.0},
                      outputs=["1x2", "2x1"], safety=0.01),
        base_metadata(metric="psnr", weber_l=None, transform={"type": "clamped", "mu_y": 30.0},
                      default_threshold=35.0, safety=0.02),
    ],
    ids=["jnyang-clamped", "flip-logistic", "psnr"],
)
def test_export_round_trip_matches_torch(tmp_path: Path, meta: dict) -> None:
    net = _trained_like_net(out_channels=len(meta["outputs"]))
    ck = checkpoint.save(tmp_path / "m.pt", net, meta)
    out = export.export_checkpoint(ck, tmp_path / "m.onnx")
    pred = sdk.load(out)
    m = pred.metadata
    assert m.digest == sdk.model_digest(out.read_bytes())
    assert m.to_dict() | {"provenance": {}, "digest": None} == (
        sdk.ModelMetadata.from_dict(meta).to_dict() | {"provenance": {}, "digest": None})
    assert m.provenance["export"]["opset"] == export.DEFAULT_OPSET
    rng = np.random.default_rng(0)
    for h, w in ((64, 96), (72, 120)):  # the second is not a multiple of 16
        x = rng.random((4, h, w), dtype=np.float32)
        np.testing.assert_allclose(pred.predict(x), _torch_pipeline(net, m, x), rtol=1e-5, atol=1e-5)


def test_a_fast_network_exports_taking_partial_tiles(tmp_path: Path) -> None:
    from rtp.train.model import FastNet

    torch.manual_seed(0)
    net = FastNet()
    with torch.no_grad():  # trained-like BatchNorm statistics
        net.train()(torch.rand(4, 4, 64, 64))
    net.eval()
    out = export.export_checkpoint(checkpoint.save(tmp_path / "f.pt", net, base_metadata()), tmp_path / "f.onnx")
    pred = sdk.load(out)
    assert pred.metadata.input_multiple == 4 and pred.metadata.finite_probe == "finite_probe"
    assert pred.metadata.schema_version == 3
    rng = np.random.default_rng(0)
    x = rng.random((4, 72, 120), dtype=np.float32)  # whole 4-pixel steps, partial 16-pixel tiles: run as is
    with torch.inference_mode():
        ref = tt.decode(net(torch.from_numpy(x)[None]), pred.metadata)[0].numpy()
    assert ref.shape == (6, 5, 8)
    np.testing.assert_allclose(pred.predict(x), ref, rtol=1e-5, atol=1e-5)
    y = x[:, :70, :118]  # padded to 72x120 by repeating the edge
    np.testing.assert_allclose(pred.predict(y), _torch_pipeline_to(net, pred.metadata, y, 4), rtol=1e-5, atol=1e-5)


def _torch_pipeline_to(net: torch.nn.Module, meta: sdk.ModelMetadata, x: np.ndarray, multiple: int) -> np.ndarray:
    h, w = x.shape[-2:]
    t = meta.tile_size
    xt = F.pad(torch.from_numpy(x)[None], (0, -w % multiple, 0, -h % multiple), mode="replicate")
    with torch.inference_mode():
        raw = net(xt)[:, :, : -(-h // t), : -(-w // t)]
    return tt.decode(raw, meta)[0].numpy()


def test_export_writes_one_metadata_key_and_onnx_fields(tmp_path: Path) -> None:
    import onnx

    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    out = export.export_checkpoint(ck)  # default output: beside the checkpoint
    assert out == tmp_path / "m.onnx"
    model = onnx.load(str(out))
    keys = [p.key for p in model.metadata_props]
    assert keys.count(sdk.METADATA_KEY) == 1
    assert json.loads(dict((p.key, p.value) for p in model.metadata_props)[sdk.METADATA_KEY])["metric"] == "jnyang"
    assert model.producer_name == "rtp-export"
    assert [i.name for i in model.graph.input] == ["input"] and [o.name for o in model.graph.output] == ["metric"]
    dims = [d.dim_param or d.dim_value for d in model.graph.input[0].type.tensor_type.shape.dim]
    assert dims == ["batch", 4, "height", "width"]


def test_extra_metadata_is_merged(tmp_path: Path) -> None:
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    extra = tmp_path / "extra.yaml"
    extra.write_text("description: test model\ndefault_threshold: 0.15\nprovenance: {scenes: [oa_dm1]}\n")
    pred = sdk.load(export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=extra))
    assert pred.metadata.description == "test model" and pred.metadata.default_threshold == 0.15
    assert pred.metadata.provenance["scenes"] == ("oa_dm1",) and "export" in pred.metadata.provenance


def test_extra_metadata_errors_name_the_sidecar_and_keep_the_checkpoints_provenance(tmp_path: Path) -> None:
    """A sidecar's `provenance: 5` (or null, or a list) was replaced by the export's own entry: exit 0, the
    checkpoint's provenance lost without a word; a sidecar's invalid field named no file."""
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata(provenance={"train": {"steps": 3}}))
    extra = tmp_path / "extra.yaml"
    for text in ("provenance: 5\n", "provenance: null\n", "provenance: [a]\n"):
        extra.write_text(text)
        with pytest.raises(sdk.MetadataError, match=r"^.*extra\.yaml: provenance: expected a mapping") as err:
            export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=extra)
        assert err.value.key == "provenance" and not (tmp_path / "x.onnx").exists()
    with pytest.raises(sdk.MetadataError, match="^provenance: expected a mapping"):
        export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata={"provenance": 5})
    extra.write_text("default_threshold: .nan\n")
    with pytest.raises(sdk.MetadataError, match=r"^.*extra\.yaml: default_threshold: expected a finite number") as err:
        export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=extra)
    assert err.value.key == "default_threshold"
    extra.write_text("provenance: {scenes: [a]}\n")
    kept = sdk.load(export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=extra)).metadata.provenance
    assert kept["train"] == {"steps": 3} and kept["scenes"] == ("a",) and "export" in kept


@pytest.mark.parametrize("extra, key", [
    ("inputs: [reprojected.g, seen, albedo.g, normal.z]\n", "inputs"),  # as many planes, others
    ("metric: flip\nweber_l: null\n", "metric"),
    ("weber_l: 0.05\n", "weber_l"),
    ("transform: {type: clamped, mu_y: 0.5}\n", "transform"),
    # (refused by a consequence: "higher_is_better: psnr is higher-is-better"; by the network check, naming no
    # sidecar: "tile_size: metadata says 8 but the network's tile is 16", "outputs: metadata lists 2 rates ...")
    ("metric: psnr\n", "metric"),
    ("tile_size: 8\n", "tile_size"),
    ("outputs: [1x2, 2x1]\n", "outputs"),
    ("inputs: [reprojected.r, seen]\n", "inputs"),
])
def test_extra_metadata_cannot_change_what_the_network_was_trained_for(tmp_path: Path, extra: str, key: str) -> None:
    # (only their number was checked: a network trained on red exported as one reading green, or a JNYang
    # network as a FLIP model, with the checkpoint's safety and mu_y)
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    (tmp_path / "extra.yaml").write_text(extra)
    # a sidecar's refusal names the sidecar (it named none: which of a script's exports said so?)
    with pytest.raises(sdk.MetadataError, match=rf"^.*extra\.yaml: {key}: the checkpoint's network was trained for") as err:
        export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=tmp_path / "extra.yaml")
    assert err.value.key == key and not (tmp_path / "x.onnx").exists()
    with pytest.raises(sdk.MetadataError, match=f"^{key}: the checkpoint's network was trained for"):
        export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=yaml.safe_load(extra))
    restated = {k: base_metadata()[k] for k in ("metric", "inputs", "outputs", "tile_size", "transform")}
    assert sdk.load(export.export_checkpoint(ck, tmp_path / "y.onnx", extra_metadata=restated)).metadata.metric == "jnyang"
    # restated from a sidecar (YAML lists for the tuples): passes
    (tmp_path / "same.yaml").write_text("tile_size: 16\nweber_l: 0.02\noutputs: [1x2, 2x1, 2x4, 4x2]\n")
    assert sdk.load(export.export_checkpoint(ck, tmp_path / "z.onnx", extra_metadata=tmp_path / "same.yaml")).tile_size == 16


def test_extra_metadata_cannot_flip_a_plugin_metrics_direction(tmp_path: Path) -> None:
    """The SDK checks higher_is_better only against rtp's own metrics: a sidecar's `higher_is_better: true` on a
    checkpoint of a plugin error metric was exported, its safety margin then applied the optimistic way
    (worse_direction -1) and every rate decision inverted."""
    meta = base_metadata(metric="my_error", weber_l=None, higher_is_better=False, default_threshold=0.1)
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), meta)
    (tmp_path / "extra.yaml").write_text("higher_is_better: true\n")
    with pytest.raises(sdk.MetadataError, match=r"^.*extra\.yaml: higher_is_better: the checkpoint's network was "
                                                r"trained for false, the extra metadata says true;") as err:
        export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=tmp_path / "extra.yaml")
    assert err.value.key == "higher_is_better" and not (tmp_path / "x.onnx").exists()
    assert "higher_is_better" in export.TRAINED_FIELDS
    (tmp_path / "extra.yaml").write_text("higher_is_better: false\ndescription: restated\n")  # restated: passes
    m = sdk.load(export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=tmp_path / "extra.yaml")).metadata
    assert m.higher_is_better is False and m.worse_direction == 1.0


@pytest.mark.parametrize("extra, key", [
    ("input_multiple: 8\n", "input_multiple"),  # (the network's is 4: replaced without a word)
    ("finite_probe: finite_probe\n", "finite_probe"),  # (finite_probe=False kept it: failed once exported)
    (f"tail: sha256:{'0' * 64}\n", "tail"),  # (kept on a network that does not split: failed once exported)
    ("schema_version: 2\n", "schema_version"),
    (f"digest: sha256:{'0' * 64}\n", "digest"),
])
def test_extra_metadata_cannot_set_what_the_export_computes(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                            extra: str, key: str) -> None:
    from rtp.cli import export_main

    ck = checkpoint.save(tmp_path / "m.pt", trained_like_fast_net(4, seed=0), base_metadata())
    (tmp_path / "extra.yaml").write_text(extra)
    for probe in (True, False):  # (the sidecar named: it named none)
        with pytest.raises(sdk.MetadataError, match=rf"^.*extra\.yaml: {key}: computed by the export .*, expected no "
                                                    f"{key} in the extra metadata, got .*: leave it out$") as err:
            export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=tmp_path / "extra.yaml", finite_probe=probe)
        assert err.value.key == key and not (tmp_path / "x.onnx").exists()
    with pytest.raises(sdk.MetadataError, match=f"^{key}: computed by the export"):
        export.export_checkpoint(ck, tmp_path / "x.onnx", extra_metadata=yaml.safe_load(extra))
    assert key in export.COMPUTED_FIELDS
    assert export_main([str(ck), "--metadata", str(tmp_path / "extra.yaml"), "-o", str(tmp_path / "x.onnx")]) == 2
    assert f"rtp-export: error: {tmp_path / 'extra.yaml'}: {key}: computed by the export" in capsys.readouterr().err
    assert not (tmp_path / "x.onnx").exists()


def test_parity_failure_is_loud_and_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    target = tmp_path / "m.onnx"
    previous = Path(sdk.load("jnyang").path or "").read_bytes()  # (a previous export: a model, which it may replace)
    target.write_bytes(previous)
    real = sdk.ShadingRatePredictor.predict_raw
    monkeypatch.setattr(sdk.ShadingRatePredictor, "predict_raw", lambda self, x: real(self, x) + 1e-3)
    with pytest.raises(export.ExportError, match="disagree"):
        export.export_checkpoint(ck, target)
    assert target.read_bytes() == previous
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.onnx", "m.pt"]


def test_an_exporter_failure_is_one_short_line_and_nothing_on_stdout(tmp_path: Path,
                                                                    capfd: pytest.CaptureFixture[str]) -> None:
    """Opset 9 cannot express the fast network's ceil-mode max-pool: the ExportError held torch's whole IR graph
    (4 kB, one "line" of escaped newlines) and torch wrote the graph once more, 9 kB, to stdout, where
    rtp-export prints only the output's path. Now one short line that says which opset to try, stdout empty."""
    ck = checkpoint.save(tmp_path / "f.pt", trained_like_fast_net(4, seed=0), base_metadata())
    capfd.readouterr()
    with pytest.raises(export.ExportError) as err:
        export.export_checkpoint(ck, tmp_path / "f.onnx", opset=9)
    message = str(err.value)
    assert message.startswith("torch.onnx.export failed at opset 9: ") and "try the default, --opset 17" in message
    assert len(message) < 400 and "\\n" not in message and "\n" not in message and "Caused by" not in message
    assert "Caused by" in str(err.value.__cause__)  # (-v shows it whole)
    assert capfd.readouterr().out == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.pt"]


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "rtp.cli.export", *args], capture_output=True, text=True, timeout=300)


def test_cli_exit_codes(tmp_path: Path) -> None:
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    ok = _cli(str(ck), "-o", str(tmp_path / "cli.onnx"))
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.strip() == str(tmp_path / "cli.onnx")
    missing = _cli(str(tmp_path / "nope.pt"))
    assert missing.returncode == 2 and "no checkpoint" in missing.stderr and "Traceback" not in missing.stderr
    (tmp_path / "dir.pt").mkdir()
    folder = _cli(str(tmp_path / "dir.pt"))
    # (a usage error of the argument, as every rtp-export path's; the library's own words below)
    assert folder.returncode == 2 and "argument checkpoint: " in folder.stderr and "dir.pt' is a folder" in folder.stderr
    with pytest.raises(sdk.ModelNotFoundError, match="dir.pt' is a folder, not a file"):
        checkpoint.load(tmp_path / "dir.pt")
    usage = _cli("--adopt", "x.onnx")
    assert usage.returncode == 2 and "-o OUTPUT.onnx" in usage.stderr
    assert _cli().returncode == 2
    for opset in ("3", "0"):  # (0 used to mean the default)
        bad_opset = _cli(str(ck), "--opset", opset, "-o", str(tmp_path / "bad.onnx"))
        assert bad_opset.returncode == 2 and "opset" in bad_opset.stderr, opset
    assert not (tmp_path / "bad.onnx").exists()


# -- adoption ---------------------------------------------------------------------------------

PAPER_SIDECAR = {
    # The paper's AdaptiveVRS model (Jaliborc/rt-percept, branch renderer; docs/export.md): JNYang, linear factor 0.7,
    # safety 0.06, inputs albedo.r, specular.r, normal.z, shadow; channels 1x2 and 2x1.
    "metric": "jnyang",
    "transform": {"type": "linear", "factor": 0.7, "offset": 0.0},
    "safety": 0.06,
    "tile_size": 16,
    "inputs": ["albedo.r", "specular", "normal.z", "shadow"],
    "outputs": ["1x2", "2x1"],
    "default_threshold": 0.25,
    "weber_l": 1e-10,
    "description": "Cardoso et al. 2022 AdaptiveVRS model (adopted)",
}


def _foreign(tmp_path: Path, h: int = 1088, w: int = 1920, out_channels: int = 2) -> Path:
    """A model with the paper's published signature: input `input` 1x4x1088x1920, output `metric`,
    static shapes, no metadata."""
    net = _trained_like_net(out_channels=out_channels)
    path = tmp_path / "Model.onnx"
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        torch.onnx.export(net, (torch.rand(1, 4, h, w),), str(path), input_names=["input"], output_names=["metric"],
                          opset_version=9, dynamo=False)
    return path


def test_adopt_the_paper_signature(tmp_path: Path) -> None:
    src = _foreign(tmp_path)
    out = export.adopt(src, PAPER_SIDECAR, tmp_path / "adopted.onnx")
    pred = sdk.load(out)
    assert pred.static_size == (1088, 1920)
    assert pred.metadata.safety == 0.06
    x = np.random.default_rng(0).random((4, 1080, 1920), dtype=np.float32)  # a 1080p frame, padded to 1088
    assert pred.predict(x).shape == (6, 68, 120)


def test_adopt_dynamic_runs_any_size(tmp_path: Path) -> None:
    src = _foreign(tmp_path, 64, 96)
    pred = sdk.load(export.adopt(src, PAPER_SIDECAR, tmp_path / "dyn.onnx", dynamic=True))
    assert pred.static_size is None
    assert pred.predict(np.zeros((4, 100, 200), np.float32)).shape == (6, 7, 13)


def test_adopt_checks_the_model_against_the_sidecar(tmp_path: Path) -> None:
    src = _foreign(tmp_path, 64, 96)
    with pytest.raises(sdk.MetadataError, match="outputs"):
        export.adopt(src, {**PAPER_SIDECAR, "outputs": ["1x2", "2x1", "2x4", "4x2"]}, tmp_path / "a.onnx")
    with pytest.raises(sdk.MetadataError, match="inputs"):
        export.adopt(src, {**PAPER_SIDECAR, "inputs": ["albedo.r", "normal.z"]}, tmp_path / "a.onnx")
    with pytest.raises(sdk.MetadataError, match="tile_size"):
        export.adopt(src, {**PAPER_SIDECAR, "tile_size": 8}, tmp_path / "a.onnx")
    assert not (tmp_path / "a.onnx").exists()
    adopted = export.adopt(src, PAPER_SIDECAR, tmp_path / "a.onnx")
    with pytest.raises(sdk.MetadataError, match="--replace"):
        export.adopt(adopted, PAPER_SIDECAR, tmp_path / "b.onnx")
    export.adopt(adopted, {**PAPER_SIDECAR, "safety": 0.1}, tmp_path / "b.onnx", replace=True)
    assert sdk.load(tmp_path / "b.onnx").metadata.safety == 0.1
    with pytest.raises(sdk.MetadataError, match="already carries rtp metadata"):  # not "not a published model"
        export.adopt(adopted, None, tmp_path / "c.onnx")
    r = _cli("--adopt", str(adopted), "-o", str(tmp_path / "c.onnx"))
    assert r.returncode == 2 and "already carries rtp metadata" in r.stderr, r.stderr


def test_adopt_reads_a_fixed_models_tile_grid_as_the_sdk_does(tmp_path: Path) -> None:
    """A fixed input that is no multiple of the tile size: adopt compared the output with 40 // 16 = 2 tiles a side,
    refusing a model that predicts its partial last tiles (3x3, which sdk.load and predict take) and passing one
    that drops them (whose every predict then failed)."""
    from .conftest import build_onnx

    sidecar = {**PAPER_SIDECAR, "outputs": ["1x2", "2x1", "2x4", "4x2"], "input_multiple": 4}
    takes = build_onnx(tmp_path / "takes.onnx", weights=np.eye(4, dtype=np.float32), static=(1, 40, 40),
                       ceil_mode=True)
    pred = sdk.load(export.adopt(takes, sidecar, tmp_path / "a.onnx"))
    assert pred.predict(np.zeros((4, 40, 40), np.float32)).shape == (6, 3, 3)
    drops = build_onnx(tmp_path / "drops.onnx", weights=np.eye(4, dtype=np.float32), static=(1, 40, 40))
    with pytest.raises(sdk.MetadataError, match="maps 40x40 to 2x2 tiles, expected 3x3 .*partial") as info:
        export.adopt(drops, sidecar, tmp_path / "b.onnx")
    assert info.value.key == "tile_size" and not (tmp_path / "b.onnx").exists()


def test_adopt_checks_that_a_dynamic_model_takes_the_partial_tiles_its_sidecar_says(tmp_path: Path) -> None:
    """A sidecar's ``input_multiple`` below the tile on a model of symbolic size: adopt ran only frames of whole
    tiles, so a model that floors partial tiles (a floor-mode pool) was adopted with ``input_multiple: 8`` and then
    failed every predict of a frame of partial tiles (InferenceError at 120x72). Now that is refused, naming the
    field, nothing written; a model that takes them (ceil mode) adopts and predicts them."""
    from .conftest import build_onnx

    sidecar = base_metadata(input_multiple=8)
    floors = build_onnx(tmp_path / "floors.onnx", weights=np.eye(4, dtype=np.float32))
    with pytest.raises(sdk.MetadataError, match="input_multiple: .*multiples of 8 pixels.*does not run") as info:
        export.adopt(floors, sidecar, tmp_path / "a.onnx")
    assert info.value.key == "input_multiple" and not (tmp_path / "a.onnx").exists()
    pred = sdk.load(export.adopt(floors, base_metadata(), tmp_path / "a.onnx"))  # whole tiles: padded to them
    assert pred.predict(np.zeros((4, 72, 120), np.float32)).shape == (6, 5, 8)
    takes = build_onnx(tmp_path / "takes.onnx", weights=np.eye(4, dtype=np.float32), ceil_mode=True)
    pred = sdk.load(export.adopt(takes, sidecar, tmp_path / "b.onnx"))
    assert pred.metadata.input_multiple == 8
    assert pred.predict(np.zeros((4, 72, 120), np.float32)).shape == (6, 5, 8)


def test_adopt_cli_with_a_yaml_sidecar(tmp_path: Path) -> None:
    import yaml

    src = _foreign(tmp_path, 64, 96)
    side = tmp_path / "side.yaml"
    side.write_text(yaml.safe_dump(PAPER_SIDECAR))
    r = _cli("--adopt", str(src), "--metadata", str(side), "-o", str(tmp_path / "cli.onnx"), "--dynamic")
    assert r.returncode == 0, r.stderr
    assert sdk.load(tmp_path / "cli.onnx").metadata.inputs == ("albedo.r", "specular", "normal.z", "shadow")
    corrupt = tmp_path / "corrupt.onnx"
    corrupt.write_bytes(b"junk")
    r = _cli("--adopt", str(corrupt), "--metadata", str(side), "-o", str(tmp_path / "x.onnx"))
    assert r.returncode == 2 and "not a readable ONNX model" in r.stderr


def test_adopt_cli_without_a_sidecar_names_a_file_that_is_no_onnx_model(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A checkpoint (or a damaged file) given to --adopt without a sidecar was told to bring one ("is not one of the
    paper's published models rtp recognises: pass its sidecar"), and with one it was no ONNX model after all."""
    from rtp.cli import export_main

    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    assert export_main(["--adopt", str(ck), "-o", str(tmp_path / "x.onnx")]) == 2
    err = capsys.readouterr().err
    assert "not a readable ONNX model" in err and "sidecar" not in err, err
    # an ONNX model rtp does not recognise still needs its sidecar, and says so
    assert export_main(["--adopt", str(_foreign(tmp_path, 64, 96)), "-o", str(tmp_path / "x.onnx")]) == 2
    err = capsys.readouterr().err
    assert "pass its sidecar with --metadata SIDECAR.yaml" in err and "not a readable" not in err, err
    assert not (tmp_path / "x.onnx").exists()



def test_adopt_refuses_graphs_that_are_not_one_plane_input_to_one_grid(tmp_path: Path) -> None:
    """Adoption names what the graph should be before writing anything: a model with a second output,
    an integer input or a rank-3 output is refused with the inputs and outputs it found."""
    import onnx
    from onnx import TensorProto, helper

    def graph(name: str, *, outputs: int = 1, in_type: int = TensorProto.FLOAT, rank3: bool = False) -> Path:
        nodes = [helper.make_node("Cast", ["input"], ["x"], to=TensorProto.FLOAT),
                 helper.make_node("Conv", ["x", "W"], ["c"], kernel_shape=[1, 1]),
                 helper.make_node("MaxPool", ["c"], ["metric"], kernel_shape=[16, 16], strides=[16, 16])]
        outs = [helper.make_tensor_value_info("metric", TensorProto.FLOAT, [1, 2, 4, 6])]
        if outputs == 2:
            nodes.append(helper.make_node("Identity", ["metric"], ["second"]))
            outs.append(helper.make_tensor_value_info("second", TensorProto.FLOAT, [1, 2, 4, 6]))
        if rank3:
            nodes[-1].output[0] = "pooled"
            nodes.append(helper.make_node("Squeeze", ["pooled", "axes"], ["metric"]))
            outs = [helper.make_tensor_value_info("metric", TensorProto.FLOAT, [2, 4, 6])]
        inits = [helper.make_tensor("W", TensorProto.FLOAT, [2, 4, 1, 1], np.ones(8).tolist()),
                 helper.make_tensor("axes", TensorProto.INT64, [1], [0])]
        g = helper.make_graph(nodes, name, [helper.make_tensor_value_info("input", in_type, [1, 4, 64, 96])], outs,
                              initializer=inits)
        model = helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)])
        model.ir_version = 8
        onnx.checker.check_model(model)
        path = tmp_path / f"{name}.onnx"
        onnx.save(model, str(path))
        return path

    out = tmp_path / "adopted.onnx"
    with pytest.raises(sdk.MetadataError, match=r"expected one input and one output, found inputs \['input'\] and "
                                                r"outputs \['metric', 'second'\]"):
        export.adopt(graph("two", outputs=2), PAPER_SIDECAR, out)
    for path in (graph("ints", in_type=TensorProto.INT32), graph("rank3", rank3=True)):
        with pytest.raises(sdk.MetadataError, match=r"expected a float32 \(N, C, H, W\) input and a rank-4 output"):
            export.adopt(path, PAPER_SIDECAR, out)
    assert not out.exists()
    assert sdk.load(export.adopt(graph("fine"), PAPER_SIDECAR, out)).predict(np.zeros((4, 64, 96), np.float32)).shape \
        == (6, 4, 6)  # the same graph, one float input to one rank-4 grid

def _researchers_model(tmp_path: Path, name: str, *, in_shape: list | None = None, before: list | None = None,
                       after: list | None = None, domain: str = "", extra: list | None = None) -> Path:
    """A per-tile predictor trained elsewhere, as onnx.helper writes it: ``input`` (N, 4, H, W) -> 1x1 Conv -> 16-pixel
    average pool (ceil mode) -> ``metric`` (N, 4, H/16, W/16), with ``before`` nodes between the input and the
    convolution (which reads ``x``) and ``after`` nodes between the pool (``p``) and the output."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    nodes = list(before or [helper.make_node("Identity", ["input"], ["x"])])
    nodes += [helper.make_node("Conv", ["x", "W"], ["c"], kernel_shape=[1, 1]),
              helper.make_node("AveragePool", ["c"], ["p"], kernel_shape=[16, 16], strides=[16, 16], ceil_mode=1)]
    nodes += after or [helper.make_node("Sigmoid", ["p"], ["metric"])]
    weights = np.random.default_rng(0).standard_normal(16).astype(np.float32) * 0.5
    g = helper.make_graph(nodes, name, [helper.make_tensor_value_info("input", TensorProto.FLOAT,
                                                                       in_shape or ["N", 4, "H", "W"])],
                          [helper.make_tensor_value_info("metric", TensorProto.FLOAT, ["N", 4, "h", "w"])],
                          initializer=[numpy_helper.from_array(weights.reshape(4, 4, 1, 1), "W"),  # (raw data)
                                       *(extra or [])])
    opsets = [helper.make_opsetid("", 17)] + ([helper.make_opsetid(domain, 1)] if domain else [])
    model = helper.make_model(g, opset_imports=opsets)
    model.ir_version = 8
    path = tmp_path / f"{name}.onnx"
    onnx.save(model, str(path))
    return path


def test_adopt_names_a_channels_last_input(tmp_path: Path) -> None:
    """A model exported channels-last (N, H, W, C), its planes last: of symbolic size it passed every check of the
    graph (its second dimension symbolic) and failed the first predict with onnxruntime's words (exit 1: "Input
    channels C is not equal to kernel channels"); of fixed size it was told "the model input has 64" channels. Now
    both are named channels-last before anything is written, exit 2."""
    from onnx import helper

    to_nchw = [helper.make_node("Transpose", ["input"], ["x"], perm=[0, 3, 1, 2])]
    side = tmp_path / "side.yaml"
    side.write_text(yaml.safe_dump(base_metadata()))
    out = tmp_path / "a.onnx"
    for shape in (["N", "H", "W", 4], [1, 64, 96, 4]):
        src = _researchers_model(tmp_path, "nhwc", in_shape=shape, before=to_nchw)
        with pytest.raises(sdk.MetadataError, match=r"channels-last \(N, H, W, C\).*rtp feeds \(N, C, H, W\)") as info:
            export.adopt(src, base_metadata(), out, dynamic=True)
        assert info.value.key == "inputs" and not out.exists()
    r = _cli("--adopt", str(src), "--metadata", str(side), "-o", str(out), "--dynamic")
    assert r.returncode == 2 and "channels-last" in r.stderr and not out.exists(), r.stderr
    # channels-first, the same model adopts (a width of 4 pixels is no plane count: the model's own C is 4)
    assert export.adopt(_researchers_model(tmp_path, "nchw"), base_metadata(), out, dynamic=True) == out


def test_adopt_names_the_model_and_its_sidecar_not_a_temporary_file(tmp_path: Path) -> None:
    """What sdk.load found in the adopted model (here: outputs at pixel resolution, where the sidecar says 16-pixel
    tiles; an operator onnxruntime lacks) named adopt's temporary file ('.a.onnx.x1y2z3.tmp', gone when the user read
    it) and blamed the file's metadata as "another model's, or was edited". Now the message names the model adopted
    and the sidecar, with the same class and key, and a foreign operator says what to do."""
    from onnx import helper

    out = tmp_path / "a.onnx"
    pixels = _researchers_model(tmp_path, "pixels", after=[helper.make_node("Sigmoid", ["c"], ["metric"])])
    with pytest.raises(sdk.MetadataError, match=r"tile_size: the metadata \(given as a mapping\) says 16, but the "
                                                r"model maps 128x128 pixels to 128x128 tiles") as info:
        export.adopt(pixels, base_metadata(), out, dynamic=True)
    assert info.value.key == "tile_size" and ".tmp" not in str(info.value) and "edited" not in str(info.value)
    fancy = _researchers_model(tmp_path, "fancy", domain="com.example.research",
                               after=[helper.make_node("FancyPool", ["p"], ["metric"], domain="com.example.research")])
    with pytest.raises(sdk.ModelLoadError, match="com.example.research:FancyPool.*standard ONNX operators") as err:
        export.adopt(fancy, base_metadata(), out)
    assert ".tmp" not in str(err.value) and str(fancy) in str(err.value)
    assert not out.exists() and not list(tmp_path.glob(".a.onnx.*"))


def test_adopt_refuses_a_model_that_predicts_nan_on_a_blank_frame(tmp_path: Path) -> None:
    """A model that divides by its input's statistics (here p / p) predicts finite values on random frames, the only
    ones adopt ran, and NaN on a frame of zeros (background: black, unseen, no normals), which predict then returned
    for every such frame. adopt now runs a frame of zeros too."""
    from onnx import helper

    src = _researchers_model(tmp_path, "ratio", after=[helper.make_node("Div", ["p", "p"], ["one"]),
                                                        helper.make_node("Sigmoid", ["p"], ["s"]),
                                                        helper.make_node("Mul", ["s", "one"], ["metric"])])
    out = tmp_path / "a.onnx"
    with pytest.raises(export.ExportError, match="non-finite predictions on a frame of zeros at 192x128"):
        export.adopt(src, base_metadata(), out, dynamic=True)
    assert not out.exists()


def test_adopt_refuses_outputs_in_the_metrics_own_units(tmp_path: Path) -> None:
    """A network trained on PSNR in dB (outputs 14 to 38 here) given a sidecar of a transform (outputs in 0 to 1)
    was adopted, and predicted -2,500 to -800 dB (the linear transform's inverse is not clamped), every tile failing
    every threshold. Now adopt names the transform and the outputs' range."""
    from onnx import TensorProto, helper

    db = helper.make_tensor("dB", TensorProto.FLOAT, [], [60.0])
    src = _researchers_model(tmp_path, "decibels", extra=[db], after=[helper.make_node("Sigmoid", ["p"], ["s"]),
                                                                     helper.make_node("Mul", ["s", "dB"], ["metric"])])
    psnr = base_metadata(metric="psnr", weber_l=None, transform={"type": "linear", "factor": -0.015, "offset": 1.0},
                         default_threshold=35.0)
    out = tmp_path / "a.onnx"
    with pytest.raises(sdk.MetadataError, match=r"transform: .*100% of its outputs .*outside -0.5 to 1.5 \(1\d\.\d+ to "
                                                r"3\d\.\d+\)") as info:
        export.adopt(src, psnr, out, dynamic=True)
    assert info.value.key == "transform" and not out.exists()


def test_adopt_takes_external_data_inside_and_refuses_a_model_too_large_for_one_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A model saved with its weights in a .data file beside it adopts with every tensor inside the one file (which its
    digest covers) and predicts as onnxruntime runs the model it came from. One whose tensors exceed what one ONNX file
    holds with them (protobuf's 2 GB; here the limit made small) was read in whole and then failed in protobuf's
    serializer (exit 1); it is now refused before its weights are read, saying why, exit 2."""
    import onnx
    import onnxruntime as ort

    src = _researchers_model(tmp_path, "plain")
    ext = tmp_path / "ext.onnx"
    onnx.save(onnx.load(str(src)), str(ext), save_as_external_data=True, location="ext.onnx.data", size_threshold=0)
    assert (tmp_path / "ext.onnx.data").stat().st_size == 64
    out = export.adopt(ext, base_metadata(), tmp_path / "a.onnx", dynamic=True)
    assert not any(t.external_data for t in onnx.load(str(out), load_external_data=False).graph.initializer)
    pred = sdk.load(out)
    assert pred.metadata.digest and pred.metadata.provenance["adopted"]["file"] == "ext.onnx"
    x = np.random.default_rng(3).random((2, 4, 64, 96), dtype=np.float32)  # (whole tiles: nothing padded)
    raw = ort.InferenceSession(str(src), providers=["CPUExecutionProvider"]).run(None, {"input": x})[0]
    assert np.array_equal(pred.predict_raw(x), raw)
    monkeypatch.setattr(export._export, "PROTOBUF_LIMIT", ext.stat().st_size + 32)  # (the file fits; not its weights)
    with pytest.raises(sdk.ModelLoadError, match="more than one ONNX file can hold.*adopt a smaller model"):
        export.adopt(ext, base_metadata(), tmp_path / "b.onnx", dynamic=True)
    assert not (tmp_path / "b.onnx").exists()


# -- the paper's published models ---------------------------------------------------------------

PUBLISHED = Path(__file__).parent / "data" / "published"  # the six files, as published (LICENSE.md there)


@pytest.mark.parametrize("name", ["Model", "FLIP", "JNFLIP", "JNYang", "LPIPS", "PSNR"])
def test_published_models_adopt_without_a_sidecar(tmp_path: Path, name: str) -> None:
    src = PUBLISHED / f"{name}.onnx"
    known = export.identify(src)
    assert known is not None and known.path.endswith(f"/{name}.onnx")
    out = export.adopt(src, None, tmp_path / "a.onnx", dynamic=True)
    pred = sdk.load(out)
    m = pred.metadata
    assert m.to_dict()["default_threshold"] == known.metadata["default_threshold"]
    origin = m.provenance["adopted"]["published"]
    assert origin["repository"] == "https://github.com/Jaliborc/rt-percept" and origin["branch"] == "renderer"
    assert m.provenance["adopted"]["sha256"] == known.sha256 and m.digest
    x = np.random.default_rng(0).random((len(m.inputs), 64, 96), dtype=np.float32)
    y = pred.predict(x)
    assert y.shape == (6, 64 // m.tile_size, 96 // m.tile_size) and np.isfinite(y).all()
    if m.tile_size == 8:  # on NVIDIA's 16-pixel hardware tiles: the worst of each 2x2 block
        assert np.array_equal(sdk.load(out, tile_size=16).predict(x), sdk.pool_tiles(y, 2, higher_is_better=m.higher_is_better))


def test_a_sidecar_overrides_the_shipped_one_and_provenance_says_so(tmp_path: Path) -> None:
    import yaml

    side = tmp_path / "mine.yaml"
    side.write_text(yaml.safe_dump({**export.identify(PUBLISHED / "Model.onnx").metadata, "default_threshold": 0.3}))
    m = sdk.load(export.adopt(PUBLISHED / "Model.onnx", side, tmp_path / "a.onnx")).metadata
    assert m.default_threshold == 0.3 and m.provenance["adopted"]["metadata"] == str(side)
    assert m.provenance["adopted"]["published"]["name"] == "vrs-unseen"


def test_an_unknown_file_without_a_sidecar_is_refused(tmp_path: Path) -> None:
    src = _foreign(tmp_path, 64, 96)
    assert export.identify(src) is None
    with pytest.raises(sdk.MetadataError, match="metadata=.*--metadata"):
        export.adopt(src, None, tmp_path / "a.onnx")
    r = _cli("--adopt", str(src), "-o", str(tmp_path / "a.onnx"))
    assert r.returncode == 2 and "--metadata SIDECAR.yaml" in r.stderr and "metadata=" not in r.stderr
    assert not (tmp_path / "a.onnx").exists()
    r = _cli("--adopt", str(PUBLISHED / "PSNR.onnx"), "-o", str(tmp_path / "psnr.onnx"))
    assert r.returncode == 0 and sdk.load(tmp_path / "psnr.onnx").metadata.metric == "psnr", r.stderr


def test_the_registry_matches_the_published_files() -> None:
    import hashlib

    files = sorted(PUBLISHED.glob("*.onnx"))
    assert len(export.published_models()) == len(files) == 6
    for f in files:
        assert export.identify(f) is not None, f
        assert hashlib.sha256(f.read_bytes()).hexdigest() in {m.sha256 for m in export.published_models()}


def test_export_names_what_it_was_given_instead_of_a_checkpoint(tmp_path: Path) -> None:
    side = tmp_path / "sidecar.yaml"
    side.write_text("metric: jnyang\n")
    junk = tmp_path / "model.pt"
    junk.write_bytes(bytes(range(256)))
    # a pickle of another program (protocol 4: torch warned in two lines before the error), an exported model
    other = tmp_path / "other.pt"
    other.write_bytes(__import__("pickle").dumps({"weights": [1.0, 2.0]}, protocol=4))
    onnx_model = tmp_path / "model.onnx"
    onnx_model.write_bytes(b"\x08\x07")  # (any bytes torch cannot read: the name says what it is)
    for path, needle in ((side, "is a metadata file, not a checkpoint"), (junk, "torch cannot read it"),
                         (other, "torch cannot read it"), (onnx_model, "by its name, an ONNX model, exported already")):
        r = _cli(str(path))
        assert r.returncode == 2 and needle in r.stderr and "weights_only" not in r.stderr, r.stderr
        assert len(r.stderr.splitlines()) == 1, r.stderr


# -- the finite probe --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def fast_onnx(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """rtp's fast network on eight planes, trained-like BatchNorm, exported (with its finite probe)."""
    tmp = tmp_path_factory.mktemp("probe")
    inputs = ["reprojected.r", "reprojected.g", "reprojected.b", "seen", "albedo.r", "albedo.g", "albedo.b", "normal.z"]
    meta = base_metadata(metric="lpips", weber_l=None, default_threshold=0.1, inputs=inputs)
    return export.export_checkpoint(checkpoint.save(tmp / "f.pt", trained_like_fast_net(8, seed=3), meta),
                                    tmp / "f.onnx")


def test_the_fast_network_is_exported_with_a_finite_probe_and_the_paper_network_without(
    fast_onnx: Path, tmp_path: Path
) -> None:
    import onnx

    model = onnx.load(str(fast_onnx))
    assert [o.name for o in model.graph.output] == ["metric", "finite_probe"]
    made = {n.output[0]: n for n in model.graph.node}
    total = made["finite_probe"]
    mean = made[total.input[0]]
    # the stem's output before its ReLU: its eight planes come in two inputs (split_input_planes), and the
    # probe reads the sum of their convolutions, so a NaN in either reaches it
    stem = made[mean.input[0]]
    assert (total.op_type, mean.op_type, stem.op_type) == ("ReduceSum", "GlobalAveragePool", "Sum")
    assert sorted(made[i].input[0] for i in stem.input) == ["input", "input.4"]
    assert all(made[i].op_type == "Conv" for i in stem.input)
    # the paper's first layer is a full-resolution 3x3 convolution: summing it would cost more than the frame
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    pred = sdk.load(export.export_checkpoint(ck))
    assert pred.metadata.finite_probe is None and pred.metadata.schema_version == 1


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(h=st.integers(1, 40), w=st.integers(1, 40), batch=st.integers(1, 2), data=st.data(),
       bad=st.sampled_from([np.nan, np.inf, -np.inf]))
def test_the_probe_refuses_a_nan_or_an_infinity_anywhere(
    fast_onnx: Path, h: int, w: int, batch: int, data: st.DataObject, bad: float
) -> None:
    """Any frame size (padded up to the stem's multiple of 4 by repeating the edge), any pixel, any plane,
    any non-finite value: the probe (not a read of the frame) catches it and the error names it."""
    pred = sdk.load(fast_onnx)
    x = np.random.default_rng(h * 41 + w).random((batch, 8, h, w), dtype=np.float32)
    clean = pred.predict(x)
    assert np.isfinite(clean).all()
    where = (data.draw(st.integers(0, batch - 1)), data.draw(st.integers(0, 7)), data.draw(st.integers(0, h - 1)),
             data.draw(st.integers(0, w - 1)))
    x[where] = bad
    with pytest.raises(sdk.NonFiniteInputError, match=re.escape(f"first at index {where}")):
        pred.predict(x)


def test_stripping_and_restamping_the_probe_change_no_prediction(fast_onnx: Path, tmp_path: Path) -> None:
    """The graph without the probe (for an engine that runs the file itself) predicts the same to the
    bit, holds exactly the nodes of an export without it, and restamping gives the probe back."""
    import onnx

    bare = export.strip_finite_probe(fast_onnx, tmp_path / "bare.onnx")
    x = np.random.default_rng(5).random((8, 68, 100), dtype=np.float32)
    assert sdk.load(bare).metadata.finite_probe is None and sdk.load(bare).metadata.schema_version == 2
    assert [o.name for o in onnx.load(str(bare)).graph.output] == ["metric"]
    assert len(onnx.load(str(bare)).graph.node) == len(onnx.load(str(fast_onnx)).graph.node) - 2
    np.testing.assert_array_equal(sdk.load(bare).predict(x), sdk.load(fast_onnx).predict(x))
    with pytest.raises(sdk.ParameterError, match="no finite probe"):
        export.strip_finite_probe(bare, tmp_path / "again.onnx")
    assert not (tmp_path / "again.onnx").exists()
    export.restamp(bare)
    again = sdk.load(bare)
    assert again.metadata.finite_probe == "finite_probe" and again.metadata.digest == sdk.model_digest(bare.read_bytes())
    np.testing.assert_array_equal(again.predict(x), sdk.load(fast_onnx).predict(x))


def test_the_cli_exports_without_the_probe_and_strips_it(fast_onnx: Path, tmp_path: Path) -> None:
    ck = fast_onnx.with_suffix(".pt")
    cmd = [sys.executable, "-m", "rtp.cli.export"]
    out = subprocess.run([*cmd, str(ck), "-o", str(tmp_path / "n.onnx"), "--no-finite-probe"], capture_output=True,
                         text=True)
    assert out.returncode == 0, out.stderr
    assert sdk.load(tmp_path / "n.onnx").metadata.finite_probe is None
    out = subprocess.run([*cmd, "--strip-probe", str(fast_onnx), "-o", str(tmp_path / "s.onnx")], capture_output=True,
                         text=True)
    assert out.returncode == 0 and out.stdout.strip() == str(tmp_path / "s.onnx")
    assert sdk.load(tmp_path / "s.onnx").metadata.finite_probe is None
    for bad, message in (([ "--strip-probe", str(fast_onnx)], "needs -o"),
                         (["--strip-probe", str(fast_onnx), str(ck), "-o", "x.onnx"], "takes only -o"),
                         (["--no-finite-probe", "--adopt", str(fast_onnx), "-o", "x.onnx"], "applies to exporting"),
                         (["--restamp", str(fast_onnx), "--no-finite-probe"], "takes no other options")):
        r = subprocess.run([*cmd, *bad], capture_output=True, text=True)
        assert r.returncode == 2 and message in r.stderr, (bad, r.stderr)



@pytest.mark.parametrize("cell", [4, 8])
def test_a_stored_contrast_finer_than_the_tile_exports_as_one_graph(tmp_path: Path, cell: int) -> None:
    """``--block-contrast`` on .blocks planes at the stem's cell or after the first pool (what ``rtp train``
    takes): its trunk's features are not per tile, so the export is one graph that does not split (it was
    exported as a split network and failed its own tail check: "features: expected (channels, 4, 6) for this
    frame's tiles, got (16, 16, 24)"), predicting as torch on frames of partial tiles."""
    from rtp.train.model import FastNet

    torch.manual_seed(0)
    net = FastNet(6, block_contrast=(4, 5), contrast_cell=cell, contrast_stored=True)
    with torch.no_grad():
        net.train()(torch.rand(2, 6, 64, 64))
    net.eval()
    assert not net.splits and FastNet(6, block_contrast=(4, 5), contrast_cell=16, contrast_stored=True).splits
    inputs = [*sdk.DEFAULT_INPUTS, "reprojected.y.blocks", "albedo.y.blocks"]
    out = export.export_checkpoint(checkpoint.save(tmp_path / "b.pt", net, base_metadata(inputs=inputs)),
                                   tmp_path / "b.onnx")
    pred = sdk.load(out)
    assert not pred.splits and pred.metadata.tail is None and pred.metadata.input_multiple == 4
    x = np.random.default_rng(1).random((6, 52, 84), dtype=np.float32)
    np.testing.assert_allclose(pred.predict(x), _torch_pipeline_to(net, pred.metadata, x, 4), rtol=1e-5, atol=1e-5)


def test_a_split_networks_tail_left_by_a_killed_export_is_removed_by_the_next(tmp_path: Path,
                                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """A split network's tail is exported to a scratch file beside the model; an export killed there (kill -9, the
    OOM killer: no cleanup runs) leaves it. It was ``.m.onnx.k2j4x9ab.tmp.tail`` (a mkstemp name plus ``.tail``), a
    name no later export knew: it
    stayed beside the model for good, one more each kill. It is now named as atomic_output names its temporary files,
    so the next export of the model removes it once it is an orphan (unlocked, a minute old), as it removes its own."""
    import os

    from rtp.export import _export as ex

    split_model(tmp_path)  # (the checkpoint split-blocks.pt and its export)
    out = tmp_path / "split-blocks.onnx"
    scratch: list[Path] = []
    real = ex._tail_model

    def tail_model(net, dummy, path, opset):  # type: ignore[no-untyped-def]
        scratch.append(Path(path))
        return real(net, dummy, path, opset)

    monkeypatch.setattr(ex, "_tail_model", tail_model)
    export.export_checkpoint(tmp_path / "split-blocks.pt", out)
    (left,) = scratch
    assert left.parent == out.parent and not left.exists()
    left.write_bytes(b"half a tail")  # what a kill inside the tail's export leaves
    os.utime(left, (os.path.getmtime(out) - 3600,) * 2)  # (an hour ago: no live export's)
    export.export_checkpoint(tmp_path / "split-blocks.pt", out)
    assert not left.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["split-blocks.onnx", "split-blocks.pt"]
    assert sdk.load(out).splits


@pytest.mark.parametrize("argv, words", [
    (["--one-input", "--adopt", "f.onnx", "-o", "x.onnx"], "--one-input applies to exporting a checkpoint"),
    (["m.pt", "--adopt", "f.onnx", "-o", "x.onnx"], "give either a checkpoint or --adopt FOREIGN.onnx, not both"),
    (["--adopt", "f.onnx", "-o", "x.onnx", "--opset", "17"], "--opset applies to exporting a checkpoint"),
    (["m.pt", "--dynamic"], "--dynamic and --replace apply to --adopt only"),
    (["m.pt", "--replace"], "--dynamic and --replace apply to --adopt only"),
    (["--retune", "jnyang", "-o", "x.onnx"], "--retune needs --metadata SIDECAR.yaml"),
    (["--retune", "jnyang", "--metadata", "s.yaml", "-o", "x.onnx", "--dynamic"], "--retune MODEL takes only"),
    (["--join-planes", "m.onnx"], "--join-planes needs -o OUTPUT.onnx"),
    (["--join-planes", "m.onnx", "--strip-probe", "m.onnx", "-o", "x.onnx"], "--strip-probe MODEL takes only -o"),
    # (--opset 0 is falsy: it passed these three checks and was ignored without a word)
    (["--restamp", "m.onnx", "--opset", "0"], "--restamp MODEL.onnx takes no other options"),
    (["--retune", "jnyang", "--metadata", "s.yaml", "-o", "x.onnx", "--opset", "0"], "--retune MODEL takes only"),
    (["--strip-probe", "m.onnx", "-o", "x.onnx", "--opset", "0"], "--strip-probe MODEL takes only -o"),
])
def test_rtp_export_refuses_flags_that_do_not_go_together(argv: list[str], words: str,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Every combination is a usage error (exit 2) naming the flags, before any file is opened."""
    from rtp.cli import export_main

    with pytest.raises(SystemExit) as info:
        export_main(argv)
    assert info.value.code == 2 and words in capsys.readouterr().err


@pytest.mark.parametrize("argv, flag", [
    (["m.pt", "--metadata", "{}"], "--metadata"),
    (["--adopt", "f.onnx", "--metadata", "{}", "-o", "x.onnx"], "--metadata"),
    (["--retune", "jnyang", "--metadata", "{}", "-o", "x.onnx"], "--metadata"),
    (["m.pt", "-o", "{}"], "-o/--output"),
    (["{}"], "checkpoint"),
    (["--adopt", "{}", "-o", "x.onnx"], "--adopt"),
    (["--restamp", "{}"], "--restamp"),
    (["--strip-probe", "{}", "-o", "x.onnx"], "--strip-probe"),
    (["--join-planes", "{}", "-o", "x.onnx"], "--join-planes"),
    (["--retune", "{}", "--metadata", "s.yaml", "-o", "x.onnx"], "--retune"),
])
def test_rtp_export_paths_that_are_empty_or_a_folder_are_usage_errors_naming_the_flag(
        argv: list[str], flag: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp-export M.pt --metadata ""` said "metadata file is a folder, not a sidecar file: '.'" (and of a folder, no
    flag); `--restamp ""`, `--adopt ""` and `--strip-probe ""` were taken as not given ("a checkpoint path is
    required"), `-o ""` said "'.' is a folder". Each is a usage error of its own flag, as `rtp`'s (cli._main._in_file);
    a folder where a file is read or written too (a model's name, --strip-probe's, may be a shipped one's: only '')."""
    from rtp.cli import export_main

    folder_refused = flag not in ("--strip-probe", "--join-planes", "--retune")
    for value, said in (("", "expected a path, got '' (empty"), (str(tmp_path), "is a folder; expected a file path")):
        if value and not folder_refused:
            continue
        with pytest.raises(SystemExit) as info:
            export_main([a.replace("{}", value) for a in argv])
        err = capsys.readouterr().err
        assert info.value.code == 2 and f"error: argument {flag}: " in err and said in err, err


def test_rtp_export_restamp_records_the_digest_in_place(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp-export --restamp MODEL.onnx` (a model exported before digests) writes the digest into the
    file itself and prints its path; the model then loads with its integrity checked."""
    from rtp.cli import export_main

    from .conftest import build_onnx

    path = build_onnx(tmp_path / "old.onnx", weights=np.eye(4, dtype=np.float32), metadata=base_metadata())
    assert sdk.load(path).metadata.digest is None
    assert export_main(["--restamp", str(path)]) == 0
    assert capsys.readouterr().out.strip() == str(path)
    assert sdk.load(path).metadata.digest == sdk.model_digest(path.read_bytes())
    assert export_main(["--restamp", "jnyang"]) == 2  # a shipped model's name: said why it is not restamped
    assert "no model file at 'jnyang' (a shipped model's name: the models that ship are" in capsys.readouterr().err
    assert export_main(["--restamp", str(tmp_path / "nope.onnx")]) == 2
    assert "shipped" not in capsys.readouterr().err


def test_retune_changes_the_decision_and_nothing_the_model_predicts(fast_onnx: Path, tmp_path: Path) -> None:
    """rtp-export --retune: the decision fields (threshold factors per rate, default threshold) from a
    sidecar, the same graph, weights, digest and predictions; other fields refused, nothing written."""
    before = sdk.load(fast_onnx)
    side = tmp_path / "factors.yaml"
    side.write_text("rate_factors: {1x2: 1.2, 2x1: 1.2, 4x4: 0.85}\ndefault_threshold: 0.3\n")
    out = export.retune(fast_onnx, side, tmp_path / "tuned.onnx")
    tuned = sdk.load(out)
    m = tuned.metadata
    assert m.rate_factors == (1.2, 1.2, 1.0, 1.0, 1.0, 0.85) and m.default_threshold == 0.3 and m.schema_version == 5
    assert m.digest == before.metadata.digest and m.safety == before.metadata.safety and m.inputs == before.metadata.inputs
    assert list(m.provenance["retuned"]["fields"]) == ["default_threshold", "rate_factors"]
    assert m.provenance["retuned"]["from"] == fast_onnx.name and m.provenance["export"] == before.metadata.provenance["export"]
    x = np.random.default_rng(2).random((len(m.inputs), 96, 160), dtype=np.float32)
    est = before.predict(x)
    np.testing.assert_array_equal(tuned.predict_raw(x), before.predict_raw(x))
    np.testing.assert_array_equal(tuned.shading_rates(x), sdk.select_rates(est, 0.3, factors=m.rate_factors))
    thresholds = np.quantile(est, [0.2, 0.5, 0.8])  # the factors decide differently somewhere
    assert any((tuned.shading_rates(x, t) != before.shading_rates(x, t)).any() for t in thresholds)
    # back to one threshold (null), in place
    export.retune(out, {"rate_factors": None}, out)
    assert sdk.load(out).metadata.rate_factors == (1.0,) * 6 and sdk.load(out).metadata.default_threshold == 0.3
    for bad, words in (({"safety": 0.1}, "safety: retune changes only"), ({}, "nothing to change"),
                       ({"rate_factors": {"1x1": 2.0}}, "unknown rate"), ({"default_threshold": None}, "cannot be removed")):
        with pytest.raises(sdk.MetadataError, match=words):
            export.retune(fast_onnx, bad, tmp_path / "bad.onnx")
        assert not (tmp_path / "bad.onnx").exists()
    cmd = [sys.executable, "-m", "rtp.cli.export"]
    r = subprocess.run([*cmd, "--retune", str(fast_onnx), "--metadata", str(side), "-o", str(tmp_path / "c.onnx")],
                       capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip() == str(tmp_path / "c.onnx"), r.stderr
    assert sdk.load(tmp_path / "c.onnx").metadata.rate_factors[-1] == 0.85
    for args, words in ((["--retune", str(fast_onnx), "-o", "x.onnx"], "needs --metadata"),
                        (["--retune", str(fast_onnx), "--metadata", str(side), "--dynamic", "-o", "x.onnx"], "takes only")):
        r = subprocess.run([*cmd, *args], capture_output=True, text=True)
        assert r.returncode == 2 and words in r.stderr, r.stderr


def test_retune_rewrites_the_doc_string_from_the_new_description(fast_onnx: Path, tmp_path: Path) -> None:
    """Export writes the description into the ONNX doc string (what Netron and onnx's tools show); a retuned
    description left the old doc string there. It is rebuilt as export builds it, and the model still loads (the
    doc string is part of the digest, written again with it)."""
    import onnx

    assert onnx.load(str(fast_onnx)).doc_string == "rtp lpips predictor, 16x16 tiles"  # no description at export
    out = export.retune(fast_onnx, {"description": "LPIPS, thresholds per rate"}, tmp_path / "d.onnx")
    assert onnx.load(str(out)).doc_string == "LPIPS, thresholds per rate"
    assert sdk.load(out).metadata.description == "LPIPS, thresholds per rate"
    export.retune(out, {"description": None, "default_threshold": 0.2}, out)  # no description: export's default
    assert onnx.load(str(out)).doc_string == "rtp lpips predictor, 16x16 tiles"
    tuned = sdk.load(out)
    assert tuned.metadata.description == "" and tuned.metadata.digest == sdk.load(fast_onnx).metadata.digest


@pytest.mark.parametrize(
    ("conv", "multiple"),
    [
        ({"kernel_shape": [4, 4], "strides": [4, 4], "pads": [1, 1, 1, 1]}, 4),   # padding
        ({"kernel_shape": [5, 5], "strides": [4, 4]}, 4),                          # windows overlap, rows left over
        ({"kernel_shape": [4, 4], "strides": [4, 4], "dilations": [2, 2]}, 4),     # holes between the taps
        ({"kernel_shape": [4, 4], "strides": [4, 4]}, 2),                          # frames of 2k rows: 2 left over
        ({"kernel_shape": [1, 1], "strides": [1, 1]}, 16),                         # as many values as the frame
    ],
    ids=["pads", "overlap", "dilation", "multiple", "not-cheaper"],
)
def test_no_probe_where_it_would_not_see_every_pixel_or_save_a_read(conv: dict, multiple: int) -> None:
    import onnx
    from onnx import helper

    k = conv["kernel_shape"]
    graph = helper.make_graph(
        [helper.make_node("Conv", ["input", "W"], ["c"], **conv), helper.make_node("Relu", ["c"], ["metric"])], "g",
        [helper.make_tensor_value_info("input", onnx.TensorProto.FLOAT, ["n", 4, "h", "w"])],
        [helper.make_tensor_value_info("metric", onnx.TensorProto.FLOAT, None)],
        initializer=[helper.make_tensor("W", onnx.TensorProto.FLOAT, [4, 4, *k], [0.1] * (16 * k[0] * k[1]))],
    )
    model = helper.make_model(graph)
    before = model.SerializeToString()
    assert export.add_finite_probe(model, multiple) is None
    assert model.SerializeToString() == before


def test_merge_slices_merges_chains_and_keeps_the_outputs(tmp_path: Path) -> None:
    """Chained single-axis slices (what the TorchScript exporter writes for ``x[:, 1:3, 0::4, 1::4]``)
    become one Slice of the chain's input; slices on a shared axis, or whose output is read by anything
    but slices it merges into, are left alone; the graph computes the same."""
    import onnx
    import onnxruntime as ort
    import torch

    from rtp.export import merge_slices

    class Net(torch.nn.Module):
        def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            a = x[:, 1:3, 0::4, 1::4]
            b = x[:, 0:2][:, 1:2]  # the same axis twice: not merged
            return a * 2.0, b + 1.0

    path = tmp_path / "s.onnx"
    torch.onnx.export(Net(), (torch.rand(1, 4, 16, 16),), str(path), input_names=["input"], output_names=["a", "b"],
                      dynamic_axes={"input": {2: "h", 3: "w"}}, opset_version=17, dynamo=False)
    model = onnx.load(str(path))
    before = [n for n in model.graph.node if n.op_type == "Slice"]
    assert len(before) >= 5
    merged = merge_slices(model)
    after = [n for n in model.graph.node if n.op_type == "Slice"]
    assert merged == 2 and len(after) == len(before) - 2
    assert sum(n.input[0] == "input" for n in after) == 2  # the merged one and the first of the pair
    onnx.checker.check_model(model, full_check=True)
    x = np.random.default_rng(0).random((1, 4, 20, 28), dtype=np.float32)
    old = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).run(None, {"input": x})
    new = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, {"input": x})
    for o, n in zip(old, new):
        np.testing.assert_array_equal(o, n)
    np.testing.assert_array_equal(new[0], x[:, 1:3, 0::4, 1::4] * 2.0)


def test_graph_passes_leave_opset_9_slices_and_refuse_a_group_of_no_planes() -> None:
    """Opset 9's Slice holds starts, ends and axes as attributes (the paper's published models are opset 9):
    merge_slices read them as inputs and raised a KeyError; now it leaves such a chain as it is.
    split_input_planes with ``most=0`` raised a ZeroDivisionError; now a ParameterError that names it."""
    import onnx
    import onnxruntime as ort
    from onnx import TensorProto, helper

    nodes = [helper.make_node("Slice", ["input"], ["a"], starts=[1], ends=[3], axes=[1]),
             helper.make_node("Slice", ["a"], ["metric"], starts=[0], ends=[4], axes=[2])]
    graph = helper.make_graph(nodes, "s", [helper.make_tensor_value_info("input", TensorProto.FLOAT, [1, 4, 8, 8])],
                              [helper.make_tensor_value_info("metric", TensorProto.FLOAT, [1, 2, 4, 8])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 9)])
    model.ir_version = 4
    assert export.merge_slices(model) == 0
    onnx.checker.check_model(model, full_check=True)
    x = np.random.default_rng(0).random((1, 4, 8, 8), dtype=np.float32)
    got = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"]).run(None, {"input": x})
    np.testing.assert_array_equal(got[0], x[:, 1:3, :4])
    for most in (0, -1, 2.5, True):
        with pytest.raises(sdk.ParameterError, match="most: expected .* integer >= 1") as info:
            export.split_input_planes(model, most)
        assert info.value.name == "most"


def test_no_export_writes_over_its_checkpoint_or_where_it_cannot_write(fast_onnx: Path, tmp_path: Path) -> None:
    """`rtp-export ck.pt -o ck.pt` used to replace the checkpoint by the model (exit 0): the training was
    lost. An export refuses its checkpoint as output, and every tool an output it cannot write, before
    any work (a model's copy may replace the model: `--retune M -o M` is documented)."""
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    before = ck.read_bytes()
    with pytest.raises(sdk.ParameterError, match="is the input itself"):
        export.export_checkpoint(ck, ck)
    with pytest.raises(sdk.ParameterError, match="is the input itself"):
        export.export_checkpoint(ck, tmp_path / "." / "m.pt")
    assert ck.read_bytes() == before
    copy = tmp_path / "copy.onnx"
    copy.write_bytes(fast_onnx.read_bytes())
    with pytest.raises(sdk.ParameterError, match="is a folder"):
        export.export_checkpoint(ck, tmp_path)
    (tmp_path / "file").write_text("x")
    for write in (export.strip_finite_probe, export.join_input_planes):
        with pytest.raises(sdk.ParameterError, match="is a file, not a folder"):
            write(copy, tmp_path / "file" / "x.onnx")
    with pytest.raises(sdk.ParameterError, match="is a folder"):
        export.retune(copy, {"default_threshold": 0.2}, tmp_path)
    assert copy.read_bytes() == fast_onnx.read_bytes()
    cli = _cli(str(ck), "-o", str(ck))
    assert cli.returncode == 2 and "is the input itself" in cli.stderr and "Traceback" not in cli.stderr
    assert ck.read_bytes() == before
    # another training's checkpoint, or any file that is no ONNX model, is not replaced either (it was, exit 0)
    other = checkpoint.save(tmp_path / "other.pt", _trained_like_net(), base_metadata())
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    kept = {other: other.read_bytes(), notes: notes.read_bytes()}
    for out, kind in ((other, r"a training checkpoint \(a zip\)"), (notes, "no ONNX model")):
        with pytest.raises(sdk.ParameterError, match=f"exists and is {kind}: an export replaces only an ONNX model"):
            export.export_checkpoint(ck, out)
    cli = _cli(str(ck), "-o", str(other))
    assert cli.returncode == 2 and "a training checkpoint" in cli.stderr
    assert all(path.read_bytes() == data for path, data in kept.items())
    (tmp_path / "empty.onnx").touch()  # (an empty file, and a model, are replaced)
    export.export_checkpoint(ck, tmp_path / "empty.onnx")
    export.export_checkpoint(ck, copy)
    a, b = (sdk.load(p).metadata.to_dict() for p in (copy, tmp_path / "empty.onnx"))
    for d in (a, b):  # (the two exports' dates differ when a second turns between them)
        d["provenance"]["export"].pop("date")
    assert a == b


@pytest.mark.parametrize("text", [b"0\n", b"x\n", b"8\n"])
def test_a_short_text_that_protobuf_parses_is_no_onnx_model_an_export_replaces(
        text: bytes, fast_onnx: Path, tmp_path: Path) -> None:
    """Protobuf parses many short texts as a message of unknown fields: a file holding `0` or `x` counted as an ONNX
    model, and `rtp-export M.pt -o notes.txt` (or a model's copy) replaced it, exit 0. A model has an IR version and
    a graph: such a file is refused as any other that is no ONNX model, and kept."""
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    notes = tmp_path / "notes.txt"
    notes.write_bytes(text)
    with pytest.raises(sdk.ParameterError, match="exists and is no ONNX model"):
        export.export_checkpoint(ck, notes)
    with pytest.raises(sdk.ParameterError, match="exists and is no ONNX model"):
        export.strip_finite_probe(fast_onnx, notes)
    assert notes.read_bytes() == text
    export.strip_finite_probe(fast_onnx, tmp_path / "copy.onnx")  # (a model is replaced, as before)
    export.export_checkpoint(ck, tmp_path / "copy.onnx")


def test_a_retune_sidecars_invalid_field_names_the_sidecar(fast_onnx: Path, tmp_path: Path) -> None:
    """`rtp-export --retune M --metadata r.yaml` said `description: expected a string, got 5`, naming no file."""
    side = tmp_path / "r.yaml"
    for text, key in (("description: 5\n", "description"), ("default_threshold: .nan\n", "default_threshold")):
        side.write_text(text)
        with pytest.raises(sdk.MetadataError, match=rf"^.*r\.yaml: {key}: expected") as err:
            export.retune(fast_onnx, side, tmp_path / "out.onnx")
        assert err.value.key == key and not (tmp_path / "out.onnx").exists()
    with pytest.raises(sdk.MetadataError, match="^description: expected a string"):
        export.retune(fast_onnx, {"description": 5}, tmp_path / "out.onnx")
    # its refusals too (they named no file)
    for text, words in (("safety: 0.1\n", "safety: retune changes only"), ("", "the sidecar sets none of"),
                        ("default_threshold: null\n", "default_threshold: retune replaces it")):
        side.write_text(text)
        with pytest.raises(sdk.MetadataError, match=rf"^.*r\.yaml: {words}"):
            export.retune(fast_onnx, side, tmp_path / "out.onnx")
        assert not (tmp_path / "out.onnx").exists()


def test_a_sidecar_that_is_not_text_or_not_yaml_is_a_metadata_error(fast_onnx: Path, tmp_path: Path) -> None:
    binary, broken = tmp_path / "bin.yaml", tmp_path / "broken.yaml"
    binary.write_bytes(b"\x00\xff\xfe\x80 binary")
    broken.write_text("default_threshold: [0.2\nrate_factors: {")
    for sidecar in (binary, broken):
        with pytest.raises(sdk.MetadataError) as err:
            export.retune(fast_onnx, sidecar, tmp_path / "out.onnx")
        assert "\n" not in str(err.value)  # one line, YAML's caret and context folded in
    assert not (tmp_path / "out.onnx").exists()


def test_an_unfinished_training_exports_with_a_warning(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A checkpoint of an interrupted training (no safety calibration yet) exported silently; it says so now,
    and a finished one says nothing."""
    net, meta = _trained_like_net(), base_metadata()
    for done in (False, True):
        ck = checkpoint.save(tmp_path / f"m{done}.pt", net, meta, {"done": done, "step": 250})
        caplog.clear()
        with caplog.at_level("WARNING", logger="rtp.export"):
            export.export_checkpoint(ck, tmp_path / f"m{done}.onnx")
        said = [r.getMessage() for r in caplog.records if "has not finished" in r.getMessage()]
        assert said == ([] if done else [f"{ck} holds a training that has not finished (step 250; its safety margin, "
                                         "calibrated at the end, is 0): the model is exported as it stands; the same "
                                         "rtp train command finishes it"])


def test_a_checkpoint_with_dead_outputs_exports_with_a_warning(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """`rtp train` exits 1 on dead outputs and calls the checkpoint not fit to export; `rtp-export` exported it with
    exit 0 and no word. It warns now, naming the outputs and what to do, and still exports; none dead says nothing."""
    net = _trained_like_net()
    for arch, dead, again in (("paper", ["2x1", "4x2"], "--head linear or another --seed"),
                              ("fast", ["1x2"], "another --seed"), ("paper", [], None)):
        meta = base_metadata(provenance={"arch": arch, "dead_outputs": dead})
        ck = checkpoint.save(tmp_path / f"m{arch}{len(dead)}.pt", net, meta, {"done": True, "step": 250})
        caplog.clear()
        with caplog.at_level("WARNING", logger="rtp.export"):
            out = export.export_checkpoint(ck, tmp_path / f"m{arch}{len(dead)}.onnx")
        assert out.is_file()
        said = [r.getMessage() for r in caplog.records if "dead_outputs" in r.getMessage()]
        assert said == ([] if again is None else [
            f"{ck}: output(s) {', '.join(dead)} predicted the same value on every validation tile when rtp train "
            "finished (provenance.dead_outputs): such a model picks rates blindly; it is exported as it stands (a dead "
            f"output does not recover with more steps): train again with {again}"])


def test_a_sidecar_pyyaml_cannot_build_is_a_metadata_error_and_reads_as_sdk_load_reads_it(
        tmp_path: Path) -> None:
    """rtp-export --metadata (and --retune, --adopt) read the sidecar apart from sdk.load: one nested too deep or a
    value PyYAML cannot build (`!!float x`, a `date: 2026-02-30`) ended the command in a RecursionError or ValueError
    traceback, exit 1, where `rtp info --metadata` said "not valid YAML"; and `default_threshold: 1e-2` was the
    string '1e-2', a key given twice its last value without a word."""
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    side = tmp_path / "extra.yaml"
    for text in ("description: " + "[" * 5000 + "]" * 5000 + "\n", "default_threshold: !!float x\n"):
        side.write_text(text)
        with pytest.raises(sdk.MetadataError, match=r"extra\.yaml: not valid YAML"):
            export.export_checkpoint(ck, tmp_path / "m.onnx", extra_metadata=side)
        with pytest.raises(sdk.MetadataError, match=r"extra\.yaml: not valid YAML"):
            export.adopt(_foreign(tmp_path, 64, 96), side, tmp_path / "a.onnx")
    side.write_text("default_threshold: 0.1\ndescription: x\ndefault_threshold: 0.3\n")
    with pytest.raises(sdk.MetadataError, match=r"'default_threshold' given twice, first on line 1"):
        export.export_checkpoint(ck, tmp_path / "m.onnx", extra_metadata=side)
    assert not (tmp_path / "m.onnx").exists() and not (tmp_path / "a.onnx").exists()
    side.write_text("default_threshold: 1e-2\nprovenance: {trained: 2026-02-30}\n")
    m = sdk.load(export.export_checkpoint(ck, tmp_path / "m.onnx", extra_metadata=side)).metadata
    assert m.default_threshold == 0.01 and m.provenance["trained"] == "2026-02-30"


def test_an_adopt_sidecars_error_keeps_its_key_and_its_provenance_is_not_dropped(tmp_path: Path) -> None:
    """adopt's sidecar errors lost the field's key (`MetadataError.key` None, where export's and retune's keep it),
    and a sidecar's `provenance` that is no mapping was replaced by rtp's own entry without a word."""
    src = _foreign(tmp_path, 64, 96)
    with pytest.raises(sdk.MetadataError, match=r"given as a mapping: default_threshold: expected") as info:
        export.adopt(src, {**PAPER_SIDECAR, "default_threshold": -1}, tmp_path / "a.onnx")
    assert info.value.key == "default_threshold"
    with pytest.raises(sdk.MetadataError, match=r"provenance: expected a mapping .*'trained on oa_dm1'") as info:
        export.adopt(src, {**PAPER_SIDECAR, "provenance": "trained on oa_dm1"}, tmp_path / "a.onnx")
    assert info.value.key == "provenance" and not (tmp_path / "a.onnx").exists()
    m = sdk.load(export.adopt(src, {**PAPER_SIDECAR, "provenance": {"scenes": ["oa_dm1"]}}, tmp_path / "a.onnx")).metadata
    assert m.provenance["scenes"] == ("oa_dm1",) and m.provenance["adopted"]["file"] == "Model.onnx"


def test_metadata_errors_name_the_file_they_come_from(tmp_path: Path) -> None:
    """`rtp-export bad.pt` said `metric: expected a lower-case name ..., got None` and an empty sidecar
    `metric: ... got None` or `transform: required, missing`, naming no file; each names it now, the empty
    sidecar as empty."""
    import torch

    src = _foreign(tmp_path)
    empty, partial = tmp_path / "empty.yaml", tmp_path / "partial.yaml"
    empty.write_text("")
    partial.write_text("metric: jnyang\n")
    with pytest.raises(sdk.MetadataError, match=r"empty\.yaml: the sidecar is empty"):
        export.adopt(src, empty, tmp_path / "a.onnx")
    with pytest.raises(sdk.MetadataError, match=r"partial\.yaml: transform: required, missing"):
        export.adopt(src, partial, tmp_path / "a.onnx")
    ck = checkpoint.save(tmp_path / "m.pt", _trained_like_net(), base_metadata())
    raw = torch.load(ck, weights_only=False)
    raw["metadata"]["metric"] = None
    torch.save(raw, tmp_path / "bad.pt")
    with pytest.raises(sdk.MetadataError, match=r"bad\.pt: its metadata: metric: expected a lower-case name"):
        export.export_checkpoint(tmp_path / "bad.pt", tmp_path / "bad.onnx")
