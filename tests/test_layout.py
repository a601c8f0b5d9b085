"""The layout of docs/architecture.md, checked from the code: which room may import which.

Every folder is one room mapped into the ``rtp`` namespace. Arrows point one way (``sdk`` is the
root and imports nothing of ours); a room imports another room only through its public names
(never ``rtp.<room>._private``); and the rooms that must run without torch or GL do.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: room -> (folder, rooms it may import). The "may import" column of docs/architecture.md.
ROOMS: dict[str, tuple[str, frozenset[str]]] = {
    "sdk": ("sdk", frozenset()),
    "scene": ("scene", frozenset({"sdk"})),
    "plugins.moderngl": ("plugins/moderngl", frozenset({"sdk", "scene"})),
    "plugins.pyrender": ("plugins/pyrender", frozenset({"sdk", "scene"})),
    "metrics": ("metrics", frozenset({"sdk"})),
    "capture": ("capture", frozenset({"sdk", "scene", "plugins.moderngl", "metrics"})),
    "evaluate": ("evaluate", frozenset({"sdk", "capture", "metrics"})),
    "train": ("train", frozenset({"sdk", "metrics", "capture", "evaluate"})),
    "export": ("export", frozenset({"sdk", "train"})),
    "conformance": ("conformance", frozenset({"sdk", "scene", "plugins.moderngl", "capture"})),
    "cli": ("cli", frozenset({"sdk", "scene", "plugins.moderngl", "plugins.pyrender", "metrics", "capture",
                              "evaluate", "train", "export", "conformance", "models"})),
}
#: Third-party packages a room may import, where the design restricts them.
THIRD_PARTY: dict[str, frozenset[str]] = {
    "sdk": frozenset({"numpy", "onnxruntime", "yaml"}),
    "scene": frozenset({"numpy"}),
    "evaluate": frozenset({"numpy", "PIL", "matplotlib", "tqdm", "imageio"}),
    "conformance": frozenset({"numpy", "matplotlib"}),
}


def _room_of(module: str) -> str | None:
    """The room an ``rtp.*`` module belongs to (longest match), or None for ``rtp`` itself."""
    parts = module.split(".")[1:]
    for n in (2, 1):
        name = ".".join(parts[:n])
        if name in ROOMS or name == "models":
            return name
    return None


def _imports(path: Path, package: str) -> list[tuple[str, int]]:
    """Absolute names of every module ``path`` imports (relative imports resolved), with line numbers."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.append((mod, node.lineno))
            # `from rtp import sdk` names rooms in the imported names
            if mod == "rtp":
                out += [(f"rtp.{a.name}", node.lineno) for a in node.names]
    return out


def _sources(room: str) -> list[tuple[Path, str]]:
    folder = ROOT / ROOMS[room][0]
    # (file, the package its relative imports resolve against)
    return [(path, ".".join(["rtp", room, *path.relative_to(folder).parts[:-1]]))
            for path in sorted(folder.rglob("*.py"))]


@pytest.mark.parametrize("room", sorted(ROOMS))
def test_room_imports_follow_the_design(room: str) -> None:
    allowed = ROOMS[room][1]
    bad = []
    for path, package in _sources(room):
        for mod, line in _imports(path, package):
            if not mod.startswith("rtp.") and mod != "rtp":
                top = mod.split(".")[0]
                if room in THIRD_PARTY and top not in THIRD_PARTY[room] and top not in sys.stdlib_module_names \
                        and top != "__future__":
                    bad.append(f"{path.relative_to(ROOT)}:{line} imports {mod} (third party not allowed here)")
                continue
            other = _room_of(mod)
            if other is None or other == room:
                continue
            if other not in allowed:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {mod} ({room} may not import {other})")
            elif any(p.startswith("_") for p in mod.split(".")[1 + other.count(".") + 1:]):
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {mod}, a private module of {other}")
    assert not bad, "\n".join(bad)


def test_moderngl_adapter_does_not_import_the_renderer() -> None:
    # The renderer uses the adapter (one code path builds inputs at capture and at run time); the
    # adapter, which engines use alone, never needs the renderer.
    folder = ROOT / "plugins" / "moderngl"
    mods = {m for m, _ in _imports(folder / "_adapter.py", "rtp.plugins.moderngl")}
    assert "rtp.plugins.moderngl._renderer" not in mods


@pytest.mark.parametrize("modules", [
    ("rtp.sdk",),
    ("rtp.scene",),
    ("rtp.metrics",),
    ("rtp.capture", "rtp.capture.scenes", "rtp.capture.viewpoints"),
    ("rtp.evaluate", "rtp.evaluate.plots"),
    ("rtp.conformance",),
    ("rtp.cli",),
])
def test_rooms_that_need_no_torch_do_not_load_it(modules: tuple[str, ...]) -> None:
    code = (
        f"import sys, json, importlib; [importlib.import_module(m) for m in {list(modules)!r}]; "
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in ('torch', 'moderngl', 'pyrender', 'onnx'))))"
    )
    loaded = json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
    assert loaded == [], f"importing {modules} loads {loaded}"


def test_no_script_folder_shadows_a_standard_library_module() -> None:
    # a script runs with its own folder first on sys.path: bench/profile.py once shadowed the standard
    # library's `profile`, which torch.optim imports (through cProfile), so every bench script that trained
    # or fitted anything failed with "module 'profile' has no attribute 'run'"
    for folder in ("bench", "examples", ".ci"):
        names = {p.stem for p in (ROOT / folder).glob("*.py")}
        clash = sorted(names & set(sys.stdlib_module_names))
        assert not clash, f"{folder}/ holds scripts named like standard-library modules: {clash}"
