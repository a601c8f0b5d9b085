"""The memory a job will need, checked before it starts.

A job past the machine's memory is not refused by anything on Linux: it runs until the kernel's
OOM killer ends it without a word, often after minutes of work (``rtp demo --size 8192x8192``
holds about 45 GB; ``rtp play`` at 3840x2160 with ``--workers 2`` about 27 GB). Each frame job
(capture, targets, the demo, the closed loop, ``rtp metric``'s image pair) sizes itself from its
frame size with the slopes of :data:`PER_PIXEL`, measured, and :func:`check_memory` refuses it past
the machine's memory and swap (a :class:`~rtp.sdk.ParameterError` naming ``size``, before anything
is drawn or written) and warns past the memory available now. Training sizes its steps and its dataset the same way
(:func:`rtp.train.step_bytes`).

``python bench/job_memory.py`` runs every job at two sizes, each in a process of its own, and
prints its measured peak (the resident set, children included) beside :func:`job_bytes`'s
estimate: rerun it after a change that holds more or fewer full-frame images, and update the
tables here from its slopes.

The tables were measured on Mesa's software GL, which keeps the renderer's images in host memory; a
hardware driver keeps them on the GPU, so there the estimates of the rendering jobs overstate host
memory. ``RTP_MEMORY_CHECK`` (:data:`CHECK_ENV`) sets what a job past the machine's memory does:
``refuse`` (the default), ``warn`` (log the same sentence and run), ``off`` (check nothing).
"""

from __future__ import annotations

import logging
import math
import numbers
import os
from collections.abc import Callable, Iterable
from typing import Any

from rtp.sdk import METRICS, ParameterError

log = logging.getLogger("rtp.capture")

#: Where the machine's memory is read (Linux). Elsewhere nothing is checked.
MEMINFO = "/proc/meminfo"

#: The environment variable that sets what a job past the machine's memory does (:data:`CHECK_MODES`).
CHECK_ENV = "RTP_MEMORY_CHECK"

#: Its values, the default first: refuse the job; warn and run it; check nothing.
CHECK_MODES = ("refuse", "warn", "off")

#: Bytes a job's process holds for each pixel of its frames, at its peak: the slope of the peak
#: resident set between 640x384 and 1280x768 (``python bench/job_memory.py``, 2026-12-03).
#: ``play.loop`` is added for each of a closed-loop run's method loops (one per swept parameter:
#: its displayed frame, its reprojection); ``play.model`` for each distinct model it loads (its
#: input planes, onnxruntime's buffers). A run with dynamic resolution holds no more than one at its
#: largest size (its one renderer resizes: ``Renderer.resize``).
PER_PIXEL: dict[str, float] = {
    "capture": 770.0,  # a sample: two frames' G-buffers, the seven rates' colour, the reprojection, its files
    "targets": 120.0,  # a sample read back, and JNYang's or PSNR's targets
    "demo": 670.0,  # a rendered path, the frame at every rate, JNYang's targets, the FLIP picture, the pictures
    "play": 650.0,  # a path's frame at every rate, the failing metric's truth (JNYang's; others add theirs)
    "play.loop": 14.0,
    "play.model": 90.0,
    "metric": 160.0,  # ``rtp metric``: the pair decoded, the per-pixel map, the figure of --out
}

#: Bytes a job adds per pixel for a metric's per-tile targets over what JNYang's take (the batched
#: FLIP port's feature maps for six images; AlexNet's for LPIPS). Metrics not named add nothing.
METRIC_PER_PIXEL: dict[str, dict[str, float]] = {
    "targets": {"flip": 1280.0, "jnflip": 1140.0, "lpips": 190.0},
    "demo": {"flip": 1020.0, "jnflip": 540.0, "lpips": 20.0},
    "play": {"flip": 1090.0, "jnflip": 930.0, "lpips": 160.0},
    "metric": {"lpips": 30.0},
}

