"""sdk.reproject's bands and threads: the reprojection runs band by band of rows on a few threads
(docs/performance.md "The host-side reprojection and input planes"); these check that no band, thread, projection
shape or forked process changes a value, against the whole frame at once and against a plain
per-pixel reference."""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable
from functools import partial
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
    """``reproject``'s arguments, both frames' cameras of the ``shape`` of :data:`CAMERAS`."""
    proj, prev_proj = CAMERAS[shape](f["projection"])
    return f["prev_colour"], f["prev_depth"], f["depth"], f["view"], proj, prev_proj @ f["prev_view"]


def _previous(shape: str, f: dict[str, Any]) -> dict[str, Any]:
    """The ``prev_proj`` keyword of a ``shape`` whose previous camera is orthographic and not the current one's."""
    proj, prev_proj = CAMERAS[shape](f["projection"])
    return {} if prev_proj is proj else {"prev_proj": prev_proj}


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


def _orthographic(half_width: float = 4.0, half_height: float = 3.0, near: float = 1.0, far: float = 51.0,
                  ) -> np.ndarray:
    """OpenGL's glOrtho of a centred box."""
    m = np.eye(4)
    m[0, 0], m[1, 1] = 1 / half_width, 1 / half_height
    m[2, 2], m[2, 3] = -2 / (far - near), -(far + near) / (far - near)
    return m


def _off_centre(p: np.ndarray) -> np.ndarray:
    """An orthographic projection off-centre (jittered) and oblique (its clip x reads the view z: lines not
    parallel to the view axis, a cabinet projection)."""
    q = p.copy()
    q[0, 3], q[1, 3], q[0, 2] = 0.013, -0.021, 0.06
    return q


#: Each case's (current projection, previous projection) from the frames' perspective.
CAMERAS: dict[str, Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]] = {
    "perspective": lambda p: (p, p),
    "jittered": lambda p: (_jittered(p), _jittered(p)),
    "sheared": lambda p: (_sheared(p), _sheared(p)),
    "orthographic": lambda p: (_orthographic(),) * 2,
    "orthographic off-centre": lambda p: (_off_centre(_orthographic()),) * 2,
    # a switch of cameras (the previous projection given where it is orthographic)
    "perspective now, orthographic before": lambda p: (p, _orthographic(5.0, 3.5, 0.5, 40.0)),
    "orthographic now, perspective before": lambda p: (_orthographic(), p),
}
PROJECTIONS = ["perspective", "jittered", "sheared"]


