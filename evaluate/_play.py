"""Closed-loop VRS on moving cameras (``rtp play``; docs/evaluation.md "Closed loop").

A camera moves along a :class:`~rtp.capture.paths.CameraPath` at 60 Hz. Every frame is rendered
once (G-buffers and every uniform rate); then each method, at each value of its swept parameter,
chooses rates from exactly what an engine would have: the current G-buffers and motion vectors and
the frame it displayed last (its own VRS output, not the full-rate frame), reprojected with the
renderer's depth test. Its rates shade the frame (software VRS, then tone mapping and FXAA over
the composite) and that image becomes its next history. Per frame and method: the shading work
saved, the share of tiles whose true error (``fail_metric``, rendered at every rate) is over
``fail_threshold``, the FLIP of the displayed frame against full-rate shading (every
``flip_every``-th frame, default parameters only: FLIP costs about 0.4 s per 640x360 frame here),
the share of tiles whose rate changed since the previous frame, and the time the method took to
choose. The first frame has no history and is left out of every summary and figure.

Methods (:func:`parse_methods`): ``full`` (always 1x1), ``oracle`` (the true ``fail_metric`` of the
frame at ``fail_threshold``), ``oracle-monotone`` (the same on the truth made monotone over the rates:
:func:`~rtp.evaluate.monotone_over_rates`), any rtp model (a shipped name or an ``.onnx`` path; ``NAME@k`` runs the
network every k-th frame and reprojects its per-tile predictions in between with
:class:`rtp.sdk.PredictionReuse`, tiles mostly unseen since the last prediction at full rate, or
predicted afresh on crops with ``NAME@k:fresh``; ``NAME@k:hW`` also blends each network run's
estimates with those carried from the previous frame, weight W on the carried ones; ``NAME@k:rS``
runs the network early once more than a share S of the tiles is unseen since it ran; ``NAME@k:sN``
carries one pixel of every N per axis; ``NAME@k:vA`` rescales carried estimates by the blocks'
variance, ``sdk.PredictionReuse(rescale=A)``; ``NAME@k:cF`` multiplies carried estimates by F,
``sdk.PredictionReuse(carry_scale=F)``; ``NAME@k:features`` carries a splitting model's trunk features
and runs its tail on every frame, ``sdk.PredictionReuse(carry="features")``; ``NAME@k:bS`` holds a budget
instead of a threshold: every frame's rates save a share S of the work, ``sdk.select_rates_for_saving``,
and the sweep is over S; ``NAME@k:fS`` keeps the threshold and its sweep with a floor of S saved under it,
``select_rates_for_saving(threshold=)``; ``NAME@k:alone`` beside an engine's own rates, ``play(engine_rates=)``,
chooses without them), ``yang2019``
(NVIDIA Adaptive Shading with its motion terms), ``yang2019-unseen-1x1`` (the same, unseen tiles at full rate), ``fidelityfx`` and
``fidelityfx-additional`` (with FFX's motion factor).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import re
import reprlib
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rtp import sdk
from rtp.sdk.files import atomic_output, writer_lock

from ._baselines import FFX_CUTOFF, FFX_MOTION_FACTOR, YANG_THRESHOLD, FidelityFX, Frame, Yang2019, _checked
from ._engine import ENGINE_IMAGES, engine_rates
from ._evaluate import failing_tiles, monotone_over_rates

if TYPE_CHECKING:
    from rtp.capture.paths import DynamicResolution

__all__ = [
    "DEFAULT_METHODS",
    "FAIL_LEVELS",
    "METHOD_KINDS",
    "MethodSpec",
    "PlayError",
    "PlayReport",
    "REUSE_CARRIES",
    "REUSE_REDUCTIONS",
    "REUSE_UNSEEN",
    "parse_methods",
    "play",
    "saved_at",
]

log = logging.getLogger("rtp.evaluate")

#: How a reused tile reduces the estimates its pixels carry (``NAME@k:reduction``) and what it does
#: with tiles the network did not see (``NAME@k:full`` or ``:fresh``): the SDK's
#: :class:`~rtp.sdk.PredictionReuse` options, which the closed loop runs.
REUSE_REDUCTIONS = sdk.REUSE_REDUCTIONS
REUSE_UNSEEN = sdk.REUSE_UNSEEN
#: What a reused frame carries (``NAME@k:features``): the SDK's.
REUSE_CARRIES = sdk.REUSE_CARRIES

# what may follow a model's '@k', each option once (the error of a method that gives something else)
_OPTIONS = (f"at most one ':reduction' ({', '.join(REUSE_REDUCTIONS)}), one ':unseen' fallback "
            f"({', '.join(REUSE_UNSEEN)}), one ':hW' history weight, one ':rS' refresh share (both in [0, 1)), one "
            f"':sN' pixel step, one ':vA' rescale exponent and one ':cF' carry scale, one ':carry' "
            f"({', '.join(REUSE_CARRIES)}) and one ':bS' budget or ':fS' floor, and ':alone', e.g. jnyang@4:mean:fresh, "
            "jnyang@1:h0.5, jnyang@8:r0.02, jnyang@4:s4, jnyang@4:v0.5, jnyang@4:c1.08, split.onnx@4:features, "
            "jnyang@1:b0.6, jnyang@1:f0.5 or jnyang@1:alone")

#: What ``rtp play`` and :func:`play` run by default: the shipped JNYang on every frame and every
#: fourth frame (its estimates carried), the shipped model for reuse with its features carried
#: (``jnyang-reuse``, docs/runtime.md), the baselines and the oracle.
DEFAULT_METHODS = ("jnyang,jnyang@4,jnyang-reuse@4:features,yang2019,yang2019-unseen-1x1,fidelityfx,"
                   "oracle")

#: Method kinds that read no history (nor are swept): the reference and the oracles.
_NO_HISTORY = ("full", "oracle", "oracle-monotone")

#: Failing-tile shares at which the matched-quality table reads each method's saving off its sweep.
FAIL_LEVELS = (0.01, 0.02, 0.05)

#: Method kinds besides models: name -> what it is.
METHOD_KINDS = {
    "full": "every tile at 1x1 (the reference; saves nothing)",
    "oracle": "the true error of the frame (rendered at every rate) at the failure threshold",
    "oracle-monotone": "the oracle on the true error made monotone over the rates (evaluate.monotone_over_rates): "
                       "what a predictor that orders the rates can reach",
    "yang2019": "NVIDIA Adaptive Shading (Yang et al. 2019) on the reprojected history, with its motion terms",
    "yang2019-unseen-1x1": "yang2019 with tiles more than half unseen at full rate",
    "fidelityfx": "AMD FidelityFX VRS (1x1, 1x2, 2x1, 2x2) with its motion factor",
    "fidelityfx-additional": "AMD FidelityFX VRS with the additional rates (2x4, 4x2, 4x4)",
}

#: Each method's swept parameter, as factors of its default (PSNR models: dB added to it). The
#: baselines' grids reach far lower: in the closed loop their history is their own coarse output,
#: which looks flat, so they need a tiny sensitivity before they fail as rarely as 1% of the tiles.
#: FidelityFX scales its cutoff and its motion factor together (at 60 Hz the motion term alone
#: makes a running camera's tiles coarse at any cutoff).
#: Every grid also reaches one step past the default, so that a method that fails rarely at its
#: default (an easy map) can still be read at 2% and 5% failing tiles. The grids are densest where
#: the methods' 1-5% failing tiles fell on the test and validation maps (models: 0.7-1.0x; Yang:
#: 1/256-1/8 fast, 1/32-1/2 slow): the matched-quality table interpolates linearly between points,
#: which under-reads a concave curve when they are far apart.
MODEL_SWEEP = (0.25, 0.5, 0.7, 0.8, 0.9, 1.0, 1.25, 2.0)
#: A budget's sweep (``NAME@k:bS``): the share of the work saved every frame.
SAVING_SWEEP = (0.2, 0.3, 0.4, 0.5, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9)
PSNR_SWEEP_DB = (12.0, 6.0, 3.0, 2.0, 1.0, 0.0, -2.0, -6.0)
BASELINE_SWEEP = (1 / 256, 1 / 128, 1 / 64, 1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0, 4.0)


class PlayError(sdk.ParameterError):
    """Bad arguments to :func:`play` (an unknown method, a bad reuse interval, too few frames)."""

    def __init__(self, message: str, parameter: str = "methods") -> None:
        super().__init__(message, parameter)


@dataclass(frozen=True)
class MethodSpec:
    """One method of a closed-loop run: ``name`` as reported, ``kind`` (a :data:`METHOD_KINDS` key or
    ``"model"``), the ``model`` (shipped name or path), its ``reuse`` interval k (1: every frame) and
    how a reused tile reduces the estimates its pixels carry (:data:`REUSE_REDUCTIONS`), what it does
    with tiles the network did not see (:data:`REUSE_UNSEEN`), the ``history`` weight of the carried
    estimates on the network's frames, the ``refresh`` share of unseen tiles that runs the network
    early and the carry's pixel ``step`` (``sdk.PredictionReuse``'s arguments of those names); ``budget``, the share of
    the work its rates save every frame (``sdk.select_rates_for_saving``) instead of a threshold; ``floor``, the
    least share saved under its threshold (the same function with the threshold); ``alone``, with an engine's own
    rates (``play(engine_rates=)``), the model chooses its rates without them and the combiner meets them after
    (by default it judges the rate the device shades: ``select_rates(engine_rates=)``)."""

    name: str
    kind: str
    model: str = ""
    reuse: int = 1
    reduce: str = "mean"
    unseen: str = "full"
    history: float = 0.0
    refresh: float | None = None
    step: int | None = None
    rescale: float = 0.0
    carry_scale: float = 1.0
    carry: str = "estimates"
    budget: float | None = None
    floor: float | None = None
    alone: bool = False


def parse_methods(text: str | Iterable[str]) -> list[MethodSpec]:
    """``"jnyang,jnyang@4,yang2019,fidelityfx"`` -> specs. Anything not in :data:`METHOD_KINDS` is a
    model (a shipped name or an ``.onnx`` path), optionally ``@k`` for prediction reuse, then
    ``:reduction`` (:data:`REUSE_REDUCTIONS`), ``:unseen`` (:data:`REUSE_UNSEEN`), ``:hW`` (history
    weight W), ``:rS`` (refresh share S), ``:sN`` (the carry keeps one pixel of N per axis), ``:vA``
    (carried estimates rescaled by the blocks' variance to the power A), ``:cF`` (carried estimates
    multiplied by F), ``:features`` (:data:`REUSE_CARRIES`: carry a splitting model's trunk features), ``:bS``
    (a budget: save a share S of the work every frame) and ``:fS`` (a floor of S saved under the threshold) in any
    order (``jnyang@4:mean:fresh``, ``jnyang@4:r0.05``,
    ``jnyang@4:s4``, ``split.onnx@4:features``, ``jnyang@1:b0.6``). Yang 2019 takes a budget too
    (``yang2019:b0.6``, ``yang2019-unseen-1x1:b0.6``: its estimates through the same selection)."""
    if not isinstance(text, str) and (not isinstance(text, Iterable) or not all(isinstance(t, str) for t in text)):
        raise PlayError(f"methods: expected a comma-separated string or a list of method names, got {text!r}")
    # (a model file whose name holds a comma or an '@' is taken whole: "model@v2.onnx" is no reuse interval)
    whole = isinstance(text, str) and _is_file(text.strip())
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) and not whole else
                                 [text] if isinstance(text, str) else text) if t.strip()]
    if not items:
        raise PlayError("expected at least one method, e.g. jnyang,yang2019,fidelityfx")
    out = []
    for item in items:
        if item in METHOD_KINDS:
            out.append(MethodSpec(item, item))
            continue
        kind, colon, option = item.partition(":")
        if colon and kind in METHOD_KINDS:  # (a baseline's option: Yang's budget alone)
            if not kind.startswith("yang2019") or option[:1] != "b":
                raise PlayError(f"method {item!r}: of the baselines only Yang 2019 takes an option, a budget ':bS' "
                                "(e.g. yang2019:b0.6; FidelityFX decides by its own rule, not a threshold per rate)")
            out.append(MethodSpec(item, kind, budget=_budget(option, item, "budget")))
            continue
        model, _, k = item.rpartition("@") if "@" in item and not _is_file(item) else (item, "", "1")
        k, *options = k.split(":")
        alone = [o for o in options if o == "alone"]
        options = [o for o in options if o != "alone"]
        if not (k.isascii() and k.isdigit()) or len(k) > 6 or int(k) < 1:  # ("²".isdigit(); int() refuses 5000 digits)
            raise PlayError(f"method {item!r}: the reuse interval after '@' must be an integer >= 1 (e.g. jnyang@4)")
        reduce = [o for o in options if o in REUSE_REDUCTIONS]
        unseen = [o for o in options if o in REUSE_UNSEEN]
        history = [_share(o, item, "history weight") for o in options if o[:1] == "h"]
        refresh = [_share(o, item, "refresh share") for o in options if o[:1] == "r"]
        step = [_step(o, item) for o in options if o[:1] == "s"]
        rescale = [_exponent(o, item) for o in options if o[:1] == "v"]
        carry = [o for o in options if o in REUSE_CARRIES]
        scale = [_carry_scale(o, item) for o in options if o[:1] == "c" and o not in REUSE_CARRIES]

        budget = [_budget(o, item, "budget") for o in options if o[:1] == "b"]
        floor = [_budget(o, item, "floor") for o in options
                 if o[:1] == "f" and o not in REUSE_UNSEEN and o not in REUSE_CARRIES]
        if (len(alone) > 1 or len(reduce) > 1 or len(unseen) > 1 or len(history) > 1 or len(refresh) > 1 or len(step) > 1
                or len(rescale) > 1 or len(scale) > 1 or len(carry) > 1 or len(budget) + len(floor) > 1
                or len(reduce) + len(unseen) + len(history) + len(refresh) + len(step) + len(rescale) + len(scale)
                + len(carry) + len(budget) + len(floor) != len(options)):
            raise PlayError(f"method {item!r}: after '@k' expected {_OPTIONS}")
        out.append(MethodSpec(item, "model", model, int(k), reduce[0] if reduce else MethodSpec.reduce,
                              unseen[0] if unseen else MethodSpec.unseen, history[0] if history else 0.0,
                              refresh[0] if refresh else None, step[0] if step else None,
                              rescale[0] if rescale else 0.0, scale[0] if scale else 1.0,
                              carry[0] if carry else MethodSpec.carry, budget[0] if budget else None,
                              floor[0] if floor else None, bool(alone)))
    if len({m.name for m in out}) != len(out):
        raise PlayError(f"methods: each method once, got {', '.join(items)}")
    return out


def _a_word(option: str) -> bool:
    """Whether an option that starts with a numbered one's letter is a word rather than a mistyped number: ':foo'
    is no floor, ':fx' or ':f2' a floor mistyped."""
    return len(option) > 2 and not any(c.isdigit() for c in option[1:])


def _unknown(option: str, item: str) -> PlayError:
    """An option that is a word (:func:`_a_word`) but none of the words: named as unknown, with the options."""
    return PlayError(f"method {item!r}: unknown option ':{option}'; after '@k' expected {_OPTIONS}")


def _is_file(text: str) -> bool:
    try:
        return Path(text).is_file()
    except (OSError, ValueError):  # (a name too long for the file system; a NUL byte)
        return False


def _step(option: str, item: str) -> int:
    if _a_word(option):
        raise _unknown(option, item)
    if not (option[1:].isascii() and option[1:].isdigit()) or len(option) > 7 or int(option[1:]) < 1:
        raise PlayError(f"method {item!r}: ':{option}' is not a pixel step: expected ':s' and an integer >= 1 that "
                        "divides the model's tile size, e.g. jnyang@4:s4")
    return int(option[1:])


def _number(option: str, item: str, lo: float, hi: float, what: str, expect: str, below_hi: bool = False) -> float:
    """The number after an option's letter (``:v0.5``), else a :class:`PlayError` naming ``what`` was expected:
    ``expect``. In ``[lo, hi]``, or ``[lo, hi)`` with ``below_hi``."""
    if _a_word(option):
        raise _unknown(option, item)
    try:
        v = float(option[1:])
    except ValueError:
        v = math.nan
    if not (lo <= v < hi if below_hi else lo <= v <= hi):  # (NaN fails both)
        raise PlayError(f"method {item!r}: ':{option}' is not a {what}: expected ':{option[0]}' and {expect}")
    return v


def _exponent(option: str, item: str) -> float:
    return _number(option, item, 0.0, sdk.MAX_RESCALE, "rescale exponent",
                   f"a number in [0, {sdk.MAX_RESCALE:g}], e.g. jnyang@4:v0.5")


def _carry_scale(option: str, item: str) -> float:
    lo, hi = 1.0 / sdk.MAX_CARRY_SCALE, sdk.MAX_CARRY_SCALE
    return _number(option, item, lo, hi, "carry scale", f"a factor in [{lo:g}, {hi:g}], e.g. jnyang@4:c1.08")


def _budget(option: str, item: str, what: str) -> float:
    return _number(option, item, 0.0, sdk.MAX_SAVING, what, "the share of the shading work to save every frame, a "
                   f"number in [0, {sdk.MAX_SAVING:g}], e.g. jnyang@1:{option[0]}0.6")


def _share(option: str, item: str, what: str) -> float:
    return _number(option, item, 0.0, 1.0, what, f"a number in [0, 1), e.g. jnyang@1:{option[0]}0.5", below_hi=True)


def fail_rule(metric: str, threshold: float) -> str:
    """When a tile fails, in words: ``its true jnyang error is over 0.25``; PSNR, a higher-is-better
    metric, ``its true psnr is under 35``."""
    from rtp import metrics

    if metrics.metric_info(metric).higher_is_better:
        return f"its true {metric} is under {threshold:g}"
    return f"its true {metric} error is over {threshold:g}"


def saved_at(points: Sequence[tuple[float, float]], fail: float) -> float | None:
    """Work saved at ``fail`` failing tiles along a sweep of ``(fail share, work saved)`` points: the
    best saving among points failing at most ``fail``, interpolated linearly towards the next point
    that fails more (never below the point's own saving: a next point that fails more and saves less leaves it
    as it is). Points that fail equally often are alternatives: only the one that saves the most counts, as a
    point of its own and as the next point of those that fail less. None when every point fails more than
    ``fail``; a :class:`~rtp.sdk.ParameterError` for a NaN share or saving (it has no place on the sweep)."""
    try:
        pairs = [(float(f), float(w)) for f, w in points]
        fail = float(fail)
    except (TypeError, ValueError, OverflowError):
        raise sdk.ParameterError(f"saved_at: expected (fail share, work saved) pairs of numbers and a fail share, got "
                                 f"{points!r} and {fail!r}") from None
    # (a NaN point was placed wherever sorting left it: the same sweep read 90%, 65% or None by the order given)
    if math.isnan(fail) or any(math.isnan(f) or math.isnan(w) for f, w in pairs):
        raise sdk.ParameterError(f"saved_at: expected numbers, not NaN, for the fail share and every point's fail "
                                 f"share and saving, got {reprlib.repr(pairs)} and {fail!r}")
    # the most saved at each failing share (the line ran towards the point of the next share that saved the least:
    # (1%, 50%), (3%, 40%), (3%, 80%) read 50% at 2%, not 65%)
    top: dict[float, float] = {}
    for f, w in pairs:
        top[f] = max(w, top.get(f, w))
    pts = sorted(top.items())
    if not pts or pts[0][0] > fail:
        return None
    best = None
    for (f0, w0), (f1, w1) in zip(pts, pts[1:] + [(math.inf, pts[-1][1])]):
        if f0 <= fail:
            # (towards a point that saves less the line falls below this one's saving, which runs at f0 <= fail)
            w = w0 if f1 == math.inf or w1 <= w0 else w0 + (w1 - w0) * min(1.0, (fail - f0) / (f1 - f0))
            best = w if best is None else max(best, w)
    return best


# -- one method at one parameter: its own history ---------------------------------------------------


@dataclass
class _Loop:
    method: MethodSpec
    param: float
    label: str  # the parameter as reported
    decide: Callable[[Any, np.ndarray | None, np.ndarray, _Loop], np.ndarray]
    default: bool = False
    history: np.ndarray | None = None  # the frame it displayed last
    rates: np.ndarray | None = None  # the rates it chose last
    rates_hw: tuple[int, int] | None = None  # the size of the frame it chose them for (dynamic resolution)
    saved: list[float] = field(default_factory=list)
    fail: list[float] = field(default_factory=list)
    change: list[float] = field(default_factory=list)
    flip: list[float] = field(default_factory=list)
    ms: list[float] = field(default_factory=list)
    ran: list[float] = field(default_factory=list)  # models: the network's work per frame (1: the whole frame)
    engine: np.ndarray | None = None  # the engine's own rates of the current frame (play(engine_rates=))

    def summary(self) -> dict[str, Any]:
        def mean(v: list[float], skip: int = 1) -> float:
            a = np.array(v[skip:], np.float64)
            a = a[np.isfinite(a)]
            return float(a.mean()) if a.size else float("nan")

        return {
            "method": self.method.name, "parameter": self.label, "value": self.param, "default": self.default,
            "work_saved": mean(self.saved), "fail_share": mean(self.fail), "flip_mean": mean(self.flip),
            "work_saved_p05": float(np.percentile(self.saved[1:], 5)) if len(self.saved) > 1 else float("nan"),
            "rate_change": mean(self.change, 2),
            "predict_ms": float(np.median(self.ms[1:])) if len(self.ms) > 1 else float("nan"),
            "network_frames": mean([float(r) for r in self.ran]) if self.method.kind == "model" else float("nan"),
        }


# -- the run ------------------------------------------------------------------------------------------


def _engine_sentence(settings: dict[str, Any]) -> str:
    """The sentence of play.md's header on the engine's own rates, where the run had them (else empty)."""
    engine = settings.get("engine_rates")
    if not engine:
        return ""
    return (f" The engine's own rates ({engine['image']}, rtp.evaluate.engine_rates) meet every method's in a "
            f"{engine['combiner']} combiner: the rates shaded, saved and judged are the combination's, full's row is "
            "the engine's rates alone, a tile fails only where the rate shaded is not the engine's own, and rtp's "
            "models and the oracle choose beside the engine's rates (a model's :alone without them).")


def _dynamic_sentence(settings: dict[str, Any]) -> str:
    """The sentence of play.md's header on dynamic resolution, where the run had it (else empty)."""
    dyn = settings.get("dynamic_resolution")
    if not dyn:
        return ""
    sizes = ", ".join(f"{w}x{h}" for w, h in dyn["sizes"])
    scales = ", ".join(f"{v:g}" for v in dyn["scales"])
    if len(dyn["sizes"]) == 1:  # (one scale, or scales that round to one size: it said "drawn at 80x48 in turn")
        several = len(dyn["scales"]) > 1
        drawn = (f"every frame is drawn at {sizes} (scale{'s' if several else ''} {scales} of the size"
                 f"{', all of them that size' if several else ''})")
    else:
        drawn = (f"the frames are drawn at {sizes} in turn, each size held {dyn['every']} frames (scales {scales} of "
                 "the size)")
    return (f" Dynamic resolution: {drawn}; every method chooses, shades and is "
            "judged at each frame's own size, its history the frame it displayed at the size it was drawn, and its "
            "saving is a share of each frame's own pixels.")


def _other_tiles(settings: dict[str, Any]) -> str:
    """The sentence of play.md's header that names the models run on other tiles than their own (the
    hardware's: finer, each takes its model tile's rate; coarser, each decides on the worst model tile it
    covers), or nothing."""
    tile = settings["tile_size"]
    other = {k: t for k, t in (settings.get("model_tiles") or {}).items() if t != tile}
    if not other:
        return ""
    told = [f"{k} ({t}px: each {tile}px tile "
            + (f"decides on the worst of the {(tile // t) ** 2} model tiles it covers)" if t < tile
               else "takes the rate of the model tile it lies in)") for k, t in other.items()]
    return f" Models on tiles other than their own: {'; '.join(told)}."


@dataclass
class PlayReport:
    """What :func:`play` measured: per path and (method, parameter) the summaries (``rows``), the
    matched-quality table (``matched``: saving at each :data:`FAIL_LEVELS` share), per-frame series
    (``frames``: path -> method label -> field -> list), each path's unseen share per frame, the
    settings and the files written."""

    settings: dict[str, Any]
    rows: list[dict[str, Any]] = field(default_factory=list)
    matched: list[dict[str, Any]] = field(default_factory=list)
    frames: dict[str, dict[str, dict[str, list[float]]]] = field(default_factory=dict)
    unseen: dict[str, list[float]] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"settings": self.settings, "rows": self.rows, "matched": self.matched, "frames": self.frames,
                "unseen": self.unseen, "files": self.files}

    def ratios(self, method: str, against: str, level: float = 0.05) -> dict[str, float]:
        """Per path, ``method``'s saving over ``against``'s at the ``level`` failing share (nan where
        either cannot reach it: its sweep never fails that rarely, or never that often). A method the report does
        not hold, or a ``level`` not among :data:`FAIL_LEVELS` (the only shares it is read at), is a
        :class:`PlayError` (either read NaN on every path, as if the method could not reach it)."""
        methods = list(dict.fromkeys(m["method"] for m in self.matched))
        for name, key in ((method, "method"), (against, "against")):
            if name not in methods:
                raise PlayError(f"ratios: {key}: expected one of the report's methods ({', '.join(map(str, methods))}), "
                                f"got {name!r}", key)
        if not any(_finite(level) and level == f for f in FAIL_LEVELS):
            raise PlayError(f"ratios: level: expected one of the matched table's failing shares "
                            f"{', '.join(f'{f:g}' for f in FAIL_LEVELS)}, got {level!r}", "level")

        def at(name: str, path: str) -> float:
            m = next((m for m in self.matched if m["path"] == path and m["method"] == name and m["fail_share"] == level),
                     None)
            return float("nan") if m is None or m.get("capped") else float(m["work_saved"])

        out = {}
        for path in self.unseen:
            a, b = at(method, path), at(against, path)
            out[path] = a / b if b and np.isfinite(a) and np.isfinite(b) and b > 0 else float("nan")
        return out

    def to_markdown(self) -> str:
        s = self.settings
        flip = (f"FLIP of the displayed frame against full-rate shading once every {s['flip_every']} frames"
                + (f" (none of these {s['frames']}: the first is frame {s['flip_every']})"
                   if s["frames"] <= s["flip_every"] else "")
                if s["flip_every"] else "no FLIP of the displayed frames")
        lines = [f"# Closed-loop VRS: {s['scene']}", "",
                 f"Paths {', '.join(self.unseen)} ({s['frames']} frames at {s['fps']:g} Hz, seed {s['seed']}), "
                 f"{s['size'][0]}x{s['size'][1]}, {s['tile_size']}px tiles. A tile fails when "
                 f"{fail_rule(s['fail_metric'], s['fail_threshold'])}; {flip}. Shading: {s.get('shading', 'renderer')}; "
                 f"each method's history: {s.get('history', 'own displayed frame')}. The first frame (no history) is "
                 f"left out.{_other_tiles(s)}{_engine_sentence(s)}{_dynamic_sentence(s)}", ""]
        for path, unseen in self.unseen.items():
            u = np.array(unseen[1:])
            cam = s.get("cameras", {}).get(path)
            walk = (f"The camera walks {cam['length_m']:.1f} m, its eye {cam['eye_height_m']:.2f} m over the floor. "
                    if cam else "")
            lines += [f"## {path}", "", f"{walk}Unseen share per frame: mean {100 * u.mean():.2f}%, "
                      f"95th percentile {100 * np.percentile(u, 95):.2f}%, max {100 * u.max():.2f}%.", "",
                      "Matched quality (work saved where the method fails that share of tiles; - : its sweep never "
                      "fails that rarely; >= : never that often, its saving at the largest share it reached, a lower "
                      "bound):", "",
                      "| method | " + " | ".join(f"saved at {100 * f:g}% fails" for f in FAIL_LEVELS) + " |",
                      "|---|" + "---:|" * len(FAIL_LEVELS)]
            for method in dict.fromkeys(m["method"] for m in self.matched if m["path"] == path):
                cells = [next(m for m in self.matched if m["path"] == path and m["method"] == method
                              and m["fail_share"] == f) for f in FAIL_LEVELS]
                lines.append(f"| {method} | " + " | ".join(
                    "-" if not np.isfinite(c["work_saved"]) else f"{'>= ' if c.get('capped') else ''}{100 * c['work_saved']:.1f}%"
                    for c in cells) + " |")
            # (a saving of 0 is one: `or np.nan` read it as none and left the method out). A share the sweep never
            # fails that rarely has no worst frames' saving either: "-", as in the matched table (a method that never
            # failed under 5% was left out of this table); a method with a saving and no worst frames' saving is a path
            # kept by an older run, which has none
            here = [m for m in self.matched if m["path"] == path]
            older = {m["method"] for m in here if _finite(m["work_saved"]) and not _finite(m.get("work_saved_p05"))}
            lows = [m for m in here if _finite(m.get("work_saved_p05"))]
            if lows:
                lines += ["", "The worst 5% of frames' saving where the method fails those shares of tiles (what a "
                          "frame-time budget plans for; a budget, `NAME@k:bS`, saves the same on every frame):", "",
                          "| method | " + " | ".join(f"worst frames at {100 * f:g}% fails" for f in FAIL_LEVELS) + " |",
                          "|---|" + "---:|" * len(FAIL_LEVELS)]
                for method in dict.fromkeys(m["method"] for m in here if m["method"] not in older):
                    by_share = {m["fail_share"]: m for m in lows if m["method"] == method}
                    lines.append(f"| {method} | " + " | ".join(
                        "-" if f not in by_share else f"{'>= ' if by_share[f].get('capped') else ''}"
                        f"{100 * by_share[f]['work_saved_p05']:.1f}%" for f in FAIL_LEVELS) + " |")
            lines += ["", "Every run (the default parameter in bold):", "",
                      "| method | parameter | saved | saved, worst 5% of frames | failing tiles | mean FLIP | rate changes "
                      "| choose (ms) | network runs |",
                      "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
            for r in (r for r in self.rows if r["path"] == path):
                p = f"**{r['parameter']}**" if r["default"] else r["parameter"]
                net = "" if not np.isfinite(r["network_frames"]) else f"{100 * r['network_frames']:.0f}%"
                flip = "-" if not np.isfinite(r["flip_mean"]) else f"{r['flip_mean']:.4f}"
                low = r.get("work_saved_p05", float("nan"))  # (a path kept by an older run has none)
                low_cell = f"{100 * low:.1f}%" if low is not None and np.isfinite(low) else "-"
                # (none measured where every frame after the second changed size: dynamic resolution's SCALES@1)
                change = f"{100 * r['rate_change']:.1f}%" if _finite(r["rate_change"]) else "-"
                lines.append(f"| {r['method']} | {p} | {100 * r['work_saved']:.1f}% | {low_cell} | "
                             f"{100 * r['fail_share']:.2f}% | {flip} | {change} | "
                             f"{r['predict_ms']:.2f} | {net} |")
            lines.append("")
        return "\n".join(lines)


def _finite(value: Any) -> bool:
    """Whether a report's number is one (play.json writes NaN as null; a path kept by an older run has none)."""
    return isinstance(value, (int, float, np.number)) and not isinstance(value, bool) and bool(np.isfinite(value))


def _integer(key: str, value: Any, lo: int, what: str = "") -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise PlayError(f"{key}: expected an integer of at least {lo}{what}, got {value!r}", key)
    return int(value)


def _check(frames: int, fps: float, flip_every: int, size: tuple[int, int], reuse: Iterable[int]) -> None:
    from rtp.capture.paths import MAX_FRAMES, MAX_SECONDS

    if _integer("frames", frames, 3, " (the first has no history)") > MAX_FRAMES:
        raise PlayError(f"frames: expected at most {MAX_FRAMES} a path (ten minutes at 60 frames a second), got {frames}",
                        "frames")
    number = not isinstance(fps, bool) and isinstance(fps, (int, float, np.number))
    try:
        rate = float(fps) if number else math.nan
    except OverflowError:  # (an int past float's range: math.isfinite raised it, untyped)
        rate = math.inf
    if not (math.isfinite(rate) and rate > 0):
        raise PlayError(f"fps: expected a finite number > 0, got {fps!r}", "fps")
    if (frames - 1) / fps > MAX_SECONDS:  # (a long walk: its planning took seconds to hours, then failed)
        raise PlayError(f"fps: {frames} frames at {fps:g} frames a second last {(frames - 1) / fps:,.0f} s; expected a path "
                        f"of at most {MAX_SECONDS:.0f} s (ten minutes): more frames a second, or fewer frames", "fps")
    _integer("flip_every", flip_every, 0, " (0: no FLIP)")
    if not isinstance(size, (tuple, list)) or len(size) != 2 or not all(
            isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 16 for v in size):
        raise PlayError(f"size: expected (width, height), integers of at least 16 pixels, got {size!r}", "size")


def _check_options(seed: Any, workers: Any, unseen_fraction: Any, flags: dict[str, Any]) -> None:
    """The arguments of :func:`play` that only travel to the frames: checked before any work."""
    _integer("seed", seed, 0, " (which path through the map)")
    _integer("workers", workers, 1)
    if isinstance(unseen_fraction, bool) or not isinstance(unseen_fraction, (int, float, np.number)) \
            or not 0.0 <= unseen_fraction < 1.0:
        raise PlayError(f"unseen_fraction: expected a share in [0, 1), got {unseen_fraction!r}", "unseen_fraction")
    for key, value in flags.items():  # ("no" is a true string)
        if not isinstance(value, bool):
            raise PlayError(f"{key}: expected True or False, got {value!r}", key)


def play(
    scene: str,
    methods: str | Iterable[str] = DEFAULT_METHODS,
    *,
    paths: Sequence[str] = ("slow", "fast"),
    frames: int = 300,
    fps: float = 60.0,
    seed: int = 0,
    size: tuple[int, int] = (1280, 720),
    tile_size: int = sdk.DEFAULT_TILE_SIZE,
    fail_metric: str = "jnyang",
    fail_threshold: float | None = None,
    sweep: bool = True,
    flip_every: int = 20,
    unseen_fraction: float = 0.5,
    cache_dir: str | None = None,
    out: str | Path | None = None,
    exact: bool = True,
    plots: bool = True,
    animation: bool = True,
    workers: int = 1,
    open_loop: bool = False,
    engine_rates: str | None = None,
    combiner: str = "max",
    dynamic_resolution: DynamicResolution | None = None,
    progress: Callable[[int], None] | None = None,
    stage: Callable[[str], None] | None = None,
    kept: Callable[[str], None] | None = None,
    palette: str = "paper",
) -> PlayReport:
    """Run the closed loop (module docstring) on ``scene`` (a map name or ``procedural:N``) along
    each of ``paths`` (profiles of :data:`~rtp.capture.paths.PATH_PROFILES`: one name or a list), every method swept over
    its parameter (``sweep=False``: defaults only). ``exact=False`` shades each method's frame by
    compositing the uniform-rate images (:func:`rtp.capture.paths.composite`) instead of the
    renderer's per-tile VRS pass. Writes ``play.md``, ``play.json``, and with
    ``plots`` the curves, the per-frame plot and (``animation``) a GIF per path into ``out``, then removes the
    pictures of rtp play's own names there that its report does not list (another run's).
    ``workers`` > 1 plays the paths in that many processes at once. ``open_loop=True`` is the
    ablation: every method's history is the full-rate frame instead of its own (what the dataset's
    reprojection holds). ``engine_rates`` (:data:`~rtp.evaluate.ENGINE_IMAGES`) gives the engine rates of its own
    each frame, which the hardware's ``combiner`` (``min``, ``max``, ``sum``) meets with every method's: the rates
    shaded, saved and judged are the combination's (``full``'s row is the engine's rates alone), a tile fails only
    where the rate shaded is not the engine's own, and rtp's models and the oracle choose beside the engine's rates
    (``select_rates(engine_rates=)``; a model's ``:alone`` chooses without them). ``dynamic_resolution`` (a
    :class:`rtp.capture.paths.DynamicResolution`, such as ``DynamicResolution((1.0, 0.75), 30)``) draws the
    frames at its schedule's sizes of ``size`` (the largest), as an engine's dynamic resolution does: each
    method chooses, shades and is judged at the frame's own size, its history the frame it displayed at the
    size it was drawn; the saving is a share of each frame's own pixels. ``progress(n)`` is called after
    every frame; ``stage(text)`` as each step between frames begins (a path's map loaded, its cameras
    planned, its renderer started, its first frame, its GIF, then the report and plots: seconds on a
    large map, while ``progress`` does not move), as ``"fast: planning the camera path"``; ``"PATH:
    playing"`` once its frames count and ``"PATH: done"`` at its end (with ``workers``, which paths are
    in a step). ``kept(path)`` is called once a path's results are kept in ``out`` for the same call to resume
    from (as the path ends, or at the start for a path read back from an interrupted run): what an interrupted
    run leaves. ``palette``: the GIFs' rate overlays and key in :data:`rtp.sdk.OVERLAY_PALETTES`' colours, ``"paper"``
    or ``"cvd"`` (told apart under colour-vision deficiency); it changes only those pictures, so a path kept by an
    interrupted run with another palette is read back, not played again (its GIF kept in that palette, a warning
    saying so)."""
    from rtp import metrics
    from rtp.capture.paths import PATH_PROFILES, DynamicResolution

    if not isinstance(palette, str) or palette not in sdk.OVERLAY_PALETTES:
        raise PlayError(f"palette: expected one of {', '.join(map(repr, sdk.OVERLAY_PALETTES))} (the GIFs' rate "
                        f"overlay colours), got {palette!r}", "palette")
    specs = parse_methods(methods)
    _check(frames, fps, flip_every, size, (m.reuse for m in specs))
    if dynamic_resolution is not None and not isinstance(dynamic_resolution, DynamicResolution):
        raise PlayError(f"dynamic_resolution: expected an rtp.capture.paths.DynamicResolution (or None), got "
                        f"{type(dynamic_resolution).__name__}", "dynamic_resolution")
    if dynamic_resolution is not None:  # (a schedule the path ends before: play.md named sizes never drawn)
        first: dict[tuple[int, int], int] = {}
        for i in range(len(dynamic_resolution.scales)):
            first.setdefault(dynamic_resolution.size(i * dynamic_resolution.every, (size[0], size[1])),
                             i * dynamic_resolution.every)
        if max(first.values()) >= frames:
            never = [f"{w}x{h}" for (w, h), i in first.items() if i >= frames]
            raise PlayError(f"dynamic_resolution: each scale is held {dynamic_resolution.every} frames, so a path of "
                            f"{frames} frames never draws {', '.join(never)}: give at least "
                            f"{max(first.values()) + 1} frames (frames=, --frames) or hold each scale fewer frames",
                            "dynamic_resolution")
    if engine_rates is not None and engine_rates not in ENGINE_IMAGES:
        raise PlayError(f"engine_rates: expected one of {', '.join(ENGINE_IMAGES)} (or None), got {engine_rates!r}",
                        "engine_rates")
    if combiner not in _SELECTING_COMBINERS:  # (those through which a method's rate reaches the frame)
        raise PlayError(f"combiner: expected one of {', '.join(_SELECTING_COMBINERS)}, got {combiner!r}", "combiner")
    if engine_rates is None and combiner != "max":  # (it was taken and nothing combined)
        raise PlayError(f"combiner: the hardware's combiner of engine_rates' rates and each method's; without "
                        f"engine_rates (--engine-rates) there is nothing for {combiner!r} to combine", "combiner")
    if any(m.alone for m in specs) and engine_rates is None:
        raise PlayError("methods: ':alone' chooses without the engine's own rates: give engine_rates (--engine-rates)")
    _check_options(seed, workers, unseen_fraction, {"sweep": sweep, "exact": exact, "plots": plots,
                                                     "animation": animation, "open_loop": open_loop})
    paths = [paths] if isinstance(paths, str) else paths  # (one name, not its letters)
    if not isinstance(paths, (list, tuple)) or not paths:
        raise PlayError(f"paths: expected a profile name or a non-empty list of them, got {paths!r}", "paths")
    for p in paths:
        if p not in PATH_PROFILES:
            raise PlayError(f"paths: unknown profile {p!r}; known: {', '.join(PATH_PROFILES)}", "paths")
    if len(set(paths)) < len(paths):  # (a path given twice was reported twice, its frames counted twice)
        raise PlayError(f"paths: each profile once, got {', '.join(paths)}", "paths")
    try:
        info = metrics.metric_info(fail_metric)  # rtp's own or a plugin's
        if workers > 1 and len(dict.fromkeys(paths)) > 1:  # (the paths in worker processes: entry points only)
            metrics.check_worker_metrics(fail_metric)
    except metrics.MetricParameterError as err:
        raise PlayError(f"fail_metric (computed per frame and rate): {err}", "fail_metric") from None
    try:
        fail_thr = info.default_threshold if fail_threshold is None else sdk.check_threshold(fail_threshold,
                                                                                              info.higher_is_better)
    except sdk.ParameterError as err:
        raise PlayError(f"fail_{err}", "fail_threshold") from None
    metrics.check_dependencies((fail_metric, "flip") if flip_every else (fail_metric,))
    predictors: dict[str, sdk.ShadingRatePredictor] = {}
    for m in specs:  # fails early on a bad model
        if m.kind == "model" and m.model not in predictors:
            try:
                predictors[m.model] = sdk.load(m.model)
            except sdk.ModelNotFoundError as err:  # a typo of a method's name reads as a missing model
                raise PlayError(f"method {m.name!r}: not one of the methods ({', '.join(METHOD_KINDS)}), so a model, "
                                f"and {err}") from err
    for m in specs:
        # (run tiles other than a model's are the hardware's, as sdk.load(tile_size=) gives them: finer, AMD's and
        # Intel's 8 under a 16-pixel model, each takes its model tile's rate; coarser, NVIDIA's 16 over an 8-pixel
        # model, each decides on the worst of the model tiles it covers)
        own = predictors[m.model].tile_size if m.kind == "model" else tile_size
        if isinstance(tile_size, int) and tile_size > 0 and max(own, tile_size) % min(own, tile_size):
            raise PlayError(f"method {m.name}: the model uses {own}px tiles, the run {tile_size}px (run at {own}px "
                            f"tiles, or finer or coarser ones that divide them or that they divide: tile_size=, "
                            f"--tile-size)", "tile_size")
        static = predictors[m.model].static_size if m.kind == "model" else None
        if m.unseen == "fresh" and static is not None:
            h, w = static
            raise PlayError(f"method {m.name}: ':fresh' runs the network on crops, but the model takes only "
                            f"{w}x{h} frames (export it with dynamic sizes)")
    if isinstance(tile_size, bool) or not isinstance(tile_size, int) or tile_size < 4 or tile_size % 4:
        # (the renderer's VRS pass refused it only once the first frame was drawn: exit 1, not 2)
        raise PlayError(f"tile_size: expected a positive multiple of 4 pixels (the largest rate), got {tile_size!r}",
                        "tile_size")
    if any(m.kind.startswith("fidelityfx") for m in specs) and tile_size not in (8, 16, 32):
        raise PlayError(f"FidelityFX supports 8, 16 and 32 pixel tiles, the run uses {tile_size}", "tile_size")

    # each reuse method's pixel step as the carry resolves it (a bad one fails here, before the run)
    steps = {m.name: sdk.PredictionReuse(predictors[m.model], m.reuse, step=m.step, rescale=m.rescale,
                                         carry_scale=m.carry_scale, carry=m.carry, reduce=m.reduce,
                                         history=m.history).step
             for m in specs if m.kind == "model"}
    settings = {"scene": scene, "methods": [m.name for m in specs], "paths": list(paths), "frames": frames, "fps": fps,
                "seed": seed, "size": list(size), "tile_size": tile_size, "fail_metric": fail_metric,
                "fail_threshold": fail_thr, "sweep": sweep, "flip_every": flip_every,
                # the grids, so that runs read off different grids are not mistaken for one another
                "grids": {"model": list(MODEL_SWEEP), "psnr_db": list(PSNR_SWEEP_DB), "baseline": list(BASELINE_SWEEP),
                          "saving": list(SAVING_SWEEP)}
                if sweep else None,
                "unseen_fraction": unseen_fraction, "shading": "renderer" if exact else "composite",
                "history": "full-rate frame (open loop)" if open_loop else "own displayed frame",
                "engine_rates": None if engine_rates is None else {"image": engine_rates, "combiner": combiner},
                "dynamic_resolution": None if dynamic_resolution is None else {
                    "scales": list(dynamic_resolution.scales), "every": dynamic_resolution.every,
                    "sizes": [list(z) for z in dynamic_resolution.sizes((size[0], size[1]))]},
                "models": {k: str(p.path) for k, p in predictors.items()},
                "model_tiles": {k: p.tile_size for k, p in predictors.items()},  # (play.md names those on other tiles)
                "reuse": {m.name: {"k": m.reuse, "reduce": m.reduce, "unseen": m.unseen, "history": m.history,
                                   "refresh": m.refresh, "step": steps[m.name], "rescale": m.rescale,
                                   "carry_scale": m.carry_scale, "carry": m.carry}
                          for m in specs if m.kind == "model" and (m.reuse > 1 or m.history > 0)}}
    from rtp.capture import check_frame_memory, check_frame_size, check_scene

    # a scene it cannot load, a size past this machine's memory or one the renderer cannot draw fails
    # before the output folder is made
    check_scene(scene, cache_dir, None, None)
    w, h = check_frame_size(size, renderer=False)
    check_frame_memory("play", (w, h), processes=min(workers, len(dict.fromkeys(paths))), metrics=(fail_metric,),
                       loops=sum(_loop_count(m, sweep, predictors) for m in specs), models=len(predictors),
                       error=PlayError)
    check_frame_size((w, h))
    if workers > len(paths):  # (as capture and targets: a process a work item at most; --workers 4 on one path
        # played it in this process without a word)
        log.warning("workers %d for %d path%s (%s): a process a path at most, so %s", workers, len(paths),
                    "" if len(paths) == 1 else "s", ", ".join(paths),
                    "it is played in this process" if len(paths) == 1 else f"{len(paths)} processes play them")
    report = PlayReport(settings)
    outdir = Path(out) if out is not None else None
    guard = contextlib.ExitStack()
    if outdir is not None:
        created, made = not outdir.exists(), outdir
        outdir.mkdir(parents=True, exist_ok=True)

        def drop_if_empty(exc_type: object, *_: object) -> bool:
            # a play that failed before writing anything (a map whose conversion fails, a metric plugin's error)
            # leaves no empty folder it made (after the lock's file is gone: the exit stack unwinds last in first)
            if exc_type is not None and created:
                with contextlib.suppress(OSError):
                    made.rmdir()  # (only when empty)
            return False

        guard.push(drop_if_empty)
        # a second play into the folder would read this one's kept paths and write its files among them
        guard.enter_context(writer_lock(outdir, "rtp play", lambda holder: PlayError(
            f"out: {outdir} is being written by another job ({holder}): wait for it to end, or play into "
            "another folder", "out"), remove=True))
    with guard:
        if outdir is not None:
            _remove_temporaries(outdir)
            _warn_of_another_report(outdir, settings)
        job = {"scene": scene, "cache_dir": cache_dir, "checked": True, "methods": [m.name for m in specs], "frames": frames,
               "fps": fps,
               "seed": seed, "size": tuple(size), "tile_size": tile_size, "fail_metric": fail_metric, "fail_thr": fail_thr,
               "sweep": sweep, "flip_every": flip_every, "unseen_fraction": unseen_fraction, "exact": exact,
               "open_loop": open_loop, "gif": str(outdir) if outdir is not None and plots and animation else None,
               "engine_rates": engine_rates, "combiner": combiner, "palette": palette,
               "dynamic": None if dynamic_resolution is None else [list(dynamic_resolution.scales),
                                                                   dynamic_resolution.every]}
        # A path finished by an interrupted run of the same job into the same folder is read back, not
        # played again; each path is kept as it finishes, until the report is written.
        if outdir is not None:  # (a level file edited between the runs: its kept paths were played on the old one)
            job["scene_digest"] = _scene_digest(scene, cache_dir)
        key = _resume_key(job, predictors) if outdir is not None else ""
        results = {p: r for p in dict.fromkeys(paths)
                   if outdir is not None and (r := _load_path(outdir, p, key)) is not None}
        if results:
            log.info("%s: %s played by an interrupted run of this job; playing the rest", outdir, ", ".join(results))
            assert outdir is not None
            for pname, res in results.items():
                res["files"] = _kept_pictures(outdir, pname, res, job["gif"] is not None, palette)
                if kept is not None:
                    kept(pname)
            if progress is not None:
                progress(frames * len(results))
        todo = [p for p in dict.fromkeys(paths) if p not in results]

        def finished(pname: str, res: dict[str, Any]) -> None:
            results[pname] = res
            if outdir is not None:
                _save_path(outdir, pname, key, res)
                if kept is not None:
                    kept(pname)

        if workers > 1 and len(todo) > 1:
            _in_workers(job, todo, min(workers, len(todo)), progress, finished, stage)
        else:
            for pname in todo:
                finished(pname, _play_path({**job, "path": pname}, progress, stage))
        for pname in paths:
            res = results[pname]
            report.unseen[pname] = res["unseen"]
            report.settings.setdefault("cameras", {})[pname] = res["camera"]
            report.rows += res["rows"]
            report.frames[pname] = res["frames"]
            report.files += res["files"]
            for m in specs:
                pts = [(r["fail_share"], r["work_saved"]) for r in res["rows"] if r["method"] == m.name]
                # the worst 5% of frames' saving along the same sweep (a path kept by an older run has none)
                low = [(r["fail_share"], r.get("work_saved_p05")) for r in res["rows"] if r["method"] == m.name]
                low_ok = all(w is not None and np.isfinite(w) for _, w in low)
                for level in FAIL_LEVELS:
                    v = saved_at(pts, level)
                    v_low = saved_at(low, level) if low_ok else None
                    # a swept method whose sweep never fails this often: its best saving, a lower bound
                    capped = v is not None and m.kind not in _NO_HISTORY and max(f for f, _ in pts) < level
                    report.matched.append({"path": pname, "method": m.name, "fail_share": level,
                                           "work_saved": float("nan") if v is None else v, "capped": capped,
                                           "work_saved_p05": float("nan") if v_low is None else v_low})
        if outdir is not None:
            if stage is not None:
                stage("writing the report" + (" and its plots" if plots else ""))
            report.files += _write(report, outdir, plots)
            _remove_other_pictures(outdir, report.files)
            for pname in paths:
                (outdir / _PARTIAL.format(pname)).unlink(missing_ok=True)
    return report


def _kept_pictures(outdir: Path, pname: str, res: dict[str, Any], animation: bool, palette: str = "paper") -> list[str]:
    """The pictures of path ``pname`` kept by an interrupted run (its GIF and middle frame) that this run reports:
    with ``animation``, those in ``outdir`` (and a warning naming the ones that are not: the kept results hold
    no frames to draw them from, and a kept path is not played again; and one where they were drawn in another
    ``palette`` than this run's, which they keep for the same reason); without, none (they are removed with the
    other runs' pictures when the report is written)."""
    if not animation:
        return []
    names = [f"play_{pname}.gif", f"play_{pname}.png"]
    files = res.get("files")
    listed: list[Any] = files if isinstance(files, list) else []
    have = [n for n in names if n in listed and (outdir / n).is_file()]
    missing = [n for n in names if n not in have]
    if missing:
        log.warning("%s: path %s is read back from an interrupted run that left no %s (it played with --no-animation "
                    "or --no-plots, animation=False or plots=False, or the files were removed since), and its frames "
                    "are not kept: this run writes none; delete %s to play the path again with them", outdir, pname,
                    " or ".join(missing), outdir / _PARTIAL.format(pname))
    drawn = res.get("palette", "paper")  # (a path kept before the palette was recorded: the only one there was)
    if have and drawn != palette:
        log.warning("%s: path %s is read back from an interrupted run that drew %s in the %r palette, and its frames "
                    "are not kept: this run's %r palette is not theirs; delete %s to play the path again in it",
                    outdir, pname, " and ".join(have), drawn, palette, outdir / _PARTIAL.format(pname))
    return have


def _remove_other_pictures(outdir: Path, files: Sequence[str]) -> None:
    """Remove the pictures of rtp play's own names (``play_curves.png``, ``play_frames.png``, ``play_PATH.gif`` and
    ``.png`` of every path profile) that this run's report does not list: another run's, which the report in
    ``outdir`` replaced (a folder holds one run's report; a slow run into a slow-and-fast run's folder kept
    play_fast.gif beside it). No other file is touched."""
    from rtp.capture.paths import PATH_PROFILES

    ours = {"play_curves.png", "play_frames.png"} | {f"play_{p}.{ext}" for p in PATH_PROFILES for ext in ("gif", "png")}
    gone = sorted(n for n in ours - set(files) if (outdir / n).is_file())
    for name in gone:
        (outdir / name).unlink(missing_ok=True)
    if gone:
        log.info("%s: removed %s, another run's pictures, which this run's report replaces", outdir, ", ".join(gone))


def _remove_temporaries(outdir: Path) -> None:
    """Remove the temporary files of rtp play's own outputs in ``outdir`` (``.play_slow.gif.k2j4x9ab.tmp``, the
    names :func:`rtp.sdk.files.atomic_output` gives): an interrupted run's. Ctrl-C or SIGTERM terminates the worker
    processes of ``--workers N``, in which no cleanup runs, so a worker stopped while writing its path's GIF left
    the GIF's temporary file, and a rerun (its own write of the GIF younger than the minute after which
    ``atomic_output`` takes another's for orphaned) left it beside its report, until a later run wrote that GIF
    again; ``kill -9`` left the job's own. Called under the folder's writer lock, while no other play writes there;
    no other file is touched."""
    from rtp.capture.paths import PATH_PROFILES

    ours = {"play.md", "play.json", "play_curves.png", "play_frames.png"}
    ours |= {f"play_{p}.{ext}" for p in PATH_PROFILES for ext in ("gif", "png")}
    ours |= {_PARTIAL.format(p).lstrip(".") for p in PATH_PROFILES}  # (their dot: the temporary's own, added below)
    pattern = re.compile(rf"\.(?:{'|'.join(map(re.escape, sorted(ours)))})\.[A-Za-z0-9_]{{8}}\.tmp")
    stale = sorted(p for p in outdir.iterdir() if pattern.fullmatch(p.name) and p.is_file())
    for p in stale:
        p.unlink(missing_ok=True)
    if stale:
        log.info("%s: removed %s, the temporary files of an interrupted run", outdir, ", ".join(p.name for p in stale))


#: The hardware's combiners through which a method's rates reach the frame beside the engine's (``sdk.COMBINERS``' min,
#: max and sum).
_SELECTING_COMBINERS = ("min", "max", "sum")

#: A path's results, kept in the output folder while the job runs (:func:`play` resumes from them).
_PARTIAL = ".play-{}.partial.json"


def _resume_key(job: dict[str, Any], predictors: dict[str, sdk.ShadingRatePredictor]) -> str:
    """What a path's kept results must have been played with to be reused: the job's settings, rtp's
    version and the bytes of every model (a model exported again since is played again)."""
    import hashlib
    import json

    models = {k: hashlib.sha256(Path(str(p.path)).read_bytes()).hexdigest() for k, p in sorted(predictors.items())}
    # (nor the palette, which changes only the GIFs' colours: a path kept with another is not played again)
    settings = {k: v for k, v in job.items() if k not in ("gif", "threads", "palette")}
    return json.dumps({"job": settings, "models": models, "rtp": sdk.__version__}, sort_keys=True, default=str)


def _scene_digest(scene: str, cache_dir: str | os.PathLike[str] | None) -> str | None:
    """A hash of what a level file loads as (geometry, materials, textures, lights, spawn points: the files it
    references too), or None for the procedural scene and the fetched maps (their content is rtp's, in its
    version). A level file edited between an interrupted run and its rerun was resumed from the paths played on
    the old level."""
    import dataclasses
    import hashlib

    from rtp.capture import MESH_EXTENSIONS, PROCEDURAL_PREFIX, load_scene

    procedural = scene == PROCEDURAL_PREFIX.rstrip(":") or scene.startswith(PROCEDURAL_PREFIX)
    if procedural or not (Path(scene).suffix.lower() in MESH_EXTENSIONS or Path(scene).is_file()):
        return None
    h = hashlib.sha256()

    def feed(v: Any) -> None:
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            h.update(f"<{type(v).__name__}".encode())
            for f in dataclasses.fields(v):
                h.update(f.name.encode())
                feed(getattr(v, f.name))
        elif isinstance(v, np.ndarray):
            h.update(f"{v.dtype.str}{v.shape}".encode())
            h.update(np.ascontiguousarray(v).data)
        elif isinstance(v, (list, tuple)):
            h.update(f"[{len(v)}".encode())
            for x in v:
                feed(x)
        else:
            h.update(repr(v).encode())

    feed(load_scene(scene, cache_dir, None, None, checked=True)[0])  # (its warnings were said by check_scene)
    return h.hexdigest()


#: The settings of the loop itself a run into a folder compares with the report there (besides the map, methods,
#: paths, frames, ...), where that report records them (older ones do not record all of them).
_LOOP_KEYS = ("sweep", "flip_every", "unseen_fraction", "shading", "history", "engine_rates")


def _warn_of_another_report(outdir: Path, settings: dict[str, Any]) -> None:
    """Say, before the work, that ``outdir`` holds the report of a run with other settings, which this run's
    replaces when it ends (a ten-minute benchmark was overwritten without a word)."""
    import json

    old = outdir / "play.json"
    if not old.is_file():
        return
    try:
        before = json.loads(old.read_text(encoding="utf-8"))["settings"]
        if not isinstance(before, dict):  # (a damaged report's settings: an AttributeError, rtp play's traceback)
            raise TypeError("settings: not a mapping")
        # (the loop's own settings too, where the old report records them: an --open-loop or --composite ablation, one
        # beside an engine's rates or without the sweep, into the benchmark's folder replaced it without a word)
        differ = [k for k in ("scene", "methods", "paths", "frames", "fps", "size", "tile_size", "fail_metric", "fail_threshold",
                              "seed", "models", "dynamic_resolution", *_LOOP_KEYS)
                  if (k not in _LOOP_KEYS or k in before)
                  and before.get(k) != json.loads(json.dumps(settings.get(k), default=str))]
    except (OSError, ValueError, KeyError, TypeError):
        differ = ["unreadable"]
    if differ:
        log.warning("%s holds the report of another run (%s differ): this run's replaces it when it ends; play into "
                    "another --out to keep both", outdir, ", ".join(differ))


def _save_path(outdir: Path, pname: str, key: str, res: dict[str, Any]) -> None:
    import json

    def plain(v: Any) -> Any:  # numpy scalars and arrays as JSON numbers and lists (NaN kept)
        return v.item() if isinstance(v, np.generic) else v.tolist() if isinstance(v, np.ndarray) else str(v)

    with atomic_output(outdir / _PARTIAL.format(pname)) as tmp:
        tmp.write_text(json.dumps({"key": key, "result": res}, default=plain), encoding="utf-8")


def _load_path(outdir: Path, pname: str, key: str) -> dict[str, Any] | None:
    """The kept results of path ``pname``, or None: none kept, kept for another job, or unreadable."""
    import json

    f = outdir / _PARTIAL.format(pname)
    try:
        kept = json.loads(f.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as err:
        log.warning("%s: not readable (%s); playing %s again", f, err, pname)
        return None
    if not isinstance(kept, dict) or kept.get("key") != key or not isinstance(kept.get("result"), dict):
        log.info("%s was played with other settings or models; playing %s again", f, pname)
        return None
    result: dict[str, Any] = kept["result"]
    return result


def _play_path(job: dict[str, Any], progress: Callable[[int], None] | None = None,
               stage: Callable[[str], None] | None = None) -> dict[str, Any]:
    """One path of :func:`play` (in this process or a worker's): its rows, per-frame series, unseen
    shares and GIF; ``stage`` hears of each step before the frames and after them."""
    from rtp import metrics
    from rtp.capture import load_scene
    from rtp.capture.paths import DynamicResolution, PathPlayer, camera_path

    pname = job["path"]

    def step(text: str) -> None:
        if stage is not None:
            stage(f"{pname}: {text}")

    step(f"loading {job['scene']}")
    specs = parse_methods(job["methods"])
    # in a worker process, its share of the cores (capture.worker_threads); alone, onnxruntime's default
    predictors = {m.model: sdk.load(m.model, threads=job.get("threads", 0)) for m in specs if m.kind == "model"}
    info = metrics.metric_info(job["fail_metric"])
    # (check_scene read a mesh file before the job and logged its warnings: not said again by each path's worker)
    scn, blockers = load_scene(job["scene"], job["cache_dir"], None, None, checked=job.get("checked", False))
    w, h = job["size"]
    tile = job["tile_size"]
    step("planning the camera path")
    path = camera_path(scn, job["frames"], pname, job["seed"], fps=job["fps"], blockers=blockers)
    engine = job.get("engine_rates")
    combiner = job.get("combiner", "max")
    loops = _loops(specs, predictors, job["sweep"], job["fail_thr"], info.higher_is_better, tile, job["unseen_fraction"],
                   combiner)
    step("starting the renderer")
    ticked = [False]

    def frame_done(n: int) -> None:
        if not ticked[0]:  # its frames count from here on: no step to show
            ticked[0] = True
            step("playing")
        if progress is not None:
            progress(n)

    dynamic = job.get("dynamic")
    with PathPlayer(scn, (w, h), exact=job["exact"],
                    dynamic=None if dynamic is None else DynamicResolution(tuple(dynamic[0]), dynamic[1])) as player:
        step("the first frame (rendered at every rate, then each method)")
        start = time.perf_counter()
        unseen, anim = _run_path(player, path, loops, metrics, job["fail_metric"], job["fail_thr"], info.higher_is_better,
                                 tile, job["flip_every"], frame_done, job["gif"] is not None, job["open_loop"],
                                 engine, combiner, job.get("palette", "paper"))
        took = time.perf_counter() - start
        log.info("%s: %d frames of %d loops played in %.1f s (%.2f s a frame)", pname, len(path), len(loops), took,
                 took / max(1, len(path)))
    files = []
    if job["gif"] is not None and anim:
        step(f"writing play_{pname}.gif")
        files = _write_animation(Path(job["gif"]) / f"play_{pname}.gif", anim)
    step("done")
    return {
        "unseen": unseen,
        "camera": {"length_m": path.length(), "eye_height_m": path.eye_height},
        "rows": [{"path": pname, **lp.summary()} for lp in loops],
        "frames": {lp.method.name: {"saved": lp.saved, "fail": lp.fail, "change": lp.change, "flip": lp.flip,
                                    "ms": lp.ms} for lp in loops if lp.default},
        "files": files,
        "palette": job.get("palette", "paper"),  # (the GIF's: a rerun that reads the path back says if it asks another)
    }


def _worker_path(job: dict[str, Any], queue: Any) -> dict[str, Any]:
    return _play_path(job, queue.put, queue.put)


def _in_workers(job: dict[str, Any], paths: list[str], workers: int, progress: Callable[[int], None] | None,
                finished: Callable[[str, dict[str, Any]], None], stage: Callable[[str], None] | None = None) -> None:
    """The paths in ``workers`` processes (each its own renderer), progress ticks (frames, ints) and
    stages (str) through a queue, ``finished(path, results)`` as each ends."""
    import queue

    from rtp.capture import tick_queue, with_ticks, worker_pool, worker_threads

    def news(item: int | str) -> None:
        if isinstance(item, str):
            if stage is not None:
                stage(item)
        elif progress is not None:
            progress(item)

    threads = worker_threads(workers)
    ticks = tick_queue()
    with worker_pool(workers, ticks=ticks) as pool:
        futures = {pool.submit(with_ticks, _worker_path, {**job, "path": p, "threads": threads}): p for p in paths}
        while futures:
            # (the paths that ended are kept before the error of one that failed is raised: a path ending in the
            # same poll as another's error was lost, its minutes of work played again by the rerun)
            for f in sorted((f for f in futures if f.done()), key=lambda f: f.exception() is not None):
                finished(futures.pop(f), f.result())
            try:
                news(ticks.get(timeout=0.5))
            except queue.Empty:
                continue
    while not ticks.empty():  # (the workers exited: their last ticks are flushed)
        news(ticks.get())


def _loops(specs: list[MethodSpec], predictors: dict[str, Any], sweep: bool, fail_thr: float, fail_hib: bool,
           tile: int, unseen_fraction: float, combiner: str = "max") -> list[_Loop]:
    loops: list[_Loop] = []
    for m in specs:
        if m.kind == "full":
            loops.append(_Loop(m, 0.0, "1x1", lambda pf, rp, truth, lp: np.zeros(truth.shape[1:], np.uint8),
                               default=True))
        elif m.kind in ("oracle", "oracle-monotone"):
            loops.append(_Loop(m, fail_thr, f"threshold {fail_thr:g}",
                               _oracle(fail_thr, fail_hib, m.kind == "oracle-monotone", combiner), default=True))
        elif m.kind == "model":
            pred = predictors[m.model]
            meta = pred.metadata
            thr0 = meta.default_threshold
            if m.budget is not None:  # a budget: the share saved every frame, swept in place of the threshold
                for b in sorted({*SAVING_SWEEP, m.budget}) if sweep else (m.budget,):
                    decide = _model(pred, thr0, m.reuse, tile, unseen_fraction, m.reduce, m.unseen, m.history,
                                    m.refresh, m.step, m.rescale, m.carry_scale, m.carry, saving=b,
                                    combiner=None if m.alone else combiner)
                    loops.append(_Loop(m, b, f"saving {b:g}", decide, default=b == m.budget))
                continue
            if meta.higher_is_better:
                values = [thr0 + d for d in (PSNR_SWEEP_DB if sweep else (0.0,))]
            else:
                values = [thr0 * f for f in (MODEL_SWEEP if sweep else (1.0,))]
            for v in values:
                decide = _model(pred, v, m.reuse, tile, unseen_fraction, m.reduce, m.unseen, m.history, m.refresh,
                                m.step, m.rescale, m.carry_scale, m.carry, saving=m.floor, floor=m.floor is not None,
                                combiner=None if m.alone else combiner)
                label = f"threshold {v:.4g}" + ("" if m.floor is None else f", floor {m.floor:g}")
                loops.append(_Loop(m, v, label, decide, default=v == thr0))
        elif m.kind.startswith("yang2019"):
            yang = Yang2019(tile, threshold=YANG_THRESHOLD, motion=True, unseen_fraction=unseen_fraction,
                           unseen="full" if m.kind == "yang2019-unseen-1x1" else "as_is")
            if m.budget is not None:  # a budget: its estimates through the model's selection, swept over the saving
                for b in sorted({*SAVING_SWEEP, m.budget}) if sweep else (m.budget,):
                    loops.append(_Loop(m, b, f"saving {b:g}", _baseline_budget(yang, b, tile), default=b == m.budget))
                continue
            for f in BASELINE_SWEEP if sweep else (1.0,):
                loops.append(_Loop(m, YANG_THRESHOLD * f, f"t {YANG_THRESHOLD * f:.4g}", _baseline(yang, YANG_THRESHOLD * f),
                                   default=f == 1.0))
        else:
            for f in BASELINE_SWEEP if sweep else (1.0,):
                ffx = FidelityFX(tile, cutoff=FFX_CUTOFF * f, motion_factor=FFX_MOTION_FACTOR * f,
                                 additional_rates=m.kind == "fidelityfx-additional")
                loops.append(_Loop(m, f, f"cutoff {FFX_CUTOFF * f:.4g}, motion {FFX_MOTION_FACTOR * f:.4g}",
                                   _baseline(ffx, FFX_CUTOFF * f), default=f == 1.0))
    return loops


def _loop_count(m: MethodSpec, sweep: bool, predictors: dict[str, Any]) -> int:
    """How many loops :func:`_loops` makes of ``m``: one per swept parameter."""
    if not sweep or m.kind in ("full", "oracle", "oracle-monotone"):
        return 1
    if m.budget is not None:  # (a model's or Yang's budget)
        return len({*SAVING_SWEEP, m.budget})
    if m.kind == "model":
        return len(PSNR_SWEEP_DB if predictors[m.model].metadata.higher_is_better else MODEL_SWEEP)
    return len(BASELINE_SWEEP)


def _oracle(thr: float, hib: bool, monotone: bool = False, combiner: str = "max") -> Callable[..., np.ndarray]:
    def decide(pf: Any, rp: np.ndarray | None, truth: np.ndarray, lp: _Loop) -> np.ndarray:
        return sdk.select_rates(monotone_over_rates(truth, hib) if monotone else truth, thr, higher_is_better=hib,
                                engine_rates=lp.engine, combiner=combiner)  # (beside the engine's rates, if any)
    return decide


def _baseline(sel: Any, value: float) -> Callable[..., np.ndarray]:
    def decide(pf: Any, rp: np.ndarray | None, truth: np.ndarray, lp: _Loop) -> np.ndarray:
        assert rp is not None
        return np.asarray(sel.shading_rates(_checked(Frame(rp, pf.frame.motion, pf.seen, terms=pf.terms)), value))
    return decide


def _baseline_budget(yang: Yang2019, saving: float, tile: int) -> Callable[..., np.ndarray]:
    """Yang 2019 with a budget: its per-rate estimates (``Yang2019.predict``, lower is better) through
    ``sdk.select_rates_for_saving``, the lowest sensitivity whose rates save ``saving`` of the frame's work
    (its own rate rule at that sensitivity: the cheapest rate under it; NAS's allowed rates kept)."""
    allowed = None if yang.allow_4x4 else tuple(r for r in sdk.ALL_RATES if r != "4x4")

    def decide(pf: Any, rp: np.ndarray | None, truth: np.ndarray, lp: _Loop) -> np.ndarray:
        assert rp is not None
        est = yang.predict(_checked(Frame(rp, pf.frame.motion, pf.seen, terms=pf.terms)))  # (its own frame)
        return sdk.select_rates_for_saving(est, saving, higher_is_better=False, allowed=allowed,
                                           frame_size=pf.seen.shape, tile_size=tile).rates
    return decide


def model_inputs(pf: Any, rp: np.ndarray, channels: Sequence[str], ys: slice, xs: slice) -> np.ndarray:
    """A model's input planes ``channels`` for the window ``(ys, xs)`` of a played frame ``pf``
    (:class:`rtp.capture.paths.PathFrame`), ``rp`` the method's own displayed frame reprojected."""
    seen = pf.seen[ys, xs]
    planes = np.empty((len(channels),) + seen.shape, np.float32)
    lum: list[np.ndarray] = []  # the window's luma, once for every plane that reads it

    def luma() -> np.ndarray:
        if not lum:
            lum.append(sdk.luma(rp[ys, xs]))
        return lum[0]

    for i, c in enumerate(channels):
        base, _, comp = c.partition(".")
        if comp in ("y.dx", "y.dy"):  # one pixel past the window: its last column / row as the frame's
            ext = sdk.luma(rp[ys.start:ys.stop + 1, xs.start:xs.stop + 1])
            planes[i] = sdk.pixel_differences(ext)[comp == "y.dy"][:seen.shape[0], :seen.shape[1]]
        elif c == "reprojected.y.blocks":  # windows start on whole cells (tiles)
            planes[i] = sdk.block_variances(luma())
        elif c == "reprojected.y.tiles":  # windows start on whole tiles
            planes[i] = sdk.tile_variances(luma())
        elif base == "reprojected":  # the method's own displayed frame, reprojected
            planes[i] = luma() if comp == "y" else rp[ys, xs, "rgb".index(comp)]
        elif c == "seen":
            planes[i] = seen
        else:  # G-buffer planes: converted once per frame, shared by every method
            planes[i] = pf.plane(c)[ys, xs]
    return planes


def _model(pred: Any, thr: float, reuse: int, tile: int, unseen_fraction: float,
           reduce: str = "mean", unseen: str = "full", history: float = 0.0,
           refresh: float | None = None, step: int | None = None, rescale: float = 0.0,
           carry_scale: float = 1.0, carries: str = "estimates", saving: float | None = None,
           floor: bool = False, combiner: str | None = "max") -> Callable[..., np.ndarray]:
    meta = pred.metadata
    hib = meta.higher_is_better
    split = meta.tile_size // tile  # (finer hardware tiles than the model's: each its model tile's rate)
    pool = tile // meta.tile_size  # (coarser ones: each the worst estimate of the model tiles it covers)
    carry = sdk.PredictionReuse(pred, reuse, reduce=reduce, unseen=unseen, unseen_fraction=unseen_fraction,
                                history=history, refresh=refresh, step=step, rescale=rescale, carry_scale=carry_scale,
                                carry=carries)

    def decide(pf: Any, rp: np.ndarray | None, truth: np.ndarray, lp: _Loop) -> np.ndarray:
        assert rp is not None

        def inputs(ys: slice, xs: slice, channels: Sequence[str] = meta.inputs) -> np.ndarray:
            # only where the frame's planes are read, and only those (a carried frame's tail: its .tiles planes)
            return model_inputs(pf, rp, channels, ys, xs)

        fetch = (pf.rows, pf.cols) if pf.index > 0 else None
        est = carry.predict(inputs, fetch, pf.seen, pf.frame.mask <= 0.5)
        lp.ran.append(carry.work)
        if pool > 1:
            est = sdk.pool_tiles(est, pool, higher_is_better=hib)
        beside: dict[str, Any] = ({} if lp.engine is None or combiner is None else
                                  {"engine_rates": lp.engine, "combiner": combiner})
        parts, tiles_of = split, max(tile, meta.tile_size)  # (est's tiles: the model's, or the hardware's coarser ones)
        if beside and parts > 1:  # (the engine's rates are on the hardware's tiles: each its model tile's estimates)
            est, parts, tiles_of = sdk.split_tiles(est, parts, truth.shape[1:]), 1, tile
        if saving is None:
            rates = sdk.select_rates(est, thr, higher_is_better=hib, factors=meta.rate_factors, **beside)
        else:  # (the budget over the frame's pixels)
            rates = sdk.select_rates_for_saving(est, saving, higher_is_better=hib, factors=meta.rate_factors,
                                                frame_size=pf.seen.shape, tile_size=tiles_of,
                                                threshold=thr if floor else None, **beside).rates
        return rates if parts <= 1 else sdk.split_tiles(rates, parts, truth.shape[1:])
    return decide


def _run_path(player: Any, path: Any, loops: list[_Loop], metrics: Any, fail_metric: str, fail_thr: float, fail_hib: bool,
              tile: int, flip_every: int, progress: Callable[[int], None] | None,
              animate: bool, open_loop: bool = False, engine_image: str | None = None,
              combiner: str = "max", palette: str = "paper") -> tuple[list[float], list[np.ndarray]]:
    from rtp.capture.paths import frame_unseen_share

    unseen: list[float] = []
    keep: list[np.ndarray] = []
    anim_every = max(1, -(-len(path) // _ANIM_FRAMES))
    for pf in player.frames(path):
        frame = pf.frame
        ref = frame.colour["1x1"]
        hw = ref.shape[:2]  # (the frame's own size: dynamic resolution changes it)
        truth = metrics.tile_targets(ref, {r: frame.colour[r] for r in sdk.PREDICTED_RATES}, (fail_metric,), tile)[fail_metric]
        unseen.append(frame_unseen_share(pf.seen) if pf.index > 0 else 1.0)
        flip_frame = flip_every > 0 and pf.index > 0 and pf.index % flip_every == 0
        # (frame 0 has no history, every method's reprojection black: left out of the GIF as of every figure)
        anim_frame = animate and pf.index > 0 and pf.index % anim_every == 0
        shown: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        engine = None if engine_image is None else engine_rates(engine_image, pf.plane("motion.x"),
                                                                pf.plane("motion.y"), tile)
        for lp in loops:
            lp.engine = engine
            measure_flip = flip_frame and lp.default
            needs_history = lp.method.kind not in _NO_HISTORY
            rp = None
            if needs_history:
                rp = pf.reproject(lp.history) if lp.history is not None else np.zeros(ref.shape, np.float32)
            t0 = time.perf_counter()
            rates = lp.decide(pf, rp, truth, lp)
            lp.ms.append((time.perf_counter() - t0) * 1000)
            if engine is not None:  # the rates the device shades: the engine's and the method's combined
                rates = sdk.combine_rates(engine, rates, combiner)
            if lp.method.kind == "full" and engine is None:
                displayed = ref
            elif needs_history or measure_flip or (anim_frame and lp.default):
                displayed = player.shade(rates, tile)
            else:
                displayed = None
            lp.saved.append(sdk.work_saved(rates, hw, tile))
            failing = failing_tiles(rates, truth, fail_thr, fail_hib)
            if engine is not None:  # (the engine's own rate is its choice: a tile fails beyond it only)
                failing &= rates != engine
            lp.fail.append(float(failing.mean()))
            # (none on the first frame, nor across a change of size: the tiles are others even where both sizes have
            # the same tile grid, 160x96 and 158x95 on 16-pixel tiles, whose rates were compared tile by tile)
            lp.change.append(float((rates != lp.rates).mean()) if lp.rates is not None and lp.rates_hw == hw
                             else float("nan"))
            # (full's displayed frame is the reference: FLIP 0, on the frames FLIP is measured only, so that a run
            # without any shows "-" for it as for every method, not 0.0000)
            lp.flip.append(float("nan") if not measure_flip else 0.0 if lp.method.kind == "full" and engine is None else
                           float(metrics.flip_map(ref, displayed).mean()) if displayed is not None else float("nan"))
            lp.history, lp.rates, lp.rates_hw = (ref if open_loop else displayed) if needs_history else None, rates, hw
            if anim_frame and lp.default and displayed is not None:
                shown[lp.method.name] = (displayed, rates)
        if shown:
            when = f"frame {pf.index} of {len(path)}"
            if isinstance(getattr(path, "fps", None), (int, float)) and path.fps > 0:
                when += f", {pf.index / path.fps:.2f} s"
            if getattr(player, "dynamic", None) is not None:
                when += f", {ref.shape[1]}x{ref.shape[0]}"
            keep.append(_anim_frame(ref, shown, tile, when, getattr(player, "size", None), palette=palette))
        if progress is not None:
            progress(1)
    return unseen, keep


# -- pictures -------------------------------------------------------------------------------------------


_ANIM_FRAMES = 60  # at most this many frames in a GIF
_ANIM_FPS = 20  # its playback rate
_ANIM_PANEL_WIDTH = 400  # each panel at most this wide


def _anim_frame(ref: np.ndarray, shown: dict[str, tuple[np.ndarray, np.ndarray]], tile: int,
                when: str = "", full: tuple[int, int] | None = None, *, palette: str = "paper") -> np.ndarray:
    """One GIF frame: the full-rate frame (labelled with ``when``, the frame's place on the path) and
    each method's displayed frame with its rate overlay, downscaled to panels at most
    ``_ANIM_PANEL_WIDTH`` wide, three per row, uint8; with ``full`` (the path's largest ``(width,
    height)``: dynamic resolution) each panel is the size a frame of that size gets, every GIF frame
    alike. The rates' colour key fills the first empty cell of the grid, legible at the panels' size;
    where no cell is empty, the first overlay carries the overlay's own small key; overlays and key in ``palette``'s
    colours (:data:`rtp.sdk.OVERLAY_PALETTES`)."""
    from PIL import Image

    spare = -(len(shown) + 1) % 3 if len(shown) + 1 > 3 else 0
    names = ["full rate (reference)" + (f", {when}" if when else ""), *shown]
    panels = [_uint8(ref)] + [_uint8(sdk.draw_rate_overlay(img, rates, tile, legend=i == 0 and not spare,
                                                           palette=palette))
                              for i, (img, rates) in enumerate(shown.values())]
    h, w = panels[0].shape[:2]
    fw, fh = full if full is not None else (w, h)
    size = (_ANIM_PANEL_WIDTH, max(1, round(fh * _ANIM_PANEL_WIDTH / fw))) if fw > _ANIM_PANEL_WIDTH else (fw, fh)
    if size != (w, h):  # (a smaller frame than the path's largest is scaled up to its panel)
        kind = Image.Resampling.BOX if size[0] < w else Image.Resampling.NEAREST
        panels = [np.asarray(Image.fromarray(p).resize(size, kind)) for p in panels]
        h, w = panels[0].shape[:2]
    panels = [_label(p, name) for p, name in zip(panels, names)]  # (after the downscale: legible at its size)
    if spare:
        panels.append(_rate_key(h, w, palette))
    cols = min(3, len(panels))
    rows = -(-len(panels) // cols)
    grid = np.zeros((rows * h, cols * w, 3), np.uint8)
    for i, p in enumerate(panels):
        r, c = divmod(i, cols)
        grid[r * h:(r + 1) * h, c * w:(c + 1) * w] = p
    return grid


def _rate_key(h: int, w: int, palette: str = "paper") -> np.ndarray:
    """An ``h`` x ``w`` uint8 panel naming the overlay's colour classes in ``palette``'s colours
    (:func:`rtp.evaluate.plots.rate_legend`):
    a swatch and its rates a row, white on black, as large as the panel holds (nothing where it is
    too small for one row)."""
    from PIL import Image, ImageDraw

    from .plots import UNTINTED_SWATCH, rate_legend

    im = Image.new("RGB", (w, h))
    rows = [("rates each method chose", None, False)] + [(label, colour, True) for label, colour in rate_legend(palette)]
    step = min(h // (len(rows) + 1), 28)
    if step < 8:
        return np.asarray(im)
    d = ImageDraw.Draw(im)
    font, left = max(6, round(step * 0.55)), step // 2
    for i, (label, colour, swatch) in enumerate(rows):
        top = left + i * step
        x = left
        if swatch:
            # (the untinted class's swatch as every rate key draws it: rtp.sdk's in a frame, the figures' legends)
            fill = tuple(round(255 * c) for c in (UNTINTED_SWATCH if colour is None else colour))
            d.rectangle((x, top, x + font, top + font), fill=fill, outline=(255, 255, 255))
            x += font + left
        d.text((x, top), label, fill=(255, 255, 255), font_size=font)
    return np.asarray(im)


def _write_animation(path: Path, frames: list[np.ndarray]) -> list[str]:
    """The GIF of :func:`_anim_frame` frames (each quantised to its own palette, so the rate tints do
    not shift the colours of the other panels) and its middle frame as a PNG, written atomically.
    Pillow's fast octree quantiser: on a 1200x675 frame of four panels 11 ms against median cut's 230 (a
    quarter of a 30-frame play's time went here), its error as small (RMS 3.7 of 255 against 4.1)."""
    from PIL import Image

    from rtp.capture import save_image

    images = [Image.fromarray(f).quantize(colors=255, method=Image.Quantize.FASTOCTREE) for f in frames]
    with atomic_output(path) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=round(1000 / _ANIM_FPS),
                       loop=0, disposal=1)
    still = path.with_suffix(".png")
    save_image(still, frames[len(frames) // 2])
    return [path.name, still.name]


def _uint8(img: np.ndarray) -> np.ndarray:
    """An RGB(A) image in [0, 1] (or uint8) as contiguous uint8 RGB."""
    arr = (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8) if img.dtype != np.uint8 else img
    return np.ascontiguousarray(arr[..., :3])


def _label(img: np.ndarray, text: str) -> np.ndarray:
    """``img`` (uint8 RGB) with ``text`` white on a black box in its top-left corner, sized to the
    text as drawn (one font pixel per 30 image columns, 12 at the least). Text wider than the image is wrapped
    after its commas, and a line still too wide drawn smaller (8 pixels at the least; cut, ending "…", beyond
    that): on a panel under 300 pixels wide, the reference's label ran off it, ``frame 75 of 150, 1.25 s`` cut
    to ``frame 7``."""
    from PIL import Image, ImageDraw

    im = Image.fromarray(_uint8(img))
    d = ImageDraw.Draw(im)
    size = max(12, im.width // 30)

    def width(line: str) -> float:
        return d.textlength(line, font_size=size)

    lines: list[str] = []
    for part in text.split(", "):
        if lines and width(f"{lines[-1]}, {part}") <= im.width - 12:
            lines[-1] += f", {part}"
        else:
            if lines:
                lines[-1] += ","
            lines.append(part)
    while size > 8 and max(map(width, lines)) > im.width - 12:
        size -= 1
    for i, line in enumerate(lines):  # (still too wide at 8 pixels: cut, and the cut shown)
        while len(line) > 1 and width(line) > im.width - 12:
            line = line[:-2] + "…"
        lines[i] = line
    text = "\n".join(lines)
    left, top, right, bottom = d.textbbox((4, 2), text, font_size=size)
    d.rectangle((0, 0, right + 4, bottom + 3), fill=(0, 0, 0))
    d.text((4, 2), text, fill=(255, 255, 255), font_size=size)
    return np.asarray(im)


def _write(report: PlayReport, out: Path, plots: bool) -> list[str]:
    import json

    from ._evaluate import _json_clean

    # the figures drawn before anything is written: a failure drawing them left this run's play.json beside the
    # previous run's figures
    images: list[tuple[str, np.ndarray]] = []
    if plots:
        from .plots import play_curves, play_frames, save_image

        images = [("play_curves.png", play_curves(report)), ("play_frames.png", play_frames(report))]
    files = []
    for name, text in (("play.md", report.to_markdown()), ("play.json", json.dumps(_json_clean(report.to_dict()), indent=1))):
        with atomic_output(out / name) as tmp:
            tmp.write_text(text, encoding="utf-8")
        files.append(name)
    for name, img in images:
        save_image(out / name, img)
        files.append(name)
    return files
