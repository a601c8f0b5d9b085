"""Prediction reuse (``sdk.PredictionReuse``): carried estimates follow the surface, unseen tiles go
to 1x1 or are predicted afresh on crops that give the whole frame's estimates, bad input is refused."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rtp import sdk
from rtp.sdk._channels import BLOCK_EPS
from rtp.sdk._reuse import (
    PLACE_BITS,
    Track,
    carry_estimates,
    context_tiles,
    cover,
    default_step,
    start_track,
    tile_block_levels,
    tile_index_map,
)

from .conftest import bench_module

TILE = 16


def test_carried_estimates_follow_the_surface() -> None:
    """A still camera keeps every estimate; a whole-tile shift moves them; an unseen tile gets 1x1
    (every second pixel kept per axis: the fractions below count eighths of a tile)."""
    th, tw = 3, 4
    h, w = th * TILE, tw * TILE
    est = np.random.default_rng(1).random((6, th, tw)).astype(np.float32)
    rows, cols = np.indices((h, w))
    ones = np.ones((h, w), np.float32)
    track = start_track((h, w), TILE, 2)

    def carry(c: np.ndarray, seen: np.ndarray = ones, reduce: str = "mean", hib: bool = False) -> np.ndarray:
        return carry_estimates(est, track, rows, c, seen, None, TILE, hib, 0.5, reduce, 2)[0]

    out, track2, missing = carry_estimates(est, track, rows, cols, ones, None, TILE, False, 0.5, step=2)
    assert np.array_equal(out, est) and not missing.any()
    for a, b in zip((track2.index, track2.place, track2.gen), (track.index, track.place, track.gen)):
        assert np.array_equal(a, b)
    assert np.array_equal(carry(np.maximum(cols - TILE, 0))[:, :, 1:], est[:, :, :-1])  # one tile left before
    seen = ones.copy()
    seen[:TILE, :TILE] = 0
    out, _, missing = carry_estimates(est, track, rows, cols, seen, None, TILE, False, 0.5, step=2)
    assert np.isinf(out[:, 0, 0]).all() and np.array_equal(out[:, 1:], est[:, 1:])
    assert missing[0, 0] and missing.sum() == 1
    # half a tile right: each tile's pixels come half from its own source tile, half from the one
    # to its left; the worst takes the larger estimate, the mean their average
    half = np.maximum(cols - TILE // 2, 0)
    worst = carry(half, reduce="worst")
    assert np.allclose(worst[:, :, 1:], np.maximum(est[:, :, 1:], est[:, :, :-1]))
    assert np.allclose(carry(half)[:, :, 1:], (est[:, :, 1:] + est[:, :, :-1]) / 2)
    assert np.allclose(carry(half, reduce="upper"), worst)
    # two pixels right: an eighth of each tile comes from its left neighbour; the upper quartile
    # ignores that sliver, the worst does not (PSNR models: the lower quartile, the same tile)
    sliver = np.maximum(cols - 2, 0)
    assert np.allclose(carry(sliver, reduce="upper"), est)
    assert np.allclose(carry(sliver, reduce="upper", hib=True), est)
    assert np.allclose(carry(sliver, reduce="worst")[:, :, 1:], np.maximum(est[:, :, 1:], est[:, :, :-1]))
    for reduce in ("worst", "upper"):  # unseen tiles: 1x1 whatever the reduction
        assert np.isinf(carry(cols, seen, reduce)[:, 0, 0]).all()
    # background keeps the estimate at its own screen position, seen or not
    sky = np.zeros((h, w), np.float32)
    sky[:TILE, :TILE] = 1
    out = carry_estimates(est, track, rows, np.maximum(cols - TILE, 0), seen, sky, TILE, False, 0.5, step=2)[0]
    assert np.array_equal(out[:, 0, 0], est[:, 0, 0])


def test_the_default_step_keeps_four_pixels_per_tile_and_axis() -> None:
    assert {t: default_step(t) for t in (1, 4, 5, 7, 8, 12, 16, 32)} == {1: 1, 4: 1, 5: 1, 7: 1, 8: 2, 12: 3, 16: 4,
                                                                         32: 8}
    assert tile_index_map((48, 64), 16).shape == (12, 16) == start_track((48, 64), 16).place.shape


@pytest.mark.parametrize("step", [2, 4, 8])
def test_small_motions_add_up_as_one(step: int) -> None:
    """A camera panning a pixel a frame carries the estimates by three pixels after three frames, as
    one three-pixel pan does, whatever the kept pixels' spacing: the surfaces' positions are carried,
    so rounding to the kept pixels does not add up (rounding down would move them a whole step a
    frame; to the nearest, not at all)."""
    th, tw = 3, 5
    h, w = th * TILE, tw * TILE
    est = np.random.default_rng(2).random((6, th * tw)).astype(np.float32)
    rows, cols = np.indices((h, w))
    ones = np.ones((h, w), np.float32)
    for shift in (1, -1):
        once = start_track((h, w), TILE, step)
        for _ in range(3):  # a pixel a frame
            out, once, _ = carry_estimates(est, once, rows, np.clip(cols - shift, 0, w - 1), ones, None, TILE, False,
                                           0.5, step=step)
        jump = carry_estimates(est, start_track((h, w), TILE, step), rows, np.clip(cols - 3 * shift, 0, w - 1), ones,
                               None, TILE, False, 0.5, step=step)[0]
        assert np.allclose(out, jump)
        # the mean follows the surface: the kept pixels that moved 3 pixels out of their tile take the neighbour's
        kept = np.arange(0, TILE, step) - 3 * shift
        f = np.mean((kept < 0) | (kept >= TILE))
        grid = est.reshape(6, th, tw)
        mix = (1 - f) * grid + f * np.roll(grid, shift, axis=2)
        inner = slice(1, tw) if shift > 0 else slice(0, tw - 1)
        assert np.allclose(out[:, :, inner], mix[:, :, inner])


def _carry_by_loops(est: np.ndarray, track: Track, rows: np.ndarray, cols: np.ndarray, seen: np.ndarray,
                    sky: np.ndarray, tile: int, hib: bool, fraction: float, reduce: str,
                    s: int) -> tuple[np.ndarray, np.ndarray]:
    """carry_estimates written out pixel by pixel and tile by tile (one pixel of every ``s`` per axis):
    the reference for the vectorised one. Returns the estimates and each kept pixel's entry. The previous frame
    (the track's) may be of another size: its pixels and tiles are its own; sky's tiles the whole-frame run's
    (``track.origin``), which may be of a third size."""
    h, w = seen.shape
    th, tw = -(-h // tile), -(-w // tile)
    ph, pw = track.shape
    pth, ptw = -(-ph // tile), -(-pw // tile)
    oh, ow = track.origin or track.shape
    otw = -(-ow // tile)
    k = tile // s
    out = np.empty((len(est), th, tw))
    entry = np.full((th * k, tw * k), -1)
    worst = -np.inf if hib else np.inf
    for ty in range(th):
        for tx in range(tw):
            known, real = [], 0
            for i in range(ty * k, ty * k + k):
                for j in range(tx * k, tx * k + k):
                    y, x = min(i * s, h - 1), min(j * s, w - 1)
                    inside = i * s < h and j * s < w  # (past the frame: the padding, no pixel of a partial tile)
                    real += inside
                    src = -1
                    if sky[y, x] > 0.5:  # the whole-frame run's tile at the same place on the screen
                        sy, sx = min(int((y + 0.5) * oh / h), oh - 1), min(int((x + 0.5) * ow / w), ow - 1)
                        src = (sy // tile) * otw + sx // tile
                    elif seen[y, x] > 0:
                        r, c = int(rows[y, x]), int(cols[y, x])
                        ki, kj = r // s, c // s  # the kept pixel at or above-left of the fetched one
                        if track.index[ki, kj] >= 0:  # its surface's place, moved by the offset: that tile's entry
                            py = (int(track.place[ki, kj]) >> PLACE_BITS) + r - ki * s
                            px = (int(track.place[ki, kj]) & ((1 << PLACE_BITS) - 1)) + c - kj * s
                            there = track.lut[track.gen[ki, kj], min(max(py // tile, 0), pth - 1) * ptw
                                              + min(max(px // tile, 0), ptw - 1)]
                            src = int(there) if there >= 0 else int(track.index[ki, kj])
                    entry[i, j] = src
                    if src >= 0 and inside:
                        known.append(est[:, src])
            if not known or 1 - len(known) / real > fraction:
                out[:, ty, tx] = worst
                continue
            v = np.array(known, np.float64)  # (pixels, outputs)
            if reduce == "mean":
                out[:, ty, tx] = v.mean(axis=0)
            elif reduce == "worst":
                out[:, ty, tx] = v.min(axis=0) if hib else v.max(axis=0)
            else:  # the quartile towards the worse side
                order = np.sort(v, axis=0) if hib else -np.sort(-v, axis=0)
                out[:, ty, tx] = order[max(int(np.floor(0.25 * (len(v) - 1))), 0)]
    return out, entry


@pytest.mark.parametrize("reduce", sorted(sdk.REUSE_REDUCTIONS))
def test_carried_estimates_match_a_tile_by_tile_reference(reduce: str) -> None:
    """Random motion, disocclusion and sky on frames that are not whole tiles (the kept pixels' padding
    repeats the last row and column in the track, and is no pixel of a partial tile's reduction), odd
    tiles (every pixel kept by default), both error directions, the default pixel step and others (a
    step that is not a power of two divides), tracks whose surfaces lie anywhere on the frames of
    several generations, some of whose tiles are no entry; and a previous frame of another size than
    this one, larger or smaller (dynamic resolution)."""
    rng = np.random.default_rng(7)
    for h, w, tile, step, ph, pw in (
            (37, 53, 8, None, 37, 53), (48, 64, 16, None, 48, 64), (30, 21, 5, None, 30, 21),
            (50, 70, 16, None, 50, 70), (50, 70, 16, 4, 50, 70), (37, 53, 8, 8, 37, 53), (40, 29, 12, 3, 40, 29),
            (30, 21, 5, 5, 30, 21), (48, 64, 16, 1, 48, 64), (48, 64, 16, None, 72, 96), (50, 70, 16, 2, 37, 61),
            (37, 53, 8, None, 40, 41), (30, 21, 5, 5, 52, 33)):
        s = default_step(tile) if step is None else step
        shape = tile_index_map((ph, pw), tile, step).shape
        assert shape == (-(-ph // tile) * tile // s, -(-pw // tile) * tile // s)
        tiles = -(-ph // tile) * -(-pw // tile)
        origin = (ph + 2 * tile + 3, max(1, pw - tile))  # (a third size: where the network ran before a resize)
        entries = max(tiles, -(-origin[0] // tile) * -(-origin[1] // tile)) + int(rng.integers(0, 9))
        lut = np.where(rng.random((3, tiles)) < 0.3, -1, rng.integers(0, entries, (3, tiles))).astype(np.int32)
        lut[0] = np.arange(tiles)
        index = np.where(rng.random(shape) < 0.15, -1, rng.integers(0, entries, shape)).astype(np.int32)
        place = (rng.integers(0, ph, shape) << PLACE_BITS) | rng.integers(0, pw, shape)
        track = Track(index, np.where(index >= 0, place, -1).astype(np.int32), rng.integers(0, 3, shape).astype(np.int32),
                      lut, (ph, pw))
        # and the track of a frame the network ran on whole, no tile predicted afresh since: one generation
        whole = Track(np.where(index >= 0, index % tiles, -1).astype(np.int32), track.place,
                      np.zeros(shape, np.int32), lut[:1], (ph, pw))
        # and a track moved onto the previous frame from one of another size: every pixel its own entry, sky the
        # whole-frame run's tiles on its grid
        moved = Track(index, track.place, np.zeros(shape, np.int32), np.full((1, tiles), -1, np.int32), (ph, pw),
                      origin)
        est = rng.random((6, entries)).astype(np.float32)
        rows, cols = rng.integers(0, ph, (h, w)), rng.integers(0, pw, (h, w))
        seen = (rng.random((h, w)) > 0.25).astype(np.float32)
        sky = (rng.random((h, w)) > 0.9).astype(np.float32)
        for hib, tr in ((False, track), (True, track), (False, whole), (True, moved)):
            got, carried, missing = carry_estimates(est, tr, rows, cols, seen, sky, tile, hib, 0.5, reduce, step)
            want, entry = _carry_by_loops(est, tr, rows, cols, seen, sky, tile, hib, 0.5, reduce, s)
            assert np.allclose(got, want, rtol=1e-6), (h, w, tile, step, hib)
            assert np.array_equal(missing, np.isinf(want).all(axis=0)), (h, w, tile, step, hib)
            assert np.array_equal(carried.index, entry), (h, w, tile, step)


@pytest.mark.parametrize("step", [None, 1, 2])
def test_a_partial_edge_tile_reduces_and_counts_its_real_pixels_only(step: int | None) -> None:
    """A 40x24 frame of 16-pixel tiles: its last tile column is 8 pixels wide, its last row 8 tall. Their
    unseen share and mean are over the tile's pixels inside the frame, as a partial tile covers only
    those (tile_extents): the kept pixels' padding past the edge repeats the last column and row, and
    counted, it weighed the edge's pixels over the rest (half seen read as three quarters unseen, 1x1; a
    tile half from its left neighbour took a quarter of its own estimate)."""
    h, w = 24, 40
    est = np.arange(6 * 6, dtype=np.float32).reshape(6, 6)
    rows, cols = np.indices((h, w))
    ones = np.ones((h, w), np.float32)
    grid = est.reshape(6, 2, 3)
    # the right half of the partial column (36..39) fetched from column 0: half the tile's pixels from tile column 0
    left = np.where(cols >= 36, 0, cols)
    out, _, missing = carry_estimates(est, start_track((h, w), TILE, step), rows, left, ones, None, TILE, False, 0.5,
                                      "mean", step)
    assert not missing.any()
    np.testing.assert_array_equal(out[:, :, :2], grid[:, :, :2])
    np.testing.assert_array_equal(out[:, :, 2], (grid[:, :, 2] + grid[:, :, 0]) / 2)
    # the same half unseen: half the tile's pixels, not more than half (0.5: carried), more than 0.4 (1x1)
    seen = ones.copy()
    seen[:, 36:] = 0
    for reduce in sorted(sdk.REUSE_REDUCTIONS):
        out, _, missing = carry_estimates(est, start_track((h, w), TILE, step), rows, cols, seen, None, TILE, False,
                                          0.5, reduce, step)
        assert not missing.any(), reduce
        np.testing.assert_array_equal(out, grid)
        missing = carry_estimates(est, start_track((h, w), TILE, step), rows, cols, seen, None, TILE, False, 0.4,
                                  reduce, step)[2]
        assert np.array_equal(missing, np.array([[False, False, True], [False, False, True]])), reduce
    # the bottom row the same way: rows 20..23 (half of the 8-row partial tiles) unseen
    seen = ones.copy()
    seen[20:] = 0
    missing = carry_estimates(est, start_track((h, w), TILE, step), rows, cols, seen, None, TILE, False, 0.5,
                              "mean", step)[2]
    assert not missing.any()
    # and through PredictionReuse: a still frame, its last column half unseen, keeps the network's estimates there
    pred = _jnyang(16)
    reuse = sdk.PredictionReuse(pred, every=4, step=step)
    x = np.random.default_rng(3).random((len(pred.metadata.inputs), h, w), dtype=np.float32)
    want = reuse.predict(x)
    seen = ones.copy()
    seen[:, 36:] = 0
    np.testing.assert_allclose(reuse.predict(x, fetch=(rows, cols), seen=seen), want, rtol=1e-6)


@pytest.mark.parametrize("name", sdk.shipped_models())
def test_a_crop_with_its_margin_predicts_what_the_whole_frame_does(name: str) -> None:
    """``unseen="fresh"`` runs the network on crops ``context_tiles`` wider than the tiles it needs:
    their estimates must be the whole frame's, for every shipped model (five blocks reach two
    tiles further than three), and not one tile less."""
    pred = sdk.load(name)
    m = context_tiles(pred)
    recipe = pred.metadata.provenance["recipe"]
    depth = recipe.get("overrides", {}).get("depth", recipe["values"]["depth"])
    t = pred.tile_size
    # three blocks reach two 16-pixel tiles around their own, five four; jnyang-8px's three reach three of its
    # 8-pixel tiles (its last two blocks both at tile resolution)
    assert m == (depth - 1 if t == 16 else depth)
    assert sdk.PredictionReuse(pred, unseen="fresh").margin == m and sdk.PredictionReuse(pred).margin is None
    x = np.random.default_rng(3).random((len(pred.metadata.inputs), 12 * t, 20 * t), dtype=np.float32)
    whole = pred.predict(x)
    part = pred.predict(x[:, (4 - m) * t:(7 + m) * t, (9 - m) * t:(15 + m) * t])
    assert np.array_equal(part[:, m:m + 3, m:m + 6], whole[:, 4:7, 9:15])
    # one tile less and they differ: the margin is not wider than it must be
    part = pred.predict(x[:, (5 - m) * t:(6 + m) * t, (9 - m) * t:(15 + m) * t])
    assert not np.array_equal(part[:, m - 1:m, m:m + 6], whole[:, 4:5, 9:15])


def test_the_cover_holds_every_tile_with_its_margin() -> None:
    rng = np.random.default_rng(0)
    for _ in range(40):
        th, tw = int(rng.integers(1, 30)), int(rng.integers(1, 40))
        tiles = rng.random((th, tw)) < rng.choice([0.005, 0.02, 0.1, 0.4])
        tiles[rng.integers(th), rng.integers(tw)] = True
        margin = int(rng.integers(0, 3))
        boxes = cover(tiles, margin)
        inside = np.zeros_like(tiles, int)
        for y0, y1, x0, x1 in boxes:
            inside[y0:y1, x0:x1] += 1
        assert inside.max() == 1  # no tile in two boxes
        for y, x in zip(*np.nonzero(tiles)):  # each tile with its margin (within the frame) in one box
            assert any(y0 <= max(y - margin, 0) and min(y + margin + 1, th) <= y1 and x0 <= max(x - margin, 0)
                       and min(x + margin + 1, tw) <= x1 for y0, y1, x0, x1 in boxes)
    assert cover(np.zeros((5, 5), bool), 2) == []
    one = np.zeros((10, 10), bool)
    one[5, 5] = True
    assert cover(one, 1) == [(4, 7, 4, 7)]
    two = np.zeros((10, 20), bool)
    two[5, 2] = two[5, 15] = True  # far apart: two boxes, not their hull
    assert sorted(cover(two, 1)) == [(4, 7, 1, 4), (4, 7, 14, 17)]


def _coarse_model(folder: Path) -> sdk.ShadingRatePredictor:
    """A fast network with a coarse context (``coarse``: 2x2 cells of tiles pooled once more), random weights
    and BatchNorm statistics, exported."""
    import torch

    from rtp.export import export_checkpoint
    from rtp.train import checkpoint
    from rtp.train.model import FastNet

    from .conftest import base_metadata

    torch.manual_seed(0)
    net = FastNet(width=4, depth=3, coarse=1, coarse_width=4)
    with torch.no_grad():  # BatchNorm statistics of the features (random ones leave most ReLUs dead)
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.momentum = None
        net.train()(torch.rand(2, 4, 128, 128))
    return sdk.load(export_checkpoint(checkpoint.save(folder / "coarse.pt", net.eval(), base_metadata()),
                                      folder / "coarse.onnx"))


def test_fresh_crops_of_a_coarse_context_start_where_its_cells_do(tmp_path: Path) -> None:
    """A coarse context pairs the tiles of the whole frame from its first: a crop that started at an odd tile
    paired others, and its estimates were not the whole frame's whatever the margin. The crops start at even
    tiles, the reach is measured so, and the fresh tiles get the whole frame's estimates at every position."""
    pred = _coarse_model(tmp_path)
    reuse = sdk.PredictionReuse(pred, 4, unseen="fresh")
    assert reuse.align == 2 and sdk.PredictionReuse(sdk.load("jnyang"), unseen="fresh").align == 1
    m = reuse.margin
    assert m is not None and 0 < m < 8
    th, tw = 2 * m + 6, 2 * m + 12
    h, w = th * TILE, tw * TILE
    x = np.random.default_rng(2).random((4, h, w), dtype=np.float32)
    rows, cols = np.indices((h, w))
    everything = np.ones((h, w), np.float32)
    for y0 in (m + 1, m + 2):  # a 1x2-tile hole at an odd and at an even row, an odd column
        reuse.reset()
        reuse.predict(x, seen=everything)
        seen = everything.copy()
        seen[y0 * TILE:(y0 + 1) * TILE, (m + 3) * TILE:(m + 5) * TILE] = 0
        frame = x.copy()
        frame[1] = seen  # (the "seen" plane)
        est = reuse.predict(frame, (rows, cols), seen)
        assert 0.0 < reuse.work < 0.5  # a crop, not the whole frame
        np.testing.assert_array_equal(est[:, y0, m + 3:m + 5], pred.predict(frame)[:, y0, m + 3:m + 5])


