"""bench/pyrender_adapter.py: the pyrender adapter's inputs for every shipped model, in a frame loop and on a
first frame."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from rtp import sdk

BENCH = Path(__file__).resolve().parents[1] / "bench" / "pyrender_adapter.py"


@pytest.mark.gl
def test_a_row_per_shipped_model() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "--sizes", "64x48", "--repeats", "1"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    rows = [line for line in out.stdout.splitlines() if re.match(r"\| [\w-]+ \| \d+ \| [\d.]+ \| [\d.]+ \|$", line)]
    assert {row.split(" | ")[0].removeprefix("| ") for row in rows} == {
        m.removesuffix(".onnx") for m in sdk.shipped_models()}, out.stdout
    bad = subprocess.run([sys.executable, str(BENCH), "--repeats", "0"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--repeats" in bad.stderr
