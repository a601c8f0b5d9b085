"""Outputs that do not fit on the disk: every writer goes through rtp.sdk.files.atomic_output, which
names the file it could not write. A full disk was a traceback ending "OSError: [Errno 28] No space
left on device" in `rtp capture`, `rtp targets` and `rtp play` (no file named, so the error policy
took it for a bug), a torch "enforce fail" in `rtp train`, "torch.onnx.export failed" in
`rtp-export`; `rtp play` left its GIF's `.tmp` behind.

The commands run in processes whose files may not grow past a few bytes (RLIMIT_FSIZE: a write past
it fails with EFBIG, "File too large", as a write to a full disk fails with ENOSPC: neither names a
file), so no disk has to be filled."""

from __future__ import annotations

import errno
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from rtp.sdk.files import atomic_output


def test_atomic_output_names_the_file_a_write_into_an_open_file_could_not_grow(tmp_path: Path) -> None:
    target = tmp_path / "model.onnx"
    target.write_bytes(b"the previous model")
    with pytest.raises(OSError) as e:
        with atomic_output(target) as tmp:
            tmp.write_bytes(b"half")
            raise OSError(errno.ENOSPC, "No space left on device")  # what f.write raises on a full disk
    assert (e.value.errno, e.value.strerror, e.value.filename) == (errno.ENOSPC, "No space left on device", str(target))
    assert isinstance(e.value.__cause__, OSError) and e.value.__cause__.filename is None
    assert target.read_bytes() == b"the previous model" and sorted(p.name for p in tmp_path.iterdir()) == ["model.onnx"]
    with pytest.raises(PermissionError) as denied:  # the errno's own class, as OSError(errno, ...) gives it
        with atomic_output(target):
            raise OSError(errno.EACCES, "")
    assert denied.value.filename == str(target) and denied.value.strerror == "Permission denied"
    for kept in (FileNotFoundError(errno.ENOENT, "No such file or directory", "/elsewhere/input.npz"),  # names its file
                 OSError("not a system error")):  # (no errno: not the file system's)
        with pytest.raises(OSError) as other:
            with atomic_output(target):
                raise kept
        assert other.value is kept
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.onnx"]


def test_atomic_output_names_the_file_when_its_temporary_file_cannot_be_made(tmp_path: Path,
                                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """A folder that takes no new file (read-only, out of inodes): mkstemp's error named the temporary file
    (".model.onnx.k2j4x9ab.tmp"), not the one the user asked for."""
    import tempfile

    target = tmp_path / "model.onnx"

    def refused(*args: object, **kwargs: object) -> tuple[int, str]:
        raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / ".model.onnx.k2j4x9ab.tmp"))

    monkeypatch.setattr(tempfile, "mkstemp", refused)
    with pytest.raises(PermissionError) as e:
        with atomic_output(target):
            pass
    assert (e.value.errno, e.value.filename) == (errno.EACCES, str(target))


def _limited(limit: int) -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))  # (CPython ignores SIGXFSZ: the write fails with EFBIG)


#: How each command runs here (the console scripts' entry points, with this interpreter).
_COMMANDS = {"rtp": [sys.executable, "-m", "rtp"],
             "rtp-export": [sys.executable, "-c", "import sys; from rtp.cli import export_main; sys.exit(export_main())"]}


