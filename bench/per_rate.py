"""Would a threshold per rate save more than one threshold for all six? An offline reading.

    python bench/per_rate.py models/jnyang.onnx --data data/train --scene kaos,oa_dm3,oacmpdm4

The runtime picks per tile the cheapest rate whose predicted error passes one threshold. A model
that errs differently per rate (too low on 4x4, say) might save more at the same failing share with
a factor per rate: rate r passes when its prediction is below ``threshold x factor[r]``. This script
predicts every sample of ``--data`` (the validation maps of data/train by default), then for each
map left out in turn fits the six factors on the other maps (coordinate ascent over a fixed set of
multipliers, maximising the work saved at ``--fit`` failing tiles, the global threshold swept), and
scores them on the map left out against one shared threshold. A tile fails when its true error at
the chosen rate is over the model's default threshold (for PSNR: under it). Prints the work saved at
1, 2 and 5% failing tiles per held-out map, the oracle's saving (every tile at its cheapest truly
passing rate) and the fitted factors. Static viewpoint pairs, not the closed loop of ``rtp play``.
For PSNR (higher is better) a factor f moves its rate's threshold by 20 log10(f) dB (``select_rates``)
and the sweep moves the shared one by 6 log2 of the factor.

``--sidecar OUT.yaml`` also fits the factors on every map given, scales all six by one number so
that the default threshold fails on as many tiles as with one threshold (the factors then change
what a failing share saves, not where the default setting sits), and writes them as a metadata sidecar
that ``rtp-export --retune MODEL --metadata OUT.yaml -o MODEL2.onnx`` bakes into a model: the runtime
(``shading_rates``, ``rtp play``, ``rtp evaluate``) then gives each rate its factor of the threshold.
``--held-out PREFIX`` writes each held-out row's factors (fitted on the other maps, not scaled) as
``PREFIX-MAP.yaml``: a model retuned with them can be played in the closed loop on MAP without having
been fitted on it (docs/results.md "JNFLIP and `jnyang-reuse` in the closed loop").

Two more columns ask whether the estimates' order across rates matters. A rate's blocks contain those
of every rate no wider and no taller (2x2's contain 1x2's and 2x1's; 4x4's every other rate's), so an
error estimate should not fall from a rate to a coarser one: "monotone estimates" replaces each
estimate by the largest over the rates its blocks contain (``evaluate.monotone_over_rates``; one
threshold, swept) and "oracle, monotone" is the oracle on the truth made so. The true error does
fall in places (the coarser rate's one sample lands on a better pixel); the oracle keeps that luck,
a predictor of monotone estimates cannot, so the second oracle is a ceiling nearer what such a
predictor can reach. Also printed: the share of (tile, rate, contained rate) triples where the
estimates and the truth fall.
"""

from __future__ import annotations

import argparse
import shlex

import numpy as np
from _common import (  # bench/ is on sys.path when run as a script
    UsageError,
    add_model_args,
    check_targets,
    run_main,
    share,
    write_factors_sidecar,
)

from rtp import sdk
from rtp.capture import DatasetReader, TargetStore
from rtp.evaluate import CONTAINED_RATES, monotone_over_rates

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

MULTIPLIERS = (0.5, 0.7, 0.85, 1.0, 1.2, 1.4, 2.0)
#: The global threshold's sweep, as a factor of the model's default (log-spaced; PSNR: an offset in dB).
SWEEP = np.exp(np.linspace(np.log(0.05), np.log(4.0), 80))
SHARES = (0.01, 0.02, 0.05)
_SAVED = {sdk.RATE_CODES[r]: 1.0 - 1.0 / (int(r[0]) * int(r[2])) for r in sdk.PREDICTED_RATES}


def _outcome(pred: np.ndarray, truth: np.ndarray, factors: np.ndarray, g: float, thr: float,
             hib: bool) -> tuple[float, float]:
    """(failing share, work saved) of one global setting ``g`` with per-rate ``factors`` (the SDK's
    ``select_rates(factors=)``, as a model with ``rate_factors`` in its metadata decides)."""
    setting = thr + 6.0 * np.log2(g) if hib else thr * g  # PSNR: the sweep is an offset in dB
    codes = sdk.select_rates(pred, setting, higher_is_better=hib, factors=factors)
    saved = np.zeros(codes.shape)
    fail = np.zeros(codes.shape, bool)
    for i, r in enumerate(sdk.PREDICTED_RATES):
        m = codes == sdk.RATE_CODES[r]
        saved[m] = _SAVED[sdk.RATE_CODES[r]]
        t = truth[:, i][m]
        fail[m] = (t < thr) if hib else (t > thr)
    return float(fail.mean()), float(saved.mean())


