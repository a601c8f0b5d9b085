"""Shading rates: names, D3D12/Vulkan codes, and per-tile rate selection.

Rates use D3D12 naming: ``WxH`` means W pixels wide by H pixels tall share one shading result,
so ``1x2`` halves the rate vertically and ``2x1`` horizontally. The code of a rate is
``(log2 W << 2) | log2 H``, identical for D3D12 shading-rate images and Vulkan fragment
shading-rate attachments.
"""

from __future__ import annotations

import math
import reprlib
from collections.abc import Iterable, Mapping

import numpy as np

from ._errors import InputDtypeError, InputShapeError, ParameterError
from ._tiles import tile_extents, tile_grid

__all__ = [
    "ALL_RATES",
    "MAX_RATE_FACTOR",
    "MAX_THRESHOLD",
    "PREDICTED_RATES",
    "RATE_CODES",
    "RATE_NAMES",
    "RateLike",
    "check_rate_factors",
    "check_threshold",
    "rate_size",
    "resolve_allowed",
    "select_rates",
    "work_saved",
]

#: Every rate, finest first: 1x1 plus the six reduced rates.
ALL_RATES: tuple[str, ...] = ("1x1", "1x2", "2x1", "2x2", "2x4", "4x2", "4x4")
#: The rates ``predict`` returns a channel for, in channel order.
PREDICTED_RATES: tuple[str, ...] = ALL_RATES[1:]


#: Largest magnitude of a threshold (metric units, dB for PSNR): every metric rtp knows stays far below
#: it, and a threshold beyond everything a model can express would pass (or fail) every tile.
MAX_THRESHOLD = 1e6
#: Largest factor of a rate's threshold (and the inverse, the smallest): ``select_rates(factors=)`` and
#: the metadata field ``rate_factors``. A factor of 4 already moves JNYang's 0.25 to 1 or 0.0625.
MAX_RATE_FACTOR = 4.0


def rate_size(rate: str) -> tuple[int, int]:
    """``(W, H)`` of a rate name such as ``"2x4"``."""
    if not isinstance(rate, str) or rate not in ALL_RATES:
        raise ParameterError(f"unknown shading rate {rate!r}; expected one of {', '.join(ALL_RATES)}", "rate")
    w, h = rate.split("x")
    return int(w), int(h)


def _code(rate: str) -> int:
    w, h = rate_size(rate)
    return (int(np.log2(w)) << 2) | int(np.log2(h))


#: Rate name to D3D12 / Vulkan shading-rate code: 1x1=0, 1x2=1, 2x1=4, 2x2=5, 2x4=6, 4x2=9, 4x4=10.
RATE_CODES: dict[str, int] = {r: _code(r) for r in ALL_RATES}
#: Code back to rate name.
RATE_NAMES: dict[int, str] = {c: r for r, c in RATE_CODES.items()}


RateLike = str | int


def work_saved(
    rates: RateLike | np.ndarray, frame_size: tuple[int, int] | None = None, tile_size: int | None = None
) -> float:
    """Fraction of the shading work saved.

    A rate name or code: ``1 - 1/(W*H)`` of that rate. A shading-rate image (uint8 codes ``(th, tw)``,
    as :meth:`ShadingRatePredictor.shading_rates` returns): the frame-level figure, each tile weighted
    by the pixels it covers; give the frame's ``frame_size = (H, W)`` and ``tile_size`` so partial
    edge tiles count their real pixels (without them every tile counts alike).
    """
    if isinstance(rates, (str, int, np.integer)) and not isinstance(rates, bool):
        name = rates if isinstance(rates, str) else RATE_NAMES.get(int(rates))
        if name is None:
            raise ParameterError(f"unknown shading-rate code {rates}; expected one of {sorted(RATE_NAMES)}", "rates")
        w, h = rate_size(name)
        return 1.0 - 1.0 / (w * h)
    try:
        codes = np.asarray(rates)
    except (TypeError, ValueError, OverflowError) as err:  # ragged nested lists and the like
        raise InputDtypeError(f"work_saved: expected a rate or an array of rate codes, got {type(rates).__name__}") from err
    if codes.ndim != 2 or codes.size == 0 or codes.dtype.kind not in "ui":
        raise InputShapeError(f"work_saved: expected a rate name, a code, or a non-empty (th, tw) array of integer "
                              f"codes, got {type(rates).__name__} {getattr(codes, 'shape', '')}")
    table = np.full(256, np.nan)
    for name, code in RATE_CODES.items():
        w, h = rate_size(name)
        table[code] = 1.0 - 1.0 / (w * h)
    # codes outside 0..255 (negative ones too) map to a NaN entry rather than clipping onto a real code
    wide = codes.astype(np.int64)
    saved = table[np.where((wide >= 0) & (wide <= 255), wide, 255)]
    if np.isnan(saved).any():
        bad = sorted({int(c) for c in codes[np.isnan(saved)].ravel()})
        raise ParameterError(f"unknown shading-rate code(s) {bad}; expected codes from {sorted(RATE_NAMES)}", "rates")
    if (frame_size is None) != (tile_size is None):
        raise ParameterError("work_saved: give frame_size and tile_size together (or neither)", "frame_size")
    if frame_size is None or tile_size is None:
        return float(saved.mean())
    if not isinstance(frame_size, (tuple, list)) or len(frame_size) != 2:
        raise ParameterError(f"frame_size: expected (H, W), got {frame_size!r}", "frame_size")
    h, w = frame_size
    if tile_grid(h, w, tile_size) != codes.shape:
        raise InputShapeError(f"work_saved: {codes.shape[0]}x{codes.shape[1]} tiles do not cover a {w}x{h} frame "
                              f"of {tile_size}-pixel tiles ({tile_grid(h, w, tile_size)} would)")
    pixels = np.outer(tile_extents(h, tile_size), tile_extents(w, tile_size))
    return float((saved * pixels).sum() / pixels.sum())


