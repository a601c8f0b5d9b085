"""Temporal reprojection with a disocclusion test: the numpy reference.

The moderngl adapter, which the reference renderer also uses, runs the same computation in a shader
(``plugins/moderngl/shaders/adapter_fs.glsl``); this module is the specification and the CPU
fallback for adapters that have the previous frame on the host. numpy only.

Conventions (docs/architecture.md):

* Images are row-major ``(H, W[, C])`` with a top-left origin. Pixel ``(x, y)`` has its centre at
  ``(x + 0.5, y + 0.5)``.
* Matrices are 4x4, column vectors (``p' = M @ p``), OpenGL clip space (NDC x right, y up,
  z in [-1, 1]); view space is right-handed, looking down -Z.
* ``depth`` is linear view depth in scene units (distance along -Z); 0 marks background (sky).
* The scene is static, only the camera moving between the frames, unless the engine's motion vectors are
  given (:func:`reproject`'s ``motion``): they then place each geometry pixel in the previous frame.

Algorithm, per current pixel:

1. Unproject the pixel centre with its depth through the current camera to a world position: the
   point of the pixel's line (a ray from the camera's centre for a perspective camera, parallel to the
   view axis for an orthographic one) at that linear depth. A background pixel of a perspective camera
   becomes a direction at infinity (``w = 0``), so the sky reprojects by camera rotation only; an
   orthographic camera has no point at infinity in view, and its background is the far plane's point.
2. Project it with the previous view-projection. If it lands behind the previous camera (an expected
   previous depth ``<= 0``: a perspective's clip ``w``) or outside ``[0, W') x [0, H')``, the pixel is
   unseen. ``(H', W')`` is the previous frame's size, its render resolution: the current one's, or
   another where the engine's dynamic resolution changed it (the same NDC position, other pixels).
3. Fetch the **nearest** previous texel (no filtering: colours are never blended across an edge,
   and the result is exactly the previous colour under a static camera).
4. Depth test. The expected previous depth is the previous linear depth of the point: a perspective
   camera's clip ``w``; for an orthographic previous camera, its view-space depth through the inverse of
   its projection (``prev_proj``: its near and far planes map the clip z back to the view's).
   A geometry pixel is seen when the nearest previous texel is geometry and the expected depth is
   within ``tolerance * expected`` of either that texel's depth, or the bilinear depth of the 2x2 texel
   footprint around the position (clamped to the frame's edge, as a GL sampler's clamp-to-edge: a footprint
   past it repeats the edge texels), when all four texels are geometry: perspective-correct for a
   perspective previous camera (interpolating 1/depth, which is affine in screen space on a plane), plain
   for an orthographic one (whose depth is affine in screen space on a plane). The second test keeps
   grazing surfaces seen, whose depth changes by more than the tolerance from one pixel to the
   next. A background pixel is seen when the nearest previous texel is background too.
5. Seen pixels take the previous colour, unseen pixels are 0 in colour and in ``seen``.

The shader computes in float32, this reference in float64: their ``seen`` masks agree except where
a position falls within rounding of a texel edge or of the tolerance (rare; tests compare away
from depth edges). The exception: a previous frame at exactly twice or half this frame's size (or
another even ratio) puts every pixel centre on a texel edge, where each side picks a neighbour by
its own rounding: the texel fetched differs between them on about 43% of the pixels (the colour
from one of two adjacent texels; ``seen`` agrees), and neither is "the one above" reliably.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import numpy as np

from ._errors import InputDtypeError, InputShapeError, NonFiniteInputError, ParameterError

__all__ = ["CAMERA_KINDS", "DEFAULT_REPROJECTION_TOLERANCE", "MAX_REPROJECTION_TOLERANCE", "check_projection",
           "check_reprojection", "reproject", "reproject_positions"]

#: Relative depth tolerance of the disocclusion test (2 % of the expected depth).
DEFAULT_REPROJECTION_TOLERANCE = 0.02


#: Largest relative depth tolerance accepted: 1 already accepts any previous depth in [0, 2x] the expected one.
MAX_REPROJECTION_TOLERANCE = 1.0


def _real(x: object, name: str) -> np.ndarray:
    """``x`` as a finite float64 array, or a typed error naming ``name``."""
    try:
        a = np.asarray(x)
    except (TypeError, ValueError, OverflowError) as err:  # ragged nested lists and the like
        raise InputDtypeError(f"{name}: expected an array of numbers, got {type(x).__name__} ({err})") from err
    if a.dtype.kind not in "biuf":
        raise InputDtypeError(f"{name}: expected an array of numbers, got dtype {a.dtype}")
    a = a.astype(np.float64, copy=False)
    if not np.isfinite(a).all():
        raise NonFiniteInputError(f"{name}: holds NaN or infinite values")
    return a


def _matrix(m: np.ndarray, name: str) -> np.ndarray:
    m = _real(m, name)
    if m.shape != (4, 4):
        raise InputShapeError(f"{name} must be a 4x4 matrix, got shape {m.shape}", tuple(m.shape), "(4, 4)")
    return m


#: Where the conversions from other APIs' matrices are written down.
_CONVERSIONS = 'docs/runtime.md "Matrices from Direct3D, Vulkan and Metal"'


def _w_row(v: np.ndarray) -> bool:
    """``v`` is ``(0, 0, a, 0)``, ``a != 0``: a perspective's divide by the view z (zeros relative to ``a``)."""
    return bool(v[2] != 0.0 and max(abs(v[0]), abs(v[1]), abs(v[3])) <= 1e-9 * abs(v[2]))


