"""Per-tile training/evaluation targets for all reduced rates of one frame."""

from __future__ import annotations

import logging
import os
import re
import time
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np

from rtp.sdk import (
    DEFAULT_TILE_SIZE,
    METRICS,
    PREDICTED_RATES,
    TARGET_METRICS,
    InputShapeError,
    luma,
    psnr_from_mse,
    tile_grid,
)

from ._deps import install_hint
from ._device import DEVICES, resolve_device
from ._errors import MetricDependencyError, MetricParameterError
from ._flip import DEFAULT_PPD, Ppd, flip_map, flip_pixels, image_ppd
from ._image import as_batch
from ._lpips import _check_quirk, _check_size, lpips_against, lpips_map, lpips_network
from ._maps import jnflip_map, jnyang_map, psnr_tiles, yang_map
from ._plugins import plugin
from ._pool import DEFAULT_WEBER_L, _check_tile, _denominator, check_weber_l, pool_tiles

if TYPE_CHECKING:  # (for a type checker only: importing rtp.metrics never imports torch)
    import torch
    from torch import Tensor

__all__ = ["FLIP_BACKENDS", "error_map", "tile_metric", "tile_targets"]

log = logging.getLogger("rtp.metrics")



def _check_metric(metric: str) -> str:
    plugin(metric)  # (an unknown name: MetricParameterError listing the known ones)
    return metric


@overload
def error_map(metric: str, reference: np.ndarray, test: np.ndarray | Tensor, *, ppd: Ppd = ..., weber_l: float = ...,
              lpips_paper_quirk: bool = ...) -> np.ndarray: ...
@overload
def error_map(metric: str, reference: Tensor, test: np.ndarray | Tensor, *, ppd: Ppd = ..., weber_l: float = ...,
              lpips_paper_quirk: bool = ...) -> Tensor: ...
def error_map(
    metric: str,
    reference: Any,
    test: Any,
    *,
    ppd: Ppd = DEFAULT_PPD,
    weber_l: float = DEFAULT_WEBER_L,
    lpips_paper_quirk: bool = False,
) -> Any:
    """Per-pixel map of ``metric`` (``flip``, ``jnflip``, ``lpips``, ``yang``, ``jnyang``, or a plugin
    metric's, :class:`~rtp.metrics.Metric`, of numpy frames).

    PSNR has no per-pixel map (it is defined per tile): use :func:`tile_metric` or
    :func:`~rtp.metrics.psnr_tiles`. Shapes and containers as in the individual map functions.
    """
    own = plugin(metric)
    if own is not None:
        ref, tst = _plugin_frame(reference, "reference"), _plugin_frame(test, "test")
        if ref.shape != tst.shape:
            raise InputShapeError(f"test has shape {tst.shape}, expected the reference's {ref.shape}",
                                  actual=tst.shape, expected=str(ref.shape))
        return own.map(ref, tst)
    if metric == "flip":
        return flip_map(reference, test, ppd=ppd)
    if metric == "jnflip":
        return jnflip_map(reference, test, ppd=ppd, weber_l=weber_l)
    if metric == "lpips":
        _check_quirk(lpips_paper_quirk, "lpips_paper_quirk")
        return lpips_map(reference, test, paper_quirk=lpips_paper_quirk)
    if metric == "yang":
        return yang_map(reference, test)
    if metric == "jnyang":
        return jnyang_map(reference, test, weber_l=weber_l)
    raise MetricParameterError("psnr has no per-pixel map; use tile_metric('psnr', ...) or psnr_tiles")


@overload
def tile_metric(metric: str, reference: np.ndarray, test: np.ndarray | Tensor, tile: int = ..., *, ppd: Ppd = ...,
                weber_l: float = ..., lpips_paper_quirk: bool = ...) -> np.ndarray: ...
@overload
def tile_metric(metric: str, reference: Tensor, test: np.ndarray | Tensor, tile: int = ..., *, ppd: Ppd = ...,
                weber_l: float = ..., lpips_paper_quirk: bool = ...) -> Tensor: ...
