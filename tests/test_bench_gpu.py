"""bench/inference_gpu.py: its torch rebuild of an exported model is the model, and it refuses to run
without a GPU in words (the timings themselves need CUDA and live in docs/performance.md)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from rtp import sdk

from .conftest import BENCH, bench_module

# torch and onnxruntime run the same float32 graph with kernels of their own, which sum in an order
# that depends on the CPU's vector width (AVX2 and AVX-512 machines differ): a few float32 ulps per
# layer, relative to the value. A wrong rebuild (a layer dropped, another padding, BatchNorm in the
# wrong place) is off by 1e-3 or more.
FLOAT32_KERNELS = {"rtol": 3e-5, "atol": 3e-6}


def _bench_module():  # type: ignore[no-untyped-def]
    return bench_module("inference_gpu"), bench_module("_common").paper_model


def _onnxruntime(path: Path, x: np.ndarray) -> np.ndarray:
    """The first output of ``path`` on ``x``, its planes fed to the graph's inputs as rtp.sdk feeds them."""
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    ins = session.get_inputs()
    ends = np.cumsum([0] + [i.shape[1] for i in ins]).tolist() if len(ins) > 1 else [0, x.shape[1]]
    return session.run(None, {i.name: x[:, a:b] for i, a, b in zip(ins, ends[:-1], ends[1:])})[0]


