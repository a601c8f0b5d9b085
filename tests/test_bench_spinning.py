"""bench/spinning.py: the three tables of what onnxruntime's spinning threads cost around a predictor."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from rtp import sdk

BENCH = Path(__file__).resolve().parents[1] / "bench" / "spinning.py"


def test_the_tables_have_a_row_per_model_and_setting_and_the_default_leaves_the_cores_idle(tmp_path: Path) -> None:
    png = tmp_path / "spinning.png"
    out = subprocess.run([sys.executable, str(BENCH), "--size", "256x144", "--repeats", "3", "--blocks", "1",
                          "--long-ms", "100", "--plot", str(png)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    models = [n.removesuffix(".onnx") for n in sdk.shipped_models()]
    after = [line for line in out.stdout.splitlines() if re.match(r"\| [\w-]+ \| (stop|spin)", line)]
    assert sorted({row.split(" | ")[0][2:] for row in after}) == sorted(models) and len(after) == 2 * len(models)
    for row in after:  # the SDK's default: the threads stop when the run returns, the process idles
        cells = [c.strip() for c in row.strip("|").split("|")]
        if cells[1].startswith("stop"):
            assert float(cells[5]) < 5.0 and float(cells[6]) < 5.0, row
    lines = out.stdout.splitlines()
    engine = [line for line in lines if re.match(r"\| (stop|spin)[^|]*\| 1 \|( [\d.]+ \|){3}$", line)]
    assert len(engine) == 2
    cells = r"( [\d.]+ \|){" + str(len(models)) + "}$"  # a column per shipped model
    in_turn = [line for line in lines if re.match(r"\| (stop|spin)[^|]*\| 1 \|" + cells, line)]
    assert len(in_turn) == 2 and len(models) >= 6
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f"wrote {png}" in out.stdout
    bad = subprocess.run([sys.executable, str(BENCH), "--repeats", "0"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--repeats" in bad.stderr
