"""Where a model's squared error lies, and whether a smarter rate rule would use its estimates better.

    python bench/residuals.py models/jnyang.onnx [--data data/val | --data data/train --scene kaos,oa_dm3,oacmpdm4]

On every sample of a dataset with targets, the model's raw output (transformed space, no safety
margin: what docs/results.md's "no safety margin" columns score) against the transformed truth.
Prints three tables:

1. **Anatomy**: R², and the share of the squared error carried by groups of tiles: at a depth
   step (the largest ``sdk.depth_edges`` value in the tile over 0.5, or over 0.1), without one,
   seen and unseen tiles, each fifth of the targets, and the tiles whose target sits at the
   transform's upper clamp (1.0), the seen tiles whose reprojected frame is off the current full-rate
   one by more than 0.05 in mean luma (what the network is shown is not what is shaded); the mean
   residual (prediction minus truth) of each group, its RMS, how many points of R² the group costs
   (its squared error over the total variance), and its share of the large underestimates (by more
   than 0.3 in transformed space: table 4's tail).
2. **Offsets**: R² per map, and R² after adding the best constant per map or per frame (an oracle:
   how much a frame- or map-level correction could buy at most), and after an affine recalibration
   of each output (``a * raw + b``, least squares) fitted on the other maps (leave one map out: what
   a recalibration fitted on held-out maps, as the safety margin is, would buy on a map it never saw;
   free at run time, it folds into the head's last convolution; needs two maps or more).
3. **Rate rules** (the metric's failing threshold: a tile fails when its true error at the chosen
   rate is over the default threshold): work saved at 1 / 2 / 5 / 10% failing tiles by the SDK's rule
   (per tile the coarsest rate whose estimate passes one threshold, swept), and by a risk rule that
   calibrates, per rate, the chance that a tile fails given its estimate (on the other maps: leave
   one map out) and picks per tile the rate maximising saving minus lambda x that chance (swept),
   and by two thresholds, one for seen and one for unseen tiles (searched on the samples scored).
4. **What accuracy the saving needs**: the SDK's rule run on synthetic estimates, the truth of every
   rate plus Gaussian noise in transformed space scaled so that each of the model's outputs has a
   given R² (the model's own, drawn per rate and once per tile for all its rates, then 90 / 95 / 98%;
   ``--noise-seed``), next to the model and the
   oracle: how much of the oracle's saving an estimate of that accuracy keeps at 1 / 2 / 5 / 10%
   failing tiles, and so whether a target such as "90% of the oracle at 5%" is within reach of a
   better predictor of this kind.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np
from _common import (  # bench/ is on sys.path when run as a script
    UsageError,
    count,
    dataset_folder,
    run_main,
    save_figure,
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

#: Work saved by each predicted rate, in ``sdk.PREDICTED_RATES`` order.
_SAVE = np.array([1.0 - 1.0 / (int(r[0]) * int(r[2])) for r in sdk.PREDICTED_RATES])
_LEVELS = (0.01, 0.02, 0.05, 0.10)


def _r2(p: np.ndarray, g: np.ndarray) -> float:
    ok = np.isfinite(g)
    d = g[ok] - g[ok].mean()
    return float(1.0 - ((p[ok] - g[ok]) ** 2).sum() / (d * d).sum())


def _affine_lomo(p: np.ndarray, g: np.ndarray, maps: np.ndarray) -> np.ndarray | None:
    """``p`` (outputs, tiles) recalibrated per output by ``a * p + b`` fitted (least squares, finite
    targets) on every other map's tiles, map by map; None with fewer than two maps."""
    names = sorted(set(maps.tolist()))
    if len(names) < 2:
        return None
    out = np.empty_like(p, dtype=np.float64)
    for name in names:
        fit, use = maps != name, maps == name
        for j in range(p.shape[0]):
            ok = np.isfinite(g[j]) & fit
            a, b = np.linalg.lstsq(np.c_[p[j, ok], np.ones(int(ok.sum()))], g[j, ok], rcond=None)[0]
            out[j, use] = a * p[j, use] + b
    return out


