"""The layout of docs/architecture.md, checked from the code: which room may import which.

Every folder is one room mapped into the ``rtp`` namespace. Arrows point one way (``sdk`` is the
root and imports nothing of ours); a room imports another room only through its public names
(never ``rtp.<room>._private``); and the rooms that must run without torch or GL do.
"""

from __future__ import annotations

import ast
import json
import os
import re
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
    "evaluate": frozenset({"numpy", "PIL", "matplotlib"}),
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
            # `from rtp import sdk` and `from rtp.plugins import pyrender` name rooms in the imported
            # names, and `from rtp.sdk import _planes` a private module or name of the room
            if mod == "rtp" or mod.startswith("rtp."):
                out += [(f"{mod}.{a.name}", node.lineno) for a in node.names if a.name != "*"]
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


#: Distribution names docs/architecture.md gives packages whose import name differs.
_DISTRIBUTIONS = {"yaml": "pyyaml", "png": "pypng", "flip_evaluator": "flip-evaluator", "OpenGL": "PyOpenGL"}


def _doc_rooms() -> dict[str, tuple[set[str], set[str]]]:
    """docs/architecture.md's room table: import name -> (rooms it may import, third-party packages it names), the
    remarks in parentheses left out."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    out = {}
    for m in re.finditer(r"^\| `[\w/]+/` \| `rtp\.([\w.]+)` \|[^|]*\|([^|]*)\|([^|]*)\|$", text, re.M):
        ours, theirs = m.group(2), m.group(3)
        while re.search(r"\([^()]*\)", ours + theirs):
            ours, theirs = (re.sub(r"\([^()]*\)", "", s) for s in (ours, theirs))
        names = {w.strip().split(" ")[0] for w in ours.split(",") if w.strip()}
        out[m.group(1)] = (names - {"nothing"}, {w.strip().split(" ")[0] for w in theirs.split(",") if w.strip()})
    return out


def test_the_architecture_page_says_what_each_room_imports() -> None:
    """docs/architecture.md's table is "exact" (its words): the "may import (ours)" column is ROOMS', and the third-party
    column names every package the room's code imports (the cli row lacked Pillow and matplotlib, which `rtp metric`,
    `rtp predict --out` and `rtp adapters check --image` import)."""
    doc = _doc_rooms()
    assert set(doc) >= set(ROOMS), f"rooms missing from docs/architecture.md's table: {sorted(set(ROOMS) - set(doc))}"
    bad = []
    for room, (_, allowed) in ROOMS.items():
        ours, theirs = doc[room]
        if ours != set(allowed) and not (room == "cli" and "every" in ours):
            bad.append(f"{room}: the page says it may import {sorted(ours)}, tests/test_layout.py {sorted(allowed)}")
        used = {_DISTRIBUTIONS.get(top, top) for path, package in _sources(room) for mod, _ in _imports(path, package)
                if (top := mod.split(".")[0]) not in sys.stdlib_module_names and top not in ("rtp", "__future__")}
        if used - theirs:
            bad.append(f"{room}: imports {sorted(used - theirs)}, which the page's third-party column does not name")
    assert not bad, "docs/architecture.md:\n" + "\n".join(bad)


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


def _library_sources() -> list[Path]:
    """Every source file of the rooms but the command line's (``cli/``, which may print)."""
    return [path for room in sorted(ROOMS) if room != "cli" for path, _ in _sources(room)]


