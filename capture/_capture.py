"""The capture driver behind ``rtp capture``: scenes -> viewpoint pairs -> rendered samples.

For every scene and motion profile it samples ``per_scene`` (previous, current) camera pairs
(paper Appendix A), renders the previous frame, then the current frame with the previous one
reprojected, and writes one dataset sample per pair. Sample ids are deterministic
(``<scene>-<profile>-<index>``) and every write is atomic, so a killed run resumes where it
stopped: existing samples are skipped and never half-written.
"""

from __future__ import annotations

import contextlib
import json
import logging
import numbers
import os
import platform
import re
import reprlib
import shutil
import time
import zlib
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, BrokenExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rtp.sdk import ALL_RATES, ParameterError
from rtp.sdk.files import writer_lock

from ._dataset import MAX_ID_LENGTH, DatasetError, DatasetReader, DatasetWriter, _read_manifest, holds_nothing
from ._memory import check_frame_memory
from ._pool import WorkerDiedError, cores, name_task, tick_queue, unfinished, with_ticks, worker_died, worker_pool

__all__ = [
    "MESH_EXTENSIONS", "PROCEDURAL_PREFIX", "VIEW_COVERAGE", "CaptureReport", "capture", "check_scene", "load_scene",
    "sample_buffers",
    "scene_id",
]

log = logging.getLogger("rtp.capture")

#: Scene names of the form ``procedural:<seed>`` select the built-in generator (no downloads).
PROCEDURAL_PREFIX = "procedural:"
#: File extensions :func:`load_scene` reads as your own scene (glTF, GLB, OBJ through trimesh).
MESH_EXTENSIONS: tuple[str, ...] = (".gltf", ".glb", ".obj")
#: Share of a view that must be covered by geometry, tried in turn: mostly-indoor views first; open
#: maps whose sky fills most views fall back to the paper's 15 % foreground rule.
VIEW_COVERAGE = (0.85, 0.5, 0.15)


@dataclass
class CaptureReport:
    written: int = 0
    skipped: int = 0
    unseen: dict[str, list[float]] = field(default_factory=dict)  # profile -> unseen share per new sample
    renderer: dict[str, Any] = field(default_factory=dict)  # Renderer.settings of the workers
    failed: list[str] = field(default_factory=list)  # "<scene>/<profile>" without valid viewpoints
    recaptured: int = 0  # existing samples whose cameras differed from the plan (written again)

    def unseen_mean(self) -> dict[str, float]:
        return {p: float(np.mean(v)) for p, v in self.unseen.items() if v}


#: The renderer settings that change what a sample's images are (Renderer.settings less the GL implementation's).
_IMAGE_SETTINGS = ("shadow_map_size", "shadow_distance", "ao_samples", "ao_radius", "ao_strength", "anisotropy", "fxaa",
                   "max_point_lights", "exposure_key", "reprojection_tolerance", "cull_back_faces")


def _warn_other_renderer(out: Path, previous: Any, report: CaptureReport) -> None:
    """A resumed capture whose new samples were drawn with other renderer settings than the folder's (another rtp
    version's defaults: the default shadow map of frames up to 128 pixels changed on 2026-12-07) is said so: the
    dataset mixes two renderers' images."""
    if not (isinstance(previous, dict) and report.renderer and report.written):
        return
    changed = [f"{k} {previous.get(k)!r} before, {report.renderer.get(k)!r} now" for k in _IMAGE_SETTINGS
               if k in previous and previous.get(k) != report.renderer.get(k)]
    if changed:
        log.warning("%s: the %d samples written now were drawn with other renderer settings than the samples there "
                    "(%s; another rtp version's defaults): the dataset mixes both; capture into a new folder to keep "
                    "one renderer's", out, report.written, "; ".join(changed))


def load_scene(
    name: str, cache_dir: str | os.PathLike[str] | None, split: str | None, splits: str | None, *,
    checked: bool = False,
) -> tuple[Any, Any]:
    """A scene and its invisible blockers (a BSP map's sky), from one of three kinds of name:

    * ``procedural:<seed>``: the built-in procedural scene, nothing to download;
    * a path to your own glTF / GLB / OBJ file (anything with a mesh extension, or an existing file);
    * a game level listed in ``scenes.yaml`` (``split`` restricts to one split), from the cache of
      ``rtp scenes fetch`` (``cache_dir``, default :func:`rtp.capture.scenes.default_cache_dir`).

    ``checked``: :func:`check_scene` read this file in the same run and logged its warnings (a texture it cannot
    read, ...); they are then logged at DEBUG here, not said a second time.
    """
    from rtp.capture import scenes

    from .scenes._mesh import said_before

    seed = _procedural_seed(name)
    if seed is not None:
        return scenes.procedural(seed), None
    if Path(name).suffix.lower() in MESH_EXTENSIONS or Path(name).is_file():
        with said_before() if checked else contextlib.nullcontext():
            return scenes.load_mesh_file(name), None
    cache = Path(scenes.default_cache_dir() if cache_dir is None else cache_dir)
    scene = scenes.scene_by_name(name, cache, split=split, splits=splits)
    return scene, scenes.scene_blockers(name, cache, splits=splits)


