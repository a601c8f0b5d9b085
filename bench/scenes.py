"""Scene sources benchmark: converts maps of scenes.yaml, loads them from the cache, samples
viewpoints, and prints a markdown table (the numbers in docs/scenes.md come from this script).

    python bench/scenes.py --maps 20kdm2,oa_dm5,oacmpctf3,oa_dm1 --views 20

"to the first pair s" is the free space (the voxels and their flood) and the first pair; "ms a pair"
the time between the first pair and the last, per pair: what ``rtp capture`` spends planning each
sample before its scene renders.

Needs the cache filled by ``rtp scenes fetch`` (``rtp.capture.scenes.fetch``).
"""

from __future__ import annotations

import argparse
import logging
import platform
import time
from pathlib import Path

from _common import count, run_main  # bench/ is on sys.path when run as a script

from rtp.capture.scenes import default_cache_dir, load_splits, procedural
from rtp.capture.scenes._cache import load_scene_npz, save_scene_npz
from rtp.capture.scenes._fetch import _cache_path, _check_listed, convert_from_cache, fetch
from rtp.capture.viewpoints import sample_viewpoints


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cache-dir", default=default_cache_dir(),
                    help="the scene cache `rtp scenes fetch` fills (default: $RTP_SCENE_CACHE, else ~/.cache/rtp/scenes)")
    ap.add_argument("--maps", default="20kdm2,oa_dm5,oacmpctf3,oa_dm1,oacmpdm5,kaos")
    ap.add_argument("--views", type=count, default=20, help="viewpoint pairs sampled per map (0: skip)")
    ap.add_argument("--seed", type=count, default=0)
    ap.add_argument("--fetch", action="store_true", help="run fetch first (downloads with apt-get if needed)")
    ap.add_argument("--unseen", type=count, default=0, metavar="N",
                    help="render N pairs per scene and profile with the moderngl renderer (320x180) and "
                    "report the unseen-pixel fraction 1 - mean(seen) (the motion-profile calibration)")
    ap.add_argument("--unseen-seed", type=count, default=11)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    maps = [m.strip() for m in args.maps.split(",") if m.strip()]
    if not maps:
        ap.error(f"--maps: expected comma-separated map names, got {args.maps!r}")
    for name in maps:  # (an unlisted map was refused after converting the maps named before it: minutes)
        _check_listed(name, None, None)
    if args.fetch:
        fetch(args.cache_dir, maps, progress=False)

    rows = []
    t0 = time.perf_counter()
    s = procedural(args.seed)
    t_gen = time.perf_counter() - t0
    rows.append(("procedural(0)", "-", s, t_gen, float("nan"), 0, None))
    for name in maps:
        _check_listed(name, None, None)
        split = next(k for k, v in load_splits().items() if name in v)
        t0 = time.perf_counter()
        conv = convert_from_cache(name, args.cache_dir)
        t_conv = time.perf_counter() - t0
        path = _cache_path(name, Path(args.cache_dir))
        save_scene_npz(path, conv.scene, conv.sky_triangles, conv.stats)
        t0 = time.perf_counter()
        scene, sky, _ = load_scene_npz(path)
        t_load = time.perf_counter() - t0
        rows.append((name, split, scene, t_conv, t_load, len(conv.missing_textures), sky))

    print(f"# scenes benchmark ({platform.processor() or platform.machine()}, python {platform.python_version()})")
    print()
    hdr = "| scene | split | triangles | materials | no image | spawns | lights | convert s | cached load s |"
    if args.views:
        hdr += f" {args.views} views s (slow) | to the first pair s | ms a pair | draws | voxel m |"
    print(hdr)
    print("|" + "---|" * (hdr.count("|") - 1))
    for name, split, scene, t_conv, t_load, missing, sky in rows:
        line = (f"| {name} | {split} | {scene.triangle_count:,} | {len(scene.materials)} | {missing} | "
                f"{len(scene.spawn_points)} | {len(scene.point_lights)} | {t_conv:.2f} | "
                + ("-" if t_load != t_load else f"{t_load:.3f}") + " |")
        if args.views:
            st: dict = {}
            found: list[float] = []  # when each pair was found
            t0 = time.perf_counter()
            sample_viewpoints(scene, args.views, args.seed, "slow", blockers=sky, stats=st,
                              progress=lambda _, found=found: found.append(time.perf_counter()))
            t_vp = time.perf_counter() - t0
            t_space = found[0] - t0  # the voxels and their flood, and the first pair
            pair_ms = f"{1000 * (found[-1] - found[0]) / (len(found) - 1):.1f}" if len(found) > 1 else "-"
            line += f" {t_vp:.2f} | {t_space:.2f} | {pair_ms} | {st['draws']} | {st['voxel']:.3f} |"
        print(line, flush=True)
    if args.unseen:
        unseen(rows, args.unseen, args.unseen_seed)
    return 0


def unseen(rows, n: int, seed: int) -> None:
    """Unseen fraction of the reference renderer per scene and motion profile."""
    import numpy as np

    from rtp.plugins.moderngl import Renderer

    print()
    print(f"| scene | slow unseen mean | slow median | fast unseen mean | fast median |  ({n} pairs each, 320x180)")
    print("|---|---|---|---|---|")
    total: dict[str, list[float]] = {"slow": [], "fast": []}
    with Renderer(320, 180, shadow_map_size=512, ao_samples=4) as r:
        for name, _, scene, _, _, _, sky in rows:
            r.load_scene(scene)
            cells = []
            for prof in ("slow", "fast"):
                u = []
                for prev, cam in sample_viewpoints(scene, n, seed, prof, blockers=sky):
                    f0 = r.render(prev)
                    u.append(1.0 - float(r.render(cam, f0).seen.mean()))
                total[prof] += u
                cells += [f"{np.mean(u):.3f}", f"{np.median(u):.3f}"]
            print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    print("| all | " + " | ".join(f"{f(total[p]):.3f}" for p in ("slow", "fast") for f in (np.mean, np.median))
          + " |")


if __name__ == "__main__":
    run_main(main)
