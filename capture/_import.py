"""A dataset from an engine's frames: G-buffers and the frame shaded at every rate, dumped by the engine,
turned into the samples ``rtp capture`` writes, so that ``rtp targets``, ``rtp train`` and ``rtp evaluate``
learn and judge that engine's look rather than the reference renderer's.

A frame file is an ``.npz`` of the arrays ``rtp predict`` reads (:data:`rtp.sdk.GBUFFERS`, in the
engine's conventions), plus ``final_<rate>`` for each rate of :data:`rtp.sdk.ALL_RATES`: the same frame
shaded at 1x1, 1x2, 2x1, 2x2, 2x4, 4x2 and 4x4 (the engine's VRS forced to one rate for the whole frame),
display-encoded as shown. The input planes are made with ``sdk.input_planes``, the SDK's single
definition of each (the reprojection and its disocclusion test included), so a model trained on them
reads what an engine gives it at run time. docs/dataset.md "A dataset from your engine's frames".
"""

from __future__ import annotations

import hashlib
import logging
import numbers
import os
import re
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rtp import sdk
from rtp.sdk import GBUFFERS, ParameterError, RtpError
from rtp.sdk.files import check_output, frame_files, read_frame, writer_lock

from ._dataset import (
    _ID_RE,
    BUFFERS,
    MAX_ID_LENGTH,
    DatasetError,
    DatasetReader,
    DatasetWriter,
    _open_sample,
    holds_nothing,
    sample_path,
)
from ._memory import check_memory

__all__ = ["FINAL_KEYS", "ImportReport", "REQUIRED_GBUFFERS", "import_frames", "linear_light_warning"]

log = logging.getLogger("rtp.capture")

#: The frame file's arrays of the frame shaded at each rate.
FINAL_KEYS = tuple(f"final_{r}" for r in sdk.ALL_RATES)
#: The G-buffers every imported frame must hold: the paper's inputs (the previous frame reprojected, albedo,
#: normals) and what the reprojection needs. The material ones, shadow and emissive may be left out.
REQUIRED_GBUFFERS = ("depth", "albedo", "normal", "view", "projection", "prev_colour", "prev_depth",
                     "prev_view_projection")
#: The dataset buffers a frame may lack (stored as zeros and listed under the manifest's ``absent``: a model
#: that reads one of their channels is refused by the reader, not trained on zeros).
OPTIONAL_BUFFERS = ("roughness", "metallic", "specular", "shadow", "emissive")
#: The optional arrays of a frame file (:data:`OPTIONAL_BUFFERS`, the engine's motion vectors and the previous
#: frame's projection): every frame of an import holds the same ones.
OPTIONAL_ARRAYS = (*OPTIONAL_BUFFERS, "motion", "prev_projection")
#: The command that writes example frames (the hints of the errors).
EXAMPLE = "rtp import FRAMES --write-example --frames 8"
#: The bytes an import holds besides its frame's arrays (Python, numpy, the SDK) and for each pixel of a frame (the
#: arrays' float copies, the input planes and the reprojection, the encoded sample): the peak resident set of an
#: import of 640x360, 1280x720 and 1920x1080 frames (uint8 final images, float32 G-buffers: 105 bytes a pixel read)
#: was 165, 509 and 1083 MiB, 522 bytes a pixel.
IMPORT_BASE = 64 * 2**20
IMPORT_PER_PIXEL = 420.0
#: ``profile``'s default (recorded in the manifest's settings only when another is given).
DEFAULT_PROFILE = "engine"
#: The manifest's ``settings["source"]`` of an imported dataset.
SOURCE = "engine frames"


@dataclass
class ImportReport:
    written: int = 0
    skipped: int = 0  # already in the dataset (an import resumes)
    replaced: int = 0  # of ``written``: samples of frame files that changed since they were imported (dumped again)
    absent: tuple[str, ...] = ()
    unseen: list[float] = field(default_factory=list)  # per new sample, the share of its geometry not seen
    warnings: dict[str, int] = field(default_factory=dict)  # sdk.check_gbuffers' warnings, by kind: frames with it
    exchanged: int = 0  # new frames whose anisotropic rates' images look exchanged (final_1x2 and final_2x1, ...)


