"""Checkpoints: the network's architecture, weights and model metadata in one file.

Format (``torch.save`` of a dict, loaded with ``weights_only=True``; see docs/export.md)::

    {
      "format": "rtp-checkpoint", "format_version": 1,
      "architecture": {"name": "MetricNet" | "FastNet", "config": {"in_channels", "out_channels", "tile", ...}},
      "state_dict": {...},                 # the network's weights and BatchNorm statistics
      "metadata": {...},                   # rtp.sdk.ModelMetadata.to_dict(): what rtp-export bakes in
      "training": {...} | None,            # optimizer / scheduler state and step, for resuming
      "versions": {"rtp": ..., "torch": ...},
    }

Writes are atomic: a crash while saving leaves the previous checkpoint intact.
"""

from __future__ import annotations

import io
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from rtp.sdk import EXIT_USAGE, MetadataError, ModelMetadata, ModelNotFoundError, RtpError
from rtp.sdk.files import atomic_output

from .model import FastNet, MetricNet, Network

__all__ = ["FORMAT", "FORMAT_VERSION", "Checkpoint", "CheckpointError", "load", "save"]

FORMAT = "rtp-checkpoint"
FORMAT_VERSION = 1
_ARCHITECTURES: dict[str, type[MetricNet] | type[FastNet]] = {"MetricNet": MetricNet, "FastNet": FastNet}


class CheckpointError(RtpError):
    """A checkpoint file is unreadable, of another format, or inconsistent."""

    exit_code = EXIT_USAGE


@dataclass
class Checkpoint:
    net: Network
    metadata: ModelMetadata
    training: dict[str, Any] | None
    versions: dict[str, str]


def _versions() -> dict[str, str]:
    from rtp import sdk

    return {"rtp": str(sdk.__version__), "torch": str(torch.__version__)}


def check_fits(net: Network, meta: ModelMetadata) -> None:
    """Raise MetadataError when the metadata's inputs, outputs or tile size do not match the network."""
    c = net.config
    if len(meta.inputs) != c["in_channels"]:
        raise MetadataError(
            f"inputs: metadata lists {len(meta.inputs)} channels but the network takes {c['in_channels']}", "inputs"
        )
    if len(meta.outputs) != c["out_channels"]:
        raise MetadataError(
            f"outputs: metadata lists {len(meta.outputs)} rates but the network outputs {c['out_channels']}", "outputs"
        )
    if meta.tile_size != c["tile"]:
        raise MetadataError(f"tile_size: metadata says {meta.tile_size} but the network's tile is {c['tile']}", "tile_size")


def _on_cpu(value: Any) -> Any:
    """``value`` (a training state: mappings, lists and tensors, as optimizers and networks keep them)
    with every tensor copied to the CPU."""
    if isinstance(value, torch.Tensor):
        return value.detach().cpu()
    if isinstance(value, dict):
        return {k: _on_cpu(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_on_cpu(v) for v in value]
    if type(value) is tuple:
        return tuple(_on_cpu(v) for v in value)
    return value


def save(
    path: str | os.PathLike[str],
    net: Network,
    metadata: ModelMetadata | Mapping[str, Any],
    training: Mapping[str, Any] | None = None,
) -> Path:
    """Write a checkpoint atomically. ``metadata`` is validated and must fit the network."""
    meta = metadata if isinstance(metadata, ModelMetadata) else ModelMetadata.from_dict(metadata)
    if not isinstance(net, (MetricNet, FastNet)):
        raise CheckpointError(f"expected a MetricNet or FastNet, got {type(net).__name__}")
    check_fits(net, meta)
    payload = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "architecture": {"name": type(net).__name__, "config": dict(net.config)},
        "state_dict": {k: v.detach().cpu() for k, v in net.state_dict().items()},
        "metadata": meta.to_dict(),
        # (on the CPU: a checkpoint of a training on a GPU loads on any machine, with plain torch.load too)
        "training": _on_cpu(dict(training)) if training is not None else None,
        "versions": _versions(),
    }
    buffer = io.BytesIO()
    torch.save(payload, buffer)  # (in memory, then written: torch's own writer on a full disk was an "enforce fail")
    with atomic_output(path) as tmp:
        tmp.write_bytes(buffer.getbuffer())
        try:  # what load() will do, before the file replaces a good one (a numpy scalar in training did not)
            torch.load(tmp, map_location="cpu", weights_only=True)
        except Exception as err:
            raise CheckpointError(f"{path}: not saved, the checkpoint would not load back with weights_only=True "
                                  f"({type(err).__name__}): keep `training` to Python numbers, strings, lists, dicts "
                                  "and tensors") from err
    return Path(path)


def _check_fits_weights(p: Path, cls: type[MetricNet] | type[FastNet], arch: dict[str, Any],
                        state: dict[str, Any]) -> None:
    """Refuse an architecture whose weights are not the file's before any of its memory is allocated.

    A damaged or hand-made ``architecture.config`` (a width of 24,390 took 21 GB and the process) is
    built on torch's ``meta`` device first, which allocates nothing, and its tensor shapes compared with
    the file's: the real network is then exactly as large as the weights already read. Counts of layers
    are bounded by the file's tensors first, as each layer holds at least one.
    """
    config = arch["config"]
    for key in ("depth", "coarse"):
        v = config.get(key)
        if isinstance(v, int) and not isinstance(v, bool) and v > len(state):
            raise CheckpointError(f"{p}: weights do not fit the architecture: {key} {v} needs more weight tensors "
                                  f"than the file's {len(state)}")
    try:
        with torch.device("meta"):
            shapes = {k: tuple(v.shape) for k, v in cls(**config).state_dict().items()}
    except (KeyError, TypeError, RuntimeError, ValueError) as err:
        raise CheckpointError(f"{p}: weights do not fit the architecture {arch}: {err}") from err
    stored = {k: tuple(v.shape) for k, v in state.items() if isinstance(v, torch.Tensor)}
    wrong = sorted(k for k in shapes.keys() & stored.keys() if shapes[k] != stored[k])
    if wrong:
        k, more = wrong[0], f" ({len(wrong) - 1} more)" if len(wrong) > 1 else ""
        raise CheckpointError(f"{p}: weights do not fit the architecture {arch}: {k} is {list(stored[k])} in the file, "
                              f"the architecture's is {list(shapes[k])}{more}")


