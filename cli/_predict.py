"""``rtp predict``: a model's predictions and shading rates for frames of an engine's G-buffers, each saved as
an ``.npz`` of the arrays ``sdk.input_planes`` takes: one frame, or a sequence (several files, or a folder of
them) with the share of tiles whose rate changes from frame to frame and an animated overlay;
``--write-example`` writes such a frame (or with ``--frames`` a sequence) from the reference renderer, to see
the layout."""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import re
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ._run import out_lock

__all__ = ["run_predict"]

log = logging.getLogger("rtp.cli")

#: The optional array of a frame file that ``--out``'s overlay is drawn on (the frame as displayed); without
#: it the overlay is drawn on ``albedo``, or on ``prev_colour``.
COLOUR_KEY = "colour"
#: A frame file's array of the engine's own shading rates (uint8 codes, a tile each) that ``--combiner`` combines.
ENGINE_RATES_KEY = "engine_rates"


def _read_frame(path: str) -> dict[str, np.ndarray]:
    """The arrays of a frame file, each named as a G-buffer of ``sdk.GBUFFERS`` (or ``colour``); others are
    named in a warning, with the G-buffer they may have meant. ``final_<rate>``, the frame shaded at every rate that
    a frame of ``rtp import`` holds (``rtp import --write-example`` writes them), are known and left out unread."""
    from rtp import sdk

    finals = tuple(f"final_{rate}" for rate in sdk.ALL_RATES)  # (rtp.capture's import FINAL_KEYS)
    frame = sdk.files.read_frame(path, extra=(COLOUR_KEY, ENGINE_RATES_KEY, *finals))
    return {k: v for k, v in frame.items() if k not in finals}


#: The bytes a prediction of a frame holds besides the arrays it reads (Python, numpy, onnxruntime, the model) and for
#: each pixel of the frame (the arrays' float copies, the input planes and the reprojection, the checks' temporaries):
#: the peak resident set of `rtp predict` (jnyang) on example frames of 320x180 and 1280x720 (84 bytes a pixel read)
#: was 92 and 344 MiB, 306 bytes a pixel.
PREDICT_BASE = 64 * 2**20
PREDICT_PER_PIXEL = 220.0


def _check_frames_memory(files: list[str]) -> None:
    """Refuse (``RTP_MEMORY_CHECK``, as ``rtp import``) a frame whose prediction would hold more than the machine's
    memory, from its arrays' headers, before the first frame is read: an array whose header says a huge shape was read
    until numpy's MemoryError, reported as a damaged file, or until the system killed the run."""
    from rtp import sdk
    from rtp.capture import check_memory

    known = {*sdk.GBUFFERS, COLOUR_KEY, ENGINE_RATES_KEY}  # (what _read_frame reads: the final_<rate> are not)
    worst: tuple[int, str, int, list[tuple[int, str, tuple[int, ...], np.dtype[Any]]]] | None = None
    for path in files:
        try:
            headers: dict[str, tuple[tuple[int, ...], np.dtype[Any]]] | None = sdk.files.array_headers(path)
        except sdk.ParameterError:  # (read_frame names what is wrong with it at its turn)
            headers = None
        if not headers:
            continue
        sizes = [(int(np.prod(shape, dtype=np.float64)) * dtype.itemsize, key, shape, dtype)
                 for key, (shape, dtype) in headers.items() if key in known]
        depth = headers.get("depth", ((), np.dtype(np.float32)))[0]
        pixels = int(np.prod(depth[:2], dtype=np.float64)) if len(depth) >= 2 else 0
        read = sum(n for n, *_ in sizes)
        need = int(PREDICT_BASE + PREDICT_PER_PIXEL * pixels + read)
        if worst is None or need > worst[0]:
            worst = (need, path, read, sizes)
    if worst is None:
        return
    need, path, read, sizes = worst
    n, key, shape, dtype = max(sizes, key=lambda s: s[0]) if sizes else (0, "", (), np.dtype(np.float32))
    largest = f" (the largest, {key}: shape {shape}, {dtype}, {n / 2**30:.1f} GiB)" if sizes else ""
    check_memory(need, f"{path!r}: a prediction of it holds about {need / 2**30:.1f} GiB ({need} bytes), its arrays "
                       f"{read / 2**30:.1f} GiB{largest}", "frame",
                 "of memory: smaller frames, or arrays of the shapes their headers should say", job="rtp predict")


def _frame_arrays(prev: Any, cur: Any, prev_cam: Any, cam: Any, size: tuple[int, int]) -> dict[str, np.ndarray]:
    """A rendered frame's G-buffers named as ``sdk.input_planes`` takes them (and ``colour``)."""
    w, h = size
    return {"depth": cur.depth, "albedo": cur.albedo, "normal": cur.normal, "roughness": cur.roughness,
            "metallic": cur.metallic, "specular": cur.specular, "shadow": cur.shadow, "emissive": cur.emissive,
            "view": cam.view(), "projection": cam.projection(w / h), "prev_colour": prev.colour["1x1"],
            "prev_depth": prev.depth, "prev_view_projection": prev_cam.view_projection(w, h),
            "motion": cur.motion, COLOUR_KEY: cur.colour["1x1"]}