def resolve_allowed(allowed: Iterable[RateLike] | None) -> tuple[str, ...]:
    """Normalise an ``allowed`` argument (names or codes) to reduced-rate names in channel order.

    ``None`` allows every rate. ``1x1`` is always allowed (it is the fallback) and may be listed.
    """
    if allowed is None:
        return PREDICTED_RATES
    if isinstance(allowed, (str, int, np.integer)):
        allowed = [allowed]
    if isinstance(allowed, Mapping) or not isinstance(allowed, Iterable):
        raise ParameterError(f"allowed: expected rate names or codes (a list), got {type(allowed).__name__} "
                             f"{allowed!r}", "allowed")
    try:
        items = list(allowed)
    except TypeError as err:  # a 0-d array, an iterator that fails
        raise ParameterError(f"allowed: expected rate names or codes (a list), got {allowed!r} ({err})", "allowed") from err
    names: set[str] = set()
    for item in items:
        if isinstance(item, (int, np.integer)) and not isinstance(item, bool):
            if int(item) not in RATE_NAMES:
                raise ParameterError(f"unknown shading-rate code {int(item)}; expected one of {sorted(RATE_NAMES)}")
            names.add(RATE_NAMES[int(item)])
        elif isinstance(item, str):
            if item not in RATE_CODES:
                raise ParameterError(f"unknown shading rate {item!r} in allowed; expected names from {', '.join(ALL_RATES)}")
            names.add(item)
        else:
            raise ParameterError(f"allowed rates must be names like '2x2' or integer codes, got {item!r}")
    return tuple(r for r in PREDICTED_RATES if r in names)


def check_threshold(threshold: object, higher_is_better: bool) -> float:
    """``threshold`` as a float if it makes sense, else :class:`ParameterError` with the range: a finite
    number of magnitude <= :data:`MAX_THRESHOLD`, and >= 0 for an error metric (lower is better)."""
    if isinstance(threshold, (bool, np.bool_)) or not isinstance(threshold, (int, float, np.integer, np.floating)):
        raise ParameterError(f"threshold: expected a number, got {type(threshold).__name__} {reprlib.repr(threshold)}",
                             "threshold")
    try:
        value = float(threshold)
    except OverflowError:  # an int too large for a float
        value = math.inf if threshold > 0 else -math.inf
    lo = -MAX_THRESHOLD if higher_is_better else 0.0
    if not lo <= value <= MAX_THRESHOLD:  # NaN fails too
        kind = "dB (higher is better)" if higher_is_better else "for an error metric (lower is better)"
        raise ParameterError(f"threshold: expected a finite number in [{lo:g}, {MAX_THRESHOLD:g}] {kind}, got "
                             f"{reprlib.repr(threshold)}", "threshold")
    return value


def check_rate_factors(factors: object, name: str = "factors") -> tuple[float, ...]:
    """Six per-rate threshold factors in :data:`PREDICTED_RATES` order from ``None`` (all 1), a mapping
    of rate names to factors (a rate left out: 1) or a sequence of six numbers; each finite and within
    ``[1 / MAX_RATE_FACTOR, MAX_RATE_FACTOR]``, else :class:`ParameterError` naming ``name``."""
    n = len(PREDICTED_RATES)
    if factors is None:
        return (1.0,) * n
    if isinstance(factors, Mapping):
        odd = [k for k in factors if k not in PREDICTED_RATES]
        if odd:
            raise ParameterError(f"{name}: unknown rate {reprlib.repr(odd[0])}; expected names from "
                                 f"{', '.join(PREDICTED_RATES)} (1x1 is never reduced)", name)
        items = [factors.get(r, 1.0) for r in PREDICTED_RATES]
    elif isinstance(factors, (str, bytes)) or not isinstance(factors, Iterable):
        raise ParameterError(f"{name}: expected a mapping of rate names to factors or {n} numbers in the order "
                             f"{', '.join(PREDICTED_RATES)}, got {type(factors).__name__} {reprlib.repr(factors)}", name)
    else:
        try:
            items = list(factors)
        except TypeError as err:  # a 0-d array, an iterator that fails
            raise ParameterError(f"{name}: expected {n} numbers ({', '.join(PREDICTED_RATES)}), got "
                                 f"{reprlib.repr(factors)} ({err})", name) from err
        if len(items) != n:
            raise ParameterError(f"{name}: expected {n} factors ({', '.join(PREDICTED_RATES)}), got {len(items)}", name)
    out = []
    for r, f in zip(PREDICTED_RATES, items):
        value = math.nan
        if not isinstance(f, (bool, np.bool_)) and isinstance(f, (int, float, np.integer, np.floating)):
            try:
                value = float(f)
            except OverflowError:  # an int too large for a float
                pass
        if not 1.0 / MAX_RATE_FACTOR <= value <= MAX_RATE_FACTOR:  # NaN fails too
            raise ParameterError(f"{name}: {r}'s factor must be a number in [{1 / MAX_RATE_FACTOR:g}, "
                                 f"{MAX_RATE_FACTOR:g}] (1: the threshold as it is), got {reprlib.repr(f)}", name)
        out.append(value)
    return tuple(out)


