"""How much of prediction reuse's loss is the true error's own change from frame to frame.

`rtp play` shows reuse losing a step at the first carried frame, then little more (`python
bench/play_report.py --by-age`). Two readings: the carried estimates miss what the network would
see on the new frame, or the true per-tile error itself changes from one frame to the next (the
content falls differently on the shading blocks after every sub-pixel move), which no estimate
made on another frame can follow. This script separates them on one camera path: per pair of
consecutive frames (t, t + 1) it chooses the rates of frame t + 1 from

- ``network t+1``: the network on frame t + 1 (k = 1),
- ``network t, carried``: the network's estimates on frame t carried to t + 1 as reuse carries them
  (``sdk.PredictionReuse``'s carry: the mean over each tile's kept pixels, default step),
- ``network t, carried, rescaled``: the same, rescaled to frame t + 1's blocks' variance as
  ``sdk.PredictionReuse(rescale=A)`` does (``--rescale A``; models with ``.blocks`` inputs),
- ``truth t, carried``: the true errors of frame t carried the same way (an oracle one frame late),
- ``truth t+1``: the oracle,

and prints each one's failing share and work saved at the model's default threshold, mean over the
pairs. The histories are the full-rate frames (open loop, as the dataset's pairs), so every row
sees the same inputs. If ``truth t, carried`` fails about as often as ``network t, carried`` does
over ``network t+1``, the loss is the truth's motion, not the carry's.

    python bench/reuse_floor.py kaos --path slow --frames 40 --rescale 0.25     # a validation map; 2-3 min
"""

from __future__ import annotations

import argparse

import numpy as np

from rtp import metrics, sdk
from rtp.capture import load_scene
from rtp.capture.paths import PathPlayer, camera_path
from rtp.evaluate._evaluate import failing_tiles
from rtp.evaluate._play import model_inputs
from rtp.sdk._channels import BLOCK_EPS
from rtp.sdk._reuse import carry_estimates, start_track, tile_block_levels

ROWS = ("network t+1", "network t, carried", "network t, carried, rescaled", "truth t, carried", "truth t+1")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map", help="a map of scenes.yaml (tune on the validation maps only)")
    ap.add_argument("--path", default="slow", help="camera path profile (default: slow)")
    ap.add_argument("--frames", type=int, default=40, help="frames of the path (default: 40)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--model", default="jnyang", help="shipped model or .onnx (default: jnyang)")
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--rescale", type=float, default=0.25, help="exponent of the rescaled row (default: 0.25)")
    args = ap.parse_args()
    pred = sdk.load(args.model)
    meta = pred.metadata
    metric, thr, hib = meta.metric, meta.default_threshold, meta.higher_is_better
    tile = pred.tile_size
    w, h = (int(v) for v in args.size.split("x"))
    scn, blockers = load_scene(args.map, None, None, None)
    path = camera_path(scn, args.frames, args.path, args.seed, blockers=blockers)
    blocks = [i for i, c in enumerate(meta.inputs) if c.endswith(".blocks")]
    rows = ROWS if blocks else tuple(r for r in ROWS if not r.endswith("rescaled"))
    fail: dict[str, list[float]] = {r: [] for r in rows}
    saved: dict[str, list[float]] = {r: [] for r in rows}

    def levels(x: np.ndarray) -> np.ndarray:  # (v + eps) ** rescale per tile and rate, as PredictionReuse
        return np.exp(args.rescale * -np.log(BLOCK_EPS) * tile_block_levels(x[blocks], tile).astype(np.float64))

    prev: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None  # network, truth, frame, levels of t
    with PathPlayer(scn, (w, h), exact=False) as player:
        for pf in player.frames(path):
            ref = pf.frame.colour["1x1"]
            truth = metrics.tile_targets(ref, {r: pf.frame.colour[r] for r in sdk.PREDICTED_RATES}, (metric,),
                                         tile)[metric]
            if pf.index == 0:
                prev = (np.zeros(0), truth, ref, np.zeros(0))
                continue
            assert prev is not None
            rp = pf.reproject(prev[2])
            x = model_inputs(pf, rp, meta.inputs, slice(0, h), slice(0, w))
            net = pred.predict(x)
            lv = levels(x) if blocks else np.zeros(0)
            if prev[0].size:  # frame t had a network run: carry it and its truth to t + 1
                sky = pf.frame.mask <= 0.5
                carried = {}
                sources = [("network t, carried", prev[0]), ("truth t, carried", prev[1])]
                if blocks:
                    sources.append(("network t, carried, rescaled", (prev[0] / prev[3]).astype(np.float32)))
                for name, est in sources:
                    carried[name], _, missing = carry_estimates(est.reshape(len(est), -1), start_track((h, w), tile),
                                                                pf.rows, pf.cols, pf.seen, sky, tile, hib, 0.5)
                if blocks:
                    r = "network t, carried, rescaled"
                    carried[r] = np.where(missing[None], carried[r], carried[r] * lv).astype(np.float32)
                for name, est in (("network t+1", net), *carried.items(), ("truth t+1", truth)):
                    rates = sdk.select_rates(est, thr, higher_is_better=hib)
                    fail[name].append(float(failing_tiles(rates, truth, thr, hib).mean()))
                    saved[name].append(sdk.work_saved(rates, (h, w), tile))
            prev = (net, truth, ref, lv)
    n = len(fail[rows[0]])
    print(f"{args.map}, {args.path} path (seed {args.seed}), {n} pairs of consecutive frames at {w}x{h}; "
          f"{args.model} ({metric}) at its default threshold {thr:g}; histories at full rate; rescaled: "
          f"exponent {args.rescale:g}\n")
    print("| rates of frame t+1 from | failing tiles % | work saved % |")
    print("|---|---:|---:|")
    for r in rows:
        print(f"| {r} | {100 * np.mean(fail[r]):.2f} | {100 * np.mean(saved[r]):.1f} |")


if __name__ == "__main__":
    main()
