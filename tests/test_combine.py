"""The engine's own rates beside rtp's: the hardware's combiners (``sdk.combine_rates``) and selections that judge
the rate the device will shade (``select_rates(engine_rates=, combiner=)``, the budget's too)."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from rtp import sdk
from rtp.sdk._rates import MAX_THRESHOLD, PREDICTED_RATES, RATE_CODES, RATE_NAMES, rate_size

from .test_predictor import base_metadata

C = RATE_CODES


def _values(**per_rate: float) -> np.ndarray:
    """One tile's predictions ``(6, 1, 1)``: 1.0 (failing any threshold below it) unless given, by name (``r1x2``)."""
    v = np.ones((6, 1, 1))
    for key, value in per_rate.items():
        v[PREDICTED_RATES.index(key[1:]), 0, 0] = value
    return v


@pytest.mark.parametrize(("a", "b", "combiner", "want"), [
    ("1x2", "2x1", "min", "1x1"),  # the DirectX specification's own example: per axis, not the enum
    ("1x2", "2x1", "max", "2x2"),  # a rate neither input holds
    ("1x2", "2x1", "sum", "2x2"),
    ("2x2", "2x2", "sum", "4x4"),
    ("2x4", "4x2", "min", "2x2"),
    ("2x4", "1x2", "max", "2x4"),
    ("2x1", "4x4", "passthrough", "2x1"),
    ("2x1", "4x4", "override", "4x4"),
    ("1x2", "1x2", "sum", "1x2"),  # 1x4 exists nowhere: the largest supported rate inside it
    ("2x4", "1x2", "sum", "2x4"),  # 2x8: clamped to 4 on the long axis
    ("4x2", "4x4", "mul", "4x4"),  # Vulkan's name for the same combiner
    ("1x1", "2x4", "keep", "1x1"),
    ("1x1", "2x4", "replace", "2x4"),
    ("4x4", "1x1", 3, "4x4"),  # the enum value (D3D12 and Vulkan share them): 3 is max
    ("4x4", "1x1", "MIN", "1x1"),
])
def test_combine_rates_follows_the_specifications(a: str, b: str, combiner: str | int, want: str) -> None:
    got = sdk.combine_rates(C[a], C[b], combiner)
    assert RATE_NAMES[int(got)] == want
    assert RATE_NAMES[int(sdk.combine_rates(a, b, combiner))] == want  # names work as codes do


def test_the_commutative_combiners_and_their_laws() -> None:
    """min and max are each other's dual and idempotent, sum's 1x1 is neutral: over every pair of rates."""
    for a, b in itertools.product(sdk.ALL_RATES, repeat=2):
        (aw, ah), (bw, bh) = rate_size(a), rate_size(b)
        for op in ("min", "max", "sum"):
            assert sdk.combine_rates(a, b, op) == sdk.combine_rates(b, a, op)
        assert RATE_NAMES[int(sdk.combine_rates(a, b, "min"))] == f"{min(aw, bw)}x{min(ah, bh)}"
        assert RATE_NAMES[int(sdk.combine_rates(a, b, "max"))] == f"{max(aw, bw)}x{max(ah, bh)}"
        assert sdk.combine_rates(a, a, "max") == C[a] and sdk.combine_rates(a, "1x1", "sum") == C[a]


def test_a_device_without_some_rates_clamps_the_combination() -> None:
    """Without the additional rates (D3D12's AdditionalShadingRatesSupported off) nothing exceeds 2 on an axis; a
    combination the device lacks becomes the largest supported rate inside it, the tall one on a wide/tall tie."""
    basic = ["1x2", "2x1", "2x2"]
    assert sdk.combine_rates("2x2", "2x2", "sum", allowed=basic) == C["2x2"]  # D3D12: min(maxRate, A + B)
    assert sdk.combine_rates("2x1", "2x1", "sum", allowed=basic) == C["2x1"]
    no_quad = ["1x2", "2x1", "2x2", "2x4", "4x2"]
    assert sdk.combine_rates("2x4", "4x2", "max", allowed=no_quad) == C["2x4"]  # 4x4 asked: 2x4 or 4x2, as cheap
    assert sdk.combine_rates("1x2", "2x1", "max", allowed=["1x2", "2x1", "4x4"]) == C["1x2"]  # (no 2x2)
    image = np.array([[0, 1, 4], [5, 6, 9]], np.uint8)
    out = sdk.combine_rates(C["2x1"], image, "max")  # one rate broadcast over an image
    assert out.dtype == np.uint8 and out.shape == (2, 3)
    assert [RATE_NAMES[int(c)] for c in out.ravel()] == ["2x1", "2x2", "2x1", "2x2", "2x4", "4x2"]


