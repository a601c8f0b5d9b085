"""Procedural, tileable textures generated with numpy.

Every generator returns an ``(size, size, 4)`` uint8 sRGB image (alpha 255 unless stated) that
tiles seamlessly (all periods divide ``size``), so the renderer can use REPEAT wrapping and
mipmaps. Colours are sRGB-encoded, like the textures of real assets. Randomness comes only from
the ``numpy.random.Generator`` passed in, so the same generator state gives identical pixels.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["TEXTURE_KINDS", "bricks", "checker", "fbm", "make_texture", "stripes", "tiles", "value_noise"]

Colour = tuple[float, float, float]


def _to_rgba8(rgb: np.ndarray, alpha: np.ndarray | None = None) -> np.ndarray:
    """Float sRGB ``(H, W, 3)`` in [0, 1] (and optional alpha) → uint8 RGBA."""
    h, w, _ = rgb.shape
    out = np.empty((h, w, 4), np.uint8)
    out[..., :3] = np.clip(rgb * 255.0 + 0.5, 0, 255).astype(np.uint8)
    out[..., 3] = 255 if alpha is None else np.clip(alpha * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return out


def _mix(a: Colour, b: Colour, t: np.ndarray) -> np.ndarray:
    """Blend two colours by a scalar field ``t`` (H, W) → (H, W, 3)."""
    a_ = np.asarray(a, np.float32)
    b_ = np.asarray(b, np.float32)
    return a_ + (b_ - a_) * t[..., None]


def value_noise(rng: np.random.Generator, size: int, cells: int) -> np.ndarray:
    """Tileable value noise in [0, 1]: random values on a ``cells`` x ``cells`` lattice, smoothstep-
    interpolated with wrap-around. ``cells`` must divide ``size``."""
    lattice = rng.random((cells, cells), dtype=np.float32)
    coords = (np.arange(size, dtype=np.float32) + 0.5) * (cells / size) - 0.5
    i0 = np.floor(coords).astype(np.int64)
    f = coords - i0
    f = f * f * (3.0 - 2.0 * f)
    i0 %= cells
    i1 = (i0 + 1) % cells
    # rows (y) then columns (x)
    top = lattice[i0][:, i0] * (1 - f)[None, :] + lattice[i0][:, i1] * f[None, :]
    bot = lattice[i1][:, i0] * (1 - f)[None, :] + lattice[i1][:, i1] * f[None, :]
    return (top * (1 - f)[:, None] + bot * f[:, None]).astype(np.float32)


def fbm(rng: np.random.Generator, size: int, base_cells: int = 4, octaves: int = 5, gain: float = 0.5) -> np.ndarray:
    """Fractal sum of value-noise octaves (cells doubling each octave), normalised to [0, 1]."""
    total = np.zeros((size, size), np.float32)
    amp, norm, cells = 1.0, 0.0, base_cells
    for _ in range(octaves):
        if cells > size:
            break
        total += amp * value_noise(rng, size, cells)
        norm += amp
        amp *= gain
        cells *= 2
    total /= norm
    lo, hi = float(total.min()), float(total.max())
    return (total - lo) / max(hi - lo, 1e-6)


def checker(rng: np.random.Generator, size: int, a: Colour, b: Colour, squares: int = 8) -> np.ndarray:
    """Checkerboard of ``squares`` x ``squares`` cells with a little noise."""
    idx = (np.arange(size) * squares // size)
    t = ((idx[:, None] + idx[None, :]) % 2).astype(np.float32)
    rgb = _mix(a, b, t) * (0.9 + 0.1 * fbm(rng, size, 8, 3))[..., None]
    return _to_rgba8(rgb)


def stripes(rng: np.random.Generator, size: int, a: Colour, b: Colour, count: int = 8) -> np.ndarray:
    """Soft horizontal bands (wood/painted-metal look) with a noise warp."""
    y = np.arange(size, dtype=np.float32)[:, None] / size
    warp = fbm(rng, size, 4, 3) - 0.5
    t = 0.5 + 0.5 * np.sin(2 * np.pi * (count * y + 0.6 * warp))
    rgb = _mix(a, b, t) * (0.85 + 0.15 * fbm(rng, size, 16, 3))[..., None]
    return _to_rgba8(rgb)


def bricks(
    rng: np.random.Generator, size: int, brick: Colour, mortar: Colour, rows: int = 8, cols: int = 4
) -> np.ndarray:
    """Running-bond bricks with per-brick tint, mortar joints and surface noise."""
    y = np.arange(size)[:, None]
    x = np.arange(size)[None, :]
    bh, bw = size // rows, size // cols
    row = y // bh
    xs = (x + (row % 2) * (bw // 2)) % size
    col = xs // bw
    jy, jx = y % bh, xs % bw
    joint = max(1, size // 128)
    is_mortar = (jy < joint) | (jx < joint)
    tint = rng.uniform(0.75, 1.15, (rows, cols)).astype(np.float32)
    shade = tint[row % rows, col % cols]
    noise = fbm(rng, size, 16, 4)
    rgb = np.asarray(brick, np.float32) * (shade * (0.8 + 0.3 * noise))[..., None]
    rgb = np.where(is_mortar[..., None], np.asarray(mortar, np.float32) * (0.85 + 0.3 * noise)[..., None], rgb)
    return _to_rgba8(rgb)


def tiles(rng: np.random.Generator, size: int, a: Colour, b: Colour, count: int = 4) -> np.ndarray:
    """Square floor tiles, each a random blend of ``a`` and ``b``, with grout lines."""
    n = size // count
    y = np.arange(size)[:, None]
    x = np.arange(size)[None, :]
    tv = rng.random((count, count), dtype=np.float32)
    t = tv[y // n, x // n]
    grout = max(2, size // 64)
    is_grout = ((y % n) < grout) | ((x % n) < grout)
    rgb = _mix(a, b, t) * (0.9 + 0.15 * fbm(rng, size, 8, 4))[..., None]
    rgb = np.where(is_grout[..., None], np.float32(0.25) * rgb, rgb)
    return _to_rgba8(rgb)


def noise_texture(rng: np.random.Generator, size: int, a: Colour, b: Colour) -> np.ndarray:
    """Plaster/stone: an fbm blend of two colours."""
    return _to_rgba8(_mix(a, b, fbm(rng, size, 4, 6)))


def grate(rng: np.random.Generator, size: int, a: Colour, b: Colour, holes: int = 8) -> np.ndarray:
    """A metal grate: square holes with alpha 0 (for alpha testing), bars with alpha 255."""
    n = size // holes
    y = np.arange(size)[:, None] % n
    x = np.arange(size)[None, :] % n
    bar = max(2, n // 4)
    solid = (y < bar) | (x < bar)
    rgb = _mix(a, b, fbm(rng, size, 8, 4))
    return _to_rgba8(rgb, solid.astype(np.float32))


TEXTURE_KINDS: dict[str, Callable[..., np.ndarray]] = {
    "checker": checker,
    "stripes": stripes,
    "bricks": bricks,
    "tiles": tiles,
    "noise": noise_texture,
    "grate": grate,
}


def make_texture(kind: str, rng: np.random.Generator, size: int, a: Colour, b: Colour) -> np.ndarray:
    """Build one texture of ``kind`` (a key of :data:`TEXTURE_KINDS`) from two palette colours."""
    try:
        fn = TEXTURE_KINDS[kind]
    except KeyError:
        raise ValueError(f"unknown texture kind {kind!r}; expected one of {sorted(TEXTURE_KINDS)}") from None
    if size < 16 or size & (size - 1):
        raise ValueError(f"texture size must be a power of two >= 16, got {size}")
    return fn(rng, size, a, b)
