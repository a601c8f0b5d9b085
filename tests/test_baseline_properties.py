"""Properties of the classic baselines ``evaluate.Yang2019`` (NVIDIA Adaptive Shading, Yang et al. 2019) and
``evaluate.FidelityFX`` (AMD FidelityFX Variable Shading), checked with hypothesis on small random frames (1x1 to
64x48, luma in [0, 1], random motion and seen masks). The specification is docs/evaluation.md "Baselines" and the
algorithms it cites (the paper's Eqs. 2, 15, 16, 20, 21; FFX's shader): what a larger threshold or cutoff, motion,
an unseen tile, a flat or an edged frame, a flip or a transpose, a partial edge tile and bad input do."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rtp import sdk
from rtp.evaluate import BaselineError, FidelityFX, Frame, Yang2019, motion_factor_half, motion_factor_quarter
from rtp.sdk import PREDICTED_RATES, RATE_CODES

#: few examples each, so that the full suite stays fast (hypothesis draws new ones every run); a few hundred
#: with RTP_PROPERTY_EXAMPLES=300
FAST = settings(max_examples=int(os.environ.get("RTP_PROPERTY_EXAMPLES", "30")), deadline=None,
                suppress_health_check=[HealthCheck.too_slow])

sizes = st.tuples(st.integers(1, 64), st.integers(1, 48))
yang_tiles = st.sampled_from([2, 3, 4, 8, 16, 32])
ffx_tiles = st.sampled_from([8, 16, 32])
seeds = st.integers(0, 2**32 - 1)
#: 1x2 <-> 2x1 and 2x4 <-> 4x2: a rate's code under a transpose of the frame
_SWAP = {RATE_CODES[a]: RATE_CODES[b] for a, b in (("1x1", "1x1"), ("1x2", "2x1"), ("2x1", "1x2"), ("2x2", "2x2"),
                                                   ("2x4", "4x2"), ("4x2", "2x4"), ("4x4", "4x4"))}


def _image(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """A display image ``(H, W, 3)`` in [0, 1]: a random mean, noise of a random amplitude (sometimes none: flat
    areas and ties), sometimes a few hard edges, sometimes quantised (equal neighbours)."""
    base = rng.uniform(0.0, 1.0)
    amp = rng.choice([0.0, 0.01, 0.05, 0.1, 0.3, 1.0])
    img = base + amp * (rng.random((h, w, 3)) - 0.5)
    if rng.random() < 0.3:  # hard edges: a few rectangles of another level
        for _ in range(int(rng.integers(1, 4))):
            y0, x0 = int(rng.integers(0, h)), int(rng.integers(0, w))
            img[y0:y0 + int(rng.integers(1, h + 1)), x0:x0 + int(rng.integers(1, w + 1))] = rng.uniform(0, 1, 3)
    if rng.random() < 0.3:
        img = np.round(img * 8) / 8
    return np.clip(img, 0.0, 1.0).astype(np.float32)


def _motion(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Screen motion in pixels ``(H, W, 2)``: a random uniform part plus per-pixel noise, some of it 0."""
    m = rng.normal(0.0, rng.choice([0.0, 0.5, 4.0, 20.0, 1e4]), 2) + rng.normal(0.0, rng.choice([0.0, 1.0, 8.0]), (h, w, 2))
    return np.where(rng.random((h, w, 1)) < 0.2, 0.0, m).astype(np.float32)