def _prints(path: Path) -> list[str]:
    """``print(...)`` calls and writes to ``sys.stdout`` / ``sys.stderr`` in ``path``."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        if isinstance(f, ast.Name) and f.id == "print" or (
                isinstance(f, ast.Attribute) and f.attr in ("write", "writelines") and isinstance(f.value, ast.Attribute)
                and f.value.attr in ("stdout", "stderr", "__stdout__", "__stderr__")):
            out.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return out


def test_library_code_logs_and_never_prints() -> None:
    # docs/runtime.md: logging goes to the `rtp` logger; the command line (cli/) is the only room that
    # prints, and a library printing would write into an engine's or a notebook's output
    bad = [hit for path in _library_sources() for hit in _prints(path)]
    assert not bad, "library code prints (log through logging.getLogger(__name__) instead):\n" + "\n".join(bad)


def _text_mode(mode: ast.expr | None) -> bool:
    """Whether a file is opened in text mode: no mode given, or a literal one without ``b`` (a mode the code
    computes counts as text: it must say its encoding, or be written as a literal)."""
    return not (isinstance(mode, ast.Constant) and isinstance(mode.value, str) and "b" in mode.value)


def _mode(call: ast.Call, position: int) -> ast.expr | None:
    given = [k.value for k in call.keywords if k.arg == "mode"]
    return given[0] if given else call.args[position] if len(call.args) > position else None


def _unnamed_encodings(path: Path) -> list[str]:
    """Files ``path`` reads or writes as text without naming an encoding: ``read_text`` / ``write_text``, ``open()``
    and ``Path.open()`` in text mode, tempfile's and ``os.fdopen``'s text files."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if not isinstance(node, ast.Call) or any(k.arg == "encoding" for k in node.keywords):
            continue
        f = node.func
        name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""
        if name in ("read_text", "write_text"):
            bad = True
        elif name == "open" and isinstance(f, ast.Name):
            bad = _text_mode(_mode(node, 1))
        elif name == "open":  # Path.open(mode); a zip member's z.open("name") or os.open(path, flags) is bytes
            mode = _mode(node, 0)
            bad = (mode is None and not node.args or isinstance(mode, ast.Constant) and isinstance(mode.value, str)
                   and set(mode.value) <= set("rwaxt+") and "b" not in mode.value)
        elif name in ("NamedTemporaryFile", "TemporaryFile", "SpooledTemporaryFile"):
            bad = _mode(node, 0) is not None and _text_mode(_mode(node, 0))  # (default: w+b)
        elif name == "fdopen":
            bad = _text_mode(_mode(node, 1))
        else:
            bad = False
        if bad:
            out.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)[:80]}")
    return out


def test_text_files_name_their_encoding() -> None:
    """A file read or written as text without ``encoding=`` uses the locale's: under LC_ALL=C (engines' and CI's
    build machines) a non-ASCII character fails with a UnicodeError, and under a Windows cp1252 locale the same
    bytes read as other text (shipped.yaml's 'R²' gave another digest). rtp's files are UTF-8 everywhere."""
    folders = {ROOMS[room][0] for room in ROOMS} | {"plugins", "models", "bench", "examples"}
    paths = sorted({p for folder in folders for p in (ROOT / folder).rglob("*.py")})
    bad = [hit for path in paths for hit in _unnamed_encodings(path)]
    assert not bad, "text files opened without encoding= (add encoding=\"utf-8\"):\n" + "\n".join(bad)


def test_library_log_messages_are_ascii() -> None:
    """The rooms' log and warning messages are ASCII: an engine that imports rtp logs through its own handlers,
    which under a C/POSIX locale or a Windows console's cp1252 print "--- Logging error ---" and a traceback for a
    character their stream cannot encode ('m³' did; rtp's own commands write such characters in ASCII through
    cli/_run.py's console handler, an engine's handlers do not)."""
    folders = {ROOMS[room][0] for room in ROOMS} | {"plugins"}
    bad = []
    for path in sorted({p for folder in folders for p in (ROOT / folder).rglob("*.py")}):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in (
                    "debug", "info", "warning", "error", "exception", "critical", "warn"):
                chars = {c for n in ast.walk(node) if isinstance(n, ast.Constant) and isinstance(n.value, str)
                         for c in n.value if ord(c) > 127}
                if chars:
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {''.join(sorted(chars))}")
    assert not bad, "log messages with characters other than ASCII:\n" + "\n".join(bad)


