"""Importing pyrender safely: the numpy-2 shim and the PyOpenGL platform.

pyrender 0.1.45 has two import-time quirks this module deals with, once, before the first
``import pyrender``:

* ``pyrender.mesh`` uses ``np.infty``, which numpy 2 removed. The alias is added to numpy only
  when it is missing (numpy < 2 keeps its own; nothing is overwritten).
* PyOpenGL picks its platform (GLX, EGL, OSMesa) from ``PYOPENGL_PLATFORM`` when ``OpenGL`` is
  first imported, and pyrender's ``OffscreenRenderer`` reads the same variable. Headless rendering
  needs ``egl`` (the default set here, if the variable is unset) or ``osmesa``. If ``OpenGL`` was
  already imported under another platform, it cannot be changed in this process: that is an error
  naming the fix, not a segfault later.
"""

from __future__ import annotations

import ctypes
import logging
import numbers
import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from importlib.metadata import PackageNotFoundError, version
from typing import Any

import numpy as np

from rtp.sdk import ParameterError

from ._errors import PyrenderAdapterError, PyrenderUnavailableError

__all__ = ["PLATFORMS", "current", "import_pyrender", "offscreen_renderer"]

log = logging.getLogger("rtp.plugins.pyrender")

#: The headless PyOpenGL platforms the adapter supports.
PLATFORMS: tuple[str, ...] = ("egl", "osmesa")

_EXTRA = "pip install 'rtp[pyrender]'"
_pyrender: Any = None


def _version_tuple(text: str) -> tuple[int, ...]:
    out = []
    for part in text.split("."):
        digits = "".join(ch for ch in part if ch.isdigit())
        if not digits:
            break
        out.append(int(digits))
    return tuple(out)


def _shim_numpy() -> None:
    if not hasattr(np, "infty"):  # numpy >= 2 removed the alias pyrender.mesh still uses
        np.infty = np.inf  # type: ignore[attr-defined]
        log.debug("added the np.infty alias pyrender 0.1.45 needs under numpy %s", np.__version__)


def import_pyrender(platform: str | None = None) -> Any:
    """Import and return the ``pyrender`` module, ready for headless rendering.

    Args:
        platform: ``"egl"`` or ``"osmesa"``; None keeps ``PYOPENGL_PLATFORM`` if set, else uses
            ``"egl"``.

    Raises:
        ImportError: pyrender is not installed (names the extra to install).
        PyrenderUnavailableError: the platform is unsupported, conflicts with an ``OpenGL`` module
            already imported under another platform, or its libraries are missing.
    """
    global _pyrender
    current = os.environ.get("PYOPENGL_PLATFORM")
    if platform is not None and not isinstance(platform, str):
        raise PyrenderUnavailableError(f"platform: expected one of {', '.join(PLATFORMS)}, got {platform!r}")
    wanted = (current or "egl" if platform is None else platform).lower()  # ("" is no platform, not the default)
    if wanted not in PLATFORMS:
        raise PyrenderUnavailableError(
            f"PYOPENGL_PLATFORM {wanted!r} cannot render headless; use one of {', '.join(PLATFORMS)}"
        )
    if current is not None and current.lower() != wanted and "OpenGL" in sys.modules:
        raise PyrenderUnavailableError(
            f"PyOpenGL was already imported with PYOPENGL_PLATFORM={current!r}; the pyrender adapter needs "
            f"{wanted!r}. Set PYOPENGL_PLATFORM={wanted} before anything imports OpenGL (or pyrender)."
        )
    if current is None and "OpenGL" in sys.modules:
        raise PyrenderUnavailableError(
            "PyOpenGL was imported before PYOPENGL_PLATFORM was set, so it chose an on-screen platform; set "
            f"PYOPENGL_PLATFORM={wanted} before importing OpenGL or pyrender (os.environ.setdefault(\"PYOPENGL_PLATFORM\", "
            f"\"{wanted}\") first thing), or take pyrender from rtp.plugins.pyrender.import_pyrender() instead of "
            "`import pyrender`, which sets it."
        )
    if _pyrender is not None:
        return _pyrender
    if wanted == "osmesa":
        try:
            pyopengl = version("PyOpenGL")
        except PackageNotFoundError:
            pyopengl = "0"
        if _version_tuple(pyopengl) < (3, 1, 5):
            raise PyrenderUnavailableError(
                f"PYOPENGL_PLATFORM=osmesa needs PyOpenGL >= 3.1.5 (installed: {pyopengl}; pyrender 0.1.45 pins "
                "3.1.0, which only works with EGL). Use EGL, or `pip install --no-deps PyOpenGL==3.1.10` and "
                "`apt-get install libosmesa6`."
            )
    os.environ["PYOPENGL_PLATFORM"] = wanted
    _shim_numpy()
    fix = "apt-get install libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri" if wanted == "egl" else "apt-get install libosmesa6"
    try:
        import pyrender
    except ImportError as exc:
        if exc.name in ("pyrender", "OpenGL"):
            raise ImportError(f"the pyrender adapter needs pyrender 0.1.45; install the extra: {_EXTRA}") from exc
        if exc.name is None:  # PyOpenGL's "Unable to load EGL library" / "Unable to load OpenGL library" (OSMesa)
            raise PyrenderUnavailableError(f"pyrender could not load its {wanted} platform ({type(exc).__name__}: "
                                           f"{exc}); on Debian/Ubuntu: {fix}") from exc
        raise PyrenderUnavailableError(f"pyrender failed to import ({type(exc).__name__}: {exc})") from exc
    except Exception as exc:  # PyOpenGL raises plain errors when libEGL / libOSMesa are missing
        raise PyrenderUnavailableError(
            f"pyrender could not load its {wanted} platform ({type(exc).__name__}: {exc}); on Debian/Ubuntu: {fix}"
        ) from exc
    _pyrender = pyrender
    log.debug("pyrender %s on PYOPENGL_PLATFORM=%s", getattr(pyrender, "__version__", "?"), wanted)
    return pyrender