def _seen(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """A 0/1 seen mask: all seen, all unseen, random pixels or a seen rectangle."""
    kind = rng.integers(0, 4)
    if kind < 2:
        return np.full((h, w), float(kind), np.float32)
    if kind == 2:
        return (rng.random((h, w)) < rng.random()).astype(np.float32)
    s = np.zeros((h, w), np.float32)
    s[int(rng.integers(0, h)):, int(rng.integers(0, w)):] = 1.0
    return s


def _frame(seed: int, size: tuple[int, int], motion: bool = True, seen: bool = True) -> Frame:
    rng = np.random.default_rng(seed)
    h, w = size
    return Frame(_image(rng, h, w), _motion(rng, h, w) if motion else None, _seen(rng, h, w) if seen else None)


def _axes(codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shading-rate size per axis, (x, y), 1, 2 or 4: the D3D12 code is ``(log2 W << 2) | log2 H``."""
    codes = np.asarray(codes, np.int64)
    return 1 << (codes >> 2), 1 << (codes & 3)


def _area(codes: np.ndarray) -> np.ndarray:
    x, y = _axes(codes)
    return x * y


def _grid(size: tuple[int, int], tile: int) -> tuple[int, int]:
    return -(-size[0] // tile), -(-size[1] // tile)


def _codes(rates: list[str] | tuple[str, ...]) -> set[int]:
    return {RATE_CODES[r] for r in rates}


def _transposed(frame: Frame) -> Frame:
    motion = None if frame.motion is None else np.ascontiguousarray(frame.motion.transpose(1, 0, 2)[..., ::-1])
    seen = None if frame.seen is None else np.ascontiguousarray(frame.seen.T)
    return Frame(np.ascontiguousarray(frame.reprojected.transpose(1, 0, 2)), motion, seen)


def _flipped(frame: Frame, axis: int) -> Frame:
    """``frame`` mirrored along ``axis`` (1: left-right, 0: up-down), the motion's component along it negated."""
    motion = None
    if frame.motion is not None:
        motion = np.flip(frame.motion, axis).copy()
        motion[..., 1 - axis] *= -1  # (x is channel 0, y channel 1)
    seen = None if frame.seen is None else np.flip(frame.seen, axis).copy()
    return Frame(np.flip(frame.reprojected, axis).copy(), motion, seen)


# -- Yang 2019 ------------------------------------------------------------------------------------------------------

yang_options = st.fixed_dictionaries({
    "norm": st.sampled_from(["max", "rms"]), "motion": st.booleans(), "allow_4x4": st.booleans(),
    "motion_reduce": st.sampled_from(["min", "mean", "max"]), "env_luminance": st.sampled_from([0.0, 0.02, 0.07]),
    "k": st.sampled_from([1.0, 2.13, 4.0]), "motion_scale": st.sampled_from([0.0, 0.5, 1.0, 3.0]),
})
thresholds = st.sampled_from([0.0, 0.01, 0.05, 0.1, 0.25, 0.5, 1.0, 4.0, 1e6])


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, t1=thresholds, t2=thresholds)
def test_yang_a_larger_threshold_never_gives_a_finer_rate_on_either_axis(
        size: tuple[int, int], tile: int, opts: dict, seed: int, t1: float, t2: float) -> None:
    """Eq. 16 per axis against ``t (L + l)``: a larger sensitivity passes every rate a smaller one passes, so each
    axis's rate is as coarse or coarser; the codes are the grid's, uint8, never 4x1/1x4, no 4x4 without
    ``allow_4x4``."""
    lo, hi = sorted((t1, t2))
    frame = _frame(seed, size)
    yang = Yang2019(tile, **opts)
    a, b = yang.shading_rates(frame, lo), yang.shading_rates(frame, hi)
    assert a.dtype == np.uint8 and a.shape == _grid(size, tile)
    allowed = _codes(PREDICTED_RATES if opts["allow_4x4"] else PREDICTED_RATES[:-1]) | {RATE_CODES["1x1"]}
    assert set(np.unique(a)) <= allowed and set(np.unique(b)) <= allowed
    (ax, ay), (bx, by) = _axes(a), _axes(b)
    assert (bx >= ax).all() and (by >= ay).all()
    if lo == 0:
        assert (a == RATE_CODES["1x1"]).all()  # (nothing is below 0)


def _eq16(yang: Yang2019, frame: Frame, t: float) -> np.ndarray:
    """The paper's decision, per axis (Eq. 16 in JNYang-like units: ``n = E / (L + l)``, full rate where
    ``b_H n >= t``, else half where ``b_Q n >= t``, else quarter), OR-combined, 4x1 / 1x4 demoted to 2x1 / 1x2."""
    (e_y, e_x), mean = yang.half_rate_error(frame)
    speeds = yang.tile_motion(frame)
    denom = mean + yang.env_luminance
    sizes = []
    for e, v in zip((e_x, e_y), (speeds[1], speeds[0])):
        with np.errstate(divide="ignore", invalid="ignore"):
            n = np.where(denom > 0, e / np.where(denom > 0, denom, 1.0), np.where(e > 0, np.inf, 0.0))
        half = np.float32(motion_factor_half(v) * n) >= t  # (the estimates are float32)
        quarter = np.float32(motion_factor_quarter(v, yang.k) * n) >= t
        sizes.append(np.where(half, 1, np.where(quarter, 2, 4)))
    x, y = sizes
    x, y = np.where((x == 4) & (y == 1), 2, x), np.where((y == 4) & (x == 1), 2, y)
    return ((np.log2(x).astype(np.int64) << 2) | np.log2(y).astype(np.int64)).astype(np.uint8)


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, t=thresholds)
def test_yang_rates_are_the_paper_s_per_axis_decision(size: tuple[int, int], tile: int, opts: dict, seed: int,
                                                      t: float) -> None:
    """docs/evaluation.md: "the cheapest rate below t" is the paper's per-axis decision (Eq. 16) OR-combined, at any
    speed and any ``k >= 1``; without ``allow_4x4`` its 4x4 becomes 2x4 or 4x2."""
    frame = _frame(seed, size)
    yang = Yang2019(tile, **opts)
    got, want = yang.shading_rates(frame, t), _eq16(yang, frame, t)
    if not opts["allow_4x4"]:
        quarter = want == RATE_CODES["4x4"]
        assert np.isin(got[quarter], list(_codes(("2x4", "4x2")))).all()
        got, want = got[~quarter], want[~quarter]
    np.testing.assert_array_equal(got, want)


