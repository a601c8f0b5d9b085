"""Properties of the reprojection and the input planes (hypothesis), on small random frames (1x1 to 64x48),
perspective and orthographic cameras at random poses, linear, window and reversed-Z depth, with and without the
engine's motion vectors: what docs/runtime.md ("Input planes from G-buffers on the host", "Objects that move",
"Dynamic resolution", the orthographic camera) and the module docstring of ``sdk/_reproject.py`` promise.

The invariants:

* the same camera twice, the same depth: every pixel seen (geometry and sky), the reprojected colour the previous
  colour to the bit, the positions the pixel centres, the expected depth the depth, the motion 0;
* a camera moved sideways, up or along its view axis: the positions move as the matrices say (motion: previous
  minus current position in pixels, x right, y down), a perspective's by the focal length over the depth, an
  orthographic camera's by the frame's scale alone; the expected depth the depth plus the move back;
* a depth given as a window or reversed-Z buffer of the same projection: the planes of the linear depth, within
  float32 precision;
* ``fetch_from_motion`` of zero motion: every pixel from itself; of any motion: the texel ``reproject`` fetches and
  tests for that motion (on the previous frame, of any size), and ``reproject_positions`` names that texel too;
* occlusion: a previous surface nearer than the tolerance leaves the pixel unseen, one within it seen; the sky
  seen only where the previous texel is sky;
* ``input_planes`` of channels in any order: the planes of one order permuted; each plane finite and in its
  channel's range;
* NaN, a wrong shape or a projection of another convention: the typed errors.

Example counts are small for CI (a few seconds a property); ``RTP_PROPERTY_EXAMPLES`` runs more.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from rtp import sdk

#: Examples a property (``RTP_PROPERTY_EXAMPLES`` to explore: more, and a new draw each run; CI: the same few).
EXAMPLES = int(os.environ.get("RTP_PROPERTY_EXAMPLES", "0")) or 50
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                    derandomize="RTP_PROPERTY_EXAMPLES" not in os.environ)


def _rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """A camera-to-world rotation (columns: the camera's right, up and back axes)."""
    cy, sy, cp, sp, cr, sr = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    return (np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]) @ np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
            @ np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]]))


def _view(position: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """The world-to-view matrix of a camera at ``position`` turned by ``rotation``."""
    m = np.eye(4)
    m[:3, :3] = rotation.T
    m[:3, 3] = -rotation.T @ position
    return m


def _perspective(fov_y: float, aspect: float, near: float, far: float) -> np.ndarray:
    """OpenGL's gluPerspective (``far`` infinite: the infinite far plane's limit)."""
    f = 1.0 / np.tan(fov_y / 2.0)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1], m[3, 2] = f / aspect, f, -1.0
    if np.isinf(far):
        m[2, 2], m[2, 3] = -1.0, -2.0 * near
    else:
        m[2, 2], m[2, 3] = -(far + near) / (far - near), -2.0 * far * near / (far - near)
    return m


