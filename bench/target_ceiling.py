"""How much of a metric's per-tile target any function of the frame's content can explain.

    python bench/target_ceiling.py models/lpips.onnx --data data/train --scene kaos,oa_dm3,oacmpdm4

The targets are computed on a fixed pixel grid. A metric built from strided features (LPIPS's
AlexNet: strides 4, 8 and 16) gives the same content a different value when the frame moves by a
few pixels against that grid; a pointwise metric (JNYang, PSNR) or one of stride-1 filters (FLIP)
does not. This script recomputes the targets of the model's metric on windows of each frame moved
by a few pixels (``--shifts``), compares the same tiles of the same content across those phases,
and splits each output's variance (transformed space, as R² scores it) into the part shared by
every phase (the content) and the part that changes with the phase alone. The content's share is
the most R² any predictor that sees the content but not the grid's phase can reach: a ceiling.

Printed per output and pooled over the outputs (as ``rtp evaluate``'s R² is): the ceiling, the
model's R² (raw output, no safety margin) against the unshifted target, and against the content
part (the mean over the phases) on the same tiles. Only tiles well inside every window count
(``--margin`` tiles from its edges), so the frame border's padding does not pass for phase.

``--mirror`` also recomputes the targets on the frame mirrored left-right and mirrors them back, and
prints how well they agree with the targets (R²) beside how well each shifted phase's do: how true
the labels of ``rtp train --mirror`` are for a metric whose filters are not symmetric (LPIPS's
AlexNet). A pointwise metric mirrors exactly.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _common import UsageError, add_model_args, count, run_main, scene_ids  # bench/ is on sys.path when run as a script

from rtp import metrics as M
from rtp import sdk
from rtp.capture import DatasetReader, TargetStore

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)

#: Default phases (rows, columns in pixels): whole and part strides of AlexNet's 4, 8 and 16.
DEFAULT_SHIFTS = "0,0 0,4 4,0 4,4 0,8 8,0 8,8 2,6 12,12 1,3"


def parse_shifts(text: str, tile: int) -> list[tuple[int, int]]:
    """``"dy,dx dy,dx ..."`` as pairs of pixel shifts, each in ``[0, tile)``, the first one ``0,0``."""
    out = []
    for part in text.split():
        try:
            dy, dx = (int(v) for v in part.split(","))
        except ValueError:
            raise UsageError(f"--shifts takes 'dy,dx' pairs separated by spaces, got {part!r}") from None
        if not (0 <= dy < tile and 0 <= dx < tile):
            raise UsageError(f"each shift must lie in [0, {tile}) pixels (one tile), got {part!r}")
        out.append((dy, dx))
    if len(out) < 2 or out[0] != (0, 0) or len(set(out)) != len(out):
        raise UsageError("--shifts needs at least two distinct phases, the first one 0,0")
    return out


def phase_targets(ref: np.ndarray, images: dict[str, np.ndarray], metric: str, shifts: list[tuple[int, int]],
                  tile: int, params: dict) -> np.ndarray:
    """Per phase, per rate of ``images`` and per tile of the original grid, the metric's target
    recomputed on the window of the frame moved by the phase's shift: ``(phases, rates, th - 2, tw - 2)``,
    the tiles of rows and columns 1 .. th - 2 (those every window holds whole)."""
    h, w = ref.shape[:2]
    th, tw = h // tile, w // tile
    out = np.empty((len(shifts), len(images), th - 2, tw - 2), np.float32)
    for p, (dy, dx) in enumerate(shifts):
        win = (slice(dy, dy + h - tile), slice(dx, dx + w - tile))
        maps = M.tile_targets(np.ascontiguousarray(ref[win]), {r: np.ascontiguousarray(img[win])
                                                               for r, img in images.items()},
                              [metric], 1, missing="nan", **params)[metric]
        maps = maps[[sdk.PREDICTED_RATES.index(r) for r in images]]
        # window pixel (y, x) is frame pixel (y + dy, x + dx): frame rows tile .. h - tile are window rows
        # tile - dy .. h - tile - dy, whole tiles of the original grid
        inner = maps[:, tile - dy:h - tile - dy, tile - dx:w - tile - dx]
        out[p] = inner.reshape(len(images), th - 2, tile, tw - 2, tile).max(axis=(2, 4))
    return out


def ceiling(t: np.ndarray) -> float:
    """``t``: ``(phases, tiles)`` transformed targets. The share of their variance the mean over the
    phases explains: 1 - (mean within-tile variance across phases) / (total variance)."""
    noise = t.var(axis=0, ddof=1).mean()
    return float(1.0 - noise / t.var())


def r2(p: np.ndarray, g: np.ndarray) -> float:
    d = g - g.mean()
    return float(1.0 - ((p - g) ** 2).sum() / (d * d).sum())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_args(ap, "an exported model (.onnx): its metric, transform, outputs and tile size", "; '' for all")
    ap.add_argument("--samples", type=count, default=0, help="at most this many samples, spread evenly (0: all)")
    ap.add_argument("--shifts", default=DEFAULT_SHIFTS, help=f"phases, 'dy,dx' pixels (default: {DEFAULT_SHIFTS!r})")
    ap.add_argument("--margin", type=count, default=4, help="tiles left out along each window's edges (default: 4)")
    ap.add_argument("--mirror", action="store_true",
                    help="also the targets of the frame mirrored left-right, mirrored back, against the targets")
    args = ap.parse_args(argv)
    pred = sdk.load(args.model, providers=["CPUExecutionProvider"])
    meta = pred.metadata
    if meta.metric == "psnr":
        raise UsageError("PSNR is computed per pixel and pooled by mean: every phase gives the same target "
              "(its ceiling is 100% by construction)")
    tile = meta.tile_size
    shifts = parse_shifts(args.shifts, tile)
    reader = DatasetReader(args.data)
    ids = scene_ids(reader, args.scene)
    if not ids:
        raise UsageError(f"{args.data} holds no sample of {args.scene}")
    if args.samples > 0 and len(ids) > args.samples:
        ids = [ids[i] for i in np.linspace(0, len(ids) - 1, args.samples).round().astype(int)]
    # the parameters the dataset's targets were computed with (a window's width must not change FLIP's ppd)
    settings = TargetStore(args.data).metrics.get(meta.metric, {}) if (Path(args.data) / "targets").is_dir() else {}
    params = {"ppd": float(settings.get("ppd", M.DEFAULT_PPD))}
    if "weber_l" in settings:
        params["weber_l"] = float(settings["weber_l"])
    m = args.margin
    phases, model, mirrored = [], [], []
    for i in tqdm(ids, desc=f"{meta.metric} at {len(shifts)} phases", unit="sample"):
        s = reader[i]
        h, w = s.size
        if h % tile or w % tile or min(h, w) // tile < 2 * m + 4:
            raise UsageError(f"{i}: {w}x{h} is not whole {tile}-pixel tiles with room for --margin {m}")
        ref = s.final("1x1")
        t = phase_targets(ref, {r: s.final(r) for r in meta.outputs}, meta.metric, shifts, tile, params)
        t = t[..., m:t.shape[-2] - m, m:t.shape[-1] - m]
        phases.append(np.asarray(meta.transform.forward(t)).reshape(len(shifts), len(meta.outputs), -1))
        if args.mirror:  # the mirrored frame's tiles are the frame's, in reverse column order
            mt = phase_targets(np.ascontiguousarray(ref[:, ::-1]), {r: np.ascontiguousarray(s.final(r)[:, ::-1])
                                                                   for r in meta.outputs},
                               meta.metric, [(0, 0)], tile, params)[0, ..., ::-1]
            mt = mt[..., m:mt.shape[-2] - m, m:mt.shape[-1] - m]
            mirrored.append(np.asarray(meta.transform.forward(mt)).reshape(len(meta.outputs), -1))
        raw = pred.predict_raw(s.inputs(meta.inputs))[:, 1 + m:h // tile - 1 - m, 1 + m:w // tile - 1 - m]
        model.append(raw.reshape(len(meta.outputs), -1))
    t = np.concatenate(phases, axis=-1)  # (phases, outputs, tiles)
    p = np.concatenate(model, axis=-1)  # (outputs, tiles)
    ok = np.isfinite(t).all(axis=0)  # (outputs, tiles)
    content = t.mean(axis=0)

    print(f"\n{meta.metric}, {args.model}: {len(ids)} samples of {args.data} ({args.scene}), {len(shifts)} phases "
          f"({args.shifts}), {ok.shape[1] // len(ids)} inner tiles a sample; R² % in transformed space\n")
    print("| output | ceiling (content's share of the variance) | model vs the unshifted target | "
          "model vs the content (mean over phases) | target's spread across phases (s.d.) |")
    print("|---|---:|---:|---:|---:|")
    for j, rate in enumerate(meta.outputs):
        k = ok[j]
        tj = t[:, j, k]
        print(f"| {rate} | {100 * ceiling(tj):.1f} | {100 * r2(p[j, k], tj[0]):.1f} | "
              f"{100 * r2(p[j, k], content[j, k]):.1f} | {float(np.sqrt(tj.var(axis=0, ddof=1).mean())):.3f} |")
    k = ok.reshape(-1)
    tp = t.reshape(len(shifts), -1)[:, k]
    print(f"| pooled | {100 * ceiling(tp):.1f} | {100 * r2(p.reshape(-1)[k], tp[0]):.1f} | "
          f"{100 * r2(p.reshape(-1)[k], content.reshape(-1)[k]):.1f} | "
          f"{float(np.sqrt(tp.var(axis=0, ddof=1).mean())):.3f} |")
    if mirrored:
        mt = np.concatenate(mirrored, axis=-1)  # (outputs, tiles)
        print("\nThe mirrored frame's targets, mirrored back, against the targets (R² %), and each shifted "
              "phase's (the mean over the phases, and the lowest):\n")
        print("| output | mirrored | shifted phases, mean | shifted phases, lowest |")
        print("|---|---:|---:|---:|")
        rows = [(rate, ok[j] & np.isfinite(mt[j]), mt[j], t[:, j]) for j, rate in enumerate(meta.outputs)]
        rows.append(("pooled", k & np.isfinite(mt.reshape(-1)), mt.reshape(-1), t.reshape(len(shifts), -1)))
        for rate, kk, mj, tj in rows:
            shifted = [r2(tj[q, kk], tj[0, kk]) for q in range(1, len(shifts))]
            print(f"| {rate} | {100 * r2(mj[kk], tj[0, kk]):.1f} | {100 * float(np.mean(shifted)):.1f} | "
                  f"{100 * min(shifted):.1f} |")
    return 0


if __name__ == "__main__":
    run_main(main)
