"""Every code block of README.md runs verbatim, so the README cannot drift from the code.

Python blocks run in a fresh interpreter and bash blocks in ``bash -eu``, each in an empty folder
with this interpreter's ``bin`` first on PATH (so ``rtp`` and ``rtp-export`` are the ones under
test). The set-up block (``make demo``, ``make test``) is the one exception: ``.ci/run`` runs those
commands itself on a fresh clone, and this test checks that it does.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
#: A block preceded by this comment is run by .ci/run itself, not by this test.
CI_RUNS_IT = "<!-- run by .ci/run -->"


def _blocks() -> list[tuple[str, str, int, bool]]:
    """``(language, code, line, run_by_ci)`` of every fenced block of the README."""
    text = README.read_text()
    out = []
    for m in re.finditer(r"^```(\w+)\n(.*?)^```", text, re.S | re.M):
        line = text.count("\n", 0, m.start()) + 1
        before = text[: m.start()].rstrip().splitlines()[-1:] or [""]
        out.append((m.group(1), m.group(2), line, before[0].strip() == CI_RUNS_IT))
    return out


BLOCKS = _blocks()


def test_the_readme_has_blocks_to_run() -> None:
    langs = {lang for lang, *_ in BLOCKS}
    assert {"python", "bash"} <= langs, langs


def test_the_blocks_ci_runs_itself_are_in_ci() -> None:
    ci = (ROOT / ".ci" / "run").read_text()
    commands = [c.split("#")[0].strip() for _, code, _, by_ci in BLOCKS if by_ci for c in code.splitlines()]
    assert commands and all(c in ci for c in commands if c), commands


def test_ci_finds_an_installed_osmesa_whatever_the_length_of_ldconfigs_list(tmp_path: Path) -> None:
    """.ci/run asks ldconfig whether libOSMesa is there, under `set -euo pipefail`: `ldconfig -p | grep -q libOSMesa`
    failed (141) where grep left at the match before ldconfig had written its list (more than a pipe holds), so an
    installed OSMesa was called missing and apt-get ran, and the run failed where apt could not reach its mirrors."""
    ci = (ROOT / ".ci" / "run").read_text()
    [condition] = re.findall(r"^if (.*libOSMesa.*); then$", ci, re.M)
    fake = tmp_path / "ldconfig"  # OSMesa first, then a megabyte more of the list
    fake.write_text("#!/bin/sh\necho '\tlibOSMesa.so.8 (libc6,x86-64) => /lib/libOSMesa.so.8'\n"
                    "head -c 1000000 /dev/zero | tr '\\0' 'x'\necho\n")
    fake.chmod(0o755)
    script = f"set -euo pipefail\nif {condition}; then echo missing; else echo found; fi\n"
    for listed, said in ((True, "found"), (False, "missing")):
        if not listed:
            fake.write_text("#!/bin/sh\nhead -c 1000000 /dev/zero | tr '\\0' 'x'\necho\n")
        r = subprocess.run(["bash", "-c", script], env={**os.environ, "PATH": f"{tmp_path}{os.pathsep}{os.environ['PATH']}"},
                           capture_output=True, text=True, timeout=60)
        assert (r.returncode, r.stdout.strip()) == (0, said), (listed, r)


@pytest.mark.slow
@pytest.mark.gl
@pytest.mark.parametrize(("lang", "code", "line"), [
    pytest.param(lang, code, line, id=f"{lang}-line{line}") for lang, code, line, by_ci in BLOCKS if not by_ci
])
def test_readme_block_runs_verbatim(lang: str, code: str, line: int, tmp_path: Path) -> None:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    if lang == "python":
        cmd = [sys.executable, "-c", code]
    elif lang == "bash":
        cmd = ["bash", "-euc", code]
    else:
        pytest.fail(f"README.md line {line}: a ```{lang} block; the README test runs python and bash only")
    r = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, f"README.md line {line} failed ({r.returncode}):\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
