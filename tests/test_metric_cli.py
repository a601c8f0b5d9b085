"""`rtp metric`: what it computes for an image pair (more in tests/test_cli.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rtp import metrics as M
from rtp.cli import main


def _pair(tmp_path: Path, seed: int = 2, width: int = 70) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    """Two 8-bit PNGs 40 pixels high, a random image and a noisy copy, and their values in [0, 1]."""
    from PIL import Image

    rng = np.random.default_rng(seed)
    ref = (rng.random((40, width, 3)) * 255).astype(np.uint8)
    test = np.clip(ref.astype(int) + rng.integers(-30, 31, ref.shape), 0, 255).astype(np.uint8)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    Image.fromarray(ref).save(a)
    Image.fromarray(test).save(b)
    return a, b, ref.astype(np.float32) / 255, test.astype(np.float32) / 255


def test_metric_computes_the_map_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp metric flip` computed FLIP twice (tile_metric, then error_map for the per-pixel line): twice the
    seconds of a 1080p pair, LPIPS likewise. Its tiles are still tile_metric's."""
    import rtp.metrics._flip as F
    import rtp.metrics._maps as maps
    import rtp.metrics._targets as targets

    a, b, ref, test = _pair(tmp_path, seed=1, width=50)
    calls: list[int] = []
    real = F.flip_pixels

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        return real(*args, **kwargs)

    for mod in (F, maps, targets):
        monkeypatch.setattr(mod, "flip_pixels", counted)
    for metric in ("flip", "jnflip"):
        calls.clear()
        assert main(["metric", metric, str(a), str(b), "--tile", "8", "--json"]) == 0
        got = json.loads(capsys.readouterr().out)
        assert len(calls) == 1, metric
        want = M.tile_metric(metric, ref, test, 8)
        np.testing.assert_array_equal(np.array(got["tiles"], np.float32), want)


@pytest.mark.parametrize(("metric", "flags", "params"), [
    ("flip", ["--ppd", "30"], {"ppd": 30.0}),
    ("flip", ["--ppd", "width"], {"ppd": M.ppd_from_width(70)}),
    ("jnflip", ["--ppd", "40", "--weber-l", "0.5"], {"ppd": 40.0, "weber_l": 0.5}),
    ("jnyang", ["--weber-l", "0.1"], {"weber_l": 0.1}),
])
def test_metric_takes_the_targets_parameters(tmp_path: Path, capsys: pytest.CaptureFixture[str], metric: str,
                                             flags: list[str], params: dict[str, float]) -> None:
    """`rtp metric` computed FLIP at 67.02 ppd and the JN metrics at l = 0.02 whatever the targets were computed
    with (`rtp targets --ppd/--weber-l`): a pair could not be checked against a dataset's targets. The values used
    are printed and in the JSON."""
    a, b, ref, test = _pair(tmp_path)
    assert main(["metric", metric, str(a), str(b), "--tile", "8", "--json", *flags]) == 0
    got = json.loads(capsys.readouterr().out)
    want = M.tile_metric(metric, ref, test, 8, **params)  # type: ignore[arg-type]
    np.testing.assert_array_equal(np.array(got["tiles"], np.float32), want)
    assert not np.array_equal(want, M.tile_metric(metric, ref, test, 8))  # (the parameters change the values)
    for key, value in params.items():
        assert got[key] == pytest.approx(value)
    assert main(["metric", metric, str(a), str(b), "--tile", "8", *flags]) == 0
    out = capsys.readouterr().out
    assert all(f"{key} {value:.4g}" in out for key, value in params.items())


