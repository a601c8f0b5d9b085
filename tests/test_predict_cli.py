"""rtp predict: one frame of an engine's G-buffers (an .npz named as sdk.input_planes' arguments) to the
model's predictions, rates and overlay; --write-example writes such a frame from the reference renderer."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from rtp import sdk
from rtp.cli import main

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def frame(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("predict") / "frame.npz"
    assert main(["predict", str(path), "--write-example", "--size", "160x96", "--seed", "2"]) == 0
    return path


def test_the_example_holds_every_gbuffer_in_the_layout(frame: Path) -> None:
    with np.load(frame) as npz:
        arrays = dict(npz)
    assert set(arrays) == {*sdk.GBUFFERS, "colour"} - {"prev_projection"}  # (for a window depth whose projection changed)
    for name, (shape, _) in sdk.GBUFFERS.items():
        if name not in arrays:
            continue
        want = (4, 4) if shape == "4x4" else (96, 160, 3) if shape.endswith(", 3)") else (96, 160)
        assert arrays[name].shape == want, name
    assert 0.0 < float((arrays["depth"] > 0).mean()) <= 1.0 and arrays["prev_colour"].max() <= 1.0


@pytest.mark.parametrize("model", ["jnyang", "lpips", "psnr-8px"])
def test_predict_gives_the_sdks_rates(frame: Path, model: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["predict", str(frame), "--model", model, "--out", str(out), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    predictor = sdk.load(model)
    with np.load(frame) as npz:
        x = sdk.input_planes(predictor.metadata.inputs, **{k: npz[k] for k in npz.files if k in sdk.GBUFFERS})
    rates = predictor.shading_rates(x)
    np.testing.assert_array_equal(np.load(out / "rates.npy"), rates)
    np.testing.assert_array_equal(np.load(out / "predictions.npy"), predictor.predict(x))
    assert got["tiles"] == list(rates.shape) and sum(got["rates"].values()) == rates.size
    assert got["work_saved"] == pytest.approx(sdk.work_saved(rates, (96, 160), predictor.tile_size))
    assert got["threshold"] == predictor.metadata.default_threshold and got["wrote"][-1] == "overlay.png"
    assert len(got["rates"]) > 1  # the decisions are mixed
    from PIL import Image

    assert Image.open(out / "overlay.png").size == (160, 96)


def test_options_reach_the_decision(frame: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", str(frame), "--tile-size", "8", "--allowed", "1x2,2x1,2x2", "--threshold", "0.4",
                 "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["tile_size"] == 8 and got["tiles"] == [12, 20] and got["threshold"] == 0.4
    assert set(got["rates"]) <= {"1x1", "1x2", "2x1", "2x2"}
    assert main(["predict", str(frame)]) == 0
    text = capsys.readouterr().out
    assert "jnyang.onnx (jnyang) on" in text and "10x6 tiles of 16px" in text and "% of the shading work" in text


def test_a_frame_that_is_not_what_it_should_be_is_named(frame: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str],
                                                       caplog: pytest.LogCaptureFixture) -> None:
    with np.load(frame) as npz:
        arrays = dict(npz)
    typo = tmp_path / "typo.npz"
    np.savez(typo, **{("normals" if k == "normal" else k): v for k, v in arrays.items()})
    with caplog.at_level(logging.WARNING, logger="rtp.cli"):
        assert main(["predict", str(typo)]) == 2
    assert "'normals' is not a G-buffer and is not read (did you mean normal?)" in caplog.text
    assert "has no 'normal' array, which jnyang.onnx reads: normal (H, W, 3)" in capsys.readouterr().err
    assert main(["predict", str(typo), "--model", "psnr", "--json"]) == 2  # PSNR reads normal.z too
    hdr = tmp_path / "hdr.npz"
    np.savez(hdr, **{**arrays, "prev_colour": arrays["prev_colour"] * 4.0})
    assert main(["predict", str(hdr)]) == 2
    assert "prev_colour: expected values in [0, 1]" in capsys.readouterr().err
    text = tmp_path / "frame.txt"
    text.write_text("depth 1 2 3")
    assert main(["predict", str(text)]) == 2
    assert "not an .npz" in capsys.readouterr().err
    assert main(["predict", str(tmp_path / "none.npz")]) == 2
    assert "--write-example" in capsys.readouterr().err


def test_an_engines_conventions_by_flag(frame: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A linear albedo, world-space normals and a depth buffer's window depth, said by --albedo-linear,
    --normal-space world and --depth-kind window: the rates of the frame in rtp's conventions."""
    with np.load(frame) as npz:
        a = dict(npz)
    proj = a["projection"]

    def window(depth: np.ndarray) -> np.ndarray:
        z = -depth.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc = (proj[2, 2] * z + proj[2, 3]) / (proj[3, 2] * z + proj[3, 3])
        return np.where(depth > 0, (ndc + 1.0) / 2.0, 1.0).astype(np.float32)

    engine = tmp_path / "engine.npz"
    np.savez(engine, **{**a, "albedo": sdk.srgb_to_linear(a["albedo"]).astype(np.float32),
                        "normal": a["normal"] @ a["view"][:3, :3], "depth": window(a["depth"]),
                        "prev_depth": window(a["prev_depth"])})
    assert main(["predict", str(frame), "--out", str(tmp_path / "rtp")]) == 0
    assert main(["predict", str(engine), "--out", str(tmp_path / "engine"), "--albedo-linear", "--normal-space",
                 "world", "--depth-kind", "window"]) == 0
    capsys.readouterr()
    ours, theirs = np.load(tmp_path / "rtp" / "rates.npy"), np.load(tmp_path / "engine" / "rates.npy")
    assert (ours == theirs).mean() > 0.95, (ours == theirs).mean()
