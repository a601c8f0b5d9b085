"""A user's own metrics: declared as entry points (or registered in-process), then computed, trained for
and evaluated as rtp's own five are.

A metric is a per-pixel error map of a reference frame and a reduced-rate one, pooled per tile by its
maximum or its mean; lower is better. A package declares one as an entry point::

    [project.entry-points."rtp.metrics"]
    ssim = "rtp_ssim:SSIM"                  # an rtp.metrics.Metric named "ssim"

and ``rtp targets --metrics ssim``, ``rtp train --metric ssim``, ``rtp-export``, ``rtp evaluate``,
``rtp demo``, ``rtp play --fail-metric ssim`` and ``rtp metric ssim`` take it (docs/metrics.md "Your own
metric"). Entry points reach every process a job starts (worker pools, Ray workers);
:func:`register_metric` reaches this process only, for notebooks and tests (a job that would start
workers refuses such a metric: :func:`check_worker_metrics`).

Discovery is lazy (the first lookup of a name rtp does not know), a plugin that fails to load is
logged and named when asked for, and the others stay usable (as ``rtp.sdk.adapters``).
"""

from __future__ import annotations

import difflib
import functools
import importlib.util
import logging
import math
import re
import threading
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from types import MappingProxyType
from typing import Any, Literal

import numpy as np

from rtp.sdk import METRIC_NAME_PATTERN, METRICS, MetricInfo

from ._errors import MetricDependencyError, MetricError, MetricParameterError

__all__ = ["METRIC_ENTRY_POINT_GROUP", "Metric", "check_worker_metrics", "known_metrics", "metric_info", "metric_plugins",
           "register_metric"]

log = logging.getLogger("rtp.metrics")

#: The entry-point group a package declares its metrics in.
METRIC_ENTRY_POINT_GROUP = "rtp.metrics"
#: How a plugin's per-pixel map becomes a tile's value.
POOLINGS = ("max", "mean")
_NAME = re.compile(METRIC_NAME_PATTERN)
_MAX_NAME = 64
#: How far below 0 a map's value may lie and be taken as 0: float round-off (``1 - SSIM`` of equal pixels gives
#: -1e-12), as images' values this close outside [0, 1] are clipped.
ROUND_OFF = 1e-6
#: The largest value, as a share of ``default_threshold``, a map of a frame against itself may give.
EQUAL_SHARE = 0.01


