"""``rtp`` subcommands. Exit codes: 0 success, 1 the job failed, 2 bad usage or bad inputs."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence

__all__ = ["build_parser", "main"]


def _cmd_info(args: argparse.Namespace) -> int:
    from rtp import sdk

    pred = sdk.load(args.model, metadata=args.metadata)
    m = pred.metadata
    if args.json:
        print(json.dumps({"path": str(pred.path), "provider": pred.provider, "metadata": m.to_dict()}, indent=2))
        return 0
    t = m.transform
    params = ", ".join(f"{k}={v:g}" for k, v in t.to_dict().items() if k != "type")
    rows = [
        ("model", str(pred.path)),
        ("provider", f"{pred.provider} (of {', '.join(pred.providers)})"),
        ("input size", "any (padded to the tile size)" if pred.static_size is None else "fixed %dx%d" % pred.static_size[::-1]),
        ("metric", f"{m.metric} ({'higher' if m.higher_is_better else 'lower'} is better)"),
        ("transform", f"{t.type} ({params})"),
        ("safety margin", f"{m.safety:g} (transformed units)"),
        ("tile size", f"{m.tile_size}x{m.tile_size}"),
        ("inputs", ", ".join(m.inputs)),
        ("network outputs", ", ".join(m.outputs)),
        ("predicted rates", ", ".join(pred.rates)),
        ("extrapolation k", f"{m.extrapolation_k:g}"),
        ("default threshold", f"{m.default_threshold:g}"),
        ("saturation", f"{m.saturation:.4g} (the worst value the model can express)"),
        ("weber l", "-" if m.weber_l is None else f"{m.weber_l:g}"),
        ("schema version", str(m.schema_version)),
    ]
    if m.description:
        rows.insert(1, ("description", m.description))
    for key, value in _flatten(m.provenance, "provenance"):
        rows.append((key, value))
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    return 0


def _flatten(d: object, prefix: str) -> list[tuple[str, str]]:
    from collections.abc import Mapping

    if isinstance(d, Mapping):
        out: list[tuple[str, str]] = []
        for k, v in d.items():
            out += _flatten(v, f"{prefix}.{k}")
        return out
    if isinstance(d, (list, tuple)):
        if any(isinstance(x, (Mapping, list, tuple)) for x in d):
            return [(prefix, f"{len(d)} records (rtp info --json shows them)")]
        return [(prefix, ", ".join(str(x) for x in d))]
    return [(prefix, str(d))]


def _csv(text: str) -> tuple[str, ...]:
    return tuple(t.strip() for t in text.split(",") if t.strip())


def _cmd_targets(args: argparse.Namespace) -> int:
    from rtp.capture import compute_targets

    ppd: float | str | None = None
    if args.ppd is not None:
        ppd = args.ppd if args.ppd == "width" else float(args.ppd)
    bar = _Bar(total=0, desc="targets", unit="sample")
    try:
        n = compute_targets(args.data, _csv(args.metrics), ppd=ppd, weber_l=args.weber_l, workers=args.workers,
                            progress=lambda done, total: (setattr(bar, "total", total), bar.update_to(done)))
    finally:
        bar.close()
    print(f"{args.data}: targets computed for {n} samples ({', '.join(_csv(args.metrics))})")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from ._demo import run_demo

    r = run_demo(args.out, model=args.model, threshold=args.threshold, scene=args.scene, size=args.size,
                 frames=args.frames, cache_dir=args.cache, seed=args.seed)
    shares = ", ".join(f"{k} {100 * v:.0f}%" for k, v in r.rate_share.items() if v > 0)
    print(f"model      {r.model} ({r.metric}), threshold {r.threshold:g}")
    print(f"rates      {shares} of {r.tiles} tiles")
    print(f"work saved {100 * r.work_saved:.1f}% of the shading (pixel-weighted)")
    print(f"over       {100 * r.over_threshold:.1f}% of the tiles have a true {r.metric} at or beyond the threshold at "
          f"their chosen rate")
    print(f"FLIP       mean {r.composite_flip_mean:.4f} of the VRS composite against full-rate shading")
    print(f"predict    {r.predict_ms:.1f} ms (onnxruntime, {args.size[0]}x{args.size[1]})")
    print(f"wrote      {', '.join(r.files)} in {r.out}")
    return 0


def _cmd_preview(args: argparse.Namespace) -> int:
    from rtp.capture import contact_sheet, open_dataset, write_png

    ds = open_dataset(args.data)
    sample_id = args.sample or ds.ids[0]
    write_png(args.out, contact_sheet(ds[sample_id], scale=args.scale))
    print(f"{args.out}: sample {sample_id} of {args.data}")
    return 0


def _cmd_train(args: argparse.Namespace) -> int:
    from rtp.train import TrainConfig, train

    val_scenes = _csv(args.val_scenes)
    if args.val_split:
        from rtp.capture.scenes import map_names

        val_scenes = tuple(map_names(args.val_split, args.scenes))
    cfg = TrainConfig(
        data=args.data, metric=args.metric, out=args.out, tile=args.tile, outputs=_csv(args.outputs),
        inputs=_csv(args.inputs), transform=args.transform, logistic_k=args.k, head=args.head, steps=args.steps,
        batch=args.batch, crop=args.crop, lr=args.lr, val_scenes=val_scenes, seed=args.seed,
        safety_quantile=args.safety_quantile, default_threshold=args.threshold, max_samples=args.max_samples,
    )
    bar = _Bar(total=cfg.steps, desc=f"train {cfg.metric}", unit="step")
    try:
        result = train(cfg, progress=lambda step, total, loss: bar.update_to(step, loss=f"{loss:.4f}"))
    finally:
        bar.close()
    if result.dead_outputs:  # the job ran and failed (exit 1), so `make train` stops before exporting
        print(f"rtp train: error: dead output(s) {', '.join(result.dead_outputs)} (see the warning above); "
              f"{result.checkpoint} is kept, not fit to export: train again with --head linear or another --seed",
              file=sys.stderr)
        return 1
    v = result.val["transformed"]
    print(f"{result.checkpoint}: {result.steps} steps; validation R2 {v['r2']:.3f}, MAE {v['mae']:.4f}; "
          f"safety {result.safety:.4f} (underestimated tiles with it: {100 * result.under_share:.1f}%)")
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from pathlib import Path

    from rtp.sdk import RtpError
    from rtp.evaluate import evaluate

    if args.plots and not args.out:
        raise RtpError("--plots writes into --out; give an output folder")
    scenes = tuple(s for item in (args.scenes or []) for s in _csv(item)) or None
    reports = []
    for model in args.model:
        bar = _Bar(total=0, desc=f"evaluate {Path(model).stem}", unit="sample")
        try:
            rep = evaluate(
                model, args.data, scenes=scenes, metadata=args.metadata, threshold=args.threshold,
                unseen_fraction=args.unseen_fraction, baselines=not args.no_baselines, max_samples=args.max_samples,
                plots_dir=args.out if args.plots else None, plot_sample=args.plot_sample,
                progress=lambda done, total: (setattr(bar, "total", total), bar.update_to(done)),
            )
        finally:
            bar.close()
        reports.append(rep)
        print(rep.table() + "\n")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "evaluation.md").write_text("\n".join(r.to_markdown() for r in reports), encoding="utf-8")
        (out / "evaluation.json").write_text(json.dumps([r.to_dict() for r in reports], indent=1, allow_nan=False),
                                             encoding="utf-8")
        extra = [p for r in reports for p in r.plots]
        print(f"wrote {out / 'evaluation.md'}, {out / 'evaluation.json'}" + (f" and {len(extra)} plots" if extra else ""))
    return 0


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1280x720, got {text!r}") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"size must be at least 16x16, got {text!r}")
    return w, h


def _default_cache() -> str:
    from rtp.capture.scenes import default_cache_dir

    return default_cache_dir()


def _cmd_scenes(args: argparse.Namespace) -> int:
    from rtp.capture import scenes

    return int(scenes.main(args.rest))


def _cmd_capture(args: argparse.Namespace) -> int:
    from rtp.capture import capture

    if args.scene:
        names = list(args.scene)
    else:
        from rtp.capture.scenes import map_names

        names = map_names(args.split, args.scenes)
    bar = _Bar(total=len(names) * len(_csv(args.profiles)) * args.per_scene, desc="capture", unit="sample")
    try:
        report = capture(
            names, args.out, per_scene=args.per_scene, size=args.size, profiles=_csv(args.profiles), seed=args.seed,
            workers=args.workers, cache_dir=args.cache or _default_cache(), split=None if args.scene else args.split,
            splits=args.scenes, progress=lambda done, total: bar.update_to(done),
        )
    finally:
        bar.close()
    if report.failed:
        print(f"rtp capture: no valid viewpoints, skipped: {', '.join(report.failed)}", file=sys.stderr)
    unseen = ", ".join(f"{p} {100 * v:.1f}%" for p, v in report.unseen_mean().items())
    print(f"{args.out}: {report.written} samples written"
          + (f" ({report.recaptured} of them replace samples from other cameras)" if report.recaptured else "")
          + f", {report.skipped} already there"
          + (f"; unseen pixels of the new samples: {unseen}" if unseen else ""))
    return 0


class _Bar:
    """A tqdm bar when tqdm is installed, else log lines every 10%."""

    def __init__(self, total: int, desc: str, unit: str) -> None:
        self.total, self.desc, self.n = total, desc, 0
        try:
            from tqdm import tqdm

            self._bar: object | None = tqdm(total=total, desc=desc, unit=unit, dynamic_ncols=True)
        except ImportError:
            self._bar = None

    def update_to(self, n: int, **postfix: str) -> None:
        if self._bar is not None:
            if self._bar.total != self.total:  # type: ignore[attr-defined]
                self._bar.total = self.total  # type: ignore[attr-defined]
            self._bar.update(n - self._bar.n)  # type: ignore[attr-defined]
            if postfix:
                self._bar.set_postfix(postfix, refresh=False)  # type: ignore[attr-defined]
        elif self.total and (n * 10 // self.total) != (self.n * 10 // self.total):
            logging.getLogger("rtp").warning("%s: %d/%d %s", self.desc, n, self.total, postfix)
        self.n = n

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()  # type: ignore[attr-defined]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="rtp", description="rtp: learned perceptual error prediction for variable-rate shading.")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress and show tracebacks")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)
    info = sub.add_parser("info", help="show a model's metadata, inputs, outputs and provider")
    info.add_argument("model", help="an .onnx path or the name of a shipped model")
    info.add_argument("--metadata", help="YAML sidecar for a model that carries no metadata")
    info.add_argument("--json", action="store_true", help="print JSON instead of a table")
    info.set_defaults(func=_cmd_info)

    sc = sub.add_parser("scenes", help="the real game levels: `rtp scenes fetch [--cache-dir DIR] [--maps a,b]`",
                        add_help=False)
    sc.add_argument("action", choices=["fetch"])
    sc.add_argument("rest", nargs=argparse.REMAINDER)
    sc.set_defaults(func=_cmd_scenes)

    cap = sub.add_parser("capture", help="render a dataset from scenes (resumable)")
    cap.add_argument("--scenes", default=None, help="scenes.yaml with the train/validation/test splits "
                     "(default: the copy shipped with rtp)")
    cap.add_argument("--split", default="train", choices=["train", "validation", "test"])
    cap.add_argument("--scene", action="append", help="capture this scene instead of a split (repeatable); "
                     "procedural:<seed> needs no download")
    cap.add_argument("--per-scene", type=int, required=True, help="viewpoint pairs per scene and motion profile")
    cap.add_argument("--size", type=_size, default=(1280, 720), help="WIDTHxHEIGHT (default 1280x720)")
    cap.add_argument("--out", required=True, help="dataset folder (created, or resumed)")
    cap.add_argument("--profiles", default="slow,fast", help="motion profiles (default slow,fast)")
    cap.add_argument("--workers", type=int, default=1, help="parallel render processes")
    cap.add_argument("--cache", default=None, help="scene cache of `rtp scenes fetch` "
                     "(default $RTP_SCENE_CACHE or ~/.cache/rtp/scenes)")
    cap.add_argument("--seed", type=int, default=0)
    cap.set_defaults(func=_cmd_capture)

    dm = sub.add_parser("demo", help="render a scene, pick VRS rates with a shipped model, show the result")
    dm.add_argument("--model", default="jnyang", help="a shipped model name or an .onnx path (default jnyang)")
    dm.add_argument("--threshold", type=float, default=None, help="default: the model's own")
    dm.add_argument("--scene", default="procedural:0", help="procedural:<seed> (default) or a fetched map name")
    dm.add_argument("--size", type=_size, default=(1280, 720))
    dm.add_argument("--frames", type=int, default=3, help="frames of the camera move (the last one is shown)")
    dm.add_argument("--cache", default=None, help="scene cache for a fetched map")
    dm.add_argument("--seed", type=int, default=0, help="which viewpoint of the scene")
    dm.add_argument("--out", default="rtp-demo", help="output folder (default ./rtp-demo)")
    dm.set_defaults(func=_cmd_demo)

    pv = sub.add_parser("preview", help="draw one sample of a dataset: final images at every rate, G-buffers, reprojection")
    pv.add_argument("data", help="dataset folder (rtp's, or the paper's released layout)")
    pv.add_argument("--sample", default=None, help="sample id (default: the first)")
    pv.add_argument("--out", required=True, help="PNG to write")
    pv.add_argument("--scale", type=int, default=1, help="subsample the panels by this factor")
    pv.set_defaults(func=_cmd_preview)

    tg = sub.add_parser("targets", help="compute per-tile metric targets of a dataset (cached, resumable)")
    tg.add_argument("data", help="dataset folder written by `rtp capture`")
    tg.add_argument("--metrics", default="flip,psnr,lpips,jnflip,jnyang", help="comma-separated metric names")
    tg.add_argument("--ppd", default=None, help="FLIP pixels per degree: a number, or 'width' for the paper's "
                    "width-based value (default 67.02, FLIP's own)")
    tg.add_argument("--weber-l", type=float, default=None, help="environment luminance l of JNFLIP/JNYang (default 0.02)")
    tg.add_argument("--workers", type=int, default=1, help="parallel processes")
    tg.set_defaults(func=_cmd_targets)

    tr = sub.add_parser("train", help="train a metric-prediction model on a captured dataset")
    tr.add_argument("--data", required=True, help="dataset folder (with targets from `rtp targets`)")
    tr.add_argument("--metric", required=True, choices=["flip", "psnr", "lpips", "jnflip", "jnyang", "yang"])
    tr.add_argument("--out", required=True, help="checkpoint to write (resumed if it exists)")
    tr.add_argument("--tile", type=int, default=16, choices=[1, 2, 4, 8, 16, 32])
    tr.add_argument("--outputs", default="1x2,2x1,2x4,4x2", help="rates the network predicts (comma-separated)")
    tr.add_argument("--inputs", default="reprojected.r,seen,albedo.r,normal.z", help="input channels, in order")
    tr.add_argument("--transform", default="clamped", choices=["clamped", "logistic"])
    tr.add_argument("--k", type=float, default=10.0, help="growth rate of the logistic transform")
    tr.add_argument("--head", default="paper", choices=["paper", "linear"],
                    help="last block: the paper's conv-ReLU-BatchNorm-sigmoid, or without the ReLU (no output can die)")
    tr.add_argument("--steps", type=int, default=3000)
    tr.add_argument("--batch", type=int, default=8)
    tr.add_argument("--crop", type=int, default=128, help="square crop size in pixels (a multiple of --tile)")
    tr.add_argument("--lr", type=float, default=1e-4)
    tr.add_argument("--val-scenes", default="", help="scenes held out for validation (default: the last scene)")
    tr.add_argument("--val-split", default=None, choices=["validation", "test", "train"],
                    help="hold out the scenes of this split of --scenes instead")
    tr.add_argument("--scenes", default=None, help="scenes.yaml for --val-split (default: the copy shipped with rtp)")
    tr.add_argument("--seed", type=int, default=0)
    tr.add_argument("--safety-quantile", type=float, default=None,
                    help="calibrate the margin so at most this share of tiles is underestimated (default: the paper's mean underestimation)")
    tr.add_argument("--threshold", type=float, default=None, help="default threshold written into the model")
    tr.add_argument("--max-samples", type=int, default=None, help="use at most this many training samples")
    tr.set_defaults(func=_cmd_train)

    ev = sub.add_parser("evaluate", help="prediction quality and VRS decisions of models on a dataset, next to the "
                        "Yang 2019 and FidelityFX baselines")
    ev.add_argument("model", nargs="+", help="one or more .onnx paths or shipped model names; each is scored on "
                    "the targets of its own metric and tile size")
    ev.add_argument("--data", required=True, help="dataset folder with targets from `rtp targets`")
    ev.add_argument("--out", default=None, help="folder for evaluation.md, evaluation.json (and --plots)")
    ev.add_argument("--scenes", action="append", default=None, help="evaluate only these scenes (comma-separated; repeatable)")
    ev.add_argument("--metadata", default=None, help="YAML sidecar for a model that carries no metadata")
    ev.add_argument("--threshold", type=float, default=None, help="decision threshold in metric units "
                    "(default: the model's default_threshold)")
    ev.add_argument("--unseen-fraction", type=float, default=0.5,
                    help="a tile is unseen when more than this share of its pixels is unseen (default 0.5)")
    ev.add_argument("--no-baselines", action="store_true", help="score only the model and the oracle")
    ev.add_argument("--plots", action="store_true", help="write heatmaps, a scatter and rate overlays (PNG) into --out")
    ev.add_argument("--plot-sample", default=None, help="sample the heatmaps and overlays show (default: the first)")
    ev.add_argument("--max-samples", type=int, default=None, help="evaluate at most this many samples")
    ev.set_defaults(func=_cmd_evaluate)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    from rtp.sdk import RtpError

    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args))
    except RtpError as err:
        if args.verbose:
            raise
        print(f"rtp {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"rtp {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into a program that stopped reading (head, less)
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
