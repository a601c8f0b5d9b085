"""sdk.reproject's bands and threads: the reprojection runs band by band of rows on a few threads
(docs/performance.md "The host-side reprojection and input planes"); these check that no band, thread, projection
shape or forked process changes a value, against the whole frame at once and against a plain
per-pixel reference."""

from __future__ import annotations

import multiprocessing
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.scene import Camera
from rtp.sdk import _reproject

H, W = 75, 61  # 61 * 11 = 671 pixels: bands of 11 rows at _BAND_PIXELS = 700, the last one of 9


def _frames(seed: int, sky: bool = True) -> dict[str, Any]:
    """Two frames of a bumpy wall in front of a moving camera, some sky in both (depth 0)."""
    rng = np.random.default_rng(seed)
    cur, prev = Camera((0.0, 1.0, 0.0), yaw=5.0, pitch=-3.0), Camera((0.15, 1.05, 0.2), yaw=8.0, pitch=-2.0)
    depth = (6.0 + rng.uniform(-0.05, 0.05, (H, W)) + np.linspace(0, 3, W)[None, :]).astype(np.float32)
    prev_depth = (6.2 + rng.uniform(-0.05, 0.05, (H, W)) + np.linspace(0, 3, W)[None, :]).astype(np.float32)
    if sky:
        depth[:9] = 0.0
        prev_depth[:7] = 0.0
        depth[rng.random((H, W)) < 0.03] = 0.0  # holes of sky in the wall
    return {"prev_colour": rng.uniform(0, 1, (H, W, 3)).astype(np.float32), "prev_depth": prev_depth,
            "depth": depth, "view": cur.view(), "projection": cur.projection(W / H),
            "prev_view_projection": prev.view_projection(W, H), "prev_view": prev.view()}


def _args(f: dict[str, Any], shape: str = "perspective") -> tuple[Any, ...]:
    """``reproject``'s arguments, both frames' projections of the ``shape`` of :data:`PROJECTIONS`."""
    proj = PROJECTIONS[shape](f["projection"])
    return f["prev_colour"], f["prev_depth"], f["depth"], f["view"], proj, proj @ f["prev_view"]


def _jittered(p: np.ndarray) -> np.ndarray:
    """A TAA-jittered, off-centre projection (still a row or a column per inverse row)."""
    q = p.copy()
    q[0, 2] += 0.37 / W
    q[1, 2] -= 0.21 / H
    return q


def _sheared(p: np.ndarray) -> np.ndarray:
    """A projection whose clip x reads the view y: every inverse row reads x and y (the full-frame path)."""
    q = p.copy()
    q[0, 1] = 0.08
    q[1, 0] = -0.05
    return q


def _orthographic() -> np.ndarray:
    m = np.eye(4)
    m[0, 0], m[1, 1], m[2, 2], m[2, 3] = 1 / 4.0, 1 / 3.0, -2 / 50.0, -52 / 50.0
    return m


PROJECTIONS = {"perspective": lambda p: p, "jittered": _jittered, "sheared": _sheared}


