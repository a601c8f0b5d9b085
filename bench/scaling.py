"""Scaling on Ray: capture and targets with 1 and 2 local Ray workers, against the local pool.

    python bench/scaling.py [--scenes procedural:0,procedural:1] [--per-scene 3] [--size 1280x720]
                        [--workers 1,2] [--cache DIR]

Each configuration captures ``len(scenes) x 2 profiles x per-scene`` samples into a fresh folder,
then computes the targets of all five metrics. A private Ray instance is started per worker count
(its start-up is reported apart, not in the per-sample times). Prints a Markdown table of seconds
per sample and the speed-up over the first worker count of ``--workers`` (one by default); docs/scaling.md
quotes it. ``--modes pool`` needs no Ray; ``--modes ray`` needs ``rtp[ray]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

from _common import UsageError, frame_size, positive, positives, run_main  # bench/ is on sys.path as a script

from rtp.capture import capture, check_scene, compute_targets

METRICS = ("flip", "psnr", "lpips", "jnflip", "jnyang")


def _modes(text: str) -> list[str]:
    modes = [m.strip() for m in text.split(",") if m.strip()]
    if not modes or any(m not in ("ray", "pool") for m in modes):
        raise argparse.ArgumentTypeError(f"expected ray and/or pool, comma-separated, got {text!r}")
    return modes


def _ray() -> Any:
    """Ray, for ``--modes ray`` only (``--modes pool`` runs without the extra), or a usage error naming the extra."""
    try:
        import ray
    except ImportError:
        raise UsageError("--modes ray needs Ray: pip install 'rtp[ray]' (or --modes pool, the local processes "
                         "alone)") from None
    return ray


def run(scenes: list[str], per_scene: int, size: tuple[int, int], workers: int, mode: str, cache: str | None,
        ) -> tuple[float, float, int]:
    with tempfile.TemporaryDirectory(prefix="rtp-bench-ray-") as d:
        out = Path(d) / "ds"
        executor = "local" if mode == "ray" else None
        t0 = time.perf_counter()
        r = capture(scenes, out, per_scene=per_scene, size=size, workers=workers, ray=executor, cache_dir=cache)
        t_cap = time.perf_counter() - t0
        t0 = time.perf_counter()
        compute_targets(out, METRICS, workers=workers, ray=executor)
        t_tg = time.perf_counter() - t0
        return t_cap / r.written, t_tg / r.written, r.written


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default="procedural:0,procedural:1")
    ap.add_argument("--per-scene", type=positive, default=3)
    ap.add_argument("--size", type=lambda s: frame_size(s, 16), default=(1280, 720), help="WIDTHxHEIGHT (default 1280x720)")
    ap.add_argument("--workers", type=positives, default="1,2",
                    help="comma-separated worker counts (default: 1,2)")
    ap.add_argument("--modes", type=_modes, default="ray,pool",
                    help="ray (a private local Ray instance) and/or pool (local processes), comma-separated (default: both)")
    ap.add_argument("--cache", default=None, help="scene cache for fetched maps")
    args = ap.parse_args()
    w, h = args.size
    scenes = [n.strip() for n in args.scenes.split(",") if n.strip()]
    if not scenes:
        ap.error(f"--scenes: expected comma-separated scene names, got {args.scenes!r}")
    twice = [n for n in dict.fromkeys(scenes) if scenes.count(n) > 1]
    if twice:  # (refused by capture after the table's header)
        ap.error(f"--scenes: each scene once, got {', '.join(twice)} more than once")
    for name in scenes:  # (a map not listed or not fetched: refused before the table and Ray's start, not after)
        check_scene(name, args.cache, None, None)
    ray = _ray() if "ray" in args.modes else None  # (imported at the top, it failed `--modes pool` without the extra)
    print(f"{len(scenes)} scenes x 2 profiles x {args.per_scene} pairs at {w}x{h}; {platform.machine()}, "
          f"{os.cpu_count()} CPUs" + (f", ray {ray.__version__}" if ray else "") + "\n")
    print("| executor | workers | capture s/sample | targets s/sample | capture speed-up | targets speed-up | Ray start s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for mode in args.modes:
        base: tuple[float, float] | None = None
        for n in args.workers:
            start = 0.0
            if ray is not None and mode == "ray":
                t0 = time.perf_counter()
                ray.init(num_cpus=n, include_dashboard=False, configure_logging=False)
                start = time.perf_counter() - t0
            try:
                cap, tg, _ = run(scenes, args.per_scene, (w, h), n, mode, args.cache)
            finally:
                if ray is not None and mode == "ray":
                    ray.shutdown()
            base = base or (cap, tg)
            print(f"| {'Ray (local)' if mode == 'ray' else 'process pool'} | {n} | {cap:.2f} | {tg:.2f} | "
                  f"{base[0] / cap:.2f}x | {base[1] / tg:.2f}x | {start:.1f} |", flush=True)


if __name__ == "__main__":
    run_main(main)