def select_rates(
    values: np.ndarray,
    threshold: float,
    *,
    higher_is_better: bool = False,
    allowed: Iterable[RateLike] | None = None,
    factors: Mapping[str, float] | Iterable[float] | None = None,
) -> np.ndarray:
    """Pick per tile the cheapest allowed rate whose predicted value passes ``threshold``.

    ``values`` has the six predicted rates (:data:`PREDICTED_RATES` order) on axis -3, e.g. shape
    ``(6, th, tw)`` or ``(N, 6, th, tw)``. A value passes when it is below the threshold (error
    metrics) or above it (``higher_is_better``, e.g. PSNR). Among passing rates of equal cost (1x2
    and 2x1, 2x4 and 4x2) the one with the better predicted value wins. Tiles where nothing passes
    get 1x1. Returns uint8 D3D12/Vulkan codes with axis -3 removed.

    ``factors`` (:func:`check_rate_factors`; a model's ``metadata.rate_factors``) gives each rate a
    threshold of its own: an error passes below ``threshold x factor``, a PSNR above ``threshold - 20
    log10(factor)`` dB (a factor on the error's amplitude, as ``extrapolation_k``). Rates of equal cost
    then compare their values over their own thresholds.
    """
    try:
        values = np.asarray(values)
    except (TypeError, ValueError, OverflowError) as error:  # ragged nested lists and the like
        raise InputDtypeError(f"values: expected a numeric array, got {type(values).__name__} ({error})") from error
    if values.dtype.kind not in "biuf":
        raise InputDtypeError(f"values: expected real numbers (predictions), got dtype {values.dtype}")
    if values.ndim < 3 or values.shape[-3] != len(PREDICTED_RATES):
        raise InputShapeError(
            f"expected predictions with {len(PREDICTED_RATES)} rate channels on axis -3, got shape {values.shape}",
            actual=tuple(values.shape),
            expected="(..., 6, th, tw)",
        )
    if not isinstance(higher_is_better, (bool, np.bool_)):
        raise ParameterError(f"higher_is_better: expected True or False, got {higher_is_better!r}", "higher_is_better")
    rates = resolve_allowed(allowed)
    threshold = check_threshold(threshold, bool(higher_is_better))
    scale = check_rate_factors(factors)
    # Orient every comparison as "smaller is better" so one code path serves both kinds.
    as_float = values.astype(np.float64, copy=False)  # bool and unsigned predictions negate correctly too
    err = -as_float if higher_is_better else as_float
    if any(f != 1.0 for f in scale):  # each rate's value against its own threshold: over the factor, or dB added
        f = np.asarray(scale, np.float64)[:, None, None]
        err = err - 20.0 * np.log10(f) if higher_is_better else err / f
    thr = -threshold if higher_is_better else threshold
    # The allowed rates from cheapest (largest area) to dearest, in channel order within a cost class.
    # A tile takes the cheapest class with a passing rate, then that class's smallest error (the first
    # in channel order on a tie); NaN never passes (comparisons with NaN are False). A handful of whole-
    # array operations, not a few per rate: each releases the GIL, and a thread waiting to take it back
    # beside Python that holds it waits a switch interval (5 ms) for each (docs/runtime.md "Threads").
    order = sorted(rates, key=lambda r: (-rate_size(r)[0] * rate_size(r)[1], PREDICTED_RATES.index(r)))
    if not order:
        return np.full(values.shape[:-3] + values.shape[-2:], RATE_CODES["1x1"], dtype=np.uint8)
    areas = [rate_size(r)[0] * rate_size(r)[1] for r in order]
    rank = np.array([sorted(set(areas), reverse=True).index(a) for a in areas], np.int8)
    e = np.take(err, [PREDICTED_RATES.index(r) for r in order], axis=-3)
    passing = e < thr
    best = np.where(passing, rank[:, None, None], np.int8(len(order))).min(axis=-3, keepdims=True)
    pick = np.where(passing & (rank[:, None, None] == best), e, np.inf).argmin(axis=-3)
    codes = np.array([RATE_CODES[r] for r in order], np.uint8)
    return np.where(best[..., 0, :, :] < len(order), codes[pick], np.uint8(RATE_CODES["1x1"]))
