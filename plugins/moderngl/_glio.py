"""GL <-> image plumbing: the ONE place where rows are flipped.

OpenGL textures have a bottom-left origin; every array this package hands out or takes in has a
top-left origin (docs/architecture.md). :func:`flip_rows` flips when reading a texture back
(:func:`read_texture`) and when uploading an image into a texture (:func:`write_texture`); :func:`read_planes`
flips inside its one copy of a framebuffer's planes (the adapter's read-back).
Material textures are not flipped: their row 0 is v = 0 and is uploaded first, so ``texture(t, uv)``
with top-left uvs samples the right texel.
"""

from __future__ import annotations

import logging
import os
import threading
from typing import Any

import numpy as np

__all__ = ["CurrentCheck", "flip_rows", "is_released", "max_texture_side", "read_planes", "read_texture",
           "warn_not_freed", "write_texture"]

#: What a texture's bytes hold, by moderngl dtype: floats, integers, and the normalised (UNORM / SNORM) formats, which
#: an engine's G-buffers use (an RGBA8 frame, RGBA16 SNORM normals) and the adapter reads.
_DTYPES = {"f1": np.uint8, "f2": np.float16, "f4": np.float32, "nu1": np.uint8, "nu2": np.uint16, "ni1": np.int8,
           "ni2": np.int16, "u1": np.uint8, "u2": np.uint16, "u4": np.uint32, "i1": np.int8, "i2": np.int16,
           "i4": np.int32}
#: The normalised dtypes: GL maps their integers to floats by dividing by the largest (a SNORM's most negative
#: integer is -1 as well).
_NORMALISED = {"f1": 255.0, "nu1": 255.0, "nu2": 65535.0, "ni1": 127.0, "ni2": 32767.0}  # (the largest integer)


def is_released(obj: Any) -> bool:
    """Whether a moderngl object (a context) has been released: moderngl swaps its native object for
    an ``InvalidObject``, whose every attribute is then missing."""
    return type(getattr(obj, "mglo", None)).__name__ == "InvalidObject"


class CurrentCheck:
    """Whether a moderngl context is current in the calling thread, checked where a call comes from another thread
    than the last (the same thread costs one comparison: ``if threading.get_ident() != check.thread: check()``).

    A GL context is current in one thread at a time, and moderngl's ``ctx.__enter__()`` does not say when the driver
    refused it (EGL, while another thread holds it): the calls then ran in no context (or in the one that thread
    had) and read back another object's bytes, uninitialised memory or zeros, in silence, or failed as a bare
    ``moderngl.Error``. A small buffer of random bytes that only this context holds tells: read back in the calling
    thread, it is those bytes only where the context is the one current there. ``owner`` names the object in the
    :class:`RendererError`, ``state`` says what went wrong and ``advice`` how to hand the context over.
    Made in the thread where ``ctx`` is current (else that error)."""

    def __init__(self, ctx: Any, owner: str, state: str, advice: str) -> None:
        import moderngl

        self._owner, self._state, self._advice = owner, state, advice
        self._magic = os.urandom(16)
        self.thread: int | None = None
        self._buffer: Any = None
        try:
            self._buffer = ctx.buffer(self._magic)
        except moderngl.Error as exc:  # ("cannot create buffer": no context current in this thread)
            raise self.error() from exc
        self.thread = threading.get_ident()

    def error(self) -> Exception:
        """The :class:`RendererError` of a call from a thread where the context is not current."""
        from ._renderer import RendererError  # (here: _renderer imports this module)

        return RendererError(f"{self._owner}: its moderngl context {self._state} in this thread (thread "
                             f"{threading.current_thread().name!r}): a GL context is current in one thread at a time, "
                             f"and the driver refuses it to a second while the first holds it. {self._advice}")

    def holds(self) -> bool:
        """Whether the context is the one current in the calling thread, read back whatever thread called last (a
        close checks it: one read, once)."""
        try:
            return bool(self._buffer.read() == self._magic)
        except Exception:  # (moderngl.Error "cannot map the buffer": no context current in this thread)
            return False

    def __call__(self) -> None:
        """Raise :meth:`error` unless the context is current in the calling thread; else remember the thread."""
        if not self.holds():
            raise self.error()
        self.thread = threading.get_ident()

    def release(self) -> None:
        """Free the buffer (in the context, which must be current)."""
        if self._buffer is not None:
            self._buffer.release()
            self._buffer = None


