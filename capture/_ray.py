"""Capture and targets on a Ray cluster: ``rtp capture --ray [ADDRESS]``, ``rtp targets --ray [ADDRESS]``.

The local process pool stays the default on one machine; Ray spreads the same work over a cluster
(docs/scaling.md). The design:

* **one long-lived actor per worker** holds what is expensive to set up: a capture worker its GL
  context and the scene it rendered last (a scene loads once per worker, not once per sample), a
  target worker the LPIPS network and torch's threads;
* **one task per sample**: the driver plans (each scene's viewpoints are planned by a worker, which
  keeps that scene loaded), skips what is on disk exactly as the local path does, and keeps every
  worker two samples deep, preferring samples of the scene the worker already holds;
* **no shared filesystem needed**: a capture worker returns the sample's ``.npz`` bytes and the
  driver writes them atomically into the dataset; a target worker gets the sample's bytes and
  returns the arrays. Scenes come from each node's own scene cache (``rtp scenes fetch`` there, or
  ``$RTP_SCENE_CACHE`` on a shared disk);
* **failures**: a worker process that dies is restarted and its samples retried by Ray
  (``MAX_RETRIES`` times); the driver only ever writes complete samples, so nothing is lost and
  nothing half-written appears. A run that is interrupted resumes like the local one.

``ADDRESS`` is ``local`` (start a private Ray instance on this machine with ``workers`` CPUs), ``auto``
(the cluster this machine belongs to) or a head node's ``host:port`` / ``ray://host:10001`` (an IPv6
address in brackets, as Ray takes it: ``[::1]:6379``).
"""

from __future__ import annotations

import contextlib
import logging
import logging.handlers
import math
import os
import sys
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from rtp.sdk import EXIT_USAGE, ParameterError, RtpError

from ._memory import job_bytes
from ._pool import cores

__all__ = ["MAX_RETRIES", "RAY_LOCAL", "RayExecutorError", "RayWorkerError", "check_ray_address", "ray_cluster"]

log = logging.getLogger("rtp.capture")

#: ``--ray`` without an address: a private Ray instance on this machine.
RAY_LOCAL = "local"
#: Times Ray restarts a dead worker and retries its samples before the job fails.
MAX_RETRIES = 3
#: Samples each worker has queued, so that it never waits for the driver to write.
IN_FLIGHT = 2
#: Seconds between two reports of a job's planning from a worker (and between the driver's reads).
PLAN_NEWS_S = 0.25


class RayExecutorError(RtpError):
    """Ray is not installed, or the address given does not lead to a Ray cluster."""

    exit_code = EXIT_USAGE


class RayWorkerError(RayExecutorError):
    """A Ray worker died more often than Ray retries, or failed with an error that is not rtp's own."""

    exit_code = 1


def _ray() -> Any:
    try:
        import ray
    except ImportError as exc:
        raise RayExecutorError("--ray needs Ray: pip install 'rtp[ray]' (or pip install 'ray>=2.40')") from exc
    return ray


def check_ray_address(address: object) -> tuple[str, int] | None:
    """The form of a ``ray`` argument (``--ray ADDRESS``) checked without Ray and without connecting: None,
    ``"local"`` or ``"auto"`` (None returned), or a head's ``HOST:PORT``, ``[IPV6]:PORT`` or ``ray://HOST:PORT``
    (its host and port returned, the host ``""`` for ``:PORT``). :func:`rtp.capture.capture` and
    :func:`rtp.capture.compute_targets` call it with their other arguments, so that a malformed address is
    refused before the job is announced (it was refused only on connecting, after the "capture: ... = N samples"
    line); whether anything answers there is :func:`ray_cluster`'s to find.

    Raises:
        RayExecutorError: the address is not text, or not of one of these forms (a port outside 1-65535, an IPv6
            address without its brackets, no port, empty).
    """
    if address is None or address in (RAY_LOCAL, "auto"):
        return None
    if not isinstance(address, str):
        raise RayExecutorError(f"Ray address: expected 'local', 'auto', HOST:PORT, [IPV6]:PORT or ray://HOST:PORT, "
                               f"got {type(address).__name__} {address!r}")
    hostport = address.split("://", 1)[-1]
    if hostport.startswith("["):  # an IPv6 address, as Ray takes it: [::1]:6379 (the brackets were looked up as a name)
        host, close, rest = hostport[1:].partition("]")
        sep, port = rest[:1], rest[1:]
        if not close or not host or sep != ":":
            sep = ""
    else:
        host, sep, port = hostport.rpartition(":")
        if ":" in host:  # ("::1" was host ":" port 1: "nothing answers there")
            raise RayExecutorError(f"Ray address {address!r}: an IPv6 address goes in brackets, before its port: "
                                   "[ADDRESS]:PORT (such as [::1]:6379)")
    if not sep or not port.isdigit() or not 0 < int(port) < 65536:  # (99999 was taken as port 34463)
        raise RayExecutorError(f"Ray address {address!r}: expected 'local', 'auto', HOST:PORT, [IPV6]:PORT or "
                               "ray://HOST:PORT, a port in 1-65535")
    return host, int(port)


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """Fail in seconds, not minutes, on a head address nothing listens at (ray.init retries for long)."""
    import socket

    parsed = check_ray_address(address)
    if parsed is None:  # ('local' and 'auto' name no head to connect to)
        return
    host, port = parsed
    try:
        socket.create_connection((host or "127.0.0.1", int(port)), timeout=timeout).close()
    except OSError as exc:
        raise RayExecutorError(f"cannot start or reach Ray at {address!r}: nothing answers there ({exc}); "
                               "start the head with `ray start --head` or pass --ray local") from exc


