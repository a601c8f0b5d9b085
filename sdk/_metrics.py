"""Metric facts every room shares: what each metric measures, its units, which direction is better,
and the PSNR <-> mean-squared-error conversion (targets store PSNR tiles as MSE)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike

from ._color import as_numbers

__all__ = ["METRICS", "METRIC_NAME_PATTERN", "TARGET_METRICS", "MetricInfo", "mse_from_psnr", "psnr_from_mse"]


@dataclass(frozen=True)
class MetricInfo:
    """Description of one per-tile metric.

    Attributes:
        name: the key used everywhere (model metadata, ``tile_targets``, the CLI).
        higher_is_better: True for similarity metrics (PSNR), False for error metrics.
        units: unit of the per-tile value.
        value_range: ``(low, high)`` of per-tile values; ``math.inf`` where unbounded.
        pooling: how the per-pixel map becomes a tile value (``"max"``, or ``"mse"`` for PSNR:
            mean squared error over the tile, then dB).
        weber: whether the map is divided by the local reference luma plus ``weber_l``.
        description: one line.
        default_threshold: the starting threshold (metric units) a newly trained model records as its
            ``default_threshold``. JNYang 0.25 and JNFLIP 0.2 are the paper code's values; PSNR 35 dB,
            FLIP 0.15 and LPIPS 0.1 sit at or below the mean training target of the shipped models'
            data. Tune them on validation data for another renderer.
    """

    name: str
    higher_is_better: bool
    units: str
    value_range: tuple[float, float]
    pooling: str
    weber: bool
    description: str
    default_threshold: float


_ALL = (
    MetricInfo("flip", False, "FLIP error", (0.0, 1.0), "max", False, "LDR-FLIP (flip-evaluator), max over the tile", 0.15),
    MetricInfo(
        "jnflip",
        False,
        "FLIP error / (luma + l)",
        (0.0, math.inf),
        "max",
        True,
        "FLIP divided by the 4x4 mean reference luma plus l, max over the tile",
        0.2,
    ),
    MetricInfo(
        "psnr",
        True,
        "dB",
        (0.0, math.inf),
        "mse",
        False,
        "PSNR (peak 1) of the tile's mean squared error; +inf if identical",
        35.0,
    ),
    MetricInfo(
        "lpips",
        False,
        "LPIPS distance",
        (0.0, math.inf),
        "max",
        False,
        "LPIPS-alex v0.1 spatial map, max over the tile",
        0.1,
    ),
    MetricInfo(
        "yang", False, "display luma", (0.0, 1.0), "max", False, "|luma(ref) - luma(test)|, Rec.601, max over the tile",
        0.02,
    ),
    MetricInfo(
        "jnyang",
        False,
        "luma / (luma + l)",
        (0.0, math.inf),
        "max",
        True,
        "Yang divided by the 4x4 mean reference luma plus l, max over the tile",
        0.25,
    ),
)

#: Every metric rtp knows, by name. A model's metadata may name another metric (a user's own), but
#: must then state ``higher_is_better`` itself.
METRICS: Mapping[str, MetricInfo] = MappingProxyType({m.name: m for m in _ALL})
#: A metric's name, in model metadata and for a user's own metric (``rtp.metrics.Metric``): lower-case
#: letters, digits and underscores, starting with a letter (a regular expression, matched whole).
METRIC_NAME_PATTERN = r"[a-z][a-z0-9_]*"
#: The metrics rtp computes targets for and ships models of (the paper's five), in that order.
TARGET_METRICS: tuple[str, ...] = ("flip", "psnr", "lpips", "jnflip", "jnyang")


def psnr_from_mse(mse: ArrayLike) -> np.ndarray:
    """PSNR in dB for a peak of 1: ``-10 log10(mse)``; ``+inf`` where ``mse == 0``, ``0.0`` where ``mse == 1``
    (black against white). float32. A negative MSE is an :class:`InputError` (it was NaN, with numpy's warning)."""
    a = as_numbers(mse, "psnr_from_mse", np.float64)
    if (a < 0).any():  # (a NaN with numpy's "invalid value in log10" warning: no PSNR has a negative MSE)
        from ._errors import InputError

        raise InputError(f"psnr_from_mse: expected mean squared errors >= 0, got {int((a < 0).sum())} negative, down "
                         f"to {float(a.min()):g}")
    with np.errstate(divide="ignore"):
        # (+ 0.0: -10 * log10(1) is -0.0, which printed as '-0' dB; every other value is unchanged by it)
        return (-10.0 * np.log10(a) + 0.0).astype(np.float32)


def mse_from_psnr(psnr: ArrayLike) -> np.ndarray:
    """Mean squared error (peak 1) of a PSNR in dB: ``10 ** (-psnr / 10)``; 0 where ``psnr == +inf``. float64."""
    return np.power(10.0, -as_numbers(psnr, "mse_from_psnr", np.float64) / 10.0)
