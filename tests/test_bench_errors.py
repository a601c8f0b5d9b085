"""The benchmark scripts and examples follow rtp's error policy (docs/errors.md): bad arguments are
argparse's usage errors, and an rtp error found while running (a model, map or dataset that is not
there) prints one line, ``NAME.py: error: ...``, with rtp's exit code, instead of a traceback."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import BENCH

ROOT = Path(__file__).resolve().parents[1]


def test_every_script_runs_its_main_under_the_error_policy() -> None:
    """Each bench script's ``__main__`` block is ``run_main(...)`` (bench/_common.py), and no script
    prints its own "error: ..." line (they had three formats, some without the program's name)."""
    for path in sorted(BENCH.glob("*.py")):
        if path.name == "_common.py":
            continue
        tree = ast.parse(path.read_text())
        blocks = [n for n in tree.body if isinstance(n, ast.If) and "__main__" in ast.unparse(n.test)]
        assert blocks and "run_main(" in ast.unparse(blocks[0]), f"{path.name}: its __main__ is not run_main(...)"
        assert '"error: ' not in path.read_text(), f"{path.name} prints its own error line"


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, *args], cwd=cwd, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(("args", "code", "words"), [
    (["bench/inference.py", "nosuchmodel"], 2, "inference.py: error: no model file at 'nosuchmodel'"),
    (["bench/inference.py", "--repeats", "0"], 2, "argument --repeats: expected a positive integer"),
    (["bench/budget.py", "--model", "nosuchmodel"], 2, "budget.py: error: no model file at 'nosuchmodel'"),
    (["bench/budget.py", "--saving", "0.99"], 2, "budget.py: error: saving: expected the share of shading work"),
    (["bench/paths.py", "--size", "12x"], 2, "argument --size: expected WIDTHxHEIGHT"),
    (["bench/paths.py", "--maps", "nosuchmap", "--frames", "3"], 2, "paths.py: error: map 'nosuchmap' is not listed"),
    (["bench/scaling.py", "--modes", "nosuch"], 2, "argument --modes: expected ray and/or pool"),
    (["bench/report.py", "README.md"], 2, "is not JSON"),
    # input_ceiling.py runs ``rtp train`` in-process: its own parser refuses what that one would
    (["bench/input_ceiling.py", "--metric", "nosuch"], 2, "input_ceiling.py: error: argument --metric"),
    (["examples/moderngl_vrs.py", "--model", "nosuch"], 2, "moderngl_vrs.py: error: no model file at 'nosuch'"),
    # numbers a run would choke on (NaN into time.sleep, a share of 5) are usage errors, and what a later table
    # reads is checked before the first table's minutes
    (["bench/spinning.py", "--long-ms", "nan"], 2, "argument --long-ms: expected a finite number in [0, 60000]"),
    (["bench/spinning.py", "--model", "nosuch"], 2, "spinning.py: error: no model file at 'nosuch'"),
    (["bench/views.py", "--seconds", "inf"], 2, "argument --seconds: expected a finite number in (0, 600]"),
    (["bench/views.py", "--size", "1x1"], 2, "argument --size: expected WIDTHxHEIGHT of at least 16x16"),
    (["bench/hardware_tiles.py", "jnyang", "--fail-share", "5"], 2, "argument --fail-share: expected a finite number "
                                                                   "in (0, 1)"),
    (["bench/per_rate.py", "jnyang", "--fit", "nan"], 2, "argument --fit: expected a finite number in (0, 1)"),
    # a child's error and git's are one line of this script's, exit 2 (exit 1 and a line naming two programs before)
    (["bench/memory.py", "/nope.onnx"], 2, "memory.py: error: no model file at '/nope.onnx'"),
    (["bench/input_planes.py", "--against", "nosuchrev"], 2, "input_planes.py: error: --against nosuchrev: git "
                                                             "cannot show"),
])
def test_bad_input_is_one_line(args: list[str], code: int, words: str) -> None:
    run = _run(args, ROOT)
    assert run.returncode == code, run.stderr
    assert "Traceback" not in run.stderr and words in run.stderr.strip().splitlines()[-1], run.stderr


def test_a_json_of_another_kind_and_a_folder_that_is_not_a_dataset(tmp_path: Path) -> None:
    (tmp_path / "other.json").write_text(json.dumps({"settings": {}, "matched": []}))
    run = _run([str(BENCH / "play_report.py"), str(tmp_path / "other.json")], tmp_path)
    assert run.returncode == 2 and "is not a play.json (the file `rtp play --out DIR` writes)" in run.stderr
    # the right keys with other kinds of value: a usage error too, not a TypeError once the tables are made
    (tmp_path / "odd.json").write_text(json.dumps({"settings": {"scene": 1}, "rows": 5, "matched": 3}))
    run = _run([str(BENCH / "play_report.py"), str(tmp_path / "odd.json")], tmp_path)
    assert run.returncode == 2 and "is not a play.json" in run.stderr and "Traceback" not in run.stderr, run.stderr
    (tmp_path / "odd.json").write_text(json.dumps({"model": 5, "quality": [1], "decisions": "x"}))
    run = _run([str(BENCH / "report.py"), str(tmp_path / "odd.json")], tmp_path)
    assert run.returncode == 2 and "is not an evaluation.json" in run.stderr and "Traceback" not in run.stderr, run.stderr
    (tmp_path / "fake").mkdir()
    (tmp_path / "fake" / "manifest.json").write_text(json.dumps({"format": "mine"}))
    run = _run([str(BENCH / "outputs.py"), "jnyang", "--data", str(tmp_path / "fake")], tmp_path)
    assert run.returncode == 2 and "Traceback" not in run.stderr and "argument --data" in run.stderr, run.stderr


def test_input_ceiling_checks_its_maps_before_the_training_they_come_after(tmp_path: Path) -> None:
    """--scene is read after hours of training: a map the dataset does not hold is refused first."""
    from rtp.capture import capture

    capture(["procedural:3"], tmp_path / "d", per_scene=1, size=(64, 48))
    for scene, words in (("nosuchmap", "--scene: nosuchmap not in"), (",", "--scene: expected comma-separated map")):
        run = _run([str(BENCH / "input_ceiling.py"), "--metric", "flip", "--data", str(tmp_path / "d"),
                    "--scene", scene, "--out", str(tmp_path / "m.pt")], tmp_path)
        assert run.returncode == 2 and words in run.stderr and "Traceback" not in run.stderr, run.stderr
        assert not list(tmp_path.glob("*m.pt*")), scene  # no training began
