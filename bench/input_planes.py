"""Benchmark ``sdk.input_planes``: what a CPU adapter pays per frame for each shipped model's planes.

    python bench/input_planes.py [--sizes 1280x720,1920x1080] [--repeats 5]

An engine that reads its G-buffers back to the host makes a model's input planes with one call
(docs/runtime.md "Input planes from G-buffers on the host"); the pyrender adapter does the same after
drawing its G-buffers. This times that call, for the channels of every shipped model, on a frame of
the built-in procedural scene drawn by the reference renderer at each size (the reprojection's cost
follows the geometry), next to ``predict`` of the same model on the planes it made (the network, for
scale), and ``sdk.reproject`` alone, the most of the call. The moderngl adapter builds the same planes
in a shader instead (``bench/adapter.py``).
Prints a Markdown table of medians (ms).
"""

from __future__ import annotations

import argparse
from functools import partial
from typing import Any

import numpy as np
from _common import cpu_description, frame_sizes, median_ms, positive, run_main  # bench/ is on sys.path as a script

from rtp import sdk


def gbuffers(w: int, h: int) -> dict[str, Any]:
    """A frame of the procedural scene as ``sdk.input_planes`` takes it (the renderer's G-buffers)."""
    from rtp.capture import load_scene
    from rtp.capture.viewpoints import sample_viewpoints
    from rtp.plugins.moderngl import Renderer

    scene, blockers = load_scene("procedural:0", None, None, None)
    prev_cam, cam = sample_viewpoints(scene, 1, seed=0, profile="fast", blockers=blockers, aspect=w / h)[0]
    with Renderer(w, h) as r:
        r.load_scene(scene)
        prev = r.render(prev_cam)
        cur = r.render(cam, prev)
    return {"depth": cur.depth, "albedo": cur.albedo, "normal": cur.normal, "roughness": cur.roughness,
            "metallic": cur.metallic, "specular": cur.specular, "view": cam.view(),
            "projection": cam.projection(w / h), "prev_colour": prev.colour["1x1"], "prev_depth": prev.depth,
            "prev_view_projection": prev_cam.view_projection(w, h)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=frame_sizes(16), default=[(1280, 720), (1920, 1080)],
                    help="comma-separated WIDTHxHEIGHT (default 1280x720,1920x1080)")
    ap.add_argument("--repeats", type=positive, default=5)
    args = ap.parse_args()
    models = {name.removesuffix(".onnx"): sdk.load(name) for name in sdk.shipped_models()}
    print(f"rtp {sdk.__version__}, numpy {np.__version__}, {cpu_description()}, median of {args.repeats}\n")
    sizes = [f"{w}x{h}" for w, h in args.sizes]
    print("| model | planes | " + " | ".join(f"input_planes {s} | predict {s}" for s in sizes) + " |")
    print("|---|---:|" + "---:|---:|" * len(sizes))
    frames = {(w, h): gbuffers(w, h) for w, h in args.sizes}
    for name, predictor in models.items():
        cells = []
        for size in args.sizes:
            g = frames[size]
            inputs = predictor.metadata.inputs
            x = sdk.input_planes(inputs, **g)
            cells += [median_ms(partial(sdk.input_planes, inputs, **g), args.repeats),
                      median_ms(partial(predictor.predict, x), args.repeats)]
        print(f"| {name} | {len(predictor.metadata.inputs)} | " + " | ".join(f"{v:.1f}" for v in cells) + " |")
    cells = []
    for size in args.sizes:  # the reprojection alone, the most of each call (reprojected.*, seen)
        g = frames[size]
        cells += [median_ms(partial(sdk.reproject, g["prev_colour"], g["prev_depth"], g["depth"], g["view"],
                                    g["projection"], g["prev_view_projection"]), args.repeats), None]
    print("| (sdk.reproject alone) | 4 | " + " | ".join("" if v is None else f"{v:.1f}" for v in cells) + " |")


if __name__ == "__main__":
    run_main(main)
