"""bench/conformance_margins.py: the margins of the conformance kit's previous-frame checks, per adapter."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from .conftest import BENCH, pyrender_or_skip


@pytest.mark.slow
def test_the_table_has_the_shipped_adapter_and_the_two_broken_ones() -> None:
    """One level at 64x48 (about 10 s): the shipped pyrender adapter passes both checks, the upside-down
    previous frame fails the edges' and the adapter without the depth test the hidden pixels'."""
    pyrender_or_skip()
    out = subprocess.run([sys.executable, str(BENCH / "conformance_margins.py"), "--levels", "0", "--sizes", "64x48"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    header = next(line for line in lines if line.startswith("| level | size |"))
    assert [c.strip() for c in header.strip("|").split("|")][2:] == [
        f"{v}: {what}" for v in ("shipped", "upside down", "no depth test")
        for what in ("edge correlation", "hidden unseen")]
    rows = [line for line in lines if line.startswith("| 0 | 64x48 |")]
    assert len(rows) == 1, out.stdout
    cells = [c.strip() for c in rows[0].strip("|").split("|")][2:]
    assert [c.endswith("(fails)") for c in cells] == [False, False, True, False, False, True], rows[0]
    assert cells[1].endswith("of 7") and float(cells[0]) >= 0.4, rows[0]  # (procedural:0 hides 7 pixels)
    ranges = {m[1] for line in lines if (m := re.match(r"\| ([\w ]+) \| -?[\d.]+ to -?[\d.]+ \(1\) \|", line))}
    assert sorted(ranges) == ["no depth test", "shipped", "upside down"], out.stdout
    assert any(line.startswith("| kit threshold | >= 0.4 (MIN_EDGE_CORRELATION)") for line in lines), out.stdout