def _auth_hint(exc: BaseException) -> str:
    """What to do where ``exc`` (a failed ``ray.init``) came of the cluster's token authentication: a head
    that ``ray start`` began (token authentication is on by default there in recent Ray: 2.60) wants a
    token, which Ray sends to an address named to it only with ``RAY_AUTH_MODE=token``; the error said
    only "Failed to connect to Ray cluster at ..." after 20 s, its cause under ``-v``. Empty otherwise."""
    seen: BaseException | None = exc
    while seen is not None:
        text = f"{type(seen).__name__}: {seen}"
        if "AuthenticationError" in text or "InvalidAuthToken" in text or "Unauthenticated" in text:
            return ("; the cluster asks for its authentication token (Ray's token authentication): set "
                    "RAY_AUTH_MODE=token, with the head's token in ~/.ray/auth_token, RAY_AUTH_TOKEN_PATH or "
                    "RAY_AUTH_TOKEN (`ray get-auth-token` on the head prints it)")
        seen = seen.__cause__ or seen.__context__
    return ""


@contextlib.contextmanager
def _native_stderr_to_log() -> Iterator[None]:
    """Ray's C++ client writes its connection retries straight to file descriptor 2 (a line a second
    for 20 s at an address where something that is not Ray answers), above the one-line error. While
    connecting, that descriptor goes to a temporary file, whose lines are logged afterwards at INFO
    (``-v`` shows them; they were logged at DEBUG, which no option shows)."""
    import tempfile

    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            for line in tmp.read().decode(errors="replace").splitlines():
                log.info("ray: %s", line)


