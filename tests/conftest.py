"""Shared fixtures. SDK tests build their models with onnx.helper, so they need no torch.

GL: every test marked ``gl`` gets the session's one headless EGL context (:func:`gl_context`) made
current, and skips, naming the packages to install, where no EGL context can be created. Tests and
fixtures that use it take the ``gl_context`` fixture; code that may run after another GL context
(a pyrender renderer, a ``Renderer`` with its own context) became current calls
:func:`make_current` first: moderngl never switches contexts by itself.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"
#: The benchmark scripts (run as ``python bench/<name>.py``).
BENCH = Path(__file__).resolve().parents[1] / "bench"

#: The thread pools a worker of ``pytest -n N`` (``make test``) limits to one thread each, before torch
#: or a BLAS is imported: N workers on N cores then compute on N threads, not N² that take turns (on
#: the 2-core CI machine two workers of two torch threads each took 9 minutes, of one each 6.6).
#: Subprocesses the tests start inherit it. A variable already set is kept.
_ONE_THREAD = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _var in _ONE_THREAD:
        os.environ.setdefault(_var, "1")

PAPER_INPUTS = ["reprojected.r", "seen", "albedo.r", "normal.z"]


def bench_module(name: str, monkeypatch: pytest.MonkeyPatch | None = None) -> Any:
    """``bench/<name>.py`` imported as a module, as when it runs as a script: ``bench/`` first on
    ``sys.path`` (its ``_common`` and sibling imports) while it imports, or for the whole test with
    ``monkeypatch``, for a script whose functions import its siblings when they run."""
    import importlib.util
    import sys

    if monkeypatch is not None:
        monkeypatch.syspath_prepend(str(BENCH))
    else:
        sys.path.insert(0, str(BENCH))
    try:
        spec = importlib.util.spec_from_file_location(f"bench_{name}", BENCH / f"{name}.py")
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = mod  # (a dataclass resolves its string annotations in its module)
        spec.loader.exec_module(mod)
    finally:
        if monkeypatch is None:
            sys.path.remove(str(BENCH))
    return mod


def pyrender_or_skip() -> Any:
    """``import_pyrender()``, or a skip naming what is missing (pyrender itself, or a headless GL platform)."""
    from rtp.plugins.pyrender import PyrenderUnavailableError, import_pyrender

    try:
        return import_pyrender()
    except ImportError as exc:
        pytest.skip(f"pyrender not installed (pip install 'rtp[pyrender]'): {exc}")
    except PyrenderUnavailableError as exc:
        pytest.skip(f"no headless GL platform for pyrender: {exc}")



def damage_zip_member(archive: Path, member: str) -> None:
    """Damage member ``member`` of the zip (pk3) ``archive`` in place: its first data byte inverted, so
    reading it fails its CRC check (stored) or its deflate stream (compressed)."""
    import struct
    import zipfile

    with zipfile.ZipFile(archive) as z:
        info = z.getinfo(member)
    data = bytearray(archive.read_bytes())
    name_len, extra_len = struct.unpack_from("<HH", data, info.header_offset + 26)
    data[info.header_offset + 30 + name_len + extra_len] ^= 0xFF
    archive.write_bytes(bytes(data))

def base_metadata(**overrides: Any) -> dict[str, Any]:
    d: dict[str, Any] = {
        "metric": "jnyang",
        "transform": {"type": "clamped", "mu_y": 0.25},
        "tile_size": 16,
        "inputs": list(PAPER_INPUTS),
        "outputs": ["1x2", "2x1", "2x4", "4x2"],
        "default_threshold": 0.2,
        "weber_l": 0.02,
    }
    d.update(overrides)
    return d


def build_onnx(
    path: Path,
    *,
    weights: np.ndarray,
    bias: np.ndarray | None = None,
    tile: int = 16,
    metadata: dict[str, Any] | None = None,
    static: Sequence[int] | None = None,
    input_name: str = "input",
    output_name: str = "metric",
    ceil_mode: bool = False,
) -> Path:
    """A tiny real model: 1x1 conv (weights ``(R, C)``) -> MaxPool(tile) -> Sigmoid.

    Its output is known in closed form, so tests can check every step of ``predict``. With
    ``ceil_mode`` the pooling takes a partial last tile (a model for ``input_multiple``).
    """
    import onnx
    from onnx import TensorProto, helper

    r, c = weights.shape
    b = np.zeros(r, np.float32) if bias is None else bias.astype(np.float32)
    if static is None:
        in_shape: list[Any] = ["batch", c, "height", "width"]
        out_shape: list[Any] = ["batch", r, "tiles_y", "tiles_x"]
    else:
        n, h, w = static
        grid = (-(-h // tile), -(-w // tile)) if ceil_mode else (h // tile, w // tile)  # (what the pooling gives)
        in_shape, out_shape = [n, c, h, w], [n, r, *grid]
    nodes = [
        helper.make_node("Conv", [input_name, "W", "B"], ["conv"], kernel_shape=[1, 1]),
        helper.make_node("MaxPool", ["conv"], ["pool"], kernel_shape=[tile, tile], strides=[tile, tile],
                         ceil_mode=int(ceil_mode)),
        helper.make_node("Sigmoid", ["pool"], [output_name]),
    ]
    graph = helper.make_graph(
        nodes,
        "tiny",
        [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, in_shape)],
        [helper.make_tensor_value_info(output_name, TensorProto.FLOAT, out_shape)],
        initializer=[
            helper.make_tensor("W", TensorProto.FLOAT, [r, c, 1, 1], weights.astype(np.float32).ravel().tolist()),
            helper.make_tensor("B", TensorProto.FLOAT, [r], b.ravel().tolist()),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    if metadata is not None:
        helper.set_model_props(model, {"rtp.metadata": json.dumps(metadata)})
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


@pytest.fixture
def tiny_model(tmp_path: Path) -> Callable[..., Path]:
    """Factory: ``tiny_model(metadata=..., weights=...)`` writes a model and returns its path."""
    counter = iter(range(10_000))

    def make(metadata: dict[str, Any] | None = None, weights: np.ndarray | None = None, **kw: Any) -> Path:
        meta = base_metadata() if metadata is None else metadata
        if weights is None:
            n_out = len(meta.get("outputs", ["1x2", "2x1", "2x4", "4x2"]))
            n_in = len(meta.get("inputs", PAPER_INPUTS))
            weights = np.zeros((n_out, n_in), np.float32)
            for i in range(n_out):
                weights[i, i % n_in] = 1.0
        return build_onnx(tmp_path / f"tiny{next(counter)}.onnx", weights=weights, metadata=meta, **kw)

    return make


@pytest.fixture
def machine_memory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Callable[..., None]:
    """The memory rtp's jobs see (``rtp.capture``'s ``MEMINFO``, a file of this test): call it with
    ``/proc/meminfo`` fields in bytes, ``machine_memory(MemTotal=4 * 2**30, MemAvailable=2**30)``;
    until then the file is empty and no job checks its memory."""
    from rtp.capture import _memory

    path = tmp_path / "meminfo"
    path.write_text("")
    monkeypatch.setattr(_memory, "MEMINFO", str(path))
    monkeypatch.delenv(_memory.CHECK_ENV, raising=False)  # the default (refuse), whatever the shell says

    def set_fields(**fields: int) -> None:
        path.write_text("".join(f"{k}:  {v // 1024} kB\n" for k, v in fields.items()))

    return set_fields


@pytest.fixture(scope="session")
def vectors() -> dict[str, Any]:
    return json.loads((DATA / "transform_vectors.json").read_text())


# ----------------------------------------------------------------------------------------------------- GL
#: What to install on Debian/Ubuntu for the headless GL tests (Mesa's EGL and GL drivers).
EGL_PACKAGES = "apt-get install libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri"


def open_gl_context() -> Any:
    """A headless moderngl context through EGL, or ``pytest.skip`` saying what to install."""
    try:
        from rtp.plugins.moderngl import create_context
    except ImportError as exc:
        pytest.skip(f"moderngl is not installed (pip install 'rtp[moderngl]'): {exc}")
    try:
        return create_context()
    except ImportError as exc:
        pytest.skip(f"moderngl is not installed (pip install 'rtp[moderngl]'): {exc}")
    except Exception as exc:  # RendererError: no EGL, no GL 3.3
        cause = exc.__cause__ or exc
        pytest.skip(f"no headless OpenGL context through EGL ({type(cause).__name__}: {cause}); "
                    f"install Mesa's EGL and GL drivers: {EGL_PACKAGES}")


def make_current(ctx: Any) -> Any:
    """Make ``ctx`` the current GL context (moderngl never does it by itself) and return it."""
    ctx.__enter__()  # moderngl's only call for it; never exited, so nothing is restored later
    return ctx


def in_thread(call: Callable[[], Any]) -> Any:
    """``call()`` in a worker thread named "worker": its value, or its exception raised in the caller's thread (a GL
    context current in the test's thread is not current there)."""
    import threading

    out: dict[str, Any] = {}

    def work() -> None:
        try:
            out["value"] = call()
        except BaseException as exc:  # (handed back to the test's thread)
            out["error"] = exc

    worker = threading.Thread(target=work, name="worker")
    worker.start()
    worker.join(300)  # (a call that never returns fails the test, not the run)
    if "error" in out:
        raise out["error"]
    return out["value"]