#: Bytes a job's process holds at any frame size (Python, numpy, the GL context, onnxruntime, torch).
BASE: dict[str, float] = {
    "capture": 150 * 2**20,
    "targets": 230 * 2**20,
    "demo": 390 * 2**20,
    "play": 330 * 2**20,
    "metric": 90 * 2**20,
}

#: Bytes a metric adds to a job's base where the base was measured without it (torch and AlexNet's
#: weights for LPIPS in ``rtp metric``; the frame jobs hold torch whatever their metric).
METRIC_BASE: dict[str, dict[str, float]] = {"metric": {"lpips": 210 * 2**20}}


#: How the messages name each job.
_NOUNS = {"capture": "a capture", "targets": "the targets", "demo": "the demo", "play": "the closed loop",
          "metric": "the metric"}


def job_bytes(job: str, size: tuple[int, int], *, processes: int = 1, metrics: Iterable[str] = (), loops: int = 0,
              models: int = 0) -> int:
    """The peak bytes of ``job`` (a key of :data:`BASE`) on frames of ``size`` (width, height), in
    each of ``processes`` processes at once, computing ``metrics``' targets (the largest counts: they
    run one after another), with ``loops`` closed-loop method loops and ``models`` distinct models."""
    if not isinstance(job, str) or job not in BASE:
        raise ParameterError(f"job: expected one of {', '.join(BASE)}, got {job!r}", "job")
    if not isinstance(size, (tuple, list)) or len(size) != 2:
        raise ParameterError(f"size: expected (width, height), got {size!r}", "size")
    w, h = (_count("size", v, 1) for v in size)
    processes, loops, models = _count("processes", processes, 1), _count("loops", loops, 0), _count("models", models, 0)
    metrics = _metric_names(metrics)
    extras = METRIC_PER_PIXEL.get(job, {})
    per_pixel = PER_PIXEL[job] + max((extras.get(m, 0.0) for m in metrics), default=0.0)
    if job == "play":
        per_pixel += loops * PER_PIXEL["play.loop"] + models * PER_PIXEL["play.model"]
    base = BASE[job] + max((METRIC_BASE.get(job, {}).get(m, 0.0) for m in metrics), default=0.0)
    return int(processes * (base + per_pixel * w * h))


