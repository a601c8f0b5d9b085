"""How coloured each map's light is, and how far the red channel is from the luma the metrics measure.

    python bench/colour.py [--data data/train data/test] [--per-map 4]

The paper feeds the network the red channel of the reprojected frame (and of the albedo) as its
stand-in for brightness; every metric measures Rec.601 luma (``sdk.luma``), and the JN metrics divide
by it. Under white light red and luma move together; under coloured light they part. For every map
of each dataset, over ``--per-map`` of its samples (spread evenly), the full-rate frame's mean luma,
its mean chroma (max minus min of R, G, B) and the mean of |R - luma|, sorted by the last; each
map's split is read from the shipped ``scenes.yaml``. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
from collections import defaultdict

import numpy as np
from _common import dataset_folder, positive, run_main  # bench/ is on sys.path when run as a script

from rtp import sdk
from rtp.capture import DatasetReader
from rtp.capture.scenes import load_splits

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", nargs="+", type=dataset_folder, default=["data/train", "data/test"],
                    help="dataset folders (default: data/train data/test, from `make dataset`)")
    ap.add_argument("--per-map", type=positive, default=4, help="samples read per map (spread evenly)")
    args = ap.parse_args()
    for folder in args.data:  # (argparse does not apply a type to a list default)
        try:
            dataset_folder(folder)
        except argparse.ArgumentTypeError as err:
            ap.error(f"argument --data: {err}")
    split_of = {m: name for name, maps in load_splits().items() for m in maps}
    rows = []
    for folder in args.data:
        reader = DatasetReader(folder)
        by_map: dict[str, list[str]] = defaultdict(list)
        for sample in reader:
            by_map[str(sample.meta.get("scene"))].append(sample.id)
        for scene, ids in tqdm(sorted(by_map.items()), desc=folder, unit="map"):
            pick = [ids[int(i)] for i in np.linspace(0, len(ids) - 1, min(args.per_map, len(ids)))]
            stats = []
            for sid in pick:
                rgb = reader[sid].final("1x1")
                y = sdk.luma(rgb)
                stats.append((y.mean(), (rgb.max(-1) - rgb.min(-1)).mean(), np.abs(rgb[..., 0] - y).mean()))
            rows.append((scene, split_of.get(scene, "?"), len(pick), *np.mean(stats, axis=0)))
    print("| map | split | samples | luma | chroma | abs(R - luma) |")
    print("|---|---|---:|---:|---:|---:|")
    for scene, split, n, y, c, d in sorted(rows, key=lambda r: -r[5]):
        print(f"| {scene} | {split} | {n} | {y:.3f} | {c:.3f} | {d:.3f} |")


if __name__ == "__main__":
    run_main(main)