@dataclass(frozen=True)
class Metric:
    """A metric of one's own: a per-pixel error map, pooled per tile.

    Attributes:
        name: the name every command and the model's metadata use: lower-case letters, digits and
            underscores, starting with a letter (:data:`rtp.sdk.METRIC_NAME_PATTERN`), at most 64
            characters, not one of rtp's own (:data:`rtp.sdk.METRICS`) and not starting with ``jn``
            (the Weber-corrected metrics' prefix).
        error_map: ``error_map(reference, test)``: two ``(H, W, 3)`` float32 frames, display-encoded
            sRGB in [0, 1] (the full-rate frame and the same frame at a reduced rate), to an ``(H, W)``
            map of finite errors >= 0, 0 where the frames are equal; lower is better (a similarity
            such as SSIM is given as its dissimilarity, ``(1 - SSIM) / 2``). Numpy in, anything
            ``np.asarray`` reads out. Round-off down to -1e-6 is taken as 0; a map of a frame against
            itself above 1% of ``default_threshold`` is refused (checked on a process's first map).
        default_threshold: the threshold (metric units, > 0) a model trained for it records as its
            default: the tile's largest acceptable error.
        pooling: ``"max"`` (the paper's pooling: a tile is as bad as its worst pixel) or ``"mean"``.
        units: what a value is, for tables and plots.
        description: one line.
        params: what defines the metric's values beyond its name (a version, a window size): recorded
            with a dataset's targets, so that targets computed by another definition are refused
            rather than mixed. JSON values. rtp does not read the map's code: change ``params`` (the
            version) whenever what the map computes changes, or its stored targets are kept as they are.
        requires: importable module names the map needs (``"scipy"``): checked before a job starts.
    """

    name: str
    error_map: Callable[[np.ndarray, np.ndarray], Any]
    default_threshold: float
    pooling: Literal["max", "mean"] = "max"
    units: str = "error"
    description: str = ""
    params: Mapping[str, Any] = field(default_factory=dict)
    requires: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name) or len(self.name) > _MAX_NAME:
            raise MetricParameterError(f"Metric name: expected lower-case letters, digits and underscores starting "
                                       f"with a letter, at most {_MAX_NAME} characters, got {self.name!r}", "name")
        if self.name in METRICS:
            raise MetricParameterError(f"Metric name {self.name!r} is one of rtp's own metrics "
                                       f"({', '.join(METRICS)}): choose another", "name")
        if self.name.startswith("jn"):  # (model metadata requires a Weber luminance of every jn* metric)
            raise MetricParameterError(f"Metric name {self.name!r}: names starting with 'jn' are rtp's Weber-corrected "
                                       f"metrics' (JNFLIP, JNYang): choose another", "name")
        if not callable(self.error_map):
            raise MetricParameterError(f"Metric {self.name!r}: error_map must be a function (reference, test) -> "
                                       f"(H, W) map, got {type(self.error_map).__name__}", "error_map")
        t = self.default_threshold
        number = not isinstance(t, bool) and isinstance(t, (int, float, np.integer, np.floating))
        try:
            threshold = float(t) if number else math.nan
        except OverflowError:  # (an int past float's range: math.isfinite raised it, untyped)
            threshold = math.inf
        if not math.isfinite(threshold) or threshold <= 0:
            raise MetricParameterError(f"Metric {self.name!r}: default_threshold must be a finite number > 0 (the "
                                       f"largest acceptable tile error), got {t!r}", "default_threshold")
        if self.pooling not in POOLINGS:
            raise MetricParameterError(f"Metric {self.name!r}: pooling must be one of {', '.join(POOLINGS)}, got "
                                       f"{self.pooling!r}", "pooling")
        for key, value in (("units", self.units), ("description", self.description)):
            if not isinstance(value, str):
                raise MetricParameterError(f"Metric {self.name!r}: {key} must be a string, got {value!r}", key)
        if not isinstance(self.params, Mapping) or not all(isinstance(k, str) for k in self.params):
            raise MetricParameterError(f"Metric {self.name!r}: params must be a mapping of names to JSON values, got "
                                       f"{self.params!r}", "params")
        import json

        try:
            json.dumps(dict(self.params), allow_nan=False)
        except (TypeError, ValueError) as err:
            raise MetricParameterError(f"Metric {self.name!r}: params must hold JSON values ({err})", "params") from err
        requires = tuple(self.requires) if isinstance(self.requires, (tuple, list)) else None
        if requires is None or not all(isinstance(m, str) and m for m in requires):
            raise MetricParameterError(f"Metric {self.name!r}: requires must be a tuple of module names, got "
                                       f"{self.requires!r}", "requires")
        object.__setattr__(self, "requires", requires)
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))
        object.__setattr__(self, "default_threshold", threshold)

    @property
    def info(self) -> MetricInfo:
        """The metric's facts in the form rtp's own have (:class:`rtp.sdk.MetricInfo`)."""
        return MetricInfo(self.name, False, self.units, (0.0, math.inf), self.pooling, False,
                          self.description or f"{self.name} (a plugin metric), {self.pooling} over the tile",
                          self.default_threshold)

    def check_requires(self) -> None:
        """A :class:`MetricDependencyError` naming each module of ``requires`` that cannot be imported."""
        missing = [m for m in self.requires if importlib.util.find_spec(m.split(".")[0]) is None]
        if missing:
            raise MetricDependencyError(f"the metric {self.name!r} needs {', '.join(missing)}: pip install "
                                        f"{' '.join(m.split('.')[0] for m in missing)}")

    def map(self, reference: np.ndarray, test: np.ndarray) -> np.ndarray:
        """``error_map(reference, test)`` of two float32 ``(H, W, 3)`` frames (given read-only), checked:
        float32 ``(H, W)``, finite (in float32 too), >= 0 (round-off down to ``-ROUND_OFF`` is taken as 0);
        else a :class:`MetricError` naming the metric and what its map gave (a bug in the plugin). The first
        call in a process also maps ``reference`` against itself, which must give 0 (at most 1% of
        ``default_threshold``): a similarity given as it is (higher is better), or a map that is not 0 on equal
        frames (an offset, noise), is a :class:`MetricError` rather than targets no threshold reads right."""
        out = self._checked(self._call(reference, test), reference.shape[:2])
        if not getattr(self, "_equal_checked", False):
            same = self._checked(self._call(reference, reference), reference.shape[:2])
            worst = float(same.max(initial=0.0))
            if worst > EQUAL_SHARE * self.default_threshold:
                raise MetricError(
                    f"the metric {self.name!r}'s error_map of a frame against itself gives up to {worst:.3g} (mean "
                    f"{float(same.mean()):.3g}), not 0: an error map is 0 where the frames are equal and grows with the "
                    f"error, lower is better (a similarity such as SSIM is given as a dissimilarity, (1 - SSIM) / 2), "
                    f"and gives the same map for the same frames; more than {EQUAL_SHARE:.0%} of its default_threshold "
                    f"({self.default_threshold:g}) where nothing differs is refused")
            object.__setattr__(self, "_equal_checked", True)  # (once a process: not twice the work a sample)
        return out

    def _call(self, reference: np.ndarray, test: np.ndarray) -> Any:
        """``error_map`` of read-only views of the frames; what it raises is a :class:`MetricError`."""
        frames = []
        for image in (reference, test):  # read-only views: a map that wrote into them would change the others'
            view = image.view()
            view.flags.writeable = False
            frames.append(view)
        try:
            return self.error_map(*frames)
        except MetricError:
            raise
        except (Exception, SystemExit) as err:  # (a plugin's sys.exit ended rtp silently with its code)
            raise MetricError(f"the metric {self.name!r}'s error_map failed on {reference.shape[1]}x"
                              f"{reference.shape[0]} frames: {type(err).__name__}: {err}") from err

    def _checked(self, out: Any, size: tuple[int, ...]) -> np.ndarray:
        """What ``error_map`` returned as a float32 ``(H, W)`` map of ``size``, or a :class:`MetricError`."""
        try:
            a = np.asarray(out)
        except Exception as err:  # (a torch tensor that requires grad raised its RuntimeError, naming no plugin)
            raise MetricError(f"the metric {self.name!r}'s error_map returned {type(out).__name__}, not an array "
                              f"({type(err).__name__}: {err})") from err
        h, w = size
        if a.shape != (h, w) or a.dtype.kind not in "biuf":
            raise MetricError(f"the metric {self.name!r}'s error_map returned {a.dtype} {a.shape}; expected an "
                              f"(H, W) = ({h}, {w}) map of numbers")
        finite = np.isfinite(a)
        negative = a < -ROUND_OFF
        if not finite.all() or negative.any():
            # (it said "NaN, infinite or negative" of 1 - SSIM's -7.6e-12 round-off on equal pixels, naming neither)
            found = [f"{n} {what}" for n, what in ((int(np.isnan(a).sum()), "NaN"),
                                                   (int(np.isinf(a).sum()), "infinite"),
                                                   (int(negative.sum()), "negative")) if n]
            low = f", down to {float(a[finite].min()):.3g}" if negative.any() else ""
            raise MetricError(f"the metric {self.name!r}'s error_map returned values outside [0, inf) "
                              f"({', '.join(found)} of {a.size} pixels{low}); an error map is finite and >= 0")
        if a.dtype.kind == "f" and a.dtype.itemsize > 4 and a.max(initial=0.0) > np.finfo(np.float32).max:
            # (the cast made them infinite, with numpy's overflow warning, and the error said "NaN, infinite")
            raise MetricError(f"the metric {self.name!r}'s error_map returned values up to {a.max():.3g}, beyond "
                              f"float32's range ({np.finfo(np.float32).max:.3g}), in which rtp stores errors")
        return np.maximum(a, 0).astype(np.float32)  # (round-off below 0, such as 1 - SSIM's -1e-12, is 0)