@pytest.fixture(scope="session")
def gl_context() -> Iterator[Any]:
    """The session's headless EGL moderngl context, created once; skips where EGL is missing."""
    ctx = open_gl_context()
    yield ctx
    make_current(ctx)
    ctx.release()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Tests marked ``gl`` request ``gl_context`` first: being session-scoped, it is set up before
    any module fixture of theirs, so that without EGL they skip before one tries to render."""
    for item in items:
        names = getattr(item, "fixturenames", None)
        if item.get_closest_marker("gl") is not None and names is not None and "gl_context" not in names:
            names.insert(0, "gl_context")


@pytest.fixture(autouse=True)
def _gl_marked_tests_get_the_context(request: pytest.FixtureRequest) -> None:
    """Tests marked ``gl`` skip cleanly without EGL, and start with the shared context current."""
    if request.node.get_closest_marker("gl") is not None:
        make_current(request.getfixturevalue("gl_context"))


# ------------------------------------------------------------------------------------------- no skips in CI
#: Set (to anything but empty) by .ci/run: a skipped test fails the run. CI installs every package and system
#: library a test can skip for (make install, libOSMesa, Mesa's EGL), so a skip there is an install step lost,
#: which a green run with "N skipped" hid. Unset, a test skips as before, naming what to install.
NO_SKIPS_ENV = "RTP_TESTS_NO_SKIPS"
_skipped: list[str] = []


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    # (under pytest-xdist the controller hears every worker's reports; a worker leaves the count to it)
    if os.environ.get(NO_SKIPS_ENV) and not os.environ.get("PYTEST_XDIST_WORKER") and report.skipped \
            and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        _skipped.append(f"{report.nodeid}: {reason}")


def pytest_terminal_summary(terminalreporter: Any) -> None:
    if _skipped:
        terminalreporter.section(f"{len(_skipped)} skipped with ${NO_SKIPS_ENV} set: each is a missing install step",
                                 sep="=", red=True)
        for line in _skipped:
            terminalreporter.line(line)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if _skipped and exitstatus == pytest.ExitCode.OK:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def trained_like_fast_net(planes: int, seed: int) -> Any:
    """rtp's fast network on ``planes`` input planes, random weights, its BatchNorm statistics those of
    one training-mode pass (not the identity), in eval mode."""
    import torch

    from rtp.train.model import FastNet

    torch.manual_seed(seed)
    net = FastNet(in_channels=planes)
    with torch.no_grad():
        net.train()(torch.rand(4, planes, 64, 64))
    return net.eval()


def split_model(folder: Path, planes: str = "blocks") -> Path:
    """A JNYang network that splits (``contrast_stored``: the block contrast from the ``.blocks`` planes, or
    with ``planes="tiles"`` from the ``.tiles`` planes, joins at tile resolution) on the shipped JNYang's
    nine planes, random weights and BatchNorm statistics, exported with its tail into ``folder``: the ONNX
    path."""
    import torch

    from rtp.export import export_checkpoint
    from rtp.train import checkpoint
    from rtp.train.model import FastNet

    torch.manual_seed(0)
    net = FastNet(9, head_width=16, block_contrast=(7, 8), contrast_cell=16, contrast_max=True, contrast_stored=True,
                  contrast_tiles=planes == "tiles")
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.2, 0.2)
            m.running_var.uniform_(0.5, 2.0)
    inputs = ["reprojected.y", "seen", "albedo.y", "normal.z", "roughness", "metallic", "specular",
              f"reprojected.y.{planes}", f"albedo.y.{planes}"]
    ck = checkpoint.save(folder / f"split-{planes}.pt", net.eval(), base_metadata(inputs=inputs))
    return export_checkpoint(ck, folder / f"split-{planes}.onnx")
