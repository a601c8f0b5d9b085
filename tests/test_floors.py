"""tests/floors.py: the lowest versions pyproject.toml allows, as pip pins for `make test-floor` (in CI)
and `make test-floor-all`. A pin that drifted from pyproject would test versions nobody declared."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from .floors import PYPROJECT, RUNTIME, floors

SCRIPT = Path(__file__).with_name("floors.py")


def test_the_runtime_pins_are_pyprojects_floors() -> None:
    text = PYPROJECT.read_text(encoding="utf-8")
    pins = floors(text, RUNTIME)
    assert [p.split("==")[0] for p in pins] == sorted(RUNTIME)
    for pin in pins:
        name, version = pin.split("==")
        assert re.search(rf'"{name}>={re.escape(version)}"', text, re.IGNORECASE), pin
    every = floors(text)
    assert set(pins) <= set(every) and "torch" not in " ".join(every)  # (torch is pinned exactly already)
    assert not any(p.startswith("setuptools") for p in every)  # a build tool; "setuptools>=77" names no release
    # pillow: 9 for training, 10.1 for capture; both extras install together, so the floor is 10.1
    assert "pillow==10.1" in every and not any(p.startswith("pillow==9") for p in every)


def test_the_highest_floor_wins_and_the_build_system_is_not_the_projects() -> None:
    text = '''[build-system]
requires = ["setuptools>=40"]
[project]
dependencies = ["numpy>=1.24.2", "PyYAML>=6.0"]
[project.optional-dependencies]
a = ["pillow>=9", "rtp[b]", "torch==2.13.0", "ray[default]>=2.40"]
b = ["pillow>=10.1", "numpy>=1.9.5"]
'''
    assert floors(text) == ["numpy==1.24.2", "pillow==10.1", "pyyaml==6.0", "ray==2.40"]  # 1.24.2 > 1.9.5 as numbers
    assert floors(text, ("pillow",)) == ["pillow==10.1"]


def test_the_script_prints_pins_and_refuses_other_arguments() -> None:
    out = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True, check=True).stdout
    assert out.split() == floors(PYPROJECT.read_text(encoding="utf-8"), RUNTIME)
    out = subprocess.run([sys.executable, str(SCRIPT), "--all"], capture_output=True, text=True, check=True).stdout
    assert len(out.split()) > len(RUNTIME)
    bad = subprocess.run([sys.executable, str(SCRIPT), "--everything"], capture_output=True, text=True)
    assert bad.returncode == 1 and "usage: python tests/floors.py [--all]" in bad.stderr
