"""The rtp dataset format: one compressed ``.npz`` per sample plus a manifest (docs/dataset.md).

Layout of a dataset folder::

    manifest.json              format version, renderer settings, package versions, sample index
    samples/<id>.npz           one sample: buffers (below) and a JSON "meta" entry
    targets/...                per-tile metric targets, written by `rtp targets` (beside the samples)

Every write is atomic (temporary file, fsync, rename), so an interrupted capture never leaves a
half-written sample and resumes by skipping the ids already present.

Buffers of a sample, with the precision they are stored at:

=====================  ================  ===================================================
buffer                 stored as         channels (``sdk.CHANNELS`` names)
=====================  ================  ===================================================
``reprojected``        uint8 (H, W, 3)   reprojected.r/g/b (display-encoded)
``seen``               uint8 (H, W)      seen (0 or 1, stored as 0 or 255)
``albedo``             uint8 (H, W, 3)   albedo.r/g/b (display-encoded)
``normal``             float16 (H,W,3)   normal.x/y/z (unit, view space, the camera looking down -z)
``roughness`` ...      uint8 (H, W)      roughness, metallic, specular, shadow, emissive
``depth``              float16 (H, W)    depth (metres along -z)
``motion``             float16 (H,W,2)   motion.x/y (pixels: previous minus current position, x right, y down)
``final_<rate>``       uint8 (H, W, 3)   final display-encoded colour at each of the 7 rates
=====================  ================  ===================================================

uint8 buffers hold ``round(255 v)``: a quantisation error of at most 1/510, the precision of the
8-bit PNGs the paper trained on. Readers decode to float32.
"""

from __future__ import annotations

import io
import json
import logging
import os
import re
import reprlib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rtp.sdk import (
    ALL_RATES,
    CHANNELS,
    EXIT_USAGE,
    InputDtypeError,
    InputShapeError,
    RtpError,
    block_variances,
    depth_edges,
    luma,
    pixel_differences,
    tile_variances,
)
from rtp.sdk.files import LOCK_NAME, atomic_output

from ._images import _image_bytes, read_image_values

__all__ = [
    "BUFFERS",
    "FORMAT",
    "FORMAT_VERSION",
    "DatasetError",
    "DatasetReader",
    "DatasetWriter",
    "PaperDatasetReader",
    "Sample",
    "open_dataset",
    "write_png",
]

log = logging.getLogger("rtp.capture")

FORMAT = "rtp-dataset"
FORMAT_VERSION = 1
_ID_RE = re.compile(r"[A-Za-z0-9_.-]+\Z")
#: The longest sample id: its file name, with the temporary prefix of an atomic write, stays within
#: the 255 bytes a file system allows (a longer one was the system's "File name too long").
MAX_ID_LENGTH = 200


class DatasetError(RtpError):
    """A dataset folder is missing, of another format or version, or a sample is malformed."""

    exit_code = EXIT_USAGE


@dataclass(frozen=True)
class _Buffer:
    dtype: str  # "u8" (values in [0, 1] stored as round(255 v)) or "f16"
    channels: tuple[str, ...]  # sdk channel names, in the buffer's last-axis order; () for images


def _b(dtype: str, *channels: str) -> _Buffer:
    return _Buffer(dtype, channels)


#: Buffer name -> storage precision and the channels it holds.
BUFFERS: dict[str, _Buffer] = {
    "reprojected": _b("u8", "reprojected.r", "reprojected.g", "reprojected.b"),
    "seen": _b("u8", "seen"),
    "albedo": _b("u8", "albedo.r", "albedo.g", "albedo.b"),
    "normal": _b("f16", "normal.x", "normal.y", "normal.z"),
    "roughness": _b("u8", "roughness"),
    "metallic": _b("u8", "metallic"),
    "specular": _b("u8", "specular"),
    "shadow": _b("u8", "shadow"),
    "emissive": _b("u8", "emissive"),
    "depth": _b("f16", "depth"),
    "motion": _b("f16", "motion.x", "motion.y"),
    **{f"final_{r}": _b("u8") for r in ALL_RATES},
}
# Every sdk channel has exactly one storage place (tests/test_dataset.py checks the coverage).
_CHANNEL_SOURCE = {c: (name, i) for name, buf in BUFFERS.items() for i, c in enumerate(buf.channels)}
#: Channels computed from stored buffers when read, by the SDK's definition (one source of truth).
_DERIVED: dict[str, Any] = {"depth.edge": lambda s: depth_edges(s.buffer("depth")),
                            "reprojected.y": lambda s: luma(s.buffer("reprojected")),
                            "albedo.y": lambda s: luma(s.buffer("albedo")),
                            "reprojected.y.dx": lambda s: pixel_differences(luma(s.buffer("reprojected")))[0],
                            "reprojected.y.dy": lambda s: pixel_differences(luma(s.buffer("reprojected")))[1],
                            "reprojected.y.blocks": lambda s: block_variances(luma(s.buffer("reprojected"))),
                            "albedo.y.blocks": lambda s: block_variances(luma(s.buffer("albedo"))),
                            "reprojected.y.tiles": lambda s: tile_variances(luma(s.buffer("reprojected"))),
                            "albedo.y.tiles": lambda s: tile_variances(luma(s.buffer("albedo")))}


