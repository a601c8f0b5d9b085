"""bench/views.py: several views a frame (serial, batch, a thread per view) and shading_rates on a worker
thread beside Python."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import bench_module

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


@pytest.mark.parametrize(("named", "expected"), [
    (["jnflip", "jnyang.onnx"], "jnyang.onnx"),
    (["jnflip", "models/jnyang.onnx"], "models/jnyang.onnx"),
    (["jnflip", "jnyang-8px", "jnyang"], "jnyang"),
    (["jnflip", "jnyang-8px"], "jnyang-8px"),
    (["jnflip", "psnr"], "jnflip"),
])
def test_the_gil_table_takes_jnyang_by_the_model_loaded_not_by_its_name(
    named: list[str], expected: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The third table is JNYang's where it is named: it was picked by the name ``jnyang`` alone, so
    ``jnyang.onnx`` or a path to it was not recognised and the first model named (``jnflip``) was timed. It is
    recognised by the file ``sdk.load`` reads (the shipped ``jnyang``), else by its metadata's metric, else the first
    model named. (The tables themselves are stand-ins here: this is about which model the third one is of.)"""
    views = bench_module("views", monkeypatch)
    monkeypatch.chdir(BENCH.parents[1])
    timed: list[str] = []
    monkeypatch.setattr(views, "views_table", lambda m, *a: {"model": m, "groups": 1, "ms": {"w": 1.0},
                                                             "same": {"w": True}})
    monkeypatch.setattr(views, "beside_python", lambda *a: {"loop kept": 1.0, "alone": 1.0, "beside": 1.0})
    monkeypatch.setattr(views, "gil_waits", lambda m, *a: timed.append(m) or {})
    monkeypatch.setattr(sys, "argv", ["views.py", *named, "--switch", "0.005"])
    views.main()
    assert timed == [expected]


@pytest.mark.parametrize("size", [(70, 36), (64, 37)])
def test_the_bare_batch_run_is_padded_as_predict_pads_it(size: tuple[int, int]) -> None:
    """The third way (the batch as one onnxruntime run, its groups copied) fed the session the frames unpadded: at a
    width or height off the model's ``input_multiple`` (1366x768: 1366 columns, a multiple of 4 is 1368) it ran a frame
    the SDK never runs, and its cell read "(differs!)" for every model. It pads as ``predict`` pads (the last row and
    column repeated), and gives ``predict_raw``'s output there too."""
    views = bench_module("views")
    for model in ("jnflip", "flip"):  # (one graph input; two)
        row = views.views_table(model, size, 2, 1, 1)
        assert row["same"] == dict.fromkeys(row["same"], True), (model, size, row["same"])
