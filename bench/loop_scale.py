"""Scale a model's thresholds per rate so that, in the closed loop, its default setting fails as often as one threshold.

    rtp play MAP --methods flip,data/study/flip-one.onnx,oracle --fail-metric flip --frames 150 --composite \\
        --flip-every 0 --no-animation --out data/playrate-flip-MAP              # each validation map
    python bench/loop_scale.py data/playrate-flip-{kaos,oa_dm3,oacmpdm4}/play.json --method flip \\
        --one data/study/flip-one.onnx --sidecar data/flip-rate-factors-loop.yaml

`bench/per_rate.py --sidecar` fits a factor per rate on static viewpoint pairs and scales all six by one
number so that the default threshold fails on as many of those pairs' tiles as with one threshold. In
the loop of `rtp play` a method's history is its own displayed frame, which is coarser where it chose
coarser rates, and the factors can move the default further there. This script reads the runs of
`rtp play` that played the model with its factors (``--method``, swept) and with one threshold
(``--one``, the same network: ``rtp-export --retune MODEL --metadata`` a sidecar of
``rate_factors: null``), takes the mean over every path of the failing share of ``--one`` at its
default, and finds where the swept model's mean failing share crosses it (linear between the sweep's
points, in the logarithm of the threshold; PSNR in dB). That setting over the default is the scale:
the factors times it (PSNR: an offset of d dB is a factor 10^(-d/20)) put the default setting there.
Prints per path the default of both and the model at the crossing (failing share, work saved), and
with ``--sidecar`` writes the scaled factors for ``rtp-export --retune``.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
from pathlib import Path
from typing import Any

import numpy as np
from _common import PLAY_JSON, UsageError, run_main, write_factors_sidecar  # bench/ is on sys.path when run as a script

from rtp import sdk
from rtp.evaluate import METHOD_KINDS


def _sweep(runs: list[dict[str, Any]], method: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """(thresholds, failing share, work saved) per path (rows) and sweep point (columns) of ``method``
    in every run, and the run's default column as a boolean mask."""
    values: list[float] | None = None
    fail, saved, default = [], [], None
    for rep in runs:
        for path in rep["unseen"]:
            rows = sorted((r for r in rep["rows"] if r["method"] == method and r["path"] == path), key=lambda r: r["value"])
            if not rows:
                raise ValueError(f"{rep['settings']['scene']} ({path}) did not play {method!r}; it played "
                                 f"{', '.join(rep['settings']['methods'])}")
            v = [r["value"] for r in rows]
            if values is None:
                values, default = v, np.array([r["default"] for r in rows])
            elif not np.allclose(v, values):
                raise ValueError(f"{method!r} was swept over other thresholds in {rep['settings']['scene']} "
                                 f"({path}): {v} against {values}")
            fail.append([r["fail_share"] for r in rows])
            saved.append([r["work_saved"] for r in rows])
    assert values is not None and default is not None
    return np.array(values), np.array(fail), np.array(saved), default


