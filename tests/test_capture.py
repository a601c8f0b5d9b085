"""rtp capture: end to end on the procedural scene, resume, and a kill mid-run."""

from __future__ import annotations

import logging
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rtp import sdk
from rtp.capture import DatasetReader
from rtp.capture._capture import VIEW_COVERAGE, capture

pytestmark = pytest.mark.gl


def test_capture_writes_complete_samples_and_resumes(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    r = capture(["procedural:5"], out, per_scene=1, size=(96, 64))
    assert (r.written, r.skipped) == (2, 0)
    ds = DatasetReader(out)
    assert ds.ids == ["procedural_5-fast-0000", "procedural_5-slow-0000"]
    s = ds["procedural_5-slow-0000"]
    assert s.meta["scene"] == "procedural:5" and s.meta["profile"] == "slow"
    assert s.size == (64, 96)
    x = s.inputs(sdk.DEFAULT_INPUTS)
    assert x.shape == (4, 64, 96) and np.isfinite(x).all()
    assert set(np.unique(s.channel("seen"))) <= {0.0, 1.0}
    assert not np.array_equal(s.final("1x1"), s.final("4x4"))  # reduced rates differ somewhere
    assert ds.manifest["settings"]["size"] == [96, 64]
    assert set(ds.manifest["unseen_share"]) == {"slow", "fast"}
    assert ds.manifest["renderer_settings"]["size"] == [96, 64] and ds.manifest["renderer_settings"]["gl_renderer"]
    again = capture(["procedural:5"], out, per_scene=1, size=(96, 64))
    assert (again.written, again.skipped) == (0, 2)
    with pytest.raises(sdk.RtpError, match="other settings"):
        capture(["procedural:5"], out, per_scene=1, size=(128, 64))



def test_parallel_capture_writes_what_one_process_writes(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """`--workers 2` (make dataset's default: a process a scene) writes the same samples, byte for
    byte in every buffer, as one process, and its progress counts every sample once, to the total.
    Both report each job's viewpoints as they are planned (`rtp capture` shows it while it plans), and
    the workers' log records reach this process's loggers (`-v`: each job's planning time; they were
    lost in the worker processes, and their warnings printed bare)."""
    import logging

    from rtp.capture import BUFFERS

    scenes, kw = ["procedural:3", "procedural:4"], {"per_scene": 2, "size": (96, 64), "profiles": ("slow",)}
    planned: dict[int, list[tuple[str, int, int]]] = {1: [], 2: []}
    one = capture(scenes, tmp_path / "one", planning=lambda *a: planned[1].append(a), **kw)
    ticks: list[tuple[int, int]] = []
    with caplog.at_level(logging.INFO):
        two = capture(scenes, tmp_path / "two", workers=2, progress=lambda d, t: ticks.append((d, t)),
                      planning=lambda *a: planned[2].append(a), **kw)
    timed = [r for r in caplog.records if "viewpoint pairs planned in" in r.getMessage()]
    assert sorted(r.getMessage().partition(": ")[0] for r in timed) == [f"{s}/slow" for s in scenes]
    assert all(r.process != os.getpid() and r.name == "rtp.capture" for r in timed)
    assert (two.written, two.skipped, two.failed) == (one.written, 0, []) == (4, 0, [])
    assert ticks[-1] == (4, 4) and [d for d, _ in ticks] == sorted(d for d, _ in ticks)
    jobs = [(f"{s}/slow", k, 2) for s in scenes for k in (1, 2)]
    assert planned[1] == jobs and sorted(planned[2]) == jobs
    a, b = DatasetReader(tmp_path / "one"), DatasetReader(tmp_path / "two")
    assert a.ids == b.ids and a.manifest["unseen_share"] == b.manifest["unseen_share"]
    for sid in a.ids:
        assert a[sid].meta == b[sid].meta
        for name in BUFFERS:
            np.testing.assert_array_equal(a[sid].buffer(name), b[sid].buffer(name), err_msg=f"{sid}/{name}")

def test_a_capture_stopped_mid_sample_and_resumed_writes_what_an_uninterrupted_one_writes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A capture stopped in the middle of a sample's write (its temporary file left as a kill -9 leaves it) and
    resumed, with one worker and with two, holds the same sample ids, meta and buffers, byte for byte, and the same
    manifest (but its versions) as one that ran through: each sample is rendered from its planned cameras alone,
    whatever the renderer drew before it."""
    import shutil

    from rtp.capture import BUFFERS, _dataset

    scenes, kw = ["procedural:3", "procedural:4"], {"per_scene": 2, "size": (48, 32)}
    capture(scenes, tmp_path / "whole", **kw)
    write, calls = _dataset.DatasetWriter.write_encoded, []

    def stopped(self: _dataset.DatasetWriter, sample_id: str, data: bytes) -> Path:
        calls.append(sample_id)
        if len(calls) == 3:  # (half the bytes in the temporary file, as a process killed while writing leaves it)
            (self.samples_dir / f".{sample_id}.npz.k2j4x9ab.tmp").write_bytes(data[: len(data) // 2])
            raise KeyboardInterrupt
        return write(self, sample_id, data)

    monkeypatch.setattr(_dataset.DatasetWriter, "write_encoded", stopped)
    with pytest.raises(KeyboardInterrupt):
        capture(scenes, tmp_path / "cut1", **kw)
    monkeypatch.undo()
    assert len(DatasetReader(tmp_path / "cut1")) == 2
    shutil.copytree(tmp_path / "cut1", tmp_path / "cut2")
    for folder, workers in (("cut1", 1), ("cut2", 2)):
        again = capture(scenes, tmp_path / folder, workers=workers, **kw)
        assert (again.written, again.skipped, again.recaptured) == (6, 2, 0), folder
        assert not list((tmp_path / folder / "samples").glob(".*")), folder
        a, b = DatasetReader(tmp_path / "whole"), DatasetReader(tmp_path / folder)
        assert a.ids == b.ids and len(a) == 8
        for sid in a.ids:
            assert a[sid].meta == b[sid].meta, (folder, sid)
            for name in BUFFERS:
                np.testing.assert_array_equal(a[sid].buffer(name), b[sid].buffer(name), err_msg=f"{folder}/{sid}/{name}")
        assert {k: v for k, v in a.manifest.items() if k != "versions"} == \
            {k: v for k, v in b.manifest.items() if k != "versions"}, folder


def test_capture_survives_a_kill(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "rtp.cli", "capture", "--scene", "procedural:7", "--per-scene", "4",
           "--size", "96x64", "--profiles", "slow", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 120
    samples = out / "samples"
    while time.time() < deadline and proc.poll() is None:
        if samples.is_dir() and len(list(samples.glob("*.npz"))) >= 1:
            break
        time.sleep(0.05)
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    before = len(list(samples.glob("*.npz")))
    assert before < 4, "the run finished before it could be killed; make it longer"
    for p in samples.glob("*.npz"):  # whatever is there is a complete sample
        DatasetReader(out)[p.stem].final("1x1")
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"{4 - before} sample{'s' if before != 3 else ''} written, {before} already there" in done.stdout
    assert len(DatasetReader(out)) == 4
    assert not list(samples.glob(".*.tmp"))



def test_a_second_job_on_a_folder_being_written_is_refused_and_a_killed_one_leaves_no_lock(tmp_path: Path) -> None:
    """A second capture into a folder a first one is writing deleted the first's files in flight as
    stale and rendered the same samples again; a second targets job wrote the manifest over the first's.
    Now each takes the folder's writer lock, which the system frees when its holder dies."""
    from rtp.capture import DatasetError, TargetError, compute_targets
    from rtp.sdk.files import LOCK_NAME, writer_lock

    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "rtp.cli", "capture", "--scene", "procedural:7", "--per-scene", "30",
           "--size", "96x64", "--profiles", "slow", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    lock, deadline = out / LOCK_NAME, time.time() + 120
    try:
        while time.time() < deadline and proc.poll() is None and not (
                lock.is_file() and lock.read_text() == f"rtp capture, pid {proc.pid}"):
            time.sleep(0.05)
        assert proc.poll() is None, "the first capture ended (or never took the lock) before the second started"
        with pytest.raises(DatasetError, match=f"^{out} is being written by another capture \\(rtp capture, pid "
                                               f"{proc.pid}\\): wait for it to end, or capture into another folder"):
            capture(["procedural:7"], out, per_scene=30, size=(96, 64), profiles=("slow",))
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    before = len(DatasetReader(out))
    assert before < 30
    again = capture(["procedural:7"], out, per_scene=30, size=(96, 64), profiles=("slow",))  # no stale lock
    assert (again.written, again.skipped) == (30 - before, before)

    (out / "targets").mkdir()
    with writer_lock(out / "targets", "rtp targets", RuntimeError):  # (another open file: refused in one process too)
        with pytest.raises(TargetError, match="targets is being written by another targets job \\(rtp targets, pid "):
            compute_targets(out, ["psnr"])
    assert compute_targets(out, ["psnr"]) == 30


def test_a_capture_refused_by_the_lock_leaves_the_holders_folder_as_it_was(tmp_path: Path) -> None:
    """A capture wrote its manifest (its settings) into the folder before it asked for the folder's lock: refused
    by a capture that held the lock but had not written its manifest yet (two started at once into a new folder),
    it left its own settings there, so the holder's later write of it was refused as "captured with other settings",
    or, once past that check, described the holder's samples with the other's size. It asks for the lock first now
    and writes nothing when refused."""
    import json

    from rtp.capture import DatasetError
    from rtp.sdk.files import LOCK_NAME, writer_lock

    out = tmp_path / "ds"
    out.mkdir()
    with writer_lock(out, "rtp capture", RuntimeError):  # (a capture that holds it, before its manifest)
        with pytest.raises(DatasetError, match=f"^{out} is being written by another capture \\(rtp capture, pid "
                                               f"{os.getpid()}\\)"):
            capture(["procedural:7"], out, per_scene=1, size=(32, 32), profiles=("slow",))
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]  # no manifest, no samples folder
    done = capture(["procedural:7"], out, per_scene=1, size=(48, 32), profiles=("slow",))
    assert done.written == 1
    assert json.loads((out / "manifest.json").read_text())["settings"]["size"] == [48, 32]


def test_a_capture_into_a_folder_that_holds_nothing_yet_takes_its_settings(tmp_path: Path) -> None:
    """A capture killed or refused before its first sample left its manifest: the rerun with a corrected option
    was refused as "captured with other settings" until the folder was deleted. A folder that holds no sample takes
    the rerun's settings, as a new folder would; but only under the writer lock: a capture that holds it and has
    not written its first sample yet keeps its manifest (a second capture, refused, replaced it before asking)."""
    import json

    from rtp.capture import DatasetError, DatasetWriter
    from rtp.sdk.files import writer_lock

    out = tmp_path / "ds"
    DatasetWriter(out, {"size": [32, 32], "renderer": "rtp.plugins.moderngl reference deferred renderer"})
    with writer_lock(out, "rtp capture", RuntimeError):  # (the capture that wrote it, not yet at its first sample)
        with pytest.raises(DatasetError, match="is being written by another capture"):
            capture(["procedural:7"], out, per_scene=1, size=(48, 32), profiles=("slow",))
        assert json.loads((out / "manifest.json").read_text())["settings"]["size"] == [32, 32]
    done = capture(["procedural:7"], out, per_scene=1, size=(48, 32), profiles=("slow",))
    assert done.written == 1
    assert DatasetReader(out).manifest["settings"]["size"] == [48, 32]
    with pytest.raises(DatasetError, match="other settings"):  # (a sample there: refused as before)
        capture(["procedural:7"], out, per_scene=1, size=(32, 32), profiles=("slow",))


def _children(pid: int) -> list[int]:
    """The live processes whose parent is ``pid`` (/proc; zombies are dead)."""
    out = []
    for p in Path("/proc").iterdir():
        try:
            state, ppid = (p / "stat").read_text().rsplit(")", 1)[1].split()[:2] if p.name.isdigit() else ("Z", "0")
        except OSError:
            continue
        if int(ppid) == pid and state != "Z":
            out.append(int(p.name))
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process parents from /proc (Linux)")
def test_a_parallel_capture_killed_outright_leaves_no_process_behind(tmp_path: Path) -> None:
    """kill -9 of `rtp capture --workers 2`: every process it started exits within seconds (the pool's
    workers watch their parent; progress comes back on a plain queue, not a multiprocessing Manager,
    whose server process, with the resource tracker, ran on for good)."""
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "rtp.cli", "capture", "--scene", "procedural:3,procedural:4", "--per-scene", "20",
           "--size", "96x64", "--workers", "2", "--no-progress", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    kids: list[int] = []
    try:
        deadline = time.time() + 120
        while time.time() < deadline and proc.poll() is None:
            kids = _children(proc.pid)
            if len(kids) >= 3 and any((out / "samples").glob("*.npz")):  # two workers (and a tracker) at work
                break
            time.sleep(0.05)
        assert proc.poll() is None and len(kids) >= 3, "the capture finished or never started its workers"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.time() + 20
        while time.time() < deadline and any(_alive(k) for k in kids):
            time.sleep(0.1)
        assert not [k for k in kids if _alive(k)], "processes of the killed capture are still running"
    finally:
        for k in [proc.pid, *kids]:
            if _alive(k):
                os.kill(k, signal.SIGKILL)

def test_preview_writes_the_format_its_extension_names(tmp_path: Path) -> None:
    from PIL import Image

    from rtp.cli import main as rtp_main

    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=1, size=(96, 64), profiles=("slow",))
    for name, fmt in (("sheet.png", "PNG"), ("sheet.jpg", "JPEG")):
        assert rtp_main(["preview", str(out), "--out", str(tmp_path / name)]) == 0
        with Image.open(tmp_path / name) as im:
            assert im.format == fmt and im.size[0] > 4 * 96 and im.size[1] > 4 * 64
    with pytest.raises(SystemExit) as exc:  # refused while parsing, before the dataset is read
        rtp_main(["preview", str(out), "--out", str(tmp_path / "sheet.nope")])
    assert exc.value.code == 2 and not (tmp_path / "sheet.nope").exists()
    # an extension Pillow reads and cannot write (.psd), or cannot write RGB pixels to (.xbm: 1-bit ones alone), is
    # refused alike, not a KeyError or OSError traceback once the sheet was drawn
    for name in ("sheet.psd", "sheet.fits", "sheet.xbm", "sheet.msp"):
        with pytest.raises(SystemExit) as exc:
            rtp_main(["preview", str(out), "--out", str(tmp_path / name)])
        assert exc.value.code == 2 and not (tmp_path / name).exists()
    from rtp.capture import save_image
    from rtp.sdk import ParameterError

    with pytest.raises(ParameterError, match="not an image extension Pillow can write"):
        save_image(tmp_path / "x.psd", np.zeros((8, 8, 3), np.float32))


