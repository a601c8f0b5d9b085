"""Pinhole camera with the conventions of docs/architecture.md: right-handed view space looking down -Z,
Y up, images with a top-left origin. Matrices are numpy float64, column vectors (``p' = M @ p``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rtp.sdk import ParameterError

from ._checks import real, vector

__all__ = ["Camera"]


@dataclass(frozen=True)
class Camera:
    """A camera at ``position`` (metres) turned by ``yaw`` and ``pitch`` (degrees). Any real numbers are taken
    (numpy's included) and stored as Python floats, the position as a tuple.

    ``yaw = 0`` looks down world -Z; positive yaw turns left (counter-clockwise seen from above);
    positive pitch looks up. ``fov_y`` is the vertical field of view in degrees.
    """

    position: tuple[float, float, float]
    yaw: float = 0.0
    pitch: float = 0.0
    fov_y: float = 70.0
    near: float = 0.05
    far: float = 200.0

    def __post_init__(self) -> None:
        vector("Camera", "position", self.position, 3)
        real("Camera", "yaw", self.yaw)
        real("Camera", "pitch", self.pitch)
        real("Camera", "fov_y", self.fov_y, 0.0, 180.0, lo_open=True, hi_open=True)
        t = math.tan(math.radians(float(self.fov_y)) / 2.0)
        if not (t > 0.0 and math.isfinite(1.0 / t)):  # (5e-324 degrees: a ZeroDivisionError in projection())
            raise ParameterError(f"Camera.fov_y: expected a field of view whose projection is finite, got {self.fov_y!r} "
                                 "degrees", "fov_y")
        real("Camera", "near", self.near, 0.0, lo_open=True)
        real("Camera", "far", self.far, float(self.near), lo_open=True)
        # stored as Python floats, a tuple position: a frozen value (a list position could be changed in place), equal
        # and hashable (an ndarray position made == a ValueError and hash() a TypeError) and JSON-writable (numpy's
        # float32 is not)
        object.__setattr__(self, "position", tuple(float(x) for x in self.position))
        for key in ("yaw", "pitch", "fov_y", "near", "far"):
            object.__setattr__(self, key, float(getattr(self, key)))
        n, fa = self.near, self.far
        if not (math.isfinite(fa + n) and math.isfinite(2.0 * fa * n)):  # (near 1, far 1.7e308: a -inf projection)
            raise ParameterError(f"Camera.far: expected clip planes whose projection is finite, got near {self.near!r} "
                                 f"and far {self.far!r}", "far")

    @property
    def forward(self) -> np.ndarray:
        y, p = math.radians(self.yaw), math.radians(self.pitch)
        return np.array([-math.sin(y) * math.cos(p), math.sin(p), -math.cos(y) * math.cos(p)])

    def rotation(self) -> np.ndarray:
        """3x3 camera-to-world rotation: columns are the camera's right, up and back (+Z) axes."""
        f = self.forward
        # forward x world up, normalised: the yaw's horizontal right axis, mirrored when the pitch is past vertical
        # (|pitch| > 90 wraps over). From the yaw, not the cross product, which vanishes looking straight up or down:
        # a fixed world +X there lost the yaw (pitch -90 drew the same image whatever the yaw)
        y = math.radians(self.yaw)
        side = 1.0 if math.cos(math.radians(self.pitch)) >= 0.0 else -1.0
        right = side * np.array([math.cos(y), 0.0, -math.sin(y)])
        up = np.cross(right, f)
        return np.stack([right, up, -f], axis=1)

    def view(self) -> np.ndarray:
        """4x4 world-to-view matrix."""
        r = self.rotation()
        m = np.eye(4)
        m[:3, :3] = r.T
        m[:3, 3] = -r.T @ np.asarray(self.position, dtype=np.float64)
        return m

    def projection(self, aspect: float) -> np.ndarray:
        """4x4 OpenGL projection (clip z in [-w, w]) for ``aspect = width / height``."""
        real("Camera.projection", "aspect", aspect, 0.0, lo_open=True)  # (0 was a ZeroDivisionError)
        f = 1.0 / math.tan(math.radians(self.fov_y) / 2.0)
        n, fa = self.near, self.far
        m = np.zeros((4, 4))
        m[0, 0] = f / aspect
        if not math.isfinite(m[0, 0]):  # (an aspect of 5e-324 gave an infinite matrix)
            raise ParameterError(f"Camera.projection.aspect: expected a width / height whose projection is finite, got "
                                 f"{aspect!r} (fov_y {self.fov_y!r})", "aspect")
        m[1, 1] = f
        m[2, 2] = (fa + n) / (n - fa)
        m[2, 3] = 2.0 * fa * n / (n - fa)
        m[3, 2] = -1.0
        return m

    def view_projection(self, width: int, height: int) -> np.ndarray:
        real("Camera.view_projection", "width", width, 0.0, lo_open=True)
        real("Camera.view_projection", "height", height, 0.0, lo_open=True)
        return self.projection(width / height) @ self.view()
