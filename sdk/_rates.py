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
from typing import NamedTuple

import numpy as np

from ._errors import InputDtypeError, InputShapeError, ParameterError
from ._tiles import tile_extents, tile_grid

__all__ = [
    "ALL_RATES",
    "COMBINERS",
    "MAX_RATE_FACTOR",
    "MAX_SAVING",
    "MAX_THRESHOLD",
    "PREDICTED_RATES",
    "RATE_CODES",
    "RATE_NAMES",
    "RateLike",
    "SavingSelection",
    "check_rate_factors",
    "check_engine_rates",
    "check_threshold",
    "combine_rates",
    "rate_size",
    "resolve_allowed",
    "select_rates",
    "select_rates_for_saving",
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
    edge tiles count their real pixels (without them every tile counts alike). Each pixel counts its rate's
    ``1 - 1/(W*H)``: where a frame side is not a multiple of a rate's block, its last blocks are partial and
    shade one sample for fewer pixels, which this overstates slightly (docs/renderer.md "Software VRS").
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
    pixels = _tile_pixels("work_saved", codes.shape, frame_size, tile_size)
    return float((saved * pixels).sum() / pixels.sum())


def _tile_pixels(who: str, tiles: tuple[int, ...], frame_size: object, tile_size: int | None) -> np.ndarray:
    """Each tile's pixels ``(th, tw)`` (float64) in a frame of ``frame_size = (H, W)`` on ``tile_size``-pixel tiles:
    partial edge tiles count their real pixels; without either every tile counts one. A typed error, naming
    ``who``, for one without the other, a size that is no ``(H, W)`` or a frame the ``tiles`` do not cover."""
    if (frame_size is None) != (tile_size is None):
        raise ParameterError(f"{who}: give frame_size and tile_size together (or neither)", "frame_size")
    if frame_size is None or tile_size is None:
        return np.ones(tiles)
    if not isinstance(frame_size, (tuple, list)) or len(frame_size) != 2:
        raise ParameterError(f"frame_size: expected (H, W), got {frame_size!r}", "frame_size")
    h, w = frame_size
    if tile_grid(h, w, tile_size) != tuple(tiles):
        raise InputShapeError(f"{who}: {tiles[0]}x{tiles[1]} tiles do not cover a {w}x{h} frame of {tile_size}-pixel "
                              f"tiles ({tile_grid(h, w, tile_size)} would)")
    return np.outer(tile_extents(h, tile_size), tile_extents(w, tile_size)).astype(np.float64)


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
                raise ParameterError(f"allowed: unknown shading-rate code {int(item)}; expected one of "
                                     f"{sorted(RATE_NAMES)}", "allowed")
            names.add(RATE_NAMES[int(item)])
        elif isinstance(item, str):
            if item not in RATE_CODES:
                raise ParameterError(f"allowed: unknown shading rate {item!r}; expected names from {', '.join(ALL_RATES)}",
                                     "allowed")
            names.add(item)
        else:
            raise ParameterError(f"allowed: expected rate names like '2x2' or integer codes, got {item!r}", "allowed")
    return tuple(r for r in PREDICTED_RATES if r in names)


def check_threshold(threshold: object, higher_is_better: bool) -> float:
    """``threshold`` as a float if it makes sense, else :class:`ParameterError` with the range: a finite
    number of magnitude <= :data:`MAX_THRESHOLD`, and >= 0 for an error metric (lower is better)."""
    if not isinstance(higher_is_better, (bool, np.bool_)):  # ('no' was taken for True: a PSNR's range, negatives in)
        raise ParameterError(f"higher_is_better: expected True or False, got {reprlib.repr(higher_is_better)}",
                             "higher_is_better")
    higher_is_better = bool(higher_is_better)
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
                             f"{value:.6g}", "threshold")  # (numpy's repr was np.float64(-0...0000000000001))
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
    engine_rates: RateLike | np.ndarray | None = None,
    combiner: str | int = "max",
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

    ``engine_rates`` are the rates the engine's own sources give the same tiles (a foveation or motion image, a
    per-draw rate: one code, a ``(th, tw)`` image of codes, or one a frame), which the hardware's ``combiner``
    (:data:`COMBINERS`: ``min``, ``max`` or ``sum``, or its enum value) meets with this image: then the rate judged
    is the rate the device will shade, ``combine_rates(engine_rates, image, combiner)``, and a tile takes the
    cheapest one reachable that passes, else what the engine's rates force. With ``max`` a ``1x2`` here and a ``2x1``
    of the engine's shade ``2x2``, a rate neither chose; this picks ``2x2`` only where it passes. The image then
    holds, with ``min`` and ``max``, the rate the device shades.
    """
    values, hib = _check_values(values, higher_is_better)
    rates = resolve_allowed(allowed)
    threshold = check_threshold(threshold, hib)
    combo = _engine_rates(engine_rates, combiner, rates, values.shape[:-3] + values.shape[-2:])
    err = _oriented(values, hib, check_rate_factors(factors))
    if combo is None:
        return _pick(err, -threshold if hib else threshold, rates)
    return _pick_combined(*_combined_values(err, *combo), -threshold if hib else threshold, *combo)[0]


def _check_values(values: object, higher_is_better: object) -> tuple[np.ndarray, bool]:
    """Predictions as an array with the six rates on axis -3 and the metric's direction as a bool, else a typed
    error (the checks every selection starts with)."""
    try:
        array = np.asarray(values)
    except (TypeError, ValueError, OverflowError) as error:  # ragged nested lists and the like
        raise InputDtypeError(f"values: expected a numeric array, got {type(values).__name__} ({error})") from error
    if array.dtype.kind not in "biuf":
        raise InputDtypeError(f"values: expected real numbers (predictions), got dtype {array.dtype}")
    if array.ndim < 3 or array.shape[-3] != len(PREDICTED_RATES):
        raise InputShapeError(
            f"expected predictions with {len(PREDICTED_RATES)} rate channels on axis -3, got shape {array.shape}",
            actual=tuple(array.shape),
            expected="(..., 6, th, tw)",
        )
    if not isinstance(higher_is_better, (bool, np.bool_)):
        raise ParameterError(f"higher_is_better: expected True or False, got {higher_is_better!r}", "higher_is_better")
    return array, bool(higher_is_better)


def _oriented(values: np.ndarray, higher_is_better: bool, scale: tuple[float, ...]) -> np.ndarray:
    """Every value oriented as "smaller is better" (float64), each rate's factor applied: a value passes a
    threshold ``t`` where it is below ``t`` (``-t`` for a higher-is-better metric), so one code path serves both."""
    as_float = values.astype(np.float64, copy=False)  # bool and unsigned predictions negate correctly too
    err = -as_float if higher_is_better else as_float
    if any(f != 1.0 for f in scale):  # each rate's value against its own threshold: over the factor, or dB added
        f = np.asarray(scale, np.float64)[:, None, None]
        err = err - 20.0 * np.log10(f) if higher_is_better else err / f
    return err


def _classes(rates: tuple[str, ...]) -> list[str]:
    """The allowed rates from cheapest (largest area) to dearest, in channel order within a cost class."""
    return sorted(rates, key=lambda r: (-rate_size(r)[0] * rate_size(r)[1], PREDICTED_RATES.index(r)))


def _pick(err: np.ndarray, thr: float, rates: tuple[str, ...]) -> np.ndarray:
    """``select_rates`` on oriented values (:func:`_oriented`) against the oriented threshold ``thr``."""
    # A tile takes the cheapest class with a passing rate, then that class's smallest error (the first
    # in channel order on a tie); NaN never passes (comparisons with NaN are False). A handful of whole-
    # array operations, not a few per rate: each releases the GIL, and a thread waiting to take it back
    # beside Python that holds it waits a switch interval (5 ms) for each (docs/runtime.md "Threads").
    order = _classes(rates)
    if not order:
        return np.full(err.shape[:-3] + err.shape[-2:], RATE_CODES["1x1"], dtype=np.uint8)
    areas = [rate_size(r)[0] * rate_size(r)[1] for r in order]
    rank = np.array([sorted(set(areas), reverse=True).index(a) for a in areas], np.int8)
    e = np.take(err, [PREDICTED_RATES.index(r) for r in order], axis=-3)
    codes = np.array([RATE_CODES[r] for r in order] + [RATE_CODES["1x1"]], np.uint8)
    return codes[_choose(e, rank[:, None, None], thr, len(order))]


def _choose(values: np.ndarray, rank: np.ndarray, thr: float, fallback: int,
            prefer: np.ndarray | None = None) -> np.ndarray:
    """Per tile the index on axis -3 of the cheapest candidate whose oriented value passes ``thr``: the lowest
    ``rank`` (int8, broadcast over ``values``), then the smallest value, then one ``prefer`` marks, then the first;
    ``fallback`` where none passes."""
    passing = values < thr
    best = np.where(passing, rank, np.int8(127)).min(axis=-3, keepdims=True)
    masked = np.where(passing & (rank == best), values, np.inf)
    if prefer is None:
        pick = masked.argmin(axis=-3)
    else:
        tied = masked == masked.min(axis=-3, keepdims=True)
        liked = tied & prefer
        pick = np.where(liked.any(axis=-3), liked.argmax(axis=-3), tied.argmax(axis=-3))
    return np.where(best[..., 0, :, :] < 127, pick, fallback)


def _pick_combined(values: np.ndarray, area: np.ndarray, thr: float, combo: _Combination,
                   engine: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The image's codes and the codes the device shades, from the candidates' oriented ``values`` and ``area``
    (:func:`_combined_values`) against the oriented threshold ``thr``: the cheapest passing, else the 1x1 candidate
    (the engine's rates alone); of two as cheap and as good, one the device shades as judged rather than one where
    it may choose between a wide and a tall rate."""
    table = combo.channels[..., 0] == combo.channels[..., 1]
    # (where no candidate of the engine's rates present may shade either of two rates, nothing to prefer)
    exact = None if table[np.unique(engine)].all() else np.moveaxis(table.T[:, engine], 0, -3)
    pick = _choose(values, (-area).astype(np.int8), thr, len(combo.candidates) - 1, prefer=exact)
    return combo.image[engine, pick], combo.shaded[engine, pick]


