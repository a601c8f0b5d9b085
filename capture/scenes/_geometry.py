"""Geometry helpers shared by the scene sources: a per-material triangle builder with primitives
(quads, boxes, cylinders, spheres) and small mesh utilities.

Conventions (those of ``rtp.scene``): right-handed world, Y up, metres;
triangles are counter-clockwise seen from the side their normal points to; texture coordinates
have a top-left origin (v grows downwards), with world-space planar mapping so textures keep a
constant texel density and tile (the renderer wraps with REPEAT).
"""

from __future__ import annotations

import numpy as np

from rtp.scene import Mesh

__all__ = ["MeshBuilder", "face_normals", "vertex_normals"]

_UP = np.array([0.0, 1.0, 0.0])


def face_normals(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Unnormalised (area-weighted) face normals ``(M, 3)`` of CCW triangles."""
    p = positions[indices]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def vertex_normals(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals; vertices without faces get +Y."""
    fn = face_normals(positions.astype(np.float64), indices)
    vn = np.zeros((len(positions), 3))
    for k in range(3):
        np.add.at(vn, indices[:, k], fn)
    n = np.linalg.norm(vn, axis=1, keepdims=True)
    out = np.where(n > 1e-12, vn / np.maximum(n, 1e-12), _UP)
    return out.astype(np.float32)


class MeshBuilder:
    """Accumulates triangles per material index and emits one :class:`Mesh` per material."""

    def __init__(self, texel_metres: float = 2.0) -> None:
        self.texel_metres = texel_metres  # one texture repeat per this many metres
        self._parts: dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = {}

    def add(self, material: int, positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray, indices: np.ndarray) -> None:
        self._parts.setdefault(material, []).append(
            (
                np.asarray(positions, np.float32),
                np.asarray(normals, np.float32),
                np.asarray(uvs, np.float32),
                np.asarray(indices, np.int64),
            )
        )

    # -- primitives ---------------------------------------------------------------------------

    def quad(self, material: int, origin, u, v, uv_origin: tuple[float, float] | None = None) -> None:
        """Parallelogram ``origin + s*u + t*v`` (s, t in [0, 1]); the normal is ``u x v`` and the
        quad is CCW seen from it. ``u`` maps to texture +u, ``v`` to texture -v (so when ``v``
        points up, the image is upright)."""
        o, u_, v_ = (np.asarray(a, np.float64) for a in (origin, u, v))
        n = np.cross(u_, v_)
        ln = np.linalg.norm(n)
        if ln < 1e-12:
            return
        n /= ln
        pos = np.stack([o, o + u_, o + u_ + v_, o + v_])
        lu, lv = np.linalg.norm(u_), np.linalg.norm(v_)
        if uv_origin is None:
            # world-anchored planar mapping: project the origin on the quad's own axes
            uv_origin = (float(o @ (u_ / lu)), float(o @ (v_ / lv)))
        s0, t0 = uv_origin[0] / self.texel_metres, uv_origin[1] / self.texel_metres
        su, sv = lu / self.texel_metres, lv / self.texel_metres
        uv = np.array([[s0, -t0], [s0 + su, -t0], [s0 + su, -t0 - sv], [s0, -t0 - sv]])
        self.add(material, pos, np.tile(n, (4, 1)), uv, np.array([[0, 1, 2], [0, 2, 3]]))

    def box(self, material: int, lo, hi, skip: tuple[str, ...] = ()) -> None:
        """Axis-aligned box with outward faces; ``skip`` names faces to leave out
        (``"-x" "+x" "-y" "+y" "-z" "+z"``)."""
        x0, y0, z0 = (float(a) for a in lo)
        x1, y1, z1 = (float(a) for a in hi)
        if x1 - x0 <= 0 or y1 - y0 <= 0 or z1 - z0 <= 0:
            return
        dx, dy, dz = np.array([x1 - x0, 0, 0]), np.array([0, y1 - y0, 0]), np.array([0, 0, z1 - z0])
        faces = {
            "+z": ((x0, y0, z1), dx, dy),
            "-z": ((x1, y0, z0), -dx, dy),
            "+x": ((x1, y0, z1), -dz, dy),
            "-x": ((x0, y0, z0), dz, dy),
            "+y": ((x0, y1, z1), dx, -dz),
            "-y": ((x0, y0, z0), dx, dz),
        }
        for key, (o, u, v) in faces.items():
            if key not in skip:
                self.quad(material, o, u, v)

    def cylinder(self, material: int, centre, radius: float, height: float, segments: int = 24) -> None:
        """Vertical cylinder standing on ``centre`` (base centre) with caps."""
        cx, cy, cz = (float(a) for a in centre)
        a = np.linspace(0.0, 2 * np.pi, segments + 1)
        ring = np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], axis=1)  # CCW seen from +Y
        bottom = ring * radius + [cx, cy, cz]
        top = bottom + [0, height, 0]
        pos = np.concatenate([bottom, top])
        nrm = np.concatenate([ring, ring])
        circ = 2 * np.pi * radius / self.texel_metres
        u = a / (2 * np.pi) * max(1.0, round(circ))
        uv = np.concatenate(
            [np.stack([u, np.full_like(u, 0.0)], 1), np.stack([u, np.full_like(u, -height / self.texel_metres)], 1)]
        )
        i = np.arange(segments)
        m = segments + 1
        idx = np.concatenate([np.stack([i, i + 1, i + 1 + m], 1), np.stack([i, i + 1 + m, i + m], 1)])
        self.add(material, pos, nrm, uv, idx)
        for y, sign in ((cy + height, 1.0), (cy, -1.0)):
            c = np.array([[cx, y, cz]])
            rim = ring * radius + [cx, y, cz]
            p = np.concatenate([c, rim])
            n = np.tile([0.0, sign, 0.0], (len(p), 1))
            uvc = (p[:, [0, 2]] - [cx, cz]) / self.texel_metres
            tri = np.stack([np.zeros(segments, int), i + 1, i + 2], 1)
            if sign > 0:
                tri = tri[:, [0, 1, 2]]  # ring is CCW seen from +Y
            else:
                tri = tri[:, [0, 2, 1]]
            self.add(material, p, n, uvc, tri)

    def sphere(self, material: int, centre, radius: float, rings: int = 16, segments: int = 32) -> None:
        """UV sphere; u wraps once around, v runs from the north pole (v = 0) to the south pole."""
        th = np.linspace(0.0, np.pi, rings + 1)  # polar angle from +Y
        ph = np.linspace(0.0, 2 * np.pi, segments + 1)
        T, P = np.meshgrid(th, ph, indexing="ij")
        n = np.stack([np.sin(T) * np.sin(P), np.cos(T), np.sin(T) * np.cos(P)], -1).reshape(-1, 3)
        pos = n * radius + np.asarray(centre, np.float64)
        uv = np.stack([P / (2 * np.pi) * 2.0, T / np.pi], -1).reshape(-1, 2)
        r, s = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
        a = (r * (segments + 1) + s).ravel()
        b = a + segments + 1
        idx = np.concatenate([np.stack([a, b, b + 1], 1), np.stack([a, b + 1, a + 1], 1)])
        # drop the degenerate triangles at the poles
        p = pos[idx]
        area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        self.add(material, pos, n, uv, idx[area > 1e-10])

    # -- output -------------------------------------------------------------------------------

    def meshes(self) -> list[Mesh]:
        """One mesh per material (in material order), vertices and indices concatenated."""
        out: list[Mesh] = []
        for mat in sorted(self._parts):
            parts = self._parts[mat]
            offs = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
            out.append(
                Mesh(
                    positions=np.concatenate([p[0] for p in parts]).astype(np.float32),
                    normals=np.concatenate([p[1] for p in parts]).astype(np.float32),
                    uvs=np.concatenate([p[2] for p in parts]).astype(np.float32),
                    indices=np.concatenate([p[3] + o for p, o in zip(parts, offs)]).astype(np.uint32),
                    material=mat,
                )
            )
        return out
