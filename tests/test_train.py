"""Targets store, scores, safety calibration and the training loop on a small synthetic dataset.

The dataset's targets are a known function of its albedo (texture contrast per tile), so a short
training run has something real to learn. Training on rendered scenes is tested with the capture
pipeline.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
import yaml

from rtp import export, sdk
from rtp.capture import BUFFERS, DatasetError, DatasetReader, DatasetWriter, TargetStore, pool_targets
from rtp.cli import main as rtp_main
from rtp.evaluate import scores
from rtp.sdk import psnr_from_mse as mse_to_psnr
from rtp.train import TrainConfig, _frames, calibrate_safety, train
from rtp.train.checkpoint import load as load_checkpoint

from .conftest import BENCH, bench_module

H, W = 64, 96


def _dataset(root: Path, n: int = 12, flip: bool = False, prefix: str = "s", profile: str | None = None,
             weber_l: float = 0.02, scenes: tuple[str, ...] = ("scene0", "scene1", "scene2")) -> Path:
    """``n`` samples over three scenes with JNYang targets (and, with ``flip``, FLIP targets: another function of
    the same texture contrast); ids ``{prefix}000`` on, each of motion ``profile`` where one is given, of
    ``scenes`` in turn."""
    w = DatasetWriter(root)
    store = TargetStore(root)
    store.declare("jnyang", {"weber_l": weber_l})
    if flip:
        store.declare("flip", {})
    rng = np.random.default_rng(0)
    for i in range(n):
        bufs = {}
        for name, spec in BUFFERS.items():
            c = len(spec.channels) or 3
            bufs[name] = rng.random((H, W, c) if c > 1 else (H, W), dtype=np.float32)
        amp = rng.random((H // 4, W // 4)).repeat(4, 0).repeat(4, 1)
        bufs["albedo"][..., 0] = 0.5 + amp * (rng.random((H, W)) - 0.5)
        sid = f"{prefix}{i:03d}"
        w.write(sid, bufs, {"scene": scenes[i % len(scenes)], **({"profile": profile} if profile else {})})
        edge = np.abs(np.diff(bufs["albedo"][..., 0], axis=1, append=0.5))
        tiles = edge.reshape(H // 4, 4, W // 4, 4).max(axis=(1, 3))
        store.write(sid, "jnyang", np.stack([tiles * k for k in (1, 1.1, 1.2, 1.5, 1.6, 2)]).astype(np.float32), (H, W))
        if flip:
            store.write(sid, "flip", np.stack([np.sqrt(tiles) * k for k in (0, .3, .3, .5, .5, .7)]).astype(np.float32),
                        (H, W))
    w.finalize()
    return root


def _bench_module(name: str, monkeypatch: pytest.MonkeyPatch) -> tuple[Path, Any]:
    """bench/<name>.py and the module it is, imported as when run as a script (bench/ first on sys.path,
    so bench/_common.py imports)."""
    return BENCH / f"{name}.py", bench_module(name, monkeypatch)


def test_pooling_targets_equals_computing_at_the_coarse_tile() -> None:
    rng = np.random.default_rng(1)
    h, w = 37, 50  # not multiples of the tile sizes
    sq = rng.random((6, h, w))
    def per_tile(t: int, fn) -> np.ndarray:  # noqa: E306, ANN001
        out = np.zeros((6, -(-h // t), -(-w // t)))
        for i in range(out.shape[1]):
            for j in range(out.shape[2]):
                out[:, i, j] = fn(sq[:, i * t : (i + 1) * t, j * t : (j + 1) * t], axis=(1, 2))
        return out
    np.testing.assert_allclose(pool_targets(per_tile(4, np.max), (h, w), 4, 16, mse=False), per_tile(16, np.max), rtol=1e-6)
    np.testing.assert_allclose(pool_targets(per_tile(4, np.mean), (h, w), 4, 16, mse=True), per_tile(16, np.mean), rtol=1e-6)
    assert mse_to_psnr(np.array([0.01, 0.0]))[0] == pytest.approx(20.0) and mse_to_psnr(np.array([0.0]))[0] == np.inf


def test_target_store(tmp_path: Path) -> None:
    store = TargetStore(tmp_path)
    store.declare("psnr", {})
    mse = np.full((6, 4, 6), 1e-3, np.float32)
    store.write("a", "psnr", mse, (16, 24))
    assert TargetStore(tmp_path).load("a", "psnr", 8).shape == (6, 2, 3)
    np.testing.assert_allclose(store.load("a", "psnr", 4), 30.0, rtol=1e-5)
    with pytest.raises(sdk.RtpError, match="expected numbers of shape"):
        store.write("b", "psnr", mse[:, :2], (16, 24))
    with pytest.raises(sdk.RtpError, match="rtp targets"):
        store.load("missing", "psnr", 4)
    with pytest.raises(sdk.RtpError, match=r"computed with .*; delete .*psnr to compute psnr's with these \(the other"):
        store.declare("psnr", {"ppd": 67})
    # the hint was to delete the whole targets folder, every other metric's targets with it; the metric's own
    # folder is enough: with none of its targets stored, its parameters are declared anew
    import shutil

    shutil.rmtree(store.root / "psnr")
    store.declare("psnr", {"ppd": 67})
    assert TargetStore(tmp_path).metrics["psnr"] == {"ppd": 67}


def test_scores_and_safety() -> None:
    g = np.array([0.1, 0.2, 0.3, 0.4])
    s = scores(g, g)
    assert s.r2 == 1.0 and s.mae == 0.0 and s.under_share == 0.0
    p = np.array([0.2, 0.1, 0.3, 0.5])  # one tile underestimated by 0.1
    s = scores(p, g)
    assert s.mae == pytest.approx(0.075) and s.mae_under == pytest.approx(0.1) and s.under_share == 0.25
    assert s.r2 == pytest.approx(1 - 0.03 / 0.05)
    safety, left = calibrate_safety(p, g)
    assert safety == pytest.approx(0.025) and left == 0.25  # the paper's mean underestimation
    rng = np.random.default_rng(0)
    g2 = rng.random(1000)
    p2 = g2 + rng.normal(0, 0.1, 1000)
    safety, left = calibrate_safety(p2, g2, quantile=0.05)
    assert left <= 0.05 and safety > 0
    # the smallest margin that leaves at most a share q underestimated (it was up to one value larger: 4 for
    # q = 0.25, which left none of these four, and 3 for q = 0.5, which left one where two may stay)
    short = np.array([1.0, 2.0, 3.0, 4.0])
    assert calibrate_safety(np.zeros(4), short, quantile=0.25) == (3.0, 0.25)
    assert calibrate_safety(np.zeros(4), short, quantile=0.5) == (2.0, 0.5)
    assert calibrate_safety(np.zeros(4), short, quantile=0.0) == (4.0, 0.0)
    assert calibrate_safety(np.zeros(4), -short, quantile=0.5) == (0.0, 0.0)  # (never a negative margin)
    for q in (0.01, 0.05, 0.3):  # and with many values: at most q left, one value less would leave more
        s, left = calibrate_safety(p2, g2, quantile=q)
        short2 = g2 - p2
        assert left <= q < np.mean(short2 > np.max(short2[short2 < s]))
    # a quantile out of range is refused whatever the values: with none finite (or none at all) it was taken, and
    # the margin 0 returned, where the same call on finite values raised
    for pred, gt in ((np.zeros(4), short), (np.full(3, np.nan), np.full(3, np.nan)), (np.zeros(0), np.zeros(0))):
        with pytest.raises(sdk.ParameterError, match=r"safety quantile: expected a number in \[0, 1\), got 1.5") as e:
            calibrate_safety(pred, gt, quantile=1.5)
        assert e.value.name == "quantile"


@pytest.mark.slow
def test_training_learns_resumes_and_exports(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "ds")
    # (400 steps with a weight average: at 240 steps of the raw weights the last validation swung with the CPU's
    # float order, an R2 of -1.1 to 0.6 over seeds and thread counts on an AVX2 EPYC, the paper head's ReLU dying
    # on some; now 0.43 to 0.68 and the error 40% down or more on every one of ten)
    cfg = dict(data=str(data), metric="jnyang", steps=400, crop=32, batch=8, val_every=40, save_every=40, lr=1e-3,
               ema=0.9)
    result = train(TrainConfig(out=str(tmp_path / "a.pt"), **cfg))
    ck = load_checkpoint(result.checkpoint)
    state = ck.training

    hist = json.loads(state["history"])
    assert hist[-1]["val"]["mae"] < hist[0]["val"]["mae"]  # validation loss went down
    assert hist[-1]["val"]["r2"] > 0.3
    meta = ck.metadata
    assert meta.metric == "jnyang" and meta.transform.type == "clamped" and meta.weber_l == 0.02
    assert meta.safety > 0 and meta.provenance["val_scenes"] == ("scene2",)
    assert meta.provenance["train_samples"] == 8

    # Resuming from a checkpoint half-way gives exactly the same model as one uninterrupted run.
    half = train(TrainConfig(out=str(tmp_path / "b.pt"), **{**cfg, "steps": 200}))
    assert half.steps == 200
    seen: list[int] = []
    read: list[tuple[int, int]] = []
    full = train(TrainConfig(out=str(tmp_path / "b.pt"), **cfg), progress=lambda step, total, loss: seen.append(step),
                 loading=lambda k, n: read.append((k, n)))
    assert seen[0] == 200 and seen[1] == 201 and seen[-1] == 400  # the progress bar starts where the run stopped
    assert read == [(k, 12) for k in range(1, 13)]  # (the samples are read first, each reported: 8 trained on, 4 validated)
    a, b = load_checkpoint(result.checkpoint).net.state_dict(), load_checkpoint(full.checkpoint).net.state_dict()
    for k in a:
        assert torch.equal(a[k], b[k]), k

    # The export predicts through sdk.load what torch predicts.
    onnx_path = export.export_checkpoint(result.checkpoint, tmp_path / "a.onnx")
    pred = sdk.load(onnx_path)
    x = np.random.default_rng(3).random((4, H, W), dtype=np.float32)
    with torch.inference_mode():
        raw = ck.net(torch.from_numpy(x)[None])[0].numpy()
    np.testing.assert_allclose(pred.predict_raw(x), raw, atol=1e-5)


def test_a_diverged_training_stops_at_once_and_keeps_the_last_finite_checkpoint(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """A NaN loss (here from input planes that turn NaN after step 4) stopped nothing: the training ran every step,
    its periodic saves replaced the last good checkpoint with NaN weights, and the final save failed on the
    provenance's JSON. It stops at the first non-finite loss, exit 1, naming the step and what is kept."""
    from rtp.train import TrainingDivergedError, _loop

    data = _dataset(tmp_path / "ds", n=6)
    real_crop, calls = _loop.crop_batch, [0]

    def poisoned(*args: Any, **kwargs: Any) -> np.ndarray:
        calls[0] += 1
        batch = real_crop(*args, **kwargs)
        return batch * np.float32("nan") if calls[0] > 4 else batch

    monkeypatch.setattr(_loop, "crop_batch", poisoned)
    out = tmp_path / "m.pt"
    cfg = TrainConfig(data=str(data), metric="jnyang", out=str(out), steps=12, crop=32, batch=2, val_every=2,
                      save_every=2, val_scenes=("scene0",))
    with pytest.raises(TrainingDivergedError, match=r"the loss is nan at step 5, .*m\.pt keeps step 4's weights"):
        train(cfg)
    kept = load_checkpoint(out)
    assert kept.training["step"] == 4
    assert all(bool(torch.isfinite(v).all()) for v in kept.net.state_dict().values() if v.is_floating_point())

    # weights that turn NaN in an update are not saved either: the checkpoint of the save before stays
    monkeypatch.setattr(_loop, "crop_batch", real_crop)
    real_step, updates = torch.optim.RMSprop.step, [0]

    def nan_update(self: torch.optim.Optimizer, *args: Any, **kwargs: Any) -> Any:
        updates[0] += 1
        result = real_step(self, *args, **kwargs)
        if updates[0] == 4:
            with torch.no_grad():
                self.param_groups[0]["params"][0].fill_(float("nan"))
        return result

    monkeypatch.setattr(torch.optim.RMSprop, "step", nan_update)
    out.unlink()
    with pytest.raises(TrainingDivergedError, match=r"the weights \(.*\) are not finite at step 4, .*keeps step 2's"):
        train(cfg)
    assert load_checkpoint(out).training["step"] == 2
    monkeypatch.setattr(torch.optim.RMSprop, "step", real_step)

    calls[0] = 0  # from the command line: exit 1, the same words; diverging before any save writes nothing
    monkeypatch.setattr(_loop, "crop_batch", lambda *a, **k: np.full_like(real_crop(*a, **k), np.inf))
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--crop", "32", "--steps", "6",
                     "--val-scenes", "scene0", "--out", str(tmp_path / "n.pt")]) == 1
    assert "no checkpoint was written" in capsys.readouterr().err and not (tmp_path / "n.pt").exists()


def test_train_cli_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _dataset(tmp_path / "ds", n=3)
    assert rtp_main(["train", "--data", str(data), "--metric", "flip", "--out", str(tmp_path / "m.pt")]) == 2
    assert "no flip targets" in capsys.readouterr().err
    assert rtp_main(["train", "--data", str(tmp_path / "nope"), "--metric", "jnyang", "--out", "m.pt"]) == 2
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(tmp_path / "m.pt"),
                     "--crop", "20"]) == 2
    assert "multiple of the tile size" in capsys.readouterr().err


def test_a_tile_finer_than_the_stored_targets_is_refused_before_any_sample_is_read(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The targets are stored per 4-pixel base tile and a model's tile pools whole ones: --tile 1 and 2, which
    `rtp train --help` offers, failed on the first sample's targets with a TargetError that named no tile that
    would do; now a ParameterError naming tile, before the samples are read."""
    data = _dataset(tmp_path / "ds", n=3)
    read: list[int] = []
    for tile in (1, 2):
        cfg = TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / f"t{tile}.pt"), tile=tile, crop=32,
                          steps=1, val_scenes=("scene0",))
        with pytest.raises(sdk.ParameterError, match=f"^tile: the targets of {re.escape(str(data))} are stored per "
                           f"4-pixel tile .*: expected 4, 8, 16, 32, got {tile}$") as err:
            train(cfg, loading=lambda n, total: read.append(n))
        assert err.value.name == "tile" and not read and not (tmp_path / f"t{tile}.pt").exists()
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--tile", "2", "--crop", "32",
                     "--val-scenes", "scene0", "--out", str(tmp_path / "c.pt")]) == 2
    assert "are stored per 4-pixel tile (rtp targets) and a model's tile pools whole ones" in capsys.readouterr().err


def test_a_dataset_of_one_scene_is_told_how_to_add_a_second(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # a user's one level (rtp capture --scene level.glb): validation holds out whole scenes, so say how to add one
    one = _dataset(tmp_path / "one", n=1)
    out = tmp_path / "m.pt"
    assert rtp_main(["train", "--data", str(one), "--metric", "jnyang", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{one} holds one scene (scene0); validation holds out whole scenes, so it needs two: capture another " \
           f"into it (rtp capture --scene procedural:1 --out {one} with the same --size" in err
    assert not out.exists()
    level = _dataset(tmp_path / "level", n=1, scenes=("procedural_1",))  # (its one scene is the one it suggested)
    assert rtp_main(["train", "--data", str(level), "--metric", "jnyang", "--out", str(out)]) == 2
    assert f"(rtp capture --scene procedural:2 --out {level} with" in capsys.readouterr().err
    # as rtp capture names it (procedural:1): it suggested the scene the dataset holds
    captured = _dataset(tmp_path / "captured", n=1, scenes=("procedural:1",))
    assert rtp_main(["train", "--data", str(captured), "--metric", "jnyang", "--out", str(out)]) == 2
    assert f"(rtp capture --scene procedural:2 --out {captured} with" in capsys.readouterr().err


def test_training_reads_several_datasets_as_one(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    usual = _dataset(tmp_path / "usual", n=12, profile="slow")
    frame = _dataset(tmp_path / "frame", n=9, prefix="f", profile="frame")
    out = tmp_path / "m.pt"
    # scene2 validates (all 4 + 3 of its samples); of the training maps' 8 + 6, the first 2 of each map and profile
    assert rtp_main(["train", "--data", f"{usual},{frame}", "--metric", "jnyang", "--out", str(out), "--steps", "20",
                     "--crop", "32", "--val-scenes", "scene2",
                     "--per-scene", "2"]) == 0
    prov = load_checkpoint(out).metadata.provenance
    assert prov["train_samples"] == 8 and prov["val_samples"] == 7 and prov["per_scene"] == 2
    assert prov["data"] == f"{usual},{frame}" and prov["train_scenes"] == ("scene0", "scene1")
    # a sample in two of the folders, targets of other parameters, a folder twice: refused, naming what is wrong
    twice = _dataset(tmp_path / "twice", n=3)
    assert rtp_main(["train", "--data", f"{usual},{twice}", "--metric", "jnyang", "--out", str(tmp_path / "x.pt")]) == 2
    assert "sample s000 is in both" in capsys.readouterr().err
    other = _dataset(tmp_path / "other", n=3, prefix="o", weber_l=0.05)
    assert rtp_main(["train", "--data", f"{usual},{other}", "--metric", "jnyang", "--out", str(tmp_path / "x.pt")]) == 2
    assert "different parameters" in capsys.readouterr().err
    assert rtp_main(["train", "--data", f"{usual},{usual}", "--metric", "jnyang", "--out", str(tmp_path / "x.pt")]) == 2
    assert "each once" in capsys.readouterr().err
    assert not (tmp_path / "x.pt").exists()
    # a folder whose name holds a comma is one dataset, not two
    comma = _dataset(tmp_path / "a,b", n=6)
    assert rtp_main(["train", "--data", str(comma), "--metric", "jnyang", "--out", str(tmp_path / "c.pt"), "--steps",
                     "20", "--crop", "32", "--val-scenes", "scene0"]) == 0, capsys.readouterr().err
    assert load_checkpoint(tmp_path / "c.pt").metadata.provenance["data"] == str(comma)


def test_train_cli_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """(Its bar says it reads the samples before the first step: minutes for the shipped recipe's.)"""
    from rtp.cli._run import Bar

    monkeypatch.setattr(Bar, "DELAY", 0.0)
    data = _dataset(tmp_path / "ds", n=6)
    out = tmp_path / "m.pt"
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(out), "--steps", "20",
                     "--crop", "32", "--val-scenes", "scene0"]) == 0
    got = capsys.readouterr()
    # R² in % as `rtp evaluate` prints it (its 'model (no safety)' row), not a fraction beside evaluate's percent
    val = load_checkpoint(out).metadata.provenance["validation"]["transformed"]
    assert f"validation R² {100 * val['r2']:.1f}%, MAE {val['mae']:.4f} (transformed, without the safety margin)" \
        in got.out, got.out
    assert "reading samples: 1/6]" in got.err and "reading samples" not in got.err.rsplit("\r", 1)[-1], got.err
    from rtp.metrics import device_name, resolve_device

    assert f"train jnyang on {device_name(resolve_device('auto'))}:" in got.err  # (where auto trains, on the bar)
    assert load_checkpoint(out).metadata.provenance["val_scenes"] == ("scene0",)


