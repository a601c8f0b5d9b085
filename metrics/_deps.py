"""Check, before any work starts, that everything the requested metrics need is installed."""

from __future__ import annotations

from collections.abc import Iterable

from ._errors import MetricDependencyError
from ._flip import _flip_module
from ._lpips import _torch, lpips_weights_path
from ._plugins import plugin

#: What each metric needs beyond numpy: checked by :func:`check_dependencies`.
METRIC_DEPENDENCIES: dict[str, tuple[str, ...]] = {
    "flip": ("flip-evaluator",),
    "jnflip": ("flip-evaluator",),
    "lpips": ("torch", "LPIPS weights"),
    "psnr": (),
    "yang": (),
    "jnyang": (),
}

#: The extra of pyproject.toml to install for each package of :data:`METRIC_DEPENDENCIES`, and the package's pin
#: there, as a :class:`MetricDependencyError` names them (tests/test_dependencies.py checks both against
#: pyproject.toml): the one with the fewest requirements among those that bring it, and one without torch where
#: there is one. flip-evaluator's is ``rtp[capture]`` (FLIP, PSNR and the Yang metrics need no torch);
#: ``rtp[metrics]`` has it too, with torch's gigabytes.
METRIC_INSTALLS: dict[str, tuple[str, str]] = {
    "flip-evaluator": ("rtp[capture]", "flip-evaluator==1.7"),
    "torch": ("rtp[metrics]", "torch==2.13.0"),
}

#: What every message naming torch's install adds (README, "Set-up"); ``rtp.cli``'s says the same.
TORCH_CPU_NOTE = ("torch from public PyPI may be its CUDA build, gigabytes: for the CPU build add --extra-index-url "
                  "https://download.pytorch.org/whl/cpu (README, Set-up)")


def install_hint(package: str) -> str:
    """The install command a :class:`MetricDependencyError` names for ``package`` (of :data:`METRIC_INSTALLS`):
    its extra, or the package alone at its pin; for torch, where its CPU build comes from."""
    extra, pin = METRIC_INSTALLS[package]
    hint = f"pip install '{extra}' (or {pin} alone)"
    return f"{hint}; {TORCH_CPU_NOTE}" if package == "torch" else hint


def check_dependencies(metrics: str | Iterable[str]) -> None:
    """Raise :class:`MetricDependencyError` listing every missing piece the ``metrics`` need (each with
    the command that installs or fetches it), so that a long job fails in its first second rather
    than after hours of work. ``metrics`` is a list of names or one name. Unknown metric names raise
    :class:`MetricParameterError`; a plugin metric's ``requires`` are checked too."""
    # (a name alone, check_dependencies("flip"), was read as the metrics "f", "l", "i", "p": unknown metric 'f')
    names = list(dict.fromkeys([metrics] if isinstance(metrics, str) else metrics))
    plugins = [p for p in (plugin(m) for m in names) if p is not None]  # (an unknown name: MetricParameterError)
    checks = {"flip-evaluator": _flip_module, "torch": _torch, "LPIPS weights": lpips_weights_path}
    problems: list[str] = []
    for piece in dict.fromkeys(p for m in names for p in METRIC_DEPENDENCIES.get(m, ())):
        try:
            checks[piece]()
        except MetricDependencyError as exc:
            users = ", ".join(m for m in names if piece in METRIC_DEPENDENCIES.get(m, ()))
            problems.append(f"{users}: {exc}")
    for p in plugins:  # a plugin metric's own modules (Metric.requires)
        try:
            p.check_requires()
        except MetricDependencyError as exc:
            problems.append(str(exc))
    if problems:
        raise MetricDependencyError("missing before any work starts: " + "; ".join(problems))
