"""Baselines on constructed images, evaluation numbers on a constructed dataset, plots and `rtp evaluate`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rtp import sdk
from rtp.capture import BUFFERS, DatasetWriter, TargetStore
from rtp.cli import main as rtp_main
from rtp.evaluate import (
    BaselineError,
    FidelityFX,
    Frame,
    ModelSelector,
    Oracle,
    Yang2019,
    evaluate,
    failing_tiles,
    motion_factor_half,
    motion_factor_quarter,
    plots,
    restrict_rates,
    spearman,
    tile_unseen_share,
)

from .conftest import PAPER_INPUTS, base_metadata, build_onnx

C = sdk.RATE_CODES


def grey(v: np.ndarray) -> np.ndarray:
    return np.repeat(np.asarray(v, np.float32)[..., None], 3, axis=2)


def stripes(h: int = 32, w: int = 32, *, vertical_lines: bool = True) -> np.ndarray:
    """0.1/0.9 alternating columns (variation along x only), or rows when not ``vertical_lines``."""
    idx = np.arange(w)[None, :].repeat(h, 0) if vertical_lines else np.arange(h)[:, None].repeat(w, 1)
    return grey(0.1 + 0.8 * (idx % 2))


# -- baselines ------------------------------------------------------------------------------------


def test_motion_factors_match_the_papers_check_values() -> None:
    assert motion_factor_half(0) == 1.0 and motion_factor_quarter(0) == pytest.approx(2.13)
    assert motion_factor_half(16) == pytest.approx(0.047, abs=5e-4)
    assert motion_factor_quarter(16) == pytest.approx(0.163, abs=5e-4)


def test_flat_tile_gets_the_coarsest_rate() -> None:
    flat = grey(np.full((32, 48), 0.5))
    assert (Yang2019(16).shading_rates(flat) == C["4x4"]).all()
    assert (Yang2019(16).predict(flat) == 0).all()
    # NAS without 4x4: equal (zero) errors keep the first of 2x4 / 4x2
    assert (Yang2019(16, allow_4x4=False).shading_rates(flat) == C["2x4"]).all()
    assert (FidelityFX(16).shading_rates(flat) == C["2x2"]).all()
    assert (FidelityFX(16, additional_rates=True).shading_rates(flat) == C["4x4"]).all()
    assert (FidelityFX(8).shading_rates(flat)).shape == (4, 6)


@pytest.mark.parametrize("vertical_lines, expected", [(True, "1x2"), (False, "2x1")])
def test_variation_along_one_axis_halves_the_other(vertical_lines: bool, expected: str) -> None:
    img = stripes(vertical_lines=vertical_lines)
    for sel in (Yang2019(16), Yang2019(16, norm="rms", threshold=0.1), FidelityFX(16), FidelityFX(16, additional_rates=True)):
        assert (sel.shading_rates(img) == C[expected]).all(), sel


def test_yang_estimates_by_hand() -> None:
    img = stripes()  # luma 0.1 / 0.9 (grey, so every luma weighting agrees), mean 0.5
    est = Yang2019(16, env_luminance=0.02).predict(img)[:, 0, 0]
    ex = 0.8 / 0.52
    np.testing.assert_allclose(est, [0.0, ex, ex, ex, 2.13 * ex, 2.13 * ex], rtol=1e-5)
    rms = Yang2019(16, norm="rms", env_luminance=0.02).predict(img)[1, 0, 0]
    assert rms == pytest.approx(0.4 / 0.52, rel=1e-5)  # RMS of half the differences
    e, mean = Yang2019(16).half_rate_error(img)
    assert e.shape == (2, 2, 2) and mean[0, 0] == pytest.approx(0.5, rel=1e-5)


def test_yang_per_axis_decision_or_combined() -> None:
    rng = np.random.default_rng(3)
    up = lambda a: a.repeat(16, 0).repeat(16, 1)  # noqa: E731
    yy, xx = np.mgrid[0:64, 0:96]
    # per tile a random contrast along x and along y, and a random speed
    img = grey(0.5 + up(rng.uniform(0, 0.3, (4, 6))) * (xx % 2 - 0.5) + up(rng.uniform(0, 0.3, (4, 6))) * (yy % 2 - 0.5))
    motion = np.stack([up(rng.uniform(-3, 3, (4, 6))), up(rng.uniform(-3, 3, (4, 6)))], axis=2).astype(np.float32)
    y = Yang2019(16, threshold=0.25)
    frame = Frame(img, motion)
    (e_y, e_x), mean = y.half_rate_error(frame)
    v_y, v_x = y.tile_motion(frame)

    def level(e: np.ndarray, v: np.ndarray) -> np.ndarray:  # 0: full, 1: half, 2: quarter
        tau = 0.25 * (mean + 0.02)
        return np.where(motion_factor_half(v) * e >= tau, 0, np.where(motion_factor_quarter(v) * e >= tau, 1, 2))

    lx, ly = level(e_x, v_x), level(e_y, v_y)
    lx, ly = np.where((lx == 2) & (ly == 0), 1, lx), np.where((ly == 2) & (lx == 0), 1, ly)  # 4x1, 1x4 demoted
    expected = ((lx << 2) | ly).astype(np.uint8)
    np.testing.assert_array_equal(y.shading_rates(frame), expected)
    assert len(np.unique(expected)) > 2  # the case is not trivial


def test_motion_lowers_the_estimate() -> None:
    img = stripes()
    motion = np.zeros((32, 32, 2), np.float32)
    motion[..., 0] = 16.0  # 16 px/frame to the right
    still, moving = Yang2019(16).predict(img), Yang2019(16).predict({"reprojected": img, "motion": motion})
    assert moving[1, 0, 0] == pytest.approx(still[1, 0, 0] * motion_factor_half(16), rel=1e-5)
    assert moving[4, 0, 0] == pytest.approx(still[1, 0, 0] * motion_factor_quarter(16), rel=1e-5)
    assert (Yang2019(16, motion=False).predict({"reprojected": img, "motion": motion}) == still).all()
    f_still, f_moving = FidelityFX(16).predict(img), FidelityFX(16).predict(Frame(img, motion))
    assert (f_moving[1:3] < f_still[1:3]).all() and (f_moving[:3] <= f_still[:3]).all()
    # 16 px * 0.05 = 0.8 cancels the 0.8 luma step: the moving stripes are shaded coarsely
    assert (FidelityFX(16).shading_rates(Frame(img, motion)) == C["2x2"]).all()
    assert (FidelityFX(16).shading_rates(img) == C["1x2"]).all()


def test_unseen_black_is_coarse_unless_told_otherwise() -> None:
    black = np.zeros((32, 32, 3), np.float32)
    seen = np.zeros((32, 32), np.float32)
    seen[:, 16:] = 1.0  # right column of tiles seen
    assert (Yang2019(16).shading_rates(black) == C["4x4"]).all()
    assert (FidelityFX(16).shading_rates(black) == C["2x2"]).all()
    full = Yang2019(16, unseen="full")
    rates = full.shading_rates(Frame(black, None, seen))
    assert (rates[:, 0] == C["1x1"]).all() and (rates[:, 1] == C["4x4"]).all()
    with pytest.raises(BaselineError, match="seen mask"):
        full.predict(black)
    # dark content with l = 0 still works (no division by zero)
    assert np.isfinite(Yang2019(16, env_luminance=0.0).predict(black)).all()


def test_fidelityfx_anti_burn_in_and_parameters() -> None:
    img = grey(np.where(np.arange(32)[None, :] < 16, 0.2, 0.8).repeat(32, 0))  # two flat tiles, an edge between
    assert (FidelityFX(16).shading_rates(img) == C["1x1"]).all()  # the neighbourhood carries the edge in
    assert (FidelityFX(16, cutoff=0.7).shading_rates(img) == C["2x2"]).all()
    with pytest.raises(BaselineError, match="tile_size"):
        FidelityFX(12)
    assert FidelityFX(16).shading_rates(grey(np.full((40, 50), 0.3))).shape == (3, 4)
    with pytest.raises(sdk.InputShapeError):
        FidelityFX(16).predict(np.zeros((8, 8), np.float32))


def test_fidelityfx_additional_rates_combine_blocks_per_axis() -> None:
    """Blocks and their neighbours meet per axis (docs/evaluation.md "Where it departs from FFX's
    shader"): a 1x2 block beside a 2x1 one gives 1x1 (FFX's minimum of the codes: 1x2, which halves
    the axis the 2x1 block needs whole), a 4x2 beside a 2x4 gives 2x2 (the minimum of the codes: 2x4)."""
    ffx = FidelityFX(8, additional_rates=True, motion_factor=0.0)
    img = np.full((8, 8), 0.5)
    img[:4, :4] = 0.1 + 0.8 * (np.arange(4)[None, :] % 2)  # varies along x: 1x2 alone
    img[:4, 4:] = 0.1 + 0.8 * (np.arange(4)[:, None] % 2)  # varies along y: 2x1 alone
    assert ffx.shading_rates(grey(np.tile(img[:4, :4], (2, 2))))[0, 0] == C["1x2"]
    assert ffx.shading_rates(grey(np.tile(img[:4, 4:], (2, 2))))[0, 0] == C["2x1"]
    assert ffx.shading_rates(grey(img))[0, 0] == C["1x1"]
    img[:4, :4] = np.where(np.arange(4)[:, None] < 2, 0.2, 0.8)  # flat 4-wide, 2-tall halves: 4x2 alone
    img[:4, 4:] = np.where(np.arange(4)[None, :] < 2, 0.2, 0.8)  # flat 2-wide, 4-tall halves: 2x4 alone
    assert ffx.shading_rates(grey(np.tile(img[:4, :4], (2, 2))))[0, 0] == C["4x2"]
    assert ffx.shading_rates(grey(np.tile(img[:4, 4:], (2, 2))))[0, 0] == C["2x4"]
    assert ffx.shading_rates(grey(img))[0, 0] == C["2x2"]


@given(h=st.integers(8, 40), w=st.integers(8, 40), tile=st.sampled_from([8, 16]), seed=st.integers(0, 2**31 - 1))
@settings(max_examples=40, deadline=None)
def test_baseline_tile_quantities_follow_their_definitions(h: int, w: int, tile: int, seed: int) -> None:
    """Yang's half-rate errors, tile means and tile speeds, and FidelityFX's sub-block ranges (built
    rate from rate, without copies when the frame is whole tiles) equal a tile-by-tile loop over
    the definitions, on whole and ragged frames (edge tiles padded with copies of the last pixel)."""
    rng = np.random.default_rng(seed)
    img = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
    motion = rng.normal(0, 3, (h, w, 2)).astype(np.float32)
    frame = Frame(img, motion)
    th, tw = -(-h // tile), -(-w // tile)
    lum = (0.299 * img[..., 0] + 0.587 * img[..., 1] + 0.114 * img[..., 2]).astype(np.float64)
    edge = np.pad(lum, ((0, th * tile - h), (0, tw * tile - w)), mode="edge")
    speed = np.pad(np.abs(motion), ((0, th * tile - h), (0, tw * tile - w), (0, 0)), mode="edge")
    (e_y, e_x), mean = Yang2019(tile).half_rate_error(frame)
    v = Yang2019(tile, motion_scale=0.5).tile_motion(frame)
    v_max = Yang2019(tile, motion_scale=0.5, motion_reduce="max").tile_motion(frame)
    for i in range(th):
        for j in range(tw):
            t = edge[i * tile:(i + 1) * tile, j * tile:(j + 1) * tile]
            assert e_y[i, j] == np.abs(np.diff(t, axis=0)).max() and e_x[i, j] == np.abs(np.diff(t, axis=1)).max()
            assert mean[i, j] == pytest.approx(lum[i * tile:(i + 1) * tile, j * tile:(j + 1) * tile].mean(), rel=1e-12)
            m = speed[i * tile:(i + 1) * tile, j * tile:(j + 1) * tile]
            assert v[0, i, j] == 0.5 * float(m[..., 1].min()) and v[1, i, j] == 0.5 * float(m[..., 0].min())
            assert v_max[0, i, j] == 0.5 * float(m[..., 1].max()) and v_max[1, i, j] == 0.5 * float(m[..., 0].max())
    ffx = FidelityFX(tile, additional_rates=True, motion_factor=0.0)
    ranges = ffx._additional(frame)
    flum = np.pad((0.30 * img[..., 0] + 0.59 * img[..., 1] + 0.11 * img[..., 2]).astype(np.float64),
                  ((0, th * tile - h), (0, tw * tile - w)), mode="edge")
    for k, rate in enumerate(sdk.PREDICTED_RATES):
        rw, rh = sdk.rate_size(rate)
        for bi, bj in ((0, 0), (th * tile // 4 - 1, tw * tile // 4 - 1), (th * tile // 8, tw * tile // 8)):
            blk = flum[bi * 4:bi * 4 + 4, bj * 4:bj * 4 + 4]
            want = max(float(np.ptp(blk[y:y + rh, x:x + rw])) for y in range(0, 4, rh) for x in range(0, 4, rw))
            assert ranges[k, bi, bj] == want, (rate, bi, bj)


@pytest.mark.parametrize("options", [{}, {"unseen": "full"}, {"norm": "max"}, {"motion_reduce": "max"}])
def test_yang_with_a_tile_past_the_frame_estimates_the_one_tile(options: dict[str, Any]) -> None:
    """Yang2019(tile_size=10**6) padded the frame to 10**12 pixels before estimating its one tile."""
    rng = np.random.default_rng(1)
    frame = Frame(rng.random((37, 53, 3)).astype(np.float32), rng.normal(0, 3, (37, 53, 2)).astype(np.float32),
                  (rng.random((37, 53)) > 0.3).astype(np.float32))
    whole = Yang2019(53, **options).predict(frame)
    assert whole.shape == (6, 1, 1) and np.array_equal(Yang2019(10**6, **options).predict(frame), whole)


def test_monotone_over_rates_takes_the_worst_of_the_contained_rates() -> None:
    from rtp.evaluate import CONTAINED_RATES, monotone_over_rates

    names = [[sdk.PREDICTED_RATES[j] for j in c] for c in CONTAINED_RATES]
    assert names == [[], [], ["1x2", "2x1"], ["1x2", "2x1", "2x2"], ["1x2", "2x1", "2x2"],
                     ["1x2", "2x1", "2x2", "2x4", "4x2"]]
    rng = np.random.default_rng(2)
    v = rng.random((3, 6, 4, 5)).astype(np.float32)
    m = monotone_over_rates(v)
    assert m.dtype == v.dtype and m is not v and np.array_equal(monotone_over_rates(m), m)  # a copy; idempotent
    for i, below in enumerate(CONTAINED_RATES):
        assert np.array_equal(m[:, i], np.max(v[:, [i, *below]], axis=1))  # the contained rates' own, transitively
    assert np.array_equal(monotone_over_rates(v[0]), m[0])  # one frame (6, th, tw)
    assert np.array_equal(monotone_over_rates(-v, higher_is_better=True), -m)  # PSNR: the worst is the lowest
    with pytest.raises(sdk.InputShapeError, match="6 rate channels"):
        monotone_over_rates(np.zeros((5, 4, 4)))


def test_frames_sharing_terms_decide_as_alone() -> None:
    """Frames of one camera frame given one ``terms`` dict (``rtp play``: every method's own history,
    the same motion and seen mask) compute the per-tile speeds and unseen shares once and decide
    exactly as frames that do not share; the shared arrays are read-only."""
    rng = np.random.default_rng(3)
    motion = rng.normal(0, 3, (48, 64, 2)).astype(np.float32)
    seen = (rng.random((48, 64)) > 0.3).astype(np.float32)
    terms: dict = {}
    methods = [Yang2019(16, threshold=t) for t in (0.1, 0.3)] + [Yang2019(16, unseen="full")]
    methods += [FidelityFX(16, cutoff=c, additional_rates=a) for c in (0.05, 0.2) for a in (False, True)]
    for _ in range(2):  # histories differ per method; the terms stay
        for m in methods:
            img = rng.uniform(0, 1, (48, 64, 3)).astype(np.float32)
            alone = m.shading_rates(Frame(img, motion, seen))
            assert np.array_equal(m.shading_rates(Frame(img, motion, seen, terms=terms)), alone), m
            assert np.array_equal(m.shading_rates({"reprojected": img, "motion": motion, "seen": seen}), alone)
    assert {k[0] for k in terms} == {"yang2019.tile_motion", "yang2019.unseen", "fidelityfx.speed"}
    assert not any(v.flags.writeable for v in terms.values())
    shared = Frame(np.zeros((48, 64, 3), np.float32), motion, seen, terms=terms)
    with pytest.raises(ValueError):
        Yang2019(16).tile_motion(shared)[0, 0, 0] = 1.0


def test_restrict_rates_demotes_per_axis() -> None:
    codes = np.array([[C["4x4"], C["2x4"]], [C["2x2"], C["1x1"]]], np.uint8)
    est = np.zeros((6, 2, 2))
    est[sdk.PREDICTED_RATES.index("2x4")] = 1.0  # 4x2 is the better of the pair
    out = restrict_rates(codes, ["1x2", "2x1", "2x2", "2x4", "4x2"], est)
    np.testing.assert_array_equal(out, [[C["4x2"], C["2x4"]], [C["2x2"], C["1x1"]]])
    out = restrict_rates(codes, ["1x2", "2x1"])
    np.testing.assert_array_equal(out, [[C["1x2"], C["1x2"]], [C["1x2"], C["1x1"]]])
    flat = grey(np.full((16, 16), 0.5))
    assert FidelityFX(16, additional_rates=True).shading_rates(flat, allowed=["2x2"])[0, 0] == C["2x2"]


# -- a constructed dataset with known targets and a model with a known output ---------------------

H, W, T = 32, 64, 16  # 2 x 4 tiles of 16 px
# per tile: albedo.r level (k/255, exact in uint8) and the unseen pixel count out of 256
LEVELS = np.array([[0, 51, 102, 153], [204, 255, 51, 102]], np.float64) / 255.0
UNSEEN_PX = np.array([[0, 128, 129, 256], [0, 0, 200, 64]])  # 128 = exactly 50%: still seen


def _seen_mask() -> np.ndarray:
    seen = np.ones((H, W), np.float32)
    for i in range(2):
        for j in range(4):
            blk = np.ones(T * T, np.float32)
            blk[: UNSEEN_PX[i, j]] = 0.0
            seen[i * T : (i + 1) * T, j * T : (j + 1) * T] = blk.reshape(T, T)
    return seen


def _truth(sample_index: int) -> np.ndarray:
    """Known jnyang targets per 16-px tile for the six rates, (6, 2, 4)."""
    rng = np.random.default_rng(100 + sample_index)
    base = rng.uniform(0.02, 0.45, (2, 4))
    return np.stack([base * f for f in (1.0, 0.8, 1.0, 2.0, 1.7, 2.1)]).astype(np.float32)


@pytest.fixture
def dataset(tmp_path: Path) -> Path:
    root = tmp_path / "data"
    writer = DatasetWriter(root)
    store = TargetStore(root)
    store.declare("jnyang", {"weber_l": 0.02})
    rng = np.random.default_rng(0)
    seen = _seen_mask()
    for i, scene in enumerate(["a", "a", "b"]):
        bufs = {}
        for name, spec in BUFFERS.items():
            c = len(spec.channels) or 3
            bufs[name] = rng.random((H, W, c) if c > 1 else (H, W), dtype=np.float32)
        bufs["seen"] = seen
        bufs["reprojected"] = bufs["reprojected"] * seen[..., None]  # black where unseen
        bufs["motion"] = np.zeros((H, W, 2), np.float32)
        bufs["albedo"][..., 0] = np.roll(LEVELS, i, axis=1).repeat(T, 0).repeat(T, 1)
        sid = f"s{i}"
        writer.write(sid, bufs, {"scene": scene})
        truth = _truth(i).repeat(T // 4, 1).repeat(T // 4, 2)  # constant per 16-px tile at the 4-px base
        store.write(sid, "jnyang", truth, (H, W))
    writer.finalize()
    return root


META = base_metadata(outputs=["1x2", "2x1"], safety=0.05, default_threshold=0.2)


@pytest.fixture
def model(tmp_path: Path) -> Path:
    # 1x2 channel: sigmoid(4 albedo.r - 2); 2x1 channel: sigmoid(-2 albedo.r + 0.5)
    weights = np.zeros((2, 4), np.float32)
    weights[0, 2], weights[1, 2] = 4.0, -2.0
    bias = np.array([-2.0, 0.5], np.float32)
    return build_onnx(tmp_path / "m.onnx", weights=weights, bias=bias, tile=T, metadata=META)


def _expected_raw(i: int) -> np.ndarray:
    a = np.roll(LEVELS, i, axis=1)
    sig = lambda z: 1.0 / (1.0 + np.exp(-z))  # noqa: E731
    # max over the tile of w*a + b: the tile is constant, and for w < 0 too
    return np.stack([sig(4.0 * a - 2.0), sig(-2.0 * a + 0.5)])


def _hand_scores(p: np.ndarray, g: np.ndarray) -> dict[str, float]:
    d = p - g
    short = g - p
    return {
        "r2": 1.0 - float(np.sum(d**2)) / float(np.sum((g - g.mean()) ** 2)),
        "mae": float(np.mean(np.abs(d))),
        "mae_under": float(short[short > 0].mean()) if (short > 0).any() else 0.0,
        "under_share": float(np.mean(short > 0)),
        "sigma": float(np.std(np.abs(d))),
    }


def test_tile_unseen_share_and_rule() -> None:
    share = tile_unseen_share(_seen_mask(), T)
    np.testing.assert_allclose(share, UNSEEN_PX / 256.0)
    assert tile_unseen_share(np.ones((20, 20)), 16).shape == (2, 2)


def test_evaluation_numbers_on_a_constructed_case(dataset: Path, model: Path) -> None:
    rep = evaluate(model, dataset)
    assert rep.samples == 3 and rep.scenes == {"a": 2, "b": 1} and rep.rates == ["1x2", "2x1"]
    unseen = UNSEEN_PX / 256.0 > 0.5  # 3 unseen tiles of 8: 129, 256 and 200 pixels
    assert unseen.sum() == 3
    # hand-computed transformed values: T(y) = clamp(y / (2 * 0.25)); the model's raw output is T-space
    ps, ps0, gs, un = [], [], [], []
    for i in range(3):
        raw = _expected_raw(i)
        ps.append(np.clip(raw + 0.05, 0, 1))
        ps0.append(raw)
        gs.append(np.clip(_truth(i)[:2] / 0.5, 0, 1))
        un.append(np.broadcast_to(unseen, raw.shape))
    p, p0, g, u = (np.concatenate([a.ravel() for a in x]) for x in (ps, ps0, gs, un))
    for split, m in (("all", np.ones_like(u)), ("seen", ~u), ("unseen", u)):
        row = rep.row("quality", "model", "all scenes", split)
        assert row["n"] == int(m.sum())
        for k, v in _hand_scores(p[m], g[m]).items():
            assert row[k] == pytest.approx(v, rel=1e-5, abs=1e-7), (split, k)
        row0 = rep.row("quality", "model (no safety)", "all scenes", split)
        assert row0["mae"] == pytest.approx(_hand_scores(p0[m], g[m])["mae"], rel=1e-5)
        # metric units: the inverse transform is y = 0.5 p
        assert row["mae_metric"] == pytest.approx(np.mean(np.abs(0.5 * p[m] - 0.5 * g[m])), rel=1e-4)
    # per scene: scene b is sample 2 alone
    row_b = rep.row("quality", "model", "b", "all")
    assert row_b["mae"] == pytest.approx(np.mean(np.abs(ps[2] - gs[2])), rel=1e-5)
    assert {r["split"] for r in rep.quality} == {"all", "seen", "unseen"}

    # decisions: the oracle never fails; the model fails where its chosen rate's truth reaches 0.2
    oracle = rep.row("decisions", "oracle")
    assert oracle["fail_share"] == 0.0 and oracle["n"] == 24
    fails, saved = [], []
    for i in range(3):
        pred6 = sdk.extrapolate(0.5 * np.clip(_expected_raw(i) + 0.05, 0, None), ["1x2", "2x1"])
        truth = _truth(i)
        for ty in range(2):
            for tx in range(4):
                passing = [r for r in sdk.PREDICTED_RATES if pred6[sdk.PREDICTED_RATES.index(r), ty, tx] < 0.2]
                if not passing:
                    fails.append(False)
                    saved.append(0.0)
                    continue
                area = max(int(r[0]) * int(r[2]) for r in passing)
                same = [r for r in passing if int(r[0]) * int(r[2]) == area]
                r = min(same, key=lambda q: pred6[sdk.PREDICTED_RATES.index(q), ty, tx])
                fails.append(bool(truth[sdk.PREDICTED_RATES.index(r), ty, tx] >= 0.2))
                saved.append(1.0 - 1.0 / area)
    m_row = rep.row("decisions", "model")
    assert m_row["fail_share"] == pytest.approx(np.mean(fails))
    assert m_row["work_saved"] == pytest.approx(np.mean(saved))
    assert 0 < np.mean(fails) < 1  # the case exercises both outcomes

    # baselines: the fully unseen tile is black -> Yang 4x4; the 1x1-for-unseen variant shades it fully
    methods = {r["method"] for r in rep.decisions}
    assert methods == {"model", "oracle", "yang2019", "yang2019-unseen-1x1", "fidelityfx", "fidelityfx-additional"}
    yang_unseen = rep.row("decisions", "yang2019", "all scenes", "unseen")
    assert yang_unseen["rate_shares"]["4x4"] > 0
    assert rep.row("decisions", "yang2019-unseen-1x1", "all scenes", "unseen")["rate_shares"]["1x1"] == 1.0
    assert rep.row("quality", "yang2019")["n"] == 48
    assert rep.row("decisions", "fidelityfx")["rate_shares"]["4x4"] == 0.0  # the base path has no quarter rates
    # serialisable, strict JSON
    text = json.dumps(rep.to_dict(), allow_nan=False)
    assert "yang2019" in text and "|" in rep.to_markdown() and "Prediction quality" in rep.table()


def test_evaluation_matches_the_engine_path(dataset: Path, model: Path) -> None:
    from rtp.capture import DatasetReader

    pred = sdk.load(model)
    sel = ModelSelector(pred)
    s = DatasetReader(dataset)["s1"]
    np.testing.assert_array_equal(sel.predict(s), pred.predict(s.inputs(pred.metadata.inputs)))
    np.testing.assert_allclose(pred.predict_raw(s.inputs(PAPER_INPUTS)), _expected_raw(1), rtol=1e-5)
    oracle = Oracle(TargetStore(dataset), "jnyang", T, threshold=0.2)
    np.testing.assert_allclose(oracle.predict(s), _truth(1))
    assert oracle.shading_rates(s).shape == (2, 4)


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"threshold": "x"}, "threshold"), ({"threshold": -0.1}, "threshold"), ({"threshold": float("nan")}, "threshold"),
    ({"threshold": 0.2, "higher_is_better": "no"}, "higher_is_better"),
])
def test_the_oracle_refuses_a_bad_threshold_when_made(dataset: Path, kwargs: dict[str, Any], name: str) -> None:
    # ("x" was a bare ValueError from float(); -0.1 was taken and refused only by the first shading_rates)
    with pytest.raises(sdk.ParameterError, match=f"^{name}: ") as err:
        Oracle(TargetStore(dataset), "jnyang", T, **kwargs)
    assert err.value.name == name
    with pytest.raises(BaselineError, match="tile_size"):
        Oracle(TargetStore(dataset), "jnyang", "16", threshold=0.2)  # type: ignore[arg-type]
    oracle = Oracle(TargetStore(dataset), "jnyang", T, threshold=0.2)
    with pytest.raises(sdk.ParameterError, match="^threshold: "):
        oracle.shading_rates(None, threshold="x")  # type: ignore[arg-type]



def test_evaluation_on_coarser_hardware_tiles_scores_the_pooled_values(dataset: Path, model: Path) -> None:
    """tile_size=2T (hardware tiles twice the model's, `rtp evaluate --tile-size`): each hardware tile
    is predicted as the worst model tile it covers, as predict() gives an engine, and scored against
    the targets pooled to that tile."""
    rep = evaluate(model, dataset, tile_size=2 * T, baselines=False)
    assert f"jnyang, tile {2 * T} (pooled from the model's {T})," in rep.to_markdown()
    ps, gs = [], []
    for i in range(3):
        pred = np.clip(_expected_raw(i) + 0.05, 0, 1)
        ps.append(sdk.pool_tiles(pred, 2, higher_is_better=False))
        gs.append(np.clip(TargetStore(dataset).load(f"s{i}", "jnyang", 2 * T)[:2] / 0.5, 0, 1))
    p, g = (np.concatenate([a.ravel() for a in x]) for x in (ps, gs))
    row = rep.row("quality", "model", "all scenes", "all")
    assert row["n"] == p.size == 3 * 2 * 1 * 2
    for k, v in _hand_scores(p, g).items():
        assert row[k] == pytest.approx(v, rel=1e-5, abs=1e-7), k
    assert rep.row("decisions", "oracle")["n"] == 3 * 2


def test_evaluation_on_finer_hardware_tiles_scores_each_model_tiles_values(dataset: Path, model: Path) -> None:
    """tile_size=T/2 (AMD's and Intel's 8-pixel hardware tiles under a 16-pixel model, `rtp evaluate
    --tile-size 8`): each hardware tile takes its model tile's values, scored against the targets of
    8-pixel tiles. Here those are each 16-pixel tile's value four times, so every score and decision
    share is the model tiles' own, over four times the tiles; the baselines decide per 8-pixel tile."""
    own = evaluate(model, dataset, baselines=False)
    fine = evaluate(model, dataset, tile_size=T // 2)
    a, b = own.row("quality", "model", "all scenes", "all"), fine.row("quality", "model", "all scenes", "all")
    assert b["n"] == 4 * a["n"] == 4 * 3 * 2 * 2 * 4
    for k in ("r2", "mae", "under_share"):
        assert b[k] == pytest.approx(a[k], rel=1e-6, abs=1e-9), k
    da, db = own.row("decisions", "model", "all scenes", "all"), fine.row("decisions", "model", "all scenes", "all")
    assert db["n"] == 4 * da["n"]
    assert (db["fail_share"], db["work_saved"]) == pytest.approx((da["fail_share"], da["work_saved"]))
    assert fine.row("decisions", "fidelityfx", "all scenes", "all")["n"] == db["n"]
    # (its report said "pooled from the model's" tiles, as for coarser ones)
    assert f"jnyang, tile {T // 2} (each its part of the model's {T})," in fine.to_markdown()
    assert f"jnyang, tile {T}, transform" in own.to_markdown()


def test_a_run_on_training_scenes_only_is_flagged(dataset: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A model whose provenance lists every evaluated scene among its training scenes: the report
    says these scores are not a test (first note, and a logged warning); one new scene clears it."""
    weights = np.zeros((2, 4), np.float32)
    weights[0, 2] = 1.0
    trained = build_onnx(tmp_path / "t.onnx", weights=weights, tile=T,
                         metadata={**META, "provenance": {"train_scenes": ["a", "b"]}})
    with caplog.at_level("WARNING", logger="rtp"):
        rep = evaluate(trained, dataset, baselines=False)
    assert rep.scene_roles == {"a": "train", "b": "train"}
    assert rep.notes[0] == "every evaluated scene was a training scene of this model: these scores are not a test"
    assert "every evaluated scene was a training scene" in caplog.text and "not a test" in rep.to_markdown()
    half = build_onnx(tmp_path / "h.onnx", weights=weights, tile=T,
                      metadata={**META, "provenance": {"train_scenes": ["a"], "val_scenes": ["b"]}})
    rep = evaluate(half, dataset, baselines=False)
    assert rep.scene_roles == {"a": "train", "b": "validation"} and not any("not a test" in n for n in rep.notes)

def test_evaluate_options_and_errors(dataset: Path, model: Path, tmp_path: Path) -> None:
    rep = evaluate(model, dataset, scenes=["b"], baselines=False, threshold=0.3)
    assert rep.samples == 1 and rep.threshold == 0.3 and {r["method"] for r in rep.decisions} == {"model", "oracle"}
    assert rep.row("quality", "model")["scene"] == "b"
    with pytest.raises(sdk.RtpError, match="not in"):
        evaluate(model, dataset, scenes=["nowhere"])
    assert evaluate(model, dataset, scenes="b", baselines=False).samples == 1  # one name, not "b"'s letters
    from rtp.evaluate import check_evaluation

    check_evaluation(model, dataset, scenes="b")  # likewise ("scenes ['b'] ..." of a longer name's letters before)
    with pytest.raises(sdk.ParameterError, match=r"^scenes: bb is not in"):
        check_evaluation(model, dataset, scenes="bb")
    for kwargs, words in (({"threshold": "0.3"}, "threshold: expected a number"), ({"threshold": -1.0}, "threshold"),
                          ({"unseen_fraction": "0.5"}, "unseen_fraction"), ({"max_samples": 0}, "max_samples"),
                          ({"max_samples": 1.5}, "max_samples"), ({"scenes": [1]}, "scenes"),
                          ({"baselines": "no"}, "baselines must be True or False"), ({"plot_sample": 3}, "plot_sample")):
        with pytest.raises(sdk.ParameterError, match=words):  # (strings were compared or passed on)
            evaluate(model, dataset, **kwargs)  # type: ignore[arg-type]
    other = build_onnx(tmp_path / "flip.onnx", weights=np.eye(2, 4, dtype=np.float32), tile=T,
                       metadata=base_metadata(metric="flip", outputs=["1x2", "2x1"], weber_l=None))
    with pytest.raises(sdk.RtpError, match="rtp targets"):
        evaluate(other, dataset)


def test_spearman() -> None:
    x = np.array([1.0, 2.0, 3.0, 4.0])
    assert spearman(x, x**3) == pytest.approx(1.0)
    assert spearman(x, -x) == pytest.approx(-1.0)
    assert np.isnan(spearman(x, np.ones(4)))
    assert spearman(np.array([0.0, 0.0, 1.0]), np.array([1.0, 1.0, 2.0])) == pytest.approx(1.0)


# -- plots ----------------------------------------------------------------------------------------


def test_colorize_uses_the_full_colour_map() -> None:
    import matplotlib

    c = plots.colorize(np.array([0.0, 1.0, np.nan, 2.0, 0.5]))
    assert c.dtype == np.uint8 and c.shape == (5, 3)
    np.testing.assert_array_equal(c[0], np.round(np.array(matplotlib.colormaps["magma"](0.0)[:3]) * 255))
    np.testing.assert_array_equal(c[4], np.round(np.array(matplotlib.colormaps["magma"](0.5)[:3]) * 255))
    np.testing.assert_array_equal(c[1], c[3])  # clipped
    assert (c[2] == 128).all()
    with pytest.raises(BaselineError, match="unknown colour map"):
        plots.colorize(np.zeros(2), cmap="no-such-map")
    with pytest.raises(BaselineError, match="vmin < vmax"):
        plots.colorize(np.zeros(2), 0.0, 0.0)


def _has_colour(img: np.ndarray, rgb: tuple[float, float, float], tol: int = 3) -> bool:
    want = np.round(np.array(rgb) * 255)
    return bool((np.abs(img.astype(int) - want).max(axis=-1) <= tol).any())


def test_figures_carry_their_colour_scale_and_legend() -> None:
    import matplotlib

    truth = np.random.default_rng(0).random((6, 3, 4))
    hm = plots.heatmaps(truth, truth, 16, (40, 60), seen=np.ones((40, 60)), threshold=0.5, label="jnyang")
    assert hm.dtype == np.uint8 and hm.ndim == 3 and hm.shape[2] == 3
    # the colour bar spans the map: its darkest and brightest colours are both drawn
    magma = matplotlib.colormaps["magma"]
    assert _has_colour(hm, magma(0.0)[:3]) and _has_colour(hm, magma(1.0)[:3])
    assert _has_colour(hm, (0.0, 229 / 255, 1.0))  # the threshold's line on the colour bar
    one = plots.heatmaps(truth, truth, 16, (40, 60), rates=("1x2",))
    assert one.shape[0] < hm.shape[0] and one.shape[1] < hm.shape[1]  # one row, two columns
    with pytest.raises(BaselineError, match="expected rates"):
        plots.heatmaps(truth, truth, 16, (40, 60), rates=("3x3",))
    sc = plots.scatter(np.linspace(0, 1, 500), np.linspace(0, 1, 500), size=128, label="jnyang")
    assert sc.shape[0] > 128 and sc.shape[1] > 128
    codes = np.zeros((3, 4), np.uint8)
    ov = plots.rate_overlays(np.zeros((40, 60, 3), np.float32), {"a": codes, "b": codes + C["2x2"]}, 16)
    for _, colour in plots.rate_legend()[1:]:  # every class of the legend is drawn at full colour
        assert colour is not None and _has_colour(ov, colour)
    assert [name.split(":")[0] for name, _ in plots.rate_legend()] == ["1x1 (untinted)", "fine", "medium", "coarse"]
    # a code past uint8 is refused as draw_rate_overlay refuses it (a uint8 cast drew 256 as 1x1: untinted, "saves 0%")
    with pytest.raises(sdk.ParameterError, match=r"no shading rate: \[256\]"):
        plots.rate_overlays(np.zeros((40, 60, 3), np.float32), {"a": np.full((3, 4), 256, np.int64)}, 16)


def test_the_heatmaps_refuse_values_and_a_mask_of_another_grid_than_the_frames() -> None:
    """Per-tile values of another grid than ``tile`` makes of ``size`` were drawn all the same, cut to the frame: with
    32 for 16-pixel tiles the heatmaps showed the map's top-left quarter as the whole frame, and a seen mask of another
    size was drawn as this frame's. Both are refused, as a scale of 0 (ZeroDivisionError) is, with what was expected."""
    truth = np.random.default_rng(0).random((6, 3, 4))  # a 60x40 frame's 16-pixel tiles
    plots.heatmaps(truth, truth, 16, (40, 60), seen=np.ones((40, 60)))
    with pytest.raises(BaselineError, match=r"expected per-tile values \(6, 2, 2\) for a 60x40 frame of 32-pixel"):
        plots.heatmaps(truth, truth, 32, (40, 60))
    with pytest.raises(BaselineError, match=r"expected per-tile values \(6, 5, 8\)"):
        plots.heatmaps(truth, truth, 8, (40, 60))
    with pytest.raises(BaselineError, match=r"seen mask of the frame's size \(40, 60\), got shape \(20, 30\)"):
        plots.heatmaps(truth, truth, 16, (40, 60), seen=np.ones((20, 30)))
    for bad in (0, -2, 1.5):
        with pytest.raises(BaselineError, match="scale: expected an integer >= 1"):
            plots.heatmaps(truth, truth, 16, (40, 60), scale=bad)  # type: ignore[arg-type]
        with pytest.raises(BaselineError, match="scale: expected an integer >= 1"):
            plots.rate_overlays(np.zeros((40, 60, 3), np.float32), {"a": np.zeros((3, 4), np.uint8)}, 16,
                                scale=bad)  # type: ignore[arg-type]
    with pytest.raises(BaselineError, match="size: expected the frame's"):
        plots.heatmaps(truth, truth, 16, (40, 0))


def test_the_rate_overlays_of_a_frame_with_alpha_draw_its_colour() -> None:
    """draw_rate_overlay keeps an (H, W, 4) frame's alpha, and rate_overlays drew its result as it was: an engine's
    back buffer with an alpha of 0 came out as a blank panel, the page's white. The frame's colour is drawn."""
    rgb = np.full((96, 160, 3), 60, np.uint8)
    rgba = np.concatenate([rgb, np.zeros((96, 160, 1), np.uint8)], axis=2)
    codes = np.zeros((6, 10), np.uint8)  # 1x1: untinted
    np.testing.assert_array_equal(plots.rate_overlays(rgba, {"m": codes}, 16), plots.rate_overlays(rgb, {"m": codes}, 16))


def test_the_rate_overlays_draw_their_panels_and_legend_in_the_palette_asked_for(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """rate_overlays(palette="cvd") tints its panels as draw_rate_overlay(palette="cvd") does and its legend names
    those colours (the legend's swatches are the palette's, not the paper's green, yellow and red); an unknown palette
    is refused before anything is drawn."""
    from matplotlib.patches import Patch

    from rtp.capture import figure_image

    figures: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or figure_image(fig))
    img = np.full((96, 160, 3), 90, np.uint8)
    codes = np.array([[sdk.RATE_CODES[r] for r in ("1x1", "1x2", "2x2", "4x4", "2x4", "2x1")] * 2 + [0] * 8] * 6,
                     np.uint8)[:, :10]
    plots.rate_overlays(img, {"m": codes}, 16, palette="cvd")
    fig = figures[-1]
    shown = np.asarray(fig.axes[0].get_images()[0].get_array())
    np.testing.assert_array_equal(shown, sdk.draw_rate_overlay(img, codes, 16, palette="cvd"))
    swatches = [tuple(np.round(np.asarray(h.get_facecolor()[:3]), 3)) for h in fig.legends[0].legend_handles
                if isinstance(h, Patch)]
    white = sdk.draw_rate_overlay(np.ones((1, 3, 3), np.float32), np.array([[1, 5, 10]], np.uint8), 1, alpha=1.0,
                                  grid=False, palette="cvd")[0]
    # (1x1's swatch the grey of every rate key, the GIF's and the sdk's in a frame: it was white here, grey there)
    assert swatches == [plots.UNTINTED_SWATCH] + [tuple(np.round(c.astype(np.float64), 3)) for c in white]
    assert plots.rate_legend() == plots.rate_legend("paper")
    assert [c for _, c in plots.rate_legend()][1:] == list(sdk.OVERLAY_COLOURS.values())
    figures.clear()
    with pytest.raises(sdk.ParameterError, match="palette"):
        plots.rate_overlays(img, {"m": codes}, 16, palette="rainbow")
    assert not figures


def test_heatmaps_draw_infinite_values_at_the_colour_ends_and_nan_grey(monkeypatch: pytest.MonkeyPatch) -> None:
    """An infinite value (a PSNR of identical tiles, +inf, negated by `rtp demo` so that bright is worse) was masked by
    matplotlib and drawn blank, the page's white: the best tiles as bright as the worst. It takes the colour at its end
    of the range now, with the colour bar's arrow there; a NaN is mid grey, as colorize draws it, the bar saying so.
    The scatter leaves non-finite pairs out and its title says how many."""
    import matplotlib

    from rtp.capture import figure_image

    figures: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or figure_image(fig))
    truth = np.full((6, 3, 4), -np.inf)  # -PSNR of identical tiles
    prediction = np.full((6, 3, 4), -40.0)
    prediction[sdk.PREDICTED_RATES.index("4x4")] = np.nan
    img = plots.heatmaps(truth, prediction, 16, (40, 60), vmin=-55.0, vmax=-15.0, label="-psnr (dB)")

    def centre(ax: Any) -> np.ndarray:
        box = ax.get_window_extent()
        return img[int(img.shape[0] - (box.y0 + box.y1) / 2), int((box.x0 + box.x1) / 2)].astype(int)

    fig = figures[-1]
    panels = {ax.get_title(): ax for ax in fig.axes if ax.get_title()}
    darkest = np.round(np.array(matplotlib.colormaps["magma"](0.0)[:3]) * 255)
    np.testing.assert_allclose(centre(panels["2x2: true"]), darkest, atol=2)
    np.testing.assert_allclose(centre(panels["4x4: predicted"]), [128, 128, 128], atol=2)
    bar = fig.axes[-1]
    assert "grey: no value" in bar.get_ylabel()
    for vmin, vmax in ((1.0, 0.0), (0.5, 0.5)):  # (matplotlib's untyped error at drawing, or a bar of no range)
        with pytest.raises(BaselineError, match="expected finite vmin < vmax"):
            plots.heatmaps(truth, prediction, 16, (40, 60), vmin=vmin, vmax=vmax)
    figures.clear()
    plots.value_map(np.array([[np.inf, 0.5], [np.nan, 0.0]]), label="x")
    assert "grey: no value" in figures[-1].axes[-1].get_ylabel()
    figures.clear()
    plots.scatter(np.array([0.1, np.nan, np.inf, 0.5]), np.array([0.2, 0.3, 0.4, 0.6]), size=128)
    assert figures[-1].axes[0].get_title() == "2 tiles\n(2 not finite, not drawn)"
    plots.scatter(np.array([0.1, np.nan]), np.array([0.2, 0.3]), size=128)  # (one tile: "1 tiles" it said)
    assert figures[-1].axes[0].get_title() == "1 tile\n(1 not finite, not drawn)"


def test_the_closed_loop_plots_keep_their_legend_off_the_panels(monkeypatch: pytest.MonkeyPatch) -> None:
    """play's curves and per-frame plots name the methods in one legend outside every panel: a legend
    inside the last panel hid the points in its corner (on a short path most methods' defaults meet
    there) and, per frame, the lines under it. The curves' legend then says what their other marks are, the ring of
    each method's default parameter and the dashed lines at the matched failing shares (explained nowhere before),
    each drawn as the figure draws it."""
    from rtp.evaluate._play import PlayReport

    figures: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or np.zeros((1, 1, 3), np.uint8))
    methods = ["jnyang", "jnyang@4", "yang2019", "fidelityfx", "oracle"]
    report = PlayReport({"scene": "procedural:0", "frames": 30, "fps": 60.0, "fail_metric": "jnyang",
                         "fail_threshold": 0.25})
    for path in ("fast", "slow"):
        report.unseen[path] = [0.05] * 30
        report.frames[path] = {m: {k: [0.6] * 30 for k in ("saved", "fail", "change")} for m in methods}
        report.rows += [{"path": path, "method": m, "fail_share": 0.3 + 0.01 * i, "work_saved": 0.1 + 0.01 * i,
                         "default": True} for i, m in enumerate(methods)]
    plots.play_curves(report)
    plots.play_frames(report)
    from rtp.evaluate._play import FAIL_LEVELS

    marks = ["default parameter", f"matched failing\n({', '.join(f'{100 * f:g}' for f in FAIL_LEVELS)}%)"]
    assert marks[1] == "matched failing\n(1, 2, 5%)"
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    for fig, want in zip(figures, (methods + marks, methods), strict=True):
        FigureCanvasAgg(fig).draw()  # (laid out as drawn: a bare Figure's canvas.draw() draws nothing, lays out nothing)
        (legend,) = fig.legends
        assert [t.get_text() for t in legend.get_texts()] == want
        if want != methods:
            ring, dashed = legend.legend_handles[-2:]
            ax = fig.axes[0]
            rings = [ln for ln in ax.get_lines() if ln.get_markerfacecolor() == "none" and ln.get_linestyle() == "None"]
            assert len(rings) == len(methods) and ring.get_marker() == rings[0].get_marker() == "o"
            assert ring.get_markerfacecolor() == "none" and ring.get_linestyle() == "None"
            assert ring.get_markersize() == rings[0].get_markersize()
            assert dashed.get_linestyle() == "--" and dashed.get_color() == "#999999"
            vlines = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--" and ln.get_color() == "#999999"]
            assert sorted(ln.get_xdata()[0] for ln in vlines) == [100 * f for f in FAIL_LEVELS]
        box = legend.get_window_extent()
        for ax in fig.axes:
            assert ax.get_legend() is None and not box.overlaps(ax.get_window_extent()), ax.get_title()


def test_the_closed_loop_plots_tell_their_methods_apart_without_colour(monkeypatch: pytest.MonkeyPatch) -> None:
    """play's curves and per-frame plots told the methods apart by colour alone (every curve the same round marker and
    solid line, every per-frame series a bare solid line): in greyscale, or under colour-vision deficiency, tab10's
    neighbours could not be told apart. Each method's line has a marker and line style of its own beside its colour,
    the same in both figures, in the order the run names the methods; past tab10's ten colours too."""
    from matplotlib.colors import to_rgba

    from rtp.evaluate._play import PlayReport

    figures: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or np.zeros((1, 1, 3), np.uint8))
    for n in (7, 12):
        figures.clear()
        methods = [f"m{i}" for i in range(n)]
        report = PlayReport({"scene": "procedural:0", "frames": 30, "fps": 60.0, "fail_metric": "jnyang",
                             "fail_threshold": 0.25, "methods": methods})
        report.unseen["fast"] = [0.05] * 30
        # (the per-frame series listed in another order than the run's: each method keeps its style all the same)
        report.frames["fast"] = {m: {k: [0.6] * 30 for k in ("saved", "fail", "change")} for m in reversed(methods)}
        report.rows += [{"path": "fast", "method": m, "fail_share": 0.01 * j, "work_saved": 0.1 * j,
                         "default": j == 1} for m in methods for j in range(3)]
        plots.play_curves(report)
        plots.play_frames(report)
        seen: dict[str, tuple[Any, ...]] = {}
        for fig in figures:
            for ax in fig.axes:
                lines = [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]
                if not lines:  # (the unseen share: no method's)
                    continue
                assert sorted(ln.get_label() for ln in lines) == sorted(methods), ax.get_title()
                styles = {ln.get_label(): (tuple(np.round(to_rgba(ln.get_color()), 4)), ln.get_marker(),
                                           ln.get_linestyle()) for ln in lines}
                assert len(set(styles.values())) == n, (ax.get_title(), styles)
                assert len({style[1:] for style in styles.values()}) == n, (ax.get_title(), styles)
                assert all(style[1] not in ("None", "", " ", None) and style[2] not in ("None", "", " ")
                           for style in styles.values())
                for m, style in styles.items():
                    assert seen.setdefault(m, style) == style, (m, ax.get_title())


