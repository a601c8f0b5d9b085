"""Target transforms, their inverses, and the paper's rate extrapolation, in plain numpy.

The network predicts a metric in a *transformed* space (paper Section 3.3) where the skewed
distribution of per-tile errors is balanced. These functions go back and forth:

* ``clamped`` (the paper's default): ``T(y) = clamp(y / (2 mu_Y), 0, 1)``,
  ``T^-1(p) = 2 mu_Y p``.
* ``logistic``: ``S(y) = 1 / (1 + exp(-k (y - mu_Y)))``, ``T(y) = (S(y) - S(0)) / (S(1) - S(0))``;
  the inverse solves for y (with S clipped into the open interval (0, 1) so it stays finite).
* ``linear`` (how the paper's published models are decoded): ``T(y) = clamp(factor y + offset, 0, 1)``,
  ``T^-1(p) = (p - offset) / factor``. A negative factor expresses models trained on ``1 - T``.

Inverses are not clamped: the network's sigmoid keeps ``p`` in (0, 1), and a safety margin may push
it past 1, which then decodes past the clamp point (a conservative, larger error).

The torch twins used in training live in ``rtp.train.transforms`` and are tested against the same
vectors (``tests/data/transform_vectors.json``).
"""

from __future__ import annotations

import math
import reprlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ._errors import InputDtypeError, InputShapeError, MetadataError, ParameterError
from ._rates import PREDICTED_RATES

__all__ = [
    "DEFAULT_EXTRAPOLATION_K",
    "DEFAULT_OUTPUTS",
    "LOGIT_EPS",
    "MAX_EXTRAPOLATION_K",
    "MAX_PARAMETER",
    "MIN_LOGISTIC_SPAN",
    "MIN_PARAMETER",
    "OUTPUT_SETS",
    "Transform",
    "complete_rates",
    "extrapolate",
]

#: Yang et al. 2019: the error of a quarter rate is about 2.13 times the error of the half rate.
DEFAULT_EXTRAPOLATION_K = 2.13
#: Largest extrapolation factor accepted: k >= 1 (a coarser rate never has less error) and at most
#: this (a quarter rate 100 times worse than the half rate would make the extrapolated rates useless).
MAX_EXTRAPOLATION_K = 100.0
#: Sets of network output rates that ``extrapolate`` can complete to all six reduced rates.
OUTPUT_SETS: tuple[tuple[str, ...], ...] = (
    ("1x2", "2x1"),
    ("1x2", "2x1", "2x4", "4x2"),
    ("1x2", "2x1", "2x2", "2x4", "4x2", "4x4"),
    ("2x2",),
)
#: The network outputs of the paper's models and rtp's default: the four rates the network predicts,
#: 2x2 and 4x4 extrapolated (paper Section 4.3).
DEFAULT_OUTPUTS: tuple[str, ...] = OUTPUT_SETS[1]

TransformType = Literal["clamped", "logistic", "linear"]
#: Largest magnitude a transform parameter may have: beyond it the decoded values overflow.
MAX_PARAMETER = 1e6
#: Smallest magnitude of ``mu_y``, ``k`` and ``factor``: below it decoding divides by (almost) zero and a
#: network output of 0.5 decodes to an error of 1e6 and more (float32 overflows near 1e300).
MIN_PARAMETER = 1e-6
#: Smallest ``S(1) - S(0)`` of a logistic transform: a flatter one (``mu_y`` far outside [0, 1] for its
#: ``k``) maps every metric value in [0, 1] to almost the same transformed value, and its inverse, which
#: clips S into (LOGIT_EPS, 1 - LOGIT_EPS), decodes every network output to the same constant.
MIN_LOGISTIC_SPAN = 1e-3
#: Transformed values are clipped to [eps, 1 - eps] before the logistic transform's logit.
LOGIT_EPS = 1e-7