def _affine_row(v: np.ndarray) -> bool:
    """``v`` is ``(0, 0, 0, a)``, ``a != 0``: no divide by the depth (an orthographic camera's last row)."""
    return bool(v[3] != 0.0 and np.abs(v[:3]).max() <= 1e-9 * abs(v[3]))


def check_projection(projection: Any, name: str = "projection", *, depth_kind: str = "linear",
                     depth: Any = None) -> np.ndarray:
    """``projection`` as a float64 4x4 matrix, if it can be an OpenGL projection as rtp takes it (column
    vectors, right-handed view space looking down -z, clip y up, clip depth in [-1, 1]); else a
    :class:`ParameterError` naming ``name`` that says which other API's convention it looks like and how
    to convert it (docs/runtime.md "Matrices from Direct3D, Vulkan and Metal").

    What a perspective matrix shows of its convention is checked: its ``w`` row (a matrix for row
    vectors has it as its last column: its transpose is wanted), the sign of ``w`` (``+z``: a left-handed
    projection), the sign of its y scale (negative: Vulkan's clip y, pointing down) and its depth row
    (OpenGL's ``m[2][2] / -m[3][2]`` is ``-(f + n) / (f - n)``, at most -1; a reversed-Z projection's is
    at least 0). A Direct3D-style right-handed projection with clip depth in [0, 1] looks like an OpenGL
    one of other near and far planes and passes: only its linearised window depth would be off. Any other
    matrix (an orthographic one, last row ``0, 0, 0, 1``) is taken as it is: :func:`check_reprojection`
    checks what the reprojection needs of an orthographic camera.

    ``depth_kind`` ``"window"`` or ``"reversed"`` (:data:`DEPTH_KINDS`): the projection linearises a hardware depth
    buffer of that kind, which needs OpenGL's convention of an orthographic camera too (a left-handed, reversed-Z or
    row-vector one is refused, as :func:`input_planes` refuses it); ``depth``, that buffer (``(H, W)``), is linearised
    through it too, which refuses points behind an orthographic camera (a near plane behind it). The moderngl
    adapter checks its engine's projection and depth so, with ``sdk.input_planes``' words.
    """
    m = _check_projection(projection, name)
    from ._planes import DEPTH_KINDS, _linear_depth  # (_planes imports this module)

    if not isinstance(depth_kind, str) or depth_kind not in DEPTH_KINDS:
        raise ParameterError(f"depth_kind: expected one of {', '.join(DEPTH_KINDS)}, got {depth_kind!r}", "depth_kind")
    if depth_kind == "linear":
        if depth is not None:
            raise ParameterError("depth: checked through the projection only for a hardware depth buffer "
                                 "(depth_kind 'window' or 'reversed'), got depth_kind 'linear'", "depth")
        return m
    _check_depth_projection(m, name)
    if depth is not None:
        d = np.asarray(depth)
        if d.ndim != 2 or d.dtype.kind not in "biuf":
            raise InputShapeError(f"depth: expected an (H, W) depth buffer of numbers, got {d.dtype} {d.shape}",
                                  d.shape, "(H, W)")
        _linear_depth(d, m, depth_kind == "reversed", name)
    return m


def _check_projection(projection: Any, name: str) -> np.ndarray:
    """:func:`check_projection`'s convention checks."""
    m = _matrix(projection, name)
    if not _w_row(m[3]):
        return m
    if abs(abs(m[3, 2]) - 1.0) > 1e-6 and _w_row(m[:, 3]) and abs(abs(m[2, 3]) - 1.0) <= 1e-6:
        raise ParameterError(f"{name}: its last column (0, 0, {m[2, 3]:g}, 0) is a perspective's w row and its last row "
                             f"(0, 0, {m[3, 2]:g}, 0) the depth's offset: a matrix for row vectors (Direct3D's, "
                             f"DirectXMath's)? rtp takes column vectors: pass its transpose ({_CONVERSIONS})", name)
    if m[3, 2] > 0.0:
        raise ParameterError(f"{name}: w = +z (last row 0, 0, {m[3, 2]:g}, 0): a left-handed projection, the camera "
                             f"looking down +z (Direct3D's convention); rtp's view space is right-handed, looking down "
                             f"-z: projection @ diag(1, 1, -1, 1), and diag(1, 1, -1, 1) @ view ({_CONVERSIONS})", name)
    _y_up(m, name)
    depth_row = m[2, 2] / -m[3, 2]
    if depth_row > -1.0 + 1e-6:
        raise ParameterError(f"{name}: m[2][2] / -m[3][2] = {depth_row:g}, where OpenGL's is -(f + n) / (f - n), at most "
                             f"-1: a reversed-Z projection (or clip depth in [0, 1])? rtp takes the OpenGL projection of "
                             f"the same near and far planes ({_CONVERSIONS}); depth_kind='reversed' says the depth "
                             f"buffer is reversed-Z", name)
    return m