# --- The engine's own rates: the hardware's combiners --------------------------------------------------------------

#: The hardware's shading-rate combiners, at their enum values (``D3D12_SHADING_RATE_COMBINER`` and Vulkan's
#: ``VkFragmentShadingRateCombinerOpKHR`` share them): ``passthrough`` keeps the first input, ``override`` takes the
#: second, ``min`` the finer size on each axis, ``max`` the coarser, ``sum`` the product of the sizes (D3D12 adds
#: their log2; Vulkan's ``MUL``). Vulkan's names ``keep``, ``replace`` and ``mul`` are accepted too.
COMBINERS: tuple[str, ...] = ("passthrough", "override", "min", "max", "sum")
_COMBINER_ALIASES = {"keep": "passthrough", "replace": "override", "mul": "sum"}


def _check_combiner(combiner: object, selecting: bool = False) -> str:
    """A combiner's rtp name from a name (D3D12's or Vulkan's, any case) or its enum value, else ParameterError.
    ``selecting``: only the combiners through which the image's rate reaches the frame (min, max, sum)."""
    name = None
    if isinstance(combiner, str):
        low = combiner.strip().lower()
        name = _COMBINER_ALIASES.get(low, low if low in COMBINERS else None)
    elif isinstance(combiner, (int, np.integer)) and not isinstance(combiner, (bool, np.bool_)):
        name = COMBINERS[int(combiner)] if 0 <= int(combiner) < len(COMBINERS) else None
    choices = ("min", "max", "sum") if selecting else COMBINERS
    if name is None or name not in choices:
        why = (" (passthrough keeps the engine's rate and override the image's: nothing to choose with the engine's)"
               if name in COMBINERS else "")
        raise ParameterError(f"combiner: expected one of {', '.join(choices)} (or its D3D12/Vulkan enum value"
                             f"{'' if selecting else ', or keep, replace, mul'}){why}, got {reprlib.repr(combiner)}",
                             "combiner")
    return name


