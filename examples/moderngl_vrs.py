"""Variable-rate shading with the decision on the GPU: the moderngl path from G-buffers to VRS.

    python examples/moderngl_vrs.py                          # a walk through a procedural level, shipped JNYang
    python examples/moderngl_vrs.py --model flip --frames 12 --gif vrs.gif --out vrs.png
    python examples/moderngl_vrs.py --model jnyang-8px        # on AMD's and Intel's 8-pixel VRS tiles, trained on them
    python examples/moderngl_vrs.py --tile-size 8             # the same tiles, each taking its 16-pixel tile's rates
    python examples/moderngl_vrs.py --saving 0.6              # a budget: 60% of the work saved, the threshold on the GPU

What an engine on the GPU does each frame, with rtp's reference pieces standing in for its own:

1. The reference deferred renderer (``rtp.plugins.moderngl.Renderer``, through
   ``Adapter.frame_source``) draws the frame and leaves its G-buffers and the previous displayed frame
   in textures of its GL context, as an engine's G-buffer pass would.
2. The moderngl adapter builds the model's input planes from those textures in a fragment shader
   (reprojection, luma, the material planes, the ``.blocks`` variances: docs/adapters.md).
3. onnxruntime runs the network (``predictor.predict_raw``: here on the CPU; an engine binds its GPU
   provider's output buffer instead).
4. ``RateSelector`` decodes the prediction and picks each tile's rate in a compute shader
   (docs/runtime.md, "The decision on the GPU"): the shading-rate image, an ``r8ui`` texture. With
   ``--saving`` a second compute dispatch first finds the lowest threshold that saves that share of the work.
5. The renderer shades each tile at its rate (software VRS, then tone mapping and FXAA) and the
   overlay of the last frame is written to ``--out``; ``--gif`` writes every frame's overlay.

Each frame's line gives the work saved and checks the GPU's decision against
``predictor.shading_rates`` on the CPU (the same codes but where a value lies within float32
rounding of the threshold). Headless through Mesa's EGL; OpenGL 4.3 for the compute shader.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

from rtp import sdk
from rtp.capture import check_memory, save_image
from rtp.capture.scenes import procedural
from rtp.cli import frame_size, out_animation, out_image, run_guarded  # as rtp's commands take them; its error policy
from rtp.plugins.moderngl import Adapter, RateSelector, create_context
from rtp.scene import Camera
from rtp.sdk.files import atomic_output

log = logging.getLogger("moderngl_vrs")

#: This example's peak memory, measured (``python bench/job_memory.py --jobs examples``, 2026-12-04, on
#: Mesa's software GL: a hardware driver keeps the renderer's images on the GPU): bytes at any size,
#: bytes a pixel of ``--size``, and bytes a pixel for each frame of ``--gif`` (its overlays, kept until
#: the GIF is written).
PEAK_BASE, PEAK_PER_PIXEL, PEAK_PER_GIF_PIXEL = 190 * 2**20, 1000.0, 8.0


def peak_bytes(width: int, height: int, frames: int, gif: bool) -> int:
    """The peak bytes of a run at ``width`` x ``height`` with ``frames`` frames (``gif``: written as a GIF)."""
    return int(PEAK_BASE + width * height * (PEAK_PER_PIXEL + (frames * PEAK_PER_GIF_PIXEL if gif else 0.0)))


def walk_camera(position: tuple[float, float, float], yaw: float, i: int) -> Camera:
    """Frame ``i`` of a walk at 60 Hz from ``position``, looking ``yaw`` degrees at frame 0: 3 m/s forward along
    that first heading (``Camera.forward``: yaw 0 looks down -Z, positive yaw turns left), the view turning
    30 degrees a second to the left."""
    heading = Camera(position, yaw=yaw).forward
    step = 0.05 * i
    x, z = position[0] + step * heading[0], position[2] + step * heading[2]
    return Camera((x, position[1], z), yaw=yaw + 0.5 * i, pitch=-3.0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="jnyang", help="a shipped model's name or an rtp ONNX path (default: jnyang)")
    ap.add_argument("--out", type=out_image, default="moderngl_vrs.png", help="overlay PNG of the last frame")
    ap.add_argument("--gif", type=out_animation, help="also write every frame's overlay as an animated GIF (imageio)")
    ap.add_argument("--size", type=frame_size, default="640x360", help="WIDTHxHEIGHT, as rtp's commands take it")
    ap.add_argument("--frames", type=int, default=6, help="frames of the walk (default: 6)")
    ap.add_argument("--threshold", type=float, help="threshold (default: the model's)")
    ap.add_argument("--seed", type=int, default=3, help="procedural level seed")
    ap.add_argument("--tile-size", type=int, help="the hardware's shading-rate tile in pixels (default: the model's, "
                    "16 for the shipped ones, NVIDIA's, 8 for the -8px ones; 8: AMD's and Intel's)")
    ap.add_argument("--saving", type=float, help="a budget instead of a threshold: the share of the shading work to "
                    "save each frame (0-0.9375), the threshold found on the GPU; with --threshold, a floor under it")
    args = ap.parse_args(argv)
    args.out, args.gif = Path(args.out), None if args.gif is None else Path(args.gif)  # (checked: writable, a format)
    # what writes the pictures (rtp[capture]), imported before the walk: without it (rtp[moderngl] alone) the walk ran
    # to its end and then failed on imageio, which only --gif needs
    import PIL.Image  # noqa: F401 - save_image's
    if args.gif is not None:
        import imageio.v3  # noqa: F401
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if args.frames < 1:
        ap.error(f"--frames: expected at least 1, got {args.frames}")
    width, height = args.size
    need = peak_bytes(width, height, args.frames, args.gif is not None)  # refused now, not by the OOM killer later
    check_memory(need, f"the example at {width}x{height}" + (f" with a GIF of {args.frames} frames" if args.gif else "")
                 + f" holds about {need / 2**30:.1f} GiB", "size",
                 "of memory: a smaller --size" + (" or fewer --frames" if args.gif else ""), job="the example")

    predictor = sdk.load(args.model, tile_size=args.tile_size)
    log.info("model %s (%s), inputs %s", predictor.path, predictor.metadata.metric, ", ".join(predictor.metadata.inputs))
    threshold = predictor.metadata.default_threshold if args.threshold is None else \
        sdk.check_threshold(args.threshold, predictor.metadata.higher_is_better)  # refused now, not at frame 1
    floor = None if args.threshold is None else threshold  # (under a budget: the threshold given, if one was)
    if args.saving is not None:  # refused now too, with the SDK's message
        sdk.select_rates_for_saving(np.zeros((6, 1, 1)), args.saving, higher_is_better=predictor.metadata.higher_is_better)
    level = procedural(args.seed)
    spawn = level.spawn_points[0]

    def camera(i: int) -> Camera:
        return walk_camera(spawn.position, spawn.yaw, i)

    ctx = create_context(430)  # compute shaders
    overlays = []
    with Adapter.frame_source(level, width, height, ctx=ctx) as source, RateSelector(predictor, ctx) as selector:
        adapter = source.adapter(predictor.metadata.inputs)
        for i in range(1, args.frames + 1):
            frame = source.frame(camera(i), camera(i - 1))
            if i == 1:  # once, where an engine is wired up: its G-buffers in the conventions the adapter was told?
                for warning in adapter.check(frame):
                    log.warning("G-buffers: %s", warning)
            x = adapter.inputs(frame)                                          # 1-2: G-buffers -> planes
            raw = predictor.predict_raw(x)                                     # 3: the network
            t0 = time.perf_counter()
            # 4: the decision, on the GPU, one texel a hardware tile of the frame
            if args.saving is None:
                rates = selector.select(raw, threshold, grid=predictor.tiles(height, width))
            else:  # a budget: the threshold found on the GPU too
                rates = selector.select(raw, floor, grid=predictor.tiles(height, width), saving=args.saving,
                                        frame_size=(height, width))
            ms = 1e3 * (time.perf_counter() - t0)
            if args.saving is None:
                cpu = predictor.shading_rates(x, threshold)
            else:
                cpu = predictor.shading_rates(x, floor, saving=args.saving)
                log.info("frame %2d: the budget's threshold %.4g", i, selector.budget()[0])
            final = source.renderer.shade_rates(rates, selector.tile_size)     # 5: software VRS
            overlay = sdk.draw_rate_overlay(final, rates, selector.tile_size)  # float in [0, 1], as the frame
            if args.gif or i == args.frames:  # (without --gif only the last is written)
                overlays.append((np.clip(overlay, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))
            saved = sdk.work_saved(rates, (height, width), selector.tile_size)
            log.info("frame %2d: work saved %.1f%%, GPU decision = CPU decision on %d of %d tiles, decided in %.2f ms",
                     i, 100 * saved, int((rates == cpu).sum()), rates.size, ms)
    ctx.release()

    save_image(args.out, overlays[-1])  # atomic: an interrupted write leaves the file there before, not half of one
    log.info("wrote %s", args.out)
    if args.gif:
        import imageio.v3 as iio

        with atomic_output(args.gif) as tmp:  # (renamed over --gif once whole; the extension names the format)
            iio.imwrite(tmp, np.stack(overlays), extension=args.gif.suffix.lower(), duration=1000 / 15, loop=0)
        log.info("wrote %s (%d frames)", args.gif, len(overlays))
    return 0


if __name__ == "__main__":
    sys.exit(run_guarded(Path(__file__).name, main))  # an rtp error in one line, as the rtp commands print it
