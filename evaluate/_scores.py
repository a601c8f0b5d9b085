"""Prediction-quality scores: the columns of the paper's prediction-quality table.

All are computed on matching arrays of predictions and ground truth, in the model's transformed
space (as the paper reports them) unless the caller passes metric units.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from rtp.sdk import InputDtypeError, InputShapeError, ParameterError

__all__ = ["Scores", "scores"]


@dataclass(frozen=True)
class Scores:
    """``r2``: 1 - SS_res / SS_tot, NaN (undefined) where the values of ``gt`` are all one (or none).
    ``mae``: mean |pred - gt|. ``mae_under``: mean shortfall (gt - pred) over the tiles the prediction
    underestimates. ``under_share``: share of such tiles. ``sigma``: standard deviation of |pred - gt|.
    ``n``: number of values."""

    r2: float
    mae: float
    mae_under: float
    under_share: float
    sigma: float
    n: int

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def real_values(value: object, name: str) -> np.ndarray:
    """``value`` as a flat float64 array of its numbers, or an :class:`~rtp.sdk.InputDtypeError` naming ``name``
    (``None`` was one NaN, and a list of strings numpy's ValueError)."""
    a = np.asarray(value)
    if a.dtype.kind not in "biuf":
        raise InputDtypeError(f"{name}: expected an array of numbers, got {type(value).__name__} of dtype {a.dtype}")
    return a.astype(np.float64).ravel()


def scores(pred: np.ndarray, gt: np.ndarray, *, worse: float = 1.0) -> Scores:
    """Scores of ``pred`` against ``gt``. ``worse`` is +1 when larger values mean a worse image
    (errors) and -1 otherwise; "underestimation" is a prediction on the optimistic side."""
    p, g = real_values(pred, "pred"), real_values(gt, "gt")
    if p.shape != g.shape:
        raise InputShapeError(f"pred and gt differ in size: {p.shape} vs {g.shape}", p.shape, str(g.shape))
    if worse not in (1, -1) or isinstance(worse, bool):
        raise ParameterError(f"worse: expected +1 (larger values are worse: errors) or -1, got {worse!r}", "worse")
    ok = np.isfinite(p) & np.isfinite(g)
    p, g = p[ok], g[ok]
    if p.size == 0:
        nan = float("nan")
        return Scores(nan, nan, nan, nan, nan, 0)
    d = np.abs(p - g)
    # undefined (NaN) where the targets are all one value: their mean's rounding left SS_tot at about 1e-31 for most
    # values (ten 0.3s), and R² read as -1e29 % or beyond, a number where there is none
    ss_tot = float(np.sum((g - g.mean()) ** 2)) if g.min() < g.max() else 0.0
    r2 = 1.0 - float(np.sum((p - g) ** 2)) / ss_tot if ss_tot > 0 else float("nan")
    short = worse * (g - p)
    under = short > 0
    return Scores(
        r2=r2,
        mae=float(d.mean()),
        mae_under=float(short[under].mean()) if under.any() else 0.0,
        under_share=float(under.mean()),
        sigma=float(d.std()),
        n=int(p.size),
    )
