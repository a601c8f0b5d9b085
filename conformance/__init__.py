"""The adapter conformance kit: the checks every rtp adapter passes, for a plugin's own CI.

An engine's adapter (docs/adapters.md) is checked the way rtp checks its own: driven through the
generic path only (``frame_source`` -> ``adapter`` -> ``inputs``) on the procedural scene
``procedural(0)`` after a small camera move, its planes compared with the conventions of
``rtp.sdk.CHANNELS`` and with the reference renderer's for the same cameras, fed to a predictor,
and put through the lifecycle (``with``, ``close``, the typed errors)::

    from rtp import conformance

    report = conformance.check_adapter("myengine")       # or "mypkg.adapter:MyAdapter", or the class
    assert report.ok, report                              # the table of checks, each failure with why

or from a shell: ``rtp adapters check myengine``. Needs ``rtp[capture]`` (the reference renderer, the
procedural scene, the picture) and a headless EGL; imports nothing of the engine beyond the adapter's own ``frame_source``.
"""

from __future__ import annotations

from ._kit import (
    AGREEMENT,
    CONFORMANCE_SCENE,
    DEFAULT_SIZE,
    ENGINE_DEFINED,
    MIN_AGREEMENT,
    MIN_EDGE_CORRELATION,
    MIN_OCCLUDED_UNSEEN,
    RANGE_SLACK,
    Check,
    ConformanceError,
    ConformanceReport,
    Tolerance,
    check_adapter,
    resolve_adapter,
    runnable_models,
)

__all__ = [
    "AGREEMENT",
    "CONFORMANCE_SCENE",
    "DEFAULT_SIZE",
    "ENGINE_DEFINED",
    "MIN_AGREEMENT",
    "MIN_EDGE_CORRELATION",
    "MIN_OCCLUDED_UNSEEN",
    "RANGE_SLACK",
    "Check",
    "ConformanceError",
    "ConformanceReport",
    "Tolerance",
    "check_adapter",
    "resolve_adapter",
    "runnable_models",
]