def _finite(v: float | np.integer | np.floating) -> bool:
    """``math.isfinite`` that is False (not OverflowError) for an int too large for a float."""
    try:
        return math.isfinite(v)
    except OverflowError:
        return False


def _array(x: Any, name: str) -> np.ndarray:
    """``np.asarray(x)``, with InputDtypeError for what numpy cannot make an array of (ragged lists)."""
    try:
        return np.asarray(x)
    except (TypeError, ValueError, OverflowError) as err:
        raise InputDtypeError(f"{name}: expected a numeric array, got {type(x).__name__} ({err})") from err


def check_extrapolation_k(k: Any, name: str = "k") -> float:
    """``k`` as a float if it is a finite number in [1, :data:`MAX_EXTRAPOLATION_K`], else ParameterError."""
    if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, float, np.integer, np.floating)) or not _finite(k) \
            or not 1.0 <= k <= MAX_EXTRAPOLATION_K:
        raise ParameterError(f"{name}: expected a finite number in [1, {MAX_EXTRAPOLATION_K:g}] (the error ratio of a "
                             f"quarter rate to a half rate, 2.13 by default), got {reprlib.repr(k)}", name)
    return float(k)


def as_float64(x: Any, name: str) -> np.ndarray:
    """``x`` as a float64 array, or InputDtypeError naming ``name`` (strings, objects, ragged lists)."""
    a = _array(x, name)
    if a.dtype.kind not in "biuf":
        raise InputDtypeError(f"{name}: expected real numbers, got {type(x).__name__} of dtype {a.dtype}")
    return a.astype(np.float64, copy=False)


def _sigmoid(x: np.ndarray | float) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * np.asarray(x, dtype=np.float64)))


