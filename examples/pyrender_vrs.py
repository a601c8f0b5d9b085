"""Variable-rate shading for a pyrender scene: a camera move, a model, the rate overlay.

    python examples/pyrender_vrs.py                       # procedural level -> GLB, the shipped JNYang model
    python examples/pyrender_vrs.py --scene level.glb --model flip --out vrs.png   # your level, another model
    python examples/pyrender_vrs.py --model jnyang-reuse --frames 24 --every 4 --gif vrs.gif   # a frame loop
    python examples/pyrender_vrs.py --frames 24 --moving --gif vrs.gif   # and an object that moves
    python examples/pyrender_vrs.py --model jnyang-8px    # AMD's and Intel's 8-pixel VRS tiles, the model trained on them
    python examples/pyrender_vrs.py --tile-size 8         # the same tiles, each taking its 16-pixel tile's rates

Headless: pyrender draws through EGL (``PYOPENGL_PLATFORM=egl``, the default here) or OSMesa.

1. The scene: ``--scene`` loads any glTF/GLB (or OBJ) through trimesh; without it a seeded
   procedural level is written to a GLB with trimesh first, then loaded back the same way.
2. The camera: the scene's first camera if it has one, else one at the level's first spawn point
   (or looking at the scene's centre); the second frame moves it 0.2 m and turns it 4 degrees.
3. pyrender draws both frames (its own lit colour image; the previous one is what the user saw),
   on the adapter's renderer: pyrender binds a scene to one renderer's GL context.
4. The adapter builds the model's inputs for the second frame from the scene, the two poses and
   the first frame; ``predictor.shading_rates`` picks a rate per tile; the overlay is saved.

``--frames N`` (more than 2) keeps the camera moving the same way for N frames, as a frame loop in
an engine: ``sdk.PredictionReuse`` runs the network every ``--every``-th frame, and in between
carries its per-tile estimates (or, for a model that splits such as ``jnyang-reuse``, its trunk's
features, running only the tail) along the surfaces, fetching each pixel from where the adapter's
motion vectors say it was (docs/runtime.md). Each frame's line says whether the network ran and
what choosing the rates cost; ``--gif`` writes the overlays as an animation (imageio). ``--moving``
slides a box across the view as the camera walks, and gives the adapter its previous pose every frame
(``SceneFrame.prev_node_poses``): its pixels are fetched from where the box was, and carried
estimates follow it.

``--model`` is a shipped model's name (``sdk.shipped_models()``: jnyang by default, flip, jnflip,
lpips, psnr, jnyang-reuse, and the models for 8-pixel tiles jnyang-8px, flip-8px, psnr-8px, jnflip-8px)
or the path of any rtp ONNX model. The pyrender adapter produces every
input plane the shipped models read (luma, RGB, material parameters, the ``.blocks`` and ``.tiles``
planes: docs/adapters.md).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")  # before anything imports PyOpenGL

import numpy as np

from rtp import sdk
from rtp.capture import check_memory, save_image
from rtp.cli import frame_size, out_animation, out_image, run_guarded  # as rtp's commands take them; its error policy
from rtp.plugins.pyrender import Adapter, SceneFrame, import_pyrender, to_trimesh_scene
from rtp.sdk.files import atomic_output

log = logging.getLogger("pyrender_vrs")

#: This example's peak memory, measured (``python bench/job_memory.py --jobs examples``, 2026-12-04, on
#: Mesa's EGL: a hardware driver keeps the renderer's images on the GPU): bytes at any size, bytes a
#: pixel of ``--size`` (a frame loop's, the larger), and bytes a pixel for each frame of ``--gif`` (its
#: overlays, kept until the GIF is written).
PEAK_BASE, PEAK_PER_PIXEL, PEAK_PER_GIF_PIXEL = 280 * 2**20, 530.0, 6.0


def peak_bytes(width: int, height: int, frames: int, gif: bool) -> int:
    """The peak bytes of a run at ``width`` x ``height`` with ``frames`` frames (``gif``: written as a GIF)."""
    return int(PEAK_BASE + width * height * (PEAK_PER_PIXEL + (frames * PEAK_PER_GIF_PIXEL if gif else 0.0)))


def write_procedural_glb(path: Path, seed: int) -> tuple[Path, Any]:
    """A procedural level written as GLB with trimesh; returns the path and the level's spawn point."""
    from rtp.capture.scenes import procedural

    level = procedural(seed, rooms=(2, 2), texture_size=128)
    to_trimesh_scene(level).export(str(path))
    return path, level.spawn_points[0] if level.spawn_points else None