def _y_up(m: np.ndarray, name: str) -> None:
    if m[1, 1] < 0.0:
        raise ParameterError(f"{name}: its y scale m[1][1] = {m[1, 1]:g} is negative: Vulkan's clip space, y pointing "
                             f"down? rtp takes OpenGL's, y up: negate its second row ({_CONVERSIONS})", name)


def _orthographic(m: np.ndarray, name: str) -> None:
    """What the reprojection needs of an orthographic projection ``m`` (last row ``0, 0, 0, a``): clip y up, and
    the view depth rising with the clip depth (OpenGL's ``m[2][2] = -2 / (f - n)``), else a typed error."""
    _y_up(m, name)
    _orthographic_depth(m, name)


def _orthographic_depth(m: np.ndarray, name: str) -> None:
    """An orthographic projection ``m``'s view depth rising with its clip depth (OpenGL's ``m[2][2] = -2 / (f - n)``),
    finite: what reading a depth through it needs (the reprojection's expected depth, a depth buffer linearised),
    else a typed error."""
    with np.errstate(over="ignore", invalid="ignore"):  # (extreme entries: an infinite or NaN product, judged below)
        dz = _inverse(m, name)[2, 2] * m[3, 3]  # d(view z) / d(NDC z) along the pixel's line: negative in OpenGL's
    if not np.isfinite(dz):
        raise ParameterError(f"{name}: an orthographic projection whose depth scale is out of range (m[2][2] = "
                             f"{m[2, 2]:g}, m[3][3] = {m[3, 3]:g}: the view depth of a clip depth overflows)", name)
    if not dz < 0.0:
        raise ParameterError(f"{name}: an orthographic projection whose clip depth does not rise away from the camera "
                             f"(m[2][2] = {m[2, 2]:g}, OpenGL's is -2 / (f - n)): a left-handed or reversed-Z one? rtp "
                             f"takes the OpenGL projection of the same near and far planes ({_CONVERSIONS})", name)


def _check_depth_projection(m: np.ndarray, name: str) -> None:
    """What linearising a hardware depth buffer (``depth_kind`` ``window`` or ``reversed``) needs of the projection
    ``m`` (a float64 4x4, through :func:`check_projection`): a perspective's (checked there), or an orthographic
    camera's whose clip depth rises away from the camera, as OpenGL's; else a typed error. Through a left-handed or
    reversed-Z orthographic projection, or one for row vectors, the depth came out wrong or negative without one."""
    if _w_row(m[3]):
        return
    if _affine_row(m[3]):
        _orthographic_depth(m, name)
        return
    transposed = (" (its last column is (0, 0, 0, 1) and its last row holds the translation: a matrix for row "
                  "vectors? rtp takes column vectors: pass its transpose)" if _affine_row(m[:, 3]) else "")
    raise ParameterError(f"{name}: its last row {np.round(m[3], 4).tolist()} is neither a perspective's (0, 0, -1, 0) "
                         f"nor an orthographic camera's (0, 0, 0, 1), the two a depth buffer is linearised through"
                         f"{transposed} ({_CONVERSIONS})", name)


def _cameras(projection: np.ndarray, prev_view_projection: np.ndarray, prev_projection: np.ndarray | None,
             names: tuple[str, str, str]) -> np.ndarray | None:
    """:func:`check_reprojection` of float64 4x4 matrices (``projection`` already through :func:`check_projection`),
    its three arguments named ``names``: the projection whose inverse gives an orthographic previous camera's
    depth (``prev_projection``, else ``projection``), or None where the previous camera is a perspective."""
    if not _w_row(projection[3]):
        if not _affine_row(projection[3]):
            raise ParameterError(f"{names[0]}: its last row {np.round(projection[3], 4).tolist()} is neither a "
                                 f"perspective's (0, 0, -1, 0) nor an orthographic camera's (0, 0, 0, 1), the two "
                                 f"cameras the reprojection (reprojected.*, seen, motion.x/y) follows pixels through",
                                 names[0])
        _orthographic(projection, names[0])
    else:  # (every pixel's line comes through its inverse: a singular one, named as its caller names it)
        _inverse(projection, names[0])
    w = prev_view_projection[3]
    if np.abs(w[:3]).max() > 1e-9 * abs(w[3]):  # its clip w reads the view's depth: a perspective's
        return None
    if not w[3] > 0.0:  # (a zero last row, a matrix not set: every point "behind" it, every pixel unseen, silently)
        raise ParameterError(f"{names[1]}: its last row {np.round(w, 4).tolist()} is neither a perspective camera's "
                             f"(its viewing axis) nor an orthographic camera's (0, 0, 0, 1): no camera the reprojection "
                             f"follows pixels into (a matrix not set? a first frame has no previous frame to reproject)",
                             names[1])
    # An orthographic previous camera: its clip w is 1 everywhere, and its depth the clip z through its projection.
    depth = prev_projection if prev_projection is not None else projection
    named = names[2] if prev_projection is not None else names[0]
    if not _affine_row(depth[3]):
        raise ParameterError(f"{named}: {names[1]} is an orthographic camera's (its last row "
                             f"{np.round(w, 4).tolist()}), whose expected depth comes from its projection's depth row, "
                             f"and {named} is not orthographic: pass the previous camera's projection as {names[2]} (a "
                             f"switch of cameras: no previous frame reprojects across a cut)", named)
    _orthographic(depth, named)
    return depth