def test_combine_rates_refuses_what_no_device_takes() -> None:
    with pytest.raises(sdk.ParameterError, match=r"combiner: expected one of passthrough, override, min, max, sum"):
        sdk.combine_rates(0, 5, "average")
    with pytest.raises(sdk.ParameterError, match="combiner"):
        sdk.combine_rates(0, 5, 5)  # enum values stop at 4 (sum, Vulkan's mul)
    with pytest.raises(sdk.ParameterError, match=r"unknown shading-rate code\(s\) \[3\]"):
        sdk.combine_rates(np.array([[0, 3]], np.uint8), 5, "max")
    with pytest.raises(sdk.ParameterError, match=r"b: 4x4 \(code 10\) not among the rates allowed"):
        sdk.combine_rates(0, 10, "max", allowed=["1x2", "2x1", "2x2"])
    with pytest.raises(sdk.InputDtypeError, match="expected shading-rate codes"):
        sdk.combine_rates(np.zeros((2, 2)), 5, "max")
    with pytest.raises(sdk.InputShapeError, match="do not broadcast"):
        sdk.combine_rates(np.zeros((2, 3), np.uint8), np.zeros((3, 2), np.uint8), "max")


def test_a_selection_judges_the_rate_the_device_shades() -> None:
    """With the engine's 2x1 meeting the image in a max combiner, a 1x2 that passes alone would be shaded 2x2:
    the selection takes 2x2 only where 2x2 passes, else the engine's own 2x1 (its image then 2x1: with min and max
    the image holds the rate shaded)."""
    mixed = _values(r1x2=0.1, r2x1=0.15, r2x2=0.5)  # 1x2 passes 0.2 alone, 2x2 does not
    assert sdk.select_rates(mixed, 0.2) == C["1x2"]
    assert sdk.combine_rates("2x1", sdk.select_rates(mixed, 0.2), "max") == C["2x2"]  # unaware: never judged
    aware = sdk.select_rates(mixed, 0.2, engine_rates=C["2x1"], combiner="max")
    assert aware == C["2x1"] and sdk.combine_rates("2x1", aware, "max") == C["2x1"]
    both = _values(r1x2=0.1, r2x1=0.15, r2x2=0.18)
    assert sdk.select_rates(both, 0.2, engine_rates="2x1", combiner="max") == C["2x2"]
    # a ceiling (min): the engine's 2x2 caps a 4x4 that passes; where 2x2 itself fails, the best finer one
    cheap = _values(r1x2=0.1, r2x1=0.05, r2x2=0.1, r4x4=0.1)
    assert sdk.select_rates(cheap, 0.2, engine_rates="2x2", combiner="min") == C["2x2"]
    odd = _values(r1x2=0.1, r2x1=0.05, r2x2=0.5, r4x4=0.1)  # (predictions need not be monotone)
    assert sdk.select_rates(odd, 0.2) == C["4x4"]
    assert sdk.combine_rates("2x2", C["4x4"], "min") == C["2x2"]  # unaware: a 2x2 that fails
    assert sdk.select_rates(odd, 0.2, engine_rates="2x2", combiner="min") == C["2x1"]
    # sum: the image holds what multiplies the engine's rate up to the rate judged
    want_quad = _values(r2x2=0.1)
    assert sdk.select_rates(want_quad, 0.2, engine_rates="2x1", combiner="sum") == C["1x2"]
    assert sdk.select_rates(want_quad, 0.2, engine_rates="2x1", combiner=4) == C["1x2"]  # (the enum value)
    # nothing passes: the engine's rate is shaded all the same (the image holds it, as every rate shaded with max)
    assert sdk.select_rates(_values(), 0.2, engine_rates="2x1", combiner="max") == C["2x1"]
    assert sdk.select_rates(_values(), 0.2, engine_rates="2x1", combiner="sum") == C["1x1"]  # (sum: 1x1 adds nothing)
    # PSNR: higher is better, the same judgement
    psnr = 40.0 - 30.0 * mixed
    assert sdk.select_rates(psnr, 30.0, higher_is_better=True, engine_rates="2x1", combiner="max") == C["2x1"]


