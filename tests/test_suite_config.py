"""The test suite's own configuration: what pyproject.toml's [tool.pytest.ini_options] promises holds."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def test_a_hanging_test_fails_with_its_stack_instead_of_holding_the_run(pytestconfig: pytest.Config,
                                                                        tmp_path: Path) -> None:
    """The suite runs under pytest-timeout (a test dependency) with a limit from pyproject.toml: a
    test that hangs fails, saying where, instead of holding its worker until CI's own limit. Checked
    on a hanging test in a pytest of its own, under this project's configuration at a 2-second limit."""
    limit = float(pytestconfig.getini("timeout"))
    assert pytestconfig.pluginmanager.hasplugin("timeout") and 60 <= limit <= 1800
    (tmp_path / "test_hangs.py").write_text("import time\n\ndef test_hangs():\n    time.sleep(60)\n")
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-c", str(PYPROJECT),
                          "--rootdir", str(tmp_path), "-o", "timeout=2", str(tmp_path / "test_hangs.py")],
                         capture_output=True, text=True, timeout=50)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "Timeout (>2.0s) from pytest-timeout" in run.stdout and "time.sleep(60)" in run.stdout