def test_yang_a_quarter_rate_needs_the_half_rate_to_pass_at_any_speed() -> None:
    """Regression: with ``k = 1`` and 20000 px/frame ``b_Q`` is below ``b_H``, and a tile whose horizontal half rate
    fails (``b_H n_x >= t``) got 4x4 from its quarter estimate ``b_Q n_x < t``; Eq. 16 keeps x at full rate: 1x2."""
    img = np.zeros((8, 8, 3), np.float32)
    img[:, ::2] = 0.5  # contrast along x only
    motion = np.zeros((8, 8, 2), np.float32)
    motion[..., 0] = 2e4
    yang = Yang2019(8, k=1.0)
    frame = Frame(img, motion)
    n_x = 0.5 / (0.25 + 0.02)
    assert motion_factor_quarter(2e4, 1.0) < motion_factor_half(2e4)  # (the case)
    t = float(np.sqrt(motion_factor_quarter(2e4, 1.0) * motion_factor_half(2e4))) * n_x  # between the two
    assert yang.shading_rates(frame, t)[0, 0] == RATE_CODES["1x2"]
    assert yang.shading_rates(frame, t)[0, 0] == _eq16(yang, frame, t)[0, 0]


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, t=thresholds, allowed=st.sets(
    st.sampled_from(PREDICTED_RATES), min_size=0, max_size=6))
def test_yang_rates_stay_in_the_allowed_set(size: tuple[int, int], tile: int, opts: dict, seed: int, t: float,
                                            allowed: set[str]) -> None:
    """Whatever ``allowed`` leaves (and ``allow_4x4=False`` takes away), a tile gets one of those rates or 1x1."""
    yang = Yang2019(tile, **opts)
    codes = yang.shading_rates(_frame(seed, size), t, allowed=sorted(allowed))
    ok = allowed - ({"4x4"} if not opts["allow_4x4"] else set())
    assert set(np.unique(codes)) <= _codes(sorted(ok)) | {RATE_CODES["1x1"]}


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, level=st.floats(0.0, 1.0),
       t=st.sampled_from([0.01, 0.25, 1.0]))
def test_yang_a_flat_frame_gets_the_coarsest_allowed_rate_and_a_checkerboard_full_rate(
        size: tuple[int, int], tile: int, opts: dict, seed: int, level: float, t: float) -> None:
    """No contrast: every estimate is 0, below any threshold > 0: 4x4 (2x4 without 4x4: the first of the two equal
    ones), with or without motion. A one-pixel checkerboard of 0 and 1: ``|dL| = 1`` on both axes over a mean
    about 0.5, so 1x1 wherever a tile holds pairs along both axes, 1x2 (2x1) on a single row (column) tile."""
    h, w = size
    rng = np.random.default_rng(seed)
    motion = _motion(rng, h, w) if opts["motion"] else None
    flat = Yang2019(tile, **opts).shading_rates(Frame(np.full((h, w, 3), level, np.float32), motion), t)
    assert (flat == RATE_CODES["4x4" if opts["allow_4x4"] else "2x4"]).all()
    board = (np.indices((h, w)).sum(axis=0) % 2).astype(np.float32)
    yang = Yang2019(tile, **{**opts, "motion": False, "norm": "max"})
    codes = yang.shading_rates(np.repeat(board[..., None], 3, axis=2), t)
    t_eff = min(tile, max(h, w))
    rows = np.minimum(t_eff, h - np.arange(codes.shape[0]) * t_eff)[:, None]  # pixels each tile holds per axis
    cols = np.minimum(t_eff, w - np.arange(codes.shape[1]) * t_eff)[None, :]
    x, y = _axes(codes)
    assert ((x == 1) | (cols == 1)).all() and ((y == 1) | (rows == 1)).all()
    assert (x[np.broadcast_to(cols > 1, x.shape)] == 1).all() and (y[np.broadcast_to(rows > 1, y.shape)] == 1).all()


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, t=thresholds,
       unseen=st.sampled_from(["as_is", "full"]), fraction=st.sampled_from([0.0, 0.25, 0.5, 0.75]))