def _clamp(size: dict[str, tuple[int, int]], fits: Callable[[int, int], bool]) -> list[str]:
    """Of the rates ``size`` lists that ``fits``, those of the largest area and then the lowest W + H."""
    kept = [r for r, (w, h) in size.items() if fits(w, h)]
    kept = [r for r in kept if size[r][0] * size[r][1] == max(size[k][0] * size[k][1] for k in kept)]
    return [r for r in sdk.ALL_RATES if r in kept and sum(size[r]) == min(sum(size[k]) for k in kept)]


def _exhaustive(values: np.ndarray, thr: float, allowed: list[str], engine: np.ndarray, op: str) -> np.ndarray:
    """Per tile, every image rate tried, the combination and the device's clamp worked out here afresh: the
    cheapest rate shaded whose prediction (the worse of two where a device may choose) passes, then the better
    value, then one shaded as judged; else the engine's rate alone. Returns the codes shaded (the tall one of two)."""
    supported = ("1x1",) + sdk.resolve_allowed(allowed)
    size = {r: rate_size(r) for r in supported}
    out = np.zeros(values.shape[1:], np.uint8)
    for y, x in np.ndindex(*values.shape[1:]):
        ew, eh = rate_size(RATE_NAMES[int(engine[y, x])])
        best: tuple[tuple[float, ...], str] | None = None
        for r in supported:
            rw, rh = size[r]
            w, h = {"min": (min(ew, rw), min(eh, rh)), "max": (max(ew, rw), max(eh, rh)), "sum": (ew * rw, eh * rh)}[op]
            may = [f"{w}x{h}"] if f"{w}x{h}" in supported else (
                _clamp(size, lambda sw, sh: sw <= w and sh <= h)  # noqa: B023 (used at once)
                + _clamp(size, lambda sw, sh: (sw <= w and sh <= h) or (sw <= h and sh <= w)))  # noqa: B023
            top = size[may[0]][0] * size[may[0]][1]
            vals = [-np.inf if s == "1x1" else values[PREDICTED_RATES.index(s), y, x] for s in may]
            value = np.nan if np.isnan(vals).any() else max(vals)
            key = (0.0, -top, value, len(may) > 1) if value < thr else ((1.0, 0.0, 0.0, 0.0) if r == "1x1" else None)
            if key is not None and (best is None or key < best[0]):
                best = (key, may[0])
        assert best is not None
        out[y, x] = C[best[1]]
    return out


def test_a_selection_with_engine_rates_is_the_exhaustive_one() -> None:
    """On random predictions (NaN too), allowed sets, engine images and combiners, the rate the device shades is
    the one trying every image rate finds; an engine image of 1x1 under max or sum changes nothing."""
    rng = np.random.default_rng(7)
    for trial in range(120):
        values = rng.random((6, 3, 4))
        if trial % 4 == 0:
            values[rng.random(values.shape) < 0.15] = np.nan
        thr = float(rng.random())
        allowed = [r for r in PREDICTED_RATES if rng.random() < 0.75]
        supported = ("1x1",) + sdk.resolve_allowed(allowed)
        engine = rng.choice([C[r] for r in supported], size=(3, 4)).astype(np.uint8)
        op = ("min", "max", "sum")[trial % 3]
        image = sdk.select_rates(values, thr, allowed=allowed, engine_rates=engine, combiner=op)
        shaded = sdk.combine_rates(engine, image, op, allowed=allowed)
        np.testing.assert_array_equal(shaded, _exhaustive(values, thr, allowed, engine, op), err_msg=f"{trial} {op}")
        plain = sdk.select_rates(values, thr, allowed=allowed)
        for neutral in ("max", "sum"):
            np.testing.assert_array_equal(sdk.select_rates(values, thr, allowed=allowed, engine_rates=0,
                                                           combiner=neutral), plain)


