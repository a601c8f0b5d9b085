"""Benchmark the pyrender adapter: the time to build each shipped model's inputs from a pyrender scene.

    python bench/pyrender_adapter.py [--sizes 640x360,1280x720] [--repeats 5]

Draws the procedural scene of seed 3 with pyrender (the adapter's frame source: pyrender's lit image
from the previous camera is the displayed frame) and times ``Adapter.inputs`` for the channels of every
shipped model, twice: in a frame loop, where the previous frame's depth is the adapter's own from the
frame before (``prev_depth`` cached: the G-buffer passes the channels need, then ``sdk.input_planes``),
and on a first frame, where it draws the previous depth too. The adapter's G-buffer passes (pyrender,
llvmpipe on a machine without a GPU) and its numpy planes (``sdk.input_planes``: the reprojection,
luma, the ``.blocks`` variances; ``bench/input_planes.py`` times them alone) make up each time.
Prints a Markdown table of medians (ms).
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from _common import cpu_description, frame_sizes, median_ms, positive, run_main  # bench/ is on sys.path as a script

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from rtp import sdk  # noqa: E402


def time_size(w: int, h: int, repeats: int) -> dict[str, tuple[float, float]]:
    """``{model: (frame-loop ms, first-frame ms)}`` at one size."""
    from rtp.capture import load_scene
    from rtp.capture.viewpoints import sample_viewpoints
    from rtp.plugins.pyrender import Adapter

    scene, blockers = load_scene("procedural:3", None, None, None)
    prev_cam, cam = sample_viewpoints(scene, 1, seed=0, profile="slow", blockers=blockers, aspect=w / h)[0]
    out = {}
    with Adapter.frame_source(scene, w, h) as source:
        frame = source.frame(cam, prev_cam)
        for name in sdk.shipped_models():
            predictor = sdk.load(name)
            with Adapter.for_predictor(predictor, w, h, **source.adapter_options()) as adapter:
                x = adapter.inputs(frame)
                if x.shape != (len(predictor.metadata.inputs), h, w) or not np.isfinite(x).all():
                    raise SystemExit(f"{name}: the adapter gave {x.shape} with non-finite values")
                prev_depth = adapter.gbuffers(frame.scene, frame.prev_pose, camera=frame.prev_camera, albedo=False,
                                              normals=()).depth
                cached = type(frame)(**{**vars(frame), "prev_depth": prev_depth})
                loop = median_ms(lambda a=adapter, f=cached: a.inputs(f), repeats)

                def first(a: Adapter = adapter) -> None:
                    a._last = None  # (forget the cached depth: a first frame)
                    a.inputs(frame)

                out[name.removesuffix(".onnx")] = (loop, median_ms(first, repeats))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=frame_sizes(16), default=[(640, 360), (1280, 720)],
                    help="comma-separated WIDTHxHEIGHT (default 640x360,1280x720)")
    ap.add_argument("--repeats", type=positive, default=5)
    args = ap.parse_args()
    print(f"pyrender adapter, Adapter.inputs, median of {args.repeats}; {cpu_description()}\n")
    rows = {f"{w}x{h}": time_size(w, h, args.repeats) for w, h in args.sizes}
    print("| model | planes | " + " | ".join(f"{s} frame loop (ms) | {s} first frame (ms)" for s in rows) + " |")
    print("|---|---:|" + "---:|---:|" * len(rows))
    for name in next(iter(rows.values())):
        planes = len(sdk.load(name).metadata.inputs)
        print(f"| {name} | {planes} | " + " | ".join(f"{t[name][0]:.1f} | {t[name][1]:.1f}" for t in rows.values())
              + " |")


if __name__ == "__main__":
    run_main(main)