def _top_level_names(tree: ast.Module) -> set[str]:
    """Names a module binds at its top level (also inside top-level ``if`` / ``try`` blocks)."""
    names: set[str] = set()
    body = list(tree.body)
    while body:
        node = body.pop()
        if isinstance(node, (ast.If, ast.Try)):
            body += node.body + node.orelse + getattr(node, "finalbody", [])
            body += [n for h in getattr(node, "handlers", []) for n in h.body]
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                names |= {n.id for n in ast.walk(target) if isinstance(n, ast.Name)}
    return names


def _all_problems(path: Path) -> list[str]:
    """What is wrong with a public module's ``__all__``: missing, not a literal list of strings, naming a
    private name, or naming something the module does not define."""
    where = str(path.relative_to(ROOT))
    tree = ast.parse(path.read_text(), str(path))
    values = [n.value for n in tree.body if isinstance(n, (ast.Assign, ast.AnnAssign)) and n.value is not None
              and any(isinstance(t, ast.Name) and t.id == "__all__"
                      for t in (n.targets if isinstance(n, ast.Assign) else [n.target]))]
    if not values:
        return [f"{where}: a public module without __all__"]
    try:
        names = ast.literal_eval(values[-1])
    except ValueError:
        return [f"{where}: __all__ is not a literal list of names"]
    bound = _top_level_names(tree)
    lazy = "__getattr__" in bound  # a module __getattr__ serves names it does not bind
    out = [f"{where}: __all__ names the private {n!r}" for n in names if n.startswith("_") and not n.startswith("__")]
    out += [f"{where}: __all__ names {n!r}, which it does not define" for n in names if n not in bound and not lazy]
    return out


def test_every_public_module_declares_its_public_names() -> None:
    # a public module (no `_` in its path) says what it exports, and exports nothing private by accident
    bad = []
    for room in sorted(ROOMS):
        for path, _ in _sources(room):
            rel = path.relative_to(ROOT / ROOMS[room][0]).parts
            if path.name == "__main__.py" or any(p.startswith("_") and p != "__init__.py" for p in rel):
                continue
            bad += _all_problems(path)
    bad += _all_problems(ROOT / "cli" / "_package" / "__init__.py")  # the `rtp` package itself
    assert not bad, "\n".join(bad)


def test_every_package_is_typed() -> None:
    # PEP 561: a user's type checker reads rtp's annotations only where a py.typed marker ships. Every
    # room, and `rtp` itself (`rtp.__version__`), carries one in the checkout and in the package data
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    package_data = config["package-data"]
    missing = []
    for package, folder in config["package-dir"].items():
        if not (ROOT / folder / "__init__.py").is_file() or package == "rtp.plugins" or package == "rtp.models":
            continue  # rtp.plugins holds only the adapters' rooms, rtp.models only data
        if not (ROOT / folder / "py.typed").is_file():
            missing.append(f"{folder}/py.typed (for {package})")
        if "py.typed" not in package_data.get(package, []):
            missing.append(f'pyproject.toml [tool.setuptools.package-data] "{package}" lacks "py.typed"')
    assert not missing, "\n".join(missing)