def _orthographic(half_width: float, half_height: float, near: float, far: float) -> np.ndarray:
    """OpenGL's glOrtho of a centred box."""
    m = np.eye(4)
    m[0, 0], m[1, 1] = 1.0 / half_width, 1.0 / half_height
    m[2, 2], m[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
    return m


def _window(linear: np.ndarray, projection: np.ndarray) -> np.ndarray:
    """The OpenGL window depth (in [0, 1], 1 on background) of a linear depth through ``projection``."""
    geo = linear > 0.0
    z = -np.where(geo, linear.astype(np.float64), 1.0)
    ndc = (projection[2, 2] * z + projection[2, 3]) / (projection[3, 2] * z + projection[3, 3])
    return np.where(geo, ndc * 0.5 + 0.5, 1.0)


@st.composite
def frames(draw: st.DrawFn, *, kinds: tuple[str, ...] = ("perspective", "orthographic"), sky: bool = True,
           max_far_ratio: float = 1000.0) -> dict[str, Any]:
    """A camera at a random pose over a frame of random depths between its near and far planes (some sky, depth
    0, where ``sky``) and a random previous colour."""
    kind = draw(st.sampled_from(kinds))
    h, w = draw(st.integers(1, 48)), draw(st.integers(1, 64))
    position = np.array(draw(st.tuples(*[st.floats(-5.0, 5.0)] * 3)))
    rotation = _rotation(draw(st.floats(-3.1, 3.1)), draw(st.floats(-1.5, 1.5)), draw(st.floats(-3.1, 3.1)))
    near = draw(st.floats(0.05, 1.0))
    far = near * draw(st.floats(10.0, max_far_ratio))
    if kind == "perspective":
        projection = _perspective(np.radians(draw(st.floats(20.0, 120.0))), w / h, near, far)
    else:
        projection = _orthographic(draw(st.floats(0.5, 20.0)), draw(st.floats(0.5, 20.0)), near, far)
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    depth = np.exp(rng.uniform(np.log(near * 1.01), np.log(far * 0.99), (h, w))).astype(np.float32)
    if sky:
        depth[rng.random((h, w)) < draw(st.sampled_from([0.0, 0.1, 0.5, 1.0]))] = 0.0
    return {"kind": kind, "h": h, "w": w, "position": position, "rotation": rotation, "near": near, "far": far,
            "view": _view(position, rotation), "projection": projection, "depth": depth,
            "colour": rng.uniform(0.0, 1.0, (h, w, 3)).astype(np.float32), "rng": rng}


def _centres(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """The pixel centres in OpenGL window coordinates (x right, y up from the bottom-left corner), ``(H, W)`` each."""
    xs = np.broadcast_to((np.arange(w) + 0.5)[None, :], (h, w))
    ys = np.broadcast_to((h - (np.arange(h) + 0.5))[:, None], (h, w))
    return xs, ys


# -- the same camera twice -------------------------------------------------------------------------------------


@SETTINGS
@given(frames())
def test_the_same_camera_twice_sees_every_pixel_where_it_was(f: dict[str, Any]) -> None:
    vp = f["projection"] @ f["view"]
    colour, seen = sdk.reproject(f["colour"], f["depth"], f["depth"], f["view"], f["projection"], vp)
    assert seen.dtype == np.float32 and colour.dtype == np.float32
    assert (seen == 1.0).all()
    np.testing.assert_array_equal(colour, f["colour"])
    qx, qy, d = sdk.reproject_positions(f["depth"], f["view"], f["projection"], vp)
    xs, ys = _centres(f["h"], f["w"])
    np.testing.assert_allclose(qx, xs, rtol=0, atol=1e-6)
    np.testing.assert_allclose(qy, ys, rtol=0, atol=1e-6)
    geo = f["depth"] > 0.0
    np.testing.assert_allclose(d[geo], f["depth"][geo], rtol=1e-6)
    assert (d > 0.0).all()  # (the sky too: in front of the camera, a direction or the far plane's point)
    motion = sdk.input_planes(["motion.x", "motion.y"], depth=f["depth"], view=f["view"], projection=f["projection"],
                              prev_view_projection=vp)
    np.testing.assert_allclose(motion, 0.0, atol=1e-4)


# -- a camera that moves ---------------------------------------------------------------------------------------


@SETTINGS
@given(frames(), st.sampled_from(["right", "up", "back"]), st.floats(-2.0, 2.0))
def test_a_camera_moved_along_its_axes_moves_the_pixels_as_the_conventions_say(f: dict[str, Any], axis: str,
                                                                                 t: float) -> None:
    """The previous camera ``t`` along the current one's right, up or back axis. Its view point is the current one
    minus ``t`` along that axis: a perspective's pixels move by its focal length times ``t`` over the depth (the
    sky not at all), an orthographic camera's by its scale times ``t`` (the sky, its far plane's points, too);
    motion is previous minus current position, x right and y down, so a previous camera to the right (or up)
    moves the pixels left (or down). Moved back, a perspective's pixels move towards the centre by depth over
    depth plus ``t``; the expected depth is the depth plus ``t``."""
    h, w, depth, proj = f["h"], f["w"], f["depth"].astype(np.float64), f["projection"]
    if axis == "back":
        t = max(t, -0.5 * f["near"])  # (in front of the previous camera)
    offset = f["rotation"][:, {"right": 0, "up": 1, "back": 2}[axis]] * t
    prev_vp = proj @ _view(f["position"] + offset, f["rotation"])
    qx, qy, d = sdk.reproject_positions(f["depth"], f["view"], proj, prev_vp)
    motion = sdk.input_planes(["motion.x", "motion.y"], depth=f["depth"], view=f["view"], projection=proj,
                              prev_view_projection=prev_vp)
    xs, ys = _centres(h, w)
    geo = depth > 0.0
    perspective = f["kind"] == "perspective"
    # the move in NDC per unit of t: a perspective's over the depth (0 on the sky), an orthographic camera's alone
    per_depth = np.where(geo, 1.0 / np.where(geo, depth, 1.0), 0.0) if perspective else np.ones_like(depth)
    want_x, want_y, want_d = xs.copy(), ys.copy(), np.where(geo, depth, np.nan)
    if axis == "right":
        want_x = xs - w / 2 * proj[0, 0] * t * per_depth
    elif axis == "up":
        want_y = ys - h / 2 * proj[1, 1] * t * per_depth
    else:
        if perspective:
            shrink = np.where(geo, depth / np.where(geo, depth + t, 1.0), 1.0)
            want_x, want_y = w / 2 + (xs - w / 2) * shrink, h / 2 + (ys - h / 2) * shrink
        want_d = want_d + t
    if not perspective:
        want_d = np.where(geo, want_d, f["far"] + (t if axis == "back" else 0.0))  # (the far plane's points)
    np.testing.assert_allclose(qx, want_x, rtol=1e-6, atol=1e-6 * w)
    np.testing.assert_allclose(qy, want_y, rtol=1e-6, atol=1e-6 * h)
    known = ~np.isnan(want_d)
    np.testing.assert_allclose(d[known], want_d[known], rtol=1e-6, atol=1e-9)
    # motion.x/y: the same move, in pixels, y down; 0 on the sky
    np.testing.assert_allclose(motion[0], np.where(geo, want_x - xs, 0.0), rtol=1e-4, atol=1e-4 * w)
    np.testing.assert_allclose(motion[1], np.where(geo, -(want_y - ys), 0.0), rtol=1e-4, atol=1e-4 * h)
    if axis == "right" and t > 0.0:  # the signs, as the conventions put them (within rounding of 0)
        assert (motion[0][geo] <= 1e-4).all()
    if axis == "up" and t > 0.0:
        assert (motion[1][geo] >= -1e-4).all()


# -- depth kinds -----------------------------------------------------------------------------------------------

#: Every channel of a frame (the planes compared between depth kinds, orders and ranges).
ALL = tuple(sdk.CHANNELS)


def _gbuffers(f: dict[str, Any], prev_vp: np.ndarray, prev_depth: np.ndarray | None = None) -> dict[str, Any]:
    """Every G-buffer of the frame ``f`` (random material and normals), its previous frame seen through ``prev_vp``
    with ``prev_depth`` (the frame's own depth where None)."""
    rng = np.random.default_rng(int(f["rng"].integers(2**32)))
    h, w = f["h"], f["w"]
    normal = rng.normal(size=(h, w, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return {"depth": f["depth"], "albedo": rng.uniform(0, 1, (h, w, 3)).astype(np.float32),
            "normal": normal.astype(np.float32), **{b: rng.uniform(0, 1, (h, w)).astype(np.float32) for b in
                                                    ("roughness", "metallic", "specular", "shadow", "emissive")},
            "view": f["view"], "projection": f["projection"], "prev_colour": f["colour"],
            "prev_depth": f["depth"] if prev_depth is None else prev_depth, "prev_view_projection": prev_vp}


@SETTINGS
@given(frames(max_far_ratio=100.0), st.sampled_from(["window", "reversed"]), st.floats(-0.3, 0.3))
def test_a_depth_buffer_gives_the_planes_of_its_linear_depth(f: dict[str, Any], kind: str, t: float) -> None:
    """The window (or reversed-Z) depth of the same projection, ``depth_kind`` saying so: the planes of the linear
    depth, within float32 precision (the previous frame's depth converted too). With the same camera twice
    ``seen`` and the colour are exact; with a moved one the positions and depths are the same within rounding."""
    proj = f["projection"]
    gb = _gbuffers(f, proj @ f["view"])
    linear = sdk.input_planes(ALL, **gb)
    window = _window(f["depth"], proj)
    raw = (1.0 - window if kind == "reversed" else window).astype(np.float32)
    hardware = sdk.input_planes(ALL, **{**gb, "depth": raw, "prev_depth": raw}, depth_kind=kind)
    depth_at = ALL.index("depth")
    np.testing.assert_allclose(hardware[depth_at], linear[depth_at], rtol=2e-3)
    for i, c in enumerate(ALL):
        if c not in ("depth", "depth.edge"):
            np.testing.assert_allclose(hardware[i], linear[i], rtol=0, atol=1e-6, err_msg=c)
    np.testing.assert_allclose(hardware[ALL.index("depth.edge")], linear[ALL.index("depth.edge")], atol=1e-2)
    # a camera moved sideways: the motion of the linearised depth
    moved = proj @ _view(f["position"] + f["rotation"][:, 0] * t, f["rotation"])
    a = sdk.input_planes(["motion.x", "motion.y"], depth=f["depth"], view=f["view"], projection=proj,
                         prev_view_projection=moved)
    b = sdk.input_planes(["motion.x", "motion.y"], depth=raw, view=f["view"], projection=proj,
                         prev_view_projection=moved, depth_kind=kind)
    np.testing.assert_allclose(b, a, rtol=2e-3, atol=1e-3 * max(f["h"], f["w"]))


@SETTINGS
@given(st.integers(1, 48), st.integers(1, 64), st.floats(0.01, 1.0), st.integers(0, 2**32 - 1))
def test_a_reversed_depth_of_an_infinite_far_plane_is_its_linear_depth(h: int, w: int, near: float,
                                                                      seed: int) -> None:
    """The reversed-Z buffer of an infinite far plane holds ``near / z``: linearised, the depth to float32
    precision, from the near plane to 10^5 times it (docs/runtime.md)."""
    rng = np.random.default_rng(seed)
    depth = (near * np.exp(rng.uniform(0.0, np.log(1e5), (h, w)))).astype(np.float32)
    depth[rng.random((h, w)) < 0.2] = 0.0
    proj = _perspective(np.radians(60.0), w / h, near, np.inf)
    raw = np.where(depth > 0.0, near / np.where(depth > 0.0, depth.astype(np.float64), 1.0), 0.0).astype(np.float32)
    plane = sdk.input_planes(["depth"], depth=raw, projection=proj, depth_kind="reversed")[0]
    np.testing.assert_allclose(plane, depth, rtol=1e-6)


# -- where each pixel comes from -------------------------------------------------------------------------------


def _ids(shape: tuple[int, int]) -> np.ndarray:
    """A previous colour that names its texel: ``(row * W + col + 1) / (H * W + 1)``, distinct in float32."""
    n = shape[0] * shape[1]
    return ((np.arange(n, dtype=np.float64) + 1.0) / (n + 1.0)).astype(np.float32).reshape(shape)


def _texel(ids: np.ndarray, value: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (row, col) of the texel whose :func:`_ids` value is ``value``."""
    flat = np.searchsorted(ids.ravel(), value)
    return np.divmod(flat, ids.shape[1])


@SETTINGS
@given(frames(kinds=("perspective",), sky=False), st.integers(1, 70), st.integers(1, 70), st.booleans())
def test_fetch_from_motion_is_the_texel_reproject_fetches(f: dict[str, Any], ph: int, pw: int, same: bool) -> None:
    """A still camera over a wall facing it (one depth: every depth test passes), the previous frame of any size
    ``(ph, pw)``: ``reproject`` with the engine's motion fetches, on every pixel it sees, the texel
    ``fetch_from_motion`` names for that motion, and sees exactly the pixels whose moved centre is on the previous
    frame (``fetch_from_motion`` keeps the others inside it). Zero motion: every pixel from itself."""
    h, w = f["h"], f["w"]
    depth = np.full((h, w), f["depth"][0, 0], np.float32)
    vp = f["projection"] @ f["view"]
    zero = np.zeros((h, w))
    rows, cols = sdk.fetch_from_motion(zero, zero)
    np.testing.assert_array_equal(rows, np.broadcast_to(np.arange(h)[:, None], (h, w)))
    np.testing.assert_array_equal(cols, np.broadcast_to(np.arange(w)[None, :], (h, w)))
    rng = f["rng"]
    # motions of whole and half pixels (a texel's edge: the previous frame's where its size is this one's) and any other
    mx, my = (np.where(rng.random((h, w)) < 0.5, rng.integers(-140, 141, (h, w)) / 2.0,
                       rng.uniform(-70.0, 70.0, (h, w))) for _ in range(2))
    ph, pw = (h, w) if same else (ph, pw)
    ids = _ids((ph, pw))
    colour, seen = sdk.reproject(ids, np.full((ph, pw), depth[0, 0], np.float32), depth, f["view"],
                                 f["projection"], vp, motion=np.stack([mx, my], -1))
    rows, cols = sdk.fetch_from_motion(mx, my, prev_shape=(ph, pw))
    xs, ys = _centres(h, w)
    gx, gy = (xs + mx) * (pw / w), (ys - my) * (ph / h)  # the moved centre, in the previous frame's window
    np.testing.assert_array_equal(seen == 1.0, (gx >= 0) & (gx < pw) & (gy >= 0) & (gy < ph))
    got_rows, got_cols = _texel(ids, colour[seen == 1.0])
    np.testing.assert_array_equal(got_rows, rows[seen == 1.0])
    np.testing.assert_array_equal(got_cols, cols[seen == 1.0])
    assert ((rows >= 0) & (rows < ph) & (cols >= 0) & (cols < pw)).all()


@SETTINGS
@given(frames(), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-0.2, 0.2), st.floats(-0.1, 0.1))
def test_reproject_fetches_the_texel_reproject_positions_names(f: dict[str, Any], tx: float, ty: float, tz: float,
                                                              turn: float) -> None:
    """A camera that moves and turns, the previous frame's depth its own: wherever ``reproject`` sees a pixel,
    its colour is the previous frame's texel ``(H - 1 - floor(qy), floor(qx))`` of ``reproject_positions``, on
    that frame; a position off it or behind the previous camera is never seen, and unseen pixels are 0."""
    h, w, proj = f["h"], f["w"], f["projection"]
    rotation = _rotation(turn, turn / 2, 0.0) @ f["rotation"]
    prev_view = _view(f["position"] + f["rotation"] @ np.array([tx, ty, tz]), rotation)
    prev_vp = proj @ prev_view
    ids = _ids((h, w))
    prev_depth = np.abs(f["rng"].permutation(f["depth"].ravel()).reshape(h, w))
    colour, seen = sdk.reproject(ids, prev_depth, f["depth"], f["view"], proj, prev_vp)
    qx, qy, d = sdk.reproject_positions(f["depth"], f["view"], proj, prev_vp)
    on = (d > 0.0) & (qx >= 0.0) & (qx < w) & (qy >= 0.0) & (qy < h)
    assert not (seen == 1.0)[~on].any()
    assert (colour[seen == 0.0] == 0.0).all()
    s = seen == 1.0
    rows, cols = _texel(ids, colour[s])
    np.testing.assert_array_equal(rows, h - 1 - np.floor(qy[s]).astype(int))
    np.testing.assert_array_equal(cols, np.floor(qx[s]).astype(int))
    # the sky is seen where its texel is sky, geometry never there
    sky_texel = np.zeros((h, w), bool)
    sky_texel[s] = prev_depth[rows, cols] == 0.0
    assert ((f["depth"] == 0.0) == sky_texel)[s].all()


# -- occlusion and the sky -------------------------------------------------------------------------------------


@SETTINGS
@given(frames(), st.floats(0.0, 0.9), st.floats(1e-3, 0.2), st.floats(0.0, 1.0))
def test_a_nearer_previous_surface_hides_the_pixel(f: dict[str, Any], nearer: float, tolerance: float,
                                                   share: float) -> None:
    """The same camera twice, the previous frame's surfaces nearer by ``nearer`` (a share of the depth) on a random
    part of the pixels: those pixels unseen where ``nearer`` is past ``tolerance``, seen within it; the others
    seen. Sky in this frame where the previous one has geometry: unseen; geometry where it had sky: unseen."""
    assume(abs(nearer - tolerance) > 1e-3)
    h, w, depth = f["h"], f["w"], f["depth"]
    hidden = f["rng"].random((h, w)) < share
    prev_depth = np.where(hidden, depth * np.float32(1.0 - nearer), depth).astype(np.float32)
    vp = f["projection"] @ f["view"]
    colour, seen = sdk.reproject(f["colour"], prev_depth, depth, f["view"], f["projection"], vp,
                                 tolerance=tolerance)
    geo = depth > 0.0
    want = ~(hidden & geo) | (nearer <= tolerance)
    np.testing.assert_array_equal(seen == 1.0, want)
    np.testing.assert_array_equal(colour, np.where(want[..., None], f["colour"], 0.0))
    # sky where it had geometry, geometry where it had sky
    flipped = f["rng"].random((h, w)) < 0.5
    swapped = np.where(flipped, np.where(geo, 0.0, f["near"] * 2.0), depth).astype(np.float32)
    _, seen = sdk.reproject(f["colour"], swapped, depth, f["view"], f["projection"], vp)
    np.testing.assert_array_equal(seen == 1.0, ~flipped)


# -- the planes: any order, in range ---------------------------------------------------------------------------


@st.composite
def moved_frames(draw: st.DrawFn) -> tuple[dict[str, Any], dict[str, Any]]:
    """A frame, and its G-buffers with a previous camera moved and turned a little (its depth a random one, its
    motion vectors given or not)."""
    f = draw(frames())
    offset = np.array(draw(st.tuples(*[st.floats(-0.5, 0.5)] * 3)))
    turn = draw(st.floats(-0.2, 0.2))
    prev_vp = f["projection"] @ _view(f["position"] + offset, _rotation(turn, 0.0, 0.0) @ f["rotation"])
    prev_depth = f["rng"].permutation(f["depth"].ravel()).reshape(f["depth"].shape)
    gb = _gbuffers(f, prev_vp, prev_depth)
    if draw(st.booleans()):
        gb["motion"] = f["rng"].uniform(-8.0, 8.0, (f["h"], f["w"], 2)).astype(np.float32)
    return f, gb


@SETTINGS
@given(moved_frames(), st.randoms(use_true_random=False))
def test_the_planes_of_channels_in_any_order_are_one_orders_permuted(frame: tuple[dict[str, Any], dict[str, Any]],
                                                                     random: Any) -> None:
    """``input_planes`` of any selection of channels, in any order (repeats included): the planes of every channel
    in ``sdk.CHANNELS``' order, picked out. Each plane is finite, float32 and within its channel's range."""
    f, gb = frame
    every = sdk.input_planes(ALL, **gb)
    assert every.dtype == np.float32 and every.shape == (len(ALL), f["h"], f["w"])
    assert np.isfinite(every).all()
    for plane, name in zip(every, ALL):
        channel = sdk.CHANNELS[name]
        assert channel.low <= plane.min() and plane.max() <= channel.high, name
    picked = [random.choice(ALL) for _ in range(random.randint(1, 8))]
    np.testing.assert_array_equal(sdk.input_planes(picked, **gb), every[[ALL.index(c) for c in picked]])
    order = list(ALL)
    random.shuffle(order)
    np.testing.assert_array_equal(sdk.input_planes(order, **gb), every[[ALL.index(c) for c in order]])
    geo = f["depth"] > 0.0
    if "motion" in gb:  # the engine's motion: the motion planes on geometry, 0 on background
        for i, c in enumerate(("motion.x", "motion.y")):
            np.testing.assert_array_equal(every[ALL.index(c)], np.where(geo, gb["motion"][..., i], 0.0))
    for c in ("albedo.r", "normal.z", "roughness", "metallic", "specular"):  # 0 on background
        assert (every[ALL.index(c)][~geo] == 0.0).all(), c
    seen = every[ALL.index("seen")]
    assert set(np.unique(seen)) <= {0.0, 1.0}
    for c in ("reprojected.r", "reprojected.g", "reprojected.b", "reprojected.y"):  # 0 where unseen
        assert (every[ALL.index(c)][seen == 0.0] == 0.0).all(), c
    np.testing.assert_array_equal(every[ALL.index("depth")], f["depth"])


# -- refused inputs --------------------------------------------------------------------------------------------


@SETTINGS
@given(frames(sky=False), st.sampled_from(["depth", "prev_depth", "prev_colour", "view", "projection",
                                           "prev_view_projection", "motion"]), st.data())
def test_a_nan_anywhere_is_a_non_finite_input_error(f: dict[str, Any], where: str, data: st.DataObject) -> None:
    gb = {**_gbuffers(f, f["projection"] @ f["view"]), "motion": np.zeros((f["h"], f["w"], 2), np.float32)}
    bad = np.array(gb[where], np.float64)
    index = tuple(data.draw(st.integers(0, n - 1)) for n in bad.shape)
    bad[index] = data.draw(st.sampled_from([np.nan, np.inf, -np.inf]))
    with pytest.raises(sdk.NonFiniteInputError, match=where):
        sdk.input_planes(["seen", "reprojected.y", "motion.x"], **{**gb, where: bad})
    args = {"prev_colour": gb["prev_colour"], "prev_depth": gb["prev_depth"], "depth": gb["depth"],
            "cur_view": gb["view"], "cur_proj": gb["projection"], "prev_view_proj": gb["prev_view_projection"],
            "motion": gb["motion"]}
    named = {"view": "cur_view", "projection": "cur_proj", "prev_view_projection": "prev_view_proj"}.get(where, where)
    with pytest.raises(sdk.NonFiniteInputError, match=named):
        sdk.reproject(**{**args, named: bad})
    if where in ("depth", "view", "projection", "prev_view_projection"):
        with pytest.raises(sdk.NonFiniteInputError, match=named):
            sdk.reproject_positions(**{k: v for k, v in {**args, named: bad}.items()
                                       if k in ("depth", "cur_view", "cur_proj", "prev_view_proj")})


#: A projection in another API's convention (docs/runtime.md "Matrices from Direct3D, Vulkan and Metal"), each
#: refused with a ParameterError that names it.
_CONVERTED = {
    "row vectors": lambda p: p.T,
    "left-handed": lambda p: p @ np.diag([1.0, 1.0, -1.0, 1.0]),
    "reversed-Z": lambda p: np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, -2, 1], [0, 0, 0, 1]]) @ p,
    "clip y down": lambda p: np.diag([1.0, -1.0, 1.0, 1.0]) @ p,
    "singular": lambda p: np.where(np.arange(4)[:, None] == 0, 0.0, p),
}


@SETTINGS
@given(frames(), st.sampled_from(sorted(_CONVERTED)))
def test_a_projection_of_another_convention_is_refused(f: dict[str, Any], how: str) -> None:
    """Through ``input_planes`` and ``reproject``: a ParameterError naming the projection by its argument's name."""
    bad = _CONVERTED[how](f["projection"])
    gb = _gbuffers(f, f["projection"] @ f["view"])
    for channels in (["seen"], ["motion.x"]):
        with pytest.raises(sdk.ParameterError, match="projection") as err:
            sdk.input_planes(channels, **{**gb, "projection": bad, "prev_view_projection": bad @ f["view"]})
        assert err.value.name == "projection"
    with pytest.raises(sdk.ParameterError, match="cur_proj") as err:
        sdk.reproject(f["colour"], f["depth"], f["depth"], f["view"], bad, bad @ f["view"])
    assert err.value.name == "cur_proj"
    with pytest.raises(sdk.ParameterError) as err:
        sdk.check_reprojection(bad, bad @ f["view"])
    assert err.value.name == "projection"


@SETTINGS
@given(frames(), st.sampled_from(["depth", "prev_colour", "motion"]), st.integers(-1, 1), st.integers(-1, 1))
def test_a_buffer_of_the_wrong_size_is_an_input_shape_error(f: dict[str, Any], which: str, dh: int, dw: int) -> None:
    """A G-buffer of another size than the frame's (``depth``'s; ``prev_colour`` against ``prev_depth``'s): an
    ``InputShapeError`` (a depth of another size: the G-buffers of the frame's size are named)."""
    h, w = f["h"], f["w"]
    assume((dh, dw) != (0, 0) and h + dh > 0 and w + dw > 0)
    gb = {**_gbuffers(f, f["projection"] @ f["view"]), "motion": np.zeros((h, w, 2), np.float32)}
    shape = {"depth": (h + dh, w + dw), "prev_colour": (h + dh, w + dw, 3), "motion": (h + dh, w + dw, 2)}[which]
    gb[which] = np.full(shape, 0.5, np.float32)
    with pytest.raises(sdk.InputShapeError, match="albedo" if which == "depth" else which):
        sdk.input_planes(ALL, **gb)
    if which != "depth":  # (a depth of another size than the previous frame's: dynamic resolution, taken)
        with pytest.raises(sdk.InputShapeError, match=which):
            sdk.reproject(gb["prev_colour"], f["depth"], f["depth"], f["view"], f["projection"],
                          f["projection"] @ f["view"], motion=gb["motion"])


# -- the engine's motion vectors, dynamic resolution -----------------------------------------------------------


@SETTINGS
@given(frames(sky=False), st.integers(1, 70), st.integers(1, 70), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0))
def test_the_cameras_own_motion_given_as_the_engines_changes_nothing(f: dict[str, Any], ph: int, pw: int, tx: float,
                                                                    ty: float) -> None:
    """A wall facing the camera (one depth), the camera moved sideways and up (the wall's depth unchanged: every
    depth test passes), the previous frame of any size: every pixel whose position is on the previous frame is
    seen, with the texel its position falls in; the camera's own move given as the engine's motion vectors (in
    this frame's pixels) gives the same colour and ``seen``."""
    h, w, proj = f["h"], f["w"], f["projection"]
    depth = np.full((h, w), f["depth"][0, 0], np.float32)
    prev_vp = proj @ _view(f["position"] + f["rotation"] @ np.array([tx, ty, 0.0]), f["rotation"])
    ids = _ids((ph, pw))
    prev_depth = np.full((ph, pw), depth[0, 0], np.float32)
    colour, seen = sdk.reproject(ids, prev_depth, depth, f["view"], proj, prev_vp)
    qx, qy, d = sdk.reproject_positions(depth, f["view"], proj, prev_vp, prev_shape=(ph, pw))
    on = (qx >= 0) & (qx < pw) & (qy >= 0) & (qy < ph)
    # (a position within rounding of the previous frame's edge or of a texel's: either side may be taken)
    firm = (np.abs(qx - np.round(qx)) > 1e-6) & (np.abs(qy - np.round(qy)) > 1e-6)
    np.testing.assert_array_equal((seen == 1.0)[firm], on[firm])
    s = (seen == 1.0) & firm
    rows, cols = _texel(ids, colour[s])
    np.testing.assert_array_equal(rows, ph - 1 - np.floor(qy[s]).astype(int))
    np.testing.assert_array_equal(cols, np.floor(qx[s]).astype(int))
    xs, ys = _centres(h, w)
    motion = np.stack([qx * (w / pw) - xs, ys - qy * (h / ph)], -1)
    moved, seen_moved = sdk.reproject(ids, prev_depth, depth, f["view"], proj, prev_vp, motion=motion)
    np.testing.assert_array_equal(seen_moved[firm], seen[firm])
    np.testing.assert_array_equal(moved[firm], colour[firm])


@SETTINGS
@given(frames(sky=False, max_far_ratio=100.0), st.sampled_from(["window", "reversed"]), st.floats(0.5, 2.0),
       st.floats(0.5, 2.0))
def test_a_previous_depth_buffer_is_linearised_through_the_previous_projection(f: dict[str, Any], kind: str,
                                                                             zoom: float, planes: float) -> None:
    """The previous camera zoomed and with other near and far planes (``prev_projection``), the same pose, over a
    wall facing it: its depth buffer of its own projection, ``depth_kind`` saying so, gives the planes of the
    linear depths (every pixel on the previous frame seen, with the texel its position falls in)."""
    h, w, proj, near, far = f["h"], f["w"], f["projection"], f["near"], f["far"]
    depth = np.full((h, w), f["depth"][0, 0], np.float32)
    if f["kind"] == "perspective":
        prev_proj = _perspective(2.0 * np.arctan(zoom / proj[1, 1]), proj[1, 1] / proj[0, 0], near * planes,
                                 far * planes)
    else:
        prev_proj = _orthographic(zoom / proj[0, 0], zoom / proj[1, 1], near * planes, far * planes)
    assume(near * planes * 1.001 < depth[0, 0] < far * planes * 0.999)  # (inside the previous camera's planes)
    gb = {"depth": depth, "view": f["view"], "projection": proj, "prev_colour": np.repeat(_ids((h, w))[..., None], 3, -1),
          "prev_depth": depth, "prev_view_projection": prev_proj @ f["view"], "prev_projection": prev_proj}
    channels = ["seen", "reprojected.y", "motion.x", "motion.y", "depth"]
    linear = sdk.input_planes(channels, **gb)
    raw, prev_raw = (_window(depth, p) for p in (proj, prev_proj))
    if kind == "reversed":
        raw, prev_raw = 1.0 - raw, 1.0 - prev_raw
    hardware = sdk.input_planes(channels, **{**gb, "depth": raw.astype(np.float32),
                                             "prev_depth": prev_raw.astype(np.float32)}, depth_kind=kind)
    qx, qy, _ = sdk.reproject_positions(depth, f["view"], proj, gb["prev_view_projection"], prev_proj=prev_proj)
    # (a position within rounding of a texel's edge, as a zoom by 2 puts half of them: either side may be taken)
    firm = (np.abs(qx - np.round(qx)) > 1e-4) & (np.abs(qy - np.round(qy)) > 1e-4)
    np.testing.assert_array_equal(hardware[:2][:, firm], linear[:2][:, firm])
    np.testing.assert_allclose(hardware[2:], linear[2:], rtol=1e-3, atol=1e-3 * max(h, w))