def _run(args: list[str], limit: int, cwd: Path) -> subprocess.CompletedProcess[str]:
    """The command ``args`` in a process whose files may not grow past ``limit`` bytes (not followed by
    ``make coverage``: its data file would not grow either)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("COVERAGE")}
    return subprocess.run([*_COMMANDS[args[0]], *args[1:]], capture_output=True, text=True, timeout=300, cwd=cwd,
                          env=env, preexec_fn=lambda: _limited(limit))


def _said(run: subprocess.CompletedProcess[str], prog: str, path: Path, note: str = "") -> None:
    """One line naming the file (and ``note``, a worker's note of its scene), exit 1, and no temporary file left
    beside it."""
    assert run.returncode == 1, run.stderr
    assert run.stderr.strip().splitlines()[-1] == f"{prog}: error: File too large: {str(path)!r}{note}", run.stderr
    assert "Traceback" not in run.stderr
    assert not list(path.parent.glob(".*.tmp")) and not list(path.parent.glob("*.tmp"))


@pytest.mark.gl
def test_a_capture_that_cannot_write_its_sample_names_it_and_leaves_nothing(tmp_path: Path) -> None:
    out = tmp_path / "data"
    run = _run(["rtp", "-q", "capture", "--scene", "procedural:1", "--per-scene", "1", "--profiles", "slow",
                "--size", "160x96", "--out", str(out)], 20_000, tmp_path)
    _said(run, "rtp capture", out / "samples" / "procedural_1-slow-0000.npz",
          " (rtp: raised while working on scene 'procedural:1')")


def test_training_and_export_that_cannot_write_their_files_name_them(tmp_path: Path) -> None:
    from rtp.cli import main as rtp_main

    from .test_train import _dataset

    data = _dataset(tmp_path / "d", n=6)
    ckpt = tmp_path / "m.pt"
    args = ["train", "--data", str(data), "--metric", "jnyang", "--steps", "2", "--batch", "2", "--crop", "32",
            "--arch", "fast", "--val-scenes", "scene0", "--out", str(ckpt)]
    _said(_run(["rtp", "-q", *args], 4_000, tmp_path), "rtp train", ckpt)
    assert not ckpt.exists()
    assert rtp_main(["-q", *args]) in (0, 1)  # (1: an output the two steps left constant; the file is kept either way)
    assert ckpt.is_file()
    onnx = tmp_path / "m.onnx"
    _said(_run(["rtp-export", "-q", str(ckpt), "--out", str(onnx)], 4_000, tmp_path), "rtp-export", onnx)
    assert not onnx.exists()


@pytest.mark.gl
def test_a_closed_loop_that_cannot_write_its_report_names_the_file_and_leaves_no_tmp(tmp_path: Path) -> None:
    out = tmp_path / "play"
    run = _run(["rtp", "-q", "play", "procedural:0", "--path", "fast", "--frames", "3", "--size", "64x48", "--methods",
                "oracle", "--no-sweep", "--out", str(out)], 2_000, tmp_path)
    assert run.returncode == 1, run.stderr
    last = run.stderr.strip().splitlines()[-1]
    assert last.startswith(f"rtp play: error: File too large: '{out}/") and "Traceback" not in run.stderr, run.stderr
    # (a folder the run made and left empty is removed with it)
    assert not out.exists() or not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]


def _free(monkeypatch: pytest.MonkeyPatch, free: int) -> None:
    """The disk of every folder has ``free`` bytes free (what ``rtp.capture`` reads of it)."""
    import shutil

    from rtp.capture import _capture

    monkeypatch.setattr(_capture.shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**13, 10**13 - free, free))


@pytest.mark.gl
def test_a_capture_whose_samples_cannot_fit_on_the_disk_is_refused_before_anything_is_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """`rtp capture --per-scene 1000000000` planned two billion viewpoints in silence (34,000 TB of
    samples); a capture past the disk filled it and stopped hours in. Refused now from the samples'
    least size on disk, naming per_scene, before the folder is made."""
    from rtp.cli import main as rtp_main

    _free(monkeypatch, 10**8)
    out = tmp_path / "data"
    assert rtp_main(["capture", "--scene", "procedural:1", "--per-scene", "1000", "--size", "160x96", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        "rtp capture: error: --per-scene: 2,000 samples at 160x96 take at least 0.2 GB on disk (typically 0.6 GB), more "
        f"than the 0.1 GB free in {str(tmp_path)!r}: fewer samples, or --out on a larger disk")
    assert not out.exists()


def test_the_disk_check_counts_the_samples_already_written_and_warns_past_their_typical_size(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    from rtp import sdk
    from rtp.capture import check_disk

    out = tmp_path / "data"
    (out / "samples").mkdir(parents=True)
    for i in range(3):
        (out / "samples" / f"s{i}.npz").write_bytes(b"")
    _free(monkeypatch, 0)
    check_disk(out, (1280, 720), 3)  # all written: a resumed capture writes nothing
    with pytest.raises(sdk.ParameterError, match=r"^per_scene: 1 samples at 1280x720 take at least 0.0 GB") as e:
        check_disk(out, (1280, 720), 4)
    assert e.value.name == "per_scene"
    _free(monkeypatch, 10**10)  # 10 GB: 1,000 samples at least 4.6 GB, typically 17.0
    with caplog.at_level("WARNING", logger="rtp.capture"):
        check_disk(out, (1280, 720), 1003)
    assert "1,000 samples at 1280x720 take about 17.0 GB on disk, more than the 10.0 GB free in" in caplog.text
    assert "it resumes where it stopped" in caplog.text
    caplog.clear()
    _free(monkeypatch, 2 * 10**10)
    check_disk(tmp_path / "new" / "deeper", (1280, 720), 1000)  # a folder not made yet: its first existing parent's disk
    assert not caplog.text


@pytest.mark.gl
def test_the_disk_check_counts_only_the_jobs_own_samples_as_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A capture of a new scene into a folder holding another scene's samples counted those as its own, written:
    1,000 samples of procedural:1 there and 1,000 of procedural:2 asked for were "nothing to write", and the capture
    started on a disk they could not fit on. Only the job's own ids (scene, profile, index below per_scene) count."""
    from rtp import sdk
    from rtp.capture import capture, check_disk

    out = tmp_path / "data"
    (out / "samples").mkdir(parents=True)
    for profile in ("slow", "fast"):
        for i in range(500):
            (out / "samples" / f"procedural_1-{profile}-{i:04d}.npz").write_bytes(b"")
    _free(monkeypatch, 10**7)  # 10 MB: 1,000 samples at 160x96 take at least 0.08 GB

    def started(total: int) -> None:
        raise AssertionError(f"the capture of {total} samples started")

    with pytest.raises(sdk.ParameterError, match=r"^per_scene: 1,000 samples at 160x96 take at least 0\.1 GB") as e:
        capture(["procedural:2"], out, per_scene=500, size=(160, 96), starting=started)
    assert e.value.name == "per_scene"
    # the job's own samples count as written: procedural:1 resumed, its other profile and indices past per_scene not
    check_disk(out, (160, 96), 1000, scene_names=["procedural:1"], profiles=["slow", "fast"])
    with pytest.raises(sdk.ParameterError, match=r"^per_scene: 300 samples at 160x96"):
        check_disk(out, (160, 96), 600, scene_names=["procedural:1"], profiles=["slow", "frame"])
    _free(monkeypatch, 10**5)  # (2 samples: 0.15 MB at least)
    with pytest.raises(sdk.ParameterError, match=r"^per_scene: 2 samples at 160x96"):
        check_disk(out, (160, 96), 1002, scene_names=["procedural:1"], profiles=["slow", "fast"])
    # (without the job's scenes and profiles, every sample in the folder counts, as before)
    check_disk(out, (160, 96), 1000)
    with pytest.raises(sdk.ParameterError, match=r"^samples: expected per_scene for each of the 2 scene and profile"):
        check_disk(out, (160, 96), 1001, scene_names=["procedural:1"], profiles=["slow", "fast"])
    with pytest.raises(sdk.ParameterError, match=r"^scene_names and profiles: expected both"):
        check_disk(out, (160, 96), 1000, scene_names=["procedural:1"])
    assert not (out / "manifest.json").exists()


def test_a_killed_writes_temporary_file_is_removed_by_the_next_write(tmp_path: Path) -> None:
    """A write killed outright (kill -9: no cleanup ran) left `.model.onnx.XXXXXXXX.tmp` beside the file for good,
    every rerun adding another. The next write of the same file removes it once no live process holds it (each
    write holds an flock on its own) and it is a minute old; a live write's, a young one's and other files stay."""
    import fcntl
    import signal
    import time

    target = tmp_path / "model.onnx"
    code = ("import sys, time; from rtp.sdk.files import atomic_output\n"
            f"with atomic_output({str(target)!r}) as tmp:\n"
            "    tmp.write_bytes(b'half'); print(tmp, flush=True); time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    killed = Path(proc.stdout.readline().strip())
    # while it lives, its file is held: not removed even when old
    os.utime(killed, (time.time() - 3600, time.time() - 3600))
    with atomic_output(target) as tmp:
        tmp.write_bytes(b"one")
    assert killed.exists()
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    young = tmp_path / ".model.onnx.youngabc.tmp"
    held = tmp_path / ".model.onnx.heldabcd.tmp"
    other = tmp_path / ".other.onnx.abcdefgh.tmp"
    for p in (young, held, other):
        p.write_bytes(b"x")
    for p in (held, other):
        os.utime(p, (time.time() - 3600, time.time() - 3600))
    with open(held, "rb") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)  # (a live writer's)
        with atomic_output(target) as tmp:
            tmp.write_bytes(b"two")
    assert target.read_bytes() == b"two"
    assert not killed.exists() and young.exists() and held.exists() and other.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["model.onnx", young.name, held.name, other.name])