#: Bytes a sample takes on disk for each pixel of its frames (a compressed ``.npz``): at least (below
#: every sample measured: procedural levels 7.5-10.6) and typically (the shipped dataset's mean, about
#: 17 MB a sample at 1280x720 on the OpenArena maps).
SAMPLE_BYTES_PER_PIXEL = {"least": 5.0, "typical": 18.5}


def _size_text(n: float) -> str:
    return f"{n / 1e12:,.1f} TB" if n >= 1e12 else f"{n / 1e9:,.1f} GB"


def check_disk(out: str | os.PathLike[str], size: tuple[int, int], samples: int, *,
               scene_names: Sequence[str] | None = None, profiles: Sequence[str] | None = None) -> None:
    """Refuse a capture of ``samples`` samples of ``size`` into ``out`` whose files could not fit on
    its disk even at their least (:data:`SAMPLE_BYTES_PER_PIXEL`), a :class:`ParameterError` naming
    ``per_scene``; warn where their typical size would not. Samples already in ``out`` count as
    written (a resumed capture skips them). Given the job's ``scene_names`` and ``profiles`` (``samples``
    being ``per_scene`` for each scene and profile), only the job's own samples there count
    (``<scene>-<profile>-<index>``, index below ``per_scene``): not other scenes' or profiles', which it
    does not skip."""
    folder = Path(out)
    files = sorted((folder / "samples").glob("*.npz")) if (folder / "samples").is_dir() else []
    if scene_names is None and profiles is None:
        have = len(files)
    elif scene_names is None or profiles is None or not scene_names or not profiles:
        raise ParameterError(f"scene_names and profiles: expected both, each one or more names, or neither; got "
                             f"{scene_names!r} and {profiles!r}", "scene_names" if not scene_names else "profiles")
    else:
        jobs = len(scene_names) * len(profiles)
        if samples % jobs:
            raise ParameterError(f"samples: expected per_scene for each of the {jobs} scene and profile pairs "
                                 f"(a multiple of {jobs}), got {samples}", "samples")
        per_scene = samples // jobs
        own = {f"{scene_id(s)}-{p}" for s in scene_names for p in profiles}
        have = 0
        for path in files:  # (the ids the job writes, as _ids makes them)
            job, _, index = path.stem.rpartition("-")
            have += job in own and index.isdigit() and int(index) < per_scene and f"{int(index):04d}" == index
    todo = max(0, samples - have)
    where = next((p for p in (folder, *folder.absolute().parents) if p.is_dir()), None)
    if not todo or where is None:
        return
    free = shutil.disk_usage(where).free
    pixels = size[0] * size[1]
    least, typical = (todo * SAMPLE_BYTES_PER_PIXEL[k] * pixels for k in ("least", "typical"))
    said = f"{todo:,} samples at {size[0]}x{size[1]} take"
    if least > free:
        raise ParameterError(f"per_scene: {said} at least {_size_text(least)} on disk (typically {_size_text(typical)}), "
                             f"more than the {_size_text(free)} free in {str(where)!r}: fewer samples, or --out on a "
                             "larger disk", "per_scene")
    if typical > free:
        log.warning("%s about %s on disk, more than the %s free in %r: the capture may stop when the disk is full "
                    "(it resumes where it stopped)", said, _size_text(typical), _size_text(free), str(where))


def check_scene(name: str, cache_dir: str | os.PathLike[str] | None, split: str | None, splits: str | None) -> None:
    """What :func:`load_scene` would refuse, found without loading anything: a bad procedural seed, a
    missing scene file, a map not listed or not fetched. Jobs call it before they write."""
    from rtp.capture import scenes

    if _procedural_seed(name) is not None:
        return
    if Path(name).suffix.lower() in MESH_EXTENSIONS or Path(name).is_file():
        if not Path(name).is_file():
            raise scenes.SceneNotFoundError(f"scene {name!r}: no such file")
        # read once more by the worker (load_scene(..., checked=True), its warnings not said again): a file it
        # cannot read fails here, first
        scenes.load_mesh_file(name)
        return
    scenes.check_map(name, Path(scenes.default_cache_dir() if cache_dir is None else cache_dir), split=split,
                     splits=splits)


def _names(key: str, value: str | Sequence[str]) -> list[str]:
    """A list of names from one name or a sequence of them (a string is one name, not its letters)."""
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, (list, tuple)) or not all(isinstance(v, str) for v in items):
        raise ParameterError(f"{key}: expected a name or a list of names, got {value!r}", key)
    return list(items)