#: The kinds of camera the reprojection follows pixels through (:func:`check_reprojection`).
CAMERA_KINDS = ("perspective", "orthographic")


def check_reprojection(projection: Any, prev_view_projection: Any, prev_projection: Any = None) -> tuple[str, str]:
    """Whether the reprojection (:func:`reproject`; the ``reprojected.*``, ``seen`` and ``motion.x/y`` planes)
    can follow pixels from the camera of ``projection`` into the previous one of ``prev_view_projection``:
    the two cameras' kinds (each one of :data:`CAMERA_KINDS`, the current camera's first), or a
    :class:`ParameterError` naming the matrix where it cannot.

    Each camera is a perspective (last row ``0, 0, -1, 0``, checked as by :func:`check_projection`; for the
    previous one, ``prev_view_projection``'s last row its viewing axis) or an orthographic one (``0, 0, 0, 1``:
    clip y up and OpenGL's depth row, ``-2 / (f - n)``, checked); ``projection`` has an inverse. A
    perspective's previous depth is its clip ``w``; an orthographic previous camera's is read through the
    inverse of its projection, ``prev_projection``, or ``projection`` where that is None (the same near and far
    planes: a camera that pans, turns or zooms), which must then be orthographic too.
    """
    proj = check_projection(_matrix(projection, "projection"), "projection")
    prev = _matrix(prev_view_projection, "prev_view_projection")
    prev_proj = None if prev_projection is None else check_projection(prev_projection, "prev_projection")
    previous = _cameras(proj, prev, prev_proj, ("projection", "prev_view_projection", "prev_projection"))
    return CAMERA_KINDS[not _w_row(proj[3])], CAMERA_KINDS[previous is not None]


def _inverse(m: np.ndarray, name: str) -> np.ndarray:
    try:
        inv = np.linalg.inv(m)
    except np.linalg.LinAlgError as err:
        raise ParameterError(f"{name} is singular (not invertible): {err}", name) from err
    if not np.isfinite(inv).all():
        raise ParameterError(f"{name} is too close to singular to invert", name)
    return inv


def _tolerance(tolerance: object) -> float:
    """The disocclusion test's relative depth tolerance, checked: a number in [0, MAX_REPROJECTION_TOLERANCE]."""
    if isinstance(tolerance, (bool, np.bool_)) or not isinstance(tolerance, (int, float, np.integer, np.floating)) \
            or not 0.0 <= tolerance <= MAX_REPROJECTION_TOLERANCE:
        raise ParameterError(f"tolerance: expected a number in [0, {MAX_REPROJECTION_TOLERANCE:g}] (relative depth "
                             f"tolerance, {DEFAULT_REPROJECTION_TOLERANCE} by default), got {tolerance!r}", "tolerance")
    return float(tolerance)


def _depth(d: object, name: str) -> np.ndarray:
    a = _real(d, name)
    if a.ndim != 2 or a.size == 0:
        raise InputShapeError(f"{name} must be a non-empty (H, W) array, got shape {a.shape}", tuple(a.shape), "(H, W)")
    if (a < 0).any():
        raise ParameterError(f"{name}: linear view depth must be >= 0 (0 marks background)", name)
    return a


