"""Inference cost of the paper's network: rtp.sdk predict vs the bare onnxruntime session vs torch.

    python bench/inference.py [--repeats 7] [--threads 2]

Builds the paper's configuration (4 inputs, outputs 1x2/2x1/2x4/4x2, 16x16 tiles, width 16) with
random weights (cost does not depend on the weights), exports it with rtp-export, and times each
path at 1920x1080 and 1280x720. Prints a Markdown table of medians (ms).
"""

from __future__ import annotations

import argparse
import platform
import tempfile
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch
from _common import median_ms, paper_model  # bench/ is on sys.path when run as a script

from rtp import sdk


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--threads", type=int, default=2, help="onnxruntime intra-op and torch threads")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    with tempfile.TemporaryDirectory() as d:
        net, onnx_path = paper_model(Path(d))
        pred = sdk.load(onnx_path, providers=["CPUExecutionProvider"], threads=args.threads)
        so = ort.SessionOptions()
        so.intra_op_num_threads = args.threads
        bare = ort.InferenceSession(str(onnx_path), so, providers=["CPUExecutionProvider"])
        rows = []
        for w, h in ((1920, 1080), (1280, 720)):
            x = np.random.default_rng(0).random((4, h, w), dtype=np.float32)
            hp, wp = sdk.padded_size(h, w, pred.tile_size)
            xp = np.pad(x[None], ((0, 0), (0, 0), (0, hp - h), (0, wp - w)), mode="edge")
            xt = torch.from_numpy(xp)

            def run_torch(xt: torch.Tensor = xt) -> object:
                with torch.inference_mode():
                    return net(xt)

            rows.append(
                (
                    f"{w}x{h}",
                    median_ms(lambda x=x: pred.predict(x), args.repeats),
                    median_ms(lambda x=x: pred.shading_rates(x), args.repeats),
                    median_ms(lambda xp=xp: bare.run(None, {"input": xp}), args.repeats),
                    median_ms(run_torch, args.repeats),
                )
            )
    print(f"rtp {sdk.__version__}, onnxruntime {ort.__version__}, torch {torch.__version__}, "
          f"{platform.processor() or platform.machine()}, {args.threads} threads, median of {args.repeats}\n")
    print("| frame | sdk predict (ms) | sdk shading_rates (ms) | bare onnxruntime (ms) | torch eager (ms) |")
    print("|---|---|---|---|---|")
    for name, a, b, c, e in rows:
        print(f"| {name} | {a:.1f} | {b:.1f} | {c:.1f} | {e:.1f} |")


if __name__ == "__main__":
    main()