def _saved_at(pred: np.ndarray, truth: np.ndarray, factors: np.ndarray, thr: float, hib: bool,
              share: float) -> float:
    pts = sorted(_outcome(pred, truth, factors, g, thr, hib) for g in SWEEP)
    fails, saved = np.array([p[0] for p in pts]), np.maximum.accumulate(np.array([p[1] for p in pts]))
    return float(np.interp(share, fails, saved))


def _fit(pred: np.ndarray, truth: np.ndarray, thr: float, hib: bool, share: float) -> np.ndarray:
    f = np.ones(len(sdk.PREDICTED_RATES))
    for _ in range(2):
        for i in range(len(f)):
            best, best_v = f[i], -1.0
            for m in MULTIPLIERS:
                trial = f.copy()
                trial[i] = f[i] * m
                v = _saved_at(pred, truth, trial, thr, hib, share)
                if v > best_v + 1e-9:
                    best, best_v = trial[i], v
            f[i] = best
    return f


def _keep_default(pred: np.ndarray, truth: np.ndarray, f: np.ndarray, thr: float, hib: bool) -> np.ndarray:
    """``f`` times the common scale that makes the model's default threshold fail on the share of tiles it
    fails with one threshold (the nearest on a grid of 0.7-1.4x; the smallest change on a tie): the factors
    then move the curve of saving against failing tiles and leave the default setting where it was."""
    want = _outcome(pred, truth, np.ones(len(f)), 1.0, thr, hib)[0]
    lo, hi = 1.0 / (sdk.MAX_RATE_FACTOR * f.min()), sdk.MAX_RATE_FACTOR / f.max()
    grid = [c for c in np.exp(np.linspace(np.log(0.7), np.log(1.4), 141)) if lo <= c <= hi]
    best = min(grid, key=lambda c: (abs(_outcome(pred, truth, f * c, 1.0, thr, hib)[0] - want), abs(np.log(c))))
    return f * best


def _oracle(truth: np.ndarray, thr: float, hib: bool) -> float:
    best = np.zeros(truth[:, 0].shape)
    for i, r in enumerate(sdk.PREDICTED_RATES):
        ok = (truth[:, i] >= thr) if hib else (truth[:, i] <= thr)
        best = np.where(ok, np.maximum(best, _SAVED[sdk.RATE_CODES[r]]), best)
    return float(best.mean())


