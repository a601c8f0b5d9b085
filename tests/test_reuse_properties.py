"""Properties of ``sdk.PredictionReuse`` (docs/runtime.md's section is the specification), checked with hypothesis
over tiny real models (a 1x1 convolution, a max over each tile, a sigmoid: tests/conftest.py's ``build_onnx``) and
random frames of any size, tile, interval and option: what the network gives where it runs, what a still camera
carries, which tiles go to 1x1, where the network runs, what a cut, a new size, sky and bad input do."""

from __future__ import annotations

import atexit
import copy
import functools
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rtp import sdk
from rtp.sdk._rates import RATE_NAMES, rate_size

from .conftest import base_metadata, build_onnx

_DIR = Path(tempfile.mkdtemp(prefix="rtp-reuse-properties-"))  # (the tiny models, built once per session)
atexit.register(shutil.rmtree, _DIR, True)
#: few examples each, so that the full suite stays fast (hypothesis draws new ones every run); a few hundred
#: with RTP_PROPERTY_EXAMPLES=300
FAST = settings(max_examples=int(os.environ.get("RTP_PROPERTY_EXAMPLES", "25")), deadline=None,
                suppress_health_check=[HealthCheck.too_slow])


@functools.cache
def _model(tile: int, psnr: bool = False) -> sdk.ShadingRatePredictor:
    """A tiny model of ``tile``-pixel tiles (an error metric, or PSNR's, better when higher) whose estimates differ
    from tile to tile on random inputs."""
    meta = (base_metadata(metric="psnr", weber_l=None, transform={"type": "clamped", "mu_y": 38.0},
                          default_threshold=35.0, tile_size=tile) if psnr else base_metadata(tile_size=tile))
    weights = np.random.default_rng(tile).normal(size=(4, len(meta["inputs"]))).astype(np.float32)
    return sdk.load(build_onnx(_DIR / f"tiny{tile}{'psnr' if psnr else ''}.onnx", weights=weights, tile=tile,
                               metadata=meta))


def _frame(pred: sdk.ShadingRatePredictor, h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    return rng.random((len(pred.metadata.inputs), h, w), dtype=np.float32)


def _grid(pred: sdk.ShadingRatePredictor, h: int, w: int) -> tuple[int, int]:
    t = pred.metadata.tile_size
    return -(-h // t), -(-w // t)


def _area(rates: np.ndarray) -> np.ndarray:
    """Pixels per shading sample of each code (1 for 1x1, 16 for 4x4)."""
    lut = np.zeros(256, np.int64)
    for code, name in RATE_NAMES.items():
        a, b = rate_size(name)
        lut[code] = a * b
    return lut[rates]


def _random_fetch(rng: np.random.Generator, h: int, w: int, ph: int, pw: int, reach: int = 3) -> tuple[np.ndarray, ...]:
    """Each pixel fetches a pixel of the previous ``ph x pw`` frame near its own place on the screen."""
    rows, cols = np.indices((h, w))
    rows, cols = ((2 * rows + 1) * ph) // (2 * h), ((2 * cols + 1) * pw) // (2 * w)
    return (np.clip(rows + rng.integers(-reach, reach + 1, (h, w)), 0, ph - 1),
            np.clip(cols + rng.integers(-reach, reach + 1, (h, w)), 0, pw - 1))


sizes = st.tuples(st.integers(1, 50), st.integers(1, 70))
tiles = st.sampled_from([1, 2, 4, 8, 16, 32])
reductions = st.sampled_from(sorted(sdk.REUSE_REDUCTIONS))


def _step(tile: int, draw: int | None) -> int | None:
    """A divisor of the tile from a drawn number (None: the default step)."""
    if draw is None:
        return None
    divisors = [d for d in range(1, tile + 1) if tile % d == 0]
    return divisors[draw % len(divisors)]


@FAST
@given(size=sizes, tile=tiles, psnr=st.booleans(), reduce=reductions, unseen=st.sampled_from(["full", "fresh"]),
       frames=st.integers(1, 5), step=st.none() | st.integers(0, 5), seed=st.integers(0, 2**16),
       refresh=st.none() | st.sampled_from([0.0, 0.3]), fraction=st.sampled_from([0.0, 0.5, 0.9]))
def test_every_frame_is_the_network_s_with_an_interval_of_one(size: tuple[int, int], tile: int, psnr: bool, reduce: str,
                                                              unseen: str, frames: int, step: int | None, seed: int,
                                                              refresh: float | None, fraction: float) -> None:
    """``every=1`` (no history): the predictor's own estimates and rates on every frame, whatever fetch, seen and
    background come with it; the work is a whole run and the age 0 each time."""
    pred = _model(tile, psnr)
    h, w = size
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, 1, reduce=reduce, unseen=unseen, step=_step(tile, step), refresh=refresh,
                                unseen_fraction=fraction)
    for f in range(frames):
        x = _frame(pred, h, w, rng)
        fetch = _random_fetch(rng, h, w, h, w) if f else None
        seen = (rng.random((h, w)) > 0.5).astype(np.float32)
        sky = (rng.random((h, w)) > 0.7).astype(np.float32)
        np.testing.assert_array_equal(reuse.shading_rates(x, fetch, seen, sky), pred.shading_rates(x))
        assert reuse.work == 1.0 and reuse.age == 0


@FAST
@given(size=sizes, tile=tiles, psnr=st.booleans(), reduce=reductions, every=st.integers(2, 6),
       frames=st.integers(2, 13), step=st.none() | st.integers(0, 5), seed=st.integers(0, 2**16),
       unseen=st.sampled_from(["full", "fresh"]), scale=st.sampled_from([1.0, 0.5, 1.5]),
       refresh=st.none() | st.sampled_from([0.0, 0.3]), given_seen=st.booleans())
def test_a_still_camera_carries_the_network_s_estimates_and_runs_it_every_k_th_frame(
        size: tuple[int, int], tile: int, psnr: bool, reduce: str, every: int, frames: int, step: int | None,
        seed: int, unseen: str, scale: float, refresh: float | None, given_seen: bool) -> None:
    """Fetch each pixel from itself, all seen (or ``seen`` None): the network runs on frames 0, k, 2k, ... and
    only there (nothing is unseen, so neither ``refresh`` nor a fresh crop runs it early), each run gives the
    predictor's estimates of that frame, and the frames between carry the last run's unchanged, times
    ``carry_scale`` (error metrics), whatever the reduction, step, tile or frame size."""
    pred = _model(tile, psnr)
    scale = 1.0 if psnr else scale
    h, w = size
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, every, reduce=reduce, unseen=unseen, step=_step(tile, step),
                                carry_scale=scale, refresh=refresh)
    still = tuple(np.indices((h, w)))
    seen = np.ones((h, w), np.float32) if given_seen else None
    for f in range(frames):
        x = _frame(pred, h, w, rng)
        est = reuse.predict(x, still if f else None, seen)
        if f % every == 0:
            last = pred.predict(x)
            np.testing.assert_array_equal(est, last)
            assert reuse.work == 1.0 and reuse.age == 0, f
        else:
            np.testing.assert_allclose(est, last * np.float32(scale), rtol=1e-6, atol=0)
            assert reuse.work == 0.0 and reuse.age == f % every, f