def _device_rates(w: int, h: int, supported: tuple[str, ...]) -> tuple[str, ...]:
    """The rates a device may shade where a combiner asks for ``w x h``, the one rtp reports first: that rate where it
    is ``supported``; else Vulkan's clamp (D3D12 leaves it to the device): of the supported rates no larger on either
    axis, those of the largest area, then of the lowest ``W + H``, the tall one first where a wide and a tall one
    remain; then any other rate a device may take where it also keeps rates that fit the swapped axes, as Vulkan
    allows."""
    if f"{w}x{h}" in supported:
        return (f"{w}x{h}",)
    sizes = {r: rate_size(r) for r in supported}

    def largest(fits: list[str]) -> list[str]:
        top = max(sizes[r][0] * sizes[r][1] for r in fits)
        fits = [r for r in fits if sizes[r][0] * sizes[r][1] == top]
        low = min(sum(sizes[r]) for r in fits)
        return [r for r in ALL_RATES if r in fits and sum(sizes[r]) == low]

    inside = largest([r for r, (rw, rh) in sizes.items() if rw <= w and rh <= h])
    swapped = largest([r for r, (rw, rh) in sizes.items() if (rw <= w and rh <= h) or (rw <= h and rh <= w)])
    return tuple(inside + [r for r in swapped if r not in inside])