def test_the_figures_of_a_small_frame_keep_every_label_inside_and_apart(monkeypatch: pytest.MonkeyPatch) -> None:
    """At 160x96 (rtp demo --size 160x96) the heatmaps' panel titles ran into each other, the FLIP
    map's colour-bar label and the overlay's rate legend off the image: small frames are drawn larger
    (plots.MIN_PANEL) and the legend wraps to the figure's width. Every text stays inside its figure
    and no two panel titles overlap."""
    figures: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or np.zeros((1, 1, 3), np.uint8))
    h, w = 96, 160
    truth = np.random.default_rng(0).random((6, h // 16, w // 16))
    plots.heatmaps(truth, truth, 16, (h, w), seen=np.ones((h, w)), threshold=0.25, label="jnyang (luma / (luma + l))",
                   title="jnyang per 16px tile: true (rendered at every rate) and predicted by jnyang.onnx")
    plots.value_map(np.zeros((h, w)), label="FLIP error (0 = identical, 1 = worst)",
                    title="FLIP of the VRS composite against full-rate shading")
    plots.rate_overlays(np.zeros((h, w, 3), np.float32), {"jnyang": np.zeros((h // 16, w // 16), np.uint8)}, 16)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    for fig in figures:
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        renderer = canvas.get_renderer()
        inside = fig.bbox.padded(1)
        texts = [t for t in fig.findobj(lambda a: hasattr(a, "get_text")) if t.get_visible() and t.get_text()]
        assert texts
        for t in texts:
            box = t.get_window_extent(renderer)
            assert inside.contains(box.x0, box.y0) and inside.contains(box.x1, box.y1), t.get_text()
        titles = [ax.title.get_window_extent(renderer) for ax in fig.axes if ax.get_title()]
        for i, a in enumerate(titles):
            assert not any(a.overlaps(b) for b in titles[i + 1:])
        for ax in fig.axes:  # (a panel's title no wider than the panel: its neighbour's starts beside it)
            assert not ax.get_title() or ax.title.get_window_extent(renderer).width <= ax.get_window_extent().width


def test_the_rate_overlays_of_a_small_frame_fit_the_evaluations_method_names(monkeypatch: pytest.MonkeyPatch) -> None:
    """`rtp evaluate --plots` on a 160x96 dataset drew its six methods in 160-pixel panels: 'yang2019-unseen-1x1:
    saves 52%' ran into its neighbours' titles, the first and last columns' titles off the image and the figure's
    title was cut at both ends. Each cell is as wide as its longest title now, the figure as its title."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    figures: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or np.zeros((1, 1, 3), np.uint8))
    h, w = 96, 160
    codes = np.zeros((h // 16, w // 16), np.uint8)
    methods = ["model", "oracle", "yang2019", "yang2019-unseen-1x1", "fidelityfx", "fidelityfx-additional"]
    plots.rate_overlays(np.zeros((h, w, 3), np.float32), dict.fromkeys(methods, codes), 16,
                        title="rates chosen on sample procedural_0-fast-0000; 'model': jnyang at jnyang threshold 0.25")
    (fig,) = figures
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    for t in (t for t in fig.findobj(lambda a: hasattr(a, "get_text")) if t.get_visible() and t.get_text()):
        box = t.get_window_extent(renderer)
        assert fig.bbox.contains(box.x0, box.y0) and fig.bbox.contains(box.x1, box.y1), t.get_text()
    titles = [ax.title.get_window_extent(renderer) for ax in fig.axes if ax.get_title()]
    assert len(titles) == len(methods)
    for i, a in enumerate(titles):
        assert not any(a.overlaps(b) for b in titles[i + 1:])


def test_the_maps_of_a_strip_of_a_frame_stay_its_size_and_keep_their_labels_apart(monkeypatch: pytest.MonkeyPatch) -> None:
    """A very wide or very tall frame (1600x16, 16x1200) was enlarged until its short side reached plots.MIN_PANEL, its
    long side with it: the heatmaps of a 1600x16 frame 48110 pixels wide, a (1, 3000) map's 720130 (550 MB). No side is
    enlarged past plots.MAX_ZOOMED now; the figure keeps MIN_PANEL around the panel, the colour bar in a column of its
    own (beside a narrow panel it lay over the last column's titles) and a narrow map's title inside the image."""
    figures: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or np.zeros((1, 1, 3), np.uint8))
    rng = np.random.default_rng(0)
    for h, w in ((16, 1600), (1200, 16)):
        values = rng.random((6, *sdk.tile_grid(h, w, 16)))
        plots.heatmaps(values, values, 16, (h, w), seen=np.ones((h, w)), threshold=0.25, label="jnyang")
    plots.value_map(rng.random((1, 3000)), label="x", title="t")
    plots.value_map(rng.random((1000, 4)), label="FLIP error (0 = identical, 1 = worst)",
                    title="FLIP of the VRS composite against full-rate shading")
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    for fig in figures:
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        assert max(fig.bbox.width, fig.bbox.height) <= 3 * 1600 + 200
        renderer = canvas.get_renderer()
        inside = fig.bbox.padded(1)
        boxes = [ax.get_window_extent() for ax in fig.axes]  # (the colour bar the last)
        boxes += [ax.title.get_window_extent(renderer) for ax in fig.axes if ax.get_title()]
        for t in (t for t in fig.findobj(lambda a: hasattr(a, "get_text")) if t.get_visible() and t.get_text()):
            box = t.get_window_extent(renderer)
            assert inside.contains(box.x0, box.y0) and inside.contains(box.x1, box.y1), t.get_text()
        assert not any(boxes[len(fig.axes) - 1].overlaps(b) for i, b in enumerate(boxes) if i != len(fig.axes) - 1)


def test_the_scatters_key_lies_off_the_data(monkeypatch: pytest.MonkeyPatch) -> None:
    """The diagonal's key ("prediction = truth") lay in the plot's upper-left corner, over the over-predicted tiles
    (true low, predicted high): it is below the plot now, the image `size + 106` high and `size + 150` wide (the docs'
    510x466 at the default)."""
    figures: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or np.zeros((1, 1, 3), np.uint8))
    plots.scatter(np.full(50, 0.95), np.full(50, 0.02))
    (fig,) = figures
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()  # (a bare Figure's canvas.draw() lays out nothing: the boxes below were the unlaid-out)
    (ax, _bar) = fig.axes
    assert ax.get_legend() is None
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == ["prediction = truth"]
    assert not legend.get_window_extent().overlaps(ax.get_window_extent())
    assert (round(fig.bbox.width), round(fig.bbox.height)) == (510, 466)


@pytest.mark.parametrize("ext", ["png", "jpg", "webp"])
def test_save_image_writes_the_format_its_extension_names(tmp_path: Path, ext: str) -> None:
    from PIL import Image

    path = tmp_path / f"x.{ext}"
    plots.save_image(path, np.zeros((8, 8, 3), np.float32))
    with Image.open(path) as im:
        assert im.format == {"png": "PNG", "jpg": "JPEG", "webp": "WEBP"}[ext] and im.size == (8, 8)
    with pytest.raises(sdk.ParameterError, match="extension"):
        plots.save_image(tmp_path / "x.nope", np.zeros((8, 8, 3)))


# -- the CLI --------------------------------------------------------------------------------------


def test_cli_evaluate_writes_markdown_json_and_pngs(dataset: Path, model: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    from PIL import Image

    out = tmp_path / "eval"
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--out", str(out), "--plots"]) == 0
    shown = capsys.readouterr().out
    assert "Prediction quality" in shown and "VRS decisions" in shown and "yang2019" in shown
    data = json.loads((out / "evaluation.json").read_text())
    assert data[0]["model"]["metric"] == "jnyang" and data[0]["samples"] == 3
    md = (out / "evaluation.md").read_text()
    assert "## Prediction quality" in md and "m_heatmaps.png" in md
    for name in ("m_heatmaps.png", "m_scatter.png", "m_rates.png"):
        with Image.open(out / name) as im:
            assert im.mode == "RGB" and im.size[0] > 0
    with Image.open(out / "m_rates.png") as im:  # model, oracle and four baselines side by side
        assert im.size[0] > 6 * W and im.size[1] > H
    capsys.readouterr()
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--scene", "zzz"]) == 2
    assert f"rtp evaluate: error: --scene: zzz is not in {dataset}; it holds a, b" in capsys.readouterr().err
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--out", str(tmp_path / "px"), "--plots",
                     "--plot-sample", "nosuch", "--no-baselines"]) == 2
    assert "rtp evaluate: error: --plot-sample: 'nosuch' is not among the evaluated samples (" in capsys.readouterr().err
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--scene", "a,b", "--scene", "b",
                     "--no-baselines", "--max-samples", "1"]) == 0
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--plots"]) == 2  # --plots needs --out
    capsys.readouterr()  # --plot-sample without --plots was taken and nothing drawn
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--out", str(tmp_path / "ps"), "--plot-sample",
                     "x"]) == 2
    assert "give --plots" in capsys.readouterr().err and not (tmp_path / "ps").exists()
    # one --threshold for models of two metrics was taken in both metrics' units; refused before any work,
    # while models of one metric share it
    capsys.readouterr()
    assert rtp_main(["evaluate", str(model), "flip", "--data", str(dataset), "--threshold", "0.3", "--out",
                     str(tmp_path / "two")]) == 2
    assert f"the models predict {model} (jnyang), flip (flip)" in capsys.readouterr().err
    assert not (tmp_path / "two").exists()
    assert rtp_main(["evaluate", str(model), "jnyang", "--data", str(dataset), "--threshold", "0.3",
                     "--no-baselines", "--max-samples", "1"]) == 0
    # a dataset without the second model's targets is refused before the first model is evaluated
    capsys.readouterr()
    assert rtp_main(["evaluate", str(model), "flip", "--data", str(dataset)]) == 2
    shown = capsys.readouterr()
    assert shown.out == "" and f"{dataset} has no flip targets (it has jnyang)" in shown.err
    # the summary tables docs/results.md quotes read the same file (bench/report.py)
    report = [sys.executable, str(Path(__file__).resolve().parents[1] / "bench" / "report.py")]
    for flag, expect in (("--compact", "saved % at 1 / 2 / 5 / 10% fails"), ("--per-scene", "| all scenes |")):
        shown = subprocess.run([*report, flag, str(out / "evaluation.json")], capture_output=True, text=True,
                               check=True).stdout
        assert expect in shown and str(model) in shown
    bad = subprocess.run([*report, str(tmp_path / "nope.json")], capture_output=True, text=True)
    assert bad.returncode == 2 and "No such file or directory" in bad.stderr
    # a run on other hardware tiles than the model's (--tile-size) says so: the two read apart
    entries = json.loads((out / "evaluation.json").read_text())
    own = entries[0]["model"]["tile_size"]
    entries[0]["model"].update(tile_size=own // 2, model_tile_size=own)
    (tmp_path / "half.json").write_text(json.dumps(entries))
    for flag in ("--compact", "--per-scene", None):
        shown = subprocess.run([*report, *([flag] if flag else []), str(out / "evaluation.json"),
                                str(tmp_path / "half.json")], capture_output=True, text=True, check=True).stdout
        assert shown.count(f"[{own // 2}-pixel tiles; the model's {own}]") >= 1 and "the model's" not in \
            shown.split(f"[{own // 2}-pixel")[0], (flag, shown)



def test_evaluate_draws_its_rate_overlays_in_the_palette_asked_for(dataset: Path, model: Path, tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """evaluate(palette="cvd") and `rtp evaluate --plots --palette cvd` draw <model>_rates.png in the colour-vision
    deficiency palette (the paper's by default); an unknown one is refused before any work (the library's before the
    model is loaded: an unknown model would be its error otherwise; argparse's choices), and --palette without --plots,
    which draws nothing, is refused as --plot-sample is."""
    real = plots.rate_overlays
    drawn: list[str] = []

    def spy(*args: Any, **kw: Any) -> np.ndarray:
        drawn.append(kw.get("palette", "paper"))
        return real(*args, **kw)

    monkeypatch.setattr(plots, "rate_overlays", spy)
    evaluate(model, dataset, baselines=False, max_samples=1, plots_dir=tmp_path / "lib", palette="cvd")
    evaluate(model, dataset, baselines=False, max_samples=1, plots_dir=tmp_path / "default")
    assert drawn == ["cvd", "paper"]
    from PIL import Image

    with Image.open(tmp_path / "lib" / "m_rates.png") as a, Image.open(tmp_path / "default" / "m_rates.png") as b:
        assert a.size == b.size and (np.asarray(a) != np.asarray(b)).any()
    with pytest.raises(sdk.ParameterError, match="palette: expected one of 'paper', 'cvd'"):
        evaluate(tmp_path / "no-such-model.onnx", dataset, plots_dir=tmp_path / "bad", palette="grey")
    assert not (tmp_path / "bad").exists()
    drawn.clear()
    base = ["evaluate", str(model), "--data", str(dataset), "--no-baselines", "--max-samples", "1"]
    assert rtp_main([*base, "--out", str(tmp_path / "cli"), "--plots", "--palette", "cvd"]) == 0
    assert drawn == ["cvd"]
    capsys.readouterr()
    with pytest.raises(SystemExit) as stop:
        rtp_main([*base, "--out", str(tmp_path / "x"), "--plots", "--palette", "grey"])
    assert stop.value.code == 2 and "--palette: invalid choice: 'grey' (choose from 'paper', 'cvd')" in capsys.readouterr().err
    assert rtp_main([*base, "--out", str(tmp_path / "y"), "--palette", "cvd"]) == 2
    assert "--palette cvd: the colours of the rate overlays --plots draws: give --plots" in capsys.readouterr().err
    assert drawn == ["cvd"] and not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_cli_evaluate_aligns_its_table_on_a_console_that_is_not_utf8(dataset: Path, model: Path) -> None:
    """Under LC_ALL=C (an ASCII stdout) the console writes the quality table's "R² %" and "σ MAE" as "R^2 %" and
    "sigma MAE", longer than the widths measured on them: the header's columns ran past their values' from "R² %" on.
    The cells are measured as the console shows them; a UTF-8 console's table keeps its characters."""
    import io

    def shown(encoding: str) -> list[str]:
        raw = io.BytesIO()
        out = io.TextIOWrapper(raw, encoding=encoding, errors="strict", write_through=True)
        old, sys.stdout = sys.stdout, out
        try:
            assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--no-baselines", "--max-samples", "1",
                             "--no-progress"]) == 0
        finally:
            sys.stdout = old
        text = raw.getvalue().decode(encoding)
        return text.split("Prediction quality\n")[1].split("\n\n")[0].splitlines()

    for encoding, head in (("ascii", "R^2 %"), ("utf-8", "R² %")):
        table = shown(encoding)
        assert head in table[0] and len(table) >= 3, table
        # (every line as long as the others, and each column's right edge where the header's is)
        assert len({len(line) for line in table}) == 1, table
        end = table[0].index(head) + len(head)
        assert all(line[end - 1] != " " and line[end] == " " for line in table), (encoding, table)


def test_cli_evaluate_into_a_folder_another_job_writes_is_refused(dataset: Path, model: Path, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Two evaluations into one --out wrote their plots under one name (m_heatmaps.png), and the report written
    last linked the other's pictures, of other scenes or data. An evaluation now holds the folder's writer lock
    from its first plot to its report: a second job is refused naming the first and writes nothing; the lock's file
    goes with the run, and a folder made for it goes with a run that failed before writing there."""
    import os

    from rtp.sdk.files import LOCK_NAME, writer_lock

    out = tmp_path / "eval"
    out.mkdir()
    run = ["evaluate", str(model), "--data", str(dataset), "--out", str(out), "--plots", "--no-baselines"]
    with writer_lock(out, "rtp evaluate", RuntimeError):  # (another process's, as far as flock goes)
        capsys.readouterr()
        assert rtp_main(run) == 2
        shown = capsys.readouterr()
        assert shown.err.strip() == (f"rtp evaluate: error: --out: {out} is being written by another job (rtp evaluate, "
                                     f"pid {os.getpid()}): wait for it to end, or evaluate into another folder")
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]  # no plot, no report
    assert rtp_main(run) == 0
    assert sorted(p.name for p in out.iterdir()) == ["evaluation.json", "evaluation.md", "m_heatmaps.png",
                                                     "m_rates.png", "m_scatter.png"]
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--out", str(tmp_path / "new" / "px"), "--plots",
                     "--plot-sample", "nosuch", "--no-baselines"]) == 2
    assert not (tmp_path / "new").exists()


def test_bench_report_marks_a_saving_past_the_sweep_as_a_lower_bound(tmp_path: Path) -> None:
    """bench/report.py reads each sweep at 1 / 2 / 5 / 10 / 15% failing tiles with evaluate.saved_at, which gives the best
    saving where every point fails less: printed plain, a sweep that never fails 10% read as saving that much at 10%.
    It is marked ">=" now, as bench/play_report.py marks it; "-" where the sweep never fails that rarely."""
    sweep = [{"method": m, "parameter": f"t {i}", "fail_share": f, "work_saved": w}
             for m, pts in (("model", [(0.0, 0.1), (0.5, 0.9)]), ("fidelityfx", [(0.02, 0.2), (0.08, 0.3)]))
             for i, (f, w) in enumerate(pts)]
    entry = {"model": {"path": "m.onnx", "metric": "jnyang", "tile_size": 16}, "data": "d", "samples": 1,
             "quality": [], "decisions": [], "matched": [], "sweep": sweep}
    (tmp_path / "evaluation.json").write_text(json.dumps([entry]))
    report = [sys.executable, str(Path(__file__).resolve().parents[1] / "bench" / "report.py")]
    shown = subprocess.run([*report, str(tmp_path / "evaluation.json")], capture_output=True, text=True,
                           check=True).stdout
    assert "| fidelityfx | - | 20.0 | 25.0 | >= 30.0 | >= 30.0 |" in shown, shown
    assert "| model | 11.6 | 13.2 | 18.0 | 26.0 | 34.0 |" in shown, shown
    entry["sweep"] = [r for r in sweep if r["method"] == "fidelityfx"]
    entry["sweep"] += [{**r, "method": "model"} for r in entry["sweep"]]
    (tmp_path / "evaluation.json").write_text(json.dumps([entry]))
    shown = subprocess.run([*report, "--compact", str(tmp_path / "evaluation.json")], capture_output=True, text=True,
                           check=True).stdout
    assert "| - / 20.0 / 25.0 / >= 30.0 |" in shown, shown


def test_bench_report_reads_an_evaluation_of_one_scene(tmp_path: Path) -> None:
    """`rtp evaluate --scene NAME` (docs/evaluation.md's run on the validation scene) writes that scene's rows and no
    "all scenes" rows, which bench/report.py alone read: its quality and decision tables were empty, --compact's R²
    "- / - / -", --per-scene added an "all scenes" row of dashes. The one scene's rows are the pooled ones now."""
    quality = [{"scene": "procedural:3", "split": s, "method": m, "n": 10, "r2": r2, "mae": 0.1, "mae_under": 0.1,
                "sigma": 0.1, "under_share": 0.2, "spearman": 0.5}
               for m, r2 in (("model", 0.42), ("model (no safety)", 0.5)) for s in ("all", "seen", "unseen")]
    decisions = [{"scene": "procedural:3", "split": "all", "method": "model", "threshold": 0.25, "fail_share": 0.03,
                  "work_saved": 0.61}]
    entry = {"model": {"path": "m.onnx", "metric": "jnyang", "tile_size": 16}, "data": "d", "samples": 4,
             "quality": quality, "decisions": decisions, "matched": [], "sweep": []}
    (tmp_path / "evaluation.json").write_text(json.dumps([entry]))
    report = [sys.executable, str(Path(__file__).resolve().parents[1] / "bench" / "report.py")]
    run = [*report, str(tmp_path / "evaluation.json")]
    shown = subprocess.run(run, capture_output=True, text=True, check=True).stdout
    assert "4 samples of procedural:3)" in shown and "| all | model | 42.0 |" in shown, shown
    assert "| all | model | 0.25 | 3.0 | 61.0 |" in shown, shown
    shown = subprocess.run([*report, "--compact", run[-1]], capture_output=True, text=True, check=True).stdout
    assert "| 42.0 / 42.0 / 42.0 | 50.0 / 50.0 / 50.0 |" in shown, shown
    shown = subprocess.run([*report, "--per-scene", run[-1]], capture_output=True, text=True, check=True).stdout
    assert "| procedural:3 | 42.0 / 42.0 / 42.0 |" in shown and "all scenes" not in shown, shown


def test_cli_evaluate_refuses_one_sidecar_for_several_models(dataset: Path, model: Path, tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """--metadata is one model's sidecar: given with several models it was read as each one's metadata, in place of
    the metadata a model carries (two models evaluated at the sidecar's threshold, 0.1, not their own 0.2: exit 0).
    Refused before any work; with one model it is read as before."""
    import shutil

    import yaml

    sidecar = tmp_path / "side.yaml"
    sidecar.write_text(yaml.safe_dump({**META, "default_threshold": 0.1}))
    other = tmp_path / "other" / "m.onnx"
    other.parent.mkdir()
    shutil.copy(model, other)
    out = tmp_path / "two"
    assert rtp_main(["evaluate", str(model), str(other), "--metadata", str(sidecar), "--data", str(dataset),
                     "--no-baselines", "--max-samples", "1", "--out", str(out)]) == 2
    shown = capsys.readouterr()
    assert shown.out == "" and "rtp evaluate: error: --metadata is one model's sidecar, and 2 models were given: " \
        "evaluate the model that carries no metadata alone with it" in shown.err, shown.err
    assert not out.exists()
    assert rtp_main(["evaluate", str(model), "--metadata", str(sidecar), "--data", str(dataset), "--no-baselines",
                     "--max-samples", "1", "--out", str(out)]) == 0
    assert json.loads((out / "evaluation.json").read_text())[0]["model"]["default_threshold"] == pytest.approx(0.1)


def test_cli_evaluate_keeps_apart_models_of_one_file_name_and_refuses_one_model_twice(
        dataset: Path, model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two models whose files share a name (a/m.onnx, b/m.onnx: a retrained model beside the old one) wrote
    their plots to the same m_heatmaps.png, the second over the first, and evaluation.md showed the second's
    pictures under both; each now has its own, named after its folder. The same file given twice was
    evaluated twice; it is refused before any work."""
    import shutil

    for folder in ("a", "b c"):
        (tmp_path / folder).mkdir()
        shutil.copy(model, tmp_path / folder / "m.onnx")
    out = tmp_path / "eval"
    assert rtp_main(["evaluate", str(tmp_path / "a" / "m.onnx"), str(tmp_path / "b c" / "m.onnx"), "--data",
                     str(dataset), "--no-baselines", "--max-samples", "1", "--out", str(out), "--plots"]) == 0
    md = (out / "evaluation.md").read_text()
    # (a space in the name is written %20 in the image link, which a space ended in every Markdown viewer)
    for folder, link in (("a", "a_m_heatmaps.png"), ("b c", "b%20c_m_heatmaps.png")):
        assert (out / f"{folder}_m_heatmaps.png").is_file() and md.count(f"]({link})") == 1
    assert not (out / "m_heatmaps.png").exists()
    capsys.readouterr()
    # a folder that holds another evaluation is replaced, and the run says so before its work (once: not when the
    # same models on the same data run again)
    again = ["evaluate", str(tmp_path / "a" / "m.onnx"), "--data", str(dataset), "--no-baselines", "--max-samples", "1",
             "--out", str(out)]
    assert rtp_main(again) == 0
    assert f"{out} holds the evaluation of m.onnx on {dataset.name}, m.onnx on {dataset.name}: this one's replaces it" \
        in capsys.readouterr().err
    assert rtp_main(again) == 0 and "holds the evaluation" not in capsys.readouterr().err
    assert rtp_main(["evaluate", str(model), str(model.parent / ".." / model.parent.name / model.name), "--data",
                     str(dataset), "--out", str(tmp_path / "twice")]) == 2
    assert "are the same model file" in capsys.readouterr().err and not (tmp_path / "twice").exists()
    with pytest.raises(sdk.ParameterError, match="plot_name must be None"):
        evaluate(model, dataset, plot_name="../up", plots_dir=tmp_path)


def test_the_library_writes_the_files_the_cli_writes(dataset: Path, model: Path, tmp_path: Path) -> None:
    """EvaluationReport.write and write_reports give what `rtp evaluate --out` gives: evaluation.json
    a list with an entry per model (report.write wrote a bare dict, which bench/report.py could not
    read), evaluation.md each report in turn; an empty or foreign list is refused, nothing written."""
    from rtp.evaluate import write_reports

    a = evaluate(model, dataset, scenes=["a"], baselines=False)
    b = evaluate(model, dataset, scenes=["b"], baselines=False)
    md, js = a.write(tmp_path / "one")
    assert (md.name, js.name) == ("evaluation.md", "evaluation.json")
    assert json.loads(js.read_text()) == [json.loads(json.dumps(a.to_dict()))]
    assert md.read_text() == a.to_markdown()
    md, js = write_reports([a, b], tmp_path / "two", stem="both")
    assert [d["scenes"] for d in json.loads(js.read_text())] == [a.to_dict()["scenes"], b.to_dict()["scenes"]]
    assert md.read_text() == a.to_markdown() + "\n" + b.to_markdown() and md.name == "both.md"
    report = [sys.executable, str(Path(__file__).resolve().parents[1] / "bench" / "report.py"), "--compact"]
    shown = subprocess.run([*report, str(tmp_path / "one" / "evaluation.json")], capture_output=True, text=True)
    assert shown.returncode == 0 and str(model) in shown.stdout, shown.stderr
    for bad in ([], [a.to_dict()]):
        with pytest.raises(sdk.ParameterError, match="expected one or more EvaluationReport"):
            write_reports(bad, tmp_path / "bad")  # type: ignore[arg-type]
    assert not (tmp_path / "bad").exists()
    # a report whose JSON cannot be written leaves both files as they were (the new .md stood beside the old .json)
    before = {p: p.read_bytes() for p in (md, js)}

    def no_json() -> dict:
        raise ValueError("Out of range float values are not JSON compliant")

    b.to_dict = no_json  # type: ignore[method-assign]
    with pytest.raises(ValueError, match="JSON compliant"):
        write_reports([b, a], tmp_path / "two", stem="both")  # (another .md: b's first)
    assert {p: p.read_bytes() for p in (md, js)} == before
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == ["both.json", "both.md"]

def test_matched_quality_interpolates_along_the_sweep() -> None:
    from rtp.evaluate._evaluate import _matched

    sweep = [
        {"method": "a", "parameter": "t 1", "fail_share": 0.0, "work_saved": 0.2},
        {"method": "a", "parameter": "t 2", "fail_share": 0.2, "work_saved": 0.6},
        {"method": "b", "parameter": "c 1", "fail_share": 0.3, "work_saved": 0.9},
    ]
    got = {m["method"]: m for m in _matched(sweep, 0.1)}
    assert got["a"]["work_saved"] == pytest.approx(0.4)
    assert "between t 1 and t 2" in got["a"]["parameter"]
    assert got["b"]["work_saved"] != got["b"]["work_saved"]  # NaN: b never fails as rarely as 10%
    exact = {m["method"]: m for m in _matched(sweep, 0.2)}
    assert exact["a"]["work_saved"] == pytest.approx(0.6) and exact["a"]["parameter"] == "t 2"


def test_the_baselines_refuse_frames_they_would_misread() -> None:
    """A NaN frame made Yang 2019 choose 4x4 for every tile, and an 8-bit one FidelityFX 1x1 everywhere:
    both silent wrong answers, now typed errors."""
    nan = np.full((48, 64, 3), np.nan, np.float32)
    eight_bit = np.full((48, 64, 3), 128, np.uint8)
    for method in (Yang2019(16), FidelityFX(16)):
        with pytest.raises(sdk.NonFiniteInputError, match="reprojected"):
            method.shading_rates(nan)
        with pytest.raises(sdk.NonFiniteInputError, match="reprojected"):  # a Frame made by the caller too
            method.shading_rates(Frame(nan))
        with pytest.raises(sdk.InputError, match=r"values in \[5, 5\], expected display-encoded"):  # HDR: 4x4
            method.shading_rates(Frame(np.full((48, 64, 3), 5.0, np.float32)))
        with pytest.raises(sdk.InputDtypeError, match="255"):
            method.shading_rates(eight_bit)
        assert method.shading_rates(eight_bit / np.float32(255)).shape == (3, 4)
        for bad in (float("nan"), -1.0, "0.05"):  # (FidelityFX read nan as 1x1 everywhere and -1 the same)
            with pytest.raises(sdk.ParameterError, match="threshold"):
                method.shading_rates(eight_bit / np.float32(255), bad)  # type: ignore[arg-type]


def test_the_baselines_refuse_motion_and_seen_masks_they_would_misread() -> None:
    """An infinite speed made Yang 2019's tile 4x4 and FidelityFX's 1x1 (NaN: both 1x1), and a 0/255 seen
    mask read every tile as seen (Yang2019(unseen="full") shaded none at full rate): silent, now typed."""
    img = stripes(32, 48)
    seen = np.zeros((32, 48), np.float32)
    seen[:, 16:] = 1.0
    for bad in (np.inf, np.nan):
        motion = np.zeros((32, 48, 2), np.float32)
        motion[3, 5, 0] = bad
        for method in (Yang2019(16, motion_reduce="max"), FidelityFX(16)):
            with pytest.raises(sdk.NonFiniteInputError, match="motion"):
                method.shading_rates(Frame(img, motion))
            with pytest.raises(sdk.NonFiniteInputError, match="motion"):
                method.shading_rates({"reprojected": img, "motion": motion})
        nan_seen = seen.copy()
        nan_seen[0, 0] = bad
        with pytest.raises(sdk.NonFiniteInputError, match="seen"):
            Yang2019(16, unseen="full").shading_rates(Frame(img, None, nan_seen))
    full = Yang2019(16, unseen="full")
    with pytest.raises(sdk.InputError, match=r"seen: values in \[0, 255\], expected a mask in \[0, 1\]"):
        full.shading_rates(Frame(img, None, seen * 255))
    rates = full.shading_rates(Frame(img, None, seen))  # the same mask in [0, 1]: the unseen column at 1x1
    assert (rates[:, 0] == C["1x1"]).all() and (rates[:, 1:] != C["1x1"]).all()


@pytest.mark.parametrize("make, name", [
    (lambda v: Yang2019(16, motion=v), "motion"), (lambda v: Yang2019(16, allow_4x4=v), "allow_4x4"),
    (lambda v: FidelityFX(16, additional_rates=v), "additional_rates")])
def test_the_baselines_on_off_parameters_take_only_booleans(make: Any, name: str) -> None:
    """``motion="false"``, ``allow_4x4="no"`` or ``additional_rates="false"`` (texts from a settings file) were
    read by their truth and switched the option on; now a BaselineError naming the parameter."""
    for bad in ("false", "no", 0, 1, None):
        with pytest.raises(BaselineError, match=f"{name}: expected True or False"):
            make(bad)
    assert getattr(make(np.bool_(False)), name) is False and getattr(make(True), name) is True


def test_the_scoring_helpers_refuse_what_they_would_misread() -> None:
    """Each took mismatched or meaningless input silently (scores(None, None) was n=0, failing_tiles on another
    grid said that no tile fails) or failed with numpy's bare ValueError."""
    from rtp.evaluate import failing_tiles, foveation_rates, motion_rates, scores

    codes, truth = np.zeros((3, 4), np.uint8), np.zeros((6, 3, 4))
    for call, error, words in (
            (lambda: scores(None, None), sdk.InputDtypeError, "pred: expected an array of numbers"),  # type: ignore
            (lambda: scores([1.0, 2.0], [1.0, 2.0, 3.0]), sdk.InputShapeError, "differ in size"),
            (lambda: scores([1.0, 2.0], [1.0, 3.0], worse=float("nan")), sdk.ParameterError, "worse: expected"),
            (lambda: spearman(np.arange(2.0), np.arange(3.0)), sdk.InputShapeError, "x and y differ in size"),
            (lambda: failing_tiles(codes, truth[:, :, :2], 0.1, False), sdk.InputShapeError, r"\(6, 3, 4\)"),
            (lambda: failing_tiles(codes + 99, truth, 0.1, False), sdk.ParameterError, r"codes: .* got \[99\]"),
            (lambda: motion_rates(np.zeros((48, 64)), np.zeros((5, 64)), 16), sdk.InputShapeError, "one size"),
            (lambda: foveation_rates(-1, 5), sdk.ParameterError, "positive integers")):
        with pytest.raises(error, match=words):
            call()
    assert scores([1.0, 2.0, 3.0], [1.0, 2.0, 4.0], worse=-1.0).n == 3 and spearman([1, 2, 3], [3, 2, 1]) == -1.0
    assert failing_tiles(codes + C["2x2"], truth + 1.0, 0.5, False).all() and foveation_rates(3, 4).shape == (3, 4)


def test_motion_rates_of_a_partial_edge_tile_are_of_its_own_pixels() -> None:
    """A partial edge tile's mean motion was of the frame padded by edge copies: 18 rows on 16-pixel tiles
    averaged (r16 + 15 r17) / 16 for the last tile row, not (r16 + r17) / 2, and chose another rate."""
    from rtp.evaluate import motion_rates

    mx = np.zeros((18, 20), np.float32)
    mx[16, :] = 4.0  # the last tile row's two real rows: a mean of 2 pixels a frame along x -> 2 wide
    # the last column of tiles (4 real columns): 16 and 0 on alternate rows, a mean of 8 -> 4 wide, made 2 beside 1 tall
    mx[:, 16:] = np.where(np.arange(18)[:, None] % 2 == 0, 16.0, 0.0)
    codes = motion_rates(mx, np.zeros_like(mx), 16)
    assert codes.shape == (2, 2)
    assert codes[1, 0] == C["2x1"], codes  # (edge copies: (4 + 15 x 0) / 16 = 0.25, full rate)
    assert codes[0, 1] == C["2x1"] and codes[1, 1] == C["2x1"], codes  # 4 wide beside 1 tall becomes 2
    assert codes[0, 0] == C["1x1"]
    # whole tiles as before
    whole = np.zeros((32, 32), np.float32)
    whole[:16, :16] = 2.0
    assert motion_rates(whole, whole * 0, 16).tolist() == [[C["2x1"], C["1x1"]], [C["1x1"], C["1x1"]]]


def test_failing_tiles_and_tile_unseen_share_refuse_what_they_misread() -> None:
    """failing_tiles took any threshold and direction: at NaN every reduced rate failed, and higher_is_better="False"
    (a true string) judged an error metric's tiles as PSNR's, silently; tile_unseen_share of a (1, H, W) plane was
    numpy's "too many values to unpack"."""
    from rtp.evaluate import failing_tiles

    codes, truth = np.full((1, 2), C["2x2"], np.uint8), np.full((6, 1, 2), 0.1)
    truth[:, 0, 1] = 40.0
    for threshold, hib, words in ((float("nan"), False, "threshold: expected a finite number"),
                                  (35.0, "False", "higher_is_better: expected True or False"),
                                  (35.0, np.float64(0.0), "higher_is_better: expected True or False"),
                                  ("0.2", False, "threshold: expected a number"),
                                  (-1.0, False, "threshold: expected a finite number in \\[0")):
        with pytest.raises(sdk.ParameterError, match=words):
            failing_tiles(codes, truth, threshold, hib)  # type: ignore[arg-type]
    assert failing_tiles(codes, truth, 35.0, np.bool_(True)).tolist() == [[True, False]]
    assert failing_tiles(codes, truth, 0.25, False).tolist() == [[False, True]]
    for seen in (np.ones((1, 32, 32)), np.ones((32, 32, 1)), np.ones(5)):
        with pytest.raises(sdk.InputShapeError, match=r"seen: expected an \(H, W\) mask"):
            tile_unseen_share(seen, 16)
    assert tile_unseen_share(np.array([[True, False], [False, False]]), 16).tolist() == [[0.75]]


def test_matched_quality_takes_the_most_saved_among_the_points_failing_at_most_the_target(
        dataset: Path, model: Path) -> None:
    """The table took, among the points failing exactly the target's share, the first in text order: the one
    that saved the least ("t 8": 93.06% where "t 11.31" saved 93.72% at the same failures), and with
    `--threshold 2` the model's row read "threshold 0.7071". It now reads the sweep as saved_at does (rtp
    play, bench/report.py): the most saved at most the target's failures, ties to the parameter nearest the
    method's own (else the smallest number, not the first text)."""
    from rtp.evaluate import saved_at
    from rtp.evaluate._evaluate import _matched

    sweep = [{"method": "yang2019", "parameter": p, "fail_share": f, "work_saved": w}
             for p, f, w in (("t 2", 0.0, 0.5), ("t 8", 0.01, 0.9306), ("t 11.31", 0.01, 0.9372), ("t 16", 0.03, 0.95))]
    sweep += [{"method": "model", "parameter": f"threshold {t}", "fail_share": 0.0, "work_saved": 0.9}
              for t in ("0.7071", "11.31", "2", "8")]
    got = {m["method"]: m for m in _matched(sweep, 0.01, {"yang2019": 0.25})}
    assert (got["yang2019"]["work_saved"], got["yang2019"]["parameter"]) == (0.9372, "t 11.31")
    (own,) = _matched(sweep[4:], 0.0, {"model": 2.0})
    assert (own["work_saved"], own["parameter"]) == (0.9, "threshold 2")  # (ties: the method's own)
    (smallest,) = _matched(sweep[4:], 0.0)
    assert smallest["parameter"] == "threshold 0.7071"  # (no default: the smallest number, not the first text)
    assert _matched(sweep[5:], 0.0)[0]["parameter"] == "threshold 2"
    # any sweep reads as saved_at reads it, inside the failures it reaches
    rng = np.random.default_rng(3)
    for _ in range(200):
        pts = [(float(f), float(w)) for f, w in zip(rng.choice([0.0, 0.01, 0.02, 0.05], 6), rng.random(6))]
        target = float(rng.choice([0.0, 0.01, 0.015, 0.02, 0.03]))
        (row,) = _matched([{"method": "m", "parameter": f"t {i}", "fail_share": f, "work_saved": w}
                           for i, (f, w) in enumerate(pts)], target)
        if min(f for f, _ in pts) <= target <= max(f for f, _ in pts):
            assert row["work_saved"] == pytest.approx(saved_at(pts, target)), (pts, target)
        else:
            assert np.isnan(row["work_saved"])
    rep = evaluate(model, dataset, threshold=2.0)
    matched = {m["method"]: m for m in rep.matched}
    assert matched["model"]["parameter"] == "threshold 2"
    for method, m in matched.items():
        pts = [(r["fail_share"], r["work_saved"]) for r in rep.sweep if r["method"] == method]
        assert m["work_saved"] == pytest.approx(saved_at(pts, m["fail_share"])), method


def test_a_sweep_reads_the_best_of_its_points_that_fail_equally_often() -> None:
    """saved_at and the matched table ran the line from a point towards the next one in (fail, saved) order: of two
    points that fail equally often, the one that saves less, as if the other were not there ((1%, 50%), (3%, 40%),
    (3%, 80%) read 50% at 2%, not 65%). And a NaN point was placed wherever sorting left it: the same points read 90%,
    65% or None by the order given; it is refused."""
    from rtp.evaluate import saved_at
    from rtp.evaluate._evaluate import _matched

    pts = [(0.01, 0.5), (0.03, 0.4), (0.03, 0.8)]
    sweep = [{"method": "m", "parameter": f"t {p}", "fail_share": f, "work_saved": w} for p, (f, w) in zip((1, 2, 4), pts)]
    for order in (1, -1):
        assert saved_at(pts[::order], 0.02) == pytest.approx(0.65)
        (row,) = _matched(sweep[::order], 0.02, {"m": 1.0})
        assert row["work_saved"] == pytest.approx(0.65) and row["parameter"] == "between t 1 and t 4"
    assert saved_at(pts, 0.03) == pytest.approx(0.8) and saved_at(pts, 0.01) == pytest.approx(0.5)
    nan = float("nan")
    for points, fail in (([(0.01, 0.5), (nan, 0.9), (0.03, 0.8)], 0.02), ([(0.03, 0.8), (nan, 0.9), (0.01, 0.5)], 0.02),
                         ([(0.01, nan), (0.03, 0.8)], 0.02), ([(0.01, 0.5)], nan)):
        with pytest.raises(sdk.ParameterError, match="not NaN"):
            saved_at(points, fail)


def test_a_threshold_at_either_end_of_its_range_is_evaluated(dataset: Path, model: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """`--threshold 1e6` was refused as "--threshold: ... got 1.41421e+06" (the sweep around it, past the range,
    under the user's flag) and `--threshold 0` as "Yang 2019's threshold: expected a number > 0", the baseline
    that takes a JNYang model's threshold: both are evaluated, the sweep kept inside the range, once each value."""
    from rtp.evaluate._evaluate import _parameter_value

    for t in ("1e6", "0"):
        assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--threshold", t]) == 0, capsys.readouterr().err
    top = evaluate(model, dataset, threshold=1e6)
    grid = [_parameter_value(r["parameter"]) for r in top.sweep if r["method"] == "model"]
    assert max(grid) == 1e6 and len(set(grid)) == len(grid) == 9
    assert max(_parameter_value(r["parameter"]) for r in top.sweep if r["method"] == "yang2019") == 1e6
    zero = evaluate(model, dataset, threshold=0.0)
    assert [r["parameter"] for r in zero.sweep if r["method"] in ("model", "yang2019")] == ["threshold 0", "t 0"]
    assert zero.row("decisions", "yang2019")["work_saved"] == 0  # (nothing is below 0: all 1x1, as the model)
    assert Yang2019(16, threshold=0.0).threshold == 0.0
    with pytest.raises(BaselineError, match=r"Yang 2019's threshold: expected a number in \[0, 1e\+06\]"):
        Yang2019(16, threshold=2e6)
    capsys.readouterr()
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), "--threshold", "1e7"]) == 2
    assert "--threshold: expected a finite number in [0, 1e+06] for an error metric (lower is better), got 1e+07" \
        in capsys.readouterr().err


def test_a_psnr_models_scatter_says_which_end_is_worst(dataset: Path, model: Path, tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The scatter plots the transformed values as they are, where PSNR's 1 is the best; its label said
    "1 = worst" for every metric. The heatmaps, turned so that bright is worse, keep theirs."""
    store = TargetStore(dataset)
    store.declare("psnr", {})
    for i in range(3):
        psnr = (20.0 + 30.0 * np.random.default_rng(i).random((6, H // T, W // T))).astype(np.float32)
        store.write(f"s{i}", "psnr", psnr.repeat(T // 4, 1).repeat(T // 4, 2), (H, W))
    meta = base_metadata(metric="psnr", weber_l=None, transform={"type": "clamped", "mu_y": 38.0},
                         default_threshold=35.0, outputs=["1x2", "2x1"])
    psnr_model = build_onnx(tmp_path / "p.onnx", weights=np.eye(2, 4, dtype=np.float32), tile=T, metadata=meta)
    labels: dict[str, str] = {}
    real_scatter, real_heatmaps = plots.scatter, plots.heatmaps

    def scatter(*args: Any, **kwargs: Any) -> np.ndarray:
        labels["scatter"] = kwargs["label"]
        return real_scatter(*args, **kwargs)

    def heatmaps(*args: Any, **kwargs: Any) -> np.ndarray:
        labels["heatmaps"] = kwargs["label"]
        return real_heatmaps(*args, **kwargs)

    monkeypatch.setattr(plots, "scatter", scatter)
    monkeypatch.setattr(plots, "heatmaps", heatmaps)
    assert sdk.load(psnr_model).metadata.worse_direction < 0
    evaluate(psnr_model, dataset, baselines=False, plots_dir=tmp_path / "psnr")
    assert labels == {"scatter": "psnr (clamped transform, 0 = worst)", "heatmaps": "psnr (clamped transform, 1 = worst)"}
    evaluate(model, dataset, baselines=False, plots_dir=tmp_path / "jnyang")
    assert labels["scatter"] == "jnyang (clamped transform, 1 = worst)"


def test_each_evaluation_plot_names_its_model_and_sample(dataset: Path, model: Path, tmp_path: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """The heatmaps were titled "sample s0: true and predicted error per tile", the scatter "jnyang: predicted vs
    true" and the rate overlays not at all: two models' plots (or one copied into a document) did not say whose they
    were. Each names the model (its plots' name), the heatmaps and the overlays the sample, the overlays the threshold
    'model' decided at."""
    import shutil

    titles: dict[str, str] = {}
    for name in ("heatmaps", "scatter", "rate_overlays"):
        def record(*args: Any, _name: str = name, **kwargs: Any) -> np.ndarray:
            titles[_name] = kwargs["title"]
            return np.zeros((1, 1, 3), np.uint8)

        monkeypatch.setattr(plots, name, record)
    mine = shutil.copy(model, tmp_path / "my-model.onnx")
    evaluate(mine, dataset, baselines=False, sweep=False, plots_dir=tmp_path / "plots", plot_sample="s1")
    assert "my-model" in titles["heatmaps"] and "sample s1" in titles["heatmaps"], titles
    assert titles["scatter"].startswith("my-model: predicted vs true jnyang"), titles
    assert "sample s1" in titles["rate_overlays"] and "my-model at jnyang threshold 0.2" in titles["rate_overlays"]
    img = np.zeros((40, 60, 3), np.float32)
    codes = np.zeros((3, 4), np.uint8)
    monkeypatch.undo()
    titled = plots.rate_overlays(img, {"a": codes}, 16, title="rates chosen on sample s1")
    assert titled.shape[0] > plots.rate_overlays(img, {"a": codes}, 16).shape[0]  # (room for the title above)


def test_an_evaluation_folder_is_recognised_from_another_working_folder(
        dataset: Path, model: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """evaluation.json kept the data's path as typed ("data") and the next run read it against its own working
    folder: the same model on the same data, run from elsewhere, was "another evaluation". The report keeps the
    paths resolved; an older report's relative ones are still read (against the working folder, as before)."""
    out = tmp_path / "eval"
    run = ["--no-baselines", "--max-samples", "1", "--out", str(out)]
    monkeypatch.chdir(dataset.parent)
    assert rtp_main(["evaluate", model.name, "--data", dataset.name, *run]) == 0
    (entry,) = json.loads((out / "evaluation.json").read_text())
    assert (entry["data"], entry["model"]["path"]) == (str(dataset.resolve()), str(model.resolve()))
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    capsys.readouterr()
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), *run]) == 0
    assert "holds the evaluation" not in capsys.readouterr().err
    entry.update(data=dataset.name)  # (a report written before: the path as typed)
    (out / "evaluation.json").write_text(json.dumps([entry]))
    monkeypatch.chdir(dataset.parent)
    assert rtp_main(["evaluate", str(model), "--data", str(dataset), *run]) == 0
    assert "holds the evaluation" not in capsys.readouterr().err


def test_an_evaluation_into_another_ones_folder_removes_that_ones_plots(
        dataset: Path, model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp evaluate psnr --out F` into a folder of jnyang's evaluation left jnyang_*.png beside psnr's report.
    The plots the replaced evaluation.json listed and the new one does not are removed; no other file."""
    import shutil

    out = tmp_path / "eval"
    other = shutil.copy(model, tmp_path / "other.onnx")
    run = ["--data", str(dataset), "--no-baselines", "--max-samples", "1", "--out", str(out)]
    assert rtp_main(["evaluate", str(model), *run, "--plots"]) == 0
    (out / "notes.png").write_bytes(b"mine")
    (out / "mine_rates.png").write_bytes(b"mine too")  # (of the plots' naming, but no report listed it)
    assert rtp_main(["evaluate", str(other), *run, "--plots"]) == 0
    left = sorted(p.name for p in out.iterdir())
    assert left == ["evaluation.json", "evaluation.md", "mine_rates.png", "notes.png", "other_heatmaps.png",
                    "other_rates.png", "other_scatter.png"], left
    assert rtp_main(["evaluate", str(other), *run]) == 0  # the same model without --plots: its old plots go too
    assert sorted(p.name for p in out.iterdir()) == ["evaluation.json", "evaluation.md", "mine_rates.png", "notes.png"]


def test_a_failure_while_drawing_the_plots_leaves_the_previous_ones_whole(
        dataset: Path, model: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The three figures were drawn and written one at a time: a failure drawing the last left this evaluation's
    heatmaps and scatter beside the previous evaluation's rate overlay. All are drawn before the first is written."""
    from rtp.evaluate import plots

    out = tmp_path / "eval"
    run = ["--data", str(dataset), "--no-baselines", "--max-samples", "1", "--out", str(out), "--plots"]
    assert rtp_main(["evaluate", str(model), *run]) == 0
    for png in out.glob("*.png"):
        png.write_bytes(b"the previous evaluation's " + png.name.encode())  # (this run would draw the same)
    before = {p.name: p.read_bytes() for p in out.glob("*.png")}
    assert len(before) == 3

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise RuntimeError("drawing failed")

    monkeypatch.setattr(plots, "rate_overlays", broken)
    with pytest.raises(RuntimeError, match="drawing failed"):
        rtp_main(["evaluate", str(model), *run])
    assert {p.name: p.read_bytes() for p in out.glob("*.png")} == before


def test_a_run_stopped_after_its_first_models_plots_leaves_the_folder_as_it_was(
        dataset: Path, model: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`rtp evaluate a b --plots --out F` drew a's plots into F as soon as a was evaluated: stopped during b (Ctrl-C,
    a failure), F held a's new pictures over the previous evaluation's of that name, beside that evaluation's report
    (other numbers, other scenes). The plots now wait in a folder of their own until the report that shows them is
    written; a stopped run leaves F as it was, and no folder of its own behind."""
    import shutil

    import rtp.evaluate as ev

    out = tmp_path / "eval"
    other = shutil.copy(model, tmp_path / "other.onnx")
    run = ["--data", str(dataset), "--no-baselines", "--max-samples", "1", "--out", str(out), "--plots"]
    assert rtp_main(["evaluate", str(model), *run]) == 0
    for png in out.glob("*.png"):
        png.write_bytes(b"the previous evaluation's " + png.name.encode())  # (this run draws the same names)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert len([n for n in before if n.endswith(".png")]) == 3
    real = ev.evaluate

    def second_stopped(m: Any, *args: Any, **kwargs: Any) -> Any:
        if Path(m) == Path(other):
            raise KeyboardInterrupt
        return real(m, *args, **kwargs)

    monkeypatch.setattr(ev, "evaluate", second_stopped)
    assert rtp_main(["evaluate", str(model), str(other), *run]) == 130  # (Ctrl-C's exit status)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    monkeypatch.setattr(ev, "evaluate", real)
    assert rtp_main(["evaluate", str(model), str(other), *run]) == 0  # a whole run: its plots beside its report
    md = (out / "evaluation.md").read_text()
    for name in ("m", "other"):
        for kind in ("heatmaps", "scatter", "rates"):
            png = out / f"{name}_{kind}.png"
            assert png.read_bytes().startswith(b"\x89PNG") and f"]({png.name})" in md
    assert json.loads((out / "evaluation.json").read_text())[0]["plots"] == [
        str(out / f"m_{kind}.png") for kind in ("heatmaps", "scatter", "rates")]
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_a_reports_plot_links_reach_plots_drawn_into_another_folder(dataset: Path, model: Path, tmp_path: Path) -> None:
    """A library call drawing its plots into a plots_dir other than the folder the report is written into linked them
    by file name: every image of evaluation.md was broken. Linked relative to the report now; beside it, by name."""
    import re

    rep = evaluate(model, dataset, baselines=False, max_samples=1, plots_dir=tmp_path / "figures")
    rep.write(tmp_path / "report")
    links = re.findall(r"!\[[^]]*\]\(([^)]+)\)", (tmp_path / "report" / "evaluation.md").read_text())
    assert len(links) == 3 and all(link.startswith("../figures/") for link in links), links
    assert all((tmp_path / "report" / link).is_file() for link in links)
    rep.write(tmp_path / "figures")  # (beside its plots, as rtp evaluate --out writes them: by name)
    links = re.findall(r"!\[[^]]*\]\(([^)]+)\)", (tmp_path / "figures" / "evaluation.md").read_text())
    assert links and all("/" not in link for link in links), links


def _sweep_point(rep: Any, method: str, label: str) -> dict[str, Any]:
    (row,) = [r for r in rep.sweep if r["method"] == method and r["parameter"] == label]
    return row


def test_each_sweep_at_the_methods_own_parameter_is_its_decision_row(dataset: Path, model: Path) -> None:
    """The matched table reads the sweeps; each sweep's point at the parameter of the decision table must be that
    row. Yang 2019's sweep chose among all rates where NAS's setting (allow_4x4=False) keeps 4x4 out: on the black,
    unseen tile it swept 4x4 (93.75% saved) where the decision shaded 2x4 (87.5%)."""
    nas = Yang2019(T, threshold=0.25, motion=False, allow_4x4=False)
    rep = evaluate(model, dataset, yang=nas)
    labels = {"model": "threshold 0.2", "yang2019": "t 0.25", "yang2019-unseen-1x1": "t 0.25"}
    for method, label in labels.items():
        row, point = rep.row("decisions", method), _sweep_point(rep, method, label)
        assert (point["fail_share"], point["work_saved"]) == pytest.approx((row["fail_share"], row["work_saved"])), method
    assert rep.row("decisions", "yang2019")["rate_shares"]["4x4"] == 0.0
    ffx = evaluate(model, dataset)  # the default baselines (Yang at a JNYang model's threshold; FidelityFX's 0.05)
    for method, label in {"model": "threshold 0.2", "yang2019": "t 0.2", "yang2019-unseen-1x1": "t 0.2",
                          "fidelityfx": "cutoff 0.05", "fidelityfx-additional": "cutoff 0.05"}.items():
        row, point = ffx.row("decisions", method), _sweep_point(ffx, method, label)
        assert (point["fail_share"], point["work_saved"]) == pytest.approx((row["fail_share"], row["work_saved"])), method


def _jnyang_store(root: Path, weber_l: float) -> tuple[DatasetWriter, TargetStore]:
    """A new dataset's writer and target store at ``root``, JNYang declared at ``weber_l``."""
    writer, store = DatasetWriter(root), TargetStore(root)
    store.declare("jnyang", {"weber_l": weber_l})
    return writer, store


def test_yang_takes_a_jnyang_models_environment_luminance(tmp_path: Path) -> None:
    """Yang 2019's estimates E / (L + l) are JNYang-like: the evaluation judges them at a JNYang model's threshold,
    so at its ``weber_l`` too. It used its own l = 0.02 whatever the model's, so on a model (and targets) at l = 0.1
    its dark tiles' estimates were in other units than the threshold they were held to: about twice as high at a
    mean luma of 0.06, and 1x1 where Yang at the model's l shades them coarser."""
    root = tmp_path / "dark"
    writer, store = _jnyang_store(root, 0.1)
    rng = np.random.default_rng(5)
    for i in range(2):
        bufs = _seen_whole(rng, H, W)
        # dark, with steps that vary per tile: E / (0.06 + 0.02) and E / (0.06 + 0.1) straddle the threshold 0.2
        step = rng.uniform(0.0, 0.04, (H // T, W // T)).repeat(T, 0).repeat(T, 1)
        bufs["reprojected"] = grey(0.06 + step * (np.arange(W)[None, :] % 2 - 0.5))
        writer.write(f"d{i}", bufs, {"scene": "d"})
        store.write(f"d{i}", "jnyang", np.full((6, H // 4, W // 4), 0.01, np.float32), (H, W))
    writer.finalize()
    weights = np.zeros((2, 4), np.float32)
    model = build_onnx(tmp_path / "l01.onnx", weights=weights, tile=T,
                       metadata=base_metadata(outputs=["1x2", "2x1"], default_threshold=0.2, weber_l=0.1))
    rep = evaluate(model, root, sweep=False)
    assert rep.baselines["yang2019"]["env_luminance"] == 0.1 == rep.baselines["yang2019-unseen-1x1"]["env_luminance"]
    from rtp.capture import DatasetReader

    reader = DatasetReader(root)
    own = Yang2019(T, threshold=0.2, env_luminance=0.1, motion=False)
    codes = np.concatenate([own.shading_rates(reader[f"d{i}"]).ravel() for i in range(2)])
    other = np.concatenate([Yang2019(T, threshold=0.2, motion=False).shading_rates(reader[f"d{i}"]).ravel()
                            for i in range(2)])
    assert (codes != other).any()  # (the case is not trivial: the two ls decide differently)
    shares = rep.row("decisions", "yang2019")["rate_shares"]
    assert shares == {r: pytest.approx(float(np.mean(codes == C[r]))) for r in sdk.ALL_RATES}


def test_the_unseen_variants_note_names_the_share_it_used(dataset: Path, model: Path) -> None:
    """'yang2019-unseen-1x1' built from a Yang2019 given to evaluate (yang=, to score it with motion, as the docs
    suggest) keeps that one's unseen_fraction; the report's note named the evaluation's --unseen-fraction instead."""
    rep = evaluate(model, dataset, yang=Yang2019(T, threshold=0.25, motion=False), unseen_fraction=0.3, sweep=False)
    assert rep.baselines["yang2019-unseen-1x1"]["unseen_fraction"] == 0.5
    (note,) = [n for n in rep.notes if "'yang2019-unseen-1x1'" in n]
    assert "more than 50% unseen at 1x1" in note, note
    default = evaluate(model, dataset, unseen_fraction=0.3, sweep=False)  # (the default variant: the evaluation's)
    assert default.baselines["yang2019-unseen-1x1"]["unseen_fraction"] == 0.3
    assert any("more than 30% unseen at 1x1" in n for n in default.notes)


def _seen_whole(rng: np.random.Generator, h: int, w: int) -> dict[str, np.ndarray]:
    """A sample's buffers of random values, every pixel seen, no motion."""
    bufs = {}
    for name, spec in BUFFERS.items():
        c = len(spec.channels) or 3
        bufs[name] = rng.random((h, w, c) if c > 1 else (h, w), dtype=np.float32)
    bufs["seen"] = np.ones((h, w), np.float32)
    bufs["motion"] = np.zeros((h, w, 2), np.float32)
    return bufs


def test_the_work_saved_counts_a_partial_edge_tile_by_its_pixels(tmp_path: Path, model: Path) -> None:
    """A frame whose height is no whole number of tiles (1920x1080 on 16-pixel tiles: the bottom row 8 pixels
    high) saves on its partial tiles the work of their real pixels, as sdk.work_saved(codes, size, tile) and `rtp
    play` count it; the mean over tiles counted each as a whole tile. Here the bottom row (half-height tiles)
    passes at 4x4 and the rest only at 1x1: the oracle saves 0.9375 x 128 x 4 / 2560 = 18.75% of the pixels'
    work (the tiles' mean read 31.25%), in the decision table and in the sweep alike."""
    h, w = 40, 64  # 3 x 4 tiles of 16 px, the last row 8 px high
    root = tmp_path / "ragged"
    writer, store = _jnyang_store(root, 0.02)
    rng = np.random.default_rng(1)
    truth = np.full((6, h // 4, w // 4), 0.9, np.float32)  # at the 4-pixel base tile: every rate fails 0.2 ...
    truth[:, 8:, :] = 0.01  # ... but on the bottom row, where every rate passes
    for i in range(2):
        bufs = _seen_whole(rng, h, w)
        writer.write(f"r{i}", bufs, {"scene": "r"})
        store.write(f"r{i}", "jnyang", truth, (h, w))
    writer.finalize()
    rep = evaluate(model, root, baselines=False)
    codes = sdk.select_rates(store.load("r0", "jnyang", T), 0.2)
    assert (codes[2] == C["4x4"]).all() and (codes[:2] == C["1x1"]).all()
    oracle = rep.row("decisions", "oracle")
    assert oracle["n"] == 2 * 12 and oracle["fail_share"] == 0.0
    assert oracle["work_saved"] == pytest.approx(0.1875) == sdk.work_saved(codes, (h, w), T)
    from rtp.capture import DatasetReader

    predictor, reader = sdk.load(model), DatasetReader(root)
    frames = [predictor.shading_rates(reader[f"r{i}"].inputs(predictor.metadata.inputs), 0.2) for i in range(2)]
    model_row = rep.row("decisions", "model")
    assert model_row["work_saved"] == pytest.approx(np.mean([sdk.work_saved(c, (h, w), T) for c in frames]))
    point = _sweep_point(rep, "model", "threshold 0.2")
    assert point["work_saved"] == pytest.approx(model_row["work_saved"])


def test_the_reports_words_give_the_failing_rule_and_the_threshold_matched(dataset: Path, model: Path,
                                                                         tmp_path: Path) -> None:
    """A PSNR tile fails where its true PSNR is not above the threshold (failing_tiles: equal fails), and the note
    said it "falls below"; the matched table said "at its default threshold" of a run at --threshold 0.3."""
    codes = np.full((1, 2), sdk.RATE_CODES["2x2"], np.uint8)
    truth = np.full((6, 1, 2), 35.0, np.float32)
    truth[:, 0, 1] = 35.5
    assert failing_tiles(codes, truth, 35.0, True).tolist() == [[True, False]]
    store = TargetStore(dataset)
    store.declare("psnr", {})
    for i in range(3):
        store.write(f"s{i}", "psnr", np.full((6, H // 4, W // 4), 35.0, np.float32), (H, W))
    meta = base_metadata(metric="psnr", weber_l=None, transform={"type": "clamped", "mu_y": 38.0},
                         default_threshold=35.0, outputs=["1x2", "2x1"])
    psnr_model = build_onnx(tmp_path / "p.onnx", weights=np.eye(2, 4, dtype=np.float32), tile=T, metadata=meta)
    rep = evaluate(psnr_model, dataset, baselines=False, sweep=False)
    assert any("true psnr is not above 35" in n for n in rep.notes), rep.notes
    assert rep.row("decisions", "model")["fail_share"] == 1.0 - rep.row("decisions", "model")["rate_shares"]["1x1"]
    text = evaluate(model, dataset, threshold=0.3).to_markdown()
    assert "as often as the model at its threshold 0.3, the decision table's" in text
    assert "default threshold" not in text


def test_samples_without_up_to_date_targets_are_refused_before_the_first_is_evaluated(
        dataset: Path, model: Path) -> None:
    """A sample captured after `rtp targets` ran (no target file), or captured again since (stale targets): the
    evaluation stopped at that sample after the work on those before it, and check_evaluation (what `rtp evaluate`
    runs on every model before the first) let it through; now both refuse it first, saying what to run, and
    --max-samples that leaves it out evaluates."""
    import os

    from rtp.capture import TargetError
    from rtp.evaluate import check_evaluation

    store = TargetStore(dataset)
    store.path("s2", "jnyang").unlink()
    calls: list[int] = []
    for run in (lambda: check_evaluation(model, dataset),
                lambda: evaluate(model, dataset, baselines=False, progress=lambda n, total: calls.append(n))):
        with pytest.raises(TargetError, match=r"1 of the 3 samples to evaluate have no jnyang targets \('s2'\); "
                                              r"run `rtp targets .* --metrics jnyang`"):
            run()
    assert calls == []  # (refused before the first sample, not after two)
    check_evaluation(model, dataset, max_samples=2)
    assert evaluate(model, dataset, baselines=False, max_samples=2).samples == 2
    check_evaluation(model, dataset, scenes="a")
    # `rtp evaluate` checks each of several models on the samples it evaluates, those --max-samples leaves
    import shutil

    other = dataset.parent / "other" / "m.onnx"
    other.parent.mkdir()
    shutil.copy(model, other)
    two = ["evaluate", str(model), str(other), "--data", str(dataset), "--no-baselines"]
    assert rtp_main([*two, "--max-samples", "2"]) == 0
    assert rtp_main(two) != 0
    with pytest.raises(sdk.ParameterError, match="max_samples"):
        check_evaluation(model, dataset, max_samples=0)
    # targets of the sample before it was captured again: found by the sample's content, not its file's time (a
    # copy of the dataset gives it any), so a sample only touched, or whose file is older, is no other sample
    store.write("s2", "jnyang", _truth(2).repeat(T // 4, 1).repeat(T // 4, 2), (H, W))
    sample = dataset / "samples" / "s1.npz"
    later = store.path("s1", "jnyang").stat().st_mtime + 10
    os.utime(sample, (later, later))
    check_evaluation(model, dataset)
    bufs = {name: np.full((H, W, len(spec.channels) or 3) if (len(spec.channels) or 3) > 1 else (H, W), 0.5,
                          np.float32) for name, spec in BUFFERS.items()}
    DatasetWriter(dataset).write("s1", bufs, {"scene": "a"})
    os.utime(sample, (1, 1))
    with pytest.raises(TargetError, match=r"have outdated \(of the sample before it was captured again\) jnyang "
                                          r"targets \('s1'\)"):
        check_evaluation(model, dataset)


def test_an_empty_split_reads_as_no_value_in_every_column(tmp_path: Path, model: Path) -> None:
    """Frames seen whole have no unseen tiles: the unseen rows' columns read "-", but the decision table's rates
    column read "nan/nan/nan/nan/nan/nan/nan", on the terminal and in evaluation.md."""
    h, w = 32, 64
    root = tmp_path / "whole"
    writer, store = _jnyang_store(root, 0.02)
    rng = np.random.default_rng(2)
    for i in range(2):
        bufs = _seen_whole(rng, h, w)
        writer.write(f"w{i}", bufs, {"scene": "w"})
        store.write(f"w{i}", "jnyang", rng.uniform(0.01, 0.5, (6, h // 4, w // 4)).astype(np.float32), (h, w))
    writer.finalize()
    rep = evaluate(model, root, sweep=False)
    assert rep.row("decisions", "oracle", split="unseen")["n"] == 0
    seen = rep.row("decisions", "oracle", split="seen")
    assert seen["n"] == 16 and "/".join(f"{100 * seen['rate_shares'][k]:.0f}" for k in sdk.ALL_RATES) in rep.table()
    md, table = rep.to_markdown(), rep.table()
    import re

    assert not re.search(r"\bnan\b", md + table, re.IGNORECASE)
    assert "| w | unseen | oracle | 0.2 | 0 | - | - | - |" in md
    unseen_line = next(line for line in table.splitlines() if " unseen " in line and " oracle " in line)
    assert unseen_line.split()[-4:] == ["0", "-", "-", "-"]
    assert json.loads(json.dumps(rep.to_dict(), allow_nan=False))["decisions"][2]["rate_shares"]["1x1"] is None


def test_targets_all_one_value_leave_r2_undefined_and_the_report_says_why(tmp_path: Path) -> None:
    """Targets all one value have no variance to explain: R² is undefined. The mean's rounding left SS_tot at
    about 1e-31 for most values (ten 0.3s; here 96 values of T(0.01)), and R² read -5e36 % in the table, a number
    computed on nothing (rtp train's validation R² too). It is NaN now: "-" in the tables, null in evaluation.json,
    and a note says why, as it does for Spearman's "-" (a constant predictor's)."""
    from rtp.evaluate import scores

    g = np.full(10, 0.3)
    assert np.isnan(scores(g - 0.1, g).r2) and np.isnan(scores(np.full(7, 0.7), np.full(7, 0.7)).r2)
    assert scores(g - 0.1, g + np.arange(10) * 1e-6).r2 < 0  # (varying, however little: defined)
    h, w = 64, 64
    root = tmp_path / "flat"
    writer, store = _jnyang_store(root, 0.02)
    rng = np.random.default_rng(4)
    for i in range(3):
        writer.write(f"f{i}", _seen_whole(rng, h, w), {"scene": "f"})
        store.write(f"f{i}", "jnyang", np.full((6, h // 4, w // 4), 0.01, np.float32), (h, w))
    writer.finalize()
    # (mu_y 0.3: T(0.01) = 0.01 / 0.6, whose mean over these 96 values rounds; the fixture's 0.5 divides exactly)
    weights = np.zeros((2, 4), np.float32)
    weights[0, 2], weights[1, 2] = 4.0, -2.0
    flat_model = build_onnx(tmp_path / "m3.onnx", weights=weights, tile=T,
                            metadata={**META, "transform": {"type": "clamped", "mu_y": 0.3}})
    rep = evaluate(flat_model, root, sweep=False)
    row = rep.row("quality", "model")
    assert row["n"] == 3 * 2 * 16 and np.isnan(row["r2"]) and np.isnan(row["spearman"]) and row["mae"] > 0
    assert json.loads(json.dumps(rep.to_dict(), allow_nan=False))["quality"][0]["r2"] is None
    line = next(x for x in rep.table().splitlines() if x.split()[:3] == ["f", "all", "model"])
    assert line.split()[4] == "-", line
    (why,) = [n for n in rep.notes if n.startswith("R² % reads '-'")]
    assert "targets are all one value" in why and "f/all/model" in why and why in rep.to_markdown()
    assert any(n.startswith("Spearman reads '-'") for n in rep.notes)


def test_targets_of_another_weber_l_than_the_models_are_said(dataset: Path, model: Path, tmp_path: Path,
                                                             caplog: pytest.LogCaptureFixture) -> None:
    """A JNYang model trained at l = 1e-10 judged against the dataset's l = 0.02 targets (another quantity: the
    published models' against `rtp targets`' default) was scored in silence; the run now warns, and the report's
    first note says so and what to run. Targets at the model's own l say nothing."""
    low = build_onnx(tmp_path / "low.onnx", weights=np.eye(2, 4, dtype=np.float32), tile=T,
                     metadata={**META, "weber_l": 1e-10})
    with caplog.at_level("WARNING", logger="rtp.evaluate"):
        rep = evaluate(low, dataset, baselines=False, sweep=False)
    words = "the model predicts jnyang at environment luminance l = 1e-10, and the targets it is judged against " \
            "were computed at l = 0.02"
    assert rep.notes[0].startswith(words) and "--metrics jnyang --weber-l 1e-10`" in rep.notes[0]
    assert words in caplog.text and words in rep.to_markdown()
    caplog.clear()
    with caplog.at_level("WARNING", logger="rtp.evaluate"):
        rep = evaluate(model, dataset, baselines=False, sweep=False)
    assert "environment luminance" not in caplog.text and not any("environment luminance" in n for n in rep.notes)


def test_the_rate_overlays_of_many_methods_wrap_to_rows_of_three(monkeypatch: pytest.MonkeyPatch) -> None:
    """The evaluation's six methods were drawn in one row, a 3860-pixel strip whose titles could not be read at a
    page's width: three panels a row at most, every method's panel drawn (titled), the empty places bare."""
    figures: list[Any] = []
    real = plots.figure_image
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or real(fig))
    codes = np.zeros((3, 4), np.uint8)
    img = np.zeros((40, 60, 3), np.float32)
    plots.rate_overlays(img, {"a": codes}, 16)
    three = plots.rate_overlays(img, {f"m{i}": codes for i in range(3)}, 16)
    six = plots.rate_overlays(img, {f"m{i}": codes for i in range(6)}, 16)
    five = plots.rate_overlays(img, {f"m{i}": codes for i in range(5)}, 16)
    assert six.shape[1] == three.shape[1] == five.shape[1] and six.shape[0] > three.shape[0]
    titled = [[ax.get_title() for ax in fig.axes if ax.get_title()] for fig in figures]
    assert titled[2] == [f"m{i}: saves 0%" for i in range(6)] and len(titled[3]) == 5
    assert [ax.axison for ax in figures[3].axes].count(False) == 1  # (the sixth place, empty)


def test_every_models_lacking_targets_are_named_in_one_error_with_one_command(
        dataset: Path, model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp evaluate flip psnr --data D` where neither metric has targets named flip's only (`rtp targets D --metrics
    flip`): psnr's lack came out on the next try. Every model is checked before any work now, and one error names
    every lacking metric with the one command (its path shell-quoted) that computes them all."""
    import shlex
    import shutil

    from rtp.capture import TargetError
    from rtp.evaluate import check_evaluation

    data = tmp_path / "my data"  # (a space: the printed command quotes it)
    shutil.copytree(dataset, data)
    command = f"run `rtp targets {shlex.quote(str(data))} --metrics flip,psnr`"
    assert rtp_main(["evaluate", "flip", "psnr", "--data", str(data)]) == 2
    shown = capsys.readouterr()
    assert shown.out == ""
    assert f"{data} lacks the targets of 2 metrics: no flip targets; no psnr targets (it has jnyang); {command}" \
        in shown.err, shown.err
    # the library's check of several models likewise; a metric lacking on some samples and one lacking altogether
    # in one error, one model of each metric named once (two models of one metric)
    TargetStore(data).path("s2", "jnyang").unlink()
    with pytest.raises(TargetError) as err:
        check_evaluation([model, "psnr", "psnr-8px", model], data)
    assert str(err.value) == (f"{data} lacks the targets of 2 metrics: 1 of the 3 samples to evaluate have no jnyang "
                              f"targets ('s2'); no psnr targets (it has jnyang); run `rtp targets "
                              f"{shlex.quote(str(data))} --metrics jnyang,psnr`")
    # one model's lack reads as it did
    with pytest.raises(TargetError, match=r"has no psnr targets \(it has jnyang\); run `rtp targets '.*' --metrics "
                                          r"psnr`$"):
        check_evaluation("psnr", data)
    with pytest.raises(sdk.ParameterError, match="model: expected a model or a list"):
        check_evaluation([], data)


def test_a_hardware_tile_not_of_the_targets_base_tile_is_named_as_the_option_gave_it(
        dataset: Path, model: Path) -> None:
    """`rtp evaluate --tile-size 4` on targets of an 8-pixel base tile said "the model's tile 4 is not a multiple of
    the targets' base tile 8": the model's tile is 16; 4 is the hardware tile the option asked for. Worded by where
    the 4 came from now; the model's own tile still reads as the model's."""
    from rtp.capture import TargetError

    manifest = dataset / "targets" / "manifest.json"
    manifest.write_text(json.dumps({**json.loads(manifest.read_text()), "base_tile": 8}))
    with pytest.raises(TargetError) as err:
        evaluate(model, dataset, tile_size=4, baselines=False, sweep=False)
    text = str(err.value)
    assert text.startswith("the hardware tile 4 asked for (tile_size, `rtp evaluate --tile-size`) is not a multiple "
                           "of the targets' base tile 8") and "model's tile 4" not in text, text
    assert text.endswith("evaluate on a multiple of 8 (the model's own 16 is one)"), text
    manifest.write_text(json.dumps({**json.loads(manifest.read_text()), "base_tile": 32}))
    with pytest.raises(TargetError, match=r"^the model's tile 16 is not a multiple of the targets' base tile 32 in "):
        evaluate(model, dataset, baselines=False, sweep=False)


def test_a_given_yang_that_shades_unseen_tiles_fully_is_scored_and_noted(dataset: Path, model: Path) -> None:
    """evaluate(yang=Yang2019(unseen="full")) reported no Yang quality rows and no Yang notes (both looked for the
    name 'yang2019', which only the unseen="as_is" variant carries), and no 'yang2019' decisions. The variants
    follow their kind now: given either, the other is built from its parameters, so the report is the one the
    other variant gives; a Yang2019 of another name is scored under its name; anything else is refused."""
    kw: dict[str, Any] = {"threshold": 0.25, "motion": False, "unseen_fraction": 0.3}
    full = evaluate(model, dataset, yang=Yang2019(T, unseen="full", **kw), sweep=False)
    as_is = evaluate(model, dataset, yang=Yang2019(T, **kw), sweep=False)
    assert {r["method"] for r in full.quality} == {"model", "model (no safety)", "yang2019"}
    assert full.to_dict() == as_is.to_dict()  # (rows, notes, baselines: NaN as null)
    assert any("more than 30% unseen at 1x1" in n for n in full.notes)

    class NAS(Yang2019):
        name = "nas"

    nas = evaluate(model, dataset, yang=NAS(T, **kw), sweep=False)
    scored = [{**r, "method": "yang2019"} for r in nas.to_dict()["quality"] if r["method"] == "nas"]
    assert scored and scored == [r for r in as_is.to_dict()["quality"] if r["method"] == "yang2019"]
    assert any("'yang2019-unseen-1x1' instead shades tiles" in n for n in nas.notes)
    with pytest.raises(sdk.ParameterError, match=r"yang: expected None \(the default\) or a Yang2019, got 'fast'"):
        evaluate(model, dataset, yang="fast")  # type: ignore[arg-type]