def _unseen_share(unknown: np.ndarray, tile: int, step: int) -> np.ndarray:
    """Per tile, the share of its kept pixels inside the frame (one of every ``step`` per axis) that are unknown."""
    h, w = unknown.shape
    kept = unknown[::step, ::step].astype(np.float64)
    ys, xs = np.arange(0, h, step) // tile, np.arange(0, w, step) // tile
    th, tw = -(-h // tile), -(-w // tile)
    total, count = np.zeros((th, tw)), np.zeros((th, tw))
    np.add.at(total, (ys[:, None], xs[None, :]), kept)
    np.add.at(count, (ys[:, None], xs[None, :]), 1.0)
    return total / count


@FAST
@given(size=sizes, tile=tiles, psnr=st.booleans(), reduce=reductions, every=st.integers(2, 6),
       frames=st.integers(2, 8), step=st.none() | st.integers(0, 5), seed=st.integers(0, 2**16),
       fraction=st.sampled_from([0.0, 0.25, 0.5, 0.75, 0.95]), hole=st.floats(0.0, 0.6),
       refresh=st.none() | st.sampled_from([0.0, 0.1, 0.5]))
def test_tiles_unseen_since_the_run_go_to_one_by_one(size: tuple[int, int], tile: int, psnr: bool, reduce: str,
                                                     every: int, frames: int, step: int | None, seed: int,
                                                     fraction: float, hole: float, refresh: float | None) -> None:
    """A still camera whose ``seen`` drops pixels (0, a negative value or NaN: all unseen): a pixel unseen on any
    frame since the network ran stays unknown, a tile with more than ``unseen_fraction`` of its (kept) pixels
    unknown gets the worst value there is (1x1) and the others the run's estimates; with ``refresh`` the network
    runs as soon as more than that share of the tiles is unseen, and the interval restarts there."""
    pred = _model(tile, psnr)
    h, w = size
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, every, reduce=reduce, step=_step(tile, step), unseen_fraction=fraction,
                                refresh=refresh)
    s = reuse.step
    still = tuple(np.indices((h, w)))
    age: int | None = None
    last, unknown = np.empty(0, np.float32), np.zeros((h, w), bool)
    for f in range(frames):
        x = _frame(pred, h, w, rng)
        seen = np.where(rng.random((h, w)) < hole, rng.choice([0.0, -1.0, np.nan], (h, w)), 1.0).astype(np.float32)
        est = reuse.predict(x, still if f else None, seen)
        if age is not None and age + 1 < every:
            unknown |= ~(seen > 0)
            missing = _unseen_share(unknown, tile, s) > fraction
            if refresh is None or missing.mean() <= refresh:
                want = np.where(missing[None], np.float32(-np.inf if psnr else np.inf), last)
                np.testing.assert_allclose(est, want, rtol=1e-6, atol=0)
                assert reuse.work == 0.0 and reuse.age == age + 1
                age += 1
                continue
        last, unknown, age = pred.predict(x), np.zeros((h, w), bool), 0
        np.testing.assert_array_equal(est, last)
        assert reuse.work == 1.0 and reuse.age == 0


