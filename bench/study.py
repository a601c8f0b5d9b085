"""Architecture and recipe study (issue "Networks that beat the paper's"): train each configuration on
the train maps, score it on the validation maps, time it at 1080p. Prints a Markdown table.

    python bench/study.py --data data/train --metric jnyang --out data/study            # every config
    python bench/study.py --data data/train --metric jnyang --out data/study --only fast-w16-d3,paper

Each configuration is the paper-net recipe (train/recipes/paper-net.yaml) with a few fields changed
(CONFIGS below). Trainings are resumable: rerunning skips finished checkpoints and continues
interrupted ones. ``--reference NAME`` adds a row for an exported model (a shipped model's name or an
.onnx path) scored the same way, without training. The scores are the validation maps' R² in
transformed space over all tiles, and over the seen and unseen ones (a tile is unseen when more than
half its pixels are); the 2x2 and 4x4 rates are scored separately (extrapolated unless the network
predicts them); the time is ``sdk predict`` of a 1920x1080 frame, median of 7, 2 threads.
Design choices are made on these validation maps only; the test split is reported once, at the end.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

import numpy as np
from _common import (  # bench/ is on sys.path when run as a script
    UsageError,
    dataset_folder,
    median_ms,
    positive,
    run_main,
)

from rtp import sdk
from rtp.capture.scenes import load_splits
from rtp.evaluate import evaluate

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from rtp.export import export_checkpoint
    from rtp.train import TrainConfig, train
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

#: name -> TrainConfig fields over the shipped recipe.
CONFIGS: dict[str, dict[str, Any]] = {
    "paper": {"arch": "paper"},
    "paper-aug": {"arch": "paper", "augment": True},
    "fast-w16-d3": {"arch": "fast", "width": 16, "depth": 3},
    "fast-w16-d5": {"arch": "fast", "width": 16, "depth": 5},
    "fast-w16-d5-aug": {"arch": "fast", "width": 16, "depth": 5, "augment": True},
    "fast-w24-d5-aug": {"arch": "fast", "width": 24, "depth": 5, "augment": True},
    "fast-w32-d5-aug": {"arch": "fast", "width": 32, "depth": 5, "augment": True},
    "fast-w16-d7-aug": {"arch": "fast", "width": 16, "depth": 7, "augment": True},
    "fast-s2-w16-d5-aug": {"arch": "fast", "stem": 2, "width": 16, "depth": 5, "augment": True},
    "fast-s2-w16-d5": {"arch": "fast", "stem": 2, "width": 16, "depth": 5},
    "fast-s2-w16-d3": {"arch": "fast", "stem": 2, "width": 16, "depth": 3},
    "fast-w32-d5": {"arch": "fast", "width": 32, "depth": 5},
    "fast-w16-d3-long": {"arch": "fast", "width": 16, "depth": 3, "steps": 12000},
    "fast-w32-d5-long": {"arch": "fast", "width": 32, "depth": 5, "steps": 12000},
    "fast-s2-w24-d3": {"arch": "fast", "stem": 2, "width": 24, "depth": 3},
    "fast-s2-w16-d3-long": {"arch": "fast", "stem": 2, "width": 16, "depth": 3, "steps": 12000},
    "fast-w16-d3-xlong": {"arch": "fast", "width": 16, "depth": 3, "steps": 24000},
    "fast-s2-w16-d3-aug": {"arch": "fast", "stem": 2, "width": 16, "depth": 3, "augment": True},
    "fast-s2-w24-d6-aug": {"arch": "fast", "stem": 2, "width": 24, "depth": 6, "augment": True},
    "fast-w16-d5-long": {"arch": "fast", "width": 16, "depth": 5, "steps": 12000},
    "fast-s8-w16-d5-long": {"arch": "fast", "stem": 8, "width": 16, "depth": 5, "steps": 12000},
    "fast-s8-w32-d4-long": {"arch": "fast", "stem": 8, "width": 32, "depth": 4, "steps": 12000},
    # all six rates predicted directly instead of 2x2 and 4x4 extrapolated from the other four
    "fast-w16-d3-long-six": {"arch": "fast", "width": 16, "depth": 3, "steps": 12000, "outputs": sdk.OUTPUT_SETS[2]},
}

#: The input study (the paper's Table 1): input sets from what the dataset holds. Use as
#: ``CONFIG+SET`` (for example ``fast-w16-d5-aug+normals``); "paper" is the paper's four channels.
INPUT_SETS: dict[str, tuple[str, ...]] = {
    "paper": ("reprojected.r", "seen", "albedo.r", "normal.z"),
    "normals": ("reprojected.r", "seen", "albedo.r", "normal.x", "normal.y", "normal.z"),
    "rgb": ("reprojected.r", "reprojected.g", "reprojected.b", "seen", "albedo.r", "normal.z"),
    "albedo-rgb": ("reprojected.r", "seen", "albedo.r", "albedo.g", "albedo.b", "normal.z"),
    "depth": ("reprojected.r", "seen", "albedo.r", "normal.z", "depth"),
    "motion": ("reprojected.r", "seen", "albedo.r", "normal.z", "motion.x", "motion.y"),
    "shadow": ("reprojected.r", "seen", "albedo.r", "normal.z", "shadow"),
    "material": ("reprojected.r", "seen", "albedo.r", "normal.z", "roughness", "metallic", "specular"),
    "emissive": ("reprojected.r", "seen", "albedo.r", "normal.z", "emissive"),
    # the material channels both adapters produce (pyrender has no specular scale)
    "rough-metal": ("reprojected.r", "seen", "albedo.r", "normal.z", "roughness", "metallic"),
    "both-adapters": ("reprojected.r", "reprojected.g", "reprojected.b", "seen", "albedo.r", "albedo.g", "albedo.b",
                      "normal.x", "normal.y", "normal.z"),
}


def _config(name: str) -> dict[str, Any]:
    base, _, inputs = name.partition("+")
    if base not in CONFIGS or (inputs and inputs not in INPUT_SETS):
        raise UsageError(f"unknown configuration {name!r}; known: {', '.join(CONFIGS)}, optionally +{'/+'.join(INPUT_SETS)}")
    return {**CONFIGS[base], **({"inputs": INPUT_SETS[inputs]} if inputs else {})}


def _score(model: str | Path, data: str, scenes: list[str]) -> dict[str, float]:
    rep = evaluate(model, data, scenes=scenes, baselines=False, sweep=False)
    return {split: rep.row("quality", "model", split=split)["r2"] for split in ("all", "seen", "unseen")}


def _score_extrapolated(model: str | Path, data: str, scenes: list[str]) -> float:
    """R² (transformed space, all tiles of ``scenes``) of the 2x2 and 4x4 rates: predicted directly by
    a six-output network, extrapolated from the others (paper Section 4.3) otherwise. No safety margin,
    like the other scores."""
    from rtp.capture import DatasetReader, TargetStore
    from rtp.evaluate import scores

    pred = sdk.load(model, providers=["CPUExecutionProvider"], threads=2)
    meta, t = pred.metadata, pred.metadata.transform
    reader, store = DatasetReader(data), TargetStore(data)
    rows = [sdk.PREDICTED_RATES.index(r) for r in ("2x2", "4x4")]
    ps, gs = [], []
    for s in reader:
        if s.meta.get("scene") not in scenes:
            continue
        raw = pred.predict_raw(s.inputs(meta.inputs))
        full = sdk.extrapolate(t.inverse(raw.astype(np.float64)), meta.outputs, meta.extrapolation_k,
                               higher_is_better=meta.higher_is_better)
        ps.append(t.forward(full[rows]).ravel())
        gs.append(t.forward(store.load(s.id, meta.metric, meta.tile_size)[rows].astype(np.float64)).ravel())
    worse = 1.0 if t.increasing != meta.higher_is_better else -1.0
    return scores(np.concatenate(ps), np.concatenate(gs), worse=worse).r2


def _ms(model: str | Path) -> float:
    pred = sdk.load(model, providers=["CPUExecutionProvider"], threads=2)
    x = np.random.default_rng(0).random((len(pred.metadata.inputs), 1080, 1920), dtype=np.float32)
    return median_ms(lambda: pred.predict(x), 7)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=dataset_folder, required=True,
                    help="dataset with targets holding the train and validation maps")
    ap.add_argument("--metric", default="jnyang", choices=sorted(sdk.METRICS), help="the metric trained (default: jnyang)")
    ap.add_argument("--out", required=True, help="folder for the checkpoints and exports")
    ap.add_argument("--only", default=None,
                    help="comma-separated configuration names (default: all; \"\": only the --reference models)")
    ap.add_argument("--steps", type=positive, default=None, help="training steps (default: the recipe's)")
    ap.add_argument("--reference", action="append", default=[], help="an exported model to score alongside")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    names = [n for n in args.only.split(",") if n] if args.only is not None else list(CONFIGS)  # --only "": references only
    if not names and not args.reference:
        ap.error('--only "" scores the --reference models only: give at least one --reference')
    configs = {n: _config(n) for n in names}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    val_maps = load_splits()["validation"]
    rows = []
    for ref in args.reference:
        rows.append((f"reference {ref}", {**_score(ref, args.data, val_maps),
                                          "2x2/4x4": _score_extrapolated(ref, args.data, val_maps)}, _ms(ref)))
        print(f"| {rows[-1][0]} | {rows[-1][1]} | {rows[-1][2]:.1f} |", file=sys.stderr, flush=True)
    for name in names:
        overrides = dict(configs[name])
        if args.steps:
            overrides["steps"] = args.steps
        cfg = TrainConfig.from_recipe("paper-net", data=args.data, metric=args.metric,
                                      out=str(out / f"{args.metric}-{name}.pt"), **overrides)
        result = train(cfg)
        onnx_path = export_checkpoint(result.checkpoint, out / f"{args.metric}-{name}.onnx")
        rows.append((name, {**_score(onnx_path, args.data, val_maps),
                            "2x2/4x4": _score_extrapolated(onnx_path, args.data, val_maps)}, _ms(onnx_path)))
        print(f"| {name} | {rows[-1][1]} | {rows[-1][2]:.1f} |", file=sys.stderr, flush=True)
    print(f"{args.metric}, validation maps {', '.join(val_maps)}, {args.data}\n")
    print("| configuration | R² all % | R² seen % | R² unseen % | R² 2x2, 4x4 % | 1080p sdk predict (ms) |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, r2, ms in rows:
        print(f"| {name} | {100 * r2['all']:.1f} | {100 * r2['seen']:.1f} | {100 * r2['unseen']:.1f} | "
              f"{100 * r2['2x2/4x4']:.1f} | {ms:.1f} |")


if __name__ == "__main__":
    run_main(main)