def test_head_with_the_fast_network_is_refused_saying_who_set_it(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """The fast network reads no ``head``: a recipe's or the caller's was taken and ignored while the provenance
    recorded a head (the shipped recipe's ``head: linear`` for LPIPS). Refused, saying whether the recipe or the
    caller set it; the shipped recipes set none now."""
    out = str(tmp_path / "m.pt")
    with pytest.raises(sdk.ParameterError, match="^head: the paper network's option .*, got head linear with arch "
                                                 "'fast'$") as err:
        TrainConfig.from_recipe("shipped", data="d", metric="jnyang", out=out, head="linear")
    assert err.value.name == "head"
    recipe = tmp_path / "r.yaml"
    recipe.write_text("arch: fast\nhead: linear\n")
    with pytest.raises(sdk.ParameterError, match="^recipe .*r.yaml sets head: linear, which does not fit: head: the "
                                                 "paper network's option") as err:
        TrainConfig.from_recipe(recipe, data="d", metric="jnyang", out=out)
    assert err.value.name == "head"
    # the paper network's recipe on the fast network: its LPIPS section's head is the recipe's
    with pytest.raises(sdk.ParameterError, match="^recipe paper-net sets head: linear, which does not fit") as err:
        TrainConfig.from_recipe("paper-net", data="d", metric="lpips", out=out, arch="fast")
    assert TrainConfig.from_recipe("paper-net", data="d", metric="lpips", out=out).head == "linear"  # (read there)
    for name in ("shipped", "tile8"):  # LPIPS's unread head: linear is gone from the shipped recipes
        assert "head" not in TrainConfig.from_recipe(name, data="d", metric="lpips", out=out).recipe["values"]
    assert rtp_main(["train", "--data", str(tmp_path), "--metric", "jnyang", "--out", out, "--head", "linear"]) == 2
    assert "rtp train: error: --head: the paper network's option" in capsys.readouterr().err
    assert not (tmp_path / "m.pt").exists()


def test_a_fast_training_begun_with_an_unread_head_resumes(tmp_path: Path) -> None:
    """A fast network's training begun before ``head`` was refused with it (the shipped LPIPS recipe's ``head:
    linear``) recorded the head it never read: it resumes without it."""
    from rtp.train import checkpoint

    data = _dataset(tmp_path / "ds", n=6)
    cfg = dict(data=str(data), metric="jnyang", crop=32, batch=4, val_every=2, save_every=2, arch="fast",
               val_scenes=("scene0",))
    out = tmp_path / "m.pt"
    train(TrainConfig(out=str(out), steps=2, **cfg))
    ck = load_checkpoint(out)
    checkpoint.save(out, ck.net, ck.metadata, {**ck.training, "done": False,
                                                "config": {**ck.training["config"], "head": "linear"}})
    assert train(TrainConfig(out=str(out), steps=4, **cfg)).steps == 4
    with pytest.raises(sdk.ParameterError, match="differs in: width"):  # (another configuration still is)
        train(TrainConfig(out=str(out), steps=6, **{**cfg, "width": 8}))


def test_a_resume_with_the_data_folder_spelled_with_a_trailing_slash_resumes(tmp_path: Path) -> None:
    """``--data data/train/`` (a shell's completion) resuming a run begun with ``data/train`` was refused as
    another configuration (differs in: data); the same folders spelled otherwise resume, other folders do not."""
    data = _dataset(tmp_path / "ds", n=6)
    cfg = dict(metric="jnyang", crop=32, batch=4, val_every=2, save_every=2, arch="fast", val_scenes=("scene0",))
    out = tmp_path / "m.pt"
    train(TrainConfig(out=str(out), steps=2, data=str(data), **cfg))
    assert train(TrainConfig(out=str(out), steps=4, data=str(data) + "/", **cfg)).steps == 4
    assert train(TrainConfig(out=str(out), steps=6, data=f"{data}/./", **cfg)).steps == 6
    other = tmp_path / "ds2"
    shutil.copytree(data, other)
    with pytest.raises(sdk.ParameterError, match="differs in: data"):
        train(TrainConfig(out=str(out), steps=8, data=str(other), **cfg))


def test_a_resume_with_the_data_folder_spelled_absolute_or_through_a_link_resumes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run begun with ``--data ds`` (relative) and resumed with the same folder's absolute path (a script, a
    Makefile's abspath) or a link to it was refused as another configuration (differs in: data); another folder
    with the same samples still is."""
    data = _dataset(tmp_path / "ds", n=6)
    cfg = dict(metric="jnyang", crop=32, batch=4, val_every=2, save_every=2, arch="fast", val_scenes=("scene0",))
    out = tmp_path / "m.pt"
    monkeypatch.chdir(tmp_path)
    train(TrainConfig(out=str(out), steps=2, data="ds", **cfg))
    assert train(TrainConfig(out=str(out), steps=4, data=str(data.resolve()), **cfg)).steps == 4
    (tmp_path / "link").symlink_to(data, target_is_directory=True)
    assert train(TrainConfig(out=str(out), steps=6, data="link", **cfg)).steps == 6
    shutil.copytree(data, tmp_path / "ds2")
    with pytest.raises(sdk.ParameterError, match="differs in: data"):
        train(TrainConfig(out=str(out), steps=8, data="ds2", **cfg))


def test_a_recipe_float_without_a_dot_is_a_number(tmp_path: Path) -> None:
    """PyYAML (YAML 1.1) reads ``lr: 5e-4`` as the string '5e-4': it was refused ("expected float, got '5e-4'").
    A string float() reads to a finite number is that number; others are refused, naming the key."""
    from rtp.train import RecipeError, load_recipe

    recipe = tmp_path / "r.yaml"
    recipe.write_text("lr: 5e-4\nsafety_quantile: '5e-1'\nper_metric:\n  flip:\n    lr: 1E-3\n")
    assert load_recipe(recipe, "jnyang").values == {"lr": 5e-4, "safety_quantile": 0.5}
    assert load_recipe(recipe, "flip").values["lr"] == 1e-3
    cfg = TrainConfig.from_recipe(recipe, data="d", metric="jnyang", out=str(tmp_path / "m.pt"))
    assert cfg.lr == 5e-4 and isinstance(cfg.lr, float) and cfg.recipe["values"]["lr"] == 5e-4
    for text, words in (("lr: 5e-4x\n", "recipe key 'lr': expected float, got '5e-4x'"),
                        ("lr: 1e999\n", "recipe key 'lr': expected a finite number, got '1e999'"),
                        ("lr: nan\n", "recipe key 'lr': expected a finite number, got 'nan'"),
                        ("per_metric:\n  psnr:\n    focus: inf\n", "per_metric psnr: recipe key 'focus': expected a "
                                                                     "finite number, got 'inf'"),
                        ("steps: 1e3\n", "recipe key 'steps': expected int, got '1e3'")):  # (an int is written as one)
        recipe.write_text(text)
        with pytest.raises(RecipeError, match=re.escape(words)):
            load_recipe(recipe, "jnyang")
    with pytest.raises(sdk.ParameterError, match="field 'lr': expected float, got '5e-4'"):  # (Python: a number)
        train(TrainConfig(data="d", metric="jnyang", out=str(tmp_path / "m.pt"), lr="5e-4"))  # type: ignore[arg-type]


def test_a_switch_the_recipe_turns_on_is_turned_off_by_its_no_flag(tmp_path: Path) -> None:
    """``rtp train --no-mirror`` where the recipe says ``mirror: true``: the caller wins, as a valued flag does
    (before, a switch had only its on form, so a recipe's could not be turned off from the command line)."""
    from rtp.cli._main import build_parser
    from rtp.cli._run import option_flags

    data = _dataset(tmp_path / "ds", n=6)
    recipe = tmp_path / "r.yaml"
    recipe.write_text("mirror: true\ncrop: 32\nbatch: 4\nhead: linear\n")
    out = tmp_path / "m.pt"
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--config", str(recipe), "--out", str(out),
                     "--steps", "2", "--val-scenes", "scene0", "--no-mirror", "-q"]) == 0
    ck = load_checkpoint(out)
    assert "mirror" not in ck.metadata.provenance  # (recorded only when on)
    assert ck.metadata.provenance["recipe"]["values"]["mirror"] is True
    assert ck.metadata.provenance["recipe"]["overrides"]["mirror"] is False
    train_parser = next(a for a in build_parser()._actions if a.dest == "command").choices["train"]
    switches = ("augment", "mirror", "separable", "separable_tail", "energy_norm", "contrast_max")
    for dest in switches:
        flag = "--" + dest.replace("_", "-")
        base = ["--data", "d", "--metric", "jnyang", "--out", "m.pt"]
        assert getattr(train_parser.parse_args(base), dest) is None  # (the recipe's)
        assert getattr(train_parser.parse_args([*base, flag]), dest) is True
        assert getattr(train_parser.parse_args([*base, flag.replace("--", "--no-", 1)]), dest) is False
        assert option_flags(train_parser)[dest] == flag  # (an error about it names --mirror, not --no-mirror)
    cfg = TrainConfig.from_recipe("reuse", data="d", metric="jnyang", out=str(out), contrast_max=False)
    assert cfg.contrast_max is False and cfg.recipe["overrides"] == {"contrast_max": False}


def test_the_dead_output_error_is_the_last_line_after_the_repeated_warnings(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """`rtp train` printed its dead-output error itself and returned 1; the counts of the warnings held back as
    repeats were said after it, so the error was not the last line (`tail -1` of a log read "WARNING (repeated):
    ..."). It goes through the one error policy now: the counts first, the error last, exit 1."""
    import logging

    import rtp.train
    from rtp.train import TrainResult

    def dead(cfg: TrainConfig, **_: Any) -> TrainResult:
        for scene in ("a", "b", "c"):
            logging.getLogger("rtp.train").warning("scene %s: a warning said once a scene", scene)
        return TrainResult(Path(cfg.out), 2, dead_outputs=["1x2"])

    monkeypatch.setattr(rtp.train, "train", dead)
    capsys.readouterr()
    assert rtp_main(["train", "--data", str(tmp_path), "--metric", "jnyang", "--out", str(tmp_path / "m.pt"),
                     "--device", "cpu", "--no-progress"]) == 1
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "WARNING rtp.train: scene a: a warning said once a scene"
    assert lines[1] == "WARNING (repeated): 2 more like: scene a: a warning said once a scene"
    assert lines[2].startswith("rtp train: error: dead output(s) 1x2 (see the warning above); ")
    assert lines[2].endswith("is kept, not fit to export: train again with another --seed") and len(lines) == 3


def test_recipe_is_the_same_flag_as_config(capsys: pytest.CaptureFixture[str]) -> None:
    """The recipe flag is ``--config``; ``--recipe`` (what the docs and ``make train RECIPE=`` call it) was an
    unrecognised argument. Both give the one value, and the help says so."""
    from rtp.cli._main import build_parser

    train_parser = next(a for a in build_parser()._actions if a.dest == "command").choices["train"]
    base = ["--data", "d", "--metric", "jnyang", "--out", "m.pt"]
    assert train_parser.parse_args(base).config == "shipped"
    assert train_parser.parse_args([*base, "--recipe", "reuse"]).config == "reuse"
    assert train_parser.parse_args([*base, "--config", "tile8"]).config == "tile8"
    with pytest.raises(SystemExit):
        rtp_main(["train", "--help"])
    assert "--config RECIPE.yaml, --recipe RECIPE.yaml" in capsys.readouterr().out


def test_resuming_on_grown_data_is_refused(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "ds", n=6)
    cfg = dict(data=str(data), metric="jnyang", crop=32, batch=4, val_every=10, save_every=10, head="linear")
    train(TrainConfig(out=str(tmp_path / "m.pt"), steps=10, **cfg))
    _dataset(tmp_path / "ds", n=9)  # more samples captured into the same folder
    with pytest.raises(sdk.RtpError, match="differs in: samples"):
        train(TrainConfig(out=str(tmp_path / "m.pt"), steps=20, **cfg))


def test_heads_and_the_dead_output_check(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from rtp.train.model import MetricNet

    paper, linear = MetricNet(head="paper"), MetricNet(head="linear")
    assert sum(p.numel() for p in paper.parameters()) == sum(p.numel() for p in linear.parameters())
    def relus(net: MetricNet) -> int:
        return sum(isinstance(m, torch.nn.ReLU) for m in net.layers)

    assert (relus(paper), relus(linear)) == (5, 4)
    with pytest.raises(ValueError, match="head"):
        MetricNet(head="relu6")
    # An output whose last ReLU never fires predicts a constant: training names it and fails.
    data = _dataset(tmp_path / "ds", n=6)
    cfg = TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), steps=4, crop=32, batch=4,
                      val_every=2, save_every=2)
    real_init = MetricNet.__init__

    def dead_2x1(self, *a, **kw):  # noqa: ANN001, ANN002, ANN003, ANN202
        real_init(self, *a, **kw)
        conv = [m for m in self.layers if isinstance(m, torch.nn.Conv2d)][-1]
        with torch.no_grad():
            conv.weight[1].zero_()
            conv.bias[1] = -1.0

    import unittest.mock

    with unittest.mock.patch.object(MetricNet, "__init__", dead_2x1):
        result = train(cfg)
        assert "2x1" in result.dead_outputs
        assert "2x1" in load_checkpoint(tmp_path / "m.pt").metadata.provenance["dead_outputs"]  # recorded, work kept
        args = ["train", "--data", str(data), "--metric", "jnyang", "--config", "paper-net", "--out", str(tmp_path / "n.pt"),
                "--steps", "4", "--crop", "32"]
        assert rtp_main(args) == 1 and "--head linear" in capsys.readouterr().err
    # On this toy data the paper's head loses outputs within a few steps; the linear head does not.
    assert rtp_main([*args[:-4], "--out", str(tmp_path / "l.pt"), "--steps", "20", "--crop", "32", "--head", "linear"]) == 0
    ck = load_checkpoint(tmp_path / "l.pt")
    assert ck.net.config["head"] == "linear" and not ck.metadata.provenance["dead_outputs"]
    assert ck.metadata.provenance["head"] == "linear"  # (the paper's network reads it: recorded)


def test_the_fast_architecture_trains_exports_and_runs_in_the_sdk(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                                   ) -> None:
    data = _dataset(tmp_path / "ds", n=6)
    out = tmp_path / "fast.pt"
    # (the shipped JNYang recipe's .blocks planes refuse --augment: the seven planes of the others)
    seven = "reprojected.y,seen,albedo.y,normal.z,roughness,metallic,specular"
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(out), "--steps", "30",
                     "--crop", "32", "--val-scenes", "scene0", "--arch", "fast", "--depth", "4", "--width", "8",
                     "--augment", "--inputs", seven]) == 0
    ck = load_checkpoint(out)
    assert type(ck.net).__name__ == "FastNet" and ck.net.config["depth"] == 4 and ck.net.config["width"] == 8
    assert ck.metadata.provenance["arch"] == "fast" and ck.metadata.provenance["augment"] is True
    assert "head" not in ck.metadata.provenance  # (it said head: paper, an option the fast network never reads)
    # rtp-export needs nothing special for it, and the SDK nothing new
    onnx_path = export.export_checkpoint(out, tmp_path / "fast.onnx")
    pred = sdk.load(onnx_path)
    assert len(pred.metadata.inputs) == 7  # the shipped recipe's planes: the paper's four + the material ones
    x = np.random.default_rng(4).random((7, H, W), dtype=np.float32)
    with torch.inference_mode():
        raw = ck.net(torch.from_numpy(x)[None])[0].numpy()
    np.testing.assert_allclose(pred.predict_raw(x), raw, atol=1e-5)
    assert pred.shading_rates(x).shape == pred.tiles(H, W)
    # an unknown architecture is a usage error before any work
    with pytest.raises(SystemExit) as exc:
        rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(tmp_path / "x.pt"), "--arch", "resnet"])
    assert exc.value.code == 2 and "--arch" in capsys.readouterr().err
    with pytest.raises(sdk.ParameterError, match="arch"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "y.pt"), arch="resnet", crop=32))


def test_the_loss_is_a_recipe_choice(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _dataset(tmp_path / "ds", n=6)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--steps", "30", "--crop", "32", "--val-scenes", "scene0"]
    for loss in ("mse", "huber", "bce"):
        out = tmp_path / f"{loss}.pt"
        assert rtp_main([*base, "--out", str(out), "--loss", loss]) == 0
        ck = load_checkpoint(out)
        assert ck.metadata.provenance["loss"] == loss and ck.training["config"]["loss"] == loss
        assert json.loads(ck.training["history"])[-1]["train_loss"] >= 0
    before = load_checkpoint(tmp_path / "mse.pt")
    # resuming a checkpoint with another loss is another training run: refused, naming the field
    with pytest.raises(sdk.RtpError, match="loss"):
        train(TrainConfig.from_recipe("shipped", data=str(data), metric="jnyang", out=str(tmp_path / "mse.pt"),
                                      steps=40, crop=32, val_scenes=("scene0",), loss="l1"))
    assert before.training["step"] == 30 and load_checkpoint(tmp_path / "mse.pt").training["step"] == 30
    with pytest.raises(sdk.ParameterError, match="loss: expected one of l1, mse, huber, bce, quantile"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "z.pt"), loss="hinge", crop=32))
    with pytest.raises(SystemExit) as exc:
        rtp_main([*base, "--out", str(tmp_path / "x.pt"), "--loss", "hinge"])
    assert exc.value.code == 2 and "--loss" in capsys.readouterr().err


def test_the_quantile_loss_predicts_an_upper_quantile(tmp_path: Path) -> None:
    from rtp.train._loop import _pinball

    # the pinball loss of q is smallest at the q-quantile of the targets: a constant fitted to it lands there
    t = torch.from_numpy(np.random.default_rng(0).standard_normal(20000))
    c = torch.zeros(1, dtype=torch.float64, requires_grad=True)
    opt = torch.optim.SGD([c], lr=0.5)
    for _ in range(300):
        opt.zero_grad()
        _pinball(0.8)(c.expand_as(t), t).mean().backward()
        opt.step()
    assert float(c.detach()) == pytest.approx(float(torch.quantile(t, 0.8)), abs=0.02)
    # q 0.5 is half the absolute error
    p = torch.tensor([0.2, 0.9])
    assert torch.allclose(_pinball(0.5)(p, torch.tensor([0.5, 0.5])), 0.5 * torch.tensor([0.3, 0.4]))

    data = _dataset(tmp_path / "ds", n=6)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--steps", "30", "--crop", "32", "--val-scenes", "scene0"]
    out = tmp_path / "q.pt"
    assert rtp_main([*base, "--out", str(out), "--loss", "quantile", "--quantile", "0.9"]) == 0
    ck = load_checkpoint(out)
    assert ck.metadata.provenance["loss"] == "quantile" and ck.metadata.provenance["quantile"] == 0.9
    assert ck.training["config"]["quantile"] == 0.9
    # resuming with another quantile is another training run: refused, naming the field
    with pytest.raises(sdk.RtpError, match="quantile"):
        train(TrainConfig.from_recipe("shipped", data=str(data), metric="jnyang", out=str(out), steps=40, crop=32,
                                      val_scenes=("scene0",), loss="quantile", quantile=0.75))
    for bad in (0.0, 1.0, -0.5):
        with pytest.raises(sdk.ParameterError, match="quantile: expected a number in"):
            train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "z.pt"), loss="quantile",
                              quantile=bad, crop=32))


def test_focus_weights_the_tiles_near_the_threshold(tmp_path: Path) -> None:
    from rtp.train._loop import FOCUS_WIDTH, _focused

    # two tiles with the same squared error: the one whose target is at the threshold counts 1 + focus
    # times the one far from it, and 0 is the plain mean
    p, t = torch.tensor([0.5, 0.1]), torch.tensor([0.6, 0.0])
    far = float(np.exp(-0.5 * (0.6 / FOCUS_WIDTH) ** 2))
    expected = (4.0 * 0.01 + (1.0 + 3.0 * far) * 0.01) / (4.0 + 1.0 + 3.0 * far)
    assert float(_focused("mse", 3.0, 0.6)(p, t)) == pytest.approx(expected, rel=1e-6)
    assert float(_focused("mse", 0.0, 0.6)(p, t)) == pytest.approx(0.01, rel=1e-6)
    # the same error on the tile at the threshold costs more than on the one far from it
    q = torch.tensor([0.4, 0.0])
    assert float(_focused("l1", 3.0, 0.6)(q, t)) > float(_focused("l1", 3.0, 0.6)(torch.tensor([0.6, 0.2]), t))

    data = _dataset(tmp_path / "ds", n=6)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--steps", "30", "--crop", "32", "--val-scenes",
            "scene0", "--loss", "mse"]
    out = tmp_path / "focus.pt"
    assert rtp_main([*base, "--out", str(out), "--focus", "3"]) == 0
    ck = load_checkpoint(out)
    assert ck.metadata.provenance["focus"] == 3.0 and ck.training["config"]["focus"] == 3.0
    assert ck.metadata.provenance["recipe"]["overrides"]["focus"] == 3.0
    # resuming it without the focus is another training run: refused, naming the field
    with pytest.raises(sdk.RtpError, match="focus"):
        train(TrainConfig.from_recipe("shipped", data=str(data), metric="jnyang", out=str(out), steps=40, crop=32,
                                      val_scenes=("scene0",), loss="mse"))
    for bad in (-1.0, float("nan"), float("inf")):
        # (-1 is out of range; nan and inf are no finite float, refused with the other fields' types)
        with pytest.raises(sdk.ParameterError, match="focus: expected a weight >= 0|field 'focus': expected a finite number"):
            train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "z.pt"), focus=bad, crop=32))


