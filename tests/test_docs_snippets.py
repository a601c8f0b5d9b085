"""Every Python block of docs/*.md runs, so the pages cannot drift from the code (the README's blocks:
tests/test_readme.py).

A page's snippet names what an engine would have (``predictor``, ``x``, the engine's textures and
matrices): :data:`SETUP` gives each block that context, made from the built-in procedural scene and
the shipped models, and a check of what the block produced. A block that needs what CI does not
have (the game levels of ``rtp scenes fetch``, ten minutes of rendering) is listed in
:data:`NOT_RUN` with the reason; its imports still run and the whole block must compile. A block in
neither list fails the first test, so a new snippet is either run or declared.

The ``rtp``, ``rtp-export`` and ``python bench/...`` commands of the pages are parsed by their own
parsers (not run: they read datasets CI does not capture), so a flag, choice or script the code no
longer has fails here."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

_MODEL = """
import numpy as np
from rtp import sdk
predictor = sdk.load("jnyang")
H, W = 72, 128
x = np.random.default_rng(0).random((len(predictor.metadata.inputs), H, W), dtype=np.float32)
"""
_SCENE = """
from rtp.capture.scenes import procedural
from rtp.capture.viewpoints import sample_viewpoints
scene = procedural(0)
prev_camera, camera = sample_viewpoints(scene, 1, seed=0)[0]
"""
_SOURCE = _MODEL + _SCENE + """
width, height = W, H
source = sdk.adapters.get("moderngl").frame_source(scene, width, height)
frame = source.frame(camera, prev_camera)
"""

#: (page, key) -> (what the block needs, a check of what it made). The key is the block's first line
#: that is not an import, without its comment.
SETUP: dict[tuple[str, str], tuple[str, str]] = {
    ("adapters.md", 'Adapter = sdk.adapters.get("moderngl")'): (
        _SOURCE + "engine_objects = source.adapter_options()\nengine_frames = [frame, source.frame(camera, camera)]\n",
        "assert rates.shape == sdk.tile_grid(height, width, predictor.tile_size) and rates.dtype == np.uint8",
    ),
    ("adapters.md", "Adapter = sdk.adapters.get(name)"): (
        _MODEL + _SCENE + 'name, width, height = "moderngl", W, H\n',
        "assert x.shape == (len(predictor.metadata.inputs), height, width) and x[1].mean() > 0.5  # seen",
    ),
    ("adapters.md", 'Adapter = sdk.adapters.get("pyrender")'): (
        "",
        'assert {"moderngl", "pyrender"} <= set(sdk.adapters.available())',
    ),
    ("adapters.md", "@dataclass(frozen=True)"): (  # the adapter skeleton, driven with a frame of arrays
        "",
        """
from rtp.scene import Camera

rng = np.random.default_rng(0)
P = Camera((0.0, 0.0, 0.0)).projection(48 / 32)  # (a perspective; an orthographic one reprojects too)
frame = MyFrame(rng.random((32, 48, 3)), rng.random((32, 48, 3)) * 2 - 1, 1 + rng.random((32, 48)), np.eye(4),
                P, rng.random((32, 48, 3)), 1 + rng.random((32, 48)), P)
with MyEngineAdapter(["reprojected.y", "seen", "albedo.y", "normal.z", "reprojected.y.blocks"], 48, 32) as a:
    x = a.inputs(frame)
assert x.shape == (5, 32, 48) and x.dtype == np.float32 and np.isfinite(x).all()
# ... and, given an engine (the reference renderer read back to numpy), it passes the conformance kit
from rtp import conformance
from rtp.plugins.moderngl import Renderer

class ReferenceEngine(MyFrameSource):
    def __init__(self, adapter_class, scene, width, height):
        FrameSource.__init__(self, adapter_class, width, height)
        self.engine = Renderer(width, height)
        self.engine.load_scene(scene)

    def frame(self, camera, prev_camera):
        self.engine.ctx.__enter__()
        prev = self.engine.render(prev_camera)
        cur = self.engine.render(camera, prev)
        return MyFrame(cur.albedo, cur.normal, cur.depth, camera.view(), camera.projection(self.width / self.height),
                       prev.colour["1x1"], prev.depth, prev_camera.view_projection(self.width, self.height))

    def close(self):
        self.engine.release()

