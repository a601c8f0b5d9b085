"""Torch twins of ``rtp.sdk``'s numpy transforms and extrapolation, for training and evaluation.

They take the same :class:`rtp.sdk.Transform` parameters and are tested against the same vectors
(``tests/data/transform_vectors.json``), so a model trained here decodes identically at run time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from rtp.sdk import DEFAULT_EXTRAPOLATION_K, LOGIT_EPS, OUTPUT_SETS, ModelMetadata, Transform, complete_rates

__all__ = ["decode", "extrapolate", "forward", "inverse"]


def _sigmoid(x: float) -> float:
    """The logistic function as ``rtp.sdk`` computes it (through tanh: no overflow, where ``1 / (1 + exp(-x))``
    raised OverflowError past ``|x|`` 709, as a valid transform with ``k * mu_y`` that large has)."""
    return 0.5 * (1.0 + math.tanh(0.5 * x))


def _s_bounds(t: Transform) -> tuple[float, float]:
    s0 = _sigmoid(t.k * (0.0 - t.mu_y))  # type: ignore[operator]
    s1 = _sigmoid(t.k * (1.0 - t.mu_y))  # type: ignore[operator]
    return s0, s1


def forward(y: torch.Tensor, t: Transform) -> torch.Tensor:
    """Metric units to transformed space (the training target)."""
    if t.type == "clamped":
        return torch.clamp(y / (2.0 * t.mu_y), 0.0, 1.0)  # type: ignore[operator]
    if t.type == "logistic":
        s0, s1 = _s_bounds(t)
        return (torch.sigmoid(t.k * (y - t.mu_y)) - s0) / (s1 - s0)  # type: ignore[operator]
    return torch.clamp(y * t.factor + t.offset, 0.0, 1.0)  # type: ignore[operator]


def inverse(p: torch.Tensor, t: Transform) -> torch.Tensor:
    """Transformed space back to metric units (not clamped)."""
    if t.type == "clamped":
        return p * (2.0 * t.mu_y)  # type: ignore[operator]
    if t.type == "logistic":
        s0, s1 = _s_bounds(t)
        s = torch.clamp(p * (s1 - s0) + s0, LOGIT_EPS, 1.0 - LOGIT_EPS)
        return t.mu_y + torch.log(s / (1.0 - s)) / t.k  # type: ignore[operator]
    return (p - t.offset) / t.factor  # type: ignore[operator]


def extrapolate(
    values: torch.Tensor, outputs: Sequence[str], k: float = DEFAULT_EXTRAPOLATION_K, *, higher_is_better: bool = False
) -> torch.Tensor:
    """Complete per-rate values (axis -3) to the six reduced rates; see ``rtp.sdk.extrapolate``."""
    outputs = tuple(outputs)
    if outputs not in OUTPUT_SETS:
        raise ValueError(f"cannot extrapolate from {list(outputs)}; expected one of {[list(s) for s in OUTPUT_SETS]}")
    chans = complete_rates(
        {r: values[..., i, :, :] for i, r in enumerate(outputs)}, outputs, k, higher_is_better, torch.maximum, torch.minimum
    )
    return torch.stack(chans, dim=-3)


def decode(raw: torch.Tensor, meta: ModelMetadata) -> torch.Tensor:
    """Torch twin of :meth:`rtp.sdk.ModelMetadata.decode`: safety, inverse transform, extrapolation."""
    p = raw.double() + meta.worse_direction * meta.safety
    values = inverse(p, meta.transform)
    return extrapolate(values, meta.outputs, meta.extrapolation_k, higher_is_better=meta.higher_is_better).float()