def test_resuming_a_focused_training_with_another_threshold_is_refused(tmp_path: Path) -> None:
    """The focus band is centred on the default threshold: a resume with another one trained another loss, silently
    (the threshold was not in the configuration a resume compares)."""
    from rtp.metrics import metric_info

    data = _dataset(tmp_path / "ds", n=6)
    base = dict(data=str(data), metric="jnyang", out=str(tmp_path / "f.pt"), crop=32, batch=2, val_scenes=("scene0",),
                val_every=2, save_every=2, focus=3.0)
    train(TrainConfig(steps=2, **base))
    with pytest.raises(sdk.ParameterError, match="another configuration .differs in: default_threshold."):
        train(TrainConfig(steps=4, default_threshold=0.5, **base))
    # the metric's own default, given by value, is the same band: it resumes
    assert train(TrainConfig(steps=4, default_threshold=metric_info("jnyang").default_threshold, **base)).steps == 4
    # without focus the threshold trains nothing: another one is the model's new default, not another run
    plain = {**base, "focus": 0.0, "out": str(tmp_path / "p.pt")}
    train(TrainConfig(steps=2, **plain))
    assert train(TrainConfig(steps=4, default_threshold=0.5, **plain)).steps == 4


def test_an_output_that_cannot_be_resumed_is_refused_before_the_samples_are_read(tmp_path: Path) -> None:
    """A file at --out that is no checkpoint, or a model without its training state, was refused only once every
    sample had been read (minutes for the shipped recipe's 1,224)."""
    from rtp.train import checkpoint
    from rtp.train.model import MetricNet

    from .conftest import base_metadata

    data = _dataset(tmp_path / "ds", n=6)
    bare = checkpoint.save(tmp_path / "bare.pt", MetricNet(), base_metadata())
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    read: list[tuple[Path, int]] = []
    for path, words in ((bare, "without its training state"), (junk, "not a checkpoint")):
        with pytest.raises(checkpoint.CheckpointError, match=words):
            train(TrainConfig(data=str(data), metric="jnyang", out=str(path), steps=2, crop=32, batch=2),
                  loading=lambda k, n, path=path: read.append((path, k)))
    assert read == []


def test_numpy_numbers_and_flags_train_and_export_as_pythons(tmp_path: Path) -> None:
    """numpy's scalars passed the field checks and then failed once the data was loaded (seed=np.int64: a TypeError
    from torch; lr=np.float32: the checkpoint's JSON) or were refused as what they are (batch=np.int64(2): 'expected an
    integer >= 1'); a string for a list was read letter by letter (val_scenes="scene0": scenes s, c, e, ...)."""
    data = _dataset(tmp_path / "ds", n=6)
    cfg = TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "n.pt"), steps=np.int64(2),
                      batch=np.int64(2), crop=np.int32(32), seed=np.int64(3), lr=np.float32(1e-3),
                      augment=np.bool_(False), val_scenes="scene0", val_every=np.int64(2))
    result = train(cfg)
    ck = load_checkpoint(result.checkpoint)
    prov = ck.metadata.provenance
    assert result.steps == 2 and prov["seed"] == 3 and type(prov["seed"]) is int and prov["val_scenes"] == ("scene0",)
    assert type(ck.training["config"]["lr"]) is float
    # from a recipe: the overrides its provenance records are Python's too
    r = TrainConfig.from_recipe("shipped", data=str(data), metric="jnyang", out=str(tmp_path / "r.pt"),
                                steps=np.int64(5), lr=np.float64(2e-3), mirror=np.bool_(True))
    assert (type(r.steps), type(r.mirror)) == (int, bool) and r.recipe is not None
    assert {k: type(v) for k, v in r.recipe["overrides"].items()} == {"steps": int, "lr": float, "mirror": bool}
    out = export.export_checkpoint(result.checkpoint, tmp_path / "n.onnx", opset=np.int64(17),
                                   finite_probe=np.bool_(False))
    assert sdk.load(out).metadata.finite_probe is None


def test_the_mlp_head_trains_from_the_command_line_and_is_recorded(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    data = _dataset(tmp_path / "ds", n=4)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--crop", "32", "--val-scenes",
            "scene0", "--arch", "fast", "--head-width", "32", "--steps", "6"]
    assert rtp_main([*base, "--out", str(tmp_path / "h.pt")]) == 0
    ck = load_checkpoint(tmp_path / "h.pt")
    assert ck.net.config["head_width"] == 32 and ck.metadata.provenance["head_width"] == 32
    assert [m.out_channels for m in ck.net.modules() if isinstance(m, torch.nn.Conv2d)][-2:] == [32, 4]
    # the same file with a linear head (0) is another network: refused, not silently resumed
    assert rtp_main([*base[:-4], "--head-width", "0", "--steps", "12", "--out", str(tmp_path / "h.pt")]) != 0
    assert "differs in: head_width" in capsys.readouterr().err
    # 0 overrides the recipe's head (the shipped recipe gives JNYang an MLP head of 64); negatives are refused
    assert rtp_main([*base[:-4], "--head-width", "0", "--steps", "6", "--out", str(tmp_path / "l.pt")]) == 0
    assert "head_width" not in load_checkpoint(tmp_path / "l.pt").net.config
    with pytest.raises(SystemExit) as exc:
        rtp_main([*base[:-4], "--head-width", "-1", "--out", str(tmp_path / "n.pt")])
    assert exc.value.code == 2 and "expected an integer >= 0, got -1" in capsys.readouterr().err
    with pytest.raises(sdk.ParameterError, match="head_width: the fast network's option"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "p.pt"), crop=32, head_width=32))


def test_the_energy_norm_trains_from_the_command_line_and_is_recorded(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    data = _dataset(tmp_path / "ds", n=4)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--crop", "32", "--val-scenes",
            "scene0", "--arch", "fast", "--energy-norm", "--steps", "6"]
    assert rtp_main([*base, "--out", str(tmp_path / "e.pt")]) == 0
    ck = load_checkpoint(tmp_path / "e.pt")
    assert ck.net.config["energy_norm"] is True and ck.metadata.provenance["energy_norm"] is True
    assert any(type(m).__name__ == "EnergyNorm" for m in ck.net.modules())
    # the same file without the option is another network: refused, not silently resumed
    assert rtp_main([*base[:-3], "--steps", "12", "--out", str(tmp_path / "e.pt")]) != 0
    assert "differs in: energy_norm" in capsys.readouterr().err


def test_the_context_pool_trains_from_the_command_line_and_is_recorded(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    data = _dataset(tmp_path / "ds", n=4)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--crop", "32", "--val-scenes",
            "scene0", "--arch", "fast", "--head-width", "0", "--context-pool", "5", "--steps", "6"]
    assert rtp_main([*base, "--out", str(tmp_path / "c.pt")]) == 0
    ck = load_checkpoint(tmp_path / "c.pt")
    assert ck.net.config["context_pool"] == 5 and ck.metadata.provenance["context_pool"] == 5
    assert any(type(m).__name__ == "ContextPool" for m in ck.net.modules())
    # the same file without the pool is another network: refused, not silently resumed
    assert rtp_main([*base[:-4], "--steps", "12", "--out", str(tmp_path / "c.pt")]) != 0
    assert "differs in: context_pool" in capsys.readouterr().err
    for bad in ("4", "1"):  # even windows have no centre; 1 is the tile itself
        with pytest.raises(sdk.ParameterError, match="context_pool: expected 0 .none. or an odd window"):
            train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "b.pt"), arch="fast", crop=32,
                              context_pool=int(bad)))
    with pytest.raises(sdk.ParameterError, match="context_pool: the fast network's option"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "p.pt"), crop=32, context_pool=5))


def test_the_coarse_context_trains_from_the_command_line_and_is_recorded(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    data = _dataset(tmp_path / "ds", n=4)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--crop", "64", "--val-scenes", "scene0", "--arch",
            "fast", "--head-width", "0", "--depth", "4", "--coarse", "1", "--coarse-width", "8", "--steps", "6"]
    assert rtp_main([*base, "--out", str(tmp_path / "c.pt")]) == 0
    ck = load_checkpoint(tmp_path / "c.pt")
    assert (ck.net.config["coarse"], ck.net.config["coarse_width"]) == (1, 8)
    assert (ck.metadata.provenance["coarse"], ck.metadata.provenance["coarse_width"]) == (1, 8)
    # the same file without it is another network: refused, not silently resumed
    assert rtp_main([*base[:-6], "--steps", "12", "--out", str(tmp_path / "c.pt")]) != 0
    assert "differs in: coarse" in capsys.readouterr().err
    with pytest.raises(sdk.ParameterError, match="coarse: expected 0 .none., or blocks at twice the tile's scale"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "b.pt"), arch="fast", crop=32, depth=2,
                          coarse=1))
    with pytest.raises(sdk.ParameterError, match="coarse: the fast network's option"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "p.pt"), crop=32, coarse=1))


def test_the_mirror_trains_with_context_and_is_recorded(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    # --mirror: each crop (with its context) mirrored left-right or not, never flipped upside down or transposed;
    # the .blocks planes mirror by whole cells (tests/test_augment.py)
    import rtp.train._loop as loop
    from rtp.train._augment import SYMMETRIES, augment_batch

    drawn: list[int] = []

    def spy(xb, yb, inputs, outputs, symmetries):  # type: ignore[no-untyped-def]
        drawn.extend(symmetries)
        return augment_batch(xb, yb, inputs, outputs, symmetries)

    monkeypatch.setattr(loop, "augment_batch", spy)
    assert SYMMETRIES[1] == (False, False, True)  # the left-right mirror
    data = _dataset(tmp_path / "ds", n=4)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--crop", "32", "--context", "16", "--val-scenes",
            "scene0", "--arch", "fast", "--head-width", "0", "--inputs",
            "reprojected.y,seen,albedo.y,normal.x,reprojected.y.blocks,albedo.y.blocks", "--batch", "16", "--seed", "1",
            "--mirror", "--steps", "6"]  # (seed 0's six steps leave the 1x2 output flat: a dead output, exit 1)
    assert rtp_main([*base, "--out", str(tmp_path / "m.pt")]) == 0
    assert set(drawn) == {0, 1} and len(drawn) == 6 * 16  # each crop mirrored or not
    ck = load_checkpoint(tmp_path / "m.pt")
    assert ck.metadata.provenance["mirror"] is True and ck.metadata.provenance["augment"] is False
    # the same file without the mirror is another training: refused, not silently resumed
    assert rtp_main([*[a for a in base[:-2] if a != "--mirror"], "--steps", "12", "--out", str(tmp_path / "m.pt")]) != 0
    assert "differs in: mirror" in capsys.readouterr().err
    common = {"data": str(data), "metric": "jnyang", "crop": 32, "arch": "fast", "mirror": True}
    with pytest.raises(sdk.ParameterError, match="augment's eight symmetries include the mirror"):
        train(TrainConfig(out=str(tmp_path / "a.pt"), augment=True, **common))
    with pytest.raises(sdk.ParameterError, match="aux_metrics and mirror cannot be combined"):
        train(TrainConfig(out=str(tmp_path / "x.pt"), aux_metrics=("flip",), **common))


def test_block_contrast_trains_from_the_command_line_and_is_recorded(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    data = _dataset(tmp_path / "ds", n=4)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--crop", "32", "--val-scenes", "scene0",
            "--arch", "fast", "--inputs", "reprojected.y,seen,albedo.y,normal.z", "--block-contrast",
            "albedo.y,reprojected.y", "--steps", "6"]
    assert rtp_main([*base, "--out", str(tmp_path / "b.pt")]) == 0
    ck = load_checkpoint(tmp_path / "b.pt")
    assert ck.net.config["block_contrast"] == [2, 0]  # indices into the inputs, in the order given
    assert list(ck.metadata.provenance["block_contrast"]) == ["albedo.y", "reprojected.y"]
    # the same file without the contrast is another network: refused, not silently resumed
    assert rtp_main([*base[:-4], "--steps", "12", "--out", str(tmp_path / "b.pt")]) != 0
    assert "differs in: block_contrast" in capsys.readouterr().err
    common = {"data": str(data), "metric": "jnyang", "crop": 32, "inputs": ("reprojected.y", "seen", "albedo.y")}
    for bad in (("depth",), ("seen", "seen")):  # not an input; twice
        with pytest.raises(sdk.ParameterError, match="block_contrast: expected distinct channels among the inputs"):
            train(TrainConfig(out=str(tmp_path / "x.pt"), arch="fast", block_contrast=bad, **common))
    with pytest.raises(sdk.ParameterError, match="block_contrast: the fast network's option"):
        train(TrainConfig(out=str(tmp_path / "p.pt"), block_contrast=("seen",), **common))
    # (the transpose is what they cannot take; the message said a flip garbled them too, where --mirror keeps them)
    with pytest.raises(sdk.ParameterError, match="augment: albedo.y.blocks pack one value per pixel.*a transposed "
                                                 "crop.*a flip keeps them: mirror takes them"):
        train(TrainConfig(out=str(tmp_path / "a.pt"), augment=True,
                          **{**common, "inputs": ("reprojected.y", "seen", "albedo.y.blocks")}))
    with pytest.raises(sdk.ParameterError, match="contrast_cell: only with block_contrast"):
        train(TrainConfig(out=str(tmp_path / "c.pt"), arch="fast", contrast_cell=8, **common))
    with pytest.raises(sdk.ParameterError, match="contrast_cell: expected 0 .the stem's. or one of 4, 8, 16"):
        train(TrainConfig(out=str(tmp_path / "c.pt"), arch="fast", block_contrast=("seen",), contrast_cell=6, **common))
    with pytest.raises(sdk.ParameterError, match="block_contrast: needs a stem of at least 2 pixels"):
        train(TrainConfig(out=str(tmp_path / "s.pt"), arch="fast", stem=1, block_contrast=("seen",), **common))
    # stored planes: .blocks or .tiles, not both, last among the inputs; .tiles summarise 16-pixel tiles
    stored = {**common, "inputs": ("reprojected.y", "seen", "reprojected.y.blocks", "albedo.y.tiles")}
    with pytest.raises(sdk.ParameterError, match="only .blocks planes or only .tiles planes"):
        train(TrainConfig(out=str(tmp_path / "m.pt"), arch="fast", block_contrast=stored["inputs"][2:], contrast_cell=16,
                          **{k: v for k, v in stored.items() if k != "crop"}))
    tiles = {**common, "inputs": ("reprojected.y", "seen", "reprojected.y.tiles", "albedo.y.tiles")}
    for bad in ({"contrast_cell": 8}, {"tile": 32, "contrast_cell": 16}):
        with pytest.raises(sdk.ParameterError, match="tiles planes summarise 16-pixel tiles"):
            train(TrainConfig(out=str(tmp_path / "t.pt"), arch="fast", block_contrast=tiles["inputs"][2:],
                              **{**tiles, "crop": 64, **bad}))
    with pytest.raises(sdk.ParameterError, match="augment: reprojected.y.tiles, albedo.y.tiles pack one value"):
        train(TrainConfig(out=str(tmp_path / "a.pt"), augment=True, **tiles))


def test_max_width_trains_from_the_command_line_and_bad_caps_are_refused(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    data = _dataset(tmp_path / "ds", n=4)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--crop", "32", "--val-scenes",
            "scene0", "--arch", "fast", "--grow", "2", "--depth", "4", "--head-width", "0", "--steps", "6"]
    assert rtp_main([*base, "--max-width", "32", "--out", str(tmp_path / "m.pt")]) == 0
    ck = load_checkpoint(tmp_path / "m.pt")
    assert ck.net.config["max_width"] == 32 and ck.metadata.provenance["max_width"] == 32
    assert max(m.out_channels for m in ck.net.modules() if isinstance(m, torch.nn.Conv2d)) == 32
    # resuming without the cap is another network: refused
    assert rtp_main([*base[:-1], "12", "--out", str(tmp_path / "m.pt")]) != 0
    assert "differs in: max_width" in capsys.readouterr().err
    rtp_main([*base[:-2], "--separable", "--steps", "6", "--out", str(tmp_path / "s.pt")])  # 6 steps: kept even if dead
    assert load_checkpoint(tmp_path / "s.pt").metadata.provenance["separable"] is True
    rtp_main([*base[:-2], "--separable-tail", "--steps", "6", "--out", str(tmp_path / "t.pt")])
    ck = load_checkpoint(tmp_path / "t.pt")
    assert ck.metadata.provenance["separable_tail"] is True and ck.net.config["separable_tail"] is True
    rtp_main([*base[:-2], "--tail-width", "24", "--steps", "6", "--out", str(tmp_path / "w.pt")])
    ck = load_checkpoint(tmp_path / "w.pt")
    assert ck.metadata.provenance["tail_width"] == 24 and ck.net.config["tail_width"] == 24
    with pytest.raises(sdk.ParameterError, match="tail_width sets the channels"):  # depth 2: no block at 1/16
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "d.pt"), arch="fast", crop=32, depth=2,
                          tail_width=24))
    with pytest.raises(sdk.ParameterError, match="separable_tail: the fast network's option"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "q.pt"), crop=32, separable_tail=True))
    with pytest.raises(sdk.ParameterError, match="separable: the fast network's option"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "p.pt"), crop=32, separable=True))
    with pytest.raises(sdk.ParameterError, match="max_width caps grow 2's channels"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "b.pt"), arch="fast", crop=32,
                          max_width=32))


def test_the_weight_average_is_what_is_saved_and_resumes_exactly(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "ds", n=6)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--crop", "32", "--val-scenes", "scene0",
            "--stem-layers", "2", "--ema", "0.9"]
    assert rtp_main([*base, "--out", str(tmp_path / "a.pt"), "--steps", "24"]) == 0
    a = load_checkpoint(tmp_path / "a.pt")
    assert a.metadata.provenance["ema"] == 0.9 and a.metadata.provenance["stem_layers"] == 2
    assert a.net.config["stem_layers"] == 2 and a.training["config"]["ema"] == 0.9
    # the saved network is the average, the raw weights travel only to resume
    raw = a.training["raw_weights"]
    assert any(not torch.equal(v, raw[k]) for k, v in a.net.state_dict().items() if v.dtype.is_floating_point)
    # stopped half-way and resumed: exactly the uninterrupted run, average and raw weights alike
    assert rtp_main([*base, "--out", str(tmp_path / "b.pt"), "--steps", "12"]) == 0
    assert rtp_main([*base, "--out", str(tmp_path / "b.pt"), "--steps", "24"]) == 0
    b = load_checkpoint(tmp_path / "b.pt")
    for k, v in a.net.state_dict().items():
        assert torch.equal(v, b.net.state_dict()[k]) and torch.equal(raw[k], b.training["raw_weights"][k]), k
    # another decay is another training run; a decay outside [0, 1) is refused before any work
    with pytest.raises(sdk.RtpError, match="ema"):
        train(TrainConfig.from_recipe("shipped", data=str(data), metric="jnyang", out=str(tmp_path / "b.pt"), steps=30,
                                      crop=32, val_scenes=("scene0",), stem_layers=2, ema=0.99))
    with pytest.raises(sdk.ParameterError, match=r"ema: expected a decay in \[0, 1\)"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "c.pt"), crop=32, ema=1.0))
    with pytest.raises(sdk.ParameterError, match="stem_layers"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "c.pt"), crop=32, arch="fast", stem=1,
                          stem_layers=2))
    with pytest.raises(sdk.ParameterError, match="energy_norm: the fast network's option"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "c.pt"), crop=32, energy_norm=True))
    # an exported average predicts what it does in torch
    pred = sdk.load(export.export_checkpoint(tmp_path / "a.pt", tmp_path / "a.onnx"))
    x = np.random.default_rng(5).random((len(pred.metadata.inputs), H, W), dtype=np.float32)
    with torch.inference_mode():
        want = a.net(torch.from_numpy(x)[None])[0].numpy()
    np.testing.assert_allclose(pred.predict_raw(x), want, atol=1e-5)


