"""Rate names, codes, selection on constructed predictions, and the overlay."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from rtp import sdk


def test_codes_follow_d3d12_and_vulkan() -> None:
    assert sdk.RATE_CODES == {"1x1": 0, "1x2": 1, "2x1": 4, "2x2": 5, "2x4": 6, "4x2": 9, "4x4": 10}
    assert sdk.RATE_CODES["2x4"] == 6
    assert all(sdk.RATE_NAMES[c] == r for r, c in sdk.RATE_CODES.items())
    # Per-axis OR composes rates, as NAS and FidelityFX rely on.
    assert sdk.RATE_CODES["2x1"] | sdk.RATE_CODES["1x2"] == sdk.RATE_CODES["2x2"]


def test_work_saved() -> None:
    assert [sdk.work_saved(r) for r in sdk.ALL_RATES] == [0, 0.5, 0.5, 0.75, 0.875, 0.875, 0.9375]
    assert [sdk.work_saved(sdk.RATE_CODES[r]) for r in sdk.ALL_RATES] == [sdk.work_saved(r) for r in sdk.ALL_RATES]
    for code in (3, 99, -1):  # codes between the named ones, past them, below them
        with pytest.raises(sdk.ParameterError, match=f"unknown shading-rate code {code}; expected one of"):
            sdk.work_saved(code)


def test_check_threshold_takes_the_direction_as_a_flag() -> None:
    """check_threshold read higher_is_better by truthiness: 'no' was True, so an error metric's negative threshold
    passed as a PSNR's dB."""
    assert sdk.check_threshold(-3, True) == -3.0 and sdk.check_threshold(-3, np.True_) == -3.0
    for flag in ("no", None, 1, "False"):
        with pytest.raises(sdk.ParameterError, match="higher_is_better: expected True or False"):
            sdk.check_threshold(-3, flag)  # type: ignore[arg-type]


def _tile(*values: float) -> np.ndarray:
    return np.array(values, dtype=np.float32).reshape(6, 1, 1)


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        ((0.1, 0.1, 0.1, 0.1, 0.1, 0.1), "4x4"),  # everything passes: the cheapest
        ((0.1, 0.1, 0.1, 0.1, 0.3, 0.3), "2x4"),  # 4x4 fails, 2x4 passes
        ((0.1, 0.1, 0.1, 0.19, 0.15, 0.3), "4x2"),  # both pass: the smaller error wins the tie
        ((0.1, 0.1, 0.1, 0.3, 0.3, 0.3), "2x2"),
        ((0.15, 0.1, 0.3, 0.3, 0.3, 0.3), "2x1"),  # equal cost: 2x1 has the smaller error
        ((0.1, 0.3, 0.3, 0.3, 0.3, 0.3), "1x2"),
        ((0.3, 0.3, 0.3, 0.3, 0.3, 0.3), "1x1"),  # nothing passes
        ((0.2, 0.2, 0.2, 0.2, 0.2, 0.2), "1x1"),  # passing means strictly below
        ((np.nan,) * 6, "1x1"),
    ],
)
def test_selection_picks_the_cheapest_passing_rate(values: tuple[float, ...], expected: str) -> None:
    got = sdk.select_rates(_tile(*values), 0.2)
    assert got.dtype == np.uint8 and got.shape == (1, 1)
    assert sdk.RATE_NAMES[int(got[0, 0])] == expected


def test_selection_for_higher_is_better_metrics() -> None:
    psnr = _tile(45, 44, 41, 38, 36, 30)
    pick = lambda thr: sdk.RATE_NAMES[int(sdk.select_rates(psnr, thr, higher_is_better=True)[0, 0])]  # noqa: E731
    assert pick(25) == "4x4"
    assert pick(35) == "2x4"
    assert pick(40) == "2x2"
    assert pick(44.5) == "1x2"
    assert pick(50) == "1x1"
    # +inf PSNR (identical tile) passes any threshold.
    assert sdk.select_rates(_tile(*([np.inf] * 6)), 60, higher_is_better=True)[0, 0] == 10


@pytest.mark.parametrize(
    ("allowed", "expected"),
    [
        (None, "4x4"),
        (["1x2", "2x1", "2x2", "2x4", "4x2"], "2x4"),  # hardware without 4x4
        (["1x2", "2x1", "2x2"], "2x2"),  # without the additional rates
        ([1, 4], "2x1"),  # by code
        ([], "1x1"),
        (["1x1"], "1x1"),
    ],
)
def test_allowed_rates(allowed: list | None, expected: str) -> None:
    v = _tile(0.1, 0.05, 0.1, 0.1, 0.15, 0.1)
    assert sdk.RATE_NAMES[int(sdk.select_rates(v, 0.2, allowed=allowed)[0, 0])] == expected


def test_allowed_rejects_unknown_rates() -> None:
    for allowed, words in ((["3x3"], "unknown shading rate '3x3'"), ([7], "unknown shading-rate code 7"),
                           ([2.0], "expected rate names like '2x2' or integer codes, got 2.0")):
        with pytest.raises(sdk.ParameterError, match=f"^allowed: {words}") as info:
            sdk.select_rates(_tile(*[0.1] * 6), 0.2, allowed=allowed)
        assert info.value.name == "allowed"


def test_selection_is_per_tile_and_batched() -> None:
    v = np.full((2, 6, 2, 3), 0.3, np.float32)
    v[0, :, 0, 0] = 0.1
    v[1, 0, 1, 2] = 0.1
    got = sdk.select_rates(v, 0.2)
    assert got.shape == (2, 2, 3)
    assert got[0, 0, 0] == 10 and got[1, 1, 2] == 1 and int(got.sum()) == 11


