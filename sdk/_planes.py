"""``input_planes``: a model's input planes from G-buffers held in numpy arrays, in one call.

What a CPU adapter does (the pyrender adapter calls it; docs/adapters.md's skeleton is this call): each
channel of :data:`CHANNELS` from the G-buffer it is made of, by the same functions the reference
renderer's GPU adapter mirrors (``reproject``, ``luma``, ``pixel_differences``, ``block_variances``,
``tile_variances``, ``depth_edges``). An engine that reads its G-buffers back to the host needs no
adapter code of its own. numpy only.
"""

from __future__ import annotations

import logging
import reprlib
import threading
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from ._channels import CHANNELS, block_variances, depth_edges, pixel_differences, tile_variances
from ._color import linear_to_srgb, luma
from ._errors import InputDtypeError, InputShapeError, NonFiniteInputError, ParameterError, RtpError
from ._reproject import (
    _CONVERSIONS,
    DEFAULT_REPROJECTION_TOLERANCE,
    _affine_row,
    _cameras,
    _check_depth_projection,
    _inverse,
    _positions,
    _reproject,
    _tolerance,
    _w_row,
    check_projection,
)

log = logging.getLogger(__name__)

__all__ = ["DEPTH_KINDS", "GBUFFERS", "NORMAL_SPACES", "check_gbuffers", "gbuffers_needed", "input_planes"]

#: What ``depth`` (and ``prev_depth``) hold: ``linear`` view depth in scene units (0 = background); the
#: ``window`` depth of a hardware depth buffer in [0, 1] (0 at the near plane, 1 on background), OpenGL's and
#: Direct3D's alike; or a ``reversed``-Z depth buffer (1 at the near plane, 0 on background and at the far
#: plane, finite or infinite: the depth of most current D3D12, Vulkan and Metal engines). Both hardware kinds
#: are linearised with the OpenGL ``projection`` of the same near and far planes, as the moderngl adapter's
#: ``depth_kind``.
DEPTH_KINDS = ("linear", "window", "reversed")
#: The space ``normal`` is in: ``view``, or ``world`` (rotated into view space with ``view``).
NORMAL_SPACES = ("view", "world")

#: The G-buffers :func:`input_planes` takes, each with its shape and what it holds (the conventions of
#: docs/metadata.md "Input channels"): ``(H, W)`` or ``(H, W, 3)``, and the range its values must lie in.
GBUFFERS: Mapping[str, tuple[str, str]] = {
    "depth": ("(H, W)", "linear view depth in scene units, >= 0; 0 on background"),
    "albedo": ("(H, W, 3)", "base colour, display-encoded sRGB in [0, 1]; 0 on background"),
    "normal": ("(H, W, 3)", "view-space unit normal in [-1, 1] (right-handed, the camera looks down -z); 0 on background"),
    "roughness": ("(H, W)", "GGX perceptual roughness in [0, 1]"),
    "metallic": ("(H, W)", "metalness in [0, 1]"),
    "specular": ("(H, W)", "dielectric specular scale in [0, 1] (0.5 = F0 of 4%)"),
    "shadow": ("(H, W)", "main-light shadow visibility in [0, 1], 1 = lit"),
    "emissive": ("(H, W)", "emissive luminance, display-encoded, in [0, 1]"),
    "view": ("4x4", "this frame's world-to-view matrix (column vectors)"),
    "projection": ("4x4", "this frame's view-to-clip matrix (OpenGL clip space)"),
    "prev_colour": ("(H', W', 3)", "the previous displayed frame, display-encoded (tone-mapped sRGB) in [0, 1], at "
                                   "prev_depth's size"),
    "prev_depth": ("(H', W')", "the previous frame's linear view depth, >= 0; 0 on background; at the previous "
                               "frame's render resolution (H, W, or another where dynamic resolution changed it)"),
    "prev_view_projection": ("4x4", "the previous frame's world-to-clip matrix"),
    "prev_projection": ("4x4", "the previous frame's view-to-clip matrix, where it differs from projection: it "
                               "linearises a window prev_depth, and gives an orthographic previous camera's depth"),
    "motion": ("(H, W, 2)", "the engine's motion vectors, optional: each pixel's previous minus current position in "
                            "pixels (x right, y down), objects' own motion included; without them the camera's move "
                            "alone places each pixel (a static scene)"),
}

_REPROJECTION = ("depth", "view", "projection", "prev_colour", "prev_depth", "prev_view_projection")
_MOTION = ("depth", "view", "projection", "prev_view_projection")
_RANGES = {"albedo": (0.0, 1.0), "normal": (-1.0, 1.0), "roughness": (0.0, 1.0), "metallic": (0.0, 1.0),
           "specular": (0.0, 1.0), "shadow": (0.0, 1.0), "emissive": (0.0, 1.0), "prev_colour": (0.0, 1.0)}
#: How far past its range a G-buffer's value may lie (float rounding of a renderer's output, an 8-bit normal's
#: encoding) before it is refused.
RANGE_SLACK = 1e-3


def _needs(channel: str) -> tuple[str, ...]:
    if channel.startswith("reprojected.") or channel == "seen":
        return _REPROJECTION
    if channel.startswith("motion."):
        return _MOTION
    if channel.startswith("albedo."):
        return ("albedo",)
    if channel.startswith("normal."):
        return ("normal",)
    if channel.startswith("depth"):
        return ("depth",)
    return (channel,)


def _channels(channels: Iterable[str]) -> tuple[str, ...]:
    if isinstance(channels, str) or not isinstance(channels, Iterable):
        raise ParameterError(f"channels: expected a sequence of channel names (a model's metadata.inputs), got "
                             f"{reprlib.repr(channels)}", "channels")
    names = tuple(channels)
    for c in names:
        if not isinstance(c, str) or c not in CHANNELS:
            import difflib

            close = difflib.get_close_matches(str(c), list(CHANNELS), n=1)
            raise ParameterError(f"channels: unknown channel {reprlib.repr(c)}"
                                 f"{f' (did you mean {close[0]}?)' if close else ''}; channels are sdk.CHANNELS: "
                                 f"{', '.join(CHANNELS)}", "channels")
    if not names:
        raise ParameterError("channels: expected at least one channel name", "channels")
    return names


