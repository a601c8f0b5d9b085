"""Image validation, layout conversion and luma.

The primary layout is numpy ``(H, W, 3)`` float32 (also ``(N, H, W, 3)``), display-encoded sRGB in
[0, 1], top-left origin. torch tensors ``(3, H, W)`` / ``(N, 3, H, W)`` are accepted as a
convenience: they are copied to numpy (no gradients) and results come back as torch tensors on the
input's device.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from rtp.sdk import InputChannelError, InputDtypeError, InputShapeError, NonFiniteInputError

from ._errors import InputRangeError

__all__ = ["RANGE_TOLERANCE", "ImageBatch", "as_batch", "as_pair"]

#: Values within this distance outside [0, 1] are clipped silently (float16 round-off); anything
#: further out raises :class:`~rtp.metrics.InputRangeError`.
RANGE_TOLERANCE = 1e-6


def _is_torch(x: object) -> bool:
    torch = sys.modules.get("torch")
    return torch is not None and isinstance(x, torch.Tensor)


@dataclass(frozen=True)
class ImageBatch:
    """Validated images as a C-contiguous float32 ``(N, H, W, 3)`` array plus how to return results.

    ``batched`` is False when the caller passed a single image (results drop the N axis);
    ``device`` is the torch device of a torch input, None for numpy input.
    """

    data: np.ndarray
    batched: bool
    device: Any = None

    @property
    def shape_hw(self) -> tuple[int, int]:
        return int(self.data.shape[1]), int(self.data.shape[2])

    def wrap(self, values: np.ndarray) -> Any:
        """Return per-image results ``(N, ...)`` in the caller's container, dropping N if unbatched."""
        values = np.ascontiguousarray(values, dtype=np.float32)
        if not self.batched:
            values = values[0]
        if self.device is not None:
            import torch

            return torch.from_numpy(values).to(self.device)
        return values


def as_batch(x: Any, name: str = "image", *, check_range: bool = True) -> ImageBatch:
    """Validate one image or a batch and convert it to float32 ``(N, H, W, 3)``.

    Accepts numpy ``(H, W, 3)`` / ``(N, H, W, 3)`` or torch ``(3, H, W)`` / ``(N, 3, H, W)``, any
    floating dtype, values in [0, 1]. Raises :class:`~rtp.sdk.InputDtypeError` for integer, bool or
    non-array input (uint8 images must be divided by 255 first), :class:`~rtp.sdk.InputShapeError` /
    :class:`~rtp.sdk.InputChannelError` for a wrong layout, :class:`~rtp.sdk.NonFiniteInputError` for
    NaN/inf and :class:`~rtp.metrics.InputRangeError` for values outside [0, 1].
    """
    device = None
    if _is_torch(x):
        import torch

        if not torch.is_floating_point(x):
            raise InputDtypeError(
                f"{name}: expected a floating-point tensor with values in [0, 1], got dtype {x.dtype}"
                + (" (divide 8-bit images by 255)" if x.dtype == torch.uint8 else "")
            )
        if x.ndim not in (3, 4):
            raise InputShapeError(
                f"{name}: expected a torch tensor (3, H, W) or (N, 3, H, W), got shape {tuple(x.shape)}",
                actual=tuple(x.shape),
                expected="(N, 3, H, W)",
            )
        batched = x.ndim == 4
        t = x if batched else x.unsqueeze(0)
        if t.shape[1] != 3:
            raise InputChannelError(
                f"{name}: expected 3 channels (RGB) on axis 1 of an NCHW tensor, got shape {tuple(x.shape)}",
                actual=tuple(x.shape),
                expected="(N, 3, H, W)",
            )
        device = x.device
        arr = t.detach().to(device="cpu", dtype=torch.float32).permute(0, 2, 3, 1).contiguous().numpy()
    elif isinstance(x, np.ndarray):
        if not np.issubdtype(x.dtype, np.floating):
            raise InputDtypeError(
                f"{name}: expected a floating-point array with values in [0, 1], got dtype {x.dtype}"
                + (" (divide 8-bit images by 255)" if x.dtype == np.uint8 else "")
            )
        if x.ndim not in (3, 4):
            raise InputShapeError(
                f"{name}: expected a numpy array (H, W, 3) or (N, H, W, 3), got shape {x.shape}",
                actual=tuple(x.shape),
                expected="(H, W, 3)",
            )
        if x.shape[-1] != 3:
            raise InputChannelError(
                f"{name}: expected 3 channels (RGB) on the last axis, got shape {x.shape}",
                actual=tuple(x.shape),
                expected="(H, W, 3)",
            )
        batched = x.ndim == 4
        with np.errstate(over="ignore"):  # (float64 values past float32's range: refused below, saying so)
            arr = np.ascontiguousarray(x if batched else x[None], dtype=np.float32)
        if not arr.flags.writeable:  # (a read-only float32 frame, np.frombuffer of a GPU readback or a memory-mapped
            # .npy, is this view: flip_evaluator refused it, "flip_evaluator failed: incompatible function arguments")
            arr = arr.copy()
    else:
        raise InputDtypeError(f"{name}: expected a numpy array or torch tensor, got {type(x).__name__}")
    if arr.shape[0] == 0 or arr.shape[1] == 0 or arr.shape[2] == 0:
        raise InputShapeError(f"{name}: empty image, shape {arr.shape}", actual=tuple(arr.shape), expected="H, W >= 1")
    if not np.isfinite(arr).all():
        if check_range and _all_finite(x):  # (1e300 in float64 is finite: the float32 copy made it infinite)
            lo, hi = float(x.min()), float(x.max())
            raise InputRangeError(f"{name}: expected display-encoded values in [0, 1], got [{lo:g}, {hi:g}]",
                                  low=lo, high=hi)
        raise NonFiniteInputError(f"{name}: contains NaN or infinite values")
    if check_range:
        lo, hi = float(arr.min()), float(arr.max())
        if lo < -RANGE_TOLERANCE or hi > 1.0 + RANGE_TOLERANCE:
            raise InputRangeError(
                f"{name}: expected display-encoded values in [0, 1], got [{lo:g}, {hi:g}]"
                + (" (8-bit data? divide by 255)" if hi > 1.5 else ""),
                low=lo,
                high=hi,
            )
        if lo < 0.0 or hi > 1.0:
            arr = np.clip(arr, 0.0, 1.0)
    return ImageBatch(arr, batched, device)


def _all_finite(x: Any) -> bool:
    """Whether the caller's array or tensor (before the float32 copy) holds only finite values."""
    if _is_torch(x):
        import torch

        return bool(torch.isfinite(x).all())
    return bool(np.isfinite(x).all())


def as_pair(reference: Any, test: Any) -> tuple[ImageBatch, ImageBatch]:
    """Validate a reference/test pair; both must have the same layout and shape."""
    ref = as_batch(reference, "reference")
    tst = as_batch(test, "test")
    if ref.data.shape != tst.data.shape or ref.batched != tst.batched:
        raise InputShapeError(
            f"reference and test differ in shape: {_shape(reference)} vs {_shape(test)}",
            actual=_shape(test),
            expected=str(_shape(reference)),
        )
    return ref, tst


def _shape(x: Any) -> tuple[int, ...]:
    return tuple(int(s) for s in x.shape)