def tile_metric(
    metric: str,
    reference: Any,
    test: Any,
    tile: int = DEFAULT_TILE_SIZE,
    *,
    ppd: Ppd = DEFAULT_PPD,
    weber_l: float = DEFAULT_WEBER_L,
    lpips_paper_quirk: bool = False,
) -> Any:
    """Per-tile value of ``metric``: the map max-pooled over ``tile x tile`` tiles (PSNR: from the tile MSE; a
    plugin metric: pooled as it says, of numpy frames).

    Returns ``(ceil(H/tile), ceil(W/tile))`` (or with a leading N) float32.
    """
    own = plugin(metric)
    _check_tile(tile)  # (before the map is computed, not after seconds of FLIP or LPIPS)
    if own is not None:
        return pool_tiles(error_map(metric, reference, test), tile, own.pooling)
    if metric == "psnr":
        return psnr_tiles(reference, test, tile)
    m = error_map(metric, reference, test, ppd=ppd, weber_l=weber_l, lpips_paper_quirk=lpips_paper_quirk)
    return pool_tiles(m, tile, "max")


def _plugin_frame(image: Any, name: str) -> np.ndarray:
    """One numpy ``(H, W, 3)`` frame in [0, 1] for a plugin metric's map (which takes numpy), float32."""
    batch = as_batch(image, name)
    if batch.batched or batch.device is not None:
        raise InputShapeError(f"{name}: a plugin metric's map takes one numpy (H, W, 3) frame, got "
                              f"{type(image).__name__} {tuple(getattr(image, 'shape', ()))}",
                              actual=tuple(getattr(image, "shape", ())), expected="(H, W, 3)")
    return np.ascontiguousarray(batch.data[0], dtype=np.float32)


#: FLIP implementations :func:`tile_targets` can use (``flip_backend``).
FLIP_BACKENDS = ("torch", "flip-evaluator")


def _flip_backend(backend: str | None) -> str:
    if backend is None:
        try:
            import torch  # noqa: F401
        except ImportError:
            return "flip-evaluator"
        return "torch"
    if backend not in FLIP_BACKENDS:
        raise MetricParameterError(f"flip_backend must be one of {', '.join(FLIP_BACKENDS)} or None, got {backend!r}")
    return backend


def _check_flip_torch(names: Iterable[str], backend: str) -> None:
    """The torch FLIP port asked for FLIP without torch installed: a :class:`MetricDependencyError` naming the
    install and the other backend (it was a bare ModuleNotFoundError from inside the port, or from the device)."""
    if backend != "torch" or not {"flip", "jnflip"} & set(names):
        return
    try:
        import torch  # noqa: F401
    except ImportError as exc:
        raise MetricDependencyError(
            "flip_backend='torch' needs torch, or pass flip_backend='flip-evaluator' (or None, which picks it when "
            f"torch is missing): {install_hint('torch')}"
        ) from exc


def targets_device(metrics: Iterable[str], device: str | None, flip_backend: str | None = None) -> torch.device | None:
    """The ``torch.device`` :func:`tile_targets` runs the torch work of ``metrics`` on (FLIP's port
    with the torch ``flip_backend``, LPIPS), or None where there is none or ``device`` is None.
    Raises :class:`MetricParameterError` as it would: a name that is no device, a device this torch
    cannot use (checked only where torch work is asked for: the numpy metrics need no torch), FLIP
    through ``flip-evaluator`` asked to run on a GPU; and :class:`MetricDependencyError` for FLIP through the
    torch backend without torch installed. A job checks its device with it before any work."""
    names = {_check_metric(m) for m in ([metrics] if isinstance(metrics, str) else metrics)}
    backend = _flip_backend(flip_backend)
    _check_flip_torch(names, backend)
    if device is None:
        return None
    if not isinstance(device, str) or not (device in DEVICES or re.fullmatch(r"cuda:\d+", device)):
        raise MetricParameterError(f"device: expected {', '.join(DEVICES)} or cuda:N, got {device!r}", "device")
    if backend == "flip-evaluator" and device not in ("cpu", "auto") and {"flip", "jnflip"} & names:
        raise MetricParameterError(f"device {device!r}: flip-evaluator runs FLIP on the CPU; the torch backend "
                                   f"(flip_backend='torch') runs it on a GPU", "device")
    if "lpips" in names or (backend == "torch" and {"flip", "jnflip"} & names):
        return resolve_device(device)
    return None


def _flip_all(reference: np.ndarray, tests: Mapping[str, np.ndarray], ppd: float, backend: str,
              device: Any = None) -> dict[str, np.ndarray]:
    """LDR-FLIP maps of every test image against one reference: the batched torch port of FLIP.h
    (reference work once, see ``_flipbatch``; on ``device``) or ``flip-evaluator`` image by image."""
    if backend == "flip-evaluator":
        return {rate: flip_pixels(reference, img, ppd) for rate, img in tests.items()}
    from ._flipbatch import FlipReference

    maps = FlipReference(reference, ppd, device).maps(np.stack(list(tests.values())))
    return dict(zip(tests, maps))


