"""Camera paths of the closed-loop benchmark on real maps: length and unseen share per frame.

    python bench/paths.py [--maps 20kdm2,oa_dm5] [--frames 300] [--size 640x360] [--seed 0]

For each map (default: the test split of scenes.yaml, from the cache of `rtp scenes fetch`) and path
profile (slow, fast), makes the seeded 60 Hz path of `rtp.capture.paths.camera_path`, renders it with
the reference renderer and prints the share of each frame's pixels the previous frame did not show
(mean, 95th percentile, max; the first frame excluded, so a path needs 2 frames or more). For comparison,
the paper's datasets left 14% (slow) and 31% (fast) of the pixels unseen between the two frames of a training
pair. A map not listed or not fetched is refused before the table; a progress bar (stderr) counts the frames
rendered.
"""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Any

import numpy as np
from _common import count, frame_size, run_main  # bench/ is on sys.path when run as a script

from rtp.capture import check_scene, load_scene
from rtp.capture.paths import MAX_FRAMES, PATH_PROFILES, camera_path, unseen_shares
from rtp.capture.scenes import load_splits

try:  # (without the extra, `python bench/NAME.py --help` too says in one line what to install)
    from tqdm import tqdm
except ImportError as err:
    from _common import missing_extra

    missing_extra(err)


def path_frames(text: str) -> int:
    """An argparse type: frames of a path, 2 (the first has no previous frame to be unseen in) to MAX_FRAMES."""
    from rtp.cli import int_at_least

    n = int_at_least(2)(text)
    if n > MAX_FRAMES:
        raise argparse.ArgumentTypeError(f"expected at most {MAX_FRAMES} (ten minutes at 60 frames a second), got {n}")
    return n


class _Counted:
    """A renderer that ticks ``bar`` once a frame it renders (``unseen_shares`` renders every frame of a path)."""

    def __init__(self, renderer: Any, bar: tqdm) -> None:
        self.renderer, self.bar = renderer, bar

    def render(self, *args: Any, **kwargs: Any) -> Any:
        frame = self.renderer.render(*args, **kwargs)
        self.bar.update()
        return frame


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", default=None, help="comma-separated maps of scenes.yaml, fetched by `rtp scenes fetch` "
                    "(default: the test split)")
    ap.add_argument("--frames", type=path_frames, default=300, help="frames of each path at 60 Hz, 2 or more "
                    "(default: 300)")
    ap.add_argument("--size", type=lambda s: frame_size(s, 16), default=(640, 360), help="WIDTHxHEIGHT (default 640x360)")
    ap.add_argument("--seed", type=count, default=0, help="which path through each map (default: 0)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    w, h = args.size
    maps = [m.strip() for m in args.maps.split(",") if m.strip()] if args.maps is not None else load_splits()["test"]
    if not maps:
        ap.error(f"--maps: expected comma-separated map names, got {args.maps!r}")
    for name in maps:  # (a map not listed or not fetched: refused before the table, not after the maps before it)
        check_scene(name, None, None, None)
    from rtp.plugins.moderngl import Renderer

    print(f"{args.frames} frames at 60 Hz, {w}x{h}, seed {args.seed}\n")
    print("| map | path | length (m) | eye (m) | unseen per frame: mean % | p95 % | max % |")
    print("|---|---|---:|---:|---:|---:|---:|", flush=True)
    with tqdm(total=len(maps) * len(PATH_PROFILES) * args.frames, desc="rendering", unit="frame", file=sys.stderr) as bar:
        for name in maps:
            bar.set_postfix_str(name)
            scene, blockers = load_scene(name, None, None, None)
            for profile in PATH_PROFILES:
                path = camera_path(scene, args.frames, profile, args.seed, blockers=blockers)
                renderer = Renderer(w, h)  # (one a path, as unseen_shares makes its own)
                try:
                    renderer.load_scene(scene)
                    u = unseen_shares(path, scene, (w, h), renderer=_Counted(renderer, bar))[1:]
                finally:
                    renderer.release()
                tqdm.write(f"| {name} | {profile} | {path.length():.1f} | {path.eye_height:.2f} | {100 * u.mean():.2f} | "
                           f"{100 * np.percentile(u, 95):.2f} | {100 * u.max():.2f} |", file=sys.stdout)
                sys.stdout.flush()


if __name__ == "__main__":
    run_main(main)