_lock = threading.RLock()
_registered: dict[str, Metric] = {}
_broken: dict[str, str] = {}
_explicit: set[str] = set()  # the names register_metric gave (not an entry point's)


def register_metric(metric: Metric) -> None:
    """Make ``metric`` known to this process under its name (not to the worker processes a job starts:
    they find metrics through entry points); it takes precedence over an entry point of the same name.
    Registering another metric under a registered name replaces it."""
    if not isinstance(metric, Metric):
        raise MetricParameterError(f"register_metric takes an rtp.metrics.Metric, got {type(metric).__name__}")
    with _lock:
        _registered[metric.name] = metric
        _explicit.add(metric.name)


def check_worker_metrics(names: str | Iterable[str]) -> None:
    """Refuse, before a job starts worker processes (``workers > 1``, Ray), a plugin metric of ``names``
    that only :func:`register_metric` made known: the workers are new processes, which find metrics
    through entry points; and one registered under an entry point's name whose ``params`` or pooling (its
    definition, as the targets manifest records it) are not the entry point's metric's, which the workers
    would compute. A :class:`MetricParameterError` naming it and the ways out."""
    names = [names] if isinstance(names, str) else list(names)
    with _lock:
        explicit = {m: _registered[m] for m in names if m in _explicit and m in _registered}
    for m, mine in explicit.items():
        ep = _entry_points().get(m)
        if ep is None:
            raise MetricParameterError(
                f"the metric {m!r} is registered in this process only (rtp.metrics.register_metric), and worker "
                f"processes do not see it: declare it in the {METRIC_ENTRY_POINT_GROUP!r} entry-point group of an "
                f"installed package, or run the job in this process (one worker, no Ray)", "metrics")
        try:  # (the workers compute the entry point's metric: one of other params than the one registered here,
            # which the targets manifest declared, stored its values under the registered one's definition)
            theirs: Any = ep.load()
        except Exception as err:
            theirs = f"fails to load ({type(err).__name__}: {err})"
        ours = {"params": dict(mine.params), "pooling": mine.pooling}
        if isinstance(theirs, Metric):
            defined = {"params": dict(theirs.params), "pooling": theirs.pooling}
            what = f"defines it by {ours}, its entry point {ep.value!r}, which worker processes compute, by {defined}"
        else:
            defined = None
            problem = theirs if isinstance(theirs, str) else f"is {type(theirs).__name__}, not a Metric"
            what = f"is not its entry point {ep.value!r}'s, which worker processes compute, and which {problem}"
        if defined != ours:
            raise MetricParameterError(
                f"the metric {m!r} registered in this process (rtp.metrics.register_metric) {what}: run the job in "
                f"this process (one worker, no Ray), or install the registered definition as the entry point",
                "metrics")


