"""Camera paths of the closed-loop benchmark on real maps: length and unseen share per frame.

    python bench/paths.py [--maps 20kdm2,oa_dm5] [--frames 300] [--size 640x360] [--seed 0]

For each map (default: the test split of scenes.yaml, from the cache of `rtp scenes fetch`) and path
profile (slow, fast), makes the seeded 60 Hz path of `rtp.capture.paths.camera_path`, renders it with
the reference renderer and prints the share of each frame's pixels the previous frame did not show
(mean, 95th percentile, max; the first frame excluded). For comparison, the paper's datasets left 14%
(slow) and 31% (fast) of the pixels unseen between the two frames of a training pair.
"""

from __future__ import annotations

import argparse
import logging

import numpy as np
from _common import count, frame_size, positive, run_main  # bench/ is on sys.path when run as a script

from rtp.capture import load_scene
from rtp.capture.paths import PATH_PROFILES, camera_path, unseen_shares
from rtp.capture.scenes import load_splits


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", default=None, help="comma-separated maps of scenes.yaml, fetched by `rtp scenes fetch` "
                    "(default: the test split)")
    ap.add_argument("--frames", type=positive, default=300, help="frames of each path at 60 Hz (default: 300)")
    ap.add_argument("--size", type=lambda s: frame_size(s, 16), default=(640, 360), help="WIDTHxHEIGHT (default 640x360)")
    ap.add_argument("--seed", type=count, default=0, help="which path through each map (default: 0)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    w, h = args.size
    maps = args.maps.split(",") if args.maps else load_splits()["test"]
    print(f"{args.frames} frames at 60 Hz, {w}x{h}, seed {args.seed}\n")
    print("| map | path | length (m) | eye (m) | unseen per frame: mean % | p95 % | max % |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name in maps:
        scene, blockers = load_scene(name, None, None, None)
        for profile in PATH_PROFILES:
            path = camera_path(scene, args.frames, profile, args.seed, blockers=blockers)
            u = unseen_shares(path, scene, (w, h))[1:]
            print(f"| {name} | {profile} | {path.length():.1f} | {path.eye_height:.2f} | {100 * u.mean():.2f} | "
                  f"{100 * np.percentile(u, 95):.2f} | {100 * u.max():.2f} |", flush=True)


if __name__ == "__main__":
    run_main(main)
