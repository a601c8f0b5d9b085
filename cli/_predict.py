"""``rtp predict``: a model's predictions and shading rates for one frame of an engine's G-buffers, saved as
an ``.npz`` of the arrays ``sdk.input_planes`` takes; ``--write-example`` writes such a frame from the
reference renderer, to see the layout."""

from __future__ import annotations

import argparse
import difflib
import json
import logging
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["run_predict"]

log = logging.getLogger("rtp.cli")

#: The optional array of a frame file that ``--out``'s overlay is drawn on (the frame as displayed); without
#: it the overlay is drawn on ``albedo``, or on ``prev_colour``.
COLOUR_KEY = "colour"


def _read_frame(path: str) -> dict[str, np.ndarray]:
    """The arrays of a frame file, each named as a G-buffer of ``sdk.GBUFFERS`` (or ``colour``); others are
    named in a warning, with the G-buffer they may have meant."""
    from rtp import sdk

    p = Path(path)
    if not p.is_file():
        raise sdk.ParameterError(f"{path!r}: no such file (expected an .npz of G-buffers: `rtp predict "
                                 f"--write-example {path}` writes one from the reference renderer)", "frame")
    if not zipfile.is_zipfile(p):
        raise sdk.ParameterError(f"{path!r}: not an .npz (numpy.savez's zip of arrays)", "frame")
    try:
        with np.load(p, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise sdk.ParameterError(f"{path!r}: not an .npz of arrays numpy can read ({err})", "frame") from None
    known = (*sdk.GBUFFERS, COLOUR_KEY)
    for key in sorted(set(arrays) - set(known)):
        close = difflib.get_close_matches(key, known, n=1)
        log.warning("%s: array %r is not a G-buffer and is not read%s; G-buffers: %s", path, key,
                    f" (did you mean {close[0]}?)" if close else "", ", ".join(known))
    return {k: v for k, v in arrays.items() if k in known}


def write_example(path: str, size: tuple[int, int], seed: int) -> dict[str, np.ndarray]:
    """A frame of the built-in procedural scene as the reference renderer draws it, its G-buffers named as
    ``sdk.input_planes`` takes them, written atomically to ``path``."""
    from rtp import sdk
    from rtp.capture import check_frame_memory, check_frame_size, load_scene
    from rtp.capture.viewpoints import sample_viewpoints
    from rtp.plugins.moderngl import Renderer

    w, h = check_frame_size(size)  # (what the GL driver draws, and this machine holds, before drawing it)
    check_frame_memory("capture", (w, h))
    sdk.files.check_output(path, what="frame")
    scene, blockers = load_scene("procedural:0", None, None, None)
    prev_cam, cam = sample_viewpoints(scene, 1, seed=seed, profile="fast", blockers=blockers, aspect=w / h)[0]
    with Renderer(w, h) as r:
        r.load_scene(scene)
        prev = r.render(prev_cam)
        cur = r.render(cam, prev)
    arrays = {"depth": cur.depth, "albedo": cur.albedo, "normal": cur.normal, "roughness": cur.roughness,
              "metallic": cur.metallic, "specular": cur.specular, "shadow": cur.shadow, "emissive": cur.emissive,
              "view": cam.view(), "projection": cam.projection(w / h), "prev_colour": prev.colour["1x1"],
              "prev_depth": prev.depth, "prev_view_projection": prev_cam.view_projection(w, h),
              COLOUR_KEY: cur.colour["1x1"]}
    assert set(arrays) == {*sdk.GBUFFERS, COLOUR_KEY} - {"prev_projection"}  # (its projection did not change)
    payload: dict[str, Any] = {k: np.asarray(v, np.float64 if k in ("view", "projection", "prev_view_projection")
                                             else np.float32) for k, v in arrays.items()}
    with sdk.files.atomic_output(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **payload)
    return arrays


def run_predict(args: argparse.Namespace) -> int:
    from rtp import sdk

    if args.write_example:
        arrays = write_example(args.frame, args.size, args.seed)
        w, h = args.size
        print(f"wrote {args.frame}: a {w}x{h} frame of the procedural scene, {len(arrays)} arrays: "
              + ", ".join(f"{k} {'x'.join(map(str, v.shape))}" for k, v in arrays.items()))
        return 0
    frame = _read_frame(args.frame)
    predictor = sdk.load(args.model, tile_size=args.tile_size)
    inputs = predictor.metadata.inputs
    buffers: dict[str, Any] = {k: v for k, v in frame.items() if k in sdk.GBUFFERS}
    missing = [b for b in sdk.gbuffers_needed(inputs) if b not in buffers]
    if missing:
        raise sdk.ParameterError(
            f"{args.frame!r} has no {', '.join(repr(b) for b in missing)} array{'s' if len(missing) > 1 else ''}, which "
            f"{predictor.path.name if predictor.path else args.model} reads: "
            + "; ".join(f"{b} {sdk.GBUFFERS[b][0]}, {sdk.GBUFFERS[b][1]}" for b in missing), "frame")
    x = sdk.input_planes(inputs, **buffers, albedo_linear=args.albedo_linear, normal_space=args.normal_space,
                         depth_kind=args.depth_kind)
    h, w = x.shape[1:]
    start = time.perf_counter()
    values = predictor.predict(x)
    ms = 1000.0 * (time.perf_counter() - start)
    threshold = predictor.metadata.default_threshold if args.threshold is None else args.threshold
    allowed = None if args.allowed is None else [r for r in args.allowed.split(",") if r.strip()]
    rates = sdk.select_rates(values, threshold, higher_is_better=predictor.metadata.higher_is_better,
                             allowed=allowed, factors=predictor.metadata.rate_factors)
    saved = sdk.work_saved(rates, (h, w), predictor.tile_size)
    counts = {r: int((rates == c).sum()) for r, c in sdk.RATE_CODES.items()}
    summary: dict[str, Any] = {
        "frame": args.frame, "model": predictor.path.name if predictor.path else args.model,
        "metric": predictor.metadata.metric, "size": [w, h], "tile_size": predictor.tile_size,
        "tiles": list(rates.shape), "threshold": threshold, "rates": {r: n for r, n in counts.items() if n},
        "work_saved": saved, "predict_ms": ms,
    }
    if args.out:
        summary["wrote"] = _write_out(args.out, frame, values, rates, predictor.tile_size)
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"{summary['model']} ({summary['metric']}) on {args.frame}: {w}x{h}, {rates.shape[1]}x{rates.shape[0]} "
          f"tiles of {predictor.tile_size}px, threshold {threshold:g}")
    print("rates      " + ", ".join(f"{r} {n}" for r, n in summary["rates"].items()))
    print(f"saved      {100.0 * saved:.1f}% of the shading work")
    print(f"predict    {ms:.1f} ms (onnxruntime, {predictor.provider})")
    if args.out:
        print(f"wrote {', '.join(summary['wrote'])} in {args.out}")
    return 0


def _write_out(folder: str, frame: dict[str, np.ndarray], values: np.ndarray, rates: np.ndarray,
               tile: int) -> list[str]:
    """``rates.npy`` (uint8 codes), ``predictions.npy`` (float32 ``(6, th, tw)``, metric units) and
    ``overlay.png`` (the rates over the frame's ``colour``, else its albedo or previous frame)."""
    from rtp import sdk
    from rtp.capture import save_image

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    for name, array in (("rates.npy", rates), ("predictions.npy", values)):
        with sdk.files.atomic_output(out / name) as tmp, open(tmp, "wb") as f:
            np.save(f, array)
    size = (*np.shape(frame["depth"]), 3)
    base = next((frame[k] for k in (COLOUR_KEY, "albedo", "prev_colour") if k in frame and frame[k].shape == size),
                np.zeros(size, np.float32))
    picture = sdk.draw_rate_overlay(np.clip(np.asarray(base, np.float32), 0.0, 1.0), rates, tile, legend=True)
    save_image(out / "overlay.png", picture)
    return ["rates.npy", "predictions.npy", "overlay.png"]