MyEngineAdapter.frame_source = classmethod(lambda cls, scene, width, height: ReferenceEngine(cls, scene, width, height))
report = conformance.check_adapter(MyEngineAdapter)
assert report.ok and not report.skipped and report.runs_models == ("lpips.onnx",), str(report)
""",
    ),
    ("adapters.md", "def test_my_adapter_conforms():"): (  # a plugin's test, on the CPU adapter of tests/
        f"import sys\nsys.path.insert(0, {str(ROOT)!r})\nfrom rtp import sdk\n"
        "from tests.test_adapter_contract import NumpyAdapter\n"
        "sdk.adapters.register('myengine', type('MyEngine', (NumpyAdapter,), {'name': 'myengine'}))\n",
        "test_my_adapter_conforms()\nassert conformance.check_adapter('myengine').runs_models == ('lpips.onnx',)",
    ),
    ("adapters.md", "scene = pyrender.Scene(ambient_light=(0.3, 0.3, 0.3))"): (
        "",
        "assert rates.shape == (1, 23, 40) and x.shape == (len(predictor.metadata.inputs), 360, 640)",
    ),
    ("adapters.md", "before = np.array(door.matrix)"): (
        """
import os; os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
import numpy as np
import pyrender
import trimesh
from rtp.plugins.pyrender import Adapter, SceneFrame

scene = pyrender.Scene(ambient_light=(0.3, 0.3, 0.3))
scene.add(pyrender.Mesh.from_trimesh(trimesh.creation.box((8.0, 8.0, 0.1))), pose=np.diag([1.0, 1, 1, 1]))
door = scene.add(pyrender.Mesh.from_trimesh(trimesh.creation.box((1.0, 2.0, 0.1))))


def door_pose(t):
    p = np.eye(4)
    p[:3, 3] = (t, 0.0, 1.0)
    return p


scene.set_pose(door, door_pose(0.0))
scene.add(pyrender.PerspectiveCamera(yfov=1.0))
pose = prev_pose = np.eye(4)
pose[2, 3] = prev_pose[2, 3] = 5.0
t = 0.25
adapter = Adapter(["seen", "motion.x"], 64, 48)
prev_colour, _ = adapter.render(scene, prev_pose)
""",
        "assert x.shape == (2, 48, 64) and x[1].min() < -0.5 and x[0][x[1] < -0.5].mean() > 0.9\nadapter.close()",
    ),
    ("metrics.md", "emap = metrics.flip_map(reference, test)"): (
        """
import numpy as np
rng = np.random.default_rng(0)
reference = rng.random((40, 56, 3), dtype=np.float32)
test, i12, i21, i22, i24, i42, i44 = (np.clip(reference + 0.05 * rng.standard_normal(reference.shape), 0, 1)
                                      .astype(np.float32) for _ in range(7))
""",
        'assert emap.shape == (40, 56) and tiles.shape == psnr.shape == (3, 4) and targets["jnflip"].shape == (6, 3, 4)',
    ),
    ("metrics.md", "def absdiff(reference: np.ndarray, test: np.ndarray) -> np.ndarray:"): (
        "",
        """
