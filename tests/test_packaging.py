"""The wheel a user installs (`pip install rtp`, not editable) carries every data file the code reads.

An editable install reads shaders, recipes and models from the checkout, so a file missing from
pyproject.toml's package data would only show on a real install. This builds the wheel the way pip
does and compares it with the tree, then installs it into a folder of its own and runs rtp from there
with the editable install out of the way (``python -S``: no .pth file runs, so the checkout's import
hook never loads), from a folder outside the checkout.
"""

from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import zipfile
from collections.abc import Callable
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


def _clean_copy(dest: Path) -> Path:
    """The checkout's files as git sees them (no build/, *.egg-info or data/) copied into ``dest``; the
    checkout itself where it is no git work tree (then an earlier build's build/lib is packed too)."""
    try:
        listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                                capture_output=True, check=True, timeout=60).stdout
    except (OSError, subprocess.CalledProcessError):
        return ROOT
    for name in filter(None, listed.decode().split("\0")):
        src = ROOT / name
        if src.is_file():  # (not a tracked file deleted in the work tree)
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)
    return dest


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The wheel pip builds from the checkout, and the build's log."""
    out = tmp_path_factory.mktemp("wheel")
    # Built from a copy of the checkout's files (tracked, and new ones git does not ignore): built in place,
    # setuptools packs its build/lib of earlier builds too, so a subpackage left out of `packages`, or a
    # module deleted since, still shipped here and nowhere else (a clone has no build/ folder)
    source = _clean_copy(out / "source")
    # --no-build-isolation: the test extras install the build backend, so no download happens here
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-v",
                           "-w", str(out), str(source)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    (whl,) = out.glob("rtp-*.whl")
    return whl, proc.stdout + proc.stderr


@pytest.fixture(scope="module")
def wheel(built: tuple[Path, str]) -> tuple[set[str], str]:
    whl, log = built
    with zipfile.ZipFile(whl) as z:
        return set(z.namelist()), log


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


@pytest.mark.slow
def test_the_wheel_carries_the_licence_it_declares(wheel: tuple[set[str], str]) -> None:
    """pyproject.toml and the README say MIT, whose terms ask that its notice go with every copy: the checkout had
    no licence file, so the wheel (and every install of it) carried none, only the word in its metadata."""
    names, _ = wheel
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names), sorted(n for n in names if "dist-info" in n)
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License") and "rtp developers" in text


@pytest.mark.slow
def test_the_wheel_carries_every_module(wheel: tuple[set[str], str]) -> None:
    """A subpackage left out of pyproject.toml's ``packages`` ships none of its modules; the editable install
    imports them from the checkout all the same, so only a real install would fail (ImportError)."""
    names, _ = wheel
    for room, dest in ROOMS.items():
        deep = room != "cli/_package"  # (rtp itself is cli/_package's files alone, not cli's)
        files = sorted((ROOT / room).rglob("*.py") if deep else (ROOT / room).glob("*.py"))
        missing = [str(f.relative_to(ROOT / room)) for f in files if "__pycache__" not in f.parts
                   and "_package" not in f.relative_to(ROOT / room).parts
                   and f"{dest}/{f.relative_to(ROOT / room).as_posix()}" not in names]
        assert not missing, f"the wheel lacks {dest}/{missing}: is the folder in pyproject.toml's packages?"


#: a console script as pip writes one for the wheel's entry points (``rtp``, ``rtp-export``): the installed
#: dist-info's entry point, loaded and called (guarded: a capture's worker processes import this file again)
_CONSOLE_SCRIPT = """\
import sys
from importlib.metadata import PathDistribution
from pathlib import Path

if __name__ == "__main__":
    (dist,) = Path(sys.argv[1]).glob("rtp-*.dist-info")
    name = sys.argv[2]
    (ep,) = [e for e in PathDistribution(dist).entry_points if e.group == "console_scripts" and e.name == name]
    sys.argv[:3] = [name]
    sys.exit(ep.load()())
"""

Run = Callable[..., "subprocess.CompletedProcess[str]"]


@pytest.fixture(scope="module")
def installed(built: tuple[Path, str], tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Run]:
    """The wheel installed (``pip install --no-deps --target``) into a folder of its own: that folder, a working
    folder outside the checkout, and a runner of ``python -S`` there with that folder first on the path and then
    the test environment's packages (the dependencies), without the editable install's import hook."""
    whl, _ = built
    base = tmp_path_factory.mktemp("installed")
    target, work = base / "site", base / "work"
    work.mkdir()
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "--target", str(target),
                           str(whl)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    script = base / "console_script.py"
    script.write_text(_CONSOLE_SCRIPT)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    # (-S leaves out the user's site folder too: named here, for an environment that has its packages there)
    user = [site.getusersitepackages()] if site.ENABLE_USER_SITE else []
    env["PYTHONPATH"] = os.pathsep.join([str(target), *site.getsitepackages(), *user])

    def run(*args: str, script_name: str | None = None) -> subprocess.CompletedProcess[str]:
        """``python -S ARGS``, or with ``script_name`` the wheel's console script of that name with ``ARGS``."""
        head = [str(script), str(target), script_name] if script_name else []
        return subprocess.run([sys.executable, "-S", *head, *args], cwd=work, env=env, capture_output=True,
                              text=True, timeout=300)

    return target, work, run


