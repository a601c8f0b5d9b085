"""The Makefile's targets as a user runs them: from another folder, with a virtualenv elsewhere, with a variable's
value that cannot work (tests/test_cli.py reads the rtp commands `make -n` prints for the variables' values).

Nothing here installs or trains: a target is either printed (``make -n``) or run with the virtualenv's stamp
given as up to date (``make -o STAMP``), as far as the check that stops it."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _make(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """``make -C ROOT ARGS`` from ``cwd`` (another folder than the checkout's)."""
    make = shutil.which("make")
    if make is None:
        pytest.skip("no make on this machine")
    return subprocess.run([make, "-C", str(ROOT), "--no-print-directory", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=120)


def test_typecheck_finds_mypy_in_a_virtualenv_named_by_its_absolute_path(tmp_path: Path) -> None:
    """The typecheck recipe runs mypy from a temporary tree, as $(CURDIR)/$(BIN)/mypy: with VENV=/opt/venv that was
    /work/main//opt/venv/bin/mypy, no such file, so `make typecheck` failed wherever the virtualenv lives outside the
    checkout. The relative default still resolves against the checkout from another folder (make -C)."""
    venv = tmp_path / "venv"
    for value, mypy in ((str(venv), f"{venv}/bin/mypy"), (".venv", f"{ROOT}/.venv/bin/mypy")):
        done = _make("-n", "typecheck", f"VENV={value}", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        [line] = [ln for ln in done.stdout.splitlines() if "--config-file" in ln]
        assert f"cd $tree && {mypy} --config-file " in line, line


@pytest.mark.parametrize(("target", "split"), [("train", "train"), ("evaluate", "test")])
def test_train_and_evaluate_without_their_dataset_say_how_to_make_it(target: str, split: str, tmp_path: Path) -> None:
    """`make train` and `make evaluate` where `make dataset` never ran ended in rtp's "no dataset folder at
    'data/train'", which named no way to get one; they now name `make dataset` (with the DATA given) and DATA=, and
    run nothing. A folder that is there goes on to rtp (tests/test_cli.py reads those commands)."""
    venv = tmp_path / "venv"  # (never made: -o takes its stamp as up to date, and the check stops the target before it)
    data = tmp_path / "my data"
    done = _make("-o", f"{venv}/.rtp-installed", target, f"VENV={venv}", f"DATA={data}", cwd=tmp_path)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert f"make {target}: no dataset folder at '{data}/{split}': make dataset DATA='{data}' captures" in done.stderr
    assert "rtp" not in done.stdout and not venv.exists() and not data.exists()
    (data / split).mkdir(parents=True)
    printed = _make("-n", "-o", f"{venv}/.rtp-installed", target, f"VENV={venv}", f"DATA={data}", cwd=tmp_path)
    assert f'{venv}/bin/rtp {target} ' in printed.stdout, printed.stdout


def _old_python(tmp_path: Path) -> Path:
    """A stand-in for an interpreter older than 3.10: the Makefile's `sys.exit(sys.version_info < (3, 10))` ends it with 1."""
    old = tmp_path / "python3.9"
    old.write_text("#!/bin/sh\nexit 1\n")
    old.chmod(0o755)
    return old


@pytest.mark.parametrize("target", ["test-python-venv", "test-python"])
def test_test_python_refuses_an_interpreter_that_cannot_run_rtp_before_removing_its_virtualenv(
        target: str, tmp_path: Path) -> None:
    """`make test-python PY=...` removed .venv-py first, then found that PY was no interpreter (PY=nope, a pyenv shim of a
    version not installed: "/bin/sh: nope: not found") or one older than requires-python (its `pip install .` failed
    after minutes of downloads): the virtualenv was gone and the error said nothing of PY. It now says so and keeps it."""
    kept = tmp_path / "venv-py"
    kept.mkdir()
    (kept / ".rtp-installed-for").write_text("python3.13\n")
    for py in (str(_old_python(tmp_path)), str(tmp_path / "nope")):
        done = _make(target, f"PY={py}", f"PY_VENV={kept}", cwd=tmp_path)
        assert done.returncode == 2, (done.stdout, done.stderr)
        assert (f"make test-python-venv: PY={py} runs no Python 3.10 or newer (pyproject.toml's requires-python): "
                f"{kept} is left as it was; PY=<a Python 3.10 or newer> names another") in done.stderr, done.stderr
        assert (kept / ".rtp-installed-for").read_text() == "python3.13\n"


@pytest.mark.parametrize(("target", "variable"), [("install", "VENV"), ("test-floor-venv", "FLOOR_VENV"),
                                                  ("test-floor-all", "FLOOR_VENV")])
def test_install_refuses_a_python_older_than_requires_python_before_making_the_virtualenv(
        target: str, variable: str, tmp_path: Path) -> None:
    """`make install` with a python3 older than 3.10 (PYTHON's default; Ubuntu 20.04's is 3.8) made .venv and then
    failed in pip on "No matching distribution found for torch==2.13.0", which blamed torch; the floors' targets
    removed .venv-floor first. Each now names PYTHON and the version it needs, and makes (and removes) nothing. The
    version the Makefile asks for is pyproject.toml's requires-python."""
    import tomllib

    requires = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["requires-python"]
    assert requires == ">=3.10" and "sys.version_info < (3, 10)" in (ROOT / "Makefile").read_text()
    venv = tmp_path / "venv"
    venv.mkdir()
    (venv / "keep").write_text("")
    old = _old_python(tmp_path)
    done = _make(target, f"PYTHON={old}", f"{variable}={venv}", cwd=tmp_path)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert f"PYTHON={old} runs no Python 3.10 or newer (pyproject.toml's requires-python)" in done.stderr, done.stderr
    assert [p.name for p in venv.iterdir()] == ["keep"]


@pytest.mark.parametrize(("target", "variable"), [("install", "VENV"), ("test-floor-venv", "FLOOR_VENV")])
def test_a_virtualenv_older_than_the_makefiles_pins_is_installed_again(target: str, variable: str,
                                                                       tmp_path: Path) -> None:
    """The pins (torch==2.13.0, NO_DEPS) live in the Makefile, but the virtualenvs' stamps were remade only when
    pyproject.toml (and tests/floors.py) changed: after a pin moved, `make install` kept the old packages and said
    nothing. A stamp older than the Makefile (a copy run with -f, its own time set) is now remade; a newer one is
    kept."""
    import os
    import time

    venv = tmp_path / "venv"
    venv.mkdir()
    now = time.time()
    (venv / ".rtp-installed").write_text("")
    os.utime(venv / ".rtp-installed", (now, now))
    makefile = tmp_path / "Makefile"
    makefile.write_text((ROOT / "Makefile").read_text())
    for offset, remade in ((-60, False), (60, True)):
        os.utime(makefile, (now + offset, now + offset))
        done = _make("-f", str(makefile), "-n", target, f"{variable}={venv}", cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        assert ("pip install -q torch==2.13.0" in done.stdout) is remade, done.stdout
