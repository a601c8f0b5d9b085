"""rtp.plugins.moderngl.RateSelector: the runtime's decision in a compute shader, against the SDK's."""

from __future__ import annotations

import itertools
import logging
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from rtp import sdk
from rtp.plugins.moderngl import RateSelector, RendererError
from rtp.plugins.moderngl._glio import is_released
from rtp.sdk.adapters import AdapterFrameError
from tests.conftest import base_metadata, in_thread, make_current
from tests.test_moderngl_adapter import H, W, frames  # noqa: F401  (frames: a fixture)

pytestmark = pytest.mark.gl

#: the reduced rates by cost class, cheapest first (select_rates' order of preference)
CLASSES = (("4x4",), ("2x4", "4x2"), ("2x2",), ("1x2", "2x1"))


def _robust(values: np.ndarray, threshold: float, higher_is_better: bool, allowed: tuple[str, ...]) -> np.ndarray:
    """Tiles whose decision float32 rounding cannot change: no allowed rate's value within a hair of the
    threshold, nor within a hair of (but not equal to) the other rate of its cost class."""
    v = values.astype(np.float64)
    hair = 1e-4 * (1.0 + np.abs(v))
    ok = np.ones(v.shape[1:], bool)
    idx = {r: sdk.PREDICTED_RATES.index(r) for r in sdk.PREDICTED_RATES}
    for r in allowed:
        ok &= ~(np.abs(v[idx[r]] - threshold) < hair[idx[r]])
    for a, b in (("2x4", "4x2"), ("1x2", "2x1")):
        if a in allowed and b in allowed:  # an exact tie (one extrapolated from the same 2x2) decides alike
            d = np.abs(v[idx[a]] - v[idx[b]])
            both_pass = (v[idx[a]] > threshold) & (v[idx[b]] > threshold) if higher_is_better else \
                (v[idx[a]] < threshold) & (v[idx[b]] < threshold)
            ok &= ~(both_pass & (d > 0) & (d < hair[idx[a]]))
    return ok


def test_every_shipped_model_decides_as_the_sdk_on_a_rendered_frame(frames, gl_context: Any) -> None:  # noqa: F811
    ctx, _, cur = frames
    for name in sdk.shipped_models():
        pred = sdk.load(name)
        x = np.stack([cur.channel(c) for c in pred.metadata.inputs])  # what the adapters build from it
        raw = pred.predict_raw(x)
        with RateSelector(pred, ctx) as selector:
            seen: set[int] = set()
            for scale in (0.5, 1.0, 2.0, 4.0):  # 4: rates whose own factor is small (LPIPS 4x4 0.47) pass too
                thr = pred.metadata.default_threshold * scale
                gpu = selector.select(raw, thr)
                seen |= set(np.unique(gpu).tolist())
                cpu = pred.shading_rates(x, thr)
                assert gpu.shape == cpu.shape == pred.tiles(H, W) and gpu.dtype == np.uint8
                values = pred.predict(x)
                ok = _robust(values, thr, pred.metadata.higher_is_better, sdk.PREDICTED_RATES)
                assert ok.mean() >= 0.9, name  # the comparison covers (nearly) the whole frame
                np.testing.assert_array_equal(gpu[ok], cpu[ok], err_msg=f"{name} at threshold {thr}")
                np.testing.assert_allclose(selector.decoded(), values, rtol=1e-5, atol=1e-6)
            assert len(seen) >= 3, (name, seen)  # the frame and thresholds exercise several rates


def _generated_metadata(transform: dict[str, Any], outputs: list[str], k: float, safety: float, pool: int,
                        factors: list[float] | None, psnr: bool) -> sdk.ModelMetadata:
    """A model's metadata from the generated settings (8-pixel tiles where they are pooled); an example whose
    settings no metadata takes is rejected (``assume``)."""
    meta_d = base_metadata(transform=transform, outputs=outputs, extrapolation_k=k, safety=safety,
                           tile_size=8 if pool > 1 else 16)
    if factors is not None:
        meta_d["rate_factors"] = dict(zip(sdk.PREDICTED_RATES, factors))
    if psnr:
        meta_d.update(metric="psnr", default_threshold=35.0)
        del meta_d["weber_l"]
    try:
        return sdk.ModelMetadata.from_dict(meta_d)
    except sdk.MetadataError:
        assume(False)
        raise


_TRANSFORMS = st.one_of(
    st.builds(lambda mu: {"type": "clamped", "mu_y": mu}, st.floats(0.02, 2.0)),
    st.builds(lambda mu, k: {"type": "logistic", "mu_y": mu, "k": k}, st.floats(0.02, 0.9), st.floats(2.0, 30.0)),
    st.builds(lambda f, o: {"type": "linear", "factor": f, "offset": o},
              st.sampled_from([-1.0, 1.0]).flatmap(lambda s: st.floats(0.05, 5.0).map(lambda f: s * f)),
              st.floats(-0.5, 0.5)),
)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(transform=_TRANSFORMS,
       outputs=st.sampled_from([["1x2", "2x1"], ["1x2", "2x1", "2x4", "4x2"], list(sdk.PREDICTED_RATES), ["2x2"]]),
       psnr=st.booleans(), k=st.floats(1.0, 8.0), safety=st.floats(0.0, 0.2),
       quantile=st.floats(0.05, 0.95),
       allowed=st.sets(st.sampled_from(sdk.PREDICTED_RATES)).map(lambda s: tuple(r for r in sdk.PREDICTED_RATES if r in s)),
       tiles=st.tuples(st.integers(1, 20), st.integers(1, 20)), pool=st.sampled_from([1, 1, 2, 4]),
       seed=st.integers(0, 2**16),
       factors=st.one_of(st.none(), st.lists(st.floats(0.25, 4.0), min_size=6, max_size=6)))
# a margin that pushes a logistic output past 1: the shader once rounded x + margin to float32 and missed
# the SDK's value by 4e-4 of it (1 - S is a few ulps there)
@example(transform={"type": "logistic", "mu_y": 0.046875, "k": 9.125}, outputs=list(sdk.PREDICTED_RATES), psnr=False,
         k=1.0, safety=0.1478266100275777, quantile=0.5, allowed=(), tiles=(13, 14), pool=1, seed=5510, factors=None)
# a margin that pushes a logistic output below 0 (PSNR: the margin lowers it): S a few ulps of the terms it was
# made of, and the float32 margin alone missed the SDK's value by 1.8e-3 of it
@example(transform={"type": "logistic", "mu_y": 0.17422626279644354, "k": 25.94921875},
         outputs=list(sdk.PREDICTED_RATES), psnr=True, k=1.0, safety=0.15518617964278758, quantile=0.5, allowed=(),
         tiles=(14, 16), pool=1, seed=16, factors=None)
