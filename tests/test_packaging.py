"""The wheel a user installs (`pip install rtp`, not editable) carries every data file the code reads.

An editable install reads shaders, recipes and models from the checkout, so a file missing from
pyproject.toml's package data would only show on a real install. This builds the wheel the way pip
does and compares it with the tree.
"""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: checkout folder -> its place in the wheel, for the data files each room reads at run time
DATA = {
    "models": ("rtp/models", "*.onnx"),
    "train/recipes": ("rtp/train/recipes", "*.yaml"),
    "plugins/moderngl/shaders": ("rtp/plugins/moderngl/shaders", "*.glsl"),
    "plugins/pyrender/shaders": ("rtp/plugins/pyrender/shaders", "gbuffer.*"),
    "capture/scenes": ("rtp/capture/scenes", "scenes.yaml"),
    "export": ("rtp/export", "published.yaml"),
}
ROOMS = {"sdk": "rtp/sdk", "export": "rtp/export", "train": "rtp/train", "capture": "rtp/capture",
         "metrics": "rtp/metrics", "scene": "rtp/scene", "evaluate": "rtp/evaluate",
         "conformance": "rtp/conformance", "cli": "rtp/cli", "cli/_package": "rtp",
         "plugins/moderngl": "rtp/plugins/moderngl", "plugins/pyrender": "rtp/plugins/pyrender"}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> tuple[set[str], str]:
    out = tmp_path_factory.mktemp("wheel")
    # --no-build-isolation: the test extras install the build backend, so no download happens here
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-v",
                           "-w", str(out), str(ROOT)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    (whl,) = out.glob("rtp-*.whl")
    with zipfile.ZipFile(whl) as z:
        return set(z.namelist()), proc.stdout + proc.stderr


@pytest.mark.slow
def test_the_wheel_carries_every_data_file(wheel: tuple[set[str], str]) -> None:
    names, _ = wheel
    for folder, (dest, pattern) in DATA.items():
        files = sorted((ROOT / folder).glob(pattern))
        assert files, f"{folder}/{pattern} matches nothing in the checkout"
        missing = [f.name for f in files if f"{dest}/{f.name}" not in names]
        assert not missing, f"the wheel lacks {dest}/{missing}"
    for room, dest in ROOMS.items():  # each room is typed for the user's type checker (PEP 561)
        assert (ROOT / room / "py.typed").is_file() and f"{dest}/py.typed" in names, room


@pytest.mark.slow
def test_the_build_configuration_is_complete(wheel: tuple[set[str], str]) -> None:
    _, log = wheel
    # setuptools names a data folder that no package in pyproject.toml claims (the file is then
    # shipped by accident of discovery, and a later setuptools drops it)
    assert "is absent from the `packages` configuration" not in log
    assert "project.license` as a TOML table is deprecated" not in log
