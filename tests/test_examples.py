"""The examples run as a user would run them, with the shipped models."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.gl
def test_pyrender_example_uses_a_shipped_model(tmp_path: Path) -> None:
    out = tmp_path / "vrs.png"
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--size", "160x96",
                        "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "jnyang.onnx" in r.stderr and "RANDOM" not in r.stderr and out.is_file()
    # on AMD's and Intel's 8-pixel tiles: 12 x 20 of them at 160x96, each its model tile's rate
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--size", "160x96",
                        "--tile-size", "8", "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "tile 8 (the model's 16)" in r.stderr
    counts = re.search(r"rates: (.*); shading work saved", r.stderr)
    assert counts is not None and sum(int(n) for n in re.findall(r" x(\d+)", counts.group(1))) == 12 * 20


@pytest.mark.gl
def test_pyrender_example_loops_with_the_reuse_model(tmp_path: Path) -> None:
    # --frames N: a frame loop in which PredictionReuse runs jnyang-reuse every --every-th frame and
    # carries its features (fetched along the adapter's motion vectors) in between
    import imageio.v3 as iio

    out, gif = tmp_path / "vrs.png", tmp_path / "vrs.gif"
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--model", "jnyang-reuse",
                        "--frames", "7", "--every", "3", "--size", "160x96", "--out", str(out), "--gif", str(gif)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if re.match(r"frame +\d+:", ln)]
    assert len(lines) == 6, r.stderr
    assert ["network ran" in ln for ln in lines] == [True, False, False, True, False, False], lines
    assert all("features carried" in ln for ln in lines[1:3] + lines[4:]), lines
    assert "the network on 33 % of them" in r.stderr
    assert out.is_file() and iio.imread(gif).shape == (6, 96, 160, 3)
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--frames", "1"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "expected --frames >= 2" in r.stderr
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--gif", str(tmp_path / "g.gif")],
                       capture_output=True, text=True, timeout=300)  # (the default two frames wrote no GIF, silently)
    assert r.returncode == 2 and "--gif animates a frame loop: give --frames 3 or more" in r.stderr


@pytest.mark.gl
def test_pyrender_example_slides_a_box_through_its_frame_loop(tmp_path: Path) -> None:
    # --moving: a node moved every frame, its previous pose given to the adapter (SceneFrame.prev_node_poses)
    out = tmp_path / "vrs.png"
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--frames", "4", "--moving",
                        "--size", "160x96", "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "a box slides across the view" in r.stderr and out.is_file()
    assert len([ln for ln in r.stderr.splitlines() if re.match(r"frame +\d+:", ln)]) == 3
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--moving"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "--moving slides a box through a frame loop" in r.stderr


@pytest.mark.gl
def test_moderngl_example_decides_on_the_gpu_and_shades_the_rates(tmp_path: Path) -> None:
    # G-buffers -> the adapter's planes -> onnxruntime -> RateSelector's compute shader -> software VRS
    import imageio.v3 as iio

    out, gif = tmp_path / "vrs.png", tmp_path / "vrs.gif"
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "moderngl_vrs.py"), "--model", "flip", "--frames", "3",
                        "--size", "160x96", "--out", str(out), "--gif", str(gif)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "flip.onnx" in r.stderr
    found = [tuple(map(int, m)) for m in re.findall(r"GPU decision = CPU decision on (\d+) of (\d+) tiles", r.stderr)]
    assert len(found) == 3 and all(n == 60 and same >= 57 for same, n in found), r.stderr
    assert "G-buffers:" not in r.stderr  # (adapter.check on the first frame: the reference renderer's are right)
    assert iio.imread(out).shape == (96, 160, 3) and iio.imread(gif).shape == (3, 96, 160, 3)
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "moderngl_vrs.py"), "--frames", "0"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "--frames: expected at least 1" in r.stderr


@pytest.mark.gl
def test_moderngl_example_on_8_pixel_hardware_tiles(tmp_path: Path) -> None:
    """`--tile-size 8` (AMD's and Intel's VRS): the GPU's rate image holds the frame's 8-pixel tiles, 13 x 20 at
    160x100 (where the model has 7 x 10: its last row is partial), and decides as the predictor loaded for them."""
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "moderngl_vrs.py"), "--tile-size", "8", "--frames", "2",
                        "--size", "160x100", "--out", str(tmp_path / "vrs.png")], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    found = [tuple(map(int, m)) for m in re.findall(r"GPU decision = CPU decision on (\d+) of (\d+) tiles", r.stderr)]
    assert len(found) == 2 and all(n == 13 * 20 and same >= n - 3 for same, n in found), r.stderr
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "moderngl_vrs.py"), "--tile-size", "12"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "tile_size: expected one of [4, 8, 16, 32]" in r.stderr


@pytest.mark.gl
def test_moderngl_example_with_a_budget_on_the_gpu(tmp_path: Path) -> None:
    """`--saving 0.6`: each frame's rates save at least 60% of the work, the threshold found on the GPU, the rates as
    predictor.shading_rates(x, saving=0.6) chooses them but for ties within float32 rounding; a saving no rate can
    reach is refused before the first frame."""
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "moderngl_vrs.py"), "--saving", "0.6", "--frames", "2",
                        "--size", "160x100", "--out", str(tmp_path / "vrs.png")], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    saved = [float(m) for m in re.findall(r"work saved ([\d.]+)%", r.stderr)]
    assert len(saved) == 2 and all(s >= 60.0 for s in saved), r.stderr
    assert len(re.findall(r"the budget's threshold [\d.e-]+", r.stderr)) == 2, r.stderr
    found = [tuple(map(int, m)) for m in re.findall(r"GPU decision = CPU decision on (\d+) of (\d+) tiles", r.stderr)]
    assert len(found) == 2 and all(n == 7 * 10 and same >= n - 3 for same, n in found), r.stderr
    r = subprocess.run([sys.executable, str(ROOT / "examples" / "moderngl_vrs.py"), "--saving", "0.97"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "saving: expected" in r.stderr and "frame  1" not in r.stderr, r.stderr


@pytest.mark.parametrize("name", ["moderngl_vrs", "pyrender_vrs"])
def test_an_example_past_the_machines_memory_is_refused_before_it_renders(
    name: str, tmp_path: Path, machine_memory: Callable[..., None]
) -> None:
    """`--size 8192x8192` needs about 63 GiB in the moderngl example (34 in the pyrender one) and was the OOM killer's, after
    the model loaded and rendering began; a GIF's overlays add 8 bytes a pixel a frame. Now each
    example sizes its run from its measured constants (`bench/job_memory.py --jobs examples`) and
    refuses it as rtp's commands do, naming the size, before loading anything or writing."""
    from rtp import sdk

    from .conftest import bench_module

    module = bench_module("job_memory").example(name)
    out, gif = tmp_path / "vrs.png", tmp_path / "vrs.gif"
    need = module.peak_bytes(8192, 8192, 4, False)
    assert need == int(module.PEAK_BASE + 8192 * 8192 * module.PEAK_PER_PIXEL) and need > 30 * 2**30
    machine_memory(MemTotal=need - 2**30, SwapTotal=0, MemAvailable=need - 2**30)
    with pytest.raises(sdk.ParameterError, match=rf"^size: the example at 8192x8192 holds about {need / 2**30:.1f} GiB, "
                                                 r"more than this machine's .* GiB of memory: a smaller --size \(") as e:
        module.main(["--size", "8192x8192", "--frames", "4", "--out", str(out)])
    assert e.value.name == "size"
    with_gif = module.peak_bytes(8192, 8192, 4, True)
    assert with_gif == need + 4 * 8192 * 8192 * module.PEAK_PER_GIF_PIXEL
    machine_memory(MemTotal=need + 2**20, SwapTotal=0, MemAvailable=need + 2**20)  # fits without the GIF, not with it
    with pytest.raises(sdk.ParameterError, match=r"^size: the example at 8192x8192 with a GIF of 4 frames holds about "
                                                 r".*: a smaller --size or fewer --frames \("):
        module.main(["--size", "8192x8192", "--frames", "4", "--out", str(out), "--gif", str(gif)])
    assert not out.exists() and not gif.exists()


