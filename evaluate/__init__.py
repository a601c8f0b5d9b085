"""Evaluation: prediction quality, the classic baselines, rate decisions, sweeps and plots.

No torch: a user who captured a dataset and computed its targets (``rtp[capture]``) evaluates any
ONNX model with it::

    from rtp import evaluate
    report = evaluate.evaluate("models/jnyang.onnx", "data/test")
    print(report.to_markdown())

The baselines (:class:`Yang2019`, NVIDIA Adaptive Shading; :class:`FidelityFX`, AMD FidelityFX
VRS) choose rates from the same frames as the model; :class:`Oracle` chooses from the true metric.
"""

from __future__ import annotations

from . import plots
from ._baselines import (
    FFX_LUMA,
    BaselineError,
    FidelityFX,
    Frame,
    ModelSelector,
    Oracle,
    RateSelector,
    Yang2019,
    as_frame,
    motion_factor_half,
    motion_factor_quarter,
    restrict_rates,
)
from ._engine import ENGINE_IMAGES, engine_rates, foveation_rates, motion_rates
from ._evaluate import (
    CONTAINED_RATES,
    DEFAULT_UNSEEN_FRACTION,
    SPLITS,
    EvaluationReport,
    check_evaluation,
    evaluate,
    failing_tiles,
    monotone_over_rates,
    spearman,
    tile_unseen_share,
    write_reports,
)
from ._play import (
    DEFAULT_METHODS,
    METHOD_KINDS,
    REUSE_REDUCTIONS,
    REUSE_UNSEEN,
    MethodSpec,
    PlayError,
    PlayReport,
    fail_rule,
    parse_methods,
    play,
    saved_at,
)
from ._scores import Scores, scores

__all__ = [
    "CONTAINED_RATES",
    "DEFAULT_METHODS",
    "DEFAULT_UNSEEN_FRACTION",
    "ENGINE_IMAGES",
    "METHOD_KINDS",
    "FFX_LUMA",
    "SPLITS",
    "BaselineError",
    "EvaluationReport",
    "FidelityFX",
    "MethodSpec",
    "Frame",
    "ModelSelector",
    "Oracle",
    "PlayError",
    "PlayReport",
    "REUSE_REDUCTIONS",
    "REUSE_UNSEEN",
    "RateSelector",
    "Scores",
    "Yang2019",
    "as_frame",
    "check_evaluation",
    "engine_rates",
    "evaluate",
    "fail_rule",
    "failing_tiles",
    "foveation_rates",
    "monotone_over_rates",
    "motion_factor_half",
    "motion_factor_quarter",
    "motion_rates",
    "parse_methods",
    "play",
    "plots",
    "restrict_rates",
    "saved_at",
    "scores",
    "spearman",
    "tile_unseen_share",
    "write_reports",
]
