"""LDR-FLIP for one reference against many test images, reference work done once (torch, CPU).

A line-for-line port of the separable LDR-FLIP of NVIDIA's C++ implementation (``FLIP.h`` 1.7,
BSD-3-Clause, the code inside ``flip-evaluator``): the same colour transforms, the same separated
spatial (YCx and two Cz Gaussians) and feature (Gaussian, first and second derivative) filters with
clamp-to-edge borders, the same Hunt / HyAB / error redistribution and feature weighting, all in
float32. What differs is only the order of work: the reference's filtered colours and its edge and
point magnitudes are computed once per frame, and the six reduced rates of a sample go through the
filters as one batch, as shifted multiply-adds in torch. ``tests/test_metrics.py`` checks it against
``flip_evaluator.evaluate``: on rendered 1280x720 frames the maps agree to about 2e-5 per pixel (mean
4e-7); where a feature difference is near zero its square root amplifies float32 round-off to a
few 1e-4 on single pixels (NVIDIA's own implementations differ the same way: misc/precision.md).

:func:`rtp.metrics.flip_map` keeps calling ``flip-evaluator`` itself; ``tile_targets`` uses this
port when torch is installed (``rtp[metrics]``) because it is several times faster per sample.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np

__all__ = ["FlipReference"]

_PI = np.float32(3.14159265358979)
# xFLIPConstants
_QC, _PC, _PT, _GW, _QF = 0.7, 0.4, 0.95, 0.082, 0.5
# xGaussianConstants (a1, b1 for Y, Cx, Cz; a2, b2 for the second Cz Gaussian)
_A1 = (1.0, 1.0, 34.1)
_B1 = (0.0047, 0.0053, 0.04)
_A2 = (0.0, 0.0, 13.5)
_B2 = (1.0e-5, 1.0e-5, 0.025)
_ILLUMINANT_INV = (1.052156925, 1.000000000, 0.918357670)
_ILLUMINANT = (0.950428545, 1.000000000, 1.088900371)
_RGB2XYZ = np.array([
    [10135552.0 / 24577794.0, 8788810.0 / 24577794.0, 4435075.0 / 24577794.0],
    [2613072.0 / 12288897.0, 8788810.0 / 12288897.0, 887015.0 / 12288897.0],
    [1425312.0 / 73733382.0, 8788810.0 / 73733382.0, 70074185.0 / 73733382.0],
], dtype=np.float32)
_XYZ2RGB = np.array([
    [3.241003275, -1.537398934, -0.498615861],
    [-0.969224334, 1.875930071, 0.041554224],
    [0.055639423, -0.204011202, 1.057148933],
], dtype=np.float32)


def _gauss_alt(x2: np.ndarray, a: float, b: float) -> np.ndarray:
    return (np.float32(a) * np.sqrt(_PI / np.float32(b)) * np.exp(-(_PI * _PI) * x2 / np.float32(b))).astype(np.float32)


def _gauss_sqrt(x2: np.ndarray, a: float, b: float) -> np.ndarray:
    return (np.sqrt(np.float32(a) * np.sqrt(_PI / np.float32(b))) * np.exp(-(_PI * _PI) * x2 / np.float32(b))).astype(
        np.float32)


@functools.lru_cache(maxsize=8)
def _spatial_filters(ppd: float) -> tuple[np.ndarray, np.ndarray]:
    """(Y, Cx) and (Cz1, Cz2) separated filters, each ``(2, 2r + 1)`` (``setSpatialFilters``)."""
    max_b = max(*_B1, *_B2)
    radius = int(math.ceil(np.float32(3.0) * np.sqrt(np.float32(max_b) / (np.float32(2.0) * _PI * _PI)) * np.float32(ppd)))
    x = ((np.arange(2 * radius + 1) - radius) * (np.float32(1.0) / np.float32(ppd))).astype(np.float32)
    x2 = x * x
    ycx = np.stack([_gauss_alt(x2, _A1[0], _B1[0]), _gauss_alt(x2, _A1[1], _B1[1])])
    cz = np.stack([_gauss_sqrt(x2, _A1[2], _B1[2]), _gauss_sqrt(x2, _A2[2], _B2[2])])
    ycx = ycx / ycx.sum(axis=1, keepdims=True)
    sums = cz.sum(axis=1)
    cz = cz / np.sqrt(sums[0] * sums[0] + sums[1] * sums[1])
    return ycx.astype(np.float32), cz.astype(np.float32)


@functools.lru_cache(maxsize=8)
def _feature_filter(ppd: float) -> np.ndarray:
    """Gaussian, first and second derivative, ``(3, 2r + 1)``, normalised as ``setFeatureFilter``."""
    sd = np.float32(0.5) * np.float32(_GW) * np.float32(ppd)
    radius = int(math.ceil(np.float32(3.0) * sd))
    xx = (np.arange(2 * radius + 1) - radius).astype(np.float32)
    g = np.exp(-(xx * xx) / (np.float32(2.0) * sd * sd)).astype(np.float32)
    dg = -xx * g
    ddg = (xx * xx / (sd * sd) - np.float32(1.0)) * g
    g = g / g.sum()
    # (below 1.7 ppd dg's taps are all 0: NaN, as FLIP.h's; near 1.7 the positive taps are subnormal and the
    # branch np.where discards overflows: a RuntimeWarning for the values it never uses)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        dg = np.where(dg > 0, dg / dg[dg > 0].sum(), dg / -dg[dg < 0].sum())
        ddg = np.where(ddg > 0, ddg / ddg[ddg > 0].sum(), ddg / -ddg[ddg < 0].sum())
    return np.stack([g, dg, ddg]).astype(np.float32)


def _lab_hunt_np(rgb: np.ndarray) -> np.ndarray:
    xyz = rgb @ _RGB2XYZ.T
    xyz = xyz * np.array(_ILLUMINANT_INV, np.float32)
    delta = np.float32(6.0 / 29.0)
    cube = delta * delta * delta
    f = np.where(xyz > cube, np.cbrt(xyz), xyz / (3 * delta * delta) + np.float32(4.0 / 29.0))
    lum = 116 * f[..., 1] - 16
    a = 500 * (f[..., 0] - f[..., 1])
    b = 200 * (f[..., 1] - f[..., 2])
    return np.stack([lum, 0.01 * lum * a, 0.01 * lum * b], -1).astype(np.float32)


@functools.lru_cache(maxsize=1)
def _cmax() -> float:
    green, blue = _lab_hunt_np(np.array([0, 1, 0], np.float32)), _lab_hunt_np(np.array([0, 0, 1], np.float32))
    hyab = abs(green[0] - blue[0]) + math.sqrt(float((green[1] - blue[1]) ** 2 + (green[2] - blue[2]) ** 2))
    return float(np.float32(hyab) ** np.float32(_QC))


class FlipReference:
    """LDR-FLIP of many test images against one reference, the reference's half computed once.

    ``FlipReference(reference, ppd).maps(tests)`` returns the ``(N, H, W)`` float32 LDR-FLIP maps of
    ``tests`` ``(N, H, W, 3)`` against ``reference`` ``(H, W, 3)``, both display-encoded sRGB floats
    (clamped to [0, 1] like ``flip-evaluator``). Needs torch. ``device`` (a ``torch.device``; default
    the CPU) is where the filtering runs: the arrays go there and the maps come back as numpy.
    """

    def __init__(self, reference: np.ndarray, ppd: float, device: Any = None) -> None:
        import torch

        self._torch = torch
        self.device = torch.device("cpu") if device is None else device
        self.ppd = float(ppd)
        ycx, cz = _spatial_filters(self.ppd)
        feat = _feature_filter(self.ppd)
        self._ycx = torch.from_numpy(ycx)
        self._cz = torch.from_numpy(cz)
        self._feat = torch.from_numpy(feat)
        self.shape = tuple(reference.shape[:2])
        ycxcz = self._ycxcz(torch.from_numpy(np.ascontiguousarray(reference, np.float32))[None].to(self.device))
        with torch.inference_mode():
            self._lab = self._filtered_lab(ycxcz)
            self._edge, self._point = self._features(ycxcz[0])

    # -- colour transforms (FLIP.h color3), on planes (N, H, W) ------------------------------------
    def _ycxcz(self, srgb: Any) -> list[Any]:
        """(N, H, W, 3) sRGB -> [Y, Cx, Cz] planes (clamp, linearise, clamp, XYZ, YCxCz)."""
        torch = self._torch
        s = srgb.permute(0, 3, 1, 2).clamp(0.0, 1.0)  # one planar copy
        lin = torch.where(s <= 0.04045, s / 12.92, torch.pow((s + 0.055) / 1.055, 2.4)).clamp_(0.0, 1.0)
        x, y, z = _mat3(_RGB2XYZ, lin[:, 0], lin[:, 1], lin[:, 2])
        x, z = x * _ILLUMINANT_INV[0], z * _ILLUMINANT_INV[2]
        return [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]

    def _conv(self, planes: list[tuple[Any, Any]], axis: str) -> list[Any]:
        """Correlate each plane (N, H, W) with its 1-D filter (K,) along ``axis`` ("x" or "y"),
        clamp-to-edge borders, taps summed in FLIP.h's order. Shifted multiply-adds: several times
        faster on a CPU than torch's depthwise convolution."""
        torch = self._torch
        out = []
        for plane, weights in planes:
            taps = weights.tolist()
            k = len(taps)
            r = k // 2
            if axis == "x":
                n = plane.shape[-1]
                xp = torch.nn.functional.pad(plane[:, None], (r, r, 0, 0), mode="replicate")[:, 0]
                acc = torch.mul(xp[..., 0:n], taps[0])
                for i in range(1, k):
                    acc.add_(xp[..., i:i + n], alpha=taps[i])
            else:
                n = plane.shape[-2]
                xp = torch.nn.functional.pad(plane[:, None], (0, 0, r, r), mode="replicate")[:, 0]
                acc = torch.mul(xp[..., 0:n, :], taps[0])
                for i in range(1, k):
                    acc.add_(xp[..., i:i + n, :], alpha=taps[i])
            out.append(acc)
        return out

    def _filtered_lab(self, ycxcz: list[Any]) -> list[Any]:
        """Spatially filtered colours in Hunt-adjusted CIELab, [L, a, b] planes (``computeColorDifference``)."""
        torch = self._torch
        y, cx, cz = ycxcz
        filters = [self._ycx[0], self._ycx[1], self._cz[0], self._cz[1]]
        first = self._conv(list(zip([y, cx, cz, cz], filters)), "x")
        fy, fcx, fcz1, fcz2 = self._conv(list(zip(first, filters)), "y")
        fcz = fcz1.add_(fcz2)
        # YCxCz -> XYZ -> linear RGB, clamp, -> XYZ -> CIELab, Hunt.
        yy = (fy + 16.0) / 116.0
        x = (yy + fcx / 500.0) * _ILLUMINANT[0]
        z = (yy - fcz / 200.0) * _ILLUMINANT[2]
        rgb = [c.clamp_(0.0, 1.0) for c in _mat3(_XYZ2RGB, x, yy, z)]
        x, yy, z = _mat3(_RGB2XYZ, *rgb)
        x, z = x * _ILLUMINANT_INV[0], z * _ILLUMINANT_INV[2]
        delta = 6.0 / 29.0

        def f(t: Any) -> Any:
            return torch.where(t > delta ** 3, torch.pow(t, 1.0 / 3.0), t / (3.0 * delta * delta) + 4.0 / 29.0)

        fx, fyy, fz = f(x), f(yy), f(z)
        lum = 116.0 * fyy - 16.0
        return [lum, 0.01 * lum * (500.0 * (fx - fyy)), 0.01 * lum * (200.0 * (fyy - fz))]

    def _features(self, y: Any) -> tuple[Any, Any]:
        """Edge and point magnitudes of the Y plane (N, H, W) (``computeFeatureDifferenceAndFinalError``)."""
        torch = self._torch
        yn = y * (1.0 / 116.0) + 16.0 / 116.0
        g, dg, ddg = self._feat[0], self._feat[1], self._feat[2]
        dx, ddx, gx = self._conv([(yn, dg), (yn, ddg), (yn, g)], "x")
        dx, ddx, dy, ddy = self._conv([(dx, g), (ddx, g), (gx, dg), (gx, ddg)], "y")
        return torch.sqrt(dx * dx + dy * dy), torch.sqrt(ddx * ddx + ddy * ddy)

    def maps(self, tests: np.ndarray) -> np.ndarray:
        """LDR-FLIP maps ``(N, H, W)`` float32 of ``tests`` ``(N, H, W, 3)`` against the reference."""
        torch = self._torch
        if tests.ndim != 4 or tuple(tests.shape[1:3]) != self.shape or tests.shape[3] != 3:
            raise ValueError(f"tests must be (N, {self.shape[0]}, {self.shape[1]}, 3), got {tests.shape}")
        cmax = _cmax()
        pccmax = _PC * cmax
        with torch.inference_mode():
            t = self._ycxcz(torch.from_numpy(np.ascontiguousarray(tests, np.float32)).to(self.device))
            lab = self._filtered_lab(t)
            dl, da, db = (a - b for a, b in zip(lab, self._lab))
            color = torch.pow(dl.abs_() + torch.sqrt(da * da + db * db), _QC)
            color = torch.where(color < pccmax, color * (_PT / pccmax),
                                _PT + ((color - pccmax) / (cmax - pccmax)) * (1.0 - _PT))
            edge, point = self._features(t[0])
            # FLIP.h's Max(edge, point), `edge > point ? edge : point`: below 1.7 ppd the edge filter's
            # taps underflow to 0/0 and the edge difference is NaN, which that macro drops (the point
            # difference stands) where torch.maximum propagated it (all-NaN maps).
            e, p = (self._edge - edge).abs_(), (self._point - point).abs_()
            feature = torch.where(e > p, e, p)
            feature = torch.pow(feature.mul_(1.0 / math.sqrt(2.0)), _QF)
            return torch.pow(color, 1.0 - feature).cpu().numpy().astype(np.float32, copy=False)


def _mat3(m: np.ndarray, a: Any, b: Any, c: Any) -> list[Any]:
    """``m @ (a, b, c)`` on planes, row by row (FLIP.h's order of terms)."""
    return [a * float(row[0]) + b * float(row[1]) + c * float(row[2]) for row in m]
