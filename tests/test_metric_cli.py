"""`rtp metric`: what it computes for an image pair (more in tests/test_cli.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rtp import metrics as M
from rtp.cli import main


def test_metric_computes_the_map_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp metric flip` computed FLIP twice (tile_metric, then error_map for the per-pixel line): twice the
    seconds of a 1080p pair, LPIPS likewise. Its tiles are still tile_metric's."""
    from PIL import Image

    import rtp.metrics._flip as F
    import rtp.metrics._maps as maps
    import rtp.metrics._targets as targets

    rng = np.random.default_rng(1)
    ref = (rng.random((40, 50, 3)) * 255).astype(np.uint8)
    test = np.clip(ref.astype(int) + rng.integers(-30, 31, ref.shape), 0, 255).astype(np.uint8)
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    Image.fromarray(ref).save(a)
    Image.fromarray(test).save(b)
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
        want = M.tile_metric(metric, ref.astype(np.float32) / 255, test.astype(np.float32) / 255, 8)
        np.testing.assert_array_equal(np.array(got["tiles"], np.float32), want)
