"""Named model input channels: the one definition every adapter, the capture driver and the
metadata validator share.

A model's metadata lists its inputs by these names, in the order the network expects them. An
adapter builds exactly those planes, in that order, as float32 ``(C, H, W)`` with a top-left
origin. Value conventions are fixed here so that training inputs and deployment inputs cannot
drift apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._errors import InputShapeError, NonFiniteInputError
from ._rates import ALL_RATES

__all__ = ["BLOCK_CELL", "BLOCK_EPS", "BLOCK_RATES", "BLOCK_TILE", "CHANNELS", "DEFAULT_INPUTS", "Channel", "block_variances",
           "depth_edges", "pixel_differences", "tile_variances"]


@dataclass(frozen=True)
class Channel:
    """One input plane: its name, its value range and what it means."""

    name: str
    low: float
    high: float
    description: str


_SPECS = [
    ("reprojected.r", 0.0, 1.0,
     "previous final colour (display-encoded sRGB) fetched where the pixel was last frame; 0 where unseen"),
    ("reprojected.g", 0.0, 1.0, "as reprojected.r, green"),
    ("reprojected.b", 0.0, 1.0, "as reprojected.r, blue"),
    ("reprojected.y", 0.0, 1.0,
     "Rec.601 luma (sdk.luma) of reprojected.r/g/b: the luma every metric measures its error and its Weber "
     "correction on; 0 where unseen"),
    ("reprojected.y.dx", 0.0, 1.0,
     "|reprojected.y to its right neighbour's| (sdk.pixel_differences): the luma a 2-pixel-wide shading block "
     "would lose; 0 in the last column"),
    ("reprojected.y.dy", 0.0, 1.0,
     "|reprojected.y to the neighbour's below| (sdk.pixel_differences): the luma a 2-pixel-tall shading block "
     "would lose; 0 in the last row"),
    ("reprojected.y.blocks", 0.0, 1.0,
     "per 4x4 cell, how much each reduced rate's blocks vary in reprojected.y (sdk.block_variances: the log "
     "variance inside the blocks, one rate per pixel of the cell, packed)"),
    ("albedo.y.blocks", 0.0, 1.0, "as reprojected.y.blocks, of albedo.y (sdk.block_variances)"),
    ("reprojected.y.tiles", 0.0, 1.0,
     "per 16x16 tile, each reduced rate's block variance in reprojected.y over the tile's 4x4 cells, mean and "
     "maximum (sdk.tile_variances: the .blocks values summarised, twelve values on the tile's first pixels)"),
    ("albedo.y.tiles", 0.0, 1.0, "as reprojected.y.tiles, of albedo.y (sdk.tile_variances)"),
    ("seen", 0.0, 1.0, "1 where the reprojected position is on the previous frame and passes its depth test, else 0"),
    ("albedo.r", 0.0, 1.0, "surface base colour, display-encoded sRGB, red; 0 on background"),
    ("albedo.g", 0.0, 1.0, "as albedo.r, green"),
    ("albedo.b", 0.0, 1.0, "as albedo.r, blue"),
    ("albedo.y", 0.0, 1.0, "Rec.601 luma (sdk.luma) of albedo.r/g/b"),
    ("normal.x", -1.0, 1.0, "view-space unit normal x (right-handed view space, camera looks down -z); 0 on background"),
    ("normal.y", -1.0, 1.0, "view-space unit normal y"),
    ("normal.z", -1.0, 1.0, "view-space unit normal z; > 0 faces the camera"),
    ("roughness", 0.0, 1.0, "GGX perceptual roughness"),
    ("metallic", 0.0, 1.0, "metalness"),
    ("specular", 0.0, 1.0, "dielectric specular reflectance scale (0.5 = F0 of 4%)"),
    ("shadow", 0.0, 1.0, "main-light shadow-map visibility, 1 = lit"),
    ("emissive", 0.0, 1.0, "emissive luminance, display-encoded"),
    ("depth", 0.0, float("inf"), "linear view depth in scene units (distance along -z); 0 on background"),
    ("depth.edge", 0.0, 1.0,
     "depth discontinuity: second difference of inverse depth over its local maximum, the larger of x and y "
     "(sdk.depth_edges); 0 on planes, 1 - d_near/d_far beside a step, 1 at silhouettes against background"),
    ("motion.x", float("-inf"), float("inf"), "screen motion in pixels, previous minus current position, x to the right"),
    ("motion.y", float("-inf"), float("inf"), "screen motion in pixels, previous minus current position, y down"),
]

#: Every known input channel, by name.
CHANNELS: dict[str, Channel] = {name: Channel(name, lo, hi, desc) for name, lo, hi, desc in _SPECS}

#: The paper's recommended 4-channel input (Section 3.2, Table 1).
DEFAULT_INPUTS: tuple[str, ...] = ("reprojected.r", "seen", "albedo.r", "normal.z")


def depth_edges(depth: np.ndarray) -> np.ndarray:
    """The ``depth.edge`` plane of a linear depth plane: where the geometry is discontinuous.

    With ``z = 1 / depth`` (0 on background, ``depth == 0``), per pixel and per axis the second
    difference ``|z[-1] + z[+1] - 2 z[0]|`` divided by the largest of the three ``z``; the plane is the
    larger of the x and y values, clipped to [0, 1]. Inverse depth is affine in screen space over a
    plane, so planes read 0 at any slope and resolution; the two pixels beside a step from depth
    ``d_near`` to ``d_far`` read ``1 - d_near / d_far``; a silhouette against background reads 1.
    The first and last column have no x value (0), the first and last row no y value. Adapters that
    build the plane on a GPU follow this definition (the moderngl adapter's shader; tests compare).

    Args:
        depth: ``(H, W)`` linear view depth (scene units along -z, 0 = background), any float dtype.

    Returns:
        float32 ``(H, W)`` in [0, 1].
    """
    d = np.asarray(depth)
    if d.ndim != 2 or 0 in d.shape or d.dtype.kind not in "iuf":  # (real numbers: not bool, not complex)
        raise InputShapeError(f"depth_edges: expected a numeric (H, W) depth plane, got shape {d.shape} dtype {d.dtype}",
                              tuple(d.shape), "(H, W)")
    d = d.astype(np.float32, copy=False)
    if not np.isfinite(d).all():
        raise NonFiniteInputError("depth_edges: the depth plane holds NaN or infinite values")
    with np.errstate(divide="ignore"):
        z = np.where(d > 0, 1.0 / np.maximum(d, np.float32(1e-30)), np.float32(0)).astype(np.float32)
    out = np.zeros_like(z)
    for axis in (1, 0):
        c = z[:, 1:-1] if axis == 1 else z[1:-1]
        lo, hi = (z[:, :-2], z[:, 2:]) if axis == 1 else (z[:-2], z[2:])
        top = np.maximum(np.maximum(lo, hi), c)
        with np.errstate(invalid="ignore", divide="ignore"):
            e = np.where(top > 0, np.abs(lo + hi - 2 * c) / np.where(top > 0, top, 1), np.float32(0))
        inner = out[:, 1:-1] if axis == 1 else out[1:-1]
        np.maximum(inner, e, out=inner)
    return np.clip(out, 0.0, 1.0).astype(np.float32, copy=False)


def _finite_plane(plane: np.ndarray, fn: str, dtype: type[np.floating] | None) -> np.ndarray:
    """``plane`` as a finite ``(H, W)`` array of ``dtype`` (None: its own), or the typed error naming ``fn``."""
    p = np.asarray(plane)
    if p.ndim != 2 or 0 in p.shape or p.dtype.kind not in "iuf":  # (real numbers: not bool, not complex)
        raise InputShapeError(f"{fn}: expected a numeric (H, W) plane, got shape {p.shape} dtype {p.dtype}",
                              tuple(p.shape), "(H, W)")
    if dtype is not None:
        p = p.astype(dtype, copy=False)
    if not np.isfinite(p).all():
        raise NonFiniteInputError(f"{fn}: the plane holds NaN or infinite values")
    return p


def pixel_differences(plane: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ``.dx`` and ``.dy`` planes of a plane: each pixel's absolute difference to its right and
    to its lower neighbour (0 in the last column, resp. row).

    What variable-rate shading loses is the variation inside each shading block (the block is
    shaded once and its sample repeated); the network's strided first layer reads a cell linearly
    and cannot take an absolute value of a difference inside it, so an adapter supplies them: on a
    GPU one more fetch per pixel. Summed over a block's aligned pairs (the even columns for ``dx``,
    the even rows for ``dy``) they are the luma a 2x1 or 1x2 block would lose (docs/results.md
    "Differences inside the shading blocks"). Adapters that build the planes on a GPU follow this
    definition (the moderngl adapter's shader; tests compare).

    Args:
        plane: ``(H, W)`` values, any float dtype (for example :func:`luma` of the reprojected frame).

    Returns:
        ``(dx, dy)``: float32 ``(H, W)`` each.
    """
    p = _finite_plane(plane, "pixel_differences", np.float32)
    dx = np.zeros_like(p)
    dy = np.zeros_like(p)
    np.abs(p[:, 1:] - p[:, :-1], out=dx[:, :-1])
    np.abs(p[1:] - p[:-1], out=dy[:-1])
    return dx, dy


#: The cell :func:`block_variances` measures over (the fast network's stem reads 4x4 cells).
BLOCK_CELL = 4
#: The rates :func:`block_variances` packs, in raster order over the first pixels of each cell.
BLOCK_RATES: tuple[str, ...] = tuple(ALL_RATES[1:])
#: Variance floor of :func:`block_variances` (a flat block reads 0, a luma step of 1 inside every block about 0.85).
BLOCK_EPS = 1e-4


def block_variances(plane: np.ndarray) -> np.ndarray:
    """The ``.blocks`` plane of a plane: per 4x4 cell, how much each reduced rate would lose of it.

    Variable-rate shading shades each block once and repeats the sample, so what a rate loses of a
    plane is about the variance inside its blocks. For each cell of :data:`BLOCK_CELL` pixels and each
    rate of :data:`BLOCK_RATES` (1x2, 2x1, 2x2, 2x4, 4x2, 4x4, blocks aligned to the cell), the mean
    over the cell of the variance inside the rate's blocks, as ``log(v + eps) / -log(eps) + 1``
    (``eps`` = :data:`BLOCK_EPS`) clipped to [0, 1], is written to the cell's k-th pixel in raster
    order (row 0: 1x2, 2x1, 2x2, 2x4; row 1: 4x2, 4x4); the cell's other pixels are 0. A network
    whose first layer reads 4x4 cells (rtp's fast network) then reads the six values directly: a
    nonlinear measure its linear first layer cannot compute (docs/results.md "Differences inside
    the shading blocks"). A frame whose sides are not multiples of 4 is padded by repeating its
    last row and column; the values of a partial last cell whose pixels lie past the frame's edge (a
    width not a multiple of 4, a height of 4k + 1) are not stored, and a predictor logs a warning for
    such frames (docs/runtime.md, padding rule). Adapters that build the plane on a GPU follow this
    definition.

    Args:
        plane: ``(H, W)`` values in [0, 1], any float dtype (for example :func:`luma` of the albedo).

    Returns:
        float32 ``(H, W)``.
    """
    h, w, values = _cell_variances(plane, "block_variances")
    c = BLOCK_CELL
    out = np.zeros((-(-h // c) * c, -(-w // c) * c), np.float32)
    for k, value in enumerate(values):
        out[k // c::c, k % c::c] = value
    return out[:h, :w]


def _cell_variances(plane: np.ndarray, fn: str) -> tuple[int, int, np.ndarray]:
    """The plane's height and width and, per rate of :data:`BLOCK_RATES`, each 4x4 cell's normalised
    log variance inside the rate's blocks (float32 ``(6, ceil(H / 4), ceil(W / 4))``, rates in
    :data:`BLOCK_RATES` order): :func:`block_variances`'s values before packing. ``plane`` (the
    caller's array, never changed) is checked as ``fn``'s."""
    p = _finite_plane(plane, fn, None)
    h, w = p.shape
    c = BLOCK_CELL
    if h % c or w % c:
        p = np.pad(p, ((0, -h % c), (0, -w % c)), mode="edge")
    hc, wc = p.shape[0] // c, p.shape[1] // c
    # A rate's blocks, aligned to the cell, lose what the cell's Haar details finer than the block
    # hold. Per 2x2 quarter of the cell (pixels a, b in its top row, c, e under them), the details
    # h = (a - b) + (c - e), v = (a + b) - (c + e) and d = (a - b) - (c - e); over the quarters' sums, the same three at
    # twice the scale, H, V and D. The squared distance of the cell's 16 values to their blocks' means
    # is then: 1x2 (columns of two rows) (sum v^2 + sum d^2) / 4; 2x1 (sum h^2 + sum d^2) / 4; 2x2
    # (sum h^2 + v^2 + d^2) / 4; 2x4 that plus (V^2 + D^2) / 16; 4x2 plus (H^2 + D^2) / 16; 4x4
    # plus (H^2 + V^2 + D^2) / 16 (the sums over the four quarters; an orthogonal basis, so no
    # cancellation: a flat cell reads exactly 0). Divided by the cell's 16 pixels: the mean over the
    # cell of the variance inside each block. In float64, on the frame laid out as 16 planes, one
    # per pixel position in the cell (``x[i, j]``: row i, column j of every cell), in bands of cell
    # rows whose planes stay in the cache (every value is of one cell: the same values).
    cells = p.reshape(hc, c, wc, c).transpose(1, 3, 0, 2)
    values = np.empty((len(BLOCK_RATES), hc, wc), np.float32)
    band = max(1, _BAND_VALUES // wc)
    x = np.empty((c, c, min(band, hc), wc))
    rss = np.empty((len(BLOCK_RATES), min(band, hc), wc))
    for r0 in range(0, hc, band):
        r1 = min(hc, r0 + band)
        xb, r = x[:, :, :r1 - r0], rss[:, :r1 - r0]
        xb[...] = cells[:, :, r0:r1]
        pair_sum, pair_diff = xb[:, 0::2] + xb[:, 1::2], xb[:, 0::2] - xb[:, 1::2]  # columns in pairs
        hd, dd = pair_diff[0::2] + pair_diff[1::2], pair_diff[0::2] - pair_diff[1::2]  # (2, 2, rows, wc): quarters
        vd, sq = pair_sum[0::2] - pair_sum[1::2], pair_sum[0::2] + pair_sum[1::2]
        hs, vs, ds = (np.einsum("ij...,ij...->...", t, t) for t in (hd, vd, dd))
        lr = sq[:, 0] - sq[:, 1]  # left minus right quarter, per quarter row
        h2, d2 = np.square(lr[0] + lr[1]), np.square(lr[0] - lr[1])
        v2 = np.square((sq[0, 0] + sq[0, 1]) - (sq[1, 0] + sq[1, 1]))
        np.add(vs, ds, out=r[0])  # 1x2
        np.add(hs, ds, out=r[1])  # 2x1
        np.add(r[1], vs, out=r[2])  # 2x2
        np.multiply(r[2], 4.0, out=r[3])
        r[3] += d2
        r[4] = r[3]
        r[3] += v2  # 2x4
        r[4] += h2  # 4x2
        np.add(r[3], h2, out=r[5])  # 4x4
        r /= _CELL_DIVISORS
        r += BLOCK_EPS
        np.log(r, out=r)
        r /= -np.log(BLOCK_EPS)
        r += 1.0
        np.clip(r, 0.0, 1.0, out=r)
        values[:, r0:r1] = r
    return h, w, values


#: What each rate's squared distances (:func:`_cell_variances`) are divided by: the details' scale
#: (4 for the quarters' details, 16 for the cell's) times the cell's 16 pixels.
_CELL_DIVISORS = np.array([64.0, 64.0, 64.0, 256.0, 256.0, 256.0])[:, None, None]

#: Cells per band of :func:`_cell_variances` (its 16 float64 planes then take 1 MiB).
_BAND_VALUES = 8192


#: The tile :func:`tile_variances` summarises (the shipped models' tile size).
BLOCK_TILE = 16


def tile_variances(plane: np.ndarray) -> np.ndarray:
    """The ``.tiles`` plane of a plane: per 16x16 tile, each reduced rate's block variance over the
    tile's 4x4 cells, mean and maximum: the block contrast a split network's tail reads at tile
    resolution (``rtp.train.model.TileContrast``), so that neither the network nor a frame whose
    trunk features are carried touches a pixel plane at a finer resolution.

    With ``v`` the cell values of :func:`block_variances` (each rate's ``log(var + eps) / s + 1``,
    ``s = -log(eps)``, ``eps`` = :data:`BLOCK_EPS`; float32, as the ``.blocks`` plane stores them), per
    tile of :data:`BLOCK_TILE` pixels and rate ``k`` of :data:`BLOCK_RATES`: the mean
    ``log(mean over the tile's cells of exp(s (v - 1))) / s + 1`` (the log of the mean variance, in
    the same units) is written to value ``k`` and the maximum of ``v`` to value ``6 + k``; value ``j``
    (0 to 11) sits on pixel ``(j // 4, j % 4)`` of the tile (its first three rows, four columns), the
    tile's other pixels are 0. A partial last tile (a 1080-row frame has half a tile row at the
    bottom) summarises the cells it has; with sides that are multiples of 4 (every model's
    ``input_multiple``) all twelve values of every tile are inside the frame. Adapters that build
    the plane on a GPU follow this definition (the moderngl adapter's shader; tests compare).

    Args:
        plane: ``(H, W)`` values in [0, 1], any float dtype (for example :func:`luma` of the albedo).

    Returns:
        float32 ``(H, W)``.
    """
    h, w, values = _cell_variances(plane, "tile_variances")
    m = BLOCK_TILE // BLOCK_CELL  # cells per tile side
    n, ch, cw = values.shape
    th, tw = -(-ch // m), -(-cw // m)
    s = -np.log(BLOCK_EPS)
    out = np.zeros((th * BLOCK_TILE, tw * BLOCK_TILE), np.float32)
    count = np.zeros((th * m, tw * m))
    count[:ch, :cw] = 1.0
    cells = count.reshape(th, m, tw, m).sum(axis=(1, 3))  # per tile, the cells the frame holds
    padded = np.zeros((th * m, tw * m))  # beyond the frame: zeros, for every rate
    top = np.zeros((n, th * m, tw * m), np.float32)
    top[:, :ch, :cw] = values  # values are >= 0: a zero beyond the frame never wins the maximum
    peaks = _block_max(top, m)
    for k, v in enumerate(values):
        np.exp(s * (v.astype(np.float64) - 1.0), out=padded[:ch, :cw])  # variance + eps, from the stored value
        mean = padded.reshape(th, m, tw, m).sum(axis=(1, 3)) / cells
        for j, stat in ((k, np.log(mean) / s + 1.0), (n + k, peaks[k])):
            out[j // BLOCK_CELL::BLOCK_TILE, j % BLOCK_CELL::BLOCK_TILE] = stat
    return out[:h, :w]


def _block_max(a: np.ndarray, m: int) -> np.ndarray:
    """The maximum over each ``m x m`` block of the last two axes of ``a`` (sides multiples of ``m``), as
    elementwise maxima of strided views: a reduction over two short axes (``.max(axis=(-3, -1))`` of a
    reshape) takes ten times as long."""
    cols = a.reshape(*a.shape[:-1], a.shape[-1] // m, m)
    c = np.maximum(cols[..., 0], cols[..., 1])
    for i in range(2, m):
        np.maximum(c, cols[..., i], out=c)
    rows = c.reshape(*c.shape[:-2], c.shape[-2] // m, m, c.shape[-1])
    r = np.maximum(rows[..., 0, :], rows[..., 1, :])
    for i in range(2, m):
        np.maximum(r, rows[..., i, :], out=r)
    return r
