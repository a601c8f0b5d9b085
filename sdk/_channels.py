"""Named model input channels: the one definition every adapter, the capture driver and the
metadata validator share.

A model's metadata lists its inputs by these names, in the order the network expects them. An
adapter builds exactly those planes, in that order, as float32 ``(C, H, W)`` with a top-left
origin. Value conventions are fixed here so that training inputs and deployment inputs cannot
drift apart.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CHANNELS", "DEFAULT_INPUTS", "Channel"]


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
    ("seen", 0.0, 1.0, "1 where the reprojected position is on the previous frame and passes its depth test, else 0"),
    ("albedo.r", 0.0, 1.0, "surface base colour, display-encoded sRGB, red; 0 on background"),
    ("albedo.g", 0.0, 1.0, "as albedo.r, green"),
    ("albedo.b", 0.0, 1.0, "as albedo.r, blue"),
    ("normal.x", -1.0, 1.0, "view-space unit normal x (right-handed view space, camera looks down -z); 0 on background"),
    ("normal.y", -1.0, 1.0, "view-space unit normal y"),
    ("normal.z", -1.0, 1.0, "view-space unit normal z; > 0 faces the camera"),
    ("roughness", 0.0, 1.0, "GGX perceptual roughness"),
    ("metallic", 0.0, 1.0, "metalness"),
    ("specular", 0.0, 1.0, "dielectric specular reflectance scale (0.5 = F0 of 4%)"),
    ("shadow", 0.0, 1.0, "main-light shadow-map visibility, 1 = lit"),
    ("emissive", 0.0, 1.0, "emissive luminance, display-encoded"),
    ("depth", 0.0, float("inf"), "linear view depth in scene units (distance along -z); 0 on background"),
    ("motion.x", float("-inf"), float("inf"), "screen motion in pixels, previous minus current position, x to the right"),
    ("motion.y", float("-inf"), float("inf"), "screen motion in pixels, previous minus current position, y down"),
]

#: Every known input channel, by name.
CHANNELS: dict[str, Channel] = {name: Channel(name, lo, hi, desc) for name, lo, hi, desc in _SPECS}

#: The paper's recommended 4-channel input (Section 3.2, Table 1).
DEFAULT_INPUTS: tuple[str, ...] = ("reprojected.r", "seen", "albedo.r", "normal.z")