metrics.register_metric(MINE)
rng = np.random.default_rng(0)
reference = rng.random((40, 56, 3), dtype=np.float32)
test = np.clip(reference + 0.1, 0, 1).astype(np.float32)
tiles = metrics.tile_metric("absdiff", reference, test, 16)
assert tiles.shape == (3, 4) and metrics.metric_info("absdiff").units == "abs. difference"
assert np.allclose(tiles, metrics.pool_tiles(np.abs(reference - test).max(axis=-1), 16))
""",
    ),
    ("quickstart.md", 'predictor = sdk.load("jnyang.onnx")'): (
        "",
        'assert predictor.tile_size == 16 and predictor.provider == "CPUExecutionProvider"',
    ),
    ("quickstart.md", "errors = predictor.predict(x)"): (
        _MODEL,
        "assert errors.shape == (6, 5, 8) and rates.shape == (5, 8)",
    ),
    ("quickstart.md", "overlay = sdk.draw_rate_overlay(frame_rgb, rates, predictor.tile_size)"): (
        _MODEL + "rates = predictor.shading_rates(x)\nframe_rgb = np.full((H, W, 3), 0.5, np.float32)\n",
        "assert overlay.shape == frame_rgb.shape",
    ),
    ("renderer.md", "with Renderer(1280, 720) as renderer:"): (
        _SCENE,
        'assert frame.colour["2x2"].shape == (720, 1280, 3) and frame.seen.mean() > 0.5',
    ),
    ("runtime.md", "budget = sdk.select_rates_for_saving(predictor.predict(x), 0.6,"): (
        _MODEL,
        "assert budget.saved >= 0.6 and (budget.rates == predictor.shading_rates(x, saving=0.6)).all()\n"
        "assert (sdk.select_rates(predictor.predict(x), budget.threshold, factors=predictor.metadata.rate_factors)"
        " == budget.rates).all()",
    ),
    ("runtime.md", "engine_rates = np.full(rates.shape, sdk.RATE_CODES[\"2x1\"], np.uint8)"): (
        _MODEL + "rates = predictor.shading_rates(x)\n",
        "values = predictor.predict(x)\n"
        "assert (image == sdk.select_rates(values, predictor.metadata.default_threshold, engine_rates=engine_rates,"
        " factors=predictor.metadata.rate_factors)).all()\n"
        "assert (shaded == image).all() and (shaded != sdk.RATE_CODES['1x2']).all()  # (max: the image is the rate shaded)",
    ),
    ("runtime.md", "selector = RateSelector(predictor, ctx)"): (
        _MODEL
        + """
from rtp.plugins.moderngl import create_context
ctx = create_context(430)
th, tw = sdk.tile_grid(H, W, predictor.tile_size)
raw_buffer = ctx.buffer(np.ascontiguousarray(predictor.predict_raw(x), np.float32).tobytes())
""",
        "assert (rates == predictor.shading_rates(x)).all() and texture.size == (tw, th)",
    ),
    ("runtime.md", "reuse = sdk.PredictionReuse(predictor, every=4)"): (
        _MODEL
        + """
rows, cols = np.indices((H, W), dtype=np.int32)     # a static camera: every pixel where it was
seen = np.ones((H, W), np.float32)
sky = np.zeros((H, W), bool)
""",
        "assert rates.shape == (5, 8) and reuse.age == 1  # the second frame carried the first one's estimates",
    ),
    ("runtime.md", 'predictor = sdk.load("jnyang-reuse")'): (
        "from rtp import sdk\n",
        "assert predictor.metadata.tail is not None",
    ),
    ("runtime.md", "needed = sdk.gbuffers_needed(predictor.metadata.inputs)"): (  # the renderer's G-buffers, read back
        _MODEL + _SCENE + """
from rtp.plugins.moderngl import Renderer
with Renderer(W, H) as r:
    r.load_scene(scene)
    prev = r.render(prev_camera)
    cur = r.render(camera, prev)
depth, albedo, normal = cur.depth, cur.albedo, cur.normal
roughness, metallic, specular = cur.roughness, cur.metallic, cur.specular
view, projection = camera.view(), camera.projection(W / H)
prev_colour, prev_depth, prev_view_projection = prev.colour["1x1"], prev.depth, prev_camera.view_projection(W, H)
""",
        "assert rates.shape == sdk.tile_grid(H, W, predictor.tile_size) and needed[:4] == "
        "('depth', 'albedo', 'normal', 'roughness')\n"
        "assert 0.2 < x[predictor.metadata.inputs.index('seen')].mean() < 1.0",
    ),
    ("runtime.md", "S = np.diag([1.0, 1.0, -1.0, 1.0])"): (  # a reversed-Z Direct3D camera, as DirectXMath builds it
        """
import numpy as np
def look_at_lh(eye, at):  # XMMatrixLookAtLH, row vectors
    z = (at - eye) / np.linalg.norm(at - eye); x = np.cross([0.0, 1, 0], z); x /= np.linalg.norm(x); y = np.cross(z, x)
    m = np.eye(4); m[:3, 0], m[:3, 1], m[:3, 2] = x, y, z; m[3, :3] = -x @ eye, -y @ eye, -z @ eye
    return m