_IMPORT_ALL = """\
import importlib, json, pkgutil, sys
import rtp
names = [m.name for m in pkgutil.walk_packages(rtp.__path__, "rtp.") if not m.name.endswith("__main__")]
for name in names:
    importlib.import_module(name)
print(json.dumps({"modules": len(names), "files": {n: getattr(m, "__file__", None) for n, m in sys.modules.items()
                                                   if n.split(".")[0] == "rtp"}}))
"""

#: every data file the rooms read, read through the installed package's own code
_READ_DATA = """\
import json
from rtp import sdk
from rtp.capture.scenes import load_splits
from rtp.export import published_models
from rtp.plugins.moderngl import _shaders
from rtp.plugins.pyrender import _gbuffer
from rtp.train import load_recipe, packaged_recipes
recipes = {n: load_recipe(n, "jnyang").sha256 for n in packaged_recipes()}
shaders = sorted(p.name for p in _shaders._SHADER_DIR.glob("*.glsl"))
print(json.dumps({
    "models": sdk.shipped_models(), "loaded": str(sdk.load("jnyang").path), "recipes": recipes,
    "maps": sum(len(maps) for maps in load_splits().values()), "published": [m.name for m in published_models()],
    "shaders": {n: len(_shaders.load_source(n)) for n in shaders},
    "pyrender": sorted(p.name for p in _gbuffer.SHADER_DIR.iterdir() if p.is_file()),
}))
"""


@pytest.mark.slow
def test_the_installed_wheel_runs_from_its_own_files(installed: tuple[Path, Path, Run]) -> None:
    target, work, run = installed
    proc = run("-c", _IMPORT_ALL)
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = json.loads(proc.stdout.splitlines()[-1])
    assert got["modules"] >= 100  # (every module of the rooms: a wheel of fewer would import them from elsewhere)
    elsewhere = {n: f for n, f in got["files"].items() if f is None or not Path(f).is_relative_to(target)}
    assert not elsewhere, f"imported from outside the installed wheel: {elsewhere}"

    proc = run("-c", _READ_DATA)
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads(proc.stdout.splitlines()[-1])
    assert data["models"] == sorted(p.name for p in (ROOT / "models").glob("*.onnx"))
    assert Path(data["loaded"]).is_relative_to(target)
    assert sorted(data["recipes"]) == sorted(p.stem for p in (ROOT / "train/recipes").glob("*.yaml"))
    assert data["maps"] and data["published"]
    assert sorted(data["shaders"]) == sorted(p.name for p in (ROOT / "plugins/moderngl/shaders").glob("*.glsl"))
    assert all(data["shaders"].values())
    assert data["pyrender"] == ["gbuffer.frag", "gbuffer.vert"]

    # what a user runs, through the wheel's console scripts and python -m, from a folder outside the checkout
    from rtp import __version__

    for proc in (run("-m", "rtp", "--version"), run("-m", "rtp.cli", "--version"),
                 run("--version", script_name="rtp")):
        assert (proc.returncode, proc.stdout.strip()) == (0, f"rtp {__version__}"), proc.stderr[-3000:]
    proc = run("info", "jnyang", script_name="rtp")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert str(target / "rtp" / "models" / "jnyang.onnx") in proc.stdout
    proc = run("scenes", "list", "--cache-dir", str(work / "cache"), script_name="rtp")
    assert proc.returncode == 0 and f"{data['maps']} maps" in proc.stdout, proc.stderr[-3000:]
    proc = run("--help", script_name="rtp-export")
    assert proc.returncode == 0 and "--adopt" in proc.stdout, proc.stderr[-3000:]


@pytest.mark.slow
@pytest.mark.gl
def test_the_installed_wheel_renders_with_its_own_shaders(installed: tuple[Path, Path, Run]) -> None:
    """The README's first command and the adapters' conformance checks, from the installed wheel: the
    reference renderer's and the adapters' shaders, the shipped models and the entry points' adapters."""
    _, work, run = installed
    proc = run("demo", "--size", "64x48", "--out", str(work / "demo"), "--no-progress", script_name="rtp")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert {p.name for p in (work / "demo").iterdir()} >= {"frame.png", "overlay.png", "vrs_composite.png"}
    for adapter in ("moderngl", "pyrender"):  # (registered by the wheel's rtp.adapters entry points)
        proc = run("adapters", "check", adapter, "--model", "jnyang", "--json", script_name="rtp")
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