def test_a_scene_without_valid_views_is_skipped_not_fatal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from rtp.capture import viewpoints

    real = viewpoints.sample_viewpoints
    tried: list[float] = []

    def picky(scene, n, seed, profile="slow", **kw):  # noqa: ANN001, ANN003, ANN202
        tried.extend(kw["min_coverage"])
        if profile == "fast":
            raise viewpoints.ViewpointError("no valid viewpoint (test)")
        return real(scene, n, seed, profile, **kw)

    monkeypatch.setattr(viewpoints, "sample_viewpoints", picky)
    r = capture(["procedural:5"], tmp_path / "ds", per_scene=1, size=(96, 64))
    assert r.written == 1 and r.failed == ["procedural:5/fast"]
    assert sorted(set(tried)) == sorted(set(VIEW_COVERAGE))  # every fallback was tried before giving up
    assert DatasetReader(tmp_path / "ds").manifest["failed"] == ["procedural:5/fast"]
    # Another scene captured into the folder keeps the record (the manifest said only the last run's failures);
    # the scene captured again says anew.
    monkeypatch.setattr(viewpoints, "sample_viewpoints", real)
    assert capture(["procedural:6"], tmp_path / "ds", per_scene=1, size=(96, 64)).failed == []
    assert DatasetReader(tmp_path / "ds").manifest["failed"] == ["procedural:5/fast"]
    assert capture(["procedural:5"], tmp_path / "ds", per_scene=1, size=(96, 64)).written == 1
    assert DatasetReader(tmp_path / "ds").manifest["failed"] == []