near, far, ys = 100.0, 0.1, 1 / np.tan(0.55)  # (reversed-Z: XMMatrixPerspectiveFovLH with near and far swapped)
engine_projection = np.array([[ys / 1.6, 0, 0, 0], [0, ys, 0, 0], [0, 0, far / (far - near), 1],
                              [0, 0, -far * near / (far - near), 0]])
engine_view = look_at_lh(np.array([1.0, 1.7, -3.0]), np.array([0.5, 1.2, 2.0]))
engine_prev_view_projection = look_at_lh(np.array([1.2, 1.7, -3.1]), np.array([0.5, 1.2, 2.0])) @ engine_projection
""",
        """
p = np.array([0.3, 1.1, 6.0, 1.0])
d3d, gl = p @ engine_view @ engine_projection, projection @ view @ p
assert np.allclose(gl[:2] / gl[3], d3d[:2] / d3d[3]) and np.isclose(1 - (gl[2] / gl[3] + 1) / 2, d3d[2] / d3d[3])
d3d, gl = p @ engine_prev_view_projection, prev_view_projection @ p
assert np.allclose(gl[:2] / gl[3], d3d[:2] / d3d[3]) and np.isclose(1 - (gl[2] / gl[3] + 1) / 2, d3d[2] / d3d[3])
""",
    ),
    ("runtime.md", 'predictor = sdk.load("jnyang", threads=1)'): (  # pickled to the pool's processes
        "import numpy as np\nfrom rtp import sdk\nrng = np.random.default_rng(0)\n"
        "frames = [rng.random((9, 64, 96), dtype=np.float32) for _ in range(3)]\n",
        "assert len(rates) == 3 and all(np.array_equal(r, predictor.shading_rates(f)) for r, f in zip(rates, frames))",
    ),
    ("runtime.md", 'Adapter = sdk.adapters.get("moderngl")'): (
        _SOURCE
        + """
