"""SSIM as an rtp metric plugin: the structural dissimilarity ``(1 - SSIM) / 2`` of the frames' luma, per
pixel, averaged over each tile.

SSIM (Wang, Bovik, Sheikh and Simoncelli 2004, "Image quality assessment: from error visibility to
structural similarity") with the paper's constants: an 11x11 Gaussian window of standard deviation 1.5
(sampled, normalised), ``C1 = (0.01 L)^2``, ``C2 = (0.03 L)^2``, ``L = 1``; on Rec. 601 luma of the
display-encoded frames (``rtp.sdk.luma``), the image edges mirrored. A similarity (1 on equal frames) is
not an error, so the map is ``(1 - SSIM) / 2`` in [0, 1]: 0 where the frames agree. SSIM is a mean over
the image in its paper, so the tiles pool by their mean.

Installed, it is the metric ``ssim`` of every rtp command (docs/metrics.md "Your own metric")::

    pip install -e examples/metric_plugin
    rtp weights list                       # ssim ... ready (plugin: rtp_ssim)
    rtp targets data/train --metrics ssim
    rtp train --data data/train --metric ssim --out ssim.pt
"""

from __future__ import annotations

import numpy as np

from rtp.metrics import Metric
from rtp.sdk import luma

__all__ = ["SSIM", "ssim_map", "dssim_map"]

#: The paper's window: 11 taps of a Gaussian of standard deviation 1.5.
SIGMA, RADIUS = 1.5, 5
C1, C2 = 0.01**2, 0.03**2
_TAPS = np.exp(-0.5 * (np.arange(-RADIUS, RADIUS + 1) / SIGMA) ** 2)
_TAPS /= _TAPS.sum()


def _blur(a: np.ndarray) -> np.ndarray:
    """The separable Gaussian window over an ``(H, W)`` float64 map, its edges mirrored (same size out)."""
    h, w = a.shape
    p = np.pad(a, RADIUS, mode="symmetric")
    rows = sum(k * p[:, i:i + w] for i, k in enumerate(_TAPS))
    return np.asarray(sum(k * rows[i:i + h, :] for i, k in enumerate(_TAPS)))  # (sum() is typed Any)


def ssim_map(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
    """Per-pixel SSIM of two ``(H, W, 3)`` frames in [0, 1] (their luma), float64 ``(H, W)``, 1 where equal."""
    x, y = (luma(np.asarray(f)).astype(np.float64) for f in (reference, test))
    mx, my = _blur(x), _blur(y)
    sxx, syy, sxy = _blur(x * x) - mx * mx, _blur(y * y) - my * my, _blur(x * y) - mx * my
    return np.asarray(((2 * mx * my + C1) * (2 * sxy + C2)) / ((mx * mx + my * my + C1) * (sxx + syy + C2)))


def dssim_map(reference: np.ndarray, test: np.ndarray) -> np.ndarray:
    """``(1 - SSIM) / 2`` per pixel, in [0, 1], float32: the error map rtp trains a network to predict."""
    return np.clip((1.0 - ssim_map(reference, test)) / 2.0, 0.0, 1.0).astype(np.float32)


#: The plugin: the entry point ``ssim = "rtp_ssim:SSIM"`` in the group ``rtp.metrics`` (pyproject.toml).
SSIM = Metric(
    name="ssim",
    error_map=dssim_map,
    default_threshold=0.03,
    pooling="mean",
    units="DSSIM",
    description="structural dissimilarity (1 - SSIM) / 2 of the luma, Gaussian window 11 x 1.5, mean over the tile",
    params={"version": 1, "window": 2 * RADIUS + 1, "sigma": SIGMA},
)
