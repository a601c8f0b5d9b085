"""rtp: learned perceptual error prediction for variable-rate shading.

The package is one import namespace over the project's rooms (docs/architecture.md): ``rtp.sdk`` is
the runtime engines use (``from rtp import sdk; sdk.load("jnyang")``), ``rtp.plugins.moderngl`` and
``rtp.plugins.pyrender`` the renderer adapters, ``rtp.export`` the exporter, and ``rtp.capture``,
``rtp.metrics``, ``rtp.train``, ``rtp.evaluate`` the toolchain. ``python -m rtp`` runs the ``rtp``
command. Importing ``rtp`` itself imports none of them.
"""

import typing as _typing

__all__ = ["__version__"]


def _module_attribute(name: str) -> str:
    # one source of truth: the installed distribution's version, which rtp.sdk reads
    if name == "__version__":
        from rtp import sdk

        return sdk.__version__
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# A type checker sees ``__version__`` declared, not a module ``__getattr__``: that would make every other name,
# a misspelt one included, exist (as a str).
if _typing.TYPE_CHECKING:
    __version__: str
else:
    __getattr__ = _module_attribute