#: An engine's program as docs/quickstart.md, runtime.md, adapters.md and metrics.md write it, under ``mypy
#: --strict``: every call type-checks, and what the main calls return is the precise type (``assert_type``), not Any.
_USER_PROGRAM = """
from __future__ import annotations

import logging
from collections.abc import Iterable
from pathlib import Path
from typing import Any, ClassVar, assert_type

import numpy as np

import rtp
from rtp import conformance, metrics, sdk
from rtp.plugins.moderngl import Adapter as GLAdapter
from rtp.plugins.moderngl import GBufferTextures, RateSelector
from rtp.sdk.adapters import Adapter, FrameSource

log = logging.getLogger("engine")


def frame(x: np.ndarray, prev_colour: np.ndarray, depth: np.ndarray, view: np.ndarray, projection: np.ndarray,
          prev_view_projection: np.ndarray) -> np.ndarray:
    predictor = sdk.load("jnyang", threads=2, providers=["CUDAExecutionProvider", ("CPUExecutionProvider", {})])
    meta = predictor.metadata
    assert_type(meta, sdk.ModelMetadata)
    assert_type(meta.inputs, tuple[str, ...])
    assert_type(meta.default_threshold, float)
    assert_type(meta.higher_is_better, bool)
    assert_type(meta.rate_factors, tuple[float, ...])
    assert_type(meta.weber_l, float | None)
    assert_type(meta.threshold_warning(0.2), str | None)
    assert_type(predictor.tile_size, int)
    assert_type(predictor.provider, str)
    assert_type(predictor.rates, tuple[str, ...])
    assert_type(predictor.path, Path | None)
    assert_type(predictor.tiles(720, 1280), tuple[int, int])
    assert_type(predictor.predict(x), np.ndarray)
    rates = predictor.shading_rates(x)
    assert_type(rates, np.ndarray)
    rates = predictor.shading_rates(x, threshold=0.2, allowed=["1x2", "2x1", "2x2"])
    rates = predictor.shading_rates(x, 0.2, (r for r in sdk.PREDICTED_RATES if r != "4x4"))
    rates = predictor.shading_rates(x, saving=0.6)
    engine_rates = np.full(rates.shape, sdk.RATE_CODES["2x1"], np.uint8)
    image = predictor.shading_rates(x, engine_rates=engine_rates, combiner="max")
    assert_type(sdk.combine_rates(engine_rates, image, "max"), np.ndarray)
    budget = sdk.select_rates_for_saving(predictor.predict(x), 0.6, higher_is_better=meta.higher_is_better,
                                         factors=meta.rate_factors, frame_size=(720, 1280),
                                         tile_size=predictor.tile_size)
    assert_type(budget, sdk.SavingSelection)
    assert_type(budget.rates, np.ndarray)
    assert_type(sdk.select_rates(predictor.predict(x), 0.2, allowed=["1x2", 5]), np.ndarray)
    assert_type(sdk.work_saved(rates), float)
    assert_type(sdk.draw_rate_overlay(prev_colour, rates, predictor.tile_size, legend=True), np.ndarray)
    assert_type(sdk.gbuffers_needed(meta.inputs), tuple[str, ...])
    for warning in sdk.check_gbuffers(depth=depth, view=view, projection=projection, prev_colour=prev_colour,
                                      prev_depth=depth, prev_view_projection=prev_view_projection):
        log.warning("%s", warning)
    colour, seen = sdk.reproject(prev_colour, depth, depth, view, projection, prev_view_projection)
    planes = sdk.input_planes(meta.inputs, depth=depth, view=view, projection=projection, prev_colour=prev_colour,
                              prev_depth=depth, prev_view_projection=prev_view_projection)
    assert_type(planes, np.ndarray)
    reuse = sdk.PredictionReuse(predictor, every=4)
    fetch = sdk.fetch_from_motion(planes[0], planes[1])
    assert_type(reuse.shading_rates(planes, fetch=fetch, seen=seen, background=depth == 0), np.ndarray)
    assert_type(reuse.age, int | None)
    assert_type(rtp.__version__, str)
    assert_type(sdk.__version__, str)
    return rates


def load_or_none(name: str) -> sdk.ShadingRatePredictor | None:
    try:
        return sdk.load(name, tile_size=8)
    except sdk.ModelNotFoundError as err:
        log.error("no model: %s", err)
    except (sdk.ModelLoadError, sdk.MetadataError) as err:
        log.error("bad model: %s", err)
    except sdk.RtpError as err:
        assert_type(sdk.exit_code(err), int)
    return None


def on_gpu(predictor: sdk.ShadingRatePredictor, ctx: Any, x: np.ndarray, tex: Any) -> None:
    selector = RateSelector(predictor, ctx)
    assert_type(selector.select(predictor.predict_raw(x)), np.ndarray)
    selector.select_buffer(tex, (45, 80), threshold=0.2, allowed=["1x2", "2x1", "2x2"])
    assert_type(selector.decoded(), np.ndarray)
    with GLAdapter.for_predictor(predictor, 1280, 720, ctx=ctx) as adapter:
        assert_type(adapter, GLAdapter)
        textures = GBufferTextures(albedo=tex, normal=tex, depth=tex, view=np.eye(4), projection=np.eye(4),
                                   prev_colour=tex, prev_depth=tex, prev_view_projection=np.eye(4))
        assert_type(adapter.inputs(textures), np.ndarray)
        assert_type(adapter.check(textures), list[str])


def absdiff(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
    return np.asarray(np.abs(reference - test), np.float32)


MINE = metrics.Metric("absdiff", absdiff, default_threshold=0.05, pooling="max", params={"version": 1})


class MyFrame:
    depth: np.ndarray


class MyEngineAdapter(Adapter[MyFrame]):
    name: ClassVar[str] = "myengine"
    supported_channels: ClassVar[frozenset[str]] = frozenset({"depth"})
    frame_type: ClassVar[type] = MyFrame

    def __init__(self, channels: Iterable[str], width: int, height: int, *, engine: Any = None) -> None:
        super().__init__(channels, width, height)
        self.engine = engine

    def inputs(self, frame: MyFrame) -> np.ndarray:
        return sdk.input_planes(self.channels, depth=frame.depth)

    def close(self) -> None:
        pass

    @classmethod
    def frame_source(cls, scene: Any, width: int, height: int, **options: Any) -> MyFrameSource:
        return MyFrameSource(cls, width, height)


class MyFrameSource(FrameSource[MyFrame]):
    def frame(self, camera: Any, prev_camera: Any) -> MyFrame:
        return MyFrame()

    def close(self) -> None:
        pass


def conform(predictor: sdk.ShadingRatePredictor, frame: MyFrame) -> None:
    sdk.adapters.register("myengine", MyEngineAdapter)
    with MyEngineAdapter.for_predictor(predictor, 64, 48) as adapter:
        assert_type(adapter, MyEngineAdapter)
        assert_type(adapter.channels, tuple[str, ...])
    with MyEngineAdapter.frame_source(None, 64, 48) as source, source.adapter(predictor.metadata.inputs) as a:
        assert_type(a.inputs(source.frame(None, None)), np.ndarray)
    report = conformance.check_adapter("myengine", tolerances={"albedo.r": 0.08})
    assert_type(report.ok, bool)
    assert_type(sdk.adapters.get("moderngl"), type[Adapter[Any]])
"""