def _combined(combiner: str, a: str, b: str, supported: tuple[str, ...]) -> tuple[str, ...]:
    """The rates a device may shade for rate ``a`` combined with ``b`` (both supported) by ``combiner``."""
    (aw, ah), (bw, bh) = rate_size(a), rate_size(b)
    w, h = {"passthrough": (aw, ah), "override": (bw, bh), "min": (min(aw, bw), min(ah, bh)),
            "max": (max(aw, bw), max(ah, bh)), "sum": (aw * bw, ah * bh)}[combiner]
    return _device_rates(w, h, supported)


def _rate_index(codes: object, supported: tuple[str, ...], name: str) -> np.ndarray:
    """Rate codes (an int, a name, or an integer array) as indices into :data:`ALL_RATES` (int8), each a rate of
    ``supported``, else a typed error naming ``name``."""
    if isinstance(codes, str):
        if codes not in RATE_CODES:
            raise ParameterError(f"{name}: unknown shading rate {codes!r}; expected a name from {', '.join(ALL_RATES)} "
                                 "or integer codes", name)
        codes = RATE_CODES[codes]
    try:
        array = np.asarray(codes)
    except (TypeError, ValueError, OverflowError) as err:  # ragged nested lists and the like
        raise InputDtypeError(f"{name}: expected shading-rate codes (integers), got {type(codes).__name__}") from err
    if array.dtype.kind not in "ui":
        raise InputDtypeError(f"{name}: expected shading-rate codes (integers, as the image holds them), got dtype "
                              f"{array.dtype}")
    table = np.full(257, -1, np.int8)  # (a code outside 0..255 maps onto the last, unknown, entry)
    for i, r in enumerate(ALL_RATES):
        table[RATE_CODES[r]] = i
    wide = array.astype(np.int64)
    index = table[np.where((wide >= 0) & (wide <= 255), wide, 256)]
    if (index < 0).any():
        bad = sorted({int(c) for c in array[index < 0].ravel()})[:8]
        raise ParameterError(f"{name}: unknown shading-rate code(s) {bad}; expected codes from {sorted(RATE_NAMES)}", name)
    odd = sorted({ALL_RATES[i] for i in np.unique(index)} - set(supported), key=ALL_RATES.index)
    if odd:
        raise ParameterError(f"{name}: {', '.join(f'{r} (code {RATE_CODES[r]})' for r in odd)} not among the rates "
                             f"allowed ({', '.join(supported)}): a device shades a rate of its own choice for it", name)
    return index


def combine_rates(
    a: RateLike | np.ndarray, b: RateLike | np.ndarray, combiner: str | int, *, allowed: Iterable[RateLike] | None = None
) -> np.ndarray:
    """The rates the hardware shades where rates ``a`` and ``b`` meet in a combiner: D3D12 tier 2's and Vulkan's
    ``combine(A, B)``, per tile. ``a`` is the combiner's first input (the per-draw or per-primitive rate, or an
    engine's own shading-rate image), ``b`` its second (rtp's image); codes (an int or a name broadcast over the
    other) or uint8 arrays of one shape. ``combiner`` is a name of :data:`COMBINERS` (or Vulkan's) or its enum
    value; ``min`` is the finer size per axis and ``max`` the coarser (the DirectX specification's "higher" and
    "lower quality"; so ``max`` of ``1x2`` and ``2x1`` is ``2x2``). ``allowed`` names the reduced rates the device
    supports (every one by default; 1x1 always): a combination outside them is clamped as Vulkan specifies (the
    largest supported rate inside it); where a device may choose a wide or a tall rate of one area (a 4x4 asked of
    a device without it) this returns the tall one, which saves as much. Returns uint8 codes of the broadcast shape.
    """
    op = _check_combiner(combiner)
    supported = ("1x1",) + resolve_allowed(allowed)
    ia, ib = _rate_index(a, supported, "a"), _rate_index(b, supported, "b")
    try:
        ia, ib = np.broadcast_arrays(ia, ib)
    except ValueError as err:
        raise InputShapeError(f"combine_rates: a {ia.shape} and b {ib.shape} do not broadcast to one shape of tiles",
                              actual=tuple(ib.shape), expected=str(ia.shape)) from err
    table = np.zeros((len(ALL_RATES), len(ALL_RATES)), np.uint8)
    for x in supported:
        for y in supported:
            table[ALL_RATES.index(x), ALL_RATES.index(y)] = RATE_CODES[_combined(op, x, y, supported)[0]]
    return table[ia, ib]


