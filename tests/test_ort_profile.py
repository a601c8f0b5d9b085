"""bench/ort_profile.py: onnxruntime's per-node profile of a model, with each convolution's multiply-adds."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import onnx
import pytest

from rtp import sdk

from .conftest import bench_module

BENCH = Path(__file__).resolve().parents[1] / "bench" / "ort_profile.py"


def _module() -> object:
    return bench_module("ort_profile")


def test_profile_lists_every_convolution_with_its_multiply_adds() -> None:
    pred = sdk.load("lpips")
    rows = _module().profile(Path(str(pred.path)), len(pred.metadata.inputs), (256, 128), 2, 1)  # type: ignore[attr-defined]
    convs = [r for r in rows if r["macs"]]
    # every convolution of the exported graph is profiled (BatchNorm folded, ReLU fused into it)
    assert len(convs) == sum(n.op_type == "Conv" for n in onnx.load(str(pred.path)).graph.node) >= 3
    # the stem: one convolution per group of input planes (rtp.export.split_input_planes), the groups'
    # planes adding up to the model's
    groups = pred.graph_inputs
    stems = convs[: len(groups)]
    c = len(pred.metadata.inputs)
    assert len(groups) == 2 and all(s["shape"][2:] == [128 // 4, 256 // 4] for s in stems)
    assert sum(s["macs"] for s in stems) == stems[0]["shape"][1] * c * 4 * 4 * (128 // 4) * (256 // 4)
    assert all(r["ms"] >= 0 for r in rows)
    assert convs[-1]["shape"][2:] == [128 // 16, 256 // 16]  # the head at tile resolution
    # the finite probe: a mean per channel of the stem's output (in onnxruntime's blocked layout), then their sum
    probe = {r["op"]: r for r in rows if "finite_probe" in r["name"]}
    assert pred.metadata.finite_probe and sorted(probe) == ["GlobalAveragePool", "ReduceSum"]
    assert probe["ReduceSum"]["shape"] == [] and probe["GlobalAveragePool"]["shape"] == [1, convs[0]["shape"][1], 1, 1]


def test_profile_lists_the_nodes_in_the_order_they_run() -> None:
    """The table read as the network runs: onnxruntime's node_index, which it went by, numbers the nodes its
    optimiser adds after the others, so the groups' Sum came before the stem's convolutions it adds and the
    probe's ReduceSum before the GlobalAveragePool it reads."""
    pred = sdk.load("lpips")
    rows = _module().profile(Path(str(pred.path)), len(pred.metadata.inputs), (256, 128), 2, 1)  # type: ignore[attr-defined]
    ops = [r["op"] for r in rows]
    first = {op: ops.index(op) for op in ("Conv", "Sum", "Relu", "GlobalAveragePool", "ReduceSum", "MaxPool")}
    stems = [i for i, r in enumerate(rows) if r["op"] == "Conv" and r["shape"][2:] == [128 // 4, 256 // 4]][:2]
    assert len(stems) == 2 and max(stems) < first["Sum"] < first["Relu"] < first["MaxPool"]  # two groups, summed
    assert first["GlobalAveragePool"] < first["ReduceSum"]  # the probe: the stem's means, then their sum
    assert ops[0] in ("Conv", "Reshape")  # the run starts with the stem (or a layout reorder it reads)


def test_profile_cli_prints_a_table_and_rejects_a_bad_size() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "jnyang", "--size", "128x64", "--repeats", "1"],
                         capture_output=True, text=True, check=True)
    assert "### jnyang" in out.stdout and "| Conv |" in out.stdout
    bad = subprocess.run([sys.executable, str(BENCH), "jnyang", "--size", "128by64"], capture_output=True, text=True)
    assert bad.returncode != 0 and "WIDTHxHEIGHT" in bad.stderr


@pytest.mark.parametrize("repeats", ["0"])
def test_profile_cli_rejects_no_runs(repeats: str) -> None:
    bad = subprocess.run([sys.executable, str(BENCH), "jnyang", "--repeats", repeats], capture_output=True, text=True)
    assert bad.returncode != 0 and "--repeats" in bad.stderr


def test_profile_cli_costs_random_fast_networks_on_a_models_inputs() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "lpips", "--fast", "grow=2,depth=5", "--fast", "depth=5",
                          "--like", "lpips", "--size", "128x64", "--repeats", "1"], capture_output=True, text=True, check=True)
    n = len(sdk.load("lpips").metadata.inputs)
    assert f"### fast grow=2,depth=5 (random weights) ({n} inputs" in out.stdout
    summary = out.stdout.split("| model | ms of kernels | x the first |")[1]
    rows = [r for r in summary.splitlines() if r.startswith("| ") and "---" not in r]
    assert [r.split(" | ")[0] for r in rows] == ["| lpips", "| fast grow=2,depth=5 (random weights)",
                                                  "| fast depth=5 (random weights)"]
    cells = [[c.strip() for c in r.strip("|").split("|")] for r in rows]
    assert cells[0][2] == "1.00" and all(len(c) == 6 for c in cells)
    assert all(float(c[3]) > 0 and float(c[4]) > 0 for c in cells)
    # rtp-export gives every fast network a finite probe: what the check costs is measured in the graph
    assert all(c[5].endswith("(in the graph: kernels with the probe minus without)") for c in cells)
    float(cells[0][5].split()[0])  # a number (a difference of two medians: on a tiny frame it may be below 0)


@pytest.mark.parametrize(("flag", "message"), [("bogus=1", "KEY one of"), ("width=wide", "width: expected an integer"),
                                               ("stem=3", "stem in (1, 2, 4, 8)")])
def test_profile_cli_rejects_a_bad_fast_option(flag: str, message: str) -> None:
    bad = subprocess.run([sys.executable, str(BENCH), "--fast", flag, "--size", "64x64", "--repeats", "1"],
                         capture_output=True, text=True)
    assert bad.returncode != 0 and message in bad.stderr


def test_a_random_fast_network_takes_the_tile_size_of_the_8px_models(tmp_path: Path) -> None:
    """``--fast tile=8`` costs a network whose blocks end at 8-pixel tiles (the `-8px` models), not at 16."""
    opts = _module()._fast_options("tile=8,stem=8,tail_width=24")  # type: ignore[attr-defined]
    assert opts == {"tile": 8, "stem": 8, "tail_width": 24}
    ((label, path),) = _module()._random_fast(tmp_path, [opts], "jnyang-8px")  # type: ignore[attr-defined]
    pred = sdk.load(path)
    assert pred.metadata.provenance["arch"] == "fast"  # (bench/inference.py's architecture column reads it)
    assert pred.metadata.tile_size == 8 and list(pred.metadata.inputs) == list(sdk.load("jnyang-8px").metadata.inputs)
    rows = _module().profile(path, len(pred.metadata.inputs), (128, 64), 1, 1)  # type: ignore[attr-defined]
    convs = [r for r in rows if r["macs"]]
    assert all(r["shape"][2:] == [64 // 8, 128 // 8] for r in convs)  # stem 8: every layer at the tile's resolution
    assert "tile=8" in label
