"""bench/input_planes.py (sdk.input_planes' time for every shipped model's planes, next to its predict) and
bench/pyrender_adapter.py (the pyrender adapter's inputs for every shipped model, frame loop and first frame)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from rtp import sdk

BENCH = Path(__file__).resolve().parents[1] / "bench"
SHIPPED = {m.removesuffix(".onnx") for m in sdk.shipped_models()}


def _run(script: str, *args: str, timeout: int = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(BENCH / script), *args], capture_output=True, text=True, timeout=timeout)


def _models(stdout: str, cells: int) -> set[str]:
    """The model names of the table rows of ``cells`` numbers after the plane count."""
    rows = re.findall(rf"^\| ([\w-]+) \| \d+ \|(?: [\d.]+ \|){{{cells}}}$", stdout, re.M)
    return set(rows)


@pytest.mark.gl
def test_input_planes_a_row_per_shipped_model() -> None:
    out = _run("input_planes.py", "--sizes", "64x48,80x48", "--repeats", "1")
    assert out.returncode == 0, out.stderr
    assert _models(out.stdout, 4) == SHIPPED, out.stdout
    assert "| model | planes | input_planes 64x48 (ms) | predict 64x48 (ms) | input_planes 80x48 (ms) |" in out.stdout
    assert re.search(r"^\| \(sdk\.reproject alone\) \| 4 \| [\d.]+ \|  \| [\d.]+ \|  \|$", out.stdout, re.M), out.stdout
    bad = _run("input_planes.py", "--sizes", "big", timeout=60)
    assert bad.returncode == 2 and "--sizes" in bad.stderr


@pytest.mark.gl
@pytest.mark.slow
def test_against_a_revision_compares_the_reprojections() -> None:
    """--against REV: this checkout's reproject against git REV's, timed and compared on rendered frames (against
    HEAD itself: nothing differs)."""
    out = _run("input_planes.py", "--against", "HEAD", "--sizes", "32x32", "--repeats", "1", "--pairs", "1")
    assert out.returncode == 0, out.stdout + out.stderr
    assert re.search(r"^\| 32x32 \| [\d.]+ \| [\d.]+ \|$", out.stdout, re.M), out.stdout
    # one pair of each profile on each of the three scenes (320x192, 640x360, 97x53), at three tolerances
    pixels = 3 * 2 * (320 * 192 + 640 * 360 + 97 * 53)
    assert (f"{pixels:,} pixels of rendered frames: seen differs on 0, the colour where seen agrees on 0 values; "
            "positions within 0 px") in out.stdout, out.stdout
    assert _models(out.stdout, 2) == SHIPPED, out.stdout  # input_planes as a whole, REV's and this checkout's
    assert re.search(r"^[\d,]+ plane values: 0 differ \(to the bit\)$", out.stdout, re.M), out.stdout
    bad = _run("input_planes.py", "--against", "no-such-revision", timeout=120)
    assert bad.returncode == 2 and "git cannot show sdk/_reproject.py there" in bad.stderr  # a usage error
    alone = _run("input_planes.py", "--pairs", "2", timeout=120)
    assert alone.returncode == 2 and "--pairs sets the frames --against compares" in alone.stderr


@pytest.mark.gl
def test_pyrender_adapter_a_row_per_shipped_model() -> None:
    out = _run("pyrender_adapter.py", "--sizes", "64x48", "--repeats", "1")
    assert out.returncode == 0, out.stderr
    assert _models(out.stdout, 2) == SHIPPED, out.stdout  # a frame loop and a first frame
    assert "| model | planes | 64x48 frame loop (ms) | 64x48 first frame (ms) |" in out.stdout, out.stdout
    bad = _run("pyrender_adapter.py", "--repeats", "0", timeout=60)
    assert bad.returncode == 2 and "--repeats" in bad.stderr


def test_the_planes_and_reuse_tables_name_their_unit() -> None:
    """bench/planes.py and bench/reuse.py (and input_planes.py and pyrender_adapter.py, above) printed tables of
    milliseconds whose header and columns named no unit ("| frame | luma of RGB | ...", "median of 7"): the corner
    cell says ms now, as docs/performance.md's tables of them do."""
    out = _run("planes.py", "--sizes", "16x16", "--repeats", "1", timeout=120)
    assert out.returncode == 0, out.stderr
    head = [line for line in out.stdout.splitlines() if line.startswith("| ")]
    assert head[0].startswith("| ms | luma of RGB | pixel_differences | block_variances |"), out.stdout
    assert re.fullmatch(r"\| 16x16 \|(?: [\d.]+ \|){6}", head[1]), out.stdout
    out = _run("reuse.py", "--repeats", "1", timeout=300)
    assert out.returncode == 0, out.stderr
    head = [line for line in out.stdout.splitlines() if line.startswith("| ")]
    assert head[0].startswith("| ms | network runs (sdk predict) | carried: mean |"), out.stdout
    assert [r.split(" | ")[0] for r in head[1:]] == ["| 1920x1080", "| 1280x720"], out.stdout