@contextlib.contextmanager
def ray_cluster(address: str | None, workers: int | None, tasks: int | None = None) -> Iterator[int]:
    """Connect to Ray (or start a private local instance); yields how many workers to start.

    ``workers`` None means one per CPU of the cluster (a private instance: one per core this process
    may run on, :func:`rtp.capture._pool.cores`, not every core of a machine that a container or a
    batch job shares). A Ray already initialised in this process (a notebook, a test) is used as it
    is and left running; one this function started is shut down on exit, and on a start that failed
    or was interrupted.

    The workers are never more than ``tasks`` (the samples the job may have: a worker more holds
    its renderer or network for nothing) nor more than the CPUs the cluster has, with a warning
    (each worker takes one CPU: one more than the cluster has waited for a CPU for good, and the job
    with it); a private instance of more workers than this machine's cores is warned of, as a local
    pool of more processes is."""
    ray = _ray()
    started = False
    if workers is not None and tasks is not None and workers > max(1, tasks):
        log.info("Ray: %d worker(s) asked for %d sample(s): %d", workers, tasks, max(1, tasks))
        workers = max(1, tasks)
    if address in (None, RAY_LOCAL) and not ray.is_initialized() and workers is not None and workers > cores():
        n_cores = cores()
        log.warning("%d Ray workers on the %d core%s this process may run on: each is a whole renderer or metric "
                    "process (hundreds of MB, torch's for targets), and more workers than cores add memory, not "
                    "speed", workers, n_cores, "" if n_cores == 1 else "s")
    if not ray.is_initialized():
        kwargs: dict[str, Any] = {"include_dashboard": False, "logging_level": logging.WARNING,
                                  "configure_logging": False}
        try:
            if address in (None, RAY_LOCAL):
                # (its native start-up lines, "Token authentication is enabled for this Ray cluster ...",
                # concern a cluster the user runs, not this private one: -v shows them)
                # (address "local": without it ray.init joins the cluster RAY_ADDRESS names, or the one `ray start`
                # began on this machine, and failed there on num_cpus: "When connecting to an existing cluster,
                # num_cpus and num_gpus must not be provided")
                with _native_stderr_to_log():
                    ray.init(address=RAY_LOCAL, num_cpus=workers or cores(), **kwargs)
            else:
                if address != "auto":
                    _check_reachable(address)
                with _native_stderr_to_log():
                    ray.init(address=address, **kwargs)
        except RayExecutorError:  # (_check_reachable's, before ray.init)
            raise
        except BaseException as exc:
            # (a start that failed or was interrupted half-way, Ctrl-C included, left the private instance's
            # processes, its GCS server and raylet, running until this process ended, and the next ray.init
            # started another beside them)
            with contextlib.suppress(Exception):
                ray.shutdown()
            if not isinstance(exc, Exception):
                raise
            # (ConnectionError, RuntimeError, ValueError from ray.init)
            raise RayExecutorError(f"cannot start or reach Ray at {address or RAY_LOCAL!r}: {exc}"
                                   + _auth_hint(exc)) from exc
        started = True
    try:
        cpus = int(ray.cluster_resources().get("CPU", 0))
        n = workers or max(1, cpus)
        if tasks is not None:
            n = min(n, max(1, tasks))
        if 0 < cpus < n:  # (the workers past its CPUs were never placed: the job waited on their samples for good)
            log.warning("%d Ray workers on a Ray cluster of %d CPU%s: %d workers (each takes one CPU; the others "
                        "would wait for one for good)", n, cpus, "" if cpus == 1 else "s", cpus)
            n = cpus
        log.info("Ray: %d worker(s) on %s", n, address or RAY_LOCAL)
        yield n
    finally:
        if started:
            ray.shutdown()


def _pick(pending: dict[str, deque[Any]], busy_on: dict[str, int], current: str | None) -> tuple[str, Any] | None:
    """The next task for a worker that holds scene ``current``: one of that scene, else one of the
    scene fewest other workers are on (most left first)."""
    if current is not None and pending.get(current):
        return current, pending[current].popleft()
    open_keys = [k for k, q in pending.items() if q]
    if not open_keys:
        return None
    key = min(open_keys, key=lambda k: (busy_on.get(k, 0), -len(pending[k])))
    return key, pending[key].popleft()


def _schedule(actors: Sequence[Any], tasks: dict[str, list[Any]], submit: Callable[[Any, Any], Any],
              done: Callable[[Any, Any], None], what: str, poll: Callable[[], None] | None = None) -> None:
    """Run ``tasks`` (grouped by an affinity key, a scene) on ``actors``, ``IN_FLIGHT`` per actor,
    calling ``done(task, result)`` in the driver as each finishes, and ``poll()`` at least every
    ``PLAN_NEWS_S`` while they run and before each ``done``."""
    ray = _ray()
    pending = {k: deque(v) for k, v in tasks.items() if v}
    current: dict[int, str | None] = dict.fromkeys(range(len(actors)))
    busy_on: dict[str, int] = {}
    running: dict[Any, tuple[int, str, Any]] = {}

    def feed(i: int) -> bool:
        picked = _pick(pending, busy_on, current[i])
        if picked is None:
            return False
        key, task = picked
        current[i] = key
        busy_on[key] = busy_on.get(key, 0) + 1
        running[submit(actors[i], task)] = (i, key, task)
        return True

    try:
        _drive(ray, actors, running, busy_on, feed, done, what, poll)
    except BaseException:
        # (stopped, Ctrl-C or a failure: the tasks still queued are cancelled before their actors are
        # killed, so that Ray does not announce their retries on the terminal)
        for ref in running:
            with contextlib.suppress(Exception):
                ray.cancel(ref)
        raise