_SHARED: dict[type, type] = {}


def _shared_display_class(base: type, delete: Any) -> type:
    """``base`` (pyrender's ``OffscreenRenderer``) whose ``delete`` is ``delete``: one subclass per base."""
    if base not in _SHARED:
        _SHARED[base] = type(base.__name__, (base,), {
            "delete": lambda self: delete(self), "__module__": __name__,
            "__doc__": f"{base.__doc__ or ''}\n\n(rtp: delete() frees this renderer's context only.)"})
    return _SHARED[base]


def offscreen_renderer(pyrender: Any, width: int, height: int) -> Any:
    """A ``pyrender.OffscreenRenderer`` of ``width`` x ``height``, or a :class:`PyrenderUnavailableError`
    naming the platform and the Debian packages when its GL context cannot be created.

    A size past the context's ``GL_MAX_TEXTURE_SIZE`` / ``GL_MAX_RENDERBUFFER_SIZE`` is a
    :class:`rtp.sdk.ParameterError` (pyrender makes its targets only at the first draw, where it failed)."""
    if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) and int(v) >= 1 for v in (width, height)):
        raise ParameterError(f"frame size: expected positive integers (pixels), got {width!r} x {height!r}", "size")
    if sys.flags.optimize:  # (it failed below with the hint to install packages that are installed)
        raise PyrenderUnavailableError(
            "pyrender 0.1.45 sets up its GL context inside assert statements (eglInitialize, eglChooseConfig, "
            "eglMakeCurrent; OSMesaMakeCurrent), which python -O / PYTHONOPTIMIZE strips: run without -O")
    before = _egl_current()
    try:
        renderer = pyrender.OffscreenRenderer(int(width), int(height))
    except Exception as exc:
        raise PyrenderUnavailableError(
            f"pyrender could not create a {os.environ.get('PYOPENGL_PLATFORM')} context "
            f"({type(exc).__name__}: {exc}); on Debian/Ubuntu: apt-get install libegl1 libgl1 libegl-mesa0 "
            "libgl1-mesa-dri (EGL) or libosmesa6 (OSMesa)"
        ) from exc
    from OpenGL import GL

    from ._gbuffer import _delete_renderer

    # deleted (by close, by pyrender's own delete() or when dropped unclosed) without pyrender's eglTerminate, which
    # ends the EGL display every renderer of the process shares (the others then fail with EGL_BAD_DISPLAY)
    renderer.__class__ = _shared_display_class(type(renderer), _delete_renderer)
    # (pyrender's constructor left its context current in this thread: given back to what was current before, so
    # that the renderer can be used from another thread, and an engine's own context is current again)
    _restore(renderer._platform, before)
    with current(renderer):
        limit = min(int(GL.glGetIntegerv(GL.GL_MAX_TEXTURE_SIZE)), int(GL.glGetIntegerv(GL.GL_MAX_RENDERBUFFER_SIZE)))
    if max(int(width), int(height)) > limit:
        _delete_renderer(renderer)
        raise ParameterError(f"frame size: this OpenGL context draws at most {limit} pixels a side "
                             f"(GL_MAX_TEXTURE_SIZE), got {width}x{height}", "size")
    return renderer