def test_yang_each_tile_reads_only_its_own_pixels(size: tuple[int, int], tile: int, opts: dict, seed: int, t: float,
                                                  unseen: str, fraction: float) -> None:
    """Only neighbour pairs inside a tile count, the mean luma, speed and unseen share are over the pixels the tile
    holds: a tile's estimates and rate, partial edge tiles included, are those of its pixels cut out as a frame."""
    frame = _frame(seed, size)
    yang = Yang2019(tile, unseen=unseen, unseen_fraction=fraction, **opts)
    est, codes = yang.predict(frame), yang.shading_rates(frame, t)
    t_eff = min(tile, max(size))
    for i in range(codes.shape[0]):
        for j in range(codes.shape[1]):
            cut = (slice(i * t_eff, (i + 1) * t_eff), slice(j * t_eff, (j + 1) * t_eff))
            assert frame.motion is not None and frame.seen is not None
            part = Frame(frame.reprojected[cut], frame.motion[cut], frame.seen[cut])
            np.testing.assert_allclose(yang.predict(part)[:, 0, 0], est[:, i, j], rtol=1e-6, atol=1e-7)
            alone = yang.shading_rates(part, t)[0, 0]
            assert alone == codes[i, j] or _area(alone) == _area(codes[i, j]), (i, j)  # (a tie of 1x2 and 2x1)


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, t=thresholds, axis=st.sampled_from([0, 1]))
def test_yang_is_symmetric_under_a_flip(size: tuple[int, int], tile: int, opts: dict, seed: int, t: float,
                                        axis: int) -> None:
    """Absolute differences, means and speeds do not see a mirror: a frame of whole tiles along the flipped axis
    (or one tile) gets the same estimates and rates, mirrored."""
    t_eff = min(tile, max(size))
    h, w = size
    size = (h - h % t_eff or h, w) if axis == 0 else (h, w - w % t_eff or w)
    frame = _frame(seed, size)
    yang = Yang2019(tile, **opts)
    mirrored = _flipped(frame, axis)
    np.testing.assert_allclose(np.flip(yang.predict(mirrored), axis + 1), yang.predict(frame), rtol=1e-6, atol=1e-7)
    got, want = np.flip(yang.shading_rates(mirrored, t), axis), yang.shading_rates(frame, t)
    assert ((got == want) | (_area(got) == _area(want))).all()


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, t=thresholds)
def test_yang_under_a_transpose_swaps_the_axes(size: tuple[int, int], tile: int, opts: dict, seed: int,
                                               t: float) -> None:
    """Eq. 2 per axis: transposing the frame (and its motion) swaps E_x and E_y, so 1x2 <-> 2x1 and 2x4 <-> 4x2 in
    the estimates, and in the rates wherever the two rates of the pair do not tie."""
    frame = _frame(seed, size)
    yang = Yang2019(tile, **opts)
    est, est_t = yang.predict(frame), yang.predict(_transposed(frame)).transpose(0, 2, 1)
    np.testing.assert_allclose(est_t[[1, 0, 2, 4, 3, 5]], est, rtol=1e-6, atol=1e-7)
    codes, codes_t = yang.shading_rates(frame, t), yang.shading_rates(_transposed(frame), t).T
    swapped = np.vectorize(_SWAP.get, otypes=[np.int64])(codes_t)
    near = lambda a, b: np.isclose(est[a], est[b], rtol=1e-5, atol=1e-7)  # noqa: E731
    tie = near(0, 1) | near(3, 4)
    assert (swapped == codes)[~tie].all()
    assert (_area(codes_t) == _area(codes)).all()


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, t=thresholds)
def test_yang_motion_only_coarsens_and_zero_motion_is_no_motion(size: tuple[int, int], tile: int, opts: dict,
                                                                seed: int, t: float) -> None:
    """``b_H <= 1`` and ``b_Q <= k``, both 1 and k at rest: motion lowers every estimate, so the work saved per tile
    never drops, and a zero motion buffer (or ``motion=False``) gives exactly the estimates of none."""
    frame = _frame(seed, size)
    yang = Yang2019(tile, **{**opts, "motion": True})
    still = Frame(frame.reprojected, None, frame.seen)
    est, est0 = yang.predict(frame), yang.predict(still)
    assert (est <= est0 * (1 + 1e-6) + 1e-7).all()
    assert (_area(yang.shading_rates(frame, t)) >= _area(yang.shading_rates(still, t))).all()
    zero = Frame(frame.reprojected, np.zeros_like(frame.motion), frame.seen)
    np.testing.assert_array_equal(yang.predict(zero), est0)
    off = Yang2019(tile, **{**opts, "motion": False})
    np.testing.assert_array_equal(off.predict(frame), est0)


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, t=thresholds,
       fraction=st.sampled_from([0.0, 0.25, 0.5, 0.75]))