def _drive(ray: Any, actors: Sequence[Any], running: dict[Any, tuple[int, str, Any]], busy_on: dict[str, int],
           feed: Callable[[int], bool], done: Callable[[Any, Any], None], what: str,
           poll: Callable[[], None] | None) -> None:
    for i in range(len(actors)):
        for _ in range(IN_FLIGHT):
            feed(i)
    while running:
        ready, _ = ray.wait(list(running), num_returns=1, timeout=None if poll is None else PLAN_NEWS_S)
        if poll is not None:
            poll()
        if not ready:
            continue
        ref = ready[0]
        i, key, task = running.pop(ref)
        busy_on[key] -= 1
        try:
            result = ray.get(ref)
        except ray.exceptions.RayActorError as exc:
            gone = _head_gone(ray)
            if gone is not None:  # (it said "a Ray worker died 4 times": the cluster had been stopped under the job)
                raise RayWorkerError(f"the Ray cluster is gone (its head at {gone} does not answer) while on {what} "
                                     f"{task[0]!r}; everything finished before is saved: start the cluster again "
                                     f"and rerun to resume") from exc
            raise RayWorkerError(f"a Ray worker died {MAX_RETRIES + 1} times on {what} {task[0]!r}; "
                                 f"everything finished before is saved, rerun to resume: {exc}") from exc
        except ray.exceptions.RayTaskError as exc:
            cause = exc.cause if isinstance(getattr(exc, "cause", None), BaseException) else None
            if isinstance(cause, RtpError):
                raise cause from exc
            raise RayWorkerError(f"{what} {task[0]!r} failed on a Ray worker: {exc}") from exc
        except ray.exceptions.RayError as exc:  # (Ray's own: a worker killed for memory, a node or object lost, ...)
            raise RayWorkerError(f"{what} {task[0]!r} failed on Ray ({type(exc).__name__}); everything finished "
                                 f"before is saved, rerun to resume: {exc}") from exc
        done(task, result)
        feed(i)


def _head_gone(ray: Any, timeout: float = 2.0) -> str | None:
    """The address of the cluster's head (its GCS server) where nothing answers there any more (``ray stop``
    on the head, the head node lost), else None (it answers, or its address is unknown)."""
    import socket

    try:
        address = str(ray.get_runtime_context().gcs_address)
    except Exception:  # noqa: BLE001 (no address to probe: say what Ray said)
        return None
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit():
        return None
    try:
        socket.create_connection((host.strip("[]") or "127.0.0.1", int(port)), timeout=timeout).close()
    except OSError:
        return address
    return None


def _kill(actors: Sequence[Any]) -> None:
    """End a job's actors (Ray shut down already, or an actor gone: nothing to end)."""
    ray = _ray()
    for a in actors:
        with contextlib.suppress(Exception):
            ray.kill(a)


def _node_memory() -> tuple[str, int, int]:
    """In a Ray worker: its node's id, memory and swap, and memory available now (bytes; 0 unknown)."""
    from ._memory import meminfo

    return _ray().get_runtime_context().get_node_id(), meminfo("MemTotal") + meminfo("SwapTotal"), meminfo("MemAvailable")


def _check_node_memory(actors: Sequence[Any], one: int, said: str, name: str, advice: str,
                       error: Callable[[str, str], Exception]) -> None:
    """Each Ray node's workers together against that node's memory and swap, as
    :func:`rtp.capture.check_memory` checks this machine's: ``one`` bytes a worker, ``said`` what
    holds them ("a capture at 8192x8192 holds"). Past a node's memory and swap, ``error(message, name)``
    (or a warning, or nothing, as ``RTP_MEMORY_CHECK`` says on the driver); past what it has available
    now, a warning. "fewer workers" is advised where one would fit."""
    from ._memory import check_mode, refuse

    if check_mode() == "off":
        return
    ray = _ray()
    nodes: dict[str, list[int]] = {}
    for node, total, available in ray.get([a.node_memory.remote() for a in actors]):
        nodes.setdefault(node, [0, total, available])[0] += 1
    for node, (count, total, available) in nodes.items():
        need, each = count * one, f" ({one / 2**30:.1f} GiB in each of its {count} workers)" if count > 1 else ""
        where = f"{said} about {need / 2**30:.1f} GiB on Ray node {node[:12]}{each}"
        if total and need > total:
            fewer = " or fewer workers" if count > 1 and one <= total else ""
            refuse(f"{name}: {where}, more than its {total / 2**30:.1f} GiB of memory and swap: {advice}{fewer}", name, error)
        elif available and need > available:
            log.warning("%s, more than the %.1f GiB of memory it has available now: the system may kill its workers",
                        where, available / 2**30)