def test_a_run_interrupted_at_a_validation_resumes_with_the_history_of_an_uninterrupted_one(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Ctrl-C at a validation step (in the progress bar's update, before the validation, or during it) saved that
    # step without its validation; the resumed run went on from it and its history, in the checkpoint and the
    # model's provenance, lacked that step's scores. The weights were exact; the record was not. And Ctrl-C during
    # the final validation and calibration lost every step since the last periodic save (here 8 of them).
    from rtp.train import _loop

    data = _dataset(tmp_path / "ds", n=6)
    kw = dict(data=str(data), metric="jnyang", crop=32, batch=4, val_scenes=("scene0",), steps=16, val_every=4,
              save_every=8)
    whole = load_checkpoint(train(TrainConfig(out=str(tmp_path / "a.pt"), **kw)).checkpoint)

    def stop_at(at: int) -> Callable[[int, int, float], None]:
        def progress(step: int, total: int, loss: float) -> None:
            if step == at:
                raise KeyboardInterrupt
        return progress

    out = tmp_path / "b.pt"
    with pytest.raises(KeyboardInterrupt):  # before step 4's validation
        train(TrainConfig(out=str(out), **kw), progress=stop_at(4))
    assert load_checkpoint(out).training["step"] == 4
    real_validate, calls = _loop._validate, [0]

    def validate_stopping_at_12(net: Any, val: Any, *args: Any) -> Any:  # inside step 12's validation
        calls[0] += 1
        if calls[0] == 3:  # (step 4's owed one, step 8's, then 12's)
            raise KeyboardInterrupt
        return real_validate(net, val, *args)

    monkeypatch.setattr(_loop, "_validate", validate_stopping_at_12)
    with pytest.raises(KeyboardInterrupt):
        train(TrainConfig(out=str(out), **kw))
    assert load_checkpoint(out).training["step"] == 12
    calls[0] = 0  # the final validation after step 16 (step 12's owed one, step 16's, then the final one)
    with pytest.raises(KeyboardInterrupt):
        train(TrainConfig(out=str(out), **kw))
    assert load_checkpoint(out).training["step"] == 16  # (the last periodic save held step 8)
    monkeypatch.setattr(_loop, "_validate", real_validate)
    resumed = load_checkpoint(train(TrainConfig(out=str(out), **kw)).checkpoint)
    assert [h["step"] for h in json.loads(resumed.training["history"])] == [0, 4, 8, 12, 16]
    assert resumed.training["history"] == whole.training["history"]
    assert resumed.metadata.provenance["history"] == whole.metadata.provenance["history"]
    assert resumed.metadata.provenance["validation"] == whole.metadata.provenance["validation"]
    for k, v in whole.net.state_dict().items():
        assert torch.equal(v, resumed.net.state_dict()[k]), k


def test_an_interrupt_after_a_steps_forward_pass_keeps_the_batchnorm_statistics_of_the_step_before(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Ctrl-C between a step's forward pass and its weight update saved the step before with the BatchNorm running
    # statistics (and num_batches_tracked) that the cut-short forward pass had already moved: the resumed run made
    # that step again, so its batch entered the statistics twice and the model ended unlike the uninterrupted run's
    # (num_batches_tracked one over; running means and variances, and the validations, off).
    from rtp.train import _loop

    data = _dataset(tmp_path / "ds", n=6)
    kw = dict(data=str(data), metric="jnyang", crop=32, batch=4, val_scenes=("scene0",), steps=8, val_every=4,
              save_every=100)
    whole = load_checkpoint(train(TrainConfig(out=str(tmp_path / "a.pt"), **kw)).checkpoint)
    real_loss, calls = _loop._LOSSES["l1"], [0]

    def loss_stopping_in_step_6(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        calls[0] += 1
        if calls[0] == 6:  # (step 6's forward pass has run; its weights are not yet updated)
            raise KeyboardInterrupt
        return real_loss(pred, target)

    out = tmp_path / "b.pt"
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(_loop._LOSSES, "l1", loss_stopping_in_step_6)
        with pytest.raises(KeyboardInterrupt):
            train(TrainConfig(out=str(out), **kw))
    kept = load_checkpoint(out)
    assert kept.training["step"] == 5
    assert all(int(v) == 5 for k, v in kept.net.state_dict().items() if k.endswith("num_batches_tracked"))
    resumed = load_checkpoint(train(TrainConfig(out=str(out), **kw)).checkpoint)
    for k, v in whole.net.state_dict().items():
        assert torch.equal(v, resumed.net.state_dict()[k]), k
    assert resumed.training["history"] == whole.training["history"]


def test_adamw_with_a_cosine_schedule_trains_resumes_exactly_and_is_recorded(tmp_path: Path) -> None:
    from rtp.train import _loop

    # the schedule: a linear warm-up over 2% of the steps, then half a cosine to zero at the last step
    cfg = TrainConfig(data="-", metric="jnyang", out="-", steps=1000, lr=1e-3, optimizer="adamw", schedule="cosine")
    opt, sched = _loop._optimizer(torch.nn.Linear(2, 1), cfg)
    assert isinstance(opt, torch.optim.AdamW)
    lrs = []
    for _ in range(1000):
        lrs.append(opt.param_groups[0]["lr"])
        opt.step()
        sched.step()
    assert lrs[0] == pytest.approx(1e-3 / 20) and lrs[19] == pytest.approx(1e-3) and max(lrs) == pytest.approx(1e-3)
    assert lrs[510] == pytest.approx(0.5e-3, rel=0.01) and lrs[-1] < 1e-8 and all(a >= b for a, b in zip(lrs[19:], lrs[20:]))
    data = _dataset(tmp_path / "ds", n=6)
    base = ["train", "--data", str(data), "--metric", "jnyang", "--crop", "32", "--val-scenes", "scene0",
            "--optimizer", "adamw", "--schedule", "cosine", "--weight-decay", "0.01"]
    assert rtp_main([*base, "--out", str(tmp_path / "a.pt"), "--steps", "24"]) == 0
    a = load_checkpoint(tmp_path / "a.pt")
    assert a.training["config"]["optimizer"] == "adamw" and a.training["config"]["schedule"] == "cosine"
    assert a.metadata.provenance["recipe"]["overrides"]["optimizer"] == "adamw"
    # interrupted after a checkpoint and resumed: exactly the uninterrupted run (the schedule's step travels too)
    kw = dict(data=str(data), metric="jnyang", crop=32, val_scenes=("scene0",), steps=24, save_every=8,
              optimizer="adamw", schedule="cosine", weight_decay=0.01)

    def stop_at_13(step: int, total: int, loss: float) -> None:
        if step == 13:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train(TrainConfig.from_recipe("shipped", out=str(tmp_path / "b.pt"), **kw), progress=stop_at_13)
    assert load_checkpoint(tmp_path / "b.pt").training["step"] == 13  # (the steps since the last save, 8, are kept)
    # and again inside step 18, its crops drawn, its weights not yet updated: step 17 is kept with the crop
    # sampler as it was before step 18 drew (resuming from what the sampler had become would draw other crops)
    real_crop, calls = _loop.crop_batch, [0]

    def crop_until_18(*args: Any, **kwargs: Any) -> Any:
        calls[0] += 1
        if calls[0] == 18 - 13:
            raise KeyboardInterrupt
        return real_crop(*args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_loop, "crop_batch", crop_until_18)
        with pytest.raises(KeyboardInterrupt):
            train(TrainConfig.from_recipe("shipped", out=str(tmp_path / "b.pt"), **kw))
    assert load_checkpoint(tmp_path / "b.pt").training["step"] == 17
    # and inside step 20's schedule update, its weights already stepped: no consistent state, the last save (17) stays
    real_optimizer = _loop._optimizer

    def schedule_stopping_at_20(*args: Any, **kwargs: Any) -> Any:
        opt, sched = real_optimizer(*args, **kwargs)
        real_step = sched.step

        def step_or_stop(*a: Any, **k: Any) -> Any:
            if sched.last_epoch + 1 == 20:
                raise KeyboardInterrupt
            return real_step(*a, **k)

        sched.step = step_or_stop
        return opt, sched

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_loop, "_optimizer", schedule_stopping_at_20)
        with pytest.raises(KeyboardInterrupt):
            train(TrainConfig.from_recipe("shipped", out=str(tmp_path / "b.pt"), **kw))
    assert load_checkpoint(tmp_path / "b.pt").training["step"] == 17
    train(TrainConfig.from_recipe("shipped", out=str(tmp_path / "b.pt"), **kw))
    b = load_checkpoint(tmp_path / "b.pt")
    for k, v in a.net.state_dict().items():
        assert torch.equal(v, b.net.state_dict()[k]), k
    # a cosine's length is part of its schedule: more steps is another run
    with pytest.raises(sdk.ParameterError, match="schedule_steps"):
        train(TrainConfig.from_recipe("shipped", out=str(tmp_path / "b.pt"), **{**kw, "steps": 30}))
    # another optimizer is another training run; unknown names are refused before any work
    with pytest.raises(sdk.ParameterError, match="optimizer"):
        train(TrainConfig.from_recipe("shipped", data=str(data), metric="jnyang", out=str(tmp_path / "a.pt"), steps=30,
                                      crop=32, val_scenes=("scene0",), schedule="cosine", weight_decay=0.01))
    with pytest.raises(sdk.ParameterError, match="optimizer: expected one of rmsprop, adamw"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "c.pt"), crop=32, optimizer="sgd"))
    with pytest.raises(sdk.ParameterError, match="schedule: expected one of exponential, cosine"):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "c.pt"), crop=32, schedule="step"))


def test_distillation_mixes_the_teachers_mean_into_the_targets(tmp_path: Path) -> None:
    from rtp.capture import DatasetReader, TargetStore
    from rtp.train import _loop

    data = _dataset(tmp_path / "ds", n=6)
    base = dict(data=str(data), metric="jnyang", crop=32, batch=4, val_scenes=("scene0",), arch="fast", loss="mse")
    teachers = []
    for seed in (0, 1):
        train(TrainConfig(out=str(tmp_path / f"t{seed}.pt"), steps=8, seed=seed, **base))
        teachers.append(str(export.export_checkpoint(tmp_path / f"t{seed}.pt", tmp_path / f"t{seed}.onnx")))
    cfg = TrainConfig(out=str(tmp_path / "s.pt"), steps=8, teachers=tuple(teachers), distill=0.7, **base)
    # the soft targets are the mean of what the teachers predict on each whole training frame
    reader = DatasetReader(str(data))
    ids = [s.id for s in reader if s.meta["scene"] != "scene0"]
    split = _loop._Split(reader, TargetStore(str(data)), ids, cfg)
    soft = _loop._teacher_targets(cfg, reader, split, _loop._make_transform(cfg, split.y))
    for k, i in enumerate(ids):
        x = reader[i].inputs(cfg.inputs)
        want = np.mean([sdk.load(t).predict_raw(x) for t in teachers], axis=0)
        np.testing.assert_allclose(soft[k], want, atol=1e-4)  # the teachers read the float16 training copy
        assert soft[k].shape == split.y[k].shape
    result = train(cfg)
    prov = load_checkpoint(result.checkpoint).metadata.provenance
    assert list(prov["teachers"]) == ["t0.onnx", "t1.onnx"] and prov["distill"] == 0.7
    # through the command line too; a teacher on other tiles, or a weight outside (0, 1], is refused
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(tmp_path / "c.pt"), "--steps",
                     "4", "--crop", "32", "--val-scenes", "scene0", "--head-width", "0",  # as the teachers
                     "--teachers", ",".join(teachers)]) == 0
    assert load_checkpoint(tmp_path / "c.pt").metadata.provenance["distill"] == 0.5
    with pytest.raises(sdk.ParameterError, match="teachers: .* on 16-pixel tiles.* the student needs jnyang on 8-pixel"):
        train(TrainConfig(out=str(tmp_path / "p.pt"), steps=4, teachers=(teachers[0],), tile=8, **base))
    with pytest.raises(sdk.ParameterError, match=r"distill: expected a weight in \(0, 1\]"):
        train(TrainConfig(out=str(tmp_path / "q.pt"), steps=4, teachers=tuple(teachers), distill=0.0, **base))
    assert not (tmp_path / "p.pt").exists() and not (tmp_path / "q.pt").exists()
    # bench/ensemble.py scores the teachers and their mean (what distillation aims at) on a dataset
    import subprocess
    import sys

    bench = Path(__file__).resolve().parents[1] / "bench" / "ensemble.py"
    out = subprocess.run([sys.executable, str(bench), *teachers, "--data", str(data)], capture_output=True, text=True,
                         check=True).stdout
    rows = [line for line in out.splitlines() if line.startswith(("| t0.onnx", "| t1.onnx", "| mean of the 2"))]
    assert len(rows) == 3 and all(len(r.split("|")) == 6 for r in rows)
    from rtp.evaluate import scores as r2_scores  # the mean row is R² of the averaged outputs

    ys, ps = [], []
    for i in (s.id for s in reader):
        ys.append(sdk.load(teachers[0]).metadata.transform.forward(TargetStore(str(data)).load(i, "jnyang", 16)[
            [sdk.PREDICTED_RATES.index(r) for r in sdk.DEFAULT_OUTPUTS]]).reshape(4, -1))
        x = reader[i].inputs(cfg.inputs)
        ps.append(np.mean([sdk.load(t).predict_raw(x) for t in teachers], axis=0).reshape(4, -1))
    want = 100 * r2_scores(np.concatenate(ps, 1), np.concatenate(ys, 1)).r2
    assert f"| mean of the 2 | {want:.1f} |" in out
    # --scene reads only those maps
    one = subprocess.run([sys.executable, str(bench), *teachers, "--data", str(data), "--scene", "scene1"],
                         capture_output=True, text=True, check=True).stdout
    assert f"on {sum(s.meta['scene'] == 'scene1' for s in reader)} samples of {data} (scene1)" in one
    # models on other tiles cannot be averaged: refused, naming both
    train(TrainConfig(out=str(tmp_path / "e.pt"), steps=2, tile=8, **base))
    other = export.export_checkpoint(tmp_path / "e.pt", tmp_path / "e.onnx")
    bad = subprocess.run([sys.executable, str(bench), teachers[0], str(other), "--data", str(data)],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "8-pixel tiles" in bad.stderr and "t0.onnx" in bad.stderr


def test_auxiliary_metrics_train_extra_outputs_and_save_only_the_metrics(tmp_path: Path) -> None:
    from rtp.train.model import FastNet, keep_outputs

    # keep_outputs cuts the head to its first rows and leaves those outputs' predictions unchanged
    net = FastNet(7, 12, 16, width=8, depth=3, head_width=16).eval()
    x = torch.rand(1, 7, 64, 96)
    cut = keep_outputs(net, 4)
    assert cut.config["out_channels"] == 4 and not cut.training
    torch.testing.assert_close(cut(x), net(x)[:, :4])
    with pytest.raises(ValueError, match="expected 1 to 12 outputs, got 13"):
        keep_outputs(net, 13)

    data = _dataset(tmp_path / "ds", n=6, flip=True)
    base = dict(data=str(data), metric="jnyang", crop=32, batch=4, val_scenes=("scene0",), arch="fast", loss="mse")
    cfg = TrainConfig(out=str(tmp_path / "a.pt"), steps=6, save_every=3, aux_metrics=("flip",), aux_weight=0.3, **base)
    result = train(cfg)
    ck = load_checkpoint(result.checkpoint)
    # the saved network has the metric's four outputs and exports like any other; the training state keeps all eight
    assert ck.net.config["out_channels"] == 4 and ck.metadata.outputs == sdk.DEFAULT_OUTPUTS
    assert list(ck.metadata.provenance["aux_metrics"]) == ["flip"] and ck.metadata.provenance["aux_weight"] == 0.3
    full = ck.training["full_weights"]
    head = [k for k in full if k.endswith(".weight") and full[k].ndim == 4][-1]
    assert full[head].shape[0] == 8
    torch.testing.assert_close(ck.net.state_dict()[head], full[head][:4])
    onnx = export.export_checkpoint(result.checkpoint, tmp_path / "a.onnx")
    assert sdk.load(onnx).predict_raw(np.random.default_rng(0).random((4, 64, 96), dtype=np.float32)).shape[0] == 4
    # resumable like any run: the same command resumes from the full weights and finishes where it was
    again = train(TrainConfig(out=str(tmp_path / "a.pt"), steps=9, save_every=3, aux_metrics=("flip",),
                              aux_weight=0.3, **base))
    assert again.steps == 9
    with pytest.raises(sdk.ParameterError, match="differs in: aux_metrics, aux_weight"):
        train(TrainConfig(out=str(tmp_path / "a.pt"), steps=9, **base))
    # bad settings are refused before any work, naming what was expected
    for kw, match in [(dict(aux_metrics=("jnyang",)), "other than jnyang"),
                      (dict(aux_metrics=("no_such_metric",)), "expected distinct metrics"),
                      (dict(aux_metrics=("flip",), aux_weight=0.0), "aux_weight: expected a weight > 0"),
                      (dict(aux_metrics=("flip",), augment=True), "cannot be combined"),
                      (dict(aux_metrics=("psnr",)), r"no psnr targets \(aux_metrics\); run `rtp targets")]:
        with pytest.raises((sdk.ParameterError, sdk.RtpError), match=match):
            train(TrainConfig(out=str(tmp_path / "b.pt"), steps=2, **{**base, **kw}))
    with pytest.raises(sdk.ParameterError, match="the fast network's option"):
        train(TrainConfig(out=str(tmp_path / "b.pt"), steps=2, **{**base, "arch": "paper"}, aux_metrics=("flip",)))
    assert not (tmp_path / "b.pt").exists()
    # through the command line
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(tmp_path / "c.pt"), "--steps", "12",
                     "--crop", "32", "--val-scenes", "scene0", "--aux-metrics", "flip", "--aux-weight", "0.25"]) == 0
    prov = load_checkpoint(tmp_path / "c.pt").metadata.provenance
    assert list(prov["aux_metrics"]) == ["flip"] and prov["aux_weight"] == 0.25
    # a weight without auxiliary metrics is a usage error, not ignored
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(tmp_path / "d.pt"), "--steps", "2",
                     "--crop", "32", "--val-scenes", "scene0", "--aux-weight", "0.25"]) == 2
    assert not (tmp_path / "d.pt").exists()


