"""bench/memory.py: a row per shipped model, each measured in a process of its own."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from rtp import sdk

BENCH = Path(__file__).resolve().parents[1] / "bench" / "memory.py"


def test_a_row_per_model_with_the_input_planes_beside_each_size() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "--sizes", "512x512,1024x512"], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.strip("|").split("|")[1:]]
            for line in out.stdout.splitlines() if line.startswith("| ") and not line.startswith("| model")}
    assert sorted(rows) == sorted(n.removesuffix(".onnx") for n in sdk.shipped_models())
    for name, (library, session, *sizes) in rows.items():
        assert float(library) >= 0 and float(session) > 0, name  # building a session takes memory
        planes = len(sdk.load(name).metadata.inputs)
        inputs = [float(c.split("(")[1].rstrip(")")) for c in sizes]
        assert inputs == [round(planes * 512 * 512 * 4 / 2**20), round(planes * 1024 * 512 * 4 / 2**20)]
    bad = subprocess.run([sys.executable, str(BENCH), "--sizes", "64by64"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "WIDTHxHEIGHT" in bad.stderr
