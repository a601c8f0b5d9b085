"""Capture throughput: samples per minute and bytes per sample at 640x360 and 1280x720.

    python bench/capture.py [--samples 4] [--scene procedural:0] [--cache DIR] [--workers 1]

Each sample is a previous and a current frame of the reference renderer (G-buffers, all 7 shading
rates, reprojection) plus the compressed write; the timed run includes the scene's viewpoint
sampling. The first sample (scene load, GL start-up) is reported apart. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from _common import positive, run_main  # bench/ is on sys.path when run as a script

from rtp.capture import capture


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=positive, default=4, help="samples per size (slow profile)")
    ap.add_argument("--scene", default="procedural:0", help="a scene name (procedural:<seed> or a fetched map)")
    ap.add_argument("--cache", default=None, help="scene cache for fetched maps")
    ap.add_argument("--workers", type=positive, default=1)
    args = ap.parse_args()
    rows = []
    for w, h in ((640, 360), (1280, 720)):
        with tempfile.TemporaryDirectory() as d:
            out = Path(d) / "ds"
            # One sample first: scene load, viewpoint sampling and GL start-up, reported apart.
            t0 = time.perf_counter()
            capture([args.scene], out, per_scene=1, size=(w, h), profiles=("slow",), cache_dir=args.cache)
            setup = time.perf_counter() - t0
            t0 = time.perf_counter()
            r = capture([args.scene], out, per_scene=1 + args.samples, size=(w, h), profiles=("slow",),
                        cache_dir=args.cache, workers=args.workers)
            dt = time.perf_counter() - t0
            manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
            rows.append((f"{w}x{h}", r.written / dt * 60, dt / r.written, setup, manifest["bytes_per_sample"] / 1e6))
    print(f"scene {args.scene}, {args.samples} samples per size, {args.workers} worker(s)\n")
    print("| size | samples/min | s/sample | first sample incl. set-up (s) | MB/sample |")
    print("|---|---|---|---|---|")
    for name, spm, sps, setup, mb in rows:
        print(f"| {name} | {spm:.1f} | {sps:.2f} | {setup:.1f} | {mb:.2f} |")


if __name__ == "__main__":
    run_main(main)