def _reprojects(channels: Iterable[str]) -> bool:
    """Whether a plane of ``channels`` follows the pixels into the previous frame (which takes a perspective)."""
    return any(c.startswith(("reprojected.", "motion.")) or c == "seen" for c in channels)


def gbuffers_needed(channels: Iterable[str]) -> tuple[str, ...]:
    """The G-buffers (:data:`GBUFFERS` names) :func:`input_planes` needs for ``channels``, in
    :data:`GBUFFERS` order: what an engine must read back for a model (``metadata.inputs``)."""
    names = _channels(channels)
    wanted = {b for c in names for b in _needs(c)} | {"depth"}
    return tuple(b for b in GBUFFERS if b in wanted)


def _resolution_hint(name: str, shape: tuple[int, ...], size: tuple[int, int]) -> str:
    """Where a G-buffer is the frame scaled by one factor (the depth's size times it): its likely cause."""
    if min(*shape[:2], *size) <= 0:
        return ""
    sy, sx = shape[0] / size[0], shape[1] / size[1]
    if abs(sy / sx - 1.0) > 0.02 or abs(sy - 1.0) < 0.05:
        return ""
    if name == "prev_colour" and sy > 1.0:
        return (f" (the frame at {sy:.3g}x prev_depth's size: the displayed frame of an upscaler (DLSS, FSR, XeSS)? "
                f"the previous frame is taken at its render resolution, its depth's: downsample it)")
    return f" (at {sy:.3g}x depth's size: every G-buffer at the render resolution, the depth's)"


def _buffer(name: str, value: Any, size: tuple[int, int] | None, window: float = np.inf) -> np.ndarray:
    """A G-buffer as a float array of its shape, finite and within its range; else a typed error naming it."""
    shape, meaning = GBUFFERS[name]
    if name.endswith("depth") and window == 1.0:  # depth_kind "window" or "reversed": not linear depth
        meaning = ("a hardware depth buffer's values as depth_kind 'window' or 'reversed' reads them; "
                   "depth_kind='linear' for linear view depth in scene units")
    try:
        a = np.asarray(value)
    except (TypeError, ValueError, OverflowError) as err:
        raise InputDtypeError(f"{name}: expected an array of numbers, {shape} {meaning}; got "
                              f"{type(value).__name__} ({err})") from err
    if a.dtype.kind not in "biuf":
        raise InputDtypeError(f"{name}: expected an array of numbers, {shape} {meaning}; got dtype {a.dtype}")
    planes = 3 if shape.endswith(", 3)") else 2 if shape.endswith(", 2)") else 0  # an image's channels (0: none)
    if a.ndim == 3 and shape != "4x4" and (planes < a.shape[2] <= 4 if planes else a.shape[2] == 1):
        # an RGBA texture read back (RGBA8, RGBA16F: the alpha is not read; an RG motion texture read back as RGB(A)),
        # or a single channel kept as (H, W, 1)
        a = a[..., :planes] if planes else a[..., 0]
    if shape == "4x4":
        expected: tuple[int, ...] = (4, 4)
    elif size is None:  # depth: its own (H, W) gives the frame's size
        expected = a.shape if a.ndim == 2 and a.size else ("H", "W")
    else:
        expected = (*size, planes) if planes else size
    if a.shape != expected:
        hint = (" (a planar (3, H, W) image: np.moveaxis(image, 0, -1))" if a.shape == (3, *(size or ())) else
                " (16 numbers in a row: np.reshape(m, (4, 4)) if they are row by row, its .T if column by column, "
                "as OpenGL's glGetFloatv gives them)" if shape == "4x4" and a.shape == (16,) else
                _resolution_hint(name, a.shape, size) if size is not None and a.ndim >= 2 else "")
        raise InputShapeError(f"{name}: expected shape {expected} ({meaning}), got {a.shape}{hint}",
                              tuple(a.shape), str(expected))
    if a.dtype in (np.uint8, np.uint16) and _RANGES.get(name) == (0.0, 1.0):
        # a texture read back as 8- or 16-bit UNORM (RGBA8, R16): its integers over their largest
        return a.astype(np.float32) / np.float32(np.iinfo(a.dtype).max)
    if a.dtype == np.uint16 and name.endswith("depth") and window == 1.0:
        return a.astype(np.float32) / np.float32(65535.0)  # a D16_UNORM depth buffer read back
    if a.dtype.kind in "iu" and name == "normal":
        raise InputDtypeError(f"normal: expected view-space normals in [-1, 1] as floats, got dtype {a.dtype} (an "
                              f"encoded normal texture: decode it first, e.g. n / 255 * 2 - 1 for 8 bits)")
    with np.errstate(over="ignore"):  # (a texture's channels read back are strided: numpy's reductions and
        # gathers on them are 2-8x slower than the copy that lays them out one after another)
        a = np.ascontiguousarray(a, np.float64 if shape == "4x4" else np.float32)
    low, high = _RANGES.get(name, (0.0, window if name.endswith("depth") else np.inf)
                            if name.endswith("depth") else (-np.inf, np.inf))
    # (two reductions read it once each: a NaN makes both NaN, an infinity one infinite; no isfinite pass)
    lo, hi = (float(a.min()), float(a.max())) if a.size else (low, high)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise NonFiniteInputError(f"{name}: holds NaN or infinite values ({meaning})")
    if lo < low - RANGE_SLACK or hi > high + RANGE_SLACK:
        hint = (": tone-map it and encode it as the display does (sdk.linear_to_srgb)"
                if name in ("prev_colour", "albedo") and hi > 1.0 else
                ": an encoded normal texture copied to floats? decode it first, e.g. n / 255 * 2 - 1 for 8 bits"
                if name == "normal" and lo >= 0.0 and hi > 2.0 else
                ": vectors longer than 1? normalise them" if name == "normal" else "")
        raise ParameterError(f"{name}: expected values in [{low:g}, {high:g}] ({meaning}), got [{lo:.4g}, {hi:.4g}]"
                             f"{hint}", name)
    return a


