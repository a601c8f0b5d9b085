"""Summary tables of `rtp evaluate` results (all scenes pooled), as quoted in docs/results.md.

    python bench/report.py data/eval-jnyang/evaluation.json [more evaluation.json ...]
"""

from __future__ import annotations

import json
import sys


def pct(v: float) -> str:
    return "-" if v is None or v != v else f"{100 * v:.1f}"


def table(header: list[str], rows: list[list[str]]) -> None:
    print("\n| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in rows:
        print("| " + " | ".join(r) + " |")


def main(paths: list[str]) -> None:
    for path in paths:
        for d in json.load(open(path, encoding="utf-8")):
            print(f"\n### {d['model']['metric']} ({d['model']['path']} on {d['data']}, {d['samples']} samples)")
            pooled = [r for r in d["quality"] if r["scene"] == "all scenes"]
            table(["tiles", "method", "R² %", "MAE", "MAE under.", "σ MAE", "under %", "Spearman"], [
                [r["split"], r["method"], pct(r["r2"]), f"{r['mae']:.3f}", f"{r['mae_under']:.3f}", f"{r['sigma']:.3f}",
                 pct(r["under_share"]), f"{r['spearman']:.3f}"] for r in pooled])
            decisions = [r for r in d["decisions"] if r["scene"] == "all scenes"]
            table(["tiles", "method", "threshold", "fails %", "work saved %"], [
                [r["split"], r["method"], f"{r['threshold']:g}", pct(r["fail_share"]), pct(r["work_saved"])]
                for r in decisions])
            if d.get("matched"):
                table(["method", "fails %", "work saved % at that failure rate", "parameter"], [
                    [m["method"], pct(m["fail_share"]), pct(m["work_saved"]), m["parameter"]] for m in d["matched"]])

if __name__ == "__main__":
    main(sys.argv[1:])