def _save_frame(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    from rtp import sdk

    payload: dict[str, Any] = {k: v if np.asarray(v).dtype == np.uint8 else  # (an 8-bit read-back stays one)
                               np.asarray(v, np.float64 if k in ("view", "projection", "prev_view_projection")
                                          else np.float32) for k, v in arrays.items()}
    with sdk.files.atomic_output(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **payload)


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
    arrays = _frame_arrays(prev, cur, prev_cam, cam, (w, h))
    assert set(arrays) == {*sdk.GBUFFERS, COLOUR_KEY} - {"prev_projection"}  # (its projection did not change)
    _save_frame(path, arrays)
    return arrays


def write_sequence(folder: str, size: tuple[int, int], seed: int, count: int,
                   progress: Callable[[int], None] | None = None, *, rates: bool = False,
                   scene_name: str = "procedural:0", cache_dir: str | None = None) -> list[str]:
    """``count`` consecutive frames at 60 Hz along a ``slow`` camera path through ``scene_name`` (the procedural
    scene by default; a map is read from the scene cache ``cache_dir``, None for the default one), as an engine
    would dump them (each frame's ``prev_colour`` the one before it as displayed, at full rate), written to
    ``folder`` as ``frame_0000.npz`` ...; the names written
    (``progress`` is called with the count written after each). ``rates``: each frame also holds
    ``final_<rate>``, the frame shaded at every rate (what ``rtp import`` trains on)."""
    from rtp import sdk
    from rtp.capture import check_frame_memory, check_frame_size, load_scene
    from rtp.capture.paths import camera_path
    from rtp.plugins.moderngl import Renderer

    w, h = check_frame_size(size)
    check_frame_memory("capture", (w, h))
    out = sdk.files.check_output(folder, folder=True, what="frame folder")
    names = [f"frame_{i:04d}.npz" for i in range(count)]
    # (frames of an earlier run, or an engine's dump, left beside these: `rtp predict` / `rtp import` of the folder
    # read them all as one sequence, two camera paths in one, without a word)
    others = sorted((f.name for f in out.glob("*.npz") if f.name not in names), key=sdk.files._natural) \
        if out.is_dir() else []
    if others:
        raise sdk.ParameterError(
            f"frame folder: {str(out)!r} holds {len(others)} other .npz frame{'s' if len(others) > 1 else ''} ("
            f"{', '.join(others[:3])}{', ...' if len(others) > 3 else ''}), which a run on the folder would take as "
            f"frames of these {count}: give an empty folder, or remove them", "frames")
    scene, blockers = load_scene(scene_name, cache_dir, None, None)
    path = camera_path(scene, count + 1, "slow", seed, blockers=blockers)
    with Renderer(w, h) as r:
        r.load_scene(scene)
        prev = r.render(path.cameras[0])
        for name, prev_cam, cam in zip(names, path.cameras, path.cameras[1:]):
            cur = r.render(cam, prev)
            arrays = _frame_arrays(prev, cur, prev_cam, cam, (w, h))
            if rates:  # as an engine reads its swap chain's 8-bit frames back
                arrays.update({f"final_{rate}": np.round(cur.colour[rate] * 255).astype(np.uint8)
                               for rate in sdk.ALL_RATES})
            _save_frame(out / name, arrays)
            prev = cur
            if progress is not None:
                progress(names.index(name) + 1)
    return names


#: The widest frame of a sequence's ``overlay.gif`` (wider frames are shown at an integer fraction of
#: their size) and its playback rate.
GIF_WIDTH, GIF_FPS = 480, 20


def frame_files(paths: list[str]) -> list[str]:
    """The frame files ``paths`` name: each an ``.npz``, or a folder whose ``*.npz`` are taken in the natural
    order of their names (``frame_9`` before ``frame_10``)."""
    from rtp import sdk

    return sdk.files.frame_files(paths)


def _warn_of_order(files: list[str]) -> None:
    """Log where a sequence's files, as given, are likely not the frames the engine drew one after another (the
    frame-to-frame changes, and ``--every``'s carry along each frame's motion, then span two frames apart): two
    files of one folder out of the natural order of their names (a shell's ``*`` sorts ``frame_10`` before
    ``frame_2``), and a number missing from a folder's numbered names (a frame the engine did not dump)."""
    from rtp import sdk

    numbered = re.compile(r"(.*?)(\d+)(\D*)")
    steps: list[tuple[str, str, int]] = []
    for a, b in zip(files, files[1:]):
        pa, pb = Path(a), Path(b)
        if pa.parent != pb.parent:
            continue
        if sdk.files._natural(pb.name) < sdk.files._natural(pa.name):
            log.warning("%s comes before %s as given, out of the natural order of their names (a shell's * sorts "
                        "names as text): the sequence is taken in the order given; give the folder, %s, to take "
                        "its frames in that order", a, b, pa.parent)
            return
        ma, mb = numbered.fullmatch(pa.stem), numbered.fullmatch(pb.stem)
        if ma and mb and (ma[1], ma[3]) == (mb[1], mb[3]):
            steps.append((a, b, int(mb[2]) - int(ma[2])))
    if not steps:
        return
    counts = Counter(s for *_, s in steps)  # the usual step (an engine may dump every k-th frame); a tie, the least
    usual = min(counts, key=lambda s: (-counts[s], s))
    gaps = [(a, b) for a, b, s in steps if s > usual]
    if gaps:
        more = f" (and {len(gaps) - 1} more such gap{'s' if len(gaps) > 2 else ''})" if len(gaps) > 1 else ""
        log.warning("%s then %s: a frame missing between, its numbers %d apart elsewhere%s: the share of tiles "
                    "that change rate, and --every's carry, span the gap", gaps[0][0], Path(gaps[0][1]).name, usual,
                    more)


#: The planes prediction reuse reads besides a model's: where each pixel was (its motion) and the sky.
_REUSE_PLANES = ("motion.x", "motion.y", "depth")
#: The planes that tell a ``prev_colour`` (or a ``colour``) in linear light, made where a frame holds ``colour``: the
#: previous frame reprojected, where it was seen, and the sky (``rtp.capture.linear_light_warning``, as ``rtp import``
#: checks ``final_1x1``). The shipped models reproject anyway: one reprojection serves both.
_ENCODING_PLANES = ("reprojected.r", "reprojected.g", "reprojected.b", "seen", "depth")


def _shown(frame: dict[str, np.ndarray]) -> np.ndarray | None:
    """A frame's ``colour`` as float ``(H, W, 3)`` in [0, 1] for the linear-light check: float display values or UNORM
    integers (``uint8``, ``uint16``) of the depth's size, RGB or RGBA; None for anything else (an HDR colour, out of
    [0, 1], is not the frame as shown: nothing to compare)."""
    a = np.asarray(frame[COLOUR_KEY])
    if a.ndim != 3 or a.shape[:2] != np.shape(frame["depth"])[:2] or a.shape[2] not in (3, 4):
        return None
    if a.dtype == np.uint8 or a.dtype == np.uint16:
        return a[..., :3].astype(np.float32) / np.float32(np.iinfo(a.dtype).max)
    if a.dtype.kind != "f":
        return None
    v = np.asarray(a[..., :3], np.float32)
    if not np.isfinite(v).all() or (v.size and (v.min() < -1e-3 or v.max() > 1 + 1e-3)):
        return None
    return np.clip(v, 0.0, 1.0)


# the SDK's options as its messages name them (normal_space='world'), and the flags that set them here
_OPTION = re.compile(r"\b(normal_space|depth_kind)='(\w+)'")


def _in_flags(text: str) -> str:
    """An SDK message in this command's words: ``depth_kind='linear'`` is ``--depth-kind linear`` here."""
    return _OPTION.sub(lambda m: f"--{m[1].replace('_', '-')} {m[2]}", text)


def _warn_of_conventions(path: str, buffers: dict[str, Any], args: argparse.Namespace,
                         warned: dict[str, list[Any]], more: list[str] | None = None) -> list[str]:
    """``sdk.check_gbuffers``' warnings for a frame, and ``more`` (the linear-light check's), logged each kind once
    (``warned``: per kind, the frames that had it and its first text; the numbers in a warning differ from frame to
    frame); all of them returned."""
    from rtp import sdk

    texts = [_in_flags(t) for t in sdk.check_gbuffers(**buffers, normal_space=args.normal_space,
                                                      depth_kind=args.depth_kind)] + list(more or [])
    for text in texts:
        kind = warned.setdefault(re.sub(r"-?\d[\d.]*", "#", text), [0, f"{path}: {text}"])
        kind[0] += 1
        if kind[0] == 1:  # (the text as the record's message: the command's log collapses records of one message,
            log.warning(kind[1])  # and a "%s" of them all hid every kind after the first)
    return texts


@contextlib.contextmanager
def _naming(path: str) -> Iterator[None]:
    """An rtp error of the block, on the frame file ``path``, named by the file (an array's error named the array
    alone: on a sequence of hundreds of frames, not which frame held it) and said in this command's flags."""
    from rtp import sdk

    try:
        yield
    except sdk.RtpError as err:
        text = _in_flags(str(err))
        err.args = (text if text.startswith(repr(path)) else f"{path!r}: {text}", *err.args[1:])
        raise


def _predict_frame(predictor: Any, path: str, args: argparse.Namespace, threshold: float,
                   allowed: list[str] | None, reuse: Any = None, warned: dict[str, list[Any]] | None = None,
                   ) -> tuple[dict[str, Any], dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """One frame file's summary, arrays, predicted values and rate codes; with ``reuse`` (an
    ``sdk.PredictionReuse``) its values, the network run or its estimates carried from the frame before
    along the frame's motion. What in the frame looks like a convention mistake is logged
    (``sdk.check_gbuffers``; where the frame holds ``colour``, a ``prev_colour`` or ``colour`` in linear light too),
    each kind once in ``warned``. With ``args.saving`` the rates save that share of the work at the frame's lowest
    threshold, which the summary holds instead of ``threshold``."""
    from rtp import sdk
    from rtp.capture import linear_light_warning

    frame = _read_frame(path)
    inputs = predictor.metadata.inputs
    extra = [c for c in _REUSE_PLANES if c not in inputs] if reuse is not None else []
    buffers: dict[str, Any] = {k: v for k, v in frame.items() if k in sdk.GBUFFERS}
    shown = _shown(frame) if COLOUR_KEY in frame and "depth" in frame else None
    encoding = list(_ENCODING_PLANES) if shown is not None and all(
        b in buffers for b in sdk.gbuffers_needed(_ENCODING_PLANES)) else []
    missing = [b for b in sdk.gbuffers_needed([*inputs, *extra]) if b not in buffers]
    if missing:
        reads = (f"{predictor.path.name if predictor.path else args.model}"
                 + (" and --every's motion" if any(b not in sdk.gbuffers_needed(inputs) for b in missing) else ""))
        raise sdk.ParameterError(
            f"{path!r} has no {', '.join(repr(b) for b in missing)} array{'s' if len(missing) > 1 else ''}, which "
            f"{reads} reads: " + "; ".join(f"{b} {sdk.GBUFFERS[b][0]}, {sdk.GBUFFERS[b][1]}" for b in missing),
            "frame")
    planes = sdk.input_planes([*inputs, *extra, *encoding], **buffers, albedo_linear=args.albedo_linear,
                              normal_space=args.normal_space, depth_kind=args.depth_kind)
    linear = None
    if encoding and shown is not None:  # (the frame shown beside the previous one reprojected, as rtp import's final_1x1)
        rep_r, rep_g, rep_b, seen, depth = planes[len(inputs) + len(extra):]
        linear = linear_light_warning(np.stack([rep_r, rep_g, rep_b], axis=-1), seen, shown, depth > 0.0,
                                      name=COLOUR_KEY)
        planes = planes[:len(inputs) + len(extra)]
    warnings = _warn_of_conventions(path, buffers, args, {} if warned is None else warned,
                                    [linear] if linear else None)
    x = planes[:len(inputs)]
    h, w = x.shape[1:]
    start = time.perf_counter()
    if reuse is None:
        values = predictor.predict(x)
    else:
        named = dict(zip([*inputs, *extra], planes))
        fetch = None if reuse.age is None else sdk.fetch_from_motion(named["motion.x"], named["motion.y"])
        values = reuse.predict(x, fetch, named.get("seen"), named["depth"] <= 0.0)
    ms = 1000.0 * (time.perf_counter() - start)
    meta = predictor.metadata
    engine = None
    if args.combiner is None and ENGINE_RATES_KEY in frame:  # (read_frame takes it as known: say it is not read)
        kind = ({} if warned is None else warned).setdefault(ENGINE_RATES_KEY, [0, (
            f"{path}: the {ENGINE_RATES_KEY!r} array is not read without --combiner (min, max or sum: how the device "
            "combines the engine's rates with rtp's)")])
        kind[0] += 1
        if kind[0] == 1:
            log.warning(kind[1])
    if args.combiner is not None:
        if ENGINE_RATES_KEY not in frame:
            raise sdk.ParameterError(f"{path!r} has no {ENGINE_RATES_KEY!r} array: with --combiner each frame holds the "
                                     f"engine's own shading rates, uint8 codes a tile (shape {tuple(np.shape(values)[1:])} "
                                     "here, rows of tiles first), which the device combines with rtp's", "frame")
        engine = frame[ENGINE_RATES_KEY]
    combine: dict[str, Any] = {"engine_rates": engine, "combiner": args.combiner or "max"}
    if args.saving is None:
        rates = sdk.select_rates(values, threshold, higher_is_better=meta.higher_is_better, allowed=allowed,
                                 factors=meta.rate_factors, **combine)
    else:
        budget = sdk.select_rates_for_saving(values, args.saving, higher_is_better=meta.higher_is_better,
                                             allowed=allowed, factors=meta.rate_factors, frame_size=(h, w),
                                             tile_size=predictor.tile_size, threshold=args.threshold, **combine)
        rates, threshold = budget.rates, float(budget.threshold)
    shaded = rates if engine is None else sdk.combine_rates(engine, rates, args.combiner, allowed=allowed)
    counts = {r: int((shaded == c).sum()) for r, c in sdk.RATE_CODES.items()}
    summary: dict[str, Any] = {
        "frame": path, "size": [w, h], "tiles": list(rates.shape), "rates": {r: n for r, n in counts.items() if n},
        "work_saved": sdk.work_saved(shaded, (h, w), predictor.tile_size), "threshold": threshold, "predict_ms": ms,
        "warnings": warnings,
    }
    if engine is not None:  # (the device's rates above; the engine's alone here)
        summary["engine_work_saved"] = sdk.work_saved(np.broadcast_to(engine, rates.shape), (h, w),
                                                      predictor.tile_size)
    if reuse is not None:
        summary["network"] = float(reuse.work)
    return summary, frame, values, rates


#: The options of a prediction, with the value each has when not given (``--write-example`` refuses them: it writes a
#: frame in the default conventions, and predicts nothing).
_PREDICT_OPTIONS = {"model": "jnyang", "metadata": None, "threshold": None, "saving": None, "combiner": None,
                    "tile_size": None, "allowed": None, "out": None, "albedo_linear": False, "normal_space": "view",
                    "depth_kind": "linear", "every": None, "json": False,
                    "palette": "paper"}
#: ``--write-example``'s options and their values when not given (refused without it).
_EXAMPLE_OPTIONS = {"size": (640, 360), "seed": 0}


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def example_options(args: argparse.Namespace, command: str, defaults: dict[str, Any],
                    others: dict[str, Any]) -> None:
    """Refuse the options that the run does not read, rather than ignore them: with ``--write-example`` those of
    ``others`` given (other than their value when not given); without it, those of ``defaults`` given. Then fill
    in the defaults of ``--write-example``'s options (which the parser leaves at None, to tell them given)."""
    from rtp import sdk

    if args.write_example:
        given = [_flag(k) for k, v in others.items() if getattr(args, k, v) != v]
        if given:
            raise sdk.ParameterError(f"{', '.join(given)}: not read with --write-example, which only writes "
                                     f"{'frames' if command == 'import' else 'a frame'} of the reference renderer (in "
                                     f"the default conventions); give {'them' if len(given) > 1 else 'it'} to `rtp "
                                     f"{command} {' '.join(args.frames)}` without --write-example, once written",
                                     given[0][2:].replace("-", "_"))
        for k, v in defaults.items():
            if getattr(args, k, None) is None:
                setattr(args, k, v)
        return
    given = [_flag("frames" if k == "count" else k) for k in defaults if getattr(args, k, None) is not None]
    if given:
        raise sdk.ParameterError(f"{', '.join(given)}: {'options' if len(given) > 1 else 'an option'} of "
                                 f"--write-example (which writes example frames), not read without it",
                                 given[0][2:].replace("-", "_"))


def run_predict(args: argparse.Namespace) -> int:
    from rtp import sdk

    example_options(args, "predict", _EXAMPLE_OPTIONS, _PREDICT_OPTIONS)
    if args.write_example:
        if len(args.frames) != 1:
            raise sdk.ParameterError(f"--write-example writes one path (a frame file, or with --frames a folder); got "
                                     f"{len(args.frames)}", "frame")
        path = args.frames[0]
        w, h = args.size
        if args.count > 1:
            from ._run import Bar

            with Bar(args, args.count, "write frames", "frame") as bar:
                written = write_sequence(path, args.size, args.seed, args.count, bar.update_to)
            print(f"wrote {len(written)} frames of {w}x{h} along a camera path through the procedural scene in "
                  f"{path}: {written[0]} ... {written[-1]}")
            return 0
        arrays = write_example(path, args.size, args.seed)
        print(f"wrote {path}: a {w}x{h} frame of the procedural scene, {len(arrays)} arrays: "
              + ", ".join(f"{k} {'x'.join(map(str, v.shape))}" for k, v in arrays.items()))
        return 0
    if args.palette != "paper" and not args.out:  # (it was taken and nothing drawn, as rtp evaluate and rtp play refuse)
        raise sdk.ParameterError(f"--palette {args.palette}: the colours of the rate overlay --out draws (overlay.png, "
                                 "a sequence's overlay.gif): give --out DIR, or leave --palette out", "palette")
    if args.count != 1:
        raise sdk.ParameterError(f"--frames {args.count}: the number of frames --write-example writes; a sequence to "
                                 "predict is every frame file given (or every .npz of a folder)", "frames")
    files = frame_files(args.frames)
    first: dict[str, int] = {}  # (a frame given twice, or a folder and one of its files, was predicted twice, the
    for i, f in enumerate(files):  # sequence going back to it: its rate changes and --every's carry across the jump)
        j = first.setdefault(os.path.realpath(f), i)
        if j != i:
            raise sdk.ParameterError(f"{f!r}: a frame given twice" + (f" (as {files[j]!r} too)" if files[j] != f else "")
                                     + ": a sequence takes each frame once, in order (a folder, or its files, not both)",
                                     "frame")
    sequence = len(files) > 1 or any(Path(f).is_dir() for f in args.frames)
    if args.out:
        _picture_modules(sequence)
    _warn_of_order(files)
    if args.every is not None and not sequence:
        raise sdk.ParameterError(f"--every {args.every}: prediction reuse carries estimates from frame to frame; give "
                                 "a sequence (several frame files, or a folder of them)", "every")
    _check_frames_memory(files)  # (from the arrays' headers: a frame past the machine's memory, before any work)
    from ._main import _load

    predictor = _load(args, tile_size=args.tile_size)  # (a foreign model's sidecar: --metadata)
    threshold = predictor.metadata.default_threshold if args.threshold is None else args.threshold
    allowed = None if args.allowed is None else [r.strip() for r in args.allowed.split(",") if r.strip()]
    if allowed == []:  # (an unset shell variable, likely: VRS off is said as --allowed 1x1)
        raise sdk.ParameterError(f"--allowed: expected comma-separated rate names, got {args.allowed!r} (for no "
                                 "reduced rate, every tile at full rate: --allowed 1x1)", "allowed")
    twice = [r for r in dict.fromkeys(allowed or []) if (allowed or []).count(r) > 1]
    if twice:  # (2x2,2x2 ran as 2x2 alone: a typo of another rate, likely, taken in silence)
        raise sdk.ParameterError(f"--allowed: each rate once, got {', '.join(twice)} more than once in "
                                 f"{args.allowed!r}", "allowed")
    if args.saving is not None:  # (its range, with the rates allowed, before the first frame's work)
        sdk.select_rates_for_saving(np.zeros((6, 1, 1)), args.saving, allowed=allowed, threshold=args.threshold,
                                    higher_is_better=predictor.metadata.higher_is_better)
    else:  # (the threshold's range and the rates allowed too: a sequence printed its header, read and predicted its
        # first frame, and only then refused --threshold nan or --allowed 3x3)
        sdk.select_rates(np.zeros((6, 1, 1)), threshold, allowed=allowed, factors=predictor.metadata.rate_factors,
                         higher_is_better=predictor.metadata.higher_is_better)
    model = predictor.path.name if predictor.path else args.model
    with out_lock(Path(args.out), "rtp predict", "write into another folder") if args.out else contextlib.nullcontext():
        if sequence:
            return _run_sequence(args, files, predictor, threshold, allowed, model)
        return _run_frame(args, files[0], predictor, threshold, allowed, model)


def _run_frame(args: argparse.Namespace, path: str, predictor: Any, threshold: float, allowed: list[str] | None,
               model: str) -> int:
    """A model on one frame file: its rates, the work they save and the predict time; with ``--out`` its
    rates.npy, predictions.npy and overlay.png."""
    with _naming(path):
        summary, frame, values, rates = _predict_frame(predictor, path, args, threshold, allowed)
    summary = {"frame": summary["frame"], "model": model, "metric": predictor.metadata.metric,
               "size": summary["size"], "tile_size": predictor.tile_size, "tiles": summary["tiles"],
               "threshold": summary["threshold"], "threshold_given": args.threshold, "saving": args.saving,
               "rates": summary["rates"],
               "work_saved": summary["work_saved"], "predict_ms": summary["predict_ms"], "warnings": summary["warnings"],
               **({} if args.combiner is None else {"combiner": args.combiner,
                                                    "engine_work_saved": summary["engine_work_saved"]})}
    if args.out:
        summary["wrote"] = _write_out(args.out, frame, values, rates, predictor.tile_size, args.palette)
    if args.json:
        print(json.dumps(summary))
        return 0
    w, h = summary["size"]
    print(f"{model} ({summary['metric']}) on {summary['frame']}: {w}x{h}, {rates.shape[1]}x{rates.shape[0]} "
          f"tiles of {predictor.tile_size}px, " + _holding(args, summary["threshold"]))
    print("rates      " + ", ".join(f"{r} {n}" for r, n in summary["rates"].items()))
    print(f"saved      {100.0 * summary['work_saved']:.1f}% of the shading work"
          + ("" if args.combiner is None else f", the engine's rates and rtp's combined by {args.combiner} (the "
                                              f"engine's alone: {100.0 * summary['engine_work_saved']:.1f}%)"))
    print(f"predict    {summary['predict_ms']:.1f} ms (onnxruntime, {predictor.provider})")
    if args.out:
        print(f"wrote {', '.join(summary['wrote'])} in {args.out}")
    return 0


def _run_sequence(args: argparse.Namespace, files: list[str], predictor: Any, threshold: float,
                  allowed: list[str] | None, model: str) -> int:
    """A model on each frame of a sequence: a line a frame (work saved, the share of tiles whose rate changed
    from the frame before, predict time), the means, and with ``--out`` the stacked arrays, ``frames.csv``, the
    overlays as ``overlay.gif`` and the per-frame curves as ``frames.png``."""
    from rtp import sdk

    from ._run import Bar

    warned: dict[str, list[Any]] = {}
    reuse = None
    if args.every is not None:
        reuse = sdk.PredictionReuse(predictor, args.every, carry="features" if predictor.splits else "estimates")
    rows: list[dict[str, Any]] = []
    all_rates: list[np.ndarray] = []
    all_values: list[np.ndarray] = []
    overlays: list[np.ndarray] = []
    first_size: list[int] | None = None
    base = os.path.commonpath([os.path.abspath(Path(f).parent) for f in files])
    shown = [os.path.relpath(os.path.abspath(f), base) for f in files]  # (each frame's name under the folder)
    width = max(5, *map(len, shown))
    held = (f"threshold {threshold:g}" if args.saving is None else f"a saving of {args.saving:g}" if args.threshold
            is None else f"threshold {threshold:g} with a floor of {args.saving:g} saved")
    # (what frames.png's title says: it named neither the model nor what its rates held)
    what = f"{model} ({predictor.metadata.metric}), {held}, tiles of {predictor.tile_size}px, {len(files)} frames"
    if not args.json and not args.quiet:
        print(f"{what} in {os.path.relpath(base) if base.startswith(os.getcwd()) else base}")
        if reuse is not None:
            print(f"prediction reuse: the network every {args.every} frames, its {reuse.carry} carried between")
        print(f"{'frame':<{width}} {'saved':>7} {'changed':>8} {'predict':>9}" + ("  network" if reuse else "")
              + ("  threshold" if args.saving is not None else ""))
    # (the lines a frame are the progress in text; a bar beside them would be drawn between them)
    quiet_bar = argparse.Namespace(**{**vars(args), "no_progress": args.no_progress or not (args.json or args.quiet)})
    with Bar(quiet_bar, len(files), "predict", "frame") as bar:
        for i, path in enumerate(files):
            with _naming(path):
                row, frame, values, rates = _predict_frame(predictor, path, args, threshold, allowed, reuse, warned)
            if first_size is None:
                first_size = row["size"]
                if args.out:  # the overlays kept for the GIF, refused now rather than by the OOM killer later
                    from rtp.capture import check_memory

                    w, h = first_size
                    step = -(-w // GIF_WIDTH)
                    need = len(files) * (-(-h // step)) * (-(-w // step)) * 3
                    check_memory(need, f"{len(files)} frames' overlays for overlay.gif take {need / 2**30:.1f} GiB",
                                 "frame", "of memory: fewer frames a run", job="rtp predict")
            elif row["size"] != first_size:
                raise sdk.ParameterError(f"{path!r} is {row['size'][0]}x{row['size'][1]}, the sequence's first frame "
                                         f"{first_size[0]}x{first_size[1]}: a sequence's frames are of one size",
                                         "frame")
            row["changed"] = float((rates != all_rates[-1]).mean()) if all_rates else None
            rows.append(row)
            all_rates.append(rates)
            if args.out:
                all_values.append(values)
                overlays.append(_overlay(frame, rates, predictor.tile_size, GIF_WIDTH, args.palette))
            if not args.json and not args.quiet:
                changed = "" if row["changed"] is None else f"{100.0 * row['changed']:.1f}%"
                network = "" if reuse is None else "  ran" if row["network"] >= 1.0 else (
                    f"  carried ({row['network']:.0%} of a run)" if row["network"] > 0 else "  carried")
                reached = "" if args.saving is None else f"  {row['threshold']:.4g}"
                print(f"{shown[i]:<{width}} {100.0 * row['work_saved']:>6.1f}% {changed:>8} {row['predict_ms']:>6.1f} ms"
                      + network + reached)
            bar.update_to(i + 1)
    for n, first in warned.values():
        if n > 1:
            log.warning(f"... and on {n - 1} more frame{'s' if n > 2 else ''} of the sequence: {first}")
    changes = [r["changed"] for r in rows if r["changed"] is not None]
    summary: dict[str, Any] = {
        "frames": rows, "model": model, "metric": predictor.metadata.metric, "size": first_size,
        "tile_size": predictor.tile_size, "threshold": threshold if args.saving is None else None,
        # (--threshold as given: with --saving the threshold the saving is a floor under, recorded nowhere else)
        "threshold_given": args.threshold, "saving": args.saving,
        "work_saved": float(np.mean([r["work_saved"] for r in rows])),
        "changed": float(np.mean(changes)) if changes else None,
        "predict_ms": float(np.median([r["predict_ms"] for r in rows])),
        "predict_ms_mean": float(np.mean([r["predict_ms"] for r in rows])),
    }
    if reuse is not None:
        summary.update(every=args.every, network=float(np.mean([r["network"] for r in rows])))
    if args.combiner is not None:  # (work_saved: the device's, the engine's rates and rtp's combined)
        summary.update(combiner=args.combiner,
                       engine_work_saved=float(np.mean([r["engine_work_saved"] for r in rows])))
    if args.saving is not None:  # (the quality a budget left each frame: its threshold's spread)
        levels = np.array([r["threshold"] for r in rows], np.float64)
        summary["thresholds"] = {"min": float(levels.min()), "median": float(np.median(levels)),
                                 "max": float(levels.max())}
    if args.out:
        summary["wrote"] = _write_sequence_out(args.out, rows, all_rates, all_values, overlays, args.saving is not None,
                                               predictor.metadata.higher_is_better, title=what)
    if args.json:
        print(json.dumps(summary))
        return 0
    changed = "" if summary["changed"] is None else f", {100.0 * summary['changed']:.1f}% of tiles change rate a frame"
    network = "" if reuse is None else f"; the network's work {100.0 * summary['network']:.0f}% of a run a frame"
    if args.saving is not None:
        spread = summary["thresholds"]
        network += (f"; thresholds reached {spread['median']:.4g} (median; {spread['min']:.4g} to "
                    f"{spread['max']:.4g})")
    if args.combiner is not None:
        network += (f"; with the engine's rates by {args.combiner} (the engine's alone "
                    f"{100.0 * summary['engine_work_saved']:.1f}%)")
    print(f"mean: {100.0 * summary['work_saved']:.1f}% of the shading work saved{changed}{network}; predict "
          f"{summary['predict_ms_mean']:.1f} ms a frame (median {summary['predict_ms']:.1f}; onnxruntime, "
          f"{predictor.provider})")
    if args.out:
        print(f"wrote {', '.join(summary['wrote'])} in {args.out}")
    return 0


def _overlay(frame: dict[str, np.ndarray], rates: np.ndarray, tile: int, width: int | None = None,
             palette: str = "paper") -> np.ndarray:
    """The rates over the frame's ``colour``, else its albedo or previous frame (black without any), legend
    drawn, uint8, in ``palette``'s colours; with ``width``, shown at the largest integer fraction of its size at most
    that wide."""
    from rtp import sdk

    size = np.shape(frame["depth"])[:2]

    def image(a: np.ndarray) -> np.ndarray | None:  # RGB or RGBA of the frame's size, float or UNORM integers
        if a.ndim != 3 or a.shape[:2] != size or a.shape[2] not in (3, 4) or a.dtype.kind not in "uif":
            return None
        scale = np.iinfo(a.dtype).max if a.dtype in (np.uint8, np.uint16) else 1.0
        return np.asarray(a[..., :3], np.float32) / np.float32(scale)

    base = next((b for k in (COLOUR_KEY, "albedo", "prev_colour") if k in frame and (b := image(frame[k])) is not None),
                np.zeros((*size, 3), np.float32))
    step = 1 if width is None else -(-size[1] // width)
    # (shown at 1/step, the grid and the key are drawn at the size shown: drawn at full size and then sampled, a
    # 1280x720 frame's GIF kept every third grid line, its tiles looking three times their size, and its key's
    # 2-pixel letters lost one column in three, unreadable)
    picture = sdk.draw_rate_overlay(np.clip(np.nan_to_num(base), 0.0, 1.0), rates, tile, grid=step == 1,
                                    legend=step == 1, palette=palette)
    if step > 1:
        picture = np.array(picture[::step, ::step])
        shown = tile / step
        if tile >= 4 and shown >= 4:  # (as draw_rate_overlay: the first row and column shown of each tile darkened;
            # none where a tile is shown under 4 pixels, where the lines would darken the frame more than mark it)
            for axis, count in enumerate(rates.shape):
                lines = np.unique(-(-np.arange(count) * tile // step))
                lines = lines[lines < picture.shape[axis]]
                if axis == 0:
                    picture[lines] *= 0.75
                else:
                    picture[:, lines] *= 0.75
        # the key at the size shown: the overlay of one-pixel tiles all 1x1 (untinted) draws its legend alone
        picture = sdk.draw_rate_overlay(picture, np.full(picture.shape[:2], sdk.RATE_CODES["1x1"], np.uint8), 1,
                                        grid=False, legend=True, palette=palette)
    return np.round(np.clip(picture, 0.0, 1.0) * 255.0).astype(np.uint8)  # (a quarter of float32's memory)


def _picture_modules(sequence: bool) -> None:
    """Import what ``--out`` draws and encodes its pictures with: Pillow, and for a sequence's GIF and curves imageio
    and matplotlib (``rtp[capture]``). On the runtime install (numpy, onnxruntime, pyyaml: an engine's) a run without
    them predicted every frame, wrote a frame's rates.npy and predictions.npy (beside an earlier run's overlay.png)
    and then ended in a traceback; it is now refused before any work, in one line naming the extra (rtp.cli's
    policy for a missing install, exit 2). Without ``--out`` nothing of them is needed."""
    import importlib

    for name in ("PIL.Image", *(("imageio.v3", "matplotlib") if sequence else ())):
        importlib.import_module(name)


def _write_sequence_out(folder: str, rows: list[dict[str, Any]], rates: list[np.ndarray], values: list[np.ndarray],
                        overlays: list[np.ndarray], budget: bool = False, higher_is_better: bool = False,
                        title: str = "") -> list[str]:
    """``rates.npy`` (uint8 ``(N, th, tw)``), ``predictions.npy`` (float32 ``(N, 6, th, tw)``), ``frames.csv``
    (a row a frame), ``overlay.gif`` (the overlays at :data:`GIF_FPS`) and ``frames.png`` (the curves, ``title``
    above them; with ``budget``, the threshold each frame reached too)."""
    import csv
    import io

    import imageio.v3 as iio

    from rtp import sdk
    from rtp.evaluate.plots import sequence_curves

    # Everything is made before anything is written: the GIF's encoding or the curves' drawing failing (or a
    # Ctrl-C in them) after the arrays were written left this run's rates.npy beside the last run's pictures.
    gif = iio.imwrite("<bytes>", np.stack(overlays), extension=".gif", duration=1000 / GIF_FPS, loop=0)
    curves = sequence_curves(rows, thresholds=budget, higher_is_better=higher_is_better, title=title)
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(["frame", "work_saved", "changed", "predict_ms", "network", "threshold", *sdk.RATE_CODES])
    for r in rows:
        writer.writerow([r["frame"], f"{r['work_saved']:.6f}", "" if r["changed"] is None else f"{r['changed']:.6f}",
                         f"{r['predict_ms']:.3f}", f"{r['network']:.4f}" if "network" in r else "", f"{r['threshold']:.6g}",
                         *(r["rates"].get(k, 0) for k in sdk.RATE_CODES)])
    return _write_run(Path(folder), {"rates.npy": _npy(np.stack(rates)), "predictions.npy": _npy(np.stack(values)),
                                     "frames.csv": _bytes(text.getvalue().encode("utf-8")), "overlay.gif": _bytes(gif),
                                     "frames.png": _png(curves)})


def _holding(args: argparse.Namespace, threshold: float) -> str:
    """What a single frame's rates held: the threshold, or (``--saving``) the saving and the threshold reached."""
    if args.saving is None:
        return f"threshold {threshold:g}"
    if args.threshold is not None:
        return f"threshold {args.threshold:g} with a floor of {args.saving:g} saved, ran at threshold {threshold:.4g}"
    return f"a saving of {args.saving:g} (a budget), reached at threshold {threshold:.4g}"


def _write_out(folder: str, frame: dict[str, np.ndarray], values: np.ndarray, rates: np.ndarray,
               tile: int, palette: str = "paper") -> list[str]:
    """``rates.npy`` (uint8 codes), ``predictions.npy`` (float32 ``(6, th, tw)``, metric units) and
    ``overlay.png`` (the rates over the frame's ``colour``, else its albedo or previous frame)."""
    picture = _overlay(frame, rates, tile, palette=palette)  # (drawn before the arrays are written, as a sequence's pictures are)
    return _write_run(Path(folder), {"rates.npy": _npy(rates), "predictions.npy": _npy(values),
                                     "overlay.png": _png(picture)})


#: Every file ``--out`` writes, for a frame or a sequence.
_OUT_FILES = ("rates.npy", "predictions.npy", "overlay.png", "frames.csv", "overlay.gif", "frames.png")


def _npy(array: np.ndarray) -> Callable[[Path], None]:
    """What writes ``array`` as an ``.npy`` file to the path it is given."""
    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            np.save(f, array)
    return write


def _bytes(data: bytes) -> Callable[[Path], None]:
    """What writes ``data`` to the path it is given."""
    def write(tmp: Path) -> None:
        tmp.write_bytes(data)
    return write


def _png(image: np.ndarray) -> Callable[[Path], None]:
    """What writes ``image`` (uint8 RGB) as a PNG to the path it is given (a temporary file's name says no format)."""
    def write(tmp: Path) -> None:
        from PIL import Image

        Image.fromarray(np.ascontiguousarray(image, np.uint8)).save(tmp, format="PNG")
    return write


#: The temporary file of a write of one of :data:`_OUT_FILES` (``sdk.files.atomic_output``'s name for it).
_TEMPORARY = re.compile(r"\.(" + "|".join(re.escape(n) for n in _OUT_FILES) + r")\.[A-Za-z0-9_]{8}\.tmp")


def _write_run(out: Path, files: dict[str, Callable[[Path], None]]) -> list[str]:
    """Write one run's files into ``out`` (held by :func:`out_lock`; ``files``: each name and what writes its
    content to the path it is given) so that the folder never holds them beside another run's: all of them are
    written to their temporary files first; then the files of :data:`_OUT_FILES` there (an earlier run's, of this
    kind or the other) are removed and this run's renamed into place, ``rates.npy`` last. A failure, a Ctrl-C or a
    kill while they are written leaves the earlier run's files as they were; a kill in the moment of the renames
    leaves part of this run's, without ``rates.npy``, and none of another's (before, a kill between two files left
    this run's rates.npy beside the earlier run's predictions.npy, frames.csv and pictures, every file there). The
    temporary files a killed run left are removed. Returns the names written."""
    from rtp import sdk

    for p in out.iterdir():  # (no other rtp job writes here while the lock is held: none is a live write's)
        if _TEMPORARY.fullmatch(p.name) and p.is_file():
            p.unlink(missing_ok=True)
            log.info("%s: removed %s, the temporary file of a run that was killed", out, p.name)
    with contextlib.ExitStack() as stack:
        for name, write in files.items():  # (renamed in the reverse order: rates.npy, written first, last)
            write(stack.enter_context(sdk.files.atomic_output(out / name)))
        gone = [name for name in _OUT_FILES if (out / name).is_file()]
        for name in gone:
            (out / name).unlink(missing_ok=True)
        if any(name not in files for name in gone):
            log.info("%s: removed %s, of the run this one replaced", out,
                     ", ".join(name for name in gone if name not in files))
    return list(files)