def test_any_metadata_decides_as_the_sdk(gl_context: Any, transform: dict[str, Any], outputs: list[str], psnr: bool,
                                          k: float, safety: float, quantile: float, allowed: tuple[str, ...],
                                          tiles: tuple[int, int], pool: int, seed: int,
                                          factors: list[float] | None) -> None:
    """Every transform, output set, metric direction, margin, extrapolation factor, allowed set, grid
    (odd sizes: the shader's 8x8 groups overhang the edge), hardware tile (8-pixel model tiles pooled
    into 16 and 32) and threshold factors per rate: the codes of select_rates(pool_tiles(decode(raw))),
    and the values."""
    meta = _generated_metadata(transform, outputs, k, safety, pool, factors, psnr)
    rng = np.random.default_rng(seed)
    raw = rng.random((len(outputs), *tiles)).astype(np.float32)
    raw.flat[rng.integers(raw.size)] = np.nan  # NaN never passes: its tile takes another rate or 1x1
    values = sdk.pool_tiles(meta.decode(raw), pool, higher_is_better=meta.higher_is_better)
    finite = values[np.isfinite(values)]
    assume(finite.size > 0)
    threshold = float(np.quantile(finite, quantile))  # a threshold that splits the tiles
    if not psnr:
        threshold = max(threshold, 0.0)
    selector = RateSelector(meta, gl_context, tile_size=meta.tile_size * pool)
    try:
        gpu = selector.select(raw, threshold, allowed=list(allowed) or ["1x1"])
        decoded = selector.decoded()
    finally:
        selector.close()
    cpu = sdk.select_rates(values, threshold, higher_is_better=meta.higher_is_better, allowed=list(allowed) or ["1x1"],
                           factors=meta.rate_factors)
    # each rate against its own threshold is the threshold against the values over the factors (PSNR: plus 20 log10)
    f = np.asarray(meta.rate_factors)[:, None, None]
    with np.errstate(invalid="ignore"):
        own = values + 20.0 * np.log10(f) if meta.higher_is_better else values / f
    np.testing.assert_array_equal(cpu, sdk.select_rates(own, threshold, higher_is_better=meta.higher_is_better,
                                                        allowed=list(allowed) or ["1x1"]))
    ok = _robust(own, threshold, meta.higher_is_better, allowed)
    np.testing.assert_array_equal(gpu[ok], cpu[ok])
    both = np.isfinite(values)
    np.testing.assert_array_equal(np.isfinite(decoded), both)
    np.testing.assert_allclose(decoded[both], values[both], rtol=2e-4, atol=2e-5)
    if not allowed:
        assert (gpu == 0).all()


def test_the_rates_stay_on_the_gpu_and_bad_input_is_refused(gl_context: Any) -> None:
    meta = sdk.load("jnyang").metadata
    raw = np.random.default_rng(1).random((4, 9, 13)).astype(np.float32)
    with RateSelector(meta, gl_context) as selector:
        buffer = gl_context.buffer(raw.tobytes())
        texture = selector.select_buffer(buffer, (9, 13))
        assert texture.size == (13, 9) and texture.dtype == "u1" and texture.components == 1
        codes = np.frombuffer(texture.read(alignment=1), np.uint8).reshape(9, 13)
        np.testing.assert_array_equal(codes, selector.select(raw))  # the same from host memory
        with pytest.raises(sdk.InputShapeError, match=r"holds 1872 bytes, expected at least 2080"):
            selector.select_buffer(buffer, (10, 13))
        with pytest.raises(sdk.InputShapeError, match=r"expected the network's float output \(4, th, tw\)"):
            selector.select(raw[:2])
        with pytest.raises(sdk.ParameterError, match="threshold"):
            selector.select(raw, -1.0)
        with pytest.raises(sdk.ParameterError, match="allowed"):
            selector.select(raw, allowed=["3x3"])
        # an empty frame used to reach moderngl (a raw moderngl.Error) and leave the selector broken
        with pytest.raises(sdk.InputShapeError):
            selector.select(raw[:, :0])
        with pytest.raises(sdk.InputDtypeError, match="moderngl.Buffer"):
            selector.select_buffer(None, (9, 13))
        with pytest.raises(sdk.ParameterError, match="tiles"):
            selector.select_buffer(buffer, (9,))  # type: ignore[arg-type]
        # numpy rows wrapped the byte count to 0 (2**62 x 4 tiles passed the size check) and the driver aborted
        with pytest.raises(sdk.ParameterError, match="at most .* hardware tiles a side"):
            selector.select_buffer(buffer, (np.int64(2**62), np.int64(4)))
        with pytest.raises(sdk.InputShapeError, match="holds 1872 bytes"):
            selector.select_buffer(buffer, (np.int64(2**13), np.int64(2**13)))
        limit = gl_context.info["GL_MAX_TEXTURE_SIZE"]
        wide = gl_context.buffer(reserve=4 * (limit + 1) * 4)
        with pytest.raises(sdk.ParameterError, match=f"at most {limit} hardware tiles a side"):
            selector.select_buffer(wide, (1, limit + 1))
        wide.release()
        np.testing.assert_array_equal(codes, selector.select(raw))  # still works after every refusal
        buffer.release()
    selector.close()  # twice: nothing released twice
    for call in (lambda: selector.select(raw), selector.decoded):
        with pytest.raises(RendererError, match="closed"):  # (an RtpError and a RuntimeError)
            call()
    with RateSelector(meta, gl_context) as fresh, pytest.raises(RendererError, match="nothing selected"):
        fresh.decoded()
    with pytest.raises(AdapterFrameError, match="moderngl.Context"):
        RateSelector(meta, object())
    from rtp.plugins.moderngl import create_context

    gone = create_context()
    gone.release()
    with pytest.raises(AdapterFrameError, match="ctx: this moderngl context has been released"):  # an AttributeError
        RateSelector(meta, gone)
    make_current(gl_context)
    with pytest.raises(sdk.ParameterError, match="ModelMetadata"):
        RateSelector("jnyang", gl_context)  # type: ignore[arg-type]
    for bad in (2, 24, 2.0):  # finer than one 4x4 coarse pixel; not a tile size; not an int
        with pytest.raises(sdk.ParameterError, match=r"tile_size: expected one of \[4, 8, 16, 32\]"):
            RateSelector(meta, gl_context, tile_size=bad)  # type: ignore[arg-type]


def test_each_selector_runs_in_its_own_context_whichever_is_current(gl_context: Any) -> None:
    """moderngl never switches contexts: a selector that ran while a second selector's context was current ran that
    context's objects of the same names and returned wrong codes without an error (as renderers did before
    2026-12-05); each call now makes its own context current."""
    meta = sdk.load("jnyang").metadata
    rng = np.random.default_rng(3)
    raw_a, raw_b = rng.random((4, 3, 5)).astype(np.float32), rng.random((4, 3, 5)).astype(np.float32)

    def cpu(raw: np.ndarray) -> np.ndarray:
        return sdk.select_rates(meta.decode(raw), meta.default_threshold, factors=meta.rate_factors)

    assert (cpu(raw_a) != cpu(raw_b)).any()
    try:
        own_a = RateSelector(meta)  # each makes its own headless context
        np.testing.assert_array_equal(own_a.select(raw_a), cpu(raw_a))  # (its buffers and texture made in its context)
        own_b = RateSelector(meta)  # (current now)
        np.testing.assert_array_equal(own_a.select(raw_a), cpu(raw_a))
        np.testing.assert_array_equal(own_b.select(raw_b), cpu(raw_b))
        np.testing.assert_array_equal(own_a.select(raw_a), cpu(raw_a))
        np.testing.assert_allclose(own_a.decoded(), meta.decode(raw_a), rtol=1e-5, atol=1e-6)
        make_current(own_b.ctx)
        borrowed = RateSelector(meta, gl_context)  # its programs are made in gl_context, not in the current one
        make_current(own_b.ctx)
        np.testing.assert_array_equal(borrowed.select(raw_b), cpu(raw_b))
        own_b.close()  # frees its objects in its own context
        np.testing.assert_array_equal(own_a.select(raw_a), cpu(raw_a))
        np.testing.assert_array_equal(borrowed.select(raw_b), cpu(raw_b))
        borrowed.close()
        own_a.close()
    finally:
        make_current(gl_context)