#: How far past [0, 1] a float value of an 8-bit buffer may be before it is refused rather than clipped: an
#: engine's overshoot (a sharpened or slightly HDR final colour, rounding) is clipped as an 8-bit write would; past
#: it, values are of another encoding (0-255 floats, signed data)
_U8_SLACK = 0.5
#: What the float16 buffers hold (the errors' hint).
_F16_WHAT = {"normal": "unit normals in [-1, 1]", "depth": "metres along -z", "motion": "pixels"}


def _encode(name: str, arr: np.ndarray, shape: tuple[int, int] | None) -> np.ndarray:
    spec = BUFFERS[name]
    a = np.asarray(arr)
    if a.dtype != np.uint8 and a.dtype.kind != "f":  # an int64 image of 0-255 was stored as all 1.0
        raise InputDtypeError(f"buffer {name!r}: expected float values (or uint8 for an 8-bit buffer), got {a.dtype}")
    if 0 in a.shape:
        raise InputShapeError(f"buffer {name!r}: empty, shape {a.shape}", tuple(a.shape), "(H, W, ...) with H, W >= 1")
    n = len(spec.channels) or 3
    expected = (n,) if n > 1 else ()
    if a.ndim not in (2, 3) or tuple(a.shape[2:]) != expected or (shape is not None and a.shape[:2] != shape):
        want = f"(H, W{', ' + str(n) if n > 1 else ''})"
        raise InputShapeError(f"buffer {name!r}: expected shape {want} matching the sample, got {a.shape}", tuple(a.shape), want)
    if a.dtype == np.uint8 and spec.dtype != "u8":  # (uint8 normals were stored as 0-255 float16 "normals")
        raise InputDtypeError(f"buffer {name!r}: uint8 values, but {name} is stored as float16 (its values as they "
                              f"are: {_F16_WHAT.get(name, 'float values')}); give float values")
    if not np.all(np.isfinite(a)):
        raise DatasetError(f"buffer {name!r} holds NaN or infinite values")
    if spec.dtype == "u8":
        if a.dtype == np.uint8:
            if name == "seen" and a.max() == 1:  # (a 0/1 mask, stored as is, read back as 1/255: "seen" nowhere)
                raise DatasetError(f"buffer {name!r}: uint8 values 0 and 1, but a uint8 buffer holds round(255 v), "
                                   f"so a seen pixel is 255; give the mask as float (or bool .astype(np.float32)) "
                                   f"values 0 and 1, or multiply it by 255")
            return a
        lo, hi = float(a.min()), float(a.max())
        if lo < -_U8_SLACK or hi > 1.0 + _U8_SLACK:  # (an albedo of 0-255 floats was stored as all 1.0)
            raise DatasetError(f"buffer {name!r}: values in [{lo:.4g}, {hi:.4g}], expected [0, 1] (stored as "
                               f"round(255 v)); give 8-bit values as uint8, or divide them by 255")
        return np.round(np.clip(a, 0.0, 1.0) * 255.0).astype(np.uint8)
    # Saturate rather than overflow to inf: the motion of a point that was behind the previous
    # camera can exceed float16's range (65504 pixels).
    big = float(np.finfo(np.float16).max)
    return np.clip(a, -big, big).astype(np.float16)


def _unreadable(path: Path, what: str, err: Exception) -> DatasetError:
    """The DatasetError for a file a third-party parser (numpy's .npz/.npy reader, Pillow) choked on.

    Those parsers meet corrupted bytes with a wide, undocumented set of exceptions (BadZipFile,
    zlib.error, EOFError, ValueError, KeyError, tokenize.TokenError and SyntaxError from a mangled .npy
    header, MemoryError from a header claiming a huge shape, OSError, ...), so every reader call on a
    dataset file is guarded with ``except Exception`` and re-raised as this, chained with ``from``.
    """
    return DatasetError(f"{path}: {what} ({type(err).__name__}: {err})")


_STORED = {"u8": np.dtype(np.uint8), "f16": np.dtype(np.float16)}


def _decode(name: str, raw: Any) -> np.ndarray:
    spec = BUFFERS[name]
    if not isinstance(raw, np.ndarray) or raw.dtype != _STORED[spec.dtype]:
        found = raw.dtype if isinstance(raw, np.ndarray) else type(raw).__name__
        raise DatasetError(f"buffer {name!r}: stored as {found}, expected {_STORED[spec.dtype]}")
    if spec.dtype == "u8":
        return raw.astype(np.float32) / 255.0
    return raw.astype(np.float32)


