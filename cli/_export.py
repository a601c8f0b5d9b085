"""``rtp-export``: bake a trained checkpoint into an ONNX model with its metadata, or adopt a foreign
ONNX model with a metadata sidecar. Same options, output and exit codes as ``rtp`` (:mod:`._run`)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from ._main import _in_file, _out_file, _path_text
from ._run import Formatter, Parser, add_common, carries_metadata, interruptible_start, option_flags, run

__all__ = ["build_export_parser", "export_main"]

EXAMPLES = """examples:
  rtp-export model.pt -o jnyang.onnx
  rtp-export --adopt JNYang.onnx -o jnyang-paper.onnx        # a published model: no sidecar needed
  rtp-export --adopt Model.onnx --metadata sidecar.yaml -o adopted.onnx --dynamic
  rtp-export --restamp old.onnx
  rtp-export --strip-probe jnyang -o jnyang-engine.onnx     # for an engine that runs the file itself
  rtp-export --join-planes jnyang -o jnyang-one-input.onnx  # every plane in one input tensor
  rtp-export --retune jnyang --metadata factors.yaml -o jnyang-tuned.onnx   # thresholds per rate
"""


def build_export_parser() -> argparse.ArgumentParser:
    from rtp.export import DEFAULT_OPSET

    p = Parser(
        prog="rtp-export", formatter_class=Formatter, epilog=EXAMPLES,
        description="Bake a trained rtp checkpoint into an ONNX model with embedded metadata, or adopt a "
        "foreign ONNX model by baking a metadata sidecar into it.",
    )
    add_common(p, top=True)
    p.add_argument("checkpoint", nargs="?", type=_in_file, help="checkpoint written by `rtp train` (model.pt)")
    p.add_argument("-o", "--output", type=_out_file, help="output .onnx path (default: the checkpoint path with .onnx)")
    p.add_argument("--opset", type=int, default=None, help=f"ONNX opset of a checkpoint's export (default: {DEFAULT_OPSET})")
    p.add_argument("--metadata", metavar="SIDECAR.yaml", type=_in_file,
                   help="metadata fields: merged over the checkpoint's (not what the network was trained for, nor "
                   "what the export computes: input_multiple, finite_probe, tail, schema_version, digest), or the "
                   "whole sidecar with --adopt (default with --adopt: rtp's sidecar for a recognised published model)")
    p.add_argument("--adopt", metavar="FOREIGN.onnx", type=_in_file, help="bake --metadata into this ONNX model instead; the "
                   "paper's six published models are recognised by their SHA-256 and need no --metadata")
    p.add_argument("--dynamic", action="store_true", help="with --adopt: make batch, height and width symbolic")
    p.add_argument("--replace", action="store_true", help="with --adopt: overwrite metadata the model already has")
    p.add_argument("--restamp", metavar="MODEL.onnx", type=_in_file, help="bring an rtp model exported by an older rtp up to "
                   "this one's format: the digest of graph and weights, the finite probe where its first "
                   "layer allows one, and the input planes in today's groups (in place; predictions checked "
                   "unchanged)")
    p.add_argument("--no-finite-probe", action="store_true", help="export a checkpoint without the finite probe "
                   "output (docs/export.md): for an engine that runs the file with its own onnxruntime session")
    p.add_argument("--one-input", action="store_true", help="export a checkpoint with every input plane in the one "
                   "input `input`, not in groups of at most seven (docs/export.md \"Input planes in groups\")")
    p.add_argument("--strip-probe", metavar="MODEL", type=_path_text,
                   help="write a copy of an rtp model (a path or a shipped model's "
                   "name) without its finite probe to -o OUTPUT.onnx (predictions unchanged)")
    p.add_argument("--join-planes", metavar="MODEL", type=_path_text,
                   help="write a copy of an rtp model (a path or a shipped model's "
                   "name) whose planes come in groups with every plane in the one input `input` to -o OUTPUT.onnx "
                   "(predictions unchanged but for float rounding; docs/export.md \"Input planes in groups\")")
    p.add_argument("--retune", metavar="MODEL", type=_path_text,
                   help="write a copy of an rtp model (a path or a shipped model's name) "
                   "to -o OUTPUT.onnx whose decision fields (default_threshold, rate_factors, description) are those "
                   "of --metadata SIDECAR.yaml (predictions unchanged; e.g. the factors `python bench/per_rate.py "
                   "--sidecar` fits on validation data, docs/export.md)")
    return p


def _check(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Every combination is checked before any work starts."""
    if args.restamp:
        if (args.checkpoint or args.adopt or args.metadata or args.output or args.opset is not None or args.dynamic
                or args.replace or args.no_finite_probe or args.one_input or args.strip_probe or args.join_planes
                or args.retune):
            parser.error("--restamp MODEL.onnx takes no other options")
        return
    if args.retune:
        if (args.checkpoint or args.adopt or args.opset is not None or args.dynamic or args.replace or args.no_finite_probe
                or args.one_input or args.strip_probe or args.join_planes):
            parser.error("--retune MODEL takes only --metadata SIDECAR.yaml and -o OUTPUT.onnx")
        if not args.metadata or not args.output:
            parser.error("--retune needs --metadata SIDECAR.yaml (the decision fields) and -o OUTPUT.onnx")
        return
    for flag, given in (("--strip-probe", args.strip_probe), ("--join-planes", args.join_planes)):
        if not given:
            continue
        if (args.checkpoint or args.adopt or args.metadata or args.opset is not None or args.dynamic or args.replace
                or args.no_finite_probe or args.one_input or (args.strip_probe and args.join_planes)):
            parser.error(f"{flag} MODEL takes only -o OUTPUT.onnx")
        if not args.output:
            parser.error(f"{flag} needs -o OUTPUT.onnx")
        return
    if args.no_finite_probe and not args.checkpoint:
        parser.error("--no-finite-probe applies to exporting a checkpoint")
    if args.one_input and not args.checkpoint:
        parser.error("--one-input applies to exporting a checkpoint")
    if args.adopt:
        if args.checkpoint:
            parser.error("give either a checkpoint or --adopt FOREIGN.onnx, not both")
        if not args.output:
            parser.error("--adopt needs -o OUTPUT.onnx")
        if args.opset is not None:
            parser.error("--opset applies to exporting a checkpoint; an adopted model keeps its own opset")
    elif not args.checkpoint:
        parser.error("a checkpoint path is required (or --adopt FOREIGN.onnx)")
    elif args.dynamic or args.replace:
        parser.error("--dynamic and --replace apply to --adopt only")