def test_bench_residuals_splits_the_squared_error_and_compares_rate_rules(tmp_path: Path) -> None:
    import re
    import subprocess
    import sys

    from rtp.capture import DatasetReader

    data = _dataset(tmp_path / "ds", n=6)
    train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), steps=20, crop=32,
                      val_scenes=("scene0",), loss="mse"))
    model = export.export_checkpoint(tmp_path / "m.pt", tmp_path / "m.onnx")
    bench = Path(__file__).resolve().parents[1] / "bench" / "residuals.py"
    png = tmp_path / "accuracy.png"
    out = subprocess.run([sys.executable, str(bench), str(model), "--data", str(data), "--plot", str(png)],
                         capture_output=True, text=True, check=True).stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f"wrote {png}" in out
    # the headline R² is the raw output's against the transformed truth, as bench/ensemble.py scores it
    pred = sdk.load(model)
    meta, reader, store = pred.metadata, DatasetReader(str(data)), TargetStore(str(data))
    rows = [sdk.PREDICTED_RATES.index(r) for r in meta.outputs]
    ps, gs = [], []
    for s in reader:
        ps.append(pred.predict_raw(s.inputs(meta.inputs)).reshape(len(rows), -1))
        gs.append(meta.transform.forward(store.load(s.id, "jnyang", 16)[rows]).reshape(len(rows), -1))
    want = 100 * scores(np.concatenate(ps, 1), np.concatenate(gs, 1)).r2
    assert f"R² {want:.1f}%" in out
    # each output's own R² (the per-tile part the pooled figure mixes with the difference between rates)
    for j, r in enumerate(meta.outputs):
        own = 100 * scores(np.concatenate(ps, 1)[j], np.concatenate(gs, 1)[j]).r2
        assert f"| {r} | {own:.1f} |" in out
    # --scene reads only those maps
    one = subprocess.run([sys.executable, str(bench), str(model), "--data", str(data), "--scene", "scene2"],
                         capture_output=True, text=True, check=True).stdout
    assert f"on {sum(s.meta['scene'] == 'scene2' for s in reader)} samples of {data} (scene2)" in one

    def row(name: str) -> list[float]:
        line = next(x for x in out.splitlines() if x.startswith(f"| {name}"))
        return [float(v) for v in re.findall(r"[-+]?\d+\.\d+", line.split("|", 2)[2])]

    # each partition of the tiles carries all of the squared error between its parts
    assert row("seen")[1] + row("unseen")[1] == pytest.approx(100.0, abs=0.2)
    assert row("seen")[5] + row("unseen")[5] in (pytest.approx(100.0, abs=0.2), 0.0)  # the large underestimates
    assert sum(row(f"target fifth {k}")[1] for k in range(1, 6)) == pytest.approx(100.0, abs=0.3)
    assert row("depth step > 0.5")[0] + row("depth step 0.1-0.5")[0] + row("no depth step")[0] == pytest.approx(
        100.0, abs=0.2)
    # per map and per frame, the best constant can only raise R²
    r_all = row("all")
    assert r_all[0] == pytest.approx(want, abs=0.06) and r_all[0] <= r_all[1] + 1e-9 <= r_all[2] + 1e-9
    assert len(r_all) == 4  # and the affine fitted on the other maps; one map has no other to fit on:
    assert next(x for x in one.splitlines() if x.startswith("| all |")).rstrip().endswith("| - |")
    # the rate rules: saving more where more tiles may fail, never more than 4x4 everywhere (93.75%)
    assert 0.0 <= float(re.search(r"the oracle saves (\d+\.\d+)%", out).group(1)) <= 93.75
    for name in ("one threshold", "calibrated risk", "two thresholds"):
        v = [x for x in row(name) if x == x]
        assert v and v == sorted(v) and all(0.0 <= x <= 93.75 for x in v)
    # the synthetic estimates: R² as named, and the same noise scaled down underestimates fewer tiles
    noise = [[c.strip() for c in x.split("|")[2:4]] for x in out.splitlines() if x.startswith("| truth + noise (each")]
    assert [float(r2) for r2, _ in noise[1:]] == [90.0, 95.0, 98.0]
    tails = [[float(v) for v in t.split("/")] for _, t in noise[1:]]
    assert all(a >= b for a, b in tails) and tails == sorted(tails, reverse=True)