def load_scene(path: Path) -> Any:
    """A ``pyrender.Scene`` from a glTF/GLB/OBJ file, through trimesh."""
    import trimesh

    pyrender = import_pyrender()
    try:
        tm = trimesh.load(str(path), force="scene", process=False)
    except Exception as err:  # trimesh refuses an unknown or broken file with many exception types
        raise sdk.ParameterError(f"--scene {path}: trimesh cannot read it ({type(err).__name__}: {err})") from err
    scene = pyrender.Scene(bg_color=(0.45, 0.6, 0.85, 1.0), ambient_light=(0.3, 0.3, 0.3))
    skipped = []
    for node in tm.graph.nodes_geometry:  # pyrender.Scene.from_trimesh_scene, keeping each material's alpha mode
        pose, name = tm.graph[node]
        geometry = tm.geometry[name]
        if not isinstance(geometry, trimesh.Trimesh) or len(geometry.faces) == 0:
            skipped.append(f"{name} ({type(geometry).__name__})")  # points and lines shade no tile
            continue
        if not (np.isfinite(geometry.vertices).all() and np.isfinite(pose).all()):
            raise sdk.ParameterError(f"--scene {path}: mesh {name!r} has vertex positions or a node transform "
                                     "that are NaN or infinite")
        mesh = pyrender.Mesh.from_trimesh(geometry)
        material = getattr(geometry.visual, "material", None)
        if isinstance(material, trimesh.visual.material.PBRMaterial):
            # pyrender blends every trimesh material (alphaMode BLEND) and draws a scene's meshes in the order of a
            # set, which changes from process to process: an alpha-tested grate's holes showed the sky in one run
            # and the room behind it in the next. glTF's OPAQUE (its default) and MASK draw opaque in pyrender.
            for primitive in mesh.primitives:
                primitive.material.alphaMode = material.alphaMode or "OPAQUE"
        scene.add(mesh, pose=pose, name=str(node))
    if not scene.mesh_nodes:
        raise sdk.ParameterError(f"--scene {path}: no triangles to draw (expected a glTF, GLB or OBJ file with at "
                                 "least one triangle mesh" + (f"; it holds {', '.join(skipped)}" if skipped else "")
                                 + ")")
    if skipped:
        log.warning("--scene %s: skipped what is not a triangle mesh: %s", path, ", ".join(skipped))
    if tm.has_camera:  # the file's (first) camera is the start of the move, its pose and field of view
        cam = tm.camera
        scene.add(pyrender.PerspectiveCamera(yfov=math.radians(float(cam.fov[1])), znear=float(cam.z_near),
                                             zfar=float(cam.z_far)), pose=_placement(tm.camera_transform, path),
                  name=cam.name)
        log.info("--scene %s: the camera starts at the file's camera %r (%.0f degrees high)", path, cam.name,
                 float(cam.fov[1]))
    # pyrender's shading needs a light; a sun-like directional light from above
    sun = np.eye(4)
    sun[:3, :3] = _rotation(yaw=30.0, pitch=-60.0)
    scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=3.0), pose=sun)
    return scene


def _placement(transform: Any, path: Path) -> np.ndarray:
    """A file camera's world transform without the scale its nodes give it (a root node scaled 0.01 to turn
    centimetres into metres scales the camera too): its rotation and position, which is where it looks from. The
    adapter takes rigid poses only; the scaled one was refused, and the example ended on such a file."""
    m = np.asarray(transform, np.float64)
    u, _, vt = np.linalg.svd(m[:3, :3])  # (the nearest rotation: the polar decomposition's)
    rotation = u @ vt  # (a mirroring node stays one: the adapter refuses it, naming the mirror)
    if not np.allclose(rotation, m[:3, :3], atol=1e-6):
        log.info("--scene %s: the camera's nodes scale it (axes %s long): placed by their rotation and position only",
                 path, np.round(np.linalg.norm(m[:3, :3], axis=0), 4).tolist())
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, m[:3, 3]
    return out


