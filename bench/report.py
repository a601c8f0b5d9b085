"""Summary tables of `rtp evaluate` results (all scenes pooled; an evaluation of one scene, `--scene NAME`, its own
rows), as quoted in docs/results.md.

    python bench/report.py data/eval-jnyang/evaluation.json [more evaluation.json ...]
    python bench/report.py --compact data/eval-*/evaluation.json    # one row per model
    python bench/report.py --per-scene data/evalhold-*/evaluation.json    # one row per model and map


The last table gives each method's work saved at fixed shares of failing tiles (1, 2, 5, 10, 15%),
read off its threshold sweep by linear interpolation between the sweep's points ("-": the sweep
never fails that rarely; ">=": it never fails that often, and its best saving is a lower bound, as
`bench/play_report.py` marks it). It compares two models of one metric (before / after a retraining) as
well as methods.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from _common import EVALUATION_JSON, run_main  # bench/ is on sys.path when run as a script

from rtp.evaluate import saved_at


def pct(v: float) -> str:
    return "-" if v is None or v != v else f"{100 * v:.1f}"


def num(v: float | None) -> str:
    """Three decimals; "-" for a score that is not defined (a Spearman of constant values, no tiles: null)."""
    return "-" if v is None or v != v else f"{v:.3f}"


def model_label(d: dict) -> str:
    """The model's path, and the hardware tiles it decided and was judged on where they are not its own
    (`rtp evaluate --tile-size`): two runs of one model on 16- and 8-pixel tiles read apart."""
    m = d["model"]
    own = m.get("model_tile_size", m.get("tile_size"))
    return str(m["path"]) + (f" [{m['tile_size']}-pixel tiles; the model's {own}]" if own != m.get("tile_size") else "")


def pooled_scene(d: dict) -> str:
    """The scene name of ``d``'s pooled rows: "all scenes" where it evaluated several, its one scene's name where it
    evaluated one (`rtp evaluate --scene NAME`, as docs/evaluation.md's run does: evaluate writes no "all scenes"
    rows then, and the tables read as empty, the compact row as "-")."""
    scenes = dict.fromkeys(r["scene"] for r in (*d["quality"], *d["decisions"]))
    return next(iter(scenes)) if len(scenes) == 1 else "all scenes"


def table(header: list[str], rows: list[list[str]]) -> None:
    print("\n| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in rows:
        print("| " + " | ".join(r) + " |")


def main(paths: list[Path]) -> None:
    for path in paths:
        for d in json.load(open(path, encoding="utf-8")):
            scene = pooled_scene(d)
            print(f"\n### {d['model']['metric']} ({model_label(d)} on {d['data']}, {d['samples']} samples"
                  + ("" if scene == "all scenes" else f" of {scene}") + ")")
            pooled = [r for r in d["quality"] if r["scene"] == scene]
            table(["tiles", "method", "R² %", "MAE", "MAE under.", "σ MAE", "under %", "Spearman"], [
                [r["split"], r["method"], pct(r["r2"]), num(r["mae"]), num(r["mae_under"]), num(r["sigma"]),
                 pct(r["under_share"]), num(r["spearman"])] for r in pooled])
            decisions = [r for r in d["decisions"] if r["scene"] == scene]
            table(["tiles", "method", "threshold", "fails %", "work saved %"], [
                [r["split"], r["method"], f"{r['threshold']:g}", pct(r["fail_share"]), pct(r["work_saved"])]
                for r in decisions])
            if d.get("matched"):
                table(["method", "fails %", "work saved % at that failure rate", "parameter"], [
                    [m["method"], pct(m["fail_share"]), pct(m["work_saved"]), m["parameter"]] for m in d["matched"]])
            at_levels(d)

#: Shares of failing tiles at which the saving is read off the sweeps.
FAIL_LEVELS = (0.01, 0.02, 0.05, 0.10, 0.15)


def saved_cell(points: list[tuple[float, float]], fail: float) -> str:
    """The work saved % at ``fail`` failing tiles read off a sweep (``evaluate.saved_at``): "-" where it never fails
    that rarely, ">= " before its best saving where it never fails that often (a lower bound: printed plain, the
    best saving of a sweep whose every point fails less read as the saving at that failing share)."""
    v = saved_at(points, fail)
    if v is None:
        return "-"
    return (">= " if max(f for f, _ in points) < fail else "") + pct(v)


def at_levels(d: dict) -> None:
    methods: dict[str, list[tuple[float, float]]] = {}
    for r in d.get("sweep", []):
        methods.setdefault(r["method"], []).append((r["fail_share"], r["work_saved"]))
    if methods:
        table(["method", *[f"saved % at {100 * f:g}% fails" for f in FAIL_LEVELS]], [
            [m, *[saved_cell(p, f) for f in FAIL_LEVELS]]
            for m, p in methods.items()])


def compact(paths: list[Path]) -> None:
    """One row per model of every file: R² on all / seen / unseen tiles with the model's safety margin
    and without it, and the work saved at 1, 2, 5 and 10% failing tiles (before / after tables)."""
    rows = []
    for path in paths:
        for d in json.load(open(path, encoding="utf-8")):
            q = {(r["split"], r["method"]): r["r2"] for r in d["quality"] if r["scene"] == pooled_scene(d)}
            sweep = [(r["fail_share"], r["work_saved"]) for r in d.get("sweep", []) if r["method"] == "model"]
            rows.append([d["model"]["metric"], model_label(d), str(d["samples"]),
                         " / ".join(pct(q.get((s, "model"))) for s in ("all", "seen", "unseen")),
                         " / ".join(pct(q.get((s, "model (no safety)"))) for s in ("all", "seen", "unseen")),
                         " / ".join(saved_cell(sweep, f) for f in FAIL_LEVELS[:4])])
    table(["metric", "model", "samples", "R² all / seen / unseen %", "same, no safety margin",
           "saved % at 1 / 2 / 5 / 10% fails"], rows)


def per_scene(paths: list[Path]) -> None:
    """One row per model and scene of every file: R² on all / seen / unseen tiles with the model's
    safety margin and without it (a pooled R² mixes the maps' levels; held-out-map studies read these)."""
    rows = []
    for path in paths:
        for d in json.load(open(path, encoding="utf-8")):
            q = {(r["scene"], r["split"], r["method"]): r["r2"] for r in d["quality"]}
            scenes = dict.fromkeys(r["scene"] for r in d["quality"] if r["scene"] != "all scenes")
            for scene in [*scenes, *(["all scenes"] if len(scenes) > 1 else [])]:  # (one scene: no pooled rows)
                rows.append([model_label(d), scene,
                             " / ".join(pct(q.get((scene, s, "model"))) for s in ("all", "seen", "unseen")),
                             " / ".join(pct(q.get((scene, s, "model (no safety)"))) for s in ("all", "seen", "unseen"))])
    table(["model", "scene", "R² all / seen / unseen %", "same, no safety margin"], rows)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description="Summary tables of `rtp evaluate` results (evaluation.json files).")
    ap.add_argument("paths", nargs="+", type=EVALUATION_JSON, metavar="evaluation.json",
                    help="files written by `rtp evaluate --out DIR` (or the DIRs)")
    form = ap.add_mutually_exclusive_group()
    form.add_argument("--compact", action="store_true", help="one row per model: R² and work saved at 1-10%% failing")
    form.add_argument("--per-scene", action="store_true", help="one row per model and scene: R² with and without the margin")
    return ap.parse_args(argv)


def run(argv: list[str] | None = None) -> None:
    a = parse_args(argv)
    if a.compact:
        compact(a.paths)
    elif a.per_scene:
        per_scene(a.paths)
    else:
        main(a.paths)


if __name__ == "__main__":
    run_main(run)
