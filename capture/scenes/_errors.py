"""Typed errors of the scene sources.

::

    RtpError (rtp.sdk)
    └── SceneError
        ├── SceneNotFoundError   (also FileNotFoundError)  a file, pk3 archive or map that should exist does not
        ├── UnlistedMapError     (also LookupError)        a map that scenes.yaml does not list was asked for
        ├── SceneFormatError     (also ValueError)         a BSP/pk3/mesh file is malformed or unsupported
        └── FetchError                                     downloading or unpacking the Debian packages failed
"""

from __future__ import annotations

from rtp.sdk import EXIT_USAGE, RtpError

__all__ = ["FetchError", "SceneError", "SceneFormatError", "SceneNotFoundError", "UnlistedMapError"]


class SceneError(RtpError):
    """Base class of the errors raised by ``rtp.capture.scenes``."""


class SceneNotFoundError(SceneError, FileNotFoundError):
    """A scene file, pk3 archive or map inside the archives is missing."""

    exit_code = EXIT_USAGE


class UnlistedMapError(SceneError, LookupError):
    """A map that is not listed in ``scenes.yaml`` (or not in the requested split) was requested."""

    exit_code = EXIT_USAGE


class SceneFormatError(SceneError, ValueError):
    """A scene file is malformed or uses an unsupported format version."""

    exit_code = EXIT_USAGE


class FetchError(SceneError):
    """``apt-get download`` or ``dpkg-deb -x`` failed, or fetched packages lack a listed map."""
