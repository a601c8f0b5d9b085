"""The `rtp` command."""

from __future__ import annotations

import json
import logging
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp.cli import main

from .conftest import base_metadata


def test_info_prints_the_metadata(tiny_model: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    path = tiny_model(base_metadata(provenance={"scenes": ["oa_dm1", "kaos2"], "samples": 40, "dead_outputs": [],
                                                "target_parameters": {}}))
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert re.search(r"provenance.dead_outputs +none\n", out), out  # (an empty list printed its name alone)
    assert re.search(r"provenance.target_parameters +none\n", out), out  # (an empty mapping printed no row)
    for text in ("jnyang", "clamped (mu_y=0.25)", "16x16", "reprojected.r, seen, albedo.r, normal.z",
                 "1x2, 2x1, 2x2, 2x4, 4x2, 4x4", "CPUExecutionProvider", "provenance.scenes", "oa_dm1, kaos2"):
        assert text in out, text
    assert re.search(r"hardware tiles +4, 8, 16, 32 \(sdk.load", out), out  # the VRS tiles it runs on
    # what an engine reads back for it (sdk.input_planes' arguments)
    assert re.search(r"G-buffers read +depth, albedo, normal, view, projection, prev_colour, prev_depth, "
                     r"prev_view_projection, and motion where objects move \(", out), out
    assert main(["info", str(path), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["metadata"]["provenance"]["samples"] == 40 and got["gbuffers"][0] == "depth"
    assert got["gbuffers_optional"] == ["motion"]  # (it reprojects: the engine's motion vectors move objects)
    static = tiny_model(base_metadata(inputs=["albedo.r", "normal.z", "depth", "roughness"]))
    assert main(["info", str(static), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["gbuffers_optional"] == []


def test_info_json_holds_what_the_table_says(tiny_model: Callable[..., Path],
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp info --json` ("JSON instead of a table") left out rows of the table: a fixed input size, the providers,
    the hardware tiles, the rates predicted and the saturation. Each is there, as sdk.load gives it, in strict JSON."""
    from rtp import sdk

    def strict(text: str) -> Any:
        def refuse(constant: str) -> None:
            raise ValueError(constant)
        return json.loads(text, parse_constant=refuse)

    sizes = []
    for path in (tiny_model(base_metadata(), static=(1, 48, 64)), tiny_model(base_metadata()), "psnr"):
        assert main(["info", str(path), "--json"]) == 0
        got = strict(capsys.readouterr().out)
        pred = sdk.load(path)
        assert got["providers"] == pred.providers and got["provider"] == pred.provider
        assert got["hardware_tiles"] == list(sdk.hardware_tiles(pred.metadata.tile_size))
        assert got["rates"] == list(pred.rates) and got["saturation"] == pred.metadata.saturation
        assert got["metadata"] == pred.metadata.to_dict()
        sizes.append(got["input_size"])
    assert sizes == [[64, 48], None, None]  # (W x H, as the table's "fixed 64x48")


def test_info_table_is_a_row_a_line(tiny_model: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    """A description of several lines (a YAML block scalar, ending in a newline) broke the table, and a foreign
    model's control characters (a terminal's escape sequences) were printed as they were: each is written as its
    escape, a row a line; the JSON keeps the text as it is."""
    text = "Two lines.\nThe second \x1b[31mred\x1b[0m.\n"
    path = tiny_model(base_metadata(description=text, provenance={"odd\nkey": "a\rb"}))
    assert main(["info", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    desc = next(line for line in lines if line.startswith("description "))
    assert desc.endswith(r"  Two lines.\nThe second \x1b[31mred\x1b[0m.\n"), desc
    assert all(line.isprintable() for line in lines) and "" not in lines, lines
    assert re.search(r"^provenance\.odd\\nkey +a\\rb$", "\n".join(lines), re.M), lines
    assert main(["info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["metadata"]["description"] == text

def test_info_errors_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(tmp_path / "missing.onnx")]) == 2
    err = capsys.readouterr().err
    assert "no model file" in err and "Traceback" not in err
    with pytest.raises(SystemExit) as info:
        main(["frobnicate"])
    assert info.value.code == 2


def _image_pair(tmp_path: Path, w: int = 40, h: int = 24) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    """Two PNGs: a smooth reference and a copy with its left half noised (its right half identical)."""
    from PIL import Image

    y, x = np.mgrid[0:h, 0:w]
    ref = np.stack([x * 255 // (w - 1), y * 255 // (h - 1), np.full_like(x, 128)], -1).astype(np.uint8)
    test = ref.copy()
    rng = np.random.default_rng(0)
    test[:, : w // 2] = np.clip(test[:, : w // 2].astype(int) + rng.integers(-60, 61, (h, w // 2, 3)), 0, 255)
    a, b = tmp_path / "ref.png", tmp_path / "test.png"
    Image.fromarray(ref).save(a)
    Image.fromarray(test).save(b)
    return a, b, ref.astype(np.float32) / 255.0, test.astype(np.float32) / 255.0


@pytest.mark.parametrize("metric", ["flip", "psnr"])
def test_metric_prints_the_librarys_tile_values(metric: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp metric M ref test --json` prints what `rtp.metrics.tile_metric` gives for the two images,
    an identical tile's +inf dB (PSNR) as null; the text form says how many tiles are identical."""
    from rtp import metrics

    a, b, ref, test = _image_pair(tmp_path)
    want = metrics.tile_metric(metric, ref, test, 8)
    assert main(["metric", metric, str(a), str(b), "--tile-size", "8", "--json"]) == 0  # (the flag of play, demo)
    alias = capsys.readouterr().out
    assert main(["metric", metric, str(a), str(b), "--tile", "8", "--json"]) == 0
    raw = capsys.readouterr().out
    assert alias == raw
    got = json.loads(raw, parse_constant=lambda c: pytest.fail(f"not JSON: {c}"))  # +inf is null, not Infinity
    assert (got["metric"], got["tile"]) == (metric, 8) and np.array(got["tiles"]).shape == (3, 5)
    as_float = np.array([[np.inf if v is None else v for v in row] for row in got["tiles"]])
    np.testing.assert_allclose(as_float, want, rtol=1e-6)
    # the identical right half: +inf dB; FLIP's filters reach a few pixels past the noise, not 12
    assert (np.isinf(as_float[:, 3:]).all() and np.isfinite(as_float[:, :2]).all()) if metric == "psnr" \
        else (as_float[:, 4:] == 0).all() and (as_float[:, :2] > 0.1).all()
    assert main(["metric", metric, str(a), str(b), "--tile", "8"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{metric} (") and "40x24, 5x3 tiles of 8px" in out
    finite = want[np.isfinite(want)]
    worst = finite.min() if metric == "psnr" else finite.max()
    assert f"per tile   mean {finite.mean():.4g}, worst ({'min' if metric == 'psnr' else 'max'}) {worst:.4g}" in out
    assert ("6 identical tiles (+inf dB)" in out) == (metric == "psnr")
    assert ("per pixel  mean" in out) == (metric == "flip")
    # an image against itself: every PSNR tile +inf dB, no mean or worst to print ("mean nan, worst (min) nan")
    assert main(["metric", metric, str(a), str(a), "--tile", "8"]) == 0
    out = capsys.readouterr().out
    assert "nan" not in out and ("per tile   all 15 tiles identical (+inf dB)" in out) == (metric == "psnr"), out


def test_metric_draws_its_map_and_refuses_images_of_two_sizes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--out writes the per-pixel map (PSNR: the per-tile values) as an image; a pair of two sizes
    is a one-line error naming both."""
    from PIL import Image

    a, b, _, _ = _image_pair(tmp_path)
    for metric in ("flip", "psnr"):
        out = tmp_path / f"{metric}.png"
        assert main(["metric", metric, str(a), str(b), "--out", str(out)]) == 0
        assert f"wrote {out}" in capsys.readouterr().out
        with Image.open(out) as im:
            picture = np.asarray(im.convert("RGB"))
        assert picture.shape[0] > 24 and picture.shape[1] > 40 and picture.std() > 10  # a figure, not a blank
        # a small pair is drawn 3 inches high (its colour bar's label was cut off at one pixel a pixel);
        # PSNR's identical tiles (the right half, +inf dB) grey, apart from the best finite tile's black
        assert picture.shape[0] >= 300
        grey = (np.abs(picture.astype(int) - 0x9A).max(-1) <= 2).mean()
        assert (0.05 < grey < 0.5) if metric == "psnr" else grey < 0.01, (metric, grey)
    small = tmp_path / "small.png"
    Image.fromarray(np.zeros((10, 12, 3), np.uint8)).save(small)
    assert main(["metric", "flip", str(a), str(small)]) == 2
    err = capsys.readouterr().err
    assert "the images differ in size: 40x24 and 12x10" in err and "Traceback" not in err
    # a path no file system name decodes to (an in-process caller's lone surrogate) was Pillow's
    # UnicodeEncodeError traceback; a usage error naming the argument now (found by the deep fuzz run)
    for argv in (["metric", "flip", "\ud800", str(b)], ["metric", "flip", str(a), "\ud800"]):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 2
        assert "expected a path, got '\\ud800' (not encodable as a file name)" in capsys.readouterr().err


def test_metric_out_keeps_its_title_inside_the_picture(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The title was wrapped at a guess of 6 pixels a character, narrower than 9-point text is: a 160x96 pair's
    'psnr per 16px tile: demo_small/frame.png vs demo_small/vrs_composite.png (grey: identical, +inf dB)', one
    line, ran off both sides of the picture ('r 16px tile: ...'). It is wrapped to the picture's width as drawn."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    import rtp.capture

    figures: list[Any] = []
    real = rtp.capture.figure_image
    monkeypatch.setattr(rtp.capture, "figure_image", lambda fig: figures.append(fig) or real(fig))
    (tmp_path / "demo_small").mkdir()
    a, b, _, _ = _image_pair(tmp_path / "demo_small", 160, 96)
    a, b = a.rename(a.with_name("frame.png")), b.rename(b.with_name("vrs_composite.png"))
    monkeypatch.chdir(tmp_path)
    for metric in ("psnr", "flip"):
        figures.clear()
        assert main(["metric", metric, "demo_small/frame.png", "demo_small/vrs_composite.png", "--out", "m.png"]) == 0
        (fig,) = figures
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        title = fig.axes[0].title
        assert "demo_small/vrs_composite.png" in title.get_text().replace("\n", " ")
        box = title.get_window_extent(canvas.get_renderer())
        assert fig.bbox.contains(box.x0, box.y0) and fig.bbox.contains(box.x1, box.y1), (metric, title.get_text())


def test_metric_json_with_out_prints_json_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--json with --out: stdout is one JSON document naming the picture written (a 'wrote PATH' line after it made
    `rtp metric psnr a.png b.png --json --out m.png | python -c 'json.load(...)'` fail on 'Extra data')."""
    a, b, _, _ = _image_pair(tmp_path)
    out = tmp_path / "map.png"
    assert main(["metric", "psnr", str(a), str(b), "--tile", "8", "--json", "--out", str(out)]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["wrote"] == str(out) and out.is_file() and np.array(got["tiles"]).shape == (3, 5)
    assert main(["metric", "psnr", str(a), str(b), "--json"]) == 0
    assert "wrote" not in json.loads(capsys.readouterr().out)


def test_metric_says_when_an_image_has_transparent_pixels(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                          caplog: pytest.LogCaptureFixture) -> None:
    """An RGBA image is compared by its colour (as it always was), and a warning says that its alpha
    was not: an image with a cut-out compares the colour under it, not what is shown."""
    from PIL import Image

    a, b, _, test = _image_pair(tmp_path)
    rgba = np.concatenate([np.round(test * 255), np.full(test.shape[:2] + (1,), 255.0)], -1).astype(np.uint8)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "opaque.png")
    rgba[:6, :10, 3] = 0  # a cut-out: 60 of 960 pixels
    Image.fromarray(rgba, "RGBA").save(tmp_path / "cut.png")
    tiles = []
    for name in ("test.png", "opaque.png", "cut.png"):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="rtp"):
            assert main(["metric", "flip", str(a), str(tmp_path / name), "--tile", "8", "--json"]) == 0
        tiles.append(json.loads(capsys.readouterr().out)["tiles"])
        warned = [r.getMessage() for r in caplog.records if "opaque" in r.getMessage()]
        assert warned == ([f"{tmp_path / name}: 6.2% of its pixels are not opaque; the metric compares the colour "
                           "alone (composite the image over its background first to compare what is shown)"]
                          if name == "cut.png" else []), (name, warned)
    assert tiles[0] == tiles[1] == tiles[2]


def test_metric_reads_16_bit_and_float_images_by_their_values(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 16-bit greyscale PNG and a float TIFF in [0, 1] are read as the values they hold, the tiles of
    the 8-bit greyscale image of the same picture (Pillow's convert('RGB') clipped the 16-bit one to
    white and cast the float one to black); a float image past [0, 1] (HDR) and 32-bit integer pixels
    are refused in words, not compared."""
    from PIL import Image

    a, b, _, test = _image_pair(tmp_path)
    grey8 = np.round(test[..., 0] * 255).astype(np.uint8)
    files = {"grey8.png": Image.fromarray(grey8), "grey16.png": Image.fromarray(grey8.astype(np.uint16) * 257),
             "float.tif": Image.fromarray(grey8.astype(np.float32) / 255, "F"),
             "white.png": Image.fromarray(np.full_like(grey8, 255)), "black.png": Image.fromarray(np.zeros_like(grey8))}
    tiles = {}
    for name, im in files.items():
        im.save(tmp_path / name)
        assert main(["metric", "flip", str(a), str(tmp_path / name), "--tile", "8", "--json"]) == 0
        tiles[name] = np.array(json.loads(capsys.readouterr().out)["tiles"], float)
    assert Image.open(tmp_path / "grey16.png").mode == "I;16"
    for wrong in ("white.png", "black.png"):  # (what the 16-bit and the float image were read as)
        assert np.abs(tiles[wrong] - tiles["grey8.png"]).max() > 0.05
    np.testing.assert_allclose(tiles["grey16.png"], tiles["grey8.png"], atol=1e-6)
    np.testing.assert_allclose(tiles["float.tif"], tiles["grey8.png"], atol=1e-6)
    Image.fromarray(grey8.astype(np.float32) / 64, "F").save(tmp_path / "hdr.tif")
    Image.fromarray(grey8.astype(np.int32) * 1000, "I").save(tmp_path / "int32.tif")
    nan = grey8.astype(np.float32) / 255
    nan[3, 4] = np.nan
    Image.fromarray(nan, "F").save(tmp_path / "nan.tif")
    for name, said in (("hdr.tif", "a float image with values in [0, 3.984]: expected display-encoded values in "
                                   "[0, 1] (tone-map an HDR image first)"),
                       ("int32.tif", "32-bit integer pixels: expected 8- or 16-bit integer channels"),
                       ("nan.tif", "a float image with 1 NaN or infinite pixels")):
        assert main(["metric", "flip", str(tmp_path / name), str(b)]) == 2
        err = capsys.readouterr().err
        assert f"{str(tmp_path / name)!r}: {said}" in err and "Traceback" not in err, err


def test_metric_reads_16_bit_rgb_pngs_with_all_16_bits(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                      monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """A 16-bit RGB PNG (Blender's, a path tracer's) is compared with all 16 bits a channel: two renders that differ
    below the top 8 bits are not identical (Pillow reads such a file with the top 8 only, and PSNR was infinite).
    Without pypng the file is read as Pillow reads it, with a warning; a damaged one is refused in words."""
    import png

    rng = np.random.default_rng(16)
    ref = rng.integers(0, 65536, (24, 40, 3), dtype=np.uint16)
    low = ref ^ rng.integers(0, 256, ref.shape, dtype=np.uint16)  # (only the low byte changes)
    paths = {}
    for name, a in (("ref", ref), ("low", low)):
        paths[name] = tmp_path / f"{name}.png"
        with open(paths[name], "wb") as f:
            png.Writer(40, 24, greyscale=False, bitdepth=16).write(f, a.reshape(24, -1))
    assert main(["metric", "psnr", str(paths["ref"]), str(paths["low"]), "--tile", "8", "--json"]) == 0
    got = np.array(json.loads(capsys.readouterr().out)["tiles"], float)
    mse = (((ref.astype(float) - low) / 65535) ** 2).reshape(3, 8, 5, 8, 3).mean(axis=(1, 3, 4))
    np.testing.assert_allclose(got, -10 * np.log10(mse), atol=1e-3)  # (about 60 dB: differences of 1/256 at most)
    monkeypatch.setitem(sys.modules, "png", None)  # (pypng not installed)
    caplog.set_level("WARNING", logger="rtp")
    assert main(["metric", "psnr", str(paths["ref"]), str(paths["low"]), "--tile", "8", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["tiles"] == [[None] * 5] * 3  # (the same top 8 bits: identical)
    assert "a 16-bit RGB PNG, read with 8 bits a channel (pip install pypng to read all 16)" in caplog.text
    monkeypatch.undo()
    data = paths["ref"].read_bytes()
    cut = tmp_path / "cut.png"
    cut.write_bytes(data[: len(data) // 2])
    assert main(["metric", "psnr", str(cut), str(paths["low"])]) == 2
    err = capsys.readouterr().err
    assert f"{str(cut)!r}: not an image Pillow can read (a damaged 16-bit PNG" in err and "Traceback" not in err, err


def test_scenes_list_shows_each_maps_split_and_cache_state(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp scenes list`: every map of scenes.yaml in split order with what the cache holds of it
    (fetched, converted or nothing), a count, and the hint to fetch when nothing is; --json the same rows."""
    from rtp.capture.scenes import load_splits
    from rtp.capture.scenes._fetch import INDEX_VERSION, _cache_path

    splits = load_splits()
    names = splits["train"] + splits["validation"] + splits["test"]
    cache = tmp_path / "cache"
    for fetched in (False, True):
        if fetched:  # an index naming two maps, the second also converted
            cache.mkdir()
            (cache / "index.json").write_text(json.dumps({"version": INDEX_VERSION, "groups": {},
                                                          "maps": {names[0]: "a.pk3", names[-1]: "b.pk3"}}))
            _cache_path(names[-1], cache).parent.mkdir()
            _cache_path(names[-1], cache).write_bytes(b"")
        want = {names[0]: "fetched", names[-1]: "converted"} if fetched else {}
        assert main(["scenes", "list", "--cache-dir", str(cache)]) == 0
        lines = capsys.readouterr().out.splitlines()
        assert lines[0].split() == ["map", "split", "cache", f"({cache})"]
        rows = [line.split() for line in lines[1:-1]]
        assert rows == [[m, s, want.get(m, "-")] for s in ("train", "validation", "test") for m in splits[s]]
        assert lines[-1] == f"{len(names)} maps, " + ("2 fetched" if fetched else "0 fetched: run `rtp scenes fetch`")
        assert main(["scenes", "list", "--cache-dir", str(cache), "--json"]) == 0
        assert [(r["name"], r["split"], r["fetched"], r["converted"]) for r in json.loads(capsys.readouterr().out)] == [
            (m, s, m in want, want.get(m) == "converted") for s in ("train", "validation", "test") for m in splits[s]]


def test_a_literal_double_dash_after_the_options_end_is_a_value(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """After the `--` that ends the options, a second `--` is a value (POSIX): here an image path that
    does not exist, not the empty list Python 3.11's argparse passed on (Pillow's open([]) raised)."""
    a, _, _, _ = _image_pair(tmp_path)
    assert main(["metric", "flip", "--", "--", str(a)]) == 2
    err = capsys.readouterr().err
    assert "'--': no such image" in err and "Traceback" not in err
    assert main(["metric", "flip", "--", str(a), "--json"]) == 2  # ("--json" is a path here too)
    assert "'--json': no such image" in capsys.readouterr().err


def test_a_device_torch_cannot_use_is_said_with_its_flag(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp targets --device cuda` and `rtp train --device cuda` on a CPU build of torch said "error: device
    'cuda': ...", naming no flag, where every other flag's error names it ("--scene: ...", "--allowed: ...")."""
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(torch.version, "cuda", None)
    out = tmp_path / "m.pt"
    for argv in (["targets", str(tmp_path / "ds"), "--metrics", "flip", "--device", "cuda"],
                 ["train", "--data", str(tmp_path / "ds"), "--metric", "jnyang", "--out", str(out), "--device", "cuda"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert f"rtp {argv[0]}: error: --device 'cuda': torch {torch.__version__} is a CPU build" in err, err
    assert not out.exists() and not (tmp_path / "ds").exists()


def test_targets_ppd_width_of_narrow_frames_is_refused_in_the_flags_words(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp targets --ppd width` on a dataset of frames under 58 pixels wide (under FLIP's 1 ppd) said the library's
    "ppd='width' ...: for a crop pass ppd=ppd_from_width(...)", after it had declared 'width' in the targets'
    manifest, at the first sample's FLIP. Refused before anything is written, in the command line's words (as `rtp
    metric` says it: one function words both); the library's compute_targets in Python's."""
    from rtp import metrics
    from rtp.capture import DatasetWriter, compute_targets

    from .test_dataset import _buffers

    for settings in ({"size": [40, 24]}, None):  # (without a size in the manifest: the first sample's)
        ds = tmp_path / f"ds{settings is None}"
        DatasetWriter(ds, settings).write("a", _buffers(24, 40), {})
        assert main(["targets", str(ds), "--metrics", "flip", "--ppd", "width"]) == 2
        err = capsys.readouterr().err
        assert ("rtp targets: error: --ppd width of a 40-pixel-wide image is 0.698 pixels per degree, outside FLIP's "
                "[1, 1000]: give --ppd a number instead") in err, err
        assert "ppd=" not in err, err
        with pytest.raises(metrics.MetricParameterError, match=r"^ppd='width' of a 40-pixel-wide image .* pass "
                                                               r"ppd=ppd_from_width"):
            compute_targets(ds, ["flip"], ppd="width")
        assert not (ds / "targets").exists()  # (nothing declared: a later run with a number is not refused by it)


def test_the_commands_errors_tell_the_user_to_run_quote_the_dataset_path(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """"run `rtp targets my data`" (a dataset folder with a space) named two folders when copied into a shell, as
    every command rtp tells its user to run did: their paths are quoted for a shell now."""
    import shlex

    from rtp.capture import DatasetWriter, TargetError, TargetStore

    from .test_dataset import _buffers

    ds = tmp_path / "my data" / "it's"
    DatasetWriter(ds, {"size": [40, 24]}).write("a", _buffers(24, 40), {})

    def command(text: str) -> list[str]:
        return shlex.split(re.search(r"run `(rtp [^`]*)`", text)[1])  # type: ignore[index]

    with pytest.raises(TargetError) as info:  # (what rtp train and rtp evaluate meet on a sample without targets)
        TargetStore(ds).load("a", "jnyang", 4)
    assert command(str(info.value)) == ["rtp", "targets", str(ds)], info.value
    assert main(["train", "--data", str(ds), "--metric", "jnyang", "--out", str(tmp_path / "m.pt"), "--steps", "1"]) == 2
    err = capsys.readouterr().err
    assert command(err) == ["rtp", "targets", str(ds), "--metrics", "jnyang"], err


def test_metric_out_naming_an_input_image_is_refused_before_any_work(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp metric flip ref.png test.png --out test.png` (or the reference, under another spelling of its path)
    replaced the image compared with the map, exit 0: refused, exit 2, the image as it was."""
    a, b, _, _ = _image_pair(tmp_path)
    monkeypatch.chdir(tmp_path)
    before = {p: p.read_bytes() for p in (a, b)}
    for out, which in ((str(b), "test"), (f"./{b.name}", "test"), (str(tmp_path / "." / a.name), "reference")):
        assert main(["metric", "psnr", str(a), str(b), "--out", out]) == 2, out
        got = capsys.readouterr()
        assert f"rtp metric: error: --out {out!r} is the {which} image itself" in got.err and got.out == "", got
        assert {p: p.read_bytes() for p in (a, b)} == before
    assert main(["metric", "psnr", str(a), str(b), "--out", "map.png"]) == 0 and (tmp_path / "map.png").is_file()


def test_preview_out_naming_a_file_of_a_sample_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The paper's layout keeps each sample's buffers as PNGs: `rtp preview DATA --out DATA/0000/output_1x1.png`
    replaced the sample's full-rate image with the sheet (exit 0), and every later read of the sample failed on its
    size. Refused, exit 2, the file as it was; a new file beside the dataset is written as before."""
    from rtp import sdk
    from rtp.capture._dataset import write_png

    folder = tmp_path / "Bistro ü" / "0000"
    rng = np.random.default_rng(0)
    for stem in ["reproject_1x1", "diffuse_1x1", "specular_1x1", "emissive_1x1", "normals_1x1", "extra_1x1",
                 *(f"output_{r}" for r in sdk.ALL_RATES)]:
        write_png(folder / f"{stem}.png", rng.integers(0, 256, (24, 32, 4), dtype=np.uint8))
    target = folder / "output_1x1.png"
    before = target.read_bytes()
    assert main(["preview", str(folder.parent), "--out", str(target)]) == 2
    got = capsys.readouterr()
    assert f"rtp preview: error: --out {str(target)!r} is a file of sample '0000' of " in got.err and got.out == ""
    assert target.read_bytes() == before
    assert main(["preview", str(folder.parent), "--out", str(tmp_path / "sheet.png")]) == 0
    assert (tmp_path / "sheet.png").is_file()


def test_a_sidecar_or_split_list_that_is_no_file_is_a_usage_error_naming_its_flag(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--metadata ""` said "'': cannot be read as a UTF-8 YAML sidecar (Is a directory: '.')" and `--splits ""` or
    `--splits FOLDER` "split file not found: ." or of a folder that is there: each is a usage error of its flag."""
    for argv, flag, value, said in ((["info", "jnyang", "--metadata"], "--metadata", "", "expected a path, got ''"),
                                    (["info", "jnyang", "--metadata"], "--metadata", str(tmp_path), "is a folder"),
                                    (["scenes", "list", "--splits"], "--splits", "", "expected a path, got ''"),
                                    (["scenes", "list", "--splits"], "--splits", str(tmp_path), "is a folder")):
        with pytest.raises(SystemExit) as info:
            main([*argv, value, "--cache-dir", str(tmp_path)] if argv[0] == "scenes" else [*argv, value])
        assert info.value.code == 2
        err = capsys.readouterr().err
        assert f"error: argument {flag}: " in err and said in err and "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("missing", ["PIL", "matplotlib"])
def test_an_image_output_without_the_picture_packages_is_one_line_before_any_work(
        missing: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """On the runtime install (no Pillow) `rtp preview --out`, `rtp metric --out` and `rtp adapters check --image`
    ended in a ModuleNotFoundError traceback while the arguments were parsed (the argument's type imported Pillow to
    check the extension); without matplotlib, `rtp metric --out` computed the metric first. Each says what to install
    in one line, exit 2, before any work, writing nothing."""
    import importlib.abc

    class NotInstalled(importlib.abc.MetaPathFinder):
        def find_spec(self, name: str, path: object, target: object = None) -> None:
            if name.partition(".")[0] == missing:
                raise ModuleNotFoundError(f"No module named {missing!r}", name=missing)

    a, b, _, _ = _image_pair(tmp_path)
    (tmp_path / "data").mkdir()
    out = tmp_path / "out.png"
    with monkeypatch.context() as m:
        for module in [k for k in sys.modules if k.partition(".")[0] == missing]:
            m.delitem(sys.modules, module)
        m.setattr(sys, "meta_path", [NotInstalled(), *sys.meta_path])
        for argv in (["preview", str(tmp_path / "data"), "--out", str(out)],
                     ["metric", "psnr", str(a), str(b), "--out", str(out)],
                     ["adapters", "check", "moderngl", "--image", str(out)]):
            assert main(argv) == 2, argv
            got = capsys.readouterr()
            assert got.err == f"rtp {' '.join(argv[:2]) if argv[0] == 'adapters' else argv[0]}: error: this needs " \
                              f"{missing}, which is not installed: pip install 'rtp[capture]'\n", got.err
            assert got.out == "" and not out.exists(), argv


@pytest.mark.parametrize(("missing", "said"), [
    (("moderngl", "PIL", "matplotlib", "flip_evaluator"), "moderngl, Pillow, matplotlib and flip-evaluator, which are"),
    (("matplotlib",), "matplotlib, which is"),
    (("PIL",), "Pillow, which is"),
])
def test_demo_and_play_without_the_capture_extra_name_it_once_before_any_work(
        missing: tuple[str, ...], said: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """On the runtime install (README: the demo needs rtp[capture]) `rtp demo` named flip-evaluator alone (`pip
    install flip-evaluator==1.7`), then, with it, moderngl (`rtp[moderngl]`), then, after rendering and predicting,
    matplotlib; `rtp play` without Pillow or matplotlib drew its first path's frames and then ended on its GIF. Each
    names everything it lacks and rtp[capture] in one line, exit 2, before any work: nothing written."""
    import importlib.abc

    class NotInstalled(importlib.abc.MetaPathFinder):
        def find_spec(self, name: str, path: object, target: object = None) -> None:
            top = name.partition(".")[0]
            if top in missing:
                raise ModuleNotFoundError(f"No module named {top!r}", name=top)

    out = tmp_path / "out"
    with monkeypatch.context() as m:
        for module in [k for k in sys.modules if k.partition(".")[0] in missing]:
            m.delitem(sys.modules, module)
        m.setattr(sys, "meta_path", [NotInstalled(), *sys.meta_path])
        for argv in (["demo", "--size", "64x48", "--frames", "2", "--out", str(out)],
                     ["play", "procedural:0", "--frames", "4", "--size", "64x48", "--no-sweep", "--flip-every", "2",
                      "--methods", "jnyang", "--out", str(out)]):
            assert main(argv) == 2, argv
            got = capsys.readouterr()
            assert got.err == f"rtp {argv[0]}: error: this needs {said} not installed: pip install 'rtp[capture]'\n", \
                got.err
            assert got.out == "" and not out.exists(), argv


def test_a_missing_module_of_an_installed_package_is_not_taken_for_a_missing_extra(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """require_extra names an extra for the optional modules it was asked for; an installed one whose own import
    fails on a module of no extra (a broken install) keeps its error, with the module it lacks."""
    import importlib

    from rtp.cli._run import require_extra

    def broken(name: str, package: str | None = None) -> object:
        raise ModuleNotFoundError("No module named 'kiwisolver'", name="kiwisolver")

    monkeypatch.setattr(importlib, "import_module", broken)
    with pytest.raises(ModuleNotFoundError, match="kiwisolver"):
        require_extra("rtp[capture]", ["matplotlib"])


def test_a_missing_flip_evaluator_or_torch_names_the_smallest_extra(capsys: pytest.CaptureFixture[str]) -> None:
    """flip-evaluator missing where no rtp module wrapped it named rtp[metrics], which pulls torch (gigabytes), where
    rtp[capture] brings it without; a missing torch named its extra alone, and a bare torch pin from public PyPI
    may be the CUDA build: it says where the CPU one comes from (README, Set-up)."""
    from rtp.cli._run import run_guarded

    def fails(name: str) -> Callable[[], int]:
        def command() -> int:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return command

    assert run_guarded("rtp targets", fails("flip_evaluator")) == 2
    assert capsys.readouterr().err == ("rtp targets: error: this needs flip_evaluator, which is not installed: "
                                       "pip install 'rtp[capture]'\n")
    assert run_guarded("rtp train", fails("torch")) == 2
    assert capsys.readouterr().err == ("rtp train: error: this needs torch, which is not installed: pip install "
                                       "'rtp[train]'; torch from public PyPI may be its CUDA build, gigabytes: for the "
                                       "CPU build add --extra-index-url https://download.pytorch.org/whl/cpu (README, "
                                       "Set-up)\n")


def test_targets_of_an_empty_dataset_path_are_refused_not_the_current_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp targets ""` (an unset shell variable) read the current folder as the dataset (". is not an rtp
    dataset"; in a dataset's own folder it computed its targets), as compute_targets("") did: refused, as an
    empty --out is."""
    from rtp import sdk
    from rtp.capture import compute_targets

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(["targets", "", "--metrics", "psnr"])
    assert info.value.code == 2
    assert "argument DATA: expected a path, got '' (empty; '.' is the current folder)" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:  # (--data, as rtp train and rtp evaluate name it, likewise)
        main(["targets", "--data", "", "--metrics", "psnr"])
    assert info.value.code == 2
    assert "argument --data: expected a path, got '' (empty; '.' is the current folder)" in capsys.readouterr().err
    with pytest.raises(sdk.ParameterError, match=r"data_root: expected a dataset folder path, got '' \(empty"):
        compute_targets("", ("psnr",))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv", [["preview", "", "--out", "sheet.png"], ["evaluate", "jnyang", "--data", ""]])
def test_an_empty_dataset_path_is_refused_not_read_as_the_current_folder(
        argv: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp preview ""` and `rtp evaluate M --data ""` (an unset shell variable) read the current folder ("." is
    not an rtp dataset; in a dataset's own folder, that dataset), as `rtp targets ""` did."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert "expected a path, got '' (empty; '.' is the current folder)" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# -- the Makefile's commands: what `make X VAR=...` runs, read with `make -n` (nothing is run) ---------------

def _make_runs(*args: str) -> list[list[str]]:
    """The rtp and rtp-export commands ``make -n ARGS`` would run, each split as the shell splits it."""
    import shlex
    import shutil
    import subprocess

    make = shutil.which("make")
    if make is None:
        pytest.skip("no make on this machine")
    done = subprocess.run([make, "-n", "--no-print-directory", *args], cwd=Path(__file__).resolve().parents[1],
                          capture_output=True, text=True, check=True)
    return [argv for argv in map(shlex.split, done.stdout.splitlines())
            if argv and Path(argv[0]).name in ("rtp", "rtp-export")]


def _after(argv: list[str], flag: str) -> str:
    return argv[argv.index(flag) + 1]


def test_make_passes_its_variables_to_the_commands_whole() -> None:
    """`make dataset RAY=HOST:PORT` gave a cluster's capture and targets a fixed --workers 2 (two of its
    CPUs; Ray's own default is one worker per CPU); a DATA, RECIPE or NAME holding a space was split into two
    arguments; `make play MAP=scenes/room.glb` wrote its pictures to data/play-scenes/room.glb/, and
    `MAP="my scenes/room.glb"` to data/play-my room/."""
    local = _make_runs("dataset", "DATA=my data")
    assert len(local) == 6 and all(_after(a, "--workers") == "2" and "--ray" not in a for a in local[1:])
    assert [_after(a, "--out") for a in local if a[1] == "capture"] == ["my data/train", "my data/train", "my data/test"]
    assert [a[2] for a in local if a[1] == "targets"] == ["my data/train", "my data/test"]
    for ray, address in (("RAY=1", "--out"), ("RAY=head:6379", "head:6379")):  # (RAY=1: --ray alone)
        jobs = _make_runs("dataset", ray)[1:]
        assert len(jobs) == 5 and all("--workers" not in a for a in jobs), jobs
        assert all(_after([*a, "--out"], "--ray") == address for a in jobs), jobs
    assert all(_after(a, "--workers") == "8" for a in _make_runs("dataset", "RAY=1", "WORKERS=8")[1:])
    # (RAY=0 is off, as no RAY: it ran `--ray 0`, an address Ray cannot reach)
    assert _make_runs("dataset", "RAY=0", "DATA=my data") == local
    train, export = _make_runs("train", "METRIC=jnyang", "RECIPE=my recipe.yaml", "NAME=my model", "STEPS=5",
                               "DATA=my data")
    assert (_after(train, "--config"), _after(train, "--steps"), _after(train, "--out")) == (
        "my recipe.yaml", "5", "my data/my model.pt")
    assert export[1:] == ["my data/my model.pt", "-o", "models/my model.onnx"]
    [evaluate] = _make_runs("evaluate", "NAME=my model", "DATA=my data")
    assert evaluate[2] == "models/my model.onnx" and _after(evaluate, "--out") == "my data/eval-my model"
    for scene, fetched, out in (("20kdm2", True, "d/play-20kdm2"), ("procedural:3", False, "d/play-procedural:3"),
                                ("scenes/room.glb", False, "d/play-room"), ("/abs/hall.gltf", False, "d/play-hall"),
                                # make's notdir and basename split on spaces: a folder with one gave "play-my room"
                                ("my scenes/room.glb", False, "d/play-room"),
                                ("my scenes/big hall.v2.obj", False, "d/play-big hall.v2")):
        runs = _make_runs("play", f"MAP={scene}", "DATA=d")
        assert (runs[0][1:] == ["scenes", "fetch", "--map", scene]) == fetched, runs
        assert runs[-1][2] == scene and _after(runs[-1], "--out") == out, runs


def test_make_play_plays_every_scene_file_rtp_play_reads(tmp_path: Path) -> None:
    """rtp play reads a .glb, .gltf or .obj in any case and any file that is there (a PLY: what trimesh reads); `make
    play` took only a lowercase .glb/.gltf/.obj for a file, so MAP=Room.GLB or MAP=room.ply went to `rtp scenes fetch
    --map`, which refuses a name no split lists, and the play never ran."""
    (tmp_path / "my scenes").mkdir()
    for name in ("room.ply", "my scenes/hall.stl"):
        (tmp_path / name).write_bytes(b"")
    for scene, out in ((f"{tmp_path}/Room.GLB", "d/play-Room"), (f"{tmp_path}/hall.Gltf", "d/play-hall"),
                       (f"{tmp_path}/x.OBJ", "d/play-x"), (f"{tmp_path}/room.ply", "d/play-room"),
                       (f"{tmp_path}/my scenes/hall.stl", "d/play-hall")):
        [run] = _make_runs("play", f"MAP={scene}", "DATA=d")
        assert run[1:3] == ["play", scene] and _after(run, "--out") == out, run
    # a name that is no file and no mesh extension is a map's, fetched first (which refuses one no split lists)
    gone = f"{tmp_path}/gone.ply"
    fetch, run = _make_runs("play", f"MAP={gone}", "DATA=d")
    assert fetch[1:] == ["scenes", "fetch", "--map", gone] and run[2] == gone


def test_adapters_check_reads_a_map_from_the_cache_dir_given(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp adapters check --scene MAP` read only the default scene cache: it had no --cache-dir, which every other
    command that reads maps takes ("unrecognized arguments"). It takes it now, with their default and help."""
    from rtp.cli import build_parser

    default, given = tmp_path / "default-cache", tmp_path / "my cache"
    monkeypatch.setenv("RTP_SCENE_CACHE", str(default))
    assert main(["adapters", "check", "moderngl", "--scene", "oa_dm1", "--cache-dir", str(given)]) == 2
    err = capsys.readouterr().err
    assert f"no scene index at {given / 'index.json'}" in err and str(default) not in err, err
    assert main(["adapters", "check", "moderngl", "--scene", "oa_dm1"]) == 2
    assert f"no scene index at {default / 'index.json'}" in capsys.readouterr().err

    def option(*command: str) -> Any:
        parser: Any = build_parser()
        for name in command:
            parser = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction").choices[name]
        return next(a for a in parser._actions if a.dest == "cache_dir")

    ours, theirs = option("adapters", "check"), option("capture")
    assert (ours.default, ours.help, ours.type) == (theirs.default, theirs.help, theirs.type) == \
        (str(default), theirs.help, theirs.type)
