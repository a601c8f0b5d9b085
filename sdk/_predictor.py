"""``load()`` and :class:`ShadingRatePredictor`: one ONNX Runtime session plus its metadata."""

from __future__ import annotations

import base64
import binascii
import importlib.util
import json
import logging
import math
import os
import reprlib
import shlex
import threading
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._channels import BLOCK_CELL, BLOCK_TILE
from ._digest import external_tensors, model_digest
from ._errors import (
    InferenceError,
    InputChannelError,
    InputDtypeError,
    InputShapeError,
    MetadataError,
    ModelIntegrityError,
    ModelLoadError,
    ModelNotFoundError,
    NonFiniteInputError,
    ParameterError,
    ProviderUnavailableError,
)
from ._metadata import DIGEST_RE, FEATURES_NAME, METADATA_KEY, TAIL_KEY, ModelMetadata
from ._rates import PREDICTED_RATES, RateLike, check_threshold, select_rates, select_rates_for_saving
from ._tiles import (
    DEFAULT_TILE_SIZE,
    MIN_HARDWARE_TILE,
    hardware_tiles,
    padded_size,
    pool_tiles,
    split_tiles,
    tile_grid,
)

__all__ = ["ShadingRatePredictor", "load", "shipped_models"]

log = logging.getLogger("rtp.sdk")

ProviderSpec = str | tuple[str, Mapping[str, Any]]
#: Most intra-op threads ``load(threads=...)`` accepts (onnxruntime takes a C int; no machine has more cores).
MAX_THREADS = 4096
_CPU = "CPUExecutionProvider"
#: onnxruntime's session option that stops the intra-op worker threads spinning when a run returns.
FORCE_SPINNING_STOP = "session.force_spinning_stop"
# Providers that onnxruntime lists as available but that run no local kernels (the Azure EP forwards
# requests to a remote endpoint); never picked by default, never reported as the one that runs.
_NON_COMPUTE = frozenset({"AzureExecutionProvider"})
#: Guards the thresholds and frame sizes a predictor has warned of (``_warn_beyond_saturation``,
#: ``_warn_cut_cells``), so that threads sharing it (and its copies) log each once; taken only where a threshold is
#: past saturation or a frame cuts its packed planes' cells, never on the way to a frame of sides multiples of 4.
_WARNED_LOCK = threading.Lock()
#: The most thresholds, and the most frame sizes, a predictor logs its once-each warnings of (``_warn_beyond_saturation``,
#: ``_warn_cut_cells``): the last one logged says that further ones are not. Each was kept for ever, so a threshold
#: controller past saturation (a new float every frame) logged a warning every frame and grew the set by one every
#: frame, and a dynamic-resolution engine's every new size did the same.
MAX_WARNED = 16


def _ort() -> Any:
    import onnxruntime

    return onnxruntime


def _models_dir() -> Path | None:
    spec = importlib.util.find_spec("rtp.models")
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))


def shipped_models() -> list[str]:
    """File names of the models that ship with the package (usable as ``load("jnyang.onnx")``)."""
    d = _models_dir()
    return sorted(p.name for p in d.glob("*.onnx")) if d else []


def _resolve_path(path: str | os.PathLike[str]) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise ParameterError(f"path: expected a model file path or a shipped model's name, got {type(path).__name__} "
                             f"{reprlib.repr(path)}", "path")
    if isinstance(path, str) and not path:  # (Path("") is ".", the working folder: "exists but is not a file")
        names = ", ".join(shipped_models()) or "none with this installation"
        raise ModelNotFoundError(f"expected a model file path or a shipped model's name, got an empty path; shipped "
                                 f"models: {names}")
    try:
        p = Path(path)
        is_file, exists = p.is_file(), p.exists()
    except (OSError, ValueError, TypeError) as err:  # a name too long, a NUL byte, a PathLike returning junk
        raise ModelNotFoundError(f"no model file at {reprlib.repr(str(path))}: {err}") from err
    if is_file:
        return p
    if exists:
        raise ModelNotFoundError(f"model path {str(p)!r} exists but is not a file")
    # A bare name such as "jnyang" or "jnyang.onnx" finds a shipped model.
    if p.parent == Path(".") and (d := _models_dir()) is not None:
        for cand in (d / p.name, d / f"{p.name}.onnx"):
            if cand.is_file():
                return cand
    shipped = shipped_models()
    hint = f"; shipped models: {', '.join(shipped)}" if shipped else "; no models ship with this installation"
    raise ModelNotFoundError(f"no model file at {str(p)!r}{hint}")


def _normalise_providers(providers: Sequence[ProviderSpec] | None, strict: bool) -> list[ProviderSpec]:
    available = list(_ort().get_available_providers())
    if providers is None:
        # onnxruntime lists its providers in priority order; keep CPU as the last resort.
        return [p for p in available if p != _CPU and p not in _NON_COMPUTE] + ([_CPU] if _CPU in available else [])
    if isinstance(providers, str):
        providers = [providers]
    if not isinstance(providers, Sequence):
        raise ProviderUnavailableError(
            f"providers: expected a list of provider names or (name, options) pairs, got {type(providers).__name__}"
        )
    out: list[ProviderSpec] = []
    for spec in providers:
        if isinstance(spec, str):
            name = spec
        elif isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[0], str) and isinstance(spec[1], Mapping):
            name = spec[0]
        else:
            raise ProviderUnavailableError(
                f"a provider is a name such as 'CUDAExecutionProvider' or a (name, options) pair, got {spec!r}"
            )
        if name not in available:
            msg = f"execution provider {name!r} is not available; this onnxruntime has {', '.join(available)}"
            if strict:
                raise ProviderUnavailableError(msg)
            log.warning("%s; skipping it", msg)
            continue
        out.append(spec)
    if not out:
        if strict or _CPU not in available:
            raise ProviderUnavailableError(f"none of the requested providers {list(providers)} is available")
        log.warning("none of the requested providers is available; falling back to %s", _CPU)
        out = [_CPU]
    return out


def _metadata_from_arg(metadata: ModelMetadata | Mapping[str, Any] | str | os.PathLike[str]) -> ModelMetadata:
    if isinstance(metadata, ModelMetadata):
        # validated again, as a dict or a sidecar is: one made with dataclasses.replace (or the constructor) is
        # never checked, and a NaN safety gave every tile 1x1, a flipped higher_is_better inverted every decision
        try:
            return ModelMetadata.from_dict(metadata.to_dict())
        except MetadataError as err:
            raise MetadataError(f"metadata=: {err}", err.key) from err
        except (AttributeError, TypeError, ValueError) as err:  # (a field of the wrong kind: to_dict fails on it)
            raise MetadataError(f"metadata=: a ModelMetadata whose fields are not valid ({type(err).__name__}: {err}); "
                                "build it with ModelMetadata.from_dict") from err
    if isinstance(metadata, Mapping):
        return ModelMetadata.from_dict(metadata)
    if isinstance(metadata, (str, os.PathLike)):
        return ModelMetadata.from_yaml(metadata)
    raise MetadataError(f"metadata=: expected a dict, a ModelMetadata or a YAML path, got {type(metadata).__name__}")


def _embedded_digest(props: Mapping[str, str]) -> str | None:
    """The digest the model's own metadata records, when ``metadata=`` replaces that metadata: the file's
    integrity is checked all the same. None when there is none or the embedded metadata is unreadable."""
    try:
        d = json.loads(props.get(METADATA_KEY, ""))
    except (ValueError, RecursionError):
        return None
    digest = d.get("digest") if isinstance(d, dict) else None
    return digest if isinstance(digest, str) and DIGEST_RE.fullmatch(digest) else None


def _read_model(model_path: Path) -> bytes:
    """The model file's bytes, read once: its integrity is checked on them and a pickled predictor carries them."""
    try:
        return model_path.read_bytes()
    except OSError as err:
        raise ModelLoadError(f"{str(model_path)!r}: cannot be read back to check its digest and keep its bytes "
                             f"({err})") from err