def load(path: str | os.PathLike[str]) -> Checkpoint:
    """Read a checkpoint, rebuild the network in eval mode and validate its metadata."""
    if not isinstance(path, (str, os.PathLike)):
        raise CheckpointError(f"expected the path of a checkpoint, got {type(path).__name__}")
    p = Path(path)
    if not p.is_file():
        raise ModelNotFoundError(f"checkpoint {str(p)!r} is a folder, not a file" if p.is_dir()
                                 else f"no checkpoint at {str(p)!r}")
    try:
        with warnings.catch_warnings():  # (a pickle of another program, protocol 4 or 5: torch's two-line warning
            # "Detected pickle protocol 4 in the checkpoint ..." came before the one-line error it ends in)
            warnings.filterwarnings("ignore", message="Detected pickle protocol", category=UserWarning)
            raw = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises UnpicklingError, RuntimeError, EOFError, ... with pages of advice
        hint = ("; to bake a sidecar into a foreign ONNX model use "
                "`rtp-export --adopt MODEL.onnx --metadata SIDECAR.yaml -o OUT.onnx`")
        if p.suffix.lower() in (".yaml", ".yml", ".json"):
            raise CheckpointError(f"{p} is a metadata file, not a checkpoint (the model.pt `rtp train` writes){hint}"
                                  ) from err
        if p.suffix.lower() == ".onnx":  # ("torch cannot read it (UnpicklingError)" of a model exported already)
            raise CheckpointError(f"{p}: not a checkpoint (the model.pt `rtp train` writes) but, by its name, an ONNX "
                                  f"model, exported already (`rtp info` shows an rtp model's metadata){hint}") from err
        raise CheckpointError(  # torch's own message is pages of weights_only advice: -v shows it
            f"{p}: not a checkpoint (the model.pt `rtp train` writes): torch cannot read it ({type(err).__name__})"
        ) from err
    if not isinstance(raw, dict) or raw.get("format") != FORMAT:
        raise CheckpointError(f"{p}: not an rtp checkpoint (expected format {FORMAT!r})")
    version = raw.get("format_version", 0)
    if isinstance(version, bool) or not isinstance(version, int) or version < 0:
        raise CheckpointError(f"{p}: format_version must be a non-negative integer, got {version!r}")
    if version > FORMAT_VERSION:
        raise CheckpointError(f"{p}: checkpoint format {version} is newer than this rtp reads ({FORMAT_VERSION})")
    # the other fields' shapes, so that a damaged or hand-made file is a CheckpointError, not an
    # AttributeError or ValueError from the lines that read them
    arch = raw.get("architecture", {})
    for key, value, ok in (("architecture", arch, isinstance(arch, dict)),
                           ("architecture.config", arch.get("config") if isinstance(arch, dict) else None,
                            isinstance(arch, dict) and isinstance(arch.get("config"), dict)),
                           ("state_dict", raw.get("state_dict"), isinstance(raw.get("state_dict"), dict)),
                           ("metadata", raw.get("metadata"), isinstance(raw.get("metadata"), (dict, type(None)))),
                           ("training", raw.get("training"), isinstance(raw.get("training"), (dict, type(None)))),
                           ("versions", raw.get("versions"), isinstance(raw.get("versions"), (dict, type(None))))):
        if not ok:
            raise CheckpointError(f"{p}: {key} must be a mapping, got {type(value).__name__}")
    name = arch.get("name")
    cls = _ARCHITECTURES.get(name) if isinstance(name, str) else None
    if cls is None:
        raise CheckpointError(f"{p}: unknown architecture {arch.get('name')!r}; known: {', '.join(_ARCHITECTURES)}")
    _check_fits_weights(p, cls, arch, raw["state_dict"])
    try:
        net = cls(**arch["config"])
        net.load_state_dict(raw["state_dict"])
    except (KeyError, TypeError, RuntimeError, ValueError) as err:
        raise CheckpointError(f"{p}: weights do not fit the architecture {arch}: {err}") from err
    bad = [k for k, v in raw["state_dict"].items()
           if isinstance(v, torch.Tensor) and v.is_floating_point() and not bool(torch.isfinite(v).all())]
    if bad:  # (exported, it failed the parity check as "max abs difference nan"; resumed, it trained on NaN)
        more = f" and {len(bad) - 1} more" if len(bad) > 1 else ""
        raise CheckpointError(f"{p}: its weights are not finite ({bad[0]}{more}): the training that wrote it diverged; "
                              "train again to another --out with a lower --lr")
    net.eval()
    try:
        meta = ModelMetadata.from_dict(raw.get("metadata") or {})
    except MetadataError as err:  # (the field's message alone did not say which file)
        raise MetadataError(f"{p}: its metadata: {err}") from err
    check_fits(net, meta)
    return Checkpoint(net=net, metadata=meta, training=raw.get("training"), versions=dict(raw.get("versions") or {}))