def input_planes(
    channels: Iterable[str],
    *,
    depth: Any,
    albedo: Any = None,
    normal: Any = None,
    roughness: Any = None,
    metallic: Any = None,
    specular: Any = None,
    shadow: Any = None,
    emissive: Any = None,
    view: Any = None,
    projection: Any = None,
    prev_colour: Any = None,
    prev_depth: Any = None,
    prev_view_projection: Any = None,
    prev_projection: Any = None,
    motion: Any = None,
    tolerance: float = DEFAULT_REPROJECTION_TOLERANCE,
    albedo_linear: bool = False,
    normal_space: str = "view",
    depth_kind: str = "linear",
) -> np.ndarray:
    """The input planes of ``channels`` (a model's ``metadata.inputs``) from G-buffers in numpy arrays:
    float32 ``(C, H, W)``, top-left origin, in the order of ``channels``, ready for ``predict``.

    Each G-buffer is one of :data:`GBUFFERS` (its shape, what it holds, its range): ``depth`` always (it
    gives the frame's size and its background), the others only where a channel is made of them
    (:func:`gbuffers_needed`): the ``reprojected.*`` planes and ``seen`` reproject ``prev_colour`` with
    ``prev_depth``, ``view``, ``projection`` and ``prev_view_projection`` (:func:`reproject`, its
    ``tolerance``); ``motion.x/y`` are each pixel's previous minus current position in pixels (x right,
    y down), 0 on background and where the point was behind the previous camera. The engine's own motion
    vectors, ``motion``, where given, place each geometry pixel in the previous frame instead of the camera's
    move alone (objects that move: :func:`reproject`'s ``motion``) and are the ``motion.x/y`` planes. A channel whose
    G-buffer is not given, a G-buffer of another shape, or values outside its range (past a slack of
    1e-3: an HDR ``prev_colour``, a window depth past 1, a normal past [-1, 1]) raise a typed error naming
    it; G-buffers no channel reads are not looked at. A G-buffer of values in [0, 1] (albedo, the
    material planes, ``prev_colour``) may come as the ``uint8`` or ``uint16`` of a UNORM texture read
    back (its integers over 255 or 65535); integer normals are refused (an encoded normal texture:
    decode it first). An ``(H, W, 3)`` G-buffer may come as the ``(H, W, 4)`` of an RGBA texture (its alpha is not
    read), an ``(H, W)`` one as ``(H, W, 1)``.

    As the moderngl adapter's shader does, the albedo, the normals and the material planes (roughness,
    metallic, specular) are 0 on background (where depth is 0); unlike it, the normals are taken as they
    are, unit length or not (within [-1, 1]) (a caller may give only the components a model reads). The
    engine's conventions the same adapter takes: ``albedo_linear=True`` for a linear albedo (encoded
    with :func:`linear_to_srgb`), ``normal_space="world"`` for world-space normals (rotated with
    ``view``), ``depth_kind="window"`` for a hardware depth buffer in [0, 1] or ``"reversed"`` for a
    reversed-Z one (:data:`DEPTH_KINDS`; float, or the ``uint16`` of a D16 buffer read back; the previous
    frame's linearised with ``prev_projection`` where given, else ``projection``).
    """
    for flag, value in (("albedo_linear", albedo_linear),):
        if not isinstance(value, (bool, np.bool_)):
            raise ParameterError(f"{flag}: expected True or False, got {reprlib.repr(value)}", flag)
    if not isinstance(normal_space, str) or normal_space not in NORMAL_SPACES:
        raise ParameterError(f"normal_space: expected one of {', '.join(NORMAL_SPACES)}, got "
                             f"{reprlib.repr(normal_space)}", "normal_space")
    if not isinstance(depth_kind, str) or depth_kind not in DEPTH_KINDS:
        raise ParameterError(f"depth_kind: expected one of {', '.join(DEPTH_KINDS)} (linear view depth, 0 on "
                             f"background; a depth buffer's [0, 1], 1 on background; or a reversed-Z one, 0 on "
                             f"background), got {reprlib.repr(depth_kind)}", "depth_kind")
    window = depth_kind != "linear"  # a hardware depth buffer's values in [0, 1]
    tolerance = _tolerance(tolerance)
    names = _channels(channels)
    given = {"depth": depth, "albedo": albedo, "normal": normal, "roughness": roughness, "metallic": metallic,
             "specular": specular, "shadow": shadow, "emissive": emissive, "view": view, "projection": projection,
             "prev_colour": prev_colour, "prev_depth": prev_depth, "prev_view_projection": prev_view_projection,
             "prev_projection": prev_projection, "motion": motion}
    because = {}  # the G-buffers an option needs besides those of the channels
    if normal_space == "world" and "normal" in gbuffers_needed(names):
        because["view"] = "normal_space='world'"
    if window:
        because["projection"] = f"depth_kind={depth_kind!r}"
        if prev_projection is not None and "prev_depth" in gbuffers_needed(names):
            because["prev_projection"] = f"depth_kind={depth_kind!r}"
    needed = list(dict.fromkeys([*gbuffers_needed(names), *because]))
    missing = [b for b in needed if given[b] is None]
    if missing:
        uses = {b: [c for c in names if b in _needs(c)] or [because.get(b, "every channel (the frame's size and its "
                                                                        "background)")] for b in missing}
        raise ParameterError("; ".join(f"{b}= is needed for {', '.join(uses[b])} ({GBUFFERS[b][0]}, {GBUFFERS[b][1]})"
                                       for b in missing), missing[0])
    limit = 1.0 if window else np.inf
    d = _buffer("depth", depth, None, limit)
    size = (int(d.shape[0]), int(d.shape[1]))
    # The previous frame is at its own render resolution (dynamic resolution may have changed it): prev_depth's
    # size is the previous frame's, prev_colour's must be the same.
    g = {"prev_depth": _buffer("prev_depth", given["prev_depth"], None, limit)} if "prev_depth" in needed else {}
    sizes = {"prev_colour": g["prev_depth"].shape if g else size}
    g.update({b: _buffer(b, given[b], sizes.get(b, size), limit) for b in needed if b not in ("depth", *g)})
    for b in ("motion", "prev_projection"):  # (optional: looked at only where they are used)
        if given[b] is not None and _reprojects(names) and b not in g:
            g[b] = _buffer(b, given[b], size if b == "motion" else None)
    for b in ("projection", "prev_projection"):  # (another API's convention is named, with its conversion)
        if b in g:
            check_projection(g[b], b)
    prev_depth_proj = None
    if "prev_view_projection" in g:  # (only read by the planes that reproject)
        prev_depth_proj = _cameras(g["projection"], g["prev_view_projection"], g.get("prev_projection"),
                                   ("projection", "prev_view_projection", "prev_projection"))
        _inverse(g["view"], "view")  # (a singular one named as here, not as reproject's cur_view)
    if window:  # a depth buffer's [0, 1] to linear view depth, as the shader's linear_depth
        reversed_z = depth_kind == "reversed"
        _check_depth_kind(d, reversed_z)
        d = _linear_depth(d, g["projection"], reversed_z)
        if "prev_depth" in g:
            prev_name = "prev_projection" if "prev_projection" in g else "projection"
            g["prev_depth"] = _linear_depth(g["prev_depth"], g[prev_name], reversed_z, prev_name)
    g["depth"] = d
    geo = d > 0.0
    background = not geo.all()  # (a frame of geometry alone needs no mask)
    wanted = set(names)
    planes: dict[str, np.ndarray] = {"depth": d}
    if "depth.edge" in wanted:
        planes["depth.edge"] = depth_edges(d)
    for name in ("roughness", "metallic", "specular"):  # 0 on background, as the shader's material
        if name in g:
            planes[name] = np.where(geo, g[name], np.float32(0.0)) if background else g[name]
    for name in ("shadow", "emissive"):
        if name in g:
            planes[name] = g[name]
    if "albedo" in g:
        albedo = linear_to_srgb(g["albedo"]).astype(np.float32) if albedo_linear else g["albedo"]
        g["albedo"] = np.where(geo[..., None], albedo, np.float32(0.0)) if background else albedo
        planes.update({f"albedo.{c}": g["albedo"][..., i] for i, c in enumerate("rgb")})
        planes["albedo.y"] = luma(g["albedo"])
        if "albedo.y.blocks" in wanted:
            planes["albedo.y.blocks"] = block_variances(planes["albedo.y"])
        if "albedo.y.tiles" in wanted:
            planes["albedo.y.tiles"] = tile_variances(planes["albedo.y"])
    if "normal" in g:
        n = g["normal"]
        if normal_space == "world":
            n = (n @ g["view"][:3, :3].T.astype(np.float32)).astype(np.float32)
        # (not made unit length, as the shader makes them: an adapter may give some components alone, the
        # pyrender adapter the ones a model reads)
        n = np.where(geo[..., None], n, np.float32(0.0)) if background else n
        planes.update({f"normal.{c}": n[..., i] for i, c in enumerate("xyz")})
    if "prev_colour" in g:
        colour = wanted & {"reprojected.r", "reprojected.g", "reprojected.b"}
        # Luma is per pixel and 0 is black's, so the luma of the reprojected frame is the reprojected luma of the
        # previous frame, value for value: a model that reads no colour plane gathers one plane instead of three.
        rep, seen = _reproject(g["prev_colour"] if colour else luma(g["prev_colour"]), g["prev_depth"], d,
                               g["view"], g["projection"], g["prev_view_projection"], prev_depth_proj, tolerance,
                               g.get("motion"))
        if colour:
            planes.update({f"reprojected.{c}": rep[..., i] for i, c in enumerate("rgb")})
        y = planes["reprojected.y"] = luma(rep) if colour else rep
        if wanted & {"reprojected.y.dx", "reprojected.y.dy"}:
            planes["reprojected.y.dx"], planes["reprojected.y.dy"] = pixel_differences(y)
        if "reprojected.y.blocks" in wanted:
            planes["reprojected.y.blocks"] = block_variances(y)
        if "reprojected.y.tiles" in wanted:
            planes["reprojected.y.tiles"] = tile_variances(y)
        planes["seen"] = seen
    if wanted & {"motion.x", "motion.y"} and "motion" in g:  # the engine's, 0 on background as the channel's
        zero = np.float32(0.0)
        planes["motion.x"], planes["motion.y"] = (np.where(geo, g["motion"][..., i], zero) for i in (0, 1))
    elif wanted & {"motion.x", "motion.y"}:
        planes["motion.x"], planes["motion.y"] = _motion_vectors(d, g["view"], g["projection"],
                                                                  g["prev_view_projection"], prev_depth_proj)
    return np.ascontiguousarray(np.stack([planes[c] for c in names]), np.float32)