@FAST
@given(size=sizes, tile=tiles, psnr=st.booleans(), reduce=reductions, every=st.integers(1, 6),
       frames=st.integers(2, 10), step=st.none() | st.integers(0, 5), seed=st.integers(0, 2**16),
       unseen=st.sampled_from(["full", "fresh"]), history=st.sampled_from([0.0, 0.5]),
       scale=st.sampled_from([1.0, 1.25]), loosen=st.floats(1.01, 3.0))
def test_a_looser_threshold_never_gives_a_finer_rate(size: tuple[int, int], tile: int, psnr: bool, reduce: str,
                                                     every: int, frames: int, step: int | None, seed: int,
                                                     unseen: str, history: float, scale: float, loosen: float) -> None:
    """Two reuses given the same moving frames, one with a looser threshold: on every frame, carried or not, no
    tile's rate under the looser threshold is finer; where the network runs without history the rates are the
    predictor's own."""
    pred = _model(tile, psnr)
    meta = pred.metadata
    scale = 1.0 if psnr else scale
    h, w = size
    rng = np.random.default_rng(seed)
    kw: dict[str, Any] = {"reduce": reduce, "step": _step(tile, step), "unseen": unseen, "history": history,
                          "carry_scale": scale}
    strict, loose = sdk.PredictionReuse(pred, every, **kw), sdk.PredictionReuse(pred, every, **kw)
    thr = meta.default_threshold
    looser = thr - 20 * np.log10(loosen) if psnr else thr * loosen  # (PSNR: better when higher, so lower)
    for f in range(frames):
        x = _frame(pred, h, w, rng)
        fetch = _random_fetch(rng, h, w, h, w) if f else None
        seen = (rng.random((h, w)) > 0.2).astype(np.float32)
        a = strict.shading_rates(x, fetch, seen, threshold=thr)
        b = loose.shading_rates(x, fetch, seen, threshold=looser)
        assert (_area(b) >= _area(a)).all(), f
        assert strict.work == loose.work and strict.age == loose.age
        if strict.work == 1.0 and history == 0.0:
            np.testing.assert_array_equal(a, pred.shading_rates(x, threshold=thr))


@FAST
@given(size=sizes, tile=tiles, every=st.integers(1, 6), frames=st.integers(0, 6), seed=st.integers(0, 2**16),
       unseen=st.sampled_from(["full", "fresh"]), history=st.sampled_from([0.0, 0.5]))
def test_after_a_reset_the_next_frame_runs_the_network(size: tuple[int, int], tile: int, every: int, frames: int,
                                                       seed: int, unseen: str, history: float) -> None:
    """``reset()`` (a camera cut) forgets the carry wherever the interval is: the age is None, and the next frame,
    fetch or not, is the network's alone (no history blended in)."""
    pred = _model(tile)
    h, w = size
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, every, unseen=unseen, history=history)
    for f in range(frames):
        reuse.predict(_frame(pred, h, w, rng), _random_fetch(rng, h, w, h, w) if f else None)
    reuse.reset()
    assert reuse.age is None
    x = _frame(pred, h, w, rng)
    np.testing.assert_array_equal(reuse.predict(x, tuple(np.indices((h, w))), np.ones((h, w), np.float32)),
                                  pred.predict(x))
    assert reuse.work == 1.0 and reuse.age == 0


@FAST
@given(tile=tiles, psnr=st.booleans(), reduce=reductions, every=st.integers(2, 6),
       sizes_=st.lists(sizes, min_size=2, max_size=8), step=st.none() | st.integers(0, 5),
       seed=st.integers(0, 2**16), history=st.sampled_from([0.0, 0.5]), hole=st.sampled_from([0.0, 0.3]))
