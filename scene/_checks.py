"""Checks of the scene model's fields: a bad value is a ``ParameterError`` naming the class and field
when the object is made, not a NaN matrix, a GL error or a black frame later."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from rtp.sdk import ParameterError


def _is_number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating))


def _finite(v: Any) -> bool:
    """A finite real number (an int past float's range is not: it has no float)."""
    try:
        return _is_number(v) and math.isfinite(float(v))
    except OverflowError:
        return False


def real(owner: str, name: str, v: Any, lo: float | None = None, hi: float | None = None, *,
         lo_open: bool = False, hi_open: bool = False) -> None:
    """``v`` is a finite number in the range given."""
    ok = _finite(v)
    if ok:
        x = float(v)
        ok = (lo is None or (x > lo if lo_open else x >= lo)) and (hi is None or (x < hi if hi_open else x <= hi))
    if not ok:
        lo_s = "" if lo is None else f"{'>' if lo_open else '>='} {lo:g}"
        hi_s = "" if hi is None else f"{'<' if hi_open else '<='} {hi:g}"
        rng = " and ".join(x for x in (lo_s, hi_s) if x)
        raise ParameterError(f"{owner}.{name}: expected a finite number{' ' + rng if rng else ''}, got {v!r}", name)


def vector(owner: str, name: str, v: Any, n: int, lo: float | None = None, hi: float | None = None) -> None:
    """``v`` is a sequence of ``n`` finite numbers in ``[lo, hi]``."""
    try:
        items = list(v)
    except TypeError:
        items = None
    if items is None or len(items) != n or not all(_finite(x) for x in items) or (
            lo is not None and min(float(x) for x in items) < lo) or (hi is not None and max(float(x) for x in items) > hi):
        bounds = "" if lo is None and hi is None else f" in [{'-inf' if lo is None else f'{lo:g}'}, " \
                                                      f"{'inf' if hi is None else f'{hi:g}'}]"
        raise ParameterError(f"{owner}.{name}: expected {n} finite numbers{bounds}, got {v!r}", name)


def array(owner: str, name: str, v: Any, columns: int, kinds: str, *, finite: bool = True,
          dtype: Any = None) -> np.ndarray:
    """``v`` as an ndarray ``(N, columns)`` whose dtype kind is one of ``kinds``, finite when asked; converted to
    ``dtype`` when given (a float past float32's range is then an infinity, and refused as one)."""
    try:
        a = np.asarray(v) if not isinstance(v, np.ndarray) else v
    except (TypeError, ValueError, OverflowError) as err:  # a ragged list
        raise ParameterError(f"{owner}.{name}: expected an array of shape (N, {columns}), got {type(v).__name__} "
                             f"({err})", name) from err
    if a.ndim != 2 or a.shape[1] != columns or a.dtype.kind not in kinds:
        what = {"f": "floats", "iu": "integers", "u": "unsigned integers"}.get(kinds, kinds)
        raise ParameterError(f"{owner}.{name}: expected an array of shape (N, {columns}) of {what}, got "
                             f"{a.dtype} {a.shape}", name)
    if dtype is not None and a.dtype != dtype:
        if finite and a.dtype.kind == "f" and a.size and not np.isfinite(a).all():
            raise ParameterError(f"{owner}.{name}: expected finite values, got NaN or infinity", name)
        with np.errstate(over="ignore"):
            a = a.astype(dtype)
        if finite and a.dtype.kind == "f" and a.size and not np.isfinite(a).all():
            raise ParameterError(f"{owner}.{name}: expected finite values within {np.dtype(dtype).name}'s range "
                                 f"(what the renderers draw with), got one past it", name)
    if finite and a.dtype.kind == "f" and a.size and not np.isfinite(a).all():
        raise ParameterError(f"{owner}.{name}: expected finite values, got NaN or infinity", name)
    return a
