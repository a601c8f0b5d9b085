"""Benchmark the moderngl adapter: the time to build each shipped model's inputs on the GPU.

    .venv/bin/python bench/adapter.py [--sizes 1280x720,1920x1080] [--repeats 5] [--models models]

Renders one frame of bench/render.py's room after another (so the previous frame is there to
reproject), then times ``Adapter.inputs`` (render the input planes and read them back, ``(C, H, W)``
float32) for the channel list of every ``*.onnx`` in ``--models``, and for the renderer's own
reprojection (``reprojected.rgb`` + ``seen``). Each adapter compiles its shader for its channels
(``adapter_fs.glsl``), so the cost follows what the channels need: the ``.blocks`` planes read a
4x4 cell's lumas per value pixel, the ``.tiles`` planes a 16x16 tile's, and cost the most. On Mesa's
llvmpipe this is CPU time; a GPU runs the same shader in well under a millisecond. The render
(``Adapter.run`` until the GL finishes) is timed apart: the rest of ``inputs`` is the read-back, GL
handing the targets over and their copy into ``(C, H, W)``, which costs a CPU the same on any GPU.
Prints a markdown table (median ms of ``--repeats`` runs).
"""

from __future__ import annotations

import argparse
import platform
from dataclasses import fields
from pathlib import Path

import numpy as np
from _common import frame_sizes, median_ms, positive, run_main  # bench/ is on sys.path when run as a script
from render import build_scene

from rtp import sdk
from rtp.plugins.moderngl import Adapter, GBufferTextures, Renderer
from rtp.plugins.moderngl._glio import read_planes, read_texture, write_texture
from rtp.scene import Camera

REPROJECTION = ("reprojected.r", "reprojected.g", "reprojected.b", "seen")


def channel_lists(models: Path) -> dict[str, tuple[str, ...]]:
    """The renderer's reprojection and each model's input channels, by name."""
    lists = {"reprojection (renderer)": REPROJECTION}
    for path in sorted(models.glob("*.onnx")):
        lists[path.stem] = tuple(sdk.load(path).metadata.inputs)
    return lists


def engine_frame(r: Renderer) -> GBufferTextures:
    """Two frames of bench/render.py's room rendered by ``r``, the second's G-buffers and the first's
    colour and depth left in ``r``'s textures as an engine's would be: what the adapter reads."""
    width, height = r.width, r.height
    cams = [Camera((-1.0 + 0.1 * i, 1.7, 8.0 - 0.05 * i), yaw=-8.0 + 1.5 * i, pitch=-6.0) for i in range(2)]
    r.load_scene(build_scene())
    prev = r.render(cams[0])
    cur = r.render(cams[1], prev)
    # The renderer's own textures as an engine's G-buffers (private names: a benchmark, not an API).
    write_texture(r._t_prev_colour, prev.colour["1x1"])
    write_texture(r._t_prev_depth, prev.depth)
    return GBufferTextures(
        albedo=r._t_albedo, normal=r._t_nd, depth=r._t_nd, depth_component=3,
        view=cur.camera.view(), projection=cur.camera.projection(width / height),
        prev_colour=r._t_prev_colour, prev_depth=r._t_prev_depth,
        prev_view_projection=prev.camera.view_projection(width, height), material=r._t_material)


def joined_read_back(adapter: Adapter) -> np.ndarray:
    """The read-back before 2026-12-06: each target read as an image (flipped), the targets joined, then
    transposed to ``(C, H, W)``: four passes over the planes where ``read_planes`` makes one."""
    planes = np.concatenate([read_texture(t) for t in adapter._targets], axis=2)
    return np.ascontiguousarray(planes[..., : len(adapter.channels)].transpose(2, 0, 1))


def time_size(width: int, height: int, lists: dict[str, tuple[str, ...]],
              repeats: int) -> dict[str, tuple[float, float, float, float]]:
    """Median ms of ``Adapter.inputs``, of its render alone (``run`` until the GL finishes), of its read-back
    alone and of the read-back before 2026-12-06, per channel list at one frame size."""
    out: dict[str, tuple[float, float, float, float]] = {}
    with Renderer(width, height) as r:
        frame = engine_frame(r)
        textures = {f.name: getattr(frame, f.name) for f in fields(frame)}
        for name, channels in lists.items():
            with Adapter(channels, width, height, ctx=r.ctx) as adapter:
                x = adapter.inputs(frame)
                if x.shape != (len(channels), height, width) or not np.isfinite(x).all():
                    raise SystemExit(f"{name}: the adapter gave {x.shape} with non-finite values; expected "
                                     f"{(len(channels), height, width)} finite planes")
                if not np.array_equal(joined_read_back(adapter), x):
                    raise SystemExit(f"{name}: the two read-backs differ")

                def render(a: Adapter = adapter) -> None:
                    a.run(**textures)
                    r.ctx.finish()

                # (the adapter's private targets: a benchmark of its read-back, not an API)
                out[name] = (median_ms(lambda a=adapter: a.inputs(frame), repeats), median_ms(render, repeats),
                             median_ms(lambda a=adapter: read_planes(a._fbo, len(a.channels), (width, height)),
                                       repeats),
                             median_ms(lambda a=adapter: joined_read_back(a), repeats))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=frame_sizes(4), default="1280x720,1920x1080", help="comma-separated WIDTHxHEIGHT")
    ap.add_argument("--repeats", type=positive, default=5)
    ap.add_argument("--models", type=Path, default=Path(__file__).resolve().parents[1] / "models",
                    help="folder of .onnx models whose channel lists to time (default: the shipped ones)")
    args = ap.parse_args()
    sizes = args.sizes
    if not args.models.is_dir() or not any(args.models.glob("*.onnx")):
        ap.error(f"--models: expected a folder of .onnx models, got {str(args.models)!r}")
    lists = channel_lists(args.models)
    with Renderer(16, 16) as probe:
        gl = probe.ctx.info["GL_RENDERER"]
    print(f"moderngl adapter, Adapter.inputs (render + read back), median of {args.repeats}; {gl}; "
          f"{platform.processor() or platform.machine()}\n")
    rows = {f"{w}x{h}": time_size(w, h, lists, args.repeats) for w, h in sizes}
    print("| channels | planes | " + " | ".join(f"{s} ms: inputs (render, read back; before)" for s in rows) + " |")
    print("|---|---|" + "---|" * len(rows))
    for name, channels in lists.items():
        cells = (f"{t[name][0]:.1f} ({t[name][1]:.1f}, {t[name][2]:.1f}; {t[name][3]:.1f})" for t in rows.values())
        print(f"| {name} | {len(channels)} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    run_main(main)