def _scene_name(scene: str | None, file: str) -> str:
    # (abspath, not resolve: a folder linked to the engine's dump folder is the level of the link's name, as given)
    name = scene if scene is not None else Path(os.path.abspath(file)).parent.name
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.-]{1,64}", name):
        raise ParameterError(f"scene: expected a name of letters, digits, '.', '_' and '-' (at most 64; the level the "
                             f"frames are of, which --val-scenes names), got {name!r}"
                             + ("" if scene is not None else " (the frames' folder name: give --scene)"), "scene")
    return name


def _sample_id(scene: str, path: str) -> str:
    stem = re.sub(r"[^A-Za-z0-9_.-]", "_", Path(path).stem)
    sid = f"{scene}-{stem}"
    if not _ID_RE.match(sid) or len(sid) > MAX_ID_LENGTH:
        raise ParameterError(f"{path!r}: its name makes the sample id {sid[:80]!r}..., longer than {MAX_ID_LENGTH} "
                             f"characters: rename the file", "frames")
    return sid


#: The arrays of a frame file an import reads (``_read``'s); others are named in a warning and left unread.
_READ = frozenset((*GBUFFERS, *FINAL_KEYS, "colour"))


def _members(path: str) -> tuple[dict[str, tuple[int, ...]], int]:
    """The arrays of a frame file and their shapes, and the bytes the arrays an import reads hold in memory, read
    from each array's header (not its data). An array it reads that is not of numbers (a pickled object array, which
    is not loaded, strings) is a ParameterError naming it, found before the first frame is written."""
    shapes: dict[str, tuple[int, ...]] = {}
    nbytes = 0
    bad: tuple[str, np.dtype[Any]] | None = None
    try:
        headers = sdk.files.array_headers(path)
    except ParameterError as err:
        raise ParameterError(f"{err}; `{EXAMPLE}` writes frames", "frames") from None
    for key, (shape, dtype) in headers.items():
        shapes[key] = shape
        if key not in _READ:  # (not read: an engine's own extra array takes no memory of the import's)
            continue
        if dtype.kind not in "biuf":
            bad = bad or (key, dtype)
        nbytes += int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
    if bad is not None:
        key, dtype = bad
        what = ("a pickled object array (as np.savez saves a dict, a list of arrays of unequal shapes or other Python "
                "objects), which rtp does not load (allow_pickle=False: unpickling runs code the file holds)"
                if dtype.hasobject else f"of dtype {dtype}")
        raise ParameterError(f"{path!r}: {key} is {what}: expected an array of numbers (float, or uint8 / uint16 "
                             f"UNORM for the colour images); `{EXAMPLE}` writes frames", key)
    return shapes, nbytes


def _read(path: str) -> dict[str, Any]:
    """The arrays of a frame file (``read_frame``: a damaged one, its deflate stream damaged past the arrays'
    headers, is a ParameterError naming it), with how an import goes on after it."""
    try:
        return read_frame(path, extra=(*FINAL_KEYS, "colour"), example=EXAMPLE)  # (colour: rtp predict's overlay)
    except ParameterError as err:
        raise ParameterError(f"{err}; the frames before it are in the dataset: dump this one again, and the same "
                             f"command imports the rest", "frames") from None


def _samples_profile(reader: DatasetReader) -> str | None:
    """The ``profile`` the samples of a folder imported before its manifest recorded one carry (the first readable
    sample's; None: no sample, or none readable)."""
    for sid in reader.ids[:3]:
        try:
            value = reader[sid].meta.get("profile")
        except DatasetError:  # (a damaged sample: _kept imports it again)
            continue
        return value if isinstance(value, str) else None
    return None


def _source(path: str) -> dict[str, Any]:
    """What a sample records of the frame file it was imported from: its size and time (a cheap check) and its
    bytes' SHA-256 (the check when the cheap one differs: a copy changes the time, not the frame)."""
    st = os.stat(path)
    return {"bytes": int(st.st_size), "mtime_ns": int(st.st_mtime_ns), "sha256": _sha256(path),
            "path": os.path.abspath(path)}


def _sha256(path: str) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):  # (hashlib.file_digest is Python 3.11's)
            digest.update(block)
    return digest.hexdigest()


