"""Small mesh and texture builders (boxes, quads, spheres, checkers) for tests, benchmarks and
hand-made scenes. Output follows the :mod:`._scene` contract: float32 positions/normals/uvs,
uint32 counter-clockwise triangles, top-left uvs."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from rtp.sdk import ParameterError

from ._checks import real, vector
from ._model import Mesh

__all__ = ["box_mesh", "checker_texture", "quad_mesh", "sphere_mesh"]


def _mesh(pos: Any, nrm: Any, uv: Any, idx: Any, material: int) -> Mesh:
    return Mesh(
        positions=np.asarray(pos, np.float32).reshape(-1, 3),
        normals=np.asarray(nrm, np.float32).reshape(-1, 3),
        uvs=np.asarray(uv, np.float32).reshape(-1, 2),
        indices=np.asarray(idx, np.uint32).reshape(-1, 3),
        material=material,
    )


def quad_mesh(
    centre: Sequence[float],
    u_axis: Sequence[float],
    v_axis: Sequence[float],
    material: int = 0,
    uv_scale: tuple[float, float] = (1.0, 1.0),
) -> Mesh:
    """A parallelogram ``centre +- u_axis +- v_axis`` (half extents). The front face (normal
    ``u x v``) is counter-clockwise; uv (0, 0) is at ``centre - u_axis + v_axis`` (top-left when
    seen from the front with v pointing up)."""
    for name, value in (("centre", centre), ("u_axis", u_axis), ("v_axis", v_axis)):
        vector("quad_mesh", name, value, 3)
    vector("quad_mesh", "uv_scale", uv_scale, 2)  # (a string or 3 numbers were numpy's ValueError)
    c, u, v = (np.asarray(a, np.float64) for a in (centre, u_axis, v_axis))
    n = np.cross(u, v)
    if not np.linalg.norm(n) > 0:
        raise ParameterError(f"quad_mesh: u_axis and v_axis must span a plane, got {u_axis!r} and {v_axis!r}", "v_axis")
    n = n / np.linalg.norm(n)
    pos = [c - u + v, c - u - v, c + u - v, c + u + v]
    su, sv = uv_scale
    uv = [(0, 0), (0, sv), (su, sv), (su, 0)]
    return _mesh(pos, [n] * 4, uv, [0, 1, 2, 0, 2, 3], material)


def box_mesh(lo: Sequence[float], hi: Sequence[float], material: int = 0, uv_per_metre: float = 1.0) -> Mesh:
    """An axis-aligned box with flat outward normals (24 vertices, 12 triangles): ``hi`` above ``lo`` on every axis."""
    vector("box_mesh", "lo", lo, 3)
    vector("box_mesh", "hi", hi, 3)
    real("box_mesh", "uv_per_metre", uv_per_metre, 0.0, lo_open=True)
    lo_, hi_ = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if not (hi_ > lo_).all():  # (a negative extent turned every face inwards; a zero one is no box)
        raise ParameterError(f"box_mesh: expected hi above lo on every axis, got lo {tuple(lo)} and hi {tuple(hi)}", "hi")
    c, e = (lo_ + hi_) / 2, (hi_ - lo_) / 2
    x, y, z = np.eye(3)
    faces = [  # (normal, u axis, v axis) with u x v = normal
        (x, -z, y), (-x, z, y), (y, x, -z), (-y, x, z), (z, x, y), (-z, -x, y),
    ]
    pos: list[np.ndarray] = []
    nrm: list[np.ndarray] = []
    uv: list[tuple[float, float]] = []
    idx: list[int] = []
    for n, u, v in faces:
        fc = c + n * e
        hu, hv = u * e, v * e
        su, sv = 2 * np.abs(hu).sum() * uv_per_metre, 2 * np.abs(hv).sum() * uv_per_metre
        base = len(pos)
        pos += [fc - hu + hv, fc - hu - hv, fc + hu - hv, fc + hu + hv]
        nrm += [n] * 4
        uv += [(0, 0), (0, sv), (su, sv), (su, 0)]
        idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return _mesh(pos, nrm, uv, idx, material)


def sphere_mesh(centre: Sequence[float], radius: float, material: int = 0, segments: int = 32, rings: int = 16) -> Mesh:
    """A UV sphere with smooth outward normals: ``radius`` > 0, at least 3 ``segments`` around and 2 ``rings``."""
    vector("sphere_mesh", "centre", centre, 3)
    real("sphere_mesh", "radius", radius, 0.0, lo_open=True)  # (a negative one turned the normals inwards)
    for name, count, least in (("segments", segments, 3), ("rings", rings, 2)):
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < least:
            raise ParameterError(f"sphere_mesh.{name}: expected an integer >= {least}, got {count!r}", name)
    th = np.linspace(0.0, np.pi, rings + 1)
    ph = np.linspace(0.0, 2 * np.pi, segments + 1)
    t, p = np.meshgrid(th, ph, indexing="ij")
    n = np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], axis=-1).reshape(-1, 3)
    uv = np.stack([p / (2 * np.pi), t / np.pi], axis=-1).reshape(-1, 2)
    pos = np.asarray(centre, np.float64) + radius * n
    idx: list[int] = []
    for i in range(rings):
        for j in range(segments):
            a, b = i * (segments + 1) + j, (i + 1) * (segments + 1) + j
            idx += [a, b, b + 1, a, b + 1, a + 1]
    return _mesh(pos, n, uv, idx, material)


def checker_texture(
    size: int = 64,
    cells: int = 8,
    a: Sequence[int] = (230, 230, 230),
    b: Sequence[int] = (40, 40, 40),
    alpha_holes: bool = False,
) -> np.ndarray:
    """An ``(size, size, 4)`` uint8 sRGB checkerboard of ``cells`` x ``cells`` cells (1 to ``size``); with
    ``alpha_holes`` every other dark cell has alpha 0 (for alpha-test tests). ``a``, ``b``: the two cells' RGB,
    integers in [0, 255]."""
    for name, count in (("size", size), ("cells", cells)):
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
            raise ParameterError(f"checker_texture.{name}: expected an integer >= 1, got {count!r}", name)
    if cells > size:  # (a cell narrower than a pixel: 8 cells over 4 pixels drew one plain colour, no checkers)
        raise ParameterError(f"checker_texture.cells: expected at most size ({size}) cells, got {cells!r}", "cells")
    for name, colour in (("a", a), ("b", b)):
        vector("checker_texture", name, colour, 3, 0, 255)
        if any(float(c) != int(c) for c in colour):  # (0.5 was drawn as 0: a colour in [0, 1] read as bytes)
            raise ParameterError(f"checker_texture.{name}: expected integers in [0, 255] (8-bit sRGB), got "
                                 f"{tuple(colour)!r}", name)
    if not isinstance(alpha_holes, (bool, np.bool_)):  # ("no" was taken for True)
        raise ParameterError(f"checker_texture.alpha_holes: expected True or False, got {alpha_holes!r}", "alpha_holes")
    y, x = np.mgrid[0:size, 0:size] * cells // size
    odd = (x + y) % 2 == 1
    img = np.empty((size, size, 4), np.uint8)
    img[..., :3] = np.where(odd[..., None], np.asarray(b, np.uint8), np.asarray(a, np.uint8))
    img[..., 3] = 255
    if alpha_holes:
        img[..., 3] = np.where(odd & (x % 2 == 0), 0, 255)
    return img