def _crossing(values: np.ndarray, fails: np.ndarray, want: float, hib: bool) -> float:
    """The threshold where the failing share (mean over paths, one per sweep point) crosses ``want``:
    linear between the two points around it, in log threshold (PSNR: dB)."""
    x = values if hib else np.log(values)
    order = np.argsort(fails, kind="stable")
    f, xs = fails[order], x[order]
    if not f[0] <= want <= f[-1]:
        raise ValueError(f"the sweep fails on {100 * f[0]:.2f}-{100 * f[-1]:.2f}% of the tiles, never "
                         f"{100 * want:.2f}%: play a wider sweep")
    t = float(np.interp(want, f, xs))
    return t if hib else math.exp(t)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=PLAY_JSON, help="play.json files of `rtp play` (the validation maps)")
    ap.add_argument("--method", required=True, help="the model with its factors, as the runs name it")
    ap.add_argument("--one", required=True, help="the same model with one threshold (`rate_factors: null`), as the runs "
                    "name it: another model file than --method, not a baseline")
    ap.add_argument("--sidecar", metavar="OUT.yaml", help="write the scaled factors for `rtp-export --retune`")
    args = ap.parse_args(argv)
    runs = [json.loads(Path(p).read_text(encoding="utf-8")) for p in args.runs]
    models = {k: v for rep in runs for k, v in rep["settings"].get("models", {}).items()}
    for flag, name in (("--method", args.method), ("--one", args.one)):  # (a baseline such as yang2019: no model)
        if name not in models:
            what = (f"{name!r} is a baseline, not a model with thresholds" if name in METHOD_KINDS
                    else f"the runs hold no model {name!r}")
            raise UsageError(f"{flag}: {what}; the runs hold the models {', '.join(models) or 'none'}")
    if args.one == args.method or Path(models[args.one]).resolve() == Path(models[args.method]).resolve():
        raise UsageError(f"--one: expected the model with one threshold, another file than --method, got {args.one!r} "
                         "for both: its scale would be 1 by construction")
    meta = sdk.load(models[args.method], providers=["CPUExecutionProvider"]).metadata
    one = sdk.load(models[args.one], providers=["CPUExecutionProvider"]).metadata
    if one.metric != meta.metric:
        raise UsageError(f"--one: expected the same model with one threshold; {args.one} predicts {one.metric}, "
                         f"{args.method} {meta.metric}")
    if one.rate_factors is not None and len(set(one.rate_factors)) > 1:
        raise UsageError(f"--one: expected the model with one threshold (`rate_factors: null`), got {args.one} with "
                         f"factors per rate {', '.join(f'{v:g}' for v in one.rate_factors)}: `rtp-export --retune "
                         "MODEL --metadata` a sidecar of `rate_factors: null` makes it")
    hib, thr = bool(meta.higher_is_better), float(meta.default_threshold)
    factors = np.array(meta.rate_factors if meta.rate_factors is not None else [1.0] * 6, np.float64)
    try:
        values, fail, saved, default = _sweep(runs, args.method)
        _, ofail, osaved, odefault = _sweep(runs, args.one)
        want = float(ofail[:, odefault].mean())
        cross = _crossing(values, fail.mean(axis=0), want, hib)
    except ValueError as err:
        raise UsageError(str(err)) from None
    scale = 10.0 ** (-(cross - thr) / 20.0) if hib else cross / thr
    scaled = factors * scale
    x = values if hib else np.log(values)
    c = cross if hib else math.log(cross)
    paths = [(rep["settings"]["scene"], p) for rep in runs for p in rep["unseen"]]
    print(f"{meta.metric}, {args.method} (factors {', '.join(f'{v:.4g}' for v in factors)}) against {args.one}; "
          f"default {thr:g}. Failing share / work saved %:\n")
    print(f"| map | path | one threshold, default | factors, default | factors at {cross:.4g} |\n|---|---|---|---|---|")
    for i, (scene, path) in enumerate(paths):
        at = (np.interp(c, x, fail[i]), np.interp(c, x, saved[i]))
        print(f"| {scene} | {path} | {100 * ofail[i, odefault][0]:.1f} / {100 * osaved[i, odefault][0]:.1f} | "
              f"{100 * fail[i, default][0]:.1f} / {100 * saved[i, default][0]:.1f} | "
              f"{100 * at[0]:.1f} / {100 * at[1]:.1f} |")
    print(f"| mean | | {100 * want:.1f} / {100 * osaved[:, odefault].mean():.1f} | "
          f"{100 * fail[:, default].mean():.1f} / {100 * saved[:, default].mean():.1f} | "
          f"{100 * np.interp(c, x, fail.mean(axis=0)):.1f} / {100 * np.interp(c, x, saved.mean(axis=0)):.1f} |")
    print(f"\nThe default setting fails as often as one threshold at {cross:.4g}: the factors x {scale:.4f} = "
          f"{', '.join(f'{v:.4g}' for v in scaled)}")
    if args.sidecar:
        if scaled.min() < 1.0 / sdk.MAX_RATE_FACTOR or scaled.max() > sdk.MAX_RATE_FACTOR:
            raise UsageError(f"a scaled factor leaves [1/{sdk.MAX_RATE_FACTOR:g}, {sdk.MAX_RATE_FACTOR:g}]")
        write_factors_sidecar(args.sidecar, scaled, "python bench/loop_scale.py " + " ".join(
            [*map(str, args.runs), "--method", args.method, "--one", args.one, "--sidecar", args.sidecar]))
        print(f"wrote {args.sidecar}: rtp-export --retune {shlex.quote(str(models[args.method]))} --metadata "
              f"{shlex.quote(str(args.sidecar))} -o OUT.onnx")
    return 0


if __name__ == "__main__":
    run_main(main)