def test_a_threshold_factor_per_rate() -> None:
    """``factors``: rate r passes below threshold x factor (PSNR: above threshold - 20 log10 factor); rates of
    equal cost compare their values over their factors; all 1 decides as no factors, bit for bit."""
    v = _tile(0.1, 0.12, 0.15, 0.18, 0.19, 0.22)  # 4x4 fails 0.2; a factor of 1.2 lets it pass, 0.8 on 2x4/4x2 not
    pick = lambda thr, f: sdk.RATE_NAMES[int(sdk.select_rates(v, thr, factors=f)[0, 0])]  # noqa: E731
    assert pick(0.2, None) == "2x4" and pick(0.2, {"4x4": 1.2}) == "4x4"
    assert pick(0.2, {"2x4": 0.8, "4x2": 0.8}) == "2x2" and pick(0.2, [1, 1, 0.5, 0.8, 0.8, 1]) == "1x2"
    # equal cost: 4x2 (0.19 of 0.2 x 1.25) is further under its threshold than 2x4 (0.18 of 0.2)
    assert pick(0.2, {"4x2": 1.25}) == "4x2" and pick(0.2, None) == "2x4"
    psnr = _tile(45, 44, 41, 38, 36, 30)
    hib = lambda thr, f: sdk.RATE_NAMES[int(sdk.select_rates(psnr, thr, higher_is_better=True, factors=f)[0, 0])]  # noqa: E731
    assert hib(35, None) == "2x4" and hib(35, {"4x4": 1.5}) == "2x4"  # 30 < 35 - 20 log10(1.5) = 31.48
    assert hib(35, {"4x4": 2.0}) == "4x4"  # 30 > 35 - 20 log10(2) = 28.98
    assert hib(35, {"2x4": 0.25, "4x2": 0.25}) == "2x2"  # 38 and 36 < 35 + 12.04
    rng = np.random.default_rng(0)
    many = rng.random((3, 6, 9, 11)).astype(np.float32)
    for f in (None, [1.0] * 6, {"2x2": 1.0}):
        np.testing.assert_array_equal(sdk.select_rates(many, 0.5, factors=f), sdk.select_rates(many, 0.5))
    for bad, words in (({"1x1": 2.0}, "unknown rate"), ([1.0] * 5, "expected 6 factors"), ({"2x2": 4.5}, "2x2's factor"),
                       ("1.2", "a mapping"), ([1, 1, 1, 1, 1, float("inf")], "4x4's factor"),
                       (np.array(1.0), "expected 6 numbers"), (np.ones((6, 2)), "1x2's factor"), ([1] * 5 + [10**400], "4x4")):
        with pytest.raises(sdk.ParameterError, match=words) as info:
            sdk.select_rates(many, 0.5, factors=bad)  # type: ignore[arg-type]
        assert info.value.name == "factors"


def test_selection_rejects_the_wrong_channel_count() -> None:
    with pytest.raises(sdk.InputShapeError):
        sdk.select_rates(np.zeros((4, 2, 2)), 0.2)


def test_overlay_colours_tiles_by_rate_class() -> None:
    img = np.full((20, 40, 3), 128, np.uint8)
    rates = np.array([[0, 1, 5], [6, 10, 4]], np.uint8)
    out = sdk.draw_rate_overlay(img, rates, 16, grid=False)
    assert out.dtype == np.uint8 and out.shape == img.shape
    assert np.array_equal(out[:16, :16], img[:16, :16])  # 1x1: untouched
    g, y, r = out[5, 20], out[5, 35], out[18, 5]
    assert g[1] > g[0] and g[1] > g[2]  # fine: green
    assert y[0] > y[2] and y[1] > y[2]  # medium: yellow
    assert r[0] > r[1] and r[0] > r[2]  # coarse: red
    assert np.array_equal(out[18, 20], out[18, 5])  # 2x4 and 4x4 are both coarse
    f = sdk.draw_rate_overlay(img.astype(np.float32) / 255, rates, 16)
    assert f.dtype == np.float32 and 0 <= f.min() and f.max() <= 1
    # an HDR frame (values over 1) is clipped before the tint, so the tint and the grid show: it came back all white
    hdr = sdk.draw_rate_overlay(np.full(img.shape, 4.0, np.float32), rates, 16)
    assert hdr[18, 5, 0] > hdr[18, 5, 1] and hdr[5, 20, 1] > hdr[5, 20, 0] and hdr[0, 5].max() < 1.0
    np.testing.assert_array_equal(hdr[5, 5], [1.0, 1.0, 1.0])  # full rate: the frame, clipped


def test_overlay_legend_names_each_colour_in_the_corner() -> None:
    img = np.full((270, 480, 3), 200, np.uint8)
    rates = np.zeros((17, 30), np.uint8)
    plain = sdk.draw_rate_overlay(img, rates, 16, grid=False)
    keyed = sdk.draw_rate_overlay(img, rates, 16, grid=False, legend=True)
    changed = np.argwhere((plain != keyed).any(axis=2))
    # only a box in the bottom-left corner changes, and it shows the three tints and white text
    assert len(changed) and changed[:, 0].min() > 270 - 60 and changed[:, 1].max() < 80
    box = keyed[210:, :80].reshape(-1, 3).astype(int)
    for colour in sdk.OVERLAY_COLOURS.values():
        tint = np.round((np.array(colour) * 0.45 + 0.5 * 0.55) * 255)  # swatch: tint over grey
        assert (np.abs(box - tint).max(axis=1) <= 1).any(), colour
    assert (box == 255).all(axis=1).any()
    # an image too small for the key is drawn without it
    small = np.zeros((20, 40, 3), np.uint8)
    assert np.array_equal(sdk.draw_rate_overlay(small, np.zeros((2, 3), np.uint8), 16, legend=True),
                          sdk.draw_rate_overlay(small, np.zeros((2, 3), np.uint8), 16))