class Sample:
    """One captured sample. Buffers are decoded to float32 on access (and cached)."""

    def __init__(self, sample_id: str, loader: Any, meta: Mapping[str, Any], where: Any = None) -> None:
        self.id = sample_id
        self.meta: Mapping[str, Any] = meta
        # what its errors name: the file it was read from where there is one (an id alone did not say which folder
        # of several, rtp train --data a,b), else the id
        self._where = f"{where}" if where is not None else f"sample {sample_id!r}"
        #: Buffers the dataset does not hold (an engine's frames imported without them: stored as zeros).
        self.absent: frozenset[str] = frozenset()
        self._loader = loader
        self._cache: dict[str, np.ndarray] = {}
        self._hw: tuple[int, int] | None = None
        #: ``(H, W)`` the dataset's manifest gives its samples (``settings["size"]``), where it gives one.
        self._manifest_hw: tuple[int, int] | None = None

    def buffer(self, name: str) -> np.ndarray:
        """A buffer as float32 ``(H, W)`` or ``(H, W, C)`` (see :data:`BUFFERS`).

        A buffer of another shape than :data:`BUFFERS` gives, of another size than the sample's other
        buffers, or holding NaN or infinite values is a malformed sample: :class:`DatasetError`.
        """
        if not isinstance(name, str) or name not in BUFFERS:
            raise DatasetError(f"unknown buffer {name!r}; buffers are {', '.join(BUFFERS)}")
        if name not in self._cache:
            self._cache[name] = self._checked(name, self._loader(name))
        return self._cache[name]

    def _checked(self, name: str, a: np.ndarray) -> np.ndarray:
        n = len(BUFFERS[name].channels) or 3
        want = f"(H, W, {n})" if n > 1 else "(H, W)"
        if a.ndim != (3 if n > 1 else 2) or (n > 1 and a.shape[2] != n) or 0 in a.shape:
            raise DatasetError(f"{self._where}: buffer {name!r} has shape {a.shape}, expected {want}")
        hw = (int(a.shape[0]), int(a.shape[1]))
        if self._hw is not None and hw != self._hw:
            raise DatasetError(f"{self._where}: buffer {name!r} is {hw[1]}x{hw[0]}, the sample's other buffers "
                               f"are {self._hw[1]}x{self._hw[0]}")
        if self._manifest_hw is not None and hw != self._manifest_hw:
            # (a sample of another dataset copied in, or captured at another size: read as it was, and rtp train
            # refused the mix much later, or trained on one size of a dataset its manifest says is of another)
            m = self._manifest_hw
            raise DatasetError(f"{self._where}: buffer {name!r} is {hw[1]}x{hw[0]}, but the dataset's manifest says "
                               f"its samples are {m[1]}x{m[0]} (settings size); {_REWRITE}")
        if not np.isfinite(a).all():
            raise DatasetError(f"{self._where}: buffer {name!r} holds NaN or infinite values")
        self._hw = hw
        return a

    def channel(self, name: str) -> np.ndarray:
        """One input channel as float32 ``(H, W)``."""
        if isinstance(name, str) and name in _DERIVED:
            return _DERIVED[name](self)
        if not isinstance(name, str) or name not in _CHANNEL_SOURCE:
            raise DatasetError(f"unknown channel {name!r}; channels are {', '.join(CHANNELS)}")
        buf, i = _CHANNEL_SOURCE[name]
        if buf in self.absent:
            raise DatasetError(f"channel {name!r}: this dataset has no {buf} (its frames were imported without a {buf} "
                               f"G-buffer, manifest settings 'absent'); a model reading it cannot train or be judged on "
                               f"it: leave {name} out of the inputs, or import frames that hold it")
        b = self.buffer(buf)
        return b if b.ndim == 2 else b[..., i]

    def inputs(self, names: Sequence[str]) -> np.ndarray:
        """Model input planes in ``names`` order: float32 ``(C, H, W)``, as ``predict`` takes them."""
        if isinstance(names, str) or not isinstance(names, Iterable) or not (names := list(names)):
            raise DatasetError(f"inputs: expected a non-empty list of channel names, got {names!r}")
        return np.stack([self.channel(n) for n in names]).astype(np.float32, copy=False)

    def final(self, rate: str) -> np.ndarray:
        """The final display-encoded image at ``rate``: float32 ``(H, W, 3)`` in [0, 1]."""
        if not isinstance(rate, str) or rate not in ALL_RATES:
            raise DatasetError(f"unknown rate {rate!r}; rates are {', '.join(ALL_RATES)}")
        return self.buffer(f"final_{rate}")

    @property
    def size(self) -> tuple[int, int]:
        """``(H, W)``."""
        return tuple(self.buffer("final_1x1").shape[:2])


def sample_path(root: str | os.PathLike[str], sample_id: str) -> Path:
    """Where the sample ``sample_id`` of the dataset folder ``root`` is stored."""
    return Path(root) / "samples" / f"{sample_id}.npz"


