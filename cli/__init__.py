"""The command line: ``rtp`` and ``rtp-export``. Each command imports what it needs only when it runs,
so ``rtp info`` works with the runtime dependencies alone; all share one set of common options and one
error policy (exit codes in docs/errors.md)."""

from ._export import build_export_parser, export_main
from ._main import (
           ANIMATION_EXTENSIONS,
           MAX_SIDE,
           build_parser,
           frame_size,
           int_at_least,
           main,
           out_animation,
           out_image,
)
from ._run import run_guarded

__all__ = ["ANIMATION_EXTENSIONS", "MAX_SIDE", "build_export_parser", "build_parser", "export_main", "frame_size",
           "int_at_least", "main", "out_animation", "out_image", "run_guarded"]