def _reference_positions(depth: np.ndarray, view: np.ndarray, proj: np.ndarray, prev_vp: np.ndarray,
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The module docstring's step 1-2, pixel by pixel through the matrices, with no shortcut."""
    h, w = depth.shape
    inv = np.linalg.inv(view) @ np.linalg.inv(proj)  # clip -> world
    qx, qy, cw = np.empty((h, w)), np.empty((h, w)), np.empty((h, w))
    for y in range(h):
        for x in range(w):
            ndc = np.array([(x + 0.5) / w * 2 - 1, 1 - (y + 0.5) / h * 2, -1.0, 1.0])
            v = np.linalg.inv(proj) @ ndc
            ray = v[:3] / v[3] / -(v[2] / v[3])  # view space, z = -1
            d = float(depth[y, x])
            p = np.append(ray * d, 1.0) if d > 0 else np.append(ray / np.linalg.norm(ray), 0.0)
            c = prev_vp @ (np.linalg.inv(view) @ p)
            safe = c[3] if c[3] > 0 else 1.0
            qx[y, x], qy[y, x], cw[y, x] = (c[0] / safe * 0.5 + 0.5) * w, (c[1] / safe * 0.5 + 0.5) * h, c[3]
    del inv
    return qx, qy, cw


@pytest.mark.parametrize("name", list(PROJECTIONS))
def test_positions_are_the_matrices_pixel_by_pixel(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every projection shape (each inverse row a row, a column or the full frame), in many bands on threads."""
    monkeypatch.setattr(_reproject, "_BAND_PIXELS", 700)
    *_, depth, view, proj, prev_vp = _args(_frames(1), name)
    got = sdk.reproject_positions(depth, view, proj, prev_vp)
    want = _reference_positions(depth, view, proj, prev_vp)
    for g, r in zip(got, want):
        np.testing.assert_allclose(g, r, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", list(PROJECTIONS))
@pytest.mark.parametrize("motion", [False, True])
def test_bands_and_threads_change_no_value(name: str, motion: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """Many bands of rows (the last one short) on the pool's threads give the whole frame's values, bit for bit."""
    f = _frames(2)
    args = _args(f, name)
    kw = {"motion": np.random.default_rng(3).uniform(-2, 2, (H, W, 2))} if motion else {}
    monkeypatch.setattr(_reproject, "_BAND_PIXELS", 10**9)  # one band, in the caller's thread
    whole = sdk.reproject(*args, **kw), sdk.reproject_positions(*args[2:])
    for pixels in (700, W, 1):  # bands of 11 rows, of one row, of one row again (fewer pixels than a row)
        monkeypatch.setattr(_reproject, "_BAND_PIXELS", pixels)
        banded = sdk.reproject(*args, **kw), sdk.reproject_positions(*args[2:])
        for a, b in zip([*whole[0], *whole[1]], [*banded[0], *banded[1]]):
            np.testing.assert_array_equal(a, b)
    seen = whole[0][1]
    assert 0.2 < seen.mean() < 0.99  # some seen, some not: the comparison says something
    assert (seen[f["depth"] == 0] == 1).any()  # sky reprojected by rotation


def test_an_error_in_a_band_reaches_the_caller(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_reproject, "_BAND_PIXELS", 700)
    calls = []

    def failing(*args: Any) -> np.ndarray:
        calls.append(args[3])
        if args[3] == 33:
            raise MemoryError("band 3")
        return np.zeros(args[2].shape, bool)

    monkeypatch.setattr(_reproject, "_band_reproject", failing)
    with pytest.raises(MemoryError, match="band 3"):
        sdk.reproject(*_args(_frames(4)))
    assert 33 in calls


def _reproject_in_child(args: tuple[Any, ...]) -> tuple[np.ndarray, np.ndarray]:
    _reproject._BAND_PIXELS = 700
    return sdk.reproject(*args)


def test_a_forked_process_reprojects_after_its_parent_did(monkeypatch: pytest.MonkeyPatch) -> None:
    """The parent's pool of threads does not follow it into a forked child (which would wait on it for ever)."""
    monkeypatch.setattr(_reproject, "_BAND_PIXELS", 700)
    args = _args(_frames(5))
    here = sdk.reproject(*args)
    assert _reproject._pool is not None  # the parent's threads ran the bands
    with multiprocessing.get_context("fork").Pool(1) as pool:
        there = pool.apply_async(_reproject_in_child, (args,)).get(timeout=60)
    for a, b in zip(here, there):
        np.testing.assert_array_equal(a, b)


def test_input_planes_gathers_the_luma_where_no_colour_plane_is_read() -> None:
    """A model that reads reprojected.y but no colour plane gets the luma of the reprojected colours, bit for bit."""
    f = _frames(6)
    colour, seen = sdk.reproject(*_args(f))
    y = sdk.luma(colour)
    g = {k: v for k, v in f.items() if k != "prev_view"}
    luma_only = sdk.input_planes(["reprojected.y", "seen", "reprojected.y.blocks"], **g)
    with_colour = sdk.input_planes(["reprojected.y", "seen", "reprojected.y.blocks", "reprojected.g"], **g)
    for x in (luma_only, with_colour):
        assert x[0].view(np.uint32).tolist() == y.view(np.uint32).tolist()
        np.testing.assert_array_equal(x[1], seen)
        np.testing.assert_array_equal(x[2], sdk.block_variances(y))
    np.testing.assert_array_equal(with_colour[3], colour[..., 1])
    assert (y[seen == 0] == 0).all() and (y[seen == 1] > 0).mean() > 0.9


def test_an_orthographic_camera_is_refused_where_pixels_are_reprojected() -> None:
    """The reprojection follows rays from the camera's centre and reads the previous depth from the clip w: an
    orthographic camera has neither, and its planes were all unseen. It is named where a plane reprojects, and
    taken where none does."""
    f = _frames(7)
    ortho = _orthographic()
    prev_ortho = ortho @ f["prev_view"]
    g = {k: v for k, v in f.items() if k != "prev_view"}
    calls = {
        "reproject": lambda: sdk.reproject(f["prev_colour"], f["prev_depth"], f["depth"], f["view"], ortho, prev_ortho),
        "positions": lambda: sdk.reproject_positions(f["depth"], f["view"], ortho, prev_ortho),
        "seen": lambda: sdk.input_planes(["seen"], **{**g, "projection": ortho, "prev_view_projection": prev_ortho}),
        "motion": lambda: sdk.input_planes(["motion.x"], **{**g, "projection": ortho,
                                                           "prev_view_projection": prev_ortho}),
        # a perspective now and an orthographic before (a camera switch): the previous one is named
        "previous": lambda: sdk.input_planes(["reprojected.y"], **{**g, "prev_view_projection": prev_ortho}),
        "reproject previous": lambda: sdk.reproject(f["prev_colour"], f["prev_depth"], f["depth"], f["view"],
                                                    f["projection"], prev_ortho),
    }
    names = {"reproject": "cur_proj", "positions": "cur_proj", "seen": "projection", "motion": "projection",
             "previous": "prev_view_projection", "reproject previous": "prev_view_proj"}
    for what, call in calls.items():
        with pytest.raises(sdk.ParameterError, match="orthographic camera") as err:
            call()
        assert err.value.name == names[what], what
    planes = sdk.input_planes(["depth", "albedo.r"], depth=f["depth"], albedo=f["prev_colour"], projection=ortho)
    assert planes.shape == (2, H, W)
    window = np.full((H, W), 0.5, np.float32)  # (a depth buffer linearised through the orthographic projection)
    depth = sdk.input_planes(["depth"], depth=window, projection=ortho, depth_kind="window")[0]
    np.testing.assert_allclose(depth, 26.0, rtol=1e-6)  # -(z_ndc - c) / a: the middle of near 1 and far 51
    np.testing.assert_array_equal(sdk.check_projection(ortho), ortho)
    with pytest.raises(sdk.ParameterError, match="no perspective's w row"):
        sdk.check_projection(ortho, perspective=True)


def test_callers_on_several_threads_share_the_pool(monkeypatch: pytest.MonkeyPatch) -> None:
    """An engine that makes planes on two threads at once (two views, or a worker per frame): the calls share the
    pool of bands (its workers never wait on one another, so none can deadlock) and each gets its own frame's
    values."""
    from concurrent.futures import ThreadPoolExecutor

    monkeypatch.setattr(_reproject, "_BAND_PIXELS", 700)
    frames = [_args(_frames(10 + i)) for i in range(6)]
    alone = [sdk.reproject(*a) for a in frames]
    with ThreadPoolExecutor(3) as callers:
        together = list(callers.map(lambda a: sdk.reproject(*a), frames * 3))
    for i, (colour, seen) in enumerate(together):
        np.testing.assert_array_equal(colour, alone[i % 6][0])
        np.testing.assert_array_equal(seen, alone[i % 6][1])
    assert len({a[1].tobytes() for a in alone}) == 6  # (six different frames: a mix-up would show)