# -- news from the workers -------------------------------------------------------------------------


class _News:
    """The channel from the actors to the driver: a ``ray.util.queue.Queue`` (an actor that takes no
    CPU: Ray's default of one for scheduling an actor would wait for a worker's) carrying each job's
    planning counts and the workers' log records. The driver reads it between its waits
    (:meth:`read`); a lost queue loses only the news."""

    def __init__(self, guard: contextlib.ExitStack, planning: Callable[[str, int, int], None] | None) -> None:
        from ray.util.queue import Queue

        self.queue: Any = Queue(actor_options={"num_cpus": 0})
        self.planning = planning
        guard.callback(_kill, [self.queue.actor])

    def read(self) -> None:
        if self.queue is None:
            return
        try:
            items = self.queue.get_nowait_batch(self.queue.qsize())
        except Exception as err:  # noqa: BLE001 (the queue's actor lost: the work goes on, unreported)
            log.warning("the workers' progress and logs are lost (%s); each scene is reported when planned", err)
            self.queue = None
            return
        for item in items:
            if isinstance(item, logging.LogRecord):
                logging.getLogger(item.name).handle(item)
            elif self.planning is not None:
                self.planning(*item)


class _NewsLogHandler(logging.handlers.QueueHandler):
    """In an actor: its ``rtp`` log records onto the news queue (a record that cannot be sent is dropped:
    the queue's actor lost)."""

    def handleError(self, record: logging.LogRecord) -> None:
        pass


class _Reporting:
    """An actor that sends news: the queue comes with its tasks (an actor handle among an actor's
    constructor arguments is kept in Ray's object store, which Ray warns a restart may not survive),
    and on the first one ``rtp``'s records at ``level`` (the driver's) and above go to the driver
    through it, as its own records do (a worker process has no logging set up: its INFO was lost, its
    warnings printed bare by Ray's log forwarding)."""

    level: int = logging.WARNING
    news: Any = None

    def _listen(self, news: Any) -> None:
        if news is None or self.news is not None:
            return
        self.news = news
        rtp_log = logging.getLogger("rtp")
        rtp_log.handlers[:] = [_NewsLogHandler(news)]
        rtp_log.setLevel(self.level)
        rtp_log.propagate = False


# -- capture ----------------------------------------------------------------------------------------


class _CaptureWorker(_Reporting):
    """A Ray actor: a GL renderer of ``size`` and the scene it holds."""

    def __init__(self, size: tuple[int, int], cache_dir: str | None, split: str | None, splits: str | None,
                 level: int = logging.WARNING) -> None:
        # Mesa's software rasteriser starts a thread per core; the worker holds one of Ray's CPUs, so
        # it rasterises on one (set before the GL context exists, which is when Mesa reads it).
        os.environ.setdefault("LP_NUM_THREADS", "1")
        self.size, self.cache_dir, self.split, self.splits = size, cache_dir, split, splits
        self.level = level
        self._renderer: Any = None
        self._scene: tuple[str, Any, Any] | None = None
        self._uploaded: str | None = None

    def pid(self) -> int:
        return os.getpid()

    def node_memory(self) -> tuple[str, int, int]:
        return _node_memory()

    def _load(self, scene_name: str) -> tuple[Any, Any]:
        from ._capture import load_scene

        if self._scene is None or self._scene[0] != scene_name:
            # (capture() ran check_scene on every name before Ray started: a mesh file's warnings were said there)
            scene, blockers = load_scene(scene_name, self.cache_dir, self.split, self.splits, checked=True)
            self._scene = (scene_name, scene, blockers)
        return self._scene[1], self._scene[2]

    def plan(self, scene_name: str, profiles: Sequence[str], per_scene: int, seed: int, placement: str,
             report: bool = False, news: Any = None) -> Any:
        """The scene's plans (``_plan``); with ``report`` each job's pairs found so far are put on the
        news queue as ``(job, found, asked)``, at most every ``PLAN_NEWS_S``."""
        from ._capture import _plan

        self._listen(news)
        scene, blockers = self._load(scene_name)
        planning = None
        news = self.news
        if report and news is not None:
            sent: dict[str, float] = {}

            def planning(job: str, found: int, asked: int) -> None:
                now = time.monotonic()
                if now - sent.get(job, -math.inf) >= PLAN_NEWS_S:  # (each put is a round trip to the queue's actor)
                    sent[job] = now
                    try:
                        news.put_nowait((job, found, asked))
                    except Exception as err:  # noqa: BLE001 (a progress report lost never fails the plan)
                        log.debug("planning news of %s lost: %s", job, err)
                        sent[job] = math.inf
        return _plan(scene_name, scene, blockers, profiles, per_scene, self.size, seed, placement, planning)

    def render(self, scene_name: str, profile: str, sample_id: str, prev_cam: Any, cam: Any, news: Any = None,
               ) -> tuple[bytes, dict[str, Any], dict[str, Any]]:
        from rtp.plugins.moderngl import Renderer

        from ._capture import _render
        from ._dataset import encode_sample

        self._listen(news)
        scene, _ = self._load(scene_name)
        if self._renderer is None:
            self._renderer = Renderer(*self.size)
        if self._uploaded != scene_name:
            self._renderer.load_scene(scene)
            self._uploaded = scene_name
        buffers, meta = _render(self._renderer, scene_name, profile, prev_cam, cam)
        return encode_sample(sample_id, buffers, meta), meta, self._renderer.settings


