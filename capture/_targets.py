"""Per-tile metric targets stored beside a dataset, at a fine base tile so coarser tiles derive.

Layout (docs/dataset.md)::

    DATA/targets/manifest.json          {"format": "rtp-targets", "format_version": 1, "base_tile": 4,
                                         "metrics": {name: parameters}}
    DATA/targets/<metric>/<id>.npz      "values": float32 (6, ceil(H/4), ceil(W/4)), "size": (H, W),
                                        "sample": the sample's fingerprint (sample_fingerprint)

``values`` hold, per base tile and reduced rate (``sdk.PREDICTED_RATES`` order), the max of the
per-pixel map, except PSNR, which stores the tile's mean squared error so that a coarser tile's MSE
is the pixel-weighted mean of its base tiles' and its PSNR ``-10 log10(MSE)``. Deriving a tile size
``t`` (a multiple of the base tile) therefore reproduces what computing the metric at ``t`` directly
gives: to the bit for max-pooled maps, to float32 round-off (the stored base tiles' rounding) for PSNR
and a mean-pooled plugin metric.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import numbers
import os
import re
import shlex
import zipfile
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rtp.sdk import (
    EXIT_USAGE,
    METRIC_NAME_PATTERN,
    METRICS,
    PREDICTED_RATES,
    TARGET_METRICS,
    ParameterError,
    RtpError,
    mse_from_psnr,
    psnr_from_mse,
    tile_extents,
    tile_grid,
)
from rtp.sdk.files import atomic_output, writer_lock

from ._dataset import DatasetReader, _check_id, sample_path
from ._memory import check_memory, job_bytes, meminfo
from ._pool import cores

#: The largest environment luminance ``weber_l`` the targets take. A JN target is the Yang or FLIP error (at most
#: 1) over ``L + l``, so at most ``1 / l``: past ``1 / MIN_PARAMETER`` of ``rtp.sdk``'s transforms (1e-6, the
#: smallest ``mu_y`` a model's metadata takes) every target is below the smallest mean training target a
#: transform can be fitted to (and far past it they are float32's zero), so no model can be trained on them.
MAX_WEBER_L = 1e6

log = logging.getLogger("rtp.capture")

__all__ = ["BASE_TILE", "MAX_WEBER_L", "TargetError", "TargetStore", "compute_targets", "pool_targets"]

FORMAT = "rtp-targets"
FORMAT_VERSION = 1
BASE_TILE = 4


def _frame_size(size: Any) -> tuple[int, int]:
    """``(H, W)`` of positive integers, or a TargetError."""
    if not isinstance(size, (tuple, list, np.ndarray)) or len(size) != 2 or not all(
            isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 1 for v in size):
        raise TargetError(f"size: expected (height, width) in pixels, got {size!r}")
    return int(size[0]), int(size[1])


def _version_ok(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, int) and 0 <= v <= FORMAT_VERSION


def _unreadable(path: Path, what: str, err: Exception) -> TargetError:
    """The TargetError for a targets file a parser choked on (as :func:`._dataset._unreadable`)."""
    return TargetError(f"{path}: {what} ({type(err).__name__}: {err})")


def _stores_mse(metric: str) -> bool:
    """PSNR targets are stored as the tile's mean squared error so that coarser tiles derive exactly."""
    return metric in METRICS and METRICS[metric].pooling == "mse"


def _mean_pooled(metric: str, declared: Mapping[str, Any]) -> bool:
    """Whether coarser tiles of ``metric`` are the pixel-weighted mean of its stored tiles (PSNR's MSE, a
    plugin metric's mean) rather than their maximum: rtp's own metrics' pooling, a plugin metric's as its
    targets' manifest records it (``declared``: the metric's parameters there), so that stored targets read
    without the plugin installed."""
    if metric in METRICS:
        return METRICS[metric].pooling in ("mse", "mean")
    if isinstance(declared.get("pooling"), str):
        return declared["pooling"] == "mean"
    from rtp import metrics as M

    return M.metric_info(metric).pooling == "mean"


def _check_name(metric: Any) -> str:
    """``metric`` if it is a metric rtp knows (its own or a plugin's), else a TargetError listing them."""
    from rtp import metrics as M

    try:
        M.metric_info(metric)
    except M.MetricParameterError as err:
        raise TargetError(str(err)) from None
    return str(metric)


