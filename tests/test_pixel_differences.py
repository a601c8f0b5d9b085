"""``sdk.pixel_differences``, ``sdk.block_variances`` and ``sdk.tile_variances``: derived input planes of
what a shading block loses (``reprojected.y.dx`` / ``.dy``, ``*.y.blocks``, ``*.y.tiles``), defined once in
the SDK."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from rtp import sdk


@settings(max_examples=40, deadline=None)
@given(hnp.arrays(np.float32, hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=12),
                  elements=st.floats(0, 1, width=32)))
def test_each_pixel_holds_its_difference_to_the_right_and_below(p: np.ndarray) -> None:
    dx, dy = sdk.pixel_differences(p)
    assert dx.dtype == dy.dtype == np.float32 and dx.shape == dy.shape == p.shape
    h, w = p.shape
    for y in range(h):
        for x in range(w):
            assert dx[y, x] == (abs(p[y, x + 1] - p[y, x]) if x + 1 < w else 0.0)
            assert dy[y, x] == (abs(p[y + 1, x] - p[y, x]) if y + 1 < h else 0.0)
    # a transpose swaps the two planes: what the 1x2 and 2x1 rates would lose
    tx, ty = sdk.pixel_differences(p.T)
    np.testing.assert_array_equal(tx, dy.T)
    np.testing.assert_array_equal(ty, dx.T)


def test_a_block_constant_plane_differs_only_between_blocks() -> None:
    blocks = np.repeat(np.repeat(np.random.default_rng(0).random((3, 4)), 2, axis=0), 2, axis=1)
    dx, dy = sdk.pixel_differences(blocks)
    assert not dx[:, 0::2].any() and not dy[0::2].any()  # inside each 2x2 block nothing to lose
    assert dx[:, 1:-1:2].any() and dy[1:-1:2].any()


# ------------------------------------------------------------------- sdk.block_variances: the .blocks planes
def test_each_cell_packs_the_variance_inside_each_rates_blocks() -> None:
    p = np.random.default_rng(1).random((8, 12)).astype(np.float32)
    b = sdk.block_variances(p)
    assert b.dtype == np.float32 and b.shape == p.shape
    rates = ("1x2", "2x1", "2x2", "2x4", "4x2", "4x4")
    for cy in range(2):
        for cx in range(3):
            cell = p[4 * cy:4 * cy + 4, 4 * cx:4 * cx + 4].astype(np.float64)
            got = b[4 * cy:4 * cy + 4, 4 * cx:4 * cx + 4].ravel()
            for k, rate in enumerate(rates):
                w, h = sdk.rate_size(rate)
                var = cell.reshape(4 // h, h, 4 // w, w).var(axis=(1, 3)).mean()
                want = np.clip(np.log(var + 1e-4) / -np.log(1e-4) + 1.0, 0.0, 1.0)
                assert got[k] == pytest.approx(want, abs=1e-6), (cy, cx, rate)
            assert not got[6:].any()  # the cell's other pixels are 0
    # a larger block loses at least what the blocks inside it lose: 2x2 >= 1x2, 2x1; 4x4 >= 2x4, 4x2
    r12, r21, r22, r24, r42, r44 = b[0::4, 0::4], b[0::4, 1::4], b[0::4, 2::4], b[0::4, 3::4], b[1::4, 0::4], b[1::4, 1::4]
    assert np.all(r22 >= np.maximum(r12, r21) - 1e-6) and np.all(r44 >= np.maximum(r24, r42) - 1e-6)


def _block_variances_by_definition(plane: np.ndarray) -> np.ndarray:
    """The ``.blocks`` plane computed as its docstring defines it: a variance per block, per rate."""
    p = np.asarray(plane, np.float64)
    h, w = p.shape
    q = np.pad(p, ((0, -h % 4), (0, -w % 4)), mode="edge")
    out = np.zeros(q.shape, np.float32)
    for k, rate in enumerate(sdk.BLOCK_RATES):
        bw, bh = sdk.rate_size(rate)
        var = q.reshape(q.shape[0] // bh, bh, q.shape[1] // bw, bw).var(axis=(1, 3))
        per_cell = var.reshape(q.shape[0] // 4, 4 // bh, q.shape[1] // 4, 4 // bw).mean(axis=(1, 3))
        out[k // 4::4, k % 4::4] = np.clip(np.log(per_cell + 1e-4) / -np.log(1e-4) + 1.0, 0.0, 1.0)
    return out[:h, :w]


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(st.sampled_from([np.float32, np.float64]),
                  hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=21),
                  elements=st.floats(0, 1, width=32)))
def test_the_fast_sums_equal_a_variance_per_block(p: np.ndarray) -> None:
    """block_variances sums the squares of each cell's Haar details (several times faster than a
    variance per block and rate); it must read the same as the definition, flat cells exactly 0, and
    leave the caller's plane alone."""
    before = p.copy()
    got = sdk.block_variances(p)
    np.testing.assert_allclose(got, _block_variances_by_definition(p), rtol=0, atol=2e-6)
    np.testing.assert_array_equal(p, before)