def ray_capture(scene_names: Sequence[str], out: str, *, profiles: Sequence[str], per_scene: int,
                size: tuple[int, int], seed: int, cache_dir: str | None, split: str | None, splits: str | None,
                settings: dict[str, Any], address: str | None, workers: int | None,
                progress: Callable[[int], None], on_actors: Callable[[list[Any]], None] | None = None,
                planning: Callable[[str, int, int], None] | None = None) -> Any:
    """The Ray path of :func:`rtp.capture.capture` (same arguments; returns a ``CaptureReport``).
    ``planning`` hears of each job's pairs as its worker finds them (through the news queue, at most
    every ``PLAN_NEWS_S`` a job) and once more when the job is planned; the workers' log records come
    the same way."""
    from ._capture import CaptureReport, _locked_writer, _todo
    from ._dataset import DatasetReader, DatasetWriter

    ray = _ray()
    # An existing folder's settings are checked before Ray starts; a new folder is made only once Ray
    # answers (an address that is not Ray's left a manifest and an empty folder behind).
    writer = DatasetWriter(out, settings) if (Path(out) / "manifest.json").exists() else None
    report = CaptureReport()
    with ray_cluster(address, workers, len(scene_names) * len(profiles) * per_scene) as n, \
            contextlib.ExitStack() as guard:
        news = _News(guard, planning)
        level = logging.getLogger().getEffectiveLevel()
        cls = ray.remote(num_cpus=1, max_restarts=MAX_RETRIES, max_task_retries=MAX_RETRIES)(_CaptureWorker)
        actors = [cls.remote(size, cache_dir, split, splits, level) for _ in range(n)]
        guard.callback(_kill, actors)  # (however the job ends: in a Ray the caller started they would hold its CPUs)
        # every node's workers against its memory, before the folder is made or anything is drawn
        _check_node_memory(actors, job_bytes("capture", size), f"a capture at {size[0]}x{size[1]} holds", "size",
                           "a smaller size", ParameterError)
        if writer is None:  # (a folder that existed: capture() holds its lock)
            writer = _locked_writer(out, settings, guard)
            # (a folder without a manifest: capture() removed no stale files, and a killed write's stayed)
            if writer.remove_stale():
                log.info("removed temporary files of an interrupted capture in %s", out)
        if on_actors is not None:
            on_actors(actors)
        # Plan every scene (the worker that plans a scene keeps it loaded and renders it first).
        planned: dict[str, dict[str, list[Any]]] = {}

        def planned_one(task: Any, result: Any) -> None:
            plans, failed = result
            planned[task[0]] = plans
            report.failed.extend(failed)
            if planning is not None:
                for profile, plan in plans.items():
                    planning(f"{task[0]}/{profile}", len(plan), per_scene)

        _schedule(actors, {s: [(s,)] for s in scene_names},
                  lambda a, t: a.plan.remote(t[0], tuple(profiles), per_scene, seed, settings.get("placement", "free"),
                                             planning is not None, news.queue),
                  planned_one, "scene", news.read)
        reader = DatasetReader(out)
        tasks: dict[str, list[Any]] = {}
        for scene_name in scene_names:
            for profile, plan in planned.get(scene_name, {}).items():
                todo = _todo(writer, reader, plan)
                report.skipped += len(plan) - len(todo)
                tasks.setdefault(scene_name, []).extend((sid, scene_name, profile, p, c) for sid, p, c in todo)
        if report.skipped:
            progress(report.skipped)

        def rendered(task: Any, result: Any) -> None:
            sid, _, profile, _, _ = task
            data, meta, renderer_settings = result
            if writer.has(sid):
                log.warning("%s was captured from other cameras than this rtp plans; recapturing it", sid)
                report.recaptured += 1
            writer.write_encoded(sid, data)
            report.written += 1
            report.renderer = renderer_settings
            report.unseen.setdefault(profile, []).append(float(meta["unseen"]))
            progress(1)

        _schedule(actors, tasks, lambda a, t: a.render.remote(t[1], t[2], t[0], t[3], t[4], news.queue), rendered,
                  "sample", news.read)
    return report