def sample_fingerprint(sample: str | os.PathLike[str] | bytes) -> str | None:
    """What a target file records of the sample it was computed from (:meth:`TargetStore.write`): a SHA-256 of the
    sample archive's index, each entry's name, size and CRC-32 of its bytes, so any change of the sample's content
    changes it, while a copy of the file (``cp -r``, ``tar``, ``rsync``, a checkout: whatever times they give it)
    keeps it. Only the archive's directory at its end is read (0.2 ms for a 27 MB 1920x1080 sample, where hashing
    the whole file takes 28 ms). ``sample``: the sample file's path or its bytes. None where it is no readable zip
    archive (missing, truncated)."""
    try:
        with zipfile.ZipFile(io.BytesIO(sample) if isinstance(sample, bytes) else sample) as z:
            index = sorted((i.filename, i.file_size, i.CRC) for i in z.infolist())
    except (OSError, EOFError, ValueError, zipfile.BadZipFile):
        return None
    return "zip-index-sha256:" + hashlib.sha256(json.dumps(index).encode()).hexdigest()


def _recorded_fingerprint(path: Path) -> str | None:
    """The sample fingerprint a target file records, or None: a file of an rtp before fingerprints (whose staleness
    is then judged by modification times), or one that cannot be read (which :meth:`TargetStore.load` refuses)."""
    try:
        with np.load(path) as npz:
            if "sample" not in npz.files:
                return None
            value = npz["sample"]
    except Exception:  # numpy's reader meets corrupt bytes with many exceptions (see _unreadable)
        return None
    return str(value[()]) if value.dtype.kind == "U" and value.ndim == 0 else None


class TargetError(RtpError):
    """Targets are missing for a sample/metric, or stored with another format or base tile."""

    exit_code = EXIT_USAGE