def test_frames_of_changing_size_are_carried_and_the_interval_holds(
        tile: int, psnr: bool, reduce: str, every: int, sizes_: list[tuple[int, int]], step: int | None, seed: int,
        history: float, hole: float) -> None:
    """Dynamic resolution: a size that changes on any frame, the fetch of each frame indexing the previous frame's
    pixels (``fetch_from_motion`` with ``prev_shape``): no error, estimates of each frame's own tile grid, no NaN,
    and the network still runs on frames 0, k, 2k, ... alone (``unseen="full"``, no ``refresh``)."""
    pred = _model(tile, psnr)
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, every, reduce=reduce, step=_step(tile, step), history=history)
    prev = None
    for f, (h, w) in enumerate(sizes_):
        x = _frame(pred, h, w, rng)
        fetch = None if prev is None else sdk.fetch_from_motion(rng.uniform(-3, 3, (h, w)), rng.uniform(-3, 3, (h, w)),
                                                                prev_shape=prev)
        seen = (rng.random((h, w)) >= hole).astype(np.float32)
        est = reuse.predict(x, fetch, seen)
        assert est.shape == (6, *_grid(pred, h, w)) and not np.isnan(est).any()
        assert reuse.age == f % every and reuse.work == float(f % every == 0)
        if f % every == 0 and history == 0.0:
            np.testing.assert_array_equal(est, pred.predict(x))
        prev = (h, w)