def _same_source(recorded: Any, path: str) -> bool:
    """Whether the frame file ``path`` is the one a sample recorded (``recorded``: its meta's ``source_file``;
    a sample imported before it was recorded is taken as the same)."""
    if not isinstance(recorded, dict):
        return True
    st = os.stat(path)
    if recorded.get("bytes") == st.st_size and recorded.get("mtime_ns") == st.st_mtime_ns:
        return True
    return recorded.get("bytes") == st.st_size and recorded.get("sha256") == _sha256(path)


def _state(writer: DatasetWriter, sample_id: str, frame: str) -> str:
    """``"kept"`` where the sample ``sample_id`` is in the dataset, readable, and of the frame file ``frame`` as it
    is now; ``"changed"`` where it is of the frame file as it was; ``"missing"`` otherwise. One damaged since (cut
    short by a copy, a disk) is deleted, with a warning, and imported again rather than kept for ``rtp targets`` to
    fail on; one of a frame dumped again since (other bytes) is imported again, with a warning, replacing it (its
    targets are then older than it, and ``rtp targets`` computes them again). One imported from another path whose
    file is still there as it was imported (a folder of the same file names imported under the same ``scene``) is a
    ParameterError, not replaced."""
    path = sample_path(writer.root, sample_id)
    if not path.is_file():
        return "missing"
    try:
        sample = _open_sample(sample_id, path, path)
    except DatasetError as err:
        log.warning("%s; imported again", err)
        path.unlink(missing_ok=True)
        return "missing"
    recorded = sample.meta.get("source_file")
    if not _same_source(recorded, frame):
        was = recorded.get("path") if isinstance(recorded, dict) else None
        if isinstance(was, str) and was != os.path.abspath(frame) and os.path.isfile(was) and _same_source(
                recorded, was):  # (another frame file, still there as imported: not this one dumped again)
            raise ParameterError(f"{frame!r} would replace the sample {sample_id!r}, imported from {was!r}, another "
                                 f"frame file, still there as imported (the same file name in two folders of one "
                                 f"--scene?): give these frames another --scene, or delete {str(path)!r} to replace "
                                 f"it", "frames")
        log.warning("%s changed since it was imported as sample %s (dumped again?): imported again", frame, sample_id)
        return "changed"
    return "kept"


def _final(path: str, key: str, a: Any, hw: tuple[int, int]) -> np.ndarray:
    """A frame shaded at one rate as float32 ``(H, W, 3)`` in [0, 1]: float display values, or UNORM integers
    (``uint8``, ``uint16``) read back; an RGBA texture's alpha is dropped."""
    a = np.asarray(a)
    if a.ndim != 3 or a.shape[:2] != hw or a.shape[2] not in (3, 4):
        raise ParameterError(f"{path!r}: {key} has shape {a.shape}, expected ({hw[0]}, {hw[1]}, 3) (or RGBA, 4): the "
                             f"frame shaded at {key[6:]}, display-encoded, of the depth's size", key)
    a = a[..., :3]
    if a.dtype == np.uint8 or a.dtype == np.uint16:
        return (a.astype(np.float32) / np.float32(np.iinfo(a.dtype).max)).astype(np.float32)
    if a.dtype.kind != "f":
        raise ParameterError(f"{path!r}: {key} is {a.dtype}: expected float display values in [0, 1], or uint8 / "
                             f"uint16 UNORM values", key)
    v = a.astype(np.float32)
    if not np.isfinite(v).all():
        raise ParameterError(f"{path!r}: {key} holds NaN or infinite values", key)
    if v.size and (v.min() < -1e-3 or v.max() > 1 + 1e-3):
        raise ParameterError(f"{path!r}: {key} has values in [{v.min():.4g}, {v.max():.4g}]: expected display-encoded "
                             f"values in [0, 1], the frame as shown (tone-mapped, sRGB-encoded)", key)
    return np.clip(v, 0.0, 1.0)


#: The frame file's arrays of the frame's own size, (H, W) or (H, W, C): checked from their headers before anything
#: is written.
_FRAME_SIZED = ("albedo", "normal", "roughness", "metallic", "specular", "shadow", "emissive", "motion")

#: The anisotropic rates whose images are told apart, (wide, tall) and the block size along the long side.
_ANISOTROPIC = (("2x1", "1x2", 2), ("4x2", "2x4", 4))
#: The fewest pixels along each side for that check (fewer: too few blocks to tell, nothing said).
_EXCHANGE_MIN_SIDE = 16