def tile_targets(
    reference: np.ndarray,
    images_by_rate: Mapping[str, np.ndarray],
    metrics: Iterable[str] = TARGET_METRICS,
    tile: int = DEFAULT_TILE_SIZE,
    *,
    ppd: Ppd = DEFAULT_PPD,
    weber_l: float = DEFAULT_WEBER_L,
    lpips_paper_quirk: bool = False,
    lpips_weights: str | os.PathLike[str] | None = None,
    missing: Literal["error", "nan"] = "error",
    flip_backend: str | None = None,
    device: str | None = None,
) -> dict[str, np.ndarray]:
    """Per-tile values of several metrics for every reduced rate of one frame.

    Each map is computed once per rate and shared: FLIP feeds both ``flip`` and ``jnflip``, the
    luma difference both ``yang`` and ``jnyang``; the reference's luma, Weber denominator, LPIPS
    features and FLIP filtering (filtered colours, edges and points) are computed once per call,
    and the six rates go through FLIP as one batch.

    Args:
        reference: the 1x1-rate frame, numpy ``(H, W, 3)`` float in [0, 1] (display-encoded sRGB).
        images_by_rate: the same frame rendered at reduced rates, keyed by rate name
            (``"1x2"``, ``"2x1"``, ``"2x2"``, ``"2x4"``, ``"4x2"``, ``"4x4"``), each like ``reference``.
        metrics: names from :data:`rtp.sdk.METRICS`, or plugin metrics' (:class:`~rtp.metrics.Metric`).
        tile: tile side in pixels; edge tiles of frames that are not a multiple pool their real pixels.
        ppd: FLIP pixels per degree, a number or ``"width"`` (see :func:`~rtp.metrics.flip_map`).
        weber_l: environment luminance l of the JN metrics.
        lpips_paper_quirk: feed LPIPS [0, 1] unscaled as the paper's code did (see :func:`~rtp.metrics.lpips_map`).
        lpips_weights: alternative LPIPS weights pickle.
        missing: ``"error"`` (default) requires all six rates; ``"nan"`` fills absent rates with NaN.
        flip_backend: ``"torch"``, a batched port of ``flip-evaluator``'s C++ LDR-FLIP that does the
            reference's half once (equal to it within float32 round-off, about 2e-5 per pixel, and
            three times as fast per sample); ``"flip-evaluator"``, NVIDIA's package image by image;
            ``None`` (default) picks ``"torch"`` when torch is installed.
        device: where the torch work runs, FLIP's port and LPIPS (:func:`~rtp.metrics.resolve_device`:
            ``"auto"``, ``"cpu"``, ``"cuda"``, ``"cuda:N"``, ``"mps"``); ``None`` (default): the CPU.
            The other metrics are numpy's, on the CPU. A GPU gives the CPU's targets to float32
            round-off (docs/dataset.md "Targets on a GPU").

    Returns:
        ``{metric: float32 array (6, ceil(H/tile), ceil(W/tile))}``, axis 0 in
        :data:`rtp.sdk.PREDICTED_RATES` order. PSNR is ``+inf`` on identical tiles.
    """
    if not isinstance(metrics, (str, list, tuple)):
        raise MetricParameterError(f"metrics: expected a metric name or a list of them, got {type(metrics).__name__}")
    if not isinstance(images_by_rate, Mapping):
        raise MetricParameterError(f"images_by_rate: expected a mapping of rate names to images, got "
                                   f"{type(images_by_rate).__name__}")
    names = list(dict.fromkeys(_check_metric(m) for m in ([metrics] if isinstance(metrics, str) else metrics)))
    if not names:
        raise MetricParameterError("metrics is empty")
    backend = _flip_backend(flip_backend)
    dev = targets_device(names, device, backend)
    if missing not in ("error", "nan"):
        raise MetricParameterError(f"missing must be 'error' or 'nan', got {missing!r}")
    tile = _check_tile(tile)  # (sdk.tile_grid's ParameterError named "tile_size", not this function's argument)
    ref = as_batch(reference, "reference")
    if ref.batched or ref.device is not None:
        raise InputShapeError(
            "tile_targets takes one numpy (H, W, 3) reference frame",
            actual=tuple(reference.shape),
            expected="(H, W, 3)",
        )
    unknown = [r for r in images_by_rate if r not in PREDICTED_RATES]
    if unknown:
        raise MetricParameterError(f"unknown rate(s) {unknown}; expected keys from {', '.join(PREDICTED_RATES)}")
    absent = [r for r in PREDICTED_RATES if r not in images_by_rate]
    if absent and missing == "error":
        raise MetricParameterError(f"missing images for rate(s) {absent} (pass missing='nan' to leave them NaN)")
    plugins = {m: p for m in names if (p := plugin(m)) is not None}
    jn = any(m in METRICS and METRICS[m].weber for m in names)
    if jn:
        check_weber_l(weber_l)
    h, w = ref.shape_hw
    th, tw = tile_grid(h, w, tile)
    ppd_value = image_ppd(ppd, w) if {"flip", "jnflip"} & set(names) else DEFAULT_PPD
    if "lpips" in names:
        _check_quirk(lpips_paper_quirk, "lpips_paper_quirk")
        _check_size(ref)
        lpips_network(lpips_weights)  # (a bad weights path failed after the six rates' FLIP; the network is cached)

    gt = ref.data[0]
    tests: dict[str, np.ndarray] = {}
    for rate in PREDICTED_RATES:
        if rate in images_by_rate:
            batch = as_batch(images_by_rate[rate], f"images_by_rate[{rate!r}]")
            if batch.batched or batch.device is not None or batch.data.shape != ref.data.shape:
                raise InputShapeError(
                    f"images_by_rate[{rate!r}] has shape {tuple(images_by_rate[rate].shape)}, "
                    f"expected the reference's {tuple(reference.shape)}",
                    actual=tuple(images_by_rate[rate].shape),
                    expected=str(tuple(reference.shape)),
                )
            tests[rate] = batch.data[0]

    out = {m: np.full((len(PREDICTED_RATES), th, tw), np.nan, dtype=np.float32) for m in names}
    timings: dict[str, float] = dict.fromkeys(names, 0.0)
    # Shared per frame; empty arrays (never read) when no metric needs them.
    y_ref = luma(gt) if {"yang", "jnyang"} & set(names) else np.zeros(0, np.float32)
    denom = _denominator(gt, check_weber_l(weber_l)) if jn else np.zeros(0, np.float32)
    flips: dict[str, np.ndarray] = {}
    if ("flip" in names or "jnflip" in names) and tests:
        t0 = time.perf_counter()
        flips = _flip_all(gt, tests, ppd_value, backend, dev)
        timings["flip" if "flip" in names else "jnflip"] += time.perf_counter() - t0
    for rate, img in tests.items():
        i = PREDICTED_RATES.index(rate)
        if flips:
            t0 = time.perf_counter()
            flip = flips[rate]
            if "flip" in names:
                out["flip"][i] = pool_tiles(flip, tile, "max")
            if "jnflip" in names:
                out["jnflip"][i] = pool_tiles(flip / denom, tile, "max")
            timings["flip" if "flip" in names else "jnflip"] += time.perf_counter() - t0
        if "psnr" in names:
            t0 = time.perf_counter()
            d = gt - img
            out["psnr"][i] = psnr_from_mse(pool_tiles((d * d).mean(axis=-1), tile, "mean"))
            timings["psnr"] += time.perf_counter() - t0
        if "yang" in names or "jnyang" in names:
            t0 = time.perf_counter()
            err = np.abs(y_ref - luma(img))
            if "yang" in names:
                out["yang"][i] = pool_tiles(err, tile, "max")
            if "jnyang" in names:
                out["jnyang"][i] = pool_tiles(err / denom, tile, "max")
            timings["yang" if "yang" in names else "jnyang"] += time.perf_counter() - t0
        for name, own in plugins.items():
            t0 = time.perf_counter()
            out[name][i] = pool_tiles(own.map(gt, img), tile, own.pooling)
            timings[name] += time.perf_counter() - t0
    if "lpips" in names and tests:
        t0 = time.perf_counter()
        maps = lpips_against(gt, list(tests.values()), paper_quirk=lpips_paper_quirk, weights=lpips_weights,
                             device=dev)
        for rate, m in zip(tests, maps):
            out["lpips"][PREDICTED_RATES.index(rate)] = pool_tiles(m, tile, "max")
        timings["lpips"] += time.perf_counter() - t0
    log.debug(
        "tile_targets %dx%d tile %d, %d rate(s): %s",
        w,
        h,
        tile,
        len(tests),
        ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in timings.items()),
    )
    return out
