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
    "MAX_RATE_FACTOR",
    "MAX_SAVING",
    "MAX_THRESHOLD",
    "PREDICTED_RATES",
    "RATE_CODES",
    "RATE_NAMES",
    "RateLike",
    "SavingSelection",
    "check_rate_factors",
    "check_threshold",
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
    values, hib = _check_values(values, higher_is_better)
    rates = resolve_allowed(allowed)
    threshold = check_threshold(threshold, hib)
    err = _oriented(values, hib, check_rate_factors(factors))
    return _pick(err, -threshold if hib else threshold, rates)


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
    passing = e < thr
    best = np.where(passing, rank[:, None, None], np.int8(len(order))).min(axis=-3, keepdims=True)
    pick = np.where(passing & (rank[:, None, None] == best), e, np.inf).argmin(axis=-3)
    codes = np.array([RATE_CODES[r] for r in order], np.uint8)
    return np.where(best[..., 0, :, :] < len(order), codes[pick], np.uint8(RATE_CODES["1x1"]))


#: The most a shading-rate image can save: every tile at 4x4.
MAX_SAVING = 1.0 - 1.0 / 16


class SavingSelection(NamedTuple):
    """What :func:`select_rates_for_saving` chose: the rates, the threshold they pass and the work they save.

    For a batch ``(N, 6, th, tw)`` of predictions ``threshold`` and ``saved`` are arrays of ``N``, one per frame."""

    #: uint8 D3D12/Vulkan codes ``(th, tw)`` (``(N, th, tw)``), as :func:`select_rates` returns them.
    rates: np.ndarray
    #: The lowest threshold whose rates save the work asked for (metric units; dB for PSNR, the highest):
    #: ``select_rates(values, threshold, ...)`` gives ``rates`` again.
    threshold: float | np.ndarray
    #: The fraction of the shading work ``rates`` saves (:func:`work_saved`): at least the saving asked for
    #: unless the predictions hold NaN, which never passes.
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
) -> SavingSelection:
    """Rates that save at least ``saving`` of the shading work with the least visible error: a budget.

    :func:`select_rates` holds the quality (a threshold) and lets the work saved follow the frame; this
    holds the work (as dynamic resolution holds the frame time) and lets the quality follow. Per frame it
    finds the lowest threshold (the highest, for PSNR) whose :func:`select_rates` choice saves ``saving``
    or more, exactly, from the predictions alone: the worst predicted tile is as good as any choice of
    that saving allows, and every tile passes that threshold. ``saving`` is a share of the full-rate work
    in ``[0, 0.9375]`` (4x4 everywhere; less where ``allowed`` leaves out the coarse rates); 0 gives 1x1
    everywhere. ``values``, ``higher_is_better``, ``allowed`` and ``factors`` are :func:`select_rates`'s;
    ``frame_size = (H, W)`` and ``tile_size`` weigh partial edge tiles by their pixels, as in
    :func:`work_saved` (without them every tile counts alike). Returns a :class:`SavingSelection`.

    With a ``threshold`` too, the saving is a floor under it: the threshold's own rates on a frame where they
    save ``saving`` or more, else the budget's (the rates at the higher of the two thresholds; for PSNR, the
    lower): the quality held while the frame allows it, the work saved never below the floor.
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
    frames = err.reshape((-1,) + err.shape[-3:])
    picked = np.empty((len(frames), th, tw), np.uint8)
    thresholds = np.empty(len(frames))
    saved = np.empty(len(frames))
    table = np.zeros(256)
    for r in PREDICTED_RATES:
        table[RATE_CODES[r]] = 1.0 - 1.0 / (rate_size(r)[0] * rate_size(r)[1])
    for i, frame in enumerate(frames):
        thr = _lowest_threshold(frame, rates, weights, target, hib)
        if floor_under is not None:  # (a floor under a threshold: the threshold unless it saves less)
            thr = max(thr, -floor_under if hib else floor_under)
        picked[i] = _pick(frame, thr, rates)
        thresholds[i] = -thr if hib else thr
        saved[i] = float((table[picked[i]] * weights).sum() / weights.sum())
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
    share = np.array([1.0 - 1.0 / a for a in classes])
    gain = np.diff(share, prepend=0.0)[:, None, None] * weights  # each step's share of the frame's work
    need = target * weights.sum() * (1.0 - 1e-12)  # (a rounding's worth short counts as reached)
    at, gain = steps.ravel(), gain.ravel()
    reachable = at < np.inf  # (a NaN or an infinite value never passes)
    if float(np.dot(gain, reachable)) < need:  # NaN tiles: the most the frame can save, just past its last step
        return float(np.clip(np.nextafter(at[reachable].max(), np.inf), lo, hi)) if reachable.any() else lo
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