def _json_object(value: Any, what: str, *, allow_nan: bool = True) -> dict[str, Any]:
    """A JSON-clean copy of the mapping ``value`` (what the manifest or a sample's meta stores), or a DatasetError
    naming ``what``: a numpy number, a NaN or a set was the json module's raw TypeError or ValueError."""
    if not isinstance(value, Mapping):
        raise DatasetError(f"{what}: expected a mapping of names to JSON values, got {type(value).__name__}")
    try:
        return dict(json.loads(json.dumps(dict(value), allow_nan=allow_nan)))
    except (TypeError, ValueError, RecursionError) as err:
        finite = "" if allow_nan else ", no NaN or infinity"
        raise DatasetError(f"{what}: expected JSON values (str, int, float, bool, None, lists and mappings of them; "
                           f"float(x) for a numpy number{finite}), got {reprlib.repr(dict(value))} ({err})") from err


def _check_id(sample_id: str) -> None:
    if not isinstance(sample_id, str) or not _ID_RE.match(sample_id) or len(sample_id) > MAX_ID_LENGTH:
        raise DatasetError(f"sample id {reprlib.repr(sample_id)}: use letters, digits, '.', '_' and '-', at most "
                           f"{MAX_ID_LENGTH} of them")


def encode_sample(sample_id: str, buffers: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> bytes:
    """One sample as the bytes of its ``.npz`` file (what :meth:`DatasetWriter.write` stores).

    Validates like ``write``: every buffer of :data:`BUFFERS`, shapes matching ``final_1x1``, finite
    values, JSON-clean meta. Remote capture workers return these bytes; the driver writes them with
    :meth:`DatasetWriter.write_encoded`."""
    _check_id(sample_id)
    missing = [b for b in BUFFERS if b not in buffers]
    extra = [b for b in buffers if b not in BUFFERS]
    if missing or extra:
        raise DatasetError(f"sample {sample_id}: missing buffers {missing}, unknown buffers {extra}")
    shape = tuple(np.asarray(buffers["final_1x1"]).shape[:2])
    encoded = {name: _encode(name, buffers[name], shape) for name in BUFFERS}
    meta_json = json.dumps(_json_object(meta, f"sample {sample_id}: meta", allow_nan=False), sort_keys=True)
    out = io.BytesIO()
    np.savez_compressed(out, meta=np.frombuffer(meta_json.encode(), dtype=np.uint8), **encoded)  # type: ignore[arg-type]
    return out.getvalue()


def _header_hw(npz: Any, name: str) -> tuple[int, int] | None:
    """``(H, W)`` of the buffer ``name`` of an open ``.npz`` archive, read from its array header (not its data);
    None where its shape is not an image's."""
    with npz.zip.open(f"{name}.npy") as fh:
        version = np.lib.format.read_magic(fh)
        header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape = tuple(header(fh)[0])
    return (int(shape[0]), int(shape[1])) if len(shape) in (2, 3) else None


class DatasetWriter:
    """Writes samples into a dataset folder; resumable (``has`` tells which ids exist).

    ``settings`` (renderer settings, resolution, package versions) go into the manifest when the
    folder is created; reopening a folder with different settings raises :class:`DatasetError`, unless
    it holds nothing made with them yet (no sample, no targets: :func:`holds_nothing`, a job killed or
    refused before its first sample): then the new settings replace them, with a warning, as in a new folder.
    """

    def __init__(self, root: str | os.PathLike[str], settings: Mapping[str, Any] | None = None) -> None:
        self.root = Path(root)
        self.samples_dir = self.root / "samples"
        manifest = self.root / "manifest.json"
        settings = _json_object(settings or {}, "settings")  # JSON-clean copy
        for folder in (self.root, self.samples_dir):  # (the system's NotADirectoryError or FileExistsError, untyped)
            if folder.exists() and not folder.is_dir():
                raise DatasetError(f"{folder}: expected a folder{' of samples' if folder == self.samples_dir else ''}, "
                                   f"found a file: write the dataset into another folder")
        replace = False
        if manifest.exists():  # (checked before anything is made: a refused folder is left as it was)
            current = _read_manifest(self.root)
            before = current.get("settings")
            if before != settings and holds_nothing(self.root, current):
                # (a job killed or refused before its first sample left its manifest: a rerun with a corrected
                # option was refused as "captured with other settings" until the folder was deleted by hand)
                replace = True
                log.warning("%s holds no sample yet: its manifest's settings (%s) are replaced by this job's", self.root,
                            _differ(before, settings))
            elif before != settings:
                raise DatasetError(f"{self.root} was captured with other settings ({_differ(before, settings)}); use "
                                   f"another folder or the same settings")
        #: ``(H, W)`` of the samples as ``settings["size"]`` gives it (the folder's, where it has a manifest: the same)
        self._hw = _settings_hw(settings)
        self.samples_dir.mkdir(parents=True, exist_ok=True)
        if replace or not manifest.exists():  # (replaced: a fresh manifest, as a new folder's)
            self._write_manifest({"format": FORMAT, "format_version": FORMAT_VERSION, "settings": settings})

    def _write_manifest(self, data: Mapping[str, Any]) -> None:
        with atomic_output(self.root / "manifest.json") as tmp:
            tmp.write_text(json.dumps(data, indent=1, sort_keys=True), encoding="utf-8")

    def remove_stale(self) -> int:
        """Delete temporary files a killed writer left behind; call only while no writer is active."""
        stale = [*self.samples_dir.glob(".*.tmp"), *self.root.glob(".manifest.json.*.tmp")]
        for p in stale:
            p.unlink(missing_ok=True)
        return len(stale)

    def has(self, sample_id: str) -> bool:
        return sample_path(self.root, sample_id).is_file()

    def write(self, sample_id: str, buffers: Mapping[str, np.ndarray], meta: Mapping[str, Any]) -> Path:
        """Write one sample atomically. ``buffers`` must hold every buffer of :data:`BUFFERS`."""
        return self.write_encoded(sample_id, encode_sample(sample_id, buffers, meta))

    def write_encoded(self, sample_id: str, data: bytes) -> Path:
        """Write a sample :func:`encode_sample` made (on this machine or a remote worker) atomically.

        The archive's index is checked first (meta and every buffer present), so a truncated or
        foreign payload raises :class:`DatasetError` and nothing is written."""
        _check_id(sample_id)
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as npz:
                names = set(npz.files)
                json.loads(bytes(npz["meta"]).decode())
                hw = _header_hw(npz, "final_1x1") if "final_1x1" in names else None
        except Exception as err:  # numpy's reader on corrupted bytes; see _unreadable
            raise DatasetError(f"sample {sample_id}: the encoded sample is unreadable ({type(err).__name__}: {err})") from err
        missing = [b for b in BUFFERS if b not in names]
        if missing:
            raise DatasetError(f"sample {sample_id}: the encoded sample lacks buffers {missing}")
        if self._hw is not None and hw != self._hw:  # (it was written, and every reader then refused it)
            found = f"{hw[1]}x{hw[0]}" if hw is not None else "of no (H, W, 3) shape"
            raise DatasetError(f"sample {sample_id}: its frames are {found}, but {self.root}'s samples are "
                               f"{self._hw[1]}x{self._hw[0]} (its manifest's settings size); nothing written")
        path = sample_path(self.root, sample_id)
        with atomic_output(path) as tmp:
            tmp.write_bytes(data)
        return path

    def finalize(self, extra: Mapping[str, Any] | None = None) -> None:
        """Record the sample index and sizes in the manifest (safe to call after every run)."""
        data = _read_manifest(self.root)
        # (the samples a reader reads: a copy "x (1).npz" or a folder "x.npz" was listed, and every reader then
        # warned that the manifest's sample was missing and that a capture would capture it again)
        ids = [i for i in _listed_ids(self.samples_dir) if len(i) <= MAX_ID_LENGTH]
        data["samples"] = ids
        data["bytes_per_sample"] = int(sum(sample_path(self.root, i).stat().st_size for i in ids) / max(len(ids), 1))
        if extra:
            reserved = sorted(set(extra) & {"format", "format_version", "settings", "samples", "bytes_per_sample"})
            if reserved:  # (format "mine" left a folder no reader opens)
                raise DatasetError(f"finalize: {reserved} are the manifest's own keys, not extra ones")
            data.update(_json_object(extra, "finalize"))
        self._write_manifest(data)


def _differ(before: Any, settings: Mapping[str, Any]) -> str:
    """The keys in which a manifest's settings ``before`` differ from ``settings``, with both values (not two whole
    dictionaries in which the user hunted for the one difference)."""
    if not isinstance(before, dict):
        return f"existing: {before!r}, new: {dict(settings)!r}"
    keys = sorted(k for k in set(before) | set(settings) if before.get(k) != settings.get(k))
    return "; ".join(f"{k}: {before.get(k)!r} there, {settings.get(k)!r} now" for k in keys)


def holds_nothing(root: str | os.PathLike[str], manifest: Mapping[str, Any]) -> bool:
    """Whether the dataset folder ``root`` (of the manifest ``manifest``) holds nothing made with its settings: no
    sample file in samples/ (a killed write's temporary files aside), none listed by the manifest, and no targets.
    Such a folder's settings are replaced by those of the next job that writes it (:class:`DatasetWriter`), as a new
    folder's would be."""
    root = Path(root)
    if manifest.get("samples"):
        return False
    try:
        samples = root / "samples"
        if samples.is_dir() and any(p.name.endswith(".npz") for p in samples.iterdir()):
            return False
        targets = root / "targets"
        if targets.exists() and (not targets.is_dir() or any(p.name != LOCK_NAME for p in targets.iterdir())):
            return False
    except OSError:  # (unlistable: not known to be empty)
        return False
    return True


def _listed_ids(folder: Path) -> list[str]:
    """The ids of the sample files in the samples folder ``folder``, sorted: files ``<id>.npz`` whose id is of a
    sample's letters (of any length: a reader leaves out, with a warning, those longer than a sample id may be).
    What a reader reads and what the manifest lists."""
    try:
        return sorted(p.stem for p in folder.glob("*.npz") if _ID_RE.match(p.stem) and p.is_file())
    except OSError as err:
        raise DatasetError(f"{folder}: cannot be listed ({err})") from err


def _read_manifest(root: Path) -> dict[str, Any]:
    path = root / "manifest.json"
    if not path.is_file():
        if path.is_symlink() and not path.exists():
            raise DatasetError(f"{path}: a link to {os.readlink(path)!r}, which does not exist: the dataset's manifest "
                               f"was moved or deleted")
        if path.exists():  # (a folder, a pipe: was "no manifest.json", of a folder that plainly holds one)
            kind = "a folder" if path.is_dir() else "not a regular file"
            raise DatasetError(f"{path} is {kind}, not the dataset's manifest file (JSON, written by rtp capture or "
                               f"rtp import): move it aside and restore the manifest, or capture into a new folder")
        raise DatasetError(f"{root} is not an rtp dataset: no manifest.json")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as err:  # unreadable, not UTF-8, not JSON
        raise DatasetError(f"{path}: not a readable JSON manifest ({type(err).__name__}: {err})") from err
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        found = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise DatasetError(f"{path}: not an rtp dataset manifest (format {found!r})")
    version = data.get("format_version", 0)
    if isinstance(version, bool) or not isinstance(version, int) or version < 0:
        raise DatasetError(f"{path}: format_version must be a non-negative integer, got {version!r}")
    if version > FORMAT_VERSION:
        raise DatasetError(f"{path}: dataset format {version} is newer than this rtp reads ({FORMAT_VERSION}): "
                           f"upgrade rtp (a newer checkout of it: the rtp on PyPI is another project) to read it")
    return data


def _settings_hw(settings: Any) -> tuple[int, int] | None:
    """``(H, W)`` from a manifest's ``settings`` whose ``size`` is ``[W, H]`` (positive integers), else None."""
    size = settings.get("size") if isinstance(settings, dict) else None
    if (isinstance(size, list) and len(size) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in size)):
        return int(size[1]), int(size[0])
    return None