def test_bench_per_rate_finds_a_rate_the_model_underestimates_and_scores_held_out_maps(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import subprocess
    import sys

    path, mod = _bench_module("per_rate", monkeypatch)
    # a model exact on every rate but 4x4, whose estimate is half the truth: one threshold lets 4x4 fail
    # where a factor below 1 on 4x4 (a stricter threshold there) does not
    rng = np.random.default_rng(3)
    truth = np.sort(rng.random((20, 6, 6, 8)) * 0.5, axis=1)  # coarser rates err more
    pred = truth.copy()
    pred[:, 5] *= 0.5
    f = mod._fit(pred, truth, 0.25, False, 0.05)
    one = mod._saved_at(pred, truth, np.ones(6), 0.25, False, 0.05)
    known = mod._saved_at(pred, truth, np.array([1, 1, 1, 1, 1, 0.5]), 0.25, False, 0.05)  # the exact correction
    fitted = mod._saved_at(pred, truth, f, 0.25, False, 0.05)
    assert one < known - 0.1 and fitted >= known - 1e-9
    assert mod._saved_at(truth, truth, np.ones(6), 0.25, False, 0.0) == pytest.approx(mod._oracle(truth, 0.25, False))
    # the sidecar's factors keep the default setting: scaled so that the default threshold fails as often as one
    # threshold does, the ratios between rates as fitted
    # (an exact model fails nowhere with one threshold; looser factors fail, the kept ones as rarely as one threshold)
    loose = np.array([1.2, 1.2, 1.0, 1.0, 1.0, 0.85]) * 1.1
    kept = mod._keep_default(truth, truth, loose, 0.25, False)
    assert np.allclose(kept / kept[0], loose / loose[0]) and kept[0] < loose[0]
    fails = [mod._outcome(truth, truth, f, 1.0, 0.25, False)[0] for f in (np.ones(6), kept, loose)]
    assert fails[0] == fails[1] == 0.0 < fails[2]
    # the share of (tile, rate, contained rate) triples whose coarser value is the better: none on a sorted truth,
    # five of the thirteen where 4x4 dips under every other rate
    assert mod.falls(truth, False) == 0.0
    dip = truth.copy()
    dip[:, 5] = 0.0
    assert mod.falls(dip, False) == pytest.approx(5 / 13) and mod.falls(-dip, True) == pytest.approx(5 / 13)
    # end to end: one row per held-out map, savings rising with the failing share, within 4x4's 93.75%
    data = _dataset(tmp_path / "ds", n=6)
    train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), steps=10, crop=32,
                      val_scenes=("scene0",), loss="mse"))
    model = export.export_checkpoint(tmp_path / "m.pt", tmp_path / "m.onnx")
    out = subprocess.run([sys.executable, str(path), str(model), "--data", str(data), "--scene", "scene0,scene1,scene2"],
                         capture_output=True, text=True, check=True).stdout
    rows = [line.split("|") for line in out.splitlines() if line.startswith("| scene")]
    assert [r[1].strip() for r in rows] == ["scene0", "scene1", "scene2"]
    for r in rows:
        for cell in (r[2], r[3], r[4]):
            v = [float(x) for x in cell.split("/")]
            assert v == sorted(v) and all(0.0 <= x <= 93.75 for x in v)
    # --sidecar: the factors fitted on every map, as metadata rtp-export --retune bakes into the model
    side = tmp_path / "factors.yaml"
    out = subprocess.run([sys.executable, str(path), str(model), "--data", str(data), "--scene", "scene0,scene1,scene2",
                          "--sidecar", str(side)], capture_output=True, text=True, check=True).stdout
    assert f"wrote {side}" in out and "Fitted on scene0, scene1, scene2 together" in out
    tuned = sdk.load(export.retune(model, side, tmp_path / "tuned.onnx"))
    assert all(0.25 <= f <= 4.0 for f in tuned.metadata.rate_factors)
    assert side.read_text().startswith("# threshold factors per rate, fitted by: python bench/per_rate.py")
    # --held-out: each row's factors, fitted without its map, as a sidecar of that map
    out = subprocess.run([sys.executable, str(path), str(model), "--data", str(data), "--scene", "scene0,scene1,scene2",
                          "--held-out", str(tmp_path / "ho")], capture_output=True, text=True, check=True).stdout
    rows = [line.split("|") for line in out.splitlines() if line.startswith("| scene")]
    assert len(rows) == 3 and f"wrote {tmp_path / 'ho'}-scene0.yaml" in out
    for r in rows:
        held = yaml.safe_load((tmp_path / f"ho-{r[1].strip()}.yaml").read_text())["rate_factors"]
        assert list(held.values()) == pytest.approx([float(x) for x in r[7].split(",")], abs=0.006)
    bad = subprocess.run([sys.executable, str(path), str(model), "--data", str(data), "--scene", "scene0,nowhere"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "no sample of nowhere" in bad.stderr


@pytest.mark.parametrize("metric", ["flip", "psnr"])
def test_bench_loop_scale_finds_where_the_swept_model_fails_as_often_as_one_threshold(
        metric: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """bench/loop_scale.py on two play.json runs: the model with its factors swept fails 2, 6 and 10% of
    the tiles (mean of the paths) at 0.5, 1 and 2 times its default (PSNR: +6, 0, -6 dB); one threshold
    fails 8% at its default: the crossing is halfway between 1x and 2x in log threshold (-3 dB), and the
    sidecar's factors are the model's times that scale."""
    import subprocess
    import sys

    path, _ = _bench_module("loop_scale", monkeypatch)
    shipped = sdk.load(metric)
    meta = shipped.metadata
    thr, hib = meta.default_threshold, meta.higher_is_better
    (tmp_path / "one.yaml").write_text("rate_factors: null\n")  # the same network with one threshold (--one)
    one = export.retune(shipped.path, tmp_path / "one.yaml", tmp_path / "one.onnx")
    values = [thr + 6.0, thr, thr - 6.0] if hib else [thr * 0.5, thr, thr * 2.0]
    runs = []
    for i, (scene, shift) in enumerate((("a", -0.01), ("b", 0.01))):  # the paths' mean is what counts
        rows = [{"path": "slow", "method": metric, "value": v, "default": v == thr, "fail_share": f + shift,
                 "work_saved": 0.3 + 0.1 * k} for k, (v, f) in enumerate(zip(values, (0.02, 0.06, 0.10)))]
        rows.append({"path": "slow", "method": "one.onnx", "value": thr, "default": True, "fail_share": 0.08 + shift,
                     "work_saved": 0.35})
        run = {"settings": {"scene": scene, "methods": [metric, "one.onnx"],
                            "models": {metric: str(shipped.path), "one.onnx": str(one)}},
               "unseen": {"slow": [1.0, 0.0]}, "rows": rows}
        runs.append(tmp_path / f"run{i}.json")
        runs[-1].write_text(json.dumps(run))
    side = tmp_path / "scaled.yaml"
    out = subprocess.run([sys.executable, str(path), *map(str, runs), "--method", metric, "--one", "one.onnx",
                          "--sidecar", str(side)], capture_output=True, text=True, check=True).stdout
    scale = 10.0 ** (3.0 / 20.0) if hib else 2.0 ** 0.5  # PSNR: 3 dB lower is each factor x 10^(3/20)
    want = np.array(meta.rate_factors) * scale
    got = yaml.safe_load(side.read_text())["rate_factors"]
    assert list(got) == list(sdk.PREDICTED_RATES) and np.allclose(list(got.values()), want, atol=1e-4)
    assert f"x {scale:.4f}" in out and "| mean | | 8.0 / 35.0 | 6.0 / 40.0 | 8.0 / 45.0 |" in out
    assert side.read_text().startswith("# threshold factors per rate, fitted by: python bench/loop_scale.py")
    # a sweep that never fails as often as one threshold cannot be read: nothing written
    run = json.loads(runs[0].read_text())
    run["rows"][-1]["fail_share"] = 0.2
    runs[0].write_text(json.dumps(run))
    never = subprocess.run([sys.executable, str(path), str(runs[0]), "--method", metric, "--one", "one.onnx",
                            "--sidecar", str(tmp_path / "never.yaml")], capture_output=True, text=True)
    assert never.returncode == 2 and "never 20.00%" in never.stderr and not (tmp_path / "never.yaml").exists()
    bad = subprocess.run([sys.executable, str(path), str(runs[0]), "--method", "nothing", "--one", "one.onnx"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "hold no model 'nothing'" in bad.stderr


def test_bench_residuals_affine_is_fitted_on_the_other_maps_only(monkeypatch: pytest.MonkeyPatch) -> None:
    path, mod = _bench_module("residuals", monkeypatch)
    rng = np.random.default_rng(5)
    g = rng.random((2, 300))
    maps = np.array(["a"] * 100 + ["b"] * 100 + ["c"] * 100)
    # the same affine miscalibration on every map (and a NaN target): undone exactly on each held-out map
    p = (g - 0.1) / np.array([[0.8], [1.25]])
    g[1, 7] = np.nan
    fixed = mod._affine_lomo(p, g, maps)
    ok = np.isfinite(g)
    assert fixed is not None and np.allclose(fixed[ok], g[ok])
    # a map's own tiles never enter its fit: a miscalibration only map c has stays there
    p2 = p.copy()
    p2[:, maps == "c"] += 0.3
    fixed2 = mod._affine_lomo(p2, g, maps)
    assert fixed2 is not None and np.allclose(fixed2[0, maps == "c"] - g[0, maps == "c"], 0.8 * 0.3)
    assert mod._affine_lomo(p, g, np.array(["a"] * 300)) is None


def test_bench_residuals_risk_table_is_monotone_towards_the_worse_side(monkeypatch: pytest.MonkeyPatch) -> None:
    path, mod = _bench_module("residuals", monkeypatch)
    rng = np.random.default_rng(0)
    est = rng.random((6, 4000)) * 50.0  # e.g. PSNR estimates in dB
    bins = np.concatenate([[-np.inf], np.linspace(5, 45, 9), [np.inf]])
    for hib in (True, False):
        worse = est < 20.0 if hib else est > 30.0  # failing where the estimate is bad, plus noise
        fails = worse ^ (rng.random(est.shape) < 0.05)
        tab = mod._risk_table(est, fails, bins, hib)
        steps = np.diff(tab, axis=1)
        assert (steps <= 1e-12).all() if hib else (steps >= -1e-12).all()
        assert tab[:, 0].mean() > 0.8 if hib else tab[:, -1].mean() > 0.8  # the bad end fails


def test_validation_targets_of_one_value_leave_r2_null_and_the_model_saved(tmp_path: Path) -> None:
    # R² is undefined (NaN) where every validation target is one value (a held-out map with no error at all): the
    # provenance holds only JSON values, so the final save failed with a MetadataError after every step was trained
    data = _dataset(tmp_path / "ds", n=6)
    store = TargetStore(data)
    for sid in ("s000", "s003"):  # scene0's samples
        store.write(sid, "jnyang", np.zeros((6, H // 4, W // 4), np.float32), (H, W))
    result = train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), crop=32, batch=4, steps=2,
                               val_scenes=("scene0",)))
    assert np.isnan(result.val["transformed"]["r2"]) and result.val["transformed"]["n"] == 2 * 4 * (H // 16) * (W // 16)
    prov = load_checkpoint(result.checkpoint).metadata.provenance
    assert prov["validation"]["transformed"]["r2"] is None and prov["validation"]["transformed"]["mae"] >= 0
    assert all(h["val"]["r2"] is None for h in prov["history"])


def test_training_targets_the_transform_cannot_fit_are_refused_naming_the_data(tmp_path: Path) -> None:
    """Training targets all 0 (no error anywhere) were refused as metadata, "transform.mu_y: expected a number in
    [1e-06, 1e+06] (the mean training target), got 0"; a logistic transform flat over targets of mean 132 as "choose
    mu_y inside [0, 1] or a smaller k" (mu_y is measured, not chosen), and logistic_k 1e7 as "transform.k": the
    targets' error names them, the logistic ones name logistic_k."""
    from rtp.capture import TargetError

    data = _dataset(tmp_path / "ds", n=6)
    store = TargetStore(data)
    base = dict(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), crop=32, steps=2, val_scenes=("scene0",))
    for sid in ("s001", "s002", "s004", "s005"):  # every training sample's (scene1 and scene2)
        store.write(sid, "jnyang", np.zeros((6, H // 4, W // 4), np.float32), (H, W))
    with pytest.raises(TargetError, match=r"^the training targets \(jnyang\) have mean 0, which the clamped transform "
                                          r"divides by \(its mu_y\): expected a number in \[1e-06, 1e\+06\] \(the mean "
                                          r"training target\), got 0; every one is 0: the data holds no error to learn$"):
        train(TrainConfig(**base))
    for sid in ("s001", "s002", "s004", "s005"):
        store.write(sid, "jnyang", np.full((6, H // 4, W // 4), 100.0, np.float32), (H, W))
    with pytest.raises(sdk.ParameterError, match=r"^logistic_k: 10 does not fit the training targets \(jnyang\), of "
                                                r"mean 100 \(the transform's mu_y\): the logistic transform is then "
                                                r"flat") as e:
        train(TrainConfig(**base, transform="logistic"))
    assert e.value.name == "logistic_k"
    with pytest.raises(sdk.ParameterError, match=r"^logistic_k: expected a finite number of magnitude <= 1e\+06, "
                                                r"got 10000000.0 \(the logistic transform's growth rate\)$") as e:
        train(TrainConfig(**base, transform="logistic", logistic_k=1e7))
    assert e.value.name == "logistic_k" and not (tmp_path / "m.pt").exists()


def test_rtp_train_says_why_the_validation_r2_is_undefined(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Validation targets all of one value leave R² undefined: `rtp train`'s report printed "validation R² nan%"
    without a word of why; it says so."""
    data = _dataset(tmp_path / "ds", n=6)
    store = TargetStore(data)
    for sid in ("s000", "s003"):  # scene0's samples: no error anywhere
        store.write(sid, "jnyang", np.zeros((6, H // 4, W // 4), np.float32), (H, W))
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--arch", "fast", "--crop", "32", "--steps",
                     "10", "--val-scenes", "scene0", "--out", str(tmp_path / "m.pt")]) == 0
    out = capsys.readouterr().out
    assert "validation R² undefined (every validation tile's target is the same value" in out and "nan" not in out


def test_validation_predicts_a_partial_tile_row_as_the_exported_model_does(tmp_path: Path,
                                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    # Validation padded every frame to whole tiles; the SDK pads the exported fast network's input only to its
    # input_multiple (4). On frames with a partial row of tiles (72 = 4.5 x 16 here; a 1920x1080 import's at
    # 16-pixel tiles) the last rows of tiles read repeated rows the exported model never sees, so the validation
    # scores and the safety margin were calibrated on predictions the model does not make.
    from rtp.train import _loop
    from rtp.train._frames import Frame

    monkeypatch.setitem(globals(), "H", 72)
    data = _dataset(tmp_path / "ds", n=6)
    cfg = TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), arch="fast", crop=32, batch=4,
                      steps=2, lr=1e-2, val_scenes=("scene0",))
    result = train(cfg)
    ck = load_checkpoint(result.checkpoint)
    model = sdk.load(export.export_checkpoint(result.checkpoint, tmp_path / "m.onnx"))
    assert ck.net.input_multiple == 4 and model.metadata.pad_multiple == 4
    reader, rng = DatasetReader(data), np.random.default_rng(5)
    frames = [Frame(reader[i].inputs(cfg.inputs), cfg.inputs) for i in ("s000", "s003")]  # scene0: validation
    frames.append(Frame(rng.random((len(cfg.inputs), 74, 90)).astype(np.float16), cfg.inputs))  # padded to 76 x 92
    got = _loop._predict_frames(ck.net, frames, 16)
    want = [model.predict_raw(f.full().astype(np.float32)) for f in frames]
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape == (len(cfg.outputs), 5, 6)
        np.testing.assert_allclose(g, w, atol=2e-5)
    # and the validation scores the checkpoint records are the exported model's on the validation frames
    t = ck.metadata.transform
    rows = [sdk.PREDICTED_RATES.index(r) for r in cfg.outputs]
    truth = [t.forward(TargetStore(data).load(i, "jnyang", 16)[rows].astype(np.float64)) for i in ("s000", "s003")]
    mine = scores(np.concatenate([w.ravel() for w in want[:2]]), np.concatenate([y.ravel() for y in truth]))
    assert ck.metadata.provenance["validation"]["transformed"]["mae"] == pytest.approx(mine.mae, rel=1e-4)


def test_a_mirrored_window_scores_the_tiles_it_scored_unmirrored(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # With --context, a window at the frame's left border scores its border column and not its right margin; a
    # mirrored window has them the other way round. The mask was not mirrored with it: such a window scored the
    # mirrored margin (tiles that read the crop's zero padding) and left out the border tiles.
    import rtp.train._loop as loop

    batches: list[tuple[np.ndarray, list[int]]] = []
    masks: list[np.ndarray] = []
    losses: list[torch.Tensor] = []

    def spy_augment(xb, yb, inputs, outputs, symmetries):  # type: ignore[no-untyped-def]
        out = augment_batch(xb, yb, inputs, outputs, symmetries)
        batches.append((out[1], list(symmetries)))
        return out

    def spy_scored(*args):  # type: ignore[no-untyped-def]
        masks.append(scored_tiles(*args))
        return masks[-1]

    def spy_loss(p: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        losses.append(t.detach().clone())
        return torch.nn.functional.l1_loss(p, t)

    augment_batch, scored_tiles = loop.augment_batch, loop._scored_tiles
    monkeypatch.setattr(loop, "augment_batch", spy_augment)
    monkeypatch.setattr(loop, "_scored_tiles", spy_scored)
    monkeypatch.setitem(loop._LOSSES, "l1", spy_loss)
    data = _dataset(tmp_path / "ds", n=4)
    train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), arch="fast", crop=32, context=16,
                      mirror=True, batch=16, steps=3, val_scenes=("scene0",)))
    t = load_checkpoint(tmp_path / "m.pt").metadata.transform
    asymmetric = 0
    for (yb, sym), mask, got in zip(batches, masks, losses, strict=True):
        want = []
        for y, m, s in zip(yb, mask, sym):  # the mask in the window's original layout, mirrored where it was
            m = m[0, :, ::-1] if s else m[0]
            asymmetric += bool(s and not np.array_equal(m, m[:, ::-1]))
            want.append(t.forward(y.astype(np.float64))[:, m].ravel())
        np.testing.assert_allclose(got.numpy(), np.concatenate(want), rtol=1e-6)
    assert asymmetric  # (windows at a border, mirrored: where the old mask was wrong)


def test_context_scores_only_tiles_that_see_what_a_whole_frame_shows() -> None:
    from rtp.train import _loop
    from rtp.train.model import FastNet

    # a window of 6x6 tiles with 1 tile of context: the outer ring is not scored, except on a side
    # where the window meets the frame's border
    inner = _loop._scored_tiles([16], [32], 6, 1, 16, 160, 224)[0, 0]
    assert inner.sum() == 16 and inner[1:5, 1:5].all()
    corner = _loop._scored_tiles([0], [128], 6, 1, 16, 96, 224)[0, 0]  # top and bottom at the border, right too
    assert corner[:, 1:].all() and not corner[:, 0].any()
    # with the shipped network (4x4 stem, depth 3: a 72-pixel receptive field) 32 pixels of context are
    # enough: the scored tiles of a window predict exactly what the whole frame predicts there
    torch.manual_seed(0)
    net = FastNet(7, 4, 16).eval()
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.2, 0.2)
    frame = torch.rand(1, 7, 160, 224)
    with torch.inference_mode():
        whole = net(frame)
        window = net(frame[:, :, 32:160, 48:176])  # 8x8 tiles at tile (2, 3); the frame's bottom edge at 160
        short = net(frame[:, :, 16:144, 48:176])  # 1 tile of context only: a 16-pixel margin is not enough
    scored = _loop._scored_tiles([32], [48], 8, 2, 16, 160, 224)[0, 0]
    assert scored.sum() == 4 * 6  # rows 2..7 (the bottom ring is on the frame's border), columns 2..5
    rows, cols = np.nonzero(scored)
    torch.testing.assert_close(window[0][:, rows, cols], whole[0][:, rows + 2, cols + 3])
    rows1, cols1 = np.nonzero(_loop._scored_tiles([16], [48], 8, 1, 16, 160, 224)[0, 0])
    assert not torch.allclose(short[0][:, rows1, cols1], whole[0][:, rows1 + 1, cols1 + 3], atol=1e-4)
    # docs/training.md's count: a 128-pixel crop without context (8x8 tiles) predicts 48 of its tiles otherwise
    # than the whole frame does there, all but the middle 4x4 (the receptive field: 72 pixels, 28 past the tile)
    big = torch.rand(1, 7, 384, 384)
    with torch.inference_mode():
        whole = net(big)
        for top, left in ((128, 128), (144, 176)):
            crop = net(big[:, :, top:top + 128, left:left + 128])
            here = whole[:, :, top // 16:top // 16 + 8, left // 16:left // 16 + 8]
            differs = ((crop - here).abs().amax(1)[0] > 1e-5).numpy()
            assert differs.sum() == 48 and not differs[2:6, 2:6].any()
    x = torch.rand(1, 7, 256, 256, requires_grad=True)
    net(x)[0, 0, 8, 8].backward()
    rows = np.nonzero(x.grad[0].abs().sum((0, 2)).numpy())[0]  # type: ignore[union-attr]
    assert (rows.min(), rows.max()) == (128 - 28, 143 + 28)


def test_context_scores_no_margin_of_a_window_that_ends_before_a_partial_tile(tmp_path: Path,
                                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    # A window ending at the last whole tile of a frame with a partial row of tiles below it (72 rows at 16-pixel
    # tiles) was taken to meet the frame's border and scored its bottom ring, whose tiles read the crop's zero
    # padding where the whole frame shows them the partial tile's pixels.
    from rtp.train import _loop
    from rtp.train.model import FastNet

    masks: list[np.ndarray] = []
    real = _loop._scored_tiles
    monkeypatch.setattr(_loop, "_scored_tiles", lambda *a: masks.append(real(*a)) or masks[-1])
    monkeypatch.setitem(globals(), "H", 72)
    data = _dataset(tmp_path / "ds", n=4)
    train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), arch="fast", crop=32, context=16,
                      batch=8, steps=3, val_scenes=("scene0",)))
    windows = np.concatenate(masks)[:, 0]  # 4x4 tiles: every window spans rows 0-63, above the partial row
    assert len(windows) == 24 and windows[:, 0].any() and not windows[:, 3].any()
    assert windows[:, :, 3].any() and windows[:, :, 0].any()  # (columns: 96 is 6 whole tiles, its border scored)
    # what that ring predicts in a window is not what the whole frame predicts there
    torch.manual_seed(0)
    net = FastNet(7, 4, 16).eval()
    frame = torch.rand(1, 7, 168, 224)
    with torch.inference_mode():
        whole, window = net(frame), net(frame[:, :, 32:160, 48:176])
    scored = _loop._scored_tiles([32], [48], 8, 2, 16, 168, 224)[0, 0]
    rows, cols = np.nonzero(scored)
    assert scored.sum() == 4 * 4 and rows.max() == 5
    torch.testing.assert_close(window[0][:, rows, cols], whole[0][:, rows + 2, cols + 3])
    assert not torch.allclose(window[0][:, 7, 2:6], whole[0][:, 9, 5:9], atol=1e-4)


def test_training_with_context_records_it_and_refuses_what_does_not_fit(tmp_path: Path) -> None:
    data = _dataset(tmp_path / "ds", n=6)
    base = dict(data=str(data), metric="jnyang", crop=32, batch=4, val_scenes=("scene0",), arch="fast", loss="mse")
    result = train(TrainConfig(out=str(tmp_path / "c.pt"), steps=6, context=16, **base))
    assert load_checkpoint(result.checkpoint).metadata.provenance["context"] == 16
    with pytest.raises(sdk.ParameterError, match="another configuration"):  # resuming without it is another run
        train(TrainConfig(out=str(tmp_path / "c.pt"), steps=8, **base))
    with pytest.raises(sdk.ParameterError, match="multiple of the tile"):
        train(TrainConfig(out=str(tmp_path / "d.pt"), steps=2, context=8, **base))
    with pytest.raises(sdk.ParameterError, match="cannot be combined"):
        train(TrainConfig(out=str(tmp_path / "d.pt"), steps=2, context=16, augment=True, **base))
    with pytest.raises(sdk.ParameterError, match=r"^crop \+ 2 x context \(96\) is larger than the frames \(96x64\): a "
                                                r"context of at most 16 fits$") as e:
        train(TrainConfig(out=str(tmp_path / "d.pt"), steps=2, context=32, **base))
    assert e.value.name == "context"  # (it named no field)
    # (what fits, said: a recipe that gives no crop took the default, and the message named a crop nobody gave)
    with pytest.raises(sdk.ParameterError, match=r"^crop \(80\) is larger than the frames \(96x64\): a crop of at most 64 "
                                                r"fits$") as e:
        train(TrainConfig(out=str(tmp_path / "d.pt"), **{**base, "steps": 2, "crop": 80}))
    assert e.value.name == "crop"
    no_crop = {k: v for k, v in base.items() if k != "crop"}
    with pytest.raises(sdk.ParameterError, match=r"^crop \(128\) is larger than the frames \(96x64\): a crop of at most "
                                                r"64 fits \(128 is the default\)$"):
        train(TrainConfig(out=str(tmp_path / "d.pt"), steps=2, **no_crop))
    assert not (tmp_path / "d.pt").exists()


def test_frames_smaller_than_a_tile_are_refused_naming_the_tile(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """Frames that hold no whole tile (12x8 at 16-pixel tiles) were refused as "crop (32) is larger than the frames
    (12x8): a context of at most -16 fits", of a training given no context; they name the tile, and what fits."""
    monkeypatch.setitem(globals(), "H", 8)
    monkeypatch.setitem(globals(), "W", 12)
    data = _dataset(tmp_path / "ds", n=6)
    for context in (0, 16):
        with pytest.raises(sdk.ParameterError, match=r"^tile: the frames \(12x8\) hold no whole 16-pixel tile to crop; "
                                                    r"expected frames of at least 16x16, or a tile of 1, 2, 4, 8$") as e:
            train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), crop=16, context=context,
                              steps=2, val_scenes=("scene0",)))
        assert e.value.name == "tile"
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--steps", "2", "--val-scenes", "scene0",
                     "--out", str(tmp_path / "m.pt")]) == 2
    err = capsys.readouterr().err
    assert "--tile-size: the frames (12x8) hold no whole 16-pixel tile" in err and "-16" not in err
    assert not (tmp_path / "m.pt").exists()


def test_bench_target_ceiling_finds_no_phase_noise_where_the_grids_align(tmp_path: Path) -> None:
    import re
    import subprocess
    import sys

    data = _dataset(tmp_path / "ds", n=3)
    train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), steps=4, crop=32,
                      val_scenes=("scene0",)))
    model = export.export_checkpoint(tmp_path / "m.pt", tmp_path / "m.onnx")
    bench = Path(__file__).resolve().parents[1] / "bench" / "target_ceiling.py"

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, str(bench), str(model), "--data", str(data), "--scene", "",
                               "--margin", "0", *args], capture_output=True, text=True)

    def rows(out: str) -> dict[str, list[float]]:
        return {line.split("|")[1].strip(): [float(v) for v in re.findall(r"[-+]?\d+\.\d+", line.split("|", 2)[2])]
                for line in out.splitlines() if re.match(r"\| (1x2|2x1|2x4|4x2|pooled) \|", line)}

    # JNYang is per pixel but for its Weber denominator, a 4x4 block mean of the reference's luma on the
    # frame's grid: shifts by whole blocks recompute exactly the same targets (a wrong offset in the
    # bookkeeping would not: the frames are noise) ...
    aligned = run("--shifts", "0,0 4,4 8,0 12,8")
    assert aligned.returncode == 0, aligned.stderr
    table = rows(aligned.stdout)
    assert set(table) == {"1x2", "2x1", "2x4", "4x2", "pooled"}
    for name, (ceil, vs_target, vs_content, spread) in table.items():
        assert ceil == 100.0 and spread == 0.0 and vs_target == vs_content, name
    # ... and shifts inside a block move the denominator's blocks against the content: some phase noise
    inside = rows(run("--shifts", "0,0 1,3 2,2").stdout)
    assert all(v[0] < 100.0 and v[3] > 0.0 for v in inside.values())
    # bad phases are refused with what was expected
    for bad, why in (("0,0 16,0", "in [0, 16)"), ("4,4 0,0", "the first one 0,0"), ("0,0 x", "'dy,dx' pairs")):
        res = run("--shifts", bad)
        assert res.returncode != 0 and why in res.stderr, (bad, res.stderr)


def test_bench_input_ceiling_trains_and_scores_on_the_current_frame(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:

    from rtp.capture import DatasetReader, Sample

    monkeypatch.setattr(Sample, "buffer", Sample.buffer)  # the study patches the class: undone after the test
    path, mod = _bench_module("input_ceiling", monkeypatch)
    data = _dataset(tmp_path / "ds", n=6)
    s = DatasetReader(str(data))["s000"]
    before = s.inputs(["reprojected.r", "seen", "albedo.r"])
    mod.use_current_frame()
    s = DatasetReader(str(data))["s000"]
    after = s.inputs(["reprojected.r", "seen", "albedo.r"])
    # the reprojected plane is the frame itself, every pixel seen, the other planes untouched
    np.testing.assert_array_equal(after[0], s.final("1x1")[..., 0])
    assert (after[1] == 1).all() and not (before[1] == 1).all()
    np.testing.assert_array_equal(after[2], before[2])
    assert not np.array_equal(after[0], before[0])
    out = tmp_path / "study" / "c.pt"
    # 12 steps: after 4 the nine-plane recipe's 1x2 output was still flat on the tiny validation scene
    # (the dead-output check refuses such a model)
    assert mod.main(["--metric", "jnyang", "--data", str(data), "--out", str(out), "--steps", "12", "--scene", "scene2"]) == 0
    text = capsys.readouterr().out
    assert out.with_suffix(".onnx").is_file() and (tmp_path / "evalval-c" / "evaluation.json").is_file()
    assert "never to ship" in text and "| 1x2 |" in text  # residuals' per-output table


@pytest.mark.parametrize("size", [(40, 56), (42, 57)])
def test_training_frames_pack_block_planes_exactly(size: tuple[int, int]) -> None:
    from rtp.train._frames import Frame

    rng = np.random.default_rng(0)
    h, w = size
    y = rng.random((h, w)).astype(np.float32)
    names = ["reprojected.y", "reprojected.y.blocks", "seen", "albedo.y.blocks"]
    x = np.stack([y, sdk.block_variances(y), rng.random((h, w)), sdk.block_variances(y[::-1].copy())])
    f = Frame(x, names)
    want = x.astype(np.float16)
    np.testing.assert_array_equal(f.full(), want)
    assert f.full().dtype == np.float16 and f.shape == x.shape
    for oy, ox, side in [(0, 0, 16), (8, 12, 24), (16, 32, 24), (4, 8, 32), (3, 5, 12)]:  # the last: off the cells
        np.testing.assert_array_equal(f.crop(oy, ox, side), want[:, oy : oy + side, ox : ox + side])
    dense = x.astype(np.float16).nbytes
    if h % 4 == 0 and w % 4 == 0:  # the two .blocks planes packed to 6/16
        assert f.nbytes == dense // 4 * 2 + 2 * (dense // 4 * 6 // 16)
    else:  # a frame off the cell grid stays dense
        assert f.nbytes == dense
    # a plane named .blocks that is not zero off the value pixels stays dense, and exact
    x[3, 2, 3] = 0.5  # row 2 of a cell holds no value
    g = Frame(x, names)
    assert g.nbytes == (dense if h % 4 or w % 4 else dense // 4 * 3 + dense // 4 * 6 // 16)
    np.testing.assert_array_equal(g.crop(8, 12, 24), x.astype(np.float16)[:, 8:32, 12:36])
    with pytest.raises(ValueError, match=r"expected planes of shape \(3, H, W\)"):
        Frame(x, names[:3])


@pytest.mark.parametrize("names", [
    ["reprojected.y", "seen", "reprojected.y.blocks", "albedo.y.blocks"],  # packed planes consecutive: one view
    ["reprojected.y", "reprojected.y.blocks", "seen", "albedo.y.blocks"],  # apart: gathered
    ["reprojected.y", "reprojected.y.tiles", "albedo.y.blocks", "albedo.y.tiles"],  # two cells
])
def test_a_batch_of_crops_is_each_frames_crop(names: list[str]) -> None:
    """``crop_batch`` (a training step's batch) unpacks the packed planes of all its crops at once: the
    same values as each frame's own ``crop``, for frames of several layouts in one batch (a plane not
    zero off its value pixels stays dense in that frame alone) and crops off the cells."""
    from rtp.train._frames import Frame, crop_batch

    rng = np.random.default_rng(2)
    h, w = 48, 64
    frames, wants = [], []
    for k in range(3):
        y, a = rng.random((h, w)).astype(np.float32), rng.random((h, w)).astype(np.float32)
        planes = {"reprojected.y": y, "seen": rng.random((h, w)), "reprojected.y.blocks": sdk.block_variances(y),
                  "albedo.y.blocks": sdk.block_variances(a), "reprojected.y.tiles": sdk.tile_variances(y),
                  "albedo.y.tiles": sdk.tile_variances(a)}
        x = np.stack([planes[n] for n in names])
        if k == 2:
            x[-1, 3, 3] = 0.5  # off the value pixels: this frame keeps its last plane dense
        frames.append(Frame(x, names))
        wants.append(x.astype(np.float16))
    assert frames[0]._layout == frames[1]._layout != frames[2]._layout
    for picks in ([(0, 0, 0, 16), (1, 16, 32, 16), (0, 32, 48, 16), (1, 16, 0, 32)],  # one layout, on the tiles
                  [(0, 0, 0, 16), (2, 16, 16, 16), (1, 32, 48, 16), (2, 0, 48, 16)],  # two layouts
                  [(0, 4, 8, 16), (1, 0, 0, 16), (2, 3, 5, 16)]):  # off the cells or the tiles
        got = crop_batch([frames[i] for i, *_ in picks], [oy for _, oy, _, _ in picks], [ox for *_, ox, _ in picks],
                         picks[0][3]) if len({s for *_, s in picks}) == 1 else None
        if got is None:  # (one side per batch)
            for i, oy, ox, side in picks:
                np.testing.assert_array_equal(crop_batch([frames[i]], [oy], [ox], side)[0],
                                              wants[i][:, oy : oy + side, ox : ox + side])
            continue
        assert got.dtype == np.float16 and got.shape == (len(picks), len(names), picks[0][3], picks[0][3])
        for row, (i, oy, ox, side) in zip(got, picks):
            np.testing.assert_array_equal(row, wants[i][:, oy : oy + side, ox : ox + side])


@pytest.mark.parametrize("size", [(48, 64), (40, 56)])
def test_training_frames_pack_tile_planes_exactly(size: tuple[int, int]) -> None:
    """``.tiles`` planes hold twelve values a 16x16 tile: packed to 12/256 of a dense plane, unpacked
    exactly for tile-aligned crops and for any other window; a frame off the tile grid stays dense."""
    from rtp.train._frames import Frame

    rng = np.random.default_rng(1)
    h, w = size
    y = rng.random((h, w)).astype(np.float32)
    names = ["reprojected.y", "reprojected.y.tiles", "albedo.y.blocks", "albedo.y.tiles"]
    x = np.stack([y, sdk.tile_variances(y), sdk.block_variances(y), sdk.tile_variances(rng.random((h, w)) ** 3)])
    f = Frame(x, names)
    want = x.astype(np.float16)
    np.testing.assert_array_equal(f.full(), want)
    for oy, ox, side in [(0, 0, 16), (16, 16, 16), (0, 32, 16), (4, 8, 32), (3, 5, 12)]:  # the last two: off the tiles
        np.testing.assert_array_equal(f.crop(oy, ox, side), want[:, oy : oy + side, ox : ox + side])
    plane = x[0].astype(np.float16).nbytes
    if h % 16 == 0 and w % 16 == 0:
        assert f.nbytes == plane + plane * 6 // 16 + 2 * (plane * 12 // 256)
    else:  # the .tiles planes stay dense, the .blocks plane is still packed
        assert f.nbytes == 3 * plane + plane * 6 // 16


def test_bench_error_features_fits_held_out_maps_and_scores_the_model(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    import re
    import subprocess
    import sys

    from rtp.capture import DatasetReader

    path, mod = _bench_module("error_features", monkeypatch)
    # the window mean is the plain mean over the edge-repeated neighbourhood
    rng = np.random.default_rng(4)
    grid = rng.random((5, 7))
    padded = np.pad(grid, 1, mode="edge")
    naive = np.array([[padded[i:i + 3, j:j + 3].mean() for j in range(7)] for i in range(5)])
    np.testing.assert_allclose(mod.window_mean(grid, 3), naive)
    assert mod.window_mean(grid, 1) is grid
    # a target that is a nonlinear function of one column: the held-out fit finds it there and not in noise
    x = rng.random((3000, 2))
    y = np.sin(3 * x[:, 0]) + 0.01 * rng.standard_normal(3000)
    groups = np.array(["a", "b", "c"])[np.arange(3000) % 3]
    assert mod.held_out_r2(x[:, :1], y, groups, iterations=300) > 0.95
    assert mod.held_out_r2(x[:, 1:], y, groups, iterations=300) < 0.1
    with pytest.raises(ValueError, match="at least two maps"):
        mod.held_out_r2(x, y, np.full(3000, "a"), iterations=2)
    # end to end: one row per output; the model's column is its own per-output R²
    data = _dataset(tmp_path / "ds", n=6)
    train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), steps=4, crop=32,
                      val_scenes=("scene0",)))
    model = export.export_checkpoint(tmp_path / "m.pt", tmp_path / "m.onnx")
    out = subprocess.run([sys.executable, str(path), str(model), "--data", str(data), "--scene", "", "--iterations", "20"],
                         capture_output=True, text=True, check=True).stdout
    pred = sdk.load(model)
    meta, reader, store = pred.metadata, DatasetReader(str(data)), TargetStore(str(data))
    rows = [sdk.PREDICTED_RATES.index(r) for r in meta.outputs]
    ps = np.concatenate([pred.predict_raw(s.inputs(meta.inputs)).reshape(len(rows), -1) for s in reader], 1)
    gs = np.concatenate([meta.transform.forward(store.load(s.id, "jnyang", 16)[rows]).reshape(len(rows), -1)
                         for s in reader], 1)
    table = {line.split("|")[1].strip(): [float(v) for v in re.findall(r"[-+]?\d+\.\d+", line.split("|", 2)[2])]
             for line in out.splitlines() if re.match(r"\| (1x2|2x1|2x4|4x2) \|", line)}
    assert list(table) == list(meta.outputs)
    for j, r in enumerate(meta.outputs):
        assert len(table[r]) == 5 and table[r][0] == pytest.approx(100 * scores(ps[j], gs[j]).r2, abs=0.06)
    # one map cannot be left out
    one = subprocess.run([sys.executable, str(path), str(model), "--data", str(data), "--scene", "scene1"],
                         capture_output=True, text=True)
    assert one.returncode == 2 and "at least two maps" in one.stderr
    bad = subprocess.run([sys.executable, str(path), str(model), "--data", str(data), "--iterations", "0"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "argument --iterations: expected a positive integer" in bad.stderr


def test_bench_scripts_say_how_to_make_a_missing_dataset(tmp_path: Path) -> None:
    """`python bench/per_rate.py jnyang --data data/val` on a checkout without data/val ended in a
    DatasetError traceback once the model had loaded; now argparse says how to capture it (exit 2)."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1] / "bench"
    for script in ("per_rate.py", "same_decisions.py"):
        argv = ["jnyang"] if script == "per_rate.py" else ["jnyang", "jnyang"]
        r = subprocess.run([sys.executable, str(root / script), *argv, "--data", str(tmp_path / "val")],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        assert "no dataset at" in r.stderr and "rtp capture --split validation" in r.stderr, r.stderr


def test_a_checkpoint_that_would_not_load_back_is_not_saved(tmp_path: Path) -> None:
    """A numpy scalar in `training` saved, then replaced a good checkpoint by one `load` refuses."""
    from rtp.train import checkpoint
    from rtp.train.model import MetricNet

    from .conftest import base_metadata

    path = checkpoint.save(tmp_path / "m.pt", MetricNet(4, 4, 16), base_metadata(), {"step": 5})
    before = path.read_bytes()
    for training in ({"step": np.int64(5)}, {"f": object()}):
        with pytest.raises(checkpoint.CheckpointError, match="would not load back"):
            checkpoint.save(path, MetricNet(4, 4, 16), base_metadata(), training)
    assert path.read_bytes() == before and load_checkpoint(path).training == {"step": 5}


@pytest.mark.parametrize(("key", "value"), [("format_version", "1"), ("format_version", -1), ("architecture", "FastNet"),
                                            ("architecture", {"name": "MetricNet", "config": [4, 4]}),
                                            ("state_dict", None), ("metadata", [1]), ("training", 5), ("versions", "x")])
def test_a_malformed_checkpoint_is_a_checkpoint_error(tmp_path: Path, key: str, value: Any) -> None:
    """A damaged or hand-made checkpoint raised TypeError ("'>' not supported"), AttributeError or
    ValueError from the lines that read its fields."""
    from rtp.train import checkpoint
    from rtp.train.model import MetricNet

    from .conftest import base_metadata

    path = checkpoint.save(tmp_path / "m.pt", MetricNet(4, 4, 16), base_metadata(), {"step": 5})
    raw = torch.load(path, weights_only=True)
    raw[key] = value
    torch.save(raw, path)
    with pytest.raises(checkpoint.CheckpointError, match=key.split("_")[0]):
        load_checkpoint(path)


def test_network_constructors_raise_parameter_errors() -> None:
    from rtp.train.model import FastNet, MetricNet, build_network, keep_outputs

    for make in (lambda: MetricNet(4, 4, 3), lambda: FastNet(4, 6, 16, width=1), lambda: build_network("nope", 4, 6, 16),
                 lambda: keep_outputs(MetricNet(4, 6, 16), 2)):  # type: ignore[arg-type]
        with pytest.raises(sdk.ParameterError):
            make()


@pytest.mark.parametrize(("key", "value"), [("steps", -5), ("steps", 0), ("batch", 0), ("crop", 0), ("val_every", 0),
                                            ("save_every", 0), ("tile", 0), ("outputs", ("9x9",)), ("head", "nope")])
def test_training_values_out_of_range_are_refused_before_any_work(tmp_path: Path, key: str, value: Any) -> None:
    """steps=-5 wrote an untrained checkpoint; the others failed in numpy, torch or a division, some only
    after training had started."""
    cfg = TrainConfig(data=str(tmp_path / "none"), metric="jnyang", out=str(tmp_path / "m.pt"), **{key: value})
    with pytest.raises(sdk.ParameterError, match=key):
        train(cfg)
    assert not (tmp_path / "m.pt").exists()


@pytest.mark.parametrize("fields, key, words", [
    ({"augment": True, "inputs": ("albedo.r", "normal.x", "normal.z", "seen")}, "augment", "needs both normal.x and normal.y"),
    ({"arch": "paper", "tail_width": 8}, "tail_width", "the fast network's option"),
    ({"arch": "fast", "head_width": -1}, "head_width", "expected 0 .a linear head."),
    ({"arch": "fast", "contrast_max": True}, "contrast_max", "only with block_contrast"),
    ({"per_scene": 0}, "per_scene", "at least 1 sample per map"),
    ({"max_samples": 0}, "max_samples", "at least 1 training sample"),  # (it trained on every sample)
    ({"max_samples": -1}, "max_samples", "at least 1 training sample"),  # (it left out the last sample)
    ({"arch": "paper", "separable": True}, "separable", "the fast network's option"),
    ({"arch": "paper", "energy_norm": True}, "energy_norm", "the fast network's option"),
    ({"arch": "paper", "depth": 5}, "depth", "the fast network's option"),  # (ignored, and recorded)
    ({"arch": "paper", "stem_layers": 2}, "stem_layers", "the fast network's option"),
    ({"arch": "fast", "head": "linear"}, "head", "the paper network's option"),  # (ignored, and recorded)
    # options of blocks the network has none of: it was built as without them, and they were recorded
    ({"arch": "fast", "grow": 2, "depth": 1}, "grow", "has none to double"),
    ({"arch": "fast", "grow": 2, "stem": 8, "tile": 8, "crop": 32}, "grow", "has none to double"),
    ({"arch": "fast", "grow": 2, "max_width": 16}, "grow", "has none to double"),
    ({"arch": "fast", "separable_tail": True, "depth": 2}, "separable_tail", "no block at tile resolution"),
    ({"arch": "fast", "separable_tail": True, "separable": True}, "separable_tail", "separable makes every block"),
    ({"distill": 0.0}, "distill", r"a weight in \(0, 1\]"),
    ({"ema": 1.0}, "ema", r"a decay in \[0, 1\)"),
    ({"aux_metrics": ("jnyang",)}, "aux_metrics", "other than jnyang"),
    # a lone .dx plane cannot be transposed (it turns into the .dy one); a .tiles plane's 16-pixel cells cannot be
    # mirrored in crops that start on 8-pixel tiles (between two cells: the mirror garbled them in silence)
    ({"augment": True, "inputs": ("reprojected.y", "seen", "reprojected.y.dx")}, "augment", "a .dx plane's .dy"),
    ({"mirror": True, "tile": 8, "inputs": ("reprojected.y", "seen", "reprojected.y.tiles")}, "mirror",
     "expected tile >= 16"),
])
def test_train_refuses_a_combination_naming_its_field_before_reading_data(fields: dict[str, Any], key: str, words: str,
                                                                           tmp_path: Path) -> None:
    """train() checks the whole configuration before it opens the data (which does not exist here):
    each refused combination is a ParameterError naming the field to change (its .name)."""
    with pytest.raises(sdk.ParameterError, match=f"^{key}: .*{words}") as info:
        train(TrainConfig(data=str(tmp_path / "nowhere"), metric="jnyang", out=str(tmp_path / "m.pt"), **fields))
    assert info.value.name == key and not (tmp_path / "m.pt").exists()


@pytest.mark.parametrize("fields", [{"arch": "fast", "width": 30000}, {"arch": "paper", "width": 30000},
                                    {"arch": "fast", "depth": 10**6}])
def test_a_network_too_large_to_build_is_refused_before_reading_data(fields: dict[str, Any], tmp_path: Path) -> None:
    """The network is sized on torch's meta device by check_config: a mistyped width is a one-line
    ParameterError instead of a 14 GB allocation after the data was read (here it does not exist)."""
    with pytest.raises(sdk.ParameterError, match="would hold|depth in"):
        train(TrainConfig(data=str(tmp_path / "nowhere"), metric="jnyang", out=str(tmp_path / "m.pt"), **fields))
    assert not (tmp_path / "m.pt").exists()


@pytest.mark.parametrize(("fields", "words"), [({"transform": "nosuch"}, "transform: expected clamped or logistic"),
                                               ({"teachers": ("nope.onnx",)}, "teachers: nope.onnx is not a model")])
def test_a_transform_or_teacher_it_cannot_use_is_refused_before_reading_data(fields: dict[str, Any], words: str,
                                                                            tmp_path: Path) -> None:
    """Both were refused only once every training sample was loaded (the transform is fitted to their mean,
    the teachers predict on them); here the data does not exist, so only check_config can have refused them."""
    with pytest.raises(sdk.ParameterError, match=words) as info:
        train(TrainConfig(data=str(tmp_path / "nowhere"), metric="jnyang", out=str(tmp_path / "m.pt"), **fields))
    assert info.value.name == next(iter(fields)) and not (tmp_path / "m.pt").exists()


@pytest.mark.parametrize("seed", [-2**63 - 1, 2**64, 2**70])
def test_a_seed_torch_cannot_take_is_refused_before_reading_data(seed: int, tmp_path: Path) -> None:
    """A seed past 64 bits was torch.manual_seed's ValueError once the data had been loaded; now a
    ParameterError naming seed from check_config. The range's ends themselves are taken."""
    with pytest.raises(sdk.ParameterError, match=r"seed: expected an integer in \[-9223372036854775808, "
                                                 r"18446744073709551615\]") as info:
        train(TrainConfig(data=str(tmp_path / "nowhere"), metric="jnyang", out=str(tmp_path / "m.pt"), seed=seed))
    assert info.value.name == "seed" and not (tmp_path / "m.pt").exists()
    for ok in (-2**63, 2**64 - 1):  # the data is what fails here, after the seed was taken
        with pytest.raises(DatasetError, match="no dataset"):
            train(TrainConfig(data=str(tmp_path / "nowhere"), metric="jnyang", out=str(tmp_path / "m.pt"), seed=ok))


def test_a_batch_past_the_machines_memory_is_refused_before_reading_data(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture,
    machine_memory: Callable[..., None]
) -> None:
    """A batch whose training step cannot fit in memory failed after the data was read, as numpy's
    MemoryError traceback (batch 10**6) or, under the machine's size, the system's OOM killer: now a
    usage error naming batch, from the network's activations measured on torch's meta device."""
    from rtp.capture import _memory
    from rtp.train import _loop

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)  # (device auto: this machine's CPU, on any machine)
    cfg = TrainConfig(data=str(tmp_path / "nowhere"), metric="jnyang", out=str(tmp_path / "m.pt"), crop=64)
    two = _loop.step_bytes(TrainConfig(data=cfg.data, metric="jnyang", out=cfg.out, crop=64, batch=2))
    crops = 4 * 64 * 64 * 6
    assert 1.4 * 2**20 < two / 2 - crops < 1.6 * 2**20  # the paper's network keeps about 1.5 MiB of a 64-pixel crop
    assert _loop.step_bytes(TrainConfig(data=cfg.data, metric="jnyang", out=cfg.out, crop=64, batch=300)) == 150 * two
    fast = _loop.step_bytes(TrainConfig(data=cfg.data, metric="jnyang", out=cfg.out, crop=64, batch=2, arch="fast"))
    assert 2 * crops < fast < two / 4  # the strided stem keeps far less
    with pytest.raises(sdk.ParameterError, match="^batch: 1 crop of 16 pixels leaves a BatchNorm layer of the fast "
                                                 "network one value per channel"):  # was a ValueError once training began
        train(TrainConfig(data=cfg.data, metric="jnyang", out=cfg.out, crop=16, batch=1, arch="fast"))

    memory = {"MemTotal": 4 * 2**30, "MemAvailable": 2**30}
    machine_memory(**memory)
    with pytest.raises(sdk.ParameterError, match=r"^batch: 4000 crops of 64 pixels take about 6\.1 GiB .* more than "
                                                 r"this machine's 4\.0 GiB of memory: lower batch or crop") as info:
        train(TrainConfig(data=cfg.data, metric="jnyang", out=cfg.out, crop=64, batch=4000))
    assert info.value.name == "batch"
    machine_memory(**memory, SwapTotal=4 * 2**30)  # with swap the job may still end (slowly): refused past both
    with pytest.raises(sdk.ParameterError, match=r"more than this machine's 8\.0 GiB of memory and swap: lower batch"):
        train(TrainConfig(data=cfg.data, metric="jnyang", out=cfg.out, crop=64, batch=6000))
    with caplog.at_level("WARNING", logger="rtp.train"), pytest.raises(DatasetError, match="no dataset folder"):
        train(TrainConfig(data=cfg.data, metric="jnyang", out=cfg.out, crop=64, batch=4000))  # fits: warned
    machine_memory(**memory)
    caplog.clear()
    with caplog.at_level("WARNING", logger="rtp.train"), pytest.raises(DatasetError, match="no dataset folder"):
        train(TrainConfig(data=cfg.data, metric="jnyang", out=cfg.out, crop=64, batch=1000))  # fits, not now: warned
    assert [r.getMessage().split(", more")[0] for r in caplog.records] == [
        "1000 crops of 64 pixels take about 1.5 GiB in a training step (what autograd keeps of the paper network's "
        "activations, and the crops)"]
    monkeypatch.setattr(_memory, "MEMINFO", "/proc/meminfo")  # the real machine's again

    data = _dataset(tmp_path / "d", n=3)
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(tmp_path / "m.pt"),
                     "--batch", "100000000"]) == 2  # on the real machine's memory
    err = capsys.readouterr().err
    assert "rtp train: error: --batch: 100000000 crops of 64 pixels take about" in err and "lower batch" in err
    assert not (tmp_path / "m.pt").exists()


def test_a_network_that_cannot_run_on_meta_is_sized_by_its_crops_with_a_warning(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Every network rtp builds runs on torch's meta device; one with an operation that cannot (a
    layer a user added) still trains, its step sized by the crops alone, and the log says so."""
    from rtp.train import _loop
    from rtp.train.model import MetricNet

    cfg = TrainConfig(data="nowhere", metric="jnyang", out="m.pt", crop=64, batch=10)
    measured = _loop.step_bytes(cfg)
    crops = 10 * 4 * 64 * 64 * 6

    def no_meta_kernel(self: Any, x: Any) -> Any:
        raise NotImplementedError("Could not run 'aten::my_op' with arguments from the 'Meta' backend")

    monkeypatch.setattr(MetricNet, "forward", no_meta_kernel)
    with caplog.at_level("WARNING", logger="rtp.train"):
        assert _loop.step_bytes(cfg) == crops < measured
    assert [r.getMessage().split(" (")[0] for r in caplog.records] == [
        "the activations of the paper network could not be measured on torch's meta device"]
    assert caplog.records[0].getMessage().endswith("the memory check of a training step counts the crops only")


def test_a_dataset_past_the_machines_memory_is_refused_before_it_is_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture, machine_memory: Callable[..., None]
) -> None:
    """Training holds every sample's planes in memory (16.8 GB for the shipped LPIPS run): a dataset
    past the machine's memory is refused from its first sample's size, before the rest are read."""
    from rtp.train import _loop

    data = _dataset(tmp_path / "d")  # 12 samples of four 96x64 float16 planes: 48 KiB each
    cfg = TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), arch="fast", batch=2, crop=16,
                      steps=2, val_every=2)
    machine_memory(MemTotal=300 * 1024, MemAvailable=300 * 1024)
    read = []
    monkeypatch.setattr(_loop, "Frame", lambda planes, names: read.append(1) or _frames.Frame(planes, names))
    with pytest.raises(sdk.ParameterError, match=r"^max_samples: the 12 samples' 4 input planes take about 0\.0 GiB .* "
                                                 r"more than this machine's 0\.0 GiB of memory: train on fewer") as info:
        train(cfg)
    assert info.value.name == "max_samples" and len(read) == 1 and not (tmp_path / "m.pt").exists()
    machine_memory(MemTotal=2**34, MemAvailable=300 * 1024)
    with caplog.at_level("WARNING", logger="rtp.train"):
        train(cfg)  # fits the machine, not what is free now: a warning, and it trains
    assert [r.getMessage().split(" (")[0] for r in caplog.records if "input planes" in r.getMessage()] == [
        "the 12 samples' 4 input planes take about 0.0 GiB in memory"]
    assert (tmp_path / "m.pt").exists()


def test_a_second_training_into_the_same_checkpoint_is_refused(tmp_path: Path) -> None:
    """Two trainings into one --out both resumed from the same checkpoint and saved over each other."""
    from rtp.sdk.files import writer_lock
    from rtp.train.checkpoint import CheckpointError

    data = _dataset(tmp_path / "d")
    out = tmp_path / "models" / "m.pt"
    cfg = TrainConfig(data=str(data), metric="jnyang", out=str(out), arch="fast", steps=2, val_every=2, crop=32)
    lock = ".m.pt.rtp-writer.lock"
    (tmp_path / "models").mkdir()
    with writer_lock(tmp_path / "models", "rtp train", RuntimeError, name=lock, remove=True):
        with pytest.raises(CheckpointError, match=f"^{out} is being written by another training \\(rtp train, pid "
                                                  f"{os.getpid()}\\): wait for it to end, or train into another file"):
            train(cfg)
        assert not out.exists()
        other = out.with_name("other.pt")  # another file beside it: its own lock
        assert train(TrainConfig(**{**vars(cfg), "out": str(other)})) and other.is_file()
    assert train(cfg) and out.is_file()
    assert sorted(f.name for f in out.parent.iterdir()) == ["m.pt", "other.pt"]  # the lock files are gone with their jobs
    with pytest.raises(DatasetError):  # a training that fails before saving leaves no folder it made for its lock
        train(TrainConfig(**{**vars(cfg), "data": str(tmp_path / "nowhere"), "out": str(tmp_path / "a" / "b" / "m.pt")}))
    assert not (tmp_path / "a").exists()


def test_train_takes_a_config_object() -> None:
    with pytest.raises(sdk.ParameterError, match="train: expected a TrainConfig, got dict"):
        train({"data": "d", "metric": "jnyang", "out": "m.pt"})  # type: ignore[arg-type]


def test_validation_that_holds_out_every_scene_is_refused_naming_what_held_them_out(tmp_path: Path) -> None:
    """Every scene of the data held out for validation (by val_scenes, or by val_split on a dataset of
    that split's maps only) left no training sample: an IndexError once the frames were loaded. Now a
    ParameterError naming the field that held them out; nothing is written."""
    data = _dataset(tmp_path / "d", n=6)
    out = tmp_path / "m.pt"
    with pytest.raises(sdk.ParameterError, match=r"^val_scenes: every scene of .* \(scene0, scene1, scene2\) is held "
                                                 r"out for validation; leave at least one to train on$") as e:
        train(TrainConfig(data=str(data), metric="jnyang", out=str(out), crop=32, val_scenes=("scene0", "scene1", "scene2")))
    assert e.value.name == "val_scenes" and not out.exists()
    splits = tmp_path / "splits.yaml"
    splits.write_text(yaml.safe_dump({"train": ["elsewhere"], "validation": ["scene0", "scene1", "scene2"],
                                      "test": ["further"]}))
    with pytest.raises(sdk.ParameterError, match=r"^val_split: every scene of") as e:
        train(TrainConfig(data=str(data), metric="jnyang", out=str(out), crop=32, val_split="validation",
                          splits=str(splits)))
    assert e.value.name == "val_split" and not out.exists()
    with pytest.raises(sdk.ParameterError, match=r"validation scenes \['scene9'\] are not in") as e:
        train(TrainConfig(data=str(data), metric="jnyang", out=str(out), crop=32, val_scenes=("scene9",)))
    assert e.value.name == "val_scenes"


def test_a_validation_scene_named_twice_is_refused(tmp_path: Path) -> None:
    """``--val-scenes scene2,scene1,scene2`` read scene2's samples twice: each validated twice, and the model's
    provenance said val_samples 6 of the 4 held out, val_scenes [scene1, scene2, scene2]. Now a ParameterError
    naming val_scenes, before any sample is read."""
    data = _dataset(tmp_path / "d", n=6)
    out = tmp_path / "m.pt"
    with pytest.raises(sdk.ParameterError, match=r"^val_scenes: expected distinct scene names, got scene2 more than "
                                                 r"once$") as e:
        train(TrainConfig(data=str(data), metric="jnyang", out=str(out), crop=32, batch=2, steps=1,
                          val_scenes=("scene2", "scene1", "scene2")))
    assert e.value.name == "val_scenes" and not out.exists()


def test_the_default_validation_scene_is_the_last_in_natural_order() -> None:
    """Without val_scenes or val_split the last scene is held out: the last by plain name sort was procedural:9 of
    procedural:2, :9 and :10 (":1" sorts before ":9"), so adding a tenth scene to a dataset did not hold it out.
    Numbers in the names are compared as numbers."""
    from types import SimpleNamespace

    from rtp.train._loop import _split_ids

    samples = [SimpleNamespace(id=f"s{i}", meta={"scene": s})
               for i, s in enumerate(["procedural:2", "procedural:10", "procedural:9", "procedural:10"])]
    cfg = TrainConfig(data="d", metric="jnyang", out="m.pt")
    train_ids, val_ids, train_scenes, val_scenes = _split_ids(samples, cfg)  # type: ignore[arg-type]
    assert val_scenes == ["procedural:10"] and val_ids == ["s1", "s3"]
    assert sorted(train_ids) == ["s0", "s2"] and sorted(train_scenes) == ["procedural:2", "procedural:9"]


def test_the_device_is_checked_before_the_data_is_read_and_recorded(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """``--device``: a GPU this torch cannot use is refused, saying why, before a sample is read; ``auto``
    trains on the CPU where torch sees no GPU; the model names the device it trained on, apart from
    the recipe's overrides (it is the machine's). The training on a GPU itself: bench/training_device.py."""
    from rtp.train._loop import resolve_device

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(torch.version, "cuda", None)
    if getattr(torch.backends, "mps", None) is not None:
        monkeypatch.setattr(torch.backends.mps, "is_available", lambda: False)
    assert resolve_device("auto") == torch.device("cpu") and resolve_device("cpu") == torch.device("cpu")
    for bad in ("tpu", "cpu:1", "meta", "", "cuda:x", "CUDA"):
        with pytest.raises(sdk.ParameterError, match=r"device: expected auto, cpu, cuda, mps or cuda:N, got"):
            resolve_device(bad)
    data = _dataset(tmp_path / "ds", n=6)
    out = tmp_path / "m.pt"
    read: list[tuple[int, int]] = []
    with pytest.raises(sdk.ParameterError, match=re.escape(f"device 'cuda': torch {torch.__version__} is a CPU "
                                                           f"build; use device cpu (or auto")):
        train(TrainConfig(data=str(data), metric="jnyang", out=str(out), device="cuda"), loading=lambda k, n: read.append((k, n)))
    assert read == [] and not out.exists()
    with pytest.raises(sdk.ParameterError, match="device 'mps': torch .* cannot use Apple's Metal"):  # (as a recipe is read)
        TrainConfig.from_recipe("shipped", data="nowhere", metric="jnyang", out=str(out), device="mps")
    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(out), "--device", "cuda:1"]) == 2
    assert "device 'cuda:1': torch" in capsys.readouterr().err and not out.exists()
    monkeypatch.setattr(torch.version, "cuda", "13.0")  # a CUDA build on a machine without the driver
    with pytest.raises(sdk.ParameterError, match=r"\(CUDA 13.0\) sees no CUDA device \(the driver, or CUDA_VISIBLE_DEVICES\)"):
        resolve_device("cuda")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    assert resolve_device("cuda") == resolve_device("auto") == torch.device("cuda", 0)
    with pytest.raises(sdk.ParameterError, match=r"device 'cuda:1': torch sees 1 CUDA device \(cuda:0\)"):
        resolve_device("cuda:1")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)

    assert rtp_main(["train", "--data", str(data), "--metric", "jnyang", "--out", str(out), "--steps", "4",
                     "--crop", "32", "--val-scenes", "scene0", "--device", "auto"]) == 0
    prov = load_checkpoint(out).metadata.provenance
    assert prov["device"] == "cpu" and "device" not in prov["recipe"].get("overrides", {})
    assert prov["recipe"]["overrides"]["steps"] == 4  # (the overrides are recorded)


def test_a_step_past_the_gpus_memory_is_refused_and_cuda_trains_deterministically(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, machine_memory: Callable[..., None]) -> None:
    """On a GPU the step's activations live in its memory, the crops in the host's: each is checked
    against its own, before the data is read. While a training runs on CUDA, torch's deterministic
    algorithms are on (a resumed training ends on the same model) and the settings before come back."""
    import types

    from rtp.train import _loop

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    monkeypatch.setattr(torch.cuda, "get_device_name", lambda dev=None: "Some GPU")
    monkeypatch.setattr(torch.cuda, "get_device_properties", lambda dev=None: types.SimpleNamespace(total_memory=2**30))
    cfg = dict(data=str(tmp_path / "nowhere"), metric="jnyang", out=str(tmp_path / "m.pt"), crop=64, device="cuda")
    with pytest.raises(sdk.ParameterError, match=r"^batch: 1000 crops of 64 pixels take about 1\.5 GiB in a training "
                                                 r"step, more than the 1\.0 GiB of cuda:0 \(Some GPU\): lower batch"):
        train(TrainConfig(**cfg, batch=1000))
    machine_memory(MemTotal=2**30, MemAvailable=2**30)  # the host: 500 crops of 4 planes, 0.05 GiB, fit; 20,000 do not
    monkeypatch.setattr(torch.cuda, "get_device_properties", lambda dev=None: types.SimpleNamespace(total_memory=2**50))
    with pytest.raises(sdk.ParameterError, match=r"^batch: 20000 crops of 64 pixels take about 1\.8 GiB in a training "
                                                 r"step \(the crops, cut here for the GPU\), more than this machine's"):
        train(TrainConfig(**cfg, batch=20000))
    with pytest.raises(DatasetError, match="no dataset folder"):  # (fits: on to the data)
        train(TrainConfig(**cfg, batch=500))

    before = (torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark,
              torch.are_deterministic_algorithms_enabled())
    monkeypatch.delenv("CUBLAS_WORKSPACE_CONFIG", raising=False)
    with _loop._deterministic(torch.device("cuda", 0)):
        assert torch.backends.cudnn.deterministic and not torch.backends.cudnn.benchmark
        assert torch.are_deterministic_algorithms_enabled() and torch.is_deterministic_algorithms_warn_only_enabled()
        assert os.environ["CUBLAS_WORKSPACE_CONFIG"] == ":4096:8"
    assert (torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark,
            torch.are_deterministic_algorithms_enabled()) == before and "CUBLAS_WORKSPACE_CONFIG" not in os.environ
    with _loop._deterministic(torch.device("cpu")):  # the CPU's kernels are deterministic already: nothing changes
        assert not torch.are_deterministic_algorithms_enabled()


def test_bench_training_device_times_each_device_from_the_same_seed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """bench/training_device.py trains the recipe on each device asked for and prints a row per device;
    a device this torch cannot use is refused before any run (its GPU rows: docs/training.md)."""
    path, mod = _bench_module("training_device", monkeypatch)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    data = _dataset(tmp_path / "ds", n=6)
    recipe = tmp_path / "r.yaml"
    recipe.write_text("crop: 32\nbatch: 4\nhead: linear\nsteps: 3000\n")
    args = ["--data", str(data), "--config", str(recipe), "--steps", "30", "--warmup", "5"]
    assert mod.main([*args, "--devices", "cpu,cpu"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith(f"| cpu, {torch.get_num_threads()} threads |")]
    assert len(rows) == 2 and "the recipe's 3,000 steps (min)" in out, out
    # the same seed on the same device: the same training, to the last digit of the validation score
    assert rows[0].split("|")[6] == rows[1].split("|")[6] and " 1.0x " in rows[0]
    monkeypatch.setattr(torch.version, "cuda", None)
    with pytest.raises(sdk.ParameterError, match="device 'cuda': torch .* is a CPU build"):
        mod.main([*args, "--devices", "cpu,cuda"])
    assert "| cpu" not in capsys.readouterr().out  # (refused before the CPU's run)
    with pytest.raises(SystemExit):
        mod.main([*args[:4], "--steps", "5", "--warmup", "5"])
    assert "--steps 5 leaves no step to time after --warmup 5" in capsys.readouterr().err


def test_bench_hardware_tiles_compares_models_on_one_tile_size(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """bench/hardware_tiles.py: a perfect estimate never fails at the judging threshold and a coarser decision
    saves more; end to end, a 16-pixel model read on 8-pixel tiles, a row per model with savings that rise with
    the failing share, its default's share, and the threshold that fails on a share asked for."""
    import subprocess
    import sys

    path, mod = _bench_module("hardware_tiles", monkeypatch)
    rng = np.random.default_rng(4)
    truth = np.sort(rng.random((6, 500)) * 0.5, axis=0)
    fail, saved = mod.outcome(truth, truth, 0.25, 0.25, None)
    assert fail == 0.0 and 0.0 < saved < 0.9375
    fail2, saved2 = mod.outcome(truth * 0.5, truth, 0.25, 0.25, None)  # underestimates: more saved, tiles fail
    assert fail2 > 0.0 and saved2 > saved
    data = _dataset(tmp_path / "ds", n=6)
    train(TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), steps=10, crop=32,
                      val_scenes=("scene0",), loss="mse"))
    model = export.export_checkpoint(tmp_path / "m.pt", tmp_path / "m.onnx")
    out = subprocess.run([sys.executable, str(path), str(model), str(model), "--data", str(data), "--scene",
                          "scene0,scene1", "--tile-size", "8", "--fail-share", "0.05"],
                         capture_output=True, text=True, check=True).stdout
    assert "jnyang on 8-pixel tiles: 4 samples" in out
    rows = [line.split("|") for line in out.splitlines() if line.startswith(f"| {model}")]
    assert len(rows) == 2 and rows[0] == rows[1] and rows[0][2].strip() == "16"
    # ("-": the sweep never fails that rarely; ">=": never that often, its best saving a lower bound)
    v = [float(x.strip().removeprefix(">= ")) if x.strip() != "-" else None for x in rows[0][3].split("/")]
    got = [x for x in v if x is not None]
    assert got == sorted(got) and all(0.0 <= x <= 93.75 for x in got), out
    # the threshold failing on 5% of the tiles, or, where the sweep of this 10-step model never fails that often, the
    # shares it covers (the loosest threshold, 4x, was printed as if it failed on 5%)
    cell = rows[0][5].strip()
    assert cell.startswith("- (the sweep fails on ") or float(cell) > 0.0, out
    bad = subprocess.run([sys.executable, str(path), "psnr", "jnyang", "--data", str(data)], capture_output=True,
                         text=True)
    assert bad.returncode == 2 and "expected models of one metric, got jnyang, psnr" in bad.stderr
    # PSNR (higher is better): a perfect estimate never fails, one 3 dB too hopeful saves more and fails; the
    # sweep's factors are dB off the judging threshold (a factor on the error's amplitude)
    db = 50.0 - 40.0 * truth
    fail, saved = mod.outcome(db, db, 35.0, 35.0, None, True)
    assert fail == 0.0 and 0.0 < saved < 0.9375
    fail2, saved2 = mod.outcome(db + 3.0, db, 35.0, 35.0, None, True)
    assert fail2 > 0.0 and saved2 > saved
    assert mod.decision(35.0, 0.1, True) == pytest.approx(55.0) and mod.decision(0.2, 0.5, False) == 0.1
    store = TargetStore(data)
    store.declare("psnr", {})
    for sid in DatasetReader(data).ids:
        # (stored as the tile MSE, as rtp targets stores PSNR: a dB value written there read as a negative MSE)
        store.write(sid, "psnr", sdk.mse_from_psnr(50.0 - 40.0 * store.load(sid, "jnyang", 4)).astype(np.float32),
                    (H, W))
    out = subprocess.run([sys.executable, str(path), "psnr", "psnr-8px", "--data", str(data), "--scene",
                          "scene0,scene1", "--tile-size", "8", "--fail-share", "0.05"],
                         capture_output=True, text=True, check=True).stdout
    assert "psnr on 8-pixel tiles: 4 samples" in out and "a tile failing under 35" in out
    rows = {line.split("|")[1].strip(): line.split("|") for line in out.splitlines() if line.startswith("| psnr")}
    assert set(rows) == {"psnr", "psnr-8px"} and [rows[n][2].strip() for n in ("psnr", "psnr-8px")] == ["16", "8"]
    for row in rows.values():
        got = [float(x.strip().removeprefix(">= ")) for x in row[3].split("/") if x.strip() != "-"]
        assert got == sorted(got) and all(0.0 <= x <= 93.75 for x in got)
        assert 35.0 - 20.0 * np.log10(4.0) <= float(row[5]) <= 35.0 - 20.0 * np.log10(0.05)  # dB inside the sweep