@pytest.mark.parametrize(("metric", "flags", "says"), [
    ("jnyang", ["--ppd", "30"], "only flip and jnflip"),
    ("psnr", ["--weber-l", "0.5"], "psnr does not use"),
    ("flip", ["--weber-l", "0.5"], "flip does not use"),
    ("flip", ["--ppd", "x"], "expected a number or 'width'"),
    ("flip", ["--ppd", "-3"], "--ppd"),
    ("jnyang", ["--weber-l", "0"], "--weber-l"),
])
def test_metric_parameters_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], metric: str,
                                   flags: list[str], says: str) -> None:
    """A parameter the metric does not take is refused, not ignored; a bad value is named."""
    a, b, _, _ = _pair(tmp_path)
    assert main(["metric", metric, str(a), str(b), *flags]) == 2
    captured = capsys.readouterr()
    assert says in captured.err and not captured.out


def test_metric_ppd_width_of_a_narrow_image_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--ppd width` of an image under 58 pixels wide (under 1 ppd) is refused as such, not as a number out of range."""
    from PIL import Image

    for name in ("a.png", "b.png"):
        Image.fromarray(np.full((40, 40, 3), 100 if name == "a.png" else 120, np.uint8)).save(tmp_path / name)
    assert main(["metric", "flip", str(tmp_path / "a.png"), str(tmp_path / "b.png"), "--ppd", "width"]) == 2
    err = capsys.readouterr().err
    # in the command line's words: its flag, not the library's "ppd='width'" and "pass ppd=ppd_from_width(...)"
    assert "--ppd width of a 40-pixel-wide image is 0.698 pixels per degree, outside FLIP's [1, 1000]" in err, err
    assert "give --ppd a number" in err and "ppd=" not in err, err


def test_metric_pair_of_two_sizes_refused_before_either_is_decoded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Two sizes were found after both images were decoded: a 1080p reference against an 8K test decoded 33 million
    pixels first (one past the machine's memory was "out of memory", exit 1, not the pair's mistake). The headers
    say it: no pixel is read. A pair of one size is still read and compared."""
    from PIL import Image

    import rtp.capture

    a, _, _, _ = _pair(tmp_path)
    Image.fromarray(np.zeros((30, 90, 3), np.uint8)).save(tmp_path / "other.png")
    real = rtp.capture.read_image_values
    decoded: list[str] = []

    def counted(path, *args, **kwargs):  # type: ignore[no-untyped-def]
        decoded.append(str(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(rtp.capture, "read_image_values", counted)
    assert main(["metric", "psnr", str(a), str(tmp_path / "other.png")]) == 2
    assert "the images differ in size: 70x40 and 90x30" in capsys.readouterr().err
    assert decoded == []
    assert main(["metric", "psnr", str(a), str(a), "--json"]) == 0
    assert decoded == [str(a), str(a)] and json.loads(capsys.readouterr().out)["metric"] == "psnr"


@pytest.mark.parametrize("size", [(1, 120), (120, 1), (3, 250)])
def test_metric_out_of_a_strip_is_a_picture_of_ordinary_size(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                             size: tuple[int, int]) -> None:
    """--out enlarged a pair under 300 pixels on its shorter side until that side was 300 pixels, whatever the
    longer: a 120x1 strip was drawn 36,000 pixels long (a 1000x1 one 300,160 pixels, 2.8 GB and 17 s; a 400x2
    one 60,160). Its longer side is now at most about 2,000 pixels, and the picture is still the map's."""
    from PIL import Image

    h, w = size
    rng = np.random.default_rng(3)
    ref = (rng.random((h, w, 3)) * 255).astype(np.uint8)
    for name, image in (("a.png", ref), ("b.png", 255 - ref)):
        Image.fromarray(image).save(tmp_path / name)
    out = tmp_path / "map.png"
    assert main(["metric", "flip", str(tmp_path / "a.png"), str(tmp_path / "b.png"), "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    with Image.open(out) as im:
        picture = np.asarray(im.convert("RGB"))
    assert max(picture.shape[:2]) <= 2200, picture.shape
    assert min(picture.shape[:2]) >= 60 and picture.std() > 10, picture.shape  # (a figure, not a blank or a line)