def _blocked(luma: np.ndarray, axis: int, size: int) -> float:
    """How much ``luma`` repeats in blocks of ``size`` pixels along ``axis``, whatever the blocks' phase: of the
    mean differences between neighbours at each of the ``size`` offsets, the second largest over the largest (near 0:
    blocks of that size, the one offset across their edges differing; near 1: none)."""
    d = np.abs(np.diff(luma, axis=axis)).mean(axis=1 - axis)
    phases = sorted(float(d[j::size].mean()) for j in range(size))
    return phases[-2] / phases[-1] if phases[-1] > 1e-6 else 1.0


def _exchanged(finals: dict[str, np.ndarray]) -> list[tuple[str, str]]:
    """The pairs of anisotropic rates (wide, tall) whose final images look exchanged: the one named tall (1x2: 1
    pixel wide, 2 tall) repeats side by side and not one above the other, and the one named wide the other way round.
    A cheap check, both images of a pair needing clear evidence (one side's ratio under half the other's): on the
    reference renderer's frames (procedural scenes, 33x19 to 160x90) the named rate's long side's ratio is under 0.15,
    its short side's over 0.6."""
    out = []
    for wide, tall, size in _ANISOTROPIC:
        t, v = (finals[f"final_{r}"].mean(axis=-1) for r in (tall, wide))
        if min(t.shape) < max(_EXCHANGE_MIN_SIDE, 4 * size + 1):
            continue
        if (_blocked(t, 1, size) < 0.5 * _blocked(t, 0, size)
                and _blocked(v, 0, size) < 0.5 * _blocked(v, 1, size)):
            out.append((wide, tall))
    return out


#: The previous frame reprojected against final_1x1 on the surfaces seen in both (the same surfaces a frame apart):
#: named as in linear light where the sRGB curve (encoding it; or decoding it, for final images in linear light)
#: brings it nearer by this factor, and by :data:`_ENCODING_GAP`, in median difference. Given as shown, either curve
#: took it 10x further off at least on the reference renderer's frames (144: procedural scenes 0-7, the ``fast`` and
#: ``slow`` camera paths, 33x19 to 160x90, float and 8-bit) and 3.4x on 72 frames of three real maps at 1280x720
#: (data/val720); given a linear prev_colour, encoding brought it nearer by 14x and 3.6x at least (0.07 and 0.27 of
#: the difference as given, and at least 0.13 less), and given linear final images decoding by 13x and 3.3x.
_ENCODING_RATIO = 0.5
_ENCODING_GAP = 0.02
#: The fewest surfaces seen in both frames for that check (fewer: nothing said).
_ENCODING_MIN_PIXELS = 64


def _encoding_errors(reprojected: np.ndarray, seen: np.ndarray, final: np.ndarray, geo: np.ndarray,
                     ) -> tuple[float, float, float] | None:
    """The median difference between ``final`` and ``reprojected`` on the surfaces ``seen`` in both frames: as
    given, ``reprojected`` sRGB-encoded and sRGB-decoded (the median: a few surfaces lit otherwise a frame apart, or
    reprojected from the wrong surface, do not move it); None where fewer than :data:`_ENCODING_MIN_PIXELS`."""
    use = (seen > 0.5) & geo
    if int(use.sum()) < _ENCODING_MIN_PIXELS:
        return None
    rep, fin = np.clip(reprojected[use], 0.0, 1.0).astype(np.float64), final[use].astype(np.float64)
    return (float(np.median(np.abs(rep - fin))), float(np.median(np.abs(sdk.linear_to_srgb(rep) - fin))),
            float(np.median(np.abs(sdk.srgb_to_linear(rep) - fin))))


