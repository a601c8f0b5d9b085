"""rtp demo, with a model given by path (the shipped ones are tested where they ship)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from rtp.cli import main as rtp_main

pytestmark = pytest.mark.gl


def test_demo_writes_its_pictures_and_reports(tiny_model: Callable[..., Path], tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert rtp_main(["demo", "--model", str(tiny_model()), "--size", "160x96", "--out", str(out),
                     "--threshold", "0.3"]) == 0
    text = capsys.readouterr().out
    for key in ("work saved", "beyond the threshold", "predict", "FLIP"):
        assert key in text
    for name in ("frame.png", "overlay.png", "predicted_vs_true.png", "vrs_composite.png", "vrs_flip.png"):
        assert (out / name).stat().st_size > 0


def test_demo_of_a_foreign_model_with_its_sidecar(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A model that carries no rtp metadata was refused with a hint to pass "the commands' --metadata SIDECAR.yaml",
    which rtp demo did not take: it takes the sidecar, and the hint is in its flags; nothing is written without."""
    import numpy as np
    import yaml

    from .conftest import base_metadata, build_onnx

    model = build_onnx(tmp_path / "foreign.onnx", weights=np.eye(4, dtype=np.float32), metadata=None)
    sidecar = tmp_path / "foreign.yaml"
    sidecar.write_text(yaml.safe_dump(base_metadata()))
    out = tmp_path / "demo"
    assert rtp_main(["demo", "--model", str(model), "--size", "160x96", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "carries no rtp metadata: pass --metadata SIDECAR.yaml" in err and "metadata=" not in err, err
    assert not out.exists()
    assert rtp_main(["demo", "--model", str(model), "--metadata", str(sidecar), "--size", "160x96", "--out",
                     str(out)]) == 0
    assert "foreign.onnx (jnyang), threshold 0.2" in capsys.readouterr().out and (out / "overlay.png").is_file()


def test_demo_without_a_model_says_what_ships(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert rtp_main(["demo", "--model", "no_such_model", "--out", str(tmp_path / "d")]) == 2
    assert "no model file" in capsys.readouterr().err


def test_a_demo_of_more_frames_than_a_path_may_have_is_refused_before_loading(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--frames 1000000000` rendered the camera move frame by frame, for days, without a word."""
    assert rtp_main(["demo", "--model", "no_such_model", "--frames", "36001", "--out", str(tmp_path / "d")]) == 2
    assert capsys.readouterr().err.strip() == ("rtp demo: error: --frames: expected an integer in [2, 36000] (the frame "
                                               "shown and at least the one before it, its history), got 36001")
    assert not (tmp_path / "d").exists()
    # one frame was taken and run as two (the same pictures, byte for byte): refused
    assert rtp_main(["demo", "--frames", "1", "--out", str(tmp_path / "d")]) == 2
    assert "--frames: expected an integer in [2, 36000]" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_demo_on_8_pixel_hardware_tiles_shades_the_same_frame(tmp_path: Path) -> None:
    """``--tile-size 8`` (AMD's and Intel's VRS) with the shipped 16-pixel JNYang: each 8-pixel tile takes its model
    tile's rate, so the composite, its FLIP and the work saved are the 16-pixel run's, while the rates, the true
    error and the failing share are per 8-pixel tile (20 x 12 of them at 160x96); a tile size the model cannot
    run on is refused before anything renders."""
    import numpy as np
    from PIL import Image

    from rtp import sdk
    from rtp.cli._demo import run_demo

    own = run_demo(tmp_path / "d16", size=(160, 96), frames=2, timing_runs=1)
    fine = run_demo(tmp_path / "d8", size=(160, 96), frames=2, timing_runs=1, tile_size=8)
    assert (own.tiles, own.tile_size, fine.tiles, fine.tile_size) == (60, 16, 240, 8)
    assert fine.work_saved == own.work_saved and fine.composite_flip_mean == own.composite_flip_mean
    assert fine.over_threshold != own.over_threshold
    for name in ("vrs_composite.png", "frame.png"):
        assert np.array_equal(np.asarray(Image.open(tmp_path / "d8" / name)), np.asarray(Image.open(tmp_path / "d16" / name)))
    with pytest.raises(sdk.ParameterError, match="tile_size"):
        run_demo(tmp_path / "bad", size=(160, 96), tile_size=12)
    assert not (tmp_path / "bad").exists()


def test_the_demos_camera_turns_the_short_way_across_the_yaw_wrap() -> None:
    """The sampler wraps yaws to [-180, 180): seed 100's pair is -175 and 170.5 degrees, 14.5 apart, and the camera
    move turned 345.5 degrees the long way, so the shown frame's history (its middle frame) looked the other way
    and every pixel of the frame was unseen (about one seed in forty). Each frame now turns the short way."""
    import math

    import numpy as np

    from rtp.capture import load_scene
    from rtp.capture.viewpoints import sample_viewpoints
    from rtp.cli._demo import _camera_path
    from rtp.plugins.moderngl import Renderer

    scene, blockers = load_scene("procedural:0", None, None, None)
    prev, cur = sample_viewpoints(scene, 1, 100, "fast", blockers=blockers, aspect=160 / 96)[0]
    assert abs(cur.yaw - prev.yaw) > 180  # (the pair this test is about: across the wrap)
    cams = _camera_path(scene, 3, blockers, 160 / 96, 100)
    turn = (cur.yaw - prev.yaw + 180) % 360 - 180
    for a, b in zip(cams, cams[1:]):
        assert abs((b.yaw - a.yaw) - turn / 2) < 1e-9
    assert math.isclose(math.cos(math.radians(cams[-1].yaw)), math.cos(math.radians(cur.yaw)), abs_tol=1e-9)
    assert math.isclose(math.sin(math.radians(cams[-1].yaw)), math.sin(math.radians(cur.yaw)), abs_tol=1e-9)
    with Renderer(160, 96) as renderer:
        renderer.load_scene(scene)
        frame = renderer.render(cams[2], renderer.render(cams[1], renderer.render(cams[0], None)))
    assert float(np.mean(frame.seen)) > 0.5  # (was 0.0)


def test_a_demo_that_fails_drawing_its_pictures_leaves_the_last_runs_whole(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """The pictures were drawn between the writes: a failure (or Ctrl-C) drawing the FLIP figure left this run's frame,
    overlay, heatmaps and composite beside the previous run's FLIP picture, of another model or scene. Every picture
    is now drawn before the first is written."""
    from rtp.cli._demo import run_demo
    from rtp.evaluate import plots

    names = ("frame.png", "overlay.png", "predicted_vs_true.png", "vrs_composite.png", "vrs_flip.png")
    out = tmp_path / "demo"
    out.mkdir()
    for name in names:
        (out / name).write_bytes(b"the previous run's")

    def fails(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(plots, "value_map", fails)
    with pytest.raises(KeyboardInterrupt):
        run_demo(out, size=(64, 48), frames=2, timing_runs=1)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == dict.fromkeys(names, b"the previous run's")


def test_demo_of_a_model_whose_plugin_metric_is_not_installed_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A model of a plugin metric (``absdiff``, its metadata recording the plugin's definition) where no plugin of
    that name is installed: the demo said "unknown metric 'absdiff'", as of a mistyped name. It names the model, says
    the metric is a plugin's that is not installed and the entry-point group to declare it in; nothing is written."""
    import numpy as np

    from rtp import metrics

    from .conftest import base_metadata, build_onnx

    assert "absdiff" not in metrics.known_metrics()  # (no such plugin here: the situation under test)
    meta = base_metadata(metric="absdiff", higher_is_better=False, weber_l=None, default_threshold=0.05,
                         transform={"type": "clamped", "mu_y": 0.05},
                         provenance={"target_parameters": {"plugin": {"version": 1}, "pooling": "max"}})
    model = build_onnx(tmp_path / "absdiff.onnx", weights=np.zeros((4, 4), np.float32), metadata=meta)
    out = tmp_path / "demo"
    assert rtp_main(["demo", "--model", str(model), "--size", "160x96", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert ("absdiff.onnx: the model's metric 'absdiff' is a plugin metric, not one of rtp's own (flip, jnflip, psnr, "
            "lpips, yang, jnyang), and no plugin of that name is installed here (the model was trained on its targets "
            "as defined by {'version': 1})") in err, err
    assert "in the 'rtp.metrics' entry-point group" in err and "unknown metric" not in err
    assert not out.exists()


@pytest.mark.slow
def test_the_demo_figures_results_md_quotes_for_the_shipped_files_are_what_it_prints(tmp_path: Path) -> None:
    """docs/results.md "The demo" quotes what `rtp demo` prints at its defaults (1280x720, procedural:0, seed 0) for
    the shipped JNYang, for it on 8-pixel tiles, and for `jnyang-8px`: work saved, the share over the threshold and
    the composite's mean FLIP. Its `jnyang-8px` figures (89.8%, 6.1%, 0.0665) were of the file before the one shipped
    on 2026-12-06 (the frame read at 8 channels), which prints 89.4%, 5.6% and 0.0649. The last figures the section
    quotes for each run are the demo's with the shipped files, to the digit it prints."""
    import re

    from rtp.cli._demo import run_demo

    text = (Path(__file__).resolve().parents[1] / "docs" / "results.md").read_text(encoding="utf-8")
    section = " ".join(text[text.index("\n## The demo\n"):text.index("\n## Where the open issues stand")].split())
    quoted = {
        ("jnyang", None): r"it printed: ([\d.]+)% of the shading work saved, ([\d.]+)% of the tiles over the threshold "
                          r"at their chosen rate, mean FLIP ([\d.]+)",
        ("jnyang", 8): r"`rtp demo --tile-size 8` \(the 16-pixel model, split\) ([\d.]+)%, ([\d.]+)%, ([\d.]+)",
        ("jnyang-8px", None): r"`rtp demo --model jnyang-8px` ([\d.]+)%, ([\d.]+)%, ([\d.]+)",
    }
    for (model, tile_size), pattern in quoted.items():
        found = re.findall(pattern, section)
        assert found, (model, tile_size)
        # (the first "it printed" is the shipped JNYang's; older models' follow it. For the others the latest quoted)
        figures = found[0] if model == "jnyang" and tile_size is None else found[-1]
        r = run_demo(tmp_path / f"{model}-{tile_size}", model=model, tile_size=tile_size, timing_runs=1)
        printed = (f"{100 * r.work_saved:.1f}", f"{100 * r.over_threshold:.1f}", f"{r.composite_flip_mean:.4f}")
        assert figures == printed, (model, tile_size, figures, printed)


def test_demo_draws_its_overlay_in_the_palette_asked_for(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """`rtp demo --palette cvd` hands the palette to run_demo (the paper's by default), and run_demo refuses an unknown
    one before it loads a model or renders (an unknown model name here would be its error otherwise)."""
    from rtp import sdk
    from rtp.cli import _demo

    got: list[str] = []

    def fake(out: object, **kw: object) -> None:
        got.append(str(kw["palette"]))
        raise sdk.ParameterError("stop")

    monkeypatch.setattr(_demo, "run_demo", fake)
    assert rtp_main(["demo", "--out", str(tmp_path / "a"), "--palette", "cvd"]) == 2
    assert rtp_main(["demo", "--out", str(tmp_path / "b")]) == 2
    assert got == ["cvd", "paper"]
    monkeypatch.undo()
    with pytest.raises(sdk.ParameterError, match="palette: expected one of 'paper', 'cvd'"):
        _demo.run_demo(tmp_path / "c", model="no-such-model", palette="grey")
    assert not (tmp_path / "c").exists()
