"""Variable-rate shading for a pyrender scene: two frames of a camera move, a model, the rate overlay.

    python examples/pyrender_vrs.py                       # procedural level -> GLB, the shipped JNYang model
    python examples/pyrender_vrs.py --scene level.glb --model flip --out vrs.png   # your level, another model

Headless: pyrender draws through EGL (``PYOPENGL_PLATFORM=egl``, the default here) or OSMesa.

1. The scene: ``--scene`` loads any glTF/GLB (or OBJ) through trimesh; without it a seeded
   procedural level is written to a GLB with trimesh first, then loaded back the same way.
2. The camera: the scene's first camera if it has one, else one at the level's first spawn point
   (or looking at the scene's centre); the second frame moves it 0.2 m and turns it 4 degrees.
3. pyrender draws both frames (its own lit colour image; the previous one is what the user saw),
   on the adapter's renderer: pyrender binds a scene to one renderer's GL context.
4. The adapter builds the model's inputs for the second frame from the scene, the two poses and
   the first frame; ``predictor.shading_rates`` picks a rate per tile; the overlay is saved.

``--model`` is a shipped model's name (``sdk.shipped_models()``: jnyang by default, flip, jnflip,
lpips, psnr, jnyang-reuse) or the path of any rtp ONNX model. The pyrender adapter produces every
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
from rtp.plugins.pyrender import Adapter, SceneFrame, import_pyrender, to_trimesh_scene

log = logging.getLogger("pyrender_vrs")


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
    tm = trimesh.load(str(path), force="scene", process=False)
    scene = pyrender.Scene.from_trimesh_scene(tm, bg_color=(0.45, 0.6, 0.85, 1.0), ambient_light=(0.3, 0.3, 0.3))
    # pyrender's shading needs a light; a sun-like directional light from above
    sun = np.eye(4)
    sun[:3, :3] = _rotation(yaw=30.0, pitch=-60.0)
    scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=3.0), pose=sun)
    return scene


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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", type=Path, help="glTF/GLB/OBJ file (default: a procedural level written as GLB)")
    ap.add_argument("--model", default="jnyang", help="a shipped model's name or an rtp ONNX path (default: jnyang)")
    ap.add_argument("--out", type=Path, default=Path("pyrender_vrs.png"), help="overlay PNG to write")
    ap.add_argument("--size", type=int, nargs=2, default=(640, 360), metavar=("W", "H"))
    ap.add_argument("--threshold", type=float, help="error threshold (default: the model's)")
    ap.add_argument("--seed", type=int, default=3, help="procedural level seed")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    logging.getLogger("OpenGL").setLevel(logging.WARNING)
    width, height = args.size
    pyrender = import_pyrender()

    with tempfile.TemporaryDirectory(prefix="rtp-pyrender-") as tmp:
        folder = Path(tmp)
        spawn = None
        scene_path = args.scene
        if scene_path is None:
            scene_path, spawn = write_procedural_glb(folder / "level.glb", args.seed)
            log.info("wrote a procedural level (seed %d) to %s", args.seed, scene_path)
        scene = load_scene(scene_path)
        predictor = sdk.load(args.model)
        log.info("model %s: inputs %s, tile %d", predictor.path, ", ".join(predictor.metadata.inputs),
                 predictor.metadata.tile_size)

        p0, p1 = camera_poses(scene, spawn)  # before adding a camera: a glTF camera, if any, is the start
        if scene.main_camera_node is None:
            scene.add(pyrender.PerspectiveCamera(yfov=math.radians(70.0), znear=0.05, zfar=200.0), pose=p0)

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
                 100.0 * float(np.mean([sdk.work_saved(sdk.RATE_NAMES[int(c)]) for c in rates.ravel()])))
        overlay = sdk.draw_rate_overlay(colour, rates, predictor.metadata.tile_size)
        from PIL import Image

        img = overlay if overlay.dtype == np.uint8 else (np.clip(overlay, 0, 1) * 255 + 0.5).astype(np.uint8)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(img).save(args.out)
        log.info("saved the rate overlay to %s", args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