def linear_light_warning(reprojected: np.ndarray, seen: np.ndarray, shown: np.ndarray, geo: np.ndarray, *,
                         name: str = "final_1x1") -> str | None:
    """A warning where ``prev_colour`` (its reprojection, ``reprojected``, float ``(H, W, 3)``) looks like linear light
    beside the frame shown, ``shown`` (float ``(H, W, 3)`` in [0, 1]; the frame file's array ``name``: ``final_1x1``
    of ``rtp import``, ``colour`` of ``rtp predict``), or ``shown`` like linear light beside ``prev_colour``: on the
    surfaces ``seen`` in both frames (of ``geo``, the frame's geometry), the sRGB curve brings the one nearer the other
    (:data:`_ENCODING_RATIO`); None otherwise, and where both are in linear light (they agree: nothing to compare them
    with)."""
    errors = _encoding_errors(reprojected, seen, shown, geo)
    if errors is None:
        return None
    as_given, encoded, decoded = errors
    if encoded < _ENCODING_RATIO * as_given and as_given - encoded > _ENCODING_GAP:
        return (f"prev_colour: looks like linear light: reprojected, it differs from {name} by {as_given:.3f} "
                f"(median) on the surfaces seen in both frames, and by {encoded:.3f} once sRGB-encoded; rtp takes "
                f"prev_colour display-encoded, as shown (tone-mapped, sRGB): read the frame back after its sRGB "
                f"conversion, or encode it (sdk.linear_to_srgb); a linear albedo likewise needs albedo_linear (--albedo-linear)")
    if decoded < _ENCODING_RATIO * as_given and as_given - decoded > _ENCODING_GAP:
        images = ("the final_<rate> images", "them", "their") if name == "final_1x1" else (name, "it", "its")
        return (f"{name}: looks like linear light: it differs from prev_colour reprojected by {as_given:.3f} "
                f"(median) on the surfaces seen in both frames, and by {decoded:.3f} from prev_colour sRGB-decoded; "
                f"rtp takes {images[0]} display-encoded, as shown (tone-mapped, sRGB): read {images[1]} back "
                f"after {images[2]} sRGB conversion, or encode {images[1]} (sdk.linear_to_srgb)")
    return None


_linear_light = linear_light_warning  # (its name before rtp predict used it too)


#: Dataset buffer -> the input planes it stores, in its last axis' order.
_STORED = {name: spec.channels for name, spec in BUFFERS.items() if spec.channels}


