"""The safety margin: calibrated on validation predictions so the model underestimates less often
(paper Section 4.1: the mean underestimation, added to every prediction at run time)."""

from __future__ import annotations

import math
import reprlib

import numpy as np

from rtp.sdk import ParameterError

__all__ = ["calibrate_safety"]


def calibrate_safety(
    pred: np.ndarray, gt: np.ndarray, *, worse: float = 1.0, quantile: float | None = None
) -> tuple[float, float]:
    """A safety margin in transformed space and the share of tiles still underestimated with it.

    Without ``quantile``: the paper's margin, the mean underestimation over all values (counting 0
    where there is none). With ``quantile = q``: the smallest margin that leaves at most a share q
    of the values underestimated.
    """
    try:
        p = np.asarray(pred, dtype=np.float64).ravel()
        g = np.asarray(gt, dtype=np.float64).ravel()
    except (TypeError, ValueError) as err:
        raise ParameterError(f"pred, gt: expected arrays of numbers ({err})") from err
    if p.shape != g.shape:
        raise ParameterError(f"pred, gt: expected arrays of one shape, got {np.shape(pred)} and {np.shape(gt)}")
    for key, value in (("worse", worse), ("quantile", 0.0 if quantile is None else quantile)):
        try:
            number = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating)) \
                and math.isfinite(value)
        except OverflowError:  # an int past float's range
            number = False
        if not number:
            raise ParameterError(f"{key}: expected a finite number, got {reprlib.repr(value)}", key)
    if quantile is not None and not 0.0 <= quantile < 1.0:  # (before the values: with none finite it was taken)
        raise ParameterError(f"safety quantile: expected a number in [0, 1), got {quantile}", "quantile")
    ok = np.isfinite(p) & np.isfinite(g)
    short = worse * (g[ok] - p[ok])
    if short.size == 0:
        return 0.0, 0.0
    if quantile is None:
        s = float(np.maximum(short, 0.0).mean())
    else:
        # at most floor(q n) values may stay above it: the margin is the next one down (numpy's "higher" quantile
        # of 1 - q was up to one value more, leaving fewer underestimated than q allows)
        above = min(math.floor(quantile * short.size), short.size - 1)
        s = max(0.0, float(np.partition(short, short.size - 1 - above)[short.size - 1 - above]))
    return s, float(np.mean(short > s))