#: ``rtp.metrics``' map functions as docs/metrics.md calls them: numpy in, numpy out; torch in, torch out (until
#: 2026-12-08 each returned ``Any``: ``metrics.flip_map(ref, test).shpe`` passed). Their container is the reference's.
_USER_METRICS = """
from __future__ import annotations

from collections.abc import Mapping
from typing import assert_type

import numpy as np
import numpy.typing as npt
import torch

from rtp import metrics, sdk


def numpy_maps(reference: npt.NDArray[np.float32], test: np.ndarray, i12: np.ndarray) -> None:
    emap = metrics.flip_map(reference, test)
    assert_type(emap, np.ndarray)
    assert_type(metrics.pool_tiles(emap, 16), np.ndarray)
    assert_type(metrics.pool_tiles([[0.5, 1.0]], 16, "mean"), np.ndarray)
    assert_type(metrics.psnr_tiles(reference, test, 16), np.ndarray)
    assert_type(metrics.jnflip_map(reference, test, ppd="width", weber_l=metrics.PAPER_WEBER_L), np.ndarray)
    assert_type(metrics.yang_map(reference, test), np.ndarray)
    assert_type(metrics.jnyang_map(reference, test, weber_l=0.05), np.ndarray)
    assert_type(metrics.squared_error_map(reference, test), np.ndarray)
    assert_type(metrics.lpips_map(reference, test, paper_quirk=True), np.ndarray)
    assert_type(metrics.error_map("jnflip", reference, test, ppd=33.5), np.ndarray)
    assert_type(metrics.tile_metric("psnr", reference, test, 8), np.ndarray)
    assert_type(metrics.weber_denominator(reference), np.ndarray)
    assert_type(metrics.tile_targets(reference, {"1x2": i12}, ["jnflip", "psnr"], missing="nan"),
                dict[str, np.ndarray])


def torch_maps(reference: torch.Tensor, test: torch.Tensor, either: np.ndarray | torch.Tensor) -> None:
    emap = metrics.flip_map(reference, test)
    assert_type(emap, torch.Tensor)
    assert_type(metrics.pool_tiles(emap, 16, "mean"), torch.Tensor)
    assert_type(metrics.psnr_tiles(reference, test), torch.Tensor)
    assert_type(metrics.jnflip_map(reference, test), torch.Tensor)
    assert_type(metrics.yang_map(reference, test), torch.Tensor)
    assert_type(metrics.jnyang_map(reference, test), torch.Tensor)
    assert_type(metrics.squared_error_map(reference, test), torch.Tensor)
    assert_type(metrics.lpips_map(reference, test), torch.Tensor)
    assert_type(metrics.error_map("flip", reference, test), torch.Tensor)
    assert_type(metrics.tile_metric("lpips", reference, test, 16, lpips_paper_quirk=True), torch.Tensor)
    assert_type(metrics.weber_denominator(reference), torch.Tensor)
    assert_type(metrics.yang_map(either, test), np.ndarray | torch.Tensor)
    assert_type(metrics.resolve_device("auto"), torch.device)
    assert_type(metrics.device_name(metrics.resolve_device("cpu")), str)
    assert_type(metrics.targets_device(["lpips"], "auto"), torch.device | None)
    assert_type(metrics.lpips_network(), torch.nn.Module)


def own(metric: metrics.Metric, reference: np.ndarray) -> None:
    metrics.register_metric(metric)
    metrics.check_worker_metrics([metric.name, "flip"])
    assert_type(metric.map(reference, reference), np.ndarray)
    assert_type(metric.info, sdk.MetricInfo)
    assert_type(metrics.metric_info(metric.name), sdk.MetricInfo)
    assert_type(metrics.known_metrics(), tuple[str, ...])
    assert_type(metrics.metric_plugins(), Mapping[str, metrics.Metric])


def mistakes(reference: np.ndarray) -> None:  # each an error (strict's warn_unused_ignores: one that is not fails)
    metrics.flip_map([[[0.5, 0.5, 0.5]]], reference)  # type: ignore[call-overload]  # a list: InputDtypeError
    metrics.check_worker_metrics(5)  # type: ignore[arg-type]
"""