def _egl(platform: Any) -> bool:
    """``platform`` is pyrender's EGL platform with a live context."""
    return type(platform).__name__ == "EGLPlatform" and getattr(platform, "_egl_context", None) is not None


def _address(pointer: Any) -> int | None:
    return ctypes.cast(pointer, ctypes.c_void_p).value


def _egl_current() -> tuple[Any, Any, Any, Any] | None:
    """This thread's current EGL ``(display, draw surface, read surface, context)``; None where EGL is not the
    platform (OSMesa) or nothing is current."""
    if os.environ.get("PYOPENGL_PLATFORM") != "egl":
        return None
    from OpenGL import EGL

    context = EGL.eglGetCurrentContext()
    if not _address(context):
        return None
    return (EGL.eglGetCurrentDisplay(), EGL.eglGetCurrentSurface(EGL.EGL_DRAW),
            EGL.eglGetCurrentSurface(EGL.EGL_READ), context)


def _restore(platform: Any, before: tuple[Any, Any, Any, Any] | None) -> None:
    """Make ``before`` (from :func:`_egl_current`) current again in this thread in place of ``platform``'s
    context: another context (an engine's), or none, which lets another thread make ``platform``'s current."""
    if not _egl(platform):
        return
    from OpenGL import EGL

    if before is not None and _address(before[3]) == _address(platform._egl_context):
        return  # (it was current here before the call: left so)
    try:
        if before is None:
            EGL.eglMakeCurrent(platform._egl_display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
        else:
            EGL.eglMakeCurrent(*before)
    except Exception as exc:  # (the context current before was destroyed meanwhile, say)
        log.warning("could not make the GL context current before the pyrender adapter's call current again: %s", exc)


@contextmanager
def current(renderer: Any) -> Iterator[None]:
    """``renderer``'s (a ``pyrender.OffscreenRenderer``'s) context current in this thread for the block, and
    what was current before (another context, or none) current again after it.

    pyrender makes a renderer's context current before each draw and never releases it (its EGL
    ``make_uncurrent`` does nothing), so a renderer used in one thread could not be used in another, where
    ``eglMakeCurrent`` fails with EGL_BAD_ACCESS: that is a :class:`PyrenderAdapterError` naming the thread.
    (OSMesa contexts are made current as pyrender does; nothing is restored.)"""
    platform = renderer._platform
    if platform is None:
        raise PyrenderAdapterError("the pyrender renderer has been deleted (its delete() freed its GL context); "
                                   "an adapter borrowing a renderer needs it alive until the adapter is closed")
    if not _egl(platform):
        platform.make_current()
        yield
        return
    from OpenGL import EGL

    before = _egl_current()
    try:
        made = bool(EGL.eglMakeCurrent(platform._egl_display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE,
                                       platform._egl_context))
        error = "" if made else f" (EGL error 0x{int(EGL.eglGetError()):04x})"
    except EGL.EGLError as exc:
        made, error = False, f" ({getattr(exc.err, 'name', exc.err)})"
    if not made:
        raise PyrenderAdapterError(
            f"the pyrender renderer's GL context cannot be made current in thread "
            f"{threading.current_thread().name!r}{error}: a context is current in one thread at a time, and "
            "another thread holds this one (pyrender's own render() leaves it current in the thread that drew). "
            "Call from the thread that draws with the renderer, or release the context there first "
            "(OpenGL.EGL.eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)); the "
            "adapter's own calls release it when they return")
    try:
        yield
    finally:
        _restore(platform, before)