@dataclass(frozen=True)
class Transform:
    """A target transform and its parameters. Build with :meth:`from_dict` or the constructors."""

    type: TransformType
    mu_y: float | None = None
    k: float | None = None
    factor: float | None = None
    offset: float | None = None

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def clamped(cls, mu_y: float) -> Transform:
        return cls.from_dict({"type": "clamped", "mu_y": mu_y})

    @classmethod
    def logistic(cls, mu_y: float, k: float = 10.0) -> Transform:
        return cls.from_dict({"type": "logistic", "mu_y": mu_y, "k": k})

    @classmethod
    def linear(cls, factor: float, offset: float = 0.0) -> Transform:
        return cls.from_dict({"type": "linear", "factor": factor, "offset": offset})

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], key: str = "transform") -> Transform:
        """Validate a mapping such as ``{"type": "clamped", "mu_y": 0.08}``."""
        if not isinstance(d, Mapping):
            raise MetadataError(f"{key}: expected a mapping with a 'type', got {type(d).__name__}", key)
        kind = d.get("type")
        need: dict[str, tuple[str, ...]] = {
            "clamped": ("mu_y",),
            "logistic": ("mu_y", "k"),
            "linear": ("factor", "offset"),
        }
        if not isinstance(kind, str) or kind not in need:
            raise MetadataError(f"{key}.type: expected one of clamped, logistic, linear; got {kind!r}", f"{key}.type")
        unknown = set(d) - {"type", *need[kind]}
        if unknown:
            first = f"{key}.{sorted(unknown)[0]}"
            raise MetadataError(f"{first}: unexpected for a {kind} transform, which takes {', '.join(need[kind])}", first)
        vals: dict[str, float] = {}
        for name in need[kind]:
            if name not in d:
                raise MetadataError(f"{key}.{name}: required for a {kind} transform, missing", f"{key}.{name}")
            v = d[name]  # (numpy's numbers too: a mu_y measured as np.float32 was "not a finite number")
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not _finite(v) or abs(v) > MAX_PARAMETER:
                raise MetadataError(f"{key}.{name}: expected a finite number of magnitude <= {MAX_PARAMETER:g}, got "
                                    f"{reprlib.repr(v)}",
                                    f"{key}.{name}")
            vals[name] = float(v)
        if kind in ("clamped", "logistic") and vals["mu_y"] < MIN_PARAMETER:
            raise MetadataError(f"{key}.mu_y: expected a number in [{MIN_PARAMETER:g}, {MAX_PARAMETER:g}] (the mean "
                                f"training target), got {vals['mu_y']:g}", f"{key}.mu_y")
        if kind == "logistic" and vals["k"] < MIN_PARAMETER:
            raise MetadataError(f"{key}.k: expected a number in [{MIN_PARAMETER:g}, {MAX_PARAMETER:g}], got {vals['k']:g}",
                                f"{key}.k")
        if kind == "linear" and abs(vals["factor"]) < MIN_PARAMETER:
            raise MetadataError(f"{key}.factor: expected a magnitude in [{MIN_PARAMETER:g}, {MAX_PARAMETER:g}] "
                                f"(negative for models trained on 1 - T), got {vals['factor']:g}", f"{key}.factor")
        t = cls(type=kind, **vals)  # type: ignore[arg-type]  # kind is one of need's keys
        if kind == "logistic":
            s0, s1 = t._s_bounds()
            if not s1 - s0 >= MIN_LOGISTIC_SPAN:
                raise MetadataError(
                    f"{key}: a logistic transform with mu_y {vals['mu_y']:g} and k {vals['k']:g} is flat over [0, 1] "
                    f"(S(1) - S(0) = {s1 - s0:.3g}, expected >= {MIN_LOGISTIC_SPAN:g}): every network output would "
                    f"decode to the same value; choose mu_y inside [0, 1] or a smaller k", key)
        return t

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"type": self.type}
        for name in ("mu_y", "k", "factor", "offset"):
            v = getattr(self, name)
            if v is not None:
                d[name] = v
        return d

    # -- maths --------------------------------------------------------------------------------
    @property
    def increasing(self) -> bool:
        """Whether T grows with the metric value (False for a linear transform with factor < 0)."""
        return not (self.type == "linear" and (self.factor or 0.0) < 0)

    def forward(self, y: np.ndarray | float) -> np.ndarray:
        """Metric units to transformed space."""
        y = as_float64(y, "y")
        if self.type == "clamped":
            return np.clip(y / (2.0 * self.mu_y), 0.0, 1.0)  # type: ignore[operator]
        if self.type == "logistic":
            s0, s1 = self._s_bounds()
            return (_sigmoid(self.k * (y - self.mu_y)) - s0) / (s1 - s0)  # type: ignore[operator]
        return np.clip(y * self.factor + self.offset, 0.0, 1.0)  # type: ignore[operator]

    def inverse(self, p: np.ndarray | float) -> np.ndarray:
        """Transformed space back to metric units (not clamped; see the module docstring)."""
        p = as_float64(p, "p")
        if self.type == "clamped":
            return p * (2.0 * self.mu_y)  # type: ignore[operator]
        if self.type == "logistic":
            s0, s1 = self._s_bounds()
            s = np.clip(p * (s1 - s0) + s0, LOGIT_EPS, 1.0 - LOGIT_EPS)
            return self.mu_y + np.log(s / (1.0 - s)) / self.k  # type: ignore[operator]
        return (p - self.offset) / self.factor  # type: ignore[operator]

    def _s_bounds(self) -> tuple[float, float]:
        s0 = float(_sigmoid(self.k * (0.0 - self.mu_y)))  # type: ignore[operator]
        s1 = float(_sigmoid(self.k * (1.0 - self.mu_y)))  # type: ignore[operator]
        return s0, s1