def _check_scene_ids(scene_names: Sequence[str]) -> None:
    """Refuse a scene given twice (its viewpoints were planned and rendered twice, in two worker processes at
    once with ``workers``, and its samples counted twice) and two scenes whose samples would share ids
    (``a/arena.glb`` and ``b/arena.glb``, ``arena.obj`` and ``arena.glb``: each run captured one over the other,
    as samples "from other cameras"): a :class:`ParameterError` about ``scene_names``."""
    twice = [name for name in dict.fromkeys(scene_names) if scene_names.count(name) > 1]
    if twice:
        raise ParameterError(f"scene_names: each scene once, got {twice[0]!r} {scene_names.count(twice[0])} times",
                             "scene_names")
    by_id: dict[str, str] = {}
    for name in scene_names:
        sid = scene_id(name)
        other = by_id.setdefault(sid, name)
        if other != name:
            raise ParameterError(
                f"scene_names: {other!r} and {name!r} both make the sample ids {sid}-<profile>-<index>, so one "
                "would be captured over the other; capture them into two folders, or rename one file", "scene_names")


def _check_id_length(scene_names: Sequence[str], profiles: Sequence[str], per_scene: int) -> None:
    """Refuse a scene whose sample ids would be longer than a sample id may be (``MAX_ID_LENGTH``: a scene file of
    a name of about 190 characters failed at its first sample's write, "File name too long", after its planning
    and rendering): a :class:`ParameterError` about ``scene_names`` that names the limit."""
    tail = max(len(f"-{p}-{per_scene - 1:04d}") for p in profiles)  # (the longest profile, the last index)
    for name in scene_names:
        sid = scene_id(name)
        if len(sid) + tail > MAX_ID_LENGTH:
            part = "its file name without the extension" if _is_scene_file(name) else "its name"
            raise ParameterError(
                f"scene_names: {reprlib.repr(name)} makes sample ids of up to {len(sid) + tail} characters "
                f"(<scene>-<profile>-<index>), more than the {MAX_ID_LENGTH} a sample id may have (its file name stays "
                f"within the 255 bytes a file system allows); shorten {part} to at most {MAX_ID_LENGTH - tail} "
                "characters", "scene_names")


def check_frame_size(size: Sequence[int], what: str = "size", *, renderer: bool = True) -> tuple[int, int]:
    """``size`` as ``(width, height)`` after checking it: two integers of at least 16 pixels, and with
    ``renderer`` a frame the reference renderer can draw here (one is made and released: a size past
    the GL context's largest texture, or past its memory within it, is a ``RendererError``). What
    :func:`capture` and :func:`rtp.evaluate.play` check before they write anything."""
    ok = isinstance(size, (tuple, list)) and len(size) == 2 and all(
        isinstance(v, numbers.Integral) and not isinstance(v, bool) and int(v) >= 16 for v in size)
    if not ok:
        raise ParameterError(f"{what}: expected (width, height), integers of at least 16 pixels, got {size!r}", what)
    w, h = int(size[0]), int(size[1])
    if renderer:
        from rtp.plugins.moderngl import Renderer

        with Renderer(w, h):
            pass
    return w, h


def _procedural_seed(name: str) -> int | None:
    """The seed of a ``procedural:<seed>`` name, None for any other name. The seed is written one way only,
    in decimal digits without a sign, leading zeros or underscores (``int`` also reads ``1_0``, ``01``,
    ``+1``, `` 1``): one scene, one name, one sample id."""
    from rtp.capture import scenes

    if not (name == PROCEDURAL_PREFIX.rstrip(":") or name.startswith(PROCEDURAL_PREFIX)):
        return None
    text = name[len(PROCEDURAL_PREFIX):]
    if not text:
        raise scenes.SceneNotFoundError(f"scene {name!r}: the procedural scene needs a seed, e.g. {PROCEDURAL_PREFIX}0")
    if not re.fullmatch(r"0|[1-9][0-9]*", text):  # (also a negative seed, which numpy refuses deep in the builder)
        raise scenes.SceneNotFoundError(
            f"scene {name!r}: the procedural scene's seed is a non-negative integer in decimal digits, without a "
            f"sign, leading zeros, underscores or spaces, e.g. {PROCEDURAL_PREFIX}0 or {PROCEDURAL_PREFIX}12, got {text!r}")
    return int(text)


def _is_scene_file(name: str) -> bool:
    """Whether :func:`load_scene` reads ``name`` as a scene file: a mesh extension, or an existing file (a PLY, an
    STL: anything trimesh reads)."""
    return Path(name).suffix.lower() in MESH_EXTENSIONS or Path(name).is_file()


def scene_id(name: str) -> str:
    """The part of sample ids that names the scene: ``procedural:3`` -> ``procedural_3``; a file path
    -> its stem (``levels/arena.glb`` -> ``arena``, ``./room.ply`` -> ``room``: any file :func:`load_scene` reads);
    a map name as it is. A procedural name whose seed is not written in plain decimal digits (``procedural:01``)
    is refused, as :func:`load_scene` refuses it."""
    _procedural_seed(name)
    if _is_scene_file(name):  # (a PLY's whole path was its id: ``./room.ply`` -> ``._room.ply``, a hidden file)
        name = Path(name).stem
    return re.sub(r"[^A-Za-z0-9_.]", "_", name)