def test_engine_rates_one_a_frame_and_their_errors() -> None:
    rng = np.random.default_rng(3)
    batch = rng.random((2, 6, 3, 4))
    engine = np.stack([np.full((3, 4), C["2x1"]), np.full((3, 4), C["1x2"])]).astype(np.uint8)
    together = sdk.select_rates(batch, 0.5, engine_rates=engine, combiner="max")
    for i in range(2):
        np.testing.assert_array_equal(together[i], sdk.select_rates(batch[i], 0.5, engine_rates=engine[i],
                                                                    combiner="max"))
    with pytest.raises(sdk.InputShapeError, match=r"engine_rates: shape \(2, 2\) does not broadcast"):
        sdk.select_rates(batch[0], 0.5, engine_rates=np.zeros((2, 2), np.uint8))
    with pytest.raises(sdk.ParameterError, match="passthrough keeps the engine's rate"):
        sdk.select_rates(batch[0], 0.5, engine_rates=0, combiner="passthrough")
    with pytest.raises(sdk.ParameterError, match=r"engine_rates: 4x4 \(code 10\) not among the rates allowed"):
        sdk.select_rates(batch[0], 0.5, engine_rates=10, allowed=["1x2", "2x1", "2x2"])
    with pytest.raises(sdk.ParameterError, match=r"engine_rates: unknown shading-rate code\(s\) \[300\]"):
        sdk.select_rates(batch[0], 0.5, engine_rates=300)
    with pytest.raises(sdk.InputDtypeError, match="engine_rates: expected shading-rate codes"):
        sdk.select_rates(batch[0], 0.5, engine_rates=np.full((3, 4), 0.5))


def test_a_budget_counts_the_engine_saving() -> None:
    """A foveated periphery at 4x4 saves part of the budget already: the image adds only the rest, at the lowest
    threshold that does, and ``saved`` is what the device's rates save together."""
    rng = np.random.default_rng(5)
    values = rng.random((6, 4, 8))
    fovea = np.full((4, 8), C["4x4"], np.uint8)
    fovea[1:3, 2:6] = C["1x1"]  # the centre at full rate: the periphery (24 of 32 tiles) saves 0.703
    periphery = sdk.work_saved(fovea)
    assert periphery == pytest.approx(24 / 32 * 0.9375)
    within = sdk.select_rates_for_saving(values, 0.6, engine_rates=fovea, combiner="max")
    assert within.threshold == 0.0 and within.saved == pytest.approx(periphery)  # (met: nothing else reduced)
    assert (within.rates[fovea == C["1x1"]] == C["1x1"]).all()
    more = sdk.select_rates_for_saving(values, 0.85, engine_rates=fovea, combiner="max")
    shaded = sdk.combine_rates(fovea, more.rates, "max")
    assert more.saved == pytest.approx(sdk.work_saved(shaded)) and more.saved >= 0.85
    unaware = sdk.select_rates_for_saving(values, 0.85)  # counting the periphery again: the centre reduced more
    assert sdk.work_saved(sdk.combine_rates(fovea, unaware.rates, "max")) > more.saved
    np.testing.assert_array_equal(sdk.select_rates(values, more.threshold, engine_rates=fovea), more.rates)
    # the lowest threshold: a hair below it the device saves less than asked
    lower = np.nextafter(np.nextafter(more.threshold, -np.inf), -np.inf)
    below = sdk.combine_rates(fovea, sdk.select_rates(values, lower, engine_rates=fovea), "max")
    assert sdk.work_saved(below) < 0.85


def test_a_budget_with_engine_rates_is_exact_on_random_frames() -> None:
    rng = np.random.default_rng(11)
    for trial in range(150):
        th, tw = (int(n) for n in rng.integers(1, 6, 2))
        values = rng.random((6, th, tw))
        if trial % 5 == 0:
            values[rng.random(values.shape) < 0.2] = np.nan
        allowed = [r for r in PREDICTED_RATES if rng.random() < 0.8] or ["2x2"]
        supported = ("1x1",) + sdk.resolve_allowed(allowed)
        engine = rng.choice([C[r] for r in supported], size=(th, tw)).astype(np.uint8)
        op = ("min", "max", "sum")[trial % 3]
        top = max(sdk.work_saved(r) for r in supported)
        saving = float(rng.random() * top)
        frame = (th * 16 - int(rng.integers(0, 15)), tw * 16 - int(rng.integers(0, 15)))
        kw = {"allowed": allowed, "engine_rates": engine, "combiner": op}
        sel = sdk.select_rates_for_saving(values, saving, frame_size=frame, tile_size=16, **kw)
        np.testing.assert_array_equal(sdk.select_rates(values, sel.threshold, **kw), sel.rates)
        shaded = sdk.combine_rates(engine, sel.rates, op, allowed=allowed)
        assert sel.saved == pytest.approx(sdk.work_saved(shaded, frame, 16), abs=1e-12)
        most = sdk.work_saved(sdk.combine_rates(engine, sdk.select_rates(values, MAX_THRESHOLD, **kw), op,
                                                allowed=allowed), frame, 16)
        assert sel.saved >= min(saving, most) - 1e-9
        if sel.threshold > 0 and sel.saved >= saving:
            lower = np.nextafter(np.nextafter(sel.threshold, -np.inf), -np.inf)
            below = sdk.combine_rates(engine, sdk.select_rates(values, lower, **kw), op, allowed=allowed)
            assert sdk.work_saved(below, frame, 16) < saving


