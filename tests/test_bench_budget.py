"""bench/budget.py: its table holds every frame size on both tile sizes, each row's rates saving the share asked."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_budget_bench_prints_a_row_a_frame_and_tile_size() -> None:
    out = subprocess.run([sys.executable, "bench/budget.py", "--repeats", "1", "--saving", "0.6"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300, check=True).stdout
    rows = [line.split("|")[1:-1] for line in out.splitlines() if line.startswith("| ") and "x" in line.split("|")[1]]
    assert [(r[0].strip(), r[2].strip()) for r in rows] == [
        (f, t) for t in ("16px", "8px") for f in ("1280x720", "1920x1080", "3840x2160")]
    assert all(float(r[6].strip().rstrip("%")) >= 60.0 for r in rows)
    assert all(float(r[3]) > 0 and float(r[4]) > 0 and float(r[7]) > 0 and float(r[8]) > 0 for r in rows)


def test_the_budget_bench_times_the_gpu_decision_with_gpu() -> None:
    """--gpu: a second table, RateSelector's decision and budget on OpenGL, its rates saving the share asked."""
    out = subprocess.run([sys.executable, "bench/budget.py", "--repeats", "1", "--saving", "0.6", "--gpu"], cwd=ROOT,
                         capture_output=True, text=True, timeout=600, check=True).stdout
    _, gpu = out.split("RateSelector on ", 1)
    rows = [line.split("|")[1:-1] for line in gpu.splitlines() if line.startswith("| ") and "x" in line.split("|")[1]]
    assert [(r[0].strip(), r[2].strip()) for r in rows] == [
        (f, t) for t in ("16px", "8px") for f in ("1280x720", "1920x1080", "3840x2160")]
    assert all(float(r[6].strip().rstrip("%")) >= 60.0 and float(r[3]) > 0 and float(r[4]) > 0 for r in rows)