def falls(values: np.ndarray, hib: bool) -> float:
    """The share of (tile, rate, contained rate) triples where the coarser rate's value is the better."""
    n = sum(len(b) for b in CONTAINED_RATES) * values[:, 0].size
    better = sum(int(((values[:, i] > values[:, j]) if hib else (values[:, i] < values[:, j])).sum())
                 for i, below in enumerate(CONTAINED_RATES) for j in below)
    return better / n


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_args(ap, "an exported model (.onnx) or a shipped model's name", ", at least two")
    ap.add_argument("--fit", type=share, default=0.05, help="failing share the factors are fitted at (default 0.05)")
    ap.add_argument("--sidecar", metavar="OUT.yaml", help="fit the factors on every map given and write them as a "
                    "metadata sidecar for `rtp-export --retune` (rate_factors)")
    ap.add_argument("--held-out", metavar="PREFIX", help="also write each held-out map's factors, fitted on the "
                    "other maps, as the sidecar PREFIX-MAP.yaml")
    args = ap.parse_args(argv)
    pred = sdk.load(args.model, providers=["CPUExecutionProvider"])
    meta = pred.metadata
    thr, hib = float(meta.default_threshold), bool(meta.higher_is_better)
    scenes = [s.strip() for s in args.scene.split(",") if s.strip()]
    if len(set(scenes)) != len(scenes):  # (a map twice: no other map to fit on when it is held out)
        raise UsageError(f"--scene: expected distinct maps, got {args.scene!r}")
    if len(scenes) < 2:
        raise UsageError("--scene needs at least two maps (one is held out while the others fit)")
    reader, store = DatasetReader(args.data), TargetStore(args.data)
    by_map: dict[str, tuple[list[np.ndarray], list[np.ndarray]]] = {s: ([], []) for s in scenes}
    ids = [i for i in reader.ids if reader[i].meta.get("scene") in by_map]
    # (a map without samples, or samples without targets: refused before the predictions, which take minutes)
    missing = [s for s in scenes if not any(reader[i].meta.get("scene") == s for i in ids)]
    if missing:
        raise UsageError(f"{args.data} holds no sample of {', '.join(missing)}")
    check_targets(store, ids, meta.metric, meta.tile_size, args.model)
    for i in tqdm(ids, desc="predicting", unit="sample"):
        s = reader[i]
        p, t = by_map[s.meta["scene"]]
        p.append(pred.predict(s.inputs(meta.inputs)))
        t.append(store.load(i, meta.metric, meta.tile_size))
    data = {s: (np.stack(p), np.stack(t)) for s, (p, t) in by_map.items()}
    print(f"\n{meta.metric}, {args.model}: work saved % at {' / '.join(f'{100 * x:g}' for x in SHARES)}% failing "
          f"tiles (threshold {thr:g}); per-rate factors fitted at {100 * args.fit:g}% on the other maps\n")
    print("| held-out map | one threshold | a factor per rate | monotone estimates | oracle | oracle, monotone | "
          "factors (" + ", ".join(sdk.PREDICTED_RATES) + ") |\n|---|---|---|---|---:|---:|---|")
    for held in tqdm(scenes, desc="fitting", unit="map", leave=False):
        fit_p = np.concatenate([data[s][0] for s in scenes if s != held])
        fit_t = np.concatenate([data[s][1] for s in scenes if s != held])
        f = _fit(fit_p, fit_t, thr, hib, args.fit)
        p, t = data[held]
        one = [100 * _saved_at(p, t, np.ones(6), thr, hib, x) for x in SHARES]
        per = [100 * _saved_at(p, t, f, thr, hib, x) for x in SHARES]
        mono = [100 * _saved_at(monotone_over_rates(p, hib), t, np.ones(6), thr, hib, x) for x in SHARES]
        print(f"| {held} | {' / '.join(f'{v:.1f}' for v in one)} | {' / '.join(f'{v:.1f}' for v in per)} | "
              f"{' / '.join(f'{v:.1f}' for v in mono)} | {100 * _oracle(t, thr, hib):.1f} | "
              f"{100 * _oracle(monotone_over_rates(t, hib), thr, hib):.1f} | {', '.join(f'{v:.2f}' for v in f)} |")
        if args.held_out:
            write_factors_sidecar(f"{args.held_out}-{held}.yaml", f, f"python bench/per_rate.py {args.model} --data "
                                  f"{args.data} --scene {','.join(scenes)} --fit {args.fit:g} --held-out "
                                  f"{args.held_out} (fitted without {held})")
    if args.held_out:
        print(f"\nwrote {', '.join(f'{args.held_out}-{s}.yaml' for s in scenes)}: each map's factors fitted without it")
    p_all = np.concatenate([data[s][0] for s in scenes])
    t_all = np.concatenate([data[s][1] for s in scenes])
    mono_all = monotone_over_rates(t_all, hib)
    print(f"\nA coarser rate's value the better (share of tile, rate, contained-rate triples): estimates "
          f"{100 * falls(p_all, hib):.1f}%, truth {100 * falls(t_all, hib):.1f}%; over all maps the oracle saves "
          f"{100 * _oracle(t_all, thr, hib):.1f}%, on the monotone truth {100 * _oracle(mono_all, thr, hib):.1f}%")
    if args.sidecar:
        fitted = _fit(p_all, t_all, thr, hib, args.fit)
        f = _keep_default(p_all, t_all, fitted, thr, hib)
        one = [100 * _saved_at(p_all, t_all, np.ones(6), thr, hib, x) for x in SHARES]
        per = [100 * _saved_at(p_all, t_all, f, thr, hib, x) for x in SHARES]
        d1, df = (_outcome(p_all, t_all, v, 1.0, thr, hib) for v in (np.ones(6), f))
        print(f"\nFitted on {', '.join(scenes)} together (in sample): {' / '.join(f'{v:.1f}' for v in one)} with one "
              f"threshold, {' / '.join(f'{v:.1f}' for v in per)} with the factors ({', '.join(f'{v:.2f}' for v in fitted)}"
              f" as fitted, x {f[0] / fitted[0]:.3f} so that the default threshold fails as often: "
              f"{', '.join(f'{v:.4g}' for v in f)}). At the default threshold {thr:g}: {100 * d1[0]:.1f}% failing, "
              f"{100 * d1[1]:.1f}% saved with one threshold; {100 * df[0]:.1f}% failing, {100 * df[1]:.1f}% saved "
              "with the factors")
        write_factors_sidecar(args.sidecar, f, f"python bench/per_rate.py {args.model} --data {args.data} --scene "
                       f"{','.join(scenes)} --fit {args.fit:g} --sidecar {args.sidecar}")
        print(f"wrote {args.sidecar}: rtp-export --retune {shlex.quote(str(args.model))} --metadata "
              f"{shlex.quote(str(args.sidecar))} -o OUT.onnx")
    return 0


if __name__ == "__main__":
    run_main(main)