class _Scene:
    """Random inputs of one frame for the shipped JNYang model and what the network says on them."""

    def __init__(self, th: int = 9, tw: int = 16) -> None:
        self.pred = sdk.load("jnyang")
        self.h, self.w = th * TILE, tw * TILE
        rng = np.random.default_rng(5)
        self.x = rng.random((len(self.pred.metadata.inputs), self.h, self.w), dtype=np.float32)
        self.rows, self.cols = np.indices((self.h, self.w))
        self.seen_at = self.pred.metadata.inputs.index("seen")

    def inputs(self, seen: np.ndarray) -> np.ndarray:
        x = self.x.copy()
        x[self.seen_at] = seen
        return x


@pytest.mark.parametrize("step", [None, 2])
def test_fresh_tiles_are_the_networks_and_are_carried_on(step: int | None) -> None:
    """``unseen="fresh"``: a tile the network did not see gets what the network says on this frame,
    computed on a crop only, and keeps it on the next reused frame (with the default pixel step and
    a sparser one)."""
    s = _Scene()
    th, tw = s.h // TILE, s.w // TILE
    reuse = sdk.PredictionReuse(s.pred, 4, unseen="fresh", step=step)
    everything = np.ones((s.h, s.w), np.float32)
    first = reuse.shading_rates(s.inputs(everything))
    assert reuse.work == 1.0 and reuse.age == 0
    seen = everything.copy()
    seen[2 * TILE:4 * TILE, 11 * TILE:13 * TILE] = 0  # four tiles the network did not see
    now = s.pred.shading_rates(s.inputs(seen))
    windows: list[tuple[slice, slice]] = []

    def lazily(ys: slice, xs: slice) -> np.ndarray:
        windows.append((ys, xs))
        return s.inputs(seen)[:, ys, xs]

    second = reuse.shading_rates(lazily, (s.rows, s.cols), seen)
    assert np.array_equal(second[2:4, 11:13], now[2:4, 11:13])  # the network's, not 1x1
    assert np.array_equal(np.delete(second, [11, 12], axis=1), np.delete(first, [11, 12], axis=1))
    m = reuse.margin
    assert m is not None and m >= 1
    assert windows == [(slice(0, (4 + m) * TILE), slice((11 - m) * TILE, (13 + m) * TILE))]  # one crop
    assert reuse.work == pytest.approx((4 + m) * (2 + 2 * m) / (th * tw)) and reuse.age == 1
    third = reuse.shading_rates(s.inputs(everything), (s.rows, s.cols), everything)  # still: the fresh tiles stay
    assert np.array_equal(third, second) and reuse.work == 0.0 and reuse.age == 2
    # without "fresh" the same tiles are shaded at 1x1 and the network does not run
    full = sdk.PredictionReuse(s.pred, 4)
    full.predict(s.inputs(everything))
    est = full.predict(s.inputs(seen), (s.rows, s.cols), seen)
    assert np.isinf(est[:, 2:4, 11:13]).all() and full.work == 0.0