def test_overlay_legend_is_left_out_exactly_where_the_docstring_says() -> None:
    """The docstring's smallest image that holds the key (it said 52x35, where the key is 54 wide and 33 tall:
    a 52-pixel-wide image had no key, a 33-pixel-tall one had)."""
    import re

    doc = " ".join((sdk.draw_rate_overlay.__doc__ or "").split())
    found = re.search(r"narrower than (\d+) pixels or shorter than (\d+)", doc)
    assert found, doc
    min_w, min_h = int(found[1]), int(found[2])
    for h, w, drawn in ((min_h, min_w, True), (min_h - 1, min_w, False), (min_h, min_w - 1, False)):
        img = np.full((h, w, 3), 0.5, np.float32)
        rates = np.zeros((-(-h // 16), -(-w // 16)), np.uint8)
        keyed = sdk.draw_rate_overlay(img, rates, 16, grid=False, legend=True)
        assert (keyed != img).any() == drawn, (h, w)
    # a tall image as narrow as that gets the key too, at a scale that fits: from 540 rows on, the key was drawn two
    # font pixels a pixel (108 wide) or not at all, so a 540x100 or 1080x60 frame had none
    for h, w in ((540, 100), (1080, min_w), (1080, 120)):
        img = np.full((h, w, 3), 0.5, np.float32)
        rates = np.zeros((-(-h // 16), -(-w // 16)), np.uint8)
        keyed = sdk.draw_rate_overlay(img, rates, 16, grid=False, legend=True)
        changed = np.argwhere((keyed != img).any(axis=2))
        assert len(changed), (h, w)
        assert changed[:, 1].max() < w and changed[:, 0].min() >= h - min_h * (w // min_w), (h, w)
    # an RGBA image is taken (its alpha kept), and the shape error says so
    rgba = np.full((40, 60, 4), 0.25, np.float32)
    np.testing.assert_array_equal(sdk.draw_rate_overlay(rgba, np.zeros((3, 4), np.uint8), 16)[..., 3], rgba[..., 3])
    with pytest.raises(sdk.InputShapeError, match=r"image: expected an \(H, W, 3\) or \(H, W, 4\) image"):
        sdk.draw_rate_overlay(np.zeros((40, 60, 2), np.float32), np.zeros((3, 4), np.uint8), 16)


# Machado, Oliveira and Fernandes (2009), severity 1.0, applied to linear RGB
_MACHADO = {
    "protanopia": [[0.152286, 1.052583, -0.204868], [0.114503, 0.786281, 0.099216], [-0.003882, -0.048116, 1.051998]],
    "deuteranopia": [[0.367322, 0.860646, -0.227968], [0.280085, 0.672501, 0.047413], [-0.011820, 0.042940, 0.968881]],
    "tritanopia": [[1.255528, -0.076749, -0.178779], [-0.078411, 0.930809, 0.147602], [0.004733, 0.691367, 0.303900]],
}


def _lab(srgb: np.ndarray) -> np.ndarray:
    lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    xyz = lin @ np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]).T
    f = np.cbrt(xyz / np.array([0.95047, 1.0, 1.08883]))  # (no value here is below the linear segment's end)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], -1)


def _ciede2000(lab1: np.ndarray, lab2: np.ndarray) -> float:
    (l1, a1, b1), (l2, a2, b2) = lab1, lab2
    cb = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2
    g = 0.5 * (1 - np.sqrt(cb ** 7 / (cb ** 7 + 25 ** 7)))
    a1, a2 = (1 + g) * a1, (1 + g) * a2
    c1, c2 = np.hypot(a1, b1), np.hypot(a2, b2)
    h1, h2 = np.degrees(np.arctan2(b1, a1)) % 360, np.degrees(np.arctan2(b2, a2)) % 360
    dh = 0.0 if c1 * c2 == 0 else (h2 - h1 + 180) % 360 - 180
    dhh = 2 * np.sqrt(c1 * c2) * np.sin(np.radians(dh / 2))
    lb, cbp = (l1 + l2) / 2, (c1 + c2) / 2
    hb = h1 + h2 if c1 * c2 == 0 else (h1 + h2) / 2 + (180 if abs(h1 - h2) > 180 else 0)
    t = (1 - 0.17 * np.cos(np.radians(hb - 30)) + 0.24 * np.cos(np.radians(2 * hb))
         + 0.32 * np.cos(np.radians(3 * hb + 6)) - 0.20 * np.cos(np.radians(4 * hb - 63)))
    rt = -np.sin(np.radians(60 * np.exp(-(((hb % 360) - 275) / 25) ** 2))) * 2 * np.sqrt(cbp ** 7 / (cbp ** 7 + 25 ** 7))
    sl = 1 + 0.015 * (lb - 50) ** 2 / np.sqrt(20 + (lb - 50) ** 2)
    sc, sh = 1 + 0.045 * cbp, 1 + 0.015 * cbp * t
    return float(np.sqrt(((l2 - l1) / sl) ** 2 + ((c2 - c1) / sc) ** 2 + (dhh / sh) ** 2
                         + rt * ((c2 - c1) / sc) * (dhh / sh)))


def _class_distances(palette: str, vision: str) -> dict[tuple[str, str], float]:
    """The least CIEDE2000 between the overlay's classes (1x1 untinted, fine, medium, coarse) as drawn at the
    default alpha over uint8 greys from dark to bright, as seen under ``vision`` (a Machado simulation)."""
    names = ("1x1", "1x2", "2x2", "4x4")
    codes = np.array([[sdk.RATE_CODES[r] for r in names]], np.uint8)
    least: dict[tuple[str, str], float] = {}
    for grey in range(13, 256, 24):
        drawn = sdk.draw_rate_overlay(np.full((1, 4, 3), grey, np.uint8), codes, 1, grid=False, palette=palette)
        srgb = drawn[0].astype(np.float64) / 255
        lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
        seen = np.clip(lin @ np.array(_MACHADO[vision]).T, 0, 1)
        lab = _lab(np.where(seen <= 0.0031308, seen * 12.92, 1.055 * seen ** (1 / 2.4) - 0.055))
        for i in range(4):
            for j in range(i + 1, 4):
                d = _ciede2000(lab[i], lab[j])
                least[names[i], names[j]] = min(least.get((names[i], names[j]), np.inf), d)
    return least


def test_the_cvd_palette_keeps_the_overlays_classes_apart_under_colour_vision_deficiency() -> None:
    """The paper's fine green and medium yellow come within a CIEDE2000 of about 4 of each other under simulated
    protanopia; palette="cvd" keeps every class (the untinted one too, over any grey) about 10 or more apart under each."""
    assert _class_distances("paper", "protanopia")["1x2", "2x2"] < 5  # (why the palette is there)
    for vision in _MACHADO:
        distances = _class_distances("cvd", vision)
        assert min(distances.values()) >= 9, (vision, distances)
    # the default stays the paper's, and the legend's swatches take the palette's colours
    codes = np.array([[1, 5, 10]], np.uint8)
    img = np.full((1, 3, 3), 0.5, np.float32)
    np.testing.assert_array_equal(sdk.draw_rate_overlay(img, codes, 1, grid=False),
                                  sdk.draw_rate_overlay(img, codes, 1, grid=False, palette="paper"))
    keyed = sdk.draw_rate_overlay(np.full((270, 480, 3), 200, np.uint8), np.zeros((17, 30), np.uint8), 16,
                                  grid=False, legend=True, palette="cvd")
    box = keyed[210:, :80].reshape(-1, 3).astype(int)
    tinted = sdk.draw_rate_overlay(np.full((1, 3, 3), 128, np.uint8), codes, 1, grid=False, palette="cvd")[0]
    for swatch in tinted.astype(int):
        assert (np.abs(box - swatch).max(axis=1) <= 1).any(), swatch
    for bad in ("CVD", "jet", None, 1):
        with pytest.raises(sdk.ParameterError, match="palette: expected one of 'paper', 'cvd'"):
            sdk.draw_rate_overlay(img, codes, 1, palette=bad)  # type: ignore[arg-type]


def test_overlay_checks_the_tile_grid() -> None:
    with pytest.raises(sdk.InputShapeError, match=r"\(2, 3\)"):
        sdk.draw_rate_overlay(np.zeros((20, 40, 3), np.uint8), np.zeros((1, 3), np.uint8), 16)
    rates = np.zeros((2, 3), np.uint8)
    for dtype in (np.uint16, np.int32, np.bool_):  # a uint16 image came back all white, read as floats
        with pytest.raises(sdk.InputDtypeError, match="uint8 or float"):
            sdk.draw_rate_overlay(np.zeros((20, 40, 3), dtype), rates, 16)
    for flag in ("grid", "legend"):
        with pytest.raises(sdk.ParameterError, match=flag):
            sdk.draw_rate_overlay(np.zeros((20, 40, 3), np.uint8), rates, 16, **{flag: "no"})


def _select_rate_by_rate(err: np.ndarray, thr: float, allowed: list[str]) -> np.ndarray:
    """The selection as sdk.select_rates did it until 2026-12-02, a few operations per rate: cost
    classes from the cheapest, within a class the smaller error, the first on a tie ("smaller is better"
    values, the factors already applied)."""
    out = np.zeros(err.shape[:-3] + err.shape[-2:], dtype=np.uint8)
    decided = np.zeros(out.shape, dtype=bool)
    by_area: dict[int, list[str]] = {}
    for r in allowed:
        w, h = (int(v) for v in r.split("x"))
        by_area.setdefault(w * h, []).append(r)
    for area in sorted(by_area, reverse=True):
        best_err = np.full(out.shape, np.inf)
        best_code = np.zeros(out.shape, dtype=np.uint8)
        found = np.zeros(out.shape, dtype=bool)
        for r in by_area[area]:
            e = err[..., sdk.PREDICTED_RATES.index(r), :, :]
            better = (e < thr) & (e < best_err)
            best_err = np.where(better, e, best_err)
            best_code = np.where(better, np.uint8(sdk.RATE_CODES[r]), best_code)
            found |= better
        take = ~decided & found
        out[take] = best_code[take]
        decided |= take
    return out


@settings(max_examples=300, deadline=None)
@given(
    values=hnp.arrays(np.float64, st.tuples(st.integers(1, 2), st.just(6), st.integers(1, 4), st.integers(1, 5)),
                      elements=st.one_of(st.sampled_from([0.1, 0.2, 0.25, 0.3, np.nan, -np.inf, np.inf]),
                                         st.floats(-1, 1))),
    allowed=st.lists(st.sampled_from(sdk.PREDICTED_RATES), unique=True),
    threshold=st.sampled_from([0.0, 0.2, 0.25, 0.5]),
    factors=st.one_of(st.none(), st.lists(st.sampled_from([0.5, 1.0, 2.0]), min_size=6, max_size=6)),
)
def test_selection_agrees_with_a_rate_by_rate_walk(values: np.ndarray, allowed: list[str], threshold: float,
                                                   factors: list[float] | None) -> None:
    """Ties (equal values of equal-cost rates), NaN, infinities, any allowed subset in any order, factors."""
    got = sdk.select_rates(values, threshold, allowed=allowed, factors=factors)
    scaled = values / np.asarray(factors or [1.0] * 6)[:, None, None]
    in_channel_order = [r for r in sdk.PREDICTED_RATES if r in allowed]
    np.testing.assert_array_equal(got, _select_rate_by_rate(scaled, threshold, in_channel_order))
    psnr = sdk.select_rates(-values, -threshold, higher_is_better=True, allowed=allowed)
    np.testing.assert_array_equal(psnr, _select_rate_by_rate(values, threshold, in_channel_order))


# -- a budget: rates for a share of the work saved ------------------------------------------------------------


def _saved(rates: np.ndarray, weights: np.ndarray) -> float:
    share = np.vectorize(lambda c: sdk.work_saved(int(c)))(rates)
    return float((share * weights).sum() / weights.sum())


def _lowest_by_scan(values: np.ndarray, saving: float, weights: np.ndarray, **kw: object) -> float:
    """The lowest threshold reaching ``saving``, by trying every value (and just above it) in order."""
    scaled = values / np.asarray(kw.get("factors") or [1.0] * 6)[:, None, None]  # each rate's own threshold
    candidates = sorted({0.0, *(float(np.nextafter(v, np.inf)) for v in scaled.ravel() if 0 <= v < 1e6)})
    for t in candidates:
        if _saved(sdk.select_rates(values, t, **kw), weights) >= saving * (1 - 1e-12):
            return t
    return candidates[-1]


@settings(max_examples=300, deadline=None)
@given(
    values=hnp.arrays(np.float64, st.tuples(st.just(6), st.integers(1, 4), st.integers(1, 5)),
                      elements=st.one_of(st.sampled_from([0.1, 0.2, 0.25, 0.3]), st.floats(0, 1))),
    saving=st.floats(0, 1),
    allowed=st.one_of(st.none(), st.lists(st.sampled_from(sdk.PREDICTED_RATES), unique=True, min_size=1)),
    factors=st.one_of(st.none(), st.lists(st.sampled_from([0.5, 1.0, 2.0]), min_size=6, max_size=6)),
    edge=st.booleans(),
)
def test_a_saving_is_reached_at_the_lowest_threshold(values: np.ndarray, saving: float, allowed: list[str] | None,
                                                      factors: list[float] | None, edge: bool) -> None:
    """The rates save what was asked, pass the threshold returned, and no lower threshold saves as much; on
    partial edge tiles each tile weighs its pixels."""
    top = max(sdk.work_saved(r) for r in (allowed or sdk.PREDICTED_RATES))
    saving *= top
    th, tw = values.shape[1:]
    size = (th * 16 - (5 if edge else 0), tw * 16 - (9 if edge else 0))
    weights = np.outer(sdk.tile_extents(size[0], 16), sdk.tile_extents(size[1], 16)).astype(float)
    kw = {"allowed": allowed, "factors": factors}
    sel = sdk.select_rates_for_saving(values, saving, frame_size=size, tile_size=16, **kw)
    assert sel.rates.dtype == np.uint8 and sel.rates.shape == (th, tw)
    np.testing.assert_array_equal(sel.rates, sdk.select_rates(values, sel.threshold, **kw))
    assert sel.saved == pytest.approx(_saved(sel.rates, weights)) == pytest.approx(
        sdk.work_saved(sel.rates, size, 16))
    assert sel.saved >= saving * (1 - 1e-12)
    assert sel.threshold == pytest.approx(_lowest_by_scan(values, saving, weights, **kw), rel=1e-12, abs=0)
    # PSNR-like (higher is better): the same choice on the negated values, the threshold negated
    hib = sdk.select_rates_for_saving(-values, saving, higher_is_better=True, frame_size=size, tile_size=16,
                                      allowed=allowed)
    plain = sdk.select_rates_for_saving(values, saving, frame_size=size, tile_size=16, allowed=allowed)
    np.testing.assert_array_equal(hib.rates, plain.rates)
    assert hib.saved == plain.saved
    # (no saving asks for nothing to pass: each kind's lowest threshold, 0 for an error, the top dB for PSNR)
    if saving > 0:
        assert hib.threshold == -plain.threshold
    else:  # (no saving asks for nothing to pass: each kind's lowest threshold, 0 for an error, the top dB for PSNR)
        assert plain.threshold == 0 and hib.threshold > 1000 and (hib.rates == 0).all()


@settings(max_examples=200, deadline=None)
@given(
    values=hnp.arrays(np.float64, st.tuples(st.just(6), st.integers(1, 4), st.integers(1, 5)),
                      elements=st.one_of(st.sampled_from([0.1, 0.2, 0.25, 0.3]), st.floats(0, 1))),
    saving=st.floats(0, sdk.MAX_SAVING),
    threshold=st.sampled_from([0.0, 0.1, 0.2, 0.25, 0.5, 2.0]),
    hib=st.booleans(),
)
def test_a_saving_as_a_floor_under_a_threshold(values: np.ndarray, saving: float, threshold: float, hib: bool) -> None:
    """A threshold and a saving: the threshold's rates where they save the floor or more, else the budget's."""
    if hib:
        values, threshold = -values, -threshold
    own = sdk.select_rates(values, threshold, higher_is_better=hib)
    budget = sdk.select_rates_for_saving(values, saving, higher_is_better=hib)
    floor = sdk.select_rates_for_saving(values, saving, higher_is_better=hib, threshold=threshold)
    if sdk.work_saved(own) >= saving * (1 - 1e-12):
        np.testing.assert_array_equal(floor.rates, own)
        assert floor.threshold == threshold
    else:
        np.testing.assert_array_equal(floor.rates, budget.rates)
        assert floor.threshold == budget.threshold
    assert floor.saved >= saving * (1 - 1e-12)


def test_a_saving_per_frame_of_a_batch_and_with_nan() -> None:
    rng = np.random.default_rng(3)
    values = rng.random((3, 6, 4, 5))
    sel = sdk.select_rates_for_saving(values, 0.6)
    assert sel.rates.shape == (3, 4, 5) and np.shape(sel.threshold) == (3,) and np.shape(sel.saved) == (3,)
    for i in range(3):
        one = sdk.select_rates_for_saving(values[i], 0.6)
        np.testing.assert_array_equal(sel.rates[i], one.rates)
        assert (sel.threshold[i], sel.saved[i]) == (one.threshold, one.saved)
        assert isinstance(one.threshold, float) and isinstance(one.saved, float)
    # a tile whose predictions are all NaN never passes: the rest save what they can
    values[0, :, 0, 0] = np.nan
    full = sdk.select_rates_for_saving(values[0], sdk.MAX_SAVING)
    assert full.rates[0, 0] == sdk.RATE_CODES["1x1"] and (full.rates.ravel()[1:] == sdk.RATE_CODES["4x4"]).all()
    assert full.saved == pytest.approx(sdk.MAX_SAVING * 19 / 20)
    assert full.threshold < 1.0  # (the lowest threshold saving what can be saved: not one past every number)
    nothing = sdk.select_rates_for_saving(np.full((6, 2, 2), np.nan), 0.5)
    assert (nothing.rates == 0).all() and nothing.saved == 0.0
    # no saving: 1x1 everywhere, at a threshold nothing passes
    zero = sdk.select_rates_for_saving(values[1], 0)
    assert (zero.rates == 0).all() and zero.saved == 0.0
    assert (sdk.select_rates(values[1], zero.threshold) == 0).all()


@pytest.mark.parametrize(
    ("saving", "kw", "match"),
    [
        (0.95, {}, r"saving: expected the share of shading work to save, a number in \[0, 0.9375\] \(the coarsest "
                   r"allowed rate, 4x4, saves 0.9375\), got 0.95"),
        (0.6, {"allowed": ["1x2", "2x1"]}, r"in \[0, 0.5\] \(the coarsest allowed rate, 1x2, saves 0.5\)"),
        (0.1, {"allowed": ["1x1"]}, r"in \[0, 0\] \(only 1x1 is allowed, which saves nothing\), got 0.1"),
        (-0.1, {}, r"got -0.1"),
        (float("nan"), {}, r"got nan"),
        (True, {}, r"got True"),
        ("half", {}, r"got 'half'"),
        (0.5, {"frame_size": (32, 32)}, r"give frame_size and tile_size together"),
        (0.5, {"frame_size": 32, "tile_size": 16}, r"frame_size: expected \(H, W\), got 32"),
        (0.5, {"threshold": -1.0}, r"threshold: expected a finite number in \[0, 1e\+06\]"),
    ],
)
def test_a_saving_out_of_range_is_a_clear_error(saving: object, kw: dict, match: str) -> None:
    with pytest.raises(sdk.ParameterError, match=match):
        sdk.select_rates_for_saving(np.zeros((6, 2, 2)), saving, **kw)  # type: ignore[arg-type]


def test_a_saving_checks_the_tile_grid() -> None:
    with pytest.raises(sdk.InputShapeError, match=r"2x2 tiles do not cover a 64x32 frame of 16-pixel tiles"):
        sdk.select_rates_for_saving(np.zeros((6, 2, 2)), 0.5, frame_size=(32, 64), tile_size=16)
    with pytest.raises(sdk.InputShapeError, match="6 rate channels on axis -3"):
        sdk.select_rates_for_saving(np.zeros((5, 2, 2)), 0.5)
    with pytest.raises(sdk.InputShapeError, match=r"at least one tile, got shape \(6, 0, 3\)"):
        sdk.select_rates_for_saving(np.zeros((6, 0, 3)), 0.5)


@pytest.mark.parametrize("seed", range(4))
def test_a_saving_on_frames_of_many_tiles(seed: int) -> None:
    """Thousands of tiles (the weighted selection partitions before it sorts), ties, NaN and partial edge tiles:
    the threshold is the lowest that saves as much, found by bisection over every candidate threshold."""
    rng = np.random.default_rng(seed)
    th, tw = 45 + seed, 80 + 3 * seed
    values = np.round(rng.gamma(2.0, 0.1, (6, th, tw)), 2 + seed % 2)  # (rounded: many ties)
    values[:, rng.random((th, tw)) < 0.01] = np.nan
    size = (th * 16 - 7, tw * 16 - 3)
    weights = np.outer(sdk.tile_extents(size[0], 16), sdk.tile_extents(size[1], 16)).astype(float)
    factors = [1.16, 1.16, 0.97, 0.97, 0.97, 0.82] if seed % 2 else None
    scaled = values / np.asarray(factors or [1.0] * 6)[:, None, None]
    candidates = np.unique(np.nextafter(scaled[np.isfinite(scaled)], np.inf))
    for saving in (0.05, 0.3, 0.5, 0.62, 0.8, 0.9):
        sel = sdk.select_rates_for_saving(values, saving, factors=factors, frame_size=size, tile_size=16)
        lo, hi = 0, len(candidates) - 1  # the first candidate that saves enough (the saving grows with it)
        while lo < hi:
            mid = (lo + hi) // 2
            if _saved(sdk.select_rates(values, candidates[mid], factors=factors), weights) >= saving * (1 - 1e-12):
                hi = mid
            else:
                lo = mid + 1
        assert sel.threshold == candidates[lo], saving
        assert sel.saved >= saving and sel.saved == pytest.approx(_saved(sel.rates, weights))


# -- invariants over plausible but unusual predictions (property-based) ---------------------------------------------

_AREA = {code: sdk.rate_size(name)[0] * sdk.rate_size(name)[1] for name, code in sdk.RATE_CODES.items()}
_predictions = st.tuples(st.integers(1, 3), st.integers(1, 4)).flatmap(  # (each value drawn: no array fill)
    lambda tiles: st.lists(st.one_of(st.sampled_from([0.0, 0.1, 0.11, 0.2, 0.25, 0.3, 0.6, 1.0, np.nan]), st.floats(0, 2)),
                           min_size=6 * tiles[0] * tiles[1], max_size=6 * tiles[0] * tiles[1])
    .map(lambda v: np.array(v, np.float64).reshape(6, *tiles)))
_thresholds = st.one_of(st.sampled_from([0.15, 0.25, 0.4]), st.floats(0, 3))


def _areas(codes: np.ndarray) -> np.ndarray:
    return np.vectorize(lambda c: _AREA[int(c)])(codes)


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(values=_predictions, a=_thresholds, b=_thresholds,
       allowed=st.one_of(st.none(), st.lists(st.sampled_from(sdk.ALL_RATES), unique=True)),
       factors=st.one_of(st.none(), st.lists(st.floats(0.25, 4), min_size=6, max_size=6)), hib=st.booleans(),
       engine=st.one_of(st.none(), st.sampled_from(sorted(sdk.RATE_NAMES))), combiner=st.sampled_from(["min", "max", "sum"]))
def test_a_looser_threshold_never_shades_a_finer_rate(values: np.ndarray, a: float, b: float, allowed: list[str] | None,
                                                      factors: list[float] | None, hib: bool, engine: int | None,
                                                      combiner: str) -> None:
    """Threshold monotonicity, with any allowed subset, per-rate factors, PSNR's direction and an engine's rates: the
    rate the device shades under a looser threshold covers at least the area it covers under a stricter one; the
    image holds allowed rates only; factors of 1 are no factors."""
    strict, loose = sorted([a, b])
    if hib:  # (PSNR: values in dB, a lower threshold is the looser)
        values, strict, loose = 40.0 - 10.0 * values, 40.0 - 10.0 * strict, 40.0 - 10.0 * loose
    supported = ("1x1", *sdk.resolve_allowed(allowed))
    if engine is not None and sdk.RATE_NAMES[engine] not in supported:
        engine = None
    kw: dict = dict(higher_is_better=hib, allowed=allowed, factors=factors, engine_rates=engine, combiner=combiner)
    tight, free = sdk.select_rates(values, strict, **kw), sdk.select_rates(values, loose, **kw)
    if engine is not None:
        tight, free = (sdk.combine_rates(engine, r, combiner, allowed=allowed) for r in (tight, free))
    assert (_areas(free) >= _areas(tight)).all(), (tight, free)
    assert {sdk.RATE_NAMES[int(c)] for c in np.unique(tight)} <= set(supported)
    if factors is None:
        np.testing.assert_array_equal(sdk.select_rates(values, strict, **{**kw, "factors": [1.0] * 6}),
                                      sdk.select_rates(values, strict, **kw))


_MIRROR = {"1x2": "2x1", "2x1": "1x2", "2x4": "4x2", "4x2": "2x4"}


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(values=_predictions, threshold=_thresholds,
       allowed=st.one_of(st.none(), st.lists(st.sampled_from(sdk.ALL_RATES), unique=True)),
       factors=st.one_of(st.none(), st.lists(st.floats(0.25, 4), min_size=6, max_size=6)))
def test_transposed_tiles_with_wide_and_tall_swapped_pick_the_transposed_rates(
        values: np.ndarray, threshold: float, allowed: list[str] | None, factors: list[float] | None) -> None:
    """Selection favours neither axis: transposing the tile grid and swapping each wide rate's predictions (and
    allowance, and factor) with the tall one's gives the transposed image, wide and tall codes swapped (exact ties
    between a wide and a tall rate aside, which go to the first in channel order)."""
    values = values + np.arange(values.size).reshape(values.shape) * 1e-9  # (no exact ties)
    swap = [sdk.PREDICTED_RATES.index(_MIRROR.get(r, r)) for r in sdk.PREDICTED_RATES]
    got = sdk.select_rates(values, threshold, allowed=allowed, factors=factors)
    mirrored = sdk.select_rates(np.swapaxes(values[swap], -1, -2), threshold,
                                allowed=None if allowed is None else [_MIRROR.get(r, r) for r in allowed],
                                factors=None if factors is None else [factors[i] for i in swap])
    back = np.vectorize(lambda c: sdk.RATE_CODES[_MIRROR.get(sdk.RATE_NAMES[int(c)], sdk.RATE_NAMES[int(c)])])(got)
    np.testing.assert_array_equal(mirrored, back.T)


def test_a_saving_beside_values_no_threshold_passes_or_below_the_lowest() -> None:
    """What docs/runtime.md says of a budget's edges: values no threshold passes (an error of +inf or past
    MAX_THRESHOLD, a PSNR of -inf) save less than asked, as NaN does; an error predicted below 0 passes the lowest
    threshold, 0, so a saving of 0 reduces that tile (and only that one), as select_rates at 0 does."""
    for bad in (np.inf, 2 * sdk.MAX_THRESHOLD):
        values = np.full((6, 2, 2), 0.1)
        values[:, 0, 0] = bad
        sel = sdk.select_rates_for_saving(values, 0.9)
        assert sel.rates[0, 0] == sdk.RATE_CODES["1x1"] and sel.saved == pytest.approx(0.9375 * 3 / 4)
    psnr = np.full((6, 2, 2), 40.0)
    psnr[:, 1, 1] = -np.inf
    assert sdk.select_rates_for_saving(psnr, 0.9, higher_is_better=True).saved == pytest.approx(0.9375 * 3 / 4)
    values = np.full((6, 2, 2), 0.1)
    values[:, 1, 0] = -0.5
    zero = sdk.select_rates_for_saving(values, 0.0)
    assert zero.threshold == 0.0 and zero.rates[1, 0] == sdk.RATE_CODES["4x4"]
    assert (np.delete(zero.rates.ravel(), 2) == sdk.RATE_CODES["1x1"]).all()
    np.testing.assert_array_equal(sdk.select_rates(values, zero.threshold), zero.rates)


def test_a_budget_past_every_threshold_reports_the_lowest_threshold_saving_what_it_can() -> None:
    """A tile predicted past MAX_THRESHOLD never passes, as NaN never does: a budget it leaves out of reach reports
    the lowest threshold that saves what the frame can (as with NaN), not the highest threshold there is (until
    2026-12-09 its unreachable step counted, and the threshold came back as 1e6, for PSNR -1e6 dB)."""
    values = np.full((6, 1, 2), 0.1)
    values[5, 0, 0] = 2e6  # (4x4 unreachable on one tile: 2x4 there, 4x4 on the other)
    with_nan = values.copy()
    with_nan[5, 0, 0] = np.nan
    want = sdk.select_rates_for_saving(with_nan, sdk.MAX_SAVING)
    assert want.threshold == np.nextafter(0.1, 1.0) and want.saved == pytest.approx((0.875 + 0.9375) / 2)
    for kw in ({}, {"engine_rates": 0, "combiner": "max"}):
        sel = sdk.select_rates_for_saving(values, sdk.MAX_SAVING, **kw)  # type: ignore[arg-type]
        np.testing.assert_array_equal(sel.rates, want.rates)
        assert (sel.threshold, sel.saved) == (want.threshold, want.saved), kw
        psnr = sdk.select_rates_for_saving(-values, sdk.MAX_SAVING, higher_is_better=True, **kw)  # type: ignore[arg-type]
        assert (psnr.threshold, psnr.saved) == (-want.threshold, want.saved), kw


_wide_predictions = st.tuples(st.integers(1, 4), st.integers(1, 4)).flatmap(  # (past the thresholds, signed, infinite)
    lambda tiles: st.lists(st.one_of(st.sampled_from([0.0, -0.0, 0.25, -0.25, 1e6, -1e6, 2e6, np.inf, -np.inf, np.nan]),
                                     st.floats(-2e6, 2e6), st.floats(0, 1)),
                           min_size=6 * tiles[0] * tiles[1], max_size=6 * tiles[0] * tiles[1])
    .map(lambda v: np.array(v, np.float64).reshape(6, *tiles)))


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(values=_wide_predictions, saving=st.one_of(st.just(1.0), st.floats(0, 1)),
       allowed=st.one_of(st.none(), st.lists(st.sampled_from(sdk.ALL_RATES), unique=True)),
       factors=st.one_of(st.none(), st.lists(st.sampled_from([0.5, 0.82, 1.16, 2.0]), min_size=6, max_size=6)),
       hib=st.booleans(), engine=st.one_of(st.none(), st.sampled_from(sorted(sdk.RATE_NAMES))),
       combiner=st.sampled_from(["min", "max", "sum"]))
def test_a_budget_on_any_values_is_the_lowest_threshold_saving_what_any_threshold_can(
        values: np.ndarray, saving: float, allowed: list[str] | None, factors: list[float] | None, hib: bool,
        engine: int | None, combiner: str) -> None:
    """Whatever the values (negative, past MAX_THRESHOLD, infinite, NaN) and beside any engine rate: the budget's
    rates are select_rates' at its threshold, a threshold check_threshold takes; they save the saving asked or, where
    no threshold reaches it, what the loosest threshold saves; and a threshold one ulp stricter saves less."""
    supported = ("1x1", *sdk.resolve_allowed(allowed))
    saving *= max(sdk.work_saved(r) for r in supported)
    if engine is not None and sdk.RATE_NAMES[engine] not in supported:
        engine = None
    kw: dict = dict(higher_is_better=hib, allowed=allowed, factors=factors, engine_rates=engine, combiner=combiner)

    def shaded_saving(threshold: float) -> float:
        rates = sdk.select_rates(values, threshold, **kw)
        return sdk.work_saved(rates if engine is None else sdk.combine_rates(engine, rates, combiner, allowed=allowed))

    sel = sdk.select_rates_for_saving(values, saving, **kw)
    assert sdk.check_threshold(sel.threshold, hib) == sel.threshold
    np.testing.assert_array_equal(sel.rates, sdk.select_rates(values, sel.threshold, **kw))
    assert sel.saved == pytest.approx(shaded_saving(sel.threshold), abs=1e-12)
    reachable = min(saving, shaded_saving(-sdk.MAX_THRESHOLD if hib else sdk.MAX_THRESHOLD))
    assert sel.saved >= reachable * (1 - 1e-12)
    if sel.threshold != (sdk.MAX_THRESHOLD if hib else 0.0):  # (not the lowest threshold there is)
        stricter = float(np.nextafter(sel.threshold, np.inf if hib else -np.inf))
        assert shaded_saving(stricter) < reachable * (1 - 1e-12), (sel, reachable)


@settings(max_examples=120, deadline=None, derandomize=True, database=None)
@given(values=_predictions, threshold=_thresholds, allowed=st.one_of(st.none(), st.lists(st.sampled_from(sdk.ALL_RATES),
       unique=True)), factors=st.one_of(st.none(), st.lists(st.sampled_from([0.5, 1.16, 2.0]), min_size=6, max_size=6)),
       hib=st.booleans(), combiner=st.sampled_from(["min", "max", "sum"]), data=st.data())
def test_beside_engine_rates_each_tile_shades_the_cheapest_reachable_rate_that_passes(
        values: np.ndarray, threshold: float, allowed: list[str] | None, factors: list[float] | None, hib: bool,
        combiner: str, data: st.DataObject) -> None:
    """docs/runtime.md "The engine's own rates": per tile, over every allowed image rate, the rate the device shades
    (combine_rates, clamped; the worse of two where a device may choose) is judged against the threshold, and the
    tile shades the largest area of those that pass, else what the engine's rate forces alone; the image holds
    allowed rates only, and with min and max it is the rate shaded."""
    from rtp.sdk._rates import _combined
    supported = ("1x1", *sdk.resolve_allowed(allowed))
    th, tw = values.shape[1:]
    engine = np.array(data.draw(st.lists(st.sampled_from([sdk.RATE_CODES[r] for r in supported]), min_size=th * tw,
                                         max_size=th * tw)), np.uint8).reshape(th, tw)
    if hib:
        values, threshold = 40.0 - 10.0 * values, 40.0 - 10.0 * threshold
    scale = np.asarray(factors or [1.0] * 6)
    passes = (lambda v, i: v > threshold - 20 * np.log10(scale[i])) if hib else (lambda v, i: v < threshold * scale[i])
    image = sdk.select_rates(values, threshold, higher_is_better=hib, allowed=allowed, factors=factors,
                             engine_rates=engine, combiner=combiner)
    shaded = sdk.combine_rates(engine, image, combiner, allowed=allowed)
    assert {sdk.RATE_NAMES[int(c)] for c in np.unique(image)} <= set(supported)
    if combiner != "sum":
        np.testing.assert_array_equal(shaded, image)
    for i, j in np.ndindex(th, tw):
        best = 1
        for c in supported:
            may = _combined(combiner, sdk.RATE_NAMES[int(engine[i, j])], c, supported)
            channels = [sdk.PREDICTED_RATES.index(r) for r in may if r != "1x1"]
            if c == "1x1" or all(passes(values[k, i, j], k) for k in channels):
                best = max(best, _AREA[sdk.RATE_CODES[may[0]]])
        assert _AREA[int(shaded[i, j])] == best, (i, j, engine[i, j], image[i, j])
