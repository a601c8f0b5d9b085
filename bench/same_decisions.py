"""Do two files of one model predict and decide alike? For a graph pass that reorders float sums
(``rtp.export.split_input_planes``, which ``rtp-export --restamp`` applies) or a rebuild of a file.

    python bench/same_decisions.py OLD.onnx NEW.onnx --data data/test
    git show HEAD~1:models/jnyang.onnx > old-jnyang.onnx && python bench/same_decisions.py old-jnyang.onnx jnyang --data data/test

Both files are loaded with ``rtp.sdk.load`` and run on the input planes of every sample of ``--data``
(a dataset folder of ``rtp capture``; no targets needed). Prints a Markdown table: the largest
difference of the network's output (``predict_raw``, transformed space) and of ``predict`` (the
metric's units), and the number of tiles whose rate code differs at 0.5, 1 and 2 times the model's
default threshold (for PSNR: 3 dB under, at and 3 dB over it). Where the decisions differ, the
evaluation's figures can too; where none does, every work-saved and failing-tile figure of
``rtp evaluate`` is the same.
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import UsageError, dataset_folder, positive, run_main  # bench/ is on sys.path when run as a script

from rtp import sdk
from rtp.capture import DatasetReader

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", help="a model: an .onnx path or a shipped model's name")
    ap.add_argument("new", help="the same model in another file")
    ap.add_argument("--data", type=dataset_folder, required=True, help="a dataset folder written by rtp capture")
    ap.add_argument("--limit", type=positive, default=None, help="the first N samples only")
    args = ap.parse_args(argv)
    a, b = sdk.load(args.old), sdk.load(args.new)
    def model(m: sdk.ModelMetadata) -> tuple[object, ...]:
        return m.metric, tuple(m.inputs), tuple(m.outputs), m.tile_size

    def said(m: sdk.ModelMetadata) -> str:
        return f"{m.metric} {list(m.outputs)} of {m.tile_size}-pixel tiles on {list(m.inputs)}"

    # (outputs or tiles of another shape: their difference was a numpy broadcast error after the progress bar)
    if model(a.metadata) != model(b.metadata):
        raise UsageError(f"the two files are not one model: {said(a.metadata)} against {said(b.metadata)}")
    meta = a.metadata
    t = meta.default_threshold
    thresholds = (t - 3.0, t, t + 3.0) if meta.higher_is_better else (0.5 * t, t, 2.0 * t)
    reader = DatasetReader(args.data)
    ids = list(reader.ids)[: args.limit]
    raw_diff = est_diff = 0.0
    differ = np.zeros(len(thresholds))
    tiles = 0
    for i in tqdm(ids, desc="predicting", unit="sample"):
        x = reader[i].inputs(meta.inputs)
        ra, rb = a.predict_raw(x), b.predict_raw(x)
        raw_diff = max(raw_diff, float(np.abs(ra - rb).max()))
        est_diff = max(est_diff, float(np.abs(meta.decode(ra) - meta.decode(rb)).max()))
        for k, thr in enumerate(thresholds):
            differ[k] += int((a.shading_rates(x, thr) != b.shading_rates(x, thr)).sum())
        tiles += ra.shape[-2] * ra.shape[-1]
    print(f"\n{meta.metric}: {args.old} against {args.new}, {len(ids)} samples of {args.data}, {tiles} tiles\n")
    print("| largest difference, network output | largest difference, predict | tiles whose rate differs at "
          + " / ".join(f"{v:g}" for v in thresholds) + " |")
    print("|---:|---:|---|")
    print(f"| {raw_diff:.2e} | {est_diff:.2e} | " + " / ".join(f"{int(v)}" for v in differ) + " |")
    return 0


if __name__ == "__main__":
    run_main(main)