def sample_buffers(frame: Any) -> dict[str, np.ndarray]:
    """Dataset buffers of a rendered :class:`rtp.plugins.moderngl.Frame`."""
    bufs = {
        name: getattr(frame, name)
        for name in ("reprojected", "seen", "albedo", "normal", "roughness", "metallic", "specular", "shadow",
                     "emissive", "depth", "motion")
    }
    bufs.update({f"final_{r}": frame.colour[r] for r in ALL_RATES})
    return bufs


def _camera_dict(cam: Any) -> dict[str, Any]:
    return {"position": [float(v) for v in cam.position], "yaw": cam.yaw, "pitch": cam.pitch, "fov_y": cam.fov_y,
            "near": cam.near, "far": cam.far}


def _job_seed(seed: int, scene: str, profile: str) -> int:
    return (seed * 1_000_003 + zlib.crc32(f"{scene}/{profile}".encode())) % (2**31)


def _same_cameras(reader: DatasetReader, sample_id: str, prev_cam: Any, cam: Any) -> bool:
    """Whether an existing sample was rendered from exactly these cameras."""
    meta = reader[sample_id].meta
    return bool(meta.get("camera") == _camera_dict(cam) and meta.get("prev_camera") == _camera_dict(prev_cam))


def _ids(scene: str, profile: str, n: int) -> list[str]:
    return [f"{scene_id(scene)}-{profile}-{i:04d}" for i in range(n)]


def _plan(scene_name: str, scene: Any, blockers: Any, profiles: Sequence[str], per_scene: int,
          size: tuple[int, int], seed: int, placement: str = "free",
          planning: Callable[[str, int, int], None] | None = None,
          ) -> tuple[dict[str, list[tuple[str, Any, Any]]], list[str]]:
    """Every planned sample of a scene: ``{profile: [(sample id, previous camera, camera)]}``, and the
    ``"<scene>/<profile>"`` jobs without valid viewpoints. Deterministic: any worker plans the same.
    ``planning(job, found, per_scene)`` as each pair is found (:func:`capture`'s ``planning``)."""
    from rtp.capture.viewpoints import ViewpointError, sample_viewpoints

    w, h = size
    plans: dict[str, list[tuple[str, Any, Any]]] = {}
    failed: list[str] = []
    for profile in profiles:
        job = f"{scene_name}/{profile}"
        found = None if planning is None else (lambda k, job=job: planning(job, k, per_scene))
        start = time.perf_counter()
        try:
            pairs = sample_viewpoints(scene, per_scene, _job_seed(seed, scene_name, profile), profile,
                                      blockers=blockers, aspect=w / h, min_coverage=VIEW_COVERAGE,
                                      placement=placement, progress=found)
        except ViewpointError as err:
            log.warning("%s (%s): %s", scene_name, profile, err)
            failed.append(job)
            continue
        log.info("%s: %d viewpoint pairs planned in %.1f s", job, per_scene, time.perf_counter() - start)
        plans[profile] = [(sid, p, c) for sid, (p, c) in zip(_ids(scene_name, profile, per_scene), pairs)]
    return plans, failed