def warn_not_freed(owner: str, objects: str, advice: str) -> None:
    """Say (a warning on the ``rtp.plugins.moderngl`` logger) that ``owner`` was closed in a thread where its context is
    not current, so that its GL ``objects`` were not freed. Freeing them there would delete nothing (no context
    current) or the objects of the same names in the context current there (an engine's own textures and buffers).
    Not raised: a close runs in a ``with`` block's exit and after an error, whose exception a refusal would hide."""
    logging.getLogger("rtp.plugins.moderngl").warning(
        "%s closed in thread %r, where its moderngl context is not current: its %s were not freed (in this thread "
        "they would have been another context's, or none); they stay in the context until it is released. %s",
        owner, threading.current_thread().name, objects, advice)


def max_texture_side(ctx: Any) -> int:
    """The largest texture or render-target side ``ctx`` takes: ``GL_MAX_TEXTURE_SIZE`` and
    ``GL_MAX_RENDERBUFFER_SIZE``, the smaller. Past it moderngl makes an unusable object (a GL error it
    does not check) or the driver aborts, so every size is checked against it first."""
    return min(int(ctx.info["GL_MAX_TEXTURE_SIZE"]), int(ctx.info["GL_MAX_RENDERBUFFER_SIZE"]))


def flip_rows(image: np.ndarray, dtype: Any = None) -> np.ndarray:
    """Swap the row order (GL bottom-left origin <-> image top-left origin), contiguous copy (converted
    to ``dtype`` in the same pass when given)."""
    return np.array(image[::-1], dtype=dtype, order="C")


def read_texture(texture: Any, components: int | None = None, size: tuple[int, int] | None = None) -> np.ndarray:
    """Read a moderngl texture to a float32 ``(H, W, C)`` array with a top-left origin.

    ``components`` keeps the first C channels (default: all); ``size = (W, H)`` only the texture's bottom-left
    ``W`` x ``H`` corner (a frame drawn with a viewport at the origin; default: all). Normalised textures (``f1``,
    ``nu1``, ``nu2``; ``ni1``, ``ni2``) are scaled to [0, 1] (signed: [-1, 1]) as GL's samplers read them; an
    integer texture's values are given as they are.
    """
    w, h = texture.size
    dtype = _DTYPES[texture.dtype]
    raw = np.frombuffer(texture.read(alignment=1), dtype=dtype)
    arr = raw.reshape(h, w, texture.components)
    if size is not None:
        arr = arr[: size[1], : size[0]]  # (GL rows: the first are the bottom ones)
    if components is not None:
        arr = arr[..., :components]
    out = flip_rows(arr, np.float32)  # one pass: the flip and float16's widening (read back on every frame)
    if texture.dtype in _NORMALISED:
        out /= np.float32(_NORMALISED[texture.dtype])
        if texture.dtype.startswith("ni"):
            np.maximum(out, np.float32(-1.0), out=out)
    return out


def read_planes(framebuffer: Any, count: int, size: tuple[int, int]) -> np.ndarray:
    """The first ``count`` planes of ``framebuffer``'s RGBA float32 colour attachments (four an attachment, in
    order) in its bottom-left ``size = (W, H)`` corner, as a C-contiguous float32 ``(count, H, W)`` array with a
    top-left origin: each plane one strided copy from what GL hands back, the flip and the interleaved-to-planar
    transpose in the same pass (flipping, joining the attachments and transposing one after the other took five
    times as long: ``python bench/adapter.py``)."""
    w, h = size
    out = np.empty((count, h, w), np.float32)
    for i in range(-(-count // 4)):
        raw = framebuffer.read(viewport=(0, 0, w, h), components=4, attachment=i, dtype="f4", alignment=1)
        rgba = np.frombuffer(raw, np.float32).reshape(h, w, 4)[::-1]
        n = min(4, count - 4 * i)
        out[4 * i : 4 * i + n] = rgba[..., :n].transpose(2, 0, 1)
    return out


def write_texture(texture: Any, image: np.ndarray) -> None:
    """Upload a top-left-origin ``(H, W[, C])`` image into a texture of the same size, its values converted to the
    texture's storage (the integers of a normalised texture: ``uint8`` for ``f1`` and ``nu1``, and so on)."""
    w, h = texture.size
    arr = np.asarray(image)
    if arr.ndim == 2:
        arr = arr[..., None]
    if arr.shape != (h, w, texture.components):
        raise ValueError(f"image of shape {arr.shape} does not fit a {w}x{h} texture with {texture.components} components")
    texture.write(flip_rows(arr, _DTYPES[texture.dtype]).tobytes(), alignment=1)