@pytest.mark.gl
def test_pyrender_example_draws_a_glb_the_same_in_every_process(tmp_path: Path) -> None:
    """pyrender blends every material it takes from trimesh (alphaMode BLEND) and draws a scene's meshes in
    the order of a set, which changes from process to process: the example's grate showed the sky through
    its holes in one run and the room behind in the next (one run in three differed, by up to 157 of 255 on
    2.4% of the pixels). Its ``load_scene`` keeps each glTF material's own mode, so an rtp level (OPAQUE,
    and MASK for the grate: drawn opaque) is never blended, while a material the file blends stays blended."""
    import importlib.util

    import trimesh

    spec = importlib.util.spec_from_file_location("pyrender_vrs", ROOT / "examples" / "pyrender_vrs.py")
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    path, _ = example.write_procedural_glb(tmp_path / "level.glb", 3)
    modes = [p.material.alphaMode for n in example.load_scene(path).mesh_nodes for p in n.mesh.primitives]
    assert len(modes) > 5 and "BLEND" not in modes and modes.count("MASK") == 1
    glass = trimesh.creation.box()
    glass.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(
        baseColorFactor=[200, 220, 255, 100], alphaMode="BLEND"))
    trimesh.Scene(glass).export(tmp_path / "glass.glb")
    assert [p.material.alphaMode for n in example.load_scene(tmp_path / "glass.glb").mesh_nodes
            for p in n.mesh.primitives] == ["BLEND"]