def _reference_positions(depth: np.ndarray, view: np.ndarray, proj: np.ndarray, prev_vp: np.ndarray,
                         prev_proj: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The module docstring's step 1-2 and the expected depth of step 4, pixel by pixel through the matrices, with
    no shortcut: the pixel's line through its points at NDC depth -1 and 1, the point at its depth on it; the sky a
    perspective's unit direction, an orthographic camera's far plane; the previous depth a perspective's clip w,
    an orthographic camera's view depth through the inverse of ``prev_proj`` (the current one where None)."""
    h, w = depth.shape
    inv_proj, inv_view = np.linalg.inv(proj), np.linalg.inv(view)
    perspective = proj[3, 3] == 0.0
    previous_perspective = prev_vp[3, :3].any()
    inv_prev = np.linalg.inv(proj if prev_proj is None else prev_proj)
    qx, qy, cw = np.empty((h, w)), np.empty((h, w)), np.empty((h, w))
    for y in range(h):
        for x in range(w):
            ndc = [(x + 0.5) / w * 2 - 1, 1 - (y + 0.5) / h * 2]
            a, b = (inv_proj @ [*ndc, z, 1.0] for z in (-1.0, 1.0))
            a, b = a[:3] / a[3], b[:3] / b[3]
            d = float(depth[y, x])
            if d > 0:
                p = np.append(a + (b - a) * (d + a[2]) / (a[2] - b[2]), 1.0)  # -z = d on the line
            else:
                p = np.append(a / np.linalg.norm(a), 0.0) if perspective else np.append(b, 1.0)
            c = prev_vp @ (inv_view @ p)
            safe = c[3] if c[3] > 0 else 1.0
            qx[y, x], qy[y, x] = (c[0] / safe * 0.5 + 0.5) * w, (c[1] / safe * 0.5 + 0.5) * h
            if previous_perspective:
                cw[y, x] = c[3]
            else:
                v = inv_prev @ c
                cw[y, x] = -v[2] / v[3] if v[3] > 0 else 0.0
    return qx, qy, cw


@pytest.mark.parametrize("name", list(CAMERAS))
def test_positions_are_the_matrices_pixel_by_pixel(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every projection shape (each inverse row a row, a column or the full frame), perspective or orthographic
    now and before, in many bands on threads."""
    monkeypatch.setattr(_reproject, "_BAND_PIXELS", 700)
    f = _frames(1)
    *_, depth, view, proj, prev_vp = _args(f, name)
    got = sdk.reproject_positions(depth, view, proj, prev_vp, **_previous(name, f))
    want = _reference_positions(depth, view, proj, prev_vp, _previous(name, f).get("prev_proj"))
    assert (want[2] > 0).mean() > 0.5  # (most of the points in front of the previous camera)
    for g, r in zip(got, want):
        np.testing.assert_allclose(g, r, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", [*PROJECTIONS, "orthographic off-centre"])
@pytest.mark.parametrize("motion", [False, True])
def test_bands_and_threads_change_no_value(name: str, motion: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """Many bands of rows (the last one short) on the pool's threads give the whole frame's values, bit for bit."""
    f = _frames(2)
    args = _args(f, name)
    kw = {"motion": np.random.default_rng(3).uniform(-2, 2, (H, W, 2))} if motion else {}
    if name.startswith("orthographic"):  # (the wall at the depths the orthographic camera expects: some seen)
        _, _, prev_d = sdk.reproject_positions(*args[2:])
        noise = np.random.default_rng(4).uniform(0.99, 1.01, (H, W))
        args = (args[0], np.where(args[1] > 0, np.maximum(prev_d, 0.0) * noise, 0.0), *args[2:])
    monkeypatch.setattr(_reproject, "_BAND_PIXELS", 10**9)  # one band, in the caller's thread
    whole = sdk.reproject(*args, **kw), sdk.reproject_positions(*args[2:])
    for pixels in (700, W, 1):  # bands of 11 rows, of one row, of one row again (fewer pixels than a row)
        monkeypatch.setattr(_reproject, "_BAND_PIXELS", pixels)
        banded = sdk.reproject(*args, **kw), sdk.reproject_positions(*args[2:])
        for a, b in zip([*whole[0], *whole[1]], [*banded[0], *banded[1]]):
            np.testing.assert_array_equal(a, b)
    seen = whole[0][1]
    assert 0.2 < seen.mean() < 0.99  # some seen, some not: the comparison says something
    if name in PROJECTIONS:
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


def test_a_process_forked_while_the_pools_lock_is_held_reprojects(monkeypatch: pytest.MonkeyPatch) -> None:
    """A fork while another thread of the parent holds the pool's lock (building the pool on its first frame in
    bands): that thread does not run in the child, so the child's copy of the lock stayed held and its first
    reprojection in bands waited on it for ever. The child gets a lock of its own."""
    monkeypatch.setattr(_reproject, "_BAND_PIXELS", 700)
    monkeypatch.setattr(_reproject, "_BAND_THREADS", 2)  # (bands on the pool, on a machine of one core too)
    args = _args(_frames(5))
    here = sdk.reproject(*args)
    with _reproject._pool_lock:  # (as a thread of the parent holds it: the child is forked meanwhile)
        pool = multiprocessing.get_context("fork").Pool(1)
    with pool:
        there = pool.apply_async(_reproject_in_child, (args,)).get(timeout=30)
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


def _isometric_pan(shift: float, depth_of: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
                   turn: float = 0.0) -> dict[str, Any]:
    """Two frames of an isometric camera (orthographic, 35 degrees down, 45 degrees round) panning ``shift``
    pixels right along its own x axis: what the previous frame showed at column ``x + shift`` the current one shows
    at ``x``, at the same depth. ``depth_of(x, y)`` gives the depth at a previous frame's pixel centre (columns may
    be fractional); by default a staircase of three heights with some background (0). ``turn`` (degrees) turns the
    current camera about its vertical axis too (its depths are then not those of the scene the matrices say)."""
    rng = np.random.default_rng(17)
    proj = _orthographic(6.0, 6.0 * H / W, 0.5, 80.0)
    pixel = 12.0 / W  # view-space units a pixel covers
    c, s_ = np.cos(np.radians(-35.0)), np.sin(np.radians(-35.0))
    tilt = np.array([[1, 0, 0, 0], [0, c, -s_, 0], [0, s_, c, 0], [0, 0, 0, 1.0]])
    c, s_ = np.cos(np.radians(45.0)), np.sin(np.radians(45.0))
    round_ = np.array([[c, 0, s_, 0], [0, 1, 0, 0], [-s_, 0, c, 0], [0, 0, 0, 1.0]])
    prev_view = tilt @ round_
    prev_view[:3, 3] = (0.4, -0.2, -30.0)
    view = prev_view.copy()
    view[0, 3] -= shift * pixel  # the camera moves right along its own x
    c, s_ = np.cos(np.radians(turn)), np.sin(np.radians(turn))
    view = np.array([[c, 0, s_, 0], [0, 1, 0, 0], [-s_, 0, c, 0], [0, 0, 0, 1.0]]) @ view

    def staircase(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        d = 30.0 + 0.05 * y + 3.0 * (x // 17 % 3)
        return np.where((x // 9 + y // 11) % 7 == 3, 0.0, d)  # some background

    depth_of = depth_of or staircase
    ys, xs = np.mgrid[0:H, 0:W] + 0.5
    prev_depth, depth = depth_of(xs - 0.5, ys - 0.5), depth_of(xs - 0.5 + shift, ys - 0.5)
    return {"prev_colour": rng.uniform(0.05, 1, (H, W, 3)).astype(np.float32), "prev_depth": prev_depth,
            "depth": depth, "view": view, "projection": proj, "prev_view_projection": proj @ prev_view}


def test_an_orthographic_camera_that_pans_reprojects_each_pixel_from_where_it_was() -> None:
    """Isometric views, top-down games, CAD: an orthographic camera's pixels lie on parallel lines, its previous
    depth is its clip z through its projection. Panning k pixels, every pixel shows what the previous frame showed
    k columns on, background included, and the k columns that came into view are unseen; what a new object now
    covers is unseen (its depth is not the previous frame's there)."""
    k = 5
    f = _isometric_pan(k)
    args = [f[n] for n in ("prev_colour", "prev_depth", "depth", "view", "projection", "prev_view_projection")]
    colour, seen = sdk.reproject(*args)
    assert (seen[:, :W - k] == 1).all() and (seen[:, W - k:] == 0).all()
    np.testing.assert_array_equal(colour[:, :W - k], f["prev_colour"][:, k:])
    assert (f["depth"][:, :W - k] == 0).any()  # (background among them: the far plane's points)
    qx, qy, prev_d = sdk.reproject_positions(*args[2:])
    np.testing.assert_allclose(qx - (np.arange(W) + 0.5), k, atol=1e-9)
    np.testing.assert_allclose(prev_d[f["depth"] > 0], f["depth"][f["depth"] > 0], rtol=1e-12)
    # motion.x/y: k pixels to the right in the previous frame, 0 on background
    planes = sdk.input_planes(["seen", "motion.x", "motion.y", "reprojected.g"], **f)
    np.testing.assert_array_equal(planes[0], seen)
    np.testing.assert_allclose(planes[1], np.where(f["depth"] > 0, k, 0), atol=1e-5)
    np.testing.assert_allclose(planes[2], 0, atol=1e-5)
    np.testing.assert_array_equal(planes[3], colour[..., 1])
    # a box that came in front of the wall (a third nearer): unseen where it covers what the wall showed
    near = f["depth"].copy()
    near[20:30, 10:20] *= 0.66
    seen_box = sdk.reproject(args[0], args[1], near, *args[3:])[1]
    assert (seen_box[20:30, 10:20][near[20:30, 10:20] > 0] == 0).all()
    np.testing.assert_array_equal(np.delete(seen_box, np.s_[20:30], 0), np.delete(seen, np.s_[20:30], 0))


def test_a_grazing_plane_under_an_orthographic_camera_is_seen_through_plain_bilinear_depth() -> None:
    """An orthographic camera's depth is affine in screen space on a plane (a perspective's inverse depth is): a
    steep plane panned a quarter of a pixel is seen by the plain bilinear depth of its 2x2 texels, exactly, where
    the nearest texel's depth is a quarter of a pixel's rise off and the perspective's harmonic mean is off by more
    than the tolerance (on its nearer half)."""
    f = _isometric_pan(0.25, lambda x, y: 5.0 + 0.5 * x + 0.0 * y)
    args = [f[n] for n in ("prev_colour", "prev_depth", "depth", "view", "projection", "prev_view_projection")]
    _, seen = sdk.reproject(*args, tolerance=0.001)
    assert (seen[:, :W - 1] == 1).all()


def _singular_perspective(p: np.ndarray) -> np.ndarray:
    """A perspective projection with no inverse (its clip x row 0)."""
    q = p.copy()
    q[0] = 0.0
    return q


def test_the_cameras_the_reprojection_cannot_follow_are_named() -> None:
    """A projection neither perspective nor orthographic, an orthographic one in another API's convention or with
    no inverse, and an orthographic previous camera whose projection is not at hand (a switch from a perspective): each a
    ParameterError naming the matrix, from sdk.check_reprojection as from the functions that reproject."""
    f = _isometric_pan(3)
    proj, prev_vp = f["projection"], f["prev_view_projection"]
    prev_view = np.linalg.inv(proj) @ prev_vp
    persp = Camera((0.0, 1.0, 0.0)).projection(W / H)
    neither = proj.copy()
    neither[3] = (0.0, 0.0, 0.5, 0.5)
    flipped, left_handed = np.diag([1.0, -1.0, 1.0, 1.0]) @ proj, proj @ np.diag([1.0, 1.0, -1.0, 1.0])
    singular = proj.copy()  # an orthographic last row over a matrix with no inverse (numpy's LinAlgError before)
    singular[2] = 0.0
    overflow = proj.copy()  # a depth scale whose view depth overflows: -inf taken for "rising" (and a RuntimeWarning)
    overflow[2, 2], overflow[3, 3] = -1e-300, 1e300
    cases = [  # (projection, prev_view_projection, prev_projection, the matrix named, what is said)
        (neither, prev_vp, None, "projection", "neither a perspective's"),
        (flipped, flipped @ prev_view, None, "projection", "Vulkan"),
        (left_handed, left_handed @ prev_view, None, "projection", "left-handed or reversed-Z"),
        (persp, prev_vp, None, "projection", "orthographic camera's .* pass the previous camera's projection"),
        (persp, prev_vp, persp, "prev_projection", "orthographic camera's"),
        (proj, prev_vp, left_handed, "prev_projection", "left-handed or reversed-Z"),
        (singular, prev_vp, None, "projection", "singular"),
        (proj, prev_vp, singular, "prev_projection", "singular"),
        (overflow, prev_vp, None, "projection", "depth scale is out of range"),
        # a singular perspective (check_reprojection took it, input_planes named it reproject's cur_proj), and a
        # previous view-projection whose last row is 0 (a matrix not set) or -1 (every point behind it): taken as an
        # orthographic camera's, every pixel unseen without a word (or the error of a switch of cameras)
        (_singular_perspective(persp), persp @ prev_view, None, "projection", "singular"),
        (proj, np.zeros((4, 4)), None, "prev_view_projection", "neither a perspective camera's"),
        (persp, np.zeros((4, 4)), None, "prev_view_projection", "neither a perspective camera's"),
        (proj, -prev_vp, None, "prev_view_projection", "neither a perspective camera's"),
    ]
    g = {k: v for k, v in f.items() if k not in ("projection", "prev_view_projection")}
    sdk_names = {"projection": "cur_proj", "prev_projection": "prev_proj", "prev_view_projection": "prev_view_proj"}
    for projection, previous, prev_projection, name, said in cases:
        calls = [
            (partial(sdk.check_reprojection, projection, previous, prev_projection), name),
            (partial(sdk.input_planes, ["seen", "motion.x"], **g, projection=projection, prev_view_projection=previous,
                     prev_projection=prev_projection), name),
            (partial(sdk.reproject, f["prev_colour"], f["prev_depth"], f["depth"], f["view"], projection, previous,
                     prev_proj=prev_projection), sdk_names[name]),
            (partial(sdk.reproject_positions, f["depth"], f["view"], projection, previous, prev_proj=prev_projection),
             sdk_names[name]),
        ]
        for call, named in calls:
            with pytest.raises(sdk.ParameterError, match=said) as err:
                call()
            assert err.value.name == named, (call.func.__name__, said)
    # those that can: orthographic now and before, its projection given or the current one; either to a
    # perspective; and a model that reprojects nothing takes any projection
    sdk.check_reprojection(proj, prev_vp)
    sdk.check_reprojection(persp, prev_vp, proj)
    sdk.check_reprojection(proj, persp @ prev_view)
    assert sdk.input_planes(["depth", "albedo.r"], depth=f["depth"], albedo=f["prev_colour"],
                            projection=neither).shape == (2, H, W)
    window = np.full((H, W), 0.5, np.float32)  # (a depth buffer linearised through the orthographic projection)
    depth = sdk.input_planes(["depth"], depth=window, projection=_orthographic(), depth_kind="window")[0]
    np.testing.assert_allclose(depth, 26.0, rtol=1e-6)  # -(z_ndc - c) / a: the middle of near 1 and far 51


def test_a_singular_view_is_named_as_the_caller_names_it() -> None:
    """A view with no inverse: ``view`` through ``input_planes`` (it said reproject's ``cur_view``), ``cur_view``
    through ``reproject`` and ``reproject_positions``."""
    f = _frames(3)
    view = f["view"].copy()
    view[1] = 0.0
    g = {k: v for k, v in f.items() if k != "prev_view"}
    for channels in (["seen"], ["motion.y"]):
        with pytest.raises(sdk.ParameterError, match="singular") as err:
            sdk.input_planes(channels, **{**g, "view": view})
        assert err.value.name == "view"
    for call in (partial(sdk.reproject, f["prev_colour"], f["prev_depth"]), sdk.reproject_positions):
        with pytest.raises(sdk.ParameterError, match="singular") as err:
            call(f["depth"], view, f["projection"], f["prev_view_projection"])
        assert err.value.name == "cur_view"


def test_check_gbuffers_takes_an_orthographic_frame_and_names_its_mistakes() -> None:
    """The engine's frame checked once: an orthographic frame whose normals face the camera (+z in view space, on
    every pixel alike) and which reprojects draws no warning; normals that face away do."""
    f = _isometric_pan(3)
    toward = np.zeros((H, W, 3), np.float32)
    toward[..., 1], toward[..., 2] = 0.6, 0.8
    g = {k: v for k, v in f.items()}
    assert sdk.check_gbuffers(normal=toward, **g) == []
    away = toward * np.array([1.0, 1.0, -1.0], np.float32)
    assert any("face away" in w for w in sdk.check_gbuffers(normal=away, **g))


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


def _resized_frames(scale: int, up: bool) -> dict[str, Any]:
    """A still camera over a bumpy wall with holes of sky, the previous frame ``scale`` times as large (``up``) or as
    small as this one in each axis, as dynamic resolution leaves it: each of its texels shows the point of the wall
    the pixel of the other frame it falls in shows."""
    rng = np.random.default_rng(31)
    cam = Camera((0.0, 1.0, 0.0), yaw=5.0, pitch=-3.0)
    small = (6.0 + rng.uniform(-0.05, 0.05, (H, W)) + np.linspace(0, 3, W)[None, :]).astype(np.float32)
    small[rng.random((H, W)) < 0.05] = 0.0
    large = np.repeat(np.repeat(small, scale, 0), scale, 1)
    depth, prev_depth = (small, large) if up else (large, small)
    ph, pw = prev_depth.shape
    return {"prev_colour": rng.uniform(0.05, 1, (ph, pw, 3)).astype(np.float32), "prev_depth": prev_depth,
            "depth": depth, "view": cam.view(), "projection": cam.projection(W / H),
            "prev_view_projection": cam.view_projection(W, H)}


@pytest.mark.parametrize("up", [True, False])
def test_a_previous_frame_at_another_render_resolution_reprojects(up: bool) -> None:
    """Dynamic resolution: the previous frame at its own render resolution, three times this one's or a third of it.
    A still camera fetches each pixel from the texel of the previous frame its centre falls in (the middle one of its
    3x3, or the one it is a ninth of), seen; with the engine's motion vectors (in this frame's pixels) one pixel
    right, from three previous texels right (or one, every third pixel). The planes are this frame's size."""
    f = _resized_frames(3, up)
    args = [f[n] for n in ("prev_colour", "prev_depth", "depth", "view", "projection", "prev_view_projection")]
    colour, seen = sdk.reproject(*args)
    h, w = f["depth"].shape
    want = f["prev_colour"][1::3, 1::3] if up else np.repeat(np.repeat(f["prev_colour"], 3, 0), 3, 1)
    assert colour.shape == (h, w, 3) and seen.shape == (h, w)
    assert (seen == 1).all()
    np.testing.assert_array_equal(colour, want)
    qx, qy, _ = sdk.reproject_positions(*args[2:], prev_shape=f["prev_depth"].shape)
    ratio = f["prev_depth"].shape[1] / w
    np.testing.assert_allclose(qx, (np.arange(w) + 0.5)[None, :] * ratio + 0 * qy, rtol=1e-9)
    motion = np.zeros((h, w, 2), np.float32)
    motion[..., 0] = 1.0
    moved, seen_moved = sdk.reproject(*args, motion=motion)
    wall = (seen_moved == 1) & (f["depth"] > 0)  # (the motion vectors move geometry; the sky follows the camera)
    if up:  # the texel three on, where the frame holds it and the wall is there
        inside = wall[:, :-1]
        assert inside.mean() > 0.8
        np.testing.assert_array_equal(moved[:, :-1][inside], f["prev_colour"][1::3, 4::3][inside])
    else:  # the previous texel of the pixel one on
        inside = wall[:, :-1]
        assert inside.mean() > 0.8
        np.testing.assert_array_equal(moved[:, :-1][inside], want[:, 1:][inside])
    planes = sdk.input_planes(["seen", "reprojected.g", "reprojected.y.blocks"], **f)
    assert planes.shape == (3, h, w)
    np.testing.assert_array_equal(planes[1], colour[..., 1])
    with pytest.raises(sdk.InputShapeError, match=r"prev_colour: expected shape .* at prev_depth's size"):
        sdk.input_planes(["seen"], **{**f, "prev_colour": np.zeros((h, w, 3), np.float32) if not up
                                      else np.zeros((h + 1, w, 3), np.float32)})
    with pytest.raises(sdk.InputShapeError, match=r"prev_colour must be \(H', W'\[, C\]\)"):
        sdk.reproject(np.zeros((h + 1, w, 3)), *args[1:])
    for bad in ((0, 5), (2.5, 3), "12x8", (True, 3), (4,)):
        with pytest.raises(sdk.ParameterError, match="prev_shape"):
            sdk.reproject_positions(*args[2:], prev_shape=bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["perspective", "orthographic off-centre"])
def test_positions_in_a_previous_frame_of_another_size_are_the_same_places(name: str) -> None:
    """The previous frame's pixels at another size are the same places in it: positions scaled by the sizes' ratio."""
    f = _frames(8)
    *_, depth, view, proj, prev_vp = _args(f, name)
    same = sdk.reproject_positions(depth, view, proj, prev_vp)
    other = sdk.reproject_positions(depth, view, proj, prev_vp, prev_shape=(2 * H + 1, 3 * W))
    np.testing.assert_allclose(other[0], same[0] * 3, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(other[1], same[1] * (2 * H + 1) / H, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(other[2], same[2])


@pytest.mark.parametrize("layout", ["fortran", "transposed view"])
def test_a_depth_in_any_memory_layout_reprojects_as_a_c_ordered_one(layout: str) -> None:
    """A depth in Fortran order (an image library's) or the transpose of a transposed buffer gives the same
    positions and planes as the same values in C order: the sky's directions were written through a copy and lost,
    so every background pixel came back unseen, 0 in colour, with no error."""
    f = _frames(9)
    args = list(_args(f))
    depth = args[2].astype(np.float64)
    args[2] = {"fortran": np.asfortranarray(depth), "transposed view": np.ascontiguousarray(depth.T).T}[layout]
    assert not args[2].flags.c_contiguous
    np.testing.assert_array_equal(args[2], depth)
    want = sdk.reproject(*_args(f)), sdk.reproject_positions(*_args(f)[2:])
    got = sdk.reproject(*args), sdk.reproject_positions(*args[2:])
    assert (want[0][1][f["depth"] == 0] == 1).any()  # (sky reprojected by rotation: the comparison says something)
    for a, b in zip([*want[0], *want[1]], [*got[0], *got[1]]):
        np.testing.assert_array_equal(a, b)


def test_check_projection_checks_what_a_depth_buffer_needs_of_it() -> None:
    """``check_projection(..., depth_kind=, depth=)``: the public check the moderngl adapter refuses an engine's
    depth-buffer projection with, in sdk.input_planes' words: an orthographic projection outside OpenGL's convention
    only for a hardware depth buffer, and the buffer's points behind the camera only with the buffer."""
    n, f = 1.0, 30.0
    ortho = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -2 / (f - n), -(f + n) / (f - n)], [0, 0, 0, 1.0]])
    left = ortho.copy()
    left[2, 2] = -left[2, 2]
    np.testing.assert_array_equal(sdk.check_projection(left), left)  # linear depth: nothing to linearise
    for kind in ("window", "reversed"):
        with pytest.raises(sdk.ParameterError, match="clip depth does not rise away from the camera"):
            sdk.check_projection(left, depth_kind=kind)
        np.testing.assert_array_equal(sdk.check_projection(ortho, depth_kind=kind), ortho)
    behind = ortho.copy()  # glOrtho(near=-1): the near plane behind the camera
    behind[2, 3] = -(f - 1.0) / (f + 1.0)
    behind[2, 2] = -2 / (f + 1.0)
    window = np.zeros((2, 2), np.float32)  # every pixel on the near plane: 1 behind the camera
    with pytest.raises(sdk.ParameterError, match="behind"):
        sdk.check_projection(behind, "prev_projection", depth_kind="window", depth=window)
    sdk.check_projection(behind, depth_kind="window", depth=np.ones((2, 2), np.float32))  # background only
    with pytest.raises(sdk.ParameterError, match="depth_kind: expected one of linear, window, reversed"):
        sdk.check_projection(ortho, depth_kind="hardware")
    with pytest.raises(sdk.ParameterError, match="depth: checked through the projection only"):
        sdk.check_projection(ortho, depth=window)
    with pytest.raises(sdk.InputShapeError, match=r"expected an \(H, W\) depth buffer"):
        sdk.check_projection(ortho, depth_kind="window", depth=np.zeros((1, 2, 2)))