#: Names a user may misspell: each line is an error of mypy's, where a module ``__getattr__`` made every name exist.
_USER_TYPOS = """
import rtp as package
from rtp import sdk
from rtp.sdk import PredictonReuse
sdk.lod("jnyang")
package.versoin
"""


def _package_tree(root: Path) -> Path:
    """An ``rtp`` package tree of links to the rooms, as pyproject.toml's package-dir maps them (what a wheel holds,
    which mypy cannot follow through the editable install's import hook); ``root`` returned for MYPYPATH."""
    import tomllib

    dirs = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    for package, folder in sorted(dirs.items(), key=lambda item: item[0].count(".")):
        target = root.joinpath(*package.split("."))
        if any(other.startswith(package + ".") for other in dirs):  # a package with subpackages mapped elsewhere
            target.mkdir(parents=True)
            for path in (ROOT / folder).iterdir():
                if path.is_file():
                    (target / path.name).symlink_to(path)
        else:
            target.symlink_to(ROOT / folder)
    return root


@pytest.mark.slow
def test_a_users_type_checker_sees_the_public_api(tmp_path: Path) -> None:
    """rtp ships py.typed: a user's ``mypy --strict`` takes the documented calls and sees precise types. Until
    2026-12-08 ``rtp`` and ``rtp.sdk`` defined a module ``__getattr__`` (for ``__version__``), which a type checker
    reads as "any other name exists, a str": ``from rtp.sdk import PredictonReuse`` and ``sdk.lod(...)`` passed. Until
    2026-12-08 ``rtp.metrics``' map functions returned ``Any`` (now numpy for numpy, torch for torch: ``maps.py``), and
    docs/metrics.md's own metric and examples/metric_plugin, copied out, failed ``--strict``."""
    tree = _package_tree(tmp_path / "tree")
    (tmp_path / "engine.py").write_text(_USER_PROGRAM)
    (tmp_path / "typos.py").write_text(_USER_TYPOS)
    (tmp_path / "maps.py").write_text(_USER_METRICS)
    # docs/metrics.md's "your own metric" block, and the example plugin, as a user copies them out
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "metrics.md").read_text(), re.S)
    (tmp_path / "own_metric.py").write_text(next(b for b in blocks if "metrics.Metric(" in b))
    (tmp_path / "rtp_ssim.py").write_text((ROOT / "examples" / "metric_plugin" / "rtp_ssim.py").read_text())
    (tmp_path / "mypy.ini").write_text(
        "[mypy]\nstrict = True\npython_version = 3.11\n\n"
        # as for an installed package: rtp's own code is read, its own errors not reported
        "[mypy-rtp.*]\nfollow_imports = silent\n\n"
        "[mypy-moderngl.*,onnxruntime.*,yaml.*,trimesh.*,PIL.*,flip_evaluator.*,matplotlib.*,scipy.*,tqdm.*]\n"
        "ignore_missing_imports = True\n"
    )
    proc = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", "mypy.ini", "--cache-dir", str(tmp_path / "cache"),
         "--no-error-summary", "engine.py", "typos.py", "maps.py", "own_metric.py", "rtp_ssim.py"],
        cwd=tmp_path, env={**os.environ, "MYPYPATH": str(tree)}, capture_output=True, text=True, timeout=300,
    )
    errors = [line for line in proc.stdout.splitlines() if ": error:" in line]
    assert not [e for e in errors if not e.startswith("typos.py:")], proc.stdout + proc.stderr
    assert [e.split(":")[1] for e in errors] == ["4", "5", "6"], proc.stdout + proc.stderr