def _pyrender_example() -> object:
    """examples/pyrender_vrs.py as a module (its main() run in this process)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("pyrender_vrs", ROOT / "examples" / "pyrender_vrs.py")
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    return example


def test_pyrender_example_refuses_options_it_would_ignore(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--every paces the network through a frame loop and --seed seeds the procedural level: with the default two
    frames, or with --scene, each was ignored without a word (the run as without it, exit 0)."""
    example: Any = _pyrender_example()
    (tmp_path / "level.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    for argv, words in ((["--every", "2"], "--every paces the network through a frame loop: give --frames 3 or more"),
                        (["--scene", str(tmp_path / "level.obj"), "--seed", "5"],
                         "--seed seeds the procedural level drawn without --scene")):
        with pytest.raises(SystemExit) as exc:
            example.main([*argv, "--size", "64x48", "--out", str(tmp_path / "o.png")])
        assert exc.value.code == 2 and words in capsys.readouterr().err
    assert not (tmp_path / "o.png").exists()


@pytest.mark.gl
@pytest.mark.parametrize("name", ["moderngl_vrs", "pyrender_vrs"])
def test_an_example_writes_its_overlay_and_gif_atomically(name: str, tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """The overlay and the GIF were written in place (PIL's save, imageio's imwrite): a write that failed half-way
    (a full disk, Ctrl-C while a long GIF encodes) left half a file where the previous run's was."""
    import errno
    import importlib.util

    import imageio.v3 as iio
    from PIL import Image

    spec = importlib.util.spec_from_file_location(name, ROOT / "examples" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    example: Any = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)

    def half(path: Any, *args: Any, **kwargs: Any) -> None:
        Path(path).write_bytes(b"half a file")
        raise OSError(errno.ENOSPC, "No space left on device")

    out, gif = tmp_path / "vrs.png", tmp_path / "vrs.gif"
    out.write_bytes(b"the previous overlay")
    gif.write_bytes(b"the previous animation")
    with monkeypatch.context() as mp:
        save = Image.Image.save  # (trimesh saves the GLB's textures into memory: those go through)
        mp.setattr(Image.Image, "save", lambda self, fp, *a, **k: half(fp) if isinstance(fp, (str, os.PathLike))
                   else save(self, fp, *a, **k))
        with pytest.raises(OSError, match="No space left on device"):
            example.main(["--size", "64x48", "--out", str(out)])
    assert out.read_bytes() == b"the previous overlay"
    with monkeypatch.context() as mp:
        mp.setattr(iio, "imwrite", half)
        with pytest.raises(OSError, match="No space left on device"):
            example.main(["--size", "64x48", "--frames", "3", "--out", str(out), "--gif", str(gif)])
    assert gif.read_bytes() == b"the previous animation"
    assert Image.open(out).size == (64, 48)  # (the overlay of that run, written whole before the GIF failed)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["vrs.gif", "vrs.png"]  # (no temporary file left)


@pytest.mark.gl
def test_pyrender_example_refuses_a_scene_with_nothing_to_draw(tmp_path: Path) -> None:
    # an empty or unreadable OBJ rendered the sky and reported 93.8% saved; points alone were a TypeError from
    # pyrender; NaN vertices failed later on as a camera pose. Each is refused in words, naming the file.
    files = {"empty.obj": "", "junk.obj": "garbage here\n", "points.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\n",
             "nan.obj": "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n"}
    for name, text in files.items():
        (tmp_path / name).write_text(text)
        r = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--scene",
                            str(tmp_path / name), "--size", "64x48", "--out", str(tmp_path / "o.png")],
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 2 and "Traceback" not in r.stderr, (name, r.stderr)
        want = {"nan.obj": "NaN or infinite", "points.obj": "it holds points.obj (PointCloud)"}.get(name,
                                                                                                   "no triangles to draw")
        assert f"pyrender_vrs.py: error: --scene {tmp_path / name}: " in r.stderr and want in r.stderr, r.stderr
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize("name", ["moderngl_vrs", "pyrender_vrs"])
def test_an_example_refuses_outputs_it_cannot_write_before_it_renders(name: str, tmp_path: Path) -> None:
    """`--out x.txt` and `--gif x.mp4` were imageio tracebacks at the end, after every frame was rendered (an MP4
    needs imageio's ffmpeg plugin, not installed); both are now argparse errors before anything loads, in the
    words of rtp's own commands (rtp.cli.out_image, out_animation), and the moderngl example makes the GIF's folder
    as the pyrender one does."""
    for flag, path, words in (("--out", "x.txt", "not an image extension Pillow can write"),
                              ("--gif", "x.mp4", "expected an animation file (.gif, .png, .apng, .webp)"),
                              ("--gif", "x.jpg", "expected an animation file")):
        r = subprocess.run([sys.executable, str(ROOT / "examples" / f"{name}.py"), "--frames", "3", flag,
                            str(tmp_path / path)], capture_output=True, text=True, timeout=300)
        assert r.returncode == 2 and words in r.stderr and "Traceback" not in r.stderr, r.stderr
        assert ".onnx" not in r.stderr  # (refused before the model loads: the examples log its file first)


