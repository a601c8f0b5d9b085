"""``rtp import``: a dataset from an engine's frames (G-buffers and the frame shaded at every rate), for
``rtp targets``, ``rtp train`` and ``rtp evaluate``; ``--write-example`` writes such frames from the
reference renderer, to see the layout."""

from __future__ import annotations

import argparse
import shlex
import sys

__all__ = ["run_import"]

#: ``--write-example``'s options and their values when not given (refused without it; ``cache_dir`` None: the
#: default scene cache, ``rtp.capture.scenes.default_cache_dir()``).
EXAMPLE_OPTIONS = {"count": 8, "size": (640, 360), "seed": 0, "example_scene": "procedural:0", "cache_dir": None}
#: The options of an import, with the value each has when not given (refused with ``--write-example``, which writes
#: frames in the default conventions and imports nothing; ``--tolerance``'s: sdk.DEFAULT_REPROJECTION_TOLERANCE).
IMPORT_OPTIONS = {"out": None, "scene": None, "profile": "engine", "albedo_linear": False, "normal_space": "view",
                  "depth_kind": "linear"}


def run_import(args: argparse.Namespace) -> int:
    from rtp import sdk
    from rtp.capture import import_frames

    from ._predict import example_options, write_sequence
    from ._run import Bar

    example_options(args, "import", EXAMPLE_OPTIONS,
                    {**IMPORT_OPTIONS, "tolerance": sdk.DEFAULT_REPROJECTION_TOLERANCE})
    if args.write_example:
        if len(args.frames) != 1:
            raise sdk.ParameterError(f"--write-example writes one folder; got {len(args.frames)} paths", "frames")
        w, h = args.size
        with Bar(args, args.count, "write frames", "frame") as bar:
            written = write_sequence(args.frames[0], args.size, args.seed, args.count, bar.update_to, rates=True,
                                     scene_name=args.example_scene, cache_dir=args.cache_dir)
        print(f"wrote {len(written)} frames of {w}x{h} along a camera path through {args.example_scene}, each with its "
              f"G-buffers and the frame shaded at every rate ({', '.join(sdk.ALL_RATES)}), in {args.frames[0]}: "
              f"{written[0]} ... {written[-1]}")
        return 0
    if args.out is None:
        raise sdk.ParameterError("--out DATA: the dataset folder to write (or --write-example to write example frames)",
                                 "out")
    files = sdk.files.frame_files(args.frames, example="rtp import FRAMES --write-example --frames 8")
    with Bar(args, len(files), "import", "frame") as bar:
        args.on_interrupt = lambda: (f"{bar.done} of {len(files)} frames are in {args.out} (each written whole): the "
                                     f"same command imports the rest")
        report = import_frames(files, args.out, scene=args.scene, profile=args.profile, albedo_linear=args.albedo_linear,
                               normal_space=args.normal_space, depth_kind=args.depth_kind, tolerance=args.tolerance,
                               progress=bar.update_to)
    unseen = sum(report.unseen) / len(report.unseen) if report.unseen else None
    print(f"{args.out}: {report.written} frames imported"
          + (f" ({report.replaced} of them dumped again since their import: their samples replaced)"
             if report.replaced else "") + f", {report.skipped} already there"
          + (f"; unseen share of the new frames' geometry {100 * unseen:.1f}%" if unseen is not None else ""))
    if report.absent:
        print(f"absent: {', '.join(report.absent)} (not in the frames: a model reading them is refused)")
    if report.warnings:
        print(f"convention warnings on {max(report.warnings.values())} of {report.written} frames (logged above): "
              f"check --albedo-linear, --normal-space and --depth-kind, and the dump itself (each warning says what "
              f"it saw and what converts it: motion's units, colour read back before its sRGB conversion)",
              file=sys.stderr)
    if report.exchanged:
        print(f"rate images look exchanged on {report.exchanged} of {report.written} frames (logged above): check "
              f"which is final_1x2 (1 pixel wide, 2 tall) and which final_2x1 (and final_2x4, final_4x2)",
              file=sys.stderr)
    out = shlex.quote(args.out)  # (a folder with a space: the commands, copied into a shell, failed)
    print(f"next: rtp targets {out}, then rtp train --data {out} --metric jnyang --out model.pt (validation "
          f"holds out whole levels: import two or more, and name one with --val-scenes)")
    return 0