def _body(args: argparse.Namespace) -> int:
    from rtp.export import (
        DEFAULT_OPSET,
        adopt,
        export_checkpoint,
        join_input_planes,
        restamp,
        retune,
        strip_finite_probe,
    )

    if args.restamp:
        out = restamp(args.restamp)
    elif args.retune:
        out = retune(args.retune, args.metadata, args.output)
    elif args.strip_probe:
        out = strip_finite_probe(args.strip_probe, args.output)
    elif args.join_planes:
        out = join_input_planes(args.join_planes, args.output)
    elif args.adopt:
        from pathlib import Path

        from rtp import sdk
        from rtp.export import identify

        # (in the command line's words, for an ONNX model only: a checkpoint or a damaged file was told to bring a
        # sidecar, and with one it was no ONNX model after all; adopt says that first)
        if args.metadata is None and Path(args.adopt).is_file() and _reads_as_onnx(args.adopt) \
                and identify(args.adopt) is None and not carries_metadata(args.adopt):
            raise sdk.MetadataError(
                f"{args.adopt} is not one of the paper's published models rtp recognises: pass its sidecar with "
                "--metadata SIDECAR.yaml (docs/export.md)")
        out = adopt(args.adopt, args.metadata, args.output, dynamic=args.dynamic, replace=args.replace)
    else:
        out = export_checkpoint(args.checkpoint, args.output, opset=DEFAULT_OPSET if args.opset is None else args.opset,
                                extra_metadata=args.metadata, finite_probe=not args.no_finite_probe,
                                split_planes=not args.one_input)
    print(out)
    return 0



def _reads_as_onnx(path: str) -> bool:
    """Whether onnx reads ``path`` as a model (what :func:`rtp.export.adopt` refuses first where it does not)."""
    import onnx

    try:
        onnx.load(path, load_external_data=False)
    except Exception:  # onnx raises DecodeError and friends
        return False
    return True


def export_main(argv: Sequence[str] | None = None) -> int:
    return interruptible_start("rtp-export", lambda: _export_main(argv))


def _export_main(argv: Sequence[str] | None) -> int:
    parser = build_export_parser()
    args = parser.parse_args(argv)
    _check(parser, args)
    return run("rtp-export", args, _body, option_flags(parser))