ctx = source.adapter_options()["ctx"]
tex_albedo, tex_normal, tex_depth = frame.albedo, frame.normal, frame.depth
V, P, prev_VP = frame.view, frame.projection, frame.prev_view_projection
tex_prev, tex_prev_depth, tex_orm = frame.prev_colour, frame.prev_depth, frame.material
""",
        "assert rates.shape == (5, 8) and x.shape == (len(predictor.metadata.inputs), height, width)",
    ),
}

#: (page, key) -> why CI does not run the block (its imports run, and it must compile).
NOT_RUN: dict[tuple[str, str], str] = {
    ("evaluation.md", 'scene, blockers = load_scene("oa_dm5", None, None, None)'):
        "a game level: needs `rtp scenes fetch` (tests/test_paths.py runs camera_path on the procedural scene)",
    ("evaluation.md", 'report = play("20kdm2", "jnyang,jnyang@4,yang2019,fidelityfx,oracle", out="play")'):
        "a game level and ten minutes (tests/test_play.py runs play on the procedural scene)",
    ("scenes.md", "scene = procedural(seed=0)"):
        "a game level: needs `rtp scenes fetch` (tests/test_viewpoints.py samples the procedural scene)",
}


def _blocks() -> list[tuple[str, int, str]]:
    """``(page, line, code)`` of every Python block of docs/*.md."""
    out = []
    for page in sorted(DOCS.glob("*.md")):
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"^```python\n(.*?)^```", text, re.S | re.M):
            out.append((page.name, text.count("\n", 0, m.start()) + 1, m.group(1)))
    return out


def _key(code: str) -> str:
    for line in code.splitlines():
        s = line.split("  #")[0].split(" # ")[0].strip()
        if s and not s.startswith(("from ", "import ")):
            return s
    return ""


def _imports(code: str) -> str:
    return "\n".join(line for line in code.splitlines() if line.startswith(("from ", "import ")))


BLOCKS = _blocks()


def test_every_block_is_run_or_declared() -> None:
    assert len(BLOCKS) >= 15
    keys = [(page, _key(code)) for page, _, code in BLOCKS]
    unknown = [f"{page}:{line} {key!r}" for (page, key), (_, line, _) in zip(keys, BLOCKS)
               if (page, key) not in SETUP and (page, key) not in NOT_RUN]
    assert not unknown, f"Python blocks neither run nor declared (add them to SETUP or NOT_RUN): {unknown}"
    assert len(set(keys)) == len(keys), "two blocks of a page share a key"
    stale = (set(SETUP) | set(NOT_RUN)) - set(keys)
    assert not stale, f"entries for blocks the docs no longer have: {sorted(stale)}"


def _run(code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "egl")}
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)


@pytest.mark.parametrize(("page", "line", "code"), BLOCKS, ids=[f"{p}:{n}" for p, n, _ in BLOCKS])
def test_the_block_runs(page: str, line: int, code: str, tmp_path: Path) -> None:
    key = (page, _key(code))
    compile(code, f"{page}:{line}", "exec")
    if key in NOT_RUN:
        r = _run(_imports(code), tmp_path)
        assert r.returncode == 0, f"docs/{page} line {line}: its imports fail:\n{r.stderr[-3000:]}"
        return
    setup, check = SETUP[key]
    program = "\n".join([textwrap.dedent(setup), code, textwrap.dedent(check), "print('ran')"])
    r = _run(program, tmp_path)
    assert r.returncode == 0 and r.stdout.strip().endswith("ran"), (
        f"docs/{page} line {line} failed ({r.returncode}):\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}")


def _commands() -> list[tuple[str, str]]:
    """``(page, command)`` of every ``rtp`` and ``rtp-export`` command in the shell blocks of the
    docs and the README, one per ``&&``/``;``-separated part, line continuations joined."""
    out = []
    for page in [*sorted(DOCS.glob("*.md")), ROOT / "README.md"]:
        text = page.read_text(encoding="utf-8")
        for m in re.finditer(r"^```(?:bash|sh)\n(.*?)^```", text, re.S | re.M):
            for line in m.group(1).replace("\\\n", " ").splitlines():
                for part in re.split(r"\s*(?:&&|;|\|\|)\s*", line.split(" #")[0].strip()):
                    if part.startswith(("rtp ", "rtp-export ")):
                        out.append((page.name, part))
    return out


def _stands_in(arg: str) -> bool:
    """An argument the reader fills in: a shell variable, an optional part in brackets, a capitalised name (``M``, ``MAP``)."""
    return "$" in arg or "[" in arg or "{" in arg or "<" in arg or (arg.isupper() and arg.isalpha())


def test_the_commands_in_the_docs_name_flags_and_choices_that_exist() -> None:
    """Every documented ``rtp`` command parses as far as its flags and choices go: a renamed or
    removed flag (``--scenes``, ``--val-split``) or a choice that no longer exists fails here. Whether
    its files exist is the reader's (``data/test`` is made by a command the page gives)."""

    from rtp.cli._export import build_export_parser
    from rtp.cli._main import build_parser

    commands = _commands()
    assert len(commands) > 200
    # docs/metrics.md's commands name the example plugin's metric, installed as its page says
    from rtp.metrics import _plugins

    from .test_metric_plugins import example_module

    registered, explicit = dict(_plugins._registered), set(_plugins._explicit)
    _plugins.register_metric(example_module().SSIM)
    try:
        broken, parsed = _parse_all(commands, build_parser, build_export_parser)
    finally:
        _plugins._registered.clear()
        _plugins._registered.update(registered)
        _plugins._explicit.clear()
        _plugins._explicit.update(explicit)
    assert parsed > 200, parsed
    assert not broken, "documented commands the parser refuses:\n" + "\n".join(broken)


def _parse_all(commands: list[tuple[str, str]], build_parser: Any, build_export_parser: Any) -> tuple[list[str], int]:
    import contextlib
    import io
    import shlex

    broken, parsed = [], 0
    for page, command in commands:
        argv = shlex.split(command)
        if any(_stands_in(a) for a in argv[1:]):
            continue
        parser = build_parser() if argv[0] == "rtp" else build_export_parser()
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                parser.parse_args(argv[1:])
        except SystemExit as exit_:
            words = err.getvalue().strip().splitlines()[-1:] or [""]
            if exit_.code and any(k in words[0] for k in ("unrecognized arguments", "invalid choice", "unknown metric",
                                                          "expected one argument", "not allowed with")):
                broken.append(f"docs/{page}: {command}\n    {words[0]}")
                continue
        parsed += 1
    return broken, parsed


def _bench_commands() -> list[tuple[str, bool, list[str]]]:
    """``(page, whole, argv)`` of every ``python bench/NAME.py ...`` command of the docs and the README,
    ``argv[0]`` the script's name: ``whole`` for a shell block's command, not for inline code, where
    prose may name a script or a flag without the files it reads (`python bench/report.py --compact`)."""
    import shlex

    out = []
    for page in [*sorted(DOCS.rglob("*.md")), ROOT / "README.md"]:
        text = page.read_text(encoding="utf-8")
        spans = [(True, m.group(1).replace("\\\n", " "))
                 for m in re.finditer(r"^```(?:bash|sh)\n(.*?)^```", text, re.S | re.M)]
        spans += [(False, t) for t in re.findall(r"(?<!`)`([^`\n]*python bench/[^`\n]*)`(?!`)", text)]
        for whole, span in spans:
            for line in span.splitlines():
                for part in re.split(r"\s*(?:&&|;|\|\||\|)\s*", line.split(" #")[0].strip()):
                    m = re.search(r"python3? bench/(\w+)\.py(.*)", part)
                    if m:
                        try:
                            args = shlex.split(m.group(2))
                        except ValueError:  # an unbalanced quote: a command cut off in prose
                            continue
                        out.append((str(page.relative_to(ROOT)), whole, [m.group(1), *args]))
    return out


class _Parsed(Exception):
    """Raised in place of parsing: carries the parser a bench script built."""


def _bench_parser(script: str) -> object:
    """The argparse parser ``bench/<script>.py`` builds, caught as its ``main`` asks it to parse, with
    the argument types that open files (datasets, reports, JSON) taking the text as it is: those files
    are made by commands the pages give, not by CI."""
    import argparse
    import importlib
    from unittest import mock

    sys.path.insert(0, str(ROOT / "bench"))
    try:
        common = importlib.import_module("_common")
        module = importlib.import_module(script)
    finally:
        sys.path.remove(str(ROOT / "bench"))

    def catch(self: argparse.ArgumentParser, *args: object, **kwargs: object) -> None:
        raise _Parsed(self)

    with mock.patch.object(argparse.ArgumentParser, "parse_args", catch), pytest.raises(_Parsed) as caught:
        # report.py builds its parser in a ``parse_args`` of its own (other scripts import it); the rest in ``main``
        (module.parse_args if callable(getattr(module, "parse_args", None)) else module.main)()
    parser = caught.value.args[0]
    opens_files = {common.dataset_folder, common.json_file, common.PLAY_JSON, common.EVALUATION_JSON}
    for action in parser._actions:
        if action.type in opens_files or getattr(action.type, "__qualname__", "").startswith("report_file."):
            action.type = None
    return parser


def test_the_bench_commands_in_the_docs_name_flags_and_choices_that_exist() -> None:
    """Every documented ``python bench/...`` command parses as far as its flags, choices and values go
    (sizes, counts): a renamed flag or a script that is gone fails here; the files it reads are the
    reader's to make."""
    import contextlib
    import io

    commands = _bench_commands()
    assert len(commands) > 200, len(commands)
    scripts = {name for _, _, (name, *_) in commands}
    missing = sorted(s for s in scripts if not (ROOT / "bench" / f"{s}.py").is_file())
    assert not missing, f"the docs run bench scripts that do not exist: {missing}"
    parsers = {s: _bench_parser(s) for s in sorted(scripts)}
    broken, parsed = [], 0
    for page, whole, (script, *argv) in commands:
        if any(_stands_in(a) for a in argv):
            continue
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                parsers[script].parse_args(argv)  # type: ignore[attr-defined]
        except SystemExit as exit_:
            words = (err.getvalue().strip().splitlines() or [""])[-1]
            if exit_.code and (whole or "arguments are required" not in words):
                broken.append(f"{page}: python bench/{script}.py {' '.join(argv)}\n    {words}")
                continue
        parsed += 1
    assert parsed > 150, parsed
    assert not broken, "documented bench commands their parser refuses:\n" + "\n".join(broken)