def test_targets_on_a_device_torch_cannot_use_are_refused_before_any_work(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """``rtp targets --device`` (FLIP's port and LPIPS on a GPU): a device this torch cannot use, or a
    GPU with Ray (whose tasks get none), is refused before a target is written or declared; the CPU
    device writes the default's targets."""
    import torch

    from rtp.capture import TargetStore, compute_targets
    from rtp.cli import main as rtp_main

    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=1, size=(96, 64), profiles=("slow",))
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(torch.version, "cuda", None)
    manifest = (out / "manifest.json").read_text()
    with pytest.raises(sdk.ParameterError, match=r"device 'cuda': torch .* is a CPU build"):
        compute_targets(out, ["flip", "psnr"], device="cuda")
    with pytest.raises(sdk.ParameterError, match=r"device 'cuda:0' with ray: Ray gives a task no GPU"):
        compute_targets(out, ["flip"], device="cuda:0", ray="local")
    for workers in (0, -1, "2", 1.5):  # (0 ran as 1; -1 reached the memory check as a negative size)
        with pytest.raises(sdk.ParameterError, match="workers must be None or an integer >= 1"):
            compute_targets(out, ["psnr"], workers=workers)  # type: ignore[arg-type]
    assert rtp_main(["targets", str(out), "--metrics", "lpips", "--device", "cuda"]) == 2
    assert "rtp targets: error: --device 'cuda': torch" in capsys.readouterr().err
    store = TargetStore(out)
    assert not store.metrics and not any(store.has("procedural_5-slow-0000", m) for m in ("flip", "psnr", "lpips"))
    assert (out / "manifest.json").read_text() == manifest
    assert compute_targets(out, ["flip", "psnr"], device="cpu") == 1  # (what auto picks here)
    assert store.has("procedural_5-slow-0000", "flip")


def test_a_gpu_named_for_numpy_metrics_only_is_said_to_be_unused(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """``rtp targets --metrics psnr --device cuda`` has no torch work to place: it runs, saying so
    (the user who asked for a GPU learns none was used), on a machine without one too."""
    import logging

    import torch

    from rtp.capture import compute_targets

    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=1, size=(96, 64), profiles=("slow",))
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        assert compute_targets(out, ["psnr", "jnyang"], device="cuda") == 1
        assert compute_targets(out, ["yang"], device="cpu") == 1
    said = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert said == ["device 'cuda': psnr, jnyang run in numpy on the CPU; nothing of them runs on the device"], said


def test_samples_from_other_cameras_are_recaptured_and_their_targets_recomputed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from rtp.capture import TargetError, TargetStore, _capture, compute_targets

    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=2, size=(96, 64), profiles=("slow",))
    assert compute_targets(out, ["psnr"]) == 2
    store = TargetStore(out)
    old = DatasetReader(out)["procedural_5-slow-0001"].meta["camera"]
    # An older rtp's viewpoint stream: the same first pair, another second one.
    monkeypatch.setattr(_capture, "_job_seed", lambda seed, scene, profile: 12345)
    r = capture(["procedural:5"], out, per_scene=2, size=(96, 64), profiles=("slow",))
    assert r.recaptured == r.written == 2 and r.skipped == 0
    assert DatasetReader(out)["procedural_5-slow-0001"].meta["camera"] != old
    os.utime(store.path("procedural_5-slow-0001", "psnr"))  # (newer than the sample: its fingerprint decides)
    assert not store.has("procedural_5-slow-0001", "psnr")
    with pytest.raises(TargetError, match="out of date, of the sample as it was before it was captured again"):
        store.load("procedural_5-slow-0001", "psnr", 16)
    assert compute_targets(out, ["psnr"]) >= 1
    assert store.has("procedural_5-slow-0001", "psnr")
    again = capture(["procedural:5"], out, per_scene=2, size=(96, 64), profiles=("slow",))
    assert (again.written, again.skipped) == (0, 2)


