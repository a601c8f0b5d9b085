"""bench/memory.py: a row per shipped model, each measured in a process of its own, in both tables (memory, then
the time of the load and the first runs)."""

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
    memory, times = out.stdout.split("Time (ms)")
    rows, timed = ({line.split("|")[1].strip(): [c.strip() for c in line.strip("|").split("|")[1:]]
                    for line in text.splitlines() if line.startswith("| ") and not line.startswith("| model")}
                   for text in (memory, times))
    assert sorted(rows) == sorted(timed) == sorted(n.removesuffix(".onnx") for n in sdk.shipped_models())
    for name, (load, *sizes) in timed.items():  # the load, then three timed runs at each size
        assert float(load) > 0 and len(sizes) == 2, name
        assert all(len(c.split(" / ")) == 3 and min(float(v) for v in c.split(" / ")) > 0 for c in sizes), name
    for name, (library, session, *sizes) in rows.items():
        assert float(library) >= 0 and float(session) > 0, name  # building a session takes memory
        planes = len(sdk.load(name).metadata.inputs)
        inputs = [float(c.split("(")[1].rstrip(")")) for c in sizes]
        assert inputs == [round(planes * 512 * 512 * 4 / 2**20), round(planes * 1024 * 512 * 4 / 2**20)]
    bad = subprocess.run([sys.executable, str(BENCH), "--sizes", "64by64"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "WIDTHxHEIGHT" in bad.stderr


def test_a_warm_up_runs_before_the_timed_runs() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "--sizes", "256x256", "--warm-up", "1", "jnyang"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "first 3 timed `predict` calls at each size in turn, after 1 on a zero frame" in out.stdout
    bad = subprocess.run([sys.executable, str(BENCH), "--warm-up", "-1"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "argument --warm-up: expected an integer >= 0" in bad.stderr