def test_yang_unseen_full_gives_1x1_exactly_on_tiles_more_than_the_share_unseen(
        size: tuple[int, int], tile: int, opts: dict, seed: int, t: float, fraction: float) -> None:
    """``unseen="full"``: 1x1 on every tile whose unseen share (over the pixels it holds) exceeds
    ``unseen_fraction``, exactly half counting as seen; every other tile as ``unseen="as_is"`` gives it."""
    frame = _frame(seed, size)
    full = Yang2019(tile, unseen="full", unseen_fraction=fraction, **opts)
    as_is = Yang2019(tile, unseen="as_is", unseen_fraction=fraction, **opts)
    assert frame.seen is not None
    t_eff = min(tile, max(size))
    th, tw = _grid(size, tile)
    unseen = np.zeros((th, tw), bool)
    for i in range(th):
        for j in range(tw):
            s = frame.seen[i * t_eff:(i + 1) * t_eff, j * t_eff:(j + 1) * t_eff]
            unseen[i, j] = 4 * int((s == 0).sum()) > int(4 * fraction) * s.size  # (exact: counts, quarter shares)
    got, ref = full.shading_rates(frame, t), as_is.shading_rates(frame, t)
    assert (got[unseen] == RATE_CODES["1x1"]).all()
    np.testing.assert_array_equal(got[~unseen], ref[~unseen])


@FAST
@given(size=sizes, tile=yang_tiles, opts=yang_options, seed=seeds, t=thresholds)
def test_yang_the_rms_norm_is_never_finer_than_the_max_and_a_larger_l_never_finer(
        size: tuple[int, int], tile: int, opts: dict, seed: int, t: float) -> None:
    """Eq. 2's RMS of ``dL / 2`` is at most half the largest ``|dL|``; ``E / (L + l)`` falls as ``l`` grows: both
    only lower the estimates, so neither ever takes a tile to a cheaper-to-miss, finer rate."""
    frame = _frame(seed, size)
    rms, mx = (Yang2019(tile, **{**opts, "norm": n}) for n in ("rms", "max"))
    assert (rms.predict(frame) <= 0.5 * mx.predict(frame) * (1 + 1e-6) + 1e-7).all()
    assert (_area(rms.shading_rates(frame, t)) >= _area(mx.shading_rates(frame, t))).all()
    bright = Yang2019(tile, **{**opts, "env_luminance": opts["env_luminance"] + 0.1})
    assert (_area(bright.shading_rates(frame, t)) >= _area(Yang2019(tile, **opts).shading_rates(frame, t))).all()


# -- FidelityFX ----------------------------------------------------------------------------------------------------

cutoffs = st.sampled_from([0.0, 0.001, 0.01, 0.05, 0.1, 0.3, 1.0, 2.0])
motion_factors = st.sampled_from([0.0, 0.01, 0.05, 0.1])


@FAST
@given(size=sizes, tile=ffx_tiles, mf=motion_factors, seed=seeds, c1=cutoffs, c2=cutoffs)
def test_ffx_base_a_larger_cutoff_never_gives_a_finer_rate_on_either_axis(
        size: tuple[int, int], tile: int, mf: float, seed: int, c1: float, c2: float) -> None:
    """Base path: ``dz < c`` -> 2x2, else along the larger delta 1x2 / 2x1 when the other ``<= c``: the deltas do
    not depend on ``c``, so a larger cutoff keeps or coarsens each axis; only 1x1, 1x2, 2x1 and 2x2 occur."""
    lo, hi = sorted((c1, c2))
    frame = _frame(seed, size)
    ffx = FidelityFX(tile, motion_factor=mf)
    a, b = ffx.shading_rates(frame, lo), ffx.shading_rates(frame, hi)
    assert a.dtype == np.uint8 and a.shape == _grid(size, tile)
    assert set(np.unique(a)) | set(np.unique(b)) <= _codes(("1x1", "1x2", "2x1", "2x2"))
    (ax, ay), (bx, by) = _axes(a), _axes(b)
    assert (bx >= ax).all() and (by >= ay).all()


