"""Per-output health of models on a dataset: does each predicted rate track its true error?

    python bench/outputs.py models/lpips.onnx [more.onnx ...] --data data/test [--every 4]

For every output rate of each model (metric units, safety included, as `predict` returns them)
against the targets of `rtp targets`: the Pearson correlation with the truth and the spread of the
predictions. A dead output (a ReLU of the paper's head that stopped firing, docs/training.md) shows
as spread ~0 and correlation ~0. Prints a Markdown table.
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import check_targets, dataset_folder, positive, run_main  # bench/ is on sys.path when run as a script

from rtp import sdk
from rtp.capture import DatasetReader, TargetStore


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="+", help="shipped model names or .onnx paths whose outputs to check")
    ap.add_argument("--data", type=dataset_folder, required=True, help="dataset folder with targets")
    ap.add_argument("--every", type=positive, default=4, help="use every n-th sample (default 4)")
    args = ap.parse_args()
    reader, store = DatasetReader(args.data), TargetStore(args.data)
    ids = reader.ids[:: args.every]
    predictors = [(path, sdk.load(path)) for path in args.models]  # (a model or its targets missing: before the table)
    for path, p in predictors:
        check_targets(store, ids, p.metadata.metric, p.metadata.tile_size, path)
    print(f"{len(ids)} samples of {args.data}\n")
    print("| model | rate | network output | correlation with the truth | prediction spread (std) | true mean | predicted mean |")
    print("|---|---|---|---|---|---|---|")
    for path, p in predictors:
        m = p.metadata
        pred = np.stack([p.predict(reader[i].inputs(m.inputs)) for i in ids])
        true = np.stack([store.load(i, m.metric, m.tile_size) for i in ids])
        for k, rate in enumerate(sdk.PREDICTED_RATES):
            q, g = pred[:, k].ravel(), true[:, k].ravel()
            ok = np.isfinite(q) & np.isfinite(g)
            q, g = q[ok], g[ok]
            corr = float(np.corrcoef(q, g)[0, 1]) if q.std() > 0 else float("nan")
            kind = "yes" if rate in m.outputs else "extrapolated"
            print(f"| {path} | {rate} | {kind} | {corr:.3f} | {q.std():.4f} | {g.mean():.4f} | {q.mean():.4f} |")


if __name__ == "__main__":
    run_main(main)
