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

import logging
import numbers
import os
import sys
from importlib.metadata import PackageNotFoundError, version
from typing import Any

import numpy as np

from rtp.sdk import ParameterError

from ._errors import PyrenderUnavailableError

__all__ = ["PLATFORMS", "import_pyrender", "offscreen_renderer"]

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
    renderer._platform.make_current()
    limit = min(int(GL.glGetIntegerv(GL.GL_MAX_TEXTURE_SIZE)), int(GL.glGetIntegerv(GL.GL_MAX_RENDERBUFFER_SIZE)))
    if max(int(width), int(height)) > limit:
        _delete_renderer(renderer)
        raise ParameterError(f"frame size: this OpenGL context draws at most {limit} pixels a side "
                             f"(GL_MAX_TEXTURE_SIZE), got {width}x{height}", "size")
    return renderer