def _reduced(values: np.ndarray, tile_of: np.ndarray, h: int, w: int, tile: int, step: int, reduce: str,
             psnr: bool) -> np.ndarray:
    """A loop's reduction: per tile of an ``h x w`` frame, ``reduce`` over its kept pixels inside the frame of the
    estimates ``values[:, tile_of]`` (``tile_of``: per kept pixel, a column of ``values``)."""
    th, tw = -(-h // tile), -(-w // tile)
    out = np.empty((len(values), th, tw), np.float64)
    for ty in range(th):
        for tx in range(tw):
            ys = [y // step for y in range(ty * tile, min((ty + 1) * tile, h), step)]
            xs = [x // step for x in range(tx * tile, min((tx + 1) * tile, w), step)]
            v = values[:, tile_of[np.ix_(ys, xs)].ravel()].astype(np.float64)
            if reduce == "mean":
                out[:, ty, tx] = v.mean(axis=1)
            else:
                worse = np.sort(v if psnr else -v, axis=1)  # worst first
                at = 0 if reduce == "worst" else int(np.floor(0.25 * (v.shape[1] - 1)))
                out[:, ty, tx] = worse[:, at] if psnr else -worse[:, at]
    return out


@FAST
@given(size=sizes, tile=tiles, psnr=st.booleans(), reduce=reductions, every=st.integers(2, 6),
       step=st.none() | st.integers(0, 5), seed=st.integers(0, 2**16), later=st.none() | sizes)
def test_sky_keeps_the_estimate_at_its_own_screen_position(size: tuple[int, int], tile: int, psnr: bool, reduce: str,
                                                           every: int, step: int | None, seed: int,
                                                           later: tuple[int, int] | None) -> None:
    """A frame all background (sky) carries each pixel the estimate of the run's tile at its own place on the screen,
    whatever its fetch and seen say: at the run's size the run's estimates; at another size (``later``), per tile
    the reduction of the run's tiles under its kept pixels' centres."""
    pred = _model(tile, psnr)
    h, w = size
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, every, reduce=reduce, step=_step(tile, step))
    s = reuse.step
    run = reuse.predict(_frame(pred, h, w, rng))
    nh, nw = later or size
    x = _frame(pred, nh, nw, rng)
    fetch = _random_fetch(rng, nh, nw, h, w, reach=20)
    seen = (rng.random((nh, nw)) > 0.5).astype(np.float32)
    est = reuse.predict(x, fetch, seen, np.ones((nh, nw), np.float32))
    assert reuse.work == 0.0 and reuse.age == 1
    if (nh, nw) == (h, w):
        np.testing.assert_allclose(est, run, rtol=1e-6, atol=0)
        return
    ys, xs = np.arange(0, -(-nh // tile) * tile, s), np.arange(0, -(-nw // tile) * tile, s)
    py = np.minimum((2 * np.minimum(ys, nh - 1) + 1) * h // (2 * nh), h - 1)  # the pixel under each kept centre
    px = np.minimum((2 * np.minimum(xs, nw - 1) + 1) * w // (2 * nw), w - 1)
    tile_of = (py // tile)[:, None] * -(-w // tile) + (px // tile)[None, :]
    want = _reduced(run.reshape(6, -1), tile_of, nh, nw, tile, s, reduce, psnr)
    np.testing.assert_allclose(est, want, rtol=1e-6, atol=0)


@FAST
@given(size=sizes, tile=tiles, every=st.integers(2, 6), step=st.none() | st.integers(0, 5), seed=st.integers(0, 2**16),
       bad=st.sampled_from(["row", "col", "negative"]), where=st.floats(0, 1), unseen=st.sampled_from(["full", "fresh"]))
def test_a_fetch_out_of_the_previous_frame_is_refused_and_leaves_the_reuse_as_it_was(
        size: tuple[int, int], tile: int, every: int, step: int | None, seed: int, bad: str, where: float,
        unseen: str) -> None:
    """A fetch index outside the previous frame at a pixel the carry reads (a kept pixel, or the last row or
    column): a ``ParameterError`` naming the fetch, the age unchanged, and the same frame given right gives what a
    reuse that never saw the bad one gives."""
    pred = _model(tile)
    h, w = size
    rng = np.random.default_rng(seed)
    kw: dict[str, Any] = {"step": _step(tile, step), "unseen": unseen}
    reuse, clean = sdk.PredictionReuse(pred, every, **kw), sdk.PredictionReuse(pred, every, **kw)
    x = _frame(pred, h, w, rng)
    reuse.predict(x)
    clean.predict(x)
    s = reuse.step
    ys, xs = np.r_[np.arange(0, h, s), h - 1], np.r_[np.arange(0, w, s), w - 1]
    y, x_ = ys[int(where * (len(ys) - 1))], xs[int((1 - where) * (len(xs) - 1))]
    fetch = _random_fetch(rng, h, w, h, w)
    rows, cols = fetch[0].copy(), fetch[1].copy()
    if bad == "row":
        rows[y, x_] = h
    elif bad == "col":
        cols[y, x_] = w + 5
    else:
        (rows if where < 0.5 else cols)[y, x_] = -1
    seen = np.ones((h, w), np.float32)
    nxt = _frame(pred, h, w, rng)
    with pytest.raises(sdk.ParameterError, match="fetch (rows|cols): expected indices in") as err:
        reuse.predict(nxt, (rows, cols), seen)
    assert err.value.name == "fetch" and reuse.age == 0
    np.testing.assert_array_equal(reuse.predict(nxt, fetch, seen), clean.predict(nxt, fetch, seen))
    assert reuse.age == clean.age == 1 % every


@FAST
@given(size=sizes, tile=tiles, seed=st.integers(0, 2**16), frames=st.integers(2, 6),
       history=st.sampled_from([0.25, 0.5, 0.9]), hole=st.sampled_from([0.0, 0.5]), reduce=reductions)
def test_history_blends_the_network_with_what_a_still_camera_carried(size: tuple[int, int], tile: int, seed: int,
                                                                     frames: int, history: float, hole: float,
                                                                     reduce: str) -> None:
    """``every=1, history=h`` on a still camera: each frame is (1 - h) x the network's + h x the last frame's
    estimate, and the network's alone on a tile more than ``unseen_fraction`` unseen."""
    pred = _model(tile)
    h, w = size
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, 1, history=history, step=1, reduce=reduce)
    still = tuple(np.indices((h, w)))
    x = _frame(pred, h, w, rng)
    last = reuse.predict(x)
    for _ in range(frames - 1):
        x = _frame(pred, h, w, rng)
        seen = (rng.random((h, w)) >= hole).astype(np.float32)
        est = reuse.predict(x, still, seen)
        net = pred.predict(x)
        missing = _unseen_share(~(seen > 0), tile, 1) > 0.5
        want = np.where(missing[None], net, (1 - history) * net + history * last)
        np.testing.assert_allclose(est, want, rtol=1e-5, atol=1e-6)
        last = est


@FAST
@given(tile=tiles, psnr=st.booleans(), reduce=reductions, every=st.integers(2, 6),
       sizes_=st.lists(sizes, min_size=2, max_size=7), step=st.none() | st.integers(0, 5),
       seed=st.integers(0, 2**16), hole=st.sampled_from([0.05, 0.3, 0.7]), fraction=st.sampled_from([0.0, 0.5]),
       history=st.sampled_from([0.0, 0.5]), moving=st.booleans())
def test_fresh_tiles_are_the_network_s_on_this_frame(tile: int, psnr: bool, reduce: str, every: int,
                                                     sizes_: list[tuple[int, int]], step: int | None, seed: int,
                                                     hole: float, fraction: float, history: float,
                                                     moving: bool) -> None:
    """``unseen="fresh"`` (a model whose reach is its tile: margin 0, crops give the whole frame's estimates): on a
    carried frame every tile that would go to 1x1 has the network's estimate of this frame instead and none is worst;
    the work is the crops' share (at most half the frame), else the network runs on the whole frame (work 1, age 0),
    at any size and with sizes that change."""
    pred = _model(tile, psnr)
    rng = np.random.default_rng(seed)
    fresh = sdk.PredictionReuse(pred, every, unseen="fresh", reduce=reduce, step=_step(tile, step),
                                unseen_fraction=fraction, history=history)
    assert fresh.margin == 0
    prev = None
    for f, (h, w) in enumerate(sizes_):
        x = _frame(pred, h, w, rng)
        fetch = None
        if prev is not None:
            motion = rng.uniform(-3, 3, (2, h, w)) if moving else np.zeros((2, h, w))
            fetch = sdk.fetch_from_motion(motion[0], motion[1], prev_shape=prev)
        seen = (rng.random((h, w)) >= hole).astype(np.float32)
        twin = copy.copy(fresh)  # (the same reuse with unseen="full": which tiles go to 1x1 there)
        twin.unseen = "full"
        age = fresh.age
        est = fresh.predict(x, fetch, seen)
        assert est.shape == (6, *_grid(pred, h, w)) and np.isfinite(est).all()
        net = pred.predict(x)
        if fresh.work == 1.0:
            assert fresh.age == 0
            if history == 0.0:
                np.testing.assert_array_equal(est, net)
            if f and age is not None and age + 1 < every:  # early: crops over half the frame, for unseen tiles
                assert np.isinf(twin.predict(x, fetch, seen)).any()
        else:
            assert age is not None and fresh.age == age + 1 and 0.0 <= fresh.work <= 0.5
            carried = twin.predict(x, fetch, seen)
            missing = np.isinf(carried).all(axis=0)
            assert (fresh.work > 0.0) == missing.any()
            np.testing.assert_array_equal(est[:, missing], net[:, missing])
            np.testing.assert_array_equal(est[:, ~missing], carried[:, ~missing])
        prev = (h, w)


@pytest.mark.parametrize(("every", "history"), [(4, 0.0), (1, 0.5)])
@pytest.mark.parametrize("huge", [(1, 1 << 16), (1 << 15, 1)])
def test_a_frame_too_large_to_carry_is_refused_before_the_network_runs(every: int, history: float,
                                                                       huge: tuple[int, int]) -> None:
    """A frame of 65536 columns (or 32768 rows) does not fit a track's packed places: it is refused with an
    ``InputShapeError`` and the reuse is as it was, so the next frame carries the last run's estimates. Before, the
    network ran on it and set it as the carry before the track refused it, and the next frame carried that frame's
    estimates under the last frame's track, silently. With ``every=1`` and no history nothing is carried: taken."""
    pred = _model(16)
    rng = np.random.default_rng(0)
    x = _frame(pred, 32, 48, rng)
    reuse = sdk.PredictionReuse(pred, every, history=history)
    first = reuse.predict(x)
    with pytest.raises(sdk.InputShapeError, match="fewer than 32768 rows and 65536 columns"):
        reuse.predict(_frame(pred, *huge, rng))
    assert reuse.age == 0
    np.testing.assert_allclose(reuse.predict(x, tuple(np.indices((32, 48)))), first, rtol=1e-6, atol=0)
    plain = sdk.PredictionReuse(pred, 1)
    assert plain.predict(_frame(pred, *huge, rng)).shape == (6, *_grid(pred, *huge))


@FAST
@given(size=sizes, tile=tiles, psnr=st.booleans(), reduce=reductions, frames=st.integers(2, 5),
       seed=st.integers(0, 2**16), fraction=st.sampled_from([0.0, 0.3, 0.5, 0.9]), hole=st.sampled_from([0.0, 0.2]),
       reach=st.integers(0, 40), sky=st.sampled_from([0.0, 0.3]))
def test_each_pixel_carries_the_estimate_of_where_its_surface_was(size: tuple[int, int], tile: int, psnr: bool,
                                                                  reduce: str, frames: int, seed: int,
                                                                  fraction: float, hole: float, reach: int,
                                                                  sky: float) -> None:
    """Every pixel kept (``step=1``), any motion: a pixel's surface is where the fetches, followed back frame by
    frame, put it on the frame the network ran on, and it carries the estimate of the run's tile there (sky: of the
    tile at its own place); unknown where any of those fetches was unseen. Each tile reduces its known pixels'
    estimates as ``reduce`` says, and more than ``unseen_fraction`` unknown is the worst value (1x1)."""
    pred = _model(tile, psnr)
    h, w = size
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, frames + 1, reduce=reduce, step=1, unseen_fraction=fraction)
    run = reuse.predict(_frame(pred, h, w, rng)).reshape(6, -1)
    rows, cols = np.indices((h, w))
    known = np.ones((h, w), bool)
    tw = -(-w // tile)
    for _ in range(frames - 1):
        fetch = _random_fetch(rng, h, w, h, w, reach)
        seen = (rng.random((h, w)) >= hole).astype(np.float32)
        background = (rng.random((h, w)) < sky).astype(np.float32)
        est = reuse.predict(_frame(pred, h, w, rng), fetch, seen, background)
        rows, cols, known = rows[fetch], cols[fetch], known[fetch] & (seen > 0)
        on = background > 0.5
        rows, cols, known = np.where(on, np.indices((h, w))[0], rows), np.where(on, np.indices((h, w))[1], cols), \
            known | on
        tile_of = (rows // tile) * tw + cols // tile
        want = np.empty_like(est)
        for ty in range(-(-h // tile)):
            for tx in range(tw):
                ys, xs = slice(ty * tile, (ty + 1) * tile), slice(tx * tile, (tx + 1) * tile)
                v = run[:, tile_of[ys, xs][known[ys, xs]]].astype(np.float64)
                if v.shape[1] == 0 or 1.0 - v.shape[1] / known[ys, xs].size > fraction:
                    want[:, ty, tx] = -np.inf if psnr else np.inf
                elif reduce == "mean":
                    want[:, ty, tx] = v.mean(axis=1)
                else:
                    worse = np.sort(v if psnr else -v, axis=1)
                    at = 0 if reduce == "worst" else int(np.floor(0.25 * (v.shape[1] - 1)))
                    want[:, ty, tx] = worse[:, at] if psnr else -worse[:, at]
        np.testing.assert_allclose(est, want, rtol=1e-6, atol=0)


@functools.cache
def _shipped(name: str) -> sdk.ShadingRatePredictor:
    return sdk.load(name)


def _shipped_frame(pred: sdk.ShadingRatePredictor, h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    """Random planes, the ``.blocks`` / ``.tiles`` ones derived from the first (the luma) as an engine's are."""
    x = _frame(pred, h, w, rng)
    for i, c in enumerate(pred.metadata.inputs):
        if c.endswith((".blocks", ".tiles")):
            x[i] = (sdk.tile_variances if c.endswith(".tiles") else sdk.block_variances)(x[0])
    return x


@settings(FAST, max_examples=max(FAST.max_examples // 3, 5))
@given(size=sizes, every=st.integers(2, 4), frames=st.integers(2, 5), seed=st.integers(0, 2**16),
       step=st.none() | st.integers(0, 4), rescale=st.sampled_from([0.25, 1.0]), same=st.booleans())
def test_a_still_camera_with_rescale_follows_the_blocks_of_each_frame(size: tuple[int, int], every: int, frames: int,
                                                                      seed: int, step: int | None, rescale: float,
                                                                      same: bool) -> None:
    """``rescale`` on a still camera, any frame size (partial tiles, a frame narrower than a 4x4 cell): a carried
    frame's estimate is the run's times ``((v_now + eps) / (v_then + eps)) ** rescale`` per tile and rate (the
    variances of ``tile_block_levels``), so a frame that is the run's own carries its estimates unchanged."""
    from rtp.sdk._channels import BLOCK_EPS
    from rtp.sdk._reuse import tile_block_levels

    pred = _shipped("jnyang")
    h, w = size
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, every, step=_step(16, step), rescale=rescale)
    blocks = [i for i, c in enumerate(pred.metadata.inputs) if c.endswith(".blocks")]

    def level(x: np.ndarray) -> np.ndarray:
        return (tile_block_levels(x[blocks], 16).astype(np.float64) - 1) * -np.log(BLOCK_EPS) * rescale

    x0 = _shipped_frame(pred, h, w, rng)
    run = reuse.predict(x0)
    still = tuple(np.indices((h, w)))
    for f in range(1, frames):
        x = x0 if same else _shipped_frame(pred, h, w, rng)
        est = reuse.predict(x, still)
        if f % every == 0:
            x0, run = x, pred.predict(x)
            np.testing.assert_array_equal(est, run)
        else:
            np.testing.assert_allclose(est, run * np.exp(level(x) - level(x0)), rtol=1e-5, atol=0)


@settings(FAST, max_examples=max(FAST.max_examples // 3, 5))
@given(size=sizes, every=st.integers(2, 4), frames=st.integers(2, 5), seed=st.integers(0, 2**16),
       step=st.none() | st.integers(0, 4), unseen=st.sampled_from(["full", "fresh"]))
def test_a_still_camera_carrying_features_runs_the_tail_on_each_frame(size: tuple[int, int], every: int, frames: int,
                                                                       seed: int, step: int | None,
                                                                       unseen: str) -> None:
    """``carry="features"`` (the shipped ``jnyang-reuse``) on a still camera, any frame size: a carried frame's
    estimates are the tail's on the run's features and this frame's inputs; the network runs every k-th frame."""
    pred = _shipped("jnyang-reuse")
    h, w = size
    rng = np.random.default_rng(seed)
    reuse = sdk.PredictionReuse(pred, every, step=_step(16, step), carry="features", unseen=unseen)
    still = tuple(np.indices((h, w)))
    for f in range(frames):
        x = _shipped_frame(pred, h, w, rng)
        est = reuse.predict(x, still if f else None, np.ones((h, w), np.float32))
        if f % every == 0:
            feats = pred.predict_split(x)[1]
            np.testing.assert_allclose(est, pred.predict(x), rtol=1e-6, atol=0)
            assert reuse.work == 1.0
        else:
            np.testing.assert_allclose(est, pred.predict_tail(feats, x), rtol=1e-5, atol=1e-7)
            assert reuse.work == 0.0 and reuse.age == f % every


@FAST
@given(size=sizes, prev=st.none() | sizes, seed=st.integers(0, 2**16), shift=st.tuples(st.integers(-60, 60),
                                                                                        st.integers(-60, 60)))
def test_fetch_from_motion_gives_pixels_of_the_previous_frame(size: tuple[int, int], prev: tuple[int, int] | None,
                                                             seed: int, shift: tuple[int, int]) -> None:
    """Any motion, any previous size: ``intp`` indices inside the previous frame; at one size a motion of whole
    pixels fetches the pixel that much away (clamped to the frame), and no motion the pixel itself; at another
    size no motion fetches the pixel under the centre (on an edge between two, either)."""
    h, w = size
    ph, pw = prev or size
    rng = np.random.default_rng(seed)
    rows, cols = sdk.fetch_from_motion(rng.normal(0, 30, (h, w)), rng.normal(0, 30, (h, w)), prev_shape=prev)
    assert rows.dtype == cols.dtype == np.intp and rows.shape == cols.shape == (h, w)
    assert 0 <= rows.min() and rows.max() < ph and 0 <= cols.min() and cols.max() < pw
    ys, xs = np.indices((h, w))
    rows, cols = sdk.fetch_from_motion(np.full((h, w), float(shift[1])), np.full((h, w), float(shift[0])),
                                       prev_shape=prev)
    if prev is None:
        np.testing.assert_array_equal(rows, np.clip(ys + shift[0], 0, h - 1))
        np.testing.assert_array_equal(cols, np.clip(xs + shift[1], 0, w - 1))
    still = sdk.fetch_from_motion(np.zeros((h, w)), np.zeros((h, w)), prev_shape=prev)
    # the pixel whose span holds the centre; a centre on an edge (exactly, in integers) may be either pixel: the
    # float positions round it to one side or the other, as reproject's do (the same texel, to the bit)
    edge_y, edge_x = (2 * ys + 1) * ph % (2 * h) == 0, (2 * xs + 1) * pw % (2 * w) == 0
    below, right = (2 * ys + 1) * ph // (2 * h), (2 * xs + 1) * pw // (2 * w)
    assert ((still[0] == np.minimum(below, ph - 1)) | (edge_y & (still[0] == below - 1))).all()
    assert ((still[1] == np.minimum(right, pw - 1)) | (edge_x & (still[1] == right - 1))).all()


@pytest.mark.parametrize("empty", [(0, 5), (4, 0), (0, 0)])
def test_a_frame_without_pixels_is_an_input_shape_error_on_every_frame(empty: tuple[int, int]) -> None:
    """A frame of no rows or columns is an ``InputShapeError`` naming the frame, on the network's frame and on a
    carried one alike, and leaves the carry as it was. On a carried frame it was a ``ParameterError`` about a
    ``height`` (or ``width``) the caller never passed."""
    pred = _model(16)
    rng = np.random.default_rng(0)
    x = _frame(pred, 20, 30, rng)
    reuse = sdk.PredictionReuse(pred, 4)
    for carried in (False, True):
        fetch = (np.zeros(empty, np.intp), np.zeros(empty, np.intp)) if carried else None
        with pytest.raises(sdk.InputShapeError, match="expected a frame of at least one pixel"):
            reuse.predict(np.zeros((4, *empty), np.float32), fetch)
        with pytest.raises(sdk.InputShapeError, match="seen: expected a frame of at least one pixel"):
            reuse.shading_rates(lambda ys, xs: x[:, ys, xs], fetch, np.ones(empty, np.float32))
        first = reuse.predict(x)
    assert reuse.age == 0
    np.testing.assert_allclose(reuse.predict(x, tuple(np.indices((20, 30)))), first, rtol=1e-6, atol=0)