def _check_integrity(model_path: Path, digest: str | None, data: bytes) -> None:
    """Refuse a file whose graph or weights (``data``, its bytes) differ from the digest its metadata records."""
    if digest is None:
        log.info("%s records no digest (exported before rtp wrote them, or adopted): integrity not checked",
                 model_path)
        return
    try:
        actual = model_digest(data)
    except ValueError as err:
        raise ModelLoadError(f"{str(model_path)!r}: cannot be read back to check its digest ({err})") from err
    if actual != digest:
        names, locations = external_tensors(data)
        if names:  # (re-saved with its weights beside it: the bytes the digest is of are not all in the file)
            where = f" ({', '.join(repr(loc) for loc in locations[:3])}{', ...' if len(locations) > 3 else ''})"
            raise ModelIntegrityError(
                f"{str(model_path)!r}: its weights are stored outside the .onnx file (ONNX external data: "
                f"{len(names)} tensor{'s' if len(names) != 1 else ''}, {', '.join(repr(n) for n in names[:3])}"
                f"{', ...' if len(names) > 3 else ''}, in the file{'s' if len(locations) > 1 else ''} beside it"
                f"{where if locations else ''}), as onnx.save_model(..., save_as_external_data=True) writes them; "
                f"rtp checks the digest its metadata records ({digest}) on the file alone, and loads a model whose "
                f"tensors are all inside it. Re-save it with every tensor inside: m = onnx.load({str(model_path)!r}) "
                f"(which reads the external data back), then `for t in m.graph.initializer: "
                f"t.ClearField('data_location')` (onnx.load marks each one read back; the mark is not in the exported "
                f"file), then onnx.save_model(m, {str(model_path)!r}) "
                f"(save_as_external_data=False, the default); or export it again"
            )
        raise ModelIntegrityError(
            f"{str(model_path)!r}: the graph or weights differ from what was exported (digest {actual}, the "
            f"metadata records {digest}); the file is corrupted or was modified after export: export it again"
        )


def _provider_name(spec: ProviderSpec) -> str:
    return spec if isinstance(spec, str) else spec[0]


#: The first onnxruntime release whose ``InferenceSession`` takes ``enable_fallback=0``.
_FALLBACK_KWARG = (1, 23)


def _version(ort: Any) -> tuple[int, ...]:
    """onnxruntime's release as numbers (``1.17.3`` -> (1, 17, 3)); a build without ``__version__``
    (a stand-in) reads as the newest."""
    parts = str(getattr(ort, "__version__", "")).split(".")
    numbers = [int(p) for p in (x.split("+")[0] for x in parts[:3]) if p.isdigit()]
    return tuple(numbers) if len(numbers) >= 2 else (10**6,)


def _inference_session(ort: Any, source: str | bytes, opts: Any, providers: Sequence[ProviderSpec]) -> Any:
    """``ort.InferenceSession`` with onnxruntime's own fallback off: when a session fails to build,
    onnxruntime's Python layer prints an "EP Error" banner to stdout and retries on other providers;
    the SDK never prints, and chooses its providers itself. Releases from 1.23 take
    ``enable_fallback=0``; the earlier ones the SDK supports (1.17-1.22, released and unchanging) read
    only the flag their constructor sets, so the session is built by a subclass that clears it
    before the build (where those releases check it, after a failed build)."""
    if _version(ort) >= _FALLBACK_KWARG:
        return ort.InferenceSession(source, sess_options=opts, providers=list(providers), enable_fallback=0)

    class _NoFallback(ort.InferenceSession):
        def _create_inference_session(self, *args: Any, **kwargs: Any) -> Any:
            self._enable_fallback = False
            return super()._create_inference_session(*args, **kwargs)

    return _NoFallback(source, sess_options=opts, providers=list(providers))


def _session(ort: Any, model_path: Path, source: str | bytes, opts: Any, requested: list[ProviderSpec],
             strict: bool) -> Any:
    """The onnxruntime session, built with onnxruntime's own fallback off (it prints to stdout, and the
    SDK never prints). If the requested providers cannot build it, CPU is tried: when CPU can, the
    requested provider failed (``ProviderUnavailableError`` with ``strict``, else a logged warning and
    the CPU session); when CPU cannot either, the file is not a loadable model (``ModelLoadError``).
    ``source`` is the file's path, or its bytes (a predictor unpickled where the file may not be)."""

    def build(providers: list[ProviderSpec]) -> Any:
        return _inference_session(ort, source, opts, providers)

    try:
        return build(requested)
    except Exception as err:  # onnxruntime raises bare Exception subclasses (InvalidProtobuf, Fail, ...)
        first = err
    names = [_provider_name(p) for p in requested]
    if names == [_CPU] or _CPU not in ort.get_available_providers():
        raise ModelLoadError(f"onnxruntime cannot load {str(model_path)!r}{_not_a_model(model_path)}: {first}") from first
    try:
        session = build([_CPU])
    except Exception as err:  # the model itself does not load
        raise ModelLoadError(f"onnxruntime cannot load {str(model_path)!r}{_not_a_model(model_path)}: {err}") from err
    msg = f"the session could not be built on {', '.join(names)} ({first}); it runs on {_CPU}"
    if strict:
        raise ProviderUnavailableError(msg) from first
    log.warning(msg)
    return session


def _utf8(text: str) -> bool:
    """Whether ``text`` encodes as UTF-8: onnxruntime takes a file path only as UTF-8 text, and a POSIX file
    name that is not valid UTF-8 reaches Python as a str holding lone surrogates (``os.fsdecode``)."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _bytes_for_unencodable_path(model_path: Path) -> bytes:
    """The bytes of a model whose path onnxruntime cannot take (a file name that is not valid UTF-8, such as
    ``b'\\xff.onnx'``): the session is built from them instead. A model whose weights are stored in files beside
    it (ONNX external data) cannot be: onnxruntime finds those only from the model's path."""
    data = _read_model(model_path)
    names, _ = external_tensors(data)
    if names:
        raise ModelLoadError(
            f"{str(model_path)!r}: its path is not valid UTF-8 text, which onnxruntime needs to find the "
            f"weights it stores outside the .onnx file (ONNX external data, {len(names)} tensor"
            f"{'s' if len(names) != 1 else ''}); rename the file (and keep it beside its external data)"
        )
    log.debug("%r: the path is not valid UTF-8; onnxruntime loads the model from its bytes", str(model_path))
    return data


def _check_external_locations(model_path: Path, data: bytes) -> None:
    """Refuse a model whose weights stored outside it (ONNX external data) are named by a file outside its folder:
    an absolute ``location``, one with a ``..`` step, or one that a symbolic link leads out of the folder. A model
    someone else made could name any file the user can read (``/home/me/.ssh/id_rsa``, ``../../secret``) as its
    weights; onnxruntime refuses those since about 1.20, but the releases before it that the SDK supports read them
    (and a model built from its bytes looks for them from the working folder)."""
    import ntpath
    import posixpath

    _, locations = external_tensors(data)
    if not locations:
        return
    folder = model_path.parent.resolve()
    for loc in locations:
        steps = loc.replace("\\", "/").split("/")
        if posixpath.isabs(loc) or ntpath.isabs(loc) or ntpath.splitdrive(loc)[0]:
            why = "an absolute path"
        elif ".." in steps:
            why = "a path with a '..' step"
        elif not (folder / loc).resolve().is_relative_to(folder):
            why = "a path that a symbolic link leads out of the model's folder"
        else:
            continue
        raise ModelLoadError(
            f"{str(model_path)!r}: its weights are stored outside the .onnx file (ONNX external data) in {loc!r}, "
            f"{why}: rtp reads external data only from files inside the model's folder ({str(folder)!r}), so that a "
            f"model cannot make it read any other file; keep the weights in the model (onnx.save_model(m, path), "
            f"save_as_external_data=False) or in a file beside it"
        )