def test_a_selector_dropped_unclosed_releases_the_context_it_made_and_says_so(gl_context: Any) -> None:
    """An engine that made a ``RateSelector(predictor)`` per level load and dropped it unclosed kept every selector's
    headless context with its programs, buffers and texture (about 4 MB each on llvmpipe, growing every level) and
    was told nothing. A context the selector made is now released when it is collected, the engine's current context
    left current, with a ResourceWarning; in a borrowed context its objects stay (the context need not be current to
    free them in) and it says so."""
    import gc
    import warnings

    meta = sdk.load("jnyang").metadata
    raw = np.random.default_rng(5).random((4, 3, 5)).astype(np.float32)
    want = sdk.select_rates(meta.decode(raw), meta.default_threshold, factors=meta.rate_factors)
    ctx = make_current(gl_context)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            own = RateSelector(meta)  # (a context of its own, current after the call)
            np.testing.assert_array_equal(own.select(raw), want)
            made = own.ctx
            make_current(gl_context)  # the engine's context current again, as the engine's next draw needs it
            del own
            gc.collect()
            assert is_released(made) and not is_released(ctx)
            assert [str(w.message) for w in caught if w.category is ResourceWarning] == [
                "an unclosed rtp RateSelector released the headless GL context it made when it was collected: "
                "close() it, or use it in a with block"]
            probe = RateSelector(meta, gl_context)  # the engine's context still current and drawing
            np.testing.assert_array_equal(probe.select(raw), want)
            probe.close()
            caught.clear()
            borrowed = RateSelector(meta, gl_context)
            np.testing.assert_array_equal(borrowed.select(raw), want)
            kept = [borrowed._program, borrowed._budget, borrowed._decoded, borrowed._raw, borrowed._texture]
            del borrowed
            gc.collect()
            assert not any(is_released(o) for o in kept)  # (not freed in whatever context is current)
            assert [w for w in caught if w.category is ResourceWarning and "borrowed GL context" in str(w.message)]
            for o in kept:
                o.release()
            caught.clear()
            with RateSelector(meta) as closed:  # closed ones say nothing
                closed.select(raw)
            del closed
            gc.collect()
            assert not [w for w in caught if w.category is ResourceWarning]
    finally:
        make_current(gl_context)


def test_a_numpy_integer_is_a_tile_size(gl_context: Any) -> None:
    """``tile_size=np.int64(8)`` (what a frame's grid arithmetic hands over) was refused as "expected one of [4, 8,
    16, 32], got np.int64(8)"."""
    meta = sdk.load("jnyang").metadata
    raw = np.random.default_rng(4).random((4, 3, 5)).astype(np.float32)
    with RateSelector(meta, gl_context, tile_size=8) as plain, \
            RateSelector(meta, gl_context, tile_size=np.int64(8)) as numpy_int:  # type: ignore[arg-type]
        assert numpy_int.tile_size == 8 and type(numpy_int.split) is int
        np.testing.assert_array_equal(numpy_int.select(raw), plain.select(raw))
    with pytest.raises(sdk.ParameterError, match="tile_size"):
        RateSelector(meta, gl_context, tile_size=np.bool_(True))  # type: ignore[arg-type]


def test_a_buffer_or_engine_texture_of_another_context_or_released_is_refused(gl_context: Any) -> None:
    """select_buffer's ``raw`` and an ``engine_rates`` texture are bound by their GL names: one of another context
    was read as whatever object of that name the selector's context holds (wrong codes, no error), a released one
    failed as an AttributeError. Both are ParameterErrors naming the argument, and the selector works on after them."""
    from rtp.plugins.moderngl import create_context

    meta = sdk.load("jnyang").metadata
    raw = np.random.default_rng(6).random((4, 3, 5)).astype(np.float32)
    engine = np.full((3, 5), sdk.RATE_CODES["2x1"], np.uint8)
    other = create_context(430)
    try:
        foreign = (other.buffer(raw.tobytes()), other.texture((5, 3), 1, engine.tobytes(), dtype="u1"))
        with RateSelector(meta, gl_context) as selector:
            want = selector.select(raw, engine_rates=engine)
            gone = (gl_context.buffer(raw.tobytes()), gl_context.texture((5, 3), 1, engine.tobytes(), dtype="u1"))
            for obj in gone:
                obj.release()
            for (buffer, texture), word in ((foreign, "of the selector's context"), (gone, "has been released")):
                with pytest.raises(sdk.ParameterError, match=f"raw: .*{word}"):
                    selector.select_buffer(buffer, (3, 5))
                with pytest.raises(sdk.ParameterError, match=f"engine_rates: .*{word}"):
                    selector.select(raw, engine_rates=texture)
            np.testing.assert_array_equal(selector.select(raw, engine_rates=engine), want)
    finally:
        other.release()
        make_current(gl_context)


def test_a_context_released_under_a_selector_is_named_and_close_still_works(gl_context: Any) -> None:
    """The engine released the context a selector borrowed: select() and decoded() raised an AttributeError (making
    the released context current), and so did close(), the with block's exit included. Now the calls are an
    AdapterFrameError naming the context, and close() lets the objects go with it."""
    from rtp.plugins.moderngl import create_context

    meta = sdk.load("jnyang").metadata
    raw = np.random.default_rng(7).random((4, 3, 5)).astype(np.float32)
    ctx = create_context(430)
    try:
        with RateSelector(meta, ctx) as selector:
            selector.select(raw)
            ctx.release()
            for call in (lambda: selector.select(raw), selector.decoded):
                with pytest.raises(AdapterFrameError, match="ctx: the moderngl context was released under this"):
                    call()
        selector.close()
        with pytest.raises(RendererError, match="closed"):
            selector.select(raw)
    finally:
        make_current(gl_context)