#: Facts ``rtp.sdk`` holds, by a value no other room has a reason to write: value -> the name to use.
SDK_FACTS = {2.13: "rtp.sdk.DEFAULT_EXTRAPOLATION_K", 0.299: "rtp.sdk.LUMA_WEIGHTS", 0.587: "rtp.sdk.LUMA_WEIGHTS",
             0.114: "rtp.sdk.LUMA_WEIGHTS"}


def test_no_room_restates_the_sdks_facts() -> None:
    # design.md: facts every room needs live once, public, in sdk; no room re-states them. (The torch port
    # of flip-evaluator in metrics/_flipbatch.py keeps FLIP's own sRGB curve, tested against FLIP.)
    from rtp import sdk

    assert sdk.DEFAULT_EXTRAPOLATION_K == 2.13 and tuple(sdk.LUMA_WEIGHTS) == (0.299, 0.587, 0.114)
    bad = []
    for path in _library_sources():
        if path.is_relative_to(ROOT / "sdk"):
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Constant) and type(node.value) is float and node.value in SDK_FACTS:
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno} writes {node.value} (use {SDK_FACTS[node.value]})")
    assert not bad, "\n".join(bad)


def _shared_facts() -> dict[str, object]:
    """The named facts other rooms take from their home: the public numeric constants of ``rtp.sdk``,
    ``rtp.sdk.files`` and ``rtp.metrics``, and ``rtp.sdk.files.LOCK_NAME``."""
    from rtp import metrics, sdk
    from rtp.sdk import files

    out: dict[str, object] = {}
    for mod in (sdk, files, metrics):
        for name in mod.__all__:
            value = getattr(mod, name)
            if name.isupper() and isinstance(value, (int, float)) and not isinstance(value, bool):
                out[name] = value
    out["LOCK_NAME"] = files.LOCK_NAME
    return out