class _Combination(NamedTuple):
    """How rtp's image meets an engine's rates in the hardware, as tables over the engine's rate ``e`` (an index of
    :data:`ALL_RATES`) and the image's candidate rate ``j`` (an index of ``candidates``)."""

    #: The image's candidate rates: the allowed reduced rates cheapest first, then 1x1 (the fallback).
    candidates: tuple[str, ...]
    #: ``(7, J, 2)`` int8: the channel (:data:`PREDICTED_RATES`) of each rate the device may shade, twice where it is
    #: one; -1 for 1x1, which costs nothing to judge.
    channels: np.ndarray
    #: ``(7, J)`` int8: the area of the rate shaded (1, 2, 4, 8, 16).
    area: np.ndarray
    #: ``(7, J)`` uint8: the code the image holds for that choice: the rate shaded itself where combining it with
    #: the engine's gives it again (always with min and max), else the finest candidate that gives the same.
    image: np.ndarray
    #: ``(7, J)`` uint8: the code of the rate shaded (the tall one where a device may choose).
    shaded: np.ndarray


def _combination(combiner: str, rates: tuple[str, ...]) -> _Combination:
    """The tables of :class:`_Combination` for the image's allowed reduced ``rates`` and a combiner of min, max, sum."""
    supported = ("1x1",) + rates
    candidates = tuple(_classes(rates)) + ("1x1",)
    n, j = len(ALL_RATES), len(candidates)
    channels = np.full((n, j, 2), -1, np.int8)
    area = np.ones((n, j), np.int8)
    image = np.zeros((n, j), np.uint8)
    shaded = np.zeros((n, j), np.uint8)
    for e in supported:
        i = ALL_RATES.index(e)
        outcome = {c: _combined(combiner, e, c, supported) for c in candidates}
        for k, c in enumerate(candidates):
            got = outcome[c]
            channels[i, k] = [PREDICTED_RATES.index(r) if r != "1x1" else -1 for r in (got[0], got[-1])]
            area[i, k] = rate_size(got[0])[0] * rate_size(got[0])[1]
            same = [c2 for c2 in candidates if outcome[c2] == got]
            image[i, k] = RATE_CODES[got[0] if got[0] in same else min(same, key=lambda r: (
                rate_size(r)[0] * rate_size(r)[1], ALL_RATES.index(r)))]
            shaded[i, k] = RATE_CODES[got[0]]
    return _Combination(candidates, channels, area, image, shaded)


