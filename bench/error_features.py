"""Is a metric's per-tile target a function of the tile's pixel error? The true error against the model.

    python bench/error_features.py models/lpips.onnx     # default: the validation maps of data/train

The ``.blocks`` input planes (the variance inside each rate's blocks: what shading a block once
loses) lifted JNYang, FLIP and PSNR and did nothing for LPIPS. This script asks why, from the
dataset alone. For every tile and output rate it computes simple statistics that no engine has:

- **the true error**: the squared colour difference between the frame shaded at that rate and the
  full-rate frame, averaged over the tile and over windows of 3, 5 and 9 tiles around it (logs);
- **the content**: the full-rate frame's luma gradient energy and luma variance over the tile and
  over 5 tiles around it (logs), and its mean luma over the same.

Then, per output and leaving one map out at a time (fit on the others, scored on it), a small MLP
maps each set of statistics to the target (transformed space, as R² scores it). Printed per output:
the model's own R² (raw output, no safety margin) and the R² of the fits on the content, on the
true error, on both, and on both plus the model's output. Where the true error and the content
explain about as much as the model, the metric is local and planes that estimate the pixel error are
its lever; where they explain far less than the model, the target depends on more than the tile's
error (LPIPS: deep features of the neighbourhood), and better error estimates cannot help it.
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import (  # bench/ is on sys.path when run as a script
    UsageError,
    add_model_args,
    check_targets,
    count,
    positive,
    run_main,
    scene_ids,
)

from rtp import sdk
from rtp.capture import DatasetReader, TargetStore

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

#: Windows (in tiles) the true error is averaged over: the tile, then its neighbourhood.
ERROR_WINDOWS = (1, 3, 5, 9)
#: The statistics' columns, in order.
CONTENT = ("log gradient energy", "log gradient energy, 5 tiles", "log luma variance",
           "log luma variance, 5 tiles", "mean luma", "mean luma, 5 tiles")
ERROR = tuple(f"log true error, {k} tiles" for k in ERROR_WINDOWS)
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def tile_means(plane: np.ndarray, tile: int) -> np.ndarray:
    """Per whole tile, the mean of ``plane`` (a partial last row or column of tiles is dropped, as the
    targets' whole tiles are what is scored)."""
    th, tw = plane.shape[0] // tile, plane.shape[1] // tile
    return plane[:th * tile, :tw * tile].reshape(th, tile, tw, tile).mean(axis=(1, 3))


def window_mean(grid: np.ndarray, k: int) -> np.ndarray:
    """The mean over a ``k x k`` window of tiles around each tile (the grid's edge repeated)."""
    if k == 1:
        return grid
    p = k // 2
    padded = np.pad(grid, p, mode="edge")
    c = padded.cumsum(0).cumsum(1)
    c = np.pad(c, ((1, 0), (1, 0)))
    h, w = grid.shape
    return (c[k:k + h, k:k + w] - c[:h, k:k + w] - c[k:k + h, :w] + c[:h, :w]) / (k * k)


def content_features(ref: np.ndarray, tile: int) -> np.ndarray:
    """The content statistics of a full-rate frame ``(H, W, 3)``: ``(th, tw, len(CONTENT))``."""
    y = ref.astype(np.float64) @ _LUMA
    gx = np.zeros_like(y)
    gy = np.zeros_like(y)
    gx[:, 1:] = np.diff(y, axis=1)
    gy[1:] = np.diff(y, axis=0)
    grad = tile_means(gx * gx + gy * gy, tile)
    mean = tile_means(y, tile)
    var = np.maximum(tile_means(y * y, tile) - mean * mean, 0.0)
    cols = [np.log(grad + 1e-6), np.log(window_mean(grad, 5) + 1e-6), np.log(var + 1e-6),
            np.log(window_mean(var, 5) + 1e-6), mean, window_mean(mean, 5)]
    return np.stack(cols, -1)


def error_features(shaded: np.ndarray, ref: np.ndarray, tile: int) -> np.ndarray:
    """The true error statistics of a frame shaded at one rate against the full-rate one:
    ``(th, tw, len(ERROR))``."""
    d = shaded.astype(np.float64) - ref.astype(np.float64)
    e = tile_means((d * d).sum(-1), tile)
    return np.stack([np.log(window_mean(e, k) + 1e-7) for k in ERROR_WINDOWS], -1)


def r2(pred: np.ndarray, truth: np.ndarray) -> float:
    d = truth - truth.mean()
    return float(1.0 - ((pred - truth) ** 2).sum() / (d * d).sum())


def held_out_r2(x: np.ndarray, y: np.ndarray, groups: np.ndarray, *, iterations: int = 1500, seed: int = 0) -> float:
    """R² of a small MLP (two hidden layers of 64, Adam) from ``x`` to ``y``, each group (map) scored
    by a fit on the others, pooled over the groups. Needs at least two groups."""
    import torch

    names = np.unique(groups)
    if len(names) < 2:
        raise ValueError(f"leave-one-map-out needs samples of at least two maps, got {list(names)}")
    preds, truths = [], []
    for k, name in enumerate(names):
        tr, te = groups != name, groups == name
        mu, sd = x[tr].mean(0), x[tr].std(0) + 1e-9
        torch.manual_seed(seed + k)
        xt = torch.tensor((x[tr] - mu) / sd, dtype=torch.float32)
        yt = torch.tensor(y[tr], dtype=torch.float32)
        net = torch.nn.Sequential(torch.nn.Linear(x.shape[1], 64), torch.nn.ReLU(), torch.nn.Linear(64, 64),
                                  torch.nn.ReLU(), torch.nn.Linear(64, 1))
        opt = torch.optim.Adam(net.parameters(), 3e-3)
        gen = torch.Generator().manual_seed(seed + k)
        for _ in range(iterations):
            idx = torch.randint(0, len(xt), (min(4096, len(xt)),), generator=gen)
            loss = ((net(xt[idx])[:, 0] - yt[idx]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        with torch.no_grad():
            preds.append(net(torch.tensor((x[te] - mu) / sd, dtype=torch.float32))[:, 0].numpy())
        truths.append(y[te])
    return r2(np.concatenate(preds).astype(np.float64), np.concatenate(truths))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_args(ap, "an exported model (.onnx); its metric's targets are scored")
    ap.add_argument("--iterations", type=positive, default=1500, help="Adam steps of each fit (default 1500)")
    ap.add_argument("--seed", type=count, default=0, help="seed of the fits (default 0)")
    args = ap.parse_args(argv)
    pred = sdk.load(args.model, providers=["CPUExecutionProvider"])
    meta = pred.metadata
    reader, store = DatasetReader(args.data), TargetStore(args.data)
    ids = scene_ids(reader, args.scene)
    if not ids:
        raise UsageError(f"{args.data} holds no sample of {args.scene}")
    scenes = sorted({str(reader[i].meta.get("scene", "?")) for i in ids})  # (before the samples are read)
    if len(scenes) < 2:
        raise UsageError(f"leave-one-map-out needs samples of at least two maps, got {scenes}: --scene names them")
    check_targets(store, ids, meta.metric, meta.tile_size, args.model)
    rows = [sdk.PREDICTED_RATES.index(r) for r in meta.outputs]
    t = meta.tile_size
    feats: list[list[np.ndarray]] = [[] for _ in rows]
    truth: list[list[np.ndarray]] = [[] for _ in rows]
    model: list[list[np.ndarray]] = [[] for _ in rows]
    maps: list[np.ndarray] = []
    for i in tqdm(ids, desc="tiles", unit="sample"):
        s = reader[i]
        g = np.asarray(meta.transform.forward(store.load(i, meta.metric, t)[rows]))
        raw = pred.predict_raw(s.inputs(meta.inputs)).reshape(g.shape)
        ref = s.final("1x1")
        th, tw = ref.shape[0] // t, ref.shape[1] // t  # whole tiles only
        content = content_features(ref, t)
        for j, rate in enumerate(meta.outputs):
            x = np.concatenate([content, error_features(s.final(rate), ref, t)], -1)
            feats[j].append(x.reshape(-1, x.shape[-1]))
            truth[j].append(g[j, :th, :tw].reshape(-1))
            model[j].append(raw[j, :th, :tw].reshape(-1))
        maps.append(np.full(th * tw, str(s.meta.get("scene", "?")), dtype=object))
    groups = np.concatenate(maps)
    nc = len(CONTENT)
    print(f"\n{meta.metric}, {args.model} on {len(ids)} samples of {args.data} ({args.scene or 'every map'}): "
          f"R² % of each output, transformed space, no safety margin; the fits leave one map out\n")
    print("| output | the model | content | true error | true error + content | + the model |")
    print("|---|---:|---:|---:|---:|---:|")
    for j, rate in enumerate(meta.outputs):
        x, y, p = np.concatenate(feats[j]), np.concatenate(truth[j]), np.concatenate(model[j])
        ok = np.isfinite(y) & np.isfinite(x).all(1) & np.isfinite(p)
        x, y, p, grp = x[ok], y[ok].astype(np.float64), p[ok].astype(np.float64), groups[ok]
        fits = [held_out_r2(cols, y, grp, iterations=args.iterations, seed=args.seed)
                for cols in (x[:, :nc], x[:, nc:], x, np.concatenate([x, p[:, None]], 1))]
        print(f"| {rate} | {100 * r2(p, y):.1f} | " + " | ".join(f"{100 * v:.1f}" for v in fits) + " |", flush=True)
    return 0


if __name__ == "__main__":
    run_main(main)
