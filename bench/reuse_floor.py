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
- with ``--model CHECKPOINT.pt`` of a fast network whose block contrast joins at tile resolution
  (``rtp train --block-contrast ... --contrast-cell TILE``), also ``trunk t carried, tail t+1``: the
  network's features before the contrast joins, computed on frame t and carried like estimates (the
  mean over each tile's kept pixels), then the contrast of frame t + 1 and the layers after it (a
  3x3 block at tile resolution and the head, almost free) run on the new frame. That is the split a
  reuse scheme could run every frame while the trunk runs every k-th (not built into the SDK),


and prints each one's failing share and work saved at the model's default threshold, mean over the
pairs. The histories are the full-rate frames (open loop, as the dataset's pairs), so every row
sees the same inputs. If ``truth t, carried`` fails about as often as ``network t, carried`` does
over ``network t+1``, the loss is the truth's motion, not the carry's.

    python bench/reuse_floor.py kaos --path slow --frames 40 --rescale 0.25     # a validation map; 2-3 min

``--sweep`` (error metrics) also asks whether carried estimates want a threshold of their own. It
sweeps the threshold over a fine grid (the default times 2^(j/16)) for the network's rows and mixes
them as reuse at ``--every k`` does, one frame in k with the network's own estimates and k - 1 with
carried ones (rescaled where the model has ``.blocks`` planes; all carried one frame, the
open-loop approximation of a carry that the slow paths show losing a step at its first frame and
little after): for 1 / 2 / 5% failing tiles it prints the most work saved with one threshold for
both kinds of frame (what ``PredictionReuse`` does), with a threshold of each kind's own (the best
pair on the grid), and the network on every frame, and the ratio of the carried frames' threshold
to the network frames' that does best. If the pair keeps clearly more of k = 1's saving, a
threshold for carried frames is worth building into ``PredictionReuse``.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
from _common import count, frame_size, number, positive, run_main  # bench/ is on sys.path when run as a script

from rtp import metrics, sdk
from rtp.capture import load_scene
from rtp.capture.paths import PATH_PROFILES, PathPlayer, camera_path
from rtp.evaluate._evaluate import failing_tiles
from rtp.evaluate._play import model_inputs
from rtp.sdk._channels import BLOCK_EPS
from rtp.sdk._reuse import carry_estimates, start_track, tile_block_levels

ROWS = ("network t+1", "network t, carried", "network t, carried, rescaled", "truth t, carried", "truth t+1")
SPLIT_ROW = "trunk t carried, tail t+1"


class CheckpointModel:
    """A trained checkpoint run in torch with the predictor's decoding: ``predict(x)`` as
    ``ShadingRatePredictor.predict``, and for a network whose block contrast joins at tile resolution
    ``trunk(x)`` (the features before it, ``(C, th, tw)``) and ``tail(features, x)`` (the estimates from
    carried features and a new frame's contrast)."""

    def __init__(self, path: str) -> None:
        import torch

        from rtp.train.checkpoint import load

        self.torch = torch
        ck = load(path)
        self.net, self.metadata = ck.net, ck.metadata
        self.tile_size = self.metadata.tile_size
        contrast = getattr(self.net, "contrast", None)
        self.splits = contrast is not None and contrast.cell == self.tile_size

    def _decode(self, raw: object) -> np.ndarray:
        return np.asarray(self.metadata.decode(np.asarray(raw)[0]), np.float32)

    def predict(self, x: np.ndarray) -> np.ndarray:
        with self.torch.no_grad():
            return self._decode(self.net(self.torch.from_numpy(x[None])).numpy())

    def trunk(self, x: np.ndarray) -> np.ndarray:
        with self.torch.no_grad():
            return self.net.trunk(self.torch.from_numpy(x[None])).numpy()[0]

    def tail(self, features: np.ndarray, x: np.ndarray) -> np.ndarray:
        t = self.torch
        with t.no_grad():
            f = t.from_numpy(np.ascontiguousarray(features[None], np.float32))
            return self._decode(self.net.tail(f, t.from_numpy(x[None])).numpy())