@functools.cache
def _entry_points() -> dict[str, Any]:
    """The group's entry points by name, read once (an editable install can list one twice: the first)."""
    return {ep.name: ep for ep in reversed(list(entry_points(group=METRIC_ENTRY_POINT_GROUP)))}


def _load(name: str) -> Metric | None:
    """The plugin metric ``name``, registered or installed; None if there is none. A plugin that
    fails to load raises :class:`MetricParameterError` naming it (and is logged once)."""
    with _lock:
        if name in _registered:
            return _registered[name]
    ep = _entry_points().get(name)
    if ep is None:
        return None
    reserved = name in METRICS or name.startswith("jn")
    try:
        # (one of rtp's own names is never a plugin's: not imported. It was, and said "is the Metric 'mse': an
        # entry point's name is its metric's" of an entry point `psnr = pkg:MSE`, not that psnr is rtp's own)
        obj = None if reserved else ep.load()
    except Exception as err:  # a broken plugin must not take the host down
        problem = f"failed to load ({type(err).__name__}: {err})"
    else:
        if reserved:
            problem = "is ignored: rtp's own metrics (and names starting with 'jn') are not a plugin's to take"
        elif isinstance(obj, Metric) and obj.name == name:
            with _lock:
                _registered.setdefault(name, obj)
                return _registered[name]
        else:
            problem = (f"is {type(obj).__name__}, not an rtp.metrics.Metric" if not isinstance(obj, Metric)
                       else f"is the Metric {obj.name!r}: an entry point's name is its metric's")
    if name not in _broken:  # (formatted: the command's log shows one record of each template, which hid the
        # second broken plugin behind a "1 more like" of the first)
        log.warning(f"metric plugin {name!r} ({ep.value}) {problem}")
    _broken[name] = problem
    raise MetricParameterError(f"the metric {name!r} is installed but {problem}: the entry point {ep.value!r} in "
                               f"{METRIC_ENTRY_POINT_GROUP!r} is its package's to fix or reinstall", "metric")


def metric_plugins() -> Mapping[str, Metric]:
    """Every plugin metric that loads, registered or installed, by name (those that fail are logged)."""
    for name in list(_entry_points()):
        try:
            _load(name)
        except MetricParameterError:
            pass
    with _lock:
        return MappingProxyType(dict(sorted(_registered.items())))


def known_metrics() -> tuple[str, ...]:
    """rtp's own metrics (:data:`rtp.sdk.METRICS`), then the plugins' that load, sorted."""
    return (*METRICS, *metric_plugins())


def plugin(name: str) -> Metric | None:
    """The plugin metric ``name``, or None for one of rtp's own; unknown names raise as :func:`metric_info`."""
    if isinstance(name, str) and name in METRICS:
        return None
    found = _load(name) if isinstance(name, str) else None
    if found is None:
        names = known_metrics()
        close = difflib.get_close_matches(name, names, n=1) if isinstance(name, str) else []
        raise MetricParameterError(
            f"unknown metric {name!r}{f' (did you mean {close[0]}?)' if close else ''}; metrics are "
            f"{', '.join(names)} (a metric of your own: an rtp.metrics.Metric declared in the "
            f"{METRIC_ENTRY_POINT_GROUP!r} entry-point group, docs/metrics.md \"Your own metric\")", "metric")
    return found


def metric_info(name: str) -> MetricInfo:
    """The facts of ``name``: one of rtp's own (:data:`rtp.sdk.METRICS`) or a plugin's
    (:attr:`Metric.info`). An unknown name raises :class:`MetricParameterError` listing the known ones."""
    found = plugin(name)
    return METRICS[name] if found is None else found.info