@pytest.mark.parametrize("unseen", ["full", "fresh"])
def test_a_frame_of_another_render_resolution_is_carried(unseen: str) -> None:
    """Dynamic resolution: a frame at half the last one's size whose fetch indexes the previous frame's pixels
    (``fetch_from_motion(..., prev_shape=)``) carries the estimates onto its own tiles without the network, as
    carry_estimates does; unseen tiles go to 1x1 (or the network's crop) and, carried on at the new size, stay
    unknown rather than spreading a worst value; the network runs when the interval is up, and a frame of the
    first size is carried back. The features of a split network are carried the same way."""
    s = _Scene()
    reuse = sdk.PredictionReuse(s.pred, 5, unseen=unseen)
    everything = np.ones((s.h, s.w), np.float32)
    first = reuse.predict(s.inputs(everything))
    h, w = s.h // 2, s.w // 2
    zero = np.zeros((h, w))
    fetch = sdk.fetch_from_motion(zero, zero, prev_shape=(s.h, s.w))
    # (each centre on a corner of four texels: the one right of it and above, as reproject(motion=) fetches)
    assert fetch[0].max() == s.h - 2 and (fetch[0][1] == 2).all() and (fetch[1][:, 1] == 3).all()
    small = s.inputs(everything)[:, ::2, ::2].copy()
    seen = np.ones((h, w), np.float32)
    seen[:TILE, 3 * TILE:4 * TILE] = 0  # one tile unseen
    est = reuse.predict(small, fetch, seen)
    assert est.shape == (6, 5, w // TILE) and reuse.age == 1  # (72 rows: four tiles and a half)
    want, _, missing = carry_estimates(first.reshape(6, -1), start_track((s.h, s.w), TILE), *fetch, seen, None,
                                       TILE, False, 0.5)
    assert missing.sum() == 1 and missing[0, 3]
    keep = ~missing
    np.testing.assert_array_equal(est[:, keep], want[:, keep])
    # each whole tile the mean of the four it covers (its pixels' centres fall in them alike)
    quads = first[:, :8].reshape(6, 4, 2, w // TILE, 2).mean(axis=(2, 4))
    np.testing.assert_allclose(est[:, :4][:, keep[:4]], quads[:, keep[:4]], rtol=1e-6)
    if unseen == "full":
        assert np.isinf(est[:, 0, 3]).all() and reuse.work == 0.0
    else:
        np.testing.assert_array_equal(est[:, 0, 3], s.pred.predict(small)[:, 0, 3])
        assert 0.0 < reuse.work < 1.0
    # from here on each kept pixel carries the entry its own surface had (the first frame's tile it lies in, or
    # the crop's), not its half-size tile's mean: what the surfaces carry, pixel by pixel, independently of the SDK
    k = TILE // 4  # (kept pixels per tile and axis: every fourth)
    ky = np.minimum(np.arange(-(-h // TILE) * k) * 4, h - 1)  # (the padding repeats the last row)
    kx = np.arange(w // TILE * k) * 4
    entry = (np.minimum(2 * ky + 1, s.h - 1) // TILE)[:, None] * (s.w // TILE) + ((2 * kx + 1) // TILE)[None, :]
    gone = (ky < TILE)[:, None] & ((kx >= 3 * TILE) & (kx < 4 * TILE))[None, :]
    values = np.concatenate([first.reshape(6, -1), est[:, 0, 3][:, None]], axis=1)  # (the crop's: the last entry)
    entry = np.where(gone, -1 if unseen == "full" else values.shape[1] - 1, entry)

    def tiles(entries: np.ndarray, th: int, tw: int) -> np.ndarray:
        """Each tile the mean of its kept pixels' entries' values, 1x1 (inf) where more than half unknown."""
        out = np.full((6, th, tw), np.inf)
        for ty in range(th):
            for tx in range(tw):
                e = entries[ty * k:(ty + 1) * k, tx * k:(tx + 1) * k].ravel()
                if (e >= 0).sum() * 2 >= e.size:
                    out[:, ty, tx] = values[:, e[e >= 0]].mean(axis=1)
        return out

    # still, at the new size: the same estimates; the unseen tile, seen now, is unknown (1x1) or the crop's
    still = np.indices((h, w))
    again = reuse.predict(small, (still[0], still[1]), np.ones((h, w), np.float32))
    np.testing.assert_array_equal(again, est)
    assert reuse.work == 0.0 and reuse.age == 2
    # half a tile left: each kept pixel takes the entry of the one half a tile right; the tile left of the unseen one
    # keeps the estimate of the first frame's tile its own right half shows (half unknown is not more than
    # unseen_fraction) where a worst value carried would have spread, and no tile takes its half-size tile's mean
    shifted = reuse.predict(small, (still[0], np.minimum(still[1] + TILE // 2, w - 1)), np.ones((h, w), np.float32))
    entry = entry[:, np.minimum(kx + TILE // 2, w - 1) // 4]
    want = tiles(entry, *shifted.shape[1:])
    np.testing.assert_allclose(shifted, want, rtol=1e-6)
    if unseen == "full":
        np.testing.assert_allclose(shifted[:, 0, 2], first[:, :2, 5].mean(axis=1), rtol=1e-6)
    mixed = (est[:, :, :-1] + est[:, :, 1:]) / 2  # (the half-size tiles' means mixed: what the carry gave before)
    assert not np.allclose(shifted[:, 1:, :-1], mixed[:, 1:], rtol=1e-6)
    assert np.isfinite(shifted[:, 0, :3]).all()
    # back to the first size, then the network when the interval is up: each big tile's pixels come from half a
    # small tile, whose surfaces were half a tile right, each with its own entry: the surfaces are followed to the
    # pixel across the sizes, not the small frame's tiles upsampled
    big = sdk.fetch_from_motion(np.zeros((s.h, s.w)), np.zeros((s.h, s.w)), prev_shape=(h, w))
    back = reuse.predict(s.inputs(everything), big, everything)
    assert back.shape == first.shape and reuse.age == 4 and reuse.work == 0.0
    by, bx = np.arange(s.h // TILE * k) * 4, np.arange(s.w // TILE * k) * 4
    entry = entry[(by // 2 // 4)[:, None], (bx // 2 // 4)[None, :]]
    np.testing.assert_allclose(back, tiles(entry, *first.shape[1:]), rtol=1e-6)
    # where the first frame's own tile is under every pixel of a big tile again, its estimate comes back exactly
    exact = [(ty, tx) for ty in range(2, 9) for tx in range(16)
             if (entry[ty * k:(ty + 1) * k, tx * k:(tx + 1) * k] == entry[ty * k, tx * k]).all()]
    assert exact and all(np.allclose(back[:, ty, tx], values[:, entry[ty * k, tx * k]], rtol=1e-6) for ty, tx in exact)
    reuse.predict(s.inputs(everything), (s.rows, s.cols), everything)
    assert reuse.age == 0 and reuse.work == 1.0
    split = sdk.load("jnyang-reuse")
    features = sdk.PredictionReuse(split, 4, carry="features")
    x = np.random.default_rng(1).random((len(split.metadata.inputs), s.h, s.w), dtype=np.float32)
    features.predict(x)
    half = np.ascontiguousarray(x[:, ::2, ::2])
    carried = features.predict(half, fetch, np.ones((h, w), np.float32))
    assert carried.shape == (6, 5, w // TILE) and np.isfinite(carried).all() and features.work == 0.0
    np.testing.assert_array_equal(features.predict(half, (still[0], still[1]), np.ones((h, w), np.float32)), carried)
    with pytest.raises(sdk.ParameterError, match=r"fetch rows: expected indices in \[0, 72\)"):
        features.predict(x, (s.rows, s.cols), everything)  # (a fetch of this frame's pixels, not the previous one's)
    for bad in ((0, 4), (2**70, 3), (3, 2.0)):  # (2**70: indices past int64, accepted as garbage once)
        with pytest.raises(sdk.ParameterError, match=r"prev_shape: expected the previous frame's \(H, W\)"):
            sdk.fetch_from_motion(zero, zero, prev_shape=bad)


@pytest.mark.parametrize("step", [2, None])
def test_small_motions_add_up_as_one_after_a_change_of_size(step: int | None) -> None:
    """On the frames after a change of size (dynamic resolution) a camera panning a pixel a frame carries the
    estimates by three pixels after three frames, as one three-pixel pan does, as at one size: each surface's place
    is carried and finds the entry it had on the resized frame. Each kept pixel took the entry of the kept pixel at
    or above-left of the one it fetched, so the estimates moved a whole step a frame there (twelve pixels for three)."""
    pred = sdk.load("jnyang")
    big, small = (64, 160), (32, 80)
    x = np.random.default_rng(3).random((len(pred.metadata.inputs), *big), dtype=np.float32)
    half = np.ascontiguousarray(x[:, ::2, ::2])
    ones = np.ones(small, np.float32)
    zero = np.zeros(small)
    rows, cols = np.indices(small)

    def pan(moves: list[int]) -> np.ndarray:
        reuse = sdk.PredictionReuse(pred, 10, step=step)
        reuse.predict(x)
        reuse.predict(half, sdk.fetch_from_motion(zero, zero, prev_shape=big), ones)
        for m in moves:
            out = reuse.predict(half, (rows, np.clip(cols - m, 0, small[1] - 1)), ones)
        assert reuse.age == 1 + len(moves) and reuse.work == 0.0
        return out

    for shift in (1, -1):
        np.testing.assert_array_equal(pan([shift] * 3), pan([3 * shift]))


def test_a_budget_on_carried_estimates() -> None:
    """``shading_rates(saving=)`` on a reuse: the budget over the estimates ``predict`` gives, tiles the network
    did not see at 1x1 and the others reduced further to make the saving; a bad saving moves nothing on."""
    s = _Scene()
    ours, plain = sdk.PredictionReuse(s.pred, 2), sdk.PredictionReuse(s.pred, 2)
    everything = np.ones((s.h, s.w), np.float32)
    seen = everything.copy()
    seen[2 * TILE:4 * TILE, 11 * TILE:13 * TILE] = 0  # four tiles the network did not see
    meta = s.pred.metadata
    for frame, (x, fetch, mask) in enumerate([(s.inputs(everything), None, None),
                                              (s.inputs(seen), (s.rows, s.cols), seen)]):
        rates = ours.shading_rates(x, fetch, mask, saving=0.6)
        est = plain.predict(x, fetch, mask)
        want = sdk.select_rates_for_saving(est, 0.6, factors=meta.rate_factors, frame_size=(s.h, s.w), tile_size=TILE)
        np.testing.assert_array_equal(rates, want.rates)
        assert sdk.work_saved(rates, (s.h, s.w), TILE) >= 0.6 and ours.age == frame
    assert (rates[2:4, 11:13] == 0).all()  # (unseen: their estimates never pass)
    with pytest.raises(sdk.ParameterError, match="threshold: expected a finite number"):
        ours.shading_rates(s.inputs(everything), (s.rows, s.cols), everything, threshold=-0.2, saving=0.5)
    with pytest.raises(sdk.ParameterError, match=r"saving: expected .* \[0, 0.75\]"):
        ours.shading_rates(s.inputs(everything), (s.rows, s.cols), everything, saving=0.8, allowed=["2x2"])
    assert ours.age == 1  # (neither call moved the carry on)
    # a threshold and a saving: the saving a floor under the threshold's rates
    floor = ours.shading_rates(s.inputs(everything), (s.rows, s.cols), everything, threshold=0.05, saving=0.5)
    est = plain.predict(s.inputs(everything), (s.rows, s.cols), everything)
    want = sdk.select_rates_for_saving(est, 0.5, factors=meta.rate_factors, frame_size=(s.h, s.w), tile_size=TILE,
                                       threshold=0.05)
    np.testing.assert_array_equal(floor, want.rates)


def test_a_threshold_past_saturation_is_said_through_a_reuse_too(caplog: pytest.LogCaptureFixture) -> None:
    """The predictor's ``shading_rates`` says once that a threshold beyond what the model can express passes every
    tile at every rate; the same call through a ``PredictionReuse`` said nothing."""
    s = _Scene()
    reuse, meta = sdk.PredictionReuse(s.pred, 2), s.pred.metadata
    factor = min(meta.rate_factors or (1.0,))
    past = meta.saturation + 20.0 * np.log10(factor) - 0.01 if meta.higher_is_better else meta.saturation / factor * 1.01
    everything = np.ones((s.h, s.w), np.float32)
    caplog.set_level("WARNING", logger="rtp")
    reuse.shading_rates(s.inputs(everything), None, None)
    assert not caplog.records
    for _ in range(2):
        reuse.shading_rates(s.inputs(everything), (s.rows, s.cols), everything, threshold=past)
    assert len(caplog.records) == 1 and "beyond the worst value the model can express" in caplog.text


def test_engine_rates_on_carried_estimates() -> None:
    """``shading_rates(engine_rates=)`` on a reuse: the selection judges the rates the device shades beside the
    engine's, as ``select_rates`` does on the estimates; engine rates it would refuse move nothing on."""
    s = _Scene()
    ours, plain = sdk.PredictionReuse(s.pred, 2), sdk.PredictionReuse(s.pred, 2)
    everything = np.ones((s.h, s.w), np.float32)
    th, tw = s.h // TILE, s.w // TILE
    engine = np.where(np.arange(tw)[None, :] < tw // 2, sdk.RATE_CODES["2x1"], sdk.RATE_CODES["1x1"]).astype(np.uint8)
    engine = np.broadcast_to(engine, (th, tw))
    meta = s.pred.metadata
    for x, fetch, mask in [(s.inputs(everything), None, None), (s.inputs(everything), (s.rows, s.cols), everything)]:
        rates = ours.shading_rates(x, fetch, mask, engine_rates=engine, combiner="max")
        want = sdk.select_rates(plain.predict(x, fetch, mask), meta.default_threshold, factors=meta.rate_factors,
                                engine_rates=engine, combiner="max")
        np.testing.assert_array_equal(rates, want)
    assert ours.age == 1
    with pytest.raises(sdk.InputShapeError, match="engine_rates: shape"):
        ours.shading_rates(s.inputs(everything), (s.rows, s.cols), everything, engine_rates=engine[:, :2].T)
    with pytest.raises(sdk.ParameterError, match="combiner"):
        ours.shading_rates(s.inputs(everything), (s.rows, s.cols), everything, engine_rates=engine, combiner="avg")
    assert ours.age == 1  # (neither call moved the carry on)


def test_the_interval_and_the_fallbacks_run_the_whole_frame() -> None:
    s = _Scene()
    everything = np.ones((s.h, s.w), np.float32)
    x = s.inputs(everything)
    fetch = (s.rows, s.cols)
    reuse = sdk.PredictionReuse(s.pred, 3)
    works = []
    for _ in range(7):
        reuse.predict(x, fetch, everything)
        works.append(reuse.work)
    assert works == [1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0]  # every third frame
    reuse.predict(x, None)  # no fetch positions (a camera cut): the network runs
    assert reuse.work == 1.0 and reuse.age == 0
    reuse.predict(x, fetch, everything)
    reuse.reset()
    assert reuse.age is None
    reuse.predict(x, fetch, everything)
    assert reuse.work == 1.0
    # "fresh" with most of the frame unseen: the whole frame, and the interval restarts from it
    fresh = sdk.PredictionReuse(s.pred, 4, unseen="fresh")
    fresh.predict(x)
    fresh.predict(x, fetch, everything)
    nothing = np.zeros_like(everything)
    est = fresh.predict(s.inputs(nothing), fetch, nothing)
    assert fresh.work == 1.0 and fresh.age == 0
    assert np.array_equal(est, s.pred.predict(s.inputs(nothing)))
    # every=1: the network on every frame, whatever else is given
    every = sdk.PredictionReuse(s.pred, 1)
    for _ in range(3):
        assert np.array_equal(every.predict(x, fetch, everything), s.pred.predict(x)) and every.work == 1.0


def test_history_filters_the_estimates_along_the_motion() -> None:
    """``history=h``: each network frame's estimate is (1 - h) x the network's + h x the one carried
    into the tile (recursively, so frame t weighs frame t - 2 by h squared); unseen tiles take the
    network's alone; a shift by a whole tile moves the history with the surface."""
    s = _Scene()
    h = 0.25
    rng = np.random.default_rng(9)
    frames = [s.x * f for f in (1.0, 0.6, 1.3)]
    frames[2] = np.clip(frames[2] + 0.2 * rng.random(frames[2].shape, dtype=np.float32), 0, 1)
    nets = [s.pred.predict(x) for x in frames]
    assert not np.allclose(nets[0], nets[1])  # the frames differ, so the filter has something to do
    everything = np.ones((s.h, s.w), np.float32)
    fetch = (s.rows, s.cols)
    reuse = sdk.PredictionReuse(s.pred, 1, history=h)
    assert np.array_equal(reuse.predict(frames[0]), nets[0])  # no history yet
    second = reuse.predict(frames[1], fetch, everything)
    assert reuse.work == 1.0
    assert np.allclose(second, (1 - h) * nets[1] + h * nets[0], atol=1e-6)
    seen = everything.copy()
    seen[:TILE, :TILE] = 0  # one tile disoccluded: the network's estimate alone there
    third = reuse.predict(frames[2], fetch, seen)
    want = (1 - h) * nets[2] + h * second
    want[:, 0, 0] = nets[2][:, 0, 0]
    assert np.allclose(third, want, atol=1e-6)
    # the camera pans one tile: tile (y, x) now shows what (y, x - 1) showed, and its history follows
    pan = sdk.PredictionReuse(s.pred, 1, history=h)
    pan.predict(frames[0])
    moved = pan.predict(frames[1], (s.rows, np.maximum(s.cols - TILE, 0)), everything)
    assert np.allclose(moved[:, :, 1:], (1 - h) * nets[1][:, :, 1:] + h * nets[0][:, :, :-1], atol=1e-6)
    # with an interval, only the network's frames blend; the frames between carry the blend
    both = sdk.PredictionReuse(s.pred, 2, history=h)
    both.predict(frames[0])
    carried = both.predict(frames[1], fetch, everything)
    assert both.work == 0.0 and np.allclose(carried, nets[0])
    blended = both.predict(frames[1], fetch, everything)
    assert both.work == 1.0 and np.allclose(blended, (1 - h) * nets[1] + h * nets[0], atol=1e-6)
    # history 0 is the network alone, and a camera cut (no fetch) restarts the filter
    assert np.array_equal(reuse.predict(frames[1]), nets[1])
    assert np.array_equal(sdk.PredictionReuse(s.pred, 1).predict(frames[1], fetch, everything), nets[1])
    assert "history=0.25" in repr(reuse)


def test_refresh_runs_the_network_early_when_much_is_unseen() -> None:
    """``refresh=s``: a frame on which more than a share s of the tiles is unseen since the network
    ran runs it on the whole frame (and restarts the interval); less than that is carried."""
    s = _Scene()
    th, tw = s.h // TILE, s.w // TILE
    everything = np.ones((s.h, s.w), np.float32)
    fetch = (s.rows, s.cols)
    few, many = everything.copy(), everything.copy()
    few[:TILE, :2 * TILE] = 0  # 2 tiles of 144
    many[:2 * TILE, :4 * TILE] = 0  # 8 tiles: over 5%
    assert 2 / (th * tw) < 0.05 < 8 / (th * tw)
    reuse = sdk.PredictionReuse(s.pred, 8, refresh=0.05)
    reuse.predict(s.inputs(everything))
    works = []
    for seen in (everything, few, few, many, everything):
        est = reuse.predict(s.inputs(seen), fetch, seen)
        works.append(reuse.work)
    assert works == [0.0, 0.0, 0.0, 1.0, 0.0]  # the unseen tiles add up since the run: 2, 2, then 8 of them
    assert reuse.age == 1 and np.isfinite(est).all()
    # without refresh the same frames carry on, the unseen tiles at 1x1
    plain = sdk.PredictionReuse(s.pred, 8)
    plain.predict(s.inputs(everything))
    for seen in (everything, few, few, many):
        est = plain.predict(s.inputs(seen), fetch, seen)
        assert plain.work == 0.0
    assert np.isinf(est[:, :2, :4]).all()
    assert "refresh=0.05" in repr(reuse)


def test_bad_arguments_are_refused() -> None:
    s = _Scene(3, 4)
    for kw, name in (({"every": 0}, "every"), ({"every": 2.5}, "every"), ({"reduce": "median"}, "reduce"),
                     ({"unseen": "skip"}, "unseen"), ({"unseen_fraction": 1.0}, "unseen_fraction"),
                     ({"margin": -1}, "margin"), ({"history": 1.0}, "history"), ({"history": -0.1}, "history"),
                     ({"history": "0.5"}, "history"), ({"history": True}, "history"),
                     ({"history": float("nan")}, "history"), ({"refresh": 1.0}, "refresh"), ({"refresh": -1}, "refresh"),
                     ({"refresh": "0.1"}, "refresh"), ({"refresh": False}, "refresh"), ({"step": 3}, "step"),
                     ({"step": 0}, "step"), ({"step": 32}, "step"), ({"step": True}, "step"), ({"step": 4.0}, "step"),
                     ({"carry_scale": [2.0]}, "carry_scale"), ({"carry_scale": "2"}, "carry_scale"),
                     ({"rescale": [0.5]}, "rescale")):
        with pytest.raises(sdk.ParameterError, match=name) as err:
            sdk.PredictionReuse(s.pred, **kw)  # type: ignore[arg-type]
        assert err.value.name == name
    reuse = sdk.PredictionReuse(s.pred, 4)
    ones = np.ones((s.h, s.w), np.float32)
    # the fetch's kind is checked on the network's frames too (the first here), where it is not read: a float
    # fetch was refused only on the next frame, as if that frame's were wrong; its shape is not (a resize's frame)
    for bad, message in (((s.rows.astype(np.float32), s.cols), "fetch rows: expected integer pixel indices"),
                         ((s.rows, s.cols.tolist()), "fetch cols: expected a numpy array"),
                         (s.rows, r"fetch: expected \(rows, cols\)")):
        with pytest.raises(sdk.ParameterError, match=message):
            sdk.PredictionReuse(s.pred, 4).predict(s.x, bad, ones)  # type: ignore[arg-type]
    sdk.PredictionReuse(s.pred, 4).predict(s.x, (s.rows[:-1], s.cols[:, :-1]), ones)  # an old size's: not read
    with pytest.raises(sdk.InputShapeError, match=r"\(C, H, W\)"):
        reuse.predict(s.x[None])
    reuse.predict(s.x)
    with pytest.raises(sdk.InputShapeError, match="fetch rows"):
        reuse.predict(s.x, (s.rows[:-1], s.cols), ones)
    with pytest.raises(sdk.ParameterError, match="integer pixel indices"):
        reuse.predict(s.x, (s.rows.astype(np.float32), s.cols), ones)
    with pytest.raises(sdk.ParameterError, match=r"indices in \[0, 64\)"):
        reuse.predict(s.x, (s.rows, s.cols + 1), ones)
    for dtype in (np.int64, np.int32, np.int16):  # negative indices too, whatever the integer type
        with pytest.raises(sdk.ParameterError, match=r"fetch rows: expected indices in \[0, \d+\) .* got -1\.\."):
            reuse.predict(s.x, ((s.rows - 1).astype(dtype), s.cols), ones)
    # only the pixels the carry reads are checked (one of every 4 per axis, the last row and column): a
    # bad index elsewhere is never read, and checking the whole maps cost 2 ms a 1080p frame
    stray = s.cols.copy()
    stray[1, 1] = 10**6
    np.testing.assert_array_equal(sdk.PredictionReuse(s.pred, 4).predict(s.x), reuse.predict(s.x))
    a, b = sdk.PredictionReuse(s.pred, 4), sdk.PredictionReuse(s.pred, 4)
    a.predict(s.x)
    b.predict(s.x)
    np.testing.assert_array_equal(a.predict(s.x, (s.rows, stray), ones), b.predict(s.x, (s.rows, s.cols), ones))
    with pytest.raises(sdk.InputShapeError, match="seen"):
        reuse.predict(s.x, (s.rows, s.cols), ones[:, :-1])
    with pytest.raises(sdk.ParameterError, match=r"fetch: expected \(rows, cols\)"):
        reuse.predict(s.x, s.rows, ones)  # type: ignore[arg-type]
    with pytest.raises(sdk.ParameterError, match="seen: expected a numpy array"):
        reuse.predict(s.x, (s.rows, s.cols), ones.tolist())  # type: ignore[arg-type]
    with pytest.raises(sdk.ParameterError, match="unseen_fraction"):
        sdk.PredictionReuse(s.pred, unseen_fraction=10**400)
    with pytest.raises(sdk.InputDtypeError, match="function of a window"):
        reuse.predict(s.x.tolist(), (s.rows, s.cols), ones)  # type: ignore[arg-type]
    with pytest.raises(sdk.ParameterError, match="pass seen"):
        reuse.predict(lambda ys, xs: s.x[:, ys, xs], (s.rows, s.cols))
    assert "every=4" in repr(reuse) and "step=4" in repr(reuse) and sdk.PredictionReuse(s.pred, step=8).step == 8


def test_tile_block_levels_average_each_rates_cells_over_a_tile() -> None:
    """Per tile and rate, the mean of that rate's value over the tile's 4x4 cells (the k-th pixel of
    each cell in raster order), averaged over the planes; a partial last tile averages its own cells."""
    h, w = 2 * TILE, TILE + 8  # a partial second tile column: two cells wide
    planes = np.zeros((2, h, w), np.float32)
    for k in range(len(sdk.BLOCK_RATES)):
        planes[0, k // 4::4, k % 4::4] = 0.1 * (k + 1)
        planes[1, k // 4::4, k % 4::4] = 0.3
    planes[0, k // 4, k % 4] = 0.1 * (k + 1) + 1.6  # one cell of the first tile 4x4 higher (16 cells a tile)
    v = tile_block_levels(planes, TILE)
    assert v.shape == (6, 2, 2)
    want = (0.1 * (np.arange(6) + 1) + 0.3) / 2
    expect = np.broadcast_to(want[:, None, None], v.shape).copy()
    expect[5, 0, 0] += 1.6 / 16 / 2
    assert np.allclose(v, expect, atol=1e-6)
    with pytest.raises(sdk.InputShapeError, match=r"\(P, H, W\)"):
        tile_block_levels(planes[0], TILE)


def _slow_block_levels(planes: np.ndarray, tile: int) -> np.ndarray:
    """tile_block_levels by loops over cells: rate k's value of cell (i, j) is its k-th pixel, or,
    where block_variances cropped that pixel off a partial last cell, the same pixel of the cell
    before it (zero on a frame too small to hold it at all)."""
    _, h, w = planes.shape
    ch, cw = -(-h // 4), -(-w // 4)
    th, tw = -(-h // tile), -(-w // tile)
    m = tile // 4
    out = np.zeros((6, th, tw))
    for k in range(6):
        r, c = divmod(k, 4)
        cells = np.zeros((ch, cw))
        for i in range(ch):
            for j in range(cw):
                y, x = 4 * i + r, 4 * j + c
                y, x = (y if y < h else y - 4), (x if x < w else x - 4)
                cells[i, j] = planes[:, y, x].mean() if y >= 0 and x >= 0 else 0.0
        for ti in range(th):
            for tj in range(tw):
                out[k, ti, tj] = cells[ti * m:(ti + 1) * m, tj * m:(tj + 1) * m].mean()
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 45), st.integers(1, 45), st.integers(1, 3), st.sampled_from([4, 8, 16]), st.integers(0, 2**31))
def test_tile_block_levels_match_a_loop_over_cells_on_any_frame(h: int, w: int, p: int, tile: int, seed: int) -> None:
    """Any frame size, multiples of the 4-pixel cell or not (a 1366-pixel-wide frame is not), and
    any number of planes: the vectorised reduction equals the loop over cells."""
    planes = np.random.default_rng(seed).random((p, h, w), dtype=np.float32)
    assert np.allclose(tile_block_levels(planes, tile), _slow_block_levels(planes, tile), atol=1e-5)


def test_rescale_scales_carried_estimates_by_the_blocks_variance() -> None:
    """``rescale=a``: on a carried frame each seen tile's estimate is the carried one times
    ((v_now + eps) / (v_then + eps)) ** a in its ``.blocks`` planes' geometric means; the unseen
    tiles stay at 1x1 and the network's frames are the network's alone."""
    s = _Scene()
    a = 0.5
    blocks = [i for i, c in enumerate(s.pred.metadata.inputs) if c.endswith(".blocks")]
    assert len(blocks) == 2
    everything = np.ones((s.h, s.w), np.float32)
    fetch = (s.rows, s.cols)
    x0 = s.inputs(everything)
    x1 = x0.copy()
    x1[blocks] = np.clip(x1[blocks] * 0.8 + 0.15, 0, 1)  # the content now falls differently on the blocks
    reuse = sdk.PredictionReuse(s.pred, 4, rescale=a)
    first = reuse.predict(x0)
    assert np.array_equal(first, s.pred.predict(x0))
    seen = everything.copy()
    seen[:TILE, :TILE] = 0
    carried = reuse.predict(x1, fetch, seen)
    assert reuse.work == 0.0
    ratio = np.exp(a * -np.log(BLOCK_EPS) * (tile_block_levels(x1[blocks], TILE) - tile_block_levels(x0[blocks], TILE)))
    assert not np.allclose(ratio, 1.0)
    want = first * ratio
    assert np.isinf(carried[:, 0, 0]).all()
    assert np.allclose(carried.reshape(6, -1)[:, 1:], want.reshape(6, -1)[:, 1:], rtol=1e-5)
    # without rescale the carried estimates are the first frame's; the same frame carried is itself
    plain = sdk.PredictionReuse(s.pred, 4)
    plain.predict(x0)
    assert np.allclose(plain.predict(x1, fetch, everything), first)
    again = sdk.PredictionReuse(s.pred, 4, rescale=a)
    again.predict(x0)
    assert np.allclose(again.predict(x0, fetch, everything), first, rtol=1e-5)
    assert "rescale=0.5" in repr(reuse)



def test_fresh_predictions_need_a_model_of_any_size(tmp_path: Path) -> None:
    """unseen='fresh' runs the network on crops of the frame: a model exported for one frame size
    cannot, and says how to export one that can."""
    from .conftest import base_metadata, build_onnx

    static = sdk.load(build_onnx(tmp_path / "s.onnx", weights=np.eye(4, dtype=np.float32), static=(1, 64, 96)),
                      metadata=base_metadata())
    with pytest.raises(sdk.ParameterError, match=r"unseen='fresh' runs the network on crops, but this model takes only "
                                                 r"96x64 frames \(export it with dynamic sizes\)") as err:
        sdk.PredictionReuse(static, 4, unseen="fresh")
    assert err.value.name == "unseen"
    assert sdk.PredictionReuse(static, 4).every == 4  # the other modes run on whole frames

def test_rescale_needs_blocks_planes_and_an_error_metric() -> None:
    s = _Scene(3, 4)
    for bad in (-0.1, sdk.MAX_RESCALE + 0.1, float("nan"), True, "0.5"):
        with pytest.raises(sdk.ParameterError, match="rescale: expected an exponent") as err:
            sdk.PredictionReuse(s.pred, rescale=bad)  # type: ignore[arg-type]
        assert err.value.name == "rescale"
    with pytest.raises(sdk.ParameterError, match=r"no \.blocks input"):
        sdk.PredictionReuse(sdk.load("lpips"), rescale=0.5)
    with pytest.raises(sdk.ParameterError, match="rescale"):
        sdk.PredictionReuse(sdk.load("psnr"), rescale=0.5)
    assert sdk.PredictionReuse(sdk.load("psnr"), rescale=0).rescale == 0.0  # 0: nothing asked of the model


def test_rescaled_fresh_tiles_are_the_networks_and_carry_on_unchanged() -> None:
    """With ``unseen="fresh"`` and ``rescale``, a tile predicted afresh is the network's estimate as it
    is, and on a next frame with the same inputs it carries on unchanged (the carry holds it divided
    by its own frame's factor)."""
    s = _Scene()
    everything = np.ones((s.h, s.w), np.float32)
    seen = everything.copy()
    seen[2 * TILE:4 * TILE, 11 * TILE:13 * TILE] = 0
    x0, x1 = s.inputs(everything), s.inputs(seen)
    reuse = sdk.PredictionReuse(s.pred, 4, unseen="fresh", rescale=0.25)
    reuse.predict(x0)
    second = reuse.predict(x1, (s.rows, s.cols), seen)
    assert np.allclose(second[:, 2:4, 11:13], s.pred.predict(x1)[:, 2:4, 11:13], rtol=1e-5)
    third = reuse.predict(x1, (s.rows, s.cols), everything)
    assert reuse.work == 0.0 and np.allclose(third, second, rtol=1e-5)


def _reuse_floor(monkeypatch: pytest.MonkeyPatch) -> Any:
    """bench/reuse_floor.py as a module (bench/ on the path for its own imports)."""
    return bench_module("reuse_floor", monkeypatch)


def test_reuse_floor_mixes_network_and_carried_frames_and_finds_the_best_pair(monkeypatch: pytest.MonkeyPatch) -> None:
    """bench/reuse_floor.py --sweep: one frame in k with the network's curve, k - 1 with the carried one;
    one threshold for both is the diagonal of the pairs, and the best pair is never worse."""
    floor = _reuse_floor(monkeypatch)
    fresh = np.array([[0.00, 0.02, 0.06], [0.10, 0.30, 0.50]])  # failing share, work saved per threshold
    carried = np.array([[0.01, 0.04, 0.10], [0.10, 0.30, 0.50]])
    fail, saved = floor.mix_curves(fresh, carried, 4)
    assert fail.shape == saved.shape == (3, 3)
    assert fail[2, 1] == pytest.approx(0.25 * 0.06 + 0.75 * 0.04) and saved[2, 1] == pytest.approx(0.35)
    one, _ = floor.best_saving(np.diagonal(fail), np.diagonal(saved), 0.05)
    pair, i = floor.best_saving(fail, saved, 0.05)
    assert one == pytest.approx(0.30) and pair == pytest.approx(0.35) and divmod(i, 3) == (2, 1)
    assert np.isnan(floor.best_saving(fail, saved, 0.001)[0])  # nothing fails that little
    assert floor.mix_curves(fresh, carried, 2)[0][0, 2] == pytest.approx(0.05)


def test_reuse_floor_splits_a_checkpoint_at_its_tile_resolution_contrast(tmp_path: Path,
                                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """bench/reuse_floor.py --model CHECKPOINT.pt: for a fast network whose block contrast joins at tile
    resolution, the tail on the trunk's own features of the same frame is the whole network (so a
    carried trunk row differs from k = 1 only by what the carry changes); other networks do not split."""
    import torch

    from rtp.train import checkpoint
    from rtp.train.model import FastNet

    from .conftest import base_metadata

    floor = _reuse_floor(monkeypatch)
    inputs = ["reprojected.y", "seen", "albedo.y", "normal.z", "roughness", "metallic", "specular"]
    meta = base_metadata(inputs=inputs)
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 1, (7, 48, 64)).astype(np.float32)
    for cell, splits in ((16, True), (4, False)):
        net = FastNet(7, head_width=16, block_contrast=(0, 2), contrast_cell=cell)
        for m in net.modules():  # BatchNorm statistics that are not the identity
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.2, 0.2)
                m.running_var.uniform_(0.5, 2.0)
        ck = checkpoint.save(tmp_path / f"c{cell}.pt", net.eval(), meta)
        model = floor.CheckpointModel(str(ck))
        assert model.splits is splits
        whole = model.predict(x)
        assert whole.shape == (6, 3, 4) and np.isfinite(whole).all()
        if splits:
            feats = model.trunk(x)
            assert feats.shape == (16, 3, 4)
            np.testing.assert_allclose(model.tail(feats, x), whole, rtol=1e-5, atol=1e-6)
            assert not np.allclose(model.tail(feats, x[:, ::-1].copy()), whole)  # the tail reads the new frame


def test_carry_scale_multiplies_carried_estimates_only() -> None:
    """``carry_scale=f``: a carried frame's seen tiles are the plain carry's times f; the network's
    frames and the unseen tiles (1x1's worst value) are untouched."""
    s = _Scene(3, 4)
    everything = np.ones((s.h, s.w), np.float32)
    seen = everything.copy()
    seen[:TILE, :TILE] = 0  # one tile the network did not see
    plain, scaled = sdk.PredictionReuse(s.pred, 4), sdk.PredictionReuse(s.pred, 4, carry_scale=1.25)
    assert "carry_scale=1.25" in repr(scaled)
    x = s.inputs(everything)
    np.testing.assert_array_equal(scaled.predict(x), plain.predict(x))  # the network's frame
    a = plain.predict(x, (s.rows, s.cols), seen)
    b = scaled.predict(x, (s.rows, s.cols), seen)
    np.testing.assert_array_equal(b[:, 0, 0], a[:, 0, 0])  # unseen: worst either way
    np.testing.assert_allclose(b[:, 1:, 1:], 1.25 * a[:, 1:, 1:], rtol=1e-6)
    for bad in (0.2, 5.0, float("nan"), True, "1.1"):
        with pytest.raises(sdk.ParameterError, match="carry_scale: expected a factor") as err:
            sdk.PredictionReuse(s.pred, carry_scale=bad)  # type: ignore[arg-type]
        assert err.value.name == "carry_scale"
    with pytest.raises(sdk.ParameterError, match="better when higher"):
        sdk.PredictionReuse(sdk.load("psnr"), carry_scale=1.1)
    assert sdk.PredictionReuse(sdk.load("psnr"), carry_scale=1).carry_scale == 1.0


def _split_predictor(folder: Path, planes: str = "blocks") -> sdk.ShadingRatePredictor:
    from .conftest import split_model

    return sdk.load(split_model(folder, planes))


def _split_frame(rng: np.random.Generator, h: int, w: int, kind: str = "blocks") -> np.ndarray:
    planes = rng.uniform(0, 1, (7, h, w)).astype(np.float32)
    derive = sdk.tile_variances if kind == "tiles" else sdk.block_variances
    return np.concatenate([planes, np.stack([derive(planes[i]) for i in (0, 2)])])


@pytest.mark.parametrize("kind", ["blocks", "tiles"])
def test_carried_features_run_the_tail_on_each_new_frame(tmp_path: Path, kind: str) -> None:
    """``carry="features"``: the network's frame gives what ``predict`` gives; a carried frame runs the
    tail on the carried features and the new frame's inputs (so its estimates follow the new frame's
    .blocks or .tiles planes); unseen tiles go to 1x1 or to fresh crops, whose features are carried on."""
    pred = _split_predictor(tmp_path, kind)
    assert pred.splits
    h, w = 64, 96
    rng = np.random.default_rng(3)
    x0, x1 = _split_frame(rng, h, w, kind), _split_frame(rng, h, w, kind)
    rows, cols = np.indices((h, w))
    everything = np.ones((h, w), np.float32)
    reuse = sdk.PredictionReuse(pred, 4, carry="features")
    first = reuse.predict(x0)
    np.testing.assert_allclose(first, pred.predict(x0), rtol=1e-6)
    assert reuse.work == 1.0 and "carry='features'" in repr(reuse)
    second = reuse.predict(x1, (rows, cols), everything)
    _, feats0 = pred.predict_split(x0)
    np.testing.assert_allclose(second, pred.predict_tail(feats0, x1), rtol=1e-5)  # a still camera: the same features
    assert reuse.work == 0.0 and reuse.age == 1 and not np.allclose(second, first)
    seen = everything.copy()
    seen[:TILE, :TILE] = 0  # one tile the network did not see: 1x1
    third = reuse.predict(x1, (rows, cols), seen)
    assert np.isinf(third[:, 0, 0]).all() and np.isfinite(third.reshape(6, -1)[:, 1:]).all()
    fourth = reuse.predict(x1, (rows, cols), everything)  # unseen since the network ran: still 1x1
    assert np.isinf(fourth[:, 0, 0]).all() and reuse.work == 0.0 and reuse.age == 3
    np.testing.assert_allclose(reuse.predict(x1, (rows, cols), everything), pred.predict(x1), rtol=1e-6)
    assert reuse.work == 1.0 and reuse.age == 0  # the 5th frame: the network again
    # unseen="fresh": the unseen tile is the network's on a crop, and its features are carried on
    fresh = sdk.PredictionReuse(pred, 4, carry="features", unseen="fresh")
    fresh.predict(x0)
    est = fresh.predict(x1, (rows, cols), seen)
    np.testing.assert_allclose(est[:, 0, 0], pred.predict(x1)[:, 0, 0], rtol=1e-5)
    assert 0.0 < fresh.work < 1.0
    after = fresh.predict(x1, (rows, cols), everything)
    assert np.isfinite(after).all() and fresh.work == 0.0


def test_carrying_features_needs_a_model_that_splits(tmp_path: Path) -> None:
    jnyang = sdk.load("jnyang")
    with pytest.raises(sdk.ParameterError, match="does not split") as info:
        sdk.PredictionReuse(jnyang, 4, carry="features")
    assert info.value.name == "carry"
    with pytest.raises(sdk.ParameterError, match="carry: expected one of estimates, features"):
        sdk.PredictionReuse(jnyang, 4, carry="trunk")
    pred = _split_predictor(tmp_path)
    for kw, word in (({"rescale": 0.25}, "rescale"), ({"history": 0.5}, "history"), ({"reduce": "worst"}, "reduce")):
        with pytest.raises(sdk.ParameterError, match=f"carry='features': .*{word}"):
            sdk.PredictionReuse(pred, 4, carry="features", **kw)
    coarse = sdk.load(pred.path, tile_size=32)
    with pytest.raises(sdk.ParameterError, match="tile_size"):
        sdk.PredictionReuse(coarse, 4, carry="features")


class _Asked:
    """An engine's input function that takes ``channels``: it builds only the planes asked for (from a
    frame it holds) and records what each call asked."""

    def __init__(self, names: tuple[str, ...]) -> None:
        self.names, self.frame, self.calls = names, np.zeros(0, np.float32), []

    def __call__(self, ys: slice, xs: slice, channels: tuple[str, ...] = ()) -> np.ndarray:
        self.calls.append(tuple(channels))
        return np.ascontiguousarray(self.frame[[self.names.index(c) for c in channels], ys, xs])


@pytest.mark.parametrize("kind", ["blocks", "tiles"])
def test_an_input_function_with_channels_builds_only_what_the_tail_reads(tmp_path: Path, kind: str) -> None:
    """``carry="features"`` with an input function that takes ``channels``: the network's frames ask for every
    plane, a carried frame for the tail's planes alone (``predictor.tail_inputs``), a fresh crop for every plane
    of its window; the estimates are those of the same frames given whole, to the bit."""
    pred = _split_predictor(tmp_path, kind)
    names = pred.metadata.inputs
    assert pred.tail_inputs == (f"reprojected.y.{kind}", f"albedo.y.{kind}")
    assert sdk.load("jnyang").tail_inputs == ()
    h, w = 64, 96
    rng = np.random.default_rng(4)
    frames = [_split_frame(rng, h, w, kind) for _ in range(6)]
    rows, cols = np.indices((h, w))
    seen = np.ones((h, w), np.float32)
    seen[:TILE, :TILE] = 0
    for unseen in ("full", "fresh"):
        whole = sdk.PredictionReuse(pred, 4, carry="features", unseen=unseen)
        asked = sdk.PredictionReuse(pred, 4, carry="features", unseen=unseen)
        fn = _Asked(names)
        for i, x in enumerate(frames):
            fn.frame, fn.calls = x, []
            fetch = None if i == 0 else (rows, cols)
            want = whole.predict(x, fetch, seen)
            got = asked.predict(fn, fetch, seen)
            assert np.array_equal(got, want), (unseen, i)
            assert asked.work == whole.work
            if i % 4 == 0:  # the network's frame
                assert fn.calls == [names]
            elif unseen == "fresh":  # the tail's planes, then the crop around the unseen tile
                assert fn.calls == [pred.tail_inputs, names] and 0 < asked.work < 1
            else:
                assert fn.calls == [pred.tail_inputs]


def test_an_input_function_with_channels_builds_only_the_blocks_planes_to_rescale() -> None:
    """``rescale``: a carried frame asks an input function that takes ``channels`` for the ``.blocks`` planes
    alone; the estimates are those of the frames given whole. A function without ``channels`` is asked for the
    whole frame, as before."""
    s = _Scene()
    names = s.pred.metadata.inputs
    blocks = tuple(c for c in names if c.endswith(".blocks"))
    everything = np.ones((s.h, s.w), np.float32)
    fetch = (s.rows, s.cols)
    x0 = s.inputs(everything)
    x1 = x0.copy()
    x1[[names.index(c) for c in blocks]] *= 0.7
    whole = sdk.PredictionReuse(s.pred, 4, rescale=0.25)
    asked = sdk.PredictionReuse(s.pred, 4, rescale=0.25)
    plain = sdk.PredictionReuse(s.pred, 4, rescale=0.25)
    fn = _Asked(names)
    windows: list[tuple[slice, slice]] = []

    def old_style(ys: slice, xs: slice) -> np.ndarray:
        windows.append((ys, xs))
        return fn.frame[:, ys, xs]

    for i, x in enumerate((x0, x1, x1)):
        fn.frame, fn.calls = x, []
        f = None if i == 0 else fetch
        want = whole.predict(x, f, everything)
        assert np.array_equal(asked.predict(fn, f, everything), want)
        assert fn.calls == ([names] if i == 0 else [blocks])
        assert np.array_equal(plain.predict(old_style, f, everything), want)
    assert windows == [(slice(0, s.h), slice(0, s.w))] * 3


def test_an_input_function_that_returns_the_wrong_planes_is_refused(tmp_path: Path) -> None:
    pred = _split_predictor(tmp_path, "tiles")
    h, w = 32, 48
    x = _split_frame(np.random.default_rng(0), h, w, "tiles")
    rows, cols = np.indices((h, w))
    seen = np.ones((h, w), np.float32)
    reuse = sdk.PredictionReuse(pred, 4, carry="features")
    reuse.predict(x)
    with pytest.raises(sdk.InputShapeError, match=r"asked for channels \['reprojected.y.tiles', 'albedo.y.tiles'\].*"
                                                  r"expected shape \(2, 32, 48\), got \(9, 32, 48\)"):
        reuse.predict(lambda ys, xs, channels: x[:, ys, xs], (rows, cols), seen)
    with pytest.raises(sdk.InputDtypeError, match="expected a float32 numpy array, got dtype float64"):
        reuse.predict(lambda ys, xs, channels: x[7:, ys, xs].astype(np.float64), (rows, cols), seen)
    assert np.isfinite(reuse.predict(lambda ys, xs, channels: x[7:, ys, xs], (rows, cols), seen)).all()


def test_the_shipped_reuse_models_tail_reads_only_its_tail_inputs() -> None:
    """What lets a carried frame skip the other planes: the shipped ``jnyang-reuse``'s tail gives the same
    estimates when every plane but ``tail_inputs`` is 0."""
    pred = sdk.load("jnyang-reuse")
    names = pred.metadata.inputs
    assert pred.tail_inputs == ("reprojected.y.tiles", "albedo.y.tiles")
    rng = np.random.default_rng(1)
    x = rng.random((len(names), 96, 160), dtype=np.float32)
    for c in pred.tail_inputs:
        x[names.index(c)] = sdk.tile_variances(x[names.index(c.removesuffix(".tiles"))])
    _, feats = pred.predict_split(x)
    only = np.zeros_like(x)
    keep = [names.index(c) for c in pred.tail_inputs]
    only[keep] = x[keep]
    assert np.array_equal(pred.predict_tail(feats, only), pred.predict_tail(feats, x))
    # features of another trunk: onnxruntime's own words (InferenceError) before; complex ones cast silently
    with pytest.raises(sdk.InputShapeError, match=f"expected {len(feats)} channels"):
        pred.predict_tail(feats[:3], x)
    with pytest.raises(sdk.InputDtypeError, match="complex"):
        pred.predict_tail(feats.astype(np.complex64), x)


def test_reuse_refuses_what_is_not_a_predictor_and_an_input_function_s_wrong_window() -> None:
    """PredictionReuse(None) was an AttributeError; a function without ``channels`` that returned a larger
    frame than ``seen`` gave estimates of another grid, then carried a mismatched cache."""
    for bad in (None, "jnyang"):
        with pytest.raises(sdk.ParameterError, match="ShadingRatePredictor"):
            sdk.PredictionReuse(bad)  # type: ignore[arg-type]
    pred = sdk.load("jnyang")
    frame = np.random.default_rng(0).random((len(pred.metadata.inputs), 64, 96), dtype=np.float32)
    larger = np.random.default_rng(0).random((len(pred.metadata.inputs), 80, 96), dtype=np.float32)
    seen = np.ones((64, 96), np.float32)
    reuse = sdk.PredictionReuse(pred, 2)
    with pytest.raises(sdk.InputShapeError, match=r"expected shape \(9, 64, 96\), got \(9, 80, 96\)"):
        reuse.predict(lambda ys, xs: larger, seen=seen)
    with pytest.raises(sdk.InputDtypeError, match="float32"):
        reuse.predict(lambda ys, xs: frame[:, ys, xs].astype(np.float64), seen=seen)
    np.testing.assert_array_equal(reuse.predict(lambda ys, xs: frame[:, ys, xs], seen=seen), pred.predict(frame))


def _reuse_options(pred: sdk.ShadingRatePredictor, every: int, unseen: str, option: str,
                   shares: dict[str, float]) -> dict[str, Any]:
    """``PredictionReuse`` arguments: ``every``, ``unseen`` and the ``option`` drawn where the model allows it
    (``features`` for a model that splits, ``rescale`` for one with ``.blocks`` planes of an error metric, or
    one of ``shares``, a share each)."""
    kw: dict[str, Any] = {"every": every, "unseen": unseen}
    if option == "features" and pred.splits:
        kw["carry"] = "features"
    elif option == "rescale" and any(c.endswith(".blocks") for c in pred.metadata.inputs) \
            and not pred.metadata.higher_is_better:
        kw["rescale"] = 0.25
    elif option in shares:
        kw[option] = shares[option]
    return kw


def _moving_frames(names: tuple[str, ...], sizes: list[tuple[int, int]], seed: int) -> Any:
    """Three random frames of each size, their ``.blocks`` / ``.tiles`` planes derived from the first plane,
    each with a seen mask (10% unseen) and, but for the first frame and one in ten, fetch positions moved by
    up to three pixels: ``(x, fetch, seen)``."""
    rng = np.random.default_rng(seed)
    ph, pw = sizes[0]
    for f, (h, w) in enumerate(s for s in sizes for _ in range(3)):
        x = rng.random((len(names), h, w), dtype=np.float32)
        for i, c in enumerate(names):
            if c.endswith((".blocks", ".tiles")):
                x[i] = (sdk.tile_variances if c.endswith(".tiles") else sdk.block_variances)(x[0])
        seen = (rng.random((h, w)) > 0.1).astype(np.float32)
        rows, cols = np.indices((h, w))  # (in the previous frame's pixels: dynamic resolution changes the size)
        rows, cols = ((2 * rows + 1) * ph) // (2 * h), ((2 * cols + 1) * pw) // (2 * w)
        fetch = (np.clip(rows + rng.integers(-3, 4, (h, w)), 0, ph - 1),
                 np.clip(cols + rng.integers(-3, 4, (h, w)), 0, pw - 1)) if f and rng.random() < 0.9 else None
        ph, pw = h, w
        yield x, fetch, seen


@settings(max_examples=12, deadline=None)
@given(model=st.sampled_from(["jnyang", "jnyang-reuse", "psnr"]), every=st.integers(1, 4),
       unseen=st.sampled_from(["full", "fresh"]), option=st.sampled_from(["", "features", "rescale", "refresh"]),
       sizes=st.lists(st.sampled_from([(48, 80), (64, 96), (36, 52)]), min_size=1, max_size=3),
       seed=st.integers(0, 2**16))
def test_a_channels_function_gives_what_the_whole_frame_gives_in_any_sequence(
        model: str, every: int, unseen: str, option: str, sizes: list[tuple[int, int]], seed: int) -> None:
    """Any sequence of frames (sizes that change, fetches that move and go missing, unseen pixels), any reuse
    settings the model allows: estimates of the frame's tile grid, no NaN, and from an input function that
    takes ``channels`` the same as from the whole frame, to the bit."""
    pred = sdk.load(model)
    names = pred.metadata.inputs
    kw = _reuse_options(pred, every, unseen, option, {"refresh": 0.05})
    whole, asked = sdk.PredictionReuse(pred, **kw), sdk.PredictionReuse(pred, **kw)
    for x, fetch, seen in _moving_frames(names, sizes, seed):
        h, w = x.shape[1:]
        want = whole.predict(x, fetch, seen)
        got = asked.predict(lambda ys, xs, channels, x=x: x[[names.index(c) for c in channels], ys, xs], fetch, seen)
        assert want.shape == (6, -(-h // TILE), -(-w // TILE)) and not np.isnan(want).any()
        assert np.array_equal(got, want) and asked.work == whole.work and asked.age == whole.age


@settings(max_examples=10, deadline=None)
@given(model=st.sampled_from(["jnyang", "jnyang-reuse", "psnr"]), fine=st.sampled_from([8, 4]),
       every=st.integers(1, 4), unseen=st.sampled_from(["full", "fresh"]),
       option=st.sampled_from(["", "features", "rescale", "refresh", "history"]),
       sizes=st.lists(st.sampled_from([(48, 80), (56, 88), (36, 52)]), min_size=1, max_size=2),
       seed=st.integers(0, 2**16))
def test_reuse_on_finer_hardware_tiles_is_the_model_tiles_reuse_split(
        model: str, fine: int, every: int, unseen: str, option: str, sizes: list[tuple[int, int]], seed: int) -> None:
    """A predictor loaded for AMD's and Intel's 8-pixel tiles (or 4) under a 16-pixel model: the reuse runs,
    crops and carries on the model's tiles and each hardware tile takes its model tile's estimate, so its
    estimates and rates are the model-tile reuse's split (``sdk.split_tiles``) to the bit, on the frame's own
    grid of hardware tiles (sides that are not whole model tiles too), with the same work and age."""
    coarse, split = sdk.load(model), sdk.load(model, tile_size=fine)
    names = coarse.metadata.inputs
    kw = _reuse_options(coarse, every, unseen, option, {"refresh": 0.3, "history": 0.3})
    ours, theirs = sdk.PredictionReuse(coarse, **kw), sdk.PredictionReuse(split, **kw)
    assert theirs.predictor is split and theirs.step == ours.step and theirs.margin == ours.margin
    factor = TILE // fine
    for x, fetch, seen in _moving_frames(names, sizes, seed):
        h, w = x.shape[1:]
        want = ours.shading_rates(x, fetch, seen, threshold=coarse.metadata.default_threshold)
        got = theirs.shading_rates(x, fetch, seen)
        grid = split.tiles(h, w)
        assert got.shape == grid and np.array_equal(got, sdk.split_tiles(want, factor, grid))
        assert theirs.work == ours.work and theirs.age == ours.age
    est = theirs.predict(x, None)  # a cut: the network, then its values split as the predictor's own predict
    np.testing.assert_array_equal(est, split.predict(x))


def test_shading_rates_refuses_every_choice_argument_before_the_carry_moves_on() -> None:
    """A bad ``threshold``, ``allowed`` or ``combiner`` (no budget, no engine rates) was refused only after
    ``predict`` had moved the carry on by a frame: the frame retried with the right argument was then another
    frame of the interval (the network ran a frame early or late)."""
    s = _Scene(3, 4)
    ones = np.ones((s.h, s.w), np.float32)
    reuse = sdk.PredictionReuse(s.pred, 4)
    reuse.shading_rates(s.x)
    for kw, name in (({"threshold": "0.2"}, "threshold"), ({"threshold": float("nan")}, "threshold"),
                     ({"allowed": ["3x3"]}, "allowed"), ({"combiner": "avg"}, "combiner")):
        with pytest.raises(sdk.ParameterError, match=name):
            reuse.shading_rates(s.x, (s.rows, s.cols), ones, **kw)  # type: ignore[arg-type]
        assert reuse.age == 0, kw


def test_shading_rates_reads_an_allowed_iterator_once() -> None:
    """``allowed`` given as an iterator was read by the early checks and found empty by the choice: a budget or
    engine rates on a reuse were refused ("only 1x1 is allowed") after the carry had moved on."""
    s = _Scene(3, 4)
    for kw in ({"saving": 0.5}, {"engine_rates": "2x2"}):
        want = sdk.PredictionReuse(s.pred, 4).shading_rates(s.x, allowed=["2x2"], **kw)  # type: ignore[arg-type]
        got = sdk.PredictionReuse(s.pred, 4).shading_rates(s.x, allowed=iter(["2x2"]), **kw)  # type: ignore[arg-type]
        np.testing.assert_array_equal(got, want)


def test_numpy_flags_are_refused_as_numeric_options() -> None:
    """``True`` is refused for a number; numpy's ``np.True_`` was taken for one (``rescale=np.True_`` an
    exponent of 1, ``carry_scale=np.True_`` a factor of 1, ``unseen_fraction=np.False_`` a share of 0)."""
    s = _Scene(3, 4)
    for kw, name in (({"rescale": np.True_}, "rescale"), ({"carry_scale": np.True_}, "carry_scale"),
                     ({"unseen_fraction": np.False_}, "unseen_fraction"), ({"refresh": np.False_}, "refresh"),
                     ({"history": np.False_}, "history")):
        with pytest.raises(sdk.ParameterError, match=name) as err:
            sdk.PredictionReuse(s.pred, **kw)  # type: ignore[arg-type]
        assert err.value.name == name
    assert sdk.PredictionReuse(s.pred, unseen_fraction=np.float32(0.25)).unseen_fraction == 0.25


def test_inputs_seen_and_background_are_checked_on_every_frame() -> None:
    """Inputs of the wrong dtype or planes, and a ``seen`` or ``background`` of the wrong shape or kind, were
    taken on the frames that do not read them (the inputs on carried frames, the masks on the network's) and
    refused only every few frames, as if that frame's were the wrong ones."""
    s = _Scene(3, 4)
    ones = np.ones((s.h, s.w), np.float32)
    fetch = (s.rows, s.cols)
    carried = sdk.PredictionReuse(s.pred, 4)
    carried.predict(s.x)  # the next frames are carried: the inputs are not read there
    with pytest.raises(sdk.InputDtypeError, match="float32, got dtype float64"):
        carried.predict(s.x.astype(np.float64), fetch, ones)
    with pytest.raises(sdk.InputChannelError, match=r"expected 9 channels .* got shape \(8, 48, 64\)") as err:
        carried.predict(s.x[:-1], fetch, ones)
    assert err.value.expected == "(9, H, W)"
    assert carried.age == 0  # (refused before the carry moved on)
    network = sdk.PredictionReuse(s.pred, 1)  # the network runs on every frame: seen and background are not read
    network.predict(s.x)
    for seen, background, message in ((ones[:, :-1], None, "seen: expected shape"),
                                      (ones.astype(object), None, "seen: expected a numeric array"),
                                      (ones, ones[:-1], "background: expected shape"),
                                      (ones, ones.tolist(), "background: expected a numpy array")):
        with pytest.raises((sdk.InputShapeError, sdk.ParameterError), match=message):
            network.predict(s.x, fetch, seen, background)  # type: ignore[arg-type]


def test_a_resized_frame_refused_midway_leaves_the_reuse_as_it_was() -> None:
    """Dynamic resolution: a frame of another size refused after its carry (a NaN where a fresh crop reads) leaves
    the reuse as before it, as a refused frame of the same size does: the same frame given again with its fetch (of
    the previous frame's pixels) gives what it gives without the refusal, and so does the next. Before, the new size
    was kept and the old size's track not moved: the fetch given again was refused as out of the previous frame."""
    s = _Scene(6, 10)
    h, w = s.h // 2, s.w // 2
    zero = np.zeros((h, w))
    fetch = sdk.fetch_from_motion(zero, zero, prev_shape=(s.h, s.w))
    seen = np.ones((h, w), np.float32)
    seen[:, -TILE:] = 0  # the last tile column unseen: a fresh crop there
    small = s.inputs(np.ones((s.h, s.w), np.float32))[:, ::2, ::2].copy()
    bad = small.copy()
    bad[:, :, -2:] = np.nan
    still = np.indices((h, w))

    def frames(refused: bool) -> list[np.ndarray]:
        reuse = sdk.PredictionReuse(s.pred, 4, unseen="fresh", margin=1)
        reuse.predict(s.inputs(np.ones((s.h, s.w), np.float32)))
        if refused:
            with pytest.raises(sdk.NonFiniteInputError):
                reuse.predict(bad, fetch, seen)
            assert reuse.age == 0
        out = [reuse.predict(small, fetch, seen)]
        assert reuse.age == 1 and 0.0 < reuse.work < 1.0
        out.append(reuse.predict(small, (still[0], np.minimum(still[1] + 3, w - 1)), np.ones((h, w), np.float32)))
        return out

    for a, b in zip(frames(False), frames(True)):
        np.testing.assert_array_equal(a, b)


def test_carry_scale_leaves_a_whole_frame_run_blended_with_history_alone() -> None:
    """``carry_scale`` is for carried frames: a frame whose fresh crops would cover most of it runs the network on
    the whole frame, and with ``history`` blends in the estimates carried there as they are, as a run when the
    interval is up does (before, times carry_scale: the network's frame changed with it)."""
    s = _Scene(6, 10)
    everything = np.ones((s.h, s.w), np.float32)
    seen = everything.copy()
    seen[:, :6 * TILE] = 0  # most of the frame unseen: crops over half of it, the whole frame runs
    x = s.inputs(everything)

    def run_frame(scale: float) -> np.ndarray:
        reuse = sdk.PredictionReuse(s.pred, 4, unseen="fresh", margin=1, history=0.5, carry_scale=scale)
        reuse.predict(x)
        est = reuse.predict(x, (s.rows, s.cols), seen)
        assert reuse.work == 1.0 and reuse.age == 0
        return est

    np.testing.assert_array_equal(run_frame(1.5), run_frame(1.0))


@pytest.mark.parametrize("bad", [-1, 150, 10**6])
def test_a_fetch_out_of_the_frame_at_its_last_pixel_is_refused(bad: int) -> None:
    """On a frame not of whole tiles the carry reads the last pixel's fetch (the padding's corner): out of the
    previous frame there it is refused as anywhere else. Before, it went unchecked: one past the last column was
    read as the next row's first pixel and -1 as the last row's, silently, and further an IndexError."""
    pred = sdk.load("jnyang")
    h, w = 90, 150
    x = np.random.default_rng(0).random((len(pred.metadata.inputs), h, w), dtype=np.float32)
    rows, cols = np.indices((h, w))
    cols[-1, -1] = bad
    reuse = sdk.PredictionReuse(pred, 4)
    reuse.predict(x)
    with pytest.raises(sdk.ParameterError, match=r"fetch cols: expected indices in \[0, 150\)"):
        reuse.predict(x, (rows, cols))
    assert reuse.age == 0


@functools.cache
def _jnyang(tile: int) -> sdk.ShadingRatePredictor:
    return sdk.load("jnyang", tile_size=tile)


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(height=st.integers(1, 50), width=st.integers(1, 50), seed=st.integers(0, 99), tile=st.sampled_from([8, 16, 32]),
       every=st.integers(1, 4), step=st.sampled_from([None, 1, 2, 4, 8, 16]),
       reduce=st.sampled_from(sorted(sdk.REUSE_REDUCTIONS)), history=st.sampled_from([0.0, 0.5]))
def test_a_frame_that_does_not_move_carries_the_network_s_estimates(height: int, width: int, seed: int, tile: int,
                                                                    every: int, step: int | None, reduce: str,
                                                                    history: float) -> None:
    """Frames of any size (partial tiles, one pixel wide), hardware tiles finer or coarser than the model's, any step,
    reduction and history: where nothing moves (fetch each pixel from itself, all seen) every carried frame's
    estimates and rates are the network's."""
    pred = _jnyang(tile)  # (each step divides the tiles reused on: the model's 16, or 32)
    reuse = sdk.PredictionReuse(pred, every=every, step=step, reduce=reduce, history=history)
    x = np.random.default_rng(seed).random((len(pred.metadata.inputs), height, width), dtype=np.float32)
    want = pred.predict(x)
    np.testing.assert_array_equal(reuse.predict(x), want)
    fetch = tuple(np.indices((height, width)))
    for _ in range(3):
        np.testing.assert_allclose(reuse.predict(x, fetch=fetch), want, rtol=1e-5, atol=1e-6)
        assert reuse.shading_rates(x, fetch=fetch).shape == want.shape[1:]


@pytest.mark.parametrize("prev_shape", [(6, 5), (9, 10), (4, 5)])
def test_fetch_from_motion_is_the_texel_reproject_tests_on_a_texel_edge(prev_shape: tuple[int, int]) -> None:
    """Half-pixel motions put the moved centre on a texel's edge: fetch_from_motion gives the texel reproject
    fetches and tests (its seen), at this size and another (dynamic resolution). It rounded the top-left y down,
    the texel below on every vertical motion of a whole number and a half of pixels (0.5: each row fetched the
    next one, its seen the test of another texel)."""
    h, w = 6, 5
    ph, pw = prev_shape
    index = np.arange(ph * pw, dtype=np.float64).reshape(ph, pw)  # each previous texel's own number
    depth, prev_depth = np.ones((h, w)), np.ones((ph, pw))
    proj = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1.02, -0.202], [0, 0, -1, 0]], float)
    for mx, my in [(0.0, 0.5), (0.0, -0.5), (0.5, 1.5), (-0.5, -2.5), (0.25, 0.5), (1.5, 0.0)]:
        motion = np.zeros((h, w, 2))
        motion[..., 0], motion[..., 1] = mx, my
        rep, seen = sdk.reproject(index[..., None], prev_depth, depth, np.eye(4), proj, proj, motion=motion)
        rows, cols = sdk.fetch_from_motion(motion[..., 0], motion[..., 1], prev_shape=prev_shape)
        on = seen > 0
        assert on.sum() >= h * w // 2
        np.testing.assert_array_equal(index[rows, cols][on], rep[..., 0][on], err_msg=f"motion ({mx}, {my})")


def test_one_reuse_called_from_a_second_thread_during_a_frame_refuses_that_call() -> None:
    """docs/runtime.md "Threads and several views": a PredictionReuse holds one view's carry. Two threads calling one
    at once moved it in silence (one frame's estimates carried under another's track) or failed far inside it (an
    IndexError, an AssertionError, a fetch refused as out of a frame it was not of). Now a call (predict,
    shading_rates, reset) while another thread's holds the instance is a ParameterError saying so, and the call under
    way finishes as it would alone: its frame's estimates, and the carry the next frame reads, are the single-threaded
    ones. The second thread is made to call while the first is inside its frame (its input function waits for it)."""
    import copy
    import pickle
    import threading
    from concurrent.futures import ThreadPoolExecutor

    pred = sdk.load("jnyang", threads=1)
    rng = np.random.default_rng(0)
    frames = [rng.random((len(pred.metadata.inputs), 48, 64), dtype=np.float32) for _ in range(3)]
    fetch = sdk.fetch_from_motion(np.full((48, 64), 2.0), np.full((48, 64), -1.0))
    # (rescale reads the inputs on a carried frame: the input function runs inside the first call)
    alone = sdk.PredictionReuse(pred, every=4, rescale=0.5)
    want = [alone.predict(frames[0]), *(alone.predict(f, fetch) for f in frames[1:])]
    reuse = sdk.PredictionReuse(pred, every=4, rescale=0.5)
    reuse.predict(frames[0])
    inside, tried = threading.Event(), threading.Event()

    def planes(ys: slice, xs: slice) -> np.ndarray:  # (the frame's inputs, read while the call holds the reuse)
        inside.set()
        assert tried.wait(20), "the second thread never called"
        return frames[1][:, ys, xs]

    refused: list[str] = []

    def second(call: Any) -> None:
        assert inside.wait(20), "the first call never read its inputs"
        try:
            call()
        except sdk.ParameterError as err:
            refused.append(str(err))
        finally:
            tried.set()

    calls = [lambda: reuse.predict(frames[2], fetch), lambda: reuse.shading_rates(frames[2], fetch), reuse.reset]
    for i, call in enumerate(calls):
        inside.clear()
        tried.clear()
        with ThreadPoolExecutor(2) as pool:
            first = pool.submit(reuse.predict, planes, fetch, np.ones((48, 64), np.float32))
            pool.submit(second, call).result(timeout=30)
            got = first.result(timeout=30)
        assert len(refused) == i + 1 and "this reuse is in a call already (another thread's" in refused[-1]
        if i == 0:
            np.testing.assert_array_equal(got, want[1])
            np.testing.assert_array_equal(reuse.predict(frames[2], fetch), want[2])  # (the carry as alone)
        reuse.reset()
        reuse.predict(frames[0])
    # a copy (another view) or a pickled one has a lock of its own, free
    twin, unpickled = copy.copy(reuse), pickle.loads(pickle.dumps(reuse))
    assert twin._busy is not reuse._busy
    for other in (twin, unpickled, copy.deepcopy(reuse)):
        np.testing.assert_array_equal(other.predict(frames[1], fetch), want[1])