def pool_targets(values: np.ndarray, size: tuple[int, int], base: int, tile: int, *, mse: bool) -> np.ndarray:
    """Coarsen base-tile values ``(..., th, tw)`` of a frame of ``size = (H, W)`` to ``tile``.

    Max-pooling for max-pooled maps; with ``mse``, a pixel-weighted mean (PSNR's per-tile MSE, a mean-pooled
    plugin metric's tiles). Edge tiles that the
    frame only partly covers are pooled over the pixels they hold.
    """
    for key, value in (("tile", tile), ("base", base)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise TargetError(f"{key} must be a positive integer, got {value!r}")
    h, w = _frame_size(size)
    try:
        values = np.asarray(values)
    except (TypeError, ValueError) as err:
        raise TargetError(f"values: expected an array of numbers, got {type(values).__name__} ({err})") from err
    if values.dtype.kind not in "biuf" or values.ndim < 2 or values.shape[-2:] != tile_grid(h, w, base):
        raise TargetError(f"values: expected numbers of shape (..., {', '.join(map(str, tile_grid(h, w, base)))}) for a "
                          f"{h}x{w} frame at base tile {base}, got {values.dtype} {values.shape}")
    if tile % base:
        raise TargetError(f"tile {tile} is not a multiple of the stored base tile {base}")
    f = tile // base
    if f == 1:
        return values.astype(np.float32)
    th, tw = values.shape[-2:]
    # a factor past an axis's tiles pools them all into one: clamped on each axis, the padding is never more than
    # the last coarse tile's (one clamp for both padded a strip of 1x3000 base tiles read 3000 times coarser to
    # 3000x3000 values)
    fh, fw = min(f, th), min(f, tw)
    oh, ow = -(-th // fh), -(-tw // fw)
    ph, pw = oh * fh - th, ow * fw - tw
    pad = [(0, 0)] * (values.ndim - 2) + [(0, ph), (0, pw)]
    if not mse:
        v = np.pad(values.astype(np.float64), pad, constant_values=-np.inf)
        v = v.reshape(*values.shape[:-2], oh, fh, ow, fw)
        return v.max(axis=(-3, -1)).astype(np.float32)
    wts = np.outer(tile_extents(h, base), tile_extents(w, base)).astype(np.float64)
    wts = np.pad(wts, [(0, ph), (0, pw)])
    v = np.pad(values.astype(np.float64), pad) * wts
    num = v.reshape(*values.shape[:-2], oh, fh, ow, fw).sum(axis=(-3, -1))
    den = wts.reshape(oh, fh, ow, fw).sum(axis=(1, 3))
    return (num / den).astype(np.float32)


class TargetStore:
    """Reads and writes the targets of one dataset folder."""

    def __init__(self, data_root: str | os.PathLike[str], *, base_tile: int = BASE_TILE) -> None:
        if not isinstance(data_root, (str, os.PathLike)) or "\0" in str(os.fspath(data_root)):
            raise TargetError(f"expected a dataset folder path, got {data_root!r}")
        self.root = Path(data_root) / "targets"
        if Path(data_root).exists() and not Path(data_root).is_dir():  # (/dev/null: NotADirectoryError at the first write)
            raise TargetError(f"expected a dataset folder, got {os.fspath(data_root)!r}, which is not a folder")
        manifest = self.root / "manifest.json"
        if manifest.is_file():
            try:
                d = json.loads(manifest.read_text(encoding="utf-8"))
            except (OSError, UnicodeDecodeError, ValueError, RecursionError) as e:  # (JSONDecodeError: a ValueError)
                raise _unreadable(manifest, "not a readable targets manifest; delete the targets folder to "
                                  "recompute", e) from e
            if not isinstance(d, dict) or d.get("format") != FORMAT or not _version_ok(d.get("format_version", 0)):
                raise TargetError(f"{manifest}: not rtp targets of a supported version")
            base, metrics = d.get("base_tile"), d.get("metrics", {})
            if isinstance(base, bool) or not isinstance(base, int) or base < 1 or not isinstance(metrics, dict):
                raise TargetError(f"{manifest}: expected a positive integer base_tile and a metrics mapping, "
                                  f"got base_tile={base!r}, metrics of type {type(metrics).__name__}")
            self.base_tile = base
            self.metrics: dict[str, Any] = dict(metrics)
        else:
            self.base_tile = base_tile
            self.metrics = {}

    def _save_manifest(self) -> None:
        data = {"format": FORMAT, "format_version": FORMAT_VERSION, "base_tile": self.base_tile, "metrics": self.metrics}
        with atomic_output(self.root / "manifest.json") as tmp:
            tmp.write_text(json.dumps(data, indent=1, sort_keys=True), encoding="utf-8")

    def declare(self, metric: str, params: Mapping[str, Any]) -> None:
        """Record the parameters a metric's targets are computed with; refuse a silent change."""
        _check_name(metric)
        if not isinstance(params, Mapping):
            raise TargetError(f"params of {metric}: expected a mapping of parameter names to values, got "
                              f"{type(params).__name__}")
        try:
            params = json.loads(json.dumps(dict(params)))
        except (TypeError, ValueError) as err:  # a value JSON cannot hold
            raise TargetError(f"params of {metric}: expected JSON values, got {dict(params)!r} ({err})") from err
        folder = self.root / metric
        if metric not in self.metrics and folder.is_dir() and any(folder.glob("*.npz")):
            # (targets/manifest.json lost, or written over without this metric: the stored files were kept and
            # the new parameters recorded, so one metric's targets mixed two parameter sets)
            manifest = self.root / "manifest.json"
            lost = "is missing" if not manifest.is_file() else f"does not record {metric}"
            raise TargetError(
                f"{folder} holds {metric} targets, but {manifest} {lost}: the parameters they were computed with are "
                f"unknown, and may not be {params}; restore the manifest, or delete {folder} to compute {metric}'s "
                f"with these (the other metrics' targets stay)")
        if metric in self.metrics and self.metrics[metric] != params:
            if folder.is_dir() and any(folder.glob("*.npz")):
                # (the hint was "delete that folder", the whole targets folder: every other metric's targets with it)
                raise TargetError(
                    f"targets for {metric} in {self.root} were computed with {self.metrics[metric]}, not {params}; "
                    f"delete {folder} to compute {metric}'s with these (the other metrics' targets stay)"
                )
            self.metrics.pop(metric)  # (none stored: the metric's parameters are declared anew)
        if metric not in self.metrics:
            self.metrics[metric] = params
            self._save_manifest()

    def path(self, sample_id: str, metric: str) -> Path:
        if not (isinstance(metric, str) and metric in self.metrics and re.fullmatch(METRIC_NAME_PATTERN, metric)):
            _check_name(metric)  # ("../samples" wrote over the captured sample; a plugin's name is an identifier)
        _check_id(sample_id)
        return self.root / metric / f"{sample_id}.npz"

    def stale(self, sample_id: str, metric: str) -> bool:
        """Whether stored targets are of another sample than the one stored now (it was captured again since). A
        target file records its sample's fingerprint (:func:`sample_fingerprint`): stale where the sample's is
        another now, whatever the files' times (a copy or a checkout gives them new ones, in any order). A target
        file written by an rtp before fingerprints, or without one (:meth:`write`), is stale where the sample file
        is newer than it."""
        sample, stored = sample_path(self.root.parent, sample_id), self.path(sample_id, metric)
        if not stored.is_file():
            raise TargetError(f"no {metric} targets for sample {sample_id!r}; run `{self._command}`")
        if not sample.is_file():
            return False
        recorded = _recorded_fingerprint(stored)
        if recorded is not None:
            return sample_fingerprint(sample) != recorded
        return sample.stat().st_mtime > stored.stat().st_mtime

    def has(self, sample_id: str, metric: str) -> bool:
        """Whether up-to-date targets exist (missing, stale or truncated ones are computed by ``rtp targets``: a file
        cut short by a full disk or a copy is no zip archive)."""
        path = self.path(sample_id, metric)
        return path.is_file() and zipfile.is_zipfile(path) and not self.stale(sample_id, metric)

    def write(self, sample_id: str, metric: str, values: np.ndarray, size: tuple[int, int], *,
              sample_mtime_ns: int | None = None, fingerprint: str | None = None) -> None:
        """Store base-tile values (for PSNR: per-tile MSE) atomically. ``fingerprint``: the sample's
        :func:`sample_fingerprint` as it was when read for these values, which the file records, so that a sample
        written again while they were computed leaves them stale (:meth:`stale`), and a copy of the dataset does
        not. ``sample_mtime_ns``: the sample file's modification time (``st_mtime_ns``) then, which the file takes
        as its own (what an rtp before fingerprints judges by). Given neither, the file records the fingerprint
        of the sample file there now (none where there is none) and has the time of its write; given only
        ``sample_mtime_ns``, it records none, and is judged by the times."""
        if sample_mtime_ns is not None and (isinstance(sample_mtime_ns, bool) or not isinstance(sample_mtime_ns, int)):
            raise TargetError(f"sample_mtime_ns: expected an integer (st_mtime_ns) or None, got {sample_mtime_ns!r}")
        if fingerprint is not None and (not isinstance(fingerprint, str) or not fingerprint):
            raise TargetError(f"fingerprint: expected the sample's fingerprint (a string, sample_fingerprint) or None, "
                              f"got {fingerprint!r}")
        h, w = _frame_size(size)
        expected = (6, *tile_grid(h, w, self.base_tile))
        if not isinstance(values, np.ndarray) or values.dtype.kind not in "biuf" or values.shape != expected:
            got = f"{values.dtype} {values.shape}" if isinstance(values, np.ndarray) else type(values).__name__
            raise TargetError(f"{metric} targets of {sample_id}: expected numbers of shape {expected}, got {got}")
        bad = int(values.size - np.count_nonzero(np.isfinite(values)))
        if bad:  # (a NaN target trained in silence: the loss of every batch holding it NaN, or a tile never judged)
            raise TargetError(f"{metric} targets of sample {sample_id!r}: {bad} of {values.size} values are NaN or "
                              f"infinite (the metric's map of this sample: check its final images, or the metric's "
                              f"code if it is your own); nothing is written")
        if _stores_mse(metric) and (values < 0).any():  # (read back, each was a NaN PSNR until psnr_from_mse refused)
            raise TargetError(f"{metric} targets of sample {sample_id!r}: expected the tile mean squared errors (>= 0, "
                              f"the store keeps PSNR as its MSE), got {int((values < 0).sum())} negative, down to "
                              f"{float(values.min()):g} (PSNRs in dB? store sdk.mse_from_psnr of them); nothing is "
                              f"written")
        if fingerprint is None and sample_mtime_ns is None:
            fingerprint = sample_fingerprint(sample_path(self.root.parent, sample_id))
        stored: dict[str, np.ndarray] = {"values": values.astype(np.float32), "size": np.array([h, w], np.int64)}
        if fingerprint is not None:
            stored["sample"] = np.array(fingerprint)
        with atomic_output(self.path(sample_id, metric)) as tmp:
            with open(tmp, "wb") as f:
                np.savez(f, **stored)  # type: ignore[arg-type]
            if sample_mtime_ns is not None:
                os.utime(tmp, ns=(sample_mtime_ns, sample_mtime_ns))

    @property
    def _command(self) -> str:
        """The command that computes this dataset's targets, for the user to copy (its path quoted for a shell)."""
        return f"rtp targets {shlex.quote(str(self.root.parent))}"

    def load(self, sample_id: str, metric: str, tile: int) -> np.ndarray:
        """Targets in metric units (PSNR in dB) at ``tile``: float32 ``(6, ceil(H/tile), ceil(W/tile))``."""
        p = self.path(sample_id, metric)
        if not p.is_file():
            raise TargetError(f"no {metric} targets for sample {sample_id!r}; run `{self._command}`")
        if self.stale(sample_id, metric):
            raise TargetError(f"{metric} targets of sample {sample_id!r} are out of date, of the sample as it was "
                              f"before it was captured again; run `{self._command}`")
        try:
            with np.load(p) as z:
                values, size = np.asarray(z["values"]), tuple(int(v) for v in z["size"])
        except Exception as e:  # numpy's reader meets corrupt bytes with many exceptions (see _unreadable)
            raise _unreadable(p, "unreadable targets; delete the file and run `rtp targets` again", e) from e
        if len(size) != 2 or min(size) < 1 or values.shape != (6, *tile_grid(*size, self.base_tile)) or values.dtype.kind != "f":
            raise TargetError(f"{p}: expected float values of shape (6, tile rows, tile columns) of a frame of size "
                              f"(H, W) at base tile {self.base_tile}, got {values.dtype} {values.shape}, size {size}; "
                              "delete the file and run `rtp targets` again")
        bad = int(values.size - np.count_nonzero(np.isfinite(values)))
        if bad:  # (written by an rtp before the write refused them, or damaged: not trained on in silence)
            raise TargetError(f"{p}: {bad} of {values.size} targets are NaN or infinite; delete the file and run "
                              f"`{self._command}` again, which computes it anew")
        if _stores_mse(metric) and (values < 0).any():  # (written by an rtp before the write refused them)
            raise TargetError(f"{p}: {int((values < 0).sum())} of {values.size} stored mean squared errors are "
                              f"negative; delete the file and run `{self._command}` again, which "
                              f"computes it anew")
        declared = self.metrics.get(metric)
        pooled = pool_targets(values, size, self.base_tile, tile,
                              mse=_mean_pooled(metric, declared if isinstance(declared, Mapping) else {}))
        return psnr_from_mse(pooled) if _stores_mse(metric) else pooled


def sample_targets(sample: Any, metrics: tuple[str, ...], params: Mapping[str, Any], base_tile: int = BASE_TILE,
                   ) -> dict[str, np.ndarray]:
    """The stored form of one sample's targets: ``{metric: float32 (6, th, tw)}`` at ``base_tile``
    (PSNR as the tile MSE so that coarser tiles derive exactly). ``params`` holds ``ppd`` and ``weber_l``."""
    from rtp import metrics as M

    ref = sample.final("1x1")
    images = {r: sample.final(r) for r in PREDICTED_RATES}
    try:
        values = M.tile_targets(ref, images, metrics, base_tile, ppd=params["ppd"], weber_l=params["weber_l"],
                                flip_backend=params.get("flip_backend"), device=params.get("device"))
    except M.MetricError as err:  # (a plugin's map refused, a backend failed: which sample, to look at it)
        where = getattr(sample, "id", None)
        if where is None:
            raise
        raise M.MetricError(f"sample {where!r}: {err}") from err
    out = {}
    for m in metrics:
        v = values[m]
        if _stores_mse(m):  # store the tile MSE so that coarser tiles derive exactly
            with np.errstate(over="ignore"):
                v = mse_from_psnr(v)
        out[m] = v.astype(np.float32)
    return out


def _set_threads(threads: int | None) -> None:
    """Torch's intra-op threads in a Ray worker (two workers with two threads each on two cores thrash;
    a local pool's workers are set so by ``worker_pool``)."""
    if threads:
        try:
            import torch
        except ImportError:
            return
        torch.set_num_threads(threads)


def _compute_one(data_root: str, sample_id: str, metrics: tuple[str, ...], params: dict[str, Any],
                 threads: int | None = None) -> str:
    _set_threads(threads)
    store = TargetStore(data_root)
    todo = tuple(m for m in metrics if not store.has(sample_id, m))
    if not todo:
        return sample_id
    # (the sample's time before it is read: one captured again while its targets are computed leaves them stale;
    # they had the later time of their own write, and were kept as up to date)
    path = sample_path(data_root, sample_id)
    as_of = path.stat().st_mtime_ns
    fingerprint = sample_fingerprint(path)
    s = DatasetReader(data_root)[sample_id]
    h, w = s.size
    for m, v in sample_targets(s, todo, params, store.base_tile).items():
        store.write(sample_id, m, v, (h, w), sample_mtime_ns=as_of, fingerprint=fingerprint)
    return sample_id


def _check_memory(reader: DatasetReader, metrics: Sequence[str], workers: int | None, ray: str | None) -> None:
    """A dataset whose targets cannot be computed in this machine's memory is refused before any
    is: a :class:`TargetError` (FLIP's targets of a 3840x2160 sample take about 11 GB in a process).
    Where one process would fit and ``workers`` do not, the advice is fewer workers."""
    settings = reader.manifest.get("settings")
    size = settings.get("size") if isinstance(settings, dict) else None
    if ray not in (None, "local") or not (isinstance(size, list) and len(size) == 2
                                          and all(isinstance(v, int) and v > 0 for v in size)):
        return  # (on a cluster each node's workers are checked against its memory: ray_targets)
    n, (w, h) = workers or (cores() if ray == "local" else 1), size  # (a private Ray instance: a worker per core)
    one = job_bytes("targets", (w, h), metrics=metrics)
    fewer = n > 1 and one <= meminfo("MemTotal") + meminfo("SwapTotal")
    each = f" ({one / 2**30:.1f} GiB in each of {n} processes)" if n > 1 else ""
    check_memory(n * one, f"the {', '.join(metrics)} targets of its {w}x{h} samples take about {n * one / 2**30:.1f} "
                          f"GiB{each}", "workers" if fewer else "data",
                 "of memory: fewer workers" if fewer else "of memory: compute them on a larger machine (or on a Ray "
                 "cluster's: --ray ADDRESS)", job="the targets job", error=lambda message, name: TargetError(message))


def compute_targets(
    data_root: str | os.PathLike[str],
    metrics: tuple[str, ...] = TARGET_METRICS,
    *,
    ppd: float | str | None = None,
    weber_l: float | None = None,
    workers: int | None = 1,
    progress: Any = None,
    flip_backend: str | None = None,
    ray: str | None = None,
    device: str | None = "auto",
    _on_ray_actors: Any = None,
    _ppd_option: str = "ppd",
) -> int:
    """Compute (or complete) the per-tile targets of every sample of a dataset; returns how many
    samples were processed. Existing targets are kept, so an interrupted run resumes.

    ``flip_backend`` as in :func:`rtp.metrics.tile_targets` (default: the batched torch port when
    torch is installed). With ``workers > 1`` each worker process gets an equal share of the CPU's
    torch threads.

    ``ray`` computes on Ray instead (as in :func:`rtp.capture.capture`): each worker gets a sample's
    bytes and returns its targets, which this process writes.

    ``device`` runs the torch work (FLIP's port, LPIPS) there, as :func:`rtp.metrics.tile_targets`
    does: ``"auto"`` (default: the first GPU torch sees, else the CPU), ``"cpu"``, ``"cuda"``,
    ``"cuda:N"``, ``"mps"``; ``None``: the CPU. Checked before
    any work; every worker process uses it. Not a target parameter: a GPU gives the CPU's targets to
    float32 round-off, so a dataset may be completed on another device. A GPU with ``ray`` is refused
    (Ray gives a task no GPU unless it asks for one, and rtp's tasks do not).

    ``ppd="width"`` of samples under 58 pixels wide (under FLIP's 1 ppd) is refused before anything is
    computed or declared (``_ppd_option``: the name its error gives the option, ``rtp targets``' ``--ppd``)."""
    from concurrent.futures import FIRST_COMPLETED, BrokenExecutor, Future, wait

    from rtp import metrics as M

    from ._pool import WorkerDiedError, name_task, unfinished, worker_died, worker_pool

    if not isinstance(data_root, (str, os.PathLike)) or not os.fspath(data_root):  # (Path('') is the current folder)
        raise ParameterError(f"data_root: expected a dataset folder path, got {data_root!r}"
                             + (" (empty; '.' is the current folder)" if data_root == "" else ""), "data_root")
    if isinstance(metrics, str):  # (one name, not its letters: 'psnr' was the unknown metric 'p')
        metrics = (metrics,)
    if not isinstance(metrics, (list, tuple)) or not metrics:  # (none: nothing was computed, and 0 returned)
        raise ParameterError(f"metrics: expected a metric name or a non-empty list of them, got {metrics!r}", "metrics")
    metrics = tuple(dict.fromkeys(metrics))  # (a name given twice: its targets computed and written twice)
    for m in metrics:
        _check_name(m)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1):
        raise ParameterError(f"workers must be None or an integer >= 1, got {workers!r}", "workers")
    from ._ray import check_ray_address

    check_ray_address(ray)  # (its form, without Ray: a malformed address, before any sample is read or reported)
    if flip_backend is not None and flip_backend not in M.FLIP_BACKENDS:
        raise TargetError(f"flip_backend must be one of {', '.join(M.FLIP_BACKENDS)} or None, got {flip_backend!r}")
    M.check_dependencies(metrics)  # every missing package or weights file now, not after hours of work
    if ray is not None or (workers or 1) > 1:
        try:
            M.check_worker_metrics(metrics)  # (a metric the workers, new processes, would not know)
        except M.MetricParameterError as err:
            raise TargetError(str(err)) from None
    if device is not None:
        if ray is not None and device not in ("cpu", "auto"):
            raise ParameterError(f"device {device!r} with ray: Ray gives a task no GPU unless it asks for one, and "
                                 f"rtp's targets tasks do not; compute on this machine's GPU without ray, or on Ray's "
                                 f"CPUs (device cpu or auto)", "device")
        # (the device, and whether this torch can use it, now)
        if M.targets_device(metrics, device, flip_backend) is None and device not in ("cpu", "auto"):
            log.warning("device %r: %s run%s in numpy on the CPU; nothing of them runs on the device", device,
                        ", ".join(metrics), "s" if len(metrics) == 1 else "")
    # The parameters too, before they are declared in the manifest: a bad one stored there would refuse
    # every later run, good values included.
    if ppd is not None:
        M.resolve_ppd(ppd, 1)  # type: ignore[arg-type]  # (a string other than 'width' is what it refuses)
        ppd = ppd if isinstance(ppd, str) else float(ppd)  # (as weber_l: a float32 is no JSON value to declare)
        if not set(M.PPD_METRICS) & set(metrics):  # (it was taken and ignored)
            raise ParameterError(f"ppd: FLIP's pixels per degree, which only {' and '.join(M.PPD_METRICS)} use; the "
                                 f"metrics asked for are {', '.join(metrics)}", "ppd")
    if weber_l is not None:
        if isinstance(weber_l, bool) or not isinstance(weber_l, numbers.Real):  # ('0.5' was declared as a string:
            # every later run, the command line's 0.5 included, was refused as other parameters)
            raise ParameterError(f"weber_l: expected a number, got {weber_l!r}", "weber_l")
        weber_l = M.check_weber_l(weber_l)  # (a float: numpy's float32 is no JSON value to declare)
        if weber_l > MAX_WEBER_L:  # (1e308 was declared and gave all-zero targets)
            raise ParameterError(f"weber_l: expected at most {MAX_WEBER_L:g}, got {weber_l:g}: a JN target is at most "
                                 f"1 / weber_l, and below {1 / MAX_WEBER_L:g} (the smallest mean target a model's "
                                 f"transform takes) no model can be trained on the targets", "weber_l")
        if not any(M.metric_info(m).weber for m in metrics):
            raise ParameterError(f"weber_l: the environment luminance of {' and '.join(m for m in METRICS if METRICS[m].weber)}"
                                 f", which the metrics asked for ({', '.join(metrics)}) do not use", "weber_l")
    reader = DatasetReader(data_root)
    if isinstance(ppd, str) and reader.ids:  # ('width' of frames too narrow for it: refused now, not declared in the
        # manifest and then refused at the first sample's FLIP, in a worker, in Python's words on the command line)
        M.image_ppd("width", (reader._size or reader[reader.ids[0]].size)[1], _ppd_option)  # (the one str taken above)
    # (a process or a Ray worker a sample at most: --workers 8 on 2 samples was refused for 8 processes' memory)
    _check_memory(reader, metrics, None if workers is None and ray is None else
                  min(workers or cores(), max(1, len(reader.ids))), ray)
    store = TargetStore(data_root)
    store.root.mkdir(exist_ok=True)
    # Held to the end: a second job on the same targets would compute them again, and its declare could
    # write the manifest over this one's.
    with writer_lock(store.root, "rtp targets", lambda holder: TargetError(
            f"{store.root} is being written by another targets job ({holder}): wait for it to end")):
        # Read again under the lock: a job that held it until now may have declared metrics since the read above,
        # and this job's declare wrote its own older copy over them (their targets then refused as of parameters
        # the manifest does not record).
        store = TargetStore(data_root)
        # (a killed job's, its targets' and its manifest's: no other writer runs now)
        for tmp in (*store.root.glob("*/.*.tmp"), *store.root.glob(".manifest.json.*.tmp")):
            tmp.unlink(missing_ok=True)
        params: dict[str, Any] = {"ppd": M.DEFAULT_PPD if ppd is None else ppd,
                                  "weber_l": M.DEFAULT_WEBER_L if weber_l is None else weber_l}
        for m in metrics:  # the backend is not a parameter: both give the same targets (to float round-off)
            p: dict[str, Any] = {}
            if m in M.PPD_METRICS:
                p["ppd"] = params["ppd"]
            if M.metric_info(m).weber:
                p["weber_l"] = params["weber_l"]
            if m == "lpips":
                p["net"] = "alex-v0.1"
            own = M.metric_plugins().get(m)
            if own is not None:  # a plugin's definition: targets of another are refused, not mixed
                p.update({"plugin": dict(own.params), "pooling": own.pooling})
            store.declare(m, p)
        params["flip_backend"] = flip_backend
        params["device"] = device  # (like the backend, not a target parameter: not declared)
        ids = [i for i in reader.ids if not all(store.has(i, m) for m in metrics)]
        done = len(reader.ids) - len(ids)
        if progress:
            progress(done, len(reader.ids))
        if ray is not None and ids:
            from ._ray import ray_targets

            def advance(n: int) -> None:
                nonlocal done
                done += n
                if progress:
                    progress(done, len(reader.ids))

            todo = {i: tuple(m for m in metrics if not store.has(i, m)) for i in ids}
            ray_targets(str(data_root), todo, params, address=ray, workers=workers, progress=advance,
                        on_actors=_on_ray_actors)
        elif ray is not None or (workers or 1) <= 1 or not ids:  # (Ray with nothing to do starts no cluster; a
            # pool with nothing to do no process: --workers 2 on targets all there was a ValueError, "max_workers")
            for i in ids:
                try:
                    _compute_one(str(data_root), i, tuple(metrics), params)
                except Exception as exc:
                    name_task(exc, f"sample {i!r}")
                    raise
                done += 1
                if progress:
                    progress(done, len(reader.ids))
        else:
            n = min(workers or 1, len(ids))  # (a process a sample at most: an idle one took the cores' threads too)
            queued = deque(ids)
            # A sample each worker at a time, so that the samples in flight are known: a worker killed (by the
            # system for memory, by a signal) broke the pool, and every pending sample got "A process in the
            # process pool was terminated abruptly" with its traceback, naming none of them.
            running: dict[Future[str], str] = {}
            with worker_pool(n) as pool:  # each worker's torch on its share of the cores (worker_threads)
                while queued or running:
                    while queued and len(running) < n:
                        i = queued.popleft()
                        running[pool.submit(_compute_one, str(data_root), i, tuple(metrics), params)] = i
                    finished, _ = wait(running, return_when=FIRST_COMPLETED)
                    for f in sorted(finished, key=lambda f: f.exception() is not None):  # (those done first)
                        try:
                            f.result()
                        except BrokenExecutor as exc:
                            lost = sorted(unfinished(running))
                            raise WorkerDiedError(
                                f"{worker_died('targets')} while computing {'sample' if len(lost) == 1 else 'one of samples'} "
                                f"{', '.join(map(repr, lost))}; the targets of {done} of {len(reader.ids)} samples "
                                f"are kept: the same command computes the rest") from exc
                        except Exception as exc:  # (a worker's: its traceback said nothing of the sample)
                            name_task(exc, f"sample {running[f]!r}")
                            raise
                        del running[f]
                        done += 1
                        if progress:
                            progress(done, len(reader.ids))
        return len(ids)