def extrapolate(
    values: np.ndarray,
    outputs: Sequence[str],
    k: float = DEFAULT_EXTRAPOLATION_K,
    *,
    higher_is_better: bool = False,
) -> np.ndarray:
    """Complete per-rate predictions to all six reduced rates (paper Section 4.3).

    ``values`` holds one channel per rate of ``outputs`` on axis -3, in metric units. Returns the
    six channels ``1x2, 2x1, 2x2, 2x4, 4x2, 4x4`` on axis -3. With ``Y_uxv`` the value of rate u x v:

    * square rates: ``Y_uxu = max(Y_(u/2)xu, Y_ux(u/2))``
    * ``u > v``: ``Y_uxv = max(k Y_(u/2)x(v/2), Y_(u/2)xv)``; ``u < v`` symmetric.

    From ``1x2, 2x1`` this gives ``2x2 = max(e12, e21)``, ``2x4 = max(k e12, e22)``,
    ``4x2 = max(k e21, e22)``, ``4x4 = max(e24, e42)``; from four outputs only ``2x2`` and ``4x4``
    are extrapolated. A single ``2x2`` output (the paper's released metric models) fills 1x2 and 2x1
    with the 2x2 value, an upper bound, and continues with the same equation.

    For a higher-is-better metric in decibels (PSNR), "worse" is the minimum and scaling an error
    amplitude by k lowers the value by ``20 log10 k`` dB.
    """
    if isinstance(outputs, str) or not isinstance(outputs, Sequence) or tuple(outputs) not in OUTPUT_SETS:
        raise MetadataError(
            f"outputs: cannot extrapolate from {outputs!r}; expected one of {[list(s) for s in OUTPUT_SETS]}",
            "outputs",
        )
    outputs = tuple(outputs)
    k = check_extrapolation_k(k)
    if not isinstance(higher_is_better, (bool, np.bool_)):
        raise ParameterError(f"higher_is_better: expected True or False, got {higher_is_better!r}", "higher_is_better")
    v = _array(values, "values")
    if v.dtype.kind not in "biuf":
        raise InputDtypeError(f"values: expected a real numeric array, got dtype {v.dtype}")
    if v.ndim < 3 or v.shape[-3] != len(outputs):
        raise InputShapeError(
            f"values: expected {len(outputs)} channels on axis -3 for outputs {list(outputs)}, got shape {v.shape}",
            tuple(v.shape), f"(..., {len(outputs)}, th, tw)",
        )
    chans = complete_rates(
        {r: v[..., i, :, :] for i, r in enumerate(outputs)}, outputs, k, higher_is_better, np.maximum, np.minimum
    )
    return np.stack(chans, axis=-3)


def complete_rates(
    ch: dict[str, Any],
    outputs: tuple[str, ...],
    k: float,
    higher_is_better: bool,
    maximum: Callable[[Any, Any], Any],
    minimum: Callable[[Any, Any], Any],
) -> list[Any]:
    """The extrapolation equation on per-rate planes of any array library (numpy here, torch in
    ``rtp.train.transforms``): returns the six planes in :data:`PREDICTED_RATES` order."""
    if higher_is_better:
        worse = minimum
        drop = 20.0 * math.log10(k)

        def scaled(x: Any) -> Any:
            return x - drop
    else:
        worse = maximum

        def scaled(x: Any) -> Any:
            return x * k

    ch = dict(ch)
    missing = [r for r in outputs if r not in ch]
    if missing:
        raise ParameterError(f"complete_rates: the planes of outputs {list(outputs)} are needed, {missing} missing")
    if outputs == ("2x2",):
        ch["1x2"] = ch["2x1"] = ch["2x2"]
    if "2x2" not in ch:
        ch["2x2"] = worse(ch["1x2"], ch["2x1"])
    if "2x4" not in ch:
        ch["2x4"] = worse(scaled(ch["1x2"]), ch["2x2"])
        ch["4x2"] = worse(scaled(ch["2x1"]), ch["2x2"])
    if "4x4" not in ch:
        ch["4x4"] = worse(ch["2x4"], ch["4x2"])
    return [ch[r] for r in PREDICTED_RATES]
