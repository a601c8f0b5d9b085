"""The derived input planes on a CPU: what an adapter without a GPU path pays per frame to build them.

    python bench/planes.py [--repeats 7] [--sizes 1920x1080,1280x720]
    python bench/planes.py --against REV [--scenes procedural:0,20kdm2] [--frames 30] [--data data/test]

The shipped JNYang, FLIP and PSNR read two ``.blocks`` planes (``sdk.block_variances`` of the
reprojected frame's and the albedo's luma); the moderngl adapter builds them in a shader, the
pyrender adapter, the dataset reader and ``rtp play`` in numpy. This times the SDK's numpy helpers
on random planes (their cost does not depend on the values): ``sdk.luma`` of an RGB frame,
``sdk.pixel_differences``, ``sdk.block_variances`` and, for comparison, the same plane computed as
its docstring defines it (a variance per block and rate, the implementation before 2026-11-29),
``sdk.tile_variances`` (the ``.tiles`` plane ``jnyang-reuse`` reads) and ``tile_block_levels`` (the
per-tile means ``PredictionReuse(rescale=...)`` takes of both planes).
Prints a Markdown table of medians (ms).

``--against REV`` times nothing: it loads ``sdk/_channels.py`` as it was at git revision ``REV`` and
counts the values of the ``.blocks`` and ``.tiles`` planes that differ from this checkout's, on the
lumas of rendered frames (the final colour at full rate and at 4x4, the albedo, the same in float64,
and a crop whose sides are not multiples of 4; every tenth frame of each scene's fast camera path),
of a dataset's samples (``--data``: the reprojected frame's and the albedo's, which the models read)
and of random, flat, two-level, near-flat and wide-range planes of many sizes. For every ``.blocks``
value that differs it computes the cell's block variances in exact rationals and says which of the
two values is nearer. Exits 1 if ``REV``'s ever is: a faster implementation must give the planes the
shipped models were trained and scored on, or more exact ones.
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import (  # bench/ is on sys.path when run as a script
    cpu_description,
    dataset_folder,
    frame_size,
    median_ms,
    module_at_revision,
    positive,
    run_main,
)

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
    ap.add_argument("--repeats", type=positive, default=7)
    ap.add_argument("--sizes", type=lambda s: [frame_size(v, minimum=4) for v in s.split(",")],
                    default=[(1920, 1080), (1280, 720)], help="comma-separated WIDTHxHEIGHT")
    ap.add_argument("--against", metavar="REV", help="compare the planes with those of sdk/_channels.py at git REV")
    ap.add_argument("--scenes", default="procedural:0", help="with --against: scenes whose frames are compared")
    ap.add_argument("--frames", type=positive, default=30, help="with --against: frames of each scene's path")
    ap.add_argument("--data", type=dataset_folder,
                    help="with --against: a dataset folder whose samples' lumas are compared too")
    args = ap.parse_args()
    if args.against:
        raise SystemExit(_against(args.against, args.scenes.split(","), args.frames, args.data))
    rng = np.random.default_rng(0)
    print(f"rtp {sdk.__version__}, numpy {np.__version__}, {cpu_description()}, "
          f"median of {args.repeats}\n")
    print("| ms | luma of RGB | pixel_differences | block_variances | the same by definition | tile_variances | "
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


def _against(rev: str, scenes: list[str], frames: int, data: str | None) -> int:
    """Count the ``.blocks`` and ``.tiles`` values that differ from ``sdk/_channels.py`` at ``rev``, and
    for each ``.blocks`` value that differs which of the two is nearer its exact value. 1 where ``rev``'s is."""
    from rtp.capture import DatasetReader, load_scene
    from rtp.capture.paths import PathPlayer, camera_path

    then = module_at_revision(rev, "sdk/_channels.py", "rtp.sdk._channels_then")
    pairs = {"block_variances": (then.block_variances, sdk.block_variances),
             "tile_variances": (then.tile_variances, sdk.tile_variances)}
    counts = {(source, name): [0, 0] for source in ("frames", "dataset", "synthetic") for name in pairs}
    nearer = {"this checkout": 0, rev: 0, "neither": 0}

    def compare(plane: np.ndarray, source: str) -> None:
        for name, (old, new) in pairs.items():
            a, b = old(plane), new(plane)
            if a.shape != b.shape or a.dtype != b.dtype:
                raise SystemExit(f"{name}: {rev} gives {a.shape} {a.dtype}, this checkout {b.shape} {b.dtype}")
            differ = np.argwhere(a != b)
            counts[source, name][0] += len(differ)
            counts[source, name][1] += a.size
            if name == "block_variances":
                for y, x in differ:
                    want = _exact_block_value(plane, int(y), int(x))
                    da, db = abs(float(a[y, x]) - want), abs(float(b[y, x]) - want)
                    nearer["this checkout" if db < da else rev if da < db else "neither"] += 1

    for name in scenes:
        scn, blockers = load_scene(name, None, None, None)
        path = camera_path(scn, frames, "fast", 0, blockers=blockers)
        with PathPlayer(scn, (1280, 720), exact=False) as player:
            for pf in player.frames(path):
                if pf.index % 10 == 0:
                    f = pf.frame
                    y = sdk.luma(f.colour["1x1"])
                    for plane in (y, sdk.luma(f.colour["4x4"]), sdk.luma(f.albedo), y.astype(np.float64), y[3:-5, 1:-2]):
                        compare(plane, "frames")
    if data:
        reader = DatasetReader(data)
        for sid in reader.ids:
            for buffer in ("reprojected", "albedo"):  # the lumas whose planes the models read
                compare(sdk.luma(reader[sid].buffer(buffer)), "dataset")
    rng = np.random.default_rng(1)
    for trial in range(300):
        h, w = (int(v) for v in rng.integers(1, 80, 2))
        kind = trial % 5
        plane = (rng.random((h, w), dtype=np.float32),
                 np.full((h, w), rng.random(), np.float32),
                 (rng.random((h, w)) > 0.5).astype(np.float32) * np.float32(rng.random()),
                 (0.5 + 1e-3 * rng.standard_normal((h, w))).astype(np.float32),
                 rng.random((h, w)) * 10 ** rng.uniform(-6, 2))[kind]
        compare(plane, "synthetic")
    what = {"frames": f"scenes {', '.join(scenes)}, every tenth of {frames} frames",
            "dataset": f"the reprojected and albedo luma of every sample of {data}", "synthetic": "300 synthetic planes"}
    print(f"against {rev}\n")
    print("| planes | plane | values compared | values that differ |")
    print("|---|---|---:|---:|")
    for (source, name), (differ, total) in counts.items():
        if total:
            print(f"| {what[source]} | {name} | {total:,} | {differ:,} |")
    print("\n.blocks values that differ, nearer their exact value (a variance per block in exact rationals): "
          + ", ".join(f"{k} {v}" for k, v in nearer.items()))
    return 1 if nearer[rev] else 0


