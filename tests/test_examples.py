"""The examples run as a user would run them, with the shipped models."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.gl
def test_pyrender_example_uses_a_shipped_model(tmp_path: Path) -> None:
    out = tmp_path / "vrs.png"
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--size", "160", "96",
                        "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "jnyang.onnx" in r.stderr and "RANDOM" not in r.stderr and out.is_file()