def _count(name: str, value: Any, least: int) -> int:
    """``value`` as an int in ``[least, 2**31 - 1]`` (a GL size; past it float arithmetic would overflow)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not least <= int(value) <= 2**31 - 1:
        raise ParameterError(f"{name}: expected an integer in [{least}, {2**31 - 1}], got {value!r}", name)
    return int(value)


def _metric_names(metrics: Any) -> tuple[str, ...]:
    """``metrics`` as a tuple of metric names rtp knows, its own (:data:`rtp.sdk.METRICS`) or plugins'
    (one name alone is one metric)."""
    names = (metrics,) if isinstance(metrics, str) else metrics
    try:
        names = tuple(names)
    except TypeError:
        raise ParameterError(f"metrics: expected metric names, got {metrics!r}", "metrics") from None
    bad = [m for m in names if not isinstance(m, str) or m not in METRICS]
    if bad:
        from rtp import metrics as M  # (a plugin's name: its map's memory is its own, not counted)

        for m in bad:
            try:
                M.metric_info(m)
            except M.MetricParameterError:
                raise ParameterError(f"metrics: expected names of {', '.join(M.known_metrics())}, got {m!r}",
                                     "metrics") from None
    return names


def meminfo(field: str) -> int:
    """A field of :data:`MEMINFO` in bytes (``MemTotal``, ``SwapTotal``, ``MemAvailable``); 0 where
    there is none (not Linux, or a kernel without it)."""
    try:
        with open(MEMINFO, encoding="ascii") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key == field:
                    return int(value.split()[0]) * 1024
    except (OSError, ValueError, IndexError, UnicodeDecodeError):
        pass
    return 0


def check_mode() -> str:
    """What a job past the machine's memory does, from :data:`CHECK_ENV` (one of
    :data:`CHECK_MODES`; unset or empty: ``refuse``). Another value is a
    :class:`~rtp.sdk.ParameterError` naming the variable."""
    mode = os.environ.get(CHECK_ENV, "").strip().lower() or CHECK_MODES[0]
    if mode not in CHECK_MODES:
        raise ParameterError(f"{CHECK_ENV}: expected one of {', '.join(CHECK_MODES)}, got {os.environ[CHECK_ENV]!r}",
                             CHECK_ENV)
    return mode


def refuse(message: str, name: str, error: Callable[[str, str], Exception], logger: logging.Logger | None = None) -> None:
    """A job past the memory, as :func:`check_mode` says: ``error(message + HINT, name)`` raised
    (the hint names :data:`CHECK_ENV`), or ``message`` logged as a warning with ``warn``."""
    if check_mode() == "warn":
        (logger or log).warning("%s (%s=warn: running it anyway)", message, CHECK_ENV)
        return
    raise error(f"{message} ({CHECK_ENV}=warn runs it anyway)", name)


def check_memory(need: int, said: str, name: str, advice: str, *, job: str = "the job",
                 error: Callable[[str, str], Exception] = ParameterError, logger: logging.Logger | None = None) -> None:
    """Refuse ``need`` bytes past the machine's memory and swap: ``error(message, name)`` (a
    :class:`~rtp.sdk.ParameterError` by default), "NAME: SAID, more than this machine's N GiB of
    memory ADVICE" (``advice`` starts "of memory"; "and swap" is added where there is swap: a job
    past the memory may still end, slowly; the message ends naming :data:`CHECK_ENV`). With
    ``RTP_MEMORY_CHECK=warn`` that sentence is a warning instead; with ``off`` nothing is checked.
    Past the memory available now: a warning that the system may kill ``job`` (logged to
    ``logger``, by default ``rtp.capture``'s)."""
    if (isinstance(need, bool) or not isinstance(need, numbers.Real) or need < 0
            or not (isinstance(need, numbers.Integral) or math.isfinite(need))):  # (math.isfinite(10**400) overflows)
        raise ParameterError(f"need: expected a number of bytes >= 0, got {need!r}", "need")
    texts = {"said": said, "name": name, "advice": advice, "job": job}
    bad = next((k for k, v in texts.items() if not isinstance(v, str)), None)
    if bad is not None:
        raise ParameterError(f"{bad}: expected a text, got {texts[bad]!r}", bad)
    if check_mode() == "off":
        return
    memory, swap, available = meminfo("MemTotal"), meminfo("SwapTotal"), meminfo("MemAvailable")
    if memory and need > memory + swap:
        advice = advice.replace("of memory", "of memory and swap", 1) if swap else advice
        refuse(f"{name}: {said}, more than this machine's {(memory + swap) / 2**30:.1f} GiB {advice}", name, error, logger)
    elif available and need > available:
        (logger or log).warning("%s, more than the %.1f GiB of memory available now: the system may kill %s",
                                said, available / 2**30, job)


def check_frame_memory(job: str, size: tuple[int, int], *, processes: int = 1, metrics: Iterable[str] = (),
                       loops: int = 0, models: int = 0,
                       error: Callable[[str, str], Exception] = ParameterError) -> None:
    """:func:`check_memory` of :func:`job_bytes` for a job whose frame size the user chose: "size: the
    demo at WxH holds about N GiB [(M GiB in each of P processes)], more than this machine's T GiB of
    memory: a smaller size [or fewer workers, where one process would fit]"."""
    one = job_bytes(job, size, metrics=metrics, loops=loops, models=models)
    n = _count("processes", processes, 1)
    w, h = (int(v) for v in size)
    each = f" ({one / 2**30:.1f} GiB in each of {n} processes)" if n > 1 else ""
    fewer = n > 1 and one <= meminfo("MemTotal") + meminfo("SwapTotal")
    check_memory(n * one, f"{_NOUNS[job]} at {w}x{h} holds about {n * one / 2**30:.1f} GiB{each}", "size",
                 "of memory: a smaller size" + (" or fewer workers" if fewer else ""), job=_NOUNS[job], error=error)
