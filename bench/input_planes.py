"""Benchmark ``sdk.input_planes``: what a CPU adapter pays per frame for each shipped model's planes.

    python bench/input_planes.py [--sizes 1280x720,1920x1080] [--repeats 5]
    python bench/input_planes.py --against REV [--sizes 1280x720,1920x1080] [--repeats 5] [--pairs 6]

An engine that reads its G-buffers back to the host makes a model's input planes with one call
(docs/runtime.md "Input planes from G-buffers on the host"); the pyrender adapter does the same after
drawing its G-buffers. This times that call, for the channels of every shipped model, on a frame of
the built-in procedural scene drawn by the reference renderer at each size (the reprojection's cost
follows the geometry), next to ``predict`` of the same model on the planes it made (the network, for
scale), and ``sdk.reproject`` alone, the most of the call. The moderngl adapter builds the same planes
in a shader instead (``bench/adapter.py``).
Prints a Markdown table of medians (ms).

``--against REV`` loads ``sdk/_reproject.py`` as it was at git revision ``REV`` and compares it with this
checkout's: ``reproject``'s time at each size, the two interleaved (medians), and its outputs on rendered
frames (``--pairs`` viewpoint pairs, 6 by default, of both camera profiles of three procedural scenes at three
sizes, tolerances 0, 0.02 and 0.2): the ``seen`` pixels that differ, the colours that differ where ``seen``
agrees, and the largest difference of ``reproject_positions``; then ``sdk.input_planes`` as a whole
(``sdk/_planes.py`` of ``REV`` over its ``sdk/_reproject.py``) for every shipped model's channels at each
size, timed the same way, and the planes that differ. Exits 1 if any ``seen`` pixel, colour or plane value
differs: a faster reprojection must give the same planes.
"""

from __future__ import annotations

import argparse
from functools import partial
from typing import Any

import numpy as np
from _common import (  # bench/ is on sys.path as a script
    cpu_description,
    frame_sizes,
    interleaved_ms,
    median_ms,
    module_at_revision,
    positive,
    run_main,
)

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


def _against(rev: str, sizes: list[tuple[int, int]], repeats: int, pairs: int) -> int:
    from rtp.capture import load_scene
    from rtp.capture.viewpoints import sample_viewpoints
    from rtp.plugins.moderngl import Renderer

    then = module_at_revision(rev, "sdk/_reproject.py", "rtp.sdk._reproject_then")
    print(f"sdk.reproject at {rev} and in this checkout; {cpu_description()}, median of {repeats}\n")
    print(f"| frame | {rev} ms | this checkout ms |\n|---|---:|---:|")
    for w, h in sizes:
        g = gbuffers(w, h)
        args = (g["prev_colour"], g["prev_depth"], g["depth"], g["view"], g["projection"], g["prev_view_projection"])
        times = interleaved_ms({"then": partial(then.reproject, *args), "now": partial(sdk.reproject, *args)},
                               repeats)
        print(f"| {w}x{h} | {np.median(times['then']):.1f} | {np.median(times['now']):.1f} |")
    pixels = seen_differ = colour_differ = 0
    position = 0.0
    for name, (w, h) in [("procedural:0", (320, 192)), ("procedural:3", (640, 360)), ("procedural:5", (97, 53))]:
        scene, blockers = load_scene(name, None, None, None)
        with Renderer(w, h) as r:
            r.load_scene(scene)
            for profile in ("slow", "fast"):
                for prev_cam, cam in sample_viewpoints(scene, pairs, seed=1, profile=profile, blockers=blockers,
                                                       aspect=w / h):
                    prev = r.render(prev_cam)
                    cur = r.render(cam, prev)
                    args = (prev.colour["1x1"], prev.depth, cur.depth, cam.view(), cam.projection(w / h),
                            prev_cam.view_projection(w, h))
                    for tolerance in (0.0, 0.02, 0.2):
                        (c0, s0), (c1, s1) = (m.reproject(*args, tolerance=tolerance) for m in (then, sdk))
                        pixels += s0.size
                        seen_differ += int((s0 != s1).sum())
                        colour_differ += int((c0 != c1)[s0 == s1].sum())
                    p0, p1 = then.reproject_positions(*args[2:]), sdk.reproject_positions(*args[2:])
                    position = max(position, *(float(np.abs(a - b).max()) for a, b in zip(p0, p1)))
    print(f"\n{pixels:,} pixels of rendered frames: seen differs on {seen_differ}, the colour where seen agrees on "
          f"{colour_differ} values; positions within {position:.3g} px")
    planes_then = module_at_revision(rev, "sdk/_planes.py", "rtp.sdk._planes_then",
                                     replace={"from ._reproject import": "from ._reproject_then import"})
    models = {name.removesuffix(".onnx"): sdk.load(name).metadata.inputs for name in sdk.shipped_models()}
    labels = [f"{w}x{h}" for w, h in sizes]
    print(f"\nsdk.input_planes at {rev} and in this checkout, the renderer's G-buffers as read back (RGBA textures' "
          f"channels), median of {repeats}\n")
    print("| model | planes | " + " | ".join(f"{rev} {s} | this checkout {s}" for s in labels) + " |")
    print("|---|---:|" + "---:|---:|" * len(labels))
    frames = [gbuffers(w, h) for w, h in sizes]
    values = planes_differ = 0
    for name, inputs in models.items():
        cells = []
        for g in frames:
            times = interleaved_ms({"then": partial(planes_then.input_planes, inputs, **g),
                                    "now": partial(sdk.input_planes, inputs, **g)}, repeats)
            cells += [np.median(times["then"]), np.median(times["now"])]
            a, b = planes_then.input_planes(inputs, **g), sdk.input_planes(inputs, **g)
            values += a.size
            planes_differ += int((a.view(np.uint32) != b.view(np.uint32)).sum())
        print(f"| {name} | {len(inputs)} | " + " | ".join(f"{v:.1f}" for v in cells) + " |")
    print(f"\n{values:,} plane values: {planes_differ} differ (to the bit)")
    return 1 if seen_differ or colour_differ or planes_differ else 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=frame_sizes(16), default=[(1280, 720), (1920, 1080)],
                    help="comma-separated WIDTHxHEIGHT (default 1280x720,1920x1080)")
    ap.add_argument("--repeats", type=positive, default=5)
    ap.add_argument("--against", metavar="REV", help="compare sdk.reproject with sdk/_reproject.py at git REV")
    ap.add_argument("--pairs", type=positive, default=None,
                    help="with --against: viewpoint pairs per scene and camera profile compared (default 6)")
    args = ap.parse_args()
    if args.pairs is not None and not args.against:
        ap.error("--pairs sets the frames --against compares: give --against REV")
    if args.against:
        raise SystemExit(_against(args.against, args.sizes, args.repeats, 6 if args.pairs is None else args.pairs))
    models = {name.removesuffix(".onnx"): sdk.load(name) for name in sdk.shipped_models()}
    print(f"rtp {sdk.__version__}, numpy {np.__version__}, {cpu_description()}, median of {args.repeats}\n")
    sizes = [f"{w}x{h}" for w, h in args.sizes]
    print("| model | planes | " + " | ".join(f"input_planes {s} (ms) | predict {s} (ms)" for s in sizes) + " |")
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