def _rotation(yaw: float, pitch: float) -> np.ndarray:
    """Camera-to-world rotation looking down -Z turned by yaw (left) and pitch (up), degrees."""
    y, p = math.radians(yaw), math.radians(pitch)
    forward = np.array([-math.sin(y) * math.cos(p), math.sin(p), -math.cos(y) * math.cos(p)])
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return np.stack([right, up, -forward], axis=1)


def camera_poses(scene: Any, spawn: Any | None) -> tuple[np.ndarray, np.ndarray]:
    """Two camera-to-world poses: a start and a small move (0.2 m sideways, 4 degrees of turn)."""
    if scene.main_camera_node is not None:
        p0 = np.array(scene.get_pose(scene.main_camera_node))
        yaw = 0.0
    else:
        p0 = np.eye(4)
        if spawn is not None:
            p0[:3, 3] = spawn.position
            yaw = float(spawn.yaw)
        else:
            lo, hi = scene.bounds
            centre, extent = (lo + hi) / 2, float(np.max(hi - lo))
            p0[:3, 3] = centre + np.array([0.0, 0.0, extent])
            yaw = 0.0
        p0[:3, :3] = _rotation(yaw, -5.0)
    p1 = p0.copy()
    p1[:3, :3] = p0[:3, :3] @ _rotation(4.0, 1.0)
    p1[:3, 3] = p0[:3, 3] + p0[:3, :3] @ np.array([0.2, 0.0, -0.1])
    return p0, p1


