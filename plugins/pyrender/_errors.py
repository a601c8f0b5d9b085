"""Typed errors of the pyrender adapter (one branch of the :class:`rtp.sdk.RtpError` tree)."""

from __future__ import annotations

from rtp.sdk import EXIT_USAGE, RtpError

__all__ = ["PyrenderAdapterError", "PyrenderUnavailableError"]


class PyrenderAdapterError(RtpError, RuntimeError):
    """The adapter cannot do what was asked: a bad pose or frame, a scene without a camera, a
    shader that failed to build, a closed adapter, ..."""


class PyrenderUnavailableError(PyrenderAdapterError):
    """pyrender or its OpenGL platform (EGL / OSMesa) cannot be loaded or gives no context."""

    exit_code = EXIT_USAGE
