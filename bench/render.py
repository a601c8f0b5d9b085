"""Benchmark the reference renderer: frames per second at 640x360 and 1280x720.

    .venv/bin/python bench/render.py [--frames 5] [--sizes 640x360,1280x720]

Renders a seeded procedural-like room (textured floor and walls, columns, boxes, spheres, metal
and rough materials, a sun and 4 point lights). Every frame produces the full output: G-buffers,
all 7 shading rates (software VRS, tone mapping, FXAA), and the reprojection of the previous
frame, all read back to numpy. A second pass with ``profile=True`` (the GPU is drained after
every stage) prints where the time goes. Prints a markdown table.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np
from _common import frame_sizes, positive, run_main  # bench/ is on sys.path when run as a script

from rtp.plugins.moderngl import Renderer
from rtp.scene import Camera, Material, PointLight, Scene, SunLight, box_mesh, checker_texture, quad_mesh, sphere_mesh


def _noise_texture(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """Tileable value noise over a base colour, as uint8 sRGB RGBA."""
    base = rng.uniform(0.3, 0.9, 3)
    acc = np.zeros((size, size))
    for octave in range(1, 6):
        n = 2**octave
        g = rng.uniform(-1, 1, (n, n))
        idx = np.arange(size) * n // size
        if size % n == 0:
            acc += np.kron(g, np.ones((size // n, size // n)))[:size, :size] / octave
        else:
            acc += g[np.ix_(idx, idx)] / octave
    img = np.clip(base[None, None, :] * (0.75 + 0.25 * acc[..., None]), 0, 1)
    out = np.empty((size, size, 4), np.uint8)
    out[..., :3] = (img * 255).astype(np.uint8)
    out[..., 3] = 255
    return out


def build_scene(seed: int = 0) -> Scene:
    """A 20 m x 20 m room, open to the sky, with columns, boxes and spheres."""
    rng = np.random.default_rng(seed)
    materials = [
        Material("floor", texture=checker_texture(256, 16, (200, 190, 170), (90, 80, 70)), roughness=0.6),
        Material("wall", texture=_noise_texture(rng), roughness=0.85),
        Material("column", texture=_noise_texture(rng), roughness=0.5, specular=0.6),
        Material("metal", base_color=(0.95, 0.8, 0.5, 1.0), metallic=1.0, roughness=0.3),
        Material("plastic", base_color=(0.2, 0.4, 0.8, 1.0), roughness=0.25),
        Material("lamp", base_color=(0.1, 0.1, 0.1, 1.0), emissive=(6.0, 5.0, 3.0)),
    ]
    meshes = [quad_mesh((0, 0, 0), (10, 0, 0), (0, 0, -10), 0, (10, 10))]
    for lo, hi in [((-10, 0, -10.5), (10, 5, -10)), ((-10.5, 0, -10), (-10, 5, 10)), ((10, 0, -10), (10.5, 5, 10))]:
        meshes.append(box_mesh(lo, hi, 1, uv_per_metre=0.25))
    for x in (-6, -2, 2, 6):
        for z in (-7, -1):
            meshes.append(box_mesh((x - 0.3, 0, z - 0.3), (x + 0.3, 4, z + 0.3), 2, uv_per_metre=0.5))
    for _ in range(12):
        c = rng.uniform([-8, 0, -9], [8, 0, 4])
        s = rng.uniform(0.3, 1.0, 3)
        meshes.append(box_mesh(c - [s[0], 0, s[2]], c + [s[0], 2 * s[1], s[2]], int(rng.integers(1, 5))))
    for _ in range(6):
        c = rng.uniform([-8, 0.5, -9], [8, 1.5, 4])
        meshes.append(sphere_mesh(c, float(c[1]), int(rng.choice([3, 4])), segments=48, rings=24))
    lights = []
    for x in (-5, 5):
        for z in (-5, 2):
            meshes.append(sphere_mesh((x, 3.5, z), 0.15, 5, segments=12, rings=6))
            lights.append(PointLight((x, 3.3, z), colour=(1.0, 0.85, 0.6), intensity=8.0, radius=8.0))
    return Scene("bench-room", meshes, materials, sun=SunLight(direction=(-0.5, -1.0, -0.35)), point_lights=lights,
                 spawn_points=[])


def bench(width: int, height: int, frames: int, scene: Scene) -> tuple[float, dict[str, float]]:
    cams = [Camera((-1.0 + 0.1 * i, 1.7, 8.0 - 0.05 * i), yaw=-8.0 + 1.5 * i, pitch=-6.0) for i in range(frames + 2)]
    with Renderer(width, height) as r:
        r.load_scene(scene)
        prev = r.render(cams[0])  # compiles the shaders
        prev = r.render(cams[1], prev)
        times = []
        for cam in cams[2:]:
            t0 = time.perf_counter()
            prev = r.render(cam, prev)
            times.append(time.perf_counter() - t0)
    with Renderer(width, height, profile=True) as r:
        r.load_scene(scene)
        prev = r.render(cams[0])
        prev = r.render(cams[1], prev)
        stages: dict[str, list[float]] = {}
        for cam in cams[2:]:
            prev = r.render(cam, prev)
            for k, v in prev.timings.items():
                stages.setdefault(k, []).append(v)
    return statistics.median(times), {k: statistics.median(v) for k, v in stages.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=positive, default=5, help="frames timed per size (default: 5)")
    ap.add_argument("--sizes", type=frame_sizes(16), default="640x360,1280x720",
                    help="comma-separated WIDTHxHEIGHT (default: 640x360,1280x720)")
    args = ap.parse_args()
    scene = build_scene()
    with Renderer(16, 16) as probe:
        gl = probe.ctx.info["GL_RENDERER"]
    print(f"scene {scene.name}: {scene.triangle_count} triangles, {len(scene.meshes)} meshes, "
          f"{len(scene.point_lights)} point lights; {gl}; {platform.processor() or platform.machine()}")
    print(f"median of {args.frames} frames; each frame = G-buffers + 7 rates + reprojection, read back to numpy\n")
    rows = []
    for w, h in args.sizes:
        t, stages = bench(w, h, args.frames, scene)
        rows.append((f"{w}x{h}", t, stages))
    print("| size | ms/frame | frames/s |")
    print("|---|---|---|")
    for size, t, _ in rows:
        print(f"| {size} | {t * 1e3:.0f} | {1 / t:.2f} |")
    names = [k for k in rows[0][2] if k != "total"]
    print("\nper stage with profile=True (ms, GPU drained after each stage):\n")
    print("| size | " + " | ".join(names) + " | total |")
    print("|---" * (len(names) + 2) + "|")
    for size, _, st in rows:
        print(f"| {size} | " + " | ".join(f"{st[k] * 1e3:.0f}" for k in names) + f" | {st['total'] * 1e3:.0f} |")


if __name__ == "__main__":
    run_main(main)