def _tile_max(plane: np.ndarray, tile: int) -> np.ndarray:
    h, w = plane.shape
    th, tw = -(-h // tile), -(-w // tile)
    pad = np.zeros((th * tile, tw * tile), np.float32)
    pad[:h, :w] = plane
    return pad.reshape(th, tile, tw, tile).max(axis=(1, 3)).reshape(-1)


def _tile_mean(plane: np.ndarray, tile: int) -> np.ndarray:
    h, w = plane.shape
    th, tw = -(-h // tile), -(-w // tile)
    pad = np.zeros((th * tile, tw * tile), np.float64)
    pad[:h, :w] = plane
    n = np.zeros_like(pad)
    n[:h, :w] = 1.0
    return (pad.reshape(th, tile, tw, tile).sum(axis=(1, 3)) / n.reshape(th, tile, tw, tile).sum(axis=(1, 3))).reshape(-1)


def _saved_at(points: list[tuple[float, float]], level: float) -> float:
    ok = [s for f, s in points if f <= level]
    return max(ok) if ok else float("nan")


def _sweep(choose: Callable[[float], np.ndarray], fails: np.ndarray, values: np.ndarray) -> list[tuple[float, float]]:
    """(failing share, work saved) per parameter; ``choose`` gives per tile a rate row or -1 (1x1)."""
    cols = np.arange(fails.shape[1])
    out = []
    for v in values:
        best = choose(float(v))
        used = best >= 0
        fail = np.where(used, fails[np.maximum(best, 0), cols], False)
        out.append((float(fail.mean()), float(np.where(used, _SAVE[np.maximum(best, 0)], 0.0).mean())))
    return out


def _risk_table(pred: np.ndarray, fails: np.ndarray, bins: np.ndarray, higher_is_better: bool) -> np.ndarray:
    """Per rate and bin of the estimate, the share of tiles that fail (smoothed, and made monotone:
    never less likely to fail where the estimate is worse)."""
    tab = np.zeros((len(pred), len(bins) - 1))
    for i in range(len(pred)):
        b = np.clip(np.digitize(pred[i], bins) - 1, 0, len(bins) - 2)
        n = np.bincount(b, minlength=len(bins) - 1)
        f = np.bincount(b, weights=fails[i].astype(np.float64), minlength=len(bins) - 1)
        share = (f + 0.5) / (n + 1.0)
        tab[i] = np.maximum.accumulate(share[::-1])[::-1] if higher_is_better else np.maximum.accumulate(share)
    return tab


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model", help="an exported model (.onnx)")
    ap.add_argument("--data", type=dataset_folder, default="data/val",
                    help="dataset with targets (default: data/val, the 72 validation samples of docs/export.md)")
    ap.add_argument("--scene", default=None, help="only these maps of --data (comma-separated), e.g. the validation "
                    "maps of data/train")
    ap.add_argument("--noise-seed", type=count, default=0, help="seed of table 4's synthetic estimates (default 0)")
    ap.add_argument("--plot", default=None, metavar="PNG",
                    help="also draw table 4's curves (work saved against failing tiles) into this PNG")
    args = ap.parse_args(argv)
    pred = sdk.load(args.model, providers=["CPUExecutionProvider"])
    meta = pred.metadata
    reader, store = DatasetReader(args.data), TargetStore(args.data)
    rows = [sdk.PREDICTED_RATES.index(r) for r in meta.outputs]
    hib = meta.higher_is_better
    raw, truth, est, metric, edge, unseen, frame, scene, every = [], [], [], [], [], [], [], [], []
    moved = []  # per tile, the mean |luma| difference between the reprojected and the current full-rate frame
    ids = scene_ids(reader, args.scene)
    if not ids:
        raise UsageError(f"{args.data} holds no sample of {args.scene}")
    for k, i in enumerate(tqdm(ids, desc="predicting", unit="sample")):
        s = reader[i]
        x = s.inputs(meta.inputs)
        y = store.load(i, meta.metric, meta.tile_size)
        r = pred.predict_raw(x)
        raw.append(r.reshape(len(rows), -1))
        truth.append(np.asarray(meta.transform.forward(y[rows])).reshape(len(rows), -1))
        est.append(meta.decode(r[None])[0].reshape(6, -1))  # every rate, safety margin included
        metric.append(y.reshape(6, -1))
        every.append(np.asarray(meta.transform.forward(y)).reshape(6, -1))  # every rate's truth, transformed
        n = raw[-1].shape[1]
        edge.append(_tile_max(sdk.depth_edges(s.channel("depth")), meta.tile_size))
        unseen.append(tile_unseen_share(s.channel("seen"), meta.tile_size).reshape(-1) > DEFAULT_UNSEEN_FRACTION)
        moved.append(_tile_mean(np.abs(sdk.luma(s.final("1x1")) - s.channel("reprojected.y")), meta.tile_size))
        frame.append(np.full(n, k))
        scene.append(np.full(n, str(s.meta.get("scene", "?")), dtype=object))
    p, g = np.concatenate(raw, 1), np.concatenate(truth, 1)
    e, u, mv = np.concatenate(edge), np.concatenate(unseen), np.concatenate(moved)
    fr, sc = np.concatenate(frame), np.concatenate(scene)
    ok = np.isfinite(g)
    res2 = np.where(ok, (p - g) ** 2, 0.0)
    total = res2.sum()
    var = float(((g[ok] - g[ok].mean()) ** 2).sum())

    where = f"{args.data} ({args.scene})" if args.scene else args.data
    print(f"\n{meta.metric}, {args.model} on {len(ids)} samples of {where}: raw output, no safety margin; "
          f"R² {100 * _r2(p, g):.1f}%\n")
    big = ok & (meta.worse_direction * (np.nan_to_num(g) - p) > 0.3)  # large underestimates (table 4's tail)
    print("| tiles | share of tiles % | share of squared error % | mean residual | RMS residual | R² points lost | "
          "share of the underestimates by > 0.3 % |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    groups = [("depth step > 0.5", e > 0.5), ("depth step 0.1-0.5", (e > 0.1) & (e <= 0.5)),
              ("no depth step (<= 0.1)", e <= 0.1), ("seen", ~u), ("unseen", u),
              ("seen, reprojection off by > 0.05 (mean luma)", ~u & (mv > 0.05)),
              ("seen, reprojection within 0.05", ~u & (mv <= 0.05))]
    q = np.quantile(g[ok], np.linspace(0.0, 1.0, 6))
    band = np.minimum(np.searchsorted(q[1:-1], np.nan_to_num(g), side="right"), 4)  # a partition, ties included once
    bands = [(f"target fifth {j + 1} ({q[j]:.2f}-{q[j + 1]:.2f})", band == j) for j in range(5)]
    for name, m in groups + bands + [("target at the clamp (1.0)", g >= 1.0 - 1e-6)]:
        m = np.broadcast_to(m, g.shape) & ok
        print(f"| {name} | {100 * m.sum() / ok.sum():.1f} | {100 * res2[m].sum() / total:.1f} | "
              f"{float(np.mean(p[m] - g[m])) if m.any() else float('nan'):+.4f} | "
              f"{float(np.sqrt(np.mean(res2[m]))) if m.any() else float('nan'):.4f} | {100 * res2[m].sum() / var:.1f} | "
              f"{100 * (big & m).sum() / max(int(big.sum()), 1):.1f} |")

    # per output: the pooled R² also counts the difference between rates (a 4x4 errs more than a 1x2
    # everywhere), which the network gets for free; each output's own R² is the per-tile part
    print("\n| output | R² % | mean target | share at the clamp % |\n|---|---:|---:|---:|")
    for j, name in enumerate(meta.outputs):
        gj, pj = g[j], p[j]
        fin = np.isfinite(gj)
        print(f"| {name} | {100 * _r2(pj, gj):.1f} | {float(gj[fin].mean()):.3f} | "
              f"{100 * float(np.mean(gj[fin] >= 1.0 - 1e-6)):.1f} |")

    lomo = _affine_lomo(p, g, sc)
    print("\n| R² % | as predicted | + the best constant per map | + the best constant per frame | "
          "an affine per output, fitted on the other maps |\n|---|---:|---:|---:|---:|")
    for name in [*sorted(set(sc)), "all"]:
        m = np.ones(sc.shape, bool) if name == "all" else sc == name
        pm, gm = p[:, m], g[:, m]
        per_map = pm + np.nanmean(gm - pm)
        per_frame = pm.copy()
        for f in np.unique(fr[m]):
            c = fr[m] == f
            per_frame[:, c] += np.nanmean(gm[:, c] - pm[:, c])
        if name == "all":
            per_map = p.copy()
            for s in set(sc):
                c = sc == s
                per_map[:, c] += np.nanmean(g[:, c] - p[:, c])
        held = "-" if lomo is None else f"{100 * _r2(lomo[:, m], gm):.1f}"
        print(f"| {name} | {100 * _r2(pm, gm):.1f} | {100 * _r2(per_map, gm):.1f} | {100 * _r2(per_frame, gm):.1f} | "
              f"{held} |")

    est_, y_ = np.concatenate(est, 1), np.concatenate(metric, 1)
    fails = np.where(np.isfinite(y_), (y_ < meta.default_threshold) if hib else (y_ > meta.default_threshold), False)
    order = np.argsort(_SAVE)

    def threshold_rule(estimate: np.ndarray) -> Callable[[float], np.ndarray]:
        def by_threshold(t: float) -> np.ndarray:
            passes = estimate >= t if hib else estimate <= t
            best = np.full(estimate.shape[1], -1)
            for r in order:  # the coarsest passing rate wins
                best = np.where(passes[r], r, best)
            return best
        return by_threshold

    span = np.abs(meta.default_threshold) if meta.default_threshold else 1.0
    thresholds = (meta.default_threshold + np.linspace(-20, 20, 161) if hib
                  else np.geomspace(span / 16, span * 4, 161))
    rule = _sweep(threshold_rule(est_), fails, thresholds)
    # risk rule: the chance of failing per rate given the estimate, calibrated on the other maps
    bins = np.concatenate([[-np.inf], np.quantile(est_[np.isfinite(est_)], np.linspace(0, 1, 41))[1:-1], [np.inf]])
    chance = np.zeros_like(est_)
    for s in set(sc):
        c = sc == s
        others = ~c if (~c).any() else c
        tab = _risk_table(est_[:, others], fails[:, others], bins, hib)
        for r in range(6):
            chance[r, c] = tab[r][np.clip(np.digitize(est_[r, c], bins) - 1, 0, len(bins) - 2)]

    def by_risk(lam: float) -> np.ndarray:
        gain = _SAVE[:, None] - lam * chance
        best = np.argmax(gain, 0)
        return np.where(gain[best, np.arange(gain.shape[1])] > 0, best, -1)

    risk = _sweep(by_risk, fails, np.geomspace(0.05, 500, 161))
    # two thresholds, one for seen and one for unseen tiles, searched on the samples scored (optimistic)
    one = threshold_rule(est_)
    pairs: list[tuple[float, float]] = []
    for a in thresholds[::2]:
        on_seen = one(float(a))
        pairs += _sweep(lambda b, s=on_seen: np.where(u, one(b), s), fails, thresholds[::4])
    oracle = float(np.where(fails, 0.0, _SAVE[:, None]).max(0).mean())
    print(f"\nwork saved % at {' / '.join(f'{100 * v:g}' for v in _LEVELS)}% failing tiles (a tile fails over "
          f"{meta.default_threshold:g}; the oracle saves {100 * oracle:.1f}% failing none)\n")
    print("| rule | saved % |\n|---|---|")
    for name, pts in (("one threshold, swept (the SDK's)", rule), ("calibrated risk, leave one map out", risk),
                      ("two thresholds, seen / unseen tiles (searched on these samples)", pairs)):
        print(f"| {name} | {' / '.join(f'{100 * _saved_at(pts, v):.1f}' for v in _LEVELS)} |")

    # what accuracy the saving needs: the same rule on the truth plus noise of a known size
    own = float(np.mean([_r2(p[j], g[j]) for j in range(len(rows))]))
    t_all = np.concatenate(every, 1)
    spread = np.array([np.nanstd(t_all[r]) for r in range(6)])[:, None]
    rng = np.random.default_rng(args.noise_seed)
    unit = rng.standard_normal(t_all.shape)
    print(f"\nthe same rule on the truth plus Gaussian noise (transformed space, every rate) sized so that each "
          f"output's R² is the level named; the model's own per-output R² averages {100 * own:.1f}% (no margin)\n")
    print("| estimate | R² per output % | underestimated by > 0.2 / 0.3 (% of tiles) | saved % | "
          "share of the oracle's saving % |\n|---|---:|---|---|---|")
    worse = meta.worse_direction

    def row(name: str, r2: float, short: np.ndarray, pts: list[tuple[float, float]]) -> None:
        # short: truth minus estimate in the worse direction, the model's outputs only (no margin)
        sv = [_saved_at(pts, v) for v in _LEVELS]
        fin = np.isfinite(short)
        tails = " / ".join(f"{100 * float(np.mean(short[fin] > d)):.1f}" for d in (0.2, 0.3))
        print(f"| {name} | {100 * r2:.1f} | {tails} | {' / '.join(f'{100 * v:.1f}' for v in sv)} | "
              f"{' / '.join(f'{100 * v / oracle:.0f}' if oracle > 0 else 'nan' for v in sv)} |")

    row(f"the model ({args.model})", own, worse * (g - p), rule)
    curves = [(f"the model (R² {100 * own:.1f}% per output)", rule)]
    shared = np.broadcast_to(rng.standard_normal((1, t_all.shape[1])), t_all.shape)  # one draw per tile
    for level, noise, kind in ((own, unit, "each rate its own"), (own, shared, "one per tile, all rates"),
                               (0.90, unit, "each rate its own"), (0.95, unit, "each rate its own"),
                               (0.98, unit, "each rate its own")):
        # no safety margin: a constant in transformed space is one more threshold of the sweep
        noisy = t_all + noise * spread * np.sqrt(1.0 - level)
        syn = np.asarray(meta.transform.inverse(noisy))
        pts = _sweep(threshold_rule(syn), fails, thresholds)
        row(f"truth + noise ({kind})", level, worse * (t_all[rows] - noisy[rows]), pts)
        if kind.startswith("each"):
            curves.append((f"truth + noise, R² {100 * level:.1f}%", pts))
    if args.plot:
        _plot(curves, oracle, f"{meta.metric}, {where}", args.plot)
    return 0


def _plot(curves: list[tuple[str, list[tuple[float, float]]]], oracle: float, title: str, path: str) -> None:
    """Work saved against failing tiles for each estimate of table 4, the oracle's saving as a line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, (name, pts) in enumerate(curves):
        xy = sorted((100 * f, 100 * v) for f, v in pts if f <= 0.2)
        ax.plot([x for x, _ in xy], [y for _, y in xy], color=f"C{i}", lw=2.2 if i == 0 else 1.4,
                ls="-" if i == 0 else "--", label=name)
    ax.axhline(100 * oracle, color="black", lw=0.8, label=f"the oracle (fails none): {100 * oracle:.1f}%")
    for level in _LEVELS:
        ax.axvline(100 * level, color="grey", lw=0.5, ls=":")
    ax.set_xlim(0, 20)
    ax.set_xlabel("failing tiles (%)")
    ax.set_ylabel("work saved (%)")
    ax.set_title(f"The SDK's rule on the model's estimates and on the truth plus noise\n{title}", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    save_figure(fig, path)


if __name__ == "__main__":
    run_main(main)
