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