def _frames(text: str) -> int:
    n = positive(text)
    if n < 3:  # (2 frames give no pair of a carried frame: a table of nan)
        raise argparse.ArgumentTypeError(f"expected at least 3 frames, got {text!r}")
    return n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map", help="a map of scenes.yaml, fetched by `rtp scenes fetch` (tune on the validation maps only)")
    ap.add_argument("--path", default="slow", choices=sorted(PATH_PROFILES), help="camera path profile (default: slow)")
    ap.add_argument("--frames", type=_frames, default=40, help="frames of the path, at least 3 (default: 40)")
    ap.add_argument("--seed", type=count, default=0, help="which path through the map (default: 0)")
    ap.add_argument("--model", default="jnyang", help="shipped model, .onnx, or a checkpoint .pt run in torch "
                    "(default: jnyang)")
    ap.add_argument("--size", type=lambda s: frame_size(s, 16), default=(1280, 720), help="WIDTHxHEIGHT (default 1280x720)")
    ap.add_argument("--rescale", type=number(-1e3, 1e3), default=0.25, help="exponent of the rescaled row (default: 0.25)")
    ap.add_argument("--sweep", action="store_true", help="also sweep the threshold and compare one threshold for "
                    "network and carried frames with one of each's own (error metrics)")
    ap.add_argument("--every", type=positive, default=4, help="with --sweep: the interval k of the reuse mixed (default: 4)")
    args = ap.parse_args()
    if args.every < 2:
        ap.error(f"--every: expected an interval >= 2, got {args.every}")
    pred: Any = CheckpointModel(args.model) if args.model.endswith(".pt") else sdk.load(args.model)
    meta = pred.metadata
    split = isinstance(pred, CheckpointModel) and pred.splits
    metric, thr, hib = meta.metric, meta.default_threshold, meta.higher_is_better
    if args.sweep and hib:
        ap.error(f"--sweep: the model's metric {metric} is better when higher; the sweep scales an error threshold")
    tile = pred.tile_size
    w, h = args.size
    scn, blockers = load_scene(args.map, None, None, None)
    path = camera_path(scn, args.frames, args.path, args.seed, blockers=blockers)
    blocks = [i for i, c in enumerate(meta.inputs) if c.endswith(".blocks")]
    rows = ROWS if blocks else tuple(r for r in ROWS if not r.endswith("rescaled"))
    rows = (*rows[:-2], SPLIT_ROW, *rows[-2:]) if split else rows
    fail: dict[str, list[float]] = {r: [] for r in rows}
    saved: dict[str, list[float]] = {r: [] for r in rows}
    grid = thr * 2.0 ** (np.arange(-48, 33) / 16)  # the sweep's thresholds
    swept = [r for r in rows if r.startswith("network") or r == SPLIT_ROW]
    curves: dict[str, list[np.ndarray]] = {r: [] for r in swept}  # per pair: (2, thresholds) failing, saved

    def levels(x: np.ndarray) -> np.ndarray:  # (v + eps) ** rescale per tile and rate, as PredictionReuse
        return np.exp(args.rescale * -np.log(BLOCK_EPS) * tile_block_levels(x[blocks], tile).astype(np.float64))

    prev: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None  # network, truth, frame, levels of t
    trunk = np.zeros(0)  # the split network's features on frame t
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
                if split and trunk.size:
                    feats, _, gone = carry_estimates(trunk.reshape(len(trunk), -1), start_track((h, w), tile),
                                                     pf.rows, pf.cols, pf.seen, sky, tile, hib, 0.5)
                    est = pred.tail(np.where(gone[None], 0.0, feats), x)
                    est[:, gone] = -np.inf if hib else np.inf  # tiles without carried features: 1x1, as the carry
                    carried[SPLIT_ROW] = est
                for name, est in (("network t+1", net), *carried.items(), ("truth t+1", truth)):
                    own = None if est is truth else meta.rate_factors  # the model's thresholds per rate, if any
                    rates = sdk.select_rates(est, thr, higher_is_better=hib, factors=own)
                    fail[name].append(float(failing_tiles(rates, truth, thr, hib).mean()))
                    saved[name].append(sdk.work_saved(rates, (h, w), tile))
                    if args.sweep and name in curves:  # fails are judged at the metric's threshold, always
                        rs = [sdk.select_rates(est, t, higher_is_better=hib, factors=own) for t in grid]
                        curves[name].append(np.array([[failing_tiles(r, truth, thr, hib).mean() for r in rs],
                                                      [sdk.work_saved(r, (h, w), tile) for r in rs]]))
            prev = (net, truth, ref, lv)
            trunk = pred.trunk(x) if split else trunk
    n = len(fail[rows[0]])
    print(f"{args.map}, {args.path} path (seed {args.seed}), {n} pairs of consecutive frames at {w}x{h}; "
          f"{args.model} ({metric}) at its default threshold {thr:g}; histories at full rate; rescaled: "
          f"exponent {args.rescale:g}\n")
    print("| rates of frame t+1 from | failing tiles % | work saved % |")
    print("|---|---:|---:|")
    for r in rows:
        print(f"| {r} | {100 * np.mean(fail[r]):.2f} | {100 * np.mean(saved[r]):.1f} |")
    if args.sweep:
        _print_sweep({r: np.mean(c, axis=0) for r, c in curves.items()}, grid / thr, args.every)