def _exact_block_value(plane: np.ndarray, y: int, x: int) -> float:
    """The ``.blocks`` value at pixel ``(y, x)`` of ``plane`` from the cell's block variances computed in
    exact rationals (the normalised log in float64)."""
    from fractions import Fraction

    c = sdk.BLOCK_CELL
    h, w = plane.shape
    padded = np.pad(np.asarray(plane), ((0, -h % c), (0, -w % c)), mode="edge")
    cy, cx = y - y % c, x - x % c
    bw, bh = sdk.rate_size(sdk.BLOCK_RATES[(y - cy) * c + (x - cx)])
    cell = [[Fraction(float(v)) for v in row] for row in padded[cy:cy + c, cx:cx + c]]
    total = Fraction(0)
    for by in range(0, c, bh):
        for bx in range(0, c, bw):
            values = [cell[i][j] for i in range(by, by + bh) for j in range(bx, bx + bw)]
            mean = sum(values, Fraction(0)) / len(values)
            total += sum(((v - mean) ** 2 for v in values), Fraction(0))
    v = np.log(float(total / (c * c)) + sdk.BLOCK_EPS) / -np.log(sdk.BLOCK_EPS) + 1.0
    return float(np.clip(v, 0.0, 1.0))


if __name__ == "__main__":
    run_main(main)