def test_the_fast_sums_keep_flat_and_stepped_cells_exact() -> None:
    rng = np.random.default_rng(3)
    levels = np.round(rng.random((36, 52)) * 3) / 3  # few values: many flat blocks, many exact steps
    levels[:8, :8] = 0.7
    got = sdk.block_variances(levels)
    assert not got[:8, :8].any()
    np.testing.assert_array_equal(got, _block_variances_by_definition(levels))


def test_flat_planes_read_zero_and_partial_cells_repeat_the_edge() -> None:
    assert not sdk.block_variances(np.full((6, 9), 0.3, np.float32)).any()
    p = np.random.default_rng(2).random((10, 13)).astype(np.float32)
    padded = np.pad(p, ((0, 2), (0, 3)), mode="edge")
    np.testing.assert_array_equal(sdk.block_variances(p), sdk.block_variances(padded)[:10, :13])
    # a luma step of 1 inside every 1x2 block reads about 0.85
    stripes = np.tile(np.array([[0.0], [1.0]], np.float32), (4, 4))
    assert sdk.block_variances(stripes)[0, 0] == pytest.approx(np.log(0.25 + 1e-4) / -np.log(1e-4) + 1, abs=1e-6)
    assert sdk.block_variances(stripes)[0, 1] == 0.0  # 2x1 blocks (side by side) see no step


# ------------------------------------------------------------------- sdk.tile_variances: the .tiles planes
def test_each_tile_holds_the_mean_and_maximum_of_its_cells_block_variances() -> None:
    """Per 16x16 tile and rate: the log of the mean of the cells' variances (through the .blocks values)
    on value k, their maximum on value 6 + k, value j on the tile's pixel (j // 4, j % 4), 0 elsewhere; a
    partial tile summarises the cells it has."""
    rng = np.random.default_rng(4)
    p = (rng.random((40, 36)) ** 2).astype(np.float32)
    p[:16, :16] = 0.25  # a flat tile
    b, t = sdk.block_variances(p), sdk.tile_variances(p)
    assert t.dtype == np.float32 and t.shape == p.shape
    s = -np.log(sdk.BLOCK_EPS)
    for ty, tx in ((0, 0), (0, 1), (2, 2), (1, 2)):  # (2, 2): 8x4 pixels, two cells
        for k in range(6):
            cells = b[16 * ty + k // 4:16 * ty + 16:4, 16 * tx + k % 4:16 * tx + 16:4].astype(np.float64)
            mean = np.log(np.exp(s * (cells - 1.0)).mean()) / s + 1.0
            assert t[16 * ty + k // 4, 16 * tx + k % 4] == pytest.approx(mean, abs=1e-6)
            assert t[16 * ty + (6 + k) // 4, 16 * tx + (6 + k) % 4] == pytest.approx(cells.max(), abs=1e-7)
    assert not t[:16, :16].any()  # flat: the variance floor reads 0
    mask = np.ones((16, 16), bool)
    mask[:3, :4] = False
    assert not np.pad(t, ((0, 8), (0, 12))).reshape(3, 16, 3, 16).transpose(1, 3, 0, 2)[mask].any()
    assert 0.0 <= t.min() and t.max() <= 1.0


@pytest.mark.parametrize(("fn", "channels"), [
    ("pixel_differences", ("reprojected.y.dx", "reprojected.y.dy")),
    ("block_variances", ("reprojected.y.blocks", "albedo.y.blocks")),
    ("tile_variances", ("reprojected.y.tiles", "albedo.y.tiles")),
])
def test_the_planes_are_registered_channels(fn: str, channels: tuple[str, ...]) -> None:
    for c in channels:
        spec = sdk.CHANNELS[c]
        assert (spec.low, spec.high) == (0.0, 1.0) and fn in spec.description


@pytest.mark.parametrize("fn", ["pixel_differences", "block_variances", "tile_variances"])
@pytest.mark.parametrize(("bad", "error"), [
    (np.zeros(5, np.float32), sdk.InputShapeError),
    (np.zeros((0, 3), np.float32), sdk.InputShapeError),
    (np.zeros((3, 0), np.float32), sdk.InputShapeError),
    (np.array([["a"]]), sdk.InputShapeError),
    (np.array([[0.0, np.nan]], np.float32), sdk.NonFiniteInputError),
    (np.array([[0.0, np.inf]], np.float32), sdk.NonFiniteInputError),
    (np.array([[0.5, 0.5 + 1j]]), sdk.InputShapeError),  # (its imaginary parts dropped in silence before)
])
def test_bad_planes_are_typed_errors(fn: str, bad: np.ndarray, error: type[Exception]) -> None:
    with pytest.raises(error, match=fn):
        getattr(sdk, fn)(bad)


def test_the_planes_benchmark_times_the_same_plane_as_the_definition() -> None:
    """bench/planes.py refuses to time a block_variances that differs from its definition."""
    script = Path(__file__).resolve().parents[1] / "bench" / "planes.py"
    out = subprocess.run([sys.executable, str(script), "--sizes", "36x20", "--repeats", "1"],
                         capture_output=True, text=True, check=True).stdout
    row = [line for line in out.splitlines() if line.startswith("| 36x20 |")]
    header = [line for line in out.splitlines() if line.startswith("| ms |")]  # (the unit names the size column)
    assert len(row) == 1 and len(header) == 1 and "tile_variances" in header[0], out
    assert len(row[0].split("|")) == len(header[0].split("|")) == 9, out  # seven timed columns