@pytest.mark.parametrize("name", sdk.shipped_models())
def test_the_torch_rebuild_of_a_shipped_model_matches_onnxruntime(name: str) -> None:
    mod, _ = _bench_module()
    path = Path(str(sdk.load(name).path))
    net = mod.torch_from_onnx(path)
    # 68 x 100: not whole 16-pixel tiles, so the ceil-mode pooling of the last partial tile counts
    x = np.random.default_rng(1).random((1, len(sdk.load(name).metadata.inputs), 68, 100), dtype=np.float32)
    with torch.inference_mode():
        got = net(torch.from_numpy(x)).numpy()
    want = _onnxruntime(path, x)
    t = sdk.load(name).metadata.tile_size  # 16; jnyang-8px's 8
    assert got.shape == want.shape == (1, 4, -(-68 // t), -(-100 // t))
    np.testing.assert_allclose(got, want, **FLOAT32_KERNELS)


def test_the_torch_rebuild_keeps_the_papers_batchnorm_after_relu(tmp_path: Path) -> None:
    mod, paper_model = _bench_module()
    _, path = paper_model(tmp_path)  # random BatchNorm statistics: not the identity
    net = mod.torch_from_onnx(path)
    assert any(isinstance(m, torch.nn.BatchNorm2d) for m in net.modules())
    x = np.random.default_rng(2).random((1, 4, 64, 96), dtype=np.float32)
    with torch.inference_mode():
        got = net(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(got, _onnxruntime(path, x), **FLOAT32_KERNELS)


def test_the_torch_rebuild_names_an_op_it_does_not_know(tmp_path: Path) -> None:
    mod, _ = _bench_module()
    h = onnx.helper
    graph = h.make_graph([h.make_node("Add", ["input", "input"], ["out"])], "g",
                         [h.make_tensor_value_info("input", onnx.TensorProto.FLOAT, [1, 4, 16, 16])],
                         [h.make_tensor_value_info("out", onnx.TensorProto.FLOAT, [1, 4, 16, 16])])
    path = tmp_path / "add.onnx"
    onnx.save(h.make_model(graph), str(path))
    with pytest.raises(ValueError, match="op Add"):
        mod.torch_from_onnx(path)


def test_without_a_gpu_the_benchmark_says_so_and_exits_2() -> None:
    env = {**os.environ, "CUDA_VISIBLE_DEVICES": ""}
    out = subprocess.run([sys.executable, str(BENCH / "inference_gpu.py"), "--frames", "64x64"], capture_output=True,
                         text=True, env=env, timeout=120)
    assert out.returncode == 2, out.stderr
    assert "needs a CUDA GPU" in out.stderr
    bad = subprocess.run([sys.executable, str(BENCH / "inference_gpu.py"), "--frames", "1920by1080"],
                         capture_output=True, text=True, env=env, timeout=120)
    assert bad.returncode != 0 and "expected WIDTHxHEIGHT" in bad.stderr


def test_the_models_given_are_read_from_their_files_each_once_and_apart(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """`bench/inference_gpu.py jnyang` (a shipped model's name) rebuilt the network from a file `jnyang` in the working
    folder (FileNotFoundError, after the paper's network and every shipped model were exported and loaded), and two
    given files of one name (`data/old/jnyang.onnx data/joined/jnyang.onnx`) were one row, the last. Each is found
    as sdk.load finds it, named as bench/inference.py names them; one that is not there is refused first."""
    import shutil

    mod, _ = _bench_module()
    shipped = Path(str(sdk.load("jnyang").path))
    monkeypatch.chdir(tmp_path)
    given = []
    for folder in ("old", "joined"):
        (tmp_path / folder).mkdir()
        given.append(str(shutil.copy(shipped, tmp_path / folder / "jnyang.onnx")))
    assert mod.given_models(["jnyang", *given, "jnyang"]) == {
        "jnyang": shipped, given[0]: Path(given[0]), given[1]: Path(given[1])}
    env = {**os.environ, "CUDA_VISIBLE_DEVICES": ""}
    out = subprocess.run([sys.executable, str(BENCH / "inference_gpu.py"), "nosuchmodel"], capture_output=True,
                         text=True, env=env, timeout=120)
    assert out.returncode == 2 and out.stderr.startswith("inference_gpu.py: error: no model file at 'nosuchmodel'"), \
        out.stderr


def test_the_fp32_columns_and_the_fp16_reference_run_in_full_float32(monkeypatch: pytest.MonkeyPatch) -> None:
    """torch's default runs a float32 convolution on cuDNN's TF32 kernels (10 bits of mantissa, as fp16's) on the
    Ampere and later GPUs this bench runs on: its "fp32" columns timed TF32, and "fp16 - fp32, largest" (docs'
    "half precision is safe") was read against a TF32 output. The fp32 runs, the graph captured from them and the
    reference now run with TF32 off; the fp16 ones as torch has it, and torch's settings are restored after."""
    mod, _ = _bench_module()
    seen: list[tuple[str, bool, bool]] = []

    def timed(fn, repeats):  # type: ignore[no-untyped-def]
        out = fn()
        dtype = "fp16" if out.dtype == torch.float16 else "fp32"
        seen.append((dtype, torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32))
        return 1.0

    def graphed(net, x):  # type: ignore[no-untyped-def]  (the capture is where cuDNN picks the kernels)
        seen.append(("capture " + ("fp16" if x.dtype == torch.float16 else "fp32"), torch.backends.cudnn.allow_tf32,
                     torch.backends.cuda.matmul.allow_tf32))
        return lambda: net(x)

    monkeypatch.setattr(mod, "_cuda_ms", timed)
    monkeypatch.setattr(mod, "_graphed", graphed)
    torch.manual_seed(0)
    n32 = torch.nn.Sequential(torch.nn.Conv2d(4, 8, 3, padding=1), torch.nn.ReLU()).eval()
    n16 = torch.nn.Sequential(torch.nn.Conv2d(4, 8, 3, padding=1), torch.nn.ReLU()).eval()
    n16.load_state_dict(n32.state_dict())
    n16 = n16.half().to(memory_format=torch.channels_last)
    x32 = torch.rand((1, 4, 16, 16))
    before = torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32
    torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = True  # (torch's default on cuDNN)
    try:
        *times, diff = mod.time_network(n32, n16, x32, 3)
        assert torch.backends.cudnn.allow_tf32 and torch.backends.cuda.matmul.allow_tf32
    finally:
        torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = before
    assert times == [1.0] * 4 and 0 <= diff < 1e-2
    assert seen == [("fp32", False, False), ("capture fp32", False, False), ("fp32", False, False),
                    ("fp16", True, True), ("capture fp16", True, True), ("fp16", True, True)]