def _combined_values(err: np.ndarray, combo: _Combination, engine: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each candidate's oriented value and area per tile ``(..., J, th, tw)``: the value of the rate the device
    shades for it beside the ``engine``'s rates (indices into :data:`ALL_RATES`, the tiles' shape), the worse of
    two where a device may choose (NaN never passes), and -inf for 1x1."""
    # The engine's rates take a few values, and for each the candidates' channels are fixed: per value, its tiles'
    # six values gathered once, each candidate's value from their rows, and written back where those tiles lie.
    n, lead, (th, tw) = len(combo.candidates), err.shape[:-3], err.shape[-2:]
    flat = np.moveaxis(err.reshape((-1,) + err.shape[-3:]), 1, 0).reshape(err.shape[-3], -1)  # (6, N * th * tw)
    where = engine.reshape(-1)
    gathered = np.empty((n, where.size))
    for e in np.unique(where):
        spots = np.flatnonzero(where == e)
        sub = flat[:, spots] if spots.size < where.size else flat
        for k, (a, b) in enumerate(combo.channels[e]):
            gathered[k, spots] = (-np.inf if a < 0 else sub[a] if a == b else np.maximum(sub[a], sub[b]))
    values = np.moveaxis(gathered.reshape((n, -1, th, tw)), 0, 1).reshape(lead + (n, th, tw))
    return values, np.moveaxis(combo.area.T[:, engine], 0, -3)


def check_engine_rates(engine_rates: object, combiner: object, allowed: Iterable[RateLike] | None,
                       tiles: tuple[int, ...]) -> None:
    """A typed error where :func:`select_rates` would refuse ``engine_rates`` or ``combiner`` for predictions of
    ``tiles`` ``(..., th, tw)`` (a caller that must refuse before it changes state checks first)."""
    _engine_rates(engine_rates, combiner, resolve_allowed(allowed), tiles)


def _engine_rates(engine_rates: object, combiner: object, rates: tuple[str, ...],
                  tiles: tuple[int, ...]) -> tuple[_Combination, np.ndarray] | None:
    """``engine_rates`` checked and broadcast over predictions' ``tiles`` shape ``(..., th, tw)``, with the tables
    of ``combiner``; None without engine rates. Typed errors name the argument."""
    op = _check_combiner(combiner, selecting=True)  # (checked without engine rates too: a typo is named at once)
    if engine_rates is None:
        return None
    index = _rate_index(engine_rates, ("1x1",) + rates, "engine_rates")
    try:
        index = np.broadcast_to(index, tiles)
    except ValueError as err:
        raise InputShapeError(f"engine_rates: shape {index.shape} does not broadcast over the predictions' tiles "
                              f"{tiles} (one code, a (th, tw) image, or one a frame)", actual=tuple(index.shape),
                              expected=str(tiles)) from err
    return _combination(op, rates), index


#: The most a shading-rate image can save: every tile at 4x4.
MAX_SAVING = 1.0 - 1.0 / 16


class SavingSelection(NamedTuple):
    """What :func:`select_rates_for_saving` chose: the rates, the threshold they pass and the work they save.

    For a batch ``(N, 6, th, tw)`` of predictions ``threshold`` and ``saved`` are arrays of ``N``, one per frame."""

    #: uint8 D3D12/Vulkan codes ``(th, tw)`` (``(N, th, tw)``), as :func:`select_rates` returns them.
    rates: np.ndarray
    #: The lowest threshold whose rates save the work asked for (metric units; dB for PSNR, the highest):
    #: ``select_rates(values, threshold, ...)`` gives ``rates`` again (a batch's: ``select_rates(values[i],
    #: threshold[i], ...)`` gives ``rates[i]``; ``select_rates`` takes one threshold, a number).
    threshold: float | np.ndarray
    #: The fraction of the shading work ``rates`` saves (:func:`work_saved`): at least the saving asked for
    #: unless the predictions hold values no threshold passes: NaN, an error of +inf or past :data:`MAX_THRESHOLD`
    #: (a PSNR of -inf or below ``-MAX_THRESHOLD``), or beside ``engine_rates`` that cap what the image can add
    #: (``min`` with an engine's finer rate); then the most any threshold saves, at the lowest threshold that does.
    saved: float | np.ndarray


def check_saving(saving: object, rates: tuple[str, ...]) -> float:
    """``saving`` as a float if it is a share of the shading work the ``rates`` allowed can save, else
    :class:`ParameterError`: a number in ``[0, 1 - 1/area]`` of the coarsest allowed rate (0.9375 with 4x4)."""
    top = max((1.0 - 1.0 / (rate_size(r)[0] * rate_size(r)[1]) for r in rates), default=0.0)
    value = math.nan
    if not isinstance(saving, (bool, np.bool_)) and isinstance(saving, (int, float, np.integer, np.floating)):
        try:
            value = float(saving)
        except OverflowError:  # an int too large for a float: out of range all the same
            pass
    if not 0.0 <= value <= top:  # NaN fails too
        why = (f"the coarsest allowed rate, {_classes(rates)[0]}, saves {top:g}" if rates else
               "only 1x1 is allowed, which saves nothing")
        raise ParameterError(f"saving: expected the share of shading work to save, a number in [0, {top:g}] ({why}), "
                             f"got {reprlib.repr(saving)}", "saving")
    return value


def select_rates_for_saving(
    values: np.ndarray,
    saving: float,
    *,
    higher_is_better: bool = False,
    allowed: Iterable[RateLike] | None = None,
    factors: Mapping[str, float] | Iterable[float] | None = None,
    frame_size: tuple[int, int] | None = None,
    tile_size: int | None = None,
    threshold: float | None = None,
    engine_rates: RateLike | np.ndarray | None = None,
    combiner: str | int = "max",
) -> SavingSelection:
    """Rates that save at least ``saving`` of the shading work with the least visible error: a budget.

    :func:`select_rates` holds the quality (a threshold) and lets the work saved follow the frame; this
    holds the work (as dynamic resolution holds the frame time) and lets the quality follow. Per frame it
    finds the lowest threshold (the highest, for PSNR) whose :func:`select_rates` choice saves ``saving``
    or more, exactly, from the predictions alone: the worst predicted tile is as good as any choice of
    that saving allows, and every tile passes that threshold. ``saving`` is a share of the full-rate work
    in ``[0, 0.9375]`` (4x4 everywhere; less where ``allowed`` leaves out the coarse rates); 0 gives 1x1
    everywhere (but on a tile whose predicted error is below 0: it passes the lowest threshold, 0). ``values``,
    ``higher_is_better``, ``allowed`` and ``factors`` are :func:`select_rates`'s;
    ``frame_size = (H, W)`` and ``tile_size`` weigh partial edge tiles by their pixels, as in
    :func:`work_saved` (without them every tile counts alike). Returns a :class:`SavingSelection`.

    With a ``threshold`` too, the saving is a floor under it: the threshold's own rates on a frame where they
    save ``saving`` or more, else the budget's (the rates at the higher of the two thresholds; for PSNR, the
    lower): the quality held while the frame allows it, the work saved never below the floor.

    With ``engine_rates`` and a ``combiner`` (:func:`select_rates`'s), the saving is the frame's, the engine's
    and the image's together, as the device shades it: where the engine's rates save some already, the image
    adds only what is missing, at the lowest threshold that does; ``saved`` is the combined figure and ``rates``
    the image to upload.
    """
    values, hib = _check_values(values, higher_is_better)
    rates = resolve_allowed(allowed)
    target = check_saving(saving, rates)
    floor_under = None if threshold is None else check_threshold(threshold, hib)
    err = _oriented(values, hib, check_rate_factors(factors))
    th, tw = values.shape[-2:]
    weights = _tile_pixels("select_rates_for_saving", (th, tw), frame_size, tile_size)
    if 0 in values.shape:
        raise InputShapeError(f"select_rates_for_saving: expected predictions of at least one tile, got shape "
                              f"{values.shape}", actual=tuple(values.shape), expected="(..., 6, th, tw)")
    combo = _engine_rates(engine_rates, combiner, rates, values.shape[:-3] + (th, tw))
    engines = None if combo is None else combo[1].reshape((-1, th, tw))
    frames = err.reshape((-1,) + err.shape[-3:])
    picked = np.empty((len(frames), th, tw), np.uint8)
    thresholds = np.empty(len(frames))
    saved = np.empty(len(frames))
    table = np.zeros(256)
    for r in PREDICTED_RATES:
        table[RATE_CODES[r]] = 1.0 - 1.0 / (rate_size(r)[0] * rate_size(r)[1])
    for i, frame in enumerate(frames):
        if engines is None or combo is None:
            thr = _lowest_threshold(frame, rates, weights, target, hib)
        else:
            candidates, area = _combined_values(frame, combo[0], engines[i])
            thr = _lowest_threshold_shaded(candidates, area, weights, target, hib)
        if floor_under is not None:  # (a floor under a threshold: the threshold unless it saves less)
            thr = max(thr, -floor_under if hib else floor_under)
        if engines is None or combo is None:
            picked[i] = shaded = _pick(frame, thr, rates)
        else:
            picked[i], shaded = _pick_combined(candidates, area, thr, combo[0], engines[i])
        thresholds[i] = -thr if hib else thr
        saved[i] = float((table[shaded] * weights).sum() / weights.sum())
    lead = values.shape[:-3]
    if not lead:
        return SavingSelection(picked[0], float(thresholds[0]), float(saved[0]))
    return SavingSelection(picked.reshape(lead + (th, tw)), thresholds.reshape(lead), saved.reshape(lead))


def _lowest_threshold(err: np.ndarray, rates: tuple[str, ...], weights: np.ndarray, target: float, hib: bool) -> float:
    """The lowest oriented threshold at which :func:`_pick` saves ``target`` of the (weighted) work of one
    frame's oriented values ``err`` ``(6, th, tw)``.

    A tile's saving only grows with the threshold, one step per cost class: it saves at least class ``k``'s
    share once the threshold passes ``T_k``, the smallest value of the allowed rates that cost no more than
    class ``k``. So the frame's saving is a sum of steps, one per tile and class, and the lowest threshold
    that reaches the target is just above the step where the sorted, weighted steps add up to it."""
    lo = 0.0 if not hib else -MAX_THRESHOLD  # the oriented thresholds check_threshold allows
    hi = MAX_THRESHOLD
    order = _classes(rates)
    classes = sorted({rate_size(r)[0] * rate_size(r)[1] for r in order})  # dearest (smallest area) first
    if not classes or target <= 0.0:  # nothing needs to pass (or can): the lowest threshold
        return lo
    clean = np.where(np.isnan(err), np.inf, err)  # (NaN never passes)
    steps = np.empty((len(classes),) + err.shape[1:])  # T_k: the best of class k and every cheaper one
    for k in range(len(classes) - 1, -1, -1):  # (cheapest first, each a contiguous plane)
        rows = [clean[PREDICTED_RATES.index(r)] for r in order if rate_size(r)[0] * rate_size(r)[1] == classes[k]]
        best = rows[0] if len(rows) == 1 else np.minimum(rows[0], rows[1])  # (a class has one rate or two)
        if k + 1 < len(classes):
            np.minimum(best, steps[k + 1], out=steps[k])
        else:
            steps[k] = best
    return _threshold_reaching(steps, classes, weights, target, lo, hi)


def _lowest_threshold_shaded(values: np.ndarray, area: np.ndarray, weights: np.ndarray, target: float,
                             hib: bool) -> float:
    """:func:`_lowest_threshold` where the image meets an engine's rates: from each candidate's oriented value and
    the area of the rate the device shades for it (:func:`_combined_values`, one frame ``(J, th, tw)``; the last
    candidate, 1x1, gives the engine's rates alone). A tile saves what the engine's rates force at any threshold,
    and more from class ``k`` on once the threshold passes the smallest value of the candidates shading that class
    or a cheaper one."""
    lo = 0.0 if not hib else -MAX_THRESHOLD
    classes = sorted(int(a) for a in np.unique(area) if a > 1)  # dearest first
    if not classes or target <= 0.0:
        return lo
    clean = np.where(np.isnan(values), np.inf, values)
    steps = np.empty((len(classes),) + values.shape[1:])
    for k in range(len(classes) - 1, -1, -1):  # (cheapest first)
        best = np.where(area == classes[k], clean, np.inf).min(axis=0)
        steps[k] = best if k + 1 == len(classes) else np.minimum(best, steps[k + 1])
    forced = 1.0 - 1.0 / area[-1].astype(np.float64)  # (the 1x1 candidate: what the engine's rates save alone)
    return _threshold_reaching(steps, classes, weights, target, lo, MAX_THRESHOLD, forced)


def _threshold_reaching(steps: np.ndarray, classes: list[int], weights: np.ndarray, target: float, lo: float,
                        hi: float, forced: np.ndarray | None = None) -> float:
    """The lowest oriented threshold in ``[lo, hi]`` past which the tiles' steps ``(K, th, tw)`` (class ``k``'s share
    from ``steps[k]`` on; ``classes`` their areas, dearest first) save ``target`` of the ``weights``' work, on top of
    what each tile saves at any threshold (``forced``, none by default); the most the frame can save where less."""
    share = np.array([1.0 - 1.0 / a for a in classes])
    need = target * weights.sum() * (1.0 - 1e-12)  # (a rounding's worth short counts as reached)
    if forced is None:
        gain = np.diff(share, prepend=0.0)[:, None, None] * weights  # each step's share of the frame's work
    else:  # (a step adds only what the tile does not save already)
        lifted = np.maximum(share[:, None, None], forced)
        gain = np.diff(lifted, axis=0, prepend=forced[None]) * weights
        need -= float((forced * weights).sum())
        if need <= 0.0:
            return lo
    at, gain = steps.ravel(), gain.ravel()
    # (a NaN, an infinite value or one at or past the highest threshold never passes: no step, else a frame that
    # cannot reach the target would report that highest threshold rather than the lowest saving what it can)
    useful = (at < hi) & (gain > 0.0)
    at, gain = at[useful], gain[useful]
    if float(gain.sum()) < need:  # NaN tiles: the most the frame can save, just past its last step
        return float(np.clip(np.nextafter(at.max(), np.inf), lo, hi)) if at.size else lo
    return float(np.clip(np.nextafter(_weighted_select(at, gain, need), np.inf), lo, hi))


def _weighted_select(values: np.ndarray, weights: np.ndarray, need: float) -> float:
    """The smallest of ``values`` at which the ``weights`` of the values up to it add up to ``need`` (<= their sum):
    a weighted quantile, by partitions that each keep at most three quarters of the values (O(n), where sorting
    the 32,400 steps of a 1080p frame on 8-pixel tiles took the most of a budget's time), then a sort of the rest.

    After a partition at k the k smallest values hold weight ``left``: where ``below + left`` reaches the need,
    the answer is among them (a value equal to the pivot on the other side only adds to a sum that already
    reaches it); else it is among the rest, with ``left`` added to the weight below them."""
    below = 0.0
    while values.size > 256:
        n = values.size
        guess = (need - below) / float(weights.mean())  # (where the answer would be, were the weights alike)
        k = int(min(max(guess, n / 4), 3 * n / 4))
        part = np.argpartition(values, k)
        low = part[:k]
        left = float(weights[low].sum())
        if below + left >= need:
            values, weights = values[low], weights[low]
        else:
            below += left
            values, weights = values[part[k:]], weights[part[k:]]
    order = np.argsort(values, kind="stable")
    total = below + np.cumsum(weights[order])
    j = min(int(np.searchsorted(total, need, side="left")), values.size - 1)
    return float(values[order][j])
