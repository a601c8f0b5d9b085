"""Training augmentations keep the targets true (train/_augment.py)."""

from __future__ import annotations

import numpy as np
import pytest

from rtp.train._augment import SYMMETRIES, augment_sample

OUTPUTS = ("1x2", "2x1", "2x4", "4x2")


def _crop() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    return rng.random((4, 32, 32), dtype=np.float32), rng.random((4, 2, 2), dtype=np.float32)


def test_identity_and_involutions() -> None:
    x, y = _crop()
    ins = ("reprojected.r", "seen", "albedo.r", "normal.z")
    x0, y0 = augment_sample(x, y, ins, OUTPUTS, 0)
    assert np.array_equal(x0, x) and np.array_equal(y0, y)
    for s in range(len(SYMMETRIES)):
        xa, ya = augment_sample(x, y, ins, OUTPUTS, s)
        assert xa.shape == x.shape and ya.shape == y.shape
    xt, yt = augment_sample(*augment_sample(x, y, ins, OUTPUTS, 4), ins, OUTPUTS, 4)  # transpose twice
    assert np.array_equal(xt, x) and np.array_equal(yt, y)


def test_transpose_swaps_the_rates_of_transposed_blocks() -> None:
    x, y = _crop()
    xt, yt = augment_sample(x, y, ("reprojected.r", "seen", "albedo.r", "normal.z"), OUTPUTS, 4)
    assert np.array_equal(xt[2], x[2].T)
    assert np.array_equal(yt[0], y[1].T) and np.array_equal(yt[1], y[0].T)  # 1x2 <-> 2x1
    assert np.array_equal(yt[2], y[3].T) and np.array_equal(yt[3], y[2].T)  # 2x4 <-> 4x2
    six = ("1x2", "2x1", "2x2", "2x4", "4x2", "4x4")
    y6 = np.random.default_rng(1).random((6, 2, 2), dtype=np.float32)
    _, y6t = augment_sample(x, y6, ("reprojected.r", "seen", "albedo.r", "normal.z"), six, 4)
    assert np.array_equal(y6t[2], y6[2].T) and np.array_equal(y6t[5], y6[5].T)  # square rates stay


def test_flips_move_tiles_and_turn_directions() -> None:
    x, y = _crop()
    ins = ("normal.x", "normal.y", "motion.x", "motion.y")
    xh, yh = augment_sample(x, y, ins, OUTPUTS, SYMMETRIES.index((False, False, True)))  # columns reversed
    assert np.array_equal(yh, y[:, :, ::-1])
    assert np.allclose(xh[0], -x[0][:, ::-1]) and np.allclose(xh[1], x[1][:, ::-1])  # normal.x turns
    assert np.allclose(xh[2], -x[2][:, ::-1]) and np.allclose(xh[3], x[3][:, ::-1])  # motion.x turns
    xv, _ = augment_sample(x, y, ins, OUTPUTS, SYMMETRIES.index((False, True, False)))  # rows reversed
    assert np.allclose(xv[1], -x[1][::-1]) and np.allclose(xv[3], -x[3][::-1])
    xt, _ = augment_sample(x, y, ins, OUTPUTS, 4)
    # the new right is the old down: normal.x' = -normal.y, motion.x' = motion.y
    assert np.allclose(xt[0], -x[1].T) and np.allclose(xt[1], -x[0].T)
    assert np.allclose(xt[2], x[3].T) and np.allclose(xt[3], x[2].T)


def test_a_lone_direction_channel_cannot_be_transposed() -> None:
    x, y = _crop()
    with pytest.raises(ValueError, match="normal.y"):
        augment_sample(x, y, ("normal.x", "seen", "albedo.r", "normal.z"), OUTPUTS, 4)


def test_packed_planes_flip_by_whole_cells_and_stay_true() -> None:
    # A flipped crop's .blocks and .tiles planes are exactly those of the flipped luma: the cells change
    # places and keep their layout (a rate's blocks, aligned to the cell, mirror onto the same blocks)
    from rtp.sdk import block_variances, tile_variances

    rng = np.random.default_rng(4)
    luma = rng.random((48, 64)).astype(np.float32)
    luma[:, 20:30] *= 0.1  # some structure besides noise
    ins = ("reprojected.y", "reprojected.y.blocks", "reprojected.y.tiles")
    x = np.stack([luma, block_variances(luma), tile_variances(luma)])
    y = rng.random((len(OUTPUTS), 3, 4)).astype(np.float32)
    for sym in (SYMMETRIES.index((False, False, True)), SYMMETRIES.index((False, True, False)),
                SYMMETRIES.index((False, True, True))):
        _, flip_rows, flip_cols = SYMMETRIES[sym]
        want = luma[::-1] if flip_rows else luma
        want = want[:, ::-1] if flip_cols else want
        xm, ym = augment_sample(x, y, ins, OUTPUTS, sym)
        assert np.array_equal(xm[0], want)
        assert np.allclose(xm[1], block_variances(want), atol=1e-5), sym
        assert np.allclose(xm[2], tile_variances(want), atol=1e-5), sym
        assert not np.allclose(xm[1], x[1][:, ::-1] if flip_cols else x[1][::-1], atol=1e-3)  # not a plain flip
    assert np.array_equal(augment_sample(x, y, ins, OUTPUTS, 0)[0], x)
    with pytest.raises(ValueError, match="never transpose"):
        augment_sample(x, y, ins, OUTPUTS, 4)
    with pytest.raises(ValueError, match="flip on whole cells"):
        augment_sample(x[:, :, :40], y, ins, OUTPUTS, 1)  # 40 columns: not whole 16-pixel tiles


def test_pixel_differences_turn_and_stay_on_the_first_pixel_of_their_pair() -> None:
    # A .dx plane holds each pixel's difference to its right neighbour, .dy to its lower one: a transpose swapped
    # nothing (the crop's 1x2 differences read as 2x1 ones) and a flip left each value on the second pixel of its
    # pair (the even columns, a 2-pixel block's own difference, then held the differences between blocks). Every
    # symmetry now gives the planes of the moved luma, but for the last column (row): its neighbour is outside
    # the crop, and it reads 0, as a frame's last one does.
    from rtp.sdk import pixel_differences

    rng = np.random.default_rng(5)
    luma = rng.random((32, 48)).astype(np.float32)
    ins = ("reprojected.y", "reprojected.y.dx", "reprojected.y.dy")
    x = np.stack([luma, *pixel_differences(luma)])
    y = rng.random((len(OUTPUTS), 2, 3)).astype(np.float32)
    for sym, (_, flip_rows, flip_cols) in enumerate(SYMMETRIES):
        xa, _ = augment_sample(x, y, ins, OUTPUTS, sym)
        dx, dy = pixel_differences(xa[0])
        assert np.allclose(xa[1][:, :-1], dx[:, :-1]) and np.allclose(xa[2][:-1], dy[:-1]), SYMMETRIES[sym]
        if flip_cols:
            assert not xa[1][:, -1].any()
        if flip_rows:
            assert not xa[2][-1].any()
    with pytest.raises(ValueError, match="reprojected.y.dy"):
        augment_sample(x[:2], y, ins[:2], OUTPUTS, 4)
