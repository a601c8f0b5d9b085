"""rtp predict: one frame of an engine's G-buffers (an .npz named as sdk.input_planes' arguments) to the
model's predictions, rates and overlay; --write-example writes such a frame from the reference renderer."""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.cli import main

pytestmark = pytest.mark.gl


def _example(tmp_path_factory: pytest.TempPathFactory, name: str, *options: str) -> Path:
    """`rtp predict NAME --write-example` at 160x96 with ``options``: a frame file, or with --frames a folder."""
    path = tmp_path_factory.mktemp("predict") / name
    assert main(["predict", str(path), "--write-example", "--size", "160x96", *options]) == 0
    return path


@pytest.fixture(scope="module")
def frame(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _example(tmp_path_factory, "frame.npz", "--seed", "2")


def test_the_example_holds_every_gbuffer_in_the_layout(frame: Path) -> None:
    with np.load(frame) as npz:
        arrays = dict(npz)
    assert set(arrays) == {*sdk.GBUFFERS, "colour"} - {"prev_projection"}  # (for a window depth whose projection changed)
    for name, (shape, _) in sdk.GBUFFERS.items():
        if name not in arrays:
            continue
        want = (4, 4) if shape == "4x4" else (96, 160, int(shape[-2])) if shape.endswith((", 3)", ", 2)")) else (96, 160)
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


def test_a_rate_allowed_twice_is_refused(frame: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--allowed 2x2,2x2` ran as `--allowed 2x2` in silence (a typo of another rate, likely); each rate is
    taken once, and a space after a comma is no part of a name."""
    for allowed in ("2x2,2x2", "1x2,2x2, 2x2", "4x4,1x2,4x4,1x2"):
        assert main(["predict", str(frame), "--allowed", allowed, "--json"]) == 2, allowed
        err = capsys.readouterr().err
        assert "rtp predict: error: --allowed: each rate once, got " in err and repr(allowed) in err, err
    assert "got 4x4, 1x2 more than once in" in err
    assert main(["predict", str(frame), "--allowed", "1x2, 2x2", "--json"]) == 0
    assert set(json.loads(capsys.readouterr().out)["rates"]) <= {"1x1", "1x2", "2x2"}


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
    assert main(["predict", str(frame), "--depth-kind", "window"]) == 2  # linear depth read as a depth buffer's
    err = capsys.readouterr().err
    assert "depth: expected values in [0, 1] (a hardware depth buffer's values" in err, err
    assert "--depth-kind linear for linear view depth" in err and "depth_kind=" not in err, err
    text = tmp_path / "frame.txt"
    text.write_text("depth 1 2 3")
    assert main(["predict", str(text)]) == 2
    assert "not an .npz" in capsys.readouterr().err
    assert main(["predict", str(tmp_path / "none.npz")]) == 2
    assert "--write-example" in capsys.readouterr().err
    # a deflate stream damaged past the arrays' headers: zlib's raw error and a traceback (exit 1) before
    import zipfile

    with zipfile.ZipFile(frame) as z:
        info = z.getinfo("albedo.npy")
    data = bytearray(frame.read_bytes())
    off = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra) + 16
    data[off:off + 64] = bytes(b ^ 0xFF for b in data[off:off + 64])
    damaged = tmp_path / "damaged.npz"
    damaged.write_bytes(bytes(data))
    assert main(["predict", str(damaged)]) == 2
    assert f"{str(damaged)!r}: a damaged .npz, numpy cannot read its arrays" in capsys.readouterr().err


def test_a_frame_of_rtp_import_is_read_without_a_warning(frame: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str],
                                                         caplog: pytest.LogCaptureFixture) -> None:
    """A frame of `rtp import` (what `rtp import --write-example` writes, "the .npz `rtp predict` reads" plus the frame
    shaded at every rate) gave `rtp predict` a warning for each final_<rate>, "is not a G-buffer and is not read",
    seven a frame. They are known and left out now; the rates are those of the frame without them, and an array of
    another name is still named."""
    with np.load(frame) as npz:
        arrays = dict(npz)
    imported = tmp_path / "imported.npz"
    finals = {f"final_{r}": np.zeros((96, 160, 3), np.uint8) for r in sdk.ALL_RATES}
    np.savez(imported, **arrays, **finals)
    assert main(["predict", str(frame), "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)
    with caplog.at_level(logging.WARNING):
        assert main(["predict", str(imported), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rates"] == plain["rates"]
    assert "is not a G-buffer" not in caplog.text, caplog.text
    np.savez(imported, **arrays, final_3x3=finals["final_1x1"])
    with caplog.at_level(logging.WARNING):
        assert main(["predict", str(imported), "--json"]) == 0
    assert "'final_3x3' is not a G-buffer and is not read" in caplog.text


@pytest.mark.parametrize("kind", ["window", "reversed"])
def test_an_engines_conventions_by_flag(frame: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                        kind: str) -> None:
    """A linear albedo, world-space normals and a depth buffer's window (or reversed-Z) depth, said by
    --albedo-linear, --normal-space world and --depth-kind: the rates of the frame in rtp's conventions."""
    with np.load(frame) as npz:
        a = dict(npz)
    proj = a["projection"]

    def window(depth: np.ndarray) -> np.ndarray:
        z = -depth.astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc = (proj[2, 2] * z + proj[2, 3]) / (proj[3, 2] * z + proj[3, 3])
        standard = np.where(depth > 0, (ndc + 1.0) / 2.0, 1.0)
        return (1.0 - standard if kind == "reversed" else standard).astype(np.float32)

    engine = tmp_path / "engine.npz"
    np.savez(engine, **{**a, "albedo": sdk.srgb_to_linear(a["albedo"]).astype(np.float32),
                        "normal": a["normal"] @ a["view"][:3, :3], "depth": window(a["depth"]),
                        "prev_depth": window(a["prev_depth"])})
    assert main(["predict", str(frame), "--out", str(tmp_path / "rtp")]) == 0
    assert main(["predict", str(engine), "--out", str(tmp_path / "engine"), "--albedo-linear", "--normal-space",
                 "world", "--depth-kind", kind]) == 0
    capsys.readouterr()
    ours, theirs = np.load(tmp_path / "rtp" / "rates.npy"), np.load(tmp_path / "engine" / "rates.npy")
    assert (ours == theirs).mean() > 0.95, (ours == theirs).mean()


# -- a sequence of frames ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _example(tmp_path_factory, "frames", "--frames", "4")


def test_a_written_sequence_is_an_engines_dump_of_consecutive_frames(sequence: Path) -> None:
    """Each frame's prev_colour and prev_depth are the frame before's colour and depth, and its previous
    view-projection that frame's camera: what an engine dumping its frames writes."""
    files = sorted(sequence.glob("*.npz"))
    assert [f.name for f in files] == [f"frame_{i:04d}.npz" for i in range(4)]
    frames = [dict(np.load(f)) for f in files]
    for before, after in zip(frames, frames[1:]):
        np.testing.assert_array_equal(after["prev_colour"], before["colour"])
        np.testing.assert_array_equal(after["prev_depth"], before["depth"])
        np.testing.assert_allclose(after["prev_view_projection"], before["projection"] @ before["view"], atol=1e-6)
        assert not np.array_equal(after["view"], before["view"])  # the camera moves


def test_a_sequence_gives_each_frames_rates_and_the_changes_between_them(
        sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A folder of frames: each frame's rates are those of `rtp predict` on it alone, stacked; `changed` is the
    share of tiles whose rate differs from the frame before; frames.csv, overlay.gif (a frame each) and
    frames.png are written."""
    out = tmp_path / "out"
    assert main(["predict", str(sequence), "--out", str(out), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    rates, values = np.load(out / "rates.npy"), np.load(out / "predictions.npy")
    assert rates.shape[0] == values.shape[0] == 4 and values.shape[1] == 6
    for i, f in enumerate(sorted(sequence.glob("*.npz"))):
        assert main(["predict", str(f), "--out", str(tmp_path / f"one{i}"), "--json"]) == 0
        one = json.loads(capsys.readouterr().out)
        np.testing.assert_array_equal(rates[i], np.load(tmp_path / f"one{i}" / "rates.npy"))
        np.testing.assert_array_equal(values[i], np.load(tmp_path / f"one{i}" / "predictions.npy"))
        row = got["frames"][i]
        assert row["frame"] == str(f) and row["work_saved"] == pytest.approx(one["work_saved"])
        assert row["rates"] == one["rates"]
        assert row["changed"] == (None if i == 0 else pytest.approx(float((rates[i] != rates[i - 1]).mean())))
    changes = [r["changed"] for r in got["frames"][1:]]
    assert 0.0 < min(changes) and max(changes) < 1.0
    assert got["changed"] == pytest.approx(np.mean(changes))
    assert got["work_saved"] == pytest.approx(np.mean([r["work_saved"] for r in got["frames"]]))
    assert got["wrote"] == ["rates.npy", "predictions.npy", "frames.csv", "overlay.gif", "frames.png"]
    lines = (out / "frames.csv").read_text().splitlines()
    assert lines[0] == "frame,work_saved,changed,predict_ms,network,threshold," + ",".join(sdk.RATE_CODES)
    assert len(lines) == 5 and {row.split(",")[5] for row in lines[1:]} == {"0.25"}  # (a threshold held)
    assert lines[1].split(",")[2] == "" and float(lines[2].split(",")[2]) == pytest.approx(changes[0], abs=1e-6)
    import imageio.v3 as iio

    gif = iio.imread(out / "overlay.gif")
    assert gif.shape == (4, 96, 160, 3)
    for i, f in enumerate(sorted(sequence.glob("*.npz"))):  # each frame's own rates over its own colour
        with np.load(f) as npz:
            want = sdk.draw_rate_overlay(npz["colour"], rates[i], 16, legend=True) * 255.0
            wrong = sdk.draw_rate_overlay(npz["colour"], rates[i - 1], 16, legend=True) * 255.0
        err = np.abs(gif[i] - want).mean()
        assert err < 3.0 and (i == 0 or err < np.abs(gif[i] - wrong).mean() / 2), (i, err)  # (a GIF's palette)
    assert iio.imread(out / "frames.png").ndim == 3


def test_out_without_the_picture_packages_is_refused_before_any_work(
        frame: Path, sequence: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """On the runtime install (numpy, onnxruntime, pyyaml: what an engine installs, README) `--out` has no Pillow
    to write overlay.png with: the run predicted, wrote rates.npy and predictions.npy, then ended in a
    ModuleNotFoundError's traceback (a sequence after predicting every frame, on imageio). It is refused before
    any work, in one line naming the extra, exit 2, and writes nothing; without --out nothing of them is needed."""
    import importlib.abc
    import sys

    class NotInstalled(importlib.abc.MetaPathFinder):  # (an import of the package, or of any module of it, fails on it)
        def __init__(self, package: str) -> None:
            self.package = package

        def find_spec(self, name: str, path: object, target: object = None) -> None:
            if name.partition(".")[0] == self.package:
                raise ModuleNotFoundError(f"No module named {self.package!r}", name=self.package)

    for missing, target, name in (("PIL", frame, "PIL"), ("PIL", sequence, "PIL"), ("imageio", sequence, "imageio"),
                                  ("matplotlib", sequence, "matplotlib")):
        with monkeypatch.context() as m:
            for module in [k for k in sys.modules if k.partition(".")[0] == missing]:
                m.delitem(sys.modules, module)
            m.setattr(sys, "meta_path", [NotInstalled(missing), *sys.meta_path])
            out = tmp_path / f"out-{missing}-{target.name}"
            assert main(["predict", str(target), "--out", str(out)]) == 2, missing
            got = capsys.readouterr()
            assert got.err == f"rtp predict: error: this needs {name}, which is not installed: pip install " \
                              "'rtp[capture]'\n", got.err
            assert got.out == "" and not out.exists(), missing  # (no frame predicted, nothing written)
            if missing == "PIL":
                assert main(["predict", str(target)]) == 0 and "% of the shading work" in capsys.readouterr().out


def test_a_budget_holds_the_work_saved_and_reports_each_frames_threshold(
        sequence: Path, frame: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--saving S: each frame's rates are the SDK's for that budget, save at least S, and the threshold each
    frame reached is in the summary, frames.csv and the text; --saving and --threshold exclude each other."""
    out = tmp_path / "out"
    assert main(["predict", str(sequence), "--saving", "0.55", "--out", str(out), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    rates = np.load(out / "rates.npy")
    predictor = sdk.load("jnyang")
    reached = []
    for i, f in enumerate(sorted(sequence.glob("*.npz"))):
        with np.load(f) as npz:
            x = sdk.input_planes(predictor.metadata.inputs, **{k: npz[k] for k in npz.files if k in sdk.GBUFFERS})
        want = sdk.select_rates_for_saving(predictor.predict(x), 0.55, factors=predictor.metadata.rate_factors,
                                           frame_size=(96, 160), tile_size=16)
        np.testing.assert_array_equal(rates[i], want.rates)
        np.testing.assert_array_equal(rates[i], predictor.shading_rates(x, saving=0.55))
        row = got["frames"][i]
        assert row["threshold"] == pytest.approx(want.threshold) and row["work_saved"] == pytest.approx(want.saved)
        assert row["work_saved"] >= 0.55
        reached.append(want.threshold)
    assert len(set(reached)) > 1  # the quality follows the frames
    assert got["saving"] == 0.55 and got["threshold"] is None
    assert got["thresholds"] == {"min": pytest.approx(min(reached)), "median": pytest.approx(np.median(reached)),
                                 "max": pytest.approx(max(reached))}
    lines = (out / "frames.csv").read_text().splitlines()
    assert [float(row.split(",")[5]) for row in lines[1:]] == pytest.approx(reached, rel=1e-5)
    assert main(["predict", *map(str, sorted(sequence.glob("*.npz"))[:2]), "--saving", "0.55"]) == 0
    text = capsys.readouterr().out.splitlines()
    assert text[0].startswith("jnyang.onnx (jnyang), a saving of 0.55, tiles of 16px, 2 frames")
    assert text[1].split()[-1] == "threshold" and float(text[2].split()[-1]) == pytest.approx(reached[0], rel=1e-3)
    assert "; thresholds reached " in text[-1]
    assert main(["predict", str(frame), "--saving", "0.7", "--allowed", "1x2,2x1,2x2"]) == 0
    text = capsys.readouterr().out
    assert "a saving of 0.7 (a budget), reached at threshold " in text and "4x4" not in text
    assert main(["predict", str(frame), "--saving", "0.8", "--allowed", "1x2,2x1,2x2"]) == 2
    assert "--saving: expected the share of shading work to save, a number in [0, 0.75]" in capsys.readouterr().err
    assert main(["predict", str(frame), "--allowed", ""]) == 2  # an unset variable, not VRS off
    assert "--allowed: expected comma-separated rate names, got '' (for no reduced rate" in capsys.readouterr().err
    assert main(["predict", str(frame), "--allowed", "2x2,bogus"]) == 2  # (it said "... 'bogus' in allowed")
    assert "rtp predict: error: --allowed: unknown shading rate 'bogus'; expected names from 1x1" in capsys.readouterr().err
    assert main(["predict", str(frame), "--allowed", "1x1", "--json"]) == 0  # VRS off, said so
    assert json.loads(capsys.readouterr().out)["work_saved"] == 0.0
    # with --threshold the saving is a floor under the threshold's rates
    assert main(["predict", str(sequence), "--saving", "0.55", "--threshold", "0.2", "--json"]) == 0
    floor = json.loads(capsys.readouterr().out)
    assert floor["saving"] == 0.55 and floor["threshold"] is None
    for row, want in zip(floor["frames"], reached):
        assert row["threshold"] == pytest.approx(max(0.2, want)) and row["work_saved"] >= 0.55
    assert main(["predict", str(frame), "--saving", "0.1", "--threshold", "0.2"]) == 0
    assert "threshold 0.2 with a floor of 0.1 saved, ran at threshold 0.2" in capsys.readouterr().out


def test_the_curves_of_a_budget_say_which_side_of_the_threshold_a_reduced_tile_is(
        sequence: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """frames.png's threshold panel said "each reduced tile predicted below it" for every model: a PSNR model's reduced
    tiles are predicted above its threshold (higher is better), and the panel says so."""
    from rtp.evaluate import plots

    titles: list[str] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: titles.extend(ax.get_title() for ax in fig.axes)
                        or np.zeros((1, 1, 3), np.uint8))
    for model, side in (("psnr", "above"), ("jnyang", "below")):
        titles.clear()
        assert main(["predict", str(sequence), "--model", model, "--saving", "0.3", "--out", str(tmp_path / model),
                     "--json"]) == 0
        assert titles[-1] == f"threshold reached (each reduced tile predicted {side} it)", (model, titles)


def test_the_curves_of_a_sequence_are_titled_with_the_model_and_what_its_rates_held(
        sequence: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """frames.png had no title: a picture of curves named neither the model nor the threshold or budget its rates held.
    It is titled as the run's first line reads, model, metric, threshold or saving, tiles and frames."""
    from rtp.evaluate import plots

    titles: list[str] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: titles.append(fig.get_suptitle())
                        or np.zeros((1, 1, 3), np.uint8))
    n = len(list(sequence.glob("*.npz")))
    for extra, held in (([], "threshold 0.25"), (["--saving", "0.3"], "a saving of 0.3"),
                        (["--threshold", "0.2", "--saving", "0.3"], "threshold 0.2 with a floor of 0.3 saved")):
        titles.clear()
        assert main(["predict", str(sequence), *extra, "--out", str(tmp_path / str(len(extra))), "-q"]) == 0
        assert titles == [f"jnyang.onnx (jnyang), {held}, tiles of 16px, {n} frames"], extra
    titles.clear()
    plots.sequence_curves([{"work_saved": 0.5, "changed": None, "predict_ms": 1.0}])  # (no title given: none drawn)
    assert titles == [""]


def test_a_sequence_in_text_a_line_a_frame(sequence: Path, capsys: pytest.CaptureFixture[str]) -> None:
    files = sorted(sequence.glob("*.npz"))
    assert main(["predict", *map(str, files[:2])]) == 0  # several files are a sequence too
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"jnyang.onnx (jnyang), threshold 0.25, tiles of 16px, 2 frames in {sequence}"
    assert lines[2].startswith("frame_0000.npz ") and lines[3].startswith("frame_0001.npz ")
    assert lines[3].split()[2].endswith("%")  # the second frame's changed share
    assert lines[-1].startswith("mean: ") and "of tiles change rate a frame" in lines[-1]


def test_a_folders_frames_in_the_natural_order_of_their_names(tmp_path: Path) -> None:
    from rtp.cli._predict import frame_files

    for name in ("frame_10.npz", "frame_9.npz", "frame_1.npz", "notes.txt"):
        (tmp_path / name).write_bytes(b"")
    assert [Path(f).name for f in frame_files([str(tmp_path)])] == ["frame_1.npz", "frame_9.npz", "frame_10.npz"]
    # a superscript two is no digit run: it sorted as one (str.isdigit) and int() raised a ValueError
    (tmp_path / "frame_1\u00b25.npz").write_bytes(b"")
    assert [Path(f).name for f in frame_files([str(tmp_path)])] == ["frame_1.npz", "frame_1\u00b25.npz", "frame_9.npz",
                                                                    "frame_10.npz"]


def test_sdk_frame_files_takes_one_path_and_breaks_ties_by_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                ) -> None:
    """sdk.files.frame_files("frames") read the string's letters as paths ('/' a folder with no .npz: a wrong
    error), a Path was a TypeError; and frame_01 and frame_1, equal in the natural order, came in the order the
    file system listed them."""
    from rtp.sdk.files import frame_files

    for name in ("frame_1.npz", "frame_01.npz", "frame_2.npz"):
        (tmp_path / name).write_bytes(b"")
    want = [str(tmp_path / n) for n in ("frame_01.npz", "frame_1.npz", "frame_2.npz")]
    assert frame_files(str(tmp_path)) == frame_files(tmp_path) == frame_files([tmp_path]) == want
    real = Path.glob
    for order in (sorted, lambda names: sorted(names, reverse=True)):  # whatever order the folder lists them in
        monkeypatch.setattr(Path, "glob", lambda self, pattern, order=order: iter(order(real(self, pattern))))
        assert frame_files([tmp_path]) == want


def test_files_out_of_order_or_a_missing_frame_are_named(sequence: Path, tmp_path: Path,
                                                         caplog: pytest.LogCaptureFixture) -> None:
    """Files given as a shell's * sorts them (frame_10 before frame_2), and a folder with a frame missing from its
    numbered names, ran in silence: the changed share (and --every's carry) measured between frames that are not one
    after the other. Each is named in a warning, and the sequence still runs in the order given."""
    files = sorted(sequence.glob("*.npz"))
    unpadded = tmp_path / "unpadded"
    unpadded.mkdir()
    for i in (0, 1, 2, 3):  # frame_0, frame_1, frame_10, frame_2 (as text sorts them)
        (unpadded / f"frame_{[0, 1, 10, 2][i]}.npz").write_bytes(files[i].read_bytes())
    given = sorted(str(f) for f in unpadded.glob("*.npz"))
    with caplog.at_level(logging.WARNING, logger="rtp.cli"):
        assert main(["predict", *given, "--json"]) == 0
    assert f"{unpadded / 'frame_10.npz'} comes before {unpadded / 'frame_2.npz'} as given" in caplog.text
    caplog.clear()
    gap = tmp_path / "gap"
    gap.mkdir()
    for f in (files[0], files[1], files[3]):  # frame_0002 missing
        (gap / f.name).write_bytes(f.read_bytes())
    with caplog.at_level(logging.WARNING, logger="rtp.cli"):
        assert main(["predict", str(gap), "--json"]) == 0
    assert f"{gap / 'frame_0001.npz'} then frame_0003.npz: a frame missing between" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtp.cli"):  # the folder itself, every frame there: no word
        assert main(["predict", str(sequence), "--json"]) == 0
        assert main(["predict", str(gap / "frame_0000.npz"), str(gap / "frame_0003.npz"), "--json"]) == 0
    assert "comes before" not in caplog.text and "missing" not in caplog.text, caplog.text


def test_example_frames_are_not_written_beside_others(sequence: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """--write-example --frames N into a folder of more frames (an earlier run's, an engine's dump) left those beside
    the N new ones, and a run on the folder read both camera paths as one sequence; refused, before a frame is
    written. The same names again (the same command twice) are written over."""
    folder = tmp_path / "frames"
    folder.mkdir()
    for f in sorted(sequence.glob("*.npz")):
        (folder / f.name).write_bytes(f.read_bytes())
    before = {f.name: f.read_bytes() for f in folder.iterdir()}
    assert main(["predict", str(folder), "--write-example", "--frames", "2", "--size", "160x96", "--seed", "5"]) == 2
    err = capsys.readouterr().err
    assert "holds 2 other .npz frames (frame_0002.npz, frame_0003.npz)" in err and "Traceback" not in err, err
    assert {f.name: f.read_bytes() for f in folder.iterdir()} == before
    assert main(["predict", str(folder), "--write-example", "--frames", "4", "--size", "160x96", "--seed", "5"]) == 0
    assert sorted(f.name for f in folder.iterdir()) == sorted(before)


def test_a_sequences_mistakes_are_named(sequence: Path, frame: Path, tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["predict", str(empty)]) == 2
    assert "a folder with no .npz frame in it" in capsys.readouterr().err
    other = tmp_path / "other.npz"  # a frame of another size
    assert main(["predict", str(other), "--write-example", "--size", "96x64"]) == 0
    capsys.readouterr()
    out = tmp_path / "out"
    assert main(["predict", str(sequence), str(other), "--out", str(out)]) == 2
    assert "is 96x64, the sequence's first frame 160x96: a sequence's frames are of one size" in capsys.readouterr().err
    assert not out.exists()  # nothing half-written
    assert main(["predict", str(frame), str(other), "--write-example"]) == 2
    assert "--write-example writes one path" in capsys.readouterr().err
    assert main(["predict", str(sequence), "--frames", "2"]) == 2  # (not a limit on the frames predicted)
    assert "--frames 2: the number of frames --write-example writes" in capsys.readouterr().err


def test_an_arrays_error_names_the_frame_file(sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A frame's array out of its range or shape was named alone ("prev_colour: expected values in [0, 1]"): on a
    sequence, not which of its frames held it. Each such error names the file, once."""
    frames = tmp_path / "frames"
    frames.mkdir()
    for f in sorted(sequence.glob("*.npz")):
        (frames / f.name).write_bytes(f.read_bytes())
    bad = frames / "frame_0002.npz"
    with np.load(bad) as npz:
        arrays = dict(npz)
    np.savez(bad, **{**arrays, "prev_colour": arrays["prev_colour"] * 4.0})
    assert main(["predict", str(frames), "--json"]) == 2
    err = capsys.readouterr().err
    assert f"rtp predict: error: {str(bad)!r}: prev_colour: expected values in [0, 1]" in err, err
    np.savez(bad, **arrays, engine_rates=np.zeros((6, 4), np.uint8))  # (the engine's rates of another tiling)
    assert main(["predict", str(bad), "--combiner", "max", "--json"]) == 2
    err = capsys.readouterr().err
    assert f"rtp predict: error: {str(bad)!r}: engine_rates: shape (6, 4) does not broadcast" in err, err
    assert main(["predict", str(frames / "missing.npz")]) == 2  # (an error that names the file already: once)
    assert capsys.readouterr().err.count("missing.npz") == 1


def test_a_threshold_or_rates_refused_before_the_first_frame(sequence: Path, capsys: pytest.CaptureFixture[str],
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """--threshold nan or --allowed 3x3 on a sequence: its header was printed, its first frame read and predicted,
    and only then the option refused; now refused before any frame is read, nothing on stdout."""
    from rtp.cli import _predict

    read: list[str] = []
    real = _predict._read_frame
    monkeypatch.setattr(_predict, "_read_frame", lambda path: (read.append(path), real(path))[1])
    for option, err in ((["--threshold", "nan"], "--threshold: expected a finite number"),
                        (["--allowed", "1x2,3x3"], "--allowed: unknown shading rate '3x3'"),
                        (["--threshold", "-1"], "--threshold: expected a finite number in [0, ")):
        assert main(["predict", str(sequence), *option]) == 2, option
        got = capsys.readouterr()
        assert err in got.err and got.out == "" and read == [], (option, got, read)
    assert main(["predict", str(sequence), "--threshold", "0.3", "--allowed", "1x2,2x2", "--json"]) == 0
    assert len(read) == 4 and json.loads(capsys.readouterr().out)["threshold"] == 0.3


def test_a_frame_given_twice_is_refused(sequence: Path, frame: Path, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """A frame file taken twice (given twice, or a folder and one of its files) is refused before any prediction: it
    was predicted twice, the sequence going back to it (its 'changed' share measured across the jump, --every's
    estimates carried across it)."""
    files = sorted(sequence.glob("*.npz"))
    monkeypatch.chdir(frame.parent)
    out = tmp_path / "out"
    for argv, named in (([str(frame), str(frame)], f"'{frame}': a frame given twice: "),
                        ([frame.name, f"./{frame.name}"], f"'./{frame.name}': a frame given twice (as '{frame.name}' "
                                                          "too): "),
                        ([str(sequence), str(files[1])], f"'{files[1]}': a frame given twice: "),
                        ([str(sequence), str(sequence), "--every", "2"], f"'{files[0]}': a frame given twice: ")):
        assert main(["predict", *argv, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert named + "a sequence takes each frame once, in order" in err, err
    assert not out.exists()


def test_out_holds_one_runs_files(sequence: Path, frame: Path, tmp_path: Path) -> None:
    """--out into a folder of the other kind of run: a frame's run after a sequence's left the sequence's frames.csv,
    overlay.gif and frames.png beside the frame's rates.npy, a sequence's after a frame's the frame's overlay.png; each
    run removes those (only rtp predict's own names), so the folder describes one run."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    kinds = {"sequence": {"rates.npy", "predictions.npy", "frames.csv", "overlay.gif", "frames.png"},
             "frame": {"rates.npy", "predictions.npy", "overlay.png"}}
    for kind, given in (("sequence", sequence), ("frame", frame), ("sequence", sequence)):
        assert main(["predict", str(given), "--out", str(out), "--json"]) == 0
        assert {f.name for f in out.iterdir()} == kinds[kind] | {"notes.txt"}, kind


def test_a_run_that_fails_drawing_leaves_the_last_runs_files_whole(sequence: Path, frame: Path, tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """A sequence's curves (or a frame's overlay) failing to draw, or a Ctrl-C there, came after rates.npy and
    predictions.npy were written: the folder held this run's rates beside the last run's pictures. Everything is
    drawn first; a failure leaves every file of the last run as it was."""
    import rtp.evaluate.plots
    from rtp.cli import _predict

    def fail(*args: object, **kw: object) -> None:
        raise KeyboardInterrupt

    for given, target, place in ((sequence, rtp.evaluate.plots, "sequence_curves"), (frame, _predict, "_overlay")):
        out = tmp_path / given.name
        assert main(["predict", str(given), "--threshold", "0.05", "--out", str(out), "--json"]) == 0
        before = {f.name: f.read_bytes() for f in out.iterdir()}
        with monkeypatch.context() as m:
            m.setattr(target, place, fail)
            assert main(["predict", str(given), "--threshold", "0.5", "--out", str(out), "--json"]) == 130
        assert {f.name: f.read_bytes() for f in out.iterdir()} == before, given
        assert main(["predict", str(given), "--threshold", "0.5", "--out", str(out), "--json"]) == 0
        assert np.load(out / "rates.npy").tolist() != np.frombuffer(before["rates.npy"], np.uint8).tolist()


def test_two_runs_into_one_out_the_second_is_refused_before_its_work(sequence: Path, frame: Path, tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Two `rtp predict --out` into one folder at once each wrote their files and removed the other's (a frame's
    run removed a sequence's frames.csv, overlay.gif and frames.png): the folder held one run's rates.npy beside the
    other's predictions.npy, and both exited 0 saying they wrote theirs. A run holds the folder's writer lock: the
    second is refused naming the first and writes nothing; the lock's file goes with the run, and a folder made for
    it with a run that failed before writing there."""
    import os

    from rtp.sdk.files import LOCK_NAME, writer_lock

    out = tmp_path / "out"
    assert main(["predict", str(sequence), "--out", str(out), "--json"]) == 0
    before = {f.name: f.read_bytes() for f in out.iterdir()}
    capsys.readouterr()
    with writer_lock(out, "rtp predict", RuntimeError):  # (another process's, as far as flock goes)
        assert main(["predict", str(frame), "--out", str(out), "--json"]) == 2
        got = capsys.readouterr()
        assert got.err.strip() == (f"rtp predict: error: --out: {out} is being written by another job (rtp predict, "
                                   f"pid {os.getpid()}): wait for it to end, or write into another folder"), got.err
        assert got.out == ""  # (refused before its work: no frame predicted)
    assert {f.name: f.read_bytes() for f in out.iterdir() if f.name != LOCK_NAME} == before
    assert main(["predict", str(frame), "--out", str(out), "--json"]) == 0
    assert {f.name for f in out.iterdir()} == {"rates.npy", "predictions.npy", "overlay.png"}  # (no lock file left)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    made = tmp_path / "new" / "out"
    assert main(["predict", str(frame), str(bad), "--out", str(made)]) == 2  # (refused at the second frame)
    assert not (tmp_path / "new").exists()


def test_a_run_killed_while_writing_out_leaves_no_mix_of_two_runs(sequence: Path, tmp_path: Path) -> None:
    """SIGKILL between two files of --out over an earlier run's: the folder held this run's rates.npy beside the
    earlier run's predictions.npy, frames.csv and pictures, every file of a run there, of two frame counts; and the
    killed write's temporary file stayed after the same command was run again (atomic_output leaves one under a
    minute old to its writer). Now every file is written to its temporary file first, the earlier run's files are
    then removed and this run's renamed into place, rates.npy last: a kill leaves the earlier run whole, or part of
    this one without rates.npy; the same command then writes the run that was not killed, no temporary file left."""
    import subprocess
    import sys

    frames = sorted(str(f) for f in sequence.glob("*.npz"))
    assert len(frames) == 4
    want = tmp_path / "want"
    assert main(["predict", *frames[:2], "--out", str(want), "--json"]) == 0
    # a process that kills itself (SIGKILL: no cleanup runs) at its n-th rename into --out
    killer = ("import os, signal, sys\n"
              "from rtp.cli import main\n"
              "n, replace = [int(sys.argv[1])], os.replace\n"
              "def killing(a, b):\n"
              "    replace(a, b)\n"
              "    n[0] -= 1\n"
              "    if n[0] == 0:\n"
              "        os.kill(os.getpid(), signal.SIGKILL)\n"
              "os.replace = killing\n"
              "main(sys.argv[2:])\n")
    for n in (1, 3):
        out = tmp_path / f"out{n}"
        assert main(["predict", *frames, "--out", str(out), "--json"]) == 0  # (the earlier run: 4 frames)
        run = ["predict", *frames[:2], "--out", str(out), "--json"]
        killed = subprocess.run([sys.executable, "-c", killer, str(n), *run], capture_output=True)
        assert killed.returncode == -9, killed.stderr.decode()
        counts = {name: int(np.load(out / name).shape[0]) for name in ("rates.npy", "predictions.npy")
                  if (out / name).is_file()}
        if (out / "frames.csv").is_file():
            counts["frames.csv"] = len((out / "frames.csv").read_text().splitlines()) - 1
        assert "rates.npy" not in counts and len(set(counts.values())) <= 1, (n, counts)  # (part of the new run)
        assert main(run) == 0
        assert sorted(f.name for f in out.iterdir()) == sorted(f.name for f in want.iterdir()), n
        for name in ("rates.npy", "predictions.npy"):
            np.testing.assert_array_equal(np.load(out / name), np.load(want / name))


@pytest.mark.parametrize("model", ["jnyang", "jnyang-reuse"])
def test_a_sequence_with_prediction_reuse_is_the_sdks(sequence: Path, tmp_path: Path, model: str,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """--every 2: the network on frames 0 and 2, its estimates (jnyang-reuse: its features) carried along each
    frame's motion on 1 and 3; the values are sdk.PredictionReuse's, fed the planes, motion and sky as an engine
    would feed them."""
    out = tmp_path / "out"
    assert main(["predict", str(sequence), "--model", model, "--every", "2", "--out", str(out), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert [r["network"] >= 1.0 for r in got["frames"]] == [True, False, True, False]
    assert got["every"] == 2 and got["network"] == pytest.approx(np.mean([r["network"] for r in got["frames"]]))
    predictor = sdk.load(model)
    reuse = sdk.PredictionReuse(predictor, 2, carry="features" if predictor.splits else "estimates")
    inputs = predictor.metadata.inputs
    values = np.load(out / "predictions.npy")
    for i, f in enumerate(sorted(sequence.glob("*.npz"))):
        with np.load(f) as npz:
            g = {k: npz[k] for k in npz.files if k in sdk.GBUFFERS}
        x = sdk.input_planes(inputs, **g)
        mx, my, depth = sdk.input_planes(["motion.x", "motion.y", "depth"], **g)
        want = reuse.predict(x, sdk.fetch_from_motion(mx, my) if i else None,
                             x[inputs.index("seen")] if "seen" in inputs else None, depth <= 0)
        np.testing.assert_allclose(values[i], want, rtol=1e-6, atol=1e-6)
    plain = tmp_path / "plain"
    assert main(["predict", str(sequence), "--model", model, "--out", str(plain), "--json"]) == 0
    capsys.readouterr()
    every_frame = np.load(plain / "predictions.npy")
    np.testing.assert_array_equal(values[[0, 2]], every_frame[[0, 2]])  # where the network ran, its own values
    assert not np.array_equal(values[1], every_frame[1])  # carried, not run
    lines = (out / "frames.csv").read_text().splitlines()
    assert [float(line.split(",")[4]) >= 1.0 for line in lines[1:]] == [True, False, True, False]


def test_reuse_needs_a_sequence_and_the_matrices(sequence: Path, frame: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", str(frame), "--every", "4"]) == 2
    assert "--every 4: prediction reuse carries estimates from frame to frame; give a sequence" in \
        capsys.readouterr().err
    bare = tmp_path / "bare"
    bare.mkdir()
    for f in sorted(sequence.glob("*.npz"))[:2]:  # frames without the previous view-projection
        with np.load(f) as npz:
            np.savez(bare / f.name, **{k: npz[k] for k in npz.files if k != "prev_view_projection"})
    assert main(["predict", str(bare), "--every", "2"]) == 2
    err = capsys.readouterr().err
    assert "'prev_view_projection'" in err and "reads" in err


def test_an_engines_rgba8_readbacks(frame: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A frame of RGBA8 textures read back (colour, albedo, previous frame) and a depth of (H, W, 1): the rates of
    the float frame (8 bits apart), and the overlay drawn on the colour."""
    with np.load(frame) as npz:
        a = dict(npz)
    rng = np.random.default_rng(0)

    def rgba8(img: np.ndarray) -> np.ndarray:
        return np.dstack([np.round(img * 255).astype(np.uint8), rng.integers(0, 256, img.shape[:2], np.uint8)])

    engine = tmp_path / "engine.npz"
    np.savez(engine, **{**a, "colour": rgba8(a["colour"]), "albedo": rgba8(a["albedo"]),
                        "prev_colour": rgba8(a["prev_colour"]), "depth": a["depth"][..., None]})
    assert main(["predict", str(frame), "--out", str(tmp_path / "float")]) == 0
    assert main(["predict", str(engine), "--out", str(tmp_path / "rgba8")]) == 0
    capsys.readouterr()
    ours, theirs = np.load(tmp_path / "float" / "rates.npy"), np.load(tmp_path / "rgba8" / "rates.npy")
    assert (ours == theirs).mean() > 0.9, (ours == theirs).mean()
    import imageio.v3 as iio

    picture = iio.imread(tmp_path / "rgba8" / "overlay.png").astype(np.float64)
    drawn = iio.imread(tmp_path / "float" / "overlay.png").astype(np.float64)
    assert np.abs(picture - drawn).mean() < 2.0  # on the colour, not on black


def test_a_convention_mistake_is_warned_of_once_a_sequence(sequence: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Normals dumped as an 8-bit texture's encoding (n * 0.5 + 0.5) give rates without an error: each frame is
    checked (sdk.check_gbuffers) and the mistake is named once, with the count of the other frames."""
    bad = tmp_path / "bad"
    bad.mkdir()
    for f in sorted(sequence.glob("*.npz")):
        with np.load(f) as npz:
            np.savez(bad / f.name, **{k: npz[k] * 0.5 + 0.5 if k == "normal" else npz[k] for k in npz.files})
    assert main(["predict", str(sequence)]) == 0
    assert "WARNING" not in capsys.readouterr().err  # the frames as written: nothing to warn of
    assert main(["predict", str(bad)]) == 0
    err = capsys.readouterr().err
    assert err.count("not unit vectors with no component below 0: an encoded texture (n * 2 - 1)?") == 2, err
    assert "frame_0000.npz: normal: mean length" in err
    assert "... and on 3 more frames of the sequence: " in err and err.count("frame_0000.npz: normal") == 2
    assert main(["predict", str(sequence), "--normal-space", "world"]) == 0  # view-space normals read as world
    err = capsys.readouterr().err
    assert re.search(r"normal: \d+% of the surfaces face away", err) and "%%" not in err, err
    assert main(["predict", str(bad), "--json"]) == 0  # each frame's own warnings, for a tool reading the JSON
    got = json.loads(capsys.readouterr().out)
    assert all(len(r["warnings"]) == 1 and "an encoded texture" in r["warnings"][0] for r in got["frames"])
    assert main(["predict", str(sorted(sequence.glob("*.npz"))[0]), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["warnings"] == []


def test_the_engines_own_rates_in_each_frame_file(frame: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--combiner OP: each frame file's engine_rates meet rtp's in that combiner; the rates written are the SDK's
    for them (the image to upload), the counts and work saved the device's; a frame without them is refused."""
    with np.load(frame) as npz:
        arrays = dict(npz)
    engine = np.full((6, 10), sdk.RATE_CODES["2x1"], np.uint8)
    engine[:, :5] = sdk.RATE_CODES["1x1"]  # the engine coarsens the right half horizontally
    with_engine = tmp_path / "with_engine.npz"
    np.savez(with_engine, **arrays, engine_rates=engine)
    out = tmp_path / "out"
    assert main(["predict", str(with_engine), "--combiner", "max", "--out", str(out), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    predictor = sdk.load("jnyang")
    x = sdk.input_planes(predictor.metadata.inputs, **{k: v for k, v in arrays.items() if k in sdk.GBUFFERS})
    want = predictor.shading_rates(x, engine_rates=engine, combiner="max")
    np.testing.assert_array_equal(np.load(out / "rates.npy"), want)
    shaded = sdk.combine_rates(engine, want, "max")
    assert got["combiner"] == "max" and got["work_saved"] == pytest.approx(sdk.work_saved(shaded, (96, 160), 16))
    assert got["engine_work_saved"] == pytest.approx(0.25)  # (half the tiles at 2x1)
    assert got["rates"] == {r: int((shaded == c).sum()) for r, c in sdk.RATE_CODES.items() if (shaded == c).any()}
    assert main(["predict", str(with_engine), "--combiner", "sum"]) == 0
    assert "the engine's rates and rtp's combined by sum (the engine's alone: 25.0%)" in capsys.readouterr().out
    assert main(["predict", str(frame), "--combiner", "max"]) == 2
    err = capsys.readouterr().err  # (its shape as numpy's: "6x10" read as 6 tiles wide, this command's WxH)
    assert "has no 'engine_rates' array: with --combiner each frame holds" in err and "(shape (6, 10) here" in err
    np.savez(with_engine, **arrays, engine_rates=engine[:, :4])
    assert main(["predict", str(with_engine), "--combiner", "max"]) == 2
    assert "engine_rates: shape (6, 4) does not broadcast" in capsys.readouterr().err
    assert main(["predict", str(with_engine)]) == 0  # without --combiner the array is named as not read
    assert "with_engine.npz: the 'engine_rates' array is not read without --combiner" in capsys.readouterr().err
    assert main(["predict", str(frame)]) == 0
    assert "engine_rates" not in capsys.readouterr().err


def test_options_not_read_are_refused_not_ignored(frame: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """--write-example writes a frame and predicts nothing: a prediction's options (--out, --model, a convention)
    beside it were taken and ignored, and --size or --seed without it ignored too; each is refused, naming it."""
    example = tmp_path / "example.npz"
    out = tmp_path / "out"
    assert main(["predict", str(example), "--write-example", "--size", "160x96", "--out", str(out),
                 "--depth-kind", "reversed"]) == 2
    err = capsys.readouterr().err
    assert "--out, --depth-kind: not read with --write-example" in err and "Traceback" not in err, err
    assert not example.exists() and not out.exists()
    assert main(["predict", str(frame), "--size", "320x192", "--out", str(out)]) == 2
    assert "--size: an option of --write-example" in capsys.readouterr().err and not out.exists()
    assert main(["predict", str(frame), "--seed", "3", "--json"]) == 2
    assert "--seed: an option of --write-example" in capsys.readouterr().err
    assert main(["predict", str(frame), "--model", "jnyang", "--json"]) == 0  # (the defaults, given, are read)


def test_each_kind_of_convention_warning_is_shown(frame: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """Two kinds of mistake in one frame (a view matrix for row vectors, and so nothing reprojects) are both
    named: the command's log collapsed records of one message template, and every warning was logged as "%s",
    so the second was hidden behind a "1 more like" of the first."""
    bad = tmp_path / "transposed.npz"
    with np.load(frame) as npz:
        np.savez(bad, **{k: npz[k].T if k == "view" else npz[k] for k in npz.files})
    assert main(["predict", str(bad)]) == 0
    err = capsys.readouterr().err
    assert "view: its last row is" in err and "seen: only" in err, err
    assert "more like" not in err, err


def test_a_foreign_model_runs_with_its_sidecar(frame: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A model that carries no rtp metadata (an adopted network's ONNX) was refused with a hint to pass "the
    commands' --metadata SIDECAR.yaml", which rtp predict did not take (exit 2, "unrecognized arguments"): it takes
    the sidecar as rtp info does, and its hint is in this command's flags."""
    import yaml

    from .conftest import base_metadata, build_onnx

    weights = np.eye(4, dtype=np.float32)
    model = build_onnx(tmp_path / "foreign.onnx", weights=weights, metadata=None)
    sidecar = tmp_path / "foreign.yaml"
    sidecar.write_text(yaml.safe_dump(base_metadata()))
    assert main(["predict", str(frame), "--model", str(model), "--json"]) == 2
    err = capsys.readouterr().err
    assert "carries no rtp metadata: pass --metadata SIDECAR.yaml" in err and "metadata=" not in err, err
    out = tmp_path / "out"
    assert main(["predict", str(frame), "--model", str(model), "--metadata", str(sidecar), "--tile-size", "8",
                 "--out", str(out), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    predictor = sdk.load(str(model), metadata=str(sidecar), tile_size=8)
    with np.load(frame) as npz:
        x = sdk.input_planes(predictor.metadata.inputs, **{k: npz[k] for k in npz.files if k in sdk.GBUFFERS})
    np.testing.assert_array_equal(np.load(out / "rates.npy"), predictor.shading_rates(x))
    assert got["model"] == "foreign.onnx" and got["tile_size"] == 8 and got["tiles"] == [12, 20]
    assert main(["predict", str(tmp_path / "example.npz"), "--write-example", "--metadata", str(sidecar)]) == 2
    assert "--metadata: not read with --write-example" in capsys.readouterr().err


def test_predict_draws_its_overlay_in_the_palette_asked_for(frame: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """--palette cvd: overlay.png's tints and key in the colour-vision-deficiency palette (sdk.draw_rate_overlay's
    palette="cvd"); the paper's by default; with --write-example, which draws nothing, refused."""
    from PIL import Image

    from rtp.cli._predict import _overlay

    pictures = {}
    for palette in ("paper", "cvd"):
        out = tmp_path / palette
        assert main(["predict", str(frame), "--out", str(out), "--json", "--palette", palette]) == 0
        capsys.readouterr()
        pictures[palette] = np.asarray(Image.open(out / "overlay.png").convert("RGB"))
        with np.load(frame) as npz:
            arrays = {k: npz[k] for k in npz.files}
        np.testing.assert_array_equal(pictures[palette], _overlay(arrays, np.load(out / "rates.npy"), 16,
                                                                  palette=palette))
    assert (pictures["paper"] != pictures["cvd"]).any()
    assert main(["predict", str(frame), "--out", str(tmp_path / "default"), "--json"]) == 0
    np.testing.assert_array_equal(np.asarray(Image.open(tmp_path / "default" / "overlay.png").convert("RGB")),
                                  pictures["paper"])
    capsys.readouterr()
    assert main(["predict", str(tmp_path / "x.npz"), "--write-example", "--palette", "cvd"]) == 2
    assert "--palette" in capsys.readouterr().err


def test_a_wide_frames_gif_overlay_keeps_every_tiles_grid_line_and_a_readable_key() -> None:
    """A frame wider than the GIF's 480 pixels was drawn at full size and then sampled: at 1280x720 (a third of its
    size) the GIF kept every third grid line, its 16-pixel tiles looking three times their size, and its key's
    2-pixel letters lost one column in three. The grid and the key are drawn at the size shown."""
    from rtp.cli._predict import GIF_WIDTH, _overlay
    from rtp.sdk._overlay import _draw_legend

    h, w, tile = 720, 1280, 16
    frame = {"depth": np.ones((h, w), np.float32), "colour": np.full((h, w, 3), 0.6, np.float32)}
    picture = _overlay(frame, np.zeros((45, 80), np.uint8), tile, GIF_WIDTH)  # every tile 1x1: untinted
    assert picture.shape == (240, 427, 3)
    grey = round(0.6 * 255)
    rows = np.flatnonzero(picture[:150, 200, 0] < grey)  # (a column of no grid line, above the key)
    cols = np.flatnonzero(picture[100, :, 0] < grey)
    assert rows.tolist() == [-(-k * tile // 3) for k in range(45) if -(-k * tile // 3) < 150]
    assert cols.tolist() == [-(-k * tile // 3) for k in range(80)]  # a line at the first column shown of each tile
    key = np.zeros((240, 427, 3), np.float32)
    _draw_legend(key, 0.45)  # the key at the size shown: its letters whole
    np.testing.assert_array_equal((picture == 255).all(-1), (key == 1.0).all(-1))
    small = {"depth": np.ones((96, 160), np.float32), "colour": np.full((96, 160, 3), 0.6, np.float32)}
    rates = np.zeros((6, 10), np.uint8)  # (a frame the GIF's width or narrower: drawn as draw_rate_overlay draws it)
    np.testing.assert_array_equal(_overlay(small, rates, tile, GIF_WIDTH), np.round(
        sdk.draw_rate_overlay(small["colour"], rates, tile, legend=True) * 255.0).astype(np.uint8))


def test_the_curves_hold_their_points_whole_inside_the_panels(monkeypatch: pytest.MonkeyPatch) -> None:
    """frames.png's panels ran from 0 to matplotlib's margin above the highest point, a share of the data's own
    spread: work saved of 55-57% drew the top markers cut in half on the panel's edge, a constant series its whole
    line on it, and a series all 0 (rates that never change) ran to 0.055. Each panel has room above its highest
    point, a series all 0 runs to 1, and no marker is clipped."""
    from rtp.evaluate import plots

    axes: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: axes.extend(fig.axes) or np.zeros((1, 1, 3), np.uint8))
    rows = [{"work_saved": 0.56, "changed": None if i == 0 else 0.0, "predict_ms": 0.4 + 0.01 * i, "threshold": 0.25}
            for i in range(4)]
    plots.sequence_curves(rows, thresholds=True)
    assert len(axes) == 4
    for ax in axes:
        y = np.concatenate([line.get_ydata() for line in ax.get_lines()]).astype(np.float64)
        low, top = ax.get_ylim()
        assert low == 0.0 and np.nanmax(y) <= 0.95 * top, (ax.get_title(), ax.get_ylim())
        assert not any(line.get_clip_on() for line in ax.get_lines())
    assert axes[1].get_ylim() == (0.0, 1.0)  # (the change in %: 0 every frame)


def test_the_curves_of_a_one_frame_folder_count_whole_frames(monkeypatch: pytest.MonkeyPatch) -> None:
    """A folder of one frame is a sequence: its frames.png's axes read -0.5, -0.4, ... 0.5 (matplotlib's integer
    locator gives up under two whole numbers). Each panel is ticked at whole frames, its one frame's 0."""
    from rtp.evaluate import plots

    axes: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: axes.extend(fig.axes) or np.zeros((1, 1, 3), np.uint8))
    for n in (1, 2, 5):
        axes.clear()
        rows = [{"work_saved": 0.6, "changed": None if i == 0 else 0.3, "predict_ms": 2.0, "threshold": 0.25}
                for i in range(n)]
        plots.sequence_curves(rows, thresholds=True)
        for ax in axes:
            lo, hi = ax.get_xlim()
            ticks = [t for t in ax.get_xticks() if lo <= t <= hi]
            assert ticks == list(range(n)), (n, ax.get_title(), ticks)


def test_an_engines_own_pickled_array_is_not_read_and_a_pickled_g_buffer_is_named(
        frame: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture) -> None:
    """An engine that stashes its own metadata beside the G-buffers (``np.savez(..., meta={"frame": 12})``, a
    pickled object array) had the whole frame refused as "a damaged .npz" (every array was loaded, the unknown ones
    too); a G-buffer saved as an object array was called damaged without naming it."""
    with np.load(frame) as npz:
        arrays = dict(npz)
    meta = tmp_path / "meta.npz"
    np.savez(meta, **arrays, meta={"frame": 12, "engine": "mine"})
    with caplog.at_level(logging.WARNING):
        assert main(["predict", str(meta), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rates"]
    assert "array 'meta' is not a G-buffer and is not read" in caplog.text
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, **{**arrays, "depth": arrays["depth"].astype(object)})
    assert main(["predict", str(pickled), "--json"]) == 2
    err = capsys.readouterr().err
    assert "pickled.npz': depth is a pickled object array" in err and "damaged" not in err, err


def test_motion_and_depth_in_another_engines_convention_are_warned(frame: Path, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Motion vectors with y up, in NDC or UV units or current minus previous, and a reversed-Z depth buffer given as
    linear depth (its values in [0, 1], 0 on background, as linear depth's) were taken without a word (or with a
    "seen" warning that named the matrices): each is named, with the conversion; the reference frame is not."""
    with np.load(frame) as npz:
        arrays = dict(npz)
    h, w = arrays["depth"].shape
    motion = arrays["motion"]
    p = arrays["projection"]
    z = -arrays["depth"].astype(np.float64)  # reversed-Z: 1 - the window depth, 0 on background
    reversed_z = np.where(arrays["depth"] > 0, 0.5 - 0.5 * (p[2, 2] * z + p[2, 3]) / -z, 0.0).astype(np.float32)
    cases = {
        "reference": ({}, None),
        "y_up": ({"motion": motion * [1, -1]}, "taken as pixels, y up: .*multiply these by \\(1, -1\\)"),
        "ndc": ({"motion": motion * [2 / w, -2 / h]}, f"taken as NDC units .*, y up: .*by \\({w // 2}, -{h // 2}\\)"),
        "uv_negated": ({"motion": -motion * [1 / w, 1 / h]},
                       f"UV units .*, current minus previous position: .*by \\(-{w}, -{h}\\)"),
        "reversed_z": ({"depth": reversed_z}, r"depth: 9\d% of the surfaces are nearer than the projection's near "
                                              r"plane .*\(--depth-kind reversed\)"),
    }
    for name, (change, match) in cases.items():
        path = tmp_path / f"{name}.npz"
        np.savez(path, **{**arrays, **change})
        assert main(["predict", str(path), "--json"]) == 0, name
        warnings = json.loads(capsys.readouterr().out)["warnings"]
        if match is None:
            assert warnings == [], warnings
        else:
            assert any(re.search(match, t) for t in warnings), (name, warnings)


def test_colour_in_linear_light_is_warned_where_the_frame_shown_is_given(
        frame: Path, sequence: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        caplog: pytest.LogCaptureFixture) -> None:
    """A prev_colour dumped in linear light (a target read back before its sRGB conversion) darkens every reprojected
    tone, and the work saved fell (48% to 9% on a reference frame) without a word: where the frame holds ``colour``,
    the frame shown, the previous frame reprojected against it names the one in linear light, as rtp import's
    final_1x1 does (an 8-bit RGBA read-back too); colour all in linear light, or no colour, says nothing."""
    with np.load(frame) as npz:
        arrays = dict(npz)

    def linear(x: np.ndarray) -> np.ndarray:
        return np.asarray(sdk.srgb_to_linear(x), np.float32)

    rgba8 = np.dstack([np.round(arrays["colour"] * 255).astype(np.uint8), np.full(arrays["depth"].shape, 255, np.uint8)])
    cases = {"reference": {}, "prev": {"prev_colour": linear(arrays["prev_colour"])},
             "colour": {"colour": linear(arrays["colour"])},
             "rgba8": {"prev_colour": linear(arrays["prev_colour"]), "colour": rgba8},
             "all": {"prev_colour": linear(arrays["prev_colour"]), "colour": linear(arrays["colour"])},
             "no_colour": {"prev_colour": linear(arrays["prev_colour"]), "colour": None}}
    for name, change in cases.items():
        path = tmp_path / f"{name}.npz"
        np.savez(path, **{k: v for k, v in {**arrays, **change}.items() if v is not None})
        assert main(["predict", str(path), "--json"]) == 0, name
        warnings = json.loads(capsys.readouterr().out)["warnings"]
        if name in ("reference", "all", "no_colour"):
            assert warnings == [], (name, warnings)
            continue
        key = "colour" if name == "colour" else "prev_colour"
        assert len(warnings) == 1 and warnings[0].startswith(f"{key}: looks like linear light"), (name, warnings)
        assert "display-encoded, as shown (tone-mapped, sRGB)" in warnings[0] and "sdk.linear_to_srgb" in warnings[0]
    # a sequence: logged once, with the count of the other frames
    bad = tmp_path / "linear"
    bad.mkdir()
    for f in sorted(sequence.glob("*.npz")):
        with np.load(f) as npz:
            np.savez(bad / f.name, **{k: linear(npz[k]) if k == "prev_colour" else npz[k] for k in npz.files})
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtp.cli"):
        assert main(["predict", str(bad)]) == 0
    capsys.readouterr()
    said = [r.getMessage() for r in caplog.records if "linear light" in r.getMessage()]
    assert len(said) == 2 and said[0].startswith(f"{bad / 'frame_0000.npz'}: prev_colour: looks like linear light: "
                                                 "reprojected, it differs from colour by "), said
    assert said[1].startswith("... and on 3 more frames of the sequence: "), said


def test_a_threshold_given_with_a_saving_is_in_the_json(sequence: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--threshold T --saving S on a sequence: the summary's threshold is null (each frame reached its own) and T was
    nowhere in the JSON; it is ``threshold_given``, for a frame too (whose ``threshold`` is the one reached)."""
    files = [str(f) for f in sorted(sequence.glob("*.npz"))[:2]]
    assert main(["predict", *files, "--saving", "0.55", "--threshold", "0.2", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["threshold"] is None and got["threshold_given"] == 0.2 and got["saving"] == 0.55
    assert main(["predict", files[0], "--saving", "0.55", "--threshold", "0.2", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["threshold_given"] == 0.2 and got["threshold"] >= 0.2
    for options in ([], ["--saving", "0.55"]):
        assert main(["predict", *files, *options, "--json"]) == 0
        got = json.loads(capsys.readouterr().out)
        assert got["threshold_given"] is None and (got["threshold"] is None) == bool(options)
    assert main(["predict", *files, "--threshold", "0.3", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["threshold_given"] == 0.3 == got["threshold"]


def _huge_header(frame: Path, path: Path, key: str, shape: tuple[int, ...]) -> None:
    """``frame`` with ``key``'s header saying ``shape`` (its data as it was)."""
    import io
    import zipfile

    with np.load(frame) as npz:
        arrays = dict(npz)
    with zipfile.ZipFile(path, "w") as z:
        for k, v in arrays.items():
            buf = io.BytesIO()
            if k == key:
                np.lib.format.write_array_header_1_0(buf, {"descr": v.dtype.str, "fortran_order": False, "shape": shape})
                buf.write(v.tobytes())
            else:
                np.save(buf, v)
            z.writestr(f"{k}.npy", buf.getvalue())


def test_frames_past_the_machines_memory_are_refused_before_any_is_read(
        frame: Path, sequence: Path, tmp_path: Path, machine_memory: Any, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A frame whose array's header says a huge shape was read until numpy's MemoryError, reported as "a damaged
    .npz" (or, where the allocation succeeded, until the system killed the run): rtp predict sizes each frame from
    its arrays' headers before any is read, as rtp import does (RTP_MEMORY_CHECK), naming the file, the array and
    the bytes needed."""
    from rtp.cli import _predict

    read: list[Any] = []
    real = _predict._read_frame
    monkeypatch.setattr(_predict, "_read_frame", lambda p: read.append(p) or real(p))
    huge = sequence.parent / "huge_frames"  # (a sequence whose third frame is the huge one)
    huge.mkdir()
    for i, f in enumerate(sorted(sequence.glob("*.npz"))[:3]):
        if i == 2:
            _huge_header(f, huge / f.name, "albedo", (100_000, 100_000, 3))
        else:
            (huge / f.name).write_bytes(f.read_bytes())
    machine_memory(MemTotal=8 * 2**30)
    assert main(["predict", str(huge)]) == 2
    err = capsys.readouterr().err
    assert re.search(r"rtp predict: error: frame: '[^']*frame_0002.npz': a prediction of it holds about 111.8 GiB "
                     r"\(\d+ bytes\), its arrays 111.8 GiB \(the largest, albedo: shape \(100000, 100000, 3\), "
                     r"float32, 111.8 GiB\), more than this machine's 8.0 GiB of memory: smaller frames.*"
                     r"\(RTP_MEMORY_CHECK=warn runs it anyway\)$", err.strip()), err
    assert read == []  # (refused before the first frame was read)
    assert main(["predict", str(frame), "--json"]) == 0  # a 160x96 frame: about 69 MiB
    capsys.readouterr()
    machine_memory(MemTotal=32 * 2**20)
    assert main(["predict", str(frame), "--json"]) == 2
    assert "frame: " in capsys.readouterr().err and len(read) == 1
    # past the check (RTP_MEMORY_CHECK=off), numpy's MemoryError names the array, not a damaged file
    monkeypatch.setenv("RTP_MEMORY_CHECK", "off")

    def no_memory(self: Any, key: str) -> Any:
        raise MemoryError(f"Unable to allocate for {key}")

    monkeypatch.setattr(np.lib.npyio.NpzFile, "__getitem__", no_memory)
    with pytest.raises(sdk.ParameterError, match=r"frame.npz': depth does not fit in memory, numpy cannot allocate the "
                                                 r"array its header describes \(Unable to allocate for depth\)") as e:
        sdk.files.read_frame(frame)
    assert e.value.name == "depth" and "damaged" not in str(e.value)


def test_array_headers_reads_shapes_and_dtypes_without_loading(tmp_path: Path) -> None:
    """sdk.files.array_headers, the one reader of an .npz's array headers that rtp predict's and rtp import's
    checks before reading share: shapes and dtypes, a pickled array not unpickled, a file that is no .npz named."""
    path = tmp_path / "f.npz"
    np.savez(path, depth=np.zeros((3, 5), np.float32), colour=np.zeros((3, 5, 4), np.uint8),
             meta=np.array([{"frame": 12}], dtype=object))
    headers = sdk.files.array_headers(path)
    assert headers["depth"] == ((3, 5), np.dtype(np.float32)) and headers["colour"] == ((3, 5, 4), np.dtype(np.uint8))
    assert headers["meta"][1].hasobject
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(sdk.ParameterError, match=r"text.npz': not an .npz of arrays numpy can read \(BadZipFile"):
        sdk.files.array_headers(tmp_path / "text.npz")
