"""The whole toolchain on a tiny rendered dataset: capture -> targets -> train -> export -> sdk.load."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from rtp import export, sdk
from rtp.capture import DatasetReader, TargetStore, capture
from rtp.cli import main as rtp_main
from rtp.train import TrainConfig, train
from rtp.train.checkpoint import load as load_checkpoint

pytestmark = [pytest.mark.gl, pytest.mark.slow]


def test_capture_targets_train_export(tmp_path: Path) -> None:
    data = tmp_path / "ds"
    capture(["procedural:11", "procedural:12", "procedural:13"], data, per_scene=2, size=(128, 96))
    assert rtp_main(["targets", str(data), "--metrics", "jnyang,psnr"]) == 0
    store = TargetStore(data)
    ids = DatasetReader(data).ids
    assert len(ids) == 12 and all(store.has(i, "jnyang") and store.has(i, "psnr") for i in ids)
    jn = store.load(ids[0], "jnyang", 16)
    assert jn.shape == (6, 6, 8) and np.all(jn >= 0)
    assert rtp_main(["targets", str(data), "--metrics", "jnyang"]) == 0  # cached: nothing recomputed

    out = tmp_path / "m.pt"
    result = train(TrainConfig(data=str(data), metric="jnyang", out=str(out), steps=200, crop=64, batch=4,
                               val_every=50, lr=3e-4))
    history = json.loads(load_checkpoint(out).training["history"])
    assert history[0]["step"] == 0  # the untrained network
    assert history[-1]["val"]["mae"] < 0.9 * history[0]["val"]["mae"]
    assert result.safety >= 0

    onnx_path = export.export_checkpoint(out, tmp_path / "m.onnx")
    pred = sdk.load(onnx_path)
    sample = DatasetReader(data)[ids[0]]
    x = sample.inputs(pred.metadata.inputs)
    net = load_checkpoint(out).net
    with torch.inference_mode():
        raw = net(torch.from_numpy(x)[None])[0].numpy()
    np.testing.assert_allclose(pred.predict_raw(x), raw, atol=1e-5)
    rates = pred.shading_rates(x)
    assert rates.shape == (6, 8) and set(np.unique(rates)) <= set(sdk.RATE_CODES.values())
