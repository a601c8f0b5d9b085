"""The lowest versions ``pyproject.toml`` allows, as pins for pip (``make test-floor``, ``make
test-floor-all``): ``python tests/floors.py`` prints the runtime's (numpy, onnxruntime, pyyaml, and
onnx, which the runtime's tests build models with), ``--all`` every ``name>=version`` of the project
and its extras, the highest floor where two extras name the same package (pillow: 9 for training,
10.1 for capture). Exact pins (torch) are pinned already; the build system's are not the project's, nor is setuptools
(:data:`UNFLOORED`).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"

#: The runtime's packages: what ``pip install rtp`` installs, and onnx for the tests that build models.
RUNTIME = ("numpy", "onnxruntime", "pyyaml", "onnx")

#: Not floored: setuptools builds the wheel ``tests/test_packaging.py`` checks (a build tool, not one
#: rtp runs on; its floor, 77, names no release: 77.0.0 was never published).
UNFLOORED = ("setuptools",)


def floors(text: str, names: tuple[str, ...] | None = None) -> list[str]:
    """``name==version`` for each ``"name>=version"`` requirement of ``text`` (a pyproject.toml) past
    its ``[project]`` table's start, the highest where a package is named twice; only ``names`` if given."""
    project = text[text.index("[project]"):]
    found: dict[str, tuple[tuple[int, ...], str]] = {}
    for name, version in re.findall(r'"([A-Za-z0-9_.-]+)(?:\[[^\]]*\])?>=([0-9]+(?:\.[0-9]+)*)"', project):
        key = name.lower()
        if key in UNFLOORED or (names is not None and key not in names):
            continue
        number = tuple(int(p) for p in version.split("."))
        if key not in found or number > found[key][0]:
            found[key] = (number, version)
    return [f"{key}=={version}" for key, (_, version) in sorted(found.items())]


if __name__ == "__main__":
    every = sys.argv[1:] == ["--all"]
    if sys.argv[1:] not in ([], ["--all"]):
        sys.exit("usage: python tests/floors.py [--all]")
    print(" ".join(floors(PYPROJECT.read_text(encoding="utf-8"), None if every else RUNTIME)))