#: Constants and parameter defaults that merely coincide with a fact of the same value and a shared word (another
#: meaning): the Weber denominator's 4x4 block (not block_variances' cell), BatchNorm's epsilon.
_COINCIDENCES = {("metrics/_pool.py", "WEBER_BLOCK", "BLOCK_CELL"), ("train/model.py", "eps", "BLOCK_EPS")}


def _fact_words(name: str) -> set[str]:
    """A name's words that say what it is (not DEFAULT, MAX, MIN); ``env_luminance`` is the Weber ``l``."""
    words = set(name.upper().strip("_").split("_")) - {"DEFAULT", "MAX", "MIN"}
    return words | ({"WEBER", "L"} if {"ENV", "LUMINANCE"} & words else set())


def test_no_room_restates_a_shared_fact() -> None:
    """A fact has one home (docs/architecture.md): no room but its home writes the value again, as a module constant
    or a parameter's default of the same meaning (the same value under a name with a word of the fact's). Found so:
    capture/_import.py's ``MAX_TOLERANCE = 1.0`` beside sdk's reprojection limit, the moderngl adapter's and
    renderer's ``tolerance=0.02``, Yang 2019's ``env_luminance=0.02`` (metrics' Weber l) and train's lock file name
    ``.rtp-writer.lock`` spelt out."""
    facts = _shared_facts()
    bad = []
    for room in sorted(ROOMS):
        if room == "sdk":
            continue
        for path, _ in _sources(room):
            rel = path.relative_to(ROOT).as_posix()
            tree = ast.parse(path.read_text(encoding="utf-8"))
            named: list[tuple[str, ast.expr, int]] = []  # (name, value, line): module constants, parameter defaults
            for node in tree.body:
                if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
                    named.append((node.targets[0].id, node.value, node.lineno))
                elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.value is not None:
                    named.append((node.target.id, node.value, node.lineno))
            docstrings = set()
            for node in ast.walk(tree):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                    a = node.args
                    positional = a.posonlyargs + a.args
                    named += [(p.arg, d, node.lineno) for p, d in zip(positional[len(positional) - len(a.defaults):],
                                                                       a.defaults, strict=True)]
                    named += [(p.arg, d, node.lineno) for p, d in zip(a.kwonlyargs, a.kw_defaults, strict=True)
                              if d is not None]
                if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
                    docstrings.add(id(node.value))
            for name, value, line in named:
                if not isinstance(value, ast.Constant) or isinstance(value.value, (bool, str)) \
                        or not isinstance(value.value, (int, float)):
                    continue
                for fact, v in facts.items():
                    if v == value.value and _fact_words(name) & _fact_words(fact) \
                            and not (room == "metrics" and fact in __import__("rtp.metrics").metrics.__all__) \
                            and (rel, name, fact) not in _COINCIDENCES:
                        bad.append(f"{rel}:{line} {name} = {value.value!r} (rtp's {fact})")
            for node in ast.walk(tree):  # the lock file's name, in a string the code uses
                if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings \
                        and str(facts["LOCK_NAME"]) in node.value:
                    bad.append(f"{rel}:{node.lineno} spells out the writer lock's name (rtp.sdk.files.LOCK_NAME)")
    assert not bad, "facts written again rather than imported from their home:\n" + "\n".join(bad)
