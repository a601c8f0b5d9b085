"""bench/views.py: several views a frame (serial, batch, a thread per view) and shading_rates on a worker
thread beside Python."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "bench" / "views.py"


def test_a_row_per_model_every_way_the_same_predictions_and_a_row_per_threads_and_switch() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "jnyang", "jnflip", "--size", "256x144", "--rounds", "2",
                          "--seconds", "0.2", "--switch", "0.005,0.001"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    views = [line for line in out.stdout.splitlines() if re.match(r"\| (jnyang|jnflip) \| \d \|( [\d.]+ \|){4}$", line)]
    # every way gave the first way's predictions (a cell that differs reads "(differs!)" and fails the match)
    assert [row.split(" | ")[:2] for row in views] == [["| jnyang", "2"], ["| jnflip", "1"]]
    beside = [line for line in out.stdout.splitlines()
              if re.match(r"\| (jnyang|jnflip) \| [12] \| [\d.]+ \| \d+% \| [\d.]+ \| [\d.]+ \|$", line)]
    assert [tuple(c.strip() for c in row.strip("|").split("|")[:3]) for row in beside] == [
        (m, t, s) for m in ("jnyang", "jnflip") for t in ("1", "2") for s in ("5", "1")]
    for row in beside:
        assert int(row.split("|")[4].strip().rstrip("%")) > 0, row
    bad = subprocess.run([sys.executable, str(BENCH), "--switch", "fast"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--switch" in bad.stderr
