"""How much averaging models would buy: R² of each model and of their mean prediction.

    python bench/ensemble.py data/study/jnyang-big-mse.onnx data/study/jnyang-big-mse-seed1.onnx \
        [--data data/val | --data data/train --scene kaos,oa_dm3,oacmpdm4]

Every model must predict the same metric on the same tiles with the same target transform (models
trained by one recipe on one dataset). Per model, and for the mean of their network outputs (what
an ensemble shipped as one graph would predict), prints R² on all, seen and unseen tiles in
transformed space without the safety margin (docs/results.md's "no safety margin" columns; a tile is
unseen when more than half its pixels are). ``rtp train --teachers`` distills such a mean into one
network (docs/training.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _common import (  # bench/ is on sys.path when run as a script
    UsageError,
    check_targets,
    dataset_folder,
    run_main,
    scene_ids,
)

from rtp import sdk
from rtp.capture import DatasetReader, TargetStore
from rtp.evaluate import DEFAULT_UNSEEN_FRACTION, tile_unseen_share

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)


def _r2(p: np.ndarray, g: np.ndarray) -> float:
    ok = np.isfinite(g)
    d = g[ok] - g[ok].mean()
    return float(1.0 - ((p[ok] - g[ok]) ** 2).sum() / (d * d).sum())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("models", nargs="+", help="exported models (.onnx) of one metric, tile size and transform")
    ap.add_argument("--data", type=dataset_folder, default="data/val",
                    help="dataset with targets (default: data/val, the 72 validation samples of docs/export.md)")
    ap.add_argument("--scene", default=None, help="only these maps of --data (comma-separated), e.g. the validation "
                    "maps of data/train")
    args = ap.parse_args(argv)
    preds = [sdk.load(m, providers=["CPUExecutionProvider"]) for m in args.models]
    m0 = preds[0].metadata
    for path, p in zip(args.models, preds):
        m = p.metadata
        if (m.metric, m.tile_size, tuple(m.outputs), m.transform.to_dict()) != \
                (m0.metric, m0.tile_size, tuple(m0.outputs), m0.transform.to_dict()):
            raise UsageError(f"{path} predicts {m.metric} {list(m.outputs)} on {m.tile_size}-pixel tiles with transform "
                  f"{m.transform.to_dict()}; {args.models[0]}: {m0.metric} {list(m0.outputs)}, {m0.tile_size}, "
                  f"{m0.transform.to_dict()}")
    reader, store = DatasetReader(args.data), TargetStore(args.data)
    rows = [sdk.PREDICTED_RATES.index(r) for r in m0.outputs]
    out: list[list[np.ndarray]] = [[] for _ in preds]
    truth, unseen = [], []
    ids = scene_ids(reader, args.scene)
    if not ids:
        raise UsageError(f"{args.data} holds no sample of {args.scene}")
    check_targets(store, ids, m0.metric, m0.tile_size, args.models[0])  # (before the progress bar, not at its first sample)
    for i in tqdm(ids, desc="predicting", unit="sample"):
        s = reader[i]
        y = store.load(i, m0.metric, m0.tile_size)[rows]
        truth.append(m0.transform.forward(y).reshape(len(rows), -1))
        share = tile_unseen_share(s.channel("seen"), m0.tile_size).reshape(-1)
        unseen.append(np.broadcast_to(share > DEFAULT_UNSEEN_FRACTION, (len(rows), share.size)))
        for k, p in enumerate(preds):
            out[k].append(p.predict_raw(s.inputs(p.metadata.inputs)).reshape(len(rows), -1))
    g, u = np.concatenate(truth, 1), np.concatenate(unseen, 1)
    table = [(Path(m).name, np.concatenate(o, 1)) for m, o in zip(args.models, out)]
    table.append((f"mean of the {len(preds)}", np.mean([p for _, p in table], axis=0)))
    where = f"{args.data} ({args.scene})" if args.scene else args.data
    print(f"\n{m0.metric} on {len(ids)} samples of {where}: R² without the safety margin\n")
    print("| model | R² all % | R² seen % | R² unseen % |\n|---|---:|---:|---:|")
    for name, p in table:
        print(f"| {name} | {100 * _r2(p, g):.1f} | {100 * _r2(p[~u], g[~u]):.1f} | {100 * _r2(p[u], g[u]):.1f} |")
    return 0


if __name__ == "__main__":
    run_main(main)