def best_saving(fail: np.ndarray, saved: np.ndarray, share: float) -> tuple[float, int]:
    """The most work saved among the points whose failing share is at most ``share`` (nan if none),
    and the flat index of that point."""
    ok = fail <= share
    if not ok.any():
        return float("nan"), -1
    i = int(np.argmax(np.where(ok, saved, -np.inf)))
    return float(saved.flat[i]), i


def mix_curves(fresh: np.ndarray, carried: np.ndarray, every: int) -> tuple[np.ndarray, np.ndarray]:
    """Failing share and work saved of reuse at interval ``every`` for every pair of thresholds (network
    frames', carried frames'): one frame in ``every`` with ``fresh`` (2, T), the others with ``carried``."""
    q = (every - 1) / every
    return ((1 - q) * fresh[0][:, None] + q * carried[0][None, :],
            (1 - q) * fresh[1][:, None] + q * carried[1][None, :])


def _print_sweep(curves: dict[str, np.ndarray], factors: np.ndarray, every: int) -> None:
    fresh = curves["network t+1"]
    print(f"\nReuse at k = {every}, mixed open-loop from the sweep ({len(factors)} thresholds, "
          f"{factors[0]:.3g}-{factors[-1]:.3g}x the default): work saved % at most 1 / 2 / 5% failing tiles "
          "(in brackets: % of k = 1's), and the best carried frames' threshold as a multiple of the network "
          "frames'\n")
    print("| carried estimates | one threshold | a threshold each | carried / network threshold |")
    print("|---|---|---|---|")
    k1 = [best_saving(fresh[0], fresh[1], s)[0] for s in (0.01, 0.02, 0.05)]
    for name in (r for r in curves if r != "network t+1"):
        f, v = mix_curves(fresh, curves[name], every)
        one, pair, ratio = [], [], []
        for share, base in zip((0.01, 0.02, 0.05), k1, strict=True):
            a = best_saving(np.diagonal(f), np.diagonal(v), share)[0]
            b, i = best_saving(f, v, share)
            one.append(f"{100 * a:.1f} ({100 * a / base:.1f}%)")
            pair.append(f"{100 * b:.1f} ({100 * b / base:.1f}%)")
            ratio.append("-" if i < 0 else f"{factors[i % len(factors)] / factors[i // len(factors)]:.2f}")
        print(f"| {name} | {' / '.join(one)} | {' / '.join(pair)} | {' / '.join(ratio)} |")
    print(f"| (network t+1 on every frame, k = 1) | {' / '.join(f'{100 * v:.1f}' for v in k1)} | | |")


if __name__ == "__main__":
    run_main(main)