@pytest.mark.parametrize(("missing", "argv"), [("PIL", []), ("imageio", ["--gif", "walk.gif"])])
def test_the_moderngl_example_without_the_picture_packages_is_refused_before_it_renders(
        missing: str, argv: list[str], tmp_path: Path) -> None:
    """With rtp[moderngl] alone (no Pillow, no imageio) the example walked every frame and then failed on
    `import imageio`, which only --gif needs: it now says what it lacks, one line naming rtp[capture], before the
    model loads."""
    blocked = f"""
import runpy, sys
class NotInstalled:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] == {missing!r}:
            raise ModuleNotFoundError("No module named {missing!r}", name={missing!r})
sys.meta_path.insert(0, NotInstalled())
sys.argv = sys.argv[1:]
runpy.run_path(sys.argv[0], run_name="__main__")
"""
    r = subprocess.run([sys.executable, "-c", blocked, str(ROOT / "examples" / "moderngl_vrs.py"), "--frames", "2",
                        "--out", str(tmp_path / "o.png"), *argv], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 2 and r.stderr.endswith(f"moderngl_vrs.py: error: this needs {missing}, which is not "
                                                   "installed: pip install 'rtp[capture]'\n"), r.stderr
    assert ".onnx" not in r.stderr and not (tmp_path / "o.png").exists()  # (refused before the model loads)


@pytest.mark.gl
def test_pyrender_example_starts_at_the_cameras_of_the_scene_file(tmp_path: Path) -> None:
    """The example's docs say the move starts at the scene's first camera if it has one, but ``load_scene`` copied the
    meshes only: a glTF's camera was dropped and the view placed at the bounds' centre (a 2 m box seen from 1 m away
    filled the frame where the file's camera stood 6 m back). The file's camera, pose and vertical field of view, is
    now the start."""
    import math

    import numpy as np
    import trimesh

    example: Any = _pyrender_example()
    level = trimesh.Scene(trimesh.creation.box((2.0, 2.0, 2.0)))
    pose = np.eye(4)
    pose[:3, 3] = (0.5, 0.3, 6.0)
    level.camera_transform = pose
    level.camera.fov = (60.0, 30.0)
    level.export(tmp_path / "level.glb")
    scene = example.load_scene(tmp_path / "level.glb")
    assert scene.main_camera_node is not None
    assert math.isclose(scene.main_camera_node.camera.yfov, math.radians(30.0))
    p0, _ = example.camera_poses(scene, None)
    assert np.allclose(p0, pose)
    # a file without a camera: the view at the bounds' centre, as before
    trimesh.Scene(trimesh.creation.box((2.0, 2.0, 2.0))).export(tmp_path / "bare.glb")
    assert example.load_scene(tmp_path / "bare.glb").main_camera_node is None


@pytest.mark.gl
def test_pyrender_example_places_a_scaled_file_camera_by_its_rotation_and_position(tmp_path: Path) -> None:
    """A glTF whose camera sits under a scaled node (a root scaled 0.01, centimetres to metres) gives a camera
    transform with axes 0.01 long: ``load_scene`` put that pose on the camera and the adapter refused it as not
    rigid, so the example ended on the file. The camera is now placed by its rotation and position."""
    import numpy as np
    import trimesh

    example: Any = _pyrender_example()
    level = trimesh.Scene(trimesh.creation.box((2.0, 2.0, 2.0)))
    pose = np.diag([0.01, 0.01, 0.01, 1.0])
    pose[:3, :3] = pose[:3, :3] @ trimesh.transformations.rotation_matrix(0.3, (0.0, 1.0, 0.0))[:3, :3]
    pose[:3, 3] = (1.5, 0.3, 6.0)
    level.camera_transform = pose
    level.export(tmp_path / "level.glb")
    scene = example.load_scene(tmp_path / "level.glb")
    p0, _ = example.camera_poses(scene, None)
    rigid = np.eye(4)
    rigid[:3, :3] = trimesh.transformations.rotation_matrix(0.3, (0.0, 1.0, 0.0))[:3, :3]
    rigid[:3, 3] = (1.5, 0.3, 6.0)
    np.testing.assert_allclose(p0, rigid, atol=1e-6)
    out = tmp_path / "vrs.png"
    proc = subprocess.run([sys.executable, str(ROOT / "examples" / "pyrender_vrs.py"), "--scene", str(tmp_path / "level.glb"),
                           "--size", "64x48", "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert out.is_file() and "placed by their rotation and position only" in proc.stderr


def test_moderngl_examples_walk_goes_forward() -> None:
    """The walk was documented as 3 m/s forward but stepped along (+sin yaw, -cos yaw), the heading mirrored left to
    right (``Camera.forward`` is (-sin yaw, 0, -cos yaw)): from seed 3's spawn point, looking 49 degrees left of -Z,
    it walked 98 degrees off the view, sideways and a little backwards; facing +-90 degrees, straight backwards."""
    import importlib.util

    import numpy as np

    from rtp.capture.scenes import procedural
    from rtp.scene import Camera

    spec = importlib.util.spec_from_file_location("moderngl_vrs", ROOT / "examples" / "moderngl_vrs.py")
    assert spec is not None and spec.loader is not None
    example: Any = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    spawn = procedural(3).spawn_points[0]
    for position, yaw in ((spawn.position, spawn.yaw), ((1.0, 1.6, 2.0), 90.0), ((0.0, 1.6, 0.0), -135.0)):
        start = example.walk_camera(position, yaw, 0)
        assert start.position == tuple(map(float, position)) and start.yaw == yaw
        later = example.walk_camera(position, yaw, 60)  # a second on
        moved = np.subtract(later.position, start.position)
        heading = Camera(position, yaw=yaw).forward  # (level: the view's own pitches 3 degrees down)
        assert np.allclose(moved, 3.0 * heading), (yaw, moved, heading)
        assert later.yaw == yaw + 30.0