def _linear_depth(raw: np.ndarray, projection: np.ndarray, reversed_z: bool = False,
                  name: str = "projection") -> np.ndarray:
    """Window depth in [0, 1] (1 = background), or reversed-Z depth (0 = background), to linear view depth
    (0 = background) through the inverse of ``projection``: the moderngl adapter's ``linear_depth``.

    A reversed-Z buffer holds 1 minus the window depth of the same near and far planes (n (f - z) / (z (f - n))
    against f (z - n) / (z (f - n)); n / z against 1 - n / z for an infinite far plane), so both go through
    OpenGL's NDC depth, 2 w - 1, computed in float64 where 1 - r is exact for a float32 r. A ``projection``
    (named ``name``) with no inverse, or one through which a pixel's depth is no finite float32 view depth,
    is a :class:`ParameterError`, as is one that is neither a perspective nor an orthographic projection in
    OpenGL's convention (:func:`_check_depth_projection`: a left-handed, reversed-Z or row-vector orthographic one)."""
    _check_depth_projection(projection, name)
    inv = _inverse(projection, name)
    r = raw.astype(np.float64)
    z = 1.0 - 2.0 * r if reversed_z else r * 2.0 - 1.0
    pz = inv[2, 2] * z + inv[2, 3]
    pw = inv[3, 2] * z + inv[3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        linear = np.where(r <= 0.0 if reversed_z else r >= 1.0, 0.0, -pz / pw)
    bad = ~(np.abs(linear) <= np.finfo(np.float32).max)  # (NaN, infinite, or past float32)
    if bad.any():
        raise ParameterError(f"{name}: the depth buffer through its inverse gives no finite view depth at "
                             f"{int(bad.sum())} of {bad.size} pixels (its largest entry {np.abs(projection).max():g}): "
                             f"pass the projection the depth buffer was rendered with", name)
    # Behind the camera: an orthographic projection whose near plane is at or behind the view's origin (glOrtho's
    # near of -1) sees points of negative view depth, which rtp's depth (>= 0, 0 the background) cannot hold: they
    # were negative depth values, taken as background. Within rounding of 0 (a near plane at 0), 0.
    behind = linear < 0.0
    if behind.any():
        if float(linear.min()) < -1e-6 * float(np.abs(linear).max()):
            raise ParameterError(f"{name}: the depth buffer through it gives a negative view depth (a point behind the "
                                 f"camera, down to {float(linear.min()):.4g}) at {int(behind.sum())} of {behind.size} "
                                 f"pixels: an orthographic projection whose near plane is behind the camera (glOrtho's "
                                 f"near -1)? rtp's linear depth is >= 0 (0 on background): move the view's origin back "
                                 f"along its axis past the nearest point, and the near and far planes forward by as much",
                                 name)
        linear = np.maximum(linear, 0.0)
    return linear.astype(np.float32)


_warned_kinds: set[str] = set()
_warned_lock = threading.Lock()


def _check_depth_kind(raw: np.ndarray, reversed_z: bool) -> None:
    """Warn once per kind where a depth buffer looks like the other kind: its background value (1, or 0 for
    reversed-Z) nowhere and the near plane's value on some pixels. A reversed-Z buffer read as a window one puts
    the background at the near plane, and every plane made of depth is wrong without an error."""
    background, near = (0.0, 1.0) if reversed_z else (1.0, 0.0)
    kind = "reversed" if reversed_z else "window"
    if kind in _warned_kinds or (raw == background).any():
        return
    at_near = int(np.count_nonzero(raw == near))
    if at_near:
        with _warned_lock:  # (the test and the add as one: threads making planes at once each logged it)
            if kind in _warned_kinds:
                return
            _warned_kinds.add(kind)
        other = "window" if reversed_z else "reversed"
        log.warning("depth: depth_kind=%r, but %d pixels hold %g (the near plane) and none %g (background): a %s "
                    "depth buffer? (depth_kind=%r); warned once", kind, at_near, near, background,
                    "standard" if reversed_z else "reversed-Z", other)


def _motion_vectors(depth: np.ndarray, view: np.ndarray, projection: np.ndarray, prev_view_projection: np.ndarray,
                   prev_depth_proj: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """``motion.x``, ``motion.y``: each pixel's previous minus current position in pixels (x right, y down),
    float32 ``(H, W)``; 0 on background and where the point was behind the previous camera."""
    h, w = depth.shape
    qx, qy, cw = _positions(depth, view, projection, prev_view_projection, prev_depth_proj)
    xs = np.arange(w, dtype=np.float64)[None, :] + 0.5
    gl_y = h - (np.arange(h, dtype=np.float64)[:, None] + 0.5)
    valid = (depth > 0.0) & (cw > 0.0)
    mx = np.where(valid, qx - xs, 0.0).astype(np.float32)
    my = np.where(valid, -(qy - gl_y), 0.0).astype(np.float32)
    return mx, my


#: How far off a rigid view's rotation may be from orthonormal, or a view-projection's w row from unit length.
_RIGID_SLACK = 1e-3
#: The share of surfaces whose normal may face away from the camera before it is named (normal maps and grazing
#: angles turn a few away; the wrong space turns about half).
_AWAY_SHARE = 0.25
#: The share of surfaces whose normal may be 0 (not written: decals, particles) before it is named.
_UNWRITTEN_SHARE = 0.5
#: The share of surfaces that must reproject onto the previous frame before too few is named.
_SEEN_SHARE = 0.5
#: The share of surfaces nearer than the projection's near plane (which no rendered surface is) past which a
#: ``linear`` depth is named as not linear view depth (a reversed-Z buffer's n / z, a depth over the far plane).
_NEAR_SHARE = 0.25
#: The engine's motion vectors against the camera's move, on the surfaces the camera moves a pixel or more (on a
#: static scene they are the same): named when they agree on under this share as given, and on at least
#: :data:`_MOTION_FIT` (and twice as many) in another convention. On the reference renderer's frames (procedural
#: scenes, 33x19 to 160x90, the ``fast`` camera path) they agree on all; the next best convention on under 45%.
_MOTION_AGREE = 0.5
_MOTION_FIT = 0.6
#: The engine's motion conventions that are told apart: units (the scale to pixels, x and y) and their names.
_MOTION_UNITS = (("pixels", lambda w, h: (1.0, 1.0)), ("NDC units (2 across the frame)", lambda w, h: (w / 2, h / 2)),
                 ("UV units (1 across the frame)", lambda w, h: (float(w), float(h))))


def check_gbuffers(
    *,
    tolerance: float = DEFAULT_REPROJECTION_TOLERANCE,
    albedo_linear: bool = False,
    normal_space: str = "view",
    depth_kind: str = "linear",
    **gbuffers: Any,
) -> list[str]:
    """What in an engine's G-buffers looks like a convention mistake: a list of warnings, each naming the
    G-buffer, what was seen and the likely cause (empty: none seen). :func:`input_planes` takes a frame in
    another convention without an error where its values are in range, and the planes are then wrong:
    this looks at what they show, once, where an engine is wired up (``rtp predict`` runs it on every frame).

    ``gbuffers`` are :func:`input_planes`' G-buffer keywords (:data:`GBUFFERS`: ``depth`` always), the options
    its own; the same call but the channels. Checked where the G-buffers are given: ``view`` is a rigid
    transform for column vectors (no translation in its last row, no scale, no reflection: a left-handed
    view); ``prev_view_projection``'s last row is a camera's viewing axis (a unit vector: not transposed, no
    scale); ``normal`` (with ``view`` for ``normal_space="world"``, ``projection`` for facing) is written on most
    surfaces (not 0), unit length, and faces the camera on most surfaces (the wrong space, or a left-handed view
    space, turns about half away); a ``linear`` depth is not a depth buffer's [0, 1] (its clear value 1 on some
    pixels, or half the surfaces past 0.9), and no surface nearer than ``projection``'s near plane (a reversed-Z
    buffer's values or a depth over the far plane, 0 on background as linear depth's, are); the engine's ``motion``
    (with the matrices) agrees with the camera's move on most surfaces it moves a pixel or more, not only once
    scaled from NDC or UV units, negated or its y flipped (the warning names the convention and the factors that
    convert it); and, with the previous frame, most surfaces reproject onto it (else the matrices or
    depth are another frame's or another convention's; with a hardware depth, where they do once the matrices
    are taken as clip depth in [0, 1], the warning names a Direct3D-style projection and its conversion; where they do
    once ``depth`` and ``prev_depth`` are taken in another depth convention, a hardware depth's other kind or, for
    values in [0, 1], one of the hardware kinds or a linear depth over the far plane, it names that one: a close-up
    frame's depth buffer, which the values alone do not show). The
    other G-buffers (``albedo``, the material) and ``albedo_linear`` are not looked at, nor whether the colour is in
    linear light (``rtp import``, which has the frame shown too, looks at that); bad arrays raise
    :func:`input_planes`' errors.
    """
    if not isinstance(albedo_linear, (bool, np.bool_)):
        raise ParameterError(f"albedo_linear: expected True or False, got {reprlib.repr(albedo_linear)}",
                             "albedo_linear")
    unknown = sorted(set(gbuffers) - set(GBUFFERS))
    if unknown:
        raise ParameterError(f"{unknown[0]}: not a G-buffer (expected {', '.join(GBUFFERS)})", unknown[0])
    given: dict[str, Any] = {b: gbuffers.get(b) for b in GBUFFERS}
    depth, normal, view, projection = given["depth"], given["normal"], given["view"], given["projection"]
    if depth is None:
        raise ParameterError(f"depth= is needed ({GBUFFERS['depth'][0]}, {GBUFFERS['depth'][1]})", "depth")
    options: dict[str, Any] = {"tolerance": tolerance, "normal_space": normal_space, "depth_kind": depth_kind}
    warnings: list[str] = []
    d = input_planes(["depth"], depth=depth, projection=projection, **options)[0]  # (the options checked too)
    geo = d > 0.0
    if view is not None:
        v = _buffer("view", view, None)
        rotation = v[:3, :3]
        if np.abs(v[3] - (0.0, 0.0, 0.0, 1.0)).max() > _RIGID_SLACK:
            warnings.append(f"view: its last row is {np.round(v[3], 4).tolist()}, not (0, 0, 0, 1): a matrix for row "
                            f"vectors (transpose it)?")
        elif np.abs(rotation @ rotation.T - np.eye(3)).max() > _RIGID_SLACK:
            warnings.append("view: its rotation is not orthonormal (a scale?): rtp takes a rigid world-to-view "
                            "transform")
        elif np.linalg.det(rotation) < 0.0:
            warnings.append('view: a reflection (determinant -1): a left-handed view space? (docs/runtime.md '
                            '"Matrices from Direct3D, Vulkan and Metal": diag(1, 1, -1, 1) @ view)')
    if given["prev_view_projection"] is not None:
        w_row = _buffer("prev_view_projection", given["prev_view_projection"], None)[3]
        perspective = abs(float(np.linalg.norm(w_row[:3])) - 1.0) <= _RIGID_SLACK
        orthographic = np.abs(w_row - (0.0, 0.0, 0.0, 1.0)).max() <= _RIGID_SLACK
        if not (perspective or orthographic):
            warnings.append(f"prev_view_projection: its last row {np.round(w_row, 4).tolist()} is not a camera's "
                            f"viewing axis (a unit vector, as a projection's w row times a rigid view gives): a matrix "
                            f"for row vectors (transpose it), or a scaled view?")
    if normal is not None and geo.any() and (normal_space == "view" or view is not None):
        n = np.stack(list(input_planes(["normal.x", "normal.y", "normal.z"], depth=depth, normal=normal, view=view,
                                       projection=projection, **options)), -1)[geo]
        length = np.linalg.norm(n, axis=-1)
        drawn = length > 0.01
        unwritten = float((~drawn).mean())
        if unwritten > _UNWRITTEN_SHARE:
            warnings.append(f"normal: {100 * unwritten:.0f}% of the surfaces have no normal (length 0): the normal "
                            f"target not written, or another texture given?")
        if drawn.any() and float(np.abs(length[drawn] - 1.0).mean()) > 0.05:
            encoded = " with no component below 0: an encoded texture (n * 2 - 1)?" if n.min() >= 0.0 else ""
            warnings.append(f"normal: mean length {float(length[drawn].mean()):.3g}, not unit vectors{encoded}")
        if projection is not None and drawn.any():
            h, w = d.shape
            proj = check_projection(projection)
            inv = _inverse(proj, "projection")  # (a singular one: a typed error)
            xs = ((np.arange(w) + 0.5) / w * 2.0 - 1.0)[None, :].repeat(h, 0)[geo]
            ys = (1.0 - (np.arange(h) + 0.5) / h * 2.0)[:, None].repeat(w, 1)[geo]
            if _affine_row(proj[3]):  # an orthographic camera: back along its lines (NDC z falling)
                to_camera = np.broadcast_to(-inv[:3, 2] / inv[3, 3], (xs.size, 3))
            else:  # a perspective: to the camera's centre from the point on the near plane
                q = [inv[i, 0] * xs + inv[i, 1] * ys - inv[i, 2] + inv[i, 3] for i in range(4)]
                to_camera = -np.stack([q[0] / q[3], q[1] / q[3], q[2] / q[3]], -1)
            away = float(((n * to_camera).sum(-1)[drawn] < 0.0).mean())
            if away > _AWAY_SHARE:
                hint = ("world-space normals given as view-space (normal_space='world')" if normal_space == "view"
                        else "normals already in view space given as world-space (normal_space='view'), or the "
                             "wrong view")
                warnings.append(f"normal: {100 * away:.0f}% of the surfaces face away from the camera: {hint}, or a "
                                f"left-handed view space (negate z)?")
    if depth_kind == "linear" and geo.any() and projection is not None:
        try:
            near = _near_plane(_buffer("projection", projection, None))
        except RtpError:  # (a projection input_planes refuses: refused where a plane reads it, not here)
            near = None
        nearer = float((d[geo] < near * (1.0 - 1e-3)).mean()) if near is not None else 0.0
        if nearer > _NEAR_SHARE:
            warnings.append(f"depth: {100 * nearer:.0f}% of the surfaces are nearer than the projection's near plane "
                            f"({near:.4g}), where nothing is drawn: not linear view depth in scene units; a reversed-Z "
                            f"depth buffer (depth_kind='reversed'), or a depth divided by the far plane (Unity's "
                            f"Linear01Depth: times far)?")
    if (given["motion"] is not None and view is not None and projection is not None
            and given["prev_view_projection"] is not None and geo.any()):
        text = _motion_convention(given, d, options)
        if text:
            warnings.append(text)
    if depth_kind == "linear" and geo.any():
        raw = np.asarray(d, np.float64)
        at_one, middle = float((raw == 1.0).mean()), float(np.median(raw[geo]))
        if raw.max() <= 1.0 and (at_one > 0.02 or middle > 0.9):
            warnings.append(f"depth: its values are in [0, 1], half the surfaces past {middle:.3g} and {100 * at_one:.0f}% "
                            f"at exactly 1 (a depth buffer's clear value): a depth buffer (depth_kind='window', or "
                            f"'reversed')? linear depth is in scene units")
    needed = ("view", "projection", "prev_colour", "prev_depth", "prev_view_projection")
    if all(given[b] is not None for b in needed) and geo.any():
        seen = input_planes(["seen"], **{b: given[b] for b in (*needed, "depth", "prev_projection", "motion")},
                            **options)[0]
        share = float(seen[geo].mean())
        if share < _SEEN_SHARE:
            converted = _zero_to_one_share(given, needed, options, geo) if depth_kind != "linear" else None
            if converted is not None and converted >= _SEEN_SHARE and converted > share:
                also = " and D @ prev_projection" if given["prev_projection"] is not None else ""
                warnings.append(
                    f"seen: only {100 * share:.0f}% of the surfaces reproject onto the previous frame and pass its "
                    f"depth test, and {100 * converted:.0f}% with the matrices' clip depth taken as [0, 1]: projection "
                    f"looks like a [0, 1]-depth matrix (Direct3D's, Vulkan's, Metal's), which depth_kind="
                    f"{depth_kind!r} linearises as OpenGL's [-1, 1] (too near: about half as far, away from the far "
                    f"plane). No option converts it: "
                    f"pass D @ projection and D @ prev_view_projection{also}, "
                    f"D = {_ZERO_TO_ONE_TEXT} (depth row 2 z - w; {_CONVERSIONS}); the depth buffer itself needs "
                    f"no conversion")
            else:
                other = _other_depth_share(given, needed, options)
                if other is not None and other[0] >= _SEEN_SHARE and other[0] > share:
                    warnings.append(f"seen: only {100 * share:.0f}% of the surfaces reproject onto the previous frame "
                                    f"and pass its depth test, and {100 * other[0]:.0f}% with depth and prev_depth "
                                    f"taken as {other[1]}")
                else:
                    warnings.append(f"seen: only {100 * share:.0f}% of the surfaces reproject onto the previous frame "
                                    f"and pass its depth test: prev_depth and prev_view_projection the previous "
                                    f"frame's, of the same conventions and depth kind? (a camera cut or a fast turn "
                                    f"does this too)")
    return warnings


def _near_plane(projection: np.ndarray) -> float | None:
    """The view depth of an OpenGL perspective ``projection``'s near plane (NDC z -1), or None for another (an
    orthographic one, one of another convention whose near plane does not come out positive)."""
    p = np.asarray(projection, np.float64)
    if np.abs(p[3] - (0.0, 0.0, -1.0, 0.0)).max() > 1e-6 or p[2, 2] == 1.0:
        return None
    near = float(p[2, 3] / (p[2, 2] - 1.0))
    return near if np.isfinite(near) and near > 0.0 else None


def _motion_convention(given: Mapping[str, Any], depth: np.ndarray, options: Mapping[str, Any]) -> str | None:
    """A warning where the engine's ``motion`` looks like another convention than rtp's (each pixel's previous
    minus current position in pixels, x right, y down): on the surfaces the camera moves a pixel or more, it
    disagrees with the camera's move as given and agrees once scaled from NDC or UV units, negated or its y flipped
    (:data:`_MOTION_AGREE`, :data:`_MOTION_FIT`); None otherwise (too few such surfaces: nothing said)."""
    h, w = depth.shape
    camera = np.stack(list(input_planes(
        ["motion.x", "motion.y"], depth=given["depth"], view=given["view"], projection=given["projection"],
        prev_view_projection=given["prev_view_projection"], prev_projection=given["prev_projection"], **options)), -1)
    motion = _buffer("motion", given["motion"], (h, w)).astype(np.float64)
    length = np.linalg.norm(camera, axis=-1)
    use = (depth > 0.0) & (length >= 1.0)
    if int(use.sum()) < 16:
        return None
    camera, motion, length = camera[use], motion[use], length[use]

    def agree(scale: tuple[float, float]) -> float:
        return float((np.linalg.norm(motion * scale - camera, axis=-1) <= 0.5 + 0.1 * length).mean())

    as_given = agree((1.0, 1.0))
    if as_given >= _MOTION_AGREE:
        return None
    fits = []
    for units, to_pixels in _MOTION_UNITS:
        sx, sy = to_pixels(w, h)
        for fx, fy in ((1, 1), (1, -1), (-1, -1), (-1, 1)):
            if (units, fx, fy) != ("pixels", 1, 1):
                fits.append((agree((sx * fx, sy * fy)), units, fx, fy, (sx * fx, sy * fy)))
    share, units, fx, fy, scale = max(fits, key=lambda f: f[0])
    if share < _MOTION_FIT or share < 2.0 * as_given:
        return None
    how = ", ".join([units] + (["current minus previous position"] if fx < 0 else [])
                    + (["y up"] if fx * fy < 0 else []))
    return (f"motion: agrees with the camera's move on {100 * as_given:.0f}% of the surfaces it moves, and on "
            f"{100 * share:.0f}% taken as {how}: rtp's motion is each pixel's previous minus current position in pixels, "
            f"x right, y down (multiply these by ({scale[0]:g}, {scale[1]:g}))")


def _other_depth_share(given: Mapping[str, Any], needed: tuple[str, ...],
                       options: Mapping[str, Any]) -> tuple[float, str] | None:
    """Where few surfaces reproject, the best share of its own surfaces ``seen`` with ``depth`` and ``prev_depth`` taken
    in another depth convention than ``options``' ``depth_kind``, and what to say of it (the option, or the
    conversion); None where none can be tried. A depth buffer given as ``linear`` depth (or one kind as the other) is
    named by its values alone where they are past 0.9 or nearer than the near plane, not on a close-up frame (a
    wall within a metre: a window depth about 0.86, a reversed-Z one about n / z, past the near plane), nor a depth
    divided by the far plane (Unity's ``Linear01Depth``) of a scene far from the camera: there the reprojection
    tells them apart."""
    kind = options["depth_kind"]
    frame = {b: given[b] for b in (*needed, "depth", "prev_projection", "motion")}
    tries: list[tuple[dict[str, Any], str, str]] = []  # (G-buffers, depth_kind, what it is said to be)
    try:  # (linear depth's values in [0, 1]: those of a hardware depth too; a hardware kind's are, input_planes saw)
        unit = kind != "linear" or all(0.0 <= float(np.min(a)) and float(np.max(a)) <= 1.0 for a in (
            np.asarray(frame[b], np.float64) for b in ("depth", "prev_depth")))
    except (TypeError, ValueError):  # (arrays input_planes refused: not here)
        return None
    if unit:  # (a hardware depth's values: any kind may be tried but one they contradict, whose background value is
        # nowhere and its near plane's somewhere: input_planes would log that as the depth_kind given, once a process)
        raw = np.asarray(frame["depth"])
        raw = raw / 65535.0 if raw.dtype == np.uint16 and kind != "linear" else raw  # (a D16 buffer read back)
        tries += [(frame, k, f"a {'reversed-Z' if k == 'reversed' else 'standard'} depth buffer "
                             f"(depth_kind={k!r})") for k in DEPTH_KINDS if k not in (kind, "linear")
                  and ((raw == (0.0 if k == "reversed" else 1.0)).any() or not (raw == (k == "reversed")).any())]
    if kind == "linear":  # a depth over the far plane (Unity's Linear01Depth): times far
        projection = np.asarray(frame["projection"], np.float64)
        far = _far_plane(projection) if projection.shape == (4, 4) else None
        if far is not None and unit:
            tries.append(({**frame, "depth": np.asarray(frame["depth"], np.float64) * far,
                           "prev_depth": np.asarray(frame["prev_depth"], np.float64) * far}, "linear",
                          f"a depth divided by the far plane (Unity's Linear01Depth): multiply both by far "
                          f"({far:.4g})"))
    best = None
    for gbuffers, k, text in tries:
        try:
            seen, depth = input_planes(["seen", "depth"], **gbuffers, **{**options, "depth_kind": k})
        except RtpError:  # (not values or matrices of that convention)
            continue
        geo = depth > 0.0
        if geo.any():
            share = float(seen[geo].mean())
            if best is None or share > best[0]:
                best = (share, text)
    return best


def _far_plane(projection: np.ndarray) -> float | None:
    """The view depth of an OpenGL perspective ``projection``'s far plane (NDC z 1), or None for another (an
    infinite far plane, an orthographic projection, another convention)."""
    if _near_plane(projection) is None or projection[2, 2] == -1.0:
        return None
    far = float(projection[2, 3] / (projection[2, 2] + 1.0))
    return far if np.isfinite(far) and far > 0.0 else None


#: The constant that turns a clip depth in [0, 1] (Direct3D's, Vulkan's, Metal's) into OpenGL's [-1, 1]
#: (docs/runtime.md "Matrices from Direct3D, Vulkan and Metal": ``D @ projection``, ``D @ prev_view_projection``).
_ZERO_TO_ONE = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 2.0, -1.0], [0.0, 0.0, 0.0, 1.0]])
_ZERO_TO_ONE_TEXT = "[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, -1], [0, 0, 0, 1]]"


def _zero_to_one_share(given: Mapping[str, Any], needed: tuple[str, ...], options: Mapping[str, Any],
                       geo: np.ndarray) -> float | None:
    """The share of the surfaces ``geo`` (a hardware depth's background, the same in any convention) ``seen`` with
    the matrices (``projection``, ``prev_view_projection``, ``prev_projection``) taken as clip depth in [0, 1] and
    converted to OpenGL's, or None where ``projection`` is no perspective or the converted ones are refused: a
    window depth linearised through a Direct3D-style projection as if it were OpenGL's comes out too near (about
    half as far), and fails the reprojection's depth test."""
    projection = np.asarray(given["projection"], np.float64)
    if projection.shape != (4, 4) or not _w_row(projection[3]):  # (an orthographic camera's depth row: not guessed)
        return None
    converted = {b: given[b] for b in (*needed, "depth", "prev_projection", "motion")}
    for b in ("projection", "prev_view_projection", "prev_projection"):
        if converted[b] is not None:
            converted[b] = _ZERO_TO_ONE @ np.asarray(converted[b], np.float64)
    try:
        seen = input_planes(["seen"], **converted, **options)[0]
    except RtpError:  # (not a matrix the conversion makes right)
        return None
    return float(seen[geo].mean())