# -- targets ----------------------------------------------------------------------------------------


class _TargetWorker(_Reporting):
    """A Ray actor computing the stored targets of samples sent to it as bytes."""

    def __init__(self, threads: int, level: int = logging.WARNING) -> None:
        from ._targets import _set_threads

        _set_threads(threads)
        self.level = level

    def pid(self) -> int:
        return os.getpid()

    def node_memory(self) -> tuple[str, int, int]:
        return _node_memory()

    def compute(self, sample_id: str, data: bytes, metrics: tuple[str, ...], params: dict[str, Any],
                base_tile: int, news: Any = None, where: str | None = None) -> tuple[dict[str, Any], tuple[int, int]]:
        from ._dataset import sample_from_bytes
        from ._targets import sample_targets

        self._listen(news)

        sample = sample_from_bytes(sample_id, data, where)  # (errors name the driver's file, not "in memory")
        return sample_targets(sample, metrics, params, base_tile), sample.size


def ray_targets(data_root: str, todo: dict[str, tuple[str, ...]], params: dict[str, Any], *, address: str | None,
                workers: int | None, progress: Callable[[int], None],
                on_actors: Callable[[list[Any]], None] | None = None) -> None:
    """The Ray path of :func:`rtp.capture.compute_targets`: ``todo`` maps sample ids to the metrics
    they lack; results are written into the dataset's target store by this process."""
    from ._dataset import DatasetReader, sample_path
    from ._targets import TargetError, TargetStore, sample_fingerprint

    ray = _ray()
    store = TargetStore(data_root)
    settings = DatasetReader(data_root).manifest.get("settings")
    size = settings.get("size") if isinstance(settings, dict) else None
    metrics = tuple(dict.fromkeys(m for ms in todo.values() for m in ms))
    with ray_cluster(address, workers, len(todo)) as n, contextlib.ExitStack() as guard:
        news = _News(guard, None)
        level = logging.getLogger().getEffectiveLevel()
        cls = ray.remote(num_cpus=1, max_restarts=MAX_RETRIES, max_task_retries=MAX_RETRIES)(_TargetWorker)
        actors = [cls.remote(1, level) for _ in range(n)]
        guard.callback(_kill, actors)
        if isinstance(size, list) and len(size) == 2 and all(isinstance(v, int) and v > 0 for v in size):
            _check_node_memory(actors, job_bytes("targets", (size[0], size[1]), metrics=metrics),
                               f"the {', '.join(metrics)} targets of its {size[0]}x{size[1]} samples take", "data",
                               "a node with more memory", lambda message, name: TargetError(message))
        if on_actors is not None:
            on_actors(actors)

        # (each sample's time and fingerprint when its bytes were read: see TargetStore.write)
        read_at: dict[str, tuple[int | None, str | None]] = {}

        def submit(actor: Any, task: Any) -> Any:
            sid, metrics = task
            path = sample_path(data_root, sid)
            as_of = path.stat().st_mtime_ns
            data = path.read_bytes()
            read_at[sid] = as_of, sample_fingerprint(data)
            return actor.compute.remote(sid, data, metrics, params, store.base_tile, news.queue, str(path))

        def done(task: Any, result: Any) -> None:
            sid, _ = task
            values, size = result
            as_of, fingerprint = read_at.get(sid, (None, None))
            for m, v in values.items():
                store.write(sid, m, v, size, sample_mtime_ns=as_of, fingerprint=fingerprint)
            progress(1)

        # One queue: targets have no affinity (every worker holds the same network).
        _schedule(actors, {"": list(todo.items())}, submit, done, "sample", news.read)