def _render(renderer: Any, scene_name: str, profile: str, prev_cam: Any, cam: Any,
            ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Render one sample (the previous frame, then the current one with it reprojected): its buffers and meta."""
    prev = renderer.render(prev_cam)
    frame = renderer.render(cam, prev)
    geo = frame.mask > 0.5
    unseen = float(1.0 - frame.seen[geo].mean()) if geo.any() else 0.0
    meta = {
        "scene": scene_name, "profile": profile, "camera": _camera_dict(cam), "prev_camera": _camera_dict(prev_cam),
        "exposure": float(frame.exposure), "unseen": unseen, "coverage": float(geo.mean()),
    }
    return sample_buffers(frame), meta


def _todo(writer: DatasetWriter, reader: DatasetReader, planned: list[tuple[str, Any, Any]]) -> list[tuple[str, Any, Any]]:
    """The planned samples that are not on disk yet, were rendered from other cameras, or cannot be read (a file
    damaged since: captured again, with a warning, rather than stopping the resume)."""
    def kept(sid: str, prev_cam: Any, cam: Any) -> bool:
        if not writer.has(sid):
            return False
        try:
            return _same_cameras(reader, sid, prev_cam, cam)
        except DatasetError as err:  # (removed: nothing of it can be read, and it is no sample of other cameras)
            log.warning("%s; captured again", err)
            (writer.samples_dir / f"{sid}.npz").unlink(missing_ok=True)
            return False

    return [(sid, p, c) for sid, p, c in planned if not kept(sid, p, c)]


def _already_captured(jobs: Sequence[tuple[Any, ...]]) -> list[CaptureReport] | None:
    """The reports of ``jobs`` (:func:`_run_job`'s arguments) when every sample they plan is on disk, rendered
    from the cameras planned for it; else None. A capture on Ray into a finished folder then needs no cluster
    (it reached for one, and failed where none answered). The scenes are planned here (a few milliseconds
    a pair, no GL), and only once every sample's file is found."""
    for scene_name, profiles, per_scene, _, out, *_, settings in jobs:
        writer = DatasetWriter(out, settings)
        if not all(writer.has(sid) for p in profiles for sid in _ids(scene_name, p, per_scene)):
            return None
    reports = []
    for scene_name, profiles, per_scene, size, out, seed, cache_dir, split, splits, settings in jobs:
        scene, blockers = load_scene(scene_name, cache_dir, split, splits, checked=True)  # (capture() checked it)
        writer, reader = DatasetWriter(out, settings), DatasetReader(out)
        planned, failed = _plan(scene_name, scene, blockers, profiles, per_scene, size, seed,
                                settings.get("placement", "free"))
        if failed or any(_todo(writer, reader, plan) for plan in planned.values()):
            return None
        reports.append(CaptureReport(skipped=sum(len(plan) for plan in planned.values())))
    return reports


def _run_job(
    scene_name: str, profiles: Sequence[str], per_scene: int, size: tuple[int, int], out: str, seed: int,
    cache_dir: str | None, split: str | None, splits: str | None, settings: dict[str, Any], queue: Any = None,
    checked: bool = False,
) -> CaptureReport:
    """One scene's capture (``checked``: :func:`check_scene` ran on it in this run, as :func:`load_scene` says)."""
    from rtp.plugins.moderngl import Renderer

    writer = DatasetWriter(out, settings)
    report = CaptureReport()
    scene, blockers = load_scene(scene_name, cache_dir, split, splits, checked=checked)
    w, h = size
    reader = DatasetReader(out)
    planning = None if queue is None else (lambda job, found, total: queue.put((job, found, total)))
    planned, report.failed = _plan(scene_name, scene, blockers, profiles, per_scene, size, seed,
                                   settings.get("placement", "free"), planning)
    plans = {profile: _todo(writer, reader, plan) for profile, plan in planned.items()}
    report.skipped = sum(len(planned[p]) - len(plans[p]) for p in plans)
    if queue is not None and report.skipped:
        queue.put(report.skipped)
    if not any(plans.values()):
        return report
    with Renderer(w, h) as renderer:
        report.renderer = renderer.settings
        renderer.load_scene(scene)
        for profile, plan in plans.items():
            for sid, prev_cam, cam in plan:
                if writer.has(sid):
                    # Captured by an older rtp whose viewpoint stream differed; the new file is
                    # newer than the sample's targets, so `rtp targets` recomputes them.
                    log.warning("%s was captured from other cameras than this rtp plans; recapturing it", sid)
                    report.recaptured += 1
                buffers, meta = _render(renderer, scene_name, profile, prev_cam, cam)
                writer.write(sid, buffers, meta)
                report.written += 1
                report.unseen.setdefault(profile, []).append(meta["unseen"])
                if queue is not None:
                    queue.put(1)
    return report


def _stored_size(path: Path) -> tuple[int, int] | None:
    """``(width, height)`` of a sample file's ``final_1x1``, read from its array header (not its data); None
    where the file cannot be read so (a damaged sample: the resume captures it again)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z, z.open("final_1x1.npy") as fh:
            version = np.lib.format.read_magic(fh)
            header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape = tuple(header(fh)[0])
    except Exception:  # noqa: BLE001 - numpy's and zipfile's readers on damaged bytes (see _dataset._unreadable)
        return None
    return (int(shape[1]), int(shape[0])) if len(shape) >= 2 else None


def _check_unlisted_samples(out: str | os.PathLike[str], size: tuple[int, int]) -> None:
    """Refuse a capture of ``size`` into a folder that holds samples but no manifest (deleted, or lost) where a
    sample there is of another size: without the manifest's settings to refuse them by, they were adopted (the
    ones planned from the same cameras skipped, the others kept), and ``rtp train`` refused the mix much later.
    Each sample's size is read from its header; nothing is deleted."""
    root = Path(out)
    if (root / "manifest.json").exists() or not (root / "samples").is_dir():
        return
    w, h = size
    for path in sorted((root / "samples").glob("*.npz")):
        found = _stored_size(path)
        if found is not None and found != (w, h):
            raise DatasetError(
                f"{root}: no manifest.json, and the samples there are not of the size asked for: {path} is "
                f"{found[0]}x{found[1]}, --size (size=) {w}x{h}; a dataset holds samples of one size: capture into "
                f"another folder, or resume this one with --size {found[0]}x{found[1]} (nothing was deleted)")


def _stored_scene(path: Path) -> str | None:
    """The ``scene`` a sample file's meta names; None where the file or its meta cannot be read (a damaged
    sample: the resume captures it again) or names none."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            meta = json.loads(bytes(npz["meta"]).decode())
    except Exception:  # noqa: BLE001 - numpy's and zipfile's readers on damaged bytes (see _dataset._unreadable)
        return None
    scene = meta.get("scene") if isinstance(meta, dict) else None
    return scene if isinstance(scene, str) else None


def _check_folder_scenes(out: str | os.PathLike[str], scene_names: Sequence[str]) -> None:
    """Refuse a scene whose sample ids ``<scene>-<profile>-<index>`` the folder holds already from another scene
    (``b/arena.glb`` into a folder captured from ``a/arena.glb``, ``procedural_5.glb`` after ``procedural:5``, or
    one file named by another path: its viewpoints are seeded by the name as given): the resume captured the new
    scene's samples over the old one's, one by one, saying they came "from other cameras than this rtp plans". A
    :class:`DatasetError` naming both; the first readable sample of each scene's ids is looked at."""
    samples = Path(out) / "samples"
    if not samples.is_dir():
        return
    by_scene: dict[str, list[Path]] = {}
    for path in sorted(samples.glob("*.npz")):  # (one listing of the folder, not one a scene)
        by_scene.setdefault(path.stem.partition("-")[0], []).append(path)  # (a scene id holds no '-')
    for name in scene_names:
        sid = scene_id(name)
        for path in by_scene.get(sid, []):
            before = _stored_scene(path)
            if before is None:
                continue
            if before != name:
                raise DatasetError(
                    f"{out}: its samples {sid}-<profile>-<index> ({path.name}, ...) were captured from the scene "
                    f"{before!r}, not {name!r}; capturing {name!r} here would write over them. Capture it into another "
                    f"folder, or, if it is the same scene, name it as it was named then ({before!r}: the viewpoints are "
                    "drawn from the name as given)")
            break


def _writer_lock(out: str | os.PathLike[str]) -> Any:
    """The dataset folder's writer lock for a capture (:func:`rtp.sdk.files.writer_lock`)."""
    return writer_lock(out, "rtp capture", lambda holder: DatasetError(
        f"{out} is being written by another capture ({holder}): wait for it to end, or capture into another folder"))


def _locked_writer(out: str | os.PathLike[str], settings: Mapping[str, Any], guard: contextlib.ExitStack) -> DatasetWriter:
    """The :class:`DatasetWriter` of the dataset folder ``out`` (made where it is not), opened once ``guard`` holds
    the folder's writer lock (:func:`_writer_lock`, until ``guard`` closes). Opened before the lock, a capture into
    a folder without a manifest wrote its own (its settings) first, and then, refused, left it in place of the
    manifest of the capture that held the lock, whose samples it then described with the other's size. A folder of
    a manifest with other settings is refused before the lock's file is made in it (it is left as it was). A folder
    that holds nothing yet (:func:`holds_nothing`) has its manifest's settings replaced, under the lock only: replaced
    before it, they were another capture's, which held the lock and had not written its first sample yet."""
    root = Path(out)
    if (root.exists() and not root.is_dir()) or (
            (root / "manifest.json").exists() and not holds_nothing(root, _read_manifest(root))):
        DatasetWriter(out, settings)  # (refuses other settings, or a file, writing nothing; else writes nothing)
    root.mkdir(parents=True, exist_ok=True)
    guard.enter_context(_writer_lock(out))
    return DatasetWriter(out, settings)  # (a manifest another capture wrote since: its settings checked again)


def capture(
    scene_names: Sequence[str],
    out: str | os.PathLike[str],
    *,
    per_scene: int,
    size: tuple[int, int] = (1280, 720),
    profiles: Sequence[str] = ("slow", "fast"),
    seed: int = 0,
    workers: int | None = 1,
    cache_dir: str | os.PathLike[str] | None = None,
    split: str | None = None,
    splits: str | os.PathLike[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    ray: str | None = None,
    placement: str = "free",
    planning: Callable[[str, int, int], None] | None = None,
    starting: Callable[[int], None] | None = None,
    _on_ray_actors: Callable[[list[Any]], None] | None = None,
) -> CaptureReport:
    """Capture ``per_scene`` samples per scene and motion profile into the dataset folder ``out``.
``scene_names`` and ``profiles`` are one name or a list of them, each name once (two scene files of one name,
    whose samples would share ids, are refused too); ``out`` is not empty.

    ``size`` is ``(width, height)``. ``placement`` is where the cameras stand
    (:data:`rtp.capture.viewpoints.PLACEMENTS`: ``"free"`` anywhere in the viewpoint domain, ``"eye"``
    at the player's eye height over a floor); the dataset's manifest records it. With
    ``workers > 1`` scenes render in parallel processes (one EGL context each; a process a scene at most). ``progress(done,
    total)`` is called as samples complete (skipped ones count). Before a scene renders, its
    viewpoints are planned (a few milliseconds a pair: minutes for a hundred thousand):
    ``planning(job, found, asked)`` is called as each pair is found, ``job`` being
    ``"<scene>/<profile>"`` (on Ray at most every ``PLAN_NEWS_S`` a job, and when it is planned).
    ``starting(total)`` is called once, with the number of samples asked for, when every argument, scene
    and the folder have been checked and before any scene is planned: a caller that announces the job
    does it there, so that a refusal is never preceded by the announcement of a job that does not run.

    ``ray`` runs the capture on Ray instead (docs/scaling.md): ``"local"`` starts a private Ray
    instance with ``workers`` CPUs, ``"auto"`` or a head address joins a cluster (``workers`` None:
    one worker per CPU of the cluster; an address of none of these forms is a ``RayExecutorError`` with the other
    arguments, before ``starting``). Samples are the same as the local path's; workers send them
    back as bytes and this process writes them, so no shared filesystem is needed.
    """
    scene_names, profiles = _names("scene_names", scene_names), _names("profiles", profiles)
    for key, value in (("per_scene", per_scene), ("workers", 1 if workers is None else workers)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
            raise ParameterError(f"{key} must be an integer >= 1, got {value!r}", key)
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise ParameterError(f"seed must be an integer, got {seed!r}", "seed")
    # (a numpy integer, taken here, reached the manifest's settings as a DatasetError about JSON values)
    per_scene, seed = int(per_scene), int(seed)
    if not scene_names:
        raise ParameterError("no scenes to capture")
    if not profiles:  # (a folder's settings would record none, refusing every later capture into it)
        raise ParameterError("profiles: expected one or more motion profiles, got none", "profiles")
    from rtp import sdk
    from rtp.capture.viewpoints import MOTION_PROFILES, PLACEMENTS

    bad = [p for p in profiles if p not in MOTION_PROFILES]
    if bad:
        raise ParameterError(f"unknown motion profile {bad[0]!r}; profiles are {', '.join(MOTION_PROFILES)}")
    if len(set(profiles)) < len(profiles):  # (one was planned and rendered twice, its samples counted twice)
        raise ParameterError(f"profiles: each motion profile once, got {', '.join(profiles)}", "profiles")
    _check_scene_ids(scene_names)
    _check_id_length(scene_names, profiles, int(per_scene))
    if not isinstance(out, (str, os.PathLike)) or not os.fspath(out):  # (Path('') is the current folder)
        raise ParameterError(f"out: expected a dataset folder path, got {out!r}"
                             + (" (empty; '.' is the current folder)" if out == "" else ""), "out")
    if placement not in PLACEMENTS:
        raise ParameterError(f"unknown placement {placement!r}; placements are {', '.join(PLACEMENTS)}", "placement")
    from ._ray import check_ray_address

    # (its form, without Ray or a connection: `--ray head.example`, with no port, was refused only on connecting,
    # after `starting` had announced the job; whether anything answers there is still found there)
    check_ray_address(ray)
    w, h = check_frame_size(size, renderer=False)
    if ray in (None, "local"):  # (on a cluster each node's workers are checked against its memory: ray_capture)
        # (locally a process a scene at most; a private Ray's workers a sample at most, any scene's: counted as
        # scenes, --ray --workers 1000 passed here and then started its 1000 workers, which it checked only once
        # every one of them had started)
        most = len(scene_names) if ray is None else len(scene_names) * len(profiles) * per_scene
        check_frame_memory("capture", (w, h), processes=min(workers or (cores() if ray == "local" else 1), most))
    if ray is None:  # (a Ray driver may have no OpenGL: its workers say so)
        check_frame_size((w, h))
    for name in scene_names:  # every name now: not after the manifest, or an hour into the first map
        check_scene(name, cache_dir, split, None if splits is None else str(splits))
    # (the files are written here, Ray or not; other scenes' samples in the folder are not this job's)
    check_disk(out, (w, h), len(scene_names) * len(profiles) * per_scene, scene_names=scene_names, profiles=profiles)
    settings = {
        "size": [w, h],
        "renderer": "rtp.plugins.moderngl reference deferred renderer",
        "motion_profiles": {p: vars(MOTION_PROFILES[p]) for p in profiles},
        "seed": seed,
    }
    if placement != "free":  # recorded only when not the default, so folders captured before it resume
        settings["placement"] = placement
    # An existing folder is checked (its settings, stale files) before any worker starts. A new one on
    # Ray is made only once Ray answers (ray_capture), so an address that is not Ray's leaves nothing.
    # The folder's writer lock is held to the end: a second capture into it would delete this one's
    # files in flight as stale and render the same samples again. (A new folder on Ray: ray_capture
    # holds it from when it makes the folder until the samples are written.)
    _check_unlisted_samples(out, (w, h))  # (before a manifest is written that would adopt them)
    _check_folder_scenes(out, scene_names)
    writer: DatasetWriter | None = None
    with contextlib.ExitStack() as guard:
        if ray is None or (Path(out) / "manifest.json").exists():
            writer = _locked_writer(out, settings, guard)
        if writer is not None and writer.remove_stale():
            log.info("removed temporary files of an interrupted capture in %s", out)
        total = len(scene_names) * len(profiles) * per_scene
        if starting:
            starting(total)
        if ray is None and (workers or 1) > len(scene_names):  # (as rtp play says of its paths: 4 workers on one
            # scene rendered it in one process without a word)
            log.warning("workers %d for %d scene%s: a process a scene at most, so %s", workers, len(scene_names),
                        "" if len(scene_names) == 1 else "s",
                        "one process renders it" if len(scene_names) == 1 else f"{len(scene_names)} processes render them")
        done = 0
        report = CaptureReport()
        args = [(s, tuple(profiles), per_scene, (w, h), str(out), seed, None if cache_dir is None else str(cache_dir),
                 split, None if splits is None else str(splits), settings) for s in scene_names]

        def merge(r: CaptureReport) -> None:
            report.written += r.written
            report.skipped += r.skipped
            report.renderer = r.renderer or report.renderer
            report.failed.extend(r.failed)
            report.recaptured += r.recaptured
            for p, v in r.unseen.items():
                report.unseen.setdefault(p, []).extend(v)

        def tick(item: int | tuple[str, int, int]) -> None:
            """A worker's news: samples done (an int), or a job's pairs planned (job, found, asked)."""
            nonlocal done
            if isinstance(item, tuple):
                if planning:
                    planning(*item)
                return
            done += item
            if progress:
                progress(done, total)

        finished = None if ray is None or writer is None else _already_captured(args)
        if finished is not None:
            log.info("every sample is in %s already, from the cameras planned for it: Ray is not needed", out)
            for r in finished:
                merge(r)
                tick(r.skipped)
        elif ray is not None:
            from ._ray import ray_capture

            merge(ray_capture(scene_names, str(out), profiles=tuple(profiles), per_scene=per_scene, size=(w, h), seed=seed,
                              cache_dir=None if cache_dir is None else str(cache_dir), split=split,
                              splits=None if splits is None else str(splits), settings=settings, address=ray,
                              workers=workers, progress=tick, on_actors=_on_ray_actors, planning=planning))
        elif (workers or 1) <= 1:
            class _Q:
                put = staticmethod(tick)

            for a in args:
                try:
                    result = _run_job(*a, queue=_Q(), checked=True)
                except Exception as exc:
                    name_task(exc, f"scene {a[0]!r}")
                    raise
                merge(result)
        else:
            queue = tick_queue()

            def drain() -> None:
                while not queue.empty():
                    tick(queue.get())

            # (a process a scene at most: one more was an idle process that took its share of the cores' threads
            # from the workers that render, and said there were more processes than cores)
            with worker_pool(min(workers or 1, len(args)), ticks=queue) as pool:
                scene_of = {pool.submit(with_ticks, _run_job, *a, checked=True): a[0] for a in args}
                pending = set(scene_of)
                while pending:
                    finished, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                    drain()
                    for f in sorted(finished, key=lambda f: f.exception() is not None):  # (those done first)
                        try:
                            result = f.result()
                        except BrokenExecutor as exc:  # (a worker killed: every unfinished scene's future fails)
                            left = unfinished(scene_of)
                            raise WorkerDiedError(
                                f"{worker_died('capture')} before {'scene' if len(left) == 1 else 'scenes'} "
                                f"{', '.join(map(repr, left))} {'was' if len(left) == 1 else 'were'} captured; the "
                                f"samples written are kept: the same command captures the rest") from exc
                        except Exception as exc:  # (a worker's: its traceback said nothing of the scene)
                            name_task(exc, f"scene {scene_of[f]!r}")
                            raise
                        merge(result)
            drain()  # (after the workers exited: their last ticks are flushed)
        unseen: dict[str, list[float]] = {}
        reader = DatasetReader(out)
        for sid in reader.ids:
            try:
                meta = reader[sid].meta
            except DatasetError as err:  # (a sample of a scene not captured now, damaged since: this run's samples
                # were written and the capture then failed on it, the manifest not written, and so every later run)
                log.warning("%s; left out of the manifest's unseen_share (a capture of its scene captures it again)",
                            err)
                continue
            value = meta.get("unseen", 0.0)
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                unseen.setdefault(str(meta.get("profile")), []).append(float(value))
        manifest = reader.manifest
        previous = manifest.get("renderer_settings")
        _warn_other_renderer(out, previous, report)
        # The jobs without viewpoints of the scenes not captured now stay (a folder filled a scene a run lost
        # them from the manifest, all but the last run's); this run's scenes say anew. Sorted: the workers' order.
        before = manifest.get("failed")
        kept = [job for job in before if isinstance(job, str) and job.rpartition("/")[0] not in scene_names] \
            if isinstance(before, list) else []
        if writer is None:  # (a new folder on Ray: made by ray_capture once Ray answered)
            writer = DatasetWriter(out, settings)
        writer.finalize({
            "renderer_settings": report.renderer or previous,
            "failed": sorted(set(kept) | set(report.failed)),
            "versions": {"rtp": str(sdk.__version__), "numpy": np.__version__, "python": platform.python_version()},
            "unseen_share": {p: float(np.mean(v)) for p, v in sorted(unseen.items())},
        })
        return report