def _folder(root: object) -> Path:
    """``root`` as the Path of an existing folder, or DatasetError."""
    if not isinstance(root, (str, os.PathLike)):
        raise DatasetError(f"expected a dataset folder path, got {type(root).__name__}")
    try:
        p = Path(root)
        is_dir = p.is_dir()
    except (OSError, ValueError, TypeError) as err:  # a name too long, a NUL byte
        raise DatasetError(f"no dataset folder at {str(root)[:200]!r} ({err})") from err
    if not is_dir:
        raise DatasetError(f"no dataset folder at {str(p)!r}")
    return p


_MISSING_SAID: set[tuple[str, int]] = set()
_LONG_SAID: set[tuple[str, int]] = set()


class DatasetReader:
    """Reads an rtp dataset folder. Iterating yields :class:`Sample` objects in id order.

    Whatever is malformed (the manifest, a sample file, a buffer's dtype, shape or values) raises
    :class:`DatasetError` naming the file, when the folder is opened or the buffer first read.
    """

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = _folder(root)
        self.manifest = _read_manifest(self.root)
        folder = self.root / "samples"
        if folder.exists() and not folder.is_dir():
            raise DatasetError(f"{folder}: expected the folder of the samples, found a file")
        found = _listed_ids(folder)
        # (a sample file renamed, or an older rtp's, with an id longer than a sample's: listed, then refused by
        # __getitem__, so iterating the dataset failed on it; left out, named in a warning)
        self.ids = [i for i in found if len(i) <= MAX_ID_LENGTH]
        long = [i for i in found if len(i) > MAX_ID_LENGTH]
        if long and (str(self.root), len(long)) not in _LONG_SAID:
            _LONG_SAID.add((str(self.root), len(long)))  # (once a process, as the missing ones below)
            log.warning("%s: %d sample file%s in samples/ %s an id longer than %d characters (%s%s), which no sample "
                        "has: renamed, or an older rtp's? left out; rename %s to at most %d characters (letters, "
                        "digits, '.', '_' and '-') to read %s", self.root, len(long), "s" if len(long) > 1 else "",
                        "have" if len(long) > 1 else "has", MAX_ID_LENGTH,
                        ", ".join(f"{i[:40]}...{i[-20:]}.npz" for i in long[:3]), ", ..." if len(long) > 3 else "",
                        "them" if len(long) > 1 else "it", MAX_ID_LENGTH, "them" if len(long) > 1 else "it")
        listed = self.manifest.get("samples")
        if isinstance(listed, list):
            missing = sorted(set(map(str, listed)) - set(found))
            if missing and (str(self.root), len(missing)) not in _MISSING_SAID:
                _MISSING_SAID.add((str(self.root), len(missing)))  # (once a process: readers are opened often)
                log.warning("%s: %d of the %d samples its manifest lists are not in samples/ (%s%s): deleted or moved "
                            "since the last capture? they are left out; the same rtp capture command captures them "
                            "again", self.root, len(missing), len(listed), ", ".join(missing[:3]),
                            ", ..." if len(missing) > 3 else "")

    def __len__(self) -> int:
        return len(self.ids)

    def __iter__(self) -> Iterator[Sample]:
        return (self[i] for i in self.ids)

    def __getitem__(self, sample_id: str) -> Sample:
        if not isinstance(sample_id, str) or not _ID_RE.match(sample_id) or len(sample_id) > MAX_ID_LENGTH:
            raise DatasetError(f"no sample {reprlib.repr(sample_id)} in {self.root} (ids are letters, digits, '.', '_' "
                               f"and '-', at most {MAX_ID_LENGTH} of them)")
        path = sample_path(self.root, sample_id)
        if not path.is_file():
            raise DatasetError(f"no sample {sample_id!r} in {self.root}")
        sample = _open_sample(sample_id, path, path)
        sample.absent = self.absent
        sample._manifest_hw = self._size
        return sample

    @property
    def _size(self) -> tuple[int, int] | None:
        """``(H, W)`` of the samples as the manifest's ``settings["size"]`` (``[W, H]``) gives it; None where it
        gives none (a folder written by :class:`DatasetWriter` without settings)."""
        return _settings_hw(self.manifest.get("settings"))

    @property
    def absent(self) -> frozenset[str]:
        """The buffers this dataset does not hold (``settings["absent"]`` of a dataset imported from an
        engine's frames without them); reading a channel of one is a :class:`DatasetError`."""
        settings = self.manifest.get("settings")
        names = settings.get("absent", []) if isinstance(settings, dict) else []
        if not isinstance(names, list) or not all(isinstance(n, str) and n in BUFFERS for n in names):
            raise DatasetError(f"{self.root / 'manifest.json'}: settings 'absent' must list buffer names of "
                               f"{', '.join(BUFFERS)}, got {names!r}")
        return frozenset(names)

    def select(self, **meta: Any) -> list[str]:
        """Ids of samples whose meta has the given values, e.g. ``select(scene="oa_dm1")``."""
        return [s.id for s in self if all(s.meta.get(k) == v for k, v in meta.items())]