def _buffers(path: str, arrays: dict[str, Any], present: Sequence[str], conventions: dict[str, Any],
             ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """A frame's dataset buffers (absent ones zero) and its ``seen`` plane."""
    gbuffers = {k: v for k, v in arrays.items() if k in GBUFFERS}
    hw = tuple(np.shape(gbuffers["depth"])[:2])
    channels = [c for name, chans in _STORED.items() if name in present for c in chans]
    try:
        planes = sdk.input_planes(channels, **gbuffers, **conventions)
    except RtpError as err:  # (the SDK's typed input errors, named with the file they are about)
        raise ParameterError(f"{path!r}: {err}", "frames") from err
    by_name = dict(zip(channels, planes))
    out: dict[str, np.ndarray] = {}
    for name, chans in _STORED.items():
        if name in present:
            stack = [by_name[c] for c in chans]
            out[name] = stack[0] if len(stack) == 1 else np.stack(stack, axis=-1)
        else:
            out[name] = np.zeros((*hw, len(chans)) if len(chans) > 1 else hw, np.float32)
    for key in FINAL_KEYS:
        out[key] = _final(path, key, arrays[key], hw)
    return out, by_name["seen"]


def import_frames(
    frames: Iterable[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    *,
    scene: str | None = None,
    profile: str = DEFAULT_PROFILE,
    albedo_linear: bool = False,
    normal_space: str = "view",
    depth_kind: str = "linear",
    tolerance: float = sdk.DEFAULT_REPROJECTION_TOLERANCE,
    progress: Callable[[int, int], None] | None = None,
) -> ImportReport:
    """Add an engine's frames to the dataset folder ``out`` (created, or grown: an import resumes, frames
    already there are skipped). Returns what it did.

    ``frames``: frame files or folders of them (natural order). Each holds :data:`REQUIRED_GBUFFERS`, the
    final images :data:`FINAL_KEYS`, and may hold ``roughness``, ``metallic``, ``specular``, ``shadow``,
    ``emissive``, ``motion`` and ``prev_projection``; every frame the same ones, of one size. The
    conventions are ``sdk.input_planes``' (``albedo_linear``, ``normal_space``, ``depth_kind``, the
    reprojection's ``tolerance``). ``scene`` names the level the frames show (``rtp train --val-scenes``
    holds levels out by it; default: each frame's folder name); ``profile`` is recorded as the capture's
    motion profile is, in each sample's meta and, when not ``"engine"``, in the manifest's settings (a folder
    grown with another profile is refused).

    Everything is checked before the first sample is written: the files, the arrays each holds, their
    size, and the dataset folder's settings (a folder imported with other conventions or G-buffers, or
    captured by the reference renderer, is refused rather than mixed). Each sample is written atomically;
    ``sdk.check_gbuffers``' convention warnings are logged once per kind and counted in the report, and so are
    frames whose anisotropic rates' images look exchanged (``final_1x2`` repeating side by side and ``final_2x1``
    one above the other; ``final_2x4`` and ``final_4x2``): ``exchanged``. So is colour in linear light where rtp
    takes it sRGB-encoded, as shown: ``prev_colour`` (or the final images) in linear light beside the other, seen where
    the previous frame reprojected matches ``final_1x1`` far better once sRGB-encoded (or decoded); colour all in linear
    light agrees with itself and is not seen, nor is a linear ``albedo``. Frames past the machine's memory are
    refused before the first is read (``RTP_MEMORY_CHECK``).
    """
    files = frame_files(list(frames) if not isinstance(frames, (str, os.PathLike)) else [frames], example=EXAMPLE)
    if not files:
        raise ParameterError("frames: expected one or more frame files or folders of them", "frames")
    if not isinstance(profile, str) or not re.fullmatch(r"[A-Za-z0-9_.-]{1,32}", profile):
        raise ParameterError(f"profile: expected a short name of letters, digits, '.', '_' and '-', got {profile!r}",
                             "profile")
    if normal_space not in sdk.NORMAL_SPACES or depth_kind not in sdk.DEPTH_KINDS or not isinstance(albedo_linear, bool):
        raise ParameterError(f"conventions: normal_space in {sdk.NORMAL_SPACES}, depth_kind in {sdk.DEPTH_KINDS} and "
                             f"albedo_linear a bool, got {normal_space!r}, {depth_kind!r}, {albedo_linear!r}",
                             "conventions")
    names = [_scene_name(scene, f) for f in files]
    ids = [_sample_id(n, f) for n, f in zip(names, files)]
    twice = [i for i, n in Counter(ids).items() if n > 1]
    if twice:
        raise ParameterError(f"frames: two files make the sample id {twice[0]!r} (the same file name in two folders?): "
                             f"import each folder with its own --scene", "frames")

    # the arrays of every frame and their size, before anything is written
    members, sizes, frame_bytes = {}, {}, 0
    for f in files:
        if not Path(f).is_file():
            raise ParameterError(f"{f!r}: no such file (`{EXAMPLE}` writes frames of the reference renderer)", "frames")
        members[f], nbytes = _members(f)
        frame_bytes = max(frame_bytes, nbytes)
        lacks = [k for k in (*REQUIRED_GBUFFERS, *FINAL_KEYS) if k not in members[f]]
        if lacks:
            raise ParameterError(f"{f!r} lacks {', '.join(lacks)}: a frame to train on holds "
                                 f"{', '.join(REQUIRED_GBUFFERS)} and the frame shaded at every rate "
                                 f"({', '.join(FINAL_KEYS)}); `{EXAMPLE}` writes such frames", "frames")
        shape = members[f]["final_1x1"]
        if len(shape) != 3:
            raise ParameterError(f"{f!r}: final_1x1 has shape {shape}, expected (H, W, 3) (or RGBA, 4): the frame "
                                 f"shaded at full rate, display-encoded", "final_1x1")
        for key in (*FINAL_KEYS[1:], "depth"):  # (every frame of the file at the depth's size, as _final asks)
            want = f"({shape[0]}, {shape[1]})" if key == "depth" else f"({shape[0]}, {shape[1]}, 3) (or RGBA, 4)"
            got = members[f][key]
            if got[:2] != shape[:2] or (key != "depth" and (len(got) != 3 or got[2] not in (3, 4))):
                raise ParameterError(f"{f!r}: {key} has shape {got}, expected {want}: final_1x1's size", key)
        # the other planes of the frame's size, and the previous frame's two of one size (the SDK's check, found
        # when the frame's turn came: the frames before it were written by then)
        for key in _FRAME_SIZED:
            if key in members[f] and (len(got := members[f][key]) not in (2, 3) or got[:2] != shape[:2]):
                raise ParameterError(f"{f!r}: {key} has shape {got}, expected {GBUFFERS[key][0]} of final_1x1's "
                                     f"size, (H, W) = ({shape[0]}, {shape[1]})", key)
        if members[f]["prev_colour"][:2] != members[f]["prev_depth"][:2]:
            raise ParameterError(f"{f!r}: prev_colour has shape {members[f]['prev_colour']}, expected prev_depth's "
                                 f"size {members[f]['prev_depth'][:2]} (the previous frame's)", "prev_colour")
        sizes[f] = shape[:2]
    if len(set(sizes.values())) > 1:
        counts = Counter(sizes.values())
        raise ParameterError(f"frames: of {len(counts)} sizes ({', '.join(f'{s[1]}x{s[0]}: {n}' for s, n in counts.items() if s)}"
                             f"); a dataset holds frames of one size", "frames")
    # every frame the same optional arrays as the first (motion vectors on some frames only would store the
    # engine's motion on those and the camera's on the rest): the first that differs is named
    first = {k for k in OPTIONAL_ARRAYS if k in members[files[0]]}
    for f in files[1:]:
        held = {k for k in OPTIONAL_ARRAYS if k in members[f]}
        if held != first:
            lacks = [k for k in OPTIONAL_ARRAYS if k in first - held]
            extra = [k for k in OPTIONAL_ARRAYS if k in held - first]
            key = (lacks or extra)[0]
            have = sum(key in m for m in members.values())
            raise ParameterError(
                f"{f!r} " + " and ".join(
                    ([f"lacks {', '.join(lacks)}"] if lacks else [])
                    + ([f"holds {', '.join(extra)} besides"] if extra else []))
                + f", unlike the first frame {files[0]!r} ({have} of {len(files)} hold {key!r}): every frame "
                f"of a dataset holds the same optional arrays ({', '.join(OPTIONAL_ARRAYS)}; a model reads a channel "
                f"on every sample or none): import those frames into a folder of their own, or drop the array from "
                f"every frame", "frames")
    present = [b for b in BUFFERS if b not in OPTIONAL_BUFFERS or b in first]
    absent = tuple(b for b in OPTIONAL_BUFFERS if b not in present)
    h, w = next(iter(sizes.values()))
    # (its range too, now: out of it, the first frame's reprojection refused it, the error naming that frame's file;
    # the range is the SDK reprojection's own, sdk.MAX_REPROJECTION_TOLERANCE)
    if isinstance(tolerance, (bool, np.bool_)) or not isinstance(tolerance, numbers.Real) \
            or not 0.0 <= tolerance <= sdk.MAX_REPROJECTION_TOLERANCE:
        raise ParameterError(f"tolerance: expected a number in [0, {sdk.MAX_REPROJECTION_TOLERANCE:g}] (the "
                             f"reprojection's relative depth tolerance, {sdk.DEFAULT_REPROJECTION_TOLERANCE:g} by "
                             f"default), got {tolerance!r}", "tolerance")
    conventions = {"albedo_linear": albedo_linear, "normal_space": normal_space, "depth_kind": depth_kind,
                   "tolerance": float(tolerance)}
    # the memory a frame's import holds (its arrays, their float copies, the planes, the sample), before the first
    # frame is read: frames past the machine's memory were read until the system killed the import, or numpy's
    # MemoryError was taken for a damaged file
    need = int(IMPORT_BASE + IMPORT_PER_PIXEL * h * w + frame_bytes)
    check_memory(need, f"an import of frames of {w}x{h} holds about {need / 2**30:.1f} GiB", "frames",
                 "of memory: smaller frames (crop or scale the dumps)", job="the import")
    # the first frame made into a sample: its arrays, the conventions and the tolerance checked by the SDK
    # before the dataset's manifest records them
    _buffers(files[0], _read(files[0]), present, conventions)
    settings = {"size": [int(w), int(h)], "source": SOURCE, "conventions": conventions, "absent": list(absent)}
    if profile != DEFAULT_PROFILE:  # (recorded only when not the default, so folders imported before it resume)
        settings["profile"] = profile

    root = check_output(out, folder=True, what="dataset folder")
    # (a folder that holds nothing yet, an import or capture killed or refused before its first sample: its settings,
    # source and profile included, are replaced by this import's under the lock, as a new folder's would be)
    if (root / "manifest.json").is_file() and not holds_nothing(root, (reader := DatasetReader(root)).manifest):
        before = reader.manifest.get("settings")
        if not isinstance(before, dict) or before.get("source") != SOURCE:
            raise DatasetError(f"{root}: a dataset the reference renderer captured; import an engine's frames into a "
                               f"folder of their own (rtp train --data takes several, comma-separated)")
        there = before.get("profile", DEFAULT_PROFILE)
        if "profile" not in before and (legacy := _samples_profile(reader)) is not None:
            there = legacy  # (imported before the profile was recorded: its samples say it)
            if legacy == profile:
                settings.pop("profile", None)  # (resumed as that folder's manifest records it: not at all)
        if there != profile:  # (a resumed import with another --profile mixed the two across its samples)
            raise DatasetError(f"{root} was imported with --profile {there}, not {profile}: a dataset's frames are of "
                               f"one profile; give --profile {there} to grow it, or import these into a folder of "
                               f"their own (rtp train --data takes several, comma-separated)")
    report = ImportReport(absent=absent)
    root.mkdir(parents=True, exist_ok=True)
    with writer_lock(root, "rtp import", lambda holder: DatasetError(
            f"{root} is being written by another job ({holder}): wait for it to end")):
        writer = DatasetWriter(root, settings)  # (other settings there: refused, naming them)
        writer.remove_stale()
        states = [_state(writer, i, f) for f, i in zip(files, ids)]
        todo = [(f, i, n) for f, i, n, st in zip(files, ids, names, states) if st != "kept"]
        report.replaced = states.count("changed")
        report.skipped = len(files) - len(todo)
        if progress:
            progress(report.skipped, len(files))
        warned: dict[str, int] = {}
        for f, sid, name in todo:
            source = _source(f)  # (before reading: a frame dumped again while it is read is imported again)
            arrays = _read(f)
            gbuffers = {k: v for k, v in arrays.items() if k in GBUFFERS}
            try:
                texts = sdk.check_gbuffers(**gbuffers, normal_space=normal_space, depth_kind=depth_kind,
                                       albedo_linear=albedo_linear, tolerance=tolerance)
            except RtpError as err:  # (named with the file it is about)
                raise ParameterError(f"{f!r}: {err}", "frames") from err
            buffers, seen = _buffers(f, arrays, present, conventions)
            encoding = linear_light_warning(buffers["reprojected"], seen, buffers["final_1x1"], buffers["depth"] > 0)
            for text in [*texts, *([encoding] if encoding else [])]:
                kind = re.sub(r"-?\d[\d.]*", "#", text)
                warned[kind] = warned.get(kind, 0) + 1
                if warned[kind] == 1:
                    log.warning(f"{f}: {text}")  # (its own message: one template hid every kind after the first)
            exchanged = _exchanged(buffers)
            if exchanged:  # (a model trained on them picks 2x1 where 1x2 would do: nothing else catches it)
                report.exchanged += 1
                if report.exchanged == 1:
                    pairs = " and ".join(f"final_{t} and final_{w}" for w, t in exchanged)
                    log.warning(f"{f}: {pairs} look exchanged: final_{exchanged[0][1]}'s pixels repeat side by side "
                                f"and final_{exchanged[0][0]}'s one above the other; final_WxH is the frame shaded at "
                                f"blocks W pixels wide and H tall (D3D12_SHADING_RATE_1X2, Vulkan's fragment size "
                                f"1x2: 1 wide, 2 tall): name the images so, or the model learns the wrong "
                                f"anisotropic rate")
            geo = buffers["depth"] > 0
            unseen = float(1.0 - seen[geo].mean()) if geo.any() else 0.0
            writer.write(sid, buffers, {"scene": name, "profile": profile, "source": Path(f).name,
                                        "source_file": source, "unseen": unseen, "coverage": float(geo.mean())})
            report.written += 1
            report.unseen.append(unseen)
            if progress:
                progress(report.skipped + report.written, len(files))
        report.warnings = warned
        writer.finalize()
    if absent:
        log.info("%s: no %s in the frames: stored as zeros, and a model reading them is refused", root,
                 ", ".join(absent))
    return report