@FAST
@given(size=sizes, tile=ffx_tiles, mf=motion_factors, seed=seeds, c1=cutoffs, c2=cutoffs)
def test_ffx_additional_a_larger_cutoff_never_lowers_the_ranges_passing(
        size: tuple[int, int], tile: int, mf: float, seed: int, c1: float, c2: float) -> None:
    """Additional rates: the codes are FFX's seven (never 4x1 / 1x4, the per-axis finest of neighbours included),
    and a tile whose every sub-block range passes a cutoff is 4x4 at it and at any larger one."""
    lo, hi = sorted((c1, c2))
    frame = _frame(seed, size)
    ffx = FidelityFX(tile, motion_factor=mf, additional_rates=True)
    a, b = ffx.shading_rates(frame, lo), ffx.shading_rates(frame, hi)
    assert a.shape == _grid(size, tile) and set(np.unique(a)) | set(np.unique(b)) <= _codes(PREDICTED_RATES + ("1x1",))
    assert (b[a == RATE_CODES["4x4"]] == RATE_CODES["4x4"]).all()


def test_ffx_additional_per_axis_neighbours_can_make_a_larger_cutoff_finer() -> None:
    """docs/evaluation.md, FidelityFX's departures, neighbours with additional rates: per 4x4 block of quadrants
    ``a b / c d`` the 4x2 range is ``max(|a-b|, |c-d|)``, the 2x4 one ``max(|a-c|, |b-d|)``. The first block
    turns from 2x4 to 4x2 as the cutoff passes its 4x2 range (0.1); beside 2x4 blocks the per-axis finest is then
    2x2 (FFX's code minimum: 2x4)."""
    def block(a: float, b: float, c: float, d: float) -> np.ndarray:
        q = np.empty((4, 4))
        q[:2, :2], q[:2, 2:], q[2:, :2], q[2:, 2:] = a, b, c, d
        return q
    first, other = block(0.0, 0.1, 0.01, 0.11), block(0.0, 0.3, 0.01, 0.31)
    img = np.repeat(np.block([[first, other], [other, other]])[..., None], 3, axis=2).astype(np.float32)
    ffx = FidelityFX(8, motion_factor=0.0, additional_rates=True)
    got = [int(ffx.shading_rates(img, c)[0, 0]) for c in (0.05, 0.105, 0.2, 0.32)]
    assert got == [RATE_CODES[r] for r in ("2x4", "2x2", "2x4", "4x4")]


@FAST
@given(size=sizes, tile=ffx_tiles, mf=motion_factors, seed=seeds, level=st.floats(0.0, 1.0),
       c=st.sampled_from([0.001, 0.05, 0.3]), additional=st.booleans())
def test_ffx_a_flat_frame_gets_the_coarsest_rate_and_a_checkerboard_full_rate(
        size: tuple[int, int], tile: int, mf: float, seed: int, level: float, c: float, additional: bool) -> None:
    """No contrast: every delta is 0 < c: 2x2 (base path) or 4x4 (additional rates), moving or not. A one-pixel
    checkerboard of 0 and 1 (at least 2x2 pixels, still): every delta is 1 > c, so full rate along each axis on
    which the tile holds two pixels or more (a tile of one real column reads the screen edge clamped: no
    horizontal contrast, so FFX may halve it, which costs nothing there)."""
    h, w = size
    rng = np.random.default_rng(seed)
    ffx = FidelityFX(tile, motion_factor=mf, additional_rates=additional)
    flat = ffx.shading_rates(Frame(np.full((h, w, 3), level, np.float32), _motion(rng, h, w)), c)
    assert (flat == RATE_CODES["4x4" if additional else "2x2"]).all()
    h, w = max(h, 2), max(w, 2)
    board = (np.indices((h, w)).sum(axis=0) % 2).astype(np.float32)
    x, y = _axes(ffx.shading_rates(np.repeat(board[..., None], 3, axis=2), c))
    rows = np.minimum(tile, h - np.arange(x.shape[0]) * tile)[:, None]  # pixels each tile holds per axis
    cols = np.minimum(tile, w - np.arange(x.shape[1]) * tile)[None, :]
    assert (x[np.broadcast_to(cols > 1, x.shape)] == 1).all() and (y[np.broadcast_to(rows > 1, y.shape)] == 1).all()


@FAST
@given(size=sizes, tile=ffx_tiles, mf=motion_factors, seed=seeds, c=cutoffs, additional=st.booleans(),
       axis=st.sampled_from([0, 1]))
