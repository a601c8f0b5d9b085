"""bench/input_planes.py: sdk.input_planes' time for every shipped model's planes, next to its predict."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from rtp import sdk

BENCH = Path(__file__).resolve().parents[1] / "bench" / "input_planes.py"


@pytest.mark.gl
def test_a_row_per_shipped_model() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "--sizes", "64x48,80x48", "--repeats", "1"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    rows = [line for line in out.stdout.splitlines() if re.match(r"\| [\w-]+ \| \d+ \|( [\d.]+ \|){4}$", line)]
    names = {row.split(" | ")[0].removeprefix("| ") for row in rows}
    assert names == {m.removesuffix(".onnx") for m in sdk.shipped_models()}, out.stdout
    assert re.search(r"^\| \(sdk\.reproject alone\) \| 4 \| [\d.]+ \|  \| [\d.]+ \|  \|$", out.stdout, re.M), out.stdout
    bad = subprocess.run([sys.executable, str(BENCH), "--sizes", "big"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--sizes" in bad.stderr


@pytest.mark.gl
@pytest.mark.slow
def test_against_a_revision_compares_the_reprojections() -> None:
    """--against REV: this checkout's reproject against git REV's, timed and compared on rendered frames (against
    HEAD itself: nothing differs)."""
    out = subprocess.run([sys.executable, str(BENCH), "--against", "HEAD", "--sizes", "32x32", "--repeats", "1"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
    assert re.search(r"^\| 32x32 \| [\d.]+ \| [\d.]+ \|$", out.stdout, re.M), out.stdout
    assert "seen differs on 0, the colour where seen agrees on 0 values; positions within 0 px" in out.stdout
    bad = subprocess.run([sys.executable, str(BENCH), "--against", "no-such-revision"], capture_output=True, text=True,
                         timeout=120)
    assert bad.returncode == 1 and "git cannot show sdk/_reproject.py there" in bad.stderr