def test_hardware_tiles_coarser_than_the_model_s_as_load_pools_them(tiny_model, gl_context: Any) -> None:
    """A model of 8-pixel tiles loaded for 16-pixel hardware tiles: the selector takes the predictor's
    tile size and returns what its shading_rates returns, one code per hardware tile."""
    pred = sdk.load(tiny_model(base_metadata(tile_size=8), tile=8), tile_size=16)
    x = np.random.default_rng(3).random((4, 72, 104)).astype(np.float32)  # 9 x 13 model tiles: partial pools
    with RateSelector(pred, gl_context) as selector:
        assert selector.pool == 2 and selector.tile_size == 16
        for thr in (0.05, 0.2, 0.4):
            gpu = selector.select(pred.predict_raw(x), thr)
            assert gpu.shape == pred.tiles(72, 104) == (5, 7)
            values = pred.predict(x)
            ok = _robust(values, thr, False, sdk.PREDICTED_RATES)
            np.testing.assert_array_equal(gpu[ok], pred.shading_rates(x, thr)[ok])
            np.testing.assert_allclose(selector.decoded(), values, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("fine", [8, 4])
def test_hardware_tiles_finer_than_the_model_s_as_load_splits_them(tiny_model, gl_context: Any, fine: int) -> None:
    """A 16-pixel model on AMD's and Intel's 8-pixel tiles (or 4): each hardware texel takes its model tile's
    decision, on the frame's own grid (``grid=predictor.tiles(h, w)``: a partial last model tile holds fewer
    hardware rows), as ``shading_rates`` of the predictor loaded for those tiles gives it; without ``grid``,
    ``split`` times the model's tiles; a grid that does not fit the model's tiles is refused."""
    pred = sdk.load(tiny_model(base_metadata(tile_size=16), tile=16), tile_size=fine)
    x = np.random.default_rng(5).random((4, 72, 104)).astype(np.float32)  # 5 x 7 model tiles, the last partial
    split = 16 // fine
    with RateSelector(pred, gl_context) as selector:
        assert (selector.split, selector.pool, selector.tile_size) == (split, 1, fine)
        grid = pred.tiles(72, 104)
        assert grid == (-(-72 // fine), -(-104 // fine))
        codes: set[int] = set()
        for thr in (0.05, 0.2, 0.4):
            gpu = selector.select(pred.predict_raw(x), thr, grid=grid)
            assert gpu.shape == grid
            codes |= set(np.unique(gpu).tolist())
            np.testing.assert_array_equal(gpu, pred.shading_rates(x, thr))
            np.testing.assert_allclose(selector.decoded(), pred.predict(x), rtol=1e-5, atol=1e-6)
        assert len(codes) >= 2  # decisions that differ from tile to tile
        whole = selector.select(pred.predict_raw(x), 0.2)  # no grid: every model tile whole
        assert whole.shape == (5 * split, 7 * split)
        np.testing.assert_array_equal(whole[:grid[0], :grid[1]], pred.shading_rates(x, 0.2))
        for bad in ((grid[0] - split, grid[1]), (grid[0], grid[1] + split), (0, 1), (1.5, 2), "ab", (1, 2, 3)):
            with pytest.raises(sdk.ParameterError, match="grid"):
                selector.select(pred.predict_raw(x), 0.2, grid=bad)  # type: ignore[arg-type]
        np.testing.assert_array_equal(selector.select(pred.predict_raw(x), 0.2, grid=grid), pred.shading_rates(x, 0.2))
    with RateSelector(sdk.load(tiny_model(base_metadata(tile_size=16), tile=16)), gl_context) as own:
        with pytest.raises(sdk.ParameterError, match=r"grid: expected 5x7 \(or None\)"):
            own.select(pred.predict_raw(x), 0.2, grid=grid)


def test_beside_the_engines_rates_the_shader_decides_as_the_sdk(frames, gl_context: Any) -> None:  # noqa: F811
    """``engine_rates`` and ``combiner``: the shader judges the rate the device shades, as ``select_rates`` does,
    for each combiner, on allowed sets where the device clamps, for an error metric and for PSNR; an engine's r8ui
    texture reads as its array; bad engine rates are the SDK's errors."""
    ctx, _, cur = frames
    rng = np.random.default_rng(4)
    mixed = 0  # tiles where judging the rate shaded decides otherwise than combining rtp's own choice
    for name in ("jnyang", "psnr"):
        pred = sdk.load(name)
        x = np.stack([cur.channel(c) for c in pred.metadata.inputs])
        raw, values = pred.predict_raw(x), pred.predict(x)
        hib = pred.metadata.higher_is_better
        with RateSelector(pred, ctx) as selector:
            for allowed in (sdk.PREDICTED_RATES, ("1x2", "2x1", "2x2"), ("1x2", "2x1", "4x4"), ("2x2", "2x4", "4x2")):
                supported = [sdk.RATE_CODES[r] for r in ("1x1", *allowed)]
                engine = rng.choice(supported, size=values.shape[1:]).astype(np.uint8)
                for combiner, scale in itertools.product(("min", "max", "sum"), (0.25, 1.0)):
                    t = pred.metadata.default_threshold  # (a low threshold: fewer tiles pass at 4x4)
                    thr = t + 6.0 * (1.0 - scale) if hib else t * scale
                    gpu = selector.select(raw, thr, allowed, engine_rates=engine, combiner=combiner)
                    cpu = pred.shading_rates(x, thr, allowed, engine_rates=engine, combiner=combiner)
                    ok = _robust(values, thr, hib, sdk.PREDICTED_RATES)
                    assert ok.mean() >= 0.9
                    np.testing.assert_array_equal(gpu[ok], cpu[ok], err_msg=f"{name} {allowed} {combiner}")
                    assert not np.array_equal(cpu, pred.shading_rates(x, thr, allowed)) or combiner == "min"
                    mixed += int((gpu != sdk.combine_rates(engine, pred.shading_rates(x, thr, allowed), combiner,
                                                           allowed=allowed)).sum())
        with RateSelector(pred, ctx) as selector:  # random outputs on a larger grid: every case of the clamp
            noise = rng.random((len(pred.metadata.outputs), 30, 40), dtype=np.float32)
            for allowed in (sdk.PREDICTED_RATES, ("1x2", "2x1", "4x4"), ("1x2", "2x1", "2x4", "4x2"), ("1x2", "2x2")):
                supported = [sdk.RATE_CODES[r] for r in ("1x1", *allowed)]
                engine = rng.choice(supported, size=(30, 40)).astype(np.uint8)
                for combiner in ("min", "max", "sum"):
                    thr = pred.metadata.default_threshold
                    gpu = selector.select(noise, thr, allowed, engine_rates=engine, combiner=combiner)
                    decoded = selector.decoded()
                    cpu = sdk.select_rates(decoded, thr, higher_is_better=hib, allowed=allowed,
                                           factors=pred.metadata.rate_factors, engine_rates=engine, combiner=combiner)
                    ok = _robust(decoded, thr, hib, sdk.PREDICTED_RATES)
                    np.testing.assert_array_equal(gpu[ok], cpu[ok], err_msg=f"{name} {allowed} {combiner} (random)")
                    mixed += int((gpu != sdk.combine_rates(engine, sdk.select_rates(
                        decoded, thr, higher_is_better=hib, allowed=allowed, factors=pred.metadata.rate_factors),
                        combiner, allowed=allowed)).sum())
        with RateSelector(pred, ctx) as selector:  # an engine's texture, read where it lies
            engine = np.full(values.shape[1:], sdk.RATE_CODES["2x1"], np.uint8)
            texture = ctx.texture((engine.shape[1], engine.shape[0]), 1, engine.tobytes(), dtype="u1")
            np.testing.assert_array_equal(selector.select(raw, engine_rates=texture),
                                          selector.select(raw, engine_rates=engine))
            with pytest.raises(sdk.InputShapeError, match="engine_rates: expected an r8ui texture of"):
                selector.select(raw, engine_rates=ctx.texture((3, 2), 1, dtype="u1"))
            with pytest.raises(sdk.ParameterError, match=r"engine_rates: 4x4 \(code 10\) not among the rates allowed"):
                selector.select(raw, allowed=["1x2", "2x1", "2x2"], engine_rates=10)
            with pytest.raises(sdk.ParameterError, match="combiner"):
                selector.select(raw, engine_rates=engine, combiner="average")
            texture.release()
    assert mixed > 100


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(transform=_TRANSFORMS,
       outputs=st.sampled_from([["1x2", "2x1"], ["1x2", "2x1", "2x4", "4x2"], list(sdk.PREDICTED_RATES), ["2x2"]]),
       psnr=st.booleans(), k=st.floats(1.0, 8.0), safety=st.floats(0.0, 0.2),
       allowed=st.sets(st.sampled_from(sdk.PREDICTED_RATES)).map(lambda s: tuple(r for r in sdk.PREDICTED_RATES if r in s)),
       tiles=st.tuples(st.integers(1, 24), st.integers(1, 24)), pool=st.sampled_from([1, 1, 2, 4]),
       seed=st.integers(0, 2**16), share=st.floats(0.0, 1.0), frame=st.booleans(),
       floor=st.one_of(st.none(), st.floats(0.05, 0.95)), nans=st.integers(0, 3),
       factors=st.one_of(st.none(), st.lists(st.floats(0.25, 4.0), min_size=6, max_size=6)))
@example(transform={"type": "clamped", "mu_y": 0.5}, outputs=list(sdk.PREDICTED_RATES), psnr=False, k=2.0,
         safety=0.0, allowed=tuple(sdk.PREDICTED_RATES), tiles=(24, 24), pool=1, seed=1, share=1.0, frame=True,
         floor=None, nans=3, factors=None)  # the most the frame can save, NaN tiles short of it
def test_a_budget_decides_as_the_sdk(gl_context: Any, transform: dict[str, Any], outputs: list[str], psnr: bool,
                                     k: float, safety: float, allowed: tuple[str, ...], tiles: tuple[int, int],
                                     pool: int, seed: int, share: float, frame: bool, floor: float | None, nans: int,
                                     factors: list[float] | None) -> None:
    """select(raw, saving=) on the GPU against sdk.select_rates_for_saving on the values the shader decoded: every
    transform, output set, direction, allowed set, hardware tile, partial edge tiles (frame_size), a floor under the
    budget, NaN tiles. With the rates' own thresholds (rate_factors) the shader's float32 oriented values can order
    two steps within a rounding of each other differently: there the rates are checked against select_rates at the
    threshold found, and the saving against the SDK's within a tile."""
    meta = _generated_metadata(transform, outputs, k, safety, pool, factors, psnr)
    rng = np.random.default_rng(seed)
    raw = rng.random((len(outputs), *tiles)).astype(np.float32)
    raw.flat[rng.integers(raw.size, size=nans)] = np.nan
    hib = meta.higher_is_better
    values = sdk.pool_tiles(meta.decode(raw), pool, higher_is_better=hib)
    finite = values[np.isfinite(values)]
    assume(finite.size > 0)
    rates = list(allowed) or ["1x1"]
    top = max((sdk.work_saved(r) for r in rates), default=0.0)
    saving = share * top
    threshold = None
    if floor is not None:
        threshold = float(np.quantile(finite, floor))
        threshold = threshold if psnr else max(threshold, 0.0)
        assume(abs(threshold) <= sdk.MAX_THRESHOLD)
    ts = meta.tile_size * pool
    grid = values.shape[1:]
    frame_size = (grid[0] * ts - int(rng.integers(ts)), grid[1] * ts - int(rng.integers(ts))) if frame else None
    weigh = {"frame_size": frame_size, "tile_size": ts} if frame else {}
    with RateSelector(meta, gl_context, tile_size=ts) as selector:
        gpu = selector.select(raw, threshold, allowed=rates, saving=saving, frame_size=frame_size)
        found, saved = selector.budget()
        decoded = selector.decoded().astype(np.float64)
    cpu = sdk.select_rates_for_saving(decoded, saving, higher_is_better=hib, allowed=rates, factors=meta.rate_factors,
                                      threshold=threshold, **weigh)
    assert saved == pytest.approx(sdk.work_saved(gpu, **weigh), abs=1e-9)  # what the budget says is what it chose
    if factors is None:  # the same float32 values on both sides: the same steps, the same choice
        np.testing.assert_array_equal(gpu, cpu.rates)
        assert saved == pytest.approx(float(cpu.saved), abs=1e-9)
        assert found == pytest.approx(float(cpu.threshold), rel=1e-6, abs=1e-37)
        o = -float(cpu.threshold) if hib else float(cpu.threshold)  # oriented: just above a float32 step
        bounds = (0.0, -sdk.MAX_THRESHOLD, sdk.MAX_THRESHOLD, None if threshold is None else (
            -threshold if hib else threshold))
        if o not in bounds:  # the GPU's is the next float32 above the same step: the least that passes it
            step = np.nextafter(o, -np.inf)
            assert np.float32(step) == step
            above = float(np.nextafter(np.float32(step), np.float32(np.inf)))
            assert found == (-above if hib else above)
    else:
        f = np.asarray(meta.rate_factors)[:, None, None]
        with np.errstate(invalid="ignore"):
            own = decoded + 20.0 * np.log10(f) if hib else decoded / f
        ok = _robust(own, found, hib, tuple(r for r in rates if r != "1x1"))
        at_found = sdk.select_rates(decoded, found, higher_is_better=hib, allowed=rates, factors=meta.rate_factors)
        np.testing.assert_array_equal(gpu[ok], at_found[ok])
        assert abs(saved - float(cpu.saved)) <= 1.0 / gpu.size + 1e-9
    if saving > 0 and np.isfinite(decoded).all() and threshold is None:
        assert saved >= saving - 1e-9  # the work asked for (NaN tiles can keep a frame short of it)


@pytest.mark.parametrize("psnr", [False, True])
def test_a_budget_past_every_threshold_reports_the_lowest_threshold_saving_what_it_can(gl_context: Any,
                                                                                      psnr: bool) -> None:
    """A value at or past MAX_THRESHOLD never passes, as a NaN does: the budget that cannot be reached reports the
    lowest threshold that saves what the frame can, as sdk.select_rates_for_saving does (the shader counted such a
    value as a step and reported MAX_THRESHOLD, PSNR -MAX_THRESHOLD: the number engines read as the cost)."""
    sign = -1.0 if psnr else 1.0
    meta = _generated_metadata({"type": "linear", "factor": sign * 1e-6, "offset": 0.0}, list(sdk.PREDICTED_RATES),
                               2.0, 0.0, 1, None, psnr)
    raw = np.full((6, 2, 4), 1e-7, np.float32)  # decoded 0.1 (PSNR -0.1 dB) everywhere
    raw[5, 0, 0] = 2.0  # but one tile's 4x4: 2e6, past every threshold (PSNR -2e6 dB, below every one)
    with RateSelector(meta, gl_context, tile_size=16) as selector:
        gpu = selector.select(raw, saving=0.9375)
        found, saved = selector.budget()
        decoded = selector.decoded().astype(np.float64)
    cpu = sdk.select_rates_for_saving(decoded, 0.9375, higher_is_better=meta.higher_is_better)
    assert abs(float(cpu.threshold)) < 1.0 and abs(found) < 1.0, (found, float(cpu.threshold))
    assert found == pytest.approx(float(cpu.threshold), rel=1e-6)
    np.testing.assert_array_equal(gpu, cpu.rates)
    assert saved == pytest.approx(float(cpu.saved)) and saved < 0.9375


def test_a_budget_on_a_rendered_frame_and_its_refusals(frames, gl_context: Any) -> None:  # noqa: F811
    """Every shipped model's budget on a rendered frame, as predictor.shading_rates(x, saving=) chooses it; the
    threshold and the saving read back; what a budget on the GPU refuses, named."""
    ctx, _, cur = frames
    for name in sdk.shipped_models():
        pred = sdk.load(name)
        x = np.stack([cur.channel(c) for c in pred.metadata.inputs])
        raw = pred.predict_raw(x)
        with RateSelector(pred, ctx) as selector:
            for saving in (0.25, 0.5, 0.8):
                gpu = selector.select(raw, saving=saving, frame_size=(H, W))
                found, saved = selector.budget()
                cpu = pred.shading_rates(x, saving=saving)
                assert saved >= saving and saved == pytest.approx(sdk.work_saved(gpu, (H, W), pred.tile_size))
                values = pred.predict(x)
                ok = _robust(values, found, pred.metadata.higher_is_better, sdk.PREDICTED_RATES)
                assert ok.mean() >= 0.8, name
                np.testing.assert_array_equal(gpu[ok], cpu[ok], err_msg=f"{name} saving {saving}")
                assert abs(saved - sdk.work_saved(cpu, (H, W), pred.tile_size)) < 0.02, name
            # the texture path: the budget stays on the GPU, the rates the same
            buffer = ctx.buffer(np.ascontiguousarray(raw[0] if raw.ndim == 4 else raw, np.float32).tobytes())
            texture = selector.select_buffer(buffer, pred.tiles(H, W), saving=0.5, frame_size=(H, W))
            codes = np.frombuffer(texture.read(alignment=1), np.uint8).reshape(pred.tiles(H, W))
            np.testing.assert_array_equal(codes, selector.select(raw, saving=0.5, frame_size=(H, W)))
            buffer.release()
    meta = sdk.load("jnyang").metadata
    raw = np.random.default_rng(2).random((len(meta.outputs), 3, 5)).astype(np.float32)
    with RateSelector(meta, gl_context) as selector:
        with pytest.raises(RendererError, match="no budget selected yet"):
            selector.budget()
        with pytest.raises(sdk.ParameterError, match="saving"):
            selector.select(raw, saving=0.95)  # more than 4x4 everywhere saves
        with pytest.raises(sdk.ParameterError, match="saving"):
            selector.select(raw, saving=0.6, allowed=["1x2"])  # more than 1x2 everywhere saves
        with pytest.raises(sdk.InputShapeError, match="do not cover"):
            selector.select(raw, saving=0.5, frame_size=(100, 80))
        with pytest.raises(sdk.ParameterError, match="combiner"):
            selector.select(raw, saving=0.5, engine_rates=sdk.RATE_CODES["2x2"], combiner="override")
        with pytest.raises(sdk.ParameterError, match="threshold"):
            selector.select(raw, -1.0, saving=0.5)  # a floor is a threshold like any other
        with pytest.raises(sdk.ParameterError, match="frame_size: it weighs a budget's tiles"):
            selector.select(raw, frame_size=(48, 80))  # (without a budget it would weigh nothing)
        selector.select(raw, saving=0.5)
        assert selector.budget()[1] >= 0.5
        # a call refused after the budget's checks (here its engine_rates of another grid) leaves budget() on the
        # last budget drawn: it divided that budget's saving by the refused frame's work (52.5 % read as 94 %)
        selector.select(raw, saving=0.5, frame_size=(48, 80))
        before = selector.budget()
        buffer = gl_context.buffer(np.ascontiguousarray(raw, np.float32).tobytes())
        refused = {"saving": 0.5, "frame_size": (33, 65), "engine_rates": np.zeros((2, 2), np.uint8)}
        for call in (lambda: selector.select(raw, **refused), lambda: selector.select_buffer(buffer, (3, 5), **refused)):
            with pytest.raises(sdk.InputShapeError):
                call()
            assert selector.budget() == before
        buffer.release()



@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(psnr=st.booleans(),
       allowed=st.sets(st.sampled_from(sdk.PREDICTED_RATES)).map(lambda s: tuple(r for r in sdk.PREDICTED_RATES if r in s)),
       tiles=st.tuples(st.integers(1, 20), st.integers(1, 20)), seed=st.integers(0, 2**16), share=st.floats(0.0, 1.0),
       frame=st.booleans(), combiner=st.sampled_from(["min", "max", "sum"]), texture=st.booleans(),
       floor=st.one_of(st.none(), st.floats(0.05, 0.95)), nans=st.integers(0, 2))
def test_a_budget_beside_the_engines_rates_decides_as_the_sdk(gl_context: Any, psnr: bool, allowed: tuple[str, ...],
                                                              tiles: tuple[int, int], seed: int, share: float,
                                                              frame: bool, combiner: str, texture: bool,
                                                              floor: float | None, nans: int) -> None:
    """select(raw, saving=, engine_rates=, combiner=) against sdk.select_rates_for_saving(engine_rates=) on the values
    the shader decoded: the engine's saving counted, the image adding only what is missing, every combiner and
    allowed set (the clamps), the engine's rates as an array or a texture, partial edge tiles, a floor, NaN tiles."""
    meta = _generated_metadata({"type": "clamped", "mu_y": 0.5}, list(sdk.PREDICTED_RATES), 2.0, 0.0, 1, None, psnr)
    rng = np.random.default_rng(seed)
    raw = rng.random((6, *tiles)).astype(np.float32)
    raw.flat[rng.integers(raw.size, size=nans)] = np.nan
    hib = meta.higher_is_better
    rates = list(allowed) or ["1x1"]
    codes = [sdk.RATE_CODES[r] for r in ("1x1", *allowed)]
    engine = rng.choice(codes, tiles).astype(np.uint8)
    saving = share * max(sdk.work_saved(r) for r in rates)
    values = meta.decode(raw)
    finite = values[np.isfinite(values)]
    assume(finite.size > 0)
    threshold = None
    if floor is not None:
        threshold = float(np.quantile(finite, floor))
        threshold = threshold if psnr else max(threshold, 0.0)
    ts = meta.tile_size
    frame_size = (tiles[0] * ts - int(rng.integers(ts)), tiles[1] * ts - int(rng.integers(ts))) if frame else None
    weigh = {"frame_size": frame_size, "tile_size": ts} if frame else {}
    with RateSelector(meta, gl_context) as selector:
        given_rates: Any = engine
        if texture:
            given_rates = gl_context.texture((tiles[1], tiles[0]), 1, engine.tobytes(), dtype="u1")
        gpu = selector.select(raw, threshold, allowed=rates, saving=saving, frame_size=frame_size,
                              engine_rates=given_rates, combiner=combiner)
        found, saved = selector.budget()
        decoded = selector.decoded().astype(np.float64)
        if texture:
            given_rates.release()
    cpu = sdk.select_rates_for_saving(decoded, saving, higher_is_better=hib, allowed=rates, threshold=threshold,
                                      engine_rates=engine, combiner=combiner, **weigh)
    np.testing.assert_array_equal(gpu, cpu.rates)
    assert saved == pytest.approx(float(cpu.saved), abs=1e-9)
    assert found == pytest.approx(float(cpu.threshold), rel=1e-6, abs=1e-37)
    shaded = sdk.combine_rates(gpu, engine, combiner, allowed=rates)
    assert saved == pytest.approx(sdk.work_saved(shaded, **weigh), abs=1e-9)  # the device's saving, as it shades


def test_a_selector_whose_construction_fails_releases_what_it_made(gl_context: Any,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """A shader that did not compile (or any later step of the constructor that raised) left the selector's own
    context and the objects made so far held: the selector was never returned, so nothing could close them. Now the
    constructor frees them before the error goes on: its own context released, a borrowed one's objects too."""
    from rtp.plugins.moderngl import _select, create_context

    meta = sdk.load("jnyang").metadata
    made: list[Any] = []

    def recorded(require: int = 330) -> Any:
        made.append(create_context(require))
        return made[-1]

    try:
        monkeypatch.setattr(_select, "create_context", recorded)
        monkeypatch.setattr(_select, "load_source", lambda name: "#version 430\nthis is no GLSL;\n")
        with pytest.raises(Exception, match="(?i)compil|error"):
            RateSelector(meta)
        assert len(made) == 1 and is_released(made[0])  # (held until the process ended, before)
        monkeypatch.undo()
        # a borrowed context: a step after the program (the budget's buffer) fails; the program is released, the
        # context stays the engine's
        ctx = create_context(430)
        programs: list[Any] = []
        compile_shader = ctx.compute_shader

        def compiled(source: str) -> Any:
            programs.append(compile_shader(source))
            return programs[-1]

        make = ctx.buffer

        def no_room(*args: Any, **kwargs: Any) -> Any:
            if "reserve" in kwargs:
                raise MemoryError("no room for the budget's buffer")
            return make(*args, **kwargs)  # (the selector's 16-byte sentinel, made first)

        ctx.compute_shader, ctx.buffer = compiled, no_room
        with pytest.raises(MemoryError):
            RateSelector(meta, ctx)
        assert len(programs) == 1 and is_released(programs[0]) and not is_released(ctx)
        ctx.release()
    finally:
        make_current(gl_context)


def test_a_selector_whose_buffer_could_not_be_made_works_on(gl_context: Any) -> None:
    """A buffer the context had no room for (a new grid's decoded values, a new size of the network's output) left
    the selector holding the old one released: every later call failed with an AttributeError, the same grid's (it
    reused the released objects) and another's (it released them again). Now the call fails alone."""
    from rtp.plugins.moderngl import create_context

    pred = sdk.load("jnyang")
    rng = np.random.default_rng(3)
    small, large = rng.random((4, 3, 5)).astype(np.float32), rng.random((4, 4, 6)).astype(np.float32)
    ctx = create_context(430)
    make = ctx.buffer
    try:
        with RateSelector(pred.metadata, ctx) as selector:
            want = {a.shape: selector.select(a) for a in (small, large)}
            selector.select(small)
            for fails in ("reserve", "data"):  # the decoded values' buffer, the output's upload
                def no_room(data: Any = None, *args: Any, fails: str = fails, **kwargs: Any) -> Any:
                    if (fails == "reserve") == ("reserve" in kwargs):
                        raise MemoryError("no room")
                    return make(data, *args, **kwargs)

                ctx.buffer = no_room
                with pytest.raises(MemoryError):
                    selector.select(large)
                ctx.buffer = make
                for a in (small, large, small):
                    np.testing.assert_array_equal(selector.select(a), want[a.shape])
    finally:
        ctx.release()
        make_current(gl_context)


def test_an_engine_rate_given_by_its_name_decides_as_by_its_code(gl_context: Any) -> None:
    """``engine_rates="2x2"`` (a rate name, which ``sdk.select_rates`` takes as one code over the frame) failed in the
    upload with a bare ValueError ("invalid literal for int()"), a budget beside it too; now it is the code's rates."""
    pred = sdk.load("jnyang")
    raw = np.random.default_rng(5).random((4, 3, 5)).astype(np.float32)
    with RateSelector(pred, gl_context) as selector:
        for name in ("2x1", "2x2", "1x1"):
            for combiner in ("max", "min", "sum"):
                by_code = selector.select(raw, engine_rates=sdk.RATE_CODES[name], combiner=combiner)
                np.testing.assert_array_equal(selector.select(raw, engine_rates=name, combiner=combiner), by_code)
                np.testing.assert_array_equal(by_code, sdk.select_rates(
                    selector.decoded(), pred.metadata.default_threshold, factors=pred.metadata.rate_factors,
                    engine_rates=name, combiner=combiner))
        budget = selector.select(raw, saving=0.8, engine_rates=sdk.RATE_CODES["2x2"])
        np.testing.assert_array_equal(selector.select(raw, saving=0.8, engine_rates="2x2"), budget)
        with pytest.raises(sdk.ParameterError, match="engine_rates: unknown shading rate '3x3'"):
            selector.select(raw, engine_rates="3x3")


def test_a_threshold_the_model_cannot_reach_is_said_as_shading_rates_says_it(tiny_model, gl_context: Any,
                                                                            caplog: pytest.LogCaptureFixture) -> None:
    """A threshold beyond the worst value the model can express (every tile at the coarsest rate) or beyond the best
    (no tile passes: every tile 1x1, VRS off, a threshold in another metric's units) was said by shading_rates and
    PredictionReuse once per threshold and by the GPU selector never: an engine that keeps its predictions on the
    GPU saved nothing, or everything, in silence. Now select and select_buffer log the same words once per threshold
    (ModelMetadata.threshold_warning, one source for both), for the first 16 thresholds as the predictor does; a
    budget's floor past saturation too (below the best value the budget's rates are taken, as without a floor)."""
    w = np.zeros((2, 4), np.float32)
    w[:, 0] = -40.0  # sigmoid(-40 x): the best output, 0, where plane 0 is 1 (clamped, mu 0.25, safety 0.1: 0.05)
    x = np.zeros((4, 16, 32), np.float32)
    x[0] = 1.0
    pred = sdk.load(tiny_model(base_metadata(outputs=["1x2", "2x1"], safety=0.1, default_threshold=0.2), weights=w))
    raw = pred.predict_raw(x)
    caplog.set_level(logging.WARNING, logger="rtp")

    def said(logger: str) -> list[str]:
        return [r.getMessage() for r in caplog.records if r.name.startswith(logger)]

    thresholds = (0.04, 0.2, 100.0, 0.04, 100.0, 0.06)  # beyond the best, fine, beyond the worst, again, fine
    with RateSelector(pred, gl_context) as selector:
        for t in thresholds:
            np.testing.assert_array_equal(selector.select(raw, t), pred.shading_rates(x, threshold=t))
        gpu, cpu = said("rtp.plugins.moderngl"), said("rtp.sdk")
        assert len(gpu) == 2 and gpu == cpu, (gpu, cpu)
        assert gpu[0].startswith(f"{pred.path.name}: threshold 0.04 is beyond the best value the model can express")
        assert "use one above 0.05" in gpu[0] and "threshold 100 is beyond the worst value" in gpu[1]
        caplog.clear()
        selector.select(raw)  # the default, 0.2: nothing to say
        # a budget's floor past saturation: every tile at the coarsest rate (a new threshold: said once more)
        for _ in range(2):
            np.testing.assert_array_equal(selector.select(raw, 200.0, saving=0.5),
                                          pred.shading_rates(x, threshold=200.0, saving=0.5))
        selector.select(raw, 0.01, saving=0.5)  # below the best value under a budget: the budget's rates, as without
        pred.shading_rates(x, threshold=0.01, saving=0.5)
        gpu, cpu = said("rtp.plugins.moderngl"), said("rtp.sdk")
        assert len(gpu) == 1 and gpu == cpu and "threshold 200 is beyond the worst value" in gpu[0], (gpu, cpu)
        caplog.clear()
    # select_buffer (the engine's own buffer) says it too; a selector of metadata alone names no file
    with RateSelector(pred.metadata, gl_context) as selector:
        buffer = gl_context.buffer(np.ascontiguousarray(raw, np.float32).tobytes())
        for _ in range(2):
            selector.select_buffer(buffer, raw.shape[-2:], 0.04)
        selector.select_buffer(buffer, raw.shape[-2:], 300.0, saving=0.5)
        buffer.release()
    gpu = said("rtp.plugins.moderngl")
    assert len(gpu) == 2 and gpu[0].startswith("model: threshold 0.04 is beyond the best value"), gpu
    assert gpu[1].startswith("model: threshold 300 is beyond the worst value"), gpu
    caplog.clear()
    # a controller that moves a threshold past saturation every frame: the first 16 said, the 16th saying so
    fresh = sdk.load(pred.path)
    with RateSelector(fresh, gl_context) as selector:
        for i in range(20):
            selector.select(raw, 1000.0 + i)
            fresh.shading_rates(x, threshold=1000.0 + i)
    gpu, cpu = said("rtp.plugins.moderngl"), said("rtp.sdk")
    assert len(gpu) == 16 and gpu == cpu and "further thresholds are not logged" in gpu[-1]


def test_a_call_ends_with_a_memory_barrier_before_its_writes_are_read(gl_context: Any) -> None:
    """The dispatch writes the rate image and the decoded values through image stores and storage-buffer writes,
    which GL makes visible to later reads only after a ``glMemoryBarrier``: ``select`` read the image back
    (``glGetTexImage``), ``decoded()`` and ``budget()`` mapped the buffers, and an engine fetched ``select_buffer``'s
    image, all with no barrier after the last dispatch (llvmpipe finishes a dispatch at once; a GPU may not). Now
    every call's last dispatch is followed by a barrier over every kind of read, with a budget too."""
    import moderngl

    from rtp.plugins.moderngl import create_context

    pred = sdk.load("jnyang")
    raw = np.random.default_rng(7).random((4, 3, 5)).astype(np.float32)
    ctx = create_context(430)
    try:
        with RateSelector(pred, ctx) as selector:
            events: list[Any] = []
            barrier, run = ctx.memory_barrier, selector._program.run

            def recorded_barrier(barriers: int = moderngl.ALL_BARRIER_BITS, by_region: bool = False) -> None:
                events.append(("barrier", barriers))
                barrier(barriers, by_region)

            def recorded_run(*args: Any, **kwargs: Any) -> None:
                events.append(("run", None))
                run(*args, **kwargs)

            ctx.memory_barrier, selector._program.run = recorded_barrier, recorded_run
            needed = (moderngl.TEXTURE_UPDATE_BARRIER_BIT | moderngl.BUFFER_UPDATE_BARRIER_BIT
                      | moderngl.TEXTURE_FETCH_BARRIER_BIT | moderngl.SHADER_IMAGE_ACCESS_BARRIER_BIT)
            for call in (lambda: selector.select(raw), lambda: selector.select(raw, saving=0.5),
                         lambda: selector.select_buffer(selector._raw, (3, 5))):
                events.clear()
                call()
                last_run = max(i for i, (kind, _) in enumerate(events) if kind == "run")
                after = [bits for kind, bits in events[last_run + 1:] if kind == "barrier"]
                assert after and after[0] & needed == needed, events
    finally:
        ctx.release()
        make_current(gl_context)


def test_a_call_from_a_thread_where_the_context_cannot_be_current_is_refused(gl_context: Any) -> None:
    """A GL context is current in one thread at a time, and moderngl's ``ctx.__enter__()`` says nothing when EGL
    refuses it: ``select`` from a worker thread while the engine's thread held the context ran in no context and
    returned uninitialised memory as rate codes, in silence (``budget()`` a bare ``moderngl.Error``). Now such a call
    is a RendererError naming the thread, and the context handed over (released in one thread, then used in the
    other) works in either."""
    from rtp.plugins.moderngl import create_context

    pred = sdk.load("jnyang")
    raw = np.random.default_rng(9).random((4, 5, 7)).astype(np.float32)

    ctx = create_context(430)
    try:
        with RateSelector(pred, ctx) as selector:
            want = selector.select(raw, saving=0.5)
            for call in (lambda: selector.select(raw), selector.decoded, selector.budget,
                         lambda: selector.select_buffer(selector._raw, (5, 7))):
                with pytest.raises(RendererError, match="could not be made current in this thread .*'worker'"):
                    in_thread(call)
            np.testing.assert_array_equal(selector.select(raw, saving=0.5), want)  # (the engine's thread: as before)
            ctx.__exit__(None, None, None)  # handed over: released here, made current there by the call

            def there() -> np.ndarray:
                rates = selector.select(raw, saving=0.5)
                ctx.__exit__(None, None, None)  # (handed back)
                return rates

            np.testing.assert_array_equal(in_thread(there), want)
            np.testing.assert_array_equal(selector.select(raw, saving=0.5), want)
        with pytest.raises(RendererError, match="could not be made current"):
            in_thread(lambda: RateSelector(pred, ctx))  # (a borrowed context current here: nothing made there)
    finally:
        ctx.release()
        make_current(gl_context)


def test_closing_from_a_thread_where_the_context_cannot_be_current_frees_nothing_of_another_context(
        gl_context: Any, caplog: pytest.LogCaptureFixture) -> None:
    """``close`` from a worker thread while the engine's thread held the selector's borrowed context: EGL refused its
    ``ctx.__enter__()`` in silence and the selector freed its programs, buffers and texture by name in the worker's
    current context (an engine's other context lost the buffers and textures of those names). Now nothing is freed
    there, one warning names the selector, the thread and the fix, and the selector is closed; a selector's own
    context is released from any thread (its objects go with it), unsaid."""
    from rtp.plugins.moderngl import create_context
    from tests.test_moderngl_adapter import close_beside_another_context

    pred = sdk.load("jnyang")
    raw = np.random.default_rng(9).random((4, 5, 7)).astype(np.float32)
    ctx = create_context(430)
    try:
        with caplog.at_level(logging.WARNING, logger="rtp.plugins.moderngl"):
            selector = RateSelector(pred, ctx)
            selector.select(raw, saving=0.5)
            assert close_beside_another_context(selector.close) == []
            with pytest.raises(RendererError, match="RateSelector: closed"):
                selector.select(raw)
            own = RateSelector(pred)
            own.select(raw, saving=0.5)
            assert close_beside_another_context(own.close) == []
            assert is_released(own.ctx)
        said = [rec.getMessage() for rec in caplog.records]
        assert len(said) == 1 and said[0].startswith(
            "an rtp RateSelector closed in thread 'worker', where its moderngl context is not current: its compute "
            "programs, buffers and rate texture were not freed") and "ctx.__exit__(None, None, None)" in said[0], said
    finally:
        ctx.release()
        make_current(gl_context)


def test_the_selectors_own_rate_texture_as_the_engine_rates_of_a_budget_is_refused(gl_context: Any) -> None:
    """``select(..., saving=, engine_rates=<the texture select_buffer returns>)``: the budget's first dispatch writes
    that texture, and the budget's dispatch and the selection at its threshold then read the first dispatch's rates as
    the engine's, in silence (rates of another saving than a copy of the same engine rates gives). Now a
    ParameterError naming engine_rates; without a budget the texture is read as it is (each tile's own texel, before
    the dispatch writes it), as before."""
    pred = sdk.load("jnyang")
    raw = np.random.default_rng(12).random((4, 5, 7)).astype(np.float32)
    with RateSelector(pred, gl_context) as selector:
        engine = selector.select(raw, 0.02)  # the engine's rates: last frame's image, copied
        want = selector.select(raw, saving=0.5, engine_rates=engine)
        texture = selector.select_buffer(selector._raw, (5, 7), 0.02)  # the selector's own texture holds them again
        with pytest.raises(sdk.ParameterError, match="engine_rates: this is the selector's own rate texture"):
            selector.select(raw, saving=0.5, engine_rates=texture)
        with pytest.raises(sdk.ParameterError, match="engine_rates: this is the selector's own rate texture"):
            selector.select_buffer(selector._raw, (5, 7), saving=0.5, engine_rates=texture)
        np.testing.assert_array_equal(selector.select(raw, engine_rates=texture),  # (no budget: read as it is)
                                      selector.select(raw, engine_rates=engine))
        np.testing.assert_array_equal(selector.select(raw, saving=0.5, engine_rates=engine), want)
