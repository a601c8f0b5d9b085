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


def _gbuffers(symmetry: int, n: int = 64) -> dict[str, np.ndarray]:
    """One frame's G-buffers (a camera at the world's origin, a square frame, a symmetric frustum), moved as an image by
    ``SYMMETRIES[symmetry]``: the frame of the mirrored (transposed) world, with the previous camera mirrored too. A
    flip of the columns mirrors view x (x -> -x), of the rows view y; a transpose (the new right the old down, the new
    down the old right; view y points up) maps (x, y) to (-y, -x). The normal turns with the world."""
    rng = np.random.default_rng(6)
    yy, xx = np.mgrid[0:n, 0:n] / n
    depth = (3 + 1.5 * xx + 0.7 * yy + 0.3 * np.sin(7 * xx * yy)).astype(np.float32)
    depth[20:40, 10:30] -= 1.0  # a step: depth edges
    depth[:5, 50:] = 0.0  # background
    normal = rng.normal(size=(n, n, 3))
    normal = (normal / np.linalg.norm(normal, axis=-1, keepdims=True)).astype(np.float32)
    albedo = rng.random((n, n, 3), dtype=np.float32)
    prev_colour = np.clip(0.5 * rng.random((n, n, 3)) + 0.5 * xx[..., None], 0.0, 1.0).astype(np.float32)
    roughness = rng.random((n, n), dtype=np.float32)
    c, s = np.cos(0.05), np.sin(0.05)
    prev_view = np.array([[c, 0, s, 0.1], [0, 1, 0, -0.07], [-s, 0, c, 0.05], [0, 0, 0, 1]])  # turned and moved
    near, far = 0.1, 100.0
    projection = np.array([[1.2, 0, 0, 0], [0, 1.2, 0, 0], [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
                           [0, 0, -1, 0]])
    transpose, flip_rows, flip_cols = SYMMETRIES[symmetry]
    world = np.diag([-1.0 if flip_cols else 1.0, -1.0 if flip_rows else 1.0, 1.0, 1.0])
    if transpose:  # applied first, as augment_sample does
        world = world @ np.array([[0, -1.0, 0, 0], [-1.0, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])

    def image(a: np.ndarray) -> np.ndarray:
        a = a.swapaxes(0, 1) if transpose else a
        a = a[::-1] if flip_rows else a
        return np.ascontiguousarray(a[:, ::-1] if flip_cols else a)

    turned = (normal @ world[:3, :3].T).astype(np.float32)
    return {"depth": image(depth), "normal": image(turned), "albedo": image(albedo), "roughness": image(roughness),
            "prev_colour": image(prev_colour), "prev_depth": image(depth), "view": np.eye(4), "projection": projection,
            "prev_view_projection": projection @ world @ prev_view @ np.linalg.inv(world)}


def test_every_channel_of_a_moved_crop_is_the_channel_of_the_moved_frame() -> None:
    # The property behind --augment and --mirror: a crop cut from a frame (Frame, crop_batch: the training pipeline's
    # own code) and moved by each symmetry reads, channel by channel, what sdk.input_planes makes of the G-buffers of
    # the moved world (normals turned, the previous camera mirrored) at the moved crop's place. Crops at the frame's
    # corners and inside it; the packed planes under the flips (a transpose refuses them); a .dx (.dy) plane but for
    # the last column (row) of a crop flipped along it, whose neighbour lies outside the crop.
    from rtp import sdk
    from rtp.train._frames import Frame, crop_batch

    n = 64
    plain = ("reprojected.r", "reprojected.y", "seen", "albedo.y", "normal.x", "normal.y", "normal.z", "depth",
             "depth.edge", "motion.x", "motion.y", "reprojected.y.dx", "reprojected.y.dy", "roughness")
    packed = ("reprojected.y.blocks", "albedo.y.blocks", "reprojected.y.tiles", "albedo.y.tiles")
    six = ("1x2", "2x1", "2x2", "2x4", "4x2", "4x4")
    frame = sdk.input_planes(plain + packed, tolerance=0.3, **_gbuffers(0, n))
    assert 0.2 < frame[2].mean() < 0.95 and np.abs(frame[9]).max() > 1  # (seen and unseen pixels, motion)
    for sym, (transpose, flip_rows, flip_cols) in enumerate(SYMMETRIES):
        ins = plain if transpose else plain + packed
        moved = Frame(sdk.input_planes(ins, tolerance=0.3, **_gbuffers(sym, n)), ins)
        source = Frame(frame[: len(ins)], ins)
        for oy, ox, side in ((0, 0, n), (16, 16, 32), (0, 32, 32), (32, 16, 32)):
            x = crop_batch([source], [oy], [ox], side)[0]
            tiles = side // 16
            y = np.arange(6 * tiles * tiles, dtype=np.float32).reshape(6, tiles, tiles)
            xa, ya = augment_sample(x, y, ins, six, sym)
            my, mx = (ox, oy) if transpose else (oy, ox)  # where the crop lies in the moved frame
            my, mx = (n - my - side if flip_rows else my), (n - mx - side if flip_cols else mx)
            want = moved.crop(my, mx, side).astype(np.float32)
            for i, name in enumerate(ins):
                got, exp = xa[i].astype(np.float32), want[i]
                if name.endswith(".dx") and flip_cols:
                    got, exp = got[:, :-1], exp[:, :-1]
                if name.endswith(".dy") and flip_rows:
                    got, exp = got[:-1], exp[:-1]
                assert np.allclose(got, exp, atol=2e-3), (SYMMETRIES[sym], (oy, ox, side), name)
            # the targets: each tile's values moved with it, 1x2 <-> 2x1 and 2x4 <-> 4x2 swapped by a transpose
            t = y.swapaxes(1, 2)[[1, 0, 2, 4, 3, 5]] if transpose else y
            t = t[:, ::-1] if flip_rows else t
            assert np.array_equal(ya, t[:, :, ::-1] if flip_cols else t), SYMMETRIES[sym]