def test_a_scene_file_of_any_format_has_its_stem_as_its_id(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """load_scene reads any existing file as a scene (a PLY, an STL), but only a glTF / GLB / OBJ name lost its
    folders and extension in its sample ids: ``room.ply`` and ``./room.ply`` were two scenes, ``room.ply`` and
    ``._room.ply`` (a hidden file), and an absolute path made ids of the whole path. Every scene file's id is its
    stem, so one file named two ways is the same scene (as ``a/arena.glb`` and ``./a/arena.glb`` are)."""
    from rtp.capture import scene_id

    (tmp_path / "room.ply").write_bytes(b"")
    monkeypatch.chdir(tmp_path)
    assert {scene_id("room.ply"), scene_id("./room.ply"), scene_id(str(tmp_path / "room.ply"))} == {"room"}
    assert scene_id("levels/arena.glb") == "arena" and scene_id("oa_dm5") == "oa_dm5"


def test_capture_takes_your_own_gltf_and_names_scenes_clearly(tmp_path: Path) -> None:
    from rtp.capture import load_scene, open_dataset, scene_id
    from rtp.capture.scenes import SceneNotFoundError, procedural
    from rtp.plugins.pyrender import to_trimesh_scene

    level = tmp_path / "levels" / "my level.glb"
    level.parent.mkdir()
    to_trimesh_scene(procedural(2)).export(level)
    r = capture([str(level)], tmp_path / "ds", per_scene=1, size=(96, 64))
    ds = open_dataset(tmp_path / "ds")
    assert r.written == 2 and ds.ids == ["my_level-fast-0000", "my_level-slow-0000"]
    assert ds[ds.ids[0]].meta["scene"] == str(level)
    assert scene_id("procedural:3") == "procedural_3" and scene_id("a/b/arena.obj") == "arena"
    for name in ("procedural", "procedural:x"):
        with pytest.raises(SceneNotFoundError, match="procedural:0"):
            load_scene(name, None, None, None)


def test_capture_cli_takes_a_scene_file_whose_name_holds_a_comma_whole(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """``--scene`` takes comma-separated lists; a file whose name holds a comma (``arena, v2.glb``) was split at it
    into the map '.../arena', which no split lists (refused), so it could not be captured. A --scene that is a file
    is one scene; a list of names is still a list."""
    from rtp.capture.scenes import procedural
    from rtp.cli import main as rtp_main
    from rtp.plugins.pyrender import to_trimesh_scene

    level = tmp_path / "lévels" / "arena, v2.glb"
    level.parent.mkdir()
    to_trimesh_scene(procedural(2, rooms=(2, 2), texture_size=32)).export(level)
    out = tmp_path / "d s"
    assert rtp_main(["capture", "-q", "--scene", str(level), "--scene", "procedural:1, procedural:2", "--per-scene",
                     "1", "--size", "32x16", "--profiles", "slow", "--out", str(out)]) == 0
    assert DatasetReader(out).ids == ["arena__v2-slow-0000", "procedural_1-slow-0000", "procedural_2-slow-0000"]
    assert DatasetReader(out)["arena__v2-slow-0000"].meta["scene"] == str(level)
    assert "3 samples written" in capsys.readouterr().out


def test_a_level_exported_as_glb_keeps_its_alpha_tests(tmp_path: Path) -> None:
    """``to_trimesh_scene`` writes each material's glTF alpha mode: MASK with the cutoff where the level
    alpha-tests (a grate), OPAQUE elsewhere. Left unset, the export wrote BLEND: a GLB of an rtp level read
    back by ``rtp capture`` drew its grates solid, and pyrender drew them in an order that changed from run
    to run (examples/pyrender_vrs.py)."""
    from rtp.capture import load_scene
    from rtp.capture.scenes import procedural
    from rtp.plugins.pyrender import to_trimesh_scene

    level = procedural(3, rooms=(2, 2), texture_size=32)
    cutoffs = {m.name: m.alpha_cutoff for m in level.materials}
    assert cutoffs["grate"] == 0.5 and sum(c is not None for c in cutoffs.values()) == 1
    path = tmp_path / "level.glb"
    to_trimesh_scene(level).export(path)
    back, _ = load_scene(str(path), None, None, None)
    used = {level.materials[m.material].name for m in level.meshes if len(m.indices)}
    assert "grate" in used
    assert sorted(m.alpha_cutoff for m in back.materials if m.alpha_cutoff is not None) == [0.5]
    assert sum(m.alpha_cutoff is None for m in back.materials) == len(back.materials) - 1


def test_preview_sheet_labels_every_panel(tmp_path: Path) -> None:
    from rtp.capture import open_dataset, preview_sheet, save_image

    capture(["procedural:4"], tmp_path / "ds", per_scene=1, size=(96, 64))
    ds = open_dataset(tmp_path / "ds")
    sheet = preview_sheet(ds[ds.ids[0]])
    assert sheet.dtype == np.uint8 and sheet.shape[0] > 4 * 64 and sheet.shape[1] > 4 * 96
    save_image(tmp_path / "sheet.jpg", sheet)
    from PIL import Image

    with Image.open(tmp_path / "sheet.jpg") as im:
        assert im.format == "JPEG"
    # past the smallest panel (160x90) a scale draws that: --scale 1000 showed one pixel a panel
    np.testing.assert_array_equal(preview_sheet(ds[ds.ids[0]], scale=1000), sheet)
    for scale in (0, -2, 1.5):  # (0 was a ZeroDivisionError)
        with pytest.raises(sdk.ParameterError, match="scale"):
            preview_sheet(ds[ds.ids[0]], scale=scale)  # type: ignore[arg-type]


def test_preview_says_whose_shadow_its_panel_shows_and_takes_no_empty_sample_id(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The shadow plane is the main light's (the reference renderer's sun) alone: indoors, under a ceiling, it is
    black where lamps light the room (the procedural levels' mean about 0.02). Its panel said '(1 = lit)', as
    if it were the lighting; it says whose shadow it is, and its mean. ``--sample ""`` drew the first sample."""
    from rtp.capture import open_dataset
    from rtp.capture._preview import _panels
    from rtp.cli import main as rtp_main

    capture(["procedural:0"], tmp_path / "ds", per_scene=1, size=(64, 48), profiles=("slow",))
    sample = open_dataset(tmp_path / "ds")[open_dataset(tmp_path / "ds").ids[0]]
    titles = [t for t, _, _ in _panels(sample)]
    shadow = [t for t in titles if "shadow" in t]
    geometry = sample.channel("depth") > 0
    assert shadow == [f"main-light (sun) shadow, 1 = lit\nmean {sample.channel('shadow')[geometry].mean():.2f}; "
                      "other lights are not in it"], titles
    assert rtp_main(["preview", str(tmp_path / "ds"), "--sample", "", "--out", str(tmp_path / "p.png")]) == 2
    assert "no sample '' in" in capsys.readouterr().err and not (tmp_path / "p.png").exists()


def test_preview_draws_the_papers_layout_saying_what_it_lacks(tmp_path: Path) -> None:
    """`rtp preview`'s help names the paper's released layout, which has no depth or metallic: the command
    failed on it ("the paper's layout has no 'depth' buffer"); those panels say so instead, and the title
    leaves out the motion profile that layout does not record ('? motion')."""
    from rtp.capture import open_dataset
    from rtp.capture._dataset import write_png
    from rtp.capture._preview import _panels
    from rtp.cli import main as rtp_main

    folder = tmp_path / "Bistro" / "0000"
    rng = np.random.default_rng(0)
    for stem in ["reproject_1x1", "diffuse_1x1", "specular_1x1", "emissive_1x1", "normals_1x1", "extra_1x1",
                 *(f"output_{r}" for r in sdk.ALL_RATES)]:
        write_png(folder / f"{stem}.png", rng.integers(0, 256, (48, 64, 4), dtype=np.uint8))
    titles = [t for t, _, _ in _panels(open_dataset(tmp_path / "Bistro")["0000"])]
    assert "depth: not in this dataset" in titles and "metallic: not in this dataset" in titles, titles
    assert "roughness" in titles and any(t.startswith("main-light (sun) shadow") for t in titles), titles
    from matplotlib.figure import Figure

    said: list[str] = []
    suptitle = Figure.suptitle
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Figure, "suptitle", lambda fig, text, **kw: said.append(text) or suptitle(fig, text, **kw))
        assert rtp_main(["preview", str(tmp_path / "Bistro"), "--out", str(tmp_path / "paper.png")]) == 0
    assert said == ["sample 0000: scene Bistro, 64x48"] and (tmp_path / "paper.png").stat().st_size > 0


def test_preview_shows_the_papers_normals_as_rtps_linear_ones(tmp_path: Path) -> None:
    """The paper's layout stores the view-space normal through an sRGB target, negatives clamped to 0; the
    preview took those stored values for the normal and applied x * 0.5 + 0.5 to them (a component of 0.5
    drawn as 0.87). It decodes them first: the panel is the linear normal's n * 0.5 + 0.5, as rtp's layout's."""
    from rtp.capture import open_dataset
    from rtp.capture._dataset import write_png
    from rtp.capture._preview import _panels

    folder = tmp_path / "Bistro" / "0000"
    rng = np.random.default_rng(0)
    for stem in ["reproject_1x1", "diffuse_1x1", "specular_1x1", "emissive_1x1", "extra_1x1",
                 *(f"output_{r}" for r in sdk.ALL_RATES)]:
        write_png(folder / f"{stem}.png", rng.integers(0, 256, (48, 64, 4), dtype=np.uint8))
    linear = np.zeros((48, 64, 3), np.float32)
    linear[:, :32] = (0.5, 0.0, 1.0)  # (negative x and y, stored as 0)
    linear[:, 32:] = (0.2, 0.6, 0.77)
    write_png(folder / "normals_1x1.png", np.concatenate([sdk.linear_to_srgb(linear), np.ones((48, 64, 1))], -1))
    ((title, panel, _),) = [p for p in _panels(open_dataset(tmp_path / "Bistro")["0000"]) if "normal" in p[0]]
    assert title == "view-space normal (x, y, z as RGB)\nthis layout stores < 0 as 0", title
    np.testing.assert_allclose(panel, linear * 0.5 + 0.5, atol=0.004)  # (8-bit sRGB, decoded: up to 0.0045 off, halved)
    assert panel[0, 0] == pytest.approx((0.75, 0.5, 1.0), abs=0.002)


def test_capture_at_eye_height_records_its_placement(tmp_path: Path) -> None:
    """--placement eye: the manifest says where the cameras stood, the cameras differ from the free
    placement's, and a folder is resumed only with the placement it was captured with."""
    out = tmp_path / "eye"
    r = capture(["procedural:5"], out, per_scene=1, size=(96, 64), profiles=("slow",), placement="eye")
    assert r.written == 1
    ds = DatasetReader(out)
    assert ds.manifest["settings"]["placement"] == "eye"
    free = tmp_path / "free"
    capture(["procedural:5"], free, per_scene=1, size=(96, 64), profiles=("slow",))
    assert "placement" not in DatasetReader(free).manifest["settings"]  # folders captured before it still resume
    assert ds["procedural_5-slow-0000"].meta["camera"] != DatasetReader(free)["procedural_5-slow-0000"].meta["camera"]
    with pytest.raises(sdk.RtpError, match="other settings"):
        capture(["procedural:5"], out, per_scene=1, size=(96, 64), profiles=("slow",))
    with pytest.raises(sdk.ParameterError, match="unknown placement"):
        capture(["procedural:5"], out, per_scene=1, size=(96, 64), placement="air")


def test_capture_checks_its_arguments_before_writing(tmp_path: Path) -> None:
    """Strings for counts were compared (a TypeError), a string of scene names or profiles was split
    into its letters, and a float size reached the renderer."""
    out = tmp_path / "ds"
    for kwargs, words in (({"per_scene": "2"}, "per_scene must be an integer"), ({"workers": 0}, "workers"),
                          ({"seed": 1.5}, "seed"), ({"size": (96.0, 64)}, "size: expected"), ({"size": (8, 64)}, "size"),
                          ({"profiles": "slow,fast"}, "unknown motion profile 'slow,fast'"),
                          ({"scene_names": [0]}, "scene_names"),
                          ({"profiles": []}, "profiles: expected one or more")):  # (recorded, it refused every later)
        args = {"scene_names": ["procedural:5"], "out": out, "per_scene": 1, "size": (96, 64), **kwargs}
        with pytest.raises(sdk.ParameterError, match=words):
            capture(**args)  # type: ignore[arg-type]
    assert not out.exists()
    r = capture("procedural:5", out, per_scene=1, size=(96, 64), profiles="slow")  # one name each, not letters
    assert r.written == 1 and DatasetReader(out).ids == ["procedural_5-slow-0000"]
    # numpy integers are integers (the seed reached the manifest's settings as a DatasetError about JSON values)
    r = capture("procedural:5", out, per_scene=np.int64(1), size=(96, 64), profiles="slow", seed=np.int64(0))
    assert (r.written, r.skipped) == (0, 1) and DatasetReader(out).manifest["settings"]["seed"] == 0


def test_sigterm_unwinds_a_capture_as_ctrl_c_does(tmp_path: Path) -> None:
    """`kill`, `timeout` and job schedulers send SIGTERM: it killed a capture outright (exit 143, no account of
    what was kept, multiprocessing's leaked-semaphore warnings). It unwinds as Ctrl-C now: the workers stop,
    the samples written are kept and named, the exit is 143, and the same command captures the rest."""
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "rtp.cli", "capture", "--scene", "procedural:7", "--per-scene", "40",
           "--size", "96x64", "--profiles", "slow", "--workers", "2", "--no-progress", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None and not list((out / "samples").glob("*.npz")):
        time.sleep(0.05)
    assert proc.poll() is None, "the capture ended before a sample was written"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    kept = len(DatasetReader(out))
    assert proc.returncode == 143, err
    assert f"rtp capture: terminated; {kept} of 40 samples are in {out} (each written whole)" in err, err
    assert "Traceback" not in err and "leaked" not in err
    assert not _children(proc.pid)
    again = capture(["procedural:7"], out, per_scene=40, size=(96, 64), profiles=("slow",))
    assert (again.written, again.skipped) == (40 - kept, kept)


def test_a_resumed_capture_captures_a_damaged_sample_again(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A sample file damaged since it was written (truncated by a full disk or a copy) stopped the resume with
    "unreadable sample" and no way on but deleting it by hand; it is captured again, saying so."""
    out = tmp_path / "ds"
    first = capture(["procedural:7"], out, per_scene=2, size=(96, 64), profiles=("slow",))
    assert first.written == 2
    damaged = out / "samples" / "procedural_7-slow-0000.npz"
    damaged.write_bytes(damaged.read_bytes()[:5000])
    with caplog.at_level("WARNING", logger="rtp.capture"):
        again = capture(["procedural:7"], out, per_scene=2, size=(96, 64), profiles=("slow",))
    assert (again.written, again.skipped, again.recaptured) == (1, 1, 0)
    assert any(f"{damaged}: unreadable sample" in r.getMessage() and r.getMessage().endswith("captured again")
               for r in caplog.records)
    assert DatasetReader(out)["procedural_7-slow-0000"].buffer("depth").shape == (64, 96)


def test_a_damaged_sample_of_another_scene_does_not_fail_the_capture_after_its_work(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A sample of a scene not captured now, damaged since (truncated by a full disk or a copy), failed the capture
    of another scene into the folder at its very end, "unreadable sample", after its samples were written: the
    manifest was not written, and every later capture of any other scene failed the same way. It is named in a
    warning and left out of the manifest's unseen_share; a capture of its own scene captures it again."""
    out = tmp_path / "ds"
    kw: dict = {"per_scene": 1, "size": (64, 48), "profiles": ("slow",)}
    assert capture(["procedural:5"], out, **kw).written == 1
    damaged = out / "samples" / "procedural_5-slow-0000.npz"
    damaged.write_bytes(damaged.read_bytes()[:5000])
    with caplog.at_level("WARNING", logger="rtp.capture"):
        assert capture(["procedural:6"], out, **kw).written == 1
    assert any(r.getMessage().startswith(f"{damaged}: unreadable sample") and "left out of the manifest's "
               "unseen_share" in r.getMessage() for r in caplog.records), [r.getMessage() for r in caplog.records]
    manifest = DatasetReader(out).manifest
    assert "procedural_6-slow-0000" in manifest["samples"]
    only = DatasetReader(out)["procedural_6-slow-0000"].meta["unseen"]
    assert manifest["unseen_share"] == {"slow": pytest.approx(only)}
    again = capture(["procedural:5"], out, **kw)
    assert (again.written, again.skipped) == (1, 0)
    assert DatasetReader(out)["procedural_5-slow-0000"].buffer("depth").shape == (48, 64)


def test_a_scene_whose_sample_ids_the_folder_holds_from_another_scene_is_refused(tmp_path: Path) -> None:
    """`_check_scene_ids` refused two files of one name in one run; across runs into one folder (`b/x.glb` after
    `a/x.glb`, `procedural_5.glb` after `procedural:5`) the second captured its samples over the first's, each
    said to come "from other cameras than this rtp plans". Now it is refused before anything is written, naming
    both scenes; the scene's own name resumes as before."""
    from rtp.capture import DatasetError
    from rtp.capture.scenes import procedural
    from rtp.plugins.pyrender import to_trimesh_scene

    for sub, seed in (("a", 2), ("b", 3)):
        (tmp_path / sub).mkdir()
        to_trimesh_scene(procedural(seed, rooms=(2, 2), texture_size=32)).export(tmp_path / sub / "x.glb")
    out = tmp_path / "ds"
    first, other = str(tmp_path / "a" / "x.glb"), str(tmp_path / "b" / "x.glb")
    assert capture([first], out, per_scene=1, size=(64, 48), profiles=("slow",)).written == 1
    before = (out / "samples" / "x-slow-0000.npz").read_bytes()
    announced: list[int] = []
    with pytest.raises(DatasetError, match=re.escape(f"captured from the scene '{first}', not '{other}'")):
        capture([other], out, per_scene=1, size=(64, 48), profiles=("slow",), starting=announced.append)
    assert (out / "samples" / "x-slow-0000.npz").read_bytes() == before and not announced
    again = capture([first], out, per_scene=1, size=(64, 48), profiles=("slow",))
    assert (again.written, again.skipped, again.recaptured) == (0, 1, 0)


def test_a_folder_without_its_manifest_refuses_samples_of_another_size(tmp_path: Path) -> None:
    """A capture into a folder whose manifest was deleted adopted the samples there whatever their size (those
    planned from the same cameras skipped as done), and `rtp train` refused the mix much later: a sample of
    another size than the one asked for is named, with both sizes, before anything is written or deleted."""
    from rtp.capture import DatasetError

    out = tmp_path / "ds"
    assert capture(["procedural:5"], out, per_scene=1, size=(96, 64), profiles=("slow",)).written == 1
    (out / "manifest.json").unlink()
    before = {p.name: p.read_bytes() for p in (out / "samples").iterdir()}
    sample = out / "samples" / "procedural_5-slow-0000.npz"
    # (192x128: the same aspect, so the same cameras: the sample was skipped as already captured)
    with pytest.raises(DatasetError, match=rf"no manifest.json, .*{sample} is 96x64, --size \(size=\) 192x128"):
        capture(["procedural:5"], out, per_scene=1, size=(192, 128), profiles=("slow",))
    assert {p.name: p.read_bytes() for p in (out / "samples").iterdir()} == before  # (nothing deleted or added)
    assert not (out / "manifest.json").exists()
    # the samples' own size resumes it (the manifest written again)
    again = capture(["procedural:5"], out, per_scene=1, size=(96, 64), profiles=("slow",))
    assert (again.written, again.skipped) == (0, 1) and DatasetReader(out).manifest["settings"]["size"] == [96, 64]


def test_a_scene_or_profile_given_twice_and_scenes_sharing_sample_ids_are_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`--scene procedural:3,procedural:3` planned and rendered the scene twice (with --workers 2 in two
    processes at once: '4 samples written (1 of them replace samples from other cameras)'), `--profiles
    slow,slow` said 2 samples and wrote 1, and two files of one name (a/x.glb, b/x.obj) captured their
    samples over each other's: each is refused before anything is written, by its flag on the command line."""
    from rtp.cli import main as rtp_main

    out = tmp_path / "ds"
    for kwargs, words in (({"scene_names": ["procedural:3", "procedural:3"]}, "scene_names: each scene once"),
                          ({"profiles": ["slow", "slow"]}, "profiles: each motion profile once"),
                          ({"scene_names": ["a/x.glb", "b/x.obj"]}, "scene_names: 'a/x.glb' and 'b/x.obj' both make")):
        args = {"scene_names": ["procedural:3"], "out": out, "per_scene": 1, "size": (64, 48), **kwargs}
        with pytest.raises(sdk.ParameterError, match=words):
            capture(**args)  # type: ignore[arg-type]
    for argv, said in ((["--scene", "procedural:3", "--scene", "procedural:3"], "--scene: each scene once"),
                       (["--scene", "procedural:3", "--profiles", "slow,slow"], "--profiles: each motion profile once")):
        assert rtp_main(["capture", *argv, "--per-scene", "1", "--size", "64x48", "--out", str(out)]) == 2
        assert f"rtp capture: error: {said}" in capsys.readouterr().err
    assert not out.exists()


def test_a_capture_refused_is_not_announced_first(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp capture --scene procedural:3,procedural:3` printed "capture: ... = 4 samples at 64x48 ..." and then
    the library's refusal: a job that never ran was announced. The line comes once the library has checked
    everything (capture's ``starting``), and a job that runs still says it, first."""
    from rtp.cli import main as rtp_main

    out = tmp_path / "ds"
    for argv in (["--scene", "procedural:3,procedural:3"], ["--scene", "procedural:3", "--profiles", "slow,slow"],
                 ["--scene", str(tmp_path / "missing.glb")]):
        assert rtp_main(["capture", *argv, "--per-scene", "1", "--size", "64x48", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "rtp capture: error: " in err and "samples at" not in err and "capture:" not in err.split("rtp capture")[0]
    assert not out.exists()
    said: list[int] = []
    report = capture(["procedural:3"], out, per_scene=1, size=(64, 48), profiles=("slow",), starting=said.append,
                     progress=lambda done, total: said.append(-done))
    assert report.written == 1 and said == [1, -1]  # (once, with the samples asked for, before the first progress)
    assert rtp_main(["capture", "--scene", "procedural:3", "--profiles", "slow", "--per-scene", "1", "--size", "64x48",
                     "--out", str(out)]) == 0
    assert ("capture: procedural:3 x 1 motion profiles x 1 pairs = 1 samples at 64x48"
            in capsys.readouterr().err)


def test_more_workers_than_scenes_say_how_many_processes_render(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                               caplog: pytest.LogCaptureFixture) -> None:
    """`rtp capture --scene procedural:3 --workers 4` rendered in one process without a word (rtp play says so
    of its paths): the warning comes after the announcement, before any work (stopped there)."""
    from rtp.capture import _capture

    class Stop(Exception):
        pass

    def stop(*args: object, **kwargs: object) -> None:
        raise Stop

    monkeypatch.setattr(_capture, "worker_pool", stop)
    caplog.set_level("WARNING", logger="rtp.capture")
    said: list[str] = []
    with pytest.raises(Stop):
        capture(["procedural:3"], tmp_path / "ds", per_scene=1, size=(64, 48), profiles=("slow",), workers=4,
                starting=lambda n: said.append(caplog.text))
    assert said == [""] and "workers 4 for 1 scene: a process a scene at most, so one process renders it" in caplog.text
    caplog.clear()
    with pytest.raises(Stop):
        capture(["procedural:3", "procedural:4"], tmp_path / "ds", per_scene=1, size=(64, 48), profiles=("slow",),
                workers=2)
    assert "a process a scene at most" not in caplog.text  # (as many workers as scenes: nothing to say)


def test_a_scene_file_whose_sample_ids_would_be_too_long_is_refused_up_front(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A scene file of a name of about 190 characters was planned and rendered, and failed at its first sample's
    write (the sample id past the 200 characters a sample file's name may have). Refused before anything is
    written, naming the limit and how long the name may be."""
    from rtp.capture._capture import _check_id_length
    from rtp.capture._dataset import MAX_ID_LENGTH
    from rtp.cli import main as rtp_main

    stem = "s" * (MAX_ID_LENGTH - len("-slow-0000"))  # (190: the longest for the default profiles, one sample each)
    _check_id_length([f"levels/{stem}.obj"], ("slow", "fast"), 1)
    for profiles, per_scene in ((("frame",), 1), (("slow",), 10001)):  # (a longer profile, a fifth digit)
        with pytest.raises(sdk.ParameterError, match=f"more than the {MAX_ID_LENGTH} a sample id may have"):
            _check_id_length([f"levels/{stem}.obj"], profiles, per_scene)
    scene = tmp_path / f"{stem}x.obj"
    scene.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    out = tmp_path / "ds"
    with pytest.raises(sdk.ParameterError, match=r"makes sample ids of up to 201 characters .*more than the 200 a "
                                                 r"sample id may have .*at most 190 characters"):
        capture([str(scene)], out, per_scene=1, size=(64, 48))
    assert rtp_main(["capture", "--scene", str(scene), "--per-scene", "1", "--size", "64x48", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "rtp capture: error: --scene: " in err and "shorten its file name without the extension" in err
    assert not out.exists()


def test_an_empty_out_is_refused_not_the_current_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp capture --out ""` (an unset shell variable) wrote the dataset into the current folder, as
    capture(out="") did: Path('') is '.'. Every --out of a folder or file is refused so."""
    from rtp.cli import main as rtp_main

    monkeypatch.chdir(tmp_path)
    with pytest.raises(sdk.ParameterError, match="out: expected a dataset folder path, got ''"):
        capture(["procedural:3"], "", per_scene=1, size=(64, 48))
    with pytest.raises(SystemExit) as exit_info:
        rtp_main(["capture", "--scene", "procedural:3", "--per-scene", "1", "--size", "64x48", "--out", ""])
    assert exit_info.value.code == 2
    assert "argument --out: expected a path, got ''" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_targets_take_one_metric_name_and_refuse_none_and_a_weber_l_that_is_no_number(tmp_path: Path) -> None:
    """compute_targets(data, 'psnr') read the name's letters ('unknown metric p'), an empty list computed nothing
    and returned 0, and weber_l='0.5' was declared as a string, so that every later run, the command line's 0.5
    included, was refused as targets of other parameters."""
    from rtp.capture import TargetStore, compute_targets

    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=1, size=(64, 48), profiles=("slow",))
    for kwargs, words in (({"metrics": ()}, "metrics: expected a metric name or a non-empty list"),
                          ({"metrics": ("jnyang",), "weber_l": "0.5"}, "weber_l: expected a number, got '0.5'"),
                          ({"metrics": ("jnyang",), "weber_l": True}, "weber_l: expected a number")):
        with pytest.raises(sdk.ParameterError, match=words):
            compute_targets(out, **kwargs)  # type: ignore[arg-type]
    assert not TargetStore(out).metrics
    assert compute_targets(out, "psnr") == 1  # (one name, not its letters)
    assert compute_targets(out, ("jnyang", "jnyang"), weber_l=np.float32(0.5)) == 1  # (a float32 declared as a float)
    assert TargetStore(out).metrics == {"psnr": {}, "jnyang": {"weber_l": 0.5}}


def test_a_weber_l_so_large_that_no_model_could_learn_the_targets_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp targets --weber-l 1e308` was taken: it was declared and wrote all-zero JNYang targets (a JN target is at
    most 1 / weber_l). A weber_l past MAX_WEBER_L, whose targets are all below the smallest mu_y a model's transform
    takes, is refused before anything is declared, as one that is not finite or not > 0; the paper's 1e-10, the
    default 0.02 and MAX_WEBER_L itself are taken."""
    import shutil

    from rtp.capture import MAX_WEBER_L, TargetStore, compute_targets
    from rtp.cli import main as rtp_main

    # (the bound is the transforms': a mean target of 1 / MAX_WEBER_L is a mu_y a model takes, one below it is not)
    sdk.Transform.clamped(1 / MAX_WEBER_L)
    with pytest.raises(sdk.MetadataError, match="mu_y"):
        sdk.Transform.clamped(0.5 / MAX_WEBER_L)
    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=1, size=(64, 48), profiles=("slow",))
    for bad, words in ((1e308, r"weber_l: expected at most 1e\+06, got 1e\+308"),
                       (MAX_WEBER_L * 1.01, r"weber_l: expected at most 1e\+06"),
                       (float("inf"), "must be finite and > 0"), (float("nan"), "must be finite and > 0"),
                       (0.0, "must be finite and > 0"), (-0.02, "must be finite and > 0")):
        with pytest.raises(sdk.ParameterError, match=words):
            compute_targets(out, ("jnyang",), weber_l=bad)
    assert rtp_main(["targets", str(out), "--metrics", "jnyang", "--weber-l", "1e308"]) == 2
    assert "rtp targets: error: --weber-l: expected at most 1e+06, got 1e+308" in capsys.readouterr().err
    assert not TargetStore(out).metrics
    for good in (1e-10, 0.02, MAX_WEBER_L):
        assert compute_targets(out, ("jnyang",), weber_l=good) == 1
        values = TargetStore(out).load("procedural_5-slow-0000", "jnyang", 4)
        assert np.isfinite(values).all() and values.max() > 0
        shutil.rmtree(out / "targets")


def test_worker_pools_start_a_process_a_job_at_most(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`--workers 4` on one scene (capture) or one sample (targets) started four processes, three idle, each
    of the working one's threads a quarter of the cores (and a warning of more processes than cores)."""
    import contextlib

    from rtp.capture import _capture, _pool, compute_targets

    asked: list[int] = []

    @contextlib.contextmanager
    def pool(workers: int, ticks: object = None) -> object:
        asked.append(workers)
        raise KeyboardInterrupt  # (nothing to run: the size asked for is what is checked)
        yield

    out = tmp_path / "ds"
    capture(["procedural:5", "procedural:6"], out, per_scene=1, size=(64, 48), profiles=("slow",))
    monkeypatch.setattr(_capture, "worker_pool", pool)
    monkeypatch.setattr(_pool, "worker_pool", pool)
    with pytest.raises(KeyboardInterrupt):
        capture(["procedural:5"], out, per_scene=2, size=(64, 48), profiles=("slow",), workers=4)
    with pytest.raises(KeyboardInterrupt):
        compute_targets(out, ("psnr",), workers=4)
    assert asked == [1, 2]  # (one scene; two samples)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_workers_failure_names_the_scene_or_sample_it_was_on(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                               workers: int) -> None:
    """A bug's exception in a capture or targets job (not an rtp error) came back from a local worker as a
    bare traceback of the worker's code, without the scene or sample it was on (the Ray path names it). It
    keeps its type, whatever catches it still does, and a note under its traceback names the scene or
    sample; an rtp error, whose one line names what it is about, and a broken pool are left as they were.
    The pool is a pool of threads here, so that the job's function can be replaced (what comes back from a
    process is the same)."""
    import contextlib
    from concurrent.futures import ThreadPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    from rtp.capture import _capture, _pool, _targets, compute_targets

    @contextlib.contextmanager
    def pool(n: int, ticks: object = None) -> object:
        with ThreadPoolExecutor(n) as ex:
            yield ex

    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=2, size=(64, 48), profiles=("slow",))
    monkeypatch.setattr(_capture, "worker_pool", pool)
    monkeypatch.setattr(_pool, "worker_pool", pool)

    def run_job(scene: str, *args: object, queue: object = None, checked: bool = False) -> object:
        if scene == "procedural:6":
            raise ZeroDivisionError("a bug")
        return _capture.CaptureReport()

    monkeypatch.setattr(_capture, "_run_job", run_job)
    with pytest.raises(ZeroDivisionError, match="a bug") as err:
        capture(["procedural:5", "procedural:6"], tmp_path / "two", per_scene=1, size=(64, 48), profiles=("slow",),
                workers=workers)
    assert getattr(err.value, "__notes__", None) == ["(rtp: raised while working on scene 'procedural:6')"]

    failing = sorted(DatasetReader(out).ids)[1]

    def compute_one(data_root: str, sample_id: str, *args: object) -> str:
        if sample_id == failing:
            raise KeyError("a bug")
        return sample_id

    monkeypatch.setattr(_targets, "_compute_one", compute_one)
    with pytest.raises(KeyError, match="a bug") as err:
        compute_targets(out, ("psnr",), workers=workers)
    assert getattr(err.value, "__notes__", None) == [f"(rtp: raised while working on sample {failing!r})"]

    for error in (_targets.TargetError("cannot be read"), BrokenProcessPool("a worker was killed")):
        # (a broken pool's error reaches every task still pending, not only the one whose worker was killed)
        def compute_none(data_root: str, sample_id: str, *args: object, error: Exception = error) -> str:
            raise error

        monkeypatch.setattr(_targets, "_compute_one", compute_none)
        with pytest.raises(type(error)) as other:
            compute_targets(out, ("psnr",), workers=workers)
        assert not hasattr(other.value, "__notes__")


def test_a_targets_worker_killed_names_the_samples_in_flight(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A local targets worker killed outright (the system's out-of-memory killer, a signal) broke the pool, and
    `rtp targets --workers 2` ended on BrokenProcessPool's traceback, "A process in the process pool was
    terminated abruptly", naming no sample and not saying what was kept. It is now a one-line rtp error (exit 1)
    naming the samples then in flight (a sample a worker at a time: the third was never started), still a
    BrokenProcessPool. The pool is a pool of threads whose every task fails as a broken pool's do."""
    import contextlib
    from concurrent.futures import ThreadPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    from rtp.capture import WorkerDiedError, _pool, _targets, compute_targets

    @contextlib.contextmanager
    def pool(n: int, ticks: object = None) -> object:
        with ThreadPoolExecutor(n) as ex:
            yield ex

    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=3, size=(64, 48), profiles=("slow",))
    ids = sorted(DatasetReader(out).ids)
    started: list[str] = []

    def compute_one(data_root: str, sample_id: str, *args: object) -> str:
        started.append(sample_id)
        raise BrokenProcessPool("A process in the process pool was terminated abruptly")

    monkeypatch.setattr(_pool, "worker_pool", pool)
    monkeypatch.setattr(_targets, "_compute_one", compute_one)
    with pytest.raises(WorkerDiedError) as err:
        compute_targets(out, ("psnr",), workers=2)
    assert isinstance(err.value, BrokenProcessPool) and err.value.exit_code == 1
    assert str(err.value) == (f"a targets worker process died (killed by the system, out of memory?, or by a signal) "
                              f"while computing one of samples {ids[0]!r}, {ids[1]!r}; the targets of 0 of 3 samples "
                              f"are kept: the same command computes the rest")
    assert sorted(started) == ids[:2]


def test_a_capture_worker_killed_names_the_scenes_not_captured(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A local capture worker killed outright broke the pool, and `rtp capture --workers 2` ended on
    BrokenProcessPool's traceback, naming no scene (name_task leaves broken pools alone: every pending task gets
    one). It is now a one-line rtp error naming the scenes not captured, still a BrokenProcessPool, and the scene a
    worker finished is kept. The pool is a pool of threads whose killed task fails as a broken pool's do."""
    import contextlib
    from concurrent.futures import ThreadPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    from rtp.capture import WorkerDiedError, _capture

    @contextlib.contextmanager
    def pool(n: int, ticks: object = None) -> object:
        with ThreadPoolExecutor(1) as ex:  # (one at a time: the first scene is done before the second dies)
            yield ex

    run_job = _capture._run_job

    def killed(scene: str, *args: object, **kwargs: object) -> object:
        if scene == "procedural:6":
            raise BrokenProcessPool("A process in the process pool was terminated abruptly")
        return run_job(scene, *args, **kwargs)

    monkeypatch.setattr(_capture, "worker_pool", pool)
    monkeypatch.setattr(_capture, "_run_job", killed)
    out = tmp_path / "ds"
    with pytest.raises(WorkerDiedError) as err:
        capture(["procedural:5", "procedural:6"], out, per_scene=1, size=(64, 48), profiles=("slow",), workers=2)
    assert isinstance(err.value, BrokenProcessPool) and err.value.exit_code == 1
    assert str(err.value) == ("a capture worker process died (killed by the system, out of memory?, or by a signal) "
                              "before scene 'procedural:6' was captured; the samples written are kept: the same "
                              "command captures the rest")
    assert [i for i in DatasetReader(out).ids if i.startswith("procedural_5")]


def test_a_resumed_capture_drawn_with_other_renderer_settings_says_so(tmp_path: Path,
                                                                      caplog: pytest.LogCaptureFixture) -> None:
    """The samples a resumed capture adds drawn with other renderer settings than the folder's (another rtp
    version's defaults: frames up to 128 px drew a 1024-texel shadow map before 2026-12-07) are said to mix."""
    import json

    out = tmp_path / "ds"
    capture(["procedural:1"], out, per_scene=1, size=(64, 48), profiles=("slow",))
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        capture(["procedural:1"], out, per_scene=2, size=(64, 48), profiles=("slow",))
    assert "other renderer settings" not in caplog.text  # (the same renderer)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["renderer_settings"]["shadow_map_size"] == 256
    manifest["renderer_settings"]["shadow_map_size"] = 1024  # (as rtp before 2026-12-07 drew them)
    (out / "manifest.json").write_text(json.dumps(manifest))
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        report = capture(["procedural:1"], out, per_scene=3, size=(64, 48), profiles=("slow",))
    assert report.written == 1 and report.skipped == 2
    assert ("the 1 samples written now were drawn with other renderer settings than the samples there "
            "(shadow_map_size 1024 before, 256 now; another rtp version's defaults)") in caplog.text


def test_targets_all_there_with_workers_start_no_pool(tmp_path: Path) -> None:
    """`rtp targets DATA --workers 2` rerun on a dataset whose targets are all there asked for a pool of no
    process (a process a sample at most, and no sample to do): ProcessPoolExecutor's ValueError "max_workers
    must be greater than 0" and its traceback. It now does nothing and says so; a pool of no worker is a
    typed error naming ``workers``."""
    from rtp.capture import compute_targets
    from rtp.capture._pool import worker_pool

    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=1, size=(64, 48), profiles=("slow",))
    seen: list[tuple[int, int]] = []
    assert compute_targets(out, ("psnr",)) == 1
    assert compute_targets(out, ("psnr",), workers=2, progress=lambda d, t: seen.append((d, t))) == 0
    assert seen == [(1, 1)]
    for bad in (0, -1, True, 1.5):
        with pytest.raises(sdk.ParameterError, match=r"^workers: expected an integer >= 1"):
            with worker_pool(bad):  # type: ignore[arg-type]
                pass


def test_a_scene_files_warnings_are_said_once_by_a_capture(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """``rtp capture`` reads a mesh file in its check before any work and again in the worker that renders it: each of
    the file's warnings (a texture it cannot read) was said twice, the second time minutes later, as if of another
    file. The worker now logs them at DEBUG; a load with no check before it still warns."""
    from rtp.capture import load_scene
    from rtp.capture.scenes import procedural
    from rtp.plugins.pyrender import to_trimesh_scene

    level = tmp_path / "level.obj"
    to_trimesh_scene(procedural(2, rooms=(1, 1), texture_size=16)).export(level)
    (tmp_path / "crate.png").unlink()

    def said() -> list[str]:
        return [r.getMessage() for r in caplog.records
                if r.levelno == logging.WARNING and "crate.png" in r.getMessage()]

    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        capture([str(level)], tmp_path / "ds", per_scene=1, size=(64, 48), profiles=("slow",))
    assert len(said()) == 1, said()
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        load_scene(str(level), None, None, None)  # (no check ran: the warning is said)
    assert len(said()) == 1, said()