def test_a_damaged_training_state_is_a_checkpoint_error_naming_the_file(tmp_path: Path) -> None:
    """Resuming from a checkpoint whose training state was damaged or edited raised KeyError, RuntimeError,
    JSONDecodeError or TypeError from inside torch; a checkpoint with no training state said it was trained with
    another configuration, and one past this run's steps was taken as done. Each is named now."""
    from rtp.train import checkpoint

    data = _dataset(tmp_path / "ds", n=6)
    cfg = dict(data=str(data), metric="jnyang", crop=32, batch=4, val_every=5, save_every=5, head="linear")
    out = tmp_path / "m.pt"
    train(TrainConfig(out=str(out), steps=5, **cfg))
    good = load_checkpoint(out)
    assert good.training is not None
    damaged = {"no generator": {k: v for k, v in good.training.items() if k != "generator"},
               "a wrong generator": {**good.training, "generator": torch.zeros(3, dtype=torch.uint8)},
               "history not JSON": {**good.training, "history": "not json"},
               "no optimizer state": {**good.training, "optimizer": {}},
               "a step that is no number": {**good.training, "step": "abc"},
               "a negative step": {**good.training, "step": -5},
               # (AttributeError and ValueError from the lines that read them, outside the check)
               "history entries that are no mappings": {**good.training, "history": "[1, 2]"},
               "a config that is no mapping": {**good.training, "config": ["data"]}}
    for why, state in damaged.items():
        path = checkpoint.save(tmp_path / "bad.pt", good.net, good.metadata, state)
        with pytest.raises(checkpoint.CheckpointError, match=r"bad\.pt: its training state cannot be resumed") as info:
            train(TrainConfig(out=str(path), steps=10, **cfg))
        assert sdk.exit_code(info.value) == sdk.EXIT_USAGE, why
    # (read for the progress bar's first value: a ValueError once the command line's bar asked for it)
    path = checkpoint.save(tmp_path / "bad.pt", good.net, good.metadata,
                           {**good.training, "history": '[{"step": 5, "train_loss": "low"}]'})
    with pytest.raises(checkpoint.CheckpointError, match=r"bad\.pt: its training state cannot be resumed \(ValueError"):
        train(TrainConfig(out=str(path), steps=10, **cfg), progress=lambda step, steps, loss: None)
    path = checkpoint.save(tmp_path / "bare.pt", good.net, good.metadata)
    with pytest.raises(checkpoint.CheckpointError, match="bare.pt exists and holds a model without its training state"):
        train(TrainConfig(out=str(path), steps=10, **cfg))
    with pytest.raises(sdk.ParameterError, match=r"steps: .*m\.pt holds step 5, past this run's 3: give --steps 5"):
        train(TrainConfig(out=str(out), steps=3, **cfg))


