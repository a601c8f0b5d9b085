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


def test_demo_without_a_model_says_what_ships(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert rtp_main(["demo", "--model", "no_such_model", "--out", str(tmp_path / "d")]) == 2
    assert "no model file" in capsys.readouterr().err


def test_a_demo_of_more_frames_than_a_path_may_have_is_refused_before_loading(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--frames 1000000000` rendered the camera move frame by frame, for days, without a word."""
    assert rtp_main(["demo", "--model", "no_such_model", "--frames", "36001", "--out", str(tmp_path / "d")]) == 2
    assert capsys.readouterr().err.strip() == "rtp demo: error: frames: expected an integer in [1, 36000], got 36001"
    assert not (tmp_path / "d").exists()
