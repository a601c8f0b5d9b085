"""Motion vectors past any plausible move: how much of a dataset, or of a camera path, holds them.

    python bench/motion_outliers.py data/val720 data/test
    python bench/motion_outliers.py --play kaos,oa_dm3 --frames 300 --size 320x180

Until 2026-12-07 the reference renderer divided the previous clip position by ``max(w, 1e-6)``, so a
visible point that had been behind the previous camera got a motion of 1e7-1e8 pixels, where
``sdk.input_planes`` gives 0 (docs/renderer.md "Limitations"). Datasets captured before keep it in their
``motion`` buffer. For each dataset given, prints the samples, those holding a motion past ``--limit``
pixels, and the share of all pixels past it; with ``--play``, renders each map's slow and fast camera paths
(``rtp play``'s, seed 0) with the renderer installed now and counts the same on every frame (0 once the fix
is in: the check that no closed-loop figure read such values).
"""

from __future__ import annotations

import argparse

import numpy as np
from _common import dataset_folder, run_main  # bench/ is on sys.path when run as a script

from rtp.capture import DatasetReader


def _datasets(folders: list[str], limit: float) -> None:
    print("| dataset | samples | samples with motion past the limit | share of all pixels % |")
    print("|---|---:|---:|---:|")
    for root in folders:
        reader = DatasetReader(root)
        samples = pixels = total = 0
        for sid in reader.ids:
            m = np.abs(reader[sid].buffer("motion")).max(axis=-1)
            n = int((m > limit).sum())
            samples += n > 0
            pixels += n
            total += m.size
        print(f"| {root} | {len(reader.ids)} | {samples} | {100 * pixels / max(total, 1):.3f} |")


def _paths(maps: list[str], frames: int, size: tuple[int, int], limit: float) -> None:
    from rtp.capture import load_scene
    from rtp.capture.paths import camera_path
    from rtp.plugins.moderngl import Renderer

    print("| map | path | frames | frames with motion past the limit | pixels past it | largest motion (px) |")
    print("|---|---|---:|---:|---:|---:|")
    for name in maps:
        scene, blockers = load_scene(name, None, None, None)
        for profile in ("slow", "fast"):
            path = camera_path(scene, frames, profile, 0, blockers=blockers)
            bad_frames = bad_pixels = 0
            largest = 0.0
            with Renderer(*size) as renderer:
                renderer.load_scene(scene)
                prev = None
                for cam in path.cameras:
                    frame = renderer.render(cam, prev_camera=prev)
                    if prev is not None:
                        m = np.abs(np.asarray(frame.motion)).max(axis=-1)
                        n = int((m > limit).sum())
                        bad_frames += n > 0
                        bad_pixels += n
                        largest = max(largest, float(m.max()))
                    prev = cam
            print(f"| {name} | {profile} | {frames} | {bad_frames} | {bad_pixels} | {largest:.1f} |")


def main() -> int:
    from rtp.cli import frame_size, int_at_least

    def positive_float(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not np.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
        return value

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("data", nargs="*", type=dataset_folder, help="dataset folders to count in")
    p.add_argument("--play", default=None, metavar="MAPS", help="comma-separated maps whose camera paths to render")
    p.add_argument("--frames", type=int_at_least(2), default=300, help="frames a path (default 300)")
    p.add_argument("--size", type=frame_size, default=(320, 180), help="frame size WxH for --play (default 320x180)")
    p.add_argument("--limit", type=positive_float, default=1e4, help="pixels past which a motion counts (default 1e4)")
    args = p.parse_args()
    if not args.data and not args.play:
        p.error("give dataset folders, or --play MAPS")
    if args.data:
        _datasets(args.data, args.limit)
    if args.play:
        _paths([m.strip() for m in args.play.split(",") if m.strip()], args.frames, args.size, args.limit)
    return 0


if __name__ == "__main__":
    run_main(main)
