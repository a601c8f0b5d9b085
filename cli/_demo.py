"""``rtp demo``: render a scene, predict per-tile error with a shipped model, shade each tile at the
rate it picked, and show what that costs and saves.

Everything runs locally with nothing downloaded: the built-in procedural scene (or a fetched map)
is drawn by the reference renderer over a short camera move, the model runs through ``sdk.load``
exactly as an engine would, and the true error comes from rendering every rate.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rtp import sdk

__all__ = ["DemoResult", "run_demo"]

log = logging.getLogger("rtp.demo")


@dataclass
class DemoResult:
    out: Path
    model: str
    metric: str
    threshold: float
    tiles: int
    tile_size: int
    work_saved: float
    rate_share: dict[str, float]
    over_threshold: float
    predict_ms: float
    predict_runs: int
    composite_flip_mean: float
    files: list[str]


def _camera_path(scene: Any, frames: int, blockers: Any, aspect: float, seed: int) -> list[Any]:
    """A short camera move: a valid viewpoint pair of the scene (the capture's sampler, fast profile),
    interpolated over ``frames`` frames. The yaw turns the short way round: the sampler wraps yaws to
    [-180, 180), so a pair across the wrap (179 and -178 degrees: about one seed in forty) turned 357
    degrees the long way, the shown frame's history looking the other way and every pixel unseen."""
    from rtp.capture.viewpoints import sample_viewpoints
    from rtp.scene import Camera

    prev, cur = sample_viewpoints(scene, 1, seed, "fast", blockers=blockers, aspect=aspect)[0]
    turn = (cur.yaw - prev.yaw + 180.0) % 360.0 - 180.0  # the signed turn, within half a circle
    if abs(cur.yaw - prev.yaw) <= 180.0:
        turn = cur.yaw - prev.yaw  # (as it was: the same cameras, bit for bit, where the pair does not wrap)
    cams = []
    for i in range(frames):
        t = i / max(frames - 1, 1)
        x, y, z = (float(a + t * (b - a)) for a, b in zip(prev.position, cur.position))
        cams.append(Camera((x, y, z), yaw=prev.yaw + t * turn, pitch=prev.pitch + t * (cur.pitch - prev.pitch),
                           fov_y=cur.fov_y))
    return cams


def _check_metric_installed(meta: sdk.ModelMetadata, path: Any) -> None:
    """Refuse a model whose metric is a plugin's that is not installed here, naming the model, its metric and the
    entry-point group (it said only "unknown metric", as of a name mistyped): the demo computes the true error with
    the metric. A plugin that is installed but fails to load is left to ``check_dependencies`` to name."""
    from importlib.metadata import entry_points

    from rtp import metrics

    if meta.metric in sdk.METRICS:
        return
    try:
        metrics.metric_info(meta.metric)
    except metrics.MetricParameterError:
        if entry_points(group=metrics.METRIC_ENTRY_POINT_GROUP, name=meta.metric):
            raise  # (installed, and broken: its own error names its entry point)
        recorded = meta.to_dict().get("provenance", {}).get("target_parameters")
        plugin = recorded.get("plugin") if isinstance(recorded, dict) else None
        defined = f" (the model was trained on its targets as defined by {plugin})" if isinstance(plugin, dict) \
            and plugin else ""
        raise metrics.MetricParameterError(
            f"{Path(str(path)).name}: the model's metric {meta.metric!r} is a plugin metric, not one of rtp's own "
            f"({', '.join(sdk.METRICS)}), and no plugin of that name is installed here{defined}; the demo computes "
            f"the true error with it: install the package that declares {meta.metric!r} in the "
            f"{metrics.METRIC_ENTRY_POINT_GROUP!r} entry-point group (docs/metrics.md \"Your own metric\"). rtp info "
            "and rtp evaluate read the model without it", "metric") from None


def run_demo(
    out: str | Path,
    *,
    model: str = "jnyang",
    threshold: float | None = None,
    scene: str = "procedural:0",
    size: tuple[int, int] = (1280, 720),
    frames: int = 3,
    cache_dir: str | None = None,
    seed: int = 0,
    timing_runs: int = 11,
    tile_size: int | None = None,
    metadata: Any = None,
    palette: str = "paper",
) -> DemoResult:
    """Run the demo and write its pictures into ``out``. ``predict`` is timed as the median of
    ``timing_runs`` runs after a warm-up. ``tile_size`` is the hardware's VRS tile when it differs from
    the model's (``sdk.load(..., tile_size=)``: 8 for AMD's and Intel's); the rates, the true error and
    the composite are then per hardware tile. ``metadata``: ``sdk.load``'s, for a model that carries none.
    ``palette``: the rate overlay's colours, ``"paper"`` or ``"cvd"`` (:func:`rtp.sdk.draw_rate_overlay`'s)."""
    from rtp import metrics
    from rtp.capture import check_frame_memory, load_scene, save_image
    from rtp.capture.paths import MAX_FRAMES, composite
    from rtp.evaluate import failing_tiles
    from rtp.evaluate.plots import heatmaps, rate_legend, rate_overlays, value_map
    from rtp.plugins.moderngl import Renderer

    if isinstance(frames, bool) or not isinstance(frames, int) or not 2 <= frames <= MAX_FRAMES:
        # (1 was taken and run as 2: the last frame needs the one before as its reprojected history)
        raise sdk.ParameterError(f"frames: expected an integer in [2, {MAX_FRAMES}] (the frame shown and at least "
                                 f"the one before it, its history), got {frames!r}", "frames")
    rate_legend(palette)  # (an unknown palette refused before the model is loaded and the scene rendered)
    predictor = sdk.load(model, tile_size=tile_size, metadata=metadata)
    meta = predictor.metadata
    tile = predictor.tile_size  # the hardware's tiles, which the rates are for
    # checked before any rendering, as every command checks a threshold (the SDK's range)
    thr = meta.default_threshold if threshold is None else sdk.check_threshold(threshold, meta.higher_is_better)
    _check_metric_installed(meta, predictor.path)
    metrics.check_dependencies((meta.metric, "flip"))  # the true error map and the FLIP picture, before rendering
    check_frame_memory("demo", size, metrics=(meta.metric,))  # (not the system's OOM killer, minutes in)
    out = Path(out)
    scn, blockers = load_scene(scene, cache_dir, None, None)
    out.mkdir(parents=True, exist_ok=True)  # (after the scene: a name it cannot load leaves no empty folder)
    w, h = size
    with Renderer(w, h) as renderer:
        renderer.load_scene(scn)
        prev = None
        for cam in _camera_path(scn, frames, blockers, w / h, seed):
            frame = renderer.render(cam, prev)
            prev = frame
    x = np.stack([frame.channel(c) for c in meta.inputs]).astype(np.float32)
    predicted = predictor.predict(x)  # warm-up: onnxruntime allocates on the first run
    times = []
    for _ in range(max(1, timing_runs)):
        t0 = time.perf_counter()
        predictor.predict(x)
        times.append((time.perf_counter() - t0) * 1000)
    predict_ms = float(np.median(times))
    rates = sdk.select_rates(predicted, thr, higher_is_better=meta.higher_is_better, factors=meta.rate_factors)
    ref = frame.colour["1x1"]
    images = {r: frame.colour[r] for r in sdk.PREDICTED_RATES}
    kw: dict[str, Any] = {}
    if meta.weber_l is not None:
        kw["weber_l"] = meta.weber_l
    true = metrics.tile_targets(ref, images, (meta.metric,), tile, **kw)[meta.metric]
    vrs = composite(frame.colour, rates, tile)
    flip = metrics.flip_map(ref, vrs)

    saved = sdk.work_saved(rates, (h, w), tile)  # pixel-weighted: edge tiles may be partial
    share = {r: float((rates == code).mean()) for r, code in sdk.RATE_CODES.items()}
    over = float(failing_tiles(rates, true, thr, meta.higher_is_better).mean())

    # Every picture is drawn before any is written: drawn between the writes (the figures take seconds at 1280x720),
    # a failure or Ctrl-C in one left this run's first pictures beside the last run's others, of another model or
    # scene, in the same folder. (Each file is written atomically.)
    pictures: dict[str, np.ndarray] = {"frame.png": ref}
    pictures["overlay.png"] = rate_overlays(ref, {Path(str(predictor.path)).stem: rates}, tile,
                                             palette=palette)
    # Heatmaps in metric units, bright = worse; the colour range ends at the threshold's double.
    # (PSNR is negated so that bright means worse there too.)
    if meta.higher_is_better:
        sign, vmin, vmax = -1.0, -(thr + 20.0), -(thr - 20.0)
    else:
        sign, vmin, vmax = 1.0, 0.0, 2.0 * thr
    units = metrics.metric_info(meta.metric).units  # (checked with its dependencies before rendering)
    pictures["predicted_vs_true.png"] = heatmaps(
        sign * true, sign * predicted, tile, (h, w), seen=frame.seen, vmin=vmin, vmax=vmax, scale=2,
        label=f"{'-' if sign < 0 else ''}{meta.metric} ({units}), bright = worse", threshold=sign * thr,
        title=f"{meta.metric} per {tile}px tile: true (rendered at every rate) and predicted by "
              f"{Path(str(predictor.path)).name}"
              + (f" ({meta.tile_size}px tiles, each split)" if tile < meta.tile_size else
                 f" (the worst of its {meta.tile_size}px tiles)" if tile > meta.tile_size else ""),
    )
    pictures["vrs_composite.png"] = vrs
    pictures["vrs_flip.png"] = value_map(flip, label="FLIP error (0 = identical, 1 = worst)",
                                         title="FLIP of the VRS composite against full-rate shading")
    for name, img in pictures.items():
        save_image(out / name, img)
    files = list(pictures)
    return DemoResult(out, str(predictor.path), meta.metric, thr, int(rates.size), tile, saved, share, over, predict_ms,
                      len(times), float(flip.mean()), files)