# -- the paper's released layout ----------------------------------------------------------------

_PAPER_BUFFERS: dict[str, tuple[str, int | slice]] = {
    # rtp buffer: (file stem, channel index or slice)
    "reprojected": ("reproject_1x1", slice(0, 3)),
    "seen": ("reproject_1x1", 3),
    "albedo": ("diffuse_1x1", slice(0, 3)),
    "normal": ("normals_1x1", slice(0, 3)),
    "roughness": ("specular_1x1", 3),
    "specular": ("specular_1x1", 0),
    "emissive": ("emissive_1x1", 0),
    "shadow": ("extra_1x1", 0),
    **{f"final_{r}": (f"output_{r}", slice(0, 3)) for r in ALL_RATES},
}


def sample_from_bytes(sample_id: str, data: bytes, where: str | None = None) -> Sample:
    """A :class:`Sample` read from the bytes of its ``.npz`` file (what :func:`encode_sample` makes); ``where`` names
    the file they were read from in its errors (default: the sample, in memory)."""
    return _open_sample(sample_id, io.BytesIO(data), where or f"sample {sample_id} (in memory)")


#: What to do about a sample file that cannot be read (the errors' hint).
_REWRITE = ("a damaged or foreign sample file: delete it, and the command that wrote the dataset (the same rtp capture "
            "or rtp import) writes it again")


