"""Capture and targets on a local Ray cluster (2 CPUs): the same samples and targets as the local
path, and a worker killed mid-task loses nothing (issue 10)."""

from __future__ import annotations

import logging
import os
import re
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import ray

from rtp.capture import BUFFERS, DatasetReader, TargetStore, capture, compute_targets
from rtp.capture._dataset import sample_path
from rtp.capture._ray import RayExecutorError, ray_cluster
from rtp.capture._targets import sample_fingerprint

#: How a refusal past memory ends (a regex): the variable that lets the job run anyway.
HINT = r" \(RTP_MEMORY_CHECK=warn runs it anyway\)$"

pytestmark = pytest.mark.gl

SCENES = ["procedural:3", "procedural:4"]
SIZE = (96, 64)
METRICS = ("flip", "psnr", "lpips", "jnflip", "jnyang")


@pytest.fixture(scope="module")
def cluster() -> Iterator[None]:
    # (address "local": a private instance, not the cluster RAY_ADDRESS names or `ray start` began on this machine)
    ray.init(address="local", num_cpus=2, include_dashboard=False, configure_logging=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def local(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference: the same capture and targets through the local path (targets in a pool of two
    one-thread workers like the Ray workers: torch's convolutions round the last bit of LPIPS
    differently with another thread count, about 6e-8)."""
    out = tmp_path_factory.mktemp("local") / "ds"
    capture(SCENES, out, per_scene=2, size=SIZE)
    compute_targets(out, METRICS, workers=2)
    return out


def assert_same_dataset(a: Path, b: Path, metrics: tuple[str, ...] = ()) -> None:
    ra, rb = DatasetReader(a), DatasetReader(b)
    assert ra.ids == rb.ids and len(ra.ids) == len(SCENES) * 2 * 2
    for sid in ra.ids:
        sa, sb = ra[sid], rb[sid]
        assert sa.meta == sb.meta
        for name in BUFFERS:
            np.testing.assert_array_equal(sa.buffer(name), sb.buffer(name), err_msg=f"{sid}/{name}")
    ta, tb = TargetStore(a), TargetStore(b)
    assert ta.metrics == tb.metrics
    for sid in ra.ids:
        for m in metrics:
            np.testing.assert_array_equal(ta.load(sid, m, 4), tb.load(sid, m, 4), err_msg=f"{sid}/{m}")
            # (each records its sample's fingerprint, as read: the Ray path's from the bytes it sent)
            fingerprints = {str(np.load(t.path(sid, m))["sample"]) for t in (ta, tb)}
            assert fingerprints == {str(sample_fingerprint(sample_path(b, sid)))}, (sid, m)
    assert not list((b / "samples").glob(".*")) and not list((b / "targets").rglob(".*.tmp"))


def test_ray_capture_and_targets_equal_the_local_path(cluster: None, local: Path, tmp_path: Path,
                                                      caplog: pytest.LogCaptureFixture) -> None:
    import logging

    out = tmp_path / "ray"
    seen: list[tuple[int, int]] = []
    planned: list[tuple[str, int, int]] = []
    with caplog.at_level(logging.INFO):
        report = capture(SCENES, out, per_scene=2, size=SIZE, workers=2, ray="local",
                         progress=lambda d, t: seen.append((d, t)), planning=lambda *a: planned.append(a))
    # the workers' log records reach this process's loggers (-v: each job's planning time)
    timed = [r for r in caplog.records if "viewpoint pairs planned in" in r.getMessage()]
    assert sorted(r.getMessage().partition(": ")[0] for r in timed) == sorted(
        f"{s}/{p}" for s in SCENES for p in ("slow", "fast"))
    assert all(r.process != os.getpid() for r in timed)
    assert (report.written, report.skipped, report.failed) == (8, 0, [])
    assert seen[-1] == (8, 8) and [d for d, _ in seen] == sorted(d for d, _ in seen)
    # each job's pairs as its worker finds them (its first at once, through the queue actor), then all
    heard: dict[str, list[int]] = {}
    for job, found, asked in planned:
        assert asked == 2
        heard.setdefault(job, []).append(found)
    assert sorted(heard) == sorted(f"{s}/{p}" for s in SCENES for p in ("slow", "fast"))
    assert all(v[0] == 1 and v[-1] == 2 and v == sorted(v) for v in heard.values()), heard
    assert report.renderer and set(report.unseen) == {"slow", "fast"}
    assert compute_targets(out, METRICS, workers=2, ray="local") == 8
    assert_same_dataset(local, out, METRICS)
    # Resumes like the local path: nothing left to do.
    again = capture(SCENES, out, per_scene=2, size=SIZE, workers=2, ray="local")
    assert (again.written, again.skipped) == (0, 8)
    assert compute_targets(out, METRICS, ray="local") == 0


def test_ray_capture_places_cameras_as_asked(cluster: None, tmp_path: Path) -> None:
    """--placement reaches the Ray workers' plans: eye-height cameras, the local path's exactly."""
    kw: dict[str, Any] = {"per_scene": 1, "size": SIZE, "profiles": ("slow",), "placement": "eye"}
    capture(SCENES[:1], tmp_path / "local", **kw)
    capture(SCENES[:1], tmp_path / "ray", workers=1, ray="local", **kw)
    a, b = DatasetReader(tmp_path / "local"), DatasetReader(tmp_path / "ray")
    assert b.manifest["settings"]["placement"] == "eye"
    assert a.ids == b.ids and all(a[i].meta["camera"] == b[i].meta["camera"] for i in a.ids)


def _killer(victims: list[int]) -> tuple[Any, Any]:
    """An ``on_actors`` hook noting the workers' pids and a progress callback that SIGKILLs the first
    worker right after the first sample lands (it has another sample queued, so it dies mid-task)."""
    killed: list[int] = []

    def on_actors(actors: list[Any]) -> None:
        victims.extend(ray.get([a.pid.remote() for a in actors]))

    def progress(done: int, total: int) -> None:
        if done >= 1 and not killed:
            os.kill(victims[0], signal.SIGKILL)
            killed.append(victims[0])

    return on_actors, progress


def test_a_lost_planning_queue_loses_only_the_planning_news(cluster: None, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch,
                                                             caplog: pytest.LogCaptureFixture) -> None:
    """The workers' planning counts travel through a queue actor: if it is gone (killed, its node
    lost), the workers plan on and the driver reports each job when planned, as it did before."""
    import ray.util.queue

    real = ray.util.queue.Queue

    def dead_queue(*args: Any, **kwargs: Any) -> Any:
        q = real(*args, **kwargs)
        ray.kill(q.actor)
        return q

    monkeypatch.setattr(ray.util.queue, "Queue", dead_queue)
    planned: list[tuple[str, int, int]] = []
    report = capture(SCENES[:1], tmp_path / "ds", per_scene=1, size=SIZE, profiles=("slow",), workers=1, ray="local",
                     planning=lambda *a: planned.append(a))
    assert report.written == 1 and planned == [(f"{SCENES[0]}/slow", 1, 1)]
    assert "progress and logs are lost" in caplog.text


def test_a_stopped_capture_does_not_announce_retries(tmp_path: Path) -> None:
    """Ctrl-C during a Ray capture printed "(raylet) Task _CaptureWorker.render failed. There are 3
    retries remaining, so the task will be retried" under the bar: the workers were killed with tasks
    queued. Those tasks are cancelled first; the samples written stay, and the capture resumes. (Its
    own process: the message reaches a driver that started its Ray, as `rtp capture --ray local` does.)"""
    import subprocess
    import sys

    out = tmp_path / "ds"
    script = f"""
import time
from rtp.capture import capture
def stop(done, total):
    if done >= 1:
        raise KeyboardInterrupt
try:
    capture({SCENES!r}, {str(out)!r}, per_scene=4, size={SIZE!r}, workers=2, ray="local", progress=stop)
except KeyboardInterrupt:
    time.sleep(3)  # (Ray's messages reach the driver's stderr from a thread)
"""
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "RAY_DEDUP_LOGS": "0"})
    assert run.returncode == 0, run.stderr
    assert "retries remaining" not in run.stdout + run.stderr, run.stdout  # (Ray prints them on stdout)
    # nor the private instance's start-up lines ("Token authentication is enabled for this Ray cluster")
    assert "Token authentication" not in run.stderr, run.stderr
    written = len(DatasetReader(out).ids)
    assert written >= 1
    again = capture(SCENES, out, per_scene=4, size=SIZE, workers=2)
    assert (again.skipped, again.written) == (written, 16 - written)


def test_a_worker_killed_mid_task_loses_nothing(cluster: None, local: Path, tmp_path: Path) -> None:
    out = tmp_path / "ray"
    victims: list[int] = []
    on_actors, progress = _killer(victims)
    report = capture(SCENES, out, per_scene=2, size=SIZE, workers=2, ray="local", progress=progress,
                     _on_ray_actors=on_actors)
    assert report.written == 8 and victims
    with pytest.raises(ProcessLookupError):
        os.kill(victims[0], 0)  # it really died
    victims.clear()
    on_actors, progress = _killer(victims)
    assert compute_targets(out, METRICS, workers=2, ray="local", progress=progress, _on_ray_actors=on_actors) == 8
    assert_same_dataset(local, out, METRICS)


def test_ray_errors_are_typed(cluster: None, tmp_path: Path) -> None:
    # A bad scene fails on the worker with the same typed error the local path raises.
    from rtp.capture.scenes import SceneNotFoundError

    with pytest.raises(SceneNotFoundError):
        capture(["procedural:x"], tmp_path / "ds", per_scene=1, size=SIZE, ray="local")
    ray.shutdown()
    try:
        with pytest.raises(RayExecutorError, match="cannot start or reach Ray"), ray_cluster("127.0.0.1:1", 1):
            pass
        with pytest.raises(RayExecutorError, match="HOST:PORT"), ray_cluster("no-port", 1):
            pass
        # a new folder is made only once Ray answers (it was made, manifest and all, before connecting)
        with pytest.raises(RayExecutorError, match="cannot start or reach Ray"):
            capture(["procedural:0"], tmp_path / "new", per_scene=1, size=SIZE, ray="127.0.0.1:1")
        assert not (tmp_path / "new").exists()
    finally:
        ray.init(address="local", num_cpus=2, include_dashboard=False, configure_logging=False)


def test_a_head_address_is_parsed_as_ray_parses_it_ipv6_in_brackets() -> None:
    """`--ray [::1]:6379` (Ray's form of an IPv6 address) was looked up with its brackets and said "nothing
    answers there"; a bare `::1` was host ':' port 1, and said the same; port 99999 was connected to as
    port 34463. Each is now parsed as Ray does, or refused saying what is expected."""
    import socket

    from rtp.capture._ray import _check_reachable

    # (the address the check connects to, whatever IPv6 this machine has: a skip for a missing loopback would fail
    # CI, which allows none)
    asked: list[tuple[str, int]] = []

    class Answered:
        def close(self) -> None:
            pass

    def connect(address: tuple[str, int], timeout: float) -> Answered:
        asked.append(address)
        return Answered()

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(socket, "create_connection", connect)
        _check_reachable("[::1]:6379", timeout=2)  # (something answers: no error)
        _check_reachable("ray://[fe80::1]:10001", timeout=2)
    assert asked == [("::1", 6379), ("fe80::1", 10001)]
    for bare in ("::1", "fe80::1", "::1:6379"):
        with pytest.raises(RayExecutorError, match=r"IPv6 address goes in brackets.*\[::1\]:6379"):
            _check_reachable(bare, timeout=2)
    for odd in ("[::1]", "[::1]6379", "[]:6379", "[::1:6379", "127.0.0.1:99999", "127.0.0.1:0"):
        with pytest.raises(RayExecutorError, match=r"expected 'local', 'auto', HOST:PORT, \[IPV6\]:PORT"):
            _check_reachable(odd, timeout=2)


def test_a_damaged_sample_on_ray_is_named_by_its_file(cluster: None, local: Path, tmp_path: Path) -> None:
    """A worker reads the bytes the driver sent: its error said "sample X (in memory)", not which file to fix."""
    import shutil

    from rtp.capture import DatasetError

    data = tmp_path / "ds"
    shutil.copytree(local, data)
    shutil.rmtree(data / "targets")
    damaged = sorted((data / "samples").glob("*.npz"))[0]
    damaged.write_bytes(damaged.read_bytes()[:5000])
    with pytest.raises(DatasetError, match=f"^{damaged}: unreadable sample"):
        compute_targets(data, ["psnr"], ray="local")


def test_cli_ray_flag(cluster: None, local: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from rtp.cli import main

    out = tmp_path / "cli"
    scenes = ",".join(SCENES)
    assert main(["capture", "--scene", scenes, "--per-scene", "2", "--size", "96x64", "--out", str(out),
                 "--ray", "--workers", "2", "--no-progress"]) == 0
    assert main(["targets", str(out), "--ray", "--no-progress"]) == 0
    assert "8 samples written" in capsys.readouterr().out
    assert_same_dataset(local, out, METRICS)


def test_ray_clients_native_lines_go_to_the_verbose_log(capfd: pytest.CaptureFixture[str],
                                                        caplog: pytest.LogCaptureFixture) -> None:
    """Ray's C++ client wrote a retry line a second for 20 s to file descriptor 2, above the error:
    they are logged instead, at INFO (-v shows them; DEBUG, where they were, no option shows)."""
    import logging

    from rtp.capture._ray import _native_stderr_to_log

    with caplog.at_level(logging.INFO, logger="rtp.capture"), pytest.raises(RuntimeError):
        with _native_stderr_to_log():
            os.write(2, b"gcs_client.cc:210: Failed to get cluster ID\n")
            raise RuntimeError("ray.init failed")
    os.write(2, b"after\n")
    assert capfd.readouterr().err == "after\n"
    assert "ray: gcs_client.cc:210: Failed to get cluster ID" in caplog.text


def test_without_ray_installed_the_flag_says_what_to_install(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """rtp[ray] is optional: without it `--ray` is a one-line error naming the extra, and nothing is
    written (Ray is the only way the flag can run)."""
    import sys

    from rtp.cli import main

    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ImportError
    with pytest.raises(RayExecutorError, match=r"--ray needs Ray: pip install 'rtp\[ray\]'"):
        capture(["procedural:0"], tmp_path / "ds", per_scene=1, size=SIZE, ray="local")
    assert main(["capture", "--scene", "procedural:0", "--per-scene", "1", "--size", "96x64", "--ray",
                 "--no-progress", "--out", str(tmp_path / "ds")]) == 2
    assert "pip install 'rtp[ray]'" in capsys.readouterr().err
    assert not (tmp_path / "ds").exists()


@pytest.mark.parametrize("address", ["head.example", ":99999", "::1:6379", "", "ray://", "[::1]6379"])
def test_a_malformed_ray_address_is_refused_before_the_job_is_announced(
    address: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--ray head.example` (no port), `:99999`, `::1:6379` or `--ray ""` was refused only on connecting, after the
    "capture: ... = N samples" line (a refusal `starting` promises never to follow), and not at all where a Ray was
    already running in the process (it was used, whatever the address). The form is checked with the other
    arguments now, without Ray (none can be imported here) and before any sample is read: capture and targets."""
    import sys

    from rtp.capture._ray import check_ray_address
    from rtp.cli import main

    monkeypatch.setitem(sys.modules, "ray", None)  # (a syntax check: import ray would raise ImportError)
    expected = r"Ray address .*(expected 'local', 'auto', HOST:PORT|IPv6 address goes in brackets)"
    with pytest.raises(RayExecutorError, match=expected):
        check_ray_address(address)
    out = tmp_path / "ds"
    assert main(["capture", "--scene", "procedural:0", "--per-scene", "1", "--size", "96x64", "--no-progress",
                 "--out", str(out), "--ray", address]) == 2
    err = capsys.readouterr().err
    assert "samples at 96x64" not in err and len(err.splitlines()) == 1 and re.search(expected, err), err
    assert not out.exists()
    with pytest.raises(RayExecutorError, match=expected):  # (before the folder is read: it need not exist)
        compute_targets(tmp_path / "no-dataset", ["psnr"], ray=address)
    assert main(["targets", str(tmp_path / "no-dataset"), "--metrics", "psnr", "--no-progress", "--ray", address]) == 2
    assert re.search(expected, capsys.readouterr().err.splitlines()[-1])
    for fine in (None, "local", "auto"):
        assert check_ray_address(fine) is None
    assert check_ray_address("ray://[::1]:10001") == ("::1", 10001) and check_ray_address(":6379") == ("", 6379)
    with pytest.raises(RayExecutorError, match="got int 6379"):
        check_ray_address(6379)


def test_each_ray_nodes_workers_are_sized_against_its_memory(cluster: None, local: Path, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """On a cluster the driver cannot see where the frames are drawn: each worker reports its node's
    memory and the driver adds up the workers of each node before anything is drawn or written (a
    16384x16384 capture holds about 193 GiB a worker; machines like this one have 24)."""
    import json
    import shutil

    from rtp.capture import TargetError, _capture, job_bytes
    from rtp.sdk import ParameterError

    # the disk check comes first (two such samples take 2.7 GB or more): a machine with less free refused it
    # there, and this test is about memory
    monkeypatch.setattr(_capture.shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**13, 0, 10**13))

    one = job_bytes("capture", (16384, 16384))
    with pytest.raises(ParameterError, match=rf"^size: a capture at 16384x16384 holds about {2 * one / 2**30:.1f} GiB "
                                             rf"on Ray node \w+ \({one / 2**30:.1f} GiB in each of its 2 workers\), more "
                                             r"than its [\d.]+ GiB of memory and swap: a smaller size" + HINT) as info:
        capture(["procedural:1"], tmp_path / "new", per_scene=1, size=(16384, 16384), workers=2, ray="auto")
    assert info.value.name == "size" and not (tmp_path / "new").exists()
    # its workers are ended with the job, in a Ray the caller started too (they held its two CPUs, and
    # the next job's workers waited for them for good)
    deadline = time.monotonic() + 30
    while ray.available_resources().get("CPU", 0) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    assert ray.available_resources().get("CPU", 0) == 2
    # a dataset whose manifest says its samples are that large: its targets are refused the same way
    data = tmp_path / "big"
    shutil.copytree(local, data, ignore=shutil.ignore_patterns("targets"))
    manifest = json.loads((data / "manifest.json").read_text())
    manifest["settings"]["size"] = [16384, 16384]
    (data / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(TargetError, match=r"^data: the flip, psnr targets of its 16384x16384 samples take about .* on "
                                          r"Ray node \w+, more than its .* a node with more memory" + HINT):
        compute_targets(data, ("flip", "psnr"), workers=1, ray="auto")
    assert not list((data / "targets").rglob("*.npz"))


def test_a_finished_folder_needs_no_cluster(local: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """capture --ray into a folder that holds every planned sample (from the cameras planned for it) plans on
    this machine and says so, without reaching for Ray (it failed where no head answered); a folder that
    lacks one sample, or holds one from other cameras, goes to Ray as before."""
    import json
    import shutil

    from rtp.capture import _ray

    class Reached(Exception):
        pass

    def reached(*args: Any, **kwargs: Any) -> None:
        raise Reached

    monkeypatch.setattr(_ray, "ray_capture", reached)
    out = tmp_path / "ds"
    shutil.copytree(local, out)
    report = capture(SCENES, out, per_scene=2, size=SIZE, ray="127.0.0.1:1")
    assert (report.written, report.skipped, report.failed) == (0, 8, [])
    assert_same_dataset(local, out, METRICS)
    ids = DatasetReader(out).ids
    sample = next((out / "samples").glob(f"{ids[0]}*"))
    moved = tmp_path / sample.name
    sample.rename(moved)
    with pytest.raises(Reached):
        capture(SCENES, out, per_scene=2, size=SIZE, ray="127.0.0.1:1")
    moved.rename(sample)
    meta_file = out / "manifest.json"
    assert json.loads(meta_file.read_text())  # (the folder is whole again)
    monkeypatch.setattr("rtp.capture._capture._job_seed", lambda seed, scene, profile: seed + 1)  # other cameras
    with pytest.raises(Reached):
        capture(SCENES, out, per_scene=2, size=SIZE, ray="127.0.0.1:1")


class _FakeRay:
    """A stand-in for the ``ray`` module whose ``init`` records the CPUs asked for in ``calls`` and raises
    ``raises``; ``shutdown`` records "shutdown"."""

    def __init__(self, calls: list[Any], raises: BaseException) -> None:
        self.calls, self.raises = calls, raises

    def is_initialized(self) -> bool:
        return False

    def init(self, **kwargs: Any) -> None:
        self.calls.append(kwargs.get("num_cpus"))
        raise self.raises

    def shutdown(self) -> None:
        self.calls.append("shutdown")


def test_a_ray_start_that_fails_or_is_interrupted_shuts_down_what_it_started(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A private instance whose ray.init failed or was interrupted half-way (its GCS server and raylet started)
    is shut down: those processes ran on until the process ended, and the next ray.init started another
    beside them. Its workers are the cores this process may run on (a container's, a batch job's), not
    every core of the machine (os.cpu_count)."""
    from rtp.capture import _ray

    calls: list[Any] = []
    fake = _FakeRay(calls, RuntimeError("the raylet did not start in time"))
    monkeypatch.setattr(_ray, "_ray", lambda: fake)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2}, raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 64)
    with pytest.raises(RayExecutorError, match="cannot start or reach Ray at 'local': the raylet did not start"):
        with ray_cluster("local", None):
            pass
    assert calls == [3, "shutdown"]
    calls.clear()
    fake.raises = KeyboardInterrupt()
    with pytest.raises(KeyboardInterrupt):
        with ray_cluster(None, 2):
            pass
    assert calls == [2, "shutdown"]


@pytest.mark.timeout(180)
def test_more_workers_than_the_cluster_has_cpus_or_the_job_samples_start_what_can_work(
        cluster: None, local: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A worker takes one of Ray's CPUs: `--ray auto --workers 3` on a cluster of 2 CPUs started a third
    worker that was never placed, and the job waited on that worker's samples (and first on its memory
    report) for good, without a word. It starts the 2 the cluster has, with a warning; and never more
    workers than the job has samples (each holds a renderer or a network)."""
    caplog.set_level(logging.INFO, logger="rtp.capture")
    with ray_cluster("auto", 3) as n:
        assert n == 2
    assert "3 Ray workers on a Ray cluster of 2 CPUs: 2 workers" in caplog.text
    with ray_cluster("auto", 3, 1) as n:
        assert n == 1
    with ray_cluster("auto", None, 1) as n:
        assert n == 1
    started: list[int] = []
    out = tmp_path / "ds"
    report = capture(SCENES[:1], out, per_scene=2, size=SIZE, workers=3, ray="auto",
                     _on_ray_actors=lambda actors: started.append(len(actors)))
    assert started == [2] and (report.written, report.skipped) == (4, 0)
    for sid in DatasetReader(out).ids:
        assert sample_path(out, sid).read_bytes() == sample_path(local, sid).read_bytes(), sid


def test_a_private_instances_workers_are_counted_as_ray_starts_them(
        local: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """`--ray --workers N` on this machine: the memory checked before Ray starts is that of the workers
    Ray starts, a sample each at most, of any scene (capture counted a worker a scene: `--workers 1000` on
    one scene passed as one process and then started 1000; targets counted all N for 8 samples), and
    more workers than cores are warned of, as a local pool's processes are."""
    from rtp.capture import _capture, _ray, _targets
    from rtp.sdk import ParameterError

    counted: list[Any] = []

    def fake_check(job: str, size: Any, *, processes: int = 1, **kw: Any) -> None:
        counted.append(processes)
        raise ParameterError("stop here", "size")

    monkeypatch.setattr(_capture, "check_frame_memory", fake_check)
    with pytest.raises(ParameterError, match="stop here"):
        capture(["procedural:1"], local.parent / "never", per_scene=3, size=SIZE, workers=1000, ray="local")
    assert counted == [6]  # one scene x 2 profiles x 3 pairs

    def fake_targets_check(reader: Any, metrics: Any, workers: int | None, ray: str | None) -> None:
        counted.append(workers)
        raise _targets.TargetError("stop here")

    monkeypatch.setattr(_targets, "_check_memory", fake_targets_check)
    counted.clear()
    with pytest.raises(_targets.TargetError, match="stop here"):
        compute_targets(local, ("psnr",), workers=1000, ray="local")
    assert counted == [8]

    inits: list[Any] = []
    monkeypatch.setattr(_ray, "_ray", lambda: _FakeRay(inits, RuntimeError("no start here")))
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    caplog.set_level(logging.WARNING, logger="rtp.capture")
    with pytest.raises(RayExecutorError, match="no start here"), ray_cluster("local", 1000, 5):
        pass
    assert inits == [5, "shutdown"] and "5 Ray workers on the 2 cores this process may run on" in caplog.text


def test_rays_own_failures_name_the_sample_and_are_typed() -> None:
    """A task that fails with Ray's own error (a worker killed by Ray's memory monitor, an object store full,
    a node lost) stops the job with a RayWorkerError naming the sample, as a worker that died does; it was
    Ray's exception itself, a traceback naming no sample."""
    from rtp.capture import _ray

    class FakeRay:
        exceptions = ray.exceptions

        @staticmethod
        def wait(refs: list[Any], num_returns: int, timeout: float | None) -> tuple[list[Any], list[Any]]:
            return refs[:1], refs[1:]

        @staticmethod
        def get(ref: Any) -> Any:
            raise ray.exceptions.OutOfMemoryError("Task was killed due to the node running low on memory.")

    done: list[Any] = []
    with pytest.raises(_ray.RayWorkerError, match=r"^sample 'procedural_3-slow-0001' failed on Ray "
                                                  r"\(OutOfMemoryError\).*rerun to resume: Task was killed") as err:
        _ray._drive(FakeRay, ["actor"], {"ref": (0, "procedural:3", ("procedural_3-slow-0001",))},
                    {"procedural:3": 1}, lambda i: False, lambda t, r: done.append(t), "sample", None)
    assert err.value.exit_code == 1 and done == []


def test_a_ray_capture_into_a_folder_without_a_manifest_removes_a_killed_writes_files(
        cluster: None, local: Path, tmp_path: Path) -> None:
    """A folder that lost its manifest (or never got one) but holds a killed write's temporary file: the Ray
    path makes its writer itself, and removed no stale files (capture() removes them only where it makes it)."""
    out = tmp_path / "ray"
    (out / "samples").mkdir(parents=True)
    stale = out / "samples" / ".procedural-3-slow-0000.npz.k2j4x9ab.tmp"
    stale.write_bytes(b"half a sample")
    report = capture(SCENES, out, per_scene=2, size=SIZE, workers=2, ray="local")
    assert (report.written, report.failed) == (8, [])
    assert not stale.exists() and not list((out / "samples").glob(".*"))
    assert DatasetReader(out).ids == DatasetReader(local).ids


def test_a_private_instance_is_started_where_a_cluster_is_named_or_running(monkeypatch: pytest.MonkeyPatch) -> None:
    """`--ray` alone starts a private instance (docs/scaling.md), but ray.init without an address joins the
    cluster RAY_ADDRESS names, or the one `ray start --head` began on this machine, and failed there:
    "cannot start or reach Ray at 'local': When connecting to an existing cluster, num_cpus and num_gpus must
    not be provided". The private instance is started whatever the environment names."""
    was = ray.is_initialized()
    if was:
        ray.shutdown()
    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:1")
    try:
        with ray_cluster("local", 1) as n:
            assert n == 1 and ray.cluster_resources().get("CPU") == 1
        assert not ray.is_initialized()
    finally:
        monkeypatch.delenv("RAY_ADDRESS")
        if was:
            ray.init(address="local", num_cpus=2, include_dashboard=False, configure_logging=False)


def test_a_cluster_that_wants_its_token_says_how_to_give_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """A head that `ray start` began asks for its authentication token, which Ray sends to an address named to it
    only with RAY_AUTH_MODE=token: the error said only "Failed to connect to Ray cluster at ..." (its cause,
    the token, under -v). It now says what to set; another failure does not."""
    from rtp.capture import _ray

    class FakeRay:
        raises: BaseException = RuntimeError("")

        @staticmethod
        def is_initialized() -> bool:
            return False

        @staticmethod
        def init(**kwargs: Any) -> None:
            raise FakeRay.raises

        @staticmethod
        def shutdown() -> None:
            pass

    def failed(cause: str) -> ConnectionError:
        try:  # (as Ray 2.60 raises it: the AuthenticationError only in the text of the error under it)
            try:
                raise RuntimeError(f"Failed to connect to GCS. Last connection error: Traceback ...\n{cause}")
            except RuntimeError as exc:
                raise ConnectionError("Failed to connect to Ray cluster at 192.0.2.2:6390") from exc
        except ConnectionError as exc:
            return exc

    monkeypatch.setattr(_ray, "_ray", lambda: FakeRay)
    FakeRay.raises = failed("ray.exceptions.AuthenticationError: RPC error: InvalidAuthToken: Authentication token "
                            "is missing or incorrect.")
    with pytest.raises(RayExecutorError, match=r"^cannot start or reach Ray at 'auto': Failed to connect to Ray "
                                               r"cluster at 192\.0\.2\.2:6390; .*authentication token.*: set "
                                               r"RAY_AUTH_MODE=token, .*`ray get-auth-token`"):
        with ray_cluster("auto", None):
            pass
    FakeRay.raises = failed("TimeoutError: the GCS did not answer")
    with pytest.raises(RayExecutorError, match="Failed to connect") as err:
        with ray_cluster("auto", None):
            pass
    assert "RAY_AUTH_MODE" not in str(err.value)


def test_a_cluster_stopped_under_the_job_is_said_to_be_gone() -> None:
    """`ray stop` on the head in the middle of a job said "a Ray worker died 4 times on sample ...": no worker had
    died four times, the cluster was gone. Where its head no longer answers, the error says so (and how to
    resume); where it answers, a dead worker is reported as before."""
    import socket

    from rtp.capture import _ray

    class FakeRay:
        exceptions = ray.exceptions
        gcs_address = ""

        @staticmethod
        def wait(refs: list[Any], num_returns: int, timeout: float | None) -> tuple[list[Any], list[Any]]:
            return refs[:1], refs[1:]

        @staticmethod
        def get(ref: Any) -> Any:
            raise ray.exceptions.RayActorError()

        @staticmethod
        def get_runtime_context() -> Any:
            return FakeRay

    def drive() -> _ray.RayWorkerError:
        with pytest.raises(_ray.RayWorkerError) as err:
            _ray._drive(FakeRay, ["actor"], {"ref": (0, "procedural:3", ("procedural_3-slow-0001",))},
                        {"procedural:3": 1}, lambda i: False, lambda t, r: None, "sample", None)
        return err.value

    with socket.socket() as head:
        head.bind(("127.0.0.1", 0))
        head.listen()
        FakeRay.gcs_address = f"127.0.0.1:{head.getsockname()[1]}"
        assert str(drive()).startswith("a Ray worker died 4 times on sample 'procedural_3-slow-0001'")
    # (the port now closed: nothing answers there)
    message = str(drive())
    assert message.startswith(f"the Ray cluster is gone (its head at {FakeRay.gcs_address} does not answer) while "
                              "on sample 'procedural_3-slow-0001'"), message
    assert message.endswith("start the cluster again and rerun to resume")