def _not_a_model(path: Any) -> str:
    """What a file onnxruntime cannot parse looks like instead, for the message (empty where nothing is known)."""
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except (OSError, TypeError):
        return ""
    if head == b"PK\x03\x04":
        return f" (a zip, as a training checkpoint is: export it first, rtp-export {shlex.quote(str(path))})"
    if str(path).lower().endswith((".yaml", ".yml")):
        return " (a metadata sidecar: load the .onnx model it describes)"
    return ""


def _usable_cores() -> int:
    """The logical cores this process may run on (its CPU affinity where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def load(
    path: str | os.PathLike[str],
    *,
    providers: Sequence[ProviderSpec] | None = None,
    threads: int | None = None,
    metadata: ModelMetadata | Mapping[str, Any] | str | os.PathLike[str] | None = None,
    strict: bool = False,
    tile_size: int | None = None,
    assume_finite: bool = False,
    spin_between_runs: bool = False,
) -> ShadingRatePredictor:
    """Load an ONNX model and its metadata into a ready :class:`ShadingRatePredictor`.

    ``path`` is a file path, or the name of a shipped model (``"jnyang"`` or ``"jnyang.onnx"``).
    ``providers`` are onnxruntime execution providers in order of preference (names or
    ``(name, options)`` pairs); the default is every available provider, CPU last. ``threads`` sets
    onnxruntime's intra-op thread count (more than the cores the process may run on is logged as a
    warning: each of those threads spin-waits on a core). ``metadata`` (a dict, a :class:`ModelMetadata` or the path
    of a YAML sidecar) replaces the metadata embedded in the model, for a model that carries none.
    With ``strict=True`` a requested provider that is unavailable, or a session that does not run on
    the first requested provider, raises :class:`ProviderUnavailableError` instead of falling back.
    ``tile_size`` is the shading-rate tile size the engine's hardware uses, when it differs from the
    model's: ``predict`` and ``shading_rates`` then give one value per hardware tile. Coarser (a model
    with 8-pixel tiles on NVIDIA's 16-pixel hardware tiles), each hardware tile takes the worst of the
    model tiles it covers (:func:`pool_tiles`); finer (a 16-pixel model on AMD's and Intel's 8-pixel
    tiles), each takes its model tile's values (:func:`split_tiles`), down to 4-pixel tiles. The
    default is the model's own tile size. ``assume_finite=True`` skips
    ``predict``'s check that the input holds no NaN or infinity, for an engine that builds the planes
    itself and knows them finite, as scikit-learn's ``assume_finite``; a NaN that gets through then
    gives unspecified predictions instead of :class:`NonFiniteInputError`. The check is one read of
    the whole frame (2-3 ms of a 1080p eight-plane frame on a 2-core CPU), or, for a model with a
    finite probe (``metadata.finite_probe``: every shipped model), a reduction inside the graph that
    onnxruntime computes anyway (about 1 ms): ``assume_finite`` then saves next to nothing.

    onnxruntime's worker threads spin-wait for more work after each run by default, on every core
    they were given; an engine that calls ``predict`` once a frame and renders in between would lose
    those cores to them (about 16 ms of CPU time in the 16.7 ms after a 1080p ``predict`` on a 2-core
    CPU: ``python bench/spinning.py``). The SDK stops them when a run returns (onnxruntime's
    ``session.force_spinning_stop``); within a run they spin as before, so ``predict`` costs the
    same. ``spin_between_runs=True`` keeps onnxruntime's default, for a process that does nothing but
    run one model back to back. (A new session's threads spin for a while after it is built, until its
    first run, either way: a one-off cost of loading. ``load`` runs a model of free frame size once
    itself, to check its tile grid, so with the default only a fixed-size model's threads and a splitting
    model's tail session spin after it returns.)
    """
    model_path = _resolve_path(path)
    return _load(model_path, None, providers=providers, threads=threads, metadata=metadata, strict=strict,
                 tile_size=tile_size, assume_finite=assume_finite, spin_between_runs=spin_between_runs)


def _load(
    model_path: Path,
    data: bytes | None,
    *,
    providers: Sequence[ProviderSpec] | None,
    threads: int | None,
    metadata: ModelMetadata | Mapping[str, Any] | str | os.PathLike[str] | None,
    strict: bool,
    tile_size: int | None,
    assume_finite: bool,
    spin_between_runs: bool,
) -> ShadingRatePredictor:
    """:func:`load` of the file at ``model_path``, or, with ``data``, of those bytes (a pickled predictor's
    model, restored where ``model_path`` may not exist: it names the model in messages and in ``path``)."""
    ort = _ort()
    # numpy's integers and flags as Python's (a count or a tile size read from an array; np.True_): checked as
    # those, kept as those in what a pickled copy is loaded with
    if isinstance(threads, np.integer):
        threads = int(threads)
    if isinstance(tile_size, np.integer):
        tile_size = int(tile_size)
    strict, assume_finite, spin_between_runs = (bool(f) if isinstance(f, np.bool_) else f
                                                for f in (strict, assume_finite, spin_between_runs))
    if threads is not None and (
        isinstance(threads, bool) or not isinstance(threads, int) or not 0 <= threads <= MAX_THREADS
    ):
        raise ParameterError(
            f"threads: expected an integer in [0, {MAX_THREADS}] (0 = onnxruntime's default), got "
            f"{reprlib.repr(threads)}", "threads"
        )
    if not isinstance(strict, bool):
        raise ParameterError(f"strict: expected True or False, got {reprlib.repr(strict)}", "strict")
    if not isinstance(spin_between_runs, bool):
        raise ParameterError(
            f"spin_between_runs: expected True or False, got {reprlib.repr(spin_between_runs)}", "spin_between_runs"
        )
    requested = _normalise_providers(providers, strict)
    opts = ort.SessionOptions()
    opts.log_severity_level = 3
    if threads:
        opts.intra_op_num_threads = threads
        if threads > (cores := _usable_cores()):
            log.warning(
                "threads=%d is more than the %d core%s this process may run on: onnxruntime starts that many "
                "worker threads, which spin-wait when the session is built and during each run, and take the "
                "cores from every other thread of the process", threads, cores, "" if cores == 1 else "s"
            )
    if not spin_between_runs:
        # The worker threads stop spinning when a run ends (the tail's session, built with the same
        # options, too): the engine's own threads get the cores back between frames.
        opts.add_session_config_entry(FORCE_SPINNING_STOP, "1")
    if data is None and not _utf8(str(model_path)):
        data = _bytes_for_unencodable_path(model_path)
    source: str | bytes = str(model_path) if data is None else data
    # (before onnxruntime reads the weights it names; the digest is checked below on the bytes read after the session
    # is built, as they were: a file replaced meanwhile is caught there)
    _check_external_locations(model_path, _read_model(model_path) if data is None else data)
    session = _session(ort, model_path, source, opts, requested, strict)
    if data is None:
        data = _read_model(model_path)

    actual = [p for p in session.get_providers() if p not in _NON_COMPUTE]
    first = requested[0] if isinstance(requested[0], str) else requested[0][0]
    if actual[0] != first:
        msg = f"requested {first} but the session runs on {actual[0]}"
        if strict:
            raise ProviderUnavailableError(msg)
        log.warning(msg)

    try:
        props = session.get_modelmeta().custom_metadata_map
    except Exception as err:  # a corrupted file can hold metadata that is not UTF-8
        if metadata is None:
            raise ModelLoadError(f"{str(model_path)!r}: its metadata_props cannot be read ({err})") from err
        props = {}
    if metadata is not None:
        meta = _metadata_from_arg(metadata)
        _check_integrity(model_path, meta.digest or _embedded_digest(props), data)
    else:
        if METADATA_KEY not in props:
            raise MetadataError(
                f"{METADATA_KEY}: {str(model_path)!r} carries no rtp metadata; pass its sidecar (sdk.load(..., "
                f"metadata=), the commands' --metadata SIDECAR.yaml) or bake it in with "
                f"`rtp-export --adopt MODEL --metadata SIDECAR.yaml -o OUT.onnx`",
                METADATA_KEY,
            )
        meta = ModelMetadata.from_json(props[METADATA_KEY])
        _check_integrity(model_path, meta.digest, data)
    if meta._passes_everything(meta.default_threshold):
        log.warning(
            "%s: default_threshold %g is beyond the worst value the model can express (%g): every tile will "
            "pass it; %s the threshold or retrain with a larger transform range",
            model_path.name, meta.default_threshold, meta.saturation, "raise" if meta.higher_is_better else "lower",
        )
    tail = None if meta.tail is None else _tail_session(ort, props, meta.tail, model_path, opts, session)
    predictor = ShadingRatePredictor(session, meta, model_path, tile_size=tile_size, assume_finite=assume_finite,
                                     tail=tail)
    _check_tile_grid(predictor, model_path, given=metadata is not None)
    # what a pickled copy is loaded again from, in the process that unpickles it (docs/runtime.md "Pickling and other processes")
    predictor._pickled = (data, {
        "providers": providers, "threads": threads, "metadata": None if metadata is None else meta,
        "strict": strict, "assume_finite": assume_finite, "spin_between_runs": spin_between_runs,
    })
    if predictor.tile_size != meta.tile_size and (variant := _tile_variant(model_path, meta.tile_size,
                                                                           predictor.tile_size)):
        if predictor.tile_size < meta.tile_size:
            log.info("%s on %d-pixel tiles: each takes its %d-pixel tile's rates; %s ships, trained on %d-pixel "
                     "tiles, and saves more shading at the same failure rate (sdk.load(%r); docs/results.md)",
                     model_path.name, predictor.tile_size, meta.tile_size, variant, predictor.tile_size, variant)
        else:  # (measured on the validation maps: about as much saved at the same failure rate, a default not set
            #     for these tiles, a dearer network; docs/results.md "The 8-pixel models on 16-pixel tiles")
            log.info("%s on %d-pixel tiles: each takes the worst of the %d-pixel tiles it covers, and its default "
                     "threshold was set for those; %s ships, trained on %d-pixel tiles, with a default set for them "
                     "(sdk.load(%r); docs/results.md)", model_path.name, predictor.tile_size, meta.tile_size,
                     variant, predictor.tile_size, variant)
    return predictor


def _check_tile_grid(predictor: ShadingRatePredictor, model_path: Path, *, given: bool = False) -> None:
    """Refuse, at load, a model whose graph maps pixels to tiles of another size than its metadata's
    ``tile_size`` (a sidecar of the 8-pixel model given to the 16-pixel one): a model of fixed size is
    checked from its shapes when the predictor is built; any other runs once on a blank frame of eight
    tiles a side (under a millisecond for the shipped models; a model that fails on it is left to ``predict``
    to name, as it would have been). ``given``: the metadata came from ``load(..., metadata=)``, and the error
    says so rather than blaming the file's own."""
    if predictor._static_hw is not None:
        return
    meta = predictor.metadata
    whose = "the metadata given as metadata=" if given else f"{str(model_path)!r}'s metadata"
    t = meta.tile_size
    side, _ = padded_size(8 * t, 8 * t, meta.pad_multiple)
    try:
        (raw,), _ = predictor._run(np.zeros((1, len(meta.inputs), side, side), np.float32))
    except InferenceError as err:
        log.debug("%s: the tile-grid check could not run (%s)", model_path.name, err)
        return
    if raw.ndim == 4 and tuple(raw.shape[2:]) != (side // t, side // t):
        raise MetadataError(
            f"tile_size: {whose} says {t}, but the model maps {side}x{side} pixels to "
            f"{raw.shape[3]}x{raw.shape[2]} tiles (tiles of {side // max(raw.shape[3], 1)} pixels): the metadata "
            "is another model's, or was edited",
            "tile_size",
        )
    if raw.ndim == 4 and raw.shape[1] != len(meta.outputs):
        raise MetadataError(
            f"outputs: {whose} declares {len(meta.outputs)} rates {list(meta.outputs)} but "
            f"the model outputs {raw.shape[1]} channels",
            "outputs",
        )


def _tile_variant(model_path: Path, own: int, tile_size: int) -> str | None:
    """The name of the shipped model trained on ``tile_size``-pixel tiles for the same metric as the shipped model
    at ``model_path``, trained on ``own``-pixel ones: ``flip`` -> ``flip-8px`` (a shipped model's name without a
    suffix is one of :data:`DEFAULT_TILE_SIZE`-pixel tiles), ``flip-8px`` -> ``flip`` on 16-pixel tiles; or None:
    none ships, or ``model_path`` is not a shipped model."""
    d = _models_dir()
    if d is None or model_path.resolve().parent != d.resolve():
        return None
    suffix = f"-{own}px"
    if tile_size == DEFAULT_TILE_SIZE and model_path.stem.endswith(suffix):
        variant = d / f"{model_path.stem.removesuffix(suffix)}.onnx"
    elif own == DEFAULT_TILE_SIZE:
        variant = d / f"{model_path.stem}-{tile_size}px.onnx"
    else:
        return None
    return variant.stem if variant.is_file() else None


def _tail_session(ort: Any, props: Mapping[str, str], digest: str, model_path: Path, opts: Any, session: Any) -> Any:
    """The onnxruntime session of a splitting model's tail (``metadata.tail``), on the main session's providers."""
    text = props.get(TAIL_KEY)
    if text is None:
        raise MetadataError(f"tail: the metadata names a tail graph but {str(model_path)!r} holds no {TAIL_KEY!r} entry",
                            "tail")
    try:
        data = base64.b64decode(text, validate=True)
        found = model_digest(data)
    except (binascii.Error, ValueError) as err:
        raise ModelLoadError(f"{str(model_path)!r}: its tail graph ({TAIL_KEY}) is not base64 ONNX ({err})") from err
    if found != digest:
        raise ModelIntegrityError(f"{str(model_path)!r}: its tail graph ({TAIL_KEY}) does not match metadata.tail (digest "
                             f"{found}, expected {digest}): the file is damaged; export it again")
    try:
        return _inference_session(ort, data, opts, session.get_providers())
    except Exception as err:
        raise ModelLoadError(f"{str(model_path)!r}: onnxruntime cannot load its tail graph ({err})") from err


def _dim(d: Any) -> int | None:
    return d if isinstance(d, int) and d > 0 else None


def _plane_groups(inputs: list[Any], metadata: ModelMetadata) -> tuple[tuple[str, int, int], ...]:
    """``(name, first plane, end)`` of each graph input, in graph order. A model takes its planes
    (``metadata.inputs``) in one input or in several that hold consecutive planes (rtp-export splits
    eight or more planes into groups of at most seven so that onnxruntime's blocked convolution reads
    each group where it lies on any x86 CPU; docs/export.md "Input planes in groups"). With several, each
    declares its number of planes, they add up to the metadata's, and their other dimensions agree."""
    c = len(metadata.inputs)
    if len(inputs) == 1:
        c_in = _dim(inputs[0].shape[1])
        if c_in is not None and c_in != c:
            raise MetadataError(
                f"inputs: metadata declares {c} channels {list(metadata.inputs)} but the model input "
                f"{inputs[0].name!r} has {c_in}",
                "inputs",
            )
        return ((inputs[0].name, 0, c),)
    sizes = [_dim(i.shape[1]) for i in inputs]
    if any(n is None for n in sizes):
        raise MetadataError(f"a model whose planes come in several inputs must give each a fixed number of planes, got "
                            f"{[(i.name, i.shape[1]) for i in inputs]}", "inputs")
    if sum(n or 0 for n in sizes) != c:
        raise MetadataError(
            f"inputs: metadata declares {c} channels {list(metadata.inputs)} but the model's inputs hold "
            f"{' + '.join(str(n) for n in sizes)} ({', '.join(i.name for i in inputs)})",
            "inputs",
        )
    rest = {tuple(i.shape[k] for k in (0, 2, 3)) for i in inputs}
    if len(rest) != 1:
        raise MetadataError(f"the model's inputs disagree on batch, height or width: "
                            f"{[(i.name, i.shape) for i in inputs]}", "inputs")
    bounds = np.cumsum([0, *sizes]).tolist()
    return tuple((i.name, int(a), int(b)) for i, a, b in zip(inputs, bounds[:-1], bounds[1:]))


class ShadingRatePredictor:
    """Predicts per-tile error of every reduced shading rate and picks rates from it.

    Create with :func:`load`. The onnxruntime session is built once; ``predict`` and
    ``shading_rates`` may be called per frame.
    """

    def __init__(
        self, session: Any, metadata: ModelMetadata, path: Path | None = None, *, tile_size: int | None = None,
        assume_finite: bool = False, tail: Any = None,
    ) -> None:
        if not isinstance(assume_finite, (bool, np.bool_)):
            raise ParameterError(f"assume_finite: expected True or False, got {reprlib.repr(assume_finite)}",
                                 "assume_finite")
        self._assume_finite = bool(assume_finite)
        self._session = session
        #: the model's bytes and load()'s arguments, which __reduce__ pickles (load() sets them)
        self._pickled: tuple[bytes, dict[str, Any]] | None = None
        # the thresholds and frame sizes warned of (_first_warning), made here so that copies share them (a copy
        # shares this __dict__'s values): made on the first warning, a copy taken before it (each PredictionReuse's
        # of a predictor on finer hardware tiles, one a view) had sets of its own and logged each warning again
        self._saturation_warned: set[float] = set()
        self._cut_cells_warned: set[tuple[int, int]] = set()
        self._meta = metadata
        self._path = path
        model_tile = metadata.tile_size
        if tile_size is None:
            tile_size = model_tile
        elif (isinstance(tile_size, bool) or not isinstance(tile_size, (int, np.integer))
              or tile_size not in hardware_tiles(model_tile)):
            raise ParameterError(
                f"tile_size: expected one of {list(hardware_tiles(model_tile))} (the hardware's shading-rate tile "
                f"size: coarser than the model's {model_tile}-pixel tiles, each takes the worst of those it covers; "
                f"finer, down to one {MIN_HARDWARE_TILE}x{MIN_HARDWARE_TILE} coarse pixel, each takes its model tile's), "
                f"got {reprlib.repr(tile_size)}", "tile_size",
            )
        self._tile = int(tile_size)
        inputs, outputs = session.get_inputs(), session.get_outputs()
        probe = metadata.finite_probe
        if probe is not None and probe not in [o.name for o in outputs]:
            raise MetadataError(
                f"finite_probe: the metadata names the output {probe!r}, the model's outputs are "
                f"{[o.name for o in outputs]}",
                "finite_probe",
            )
        self._tail = tail
        # a tail graph reads the whole padded frame through its one input besides the features
        self._tail_input = next((i.name for i in tail.get_inputs() if i.name != FEATURES_NAME), "") if tail else ""
        dims = next((i.shape for i in tail.get_inputs() if i.name == FEATURES_NAME), None) if tail else None
        self._tail_channels = dims[1] if dims is not None and len(dims) == 4 and isinstance(dims[1], int) else None
        if tail is not None and FEATURES_NAME not in [o.name for o in outputs]:
            raise MetadataError(f"tail: the model splits, but its outputs {[o.name for o in outputs]} hold no "
                                f"{FEATURES_NAME!r}", "tail")
        outputs = [o for o in outputs if o.name != probe and not (tail is not None and o.name == FEATURES_NAME)]
        if not inputs or len(outputs) != 1:
            besides = f" besides the finite probe {probe!r}" if probe is not None else ""
            besides += f" and the features {FEATURES_NAME!r}" if tail is not None else ""
            # (a sidecar written without the model's own finite_probe: the scalar probe output was counted as a
            # second output, and the error said nothing of the field)
            scalars = [o.name for o in outputs if len(o.shape) == 0] if probe is None and inputs else []
            hint = (f": the model's scalar output {scalars[0]!r} looks like a finite probe, which the metadata does "
                    f"not name (metadata given beside the model replaces its own: add finite_probe: {scalars[0]})"
                    if len(scalars) == 1 and len(outputs) == 2 else "")
            raise MetadataError(
                f"expected a model with one output{besides} and its input planes in one or more inputs, got "
                f"{len(inputs)} inputs and {len(outputs)} outputs{hint}", "finite_probe" if hint else None
            )
        self._probe_name = probe
        o = outputs[0]
        for i in inputs:
            if i.type != "tensor(float)" or len(i.shape) != 4:
                raise MetadataError(f"expected float32 NCHW inputs, got input {i.name} {i.type} {i.shape}")
        if len(o.shape) != 4:
            raise MetadataError(f"expected a rank-4 output, got output {o.name} {o.shape}")
        self._out_name = o.name
        self._groups = _plane_groups(inputs, metadata)
        i = inputs[0]
        self._batch = _dim(i.shape[0])
        c_out = _dim(o.shape[1])
        if c_out is not None and c_out != len(metadata.outputs):
            raise MetadataError(
                f"outputs: metadata declares {len(metadata.outputs)} rates {list(metadata.outputs)} but the model "
                f"output {o.name!r} has {c_out} channels",
                "outputs",
            )
        hw_in = (_dim(i.shape[2]), _dim(i.shape[3]))
        self._static_hw: tuple[int, int] | None = None
        if hw_in[0] is not None and hw_in[1] is not None:
            self._static_hw = (hw_in[0], hw_in[1])
            hw_out = (_dim(o.shape[2]), _dim(o.shape[3]))
            w = metadata.tile_size
            # what predict_raw expects of the output: every tile of the input, a partial last one included
            grid = tile_grid(hw_in[0], hw_in[1], w)
            if (hw_out[0] is not None and hw_out[0] != grid[0]) or (hw_out[1] is not None and hw_out[1] != grid[1]):
                partial = hw_in[0] % w or hw_in[1] % w
                raise MetadataError(
                    f"tile_size: metadata says {w} but the model maps {hw_in[1]}x{hw_in[0]} to "
                    f"{o.shape[3]}x{o.shape[2]} tiles, expected {grid[1]}x{grid[0]}"
                    + (f" (a fixed input that is no multiple of the tile size must give its partial last "
                       f"{w}-pixel tiles too, or no frame's last tiles would be predicted)" if partial else ""),
                    "tile_size",
                )

    # -- properties ---------------------------------------------------------------------------
    @property
    def metadata(self) -> ModelMetadata:
        return self._meta

    @property
    def rates(self) -> tuple[str, ...]:
        """Rate names of ``predict``'s channels: ``1x2, 2x1, 2x2, 2x4, 4x2, 4x4``."""
        return PREDICTED_RATES

    @property
    def tile_size(self) -> int:
        """Pixels per side of the tiles ``predict`` and ``shading_rates`` give: the model's
        (``metadata.tile_size``) unless ``load(tile_size=...)`` asked for the hardware's, coarser or finer."""
        return self._tile

    def _on_model_tiles(self) -> ShadingRatePredictor:
        """This predictor on the model's own tiles (itself where it already is): the same session and
        metadata, for the work that runs on whole model tiles (``PredictionReuse`` on finer hardware
        tiles, which splits its estimates afterwards)."""
        if self._tile == self._meta.tile_size:
            return self
        import copy

        view = copy.copy(self)
        view._tile = self._meta.tile_size
        return view

    @property
    def providers(self) -> list[str]:
        """Execution providers of the session, the one that runs first."""
        return [p for p in self._session.get_providers() if p not in _NON_COMPUTE]

    @property
    def provider(self) -> str:
        """The execution provider that actually runs the model."""
        return self.providers[0]

    @property
    def path(self) -> Path | None:
        return self._path

    @property
    def graph_inputs(self) -> tuple[tuple[str, tuple[str, ...]], ...]:
        """The onnxruntime inputs the planes go to, in order, each with the planes (``metadata.inputs``
        names) it takes: one ``("input", all planes)``, or consecutive groups for a model whose planes
        come in several inputs (docs/export.md "Input planes in groups"). ``predict`` feeds them itself;
        an engine that runs the file with its own session binds each to its slice of the planes."""
        return tuple((name, self._meta.inputs[a:b]) for name, a, b in self._groups)

    @property
    def static_size(self) -> tuple[int, int] | None:
        """``(H, W)`` of a model with a fixed input size (frames are padded up to it), else None."""
        return self._static_hw

    def __copy__(self) -> ShadingRatePredictor:
        """A copy shares the session: a predictor holds nothing that changes (``copy.copy`` and
        ``copy.deepcopy``; pickling loads the model again, in the process that unpickles it)."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        return new

    def __deepcopy__(self, memo: dict[int, Any]) -> ShadingRatePredictor:
        return self.__copy__()

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled, a predictor carries its model's bytes and the arguments it was loaded with, not its
        onnxruntime session (which cannot be pickled): unpickling loads the model again from those bytes,
        with the same options, in the process that unpickles it (a ``multiprocessing`` or Ray worker), where
        the file need not exist. docs/runtime.md "Pickling and other processes"."""
        state = self._pickled
        if state is None:
            raise TypeError(
                "cannot pickle a ShadingRatePredictor built from an onnxruntime session of your own: pickling "
                "loads the model again from its bytes, which only rtp.sdk.load() keeps; load it with sdk.load()"
            )
        data, args = state
        return _unpickle, (str(self._path), data, {**args, "tile_size": self._tile})

    def __repr__(self) -> str:
        m = self._meta
        return (
            f"<ShadingRatePredictor {m.metric} tile={self._tile}"
            f"{f' (model {m.tile_size})' if self._tile != m.tile_size else ''} inputs={list(m.inputs)} "
            f"outputs={list(m.outputs)} provider={self.provider}>"
        )

    # -- inference ----------------------------------------------------------------------------
    def tiles(self, height: int, width: int) -> tuple[int, int]:
        """Number of tile rows and columns for a frame: ``(ceil(H/w), ceil(W/w))``, ``w`` = :attr:`tile_size`."""
        return tile_grid(height, width, self._tile)

    def _check(self, x: Any) -> np.ndarray:
        if not isinstance(x, np.ndarray):
            raise InputDtypeError(f"expected a numpy.ndarray of float32, got {type(x).__name__}")
        x = np.asarray(x)  # a subclass as the plain array the model reads (a masked array's mask hid its NaNs)
        if x.dtype != np.float32:
            swapped = x.dtype.kind == "f" and x.dtype.itemsize == 4  # (big-endian '>f4': float32, other byte order)
            raise InputDtypeError(f"expected dtype float32{' in native byte order' if swapped else ''}, got "
                                  f"{x.dtype.str if swapped else x.dtype}; convert with x.astype(np.float32)")
        c = len(self._meta.inputs)
        if x.ndim not in (3, 4):
            raise InputShapeError(
                f"expected shape ({c}, H, W) or (N, {c}, H, W), got {x.shape}", tuple(x.shape), f"(N, {c}, H, W)"
            )
        x4 = x[None] if x.ndim == 3 else x
        if x4.shape[1] != c:
            hint = ""
            if x4.shape[-1] == c:
                order = "(2, 0, 1)" if x.ndim == 3 else "(0, 3, 1, 2)"
                hint = f"; the array looks channels-last: transpose it with x.transpose{order}"
            raise InputChannelError(
                f"expected {c} channels {list(self._meta.inputs)} on axis {x.ndim - 3}, got shape {x.shape}{hint}",
                tuple(x.shape),
                f"(N, {c}, H, W)",
            )
        n, _, h, w = x4.shape
        if n == 0 or h == 0 or w == 0:
            raise InputShapeError(f"expected a non-empty input, got shape {x.shape}", tuple(x.shape), f"(N, {c}, H, W)")
        if self._static_hw is not None and (h > self._static_hw[0] or w > self._static_hw[1]):
            sh, sw = self._static_hw
            raise InputShapeError(
                f"this model has a fixed input of {sw}x{sh}; a {w}x{h} frame does not fit (smaller frames are padded)",
                tuple(x.shape),
                f"(N, {c}, <= {sh}, <= {sw})",
            )
        if self._assume_finite or self._probe_name is not None:
            return x4  # nothing to check, or the graph checks it (_run's probe, then _exact_check)
        # One float32 reduction (pairwise and vectorised: a third of the cost of accumulating in
        # float64, 1.7 against 6 ms for a 1080p frame) instead of a boolean temporary; NaN and inf
        # both survive a sum. Finite values beyond ~1e34 can overflow it: the exact test decides.
        with np.errstate(over="ignore", invalid="ignore"):
            total = float(x4.sum())
        if not math.isfinite(total):
            self._exact_check(x4)
        return x4

    def _exact_check(self, x4: np.ndarray) -> None:
        """:class:`NonFiniteInputError` naming the first NaN or infinity of ``x4``, if it holds one (a
        reduction that overflowed on huge but finite values passes)."""
        bad = ~np.isfinite(x4)
        if bad.any():
            where = np.argwhere(bad)[0].tolist()
            raise NonFiniteInputError(
                f"input holds {int(bad.sum())} NaN or infinite values (first at index {tuple(where)}, channel "
                f"{self._meta.inputs[where[1]]!r})"
            )

    def _padded(self, x4: np.ndarray) -> np.ndarray:
        """Pad H and W up to the model's fixed size, or up to ``metadata.pad_multiple`` (whole tiles,
        or less for a network that takes partial tiles itself), by repeating the last row and
        column, so edge tiles see real content rather than an artificial border. A frame already
        of that size is passed as it is (no copy when it is C-contiguous): at 1920x1080 a network
        with ``input_multiple`` 4 saves the 4 ms copy to 1088 rows."""
        _, _, h, w = x4.shape
        if w % BLOCK_CELL or h % BLOCK_CELL == 1 or h % BLOCK_TILE in (1, 2):  # (W mod 16 of 1-3: W mod 4 too)
            self._warn_cut_cells(h, w)
        if self._static_hw is not None:
            ph, pw = self._static_hw
        else:
            ph, pw = padded_size(h, w, self._meta.pad_multiple)
        if (ph, pw) == (h, w):
            return np.ascontiguousarray(x4)
        # np.pad(mode="edge") by hand: one copy into a fresh array (a millisecond less at 1080p)
        out = np.empty((*x4.shape[:2], ph, pw), np.float32)
        out[:, :, :h, :w] = x4
        out[:, :, h:, :w] = x4[:, :, h - 1 : h, :]
        out[:, :, :, w:] = out[:, :, :, w - 1 : w]
        return out

    def _warn_cut_cells(self, h: int, w: int) -> None:
        """Log once per frame size (for the first :data:`MAX_WARNED` sizes) when a ``h x w`` frame has no pixel for
        some values of its ``.blocks`` planes' last 4x4 cells (a width not a multiple of 4, a height of 4k + 1) or of
        its ``.tiles`` planes' last tiles (``W mod 16`` of 1 to 3, ``H mod 16`` of 1 or 2): :func:`block_variances`
        packs a cell's six values on its first two rows, four columns, so those past the frame's edge are lost, and
        the padding gives the network copies of the last column or row in their place (a rate's value read as
        another's). The last tile column or row, and the tiles beside it, are then predicted from wrong inputs."""
        names = self._meta.inputs
        cut = [c for c in names if (c.endswith(".blocks") and (w % BLOCK_CELL or h % BLOCK_CELL == 1))
               or (c.endswith(".tiles") and (w % BLOCK_TILE in (1, 2, 3) or h % BLOCK_TILE in (1, 2)))]
        if not cut:
            return
        count = self._first_warning("_cut_cells_warned", (h, w))
        if not count:
            return
        blocks, tiles = any(c.endswith(".blocks") for c in cut), any(c.endswith(".tiles") for c in cut)
        what = "4x4 cells and 16-pixel tiles" if blocks and tiles else "4x4 cells" if blocks else "16-pixel tiles"
        log.warning("%s: a %dx%d frame cuts the last %s of its %s planes: the values they pack on pixels past the "
                    "frame's edge are lost, the network reads copies of the frame's last column or row in their "
                    "place, and predicts the last tile column or row (and the tiles beside it) from wrong inputs; "
                    "render at a size whose sides are multiples of 4%s", self._path.name if self._path else "model",
                    w, h, what, ", ".join(cut), _last_said(count, "frame sizes"))

    def _first_warning(self, kind: str, key: Any) -> int:
        """Whether to log the warning ``kind`` (the name of the set of what it was logged for) of ``key``: its number
        among them (1 for the first; :data:`MAX_WARNED` for the last), or 0 where it was logged before or
        :data:`MAX_WARNED` keys were (the set then grows no more)."""
        with _WARNED_LOCK:  # (the test and the add as one: two threads between them both logged it)
            seen = self.__dict__.setdefault(kind, set())
            if key in seen or len(seen) >= MAX_WARNED:
                return 0
            seen.add(key)
            return len(seen)

    def _feed(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """The session's inputs from one padded array: each graph input its consecutive planes (a view,
        no copy, for a C-contiguous batch of one; see :func:`_plane_groups`)."""
        if len(self._groups) == 1:
            return {self._groups[0][0]: x}
        return {name: np.ascontiguousarray(x[:, a:b]) for name, a, b in self._groups}

    def _run(self, x: np.ndarray, extra: tuple[str, ...] = ()) -> tuple[list[np.ndarray], bool]:
        """The metric output for ``x`` then the ``extra`` outputs (a splitting model's features), and
        whether the graph's finite probe (if the model has one and the input is not assumed finite)
        says the input holds a NaN or an infinity."""
        names = [self._out_name, *extra]
        if self._probe_name is not None and not self._assume_finite:
            names.append(self._probe_name)
        try:
            outs = self._session.run(names, self._feed(x))
        except Exception as err:
            raise InferenceError(f"onnxruntime failed on an input of shape {x.shape}: {err}") from err
        k = 1 + len(extra)
        return outs[:k], len(outs) > k and not bool(np.isfinite(outs[k]).all())

    def predict_raw(self, x: np.ndarray) -> np.ndarray:
        """The network's own output (transformed space, one channel per metadata ``outputs`` rate),
        cropped to ``(N, C, ceil(H/w), ceil(W/w))`` on the model's own tiles (``w`` =
        ``metadata.tile_size``, never pooled). Same input rules as :meth:`predict`."""
        x4 = self._check(x)
        n, _, h, w = x4.shape
        xp = self._padded(x4)
        if self._batch is not None and self._batch not in (1, n):
            raise InputShapeError(
                f"this model has a fixed batch of {self._batch}, got {n}", tuple(x.shape), f"({self._batch}, ...)"
            )
        if n > 1 and (self._batch == 1 or (self._batch is None and len(self._groups) > 1)):
            # Frame by frame: a model with a fixed batch of one, or one whose planes come in several
            # inputs, where a frame's groups are views of the batch but a batch's groups are copies (at
            # 1920x1080 two frames of nine planes: 23 ms of copying, a 29 ms run; bench/views.py).
            runs = [self._run(xp[i : i + 1]) for i in range(n)]
            raw, flagged = np.concatenate([r[0][0] for r in runs], axis=0), any(r[1] for r in runs)
        else:
            (raw,), flagged = self._run(xp)
        if flagged:  # the graph saw a NaN or an infinity (or a sum that overflowed): the exact test decides
            self._exact_check(x4)
        t = self._meta.tile_size
        expect = (n, len(self._meta.outputs), *tile_grid(xp.shape[2], xp.shape[3], t))
        if raw.shape != expect:
            raise InferenceError(
                f"model output has shape {raw.shape}, expected {expect} from an input of {xp.shape} with "
                f"tile_size {t} and outputs {list(self._meta.outputs)}; the metadata does not fit this model"
            )
        th, tw = tile_grid(h, w, t)
        out = raw[:, :, :th, :tw]
        return out if x.ndim == 4 else out[0]

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Per-tile predicted metric for the six reduced rates.

        ``x`` is float32 ``(C, H, W)`` or ``(N, C, H, W)`` with the channels of
        ``metadata.inputs``. Returns float32 ``(6, ceil(H/w), ceil(W/w))`` (or with the batch axis),
        channels in :attr:`rates` order, in the metric's units, the safety margin included; ``w`` is
        :attr:`tile_size` (on hardware tiles coarser than the model's, the worst model tile of each; on
        finer ones, the model tile each lies in).
        """
        values = self._meta.decode(self.predict_raw(x))
        if self._tile < self._meta.tile_size:  # (finer hardware tiles: each its model tile's values)
            h, w = np.shape(x)[-2:]
            return split_tiles(values, self._meta.tile_size // self._tile, tile_grid(h, w, self._tile))
        factor = self._tile // self._meta.tile_size
        return values if factor == 1 else pool_tiles(values, factor, higher_is_better=self._meta.higher_is_better)

    # -- a network that splits (metadata.tail) ------------------------------------------------------
    @property
    def splits(self) -> bool:
        """Whether the network splits into a trunk and a tail (``metadata.tail``): :meth:`predict_split`
        and :meth:`predict_tail`, which ``PredictionReuse(carry="features")`` uses."""
        return self._tail is not None

    @property
    def tail_inputs(self) -> tuple[str, ...]:
        """The input channels the tail reads (:meth:`predict_tail`): the ``.blocks`` or ``.tiles`` planes of
        a model that splits, () for one that does not. On a frame whose trunk features are carried the
        other planes are never read: ``PredictionReuse(carry="features")`` asks an input function that
        takes ``channels`` for these alone (docs/runtime.md)."""
        if self._tail is None:
            return ()
        return tuple(c for c in self._meta.inputs if c.endswith((".blocks", ".tiles")))

    def _split_frame(self, x: Any) -> tuple[np.ndarray, np.ndarray]:
        """One frame's checked and padded input ``(x4, xp)`` for the split methods."""
        if self._tail is None:
            raise ParameterError("this model does not split (metadata.tail is null): it has no trunk features to carry; "
                                 "export a network trained with --block-contrast on .blocks or .tiles planes and "
                                 "--contrast-cell 16 (the tile's: a finer cell joins inside the stem, no per-tile "
                                 "features)", "carry")
        if isinstance(x, np.ndarray) and x.ndim != 3:
            c = len(self._meta.inputs)
            raise InputShapeError(f"expected one frame's inputs ({c}, H, W), got shape {x.shape}", tuple(x.shape),
                                  f"({c}, H, W)")
        if self._tile != self._meta.tile_size:
            raise ParameterError(f"the split methods work on the model's own {self._meta.tile_size}-pixel tiles, not "
                                 f"{'pooled' if self._tile > self._meta.tile_size else 'split'} {self._tile}-pixel "
                                 f"ones: load the model without tile_size", "tile_size")
        x4 = self._check(x)
        return x4, self._padded(x4)

    def predict_split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`predict` on one frame ``(C, H, W)``, and the trunk's features that gave it: float32
        ``(features, ceil(H/w), ceil(W/w))``, what :meth:`predict_tail` takes, on this frame or carried
        to a later one. One network run (the features are an output of the same graph)."""
        x4, xp = self._split_frame(x)
        outs, flagged = self._run(xp, (FEATURES_NAME,))
        if flagged:
            self._exact_check(x4)
        th, tw = tile_grid(x4.shape[2], x4.shape[3], self._meta.tile_size)
        raw, feats = outs[0][:, :, :th, :tw], outs[1][0, :, :th, :tw]
        return self._meta.decode(raw)[0], np.ascontiguousarray(feats, dtype=np.float32)

    def predict_tail(self, features: np.ndarray, x: np.ndarray) -> np.ndarray:
        """:meth:`predict` of one frame ``(C, H, W)`` from trunk features (:meth:`predict_split`'s, of this
        frame or carried from an earlier one) and this frame's inputs: the tail alone runs, at tile
        resolution (it reads only the frame's ``.blocks`` planes, or of its ``.tiles`` planes twelve pixels
        a tile). With the frame's own features it gives what :meth:`predict` gives, but on a model of a
        fixed input size given a smaller frame: there the tail runs on the padded frame with the frame's
        last row and column of features repeated (the trunk's features of the padded tiles are not
        kept), and its last tile row and column differ from :meth:`predict`'s."""
        x4, xp = self._split_frame(x)
        th, tw = tile_grid(x4.shape[2], x4.shape[3], self._meta.tile_size)
        gh, gw = tile_grid(xp.shape[2], xp.shape[3], self._meta.tile_size)
        if not isinstance(features, np.ndarray) or features.ndim != 3 or features.shape[1:] != (th, tw):
            got = features.shape if isinstance(features, np.ndarray) else type(features).__name__
            raise InputShapeError(f"features: expected (channels, {th}, {tw}) for this frame's tiles, got {got}",
                                  tuple(getattr(features, "shape", ())), f"(C, {th}, {tw})")
        if features.dtype.kind not in "fiu":
            raise InputDtypeError(f"features: expected float32 values (the trunk's), got dtype {features.dtype}")
        if self._tail_channels is not None and len(features) != self._tail_channels:
            raise InputShapeError(f"features: expected {self._tail_channels} channels (the trunk's, from predict_split), "
                                  f"got {len(features)}", tuple(features.shape), f"({self._tail_channels}, {th}, {tw})")
        f = features.astype(np.float32, copy=False)[None]
        if (gh, gw) != (th, tw):  # a frame padded past its last tile row or column: repeat the last ones
            f = np.pad(f, ((0, 0), (0, 0), (0, gh - th), (0, gw - tw)), mode="edge")
        if not self._assume_finite:  # the tail reads the .blocks or .tiles planes: they alone need the check
            with np.errstate(over="ignore", invalid="ignore"):
                if not math.isfinite(self._tail_read_sum(x4)) or not math.isfinite(float(f.sum())):
                    self._exact_check(x4)
                    raise NonFiniteInputError("features: expected finite values (the trunk's features), got NaN or "
                                              "infinite ones")
        try:
            raw = self._tail.run([self._out_name], {FEATURES_NAME: f, self._tail_input: xp})[0]
        except Exception as err:
            raise InferenceError(f"onnxruntime failed on the tail, features {f.shape} and input {xp.shape}: {err}") \
                from err
        return self._meta.decode(raw[:, :, :th, :tw])[0]

    def _tail_read_sum(self, x4: np.ndarray) -> float:
        """The sum of what the tail reads of a frame: its .blocks planes, or of its .tiles planes the first
        three rows of each tile (the twelve values a tile; a fifth of the planes, the rest never read)."""
        names = self.tail_inputs
        planes = [i for i, c in enumerate(self._meta.inputs) if c in names]
        read = x4[:, planes[0]:planes[-1] + 1] if planes == list(range(planes[0], planes[-1] + 1)) else x4[:, planes]
        if self._meta.inputs[planes[0]].endswith(".tiles"):
            return float(sum(read[:, :, r::BLOCK_TILE].sum() for r in range(3)))
        return float(read.sum())

    def shading_rates(
        self,
        x: np.ndarray,
        threshold: float | None = None,
        allowed: Iterable[RateLike] | None = None,
        *,
        saving: float | None = None,
        engine_rates: RateLike | np.ndarray | None = None,
        combiner: str | int = "max",
    ) -> np.ndarray:
        """Per tile the cheapest allowed rate whose predicted value passes ``threshold``, else 1x1.

        Passing means below the threshold for error metrics and above it for PSNR. ``threshold``
        defaults to ``metadata.default_threshold``; ``allowed`` restricts the rates (names or codes)
        for hardware without 4x4 or without 2x4/4x2. A model whose metadata holds ``rate_factors`` gives
        each rate that factor of the threshold (``select_rates(factors=)``). Returns uint8 D3D12/Vulkan
        rate codes of shape ``(ceil(H/w), ceil(W/w))`` (or ``(N, ...)``), ready to upload as a
        shading-rate image.

        ``saving`` instead of a threshold holds the shading work rather than the quality (a budget, as
        dynamic resolution holds the frame time): each frame's rates save at least that share of it
        (``[0, 0.9375]``) at the lowest threshold that does, so with the least visible error its
        predictions allow (:func:`~rtp.sdk.select_rates_for_saving`, which also says the threshold reached).
        Both: the threshold's rates, with the saving as a floor under them on frames where they save less.

        ``engine_rates`` (one code, a ``(th, tw)`` image, or one a frame) are the engine's own rates for the same
        tiles, which the hardware's ``combiner`` (``min``, ``max``, ``sum`` or its enum value) meets with this image:
        each tile then takes the cheapest rate the device will shade that passes, not a rate whose combination
        with the engine's was never judged, and a ``saving`` counts the two together
        (:func:`~rtp.sdk.select_rates`, :func:`~rtp.sdk.combine_rates`).
        """
        if threshold is not None:  # (before the network: a threshold it refuses came back after a whole frame's run)
            check_threshold(threshold, self._meta.higher_is_better)
        if saving is not None:
            values = self.predict(x)  # (first: it refuses what is no frame, whose shape has no H and W)
            h, w = np.shape(x)[-2:]
            chosen = select_rates_for_saving(values, saving, higher_is_better=self._meta.higher_is_better,
                                             allowed=allowed, factors=self._meta.rate_factors, frame_size=(h, w),
                                             tile_size=self._tile, threshold=threshold, engine_rates=engine_rates,
                                             combiner=combiner).rates
            if threshold is not None:  # (a floor past saturation took every tile to the coarsest rate in silence)
                self._warn_beyond_saturation(threshold, budget=True)
            return chosen
        thr = self._meta.default_threshold if threshold is None else threshold
        rates = select_rates(self.predict(x), thr, higher_is_better=self._meta.higher_is_better, allowed=allowed,
                             factors=self._meta.rate_factors, engine_rates=engine_rates, combiner=combiner)
        self._warn_beyond_saturation(thr)
        return rates

    def _warn_beyond_saturation(self, threshold: float, *, budget: bool = False) -> None:
        """Log once per threshold, for the first :data:`MAX_WARNED` thresholds, what
        :meth:`ModelMetadata.threshold_warning` says of it: every rate's threshold (its ``rate_factors`` share of it)
        beyond the worst value the model can express, every tile then passing at the coarsest allowed rate (``load``
        says so of a default threshold); or beyond the best value it can express, no tile then passing at any rate
        and every tile 1x1 on every frame. ``budget``: the threshold is a floor under a budget (only the first end)."""
        t = float(threshold)
        message = self._meta.threshold_warning(t, budget=budget)
        if message is None:
            return
        count = self._first_warning("_saturation_warned", t)
        if count:
            log.warning("%s: %s%s", self._path.name if self._path else "model", message,
                        _last_said(count, "thresholds"))


def _last_said(count: int, what: str) -> str:
    """The end of a once-each warning: where it is the :data:`MAX_WARNED`-th, that no more of them are logged."""
    return f" (the {MAX_WARNED}th {what[:-1]} warned of: further {what} are not logged)" if count >= MAX_WARNED else ""


def _unpickle(path: str, data: bytes, args: dict[str, Any]) -> ShadingRatePredictor:
    """A pickled :class:`ShadingRatePredictor` loaded again (its ``__reduce__``)."""
    return _load(Path(path), data, **args)
