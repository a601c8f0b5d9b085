"""Check, before any work starts, that everything the requested metrics need is installed."""

from __future__ import annotations

from collections.abc import Iterable

from rtp.sdk import METRICS

from ._errors import MetricDependencyError, MetricParameterError
from ._flip import _flip_module
from ._lpips import _torch, lpips_weights_path

#: What each metric needs beyond numpy: checked by :func:`check_dependencies`.
METRIC_DEPENDENCIES: dict[str, tuple[str, ...]] = {
    "flip": ("flip-evaluator",),
    "jnflip": ("flip-evaluator",),
    "lpips": ("torch", "LPIPS weights"),
    "psnr": (),
    "yang": (),
    "jnyang": (),
}


def check_dependencies(metrics: Iterable[str]) -> None:
    """Raise :class:`MetricDependencyError` listing every missing piece the ``metrics`` need (each with
    the command that installs or fetches it), so that a long job fails in its first second rather
    than after hours of work. Unknown metric names raise :class:`MetricParameterError`."""
    names = list(dict.fromkeys(metrics))
    unknown = [m for m in names if m not in METRICS]
    if unknown:
        raise MetricParameterError(f"unknown metric {unknown[0]!r}; metrics are {', '.join(METRICS)}")
    checks = {"flip-evaluator": _flip_module, "torch": _torch, "LPIPS weights": lpips_weights_path}
    problems: list[str] = []
    for piece in dict.fromkeys(p for m in names for p in METRIC_DEPENDENCIES.get(m, ())):
        try:
            checks[piece]()
        except MetricDependencyError as exc:
            users = ", ".join(m for m in names if piece in METRIC_DEPENDENCIES.get(m, ()))
            problems.append(f"{users}: {exc}")
    if problems:
        raise MetricDependencyError("missing before any work starts: " + "; ".join(problems))