def test_ffx_is_symmetric_under_a_flip(size: tuple[int, int], tile: int, mf: float, seed: int, c: float,
                                       additional: bool, axis: int) -> None:
    """Pair differences, ranges, motion lengths and the 4-neighbourhood do not see a mirror: a frame of whole tiles
    along the flipped axis gets the same deltas and rates, mirrored."""
    h, w = size
    size = (max(tile, h - h % tile), w) if axis == 0 else (h, max(tile, w - w % tile))
    frame = _frame(seed, size)
    ffx = FidelityFX(tile, motion_factor=mf, additional_rates=additional)
    mirrored = _flipped(frame, axis)
    np.testing.assert_allclose(np.flip(ffx.predict(mirrored), axis + 1), ffx.predict(frame), rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(np.flip(ffx.shading_rates(mirrored, c), axis), ffx.shading_rates(frame, c))


@FAST
@given(size=sizes, tile=ffx_tiles, mf=motion_factors, seed=seeds, c=cutoffs)
def test_ffx_base_under_a_transpose_swaps_the_axes(size: tuple[int, int], tile: int, mf: float, seed: int,
                                                   c: float) -> None:
    """Base path: transposing swaps ``dx`` and ``dy`` (``dz`` stays), so 1x2 <-> 2x1 wherever ``dx != dy`` (on a tie
    FFX's rule takes 2x1 both ways)."""
    frame = _frame(seed, size)
    ffx = FidelityFX(tile, motion_factor=mf)
    est, est_t = ffx.predict(frame), ffx.predict(_transposed(frame)).transpose(0, 2, 1)
    np.testing.assert_allclose(est_t[[1, 0, 2]], est[:3], rtol=1e-6, atol=1e-7)
    codes, codes_t = ffx.shading_rates(frame, c), ffx.shading_rates(_transposed(frame), c).T
    swapped = np.vectorize(_SWAP.get, otypes=[np.int64])(codes_t)
    tie = np.isclose(est[0], est[1], rtol=1e-5, atol=1e-7)
    assert (swapped == codes)[~tie].all()


@FAST
@given(size=sizes, tile=ffx_tiles, mf=motion_factors, seed=seeds, c=cutoffs.filter(lambda c: c > 0),
       additional=st.booleans())
def test_ffx_motion_only_lowers_the_deltas_and_zero_motion_is_no_motion(
        size: tuple[int, int], tile: int, mf: float, seed: int, c: float, additional: bool) -> None:
    """``|mv| * motion_factor`` is subtracted (the anti-burn-in padding cannot win it back): every delta with motion
    is at most the still one, the base path's work saved per tile never drops, and a zero motion buffer (or
    ``motion_factor=0``) is exactly no motion."""
    frame = _frame(seed, size)
    ffx = FidelityFX(tile, motion_factor=mf, additional_rates=additional)
    still = Frame(frame.reprojected, None, frame.seen)
    est, est0 = ffx.predict(frame), ffx.predict(still)
    assert (est <= est0 + 1e-6).all()
    if not additional:
        assert (_area(ffx.shading_rates(frame, c)) >= _area(ffx.shading_rates(still, c))).all()
    zero = Frame(frame.reprojected, np.zeros_like(frame.motion), frame.seen)
    np.testing.assert_array_equal(ffx.shading_rates(zero, c), ffx.shading_rates(still, c))
    off = FidelityFX(tile, motion_factor=0.0, additional_rates=additional)
    np.testing.assert_array_equal(off.predict(frame), est0)


@FAST
@given(size=sizes, tile=ffx_tiles, mf=motion_factors, seed=seeds, c=cutoffs, additional=st.booleans())
def test_ffx_partial_edge_tiles_read_the_screen_edge_clamped(size: tuple[int, int], tile: int, mf: float, seed: int,
                                                             c: float, additional: bool) -> None:
    """FFX fetches luma clamped to the screen: a frame whose last tiles are partial decides as the same frame with
    its last row and column repeated up to whole tiles."""
    frame = _frame(seed, size)
    h, w = size
    ph, pw = sdk.padded_size(h, w, tile)
    assert frame.motion is not None
    pad = ((0, ph - h), (0, pw - w), (0, 0))
    whole = Frame(np.pad(frame.reprojected, pad, mode="edge"), np.pad(frame.motion, pad, mode="edge"))
    ffx = FidelityFX(tile, motion_factor=mf, additional_rates=additional)
    np.testing.assert_array_equal(ffx.shading_rates(frame, c), ffx.shading_rates(whole, c))


# -- both ----------------------------------------------------------------------------------------------------------


@FAST
@given(size=sizes, seed=seeds, which=st.sampled_from(["yang", "ffx", "ffx-additional"]))
def test_float64_frames_decide_as_float32_ones(size: tuple[int, int], seed: int, which: str) -> None:
    """The frame is read as float32 colours: the same image in float64 gives the same estimates and rates."""
    frame = _frame(seed, size)
    method = Yang2019(16) if which == "yang" else FidelityFX(16, additional_rates=which == "ffx-additional")
    assert frame.motion is not None and frame.seen is not None
    wide = Frame(frame.reprojected.astype(np.float64), frame.motion.astype(np.float64), frame.seen.astype(np.float64))
    np.testing.assert_array_equal(method.predict(wide), method.predict(frame))
    np.testing.assert_array_equal(method.shading_rates(wide), method.shading_rates(frame))


_BAD_FRAMES = {
    "nan": (lambda f: Frame(np.where(np.indices(f.reprojected.shape)[0] == 0, np.nan, f.reprojected)),
            sdk.NonFiniteInputError),
    "hdr": (lambda f: Frame(f.reprojected * 3 + 2), sdk.InputError),
    "uint8": (lambda f: Frame((f.reprojected * 255).astype(np.uint8)), sdk.InputDtypeError),
    "gray": (lambda f: Frame(f.reprojected[..., 0]), sdk.InputShapeError),
    "motion shape": (lambda f: Frame(f.reprojected, np.zeros(f.reprojected.shape[:2] + (3,))), sdk.InputShapeError),
    "motion inf": (lambda f: Frame(f.reprojected, np.full(f.reprojected.shape[:2] + (2,), np.inf)),
                   sdk.NonFiniteInputError),
    "seen 255": (lambda f: Frame(f.reprojected, None, np.full(f.reprojected.shape[:2], 255.0)), sdk.InputError),
    "seen shape": (lambda f: Frame(f.reprojected, None, np.ones(f.reprojected.shape[:2] + (1,))), sdk.InputShapeError),
}


@FAST
@given(size=sizes, seed=seeds, bad=st.sampled_from(sorted(_BAD_FRAMES)),
       which=st.sampled_from(["yang", "yang-unseen", "ffx", "ffx-additional"]))
def test_bad_frames_raise_typed_errors(size: tuple[int, int], seed: int, bad: str, which: str) -> None:
    """NaN, HDR, 8-bit, single-channel, mis-shaped or infinite motion, a 0/255 seen mask: the input error of its
    kind (all ValueErrors), from ``predict`` and ``shading_rates`` alike, whatever the size."""
    make, error = _BAD_FRAMES[bad]
    frame = make(_frame(seed, size))
    method = (Yang2019(8, unseen="full" if which == "yang-unseen" else "as_is") if which.startswith("yang")
              else FidelityFX(8, additional_rates=which == "ffx-additional"))
    for call in (method.predict, method.shading_rates):
        with pytest.raises(error) as info:
            call(frame)
        assert isinstance(info.value, ValueError)


@pytest.mark.parametrize("make", [
    lambda: Yang2019(1), lambda: Yang2019(16.0), lambda: Yang2019(True), lambda: Yang2019(threshold=-0.1),
    lambda: Yang2019(threshold=float("nan")), lambda: Yang2019(threshold="0.25"), lambda: Yang2019(k=0.5),
    lambda: Yang2019(env_luminance=-1), lambda: Yang2019(motion_scale=float("inf") * 0),
    lambda: Yang2019(unseen_fraction=1.0), lambda: Yang2019(norm="l2"), lambda: Yang2019(motion="false"),
    lambda: Yang2019(allow_4x4=1), lambda: Yang2019(unseen="none"), lambda: Yang2019(motion_reduce="median"),
    lambda: FidelityFX(4), lambda: FidelityFX(12), lambda: FidelityFX(cutoff=-0.01), lambda: FidelityFX(cutoff=None),
    lambda: FidelityFX(motion_factor=float("nan")), lambda: FidelityFX(additional_rates="yes"),
], ids=lambda _: "")
def test_bad_parameters_raise_baseline_errors(make) -> None:
    with pytest.raises(BaselineError):
        make()


@FAST
@given(threshold=st.one_of(st.floats(max_value=-1e-300), st.just(float("nan")), st.just(float("inf")),
                           st.floats(min_value=1.5e6)), which=st.sampled_from(["yang", "ffx"]))
def test_bad_thresholds_raise_parameter_errors(threshold: float, which: str) -> None:
    frame = np.full((8, 8, 3), 0.5, np.float32)
    method = Yang2019(8) if which == "yang" else FidelityFX(8)
    with pytest.raises(sdk.ParameterError):
        method.shading_rates(frame, threshold)


def test_unseen_full_without_a_seen_mask_is_refused() -> None:
    with pytest.raises(BaselineError, match="seen mask"):
        Yang2019(8, unseen="full").shading_rates(np.zeros((8, 8, 3), np.float32))
