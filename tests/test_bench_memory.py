"""bench/memory.py: a row per shipped model, each measured in a process of its own, in both tables (memory, then
the time of the load and the first runs)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from rtp import sdk

BENCH = Path(__file__).resolve().parents[1] / "bench" / "memory.py"


def test_a_row_per_model_with_the_input_planes_beside_each_size() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "--sizes", "512x512,1024x512"], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    memory, times = out.stdout.split("Time (ms)")
    rows, timed = ({line.split("|")[1].strip(): [c.strip() for c in line.strip("|").split("|")[1:]]
                    for line in text.splitlines() if line.startswith("| ") and not line.startswith("| model")}
                   for text in (memory, times))
    assert sorted(rows) == sorted(timed) == sorted(n.removesuffix(".onnx") for n in sdk.shipped_models())
    for name, (load, *sizes) in timed.items():  # the load, then three timed runs at each size
        assert float(load) > 0 and len(sizes) == 2, name
        assert all(len(c.split(" / ")) == 3 and min(float(v) for v in c.split(" / ")) > 0 for c in sizes), name
    for name, (library, session, *sizes) in rows.items():
        assert float(library) >= 0 and float(session) > 0, name  # building a session takes memory
        planes = len(sdk.load(name).metadata.inputs)
        inputs = [float(c.split("(")[1].rstrip(")")) for c in sizes]
        assert inputs == [round(planes * 512 * 512 * 4 / 2**20), round(planes * 1024 * 512 * 4 / 2**20)]
    bad = subprocess.run([sys.executable, str(BENCH), "--sizes", "64by64"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "WIDTHxHEIGHT" in bad.stderr


def test_a_warm_up_runs_before_the_timed_runs() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "--sizes", "256x256", "--warm-up", "1", "jnyang"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "first 3 timed `predict` calls at each size in turn, after 1 on a zero frame" in out.stdout
    bad = subprocess.run([sys.executable, str(BENCH), "--warm-up", "-1"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "argument --warm-up: expected an integer >= 0" in bad.stderr


def test_a_size_given_twice_is_measured_once(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`--sizes 64x64,64x64` measured the size twice in each model's process (the second, warm runs reported as the
    first runs, the memory they added ~0) and printed its column twice; a size is measured once, in the order given."""
    from .conftest import bench_module

    mod = bench_module("memory", monkeypatch)
    seen: list[list[tuple[int, int]]] = []

    def measure(model: str, sizes: list[tuple[int, int]], threads: int, warm_up: int = 0) -> dict[str, float]:
        seen.append(list(sizes))
        out = {"library": 1.0, "load": 2.0, "load ms": 3.0}
        for w, h in sizes:
            out.update({f"{w}x{h}": 4.0, f"{w}x{h} input": 5.0, **{f"{w}x{h} run {i + 1} ms": 6.0 for i in range(3)}})
        return out

    monkeypatch.setattr(mod, "measure", measure)
    monkeypatch.setattr(sys, "argv", ["memory.py", "--one", "jnyang", "--sizes", "64x64,32x32,64x64"])
    mod.main()
    assert seen == [[(64, 64), (32, 32)]]
    children: list[list[str]] = []

    def child(argv: list[str], **_: object) -> subprocess.CompletedProcess[str]:
        children.append(argv)
        sizes = [tuple(int(v) for v in s.split("x")) for s in argv[argv.index("--sizes") + 1].split(",")]
        return subprocess.CompletedProcess(argv, 0, json.dumps(measure(argv[3], sizes, 2)), "")  # type: ignore[arg-type]

    monkeypatch.setattr(mod.subprocess, "run", child)
    monkeypatch.setattr(sys, "argv", ["memory.py", "--sizes", "64x64,32x32,64x64"])
    capsys.readouterr()
    mod.main()
    assert children and all(a[a.index("--sizes") + 1] == "64x64,32x32" for a in children)
    header = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("| model | onnxruntime"))
    assert header.count("first runs at 64x64") == 1 and header.count("first runs at 32x32") == 1


def test_job_memory_reads_a_command_that_writes_more_stderr_than_a_pipe_holds() -> None:
    """bench/job_memory.py waits for each command with ``os.wait4`` (its peak resident set) and read its stderr from a
    pipe only after: a command that wrote more than the pipe holds (64 KiB on Linux) blocked on its write, and the
    benchmark with it, for ever. Its stderr goes to a file: the peak is read, and a failing command's last line is
    still said."""
    script = ("import sys\n"
              "from tests.conftest import bench_module\n"
              "peak = bench_module('job_memory').peak\n"
              "print(peak([sys.executable, '-c', \"import sys; sys.stderr.write('w' * 300_000 + '\\\\n')\"]))\n"
              "try:\n"
              "    peak([sys.executable, '-c', \"import sys; sys.stderr.write('w\\\\n' * 100_000 + 'the last line\\\\n'); "
              "raise SystemExit(3)\"])\n"
              "except Exception as err:\n"
              "    print(type(err).__name__, str(err)[-40:])\n")
    root = BENCH.parents[1]
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, cwd=root)
    assert out.returncode == 0, out.stderr
    first, second = out.stdout.splitlines()
    assert int(first) > 1_000_000  # (bytes: a Python process's peak)
    assert second.startswith("RtpError") and second.endswith("exit 3: the last line"), second