def test_batchnorm_statistics_gone_non_finite_stop_the_training_at_their_step(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """BatchNorm's running statistics gone infinite (a large learning rate) leave a training-mode loss finite: the
    training went on to its next save, which refused them naming its own step (4), not the one they went at (3)."""
    from torch.nn.modules.batchnorm import _BatchNorm

    from rtp.train import TrainingDivergedError

    data = _dataset(tmp_path / "ds", n=6)
    real_step, real_forward, seen, done = torch.optim.RMSprop.step, _BatchNorm.forward, [], [0]

    def poisoned(self: torch.optim.Optimizer, *args: Any, **kwargs: Any) -> Any:
        result = real_step(self, *args, **kwargs)
        done[0] += 1
        if done[0] == 3:  # (step 3's update: a BatchNorm layer's running variance goes infinite with it)
            seen[-1].running_var.fill_(float("inf"))
        return result

    def kept(self: _BatchNorm, x: torch.Tensor) -> torch.Tensor:
        if self.training:  # (the network trained, not its validation copy)
            seen.append(self)
        return real_forward(self, x)

    monkeypatch.setattr(torch.optim.RMSprop, "step", poisoned)
    monkeypatch.setattr(_BatchNorm, "forward", kept)
    cfg = TrainConfig(data=str(data), metric="jnyang", out=str(tmp_path / "m.pt"), steps=8, crop=32, batch=2,
                      val_every=100, save_every=4, val_scenes=("scene0",))
    with pytest.raises(TrainingDivergedError, match=r"the weights \(.*running_var\) are not finite at step 3, "
                                                    r"with learning rate .*; no checkpoint was written"):
        train(cfg)
    assert done[0] == 3 and not (tmp_path / "m.pt").exists()