def test_the_predictor_takes_the_engine_rates(tiny_model: Callable[..., Path]) -> None:
    p = sdk.load(tiny_model(base_metadata(default_threshold=0.3)))
    x = np.full((4, 16, 48), -10.0, np.float32)  # tiny errors ...
    x[:, :, 32:] = 10.0  # ... and one tile failing at every rate
    engine = np.array([[C["1x1"], C["2x1"], C["2x1"]]], np.uint8)
    assert p.shading_rates(x).tolist() == [[10, 10, 0]]
    assert p.shading_rates(x, engine_rates=engine).tolist() == [[10, 10, 4]]  # (max: the failing tile shades 2x1)
    assert p.shading_rates(x, engine_rates=engine, combiner="min").tolist() == [[0, 4, 0]]  # a ceiling (1x1 on the first)
    # sum: 4x4 times the engine's 2x1 asks 8x4, clamped to 4x4 again; the failing tile asks nothing (1x1)
    assert p.shading_rates(x, engine_rates=engine, combiner="sum").tolist() == [[10, 10, 0]]
    # a budget counts the engine's 2x1 on the failing tile (it saves 0.5 of that third)
    sel = sdk.select_rates_for_saving(p.predict(x), 0.4, engine_rates=engine, frame_size=(16, 48), tile_size=16)
    assert p.shading_rates(x, saving=0.4, engine_rates=engine).tolist() == sel.rates.tolist()
    assert sel.saved >= 0.4


def test_engine_rates_are_on_the_hardware_tiles_of_a_predictor_loaded_for_them(tiny_model: Callable[..., Path]) -> None:
    """docs/runtime.md: ``engine_rates`` is an image of the rate image's tiles, ``predictor.tiles(h, w)``: with
    ``load(tile_size=8)`` the hardware's 8-pixel grid, not the model's 16-pixel one."""
    path = tiny_model(base_metadata(default_threshold=0.3))
    fine = sdk.load(path, tile_size=8)
    x = np.full((4, 24, 40), -10.0, np.float32)
    grid = fine.tiles(24, 40)
    assert grid == (3, 5)
    engine = np.full(grid, C["2x1"], np.uint8)
    got = fine.shading_rates(x, engine_rates=engine)
    assert got.shape == grid
    assert (got == sdk.select_rates(fine.predict(x), 0.3, engine_rates=engine)).all()
    with pytest.raises(sdk.InputShapeError, match="engine_rates"):  # the model's 2x3 tiles are not the image's
        fine.shading_rates(x, engine_rates=np.full(sdk.tile_grid(24, 40, 16), C["2x1"], np.uint8))


def test_a_device_chooses_between_two_rates_at_most() -> None:
    """The selection judges the worse of two rates where a device may choose; over every allowed set, combiner
    and pair of rates there are never more than two, and they save alike where their areas match."""
    from rtp.sdk._rates import _combined

    for n in range(len(PREDICTED_RATES) + 1):
        for allowed in itertools.combinations(PREDICTED_RATES, n):
            supported = ("1x1",) + allowed
            for op, a, b in itertools.product(sdk.COMBINERS, supported, supported):
                got = _combined(op, a, b, supported)
                assert 1 <= len(got) <= 2 and set(got) <= set(supported)
                assert RATE_NAMES[int(sdk.combine_rates(a, b, op, allowed=allowed))] == got[0]