def walk(p0: np.ndarray, frames: int, turn: float = 1.0, move: float = 0.05) -> list[np.ndarray]:
    """``frames`` camera poses from ``p0``, each ``move`` metres sideways (and half that forward)
    and ``turn`` degrees to the left of the one before: at 60 frames a second, by default a walk of
    3 m/s turning 60 degrees a second (the two-frame move above is four of these steps)."""
    step = np.eye(4)
    step[:3, :3] = _rotation(turn, turn / 4)
    step[:3, 3] = (move, 0.0, -move / 2)
    poses = [p0]
    for _ in range(frames - 1):
        poses.append(poses[-1] @ step)
    return poses


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", type=Path, help="glTF/GLB/OBJ file (default: a procedural level written as GLB)")
    ap.add_argument("--model", default="jnyang", help="a shipped model's name or an rtp ONNX path (default: jnyang)")
    ap.add_argument("--out", type=out_image, default="pyrender_vrs.png", help="overlay PNG to write")
    ap.add_argument("--size", type=frame_size, default="640x360", help="WIDTHxHEIGHT, as rtp's commands take it")
    ap.add_argument("--threshold", type=float, help="error threshold (default: the model's)")
    ap.add_argument("--seed", type=int, default=None, help="procedural level seed (default 3; without --scene)")
    ap.add_argument("--frames", type=int, default=2,
                    help="frames of the camera move (default 2: one prediction; more: a frame loop with reuse)")
    ap.add_argument("--every", type=int, default=None,
                    help="in a frame loop, run the network every this many frames (default 4)")
    ap.add_argument("--gif", type=out_animation, help="in a frame loop, write the rate overlays as an animated GIF")
    ap.add_argument("--moving", action="store_true", help="in a frame loop, a box slides across the view: the "
                    "adapter makes its motion vectors from its previous pose (SceneFrame.prev_node_poses)")
    ap.add_argument("--tile-size", type=int, help="the hardware's shading-rate tile in pixels (default: the model's, "
                    "16 for the shipped ones, NVIDIA's, 8 for the -8px ones; 8: AMD's and Intel's)")
    args = ap.parse_args(argv)
    args.out, args.gif = Path(args.out), None if args.gif is None else Path(args.gif)  # (checked: writable, a format)
    if args.frames < 2 or (args.every is not None and args.every < 1):
        ap.error(f"expected --frames >= 2 and --every >= 1, got {args.frames} and {args.every}")
    if args.every is not None and args.frames < 3:  # (two frames decide once: it was ignored)
        ap.error("--every paces the network through a frame loop: give --frames 3 or more")
    if args.seed is not None and args.scene is not None:  # (it seeds the procedural level only: it was ignored)
        ap.error("--seed seeds the procedural level drawn without --scene; leave one out")
    args.every = 4 if args.every is None else args.every
    args.seed = 3 if args.seed is None else args.seed
    if args.gif is not None and args.frames < 3:
        ap.error("--gif animates a frame loop: give --frames 3 or more")
    if args.moving and args.frames < 3:
        ap.error("--moving slides a box through a frame loop: give --frames 3 or more")
    if args.scene is not None and not args.scene.is_file():
        ap.error(f"--scene: no file at {str(args.scene)!r} (a glTF, GLB or OBJ file)")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("OpenGL").setLevel(logging.WARNING)
    width, height = args.size
    gif = args.gif is not None and args.frames > 2
    need = peak_bytes(width, height, args.frames, gif)  # refused now, not by the OOM killer later
    check_memory(need, f"the example at {width}x{height}" + (f" with a GIF of {args.frames} frames" if gif else "")
                 + f" holds about {need / 2**30:.1f} GiB", "size",
                 "of memory: a smaller --size" + (" or fewer --frames" if gif else ""), job="the example")
    pyrender = import_pyrender()

    with tempfile.TemporaryDirectory(prefix="rtp-pyrender-") as tmp:
        folder = Path(tmp)
        spawn = None
        scene_path = args.scene
        if scene_path is None:
            scene_path, spawn = write_procedural_glb(folder / "level.glb", args.seed)
            log.info("wrote a procedural level (seed %d) to %s", args.seed, scene_path)
        scene = load_scene(scene_path)
        predictor = sdk.load(args.model, tile_size=args.tile_size)
        if args.threshold is not None:  # refused now, not at the first frame
            sdk.check_threshold(args.threshold, predictor.metadata.higher_is_better)
        log.info("model %s: inputs %s, tile %d%s", predictor.path, ", ".join(predictor.metadata.inputs),
                 predictor.tile_size, "" if predictor.tile_size == predictor.metadata.tile_size else
                 f" (the model's {predictor.metadata.tile_size})")

        p0, p1 = camera_poses(scene, spawn)  # before adding a camera: a glTF camera, if any, is the start
        if scene.main_camera_node is None:
            scene.add(pyrender.PerspectiveCamera(yfov=math.radians(70.0), znear=0.05, zfar=200.0), pose=p0)

        if args.frames > 2:
            return loop(args, scene, predictor, walk(p0, args.frames), width, height)
        with Adapter.for_predictor(predictor, width, height) as adapter:
            # the displayed frames: pyrender's own lit images, drawn on the adapter's renderer
            # (pyrender binds a scene to one renderer; to use your own, pass Adapter(..., renderer=r))
            prev_colour, _ = adapter.render(scene, p0)
            colour, _ = adapter.render(scene, p1)
            # prev_depth=None: the adapter renders a point-sampled depth at p0 (pyrender's own depth is
            # an MSAA sample off the pixel centre; in a frame loop the previous call's depth is reused)
            x = adapter.inputs(SceneFrame(scene, p1, p0, prev_colour))
        seen = predictor.metadata.inputs.index("seen") if "seen" in predictor.metadata.inputs else None
        if seen is not None:
            log.info("seen (reprojected and depth-tested): %.1f %% of the pixels", 100.0 * float(x[seen].mean()))
        rates = predictor.shading_rates(x[None], threshold=args.threshold)[0]
        names, counts = np.unique(rates, return_counts=True)
        log.info("rates: %s; shading work saved %.1f %%",
                 ", ".join(f"{sdk.RATE_NAMES[int(c)]} x{n}" for c, n in zip(names, counts)),
                 100.0 * sdk.work_saved(rates, (height, width), predictor.tile_size))  # partial tiles by their pixels
        overlay = sdk.draw_rate_overlay(colour, rates, predictor.tile_size)
        img = overlay if overlay.dtype == np.uint8 else (np.clip(overlay, 0, 1) * 255 + 0.5).astype(np.uint8)
        save_image(args.out, img)  # atomic: an interrupted write leaves the file there before, not half of one
        log.info("saved the rate overlay to %s", args.out)
    return 0


