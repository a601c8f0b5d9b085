"""Properties of tiles and per-tile targets (docs/runtime.md's ``tile_size``, docs/metrics.md's "Pooling and edge
tiles", docs/dataset.md's stored targets are the specification), checked with hypothesis on small random frames
(1x1 to 50x70 pixels), tiles of 1 to 32 pixels and random per-tile values (infinities and zeros where allowed):
the grid is ceil division, pooling is associative (the max, the min, the mean weighted by the pixels a partial
edge tile covers, PSNR through its MSE), splitting undoes pooling, the stored base-tile targets read at a coarser
tile are the targets computed at that tile (to the bit, or a unit in the last place where mean-pooled), and a
predictor loaded for the hardware's tiles gives the worst of the model tiles a hardware tile covers (coarser) or
its model tile's values (finer) for every size it takes. Pooling past one axis's length pads no more than its last
tile (a regression test)."""

from __future__ import annotations

import atexit
import functools
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rtp import metrics, sdk
from rtp.capture import TargetStore, pool_targets
from rtp.sdk import PREDICTED_RATES

from .conftest import base_metadata, build_onnx

_DIR = Path(tempfile.mkdtemp(prefix="rtp-tile-properties-"))  # (the tiny models, built once per session)
atexit.register(shutil.rmtree, _DIR, True)
#: few examples each, so that the full suite stays fast (hypothesis draws new ones every run); a few hundred
#: with RTP_PROPERTY_EXAMPLES=300
FAST = settings(max_examples=int(os.environ.get("RTP_PROPERTY_EXAMPLES", "40")), deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

sizes = st.tuples(st.integers(1, 50), st.integers(1, 70))
tiles = st.integers(1, 32)
powers = st.sampled_from(sdk.TILE_SIZES)
seeds = st.integers(0, 2**32 - 1)


def _values(rng: np.random.Generator, shape: tuple[int, ...], special: bool) -> np.ndarray:
    """Random float32 per-tile values, with some zeros and infinities of both signs where ``special``."""
    v = rng.normal(size=shape).astype(np.float32)
    if special:
        pick = rng.random(shape)
        v[pick < 0.1] = 0.0
        v[(pick >= 0.1) & (pick < 0.15)] = np.inf
        v[(pick >= 0.15) & (pick < 0.2)] = -np.inf
    return v


def _reference_pool(values: np.ndarray, weights: np.ndarray, f: int, reduce: str) -> np.ndarray:
    """The coarse tiles of ``values`` ``(th, tw)`` (tile ``i, j`` of weight ``weights[i, j]``), a loop."""
    th, tw = values.shape
    out = np.empty((-(-th // f), -(-tw // f)), np.float64)
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            block = values[i * f:(i + 1) * f, j * f:(j + 1) * f].astype(np.float64)
            wts = weights[i * f:(i + 1) * f, j * f:(j + 1) * f]
            out[i, j] = (block.max() if reduce == "max" else block.min() if reduce == "min"
                         else (block * wts).sum() / wts.sum())
    return out


# -- the grid -------------------------------------------------------------------------------------------------

@FAST
@given(size=sizes, tile=tiles)
def test_the_grid_is_ceil_division_and_its_extents_are_the_real_pixels(size: tuple[int, int], tile: int) -> None:
    """``tile_grid`` is ``ceil(H / w) x ceil(W / w)``, ``padded_size`` the grid times the tile (the least whole
    tiles holding the frame), and ``tile_extents`` the pixels each tile covers: the tile's size but for a partial
    last one, all positive, summing to the length; the metrics room's pooling gives that grid."""
    h, w = size
    th, tw = sdk.tile_grid(h, w, tile)
    assert (th, tw) == (int(np.ceil(h / tile)), int(np.ceil(w / tile)))
    ph, pw = sdk.padded_size(h, w, tile)
    assert (ph, pw) == (th * tile, tw * tile) and h <= ph < h + tile and w <= pw < w + tile
    for n, count in ((h, th), (w, tw)):
        ext = sdk.tile_extents(n, tile)
        assert ext.shape == (count,) and ext.sum() == n and ext.min() >= 1 and (ext[:-1] == tile).all()
    assert metrics.pool_tiles(np.zeros((h, w), np.float32), tile).shape == (th, tw)


# -- the SDK's pooling and splitting ----------------------------------------------------------------------------

@FAST
@given(grid=sizes, a=st.integers(1, 8), b=st.integers(1, 8), better=st.booleans(), special=st.booleans(),
       seed=seeds)
def test_pooling_per_tile_values_is_associative(grid: tuple[int, int], a: int, b: int, better: bool, special: bool,
                                                seed: int) -> None:
    """``sdk.pool_tiles`` by ``a`` then ``b`` is pooling by ``a * b`` (8 -> 16 -> 32 is 8 -> 32): the worst of
    the fine tiles each coarse one covers, the partial last row and column pooling the tiles they have."""
    v = _values(np.random.default_rng(seed), grid, special)
    once = sdk.pool_tiles(v, a * b, higher_is_better=better)
    np.testing.assert_array_equal(sdk.pool_tiles(sdk.pool_tiles(v, a, higher_is_better=better), b,
                                                 higher_is_better=better), once)
    ref = _reference_pool(v, np.ones(grid), a * b, "min" if better else "max")
    np.testing.assert_array_equal(once, ref.astype(np.float32))


@FAST
@given(size=sizes, coarse=powers, fine=powers, special=st.booleans(), better=st.booleans(), seed=seeds)
def test_splitting_then_pooling_is_the_identity_and_pooling_then_splitting_gives_each_tile_its_coarse_value(
        size: tuple[int, int], coarse: int, fine: int, special: bool, better: bool, seed: int) -> None:
    """On a frame's grids of two tile sizes: ``split_tiles`` of coarse values onto the frame's fine grid, pooled
    back, is those values (every coarse tile keeps at least one fine tile of the frame); pooling fine values then
    splitting them gives each fine tile its coarse tile's value, never better than its own."""
    if coarse < fine:
        coarse, fine = fine, coarse
    f = coarse // fine
    h, w = size
    rng = np.random.default_rng(seed)
    cg, fg = sdk.tile_grid(h, w, coarse), sdk.tile_grid(h, w, fine)
    v = _values(rng, (2, *cg), special)
    split = sdk.split_tiles(v, f, fg)
    assert split.shape == (2, *fg)
    np.testing.assert_array_equal(sdk.pool_tiles(split, f, higher_is_better=better), v)
    u = _values(rng, (2, *fg), special)
    pooled = sdk.pool_tiles(u, f, higher_is_better=better)
    assert pooled.shape == (2, *cg)
    back = sdk.split_tiles(pooled, f, fg)
    rows, cols = np.indices(fg)
    np.testing.assert_array_equal(back, pooled[:, rows // f, cols // f])
    assert ((back <= u) if better else (back >= u)).all()


# -- the metrics room's pooling of maps -------------------------------------------------------------------------

@FAST
@given(size=sizes, base=st.integers(1, 8), k=st.integers(1, 6), j=st.integers(1, 4), special=st.booleans(),
       seed=seeds)
def test_pooling_a_map_is_associative_with_partial_tiles_weighted_by_their_pixels(
        size: tuple[int, int], base: int, k: int, j: int, special: bool, seed: int) -> None:
    """A map pooled over ``base`` pixels, then its tiles pooled ``k`` and ``j`` times coarser (``pool_targets``:
    the max; the mean weighted by the pixels each partial edge tile covers) is the map pooled at ``base * k *
    j`` directly, as docs/dataset.md says of the stored targets: to the bit for the max, to round-off for the
    mean. The max of the base tiles pooled by the SDK is the same."""
    h, w = size
    rng = np.random.default_rng(seed)
    m = rng.random((2, h, w), dtype=np.float32) * 3
    if special:
        m[rng.random((2, h, w)) < 0.1] = 0.0
    t1, t2, t3 = base, base * k, base * k * j
    for reduce, mse in (("max", False), ("mean", True)):
        fine = metrics.pool_tiles(m, t1, reduce)
        direct = metrics.pool_tiles(m, t3, reduce)
        once = pool_targets(fine, (h, w), t1, t3, mse=mse)
        twice = pool_targets(pool_targets(fine, (h, w), t1, t2, mse=mse), (h, w), t2, t3, mse=mse)
        if reduce == "max":
            np.testing.assert_array_equal(once, direct)
            np.testing.assert_array_equal(twice, direct)
            np.testing.assert_array_equal(sdk.pool_tiles(fine, k * j), direct)
        else:
            np.testing.assert_allclose(once, direct, rtol=2e-6, atol=1e-7)
            np.testing.assert_allclose(twice, direct, rtol=4e-6, atol=1e-7)
            ext = np.outer(sdk.tile_extents(h, t1), sdk.tile_extents(w, t1))
            np.testing.assert_allclose(once[0], _reference_pool(fine[0], ext, k * j, "mean"), rtol=2e-6, atol=1e-7)


@FAST
@given(size=sizes, base=st.integers(1, 8), k=st.integers(1, 6), seed=seeds)
def test_max_pooled_tiles_never_decrease_when_pooled_coarser(size: tuple[int, int], base: int, k: int,
                                                              seed: int) -> None:
    """Every pixel's coarse tile is at least its fine tile, for the max-pooled targets read coarser."""
    h, w = size
    m = np.random.default_rng(seed).random((h, w), dtype=np.float32)
    fine = metrics.pool_tiles(m, base)
    coarse = pool_targets(fine, (h, w), base, base * k, mse=False)
    rows, cols = np.indices(fine.shape)
    assert (coarse[rows // k, cols // k] >= fine).all()
    assert (metrics.pool_tiles(m, base) >= m[::base, ::base]).all()


@FAST
@given(size=sizes, a=st.integers(1, 8), b=st.integers(1, 6), batch=st.booleans(), seed=seeds)
def test_a_metric_s_tiles_pooled_coarser_are_its_tiles_at_the_coarser_size(size: tuple[int, int], a: int, b: int,
                                                                           batch: bool, seed: int) -> None:
    """``tile_metric`` of a max-pooled metric at ``a`` pixels, pooled ``b`` times coarser, is ``tile_metric`` at
    ``a * b`` to the bit, and is ``pool_tiles`` of its ``error_map``; PSNR's, through its MSE, to float32
    round-off; a batch of frames is each frame's, and torch tensors give numpy's values."""
    h, w = size
    rng = np.random.default_rng(seed)
    lead = (2,) if batch else ()
    ref = rng.random((*lead, h, w, 3), dtype=np.float32)
    test = np.clip(ref + (rng.random((*lead, h, w, 3), dtype=np.float32) - 0.5) * 0.2, 0, 1)
    keep = rng.random((*lead, h, w)) < 0.3  # (some pixels equal: tiles of PSNR +inf)
    test[keep] = ref[keep]
    for m in ("yang", "jnyang"):
        fine, coarse = metrics.tile_metric(m, ref, test, a), metrics.tile_metric(m, ref, test, a * b)
        assert coarse.shape == (*lead, *sdk.tile_grid(h, w, a * b))
        np.testing.assert_array_equal(sdk.pool_tiles(fine, b), coarse)
        np.testing.assert_array_equal(metrics.pool_tiles(metrics.error_map(m, ref, test), a * b), coarse)
        if batch:
            np.testing.assert_array_equal(coarse[1], metrics.tile_metric(m, ref[1], test[1], a * b))
    fine, coarse = metrics.tile_metric("psnr", ref, test, a), metrics.tile_metric("psnr", ref, test, a * b)
    pooled = sdk.psnr_from_mse(pool_targets(sdk.mse_from_psnr(fine), (h, w), a, a * b, mse=True))
    assert (np.isposinf(pooled) == np.isposinf(coarse)).all()
    np.testing.assert_allclose(pooled[np.isfinite(coarse)], coarse[np.isfinite(coarse)], rtol=1e-6)
    torch = pytest.importorskip("torch")
    planar = {k: torch.from_numpy(np.moveaxis(v, -1, -3).copy()) for k, v in (("ref", ref), ("test", test))}
    for m in ("yang", "psnr"):  # (a tensor is ((N,) 3, H, W))
        got = metrics.tile_metric(m, planar["ref"], planar["test"], a * b)
        assert isinstance(got, torch.Tensor)
        np.testing.assert_array_equal(got.numpy(), metrics.tile_metric(m, ref, test, a * b))


def test_pooling_past_an_axis_s_length_pads_no_more_than_the_last_tile() -> None:
    """A tile (or factor) past one axis's length but not the other's pooled the short axis whole by padding it to
    the long one's size: a 1x3000 map pooled by 3000 made 3000x3000 values (36 MB, 72 for the mean; a 4x12000
    frame's base tiles read at 12000 pixels 936 MB), a panorama strip's far more (MemoryError). Each axis is now
    clamped to its own length; the values are those of a loop."""
    import tracemalloc

    rng = np.random.default_rng(5)
    strip = rng.random((1, 3000), dtype=np.float32)
    base = rng.random((6, 1, 3000), dtype=np.float32)
    calls = [(lambda: metrics.pool_tiles(strip, 3000), strip.max()),
             (lambda: metrics.pool_tiles(strip, 3000, "mean"), strip.astype(np.float64).mean()),
             (lambda: sdk.pool_tiles(strip, 3000), strip.max()),
             (lambda: sdk.pool_tiles(strip, 3000, higher_is_better=True), strip.min()),
             (lambda: pool_targets(base, (4, 12000), 4, 12000, mse=False), base.max(axis=(1, 2))),
             (lambda: pool_targets(base, (4, 12000), 4, 12000, mse=True), base.astype(np.float64).mean(axis=(1, 2)))]
    for call, expected in calls:
        tracemalloc.start()
        try:
            got = call()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 2_000_000, peak  # (the input is 12 kB, and 72 kB for the six rates)
        np.testing.assert_allclose(np.ravel(got), np.ravel(expected), rtol=1e-6)


# -- PSNR and MSE ---------------------------------------------------------------------------------------------

@FAST
@given(mse=st.lists(st.floats(0.0, 1e6, allow_subnormal=False) | st.just(0.0), min_size=1, max_size=20))
def test_psnr_and_mse_round_trip(mse: list[float]) -> None:
    """``psnr_from_mse`` is ``-10 log10(mse)`` in float32: ``+inf`` of 0, 0 of 1 (never ``-0``); ``mse_from_psnr``
    is its inverse, 0 of ``+inf``, to float32 round-off of the PSNR."""
    m = np.array(mse, np.float64)
    p = sdk.psnr_from_mse(m)
    assert p.dtype == np.float32
    assert (np.isposinf(p) == (m == 0)).all()
    assert not np.signbit(sdk.psnr_from_mse([1.0])).any() and sdk.psnr_from_mse([1.0])[0] == 0
    back = sdk.mse_from_psnr(p)
    assert back.dtype == np.float64 and (back[m == 0] == 0).all()
    # a float32 PSNR is within half an ulp of the true one; 10**(-p/10) turns that into a relative error of MSE
    tol = np.log(10) / 10 * np.abs(p[m > 0].astype(np.float64)) * 2.0**-23 + 1e-12
    np.testing.assert_array_less(np.abs(back[m > 0] / m[m > 0] - 1), tol)


@FAST
@given(size=sizes, base=st.sampled_from([1, 2, 4]), k=st.integers(1, 8), same=st.floats(0, 1), seed=seeds)
def test_psnr_pooled_through_its_mse_is_the_psnr_of_the_coarser_tile(size: tuple[int, int], base: int, k: int,
                                                                     same: float, seed: int) -> None:
    """Fine-tile PSNR turned to MSE, pooled by the pixel-weighted mean and turned back, is the coarse tile's PSNR
    (``+inf`` exactly where the whole coarse tile is identical) to float32 round-off."""
    h, w = size
    rng = np.random.default_rng(seed)
    ref = rng.random((h, w, 3), dtype=np.float32)
    test = ref + (rng.random((h, w, 3), dtype=np.float32) - 0.5) * 0.1
    keep = rng.random((h, w)) < same
    test[keep] = ref[keep]
    test = np.clip(test, 0, 1)
    fine = metrics.psnr_tiles(ref, test, base)
    direct = metrics.psnr_tiles(ref, test, base * k)
    pooled = sdk.psnr_from_mse(pool_targets(sdk.mse_from_psnr(fine), (h, w), base, base * k, mse=True))
    assert (np.isposinf(pooled) == np.isposinf(direct)).all()
    finite = np.isfinite(direct)
    np.testing.assert_allclose(pooled[finite], direct[finite], rtol=1e-6, atol=1e-5)


# -- stored targets at a coarser tile ---------------------------------------------------------------------------

class _Sample:
    """What ``sample_targets`` reads of a sample: each rate's final frame."""

    def __init__(self, frames: dict[str, np.ndarray]) -> None:
        self.frames = frames

    def final(self, rate: str) -> np.ndarray:
        return self.frames[rate]


def _absdiff(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
    return np.abs(reference - test).mean(axis=-1)


@pytest.fixture
def plugins(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two metrics of one's own, the same map mean-pooled and max-pooled, known to this test alone."""
    from rtp.metrics import _plugins

    monkeypatch.setattr(_plugins, "_registered", {})
    monkeypatch.setattr(_plugins, "_broken", {})
    monkeypatch.setattr(_plugins, "_explicit", set())
    for name, pooling in (("meandiff", "mean"), ("maxdiff", "max")):
        metrics.register_metric(metrics.Metric(name, _absdiff, 0.05, pooling=pooling))  # type: ignore[arg-type]


@FAST
@given(size=sizes, base=st.sampled_from([4, 4, 1, 2, 8]), k=st.sampled_from([1, 2, 3, 4, 8]),
       same=st.sampled_from([0.0, 0.5, 1.0]), amplitude=st.sampled_from([0.2, 0.002]), seed=seeds)
def test_stored_targets_read_at_a_coarser_tile_are_the_targets_computed_there(
        plugins: None, tmp_path_factory: pytest.TempPathFactory, size: tuple[int, int], base: int, k: int,
        same: float, amplitude: float, seed: int) -> None:
    """docs/dataset.md: the stored base-tile targets (4 pixels as ``rtp targets`` stores them, or another base)
    read at ``k`` times the base are what computing the metric at that
    tile gives, to the bit for the max-pooled metrics (Yang, JNYang, a plugin's) and to a unit in the last place
    for PSNR (``+inf`` exactly where the tile is identical) and a mean-pooled plugin metric, partial edge tiles
    pooled over the pixels they hold."""
    from rtp.capture._targets import sample_targets

    h, w = size
    rng = np.random.default_rng(seed)
    ref = rng.random((h, w, 3), dtype=np.float32)
    frames = {"1x1": ref}
    for rate in PREDICTED_RATES:
        img = np.clip(ref + (rng.random((h, w, 3), dtype=np.float32) - 0.5) * amplitude, 0, 1)
        keep = rng.random((h, w)) < same
        img[keep] = ref[keep]
        frames[rate] = img
    names = ("psnr", "yang", "jnyang", "meandiff", "maxdiff")
    params = {"ppd": 67.0, "weber_l": 0.02}
    root = tmp_path_factory.mktemp("ds")
    store = TargetStore(root, base_tile=base)
    for m, v in sample_targets(_Sample(frames), names, params, store.base_tile).items():
        store.declare(m, {"weber_l": 0.02} if m == "jnyang" else {"pooling": metrics.metric_info(m).pooling}
                      if m not in sdk.METRICS else {})
        store.write("s", m, v, (h, w))
    tile = base * k
    direct = metrics.tile_targets(ref, {r: frames[r] for r in PREDICTED_RATES}, names, tile)
    for m in names:
        got = TargetStore(root).load("s", m, tile)  # (the base tile as the manifest records it)
        assert got.shape == (6, *sdk.tile_grid(h, w, tile)) and got.dtype == np.float32, m
        if m in ("psnr", "meandiff"):
            assert (np.isposinf(got) == np.isposinf(direct[m])).all(), m
            finite = np.isfinite(direct[m])
            np.testing.assert_array_max_ulp(got[finite], direct[m][finite], maxulp=1)
        else:
            np.testing.assert_array_equal(got, direct[m], err_msg=m)


# -- the predictor on hardware tiles ----------------------------------------------------------------------------

@functools.cache
def _model(tile: int, psnr: bool, partial: bool) -> Path:
    """A tiny model of ``tile``-pixel tiles (an error metric, or PSNR's); ``partial``: one that takes a partial
    last tile itself (``input_multiple``: the frame is padded to 4 pixels, or its tile where that is less)."""
    extra = {"input_multiple": min(4, tile)} if partial else {}
    meta = (base_metadata(metric="psnr", weber_l=None, transform={"type": "clamped", "mu_y": 38.0},
                          default_threshold=35.0, tile_size=tile, **extra) if psnr
            else base_metadata(tile_size=tile, **extra))
    weights = np.random.default_rng(tile).normal(size=(4, len(meta["inputs"]))).astype(np.float32)
    return build_onnx(_DIR / f"tiny{tile}{'psnr' if psnr else ''}{'partial' if partial else ''}.onnx",
                      weights=weights, tile=tile, metadata=meta, ceil_mode=partial)


@functools.cache
def _predictor(tile: int, psnr: bool, partial: bool, hardware: int | None) -> sdk.ShadingRatePredictor:
    return sdk.load(_model(tile, psnr, partial), tile_size=hardware)


@FAST
@given(size=sizes, model=st.sampled_from(sdk.TILE_SIZES), hardware=st.sampled_from(sdk.TILE_SIZES),
       psnr=st.booleans(), partial=st.booleans(), saving=st.sampled_from([0.0, 0.3, 0.6, 0.9]), seed=seeds)
def test_the_predictor_on_hardware_tiles_pools_the_worst_and_splits_its_model_tiles(
        size: tuple[int, int], model: int, hardware: int, psnr: bool, partial: bool, saving: float, seed: int) -> None:
    """Every hardware tile size each model tile size runs on (``hardware_tiles``; any other is refused), on models
    that take whole or partial tiles: coarser, each hardware tile's estimate is the worst of the model tiles it
    covers (max of an error, min of PSNR); finer, its model tile's, and so its rate, at a threshold and at a
    budget (which weighs each tile by its pixels: the same shares of the frame); the grid is the frame's at the
    hardware tile, and the rates are those of the pooled or split estimates."""
    if hardware not in sdk.hardware_tiles(model):
        with pytest.raises(sdk.ParameterError, match="tile_size"):
            sdk.load(_model(model, psnr, partial), tile_size=hardware)
        return
    own, hw = _predictor(model, psnr, partial, None), _predictor(model, psnr, partial, hardware)
    h, w = size
    x = np.random.default_rng(seed).random((len(own.metadata.inputs), h, w), dtype=np.float32)
    est, mine = own.predict(x), hw.predict(x)
    grid = sdk.tile_grid(h, w, hardware)
    assert hw.tile_size == hardware and hw.tiles(h, w) == grid and mine.shape == (6, *grid)
    rows, cols = np.indices(grid)
    if hardware <= model:
        f = model // hardware
        np.testing.assert_array_equal(mine, est[:, rows // f, cols // f])
    else:
        f = hardware // model
        ref = np.stack([_reference_pool(e, np.ones(e.shape), f, "min" if psnr else "max") for e in est])
        np.testing.assert_array_equal(mine, ref.astype(np.float32))
        cover = mine[:, np.arange(est.shape[1])[:, None] // f, np.arange(est.shape[2]) // f]
        assert ((cover <= est) if psnr else (cover >= est)).all()
    meta = hw.metadata
    rates = hw.shading_rates(x)
    np.testing.assert_array_equal(rates, sdk.select_rates(mine, meta.default_threshold,
                                                          higher_is_better=meta.higher_is_better,
                                                          factors=meta.rate_factors))
    if hardware <= model:  # (finer: each hardware tile takes its model tile's rate, at a threshold and a budget)
        f = model // hardware
        np.testing.assert_array_equal(rates, own.shading_rates(x)[rows // f, cols // f])
        np.testing.assert_array_equal(hw.shading_rates(x, saving=saving),
                                      own.shading_rates(x, saving=saving)[rows // f, cols // f])
