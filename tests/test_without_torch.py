"""An install without torch (``pip install rtp[capture]``) runs ``rtp evaluate`` and ``rtp demo``.

torch is a dependency of training, export and LPIPS targets only. These tests run the commands in a
fresh interpreter where importing torch (or onnx, the exporter's) fails as it would on such an
install, so an eager import anywhere on those paths turns them red.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from .test_evaluate import dataset, model  # noqa: F401  (fixtures)

_BLOCKED = ("torch", "torchvision", "onnx")
_RUN_WITHOUT_TORCH = f"""
import sys
class _NoTorch:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {_BLOCKED!r}:
            raise ModuleNotFoundError(f"No module named {{name!r}} (this test's install has no torch)")
        return None
sys.meta_path.insert(0, _NoTorch())
from rtp.cli import main
code = main(sys.argv[1:])
leaked = sorted(m for m in sys.modules if m.split(".")[0] in {_BLOCKED!r})
assert not leaked, leaked
sys.exit(code)
"""


def _rtp(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", _RUN_WITHOUT_TORCH, *args], capture_output=True, text=True,
                          timeout=600)


def test_the_blocker_blocks() -> None:
    r = subprocess.run([sys.executable, "-c", _RUN_WITHOUT_TORCH.replace("from rtp.cli import main", "import torch")],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "this test's install has no torch" in r.stderr


def test_evaluate_runs_without_torch(dataset: Path, model: Path, tmp_path: Path) -> None:  # noqa: F811
    r = _rtp("evaluate", str(model), "--data", str(dataset), "--out", str(tmp_path / "ev"), "--plots")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "ev" / "evaluation.json").is_file()


@pytest.mark.gl
def test_demo_runs_without_torch(tmp_path: Path) -> None:
    r = _rtp("demo", "--size", "160x96", "--frames", "2", "--out", str(tmp_path / "demo"))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "demo" / "overlay.png").is_file()
