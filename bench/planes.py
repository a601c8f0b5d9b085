"""The derived input planes on a CPU: what an adapter without a GPU path pays per frame to build them.

    python bench/planes.py [--repeats 7] [--sizes 1920x1080,1280x720]

The shipped JNYang, FLIP and PSNR read two ``.blocks`` planes (``sdk.block_variances`` of the
reprojected frame's and the albedo's luma); the moderngl adapter builds them in a shader, the
pyrender adapter, the dataset reader and ``rtp play`` in numpy. This times the SDK's numpy helpers
on random planes (their cost does not depend on the values): ``sdk.luma`` of an RGB frame,
``sdk.pixel_differences``, ``sdk.block_variances`` and, for comparison, the same plane computed as
its docstring defines it (a variance per block and rate, the implementation before 2026-11-29),
``sdk.tile_variances`` (the ``.tiles`` plane ``jnyang-reuse`` reads) and ``tile_block_levels`` (the
per-tile means ``PredictionReuse(rescale=...)`` takes of both planes).
Prints a Markdown table of medians (ms).
"""

from __future__ import annotations

import argparse
import platform

import numpy as np
from _common import frame_size, median_ms  # bench/ is on sys.path when run as a script

from rtp import sdk
from rtp.sdk._reuse import tile_block_levels


def block_variances_by_definition(plane: np.ndarray) -> np.ndarray:
    """``sdk.block_variances`` as its docstring defines it: ``np.var`` per block, per rate."""
    p = np.asarray(plane, np.float64)
    h, w = p.shape
    c = sdk.BLOCK_CELL
    q = np.pad(p, ((0, -h % c), (0, -w % c)), mode="edge")
    out = np.zeros(q.shape, np.float32)
    eps = 1e-4
    for k, rate in enumerate(sdk.BLOCK_RATES):
        bw, bh = sdk.rate_size(rate)
        var = q.reshape(q.shape[0] // bh, bh, q.shape[1] // bw, bw).var(axis=(1, 3))
        per_cell = var.reshape(q.shape[0] // c, c // bh, q.shape[1] // c, c // bw).mean(axis=(1, 3))
        out[k // c::c, k % c::c] = np.clip(np.log(per_cell + eps) / -np.log(eps) + 1.0, 0.0, 1.0)
    return out[:h, :w]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--sizes", type=lambda s: [frame_size(v, minimum=4) for v in s.split(",")],
                    default=[(1920, 1080), (1280, 720)], help="comma-separated WIDTHxHEIGHT")
    args = ap.parse_args()
    if args.repeats < 1:
        ap.error("--repeats must be at least 1")
    rng = np.random.default_rng(0)
    print(f"rtp {sdk.__version__}, numpy {np.__version__}, {platform.processor() or platform.machine()}, "
          f"median of {args.repeats}\n")
    print("| frame | luma of RGB | pixel_differences | block_variances | the same by definition | tile_variances | "
          "tile_block_levels, two planes |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for w, h in args.sizes:
        print(f"| {w}x{h} | " + " | ".join(f"{v:.1f}" for v in _row(rng, w, h, args.repeats)) + " |")


def _row(rng: np.random.Generator, w: int, h: int, repeats: int) -> list[float]:
    rgb = rng.random((h, w, 3), dtype=np.float32)
    y = sdk.luma(rgb)
    fast = sdk.block_variances(y)
    if not np.array_equal(fast, block_variances_by_definition(y)):  # what is timed must be the same plane
        raise SystemExit("block_variances differs from its definition")
    planes = np.stack([fast, sdk.block_variances(sdk.luma(rng.random((h, w, 3), dtype=np.float32)))])
    return [median_ms(lambda: sdk.luma(rgb), repeats),
            median_ms(lambda: sdk.pixel_differences(y), repeats),
            median_ms(lambda: sdk.block_variances(y), repeats),
            median_ms(lambda: block_variances_by_definition(y), repeats),
            median_ms(lambda: sdk.tile_variances(y), repeats),
            median_ms(lambda: tile_block_levels(planes, 16), repeats)]

if __name__ == "__main__":
    main()