def _add_slider(scene: Any, pose: np.ndarray) -> Any:
    """A 0.5 m orange box 2.5 m in front of the camera at ``pose`` and a little left of its axis: the node."""
    import trimesh

    pyrender = import_pyrender()
    box = pyrender.Mesh.from_trimesh(trimesh.creation.box((0.5, 0.5, 0.5)), smooth=False,
                                     material=pyrender.MetallicRoughnessMaterial(baseColorFactor=(1.0, 0.5, 0.1, 1.0)))
    at = np.eye(4)
    at[:3, 3] = (-0.4, -0.1, -2.5)
    log.info("a box slides across the view (--moving): its motion vectors from its previous pose")
    return scene.add(box, pose=pose @ at)


def loop(args: argparse.Namespace, scene: Any, predictor: sdk.ShadingRatePredictor, poses: list[np.ndarray],
         width: int, height: int) -> int:
    """The frame loop: the adapter's inputs every frame, the network every ``args.every``-th."""
    import time

    inputs = predictor.metadata.inputs
    carry = "features" if predictor.splits else "estimates"
    reuse = sdk.PredictionReuse(predictor, args.every, carry=carry)
    log.info("frame loop: %d frames decided (the first of the %d only draws the previous image), the network every "
             "%d, carrying its %s", len(poses) - 1, len(poses), args.every, carry)
    # the model's planes, then what the loop needs besides: motion vectors (where each pixel was) and depth (sky)
    channels = (*inputs, "motion.x", "motion.y", "depth")
    overlays, saved, ran = [], [], []
    mover = _add_slider(scene, poses[0]) if args.moving else None
    with Adapter(channels, width, height) as adapter:
        prev_colour, _ = adapter.render(scene, poses[0])
        for i in range(1, len(poses)):
            moved = None
            if mover is not None:  # this frame's animation; the adapter is told where the box was
                moved = {mover: np.array(mover.matrix, copy=True)}
                step = np.eye(4)
                step[0, 3] = 0.04  # 4 cm a frame to the first camera's right
                scene.set_pose(mover, moved[mover] @ step)
            colour, _ = adapter.render(scene, poses[i])
            planes = adapter.inputs(SceneFrame(scene, poses[i], poses[i - 1], prev_colour, prev_node_poses=moved))
            x, (motion_x, motion_y, depth) = planes[:len(inputs)], planes[len(inputs):]
            fetch = sdk.fetch_from_motion(motion_x, motion_y)
            seen = x[inputs.index("seen")] if "seen" in inputs else None
            t0 = time.perf_counter()
            rates = reuse.shading_rates(x, fetch=fetch if i > 1 else None, seen=seen, background=depth <= 0.0,
                                        threshold=args.threshold)
            ms = 1000.0 * (time.perf_counter() - t0)
            saved.append(sdk.work_saved(rates, (height, width), predictor.tile_size))
            ran.append(reuse.work)
            log.info("frame %2d: %s, %.1f ms, shading work saved %.1f %%", i,
                     "network ran" if reuse.work >= 1.0 else f"carried ({reuse.work:.0%} of a network run on crops)"
                     if reuse.work > 0 else f"{carry} carried, age {reuse.age}", ms, 100.0 * saved[-1])
            if args.gif is not None or i == len(poses) - 1:  # (without --gif only the last is written)
                overlay = sdk.draw_rate_overlay(colour, rates, predictor.tile_size)
                overlays.append(overlay if overlay.dtype == np.uint8 else
                                (np.clip(overlay, 0, 1) * 255 + 0.5).astype(np.uint8))
            prev_colour = colour  # what the frame displayed (a VRS engine: its own shaded frame)
    log.info("%d frames: the network on %.0f %% of them, %.1f %% of the shading work saved on average",
             len(saved), 100.0 * float(np.mean(ran)), 100.0 * float(np.mean(saved)))
    save_image(args.out, overlays[-1])
    log.info("saved the last frame's rate overlay to %s", args.out)
    if args.gif is not None:
        import imageio.v3 as iio

        with atomic_output(args.gif) as tmp:  # (renamed over --gif once whole; the extension names the format)
            iio.imwrite(tmp, np.stack(overlays), extension=args.gif.suffix.lower(), duration=1000 / 15, loop=0)
        log.info("saved the overlays of every frame to %s", args.gif)
    return 0


if __name__ == "__main__":
    sys.exit(run_guarded(Path(__file__).name, main))  # an rtp error in one line, as the rtp commands print it
