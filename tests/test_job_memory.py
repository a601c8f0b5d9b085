"""Frame jobs sized against the machine's memory before they start (rtp.capture's job_bytes and
check_memory): a size past memory and swap was the system's OOM killer minutes in (`rtp demo --size
8192x8192` holds about 45 GB), now a usage error naming the size that draws and writes nothing."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from rtp import sdk
from rtp.capture import TargetError, capture, check_memory, compute_targets, job_bytes
from rtp.capture._memory import BASE, METRIC_BASE, METRIC_PER_PIXEL, PER_PIXEL, meminfo
from rtp.cli import main as rtp_main
from rtp.evaluate import DEFAULT_METHODS, PlayError, parse_methods, play
from rtp.evaluate._play import _loop_count, _loops

GiB = 2**30
#: How every refusal past memory ends: the variable that lets a job run anyway (a regex; then as said).
HINT = r" \(RTP_MEMORY_CHECK=warn runs it anyway\)$"
SAID_HINT = " (RTP_MEMORY_CHECK=warn runs it anyway)"


def test_job_bytes_add_the_metrics_loops_models_and_processes() -> None:
    assert job_bytes("demo", (100, 10)) == int(BASE["demo"] + PER_PIXEL["demo"] * 1000)
    assert job_bytes("capture", (100, 10), processes=3) == 3 * job_bytes("capture", (100, 10))
    flip = job_bytes("targets", (100, 10), metrics=("flip",))
    assert flip == int(BASE["targets"] + (PER_PIXEL["targets"] + METRIC_PER_PIXEL["targets"]["flip"]) * 1000)
    # metrics computed one after another: the largest counts, not their sum; JNYang's are in the base
    assert job_bytes("targets", (100, 10), metrics=("jnyang", "flip", "lpips")) == flip
    assert job_bytes("targets", (100, 10), metrics=("jnyang", "psnr")) == job_bytes("targets", (100, 10))
    loops = job_bytes("play", (100, 10), loops=55, models=2) - job_bytes("play", (100, 10))
    assert loops == int(1000 * (55 * PER_PIXEL["play.loop"] + 2 * PER_PIXEL["play.model"]))
    assert job_bytes("demo", (100, 10), loops=55) == job_bytes("demo", (100, 10))  # (a closed loop's only)
    lpips = job_bytes("metric", (100, 10), metrics=("psnr", "lpips"))  # torch and AlexNet: a base of their own
    assert lpips == int(BASE["metric"] + METRIC_BASE["metric"]["lpips"]
                        + (PER_PIXEL["metric"] + METRIC_PER_PIXEL["metric"]["lpips"]) * 1000)
    with pytest.raises(sdk.ParameterError, match="^job: expected one of capture, targets, demo, play, metric, got 'render'"):
        job_bytes("render", (100, 10))
    assert job_bytes("demo", (100, 10), metrics="flip") == job_bytes("demo", (100, 10), metrics=["flip"])  # one name
    for kw, words in (({"size": (0, 10)}, r"^size: expected an integer in \[1, 2147483647\], got 0"),
                      ({"size": (100,)}, r"^size: expected \(width, height\)"),
                      ({"size": (2**40, 10)}, r"^size: expected an integer in"),  # (float products would overflow)
                      ({"processes": 0}, "^processes: expected an integer in"),
                      ({"loops": -1}, r"^loops: expected an integer in \[0,"),
                      ({"metrics": ("flip", "flipp")}, "^metrics: expected names of flip, .*, got 'flipp'")):
        with pytest.raises(sdk.ParameterError, match=words):
            job_bytes("demo", **{"size": (100, 10), **kw})
    for need in (-1, float("nan"), float("inf"), "1 GB", True):
        with pytest.raises(sdk.ParameterError, match="^need: expected a number of bytes >= 0"):
            check_memory(need, "a job", "size", "of memory: less")  # type: ignore[arg-type]


def test_meminfo_reads_linux_fields_and_nothing_elsewhere(machine_memory: Callable[..., None], tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    assert meminfo("MemTotal") == 0  # an empty file: no field, nothing checked
    machine_memory(MemTotal=8 * GiB, SwapTotal=0, MemAvailable=3 * GiB)
    assert (meminfo("MemTotal"), meminfo("SwapTotal"), meminfo("MemAvailable")) == (8 * GiB, 0, 3 * GiB)
    assert meminfo("Hugepagesize") == 0
    from rtp.capture import _memory

    (tmp_path / "damaged").write_bytes(b"MemTotal: lots kB\n\xff\xfe")
    for path in (tmp_path / "damaged", tmp_path / "absent"):
        monkeypatch.setattr(_memory, "MEMINFO", str(path))
        assert meminfo("MemTotal") == 0
        check_memory(2**60, "a job", "size", "of memory: less")  # nothing known: nothing refused
    monkeypatch.setattr(_memory, "MEMINFO", "/proc/meminfo")
    assert meminfo("MemTotal") > 0


def test_check_memory_refuses_past_memory_and_swap_and_warns_past_what_is_free(
    machine_memory: Callable[..., None], caplog: pytest.LogCaptureFixture
) -> None:
    machine_memory(MemTotal=4 * GiB, MemAvailable=1 * GiB)
    with pytest.raises(sdk.ParameterError,
                       match=r"^size: a job, more than this machine's 4\.0 GiB of memory: less" + HINT) as info:
        check_memory(5 * GiB, "a job", "size", "of memory: less")
    assert info.value.name == "size"
    machine_memory(MemTotal=4 * GiB, SwapTotal=2 * GiB, MemAvailable=1 * GiB)
    with pytest.raises(sdk.ParameterError, match=r"6\.0 GiB of memory and swap: less" + HINT):
        check_memory(7 * GiB, "a job", "size", "of memory: less")
    with pytest.raises(TargetError, match="^data: a job"):
        check_memory(7 * GiB, "a job", "data", "of memory: less", error=lambda message, name: TargetError(message))
    with caplog.at_level(logging.WARNING):
        check_memory(5 * GiB, "a job", "size", "of memory: less", job="the capture")  # fits with swap: warned
        check_memory(GiB // 2, "a small job", "size", "of memory: less")  # fits what is free: quiet
    assert [(r.name, r.getMessage()) for r in caplog.records] == [
        ("rtp.capture", "a job, more than the 1.0 GiB of memory available now: the system may kill the capture")]
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        check_memory(2 * GiB, "a job", "size", "of memory: less", logger=logging.getLogger("rtp.train"))
    assert [r.name for r in caplog.records] == ["rtp.train"]


def test_a_capture_past_the_machines_memory_is_refused_before_anything_is_drawn(
    machine_memory: Callable[..., None], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    out = tmp_path / "ds"
    machine_memory(MemTotal=8 * GiB, MemAvailable=8 * GiB)
    with pytest.raises(sdk.ParameterError, match=r"^size: a capture at 4096x4096 holds about 12\.2 GiB, more than this "
                                                 r"machine's 8\.0 GiB of memory: a smaller size" + HINT) as info:
        capture(["procedural:1"], out, per_scene=1, size=(4096, 4096))
    assert info.value.name == "size" and not out.exists()
    # two scenes in two processes: each would fit alone
    with pytest.raises(sdk.ParameterError, match=r"at 3072x2048 holds about 9\.3 GiB \(4\.7 GiB in each of 2 processes\)"
                                                 r".* a smaller size or fewer workers" + HINT):
        capture(["procedural:1", "procedural:2"], out, per_scene=1, size=(3072, 2048), workers=2)
    assert not out.exists()
    assert job_bytes("capture", (3072, 2048)) < 8 * GiB  # (one scene would be one process: it would be drawn)
    machine_memory(MemTotal=8 * GiB, MemAvailable=job_bytes("capture", (64, 48)) - 1)
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        report = capture(["procedural:1"], out, per_scene=1, size=(64, 48), profiles="slow")
    assert report.written == 1  # fits the machine, not what is free now: warned, and captured
    assert any("a capture at 64x48 holds about" in r.getMessage() and "may kill a capture" in r.getMessage()
               for r in caplog.records)


def test_targets_past_the_machines_memory_are_refused_before_any_is_computed(
    machine_memory: Callable[..., None], tmp_path: Path
) -> None:
    data = tmp_path / "ds"
    # (two samples: two workers on one would start one process, which fits)
    capture(["procedural:1"], data, per_scene=1, size=(64, 48), profiles=("slow", "fast"))
    one = job_bytes("targets", (64, 48), metrics=("flip",))
    machine_memory(MemTotal=one - 1, MemAvailable=one - 1)
    with pytest.raises(TargetError, match=r"^data: the jnyang, flip targets of its 64x48 samples take about 0\.\d GiB, "
                                          r"more than this machine's 0\.\d GiB of memory: compute them on a larger machine"):
        compute_targets(data, ("jnyang", "flip"))
    with pytest.raises(TargetError, match=r"^data: .* \(0\.\d GiB in each of 2 processes\), .* on a larger machine"):
        compute_targets(data, ("jnyang", "flip"), workers=2)  # (one alone does not fit: not "fewer workers")
    assert not (data / "targets").exists()
    machine_memory(MemTotal=one + 1, MemAvailable=one + 1)
    with pytest.raises(TargetError, match=r"^workers: the jnyang, flip targets .* \(0\.\d GiB in each of 2 processes\), "
                                          r".* of memory: fewer workers" + HINT):
        compute_targets(data, ("jnyang", "flip"), workers=2)
    assert not (data / "targets").exists()
    assert compute_targets(data, ("jnyang", "flip")) == 2  # one process fits


def test_the_closed_loop_counts_its_loops_and_refuses_a_size_past_memory(
    machine_memory: Callable[..., None], tmp_path: Path
) -> None:
    specs = parse_methods(DEFAULT_METHODS + ",full,oracle-monotone,fidelityfx-additional,psnr")
    predictors = {m.model: sdk.load(m.model) for m in specs if m.kind == "model"}
    for sweep in (True, False):  # what the check counts is what the run makes
        loops = _loops(specs, predictors, sweep, 0.25, False, 16, 0.5)
        assert sum(_loop_count(m, sweep, predictors) for m in specs) == len(loops) == (75 if sweep else len(specs))
    out = tmp_path / "play"
    machine_memory(MemTotal=8 * GiB, MemAvailable=8 * GiB)
    with pytest.raises(PlayError, match=r"^size: the closed loop at 3072x2048 holds about 9\.7 GiB, more than this "
                                        r"machine's 8\.0 GiB of memory: a smaller size" + HINT) as info:
        play("procedural:0", size=(3072, 2048), out=out)
    assert info.value.name == "size" and not out.exists()
    with pytest.raises(PlayError, match=r"\(4\.2 GiB in each of 2 processes\), .* a smaller size or fewer workers" + HINT):
        play("procedural:0", "oracle", size=(3072, 2048), sweep=False, workers=2, out=out)
    # FLIP's truth on six rates: one path alone would not fit either, so fewer workers would not do
    with pytest.raises(PlayError, match=r"at 3072x2048 holds about 21\.2 GiB \(10\.6 GiB in each of 2 processes\), "
                                        r"more than this machine's 8\.0 GiB of memory: a smaller size" + HINT):
        play("procedural:0", "oracle", size=(3072, 2048), sweep=False, workers=2, fail_metric="flip", out=out)
    assert not out.exists()


def test_rtp_demo_refuses_a_size_past_memory_in_one_line(
    machine_memory: Callable[..., None], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "demo"
    machine_memory(MemTotal=8 * GiB, MemAvailable=8 * GiB)
    assert rtp_main(["demo", "--size", "4096x3072", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip() == ("rtp demo: error: --size: the demo at 4096x3072 holds about 8.2 GiB, more "
                                               "than this machine's 8.0 GiB of memory: a smaller size" + SAID_HINT)
    assert not out.exists()
    assert rtp_main(["demo", "--model", "flip", "--size", "3072x2048", "--out", str(out)]) == 2  # FLIP's targets
    assert "size: the demo at 3072x2048 holds about 10.3 GiB" in capsys.readouterr().err  # (JNYang's: 4.3 GiB)
    assert not out.exists()


def test_bench_job_memory_prints_the_measured_peak_beside_the_estimate() -> None:
    import subprocess
    import sys

    bench = Path(__file__).resolve().parents[1] / "bench" / "job_memory.py"
    out = subprocess.run([sys.executable, str(bench), "--jobs", "capture", "--sizes", "64x48,128x96"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "2/2" in out.stderr and "capture: procedural:1, 2 samples at 128x96" in out.stderr  # its progress, on stderr
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in out.stdout.splitlines()
            if line.startswith("| capture")]
    assert len(rows) == 1
    _, label, small, large, slope, estimated, peak, ratio = rows[0]
    assert label == "procedural:1, 2 samples" and 0 < float(small) <= float(large)  # (MB: the larger frame holds more)
    assert float(estimated) == PER_PIXEL["capture"]
    assert float(peak) == round(job_bytes("capture", (128, 96)) / 1e6)
    assert abs(float(ratio) - float(peak) / float(large)) < 0.02
    for args, words in ((["--jobs", "targets"], "targets are computed on the capture's samples: add capture"),
                        (["--jobs", "render"], "--jobs: expected a comma-separated list of capture, targets"),
                        (["--sizes", "128x96,64x48"], "--sizes: expected two sizes, the smaller first")):
        bad = subprocess.run([sys.executable, str(bench), *args], capture_output=True, text=True, timeout=120)
        assert bad.returncode == 2 and words in bad.stderr, (args, bad.stderr)


def test_bench_job_memory_says_a_failed_command_as_text() -> None:
    """A command that fails stops the benchmark with its exit code and its last line of stderr as text (it was a
    Python list, ``exit 2: ['rtp play: error: ...']``, in a line of its own without the script's name)."""
    import sys

    from .conftest import bench_module

    peak = bench_module("job_memory").peak
    child = "import sys; sys.stderr.write('warming up\\nrtp play: error: --frames: too few\\n'); sys.exit(2)"
    with pytest.raises(sdk.RtpError) as info:
        peak([sys.executable, "-c", child])
    assert str(info.value) == f"-c {child}: exit 2: rtp play: error: --frames: too few"
    with pytest.raises(sdk.RtpError, match=r": exit 3$"):  # (nothing on stderr: the exit code alone)
        peak([sys.executable, "-c", "raise SystemExit(3)"])
    assert peak([sys.executable, "-c", "pass"]) > 0


def test_rtp_metric_refuses_an_image_pair_past_memory_before_decoding_it(
    machine_memory: Callable[..., None], tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch
) -> None:
    """Pillow decodes images of up to 179 million pixels; LPIPS of such a pair takes about 32 GiB."""
    import numpy as np
    from PIL import Image

    from rtp.cli import _metric

    ref, test = tmp_path / "ref.png", tmp_path / "test.png"
    Image.fromarray(np.full((96, 160, 3), 128, np.uint8)).save(ref)
    Image.fromarray(np.full((96, 160, 3), 120, np.uint8)).save(test)
    need = job_bytes("metric", (160, 96), metrics=("lpips",))
    machine_memory(MemTotal=need - 2**20, MemAvailable=need - 2**20)
    decoded: list[str] = []
    read = _metric._read
    monkeypatch.setattr(_metric, "_read", lambda path: decoded.append(path))
    assert rtp_main(["metric", "lpips", str(ref), str(test)]) == 2
    assert capsys.readouterr().err.strip() == (
        f"rtp metric: error: reference: lpips of a 160x96 image pair takes about {need / GiB:.1f} GiB, more than this "
        f"machine's {(need - 2**20) / GiB:.1f} GiB of memory: smaller images" + SAID_HINT)
    assert decoded == []  # refused from the header
    monkeypatch.setattr(_metric, "_read", read)
    assert rtp_main(["metric", "psnr", str(ref), str(test)]) == 0  # the same machine: without torch's base it fits
    assert "psnr (dB), 160x96" in capsys.readouterr().out


def test_rtp_memory_check_turns_the_refusal_into_a_warning_or_off(
    machine_memory: Callable[..., None], tmp_path: Path, caplog: pytest.LogCaptureFixture,
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The tables were measured on Mesa's software GL; with a hardware driver the renderer's images
    live on the GPU and a refusal can be a false one: RTP_MEMORY_CHECK=warn runs the job anyway,
    saying what it would have refused; off checks nothing; another value is a usage error."""
    need = job_bytes("capture", (64, 48))
    machine_memory(MemTotal=need - 2**20, MemAvailable=need - 2**20)
    with pytest.raises(sdk.ParameterError, match=r"^size: a capture at 64x48 .* a smaller size" + HINT):
        capture(["procedural:1"], tmp_path / "refused", per_scene=1, size=(64, 48), profiles="slow")
    assert not (tmp_path / "refused").exists()
    monkeypatch.setenv("RTP_MEMORY_CHECK", " Warn ")  # (case and spaces as a shell may leave them)
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        assert capture(["procedural:1"], tmp_path / "warned", per_scene=1, size=(64, 48), profiles="slow").written == 1
    said = [r.getMessage() for r in caplog.records if r.name == "rtp.capture" and "GiB" in r.getMessage()]
    assert len(said) == 1 and said[0].startswith("size: a capture at 64x48 holds about")
    assert said[0].endswith("of memory: a smaller size (RTP_MEMORY_CHECK=warn: running it anyway)")
    caplog.clear()
    monkeypatch.setenv("RTP_MEMORY_CHECK", "off")
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        assert capture(["procedural:1"], tmp_path / "off", per_scene=1, size=(64, 48), profiles="slow").written == 1
        check_memory(2**60, "a job", "size", "of memory: less")  # not even the warning past what is free
    assert not [r for r in caplog.records if "GiB" in r.getMessage()]
    monkeypatch.setenv("RTP_MEMORY_CHECK", "ignore")
    with pytest.raises(sdk.ParameterError, match="^RTP_MEMORY_CHECK: expected one of refuse, warn, off, got 'ignore'$"):
        check_memory(1, "a small job", "size", "of memory: less")  # a typo is said, whatever the job's size
    assert rtp_main(["capture", "--scene", "procedural:1", "--per-scene", "1", "--size", "64x48", "--no-progress",
                     "--out", str(tmp_path / "typo")]) == 2
    assert capsys.readouterr().err.strip().endswith(
        "rtp capture: error: RTP_MEMORY_CHECK: expected one of refuse, warn, off, got 'ignore'")
    assert not (tmp_path / "typo").exists()


def test_ray_nodes_follow_rtp_memory_check(monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """Each Ray node's workers against its memory (capture/_ray.py) read the same variable on the
    driver: refused, warned, or not asked (the workers' memory is not even fetched)."""
    from rtp.capture import _ray

    asked: list[int] = []

    class Worker:  # a Ray actor's handle as _check_node_memory uses it: node id, memory + swap, available
        class node_memory:  # noqa: N801
            @staticmethod
            def remote() -> tuple[str, int, int]:
                asked.append(1)
                return ("node0123456789", 4 * GiB, 4 * GiB)

    class FakeRay:
        @staticmethod
        def get(refs: list[Any]) -> list[Any]:
            return refs

    monkeypatch.setattr(_ray, "_ray", lambda: FakeRay)
    check = lambda: _ray._check_node_memory([Worker(), Worker()], 3 * GiB, "a capture at 8x8 holds", "size",  # noqa: E731
                                            "a smaller size", sdk.ParameterError)
    monkeypatch.delenv("RTP_MEMORY_CHECK", raising=False)
    with pytest.raises(sdk.ParameterError, match=r"^size: a capture at 8x8 holds about 6\.0 GiB on Ray node node01234567 "
                                                 r"\(3\.0 GiB in each of its 2 workers\), more than its 4\.0 GiB of memory "
                                                 r"and swap: a smaller size or fewer workers" + HINT):
        check()
    monkeypatch.setenv("RTP_MEMORY_CHECK", "warn")
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        check()
    assert [r.getMessage().endswith("or fewer workers (RTP_MEMORY_CHECK=warn: running it anyway)")
            for r in caplog.records] == [True]
    asked.clear()
    monkeypatch.setenv("RTP_MEMORY_CHECK", "off")
    check()
    assert asked == []
