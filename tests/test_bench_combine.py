"""bench/combine.py on a small captured dataset: its tables, the aware selection shading no unjudged rate and a
budget beside the fovea saving what was asked; bad --savings is one line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from rtp.capture import capture

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("combine") / "data"
    capture(["procedural:3"], out, per_scene=2, size=(256, 160))
    subprocess.run([sys.executable, "-m", "rtp.cli", "targets", str(out), "--metrics", "jnyang"], cwd=ROOT, check=True,
                   capture_output=True, timeout=300)
    return out


def _rows(text: str, first: str) -> list[list[str]]:
    return [[c.strip() for c in line.split("|")[1:-1]] for line in text.splitlines() if line.startswith(f"| {first}")]


def test_the_combine_bench_reads_a_dataset(dataset: Path) -> None:
    out = subprocess.run([sys.executable, "bench/combine.py", "jnyang", "--data", str(dataset), "--scene", "procedural:3",
                          "--savings", "0.5,0.8"], cwd=ROOT, capture_output=True, text=True, timeout=300, check=True).stdout
    rows = {(r[0], r[1]): [float(c) for c in r[2:]] for img in ("foveation", "motion") for r in _rows(out, img)}
    assert len(rows) == 8
    for img in ("foveation", "motion"):
        assert rows[img, "aware"][3] == 0.0  # (nothing shaded at a rate neither chose)
        assert rows[img, "engine alone"][2] == 0.0 and rows[img, "rtp alone"][1] == rows[img, "rtp alone"][2]
        assert rows[img, "unaware"][0] >= rows[img, "engine alone"][0]  # (max: never less saved than the engine's)
    budget = {r[0]: [float(c) for c in r[1:]] for r in _rows(out, "50") + _rows(out, "80")}
    fovea_alone = rows["foveation", "engine alone"][0]
    for asked, cells in budget.items():
        aware_mean, aware_low = cells[4], cells[5]
        assert aware_low >= min(float(asked), fovea_alone) - 0.05 and aware_mean >= float(asked) - 0.05


def test_bad_savings_are_one_line(dataset: Path) -> None:
    r = subprocess.run([sys.executable, "bench/combine.py", "jnyang", "--data", str(dataset), "--scene", "procedural:3",
                        "--savings", "half"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.strip() == ("combine.py: error: --savings: expected numbers, comma-separated, "
                                                      "got 'half'")


def test_a_saving_given_twice_is_one_row_of_the_same_figures(dataset: Path) -> None:
    """`--savings 0.8,0.5,0.8` tallied the samples twice into one row: its failing tiles beyond the engine's rate
    doubled (0.28% of a map's tiles read 0.56%), the row printed twice. Each saving is one row, as given once."""
    def budget(savings: str) -> list[list[str]]:
        out = subprocess.run([sys.executable, "bench/combine.py", "jnyang", "--data", str(dataset), "--scene",
                              "procedural:3", "--savings", savings, "--threshold", "0.05"], cwd=ROOT,
                             capture_output=True, text=True, timeout=300, check=True).stdout
        return _rows(out, "50") + _rows(out, "80")

    once = budget("0.5,0.8")
    assert any(float(r[4]) > 0 for r in once), once  # (failing tiles beyond the engine's, to be doubled)
    assert budget("0.8,0.5,0.8") == once  # (one row each: _rows reads the 50 rows, then the 80 ones)
