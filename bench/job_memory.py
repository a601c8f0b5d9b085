"""Peak memory of rtp's frame jobs, measured, beside the estimate they are refused by.

    python bench/job_memory.py [--sizes 640x384,1280x768] [--jobs capture,targets,demo,play,metric,examples] [--frames 3]

Each configuration below runs as an ``rtp`` command in a process of its own at each size; its peak
resident set (the process and every child it waited for: ``os.wait4``) is read. The table gives
both peaks, the slope between them in bytes per pixel, the slope and the peak at the larger size
that ``rtp.capture.job_bytes`` estimates (the numbers ``rtp capture``, ``rtp targets``, ``rtp
demo`` and ``rtp play`` refuse a frame size by, past the machine's memory and swap), and the ratio
of the estimated to the measured peak. The configurations:

- capture: ``rtp capture --scene procedural:1 --per-scene 1`` (two samples, one process)
- targets: ``rtp targets --metrics M`` of that capture, for each metric
- demo: ``rtp demo --model M``, for each shipped model
- play: ``rtp play procedural:0 --path fast --frames N --no-plots`` with the oracle alone, JNYang
  alone, the default methods (each without and with the sweep), the oracle with dynamic resolution
  (``--dynamic-resolution 0.5,0.75,1@1``: its renderer resized twice a path), and the oracle failing by FLIP,
  JNFLIP and LPIPS
- metric: ``rtp metric M REF TEST --out MAP.png`` of two noise images of the size, for each metric
- examples: ``examples/moderngl_vrs.py`` and ``examples/pyrender_vrs.py``, each alone and with a GIF
  of 9 frames; their estimate is the example's own ``peak_bytes`` (its constants ``PEAK_*``)

The slopes are what ``rtp.capture``'s tables (``PER_PIXEL``, ``METRIC_PER_PIXEL``) and the examples'
``PEAK_*`` constants hold: rerun this after a change that holds more or fewer full-frame images.
Linux only (``os.wait4``). Prints a Markdown table once every command has run (minutes: a progress bar on
stderr names the command running); a command that fails stops it with that command's error line.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from _common import frame_sizes, run_main  # bench/ is on sys.path when run as a script

from rtp import sdk
from rtp.capture import job_bytes

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

JOBS = ("capture", "targets", "demo", "play", "metric", "examples")
RTP = [sys.executable, "-m", "rtp", "-q"]
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@dataclass
class Config:
    """One measured command: ``job`` and its label, the ``rtp`` arguments after the size (``{out}`` and
    ``{data}`` filled in; ``command`` instead of ``rtp``), and what :func:`rtp.capture.job_bytes` is
    told of it (or ``estimate``, the peak bytes at a size)."""

    job: str
    label: str
    args: list[str]
    metrics: tuple[str, ...] = ()
    loops: int = 0
    models: int = 0
    peaks: list[int] = field(default_factory=list)
    command: list[str] = field(default_factory=lambda: list(RTP))
    estimate: Callable[[tuple[int, int]], int] | None = None

    def estimated(self, size: tuple[int, int]) -> int:
        if self.estimate is not None:
            return self.estimate(size)
        return job_bytes(self.job, size, metrics=self.metrics, loops=self.loops, models=self.models)


def example(name: str) -> object:
    """``examples/NAME.py`` as a module (its ``peak_bytes``), without running its main."""
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def configs(frames: int) -> Iterator[Config]:
    from rtp.evaluate import DEFAULT_METHODS, parse_methods
    from rtp.evaluate._play import _loop_count

    yield Config("capture", "procedural:1, 2 samples",
                 ["capture", "--scene", "procedural:1", "--per-scene", "1", "--out", "{data}"])
    for m in sdk.TARGET_METRICS:
        yield Config("targets", m, ["targets", "{data}", "--metrics", m], metrics=(m,))
    for name in sdk.shipped_models():
        model = name.removesuffix(".onnx")
        yield Config("demo", model, ["demo", "--model", model, "--out", "{out}"], metrics=(sdk.load(model).metadata.metric,))
    predictors = {m.model: sdk.load(m.model) for m in parse_methods(DEFAULT_METHODS) if m.kind == "model"}
    for methods, sweep in (("oracle", False), ("jnyang", False), (DEFAULT_METHODS, False), (DEFAULT_METHODS, True)):
        specs = parse_methods(methods)
        label = ("default methods" if methods == DEFAULT_METHODS else methods) + (", swept" if sweep else "")
        yield Config("play", label,
                     ["play", "procedural:0", "--path", "fast", "--frames", str(frames), "--no-plots", "--out", "{out}",
                      "--methods", methods, *([] if sweep else ["--no-sweep"])],
                     metrics=("jnyang",), loops=sum(_loop_count(m, sweep, predictors) for m in specs),
                     models=len({m.model for m in specs if m.kind == "model"}))
    # one renderer resized to each size, the largest last (what a smaller size's targets held is freed)
    yield Config("play", "oracle, dynamic resolution 0.5,0.75,1@1",
                 ["play", "procedural:0", "--path", "fast", "--frames", str(frames), "--no-plots", "--out", "{out}",
                  "--methods", "oracle", "--no-sweep", "--dynamic-resolution", "0.5,0.75,1@1"],
                 metrics=("jnyang",), loops=1)
    for metric in ("flip", "jnflip", "lpips"):
        yield Config("play", f"oracle, failing by {metric}",
                     ["play", "procedural:0", "--path", "fast", "--frames", str(frames), "--no-plots", "--out", "{out}",
                      "--methods", "oracle", "--no-sweep", "--fail-metric", metric], metrics=(metric,), loops=1)
    for m in sdk.METRICS:
        yield Config("metric", m, ["metric", m, "{ref}", "{test}", "--out", "{out}.png"], metrics=(m,))
    for name, model, frames in (("moderngl_vrs", "jnyang", 3), ("pyrender_vrs", "jnyang-reuse", 5)):
        peak_bytes = example(name).peak_bytes  # type: ignore[attr-defined]
        for gif in (False, True):
            n = 9 if gif else frames
            yield Config("examples", f"{name}.py, {n} frames" + (", GIF" if gif else ""),
                         ["--model", model, "--frames", str(n), "--out", "{out}.png", *(["--gif", "{out}.gif"] if gif else [])],
                         command=[sys.executable, str(EXAMPLES / f"{name}.py")],
                         estimate=lambda size, f=peak_bytes, n=n, gif=gif: f(*size, n, gif))


def image_pair(folder: Path, size: tuple[int, int]) -> tuple[Path, Path]:
    """Two PNGs of ``size``: uniform noise, and the same with noise of +-20 levels added."""
    import numpy as np
    from PIL import Image

    rng = np.random.default_rng(0)
    ref = (rng.random((size[1], size[0], 3)) * 255).astype(np.uint8)
    test = np.clip(ref.astype(np.int16) + rng.integers(-20, 21, ref.shape), 0, 255).astype(np.uint8)
    paths = folder / f"ref-{size[0]}x{size[1]}.png", folder / f"test-{size[0]}x{size[1]}.png"
    for path, img in zip(paths, (ref, test), strict=True):
        Image.fromarray(img).save(path)
    return paths


def play_frames(text: str) -> int:
    """An argparse type: frames of the closed-loop runs, as ``rtp play --frames`` takes them (3 or more: the first
    has no history; at most ``rtp.capture.paths.MAX_FRAMES``), refused here rather than by the first ``rtp play``
    after the jobs before it ran."""
    from rtp.capture.paths import MAX_FRAMES
    from rtp.cli import int_at_least

    n = int_at_least(3)(text)
    if n > MAX_FRAMES:
        raise argparse.ArgumentTypeError(f"expected at most {MAX_FRAMES} (ten minutes at 60 frames a second), got {n}")
    return n


def peak(argv: list[str]) -> int:
    """Run ``argv``; its peak resident set in bytes (its children's included), or an error that gives the command,
    its exit code and the last line it wrote to stderr."""
    # stderr into a file, not a pipe: wait4 reads nothing while it waits, so a command that wrote more than the pipe
    # holds (64 KiB on Linux: warnings, a traceback's chain) blocked on its write and this script waited for ever
    with tempfile.TemporaryFile() as log:
        proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=log)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        log.seek(0)
        err = log.read().decode(errors="replace")
    if proc.returncode != 0:
        lines = err.strip().splitlines()
        raise sdk.RtpError(f"{' '.join(argv[1:])}: exit {proc.returncode}" + (f": {lines[-1]}" if lines else ""))
    return int(usage.ru_maxrss) * 1024  # (KiB on Linux)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=frame_sizes(16), default="640x384,1280x768",
                    help="two comma-separated WIDTHxHEIGHT, the smaller first")
    ap.add_argument("--jobs", default=",".join(JOBS), help=f"comma-separated, of {', '.join(JOBS)}")
    ap.add_argument("--frames", type=play_frames, default=3, help="frames of each closed-loop run, 3 or more (default 3)")
    args = ap.parse_args()
    jobs = [j.strip() for j in args.jobs.split(",") if j.strip()]
    if not jobs or any(j not in JOBS for j in jobs):
        ap.error(f"--jobs: expected a comma-separated list of {', '.join(JOBS)}, got {args.jobs!r}")
    if len(args.sizes) != 2 or args.sizes[0][0] * args.sizes[0][1] >= args.sizes[1][0] * args.sizes[1][1]:
        ap.error("--sizes: expected two sizes, the smaller first")
    if "targets" in jobs and "capture" not in jobs:
        ap.error("--jobs: targets are computed on the capture's samples: add capture")
    chosen = [c for c in configs(args.frames) if c.job in jobs]
    with tempfile.TemporaryDirectory(prefix="rtp-job-memory-") as tmp, \
            tqdm(total=len(chosen) * len(args.sizes), desc="commands", unit="cmd", file=sys.stderr) as bar:
        for w, h in args.sizes:
            data, out = Path(tmp) / f"data-{w}x{h}", Path(tmp) / "out"
            ref, test = image_pair(Path(tmp), (w, h)) if "metric" in jobs else ("", "")
            for c in chosen:
                bar.set_postfix_str(f"{c.job}: {c.label} at {w}x{h}")
                # (targets: the capture's size; metric: its images')
                size = [] if c.job in ("targets", "metric") else ["--size", f"{w}x{h}"]
                c.peaks.append(peak([*c.command, *(a.format(out=out, data=data, ref=ref, test=test) for a in c.args), *size]))
                bar.update()
                shutil.rmtree(out, ignore_errors=True)
                for suffix in (".png", ".gif"):
                    Path(f"{out}{suffix}").unlink(missing_ok=True)
    (w0, h0), (w1, h1) = args.sizes
    pixels = w1 * h1 - w0 * h0
    print(f"rtp {sdk.__version__}, peak resident set of each command (MB), each in a process of its own; "
          f"slopes in bytes per pixel between {w0}x{h0} and {w1}x{h1}\n")
    print(f"| job | configuration | peak at {w0}x{h0} | peak at {w1}x{h1} | slope | estimated slope | "
          f"estimated peak at {w1}x{h1} | estimated / measured |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for c in chosen:
        est = [c.estimated(size) for size in args.sizes]
        print(f"| {c.job} | {c.label} | {c.peaks[0] / 1e6:.0f} | {c.peaks[1] / 1e6:.0f} | "
              f"{(c.peaks[1] - c.peaks[0]) / pixels:.0f} | {(est[1] - est[0]) / pixels:.0f} | {est[1] / 1e6:.0f} | "
              f"{est[1] / c.peaks[1]:.2f} |")


if __name__ == "__main__":
    run_main(main)