def _open_sample(sample_id: str, source: Any, path: Any) -> Sample:
    try:
        npz = np.load(source, allow_pickle=False)
        if not isinstance(npz, np.lib.npyio.NpzFile):
            raise DatasetError(f"{path}: not an .npz archive (a {type(npz).__name__})")
        meta = json.loads(bytes(npz["meta"]).decode())
    except RtpError:
        raise
    except Exception as err:  # numpy's reader on corrupted bytes; see _unreadable
        raise _unreadable(path, "unreadable sample", err) from err
    if not isinstance(meta, dict):
        raise DatasetError(f"{path}: the sample's meta is not a JSON object")

    # (what to do about a damaged or foreign file of a dataset folder; nothing for a sample in memory)
    fix = f"; {_REWRITE}" if isinstance(path, Path) else ""

    def load(name: str) -> np.ndarray:
        if name not in npz.files:
            raise DatasetError(f"{path}: buffer {name!r} missing{fix}")
        try:
            return _decode(name, npz[name])
        except RtpError as err:
            raise DatasetError(f"{path}: {err}{fix}") from err
        except Exception as err:  # numpy's reader on corrupted bytes; see _unreadable
            raise DatasetError(f"{_unreadable(path, f'buffer {name!r} is unreadable', err)}{fix}") from err

    return Sample(sample_id, load, meta, path if isinstance(path, Path) else None)