def reproject_positions(
    depth: np.ndarray,
    cur_view: np.ndarray,
    cur_proj: np.ndarray,
    prev_view_proj: np.ndarray,
    *,
    prev_proj: np.ndarray | None = None,
    prev_shape: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where every current pixel was in the previous frame.

    Args:
        depth: ``(H, W)`` current linear depth, 0 on background.
        cur_view: current world-to-view matrix.
        cur_proj: current view-to-clip (OpenGL) matrix, perspective or orthographic.
        prev_view_proj: previous world-to-clip matrix.
        prev_proj: the previous view-to-clip matrix, read only where the previous camera is orthographic
            (its depth comes from its clip z through this); ``cur_proj`` where None.
        prev_shape: the previous frame's ``(H', W')`` where its render resolution differs (dynamic
            resolution); ``depth``'s where None.

    Returns:
        ``(qx, qy, d)``, each ``(H, W)`` float64: the previous position in OpenGL window
        coordinates of the previous frame (its pixels, origin at the BOTTOM-left corner of the frame, as
        the shader sees it; the top-left y is ``H' - qy``, and the texel :func:`reproject` fetches, in
        top-left rows and columns, ``(H' - 1 - floor(qy), floor(qx))``: on a texel's edge the one above, up to rounding)
        and the expected previous linear depth (a perspective previous camera's clip ``w``); ``d <= 0``
        where the point was behind the previous camera (only its sign matters for background).
    """
    cameras = _checked(cur_view, cur_proj, prev_view_proj, prev_proj)
    return _positions(_depth(depth, "depth"), *cameras, None if prev_shape is None else _shape(prev_shape))


def _shape(shape: object) -> tuple[int, int]:
    """A frame's ``(H, W)``, two positive integers below 2**31 (past any GPU's textures; pixel indices stay
    in int32 and int64 arithmetic), or a typed error."""
    ok = (isinstance(shape, (tuple, list)) and len(shape) == 2
          and all(isinstance(n, (int, np.integer)) and not isinstance(n, (bool, np.bool_)) and 0 < n < 2**31
                  for n in shape))
    if not ok:
        raise ParameterError(f"prev_shape: expected the previous frame's (H, W), two positive integers below 2**31, "
                             f"got {shape!r}", "prev_shape")
    return int(shape[0]), int(shape[1])  # type: ignore[index]


def _checked(cur_view: Any, cur_proj: Any, prev_view_proj: Any, prev_proj: Any,
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """:func:`reproject`'s matrices checked (:func:`check_reprojection`), with the previous depth's projection
    (None: a perspective previous camera)."""
    proj = check_projection(cur_proj, "cur_proj")
    prev_vp = _matrix(prev_view_proj, "prev_view_proj")
    prev_p = None if prev_proj is None else check_projection(prev_proj, "prev_proj")
    return (_matrix(cur_view, "cur_view"), proj, prev_vp,
            _cameras(proj, prev_vp, prev_p, ("cur_proj", "prev_view_proj", "prev_proj")))


#: Pixels a band of rows holds at most: the reprojection runs band by band, so that its float64 temporaries (a
#: few dozen of them) stay in the cache instead of streaming a whole frame through memory each, and the bands run
#: on :data:`_BAND_THREADS` threads (numpy lets go of the GIL inside its loops). Every pixel's arithmetic is its
#: own, so the values are those of one pass over the frame.
_BAND_PIXELS = 65536

#: Threads the reprojection's bands run on at most (the CPU's cores, up to 4: past that the gathers from the
#: previous frame are bound by memory).
_BAND_THREADS = max(1, min(4, os.cpu_count() or 1))

_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _forget_pool() -> None:
    """In a forked child: the parent's pool (its object, not its threads) and lock forgotten. A lock that a thread of
    the parent held at the fork (building the pool) is held for ever in the child, where that thread does not run."""
    global _pool, _pool_lock
    _pool = None
    _pool_lock = threading.Lock()


os.register_at_fork(after_in_child=_forget_pool)


def _band_rows(h: int, w: int) -> int:
    """Rows a band of an ``(h, w)`` frame holds (:data:`_BAND_PIXELS` at most, one row at least)."""
    return max(1, _BAND_PIXELS // max(w, 1))


def _in_bands(h: int, w: int, band: Callable[[int, int], None]) -> None:
    """``band(r0, r1)`` for each band of rows of an ``(h, w)`` frame, on up to :data:`_BAND_THREADS` threads
    (in this thread where there is one band or one thread); an exception of a band is raised here."""
    global _pool
    step = _band_rows(h, w)
    starts = range(0, h, step)
    if len(starts) == 1 or _BAND_THREADS == 1:
        for r0 in starts:
            band(r0, min(h, r0 + step))
        return
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(_BAND_THREADS, thread_name_prefix="rtp-reproject")
        pool = _pool
    for future in [pool.submit(band, r0, min(h, r0 + step)) for r0 in starts]:
        future.result()


def _affine(a0: float, xs: np.ndarray, a1: float, ys: np.ndarray, c: float) -> Any:
    """``a0 * xs + a1 * ys + c``, leaving out a term whose coefficient is 0: a row ``(1, W)`` or a column ``(H, 1)``
    where the other is 0 (a perspective or orthographic projection, off-centre or jittered: each of the inverse
    projection's first two rows reads one of x and y, its last two neither), else the full ``(H, W)``."""
    out: Any = np.float64(c)
    for a, v in ((a0, xs), (a1, ys)):
        if a != 0.0:
            out = a * v + out
    return out


def _positions(depth: np.ndarray, cur_view: np.ndarray, cur_proj: np.ndarray, prev_vp: np.ndarray,
               prev_depth_proj: np.ndarray | None = None, prev_shape: tuple[int, int] | None = None,
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`reproject_positions` of arrays already checked (finite, ``depth`` (H, W) >= 0, 4x4 matrices through
    :func:`_cameras`, whose result ``prev_depth_proj`` is), float32 or float64 alike (each float32 value is a
    float64 exactly, and the arithmetic is float64)."""
    h, w = depth.shape
    cams = _transforms(cur_view, cur_proj, prev_vp, prev_depth_proj, prev_shape or (h, w))
    qx, qy, cw = np.empty((h, w)), np.empty((h, w)), np.empty((h, w))

    def band(r0: int, r1: int) -> None:
        qx[r0:r1], qy[r0:r1], cw[r0:r1] = _band_positions(depth[r0:r1], r0, h, w, cams)

    _in_bands(h, w, band)
    return qx, qy, cw


class _Transforms(NamedTuple):
    inv_proj: np.ndarray  # the current projection's inverse
    m: np.ndarray  # the current view space to the previous clip space
    orthographic: bool  # the current camera's kind: pixels on parallel lines, not rays from a centre
    depth_rows: np.ndarray | None  # an orthographic previous camera: (numerator, denominator) of its depth
    prev_shape: tuple[int, int]  # the previous frame's (H, W): its render resolution, the positions' pixels


def _transforms(cur_view: np.ndarray, cur_proj: np.ndarray, prev_vp: np.ndarray,
                prev_depth_proj: np.ndarray | None, prev_shape: tuple[int, int]) -> _Transforms:
    """The current projection's inverse, the matrix from the current view space to the previous clip space and,
    for an orthographic previous camera (``prev_depth_proj`` its projection), the two rows over current view
    points whose quotient is the previous view depth (the previous view point's ``-z`` over its ``w``)."""
    inv_proj = _inverse(cur_proj, "cur_proj")
    m = prev_vp @ _inverse(cur_view, "cur_view")
    rows = None
    if prev_depth_proj is not None:
        inv_prev = _inverse(prev_depth_proj, "prev_proj")
        rows = np.stack([-(inv_prev[2] @ m), inv_prev[3] @ m])
    return _Transforms(inv_proj, m, not _w_row(cur_proj[3]), rows, prev_shape)


def _band_positions(depth: np.ndarray, r0: int, h: int, w: int, cams: _Transforms,
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_positions` of the rows ``r0 : r0 + len(depth)`` of an ``(h, w)`` frame (``depth``: those rows)."""
    inv_proj = cams.inv_proj
    xs = ((np.arange(w, dtype=np.float64) + 0.5) / w * 2.0 - 1.0)[None, :]
    ys = (1.0 - (np.arange(r0, r0 + depth.shape[0], dtype=np.float64) + 0.5) / h * 2.0)[:, None]  # top-left rows
    geometry = depth > 0.0
    dot = (_orthographic_points if cams.orthographic else _perspective_points)(depth, geometry, xs, ys, inv_proj)
    m = cams.m
    cx, cy, cw = dot(m[0]), dot(m[1]), dot(m[3])
    safe = np.where(cw > 0.0, cw, 1.0)
    ph, pw = cams.prev_shape  # (the previous frame's pixels: its render resolution may differ)
    qx = (cx / safe * 0.5 + 0.5) * pw
    qy = (cy / safe * 0.5 + 0.5) * ph
    if cams.depth_rows is None:
        return qx, qy, cw  # a perspective's clip w is the previous linear depth
    num, den = dot(cams.depth_rows[0]), dot(cams.depth_rows[1])
    ahead = den > 0.0  # (0 for the sky's directions, which an orthographic camera does not see)
    return qx, qy, np.where(ahead, num / np.where(ahead, den, 1.0), 0.0)


def _perspective_points(depth: np.ndarray, geometry: np.ndarray, xs: np.ndarray, ys: np.ndarray,
                        inv_proj: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """``row -> row . p`` over the band's view-space points ``p`` of a perspective camera: the pixel's ray at its
    depth (``w = 1``), or the ray's unit direction at infinity on background (``w = 0``)."""
    # The pixel centre's NDC (x, y) on the near plane (z = -1) through the inverse projection: affine in x
    # and y, so each component is a sum of a column and a row (a row or a column alone for the usual projections).
    q = [_affine(inv_proj[i, 0], xs, inv_proj[i, 1], ys, inv_proj[i, 3] - inv_proj[i, 2]) for i in range(4)]
    # the view-space point on the ray with z = -1: (q / q_w) / -(q_z / q_w)
    rx, ry = (q[0] / q[3]) / -(q[2] / q[3]), (q[1] / q[3]) / -(q[2] / q[3])
    # geometry: the point (rx, ry, -1) * depth, w = 1; background: the ray's unit direction at infinity (w = 0).
    # A row's product is then scale * (r[0] rx + r[1] ry - r[2]), plus r[3] on geometry.
    # (a C-ordered copy always: the sky's scales are written through its ravel, which for a depth in Fortran
    # order, or a band of rows of one, is a copy: the writes were lost and every sky pixel came back unseen)
    scale = np.array(depth, np.float64, order="C")
    sky = np.flatnonzero(~geometry)
    if sky.size:  # (the unit length only where it is used: most frames are mostly geometry)
        at = np.divmod(sky, depth.shape[1])
        sx, sy = np.broadcast_to(rx, depth.shape)[at], np.broadcast_to(ry, depth.shape)[at]
        scale.ravel()[sky] = 1.0 / np.sqrt(sx * sx + sy * sy + 1.0)

    def dot(r: np.ndarray) -> np.ndarray:
        c = scale * (r[0] * rx + r[1] * ry - r[2])
        if r[3] != 0.0:
            np.add(c, r[3], out=c, where=geometry)
        return c

    return dot


def _orthographic_points(depth: np.ndarray, geometry: np.ndarray, xs: np.ndarray, ys: np.ndarray,
                         inv_proj: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """``row -> row . p`` over the band's view-space points ``p`` (``w = 1``) of an orthographic camera: the point
    of the pixel's line (parallel to the view axis, or sheared) at its depth, the far plane's on background."""
    ip = inv_proj / inv_proj[3, 3]  # (its last row 0, 0, 0, 1: view points without a divide)
    # The view point at NDC (x, y, z) is c + ip[:3, 2] z, c the one at z = 0 (affine in x and y); its depth -vz
    # is the pixel's where z = (-depth - c_z) / ip[2][2], and the far plane's at z = 1.
    c = [_affine(ip[i, 0], xs, ip[i, 1], ys, ip[i, 3]) for i in range(3)]
    z = np.where(geometry, (-depth - c[2]) / ip[2, 2], 1.0)
    vx, vy = (c[i] + ip[i, 2] * z if ip[i, 2] != 0.0 else c[i] for i in (0, 1))
    vz = np.where(geometry, -depth.astype(np.float64), c[2] + ip[2, 2])

    def dot(r: np.ndarray) -> np.ndarray:
        out = np.full(depth.shape, r[3])
        for a, v in ((r[0], vx), (r[1], vy), (r[2], vz)):
            if a != 0.0:
                out += a * v
        return out

    return dot


def reproject(
    prev_colour: np.ndarray,
    prev_depth: np.ndarray,
    depth: np.ndarray,
    cur_view: np.ndarray,
    cur_proj: np.ndarray,
    prev_view_proj: np.ndarray,
    *,
    tolerance: float = DEFAULT_REPROJECTION_TOLERANCE,
    motion: np.ndarray | None = None,
    prev_proj: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Fetch the previous frame's colour where each current pixel was, with a disocclusion test.

    Args:
        prev_colour: ``(H', W', C)`` (or ``(H', W')``) previous final colour, display-encoded, top-left.
        prev_depth: ``(H', W')`` previous linear depth (0 = background). ``(H', W')`` is the previous
            frame's render resolution: ``(H, W)``, or another where the engine's dynamic resolution changed it.
        depth: ``(H, W)`` current linear depth (0 = background).
        cur_view: current 4x4 world-to-view matrix (``Camera.view()``).
        cur_proj: current 4x4 OpenGL projection (``Camera.projection(W / H)``), perspective or orthographic
            (:func:`check_reprojection`).
        prev_view_proj: previous 4x4 world-to-clip matrix (``prev_camera.view_projection(W, H)``).
        tolerance: relative depth tolerance (default 0.02, i.e. 2 % of the expected depth).
        motion: the engine's motion vectors, ``(H, W, 2)``: each pixel's previous minus current position
            in this frame's pixels (x right, y down; a UV motion times ``(W, H)``), objects' own motion
            included. Where given, a geometry pixel is
            fetched from there instead of from where the camera's move alone puts it (the matrices: a
            static scene), and its depth is tested against the depth the camera's move gives it (an
            object moving in depth by more than ``tolerance`` in a frame is unseen); background pixels
            follow the camera.
        prev_proj: the previous 4x4 projection, read only where the previous camera is orthographic (its
            clip z to its linear depth); ``cur_proj`` where None (the same near and far planes).

    Returns:
        ``(reprojected, seen)``: ``reprojected`` is ``(H, W[, C])`` (``depth``'s size, ``prev_colour``'s
        channels), float32, 0 where unseen; ``seen`` is ``(H, W)`` float32 in {0, 1}. See the module
        docstring for the rules.
    """
    tolerance = _tolerance(tolerance)
    depth = _depth(depth, "depth")
    prev_depth = _depth(prev_depth, "prev_depth")  # (its own size: the previous frame's render resolution)
    colour = _real(prev_colour, "prev_colour")
    if colour.ndim not in (2, 3) or colour.shape[:2] != prev_depth.shape:
        raise InputShapeError(f"prev_colour must be (H', W'[, C]) with (H', W') = {prev_depth.shape}, prev_depth's "
                              f"(the previous frame's render resolution); got {colour.shape}", tuple(colour.shape),
                              f"({prev_depth.shape[0]}, {prev_depth.shape[1]}[, C])")
    if motion is not None:
        motion = _real(motion, "motion")
        if motion.shape != (*depth.shape, 2):
            raise InputShapeError(f"motion must be (H, W, 2) with (H, W) = {depth.shape} (pixels, previous minus "
                                  f"current position, x right, y down); got {motion.shape}", tuple(motion.shape),
                                  f"({depth.shape[0]}, {depth.shape[1]}, 2)")
    cameras = _checked(cur_view, cur_proj, prev_view_proj, prev_proj)
    return _reproject(np.asarray(prev_colour), prev_depth, depth, *cameras, tolerance, motion)


def _reproject(prev_colour: np.ndarray, prev_depth: np.ndarray, depth: np.ndarray, cur_view: np.ndarray,
               cur_proj: np.ndarray, prev_vp: np.ndarray, prev_depth_proj: np.ndarray | None, tolerance: float,
               motion: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`reproject` of arrays already checked (``input_planes`` checks its G-buffers once, not twice; the
    matrices through :func:`_cameras`, whose result ``prev_depth_proj`` is)."""
    h, w = depth.shape
    cams = _transforms(cur_view, cur_proj, prev_vp, prev_depth_proj, prev_depth.shape)
    colours = prev_colour.reshape(prev_depth.size, -1)
    out = np.empty((h * w, colours.shape[1]), np.float32)
    seen = np.empty((h, w), np.float32)
    flat_depth = prev_depth.ravel()

    def band(r0: int, r1: int) -> None:
        seen[r0:r1] = _band_reproject(colours, flat_depth, depth[r0:r1], r0, h, w, cams, tolerance,
                                      None if motion is None else motion[r0:r1], out[r0 * w:r1 * w])

    _in_bands(h, w, band)
    return out.reshape(depth.shape + prev_colour.shape[2:]), seen


def _band_reproject(colours: np.ndarray, flat_depth: np.ndarray, depth: np.ndarray, r0: int, h: int, w: int,
                    cams: _Transforms, tolerance: float, motion: np.ndarray | None, out: np.ndarray) -> np.ndarray:
    """:func:`_reproject` of the rows ``r0 : r0 + len(depth)``: their colours into ``out`` (``(rows * w, C)``), and
    their ``seen`` (bool). ``colours`` and ``flat_depth`` are the whole previous frame's, raveled."""
    qx, qy, cw = _band_positions(depth, r0, h, w, cams)
    geometry = depth > 0.0
    ph, pw = cams.prev_shape
    if motion is not None:  # the engine's motion vectors place geometry; the expected depth stays the camera's
        # (in this frame's pixels, as its UV times its size: the previous frame's are pw / w of them)
        qx = np.where(geometry, ((np.arange(w, dtype=np.float64) + 0.5)[None, :] + motion[..., 0]) * (pw / w), qx)
        qy = np.where(geometry, ((h - (np.arange(r0, r0 + depth.shape[0], dtype=np.float64) + 0.5))[:, None]
                                 - motion[..., 1]) * (ph / h), qy)
    on = (cw > 0.0) & (qx >= 0.0) & (qx < pw) & (qy >= 0.0) & (qy < ph)
    qx = np.where(on, qx, 0.5)
    qy = np.where(on, qy, 0.5)

    def rows(gl_y: np.ndarray) -> np.ndarray:  # GL row index -> top-left row index
        return ph - 1 - gl_y

    # gathers through flat indices into the raveled frames (2-3x faster than 2-D fancy indexing)
    ix = np.floor(qx).astype(np.intp)
    iy = np.floor(qy).astype(np.intp)
    nearest = rows(iy) * pw + ix
    pd = flat_depth.take(nearest)
    exp_d = cw
    near_ok = (pd > 0.0) & (np.abs(pd - exp_d) <= tolerance * exp_d)

    # The bilinear test only where the nearest texel's failed (a grazing surface): the same mask as testing
    # every pixel, without four gathers and a division a pixel for the most, which pass the first test.
    bil_ok = np.zeros(depth.shape, dtype=bool)
    grazing = np.flatnonzero(on & geometry & (pd > 0.0) & ~near_ok)
    if grazing.size:
        fx, fy = qx.ravel()[grazing] - 0.5, qy.ravel()[grazing] - 0.5
        ox, oy = np.floor(fx).astype(np.intp), np.floor(fy).astype(np.intp)
        tx, ty = fx - ox, fy - oy
        x0, x1 = np.clip(ox, 0, pw - 1), np.clip(ox + 1, 0, pw - 1)
        y0, y1 = rows(np.clip(oy, 0, ph - 1)) * pw, rows(np.clip(oy + 1, 0, ph - 1)) * pw
        d00, d10 = flat_depth.take(y0 + x0), flat_depth.take(y0 + x1)
        d01, d11 = flat_depth.take(y1 + x0), flat_depth.take(y1 + x1)
        full = np.minimum(np.minimum(d00, d10), np.minimum(d01, d11)) > 0.0
        if cams.depth_rows is not None:  # an orthographic previous camera: depth is affine on a plane
            bil = ((1 - tx) * d00 + tx * d10) * (1 - ty) + ((1 - tx) * d01 + tx * d11) * ty
        else:  # a perspective's: 1 / depth is
            with np.errstate(divide="ignore", invalid="ignore"):
                bil = 1.0 / (((1 - tx) / d00 + tx / d10) * (1 - ty) + ((1 - tx) / d01 + tx / d11) * ty)
        expected = exp_d.ravel()[grazing]
        bil_ok.ravel()[grazing] = full & (np.abs(bil - expected) <= tolerance * expected)

    seen = on & np.where(geometry, (pd > 0.0) & (near_ok | bil_ok), pd <= 0.0)
    out[...] = colours.take(nearest.ravel(), axis=0)
    out[~seen.ravel()] = 0.0
    return seen
