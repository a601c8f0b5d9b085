"""LDR-FLIP through NVIDIA's ``flip-evaluator`` package (BSD-3-Clause).

The wrapper validates everything ``flip_evaluator.evaluate`` would mishandle: it treats uint8
arrays as 0..255 without complaint and calls ``sys.exit(1)`` on bad arguments. Inputs here are float
images in [0, 1]; the result is the raw per-pixel LDR-FLIP map (``applyMagma=False``).
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np

from ._errors import MetricDependencyError, MetricError, MetricParameterError
from ._image import as_pair

if TYPE_CHECKING:  # (for a type checker only: importing rtp.metrics never imports torch)
    from torch import Tensor

__all__ = ["DEFAULT_PPD", "FLIP_DEFAULT_PPD", "PPD_METRICS", "Ppd", "flip_map", "ppd_from_width", "resolve_ppd"]

log = logging.getLogger("rtp.metrics")

#: FLIP's own default: a 0.7 m wide 3840-pixel display seen from 0.7 m, 67.02 pixels per degree
#: (the float32 value ``flip_evaluator`` reports).
FLIP_DEFAULT_PPD = 67.02064514160156
#: rtp's default pixels per degree: FLIP's standard viewing condition. It does not depend on the
#: image size, so crops and different capture resolutions are scored alike. Pass ``ppd="width"``
#: for the RT-Percept paper's width-based value (33.5 at 1920 pixels wide).
DEFAULT_PPD = FLIP_DEFAULT_PPD

#: The metrics that take FLIP's pixels per degree, ``ppd`` (the rest ignore it).
PPD_METRICS = ("flip", "jnflip")

Ppd = float | Literal["width"]


def ppd_from_width(width_px: int, monitor_width_m: float = 0.7, distance_m: float = 0.7) -> float:
    """Pixels per degree of a ``width_px`` wide image shown full width on a monitor.

    ``distance_m * (width_px / monitor_width_m) * pi / 180``. With the defaults (the RT-Percept
    paper's 0.7 m monitor at 0.7 m) this is ``width_px * pi / 180``: 33.51 at 1920, 22.34 at 1280.
    For crops pass the width of the full frame, not of the crop.
    """
    numbers = (width_px, monitor_width_m, distance_m)
    # (NaN passed `<= 0` and gave a NaN ppd; an infinity gave inf or 0)
    if not all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
               and (isinstance(v, (int, np.integer)) or math.isfinite(v)) for v in numbers) \
            or width_px <= 0 or monitor_width_m <= 0 or distance_m <= 0:
        raise MetricParameterError(
            f"ppd_from_width needs positive arguments, got width_px={width_px}, "
            f"monitor_width_m={monitor_width_m}, distance_m={distance_m}"
        )
    try:
        return float(distance_m * (width_px / monitor_width_m) * math.pi / 180.0)
    except OverflowError:  # (an int past float's range)
        raise MetricParameterError(f"ppd_from_width: width_px={width_px!r} is past any screen") from None


#: The pixels per degree FLIP takes: a viewer from very far to a phone held at the nose (its filters'
#: kernels grow with the value; outside the range they fill memory, or turn the maps to NaN).
MIN_PPD, MAX_PPD = 1.0, 1000.0


def resolve_ppd(ppd: Ppd, width_px: int) -> float:
    """Turn a ``ppd`` argument into a number: a positive float as is, ``"width"`` via :func:`ppd_from_width`."""
    if isinstance(ppd, str):
        if ppd != "width":
            raise MetricParameterError(f"ppd must be a positive number or 'width', got {ppd!r}")
        return ppd_from_width(width_px)
    if isinstance(ppd, (bool, np.bool_)):
        raise MetricParameterError(f"ppd must be a positive number or 'width', got {ppd!r}")
    try:
        value = float(ppd)
    except (TypeError, ValueError, OverflowError):  # (OverflowError: an int past float's range)
        raise MetricParameterError(f"ppd must be a positive number or 'width', got {ppd!r}") from None
    if not math.isfinite(value) or not MIN_PPD <= value <= MAX_PPD:
        # (1e10 made the filters' kernels grow until the process was killed; 1e-10 gave NaN maps)
        raise MetricParameterError(f"ppd must be a number of pixels per degree in [{MIN_PPD:g}, {MAX_PPD:g}] (FLIP's "
                                   f"default {DEFAULT_PPD:.2f}), got {ppd!r}")
    return value


def image_ppd(ppd: Ppd, width_px: int, option: str = "ppd") -> float:
    """:func:`resolve_ppd` for an image ``width_px`` wide that FLIP will score: ``"width"`` must give a
    value in FLIP's range too (an image under 58 pixels wide is under 1 ppd: the torch port's targets
    were NaN). (``resolve_ppd(ppd, 1)`` stays the check of the argument alone.)

    ``option`` is the name the caller's user gives the argument, which the error is worded in: ``"ppd"``
    (Python's, the default) or a command-line flag (``"--ppd"``: ``rtp metric``, ``rtp targets``)."""
    value = resolve_ppd(ppd, width_px)
    if isinstance(ppd, str) and not MIN_PPD <= value <= MAX_PPD:
        found = (f"of a {width_px}-pixel-wide image is {value:.3g} pixels per degree, outside FLIP's "
                 f"[{MIN_PPD:g}, {MAX_PPD:g}]")
        if option == "ppd":
            raise MetricParameterError(f"ppd='width' {found}: for a crop pass ppd=ppd_from_width(the full frame's "
                                       f"width), or a number", "ppd")
        raise MetricParameterError(f"{option} width {found}: give {option} a number instead (for a crop of a wider "
                                   f"frame, that frame's width-based value, rtp.metrics.ppd_from_width(its width))",
                                   "ppd")
    return value


def _flip_module() -> Any:
    try:
        import flip_evaluator
    except ImportError as exc:
        from ._deps import install_hint  # (not above: _deps imports this module)

        raise MetricDependencyError(f"FLIP needs NVIDIA's flip-evaluator package: {install_hint('flip-evaluator')}") \
            from exc
    return flip_evaluator


def flip_pixels(reference: np.ndarray, test: np.ndarray, ppd: float) -> np.ndarray:
    """LDR-FLIP map of one validated pair: float32 ``(H, W, 3)`` in [0, 1] -> ``(H, W)`` float32 in [0, 1]."""
    flip = _flip_module()
    # (C-contiguous and writable: flip_evaluator's binding refuses a read-only array, as a TypeError of its own)
    ref = np.require(reference, np.float32, ["C", "W"])
    tst = np.require(test, np.float32, ["C", "W"])
    try:
        emap, _, _ = flip.evaluate(
            ref, tst, "LDR", inputsRGB=True, applyMagma=False, computeMeanError=False, parameters={"ppd": float(ppd)}
        )
    except SystemExit as exc:  # flip_evaluator exits the interpreter on bad arguments
        raise MetricError(f"flip_evaluator rejected its arguments (sys.exit({exc.code})); ppd={ppd}") from None
    except Exception as exc:
        raise MetricError(f"flip_evaluator failed: {exc}") from exc
    emap = np.asarray(emap, dtype=np.float32)
    if emap.shape[:2] != ref.shape[:2]:
        raise MetricError(f"flip_evaluator returned a map of shape {emap.shape} for images of shape {ref.shape}")
    return emap.reshape(ref.shape[:2])


@overload
def flip_map(reference: np.ndarray, test: np.ndarray | Tensor, *, ppd: Ppd = ...) -> np.ndarray: ...
@overload
def flip_map(reference: Tensor, test: np.ndarray | Tensor, *, ppd: Ppd = ...) -> Tensor: ...
def flip_map(reference: Any, test: Any, *, ppd: Ppd = DEFAULT_PPD) -> Any:
    """Per-pixel LDR-FLIP error between a reference and a test image (Andersson et al. 2020).

    Args:
        reference: the 1x1-rate image, display-encoded sRGB in [0, 1]: numpy ``(H, W, 3)`` /
            ``(N, H, W, 3)`` or torch ``(3, H, W)`` / ``(N, 3, H, W)``, any float dtype.
        test: the reduced-rate image, same layout and shape.
        ppd: pixels per degree of visual angle, > 0, or ``"width"`` for the paper's
            ``W * pi / 180`` computed from the image width. Default :data:`DEFAULT_PPD` (67.02).

    Returns:
        ``(H, W)`` (or ``(N, H, W)``) float32 in [0, 1], 0 where the images agree; numpy or torch
        like the input.
    """
    ref, tst = as_pair(reference, test)
    value = image_ppd(ppd, ref.shape_hw[1])
    log.debug("FLIP on %d image(s) of %dx%d at %.3f ppd", ref.data.shape[0], ref.shape_hw[1], ref.shape_hw[0], value)
    maps = np.stack([flip_pixels(r, t, value) for r, t in zip(ref.data, tst.data)])
    return ref.wrap(maps)