class PaperDatasetReader:
    """Reads the paper's released dataset layout: one folder per sample holding
    ``<buffer>_<rate>.png`` files (the paper's released dataset; docs/dataset.md).

    Values are returned as stored: 8-bit sRGB-encoded PNG values in [0, 1]. In that layout the
    normals are view-space normals written through an sRGB target with negative components clamped
    to 0, roughness is the alpha of ``specular_1x1`` and the seen mask the alpha of
    ``reproject_1x1`` (an image of them without an alpha channel raises, rather than read as 1 everywhere);
    ``metallic``, ``depth`` and ``motion`` do not exist there and raise. A sample's ``scene`` is the folder's name.
    """

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = _folder(root)
        try:
            self.ids = sorted(p.name for p in self.root.iterdir() if (p / "output_1x1.png").is_file())
        except OSError as err:
            raise DatasetError(f"{self.root}: cannot be listed ({err})") from err
        if not self.ids:
            rtp = (self.root / "samples").is_dir()  # (an rtp dataset that lost its manifest: said as such)
            raise DatasetError(f"{self.root}: no manifest.json (an rtp dataset's; its samples/ folder is here)" if rtp
                               else f"{self.root}: neither an rtp dataset (no manifest.json) nor the paper's layout "
                               "(no sample folders with output_1x1.png)")

    def __len__(self) -> int:
        return len(self.ids)

    def __iter__(self) -> Iterator[Sample]:
        return (self[i] for i in self.ids)

    def __getitem__(self, sample_id: str) -> Sample:
        if not isinstance(sample_id, str) or sample_id not in self.ids:
            raise DatasetError(f"no sample {sample_id!r} in {self.root}")
        folder = self.root / sample_id
        if not folder.is_dir():
            raise DatasetError(f"no sample {sample_id!r} in {self.root}")

        def load(name: str) -> np.ndarray:
            if name not in _PAPER_BUFFERS:
                raise DatasetError(f"the paper's layout has no {name!r} buffer")
            stem, sl = _PAPER_BUFFERS[name]
            img = _read_png(folder / f"{stem}.png")
            if sl == 3 and not _has_alpha(folder / f"{stem}.png"):  # (its alpha read as 1: every pixel seen)
                raise DatasetError(f"{folder / f'{stem}.png'}: no alpha channel, which holds the paper layout's "
                                   f"{name} (expected an RGBA or greyscale-with-alpha image; re-saved without "
                                   "its alpha, it read as 1 on every pixel)")
            return img[..., sl]

        # (the folder's own name: of "." or "..", given as such, the scene was '' or '..'; a link keeps its name)
        return Sample(sample_id, load, {"scene": Path(os.path.abspath(self.root)).name, "source": "paper"})


def _read_png(path: Path) -> np.ndarray:
    if not path.is_file():
        raise DatasetError(f"missing file {path}")
    try:
        try:
            return read_image_values(path, alpha=True)
        except ValueError as err:  # (what it holds, not its bytes: a float image past [0, 1], ...)
            raise DatasetError(f"{path}: {err}") from None
    except DatasetError:
        raise
    except Exception as err:  # Pillow on corrupted bytes; see _unreadable
        raise _unreadable(path, "not a readable PNG", err) from err


def _has_alpha(path: Path) -> bool:
    """Whether the image file at ``path`` (already read) has an alpha channel, or a transparent colour (a PNG's
    tRNS), which its reading gives as alpha; without either, the alpha it is read with is 1 everywhere."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            return im.mode in ("RGBA", "RGBa", "LA", "La", "PA") or "transparency" in im.info
    except Exception as err:  # Pillow on corrupted bytes; see _unreadable
        raise _unreadable(path, "not a readable PNG", err) from err


def open_dataset(root: str | os.PathLike[str]) -> DatasetReader | PaperDatasetReader:
    """Open an rtp dataset, or the paper's released layout, whichever the folder holds."""
    p = _folder(root)
    manifest = p / "manifest.json"
    if manifest.exists() or manifest.is_symlink():  # (one that is no file: DatasetReader says what is wrong with it)
        return DatasetReader(p)
    return PaperDatasetReader(p)


def write_png(path: str | os.PathLike[str], image: np.ndarray) -> None:
    """Write a float [0, 1] or uint8 image as PNG, atomically (for figures and the paper layout)."""
    from PIL import Image

    a = _image_bytes(np.asarray(image), "write_png")
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, format="PNG")
    with atomic_output(path) as tmp:
        tmp.write_bytes(buf.getvalue())

