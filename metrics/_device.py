"""Where rtp's torch work runs: the metrics' FLIP port and LPIPS network, and training.

``auto`` is the first CUDA GPU torch sees, else Apple's ``mps``, else the CPU; ``cpu``, ``cuda``,
``cuda:N`` and ``mps`` name one. A device this torch cannot use is refused, saying why, before any
work. torch is imported when a name is resolved, not with this module (the metrics run without it).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from ._errors import MetricParameterError

if TYPE_CHECKING:  # (for a type checker only: importing rtp.metrics never imports torch)
    import torch

__all__ = ["DEVICES", "device_name", "full_float32", "resolve_device"]

#: The device names :func:`resolve_device` takes (``cuda:N`` too).
DEVICES = ("auto", "cpu", "cuda", "mps")


def resolve_device(name: str, what: str = "device") -> torch.device:
    """The ``torch.device`` ``name`` names, once torch can run there (module docstring): else a
    :class:`MetricParameterError` (a :class:`rtp.sdk.ParameterError`) naming ``what`` and why (the
    CPU build of torch, no driver, ``cuda:3`` on a machine of two)."""
    import torch

    if not isinstance(name, str):
        raise MetricParameterError(f"{what}: expected a device name ({', '.join(DEVICES)} or cuda:N), got "
                                   f"{type(name).__name__}", what)
    if name == "auto":
        if torch.cuda.is_available():
            return torch.device("cuda", 0)
        mps = getattr(torch.backends, "mps", None)
        return torch.device("mps") if mps is not None and mps.is_available() else torch.device("cpu")
    try:
        dev = torch.device(name)
    except (RuntimeError, ValueError):
        dev = None
    if dev is None or dev.type not in DEVICES or (dev.type != "cuda" and dev.index not in (None, 0)):
        raise MetricParameterError(f"{what}: expected {', '.join(DEVICES)} or cuda:N, got {name!r}", what)
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            why = (f"torch {torch.__version__} is a CPU build" if torch.version.cuda is None else
                   f"torch {torch.__version__} (CUDA {torch.version.cuda}) sees no CUDA device (the driver, or "
                   f"CUDA_VISIBLE_DEVICES)")
            raise MetricParameterError(f"{what} {name!r}: {why}; use device cpu (or auto: a GPU where there is one)",
                                       what)
        count = torch.cuda.device_count()
        if (dev.index or 0) >= count:
            raise MetricParameterError(f"{what} {name!r}: torch sees {count} CUDA device{'s' if count > 1 else ''} "
                                       f"(cuda:0{f' to cuda:{count - 1}' if count > 1 else ''})", what)
        return torch.device("cuda", dev.index or 0)
    if dev.type == "mps":
        mps = getattr(torch.backends, "mps", None)
        if mps is None or not mps.is_available():
            raise MetricParameterError(f"{what} {name!r}: torch {torch.__version__} cannot use Apple's Metal (mps) "
                                       f"here; use device cpu or auto", what)
    return torch.device(dev.type)


def device_name(dev: torch.device) -> str:
    """A ``torch.device`` as logs and provenance name it: ``cuda:0 (NVIDIA H200)``, ``cpu``."""
    import torch

    return f"{dev} ({torch.cuda.get_device_name(dev)})" if dev.type == "cuda" else str(dev)


@contextlib.contextmanager
def full_float32(dev: Any) -> Iterator[None]:
    """On CUDA, convolutions and matrix products in full float32 while it lasts (torch's settings before
    are restored): cuDNN's TF32 kernels, on by default for convolutions on Ampere and later GPUs, round
    the inputs to 10 bits of mantissa, which moved LPIPS targets by up to 5e-4 from the CPU's on an H200
    (2e-6 without them). Elsewhere nothing changes."""
    if getattr(dev, "type", None) != "cuda":
        yield
        return
    import torch

    before = torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32
    torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = False
    try:
        yield
    finally:
        torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = before
